"""The rerun recorder: a no-op without a path; with one, a .rrd that rerun reads back."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from agent.recording import Recorder, wall_boxes
from envs.camera import camera_at
from envs.detector import detect_ids
from envs.layout import Door, RoomLayout
from envs.robot_spec import RobotPose
from knowledge.geometry import ObjectInstance, relation_volume

OBJECTS = (
    ObjectInstance("Desk", 1, (0.0, 0.0, 0.37), 0.3, (0.7, 1.4, 0.74)),
    ObjectInstance("Cup", 2, (0.0, 0.1, 0.79), 0.0, (0.08, 0.08, 0.10)),
)
LAYOUT = RoomLayout("test", 0, 6.0, 5.0, 2.6, Door("south", 0.5, 0.9), OBJECTS)


def _frame(pose: RobotPose) -> SimpleNamespace:
    ids = np.full((240, 320), -1, np.int32)
    ids[100:200, 50:250] = 1
    return SimpleNamespace(
        rgb=np.zeros((240, 320, 3), np.uint8),
        depth=np.full((240, 320), 2.0, np.float32),
        instance_ids=ids,
        camera=camera_at(pose),
        pose=pose,
    )


def _chunks(path):
    import rerun as rr

    return list(rr.chunk.RrdReader(path).stream())


def test_disabled_recorder_is_a_no_op(catalog, tmp_path):
    rec = Recorder(None)
    assert not rec.enabled
    rec.log_room(LAYOUT, catalog)
    rec.set_time(1.0, step=1)
    rec.log_robot(RobotPose(0, 0, 0))
    rec.log_camera(_frame(RobotPose(0, 0, 0)), [])
    rec.log_volumes("world/volumes/x", [OBJECTS[0].box()])
    rec.log_path(np.zeros((2, 2)))
    rec.log_text("nothing")
    rec.log_scalar("metrics/x", 1.0)
    rec.close()
    assert list(tmp_path.iterdir()) == []


def test_wall_boxes_leave_the_door_open():
    walls = wall_boxes(LAYOUT)
    assert len(walls) == 5  # the south wall is split by the door
    door_x = LAYOUT.door.center
    for b in walls:
        on_south = b.center[1] < -LAYOUT.depth / 2
        if on_south:
            lo, hi = b.center[0] - b.half[0], b.center[0] + b.half[0]
            assert (
                hi <= door_x - LAYOUT.door.width / 2 + 1e-9
                or lo >= door_x + LAYOUT.door.width / 2 - 1e-9
            )


def test_recording_round_trip(catalog, tmp_path):
    path = tmp_path / "sub" / "run.rrd"
    desk = OBJECTS[0]
    with Recorder(path) as rec:
        assert rec.enabled
        rec.log_room(LAYOUT, catalog)
        rels = catalog.type("Desk").relations
        rec.log_volumes(
            "world/volumes/Desk_1",
            [relation_volume(r, desk) for r in rels],
            labels=[r.name for r in rels],
            color=(1, 0, 0),
            static=True,
        )
        for i, pose in enumerate(
            [RobotPose(-2.0, -1.5, 0.5), RobotPose(-1.0, -1.5, 0.8, 0.2, -0.3)]
        ):
            rec.set_time(1.5 * i, step=i)
            rec.log_robot(pose, path=np.array([[-2.0, -1.5], [-1.5, -1.6]]) if i else None)
            frame = _frame(pose)
            dets = detect_ids(
                frame.instance_ids, {o.id: o for o in OBJECTS}, catalog, depth=frame.depth
            )
            rec.log_camera(frame, dets)
            rec.log_text(f"step {i}")
            rec.log_scalar("metrics/coverage", 0.5 * i)
    assert path.stat().st_size > 0
    chunks = _chunks(path)
    entities = {c.entity_path for c in chunks}
    expected = {
        "/world/room/floor",
        "/world/room/walls",
        "/world/objects/Desk_1",
        "/world/objects/Desk_1/parts",
        "/world/objects/Cup_2",
        "/world/volumes/Desk_1",
        "/world/robot",
        "/world/robot/body",
        "/world/robot_path",
        "/world/camera",
        "/world/camera/image",
        "/world/camera/image/rgb",
        "/world/camera/image/segmentation",
        "/world/camera/image/depth",
        "/world/camera/image/detections",
        "/log",
        "/metrics/coverage",
    }
    assert expected <= entities, expected - entities
    by_entity: dict[str, list] = {}
    for c in chunks:
        by_entity.setdefault(c.entity_path, []).append(c)
    # The room is static; what moves is on the sim_time and step timelines.
    assert all(c.is_static for c in by_entity["/world/objects/Desk_1"])
    for ent in ("/world/camera", "/world/robot", "/world/camera/image/rgb", "/metrics/coverage"):
        assert any(
            "sim_time" in c.timeline_names and "step" in c.timeline_names for c in by_entity[ent]
        ), ent
    # Labels of the room's boxes carry the type names.
    table = next(c for c in by_entity["/world/objects/Desk_1"]).to_record_batch()
    text = str(table.to_pydict())
    assert "Desk" in text
    # The camera rotation is MuJoCo's xmat turned into rerun's RDF convention.
    cam = camera_at(RobotPose(-1.0, -1.5, 0.8, 0.2, -0.3))
    rot = cam.xmat @ np.diag([1.0, -1.0, -1.0])
    fwd = rot @ np.array([0.0, 0.0, 1.0])
    heading = 0.8 + 0.2
    np.testing.assert_allclose(
        fwd,
        [math.cos(-0.3) * math.cos(heading), math.cos(-0.3) * math.sin(heading), math.sin(-0.3)],
        atol=1e-9,
    )
    assert (rot @ np.array([0.0, 1.0, 0.0]))[2] < 0  # image y (down) points down in the world


def test_close_twice_and_empty_volumes(catalog, tmp_path):
    rec = Recorder(tmp_path / "x.rrd")
    rec.log_volumes("world/volumes/none", [])
    rec.close()
    rec.close()
    assert not rec.enabled
    assert "/world/volumes/none" in {c.entity_path for c in _chunks(tmp_path / "x.rrd")}


@pytest.mark.render
def test_recording_a_rendered_frame(catalog, tmp_path):
    world_mod = pytest.importorskip("envs.world")
    world = world_mod.World(LAYOUT, catalog)
    try:
        world.reset_pose(RobotPose(-2.0, -1.5, math.atan2(1.5, 2.0), 0.0, -0.3))
        frame = world.capture(rgb=True, depth=True)
    finally:
        world.close()
    with Recorder(tmp_path / "r.rrd") as rec:
        rec.set_time(world.sim_time)
        rec.log_camera(frame, [])
    assert "/world/camera/image/rgb" in {c.entity_path for c in _chunks(tmp_path / "r.rrd")}
