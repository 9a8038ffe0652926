"""Floor plans: ``generate_house(house_style, seed) -> RoomLayout`` (pure data, no MuJoCo).

Deterministic by seed: the random stream is ``np.random.default_rng([seed, crc32(name)])``, the
name being the house style's ``seed_name`` where it has one (a control style that draws another
style's worlds).

Order of work (steps 1 and 2 in ``envs.plans``):
1. The rooms: a count per room style from the house style's ranges (redrawn until the total is in
   ``house.rooms``), each with a target floor area drawn from its room style's size ranges; the
   areas are scaled so the whole plan (corridor included) is within ``house.footprint``.
2. The plan, a rectangle cut into rooms:
   - ``corridor``: one corridor runs the plan's length; the rooms are split between the two bands
     beside it (largest first, to the lighter band) and each band is cut across into its rooms.
     Every room has a door onto the corridor; the entrance is at one end of the corridor.
   - ``open``: recursive subdivision (cut the longer side at the area ratio of two groups of
     rooms). Doors join neighbouring rooms along a breadth-first spanning tree from the entrance
     room (``house.entrance``, else the largest), so the entrance room is the hub.
   Many candidate plans are drawn; the first whose rooms all fit their style (each side at least
   ``MIN_SIDE_FRACTION`` of the style's smallest side, aspect at most ``MAX_ASPECT``) is kept,
   else the one that misses least. A house style's ``[layout]`` rules (which room kinds must or
   may share a door) change both plans and come first (``envs.plans``, ``envs.house_rules``).
3. Every room is furnished by its room style's rules with ``envs.rooms.generate_room`` on a
   ``RoomShell`` (the plan's size, all its doors: their fronts are kept clear and lie in one free
   region), then moved into house coordinates; ids are renumbered so they are unique in the house.

Walls: interior walls (``WALL`` thick) stand centred on the cuts, so a room's interior outline is
its cell shrunk by ``WALL / 2`` on every inner side; the outer walls stand just outside the
footprint, as a single room's do. ``wall_boxes`` gives them with the door gaps (and lintels),
``wall_obstacles`` the part the robot cannot cross.
"""

from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np

from ctxsearch.envs.houses import CORRIDOR, HouseStyle, WorldStyle
from ctxsearch.envs.layout import Door, Passage, Room, RoomLayout
from ctxsearch.envs.plans import _E, WALL, house_hash, plan
from ctxsearch.envs.robot_spec import RobotSpec, wrap_angle
from ctxsearch.envs.rooms import RoomShell, generate_room
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.geometry import Box, ObjectInstance


# -- 3. furnishing ----------------------------------------------------------------------------------
def _interior(rect, W: float, D: float) -> tuple[float, float, float, float]:
    """A cell's interior: shrunk by half a wall on each side that is not the footprint's edge."""
    x0, y0, x1, y1 = rect
    h = WALL / 2
    return (
        x0 if x0 < _E else x0 + h,
        y0 if y0 < _E else y0 + h,
        x1 if x1 > W - _E else x1 - h,
        y1 if y1 > D - _E else y1 - h,
    )


def _room_door(outline, p: Passage) -> Door:
    """A passage as a door of the room with interior ``outline`` (room-centred coordinates)."""
    x0, y0, x1, y1 = outline
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    if p.axis == "x":
        return Door("north" if p.center[1] > cy else "south", p.center[0] - cx, p.width)
    return Door("east" if p.center[0] > cx else "west", p.center[1] - cy, p.width)


def _entrance_door(p: Passage, W: float, D: float) -> Door:
    """The entrance passage as the layout's ``door`` (a gap in the outer wall)."""
    if p.axis == "x":
        return Door("north" if p.center[1] > 0 else "south", p.center[0], p.width)
    return Door("east" if p.center[0] > 0 else "west", p.center[1], p.width)


