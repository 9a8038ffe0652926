"""Gaze planning: camera geometry, aiming, frustum coverage, the planner, and executing a gaze."""

from __future__ import annotations

import math

import numpy as np
import pytest

import ctxsearch.agent.viewplan as viewplan_module
from ctxsearch.agent.navigation import OccupancyGrid, plan_path
from ctxsearch.agent.viewplan import (
    Gaze,
    aim,
    box_samples,
    execute_gaze,
    facing_for,
    in_view,
    plan_gazes,
)
from ctxsearch.envs.camera import PinholeCamera, camera_at, camera_axes
from ctxsearch.envs.layout import Door, RoomLayout
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, TimeModel
from ctxsearch.knowledge.geometry import Box, ObjectInstance, relation_volume

SPEC = RobotSpec()
DESK = ObjectInstance("Desk", 1, (0.0, 0.0, 0.37), 0.3, (0.7, 1.4, 0.74))
OBJECTS = (
    DESK,
    ObjectInstance("Shelf", 2, (-1.5, 1.0, 0.9), math.pi / 2, (0.4, 1.0, 1.8)),
    ObjectInstance("Table", 3, (1.5, -1.3, 0.37), 0.0, (0.9, 1.2, 0.74)),
)
OFFICE = RoomLayout("test", 0, 6.0, 5.0, 2.6, Door("south", 0.0, 0.9), OBJECTS)


def test_camera_axes_are_a_rotation_looking_along_the_heading():
    for heading, tilt in [(0.0, 0.0), (1.0, -0.5), (-2.5, 0.3)]:
        r = camera_axes(heading, tilt)
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0)
        fwd = -r[:, 2]
        np.testing.assert_allclose(
            fwd,
            [
                math.cos(tilt) * math.cos(heading),
                math.cos(tilt) * math.sin(heading),
                math.sin(tilt),
            ],
            atol=1e-12,
        )
        assert r[2, 0] == pytest.approx(0.0)  # image right stays horizontal (no roll)
        assert r[2, 1] > 0  # image up points up


def test_projection_and_aim():
    pose_xy = np.array([1.0, -0.5])
    target = np.array([2.5, 0.7, 0.4])
    for yaw in (0.0, 1.2, -2.0):
        pan, tilt = aim(pose_xy, yaw, SPEC.camera_height, target, SPEC)
        cam = camera_at(RobotPose(pose_xy[0], pose_xy[1], yaw, pan, tilt), SPEC)
        pix, depth = cam.project(target[None])
        np.testing.assert_allclose(pix[0], [160, 120], atol=1e-6)
        assert depth[0] == pytest.approx(np.linalg.norm(target - cam.position))
    # Straight ahead at camera height: no pan, no tilt; to the left: pan +90 degrees; below: tilt < 0.
    assert aim(np.zeros(2), 0.0, 1.2, np.array([2.0, 0.0, 1.2]), SPEC) == pytest.approx((0.0, 0.0))
    pan, tilt = aim(np.zeros(2), 0.0, 1.2, np.array([0.0, 2.0, 1.2]), SPEC)
    assert pan == pytest.approx(math.pi / 2) and tilt == pytest.approx(0.0)
    assert aim(np.zeros(2), 0.0, 1.2, np.array([1.0, 0.0, 0.2]), SPEC)[1] == pytest.approx(
        -math.pi / 4
    )
    # Beyond the joint limits: clipped.
    assert aim(np.zeros(2), 0.0, 1.2, np.array([0.05, 0.0, 0.0]), SPEC)[1] == SPEC.tilt_range[0]
    assert abs(aim(np.zeros(2), 0.0, 1.2, np.array([-2.0, 0.0, 1.2]), SPEC)[0]) == pytest.approx(
        SPEC.pan_range[1]
    )
    # Pixel conventions: a point up and to the right lands up (small v) and right (large u).
    cam = camera_at(RobotPose(0, 0, 0), SPEC)
    pix, _ = cam.project(np.array([[2.0, -0.3, 1.5]]))
    assert pix[0, 0] > 160 and pix[0, 1] < 120
    k = cam.intrinsics()
    assert k[0, 0] == pytest.approx(120 / math.tan(math.radians(29)))


