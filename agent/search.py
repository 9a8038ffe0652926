"""Object search with learned context (paper, section 3): the policies and one episode's run.

An *episode* (``Episode``) is a room (style and seed), a start pose, a target type and a time
budget in simulated seconds. It ends when the detector (envs.detector, on rendered
segmentation) reports an instance of the target type, or when the budget is spent. Every policy
drives, moves the head and takes images through the same World, so the seconds are the one
TimeModel's (envs.robot_spec) and comparable across policies.

Held-out rooms. Search rooms are never rooms the robot learned in: ``ctxsearch learn`` derives
its room seeds from (seed, index) with ``agent.learning.room_seed``; search episodes use
``held_out_seed(seed, i)``, the same hash of (seed, i) with a distinct tag, and the benchmark
skips any seed the store lists among its learned rooms.

Two map scenarios (``RoomMaps.map``, ``--map``; ``POLICY_MAPS`` says which policy runs in
which, ``check_scenario`` gives the one-line error, ``DEFAULT_POLICIES`` the lists run when none
are named):

- ``built`` (``RoomMaps.built``, the default in houses): the robot knows nothing at the start:
  no furniture, no free cell. Each policy's context builds its own agent.mapping ``BuiltMap``
  from its depth images (the same map and rules as learning's ``--map built``: it plans only
  through cells seen to be floor with nothing within the clearance), objects are known only once
  detected, and the seen map's lattice covers the footprint without knowing the furniture.
  Policies: ``frontier``, ``indirect``, ``oracle-prior-indirect``, ``oracle``.
- ``given`` (``RoomMaps.given``): the furniture poses and the true layout's grid are known.
  Policies: ``map-only``, ``location``, ``oracle-prior``, ``oracle``, and ``exhaustive`` as a
  reference; ``indirect`` runs here too (its plan made once at the start, below).

The oracle plans on the true layout's maps in both (``TRUE_MAP_POLICIES``): it is the bound.

Policies (``POLICIES``; ``make_policy(name)``, one-line error for unknown names), each a small
class with a ``name`` and ``run(ctx) -> SearchResult``:

- ``frontier`` (built): no context. At each step it drives to the viewpoint of the built map
  that shows the largest share of what is left to see for the target per expected second
  (agent.search_explore: information gain by 2-D rays over the mapped obstacles, the unknown
  beyond the frontier counted) and sweeps there (pan/tilt, skipping images predicted to add
  little, plus near-floor images where the floor around is unknown, so the map grows); when no
  viewpoint is left, coverage of what stayed unseen.
- ``map-only`` (given): the value of the map alone: every relation volume of the known
  furniture, no probabilities, in the order of a short tour; then coverage.

- ``exhaustive``: no context. Covers the room for the target's effective detection range:
  viewpoints from a greedy set cover, visited in a short tour, with pan/tilt sweeps that skip
  what the depth images already showed (agent.search_space).
- ``location``: location constraint. Knows the furniture (a map of the room's furniture poses,
  not the small objects) and every object detected so far; candidate regions are their relation
  volumes, ranked by P(T in the unseen part) per expected second (agent.search_space), each
  looked into with the view planner's gazes; falls back to ``exhaustive`` when no candidate
  has probability left.
- ``indirect``: detectability-driven. On the built map it decides online: at each step it takes
  the best expected probability of finding T per second among (a) looking into a relation volume
  of an object detected so far, (b) sweeping for an intermediate type I that Wixson & Ballard's
  efficiency model says pays (agent.search_explore.predicted_plan: gain C_direct / C_via > 1
  from I's detectability, the intervals' q_I and the instances per world), valued as P(a new I
  is seen there) q_I, given up after the model's expected seconds to find one, and (c) the
  frontier step above. All three are valued in one currency: the probability that T is at each
  point of the seen map given that it was not seen yet (``search_space.target_density``: the
  known objects' relation volumes spread their P(rel(T)) over their points, the unexplored rest
  of the house gets the surveyed part's mean density; ``SearchContext._belief``), so the
  frontier step of (c) is drawn towards likely places and no option counts an overlap twice.
  Each option kind's expected seconds are corrected by what its actions took so far in the
  episode. Measured with ``ctxsearch learn --style apartment --rooms 10 --kb K`` and ``ctxsearch
  bench search --kb K --style apartment --map built --episodes 48 --policies frontier,indirect``
  (indirect's median / mean seconds, failures at the budget, and success): 71.6 / 117 / 92%
  before, 57.7 / 100 / 90% with the one currency, 60.6 / 99 / 94% with the calibration too
  (frontier: 91.8 / 131 / 81%).
  Its result records the intermediate type it used (searched for, or whose relation volume it
  looked into first) and the model's predicted gain. On the given map it knows the furniture
  map but plans once: it compares the expected cost of looking for T directly with looking first
  for I (``search_space.indirect_plan`` on the map's coverage costs); if I wins it sweeps for
  I, then applies the location constraint around what it detected, then falls back.
- ``oracle-prior``: ``location`` with the ground-truth probabilities (envs.truth) instead of
  the learned intervals; ``oracle-prior-indirect`` likewise for ``indirect``.
- ``oracle``: knows where the target's instances are and what the detector will report, and goes
  straight to the soonest view that detects one (``oracle_view``): the lower bound on time to
  find (``bench search`` counts the episodes any policy beat it in: ``oracle_violations``).

Which value of the interval ranks candidates is ``rank`` (``low``, ``p0`` or ``high``; default
``low``, the lower bound, chosen by measurement). ``ctxsearch bench search --episodes 80
--policies exhaustive,location@low,location@p0,location@high,indirect@low,indirect@p0,indirect@high``
on three office stores learned by hif (30 rooms, oracle perception: 1105 examinations; 5 rooms
oracle: 194; 6 rooms camera: 227), median / mean simulated seconds to find, low / p0 / high:

- ``location``: 1.6/5.3, 1.6/5.8, 1.7/6.1 (30 rooms); 1.6/5.7, 1.8/6.4, 3.1/7.8 (5 rooms);
  1.4/4.6, 1.7/6.4, 2.9/7.8 (6 camera rooms).
- ``indirect``: 3.0/6.2, 2.9/5.8, 2.9/6.8; 3.0/5.7, 3.1/6.3, 3.1/6.4; 3.0/5.8, 2.5/6.5, 2.2/7.2.
- (``exhaustive``: 5.9/8.1 on the same episodes.)

The lower bound is best or tied for ``location`` everywhere and its margin grows as evidence
thins: an upper bound ranks barely-examined relations (wide intervals) too high. For
``indirect`` the differences are within noise (low has the best or near-best mean); it uses the
same default.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np

from ctxsearch.agent import search_explore as sx
from ctxsearch.agent import search_space as ss
from ctxsearch.agent.frontiers import NEAR_TILT
from ctxsearch.agent.interfaces import Body, WrappedBody
from ctxsearch.agent.mapping import MAP_MODES, BuiltMap
from ctxsearch.agent.navigation import OccupancyGrid, nearest_free, plan_path
from ctxsearch.agent.recording import Recorder
from ctxsearch.agent.viewplan import Gaze, GazePlanOptions, aim, face_gaze, plan_gazes
from ctxsearch.envs.camera import Frame, frustum_mask, half_fov_tangents
from ctxsearch.envs.detector import (
    Detection,
    DetectorModel,
    SimDetector,
    box_distance,
    box_distances,
    load_detector,
    ray_scale,
)
from ctxsearch.envs.floorplan import visible_rooms
from ctxsearch.envs.houses import WorldStyle
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, TimeModel, wrap_angle
from ctxsearch.envs.truth import ground_truth, load_truth
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance, relation_volume
from ctxsearch.knowledge.pooling import PooledCounts
from ctxsearch.knowledge.store import EvidenceStore

DEFAULT_BUDGET_S = 300.0
HELD_OUT_TAG = 0x5EA4C4  # distinguishes search rooms from learning rooms in the seed hash
MIN_REGION_SCORE = 0.01  # regions with less probability left are not worth a look
# A detection of the target is confirmed by a second image from the same pose before the search
# ends (SearchContext._confirmed): a target-type detection in it within this distance (m, on the
# floor plane) of the first one's estimated position. A real robot that stopped at every report
# of its detector would end a fifth of its searches on clutter (measured with the realistic
# preset: 0.05 false detections per image over a few hundred images); a false positive gets a
# new position in every image, a true instance is detected again with its recall.
CONFIRM_RADIUS_M = 0.5
# The best few regions by the cost model are re-costed with their planned gazes before one is
# chosen (the estimate misses detours: furniture in the way, on a built map what is not mapped).
# bench search --style apartment --map given --policies map-only,location --episodes 20 on a
# 10-world camera store: location's median 39.3 s without, 28.1 s with 3, 25.0 s with 6
# (map-only: 52.6 s; paired ratio to map-only 1.09, 1.00, 1.00).
REPLAN_REGIONS = 6
# On the built map (indirect's region option) 3: over the same 20 built-map episodes indirect's
# median was 36.0 s with 3 and 54.3 s with 6 (frontier: 29.1 s; paired 5 wins / 5 losses
# against 3 / 6).
REPLAN_REGIONS_BUILT = 3


# =========================================================================== episodes and results
def held_out_seed(seed: int, index: int) -> int:
    """The room seed of search episode ``index`` for benchmark seed ``seed`` (31-bit, spread out,
    never produced for the same (seed, index) by ``agent.learning.room_seed``)."""
    return int(
        np.random.SeedSequence([int(seed), int(index), HELD_OUT_TAG]).generate_state(1)[0]
        & 0x7FFFFFFF
    )


@dataclass(frozen=True)
class Episode:
    """One search task: the room, where the robot starts, what it looks for, how long it may."""

    index: int
    style: str
    room_seed: int
    target: str
    start: RobotPose
    budget_s: float = DEFAULT_BUDGET_S
    # The oracle's first plan (``oracle_view`` from ``start`` at second 0), as the episode draw
    # computed it to check the episode is feasible: the Oracle policy starts from it instead of
    # planning the same view again. Not part of the episode's identity.
    first_view: OracleView | None = field(default=None, compare=False, repr=False)

    def to_json(self) -> dict:
        """A JSON-serialisable dict."""
        s = self.start
        return {
            "index": self.index,
            "style": self.style,
            "room_seed": self.room_seed,
            "target": self.target,
            "start": [s.x, s.y, s.yaw],
            "budget_s": self.budget_s,
        }


@dataclass(frozen=True)
class GazeRecord:
    """One image of a search: when (seconds since the start, after the image), from where, why,
    and what the detector reported (type, instance id)."""

    t: float
    pose: RobotPose
    purpose: str
    detections: tuple[tuple[str, int], ...]


@dataclass
class SearchResult:
    """How an episode went for one policy. ``sim_time`` is the simulated seconds until the
    target was detected (or until the policy stopped); ``success`` requires the detection within
    the budget."""

    policy: str
    episode: int
    target: str
    found: bool
    found_id: int | None
    sim_time: float
    gazes: int
    path_m: float
    budget_s: float
    trace: list[GazeRecord] = field(default_factory=list)
    log: list[str] = field(default_factory=list)
    # indirect search on the built map: the intermediate type it used first (searched for, or
    # whose relation volume it looked into; None: none), and Wixson & Ballard's predicted gain
    # C_direct / C_via for it (else for the best candidate type)
    intermediate: str | None = None
    predicted_gain: float | None = None
    unconfirmed: int = 0  # detections of the target a second image did not confirm

    @property
    def success(self) -> bool:
        """Found within the budget."""
        return self.found and self.sim_time <= self.budget_s + 1e-9

    @property
    def time_to_find(self) -> float:
        """Seconds to find; a failure counts as the budget."""
        return self.sim_time if self.success else self.budget_s

    def summary(self) -> str:
        """One line for the terminal."""
        what = (
            f"found {self.target} #{self.found_id}"
            if self.success
            else f"did not find {self.target}"
        )
        return (
            f"{self.policy}: {what} in {self.sim_time:.1f} simulated s "
            f"({self.gazes} gazes, {self.path_m:.1f} m driven; budget {self.budget_s:.0f} s)"
        )


def random_start(layout: RoomLayout, grid: OccupancyGrid, rng: np.random.Generator) -> RobotPose:
    """A start pose: a uniformly drawn free cell of the largest free region, random heading."""
    region = grid.largest_region()
    if region is None:
        raise CtxsearchError(f"room {layout.style}/{layout.seed} has no free space for the robot")
    rows, cols = np.nonzero(region)
    k = int(rng.integers(len(rows)))
    xy = grid.to_xy(int(rows[k]), int(cols[k]))
    return RobotPose(float(xy[0]), float(xy[1]), float(rng.uniform(-math.pi, math.pi)))


def small_types_present(layout: RoomLayout, catalog: Catalog) -> list[str]:
    """The small-object (kind=object) types with an instance in the room, in catalog order."""
    present = {o.type for o in layout.objects}
    return [t.name for t in catalog.types if t.name in present and not t.is_furniture]


@dataclass(frozen=True)
class ViaOption:
    """An intermediate type worth searching for (Wixson & Ballard's model says it pays): its
    q = P(T related to one found), expected instances per world, the height it is found up to,
    the seconds to look into its best relation volume, and the model's predicted gain; and the
    model's expected seconds to find one (half a coverage at its range): the online search stops
    looking for it once it has spent that long on it (the model's expectation) without
    finding one: a world that held the expected instances would most likely have shown one."""

    type: str
    q: float
    instances: float
    zmax: float
    look_s: float
    gain: float
    find_s: float = math.inf


# An online search option: (probability per expected second, label, action, kind, expected
# seconds); the kinds ("region", "explore", "via") are calibrated apart (SearchContext.online_search).
_Option = tuple[float, str, Callable[[], None], str, float]
# The online search's calibration of each option kind's expected seconds starts at 1 (estimates
# taken as they are) and holds this many expected seconds of weight: after that much of a kind
# was done, its measured ratio weighs as much as the prior.
CALIBRATION_PRIOR_S = 30.0


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


# =========================================================================== the running episode
class _Stop(Exception):
    """Raised inside a policy when the target is found or the budget is spent."""


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


@dataclass(frozen=True)
class RoomMaps:
    """What the robot is given of a room before it searches it, built once and shared by the
    policies run in it: the occupancy grid, the seen map's lattice (each policy gets a copy),
    the furniture poses the location constraint may assume, the detector preset its images
    are read with (None: perfect), and the scenario (``map``: ``given`` or ``built``; in
    ``built`` each policy's SearchContext builds its own agent.mapping ``BuiltMap`` from its
    depth images, starting from nothing but its pose)."""

    grid: OccupancyGrid
    seen: ss.SeenMap
    furniture: tuple[ObjectInstance, ...] = ()
    detector: DetectorModel | None = None
    map: str = "given"
    # What the efficiency model of indirect search assumes of the world before seeing it: its
    # footprint (m^2) and room count (a house style says how many rooms it has).
    size: sx.WorldSize = sx.WorldSize(0.0, 1)

    @classmethod
    def built(
        cls,
        layout: RoomLayout,
        catalog: Catalog,
        spec: RobotSpec,
        detector: DetectorModel | None = None,
    ) -> RoomMaps:
        """The ``built`` map scenario: the robot knows nothing at the start, no furniture, no
        free cell (``grid`` is all unknown); only the footprint's extent (the map's allocation,
        as in learning's built map) and height bound the seen map's lattice. Objects become
        known when detected; the robot plans on what its depth images mapped."""
        hw, hd = layout.width / 2, layout.depth / 2
        empty = BuiltMap((-hw, -hd, hw, hd), spec, RobotPose(0.0, 0.0, 0.0))
        empty.floor[:] = False
        grid = OccupancyGrid(
            free=np.zeros_like(empty.floor), x0=empty.x0, y0=empty.y0,
            resolution=empty.resolution, clearance=spec.clearance,
        )  # fmt: skip
        size = sx.WorldSize(layout.width * layout.depth, max(1, len(layout.rooms)))
        return cls(grid, ss.SeenMap.for_footprint(layout), (), detector, "built", size)

    @classmethod
    def given(
        cls,
        layout: RoomLayout,
        catalog: Catalog,
        spec: RobotSpec,
        detector: DetectorModel | None = None,
    ) -> RoomMaps:
        """The ``given`` map scenario: the maps of the true layout (walls, furniture poses).
        This, the simulated sensor and the oracle policies are the only places a search reads
        the true layout."""
        furniture = tuple(o for o in layout.objects if catalog.type(o.type).is_furniture)
        grid = OccupancyGrid.from_layout(layout, spec)
        size = sx.WorldSize(layout.width * layout.depth, max(1, len(layout.rooms)))
        return cls(grid, ss.SeenMap.for_room(layout, catalog), furniture, detector, "given", size)


class SearchContext:
    """One policy's run of one episode on a built world: the body (an agent.interfaces ``Body``,
    e.g. an envs.world.World), the map, what has been seen, what is known, the clock, the trace
    and the recording. ``maps`` defaults to ``RoomMaps.given(layout, ...)``; ``truth`` (the true
    layout) is read only by the simulated detector (envs.detector: the maps' preset, None:
    perfect, its stream seeded by the room and the image's simulated second), which reads what
    the body's images show against the layout's poses, and by the oracle policies. The search
    ends when a detection of the target is confirmed by a second image from the same pose (one
    image's seconds more; ``CONFIRM_RADIUS_M``); success needs the confirmed detection to be of a
    true instance of the target: a look-alike or a false positive confirmed as the target ends
    the search as a failure; one not confirmed is forgotten and the search goes on."""

    found_id: int | None  # the instance whose confirmed detection ended the search
    found_at: float | None  # seconds since the start when it was confirmed

    def __init__(
        self,
        episode: Episode,
        layout: RoomLayout,
        catalog: Catalog,
        body: Body,
        *,
        maps: RoomMaps | None = None,
        probs: ss.ProbabilitySource | None = None,
        recorder: Recorder | None = None,
        policy: str = "?",
    ):
        self.episode, self.truth, self.catalog = episode, layout, catalog
        self.spec: RobotSpec = body.spec
        self.time_model: TimeModel = body.time_model
        self.raw_body = body  # the oracle's views render through it without charging time
        self.body = _PathMeter(body)
        self.maps = maps or RoomMaps.given(layout, catalog, self.spec)
        # The built scenario's own map (the layout gives only the footprint's extent).
        self.built: BuiltMap | None = (
            BuiltMap.for_layout(layout, self.spec, episode.start)
            if self.maps.map == "built"
            else None
        )
        self.probs = probs
        self.recorder = recorder or Recorder(None)
        self.policy = policy
        self.width, self.height = int(body.width), int(body.height)
        sim = SimDetector(
            self.maps.detector or load_detector("perfect"), layout, catalog, layout.seed
        )
        # The detector's random stream is indexed by the seconds since the episode started, not
        # the world's clock (which runs on from policy to policy in a shared World): policies
        # compared on an episode draw the same numbers at the same second (paired comparison).
        self.detector: Callable[[Frame | None], list[Detection]] = lambda frame: sim(
            frame, self.elapsed
        )
        self.seen = self.maps.seen.copy()
        self.target = episode.target
        catalog.type(self.target)
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
        self._mean_drive: float | None = None
        self._visited: set[tuple] = set()  # candidate regions already looked into
        self.intermediate: str | None = None  # set by indirect search (SearchResult)
        self.predicted_gain: float | None = None
        self._scorer: sx.ViewpointScorer | None = None
        self._exhausted: dict[float, np.ndarray] = {}
        self._deferred: set[tuple] = set()  # regions no gaze reached yet (built map)
        self._swept: dict[float, list[np.ndarray]] = {}  # where sweeps for each range were made
        self._vias: dict[str, float] = {}  # intermediate types worth it: predicted gain
        self._confirming, self.unconfirmed = False, 0  # confirming a detection; not confirmed

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
            raise _Stop

    def range_of(self, type_name: str) -> float:
        """The effective detection range of a type (cached)."""
        r = self._range_cache.get(type_name)
        if r is None:
            r = ss.effective_range(self.catalog.type(type_name), self.spec, self.width, self.height)
            self._range_cache[type_name] = r
        return r

    def furniture_map(self) -> list[ObjectInstance]:
        """The map the location constraint may assume: the furniture poses of ``maps``."""
        return list(self.maps.furniture)

    def note(self, msg: str) -> None:
        """A line in the result's log and the recording's text log."""
        self.log.append(f"[{self.elapsed:7.1f} s] {msg}")
        self.recorder.set_time(self.elapsed)
        self.recorder.log_text(f"{self.policy}: {msg}")

    # ----------------------------------------------------------------- acting
    def _after_image(self, frame: Frame, purpose: str) -> list[Detection]:
        dets = self.detector(frame)
        if self.built is not None:
            self.built.update(frame)
        if frame.depth is not None:
            self.seen.update(frame.camera, frame.depth)
        else:
            self.seen.mark_frustum(frame.camera, self.target_range)
        for d in dets:
            self.known.setdefault(d.instance_id, d.pose)
        hit = next((d for d in dets if d.type == self.target), None)
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
        if self._confirming:
            return dets
        if hit is not None and self.found_id is None:
            hit = self._confirmed(hit)
        if hit is not None and self.found_id is None and self.elapsed <= self.episode.budget_s:
            self.found_id, self.found_at = hit.instance_id, self.elapsed
            self.note(
                f"FOUND {self.target} #{hit.instance_id} ({hit.pixels} px at {hit.distance:.1f} m) "
                f"after {len(self.trace)} gazes"
            )
            if rec.enabled:
                rec.log_volumes(
                    "world/search/found",
                    [hit.pose.box()],
                    [f"{self.target} #{hit.instance_id}"],
                    color=(0.1, 0.9, 0.2),
                )
        return dets

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

    # ----------------------------------------------------------------- shared behaviours
    def cover(
        self,
        type_name: str | None = None,
        *,
        tilts: Sequence[float] = ss.SWEEP_TILTS,
        until: Callable[[], bool] | None = None,
        rounds: int = 6,
        purpose: str = "sweep",
    ) -> None:
        """Exhaustive coverage for ``type_name`` (default: the target): tour the coverage
        viewpoints and sweep at each (see the module docstring). Returns when ``until()`` turns
        true after an image, or when nothing coverable is left: a round whose sweeps found no
        image worth ``SWEEP_MIN_SHARE`` of what is unseen is followed by one that takes every
        image showing at least a few unseen points."""
        name = type_name or self.target
        rng = self.range_of(name)
        share = ss.SWEEP_MIN_SHARE
        for _ in range(rounds):
            unseen = self.seen.unseen(rng)
            sites = ss.coverage_viewpoints(
                self.grid, self.seen.points[unseen], self.body.pose().xy, rng, self.spec
            )
            if len(sites) == 0:
                return
            self.note(
                f"coverage for {name} (range {rng:.1f} m): {len(sites)} viewpoints, "
                f"{100 * self.seen.seen_fraction(rng):.0f}% seen"
            )
            took = 0
            for xy in sites:
                unseen = self.seen.unseen(rng)
                cam = np.array([xy[0], xy[1], self.spec.camera_height])
                if (np.linalg.norm(self.seen.points[unseen] - cam, axis=1) <= rng).sum() < 8:
                    continue
                if not self.drive_to(xy):
                    continue
                took += self.sweep(rng, tilts=tilts, purpose=purpose, until=until, share=share)
                if until is not None and until():
                    return
            if took == 0:
                if share == 0.0:
                    return
                share = 0.0

    def sweep(
        self,
        rng: float,
        *,
        tilts: Sequence[float] = ss.SWEEP_TILTS,
        purpose: str = "sweep",
        until: Callable[[], bool] | None = None,
        share: float = ss.SWEEP_MIN_SHARE,
    ) -> int:
        """A pan/tilt sweep here, skipping images predicted to add little (and stopping early when
        ``until()`` turns true after an image); images taken."""
        pose = self.body.pose()
        cam = np.array([pose.x, pose.y, self.spec.camera_height])
        unseen = self.seen.unseen(rng)
        plan = ss.sweep_gazes(
            pose.xy,
            pose.yaw + pose.pan,
            self.seen.points,
            unseen,
            self.spec,
            rng,
            ss.SweepOptions(tilts=tuple(tilts), min_share=share),
        )
        near = np.linalg.norm(self.seen.points - cam, axis=1) <= rng
        need = max(8, int(math.ceil(share * np.count_nonzero(unseen & near))))
        n = 0
        for g in plan:
            # Re-check against what the images so far really showed.
            m = frustum_mask(
                cam, g.heading, g.tilt, self.seen.points, self.spec, rng
            ) & self.seen.unseen(rng)
            if m.sum() < need:
                continue
            self.look_heading(g.heading, g.tilt, purpose)
            n += 1
            if until is not None and until():
                break
        return n

    def search_regions(
        self,
        probs: ss.ProbabilitySource,
        *,
        known: Callable[[], Sequence[ObjectInstance]],
        replan: int = 0,
    ) -> None:
        """The location constraint: look into the best candidate region (probability per second)
        until none has probability left (see agent.search_space); with ``replan`` > 0 the best
        ``replan`` regions by the cost model are re-costed with their planned gazes."""
        visited = self._visited
        costs = ss.CostModel(self.grid, self.time_model, view_distance=min(self.target_range, 2.5))
        builder = ss.RegionBuilder(self.catalog, probs, self.seen, self.target)
        round_ = 0
        while True:
            self.check()
            regions = [r for r in builder.regions(known()) if r.key not in visited]
            ranked = ss.score_regions(
                regions, self.seen, self.target_range, costs, self.body.pose().xy
            )
            ranked = [r for r in ranked if r.score >= MIN_REGION_SCORE]
            round_ += 1
            self._log_candidates(ranked)
            if not ranked:
                self.note("no candidate region left")
                return
            best, gazes = self._best_planned(ranked, replan)
            visited.add(best.key)
            self.note(
                f"look into {best.label}: P={best.score:.2f}, ~{best.cost:.1f} s, {len(gazes)} gazes "
                f"({len(ranked)} candidates)"
            )
            for g in gazes:
                self.look_gaze(g, f"region {best.label}")

    def _best_planned(
        self, ranked: Sequence[ss.Region], replan: int
    ) -> tuple[ss.Region, list[Gaze]]:
        """The region to look into and its gazes: ``ranked[0]``, or with ``replan`` > 0 the best
        probability per planned second among the first ``replan``."""
        if replan <= 0:
            return ranked[0], self._region_gazes(ranked[0])
        planned = []
        for r in ranked[:replan]:
            gz = self._region_gazes(r)
            cost = sum(g.cost for g in gz) + self.time_model.image_cost * len(gz)
            planned.append((r.score / max(cost, 1e-6) if gz else -1.0, -cost, r.key, r, gz))
        best = max(planned, key=lambda x: x[:3])
        return best[3], best[4]

    # ----------------------------------------------------------------- the built map
    def todo(self, rng: float, zmax: float | None = None) -> np.ndarray:
        """(N,) bool: seen-map points still to be seen for range ``rng`` (not seen from within
        it, not exhausted), up to height ``zmax`` if given."""
        m = self.seen.unseen(rng)
        ex = self._exhausted.get(rng)
        if ex is not None:
            m &= ~ex
        if zmax is not None:
            m &= self.seen.points[:, 2] <= zmax
        return m

    def scorer(self) -> sx.ViewpointScorer:
        """The built map's viewpoint scorer (made on first use)."""
        if self._scorer is None:
            self._scorer = sx.ViewpointScorer(
                self.built, self.seen.points, self.spec, self.time_model
            )
        return self._scorer

    def viewpoint(
        self,
        rng: float,
        images: float,
        zmax: float | None = None,
        weights: np.ndarray | None = None,
    ) -> sx.Viewpoint | None:
        """Where to sweep next for range ``rng`` on the built map: the best share per second
        (agent.search_explore; ``weights``: of the target's probability over the points, else of
        the points); None on a given map or if none is worth it."""
        if self.built is None:
            return None
        here = self.body.pose().xy
        avoid = np.array(self._swept[rng]) if self._swept.get(rng) else None
        return self.scorer().best(
            self.grid, self.todo(rng, zmax), here, rng, images, avoid, key=(rng, zmax),
            weights=weights,
        )  # fmt: skip

    def explore_step(
        self,
        vp: sx.Viewpoint,
        rng: float,
        tilts: Sequence[float] = ss.SWEEP_TILTS,
        purpose: str = "explore",
        until: Callable[[], bool] | None = None,
    ) -> None:
        """Drive to ``vp`` and sweep there for range ``rng``; what stayed unseen nearby is
        exhausted."""
        self._swept.setdefault(rng, []).append(np.asarray(vp.xy, float))
        if self.drive_to(vp.xy):
            self.sweep(rng, tilts=tilts, purpose=purpose, until=until)
            if until is None or not until():
                self.map_floor()
        self.exhaust(rng, vp.xy)

    def map_floor(self) -> None:
        """On the built map: images at the near-floor tilt where the floor around is still
        unknown (agent.search_explore.floor_headings)."""
        if self.built is None:
            return
        p = self.body.pose()
        for h in sx.floor_headings(self.built, p.xy, p.yaw + p.pan):
            self.look_heading(h, NEAR_TILT, "map the floor")

    def exhaust(self, rng: float, xy: np.ndarray | None = None) -> None:
        """Mark what a sweep at ``xy`` (default: here) left unseen nearby as exhausted for
        ``rng`` (agent.search_explore)."""
        if self.built is None:
            return
        here = self.body.pose().xy if xy is None else np.asarray(xy, float)
        ex = self.scorer().exhaust(here, self.seen.unseen(rng), rng)
        old = self._exhausted.get(rng)
        self._exhausted[rng] = ex if old is None else old | ex
        self._deferred.clear()

    def look_around(self) -> None:
        """A sweep for the target where the robot stands (the first images of a built map)."""
        self._swept.setdefault(self.target_range, []).append(self.body.pose().xy)
        self.sweep(self.target_range, purpose="look around")
        self.map_floor()
        self.exhaust(self.target_range)

    def online_search(self, probs: ss.ProbabilitySource | None, vias: Sequence[ViaOption]) -> None:
        """Search on the built map: at each decision the best expected probability of finding
        the target per second among looking into a known object's relation volume (``probs``),
        sweeping for an intermediate type of ``vias``, and sweeping the best frontier viewpoint
        for the target; returns when none is left.

        The options' seconds come from different estimates (a sweep's drive and images, a
        volume's planned gazes, the efficiency model's look), which err differently: each kind's
        expected seconds are scaled by the ratio of the seconds its actions took so far in this
        episode to the seconds they were expected to take (``CALIBRATION_PRIOR_S`` of prior
        weight at ratio 1). The robot corrects its own estimates; nothing is fitted offline."""
        builder = ss.RegionBuilder(self.catalog, probs, self.seen, self.target) if probs else None
        self._vias = {v.type: v.gain for v in vias}
        self._via_spent: dict[str, float] = {}  # seconds spent looking for each of them
        prior = (ss.expected_mass(self.catalog, probs, self.target) if probs else None) or 1.0
        self.look_around()
        took: dict[str, list[float]] = {}  # kind: [expected, measured] seconds so far
        while True:
            self.check()
            regions, weights, mass = self._belief(builder, prior)
            options = [
                o
                for o in (self._region_option(regions, weights), self._direct_option(weights))
                if o
            ]
            options += [o for o in (self._via_option(v, mass) for v in vias) if o]
            if not options:
                return

            def scale(kind: str) -> float:
                exp_s, got_s = took.get(kind, (0.0, 0.0))
                return (got_s + CALIBRATION_PRIOR_S) / (exp_s + CALIBRATION_PRIOR_S)

            rate, label, act, kind, seconds = max(options, key=lambda o: o[0] / scale(o[3]))
            f = scale(kind)
            self.note(f"{label} ({rate / f:.4f}/s, time x{f:.2f}; {len(options)} options)")
            t0 = self.elapsed
            act()
            sums = took.setdefault(kind, [0.0, 0.0])
            sums[0] += seconds
            sums[1] += self.elapsed - t0

    def _belief(
        self, builder: ss.RegionBuilder | None, prior: float = 1.0
    ) -> tuple[list[ss.Region], np.ndarray | None, float]:
        """Where the target may be (online search): the candidate regions of what is known and
        not looked into yet; the probability that the target is at each seen-map point given
        that it was not seen yet (``search_space.target_density`` normalised over the points
        left to see; None without context or before a known object has a relation volume worth
        anything: every point alike, as ``frontier`` assumes); and the density's total over
        those points (P(rel(T)) units; when None, ``prior``: ``search_space.expected_mass``, the
        total a whole world is expected to hold, or 1), which turns an intermediate type's
        P(rel(T)) into the same share."""
        if builder is None:
            return [], None, 1.0
        every = builder.regions(list(self.known.values()))
        skip = self._visited | self._deferred
        regions = [r for r in every if r.key not in skip]
        dens = ss.target_density(every, ~self.seen.unseen(sx.MAX_VIEW))
        if dens is None:
            return regions, None, prior
        mass = float(dens[self.todo(self.target_range)].sum())
        if mass <= 0.0:
            return regions, None, prior
        return regions, dens / mass, mass

    def _direct_option(self, weights: np.ndarray | None = None) -> _Option | None:
        v = self.viewpoint(self.target_range, sx.SWEEP_IMAGES, weights=weights)
        if v is None:
            return None
        return (v.rate, f"explore for {self.target} at ({v.xy[0]:.1f}, {v.xy[1]:.1f}): "
                f"{v.gain} points, ~{v.seconds:.0f} s",
                lambda: self.explore_step(v, self.target_range), "explore", v.seconds)  # fmt: skip

    def _via_option(self, via: ViaOption, mass: float = 1.0) -> _Option | None:
        found = sum(1 for o in self.known.values() if o.type == via.type)
        left = 1.0 - math.exp(-max(0.0, via.instances - found))
        if left < 0.05 or self._via_spent.get(via.type, 0.0) >= via.find_s:
            return None
        rng = self.range_of(via.type)
        v = self.viewpoint(rng, sx.RING_IMAGES, via.zmax)
        if v is None:
            return None
        m = left * min(1.0, v.share * max(1.0, via.instances - found))
        seconds = v.seconds + m * via.look_s
        rate = m * via.q / mass / seconds

        def act() -> None:
            if self.intermediate is None:
                self.intermediate, self.predicted_gain = via.type, via.gain
            n0, t0 = found, self.elapsed
            try:
                self.explore_step(v, rng, FURNITURE_TILTS, f"find {via.type}", until=lambda: sum(
                    1 for o in self.known.values() if o.type == via.type) > n0)  # fmt: skip
            finally:
                self._via_spent[via.type] = self._via_spent.get(via.type, 0.0) + (self.elapsed - t0)

        return rate, f"look for {via.type} at ({v.xy[0]:.1f}, {v.xy[1]:.1f})", act, "via", v.seconds

    def _region_option(
        self, regions: Sequence[ss.Region], weights: np.ndarray | None = None
    ) -> _Option | None:
        if not regions:
            return None
        costs = ss.CostModel(self.grid, self.time_model, view_distance=min(self.target_range, 2.5))
        ranked = ss.score_regions(
            regions, self.seen, self.target_range, costs, self.body.pose().xy, weights
        )
        ranked = [r for r in ranked if r.score >= MIN_REGION_SCORE]
        if not ranked:
            return None
        self._log_candidates(ranked)
        # The cost model's estimate ranks; the best few are re-costed with their planned gazes
        # (on a built map the drive around what is not mapped yet can be much longer).
        planned = []
        for r in ranked[:REPLAN_REGIONS_BUILT]:
            gz = self._region_gazes(r)
            if not gz:
                self._deferred.add(r.key)
                continue
            cost = sum(g.cost for g in gz) + self.time_model.image_cost * len(gz)
            planned.append((r.score / max(cost, 1e-6), cost, r, gz))
        if not planned:
            return None
        rate, cost, best, gazes = max(planned, key=lambda x: (x[0], -x[1]))
        return rate, f"look into {best.label}: P={best.score:.2f}, ~{cost:.1f} s", (
            lambda: self.look_region(best, gazes)), "region", cost  # fmt: skip

    def _region_gazes(self, region: ss.Region) -> list[Gaze]:
        return plan_gazes(
            self.grid, region.box, self.body.pose(), self.spec, self.time_model,
            GazePlanOptions(max_distance=min(self.target_range, 2.5)), facing=region.facing,
        )  # fmt: skip

    def look_region(self, region: ss.Region, gazes: Sequence[Gaze] | None = None) -> None:
        """Look into a candidate region with the view planner's gazes (``gazes`` if planned
        already; a region no gaze reaches on the map as it stands waits for the next
        exploration step)."""
        gazes = self._region_gazes(region) if gazes is None else gazes
        if not gazes:
            self._deferred.add(region.key)
            return
        self._visited.add(region.key)
        if self.intermediate is None:  # indirect search via a type found before, maybe by chance
            for _rel, ref in region.members:
                ref_type = self.known[ref].type if ref in self.known else None
                if ref_type in self._vias:
                    self.intermediate, self.predicted_gain = ref_type, self._vias[ref_type]
                    break
        for g in gazes:
            self.look_gaze(g, f"region {region.label}")

    def tour_regions(self, objects: Sequence[ObjectInstance]) -> None:
        """``map-only``: look into every relation volume of ``objects`` (no probabilities) in the
        order of a short tour from here, skipping volumes already mostly seen."""
        regions = ss.build_regions(
            objects, self.target, self.catalog, ss.UniformProbabilities(), self.seen
        )
        if not regions:
            return
        grid = self.grid
        here = self.body.pose().xy
        sites = []
        for r in regions:
            p = nearest_free(grid, np.asarray(r.box.center[:2], float))
            sites.append(p if p is not None else np.asarray(r.box.center[:2], float))
        by_site: dict[tuple[float, float], list[ss.Region]] = {}
        for xy, r in zip(sites, regions, strict=True):
            by_site.setdefault((round(float(xy[0]), 6), round(float(xy[1]), 6)), []).append(r)
        order = ss.tour_order(grid, np.array(list(by_site)), here)
        self.note(f"tour of {len(regions)} relation volumes of the map")
        for xy in order:
            for r in by_site[(round(float(xy[0]), 6), round(float(xy[1]), 6))]:
                if self.seen.unseen(self.target_range)[r.points].mean() >= 0.5:
                    self.look_region(r)

    def _log_candidates(
        self, ranked: Sequence[ss.Region], show: int = 12, labelled: int = 3
    ) -> None:
        """The best ``show`` candidate regions; only the best ``labelled`` carry a short label
        (the next one, in red: its region and P; the others: rank and P)."""
        rec = self.recorder
        if not rec.enabled:
            return
        rec.set_time(self.elapsed)
        best = list(ranked[:labelled])
        rec.log_volumes(
            "world/search/candidates",
            [r.box for r in ranked[labelled:show]],
            color=(0.85, 0.7, 0.3),
        )
        rec.log_volumes(
            "world/search/top",
            [r.box for r in best[1:]],
            [f"#{i + 2} P={r.score:.2f}" for i, r in enumerate(best[1:])],
            color=(0.95, 0.75, 0.1),
        )
        rec.log_volumes(
            "world/search/best",
            [r.box for r in best[:1]],
            [f"next: {r.label} P={r.score:.2f}" for r in best[:1]],
            color=(0.95, 0.2, 0.1),
        )

    def result(self) -> SearchResult:
        """The episode's outcome so far."""
        found = self.found_id is not None
        t = self.found_at if found else self.elapsed
        true_ids = {o.id for o in self.truth.objects if o.type == self.target}  # the sensor's truth
        return SearchResult(
            self.policy,
            self.episode.index,
            self.target,
            found and self.found_id in true_ids,
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
        )


# =========================================================================== the policies
class SearchPolicy:
    """A search policy: ``name`` and ``run(ctx) -> SearchResult`` (subclasses write ``search``)."""

    name: ClassVar[str] = "?"
    needs: ClassVar[str] = "none"  # which probabilities: "none", "kb" (learned) or "truth"

    def run(self, ctx: SearchContext) -> SearchResult:
        """Run the episode until found or out of time; the result."""
        ctx.policy = self.name
        ctx.note(f"looking for {ctx.target} (detection range {ctx.target_range:.1f} m)")
        try:
            self.search(ctx)
            ctx.note("nothing left to look at")
        except _Stop:
            pass
        if ctx.found_id is None and ctx.elapsed >= ctx.episode.budget_s:
            ctx.note("time budget spent")
        return ctx.result()

    def search(self, ctx: SearchContext) -> None:  # pragma: no cover - interface
        """The policy's behaviour; raises _Stop (via ctx) when done."""
        raise NotImplementedError


class Exhaustive(SearchPolicy):
    """No context: cover the room with sweeps from a short tour of viewpoints."""

    name = "exhaustive"

    def search(self, ctx: SearchContext) -> None:
        ctx.cover()


class Frontier(SearchPolicy):
    """No context, on the built map: sweep the frontier viewpoint that shows the most of what is
    left to see for the target per expected second, until nothing is left (then coverage)."""

    name = "frontier"

    def search(self, ctx: SearchContext) -> None:
        ctx.online_search(None, [])
        ctx.note("no viewpoint left; coverage of what stayed unseen")
        ctx.cover()


class MapOnly(SearchPolicy):
    """The value of the map alone: the relation volumes of the known furniture in the order of a
    short tour, no probabilities; then coverage."""

    name = "map-only"

    def search(self, ctx: SearchContext) -> None:
        ctx.tour_regions(ctx.furniture_map())
        ctx.note("falling back to exhaustive coverage")
        ctx.cover()


class Location(SearchPolicy):
    """Location constraint around the furniture map and everything detected so far."""

    name = "location"
    needs = "kb"
    replan = REPLAN_REGIONS  # re-cost the best regions with planned gazes (search_regions)

    def search(self, ctx: SearchContext) -> None:
        base = ctx.furniture_map()

        def known() -> list[ObjectInstance]:
            objs = {o.id: o for o in base}
            objs.update(ctx.known)
            return list(objs.values())

        ctx.search_regions(_probs(ctx), known=known, replan=self.replan)
        ctx.note("falling back to exhaustive coverage")
        ctx.cover()


class Indirect(SearchPolicy):
    """Detectability-driven: maybe find an easier intermediate type first, then search around it."""

    name = "indirect"
    needs = "kb"
    min_q = 0.05  # intermediate types less related than this are not considered
    max_vias = 3  # intermediate types compared online on the built map

    def search(self, ctx: SearchContext) -> None:
        if ctx.built is not None:
            self.search_built(ctx)
        else:
            self.search_given(ctx)

    def search_built(self, ctx: SearchContext) -> None:
        """Online on the built map (SearchContext.online_search): known objects' relation
        volumes, the intermediate types Wixson & Ballard's model says pay, and the frontier."""
        probs = _probs(ctx)
        vias = self.worth(ctx, probs)
        ctx.online_search(probs, vias)
        ctx.note("no option left; coverage of what stayed unseen")
        ctx.cover()

    def worth(self, ctx: SearchContext, probs: ss.ProbabilitySource) -> list[ViaOption]:
        """The intermediate types whose predicted gain (agent.search_explore.predicted_plan)
        exceeds 1, best first (at most ``max_vias``); sets the context's predicted gain to the
        best candidate's."""
        cat = ctx.catalog
        cands = [
            t.name
            for t in cat.types
            if t.name != ctx.target
            and ss.relation_probability(cat, probs, t.name, ctx.target) >= self.min_q
            and self._present(ctx, t.name)
        ]
        size = ctx.maps.size
        ranges = {n: ctx.range_of(n) for n in [ctx.target, *cands]}
        plan = sx.predicted_plan(ctx.target, cat, probs, size, ranges, ctx.time_model, cands)
        gains = {o.via: sx.predicted_gain(plan, o.via) or 0.0 for o in plan if o.via}
        ctx.note("predicted gains: " + ", ".join(f"{k} {v:.2f}" for k, v in gains.items()))
        best = max(gains.items(), key=lambda kv: kv[1], default=None)
        ctx.predicted_gain = best[1] if best else None
        out = []
        for o in sorted(
            (o for o in plan if o.via and gains[o.via] > 1.0), key=lambda o: -gains[o.via]
        ):
            typ = cat.type(o.via)
            k = probs.instances(o.via)
            zmax = max(typ.size_max[2], 0.3) if typ.is_furniture else None
            out.append(ViaOption(o.via, o.q, 1.0 if k is None else k, zmax or 9.0, o.look_s,
                                 gains[o.via], o.find_s))  # fmt: skip
        return out[: self.max_vias]

    def search_given(self, ctx: SearchContext) -> None:
        """On the given map: the plan of ``options`` made once at the start (module docstring)."""
        probs = _probs(ctx)
        options = self.options(ctx, probs)
        best = options[0]
        ctx.note(
            "plans: "
            + "; ".join(
                f"{o.via or 'direct'} {o.cost:.0f} s" + (f" (q={o.q:.2f})" if o.via else "")
                for o in options[:5]
            )
        )
        if best.via is None:
            ctx.note(f"look for {ctx.target} directly")
            ctx.cover()
            return
        via = best.via
        ctx.note(f"look first for {via} (q={best.q:.2f}, find ~{best.find_s:.0f} s)")
        furniture = ctx.catalog.type(via).is_furniture
        tilts = FURNITURE_TILTS if furniture else ss.SWEEP_TILTS

        def found_via() -> int:
            return sum(1 for o in ctx.known.values() if o.type == via)

        # Find an instance of ``via`` (stop at the first image showing a new one), search around
        # everything detected so far, and repeat while the sweeps find new instances.
        while True:
            before = found_via()
            ctx.cover(
                via,
                tilts=tilts,
                until=lambda b=before: found_via() > b,
                rounds=1,
                purpose=f"find {via}",
            )
            new = found_via() > before
            ctx.search_regions(probs, known=lambda: list(ctx.known.values()))
            if not new:
                break
        ctx.note("falling back to exhaustive coverage")
        ctx.cover()

    def options(self, ctx: SearchContext, probs: ss.ProbabilitySource) -> list[ss.IndirectOption]:
        """The candidate plans with their expected costs, cheapest first."""
        cat = ctx.catalog
        start = ctx.body.pose().xy
        cands = [
            t.name
            for t in cat.types
            if t.name != ctx.target
            and ss.relation_probability(cat, probs, t.name, ctx.target) >= self.min_q
            and self._present(ctx, t.name)
        ]
        cover_s: dict[str, float] = {}
        cache: dict[tuple, float] = {}
        for name in [ctx.target, *cands]:
            typ = cat.type(name)
            furniture = typ.is_furniture and name != ctx.target
            key = (round(ctx.range_of(name) * 4) / 4, furniture)
            if key not in cache:
                # Furniture is found by one ring of images at its height (as Indirect.search does).
                cache[key] = estimate_cover_seconds(
                    ctx,
                    start,
                    key[0],
                    tilts=FURNITURE_TILTS if furniture else ss.SWEEP_TILTS,
                    zmax=max(typ.size_max[2], 0.3) if furniture else None,
                )
            cover_s[name] = cache[key]
        look_s = {name: self._look_seconds(ctx, probs, name) for name in cands}
        return ss.indirect_plan(ctx.target, cat, probs, cover_s, look_s, cands)

    @staticmethod
    def _present(ctx: SearchContext, type_name: str) -> bool:
        """Only types the knowledge base has evidence about (n > 0) are worth looking for."""
        kb = ctx.probs.kb if ctx.probs is not None else None
        return kb is None or kb.n(type_name) > 0

    @staticmethod
    def _look_seconds(ctx: SearchContext, probs: ss.ProbabilitySource, via: str) -> float:
        """Seconds to look into the most likely relation volume of a found ``via``: the drive
        to within the target's detection range of it (half of the mean driving distance from
        the start to the room's free cells beyond that range: the nearest instance found is
        visited first) with a quarter turn if it drives, and the images that volume needs for an
        instance of mid-range size."""
        tm = ctx.time_model
        if ctx._mean_drive is None:
            d = ctx.grid.distances_from(ctx.episode.start.xy)
            d = d[np.isfinite(d)]
            ctx._mean_drive = (
                float(np.mean(np.maximum(d - ctx.target_range, 0.0))) if len(d) else 0.0
            )
        typ = ctx.catalog.type(via)
        size = tuple((np.asarray(typ.size_min) + np.asarray(typ.size_max)) / 2)
        mid = ObjectInstance(via, -1, (0.0, 0.0, size[2] / 2), 0.0, size)
        best = max(typ.relations, key=lambda r: (probs.p(r.name, ctx.target), r.name))
        costs = ss.CostModel(ctx.grid, tm, view_distance=ctx.target_range)
        images = costs.images(relation_volume(best, mid))
        drive = 0.5 * ctx._mean_drive
        return tm.leg_estimate(drive) + tm.looks_estimate(images, costs.head_s)


class OraclePrior(Location):
    """``location`` with the ground-truth probabilities."""

    name = "oracle-prior"
    needs = "truth"


class OraclePriorIndirect(Indirect):
    """``indirect`` with the ground-truth probabilities."""

    name = "oracle-prior-indirect"
    needs = "truth"


class Oracle(SearchPolicy):
    """Knows where the target's instances are, and what the detector in use will report from any
    pose at any simulated second, and goes straight to the pose that detects one soonest: the
    lower bound (``oracle_view``). There it renders what the camera will show from where the
    drive actually ended (a physical drive ends a little off the planned pose) and takes images
    while the detector's draws there end the search soonest (``OracleEye.first_success``); if
    they do not, it plans again from where it stands, without the views it tried; exhaustive
    coverage when no view is left."""

    name = "oracle"

    def search(self, ctx: SearchContext) -> None:
        eye = OracleEye(ctx.raw_body, ctx.truth, ctx.catalog, ctx.maps.detector, ctx.target)
        grid = OccupancyGrid.from_layout(ctx.truth, ctx.spec)  # the oracle reads the truth
        ic = ctx.time_model.image_cost
        tried: set[tuple] = set()
        view = ctx.episode.first_view if ctx.elapsed == 0.0 and not ctx.trace else None
        while True:
            ctx.check()
            if view is None or tried:
                view = oracle_view(
                    eye,
                    grid,
                    ctx.body.pose(),
                    ctx.elapsed,  # the detector's stream runs on the episode's seconds
                    ctx.time_model,
                    deadline_s=ctx.episode.budget_s - ctx.elapsed,
                    exclude=tried,
                )
            if view is None:
                break
            tried.add(view.key)
            ctx.note(
                f"go and see {ctx.target} #{view.instance_id} (~{view.seconds:.1f} s, "
                f"{view.renders} views checked)"
            )
            ctx.face(view.gaze)
            frame = eye.frame_at(ctx.body.pose())  # the image the camera will take here
            if eye.first_success(frame, ctx.elapsed + ic, ctx.episode.budget_s) is None:
                continue  # the pose reached does not show it soon enough: plan again
            for _ in range(ORACLE_IMAGES):
                ctx.capture(f"oracle {ctx.target} #{view.instance_id}")  # stops when found
        ctx.note("no view left that detects the target; falling back to exhaustive coverage")
        ctx.cover()


# =========================================================================== the oracle's views
# The oracle's candidate views (``oracle_view``) and the episode checks (``OracleEye``):
# - base positions: the pose's own position and every reachable free cell of every
#   ``ORACLE_CELL_STEP``-th row and column (0.1 m on the 5 cm grid, offset one cell: a superset
#   of the lattices the other policies stand on, the coverage viewpoints' 0.5 m and the gaze
#   planner's 0.3 m, both offset by half their step), within the detector's reach of an
#   instance (camera to bounding box: the perfect detector's ``max_range``; a detector that errs:
#   where its range fall-off leaves ``MIN_RECALL``);
# - at each, the views of ``ORACLE_VIEWS``: the head aimed at the instance's centre (turning the
#   base beyond the pan limit), or moved as little as it can from where it is while the centre
#   stays within half or 0.9 of the half field of view (a view that shows the target off-centre
#   can be cheaper: other policies' sweeps take such images), each charged exactly as
#   ``execute_gaze`` will charge it (the planned path, turns, head slew, image: the one
#   TimeModel);
# - in order of a lower bound on those seconds (drive: the straight line or the grid distance
#   around obstacles over sqrt 2; tilt slew; image), each
#   view is charged exactly and, if it would beat the best so far, rendered from that pose
#   (no time charged, the robot put back) and read by the detector in use at the simulated
#   second the image would be taken, and at the seconds of the images after it when the robot
#   stays and takes more (up to ``ORACLE_IMAGES``, a confirming image after each that showed the
#   target: ``OracleEye.first_success``); a position whose aimed image shows the instance too
#   little to be detected even with ``PERSPECTIVE_GAIN`` times its pixels (perfect: below
#   min_pixels or beyond max_range; a detector that errs: recall below ``MIN_RECALL``) is not
#   rendered again.
# The detector's random stream is seeded by the room and the image's second, so that reading is
# what the robot would get there and then: the oracle knows the draws as it knows the layout, and
# takes the soonest (view, second) that detects a true instance reported as the target. With the
# perfect detector (no draws) this is the least time over every pose the other policies can stand
# at (up to the views above); with a detector that errs, a policy reaching a pose later draws
# again, so a luckier draw (or one at a recall below ``MIN_RECALL``) could beat the oracle; the
# images after the first at a view make that rare: ``bench search`` counts such episodes
# (``oracle_violations``: 0 of 1400 in the 200-episode apartment runs of both map scenarios,
# README) and the tests check there are none. The view it executes is checked
# again from the pose the physical drive reached (a tenth of a millimetre and a milliradian off
# can move a far target's recall across its draw). A plan renders at most
# ``ORACLE_MAX_RENDERS`` images.
ORACLE_CELL_STEP = 2
# the views at each base position: the head aimed at the instance (0), or moved as little as it
# can while the instance stays within this fraction of the half field of view of the centre
ORACLE_VIEWS = (0.0, 0.5, 0.9)
RAY_SPACING_PX = 2.0  # the ray test's grid: a ray every this many pixels across the target
RAY_GRID_MAX = 5  # points along each axis of the target's box at most
GRID_PATH_RATIO = math.sqrt(2.0)  # the grid distance over the shortest free path, at most
ORACLE_IMAGES = 8  # images taken one after the other at a view (the detector draws anew each)
MIN_RECALL = 0.02  # a detector that errs: views where the target's recall is below this
PERSPECTIVE_GAIN = 2.5  # an object at the image corner shows up to ~1/cos^3(43 deg) its pixels
ORACLE_MAX_RENDERS = 600  # images rendered per plan: bounds the look for an undetectable target
VISIBLE_MIN_P = MIN_RECALL  # visible at the start: some start view may detect it this likely


@dataclass(frozen=True)
class OracleView:
    """The oracle's choice: the gaze, the seconds it costs from the pose it was planned from, the
    instance it detects, and how many views were rendered to find it."""

    seconds: float
    gaze: Gaze
    instance_id: int
    renders: int
    key: tuple  # (base x, base y, instance id, view): for not trying it twice


class OracleEye:
    """What the head camera would see from a pose, read by the detector in use, without moving
    the robot or charging time: the oracle's knowledge of the sensor, and the episode checks'
    (visible from the start, some pose detects the target). ``body`` renders (an envs World);
    ``detector``: the preset (None: perfect), its stream seeded as the search's."""

    def __init__(
        self,
        body: Body,
        layout: RoomLayout,
        catalog: Catalog,
        detector: DetectorModel | None,
        target: str,
    ):
        self.body, self.catalog, self.target = body, catalog, target
        self.model = detector or load_detector("perfect")
        self.sim = SimDetector(self.model, layout, catalog, layout.seed)
        self.instances = layout.of_type(target)
        self.true_ids = {o.id for o in self.instances}
        self.renders = 0
        self.layout = layout
        self._rooms_seen: dict[tuple[float, float], frozenset[int] | None] = {}

    def rays_meet(self, camera: np.ndarray, o: ObjectInstance) -> bool:
        """False if no ray from ``camera`` (3,) through a grid of points filling ``o``'s
        bounding box meets ``o`` first (``World.ray_instances``): it is hidden from there, or
        shows in fewer pixels than the grid's spacing (``RAY_SPACING_PX``) covers; True
        otherwise, or if the body renders nothing. A test before an image is rendered: the
        oracle's planner renders only the views whose rays meet the target."""
        size = np.asarray(o.size, float)
        dist = max(box_distance(camera, o), 0.05)
        focal = 0.5 * self.body.height / math.tan(math.radians(self.body.spec.fovy_deg) / 2)
        n = np.clip(np.ceil(size * focal / dist / RAY_SPACING_PX), 2, RAY_GRID_MAX).astype(int)
        axes = [(np.arange(k) + 0.5) / k - 0.5 for k in n]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3) * size
        hits = self.body.ray_instances(np.asarray(camera, float), o.box().world_points(grid))
        return hits is None or bool(np.any(hits == o.id))

    def may_see(self, xy: np.ndarray, o: ObjectInstance) -> bool:
        """False if a camera at base position ``xy`` cannot see into ``o``'s room through the
        house's door openings (``visible_rooms``: the culling the head camera's images use, so
        such an image would show ``o`` in no pixel); True otherwise (and in a single room)."""
        room = self.layout.room_of.get(o.id)
        if room is None:
            return True
        key = (float(xy[0]), float(xy[1]))
        if key not in self._rooms_seen:
            self._rooms_seen[key] = visible_rooms(self.layout, *key)
        rooms = self._rooms_seen[key]
        return rooms is None or room in rooms

    @property
    def reach(self) -> float:
        """How far (m, camera to bounding box) the detector can report the target at all."""
        typ = self.catalog.type(self.target)
        r = self.model.recall
        if self.model.perfect or r is None:
            return float(typ.max_range)
        return float(
            (r.range_fraction + r.range_width * math.log(1.0 / MIN_RECALL - 1.0)) * typ.max_range
        )

    def frame_at(self, pose: RobotPose) -> Frame:
        """The image (ids and depth) the head camera takes at ``pose``; nothing charged, the robot
        put back where it was."""
        b = self.body
        t, here = b.sim_time, b.pose()
        b.reset_pose(pose)
        try:
            frame = b.capture(rgb=False, depth=True)
        finally:
            b.sim_time = t
            b.reset_pose(here)
        self.renders += 1
        if frame is None:
            raise CtxsearchError("the oracle's views need a body that renders images")
        return frame

    def ends_search(self, frame: Frame, sim_time: float) -> tuple[bool, bool]:
        """Whether the image ``frame``, read by the detector at simulated second ``sim_time``
        (seconds since the episode started, after the image), ends the search with success: its
        first detection of the target is confirmed by the second image the robot takes from the
        same pose (read at ``sim_time`` plus an image's seconds: ``confirming_detection``) as a
        true instance (``SearchContext._after_image``); and whether it showed the target at all
        (the robot then took that second image)."""
        # The false positives, which cost most to draw, are drawn only where they can decide:
        # they cover no pixel, so they come after every true detection in an image's list.
        first, first_all = self.sim.split(frame, sim_time)
        hit = self._first(first) or self._first(first_all())
        if hit is None:
            return False, False
        second, second_all = self.sim.split(frame, sim_time + self.body.time_model.image_cost)
        if not self._true(confirming_detection(hit, second, self.target)):
            return False, True  # a false positive can confirm only a false positive
        return self._true(confirming_detection(hit, second_all(), self.target)), True

    def first_success(
        self, frame: Frame, sim_time: float, until: float, images: int | None = None
    ) -> float | None:
        """The second of the first of the images the robot takes one after the other from the
        pose of ``frame``, the first at ``sim_time``, that ends the search (``ends_search``; an
        image that showed the target is followed by its confirming image), at most ``images``
        of them (default ``ORACLE_IMAGES``) and none after ``until``; None: none does."""
        ic = self.body.time_model.image_cost
        t = sim_time
        for _ in range(ORACLE_IMAGES if images is None else images):
            if t > until + 1e-9:
                break
            ok, seen = self.ends_search(frame, t)
            if ok:
                return t
            t += 2 * ic if seen else ic
        return None

    def _first(self, dets: Sequence[Detection]) -> Detection | None:
        return next((d for d in dets if d.type == self.target), None)

    def _true(self, d: Detection | None) -> bool:
        return d is not None and d.instance_id in self.true_ids

    def probability(
        self, frame: Frame, gain: float = 1.0, instance: ObjectInstance | None = None
    ) -> float:
        """The largest probability with which the detector reports a true target instance (or
        ``instance``) in ``frame``: its recall for the instance's visible pixels, times ``gain``,
        and distance (perfect: 0 or 1)."""
        ids = np.asarray(frame.instance_ids)
        h, w = ids.shape
        typ = self.catalog.type(self.target)
        scale = ray_scale(w, h, float(frame.camera.fovy_deg))
        best = 0.0
        for o in self.instances if instance is None else [instance]:
            mask = ids == o.id
            px = int(mask.sum())
            if px == 0:
                continue
            if frame.depth is not None:
                dist = float(np.median(np.asarray(frame.depth)[mask] * scale[mask]))
            else:
                dist = box_distance(np.asarray(frame.camera.position, float), o)
            best = max(best, float(self.model.recall_prob(typ, gain * px, dist, w, h)))
        return best

    def worth(self, p: float) -> bool:
        """True if a view whose probability (``probability``) is ``p`` may detect the target."""
        return p >= (1.0 if self.model.perfect else MIN_RECALL)

    def start_visibility(self, start: RobotPose) -> float:
        """The largest probability that some image from ``start`` (turning in place, pan and
        tilt, no driving) reports a true target instance: the head aimed at each instance, its
        pixels times ``PERSPECTIVE_GAIN`` (an image showing it off-centre may show more)."""
        spec = self.body.spec
        best = 0.0
        cam = np.array([start.x, start.y, spec.camera_height])
        for o in self.instances:
            if box_distance(cam, o) > self.reach or not self.may_see(start.xy, o):
                continue  # out of the detector's reach or behind walls: no image needed
            if not self.rays_meet(cam, o):
                continue  # hidden from here
            target = np.asarray(o.position, float)
            yaw = start.yaw
            pan, tilt = aim(start.xy, yaw, spec.camera_height, target, spec)
            d = target[:2] - start.xy
            heading = math.atan2(d[1], d[0])
            if abs(wrap_angle(yaw + pan - heading)) > 1e-3:  # beyond the pan limit: turn
                yaw = heading
                pan, tilt = aim(start.xy, yaw, spec.camera_height, target, spec)
            frame = self.frame_at(RobotPose(start.x, start.y, yaw, pan, tilt))
            best = max(best, self.probability(frame, PERSPECTIVE_GAIN, o))
        return best


def _exact_gaze(
    grid: OccupancyGrid,
    pose: RobotPose,
    xy: np.ndarray,
    target: np.ndarray,
    spec: RobotSpec,
    tm: TimeModel,
    frac: float = 0.0,
) -> Gaze | None:
    """The gaze at base position ``xy`` that shows ``target`` as ``execute_gaze`` runs it from
    ``pose``, its ``cost`` the seconds it charges (None: ``xy`` cannot be reached). ``frac`` 0:
    the head aimed at ``target``; ``frac`` > 0: the head moved as little as it can from where it
    is while ``target`` stays within ``frac`` of the half field of view from the image centre."""
    path = None
    if float(np.hypot(*(np.asarray(xy) - pose.xy))) > 1e-9:
        path = plan_path(grid, pose.xy, np.asarray(xy, float))
        if path is None:
            return None
    yaw, end = pose.yaw, pose.xy
    if path is not None and len(path) >= 2:
        seg = path[-1] - path[-2]
        if np.hypot(*seg) > 1e-9:
            yaw = math.atan2(seg[1], seg[0])
        end = path[-1]
    pan, tilt = aim(end, yaw, spec.camera_height, target, spec)
    d = target[:2] - end
    heading = math.atan2(d[1], d[0])
    if abs(wrap_angle(yaw + pan - heading)) > 1e-3:  # beyond the pan limit: turn the base
        yaw = heading
        pan, tilt = aim(end, yaw, spec.camera_height, target, spec)
    aim_xyz = np.asarray(target, float)
    if frac > 0.0:
        tx, ty = half_fov_tangents(spec.fovy_deg, 320, 240)
        a, b = frac * math.atan(tx), frac * math.atan(ty)
        pan, tilt = spec.clip_head(
            float(np.clip(pose.pan, pan - a, pan + a)),
            float(np.clip(pose.tilt, tilt - b, tilt + b)),
        )
        h, rng = yaw + pan, max(float(np.hypot(*d)), 0.5)  # a point along the camera's axis
        aim_xyz = np.array(
            [
                end[0] + rng * math.cos(h),
                end[1] + rng * math.sin(h),
                spec.camera_height + rng * math.tan(tilt),
            ]
        )
    if path is not None and len(path) >= 2:
        t = tm.drive_time(path, pose.yaw, yaw)
    else:
        t = tm.turn_time(pose.yaw, yaw) if abs(wrap_angle(yaw - pose.yaw)) > 1e-6 else 0.0
    t += tm.head_time(pose.pan, pose.tilt, pan, tilt) + tm.image_cost
    out = RobotPose(float(end[0]), float(end[1]), float(yaw), float(pan), float(tilt))
    return Gaze(out, aim_xyz, cost=float(t), path=path)


def _oracle_candidates(
    eye: OracleEye, grid: OccupancyGrid, pose: RobotPose, tm: TimeModel
) -> tuple[np.ndarray, list[tuple[float, int, int, int]]]:
    """The oracle's base positions (M, 2) (``pose``'s own first) and its candidate views as
    (lower bound on the seconds from ``pose``, position index, instance index, view index),
    sorted: the drive (the straight line, or the grid's distance around obstacles), the tilt
    slew the view needs at least, and the image."""
    spec = eye.body.spec
    rows, cols = grid.lattice_cells(ORACLE_CELL_STEP)
    geo = grid.distances_from(pose.xy)[rows, cols]
    ok = np.isfinite(geo)
    xs, ys = grid.cell_centers()
    pos = np.vstack([pose.xy[None, :], np.column_stack([xs[cols[ok]], ys[rows[ok]]])])
    # the drive's length is at least the straight line, and at least the grid's distance (the
    # planner's graph) over sqrt 2 less the two end cells' offsets: a free path crosses a chain
    # of edge-sharing free cells, whose grid path is at most sqrt 2 as long. Around walls and
    # through doors the second is the tighter: with the straight line alone a house's plan
    # rendered hundreds of views in the rooms behind the wall and hit ORACLE_MAX_RENDERS
    geo = np.concatenate([[0.0], geo[ok] / GRID_PATH_RATIO - 2.0 * grid.resolution])
    reach_m = np.maximum(np.hypot(*(pos - pose.xy).T), geo)
    cams = np.column_stack([pos, np.full(len(pos), spec.camera_height)])
    _, ty = half_fov_tangents(spec.fovy_deg, 320, 240)
    pairs = []
    for j, o in enumerate(eye.instances):
        idx = np.flatnonzero(box_distances(cams, o) <= eye.reach)
        if not len(idx):
            continue
        d = np.asarray(o.position, float) - cams[idx]
        tilt = np.clip(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])), *spec.tilt_range)
        drive = reach_m[idx] / tm.drive_speed
        for v, frac in enumerate(ORACLE_VIEWS):
            slack = frac * math.atan(ty)
            lb = drive + np.maximum(np.abs(tilt - pose.tilt) - slack, 0.0) / tm.tilt_rate
            lb = lb + tm.image_cost
            pairs.extend(
                zip(lb.tolist(), idx.tolist(), [j] * len(idx), [v] * len(idx), strict=True)
            )
    pairs.sort()
    return pos, pairs


