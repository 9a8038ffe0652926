"""The room's shell as a composer Arena: floor, four walls with a door gap, a ceiling, lights.

Room frame as in ``envs/layout.py``: the floor is z = 0 and the room spans x in [-w/2, w/2], y in
[-d/2, d/2]. Walls stand just outside that boundary (the interior is exactly the layout's room).

A house (``layout.is_house``) gets its walls from ``envs.floorplan.wall_boxes`` (outer and
interior walls, a gap and a lintel at every door), one floor per room in its style's colour, one
ceiling and a dim light over each of the largest rooms.

Geom groups: the floor and walls are group ``ROOM_GEOM_GROUP`` (0); the ceiling and the lintel
over the door are group ``OVERHEAD_GEOM_GROUP`` (3), which the head camera shows and the top-down
overview hides (so the map shows the door gap). Lights
cast no shadows by default (on a CPU shadows cost about 8x per frame); ``World(shadows=True)``
turns them on at run time.

Physics options chosen for cheap stepping: the robot's joints are the only degrees of freedom and
nothing collides, so contacts are disabled and the servos run with ``implicitfast`` at a 10 ms
step.
"""

from __future__ import annotations

import os
import zlib

os.environ.setdefault("MUJOCO_GL", "egl")  # before dm_control/mujoco are first imported

from dm_control import composer, mjcf

from ctxsearch.envs.floorplan import wall_boxes as house_wall_boxes
from ctxsearch.envs.layout import RoomLayout

ROOM_GEOM_GROUP = 0
OVERHEAD_GEOM_GROUP = 3
WALL_THICKNESS = 0.1  # m
DOOR_HEIGHT = 2.1  # m
PHYSICS_TIMESTEP = 0.01  # s
MAX_IMAGE_SIZE = (1280, 960)  # off-screen framebuffer (width, height): the largest image rendered
# OpenGL's fixed pipeline has 8 lights and MuJoCo's headlight is one of them: the three key
# lights plus one per room, largest rooms first (an 8th light fails the context with GL error 0x500).
MAX_LIGHTS = 7
VIEW_EXTENT = 10.0  # m: fixed model extent, so znear/zfar below are metric and room-independent

_FLOOR_RGB = ((0.62, 0.58, 0.52), (0.56, 0.52, 0.47))
# Two oblique key lights from above and a weak upward "bounce" light: (name, direction, grey)
KEY_LIGHTS = (
    ("key0", (0.5, 0.3, -0.8), 0.45),
    ("key1", (-0.4, -0.55, -0.75), 0.40),
    ("bounce", (0.1, 0.2, 1.0), 0.22),
)
WALL_RGBA = (0.86, 0.85, 0.80, 1.0)
CEILING_RGBA = (0.93, 0.93, 0.92, 1.0)


