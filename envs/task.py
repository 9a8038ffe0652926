"""The composer Task: a room per episode, from (style, seed) or from a given RoomLayout.

``initialize_episode_mjcf`` rebuilds the MJCF for the episode's room (walls, door, furniture and
objects; everything but the robot is static, so this is cheap) and ``initialize_episode`` puts the
robot at its start pose. With a style, episode k uses seed ``seed + k``, so a task and a seed give
the same sequence of rooms. The task works under ``composer.Environment`` (the action is the five
position-servo targets x, y, yaw, pan, tilt); ``envs.world.World`` runs on the compiled model
of its XML (made once per world: ``envs.world_store``) and makes the task itself on demand.

Its observables are the head camera's images, ``head_rgb`` (H, W, 3) uint8 and ``head_depth``
(H, W, 1) float32 metres, at ``camera_size`` (width, height), rendered as the World's head camera
renders them (the robot's own geoms hidden), so a dm_env user of ``composer.Environment`` sees
what the robot sees; the World never evaluates them (it renders through its own renderer).
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before dm_control/mujoco are first imported

import collections

import numpy as np
from dm_control import composer, mjcf
from dm_control.composer.observation import observable
from dm_control.mujoco.wrapper import core

from ctxsearch.envs.arena import MAX_IMAGE_SIZE, OVERHEAD_GEOM_GROUP, PHYSICS_TIMESTEP, RoomArena
from ctxsearch.envs.entities import RoomObjects
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot import ROBOT_GEOM_GROUP, Robot
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec
from ctxsearch.envs.rooms import door_entry
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.errors import CtxsearchError

CONTROL_TIMESTEP = 0.05  # s, composer.Environment's agent step (5 physics steps)
CAMERA_SIZE = (320, 240)  # the head camera observables' default (width, height), as World's


def check_camera_size(width: int, height: int) -> tuple[int, int]:
    """(width, height) as ints, or a one-line error outside 1x1 .. ``MAX_IMAGE_SIZE``."""
    w, h = MAX_IMAGE_SIZE
    if not all(
        isinstance(v, int | np.integer) and not isinstance(v, bool) for v in (width, height)
    ):
        raise CtxsearchError(f"image size must be whole pixels, got {width!r}x{height!r}")
    if not (0 < width <= w and 0 < height <= h):
        raise CtxsearchError(f"image size {width}x{height} outside 1x1..{w}x{h}")
    return int(width), int(height)


def head_scene_option() -> core.MjvOption:
    """The head camera's render option: the robot's own geoms hidden, the ceiling shown."""
    option = core.MjvOption()
    option.geomgroup[ROBOT_GEOM_GROUP] = 0
    option.geomgroup[OVERHEAD_GEOM_GROUP] = 1
    return option


def start_pose(layout: RoomLayout) -> RobotPose:
    """Where an episode starts: just inside the door, facing into the room (``door_entry``)."""
    return RobotPose(*door_entry(layout))


class RoomTask(composer.Task):
    """A furnished room with the robot in it; no reward (the agent's goals live in ``agent/``)."""

    def __init__(
        self,
        catalog: Catalog | None = None,
        *,
        layout: RoomLayout | None = None,
        style: str | None = None,
        seed: int = 0,
        spec: RobotSpec | None = None,
        camera_size: tuple[int, int] = CAMERA_SIZE,
    ) -> None:
        if (layout is None) == (style is None):
            raise ValueError("RoomTask needs exactly one of layout= or style=")
        width, height = check_camera_size(*camera_size)
        self._catalog = catalog or load_catalog()
        self._fixed_layout, self._style, self._seed = layout, style, seed
        self._episode = 0
        self._arena = RoomArena()
        self._robot = Robot(spec)
        self._arena.attach(self._robot)
        self._objects: RoomObjects | None = None
        self._layout: RoomLayout | None = None
        self.set_timesteps(control_timestep=CONTROL_TIMESTEP, physics_timestep=PHYSICS_TIMESTEP)
        self._camera_observables = self._head_camera(width, height)

    def _head_camera(self, width: int, height: int) -> collections.OrderedDict:
        cam = self._robot.camera
        out = collections.OrderedDict()
        for name, depth in (("head_rgb", False), ("head_depth", True)):
            obs = observable.MJCFCamera(
                cam, height=height, width=width, depth=depth, scene_option=head_scene_option()
            )
            obs.enabled = True
            out[name] = obs
        return out

    @property
    def task_observables(self) -> collections.OrderedDict:
        """The head camera: ``head_rgb`` (H, W, 3) uint8 and ``head_depth`` (H, W, 1) metres."""
        return self._camera_observables

    @property
    def root_entity(self) -> RoomArena:
        return self._arena

    @property
    def robot(self) -> Robot:
        """The robot entity."""
        return self._robot

    @property
    def objects(self) -> RoomObjects:
        """The current room's furniture and objects (after ``initialize_episode_mjcf``)."""
        if self._objects is None:
            raise RuntimeError("no room built yet: call initialize_episode_mjcf first")
        return self._objects

    @property
    def layout(self) -> RoomLayout:
        """The current room's layout (after ``initialize_episode_mjcf``)."""
        if self._layout is None:
            raise RuntimeError("no room built yet: call initialize_episode_mjcf first")
        return self._layout

    @property
    def catalog(self) -> Catalog:
        """The object-type catalog the rooms are built from."""
        return self._catalog

    def set_layout(self, layout: RoomLayout) -> None:
        """Build ``layout`` from the next episode on (instead of the given one or the style's)."""
        self._fixed_layout, self._style = layout, None

    def _next_layout(self) -> RoomLayout:
        if self._fixed_layout is not None:
            return self._fixed_layout
        layout = generate_layout(
            resolve_style(self._style, self._catalog), self._seed + self._episode, self._catalog
        )
        self._episode += 1
        return layout

    def initialize_episode_mjcf(self, random_state: np.random.RandomState) -> None:
        """Build this episode's room: shell, robot workspace, furniture and objects."""
        layout = self._next_layout()
        if layout is self._layout and self._objects is not None:
            return  # a fixed layout is built once
        self._layout = layout
        self._arena.set_layout(layout)
        hw, hd = layout.width / 2, layout.depth / 2
        self._robot.set_workspace((-hw, hw), (-hd, hd))
        if self._objects is not None:
            self._objects.detach()
        self._objects = RoomObjects(layout, self._catalog)
        self._arena.attach(self._objects)

    def initialize_episode(
        self, physics: mjcf.Physics, random_state: np.random.RandomState
    ) -> None:
        """Put the robot at the start pose (inside the door, facing the room), head level."""
        self._robot.set_pose(physics, start_pose(self.layout))

    def get_reward(self, physics: mjcf.Physics) -> float:
        return 0.0
