"""Perception modes of the learning loop (agent.acquisition): what one image recognizes and which
objects an examined object is related to, and the body whose motions and images are charged.

``camera`` renders segmentation in MuJoCo (envs.world) and runs the detector (envs.detector, a
preset: ``realistic`` by default, ``perfect`` the exact threshold detector; with ``confirm`` k,
an object counts as related only once k images of the room detected it; with ``min_score`` c,
only once a detection of it scored at least c);
``oracle`` reads relations from the true layout and decides what a look-around recognizes
geometrically (type's max_range, inside the frustum, clear line of sight past furniture boxes),
without rendering, on a ``KinematicBody``. Both charge the same ``TimeModel`` seconds for the same
planned drives, head moves and images, so simulated time is comparable.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ctxsearch.agent.interfaces import Perception
from ctxsearch.envs.camera import Frame, camera_axes, half_fov_tangents, in_frustum
from ctxsearch.envs.detector import Detection, DetectorModel, SimDetector, load_detector
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, TimeModel, wrap_angle
from ctxsearch.knowledge import geometry
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.options import PerceptionMode, values

PERCEPTION_MODES = values(PerceptionMode)
DEFAULT_DETECTOR = "realistic"  # camera mode's default preset (assets/detectors)


@dataclass(frozen=True)
class Sensing:
    """Camera mode's detector settings: the preset (None: perfect), the run's seed its stream
    derives from, how many images of a room must detect an object before it counts as related
    (``confirm``) and before it may be the reference of an examination (``confirm_reference``),
    and the confidence one of its detections must reach (envs.detector: ``Detection.score``)."""

    detector: DetectorModel | None = None
    seed: int = 0
    confirm: int = 1
    min_score: float = 0.0
    confirm_reference: int = 1


def perception_label(
    mode: str,
    detector: DetectorModel | None,
    confirm: int = 1,
    min_score: float = 0.0,
    confirm_reference: int = 1,
) -> str:
    """The perception's name in run keys and results: the mode, and in camera mode the detector
    unless it is the perfect one (so runs made before detector models keep their keys), the
    confirmation count if above 1, the minimum confidence if above 0 and the reference's
    confirmation count if above 1."""
    if mode != PerceptionMode.CAMERA or detector is None:
        return mode
    label = mode if detector.perfect else f"{mode}+{detector.name}"
    if confirm > 1:
        label += f"+confirm{confirm}"
    if min_score > 0:
        label += f"+score{min_score:g}"
    return label if confirm_reference <= 1 else f"{label}+ref{confirm_reference}"


# =========================================================================== the oracle's body
class KinematicBody:
    """The robot without physics or rendering: a pose and a clock charged by the TimeModel.

    An agent.interfaces ``Body`` like envs.world.World, so agent.viewplan's ``execute_gaze``
    charges the oracle exactly what it charges the camera mode.
    """

    def __init__(
        self,
        spec: RobotSpec | None = None,
        time_model: TimeModel | None = None,
        width: int = 320,
        height: int = 240,
    ):
        self.spec = spec or RobotSpec()
        self.time_model = time_model or TimeModel()
        self.width, self.height = int(width), int(height)
        self.sim_time = 0.0
        self._pose = RobotPose(0.0, 0.0, 0.0)

    def reset_pose(self, pose: RobotPose) -> None:
        """Put the robot at ``pose`` (no time charged)."""
        pan, tilt = self.spec.clip_head(pose.pan, pose.tilt)
        self._pose = RobotPose(float(pose.x), float(pose.y), float(pose.yaw), pan, tilt)

    def pose(self) -> RobotPose:
        """The current base pose and head angles."""
        return self._pose

    def drive(self, path: np.ndarray, final_yaw: float | None = None) -> float:
        """Follow ``path`` (K, 2) and turn to ``final_yaw``; the seconds it took."""
        p = self._pose
        path = np.asarray(path, float).reshape(-1, 2)
        dt = self.time_model.drive_time(path, p.yaw, final_yaw)
        end = path[-1] if len(path) else p.xy
        yaw = p.yaw if final_yaw is None else wrap_angle(final_yaw)
        self._pose = RobotPose(float(end[0]), float(end[1]), yaw, p.pan, p.tilt)
        self.sim_time += dt
        return dt

    def move_head(self, pan: float, tilt: float) -> float:
        """Slew the head to (pan, tilt), clipped to the limits; the seconds it took."""
        p = self._pose
        pan, tilt = self.spec.clip_head(pan, tilt)
        dt = self.time_model.head_time(p.pan, p.tilt, pan, tilt)
        self._pose = RobotPose(p.x, p.y, p.yaw, pan, tilt)
        self.sim_time += dt
        return dt

    def capture(self, rgb: bool = False, depth: bool = True) -> None:
        """Charge one image; the oracle renders nothing."""
        self.sim_time += self.time_model.image_cost

    def close(self) -> None:
        """Nothing to release."""


# =========================================================================== perception modes
def _in_box_frames(p: np.ndarray, boxes: geometry.BoxArray) -> np.ndarray:
    """(M, K, 3): points p (M, 3) in the frame of every box k (origin at its centre, x along its
    yaw)."""
    c, s = np.cos(boxes.yaws), np.sin(boxes.yaws)  # (K,)
    d = p[:, None, :] - boxes.centers[None, :, :]
    return np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1], d[..., 2]], -1)


def _segment_hits_boxes(a: np.ndarray, b: np.ndarray, boxes: geometry.BoxArray) -> np.ndarray:
    """(M, K) bool: segment a[m] -> b[m] passes through box k (slab test in each box's frame)."""
    pa, pb = _in_box_frames(a, boxes), _in_box_frames(b, boxes)
    v = pb - pa
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-boxes.halves[None] - pa) / v
        t2 = (boxes.halves[None] - pa) / v
    tmin = np.where(
        np.abs(v) < 1e-12,
        np.where(np.abs(pa) <= boxes.halves[None], -np.inf, np.inf),
        np.minimum(t1, t2),
    )
    tmax = np.where(
        np.abs(v) < 1e-12,
        np.where(np.abs(pa) <= boxes.halves[None], np.inf, -np.inf),
        np.maximum(t1, t2),
    )
    enter = np.maximum(tmin.max(-1), 0.0)
    leave = np.minimum(tmax.min(-1), 1.0)
    return enter < leave - 1e-6


