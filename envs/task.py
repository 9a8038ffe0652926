"""The composer Task: a room per episode, from (style, seed) or from a given RoomLayout.

``initialize_episode_mjcf`` rebuilds the MJCF for the episode's room (walls, door, furniture and
objects; everything but the robot is static, so this is cheap) and ``initialize_episode`` puts the
robot at its start pose. With a style, episode k uses seed ``seed + k``, so a task and a seed give
the same sequence of rooms. The task works under ``composer.Environment`` (the action is the five
position-servo targets x, y, yaw, pan, tilt) and is what ``envs.world.World`` drives directly.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before dm_control/mujoco are first imported

import numpy as np
from dm_control import composer, mjcf

from envs.arena import PHYSICS_TIMESTEP, RoomArena
from envs.entities import RoomObjects
from envs.floorplan import generate_layout
from envs.houses import resolve_style
from envs.layout import RoomLayout
from envs.robot import Robot
from envs.robot_spec import RobotPose, RobotSpec
from envs.rooms import door_entry
from knowledge.catalog import Catalog, load_catalog

CONTROL_TIMESTEP = 0.05  # s, composer.Environment's agent step (5 physics steps)


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
    ) -> None:
        if (layout is None) == (style is None):
            raise ValueError("RoomTask needs exactly one of layout= or style=")
        self._catalog = catalog or load_catalog()
        self._fixed_layout, self._style, self._seed = layout, style, seed
        self._episode = 0
        self._arena = RoomArena()
        self._robot = Robot(spec)
        self._arena.attach(self._robot)
        self._objects: RoomObjects | None = None
        self._layout: RoomLayout | None = None
        self.set_timesteps(control_timestep=CONTROL_TIMESTEP, physics_timestep=PHYSICS_TIMESTEP)

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
