"""The evidence store: learned knowledge as an append-only SQLite log of examinations.

One row per examination (run, room style and seed, object id, reference type, simulated time,
strategy) and one row per observed (relation, related type, related object id); the counts of the
knowledge base, hence its intervals, are rebuilt from this log, so runs resume, stores from several
robots merge (``merge_stores``), and the same evidence can be re-read with another alpha.

Tables (schema version 7)::

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
    views         (examination_id REFERENCES examinations, relation, recall, false_rate)
                                                       version 5: per relation of the examined
                                                       type, what the examination's images could
                                                       show of every catalog type (expected
                                                       recall, false-report rate: uint16 blobs in
                                                       catalog order; knowledge.corrected); none
                                                       for the oracle perception
    room_contents (run, style, room_seed, day, segment, type, instances)
                                                       version 6: per house visit done, per
                                                       segment of the robot's map, how many
                                                       instances of each type it recognized
                                                       there (knowledge.room_context)
    home_maps     (run, style, seed, day, map)         version 7: per house visit done, the
                                                       robot's remembered map of the world
                                                       (knowledge.home_map.HomeMap.to_bytes: a
                                                       pickle-free .npz blob);
                                                       PRIMARY KEY (run, style, seed, day)

The uniqueness key ``EXAM_KEY`` (run, style, room_seed, day, object_id) is what identifies an
examination of a run: a second process learning the same run on the same store cannot add an
examination twice (its write fails with a one-line StoreError and nothing of it is written);
different runs on one store never collide. ``day`` (version 4) is the day of the world's visit
(``learn --days``): a world persists across days (its furniture stays, its small objects stay
or move by their type's stay probability), so a desk examined yesterday is a new trial today, and still at most one
per day.

Older stores are read as they are: version 1 (no rooms.end_time; its rooms have no end time),
version 2 (no uniqueness key) and version 3 (no day stamps: every examination and visit is of day
0), version 4 (no views), version 5 (no room contents) and version 6 (no remembered maps:
``home_map`` is None, ``home_maps`` empty). Reading (``open(..., read_only=True)``: ``kb show``,
``kb stats``, search) never migrates. The first write to one (``record``, ``mark_room``, a merge
into it) upgrades it in place to version 7 in the same transaction as the write: a version-6 store
gains the empty home_maps table, a version-5 store that and the empty room_contents table, a
version-4 store those and the empty views table; older ones have their tables rebuilt in this
version's exact schema (older rows get day 0) and duplicate examinations (same ``EXAM_KEY``,
written by two processes before version 3) are dropped, keeping the first; a failure anywhere
rolls the whole transaction back, leaving the file as it was. Older ctxsearch then refuses the
store with its one-line "newer schema" error. ``examinations()`` reads the log back, examination
by examination; ``home_map(style, seed)`` the latest remembered map of a world.

A store's schema (tables, columns, indexes, triggers, views) must be exactly what this version (or
the older version it claims) writes: anything else, e.g. a trigger that would add evidence on
every append, is refused. Every value read back is checked (types, finite numbers, names in the
catalog) and a bad one is a one-line StoreError naming the store.

Every examination is written in one transaction (its row and its observation rows); a visit's
'done' in one with its room contents and its remembered map (``mark_room``). The store
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
import sqlite3
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.errors import CtxsearchError, StoreError
from ctxsearch.knowledge.home_map import MAX_BYTES as MAX_MAP_BYTES
from ctxsearch.knowledge.home_map import HomeMap, check_types
from ctxsearch.knowledge.store_reads import EvidenceReads, Examination
from ctxsearch.knowledge.store_schema import (
    _EXAM_COLS,
    _OLD_EXAM_COLS,
    _V3_EXAM_KEY,
    EXAM_KEY,
    MAX_DAY,
    ROOM_STATUSES,
    SCHEMA_VERSION,
    VIEW_SCALE,
    _check_alpha,
    _check_catalog,
    _check_store,
    _connect,
    _connect_ro,
    _create,
    _migrate,
    _one_line,
    _store_exists,
    inspect_store,
)

# The store's public names (its schema's and its read records' included: callers import them from
# here).
__all__ = [
    "EXAM_KEY",
    "MAX_DAY",
    "SCHEMA_VERSION",
    "EvidenceStore",
    "Examination",
    "NewExamination",
    "StoreError",
    "inspect_store",
    "merge_stores",
]


@dataclass(frozen=True)
class NewExamination:
    """An examination to append (``EvidenceStore.append``): the visit (run, style, room seed,
    day), the object and its type, the run clock, the strategy, RELATED-OBJECTS as
    (relation, related type, related object id), and what its images could show (``views``:
    (relation, expected recall per catalog type, false-report rate per catalog type), both in
    catalog order and in [0, 1]; empty where unknown: knowledge.corrected)."""

    run: str
    style: str
    room_seed: int
    object_id: int
    ref_type: str
    sim_time: float
    strategy: str
    related: tuple[tuple[str, str, int], ...]
    day: int = 0
    views: tuple[tuple[str, Sequence[float], Sequence[float]], ...] = ()


class EvidenceStore(EvidenceReads):
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
            rel, t, rid = _triple(item, "related entries must be (relation, type, object id)")
            spec = self.catalog.relation(rel)
            if spec.ref != ref_type:
                raise CtxsearchError(f"relation {rel} is not a relation of {ref_type}")
            self.catalog.type(t)
            rows.append((rel, t, _int(rid, "related object id")))
        views = self._view_rows(ref_type, e.views)
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
                cur.executemany(
                    "INSERT INTO views (examination_id, relation, recall, false_rate) "
                    "VALUES (?, ?, ?, ?)",
                    [(eid, *v) for v in views],
                )
        except sqlite3.IntegrityError:
            raise StoreError(
                f"{self.path}: object {exam[4]} of room {exam[1]}/{exam[2]} is already examined "
                f"in run {exam[0]!r} on day {day}: another process is learning the same run on "
                "this store "
                "(nothing was written; its evidence is kept once)"
            ) from None
        return eid

    def _view_rows(
        self, ref_type: str, views: Iterable[tuple[str, Sequence[float], Sequence[float]]]
    ) -> list[tuple[str, bytes, bytes]]:
        """The views of an examination of ``ref_type`` as table rows (checked: a relation of
        the type, once each; one value in [0, 1] per catalog type)."""
        rows, seen, n_types = [], set(), len(self.catalog.type_names)
        for item in views:
            rel, recall, false_rate = _triple(
                item, "views must be (relation, recall per type, false rate per type)"
            )
            if self.catalog.relation(rel).ref != ref_type or rel in seen:
                raise CtxsearchError(f"view of {rel}: not a relation of {ref_type}, or given twice")
            seen.add(rel)
            blobs = []
            for what, vals in (("recall", recall), ("false_rate", false_rate)):
                arr = np.asarray(vals, float)
                if arr.shape != (n_types,) or not np.all((arr >= 0) & (arr <= 1)):
                    raise CtxsearchError(
                        f"view of {rel}: {what} must be {n_types} numbers in [0, 1]"
                    )
                blobs.append(np.rint(arr * VIEW_SCALE).astype("<u2").tobytes())
            rows.append((rel, *blobs))
        return rows

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
        contents: Iterable[tuple[int, str, int]] = (),
        home_map: HomeMap | None = None,
    ) -> None:
        """Set the status of a room's visit on ``day``: 'started' when the robot enters it (a
        visit already done stays done), 'done' when it is finished; ``end_time`` (the run's
        simulated clock when it was done) replaces the stored one. ``contents`` (with 'done'
        only): what the visit's rooms held, (segment, type, instances) rows
        (knowledge.room_context); ``home_map`` (with 'done' only): the robot's remembered map of
        the world (of this style, seed and day, its furniture of catalog types); both written
        in the same transaction; a visit keeps the contents and the map it was first given (a
        second 'done' adds none: nothing counts twice)."""
        if status not in ROOM_STATUSES:
            raise CtxsearchError(f"room status must be one of {ROOM_STATUSES}, got {status!r}")
        key = (_text(run, "run"), _text(style, "style"), _int(seed, "seed"), _day(day), status)
        end = None if end_time is None else _float(end_time, "end_time")
        rows = self._content_rows(key[:4], contents)
        if rows and status != "done":
            raise CtxsearchError("room contents are recorded only with a visit marked 'done'")
        if home_map is not None and status != "done":
            raise CtxsearchError("a home map is recorded only with a visit marked 'done'")
        blob = None if home_map is None else _map_blob(key[:4], home_map, self.catalog)
        with self._transaction() as cur:
            if (
                rows
                and not cur.execute(
                    "SELECT 1 FROM room_contents WHERE run = ? AND style = ? AND room_seed = ? "
                    "AND day = ? LIMIT 1",
                    key[:4],
                ).fetchone()
            ):
                cur.executemany(
                    "INSERT INTO room_contents (run, style, room_seed, day, segment, type, "
                    "instances) VALUES (?, ?, ?, ?, ?, ?, ?)",
                    rows,
                )
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
            if blob is not None:
                self._insert_home_map(cur, (*key[:4], blob))

    def _insert_home_map(self, cur: sqlite3.Cursor, row: tuple) -> None:
        """Store a visit's map unless it has one (the first kept)."""
        cur.execute(
            "INSERT INTO home_maps (run, style, seed, day, map) VALUES (?, ?, ?, ?, ?) "
            "ON CONFLICT (run, style, seed, day) DO NOTHING",
            row,
        )

    def _content_rows(self, visit: tuple, contents: Iterable[tuple[int, str, int]]) -> list[tuple]:
        """``mark_room``'s contents as rows, checked against the catalog (CtxsearchError)."""
        rows, keys = [], set()
        for segment, typ, instances in contents:
            seg, n = _int(segment, "segment"), _int(instances, "instances")
            if typ not in self.catalog or seg < 0 or n < 1:
                raise CtxsearchError(
                    f"room contents: bad row (segment {segment!r}, type {typ!r}, "
                    f"instances {instances!r})"
                )
            if (seg, typ) in keys:
                raise CtxsearchError(f"room contents: segment {seg} lists {typ} twice")
            keys.add((seg, typ))
            rows.append((*visit, seg, typ, n))
        return rows

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


