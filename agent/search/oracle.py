"""The oracle: the lower bound on time to find, and the episode draw's checks. It knows where the
target's instances are and what the detector in use will report from any pose at any simulated
second (``OracleEye``), and goes straight to the soonest view that detects one (``oracle_view``).
This module, the episode draw (agent.search.draw) and the episode runner (agent.search.runner)
are the search's only readers of the true layout.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from ctxsearch.agent.interfaces import Body
from ctxsearch.agent.navigation import OccupancyGrid, plan_path
from ctxsearch.agent.search.context import SearchContext, confirming_detection
from ctxsearch.agent.search.coverage import cover
from ctxsearch.agent.search.episode import OracleView
from ctxsearch.agent.search.policies import SearchPolicy
from ctxsearch.agent.viewplan import Gaze, aim
from ctxsearch.envs.camera import Frame, focal_length, half_fov_tangents
from ctxsearch.envs.detector import (
    Detection,
    DetectorModel,
    SimDetector,
    box_distance,
    box_distances,
    load_detector,
    ray_scale,
)
from ctxsearch.envs.floorplan import visible_rooms
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, TimeModel, wrap_angle
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance


class RenderingBody(Body, Protocol):
    """A ``Body`` the oracle can look through without charging time: its clock can be set back,
    and it traces rays to the instances its camera would show."""

    sim_time: float

    def ray_instances(
        self, origin: np.ndarray, points: np.ndarray, reach: float = 1e3
    ) -> np.ndarray | None:
        """The object instance each ray from ``origin`` (3,) through ``points`` (N, 3) meets
        first among what the head camera shows within ``reach`` m (-1: none); None where nothing
        is rendered. No time charged."""
        ...


# =========================================================================== the oracle's views
# The oracle's candidate views (``oracle_view``) and the episode checks (``OracleEye``):
# - base positions: the pose's own position and every reachable free cell of every
#   ``ORACLE_CELL_STEP``-th row and column (0.1 m on the 5 cm grid, offset one cell: a superset
#   of the lattices the other policies stand on, the coverage viewpoints' 0.5 m and the gaze
#   planner's 0.3 m, both offset by half their step), within the detector's reach of an
#   instance (camera to bounding box: the perfect detector's ``max_range``; a detector that errs:
#   where its range fall-off leaves ``MIN_RECALL``);
# - at each, the views of ``ORACLE_VIEWS``: the head aimed at the instance's centre (turning the
#   base beyond the pan limit), or moved as little as it can from where it is while the centre
#   stays within half or 0.9 of the half field of view (a view that shows the target off-centre
#   can be cheaper: other policies' sweeps take such images), each charged exactly as
#   ``execute_gaze`` will charge it (the planned path, turns, head slew, image: the one
#   TimeModel);
# - in order of a lower bound on those seconds (drive: the straight line or the grid distance
#   around obstacles over sqrt 2; tilt slew; image), each
#   view is charged exactly and, if it would beat the best so far, rendered from that pose
#   (no time charged, the robot put back) and read by the detector in use at the simulated
#   second the image would be taken, and at the seconds of the images after it when the robot
#   stays and takes more (up to ``ORACLE_IMAGES``, a confirming image after each that showed the
#   target: ``OracleEye.first_success``); a position whose aimed image shows the instance too
#   little to be detected even with ``PERSPECTIVE_GAIN`` times its pixels (perfect: below
#   min_pixels or beyond max_range; a detector that errs: recall below ``MIN_RECALL``) is not
#   rendered again.
# The detector's random stream is seeded by the room and the image's second, so that reading is
# what the robot would get there and then: the oracle knows the draws as it knows the layout, and
# takes the soonest (view, second) that detects a true instance reported as the target. With the
# perfect detector (no draws) this is the least time over every pose the other policies can stand
# at (up to the views above); with a detector that errs, a policy reaching a pose later draws
# again, so a luckier draw (or one at a recall below ``MIN_RECALL``) could beat the oracle; the
# images after the first at a view make that rare: ``bench search`` counts such episodes
# (``oracle_violations``: 0 of 1400 in the 200-episode apartment runs of both map scenarios,
# docs/results.md) and the tests check there are none. The view it executes is checked
# again from the pose the physical drive reached (a tenth of a millimetre and a milliradian off
# can move a far target's recall across its draw). A plan renders at most
# ``ORACLE_MAX_RENDERS`` images.
ORACLE_CELL_STEP = 2
# the views at each base position: the head aimed at the instance (0), or moved as little as it
# can while the instance stays within this fraction of the half field of view of the centre
ORACLE_VIEWS = (0.0, 0.5, 0.9)
RAY_SPACING_PX = 2.0  # the ray test's grid: a ray every this many pixels across the target
RAY_GRID_MAX = 5  # points along each axis of the target's box at most
GRID_PATH_RATIO = math.sqrt(2.0)  # the grid distance over the shortest free path, at most
ORACLE_IMAGES = 8  # images taken one after the other at a view (the detector draws anew each)
MIN_RECALL = 0.02  # a detector that errs: views where the target's recall is below this
PERSPECTIVE_GAIN = 2.5  # an object at the image corner shows up to ~1/cos^3(43 deg) its pixels
ORACLE_MAX_RENDERS = 600  # images rendered per plan: bounds the look for an undetectable target
VISIBLE_MIN_P = MIN_RECALL  # visible at the start: some start view may detect it this likely
# whether a base position can be reached, and the planned path there (None: no drive)
Route = tuple[bool, np.ndarray | None]


class OracleEye:
    """What the head camera would see from a pose, read by the detector in use, without moving
    the robot or charging time: the oracle's knowledge of the sensor, and the episode checks'
    (visible from the start, some pose detects the target). ``body`` renders (an envs World);
    ``detector``: the preset (None: perfect), its stream seeded as the search's."""

    def __init__(
        self,
        body: RenderingBody,
        layout: RoomLayout,
        catalog: Catalog,
        detector: DetectorModel | None,
        target: str,
    ):
        self.body, self.catalog, self.target = body, catalog, target
        self.model = detector or load_detector("perfect")
        self.sim = SimDetector(self.model, layout, catalog, layout.seed)
        self.instances = layout.of_type(target)
        self.true_ids = {o.id for o in self.instances}
        self.renders = 0
        self.layout = layout
        self._rooms_seen: dict[tuple[float, float], frozenset[int] | None] = {}
        self._ray_points: dict[tuple[int, ...], np.ndarray] = {}  # ``rays_meet``'s grids
        self._corners: dict[int, np.ndarray] = {}  # the instances' box corners (8, 3)

    def rays_meet(self, camera: np.ndarray, o: ObjectInstance) -> bool:
        """False if no ray from ``camera`` (3,) through a grid of points filling ``o``'s
        bounding box meets ``o`` first (``World.ray_instances``): it is hidden from there, or
        shows in fewer pixels than the grid's spacing (``RAY_SPACING_PX``) covers; True
        otherwise, or if the body renders nothing. A test before an image is rendered: the
        oracle's planner renders only the views whose rays meet the target."""
        focal = focal_length(self.body.spec.fovy_deg, self.body.height)
        size = np.asarray(o.size, float)
        dist = max(box_distance(camera, o), 0.05)
        n = np.clip(np.ceil(size * focal / dist / RAY_SPACING_PX), 2, RAY_GRID_MAX)
        key = (o.id, *n.astype(int).tolist())
        points = self._ray_points.get(key)
        if points is None:  # the grid's points depend on the instance and the counts only
            axes = [(np.arange(k) + 0.5) / k - 0.5 for k in key[1:]]
            grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3) * size
            points = self._ray_points[key] = o.box().world_points(grid)
        cam = np.asarray(camera, float)
        corners = self._corners.get(o.id)
        if corners is None:
            unit = np.array(
                [[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
            )
            corners = self._corners[o.id] = o.box().world_points(unit * size)
        # o's geoms lie in its box: nothing beyond its farthest corner can hide it or be it
        reach = float(np.sqrt(((corners - cam) ** 2).sum(axis=1).max())) + 0.01
        hits = self.body.ray_instances(cam, points, reach)
        return hits is None or bool(np.any(hits == o.id))

    def may_see(self, xy: np.ndarray, o: ObjectInstance) -> bool:
        """False if a camera at base position ``xy`` cannot see into ``o``'s room through the
        house's door openings (``visible_rooms``: the culling the head camera's images use, so
        such an image would show ``o`` in no pixel); True otherwise (and in a single room)."""
        room = self.layout.room_of.get(o.id)
        if room is None:
            return True
        key = (float(xy[0]), float(xy[1]))
        if key not in self._rooms_seen:
            self._rooms_seen[key] = visible_rooms(self.layout, *key)
        rooms = self._rooms_seen[key]
        return rooms is None or room in rooms

    @property
    def reach(self) -> float:
        """How far (m, camera to bounding box) the detector can report the target at all."""
        typ = self.catalog.type(self.target)
        r = self.model.recall
        if self.model.perfect or r is None:
            return float(typ.max_range)
        return float(
            (r.range_fraction + r.range_width * math.log(1.0 / MIN_RECALL - 1.0)) * typ.max_range
        )

    def frame_at(self, pose: RobotPose) -> Frame:
        """The image (ids and depth) the head camera takes at ``pose``; nothing charged, the robot
        put back where it was."""
        b = self.body
        t, here = b.sim_time, b.pose()
        b.reset_pose(pose)
        try:
            frame = b.capture(rgb=False, depth=True)
        finally:
            b.sim_time = t
            b.reset_pose(here)
        self.renders += 1
        if frame is None:
            raise CtxsearchError("the oracle's views need a body that renders images")
        return frame

    def ends_search(self, frame: Frame, sim_time: float) -> tuple[bool, bool]:
        """Whether the image ``frame``, read by the detector at simulated second ``sim_time``
        (seconds since the episode started, after the image), ends the search with success: its
        first detection of the target is confirmed by the second image the robot takes from the
        same pose (read at ``sim_time`` plus an image's seconds: ``confirming_detection``) as a
        true instance (``agent.search.context.SearchContext``); and whether it showed the target at all
        (the robot then took that second image)."""
        # The false positives, which cost most to draw, are drawn only where they can decide:
        # they cover no pixel, so they come after every true detection in an image's list.
        first, first_all = self.sim.split(frame, sim_time)
        hit = self._first(first) or self._first(first_all())
        if hit is None:
            return False, False
        second, second_all = self.sim.split(frame, sim_time + self.body.time_model.image_cost)
        if not self._true(confirming_detection(hit, second, self.target)):
            return False, True  # a false positive can confirm only a false positive
        return self._true(confirming_detection(hit, second_all(), self.target)), True

    def first_success(
        self, frame: Frame, sim_time: float, until: float, images: int | None = None
    ) -> float | None:
        """The second of the first of the images the robot takes one after the other from the
        pose of ``frame``, the first at ``sim_time``, that ends the search (``ends_search``; an
        image that showed the target is followed by its confirming image), at most ``images``
        of them (default ``ORACLE_IMAGES``) and none after ``until``; None: none does."""
        ic = self.body.time_model.image_cost
        t = sim_time
        for _ in range(ORACLE_IMAGES if images is None else images):
            if t > until + 1e-9:
                break
            ok, seen = self.ends_search(frame, t)
            if ok:
                return t
            t += 2 * ic if seen else ic
        return None

    def _first(self, dets: Sequence[Detection]) -> Detection | None:
        return next((d for d in dets if d.type == self.target), None)

    def _true(self, d: Detection | None) -> bool:
        return d is not None and d.instance_id in self.true_ids

    def probability(
        self, frame: Frame, gain: float = 1.0, instance: ObjectInstance | None = None
    ) -> float:
        """The largest probability with which the detector reports a true target instance (or
        ``instance``) in ``frame``: its recall for the instance's visible pixels, times ``gain``,
        and distance (perfect: 0 or 1)."""
        ids = np.asarray(frame.instance_ids)
        h, w = ids.shape
        typ = self.catalog.type(self.target)
        scale = ray_scale(w, h, float(frame.camera.fovy_deg))
        best = 0.0
        for o in self.instances if instance is None else [instance]:
            mask = ids == o.id
            px = int(mask.sum())
            if px == 0:
                continue
            if frame.depth is not None:
                dist = float(np.median(np.asarray(frame.depth)[mask] * scale[mask]))
            else:
                dist = box_distance(np.asarray(frame.camera.position, float), o)
            best = max(best, float(self.model.recall_prob(typ, gain * px, dist, w, h)))
        return best

    def worth(self, p: float) -> bool:
        """True if a view whose probability (``probability``) is ``p`` may detect the target."""
        return p >= (1.0 if self.model.perfect else MIN_RECALL)

    def start_visibility(self, start: RobotPose, enough: float = math.inf) -> float:
        """The largest probability that some image from ``start`` (turning in place, pan and
        tilt, no driving) reports a true target instance: the head aimed at each instance, its
        pixels times ``PERSPECTIVE_GAIN`` (an image showing it off-centre may show more). The
        instances are looked at nearest first, and the look stops at the first whose
        probability reaches ``enough`` (returned then; a caller that asks only whether the
        largest reaches a level decides the same with fewer images)."""
        spec = self.body.spec
        best = 0.0
        cam = np.array([start.x, start.y, spec.camera_height])
        near_first = sorted((box_distance(cam, o), o.id, o) for o in self.instances)
        for dist, _, o in near_first:
            if best >= enough:
                break
            if dist > self.reach or not self.may_see(start.xy, o):
                continue  # out of the detector's reach or behind walls: no image needed
            if not self.rays_meet(cam, o):
                continue  # hidden from here
            target = np.asarray(o.position, float)
            yaw = start.yaw
            pan, tilt = aim(start.xy, yaw, spec.camera_height, target, spec)
            d = target[:2] - start.xy
            heading = math.atan2(d[1], d[0])
            if abs(wrap_angle(yaw + pan - heading)) > 1e-3:  # beyond the pan limit: turn
                yaw = heading
                pan, tilt = aim(start.xy, yaw, spec.camera_height, target, spec)
            frame = self.frame_at(RobotPose(start.x, start.y, yaw, pan, tilt))
            best = max(best, self.probability(frame, PERSPECTIVE_GAIN, o))
        return best


def _exact_gaze(
    grid: OccupancyGrid,
    pose: RobotPose,
    xy: np.ndarray,
    target: np.ndarray,
    spec: RobotSpec,
    tm: TimeModel,
    frac: float = 0.0,
    route: Route | None = None,
) -> Gaze | None:
    """The gaze at base position ``xy`` that shows ``target`` as ``execute_gaze`` runs it from
    ``pose``, its ``cost`` the seconds it charges (None: ``xy`` cannot be reached). ``frac`` 0:
    the head aimed at ``target``; ``frac`` > 0: the head moved as little as it can from where it
    is while ``target`` stays within ``frac`` of the half field of view from the image centre.
    ``route``: ``_path_to(grid, pose, xy)`` if the caller has it (planned here otherwise)."""
    reachable, path = _path_to(grid, pose, xy) if route is None else route
    if not reachable:
        return None
    yaw, end = pose.yaw, pose.xy
    if path is not None and len(path) >= 2:
        seg = path[-1] - path[-2]
        if np.hypot(*seg) > 1e-9:
            yaw = math.atan2(seg[1], seg[0])
        end = path[-1]
    pan, tilt = aim(end, yaw, spec.camera_height, target, spec)
    d = target[:2] - end
    heading = math.atan2(d[1], d[0])
    if abs(wrap_angle(yaw + pan - heading)) > 1e-3:  # beyond the pan limit: turn the base
        yaw = heading
        pan, tilt = aim(end, yaw, spec.camera_height, target, spec)
    aim_xyz = np.asarray(target, float)
    if frac > 0.0:
        tx, ty = half_fov_tangents(spec.fovy_deg, 320, 240)
        a, b = frac * math.atan(tx), frac * math.atan(ty)
        pan, tilt = spec.clip_head(
            float(np.clip(pose.pan, pan - a, pan + a)),
            float(np.clip(pose.tilt, tilt - b, tilt + b)),
        )
        h, rng = yaw + pan, max(float(np.hypot(*d)), 0.5)  # a point along the camera's axis
        aim_xyz = np.array(
            [
                end[0] + rng * math.cos(h),
                end[1] + rng * math.sin(h),
                spec.camera_height + rng * math.tan(tilt),
            ]
        )
    if path is not None and len(path) >= 2:
        t = tm.drive_time(path, pose.yaw, yaw)
    else:
        t = tm.turn_time(pose.yaw, yaw) if abs(wrap_angle(yaw - pose.yaw)) > 1e-6 else 0.0
    t += tm.head_time(pose.pan, pose.tilt, pan, tilt) + tm.image_cost
    out = RobotPose(float(end[0]), float(end[1]), float(yaw), float(pan), float(tilt))
    return Gaze(out, aim_xyz, cost=float(t), path=path)


def _path_to(grid: OccupancyGrid, pose: RobotPose, xy: np.ndarray) -> Route:
    """Whether base position ``xy`` can be reached from ``pose`` and the planned path there
    (None: the robot stands there already)."""
    if float(np.hypot(*(np.asarray(xy) - pose.xy))) <= 1e-9:
        return True, None
    path = plan_path(grid, pose.xy, np.asarray(xy, float))
    return path is not None, path


def _oracle_candidates(
    eye: OracleEye, grid: OccupancyGrid, pose: RobotPose, tm: TimeModel
) -> tuple[np.ndarray, list[tuple[float, int, int, int]]]:
    """The oracle's base positions (M, 2) (``pose``'s own first) and its candidate views as
    (lower bound on the seconds from ``pose``, position index, instance index, view index),
    sorted: the drive (the straight line, or the grid's distance around obstacles), the tilt
    slew the view needs at least, and the image."""
    spec = eye.body.spec
    rows, cols = grid.lattice_cells(ORACLE_CELL_STEP)
    geo = grid.distances_from(pose.xy)[rows, cols]
    ok = np.isfinite(geo)
    xs, ys = grid.cell_centers()
    pos = np.vstack([pose.xy[None, :], np.column_stack([xs[cols[ok]], ys[rows[ok]]])])
    # the drive's length is at least the straight line, and at least the grid's distance (the
    # planner's graph) over sqrt 2 less the two end cells' offsets: a free path crosses a chain
    # of edge-sharing free cells, whose grid path is at most sqrt 2 as long. Around walls and
    # through doors the second is the tighter: with the straight line alone a house's plan
    # rendered hundreds of views in the rooms behind the wall and hit ORACLE_MAX_RENDERS
    geo = np.concatenate([[0.0], geo[ok] / GRID_PATH_RATIO - 2.0 * grid.resolution])
    reach_m = np.maximum(np.hypot(*(pos - pose.xy).T), geo)
    cams = np.column_stack([pos, np.full(len(pos), spec.camera_height)])
    _, ty = half_fov_tangents(spec.fovy_deg, 320, 240)
    pairs = []
    for j, o in enumerate(eye.instances):
        idx = np.flatnonzero(box_distances(cams, o) <= eye.reach)
        if not len(idx):
            continue
        d = np.asarray(o.position, float) - cams[idx]
        tilt = np.clip(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])), *spec.tilt_range)
        drive = reach_m[idx] / tm.drive_speed
        for v, frac in enumerate(ORACLE_VIEWS):
            slack = frac * math.atan(ty)
            lb = drive + np.maximum(np.abs(tilt - pose.tilt) - slack, 0.0) / tm.tilt_rate
            lb = lb + tm.image_cost
            pairs.extend(
                zip(lb.tolist(), idx.tolist(), [j] * len(idx), [v] * len(idx), strict=True)
            )
    pairs.sort()
    return pos, pairs


