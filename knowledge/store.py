"""The evidence store: learned knowledge as an append-only SQLite log of examinations.

One row per examination (run, room style and seed, object id, reference type, simulated time,
strategy) and one row per observed (relation, related type, related object id); the counts of the
knowledge base, hence its intervals, are rebuilt from this log, so runs resume, stores from several
robots merge (``merge_stores``), and the same evidence can be re-read with another alpha.

Tables (schema version 2)::

    meta          (key TEXT PRIMARY KEY, value TEXT)   app='ctxsearch', schema_version,
                                                       catalog_fingerprint, catalog_path, alpha,
                                                       created
    rooms         (run, style, seed, status, end_time) status 'started' | 'done';
                                                       end_time: the run's simulated clock when
                                                       the room was done (NULL if not recorded);
                                                       PRIMARY KEY (run, style, seed)
    examinations  (id INTEGER PRIMARY KEY, run, style, room_seed, object_id, type, sim_time,
                   strategy, created)
    observations  (examination_id REFERENCES examinations, relation, type, related_id)

Version 1 (no rooms.end_time) is still read: its rooms have no end time. The first write of an
end time (``mark_room(..., end_time=...)``, or a merge into it) upgrades a version-1 store in place
(one transaction: ADD COLUMN, schema_version 2); older ctxsearch then refuses it with its one-line
"newer schema" error. ``examinations()`` reads the log back, examination by examination.

Every examination is written in one transaction (its row and its observation rows). The store
uses SQLite's write-ahead log (journal_mode=WAL, synchronous=NORMAL): a process killed at any
point loses at most the examination in flight (a power cut, at most the last few), commits cost
no fsync, and readers (``ctxsearch kb show``) do not block a running robot. A file that is not a ctxsearch store, has a newer schema, is corrupt, or was built on a
different catalog (relation volumes decide what the counts mean) is refused with a one-line
StoreError after a read-only check: the file is never modified when opening fails.

Stdlib only (``sqlite3``); no pickles.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import os
import sqlite3
import time
import urllib.parse
from collections import defaultdict
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from knowledge import intervals
from knowledge.base import KnowledgeBase
from knowledge.catalog import Catalog
from knowledge.errors import CtxsearchError, StoreError

SCHEMA_VERSION = 2
APP = "ctxsearch"
ROOM_STATUSES = ("started", "done")
_SQLITE_MAGIC = b"SQLite format 3\x00"
_TABLES = ("meta", "rooms", "examinations", "observations")

_SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE rooms (
    run TEXT NOT NULL, style TEXT NOT NULL, seed INTEGER NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('started', 'done')),
    end_time REAL,
    PRIMARY KEY (run, style, seed)
);
CREATE TABLE examinations (
    id INTEGER PRIMARY KEY,
    run TEXT NOT NULL, style TEXT NOT NULL, room_seed INTEGER NOT NULL,
    object_id INTEGER NOT NULL, type TEXT NOT NULL,
    sim_time REAL NOT NULL, strategy TEXT NOT NULL, created REAL NOT NULL
);
CREATE INDEX examinations_room ON examinations (run, style, room_seed);
CREATE TABLE observations (
    examination_id INTEGER NOT NULL REFERENCES examinations (id),
    relation TEXT NOT NULL, type TEXT NOT NULL, related_id INTEGER NOT NULL
);
CREATE INDEX observations_pair ON observations (relation, type, examination_id);
"""

_EXAM_COLS = "run, style, room_seed, object_id, type, sim_time, strategy, created"


