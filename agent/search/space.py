"""The pure parts of object search: detectability, where has been seen, candidate regions and
their scores, coverage tours, and the expected-cost decision of detectability-driven search.

Nothing here renders or steps MuJoCo; the policies (agent.search.policies) run on the world.

Seen map. The room's volume is sampled on a lattice (``SeenMap``: 0.2 m in x and y, 0.15 m in z
from 5 cm to 1.85 m, minus the points inside the solid parts of furniture, which no object can
occupy and no camera can see). After every image, the points that the depth image shows are
*visible* (inside the frustum and not behind the rendered surface by more than 10 cm) get their
viewing distance recorded; a point counts as *seen for type T* once it was visible from within
T's effective detection range (``effective_range``). This is bookkeeping of where the robot has
looked, from the real rendered depth, so occlusion by furniture is respected.

Effective range. An object of type T is detected with at least ``min_pixels`` visible pixels
within ``max_range``. Its projected area at distance d is about f^2 A / d^2 (f: focal length in
pixels, A: the mean of its three face areas, an orientation average), so the pixel rule alone
allows d up to f sqrt(A / min_pixels); ``effective_range`` takes ``RANGE_SAFETY`` (0.8) of that
(partial occlusion, oblique views) and caps it at ``max_range``. A cup: about 3.0 m, a pen
1.9 m, a desk 9 m (rendered detections reach further: this errs on the side of looking again).

Candidate regions (location constraint, paper section 3). Every known object b (the furniture
map, plus everything detected so far) and every rel in RELATIONS(type(b)) gives a region, the
relation volume v_rel(b), with p = P(rel(T)) read from a ``ProbabilitySource`` (the knowledge
base's interval: its lower bound, p0 or upper bound, by ``rank``; or ground truth). Regions
whose lattice points nearly coincide (Jaccard >= 0.6) are merged into one candidate (noisy-or of
their p). A region's score is the probability that T is in its *unseen* part, counting every
region that overlaps it:

    P(r) = 1 - prod_{r'} (1 - p_{r'} |r & r' & U| / |r'|)       U: points not yet seen for T

(T uniformly placed inside r' given rel'(T); independent evidence), so the space near both a
monitor and a desk ranks above the space near only one, a region already looked into scores
little, and two regions that share space count it once. Candidates are ranked by P(r) per
expected second to look there (drive over the grid, turns, head slews and images, TimeModel):
the classic optimal order for searching independent places.

Coverage (exhaustive search and the fallback). ``coverage_viewpoints``: base positions on a
0.5 m lattice of reachable free cells, chosen by greedy set cover of the unseen points within
the type's effective range, then ordered by a nearest-neighbour tour (grid distances) improved
by 2-opt. At each viewpoint the head sweeps (``sweep_gazes``): headings 60 degrees apart and
three tilts, each kept only if its frustum still holds at least ``SWEEP_MIN_SHARE`` (10%) of the
points unseen within range there (and 8 points). That threshold was measured: 0 (any image that
shows 8 new points) gave exhaustive a median of 10.8 s over 40 office episodes, 0.05 6.5 s, 0.1
5.9 s, 0.15 7.2 s; the best value makes the baseline as strong as we could make it. A round of
the tour whose sweeps take no image is followed by one without the share threshold, so the
coverage still completes.

Detectability-driven search (``indirect_plan``). With nothing known, looking for T directly
costs about half a coverage tour at T's range, C_T = cover(r_T) / 2. Looking first for an
intermediate type I costs cover(r_I) / 2 to find one (furniture: one ring of images at its
height), then the time to look into its most likely relation volume. I is in the room with
probability 1 - exp(-k_I) (k_I: instances per room, n_I over the rooms learned in), and T is then
related to one of them with q = 1 - (1 - q_I)^max(1, k_I), q_I = max_{rel in RELATIONS(I)}
P(rel(T)); otherwise the direct search remains:
C_I = present (cover(r_I)/2 + look_I + (1 - q) C_T) + (1 - present)(cover(r_I) + C_T).
The cheapest plan wins.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

from ctxsearch.agent.navigation import OccupancyGrid, nearest_free
from ctxsearch.agent.sight import focal_px, mean_face_area
from ctxsearch.agent.viewplan import facing_for
from ctxsearch.envs.camera import PinholeCamera, frustum_mask
from ctxsearch.envs.detector import min_pixels_at
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.parts import world_parts_array
from ctxsearch.envs.robot_spec import RobotSpec, TimeModel, wrap_angle
from ctxsearch.knowledge.catalog import Catalog, ObjectType
from ctxsearch.knowledge.geometry import Box, ObjectInstance, relation_volume

# The probability sources live in knowledge.ranking (one place); re-exported for the policies.
from ctxsearch.knowledge.ranking import (  # noqa: F401
    DEFAULT_ESTIMATE,
    DEFAULT_MIN_EVIDENCE,
    DEFAULT_RANK,
    ESTIMATES,
    RANK_MODES,
    BackoffProbabilities,
    KBProbabilities,
    ProbabilitySource,
    TableProbabilities,
    UniformProbabilities,
)

RANGE_SAFETY = 0.8
LATTICE_XY = 0.2  # m
LATTICE_Z = (0.05, 1.85, 0.15)  # first, last, step (m)
VISIBLE_TOL = 0.10  # m a point may lie behind the rendered surface and still count as visible
MIN_REGION_HALF = 0.1  # m: thin volumes (TOUCHING-BOTTOM-OF-CUP) are thickened to catch points
MERGE_JACCARD = 0.6
SWEEP_HEADING_STEP = math.radians(60.0)
SWEEP_TILTS = (-0.95, -0.35, 0.25)
SWEEP_MIN_SHARE = 0.1  # an image of a sweep must show this share of what is unseen around
# Where an object may stand (``SeenMap.standable``): a point seen with no surface seen below it
# keeps this weight (free air; objects rest on something, a little is kept for what hangs).
AIR_WEIGHT = 0.02
SUPPORT_STRIDE = 4  # pixels between the depth points that mark supports (built map)


# =========================================================================== detectability
# (the focal length in pixels and a type's mean face area: agent.sight, shared with learning)
def effective_range(
    typ: ObjectType,
    spec: RobotSpec | None = None,
    width: int = 320,
    height: int = 240,
    safety: float = RANGE_SAFETY,
) -> float:
    """How far (m) an instance of ``typ`` is reliably detected (see the module docstring)."""
    spec = spec or RobotSpec()
    mp = min_pixels_at(typ.min_pixels, width, height)
    pixel_range = focal_px(spec, height) * math.sqrt(mean_face_area(typ) / mp) * safety
    return float(min(typ.max_range, pixel_range))


# =========================================================================== the seen map
@dataclass
class SeenMap:
    """Lattice points of the room's free volume, the distance each was best seen from, and where
    an object can stand (``support``: the floor layer and the points just above a surface)."""

    points: np.ndarray  # (N, 3)
    best: np.ndarray  # (N,) metres; inf: never visible
    # (N,) bool: a surface lies less than one lattice step below the point (the floor layer,
    # a top, a shelf board): known from the furniture map (given), or seen in depth images
    # (built: ``learn_support``); None: every point
    support: np.ndarray | None = None
    learn_support: bool = False
    # the points' lattice keys sorted, the point of each, the lattice's corner (``_keys``)
    _index: tuple | None = field(default=None, repr=False, compare=False)

    @classmethod
    def for_room(
        cls, layout: RoomLayout, catalog: Catalog, step_xy: float = LATTICE_XY,
        z: tuple[float, float, float] = LATTICE_Z,
    ) -> SeenMap:  # fmt: skip
        """The lattice over ``layout``'s room minus the points inside furniture's solid parts."""
        pts = cls._lattice(layout, step_xy, z)
        keep = np.ones(len(pts), bool)
        rests = pts[:, 2] < z[0] + z[2] / 2  # the floor layer
        for o in layout.objects:
            if not catalog.type(o.type).is_furniture:
                continue
            arr = world_parts_array(o, catalog)
            for c, yaw, h in zip(arr.centers, arr.yaws, arr.halves, strict=True):
                # the same test on the points within the part's x extent (the lattice is x-major)
                ex = abs(math.cos(yaw)) * h[0] + abs(math.sin(yaw)) * h[1] + 1e-6
                i, j = np.searchsorted(pts[:, 0], [c[0] - ex, c[0] + ex + 1e-12])
                keep[i:j] &= ~Box(c, float(yaw), h).contains_points(pts[i:j])
                # the slab of one lattice step above the part's top rests on it
                top = float(c[2] + h[2])
                slab = Box((c[0], c[1], top + z[2] / 2), float(yaw), (h[0], h[1], z[2] / 2))
                rests[i:j] |= slab.contains_points(pts[i:j])
        return cls(pts[keep], np.full(int(keep.sum()), np.inf), rests[keep])

    @classmethod
    def for_footprint(
        cls, layout: RoomLayout, step_xy: float = LATTICE_XY, z: tuple[float, float, float] = LATTICE_Z
    ) -> SeenMap:  # fmt: skip
        """The lattice over ``layout``'s footprint and height only (what a robot that knows
        nothing of the furniture may assume: ``--map built``)."""
        pts = cls._lattice(layout, step_xy, z)
        floor = pts[:, 2] < z[0] + z[2] / 2
        return cls(pts, np.full(len(pts), np.inf), floor, learn_support=True)

    @staticmethod
    def _lattice(layout: RoomLayout, step_xy: float, z: tuple[float, float, float]) -> np.ndarray:
        """(N, 3) lattice points over the footprint, from z[0] to z[1] below the ceiling."""
        hw, hd = layout.width / 2, layout.depth / 2
        xs = np.arange(-hw + step_xy / 2, hw, step_xy)
        ys = np.arange(-hd + step_xy / 2, hd, step_xy)
        zs = np.arange(z[0], z[1] + 1e-9, z[2])
        zs = zs[zs < layout.height]
        gx, gy, gz = np.meshgrid(xs, ys, zs, indexing="ij")
        return np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])

    def __len__(self) -> int:
        return len(self.points)

    def copy(self) -> SeenMap:
        """An independent copy."""
        sup = None if self.support is None else self.support.copy()
        return SeenMap(self.points.copy(), self.best.copy(), sup, self.learn_support)

    def standable(self) -> np.ndarray:
        """(N,) weights of where an object of the target may be: 1 on a support, ``AIR_WEIGHT``
        elsewhere (free air: objects rest on something). On the built map a point not seen yet
        may have a surface below it: it gets the share of the seen points of its height that
        had one (Laplace's rule: (supported + 1) / (seen + 2)), so the space not explored yet
        is expected to be furnished as the explored part was."""
        if self.support is None:
            return np.ones(len(self.points))
        w = np.where(self.support, 1.0, AIR_WEIGHT)
        if not self.learn_support:
            return w
        level = np.rint((self.points[:, 2] - LATTICE_Z[0]) / LATTICE_Z[2]).astype(np.int64)
        seen = np.isfinite(self.best)
        k = int(level.max()) + 1
        rate = (np.bincount(level[seen & self.support], minlength=k) + 1.0) / (
            np.bincount(level[seen], minlength=k) + 2.0
        )
        unknown = ~seen & ~self.support
        w[unknown] = np.maximum(rate[level[unknown]], AIR_WEIGHT)
        return w

    def _supports(self, camera: PinholeCamera, depth: np.ndarray) -> None:
        """Mark the points just above the level surfaces a depth image shows (every
        ``SUPPORT_STRIDE`` pixel whose surface normal, from the neighbouring pixels, is within
        about 25 degrees of vertical, up to the lattice's top): each supports the lattice point of
        its column whose height is within one step above it. Walls and the sides of furniture
        support nothing."""
        # only the strided pixels and their right and lower neighbours (the same numbers)
        s = SUPPORT_STRIDE
        h, w = np.shape(depth)
        r0, c0 = np.arange(0, h - 1, s), np.arange(0, w - 1, s)
        rows = np.column_stack([r0, r0 + 1]).ravel()
        cols = np.column_stack([c0, c0 + 1]).ravel()
        pts = camera.backproject(depth, rows, cols)
        p = pts[0::2, 0::2]
        n = np.cross(pts[0::2, 1::2] - p, pts[1::2, 0::2] - p)
        with np.errstate(invalid="ignore", divide="ignore"):
            level = np.abs(n[..., 2]) > 0.9 * np.linalg.norm(n, axis=-1)
        hits = p.reshape(-1, 3)
        z0, z1, dz = LATTICE_Z
        ok = level.ravel() & np.isfinite(hits).all(axis=1)
        ok &= (hits[:, 2] > 0.02) & (hits[:, 2] < z1)
        hits = hits[ok]
        if len(hits) == 0:
            return
        key, order, lo = self._keys()
        ix = np.floor((hits[:, 0] - lo[0]) / LATTICE_XY + 0.5).astype(np.int64)
        iy = np.floor((hits[:, 1] - lo[1]) / LATTICE_XY + 0.5).astype(np.int64)
        iz = np.ceil((hits[:, 2] - z0) / dz - 1e-9).astype(np.int64)
        want = _lattice_key(ix, iy, iz)
        found = np.clip(np.searchsorted(key, want), 0, len(key) - 1)
        self.support[order[found[key[found] == want]]] = True

    def _keys(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The points' lattice keys sorted, the point of each, and the lattice's corner (the
        points' least x and y: the whole footprint lattice, ``for_footprint``); made once."""
        if self._index is None:
            lo = self.points[:, :2].min(axis=0)
            ix = np.rint((self.points[:, 0] - lo[0]) / LATTICE_XY).astype(np.int64)
            iy = np.rint((self.points[:, 1] - lo[1]) / LATTICE_XY).astype(np.int64)
            iz = np.rint((self.points[:, 2] - LATTICE_Z[0]) / LATTICE_Z[2]).astype(np.int64)
            k = _lattice_key(ix, iy, iz)
            order = np.argsort(k, kind="stable")
            self._index = (k[order], order, lo)
        return self._index

    def update(self, camera: PinholeCamera, depth: np.ndarray) -> np.ndarray:
        """Record an image: the points visible in ``depth`` (H, W, optical-axis metres) from
        ``camera``. Returns their mask."""
        depth = np.asarray(depth, float)
        idx = np.flatnonzero(camera.visible(self.points, depth, VISIBLE_TOL))
        dist = np.linalg.norm(self.points[idx] - np.asarray(camera.position, float), axis=1)
        self.best[idx] = np.minimum(self.best[idx], dist)
        if self.learn_support and self.support is not None:
            self._supports(camera, depth)
        mask = np.zeros(len(self.points), bool)
        mask[idx] = True
        return mask

    def mark_frustum(self, camera: PinholeCamera, max_distance: float) -> np.ndarray:
        """Record an image without depth: every point inside the frustum within ``max_distance``
        (no occlusion; for bodies that render nothing). Returns their mask."""
        m = camera.sees(self.points, max_distance)
        d = np.linalg.norm(self.points[m] - np.asarray(camera.position, float), axis=1)
        self.best[m] = np.minimum(self.best[m], d)
        return m

    def unseen(self, max_range: float) -> np.ndarray:
        """(N,) bool: points not yet seen from within ``max_range``."""
        return ~(self.best <= max_range)

    def seen_fraction(self, max_range: float) -> float:
        """The share of points seen from within ``max_range``."""
        return float(np.mean(self.best <= max_range)) if len(self.best) else 1.0

    def in_box(self, box: Box, min_half: float = MIN_REGION_HALF) -> np.ndarray:
        """Indices of the points inside ``box`` (each half extent at least ``min_half``)."""
        half = np.maximum(np.asarray(box.half, float), min_half)
        return np.flatnonzero(
            Box(np.asarray(box.center, float), float(box.yaw), half).contains_points(self.points)
        )


def _lattice_key(ix: np.ndarray, iy: np.ndarray, iz: np.ndarray) -> np.ndarray:
    """One integer per lattice cell (ix, iy, iz), for sorted look-ups."""
    return (ix * 100_003 + iy) * 64 + iz


# =========================================================================== candidate regions
@dataclass
class Region:
    """A candidate place to look: one relation volume (or several merged), its probability."""

    box: Box
    p: float  # P(rel(T)) (noisy-or of the merged relations)
    members: list[tuple[str, int]]  # (relation, reference instance id)
    points: np.ndarray  # indices into the SeenMap
    facing: np.ndarray | None = None  # the side to look from (viewplan.facing_for), if any
    score: float = 0.0  # P(T in the unseen part) (set by score_regions)
    cost: float = 0.0  # expected seconds to look (set by score_regions)

    @property
    def key(self) -> tuple[tuple[str, int], ...]:
        """A stable identity: the sorted members."""
        return tuple(sorted(self.members))

    @property
    def label(self) -> str:
        """e.g. ``ON-TOP-OF-DESK #3 + NEAR-MONITOR #7``."""
        return " + ".join(f"{r} #{i}" for r, i in self.members)

    @property
    def rate(self) -> float:
        """Probability per second: the ranking key."""
        return self.score / max(self.cost, 1e-6)


def object_regions(
    b: ObjectInstance,
    target: str,
    catalog: Catalog,
    probs: ProbabilitySource,
    seen: SeenMap,
    min_p: float = 1e-6,
) -> list[Region]:
    """One region per rel in RELATIONS(type(b)) with P(rel(target)) > ``min_p`` whose volume
    holds lattice points (none for an instance of the target type itself)."""
    if b.type == target:
        return []
    out = []
    for rel in catalog.type(b.type).relations:
        p = float(probs.p(rel.name, target))
        if p <= min_p:
            continue
        box = relation_volume(rel, b)
        pts = seen.in_box(box)
        if len(pts):
            out.append(Region(box, p, [(rel.name, b.id)], pts, facing_for(rel, b)))
    return out


def build_regions(
    known: Iterable[ObjectInstance],
    target: str,
    catalog: Catalog,
    probs: ProbabilitySource,
    seen: SeenMap,
    min_p: float = 1e-6,
) -> list[Region]:
    """The candidate regions of every known object (``object_regions``), near-duplicates merged.
    Deterministic order."""
    raw = [
        r
        for b in sorted(known, key=lambda o: o.id)
        for r in object_regions(b, target, catalog, probs, seen, min_p)
    ]
    return merge_regions(raw)


class RegionBuilder:
    """``build_regions`` with the per-object regions cached (objects do not move)."""

    def __init__(self, catalog: Catalog, probs: ProbabilitySource, seen: SeenMap, target: str):
        self.catalog, self.probs, self.seen, self.target = catalog, probs, seen, target
        self._per_object: dict[int, list[Region]] = {}
        self._merged: tuple[tuple[int, ...], list[Region]] | None = None

    def regions(self, known: Iterable[ObjectInstance]) -> list[Region]:
        """The merged candidate regions of ``known`` (fresh Region objects every call)."""
        objs = sorted(known, key=lambda o: o.id)
        ids = tuple(o.id for o in objs)
        if self._merged is None or self._merged[0] != ids:
            raw = []
            for b in objs:
                if b.id not in self._per_object:
                    self._per_object[b.id] = object_regions(
                        b, self.target, self.catalog, self.probs, self.seen
                    )
                raw.extend(self._per_object[b.id])
            self._merged = (ids, merge_regions(raw))
        return [Region(r.box, r.p, list(r.members), r.points, r.facing) for r in self._merged[1]]


def merge_regions(regions: Sequence[Region], jaccard: float = MERGE_JACCARD) -> list[Region]:
    """Merge regions whose point sets overlap with Jaccard index >= ``jaccard`` (greedy, in
    order of decreasing p): the merged region keeps the larger box and the union of the points,
    and p becomes the noisy-or 1 - prod(1 - p_i)."""
    order = sorted(range(len(regions)), key=lambda i: (-regions[i].p, regions[i].key))
    out: list[Region] = []
    bounds: list[np.ndarray] = []  # index-space bounds of each merged set, for a cheap pre-test
    for i in order:
        r = regions[i]
        lo_r, hi_r = int(r.points.min()), int(r.points.max())
        for j, o in enumerate(out):
            lo_o, hi_o = bounds[j]
            if hi_r < lo_o or hi_o < lo_r:
                continue
            inter = len(np.intersect1d(r.points, o.points, assume_unique=True))
            union = len(r.points) + len(o.points) - inter
            if inter and inter / union >= jaccard:
                bigger = r if len(r.points) > len(o.points) else o
                pts = np.union1d(r.points, o.points)
                out[j] = Region(
                    bigger.box, 1 - (1 - o.p) * (1 - r.p), o.members + r.members, pts, bigger.facing
                )
                bounds[j] = np.array([int(pts[0]), int(pts[-1])])
                break
        else:
            out.append(Region(r.box, r.p, list(r.members), np.sort(r.points), r.facing))
            bounds.append(np.array([lo_r, hi_r]))
    return out


def region_probabilities(regions: Sequence[Region], unseen: np.ndarray) -> np.ndarray:
    """P(T in the unseen part of each region), counting every overlapping region (see the module
    docstring). (R,)"""
    if not regions:
        return np.zeros(0)
    n = len(unseen)
    rows = np.concatenate([np.full(len(r.points), i) for i, r in enumerate(regions)])
    cols = np.concatenate([r.points for r in regions])
    m = sparse.csr_matrix((np.ones(len(cols)), (rows, cols)), shape=(len(regions), n))
    size = np.asarray(m.sum(1)).ravel()  # |r'|
    mu = m @ sparse.diags(unseen.astype(float))
    inter = (mu @ m.T).toarray()  # [r, r'] = |r & r' & U|
    p = np.array([r.p for r in regions])
    share = np.clip(p[None, :] * inter / np.maximum(size[None, :], 1.0), 0.0, 1.0)
    return 1.0 - np.prod(1.0 - share, axis=1)


@dataclass
class CostModel:
    """Expected seconds to look into a box from the robot's position (drive + head + images)."""

    grid: OccupancyGrid
    time_model: TimeModel
    view_distance: float  # the base stands at most this far from the box's footprint
    head_s: float = 0.6  # mean head slew per image (s)
    image_span: float = 1.2  # m of footprint one image covers (for the image count)
    _cells: np.ndarray = field(init=False, repr=False)
    _free: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        xs, ys = self.grid.cell_centers()
        self._cells = np.column_stack([np.tile(xs, len(ys)), np.repeat(ys, len(xs))])
        self._free = self.grid.free.ravel()

    def images(self, box: Box) -> int:
        """Images expected to cover ``box`` (1 to 4)."""
        ext = 2 * float(max(box.half[0], box.half[1]))
        return int(np.clip(math.ceil(ext / self.image_span - 1e-9), 1, 4))

    def seconds(self, box: Box, xy: np.ndarray, field_: np.ndarray | None = None) -> float:
        """Expected seconds to look into ``box`` starting at ``xy`` (``field_``: the grid's
        distance field from ``xy``, flattened, if already computed)."""
        if field_ is None:
            field_ = self.grid.distances_from(xy).ravel()
        # free cells within reach: first the square around the box's circumscribed circle
        r = self.view_distance + float(np.hypot(box.half[0], box.half[1])) + 1e-6
        c = self._cells
        idx = np.flatnonzero(
            self._free
            & (np.abs(c[:, 0] - box.center[0]) <= r)
            & (np.abs(c[:, 1] - box.center[1]) <= r)
        )
        idx = idx[box.footprint_distance(c[idx]) <= self.view_distance]
        d = float(field_[idx].min()) if len(idx) else math.inf
        if not math.isfinite(d):
            d = float(np.hypot(*(np.asarray(box.center[:2]) - np.asarray(xy))))
        tm = self.time_model
        return tm.leg_estimate(d) + tm.looks_estimate(self.images(box), self.head_s)


def expected_mass(catalog: Catalog, probs: ProbabilitySource, target: str) -> float | None:
    """The relation volumes' P(rel(T)) summed over a world's expected objects: sum over types t
    of instances(t) * sum over rel in RELATIONS(t) of P(rel(T)) (None if ``probs`` knows no
    instance counts, or it is 0). What ``target_density`` totals over a whole world, before
    anything in it is seen."""
    total = 0.0
    for t in catalog.types:
        k = probs.instances(t.name)
        if k is None:
            return None
        if k > 0 and t.name != target:
            total += k * sum(float(probs.p(r.name, target)) for r in t.relations)
    return total if total > 0 else None


def target_density(
    regions: Sequence[Region], surveyed: np.ndarray, stand: np.ndarray | None = None
) -> np.ndarray | None:
    """(N,) where the target may be, in P(rel(T)) per seen-map point, from the known objects'
    relation volumes (``regions``; ``surveyed`` (N,) bool: the points seen from within the
    built map's depth range, where furniture would have been detected); None when no volume has
    a probability (nothing known yet: every point alike).

    A point inside relation volumes gets the largest of their densities p_r / |r| (a volume's
    probability spread over its points; overlapping volumes, NEAR-DESK and NEAR-CHAIR around
    one desk, are not evidence twice). Every other point gets the mean density of the surveyed
    part (the mass the volumes give its points, each point once, over its points): the part not
    explored yet is expected to hold furniture, and with it the target, as the part explored so
    far did, and the floor between the known
    volumes (where clutter may lie) is not assumed empty. The search policies normalise it over
    what is left to see, so the share of it an image or a volume shows is the probability that
    the target is there given that it was not found yet (``SearchContext.online_search``). The
    choice of the surveyed part's mean is this module's, not the paper's (which gives no
    prior for space no known object explains).

    ``stand`` (N,) weights of where an object can stand (``SeenMap.standable``; None: every
    point alike): a volume's probability is spread over its points in proportion to them, the
    mean density counts them, and the density is multiplied by them."""
    stand = np.ones(len(surveyed)) if stand is None else np.asarray(stand, float)
    regions = [r for r in regions if r.p > 0 and len(r.points) and stand[r.points].sum() > 0]
    if not regions:
        return None
    w = np.zeros(len(surveyed))
    covered = np.zeros(len(surveyed), bool)
    for r in regions:
        w[r.points] = np.maximum(w[r.points], r.p / float(stand[r.points].sum()))
        covered[r.points] = True
    mass = float((w * stand)[covered].sum())
    base = mass / max(float(stand[surveyed | covered].sum()), 1.0)
    w[~covered] = base
    return w * stand


def score_regions(
    regions: Sequence[Region],
    seen: SeenMap,
    target_range: float,
    costs: CostModel,
    xy: np.ndarray,
    weights: np.ndarray | None = None,
) -> list[Region]:
    """Set every region's score and cost (expected seconds from ``xy``) and return them best
    first (score per second; ties: cheaper, then key). The score is P(T in its unseen part)
    (``region_probabilities``), or with ``weights`` ((N,): the belief, the probability that
    the target is at each point given every image so far: agent.search.belief) their sum over
    the region's points."""
    if not regions:
        return []
    if weights is None:
        probs = region_probabilities(regions, seen.unseen(target_range))
    else:
        probs = [float(weights[r.points].sum()) for r in regions]
    field_ = costs.grid.distances_from(xy).ravel()
    for r, p in zip(regions, probs, strict=True):
        r.score = float(p)
        r.cost = costs.seconds(r.box, xy, field_)
    return sorted(regions, key=lambda r: (-r.rate, r.cost, r.key))


# =========================================================================== coverage
def lattice_candidates(grid: OccupancyGrid, start_xy: np.ndarray, step: float = 0.5) -> np.ndarray:
    """Reachable free cell centres on a ``step`` lattice (M, 2), the start's free cell first."""
    start = nearest_free(grid, start_xy)
    if start is None:
        return np.zeros((0, 2))
    reach = grid.reachable_mask(start)
    k = max(1, int(round(step / grid.resolution)))
    lat = np.zeros_like(reach)
    lat[k // 2 :: k, k // 2 :: k] = True
    rows, cols = np.nonzero(reach & lat)
    xs, ys = grid.cell_centers()
    return np.vstack([start[None, :], np.column_stack([xs[cols], ys[rows]])])


def coverage_viewpoints(
    grid: OccupancyGrid,
    points: np.ndarray,
    start_xy: np.ndarray,
    max_range: float,
    spec: RobotSpec | None = None,
    goal: float = 0.95,
    step: float = 0.5,
    max_viewpoints: int = 40,
) -> np.ndarray:
    """Base positions (K, 2) from which every one of ``points`` (N, 3) is within ``max_range`` of
    the camera (greedy set cover until ``goal`` of the coverable points), in tour order from
    ``start_xy``. Occlusion is not modelled here: the sweeps at each viewpoint skip what the
    depth images already showed, and a later tour covers what stayed hidden."""
    spec = spec or RobotSpec()
    cand = lattice_candidates(grid, start_xy, step)
    if len(cand) == 0 or len(points) == 0:
        return np.zeros((0, 2))
    cams = np.column_stack([cand, np.full(len(cand), spec.camera_height)])
    cover = np.zeros((len(points), len(cand)), bool)  # (point, candidate): its rows are read
    pts = [np.ascontiguousarray(points[:, j]) for j in range(3)]
    for i in range(0, len(cand), 64):  # norm's sum, (dx^2 + dy^2) + dz^2, without (., ., 3)
        c = cams[i : i + 64]  # only the points within range of the chunk's x and y spans
        lo, hi = c.min(axis=0) - max_range - 1e-9, c.max(axis=0) + max_range + 1e-9
        near = (pts[0] >= lo[0]) & (pts[0] <= hi[0]) & (pts[1] >= lo[1]) & (pts[1] <= hi[1])
        dx, dy, dz = (c[:, j, None] - pts[j][near] for j in range(3))
        cover[near, i : i + 64] = (np.sqrt((dx * dx + dy * dy) + dz * dz) <= max_range).T
    need = int(math.ceil(goal * cover.any(1).sum()))
    got = np.zeros(len(points), bool)
    gain, chosen = cover.sum(0), []  # a candidate's gain: what it covers that none chosen does
    while got.sum() < need and len(chosen) < max_viewpoints:
        i = int(np.argmax(gain))
        if gain[i] == 0:
            break
        chosen.append(i)
        new = cover[:, i] & ~got
        got |= new
        gain -= cover[new].sum(0)
    return tour_order(grid, cand[chosen], start_xy)


def tour_order(grid: OccupancyGrid, sites: np.ndarray, start_xy: np.ndarray) -> np.ndarray:
    """``sites`` (K, 2) in the order of a short open tour from ``start_xy``: nearest neighbour on
    grid driving distances, then 2-opt."""
    k = len(sites)
    if k <= 1:
        return np.asarray(sites, float).reshape(-1, 2)
    nodes = np.vstack([np.asarray(start_xy, float)[None, :], sites])
    dist = np.zeros((k + 1, k + 1))
    for i, a in enumerate(nodes):
        f = grid.distances_from(a)
        for j, b in enumerate(nodes):
            r, c = grid.to_cell(b)
            v = f[r, c] if grid.in_grid(r, c) else np.inf
            dist[i, j] = v if np.isfinite(v) else 1e3 + float(np.hypot(*(a - b)))
    order = [0]
    left = set(range(1, k + 1))
    while left:
        nxt = min(left, key=lambda j: (dist[order[-1], j], j))
        order.append(nxt)
        left.remove(nxt)
    improved = True
    while improved:
        improved = False
        for i in range(1, k):
            for j in range(i + 1, k + 1):
                a, b = order[i - 1], order[i]
                c = order[j]
                d_ = order[j + 1] if j + 1 <= k else None
                old = dist[a, b] + (dist[c, d_] if d_ is not None else 0.0)
                new = dist[a, c] + (dist[b, d_] if d_ is not None else 0.0)
                if new < old - 1e-9:
                    order[i : j + 1] = order[i : j + 1][::-1]
                    improved = True
    return nodes[order[1:]]


def tour_seconds(
    grid: OccupancyGrid, sites: np.ndarray, start_xy: np.ndarray, time_model: TimeModel
) -> float:
    """Seconds to drive the tour through ``sites`` in order (grid distances, a quarter turn per
    leg)."""
    t, cur = 0.0, np.asarray(start_xy, float)
    for s in sites:
        r, c = grid.to_cell(s)
        d = grid.distances_from(cur)[r, c] if grid.in_grid(r, c) else np.inf
        if not np.isfinite(d):
            d = float(np.hypot(*(s - cur)))
        t += time_model.leg_estimate(d, always_turn=True)
        cur = s
    return t


@dataclass(frozen=True)
class SweepGaze:
    """One image of a sweep: world heading of the camera and tilt."""

    heading: float
    tilt: float
    gain: int  # unseen points predicted in the frustum


@dataclass(frozen=True)
class SweepOptions:
    """How a sweep is laid out: the tilts of each heading, the heading step, and what an image
    must be predicted to show (``min_gain`` unseen points and ``min_share`` of those unseen
    around)."""

    tilts: Sequence[float] = SWEEP_TILTS
    heading_step: float = SWEEP_HEADING_STEP
    min_gain: int = 8
    min_share: float = SWEEP_MIN_SHARE


def sweep_gazes(
    xy: np.ndarray,
    current_heading: float,
    points: np.ndarray,
    unseen: np.ndarray,
    spec: RobotSpec,
    max_range: float,
    options: SweepOptions | None = None,
) -> list[SweepGaze]:
    """The images of a pan/tilt sweep at ``xy`` worth taking, ordered as one turn starting from
    ``current_heading``: each is predicted to show at least ``min_gain`` unseen points within
    ``max_range`` and ``min_share`` of those unseen here, counting the earlier images of the
    sweep."""
    opt = options or SweepOptions()
    min_gain, tilts, heading_step = opt.min_gain, opt.tilts, opt.heading_step
    cam = np.array([xy[0], xy[1], spec.camera_height])
    todo = unseen.copy()
    near = np.linalg.norm(points - cam, axis=1) <= max_range
    todo &= near
    if todo.sum() < min_gain:
        return []
    min_gain = max(min_gain, int(math.ceil(opt.min_share * todo.sum())))
    n_h = max(1, int(round(2 * math.pi / heading_step)))
    headings = [current_heading + i * 2 * math.pi / n_h for i in range(n_h)]
    out: list[SweepGaze] = []
    for h in headings:
        for t in tilts:
            t = float(np.clip(t, *spec.tilt_range))
            m = frustum_mask(cam, h, t, points, spec, max_range) & todo
            g = int(m.sum())
            if g >= min_gain:
                out.append(SweepGaze(wrap_angle(h), t, g))
                todo &= ~m
    return out


# =========================================================================== indirect search
@dataclass(frozen=True)
class IndirectOption:
    """One plan of detectability-driven search and its expected cost (s)."""

    via: str | None  # the intermediate type, None: look for the target directly
    cost: float
    q: float = 0.0  # P(T in a relation volume of a found instance of ``via``)
    find_s: float = 0.0  # expected seconds to find an instance of ``via``
    look_s: float = 0.0  # expected seconds to look into its best relation volumes


def relation_probability(
    catalog: Catalog, probs: ProbabilitySource, via: str, target: str
) -> float:
    """q_I = max over rel in RELATIONS(via) of P(rel(target))."""
    rels = catalog.type(via).relations
    return max((float(probs.p(r.name, target)) for r in rels), default=0.0)


def indirect_plan(
    target: str,
    catalog: Catalog,
    probs: ProbabilitySource,
    cover_s: Mapping[str, float],
    look_s: Mapping[str, float],
    candidates: Sequence[str] | None = None,
) -> list[IndirectOption]:
    """Every plan (direct, and via each candidate type) with its expected cost, cheapest first.

    ``cover_s[t]``: seconds of a coverage tour at type t's effective range; ``look_s[t]``:
    seconds to look into the most likely relation volume of one found t. Expected costs:
    direct C_T = cover_s[T] / 2. Via I, with k = ``probs.instances(I)`` expected instances per
    room (1 if unknown), I is present with probability 1 - exp(-k) and then T is related to one
    of them with q = 1 - (1 - q_I)^max(1, k):

        C_I = present (cover_s[I]/2 + look_s[I] + (1 - q) C_T) + (1 - present)(cover_s[I] + C_T)

    Ties go to the direct plan, then to catalog order.
    """
    direct = cover_s[target] / 2
    out = [IndirectOption(None, direct)]
    names = candidates if candidates is not None else catalog.type_names
    for name in names:
        if name == target or name not in cover_s:
            continue
        q1 = relation_probability(catalog, probs, name, target)
        if q1 <= 0:
            continue
        k = probs.instances(name)
        present = 1.0 if k is None else 1.0 - math.exp(-k)
        q = 1.0 - (1.0 - q1) ** max(1.0, k if k is not None else 1.0)
        find = cover_s[name] / 2
        look = look_s.get(name, 0.0)
        cost = present * (find + look + (1 - q) * direct) + (1 - present) * (cover_s[name] + direct)
        out.append(IndirectOption(name, cost, q, find, look))
    order = {n: i for i, n in enumerate(catalog.type_names)}
    out.sort(key=lambda o: (o.cost, o.via is not None, order.get(o.via, -1) if o.via else -1))
    return out
