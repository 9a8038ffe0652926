"""The search task as a Gymnasium environment: ``ctxsearch/ObjectSearch-v0``.

``import ctxsearch.agent.gym_env`` registers it; then ::

    env = gymnasium.make("ctxsearch/ObjectSearch-v0", style="office", detector="perfect",
                         kb="build/kb_office.sqlite", width=64, height=48)
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

An episode is the benchmark's (``ctxsearch bench search``, ``agent.search.draw``):
``reset(seed=s)`` draws the benchmark's episode 0 for seed s (``options={"index": k}``: its
episode k) with agent.search.draw, as the benchmark does: held-out rooms the store (``kb``) did
not learn in, a target drawn among the room's small types, a start from which it is not visible
and from which the oracle's planner detects it within the budget (with the env's detector;
the task has no oracle, so the planner is asked only whether, not when: ``DrawSpec.first_view``
False, the same episodes at a fraction of the images). ``reset()`` without a seed draws the seed
from the environment's own generator, so one seeded reset fixes every later episode. A reset to
a (seed, index) drawn before in the process reuses its draw; ``draw_cache=DIR`` keeps the draws
on disk for later processes (vectorised copies, the next training run). What a reset costs:
``scripts/examples/gym_timing.py`` (docs/speed.md).

Actions (``Discrete(8)``, ``ACTIONS``), each charged by the one time model
(``envs.robot_spec.TimeModel``) through the World, as every search policy is:

====  ==========  ======================================================================
 0    forward     drive 0.5 m straight ahead (as far as the occupancy grid is free; 0 s
                  when blocked)
 1    turn_left   turn the base +30 degrees
 2    turn_right  turn the base -30 degrees
 3    pan_left    pan the head +30 degrees (within its limits)
 4    pan_right   pan the head -30 degrees
 5    tilt_up     tilt the head +15 degrees (within its limits)
 6    tilt_down   tilt the head -15 degrees
 7    look        take an image (``image_cost``) and run the detector on it
====  ==========  ======================================================================

Reward: minus the simulated seconds the action took. ``terminated``: the search ended as the
benchmark's do (agent.search.measures): a ``look`` whose image shows the target is followed by a
confirming image from the same pose (its seconds charged too), and a detection it confirms ends
the episode; ``info["success"]`` says whether it was a true instance of the target (a confirmed
look-alike or false positive ends the episode as a failure); ``truncated``: the budget (``budget_s``) is spent, or ``MAX_EPISODE_STEPS``
steps were taken (Gymnasium's TimeLimit: a blocked forward or a head at its limit costs 0 s).

``map="remembered"``: the episode's house is one the robot toured the day before (the
benchmark's ``--map remembered``: episodes on day 1, the tour of day 0 made by agent.search.tour
and kept in the same cache); the furniture it remembers is known from the start (the
``context`` rows rank its relation volumes before the first image; ``info["remembered_furniture"]``
counts it). The default, ``"given"``, knows only what it detects.

Observations (a Dict): ``rgb`` (H, W, 3) uint8 and ``depth`` (H, W, 1) float32 metres (clipped
to ``DEPTH_MAX``) of the last ``look`` (zeros before the first: images cost time), ``pose`` (x,
y, yaw), ``head`` (pan, tilt), ``elapsed`` simulated seconds (saturating at twice the budget), ``target`` (the target's index in
the catalog's types), ``detected`` (which types the detector has reported so far) and, with a
store, ``context``: the ``top_k`` relation volumes v_rel(b) of the objects detected so far,
best first by the lower bound of P(rel(target)) (``knowledge.ranking.candidate_volumes``), one
row each of ``CONTEXT_FEATURES`` (centre, yaw, half extents, the interval's bounds, 1), zero
rows after the last.

It lives in ``agent/``, not ``envs/``: the start pose and ``forward``'s collision test need the
occupancy grid (agent.navigation) and the held-out rooms are the search's (agent.search).
"""

from __future__ import annotations

