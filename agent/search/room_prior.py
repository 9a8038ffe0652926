"""Room context in the belief: the room a piece of furniture stands in tells
the robot how likely the target is anywhere in that room, before it looks there.

For a known furniture instance of type F standing in room R of the robot's map, the source's
P(SAME-ROOM-AS-F(T)) is the probability that R holds an instance of the target type T; the
share of all rooms holding a T (``ProbabilitySource.room_share``) is what a room nothing is known
about holds. Every point of R has its prior density multiplied by the ratio

    f_R = P_R / share(T),    P_R = max over the known furniture F in R of P(SAME-ROOM-AS-F(T)),

clipped to [``MIN_FACTOR``, ``MAX_FACTOR``]; a point in no room, or in a room without known
furniture, keeps its density (f = 1). Choices of this module, not the paper's (which leaves
rooms out, section 2.1), each stated so it can be measured:

- The ratio multiplies the object-centred density (the relation volumes and the rest alike): a
  naive-Bayes combination that takes the room and the object-centred relations as independent
  evidence. A Cup volume on a cabinet in a bathroom is worth less than the same volume in a
  kitchen.
- Several furniture types in one room: the largest of their probabilities, an optimistic rule.
  Pairwise statistics cannot be combined exactly (what a room holds depends on its kind, which
  the counts do not name), and the errors are not symmetric: a room wrongly played down sends
  the robot away from the target for the rest of the search, one wrongly played up costs a
  look. The most telling type (the ratio furthest from 1) would rule out an office for a Laptop
  because offices have shelves (apartment: Desk 2.8, Shelf 0.1); the largest probability
  keeps it, and pays for it in a kitchen, whose table (0.6) outvotes its fridge (0.0) for a
  Remote. Not their noisy-or or product: a Fridge and a Counter in one kitchen are one piece of
  evidence about the kitchen, not two.
- The floor ``MIN_FACTOR`` keeps a room the statistics rule out searchable: the robot's rooms
  are segmented from its own map and may join two of the plan's, and a learned interval's
  zero is never certain. The cap ``MAX_FACTOR`` bounds a rare type's ratio.

Rooms: on the given map the plan's (``WorldMaps.plan_rooms``); on the built map the segmentation of
the robot's map as it stands (agent.room_segmentation, recomputed when the map has new images),
so the rooms of furniture seen beyond the mapped floor are not known yet and their points keep
f = 1.

Beyond the mapped rooms (``knowledge.next_rooms``, built map only): a point in no segment lies in
space the robot has not mapped, most of it through a door of a mapped room. Within
``knowledge.next_room_m`` of the nearest segment it takes

    g = clip(P_next / share(T)),  P_next = max over the known furniture F of the nearest segment
        of P(NEXT-ROOM-OF-F(T)) (knowledge.room_context: a room a door of a room holding F
        leads to holds a T),

and, within ``knowledge.glimpse_m`` of furniture seen beyond the mapped floor (glimpsed through a
door: it stands in the room there), that furniture's room ratio P(SAME-ROOM-AS-F(T)) / share(T)
instead (the largest where several are that close). Choices of this module, each a setting:

- The nearest segment is by straight-line distance on the map's grid
  (``scipy.ndimage.distance_transform_edt``): the space beyond a door goes with the room the door
  opens from and, behind a wall, with the nearer room.
- The room a door leads to is taken to reach ``next_room_m`` (4 m, about a room's depth) behind
  the mapped room's edge; unmapped space further on, rooms beyond the next, keeps f = 1 (the
  house's average): the relation is about the next room, and a bedroom's door that opens onto
  the living room says little of the study behind it.
- The unmapped rest of a partly mapped room takes the next room's ratio too (the robot's first
  look around maps most of the room it stands in).

Without next-room knowledge of the nearest segment's furniture a point keeps f = 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt

from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.room_segmentation import RoomLabels
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.ranking import ProbabilitySource

MIN_FACTOR = 0.1
MAX_FACTOR = 10.0


@dataclass(frozen=True)
class Beyond:
    """How the space beyond the built map's rooms takes the next-room relations (module
    docstring; ``knowledge.next_room_m``, ``knowledge.glimpse_m``)."""

    next_room_m: float = 4.0
    glimpse_m: float = 2.0


class RoomPrior:
    """The room factor of every seen-map point (``points`` (N, 3)) for target ``target`` under
    ``probs``'s room context, on the given map's rooms ``plan`` or else the built map's."""

    def __init__(
        self,
        probs: ProbabilitySource,
        target: str,
        catalog: Catalog,
        points: np.ndarray,
        plan: RoomLabels | None,
        beyond: Beyond | None = None,
    ):
        self.probs, self.target, self.catalog = probs, target, catalog
        self.points = np.asarray(points, float)
        self.share = probs.room_share(target)
        self.plan = plan
        self.next = beyond  # the space beyond the mapped rooms (module docstring): None: off
        self._plan_rooms = plan.at(self.points) if plan is not None else None
        self._built_key: int | None = None
        self._built: tuple[RoomLabels, np.ndarray] | None = None
        # each point's nearest segment of the built map and its distance to it (m)
        self._nearest: tuple[np.ndarray, np.ndarray] | None = None

    @classmethod
    def for_search(
        cls,
        probs: ProbabilitySource | None,
        target: str,
        catalog: Catalog,
        points: np.ndarray,
        plan: RoomLabels | None,
        beyond: Beyond | None = None,
    ) -> RoomPrior | None:
        """The room prior if ``probs`` knows room context for ``target``, else None; with
        ``beyond`` (the built map only: without the plan's rooms) also for the space beyond the
        mapped rooms."""
        if probs is None:
            return None
        share = probs.room_share(target)
        if share is None or share <= 0:
            return None
        return cls(probs, target, catalog, points, plan, None if plan is not None else beyond)

    def rooms(self, built: BuiltMap | None) -> tuple[RoomLabels, np.ndarray] | None:
        """The rooms in use and each point's room: the plan's, or the built map's segmentation
        (recomputed when the map took new images)."""
        if self.plan is not None:
            return self.plan, self._plan_rooms
        if built is None:
            return None
        if self._built is None or self._built_key != built.images:
            labels = RoomLabels.of_built(built)
            self._built = (labels, labels.at(self.points))
            self._built_key = built.images
            self._nearest = None
        return self._built

    def nearest(self) -> tuple[np.ndarray, np.ndarray] | None:
        """((N,) the segment of the built map nearest to each point (-1: no segment yet), (N,)
        the distance to it in m), as the rooms now stand (``rooms`` called first)."""
        if self._built is None:
            return None
        if self._nearest is None:
            labels, _ = self._built
            lab = labels.labels
            n = len(self.points)
            if not (lab >= 0).any():
                self._nearest = (np.full(n, -1, np.int64), np.full(n, np.inf))
                return self._nearest
            dist, (rows, cols) = distance_transform_edt(lab < 0, return_indices=True)
            h, w = lab.shape
            col = np.floor((self.points[:, 0] - labels.x0) / labels.resolution).astype(np.int64)
            row = np.floor((self.points[:, 1] - labels.y0) / labels.resolution).astype(np.int64)
            row, col = np.clip(row, 0, h - 1), np.clip(col, 0, w - 1)
            self._nearest = (
                lab[rows[row, col], cols[row, col]].astype(np.int64),
                dist[row, col] * labels.resolution,
            )
        return self._nearest

    def placed(self, known: list[ObjectInstance], labels: RoomLabels) -> list[tuple]:
        """The known furniture with the segment each stands in (-1: beyond the mapped floor)."""
        furniture = [o for o in known if self.catalog.type(o.type).is_furniture]
        if not furniture:
            return []
        return list(zip(furniture, labels.of_objects(furniture).tolist(), strict=True))

    def ratio(self, p: float | None) -> float | None:
        """A probability over the target's share of rooms, clipped (module docstring)."""
        return None if p is None else float(np.clip(p / self.share, MIN_FACTOR, MAX_FACTOR))

    def room_ratios(self, placed: list[tuple]) -> dict[int, float]:
        """The clipped ratio f_R of every room holding known furniture (``placed``) with a room
        probability for the target (module docstring)."""
        out: dict[int, float] = {}
        for o, r in placed:
            f = self.ratio(self.probs.same_room(o.type, self.target))
            if r >= 0 and f is not None:
                out[r] = max(out.get(r, 0.0), f)
        return out

    def next_ratios(
        self, placed: list[tuple]
    ) -> tuple[dict[int, float], list[tuple[ObjectInstance, float]]]:
        """The space beyond the mapped rooms (module docstring): the clipped next-room ratio g of
        every segment holding known furniture (``placed``) with a next-room probability for the
        target, and the furniture seen beyond the mapped floor with its room ratio."""
        out: dict[int, float] = {}
        glimpsed: list[tuple[ObjectInstance, float]] = []
        for o, r in placed:
            if r < 0:
                f = self.ratio(self.probs.same_room(o.type, self.target))
                if f is not None:
                    glimpsed.append((o, f))
                continue
            g = self.ratio(self.probs.next_room(o.type, self.target))
            if g is not None:
                out[r] = max(out.get(r, 0.0), g)
        return out, glimpsed

    def beyond(self, placed: list[tuple], point_rooms: np.ndarray) -> np.ndarray | None:
        """(N,) the factor of the points in no segment (module docstring; 1 elsewhere), None
        where nothing is known of what lies beyond (``placed``: the known furniture and its
        segments)."""
        ratios, glimpsed = self.next_ratios(placed)
        if not ratios and not glimpsed:
            return None
        out = np.ones(len(self.points))
        outside = point_rooms < 0
        nearest, dist = self.nearest()
        next_room = outside & (dist <= self.next.next_room_m)
        for r, g in ratios.items():
            out[next_room & (nearest == r)] = g
        if glimpsed:
            idx = np.flatnonzero(outside)
            xy = self.points[idx, :2]
            best = np.zeros(len(idx))
            for o, ratio in glimpsed:
                near = np.hypot(xy[:, 0] - o.position[0], xy[:, 1] - o.position[1])
                close = near <= self.next.glimpse_m
                best[close] = np.maximum(best[close], ratio)
            got = best > 0
            out[idx[got]] = best[got]
        return out

    def factor(self, known: list[ObjectInstance], built: BuiltMap | None) -> np.ndarray | None:
        """(N,) the room factor of every point (module docstring); None where no room with
        known furniture is known yet (nor, with the space beyond the mapped rooms, anything of
        what lies beyond them)."""
        got = self.rooms(built)
        if got is None:
            return None
        labels, point_rooms = got
        placed = self.placed(known, labels)
        ratios = self.room_ratios(placed)
        beyond = None
        if self.next is not None and self.plan is None:
            beyond = self.beyond(placed, point_rooms)
        if not ratios and beyond is None:
            return None
        f = np.ones(len(self.points)) if beyond is None else beyond
        for r, ratio in ratios.items():
            f[point_rooms == r] = ratio
        return f

    def beyond_groups(self, weights: np.ndarray | None) -> list[tuple[int, np.ndarray, float]]:
        """The belief ``weights`` (N,) of the space beyond the mapped rooms, by the segment it
        lies beyond: (segment, the mass-weighted centre (3,), the mass) for each segment with
        mass there (for the recording: the mass expected behind each room's doors and
        frontiers); empty off the built map or before any segment."""
        if weights is None or self._built is None or self.next is None:
            return []
        _, point_rooms = self._built
        nearest, _ = self.nearest()
        outside = point_rooms < 0
        out = []
        for r in np.unique(nearest[outside & (nearest >= 0)]):
            sel = outside & (nearest == r)
            mass = float(weights[sel].sum())
            if mass > 0:
                centre = (weights[sel, None] * self.points[sel]).sum(axis=0) / mass
                out.append((int(r), centre, mass))
        return out


