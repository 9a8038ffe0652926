"""The procedural room generator: ``generate_room(style, seed) -> RoomLayout`` (pure data).

Deterministic by seed: the random stream is ``np.random.default_rng([seed, crc32(style name)])``,
so the same (style, seed) always gives the same layout, on any machine.

Order of work:
1. Room size and door (a gap in one wall; about 1 m in front of it stays free). A room of a house
   gets both from a ``RoomShell`` instead (its size in the plan and all its doors: the front of
   every door stays free and they all lie in the one free region).
2. Furniture from ``[furniture]``, largest first, on the floor: desks, shelves, cabinets,
   counters, beds and (often) sofas with their back to a wall and their front facing the room;
   tables and chairs free-standing. Furniture bounding boxes never overlap.
3. Placement rules in file order: for each instance a of ``ref``, with probability p, ``count``
   instances of ``type`` such that ``holds(relation, b, a)``: small objects rest on a support
   surface (``envs.parts``) or the floor, furniture stands on the floor (a chair in front of a
   desk faces it).
4. Clutter: small objects anywhere on a furniture surface or the floor.

Every candidate position is checked against the solid parts (``envs.parts.world_parts``) of
everything already placed with ``knowledge.geometry.overlaps``, so nothing interpenetrates
(touching is fine: a cup on a desk top touches it; a book is inside a shelf's bounding box but
not inside its boards). Everything that stands on the floor is also checked on a 10 cm
occupancy grid: the space where the robot's base centre can be (``RobotSpec().clearance`` from
every obstacle and wall) must be one connected region that contains the door's entry, and every
piece of furniture must be reachable - a free cell within ``REACH`` of its front (or of any side,
for tables and chairs). A candidate that breaks this is rejected; a piece that cannot be placed
is dropped, and if that leaves a furniture type below the style's minimum, the whole room is
redrawn.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ctxsearch.envs.layout import Door, RoomLayout
from ctxsearch.envs.parts import WorldSurface, world_parts_array, world_surfaces
from ctxsearch.envs.persistence import Credits, DayMemo, DayState, choose_stayers
from ctxsearch.envs.robot_spec import RobotSpec, wrap_angle
from ctxsearch.envs.styles import Rule, Style
from ctxsearch.knowledge.catalog import Catalog, ObjectType, load_catalog
from ctxsearch.knowledge.geometry import (
    EPS,
    Box,
    BoxArray,
    ObjectInstance,
    box_overlap,
    footprint_distance,
    overlap_any,
    relation_volume,
)

GRID = 0.1  # m, occupancy grid resolution for the free-space check
REACH = 0.6  # m beyond the robot's clearance: how close the base must get to a piece's front
DOOR_KEEP = 1.0  # m kept free in front of the door
WALL_GAP = 0.005  # m between a wall and furniture standing against it
MIN_POCKET_CELLS = 10  # free components smaller than this (0.1 m^2) are ignored
# The generator's check keeps this much more than the robot's clearance, so that a passage it
# finds open stays open on any other grid (navigation may discretise differently).
GRID_SLACK = 0.07
MAX_ROOM_ATTEMPTS = 12
DAY_TAG = 0xDA75  # the day stream's hash tag (``day_rng``)
STAY_TAG = 0x57A7  # the stay stream's hash tag (``stay_rng``)
DAYS_KEPT = 256  # rooms whose latest day is kept in memory (``envs.persistence.DayMemo``)
FURNITURE_TRIES = 60
OBJECT_TRIES = 30
# Probability that a piece of furniture of this shape stands with its back to a wall.
WALL_PROB = {
    "desk": 0.75,
    "shelf": 1.0,
    "cabinet": 0.95,
    "counter": 1.0,
    "bed": 1.0,
    "sofa": 0.5,
    "table": 0.15,
    "chair": 0.1,
}
# Shapes whose front matters for reachability; others can be reached from any side.
FRONTED = {"desk", "shelf", "cabinet", "counter", "sofa", "bed"}
# Small objects that face the way their support or reference faces (screens, keyboards...).
ALIGNED = {"monitor", "laptop", "keyboard", "microscope"}
# Small objects that stand in the back half of the surface they rest on.
BACK_HALF = {"monitor"}
WALLS = ("north", "south", "east", "west")


def style_hash(name: str) -> int:
    """A stable (cross-process, cross-platform) hash of a style name for seeding."""
    return zlib.crc32(name.encode("utf-8"))


@dataclass
class _Obstacle:
    """A floor footprint the robot cannot drive through (a furniture bbox, a floor object)."""

    obj: ObjectInstance
    dist: np.ndarray  # distance of every grid cell to the footprint
    reach_mask: np.ndarray | None  # cells from which the robot can look at it (furniture only)


@dataclass(frozen=True)
class RoomShell:
    """A room's given size and doors (a room of a house): the generator then draws neither.
    Every door's entry is kept free and all of them lie in the one free region."""

    width: float
    depth: float
    height: float
    doors: tuple[Door, ...]