def generate_house(
    house: HouseStyle,
    seed: int,
    catalog: Catalog | None = None,
    robot: RobotSpec | None = None,
    day: int = 0,
) -> RoomLayout:
    """A furnished house of ``house`` style, the same for the same (house, seed, day); on a later
    ``day`` its plan and furniture (house ids included) stay and every room's small objects are
    those of ``generate_room``'s day: made from the day before, each small object staying with
    its room style's probability (``Style.stay``) where the day's rules still want one of its
    type. Small objects are numbered anew every day (``_house_ids``): across days, an object that
    stayed is identified by its type and exact pose (``envs.persistence.stayed``), not its id."""
    catalog = catalog or load_catalog()
    robot = robot or RobotSpec()
    stream = house_hash(house.seed_name or house.name)
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFFFFFFFFFF, stream])
    cells, raw, W, D = plan(house, rng)
    height = float(rng.uniform(*house.height))
    ox, oy = W / 2, D / 2  # plan -> house coordinates (origin at the centre)
    passages = tuple(
        Passage((a, b), (float(x - ox), float(y - oy)), axis, float(w))
        for a, b, x, y, axis, w in raw
    )
    rooms, objects = [], []
    support: dict[int, int | None] = {}
    placed_by: dict[int, tuple[int, str]] = {}
    room_of: dict[int, int] = {}
    furnished = []  # (room index, its layout, its id base on day 0, its centre)
    base = 0
    for i, cell in enumerate(cells):
        ix0, iy0, ix1, iy1 = _interior(cell.rect, W, D)
        outline = (float(ix0 - ox), float(iy0 - oy), float(ix1 - ox), float(iy1 - oy))
        room_seed = int(rng.integers(2**31))
        rooms.append(Room(i, cell.style.name if cell.style else CORRIDOR, outline))
        if cell.style is None:
            continue
        doors = tuple(_room_door(outline, p) for p in passages if i in p.rooms)
        shell = RoomShell(outline[2] - outline[0], outline[3] - outline[1], height, doors)
        room = generate_room(cell.style, room_seed, catalog, robot, shell, day)
        centre = ((outline[0] + outline[2]) / 2, (outline[1] + outline[3]) / 2)
        furnished.append((i, room, base, centre))
        day0 = room if not day else generate_room(cell.style, room_seed, catalog, robot, shell)
        base += len(day0.objects)
    for i, room, base, (cx, cy) in furnished:
        ids = _house_ids(room, base, catalog, day, furnished)
        for o in room.objects:
            x, y, z = o.position
            obj = ObjectInstance(o.type, ids[o.id], (x + cx, y + cy, z), o.yaw, o.size)
            objects.append(obj)
            room_of[obj.id] = i
            sup = room.support.get(o.id)
            support[obj.id] = None if sup is None else ids[sup]
        for oid, (ref, rel) in room.placed_by.items():
            placed_by[ids[oid]] = (ids[ref], rel)
    entrance = next(p for p in passages if p.rooms[1] == -1)
    return RoomLayout(
        style=house.name,
        seed=int(seed),
        width=float(W),
        depth=float(D),
        height=height,
        door=_entrance_door(entrance, W, D),
        objects=tuple(objects),
        support=support,
        placed_by=placed_by,
        rooms=tuple(rooms),
        doors=passages,
        room_of=room_of,
    )


def _house_ids(room: RoomLayout, base: int, catalog: Catalog, day: int, furnished) -> dict:
    """Room-local id -> house id. Day 0: local + the room's base (the rooms' ids in turn), 1..N.
    A later day: furniture keeps its day-0 house id; small objects take the smallest ids no
    furniture of the house holds, in order (rooms in turn, a room's objects in its order), so
    ids stay unique and fill 1..N but for the day-0 ids of furniture above N (a day with fewer
    small objects than day 0)."""
    if not day:
        return {o.id: o.id + base for o in room.objects}
    taken = {o.id + b for _i, r, b, _c in furnished for o in r.objects
             if catalog.type(o.type).is_furniture}  # fmt: skip
    earlier = sum(
        sum(1 for o in r.objects if not catalog.type(o.type).is_furniture)
        for _i, r, b, _c in furnished
        if b < base
    )
    free = (k for k in range(1, 10**9) if k not in taken)
    for _ in range(earlier):  # the free ids the small objects of earlier rooms took
        next(free)
    ids = {}
    for o in room.objects:
        ids[o.id] = o.id + base if catalog.type(o.type).is_furniture else next(free)
    return ids


# -- walls and free space -------------------------------------------------------------------------
def _merge(intervals: list[tuple[float, float]]) -> list[tuple[float, float]]:
    out: list[tuple[float, float]] = []
    for a, b in sorted(intervals):
        if out and a <= out[-1][1] + _E:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def _cut(intervals, gaps) -> list[tuple[float, float]]:
    out = list(intervals)
    for g0, g1 in gaps:
        nxt = []
        for a, b in out:
            if g1 <= a or g0 >= b:
                nxt.append((a, b))
                continue
            if g0 > a:
                nxt.append((a, g0))
            if g1 < b:
                nxt.append((g1, b))
        out = nxt
    return [(a, b) for a, b in out if b - a > 1e-3]


