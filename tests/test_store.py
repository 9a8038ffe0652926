"""The evidence store: append-only log, counts rebuilt from it, refusal of foreign files without
touching them, crash safety, merging."""

from __future__ import annotations

import hashlib
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.errors import CtxsearchError, StoreError
from ctxsearch.knowledge.store import SCHEMA_VERSION, EvidenceStore, inspect_store, merge_stores
from tests.old_stores import as_version

ROOT = Path(__file__).resolve().parents[1]


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def exam(
    store: EvidenceStore,
    object_id: int,
    ref: str = "Desk",
    related=(),
    *,
    run="r1",
    style="office",
    seed=1,
):
    return store.record(
        run=run,
        style=style,
        room_seed=seed,
        object_id=object_id,
        ref_type=ref,
        sim_time=float(object_id),
        strategy="hif",
        related=list(related),
    )


def _desk_rel(cat, prefix: str) -> str:
    return next(r for r in cat.type("Desk").relation_names if r.startswith(prefix))


@pytest.fixture
def store(tmp_path, catalog):
    with EvidenceStore.open(tmp_path / "kb.sqlite", catalog) as s:
        yield s


def test_new_store_records_meta(tmp_path, catalog):
    path = tmp_path / "kb.sqlite"
    with EvidenceStore.open(path, catalog) as s:
        assert s.alpha == 0.10
        assert s.meta["app"] == "ctxsearch"
        assert s.meta["schema_version"] == str(SCHEMA_VERSION)
        assert s.fingerprint == catalog.fingerprint
        assert s.examinations_count() == 0 and s.runs() == []
    with EvidenceStore.open(path, catalog, alpha=0.05, create=False) as s:
        assert s.alpha == 0.05  # this session's default ...
    assert inspect_store(path)["alpha"] == "0.1"  # ... the file's is unchanged
    with EvidenceStore.open(tmp_path / "b.sqlite", catalog, alpha=0.2) as s:
        assert s.alpha == 0.2
    with EvidenceStore.open(tmp_path / "b.sqlite", catalog) as s:
        assert s.alpha == 0.2
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "b.sqlite",
        "kb.sqlite",
    ]  # no side files left


def test_record_and_rebuild_counts(store, catalog):
    on, near = _desk_rel(catalog, "ON-TOP-OF"), _desk_rel(catalog, "NEAR")
    kb = KnowledgeBase(catalog)
    examinations = [
        (
            "Desk",
            [(on, "Cup", 10), (on, "Cup", 11), (near, "Chair", 12)],
        ),  # two cups: "at least one"
        ("Desk", [(on, "Cup", 13)]),
        ("Desk", []),
        ("Cup", []),
    ]
    for i, (ref, rel) in enumerate(examinations):
        eid = exam(store, i, ref, rel)
        assert eid == i + 1
        kb.record_examination(ref, [(r, t) for r, t, _ in rel])
    got = store.knowledge_base()
    assert got.alpha == 0.10
    for t in catalog.type_names:
        assert got.n(t) == kb.n(t)
        assert got.nonzero(t) == kb.nonzero(t)
    assert got.y(on, "Cup") == 2 and got.n("Desk") == 3
    assert store.knowledge_base(alpha=0.05).interval(on, "Cup") == pytest.approx(
        tuple(float(v) for v in intervals.interval(2, 3, 0.05))
    )
    assert store.examinations_count() == 4


def test_record_validates_before_writing(store, catalog):
    on = _desk_rel(catalog, "ON-TOP-OF")
    cup_rel = catalog.type("Cup").relation_names[0]
    exam(store, 1, "Desk", [(on, "Cup", 5)])
    bad = [
        dict(
            ref_type="Desk", related=[(on, "Cup", 5), (cup_rel, "Desk", 6)]
        ),  # other type's relation
        dict(ref_type="Desk", related=[(on, "Mug", 5)]),  # unknown type
        dict(ref_type="Desk", related=[("FLYING-OVER-DESK", "Cup", 5)]),  # unknown relation
        dict(ref_type="Mug", related=[]),
        dict(ref_type="Desk", related=[(on, "Cup")]),  # not a triple
        dict(ref_type="Desk", related=[(on, "Cup", "five")]),
        dict(ref_type="Desk", related=[], object_id=1.5),
        dict(ref_type="Desk", related=[], run=""),
        dict(ref_type="Desk", related=[], sim_time="soon"),
    ]
    for kw in bad:
        args = (
            dict(run="r1", style="office", room_seed=1, object_id=2, sim_time=0.0, strategy="hif")
            | kw
        )
        with pytest.raises(CtxsearchError):
            store.record(**args)
    assert store.examinations_count() == 1
    assert store.conn.execute("SELECT COUNT(*) FROM observations").fetchone()[0] == 1