def _map_blob(visit: tuple, home_map: object, catalog: Catalog) -> bytes:
    """``mark_room``'s map as bytes, checked: a HomeMap of the visit's (run, style, seed, day)
    world and day, its furniture of the catalog's types (CtxsearchError otherwise)."""
    _run, style, seed, day = visit
    if not isinstance(home_map, HomeMap):
        raise CtxsearchError(f"home_map must be a HomeMap, got {type(home_map).__name__}")
    where = f"home map of {style}/{seed} day {day}"
    if (home_map.style, home_map.seed, home_map.day) != (style, seed, day):
        raise CtxsearchError(
            f"{where}: the map is of {home_map.style}/{home_map.seed} day {home_map.day}"
        )
    blob = check_types(home_map, catalog.type_names, where).to_bytes()
    if len(blob) > MAX_MAP_BYTES:
        raise CtxsearchError(f"{where}: {len(blob)} bytes, larger than {MAX_MAP_BYTES}")
    return blob


def merge_stores(out_path: str | Path, in_paths: Sequence[str | Path], catalog: Catalog) -> int:
    """Append the logs of ``in_paths`` to the store at ``out_path`` (created if missing).

    Every input must be a store built on ``catalog`` (StoreError naming the file otherwise); all
    inputs are checked before anything is written, and the whole merge is one transaction.
    Examination ids are renumbered; a room marked 'done' in any input is 'done' in the output,
    with the first end time any of them recorded, the first room contents and the first
    remembered map (each checked: one that cannot be decoded, or holds a type outside the
    catalog, is a one-line error naming the input and nothing is merged). An output older than
    version 7 is upgraded. An examination that is already in the output (same EXAM_KEY) is a
    StoreError: nothing is merged. A new output gets the first input's alpha. Returns the number
    of examinations appended.
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
            for p in ins:
                src = _connect_ro(p)
                try:
                    src.execute("BEGIN")  # one snapshot of the input, even if a robot is writing it
                    # Its version as this snapshot sees it: a robot writing it may have upgraded
                    # it in its WAL since the check of its main file (inspect_store).
                    version = int(_check_store(src, p, quick_check=False)["schema_version"])
                    appended += _append_log(cur, src, version)
                    if version >= 7:
                        _append_maps(cur, src, p, catalog)
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


def _append_log(cur: sqlite3.Cursor, src: sqlite3.Connection, version: int) -> int:
    """Append the log of ``src`` (a store of schema ``version``) in ``cur``'s transaction: its
    examinations renumbered after the output's, their observations and views, its rooms (a
    room 'done' in either is 'done', the first end time kept). Returns the examinations
    appended. Duplicates within an input (older than version 3) are read once, the first."""
    offset = int(cur.execute("SELECT COALESCE(MAX(id), 0) FROM examinations").fetchone()[0])
    new_in = version >= 4
    key = EXAM_KEY if new_in else _V3_EXAM_KEY
    keep = f"SELECT MIN(id) FROM examinations GROUP BY {', '.join(key)}"
    cols = _EXAM_COLS if new_in else _OLD_EXAM_COLS
    exams = src.execute(f"SELECT id, {cols} FROM examinations WHERE id IN ({keep}) ORDER BY id")
    appended = _copy_shifted(cur, exams, "examinations", f"id, {_EXAM_COLS}", offset, 10_000)
    obs_cols = "examination_id, relation, type, related_id"
    obs = src.execute(
        f"SELECT {obs_cols} FROM observations WHERE examination_id IN ({keep}) ORDER BY rowid"
    )
    _copy_shifted(cur, obs, "observations", obs_cols, offset, 50_000)
    if version >= 5:
        view_cols = "examination_id, relation, recall, false_rate"
        views = src.execute(f"SELECT {view_cols} FROM views WHERE examination_id IN ({keep}) "
                            "ORDER BY examination_id, relation")  # fmt: skip
        _copy_shifted(cur, views, "views", view_cols, offset, 50_000)
    if version >= 6:
        _append_contents(cur, src)
    end = "end_time" if version >= 2 else "NULL"
    day = "day" if new_in else "0"
    cur.executemany(
        "INSERT INTO rooms (run, style, seed, day, status, end_time) "
        "VALUES (?, ?, ?, ?, ?, ?) "
        "ON CONFLICT (run, style, seed, day) DO UPDATE SET status = "
        "CASE WHEN rooms.status = 'done' OR excluded.status = 'done' THEN 'done' ELSE 'started' END, "
        "end_time = COALESCE(rooms.end_time, excluded.end_time)",
        src.execute(f"SELECT run, style, seed, {day}, status, {end} FROM rooms").fetchall(),
    )
    return appended


def _append_contents(cur: sqlite3.Cursor, src: sqlite3.Connection) -> None:
    """Copy ``src``'s room contents: a visit keeps the contents it was first given (as it keeps
    its first end time), so a visit already holding some in the output takes none from ``src``."""
    cols = "run, style, room_seed, day, segment, type, instances"
    by_visit: dict[tuple, list[tuple]] = {}
    for row in src.execute(f"SELECT {cols} FROM room_contents ORDER BY {cols}"):
        by_visit.setdefault(tuple(row[:4]), []).append(tuple(row))
    for visit, rows in by_visit.items():
        held = cur.execute(
            "SELECT 1 FROM room_contents WHERE run = ? AND style = ? AND room_seed = ? AND day = ? "
            "LIMIT 1",
            visit,
        ).fetchone()
        if not held:
            cur.executemany(
                f"INSERT INTO room_contents ({cols}) VALUES (?, ?, ?, ?, ?, ?, ?)", rows
            )


def _append_maps(
    cur: sqlite3.Cursor, src: sqlite3.Connection, path: Path, catalog: Catalog
) -> None:
    """Copy ``src``'s remembered maps, each decoded and checked first (a one-line HomeMapError
    or StoreError naming ``path``); a visit that already has a map in the output keeps it."""
    cols = "run, style, seed, day, map"
    for run, style, seed, day, blob in src.execute(
        f"SELECT {cols} FROM home_maps ORDER BY 1, 2, 3, 4"
    ):
        where = f"{path}: home map {style}/{seed} day {day}"
        m = check_types(HomeMap.from_bytes(blob, where), catalog.type_names, where)
        if (
            not isinstance(run, str) or not isinstance(style, str)
            or (m.style, m.seed, m.day) != (style, seed, day)
        ):  # fmt: skip
            raise StoreError(f"{where}: damaged knowledge store: the row is not the map's visit")
        cur.execute(
            f"INSERT INTO home_maps ({cols}) VALUES (?, ?, ?, ?, ?) "
            "ON CONFLICT (run, style, seed, day) DO NOTHING",
            (run, style, seed, day, blob),
        )


def _copy_shifted(
    cur: sqlite3.Cursor, rows: sqlite3.Cursor, table: str, cols: str, offset: int, batch: int
) -> int:
    """Insert ``rows`` (examination id first, shifted by ``offset``) into ``table`` (``cols``),
    ``batch`` at a time; how many."""
    marks = ", ".join("?" * len(cols.split(",")))
    n = 0
    while chunk := rows.fetchmany(batch):
        cur.executemany(
            f"INSERT INTO {table} ({cols}) VALUES ({marks})",
            [(r[0] + offset, *r[1:]) for r in chunk],
        )
        n += len(chunk)
    return n


def _triple(item: object, what: str) -> tuple:
    """``item`` unpacked as three values, or a CtxsearchError: ``what``, got ``item``."""
    try:
        a, b, c = item  # type: ignore[misc]
    except (TypeError, ValueError):
        raise CtxsearchError(f"{what}, got {item!r}") from None
    return a, b, c


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