# =========================================================================== the shell's walls
def draw_door(style: Style, width: float, depth: float, rng: np.random.Generator) -> Door:
    """A door on a wall drawn uniformly, its width from the style, its centre anywhere it fits."""
    wall = WALLS[int(rng.integers(4))]
    door_w = float(rng.uniform(*style.door_width))
    length = width if wall in ("north", "south") else depth
    span = max(0.0, length / 2 - door_w / 2 - 0.3)
    return Door(wall=wall, center=float(rng.uniform(-span, span)), width=door_w)


def wall_inward(width: float, depth: float, wall: str) -> tuple[float, float, float, float]:
    """(x, y of the wall's centre line point at along=0, inward unit normal nx, ny)."""
    W, D = width / 2, depth / 2
    return {
        "north": (0.0, D, 0.0, -1.0),
        "south": (0.0, -D, 0.0, 1.0),
        "east": (W, 0.0, -1.0, 0.0),
        "west": (-W, 0.0, 1.0, 0.0),
    }[wall]


def wall_point(
    width: float, depth: float, wall: str, along: float, inset: float
) -> tuple[float, float]:
    """The point ``along`` the wall (x for north/south walls, y for east/west) ``inset`` m in."""
    x0, y0, nx, ny = wall_inward(width, depth, wall)
    if wall in ("north", "south"):
        return along, y0 + ny * inset
    return x0 + nx * inset, along


def door_zone(width: float, depth: float, door: Door) -> Box:
    """The box in front of a door that furniture keeps clear of (``DOOR_KEEP`` deep)."""
    cx, cy = wall_point(width, depth, door.wall, door.center, DOOR_KEEP / 2)
    half_along = door.width / 2 + 0.15
    if door.wall in ("north", "south"):
        half = (half_along, DOOR_KEEP / 2, 5.0)
    else:
        half = (DOOR_KEEP / 2, half_along, 5.0)
    return Box(np.array([cx, cy, 0.0]), 0.0, np.array(half))


