"""Figure 2, lines 4-7 on the robot's own map: explore frontiers for an unexamined object.

``FrontierExplorer`` is the ``--map built`` counterpart of agent.exploration's ``Explorer`` (the
same ``find`` / ``look_around`` interface, driven by agent.acquisition's ``RoomLearner``). It
knows no layout: it drives only through cells its agent.mapping ``BuiltMap`` knows free, and goes
where the map ends.

A *frontier* cell is a floor cell next to an unknown one. A *goal* is a free (navigable) cell
within ``view_reach`` of a frontier cell not yet exhausted, reachable from the robot. After a
look-around at a spot, every frontier cell within ``done_radius`` (> ``view_reach``) of it is
exhausted: what is still unknown there cannot be seen from nearby (under furniture, behind a
wardrobe). Each look-around exhausts the frontier cell its goal was chosen for, so exploration
ends. The world is done when no goal is left (no frontier) and nothing recognized is unexamined.

The rule that picks the goal (``FRONTIER_RULES``):

- ``info`` (the default): the goal with the most information per second: unknown cells within
  ``info_radius`` of it over (travel seconds + one look-around's images);
- ``nearest``: the goal with the shortest driving distance.

Measured on apartments 0-3 (full exploration, ``ctxsearch bench sim --style apartment --rooms 4
--explore 4 --frontier-rule R``): ``info`` reached the same free recall (0.903, 0.896, 0.863,
0.897) as ``nearest`` (0.903, 0.896, 0.864, 0.897) in 594-691 simulated seconds against 685-944
(medians 649 s against 815 s), with about half the goals (31-40 against 52-73).

A look-around is ``LOOK_PANS_DEG`` at two tilts: ``LOOK_TILT`` (furniture, desk tops, far floor)
and ``NEAR_TILT`` (the floor from about 0.1 m to 2.2 m, which the first tilt misses: without it
the robot could never know the floor around itself free; agent.sight, shared with the search's
exploration).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from ctxsearch.agent import strategies as strat
from ctxsearch.agent.exploration import LOOK_PANS_DEG, LOOK_TILT, ExploringRoom
from ctxsearch.agent.grid_costs import GridCosts
from ctxsearch.agent.interfaces import Body
from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.navigation import OccupancyGrid, plan_path
from ctxsearch.agent.sight import NEAR_TILT
from ctxsearch.envs.robot_spec import TimeModel
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.options import FrontierRule, values

FRONTIER_RULES = values(FrontierRule)


class FrontierExplorer:
    """Figure 2, line 5 on a built map: the nearest recognized unexamined object, else explore the
    next frontier goal (module docstring) and look around there; None when no goal is left
    (``out_of_time`` says whether the time budget ended it)."""

    def __init__(
        self,
        room: ExploringRoom,
        built: BuiltMap,
        time_model: TimeModel,
        rule: str = "info",
        view_reach: float = 0.8,
        done_radius: float = 1.0,
        info_radius: float = 2.0,
    ):
        if rule not in FRONTIER_RULES:
            raise ValueError(f"unknown frontier rule {rule!r} (known: {', '.join(FRONTIER_RULES)})")
        self.L, self.map, self.tm, self.rule = room, built, time_model, rule
        self.view_reach, self.done_radius, self.info_radius = view_reach, done_radius, info_radius
        self.seen: dict[int, ObjectInstance] = {}
        self.looks: list[np.ndarray] = []
        self.deferred: set[int] = set()  # recognized, not examinable from the map known so far
        self.exhausted = np.zeros(built.floor.shape, bool)
        self.out_of_time = False
        self.final = False  # no goal is left: deferred objects are not deferred again
        self.goals = 0  # frontier goals driven to

    def find(self, examined: set[int]) -> ObjectInstance | None:
        """A recognizable object not in ``examined`` (the nearest known), or None."""
        L = self.L
        while True:
            skip = examined | self.deferred
            seen = [o for oid, o in sorted(self.seen.items()) if oid not in skip]
            cands = [c for c in map(L.reference, seen) if c is not None]  # confirmed ones
            if cands:
                return strat.nearest_object(cands, L.costs.at(L.body.pose()))
            if L.budget_spent():
                self.out_of_time = True
                return None
            if not self.looks:
                self.look_around()
                continue
            goal = None if self.final else self.next_goal()
            if goal is None:
                self.final = True
                if self.deferred:  # examinable or not, they are tried once more now
                    self.deferred.clear()
                    continue
                return None
            self.goals += 1
            L.drive_to(goal)
            if L.budget_spent():
                self.out_of_time = True
                return None
            self.look_around()

    def next_goal(self) -> np.ndarray | None:
        """The next frontier goal by the rule (module docstring), or None."""
        grid = self.map.refresh()
        front = self.map.frontier() & ~self.exhausted
        if not front.any():
            return None
        here = self.L.body.pose().xy
        dist = grid.distances_from(here)
        near_front = ndimage.distance_transform_edt(~front) * grid.resolution <= self.view_reach
        ok = grid.free & np.isfinite(dist) & near_front
        if not ok.any():
            return None
        if self.rule == FrontierRule.NEAREST:
            score = np.where(ok, -dist, -np.inf)
        else:
            k = 2 * int(round(self.info_radius / grid.resolution)) + 1
            unknown = ndimage.uniform_filter(self.map.unknown.astype(float), size=k) * k * k
            secs = self.tm.travel_time(dist) + self.look_seconds()
            score = np.where(ok, unknown / secs, -np.inf)
        r, c = np.unravel_index(int(np.argmax(score)), score.shape)
        return grid.to_xy(int(r), int(c))

    def look_seconds(self) -> float:
        """The images of one look-around (head slews left out: the same for every goal)."""
        return 2 * len(LOOK_PANS_DEG) * self.tm.image_cost

    def defer(self, object_id: int) -> bool:
        """Put a recognized object that cannot be examined yet aside until the next look-around;
        False once no frontier goal is left (it is then unexaminable)."""
        if self.final:
            return False
        self.deferred.add(object_id)
        return True

    def look_around(self) -> None:
        """Pan sweeps at two tilts: every image updates the map, everything recognized is
        remembered; frontier cells near here are exhausted; deferred objects are retried."""
        L = self.L
        p = L.body.pose()
        self.looks.append(p.xy)
        pans = [math.radians(a) for a in LOOK_PANS_DEG]
        if abs(p.pan - pans[-1]) < abs(p.pan - pans[0]):
            pans = pans[::-1]
        for tilt in (LOOK_TILT, NEAR_TILT):
            for pan in pans:
                L.body.move_head(pan, tilt)
                for o in L.look("look"):
                    self.seen.setdefault(o.id, o)
            pans = pans[::-1]
        xs, ys = self.map.refresh().cell_centers()
        self.exhausted |= np.hypot(xs[None, :] - p.x, ys[:, None] - p.y) <= self.done_radius
        self.deferred.clear()


@dataclass
class _MapOnlyRoom:
    """An ``ExploringRoom`` that only maps (``explore_world``): images update the map, nothing is
    recognized, every planned drive is kept."""

    body: Body
    built: BuiltMap
    time_model: TimeModel
    budget_s: float | None = None
    paths: list[np.ndarray] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._t0 = self.body.sim_time
        self._costs = GridCosts(self.grid, self.time_model, lambda _o: 0.0)

    @property
    def grid(self) -> OccupancyGrid:
        """The map's grid as it stands."""
        return self.built.grid

    @property
    def costs(self) -> GridCosts:
        """The cost model on the current grid (unused: nothing is recognized)."""
        return self._costs

    def budget_spent(self) -> bool:
        """True once ``budget_s`` simulated seconds have passed."""
        return self.budget_s is not None and self.body.sim_time - self._t0 >= self.budget_s

    def drive_to(self, xy: np.ndarray) -> None:
        """Drive along a path planned on the map (kept in ``paths``)."""
        path = plan_path(self.grid, self.body.pose().xy, xy)
        if path is None or len(path) < 2:
            return
        self.paths.append(path)
        seg = path[-1] - path[-2]
        self.body.drive(path, math.atan2(seg[1], seg[0]))

    def reference(self, obj: ObjectInstance) -> ObjectInstance | None:
        """Nothing is recognized, so nothing is asked: ``obj``."""
        return obj

    def look(self, purpose: str) -> list[ObjectInstance]:
        """One depth image into the map; recognizes nothing."""
        self.built.update(self.body.capture(rgb=False, depth=True))
        return []


@dataclass(frozen=True)
class Exploration:
    """A full exploration of one world (``explore_world``)."""

    built: BuiltMap
    sim_s: float  # simulated seconds from the first image to the last
    goals: int  # frontier goals driven to
    looks: int  # look-arounds
    paths: list[np.ndarray]  # every planned drive (K, 2)


def explore_world(
    body: Body,
    built: BuiltMap,
    time_model: TimeModel,
    rule: str = "info",
    budget_s: float | None = None,
) -> Exploration:
    """Explore frontiers from where ``body`` stands until no goal is left (or ``budget_s``
    simulated seconds have passed), building ``built``; nothing is examined."""
    room = _MapOnlyRoom(body, built, time_model, budget_s)
    ex = FrontierExplorer(room, built, time_model, rule)
    t0 = body.sim_time
    ex.find(set())
    return Exploration(built, body.sim_time - t0, ex.goals, len(ex.looks), room.paths)
