"""Autonomous acquisition of spatial context: Figure 2 of the paper on the simulated robot.

``learn`` runs procedure learn-spatial-contexts over a sequence of rooms; the knowledge (the
evidence store and the knowledge base derived from it) carries over from room to room. In one
room, faithfully to Figure 2:

- lines 1-2: UNEXAMINED := EXAMINED := {} (objects are the room's instances, by id);
- lines 4-7: when UNEXAMINED is empty, use the camera to find a nearby recognizable object not in
  EXAMINED (``Explorer``: look around at the current spot with a pan sweep, then drive to the next
  viewpoint of a deterministic tour of the room's free space and look around there); the room is
  done when the tour is over and nothing unexamined was seen;
- lines 8-13: the strategy picks a type among the UNEXAMINED types, the object is the nearest of
  that type (``agent.strategies``);
- line 14-16: examine it: its relation volumes (knowledge.geometry.relation_volume for every
  relation of its type) are grouped into few boxes, the view planner plans gazes that cover them,
  the robot executes them (drive, head, image), the detector reports what it sees, and
  RELATED-OBJECTS / RELATED-TYPES follow from knowledge.geometry.related on the detected poses
  (the examined object's own pose is the reference); an object no reachable viewpoint can see
  into is marked examined without counting as a trial;
- lines 17-20: one transaction in the evidence store and the same counts in the knowledge base
  (intervals are derived from counts on demand, see DESIGN.md);
- line 21: UNEXAMINED := (UNEXAMINED + RELATED-OBJECTS) - EXAMINED.

Perception modes share this loop and the time model. ``camera`` renders segmentation in MuJoCo
(envs.world) and runs the detector; ``oracle`` reads relations from the true layout and decides
what a look-around recognizes geometrically (type's max_range, inside the frustum, clear line of
sight past furniture boxes), without rendering. Both charge the same ``TimeModel`` seconds for the
same planned drives, head moves and images, so simulated time is comparable.

Limited time (``room_budget_s``). The paper's robot "will not have an infinite amount of time to
learn": with a budget of B simulated seconds per room, the robot leaves a room as soon as B
seconds have passed since it entered, whatever is left unexamined. What is in flight is
completed: an examination, or one exploration step (a drive to the next viewpoint, a six-image
look-around), so a room takes at most B plus one of those; nothing new starts once B is
spent. Without a budget (None, the default) every room is run to completion as in Figure 2, and
every strategy examines the same objects per room in another order. The budget is part of the run's identity: runs with another
budget are separate runs in the same store.

Runs, rooms and resume. A run is identified by (strategy, perception, seed, room budget); room
i's seed is derived from (seed, i). Rooms marked done in the store are skipped; the run clock
goes on from the end time the store recorded for them (stores written before end times were
recorded: from their last examination). A room in progress is *replayed* from its start: the
knowledge base as it was before the room, the same rng, the same motions, the same budget
checks; the examinations already in the store are not perceived again but read back (and checked
against the choices), so a resumed run makes exactly the choices of an uninterrupted one. Every
examination is one store transaction: Ctrl-C or a kill loses at most the one in flight.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agent import strategies as strat
from agent.navigation import OccupancyGrid, nearest_free, plan_path
from agent.strategies import Choice, Strategy
from envs.layout import RoomLayout
from envs.robot_spec import RobotPose, RobotSpec, TimeModel, wrap_angle
from envs.rooms import door_entry
from knowledge import geometry
from knowledge.base import KnowledgeBase
from knowledge.catalog import Catalog
from knowledge.errors import CtxsearchError
from knowledge.geometry import Box, ObjectInstance

PERCEPTION_MODES = ("camera", "oracle")
# Examination gazes prefer the open side of a relation volume (agent.viewplan.facing_for) when
# True. Off: measured on 2 x 3 office rooms in camera mode (results/learning_budget/facing.md),
# it found no more related pairs (recall 0.994 -> 0.994 and 0.992 -> 0.986 of the oracle's) and
# took about as long or longer per examination.
EXAMINE_FACING = False
ROOM_DONE = "done"
ROOM_STARTED = "started"


# =========================================================================== seeds and run ids
def room_seed(seed: int, index: int) -> int:
    """The seed of room ``index`` of a run started with ``seed`` (deterministic, spread out)."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1)[0] & 0x7FFFFFFF)


def room_rng(seed: int, index: int) -> np.random.Generator:
    """The strategy's rng for room ``index`` (fresh per room, so a replayed room draws the same)."""
    return np.random.default_rng([int(seed), int(index), 0x51])


def run_id(strategy: str, perception: str, seed: int, room_budget_s: float | None = None) -> str:
    """The store's run key: runs with another strategy, perception, seed or room budget are
    separate runs (no budget: the key has no budget part)."""
    key = f"{strategy}/{perception}/seed={int(seed)}"
    return key if room_budget_s is None else f"{key}/budget={float(room_budget_s)!r}s"


# =========================================================================== the oracle's body
class KinematicBody:
    """The robot without physics or rendering: a pose and a clock charged by the TimeModel.

    Same interface as envs.world.World where the loop uses it (``sim_time``, ``pose``,
    ``reset_pose``, ``drive``, ``move_head``, ``capture``, ``spec``), so agent.viewplan's
    ``execute_gaze`` charges the oracle exactly what it charges the camera mode.
    """

    def __init__(self, spec: RobotSpec | None = None, time_model: TimeModel | None = None):
        self.spec = spec or RobotSpec()
        self.time_model = time_model or TimeModel()
        self.sim_time = 0.0
        self._pose = RobotPose(0.0, 0.0, 0.0)

    def reset_pose(self, pose: RobotPose) -> None:
        """Put the robot at ``pose`` (no time charged)."""
        pan, tilt = self.spec.clip_head(pose.pan, pose.tilt)
        self._pose = RobotPose(float(pose.x), float(pose.y), float(pose.yaw), pan, tilt)

    def pose(self) -> RobotPose:
        """The current base pose and head angles."""
        return self._pose

    def drive(self, path: np.ndarray, final_yaw: float) -> float:
        """Follow ``path`` (K, 2) and turn to ``final_yaw``; the seconds it took."""
        p = self._pose
        path = np.asarray(path, float).reshape(-1, 2)
        dt = self.time_model.drive_time(path, p.yaw, final_yaw)
        end = path[-1] if len(path) else p.xy
        self._pose = RobotPose(float(end[0]), float(end[1]), wrap_angle(final_yaw), p.pan, p.tilt)
        self.sim_time += dt
        return dt

    def move_head(self, pan: float, tilt: float) -> float:
        """Slew the head to (pan, tilt), clipped to the limits; the seconds it took."""
        p = self._pose
        pan, tilt = self.spec.clip_head(pan, tilt)
        dt = self.time_model.head_time(p.pan, p.tilt, pan, tilt)
        self._pose = RobotPose(p.x, p.y, p.yaw, pan, tilt)
        self.sim_time += dt
        return dt

    def capture(self, rgb: bool = False, depth: bool = True) -> None:
        """Charge one image; the oracle renders nothing."""
        self.sim_time += self.time_model.image_cost

    def close(self) -> None:
        """Nothing to release."""