class _Builder:
    """Mutable state while one room is being generated."""

    def __init__(
        self,
        style: Style,
        catalog: Catalog,
        rng: np.random.Generator,
        robot: RobotSpec,
        shell: RoomShell | None = None,
    ):
        self.style, self.catalog, self.rng = style, catalog, rng
        self.clear = robot.clearance
        if shell is None:
            self.width = float(rng.uniform(*style.width))
            self.depth = float(rng.uniform(*style.depth))
            self.height = float(rng.uniform(*style.height))
            self.door = draw_door(style, self.width, self.depth, rng)
            self.doors: tuple[Door, ...] = (self.door,)
        else:
            self.width, self.depth, self.height = shell.width, shell.depth, shell.height
            self.doors = shell.doors
            self.door = shell.doors[0]
        self.objects: list[ObjectInstance] = []
        self._ids: set[int] = set()
        self._free = 1
        self.support: dict[int, int | None] = {}
        self.placed_by: dict[int, tuple[int, str]] = {}
        self.resting: dict[int, WorldSurface | None] = {}  # the surface each object rests on
        self.furniture_boxes: list[Box] = []
        self._parts: list[BoxArray] = []
        self._parts_cache: BoxArray | None = None
        self._radius_cache: np.ndarray | None = None
        self.surfaces: list[WorldSurface] = []
        # Occupancy grid: cell centres.
        nx, ny = max(2, int(self.width / GRID)), max(2, int(self.depth / GRID))
        xs = -self.width / 2 + (np.arange(nx) + 0.5) * self.width / nx
        ys = -self.depth / 2 + (np.arange(ny) + 0.5) * self.depth / ny
        self.gx, self.gy = np.meshgrid(xs, ys, indexing="ij")
        wall = self.clear + GRID_SLACK
        self.wall_free = (np.abs(self.gx) <= self.width / 2 - wall) & (
            np.abs(self.gy) <= self.depth / 2 - wall
        )
        self.dmin = np.full(self.gx.shape, np.inf)
        self.obstacles: list[_Obstacle] = []
        self.entry_cells = []
        for door in self.doors:
            ex, ey = wall_point(self.width, self.depth, door.wall, door.center, 0.6)
            self.entry_cells.append(
                (int(np.argmin(np.abs(xs - ex))), int(np.argmin(np.abs(ys - ey))))
            )
        self.entry_cell = self.entry_cells[0]
        self.door_boxes = [door_zone(self.width, self.depth, door) for door in self.doors]

    # -- bookkeeping --------------------------------------------------------------------------
    def next_id(self) -> int:
        """The smallest id not in use (1, 2, ...: on a later day the gaps the furniture kept
        leaves, so ids stay 1..N)."""
        while self._free in self._ids:
            self._free += 1
        return self._free

    @property
    def parts(self) -> BoxArray:
        if self._parts_cache is None:
            if self._parts:
                self._parts_cache = BoxArray(
                    np.concatenate([p.centers for p in self._parts]),
                    np.concatenate([p.yaws for p in self._parts]),
                    np.concatenate([p.halves for p in self._parts]),
                )
            else:
                self._parts_cache = BoxArray(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)))
        return self._parts_cache

    def collides(self, parts: BoxArray) -> bool:
        """True if any of ``parts`` overlaps (positive volume) a part already placed."""
        allp = self.parts
        if len(allp) == 0:
            return False
        # Cheap pre-filter: bounding circles in the ground plane and z intervals.
        if self._radius_cache is None or len(self._radius_cache) != len(allp):
            self._radius_cache = np.hypot(allp.halves[:, 0], allp.halves[:, 1])
        rad = np.hypot(parts.halves[:, 0], parts.halves[:, 1])
        lo = parts.centers - np.column_stack([rad, rad, parts.halves[:, 2]])
        hi = parts.centers + np.column_stack([rad, rad, parts.halves[:, 2]])
        cx, cy = (lo[:, 0].min() + hi[:, 0].max()) / 2, (lo[:, 1].min() + hi[:, 1].max()) / 2
        r = math.hypot(hi[:, 0].max() - lo[:, 0].min(), hi[:, 1].max() - lo[:, 1].min()) / 2
        d = np.hypot(allp.centers[:, 0] - cx, allp.centers[:, 1] - cy)
        near = (
            (d < r + self._radius_cache)
            & (allp.centers[:, 2] - allp.halves[:, 2] < hi[:, 2].max() - EPS)
            & (allp.centers[:, 2] + allp.halves[:, 2] > lo[:, 2].min() + EPS)
        )
        idx = np.flatnonzero(near)
        if len(idx) == 0:
            return False
        return overlap_any(BoxArray(allp.centers[idx], allp.yaws[idx], allp.halves[idx]), parts)

    def inside_room(self, obj: ObjectInstance) -> bool:
        xy = obj.box().corners_xy()
        return bool(
            np.all(np.abs(xy[:, 0]) <= self.width / 2 + 1e-9)
            and np.all(np.abs(xy[:, 1]) <= self.depth / 2 + 1e-9)
            and obj.top <= self.height
        )

    def in_door_zone(self, obj: ObjectInstance) -> bool:
        return any(box_overlap(obj.box(), zone) for zone in self.door_boxes)

    def add(
        self,
        obj: ObjectInstance,
        parts: BoxArray,
        surface: WorldSurface | None,
        obstacle: _Obstacle | None = None,
        placed_by: tuple[int, str] | None = None,
    ) -> None:
        self.objects.append(obj)
        self._ids.add(obj.id)
        self._parts.append(parts)
        self._parts_cache = None
        self.support[obj.id] = None if surface is None else surface.owner
        self.resting[obj.id] = surface
        if placed_by is not None:
            self.placed_by[obj.id] = placed_by
        if self.catalog.type(obj.type).is_furniture:
            self.furniture_boxes.append(obj.box())
            self.surfaces.extend(world_surfaces(obj, self.catalog))
        if obstacle is not None:
            self.obstacles.append(obstacle)
            self.dmin = np.minimum(self.dmin, obstacle.dist)

    def drop(self, ids: set[int]) -> None:
        """Take the objects of ``ids`` out of the finished room, with whatever rests on them
        (the stayers no placement of the day took); a placement that names one of them as its
        reference forgets it. Only the room's contents are updated, not the collision state."""
        gone = set(ids)
        while more := {o for o, s in self.support.items() if s in gone and o not in gone}:
            gone |= more
        self.objects = [o for o in self.objects if o.id not in gone]
        self._ids -= gone
        for k in gone:
            self.support.pop(k, None)
            self.resting.pop(k, None)
            self.placed_by.pop(k, None)
        self.placed_by = {k: v for k, v in self.placed_by.items() if v[0] not in gone}

    # -- free space -----------------------------------------------------------------------------
    def make_obstacle(self, obj: ObjectInstance, furniture: bool) -> _Obstacle:
        b = obj.box()
        dist = footprint_distance(b, self.gx, self.gy)
        reach = None
        if furniture:
            reach = dist <= self.clear + GRID_SLACK + REACH
            if self.catalog.type(obj.type).shape in FRONTED:
                c, s = math.cos(b.yaw), math.sin(b.yaw)
                lx = c * (self.gx - b.center[0]) + s * (self.gy - b.center[1])
                reach &= lx > b.half[0]
        return _Obstacle(obj, dist, reach)

    def free_space_ok(self, extra: _Obstacle | None = None) -> bool:
        """Is the robot's free space one region holding every door's entry, reaching all
        furniture?"""
        dmin = self.dmin if extra is None else np.minimum(self.dmin, extra.dist)
        free = self.wall_free & (dmin > self.clear + GRID_SLACK)
        if not all(free[c] for c in self.entry_cells):
            return False
        labels, n = ndimage.label(free)
        main = labels[self.entry_cell]
        if any(labels[c] != main for c in self.entry_cells[1:]):
            return False
        if n > 1:
            sizes = np.bincount(labels.ravel(), minlength=n + 1)
            sizes[0] = 0
            sizes[main] = 0
            if sizes.max() >= MIN_POCKET_CELLS:
                return False
        reachable = labels == main
        obstacles = self.obstacles if extra is None else [*self.obstacles, extra]
        return all(
            not (o.reach_mask is not None and not np.any(o.reach_mask & reachable))
            for o in obstacles
        )

    # -- furniture ------------------------------------------------------------------------------
    def try_furniture(self, obj: ObjectInstance, placed_by: tuple[int, str] | None = None) -> bool:
        """Add a piece of furniture if it fits: inside, clear of the door, no overlaps, free space."""
        if not self.inside_room(obj) or self.in_door_zone(obj):
            return False
        box = obj.box()
        if any(box_overlap(box, other) for other in self.furniture_boxes):
            return False
        parts = world_parts_array(obj, self.catalog)
        if self.collides(parts):
            return False
        obstacle = self.make_obstacle(obj, furniture=True)
        if not self.free_space_ok(obstacle):
            return False
        self.add(obj, parts, None, obstacle, placed_by)
        return True

    def furniture_candidate(self, ot: ObjectType, size, oid: int) -> ObjectInstance:
        rng = self.rng
        sx, sy, sz = size
        if rng.random() < WALL_PROB.get(ot.shape, 0.3):
            lengths = np.array([self.width, self.width, self.depth, self.depth])
            wall = WALLS[int(rng.choice(4, p=lengths / lengths.sum()))]
            length = self.width if wall in ("north", "south") else self.depth
            span = max(0.0, length / 2 - sy / 2 - WALL_GAP)
            along = float(rng.uniform(-span, span))
            x, y = wall_point(self.width, self.depth, wall, along, sx / 2 + WALL_GAP)
            _, _, nx, ny = wall_inward(self.width, self.depth, wall)
            yaw = math.atan2(ny, nx)
        else:
            r = math.hypot(sx, sy) / 2
            x = (
                float(rng.uniform(-self.width / 2 + r, self.width / 2 - r))
                if self.width > 2 * r
                else 0.0
            )
            y = (
                float(rng.uniform(-self.depth / 2 + r, self.depth / 2 - r))
                if self.depth > 2 * r
                else 0.0
            )
            yaw = float(rng.integers(4)) * math.pi / 2
            if rng.random() < 0.3:
                yaw += float(rng.uniform(-0.15, 0.15))
        return ObjectInstance(ot.name, oid, (x, y, sz / 2), wrap_angle(yaw), size)

    def place_furniture(self, tname: str) -> bool:
        ot = self.catalog.type(tname)
        size = ot.sample_size(self.rng)
        oid = self.next_id()
        for _ in range(FURNITURE_TRIES):
            if self.try_furniture(self.furniture_candidate(ot, size, oid)):
                return True
        return False

    def place_furniture_by_rule(self, rule: Rule, ref: ObjectInstance) -> bool:
        ot = self.catalog.type(rule.type)
        rel = self.catalog.relation(rule.relation)
        vol = relation_volume(rel, ref)
        size = ot.sample_size(self.rng)
        oid = self.next_id()
        c, s = math.cos(vol.yaw), math.sin(vol.yaw)
        for _ in range(FURNITURE_TRIES):
            u = float(self.rng.uniform(-vol.half[0], vol.half[0]))
            v = float(self.rng.uniform(-vol.half[1], vol.half[1]))
            x, y = vol.center[0] + c * u - s * v, vol.center[1] + s * u + c * v
            if ot.shape == "chair":  # sits facing its reference
                yaw = math.atan2(ref.position[1] - y, ref.position[0] - x) + float(
                    self.rng.uniform(-0.2, 0.2)
                )
            elif ot.shape in FRONTED:  # faces the way its reference faces (nightstand by a bed)
                yaw = ref.yaw
            else:
                yaw = ref.yaw + float(self.rng.integers(4)) * math.pi / 2
            obj = ObjectInstance(
                ot.name, oid, (float(x), float(y), size[2] / 2), wrap_angle(yaw), size
            )
            if box_overlap(obj.box(), vol) and self.try_furniture(obj, (ref.id, rel.name)):
                return True
        return False

    # -- small objects ----------------------------------------------------------------------------
    def floor_surface(self) -> WorldSurface:
        return WorldSurface(
            owner=-1,
            center=(0.0, 0.0, 0.0),
            yaw=0.0,
            half_xy=(self.width / 2, self.depth / 2),
            clearance=self.height,
        )

    def small_yaw(self, ot: ObjectType, facing: float | None) -> float:
        if ot.shape in ALIGNED and facing is not None:
            return wrap_angle(facing + float(self.rng.uniform(-0.25, 0.25)))
        return float(self.rng.uniform(-math.pi, math.pi))

    def try_small(
        self,
        ot: ObjectType,
        size,
        yaw: float,
        surf: WorldSurface,
        oid: int,
        region: tuple[float, float, float, float] | None,
        check=None,
        placed_by: tuple[int, str] | None = None,
    ) -> bool:
        """Sample a spot for a small object on ``surf`` and add it if it is valid."""
        sx, sy, sz = size
        if sz > surf.clearance:
            return False
        d = yaw - surf.yaw
        ex = abs(math.cos(d)) * sx / 2 + abs(math.sin(d)) * sy / 2
        ey = abs(math.sin(d)) * sx / 2 + abs(math.cos(d)) * sy / 2
        lo_u, hi_u = -surf.half_xy[0] + ex, surf.half_xy[0] - ex
        lo_v, hi_v = -surf.half_xy[1] + ey, surf.half_xy[1] - ey
        if region is not None:  # proposal rect (u0, u1, v0, v1) in the surface frame
            lo_u, hi_u = max(lo_u, region[0] - ex), min(hi_u, region[1] + ex)
            lo_v, hi_v = max(lo_v, region[2] - ey), min(hi_v, region[3] + ey)
        if ot.shape in BACK_HALF and surf.owner >= 0 and abs(wrap_angle(yaw - surf.yaw)) < 0.5:
            hi_u = min(hi_u, 0.0)  # screens stand in the back half of a desk, facing its front
        if lo_u > hi_u or lo_v > hi_v:
            return False
        u, v = float(self.rng.uniform(lo_u, hi_u)), float(self.rng.uniform(lo_v, hi_v))
        c, s = math.cos(surf.yaw), math.sin(surf.yaw)
        x = surf.center[0] + c * u - s * v
        y = surf.center[1] + s * u + c * v
        obj = ObjectInstance(ot.name, oid, (x, y, surf.center[2] + sz / 2), wrap_angle(yaw), size)
        if check is not None and not check(obj):
            return False
        on_floor = surf.owner < 0
        if on_floor and self.in_door_zone(obj):
            return False
        parts = world_parts_array(obj, self.catalog)
        if self.collides(parts):
            return False
        obstacle = None
        if on_floor:
            obstacle = self.make_obstacle(obj, furniture=False)
            if not self.free_space_ok(obstacle):
                return False
        self.add(obj, parts, None if on_floor else surf, obstacle, placed_by)
        return True

    def place_small_by_rule(self, rule: Rule, ref: ObjectInstance) -> bool:
        ot = self.catalog.type(rule.type)
        rel = self.catalog.relation(rule.relation)
        vol = relation_volume(rel, ref)
        size = ot.sample_size(self.rng)
        h = size[2]
        zlo, zhi = vol.center[2] - vol.half[2], vol.center[2] + vol.half[2]

        def reaches(z: float) -> bool:  # an object resting at z overlaps the volume in z
            return min(z + h, zhi) - max(z, zlo) > EPS

        own = [
            s
            for s in world_surfaces(ref, self.catalog)
            if reaches(s.center[2]) and s.clearance >= h
        ]
        below = self.resting.get(ref.id)
        sup = (
            [below]
            if below is not None and reaches(below.center[2]) and below.clearance >= h
            else []
        )
        floor = [self.floor_surface()] if reaches(0.0) else []
        if rule.on == "floor":
            tiers = [floor]
        elif rule.on == "surface":
            tiers = [own + sup]
        else:
            tiers = [own, sup, floor]
        cands = next((t for t in tiers if t), [])
        if not cands:
            return False
        weights = np.array([s.area for s in cands])
        weights = weights / weights.sum()
        oid = self.next_id()
        facing = ref.yaw

        def check(obj: ObjectInstance) -> bool:  # holds(rel, obj, ref), fast
            return box_overlap(obj.box(), vol)

        for _ in range(OBJECT_TRIES):
            surf = (
                cands[int(self.rng.choice(len(cands), p=weights))] if len(cands) > 1 else cands[0]
            )
            yaw = self.small_yaw(ot, facing)
            region = _volume_region(vol, surf)
            if self.try_small(ot, size, yaw, surf, oid, region, check, (ref.id, rel.name)):
                return True
        return False

    def place_clutter(self, tname: str) -> bool:
        ot = self.catalog.type(tname)
        size = ot.sample_size(self.rng)
        oid = self.next_id()
        surfaces = [s for s in self.surfaces if s.clearance >= size[2]]
        weights = np.array([s.area for s in surfaces]) if surfaces else np.zeros(0)
        for _ in range(OBJECT_TRIES):
            if not surfaces or self.rng.random() < 0.2:
                surf = self.floor_surface()
                facing = None
            else:
                surf = surfaces[int(self.rng.choice(len(surfaces), p=weights / weights.sum()))]
                facing = surf.yaw
            if self.try_small(ot, size, self.small_yaw(ot, facing), surf, oid, None):
                return True
        return False


