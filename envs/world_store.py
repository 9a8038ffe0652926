"""A world's MuJoCo model made once: kept in this process and in the user's cache directory.

Building a world through dm_control's MJCF elements costs about 50-100 ms in a house (every
element and attribute is a Python object, written out as XML attribute by attribute), compiling
its XML about 4 ms, generating its layout about 25 ms. ``world_model(layout, catalog, spec)``
gives the compiled model of a layout's world and makes it once:

- the XML is ``envs.task.RoomTask``'s, byte for byte, written as text: the robot's and the
  arena's fixed elements from dm_control's once per robot (``_template``), the layout's walls,
  floors, lights and ceiling (``_layout_elements``, kept per shell: the days of a house and its
  episodes' layouts share one) and its furniture and small objects (``envs.entities.objects_xml``)
  written directly, the same bytes as the elements give (tested in every style);
- the compiled model is kept in this process (``MEMO_WORLDS`` worlds, most recent first); each
  World gets a copy of it (``mj_copyModel``: a World changes its model's colours and lights);
- the XML is kept on disk in the cache directory's ``worlds/`` (``cache_dir``), so a later
  process compiles it instead of building it.

A world is named by a SHA-256 over the format, the source of the packages that build it (``envs``,
``knowledge``) and the versions of MuJoCo and dm_control, the catalog's fingerprint (types, shapes,
sizes, colours), the robot's spec and the layout itself (its ``repr``: every object's type, id,
pose and size, the plan's rooms and doors): a changed generator, catalog or robot is another
name, never a stale world. A file is read back only if it is the world of that name for that
layout (``_fits``): its digest matches its content, it compiles, its furniture and objects are
the layout's exactly (the objects' XML written afresh, a few milliseconds), its walls and ceiling
stand where the layout puts them, it holds no geom besides those, the floors and the robot's, the
robot's joints and camera are there, and the options and view settings the images depend on are
the arena's. Anything else (any bytes, a truncated write, an edit by hand, another world's file)
is a miss: the world is built and the file replaced (written to a temporary file first, then
renamed). The cache directory is ``$CTXSEARCH_CACHE_DIR`` if set (empty: no cache on disk), else
``$XDG_CACHE_HOME/ctxsearch`` (default ``~/.cache/ctxsearch``); ``worlds/`` may be deleted at any
time.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco/dm_control are first imported

import copy
import functools
import hashlib
import json
from collections import OrderedDict
from dataclasses import dataclass, replace
from importlib import metadata
from pathlib import Path

import mujoco
import numpy as np

from ctxsearch.envs.arena import (
    CEILING_RGBA,
    DOOR_HEIGHT,
    KEY_LIGHTS,
    MAX_IMAGE_SIZE,
    MAX_LIGHTS,
    OVERHEAD_GEOM_GROUP,
    PHYSICS_TIMESTEP,
    ROOM_GEOM_GROUP,
    VIEW_EXTENT,
    WALL_RGBA,
    WALL_THICKNESS,
    _wall_boxes,
    floor_rect,
    room_floor_rgb,
)
from ctxsearch.envs.entities import body_name, object_geoms, objects_xml
from ctxsearch.envs.floorplan import wall_boxes as house_wall_boxes
from ctxsearch.envs.layout import Door, RoomLayout
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.envs.task import RoomTask
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.files import (
    InputFileError,
    cache_dir,
    read_json,
    tree_hash,
    write_bytes,
)

FORMAT = 1
MEMO_WORLDS = 16  # compiled worlds kept in this process
MEMO_SHELLS = 16  # shells (arena and robot XML) kept in this process
MAX_WORLD_BYTES = 16 * 2**20  # a family house's world is about 200 kB
EMPTY_OBJECTS = '    <body name="objects/"/>\n'  # the shell's objects entity, with no object
ROBOT_JOINTS = ("x", "y", "yaw", "pan", "tilt")
CAMERA = "robot/head_cam"
_PACKAGES = ("envs", "knowledge")


@dataclass(frozen=True)
class WorldModel:
    """A world's compiled model (``model``: the kept one; a World takes ``copy()``), its XML and
    the robot's own XML as attached to it (``envs.robot.robot_dynamics`` compiles that)."""

    model: mujoco.MjModel
    xml: str
    robot_xml: str

    def copy(self) -> mujoco.MjModel:
        """A copy of the model, the same bit for bit, for one World to change."""
        return copy.copy(self.model)


