"""One policy's run of one episode: the clock and the budget, the robot's actions, and what the
robot knows so far. The behaviours (``coverage``, ``regions``, ``frontier``, ``online``) act on
a context through its public methods and state; the policies (``policies``) put them together.

The context senses only through a ``Perception`` (agent.interfaces, the protocol learning uses):
a real robot's detector plugs in as the simulated one does. It never reads the true layout: the
episode runner (``runner``) builds the sensor from it and judges the result
(``measures.judge``).

A search ends when a detection of the target is confirmed by a second image from the same pose
(one image's seconds more; ``CONFIRM_RADIUS_M``); a detection that is not confirmed is forgotten
and the search goes on.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from ctxsearch.agent.interfaces import Body, Perception, WrappedBody
from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.navigation import OccupancyGrid, plan_path
from ctxsearch.agent.recording import Recorder
from ctxsearch.agent.search import belief
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.agent.search.episode import Episode, GazeRecord, SearchResult
from ctxsearch.agent.search.maps import WorldMaps
from ctxsearch.agent.viewplan import Gaze, face_gaze
from ctxsearch.envs.camera import Frame
from ctxsearch.envs.detector import Detection
from ctxsearch.envs.robot_spec import RobotSpec, TimeModel, wrap_angle
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.persistence import Persistence

# A detection of the target is confirmed by a second image from the same pose before the search
# ends: a target-type detection in it within this distance (m, on the floor plane) of the first
# one's estimated position. A real robot that stopped at every report of its detector would end
# a fifth of its searches on clutter (measured with the realistic preset: 0.05 false detections
# per image over a few hundred images); a false positive gets a new position in every image, a
# true instance is detected again with its recall.
CONFIRM_RADIUS_M = 0.5
BELIEF_ENTITY = "world/search/belief"  # the recording's floor heat map of the belief
# the belief mass beyond each mapped room of the built map (knowledge.next_rooms), labelled
BEYOND_ENTITY = "world/search/beyond"
# the best place beyond the frontier at each decision (online.beyond) and where its way leaves
# the map, labelled with the belief a sweep there would find
FRONTIER_ENTITY = "world/search/beyond_frontier"


class SearchStopped(Exception):
    """Raised by a context's actions when the target was found or the budget is spent."""


def confirming_detection(
    hit: Detection, dets: Sequence[Detection], target: str
) -> Detection | None:
    """The detection of ``target`` in the confirming image's ``dets`` nearest to ``hit``'s
    estimated position, within ``CONFIRM_RADIUS_M`` of it; None: ``hit`` is not confirmed."""
    at = np.asarray(hit.pose.position[:2], float)

    def dist(d: Detection) -> float:
        return float(np.hypot(*(np.asarray(d.pose.position[:2], float) - at)))

    again = [d for d in dets if d.type == target and dist(d) <= CONFIRM_RADIUS_M]
    return min(again, key=dist) if again else None


class _PathMeter(WrappedBody):
    """A body that adds up the metres driven."""

    def __init__(self, body: Body):
        super().__init__(body)
        self.metres = 0.0

    def drive(self, path: np.ndarray, final_yaw: float | None = None) -> float:
        """Drive the wrapped body, counting the path's length."""
        p = self._b.pose()
        pts = np.vstack([p.xy[None, :], np.asarray(path, float).reshape(-1, 2)])
        self.metres += TimeModel.path_length(pts)
        return self._b.drive(path, final_yaw)


