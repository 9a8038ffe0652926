"""The robot as a dm_control composer Entity, built with ``mjcf`` from ``RobotSpec``.

Kinematic tree (modelled on Hello Robot Stretch's head, MJCF conventions of mujoco_menagerie)::

    base  [slide x, slide y, hinge yaw]    round base + mast
      head_pan  [hinge pan, axis +z]        at camera_height above the floor
        head_tilt  [hinge tilt, axis -y]    positive tilt looks up
          camera head_cam                   on both head axes, looks along the head's +x

The camera sits on the pan and on the tilt axis, so its position is (x, y, camera_height)
whatever the head does; at pan = tilt = 0 it looks along the base's heading. MuJoCo cameras look
along their local -z with +y up: ``xyaxes="0 -1 0 0 0 1"`` makes image-right the head's -y and
image-up its +z, hence the view direction -z = +x.

Every joint is driven by a position actuator (``ctrlrange`` = the joint's limits; the yaw hinge is
unlimited) whose stiffness gives each joint the same servo bandwidth, critically damped
(``dampratio=1``). Robot geoms neither collide (contype = conaffinity = 0: the planner guarantees
free paths, and stepping stays cheap) nor show in the head camera: they live in geom group
``ROBOT_GEOM_GROUP``, which the head camera's render option hides.
"""

from __future__ import annotations

import functools
import math
import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before dm_control/mujoco are first imported

import mujoco
import numpy as np
from dm_control import composer, mjcf

from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, wrap_angle

ROBOT_GEOM_GROUP = 2  # hidden from the head camera
JOINTS = ("x", "y", "yaw", "pan", "tilt")  # qpos order of the robot (and of its actuators)

SERVO_BANDWIDTH = 30.0  # rad/s: natural frequency of every position servo
BASE_MASS, PAN_MASS, TILT_MASS = 25.0, 0.6, 0.4  # kg
HEAD_ARMATURE = 0.01  # kg m^2 of reflected motor inertia on pan and tilt
DEFAULT_WORKSPACE = (-10.0, 10.0)  # m, slide limits until a room sets them
HEAD_INERTIA = 0.002  # kg m^2 of the pan body (the tilt body has half)
DARK, LIGHT = [0.18, 0.18, 0.2, 1], [0.85, 0.85, 0.88, 1]  # robot colours


def _add_defaults(root: mjcf.RootElement, spec: RobotSpec) -> None:
    """The default classes: robot geoms (visual only, their own group), and per joint class
    (slide, yaw, pan, tilt) the joint type and a position servo whose gain gives every joint
    the same bandwidth for the inertia it drives."""
    base_izz = _cylinder_inertia(BASE_MASS, spec.base_radius, spec.base_height)[2]
    inertia = {
        "slide": BASE_MASS + PAN_MASS + TILT_MASS,
        "yaw": base_izz + 2 * HEAD_INERTIA,
        "pan": 2 * HEAD_INERTIA + HEAD_ARMATURE,
        "tilt": HEAD_INERTIA + HEAD_ARMATURE,
    }
    d = root.default
    d.geom.set_attributes(group=ROBOT_GEOM_GROUP, contype=0, conaffinity=0, density=0)
    for cls in ("slide", "yaw", "pan", "tilt"):
        c = d.add("default", dclass=cls)
        c.joint.set_attributes(
            type="slide" if cls == "slide" else "hinge",
            armature=HEAD_ARMATURE if cls in ("pan", "tilt") else 0.0,
            damping=0.0,
        )
        c.position.set_attributes(kp=inertia[cls] * SERVO_BANDWIDTH**2, dampratio=1.0)


def _cylinder_inertia(mass: float, radius: float, height: float) -> list[float]:
    ixx = mass * (3 * radius**2 + height**2) / 12
    return [ixx, ixx, 0.5 * mass * radius**2]