# =========================================================================== perception modes
def _segment_hits_boxes(a: np.ndarray, b: np.ndarray, boxes: geometry.BoxArray) -> np.ndarray:
    """(M, K) bool: segment a[m] -> b[m] passes through box k (slab test in each box's frame)."""
    c, s = np.cos(boxes.yaws), np.sin(boxes.yaws)  # (K,)

    def local(p):  # (M, 3) -> (M, K, 3)
        d = p[:, None, :] - boxes.centers[None, :, :]
        return np.stack(
            [c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1], d[..., 2]], -1
        )

    pa, pb = local(a), local(b)
    v = pb - pa
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-boxes.halves[None] - pa) / v
        t2 = (boxes.halves[None] - pa) / v
    tmin = np.where(
        np.abs(v) < 1e-12,
        np.where(np.abs(pa) <= boxes.halves[None], -np.inf, np.inf),
        np.minimum(t1, t2),
    )
    tmax = np.where(
        np.abs(v) < 1e-12,
        np.where(np.abs(pa) <= boxes.halves[None], np.inf, -np.inf),
        np.maximum(t1, t2),
    )
    enter = np.maximum(tmin.max(-1), 0.0)
    leave = np.minimum(tmax.min(-1), 1.0)
    return enter < leave - 1e-6


class OraclePerception:
    """Relations from the true layout; recognition from geometry. No rendering."""

    name = "oracle"
    reads_truth = True

    def __init__(
        self,
        layout: RoomLayout,
        catalog: Catalog,
        spec: RobotSpec,
        time_model: TimeModel,
        width: int = 320,
        height: int = 240,
    ):
        self.layout, self.catalog, self.spec = layout, catalog, spec
        self.body = KinematicBody(spec, time_model)
        self.width, self.height = width, height
        objs = layout.objects
        self._objs = list(objs)
        self._centers = np.array([o.position for o in objs], float).reshape(-1, 3)
        self._half = np.array([o.size for o in objs], float).reshape(-1, 3) / 2
        self._range = np.array([catalog.type(o.type).max_range for o in objs], float)
        # Occluders: furniture-sized boxes (anything with a side over 30 cm).
        self._occ_idx = np.flatnonzero(self._half.max(1) > 0.15) if len(objs) else np.zeros(0, int)
        self._occ = geometry.BoxArray.from_instances([objs[i] for i in self._occ_idx])
        self._tan_y = math.tan(math.radians(spec.fovy_deg) / 2)
        self._tan_x = self._tan_y * width / height
        self._radius = np.linalg.norm(self._half, axis=1)
        self._vis_cache: dict[tuple[float, float], np.ndarray] = {}
        if len(objs):
            self._sight = self._sight_points()
            flat = self._sight.reshape(-1, 3)
            self._sight_inside = _points_in_boxes(flat, self._occ).reshape(
                self._sight.shape[0], len(objs), len(self._occ)
            )

    def see(self, frame: Any) -> list[ObjectInstance]:
        """The objects a look from the current pose recognizes: within the type's max_range,
        inside the frustum, and with a clear line of sight (to the centre, the top or a top
        corner) past the furniture boxes that do not contain it."""
        if not self._objs:
            return []
        p = self.body.pose()
        cam = np.array([p.x, p.y, self.spec.camera_height])
        heading, tilt = p.yaw + p.pan, p.tilt
        ch, sh, ct, st = math.cos(heading), math.sin(heading), math.cos(tilt), math.sin(tilt)
        fwd = np.array([ct * ch, ct * sh, st])
        right = np.array([sh, -ch, 0.0])
        up = np.array([-st * ch, -st * sh, ct])
        rel = self._centers - cam
        z, x, y = rel @ fwd, rel @ right, rel @ up
        rad = self._radius  # bounding-sphere radius: any part in view
        ok = self._visible_from(p.x, p.y).copy()
        ok &= z > -rad
        ok &= np.abs(x) <= z * self._tan_x + rad * math.sqrt(1 + self._tan_x**2)
        ok &= np.abs(y) <= z * self._tan_y + rad * math.sqrt(1 + self._tan_y**2)
        return [self._objs[i] for i in np.flatnonzero(ok)]

    def _visible_from(self, x: float, y: float) -> np.ndarray:
        """(N,) bool: in range and in clear line of sight from the camera above (x, y); it does
        not depend on where the head points, so it is computed once per position."""
        key = (round(x, 6), round(y, 6))
        vis = self._vis_cache.get(key)
        if vis is not None:
            return vis
        cam = np.array([x, y, self.spec.camera_height])
        vis = np.linalg.norm(self._centers - cam, axis=1) <= self._range
        idx = np.flatnonzero(vis)
        if len(idx) and len(self._occ):
            pts = self._sight[:, idx, :]  # (S, M, 3)
            S, M = pts.shape[:2]
            ends = pts.reshape(-1, 3)
            hits = _segment_hits_boxes(np.repeat(cam[None], len(ends), 0), ends, self._occ)
            # A box holding the end point (the object itself, the desk a chair is under) does
            # not hide it.
            blocked = (hits & ~self._sight_inside[:, idx, :].reshape(-1, len(self._occ))).any(1)
            vis[idx] = (~blocked.reshape(S, M)).any(0)
        if len(self._vis_cache) > 256:
            self._vis_cache.clear()
        self._vis_cache[key] = vis
        return vis

    def _sight_points(self) -> np.ndarray:
        """(6, N, 3): points of every object a line of sight may reach: its centre, the centre of
        its top face and (just inside) the four corners of its top face."""
        c, h = self._centers, self._half
        yaw = np.array([o.yaw for o in self._objs])
        cy, sy = np.cos(yaw), np.sin(yaw)
        pts = [c, c + np.column_stack([0 * cy, 0 * cy, h[:, 2]])]
        for sx, sy_ in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
            lx, ly = sx * h[:, 0] * 0.9, sy_ * h[:, 1] * 0.9
            pts.append(c + np.column_stack([cy * lx - sy * ly, sy * lx + cy * ly, h[:, 2]]))
        return np.stack(pts)

    def related(
        self, obj: ObjectInstance, seen: Sequence[ObjectInstance]
    ) -> list[tuple[str, ObjectInstance]]:
        """RELATED-OBJECTS/-TYPES read from the true layout."""
        return geometry.related(self.catalog, obj, self._objs)

    def close(self) -> None:
        """Nothing to release."""


