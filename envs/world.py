"""The World: one furnished room in MuJoCo with the robot in it; the facade the agent uses.

Every action happens in MuJoCo and is charged simulated seconds by the one ``TimeModel``:

- ``drive(path, final_yaw)`` and ``move_head(pan, tilt)`` move the servo targets along the path
  (turn in place towards each segment, drive it, turn to the final heading) or the head slew at
  the time model's speeds, stepping the physics through the motion, then hold the final target
  until the joints settle within 1 mm / 1 mrad. The physics clock therefore runs about as long as
  the charged time (plus the settle); ``sim_time`` is charged exactly the time model's figure.
- ``capture()`` renders from the head camera where the joints really are after the motion, and
  charges ``TimeModel.image_cost``.

Rendering is off-screen (``MUJOCO_GL=egl``; on a CPU Mesa's llvmpipe does it). One renderer per
image size is kept for the World's life, and all renderers of the process share one GL context
(render from one thread). Segmentation and depth come from ONE pass (MuJoCo's segmentation
colours and the depth buffer of the same draw); RGB, only when asked, is a second pass. The head camera's render option hides the robot's geom group and
shows the ceiling; the top-down overview (orthographic) shows the robot and hides the ceiling.
Depth is the distance along the optical axis in metres (as ``mujoco.Renderer`` gives it). No
multisampling (see ``envs/arena.py``): RGB edges are aliased, segmentation is exact.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco/dm_control are first imported

import atexit
import logging
import math
import weakref

import mujoco
import numpy as np
from dm_control import mjcf
from dm_control.mujoco import wrapper

from ctxsearch.envs.arena import MAX_IMAGE_SIZE, OVERHEAD_GEOM_GROUP, WALL_THICKNESS
from ctxsearch.envs.camera import Frame, PinholeCamera
from ctxsearch.envs.entities import body_name
from ctxsearch.envs.house_view import RoomCulling
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot import (
    JOINTS,
    ROBOT_GEOM_GROUP,
    pose_to_qpos,
    qpos_to_pose,
    robot_dynamics,
)
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, TimeModel, wrap_angle
from ctxsearch.envs.task import RoomTask, start_pose
from ctxsearch.envs.world_store import world_model
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.errors import CtxsearchError

log = logging.getLogger(__name__)

CONTROL_STEPS = 5  # physics steps per servo-target update (50 ms at the 10 ms physics step)
SETTLE_POS_TOL = 1e-3  # m / rad: the joints count as settled within this of the target ...
SETTLE_VEL_TOL = 1e-2  # ... and slower than this (m/s, rad/s)
MAX_SETTLE_S = 3.0  # give up settling after this much physics time (never reached in practice)
EGL_HINT = "apt-get install -y libegl1 libgl1-mesa-dri"

_gl_renderer: str | None = None  # the GL renderer string, once a renderer has been made


_shared_gl = None  # the process's one GL context, shared by every renderer (see _Renderer)


def _shared_gl_context():
    """The process's GL context, created on first use."""
    global _shared_gl
    if _shared_gl is None:
        from mujoco.rendering.classic import gl_context

        _shared_gl = gl_context.GLContext(*MAX_IMAGE_SIZE)
        # Registered after the GL backend's own exit hook (EGL registers eglTerminate when its
        # first context is made), so it runs before it: hooks run last-registered first.
        atexit.register(_shutdown_gl)
    return _shared_gl


