"""Search on the robot's own map (``--map built``): where to look next, and Wixson & Ballard's
efficiency model of indirect search. Pure numpy on agent.mapping's ``BuiltMap`` arrays; nothing
here renders or drives (the behaviours of agent.search run the policies).

Viewpoints. A candidate viewpoint is a reachable free cell of the built map's navigable grid on a
0.5 m lattice (``space.lattice_candidates``). Its *gain* for a detection range r is the
number of seen-map lattice points still to be seen for r (not seen from within r, not
exhausted) that lie within r of the camera there and in a 2-D cell the camera can see: the
built map's occupied cells, pooled onto the lattice's 0.2 m cells, stop each of ``RAY_COUNT``
rays (the first occupied cell itself is seen: a desk top is), unknown cells do not (the space
beyond the frontier is what exploring is for). Its *seconds* are the planned drive there (grid
distance, a quarter turn) plus the images of a sweep. Viewpoints are ranked by the share of what
is left that they show per second: information gain per expected second.

Places beyond the frontier (``ViewpointScorer.beyond``, a frontier potential). Of every coarse
cell (``COARSE`` m) neither occupied nor reachable on the grid, the one whose sweep finds the
most belief per expected second, counting only the todo points out of every reachable
candidate's range (what no viewpoint ``best`` weighs can find; the share is of all the todo
points' weight). The choices, this module's: the way is the shortest 8-connected path over
coarse cells that hold no occupied map cell (unknown space is passable, as a frontier explorer
assumes) from the robot's cell; the seconds are a viewpoint's (the drive along that path and the
sweep); what the sweep finds is each point's weight times P(found) at its distance in the plane
from the cell's centre and the camera's height above the points' weighted mean height, within
the sight's range, nothing hiding it (the space is not mapped). A cell reachable on the grid is
left to ``best``, which traces what hides what.

Exhaustion. After a sweep at p, the points within ``EXHAUST_RADIUS`` of p that p's rays reach
and that are still unseen are *exhausted* for that range: they cannot be seen from nearby
(inside furniture, under a bed), so they no longer attract the robot. Without it the points
inside the furniture's solid parts, which the robot does not know about, would.

Wixson & Ballard's efficiency model (IJCV 12(2/3), 1994). Direct search for T costs the expected
half of a coverage at T's detection range; indirect search via I costs finding I (coverage at
I's larger range, one ring of images for furniture) plus looking into I's most likely relation
volume, plus the direct search when T is not there (``space.indirect_plan``). Indirect
search pays when the efficiency ratio C_direct / C_via exceeds 1 (``predicted_gain``). Coverage
costs come from the area model ``area_cover_seconds`` (the house's footprint and room count,
the detection range and the images per site), so the prediction needs no map: it is what the
robot can expect before it has seen anything.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search.config import DEFAULT_DEPTH_RANGE_M
from ctxsearch.envs.robot_spec import RobotSpec, TimeModel
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.geometry import ObjectInstance, relation_volume

RAY_COUNT = 120
COARSE = ss.LATTICE_XY  # m: the visibility cells (the seen map's lattice spacing)
EXHAUST_RADIUS = 1.5  # m
# Occlusion in 2-D with two heights (``Blockers``): points below LOW_Z are hidden by anything
# occupied, points above it only by obstacles reaching agent.mapping.TALL_M (the camera is at
# 1.2 m).
LOW_Z = 0.4  # m
MIN_GAIN = 8  # points a viewpoint must show to be worth driving to
# ``ViewpointScorer.best``'s first bounds: bins of this many visibility cells a side, and the
# relative allowance for rounding that keeps them above the points' bounds they stand for
BIN_CELLS = 2
BOUND_SLACK = 1e-9
VISITED_RADIUS = 0.4  # m: a viewpoint this near an earlier sweep's is not chosen again
HEAD_S = 0.6  # s: mean head slew per image
FLOOR_IMAGES = 3.0  # near-floor images expected where the robot advances toward a place beyond
FRONTIER_SNAP_M = 1.0  # m: a beyond-the-frontier place is driven toward via a viewpoint this near
VIEWS_KEPT = 1024  # kept views (``ViewpointScorer._kept_shown``) at most: ~6,000 points each


@dataclass(frozen=True)
class Sight:
    """What a sweep is scored for: the range (m) within which it counts points and, for the
    target, the probability of finding it against distance (agent.search.belief's
    ``DetectionCurve.found``; None: every point within range counts fully)."""

    range: float
    found: Callable[[np.ndarray], np.ndarray] | None = None


@dataclass(frozen=True)
class Viewpoint:
    """A place to sweep from: where, what it shows (points), the share of what is left, and
    the expected seconds to get there and sweep."""

    xy: np.ndarray
    gain: int
    share: float
    seconds: float

    @property
    def rate(self) -> float:
        """Share of what is left shown per second."""
        return self.share / max(self.seconds, 1e-6)


@dataclass(frozen=True)
class Beyond:
    """A place beyond the frontier worth a sweep (``ViewpointScorer.beyond``): the reachable
    viewpoint where the way there leaves the map, the place itself, the share of the belief a
    sweep there would find, that share per expected second of the whole way (the drive there
    and the sweep), and the expected seconds of the way's first leg."""

    via: Viewpoint
    goal: np.ndarray
    share: float
    rate: float
    first_s: float  # expected seconds of the first leg: the drive to ``via``, floor images