def test_rooms_examined_runs(store):
    assert store.room_status("r1", "office", 3) is None
    store.mark_room("r1", "office", 3, "started")
    assert store.room_status("r1", "office", 3) == "started"
    store.mark_room("r1", "office", 3, "done")
    assert store.room_status("r1", "office", 3) == "done"
    with pytest.raises(CtxsearchError, match="status"):
        store.mark_room("r1", "office", 3, "finished")
    exam(store, 7, seed=3)
    exam(store, np.int64(9), seed=3)
    exam(store, 7, seed=4)
    exam(store, 8, seed=3, run="r2")
    store.mark_room("r0", "kitchen", 1, "started")
    assert store.examined("r1", "office", 3) == {7, 9}
    assert store.examined("r1", "office", 4) == {7}
    assert store.examined("r1", "kitchen", 3) == set()
    assert store.runs() == ["r0", "r1", "r2"]
    assert store.examinations_count() == 4 and store.examinations_count("r1") == 3
    assert store.rooms() == [("r0", "kitchen", 1, "started"), ("r1", "office", 3, "done")]
    assert store.knowledge_base(run="r2").n("Desk") == 1


# ---- files that are not (usable) stores: one-line error, bytes untouched ---------------------
def _foreign_sqlite(path: Path) -> None:
    conn = sqlite3.connect(path)
    conn.execute("CREATE TABLE meta (key TEXT, value TEXT)")
    conn.execute("INSERT INTO meta VALUES ('app', 'someone-else')")
    conn.commit()
    conn.close()


def _no_meta_sqlite(path: Path) -> None:
    conn = sqlite3.connect(path)
    conn.execute("CREATE TABLE songs (title TEXT)")
    conn.commit()
    conn.close()


def _newer_schema(path: Path, catalog) -> None:
    EvidenceStore.open(path, catalog).close()
    conn = sqlite3.connect(path)
    conn.execute(
        "UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(SCHEMA_VERSION + 1),)
    )
    conn.commit()
    conn.close()


def _big_store(path: Path, catalog, n: int = 300) -> None:
    with EvidenceStore.open(path, catalog) as s:
        on = _desk_rel(catalog, "ON-TOP-OF")
        for i in range(n):
            exam(s, i, "Desk", [(on, "Cup", 1000 + i)] * 3)


def make_bad(kind: str, path: Path, catalog, other_catalog) -> str:
    """Write a bad file of ``kind``; return a regex the error must match."""
    if kind == "random-bytes":
        path.write_bytes(np.random.default_rng(0).bytes(5000))
        return "not a ctxsearch knowledge store"
    if kind == "empty":
        path.write_bytes(b"")
        return "not a ctxsearch knowledge store"
    if kind == "text":
        path.write_text("schema = 1\n")
        return "not a ctxsearch knowledge store"
    if kind == "foreign-sqlite":
        _foreign_sqlite(path)
        return "not a ctxsearch knowledge store"
    if kind == "sqlite-without-meta":
        _no_meta_sqlite(path)
        return "not a ctxsearch knowledge store"
    if kind == "other-catalog":
        EvidenceStore.open(path, other_catalog).close()
        return f"{other_catalog.fingerprint}.*{catalog.fingerprint}"
    if kind == "newer-schema":
        _newer_schema(path, catalog)
        return f"schema version {SCHEMA_VERSION + 1} is newer"
    if kind == "truncated-header":
        _big_store(path, catalog)
        path.write_bytes(path.read_bytes()[:60])
        return "truncated or corrupt"
    if kind == "truncated":
        _big_store(path, catalog)
        path.write_bytes(path.read_bytes()[: 4096 * 4 + 100])
        return "corrupt"
    if kind == "garbled-pages":
        _big_store(path, catalog)
        data = bytearray(path.read_bytes())
        data[4096 * 3 : 4096 * 6] = np.random.default_rng(1).bytes(4096 * 3)
        path.write_bytes(bytes(data))
        return "corrupt"
    raise AssertionError(kind)


