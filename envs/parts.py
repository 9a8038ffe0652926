"""What every catalog shape is made of: solid parts and support surfaces (pure numpy, no MuJoCo).

This is the single description of an object's geometry. The room generator uses it to keep
objects from interpenetrating and to know where small objects can rest; the MuJoCo builder turns
the same parts into geoms; navigation uses the world-frame parts as obstacles. So ground truth,
rendering and motion agree.

Conventions (as in ``knowledge/catalog.py``): the object frame's origin is the centre of the
bounding box, +x is the object's FRONT, +y its LEFT, +z up; ``size`` is the full extent (sx, sy,
sz). Every part lies inside the bounding box [-size/2, size/2]. The floor under a floor-standing
object is at local z = -sz/2.

A ``Part`` is a box (``geom='box'``, half extents ``half``) or an upright cylinder
(``geom='cylinder'``, radius ``half[0]`` (= ``half[1]``), half-height ``half[2]``).
``color_scale`` multiplies the type's colour (legs darker, screens black...); ``color``, when
set, replaces it (a terracotta pot under green foliage).

Shapes and their fronts:
- desk: top board + 4 legs, a hanging drawer block on the right (-y) when the desk is at least
  1.35 m wide; the knee space is open. Front (+x) is where one sits.
- table: top board + 4 legs.  chair: seat, 4 legs, backrest on the -x side (front +x faces away
  from the backrest).
- shelf: 2 side boards, a back board (-x), 3-5 horizontal boards, open front (+x).
- cabinet / counter: a solid body with a top slab (counter: recessed toe kick, overhanging top).
- sofa: base, back (-x), two arms.  bed: frame, mattress, headboard (-x); the foot is +x.
- monitor: base plate, neck, screen facing +x.  laptop: base, lid facing +x.
- keyboard: a plate and a key block.  microscope: base, pillar (-x), arm, stage, eyepiece.
- plant: pot (cylinder) + foliage (box).  mug / cylinder: one cylinder.  bottle: body + neck.
- box: one box.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ctxsearch.knowledge.catalog import SHAPES, Catalog, load_catalog
from ctxsearch.knowledge.geometry import Box, BoxArray, ObjectInstance

Vec3 = tuple[float, float, float]

BOARD = 0.02  # m, shelf board thickness
TOP = 0.04  # m, desk/table top thickness
LEG = 0.05  # m, desk/table leg side


@dataclass(frozen=True)
class Part:
    """One solid piece of an object, in the object's frame (origin = bounding-box centre)."""

    name: str
    center: Vec3
    half: Vec3
    geom: str = "box"  # 'box' or 'cylinder' (radius = half[0] = half[1], half-height = half[2])
    color_scale: float = 1.0
    color: Vec3 | None = None  # replaces the type colour when set

    @property
    def lo(self) -> np.ndarray:
        """The part's lower corner (3,)."""
        return np.asarray(self.center) - np.asarray(self.half)

    @property
    def hi(self) -> np.ndarray:
        """The part's upper corner (3,)."""
        return np.asarray(self.center) + np.asarray(self.half)


@dataclass(frozen=True)
class Surface:
    """A horizontal surface something can rest on, in the object's frame.

    ``center`` is at the surface height, ``half_xy`` its half extents along local x and y,
    ``clearance`` the free height above it (metres).
    """

    center: Vec3
    half_xy: tuple[float, float]
    clearance: float


def _box(name: str, lo, hi, color_scale: float = 1.0, color: Vec3 | None = None) -> Part:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c, h = (lo + hi) / 2, (hi - lo) / 2
    return Part(
        name, tuple(float(v) for v in c), tuple(float(v) for v in h), "box", color_scale, color
    )


def _cyl(
    name: str,
    cx: float,
    cy: float,
    zlo: float,
    zhi: float,
    r: float,
    color_scale: float = 1.0,
    color: Vec3 | None = None,
) -> Part:
    return Part(
        name,
        (float(cx), float(cy), float((zlo + zhi) / 2)),
        (float(r), float(r), float((zhi - zlo) / 2)),
        "cylinder",
        color_scale,
        color,
    )


