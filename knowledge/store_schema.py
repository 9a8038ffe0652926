"""The evidence store's schema: its tables (version 7: version 6 and the robot's remembered map
of each house visit, ``home_maps``) and the older versions it reads, the checks a file passes
before it is opened (``inspect_store``: a ctxsearch store of this catalog, the exact schema its
version writes, sane day stamps), the upgrade of an older store inside the first write's
transaction (``_migrate``), and the connections (read-only ones never write). The store itself is
``knowledge.store``."""

from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import os
import sqlite3
import urllib.parse
from collections.abc import Iterable
from pathlib import Path

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.errors import CtxsearchError, StoreError
from ctxsearch.knowledge.files import InputFileError, regular_file_exists

SCHEMA_VERSION = 7
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
_TABLES = ("meta", "rooms", "examinations", "observations", "views", "room_contents", "home_maps")
# The first version holding each table that not every version has.
_TABLE_SINCE = {"views": 5, "room_contents": 6, "home_maps": 7}

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
# Version 5: what the examination's images could show (knowledge.corrected): per relation of
# the examined type, the expected recall and the false-report rate of every catalog type, in
# catalog order, each as VIEW_SCALE-quantised little-endian uint16 (the catalog's fingerprint,
# which every store carries, fixes the order).
_VIEWS_SQL = """CREATE TABLE views (
    examination_id INTEGER NOT NULL REFERENCES examinations (id),
    relation TEXT NOT NULL,
    recall BLOB NOT NULL, false_rate BLOB NOT NULL,
    PRIMARY KEY (examination_id, relation)
) WITHOUT ROWID"""
VIEW_SCALE = 65535
# Version 6: what a house visit's rooms held (knowledge.room_context): per segment of
# the robot's map at the end of a visit done to the end, how many instances of each type it
# recognized there (a segment is listed only with its types; only segments holding furniture).
_ROOM_CONTENTS_SQL = """CREATE TABLE room_contents (
    run TEXT NOT NULL, style TEXT NOT NULL, room_seed INTEGER NOT NULL,
    day INTEGER NOT NULL CHECK (day >= 0),
    segment INTEGER NOT NULL CHECK (segment >= 0), type TEXT NOT NULL,
    instances INTEGER NOT NULL CHECK (instances >= 1),
    PRIMARY KEY (run, style, room_seed, day, segment, type)
) WITHOUT ROWID"""
# Version 7: the robot's remembered map of a world at the end of a house visit done to the end
# (knowledge.home_map.HomeMap.to_bytes: a pickle-free .npz archive), one per visit, the first
# kept; written with the visit's 'done' and its room contents. A rowid table: its rows are large.
_HOME_MAPS_SQL = """CREATE TABLE home_maps (
    run TEXT NOT NULL, style TEXT NOT NULL, seed INTEGER NOT NULL,
    day INTEGER NOT NULL CHECK (day >= 0),
    map BLOB NOT NULL,
    PRIMARY KEY (run, style, seed, day)
)"""
_EXAM_KEY_INDEX = f"CREATE UNIQUE INDEX examinations_key ON examinations ({', '.join(EXAM_KEY)})"
# The schema this version writes, statement by statement (meta first).
_SCHEMA_STATEMENTS = (
    _META_SQL,
    _ROOMS_SQL,
    _EXAMINATIONS_SQL,
    _EXAM_KEY_INDEX,
    _OBSERVATIONS_SQL,
    _OBSERVATIONS_INDEX,
    _VIEWS_SQL,
    _ROOM_CONTENTS_SQL,
    _HOME_MAPS_SQL,
)
# The schemas of older versions, still read (and upgraded to version 7 on the first write).
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
    4: _SCHEMA_STATEMENTS[:-3],  # without the views table
    5: _SCHEMA_STATEMENTS[:-2],  # without the room_contents table
    6: _SCHEMA_STATEMENTS[:-1],  # without the home_maps table
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
    missing = [t for t in _TABLES if t not in tables and version >= _TABLE_SINCE.get(t, 1)]
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
    tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    for table, seed, what in (("room_contents", "room_seed", "room contents"),
                              ("home_maps", "seed", "home map")):  # fmt: skip
        if table in tables:
            q = f"SELECT style, {seed}, day FROM {table} WHERE {bad} LIMIT 1"
            row = conn.execute(q).fetchone()
            if row is not None:
                return (
                    f"{what} of {row[0]!r}/{row[1]!r}: day {row[2]!r} is not a day in "
                    f"[0, {MAX_DAY}]"
                )
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


class _Corrupt(Exception):
    """quick_check found damage (maybe only seen through an immutable read of a live store)."""


def _migrate(cur: sqlite3.Cursor, version: int) -> int:
    """Bring a store of an older ``version`` to SCHEMA_VERSION inside the caller's transaction:
    version 6 gains the (empty) home_maps table, version 5 that and the (empty) room_contents
    table, version 4 those and the (empty) views table; older ones have their tables rebuilt in
    this version's exact schema, dropping duplicate examinations (same EXAM_KEY: keep the first
    and its observations). Returns how many were dropped. Examinations of older stores have no
    views (knowledge.corrected counts them with recall 1), and their visits no room contents (no
    room context learned from them) and no remembered maps."""
    if version in (4, 5, 6):
        for stmt, since in ((_VIEWS_SQL, 5), (_ROOM_CONTENTS_SQL, 6), (_HOME_MAPS_SQL, 7)):
            if version < since:
                cur.execute(stmt)
        cur.execute(
            "UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(SCHEMA_VERSION),)
        )
        return 0
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