class SearchContext:
    """One policy's run of one episode: the body (an agent.interfaces ``Body``), what it senses
    (``perception``: its ``see`` reads an image, ``last_detections`` what it reported), the maps
    it was given (``maps``; on the built map it also builds its own, ``built``), the knowledge
    source (``probs``), the configuration the behaviours read (``config``: agent.search.config),
    the clock, the trace and the recording.

    Public state the behaviours share: ``seen`` (the seen map), ``known`` (objects detected so
    far, by instance id), ``looked_into`` (candidate regions looked into) and ``waiting``
    (regions no gaze reached yet on the built map; an exploration step clears it), and the
    indirect search's ``intermediate`` and ``predicted_gain``."""

    found_id: int | None  # the instance whose confirmed detection ended the search
    found_at: float | None  # seconds since the start when it was confirmed

    def __init__(
        self,
        episode: Episode,
        catalog: Catalog,
        body: Body,
        perception: Perception,
        maps: WorldMaps,
        *,
        probs: ss.ProbabilitySource | None = None,
        recorder: Recorder | None = None,
        config: SearchConfig | None = None,
    ):
        self.episode, self.catalog, self.maps = episode, catalog, maps
        # P(still where seen after d days) for the remembered sightings (agent.search.memory;
        # None, unless the runner sets it: the policy has no memory)
        self.persistence: Persistence | None = None
        # the settings the behaviours read (``online``, ``belief``, ``map``)
        self.config = config or SearchConfig()
        # called at each online decision (agent.search.online.OnlineSearch): (search, belief,
        # chosen option); read-only, for diagnostics (None: nothing)
        self.observer: Callable | None = None
        self.spec: RobotSpec = body.spec
        self.time_model: TimeModel = body.time_model
        self.body = _PathMeter(body)
        self.perception = perception
        self.built: BuiltMap | None = maps.new_built_map(episode.start, self.spec)
        # the remembered furniture as today's images update it (None: not a remembered map)
        self.memory = maps.furniture_memory(self.range_of)
        self.probs = probs
        self.recorder = recorder or Recorder(None)
        self.policy = "?"  # the policy's name, set when it runs (SearchPolicy.run)
        self.width, self.height = int(body.width), int(body.height)
        self.seen = maps.seen.copy()
        self.target = episode.target
        self.target_range = ss.effective_range(
            catalog.type(self.target), self.spec, self.width, self.height
        )
        self.known: dict[int, ObjectInstance] = {}
        self.trace: list[GazeRecord] = []
        self.log: list[str] = []
        self.found_id = self.found_at = None
        body.reset_pose(episode.start)
        self.t0 = float(body.sim_time)
        self._range_cache: dict[str, float] = {}
        self.looked_into: set[tuple] = set()
        self.waiting: set[tuple] = set()
        self.intermediate: str | None = None
        self.predicted_gain: float | None = None
        self._confirming, self.unconfirmed = False, 0  # confirming a detection; not confirmed
        # the robot's model of its detector for the target, and what every image missed
        self.curve = belief.detection_curve(
            catalog.type(self.target), maps.detector, self.spec, self.width, self.height
        )
        self.misses = belief.MissField(self.seen.points, self.curve)
        self._held: tuple[np.ndarray, np.ndarray] | None = None
        self.mass_left: float | None = None  # the belief's detectable mass left (online search)
        # the belief as it stands (set by a search that holds one): recorded after every image
        self.belief_now: Callable[[], np.ndarray | None] | None = None

    @property
    def sight_cap(self) -> float:
        """m: nothing further than this counts as seen (the built map's depth range)."""
        return self.config.map.depth_range_m

    @property
    def occluders(self):
        """What blocks the view: the robot's own map (built), the given map's footprints
        (``maps.occluders``), or None."""
        return self.built if self.built is not None else self.maps.occluders

    @property
    def grid(self) -> OccupancyGrid:
        """The grid the robot plans on: the given map's, or its built map as it stands."""
        return self.maps.grid if self.built is None else self.built.refresh()

    # ----------------------------------------------------------------- clock and knowledge
    @property
    def elapsed(self) -> float:
        """Simulated seconds since the episode started."""
        return float(self.body.sim_time) - self.t0

    def check(self) -> None:
        """Stop the policy if the target was found or the budget is spent."""
        if self.found_id is not None or self.elapsed >= self.episode.budget_s:
            raise SearchStopped

    def range_of(self, type_name: str) -> float:
        """The effective detection range of a type (cached)."""
        r = self._range_cache.get(type_name)
        if r is None:
            r = ss.effective_range(self.catalog.type(type_name), self.spec, self.width, self.height)
            self._range_cache[type_name] = r
        return r

    def furniture_map(self) -> list[ObjectInstance]:
        """The map the location constraint may assume: the furniture poses of ``maps`` (on the
        remembered map, what is left of it after today's images: agent.search.remembered)."""
        if self.memory is not None:
            return self.memory.objects()
        return list(self.maps.furniture)

    def found_of(self, type_name: str) -> int:
        """How many objects detected so far are of ``type_name``."""
        return sum(1 for o in self.known.values() if o.type == type_name)

    def note(self, msg: str) -> None:
        """A line in the result's log and the recording's text log."""
        self.log.append(f"[{self.elapsed:7.1f} s] {msg}")
        self.recorder.set_time(self.elapsed)
        self.recorder.log_text(f"{self.policy}: {msg}")

    # ----------------------------------------------------------------- acting
    def _after_image(self, frame: Frame, purpose: str) -> list[Detection]:
        self.perception.see(frame)
        dets = list(self.perception.last_detections)
        if self.built is not None:
            self.built.update(frame)
        if self.memory is not None:
            for gone in self.memory.observe(frame, dets):
                self.note(f"{gone.type} #{gone.id} of the remembered map is not there: dropped")
        hit = self._target_hit(dets)
        if hit is not None and not self._confirming:  # what the miss field held there before
            near = self.misses.near(hit.pose.position, CONFIRM_RADIUS_M)
            self._held = (near, self.misses.miss[near].copy())
        if frame.depth is not None:
            shown = self.seen.update(frame.camera, frame.depth)
        else:
            shown = self.seen.mark_frustum(frame.camera, self.curve.reach)
        self.misses.observe(frame.camera.position, shown)
        for d in dets:
            self.known.setdefault(d.instance_id, d.pose)
        pose = self.body.pose()
        self.trace.append(
            GazeRecord(self.elapsed, pose, purpose, tuple((d.type, d.instance_id) for d in dets))
        )
        rec = self.recorder
        if rec.enabled:
            rec.set_time(self.elapsed)
            rec.log_robot(pose, self.spec)
            rec.log_camera(frame, dets)
            rec.log_scalar(
                f"search/seen_fraction/{self.policy}", self.seen.seen_fraction(self.target_range)
            )
            if self.belief_now is not None:
                belief.log_belief(rec, self.seen.points, self.belief_now(), BELIEF_ENTITY)
        if self._confirming:
            return dets
        if hit is not None and self.found_id is None:
            hit = self._confirmed(hit)
        if hit is not None and self.found_id is None and self.elapsed <= self.episode.budget_s:
            self._found(hit)
        return dets

    def _target_hit(self, dets: Sequence[Detection]) -> Detection | None:
        """The image's first detection of the target (None: none)."""
        return next((d for d in dets if d.type == self.target), None)

    def _found(self, hit: Detection) -> None:
        self.found_id, self.found_at = hit.instance_id, self.elapsed
        self.note(
            f"FOUND {self.target} #{hit.instance_id} ({hit.pixels} px at {hit.distance:.1f} m) "
            f"after {len(self.trace)} gazes"
        )
        if self.recorder.enabled:
            self.recorder.log_volumes(
                "world/search/found",
                [hit.pose.box()],
                [f"{self.target} #{hit.instance_id}"],
                color=(0.1, 0.9, 0.2),
            )

    def _confirmed(self, hit: Detection) -> Detection | None:
        """A second image from the same pose (the detector draws anew): the detection of the
        target in it nearest to ``hit``'s estimated position, within ``CONFIRM_RADIUS_M``; None
        (and ``hit`` forgotten) if there is none."""
        self._confirming = True
        try:
            frame = self.body.capture(rgb=self.recorder.enabled, depth=True)
            dets = self._after_image(frame, "confirm")
        finally:
            self._confirming = False
        again = confirming_detection(hit, dets, self.target)
        if again is None:
            self.unconfirmed += 1
            self.known.pop(hit.instance_id, None)
            if self._held is not None:  # the detector fired there (agent.search.belief)
                near, held = self._held
                self.misses.miss[near] = held * self.curve.unconfirmed_ratio(
                    hit.distance, CONFIRM_RADIUS_M
                )
            x, y = hit.pose.position[:2]
            self.note(f"{self.target} at ({x:.2f}, {y:.2f}) not confirmed by a second image")
        return again

    def capture(self, purpose: str) -> list[Detection]:
        """Take an image where the head points now; detections. Stops when found or out of time."""
        self.check()
        frame = self.body.capture(rgb=self.recorder.enabled, depth=True)
        dets = self._after_image(frame, purpose)
        self.check()
        return dets

    def drive_to(self, xy: np.ndarray, final_yaw: float | None = None) -> bool:
        """Drive along a planned path to ``xy``; False if it cannot be reached."""
        self.check()
        pose = self.body.pose()
        path = plan_path(self.grid, pose.xy, np.asarray(xy, float))
        if path is None:
            return False
        if len(path) >= 2 or final_yaw is not None:
            yaw = final_yaw
            if yaw is None:
                seg = path[-1] - path[-2]
                yaw = math.atan2(seg[1], seg[0]) if np.hypot(*seg) > 1e-9 else pose.yaw
            self.recorder.log_path(path)
            self.body.drive(path, yaw)
        return True

    def look_heading(self, heading: float, tilt: float, purpose: str) -> list[Detection]:
        """Point the camera along world ``heading`` with ``tilt`` (turning the base when the pan
        limit requires it) and take an image."""
        self.check()
        pose = self.body.pose()
        pan = wrap_angle(heading - pose.yaw)
        lo, hi = self.spec.pan_range
        if not lo <= pan <= hi:
            self.body.drive(pose.xy[None, :], heading)
            pan = 0.0
        self.body.move_head(pan, tilt)
        return self.capture(purpose)

    def look_gaze(self, gaze: Gaze, purpose: str) -> list[Detection]:
        """Execute a view planner Gaze (drive, turn, aim) and take an image."""
        self.face(gaze)
        return self.capture(purpose)

    def face(self, gaze: Gaze) -> None:
        """Execute a view planner Gaze's motion (drive, turn, aim) without taking an image."""
        self.check()
        if gaze.path is not None and len(gaze.path) >= 2:
            self.recorder.log_path(gaze.path)
        face_gaze(self.body, self.grid, gaze)
        self.check()

    # ----------------------------------------------------------------- the outcome
    def result(self) -> SearchResult:
        """The episode's outcome so far, as the robot knows it: ``found`` is left False for
        whoever knows the truth to judge (``measures.judge``)."""
        t = self.found_at if self.found_id is not None else self.elapsed
        return SearchResult(
            self.policy,
            self.episode.index,
            self.target,
            False,
            self.found_id,
            float(t),
            len(self.trace),
            float(self.body.metres),
            self.episode.budget_s,
            list(self.trace),
            list(self.log),
            self.intermediate,
            self.predicted_gain,
            self.unconfirmed,
            self.mass_left if self.found_id is None and t < self.episode.budget_s else None,
        )
