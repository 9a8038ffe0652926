"""The one pinhole camera model: intrinsics, axes, projection and the frustum test (no MuJoCo).

Used by the World (the head camera of every rendered ``Frame``), the gaze planner, the search's
seen map and the oracle perception, so all of them agree on what a camera sees.

Conventions are MuJoCo's: ``xmat``'s columns are the camera's right (x), up (y) and backward (z)
axes in the world; the camera looks along -z. Pixel coordinates: u to the right, v down, the
image's top-left corner at (0, 0), so pixel (row i, column j) has its centre at (j + 0.5, i + 0.5).
Square pixels, principal point at the image centre, vertical field of view ``fovy_deg``.

The robot's head camera (envs/robot.py) sits on both the pan and the tilt axis, at
``spec.camera_height`` above the base centre, so its position is (x, y, camera_height) whatever
the head does, and it looks along heading yaw + pan, tilted by tilt (positive up):
``camera_at(pose, spec)``.

The frustum test (``in_frustum``) is written once, on camera-frame coordinates (depth along the
optical axis, right, up); ``PinholeCamera.sees`` applies it to world points for one camera,
``frustum_mask`` for a camera given by heading and tilt, ``frustum_masks`` to many cameras at
once (the gaze planner's vectorised form).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ctxsearch.envs.robot_spec import RobotPose, RobotSpec

NEAR_CLIP = 0.05  # m: points closer to the camera than this (along the optical axis) are unseen


def focal_length(fovy_deg: float, height: int) -> float:
    """The focal length in pixels of an image ``height`` pixels high with vertical field of view
    ``fovy_deg`` (square pixels)."""
    return (height / 2) / math.tan(math.radians(fovy_deg) / 2)


def half_fov_tangents(fovy_deg: float, width: int, height: int) -> tuple[float, float]:
    """tan of half the horizontal and of half the vertical field of view."""
    tan_y = math.tan(math.radians(fovy_deg) / 2)
    return tan_y * width / height, tan_y


def intrinsics(fovy_deg: float, width: int, height: int) -> np.ndarray:
    """The 3x3 intrinsic matrix K (OpenCV convention: x right, y down, z forward)."""
    f = focal_length(fovy_deg, height)
    return np.array([[f, 0.0, width / 2], [0.0, f, height / 2], [0.0, 0.0, 1.0]])


def camera_axes(heading: float, tilt: float) -> np.ndarray:
    """The camera's ``xmat`` (3, 3) for a world heading (yaw + pan) and a tilt (positive up):
    columns right, up, backward (the camera looks along -column 2)."""
    ch, sh, ct, st = math.cos(heading), math.sin(heading), math.cos(tilt), math.sin(tilt)
    right = [sh, -ch, 0.0]
    up = [-st * ch, -st * sh, ct]
    back = [-ct * ch, -ct * sh, -st]
    return np.array([right, up, back]).T


def in_frustum(
    z: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    tan_x: float,
    tan_y: float,
    near: float = NEAR_CLIP,
    radius: np.ndarray | float = 0.0,
) -> np.ndarray:
    """THE frustum test on camera-frame coordinates (depth ``z`` along the optical axis, ``x``
    right, ``y`` up, broadcastable arrays): in front of the near plane and inside the four side
    planes. With ``radius`` (per point), a sphere of that radius around the point touching the
    frustum counts (any part of an object in view)."""
    if np.isscalar(radius) and radius == 0.0:
        ok = z > near
        ok &= np.abs(x) <= z * tan_x
        ok &= np.abs(y) <= z * tan_y
        return ok
    ok = z > near - radius
    ok &= np.abs(x) <= z * tan_x + radius * math.sqrt(1 + tan_x**2)
    ok &= np.abs(y) <= z * tan_y + radius * math.sqrt(1 + tan_y**2)
    return ok


@dataclass(frozen=True)
class PinholeCamera:
    """A pinhole camera in the world: position (3,), world rotation ``xmat`` (3, 3) (MuJoCo
    convention, see the module docstring), vertical field of view and image size."""

    position: np.ndarray
    xmat: np.ndarray
    fovy_deg: float
    width: int
    height: int

    @property
    def focal(self) -> float:
        """Focal length in pixels (square pixels)."""
        return focal_length(self.fovy_deg, self.height)

    @property
    def forward(self) -> np.ndarray:
        """The viewing direction (3,), a unit vector."""
        return -self.xmat[:, 2]

    def intrinsics(self) -> np.ndarray:
        """The 3x3 intrinsic matrix K (OpenCV convention: x right, y down, z forward)."""
        return intrinsics(self.fovy_deg, self.width, self.height)

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """World points (N, 3) in the camera frame (N, 3): right, up, backward."""
        pts = np.atleast_2d(np.asarray(points, float))
        return (pts - np.asarray(self.position, float)) @ np.asarray(self.xmat, float)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (N, 3) -> pixel coordinates (N, 2) (u, v) and depth (N,) along the optical
        axis; points at or behind the camera get NaN pixels and depth <= 0."""
        local = self.to_camera(points)
        depth = -local[:, 2]
        f = self.focal
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.width / 2 + f * local[:, 0] / depth
            v = self.height / 2 - f * local[:, 1] / depth
        uv = np.column_stack([u, v])
        uv[depth <= 1e-9] = np.nan
        return uv, depth

    def sees(self, points: np.ndarray, max_distance: float | None = None) -> np.ndarray:
        """(N,) bool: which world ``points`` (N, 3) lie inside the frustum (and within
        ``max_distance`` of the camera)."""
        local = self.to_camera(points)
        tan_x, tan_y = half_fov_tangents(self.fovy_deg, self.width, self.height)
        ok = in_frustum(-local[:, 2], local[:, 0], local[:, 1], tan_x, tan_y)
        if max_distance is not None:
            ok &= np.linalg.norm(local, axis=1) <= max_distance
        return ok

    def visible(self, points: np.ndarray, depth: np.ndarray, tol: float) -> np.ndarray:
        """(N,) bool: which world ``points`` (N, 3) an image with ``depth`` (H, W, optical-axis
        metres) shows: inside the image, more than 5 cm in front of the camera, and not more
        than ``tol`` m behind the surface the depth image holds at their pixel."""
        depth = np.asarray(depth, float)
        h, w = depth.shape
        uv, z = self.project(points)
        ok = z > 0.05
        with np.errstate(invalid="ignore"):
            ok &= (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        idx = np.flatnonzero(ok)
        if len(idx):
            col = np.clip(uv[idx, 0].astype(int), 0, w - 1)
            row = np.clip(uv[idx, 1].astype(int), 0, h - 1)
            ok[idx] = z[idx] <= depth[row, col] + tol
        return ok

    def _local_rays(self, rows: np.ndarray | None = None, cols: np.ndarray | None = None):
        """(H, W, 3) camera-frame rays through the pixel centres, scaled to z = -1 (only the
        pixels of ``rows`` x ``cols`` if given)."""
        f = self.focal
        u = np.arange(self.width) if cols is None else np.asarray(cols)
        v = np.arange(self.height) if rows is None else np.asarray(rows)
        x = (u + 0.5 - self.width / 2) / f
        y = -(v + 0.5 - self.height / 2) / f
        return np.stack(np.broadcast_arrays(x[None, :], y[:, None], -1.0), axis=-1)

    def pixel_rays(self) -> np.ndarray:
        """(H, W, 3) world-frame unit rays through every pixel centre."""
        local = self._local_rays()
        local /= np.linalg.norm(local, axis=-1, keepdims=True)
        return local @ self.xmat.T

    def backproject(
        self, depth: np.ndarray, rows: np.ndarray | None = None, cols: np.ndarray | None = None
    ) -> np.ndarray:
        """(H, W, 3) world points of a depth image (distance along the optical axis); with
        ``rows`` and ``cols`` (sorted pixel indices) only the pixels of ``rows`` x ``cols``, the
        same numbers as the whole image's at those pixels."""
        local = self._local_rays(rows, cols)
        d = np.asarray(depth, float)
        if rows is not None:
            d = d[np.ix_(np.asarray(rows), np.asarray(cols))]
        return self.position + (local * d[..., None]) @ self.xmat.T


@dataclass(frozen=True)
class Frame:
    """One image from the head camera: RGB (only when asked), depth in metres along the optical
    axis (when asked), the object instance id of every pixel (-1: floor, walls, ceiling,
    background), the camera it was taken with and the robot's pose at the time."""

    rgb: np.ndarray | None
    depth: np.ndarray | None
    instance_ids: np.ndarray
    camera: PinholeCamera
    pose: RobotPose


def camera_at(
    pose: RobotPose, spec: RobotSpec | None = None, width: int = 320, height: int = 240
) -> PinholeCamera:
    """The head camera of the robot at ``pose`` (see the module docstring)."""
    spec = spec or RobotSpec()
    return PinholeCamera(
        np.array([pose.x, pose.y, spec.camera_height]),
        camera_axes(pose.yaw + pose.pan, pose.tilt),
        spec.fovy_deg,
        width,
        height,
    )


def frustum_mask(
    cam_xyz: np.ndarray,
    heading: float,
    tilt: float,
    points: np.ndarray,
    spec: RobotSpec,
    max_range: float,
    width: int = 320,
    height: int = 240,
) -> np.ndarray:
    """(N,) bool: points inside the frustum of a camera at ``cam_xyz`` looking along world
    ``heading`` with ``tilt``, within ``max_range``."""
    ch, sh, ct, st = math.cos(heading), math.sin(heading), math.cos(tilt), math.sin(tilt)
    fwd = np.array([ct * ch, ct * sh, st])
    right = np.array([sh, -ch, 0.0])
    up = np.array([-st * ch, -st * sh, ct])
    rel = points - cam_xyz
    tan_x, tan_y = half_fov_tangents(spec.fovy_deg, width, height)
    ok = in_frustum(rel @ fwd, rel @ right, rel @ up, tan_x, tan_y)
    ok &= np.linalg.norm(rel, axis=1) <= max_range
    return ok


_FRUSTUM_BLOCK = 65536  # (camera, aim, point) triples per block: temporaries stay in cache


def frustum_masks(
    cams: np.ndarray,
    heading: np.ndarray,
    tilt: np.ndarray,
    points: np.ndarray,
    tangents: tuple[float, float],
    max_distance: float,
) -> np.ndarray:
    """(C, T, N) bool: point n inside the frustum of the camera at cams[c] looking along
    (heading[c, t], tilt[c, t]) and within ``max_distance`` of it; ``tangents`` =
    ``half_fov_tangents(...)``. The vectorised form of ``frustum_mask``.

    A point's camera-frame coordinates are the dot products of its offset with the camera's
    forward (ct ch, ct sh, st), right (sh, -ch, 0) and up (-st ch, -st sh, ct) axes, written as
    broadcast sums of products. Cameras are processed in blocks of about ``_FRUSTUM_BLOCK``
    triples so the float temporaries stay in the CPU cache; blocking changes no value."""
    tan_x, tan_y = tangents
    n_c, n_t = heading.shape
    n = len(points)
    out = np.empty((n_c, n_t, n), bool)
    ch, sh, ct, st = np.cos(heading), np.sin(heading), np.cos(tilt), np.sin(tilt)
    fwd = [(ct * ch)[..., None], (ct * sh)[..., None], st[..., None]]  # (C, T, 1) each
    right = [sh[..., None], (-ch)[..., None]]
    up = [(-st * ch)[..., None], (-st * sh)[..., None], ct[..., None]]
    step = max(1, _FRUSTUM_BLOCK // max(1, n_t * n))
    for a in range(0, n_c, step):
        b = slice(a, min(n_c, a + step))
        rel = points[None, :, :] - cams[b, None, :]  # (c, N, 3)
        near = np.linalg.norm(rel, axis=-1) <= max_distance  # (c, N)
        rx, ry, rz = rel[:, None, :, 0], rel[:, None, :, 1], rel[:, None, :, 2]  # (c, 1, N)
        z = fwd[0][b] * rx
        z += fwd[1][b] * ry
        z += fwd[2][b] * rz
        x = right[0][b] * rx
        x += right[1][b] * ry
        y = up[0][b] * rx
        y += up[1][b] * ry
        y += up[2][b] * rz
        ok = in_frustum(z, x, y, tan_x, tan_y)
        ok &= near[:, None, :]
        out[b] = ok
    return out
