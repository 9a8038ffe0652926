"""The robot's remembered map of a home (knowledge.home_map) and the evidence store that keeps
one per house visit (schema 7's home_maps): bytes that round-trip, hostile bytes refused in one
line, the map written with the visit's 'done' in one transaction (the first kept, nothing on a
refusal or a kill), read back by world and day, older stores without maps, merging."""

from __future__ import annotations

import hashlib
import io
import json
import sqlite3
import subprocess
import sys
import tracemalloc
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ctxsearch.knowledge.errors import CtxsearchError, StoreError
from ctxsearch.knowledge.home_map import (
    HomeMap,
    HomeMapError,
    PersistenceCheck,
    RememberedObject,
    check_types,
)
from ctxsearch.knowledge.store import SCHEMA_VERSION, EvidenceStore, inspect_store, merge_stores
from ctxsearch.scripts.cli import main
from tests.old_stores import as_version

ROOT = Path(__file__).resolve().parents[1]
ARRAYS = ("floor", "occupied", "top_z", "rooms", "support")


def make_map(style="apartment", seed=1, day=0, types=("Bed", "Sofa"), images=3, rng=0) -> HomeMap:
    """A small map of world (style, seed) on ``day``, its furniture of ``types``."""
    g = np.random.default_rng(rng)
    shape = (30, 50)
    floor = g.random(shape) < 0.6
    occupied = ~floor & (g.random(shape) < 0.5)
    top_z = np.where(occupied, g.uniform(0.3, 1.2, shape), 0.0).astype(np.float32)
    rooms = np.where(floor, np.arange(shape[1])[None, :] // 25, -1).astype(np.int16)
    furniture = tuple(
        RememberedObject(t, 100 + i, (1.0 + i, 0.5, 0.4), 0.3 * i, (1.0, 0.8, 0.5), 0.9, 4 + i)
        for i, t in enumerate(types)
    )
    return HomeMap(
        style, seed, day, (0.0, 0.0, 5.0, 3.0), 2.0, 0.0, 0.0, 0.1,
        floor, occupied, top_z, rooms, furniture, g.random(200) < 0.3, images,
    )  # fmt: skip


def same(a: HomeMap, b: HomeMap) -> bool:
    """Whether two maps hold the same values (HomeMap compares by identity)."""
    fields = ("style", "seed", "day", "bounds", "top", "x0", "y0", "resolution", "furniture",
              "small", "checks")  # fmt: skip
    return all(getattr(a, f) == getattr(b, f) for f in (*fields, "images")) and all(
        getattr(a, k).dtype == getattr(b, k).dtype and np.array_equal(getattr(a, k), getattr(b, k))
        for k in ARRAYS
    )


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def rows(store: EvidenceStore) -> list[str]:
    """Every row of every table, as SQL (what a refused write must leave as it was)."""
    return list(store.conn.iterdump())


def one_line(exc: BaseException, start: str) -> str:
    msg = str(exc)
    assert "\n" not in msg and "\r" not in msg and msg.startswith(start), msg
    return msg


# ---- the map's bytes ----------------------------------------------------------------------------
def test_a_map_round_trips_through_its_bytes():
    m = make_map(types=("Bed", "Sofa", "Shelf"), images=17)
    back = HomeMap.from_bytes(m.to_bytes(), "here")
    assert same(back, m) and back.to_bytes() == m.to_bytes()
    assert back.room_count() == 2 and back.shape == (30, 50)
    assert [o.type for o in back.objects()] == ["Bed", "Sofa", "Shelf"]
    assert same(HomeMap.from_bytes(memoryview(m.to_bytes())), m)


def test_small_objects_and_checks_round_trip_and_a_version_1_map_reads_without_them():
    m = make_map(day=4)
    small = (
        RememberedObject("Cup", 7, (1.0, 2.0, 0.8), 0.1, (0.1, 0.1, 0.1), 0.7, 2),
        RememberedObject("Book", 9, (2.0, 1.0, 0.9), 0.0, (0.2, 0.1, 0.3), 0.9, 1, day=2),
    )
    checks = (
        PersistenceCheck("Cup", 1, 0.8, 0.0, False),
        PersistenceCheck("Book", 2, 0.5, 0, True),
    )
    m = replace(m, small=small, checks=checks)
    back = HomeMap.from_bytes(m.to_bytes(), "here")
    assert same(back, m) and back.small == small and back.checks == checks
    assert [back.seen_day(o) for o in back.small] == [4, 2]
    assert [o.id for o in back.last_seen("Book")] == [9] and back.last_seen("Pen") == []
    old = json.loads(_header(m)) | {"version": 1}
    del old["small"], old["checks"]
    v1 = HomeMap.from_bytes(_npz(old), "old")
    assert v1.small == () and v1.checks == () and v1.furniture == m.furniture
    with pytest.raises(HomeMapError, match="unknown type 'Mug'"):
        check_types(replace(m, small=(replace(small[0], type="Mug"),)), ["Cup", "Bed", "Sofa"], "x")
    with pytest.raises(HomeMapError, match="unknown type 'Mug'"):
        check_types(
            replace(m, small=(), checks=(replace(checks[0], type="Mug"),)),
            ["Cup", "Bed", "Sofa"],
            "x",
        )


def _npz(head: dict | bytes | None = None, **arrays) -> bytes:
    """An archive as to_bytes writes it, with ``head`` (a dict, or raw header bytes) and
    ``arrays`` replacing the map's."""
    m = make_map()
    base = {k: getattr(m, k) for k in ARRAYS} | arrays
    if head is None or isinstance(head, dict):
        head = json.dumps(json.loads(_header(m)) | (head or {})).encode()
    buf = io.BytesIO()
    np.savez_compressed(buf, header=np.frombuffer(head, np.uint8), **base)
    return buf.getvalue()


def _header(m: HomeMap) -> str:
    with np.load(io.BytesIO(m.to_bytes())) as z:
        return z["header"].tobytes().decode()


def _zip(members: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    return buf.getvalue()


def _entry(i: int, **fields) -> dict:
    """A furniture entry of the header as to_bytes writes one."""
    return {"type": "Bed", "id": i, "position": [0, 0, 0], "yaw": 0, "size": [1, 1, 1],
            "confidence": 0.5, "sightings": 1} | fields  # fmt: skip


def _check(**fields) -> dict:
    """A persistence check of the header as to_bytes writes one."""
    return {"type": "Cup", "age": 1, "recall": 0.8, "false_rate": 0.0, "still": True} | fields


def _other_npz() -> bytes:
    buf = io.BytesIO()
    np.savez(buf, header=np.zeros(3, np.uint8), a=np.zeros(3))
    return buf.getvalue()


def _bomb() -> bytes:
    """A blob of well under a megabyte whose floor unpacks to 64 MB (16 times the largest map)."""
    buf = io.BytesIO()
    good = np.load(io.BytesIO(make_map().to_bytes()))
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for k in ("header", *ARRAYS):
            with z.open(f"{k}.npy", "w", force_zip64=True) as f:
                if k == "floor":
                    np.lib.format.write_array_header_1_0(
                        f, {"descr": "|b1", "fortran_order": False, "shape": (8000, 8000)}
                    )
                    for _ in range(8):
                        f.write(bytes(8_000_000))
                else:
                    np.lib.format.write_array(f, good[k])
    return buf.getvalue()


HOSTILE = {
    "truncated": (lambda: make_map().to_bytes()[:-300], "unreadable"),
    "half": (lambda: make_map().to_bytes()[:1000], "unreadable"),
    "empty": (lambda: b"", "unreadable"),
    "random": (lambda: np.random.default_rng(3).bytes(5000), "unreadable"),
    "text": (lambda: "a map", "not bytes"),
    "other arrays": (lambda: _zip({"a.npy": b"x"}), "its arrays differ"),
    "numpy's other arrays": (lambda: _other_npz(), "its arrays differ"),
    "not npy members": (
        lambda: _zip({f"{k}.npy": b"not an array" for k in ("header", *ARRAYS)}),
        "not .npy arrays",
    ),
    "non-finite top": (lambda: _npz({"top": float("nan")}), "'top' is not a finite number"),
    "infinite origin": (lambda: _npz({"x0": float("-inf")}), "'x0' is not a finite number"),
    "non-finite bound": (lambda: _npz({"bounds": [0, 0, "Infinity", 1]}), "'bounds'"),
    "infinite size": (
        lambda: _npz({"furniture": [_entry(1, size=[1, 1, float("inf")])]}),
        "'size' is not a finite number",
    ),
    "nan heights": (lambda: _npz(top_z=np.full((30, 50), np.nan, np.float32)), "not finite"),
    "huge image count": (lambda: _npz({"images": 10**30}), "'images' is not an integer"),
    "huge object count": (
        lambda: _npz({"furniture": [_entry(i) for i in range(10_001)]}),
        "more than 10000 objects",
    ),
    "huge seed": (lambda: _npz({"seed": 2**70}), "'seed' is not an integer"),
    "array of another kind": (lambda: _npz(rooms=np.zeros((30, 50), np.int64)), "'rooms' is int64"),
    "arrays of other shapes": (lambda: _npz(rooms=np.zeros((3, 5), np.int16)), "grid's shape"),
    "nested header": (lambda: _npz(b"[" * 100_000 + b"]" * 100_000), "bad header"),
    "other format": (lambda: _npz({"format": "pickle"}), "not a ctxsearch remembered map"),
    "newer version": (lambda: _npz({"version": 3}), "version 3"),
    "version true": (lambda: _npz({"version": True}), "version True"),
    "small not a list": (lambda: _npz({"small": {}}), "'small' is not a list"),
    "check not a table": (lambda: _npz({"checks": [1]}), "a check entry is not a table"),
    "check recall": (lambda: _npz({"checks": [_check(recall=1.5)]}), "out of range"),
    "check outcome": (lambda: _npz({"checks": [_check(still=1)]}), "out of range"),
    "check age 0": (lambda: _npz({"checks": [_check(age=0)]}), "'age' is not an integer"),
    "seen after the map": (
        lambda: _npz({"small": [_entry(3, type="Cup", day=9)]}),
        "last seen after the map's day",
    ),
    "bomb": (_bomb, "array 'floor' is too large"),
}


@pytest.mark.parametrize("kind", sorted(HOSTILE))
def test_hostile_bytes_are_refused_in_one_line_naming_where(kind):
    make, match = HOSTILE[kind]
    data = make()
    tracemalloc.start()
    try:
        with pytest.raises(HomeMapError, match=match) as err:
            HomeMap.from_bytes(data, "somewhere/kb.sqlite: home map x/1 day 0")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    one_line(err.value, "somewhere/kb.sqlite: home map x/1 day 0: remembered map: ")
    assert isinstance(err.value, CtxsearchError) and isinstance(err.value, ValueError)
    assert peak < 40 * 2**20, peak  # the bomb (64 MB unpacked) was never unpacked


def test_unknown_types_are_named_once_and_escaped():
    m = make_map(types=("Bed", "Unicorn\n\x1b[2J"))
    with pytest.raises(HomeMapError, match="unknown type 'Unicorn") as err:
        check_types(m, ["Bed", "Sofa"], "w")
    one_line(err.value, "w: remembered map: ")
    assert check_types(make_map(), ["Bed", "Sofa"], "w").style == "apartment"


# ---- the store: writing and reading -------------------------------------------------------------
def _visit(store, m: HomeMap, run="r1", contents=((0, "Bed", 1),), status="done"):
    store.mark_room(run, m.style, m.seed, status, end_time=5.0, day=m.day, contents=contents,
                    home_map=m)  # fmt: skip


def test_the_store_writes_a_visits_map_and_reads_it_back(tmp_path, catalog):
    path = tmp_path / "kb.sqlite"
    m = make_map(seed=4, day=2)
    with EvidenceStore.open(path, catalog) as s:
        assert s.version == SCHEMA_VERSION == 7
        assert s.home_maps() == [] and s.home_map("apartment", 4) is None
        s.mark_room("r1", "apartment", 4, "started", day=2)
        _visit(s, m)
        assert s.room_status("r1", "apartment", 4, day=2) == "done"
        assert s.room_context().n == {"Bed": 1}  # the contents in the same write
    with EvidenceStore.open(path, catalog, read_only=True) as s:
        assert s.home_maps() == [("r1", "apartment", 4, 2)]
        assert s.home_maps(run="r2") == []
        got = s.home_map("apartment", 4)
        assert got is not None and same(got, m)
        assert same(s.home_map("apartment", np.int64(4), run="r1", upto_day=2), m)
        assert s.home_map("apartment", 4, upto_day=1) is None
        assert s.home_map("apartment", 5) is None and s.home_map("office", 4) is None
        assert s.home_map("apartment", 4, run="r2") is None
        with pytest.raises(CtxsearchError, match="upto_day must be an integer"):
            s.home_map("apartment", 4, upto_day=1.5)


def test_the_latest_day_is_read_ties_by_run_name(tmp_path, catalog):
    path = tmp_path / "kb.sqlite"
    with EvidenceStore.open(path, catalog) as s:
        for run, day, images in (("r1", 0, 10), ("r1", 3, 13), ("r0", 3, 3), ("r2", 5, 25)):
            _visit(s, make_map(day=day, images=images), run=run)
        _visit(s, make_map(seed=2, day=9, images=99), run="r1")  # another world
        assert s.home_maps() == [("r0", "apartment", 1, 3), ("r1", "apartment", 1, 0),
                                 ("r1", "apartment", 1, 3), ("r1", "apartment", 2, 9),
                                 ("r2", "apartment", 1, 5)]  # fmt: skip
        assert s.home_maps("r1") == [("r1", "apartment", 1, 0), ("r1", "apartment", 1, 3),
                                     ("r1", "apartment", 2, 9)]  # fmt: skip
        assert s.home_map("apartment", 1).images == 25
        assert s.home_map("apartment", 1, upto_day=4).images == 3  # day 3: r0 before r1
        assert s.home_map("apartment", 1, run="r1").images == 13
        assert s.home_map("apartment", 1, run="r1", upto_day=2).images == 10
        assert s.home_map("apartment", 1, upto_day=-1) is None


def test_a_visit_keeps_the_map_it_was_first_given(tmp_path, catalog):
    with EvidenceStore.open(tmp_path / "kb.sqlite", catalog) as s:
        _visit(s, make_map(images=1))
        _visit(s, make_map(images=2, types=("Desk",)), contents=[(0, "Desk", 1)])
        s.mark_room("r1", "apartment", 1, "started")  # a late writer: done stays done
        assert s.home_map("apartment", 1).images == 1
        assert s.conn.execute("SELECT COUNT(*) FROM home_maps").fetchone()[0] == 1
        assert s.room_context().n == {"Bed": 1}  # nothing counts twice
        _visit(s, make_map(images=3), run="r2")  # another run: its own map
        assert s.home_maps() == [("r1", "apartment", 1, 0), ("r2", "apartment", 1, 0)]


REFUSED = {
    "started": (lambda: make_map(), "started", "only with a visit marked 'done'"),
    "other style": (lambda: make_map(style="office"), "done", "map is of office/1 day 0"),
    "other seed": (lambda: make_map(seed=2), "done", "map is of apartment/2 day 0"),
    "other day": (lambda: make_map(day=1), "done", "map is of apartment/1 day 1"),
    "unknown type": (lambda: make_map(types=("Bed", "Unicorn")), "done", "unknown type 'Unicorn'"),
    "not a map": (lambda: make_map().to_bytes(), "done", "home_map must be a HomeMap"),
}


@pytest.mark.parametrize("kind", sorted(REFUSED))
def test_a_refused_map_writes_nothing(tmp_path, catalog, kind):
    make, status, match = REFUSED[kind]
    path = tmp_path / "kb.sqlite"
    with EvidenceStore.open(path, catalog) as s:
        _visit(s, make_map(seed=7))
        s.mark_room("r1", "apartment", 1, "started")
        before = rows(s)
        with pytest.raises(CtxsearchError, match=match) as err:
            s.mark_room("r1", "apartment", 1, status, end_time=3.0, contents=[(0, "Bed", 1)],
                        home_map=make())  # fmt: skip
        one_line(err.value, "")
        assert rows(s) == before
        assert s.room_status("r1", "apartment", 1) == "started"
        assert s.home_maps() == [("r1", "apartment", 7, 0)]


def test_a_failure_inside_the_write_loses_the_whole_visit(tmp_path, catalog, monkeypatch):
    with EvidenceStore.open(tmp_path / "kb.sqlite", catalog) as s:
        s.mark_room("r1", "apartment", 1, "started")
        before = rows(s)

        def boom(self, cur, row):
            cur.execute("INSERT INTO home_maps VALUES (?, ?, ?, ?, ?)", row)
            raise RuntimeError("power cut")

        monkeypatch.setattr(EvidenceStore, "_insert_home_map", boom)
        with pytest.raises(RuntimeError, match="power cut"):
            _visit(s, make_map())
        monkeypatch.undo()
        assert rows(s) == before  # no 'done', no contents, no map
        _visit(s, make_map())  # and the store is still usable
        assert s.home_maps() == [("r1", "apartment", 1, 0)]


KILLER = r"""
import os, sys
sys.path.insert(0, sys.argv[2])
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.store import EvidenceStore
from tests.test_home_map import make_map

s = EvidenceStore.open(sys.argv[1], load_catalog())
s.mark_room("r1", "apartment", 1, "done", end_time=1.0, contents=[(0, "Bed", 1)],
            home_map=make_map())
s.mark_room("r1", "apartment", 2, "started")
real = EvidenceStore._insert_home_map

def killed(self, cur, row):  # dies once the second visit's map is written, before its commit
    real(self, cur, row)
    cur.connection.execute("PRAGMA cache_size = 1")
    cur.execute("INSERT INTO home_maps SELECT run, style, seed, day + 1, map FROM home_maps")
    os._exit(9)

EvidenceStore._insert_home_map = killed
s.mark_room("r1", "apartment", 2, "done", end_time=2.0, contents=[(0, "Sofa", 1)],
            home_map=make_map(seed=2))
"""


def test_a_process_killed_while_marking_a_visit_done_loses_only_that_visit(tmp_path, catalog):
    path = tmp_path / "kb.sqlite"
    proc = subprocess.run(
        [sys.executable, "-c", KILLER, str(path), str(ROOT)], capture_output=True, text=True
    )
    assert proc.returncode == 9, proc.stderr
    with EvidenceStore.open(path, catalog, create=False) as s:
        assert s.home_maps() == [("r1", "apartment", 1, 0)]
        assert same(s.home_map("apartment", 1), make_map())
        assert s.room_status("r1", "apartment", 2) == "started"
        assert s.room_context().n == {"Bed": 1}
        _visit(s, make_map(seed=2))
        assert s.home_maps() == [("r1", "apartment", 1, 0), ("r1", "apartment", 2, 0)]


# ---- older stores -------------------------------------------------------------------------------
@pytest.mark.parametrize("version", [1, 2, 3, 4, 5, 6])
def test_an_older_store_has_no_maps_and_gains_the_table_on_its_first_write(
    tmp_path, catalog, version
):
    path = tmp_path / "old.sqlite"
    with EvidenceStore.open(path, catalog) as s:
        s.record(run="r1", style="apartment", room_seed=1, object_id=1, ref_type="Bed",
                 sim_time=0.0, strategy="hif", related=[])  # fmt: skip
        s.mark_room("r1", "apartment", 1, "done", end_time=1.0)
    as_version(path, version)
    before = digest(path)
    assert inspect_store(path, catalog)["schema_version"] == str(version)
    conn = sqlite3.connect(path)
    assert "home_maps" not in {r[0] for r in conn.execute("SELECT name FROM sqlite_master")}
    conn.close()
    for read_only in (True, False):
        with EvidenceStore.open(path, catalog, read_only=read_only) as s:
            assert s.version == version
            assert s.home_maps() == [] and s.home_maps("r1") == []
            assert s.home_map("apartment", 1) is None
    assert digest(path) == before  # reading never migrates
    with EvidenceStore.open(path, catalog) as s:
        _visit(s, make_map(seed=3))
        assert s.version == SCHEMA_VERSION
        assert s.home_maps() == [("r1", "apartment", 3, 0)]
    assert inspect_store(path, catalog)["schema_version"] == str(SCHEMA_VERSION)
    with EvidenceStore.open(path, catalog, read_only=True) as s:
        assert same(s.home_map("apartment", 3), make_map(seed=3))
        assert [e.object_id for e in s.examinations()] == [1]


def test_a_store_whose_maps_table_does_not_fit_its_version_is_refused_untouched(tmp_path, catalog):
    v6 = tmp_path / "v6.sqlite"  # a version-6 store with a home_maps table
    with EvidenceStore.open(v6, catalog) as s:
        _visit(s, make_map())
    _set(v6, "UPDATE meta SET value = '6' WHERE key = 'schema_version'")
    v7 = tmp_path / "v7.sqlite"  # a version-7 store without one
    EvidenceStore.open(v7, catalog).close()
    _set(v7, "DROP TABLE home_maps")
    v7b = tmp_path / "v7b.sqlite"  # a version-7 store whose maps are not BLOB NOT NULL
    EvidenceStore.open(v7b, catalog).close()
    _set(v7b, "ALTER TABLE home_maps DROP COLUMN map")
    for path, match in ((v6, "unexpected (table|index) '.*home_maps"),
                        (v7, r"missing \['home_maps'\]"), (v7b, "'home_maps' is not as")):  # fmt: skip
        before = digest(path)
        with pytest.raises(StoreError, match=match) as err:
            EvidenceStore.open(path, catalog)
        one_line(err.value, str(path))
        assert digest(path) == before


# ---- damaged rows -------------------------------------------------------------------------------
def _set(path: Path, sql: str, *args, unchecked: bool = False) -> None:
    conn = sqlite3.connect(path)
    if unchecked:
        conn.execute("PRAGMA ignore_check_constraints = 1")
    with conn:
        conn.execute(sql, args)
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    conn.close()


def _garbage(kind: str) -> tuple[str, tuple, type, str]:
    """(SQL, arguments, error, what it says) of one damaged home_maps row."""
    upd = "UPDATE home_maps SET map = ?"
    if kind == "too large":
        return "UPDATE home_maps SET map = zeroblob(64 * 1024 * 1024 + 1)", (), StoreError, "larger"
    value, error, says = {
        "random bytes": (np.random.default_rng(1).bytes(900), HomeMapError, "unreadable"),
        "truncated": (make_map().to_bytes()[:500], HomeMapError, "unreadable"),
        "text": ("a map", StoreError, "is text, not a blob"),
        "integer": (7, StoreError, "is integer, not a blob"),
        "another world's map": (make_map(seed=2).to_bytes(), StoreError, "map of apartment/2"),
        "unknown type": (make_map(types=("Unicorn",)).to_bytes(), HomeMapError, "'Unicorn'"),
        "bomb": (_bomb(), HomeMapError, "too large"),
    }[kind]
    return upd, (value,), error, says


@pytest.mark.parametrize(
    "kind",
    ["random bytes", "truncated", "text", "integer", "too large", "another world's map",
     "unknown type", "bomb"],
)  # fmt: skip
def test_a_damaged_map_row_is_a_one_line_error_naming_the_store(tmp_path, catalog, kind):
    path = tmp_path / "kb.sqlite"
    with EvidenceStore.open(path, catalog) as s:
        _visit(s, make_map())
    sql, args, error, says = _garbage(kind)
    _set(path, sql, *args)
    before = digest(path)
    with EvidenceStore.open(path, catalog, read_only=True) as s:
        assert s.home_maps() == [("r1", "apartment", 1, 0)]  # the key is fine
        with pytest.raises(error, match=says) as err:
            s.home_map("apartment", 1)
        assert isinstance(err.value, CtxsearchError)
        msg = one_line(err.value, f"{path}: ")
        assert "home map apartment/1 day 0" in msg
        assert s.home_map("apartment", 1, upto_day=-1) is None
    out = tmp_path / "out.sqlite"  # merging it is refused too, nothing written
    with pytest.raises(CtxsearchError) as err:
        merge_stores(out, [path], catalog)
    one_line(err.value, f"{path}: ")
    assert not out.exists() and digest(path) == before


@pytest.mark.parametrize("day", ["-5", "'tomorrow'", "2.5", str(2**62)])
def test_a_bad_day_stamp_on_a_map_is_refused_by_every_command_untouched(
    tmp_path, catalog, capsys, day
):
    path = tmp_path / "kb.sqlite"
    with EvidenceStore.open(path, catalog) as s:
        _visit(s, make_map())
    _set(path, f"UPDATE home_maps SET day = {day}", unchecked=True)
    before = digest(path)
    with pytest.raises(StoreError, match="home map of 'apartment'/1: day .* is not a day"):
        EvidenceStore.open(path, catalog, read_only=True)
    for argv in (["kb", "stats", str(path)], ["kb", "show", str(path)],
                 ["kb", "merge", str(tmp_path / "out.sqlite"), str(path)]):  # fmt: skip
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err, err
        assert "kb.sqlite: damaged knowledge store: home map of" in err
    assert digest(path) == before and not (tmp_path / "out.sqlite").exists()


# ---- merging ------------------------------------------------------------------------------------
def test_merge_keeps_the_first_map_of_each_visit(tmp_path, catalog):
    a, b, c, old = (tmp_path / f"{n}.sqlite" for n in ("a", "b", "c", "old"))
    with EvidenceStore.open(a, catalog) as s:
        _visit(s, make_map(images=1))
        _visit(s, make_map(day=2, images=2))
    with EvidenceStore.open(b, catalog) as s:
        _visit(s, make_map(images=10))  # the same visit as a's day 0: a's is kept
        _visit(s, make_map(images=11), run="rb")
    with EvidenceStore.open(old, catalog) as s:
        s.mark_room("r9", "apartment", 1, "done")
    as_version(old, 6)
    out = tmp_path / "out.sqlite"
    merge_stores(out, [a, b, old], catalog)
    with EvidenceStore.open(out, catalog, read_only=True) as s:
        assert s.home_maps() == [("r1", "apartment", 1, 0), ("r1", "apartment", 1, 2),
                                 ("rb", "apartment", 1, 0)]  # fmt: skip
        assert s.home_map("apartment", 1, run="r1", upto_day=0).images == 1
        assert s.home_map("apartment", 1).images == 2
        assert s.home_map("apartment", 1, run="rb").images == 11
        assert s.room_status("r9", "apartment", 1) == "done"
        assert same(s.home_map("apartment", 1, run="r1"), make_map(day=2, images=2))
    with EvidenceStore.open(c, catalog) as s:  # into an existing output: its own map stays
        _visit(s, make_map(day=2, images=30))
        _visit(s, make_map(day=3, images=31))
    merge_stores(out, [c], catalog)
    with EvidenceStore.open(out, catalog, read_only=True) as s:
        assert s.home_map("apartment", 1, upto_day=2).images == 2
        assert s.home_map("apartment", 1).images == 31
    merge_stores(old, [a], catalog)  # a version-6 output is upgraded and gains the maps
    with EvidenceStore.open(old, catalog, read_only=True) as s:
        assert s.version == SCHEMA_VERSION and len(s.home_maps()) == 2


def test_merge_reads_an_input_a_running_robot_upgraded_with_its_maps(tmp_path, catalog):
    """The input's main file is version 6; a robot writing it has upgraded it and written a
    map in its WAL (not checkpointed yet): the merge reads the snapshot's version, not the
    main file's, and loses no map."""
    a = tmp_path / "a.sqlite"
    with EvidenceStore.open(a, catalog) as s:
        s.mark_room("r1", "apartment", 1, "done", contents=[(0, "Bed", 1)])
    as_version(a, 6)
    with EvidenceStore.open(a, catalog) as robot:
        _visit(robot, make_map(seed=2))
        assert Path(f"{a}-wal").exists()
        assert inspect_store(a, catalog)["schema_version"] == "6"  # the main file's
        out = tmp_path / "out.sqlite"
        merge_stores(out, [a], catalog)
    with EvidenceStore.open(out, catalog, read_only=True) as s:
        assert s.home_maps() == [("r1", "apartment", 2, 0)]
        assert same(s.home_map("apartment", 2), make_map(seed=2))