import contextlib
import math
import numbers
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.agent.perception_modes import DEFAULT_DETECTOR
from ctxsearch.agent.search import measures
from ctxsearch.agent.search.config import DEFAULT_BUDGET_S, MapConfig
from ctxsearch.agent.search.context import confirming_detection
from ctxsearch.agent.search.draw import DrawSpec, draw_episodes
from ctxsearch.agent.search.episode import Episode, EpisodeDraw, episode_layout
from ctxsearch.agent.search.priors import open_knowledge
from ctxsearch.agent.search.runner import toured
from ctxsearch.envs.camera import Frame
from ctxsearch.envs.detector import Detection, DetectorModel, SimDetector, default_or_named
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import WorldStyle, resolve_style
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotSpec, TimeModel, wrap_angle
from ctxsearch.envs.task import CAMERA_SIZE, check_camera_size
from ctxsearch.envs.world import World
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.errors import ArgumentTypeError, ArgumentValueError, CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.home_map import HomeMap
from ctxsearch.knowledge.options import MapMode
from ctxsearch.knowledge.ranking import KBProbabilities, candidate_volumes

ENV_ID = "ctxsearch/ObjectSearch-v0"
ACTIONS = (
    "forward",
    "turn_left",
    "turn_right",
    "pan_left",
    "pan_right",
    "tilt_up",
    "tilt_down",
    "look",
)
FORWARD_M = 0.5
TURN_RAD = math.radians(30.0)
PAN_RAD = math.radians(30.0)
TILT_RAD = math.radians(15.0)
DEPTH_MAX = 20.0  # m: depth beyond (the background) reads as this
POSITION_LIMIT = 100.0  # m: |x|, |y| of any room or house the generators make
ELAPSED_LIMIT = 2.0  # the ``elapsed`` observation saturates at this many budgets
MAX_EPISODE_STEPS = 2000
DEFAULT_TOP_K = 8
CONTEXT_FEATURES = ("cx", "cy", "cz", "yaw", "hx", "hy", "hz", "p_low", "p_high", "valid")
# given: the robot knows nothing but what it detects (the true grid bounds its motion);
# remembered: the house is one it toured the day before, its remembered furniture known from
# the start (the context's volumes, ``info["remembered_furniture"]``)
MAPS = (MapMode.GIVEN.value, MapMode.REMEMBERED.value)


def draw_episode(
    style: WorldStyle,
    seed: int,
    catalog: Catalog,
    *,
    index: int = 0,
    budget_s: float = DEFAULT_BUDGET_S,
    exclude_seeds: set[int] | frozenset[int] = frozenset(),
    cache: Path | None = None,
    **spec_fields,
) -> tuple[Episode, RoomLayout]:
    """Episode ``index`` of the benchmark's episodes for ``seed`` (the draw of ``DrawSpec.make(
    style, index + 1, seed, ..., detector=detector)``: agent.search.draw's worlds in order, the
    target not visible from the start and detectable within the budget) and its room's layout.
    ``cache``: a directory where the draw is kept for later processes (agent.search.draw_store:
    the benchmark's draw cache; None: this process only); ``spec_fields``: the draw's other
    fields by name (``detector``, ``day``: agent.search.draw.DrawSpec)."""
    spec = DrawSpec.make(style, index + 1, seed, catalog, budget_s, exclude_seeds, **spec_fields)
    spec = replace(spec, first_view=False)  # the task has no oracle: whether, not when
    draw = _DRAWS.get(spec)
    if draw is None:
        draw = draw_episodes(spec, catalog, cache=cache)
        _DRAWS[spec] = draw
        if len(_DRAWS) > DRAWS_KEPT:
            _DRAWS.popitem(last=False)
    _DRAWS.move_to_end(spec)
    ep = draw.episodes[index]
    return ep, episode_layout(generate_layout(style, ep.room_seed, catalog, day=ep.day), ep)


