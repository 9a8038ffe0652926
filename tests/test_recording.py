"""The rerun recorder: a no-op without a path; with one, a .rrd that rerun reads back."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from ctxsearch.agent.recording import Recorder, wall_boxes
from ctxsearch.envs.camera import camera_at
from ctxsearch.envs.detector import detect_ids
from ctxsearch.envs.layout import Door, RoomLayout
from ctxsearch.envs.robot_spec import RobotPose
from ctxsearch.knowledge.geometry import ObjectInstance, relation_volume

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
    rec.set_time(1.0)
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
            rec.set_time(1.5 * i)
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
        "/world/camera/depth/image",
        "/world/camera/image/detections",
        "/log",
        "/metrics/coverage",
    }
    assert expected <= entities, expected - entities
    by_entity: dict[str, list] = {}
    for c in chunks:
        by_entity.setdefault(c.entity_path, []).append(c)
    # The room is static; what moves is on the sim_time timeline, and on no other.
    assert all(c.is_static for c in by_entity["/world/objects/Desk_1"])
    for ent in ("/world/camera", "/world/robot", "/world/camera/image/rgb", "/metrics/coverage"):
        assert all(c.timeline_names == ["sim_time"] for c in by_entity[ent]), ent
    assert {tuple(c.timeline_names) for c in chunks if not c.is_static} == {("sim_time",)}
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
    world_mod = pytest.importorskip("ctxsearch.envs.world")
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


def test_a_learning_run_is_one_named_recording_laid_out_by_its_blueprint(catalog, tmp_path):
    from ctxsearch.agent.learning import LearnConfig, learn, room_seed, style_layouts
    from tests.rrd_files import read_rrd

    rrd = tmp_path / "run.rrd"
    config = LearnConfig(
        "office", 2, tmp_path / "kb.sqlite", perception="oracle", record=rrd, progress=False
    )
    summary = learn(config)
    assert summary.files == [rrd]
    assert sorted(p.name for p in tmp_path.glob("*.rrd")) == ["run.rrd"]
    f = read_rrd(rrd)
    assert [r.application_id for r in f.recordings] == ["ctxsearch-learn"]
    assert f.name is not None and f.name.startswith("learn: office, strategy hif")
    # Every entity and log line is on sim_time, and only there.
    assert f.timelines == {("sim_time",)}
    assert f.static <= {"/__properties", "/world", "/world/robot/body", "/world/robot/nose"}
    # Both rooms are in it, one after the other on the run clock.
    floor = sorted(f.times["/world/room/floor"])
    assert len(floor) == 2 and floor[0] == 0 < floor[1]
    starts = [t for t, text in f.texts if text.startswith("room ") and "objects" in text]
    assert starts == floor
    assert f.texts[-1][1].startswith("room 1 done")
    assert all(t <= f.texts[-1][0] for t, _ in f.texts)
    # n is plotted for the types present in the rooms, not for every type of the catalog.
    _, generate = style_layouts("office", catalog)
    present = {o.type for i in range(2) for o in generate(i, room_seed(0, i)).objects}
    plotted = {e.rsplit("/", 1)[1] for e in f.entities if e.startswith("/knowledge/n/")}
    assert plotted == present and len(plotted) < len(catalog.type_names)
    assert "/knowledge/mean_width" in f.entities
    # The blueprint: a 3-D view of the world, the camera and its depth apart, two plots, a log.
    assert len(f.blueprints) == 1 and f.blueprint_timeline == "sim_time"
    views = {(v["class"], v["origin"]) for v in f.views}
    assert views == {
        ("3D", "world"),
        ("2D", "world/camera/image"),
        ("2D", "world/camera/depth"),
        ("TimeSeries", "knowledge/n"),
        ("TimeSeries", "knowledge/mean_width"),
        ("TextLog", "log"),
    }


@pytest.mark.render
def test_searches_side_by_side_in_one_recording(catalog, tmp_path, desk_cup_store):
    from ctxsearch.agent.search.config import SearchConfig
    from ctxsearch.agent.search.runner import search_once
    from tests.rrd_files import read_rrd

    kb = desk_cup_store(tmp_path / "kb.sqlite")
    rrd = tmp_path / "search.rrd"
    config = SearchConfig("office", ("location", "exhaustive"), budget_s=25.0)
    config = config.updated({"map.scenario": "given", "knowledge.kb": kb})
    one = search_once(config, "Cup", record=rrd, catalog=catalog)
    assert one.files == [rrd]
    f = read_rrd(rrd)
    assert len(f.recordings) == 1 and f.recordings[0].application_id == "ctxsearch-search"
    assert f.name is not None and "location vs exhaustive" in f.name
    assert f.timelines == {("sim_time",)}
    for root in ("location", "exhaustive"):
        assert {f"/{root}/world/room/walls", f"/{root}/world/camera/depth/image"} <= f.entities
        assert f"/{root}/world/camera/image/rgb" in f.entities
        lines = [(t, x) for t, x in f.texts if x.startswith(f"{root}: ")]
        assert lines[0][0] == 0 and lines[0][1].startswith(f"{root}: looking for Cup (")
        assert not any(x.startswith(f"{root}: {root}:") for _, x in lines)  # no doubled prefix
    # Only the best three candidate regions carry a label on screen.
    assert "/location/world/search/best" in f.entities
    # The belief is drawn on the floor and thins out as images come (agent.search.belief): a
    # heat map at more than one time, beside the detectable mass left.
    assert len(set(f.times["/location/world/search/belief"])) >= 2
    assert "/location/search/mass_left/location" in f.entities
    assert "/exhaustive/world/search/belief" not in f.entities  # a reference: no belief
    views = [(v["class"], v["origin"]) for v in f.views]
    for root in ("location", "exhaustive"):
        assert ("3D", f"{root}/world") in views
        assert ("2D", f"{root}/world/camera/image") in views
        assert ("2D", f"{root}/world/camera/depth") in views
    assert ("TextLog", "/") in views and f.blueprint_timeline == "sim_time"