@functools.cache
def source_digest() -> str:
    """SHA-256 over the source files of the packages that build a world (sorted by path) and
    the versions of MuJoCo and dm_control."""
    h = tree_hash(_PACKAGES)
    h.update(f"mujoco {mujoco.__version__}\ndm_control {metadata.version('dm_control')}".encode())
    return h.hexdigest()


def world_key(layout: RoomLayout, catalog: Catalog, spec: RobotSpec) -> str:
    """The name of the world of ``layout`` with ``catalog`` and the robot ``spec``."""
    h = hashlib.sha256()
    h.update(f"world format {FORMAT}\n{source_digest()}\n{catalog.fingerprint}\n".encode())
    h.update(f"{spec!r}\n{layout!r}".encode())
    return h.hexdigest()[:32]


_worlds: OrderedDict[str, WorldModel] = OrderedDict()
_shells: OrderedDict[str, tuple[str, str]] = OrderedDict()


def world_model(
    layout: RoomLayout,
    catalog: Catalog,
    spec: RobotSpec,
    disk: bool = True,
    directory: Path | None = None,
) -> WorldModel:
    """The world of ``layout`` (module docstring): from this process's memory, else from the
    cache directory (``disk``: ``directory`` if given, else ``cache_dir``), else built and kept
    in both."""
    key = world_key(layout, catalog, spec)
    world = _worlds.get(key)
    if world is None:
        root = (directory or cache_dir()) if disk else None
        path = None if root is None else root / "worlds" / f"{key}.json"
        world = None if path is None else load(path, key, layout, catalog)
        if world is None:
            xml, robot_xml = build_xml(layout, catalog, spec)
            world = WorldModel(mujoco.MjModel.from_xml_string(xml), xml, robot_xml)
            if path is not None:
                save(path, key, world)
        _worlds[key] = world
        if len(_worlds) > MEMO_WORLDS:
            _worlds.popitem(last=False)
    _worlds.move_to_end(key)
    return world


def forget() -> None:
    """Empty this process's memory of worlds and shells (the files on disk stay)."""
    _worlds.clear()
    _shells.clear()


def build_xml(layout: RoomLayout, catalog: Catalog, spec: RobotSpec) -> tuple[str, str]:
    """The world's XML (``RoomTask(catalog, layout=layout, spec=spec)``'s, byte for byte) and
    the robot's own XML as attached to it."""
    shell, robot_xml = _shell(layout, spec)
    return shell.replace(EMPTY_OBJECTS, objects_xml(layout, catalog)), robot_xml


def _shell(layout: RoomLayout, spec: RobotSpec) -> tuple[str, str]:
    """The XML of the layout's world without its objects, and the robot's, kept per shell:
    the robot's and the arena's fixed elements from dm_control's (``_template``, once per robot),
    the layout's walls, floors, lights and ceiling written as ``RoomArena.set_layout`` makes them
    (the same bytes: ``tests/test_world_store.py`` compares them with the composer task's)."""
    bare = replace(layout, objects=(), support={}, placed_by={}, room_of={})
    key = f"{spec!r}\n{bare!r}"
    got = _shells.get(key)
    if got is None:
        got = _shells[key] = _shell_text(bare, spec)
        if len(_shells) > MEMO_SHELLS:
            _shells.popitem(last=False)
    _shells.move_to_end(key)
    return got


def composer_shell(layout: RoomLayout, catalog: Catalog | None, spec: RobotSpec) -> tuple[str, str]:
    """``_shell``'s XML as the composer task writes it, through dm_control's elements."""
    bare = replace(layout, objects=(), support={}, placed_by={}, room_of={})
    task = RoomTask(catalog, layout=bare, spec=spec)
    task.initialize_episode_mjcf(np.random.RandomState(0))  # the rng is not used
    xml = task.root_entity.mjcf_model.to_xml_string()
    if xml.count(EMPTY_OBJECTS) != 1:
        raise RuntimeError("the arena's XML does not hold the objects' entity once")
    return xml, task.robot.mjcf_model.to_xml_string()