def _volume_region(vol: Box, surf: WorldSurface) -> tuple[float, float, float, float]:
    """The volume's footprint as an axis-aligned rect (u0, u1, v0, v1) in the surface's frame
    (its bounding rect if the two are not aligned): where to propose positions."""
    c, s = math.cos(surf.yaw), math.sin(surf.yaw)
    corners = vol.corners_xy() - np.asarray(surf.center[:2])
    u = c * corners[:, 0] + s * corners[:, 1]
    v = -s * corners[:, 0] + c * corners[:, 1]
    return float(u.min()), float(u.max()), float(v.min()), float(v.max())


def _furniture_order(style: Style, catalog: Catalog, rng: np.random.Generator) -> list[str]:
    """The furniture to place (type names), largest footprint first."""
    names = []
    for tname, (lo, hi) in style.furniture:
        names += [tname] * int(rng.integers(lo, hi + 1))
    area = {t: catalog.type(t).size_max[0] * catalog.type(t).size_max[1] for t in names}
    return sorted(names, key=lambda t: -area[t])  # stable: file order among equals


def _build(
    style: Style,
    catalog: Catalog,
    rng: np.random.Generator,
    robot: RobotSpec,
    strict: bool,
    shell: RoomShell | None = None,
) -> _Builder | None:
    b = _Builder(style, catalog, rng, robot, shell)
    placed: dict[str, int] = {}
    for tname in _furniture_order(style, catalog, rng):
        if b.place_furniture(tname):
            placed[tname] = placed.get(tname, 0) + 1
    if strict and any(placed.get(t, 0) < lo for t, (lo, _) in style.furniture):
        return None
    _place_small(b, style, catalog, rng, furniture_rules=True)
    return b