class _Renderer(mujoco.Renderer):
    """``mujoco.Renderer`` on the process's shared GL context that also reads segmentation and
    depth from a single draw.

    ``mujoco.Renderer`` makes a GL context per renderer; on llvmpipe a fresh context costs about
    150 ms before its first frame (shader compilation), paid again for every room. Here every
    renderer of every World shares one context and owns only its ``MjrContext`` and scene, so
    ``__init__`` sets up what ``mujoco.Renderer.__init__`` does, with that context, and ``close``
    frees the ``MjrContext`` only.
    """

    def __init__(self, model: mujoco.MjModel, height: int, width: int) -> None:
        self._gl_context = None
        self._mjr_context = None
        self._width, self._height, self._model = width, height, model
        self._scene = mujoco.MjvScene(model=model, maxgeom=max(1000, 2 * model.ngeom))
        self._scene_option = mujoco.MjvOption()
        self._rect = mujoco.MjrRect(0, 0, width, height)
        self._gl_context = _shared_gl_context()
        self._gl_context.make_current()
        self._mjr_context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150.value)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._mjr_context)
        self._mjr_context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._depth_rendering = False
        self._segmentation_rendering = False

    def close(self) -> None:
        """Free this renderer's MjrContext (the shared GL context stays)."""
        if self._mjr_context is not None and self._gl_context is not None:
            self._gl_context.make_current()
            self._mjr_context.free()
        self._mjr_context = None
        self._gl_context = None

    def render_ids_depth(
        self, geom_instance: np.ndarray, depth: bool
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Instance ids (H, W) int32 via ``geom_instance`` (geom id -> instance id) and, if
        ``depth``, the depth image (H, W) float32 in metres, from one segmentation draw of the
        scene last passed to ``update_scene``."""
        if self._mjr_context is None:
            raise RuntimeError("render cannot be called after close.")
        scn, h, w = self._scene, self._height, self._width
        flags = scn.flags
        saved = flags.copy()
        flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = True
        flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = True
        self._gl_context.make_current()
        seg = np.empty((h, w, 3), np.uint8)
        zbuf = np.empty((h, w), np.float32) if depth else None
        try:
            mujoco.mjr_render(self._rect, scn, self._mjr_context)
            mujoco.mjr_readPixels(seg, zbuf, self._rect, self._mjr_context)
        finally:
            np.copyto(flags, saved)
        # Segmentation colour = scene-geom index + 1 (0: background), 24 bits over r, g, b.
        segid = seg[::-1, :, 0].astype(np.int32)
        segid |= seg[::-1, :, 1].astype(np.int32) << 8
        if scn.ngeom >= 1 << 16:
            segid |= seg[::-1, :, 2].astype(np.int32) << 16
        geoms = scn.geoms[: scn.ngeom]
        objtype = np.fromiter((g.objtype for g in geoms), np.int32, scn.ngeom)
        objid = np.fromiter((g.objid for g in geoms), np.int32, scn.ngeom)
        seg_to_inst = np.full(scn.ngeom + 1, -1, np.int32)
        is_geom = objtype == int(mujoco.mjtObj.mjOBJ_GEOM)
        seg_to_inst[1:][is_geom] = geom_instance[objid[is_geom]]
        ids = seg_to_inst[segid]
        return ids, (self._linear_depth(zbuf[::-1]) if depth else None)

    def _linear_depth(self, z: np.ndarray) -> np.ndarray:
        """Metric depth from the (reversed-Z) depth buffer, as ``mujoco.Renderer`` computes it."""
        extent = self._model.stat.extent
        near = np.float32(self._model.vis.map.znear * extent)
        far = np.float32(self._model.vis.map.zfar * extent)
        c_coef = -(far + near) / (far - near)
        d_coef = -(np.float32(2) * far * near) / (far - near)
        c_coef = np.float32(-0.5) * c_coef - np.float32(0.5)
        d_coef = np.float32(-0.5) * d_coef
        return (d_coef / (z.astype(np.float64) + c_coef)).astype(np.float32)

    def render_rgb(self) -> np.ndarray:
        """An RGB image (H, W, 3) uint8 of the scene last passed to ``update_scene``."""
        self.disable_depth_rendering()
        self.disable_segmentation_rendering()
        return self.render()


# The renderers of every World not closed yet, closed at exit before the GL context goes.
_open_renderers: dict[int, dict] = {}


def _close_renderers(renderers: dict) -> None:
    _open_renderers.pop(id(renderers), None)
    for r in renderers.values():
        r.close()
    renderers.clear()


def _shutdown_gl() -> None:
    """At exit: close every World's renderers, then free the shared GL context."""
    global _shared_gl
    for renderers in list(_open_renderers.values()):
        _close_renderers(renderers)
    if _shared_gl is not None:
        _shared_gl.free()
        _shared_gl = None


class World:
    """A room built in MuJoCo with the robot in it (see the module docstring)."""

    def __init__(
        self,
        layout: RoomLayout,
        catalog: Catalog | None = None,
        *,
        width: int = 320,
        height: int = 240,
        shadows: bool = False,
        spec: RobotSpec | None = None,
        time_model: TimeModel | None = None,
    ) -> None:
        _check_size(width, height)
        self.layout = layout
        self.catalog = catalog or load_catalog()
        self.spec = spec or RobotSpec()
        self.time_model = time_model or TimeModel()
        self.width, self.height = int(width), int(height)
        self.sim_time = 0.0
        self._task: RoomTask | None = None
        world = world_model(layout, self.catalog, self.spec)
        self.physics = mjcf.Physics.from_model(wrapper.MjModel(world.copy()))
        self._m, self._d = self.physics.model.ptr, self.physics.data.ptr
        joints = [_name_id(self._m, mujoco.mjtObj.mjOBJ_JOINT, f"robot/{j}") for j in JOINTS]
        self._qadr = self._m.jnt_qposadr[joints].astype(int)
        self._vadr = self._m.jnt_dofadr[joints].astype(int)
        self._act = np.array(
            [_name_id(self._m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"robot/{j}") for j in JOINTS]
        )
        self._cam_id = _name_id(self._m, mujoco.mjtObj.mjOBJ_CAMERA, "robot/head_cam")
        own = robot_dynamics(world.robot_xml, self._m)  # the robot's motion, without the room
        self._motion = (own, mujoco.MjData(own)) if own is not None else (self._m, self._d)
        self._geom_instance = _geom_instances(self._m, layout)
        self._set_pose(start_pose(layout))  # where the composer task's episode starts
        self._culling = (
            RoomCulling(layout, self._m.geom_rgba, self._geom_instance) if layout.is_house else None
        )
        self._m.light_castshadow[:] = 1 if shadows else 0
        self._head_option = mujoco.MjvOption()
        self._head_option.geomgroup[ROBOT_GEOM_GROUP] = 0
        self._head_option.geomgroup[OVERHEAD_GEOM_GROUP] = 1
        self._overview_option = mujoco.MjvOption()
        self._overview_option.geomgroup[ROBOT_GEOM_GROUP] = 1
        self._overview_option.geomgroup[OVERHEAD_GEOM_GROUP] = 0
        self._renderers: dict[tuple[int, int], _Renderer] = {}
        self._finalizer = weakref.finalize(self, _close_renderers, self._renderers)
        _open_renderers[id(self._renderers)] = self._renderers
        mujoco.mj_forward(self._m, self._d)

    @property
    def task(self) -> RoomTask:
        """The world as a composer Task (``envs.task.RoomTask``: its arena, robot and objects
        entities, made on first use; their elements bind to ``physics`` by name). The World
        itself runs on the compiled model alone (``envs.world_store``)."""
        if self._task is None:
            self._task = RoomTask(self.catalog, layout=self.layout, spec=self.spec)
            self._task.initialize_episode_mjcf(np.random.RandomState(self.layout.seed % 2**32))
        return self._task

    # -- pose and motion ---------------------------------------------------------------------

    def pose(self) -> RobotPose:
        """The robot's pose, read from the joint positions."""
        return qpos_to_pose(self._d.qpos[self._qadr])

    def reset_pose(self, pose: RobotPose) -> None:
        """Teleport the robot to ``pose`` (episode start); no time charged."""
        self._set_pose(pose)
        mujoco.mj_forward(self._m, self._d)

    def _set_pose(self, pose: RobotPose) -> None:
        """Joint positions and servo targets to ``pose``, velocities zero (``Robot.set_pose``)."""
        q = pose_to_qpos(pose, self.spec)
        self._d.qpos[self._qadr] = q
        self._d.qvel[self._vadr] = 0.0
        self._d.ctrl[self._act] = q

    def drive(self, path: np.ndarray, final_yaw: float | None = None) -> float:
        """Follow the polyline ``path`` (K, 2): turn in place towards each segment, drive it, then
        turn to ``final_yaw`` (if given). A path not starting at the robot gets the robot's
        position prepended. Returns the seconds charged (``TimeModel.drive_time``)."""
        path = np.asarray(path, float).reshape(-1, 2)
        q0 = self._d.qpos[self._qadr].copy()
        if len(path) == 0 or np.hypot(*(path[0] - q0[:2])) > 0.01:
            path = np.vstack([q0[:2], path])
        knots_t, knots_q = [0.0], [q0]
        q = q0.copy()
        tm = self.time_model
        for a, b in zip(path[:-1], path[1:], strict=True):
            length = float(np.hypot(*(b - a)))
            if length < 1e-9:
                continue
            heading = math.atan2(b[1] - a[1], b[0] - a[0])
            knots_t.append(knots_t[-1] + tm.turn_time(q[2], heading))
            q = q.copy()
            q[2] += wrap_angle(heading - q[2])
            knots_q.append(q)
            q = q.copy()
            q[:2] = b
            knots_t.append(knots_t[-1] + tm.travel_time(length))
            knots_q.append(q)
        if final_yaw is not None:
            knots_t.append(knots_t[-1] + tm.turn_time(q[2], final_yaw))
            q = q.copy()
            q[2] += wrap_angle(final_yaw - q[2])
            knots_q.append(q)
        self._execute(np.asarray(knots_t), np.asarray(knots_q))
        seconds = float(tm.drive_time(path, wrap_angle(q0[2]), final_yaw))
        self.sim_time += seconds
        return seconds

    def move_head(self, pan: float, tilt: float) -> float:
        """Slew the head to (pan, tilt), clipped to the joint limits. Returns the seconds charged
        (``TimeModel.head_time``)."""
        pan, tilt = self.spec.clip_head(pan, tilt)
        q0 = self._d.qpos[self._qadr].copy()
        q1 = q0.copy()
        q1[3:] = pan, tilt
        seconds = float(self.time_model.head_time(q0[3], q0[4], pan, tilt))
        self._execute(np.array([0.0, seconds]), np.stack([q0, q1]))
        self.sim_time += seconds
        return seconds

    def _execute(self, knots_t: np.ndarray, knots_q: np.ndarray) -> None:
        """Step the physics while the servo targets follow the piecewise-linear joint trajectory
        (knots_t (K,), knots_q (K, 5)), then hold the last knot until the joints settle."""
        m, d = self._motion  # the robot's own model (``robot_dynamics``), or the world's
        _copy_state(self._d, d)
        dt = CONTROL_STEPS * m.opt.timestep
        total = float(knots_t[-1])
        n = math.ceil(total / dt - 1e-9) if total > 0 else 0
        # every tick's targets at once (np.interp gives each the same number as alone)
        ticks = np.minimum(np.arange(1, n + 1) * dt, total)
        for row in np.column_stack([np.interp(ticks, knots_t, knots_q[:, j]) for j in range(5)]):
            d.ctrl[self._act] = row
            mujoco.mj_step(m, d, CONTROL_STEPS)
        target = knots_q[-1]
        d.ctrl[self._act] = target
        for _ in range(math.ceil(MAX_SETTLE_S / dt)):
            if (
                np.abs(d.qpos[self._qadr] - target).max() < SETTLE_POS_TOL
                and np.abs(d.qvel[self._vadr]).max() < SETTLE_VEL_TOL
            ):
                break
            mujoco.mj_step(m, d, CONTROL_STEPS)
        _copy_state(d, self._d)
        mujoco.mj_forward(self._m, self._d)

    # -- images --------------------------------------------------------------------------------

    def camera_info(self) -> PinholeCamera:
        """The head camera where it is now."""
        return PinholeCamera(
            position=self._d.cam_xpos[self._cam_id].copy(),
            xmat=self._d.cam_xmat[self._cam_id].reshape(3, 3).copy(),
            fovy_deg=float(self._m.cam_fovy[self._cam_id]),
            width=self.width,
            height=self.height,
        )

    def ray_instances(
        self, origin: np.ndarray, points: np.ndarray, reach: float = 1e3
    ) -> np.ndarray:
        """(N,) int: the object instance each ray from ``origin`` (3,) through ``points`` (N, 3)
        meets first among the geoms the head camera shows (-1: none, or the room's walls and
        floor); no image, no time charged (``mj_multiRay``: about 3 us a ray in a house).
        ``reach``: geoms farther than this (m) are left out (MuJoCo's cutoff): a ray that meets
        nothing within it reads -1, one that does reads the same as without it, and the rays are
        cheaper (about 30% for a small object's grid in an apartment)."""
        o = np.asarray(origin, float).reshape(3)
        vec = np.asarray(points, float).reshape(-1, 3) - o
        n = len(vec)
        if n == 0:
            return np.zeros(0, int)
        vec /= np.maximum(np.linalg.norm(vec, axis=1), 1e-12)[:, None]
        geom = np.full(n, -1, np.int32)
        dist = np.zeros(n)
        groups = np.asarray(self._head_option.geomgroup, np.uint8)
        mujoco.mj_multiRay(
            self._m, self._d, o, vec.ravel(), groups, 1, -1, geom, dist, None, n, reach
        )
        return np.where(geom >= 0, self._geom_instance[np.maximum(geom, 0)], -1)

    def capture(self, rgb: bool = False, depth: bool = True) -> Frame:
        """An image from the head camera at the robot's actual pose: instance ids always, depth
        and RGB as asked. Charges ``TimeModel.image_cost``."""
        r = self._renderer(self.width, self.height)
        if self._culling is not None:  # a house: leave out the rooms the camera cannot see
            self._culling.hide(
                self._d.cam_xpos[self._cam_id],
                self._d.cam_xmat[self._cam_id],
                float(self._m.cam_fovy[self._cam_id]),
                self.width,
                self.height,
            )
        try:
            r.update_scene(self._d, self._cam_id, self._head_option)
        finally:
            if self._culling is not None:
                self._culling.restore()
        ids, dep = r.render_ids_depth(self._geom_instance, depth)
        color = r.render_rgb() if rgb else None
        self.sim_time += self.time_model.image_cost
        return Frame(color, dep, ids, self.camera_info(), self.pose())

    def render_overview(self, width: int = 640, height: int = 480) -> np.ndarray:
        """A top-down orthographic RGB image (H, W, 3) of the whole room, robot included (image
        right = +x, image up = +y; ``overview_pixels`` maps points onto it); no time charged."""
        _check_size(width, height)
        r = self._renderer(width, height)
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.orthographic = 1  # a map: walls do not lean; the free camera's fovy is then metres
        cam.distance = self.layout.height + 5.0
        cam.lookat[:] = 0.0, 0.0, 0.0
        cam.azimuth, cam.elevation = 90.0, -90.0  # image right = +x, image up = +y
        vis = self._m.vis.global_
        saved = vis.fovy, vis.orthographic
        vis.fovy, vis.orthographic = 2 * self._overview_half_height(width, height), 1
        try:
            r.update_scene(self._d, cam, self._overview_option)
        finally:
            vis.fovy, vis.orthographic = saved
        return r.render_rgb()

    def overview_pixels(
        self, points: np.ndarray, width: int = 640, height: int = 480
    ) -> np.ndarray:
        """World points (N, 3) or (N, 2) -> their pixels (N, 2) (u right, v down) in
        ``render_overview(width, height)``."""
        pts = np.atleast_2d(np.asarray(points, float))
        px_per_m = height / (2 * self._overview_half_height(width, height))
        return np.column_stack(
            [width / 2 + px_per_m * pts[:, 0], height / 2 - px_per_m * pts[:, 1]]
        )

    def _overview_half_height(self, width: int, height: int) -> float:
        """Half the overview's height in metres: the room, its walls and a 0.2 m border fit."""
        hw = self.layout.width / 2 + WALL_THICKNESS + 0.2
        hd = self.layout.depth / 2 + WALL_THICKNESS + 0.2
        return max(hd, hw * height / width)

    def _renderer(self, width: int, height: int) -> _Renderer:
        if not self._finalizer.alive:
            raise RuntimeError("this World is closed")
        key = (width, height)
        if key not in self._renderers:
            self._renderers[key] = _make_renderer(self.physics.model.ptr, width, height)
        return self._renderers[key]

    # -- lifetime ------------------------------------------------------------------------------

    def close(self) -> None:
        """Free the renderers (GL contexts). The World cannot render afterwards."""
        self._finalizer()

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _copy_state(src: mujoco.MjData, dst: mujoco.MjData) -> None:
    """What a physics step reads of the robot's state (both models have only its joints and
    actuators, in the same order: ``robot_dynamics``), from ``src`` to ``dst``."""
    if src is dst:
        return
    dst.time = src.time
    for name in ("qpos", "qvel", "act", "ctrl", "qacc_warmstart", "qfrc_applied"):
        getattr(dst, name)[:] = getattr(src, name)


def _name_id(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str) -> int:
    i = int(mujoco.mj_name2id(model, kind, name))
    if i < 0:
        raise RuntimeError(f"the world's model has no {name}")
    return i


def _geom_instances(model: mujoco.MjModel, layout: RoomLayout) -> np.ndarray:
    """(ngeom,) int32: the instance id owning each geom of the world's ``model``, -1 for the
    others (``envs.entities.RoomObjects.geom_instance_ids`` on the compiled model)."""
    body_to_inst = np.full(model.nbody, -1, np.int32)
    for o in layout.objects:
        body_to_inst[_name_id(model, mujoco.mjtObj.mjOBJ_BODY, f"objects/{body_name(o.id)}")] = o.id
    return body_to_inst[model.geom_bodyid]


def _check_size(width: int, height: int) -> None:
    if not (0 < width <= MAX_IMAGE_SIZE[0] and 0 < height <= MAX_IMAGE_SIZE[1]):
        raise ValueError(
            f"image size {width}x{height} outside 1x1..{MAX_IMAGE_SIZE[0]}x{MAX_IMAGE_SIZE[1]}"
        )


def _make_renderer(model: mujoco.MjModel, width: int, height: int) -> _Renderer:
    """A renderer, with a one-line CtxsearchError when off-screen OpenGL cannot start."""
    global _gl_renderer
    try:
        r = _Renderer(model, height=height, width=width)
    except Exception as exc:  # EGL/GL loading fails with ImportError, OSError, RuntimeError...
        detail = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise CtxsearchError(
            f"off-screen rendering (MUJOCO_GL={os.environ.get('MUJOCO_GL')}) could not start "
            f"({detail}); install Mesa's EGL: {EGL_HINT}"
        ) from None
    if _gl_renderer is None:
        try:
            from OpenGL import GL

            _gl_renderer = GL.glGetString(GL.GL_RENDERER).decode()
        except Exception as exc:  # informative only: never fail a render for it
            _gl_renderer = f"unknown ({type(exc).__name__})"
        log.info("OpenGL renderer: %s", _gl_renderer)
    return r


def gl_renderer() -> str | None:
    """The OpenGL renderer string (e.g. Mesa's llvmpipe), once any World has rendered."""
    return _gl_renderer
