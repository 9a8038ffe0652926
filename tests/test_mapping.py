"""The robot's own map (agent.mapping) and frontier exploration (agent.frontiers): the built map
never calls an occupied cell free, drives on it never cross furniture or walls, and learning
runs on it (``--map built``), with ``--map given`` as it was."""

from __future__ import annotations

import numpy as np
import pytest

from ctxsearch.agent import learning
from ctxsearch.agent.acquisition import start_pose
from ctxsearch.agent.learning import LearnConfig
from ctxsearch.agent.mapping import BuiltMap, default_map_mode, map_quality
from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.envs.camera import Frame, camera_at
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, TimeModel
from ctxsearch.knowledge.errors import CtxsearchError


def _plane_frame(pose: RobotPose, spec: RobotSpec, wall_x: float | None = None) -> Frame:
    """A depth image of an empty floor (z = 0), with an infinite wall at x = ``wall_x``."""
    cam = camera_at(pose, spec)
    rays = cam.pixel_rays()  # unit rays
    fwd = cam.forward
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(rays[..., 2] < -1e-9, -cam.position[2] / rays[..., 2], np.inf)
        if wall_x is not None:
            tw = np.where(rays[..., 0] > 1e-9, (wall_x - cam.position[0]) / rays[..., 0], np.inf)
            t = np.minimum(t, tw)
    depth = np.minimum(t, 50.0) * (rays @ fwd)  # along the optical axis
    ids = np.full(depth.shape, -1, np.int32)
    return Frame(None, depth.astype(np.float32), ids, cam, pose)


def test_an_empty_map_knows_nothing_but_the_robot_and_grows_with_images():
    spec = RobotSpec()
    start = RobotPose(0.0, 0.0, 0.0)
    m = BuiltMap((-3.0, -3.0, 3.0, 3.0), spec, start)
    assert not m.grid.free.any()  # its own disc is floor, not enough for the clearance
    assert m.floor.sum() > 0 and not m.occupied.any()
    for pan in np.radians([-150, -90, -30, 30, 90, 150]):
        for tilt in (-0.35, -1.0):
            m.update(_plane_frame(RobotPose(0.0, 0.0, 0.0, pan, tilt), spec, wall_x=2.0))
    g = m.refresh()
    assert g.is_free(np.array([0.0, 0.0])) and g.is_free(np.array([1.2, 0.5]))
    # The wall is occupied, nothing beyond it is known, and no free cell is near it.
    xs, _ = g.cell_centers()
    assert m.occupied[:, (xs > 1.95) & (xs < 2.05)].any()
    assert not m.floor[:, xs > 2.1].any()
    assert not g.free[:, xs > 2.0 - spec.clearance].any()
    assert m.seen_voxels.any()
    assert m.frontier().any()


@pytest.mark.render
@pytest.mark.parametrize(("style", "seeds", "budget"), [("office", range(4), 80.0),
                                                        ("apartment", [3], 150.0)])  # fmt: skip
def test_the_built_map_never_calls_an_occupied_cell_free_and_drives_touch_nothing(
    style, seeds, budget
):
    from ctxsearch.agent.frontiers import explore_world
    from ctxsearch.envs.floorplan import generate_layout
    from ctxsearch.envs.houses import resolve_style
    from ctxsearch.envs.world import World
    from ctxsearch.knowledge.catalog import load_catalog
    from ctxsearch.scripts.experiments.bench_map import body_grid, unsafe_segments

    cat, spec, tm = load_catalog(), RobotSpec(), TimeModel()
    st = resolve_style(style, cat)
    drives = 0
    for seed in seeds:
        lay = generate_layout(st, seed, cat)
        given = OccupancyGrid.from_layout(lay, spec)
        start = start_pose(lay, given)
        with World(lay, cat, spec=spec, time_model=tm) as world:
            world.reset_pose(start)
            built = BuiltMap.for_layout(lay, spec, start)
            ex = explore_world(world, built, tm, budget_s=budget)
        body = body_grid(lay, spec)
        q = map_quality(built.refresh(), given, body, start.xy)
        assert q.false_free == 0, (style, seed)
        assert q.free_recall > 0.2, (style, seed)
        assert unsafe_segments(ex.paths, body) == 0, (style, seed)
        drives += len(ex.paths)
    assert drives > 0


def test_map_modes_default_by_perception_and_the_oracle_needs_the_given_map(tmp_path):
    assert default_map_mode("camera") == "built" and default_map_mode("oracle") == "given"
    cfg = LearnConfig("office", 1, tmp_path / "k.sqlite", perception="oracle").checked()
    assert cfg.map_mode == "given"
    assert LearnConfig("office", 1, tmp_path / "k.sqlite").checked().map_mode == "built"
    with pytest.raises(CtxsearchError, match="--map given"):
        LearnConfig(
            "office", 1, tmp_path / "k.sqlite", perception="oracle", map_mode="built"
        ).checked()
    with pytest.raises(CtxsearchError, match="unknown map mode"):
        LearnConfig("office", 1, tmp_path / "k.sqlite", map_mode="sonar").checked()
    assert learning.run_id("hif", "camera", 0, None, "built") == "hif/camera/seed=0/map=built"
    assert learning.run_id("hif", "camera", 0, None, "given") == "hif/camera/seed=0"