def _grown(box: Box) -> Box:
    return Box(box.center, box.yaw, box.half + 1e-9)  # corners lie on the boundary


def test_in_view_and_samples():
    cam = camera_at(RobotPose(0, 0, 0), SPEC)
    ahead = Box(np.array([3.0, 0.0, 1.2]), 0.0, np.array([0.2, 0.2, 0.2]))
    behind = Box(np.array([-3.0, 0.0, 1.2]), 0.0, np.array([0.2, 0.2, 0.2]))
    wide = Box(np.array([1.0, 0.0, 1.2]), 0.0, np.array([0.2, 5.0, 0.2]))
    assert in_view(cam, ahead) == 1.0
    assert in_view(cam, behind) == 0.0
    assert 0.0 < in_view(cam, wide) < 0.5
    assert in_view(cam, ahead, max_distance=2.0) == 0.0
    pts = box_samples(ahead)  # 0.4 m sides, samples at most 0.25 m apart: 3 per axis
    assert len(pts) == 27 and _grown(ahead).contains_points(pts).all()
    small = Box(np.array([3.0, 0.0, 1.2]), 0.0, np.array([0.1, 0.1, 0.1]))
    assert len(box_samples(small)) == 8  # just the corners
    big = Box(np.array([0.0, 0.0, 1.0]), 0.4, np.array([2.0, 2.0, 1.0]))
    pts = box_samples(big, max_points=200)
    assert len(pts) <= 200 and _grown(big).contains_points(pts).all()
    assert cam.sees(pts).dtype == bool


def test_facing_for_desk_relations(catalog):
    front = np.array([math.cos(DESK.yaw), math.sin(DESK.yaw)])
    left = np.array([-math.sin(DESK.yaw), math.cos(DESK.yaw)])
    desk = catalog.type("Desk")
    expect = {
        "IN-FRONT-OF-DESK": front,
        "UNDER-DESK": front,
        "BEHIND-DESK": -front,
        "LEFT-OF-DESK": left,
        "RIGHT-OF-DESK": -left,
        "ON-TOP-OF-DESK": None,
        "NEAR-DESK": None,
    }
    for rel in desk.relations:
        got = facing_for(rel, DESK)
        want = expect[rel.name]
        if want is None:
            assert got is None, rel.name
        else:
            np.testing.assert_allclose(got, want, atol=1e-9, err_msg=rel.name)


def _coverage(gazes: list[Gaze], box: Box, max_distance: float) -> float:
    pts = box_samples(box, max_points=200)
    hit = np.zeros(len(pts), bool)
    for g in gazes:
        hit |= camera_at(g.pose, SPEC).sees(pts, max_distance)
    return float(hit.mean())


@pytest.mark.parametrize(
    "rel_name",
    [
        "ON-TOP-OF-DESK",
        "UNDER-DESK",
        "IN-FRONT-OF-DESK",
        "BEHIND-DESK",
        "LEFT-OF-DESK",
        "RIGHT-OF-DESK",
        "NEAR-DESK",
    ],
)
def test_plan_gazes_cover_the_desk_volumes(catalog, rel_name):
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    rel = catalog.relation(rel_name)
    vol = relation_volume(rel, DESK)
    start = RobotPose(-2.5, -2.0, 0.0)
    facing = facing_for(rel, DESK)
    gazes = plan_gazes(grid, vol, start, SPEC, TimeModel(), facing=facing)
    assert 1 <= len(gazes) <= 6
    reach = grid.reachable_mask(start.xy)
    for g in gazes:
        assert grid.is_free(g.pose.xy) and reach[grid.to_cell(g.pose.xy)]
        assert SPEC.pan_range[0] <= g.pose.pan <= SPEC.pan_range[1]
        assert SPEC.tilt_range[0] <= g.pose.tilt <= SPEC.tilt_range[1]
        assert g.cost > 0 and g.coverage > 0
    cov = _coverage(gazes, vol, 2.5)
    assert cov >= (0.75 if rel_name == "NEAR-DESK" else 0.9), cov
    if facing is not None:  # the first view is from the open side
        off = gazes[0].pose.xy - vol.center[:2]
        assert off @ facing > 0