@dataclass(frozen=True)
class Blockers:
    """Coarse cells that block the view (``coarse_blocked``): of the points near the floor
    (below ``LOW_Z``), anything occupied (``low``); of the points higher up, only what reaches
    ``TALL_M`` (``tall``): a camera at 1.2 m sees over a table or a bed onto the tops beyond."""

    low: np.ndarray
    tall: np.ndarray


def _pool(occ: np.ndarray, k: int) -> np.ndarray:
    h, w = occ.shape
    pad = np.zeros((-(-h // k) * k, -(-w // k) * k), bool)
    pad[:h, :w] = occ
    return pad.reshape(pad.shape[0] // k, k, pad.shape[1] // k, k).any(axis=(1, 3))


def coarse_blocked(built: Occupancy, cell: float = COARSE) -> Blockers:
    """The coarse cells (``cell`` m, from the map's corner) holding an occupied cell, and those
    holding a tall one (``Blockers``)."""
    k = max(1, int(round(cell / built.resolution)))
    return Blockers(_pool(built.occupied, k), _pool(built.tall, k))


def visible_cells(
    blocked: np.ndarray,
    origin: tuple[float, float],
    xy: np.ndarray,
    radius: float,
    cell: float = COARSE,
    rays: int = RAY_COUNT,
) -> np.ndarray:
    """(h, w) bool: the coarse cells that rays from ``xy`` reach within ``radius`` before (and
    including) the first blocked cell."""
    h, w = blocked.shape
    a = np.linspace(0.0, 2 * math.pi, rays, endpoint=False)
    t = np.arange(0.0, radius + 1e-9, cell * 0.5)
    px = xy[0] + np.cos(a)[:, None] * t[None, :]
    py = xy[1] + np.sin(a)[:, None] * t[None, :]
    c = np.floor((px - origin[0]) / cell).astype(np.int64)
    r = np.floor((py - origin[1]) / cell).astype(np.int64)
    inside = (r >= 0) & (r < h) & (c >= 0) & (c < w)
    rc, cc = np.clip(r, 0, h - 1), np.clip(c, 0, w - 1)
    blk = blocked[rc, cc] & inside
    before = np.cumsum(blk, axis=1) - blk  # blocked cells passed before this step
    keep = inside & (before == 0) & (np.cumsum(~inside, axis=1) == 0)
    out = np.zeros((h, w), bool)
    out[rc[keep], cc[keep]] = True
    return out


class Occupancy(Protocol):
    """What blocks the view, as cells: a ``BuiltMap`` (the robot's own map) or the given map's
    ``agent.search.maps.Occluders``; ``tall``: the occupied cells reaching ``TALL_M``."""

    occupied: np.ndarray
    tall: np.ndarray
    x0: float
    y0: float
    resolution: float


class ViewpointScorer:
    """Gains and seconds of candidate viewpoints on a map whose occupied cells block the view
    (``built``: the robot's own map, or the given map's occluders; module docstring).

    ``views``: where what blocks the view never changes (the given map's occluders), a dict
    that keeps each candidate's view, every lattice point within a range that a sweep there
    shows, traced once (``_kept_shown``); the scorers of the policies run in one room share it
    (``maps.WorldMaps.views``). A later trace of a kept view only reads which of its points are
    still to be seen, and ``best`` traces such a candidate without bounding it first. The gains
    and weights are the same numbers as tracing the todo points afresh. None: the map changes
    (the robot's own), nothing is kept."""

    def __init__(
        self, built: Occupancy, points: np.ndarray, spec: RobotSpec, tm: TimeModel,
        views: dict[tuple[float, float, float, float], np.ndarray] | None = None,
        max_view: float = DEFAULT_DEPTH_RANGE_M,
    ):  # fmt: skip
        self.built, self.points, self.spec, self.tm = built, points, spec, tm
        self.max_view = max_view  # m: nothing further counts as seen (the map's depth range)
        self._views = views  # ``_kept_shown``
        self.origin = (built.x0, built.y0)
        self.cells = np.floor((points[:, :2] - np.array(self.origin)) / COARSE).astype(np.int64)
        self._gains: dict[Hashable, dict[tuple[float, float], int]] = {}  # best(): last gains
        # ``_bin_bounds``' bins: each point's bin and each bin's box (low, high) around all its
        # points (``_boxes``, made on first use: many scorers never choose a viewpoint)
        b = self.cells // BIN_CELLS
        b -= b.min(axis=0) if len(b) else 0
        self._bin = b[:, 1] * (int(b[:, 0].max()) + 1 if len(b) else 1) + b[:, 0]
        self._bin_box: tuple[np.ndarray, np.ndarray] | None = None

    def _boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """(B, 3) low and high corners of the box around each bin's points (inf, -inf: none)."""
        if self._bin_box is None:
            n = int(self._bin.max()) + 1 if len(self._bin) else 0
            lo, hi = np.full((n, 3), np.inf), np.full((n, 3), -np.inf)
            if n:  # each bin's points one after the other, reduced run by run
                order = np.argsort(self._bin, kind="stable")
                b, p = self._bin[order], self.points[order]
                first = np.flatnonzero(np.r_[True, b[1:] != b[:-1]])
                lo[b[first]] = np.minimum.reduceat(p, first, axis=0)
                hi[b[first]] = np.maximum.reduceat(p, first, axis=0)
            self._bin_box = (lo, hi)
        return self._bin_box

    def visible_points(self, blocked: Blockers, xy: np.ndarray, rng: float) -> np.ndarray:
        """(N,) bool: lattice points within ``rng`` of the camera at ``xy`` in a visible cell."""
        cam = np.array([xy[0], xy[1], self.spec.camera_height])
        near = np.flatnonzero(np.linalg.norm(self.points - cam, axis=1) <= min(rng, self.max_view))
        m = np.zeros(len(self.points), bool)
        m[near[self._visible(blocked, xy, min(rng, self.max_view), near)]] = True
        return m

    def _visible(self, blocked: Blockers, xy: np.ndarray, rng: float, idx: np.ndarray):
        """(len(idx),) bool: which of the points ``idx`` lie in a cell rays from ``xy`` reach
        (``Blockers``: the low ones past anything occupied, the higher ones past tall things)."""
        cells = self.cells[idx]
        r, c = cells[:, 1], cells[:, 0]
        out = np.zeros(len(idx), bool)
        low = self.points[idx, 2] < LOW_Z
        for grid, which in ((blocked.low, low), (blocked.tall, ~low)):
            if not which.any():
                continue
            vis = visible_cells(grid, self.origin, xy, rng)
            h, w = vis.shape
            ok = which & (r >= 0) & (r < h) & (c >= 0) & (c < w)
            out[ok] = vis[r[ok], c[ok]]
        return out

    def best(
        self,
        grid: OccupancyGrid,
        todo: np.ndarray,
        here: np.ndarray,
        sight: Sight,
        images: float,
        avoid: np.ndarray | None = None,
        key: Hashable | None = None,
        weights: np.ndarray | None = None,
    ) -> Viewpoint | None:
        """The candidate viewpoint with the best rate (share of the points ``todo`` (N,) bool
        within ``sight.range`` it shows per second, a sweep taking ``images`` images; with
        ``sight.found`` each point's share times P(found) at its distance; ties: fewer
        seconds, then smaller x, y); None if none shows ``MIN_GAIN`` points. Candidates within
        ``VISITED_RADIUS`` of a point of ``avoid`` (K, 2: where sweeps were made) are left out.

        Lazy evaluation, exact: a candidate's gain is at most the number of todo points within
        range of it (the trace only removes points) and, for calls with the same ``key`` whose
        ``todo`` only shrinks (the seen map and the exhausted points only grow, occupied cells
        of the built map are never cleared), at most the gain it had at the last call. Those
        bounds on the rate are bounded in turn by their bins' (``_bin_bounds``). Candidates
        are taken by bound, largest first: a bin bound gives way to the points' bound, a points'
        bound is traced, until the largest left falls below the best rate found: the viewpoint
        tracing them all would pick (a bound never changes what is picked, only how soon).

        ``weights`` (N,) non-negative: a point's share is its weight over the todo points'
        total (the belief: agent.search.belief); the bound is then the weight within range, and
        gains are not cached (the weights change with every image)."""
        count = int(todo.sum())
        w = None if weights is None else np.asarray(weights, float)[todo]
        left = float(count) if w is None else float(w.sum())
        if count < MIN_GAIN or left <= 0.0:
            return None
        cand, seconds = self._reachable(grid, here, images, avoid)
        if len(cand) == 0:
            return None
        sub = np.flatnonzero(todo)
        pts, blocked, best = self.points[sub], None, None
        cache = self._gains.setdefault(key, {}) if key is not None and w is None else {}
        ids = [(round(float(x), 3), round(float(y), 3)) for x, y in cand]
        upper, mass, exact = self._bin_bounds(cand, sub, sight, w, [cache.get(i, -1) for i in ids])
        heap = _heap(mass / left / seconds, upper, exact)
        kept = None if self._views is None else (todo, np.cumsum(todo) - 1)  # and their ranks
        while heap:
            neg, i, fine = heapq.heappop(heap)
            if best is not None and -neg < best.rate:
                break
            if not fine and not self._has_view(cand[i], sight):  # the points' bound replaces
                up, m = self._bounds(cand[i : i + 1], pts, sight, w)
                if up[0] >= MIN_GAIN:
                    heapq.heappush(heap, (-float(m[0] / left / seconds[i]), i, True))
                continue
            blocked = blocked or coarse_blocked(self.built)
            g, m = self._gain(blocked, cand[i], sight, sub, pts, w, kept)
            cache[ids[i]] = g
            v = Viewpoint(cand[i], g, m / left, float(seconds[i]))
            if g >= MIN_GAIN and (best is None or _order(v) < _order(best)):
                best = v
        return best

    def beyond(
        self,
        grid: OccupancyGrid,
        todo: np.ndarray,
        here: np.ndarray,
        sight: Sight,
        images: float,
        weights: np.ndarray,
        avoid: np.ndarray | None = None,
    ) -> Beyond | None:
        """The best place beyond the frontier (module docstring) for the belief ``weights`` (N,)
        on the ``todo`` points, and the reachable candidate viewpoint where the way there leaves
        the map (None: no such place finds any mass, or no candidate stands within
        ``FRONTIER_SNAP_M`` of where the way leaves)."""
        w = np.asarray(weights, float)[todo]
        left = float(w.sum())
        cand, seconds = self._reachable(grid, here, images, avoid)
        if left <= 0.0 or len(cand) == 0:
            return None
        k = max(1, int(round(COARSE / self.built.resolution)))
        occupied = _pool(self.built.occupied, k)
        h, wd = occupied.shape
        known = _pool(grid.reachable_mask(here), k)[:h, :wd]
        passable = ~occupied | known
        start = _coarse_cell(self.origin, here, (h, wd))
        if start is None:
            return None
        passable[start] = True
        dist, pred = _coarse_paths(passable, start, COARSE)
        rng = min(sight.range, self.max_view)
        sub = np.flatnonzero(todo)
        mass = _far_mass(self.cells[sub], w, [_coarse_cell(self.origin, xy, (h, wd)) for xy in cand],
                         rng, (h, wd))  # fmt: skip
        dz = self.spec.camera_height - float((self.points[sub, 2] * w).sum() / left)
        finds = ndimage.correlate(mass, _sweep_kernel(rng, dz, sight), mode="constant")
        virtual = passable & ~known & np.isfinite(dist) & (finds > 0.0)
        if not virtual.any():
            return None
        sweep_s = self.tm.looks_estimate(images, HEAD_S)
        legs = np.vectorize(self.tm.leg_estimate, otypes=[float])(dist[virtual])
        rate = finds[virtual] / left / (legs + sweep_s)
        best = int(np.argmax(rate))  # ties: the first in row-major order
        cell = tuple(int(a[best]) for a in np.nonzero(virtual))
        at = _cell_xy(self.origin, _crossing(pred, cell, start, known, wd))
        gap = np.hypot(cand[:, 0] - at[0], cand[:, 1] - at[1])
        j = int(np.argmin(gap))
        if gap[j] > FRONTIER_SNAP_M:
            return None
        share = float(finds[cell]) / left
        v = Viewpoint(cand[j], 0, share, float(seconds[j]))
        first = float(seconds[j]) - sweep_s + self.tm.looks_estimate(FLOOR_IMAGES, HEAD_S)
        return Beyond(v, _cell_xy(self.origin, cell), share, float(rate[best]), first)

    def open_share(
        self, xy: np.ndarray, todo: np.ndarray, sight: Sight, weights: np.ndarray
    ) -> float:
        """The share of the todo points' weight a sweep at ``xy`` would find if nothing hid
        anything (``_bounds``: each point's weight times ``sight.found`` within range): what
        ``best``'s traced share is at most."""
        w = np.asarray(weights, float)[todo]
        left = float(w.sum())
        if left <= 0.0:
            return 0.0
        _, m = self._bounds(np.asarray(xy, float)[None, :], self.points[todo], sight, w)
        return float(m[0]) / left

    def _reachable(
        self, grid: OccupancyGrid, here: np.ndarray, images: float, avoid: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The candidate viewpoints (M, 2) reachable from ``here`` and not within
        ``VISITED_RADIUS`` of ``avoid``, and the expected seconds to drive to each and sweep."""
        cand = ss.lattice_candidates(grid, here, 0.5)
        if avoid is not None and len(avoid) and len(cand):
            d = np.linalg.norm(cand[:, None, :] - np.asarray(avoid)[None, :, :], axis=-1)
            cand = cand[d.min(axis=1) > VISITED_RADIUS]
        if len(cand) == 0:
            return cand, np.zeros(0)
        dist = grid.distances_from(here)
        rc = [grid.to_cell(xy) for xy in cand]
        drive = np.array(
            [float(dist[r, c]) if grid.in_grid(r, c) else math.inf for r, c in rc], float
        )
        reach = np.isfinite(drive)
        sweep_s = self.tm.looks_estimate(images, HEAD_S)
        seconds = np.array([self.tm.leg_estimate(d) for d in drive[reach]], float) + sweep_s
        return cand[reach], seconds

    def _bin_bounds(
        self, cand: np.ndarray, sub: np.ndarray, sight: Sight, w: np.ndarray | None, cached: list
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Upper bounds on ``_bounds``' bounds of each candidate, cheap: the todo points ``sub``
        summed per bin (``BIN_CELLS`` x ``BIN_CELLS`` visibility cells), each bin counted whole
        when the nearest point of the box around its points is within range, its weight times
        ``sight.found`` at that distance (P(found) never grows with distance: the recall falls
        with distance and with fewer pixels), and an allowance for rounding; and which are
        exact already (``cached``, the last call's gain, where it is not -1, is both bounds)."""
        cached_a = np.array(cached, np.int64)
        exact = cached_a >= 0
        upper, mass = cached_a.copy(), cached_a.astype(float)
        new = np.flatnonzero(~exact)
        nb = len(self._boxes()[0])
        count = np.bincount(self._bin[sub], minlength=nb)
        live = np.flatnonzero(count)
        count = count[live]
        if len(new) == 0 or len(live) == 0:
            upper[new], mass[new] = 0, 0.0
            return upper, mass, exact
        d2 = self._bin_d2(cand[new], live)
        near = d2 <= min(sight.range, self.max_view) ** 2 * (1.0 + BOUND_SLACK)
        upper[new] = near @ count
        if w is None:
            mass[new] = upper[new]
            return upper, mass, exact
        weight = np.bincount(self._bin[sub], weights=w, minlength=nb)[live]
        if sight.found is not None:
            f = np.zeros_like(d2)
            f[near] = sight.found(np.sqrt(d2[near]))
            mass[new] = (f * weight).sum(1) * (1.0 + BOUND_SLACK)  # not BLAS: see _bounds
        else:
            mass[new] = (near * weight).sum(1) * (1.0 + BOUND_SLACK)
        return upper, mass, exact

    def _bin_d2(self, cand: np.ndarray, bins: np.ndarray) -> np.ndarray:
        """(M, B): the squared distance from the camera at each candidate (M, 2) to the nearest
        point of the box around the points of each bin of ``bins`` (B,)."""
        lo, hi = (a[bins] for a in self._boxes())
        cx, cy = cand[:, 0][:, None], cand[:, 1][:, None]
        cz = self.spec.camera_height
        dx = np.maximum(np.maximum(lo[:, 0] - cx, cx - hi[:, 0]), 0.0)
        dy = np.maximum(np.maximum(lo[:, 1] - cy, cy - hi[:, 1]), 0.0)
        dz = np.maximum(np.maximum(lo[:, 2] - cz, cz - hi[:, 2]), 0.0)
        return dx * dx + dy * dy + dz * dz

    def _bounds(
        self, cand: np.ndarray, pts: np.ndarray, sight: Sight, w: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Upper bounds on each candidate's gain: the count of the todo points ``pts`` within
        range (the trace only removes points) and their weight (``w`` over ``pts``, times
        ``sight.found`` at its distance; None: the count)."""
        upper = np.zeros(len(cand), np.int64)
        mass = np.zeros(len(cand))
        view2 = min(sight.range, self.max_view) ** 2
        cams = np.column_stack([cand, np.full(len(cand), self.spec.camera_height)])
        x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
        for k in range(0, len(cand), 16):  # the todo points within range of each camera
            c = cams[k : k + 16, :, None]
            # the squared distances, summed in the order a sum over the last axis takes
            d2 = (x - c[:, 0]) ** 2 + (y - c[:, 1]) ** 2 + (z - c[:, 2]) ** 2
            near = d2 <= view2
            upper[k : k + 16] = near.sum(1)
            if w is None:
                mass[k : k + 16] = near.sum(1)
            elif sight.found is None:
                mass[k : k + 16] = (near * w).sum(1)  # not BLAS: thread-independent
            else:  # P(found) where it counts only: 0 elsewhere, as near times any value was
                f = np.zeros_like(d2)
                f[near] = sight.found(np.sqrt(d2[near]))
                mass[k : k + 16] = (near * f * w).sum(1)
        return upper, mass

    def _gain(
        self, blocked, xy, sight: Sight, sub, pts, weights=None, kept=None
    ) -> tuple[int, float]:
        """The todo points (``sub``, at ``pts``) a sweep at ``xy`` shows: their count and their
        weight (``weights`` over ``sub``, times ``sight.found`` at their distance; None: the
        count). ``kept``: (the todo mask, each todo point's position in ``sub``) where views
        are kept (``_kept_shown``)."""
        hit = None if kept is None else self._kept_shown(blocked, xy, sight, *kept)
        if hit is None:
            shown, dist = self._shown(blocked, xy, sight, sub, pts)
            hit = shown, dist[shown]
        shown, dist = hit
        g = len(shown)
        if g == 0:
            return 0, 0.0
        if weights is None:
            return g, float(g)
        if sight.found is None:
            return g, float(weights[shown].sum())
        return g, float((weights[shown] * sight.found(dist)).sum())

    def _distances(self, pts: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """Each of ``pts``' distance from the camera at ``xy``: the norm of pts - cam, summed in
        the order np.linalg.norm takes (the same numbers, point by point)."""
        dx, dy = pts[:, 0] - xy[0], pts[:, 1] - xy[1]
        dz = pts[:, 2] - self.spec.camera_height
        return np.sqrt(dx * dx + dy * dy + dz * dz)

    def _shown(self, blocked, xy, sight: Sight, sub, pts) -> tuple[np.ndarray, np.ndarray]:
        """(positions in ``sub`` of the points a sweep at ``xy`` shows, none if fewer than
        ``MIN_GAIN``; every point's distance from the camera)."""
        rng = min(sight.range, self.max_view)
        dist = self._distances(pts, xy)
        near = np.flatnonzero(dist <= rng)
        if len(near) < MIN_GAIN:
            return near[:0], dist
        return near[self._visible(blocked, xy, rng, sub[near])], dist

    def _has_view(self, xy: np.ndarray, sight: Sight) -> bool:
        """Whether ``xy``'s view for ``sight``'s range is kept (``_kept_shown``)."""
        return self._views is not None and self._view_key(xy, sight) in self._views

    def _view_key(self, xy: np.ndarray, sight: Sight) -> tuple[float, float, float, float]:
        return (
            float(xy[0]),
            float(xy[1]),
            min(sight.range, self.max_view),
            self.spec.camera_height,
        )

    def _kept_shown(self, blocked, xy, sight: Sight, todo: np.ndarray, rank: np.ndarray):
        """``_shown`` from the candidate's kept view (``views``): (positions among the todo
        points (``todo`` (N,) bool; ``rank``: each todo point's position) of those a sweep at
        ``xy`` shows, their distances). The view, every point within range in a cell the rays
        reach, is traced over all points on first use; a point's visibility and distance do not
        depend on the others, so the todo points it holds are those ``_shown`` finds. None
        where fewer than ``MIN_GAIN`` are left: ``_shown``'s test on the points within range
        decides then."""
        assert self._views is not None
        key = self._view_key(xy, sight)
        view = self._views.get(key)
        if view is None:
            if len(self._views) >= VIEWS_KEPT:
                self._views.clear()
            every = np.arange(len(self.points))
            view = self._shown(blocked, xy, sight, every, self.points)[0].astype(np.int32)
            self._views[key] = view
        shown = view[todo[view]]
        if len(shown) < MIN_GAIN:
            return None
        return rank[shown], self._distances(self.points[shown], xy)

    def sweep_finds(self, xy: np.ndarray, sight: Sight, todo: np.ndarray):
        """(point indices, P(found) of each) of a sweep at ``xy`` for ``sight`` among the points
        ``todo`` (N,) bool: what ``best`` weighed it by."""
        sub = np.flatnonzero(todo)
        shown, dist = self._shown(coarse_blocked(self.built), xy, sight, sub, self.points[sub])
        p = np.ones(len(shown)) if sight.found is None else sight.found(dist[shown])
        return sub[shown], p

    def exhaust(self, xy: np.ndarray, unseen: np.ndarray, rng: float) -> np.ndarray:
        """(N,) bool: the points a sweep at ``xy`` should have shown but did not (module
        docstring)."""
        near = self.visible_points(coarse_blocked(self.built), xy, min(rng, EXHAUST_RADIUS))
        return near & unseen


def _coarse_cell(
    origin: tuple[float, float], xy: np.ndarray, shape: tuple[int, int]
) -> tuple[int, int] | None:
    """The (row, col) of the coarse cell (``COARSE`` m from ``origin``) holding ``xy`` (None:
    outside a grid of ``shape``)."""
    c, r = np.floor((np.asarray(xy, float) - np.array(origin)) / COARSE).astype(int)
    return (int(r), int(c)) if 0 <= r < shape[0] and 0 <= c < shape[1] else None


def _cell_xy(origin: tuple[float, float], cell: tuple[int, int]) -> np.ndarray:
    """The centre of coarse cell (row, col)."""
    return (np.array([cell[1], cell[0]], float) + 0.5) * COARSE + np.array(origin)


def _far_mass(
    cells: np.ndarray, w: np.ndarray, stand: Sequence, rng: float, shape: tuple[int, int]
) -> np.ndarray:
    """(h, w) the weight ``w`` of the points in coarse ``cells`` (P, 2: col, row) summed per
    cell, of the points farther than ``rng`` (in the plane, cell to cell) from every cell of
    ``stand`` ((row, col) or None: the reachable candidates')."""
    h, wd = shape
    near = np.zeros(shape, bool)
    for rc in stand:
        if rc is not None:
            near[rc] = True
    far = ndimage.distance_transform_edt(~near) * COARSE
    c, r = cells[:, 0], cells[:, 1]
    ok = (r >= 0) & (r < h) & (c >= 0) & (c < wd)
    ok[ok] = far[r[ok], c[ok]] > rng
    return np.bincount(r[ok] * wd + c[ok], weights=w[ok], minlength=h * wd).reshape(shape)


def _coarse_paths(
    passable: np.ndarray, start: tuple[int, int], cell: float
) -> tuple[np.ndarray, np.ndarray]:
    """(h, w) shortest 8-connected path lengths (m) over the ``passable`` cells (``cell`` m a
    side) from ``start`` (inf: none), and each cell's predecessor on its path (flat index; -9999
    at the start and where none)."""
    h, w = passable.shape
    idx = np.arange(h * w).reshape(h, w)
    rows, cols, lens = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):  # each neighbour pair once
        lo, hi = max(0, -dc), w - max(0, dc)
        both = passable[: h - dr, lo:hi] & passable[dr:, lo + dc : hi + dc]
        rows.append(idx[: h - dr, lo:hi][both])
        cols.append(idx[dr:, lo + dc : hi + dc][both])
        lens.append(np.full(int(both.sum()), cell * math.hypot(dr, dc)))
    r, c, d = np.concatenate(rows), np.concatenate(cols), np.concatenate(lens)
    g = csr_matrix((np.r_[d, d], (np.r_[r, c], np.r_[c, r])), shape=(h * w, h * w))
    dist, pred = dijkstra(g, indices=start[0] * w + start[1], return_predecessors=True)
    return dist.reshape(h, w), pred.reshape(h, w)


def _crossing(
    pred: np.ndarray, cell: tuple[int, int], start: tuple[int, int], known: np.ndarray, w: int
) -> tuple[int, int]:
    """The last cell of ``known`` on the path from ``start`` to ``cell`` (``pred``:
    ``_coarse_paths``' predecessors): where the way leaves the reachable map."""
    path = [cell]
    while path[-1] != start:
        p = int(pred[path[-1]])
        if p < 0:
            break
        path.append((p // w, p % w))
    last = start
    for rc in reversed(path):  # from the start outwards
        if not known[rc]:
            break
        last = rc
    return last


def _sweep_kernel(rng: float, dz: float, sight: Sight) -> np.ndarray:
    """(2n+1, 2n+1) what a sweep finds of a coarse cell's weight at each offset: ``sight.found``
    at the distance from a camera ``dz`` m above it (1 without a curve) within ``rng`` m in the
    plane, 0 beyond."""
    n = int(math.ceil(rng / COARSE))
    off = np.arange(-n, n + 1) * COARSE
    dxy = np.hypot(off[:, None], off[None, :])
    k = np.zeros_like(dxy)
    near = dxy <= rng
    d = np.sqrt(dxy[near] ** 2 + dz * dz)
    k[near] = 1.0 if sight.found is None else sight.found(d)
    return k


def _heap(bound: np.ndarray, upper: np.ndarray, exact: np.ndarray) -> list:
    """(-bound, candidate index, exact?) of the candidates whose ``upper`` bound on their points
    reaches ``MIN_GAIN``, as a heap: the largest bound first, then the lowest index
    (``ViewpointScorer.best``)."""
    rows = zip(bound.tolist(), upper.tolist(), exact.tolist(), strict=True)
    heap = [(-b, i, e) for i, (b, u, e) in enumerate(rows) if u >= MIN_GAIN]
    heapq.heapify(heap)
    return heap


def _order(v: Viewpoint) -> tuple[float, float, float, float]:
    return (-v.rate, v.seconds, float(v.xy[0]), float(v.xy[1]))


def floor_headings(
    built: BuiltMap, xy: np.ndarray, heading0: float, near: tuple[float, float] = (0.4, 2.0),
    min_unknown: float = 0.3,
) -> list[float]:  # fmt: skip
    """World headings (six, 60 degrees apart from ``heading0``) whose floor wedge (within
    ``near`` metres, 50 degrees wide) is at least ``min_unknown`` unknown: where an image at
    the near-floor tilt still maps something. Without these the robot would never know the floor
    around itself free (agent.frontiers: its look-around's second tilt)."""
    xs, ys = built._centers()
    # the cells within ``near[1]`` along both axes (the same cells of the ring, in the same order)
    cols = np.flatnonzero(np.abs(xs - xy[0]) <= near[1] + 1e-6)
    rows = np.flatnonzero(np.abs(ys - xy[1]) <= near[1] + 1e-6)
    dx, dy = xs[None, cols] - xy[0], ys[rows, None] - xy[1]
    d = np.hypot(dx, dy)
    ring = (d >= near[0]) & (d <= near[1])
    ang = np.arctan2(dy, dx)
    unknown = built.unknown[np.ix_(rows, cols)]
    out = []
    for i in range(6):
        h = heading0 + i * math.pi / 3
        wedge = ring & (np.abs(np.angle(np.exp(1j * (ang - h)))) <= math.radians(25))
        if wedge.any() and unknown[wedge].mean() >= min_unknown:
            out.append(float(np.angle(np.exp(1j * h))))
    return out


# =========================================================================== the efficiency model
def area_cover_seconds(
    area: float, rooms: int, rng: float, tm: TimeModel, images_per_site: float
) -> float:
    """Seconds to cover a footprint of ``area`` m^2 in ``rooms`` rooms for detection range
    ``rng`` (capped by what counts as seen): sites of radius 0.8 ``rng`` but at least one per
    room, the legs between them (a square lattice's spacing) and ``images_per_site`` images at
    each."""
    reach = 0.8 * rng
    rooms = max(1, rooms)
    per_room = max(1.0, (area / rooms) / (math.pi * reach * reach))
    sites = rooms * per_room
    spacing = math.sqrt(area / sites)
    return sites * (tm.leg_estimate(spacing) + tm.looks_estimate(images_per_site, HEAD_S))


@dataclass(frozen=True)
class WorldSize:
    """What the efficiency model assumes of the world before seeing it: footprint and rooms."""

    area: float
    rooms: int


def look_seconds_model(
    catalog: Catalog, probs: ss.ProbabilitySource, via: str, target: str, size: WorldSize,
    tm: TimeModel,
) -> float:  # fmt: skip
    """Seconds to look into the most likely relation volume of a found ``via`` (mid-range size):
    a drive of half a room's side and the images the volume needs."""
    typ = catalog.type(via)
    s = tuple((np.asarray(typ.size_min) + np.asarray(typ.size_max)) / 2)
    mid = ObjectInstance(via, -1, (0.0, 0.0, s[2] / 2), 0.0, s)
    best = max(typ.relations, key=lambda r: (probs.p(r.name, target), r.name))
    box = relation_volume(best, mid)
    images = int(np.clip(math.ceil(2 * float(max(box.half[0], box.half[1])) / 1.2 - 1e-9), 1, 4))
    drive = 0.5 * math.sqrt(size.area / max(1, size.rooms))
    return tm.leg_estimate(drive) + tm.looks_estimate(images, HEAD_S)


SWEEP_IMAGES = 0.6 * 6 * len(ss.SWEEP_TILTS)  # images of a target sweep (60% of 6 x 3 taken)
RING_IMAGES = 6.0  # one ring of images finds furniture


def predicted_plan(
    target: str,
    catalog: Catalog,
    probs: ss.ProbabilitySource,
    size: WorldSize,
    ranges: Mapping[str, float],
    tm: TimeModel,
    candidates: Sequence[str],
) -> list[ss.IndirectOption]:
    """Wixson & Ballard's expected costs (``space.indirect_plan``) with the area model's
    coverage costs: the direct plan and one per candidate type, cheapest first."""
    cover = {target: area_cover_seconds(size.area, size.rooms, ranges[target], tm, SWEEP_IMAGES)}
    for name in candidates:
        furniture = catalog.type(name).is_furniture
        images = RING_IMAGES if furniture else SWEEP_IMAGES
        cover[name] = area_cover_seconds(size.area, size.rooms, ranges[name], tm, images)
    look = {n: look_seconds_model(catalog, probs, n, target, size, tm) for n in candidates}
    return ss.indirect_plan(target, catalog, probs, cover, look, candidates)


def predicted_gain(plan: Sequence[ss.IndirectOption], via: str | None) -> float | None:
    """The efficiency ratio C_direct / C_via of ``via`` in ``plan`` (None if not in it)."""
    direct = next(o.cost for o in plan if o.via is None)
    for o in plan:
        if o.via == via and via is not None:
            return direct / max(o.cost, 1e-9)
    return None
