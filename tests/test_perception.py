"""The detector: synthetic segmentation frames (pure), and rendered rooms (render-marked)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ctxsearch.envs.detector import (
    Detection,
    box_distance,
    detect,
    detect_ids,
    min_pixels_at,
    ray_scale,
)
from ctxsearch.knowledge.geometry import ObjectInstance

DESK = ObjectInstance("Desk", 3, (2.0, 0.0, 0.37), 0.0, (0.7, 1.4, 0.74))
CUP = ObjectInstance("Cup", 7, (2.0, 0.2, 0.79), 0.0, (0.08, 0.08, 0.10))
OBJECTS = {o.id: o for o in (DESK, CUP)}


def frame_ids(h: int = 240, w: int = 320) -> np.ndarray:
    return np.full((h, w), -1, np.int32)


def test_pixel_threshold(catalog):
    desk_min = catalog.type("Desk").min_pixels
    cup_min = catalog.type("Cup").min_pixels
    ids = frame_ids()
    ids[100:200, 50:250] = DESK.id  # 20000 pixels
    ids[10 : 10 + 4, 10 : 10 + max(1, (cup_min - 1) // 4)] = CUP.id  # fewer than the cup needs
    dets = detect_ids(ids, OBJECTS, catalog, depth=np.full(ids.shape, 2.0, np.float32))
    assert [d.type for d in dets] == ["Desk"]
    d = dets[0]
    assert isinstance(d, Detection)
    assert d.instance_id == DESK.id and d.pose == DESK
    assert d.pixels == 20000 >= desk_min
    assert d.bbox == (50, 100, 249, 199)
    assert d.distance == pytest.approx(2.0)
    # Exactly the threshold is enough.
    ids[10:, :] = -1
    ids[0, :cup_min] = CUP.id
    dets = detect_ids(ids, OBJECTS, catalog, depth=np.full(ids.shape, 1.0, np.float32))
    assert [d.type for d in dets] == ["Cup"] and dets[0].pixels == cup_min


def test_range_limit(catalog):
    cup_range = catalog.type("Cup").max_range
    ids = frame_ids()
    ids[100:140, 100:140] = CUP.id
    depth = np.full(ids.shape, cup_range + 0.5, np.float32)
    assert detect_ids(ids, OBJECTS, catalog, depth=depth) == []
    depth[:] = cup_range - 0.5
    assert len(detect_ids(ids, OBJECTS, catalog, depth=depth)) == 1


def test_unknown_ids_and_background_are_ignored(catalog):
    ids = frame_ids()
    ids[:, :100] = 99  # not an object of interest
    ids[:, 100:] = -1
    assert detect_ids(ids, OBJECTS, catalog, depth=np.ones(ids.shape, np.float32)) == []


def test_distance_is_median_ray_length(catalog):
    ids = frame_ids()
    ids[:, :] = DESK.id
    depth = np.full(ids.shape, 3.0, np.float32)
    dets = detect_ids(ids, OBJECTS, catalog, depth=depth, fovy_deg=58.0)
    scale = ray_scale(320, 240, 58.0)
    assert dets[0].distance == pytest.approx(3.0 * float(np.median(scale)), rel=1e-6)
    assert scale.min() >= 1.0 and scale[120, 160] == pytest.approx(1.0, abs=1e-4)
    # Corner ray: 1 / cos of the angle to the optical axis.
    f = 120 / math.tan(math.radians(29))
    assert scale[0, 0] == pytest.approx(math.sqrt(1 + (159.5 / f) ** 2 + (119.5 / f) ** 2))


def test_distance_without_depth_uses_bounding_box(catalog):
    ids = frame_ids()
    ids[50:150, 50:150] = DESK.id
    cam = np.array([0.0, 0.0, 1.2])
    dets = detect_ids(ids, OBJECTS, catalog, camera_position=cam)
    assert dets[0].distance == pytest.approx(box_distance(cam, DESK))
    assert box_distance(cam, DESK) == pytest.approx(math.hypot(2.0 - 0.35, 1.2 - 0.74))
    with pytest.raises(ValueError):
        detect_ids(ids, OBJECTS, catalog)


def test_threshold_scales_with_resolution(catalog):
    assert min_pixels_at(100, 320, 240) == 100
    assert min_pixels_at(100, 640, 480) == 400
    assert min_pixels_at(100, 160, 120) == 25
    assert min_pixels_at(1, 16, 12) == 1
    # A 640x480 frame: a 300-pixel desk (enough at 320x240) is no longer enough.
    desk_min = catalog.type("Desk").min_pixels
    ids = frame_ids(480, 640)
    ids[0:10, 0 : desk_min // 10 + 1] = DESK.id
    assert detect_ids(ids, OBJECTS, catalog, depth=np.ones(ids.shape, np.float32)) == []


def test_sorted_by_pixels_and_occlusion_is_what_is_rendered(catalog):
    ids = frame_ids()
    ids[100:200, 50:250] = DESK.id
    ids[120:140, 120:140] = CUP.id  # the cup in front hides part of the desk
    dets = detect_ids(ids, OBJECTS, catalog, depth=np.ones(ids.shape, np.float32))
    assert [d.type for d in dets] == ["Desk", "Cup"]
    assert dets[0].pixels == 20000 - 400 and dets[1].pixels == 400


class _Cam:
    position = np.array([0.0, 0.0, 1.2])
    fovy_deg = 58.0
    width, height = 320, 240


class _Frame:
    def __init__(self, ids, depth):
        self.instance_ids, self.depth, self.rgb, self.camera = ids, depth, None, _Cam()


def test_detect_on_a_frame_object(catalog):
    ids = frame_ids()
    ids[100:200, 50:250] = DESK.id
    dets = detect(_Frame(ids, None), [DESK, CUP], catalog)
    assert dets[0].distance == pytest.approx(box_distance(_Cam.position, DESK))


# --------------------------------------------------------------------------- rendered
@pytest.mark.render
def test_desk_seen_across_the_room_pen_is_not(catalog):
    world_mod = pytest.importorskip("ctxsearch.envs.world")
    from ctxsearch.agent.viewplan import aim
    from ctxsearch.envs.layout import Door, RoomLayout
    from ctxsearch.envs.robot_spec import RobotPose

    small = next(t for t in ("Pen", "Remote", "Phone", "Cup") if t in catalog)
    sz = catalog.type(small).size_min
    desk = ObjectInstance("Desk", 1, (2.3, 0.0, 0.37), math.pi, (0.7, 1.4, 0.74))
    pen = ObjectInstance(small, 2, (2.3, 0.2, 0.74 + sz[2] / 2), 0.0, tuple(sz))
    near_pen = ObjectInstance(small, 3, (-1.9, -1.6, sz[2] / 2), 0.0, tuple(sz))
    layout = RoomLayout("test", 0, 6.0, 4.0, 2.6, Door("south", 0.0, 0.9), (desk, pen, near_pen))
    world = world_mod.World(layout, catalog)
    try:
        # From the far end of the room (about 4.5 m) looking at the desk.
        world.reset_pose(RobotPose(-2.2, 0.0, 0.0, 0.0, -0.12))
        frame = world.capture(rgb=False, depth=True)
        visible = set(np.unique(frame.instance_ids)) - {-1}
        assert desk.id in visible
        dets = detect(frame, layout, catalog)
        types = {d.type for d in dets}
        assert "Desk" in types
        assert all(d.instance_id != pen.id for d in dets)
        # The pen is in view but too small there: (almost) no pixels, fewer than its type needs.
        assert int((frame.instance_ids == pen.id).sum()) < catalog.type(small).min_pixels
        desk_det = next(d for d in dets if d.type == "Desk")
        assert 3.0 < desk_det.distance < 5.5
        # The same small object close to the camera is detected.
        pan, tilt = aim(
            np.array([-2.2, -1.0]), 0.0, world.spec.camera_height, np.array(near_pen.position)
        )
        world.reset_pose(RobotPose(-2.2, -1.0, 0.0, pan, tilt))
        frame = world.capture(rgb=False, depth=True)
        near = [d for d in detect(frame, layout, catalog) if d.instance_id == near_pen.id]
        assert near and near[0].distance < catalog.type(small).max_range
    finally:
        world.close()