def _aimed_view(
    eye: OracleEye,
    grid: OccupancyGrid,
    pose: RobotPose,
    xy: np.ndarray,
    o: ObjectInstance,
    now: float,
    until: float,
    tm: TimeModel,
) -> tuple[Gaze | None, bool, float | None]:
    """The gaze at ``xy`` aimed at ``o`` from ``pose`` (None: unreachable), whether any view
    from there may detect ``o`` (the aimed image's pixels times ``PERSPECTIVE_GAIN``), and the
    second of the first image taken there that ends the search by ``until`` (None: none,
    ``OracleEye.first_success``)."""
    cam = np.array([xy[0], xy[1], eye.body.spec.camera_height])
    if not eye.may_see(xy, o) or not eye.rays_meet(cam, o):
        return None, False, None
    g = _exact_gaze(grid, pose, xy, np.asarray(o.position, float), eye.body.spec, tm)
    if g is None:
        return None, False, None
    frame = eye.frame_at(g.pose)
    if not eye.worth(eye.probability(frame, PERSPECTIVE_GAIN, o)):
        return g, False, None
    return g, True, eye.first_success(frame, now + g.cost, until)


def oracle_view(
    eye: OracleEye,
    grid: OccupancyGrid,
    pose: RobotPose,
    now: float,
    tm: TimeModel,
    *,
    deadline_s: float = math.inf,
    exclude: set[tuple] | frozenset[tuple] = frozenset(),
) -> OracleView | None:
    """The soonest view from ``pose`` (at the body's simulated second ``now``) whose image the
    detector reads as a true target instance, within ``deadline_s`` seconds (see the comment
    above); None if no candidate view does (or ``ORACLE_MAX_RENDERS`` renders found none)."""
    spec = eye.body.spec
    if not eye.instances:
        return None
    renders0 = eye.renders
    pos, pairs = _oracle_candidates(eye, grid, pose, tm)
    best: OracleView | None = None
    # (position, instance) -> the aimed gaze (None: unreachable), whether it may detect (if it
    # shows too little, so do the off-centre views) and the second its images end the search
    aimed: dict[tuple[int, int], tuple[Gaze | None, bool, float | None]] = {}
    for lb, i, j, v in pairs:
        limit = deadline_s if best is None else min(deadline_s, best.seconds - 1e-9)
        if lb > limit + 1e-9:
            break
        o = eye.instances[j]
        key = (round(float(pos[i, 0]), 3), round(float(pos[i, 1]), 3), o.id, v)
        if key in exclude or eye.renders - renders0 >= ORACLE_MAX_RENDERS:
            continue
        target = np.asarray(o.position, float)
        if (i, j) not in aimed:
            aimed[i, j] = _aimed_view(eye, grid, pose, pos[i], o, now, now + limit, tm)
        g0, worth, hit0 = aimed[i, j]
        if not worth:
            continue
        g = g0 if v == 0 else _exact_gaze(grid, pose, pos[i], target, spec, tm, ORACLE_VIEWS[v])
        if g.cost > limit + 1e-9:
            continue
        if v == 0:
            hit = hit0
        else:
            hit = eye.first_success(eye.frame_at(g.pose), now + g.cost, now + limit)
        if hit is not None and hit - now < limit + 1e-9:
            best = OracleView(hit - now, g, o.id, eye.renders - renders0, key)
    return best