def _place_small(
    b: _Builder,
    style: Style,
    catalog: Catalog,
    rng: np.random.Generator,
    furniture_rules: bool,
    credits: Credits | None = None,
) -> None:
    """The rules in file order (those placing furniture only with ``furniture_rules``), then the
    clutter. With ``credits`` (a later day's stayers), an instance of a type with stayers left
    takes one of them instead of being placed; stayers not taken yet are no rule's reference."""
    for rule in style.rules:
        pending = credits.pending() if credits else ()
        refs = [o for o in b.objects if o.type == rule.ref and o.id not in pending]
        is_furniture = catalog.type(rule.type).is_furniture
        if is_furniture and not furniture_rules:
            continue
        for ref in refs:
            if rng.random() >= rule.p:
                continue
            for _ in range(int(rng.integers(rule.count[0], rule.count[1] + 1))):
                if is_furniture:
                    b.place_furniture_by_rule(rule, ref)
                elif not (credits and credits.take(rule.type, (ref.id, rule.relation))):
                    b.place_small_by_rule(rule, ref)
    for tname, (lo, hi) in style.clutter:
        for _ in range(int(rng.integers(lo, hi + 1))):
            if not (credits and credits.take(tname)):
                b.place_clutter(tname)


def day_rng(style: Style, seed: int, day: int) -> np.random.Generator:
    """The random stream that places a world's small objects on ``day`` >= 1 (its own hash tag,
    so it shares no draws with the world's own stream)."""
    return np.random.default_rng(
        [int(seed) & 0xFFFFFFFFFFFFFFFF, style_hash(style.name), int(day), DAY_TAG]
    )


