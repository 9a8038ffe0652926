"""Gaze planning: where to put the base and how to point the head to see a region of space.

Used by the acquisition loop (look into every relation volume of an object being examined) and by
search (look at a candidate region). A *gaze* is a robot pose (base on a free, reachable grid
cell; pan and tilt within their limits) plus the point the camera is aimed at.

Camera model: envs.camera (the head camera at a pose is ``camera_at(pose, spec)``; the frusta of
all candidate gazes are ``frustum_masks``, its vectorised frustum test).

Planner (``plan_gazes``):
1. sample points on a lattice filling the box (at most 0.25 m apart, corners included, coarser
   for a big box so there are at most ``max_points``);
2. candidate base positions: every reachable free cell on a ``candidate_step`` lattice whose
   ground distance to the box's footprint is at most ``max_distance``, plus the current position;
3. aim points: the box's centre and, for a box whose footprint is larger than ``split`` (NEAR-DESK
   is about 3 x 3.4 m), the centres of its pieces after cutting the footprint into parts of at
   most ``split`` metres;
4. for every (position, aim point) the sample points inside the frustum and within
   ``max_distance`` of the camera, weighted by a line-of-sight preference: when the volume has an
   open side (``facing``, e.g. a desk's front for UNDER-DESK or IN-FRONT-OF-DESK, see
   ``facing_for``), a viewpoint counts ((1 + cos a) / 2)^2 (at least 0.05: 1 in front, 1/4 from the side) where a is the angle
   between that side and the direction from the box to the viewpoint;
5. greedy weighted set cover: repeatedly take the gaze with the best (new weighted coverage) /
   (simulated seconds to get there from the previous gaze: TimeModel drive over the grid distance,
   the turn, the head slew and the image), until ``coverage_goal`` of the points are in some
   frustum, no gaze adds ``min_gain``, or ``max_gazes`` are chosen.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ctxsearch.agent.interfaces import Body
from ctxsearch.agent.navigation import OccupancyGrid, nearest_free, plan_path
from ctxsearch.envs.camera import Frame, PinholeCamera, frustum_masks, half_fov_tangents
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, TimeModel, wrap_angle, wrap_angles
from ctxsearch.knowledge.catalog import RelationSpec
from ctxsearch.knowledge.geometry import Box, ObjectInstance


# --------------------------------------------------------------------------- sampling
def box_samples(box: Box, spacing: float = 0.25, max_points: int = 400) -> np.ndarray:
    """World points (N, 3) on a lattice filling ``box``, corners included, at most ``spacing``
    apart (coarser if that would exceed ``max_points``). Ordered x-major, z fastest."""
    half = [float(h) for h in box.half]
    while True:
        n = [max(2, math.ceil(2 * h / spacing) + 1) for h in half]
        if n[0] * n[1] * n[2] <= max_points:
            break
        spacing *= 1.25
    ax, ay, az = (np.linspace(-h, h, k) for h, k in zip(half, n, strict=True))
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    cx, cy, cz = (float(v) for v in box.center)
    out = np.empty((n[0], n[1], n[2], 3))
    out[..., 0] = ((c * ax[:, None] - s * ay[None, :]) + cx)[:, :, None]
    out[..., 1] = ((s * ax[:, None] + c * ay[None, :]) + cy)[:, :, None]
    out[..., 2] = az + cz
    return out.reshape(-1, 3)


def in_view(camera: PinholeCamera, box: Box, max_distance: float | None = None) -> float:
    """The fraction of ``box``'s sample points (lattice incl. corners) inside the camera's frustum."""
    return float(camera.sees(box_samples(box), max_distance).mean())


def aim(
    pose_xy: np.ndarray,
    base_yaw: float,
    camera_height: float,
    target_xyz: np.ndarray,
    spec: RobotSpec | None = None,
) -> tuple[float, float]:
    """Pan and tilt (within the joint limits) that point the camera of a base at ``pose_xy`` with
    heading ``base_yaw`` at ``target_xyz``."""
    spec = spec or RobotSpec()
    d = np.asarray(target_xyz, float) - np.array([pose_xy[0], pose_xy[1], camera_height])
    heading = math.atan2(d[1], d[0]) if math.hypot(d[0], d[1]) > 1e-9 else base_yaw
    tilt = math.atan2(d[2], math.hypot(d[0], d[1]))
    return spec.clip_head(wrap_angle(heading - base_yaw), tilt)


def facing_for(rel: RelationSpec, ref: ObjectInstance) -> np.ndarray | None:
    """The world direction (2,) from which volume v_rel(ref) is best seen, or None if any side will
    do: the side the volume sticks out of (IN-FRONT-OF: the front, LEFT-OF: the left...), and the
    reference's front for a volume tucked under it (UNDER-DESK: desks are open at the front)."""
    lo, hi = rel.local_bounds(np.asarray(ref.size, float))
    center = (lo + hi) / 2
    half = np.asarray(ref.size, float) / 2
    out = np.abs(center[:2]) - half[:2]
    c, s = math.cos(ref.yaw), math.sin(ref.yaw)
    if np.any(out > -1e-6) and np.hypot(*center[:2]) > 1e-6:
        d = center[:2] * (out > -1e-6)  # the axes along which the volume leaves the footprint
        local = d / np.linalg.norm(d)
    elif hi[2] < half[2] - 1e-6:  # inside the footprint and below the top: under it
        local = np.array([1.0, 0.0])
    else:
        return None
    return np.array([c * local[0] - s * local[1], s * local[0] + c * local[1]])


