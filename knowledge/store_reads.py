"""Reading the evidence log back (``EvidenceReads``, the read side of ``knowledge.store.EvidenceStore``):
examinations, rooms and visits, counts per room, the knowledge base, and the robot's remembered
maps of the houses it visited (``HomeMapReads``, schema 7); every value read is checked and a bad
one is a one-line StoreError naming the store (a remembered map that cannot be decoded, a one-line
``knowledge.home_map.HomeMapError`` naming the store and the map)."""

from __future__ import annotations

import contextlib
import math
import sqlite3
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.clustered import ClusteredIntervals, RoomCounts, room_counts_from_rows
from ctxsearch.knowledge.corrected import CorrectedIntervals, ExamViews
from ctxsearch.knowledge.errors import CtxsearchError, StoreError
from ctxsearch.knowledge.home_map import MAX_BYTES as MAX_MAP_BYTES
from ctxsearch.knowledge.home_map import HomeMap, check_types
from ctxsearch.knowledge.options import IntervalMethod
from ctxsearch.knowledge.room_context import RoomContext, segment_neighbours
from ctxsearch.knowledge.store_schema import (
    MAX_DAY,
    ROOM_STATUSES,
    VIEW_SCALE,
    _check_alpha,
    _one_line,
)


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


class _ReadChecks:
    """What every read of an open evidence store checks its values with (one-line StoreErrors
    naming the store); the store holds the connection ``conn``, the catalog, its ``alpha``,
    its ``path`` and its schema ``version``."""

    conn: sqlite3.Connection
    catalog: Catalog
    alpha: float
    path: Path
    version: int

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


class HomeMapReads(_ReadChecks):
    """The robot's remembered maps (schema 7's ``home_maps``: one per house visit done, the
    first kept); a store older than version 7 holds none."""

    def home_maps(self, run: str | None = None) -> list[tuple[str, str, int, int]]:
        """(run, style, seed, day) of every stored map (of one run, or all), sorted."""
        if self.version < 7:
            return []
        where, args = (" WHERE run = ?", (run,)) if run is not None else ("", ())
        out = []
        with self._reading():
            for r, st, seed, day in self.conn.execute(
                f"SELECT run, style, seed, day FROM home_maps{where}", args
            ):
                out.append((self._name(r, "home map run"), self._name(st, "home map style"),
                            self._integer(seed, "home map seed"),
                            self._day_stamp(day, "home map day")))  # fmt: skip
        return sorted(out)

    def home_map(
        self, style: str, seed: int, run: str | None = None, upto_day: int | None = None
    ) -> HomeMap | None:
        """The remembered map of world (``style``, ``seed``) of the latest day (at most
        ``upto_day`` if given) that has one, of ``run`` (or of any run: the latest day, then
        the first run by name); None if there is none. A row that is not a map of that visit
        and of this catalog is a one-line error naming the store."""
        if self.version < 7:
            return None
        conds, args = ["style = ?", "seed = ?"], [style, _whole(seed, "seed")]
        if run is not None:
            conds.append("run = ?")
            args.append(run)
        if upto_day is not None:
            conds.append("day <= ?")
            args.append(_whole(upto_day, "upto_day"))
        sql = (
            "SELECT run, day, typeof(map), length(map), CASE WHEN typeof(map) = 'blob' AND "
            f"length(map) <= {MAX_MAP_BYTES} THEN map END FROM home_maps "
            f"WHERE {' AND '.join(conds)} ORDER BY day DESC, run LIMIT 1"
        )
        with self._reading():
            row = self.conn.execute(sql, args).fetchone()
        if row is None:
            return None
        day = self._day_stamp(row[1], f"home map {style}/{seed}: day")
        where = f"{self.path}: home map {style}/{seed} day {day}"
        if row[2] != "blob":
            raise self._bad(f"home map {style}/{seed} day {day} is {row[2]}, not a blob")
        if row[4] is None:
            raise self._bad(f"home map {style}/{seed} day {day}: {row[3]} bytes, larger than "
                            f"{MAX_MAP_BYTES}")  # fmt: skip
        m = check_types(HomeMap.from_bytes(row[4], where), self.catalog.type_names, where)
        if (m.style, m.seed, m.day) != (style, args[1], day):
            raise self._bad(f"home map {style}/{seed} day {day} holds the map of "
                            f"{m.style}/{m.seed} day {m.day}")  # fmt: skip
        return m