class _Aimed:
    """A base position's aimed view of one instance in ``oracle_view``: the gaze (None: the
    position cannot see the instance or cannot be reached) and, once a view from there is cheap
    enough to be tried (``read``), whether any view from there may detect the instance (the
    aimed image's pixels times ``PERSPECTIVE_GAIN``) and the second of the first aimed image
    that ends the search (None: none). The image is rendered only then: more than half of the
    aimed views a plan met cost more than its best so far, and none of their views was tried."""

    def __init__(
        self, eye: OracleEye, grid: OccupancyGrid, pose: RobotPose, xy: np.ndarray,
        o: ObjectInstance, tm: TimeModel, route: Callable[[], Route],
    ):  # fmt: skip
        self.gaze: Gaze | None = None
        self.worth: bool | None = None  # None: not rendered yet
        self.hit: float | None = None
        cam = np.array([xy[0], xy[1], eye.body.spec.camera_height])
        if eye.may_see(xy, o) and eye.rays_meet(cam, o):
            target = np.asarray(o.position, float)
            self.gaze = _exact_gaze(grid, pose, xy, target, eye.body.spec, tm, 0.0, route())

    def read(self, eye: OracleEye, o: ObjectInstance, now: float, until: float) -> bool:
        """Render the aimed image (once) and read it (``OracleEye.first_success`` by ``until``:
        a later call's limit is never larger, so a second found after it is never taken);
        returns ``worth``."""
        if self.worth is None:
            assert self.gaze is not None
            frame = eye.frame_at(self.gaze.pose)
            self.worth = eye.worth(eye.probability(frame, PERSPECTIVE_GAIN, o))
            if self.worth:
                self.hit = eye.first_success(frame, now + self.gaze.cost, until)
        return self.worth