class RoomArena(composer.Arena):
    """Floor, walls with a door gap, ceiling and lights, sized per layout by ``set_layout``."""

    def _build(self, name: str = "room") -> None:
        super()._build(name=name)
        root = self._mjcf_root
        root.option.timestep = PHYSICS_TIMESTEP
        root.option.integrator = "implicitfast"
        root.option.flag.contact = "disable"
        root.statistic.extent = VIEW_EXTENT
        root.statistic.center = [0, 0, 1]
        vis = root.visual
        vis.__getattr__("global").offwidth = MAX_IMAGE_SIZE[0]
        vis.__getattr__("global").offheight = MAX_IMAGE_SIZE[1]
        vis.__getattr__("global").fovy = 45
        vis.map.znear = 0.03 / VIEW_EXTENT  # 3 cm
        vis.map.zfar = 60.0 / VIEW_EXTENT  # 60 m
        # No multisampling: on llvmpipe it doubles the cost of every frame (segmentation and
        # depth included) and makes each renderer's context 10x slower to create.
        vis.quality.offsamples = 0
        vis.quality.shadowsize = 1024  # used only with World(shadows=True)
        vis.headlight.ambient = [0.32, 0.32, 0.32]
        vis.headlight.diffuse = [0.28, 0.28, 0.28]
        vis.headlight.specular = [0, 0, 0]
        root.default.geom.set_attributes(contype=0, conaffinity=0)

        root.asset.add(
            "texture",
            name="floor",
            type="2d",
            builtin="checker",
            width=256,
            height=256,
            rgb1=_FLOOR_RGB[0],
            rgb2=_FLOOR_RGB[1],
            mark="edge",
            markrgb=[0.5, 0.47, 0.42],
        )
        floor_mat = root.asset.add(
            "material",
            name="floor",
            texture="floor",
            texrepeat=[1, 1],
            texuniform=True,
            reflectance=0.0,
            specular=0.1,
        )
        self._floor = root.worldbody.add(
            "geom",
            name="floor",
            type="plane",
            size=[5, 5, 0.1],
            material=floor_mat,
            group=ROOM_GEOM_GROUP,
        )
        root.asset.add(
            "texture",
            name="sky",
            type="skybox",
            builtin="gradient",
            width=64,
            height=64,
            rgb1=[0.80, 0.84, 0.88],
            rgb2=[0.55, 0.58, 0.62],
        )
        # Two oblique key lights from above and a weak upward "bounce" light for the ceiling and
        # the undersides of table tops (MuJoCo lights pass through geometry when unshadowed).
        self._lights = [
            root.worldbody.add(
                "light",
                name=name,
                directional=True,
                castshadow=False,
                pos=[0, 0, 3],
                dir=list(d),
                diffuse=[c] * 3,
                specular=[0.05] * 3,
            )
            for name, d, c in KEY_LIGHTS
        ]
        self._shell: list[mjcf.Element] = []
        self._layout: RoomLayout | None = None

    @property
    def layout(self) -> RoomLayout | None:
        """The layout the shell is sized for (None before ``set_layout``)."""
        return self._layout

    def set_layout(self, layout: RoomLayout) -> None:
        """Resize the floor, rebuild the walls (door gap included) and ceiling for ``layout``."""
        for el in self._shell:
            el.remove()
        self._shell = []
        self._layout = layout
        if layout.is_house:
            self._set_house(layout)
            return
        self._floor.pos = None
        hw, hd, h = layout.width / 2, layout.depth / 2, layout.height
        self._floor.size = [hw + WALL_THICKNESS, hd + WALL_THICKNESS, 0.1]
        for light in self._lights:
            light.pos = [0, 0, h]
        self._add_walls(_wall_boxes(layout))
        self._add_ceiling(hw, hd, h, WALL_THICKNESS)

    def _set_house(self, layout: RoomLayout) -> None:
        """The shell of a house: the outer and interior walls with their door openings (lintels
        overhead), one floor per room in its style's colour, one ceiling, a dim light per room.

        Kept cheap: every wall run between two openings is one box, the ceiling is one box,
        and the per-room lights are few (see ``MAX_LIGHTS``)."""
        hw, hd, h, t = layout.width / 2, layout.depth / 2, layout.height, WALL_THICKNESS
        # The rooms' floors cover the whole plan (under the walls too); the base floor is not
        # needed: shrunk out of sight (drawing a plane costs in proportion to its area).
        self._floor.size = [0.01, 0.01, 0.1]
        self._floor.pos = [0, 0, -0.01]
        for light in self._lights:
            light.pos = [0, 0, h]
        self._add_walls(house_wall_boxes(layout, t, DOOR_HEIGHT))
        self._add_room_floors(layout, hw, hd, t)
        self._add_room_lights(layout, h)
        self._add_ceiling(hw, hd, h, t)

    def _add_walls(self, boxes) -> None:
        """One box geom per (name, centre, half extents); lintels over doors are overhead."""
        wb = self._mjcf_root.worldbody
        for name, center, half in boxes:
            group = OVERHEAD_GEOM_GROUP if name.endswith("lintel") else ROOM_GEOM_GROUP
            self._shell.append(
                wb.add(
                    "geom",
                    name=name,
                    type="box",
                    pos=center,
                    size=half,
                    rgba=WALL_RGBA,
                    group=group,
                )  # fmt: skip
            )

    def _add_ceiling(self, hw: float, hd: float, h: float, t: float) -> None:
        """One box over the whole plan."""
        self._shell.append(
            self._mjcf_root.worldbody.add(
                "geom",
                name="ceiling",
                type="box",
                pos=[0, 0, h + t / 2],
                size=[hw + t, hd + t, t / 2],
                rgba=CEILING_RGBA,
                group=OVERHEAD_GEOM_GROUP,
            )
        )

    def _floor_material(self, style: str, k: int) -> mjcf.Element:
        """A checker floor material in the colour of room style ``style`` (the k-th one)."""
        root = self._mjcf_root
        rgb = room_floor_rgb(style)
        tex = root.asset.add(
            "texture",
            name=f"house_floor{k}",
            type="2d",
            builtin="checker",
            width=64,
            height=64,
            rgb1=rgb,
            rgb2=[0.92 * c for c in rgb],
            mark="edge",
            markrgb=[0.8 * c for c in rgb],
        )
        mat = root.asset.add(
            "material",
            name=f"house_floor{k}",
            texture=tex,
            texrepeat=[1, 1],
            texuniform=True,
            reflectance=0.0,
            specular=0.1,
        )
        self._shell += [tex, mat]
        return mat

    def _add_room_floors(self, layout: RoomLayout, hw: float, hd: float, t: float) -> None:
        """One floor plane per room, one material per room style."""
        materials: dict[str, mjcf.Element] = {}
        for room in layout.rooms:
            if room.style not in materials:
                materials[room.style] = self._floor_material(room.style, len(materials))
            x0, y0, x1, y1 = floor_rect(room.outline, hw, hd, t)
            self._shell.append(
                self._mjcf_root.worldbody.add(
                    "geom",
                    name=f"floor_room{room.index}",
                    type="plane",
                    pos=[(x0 + x1) / 2, (y0 + y1) / 2, 0.0],
                    size=[(x1 - x0) / 2, (y1 - y0) / 2, 0.1],
                    material=materials[room.style],
                    group=ROOM_GEOM_GROUP,
                )
            )

    def _add_room_lights(self, layout: RoomLayout, h: float) -> None:
        """A dim light over each of the largest rooms (at most ``MAX_LIGHTS`` lights in all)."""
        largest = sorted(layout.rooms, key=lambda r: -r.area)[: MAX_LIGHTS - len(self._lights)]
        for room in sorted(largest, key=lambda r: r.index):
            cx, cy = room.center
            self._shell.append(
                self._mjcf_root.worldbody.add(
                    "light",
                    name=f"room_light{room.index}",
                    directional=False,
                    castshadow=False,
                    pos=[cx, cy, h - 0.3],
                    dir=[0, 0, -1],
                    diffuse=[0.12] * 3,
                    specular=[0.0] * 3,
                    attenuation=[1.0, 0.05, 0.0],
                )
            )


