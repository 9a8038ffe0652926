"""Small objects from one day to the next: which of them stay, and which did.

A world's day d is made from its day d - 1 (``envs.rooms``' days): first every small object of
day d - 1 is kept with its type's stay probability (``Style.stay``; ``choose_stayers``, on a
random stream of its own), then the day's placement runs as it would from scratch, except that
an instance of a type with unused stayers takes one of them (``Credits``) instead of being
placed anew; stayers that no placement took stay as well. So a type holds that day the larger
of its stayers and the day's draw (its rules, their drift), an object stays with its type's
probability (a design that let the day's smaller draw send stayers away measured a third to a
half of that probability in living rooms), and an object that stays keeps its exact pose, its
support and (in a single room) its id.

Across days, an object that stayed is identified by its type and exact pose: ``stayed`` gives
the objects of a later layout that stand where an object of the same type stood before (a
house renumbers its small objects every day, so an id does not carry over).

Day d of a world is thus a chain of d day steps from day 0. ``DayMemo`` keeps, in memory only,
the latest day made of each of the last rooms asked for, so that asking for a room's days in
turn (``learn --days``, the day before and the day of a search) costs one step per day.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterable
from dataclasses import dataclass

import numpy as np

from ctxsearch.envs.layout import Door, RoomLayout
from ctxsearch.envs.parts import WorldSurface
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.geometry import ObjectInstance

POSE_TOL = 1e-6  # metres and radians: "the same pose" in ``stayed``


@dataclass(frozen=True)
class DayState:
    """What one day of a room hands to the next: its shell and contents, with what each object
    rests on (``support``: the id, ``resting``: the surface) and the rule that placed it."""

    width: float
    depth: float
    height: float
    doors: tuple[Door, ...]
    objects: tuple[ObjectInstance, ...]
    support: dict[int, int | None]
    placed_by: dict[int, tuple[int, str]]
    resting: dict[int, WorldSurface | None]


class DayMemo:
    """The latest day made of each of the last ``size`` rooms (keyed by everything the room's
    days depend on), in memory only; a day is the same whether it comes from here or from day 0."""

    def __init__(self, size: int):
        self.size = size
        self._days: OrderedDict[Hashable, tuple[int, DayState]] = OrderedDict()

    def start(self, key: Hashable, day: int) -> tuple[int, DayState] | None:
        """The latest kept (day, state) of the room ``key`` that is not after ``day``."""
        hit = self._days.get(key)
        if hit is None or hit[0] > day:
            return None
        self._days.move_to_end(key)
        return hit

    def keep(self, key: Hashable, day: int, state: DayState) -> None:
        """Keep ``state`` as the room's latest day (the least recently used room goes)."""
        self._days[key] = (day, state)
        self._days.move_to_end(key)
        while len(self._days) > self.size:
            self._days.popitem(last=False)

    def clear(self) -> None:
        """Forget every room."""
        self._days.clear()


def choose_stayers(
    objects: Iterable[ObjectInstance],
    support: dict[int, int | None],
    stay: Callable[[str], float],
    catalog: Catalog,
    rng: np.random.Generator,
) -> list[ObjectInstance]:
    """The small objects of a day that stay to the next, in order: each draws one number from
    ``rng`` (every small object, in order, so the stream does not depend on the outcome) and
    stays when it is below ``stay(type)``; one resting on a small object that left leaves too."""
    gone: set[int] = set()
    out = []
    for o in objects:
        if catalog.type(o.type).is_furniture:
            continue
        u = float(rng.random())
        if u < stay(o.type) and support.get(o.id) not in gone:
            out.append(o)
        else:
            gone.add(o.id)
    return out


class Credits:
    """The stayers of a day that no placement of the day has taken yet, per type. A placement of
    an instance of a type with some left takes one (``take``): first one that the same rule put
    there (same reference and relation; none for clutter), else the first in order."""

    def __init__(self, stayers: list[ObjectInstance], placed_by: dict[int, tuple[int, str]]):
        self.left: dict[str, list[ObjectInstance]] = {}
        for o in stayers:
            self.left.setdefault(o.type, []).append(o)
        self.placed_by = placed_by

    def take(self, type_name: str, placed_by: tuple[int, str] | None = None) -> bool:
        """Take a stayer of ``type_name`` for a placement (False: none left, place one anew)."""
        queue = self.left.get(type_name)
        if not queue:
            return False
        k = next((i for i, o in enumerate(queue) if self.placed_by.get(o.id) == placed_by), 0)
        queue.pop(k)
        return True

    def pending(self) -> set[int]:
        """The ids of the stayers not taken (yet): not references of the day's rules."""
        return {o.id for queue in self.left.values() for o in queue}


def same_pose(a: ObjectInstance, b: ObjectInstance, tol: float = POSE_TOL) -> bool:
    """Same type, position, yaw (mod 2 pi) and size within ``tol``."""
    if a.type != b.type:
        return False
    dyaw = abs(math.remainder(a.yaw - b.yaw, 2 * math.pi))
    return (
        dyaw <= tol
        and all(abs(x - y) <= tol for x, y in zip(a.position, b.position, strict=True))
        and all(abs(x - y) <= tol for x, y in zip(a.size, b.size, strict=True))
    )


def stayed(before: RoomLayout, after: RoomLayout) -> set[int]:
    """The ids (in ``after``) of the objects at the same type and exact pose (``POSE_TOL``) as an
    object of ``before``: what did not move from one layout of a world to another (furniture
    included; keep the small types to ask which small objects stayed)."""
    by_type: dict[str, list[ObjectInstance]] = {}
    for o in before.objects:
        by_type.setdefault(o.type, []).append(o)
    return {o.id for o in after.objects if any(same_pose(o, b) for b in by_type.get(o.type, ()))}
