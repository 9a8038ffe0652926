"""What an examination's images could show: the views the evidence log keeps for the corrected
interval (``--interval corrected``, knowledge.corrected).

For every relation volume v_rel(A) of the examined object and every catalog type B:

- **expected recall q**: the mean, over the points of a lattice in v_rel(A) (``LATTICE_M``
  apart, at most ``MAX_PER_AXIS`` per axis) that at least one of the examination's images showed
  (``PinholeCamera.visible`` on its depth image), of P(a B centred there is counted): P(at least
  one of the images reports it), each image reporting it with the detector preset's recall at
  the pixels and distance it would have there (``agent.sight.DetectionCurve``, read
  through the function the detector simulation draws with), zero where the image does not show
  the point, and zero where that recall is below ``min_score`` (a true detection scores its
  recall). A point no image showed may be inside solid furniture (no B stands there) or hidden
  behind something; depth cannot tell the two apart, and the gaze planner aims to cover the
  volumes, so only shown points are averaged: q is the recall given that the B stood where the
  examination looked (an overestimate where a volume was partly hidden). With ``confirm`` k > 1
  a related object counts once k images *of the room* detected it; the look-arounds before the
  examination see most objects near furniture, so q takes the confirmation as given (P(at least k
  of the examination's own images) made q 0.26 where it is 0.85, and the corrected interval 70%
  wider and biased up by 0.05-0.24; the bias of Wilson's p0 with ``--confirm 2`` is within 0.01
  of that without, `bench intervals`).
- **false-report rate f**: with ``confirm`` 1, 1 - exp(-lambda), lambda the expected number of
  the preset's clutter false positives of type B inside v_rel(A) over the images: per image, the
  preset's rate per type times the share of the image's surface pixels
  (``envs.detector.false_positive_sites``, where the simulation puts them) whose point, lifted by
  B's half height, lies in the volume grown by B's half size, times P(score >= min_score) (a
  false positive scores uniformly up to the preset's ``max_score``). With ``confirm`` > 1, 0: a
  false positive is drawn anew in every image, under a new id.

Examinations planned to see (``learn --exam-recall R``, ``ViewModel.exam_range``): the gaze
planner's ``max_distance`` (2.5 m by default, where the realistic preset's recall of a pen is
0.01 and of a cup 0.48) becomes the farthest distance at which the catalog's object types are
detected with mean single-image recall R (``EXAM_RANGES`` apart), never below ``EXAM_MIN_RANGE``
(the camera stands 1.2 m above the floor). Where no viewpoint that near sees a volume, the
examination is planned with the default range (agent.acquisition), so no object becomes
unexaminable because of it.

Only the camera perception with the simulated detector has views (the robot knows its detector's
curve: the preset plays the calibration a real robot would make); the oracle perception and a
user's own perception record none, and their examinations count with q = 1, f = 0.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ctxsearch.agent.sight import DetectionCurve, mean_face_area
from ctxsearch.envs.camera import Frame
from ctxsearch.envs.detector import DetectorModel, false_positive_sites
from ctxsearch.knowledge import geometry
from ctxsearch.knowledge.catalog import Catalog

LATTICE_M = 0.1  # m between the lattice points of a volume
MAX_PER_AXIS = 8  # lattice points per axis at most (a large volume is sampled more sparsely)
VISIBLE_TOL = 0.05  # m a point may lie behind the rendered surface and still be shown
GROWN_PAD = 1e-6  # m the prefilter of ``_false_rate`` is wider than the grown volume it bounds
EXAM_MIN_RANGE = 1.0  # m: examinations planned to see never ask for closer viewpoints
EXAM_RANGES = np.round(np.arange(EXAM_MIN_RANGE, 2.5001, 0.05), 2)  # the ranges considered

Views = tuple[tuple[str, np.ndarray, np.ndarray], ...]


def volume_lattice(box: geometry.Box) -> np.ndarray:
    """(M, 3) world points of a lattice filling ``box`` (cell centres)."""
    axes = []
    for h in np.asarray(box.half, float):
        k = int(np.clip(np.ceil(2 * h / LATTICE_M), 1, MAX_PER_AXIS))
        axes.append((np.arange(k) + 0.5) / k * 2 * h - h)
    local = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return box.world_points(local)


class ViewModel:
    """The robot's model of what its images can show, for ``model`` (the detector preset) with
    the run's ``confirm`` and ``min_score`` (module docstring)."""

    def __init__(self, catalog: Catalog, model: DetectorModel, confirm: int, min_score: float):
        self.catalog, self.model = catalog, model
        self.confirm, self.min_score = int(confirm), float(min_score)
        self._curves: dict[tuple[float, int, int], list[DetectionCurve]] = {}
        types = catalog.types
        fp = set(model.fp_types) if not model.perfect else set()
        share = model.fp_per_image / len(model.fp_types) if fp else 0.0
        score_ok = max(0.0, 1.0 - self.min_score / model.fp_max_score) if fp else 0.0
        self._fp_rate = np.array([share * score_ok if t.name in fp else 0.0 for t in types])
        mid = [(np.asarray(t.size_min, float) + np.asarray(t.size_max, float)) / 2 for t in types]
        self._half = np.array(mid) / 2

    def _curves_for(self, frame: Frame) -> list[DetectionCurve]:
        cam = frame.camera
        return self._curves_at(float(cam.focal), int(cam.width), int(cam.height))

    def _curves_at(self, focal: float, width: int, height: int) -> list[DetectionCurve]:
        key = (focal, width, height)
        curves = self._curves.get(key)
        if curves is None:
            curves = [
                DetectionCurve(t, self.model, key[0], key[1], key[2], mean_face_area(t))
                for t in self.catalog.types
            ]
            self._curves[key] = curves
        return curves

    def exam_range(self, recall: float, focal: float, width: int, height: int) -> float:
        """The farthest of ``EXAM_RANGES`` at which the catalog's object types are detected in
        one image with mean recall at least ``recall`` (``EXAM_MIN_RANGE`` if none is)."""
        objects = [i for i, t in enumerate(self.catalog.types) if not t.is_furniture]
        curves = self._curves_at(float(focal), int(width), int(height))
        mean = np.mean([curves[i].p(EXAM_RANGES) for i in objects], axis=0)
        ok = np.flatnonzero(mean >= recall)
        return float(EXAM_RANGES[ok[-1]]) if len(ok) else EXAM_MIN_RANGE

    def views(self, ref: geometry.ObjectInstance, frames: Sequence[Frame | None]) -> Views:
        """(relation, q (T,), f (T,)) for every relation of ``ref``'s type, from the images
        ``frames`` of its examination (those without depth are skipped; none: no views)."""
        frames = [f for f in frames if f is not None and f.depth is not None]
        if not frames:
            return ()
        rels = self.catalog.type(ref.type).relations
        boxes = [geometry.relation_volume(rel, ref) for rel in rels]
        # Where false reports may stand, kept only in the box that bounds every volume's
        # ``_grown`` box (the shares count all).
        surfaces = []
        if self.confirm == 1 and self._fp_rate.any():
            grown = np.array([self._grown(b) for b in boxes])  # (V, 2, 3)
            lo, hi = grown[:, 0].min(axis=0), grown[:, 1].max(axis=0)
            for f in frames:
                points, valid, _ = false_positive_sites(f.instance_ids, f.camera, f.depth)
                at = points[valid]
                xyz = at[_within(at[:, 0], at[:, 1], at[:, 2], lo, hi)]
                surfaces.append((tuple(np.ascontiguousarray(xyz.T)), len(at)))
        return tuple(
            (rel.name, self._recall(box, frames), self._false_rate(box, surfaces))
            for rel, box in zip(rels, boxes, strict=True)
        )

    def _reach(self, box: geometry.Box) -> float:
        """How far from ``box``'s centre a surface point may be and still put a false positive
        of some type in it (half its diagonal, a type's half diagonal and its lift)."""
        halves = self._half[np.flatnonzero(self._fp_rate)] if self._fp_rate.any() else self._half
        lift = float((np.linalg.norm(halves, axis=1) + halves[:, 2]).max())
        return float(np.linalg.norm(np.asarray(box.half, float))) + lift

    def _grown(self, box: geometry.Box) -> np.ndarray:
        """(2, 3) world-axis bounds (low, high) of ``box`` grown by the largest false-positive
        type's half size, and as far down as such a type's lifted point may stand, ``GROWN_PAD``
        wider: every surface point that can put a false positive in it lies within them."""
        big = self._half[np.flatnonzero(self._fp_rate)].max(axis=0)
        center, half = np.asarray(box.center, float), np.asarray(box.half, float)
        c, s = abs(float(np.cos(box.yaw))), abs(float(np.sin(box.yaw)))
        gx, gy = half[0] + big[0], half[1] + big[1]
        ext = np.array([c * gx + s * gy, s * gx + c * gy, 0.0]) + GROWN_PAD
        low = center - ext - np.array([0.0, 0.0, half[2] + 2.0 * big[2]])
        high = center + ext + np.array([0.0, 0.0, half[2]])
        return np.array([low, high])

    def _recall(self, box: geometry.Box, frames: list[Frame]) -> np.ndarray:
        """q (T,) of the volume ``box`` (module docstring)."""
        pts = volume_lattice(box)
        n_t = len(self.catalog.types)
        p = np.zeros((len(frames), n_t, len(pts)))
        shown = np.zeros(len(pts), bool)
        for i, frame in enumerate(frames):
            vis = frame.camera.visible(pts, frame.depth, VISIBLE_TOL)
            if not vis.any():
                continue
            shown |= vis
            d = np.linalg.norm(pts[vis] - np.asarray(frame.camera.position, float), axis=1)
            for b, curve in enumerate(self._curves_for(frame)):
                pb = curve.p(d)
                p[i, b, vis] = np.where(pb >= self.min_score, pb, 0.0)
        if not shown.any():
            return np.zeros(n_t)
        return (1.0 - np.prod(1.0 - p[:, :, shown], axis=0)).mean(axis=1)

    def _false_rate(self, box: geometry.Box, surfaces: list[tuple[tuple, int]]) -> np.ndarray:
        """f (T,) of the volume ``box`` (module docstring) from each image's surface points near
        the volumes (their x, y and z arrays) and its count of all of them. Only the points
        within ``_reach`` of the volume are turned into its frame (the others cannot put a
        false positive in it), and before that only those within its ``_grown`` bounds are read
        (a superset: each point kept gets the exact test)."""
        rate = np.zeros(len(self.catalog.types))
        if self.confirm > 1 or not self._fp_rate.any():
            return rate
        fp = np.flatnonzero(self._fp_rate)
        halves = self._half[fp]  # (k, 3): each false-positive type's half size
        center, half = np.asarray(box.center, float), np.asarray(box.half, float)
        reach = self._reach(box)
        lo, hi = self._grown(box)
        c, s = np.cos(box.yaw), np.sin(box.yaw)
        lam = np.zeros(len(fp))
        for (x, y, z), total in surfaces:
            if not total:
                continue
            keep = _within(x, y, z, lo, hi)
            z = z[keep]
            dx, dy, dz = x[keep] - center[0], y[keep] - center[1], z - center[2]
            # (dx^2 + dy^2) + dz^2: the order numpy's sum over a point's three coordinates takes
            near = np.flatnonzero((dx * dx + dy * dy) + dz * dz <= reach * reach)
            if not len(near):
                continue
            dx, dy = dx[near], dy[near]
            lx, ly = c * dx + s * dy, -s * dx + c * dy
            lz = (z[near][:, None] + halves[:, 2]) - center[2]  # lifted by half a height
            inside = (
                (np.abs(lx)[:, None] <= half[0] + halves[:, 0])
                & (np.abs(ly)[:, None] <= half[1] + halves[:, 1])
                & (np.abs(lz) <= half[2] + halves[:, 2])
            )
            lam += self._fp_rate[fp] * inside.sum(axis=0) / total
        rate[fp] = 1.0 - np.exp(-lam)
        return rate


def _within(x, y, z, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """(N,) bool: which points (coordinate arrays ``x``, ``y``, ``z``) lie within the world-axis
    bounds ``low``..``high``."""
    return (
        (x >= low[0]) & (x <= high[0]) & (y >= low[1]) & (y <= high[1])
        & (z >= low[2]) & (z <= high[2])
    )  # fmt: skip
