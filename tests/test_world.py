"""The MuJoCo world: MJCF conventions, motion and time, rendering from the robot's camera."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ctxsearch.envs.entities import OBJECT_GEOM_GROUP, body_name
from ctxsearch.envs.layout import Door, RoomLayout
from ctxsearch.envs.robot import JOINTS, ROBOT_GEOM_GROUP
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, TimeModel
from ctxsearch.envs.task import RoomTask
from ctxsearch.envs.world import World
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance

DESK, CUP, CHAIR, PEN = 1, 2, 3, 4


@pytest.fixture(scope="module")
def layout() -> RoomLayout:
    """A hand-made 5 m x 4 m room: a desk against the east wall facing west (-x), a cup on it,
    a chair in front of it, a pen on the floor by the north wall; the door in the west wall."""
    desk_size = (0.7, 1.4, 0.74)
    objs = (
        ObjectInstance("Desk", DESK, (2.0, 0.0, 0.37), math.pi, desk_size),
        ObjectInstance("Cup", CUP, (1.9, 0.35, 0.74 + 0.05), 0.0, (0.08, 0.08, 0.10)),
        ObjectInstance("Chair", CHAIR, (1.3, -0.3, 0.45), 0.0, (0.5, 0.5, 0.9)),
        ObjectInstance("Pen", PEN, (0.0, 1.8, 0.0075), 0.3, (0.14, 0.015, 0.015)),
    )
    return RoomLayout(
        "handmade",
        0,
        5.0,
        4.0,
        2.6,
        Door("west", 0.0, 0.9),
        objs,
        support={CUP: DESK, DESK: None, CHAIR: None, PEN: None},
    )


@pytest.fixture(scope="module")
def world(layout, catalog):
    w = World(layout, catalog)
    yield w
    w.close()


def _close(a: RobotPose, b: RobotPose) -> bool:
    dyaw = math.atan2(math.sin(a.yaw - b.yaw), math.cos(a.yaw - b.yaw))
    return (
        math.hypot(a.x - b.x, a.y - b.y) < 0.01
        and abs(dyaw) < 0.01
        and abs(a.pan - b.pan) < 0.01
        and abs(a.tilt - b.tilt) < 0.01
    )


def test_mjcf_follows_the_conventions(layout, catalog):
    """Robot: five joints with position servos whose ctrlrange is the joint range, a keyframe,
    non-colliding geoms in their own group; one static body per object instance."""
    task = RoomTask(catalog, layout=layout)
    task.initialize_episode_mjcf(np.random.RandomState(0))
    from dm_control import mjcf

    physics = mjcf.Physics.from_mjcf_model(task.root_entity.mjcf_model)
    m = physics.model
    assert m.nq == m.nv == m.nu == 5  # furniture and objects are static
    joints = physics.bind(task.robot.joints)
    acts = physics.bind(task.robot.actuators)
    assert [j.name.split("/")[-1] for j in task.robot.joints] == list(JOINTS)
    limited = joints.limited.astype(bool)
    np.testing.assert_allclose(acts.ctrlrange[limited], joints.range[limited])
    np.testing.assert_allclose(joints.range[0], [-2.5, 2.5])  # x limited to the room
    assert not limited[2]  # yaw turns freely
    assert m.nkey == 1
    robot_geoms = m.geom_group == ROBOT_GEOM_GROUP
    assert robot_geoms.sum() >= 3
    assert not m.geom_contype[robot_geoms].any() and not m.geom_conaffinity[robot_geoms].any()
    lut = task.objects.geom_instance_ids(physics)
    for obj in layout.objects:
        geoms = np.flatnonzero(lut == obj.id)
        assert len(geoms) >= 1
        assert len(set(m.geom_bodyid[geoms])) == 1  # one body per instance
        assert physics.model.id2name(m.geom_bodyid[geoms[0]], "body").endswith(body_name(obj.id))
        assert (m.geom_group[geoms] == OBJECT_GEOM_GROUP).all()
    assert len(np.flatnonzero(lut == DESK)) >= 5  # a top and four legs


def test_task_runs_under_a_composer_environment(layout, catalog):
    from dm_control import composer

    env = composer.Environment(
        RoomTask(catalog, layout=layout), strip_singleton_obs_buffer_dim=True
    )
    env.reset()
    assert env.action_spec().shape == (5,)
    action = env.physics.data.qpos.copy()
    action[3] = 0.5
    for _ in range(20):
        env.step(action)
    assert abs(env.physics.data.qpos[3] - 0.5) < 0.02
    env.close()


def test_drive_and_head_reach_targets_and_charge_time_model(world):
    tm = world.time_model
    world.reset_pose(RobotPose(-1.5, 0.0, 0.0))
    t0 = world.sim_time
    path = np.array([[-1.5, 0.0], [-0.5, 1.0], [0.5, 1.0]])
    charged = world.drive(path, final_yaw=-math.pi / 2)
    assert charged == pytest.approx(tm.drive_time(path, 0.0, -math.pi / 2))
    assert world.sim_time - t0 == pytest.approx(charged)
    assert _close(world.pose(), RobotPose(0.5, 1.0, -math.pi / 2))
    assert world.physics.data.time >= charged  # the physics really ran through the motion

    t1 = world.sim_time
    charged = world.move_head(1.0, -0.6)
    # Charged from where the joints actually are (within the settle tolerance of 0, 0).
    assert charged == pytest.approx(tm.head_time(0.0, 0.0, 1.0, -0.6), abs=1e-3)
    assert world.sim_time - t1 == pytest.approx(charged)
    assert _close(world.pose(), RobotPose(0.5, 1.0, -math.pi / 2, 1.0, -0.6))

    world.move_head(10.0, -5.0)  # clipped to the joint limits
    spec = world.spec
    assert world.pose().pan == pytest.approx(spec.clip_head(10.0, -5.0)[0], abs=0.01)
    assert world.pose().tilt == pytest.approx(spec.tilt_range[0], abs=0.01)

    # A path that does not start at the robot: the robot's position is prepended and charged.
    world.reset_pose(RobotPose(0.0, 0.0, 0.0))
    charged = world.drive(np.array([[1.0, 0.0]]), None)
    assert charged == pytest.approx(tm.drive_time(np.array([[0, 0], [1.0, 0]]), 0.0))
    assert _close(world.pose(), RobotPose(1.0, 0.0, 0.0))


@pytest.mark.parametrize("style", ["office", "apartment"])
def test_the_robot_alone_moves_as_it_does_in_the_world_bit_for_bit(catalog, style):
    """``World`` steps the robot's motion in the robot's own model (``robot_dynamics``): the same
    joint positions, velocities and physics time as stepping the whole world's model, after
    every drive and head motion, with joint limits met on the way."""
    from ctxsearch.envs.floorplan import generate_layout
    from ctxsearch.envs.houses import resolve_style

    layout = generate_layout(resolve_style(style, catalog), 3, catalog)
    own, full = World(layout, catalog), World(layout, catalog)
    assert own._motion[0].nbody == 5 and own._motion[0] is not own._m  # the robot alone
    full._motion = (full._m, full._d)  # the whole world's model, as before
    rng = np.random.default_rng(3)
    half = np.array([layout.width, layout.depth]) / 2 - 0.5
    for w in (own, full):
        w.reset_pose(RobotPose(0.0, 0.0, 0.3))
    for _ in range(6):
        path = rng.uniform(-half, half, (3, 2))
        yaw, pan, tilt = rng.uniform(-3, 3), rng.uniform(-4, 4), rng.uniform(-2, 1)
        for w in (own, full):
            w.drive(path, final_yaw=yaw)
            w.move_head(pan, tilt)  # beyond the head's limits at times
        for name in ("qpos", "qvel", "qacc_warmstart", "ctrl", "xpos", "cam_xpos", "cam_xmat"):
            assert getattr(own._d, name).tobytes() == getattr(full._d, name).tobytes(), name
        assert own._d.time == full._d.time and own.sim_time == full.sim_time
    own.close()
    full.close()


@pytest.mark.render
def test_camera_sees_the_desk_in_front_and_projects_consistently(world, layout):
    world.reset_pose(RobotPose(-0.5, 0.0, 0.0, 0.0, -0.3))
    t0 = world.sim_time
    frame = world.capture(rgb=True, depth=True)
    assert world.sim_time - t0 == pytest.approx(TimeModel().image_cost)
    assert frame.rgb.shape == (240, 320, 3) and frame.rgb.dtype == np.uint8
    assert frame.depth.shape == (240, 320) and frame.depth.dtype == np.float32
    assert frame.instance_ids.shape == (240, 320) and frame.instance_ids.dtype == np.int32
    ids, counts = np.unique(frame.instance_ids, return_counts=True)
    seen = dict(zip(ids.tolist(), counts.tolist(), strict=True))
    assert seen.get(DESK, 0) > 1000 and seen.get(CHAIR, 0) > 500
    assert set(seen) <= {-1, DESK, CUP, CHAIR, PEN}

    cam = frame.camera
    np.testing.assert_allclose(cam.position, [-0.5, 0.0, RobotSpec().camera_height], atol=1e-6)
    np.testing.assert_allclose(cam.forward, [math.cos(0.3), 0.0, -math.sin(0.3)], atol=1e-3)
    # A point on the desk top projects onto desk pixels, at the depth the depth image holds.
    top = np.array([[2.0, 0.55, 0.74]])
    (u, v), z = cam.project(top)[0][0], cam.project(top)[1][0]
    i, j = int(v), int(u)
    assert frame.instance_ids[i, j] == DESK
    assert frame.depth[i, j] == pytest.approx(z, abs=0.03)
    # Back-projecting that pixel lands on the desk top.
    assert cam.backproject(frame.depth)[i, j, 2] == pytest.approx(0.74, abs=0.03)
    rays = cam.pixel_rays()
    np.testing.assert_allclose(np.linalg.norm(rays, axis=-1), 1.0, atol=1e-6)
    np.testing.assert_allclose(cam.intrinsics()[0, 2], 160.0)


@pytest.mark.render
def test_head_camera_does_not_see_the_robot(world):
    """Looking steeply down, the centre pixel sees the floor, not the mast or the base."""
    world.reset_pose(RobotPose(-1.0, -1.0, 0.3))
    world.move_head(0.0, world.spec.tilt_range[0])
    frame = world.capture(depth=True)
    tilt = -world.pose().tilt
    floor_depth = world.spec.camera_height / math.sin(tilt)
    c = frame.depth[118:122, 158:162]
    np.testing.assert_allclose(c, floor_depth, atol=0.03)
    # And no robot geom made it into the head camera's scene at all.
    import mujoco  # after envs.world, which selects the EGL backend

    r = world._renderers[(world.width, world.height)]
    geoms = r.scene.geoms[: r.scene.ngeom]
    geom_ids = [g.objid for g in geoms if g.objtype == int(mujoco.mjtObj.mjOBJ_GEOM)]
    assert not (world.physics.model.geom_group[geom_ids] == ROBOT_GEOM_GROUP).any()


@pytest.mark.render
def test_overview_shows_the_room_and_no_time_is_charged(world):
    t0 = world.sim_time
    img = world.render_overview(320, 240)
    assert img.shape == (240, 320, 3)
    assert world.sim_time == t0
    assert img.std() > 10  # not a blank image
    # The robot's orange nose marker is where overview_pixels puts it.
    pose = world.pose()
    nose = [
        pose.x + 0.7 * world.spec.base_radius * math.cos(pose.yaw),
        pose.y + 0.7 * world.spec.base_radius * math.sin(pose.yaw),
    ]
    u, v = world.overview_pixels(np.array([nose]), 320, 240)[0]
    r, g, b = img[int(v), int(u)].astype(int)
    assert r > 180 and r - b > 100 and g < r - 40, (r, g, b)  # orange


@pytest.mark.render
def test_renderers_close(layout, catalog):
    with World(layout, catalog, width=160, height=120) as w:
        frame = w.capture(depth=False)
        assert frame.depth is None and frame.rgb is None
        assert frame.instance_ids.shape == (120, 160)
        r = w._renderers[(160, 120)]
    assert r._mjr_context is None and not w._renderers
    with pytest.raises(RuntimeError):
        w.capture()


def test_egl_failure_is_a_one_line_error(layout, catalog, monkeypatch):
    import ctxsearch.envs.world as world_mod

    def broken(*args, **kwargs):
        raise ImportError("Cannot initialize a EGL device display.\nsecond line")

    monkeypatch.setattr(world_mod, "_Renderer", broken)
    w = World(layout, catalog)
    with pytest.raises(CtxsearchError) as exc:
        w.capture()
    msg = str(exc.value)
    assert "\n" not in msg and "apt-get install -y libegl1 libgl1-mesa-dri" in msg
    w.close()


@pytest.mark.render
def test_bench_sim_writes_json_table_and_plot(tmp_path, capsys):
    """`ctxsearch bench sim` on a tiny run writes its three files with the issue's keys."""
    import csv
    import json
    import statistics

    from ctxsearch.scripts.cli import main

    assert main(["bench", "sim", "--out", str(tmp_path), "--rooms", "2", "--gazes", "5"]) == 0
    r = json.loads((tmp_path / "bench_sim.json").read_text())
    for key in ("layouts_per_s", "compile_ms", "gazes_per_s", "overhead_ratio"):
        assert r[key] > 0
    with (tmp_path / "bench_sim.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))  # one per timed gaze: the JSON's medians are over them
    assert [(int(x["room"]), int(x["gaze"])) for x in rows] == [
        (i, g) for i in (0, 1) for g in range(5)
    ]
    assert statistics.median(float(x["gaze_ms"]) for x in rows) == pytest.approx(r["gaze_ms"])
    assert statistics.median(float(x["compile_ms"]) for x in rows[::5]) == pytest.approx(
        r["compile_ms"]
    )
    assert (tmp_path / "bench_sim.md").read_text().startswith("# bench sim")
    assert (tmp_path / "bench_sim.png").stat().st_size > 1000
    assert "gazes per second" in capsys.readouterr().out


@pytest.mark.render
def test_bench_sim_without_out_writes_nothing(tmp_path, capsys, monkeypatch):
    """Without --out only the table is printed (its files go to a removed temporary directory);
    fewer gazes than the warm-up are timed as asked."""
    import tempfile

    from ctxsearch.scripts.cli import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    assert main(["bench", "sim", "--rooms", "1", "--gazes", "3", "--explore", "0"]) == 0
    out = capsys.readouterr().out
    assert "gazes per second" in out and "no files written" in out
    assert [p.name for p in tmp_path.iterdir()] == ["tmp"] and not any((tmp_path / "tmp").iterdir())


@pytest.mark.render
def test_task_exposes_the_head_camera_as_observables(layout, catalog):
    from dm_control import composer

    task = RoomTask(catalog, layout=layout, camera_size=(64, 48))
    assert {"head_rgb", "head_depth"} <= set(task.observables)
    env = composer.Environment(task, strip_singleton_obs_buffer_dim=True)
    obs = env.reset().observation
    assert obs["head_rgb"].shape == (48, 64, 3) and obs["head_rgb"].dtype == np.uint8
    assert obs["head_depth"].shape == (48, 64, 1)
    # The same picture as the World's head camera at the same pose (the robot's geoms hidden).
    with World(layout, catalog, width=64, height=48) as world:
        world.reset_pose(RobotPose(*env.physics.bind(task.robot.joints).qpos))
        frame = world.capture(rgb=True, depth=True)
    assert np.median(np.abs(obs["head_depth"][:, :, 0] - frame.depth)) < 0.01
    assert np.abs(obs["head_rgb"].astype(int) - frame.rgb.astype(int)).mean() < 8
    env.close()
    with pytest.raises(CtxsearchError, match="image size"):
        RoomTask(catalog, layout=layout, camera_size=(0, 48))


def test_rays_meet_what_the_camera_would_show_first(world, layout):
    """``ray_instances``: the cup on the desk seen from the room's centre, the desk's top along a
    ray beside the cup, nothing (a wall) along a ray away from both."""
    eye = np.array([0.0, 0.0, world.spec.camera_height])
    cup = np.array(layout.objects[1].position)
    top = np.array([1.75, 0.55, 0.735])
    hits = world.ray_instances(eye, np.array([cup, top, [0.0, -3.0, 1.2]]))
    assert hits.tolist() == [CUP, DESK, -1]
    t = world.sim_time
    world.ray_instances(eye, cup[None, :])
    assert world.sim_time == t  # no time charged