def _probs(ctx: SearchContext) -> ss.ProbabilitySource:
    if ctx.probs is None:
        raise CtxsearchError(
            f"policy '{ctx.policy}' needs probabilities (a knowledge base or ground truth)"
        )
    return ctx.probs


def estimate_cover_seconds(
    ctx: SearchContext,
    start_xy: np.ndarray,
    rng: float,
    head_s: float = 0.6,
    tilts: Sequence[float] = ss.SWEEP_TILTS,
    zmax: float | None = None,
) -> float:
    """Seconds a coverage of the room for detection range ``rng`` would take from ``start_xy``
    on ``ctx``'s grid and seen map: the tour plus the sweeps' images (predicted without
    occlusion), sweeping ``tilts`` and counting only lattice points up to ``zmax`` (furniture:
    its height) if given."""
    grid, seen, spec, tm = ctx.grid, ctx.seen, ctx.spec, ctx.time_model
    pts = seen.points if zmax is None else seen.points[seen.points[:, 2] <= zmax]
    unseen = seen.unseen(rng) if zmax is None else seen.unseen(rng)[seen.points[:, 2] <= zmax]
    sites = ss.coverage_viewpoints(grid, pts[unseen], start_xy, rng, spec)
    t = ss.tour_seconds(grid, sites, start_xy, tm)
    todo = unseen.copy()
    heading = 0.0
    for xy in sites:
        g = ss.sweep_gazes(xy, heading, pts, todo, spec, rng, ss.SweepOptions(tilts=tuple(tilts)))
        t += tm.looks_estimate(len(g), head_s)
        cam = np.array([xy[0], xy[1], spec.camera_height])
        for x in g:
            todo &= ~frustum_mask(cam, x.heading, x.tilt, pts, spec, rng)
    return t