# --------------------------------------------------------------------------- planning
@dataclass(frozen=True)
class Gaze:
    """A robot pose from which to take one image, the point it aims at, and the planner's
    estimates of the coverage it adds and the seconds it costs from the previous gaze."""

    pose: RobotPose
    target: np.ndarray
    coverage: float = 0.0
    cost: float = 0.0
    path: np.ndarray | None = field(default=None, compare=False, repr=False)


def _aim_points(box: Box, split: float) -> np.ndarray:
    """The box's centre and, when its footprint is larger than ``split``, the centres of its pieces
    after cutting it along x and y into parts of at most ``split`` metres (at the centre's height)."""
    half = np.asarray(box.half, float)
    n = np.maximum(1, np.ceil(2 * half[:2] / split - 1e-9).astype(int))
    pts = [np.asarray(box.center, float)]
    if np.prod(n) > 1:
        axes = [(np.arange(k) + 0.5) / k * 2 * h - h for h, k in zip(half[:2], n, strict=True)]
        lx, ly = (a.ravel() for a in np.meshgrid(*axes, indexing="ij"))
        c, s = math.cos(box.yaw), math.sin(box.yaw)
        pts.extend(
            np.column_stack([c * lx - s * ly, s * lx + c * ly, np.zeros_like(lx)]) + box.center
        )
    return np.array(pts)


def _aim_angles(
    cams: np.ndarray, aims: np.ndarray, spec: RobotSpec
) -> tuple[np.ndarray, np.ndarray]:
    """(C, T) world heading and (clipped) tilt of the camera at cams[c] aimed at aims[t]."""
    d = aims[None, :, :] - cams[:, None, :]  # (C, T, 3)
    heading = np.arctan2(d[..., 1], d[..., 0])
    tilt = np.clip(np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])), *spec.tilt_range)
    return heading, tilt


def _gains(seen_w: np.ndarray, cov: np.ndarray, hit: np.ndarray, n: int, unit: bool) -> np.ndarray:
    """(P,) float32: the share of the ``n`` points each pair's weighted frustum ``seen_w`` (P, N)
    adds to the weighted coverage ``cov`` (N,): sum over points of max(w - cov, 0), over n.
    ``unit`` (every weight 1, so cov is ``hit`` as 0/1): the count of seen points not yet
    ``hit``, as a float32 matrix-vector product of 0/1 values, which is exact (integers below
    2**24) whatever the summation order, hence the same float32 values, several times faster."""
    if unit:
        return (seen_w @ (~hit).astype(np.float32)) / n
    return np.maximum(seen_w - cov, 0.0).sum(-1) / n