def test_plan_gazes_prefers_nearby_viewpoints(catalog):
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    vol = relation_volume(catalog.relation("IN-FRONT-OF-DESK"), DESK)
    front = np.array([math.cos(DESK.yaw), math.sin(DESK.yaw)])
    near_start = DESK.box().center[:2] + 1.6 * front
    far_start = np.array([-2.5, 2.2])
    g_near = plan_gazes(grid, vol, RobotPose(*near_start, 0.0), SPEC)
    g_far = plan_gazes(grid, vol, RobotPose(*far_start, 0.0), SPEC)
    assert np.linalg.norm(g_near[0].pose.xy - near_start) < 1.0
    assert g_near[0].cost < g_far[0].cost


def test_plan_gazes_nothing_reachable():
    # The box is in a part of the room the robot cannot reach and cannot see from where it can.
    wall = ObjectInstance("Shelf", 7, (1.0, 0.0, 0.9), 0.0, (0.4, 5.0, 1.8))
    split = RoomLayout("test", 0, 12.0, 5.0, 2.6, Door("south", 0.0, 0.9), (wall,))
    grid = OccupancyGrid.from_layout(split, SPEC)
    box = Box(np.array([5.5, 0.0, 0.3]), 0.0, np.array([0.2, 0.2, 0.2]))
    assert plan_gazes(grid, box, RobotPose(-5.0, 0.0, 0.0), SPEC) == []


def test_volume_against_a_wall_still_gets_gazes(catalog):
    # A desk whose left side touches the north wall: LEFT-OF-DESK lies mostly beyond the wall and
    # cannot be seen from the left; the planner drops the outside part and looks from elsewhere.
    desk = ObjectInstance("Desk", 1, (0.0, 2.5 - 0.7, 0.37), 0.0, (0.7, 1.4, 0.74))
    layout = RoomLayout("test", 0, 6.0, 5.0, 2.6, Door("south", 0.0, 0.9), (desk,))
    grid = OccupancyGrid.from_layout(layout, SPEC)
    rel = catalog.relation("LEFT-OF-DESK")
    vol = relation_volume(rel, desk)
    assert vol.center[1] + vol.half[1] > 2.5  # reaches beyond the wall
    gazes = plan_gazes(grid, vol, RobotPose(0.0, -1.5, 0.0), SPEC, facing=facing_for(rel, desk))
    assert gazes
    inside = box_samples(vol, max_points=200)
    inside = inside[inside[:, 1] <= 2.5]
    hit = np.zeros(len(inside), bool)
    for g in gazes:
        hit |= camera_at(g.pose, SPEC).sees(inside, 2.5)
    assert hit.mean() > 0.9
    # Entirely outside the room: nothing to plan.
    outside = Box(np.array([0.0, 4.0, 0.5]), 0.0, np.array([0.3, 0.3, 0.3]))
    assert plan_gazes(grid, outside, RobotPose(0.0, -1.5, 0.0), SPEC) == []


class FakeWorld:
    """Records the motions execute_gaze asks for."""

    def __init__(self, pose: RobotPose):
        self.spec = SPEC
        self._pose = pose
        self.calls: list[tuple] = []

    def pose(self) -> RobotPose:
        return self._pose

    def drive(self, path, final_yaw=None):
        self.calls.append(("drive", np.asarray(path), final_yaw))
        end = np.asarray(path)[-1]
        self._pose = RobotPose(
            float(end[0]), float(end[1]), final_yaw, self._pose.pan, self._pose.tilt
        )
        return 1.0

    def move_head(self, pan, tilt):
        self.calls.append(("head", pan, tilt))
        self._pose = RobotPose(self._pose.x, self._pose.y, self._pose.yaw, pan, tilt)
        return 0.5

    def capture(self, rgb=False, depth=True):
        self.calls.append(("capture", rgb, depth))
        return self._pose