def stay_rng(style: Style, seed: int, day: int) -> np.random.Generator:
    """The random stream that decides which small objects of ``day`` - 1 stay on ``day`` (its
    own hash tag: the day's placements draw from ``day_rng`` as they would without it)."""
    return np.random.default_rng(
        [int(seed) & 0xFFFFFFFFFFFFFFFF, style_hash(style.name), int(day), STAY_TAG]
    )


def _next_day(
    prev: DayState, style: Style, catalog: Catalog, robot: RobotSpec, seed: int, day: int
) -> _Builder:
    """The room of ``prev`` (its day ``day`` - 1) on ``day``: the same shell and furniture (same
    ids and poses); each small object stays with its type's ``style.stay`` (``stay_rng``), then
    ``style.on_day(day)``'s rules place the day's small objects from the day's stream, an
    instance of a type with stayers left taking one of them (``envs.persistence``); the stayers
    none took stay as well (a household's things do not vanish because the day's draw of a type
    was smaller: that day holds more of it than its rules drew). With every stay probability 0
    this is the day placed from scratch."""
    shell = RoomShell(prev.width, prev.depth, prev.height, prev.doors)
    rng = day_rng(style, seed, day)
    today = style.on_day(day)
    b = _Builder(today, catalog, rng, robot, shell)
    for obj in prev.objects:
        if catalog.type(obj.type).is_furniture:
            obstacle = b.make_obstacle(obj, furniture=True)
            b.add(obj, world_parts_array(obj, catalog), None, obstacle, prev.placed_by.get(obj.id))
    stayers = choose_stayers(prev.objects, prev.support, lambda t: style.stay(t, catalog),
                             catalog, stay_rng(style, seed, day))  # fmt: skip
    credits = Credits(_keep(b, prev, stayers), b.placed_by) if stayers else None
    _place_small(b, today, catalog, rng, furniture_rules=False, credits=credits)
    return b