# the robot's workspace while the template is made: its numbers are replaced by the layout's
_SENTINEL = (-977.5, 977.5, -988.5, 988.5)


@functools.lru_cache(maxsize=8)
def _template(spec: RobotSpec) -> tuple[str, str, str, str]:
    """The composer task's XML for ``spec`` cut where a layout's elements go: the part before
    the house floors' assets, the robot's body, the part from the objects' entity on, and the
    robot's own XML; their workspace is ``_SENTINEL``'s."""
    x0, x1, y0, y1 = _SENTINEL
    door = Door("north", 0.0, 0.9)
    room = RoomLayout("template", 0, x1 * 2, y1 * 2, 2.5, door, ())
    xml, robot_xml = composer_shell(room, None, spec)
    head, rest = xml.split("  </asset>\n", 1)
    start = rest.index('    <body name="robot/">\n')
    end = rest.index("\n    </body>\n", start) + len("\n    </body>\n")
    return head, rest[start:end], rest[rest.index(EMPTY_OBJECTS) :], robot_xml


def _workspace(text: str, layout: RoomLayout) -> str:
    """``text`` with the template's workspace replaced by ``layout``'s (``RoomTask``)."""
    hw, hd = layout.width / 2, layout.depth / 2
    x0, x1, y0, y1 = _SENTINEL
    for (a, b), (c, d) in (((x0, x1), (-hw, hw)), ((y0, y1), (-hd, hd))):
        text = text.replace(f'range="{_floats((a, b))}"', f'range="{_floats((c, d))}"')
    return text


def _floats(values) -> str:
    return " ".join(f"{float(v):.17g}" for v in values)


def _shell_text(layout: RoomLayout, spec: RobotSpec) -> tuple[str, str]:
    """The composer task's XML of ``layout`` without objects, and the robot's (``_shell``)."""
    head, robot_body, tail, robot_xml = _template(spec)
    assets, elements = _layout_elements(layout)
    t, h = WALL_THICKNESS, layout.height
    if layout.is_house:
        floor = '    <geom name="floor" class="/" type="plane" group="0" size="0.01 0.01 '
        floor += f'{0.1:.17g}" material="floor" pos="0 0 -0.01"/>'
    else:
        size = (layout.width / 2 + t, layout.depth / 2 + t, 0.1)
        floor = f'    <geom name="floor" class="/" type="plane" group="0" size="{_floats(size)}" '
        floor += 'material="floor"/>'
    lights = [
        f'    <light name="{name}" class="/" directional="true" castshadow="false" '
        f'pos="{_floats((0, 0, h))}" dir="{_floats(d)}" diffuse="{_floats([c] * 3)}" '
        f'specular="{_floats([0.05] * 3)}"/>'
        for name, d, c in KEY_LIGHTS
    ]
    xml = "".join(
        [
            head,
            *(line + "\n" for line in assets),
            "  </asset>\n  <worldbody>\n",
            *(line + "\n" for line in (floor, *lights)),
            _workspace(robot_body, layout),
            *(line + "\n" for line in elements),
            _workspace(tail, layout),
        ]
    )
    return xml, _workspace(robot_xml, layout)


