"""Travel and examination seconds estimated on the occupancy grid: the cost model the learning
loop (agent.acquisition) hands the strategies (agent.strategies)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.envs.robot_spec import RobotPose, TimeModel
from ctxsearch.knowledge.geometry import Box, ObjectInstance


class GridCosts:
    """Travel and examination seconds estimated on the occupancy grid (for the strategies).

    Travel: the driving distance along the grid from the robot to the nearest free cell within
    ``standoff`` of the object's footprint (where the view planner will put the base), over the
    drive speed. Examination: travel plus the head moves and images of the gazes planned for the
    object (from where the object was first a candidate; cached per object).
    """

    def __init__(
        self,
        grid: OccupancyGrid,
        time_model: TimeModel,
        gaze_seconds: Callable[[ObjectInstance], float],
        standoff: float = 1.0,
    ):
        self.grid, self.tm, self.standoff = grid, time_model, standoff
        self._gaze_seconds = gaze_seconds
        self._approach: dict[int, np.ndarray] = {}
        self._pose: RobotPose | None = None
        self._field: np.ndarray | None = None
        xs, ys = grid.cell_centers()
        self._cells = np.column_stack([np.tile(xs, len(ys)), np.repeat(ys, len(xs))])
        self._free_flat = grid.free.ravel()

    def at(self, pose: RobotPose) -> GridCosts:
        """Estimates from ``pose`` (the distance field is computed lazily, once per pose)."""
        if self._pose is None or (pose.x, pose.y) != (self._pose.x, self._pose.y):
            self._field = None
        self._pose = pose
        return self

    def _approach_cells(self, obj: ObjectInstance) -> np.ndarray:
        """Flat indices of the free cells within ``standoff`` of the object's footprint (within
        2.5 m if there are none); cached per object."""
        cells = self._approach.get(obj.id)
        if cells is None:
            box = obj.box()
            cells = self._cells_near(box, self.standoff)
            if not len(cells):
                cells = self._cells_near(box, 2.5)
            self._approach[obj.id] = cells
        return cells

    def _cells_near(self, box: Box, reach: float) -> np.ndarray:
        g = self.grid
        h, w = g.shape
        r = float(np.hypot(box.half[0], box.half[1])) + reach
        r0, c0 = g.to_cell(box.center[:2] - r)  # (row, col) of the window's corners
        r1, c1 = g.to_cell(box.center[:2] + r)
        r0, c0, r1, c1 = max(0, r0), max(0, c0), min(h - 1, r1), min(w - 1, c1)
        rows, cols = np.mgrid[r0 : r1 + 1, c0 : c1 + 1]
        flat = (rows * w + cols).ravel()
        dist = box.footprint_distance(self._cells[flat])
        return flat[self._free_flat[flat] & (dist <= reach)]

    def travel_s(self, obj: ObjectInstance) -> float:
        """Seconds to drive to where ``obj`` is examined from."""
        if self._field is None:
            self._field = self.grid.distances_from(self._pose.xy).ravel()
        cells = self._approach_cells(obj)
        dist = float(self._field[cells].min()) if len(cells) else math.inf
        if not math.isfinite(dist):  # unreachable: the straight line, as a fallback
            dist = math.hypot(obj.position[0] - self._pose.x, obj.position[1] - self._pose.y)
        return self.tm.travel_time(dist)

    def examine_s(self, obj: ObjectInstance) -> float:
        """travel_s plus the planned gazes' head moves and images."""
        return self.travel_s(obj) + self._gaze_seconds(obj)
