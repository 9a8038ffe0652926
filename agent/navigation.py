"""Navigation: an occupancy grid of the room and shortest collision-free paths on it.

The robot is a disc of radius ``spec.base_radius`` driving on the floor, with a mast and a head
up to ``spec.camera_height``. The grid marks a cell *blocked* when its centre lies within
``spec.clearance`` (base radius + margin) of an obstacle's footprint or of a wall, so the base
centre may go anywhere a free cell is.

Obstacles. Every object whose bounding box starts below the head (``bottom < camera_height``)
blocks its whole ground-plane footprint (its yaw-only bounding rectangle). That includes the
free space under a desk or table top: the base would fit under it, but the mast and head would
hit the top, so furniture is treated as solid from the floor up. Small objects on furniture lie
inside the furniture's footprint anyway; small objects on the floor (a plant, a bin) block too.
Using the bounding rectangle is conservative: it contains every solid part of the object.

Walls: the room spans x in [-width/2, width/2] and y in [-depth/2, depth/2]; every cell closer
than the clearance to that boundary is blocked (the robot never leaves through the door).

Planning: shortest paths on the 8-connected grid (moves of 1 or sqrt(2) cells; no diagonal
move squeezes between two blocked cells), then greedy line-of-sight shortcutting so a path is a
few straight segments. The search is Dijkstra's algorithm with a binary heap, run in C by
``scipy.sparse.csgraph`` on a graph built once per grid: one search from the robot's position
gives the driving distance to *every* cell (the view planner ranks many candidate viewpoints by
it) and every path from there, several times faster than a pure-Python A* when the straight
route is blocked.

Caches. A grid is treated as immutable once built (nothing may change ``free`` afterwards): its
graph, connected components, candidate lattices and the results of its last
``SEARCH_CACHE_SIZE`` searches (an LRU keyed by the start cell) are computed on first use and kept
for the grid's lifetime; they go away with the grid (one per room). The cached distance and
predecessor arrays are read-only, so a caller cannot corrupt them. The robot returns to the same
few cells often (the strategies' travel estimates, the view planner's cost of every gaze, the
drive that executes it), and a search costs about a millisecond, so most queries are hits.

Line of sight is checked by
sampling the segment every quarter cell, so the guarantee is: every point of a returned path
lies in a free cell, i.e. within one cell diagonal of a point at least ``clearance`` from every
obstacle, hence at least ``clearance - 0.71 * resolution`` from it (with the default 5 cm margin
and 5 cm cells the base itself never touches an obstacle).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from ctxsearch.agent.interfaces import Body
from ctxsearch.envs.floorplan import wall_obstacles
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec
from ctxsearch.envs.rooms import door_entry
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import Box

_SQRT2 = math.sqrt(2.0)
SEARCH_CACHE_SIZE = 16  # Dijkstra results kept per grid (least recently used dropped first)


@dataclass
class OccupancyGrid:
    """A 2-D grid over the room's floor: ``free[row, col]`` is True where the base centre may be.

    Cell (row, col) has its centre at (x0 + (col + 0.5) * resolution, y0 + (row + 0.5) * resolution).
    """

    free: np.ndarray  # (H, W) bool
    x0: float
    y0: float
    resolution: float
    clearance: float = 0.0
    _labels: np.ndarray | None = field(default=None, init=False, repr=False)
    _graph: csr_matrix | None = field(default=None, init=False, repr=False)
    _searches: OrderedDict[int, tuple[np.ndarray, np.ndarray]] = field(
        default_factory=OrderedDict, init=False, repr=False, compare=False
    )
    _lattices: dict[int, tuple[np.ndarray, np.ndarray]] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    # ----------------------------------------------------------------- construction
    @classmethod
    def from_boxes(
        cls,
        boxes: Iterable[Box],
        bounds: tuple[float, float, float, float],
        clearance: float,
        resolution: float = 0.05,
    ) -> OccupancyGrid:
        """A grid over ``bounds`` = (xmin, ymin, xmax, ymax) with the footprints of ``boxes``
        blocked, all inflated by ``clearance``; cells nearer than ``clearance`` to the bounds'
        border are blocked too (the bounds are walls)."""
        xmin, ymin, xmax, ymax = bounds
        w = max(1, int(math.ceil((xmax - xmin) / resolution - 1e-9)))
        h = max(1, int(math.ceil((ymax - ymin) / resolution - 1e-9)))
        xs = xmin + (np.arange(w) + 0.5) * resolution
        ys = ymin + (np.arange(h) + 0.5) * resolution
        free = np.ones((h, w), bool)
        # Walls.
        free &= (ys[:, None] - ymin > clearance) & (ymax - ys[:, None] > clearance)
        free &= (xs[None, :] - xmin > clearance) & (xmax - xs[None, :] > clearance)
        for box in boxes:
            corners = box.corners_xy()
            lo = corners.min(0) - clearance
            hi = corners.max(0) + clearance
            c0 = max(0, int(math.floor((lo[0] - xmin) / resolution)))
            c1 = min(w, int(math.ceil((hi[0] - xmin) / resolution)) + 1)
            r0 = max(0, int(math.floor((lo[1] - ymin) / resolution)))
            r1 = min(h, int(math.ceil((hi[1] - ymin) / resolution)) + 1)
            if c0 >= c1 or r0 >= r1:
                continue
            dx = xs[c0:c1][None, :] - box.center[0]
            dy = ys[r0:r1][:, None] - box.center[1]
            c, s = math.cos(box.yaw), math.sin(box.yaw)
            lx = np.abs(c * dx + s * dy) - box.half[0]
            ly = np.abs(-s * dx + c * dy) - box.half[1]
            dist = np.hypot(np.maximum(lx, 0.0), np.maximum(ly, 0.0))
            free[r0:r1, c0:c1] &= dist > clearance
        return cls(free=free, x0=xmin, y0=ymin, resolution=resolution, clearance=clearance)

    @classmethod
    def from_layout(
        cls, layout: RoomLayout, spec: RobotSpec | None = None, resolution: float = 0.05
    ) -> OccupancyGrid:
        """The room's grid: walls and the footprint of every object reaching below the head,
        inflated by ``spec.clearance`` (see the module docstring)."""
        spec = spec or RobotSpec()
        return cls.from_boxes(
            obstacle_boxes(layout, spec),
            (-layout.width / 2, -layout.depth / 2, layout.width / 2, layout.depth / 2),
            spec.clearance,
            resolution,
        )

    # ----------------------------------------------------------------- coordinates
    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols)."""
        return self.free.shape  # type: ignore[return-value]

    def to_cell(self, xy: np.ndarray) -> tuple[int, int]:
        """The (row, col) containing point ``xy`` (may lie outside the grid)."""
        return (
            int(math.floor((float(xy[1]) - self.y0) / self.resolution)),
            int(math.floor((float(xy[0]) - self.x0) / self.resolution)),
        )

    def to_xy(self, row: int, col: int) -> np.ndarray:
        """The centre of cell (row, col) as a (2,) array."""
        return np.array(
            [self.x0 + (col + 0.5) * self.resolution, self.y0 + (row + 0.5) * self.resolution]
        )

    def cell_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """x of every column (W,) and y of every row (H,)."""
        h, w = self.shape
        return self.x0 + (np.arange(w) + 0.5) * self.resolution, self.y0 + (
            np.arange(h) + 0.5
        ) * self.resolution

    def in_grid(self, row: int, col: int) -> bool:
        """True if (row, col) is a cell of the grid."""
        h, w = self.shape
        return 0 <= row < h and 0 <= col < w

    def is_free(self, xy: np.ndarray) -> bool:
        """True if the base centre may stand at ``xy``."""
        r, c = self.to_cell(xy)
        return self.in_grid(r, c) and bool(self.free[r, c])

    def free_mask(self, points: np.ndarray) -> np.ndarray:
        """Which of ``points`` (N, 2) lie in free cells. (N,) bool."""
        pts = np.atleast_2d(np.asarray(points, float))
        cols = np.floor((pts[:, 0] - self.x0) / self.resolution).astype(int)
        rows = np.floor((pts[:, 1] - self.y0) / self.resolution).astype(int)
        h, w = self.shape
        ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        out = np.zeros(len(pts), bool)
        out[ok] = self.free[rows[ok], cols[ok]]
        return out

    # ----------------------------------------------------------------- connectivity
    def largest_region(self) -> np.ndarray | None:
        """Mask of the largest connected free region (None if there is no free cell)."""
        sizes = np.bincount(self.labels.ravel())
        if len(sizes) <= 1:
            return None
        sizes[0] = 0
        return self.labels == int(np.argmax(sizes))

    @property
    def labels(self) -> np.ndarray:
        """Connected components of the free cells (8-connected); 0 on blocked cells."""
        if self._labels is None:
            self._labels, _ = ndimage.label(self.free, structure=np.ones((3, 3), int))
        return self._labels

    def reachable_mask(self, xy: np.ndarray) -> np.ndarray:
        """(H, W) bool: the free cells reachable from the free cell nearest ``xy``."""
        start = nearest_free(self, xy)
        if start is None:
            return np.zeros(self.shape, bool)
        r, c = self.to_cell(start)
        return self.labels == self.labels[r, c]

    @property
    def graph(self) -> csr_matrix:
        """The 8-connected graph of free cells over flat indices (row * W + col), edge weights in
        metres; a diagonal edge needs both orthogonal neighbours free (no corner cutting)."""
        if self._graph is None:
            f = self.free
            h, w = f.shape
            idx = np.arange(h * w).reshape(h, w)
            src, dst, wts = [], [], []
            for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
                c0, c1 = (0, w - dc) if dc >= 0 else (-dc, w)
                a = (slice(0, h - dr), slice(c0, c1))
                b = (slice(dr, h), slice(c0 + dc, c1 + dc))
                ok = f[a] & f[b]
                if dr and dc:
                    ok &= f[dr:h, c0:c1] & f[0 : h - dr, c0 + dc : c1 + dc]
                i, j = idx[a][ok], idx[b][ok]
                step = self.resolution * (math.sqrt(2.0) if dr and dc else 1.0)
                src += [i, j]
                dst += [j, i]
                wts += [np.full(len(i), step)] * 2
            self._graph = csr_matrix(
                (np.concatenate(wts), (np.concatenate(src), np.concatenate(dst))),
                shape=(h * w, h * w),
            )
        return self._graph

    def _search(self, start_cell: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """Dijkstra from one cell: (distances (H*W,) in metres, predecessors (H*W,)), both
        read-only. The last ``SEARCH_CACHE_SIZE`` searches of this grid are kept (LRU by start
        cell), so distance queries and paths from a cell the robot was at recently cost nothing."""
        w = self.shape[1]
        s = start_cell[0] * w + start_cell[1]
        hit = self._searches.get(s)
        if hit is not None:
            self._searches.move_to_end(s)
            return hit
        dist, pred = dijkstra(self.graph, indices=s, return_predecessors=True)
        dist.flags.writeable = False
        pred.flags.writeable = False
        self._searches[s] = (dist, pred)
        if len(self._searches) > SEARCH_CACHE_SIZE:
            self._searches.popitem(last=False)
        return dist, pred

    def lattice_cells(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the free cells on the lattice of every ``step``-th row and column
        (offset ``step // 2``), in row-major order; cached per step. Read-only arrays."""
        hit = self._lattices.get(step)
        if hit is None:
            lattice = np.zeros(self.shape, bool)
            lattice[step // 2 :: step, step // 2 :: step] = True
            rows, cols = np.nonzero(self.free & lattice)
            rows.flags.writeable = False
            cols.flags.writeable = False
            hit = self._lattices[step] = (rows, cols)
        return hit

    def distances_from(self, xy: np.ndarray) -> np.ndarray:
        """(H, W) driving distance in metres along the grid from the free cell nearest ``xy`` to
        every cell (inf where unreachable or blocked). Read-only (a view of the cached search)."""
        start = nearest_free(self, xy)
        if start is None:
            return np.full(self.shape, np.inf)
        dist, _ = self._search(self.to_cell(start))
        return dist.reshape(self.shape)

    def line_of_sight(self, a: np.ndarray, b: np.ndarray) -> bool:
        """True if every point of segment a-b (sampled every quarter cell) lies in a free cell."""
        a, b = np.asarray(a, float), np.asarray(b, float)
        n = int(math.ceil(float(np.hypot(*(b - a))) / (0.25 * self.resolution))) + 1
        t = np.linspace(0.0, 1.0, max(n, 2))[:, None]
        return bool(self.free_mask(a + t * (b - a)).all())

    def visible_from(self, a: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """For each of ``targets`` (J, 2): True if the segment from ``a`` to it lies in free cells
        (each sampled at least every quarter cell, as ``line_of_sight``). (J,) bool."""
        targets = np.asarray(targets, float).reshape(-1, 2)
        if len(targets) == 0:
            return np.zeros(0, bool)
        a = np.asarray(a, float)
        longest = float(np.max(np.hypot(*(targets - a).T)))
        n = max(2, int(math.ceil(longest / (0.25 * self.resolution))) + 1)
        t = np.linspace(0.0, 1.0, n)
        samples = a + t[None, :, None] * (targets - a)[:, None, :]  # (J, n, 2)
        return self.free_mask(samples.reshape(-1, 2)).reshape(len(targets), n).all(axis=1)


def obstacle_boxes(layout: RoomLayout, spec: RobotSpec | None = None) -> list[Box]:
    """The bounding boxes that block the robot: every object whose bottom is below the head,
    and a house's interior walls."""
    spec = spec or RobotSpec()
    walls = wall_obstacles(layout)
    return walls + [o.box() for o in layout.objects if o.bottom < spec.camera_height]


def nearest_free(
    grid: OccupancyGrid, xy: np.ndarray, mask: np.ndarray | None = None
) -> np.ndarray | None:
    """The centre of the free cell nearest ``xy`` (``xy`` itself if its cell is free), optionally
    only among cells where ``mask`` (H, W) is True; None if there is none."""
    xy = np.asarray(xy, float)
    allowed = grid.free if mask is None else grid.free & mask
    r, c = grid.to_cell(xy)
    if grid.in_grid(r, c) and allowed[r, c]:
        return xy.copy()
    rows, cols = np.nonzero(allowed)
    if len(rows) == 0:
        return None
    xs = grid.x0 + (cols + 0.5) * grid.resolution
    ys = grid.y0 + (rows + 0.5) * grid.resolution
    k = int(np.argmin((xs - xy[0]) ** 2 + (ys - xy[1]) ** 2))
    return np.array([xs[k], ys[k]])


def _shortcut(grid: OccupancyGrid, pts: np.ndarray) -> np.ndarray:
    """Greedy line-of-sight smoothing: from each kept point, jump to the farthest visible corner."""
    if len(pts) <= 2:
        return pts
    # Keep only the corners of the cell path first (collinear runs carry no information).
    d = np.diff(pts, axis=0)
    turn = np.any(np.abs(d[1:] - d[:-1]) > 1e-9, axis=1)
    pts = np.vstack([pts[:1], pts[1:-1][turn], pts[-1:]])
    out = [pts[0]]
    i = 0
    while i < len(pts) - 1:
        # The farthest corner visible from pts[i], checked in batches of 8 from the far end.
        j = i + 1
        hi = len(pts)
        while hi > i + 2:
            lo = max(i + 2, hi - 8)
            later = np.flatnonzero(grid.visible_from(pts[i], pts[lo:hi]))
            if len(later):
                j = lo + int(later[-1])
                break
            hi = lo
        out.append(pts[j])
        i = j
    return np.array(out)


def plan_path(grid: OccupancyGrid, start_xy: np.ndarray, goal_xy: np.ndarray) -> np.ndarray | None:
    """A collision-free polyline (K, 2) from ``start_xy`` to ``goal_xy``, or None if the goal is
    blocked or unreachable. The first point is ``start_xy`` and the last ``goal_xy``; ``start_xy ==
    goal_xy`` gives a one-point path. A start inside an inflated obstacle (e.g. after numerical
    drift) leaves via the nearest free cell."""
    start = np.asarray(start_xy, float).reshape(2)
    goal = np.asarray(goal_xy, float).reshape(2)
    if not grid.is_free(goal):
        return None
    # np.allclose(start, goal, atol=1e-9) without its overhead
    if all(abs(a - b) <= 1e-9 + 1e-5 * abs(b) for a, b in zip(start, goal, strict=True)):
        return goal[None, :].copy()
    prefix: list[np.ndarray] = [start]
    if not grid.is_free(start):
        escape = nearest_free(grid, start)
        if escape is None:
            return None
        start = escape
        prefix.append(start)
    if grid.line_of_sight(start, goal):
        return np.array([*prefix, goal])
    s_cell, g_cell = grid.to_cell(start), grid.to_cell(goal)
    dist, pred = grid._search(s_cell)
    w = grid.shape[1]
    j = g_cell[0] * w + g_cell[1]
    if not np.isfinite(dist[j]):
        return None
    cells = [j]
    while (j := int(pred[j])) >= 0:
        cells.append(j)
    rows, cols = np.divmod(np.array(cells[::-1]), w)
    pts = np.column_stack(
        [grid.x0 + (cols + 0.5) * grid.resolution, grid.y0 + (rows + 0.5) * grid.resolution]
    )
    # Replace the first and last cell centres by the exact start and goal (both lie in those cells).
    pts[0], pts[-1] = start, goal
    pts = _shortcut(grid, pts)
    return np.vstack([np.array(prefix[:-1]).reshape(-1, 2), pts]) if len(prefix) > 1 else pts


def drive_along(body: Body, grid: OccupancyGrid, goal_xy: np.ndarray) -> bool:
    """Drive ``body`` along a planned path to ``goal_xy``, facing along its last segment; False
    (and no motion) when there is no path or the body is already there."""
    p = body.pose()
    path = plan_path(grid, p.xy, goal_xy)
    if path is None or len(path) < 2:
        return False
    seg = path[-1] - path[-2]
    body.drive(path, math.atan2(seg[1], seg[0]))
    return True


def start_pose(layout: RoomLayout, grid: OccupancyGrid) -> RobotPose:
    """Where the robot enters: the free cell nearest a point 0.6 m inside the door, facing into
    the room (in the largest free region if the door's side is cut off)."""
    x, y, yaw = door_entry(layout)
    p = nearest_free(grid, np.array([x, y]), grid.largest_region())
    if p is None:
        raise CtxsearchError(f"room {layout.style}/{layout.seed} has no free space for the robot")
    return RobotPose(float(p[0]), float(p[1]), yaw)