def test_execute_gaze_drives_aims_and_captures(catalog):
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    vol = relation_volume(catalog.relation("IN-FRONT-OF-DESK"), DESK)
    start = RobotPose(-2.5, -2.0, 0.0)
    gaze = plan_gazes(grid, vol, start, SPEC)[0]
    world = FakeWorld(start)
    final = execute_gaze(world, grid, gaze, rgb=True)
    kinds = [c[0] for c in world.calls]
    assert kinds == ["drive", "head", "capture"]
    path = world.calls[0][1]
    np.testing.assert_allclose(path, plan_path(grid, start.xy, gaze.pose.xy))
    np.testing.assert_allclose(final.xy, gaze.pose.xy)
    cam = camera_at(final, SPEC)
    pix, _ = cam.project(gaze.target[None])
    np.testing.assert_allclose(pix[0], [160, 120], atol=1e-6)
    # Already there: no driving, just the head and the image.
    world2 = FakeWorld(final)
    execute_gaze(world2, grid, gaze)
    assert [c[0] for c in world2.calls] == ["head", "capture"]


def test_execute_gaze_reuses_the_planned_path_only_from_its_start(catalog, monkeypatch):
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    vol = relation_volume(catalog.relation("IN-FRONT-OF-DESK"), DESK)
    start = RobotPose(-2.5, -2.0, 0.0)
    gaze = plan_gazes(grid, vol, start, SPEC)[0]
    assert gaze.path is not None and len(gaze.path) >= 2
    planned: list[tuple] = []

    def counting_plan_path(g, a, b):
        planned.append((tuple(a), tuple(b)))
        return plan_path(g, a, b)

    monkeypatch.setattr(viewplan_module, "plan_path", counting_plan_path)
    world = FakeWorld(start)
    execute_gaze(world, grid, gaze)
    assert planned == []  # standing where gaze.path starts: the planned path is driven
    assert world.calls[0][1] is gaze.path
    # A robot standing a little off (a physical drive ends near, not at, a point) replans.
    off = RobotPose(-2.5 + 1e-4, -2.0, 0.0)
    world2 = FakeWorld(off)
    execute_gaze(world2, grid, gaze)
    assert len(planned) == 1
    np.testing.assert_allclose(world2.calls[0][1][0], off.xy)
    np.testing.assert_allclose(world2.calls[0][1][-1], gaze.pose.xy)


def _visibility_reference(cams, heading, tilt, points, width, height, max_distance):
    """The frustum test written plainly: camera axes stacked, dot products by einsum."""
    ch, sh, ct, st = np.cos(heading), np.sin(heading), np.cos(tilt), np.sin(tilt)
    fwd = np.stack([ct * ch, ct * sh, st], -1)
    right = np.stack([sh, -ch, np.zeros_like(ch)], -1)
    up = np.stack([-st * ch, -st * sh, ct], -1)
    rel = points[None, :, :] - cams[:, None, :]
    z = np.einsum("ctk,cnk->ctn", fwd, rel)
    x = np.einsum("ctk,cnk->ctn", right, rel)
    y = np.einsum("ctk,cnk->ctn", up, rel)
    tan_y = math.tan(math.radians(SPEC.fovy_deg) / 2)
    tan_x = tan_y * width / height
    dist = np.linalg.norm(rel, axis=-1)[:, None, :]
    return (z > 0.05) & (np.abs(x) <= z * tan_x) & (np.abs(y) <= z * tan_y) & (dist <= max_distance)