@pytest.mark.render
def test_learning_on_the_built_map_resumes_exactly(tmp_path):
    """A built-map run interrupted and resumed makes the choices, at the clock, of an
    uninterrupted one (the replay renders depth for the map), with either detector. With the
    realistic one the replay re-takes the examination images: they must update the built map as
    the first run's did (a replay that skipped it diverged after ~20 examinations)."""

    def go(path, detector, rooms, **kw):
        seq = []
        s = learning.learn(
            LearnConfig("office", rooms, path, progress=False, detector=detector, **kw),
            on_examination=lambda res, kb: seq.append((res.choice.obj.id, round(res.sim_time, 6))),
        )
        return s, seq

    for detector, rooms, cut in (("perfect", 1, 4), ("realistic", 2, 7)):
        full, seq_full = go(tmp_path / f"full_{detector}.sqlite", detector, rooms)
        assert full.map_mode == "built" and full.run.endswith("/map=built")
        assert len(seq_full) >= 20  # long enough that a map left behind in the replay shows
        part = tmp_path / f"part_{detector}.sqlite"
        _, seq1 = go(part, detector, rooms, max_examinations=cut)
        _, seq2 = go(part, detector, rooms)
        assert seq1 == seq_full[:cut]
        assert seq2 == seq_full, detector


def test_learn_says_which_map_and_takes_the_world_budget(tmp_path, capsys):
    from ctxsearch.scripts.cli import main

    kb = tmp_path / "k.sqlite"
    args = ["learn", "--style", "office", "--rooms", "1", "--kb", str(kb), "--no-progress"]
    assert main([*args, "--perception", "oracle", "--world-budget", "30"]) == 0
    out = capsys.readouterr().out
    assert "map: given" in out and "room budget: 30 s simulated per room" in out
    assert "run hif/oracle/seed=0/budget=30.0s" in out
    with pytest.raises(SystemExit) as e:
        main([*args, "--map", "sonar"])
    assert e.value.code == 2
    assert main([*args, "--perception", "oracle", "--map", "built"]) == 2
    assert "needs --map given" in capsys.readouterr().err


def _reference_update(m: BuiltMap, frame: Frame) -> None:
    """The built map's update as first written (every hit through ``np.maximum.at``, every
    ray's samples as one (rays, steps, 3) array): the definition the faster code must equal."""
    from ctxsearch.agent import mapping as mp

    cam = frame.camera
    depth = np.asarray(frame.depth, np.float32)[:, :: mp.COL_STRIDE].ravel()
    local = m._local_rays(cam)
    rng = depth * local[:, 3]
    keep = np.flatnonzero(np.isfinite(depth) & (depth > mp.NEAR_CLIP) & (rng <= m.max_range))
    rays = local[keep, :3] @ np.asarray(cam.xmat, np.float32).T
    pts = np.asarray(cam.position, np.float32) + rays * depth[keep, None]
    z = pts[:, 2]
    rows = np.floor((pts[:, 1] - m.y0) / m.resolution).astype(np.int64)
    cols = np.floor((pts[:, 0] - m.x0) / m.resolution).astype(np.int64)
    h, w = m.floor.shape
    ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    hit = ok & (z >= mp.FLOOR_EPS) & (z <= m.spec.camera_height + mp.HEAD_MARGIN)
    m.occupied[rows[hit], cols[hit]] = True
    np.maximum.at(m.top_z, (rows[hit], cols[hit]), z[hit])
    flo = ok & (z < mp.FLOOR_EPS)
    m.floor[rows[flo], cols[flo]] = True
    m.floor &= ~m.occupied
    sub = m._traced[keep]
    origin, p, d = np.asarray(cam.position, float), pts[sub], rng[keep][sub]
    u = (p - origin) / np.maximum(d, 1e-9)[:, None]
    t = np.arange(0.0, m.max_range, mp.VOXEL)
    q = (origin + u[:, None, :] * t[None, :, None])[t[None, :] <= d[:, None]]
    vh, vw, vz = m.seen_voxels.shape
    r = np.floor((q[:, 1] - m.y0) / mp.VOXEL).astype(np.int64)
    c = np.floor((q[:, 0] - m.x0) / mp.VOXEL).astype(np.int64)
    k = np.floor(q[:, 2] / mp.VOXEL).astype(np.int64)
    inside = (r >= 0) & (r < vh) & (c >= 0) & (c < vw) & (k >= 0) & (k < vz)
    m.seen_voxels[r[inside], c[inside], k[inside]] = True


def test_the_map_update_equals_its_definition_cell_for_cell():
    """Images of a floor with a wall, and of clutter at random depths (many points per cell,
    later images raising some cells' highest point and not others), out of range and
    beyond the map's edge: the update's floor, occupied cells, highest points and seen voxels
    are those of the update as first written, bit for bit."""
    spec = RobotSpec()
    rng = np.random.default_rng(7)
    fast = BuiltMap((-3.0, -2.0, 3.0, 2.5), spec, RobotPose(0.0, 0.0, 0.0))
    ref = BuiltMap((-3.0, -2.0, 3.0, 2.5), spec, RobotPose(0.0, 0.0, 0.0))
    for i in range(12):
        pose = RobotPose(*rng.uniform(-1.0, 1.0, 2), rng.uniform(-3, 3), rng.uniform(-1, 1),
                         rng.uniform(-0.9, 0.1))  # fmt: skip
        frame = _plane_frame(pose, spec, wall_x=float(rng.uniform(1.5, 4.0)))
        if i % 2:  # clutter: depths scattered in front of the floor, some beyond range
            d = frame.depth * rng.uniform(0.2, 1.0, frame.depth.shape).astype(np.float32)
            d[rng.random(d.shape) < 0.05] = np.inf
            frame = Frame(None, d, frame.instance_ids, frame.camera, pose)
        fast.update(frame)
        _reference_update(ref, frame)
        for a in ("floor", "occupied", "top_z", "seen_voxels"):
            assert np.array_equal(getattr(fast, a), getattr(ref, a)), (i, a)
    assert fast.occupied.sum() > 100 and (fast.top_z > 0.5).sum() > 10
    assert fast.seen_voxels.sum() > 1000 and fast.floor.sum() > 100