def _not_a_store(path: Path, why: str = "") -> StoreError:
    return StoreError(f"{path}: not a ctxsearch knowledge store" + (f" ({why})" if why else ""))


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
    line, starting with the path) otherwise; the file is not modified.
    """
    path = Path(path)
    if not path.exists():
        raise StoreError(f"{path}: no such knowledge store")
    if not path.is_file():
        raise _not_a_store(path, "not a regular file")
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
    # normal read-only connection, which applies the WAL. A hot rollback journal (not ours: stores
    # use WAL) needs a read-write connection, which rolls it back to the last committed state.
    journal = Path(str(path) + "-journal")
    if journal.exists() and journal.stat().st_size > 0:
        connects = [lambda: sqlite3.connect(str(path))]
    else:
        connects = [lambda: sqlite3.connect(_ro_uri(path) + "&immutable=1", uri=True)]
        if Path(str(path) + "-wal").exists():
            connects.append(lambda: sqlite3.connect(_ro_uri(path), uri=True))
    for i, connect in enumerate(connects):
        try:
            meta = _read_meta(connect(), path)
            break
        except (sqlite3.DatabaseError, _Corrupt) as exc:
            if i + 1 < len(connects):
                continue
            if isinstance(exc, _Corrupt):
                raise StoreError(str(exc)) from None
            raise StoreError(
                f"{path}: corrupt or unreadable knowledge store ({_one_line(exc)})"
            ) from None
    if catalog is not None and meta["catalog_fingerprint"] != catalog.fingerprint:
        raise StoreError(
            f"{path}: built on catalog fingerprint {meta['catalog_fingerprint']} "
            f"({meta.get('catalog_path', 'unknown file')}), but the catalog in use ({catalog.path}) "
            f"has fingerprint {catalog.fingerprint}; use the catalog the store was built with"
        )
    return meta


def _read_meta(conn: sqlite3.Connection, path: Path) -> dict[str, str]:
    """The meta table of an open connection, validated; closes the connection."""
    try:
        tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if "meta" not in tables:
            raise _not_a_store(path, "no meta table")
        try:
            meta = {str(k): str(v) for k, v in conn.execute("SELECT key, value FROM meta")}
        except sqlite3.OperationalError:
            raise _not_a_store(path, "unexpected meta table") from None
        if meta.get("app") != APP:
            raise _not_a_store(path)
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
            raise StoreError(
                f"{path}: damaged knowledge store (missing {missing or 'meta entries'})"
            )
        check = conn.execute("PRAGMA quick_check").fetchone()[0]
        if check != "ok":
            raise _Corrupt(
                f"{path}: corrupt knowledge store (sqlite quick_check: {_one_line(check)})"
            )
        return meta
    finally:
        conn.close()


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


def _has_end_time(conn: sqlite3.Connection) -> bool:
    """True when the rooms table has the end_time column (schema version 2)."""
    return any(r[1] == "end_time" for r in conn.execute("PRAGMA table_info(rooms)"))


def _upgrade(cur: sqlite3.Cursor) -> None:
    """Bring a version-1 store to version 2 inside the caller's transaction."""
    if not _has_end_time(cur.connection):
        cur.execute("ALTER TABLE rooms ADD COLUMN end_time REAL")
        cur.execute(
            "UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(SCHEMA_VERSION),)
        )


class _Corrupt(Exception):
    """quick_check found damage (maybe only seen through an immutable read of a live store)."""