def _keep(b: _Builder, prev: DayState, stayers: list[ObjectInstance]) -> list[ObjectInstance]:
    """Add the stayers to the day's room at their exact pose, on what they rested on, with the
    rule that placed them where its reference is still there; one on the floor that would now
    close off free space leaves (as does whatever rested on it). Returns those kept."""
    kept = []
    for obj in stayers:
        surf = prev.resting.get(obj.id)
        if surf is not None and surf.owner not in b._ids:
            continue  # it rested on a small object that did not stay
        obstacle = None
        if surf is None:
            obstacle = b.make_obstacle(obj, furniture=False)
            if not b.free_space_ok(obstacle):
                continue
        by = prev.placed_by.get(obj.id)
        by = by if by is not None and by[0] in b._ids else None
        b.add(obj, world_parts_array(obj, b.catalog), surf, obstacle, by)
        kept.append(obj)
    return kept


def door_entry(layout: RoomLayout, inset: float = 0.6) -> tuple[float, float, float]:
    """A pose (x, y, yaw) just inside the door, facing into the room: kept free by the generator
    and inside the robot's connected free space (a natural start pose)."""
    W, D, d = layout.width / 2, layout.depth / 2, layout.door
    return {
        "north": (d.center, D - inset, -math.pi / 2),
        "south": (d.center, -D + inset, math.pi / 2),
        "east": (W - inset, d.center, math.pi),
        "west": (-W + inset, d.center, 0.0),
    }[d.wall]