def _layout_elements(layout: RoomLayout) -> tuple[list[str], list[str]]:
    """The asset lines (the house floors' textures and materials) and the worldbody lines
    (walls, room floors, room lights, ceiling) ``RoomArena.set_layout`` adds for ``layout``."""
    t, h = WALL_THICKNESS, layout.height
    hw, hd = layout.width / 2, layout.depth / 2
    walls = house_wall_boxes(layout, t, DOOR_HEIGHT) if layout.is_house else _wall_boxes(layout)
    out = [
        _box_line(name, OVERHEAD_GEOM_GROUP if name.endswith("lintel") else ROOM_GEOM_GROUP,
                  half, center, WALL_RGBA)
        for name, center, half in walls
    ]  # fmt: skip
    assets: list[str] = []
    if layout.is_house:
        materials: dict[str, str] = {}
        for room in layout.rooms:
            if room.style not in materials:
                k = materials[room.style] = f"house_floor{len(materials)}"
                rgb = room_floor_rgb(room.style)
                assets += [
                    f'    <texture name="{k}" class="/" type="2d" builtin="checker" '
                    f'rgb1="{_floats(rgb)}" rgb2="{_floats([0.92 * c for c in rgb])}" mark="edge" '
                    f'markrgb="{_floats([0.8 * c for c in rgb])}" width="64" height="64"/>',
                    f'    <material name="{k}" class="/" texture="{k}" texrepeat="1 1" '
                    f'texuniform="true" specular="{0.1:.17g}" reflectance="0"/>',
                ]
            x0, y0, x1, y1 = floor_rect(room.outline, hw, hd, t)
            size, pos = ((x1 - x0) / 2, (y1 - y0) / 2, 0.1), ((x0 + x1) / 2, (y0 + y1) / 2, 0.0)
            out.append(
                f'    <geom name="floor_room{room.index}" class="/" type="plane" group="0" '
                f'size="{_floats(size)}" material="{materials[room.style]}" pos="{_floats(pos)}"/>'
            )
        largest = sorted(layout.rooms, key=lambda r: -r.area)[: MAX_LIGHTS - len(KEY_LIGHTS)]
        for room in sorted(largest, key=lambda r: r.index):
            cx, cy = room.center
            out.append(
                f'    <light name="room_light{room.index}" class="/" directional="false" '
                f'castshadow="false" pos="{_floats((cx, cy, h - 0.3))}" dir="0 0 -1" '
                f'attenuation="{_floats((1.0, 0.05, 0.0))}" diffuse="{_floats([0.12] * 3)}" '
                'specular="0 0 0"/>'
            )
    out.append(
        _box_line("ceiling", OVERHEAD_GEOM_GROUP, (hw + t, hd + t, t / 2), (0, 0, h + t / 2),
                  CEILING_RGBA)
    )  # fmt: skip
    return assets, out


def _box_line(name: str, group: int, size, pos, rgba) -> str:
    return (
        f'    <geom name="{name}" class="/" type="box" group="{group}" size="{_floats(size)}" '
        f'pos="{_floats(pos)}" rgba="{_floats(rgba)}"/>'
    )


def _digest(xml: str, robot_xml: str) -> str:
    return hashlib.sha256(f"{xml}\0{robot_xml}".encode()).hexdigest()


def save(path: Path, key: str, world: WorldModel) -> None:
    """Store ``world``'s XML under ``key`` at ``path`` (atomically; a warning if it cannot)."""
    doc = {
        "format": FORMAT,
        "key": key,
        "sha256": _digest(world.xml, world.robot_xml),
        "xml": world.xml,
        "robot_xml": world.robot_xml,
    }
    write_bytes(path.parent, path.name, json.dumps(doc).encode("utf-8"), "world model")


def load(path: Path, key: str, layout: RoomLayout, catalog: Catalog) -> WorldModel | None:
    """The world kept at ``path`` if it is the world ``key`` of ``layout`` (module docstring),
    compiled; None otherwise."""
    try:
        doc = read_json(path, MAX_WORLD_BYTES)
    except InputFileError:
        return None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or doc.get("key") != key:
        return None
    xml, robot_xml = doc.get("xml"), doc.get("robot_xml")
    if not (isinstance(xml, str) and isinstance(robot_xml, str)):
        return None
    if doc.get("sha256") != _digest(xml, robot_xml):
        return None
    if xml.count(objects_xml(layout, catalog)) != 1:
        return None
    try:
        model = mujoco.MjModel.from_xml_string(xml)
    except (ValueError, mujoco.FatalError):
        return None
    return WorldModel(model, xml, robot_xml) if _fits(model, layout, catalog) else None