def wall_boxes(
    layout: RoomLayout, thickness: float = WALL, door_height: float = 2.1
) -> list[tuple[str, list[float], list[float]]]:
    """(name, centre, half extents) of every wall box of a house: the outer walls (entrance gap
    included) just outside the footprint, the interior walls on the cuts with their door gaps,
    and a lintel over every opening (name ending in ``lintel``). Empty for a single room."""
    if not layout.is_house:
        return []
    hw, hd, h, t = layout.width / 2, layout.depth / 2, layout.height, thickness
    lines: dict[tuple[str, float], list[tuple[float, float]]] = {}
    outer = {("x", hd + t / 2), ("x", -hd - t / 2), ("y", hw + t / 2), ("y", -hw - t / 2)}
    for axis, fixed in outer:
        span = hw + t if axis == "x" else hd + t
        lines[(axis, round(fixed, 6))] = [(-span, span)]
    for room in layout.rooms:
        x0, y0, x1, y1 = room.outline
        h2 = WALL / 2
        edges = []
        if y0 > -hd + _E:
            edges.append(("x", y0 - h2, x0 - h2, x1 + h2))
        if y1 < hd - _E:
            edges.append(("x", y1 + h2, x0 - h2, x1 + h2))
        if x0 > -hw + _E:
            edges.append(("y", x0 - h2, y0 - h2, y1 + h2))
        if x1 < hw - _E:
            edges.append(("y", x1 + h2, y0 - h2, y1 + h2))
        for axis, fixed, a, b in edges:
            lines.setdefault((axis, round(fixed, 6)), []).append((a, b))
    gaps: dict[tuple[str, float], list[tuple[float, float]]] = {}
    for p in layout.doors:
        if p.rooms[1] == -1:  # the entrance: on the outer wall's centre line
            if p.axis == "x":
                key = ("x", round((hd + t / 2) * (1 if p.center[1] > 0 else -1), 6))
            else:
                key = ("y", round((hw + t / 2) * (1 if p.center[0] > 0 else -1), 6))
        else:
            key = (p.axis, round(p.center[1] if p.axis == "x" else p.center[0], 6))
        along = p.center[0] if p.axis == "x" else p.center[1]
        gaps.setdefault(key, []).append((along - p.width / 2, along + p.width / 2))
    out = []
    for k, ((axis, fixed), ivs) in enumerate(sorted(lines.items())):
        pieces = [(a, b, 0.0, h, "") for a, b in _cut(_merge(ivs), gaps.get((axis, fixed), []))]
        if h > door_height:
            pieces += [(a, b, door_height, h, "_lintel") for a, b in gaps.get((axis, fixed), [])]
        for j, (a, b, z0, z1, suffix) in enumerate(pieces):
            mid, half_len = (a + b) / 2, (b - a) / 2
            if axis == "x":
                center, half = [mid, fixed, (z0 + z1) / 2], [half_len, t / 2, (z1 - z0) / 2]
            else:
                center, half = [fixed, mid, (z0 + z1) / 2], [t / 2, half_len, (z1 - z0) / 2]
            out.append((f"hwall{k}_{j}{suffix}", center, half))
    return out


def wall_obstacles(layout: RoomLayout) -> list[Box]:
    """The interior walls of a house as boxes the robot cannot cross (lintels excluded; the
    outer walls are the footprint's edge). Empty for a single room."""
    return [
        Box(np.array(c, float), 0.0, np.array(h, float))
        for name, c, h in wall_boxes(layout)
        if not name.endswith("lintel")
        and abs(c[0]) < layout.width / 2
        and abs(c[1]) < layout.depth / 2
    ]


def room_at(layout: RoomLayout, x: float, y: float) -> int | None:
    """The index of the room whose interior holds (x, y), or None (a wall, outside)."""
    for room in layout.rooms:
        x0, y0, x1, y1 = room.outline
        if x0 - _E <= x <= x1 + _E and y0 - _E <= y <= y1 + _E:
            return room.index
    return None