def _points_in_boxes(pts: np.ndarray, boxes: geometry.BoxArray) -> np.ndarray:
    """(M, K) bool: point m inside box k (boundary included)."""
    d = pts[:, None, :] - boxes.centers[None, :, :]
    c, s = np.cos(boxes.yaws), np.sin(boxes.yaws)
    lx = c * d[..., 0] + s * d[..., 1]
    ly = -s * d[..., 0] + c * d[..., 1]
    h = boxes.halves
    return (
        (np.abs(lx) <= h[:, 0] + 1e-9)
        & (np.abs(ly) <= h[:, 1] + 1e-9)
        & (np.abs(d[..., 2]) <= h[:, 2] + 1e-9)
    )


class CameraPerception:
    """Rendered segmentation in MuJoCo and the detector (agent.perception)."""

    name = "camera"
    reads_truth = False

    def __init__(
        self,
        layout: RoomLayout,
        catalog: Catalog,
        spec: RobotSpec,
        time_model: TimeModel,
        width: int = 320,
        height: int = 240,
        rgb: bool = False,
    ):
        from agent.perception import objects_by_id
        from envs.world import World

        self.layout, self.catalog, self.spec, self.rgb = layout, catalog, spec, rgb
        self.body = World(layout, catalog, width=width, height=height)
        self._objects = objects_by_id(layout)

    def see(self, frame: Any) -> list[ObjectInstance]:
        """The detector's objects (poses read from the simulator) in a captured frame."""
        from agent.perception import detect

        self.last_detections = detect(frame, self._objects, self.catalog)
        return [d.pose for d in self.last_detections]

    def related(
        self, obj: ObjectInstance, seen: Sequence[ObjectInstance]
    ) -> list[tuple[str, ObjectInstance]]:
        """RELATED-OBJECTS/-TYPES from the detected poses."""
        return geometry.related(self.catalog, obj, seen)

    def close(self) -> None:
        """Release the renderer."""
        self.body.close()


def make_perception(
    mode: str,
    layout: RoomLayout,
    catalog: Catalog,
    spec: RobotSpec,
    time_model: TimeModel,
    rgb: bool = False,
):
    """A perception mode by name ('camera' or 'oracle')."""
    if mode == "oracle":
        return OraclePerception(layout, catalog, spec, time_model)
    if mode == "camera":
        return CameraPerception(layout, catalog, spec, time_model, rgb=rgb)
    raise CtxsearchError(f"unknown perception mode '{mode}' (known: {', '.join(PERCEPTION_MODES)})")


# =========================================================================== costs on the grid
class GridCosts:
    """Travel and examination seconds estimated on the occupancy grid (for the strategies).

    Travel: the driving distance along the grid from the robot to the nearest free cell within
    ``standoff`` of the object's footprint (where the view planner will put the base), over the
    drive speed. Examination: travel plus the head moves and images of the gazes planned for the
    object (from where the object was first a candidate; cached per object).
    """

    def __init__(
        self,
        grid: OccupancyGrid,
        time_model: TimeModel,
        gaze_seconds: Callable[[ObjectInstance], float],
        standoff: float = 1.0,
    ):
        self.grid, self.tm, self.standoff = grid, time_model, standoff
        self._gaze_seconds = gaze_seconds
        self._approach: dict[int, np.ndarray] = {}
        self._pose: RobotPose | None = None
        self._field: np.ndarray | None = None
        xs, ys = grid.cell_centers()
        self._cells = np.column_stack([np.tile(xs, len(ys)), np.repeat(ys, len(xs))])
        self._free_flat = grid.free.ravel()

    def at(self, pose: RobotPose) -> GridCosts:
        """Estimates from ``pose`` (the distance field is computed lazily, once per pose)."""
        if self._pose is None or (pose.x, pose.y) != (self._pose.x, self._pose.y):
            self._field = None
        self._pose = pose
        return self

    def _approach_cells(self, obj: ObjectInstance) -> np.ndarray:
        """Flat indices of the free cells within ``standoff`` of the object's footprint (within
        2.5 m if there are none); cached per object."""
        cells = self._approach.get(obj.id)
        if cells is None:
            box = obj.box()
            cells = self._cells_near(box, self.standoff)
            if not len(cells):
                cells = self._cells_near(box, 2.5)
            self._approach[obj.id] = cells
        return cells

    def _cells_near(self, box: Box, reach: float) -> np.ndarray:
        g = self.grid
        h, w = g.shape
        r = float(np.hypot(box.half[0], box.half[1])) + reach
        r0, c0 = g.to_cell(box.center[:2] - r)  # (row, col) of the window's corners
        r1, c1 = g.to_cell(box.center[:2] + r)
        r0, c0, r1, c1 = max(0, r0), max(0, c0), min(h - 1, r1), min(w - 1, c1)
        rows, cols = np.mgrid[r0 : r1 + 1, c0 : c1 + 1]
        flat = (rows * w + cols).ravel()
        d = self._cells[flat] - box.center[:2]
        c, s = math.cos(box.yaw), math.sin(box.yaw)
        lx = np.abs(c * d[:, 0] + s * d[:, 1]) - box.half[0]
        ly = np.abs(-s * d[:, 0] + c * d[:, 1]) - box.half[1]
        dist = np.hypot(np.maximum(lx, 0), np.maximum(ly, 0))
        return flat[self._free_flat[flat] & (dist <= reach)]

    def travel_s(self, obj: ObjectInstance) -> float:
        """Seconds to drive to where ``obj`` is examined from."""
        if self._field is None:
            self._field = self.grid.distances_from(self._pose.xy).ravel()
        cells = self._approach_cells(obj)
        dist = float(self._field[cells].min()) if len(cells) else math.inf
        if not math.isfinite(dist):  # unreachable: the straight line, as a fallback
            dist = math.hypot(obj.position[0] - self._pose.x, obj.position[1] - self._pose.y)
        return dist / self.tm.drive_speed

    def examine_s(self, obj: ObjectInstance) -> float:
        """travel_s plus the planned gazes' head moves and images."""
        return self.travel_s(obj) + self._gaze_seconds(obj)


# =========================================================================== examination volumes
def group_volumes(boxes: Sequence[Box], slack: float = 2.0) -> list[Box]:
    """Merge relation volumes that share a frame (all volumes of one object share its yaw) into
    few boxes: two groups merge when their joint bounding box is at most ``slack`` times the sum
    of their volumes (a volume inside another always merges). Greedy, deterministic."""
    return [box for box, _ in group_volume_members(boxes, slack)]


