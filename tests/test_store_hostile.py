"""The evidence store against hostile use (issue 9): two writers, crafted schemas, bad values,
foreign files, read-only and full stores. Each case: a one-line StoreError, the input untouched."""

from __future__ import annotations

import hashlib
import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from ctxsearch.knowledge.errors import CtxsearchError, StoreError
from ctxsearch.knowledge.store import (
    EXAM_KEY,
    SCHEMA_VERSION,
    EvidenceStore,
    inspect_store,
    merge_stores,
)
from ctxsearch.scripts.cli import main
from tests.old_stores import as_version

ROOT = Path(__file__).resolve().parents[1]


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _on(catalog) -> str:
    return next(r for r in catalog.type("Desk").relation_names if r.startswith("ON-TOP-OF"))


def _exam(store, oid: int, *, run: str = "r1", related=()):
    return store.record(
        run=run,
        style="office",
        room_seed=1,
        object_id=oid,
        ref_type="Desk",
        sim_time=float(oid),
        strategy="hif",
        related=related,
    )


def _store(path: Path, catalog, n: int = 3) -> Path:
    with EvidenceStore.open(path, catalog) as s:
        for i in range(n):
            _exam(s, i, related=[(_on(catalog), "Monitor", 100 + i)])
        s.mark_room("r1", "office", 1, "done", end_time=9.0)
    return path


# ---- 1. two writers ---------------------------------------------------------------------------
def test_the_same_examination_twice_is_refused_and_other_runs_still_append(tmp_path, catalog):
    path = _store(tmp_path / "s.sqlite", catalog)
    with EvidenceStore.open(path, catalog) as a, EvidenceStore.open(path, catalog) as b:
        _exam(a, 10)
        with pytest.raises(StoreError, match="already examined in run 'r1'.*another process"):
            _exam(b, 10, related=[(_on(catalog), "Cup", 7)])
        _exam(b, 10, run="r2")  # another run: its own evidence
        assert a.examinations_count() == 5 and a.examinations_count("r1") == 4
        # Nothing of the refused examination was written (no orphan observations either).
        assert a.conn.execute("SELECT COUNT(*) FROM observations").fetchone()[0] == 3
    assert EXAM_KEY == ("run", "style", "room_seed", "day", "object_id")


def test_two_learn_processes_of_one_run_leave_the_single_run_counts(tmp_path):
    """The issue's command (two `ctxsearch learn` of the same run at once, on one store)."""
    args = ["learn", "--style", "office", "--rooms", "2", "--perception", "oracle", "--no-progress"]
    single = tmp_path / "single.sqlite"
    assert main([*args, "--kb", str(single)]) == 0
    both = tmp_path / "both.sqlite"
    cmd = [sys.executable, "-m", "ctxsearch.scripts.cli", *args, "--kb", str(both)]
    procs = [
        subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for _ in range(2)
    ]
    results = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    for rc, err in results:
        assert "Traceback" not in err
        assert rc == 0 or (rc == 2 and len(err.strip().splitlines()) == 1), err
    with EvidenceStore.open(single, _cat()) as a, EvidenceStore.open(both, _cat()) as b:
        assert b.examinations_count() == a.examinations_count() > 0
        ka, kb = a.knowledge_base(), b.knowledge_base()
        for t in _cat().type_names:
            assert kb.n(t) == ka.n(t) and kb.nonzero(t) == ka.nonzero(t)
        assert b.rooms() == a.rooms()


def _cat():
    from ctxsearch.knowledge.catalog import load_catalog

    return load_catalog()


def _as_version_2(path: Path) -> None:
    as_version(path, 2)


def test_a_version_2_store_with_duplicates_is_deduplicated_by_its_upgrade(tmp_path, catalog):
    path = _store(tmp_path / "v2.sqlite", catalog)
    _as_version_2(path)
    conn = sqlite3.connect(path)  # what two writers left in a version-2 store: every row twice
    conn.execute(
        "INSERT INTO examinations (run, style, room_seed, object_id, type, sim_time, strategy, "
        "created) SELECT run, style, room_seed, object_id, type, sim_time, strategy, created "
        "FROM examinations"
    )
    conn.execute(
        "INSERT INTO observations SELECT examination_id + 3, relation, type, related_id "
        "FROM observations"
    )
    conn.commit()
    conn.close()
    with EvidenceStore.open(path, catalog, read_only=True) as s:  # read as it is
        assert s.version == 2 and s.examinations_count() == 6
    with EvidenceStore.open(path, catalog) as s:
        s.mark_room("r1", "office", 2, "started")  # the first write upgrades
        assert s.version == SCHEMA_VERSION and s.duplicates_dropped == 3
    with EvidenceStore.open(path, catalog) as s:
        assert s.examinations_count() == 3
        assert s.knowledge_base().n("Desk") == 3
        assert s.knowledge_base().y(_on(catalog), "Monitor") == 3
        assert s.room_end_time("r1", "office", 1) == 9.0
        assert [e.object_id for e in s.examinations()] == [0, 1, 2]
        with pytest.raises(StoreError, match="already examined"):
            _exam(s, 1)