def _legs(
    lo: tuple[float, float, float],
    hi: tuple[float, float, float],
    t: float,
    scale: float = 0.7,
    prefix: str = "leg",
) -> list[Part]:
    """Four square legs of side t in the corners of [x0,x1] x [y0,y1], from z0 to z1 (``lo`` =
    (x0, y0, z0), ``hi`` = (x1, y1, z1))."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    out = []
    for i, (xa, ya) in enumerate(((x1 - t, y1 - t), (x1 - t, y0), (x0, y1 - t), (x0, y0))):
        out.append(_box(f"{prefix}{i}", (xa, ya, z0), (xa + t, ya + t, z1), scale))
    return out


def shelf_board_count(sz: float) -> int:
    """How many horizontal boards a shelf of height sz has (3 to 5, bottom and top included)."""
    return int(np.clip(round(sz / 0.4), 3, 5))


def desk_has_drawer(sy: float) -> bool:
    """Desks at least 1.35 m wide get a hanging drawer block on their right (-y) side."""
    return sy >= 1.35


def _desk(sx, sy, sz, *, drawer: bool) -> list[Part]:
    X, Y, Z = sx / 2, sy / 2, sz / 2
    t = min(TOP, sz * 0.1)
    leg = min(LEG, sx * 0.15, sy * 0.15)
    parts = [_box("top", (-X, -Y, Z - t), (X, Y, Z))]
    parts += _legs((-X + 0.02, -Y + 0.02, -Z), (X - 0.02, Y - 0.02, Z - t), leg)
    if drawer and desk_has_drawer(sy):
        dy = min(0.42, sy * 0.3)
        dz = min(0.25, (sz - t) * 0.4)
        y0 = -Y + 0.02 + leg
        parts.append(
            _box("drawer", (-X + 0.02 + leg, y0, Z - t - dz), (X - 0.03, y0 + dy, Z - t), 0.85)
        )
    return parts


def _chair(sx, sy, sz) -> list[Part]:
    X, Y, Z = sx / 2, sy / 2, sz / 2
    seat_top = -Z + min(0.46, sz * 0.5)
    st = 0.05
    back_t = min(0.05, sx * 0.15)
    leg = min(0.04, sx * 0.1, sy * 0.1)
    parts = [_box("seat", (-X, -Y, seat_top - st), (X, Y, seat_top))]
    parts += _legs((-X, -Y, -Z), (X, Y, seat_top - st), leg, 0.6)
    parts.append(_box("back", (-X, -Y, seat_top), (-X + back_t, Y, Z), 0.9))
    return parts


def _shelf(sx, sy, sz) -> list[Part]:
    X, Y, Z = sx / 2, sy / 2, sz / 2
    t = BOARD
    parts = [
        _box("side_l", (-X, Y - t, -Z), (X, Y, Z), 0.85),
        _box("side_r", (-X, -Y, -Z), (X, -Y + t, Z), 0.85),
        _box("back", (-X, -Y + t, -Z), (-X + t, Y - t, Z), 0.75),
    ]
    n = shelf_board_count(sz)
    for k in range(n):
        b = -Z + k * (sz - t) / (n - 1)
        parts.append(_box(f"board{k}", (-X + t, -Y + t, b), (X, Y - t, b + t)))
    return parts


def _shelf_surfaces(sx, sy, sz) -> list[Surface]:
    Z = sz / 2
    t = BOARD
    n = shelf_board_count(sz)
    spacing = (sz - t) / (n - 1)
    out = []
    for k in range(n - 1):  # the top board's upper face is the shelf's top, not "on the shelf"
        z = -Z + k * spacing + t
        out.append(Surface((t / 2, 0.0, z), ((sx - t) / 2, sy / 2 - t), spacing - t))
    return out


def _cabinet(sx, sy, sz, *, counter: bool) -> list[Part]:
    X, Y, Z = sx / 2, sy / 2, sz / 2
    top_t = min(0.04 if counter else 0.03, sz * 0.1)
    over = min(0.03, sx * 0.1)  # the top overhangs the front
    if counter:
        kick_h, kick_d = min(0.1, sz * 0.12), min(0.07, sx * 0.15)
        return [
            _box("toe_kick", (-X, -Y, -Z), (X - over - kick_d, Y, -Z + kick_h), 0.4),
            _box("body", (-X, -Y, -Z + kick_h), (X - over, Y, Z - top_t), 0.9),
            _box("top", (-X, -Y, Z - top_t), (X, Y, Z), 1.15),
        ]
    return [
        _box("body", (-X, -Y, -Z), (X - over, Y, Z - top_t), 0.9),
        _box("top", (-X, -Y, Z - top_t), (X, Y, Z)),
        _box(
            "handle",
            (X - over, -0.02, Z - top_t - min(0.2, sz * 0.2)),
            (X - over + min(0.02, over), 0.02, Z - top_t - min(0.05, sz * 0.05)),
            0.4,
        ),
    ]


def _sofa_dims(sx, sy, sz) -> tuple[float, float, float]:
    """(seat height above the floor, back depth, arm width) of a sofa."""
    return min(0.42, sz * 0.5), min(0.2, sx * 0.25), min(0.15, sy * 0.1)


def _sofa(sx, sy, sz) -> list[Part]:
    X, Y, Z = sx / 2, sy / 2, sz / 2
    seat, back, arm = _sofa_dims(sx, sy, sz)
    arm_h = min(0.62, sz * 0.75)
    return [
        _box("base", (-X + back, -Y + arm, -Z), (X, Y - arm, -Z + seat)),
        _box("back", (-X, -Y + arm, -Z), (-X + back, Y - arm, Z), 0.85),
        _box("arm_l", (-X, Y - arm, -Z), (X, Y, -Z + arm_h), 0.8),
        _box("arm_r", (-X, -Y, -Z), (X, -Y + arm, -Z + arm_h), 0.8),
    ]


def _bed_dims(sx, sy, sz) -> tuple[float, float, float]:
    """(frame height, mattress top height above the floor, headboard thickness) of a bed."""
    frame = min(0.3, sz * 0.3)
    return frame, min(0.5, sz * 0.55), min(0.06, sx * 0.05)


def _bed(sx, sy, sz) -> list[Part]:
    X, Y, Z = sx / 2, sy / 2, sz / 2
    frame, mattress, head = _bed_dims(sx, sy, sz)
    return [
        _box("frame", (-X + head, -Y, -Z), (X, Y, -Z + frame), 0.6),
        _box(
            "mattress",
            (-X + head, -Y + 0.02, -Z + frame),
            (X - 0.02, Y - 0.02, -Z + mattress),
            color=(0.92, 0.92, 0.95),
        ),
        _box("headboard", (-X, -Y, -Z), (-X + head, Y, Z), 0.6),
    ]


def _monitor(sx, sy, sz) -> list[Part]:
    X, Y, Z = sx / 2, sy / 2, sz / 2
    plate_t = min(0.02, sz * 0.05)
    neck_x0 = -X + min(0.03, sx * 0.15)
    neck_x1 = neck_x0 + min(0.04, sx * 0.2)
    screen_t = min(0.03, sx * 0.15)
    screen_z0 = -Z + min(0.08, sz * 0.2)
    inset = min(0.015, (Z - screen_z0) * 0.2, Y * 0.1)
    return [
        _box("base", (-X, -min(0.12, Y), -Z), (X, min(0.12, Y), -Z + plate_t), 0.8),
        _box(
            "neck",
            (neck_x0, -min(0.03, Y), -Z + plate_t),
            (neck_x1, min(0.03, Y), min(screen_z0 + 0.05, Z)),
            0.8,
        ),
        _box("screen", (neck_x1, -Y, screen_z0), (neck_x1 + screen_t, Y, Z)),
        _box(
            "display",
            (neck_x1 + screen_t, -Y + inset, screen_z0 + inset),
            (min(X, neck_x1 + screen_t + 0.002), Y - inset, Z - inset),
            color=(0.12, 0.22, 0.38),
        ),
    ]


def _laptop(sx, sy, sz) -> list[Part]:
    X, Y, Z = sx / 2, sy / 2, sz / 2
    base_t = min(0.02, sz * 0.15)
    lid_t = min(0.012, sx * 0.08)
    return [
        _box("base", (-X, -Y, -Z), (X, Y, -Z + base_t)),
        _box("lid", (-X, -Y, -Z + base_t), (-X + lid_t, Y, Z)),
        _box(
            "display",
            (-X + lid_t, -Y + 0.01, -Z + base_t + 0.01),
            (-X + lid_t + 0.002, Y - 0.01, Z - 0.01),
            color=(0.12, 0.22, 0.38),
        ),
    ]


def _keyboard(sx, sy, sz) -> list[Part]:
    X, Y, Z = sx / 2, sy / 2, sz / 2
    plate = sz * 0.5
    return [
        _box("plate", (-X, -Y, -Z), (X, Y, -Z + plate)),
        _box("keys", (-X + 0.01, -Y + 0.01, -Z + plate), (X - 0.01, Y - 0.01, Z), 1.6),
    ]


def _microscope(sx, sy, sz) -> list[Part]:
    X, Y, Z = sx / 2, sy / 2, sz / 2
    pillar = min(0.06, sx * 0.25)
    stage_z = -Z + sz * 0.4
    return [
        _box("base", (-X, -Y, -Z), (X, Y, -Z + 0.08 * sz), 0.5),
        _box(
            "pillar",
            (-X, -min(0.04, Y), -Z + 0.08 * sz),
            (-X + pillar, min(0.04, Y), Z - 0.08 * sz),
        ),
        _box(
            "stage",
            (-X + pillar, -Y * 0.8, stage_z - 0.03 * sz),
            (X * 0.7, Y * 0.8, stage_z + 0.03 * sz),
            0.4,
        ),
        _box(
            "arm",
            (-X + pillar, -min(0.03, Y), Z - 0.22 * sz),
            (X * 0.3, min(0.03, Y), Z - 0.08 * sz),
        ),
        _cyl("eyepiece", -X + pillar * 1.5, 0.0, Z - 0.08 * sz, Z, min(0.02, pillar / 2), 0.5),
        _cyl(
            "objective", X * 0.15, 0.0, stage_z + 0.1 * sz, Z - 0.22 * sz, min(0.015, X * 0.15), 0.6
        ),
    ]


def _plant(sx, sy, sz) -> list[Part]:
    r = min(sx, sy) / 2
    pot_h = sz * 0.4
    Z = sz / 2
    return [
        _cyl("pot", 0.0, 0.0, -Z, -Z + pot_h, r * 0.7, color=(0.65, 0.33, 0.20)),
        _box("foliage", (-sx / 2, -sy / 2, -Z + pot_h), (sx / 2, sy / 2, Z)),
    ]


def _bottle(sx, sy, sz) -> list[Part]:
    r = min(sx, sy) / 2
    Z = sz / 2
    neck_z = Z - sz * 0.3
    return [
        _cyl("body", 0.0, 0.0, -Z, neck_z, r),
        _cyl("neck", 0.0, 0.0, neck_z, Z, r * 0.4, 0.8),
    ]


def solid_parts(shape: str, size) -> list[Part]:
    """The solid parts of an object of ``shape`` and full ``size`` (sx, sy, sz), object frame."""
    sx, sy, sz = (float(v) for v in size)
    X, Y, Z = sx / 2, sy / 2, sz / 2
    if shape == "desk":
        return _desk(sx, sy, sz, drawer=True)
    if shape == "table":
        return _desk(sx, sy, sz, drawer=False)
    if shape == "chair":
        return _chair(sx, sy, sz)
    if shape == "shelf":
        return _shelf(sx, sy, sz)
    if shape in ("cabinet", "counter"):
        return _cabinet(sx, sy, sz, counter=shape == "counter")
    if shape == "sofa":
        return _sofa(sx, sy, sz)
    if shape == "bed":
        return _bed(sx, sy, sz)
    if shape == "monitor":
        return _monitor(sx, sy, sz)
    if shape == "laptop":
        return _laptop(sx, sy, sz)
    if shape == "keyboard":
        return _keyboard(sx, sy, sz)
    if shape == "microscope":
        return _microscope(sx, sy, sz)
    if shape == "plant":
        return _plant(sx, sy, sz)
    if shape == "bottle":
        return _bottle(sx, sy, sz)
    if shape in ("mug", "cylinder"):
        return [_cyl("body", 0.0, 0.0, -Z, Z, min(X, Y))]
    if shape == "box":
        return [_box("body", (-X, -Y, -Z), (X, Y, Z))]
    raise ValueError(f"no parts for shape '{shape}' (known: {', '.join(SHAPES)})")


def support_surfaces(shape: str, size) -> list[Surface]:
    """Where things can rest on an object of ``shape`` and ``size``, in the object's frame.

    Desk/table/cabinet/counter tops, every shelf board below the top one (clearance = the free
    height up to the next board), sofa and bed seats, chair seats, and the top of a plain box
    (books stack). Other small objects have none.
    """
    sx, sy, sz = (float(v) for v in size)
    X, Z = sx / 2, sz / 2
    if shape in ("desk", "table", "cabinet", "counter"):
        return [Surface((0.0, 0.0, Z), (X, sy / 2), 1.0)]
    if shape == "shelf":
        return _shelf_surfaces(sx, sy, sz)
    if shape == "chair":
        seat_top = -Z + min(0.46, sz * 0.5)
        back_t = min(0.05, sx * 0.15)
        return [Surface((back_t / 2, 0.0, seat_top), ((sx - back_t) / 2, sy / 2), Z - seat_top)]
    if shape == "sofa":
        seat, back, arm = _sofa_dims(sx, sy, sz)
        return [Surface((back / 2, 0.0, -Z + seat), ((sx - back) / 2, sy / 2 - arm), 0.5)]
    if shape == "bed":
        _, mattress, head = _bed_dims(sx, sy, sz)
        return [
            Surface(
                ((head - 0.02) / 2, 0.0, -Z + mattress),
                ((sx - head - 0.02) / 2, sy / 2 - 0.02),
                0.6,
            )
        ]
    if shape == "box":
        return [Surface((0.0, 0.0, Z), (X, sy / 2), 0.3)]
    if shape in SHAPES:
        return []
    raise ValueError(f"no surfaces for shape '{shape}' (known: {', '.join(SHAPES)})")


@functools.lru_cache(maxsize=1)
def _default_catalog() -> Catalog:
    return load_catalog()


def _shape_of(obj: ObjectInstance, catalog: Catalog | None) -> str:
    return (catalog or _default_catalog()).type(obj.type).shape


# Sizes are drawn per object, so entries are useful within one room only (its generator asks for
# the same object many times): a small cache keeps memory flat over many rooms.
@functools.lru_cache(maxsize=512)
def _local_parts_array(
    shape: str, size: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray]:
    parts = solid_parts(shape, size)
    return np.array([p.center for p in parts], float), np.array([p.half for p in parts], float)


def world_parts_array(obj: ObjectInstance, catalog: Catalog | None = None) -> BoxArray:
    """``world_parts`` packed as a BoxArray (cylinders as their bounding boxes)."""
    centers, halves = _local_parts_array(_shape_of(obj, catalog), tuple(float(v) for v in obj.size))
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    w = np.empty_like(centers)
    w[:, 0] = obj.position[0] + c * centers[:, 0] - s * centers[:, 1]
    w[:, 1] = obj.position[1] + s * centers[:, 0] + c * centers[:, 1]
    w[:, 2] = obj.position[2] + centers[:, 2]
    return BoxArray(w, np.full(len(w), float(obj.yaw)), halves.copy())


def world_parts(obj: ObjectInstance, catalog: Catalog | None = None) -> list[Box]:
    """The object's solid parts as world-frame boxes (cylinders as their bounding boxes).

    Used for interpenetration checks and as navigation obstacles. ``catalog`` gives the type's
    shape (default: ``assets/types.toml``).
    """
    arr = world_parts_array(obj, catalog)
    return [Box(arr.centers[i], float(arr.yaws[i]), arr.halves[i]) for i in range(len(arr))]


@dataclass(frozen=True)
class WorldSurface:
    """A support surface in world coordinates: its owner's id, centre (at the surface height),
    yaw, half extents along the owner's x and y, and free height above it."""

    owner: int
    center: tuple[float, float, float]
    yaw: float
    half_xy: tuple[float, float]
    clearance: float

    @property
    def area(self) -> float:
        """The surface's area in square metres."""
        return 4.0 * self.half_xy[0] * self.half_xy[1]


def world_surfaces(obj: ObjectInstance, catalog: Catalog | None = None) -> list[WorldSurface]:
    """The object's support surfaces in world coordinates."""
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    out = []
    for surf in support_surfaces(_shape_of(obj, catalog), obj.size):
        lx, ly, lz = surf.center
        out.append(
            WorldSurface(
                owner=obj.id,
                center=(
                    obj.position[0] + c * lx - s * ly,
                    obj.position[1] + s * lx + c * ly,
                    obj.position[2] + lz,
                ),
                yaw=float(obj.yaw),
                half_xy=surf.half_xy,
                clearance=surf.clearance,
            )
        )
    return out
