"""Room context learned by the robot: SAME-ROOM-AS-F relations with the paper's
counts and Wilson intervals, from what the rooms of its own map held.

At the end of a house visit done to the end, the learner cuts its map into rooms
(agent.room_segmentation) and records, per segment holding furniture, the instances of each type
it recognized there (the examined objects and the objects found in their relation volumes, with
a detector that has false positives only those it once saw with more confidence than a false
positive can have: ``agent.room_segmentation.Recognized``; ``EvidenceStore.mark_room``'s
contents, the store's ``room_contents`` table). From those rows:

    n_F      = the segments holding furniture type F
    y_{F,T}  = those of them also holding a T (T = F: a second F)
    P(SAME-ROOM-AS-F(T)) in the Wilson interval of (y_{F,T}, n_F) at the store's alpha (eq. 1-2)
    share(T) = the share of segments holding a T (what a room with furniture holds)

The unit is the room, not the instance of F (the paper counts instances of the reference, whose
relation volumes rarely overlap): the four chairs of a dining room share one room and so one
outcome for every T, and counting each would make the Wilson interval as if four rooms had been
seen. Measured on 30 learned apartments (``python -m
ctxsearch.scripts.experiments.room_coverage``): counting instances, the intervals held the plans'
value on 0.862 of the informative entries with oracle perception (0.838 with the camera); counting
rooms, 0.938 (0.908), at a mean width of 0.150 instead of 0.122. The truth
(envs.truth.room_truth) counts rooms the same way.

When a visit may count (the issue's question): only a visit the learner finished (its tour of
the house over; one left early by ``--room-budget`` records none), on its map as the tour left
it; every segment holding recognized furniture counts. Misses: a T the robot never recognized
in a segment counts as absent, which biases both y and share(T) low, by the same detector's
misses; false reports: an object counts under the type reported most often, and only once an
image saw it with more confidence than a false positive can have, so clutter does not put a
phantom in every room. The
belief uses the ratio of y / n to share(T) (agent.search.room_prior), in which a bias common
to both largely cancels. A segment that joins two of the plan's rooms (a door the segmentation missed) counts
as one room.

Next-room relations: what lies through a door. From the same visits, with the segmentation the
visit's remembered map keeps (``HomeMap.rooms``; the segments meet where a door joins two rooms:
``segment_neighbours``), in hindsight once the house is mapped:

    m_F      = the pairs (segment holding furniture type F, a segment with furniture its doors
               lead to)
    z_{F,T}  = those whose other segment holds a T
    P(NEXT-ROOM-OF-F(T)) in the Wilson interval of (z_{F,T}, m_F)

the probability that a room a door of a room holding an F leads to holds a T: the mass the
search gives the space beyond a mapped room's doors (agent.search.room_prior). A door leads
through segments without recognized furniture (a hall, a corridor: a way through, not a room
the counts know) to the rooms with furniture beyond them: in a house whose rooms all open onto a
hall, a bedroom's next rooms are the hall's other rooms, not the empty hall (counting the hall
would say that nothing lies beyond a bedroom's door). The unit is the pair, not the room: the
space beyond each door is a room of its own (a room with three doors counts three times, and its
pairs share the room, so the interval is somewhat narrower than if the trials were
independent). A visit without a remembered map (a given-map visit) counts for no pair.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.options import Rank


def relation_name(ref_type: str) -> str:
    """``SAME-ROOM-AS-FRIDGE`` for ``Fridge``."""
    return f"SAME-ROOM-AS-{ref_type.upper()}"


def next_relation_name(ref_type: str) -> str:
    """``NEXT-ROOM-OF-FRIDGE`` for ``Fridge``."""
    return f"NEXT-ROOM-OF-{ref_type.upper()}"


def _furniture(catalog: Catalog, type_name: str) -> bool:
    return catalog.type(type_name).is_furniture


def _next_rooms(pairs: Iterable[tuple[int, int]], furnished: set[int]) -> list[tuple[int, int]]:
    """The ordered pairs (a room with furniture, a room with furniture through its doors): the
    rooms a door leads to, through any rooms without furniture (a hall is a way through, not a
    room the counts know), sorted."""
    links: dict[int, set[int]] = {}
    for a, b in pairs:
        links.setdefault(a, set()).add(b)
        links.setdefault(b, set()).add(a)
    out = []
    for here in sorted(furnished):
        seen, todo, found = {here}, [here], set()
        while todo:
            for nxt in links.get(todo.pop(), ()):
                if nxt in seen:
                    continue
                seen.add(nxt)
                if nxt in furnished:
                    found.add(nxt)
                else:
                    todo.append(nxt)
        out += [(here, there) for there in sorted(found)]
    return out


def segment_neighbours(labels: np.ndarray) -> frozenset[tuple[int, int]]:
    """The pairs (a, b), a < b, of segments of ``labels`` (H, W) (-1: none) that share a door:
    cells of the two side by side (4-neighbours). The segmentation (agent.room_segmentation)
    grows its rooms over the room space, walls excluded, and merges two that touch along more
    than a door's width, so two segments meet only where a door (or an opening of its width)
    joins them."""
    lab = np.asarray(labels)
    pairs: set[tuple[int, int]] = set()
    for a, b in ((lab[1:, :], lab[:-1, :]), (lab[:, 1:], lab[:, :-1])):
        touch = (a >= 0) & (b >= 0) & (a != b)
        if touch.any():
            lo = np.minimum(a[touch], b[touch])
            hi = np.maximum(a[touch], b[touch])
            pairs.update(zip(lo.tolist(), hi.tolist(), strict=True))
    return frozenset(pairs)


@dataclass(frozen=True)
class RoomContext:
    """The counts of room context (module docstring) and the intervals they give."""

    n: dict[str, int]  # F: segments holding a recognized F
    y: dict[tuple[str, str], int]  # (F, T): those also holding a T (T = F: a second F)
    rooms: int  # segments holding furniture
    holding: dict[str, int]  # T: segments holding a T
    alpha: float
    # next-room relations (module docstring): F: pairs (segment holding F, a neighbour);
    # (F, T): those whose neighbour holds a T
    next_n: dict[str, int] = field(default_factory=dict)
    next_y: dict[tuple[str, str], int] = field(default_factory=dict)

    @classmethod
    def from_rows(
        cls,
        rows: Iterable[tuple[str, str, int, int, int, str, int]],
        catalog: Catalog,
        alpha: float,
        doors: Mapping[tuple, Iterable[tuple[int, int]]] | None = None,
    ) -> RoomContext:
        """From ``room_contents`` rows (run, style, room_seed, day, segment, type, instances);
        only segments holding furniture count. ``doors``: per visit (the rows' key before the
        segment), the pairs of its segments that share a door (``segment_neighbours``), for the
        next-room relations; a visit not in it counts for none."""
        segments: dict[tuple, dict[str, int]] = {}
        for *visit, segment, typ, k in rows:
            segments.setdefault((*visit, segment), {})[typ] = int(k)
        next_n: dict[str, int] = {}
        next_y: dict[tuple[str, str], int] = {}
        for visit, pairs in sorted((doors or {}).items()):
            held = {seg: segments.get((*visit, seg), {}) for pair in pairs for seg in pair}
            furnished = {seg for seg, h in held.items() if any(_furniture(catalog, t) for t in h)}
            for here, there in _next_rooms(pairs, furnished):
                for f in (t for t in held[here] if _furniture(catalog, t)):
                    next_n[f] = next_n.get(f, 0) + 1
                    for t in held[there]:
                        next_y[(f, t)] = next_y.get((f, t), 0) + 1
        n: dict[str, int] = {}
        y: dict[tuple[str, str], int] = {}
        holding: dict[str, int] = {}
        rooms = 0
        for held in segments.values():
            furniture = [t for t in held if catalog.type(t).is_furniture]
            if not furniture:
                continue
            rooms += 1
            for t in held:
                holding[t] = holding.get(t, 0) + 1
            for f in furniture:
                n[f] = n.get(f, 0) + 1
                for t in held:
                    if t != f or held[f] > 1:
                        y[(f, t)] = y.get((f, t), 0) + 1
        return cls(n, y, rooms, holding, alpha, next_n, next_y)

    def interval(self, ref_type: str, type_name: str) -> tuple[float, float, int, int] | None:
        """(low, high, y, n) of P(SAME-ROOM-AS-ref(T)); None if no ``ref_type`` was counted."""
        return self._interval(self.n, self.y, ref_type, type_name)

    def same_room(self, ref_type: str, type_name: str, rank: Rank) -> float | None:
        """P(SAME-ROOM-AS-ref(T)) read by ``rank``: the interval's lower bound, its Wilson
        centre p0 or its upper bound; None if no ``ref_type`` was counted."""
        return self._read(self.interval(ref_type, type_name), rank)

    def next_interval(self, ref_type: str, type_name: str) -> tuple[float, float, int, int] | None:
        """(low, high, z, m) of P(NEXT-ROOM-OF-ref(T)); None if no pair with ``ref_type``."""
        return self._interval(self.next_n, self.next_y, ref_type, type_name)

    def next_room(self, ref_type: str, type_name: str, rank: Rank) -> float | None:
        """P(NEXT-ROOM-OF-ref(T)) read by ``rank`` (as ``same_room``); None without a pair."""
        return self._read(self.next_interval(ref_type, type_name), rank)

    def _interval(self, trials: dict, successes: dict, ref_type: str, type_name: str):
        """(low, high, y, n) of the counts ``successes[(ref, T)]`` of ``trials[ref]``."""
        n = trials.get(ref_type, 0)
        if n == 0:
            return None
        y = successes.get((ref_type, type_name), 0)
        lo, hi = intervals.interval(y, n, self.alpha)
        return float(lo), float(hi), y, n

    def _read(self, got: tuple[float, float, int, int] | None, rank: Rank) -> float | None:
        """An interval (``_interval``) read by ``rank``: low, Wilson centre p0 or high."""
        if got is None:
            return None
        lo, hi, y, n = got
        if rank == Rank.LOW:
            return lo
        if rank == Rank.HIGH:
            return hi
        return float(intervals.p0(y, n, self.alpha))

    def room_share(self, type_name: str) -> float | None:
        """The share of segments with furniture holding a ``type_name``; None without any."""
        if self.rooms == 0:
            return None
        return self.holding.get(type_name, 0) / self.rooms