BAD_KINDS = [
    "random-bytes",
    "empty",
    "text",
    "foreign-sqlite",
    "sqlite-without-meta",
    "other-catalog",
    "newer-schema",
    "truncated-header",
    "truncated",
    "garbled-pages",
]


@pytest.mark.parametrize("kind", BAD_KINDS)
def test_bad_files_are_refused_and_left_untouched(tmp_path, catalog, other_catalog, kind):
    path = tmp_path / "bad.sqlite"
    pattern = make_bad(kind, path, catalog, other_catalog)
    before = digest(path)
    for create in (True, False):
        with pytest.raises(StoreError, match=pattern) as info:
            EvidenceStore.open(path, catalog, create=create)
        msg = str(info.value)
        assert "\n" not in msg and msg.startswith(str(path)), msg
    assert digest(path) == before
    # No journal, WAL or temporary files were created beside it.
    assert [p.name for p in tmp_path.iterdir()] == ["bad.sqlite"]


def test_other_catalog_error_names_both_fingerprints(tmp_path, catalog, other_catalog):
    path = tmp_path / "other.sqlite"
    EvidenceStore.open(path, other_catalog).close()
    with pytest.raises(StoreError) as info:
        EvidenceStore.open(path, catalog)
    msg = str(info.value)
    assert (
        other_catalog.fingerprint in msg and catalog.fingerprint in msg and "<other catalog>" in msg
    )


def test_missing_and_uncreatable(tmp_path, catalog):
    with pytest.raises(StoreError, match="no such knowledge store"):
        EvidenceStore.open(tmp_path / "nope.sqlite", catalog, create=False)
    assert not (tmp_path / "nope.sqlite").exists()
    with pytest.raises(StoreError, match="cannot create"):
        EvidenceStore.open(tmp_path / "no" / "such" / "dir.sqlite", catalog)
    with pytest.raises(StoreError, match="not a regular file"):
        EvidenceStore.open(tmp_path, catalog)
    with pytest.raises(CtxsearchError, match="alpha"):
        EvidenceStore.open(tmp_path / "a.sqlite", catalog, alpha=1.5)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_closed_store_refuses_use(tmp_path, catalog):
    s = EvidenceStore.open(tmp_path / "kb.sqlite", catalog)
    s.close()
    s.close()
    with pytest.raises(StoreError, match="closed"):
        s.examinations_count()


# ---- crash safety ----------------------------------------------------------------------------
def test_failure_inside_the_transaction_keeps_earlier_examinations(tmp_path, catalog, monkeypatch):
    path = tmp_path / "kb.sqlite"
    on = _desk_rel(catalog, "ON-TOP-OF")
    with EvidenceStore.open(path, catalog) as s:
        for i in range(3):
            exam(s, i, "Desk", [(on, "Cup", 100 + i)])

        def boom(*a, **k):
            raise RuntimeError("power cut")

        monkeypatch.setattr(EvidenceStore, "_insert_observations", boom)
        with pytest.raises(RuntimeError, match="power cut"):
            exam(s, 3, "Desk", [(on, "Cup", 103)])
        monkeypatch.undo()
        assert s.examinations_count() == 3  # the examination row of the failed one is gone too
        exam(s, 4, "Desk", [(on, "Cup", 104)])  # and the store is still usable
    with EvidenceStore.open(path, catalog, create=False) as s:
        assert s.examinations_count() == 4
        assert s.examined("r1", "office", 1) == {0, 1, 2, 4}
        assert s.knowledge_base().y(on, "Cup") == 4