class Robot(composer.Entity):
    """The mobile pan-tilt camera robot (see the module docstring)."""

    def _build(self, spec: RobotSpec | None = None, name: str = "robot") -> None:
        spec = spec or RobotSpec()
        self._spec = spec
        root = mjcf.RootElement(model=name)
        self._mjcf_root = root
        _add_defaults(root, spec)
        base = self._add_base(root, spec)
        self._add_head(base, spec)
        self._joints = (self._x, self._y, self._yaw, self._pan, self._tilt)
        self._actuators = []
        for joint in self._joints:
            act = root.actuator.add("position", name=joint.name, joint=joint, dclass=joint.dclass)
            if joint.range is not None:
                act.ctrlrange = joint.range
            else:
                act.ctrllimited = False
            self._actuators.append(act)
        root.keyframe.add("key", name="home", qpos=[0.0] * 5, ctrl=[0.0] * 5)

    def _add_base(self, root: mjcf.RootElement, spec: RobotSpec) -> mjcf.Element:
        """The base body: its x, y and yaw joints, the base cylinder, the nose and the mast."""
        r, hb = spec.base_radius, spec.base_height
        base = root.worldbody.add("body", name="base")
        base.add(
            "inertial",
            pos=[0, 0, hb / 2],
            mass=BASE_MASS,
            diaginertia=_cylinder_inertia(BASE_MASS, r, hb),
        )
        self._x = base.add(
            "joint", name="x", dclass="slide", axis=[1, 0, 0], range=DEFAULT_WORKSPACE
        )
        self._y = base.add(
            "joint", name="y", dclass="slide", axis=[0, 1, 0], range=DEFAULT_WORKSPACE
        )
        self._yaw = base.add("joint", name="yaw", dclass="yaw", axis=[0, 0, 1], limited=False)
        base.add(
            "geom", name="base", type="cylinder", size=[r, hb / 2], pos=[0, 0, hb / 2], rgba=DARK
        )
        base.add(
            "geom",
            name="nose",
            type="box",
            size=[0.04, 0.06, 0.01],
            pos=[r * 0.7, 0, hb + 0.01],
            rgba=[0.9, 0.5, 0.1, 1],
        )
        mast_top = spec.camera_height - 0.06
        base.add(
            "geom",
            name="mast",
            type="cylinder",
            size=[spec.mast_radius, (mast_top - hb) / 2],
            pos=[0, 0, (mast_top + hb) / 2],
            rgba=LIGHT,
        )
        return base

    def _add_head(self, base: mjcf.Element, spec: RobotSpec) -> None:
        """The pan body on the mast, the tilt body on it, and the camera (on both axes)."""
        pan = base.add("body", name="head_pan", pos=[0, 0, spec.camera_height])
        pan.add("inertial", pos=[0, 0, 0], mass=PAN_MASS, diaginertia=[HEAD_INERTIA] * 3)
        self._pan = pan.add("joint", name="pan", dclass="pan", axis=[0, 0, 1], range=spec.pan_range)
        pan.add(
            "geom",
            name="pan_bracket",
            type="box",
            size=[0.03, 0.05, 0.02],
            pos=[0, 0, -0.04],
            rgba=DARK,
        )
        tilt = pan.add("body", name="head_tilt")
        tilt.add("inertial", pos=[0, 0, 0], mass=TILT_MASS, diaginertia=[HEAD_INERTIA / 2] * 3)
        self._tilt = tilt.add(
            "joint", name="tilt", dclass="tilt", axis=[0, -1, 0], range=spec.tilt_range
        )
        tilt.add("geom", name="head", type="box", size=[0.035, 0.09, 0.025], rgba=DARK)
        tilt.add(
            "geom",
            name="lens",
            type="cylinder",
            size=[0.015, 0.005],
            pos=[0.04, 0, 0],
            quat=[math.cos(math.pi / 4), 0, math.sin(math.pi / 4), 0],
            rgba=[0.05, 0.05, 0.05, 1],
        )
        self._camera = tilt.add(
            "camera", name="head_cam", pos=[0, 0, 0], xyaxes=[0, -1, 0, 0, 0, 1], fovy=spec.fovy_deg
        )

    @property
    def mjcf_model(self) -> mjcf.RootElement:
        return self._mjcf_root

    @property
    def spec(self) -> RobotSpec:
        """The dimensions this robot was built from."""
        return self._spec

    @property
    def joints(self) -> tuple[mjcf.Element, ...]:
        """The joints x, y, yaw, pan, tilt (in that order)."""
        return self._joints

    @property
    def actuators(self) -> tuple[mjcf.Element, ...]:
        """The position actuators, one per joint, same order."""
        return tuple(self._actuators)

    @property
    def camera(self) -> mjcf.Element:
        """The head camera."""
        return self._camera

    def set_workspace(self, x_range: tuple[float, float], y_range: tuple[float, float]) -> None:
        """Limit the base's slides (and their actuators' ctrlrange) to a room's extent."""
        for joint, act, rng in zip(
            self._joints[:2], self._actuators[:2], (x_range, y_range), strict=True
        ):
            joint.range = rng
            act.ctrlrange = rng

    def set_pose(self, physics: mjcf.Physics, pose: RobotPose) -> None:
        """Teleport the robot: joint positions and servo targets to ``pose``, velocities zero."""
        q = pose_to_qpos(pose, self._spec)
        physics.bind(self._joints).qpos = q
        physics.bind(self._joints).qvel = 0.0
        physics.bind(self._actuators).ctrl = q