FURNITURE_TILTS = (-0.35,)  # one ring of images finds furniture (detected from metres away)


POLICIES: dict[str, type[SearchPolicy]] = {
    cls.name: cls
    for cls in (
        Exhaustive, Location, Indirect, OraclePrior, OraclePriorIndirect, Oracle, Frontier,
        MapOnly,
    )
}  # fmt: skip

# The map scenarios each policy runs in (``--map``), and each scenario's default policies.
POLICY_MAPS: dict[str, tuple[str, ...]] = {
    "exhaustive": ("given",),
    "location": ("given",),
    "map-only": ("given",),
    "oracle-prior": ("given",),
    "frontier": ("built",),
    "indirect": ("built", "given"),
    "oracle-prior-indirect": ("built", "given"),
    "oracle": ("built", "given"),
}
DEFAULT_POLICIES: dict[str, tuple[str, ...]] = {
    "built": ("frontier", "indirect", "oracle-prior-indirect", "oracle"),
    "given": ("map-only", "location", "oracle-prior", "oracle", "exhaustive"),
}
# Policies that plan on the true layout's maps whatever the scenario (the bound knows all).
TRUE_MAP_POLICIES = frozenset({"oracle"})


def check_scenario(names: Sequence[str], map_mode: str) -> None:
    """One-line errors: an unknown map scenario, or a policy (``name`` or ``name@rank``) that
    does not run in ``map_mode``."""
    if map_mode not in MAP_MODES:
        raise CtxsearchError(f"unknown map '{map_mode}' (known: {', '.join(MAP_MODES)})")
    for n in names:
        base = n.partition("@")[0]
        maps = POLICY_MAPS.get(base, ())
        if maps and map_mode not in maps:
            raise CtxsearchError(f"policy '{base}' needs --map {maps[0]}")