KILLER = r"""
import os, sys
sys.path.insert(0, sys.argv[2])
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.store import EvidenceStore

cat = load_catalog()
on = next(r for r in cat.type("Desk").relation_names if r.startswith("ON-TOP-OF"))
s = EvidenceStore.open(sys.argv[1], cat)
for i in range(5):
    s.record(run="r1", style="office", room_seed=1, object_id=i, ref_type="Desk", sim_time=0.0,
             strategy="hif", related=[(on, "Cup", 100 + i)])

def killed(self, cur, eid, rows):  # dies halfway through the sixth examination's transaction
    cur.connection.execute("PRAGMA cache_size = 1")
    for j in range(5000):
        cur.execute("INSERT INTO observations VALUES (?, ?, ?, ?)", (eid, on, "Cup", j))
    os._exit(9)

EvidenceStore._insert_observations = killed
s.record(run="r1", style="office", room_seed=1, object_id=5, ref_type="Desk", sim_time=0.0,
         strategy="hif", related=[(on, "Cup", 105)])
"""


def test_killed_process_loses_only_the_examination_in_flight(tmp_path, catalog):
    path = tmp_path / "kb.sqlite"
    proc = subprocess.run(
        [sys.executable, "-c", KILLER, str(path), str(ROOT)], capture_output=True, text=True
    )
    assert proc.returncode == 9, proc.stderr
    with EvidenceStore.open(path, catalog, create=False) as s:
        assert s.examinations_count() == 5
        assert s.examined("r1", "office", 1) == {0, 1, 2, 3, 4}
        assert s.conn.execute("SELECT COUNT(*) FROM observations").fetchone()[0] == 5
        exam(s, 5, "Desk")
        assert s.examinations_count() == 6


# ---- merging ---------------------------------------------------------------------------------
def _fill(path: Path, catalog, run: str, n: int, seed: int, first_id: int = 0) -> KnowledgeBase:
    rng = np.random.default_rng(seed)
    kb = KnowledgeBase(catalog)
    refs = [t.name for t in catalog.types if t.relations]
    with EvidenceStore.open(path, catalog) as s:
        s.mark_room(run, "office", 1, "started")
        s.mark_room(run, "office", 2, "done")
        for i in range(n):
            ref = refs[rng.integers(len(refs))]
            rels = catalog.type(ref).relation_names
            related = [
                (
                    rels[rng.integers(len(rels))],
                    catalog.type_names[rng.integers(len(catalog))],
                    int(j),
                )
                for j in range(rng.integers(0, 4))
            ]
            s.record(
                run=run,
                style="office",
                room_seed=1 + i % 2,
                object_id=first_id + i,
                ref_type=ref,
                sim_time=i,
                strategy="hif",
                related=related,
            )
            kb.record_examination(ref, [(r, t) for r, t, _ in related])
    return kb


def _assert_same_counts(a: KnowledgeBase, b: KnowledgeBase, catalog) -> None:
    for t in catalog.type_names:
        assert a.n(t) == b.n(t), t
        assert a.nonzero(t) == b.nonzero(t), t


def test_merge_into_new_and_existing(tmp_path, catalog):
    a, b, c = tmp_path / "a.sqlite", tmp_path / "b.sqlite", tmp_path / "c.sqlite"
    ka, kb_, kc = (
        _fill(a, catalog, "ra", 40, 1),
        _fill(b, catalog, "rb", 30, 2),
        _fill(c, catalog, "ra", 20, 3, first_id=1000),  # same run and rooms, other objects
    )
    out = tmp_path / "out.sqlite"
    assert merge_stores(out, [a, b], catalog) == 70
    expect = KnowledgeBase(catalog)
    for k in (ka, kb_):
        for t in catalog.type_names:
            expect.add_counts(t, k.n(t), k.nonzero(t))
    with EvidenceStore.open(out, catalog, create=False) as s:
        _assert_same_counts(s.knowledge_base(), expect, catalog)
        assert s.runs() == ["ra", "rb"]
        ids = [r[0] for r in s.conn.execute("SELECT id FROM examinations ORDER BY id")]
        assert ids == list(range(1, 71))
        # Every observation still belongs to an examination of its relation's reference type.
        bad = s.conn.execute(
            "SELECT COUNT(*) FROM observations o LEFT JOIN examinations e ON e.id = o.examination_id "
            "WHERE e.id IS NULL OR o.relation NOT LIKE '%-' || UPPER(e.type)"
        ).fetchone()[0]
        assert bad == 0
    # Append a third store (same run and rooms as a, other objects): 'done' wins for the rooms.
    with EvidenceStore.open(c, catalog, create=False) as s:
        s.mark_room("ra", "office", 1, "done")
    assert merge_stores(out, [c], catalog) == 20
    for t in catalog.type_names:
        expect.add_counts(t, kc.n(t), kc.nonzero(t))
    with EvidenceStore.open(out, catalog, create=False) as s:
        _assert_same_counts(s.knowledge_base(), expect, catalog)
        assert s.examinations_count() == 90
        assert (
            s.room_status("ra", "office", 1) == "done"
            and s.room_status("rb", "office", 1) == "started"
        )
    # The inputs are untouched.
    with EvidenceStore.open(a, catalog, create=False) as s:
        assert s.examinations_count() == 40