class EvidenceStore:
    """An open evidence store. Use ``EvidenceStore.open(...)``, as a context manager or ``close()``."""

    def __init__(
        self, conn: sqlite3.Connection, path: Path, catalog: Catalog, alpha: float, meta: dict
    ):
        self._conn: sqlite3.Connection | None = conn
        self.path = path
        self.catalog = catalog
        self.alpha = alpha
        self.meta = dict(meta)
        self._end_time = _has_end_time(conn)  # schema 2; a version-1 store is upgraded on demand
        if self._end_time:  # an immutable read of the main file may predate an upgrade in the WAL
            self.meta["schema_version"] = str(SCHEMA_VERSION)

    # ---- opening ------------------------------------------------------------------------------
    @classmethod
    def open(
        cls, path: str | Path, catalog: Catalog, alpha: float | None = None, create: bool = True
    ) -> EvidenceStore:
        """Open the store at ``path`` (creating it unless ``create=False``).

        A new store records the catalog's fingerprint and ``alpha`` (default 0.10). An existing
        store must have been built on the same catalog; its stored alpha is the default for
        ``knowledge_base()`` unless ``alpha`` is given (the file's alpha is not changed).
        """
        path = Path(path)
        if alpha is not None:
            alpha = _check_alpha(alpha)
        if not path.exists():
            if not create:
                raise StoreError(f"{path}: no such knowledge store")
            _create(path, catalog, intervals.DEFAULT_ALPHA if alpha is None else alpha)
        meta = inspect_store(path, catalog)
        conn = _connect(path)
        return cls(conn, path, catalog, float(meta["alpha"]) if alpha is None else alpha, meta)

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
        """Append one examination and its observations in one transaction; returns its id.

        ``related`` lists (relation, related type, related object id) for every object found in
        one of the examined object's relation volumes (the same pair may appear for several
        objects: the counts treat it as "at least one"). Everything is validated against the
        catalog before anything is written (CtxsearchError).
        """
        self.catalog.type(ref_type)
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
            _int(object_id, "object_id"),
            ref_type,
            _float(sim_time, "sim_time"),
            _text(strategy, "strategy"),
            time.time(),
        )
        with self._transaction() as cur:
            cur.execute(
                f"INSERT INTO examinations ({_EXAM_COLS}) VALUES (?, ?, ?, ?, ?, ?, ?, ?)", exam
            )
            eid = int(cur.lastrowid)
            self._insert_observations(cur, eid, rows)
        return eid

    def _insert_observations(
        self, cur: sqlite3.Cursor, eid: int, rows: Sequence[tuple[str, str, int]]
    ) -> None:
        cur.executemany(
            "INSERT INTO observations (examination_id, relation, type, related_id) VALUES (?, ?, ?, ?)",
            [(eid, rel, t, rid) for rel, t, rid in rows],
        )

    def mark_room(
        self, run: str, style: str, seed: int, status: str, end_time: float | None = None
    ) -> None:
        """Set a room's status: 'started' when the robot enters it, 'done' when it is finished;
        ``end_time`` (the run's simulated clock when it was done) replaces the stored one. A
        version-1 store is upgraded in the same transaction when an end time is given."""
        if status not in ROOM_STATUSES:
            raise CtxsearchError(f"room status must be one of {ROOM_STATUSES}, got {status!r}")
        key = (_text(run, "run"), _text(style, "style"), _int(seed, "seed"), status)
        end = None if end_time is None else _float(end_time, "end_time")
        with self._transaction() as cur:
            if end is not None:
                _upgrade(cur)
            if end is not None or self._end_time:
                cur.execute(
                    "INSERT INTO rooms (run, style, seed, status, end_time) VALUES (?, ?, ?, ?, ?) "
                    "ON CONFLICT (run, style, seed) DO UPDATE SET status = excluded.status, "
                    "end_time = excluded.end_time",
                    (*key, end),
                )
            else:
                cur.execute(
                    "INSERT INTO rooms (run, style, seed, status) VALUES (?, ?, ?, ?) "
                    "ON CONFLICT (run, style, seed) DO UPDATE SET status = excluded.status",
                    key,
                )
        if end is not None and not self._end_time:
            self._end_time = True
            self.meta["schema_version"] = str(SCHEMA_VERSION)

    # ---- reading ------------------------------------------------------------------------------
    def room_status(self, run: str, style: str, seed: int) -> str | None:
        """'started', 'done', or None for a room never entered."""
        row = self.conn.execute(
            "SELECT status FROM rooms WHERE run = ? AND style = ? AND seed = ?",
            (run, style, int(seed)),
        ).fetchone()
        return None if row is None else str(row[0])

    def room_end_time(self, run: str, style: str, seed: int) -> float | None:
        """The run's simulated clock when the room was done, or None (not done, not recorded,
        or a version-1 store)."""
        if not self._end_time:
            return None
        row = self.conn.execute(
            "SELECT end_time FROM rooms WHERE run = ? AND style = ? AND seed = ?",
            (run, style, int(seed)),
        ).fetchone()
        return None if row is None or row[0] is None else float(row[0])

    def examinations(self, run: str | None = None) -> Iterator[Examination]:
        """Every examination of the log (of one run, or all) in log order, each with its
        observation rows in the order they were written. The observations of the selected
        examinations are read first, the examinations then streamed; do not write to the store
        while iterating."""
        exams = "SELECT id, run, style, room_seed, object_id, type, sim_time, strategy FROM examinations"
        obs = "SELECT examination_id, relation, type, related_id FROM observations"
        args: tuple = ()
        if run is not None:
            exams += " WHERE run = ?"
            obs += " WHERE examination_id IN (SELECT id FROM examinations WHERE run = ?)"
            args = (run,)
        related: dict[int, list[tuple[str, str, int]]] = defaultdict(list)
        for eid, rel, t, rid in self.conn.execute(obs + " ORDER BY rowid", args):
            related[int(eid)].append((str(rel), str(t), int(rid)))
        for i, r, st, seed, oid, t, sim, strategy in self.conn.execute(
            exams + " ORDER BY id", args
        ):
            yield Examination(
                int(i),
                str(r),
                str(st),
                int(seed),
                int(oid),
                str(t),
                float(sim),
                str(strategy),
                tuple(related.pop(int(i), ())),
            )

    def examined(self, run: str, style: str, room_seed: int) -> set[int]:
        """Ids of the objects already examined in that room (to resume without re-examining)."""
        cur = self.conn.execute(
            "SELECT object_id FROM examinations WHERE run = ? AND style = ? AND room_seed = ?",
            (run, style, int(room_seed)),
        )
        return {int(r[0]) for r in cur}

    def examinations_count(self, run: str | None = None) -> int:
        """How many examinations the log holds (of one run, or in all)."""
        if run is None:
            return int(self.conn.execute("SELECT COUNT(*) FROM examinations").fetchone()[0])
        return int(
            self.conn.execute("SELECT COUNT(*) FROM examinations WHERE run = ?", (run,)).fetchone()[
                0
            ]
        )

    def runs(self) -> list[str]:
        """The names of the runs with an examination or a room, sorted."""
        cur = self.conn.execute(
            "SELECT run FROM examinations UNION SELECT run FROM rooms ORDER BY 1"
        )
        return [str(r[0]) for r in cur]

    def rooms(self, run: str | None = None) -> list[tuple[str, str, int, str]]:
        """(run, style, seed, status) of every room entered (of one run, or all), sorted."""
        sql = "SELECT run, style, seed, status FROM rooms"
        args: tuple = ()
        if run is not None:
            sql, args = sql + " WHERE run = ?", (run,)
        return [
            (str(a), str(b), int(c), str(d))
            for a, b, c, d in self.conn.execute(sql + " ORDER BY 1, 2, 3", args)
        ]

    def knowledge_base(
        self, alpha: float | None = None, *, run: str | None = None
    ) -> KnowledgeBase:
        """The counts rebuilt from the log (of one run, or all), as a KnowledgeBase.

        n_A = examinations of type A; y_{rel,B} = examinations with at least one observation row
        (rel, B). ``alpha`` defaults to the store's.
        """
        kb = KnowledgeBase(self.catalog, self.alpha if alpha is None else _check_alpha(alpha))
        where, args = ("", ()) if run is None else (" WHERE run = ?", (run,))
        n = {
            str(t): int(c)
            for t, c in self.conn.execute(
                f"SELECT type, COUNT(*) FROM examinations{where} GROUP BY type", args
            )
        }
        if run is None:
            sql = "SELECT relation, type, COUNT(DISTINCT examination_id) FROM observations GROUP BY relation, type"
        else:
            sql = (
                "SELECT o.relation, o.type, COUNT(DISTINCT o.examination_id) FROM observations o "
                "JOIN examinations e ON e.id = o.examination_id WHERE e.run = ? GROUP BY o.relation, o.type"
            )
        ys: dict[str, dict[tuple[str, str], int]] = defaultdict(dict)
        for rel, t, c in self.conn.execute(sql, args):
            if not self.catalog.has_relation(rel) or t not in self.catalog:
                raise StoreError(f"{self.path}: observation ({rel}, {t}) is not in the catalog")
            ys[self.catalog.relation(rel).ref][(str(rel), str(t))] = int(c)
        for t in set(n) | set(ys):
            if t not in self.catalog:
                raise StoreError(f"{self.path}: examined type {t!r} is not in the catalog")
            try:
                kb.add_counts(t, n.get(t, 0), ys.get(t, {}))
            except CtxsearchError as exc:
                raise StoreError(f"{self.path}: inconsistent log: {exc}") from None
        return kb

    # ---- internals ----------------------------------------------------------------------------
    @contextlib.contextmanager
    def _transaction(self):
        cur = self.conn.cursor()
        cur.execute("BEGIN IMMEDIATE")
        try:
            yield cur
        except BaseException:
            cur.execute("ROLLBACK")
            raise
        else:
            cur.execute("COMMIT")
        finally:
            cur.close()


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
            for stmt in _SCHEMA.split(";"):
                if stmt.strip():
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