def group_volume_members(boxes: Sequence[Box], slack: float = 2.0) -> list[tuple[Box, list[int]]]:
    """``group_volumes`` with, for every group, the indices of the input boxes merged into it."""
    if not boxes:
        return []
    yaw = float(boxes[0].yaw)
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s], [s, c]])
    origin = np.asarray(boxes[0].center, float)

    def to_local(b: Box) -> tuple[np.ndarray, np.ndarray]:
        d = np.asarray(b.center, float) - origin
        lc = np.array([*(rot.T @ d[:2]), d[2]])
        if abs(wrap_angle(float(b.yaw) - yaw)) > 1e-9:
            raise ValueError("group_volumes needs boxes sharing one yaw")
        return lc - b.half, lc + b.half

    # (lo, hi, summed volume, members)
    groups = [(*to_local(b), float(np.prod(2 * b.half)), [i]) for i, b in enumerate(boxes)]
    merged = True
    while merged and len(groups) > 1:
        merged = False
        best = None
        for i in range(len(groups)):
            for j in range(i + 1, len(groups)):
                lo = np.minimum(groups[i][0], groups[j][0])
                hi = np.maximum(groups[i][1], groups[j][1])
                joint = float(np.prod(hi - lo))
                ratio = joint / max(groups[i][2] + groups[j][2], 1e-12)
                big = max(
                    float(np.prod(groups[i][1] - groups[i][0])),
                    float(np.prod(groups[j][1] - groups[j][0])),
                )
                if (joint <= big * (1 + 1e-9) or ratio <= slack) and (
                    best is None or ratio < best[0]
                ):
                    best = (ratio, i, j, lo, hi)
        if best is not None:
            _, i, j, lo, hi = best
            vol = groups[i][2] + groups[j][2]
            members = sorted(groups[i][3] + groups[j][3])
            groups = [g for k, g in enumerate(groups) if k not in (i, j)] + [(lo, hi, vol, members)]
            merged = True
    out = []
    for lo, hi, _, members in groups:
        lc = (lo + hi) / 2
        center = np.array([*(origin[:2] + rot @ lc[:2]), origin[2] + lc[2]])
        out.append((Box(center, yaw, (hi - lo) / 2), members))
    return out


def group_facing(directions: Sequence[np.ndarray | None], max_angle_deg: float = 60.0):
    """The open side of a group of relation volumes (agent.viewplan.facing_for of each member):
    None when no member has one (any side will do) or when the members' sides disagree (more than
    ``max_angle_deg`` from their mean); otherwise the unit mean of the members that have one
    (members open on every side do not constrain it)."""
    dirs = [np.asarray(d, float)[:2] for d in directions if d is not None]
    if not dirs:
        return None
    mean = np.sum(dirs, axis=0)
    norm = float(np.linalg.norm(mean))
    if norm < 1e-9:
        return None
    mean = mean / norm
    cos_max = math.cos(math.radians(max_angle_deg))
    if any(float(d @ mean) / max(float(np.linalg.norm(d)), 1e-12) < cos_max for d in dirs):
        return None
    return mean


def relation_boxes(catalog: Catalog, obj: ObjectInstance) -> list[Box]:
    """v_rel(obj) for every rel in RELATIONS(type(obj)), in catalog order."""
    return [geometry.relation_volume(rel, obj) for rel in catalog.type(obj.type).relations]


# =========================================================================== exploration
LOOK_TILT = -0.35  # rad: the look-around tilt (sees the floor from about 1 m out and desk tops)
LOOK_PANS_DEG = (-150.0, -90.0, -30.0, 30.0, 90.0, 150.0)  # a 360 degree sweep in six images


class Explorer:
    """Figure 2, line 5: find a nearby recognizable object not yet examined.

    Remembers every object its look-arounds recognized. Asked for an object, it returns the
    nearest remembered one not in EXAMINED; failing that it looks around at the current spot
    (unless it already looked within ``spacing / 2``), then drives to the nearest unvisited
    viewpoint of a tour (a ``spacing`` lattice over the reachable free space) and looks there,
    until it has one or the tour is over (None: the room is done).
    """

    def __init__(self, learner: RoomLearner, spacing: float = 1.5):
        self.L = learner
        self.spacing = spacing
        self.seen: dict[int, ObjectInstance] = {}
        self.looks: list[np.ndarray] = []
        grid = learner.grid
        reach = grid.reachable_mask(learner.start_pose.xy)
        xs, ys = grid.cell_centers()
        pts = []
        for y in np.arange(ys[0] + spacing / 2, ys[-1] + 1e-9, spacing):
            for x in np.arange(xs[0] + spacing / 2, xs[-1] + 1e-9, spacing):
                p = nearest_free(grid, np.array([x, y]), reach)
                if p is not None and np.hypot(*(p - (x, y))) <= spacing / 2:
                    pts.append(p)
        # deduplicate (two lattice points may snap to one cell)
        uniq: list[np.ndarray] = []
        for p in pts:
            if all(np.hypot(*(p - q)) > 1e-6 for q in uniq):
                uniq.append(p)
        self.todo = uniq

    def find(self, examined: set[int]) -> ObjectInstance | None:
        """A recognizable object not in ``examined`` (the nearest known), or None."""
        L = self.L
        while True:
            cands = [o for oid, o in sorted(self.seen.items()) if oid not in examined]
            if cands:
                return strat.nearest_object(cands, L.costs.at(L.body.pose()))
            if L.budget_spent():  # no new exploration step once the room's time is spent
                L.left_early = True
                return None
            here = L.body.pose().xy
            if not any(np.hypot(*(here - q)) <= self.spacing / 2 for q in self.looks):
                self.look_around()
                continue
            if not self.todo:
                return None
            field = L.grid.distances_from(here)
            d = [field[L.grid.to_cell(p)] for p in self.todo]
            k = int(np.argmin(d))
            if not math.isfinite(d[k]):
                self.todo = []
                return None
            goal = self.todo.pop(k)
            L.drive_to(goal)
            if L.budget_spent():
                L.left_early = True
                return None
            self.look_around()

    def look_around(self) -> None:
        """A pan sweep at the current spot: six images, everything recognized is remembered."""
        L = self.L
        p = L.body.pose()
        self.looks.append(p.xy)
        self.todo = [q for q in self.todo if np.hypot(*(q - p.xy)) > self.spacing / 2]
        pans = [math.radians(a) for a in LOOK_PANS_DEG]
        if abs(p.pan - pans[-1]) < abs(p.pan - pans[0]):
            pans = pans[::-1]
        for pan in pans:
            L.body.move_head(pan, LOOK_TILT)
            frame = L.body.capture(rgb=L.log.wants_rgb, depth=True)
            objs = L.perception.see(frame)
            for o in objs:
                self.seen.setdefault(o.id, o)
            L.log.frame(L, frame, objs, purpose="look")


