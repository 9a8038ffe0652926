"""The robot's own map: an occupancy grid built from its depth images (``--map built``).

In camera mode the robot starts knowing only its own pose. Every depth image it renders updates
``BuiltMap``: each pixel's depth is back-projected to a world point within ``max_range``
of the camera (every second column: ``COL_STRIDE``), and

- a point on the floor (z below ``FLOOR_EPS``) marks its cell *floor seen*;
- a point between ``FLOOR_EPS`` and the head (``camera_height + HEAD_MARGIN``) marks its cell
  *occupied*: something the base, the mast or the head would hit (points above the head, the
  ceiling or a door's lintel, block nothing);
- the space along the rays, up to the hit, is recorded as *seen* in a coarse 3-D voxel grid
  (``seen_voxels``, what a search or a viewer may ask about; it does not decide where to drive).

Occupied is sticky: a cell once seen occupied is never floor. A cell is *unknown* while it is
neither. The robot's own footprint (a disc of ``base_radius`` at its start pose) is floor: it
stands there.

The navigable grid (``grid``) is agent.navigation's ``OccupancyGrid`` (one occupancy-grid type:
navigation, the gaze planner and the strategies' cost model use it unchanged). It is
conservative by construction: a cell is free only if its floor was seen and no occupied *or
unknown* cell lies within ``clearance + 0.71 * resolution`` of its centre (the robot's clearance,
plus half a cell diagonal because an obstacle may lie anywhere in a cell). So a path through free
cells keeps the base ``clearance`` from everything seen and never enters space not seen to be
floor. The grid is rebuilt by ``refresh`` (the learning loop refreshes after each look-around
and before each choice; a new ``OccupancyGrid`` only when its free cells changed, so its caches
stay valid because a grid is never changed).

Frontiers (agent.frontiers) are floor cells next to unknown ones.

The map's arrays cover the world's footprint (an allocation size: every cell starts unknown).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.envs.camera import NEAR_CLIP, Frame, PinholeCamera
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec
from ctxsearch.knowledge.options import MapMode, PerceptionMode

# the maps learning plans on (a remembered map is a search's: agent.search.tour, agent.search.remembered)
MAP_MODES = (MapMode.GIVEN.value, MapMode.BUILT.value)
FLOOR_EPS = 0.005  # m: depth points below this height are floor (a pen lying there is not)
HEAD_MARGIN = 0.10  # m above the camera: the head's top (points up to here are obstacles)
VOXEL = 0.10  # m: the seen-space record's voxel edge
RAY_STRIDE = 12  # pixels between the rays traced into the seen-space record
# Every second column of a depth image is used: 2 pixels are 4 cm across at 5 m (the cells are
# 5 cm), and the rows, which space the far floor along the view, are all kept.
COL_STRIDE = 2
TALL_M = 1.0  # m: an obstacle this high hides what stands on lower furniture beyond it


def default_map_mode(perception: str) -> str:
    """The map a perception mode uses by default: ``built`` for the camera, ``given`` for the
    oracle (which reads the true layout anyway) and for a user's own perception."""
    return MapMode.BUILT if perception == PerceptionMode.CAMERA else MapMode.GIVEN


