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
"""

from __future__ import annotations

import numpy as np

from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.room_segmentation import RoomLabels
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.ranking import ProbabilitySource

MIN_FACTOR = 0.1
MAX_FACTOR = 10.0


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
    ):
        self.probs, self.target, self.catalog = probs, target, catalog
        self.points = np.asarray(points, float)
        self.share = probs.room_share(target)
        self.plan = plan
        self._plan_rooms = plan.at(self.points) if plan is not None else None
        self._built_key: int | None = None
        self._built: tuple[RoomLabels, np.ndarray] | None = None

    @classmethod
    def for_search(
        cls,
        probs: ProbabilitySource | None,
        target: str,
        catalog: Catalog,
        points: np.ndarray,
        plan: RoomLabels | None,
    ) -> RoomPrior | None:
        """The room prior if ``probs`` knows room context for ``target``, else None."""
        if probs is None:
            return None
        share = probs.room_share(target)
        if share is None or share <= 0:
            return None
        return cls(probs, target, catalog, points, plan)

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
        return self._built

    def room_ratios(self, known: list[ObjectInstance], labels: RoomLabels) -> dict[int, float]:
        """The clipped ratio f_R of every room holding known furniture with a room probability
        for the target (module docstring)."""
        out: dict[int, float] = {}
        furniture = [o for o in known if self.catalog.type(o.type).is_furniture]
        if not furniture:
            return out
        where = labels.of_objects(furniture)
        for o, r in zip(furniture, where, strict=True):
            p = self.probs.same_room(o.type, self.target)
            if r < 0 or p is None:
                continue
            f = float(np.clip(p / self.share, MIN_FACTOR, MAX_FACTOR))
            out[int(r)] = max(out.get(int(r), 0.0), f)
        return out

    def factor(self, known: list[ObjectInstance], built: BuiltMap | None) -> np.ndarray | None:
        """(N,) the room factor of every point (module docstring); None where no room with
        known furniture is known yet."""
        got = self.rooms(built)
        if got is None:
            return None
        labels, point_rooms = got
        ratios = self.room_ratios(known, labels)
        if not ratios:
            return None
        f = np.ones(len(self.points))
        for r, ratio in ratios.items():
            f[point_rooms == r] = ratio
        return f


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