# =========================================================================== one room
@dataclass(frozen=True)
class StoredExam:
    """An examination read back from the store: the object, its type and the related rows."""

    object_id: int
    ref_type: str
    related: tuple[tuple[str, str, int], ...]  # (relation, type, related object id)
    sim_time: float = 0.0


@dataclass(frozen=True)
class ExamResult:
    """One examination as the loop made it (what callbacks and the recorder get)."""

    index: int  # examinations so far in this run, this one included
    room_index: int
    room_seed: int
    choice: Choice
    related: tuple[tuple[str, ObjectInstance], ...]
    gazes: int
    sim_time: float  # run clock after the examination
    replayed: bool = False

    @property
    def pairs(self) -> set[tuple[str, str]]:
        """RELATED-TYPES: the distinct (relation, type) pairs."""
        return {(r, o.type) for r, o in self.related}


class RoomLearner:
    """Figure 2 in one room (see the module docstring)."""

    def __init__(
        self, run: Run, layout: RoomLayout, room_index: int, prior: Sequence[StoredExam] = ()
    ):
        self.run, self.layout, self.room_index = run, layout, room_index
        self.catalog, self.kb, self.log = run.catalog, run.kb, run.log
        self.spec, self.tm = run.spec, run.time_model
        self.prior = list(prior)
        self.grid = OccupancyGrid.from_layout(layout, self.spec)
        self.start_pose = start_pose(layout, self.grid)
        self.perception = make_perception(
            run.perception, layout, self.catalog, self.spec, self.tm, rgb=self.log.wants_rgb
        )
        self.body = self.perception.body
        self.body.reset_pose(self.start_pose)
        self._t0 = self.body.sim_time
        self.rng = room_rng(run.seed, room_index)
        self._gaze_s: dict[int, float] = {}
        self.costs = GridCosts(self.grid, self.tm, self._gaze_seconds)
        self.explorer = Explorer(self)
        self.examined: set[int] = set()
        self.unexamined: dict[int, ObjectInstance] = {}
        self.last_exam_clock = self.clock  # the run clock after the room's last examination
        self.new_since = self.clock  # the run clock when the replay (if any) was over
        self.budget_s = run.room_budget_s
        self.left_early = False  # the budget ended the room (objects may be left unexamined)

    # ---- time and motion ------------------------------------------------------------------
    @property
    def clock(self) -> float:
        """The run clock: seconds before this room plus the room's own."""
        return self.run.clock_offset + (self.body.sim_time - self._t0)

    @property
    def room_elapsed(self) -> float:
        """Simulated seconds since the robot entered this room."""
        return self.body.sim_time - self._t0

    def budget_spent(self) -> bool:
        """True once the room's time budget (if any) is used up."""
        return self.budget_s is not None and self.room_elapsed >= self.budget_s

    def drive_to(self, xy: np.ndarray) -> None:
        """Drive along a planned path to ``xy``, facing along the last segment."""
        p = self.body.pose()
        path = plan_path(self.grid, p.xy, xy)
        if path is None or len(path) < 2:
            return
        seg = path[-1] - path[-2]
        self.body.drive(path, math.atan2(seg[1], seg[0]))
        self.log.robot(self)

    # ---- examination -------------------------------------------------------------------------
    def plan_examination(self, obj: ObjectInstance, start: RobotPose):
        """The gazes (agent.viewplan) that cover the object's relation volumes, group by group."""
        from agent.viewplan import facing_for, plan_gazes

        rels = self.catalog.type(obj.type).relations
        gazes = []
        pose = start
        for box, members in group_volume_members(relation_boxes(self.catalog, obj)):
            facing = (
                group_facing([facing_for(rels[i], obj) for i in members])
                if EXAMINE_FACING
                else None
            )
            gs = plan_gazes(self.grid, box, pose, self.spec, self.tm, facing=facing)
            gazes.extend(gs)
            if gs:
                pose = gs[-1].pose
        return gazes

    def _gaze_seconds(self, obj: ObjectInstance) -> float:
        """Head moves and images of the object's planned examination, without the first drive
        (cost-hif's estimate; planned once per object from where the robot was then)."""
        t = self._gaze_s.get(obj.id)
        if t is None:
            gazes = self.plan_examination(obj, self.body.pose())
            t = sum(g.cost for g in gazes[1:]) + (self.tm.image_cost if gazes else 0.0)
            self._gaze_s[obj.id] = t
        return t

    def examine(
        self, choice: Choice, stored: StoredExam | None, gazes: Sequence[Any]
    ) -> list[tuple[str, ObjectInstance]]:
        """Lines 15-16: execute the planned gazes, detect, decide the relations. With ``stored``
        (a replay) the motions are made, images are not taken, and the stored result is used."""
        from agent.viewplan import execute_gaze

        obj = choice.obj
        self.log.examine_start(self, obj, gazes)
        seen: dict[int, ObjectInstance] = {}
        replay = stored is not None
        need_images = not (replay or self.perception.reads_truth) or self.log.wants_frames
        for gaze in gazes:
            if replay:
                execute_gaze(_NoCapture(self.body), self.grid, gaze)
                continue
            frame = execute_gaze(self.body, self.grid, gaze, rgb=self.log.wants_rgb, depth=True)
            self.log.robot(self)
            if need_images:
                objs = self.perception.see(frame)
                seen.update((o.id, o) for o in objs)
                self.log.frame(self, frame, objs, purpose="examine")
        if replay:
            by_id = {o.id: o for o in self.layout.objects}
            related = [(rel, by_id[i]) for rel, _t, i in stored.related]
        else:
            related = self.perception.related(obj, list(seen.values()))
        return related

    # ---- Figure 2 ----------------------------------------------------------------------------
    def run_room(self) -> Iterator[ExamResult]:
        """Lines 3-21 until the room is done or its time budget is spent; yields every
        examination."""
        n_room = 0
        while True:
            if self.budget_spent():  # limited time: leave the room
                self.left_early = True
                break
            if not self.unexamined:  # lines 4-7
                obj = self.explorer.find(self.examined)
                if obj is None:
                    break
                self.unexamined[obj.id] = obj
            pose = self.body.pose()
            cands = [self.unexamined[i] for i in sorted(self.unexamined)]
            choice = strat.choose(
                self.run.strategy, self.kb, cands, pose, self.costs.at(pose), self.rng
            )
            stored = self.prior[n_room] if n_room < len(self.prior) else None
            if self.run.on_choice is not None:
                self.run.on_choice(self.kb, choice)
            self.log.choice(self, choice)
            del self.unexamined[choice.obj.id]  # line 14
            self.examined.add(choice.obj.id)
            gazes = self.plan_examination(choice.obj, self.body.pose())
            if not gazes:
                # No reachable viewpoint sees its relation volumes: not a trial, no evidence (so
                # nothing in the store either, and a replay skips it the same way).
                self.log.text(
                    self,
                    f"{choice.obj.type} #{choice.obj.id} cannot be examined: "
                    "no reachable viewpoint sees its relation volumes",
                )
                continue
            if stored is not None and stored.object_id != choice.obj.id:
                raise self._resume_error(
                    f"the store says object {stored.object_id} was examined next, the replay "
                    f"chose {choice.obj.id}"
                )
            related = self.examine(choice, stored, gazes)  # lines 15-16
            n_gazes = len(gazes)
            pairs = geometry.related_pairs(related)
            if stored is None:  # lines 17-20: one transaction, then the same counts in memory
                self.run.store.record(
                    run=self.run.run,
                    style=self.run.style,
                    room_seed=self.layout.seed,
                    object_id=choice.obj.id,
                    ref_type=choice.obj.type,
                    sim_time=self.clock,
                    strategy=self.run.strategy.name,
                    related=sorted({(r, o.type, o.id) for r, o in related}),
                )
            self.kb.record_examination(choice.obj.type, pairs)
            self.run.strategy.observe(choice.obj.type)
            for _, o in related:  # line 21
                if o.id not in self.examined:
                    self.unexamined.setdefault(o.id, o)
            if stored is not None and n_room == 0:
                # The run clock of a replayed room comes from the store: the room started when
                # its first examination was stored minus the time the replay took to get there.
                self.run.clock_offset += stored.sim_time - self.clock
            n_room += 1
            self.run.examinations += 1
            self.last_exam_clock = self.clock
            if n_room == len(self.prior):
                self.new_since = self.clock
            yield ExamResult(
                self.run.examinations,
                self.room_index,
                self.layout.seed,
                choice,
                tuple(related),
                n_gazes,
                self.clock,
                replayed=stored is not None,
            )
        if n_room < len(self.prior):
            raise self._resume_error(
                f"the store holds {len(self.prior)} examinations of it, the replay left it after "
                f"{n_room}"
            )

    def _resume_error(self, what: str) -> CtxsearchError:
        return CtxsearchError(
            f"cannot resume room seed {self.layout.seed}: {what} "
            "(store written by other code or settings?)"
        )

    def close(self) -> None:
        """Release the renderer (camera mode)."""
        self.perception.close()


