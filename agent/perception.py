"""The detector: from a segmentation frame to detections (paper, section 4: recognition and pose
estimation are assumed; what the robot cannot assume is *seeing* an object).

The renderer labels every pixel with the instance id of the object it shows (-1: wall, floor,
robot, nothing). An instance becomes a ``Detection`` when

- at least its type's ``min_pixels`` of it are visible (the catalog's figure is for 320x240;
  other resolutions scale it by their pixel count), and
- it lies within its type's ``max_range`` of the camera,

so a pen across the room (a handful of pixels) goes unseen while a desk does not, and an object
hidden behind another has no pixels at all: occlusion comes from the rendering. The pose is read
from the simulator (the room layout), as the paper assumes a recogniser that also estimates pose.

Distance: the median, over the instance's visible pixels, of the Euclidean camera-to-surface
distance (the depth image holds distance along the optical axis; each pixel's ray length follows
from the intrinsics). Without a depth image it is the distance from the camera to the nearest
point of the object's bounding box.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from envs.camera import Frame, focal_length
from envs.layout import RoomLayout
from knowledge.catalog import Catalog
from knowledge.geometry import ObjectInstance

REFERENCE_PIXELS = 320 * 240  # the resolution the catalog's min_pixels refers to


@dataclass(frozen=True)
class Detection:
    """One detected object: instance id, type, pose (from the simulator), visible pixels, distance
    (m) from the camera, and the pixel bounding box (x0, y0, x1, y1), inclusive."""

    instance_id: int
    type: str
    pose: ObjectInstance
    pixels: int
    distance: float
    bbox: tuple[int, int, int, int]


def min_pixels_at(min_pixels: int, width: int, height: int) -> int:
    """A type's pixel threshold at ``width`` x ``height`` (the catalog's is for 320x240)."""
    return max(1, int(math.ceil(min_pixels * (width * height) / REFERENCE_PIXELS)))


@functools.lru_cache(maxsize=8)
def ray_scale(width: int, height: int, fovy_deg: float) -> np.ndarray:
    """(H, W) factor turning optical-axis depth into ray length for a centred pinhole camera
    (cached; read-only)."""
    f = focal_length(fovy_deg, height)
    u = (np.arange(width) + 0.5 - width / 2) / f
    v = (np.arange(height) + 0.5 - height / 2) / f
    out = np.sqrt(1.0 + u[None, :] ** 2 + v[:, None] ** 2)
    out.flags.writeable = False
    return out


def box_distance(point: np.ndarray, obj: ObjectInstance) -> float:
    """Euclidean distance from ``point`` (3,) to the nearest point of ``obj``'s bounding box."""
    d = np.asarray(point, float) - np.asarray(obj.position, float)
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    local = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]])
    out = np.maximum(np.abs(local) - np.asarray(obj.size, float) / 2, 0.0)
    return float(np.linalg.norm(out))


def detect_ids(
    instance_ids: np.ndarray,
    objects: Mapping[int, ObjectInstance],
    catalog: Catalog,
    *,
    depth: np.ndarray | None = None,
    camera_position: np.ndarray | None = None,
    fovy_deg: float | None = None,
) -> list[Detection]:
    """Detections in one segmentation image (H, W) of instance ids (-1: nothing of interest).

    ``objects`` maps instance ids to their (simulator) poses; ids not in it are ignored. Distance
    is the median ray length of the instance's pixels when ``depth`` (H, W) is given (optical-axis
    depth; with ``fovy_deg`` it is converted to ray length, without it used as is), else the
    distance from ``camera_position`` to the object's bounding box. Sorted by pixel count,
    largest first.
    """
    ids = np.asarray(instance_ids)
    h, w = ids.shape
    flat = ids.ravel()
    depth_flat = None if depth is None else np.asarray(depth).ravel()
    counts = np.bincount((flat.astype(np.int64) + 1).clip(0))
    out: list[Detection] = []
    candidates = np.flatnonzero(counts[1:]) if len(counts) > 1 else np.zeros(0, int)
    scale = None
    for oid in candidates:
        oid = int(oid)
        obj = objects.get(oid)
        if obj is None:
            continue
        typ = catalog.type(obj.type)
        n = int(counts[oid + 1])
        if n < min_pixels_at(typ.min_pixels, w, h):
            continue
        idx = np.flatnonzero(flat == oid)
        if depth is not None:
            d = depth_flat[idx]
            if fovy_deg is not None:
                if scale is None:
                    scale = ray_scale(w, h, float(fovy_deg)).ravel()
                d = d * scale[idx]
            dist = float(np.median(d))
        elif camera_position is not None:
            dist = box_distance(camera_position, obj)
        else:
            raise ValueError("detect_ids needs depth or camera_position to measure distance")
        if dist > typ.max_range:
            continue
        rows, cols = np.divmod(idx, w)
        bbox = (int(cols.min()), int(rows[0]), int(cols.max()), int(rows[-1]))
        out.append(Detection(oid, obj.type, obj, n, dist, bbox))
    out.sort(key=lambda d: (-d.pixels, d.instance_id))
    return out


def objects_by_id(
    layout_or_objects: RoomLayout | Iterable[ObjectInstance] | Mapping[int, ObjectInstance],
) -> dict[int, ObjectInstance]:
    """An id -> instance map from a layout, a sequence of instances or such a map."""
    if isinstance(layout_or_objects, RoomLayout):
        return {o.id: o for o in layout_or_objects.objects}
    if isinstance(layout_or_objects, Mapping):
        return dict(layout_or_objects)
    return {o.id: o for o in layout_or_objects}


def detect(
    frame: Frame,
    layout_or_objects: RoomLayout | Iterable[ObjectInstance] | Mapping[int, ObjectInstance],
    catalog: Catalog,
) -> list[Detection]:
    """Detections in a rendered ``Frame`` (its ``instance_ids``, ``depth`` if present, and the
    camera it came from); see the module docstring for the rules."""
    cam = frame.camera
    return detect_ids(
        frame.instance_ids,
        objects_by_id(layout_or_objects),
        catalog,
        depth=frame.depth,
        camera_position=np.asarray(cam.position, float),
        fovy_deg=float(cam.fovy_deg),
    )
