"""The robot's two interfaces: its ``Body`` (what moves and takes images) and its ``Perception``
(what it makes of an image). The learning loop (agent.acquisition, agent.learning) and the search
(agent.search) use nothing else of the robot, so any implementation fits: the simulated World
(envs.world), the kinematic body of the oracle mode (agent.perception_modes), or a real robot and
its detector.

Time is the body's: every motion and every image adds the seconds its ``time_model`` charges to
``sim_time``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from ctxsearch.envs.camera import Frame
from ctxsearch.envs.detector import Detection
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, TimeModel
from ctxsearch.knowledge.geometry import ObjectInstance


class Body(Protocol):
    """A mobile base with a pan-tilt camera, charged simulated seconds by its time model.

    ``drive`` follows a path and turns (a one-point path only turns), ``move_head`` points the
    camera, ``capture`` takes one image (None where nothing is rendered) of ``width`` x
    ``height`` pixels; each returns after charging ``time_model``'s seconds to ``sim_time``.
    This is what a real base offers; rendering a view without charging time is the oracle's
    (agent.search.oracle.RenderingBody).
    """

    spec: RobotSpec
    time_model: TimeModel
    width: int
    height: int

    @property
    def sim_time(self) -> float:
        """Simulated seconds charged so far."""
        ...

    def pose(self) -> RobotPose:
        """Where the base is and where the head points."""
        ...

    def reset_pose(self, pose: RobotPose) -> None:
        """Put the robot at ``pose`` (the start of a room or an episode; no time charged)."""
        ...

    def drive(self, path: np.ndarray, final_yaw: float | None = None) -> float:
        """Follow ``path`` (K, 2), then turn to ``final_yaw``; the seconds charged."""
        ...

    def move_head(self, pan: float, tilt: float) -> float:
        """Slew the head to (pan, tilt) within its limits; the seconds charged."""
        ...

    def capture(self, rgb: bool = False, depth: bool = True) -> Frame | None:
        """One image from the head camera where it points now (one ``image_cost`` charged)."""
        ...

    def close(self) -> None:
        """Release what the body holds (a renderer)."""
        ...


class WrappedBody:
    """A ``Body`` that forwards everything to another; subclasses change one thing (the replay
    charges images without taking them, the search meters the path driven)."""

    def __init__(self, body: Body):
        self._b = body
        self.spec, self.time_model = body.spec, body.time_model
        self.width, self.height = body.width, body.height

    @property
    def sim_time(self) -> float:
        """The wrapped body's clock."""
        return self._b.sim_time

    def pose(self) -> RobotPose:
        """The wrapped body's pose."""
        return self._b.pose()

    def reset_pose(self, pose: RobotPose) -> None:
        """Put the wrapped body at ``pose``."""
        self._b.reset_pose(pose)

    def drive(self, path: np.ndarray, final_yaw: float | None = None) -> float:
        """Drive the wrapped body."""
        return self._b.drive(path, final_yaw)

    def move_head(self, pan: float, tilt: float) -> float:
        """Move the wrapped body's head."""
        return self._b.move_head(pan, tilt)

    def capture(self, rgb: bool = False, depth: bool = True) -> Frame | None:
        """An image from the wrapped body."""
        return self._b.capture(rgb=rgb, depth=depth)

    def close(self) -> None:
        """Close the wrapped body."""
        self._b.close()


class Perception(Protocol):
    """What the robot recognizes in an image and which objects an examined object is related
    to, on its ``body``. ``reads_truth``: it needs no image to decide relations (the oracle)."""

    name: str
    reads_truth: bool
    body: Body
    last_detections: Sequence[Detection]  # of the last ``see`` (empty where there are none)

    def see(self, frame: Frame | None) -> list[ObjectInstance]:
        """The objects recognized in ``frame``, taken by ``body`` where it stands now."""
        ...

    def related(
        self, obj: ObjectInstance, seen: Sequence[ObjectInstance]
    ) -> list[tuple[str, ObjectInstance]]:
        """RELATED-OBJECTS of ``obj`` given what its examination saw: (relation, object) pairs."""
        ...

    def reference(self, obj: ObjectInstance) -> ObjectInstance | None:
        """``obj`` (perhaps under another type) once it may be the reference of an examination,
        None while it may not (a perception that trusts every object it sees returns ``obj``)."""
        ...

    def close(self) -> None:
        """Release the body and whatever perception holds."""
        ...