# A handed bound's factor where its knowledge rules the target out (a room of a kind that never
# holds it, a room the target is not in, a point in no room): small, not 0, so that no point is
# ever unsearchable and a search that misses keeps going.
HANDED_FLOOR = 0.01


class HandedRooms:
    """A bound's room knowledge, handed at the start and fixed (agent.search.registry's
    ``handed``): each plan room's factor on the prior density (``factors``: plan room index ->
    factor, at least ``HANDED_FLOOR``; a room not listed and a point in no room get the floor).
    Made by the episode runner from the true plan: with every room's kind, the true density
    ratio of the target by kind (envs.truth.RoomKindTruth); with the target's rooms, 1 there.
    It multiplies the frontier's every-point-alike prior, so the difference to ``frontier`` is
    the room knowledge alone."""

    def __init__(self, labels: RoomLabels, factors: dict[int, float]):
        self.labels = labels
        self.factors = {int(k): max(float(v), HANDED_FLOOR) for k, v in factors.items()}

    def factor(self, points: np.ndarray) -> np.ndarray:
        """(N,) the factor of every point of ``points`` (N, 3)."""
        rooms = self.labels.at(np.asarray(points, float))
        f = np.full(len(rooms), HANDED_FLOOR)
        for r, v in self.factors.items():
            f[rooms == r] = v
        return f
