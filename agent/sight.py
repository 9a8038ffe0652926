"""The robot's model of its own detector, and the viewing constants that learning and search share.

What the robot believes its detector sees of a type at a distance: one image reports an instance
whose centre is in view and not hidden, at distance d, with the detector preset's recall
(``envs.detector.DetectorModel.recall_prob``, the one function the detector simulation also draws
with) at the pixels it would cover there, f^2 A / d^2 (f: the focal length in pixels,
``focal_px``; A: the type's mean face area, an orientation average, ``mean_face_area``). A real
robot calibrates its own curve; the preset file plays that role. A confirmed detection (a second
image from the same pose sees it again; the detector draws anew) finds the target with
``found(d) = p(d)^2`` (``DetectionCurve``).

The examination views of the learning loop (agent.exam_views) and the belief of the search
(agent.search.belief) both read the curve from here, and the floor-near look-around tilt
(``NEAR_TILT``) is shared by the learning loop's frontier exploration (agent.frontiers) and the
search's (agent.search.frontier), so neither side imports the other.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ctxsearch.envs.camera import focal_length
from ctxsearch.envs.detector import DetectorModel, load_detector
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.knowledge.catalog import ObjectType

# A view is counted for the points where one confirmed detection has at least this probability:
# beyond, an image changes the belief by less than 2% of a point's mass per image.
P_REACH = 0.02
MAX_REACH_M = 5.0  # the built map's depth range: nothing further is counted as seen
# The least per-image rate of false reports of a type the belief assumes (a preset without
# false positives or confusions would otherwise make one unconfirmed report certain).
MIN_FALSE_RATE = 1e-3
NEAR_TILT = -1.0  # rad: the second look-around tilt (the floor near the robot)


def focal_px(spec: RobotSpec, height: int = 240) -> float:
    """The head camera's focal length in pixels for images ``height`` pixels high."""
    return focal_length(spec.fovy_deg, height)


def mean_face_area(typ: ObjectType) -> float:
    """The mean of the three face areas of a type's mid-range size (m^2): an orientation average
    of the area it shows the camera."""
    s = (np.asarray(typ.size_min, float) + np.asarray(typ.size_max, float)) / 2
    return float((s[0] * s[1] + s[0] * s[2] + s[1] * s[2]) / 3)


@dataclass(frozen=True)
class DetectionCurve:
    """P(one image reports an instance of ``typ``) against distance, from ``model``'s recall at
    the pixels it would cover (module docstring), for a camera of focal length ``focal`` px
    taking ``width`` x ``height`` images."""

    typ: ObjectType
    model: DetectorModel
    focal: float
    width: int
    height: int
    area: float  # m^2: the type's mean face area
    reach: float = field(init=False)  # m: the farthest a confirmed detection has P_REACH

    def __post_init__(self) -> None:
        d = np.linspace(0.05, MAX_REACH_M, 500)
        ok = np.flatnonzero(self.found(d) >= P_REACH)
        object.__setattr__(self, "reach", float(d[ok[-1]]) if len(ok) else 0.05)

    def p(self, distance: np.ndarray | float) -> np.ndarray:
        """P(reported by one image) at ``distance`` m (array)."""
        d = np.maximum(np.asarray(distance, float), 0.05)
        pixels = self.focal**2 * self.area / (d * d)
        return np.asarray(
            self.model.recall_prob(self.typ, pixels, d, self.width, self.height), float
        )

    def found(self, distance: np.ndarray | float) -> np.ndarray:
        """P(a confirmed detection from one pose): reported by both images, drawn anew."""
        return self.p(distance) ** 2

    def false_report_rate(self) -> float:
        """P(one image reports the type where none is): the preset's clutter false positives of
        the type (``fp_per_image`` shared among ``fp_types``) plus the look-alike types it
        confuses with it, at their best recall; at least ``MIN_FALSE_RATE``."""
        m, name = self.model, self.typ.name
        rate = m.fp_per_image / len(m.fp_types) if name in m.fp_types else 0.0
        best = m.recall.max_recall if m.recall is not None else 1.0
        rate += sum(p * best for a, b, p in m.confusion if name in (a, b))
        return max(rate, MIN_FALSE_RATE)

    def unconfirmed_ratio(self, distance: float, radius: float) -> float:
        """The likelihood ratio of "reported once within ``radius`` m of a place at ``distance``
        m, not confirmed by the second image" for a target there against none there: p (1 - p)
        over the false reports that land that near, ``false_report_rate`` times the disc's
        share of the image's footprint at that distance (false reports stand on surface points
        the image shows)."""
        p = float(self.p(distance))
        d = max(float(distance), 0.3)
        footprint = (d * self.width / self.focal) * (d * self.height / self.focal)
        share = min(1.0, np.pi * radius * radius / footprint)
        return p * (1.0 - p) / (self.false_report_rate() * share)


def detection_curve(
    typ: ObjectType, model: DetectorModel | None, spec: RobotSpec, width: int, height: int
) -> DetectionCurve:
    """The curve of ``typ`` for ``model`` (None: the perfect preset) on ``spec``'s camera."""
    model = model or load_detector("perfect")
    return DetectionCurve(
        typ, model, focal_px(spec, height), int(width), int(height), mean_face_area(typ)
    )