def oracle_view(
    eye: OracleEye,
    grid: OccupancyGrid,
    pose: RobotPose,
    now: float,
    tm: TimeModel,
    *,
    deadline_s: float = math.inf,
    exclude: set[tuple] | frozenset[tuple] = frozenset(),
    soonest: bool = True,
) -> OracleView | None:
    """The soonest view from ``pose`` (at the body's simulated second ``now``) whose image the
    detector reads as a true target instance, within ``deadline_s`` seconds (see the comment
    above); None if no candidate view does (or ``ORACLE_MAX_RENDERS`` renders found none).
    ``soonest`` False: the first such view in the order of the lower bounds instead, which is
    None exactly when the soonest is (both look at the same views, in the same order, until the
    first that ends the search) at a fraction of the images (7-24 instead of 30-190 in office
    rooms): whether the target can be found in time, not when."""
    if not eye.instances:
        return None
    pos, pairs = _oracle_candidates(eye, grid, pose, tm)
    best: OracleView | None = None
    # ``checked`` counts every aimed view met as rendered (``_Aimed``): the cap, the count a
    # plan reports and every choice are those of rendering each when met
    aimed: dict[tuple[int, int], _Aimed] = {}
    route = functools.cache(lambda i: _path_to(grid, pose, pos[i]))  # position -> its Route
    checked = 0
    for lb, i, j, v in pairs:
        limit = deadline_s if best is None else min(deadline_s, best.seconds - 1e-9)
        if lb > limit + 1e-9:
            break
        o = eye.instances[j]
        key = (round(float(pos[i, 0]), 3), round(float(pos[i, 1]), 3), o.id, v)
        if key in exclude or checked >= ORACLE_MAX_RENDERS:
            continue
        if (i, j) not in aimed:
            aimed[i, j] = _Aimed(eye, grid, pose, pos[i], o, tm, functools.partial(route, i))
            checked += aimed[i, j].gaze is not None
        a = aimed[i, j]
        if a.gaze is None:
            continue
        if v == 0:
            g = a.gaze
        elif a.worth is False:
            continue
        else:
            target, spec = np.asarray(o.position, float), eye.body.spec
            g = _exact_gaze(grid, pose, pos[i], target, spec, tm, ORACLE_VIEWS[v], route(i))
        if g.cost > limit + 1e-9 or not a.read(eye, o, now, now + limit):
            continue
        if v == 0:
            hit = a.hit
        else:
            checked += 1
            hit = eye.first_success(eye.frame_at(g.pose), now + g.cost, now + limit)
        if hit is not None and hit - now < limit + 1e-9:
            best = OracleView(hit - now, g, o.id, checked, key)
            if not soonest:
                break
    return best