def make_policy(name: str) -> SearchPolicy:
    """A policy by name; a one-line error naming the known ones otherwise."""
    cls = POLICIES.get(name)
    if cls is None:
        raise CtxsearchError(f"unknown search policy '{name}' (known: {', '.join(POLICIES)})")
    return cls()


def parse_policies(text: str) -> list[str]:
    """A comma-separated list of policy names (each optionally ``name@rank``), checked."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise CtxsearchError("no search policy given")
    for n in names:
        base, _, rank = n.partition("@")
        make_policy(base)
        if rank and rank not in ss.RANK_MODES:
            raise CtxsearchError(
                f"unknown rank '{rank}' in '{n}' (known: {', '.join(ss.RANK_MODES)})"
            )
    if len(set(names)) != len(names):
        raise CtxsearchError(f"a policy is listed twice in '{text}'")
    return names


def check_target(catalog: Catalog, target: str) -> None:
    """A one-line error unless ``target`` is a small-object type of the catalog."""
    if target not in catalog:
        small = [t.name for t in catalog.types if not t.is_furniture]
        raise CtxsearchError(
            f"unknown target type '{target}' (small-object types: {', '.join(small)})"
        )


def nearest_free_start(grid: OccupancyGrid, pose: RobotPose) -> RobotPose:
    """``pose`` moved to the nearest free cell (a start pose must be drivable)."""
    p = nearest_free(grid, pose.xy)
    if p is None:
        raise CtxsearchError("the room has no free space for the robot")
    return RobotPose(float(p[0]), float(p[1]), pose.yaw, pose.pan, pose.tilt)


# =========================================================================== knowledge and truth
def open_knowledge(path, catalog: Catalog, alpha: float | None = None, interval: str = "wilson"):
    """The knowledge base of the evidence store at ``path`` and the room seeds it learned in
    (its intervals read with ``interval``: wilson or clustered).

    One-line errors (CtxsearchError): no such file, not a store or another catalog's (StoreError
    from the store), a store without examinations."""
    p = Path(path)
    if not p.is_file():
        raise CtxsearchError(
            f"{p}: no such knowledge store (make one with: ctxsearch learn --kb {p} ...)"
        )
    with EvidenceStore.open(p, catalog, alpha=alpha, read_only=True) as store:
        kb = store.knowledge_base(interval=interval)
        learned = _learned_seeds(store)
    if kb.total_examinations == 0:
        raise CtxsearchError(
            f"{p}: the knowledge store is empty (no examinations); run ctxsearch learn first"
        )
    return kb, learned


def open_pooled(path, catalog: Catalog) -> PooledCounts:
    """The evidence of the store at ``path`` pooled over the catalog's hierarchy (for the backoff
    estimate); the store's one-line errors as ``open_knowledge``."""
    with EvidenceStore.open(Path(path), catalog, read_only=True) as store:
        return PooledCounts.from_store(store)


def _learned_seeds(store) -> set[int]:
    """Room seeds the store has evidence from (any run, any style: stricter than needed)."""
    return {int(seed) for _run, _style, seed, _status in store.rooms()}


def truth_probabilities(
    style: WorldStyle | str,
    catalog: Catalog,
    samples: int = 200,
    seed: int = 0,
    path: str | Path | None = None,
) -> ss.TableProbabilities:
    """Ground-truth P(rel(B)) for the oracle-prior policies: read from ``ctxsearch truth``'s JSON
    at ``path`` if given, else estimated over ``samples`` generated rooms of ``style``."""
    if path is not None:
        doc = load_truth(path, catalog, style if isinstance(style, str) else style.name)
        return ss.TableProbabilities.from_truth(doc)
    return ss.TableProbabilities.from_truth(ground_truth(style, samples, seed, catalog))
