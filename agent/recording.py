"""Rerun recordings of what the robot does: the room, relation volumes, the robot and its camera.

``Recorder(path, name=..., blueprint=...)`` writes a ``.rrd`` file (open it with
``rerun FILE.rrd``) holding one named recording and the blueprint the viewer lays it out by
(agent.rr_layout); ``Recorder(None)`` records nothing and every method returns at once, so
callers log unconditionally. ``Recorder(stream=..., root="a")`` logs into an open stream
(``open_stream``) under the entity ``a/``: several searches side by side in one recording.

Entity tree (under ``root``; world frame: x east, y north, z up, metres)::

    world/room/floor, world/room/walls          static boxes
    world/objects/<Type>_<id>                   static: labelled bounding box (wireframe)
    world/objects/<Type>_<id>/parts             static: the solid parts, filled, type colour
    world/volumes/...                           relation volumes (wireframes), log_volumes
    world/robot                                 base pose (Transform3D), with base/mast/head
    world/robot_path                            the path driven so far (line strip)
    world/camera                                camera pose (Transform3D, RDF)
    world/camera/image                          Pinhole; rgb (JPEG), segmentation, detections
    world/camera/depth                          Pinhole at half resolution; image (depth, mm)
    log                                         text messages
    <any path>                                  scalars (log_scalar)

Everything is logged on the one ``sim_time`` timeline (simulated seconds; set it with
``set_time``; it starts at 0): rerun's automatic ``log_time`` is switched off, so every entity
and log line is where the viewer's time cursor expects it. A room is static, or, for a run over
several rooms in one recording (``log_room(static=False)``), logged at the second the robot
enters it, replacing the last room.

Cameras: MuJoCo's look along their -z with +y up; rerun's pinhole is RDF (x right, y down, z
forward), so the camera's world rotation is ``xmat @ diag(1, -1, -1)``. Segmentation images hold
instance id + 1 (0: nothing), with an annotation context naming every instance by its type.

rerun is imported inside the methods that log: importing it is slow (``python -X importtime -c
"import rerun"`` shows how slow), and ``Recorder(None)`` (every run without a recording) never
needs it.
"""

from __future__ import annotations

import math
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ctxsearch.envs.camera import Frame, PinholeCamera, intrinsics
from ctxsearch.envs.floorplan import wall_boxes as house_wall_boxes
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.parts import world_parts
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.geometry import Box, ObjectInstance

WALL_THICKNESS = 0.1  # m, drawn outside the room's boundary
RDF_FROM_MUJOCO = np.diag([1.0, -1.0, -1.0])
JPEG_QUALITY = 85  # camera images are stored as JPEG (a tenth of the raw size)
DEPTH_STRIDE = 2  # depth images are stored at half resolution, in millimetres


def rgb255(color: Sequence[float]) -> list[int]:
    """An RGB colour in [0, 1] as 0-255 integers."""
    return [int(round(255 * float(np.clip(c, 0.0, 1.0)))) for c in color[:3]]


@dataclass(frozen=True)
class Shot:
    """What ``Recorder.log_camera`` shows of an image: the camera and whichever pixels there are
    (a ``Frame`` is one; the oracle's gazes have a camera and no pixels)."""

    camera: PinholeCamera
    rgb: np.ndarray | None = None
    depth: np.ndarray | None = None
    instance_ids: np.ndarray | None = None


def wall_boxes(layout: RoomLayout, thickness: float = WALL_THICKNESS) -> list[Box]:
    """The room's walls as boxes standing just outside its boundary, the door left open (a
    house: its outer and interior walls, the door openings left open)."""
    if layout.is_house:
        return [
            Box(np.array(c, float), 0.0, np.array(hf, float))
            for name, c, hf in house_wall_boxes(layout, thickness)
            if not name.endswith("lintel")
        ]
    w, d, h = layout.width, layout.depth, layout.height
    t = thickness
    # (wall, centre of the wall line, direction along the wall, length)
    walls = {
        "north": (np.array([0.0, d / 2 + t / 2]), 0, w + 2 * t),
        "south": (np.array([0.0, -d / 2 - t / 2]), 0, w + 2 * t),
        "east": (np.array([w / 2 + t / 2, 0.0]), 1, d),
        "west": (np.array([-w / 2 - t / 2, 0.0]), 1, d),
    }
    out: list[Box] = []
    for name, (c, axis, length) in walls.items():
        spans = [(-length / 2, length / 2)]
        if layout.door is not None and layout.door.wall == name:
            a, b = (
                layout.door.center - layout.door.width / 2,
                layout.door.center + layout.door.width / 2,
            )
            spans = [(-length / 2, a), (b, length / 2)]
        for lo, hi in spans:
            if hi - lo <= 1e-6:
                continue
            center = c.copy()
            center[axis] = (lo + hi) / 2
            half = [t / 2, t / 2, h / 2]
            half[axis] = (hi - lo) / 2
            out.append(Box(np.array([center[0], center[1], h / 2]), 0.0, np.array(half)))
    return out


