"""The robot's dimensions, pose and time model, as pure data (no MuJoCo).

One source of truth: the MJCF robot is built from ``RobotSpec``, navigation inflates obstacles by
its radius, and the oracle perception mode charges time with the same ``TimeModel`` that the
camera mode uses, so simulated seconds are comparable across modes.

Robot (modelled on Hello Robot Stretch's head): a round mobile base driving on the floor
(x, y, yaw), a mast, and a pan-tilt head carrying one camera. Pan 0 looks along the base's
heading; positive tilt looks up.

Time model (simulated seconds, all documented defaults chosen as plausible for an indoor mobile
base with a pan-tilt unit):
- driving: path length / ``drive_speed`` (0.5 m/s), plus turning in place at ``turn_rate``
  (1.2 rad/s) at the start, at every path vertex, and to the final heading;
- head: pan and tilt slew simultaneously, so a head move costs
  max(|dpan| / ``pan_rate``, |dtilt| / ``tilt_rate``) (2.0 and 1.5 rad/s);
- every image the robot acquires and runs detection on costs ``image_cost`` (0.25 s).
Head moves happen while stationary; base and head moves do not overlap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def wrap_angle(a: float) -> float:
    """The angle in (-pi, pi]."""
    return float(math.atan2(math.sin(a), math.cos(a)))


def wrap_angles(a: np.ndarray) -> np.ndarray:
    """``wrap_angle`` of every element of an array."""
    return np.arctan2(np.sin(a), np.cos(a))


@dataclass(frozen=True)
class RobotSpec:
    """Geometry, joint limits and camera of the robot."""

    base_radius: float = 0.22  # m, footprint for navigation (inflate obstacles by this + margin)
    base_height: float = 0.25
    mast_radius: float = 0.03
    camera_height: float = 1.20  # m above the floor, at pan = tilt = 0
    pan_range: tuple[float, float] = (-math.pi * 0.95, math.pi * 0.95)
    tilt_range: tuple[float, float] = (-1.30, 0.50)  # rad; -1.3 looks steeply down
    fovy_deg: float = 58.0
    nav_margin: float = 0.05  # m of clearance kept beyond the base radius

    @property
    def clearance(self) -> float:
        """The distance the base centre keeps from any obstacle."""
        return self.base_radius + self.nav_margin

    def clip_head(self, pan: float, tilt: float) -> tuple[float, float]:
        """Pan and tilt clipped to the joint limits."""
        pan = wrap_angle(pan)
        return (
            float(min(max(pan, self.pan_range[0]), self.pan_range[1])),
            float(min(max(tilt, self.tilt_range[0]), self.tilt_range[1])),
        )


@dataclass(frozen=True)
class RobotPose:
    """Base pose on the floor (x, y, yaw) and head joint angles (pan, tilt), radians."""

    x: float
    y: float
    yaw: float
    pan: float = 0.0
    tilt: float = 0.0

    @property
    def xy(self) -> np.ndarray:
        """The base position as a (2,) array."""
        return np.array([self.x, self.y])

    def camera_heading(self) -> float:
        """The world yaw the camera looks along."""
        return wrap_angle(self.yaw + self.pan)


@dataclass(frozen=True)
class TimeModel:
    """Simulated seconds charged for every action (see the module docstring)."""

    drive_speed: float = 0.5  # m/s
    turn_rate: float = 1.2  # rad/s, base rotation in place
    pan_rate: float = 2.0  # rad/s
    tilt_rate: float = 1.5  # rad/s
    image_cost: float = 0.25  # s per image acquired and analysed

    def travel_time(self, distance: float | np.ndarray) -> float | np.ndarray:
        """Seconds to drive ``distance`` metres straight (a number or an array)."""
        return distance / self.drive_speed

    def turn_time(self, yaw0: float, yaw1: float) -> float:
        """Seconds to rotate the base in place from yaw0 to yaw1 (shortest way)."""
        return abs(wrap_angle(yaw1 - yaw0)) / self.turn_rate

    def turn_times(self, yaw0: np.ndarray | float, yaw1: np.ndarray) -> np.ndarray:
        """``turn_time`` for arrays of headings (the vectorised planners)."""
        return np.abs(wrap_angles(yaw1 - yaw0)) / self.turn_rate

    def leg_estimate(self, distance: float, always_turn: bool = False) -> float:
        """Expected seconds of one leg of a tour whose path is not planned yet: the drive plus a
        quarter turn (only if the leg is longer than 5 cm, unless ``always_turn``)."""
        turn = (math.pi / 2) / self.turn_rate if always_turn or distance > 0.05 else 0.0
        return distance / self.drive_speed + turn

    def looks_estimate(self, images: float, head_s: float) -> float:
        """Expected seconds of ``images`` images with a mean head slew of ``head_s`` before each."""
        return images * (head_s + self.image_cost)

    def drive_time(self, path: np.ndarray, yaw0: float, yaw1: float | None = None) -> float:
        """Seconds to follow a polyline ``path`` (K, 2) starting at heading yaw0.

        The robot turns in place towards each segment, drives it, and finally turns to ``yaw1``
        (if given). A path of fewer than two points costs only the final turn.
        """
        path = np.asarray(path, float).reshape(-1, 2)
        t, yaw = 0.0, yaw0
        for a, b in zip(path[:-1], path[1:], strict=True):
            seg = b - a
            length = float(np.hypot(*seg))
            if length < 1e-9:
                continue
            heading = math.atan2(seg[1], seg[0])
            t += self.turn_time(yaw, heading) + length / self.drive_speed
            yaw = heading
        if yaw1 is not None:
            t += self.turn_time(yaw, yaw1)
        return t

    def head_time(self, pan0: float, tilt0: float, pan1: float, tilt1: float) -> float:
        """Seconds to slew the head; pan and tilt move simultaneously."""
        return max(abs(pan1 - pan0) / self.pan_rate, abs(tilt1 - tilt0) / self.tilt_rate)

    def head_times(
        self, pan0: np.ndarray, tilt0: np.ndarray | float, pan1: np.ndarray, tilt1: np.ndarray
    ) -> np.ndarray:
        """``head_time`` for arrays of head moves (the vectorised planners)."""
        return np.maximum(
            np.abs(pan1 - pan0) / self.pan_rate, np.abs(tilt1 - tilt0) / self.tilt_rate
        )

    @staticmethod
    def path_length(path: np.ndarray) -> float:
        """Length in metres of a polyline (K, 2)."""
        path = np.asarray(path, float).reshape(-1, 2)
        return float(np.sum(np.hypot(*np.diff(path, axis=0).T))) if len(path) > 1 else 0.0