class EvidenceReads(HomeMapReads):
    """The read queries of an open evidence store (mixed into ``EvidenceStore``, which holds
    the connection ``conn``, the catalog, the store's ``alpha`` and its ``path``)."""

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

    def room_counts(self, run: str | None = None, upto: int | None = None) -> dict[str, RoomCounts]:
        """Per reference type, its examinations and y counts per room (of one run, or all; with
        ``upto``, of the examinations with id <= upto): the input of the clustered interval
        (knowledge.clustered). A room is (style, room seed): runs that visit the same room share
        its cluster. Read-only."""
        where, args = _exam_filter(run, upto)
        obs = (
            "SELECT DISTINCT o.examination_id, e.type, e.style, e.room_seed, o.relation, o.type "
            "FROM observations o JOIN examinations e ON e.id = o.examination_id"
            + _exam_filter(run, upto, "e.")[0]
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

    def room_context(self, run: str | None = None) -> RoomContext:
        """The room context learned (knowledge.room_context) from the visits' room contents (of
        one run, or all); empty in a store older than version 6. Read-only."""
        if self.version < 6:
            return RoomContext.from_rows((), self.catalog, self.alpha)
        where, args = (" WHERE run = ?", (run,)) if run is not None else ("", ())
        cols = "run, style, room_seed, day, segment, type, instances"
        rows = []
        with self._reading():
            for r in self.conn.execute(
                f"SELECT {cols} FROM room_contents{where} ORDER BY {cols}", args
            ):
                typ = self._name(r[5], "room contents type")
                if typ not in self.catalog:
                    raise self._bad(f"room contents type {typ!r} is not in the catalog")
                seg = self._integer(r[4], "room contents segment")
                k = self._integer(r[6], "room contents instances")
                if seg < 0 or k < 1:
                    raise self._bad(f"room contents row {tuple(r)!r} is out of range")
                rows.append((str(r[0]), str(r[1]), self._integer(r[2], "room seed"),
                             self._day_stamp(r[3], "room contents day"), seg, typ, k))  # fmt: skip
        return RoomContext.from_rows(rows, self.catalog, self.alpha, self.segment_doors(run))

    def segment_doors(self, run: str | None = None) -> dict[tuple, frozenset[tuple[int, int]]]:
        """Per visit (run, style, seed, day) with a remembered map (of one run, or all): the
        pairs of its map's segments that share a door (knowledge.room_context.segment_neighbours
        of ``HomeMap.rooms``, the segmentation its room contents were counted on). Read-only."""
        out = {}
        for r, st, seed, day in self.home_maps(run):
            m = self.home_map(st, seed, run=r, upto_day=day)
            if m is not None and m.day == day:
                out[(r, st, seed, day)] = segment_neighbours(m.rooms)
        return out

    def exam_views(self, run: str | None = None, upto: int | None = None) -> dict[str, ExamViews]:
        """Per reference type, its examinations (of one run, or all; with ``upto``, those with id
        <= upto) in log order: what each reported and what its images could show
        (knowledge.corrected's input). An examination without views (the oracle perception, a
        store older than schema 5) has recall 1 and false-report rate 0. Read-only."""
        cat = self.catalog
        names = cat.type_names
        t_index = {t: i for i, t in enumerate(names)}
        where, args = _exam_filter(run, upto)
        join = _exam_filter(run, upto, "e.")[0]
        with self._reading():
            exams = [
                (self._integer(i, "examination id"), self._name(t, "type"))
                for i, t in self.conn.execute(
                    f"SELECT id, type FROM examinations{where} ORDER BY id", args
                )
            ]
            obs = self.conn.execute(
                "SELECT o.examination_id, o.relation, o.type, COUNT(DISTINCT o.related_id) "
                f"FROM observations o JOIN examinations e ON e.id = o.examination_id{join} "
                "GROUP BY o.examination_id, o.relation, o.type",
                args,
            ).fetchall()
            views = (
                self.conn.execute(
                    "SELECT v.examination_id, v.relation, v.recall, v.false_rate FROM views v "
                    f"JOIN examinations e ON e.id = v.examination_id{join}",
                    args,
                ).fetchall()
                if self.version >= 5
                else []
            )
        by_type: dict[str, list[int]] = defaultdict(list)
        for eid, t in exams:
            if t not in cat:
                raise self._bad(f"examination {eid}: examined type {t!r} is not in the catalog")
            by_type[t].append(eid)
        out: dict[str, ExamViews] = {}
        where_is: dict[int, tuple[str, int]] = {}
        for t, ids in by_type.items():
            r_n = len(cat.type(t).relations)
            out[t] = ExamViews(
                np.zeros((len(ids), r_n, len(names)), np.int64),
                np.ones((len(ids), r_n, len(names))),
                np.zeros((len(ids), r_n, len(names))),
            )
            where_is.update((eid, (t, k)) for k, eid in enumerate(ids))
        for eid, rel, b, count in obs:
            t, k = where_is[eid]
            r = self._relation_index(t, rel, eid)
            if b not in t_index:
                raise self._bad(f"examination {eid}: observed type {b!r} is not in the catalog")
            out[t].d[k, r, t_index[b]] = self._integer(count, f"examination {eid}: count")
        for eid, rel, recall, false_rate in views:
            t, k = where_is[eid]
            r = self._relation_index(t, rel, eid)
            out[t].q[k, r] = self._view(recall, len(names), f"examination {eid}: recall")
            out[t].f[k, r] = self._view(false_rate, len(names), f"examination {eid}: false rate")
        return out

    def _relation_index(self, ref: str, rel: object, eid: int) -> int:
        """The index of ``rel`` in RELATIONS(ref) (a damaged-store error if it is not one)."""
        rels = self.catalog.type(ref).relation_names
        if rel not in rels:
            raise self._bad(f"examination {eid}: {rel!r} is not a relation of {ref} in the catalog")
        return rels.index(rel)

    def _view(self, blob: object, n_types: int, what: str) -> np.ndarray:
        """A views blob as n_types values in [0, 1]."""
        if not isinstance(blob, bytes) or len(blob) != 2 * n_types:
            raise self._bad(f"{what} is not {n_types} uint16 values")
        return np.frombuffer(blob, "<u2").astype(float) / VIEW_SCALE

    def knowledge_base(
        self,
        alpha: float | None = None,
        *,
        run: str | None = None,
        interval: str = "wilson",
    ) -> KnowledgeBase:
        """The counts rebuilt from the log (of one run, or all), as a KnowledgeBase.

        n_A = examinations of type A; y_{rel,B} = examinations with at least one observation row
        (rel, B). ``alpha`` defaults to the store's. ``interval``: 'wilson' (the paper's),
        'clustered' (its intervals on the room-level effective counts of ``room_counts``) or
        'corrected' (knowledge.corrected on ``exam_views``, clustered the same way); the counts
        and HIF are the same.
        """
        if interval not in tuple(IntervalMethod):
            raise CtxsearchError(
                f"unknown interval method '{interval}' (known: {', '.join(tuple(IntervalMethod))})"
            )
        kb = KnowledgeBase(self.catalog, self.alpha if alpha is None else _check_alpha(alpha))
        if interval == IntervalMethod.CLUSTERED:
            kb.use_clustered(ClusteredIntervals(self.room_counts(run), kb.alpha))
        elif interval == IntervalMethod.CORRECTED:
            kb.use_corrected(self.corrected_intervals(kb.alpha, run))
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

    def corrected_intervals(
        self, alpha: float | None = None, run: str | None = None, upto: int | None = None
    ) -> CorrectedIntervals:
        """The corrected intervals (knowledge.corrected) of the log (of one run, or all; with
        ``upto``, of the examinations with id <= upto)."""
        alpha = self.alpha if alpha is None else _check_alpha(alpha)
        cat = self.catalog
        return CorrectedIntervals(
            self.exam_views(run, upto),
            ClusteredIntervals(self.room_counts(run, upto), alpha),
            {t.name: t.relation_names for t in cat.types},
            cat.type_names,
            alpha,
        )


def _exam_filter(run: str | None, upto: int | None, prefix: str = "") -> tuple[str, tuple]:
    """The WHERE clause (with its leading space, or empty) and arguments selecting the
    examinations of ``run`` (None: all) with id <= ``upto`` (None: all); ``prefix`` names the
    examinations table's alias ("e.")."""
    conds, args = [], []
    if run is not None:
        conds.append(f"{prefix}run = ?")
        args.append(run)
    if upto is not None:
        conds.append(f"{prefix}id <= ?")
        args.append(int(upto))
    return (" WHERE " + " AND ".join(conds) if conds else "", tuple(args))


def _whole(v: object, what: str) -> int:
    """``v`` as an integer (numpy integers too), or a CtxsearchError."""
    if isinstance(v, bool) or not isinstance(v, int | np.integer):
        raise CtxsearchError(f"{what} must be an integer, got {v!r}")
    return int(v)