class OraclePerception:
    """Relations from the true layout; recognition from geometry. No rendering."""

    name = "oracle"
    reads_truth = True
    last_detections: Sequence[Detection] = ()

    def __init__(
        self,
        layout: RoomLayout,
        catalog: Catalog,
        spec: RobotSpec,
        time_model: TimeModel,
        width: int = 320,
        height: int = 240,
    ):
        self.layout, self.catalog, self.spec = layout, catalog, spec
        self.body = KinematicBody(spec, time_model, width, height)
        self.width, self.height = width, height
        objs = layout.objects
        self._objs = list(objs)
        self._centers = np.array([o.position for o in objs], float).reshape(-1, 3)
        self._half = np.array([o.size for o in objs], float).reshape(-1, 3) / 2
        self._range = np.array([catalog.type(o.type).max_range for o in objs], float)
        # Occluders: furniture-sized boxes (anything with a side over 30 cm).
        self._occ_idx = np.flatnonzero(self._half.max(1) > 0.15) if len(objs) else np.zeros(0, int)
        self._occ = geometry.BoxArray.from_instances([objs[i] for i in self._occ_idx])
        self._tan_x, self._tan_y = half_fov_tangents(spec.fovy_deg, width, height)
        self._radius = np.linalg.norm(self._half, axis=1)
        self._vis_cache: dict[tuple[float, float], np.ndarray] = {}
        if len(objs):
            self._sight = self._sight_points()
            flat = self._sight.reshape(-1, 3)
            self._sight_inside = _points_in_boxes(flat, self._occ).reshape(
                self._sight.shape[0], len(objs), len(self._occ)
            )

    def see(self, frame: Frame | None) -> list[ObjectInstance]:
        """The objects a look from the current pose recognizes: within the type's max_range,
        inside the frustum, and with a clear line of sight (to the centre, the top or a top
        corner) past the furniture boxes that do not contain it."""
        if not self._objs:
            return []
        p = self.body.pose()
        cam = np.array([p.x, p.y, self.spec.camera_height])
        right, up, back = camera_axes(p.yaw + p.pan, p.tilt).T
        fwd = -back
        rel = self._centers - cam
        z, x, y = rel @ fwd, rel @ right, rel @ up
        ok = self._visible_from(p.x, p.y).copy()
        # Any part of the object in view: its bounding sphere touches the frustum.
        ok &= in_frustum(z, x, y, self._tan_x, self._tan_y, near=0.0, radius=self._radius)
        return [self._objs[i] for i in np.flatnonzero(ok)]

    def _visible_from(self, x: float, y: float) -> np.ndarray:
        """(N,) bool: in range and in clear line of sight from the camera above (x, y); it does
        not depend on where the head points, so it is computed once per position."""
        key = (round(x, 6), round(y, 6))
        vis = self._vis_cache.get(key)
        if vis is not None:
            return vis
        cam = np.array([x, y, self.spec.camera_height])
        vis = np.linalg.norm(self._centers - cam, axis=1) <= self._range
        idx = np.flatnonzero(vis)
        if len(idx) and len(self._occ):
            pts = self._sight[:, idx, :]  # (S, M, 3)
            S, M = pts.shape[:2]
            ends = pts.reshape(-1, 3)
            hits = _segment_hits_boxes(np.repeat(cam[None], len(ends), 0), ends, self._occ)
            # A box holding the end point (the object itself, the desk a chair is under) does
            # not hide it.
            blocked = (hits & ~self._sight_inside[:, idx, :].reshape(-1, len(self._occ))).any(1)
            vis[idx] = (~blocked.reshape(S, M)).any(0)
        if len(self._vis_cache) > 256:
            self._vis_cache.clear()
        self._vis_cache[key] = vis
        return vis

    def _sight_points(self) -> np.ndarray:
        """(6, N, 3): points of every object a line of sight may reach: its centre, the centre of
        its top face and (just inside) the four corners of its top face."""
        c, h = self._centers, self._half
        yaw = np.array([o.yaw for o in self._objs])
        cy, sy = np.cos(yaw), np.sin(yaw)
        pts = [c, c + np.column_stack([0 * cy, 0 * cy, h[:, 2]])]
        for sx, sy_ in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
            lx, ly = sx * h[:, 0] * 0.9, sy_ * h[:, 1] * 0.9
            pts.append(c + np.column_stack([cy * lx - sy * ly, sy * lx + cy * ly, h[:, 2]]))
        return np.stack(pts)

    def reference(self, obj: ObjectInstance) -> ObjectInstance | None:
        """Every object the oracle sees is real: ``obj``."""
        return obj

    def related(
        self, obj: ObjectInstance, seen: Sequence[ObjectInstance]
    ) -> list[tuple[str, ObjectInstance]]:
        """RELATED-OBJECTS/-TYPES read from the true layout."""
        return geometry.related(self.catalog, obj, self._objs)

    def close(self) -> None:
        """Nothing to release."""


