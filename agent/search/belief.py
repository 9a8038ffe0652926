"""Where the target is, as search theory has it (Koopman; Stone, *Theory of Optimal Search*): a
look is evidence weighted by the probability of detection, never a finished area.

Detection curve. The robot's model of its own detector for the target type
(``DetectionCurve``, agent.sight, shared with the learning loop's examination views):
one image reports an instance whose centre is in view and not hidden, at distance d, with the
detector preset's recall (``envs.detector.DetectorModel.recall_prob``, the one function the
detector simulation also draws with) at the pixels it would cover there, f^2 A / d^2 (f: the
focal length in pixels, A: the type's mean face area, an orientation average:
``agent.sight.mean_face_area``). A real robot calibrates its own curve; the preset file plays
that role.
A search ends on a *confirmed* detection (a second image from the same pose sees it again,
``context.CONFIRM_RADIUS_M``; the detector draws anew), so a view finds the target at a point with
``found(d) = p(d)^2``.

The miss field (``MissField``). For every point of the seen map's lattice, the probability that a
target standing there would have gone unreported by every image so far: each image multiplies the
points the depth image shows (inside the frustum, not hidden: ``space.SeenMap.update``) by
1 - p(d). A point seen from far keeps most of its mass; no point is ever done. Where a detection
was not confirmed, the points within ``CONFIRM_RADIUS_M`` of it keep the mass they had before the
two images times the likelihood ratio of what was observed there, reported once and not
confirmed: p (1 - p) for a target there against the preset's per-image rate of false reports of
the type (``DetectionCurve.unconfirmed_ratio``), so the robot goes back for a closer look.

The belief over the target's position is the policy's prior (its stated density: the relation
volumes of the known objects with P(rel(T)) from its knowledge source, the rest at the surveyed
part's mean, ``space.target_density``; uniform for the no-context twins) times the miss field,
normalised over the points still worth a look (``belief_weights``). An option's value is the
belief mass it would find, sum_x b(x) found(d(x, view)), per expected second (agent.search.online).

Stopping. A policy stops before its budget only when the *detectable mass left*
(``mass_left``: the prior's share over the points not given up on that the miss field still
holds) is below the configuration's ``belief.stop_mass`` (agent.search.config); the share at a stop is reported with the result
(``SearchResult.mass_left``).
"""

from __future__ import annotations

import numpy as np

from ctxsearch.agent.recording import Recorder

# The detection curve and its constants live in agent.sight (below learning and search);
# re-exported here for the search's callers.
from ctxsearch.agent.sight import (  # noqa: F401
    MAX_REACH_M,
    MIN_FALSE_RATE,
    P_REACH,
    DetectionCurve,
    detection_curve,
)

# A point whose miss probability fell below this is no longer worth a look of its own (it keeps
# its mass in the belief; options stop counting it towards their minimum number of points).
MISS_DONE = 0.05
BELIEF_CELL_M = 0.2  # the recording's floor heat map: cells of this size


class MissField:
    """Per seen-map point (``points`` (N, 3)), the probability that a target there went unreported
    by every image so far (module docstring)."""

    def __init__(self, points: np.ndarray, curve: DetectionCurve):
        self.points, self.curve = points, curve
        self.miss = np.ones(len(points))

    def observe(self, position: np.ndarray, shown: np.ndarray) -> None:
        """An image from camera ``position`` that reported no target showed the points ``shown``
        ((N,) bool or indices): each keeps 1 - p(d) of its mass."""
        idx = np.flatnonzero(shown) if np.asarray(shown).dtype == bool else np.asarray(shown)
        if len(idx) == 0:
            return
        d = np.linalg.norm(self.points[idx] - np.asarray(position, float), axis=1)
        self.miss[idx] *= 1.0 - self.curve.p(d)

    def near(self, xy: np.ndarray, radius: float) -> np.ndarray:
        """Indices of the points within ``radius`` m of ``xy`` on the floor plane."""
        d = np.hypot(*(self.points[:, :2] - np.asarray(xy, float)[:2]).T)
        return np.flatnonzero(d <= radius)


def belief_weights(prior: np.ndarray, miss: np.ndarray, todo: np.ndarray) -> np.ndarray | None:
    """(N,) the probability that the target is at each point, given every image so far: ``prior``
    times ``miss`` over the points ``todo`` (bool), normalised; None if nothing is left."""
    w = np.where(todo, prior * miss, 0.0)
    total = float(w.sum())
    return w / total if total > 0 else None


def mass_left(prior: np.ndarray, miss: np.ndarray, keep: np.ndarray) -> float:
    """The detectable mass left: the share of ``prior`` over the points ``keep`` (not given up
    on) that ``miss`` still holds (1 before the first image)."""
    total = float(prior[keep].sum())
    held = np.minimum(miss[keep], 1.0)  # a boosted point counts as never seen
    return float((prior[keep] * held).sum()) / total if total > 0 else 0.0


def gazes_found(curve: DetectionCurve, cameras: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) P(a confirmed detection of a target at ``points`` (N, 3)) from images at camera
    positions ``cameras`` (K, 3) aimed at them (the view planner's gazes into a volume): one
    minus the product of the misses."""
    if len(cameras) == 0 or len(points) == 0:
        return np.zeros(len(points))
    d = np.linalg.norm(points[:, None, :] - cameras[None, :, :], axis=-1)
    return 1.0 - np.prod(1.0 - curve.found(d), axis=1)


def log_belief(rec: Recorder, points: np.ndarray, weights: np.ndarray | None, entity: str) -> None:
    """The belief as a floor heat map at ``entity``: one point per ``BELIEF_CELL_M`` cell holding
    mass, its colour and radius by the cell's share of the largest cell's mass (dark blue: little,
    yellow: the most)."""
    if not rec.enabled:
        return
    if weights is None or not np.any(weights > 0):
        rec.log_points(entity, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
        return
    cells = np.floor(points[:, :2] / BELIEF_CELL_M).astype(np.int64)
    keys, inv = np.unique(cells, axis=0, return_inverse=True)
    mass = np.bincount(inv.ravel(), weights=weights, minlength=len(keys))
    keep = mass > mass.max() * 1e-3
    share = mass[keep] / mass.max()
    xy = (keys[keep] + 0.5) * BELIEF_CELL_M
    pos = np.column_stack([xy, np.full(len(xy), 0.02)])
    t = np.sqrt(share)[:, None]
    colors = (1 - t) * np.array([0.15, 0.1, 0.5]) + t * np.array([1.0, 0.9, 0.1])
    rec.log_points(entity, pos, colors, 0.03 + 0.07 * np.sqrt(share))