@dataclass(frozen=True)
class GazePlanOptions:
    """The planner's settings (see the module docstring): how far a viewpoint may stand from the
    box, the image size, when to stop (``coverage_goal``, ``min_gain``, ``max_gazes``), how to cut
    and sample the box, the candidate lattice step, and ``cost_weight``: gazes are ranked by
    gain / cost**cost_weight (1: coverage per second; 0: coverage only, for the best picture
    whatever the walk)."""

    max_distance: float = 2.5
    width: int = 320
    height: int = 240
    coverage_goal: float = 0.95
    min_gain: float = 0.03
    max_gazes: int = 6
    split: float = 1.2
    candidate_step: float = 0.3
    max_points: int = 200
    cost_weight: float = 1.0


@dataclass
class _Candidates:
    """Everything the greedy cover scores: candidate base positions and their grid cells, aim
    points and directions, sample points, and which (position, aim) pair sees which point."""

    cand: np.ndarray  # (C, 2) base positions; row 0 is the start
    cells: tuple[np.ndarray, np.ndarray]  # (rows, cols) of the candidates
    aims: np.ndarray  # (T, 3)
    heading: np.ndarray  # (C, T) world heading of the aim direction
    tilt: np.ndarray  # (C, T)
    seen_pairs: np.ndarray  # (C*T, N) bool: pair p = (p // T, p % T)


def plan_gazes(
    grid: OccupancyGrid,
    box: Box,
    start_pose: RobotPose,
    spec: RobotSpec | None = None,
    time_model: TimeModel | None = None,
    options: GazePlanOptions | None = None,
    facing: np.ndarray | None = None,
) -> list[Gaze]:
    """A short sequence of gazes whose frusta together cover ``box`` (see the module docstring).

    The first gaze starts from ``start_pose``, each later one from the previous gaze. Sample
    points outside the grid (beyond the walls) are dropped. If ``facing`` leaves no gaze worth
    taking (the open side is against a wall), the plan is made without it. Returns [] if no
    reachable viewpoint sees any of the box.

    Speed (the plans are those of scoring every pair in full):
    the candidate lattice is cached per grid (``OccupancyGrid.lattice_cells``) and the driving
    distances come from the grid's search cache; the greedy loop scores only the (position,
    aim) pairs that can still add ``min_gain`` (a pair's gain never grows), kept in the order of
    the full (position, aim) table so ties go to the same pair; unit weights count points
    (``_gains``). Each gaze carries its planned path, which ``execute_gaze`` drives as is.
    """
    spec = spec or RobotSpec()
    tm = time_model or TimeModel()
    opt = options or GazePlanOptions()
    c = _candidates(grid, box, start_pose, spec, opt)
    if c is None:
        return []
    weights = [np.ones(len(c.cand))]
    if facing is not None:
        f = np.asarray(facing, float)[:2]
        f = f / max(np.linalg.norm(f), 1e-12)
        off = c.cand - np.asarray(box.center[:2], float)
        cos = (off @ f) / np.maximum(np.linalg.norm(off, axis=1), 1e-9)
        weights.insert(0, np.maximum(0.05, (1.0 + cos) / 2) ** 2)
    for weight in weights:  # with the facing preference; if that finds nothing, without it
        gazes = _greedy_cover(grid, c, weight, start_pose, spec, tm, opt)
        if gazes:
            return gazes
    return []


def _room_points(grid: OccupancyGrid, box: Box, max_points: int) -> np.ndarray:
    """The box's sample points inside the grid (points beyond the walls can never be seen)."""
    points = box_samples(box, max_points=max_points)
    h, w = grid.shape
    lo = np.array([grid.x0, grid.y0])
    inside = np.all(
        (points[:, :2] >= lo) & (points[:, :2] <= lo + grid.resolution * np.array([w, h])), axis=1
    )
    return points[inside]