def _points_in_boxes(pts: np.ndarray, boxes: geometry.BoxArray) -> np.ndarray:
    """(M, K) bool: point m inside box k (boundary included, to 1e-9 m)."""
    return (np.abs(_in_box_frames(pts, boxes)) <= boxes.halves[None] + 1e-9).all(-1)


class CameraPerception:
    """Rendered segmentation in MuJoCo and the detector (envs.detector): the preset ``detector``
    (None: perfect) with its stream seeded by the run's ``seed``, the room and the image; with
    ``confirm`` k > 1, ``related`` counts only objects k images of this room detected, under the
    type most of them reported; with ``min_score`` c > 0, only objects one of whose detections in
    this room scored at least c (a detection confidence threshold on the counting, not on what
    the robot sees: a weak detection still makes an object a candidate to examine); with
    ``confirm_reference`` k > 1, an object may be the reference of an examination (``reference``)
    only once k images of this room detected it, under the type most of them reported: a false
    positive is drawn anew in every image, so it is almost never detected twice (the
    detections of one object are associated by its id, a tracker's perfect data association)."""

    name = "camera"
    reads_truth = False

    def __init__(
        self,
        layout: RoomLayout,
        catalog: Catalog,
        spec: RobotSpec,
        time_model: TimeModel,
        width: int = 320,
        height: int = 240,
        rgb: bool = False,
        sensing: Sensing | None = None,
    ):
        # Imported here: MuJoCo and dm_control slow the start of every run (`python -X importtime`),
        # and oracle runs never use them.
        from ctxsearch.envs.world import World

        self.layout, self.catalog, self.spec, self.rgb = layout, catalog, spec, rgb
        self.body = World(
            layout, catalog, width=width, height=height, spec=spec, time_model=time_model
        )
        sensing = sensing or Sensing()
        model = sensing.detector if sensing.detector is not None else load_detector("perfect")
        self.detector = SimDetector(model, layout, catalog, sensing.seed)
        self.confirm = int(sensing.confirm)
        self.min_score = float(sensing.min_score)
        self.confirm_reference = int(sensing.confirm_reference)
        self._sightings: dict[int, Counter[str]] = {}
        self._best_score: dict[int, float] = {}
        self.last_detections: Sequence[Detection] = ()

    def see(self, frame: Frame | None) -> list[ObjectInstance]:
        """The detector's objects (their estimated poses) in a captured frame."""
        if frame is None:
            raise CtxsearchError("camera perception needs an image (the body rendered none)")
        self.last_detections = self.detector(frame, self.body.sim_time)
        if self.confirm > 1 or self.confirm_reference > 1:
            for d in self.last_detections:
                self._sightings.setdefault(d.instance_id, Counter())[d.type] += 1
        for d in self.last_detections:
            best = self._best_score.get(d.instance_id, 0.0)
            self._best_score[d.instance_id] = max(best, d.score)
        return [d.pose for d in self.last_detections]

    def related(
        self, obj: ObjectInstance, seen: Sequence[ObjectInstance]
    ) -> list[tuple[str, ObjectInstance]]:
        """RELATED-OBJECTS/-TYPES from the detected poses (confirmed ones, with ``confirm``)."""
        if self.confirm > 1:
            seen = [c for c in (self._confirmed(o) for o in seen) if c is not None]
        if self.min_score > 0:
            seen = [o for o in seen if self._best_score.get(o.id, 0.0) >= self.min_score]
        return geometry.related(self.catalog, obj, seen)

    def reference(self, obj: ObjectInstance) -> ObjectInstance | None:
        """``obj`` as the reference of an examination: under its majority type once
        ``confirm_reference`` images of this room detected it, else None (not yet)."""
        if self.confirm_reference <= 1:
            return obj
        return self._confirmed(obj, self.confirm_reference)

    def _confirmed(self, obj: ObjectInstance, k: int | None = None) -> ObjectInstance | None:
        """``obj`` under its majority type if ``k`` (default ``confirm``) images detected it,
        else None."""
        counts = self._sightings.get(obj.id)
        if counts is None or sum(counts.values()) < (self.confirm if k is None else k):
            return None
        best = max(sorted(counts), key=counts.__getitem__)
        return obj if best == obj.type else replace(obj, type=best)

    def close(self) -> None:
        """Release the renderer."""
        self.body.close()


def make_perception(
    mode: str,
    layout: RoomLayout,
    catalog: Catalog,
    spec: RobotSpec,
    time_model: TimeModel,
    rgb: bool = False,
    sensing: Sensing | None = None,
) -> Perception:
    """A perception mode by name ('camera' or 'oracle'); ``sensing`` is the camera mode's
    detector (CameraPerception; the oracle has none)."""
    if mode == PerceptionMode.ORACLE:
        return OraclePerception(layout, catalog, spec, time_model)
    if mode == PerceptionMode.CAMERA:
        return CameraPerception(layout, catalog, spec, time_model, rgb=rgb, sensing=sensing)
    raise CtxsearchError(f"unknown perception mode '{mode}' (known: {', '.join(PERCEPTION_MODES)})")