class BuiltMap:
    """Floor / occupied / unknown cells and seen 3-D space, from depth images (module docstring)."""

    def __init__(
        self,
        bounds: tuple[float, float, float, float],
        spec: RobotSpec,
        start: RobotPose,
        resolution: float = 0.05,
        max_range: float = 5.0,
        top: float = 2.6,
    ):
        xmin, ymin, xmax, ymax = bounds
        self.spec, self.resolution, self.max_range = spec, resolution, max_range
        self.x0, self.y0 = xmin, ymin
        w = max(1, int(math.ceil((xmax - xmin) / resolution - 1e-9)))
        h = max(1, int(math.ceil((ymax - ymin) / resolution - 1e-9)))
        self.floor = np.zeros((h, w), bool)
        self.occupied = np.zeros((h, w), bool)
        self.top_z = np.zeros((h, w), np.float32)  # the highest obstacle point seen per cell
        vw = max(1, int(math.ceil((xmax - xmin) / VOXEL)))
        vh = max(1, int(math.ceil((ymax - ymin) / VOXEL)))
        self.seen_voxels = np.zeros((vh, vw, max(1, int(math.ceil(top / VOXEL)))), bool)
        self.images = 0
        self._rays_key: tuple[int, int, float] | None = None
        self._rays = np.zeros((0, 4), np.float32)
        self._traced = np.zeros(0, bool)  # per ray of ``_rays``: traced into ``seen_voxels``
        self._grid: OccupancyGrid | None = None
        self._dirty = True
        xs, ys = self._centers()
        d = np.hypot(xs[None, :] - start.x, ys[:, None] - start.y)
        self.floor |= d <= spec.base_radius

    @classmethod
    def for_layout(cls, layout: RoomLayout, spec: RobotSpec, start: RobotPose) -> BuiltMap:
        """An empty map over ``layout``'s footprint (the same cells as its given grid)."""
        return cls((-layout.width / 2, -layout.depth / 2, layout.width / 2, layout.depth / 2),
                   spec, start, top=layout.height)  # fmt: skip

    def _centers(self) -> tuple[np.ndarray, np.ndarray]:
        h, w = self.floor.shape
        r = self.resolution
        return self.x0 + (np.arange(w) + 0.5) * r, self.y0 + (np.arange(h) + 0.5) * r

    @property
    def tall(self) -> np.ndarray:
        """(H, W) bool: occupied cells with an obstacle point seen at or above ``TALL_M``."""
        return self.occupied & (self.top_z >= TALL_M)

    @property
    def unknown(self) -> np.ndarray:
        """(H, W) bool: cells neither seen as floor nor as occupied."""
        return ~self.floor & ~self.occupied

    # ------------------------------------------------------------------ updates
    def update(self, frame: Frame | None) -> None:
        """Add one depth image (a frame without depth changes nothing)."""
        if frame is None or frame.depth is None:
            return
        cam = frame.camera
        depth = np.asarray(frame.depth, np.float32)[:, ::COL_STRIDE].ravel()
        local = self._local_rays(cam)  # (N, 3) rays with z = -1 in the camera frame
        # Distance along a ray = depth * |local ray|; within range and past the near clip only.
        rng = depth * local[:, 3]
        keep = np.flatnonzero(np.isfinite(depth) & (depth > NEAR_CLIP) & (rng <= self.max_range))
        # np.take: the same rows as local[keep, :3], several times faster
        rays = np.take(local, keep, axis=0)[:, :3] @ np.asarray(cam.xmat, np.float32).T
        pts = np.asarray(cam.position, np.float32) + rays * depth[keep, None]
        z = pts[:, 2]
        rows = np.floor((pts[:, 1] - self.y0) / self.resolution).astype(np.int64)
        cols = np.floor((pts[:, 0] - self.x0) / self.resolution).astype(np.int64)
        h, w = self.floor.shape
        ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        top = self.spec.camera_height + HEAD_MARGIN
        cell = rows * w + cols  # the flat cell index (valid where ok)
        hit = np.flatnonzero(ok & (z >= FLOOR_EPS) & (z <= top))
        np.put(self.occupied, cell[hit], True)
        # the highest point per cell: only the points above what their cell holds can raise it
        hr, hc, zh = rows[hit], cols[hit], z[hit]
        up = zh > self.top_z[hr, hc]
        np.maximum.at(self.top_z, (hr[up], hc[up]), zh[up])
        np.put(self.floor, cell[ok & (z < FLOOR_EPS)], True)
        self.floor &= ~self.occupied
        sub = self._traced[keep]
        self._trace(np.asarray(cam.position, float), pts[sub], rng[keep][sub])
        self.images += 1
        self._dirty = True

    def _local_rays(self, cam: PinholeCamera) -> np.ndarray:
        """(H * W', 4) float32: the camera-frame ray of each pixel of every ``COL_STRIDE``-th
        column, scaled to z = -1, and its length."""
        key = (cam.width, cam.height, cam.fovy_deg)
        if self._rays_key != key:
            f = cam.focal
            x = (np.arange(0, cam.width, COL_STRIDE) + 0.5 - cam.width / 2) / f
            y = -(np.arange(cam.height) + 0.5 - cam.height / 2) / f
            local = np.stack(np.broadcast_arrays(x[None, :], y[:, None], -1.0), -1).reshape(-1, 3)
            self._rays = np.column_stack([local, np.linalg.norm(local, axis=1)]).astype(np.float32)
            # the rays traced into the seen-space record: every RAY_STRIDE-th row and pixel
            w_sub = len(range(0, cam.width, COL_STRIDE))
            pix = np.arange(len(local))
            self._traced = pix % w_sub % (RAY_STRIDE // COL_STRIDE) == 0
            self._traced &= pix // w_sub % RAY_STRIDE == 0
            self._rays_key = key
        return self._rays

    def _trace(self, origin: np.ndarray, p: np.ndarray, d: np.ndarray) -> None:
        """Mark the voxels along rays from ``origin`` to the points ``p`` (at distances ``d``)."""
        if not len(p):
            return
        u = (p - origin) / np.maximum(d, 1e-9)[:, None]
        t = np.arange(0.0, self.max_range, VOXEL)
        ray, step = np.nonzero(t[None, :] <= d[:, None])  # the samples along each ray
        ts = t[step]
        qx, qy, qz = (origin[j] + u[ray, j] * ts for j in range(3))
        vh, vw, vz = self.seen_voxels.shape
        r = np.floor((qy - self.y0) / VOXEL).astype(np.int64)
        c = np.floor((qx - self.x0) / VOXEL).astype(np.int64)
        k = np.floor(qz / VOXEL).astype(np.int64)
        inside = (r >= 0) & (r < vh) & (c >= 0) & (c < vw) & (k >= 0) & (k < vz)
        np.put(self.seen_voxels, ((r * vw + c) * vz + k)[inside], True)

    # ------------------------------------------------------------------ the navigable grid
    @property
    def grid(self) -> OccupancyGrid:
        """The navigable grid as of the last ``refresh`` (the first use refreshes)."""
        if self._grid is None:
            self.refresh()
        assert self._grid is not None
        return self._grid

    def refresh(self) -> OccupancyGrid:
        """Rebuild the navigable grid from the images so far: floor cells with no occupied or
        unknown cell within the clearance plus half a cell diagonal (module docstring). The grid
        object (and its search caches) is kept when its free cells did not change. Every grid
        it ever gives is safe, so a plan made on an older one stays safe."""
        if self._dirty or self._grid is None:
            self._dirty = False
            bad = ~self.floor | self.occupied
            reach = self.spec.clearance + 0.71 * self.resolution
            # Beyond the array is unknown too: a border of bad cells around it.
            dist = ndimage.distance_transform_edt(np.pad(~bad, 1, constant_values=False))
            free = self.floor & (dist[1:-1, 1:-1] * self.resolution > reach)
            if self._grid is not None and np.array_equal(free, self._grid.free):
                return self._grid
            self._grid = OccupancyGrid(
                free=free, x0=self.x0, y0=self.y0, resolution=self.resolution,
                clearance=self.spec.clearance,
            )  # fmt: skip
        return self._grid

    def frontier(self) -> np.ndarray:
        """(H, W) bool: floor cells with an unknown 4-neighbour."""
        unk = self.unknown
        near = np.zeros_like(unk)
        near[1:] |= unk[:-1]
        near[:-1] |= unk[1:]
        near[:, 1:] |= unk[:, :-1]
        near[:, :-1] |= unk[:, 1:]
        return self.floor & near


@dataclass(frozen=True)
class MapQuality:
    """How a built map compares with the true layout's grid (``map_quality``)."""

    free_recall: float  # share of the true grid's free cells reachable from the start it knows
    false_free: int  # built-free cells where the base would overlap an obstacle (must be 0)
    false_free_margin: int  # built-free cells the true grid blocks (its margin included)
    reachable_cells: int  # free cells of the true grid reachable from the start
    known_free_cells: int  # free cells of the built map


def map_quality(
    built: OccupancyGrid, given: OccupancyGrid, body: OccupancyGrid, start_xy: np.ndarray
) -> MapQuality:
    """``map_free_recall`` and ``map_false_free`` of ``built`` against the true layout (all three
    grids on the same cells): the share of the cells free and reachable from ``start_xy`` in the
    true grid ``given`` that the built map calls free; the cells the built map calls free where
    the base would overlap an obstacle's bounding box (``body``: the true layout's grid at the bare
    base radius, no margin); and the cells it calls free that ``given`` blocks (within the
    navigation margin of an obstacle's bounding box: the bounding box is larger than a chair's
    legs and seat, so these are not collisions)."""
    reach = given.reachable_mask(start_xy)
    n = int(reach.sum())
    known = int((built.free & reach).sum())
    return MapQuality(
        free_recall=known / n if n else 0.0,
        false_free=int((built.free & ~body.free).sum()),
        false_free_margin=int((built.free & ~given.free).sum()),
        reachable_cells=n,
        known_free_cells=int(built.free.sum()),
    )