def generate_room(
    style: Style,
    seed: int,
    catalog: Catalog | None = None,
    robot: RobotSpec | None = None,
    shell: RoomShell | None = None,
    day: int = 0,
) -> RoomLayout:
    """A furnished room of ``style``, the same for the same (style, seed, shell, day). With
    ``shell`` (a room of a house) its size and doors are given instead of drawn. On ``day`` >= 1
    the room persists: the same size, doors and furniture (ids and poses) as on day 0, and day d
    is made from day d - 1 (``_next_day``): each small object stays exactly where it was with its
    type's probability (``Style.stay``), and the style's rules as they stand that day
    (``Style.on_day``) place the day's small objects (``day_rng``), taking stayers of a type
    before placing new ones; the stayers not taken stay too (a type then has more that day than
    its rules drew, so an object stays with its type's probability, not less). A stayer keeps its id; the ids of those that left are gaps, new objects take the
    smallest free ones. Day d is d day steps from day 0 (each about half the room's own build);
    the latest day of each of the last ``DAYS_KEPT`` rooms is kept in memory, so a room's days
    asked for in turn cost one step each. With every stay probability 0
    (``Style.moves_everything``) each day is placed from day 0 directly, as before small
    objects stayed."""
    catalog = catalog or load_catalog()
    robot = robot or RobotSpec()
    if not day:
        state = _state(_day_zero(style, seed, catalog, robot, shell))
    elif style.moves_everything(catalog):
        state = _state(_day_zero(style, seed, catalog, robot, shell))
        state = _state(_next_day(state, style, catalog, robot, seed, day))
    else:
        state = _chain(style, seed, catalog, robot, shell, int(day))
    return RoomLayout(
        style=style.name,
        seed=int(seed),
        width=state.width,
        depth=state.depth,
        height=state.height,
        door=state.doors[0],
        objects=state.objects,
        support=dict(state.support),
        placed_by=dict(state.placed_by),
    )


_DAYS = DayMemo(DAYS_KEPT)


def _chain(
    style: Style, seed: int, catalog: Catalog, robot: RobotSpec, shell: RoomShell | None, day: int
) -> DayState:
    """Day ``day`` of the room, made day by day from the latest day of it kept in memory that is
    not later (else from day 0)."""
    key = (style, int(seed), catalog, robot, shell)
    start, state = _DAYS.start(key, day) or (0, None)
    if state is None:
        state = _state(_day_zero(style, seed, catalog, robot, shell))
    for d in range(start + 1, day + 1):
        state = _state(_next_day(state, style, catalog, robot, seed, d))
    _DAYS.keep(key, day, state)
    return state


def _state(b: _Builder) -> DayState:
    return DayState(b.width, b.depth, b.height, b.doors, tuple(b.objects), dict(b.support),
                    dict(b.placed_by), dict(b.resting))  # fmt: skip


def _day_zero(
    style: Style, seed: int, catalog: Catalog, robot: RobotSpec, shell: RoomShell | None
) -> _Builder:
    """The room as first generated (its own stream; redrawn while a furniture minimum fails)."""
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFFFFFFFFFF, style_hash(style.name)])
    b = None
    for attempt in range(MAX_ROOM_ATTEMPTS):
        b = _build(style, catalog, rng, robot, attempt < MAX_ROOM_ATTEMPTS - 1, shell)
        if b is not None:
            break
    assert b is not None
    return b