# The draws this process made, newest last: a reset to a (seed, index) drawn before (an
# evaluation that replays its seeds, vectorised copies of one task) takes its episode from here
# instead of checking the worlds again (a draw is deterministic in its spec).
DRAWS_KEPT = 64
_DRAWS: OrderedDict[DrawSpec, EpisodeDraw] = OrderedDict()


def _box(low, high, shape: tuple[int, ...] | None = None) -> spaces.Box:
    """A float32 Box (bounds broadcast to ``shape`` when one is given)."""
    lo, hi = np.asarray(low, np.float32), np.asarray(high, np.float32)
    if shape is not None:
        lo, hi = np.full(shape, lo, np.float32), np.full(shape, hi, np.float32)
    return spaces.Box(lo, hi, dtype=np.float32)


MAX_BUDGET_S = 1e9  # simulated seconds, as the CLI's --budget-seconds
MAX_TOP_K = 10_000  # context rows


@contextlib.contextmanager
def _api_errors() -> Iterator[None]:
    """The project's one-line errors raised inside as what Python callers catch: a bad value (an
    unknown name, a file that is not what it should be) is also a ValueError, a bad type also a
    TypeError (``ArgumentValueError``, ``ArgumentTypeError``)."""
    try:
        yield
    except (ValueError, TypeError):
        raise
    except CtxsearchError as exc:
        raise ArgumentValueError(str(exc)) from None


def _check_arguments(style, detector, kb, budget_s, top_k, render_mode, draw_cache) -> None:
    """A one-line error for an argument of the wrong type (``ArgumentTypeError``, a TypeError)
    or out of range (``ArgumentValueError``, a ValueError); the files they name are checked by
    their loaders: budget_s a finite number in (0, MAX_BUDGET_S], top_k a whole number in
    [1, MAX_TOP_K] (not a bool), names strings or paths."""
    for name, value, kinds in (
        ("style", style, (str, Path)),
        ("detector", detector, (str, Path, type(None))),
        ("kb", kb, (str, Path, KnowledgeBase, type(None))),
        ("draw_cache", draw_cache, (str, Path, type(None))),
    ):
        if not isinstance(value, kinds):
            raise ArgumentTypeError(f"{name} must be a name or a path, got {value!r}"[:300])
        if isinstance(value, str) and not value:
            raise ArgumentValueError(f"{name} must be a name or a path, got {value!r}")
    if isinstance(budget_s, bool) or not isinstance(budget_s, numbers.Real):
        raise ArgumentTypeError(f"budget_s must be a number of seconds, got {budget_s!r}"[:300])
    if not (0 < float(budget_s) <= MAX_BUDGET_S):  # NaN and inf fail too
        raise ArgumentValueError(
            f"budget_s must be a number of seconds in (0, {MAX_BUDGET_S:g}], got {budget_s!r}"
        )
    if isinstance(top_k, bool) or not isinstance(top_k, numbers.Integral):
        raise ArgumentTypeError(f"top_k must be a whole number, got {top_k!r}"[:300])
    if not 1 <= int(top_k) <= MAX_TOP_K:
        raise ArgumentValueError(f"top_k must be in [1, {MAX_TOP_K}], got {top_k!r}")
    if render_mode is not None and not isinstance(render_mode, str):
        raise ArgumentTypeError(f"render_mode must be a string, got {render_mode!r}"[:300])
    if render_mode is not None and render_mode not in ObjectSearchEnv.metadata["render_modes"]:
        raise ArgumentValueError(f"unknown render_mode {render_mode!r} (known: rgb_array)")