def _candidates(
    grid: OccupancyGrid, box: Box, start_pose: RobotPose, spec: RobotSpec, opt: GazePlanOptions
) -> _Candidates | None:
    """Steps 1-4 of the planner; None when no reachable viewpoint sees any of the box."""
    points = _room_points(grid, box, opt.max_points)
    if len(points) == 0:
        return None
    aims = _aim_points(box, opt.split)
    # Candidate base positions: reachable free cells on a coarse lattice near the box.
    start_xy = nearest_free(grid, start_pose.xy)
    if start_xy is None:
        return None
    k = max(1, int(round(opt.candidate_step / grid.resolution)))
    rows, cols = grid.lattice_cells(k)
    reach = np.isfinite(grid.distances_from(start_xy)[rows, cols])
    rows, cols = rows[reach], cols[reach]
    xs, ys = grid.cell_centers()
    cand = np.column_stack([xs[cols], ys[rows]])
    cand = cand[box.footprint_distance(cand) <= opt.max_distance]
    cand = np.vstack([start_xy[None, :], cand])
    cams = np.column_stack([cand, np.full(len(cand), spec.camera_height)])
    # Heading and tilt of the aim direction for every (candidate, aim): the frusta, and the
    # head/turn cost estimate.
    heading, tilt = _aim_angles(cams, aims, spec)
    tangents = half_fov_tangents(spec.fovy_deg, opt.width, opt.height)
    seen = frustum_masks(cams, heading, tilt, points, tangents, opt.max_distance)
    if not seen.any():
        return None
    # Grid cell of every candidate, for its driving distance.
    r_c = np.floor((cand[:, 1] - grid.y0) / grid.resolution).astype(int)
    c_c = np.floor((cand[:, 0] - grid.x0) / grid.resolution).astype(int)
    return _Candidates(cand, (r_c, c_c), aims, heading, tilt, seen.reshape(-1, len(points)))


def _greedy_cover(
    grid: OccupancyGrid,
    c: _Candidates,
    weight: np.ndarray,
    start_pose: RobotPose,
    spec: RobotSpec,
    tm: TimeModel,
    opt: GazePlanOptions,
) -> list[Gaze]:
    """Step 5: greedy weighted set cover by gain per second from the previous gaze."""
    n_t, n = len(c.aims), c.seen_pairs.shape[1]
    # Only pairs that see something can ever be chosen; ``live`` (row-major (c, t) order)
    # shrinks as pairs fall below min_gain.
    live = np.flatnonzero(c.seen_pairs.any(axis=1))
    seen_w = c.seen_pairs[live] * np.repeat(weight.astype(np.float32), n_t)[live, None]
    unit = bool(np.all(weight == 1.0))
    cov = np.zeros(n, np.float32)  # weighted coverage so far
    hit = np.zeros(n, bool)  # in some chosen frustum
    cur = start_pose
    gazes: list[Gaze] = []
    while len(gazes) < opt.max_gazes and hit.mean() < opt.coverage_goal:
        gain = _gains(seen_w, cov, hit, n, unit)  # (P,)
        keep = gain >= opt.min_gain
        if not keep.any():
            break
        if not keep.all():
            live, seen_w, gain = live[keep], seen_w[keep], gain[keep]
        ci, ti = np.divmod(live, n_t)
        cost = _pair_costs(grid, c, ci, ti, cur, tm)
        best = int(np.argmax(gain / cost**opt.cost_weight))
        gaze = _gaze(grid, c, int(ci[best]), int(ti[best]), cur, spec)
        gazes.append(replace(gaze, coverage=float(gain[best]), cost=float(cost[best])))
        if not unit:
            cov = np.maximum(cov, seen_w[best])
        hit |= c.seen_pairs[live[best]]
        cur = gaze.pose
    return gazes


def _pair_costs(
    grid: OccupancyGrid,
    c: _Candidates,
    ci: np.ndarray,
    ti: np.ndarray,
    cur: RobotPose,
    tm: TimeModel,
) -> np.ndarray:
    """Seconds from pose ``cur`` to the gaze of every (position ci, aim ti) pair: the drive over
    the grid distance with its turn, the head slew (the head is kept while driving) and the
    image (the vectorised TimeModel)."""
    cur_xy = np.asarray(cur.xy, float)
    p_xy = c.cand[ci]
    drive = grid.distances_from(cur_xy)[c.cells[0][ci], c.cells[1][ci]]  # metres along the grid
    moved = np.hypot(*(p_xy - cur_xy).T) > 1e-3
    arrive = np.where(
        moved, np.arctan2(p_xy[:, 1] - cur_xy[1], p_xy[:, 0] - cur_xy[0]), float(cur.yaw)
    )
    t_drive = tm.travel_time(drive) + np.where(moved, tm.turn_times(float(cur.yaw), arrive), 0.0)
    pan = wrap_angles(c.heading[ci, ti] - arrive)
    pan0 = np.where(moved, 0.0, float(cur.pan))
    t_head = tm.head_times(pan0, float(cur.tilt), pan, c.tilt[ci, ti])
    return t_drive + t_head + tm.image_cost