def _boxes3d(boxes: Sequence[Box], **kwargs: Any) -> Any:
    import rerun as rr

    return rr.Boxes3D(
        centers=[b.center for b in boxes],
        half_sizes=[b.half for b in boxes],
        rotation_axis_angles=[
            rr.RotationAxisAngle(axis=[0, 0, 1], radians=float(b.yaw)) for b in boxes
        ],
        **kwargs,
    )


def open_stream(
    path: str | Path, app_id: str, name: str | None = None, blueprint: Any = None
) -> Any:
    """A rerun RecordingStream saving to ``path``: a fresh recording id, the recording named
    ``name``, ``blueprint`` (a ``rerun.blueprint.Blueprint``) stored as the active and default
    layout of ``app_id``, no ``log_time``, the time at sim_time 0."""
    import rerun as rr

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream(app_id, recording_id=uuid.uuid4())
    rec.save(path)
    if blueprint is not None:  # active, not only default: the viewer may remember another layout
        rec.send_blueprint(blueprint, make_active=True, make_default=True)
    rr.set_log_time_enabled(False, recording=rec)
    if name:
        rec.send_recording_name(name)
    rec.set_time("sim_time", duration=0.0)
    return rec


class Recorder:
    """Logs the robot's world to rerun: a ``.rrd`` file of its own (``path``), or entities under
    ``root`` of an open stream; a no-op when neither is given."""

    def __init__(
        self,
        path: str | Path | None = None,
        app_id: str = "ctxsearch",
        *,
        name: str | None = None,
        blueprint: Any = None,
        stream: Any = None,
        root: str = "",
    ) -> None:
        self.path = Path(path) if path is not None else None
        self.root = root.strip("/")
        self._rec: Any = None
        self._owns = False
        self._path_xy: list[list[float]] = []
        self._robot_logged = False
        if self.path is not None:
            self._rec, self._owns = open_stream(self.path, app_id, name, blueprint), True
        elif stream is not None:
            self._rec = stream
            self._rec.set_time("sim_time", duration=0.0)
        else:
            return
        import rerun as rr

        self._rec.log(self.entity("world"), rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    @property
    def enabled(self) -> bool:
        """True if this recorder writes a file."""
        return self._rec is not None

    def entity(self, path: str) -> str:
        """The entity path ``path`` under this recorder's root."""
        return f"{self.root}/{path}" if self.root else path

    # ----------------------------------------------------------------- time
    def set_time(self, sim_time: float) -> None:
        """Set the ``sim_time`` timeline (simulated seconds) for what is logged next."""
        if self._rec is None:
            return
        self._rec.set_time("sim_time", duration=float(sim_time))

    # ----------------------------------------------------------------- the room
    def log_room(self, layout: RoomLayout, catalog: Catalog, static: bool = True) -> None:
        """Floor, walls (wireframes: the inside stays visible), every object's parts (filled) and
        bounding box (labelled on screen for furniture, by hover for small objects). Static, or
        (``static=False``) at the current time, clearing the previous room, its volumes, plans
        and path."""
        if self._rec is None:
            return
        import rerun as rr

        rec, e = self._rec, self.entity
        if not static:
            for ent in ("world/room", "world/objects", "world/volumes", "world/search"):
                rec.log(e(ent), rr.Clear(recursive=True))
            for ent in ("world/robot_path", "world/plan"):
                rec.log(e(ent), rr.Clear(recursive=False))
            self._path_xy = []
        w, d = layout.width, layout.depth
        rec.log(
            e("world/room/floor"),
            rr.Boxes3D(
                centers=[[0, 0, -0.005]],
                half_sizes=[[w / 2, d / 2, 0.005]],
                colors=[[200, 200, 195]],
                fill_mode=rr.components.FillMode.Solid,
            ),
            static=static,
        )
        rec.log(
            e("world/room/walls"),
            _boxes3d(
                wall_boxes(layout),
                colors=[[150, 150, 145]],
                fill_mode=rr.components.FillMode.MajorWireframe,
            ),
            static=static,
        )
        infos = [self._log_object(o, catalog, static) for o in layout.objects]
        infos.append(rr.AnnotationInfo(id=0, label="background", color=[0, 0, 0]))
        rec.log(e("world"), rr.AnnotationContext(infos), static=static)

    def _log_object(self, o: ObjectInstance, catalog: Catalog, static: bool):
        """One object's bounding box and solid parts; its annotation (id, label, colour)."""
        import rerun as rr

        typ = catalog.type(o.type)
        color = rgb255(typ.color)
        entity = self.entity(f"world/objects/{o.type}_{o.id}")
        fill = rr.components.FillMode
        box = _boxes3d([o.box()], labels=[o.type], colors=[color], show_labels=typ.is_furniture,
                       fill_mode=fill.MajorWireframe)  # fmt: skip
        self._rec.log(entity, box, static=static)
        parts = world_parts(o, catalog)
        if parts:
            solid = _boxes3d(parts, colors=[color] * len(parts), fill_mode=fill.Solid)
            self._rec.log(f"{entity}/parts", solid, static=static)
        return rr.AnnotationInfo(id=o.id + 1, label=f"{o.type} #{o.id}", color=color)

    def log_volumes(
        self,
        entity: str,
        boxes: Sequence[Box],
        labels: Sequence[str] | None = None,
        color: Sequence[float] | None = None,
        static: bool = False,
        show_labels: bool = True,
        colors: Sequence[Sequence[float]] | None = None,
    ) -> None:
        """Boxes (relation volumes, search regions) as labelled wireframes at ``entity`` (with
        ``show_labels=False`` the labels show on hover only); ``colors``: one per box (RGB in
        [0, 1]), else ``color`` for all."""
        if self._rec is None:
            return
        import rerun as rr

        kwargs: dict[str, Any] = {"fill_mode": rr.components.FillMode.MajorWireframe}
        if labels is not None:
            kwargs["labels"] = list(labels)
            kwargs["show_labels"] = show_labels
        if colors is not None:
            kwargs["colors"] = [rgb255(c) for c in colors]
        elif color is not None:
            kwargs["colors"] = [rgb255(color)] * len(boxes)
        if not boxes:
            self._rec.log(self.entity(entity), rr.Clear(recursive=False), static=static)
            return
        self._rec.log(self.entity(entity), _boxes3d(list(boxes), **kwargs), static=static)

    # ----------------------------------------------------------------- the robot
    def log_robot(
        self, pose: RobotPose, spec: RobotSpec | None = None, path: np.ndarray | None = None
    ) -> None:
        """The robot's base pose and the path driven so far (``path`` (K, 2): the way it came
        since the last call, if known; else a straight line from the last pose)."""
        if self._rec is None:
            return
        import rerun as rr

        spec = spec or RobotSpec()
        rec, e = self._rec, self.entity
        if not self._robot_logged:
            r, hb, hc = spec.base_radius, spec.base_height, spec.camera_height
            rec.log(
                e("world/robot/body"),
                rr.Cylinders3D(
                    lengths=[hb, hc - hb],
                    radii=[r, spec.mast_radius],
                    centers=[[0, 0, hb / 2], [0, 0, (hb + hc) / 2]],
                    colors=[[46, 46, 51], [217, 217, 224]],
                    fill_mode=rr.components.FillMode.Solid,
                ),
                static=True,
            )
            rec.log(
                e("world/robot/nose"),
                rr.Arrows3D(
                    origins=[[0, 0, hb + 0.01]], vectors=[[r * 1.2, 0, 0]], colors=[[230, 128, 25]]
                ),
                static=True,
            )
            self._robot_logged = True
        rec.log(
            e("world/robot"),
            rr.Transform3D(
                translation=[pose.x, pose.y, 0.0],
                rotation_axis_angle=rr.RotationAxisAngle(axis=[0, 0, 1], radians=float(pose.yaw)),
            ),
        )
        for x, y in np.asarray(path if path is not None else [], float).reshape(-1, 2):
            if (
                not self._path_xy
                or math.hypot(x - self._path_xy[-1][0], y - self._path_xy[-1][1]) > 1e-3
            ):
                self._path_xy.append([float(x), float(y)])
        xy = [float(pose.x), float(pose.y)]
        if (
            not self._path_xy
            or np.hypot(xy[0] - self._path_xy[-1][0], xy[1] - self._path_xy[-1][1]) > 1e-3
        ):
            self._path_xy.append(xy)
        if len(self._path_xy) >= 2:
            rec.log(
                e("world/robot_path"),
                rr.LineStrips3D(
                    [[[x, y, 0.02] for x, y in self._path_xy]],
                    colors=[[230, 128, 25]],
                    radii=[0.015],
                ),
            )

    def log_path(self, path: np.ndarray, entity: str = "world/plan") -> None:
        """A planned path (K, 2) as a line strip on the floor."""
        if self._rec is None:
            return
        import rerun as rr

        pts = [[float(x), float(y), 0.03] for x, y in np.asarray(path, float).reshape(-1, 2)]
        self._rec.log(
            self.entity(entity), rr.LineStrips3D([pts], colors=[[40, 120, 230]], radii=[0.01])
        )

    # ----------------------------------------------------------------- the camera
    def log_camera(self, frame: Frame | Shot, detections: Sequence[Any] = ()) -> None:
        """The camera's pose and pinhole, the frame's images and the detections as 2-D boxes."""
        if self._rec is None:
            return
        import rerun as rr

        rec, e = self._rec, self.entity
        cam = frame.camera
        width, height = int(cam.width), int(cam.height)
        rot = np.asarray(cam.xmat, float).reshape(3, 3) @ RDF_FROM_MUJOCO
        rec.log(
            e("world/camera"),
            rr.Transform3D(translation=np.asarray(cam.position, float), mat3x3=rot),
        )
        rec.log(
            e("world/camera/image"),
            rr.Pinhole(
                image_from_camera=intrinsics(float(cam.fovy_deg), width, height),
                resolution=[width, height],
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=0.4,
            ),
        )
        if frame.rgb is not None:
            rgb = rr.Image(np.ascontiguousarray(frame.rgb))
            rec.log(e("world/camera/image/rgb"), rgb.compress(jpeg_quality=JPEG_QUALITY))
        if frame.instance_ids is not None:
            seg = (
                (np.asarray(frame.instance_ids).astype(np.int64) + 1)
                .clip(0, 65535)
                .astype(np.uint16)
            )
            rec.log(e("world/camera/image/segmentation"), rr.SegmentationImage(seg, opacity=0.35))
        if frame.depth is not None:
            self._log_depth(cam, np.asarray(frame.depth, np.float32))
        if detections:
            mins = [[d.bbox[0], d.bbox[1]] for d in detections]
            sizes = [[d.bbox[2] - d.bbox[0] + 1, d.bbox[3] - d.bbox[1] + 1] for d in detections]
            labels = [d.type for d in detections]  # id, pixels and distance: in the log
            rec.log(
                e("world/camera/image/detections"),
                rr.Boxes2D(
                    mins=mins,
                    sizes=sizes,
                    labels=labels,
                    # A false detection (negative id) gets class 0, the segmentation's nothing.
                    class_ids=[max(0, d.instance_id + 1) for d in detections],
                ),
            )
        else:
            rec.log(e("world/camera/image/detections"), rr.Clear(recursive=False))

    def _log_depth(self, cam: PinholeCamera, depth: np.ndarray) -> None:
        """The depth image, every ``DEPTH_STRIDE``-th pixel in millimetres, under a pinhole of
        its own (``world/camera/depth``: its own view, not drawn over the RGB image)."""
        import rerun as rr

        k = DEPTH_STRIDE
        d = depth[::k, ::k]
        h, w = d.shape
        mm = np.clip(np.nan_to_num(d * 1000.0, nan=0.0, posinf=0.0), 0, 65535).astype(np.uint16)
        self._rec.log(
            self.entity("world/camera/depth"),
            rr.Pinhole(
                image_from_camera=intrinsics(float(cam.fovy_deg), w, h),
                resolution=[w, h],
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=0.2,
            ),
        )
        self._rec.log(self.entity("world/camera/depth/image"), rr.DepthImage(mm, meter=1000.0))

    # ----------------------------------------------------------------- text and numbers
    def log_text(self, msg: str, level: str = "INFO") -> None:
        """A line in the recording's text log."""
        if self._rec is None:
            return
        import rerun as rr

        self._rec.log(self.entity("log"), rr.TextLog(msg, level=level))

    def log_points(
        self,
        entity: str,
        positions: np.ndarray,
        colors: np.ndarray,
        radii: np.ndarray,
        labels: Sequence[str] | None = None,
    ) -> None:
        """3-D points at ``entity`` (colours as 0-1 RGB, radii in metres, an optional label
        each); none clears it."""
        if self._rec is None:
            return
        import rerun as rr

        if len(positions) == 0:
            self._rec.log(self.entity(entity), rr.Clear(recursive=False))
            return
        cols = [rgb255(c) for c in np.asarray(colors, float)]
        self._rec.log(
            self.entity(entity),
            rr.Points3D(
                np.asarray(positions, float), colors=cols, radii=np.asarray(radii, float),
                labels=None if labels is None else list(labels),
            ),
        )  # fmt: skip

    def log_scalar(self, path: str, value: float) -> None:
        """One value of a time series at entity ``path``."""
        if self._rec is None:
            return
        import rerun as rr

        self._rec.log(self.entity(path), rr.Scalars(float(value)))

    # ----------------------------------------------------------------- lifetime
    def flush(self) -> None:
        """Write everything logged so far to the file."""
        if self._rec is not None:
            self._rec.flush()

    def close(self) -> None:
        """Flush and close the file (a stream it was given stays open); later calls are no-ops."""
        if self._rec is None:
            return
        self._rec.flush()
        if self._owns:
            self._rec.disconnect()
        self._rec = None

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