def _fits(model: mujoco.MjModel, layout: RoomLayout, catalog: Catalog) -> bool:
    """Whether ``model`` is the world of ``layout`` in everything the images, rays and motions
    read: the arena's options and view settings, the robot's joints and camera, the objects'
    bodies and geoms, the walls and ceiling, and no other geom than those, the floors and the
    robot's."""
    settings = (
        (model.opt.timestep, PHYSICS_TIMESTEP),
        (model.stat.extent, VIEW_EXTENT),
        (model.vis.map.znear, np.float32(0.03 / VIEW_EXTENT)),  # MuJoCo keeps them as float32
        (model.vis.map.zfar, np.float32(60.0 / VIEW_EXTENT)),
        (model.vis.global_.offwidth, MAX_IMAGE_SIZE[0]),
        (model.vis.global_.offheight, MAX_IMAGE_SIZE[1]),
        (model.opt.integrator, int(mujoco.mjtIntegrator.mjINT_IMPLICITFAST)),
        (model.opt.disableflags, int(mujoco.mjtDisableBit.mjDSBL_CONTACT)),
    )
    if any(float(a) != float(b) for a, b in settings):
        return False
    if model.nq != len(ROBOT_JOINTS) or _id(model, mujoco.mjtObj.mjOBJ_CAMERA, CAMERA) < 0:
        return False
    if any(_id(model, mujoco.mjtObj.mjOBJ_JOINT, f"robot/{j}") < 0 for j in ROBOT_JOINTS):
        return False
    expected: dict[str, tuple[int, np.ndarray, np.ndarray]] = {}
    box = int(mujoco.mjtGeom.mjGEOM_BOX)
    t = WALL_THICKNESS
    walls = house_wall_boxes(layout, t, DOOR_HEIGHT) if layout.is_house else _wall_boxes(layout)
    for name, center, half in walls:
        expected[name] = (box, np.asarray(center, float), np.asarray(half, float))
    hw, hd, h = layout.width / 2, layout.depth / 2, layout.height
    expected["ceiling"] = (box, np.array([0, 0, h + t / 2]), np.array([hw + t, hd + t, t / 2]))
    bodies = {}
    for o in layout.objects:
        b = _id(model, mujoco.mjtObj.mjOBJ_BODY, f"objects/{body_name(o.id)}")
        if b < 0:
            return False
        bodies[b] = o
    robot_body = _id(model, mujoco.mjtObj.mjOBJ_BODY, "robot/")
    robot_root = model.body_rootid
    seen = set()
    for g in range(model.ngeom):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or ""
        body = int(model.geom_bodyid[g])
        if body in bodies:
            continue  # checked below, with their bodies' poses
        if robot_body >= 0 and robot_root[body] == robot_body:
            continue  # the robot's own (hidden from the head camera and from its rays)
        if body != 0:
            return False
        if name in expected:
            typ, pos, size = expected[name]
            if model.geom_type[g] != typ or not (
                np.array_equal(model.geom_pos[g], pos) and np.array_equal(model.geom_size[g], size)
            ):
                return False
            seen.add(name)
        elif not _is_floor(model, g, name):
            return False
    if seen != expected.keys():
        return False
    return _objects_fit(model, bodies, catalog)


def _objects_fit(model: mujoco.MjModel, bodies: dict, catalog: Catalog) -> bool:
    """Every object's body holds its geoms as ``objects_xml`` writes them (counted; their
    values are the XML's, checked against the layout's by the caller) and only the layout's
    object bodies exist under the objects' entity."""
    parent = _id(model, mujoco.mjtObj.mjOBJ_BODY, "objects/")
    if parent < 0:
        return not bodies
    under = set(np.flatnonzero(model.body_parentid == parent).tolist())
    if under != set(bodies) or np.any(np.isin(model.body_parentid, list(bodies))):
        return False
    for b, o in bodies.items():
        if int(model.body_geomnum[b]) != len(object_geoms(o, catalog.type(o.type))):
            return False
    return True


def _is_floor(model: mujoco.MjModel, g: int, name: str) -> bool:
    plane = model.geom_type[g] == int(mujoco.mjtGeom.mjGEOM_PLANE)
    return plane and (name == "floor" or name.startswith("floor_room"))


def _id(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str) -> int:
    return int(mujoco.mj_name2id(model, kind, name))
