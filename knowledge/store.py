"""The evidence store: learned knowledge as an append-only SQLite log of examinations.

One row per examination (run, room style and seed, object id, reference type, simulated time,
strategy) and one row per observed (relation, related type, related object id); the counts of the
knowledge base, hence its intervals, are rebuilt from this log, so runs resume, stores from several
robots merge (``merge_stores``), and the same evidence can be re-read with another alpha.

Tables (schema version 4)::

    meta          (key TEXT PRIMARY KEY, value TEXT)   app='ctxsearch', schema_version,
                                                       catalog_fingerprint, catalog_path, alpha,
                                                       created
    rooms         (run, style, seed, day, status,      one row per visit of a world: status
                   end_time)                           'started' | 'done'; end_time: the run's
                                                       simulated clock when the visit was done
                                                       (NULL if not recorded);
                                                       PRIMARY KEY (run, style, seed, day)
    examinations  (id INTEGER PRIMARY KEY, run, style, room_seed, day, object_id, type,
                   sim_time, strategy, created)        UNIQUE (EXAM_KEY): one examination of an
                                                       object per world, day and run
    observations  (examination_id REFERENCES examinations, relation, type, related_id)

The uniqueness key ``EXAM_KEY`` (run, style, room_seed, day, object_id) is what identifies an
examination of a run: a second process learning the same run on the same store cannot add an
examination twice (its write fails with a one-line StoreError and nothing of it is written);
different runs on one store never collide. ``day`` (version 4) is the day of the world's visit
(``learn --days``): a world persists across days (its furniture stays, its small objects are
placed anew every day), so a desk examined yesterday is a new trial today, and still at most one
per day.

Older stores are read as they are: version 1 (no rooms.end_time; its rooms have no end time),
version 2 (no uniqueness key) and version 3 (no day stamps: every examination and visit is of day
0). Reading (``open(..., read_only=True)``: ``kb show``, ``kb stats``, search) never migrates. The
first write to one (``record``, ``mark_room``, a merge into it) upgrades it in place to version 4
in the same transaction as the write: the tables are rebuilt in this version's exact schema
(older rows get day 0) and duplicate examinations (same ``EXAM_KEY``, written by two processes
before version 3) are dropped, keeping the first; a failure anywhere rolls the whole transaction
back, leaving the file as it was. Older ctxsearch then refuses the store with its one-line
"newer schema" error. ``examinations()`` reads the log back, examination by examination.

A store's schema (tables, columns, indexes, triggers, views) must be exactly what this version (or
the older version it claims) writes: anything else, e.g. a trigger that would add evidence on
every append, is refused. Every value read back is checked (types, finite numbers, names in the
catalog) and a bad one is a one-line StoreError naming the store.

Every examination is written in one transaction (its row and its observation rows). The store
uses SQLite's write-ahead log (journal_mode=WAL, synchronous=NORMAL): a process killed at any
point loses at most the examination in flight (a power cut, at most the last few), commits cost
no fsync, and readers (``ctxsearch kb show``) do not block a running robot. A file that is not a ctxsearch store, has a newer schema, is corrupt, or was built on a
different catalog (relation volumes decide what the counts mean) is refused with a one-line
StoreError after a read-only check: the file is never modified when opening fails (a file that
is not ours is only read immutably, its journal is never rolled back), and ``open(...,
read_only=True)`` (``kb show``, ``kb stats``, search) never writes, even in a read-only
directory.

Stdlib only (``sqlite3``); no pickles.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import math
import os
import sqlite3
import time
import urllib.parse
from collections import defaultdict
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.clustered import (
    INTERVAL_METHODS,
    ClusteredIntervals,
    RoomCounts,
    room_counts_from_rows,
)
from ctxsearch.knowledge.errors import CtxsearchError, StoreError
from ctxsearch.knowledge.files import InputFileError, regular_file_exists

SCHEMA_VERSION = 4
APP = "ctxsearch"
ROOM_STATUSES = ("started", "done")
# What identifies an examination of a run: at most one row per key (a UNIQUE index from v3 on;
# the day from v4 on).
EXAM_KEY = ("run", "style", "room_seed", "day", "object_id")
# The last day a store holds (``learn --days`` is at most 10^6): a stamp outside [0, MAX_DAY], or
# not an integer, is a damaged store.
MAX_DAY = 1_000_000
_V3_EXAM_KEY = ("run", "style", "room_seed", "object_id")
_SQLITE_MAGIC = b"SQLite format 3\x00"
_TABLES = ("meta", "rooms", "examinations", "observations")

_META_SQL = "CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)"
_ROOMS_SQL = """CREATE TABLE rooms (
    run TEXT NOT NULL, style TEXT NOT NULL, seed INTEGER NOT NULL,
    day INTEGER NOT NULL DEFAULT 0 CHECK (day >= 0),
    status TEXT NOT NULL CHECK (status IN ('started', 'done')),
    end_time REAL,
    PRIMARY KEY (run, style, seed, day)
)"""
_EXAMINATIONS_SQL = """CREATE TABLE examinations (
    id INTEGER PRIMARY KEY,
    run TEXT NOT NULL, style TEXT NOT NULL, room_seed INTEGER NOT NULL,
    day INTEGER NOT NULL DEFAULT 0 CHECK (day >= 0),
    object_id INTEGER NOT NULL, type TEXT NOT NULL,
    sim_time REAL NOT NULL, strategy TEXT NOT NULL, created REAL NOT NULL
)"""
# The version-3 tables (no day stamps).
_V3_ROOMS_SQL = """CREATE TABLE rooms (
    run TEXT NOT NULL, style TEXT NOT NULL, seed INTEGER NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('started', 'done')),
    end_time REAL,
    PRIMARY KEY (run, style, seed)
)"""
_V3_EXAMINATIONS_SQL = """CREATE TABLE examinations (
    id INTEGER PRIMARY KEY,
    run TEXT NOT NULL, style TEXT NOT NULL, room_seed INTEGER NOT NULL,
    object_id INTEGER NOT NULL, type TEXT NOT NULL,
    sim_time REAL NOT NULL, strategy TEXT NOT NULL, created REAL NOT NULL
)"""
_OBSERVATIONS_SQL = """CREATE TABLE observations (
    examination_id INTEGER NOT NULL REFERENCES examinations (id),
    relation TEXT NOT NULL, type TEXT NOT NULL, related_id INTEGER NOT NULL
)"""
_OBSERVATIONS_INDEX = (
    "CREATE INDEX observations_pair ON observations (relation, type, examination_id)"
)
_EXAM_KEY_INDEX = f"CREATE UNIQUE INDEX examinations_key ON examinations ({', '.join(EXAM_KEY)})"
# The schema this version writes, statement by statement (meta first).
_SCHEMA_STATEMENTS = (
    _META_SQL,
    _ROOMS_SQL,
    _EXAMINATIONS_SQL,
    _EXAM_KEY_INDEX,
    _OBSERVATIONS_SQL,
    _OBSERVATIONS_INDEX,
)
# The schemas of older versions, still read (and upgraded to version 4 on the first write).
_OLD_ROOM_INDEX = "CREATE INDEX examinations_room ON examinations (run, style, room_seed)"
_OLD_SCHEMAS = {
    1: (
        _META_SQL,
        _V3_ROOMS_SQL.replace("    end_time REAL,\n", ""),
        _V3_EXAMINATIONS_SQL,
        _OLD_ROOM_INDEX,
        _OBSERVATIONS_SQL,
        _OBSERVATIONS_INDEX,
    ),
    2: (
        _META_SQL,
        _V3_ROOMS_SQL,
        _V3_EXAMINATIONS_SQL,
        _OLD_ROOM_INDEX,
        _OBSERVATIONS_SQL,
        _OBSERVATIONS_INDEX,
    ),
    3: (
        _META_SQL,
        _V3_ROOMS_SQL,
        _V3_EXAMINATIONS_SQL,
        f"CREATE UNIQUE INDEX examinations_key ON examinations ({', '.join(_V3_EXAM_KEY)})",
        _OBSERVATIONS_SQL,
        _OBSERVATIONS_INDEX,
    ),
}

_EXAM_COLS = "run, style, room_seed, day, object_id, type, sim_time, strategy, created"
# The same columns read from a store older than version 4 (no day stamps: day 0).
_OLD_EXAM_COLS = _EXAM_COLS.replace("day,", "0,")


def _not_a_store(path: Path, why: str = "") -> StoreError:
    return StoreError(f"{path}: not a ctxsearch knowledge store" + (f" ({why})" if why else ""))


def _store_exists(path: Path) -> bool:
    """Whether a store file is at ``path`` (a regular file, or a symlink resolving to one);
    False if nothing is there; a StoreError for anything else: a dangling symlink or a symlink
    loop (a store is never created or written through one), a directory, FIFO or device."""
    try:
        return regular_file_exists(path)
    except InputFileError as exc:
        raise _not_a_store(path, exc.problem) from None


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _ro_uri(path: Path) -> str:
    return "file:" + urllib.parse.quote(str(path.resolve())) + "?mode=ro"


def _check_alpha(alpha: float) -> float:
    try:
        intervals.z_value(float(alpha))
    except (TypeError, ValueError):
        raise CtxsearchError(f"alpha must be a number in (0, 1), got {alpha!r}") from None
    return float(alpha)


def inspect_store(path: str | Path, catalog: Catalog | None = None) -> dict[str, str]:
    """Check, read-only, that ``path`` is a usable ctxsearch store and return its meta table.

    With ``catalog`` the store's catalog fingerprint must equal the catalog's. StoreError (one
    line, starting with the path) otherwise; the file is not modified (nor is a journal or WAL
    beside it).
    """
    path = Path(path)
    if not _store_exists(path):
        raise StoreError(f"{path}: no such knowledge store")
    try:
        with open(path, "rb") as f:
            head = f.read(100)
    except OSError as exc:
        raise StoreError(f"{path}: cannot read ({exc.strerror})") from None
    if not head.startswith(_SQLITE_MAGIC):
        raise _not_a_store(path, "not an SQLite database" if head else "empty file")
    if len(head) < 100:
        raise StoreError(f"{path}: truncated or corrupt knowledge store (shorter than its header)")
    # The meta table never changes after creation and a new store is renamed into place only once
    # checkpointed, so an immutable read of the main file sees it without creating -wal/-shm files
    # beside a file that may not even be ours. Only where a -wal file exists (a writer is running
    # or was killed) can the main file alone be behind or mid-checkpoint: then read through a
    # normal read-only connection, which applies the WAL (only once the immutable read found a
    # ctxsearch store). A hot rollback journal is never ours (stores use WAL): the file is read
    # immutably, to say what it is, and refused; its journal is left alone.
    journal = Path(str(path) + "-journal")
    hot_journal = journal.exists() and journal.stat().st_size > 0
    connects = [lambda: sqlite3.connect(_ro_uri(path) + "&immutable=1", uri=True)]
    if not hot_journal and Path(str(path) + "-wal").exists():
        connects.append(lambda: sqlite3.connect(_ro_uri(path), uri=True))
    for i, connect in enumerate(connects):
        try:
            conn = connect()
            try:
                meta = _check_store(conn, path, quick_check=True)
            finally:
                conn.close()
            break
        except (sqlite3.DatabaseError, _Corrupt) as exc:
            if i + 1 < len(connects):
                continue
            if isinstance(exc, _Corrupt):
                raise StoreError(str(exc)) from None
            raise StoreError(
                f"{path}: corrupt or unreadable knowledge store ({_one_line(exc)})"
            ) from None
    if hot_journal:
        raise StoreError(
            f"{path}: has a hot rollback journal ({journal.name}), which ctxsearch never writes; "
            "refusing to open it (nothing was changed)"
        )
    _check_catalog(path, meta, catalog)
    return meta


def _check_catalog(path: Path, meta: dict[str, str], catalog: Catalog | None) -> None:
    if catalog is not None and meta["catalog_fingerprint"] != catalog.fingerprint:
        raise StoreError(
            f"{path}: built on catalog fingerprint {meta['catalog_fingerprint']} "
            f"({meta.get('catalog_path', 'unknown file')}), but the catalog in use ({catalog.path}) "
            f"has fingerprint {catalog.fingerprint}; use the catalog the store was built with"
        )


def _check_store(conn: sqlite3.Connection, path: Path, *, quick_check: bool) -> dict[str, str]:
    """The meta table of an open connection, validated with the schema (and, with
    ``quick_check``, SQLite's integrity check)."""
    tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    if "meta" not in tables:
        raise _not_a_store(path, "no meta table")
    try:
        meta = {k: v for k, v in conn.execute("SELECT key, value FROM meta")}
    except sqlite3.OperationalError:
        raise _not_a_store(path, "unexpected meta table") from None
    if meta.get("app") != APP:
        raise _not_a_store(path)
    if not all(isinstance(k, str) and isinstance(v, str) for k, v in meta.items()):
        raise StoreError(f"{path}: damaged knowledge store (meta holds a value that is not text)")
    try:
        version = int(meta.get("schema_version", ""))
    except ValueError:
        raise _not_a_store(path, "bad schema_version") from None
    if version > SCHEMA_VERSION:
        raise StoreError(
            f"{path}: store schema version {version} is newer than this ctxsearch supports "
            f"({SCHEMA_VERSION}); upgrade ctxsearch to read it"
        )
    if version < 1:
        raise _not_a_store(path, f"unknown schema version {version}")
    missing = [t for t in _TABLES if t not in tables]
    if missing or "catalog_fingerprint" not in meta or "alpha" not in meta:
        raise StoreError(f"{path}: damaged knowledge store (missing {missing or 'meta entries'})")
    problem = _schema_problem(conn, version)
    if problem:
        raise StoreError(
            f"{path}: refused: its schema is not the one ctxsearch writes for version {version} "
            f"({problem})"
        )
    if version >= 4:
        bad = _bad_day(conn)
        if bad:
            raise StoreError(f"{path}: damaged knowledge store: {bad}")
    try:
        _check_alpha(meta["alpha"])
    except CtxsearchError:
        raise StoreError(
            f"{path}: damaged knowledge store (alpha {meta['alpha']!r} is not a number in (0, 1))"
        ) from None
    if quick_check:
        check = conn.execute("PRAGMA quick_check").fetchone()[0]
        if check != "ok":
            raise _Corrupt(
                f"{path}: corrupt knowledge store (sqlite quick_check: {_one_line(check)})"
            )
    return meta


def _bad_day(conn: sqlite3.Connection) -> str | None:
    """The first day stamp that is not an integer in [0, MAX_DAY] (a row written past the
    CHECK, e.g. with ignore_check_constraints), worded; None if every one is."""
    bad = f"typeof(day) != 'integer' OR day < 0 OR day > {MAX_DAY}"
    row = conn.execute(f"SELECT id, day FROM examinations WHERE {bad} LIMIT 1").fetchone()
    if row is not None:
        return f"examination {row[0]!r}: day {row[1]!r} is not a day in [0, {MAX_DAY}]"
    row = conn.execute(f"SELECT style, seed, day FROM rooms WHERE {bad} LIMIT 1").fetchone()
    if row is not None:
        return f"room {row[0]!r}/{row[1]!r}: day {row[2]!r} is not a day in [0, {MAX_DAY}]"
    return None


def _schema_signature(conn: sqlite3.Connection, names: Iterable[str] | None = None):
    """(objects, structure) of a connection's schema: objects maps (type, name) to (table, SQL
    with whitespace collapsed); structure maps each table and index among ``names`` (default:
    all) to what SQLite reports of its columns, keys and indexes."""
    objects: dict[tuple[str, str], tuple[str, str | None]] = {}
    for typ, name, tbl, sql in conn.execute("SELECT type, name, tbl_name, sql FROM sqlite_master"):
        objects[(str(typ), str(name))] = (
            str(tbl),
            None if sql is None else " ".join(str(sql).split()),
        )
    wanted = None if names is None else set(names)
    structure: dict[str, tuple] = {}
    for (typ, name), _ in sorted(objects.items()):
        if wanted is not None and name not in wanted:
            continue
        q = name.replace('"', '""')
        if typ == "table":
            structure[name] = (
                tuple(conn.execute(f'PRAGMA table_xinfo("{q}")')),
                tuple(sorted(conn.execute(f'PRAGMA foreign_key_list("{q}")'))),
                tuple(sorted(tuple(r[1:]) for r in conn.execute(f'PRAGMA index_list("{q}")'))),
            )
        elif typ == "index":
            structure[name] = tuple(conn.execute(f'PRAGMA index_xinfo("{q}")'))
    return objects, structure


@functools.cache
def _expected_schema(version: int):
    """The schema signature a store of ``version`` has, built in memory from its statements."""
    conn = sqlite3.connect(":memory:")
    try:
        for stmt in _SCHEMA_STATEMENTS if version == SCHEMA_VERSION else _OLD_SCHEMAS[version]:
            conn.execute(stmt)
        return _schema_signature(conn)
    finally:
        conn.close()


def _schema_problem(conn: sqlite3.Connection, version: int) -> str | None:
    """What differs between the connection's schema and the one ``version`` writes, or None.

    Objects (tables, indexes, triggers, views) and their columns, keys and indexes must match;
    for the current version the SQL text too (older stores may carry an ALTER-ed text)."""
    exp_objects, exp_structure = _expected_schema(version)
    objects = {
        (str(t), str(n)): None for t, n in conn.execute("SELECT type, name FROM sqlite_master")
    }
    extra = sorted(set(objects) - set(exp_objects))
    if extra:
        return f"unexpected {extra[0][0]} {extra[0][1]!r}"
    gone = sorted(set(exp_objects) - set(objects))
    if gone:
        return f"no {gone[0][0]} {gone[0][1]!r}"
    got_objects, got_structure = _schema_signature(conn, [n for _t, n in exp_objects])
    for key, (tbl, sql) in sorted(exp_objects.items()):
        got_tbl, got_sql = got_objects[key]
        if got_tbl != tbl or (version == SCHEMA_VERSION and got_sql != sql):
            return f"{key[0]} {key[1]!r} is not as ctxsearch creates it"
    for name, s in sorted(exp_structure.items()):
        if got_structure.get(name) != s:
            return f"{name!r} has other columns, keys or indexes"
    return None


@dataclass(frozen=True)
class NewExamination:
    """An examination to append (``EvidenceStore.append``): the visit (run, style, room seed,
    day), the object and its type, the run clock, the strategy and RELATED-OBJECTS as
    (relation, related type, related object id)."""

    run: str
    style: str
    room_seed: int
    object_id: int
    ref_type: str
    sim_time: float
    strategy: str
    related: tuple[tuple[str, str, int], ...]
    day: int = 0


@dataclass(frozen=True)
class Examination:
    """One examination of the log with its observation rows (``EvidenceStore.examinations``)."""

    id: int
    run: str
    style: str
    room_seed: int
    object_id: int
    type: str  # the examined object's (reference) type
    sim_time: float
    strategy: str
    related: tuple[tuple[str, str, int], ...]  # (relation, related type, related object id)
    day: int = 0  # the day of the world's visit (0 in stores older than version 4)


def _migrate(cur: sqlite3.Cursor, version: int) -> int:
    """Bring a store of an older ``version`` to SCHEMA_VERSION inside the caller's transaction:
    rebuild its tables in this version's exact schema, dropping duplicate examinations (same
    EXAM_KEY: keep the first and its observations). Returns how many were dropped."""
    end = "end_time" if version >= 2 else "NULL"
    cur.execute("DROP INDEX IF EXISTS examinations_room")
    cur.execute("DROP INDEX IF EXISTS examinations_key")
    cur.execute("DROP INDEX IF EXISTS observations_pair")
    for t in ("observations", "examinations", "rooms"):
        cur.execute(f"ALTER TABLE {t} RENAME TO _old_{t}")
    for stmt in _SCHEMA_STATEMENTS[1:]:
        cur.execute(stmt)
    cur.execute(
        "INSERT INTO rooms (run, style, seed, day, status, end_time) "
        f"SELECT run, style, seed, 0, status, {end} FROM _old_rooms"
    )
    keep = f"SELECT MIN(id) FROM _old_examinations GROUP BY {', '.join(_V3_EXAM_KEY)}"
    cur.execute(
        f"INSERT INTO examinations (id, {_EXAM_COLS}) SELECT id, {_OLD_EXAM_COLS} "
        f"FROM _old_examinations WHERE id IN ({keep}) ORDER BY id"
    )
    total = int(cur.execute("SELECT COUNT(*) FROM _old_examinations").fetchone()[0])
    kept = int(cur.execute("SELECT COUNT(*) FROM examinations").fetchone()[0])
    cur.execute(
        "INSERT INTO observations (examination_id, relation, type, related_id) "
        "SELECT examination_id, relation, type, related_id FROM _old_observations "
        "WHERE examination_id IN (SELECT id FROM examinations) ORDER BY rowid"
    )
    for t in ("observations", "examinations", "rooms"):
        cur.execute(f"DROP TABLE _old_{t}")
    cur.execute("UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(SCHEMA_VERSION),))
    return total - kept


class _Corrupt(Exception):
    """quick_check found damage (maybe only seen through an immutable read of a live store)."""


class EvidenceStore:
    """An open evidence store. Use ``EvidenceStore.open(...)``, as a context manager or ``close()``."""

    def __init__(
        self,
        conn: sqlite3.Connection,
        path: Path,
        catalog: Catalog,
        alpha: float,
        meta: dict,
        read_only: bool = False,
    ):
        self._conn: sqlite3.Connection | None = conn
        self.path = path
        self.catalog = catalog
        self.alpha = alpha
        self.meta = dict(meta)
        self.read_only = read_only
        self.version = int(self.meta["schema_version"])  # older ones upgrade on the first write
        self.duplicates_dropped = 0  # by the upgrade of a store older than version 3

    # ---- opening ------------------------------------------------------------------------------
    @classmethod
    def open(
        cls,
        path: str | Path,
        catalog: Catalog,
        alpha: float | None = None,
        create: bool = True,
        read_only: bool = False,
    ) -> EvidenceStore:
        """Open the store at ``path`` (creating it unless ``create=False`` or ``read_only``).

        A new store records the catalog's fingerprint and ``alpha`` (default 0.10). An existing
        store must have been built on the same catalog; its stored alpha is the default for
        ``knowledge_base()`` unless ``alpha`` is given (the file's alpha is not changed). A
        ``read_only`` store is never written (writes are a StoreError), also in a read-only
        directory.
        """
        path = Path(path)
        if alpha is not None:
            alpha = _check_alpha(alpha)
        if not _store_exists(path):
            if not create or read_only:
                raise StoreError(f"{path}: no such knowledge store")
            _create(path, catalog, intervals.DEFAULT_ALPHA if alpha is None else alpha)
        inspect_store(path, catalog)
        conn = _connect_ro(path) if read_only else _connect(path)
        try:  # again through the connection in use: it sees the WAL, the immutable read did not
            meta = _check_store(conn, path, quick_check=False)
            _check_catalog(path, meta, catalog)
        except sqlite3.DatabaseError as exc:
            conn.close()
            raise StoreError(f"{path}: cannot read knowledge store ({_one_line(exc)})") from None
        except BaseException:
            conn.close()
            raise
        return cls(
            conn,
            path,
            catalog,
            float(meta["alpha"]) if alpha is None else alpha,
            meta,
            read_only=read_only,
        )

    def close(self) -> None:
        """Close the connection (idempotent)."""
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def __enter__(self) -> EvidenceStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return (
            f"EvidenceStore({str(self.path)!r}, alpha={self.alpha}, fingerprint={self.fingerprint})"
        )

    @property
    def fingerprint(self) -> str:
        """The catalog fingerprint the store was built on."""
        return self.meta["catalog_fingerprint"]

    @property
    def conn(self) -> sqlite3.Connection:
        """The open connection (StoreError once closed)."""
        if self._conn is None:
            raise StoreError(f"{self.path}: store is closed")
        return self._conn

    # ---- writing ------------------------------------------------------------------------------
    def record(
        self,
        *,
        run: str,
        style: str,
        room_seed: int,
        object_id: int,
        ref_type: str,
        sim_time: float,
        strategy: str,
        related: Iterable[tuple[str, str, int]],
    ) -> int:
        """Append one examination (of day 0) and its observations in one transaction; returns
        its id.

        ``related`` lists (relation, related type, related object id) for every object found in
        one of the examined object's relation volumes (the same pair may appear for several
        objects: the counts treat it as "at least one"). Everything is validated against the
        catalog before anything is written (CtxsearchError). An examination whose EXAM_KEY is
        already in the store (another process learning the same run) is a StoreError and
        nothing is written. ``append`` records one of any day.
        """
        return self.append(
            NewExamination(
                run, style, room_seed, object_id, ref_type, sim_time, strategy, tuple(related)
            )  # fmt: skip
        )

    def append(self, e: NewExamination) -> int:
        """``record`` for an examination of any day (``NewExamination.day``)."""
        run, style, room_seed, object_id, ref_type = (
            e.run,
            e.style,
            e.room_seed,
            e.object_id,
            e.ref_type,
        )
        sim_time, strategy, related = e.sim_time, e.strategy, e.related
        self.catalog.type(ref_type)
        day = _day(e.day)
        rows = []
        for item in related:
            try:
                rel, t, rid = item
            except (TypeError, ValueError):
                raise CtxsearchError(
                    f"related entries must be (relation, type, object id), got {item!r}"
                ) from None
            spec = self.catalog.relation(rel)
            if spec.ref != ref_type:
                raise CtxsearchError(f"relation {rel} is not a relation of {ref_type}")
            self.catalog.type(t)
            rows.append((rel, t, _int(rid, "related object id")))
        exam = (
            _text(run, "run"),
            _text(style, "style"),
            _int(room_seed, "room_seed"),
            day,
            _int(object_id, "object_id"),
            ref_type,
            _float(sim_time, "sim_time"),
            _text(strategy, "strategy"),
            time.time(),
        )
        try:
            with self._transaction() as cur:
                cur.execute(
                    f"INSERT INTO examinations ({_EXAM_COLS}) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    exam,
                )
                eid = int(cur.lastrowid)
                self._insert_observations(cur, eid, rows)
        except sqlite3.IntegrityError:
            raise StoreError(
                f"{self.path}: object {exam[4]} of room {exam[1]}/{exam[2]} is already examined "
                f"in run {exam[0]!r} on day {day}: another process is learning the same run on "
                "this store "
                "(nothing was written; its evidence is kept once)"
            ) from None
        return eid

    def _insert_observations(
        self, cur: sqlite3.Cursor, eid: int, rows: Sequence[tuple[str, str, int]]
    ) -> None:
        cur.executemany(
            "INSERT INTO observations (examination_id, relation, type, related_id) VALUES (?, ?, ?, ?)",
            [(eid, rel, t, rid) for rel, t, rid in rows],
        )

    def mark_room(
        self,
        run: str,
        style: str,
        seed: int,
        status: str,
        end_time: float | None = None,
        day: int = 0,
    ) -> None:
        """Set the status of a room's visit on ``day``: 'started' when the robot enters it (a
        visit already done stays done), 'done' when it is finished; ``end_time`` (the run's
        simulated clock when it was done) replaces the stored one."""
        if status not in ROOM_STATUSES:
            raise CtxsearchError(f"room status must be one of {ROOM_STATUSES}, got {status!r}")
        key = (_text(run, "run"), _text(style, "style"), _int(seed, "seed"), _day(day), status)
        end = None if end_time is None else _float(end_time, "end_time")
        with self._transaction() as cur:
            if end is not None:
                cur.execute(
                    "INSERT INTO rooms (run, style, seed, day, status, end_time) "
                    "VALUES (?, ?, ?, ?, ?, ?) "
                    "ON CONFLICT (run, style, seed, day) DO UPDATE SET status = excluded.status, "
                    "end_time = excluded.end_time",
                    (*key, end),
                )
            else:  # a room done stays done (another writer of the run may have finished it)
                cur.execute(
                    "INSERT INTO rooms (run, style, seed, day, status) VALUES (?, ?, ?, ?, ?) "
                    "ON CONFLICT (run, style, seed, day) DO UPDATE SET status = excluded.status "
                    "WHERE rooms.status != 'done'",
                    key,
                )

    # ---- reading ------------------------------------------------------------------------------
    def _visit(self, day: int) -> tuple[str, tuple]:
        """The WHERE part selecting one day's visit (older stores hold only day 0)."""
        if self.version >= 4:
            return " AND day = ?", (int(day),)
        return ("", ()) if int(day) == 0 else (" AND 0", ())

    def room_status(self, run: str, style: str, seed: int, day: int = 0) -> str | None:
        """'started', 'done', or None for a room never entered (on ``day``)."""
        where, args = self._visit(day)
        with self._reading():
            row = self.conn.execute(
                "SELECT status FROM rooms WHERE run = ? AND style = ? AND seed = ?" + where,
                (run, style, int(seed), *args),
            ).fetchone()
        if row is None:
            return None
        if row[0] not in ROOM_STATUSES:
            raise self._bad(f"room {style}/{seed} of run {run!r} has status {row[0]!r}")
        return str(row[0])

    def room_end_time(self, run: str, style: str, seed: int, day: int = 0) -> float | None:
        """The run's simulated clock when the room's visit on ``day`` was done, or None (not
        done, not recorded, or a version-1 store)."""
        if self.version < 2:
            return None
        where, args = self._visit(day)
        with self._reading():
            row = self.conn.execute(
                "SELECT end_time FROM rooms WHERE run = ? AND style = ? AND seed = ?" + where,
                (run, style, int(seed), *args),
            ).fetchone()
        if row is None or row[0] is None:
            return None
        return self._number(row[0], f"end time of room {style}/{seed}")

    def examinations(self, run: str | None = None) -> Iterator[Examination]:
        """Every examination of the log (of one run, or all) in log order, each with its
        observation rows in the order they were written. The observations of the selected
        examinations are read first, the examinations then streamed; do not write to the store
        while iterating. A row that does not fit the catalog or holds a bad value is a
        StoreError naming the store."""
        day = "day" if self.version >= 4 else "0"
        exams = (
            "SELECT id, run, style, room_seed, object_id, type, sim_time, strategy, "
            f"{day} FROM examinations"
        )
        obs = "SELECT examination_id, relation, type, related_id FROM observations"
        args: tuple = ()
        if run is not None:
            exams += " WHERE run = ?"
            obs += " WHERE examination_id IN (SELECT id FROM examinations WHERE run = ?)"
            args = (run,)
        with self._reading():
            related: dict[int, list[tuple[str, str, int]]] = defaultdict(list)
            for eid, rel, t, rid in self.conn.execute(obs + " ORDER BY rowid", args):
                related[self._integer(eid, "observation examination id")].append(
                    (
                        self._name(rel, "relation"),
                        self._name(t, "observed type"),
                        self._integer(rid, "related object id"),
                    )
                )
            for i, r, st, seed, oid, t, sim, strategy, d in self.conn.execute(
                exams + " ORDER BY id", args
            ):
                i = self._integer(i, "examination id")
                where = f"examination {i}"
                ref = self._name(t, f"{where}: type")
                if ref not in self.catalog:
                    raise self._bad(f"{where}: examined type {ref!r} is not in the catalog")
                rows = tuple(related.pop(i, ()))
                for rel, b, _rid in rows:
                    if not self.catalog.has_relation(rel) or self.catalog.relation(rel).ref != ref:
                        raise self._bad(
                            f"{where}: {rel!r} is not a relation of {ref} in the catalog"
                        )
                    if b not in self.catalog:
                        raise self._bad(f"{where}: observed type {b!r} is not in the catalog")
                yield Examination(
                    i,
                    self._name(r, f"{where}: run"),
                    self._name(st, f"{where}: style"),
                    self._integer(seed, f"{where}: room seed"),
                    self._integer(oid, f"{where}: object id"),
                    ref,
                    self._number(sim, f"{where}: sim_time"),
                    self._name(strategy, f"{where}: strategy"),
                    rows,
                    self._day_stamp(d, f"{where}: day"),
                )

    def examined(self, run: str, style: str, room_seed: int, day: int | None = None) -> set[int]:
        """Ids of the objects already examined in that room (on ``day``, or on any day)."""
        where, args = ("", ()) if day is None else self._visit(day)
        with self._reading():
            cur = self.conn.execute(
                "SELECT object_id FROM examinations WHERE run = ? AND style = ? AND room_seed = ?"
                + where,
                (run, style, int(room_seed), *args),
            )
            return {self._integer(r[0], "object id") for r in cur}

    def examined_before(self, run: str, style: str, room_seed: int, day: int) -> set[int]:
        """Ids of the objects of that room examined in the run on a day before ``day``."""
        if self.version < 4 or day <= 0:
            return self.examined(run, style, room_seed) if day > 0 else set()
        with self._reading():
            cur = self.conn.execute(
                "SELECT object_id FROM examinations WHERE run = ? AND style = ? AND room_seed = ? "
                "AND day < ?",
                (run, style, int(room_seed), int(day)),
            )
            return {self._integer(r[0], "object id") for r in cur}

    def examinations_count(self, run: str | None = None) -> int:
        """How many examinations the log holds (of one run, or in all)."""
        with self._reading():
            if run is None:
                return int(self.conn.execute("SELECT COUNT(*) FROM examinations").fetchone()[0])
            sql = "SELECT COUNT(*) FROM examinations WHERE run = ?"
            return int(self.conn.execute(sql, (run,)).fetchone()[0])

    def runs(self) -> list[str]:
        """The names of the runs with an examination or a room, sorted."""
        with self._reading():
            cur = self.conn.execute(
                "SELECT run FROM examinations UNION SELECT run FROM rooms ORDER BY 1"
            )
            return [self._name(r[0], "run") for r in cur]

    def rooms(self, run: str | None = None) -> list[tuple[str, str, int, str]]:
        """(run, style, seed, status) of every room entered (of one run, or all), sorted; a room
        visited on several days is 'done' once every visit is."""
        sql = "SELECT run, style, seed, MAX(status) FROM rooms"  # 'started' > 'done'
        args: tuple = ()
        if run is not None:
            sql, args = sql + " WHERE run = ?", (run,)
        out = []
        with self._reading():
            for a, b, c, d in self.conn.execute(sql + " GROUP BY 1, 2, 3 ORDER BY 1, 2, 3", args):
                if d not in ROOM_STATUSES:
                    raise self._bad(f"a room of run {a!r} has status {d!r}")
                out.append(
                    (self._name(a, "run"), self._name(b, "style"), self._integer(c, "seed"), d)
                )
        return out

    def visits(self, run: str | None = None) -> list[tuple[str, str, int, int, str]]:
        """(run, style, seed, day, status) of every visit of a room (of one run, or all),
        sorted."""
        day = "day" if self.version >= 4 else "0"
        sql = f"SELECT run, style, seed, {day}, status FROM rooms"
        args: tuple = ()
        if run is not None:
            sql, args = sql + " WHERE run = ?", (run,)
        out = []
        with self._reading():
            for a, b, c, d, st in self.conn.execute(sql + " ORDER BY 1, 2, 3, 4", args):
                if st not in ROOM_STATUSES:
                    raise self._bad(f"a room of run {a!r} has status {st!r}")
                out.append(
                    (
                        self._name(a, "run"),
                        self._name(b, "style"),
                        self._integer(c, "seed"),
                        self._integer(d, "day"),
                        st,
                    )
                )
        return out

    def room_counts(self, run: str | None = None) -> dict[str, RoomCounts]:
        """Per reference type, its examinations and y counts per room (of one run, or all): the
        input of the clustered interval (knowledge.clustered). A room is (style, room seed):
        runs that visit the same room share its cluster. Read-only."""
        where, args = ("", ()) if run is None else (" WHERE run = ?", (run,))
        obs = (
            "SELECT DISTINCT o.examination_id, e.type, e.style, e.room_seed, o.relation, o.type "
            "FROM observations o JOIN examinations e ON e.id = o.examination_id"
            + ("" if run is None else " WHERE e.run = ?")
        )
        with self._reading():
            exam_rows = [
                (self._name(t, "type"), (str(st), int(seed)))
                for t, st, seed in self.conn.execute(
                    f"SELECT type, style, room_seed FROM examinations{where} ORDER BY id", args
                )
            ]
            obs_rows = [
                (self._name(t, "type"), (str(st), int(seed)), str(rel), str(b))
                for _eid, t, st, seed, rel, b in self.conn.execute(obs, args)
            ]
        for _ref, _room, rel, b in obs_rows:
            if not self.catalog.has_relation(rel) or b not in self.catalog:
                raise self._bad(f"observation ({rel!r}, {b!r}) is not in the catalog")
        return room_counts_from_rows(exam_rows, obs_rows)

    def knowledge_base(
        self,
        alpha: float | None = None,
        *,
        run: str | None = None,
        interval: str = "wilson",
    ) -> KnowledgeBase:
        """The counts rebuilt from the log (of one run, or all), as a KnowledgeBase.

        n_A = examinations of type A; y_{rel,B} = examinations with at least one observation row
        (rel, B). ``alpha`` defaults to the store's. ``interval``: 'wilson' (the paper's) or
        'clustered' (its intervals on the room-level effective counts of ``room_counts``; the
        counts and HIF are the same).
        """
        if interval not in INTERVAL_METHODS:
            raise CtxsearchError(
                f"unknown interval method '{interval}' (known: {', '.join(INTERVAL_METHODS)})"
            )
        kb = KnowledgeBase(self.catalog, self.alpha if alpha is None else _check_alpha(alpha))
        if interval == "clustered":
            kb.use_clustered(ClusteredIntervals(self.room_counts(run), kb.alpha))
        where, args = ("", ()) if run is None else (" WHERE run = ?", (run,))
        if run is None:
            sql = "SELECT relation, type, COUNT(DISTINCT examination_id) FROM observations GROUP BY relation, type"
        else:
            sql = (
                "SELECT o.relation, o.type, COUNT(DISTINCT o.examination_id) FROM observations o "
                "JOIN examinations e ON e.id = o.examination_id WHERE e.run = ? GROUP BY o.relation, o.type"
            )
        with self._reading():
            n = {
                t: int(c)
                for t, c in self.conn.execute(
                    f"SELECT type, COUNT(*) FROM examinations{where} GROUP BY type", args
                )
            }
            ys: dict[str, dict[tuple[str, str], int]] = defaultdict(dict)
            for rel, t, c in self.conn.execute(sql, args):
                if not self.catalog.has_relation(rel) or t not in self.catalog:
                    raise self._bad(f"observation ({rel!r}, {t!r}) is not in the catalog")
                ys[self.catalog.relation(rel).ref][(str(rel), str(t))] = int(c)
        for t in set(n) | set(ys):
            if t not in self.catalog:
                raise self._bad(f"examined type {t!r} is not in the catalog")
            try:
                kb.add_counts(t, n.get(t, 0), ys.get(t, {}))
            except CtxsearchError as exc:
                raise self._bad(f"inconsistent log: {exc}") from None
        return kb

    # ---- internals ----------------------------------------------------------------------------
    def _bad(self, what: str) -> StoreError:
        return StoreError(f"{self.path}: damaged knowledge store: {what}")

    def _integer(self, v: object, what: str) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise self._bad(f"{what} {v!r} is not an integer")
        return v

    def _day_stamp(self, v: object, what: str) -> int:
        d = self._integer(v, what)
        if not 0 <= d <= MAX_DAY:
            raise self._bad(f"{what} {d} is not a day in [0, {MAX_DAY}]")
        return d

    def _number(self, v: object, what: str) -> float:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise self._bad(f"{what} {v!r} is not a finite number")
        return float(v)

    def _name(self, v: object, what: str) -> str:
        if not isinstance(v, str) or not v or not v.isprintable():
            raise self._bad(f"{what} {v!r} is not a name")
        return v

    @contextlib.contextmanager
    def _reading(self):
        try:
            yield
        except sqlite3.Error as exc:
            raise StoreError(
                f"{self.path}: cannot read knowledge store ({_one_line(exc)})"
            ) from None

    @contextlib.contextmanager
    def _transaction(self):
        """One write transaction; a store older than SCHEMA_VERSION is upgraded in it first.
        SQLite failures (read-only file, full disk, lock timeout) are a StoreError; a broken
        uniqueness key stays an sqlite3.IntegrityError for the caller to word."""
        if self.read_only:
            raise StoreError(f"{self.path}: opened read-only")
        cur = self.conn.cursor()
        upgraded = dropped = 0
        try:
            cur.execute("BEGIN IMMEDIATE")
            try:
                if self.version < SCHEMA_VERSION:
                    # Another process may have upgraded it since we opened it: ask the file.
                    row = cur.execute(
                        "SELECT value FROM meta WHERE key = 'schema_version'"
                    ).fetchone()
                    if int(row[0]) < SCHEMA_VERSION:
                        dropped = _migrate(cur, int(row[0]))
                    upgraded = 1
                yield cur
            except BaseException:
                with contextlib.suppress(sqlite3.Error):
                    cur.execute("ROLLBACK")
                raise
            cur.execute("COMMIT")
        except sqlite3.IntegrityError:
            raise
        except sqlite3.Error as exc:
            with contextlib.suppress(sqlite3.Error):
                if self.conn.in_transaction:
                    cur.execute("ROLLBACK")
            raise StoreError(
                f"{self.path}: cannot write knowledge store ({_one_line(exc)}); nothing of "
                "this write was stored"
            ) from None
        finally:
            cur.close()
        if upgraded:
            self.version = SCHEMA_VERSION
            self.meta["schema_version"] = str(SCHEMA_VERSION)
            self.duplicates_dropped += dropped


def _connect_ro(path: Path) -> sqlite3.Connection:
    """A read-only connection that never writes nor creates a file: through the WAL where one
    exists (a writer is running), else an immutable read of the main file (which a WAL writer
    starting meanwhile changes only when it checkpoints, after about 4 MB of log)."""
    uri = _ro_uri(path)
    if not Path(str(path) + "-wal").exists():
        uri += "&immutable=1"
    try:
        return sqlite3.connect(uri, uri=True, timeout=30.0, isolation_level=None)
    except sqlite3.Error as exc:
        raise StoreError(f"{path}: cannot open knowledge store ({_one_line(exc)})") from None


def _connect(path: Path) -> sqlite3.Connection:
    try:
        conn = sqlite3.connect(str(path), timeout=30.0, isolation_level=None)
        conn.execute("PRAGMA foreign_keys = ON")
        conn.execute(
            "PRAGMA synchronous = NORMAL"
        )  # WAL: safe against crashes, no fsync per commit
    except sqlite3.DatabaseError as exc:
        raise StoreError(f"{path}: cannot open knowledge store ({_one_line(exc)})") from None
    return conn


def _create(path: Path, catalog: Catalog, alpha: float) -> None:
    """Write a new, empty store at ``path`` atomically (built aside, then renamed into place)."""
    tmp = path.with_name(f".{path.name}.creating-{os.getpid()}")
    created = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    meta = {
        "app": APP,
        "schema_version": str(SCHEMA_VERSION),
        "catalog_fingerprint": catalog.fingerprint,
        "catalog_path": str(catalog.path),
        "alpha": repr(float(alpha)),
        "created": created,
    }
    try:
        conn = sqlite3.connect(str(tmp), isolation_level=None)
        try:
            conn.execute("PRAGMA journal_mode = WAL")  # persistent: every later connection uses it
            conn.execute("BEGIN")
            for stmt in _SCHEMA_STATEMENTS:
                conn.execute(stmt)
            conn.executemany("INSERT INTO meta (key, value) VALUES (?, ?)", sorted(meta.items()))
            conn.execute("COMMIT")
        finally:
            conn.close()
        if path.exists():  # created meanwhile by someone else: use theirs
            tmp.unlink()
            return
        os.replace(tmp, path)
    except (sqlite3.Error, OSError) as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise StoreError(f"{path}: cannot create knowledge store ({_one_line(exc)})") from None
    except BaseException:  # Ctrl-C while creating: leave nothing behind
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def merge_stores(out_path: str | Path, in_paths: Sequence[str | Path], catalog: Catalog) -> int:
    """Append the logs of ``in_paths`` to the store at ``out_path`` (created if missing).

    Every input must be a store built on ``catalog`` (StoreError naming the file otherwise); all
    inputs are checked before anything is written, and the whole merge is one transaction.
    Examination ids are renumbered; a room marked 'done' in any input is 'done' in the output,
    with the first end time any of them recorded. An output older than version 4 is upgraded. An
    examination that is already in the output (same EXAM_KEY) is a StoreError: nothing is merged.
    A new output gets the first input's alpha. Returns the number of examinations appended.
    """
    out_path = Path(out_path)
    ins = [Path(p) for p in in_paths]
    if not ins:
        raise StoreError("merge: no input stores given")
    metas = [inspect_store(p, catalog) for p in ins]
    seen: dict[Path, Path] = {}
    for p in ins:
        r = p.resolve()
        if r in seen:
            raise StoreError(f"{p}: given twice as an input (its evidence would count twice)")
        seen[r] = p
    new_out = not _store_exists(out_path)
    if not new_out and out_path.resolve() in seen:
        raise StoreError(f"{out_path}: the output is also an input")
    store = EvidenceStore.open(
        out_path, catalog, alpha=float(metas[0]["alpha"]) if new_out else None
    )
    appended = 0
    try:
        with store, store._transaction() as cur:
            for p, meta in zip(ins, metas, strict=True):
                src = _connect_ro(p)
                try:
                    src.execute("BEGIN")  # one snapshot of the input, even if a robot is writing it
                    offset = int(
                        cur.execute("SELECT COALESCE(MAX(id), 0) FROM examinations").fetchone()[0]
                    )
                    new_in = int(meta["schema_version"]) >= 4
                    # Duplicates within an input (older than version 3) are read once, the first.
                    key = EXAM_KEY if new_in else _V3_EXAM_KEY
                    keep = f"SELECT MIN(id) FROM examinations GROUP BY {', '.join(key)}"
                    cols = _EXAM_COLS if new_in else _OLD_EXAM_COLS
                    rows = src.execute(
                        f"SELECT id, {cols} FROM examinations WHERE id IN ({keep}) ORDER BY id"
                    )
                    while batch := rows.fetchmany(10_000):
                        cur.executemany(
                            f"INSERT INTO examinations (id, {_EXAM_COLS}) "
                            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                            [(r[0] + offset, *r[1:]) for r in batch],
                        )
                        appended += len(batch)
                    rows = src.execute(
                        "SELECT examination_id, relation, type, related_id FROM observations "
                        f"WHERE examination_id IN ({keep}) ORDER BY rowid"
                    )
                    while batch := rows.fetchmany(50_000):
                        cur.executemany(
                            "INSERT INTO observations (examination_id, relation, type, related_id) VALUES (?, ?, ?, ?)",
                            [(r[0] + offset, *r[1:]) for r in batch],
                        )
                    end = "end_time" if int(meta["schema_version"]) >= 2 else "NULL"
                    day = "day" if new_in else "0"
                    cur.executemany(
                        "INSERT INTO rooms (run, style, seed, day, status, end_time) "
                        "VALUES (?, ?, ?, ?, ?, ?) "
                        "ON CONFLICT (run, style, seed, day) DO UPDATE SET status = "
                        "CASE WHEN rooms.status = 'done' OR excluded.status = 'done' THEN 'done' ELSE 'started' END, "
                        "end_time = COALESCE(rooms.end_time, excluded.end_time)",
                        src.execute(
                            f"SELECT run, style, seed, {day}, status, {end} FROM rooms"
                        ).fetchall(),
                    )
                except sqlite3.IntegrityError:
                    raise StoreError(
                        f"{p}: holds examinations already in {out_path} (same run, room and "
                        "object): merged, they would count twice; nothing was merged"
                    ) from None
                except sqlite3.DatabaseError as exc:
                    raise StoreError(f"{p}: cannot read ({_one_line(exc)})") from None
                finally:
                    src.close()
    except BaseException:
        if new_out:
            with contextlib.suppress(OSError):
                out_path.unlink()
        raise
    return appended


def _text(v: object, what: str) -> str:
    if not isinstance(v, str) or not v or not v.isprintable():
        raise CtxsearchError(f"{what} must be a non-empty printable string, got {v!r}")
    return v


def _int(v: object, what: str) -> int:
    if isinstance(v, bool):
        raise CtxsearchError(f"{what} must be an integer, got {v!r}")
    try:
        iv = int(v)  # numpy integers too
    except (TypeError, ValueError):
        raise CtxsearchError(f"{what} must be an integer, got {v!r}") from None
    if iv != v:
        raise CtxsearchError(f"{what} must be an integer, got {v!r}")
    return iv


def _day(v: object) -> int:
    d = _int(v, "day")
    if not 0 <= d <= MAX_DAY:
        raise CtxsearchError(f"day must be in [0, {MAX_DAY}], got {d}")
    return d


def _float(v: object, what: str) -> float:
    try:
        fv = float(v)
    except (TypeError, ValueError):
        raise CtxsearchError(f"{what} must be a number, got {v!r}") from None
    if fv != fv:
        raise CtxsearchError(f"{what} must not be NaN")
    return fv