def _gaze(
    grid: OccupancyGrid, c: _Candidates, c_i: int, t_i: int, cur: RobotPose, spec: RobotSpec
) -> Gaze:
    """The gaze of pair (c_i, t_i) reached from ``cur``: the planned path, the heading it
    arrives with, and the head aimed at the aim point (turning the base beyond the pan limit)."""
    xy = c.cand[c_i]
    path = plan_path(grid, np.asarray(cur.xy, float), xy)
    yaw = float(cur.yaw)
    if path is not None and len(path) >= 2:
        seg = path[-1] - path[-2]
        if np.hypot(*seg) > 1e-9:
            yaw = math.atan2(seg[1], seg[0])
    pan, tilt = aim(xy, yaw, spec.camera_height, c.aims[t_i], spec)
    if abs(wrap_angle(yaw + pan - c.heading[c_i, t_i])) > 1e-3:  # pan limit: turn the base
        yaw, pan = float(c.heading[c_i, t_i]), 0.0
    pose = RobotPose(float(xy[0]), float(xy[1]), float(yaw), float(pan), float(tilt))
    return Gaze(pose, c.aims[t_i].copy(), path=path)


def _path_between(path: np.ndarray | None, a: tuple[float, float], b: tuple[float, float]) -> bool:
    """True if ``path`` (K, 2) starts exactly at ``a`` and ends exactly at ``b``."""
    return (
        path is not None
        and len(path) > 0
        and (float(path[0, 0]), float(path[0, 1])) == a
        and (float(path[-1, 0]), float(path[-1, 1])) == b
    )


def execute_gaze(
    world: Body, grid: OccupancyGrid, gaze: Gaze, *, rgb: bool = False, depth: bool = True
) -> Frame | None:
    """Drive to the gaze's base position (a planned path), turn, point the head at its target and
    capture a frame (``face_gaze``, then ``capture``); returns the world's ``Frame``."""
    face_gaze(world, grid, gaze)
    return world.capture(rgb=rgb, depth=depth)


def face_gaze(world: Body, grid: OccupancyGrid, gaze: Gaze) -> None:
    """Drive to the gaze's base position (a planned path), turn and point the head at its
    target; no image. If the position cannot be reached from where the robot stands, the robot
    turns towards the target from where it is.

    The path is ``gaze.path`` (planned by ``plan_gazes`` on the same ``grid``) when the robot
    stands exactly where it starts and it ends at the gaze's position: ``plan_path`` would return
    it again. Otherwise, e.g. after a physical drive ended a little off, it is planned anew."""
    spec = world.spec
    pose = world.pose()
    path = gaze.path
    if not _path_between(path, (pose.x, pose.y), (gaze.pose.x, gaze.pose.y)):
        path = plan_path(grid, pose.xy, gaze.pose.xy)
    yaw = pose.yaw
    if path is not None and len(path) >= 2:
        seg = path[-1] - path[-2]
        if np.hypot(*seg) > 1e-9:
            yaw = math.atan2(seg[1], seg[0])
        xy = path[-1]
    else:
        xy = pose.xy
    pan, tilt = aim(xy, yaw, spec.camera_height, gaze.target, spec)
    d = np.asarray(gaze.target, float)[:2] - xy
    heading = math.atan2(d[1], d[0])
    if abs(wrap_angle(yaw + pan - heading)) > 1e-3:  # beyond the pan limit: turn the base instead
        yaw = heading
        pan, tilt = aim(xy, yaw, spec.camera_height, gaze.target, spec)
    if path is not None and len(path) >= 2:
        world.drive(path, yaw)
    elif abs(wrap_angle(yaw - pose.yaw)) > 1e-6:
        world.drive(np.asarray(pose.xy, float)[None, :], yaw)
    world.move_head(pan, tilt)