# ---- 6. crafted schemas -----------------------------------------------------------------------
CRAFTED = {
    "trigger": "CREATE TRIGGER fake AFTER INSERT ON examinations BEGIN "
    "INSERT INTO observations VALUES (new.id, 'ON-TOP-OF-DESK', 'Monitor', 1); END",
    "view": "CREATE VIEW v AS SELECT * FROM examinations",
    "index": "CREATE INDEX extra ON observations (type)",
    "table": "CREATE TABLE notes (x)",
    "dropped key": "DROP INDEX examinations_key",
    "other column": "ALTER TABLE observations ADD COLUMN weight REAL DEFAULT 2",
    "map trigger": "CREATE TRIGGER forget AFTER INSERT ON home_maps BEGIN "
    "DELETE FROM home_maps WHERE rowid != new.rowid; END",
    "map index": "CREATE INDEX maps_by_day ON home_maps (day)",
}


@pytest.mark.parametrize("kind", sorted(CRAFTED))
def test_a_store_with_a_crafted_schema_is_refused_untouched(tmp_path, catalog, kind):
    path = _store(tmp_path / "s.sqlite", catalog)
    conn = sqlite3.connect(path)
    conn.execute(CRAFTED[kind])
    conn.commit()
    conn.close()
    before = digest(path)
    with pytest.raises(StoreError, match="refused: its schema is not the one ctxsearch writes"):
        EvidenceStore.open(path, catalog)
    assert digest(path) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.sqlite"]


# ---- 3. bad values inside a store -------------------------------------------------------------
def _set(path: Path, sql: str, *args) -> None:
    conn = sqlite3.connect(path)
    conn.execute(sql, args)
    conn.commit()
    conn.close()


@pytest.mark.parametrize("alpha", ["abc", "2.0", "nan", "0", ""])
def test_a_bad_stored_alpha_is_a_one_line_error(tmp_path, catalog, capsys, alpha):
    path = _store(tmp_path / "s.sqlite", catalog)
    _set(path, "UPDATE meta SET value = ? WHERE key = 'alpha'", alpha)
    with pytest.raises(StoreError, match="alpha .* is not a number in"):
        EvidenceStore.open(path, catalog)
    assert main(["kb", "show", str(path)]) == 2
    assert "is not a number in (0, 1)" in capsys.readouterr().err


@pytest.mark.parametrize(
    "sql, match",
    [
        (
            "UPDATE examinations SET sim_time = 'soon' WHERE id = 2",
            "sim_time 'soon' is not a finite",
        ),
        ("UPDATE examinations SET sim_time = 1e999 WHERE id = 2", "sim_time inf is not a finite"),
        ("UPDATE examinations SET object_id = 'x' WHERE id = 2", "object id 'x' is not an integer"),
        (
            "UPDATE examinations SET type = 'Ghost' WHERE id = 2",
            "type 'Ghost' is not in the catalog",
        ),
        ("UPDATE observations SET relation = 'UNDER-GHOST'", "'UNDER-GHOST' is not a relation of"),
        ("UPDATE observations SET type = x'00ff'", "observed type b'\\\\x00\\\\xff' is not a name"),
        ("UPDATE rooms SET end_time = 'late'", "end time .* 'late' is not a finite"),
    ],
)
def test_bad_values_in_rows_are_one_line_errors_naming_the_store(tmp_path, catalog, sql, match):
    path = _store(tmp_path / "s.sqlite", catalog)
    _set(path, sql)
    with pytest.raises(StoreError, match=match) as err, EvidenceStore.open(path, catalog) as s:
        list(s.examinations())
        s.room_end_time("r1", "office", 1)
    assert str(err.value).startswith(f"{path}: damaged knowledge store")