def pose_to_qpos(pose: RobotPose, spec: RobotSpec) -> np.ndarray:
    """Joint positions (x, y, yaw, pan, tilt) of ``pose``, head clipped to its limits."""
    pan, tilt = spec.clip_head(pose.pan, pose.tilt)
    return np.array([pose.x, pose.y, wrap_angle(pose.yaw), pan, tilt], float)


def qpos_to_pose(q: np.ndarray) -> RobotPose:
    """The RobotPose of joint positions (x, y, yaw, pan, tilt)."""
    q = np.asarray(q, float)
    return RobotPose(float(q[0]), float(q[1]), wrap_angle(float(q[2])), float(q[3]), float(q[4]))


# What the robot's motion depends on, compared between a world's model and the robot's own
_SAME_OPTIONS = ("timestep", "integrator", "disableflags", "enableflags", "gravity", "wind",
                 "magnetic", "density", "viscosity", "cone", "jacobian")  # fmt: skip
_SAME_ARRAYS = ("jnt_type", "jnt_range", "jnt_limited", "jnt_axis", "jnt_pos", "jnt_qposadr",
                "jnt_dofadr", "dof_parentid", "dof_armature", "dof_damping", "dof_frictionloss",
                "actuator_trntype", "actuator_trnid", "actuator_dyntype", "actuator_gaintype",
                "actuator_biastype", "actuator_gainprm", "actuator_biasprm", "actuator_dynprm",
                "actuator_ctrlrange", "actuator_ctrllimited", "actuator_forcerange",
                "actuator_forcelimited", "actuator_gear", "qpos0")  # fmt: skip
_SAME_BODY = ("body_mass", "body_inertia", "body_pos", "body_quat", "body_ipos", "body_iquat",
              "body_gravcomp")  # fmt: skip


def robot_dynamics(robot: Robot | str, model: mujoco.MjModel) -> mujoco.MjModel | None:
    """The robot alone as a MuJoCo model of its own, for stepping its motion in ``model`` (a
    world it is attached to at the origin): nothing in a world acts on the robot (no contacts,
    no constraints but its own joint limits; every other body is static), so its joints move
    the same there as here, bit for bit (``tests/test_world.py`` steps both side by side), at
    a quarter of the cost of a house (about 2.5 against 10 us a physics step: MuJoCo poses
    every static body at every step). None where the two models differ in anything the motion
    depends on (the options, the joints, actuators and bodies): then the world's model is
    stepped. ``robot``: the entity attached to the world, or its XML as attached."""
    xml = robot if isinstance(robot, str) else robot.mjcf_model.to_xml_string()
    xml = xml.replace("<worldbody>", '<worldbody><body name="attachment">', 1)
    xml = xml.replace("</worldbody>", "</body></worldbody>", 1)
    opts = tuple(np.asarray(getattr(model.opt, k)).tobytes() for k in _SAME_OPTIONS)
    own = _compiled(xml, opts)
    if own is None or own.nq != model.nq or own.nv != model.nv or own.nu != model.nu:
        return None
    for k in _SAME_OPTIONS:
        if not np.array_equal(getattr(own.opt, k), getattr(model.opt, k)):
            return None
    if any(not np.array_equal(getattr(own, k), getattr(model, k)) for k in _SAME_ARRAYS):
        return None
    # the bodies that move, with the attachment frame above them, in the same order
    moving = np.flatnonzero(model.body_dofnum > 0)
    if not len(moving):
        return None
    ids = np.concatenate([[model.body_parentid[moving[0]]], moving])
    row = {int(b): i + 1 for i, b in enumerate(ids)}  # a body's index in ``own``
    if [row.get(int(model.body_parentid[b]), 0) for b in ids] != list(own.body_parentid[1:]):
        return None
    for k in _SAME_BODY:
        if not np.array_equal(getattr(own, k)[1:], getattr(model, k)[ids]):
            return None
    return own


@functools.lru_cache(maxsize=32)
def _compiled(xml: str, opts: tuple[bytes, ...]) -> mujoco.MjModel | None:
    """The robot's model from its XML with a world's options (``_SAME_OPTIONS``, as bytes)."""
    try:
        spec = mujoco.MjSpec.from_string(xml)
        for k, raw in zip(_SAME_OPTIONS, opts, strict=True):
            cur = getattr(spec.option, k)
            value = np.frombuffer(raw, np.asarray(cur).dtype)
            setattr(spec.option, k, value if np.ndim(cur) else value[0].item())
        return spec.compile()
    except (ValueError, TypeError, mujoco.FatalError):
        return None