class _NoCapture:
    """A body whose capture is a no-op apart from its time (replayed examinations)."""

    def __init__(self, body):
        self._b = body
        self.spec = body.spec

    def pose(self):
        return self._b.pose()

    def drive(self, path, yaw):
        return self._b.drive(path, yaw)

    def move_head(self, pan, tilt):
        return self._b.move_head(pan, tilt)

    def capture(self, rgb=False, depth=True):
        tm = getattr(self._b, "time_model", None) or TimeModel()
        if hasattr(self._b, "charge"):
            self._b.charge(tm.image_cost)
        else:
            self._b.sim_time += tm.image_cost


def start_pose(layout: RoomLayout, grid: OccupancyGrid) -> RobotPose:
    """Where the robot enters: the free cell nearest a point 0.6 m inside the door, facing into
    the room (in the largest free region if the door's side is cut off)."""
    x, y, yaw = door_entry(layout)
    labels = grid.labels
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    mask = labels == int(np.argmax(sizes)) if len(sizes) > 1 else None
    p = nearest_free(grid, np.array([x, y]), mask)
    if p is None:
        raise CtxsearchError(f"room {layout.style}/{layout.seed} has no free space for the robot")
    return RobotPose(float(p[0]), float(p[1]), yaw)


# =========================================================================== a run over rooms
@dataclass
class Summary:
    """What a ``learn`` call did and what the knowledge base holds at its end."""

    run: str
    rooms: int  # rooms of the run (done at the end, including rooms done before)
    rooms_done_now: int
    examinations: int  # made by this call (replayed ones not counted)
    total_examinations: int  # in the store
    types_seen: int  # types with n > 0
    mean_width: float
    wall_s: float
    sim_s: float  # simulated seconds of this call (replayed motions not counted)
    interrupted: bool = False
    files: list[Path] = field(default_factory=list)  # recordings written
    room_budget_s: float | None = None  # simulated seconds per room (None: no limit)
    rooms_left_early: int = 0  # rooms done now that the budget ended (objects left unexamined)

    @property
    def exams_per_wall_s(self) -> float:
        """Examinations per wall-clock second of this call."""
        return self.examinations / self.wall_s if self.wall_s > 0 else 0.0

    def lines(self) -> list[str]:
        """Human-readable summary lines."""
        return [
            f"run {self.run}: {self.rooms} rooms done ({self.rooms_done_now} in this call)",
            f"examinations: {self.examinations} now, {self.total_examinations} in the store",
            f"types seen: {self.types_seen}; mean interval width: {self.mean_width:.4f}",
            f"time: {self.wall_s:.1f} s wall, {self.sim_s:.1f} s simulated; "
            f"{self.exams_per_wall_s:.1f} examinations per wall second",
        ] + (
            [
                f"room budget: {self.room_budget_s:g} s simulated per room; the budget ended "
                f"{self.rooms_left_early} of the {self.rooms_done_now} rooms done in this call"
            ]
            if self.room_budget_s is not None
            else []
        )


@dataclass
class Run:
    """Run-level state shared by the rooms: knowledge, store, strategy, clock, logging."""

    catalog: Catalog
    kb: KnowledgeBase
    store: Any
    strategy: Strategy
    perception: str
    style: str
    seed: int
    run: str
    log: Any
    spec: RobotSpec = field(default_factory=RobotSpec)
    time_model: TimeModel = field(default_factory=TimeModel)
    clock_offset: float = 0.0  # the run clock when the current room started
    examinations: int = 0  # made in this run so far (replayed ones included)
    sim_new: float = 0.0  # simulated seconds of new (not replayed) work in this call
    room_budget_s: float | None = None  # simulated seconds per room (None: each to completion)
    on_choice: Callable[[KnowledgeBase, Choice], None] | None = None  # before each examination