def layout_dict(layout: RoomLayout) -> dict:
    """The layout as JSON-ready data: style, seed, size, rooms (style, outline), doors, and every
    object (type, id, position, yaw, size, room). A single room is one room of index 0."""
    if layout.is_house:
        rooms = [
            {"index": r.index, "style": r.style, "outline": list(r.outline)} for r in layout.rooms
        ]
        doors = [
            {"rooms": list(p.rooms), "center": list(p.center), "axis": p.axis, "width": p.width}
            for p in layout.doors
        ]
    else:
        hw, hd = layout.width / 2, layout.depth / 2
        rooms = [{"index": 0, "style": layout.style, "outline": [-hw, -hd, hw, hd]}]
        d = layout.door
        axis = "x" if d.wall in ("north", "south") else "y"
        center = {
            "north": (d.center, hd),
            "south": (d.center, -hd),
            "east": (hw, d.center),
            "west": (-hw, d.center),
        }[d.wall]
        doors = [{"rooms": [0, -1], "center": list(center), "axis": axis, "width": d.width}]
    return {
        "style": layout.style,
        "seed": layout.seed,
        "kind": "house" if layout.is_house else "room",
        "width": layout.width,
        "depth": layout.depth,
        "height": layout.height,
        "entrance": {
            "wall": layout.door.wall,
            "center": layout.door.center,
            "width": layout.door.width,
        },
        "rooms": rooms,
        "doors": doors,
        "objects": [
            {
                "type": o.type,
                "id": o.id,
                "position": list(o.position),
                "yaw": o.yaw,
                "size": list(o.size),
                "room": layout.room_of.get(o.id, 0),
                "support": layout.support.get(o.id),
            }
            for o in layout.objects
        ],
    }


def visible_rooms(layout: RoomLayout, x: float, y: float) -> frozenset[int] | None:
    """The rooms a camera at (x, y) can see into, by 2-D portal visibility: its own room, and
    every room seen through a chain of door openings (each opening narrowed to the angular
    wedge of the openings before it). Exact in plan for rectangular rooms and conservative in
    height (an opening counts as full height). None where it cannot tell (not inside a room:
    in a doorway or a wall), meaning every room."""
    start = room_at(layout, x, y)
    if start is None:
        return None
    doors: dict[int, list[tuple[int, Passage]]] = {r.index: [] for r in layout.rooms}
    for k, p in enumerate(layout.doors):
        a, b = p.rooms
        if b >= 0:
            doors[a].append((k, p))
            doors[b].append((k, p))
    seen = {start}

    def ends(p: Passage) -> tuple[np.ndarray, np.ndarray]:
        c = np.asarray(p.center, float)
        d = np.array([p.width / 2, 0.0]) if p.axis == "x" else np.array([0.0, p.width / 2])
        return c - d, c + d

    def angle(q: np.ndarray, ref: float) -> float:
        a = math.atan2(q[1] - y, q[0] - x) - ref
        return wrap_angle(a)

    def walk(room: int, lo: float, hi: float, ref: float, used: frozenset[int]) -> None:
        for k, p in doors[room]:
            if k in used:
                continue
            q0, q1 = ends(p)
            a0, a1 = sorted((angle(q0, ref), angle(q1, ref)))
            if a1 - a0 > math.pi:  # the opening straddles the back: keep it (conservative)
                a0, a1 = -math.pi, math.pi
            l2, h2 = max(lo, a0), min(hi, a1)
            if l2 < h2:
                other = p.rooms[1] if p.rooms[0] == room else p.rooms[0]
                seen.add(other)
                walk(other, l2, h2, ref, used | {k})

    for k, p in doors[start]:
        q0, q1 = ends(p)
        mid = (q0 + q1) / 2
        # Too close to the opening's line to bound a wedge: everything beyond may show.
        line_dist = abs(mid[1] - y) if p.axis == "x" else abs(mid[0] - x)
        ref = math.atan2(mid[1] - y, mid[0] - x)
        if line_dist < 0.05:
            walk(start, -math.pi, math.pi, ref, frozenset())
            continue
        a0, a1 = sorted((angle(q0, ref), angle(q1, ref)))
        other = p.rooms[1] if p.rooms[0] == start else p.rooms[0]
        seen.add(other)
        walk(other, a0, a1, ref, frozenset({k}))
    return frozenset(seen)


def generate_layout(
    style: WorldStyle, seed: int, catalog: Catalog | None = None, day: int = 0
) -> RoomLayout:
    """The world of a room style (``generate_room``) or a house style (``generate_house``), the
    same for the same (style, seed, day); day 0 is the world as first generated. The
    ``LAYOUTS_KEPT`` worlds asked for last are kept in this process and given again (a world's
    draw, its episodes' searches, their checks and the truth ask for the same worlds in turn)."""
    key = (style, int(seed), int(day), catalog)
    layout = _layouts.get(key)
    if layout is None:
        if isinstance(style, HouseStyle):
            layout = generate_house(style, seed, catalog, day=day)
        else:
            layout = generate_room(style, seed, catalog, day=day)
        _layouts[key] = layout
        if len(_layouts) > LAYOUTS_KEPT:
            _layouts.popitem(last=False)
    _layouts.move_to_end(key)
    return layout


LAYOUTS_KEPT = 64
_layouts: OrderedDict[tuple, RoomLayout] = OrderedDict()


def forget_layouts() -> None:
    """Empty this process's memory of layouts (``generate_layout``)."""
    _layouts.clear()