def floor_rect(
    outline: tuple[float, float, float, float], hw: float, hd: float, t: float
) -> tuple[float, float, float, float]:
    """A room's floor: its outline grown to the centre line of each inner wall (so neighbouring
    floors meet under the wall and fill its door openings) and under the outer walls."""
    x0, y0, x1, y1 = outline
    e = 1e-6
    return (
        x0 - (t if x0 < -hw + e else t / 2),
        y0 - (t if y0 < -hd + e else t / 2),
        x1 + (t if x1 > hw - e else t / 2),
        y1 + (t if y1 > hd - e else t / 2),
    )


def room_floor_rgb(style: str) -> list[float]:
    """A floor colour per room style: the common ones by name, others from the name's hash."""
    known = {
        "kitchen": (0.78, 0.78, 0.74),
        "living_room": (0.62, 0.48, 0.34),
        "bedroom": (0.70, 0.58, 0.44),
        "office": (0.50, 0.55, 0.60),
        "biology_lab": (0.80, 0.84, 0.82),
        "corridor": (0.58, 0.56, 0.52),
    }
    if style in known:
        return list(known[style])
    h = zlib.crc32(style.encode("utf-8"))
    return [0.45 + 0.35 * ((h >> s) & 0xFF) / 255 for s in (0, 8, 16)]


def _wall_boxes(layout: RoomLayout) -> list[tuple[str, list[float], list[float]]]:
    """(name, centre, half extents) of every wall box: two pieces and a lintel at the door."""
    hw, hd, h, t = layout.width / 2, layout.depth / 2, layout.height, WALL_THICKNESS
    door = layout.door
    # Each wall: (name, along-axis 'x' or 'y', span lo..hi along it, fixed coordinate of its centre).
    walls = {
        "north": ("x", -hw - t, hw + t, hd + t / 2),
        "south": ("x", -hw - t, hw + t, -hd - t / 2),
        "east": ("y", -hd, hd, hw + t / 2),
        "west": ("y", -hd, hd, -hw - t / 2),
    }
    out = []
    for name, (axis, lo, hi, fixed) in walls.items():
        if door.wall == name:
            g0, g1 = door.center - door.width / 2, door.center + door.width / 2
            pieces = [(f"wall_{name}_a", lo, g0, 0.0, h), (f"wall_{name}_b", g1, hi, 0.0, h)]
            if h > DOOR_HEIGHT:
                pieces.append((f"wall_{name}_lintel", g0, g1, DOOR_HEIGHT, h))
        else:
            pieces = [(f"wall_{name}", lo, hi, 0.0, h)]
        for pname, a, b, z0, z1 in pieces:
            if b - a < 1e-3:
                continue
            mid, half_len = (a + b) / 2, (b - a) / 2
            if axis == "x":
                center, half = [mid, fixed, (z0 + z1) / 2], [half_len, t / 2, (z1 - z0) / 2]
            else:
                center, half = [fixed, mid, (z0 + z1) / 2], [t / 2, half_len, (z1 - z0) / 2]
            out.append((pname, center, half))
    return out