def test_merge_refuses_bad_inputs_without_writing(tmp_path, catalog, other_catalog):
    a, b = tmp_path / "a.sqlite", tmp_path / "b.sqlite"
    _fill(a, catalog, "ra", 5, 1)
    EvidenceStore.open(b, other_catalog).close()
    out = tmp_path / "out.sqlite"
    with pytest.raises(StoreError, match=f"^{b}: built on catalog fingerprint"):
        merge_stores(out, [a, b], catalog)
    assert not out.exists()
    _fill(out, catalog, "ro", 3, 2)
    before = digest(out)
    with pytest.raises(StoreError, match="given twice"):
        merge_stores(out, [a, tmp_path / "." / "a.sqlite"], catalog)
    with pytest.raises(StoreError, match="also an input"):
        merge_stores(out, [a, out], catalog)
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"\x00" * 300)
    with pytest.raises(StoreError, match=f"^{junk}: not a ctxsearch"):
        merge_stores(out, [a, junk], catalog)
    with pytest.raises(StoreError, match="no input"):
        merge_stores(out, [], catalog)
    assert digest(out) == before


def test_rebuild_is_fast_for_100k_examinations(tmp_path, catalog):
    path = tmp_path / "big.sqlite"
    rng = np.random.default_rng(0)
    refs = [t.name for t in catalog.types if t.relations]
    with EvidenceStore.open(path, catalog) as s:
        cur = s.conn.cursor()
        cur.execute("BEGIN")
        N = 100_000
        ref_idx = rng.integers(len(refs), size=N)
        cur.executemany(
            "INSERT INTO examinations (run, style, room_seed, object_id, type, sim_time, strategy, created) "
            "VALUES ('r', 'office', ?, ?, ?, 0, 'hif', 0)",
            ((i // 50, i, refs[k]) for i, k in enumerate(ref_idx)),
        )
        obs = []
        names = catalog.type_names
        rel_names = [catalog.type(r).relation_names for r in refs]
        for i, k in enumerate(ref_idx):
            rels = rel_names[k]
            for j in range(3):
                obs.append(
                    (
                        i + 1,
                        rels[(i + j) % len(rels)],
                        names[(i * 7 + j) % len(names)],
                        j,
                    )
                )
        cur.executemany("INSERT INTO observations VALUES (?, ?, ?, ?)", obs)
        cur.execute("COMMIT")
        t0 = time.perf_counter()
        kb = s.knowledge_base()
        elapsed = time.perf_counter() - t0
    assert kb.total_examinations == 100_000
    print(f"knowledge_base() over 100k examinations: {elapsed:.3f} s")
    assert elapsed < 3.0, elapsed


def test_examinations_iterates_rows_with_their_observations(store, catalog):
    on = _desk_rel(catalog, "ON-TOP-OF")
    exam(store, 1, "Desk", [(on, "Cup", 10), (on, "Book", 11)])
    exam(store, 2, "Cup")
    exam(store, 3, "Desk", [(on, "Cup", 12)], run="r2", seed=4)
    rows = list(store.examinations())
    assert [(e.id, e.run, e.object_id, e.type) for e in rows] == [
        (1, "r1", 1, "Desk"),
        (2, "r1", 2, "Cup"),
        (3, "r2", 3, "Desk"),
    ]
    assert rows[0].related == ((on, "Cup", 10), (on, "Book", 11))
    assert rows[1].related == () and rows[1].sim_time == 2.0 and rows[1].strategy == "hif"
    assert rows[2].room_seed == 4 and rows[2].style == "office"
    assert [e.id for e in store.examinations(run="r2")] == [3]
    assert list(store.examinations(run="nobody")) == []


def test_room_end_time(store):
    assert store.room_end_time("r1", "office", 3) is None
    store.mark_room("r1", "office", 3, "started")
    assert store.room_end_time("r1", "office", 3) is None
    store.mark_room("r1", "office", 3, "done", end_time=123.5)
    assert store.room_end_time("r1", "office", 3) == 123.5
    assert store.rooms() == [("r1", "office", 3, "done")]
    with pytest.raises(CtxsearchError, match="end_time must be a number"):
        store.mark_room("r1", "office", 3, "done", end_time="late")


def _old_version(path: Path, catalog, version: int) -> None:
    """A store as schema version 1 (no rooms.end_time, no uniqueness key) or 2 (no uniqueness
    key) wrote it."""
    with EvidenceStore.open(path, catalog) as s:
        exam(s, 1, "Desk")
        s.mark_room("r1", "office", 1, "done")
    as_version(path, version)


def _version1(path: Path, catalog) -> None:
    _old_version(path, catalog, 1)


def test_version_1_store_is_read_and_upgraded_on_the_first_write(tmp_path, catalog):
    path = tmp_path / "v1.sqlite"
    _version1(path, catalog)
    before = digest(path)
    with EvidenceStore.open(path, catalog, create=False) as s:  # reading leaves it as it is
        assert s.meta["schema_version"] == "1"
        assert s.room_status("r1", "office", 1) == "done"
        assert s.room_end_time("r1", "office", 1) is None
        assert [e.object_id for e in s.examinations()] == [1]
    assert digest(path) == before
    with EvidenceStore.open(path, catalog, create=False) as s:
        s.mark_room("r1", "office", 2, "started")  # any write upgrades (the key guards appends)
        assert s.version == SCHEMA_VERSION
    assert inspect_store(path)["schema_version"] == str(SCHEMA_VERSION)
    with EvidenceStore.open(path, catalog, create=False) as s:
        s.mark_room("r1", "office", 2, "done", end_time=7.0)
        assert s.meta["schema_version"] == str(SCHEMA_VERSION)
        assert s.room_end_time("r1", "office", 2) == 7.0
        assert s.room_end_time("r1", "office", 1) is None
    with EvidenceStore.open(path, catalog, create=False) as s:
        assert s.meta["schema_version"] == str(SCHEMA_VERSION)
        assert s.rooms() == [("r1", "office", 1, "done"), ("r1", "office", 2, "done")]
        assert [e.object_id for e in s.examinations()] == [1]


def test_merge_keeps_end_times_and_upgrades_a_version_1_output(tmp_path, catalog):
    old, new = tmp_path / "old.sqlite", tmp_path / "new.sqlite"
    _version1(old, catalog)
    with EvidenceStore.open(new, catalog) as s:
        exam(s, 5, "Cup", run="r2")
        s.mark_room("r2", "office", 1, "done", end_time=42.0)
    assert merge_stores(old, [new], catalog) == 1
    with EvidenceStore.open(old, catalog, create=False) as s:
        assert s.meta["schema_version"] == str(SCHEMA_VERSION)
        assert s.room_end_time("r2", "office", 1) == 42.0
        assert s.room_end_time("r1", "office", 1) is None
    out = tmp_path / "out.sqlite"
    # old now holds new's examination too: merging both would count it twice.
    with pytest.raises(StoreError, match="already in .*count twice"):
        merge_stores(out, [new, old], catalog)
    assert not out.exists()
    assert merge_stores(out, [old], catalog) == 2
    with EvidenceStore.open(out, catalog, create=False) as s:
        assert s.room_end_time("r2", "office", 1) == 42.0