# =========================================================================== recording
class RunLog:
    """What a run writes to rerun (agent.recording.Recorder), one recording per room.

    Per room: the room in 3D (labelled boxes), the robot's path and head (camera pose) over the
    run clock, the camera as a pinhole with its RGB and segmentation images for every gaze, the
    examined object's relation volumes highlighted, a text log of every choice with each
    candidate type's score, and time series of the mean interval width and of n per type.

    A recording holds one room (the Recorder's room entities are static), so a run of several
    rooms writes ``FILE.rrd`` for the first room of the call and ``FILE.room<i>.rrd`` for room i
    after it; ``rerun FILE*.rrd`` opens them together. Without a path nothing is recorded.
    """

    def __init__(self, path: str | Path | None):
        self.path = Path(path) if path is not None else None
        self.rec = None
        self.files: list[Path] = []
        self._step = 0

    @property
    def enabled(self) -> bool:
        """True while a recording is open."""
        return self.rec is not None

    @property
    def wants_rgb(self) -> bool:
        """Render RGB only when it is recorded."""
        return self.rec is not None

    @property
    def wants_frames(self) -> bool:
        """Look at every examination frame (oracle mode skips it unless recording)."""
        return self.rec is not None

    def start_room(self, L: RoomLearner) -> None:
        """Open the room's recording and log the room, its start and the knowledge so far."""
        if self.path is None:
            return
        from agent.recording import Recorder

        path = (
            self.path
            if not self.files
            else self.path.with_name(
                f"{self.path.stem}.room{L.room_index}{self.path.suffix or '.rrd'}"
            )
        )
        self.rec = Recorder(path)
        self.files.append(path)
        self.rec.set_time(L.clock, self._step)
        self.rec.log_room(L.layout, L.catalog)
        self.rec.log_text(
            f"room {L.room_index} (style {L.layout.style}, seed {L.layout.seed}): "
            f"{len(L.layout.objects)} objects; run {L.run.run}"
        )
        self.robot(L)
        self.knowledge(L)

    def end_room(self, L: RoomLearner, n_exams: int) -> None:
        """Close the room's recording."""
        if self.rec is None:
            return
        self.rec.set_time(L.clock, self._step)
        self.rec.log_text(
            f"room {L.room_index} done: {n_exams} examinations, "
            f"{L.clock - L.run.clock_offset:.1f} s simulated"
            + (" (time budget spent: leaving)" if L.left_early else "")
        )
        self.rec.close()
        self.rec = None

    def robot(self, L: RoomLearner) -> None:
        """The robot's base pose and path, and where the head points (camera pose)."""
        if self.rec is None:
            return
        from agent.viewplan import camera_at

        pose = L.body.pose()
        self.rec.set_time(L.clock, self._step)
        self.rec.log_robot(pose, L.spec)
        self.rec.log_camera(_Shot(camera_at(pose, L.spec)))

    def frame(
        self, L: RoomLearner, frame: Any, objs: Sequence[ObjectInstance], purpose: str
    ) -> None:
        """One image: the camera pinhole, RGB and segmentation (camera mode), detections."""
        if self.rec is None:
            return
        self.rec.set_time(L.clock, self._step)
        self.rec.log_robot(L.body.pose(), L.spec)
        if frame is None:  # oracle: the pose of the camera, no pixels
            from agent.viewplan import camera_at

            self.rec.log_camera(_Shot(camera_at(L.body.pose(), L.spec)))
        else:  # RGB and segmentation; depth is left out (it would double the file's size)
            shot = _Shot(frame.camera, rgb=frame.rgb, instance_ids=frame.instance_ids)
            self.rec.log_camera(shot, getattr(L.perception, "last_detections", ()))
        if purpose == "look" and objs:
            self.rec.log_text(
                "look-around recognizes " + ", ".join(f"{o.type} #{o.id}" for o in objs),
                level="DEBUG",
            )

    def choice(self, L: RoomLearner, choice: Choice) -> None:
        """The decision of lines 8-13 with every candidate type's score."""
        if self.rec is None:
            return
        self._step += 1
        self.rec.set_time(L.clock, self._step)
        ranked = sorted(choice.scores.items(), key=lambda kv: -kv[1])
        scores = ", ".join(f"{t} {s:.4f}" for t, s in ranked)
        n_unex = len(L.unexamined)
        self.rec.log_text(
            f"exam {L.run.examinations + 1}: {L.run.strategy.name} chooses {choice.type} "
            f"(object #{choice.obj.id}) among {n_unex} unexamined; scores: {scores}"
        )

    def examine_start(self, L: RoomLearner, obj: ObjectInstance, gazes: Sequence[Any]) -> None:
        """Highlight the examined object's relation volumes and show its planned gazes."""
        if self.rec is None:
            return
        rels = L.catalog.type(obj.type).relations
        self.rec.log_volumes(
            "world/volumes/examined",
            relation_boxes(L.catalog, obj),
            labels=[r.name for r in rels],
            color=(1.0, 0.85, 0.1),
        )
        self.rec.log_volumes(
            "world/volumes/examined_object",
            [obj.box()],
            labels=[f"examining {obj.type} #{obj.id}"],
            color=(1.0, 0.3, 0.1),
        )
        self.rec.log_text(
            f"examining {obj.type} #{obj.id}: {len(rels)} relation volumes, "
            f"{len(gazes)} gazes planned",
            level="DEBUG",
        )

    def examination(self, L: RoomLearner, res: ExamResult) -> None:
        """The examination's outcome and the knowledge's new state."""
        if self.rec is None:
            return
        self.rec.set_time(L.clock, self._step)
        found = ", ".join(f"{r}({o.type} #{o.id})" for r, o in res.related) or "nothing"
        self.rec.log_text(f"{res.choice.obj.type} #{res.choice.obj.id}: {found}")
        self.knowledge(L)

    def text(self, L: RoomLearner, msg: str) -> None:
        """A line in the text log."""
        if self.rec is None:
            return
        self.rec.set_time(L.clock, self._step)
        self.rec.log_text(msg, level="WARN")

    def knowledge(self, L: RoomLearner) -> None:
        """Time series: mean interval width and n per type."""
        if self.rec is None:
            return
        self.rec.log_scalar("knowledge/mean_width", L.kb.mean_width())
        for t in L.catalog.type_names:
            self.rec.log_scalar(f"knowledge/n/{t}", L.kb.n(t))

    def close(self) -> None:
        """Close an open recording (interrupted runs keep what was logged)."""
        if self.rec is not None:
            self.rec.close()
            self.rec = None


@dataclass(frozen=True)
class _Shot:
    """A frame without pixels: only the camera (the oracle's gazes, head moves)."""

    camera: Any
    rgb: Any = None
    depth: Any = None
    instance_ids: Any = None


# =========================================================================== learn
ExamCallback = Callable[[ExamResult, KnowledgeBase], None]
LayoutFn = Callable[[int, int], RoomLayout]  # (room index, room seed) -> layout


def style_layouts(style: str, catalog: Catalog) -> tuple[str, LayoutFn]:
    """The style's name and its room generator."""
    from envs.rooms import generate_room
    from envs.styles import load_style

    st = load_style(style, catalog)
    return st.name, lambda index, seed: generate_room(st, seed, catalog)