@pytest.mark.parametrize("block", [1, 700, 65536])
def test_visibility_matches_the_plain_frustum_test(monkeypatch, block):
    import ctxsearch.envs.camera as camera_module

    monkeypatch.setattr(camera_module, "_FRUSTUM_BLOCK", block)
    rng = np.random.default_rng(3)
    cams = np.column_stack([rng.uniform(-3, 3, (40, 2)), np.full(40, SPEC.camera_height)])
    aims = rng.uniform([-2, -2, 0], [2, 2, 1.5], (5, 3))
    points = rng.uniform([-2.5, -2.5, 0], [2.5, 2.5, 2], (120, 3))
    heading, tilt = viewplan_module._aim_angles(cams, aims, SPEC)
    tangents = camera_module.half_fov_tangents(SPEC.fovy_deg, 320, 240)
    got = camera_module.frustum_masks(cams, heading, tilt, points, tangents, 2.5)
    want = _visibility_reference(cams, heading, tilt, points, 320, 240, 2.5)
    assert got.shape == (40, 5, 120) and 0 < want.sum() < want.size
    np.testing.assert_array_equal(got, want)
    # The single-camera form of the same test agrees too.
    for c in range(0, 40, 7):
        for t in range(5):
            one = camera_module.frustum_mask(
                cams[c], float(heading[c, t]), float(tilt[c, t]), points, SPEC, 2.5
            )
            np.testing.assert_array_equal(one, want[c, t])


def test_unit_weight_gains_are_the_weighted_formula():
    # With unit weights the planner counts new points (a 0/1 matrix-vector product); that must
    # equal, bit for bit, the general sum of max(w - cov, 0) it uses for other weights.
    rng = np.random.default_rng(4)
    seen_w = (rng.random((300, 173)) < 0.4).astype(np.float32)
    hit = rng.random(173) < 0.3
    cov = hit.astype(np.float32)
    unit = viewplan_module._gains(seen_w, cov, hit, 173, unit=True)
    general = viewplan_module._gains(seen_w, cov, hit, 173, unit=False)
    assert unit.dtype == general.dtype == np.float32
    np.testing.assert_array_equal(unit, general)


def test_pinhole_view_is_a_camera():
    cam = camera_at(RobotPose(0.5, 0.5, 1.0, 0.2, -0.3), SPEC, 640, 480)
    assert isinstance(cam, PinholeCamera)
    assert cam.width == 640 and cam.focal == pytest.approx(240 / math.tan(math.radians(29)))


# --------------------------------------------------------------------------- rendered
@pytest.mark.render
def test_model_matches_the_simulated_camera(catalog):
    world_mod = pytest.importorskip("ctxsearch.envs.world")
    world = world_mod.World(OFFICE, catalog)
    try:
        for pose in (RobotPose(-2.0, -1.5, 0.4, 0.3, -0.4), RobotPose(2.0, 1.5, -2.5, -1.0, 0.2)):
            world.reset_pose(pose)
            info = world.camera_info()
            model = camera_at(world.pose(), world.spec)
            np.testing.assert_allclose(info.position, model.position, atol=1e-6)
            np.testing.assert_allclose(info.xmat, model.xmat, atol=1e-6)
            assert info.fovy_deg == pytest.approx(model.fovy_deg)
        # execute_gaze in MuJoCo: the target ends up in the middle of the image, the desk is seen.
        grid = OccupancyGrid.from_layout(OFFICE, world.spec)
        world.reset_pose(RobotPose(-2.5, -2.0, 0.0))
        vol = relation_volume(catalog.relation("ON-TOP-OF-DESK"), DESK)
        gaze = plan_gazes(grid, vol, world.pose(), world.spec, world.time_model)[0]
        t0 = world.sim_time
        frame = execute_gaze(world, grid, gaze)
        assert world.sim_time > t0
        pix, _ = frame.camera.project(gaze.target[None])
        np.testing.assert_allclose(pix[0], [160, 120], atol=3.0)
        assert DESK.id in set(np.unique(frame.instance_ids))
    finally:
        world.close()