class Oracle(SearchPolicy):
    """Knows where the target's instances are, and what the detector in use will report from any
    pose at any simulated second, and goes straight to the pose that detects one soonest: the
    lower bound (``oracle_view``). There it renders what the camera will show from where the
    drive actually ended (a physical drive ends a little off the planned pose) and takes images
    while the detector's draws there end the search soonest (``OracleEye.first_success``); if
    they do not, it plans again from where it stands, without the views it tried; exhaustive
    coverage when no view is left. ``eye`` reads the true layout through the episode's world
    (the runner builds it), ``grid`` is the true layout's."""

    def __init__(self, name: str, eye: OracleEye, grid: OccupancyGrid):
        super().__init__(name)
        self.eye, self.grid = eye, grid

    def search(self, ctx: SearchContext) -> None:
        eye, grid = self.eye, self.grid
        ic = ctx.time_model.image_cost
        tried: set[tuple] = set()
        view = ctx.episode.first_view if ctx.elapsed == 0.0 and not ctx.trace else None
        while True:
            ctx.check()
            if view is None or tried:
                view = oracle_view(
                    eye,
                    grid,
                    ctx.body.pose(),
                    ctx.elapsed,  # the detector's stream runs on the episode's seconds
                    ctx.time_model,
                    deadline_s=ctx.episode.budget_s - ctx.elapsed,
                    exclude=tried,
                )
            if view is None:
                break
            tried.add(view.key)
            ctx.note(
                f"go and see {ctx.target} #{view.instance_id} (~{view.seconds:.1f} s, "
                f"{view.renders} views checked)"
            )
            ctx.face(view.gaze)
            frame = eye.frame_at(ctx.body.pose())  # the image the camera will take here
            if eye.first_success(frame, ctx.elapsed + ic, ctx.episode.budget_s) is None:
                continue  # the pose reached does not show it soon enough: plan again
            for _ in range(ORACLE_IMAGES):
                ctx.capture(f"oracle {ctx.target} #{view.instance_id}")  # stops when found
        ctx.note("no view left that detects the target; falling back to exhaustive coverage")
        cover(ctx)