def learn(
    style: str,
    rooms: int,
    kb_path: str | Path,
    strategy: str = "hif",
    perception: str = "camera",
    alpha: float | None = None,
    seed: int = 0,
    record: str | Path | None = None,
    max_examinations: int | None = None,
    progress: bool = True,
    room_budget_s: float | None = None,
    *,
    catalog: Catalog | None = None,
    layouts: LayoutFn | None = None,
    on_examination: ExamCallback | None = None,
    on_choice: Callable[[KnowledgeBase, Choice], None] | None = None,
) -> Summary:
    """Run learn-spatial-contexts (Figure 2) over ``rooms`` rooms of ``style``.

    ``kb_path`` is the evidence store, created or resumed (see the module docstring); ``alpha``
    defaults to the store's. ``max_examinations`` stops the call after that many new
    examinations (run it again to go on). ``layouts`` replaces the room generator (tests);
    ``on_examination(result, kb)`` is called after every examination, replayed ones included,
    and ``on_choice(kb, choice)`` after every choice, before the examination (benchmarks).
    ``room_budget_s`` limits the simulated seconds spent in each room (see the module
    docstring; None: every room to completion, Figure 2 as published).
    Ctrl-C ends the call at once (the examination in flight is lost) with
    ``Summary.interrupted`` set.

    The run clock (``sim_time`` in the store) runs on from room to room. A room done in an
    earlier call resumes the clock from the end time the store recorded for it, a replayed room
    takes its clock from its stored examinations, so a resumed run's clock equals an
    uninterrupted one's. (Rooms done by a store of schema version 1, which has no end times,
    resume it from their last examination: their final exploration is missing from the clock.)
    """
    from knowledge.catalog import load_catalog
    from knowledge.store import EvidenceStore

    if rooms < 0:
        raise CtxsearchError(f"rooms must be >= 0, got {rooms}")
    if max_examinations is not None and max_examinations < 0:
        raise CtxsearchError(f"max_examinations must be >= 0, got {max_examinations}")
    if room_budget_s is not None:
        try:
            room_budget_s = float(room_budget_s)
        except (TypeError, ValueError):
            raise CtxsearchError(
                f"room budget must be a number of seconds, got {room_budget_s!r}"
            ) from None
        if not (math.isfinite(room_budget_s) and room_budget_s > 0):
            raise CtxsearchError(
                f"room budget must be a positive number of seconds, got {room_budget_s}"
            )
    if perception not in PERCEPTION_MODES:
        raise CtxsearchError(
            f"unknown perception mode '{perception}' (known: {', '.join(PERCEPTION_MODES)})"
        )
    strategy_obj = strat.make_strategy(strategy)
    catalog = catalog or load_catalog()
    if layouts is None:
        style, layouts = style_layouts(style, catalog)
    rid = run_id(strategy, perception, seed, room_budget_s)
    seeds = [room_seed(seed, i) for i in range(rooms)]
    t_wall = time.perf_counter()
    log = RunLog(record)
    summary = Summary(rid, 0, 0, 0, 0, 0, 0.0, 0.0, 0.0, room_budget_s=room_budget_s)
    with ExitStack() as stack:
        store = stack.enter_context(EvidenceStore.open(kb_path, catalog, alpha=alpha, create=True))
        stack.callback(log.close)
        done = {s for s in seeds if store.room_status(rid, style, s) == ROOM_DONE}
        history = list(store.examinations())
        mine = {
            s: [e for e in history if e.run == rid and e.style == style and e.room_seed == s]
            for s in seeds
        }
        # The knowledge before the first unfinished room: all evidence but that of this run's
        # unfinished rooms, which are replayed.
        kb = KnowledgeBase(catalog, store.alpha)
        replay_seeds = {s for s in seeds if s not in done}
        for ex in history:
            if ex.run == rid and ex.style == style and ex.room_seed in replay_seeds:
                continue
            kb.record_examination(ex.type, {(r, t) for r, t, _ in ex.related})
            if ex.run == rid:
                strategy_obj.observe(ex.type)
        run = Run(
            catalog,
            kb,
            store,
            strategy_obj,
            perception,
            style,
            seed,
            rid,
            log,
            on_choice=on_choice,
            room_budget_s=room_budget_s,
        )
        bar = None
        if progress:
            from tqdm import tqdm

            bar = stack.enter_context(
                tqdm(
                    total=rooms,
                    initial=len(done),
                    unit="room",
                    desc=f"learn {style}",
                    dynamic_ncols=True,
                )
            )
        last_post = 0.0
        try:
            for i, s in enumerate(seeds):
                if s in done:
                    end = store.room_end_time(rid, style, s)
                    run.clock_offset = (
                        end
                        if end is not None
                        else max([run.clock_offset] + [e.sim_time for e in mine[s]])
                    )
                    continue
                if max_examinations is not None and summary.examinations >= max_examinations:
                    break
                L = RoomLearner(
                    run,
                    layouts(i, s),
                    i,
                    [StoredExam(e.object_id, e.type, e.related, e.sim_time) for e in mine[s]],
                )
                stack.callback(L.close)
                if store.room_status(rid, style, s) is None:
                    store.mark_room(rid, style, s, ROOM_STARTED)
                log.start_room(L)
                n_room, stopped = 0, False
                for res in L.run_room():
                    n_room += 1
                    log.examination(L, res)
                    if not res.replayed:
                        summary.examinations += 1
                        summary.sim_s = run.sim_new + (L.clock - L.new_since)
                    if on_examination is not None:
                        on_examination(res, kb)
                    if bar is not None and time.perf_counter() - last_post > 0.2:
                        last_post = time.perf_counter()
                        bar.set_postfix_str(
                            f"exams {run.examinations}, sim {res.sim_time:.0f} s", refresh=True
                        )
                    if max_examinations is not None and summary.examinations >= max_examinations:
                        stopped = True
                        break
                log.end_room(L, n_room)
                L.close()
                run.sim_new += L.clock - L.new_since
                summary.sim_s = run.sim_new
                if stopped:
                    break
                store.mark_room(rid, style, s, ROOM_DONE, end_time=L.clock)
                run.clock_offset = L.clock
                summary.rooms_done_now += 1
                summary.rooms_left_early += int(L.left_early)
                if bar is not None:
                    bar.update(1)
                    bar.set_postfix_str(
                        f"exams {run.examinations}, sim {run.clock_offset:.0f} s", refresh=True
                    )
        except KeyboardInterrupt:
            summary.interrupted = True
        summary.rooms = sum(1 for s in seeds if store.room_status(rid, style, s) == ROOM_DONE)
        summary.total_examinations = store.examinations_count()
        summary.types_seen = sum(1 for t in catalog.type_names if kb.n(t) > 0)
        summary.mean_width = kb.mean_width()
        summary.files = list(log.files)
    summary.wall_s = time.perf_counter() - t_wall
    return summary
