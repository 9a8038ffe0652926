"""Where to look for a target: P(rel(T)) from the learned intervals, and the relation volumes of
known objects ranked by it (location constraint, paper section 3).

This is the robot-independent half of object search. Given the objects a robot knows (its own
detections, as ``ObjectInstance``), every known object b and every rel in RELATIONS(type(b))
give one candidate volume v_rel(b) with probability P(rel(T)), read from a ``ProbabilitySource``:
the knowledge base's interval (its lower bound, the Wilson centre p0, or the upper bound, by
``rank``; for reference types with little evidence optionally the class's backoff estimate,
``BackoffProbabilities``), or a fixed table (ground truth, or a test's). ``candidate_volumes`` returns them best
first. The simulated robot's search (``agent/search/space.py``) builds its regions from exactly
these candidates and then adds what only a robot with a map knows: which part of each volume it
has already seen and how many seconds it costs to look there.

Pure numpy: usable by any robot (see ``scripts/examples/real_robot_api.py``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import Box, ObjectInstance, relation_volume
from ctxsearch.knowledge.options import Rank
from ctxsearch.knowledge.pooling import Backoff, PooledCounts
from ctxsearch.knowledge.room_context import RoomContext

RANK_MODES = ("low", "p0", "high")
# The lower bound was best or tied on three stores of different sizes (measured; docs/results.md, Search).
DEFAULT_RANK = "low"
# Where P(rel(T)) comes from: the type's own counts (the paper's, "flat"), or, for reference types
# with fewer than ``min_evidence`` examinations, their class's backoff (knowledge.pooling).
ESTIMATES = ("flat", "backoff")
DEFAULT_ESTIMATE = "flat"
# Below this many examinations a reference type reads the backoff estimate (bench hierarchy: the
# backoff's error is below the flat estimate's up to k = 10 examinations; docs/results.md, Type hierarchy).
DEFAULT_MIN_EVIDENCE = 10


class ProbabilitySource:
    """P(rel(T)) for the search: a number in [0, 1] per (relation, type)."""

    name = "none"
    kb: KnowledgeBase | None = None  # the evidence behind the numbers, where there is one

    def p(self, relation: str, type_name: str) -> float:  # pragma: no cover - interface
        """The probability used to rank rel's volume when looking for ``type_name``."""
        raise NotImplementedError

    def instances(self, type_name: str) -> float | None:
        """Expected instances of ``type_name`` per room, or None if unknown."""
        return None

    def same_room(self, ref_type: str, type_name: str) -> float | None:
        """P(SAME-ROOM-AS-ref(T)): the probability that the room of an instance of furniture
        type ``ref_type`` holds an instance of ``type_name`` (room context); None
        where this source knows no room context."""
        return None

    def room_share(self, type_name: str) -> float | None:
        """P(a room holds an instance of ``type_name``), over all rooms: what a room nothing is
        known about holds; None where this source knows no room context."""
        return None

    def next_room(self, ref_type: str, type_name: str) -> float | None:
        """P(NEXT-ROOM-OF-ref(T)): the probability that a room sharing a door with a room
        holding furniture type ``ref_type`` holds an instance of ``type_name``
        (knowledge.room_context); None where this source knows none."""
        return None


class UniformProbabilities(ProbabilitySource):
    """No probabilities: every relation counts the same (``map-only`` search, the value of the
    map alone)."""

    name = "uniform"

    def p(self, relation: str, type_name: str) -> float:
        """1 for every relation and type."""
        return 1.0


class KBProbabilities(ProbabilitySource):
    """The learned intervals: lower bound, p0 (the Wilson centre) or upper bound, by ``rank``."""

    def __init__(self, kb: KnowledgeBase, rank: str = DEFAULT_RANK, rooms: int | None = None):
        if rank not in RANK_MODES:
            raise CtxsearchError(f"unknown rank '{rank}' (known: {', '.join(RANK_MODES)})")
        self.kb, self.rank, self.rooms = kb, rank, rooms
        self.name = f"kb-{rank}"
        self._cache: dict[tuple[str, str], float] = {}
        self.room_context: RoomContext | None = None  # learned room context, if given

    def with_room_context(self, rooms: RoomContext | None) -> KBProbabilities:
        """This source, also reading the learned room context ``rooms`` (by the same rank)."""
        self.room_context = rooms
        return self

    def same_room(self, ref_type: str, type_name: str) -> float | None:
        if self.room_context is None:
            return None
        return self.room_context.same_room(ref_type, type_name, Rank(self.rank))

    def room_share(self, type_name: str) -> float | None:
        if self.room_context is None:
            return None
        return self.room_context.room_share(type_name)

    def next_room(self, ref_type: str, type_name: str) -> float | None:
        if self.room_context is None:
            return None
        return self.room_context.next_room(ref_type, type_name, Rank(self.rank))

    def instances(self, type_name: str) -> float | None:
        """n_T / rooms learned in: examined instances per room (None without a room count)."""
        if not self.rooms:
            return None
        return self.kb.n(type_name) / self.rooms

    def p(self, relation: str, type_name: str) -> float:
        key = (relation, type_name)
        v = self._cache.get(key)
        if v is None:
            if self.rank == Rank.P0:
                rel = self.kb.catalog.relation(relation)
                v = float(
                    intervals.p0(self.kb.y(relation, type_name), self.kb.n(rel.ref), self.kb.alpha)
                )
            else:
                lo, hi = self.kb.interval(relation, type_name)
                v = lo if self.rank == Rank.LOW else hi
            self._cache[key] = v
        return v


