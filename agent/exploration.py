"""Figure 2, lines 4-7: find a nearby recognizable object not yet examined, by looking around and
touring the room's free space (``Explorer``, driven by agent.acquisition's ``RoomLearner``, which
is an ``ExploringRoom``)."""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from ctxsearch.agent import strategies as strat
from ctxsearch.agent.grid_costs import GridCosts
from ctxsearch.agent.interfaces import Body
from ctxsearch.agent.navigation import OccupancyGrid, nearest_free
from ctxsearch.knowledge.geometry import ObjectInstance

LOOK_TILT = -0.35  # rad: the look-around tilt (sees the floor from about 1 m out and desk tops)
LOOK_PANS_DEG = (-150.0, -90.0, -30.0, 30.0, 90.0, 150.0)  # a 360 degree sweep in six images


class ExploringRoom(Protocol):
    """What the explorer needs of the room it explores."""

    body: Body
    grid: OccupancyGrid
    costs: GridCosts

    def budget_spent(self) -> bool:
        """True once the room's time budget is used up."""
        ...

    def drive_to(self, xy: np.ndarray) -> None:
        """Drive along a planned path to ``xy``."""
        ...

    def look(self, purpose: str) -> list[ObjectInstance]:
        """Take an image where the head points and return what it recognizes."""
        ...

    def reference(self, obj: ObjectInstance) -> ObjectInstance | None:
        """``obj`` once it may be examined (its perception's ``reference``), else None."""
        ...


class Explorer:
    """Figure 2, line 5: find a nearby recognizable object not yet examined.

    Remembers every object its look-arounds recognized. Asked for an object, it returns the
    nearest remembered one not in EXAMINED; failing that it looks around at the current spot
    (unless it already looked within ``spacing / 2``), then drives to the nearest unvisited
    viewpoint of a tour (a ``spacing`` lattice over the reachable free space) and looks there,
    until it has one or the tour is over (None: the room is done; ``out_of_time`` says whether
    the room's time budget ended it).
    """

    def __init__(self, room: ExploringRoom, start_xy: np.ndarray, spacing: float = 1.5):
        self.L = room
        self.spacing = spacing
        self.seen: dict[int, ObjectInstance] = {}
        self.looks: list[np.ndarray] = []
        self.out_of_time = False
        grid = room.grid
        reach = grid.reachable_mask(start_xy)
        xs, ys = grid.cell_centers()
        pts = []
        for y in np.arange(ys[0] + spacing / 2, ys[-1] + 1e-9, spacing):
            for x in np.arange(xs[0] + spacing / 2, xs[-1] + 1e-9, spacing):
                p = nearest_free(grid, np.array([x, y]), reach)
                if p is not None and np.hypot(*(p - (x, y))) <= spacing / 2:
                    pts.append(p)
        # deduplicate (two lattice points may snap to one cell)
        uniq: list[np.ndarray] = []
        for p in pts:
            if all(np.hypot(*(p - q)) > 1e-6 for q in uniq):
                uniq.append(p)
        self.todo = uniq

    def find(self, examined: set[int]) -> ObjectInstance | None:
        """A recognizable object not in ``examined`` (the nearest known), or None."""
        L = self.L
        while True:
            seen = [o for oid, o in sorted(self.seen.items()) if oid not in examined]
            cands = [c for c in map(L.reference, seen) if c is not None]  # confirmed ones
            if cands:
                return strat.nearest_object(cands, L.costs.at(L.body.pose()))
            if L.budget_spent():  # no new exploration step once the room's time is spent
                self.out_of_time = True
                return None
            here = L.body.pose().xy
            if not any(np.hypot(*(here - q)) <= self.spacing / 2 for q in self.looks):
                self.look_around()
                continue
            if not self.todo:
                return None
            field = L.grid.distances_from(here)
            d = [field[L.grid.to_cell(p)] for p in self.todo]
            k = int(np.argmin(d))
            if not math.isfinite(d[k]):
                self.todo = []
                return None
            goal = self.todo.pop(k)
            L.drive_to(goal)
            if L.budget_spent():
                self.out_of_time = True
                return None
            self.look_around()

    def look_around(self) -> None:
        """A pan sweep at the current spot: six images, everything recognized is remembered."""
        L = self.L
        p = L.body.pose()
        self.looks.append(p.xy)
        self.todo = [q for q in self.todo if np.hypot(*(q - p.xy)) > self.spacing / 2]
        pans = [math.radians(a) for a in LOOK_PANS_DEG]
        if abs(p.pan - pans[-1]) < abs(p.pan - pans[0]):
            pans = pans[::-1]
        for pan in pans:
            L.body.move_head(pan, LOOK_TILT)
            for o in L.look("look"):
                self.seen.setdefault(o.id, o)