def merge_stores(out_path: str | Path, in_paths: Sequence[str | Path], catalog: Catalog) -> int:
    """Append the logs of ``in_paths`` to the store at ``out_path`` (created if missing).

    Every input must be a store built on ``catalog`` (StoreError naming the file otherwise); all
    inputs are checked before anything is written, and the whole merge is one transaction.
    Examination ids are renumbered; a room marked 'done' in any input is 'done' in the output,
    with the first end time any of them recorded. A version-1 output is upgraded to version 2.
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
    if out_path.exists() and out_path.resolve() in seen:
        raise StoreError(f"{out_path}: the output is also an input")
    new_out = not out_path.exists()
    store = EvidenceStore.open(
        out_path, catalog, alpha=float(metas[0]["alpha"]) if new_out else None
    )
    appended = 0
    try:
        with store, store._transaction() as cur:
            _upgrade(cur)
            for p in ins:
                src = _connect(p)
                try:
                    src.execute("BEGIN")  # one snapshot of the input, even if a robot is writing it
                    offset = int(
                        cur.execute("SELECT COALESCE(MAX(id), 0) FROM examinations").fetchone()[0]
                    )
                    rows = src.execute(f"SELECT id, {_EXAM_COLS} FROM examinations ORDER BY id")
                    while batch := rows.fetchmany(10_000):
                        cur.executemany(
                            f"INSERT INTO examinations (id, {_EXAM_COLS}) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                            [(r[0] + offset, *r[1:]) for r in batch],
                        )
                        appended += len(batch)
                    rows = src.execute(
                        "SELECT examination_id, relation, type, related_id FROM observations ORDER BY rowid"
                    )
                    while batch := rows.fetchmany(50_000):
                        cur.executemany(
                            "INSERT INTO observations (examination_id, relation, type, related_id) VALUES (?, ?, ?, ?)",
                            [(r[0] + offset, *r[1:]) for r in batch],
                        )
                    end = "end_time" if _has_end_time(src) else "NULL"
                    cur.executemany(
                        "INSERT INTO rooms (run, style, seed, status, end_time) VALUES (?, ?, ?, ?, ?) "
                        "ON CONFLICT (run, style, seed) DO UPDATE SET status = "
                        "CASE WHEN rooms.status = 'done' OR excluded.status = 'done' THEN 'done' ELSE 'started' END, "
                        "end_time = COALESCE(rooms.end_time, excluded.end_time)",
                        src.execute(
                            f"SELECT run, style, seed, status, {end} FROM rooms"
                        ).fetchall(),
                    )
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
    if not isinstance(v, str) or not v:
        raise CtxsearchError(f"{what} must be a non-empty string, got {v!r}")
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


def _float(v: object, what: str) -> float:
    try:
        fv = float(v)
    except (TypeError, ValueError):
        raise CtxsearchError(f"{what} must be a number, got {v!r}") from None
    if fv != fv:
        raise CtxsearchError(f"{what} must not be NaN")
    return fv