def test_an_unknown_relation_in_a_store_is_reported_against_the_store(tmp_path, catalog, capsys):
    path = _store(tmp_path / "s.sqlite", catalog)
    _set(path, "UPDATE observations SET relation = 'UNDER-GHOST'")
    argv = ["learn", "--style", "office", "--rooms", "1", "--kb", str(path)]
    assert main([*argv, "--perception", "oracle", "--no-progress", "--seed", "0"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"ctxsearch: error: {path}: ") and "UNDER-GHOST" in err
    assert main(["kb", "show", str(path)]) == 2
    assert capsys.readouterr().err.startswith(f"ctxsearch: error: {path}: ")


# ---- 3. stores that cannot be written ---------------------------------------------------------
def test_a_full_disk_is_a_one_line_error_and_loses_nothing(tmp_path, catalog):
    path = _store(tmp_path / "s.sqlite", catalog)
    with EvidenceStore.open(path, catalog) as s:
        pages = s.conn.execute("PRAGMA page_count").fetchone()[0]
        s.conn.execute(f"PRAGMA max_page_count = {pages}")  # as if the disk were full
        with pytest.raises(StoreError, match="cannot write knowledge store .*full"):
            for i in range(10, 5000):
                _exam(s, i, related=[(_on(catalog), "Cup", j) for j in range(20)])
        kept = s.examinations_count()
    with EvidenceStore.open(path, catalog) as s:
        assert s.examinations_count() == kept >= 3  # every committed examination is there


def test_writing_a_read_only_store_is_a_one_line_error(tmp_path, catalog):
    path = _store(tmp_path / "s.sqlite", catalog)
    before = digest(path)
    with EvidenceStore.open(path, catalog, read_only=True) as s:
        assert s.examinations_count() == 3
        with pytest.raises(StoreError, match="opened read-only"):
            _exam(s, 10)
    assert digest(path) == before
    with pytest.raises(StoreError, match="no such knowledge store"):
        EvidenceStore.open(tmp_path / "new.sqlite", catalog, read_only=True)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes read-only files")
def test_learn_on_a_read_only_file_is_a_one_line_error(tmp_path, catalog, capsys):
    path = _store(tmp_path / "s.sqlite", catalog)
    path.chmod(0o444)
    argv = ["learn", "--style", "office", "--rooms", "1", "--kb", str(path)]
    assert main([*argv, "--perception", "oracle", "--no-progress"]) == 2
    assert "cannot write knowledge store" in capsys.readouterr().err


def test_kb_show_reads_a_store_in_a_read_only_directory_and_creates_nothing(
    tmp_path, catalog, capsys
):
    d = tmp_path / "ro"
    d.mkdir()
    path = _store(d / "s.sqlite", catalog)
    before = digest(path)
    d.chmod(0o555)
    try:
        assert main(["kb", "show", str(path)]) == 0
        assert "ON-TOP-OF-DESK  Monitor  3/3" in capsys.readouterr().out
        assert sorted(p.name for p in d.iterdir()) == ["s.sqlite"]  # no -wal, no -shm
    finally:
        d.chmod(0o755)
    assert digest(path) == before


# ---- 5. foreign files are opened strictly read-only -------------------------------------------
def test_a_foreign_database_with_a_hot_journal_is_refused_and_not_rolled_back(tmp_path, catalog):
    src = tmp_path / "src"
    src.mkdir()
    db = src / "app.db"
    conn = sqlite3.connect(db)
    conn.execute("CREATE TABLE t (x)")
    conn.execute("INSERT INTO t VALUES (1)")
    conn.commit()
    conn.execute("PRAGMA cache_size = 1")
    conn.execute("BEGIN")
    conn.executemany("INSERT INTO t VALUES (?)", [(str(i) * 200,) for i in range(2000)])
    # Mid-transaction: the main file has uncommitted pages, the journal the originals.
    dst = tmp_path / "copy.db"
    shutil.copy(db, dst)
    shutil.copy(str(db) + "-journal", str(dst) + "-journal")
    conn.rollback()
    conn.close()
    journal = Path(str(dst) + "-journal")
    assert journal.stat().st_size > 0
    before = (digest(dst), digest(journal))
    for attempt in (lambda: inspect_store(dst), lambda: EvidenceStore.open(dst, catalog)):
        with pytest.raises(StoreError, match="not a ctxsearch knowledge store|rollback journal"):
            attempt()
    assert (digest(dst), digest(journal)) == before


# ---- 5. what is echoed is sanitised -----------------------------------------------------------
def test_control_characters_from_a_store_do_not_reach_the_terminal(tmp_path, catalog, capsys):
    path = _store(tmp_path / "s.sqlite", catalog)
    _set(path, "UPDATE meta SET value = ? WHERE key = 'catalog_path'", "x\n\x1b[2J\x1b]0;owned\x07")
    _set(path, "UPDATE meta SET value = ? WHERE key = 'catalog_fingerprint'", "f\r\nFAKE: ok")
    assert main(["kb", "show", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.endswith("\n")
    assert "\x1b" not in err and "\r" not in err and "\x07" not in err
    assert "built on catalog fingerprint" in err


def test_merge_reads_its_inputs_read_only(tmp_path, catalog):
    a = _store(tmp_path / "a.sqlite", catalog)
    before = digest(a)
    assert merge_stores(tmp_path / "out.sqlite", [a], catalog) == 3
    assert digest(a) == before
    with pytest.raises(CtxsearchError):
        merge_stores(tmp_path / "out.sqlite", [a], catalog)  # the same evidence again
    with EvidenceStore.open(tmp_path / "out.sqlite", catalog) as s:
        assert s.examinations_count() == 3


def test_two_processes_opening_a_version_2_store_upgrade_it_once(tmp_path, catalog):
    path = _store(tmp_path / "v2.sqlite", catalog)
    _as_version_2(path)
    with EvidenceStore.open(path, catalog) as a, EvidenceStore.open(path, catalog) as b:
        assert a.version == b.version == 2
        _exam(a, 10)  # a upgrades
        with pytest.raises(StoreError, match="already examined"):
            _exam(b, 10)  # b sees the upgraded file: no second rebuild, the key holds
        _exam(b, 11)
        assert b.version == SCHEMA_VERSION and b.examinations_count() == 5


def test_merge_reads_a_version_2_input_with_duplicates_once(tmp_path, catalog):
    src = _store(tmp_path / "v2.sqlite", catalog)
    _as_version_2(src)
    conn = sqlite3.connect(src)
    conn.execute(
        "INSERT INTO examinations (run, style, room_seed, object_id, type, sim_time, strategy, "
        "created) SELECT run, style, room_seed, object_id, type, sim_time, strategy, created "
        "FROM examinations"
    )
    conn.commit()
    conn.close()
    before = digest(src)
    assert merge_stores(tmp_path / "out.sqlite", [src], catalog) == 3
    assert digest(src) == before


def test_a_room_done_stays_done_when_a_late_writer_marks_it_started(tmp_path, catalog):
    path = _store(tmp_path / "s.sqlite", catalog)
    with EvidenceStore.open(path, catalog) as s:
        s.mark_room("r1", "office", 1, "started")  # the second writer's late "entered"
        assert s.room_status("r1", "office", 1) == "done"
        assert s.room_end_time("r1", "office", 1) == 9.0


def test_run_names_with_control_characters_are_refused_on_write_and_read(tmp_path, catalog):
    path = _store(tmp_path / "s.sqlite", catalog)
    with EvidenceStore.open(path, catalog) as s, pytest.raises(CtxsearchError, match="printable"):
        _exam(s, 50, run="r\x1b[2J")
    _set(path, "UPDATE examinations SET run = ? WHERE id = 1", "r1\n\x1b[31mok")
    with EvidenceStore.open(path, catalog) as s, pytest.raises(StoreError, match="is not a name"):
        s.runs()


def test_ctrl_c_while_a_store_is_created_leaves_no_file(tmp_path, catalog, monkeypatch):
    import ctxsearch.knowledge.store as store_mod

    real = store_mod.sqlite3.connect

    def connect_then_interrupt(*a, **kw):
        conn = real(*a, **kw)
        conn.execute("CREATE TABLE x (y)")  # something written to the file being built
        raise KeyboardInterrupt

    monkeypatch.setattr(store_mod.sqlite3, "connect", connect_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        EvidenceStore.open(tmp_path / "new.sqlite", catalog)
    assert list(tmp_path.iterdir()) == []


def test_learn_on_a_store_sqlite_cannot_write_is_a_one_line_error(
    tmp_path, catalog, capsys, monkeypatch
):
    """As learn on a read-only file sees it (root, running the tests, can write any file: the
    connection is opened read-only instead)."""
    import ctxsearch.knowledge.store as store_mod
    import ctxsearch.knowledge.store_schema as schema_mod

    path = _store(tmp_path / "s.sqlite", catalog)
    before = digest(path)
    monkeypatch.setattr(
        store_mod,
        "_connect",
        lambda p: sqlite3.connect(schema_mod._ro_uri(p), uri=True, isolation_level=None),
    )
    argv = ["learn", "--style", "office", "--rooms", "1", "--kb", str(path)]
    assert main([*argv, "--perception", "oracle", "--no-progress"]) == 2
    err = _err_line(capsys)
    assert "cannot write knowledge store (attempt to write a readonly database)" in err
    assert digest(path) == before


def _err_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err