class TableProbabilities(ProbabilitySource):
    """Fixed probabilities from a table {(relation, type): p} (ground truth, or a test's)."""

    def __init__(
        self,
        table: Mapping[tuple[str, str], float],
        name: str = "table",
        per_room: Mapping[str, float] | None = None,
    ):
        self.table = {k: float(v) for k, v in table.items()}
        self.name = name
        self.per_room = dict(per_room) if per_room is not None else None
        self.rooms: tuple[dict[tuple[str, str], float], dict[str, float]] | None = None
        self.next_rooms: dict[tuple[str, str], float] | None = None

    def with_rooms(
        self,
        same_room: Mapping[tuple[str, str], float],
        room_share: Mapping[str, float],
        next_room: Mapping[tuple[str, str], float] | None = None,
    ) -> TableProbabilities:
        """A copy that also knows room context: P(SAME-ROOM-AS-F(T)) per (F, T), the share of
        rooms holding each type and, if given, P(NEXT-ROOM-OF-F(T)) per (F, T) (``same_room``,
        ``room_share``, ``next_room``)."""
        out = TableProbabilities(self.table, self.name, self.per_room)
        out.rooms = (dict(same_room), dict(room_share))
        out.next_rooms = None if next_room is None else dict(next_room)
        return out

    @classmethod
    def from_truth(cls, doc: Mapping) -> TableProbabilities:
        """From ``ctxsearch truth``'s JSON document ({"samples", "entries": [{"ref", "relation",
        "type", "p", "n"}, ...]}); instances per room are n_ref / samples."""
        entries = doc.get("entries", [])
        per_room = None
        if doc.get("samples"):
            per_room = {
                e["ref"]: float(e["n"]) / float(doc["samples"])
                for e in entries
                if "n" in e and "ref" in e
            }
        return cls(
            {(e["relation"], e["type"]): float(e["p"]) for e in entries},
            name="truth",
            per_room=per_room,
        )

    def p(self, relation: str, type_name: str) -> float:
        return self.table.get((relation, type_name), 0.0)

    def instances(self, type_name: str) -> float | None:
        if self.per_room is None:
            return None
        return self.per_room.get(type_name, 0.0)

    def same_room(self, ref_type: str, type_name: str) -> float | None:
        if self.rooms is None:
            return None
        return self.rooms[0].get((ref_type, type_name))

    def room_share(self, type_name: str) -> float | None:
        if self.rooms is None:
            return None
        return self.rooms[1].get(type_name)

    def next_room(self, ref_type: str, type_name: str) -> float | None:
        if self.next_rooms is None:
            return None
        return self.next_rooms.get((ref_type, type_name))


class BackoffProbabilities(KBProbabilities):
    """``KBProbabilities`` where the reference type has fewer than ``min_evidence`` examinations
    and a class: there the backed-off interval (knowledge.pooling.Backoff on ``pooled``, the
    evidence pooled over the catalog's hierarchy), ranked by its lower bound, its Wilson centre
    or its upper bound. A never-examined type of a known class is searched around from its
    class's knowledge; types with enough evidence, or in no class, read their own interval."""

    def __init__(
        self,
        kb: KnowledgeBase,
        pooled: PooledCounts,
        rank: str = DEFAULT_RANK,
        rooms: int | None = None,
        min_evidence: int = DEFAULT_MIN_EVIDENCE,
    ):
        super().__init__(kb, rank, rooms)
        if min_evidence < 0:
            raise CtxsearchError(f"min_evidence must be >= 0, got {min_evidence}")
        self.backoff = Backoff(pooled, kb.alpha, kb.corrected)  # corrected: on its counts
        self.min_evidence = int(min_evidence)
        self.name = f"backoff-{rank}"

    def p(self, relation: str, type_name: str) -> float:
        ref = self.kb.catalog.relation(relation).ref
        h = self.kb.catalog.hierarchy
        if self.kb.n(ref) >= self.min_evidence or h.parent(ref) is None or h.lift(relation) is None:
            return super().p(relation, type_name)
        key = (relation, type_name)
        v = self._cache.get(key)
        if v is None:
            e = self.backoff.estimate(ref, relation, type_name)
            if self.rank == Rank.P0:
                v = float(intervals.p0(e.y_eff, e.n_eff, self.kb.alpha))
            else:
                v = e.low if self.rank == Rank.LOW else e.high
            self._cache[key] = v
        return v


@dataclass(frozen=True)
class Candidate:
    """One place to look for the target: v_rel(b) of a known object b, with P(rel(T))."""

    relation: str
    ref_id: int  # the known object's instance id
    box: Box  # v_rel(b), world frame
    p: float  # P(rel(T)) from the probability source


def candidate_volumes(
    known: Iterable[ObjectInstance],
    target: str,
    catalog: Catalog,
    probs: ProbabilitySource,
    min_p: float = 1e-6,
) -> list[Candidate]:
    """Every (known object b, rel in RELATIONS(type(b))) with P(rel(target)) > ``min_p``, best
    first (ties: relation name, then instance id). Instances of the target type give none."""
    out = []
    for b in sorted(known, key=lambda o: o.id):
        if b.type == target:
            continue
        for rel in catalog.type(b.type).relations:
            p = float(probs.p(rel.name, target))
            if p > min_p:
                out.append(Candidate(rel.name, b.id, relation_volume(rel, b), p))
    return sorted(out, key=lambda c: (-c.p, c.relation, c.ref_id))