class ObjectSearchEnv(gymnasium.Env):
    """Find an object of the target type in a held-out room (see the module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(
        self,
        style: str = "office",
        detector: str | Path | None = None,
        kb: str | Path | KnowledgeBase | None = None,
        *,
        width: int = CAMERA_SIZE[0],
        height: int = CAMERA_SIZE[1],
        budget_s: float = DEFAULT_BUDGET_S,
        top_k: int = DEFAULT_TOP_K,
        render_mode: str | None = None,
        draw_cache: str | Path | None = None,
        map: str = "given",  # noqa: A002 - the CLI's name (--map)
    ) -> None:
        _check_arguments(style, detector, kb, budget_s, top_k, render_mode, draw_cache)
        if map not in MAPS:
            raise ArgumentValueError(f"map must be one of {', '.join(MAPS)}, got {map!r}"[:300])
        self.map = MapMode(map)
        self.draw_cache = None if draw_cache is None else Path(draw_cache)
        self.catalog = load_catalog()
        with _api_errors():
            self.style = resolve_style(style, self.catalog)
            self.detector_model: DetectorModel = default_or_named(
                detector, self.catalog, DEFAULT_DETECTOR
            )
            self.width, self.height = check_camera_size(width, height)
            self.kb, self.learned = self._knowledge(kb)
        self.budget_s, self.top_k, self.render_mode = float(budget_s), int(top_k), render_mode
        self.robot_spec, self.time_model = RobotSpec(), TimeModel()
        self._types = [t.name for t in self.catalog.types]
        self.action_space = spaces.Discrete(len(ACTIONS))
        self.observation_space = self._observation_space()
        self.world: World | None = None
        self.home: HomeMap | None = None  # the remembered map of the episode's house
        self.episode: Episode | None = None
        self.layout: RoomLayout | None = None

    # ----------------------------------------------------------------- construction
    def _knowledge(self, kb) -> tuple[KnowledgeBase | None, frozenset[int]]:
        if kb is None or isinstance(kb, KnowledgeBase):
            return kb, frozenset()
        knowledge, learned = open_knowledge(kb, self.catalog)
        return knowledge, frozenset(learned)

    def _observation_space(self) -> spaces.Dict:
        h, w, n = self.height, self.width, len(self._types)
        (pan_lo, pan_hi), (tilt_lo, tilt_hi) = self.robot_spec.pan_range, self.robot_spec.tilt_range
        lim = POSITION_LIMIT
        d: dict[str, spaces.Space] = {
            "rgb": spaces.Box(0, 255, (h, w, 3), np.uint8),
            "depth": _box(0.0, DEPTH_MAX, (h, w, 1)),
            "pose": _box([-lim, -lim, -math.pi], [lim, lim, math.pi]),
            "head": _box([pan_lo, tilt_lo], [pan_hi, tilt_hi]),
            "elapsed": _box([0.0], [ELAPSED_LIMIT * self.budget_s]),
            "target": spaces.Discrete(n),
            "detected": spaces.MultiBinary(n),
        }
        if self.kb is not None:
            d["context"] = _box(-lim, lim, (self.top_k, len(CONTEXT_FEATURES)))
        return spaces.Dict(d)

    # ----------------------------------------------------------------- the Gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict, dict]:
        """A new episode (see the module docstring): the observation and info."""
        super().reset(seed=seed)
        index = (options or {}).get("index", 0)
        if isinstance(index, bool) or not isinstance(index, int | np.integer):
            raise ArgumentTypeError(f"options['index'] must be a whole number, got {index!r}"[:300])
        if index < 0:
            raise ArgumentValueError(f"options['index'] must be >= 0, got {index!r}")
        ep_seed = seed if seed is not None else int(self.np_random.integers(2**31))
        self.episode, self.layout = draw_episode(
            self.style,
            int(ep_seed),
            self.catalog,
            index=int(index),
            budget_s=self.budget_s,
            exclude_seeds=self.learned,
            detector=self.detector_model,
            cache=self.draw_cache,
            day=1 if self.map is MapMode.REMEMBERED else 0,
        )
        self.home = self._remembered()
        self.close()
        self.world = World(
            self.layout, self.catalog, width=self.width, height=self.height, spec=self.robot_spec,
            time_model=self.time_model,
        )  # fmt: skip
        self.world.reset_pose(self.episode.start)
        self.grid = OccupancyGrid.from_layout(self.layout, self.robot_spec)
        self._detect = SimDetector(self.detector_model, self.layout, self.catalog, self.layout.seed)
        self._true_ids = {o.id for o in self.layout.objects if o.type == self.episode.target}
        self._t0 = self.world.sim_time
        self._rgb = np.zeros((self.height, self.width, 3), np.uint8)
        self._depth = np.zeros((self.height, self.width, 1), np.float32)
        self._detected = np.zeros(len(self._types), np.int8)
        # what the robot knows of the world: on the remembered map its furniture from the start
        self._known: dict[int, ObjectInstance] = {}
        if self.home is not None:
            self._known.update((o.id, o.instance()) for o in self.home.furniture)
        self.found_id: int | None = None
        self.success = False
        return self._observation(), self._info([])

    def _remembered(self) -> HomeMap | None:
        """On the remembered map: the map of the robot's tour of the episode's house the day
        before (agent.search.tour, cached as the benchmark's tours are); else None."""
        if self.map is not MapMode.REMEMBERED:
            return None
        ep = self.episode
        day0 = generate_layout(self.style, ep.room_seed, self.catalog, day=ep.day - 1)
        with _api_errors():
            return toured(day0, self.catalog, self.detector_model, MapConfig(), ep.day - 1)[0]

    def step(self, action) -> tuple[dict, float, bool, bool, dict]:
        """Do ``ACTIONS[action]``; observation, reward (minus its seconds), terminated,
        truncated, info."""
        if self.world is None or self.episode is None:
            raise CtxsearchError("call reset() before step()")
        if not self.action_space.contains(action):
            raise ArgumentValueError(
                f"invalid action {action!r} (0..{len(ACTIONS) - 1}: {', '.join(ACTIONS)})"[:300]
            )
        name = ACTIONS[int(action)]
        t = self.world.sim_time
        dets = self._look() if name == "look" else self._move(name)
        seconds = float(self.world.sim_time - t)
        terminated = self.found_id is not None
        truncated = not terminated and self.elapsed >= self.budget_s
        info = self._info(dets)
        info.update(action=name, seconds=seconds)
        return self._observation(), -seconds, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """With ``render_mode="rgb_array"``: a top-down view of the room and the robot."""
        if self.render_mode != "rgb_array" or self.world is None:
            return None
        return self.world.render_overview(320, 240)

    def close(self) -> None:
        """Free the World (its renderer); safe to call twice."""
        if self.world is not None:
            self.world.close()
            self.world = None

    # ----------------------------------------------------------------- acting
    @property
    def elapsed(self) -> float:
        """Simulated seconds since the episode began."""
        return float(self.world.sim_time - self._t0) if self.world is not None else 0.0

    def _move(self, name: str) -> list[Detection]:
        world = self.world
        p = world.pose()
        if name == "forward":
            goal = self._free_ahead(p.xy, p.yaw)
            if goal is not None:
                world.drive(goal[None, :])
        elif name in ("turn_left", "turn_right"):
            step = TURN_RAD if name == "turn_left" else -TURN_RAD
            world.drive(p.xy[None, :], wrap_angle(p.yaw + step))
        elif name in ("pan_left", "pan_right"):
            world.move_head(p.pan + (PAN_RAD if name == "pan_left" else -PAN_RAD), p.tilt)
        else:
            world.move_head(p.pan, p.tilt + (TILT_RAD if name == "tilt_up" else -TILT_RAD))
        return []

    def _free_ahead(self, xy: np.ndarray, yaw: float) -> np.ndarray | None:
        """The farthest point up to ``FORWARD_M`` ahead with a free grid all the way (None: not
        even 1 cm)."""
        step = 0.25 * self.grid.resolution
        ts = np.append(np.arange(step, FORWARD_M, step), FORWARD_M)
        pts = xy[None, :] + ts[:, None] * np.array([math.cos(yaw), math.sin(yaw)])
        free = self.grid.free_mask(pts)
        n = len(free) if free.all() else int(np.argmin(free))
        return pts[n - 1] if n > 0 and ts[n - 1] >= 0.01 else None

    def _image(self) -> list[Detection]:
        """One image where the head points, read by the detector; the observation kept."""
        frame: Frame = self.world.capture(rgb=True, depth=True)
        dets = self._detect(frame, float(self.world.sim_time))
        self._rgb = frame.rgb.copy()
        depth = np.nan_to_num(frame.depth, nan=DEPTH_MAX, posinf=DEPTH_MAX)
        self._depth = np.clip(depth, 0.0, DEPTH_MAX).astype(np.float32)[:, :, None]
        for d in dets:
            self._known.setdefault(d.instance_id, d.pose)
            self._detected[self._types.index(d.type)] = 1
        return dets

    def _look(self) -> list[Detection]:
        """An image; a detection of the target in it is confirmed by a second image from the same
        pose, as the benchmark's searches are (agent.search.context): a confirmed detection ends
        the episode, judged by ``measures.judge`` (a confirmed look-alike or false positive ends
        it as a failure); one not confirmed is forgotten."""
        target = self.episode.target
        dets = self._image()
        hit = next((d for d in dets if d.type == target), None)
        if hit is None or self.found_id is not None:
            return dets
        again = self._image()
        confirmed = confirming_detection(hit, again, target)
        if confirmed is None:
            self._known.pop(hit.instance_id, None)
        else:
            self.found_id = confirmed.instance_id
            self.success = measures.judge(self.found_id, self._true_ids)
        return dets + again

    # ----------------------------------------------------------------- observing
    def _observation(self) -> dict:
        p = self.world.pose()
        obs = {
            "rgb": self._rgb.copy(),
            "depth": self._depth.copy(),
            "pose": np.array([p.x, p.y, wrap_angle(p.yaw)], np.float32),
            "head": np.clip(
                np.array([p.pan, p.tilt], np.float32),
                self.observation_space["head"].low,
                self.observation_space["head"].high,
            ),
            "elapsed": np.array([min(self.elapsed, ELAPSED_LIMIT * self.budget_s)], np.float32),
            "target": self._types.index(self.episode.target),
            "detected": self._detected.copy(),
        }
        if self.kb is not None:
            obs["context"] = self.context_feature()
        return obs

    def context_feature(self) -> np.ndarray:
        """(top_k, len(CONTEXT_FEATURES)) float32: the best relation volumes of the objects
        detected so far for the target, with the learned interval's bounds; zero-padded."""
        out = np.zeros((self.top_k, len(CONTEXT_FEATURES)), np.float32)
        if self.kb is None:
            return out
        probs = KBProbabilities(self.kb, "low", rooms=len(self.learned) or None)
        target = self.episode.target
        cands = candidate_volumes(self._known.values(), target, self.catalog, probs)
        for row, c in zip(out, cands[: self.top_k], strict=False):
            lo, hi = self.kb.interval(c.relation, target)
            b = c.box
            row[:] = [*b.center, wrap_angle(b.yaw), *b.half, lo, hi, 1.0]
        return np.clip(out, -POSITION_LIMIT, POSITION_LIMIT)

    def _info(self, dets: list[Detection]) -> dict:
        ep = self.episode
        return {
            "style": ep.style,
            "room_seed": ep.room_seed,
            "target": ep.target,
            "elapsed": self.elapsed,
            "found_id": self.found_id,
            "success": bool(self.success),
            "detections": [(d.type, d.instance_id) for d in dets],
            "day": ep.day,
            "remembered_furniture": 0 if self.home is None else len(self.home.furniture),
        }


def register() -> None:
    """Register ``ENV_ID`` with Gymnasium (once; importing this module does it)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(
            id=ENV_ID,
            entry_point="ctxsearch.agent.gym_env:ObjectSearchEnv",
            max_episode_steps=MAX_EPISODE_STEPS,
        )


register()
