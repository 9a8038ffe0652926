"""Running search episodes: one policy on one episode, every policy on every episode, and
``ctxsearch search``'s one episode, with their rerun recordings. Shared by the CLI, the benchmarks
and the demo.

For each episode the world is built once and shared by the policies (the robot put back at the
same start pose for each, with a fresh seen map and nothing known). The runner is where the true
layout meets the behaviour: it builds the simulated sensor from it (``EpisodeSensor``, the
robot's ``Perception`` during a run), builds the oracle with what it reads, and judges each result
(``measures.judge``). A shared recording holds every policy of an episode side by side, each under
its own root entity, on the same simulated seconds.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from ctxsearch.agent.interfaces import Body
from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.agent.perception_modes import DEFAULT_DETECTOR
from ctxsearch.agent.recording import Recorder, open_stream
from ctxsearch.agent.rr_layout import SEARCH_APP, search_blueprint
from ctxsearch.agent.search import measures
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search.context import SearchContext
from ctxsearch.agent.search.draw import DrawSpec, make_episodes
from ctxsearch.agent.search.episode import (
    DEFAULT_BUDGET_S,
    Episode,
    SearchResult,
    check_budget,
    check_target,
    episode_layout,
)
from ctxsearch.agent.search.maps import RoomMaps
from ctxsearch.agent.search.oracle import Oracle, OracleEye
from ctxsearch.agent.search.policies import SearchPolicy, make_policy
from ctxsearch.agent.search.priors import KnowledgeSource, Priors, PriorSettings, make_priors
from ctxsearch.agent.search.registry import PolicyInfo, info, split_name
from ctxsearch.envs.camera import Frame
from ctxsearch.envs.detector import (
    Detection,
    DetectorModel,
    SimDetector,
    default_or_named,
    load_detector,
)
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import HouseStyle, WorldStyle, resolve_style
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.world import World
from ctxsearch.knowledge import geometry
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.options import (
    Estimate,
    IntervalMethod,
    MapMode,
    Rank,
    Targets,
    parse,
)

ProbsFor = Callable[[str, Rank | None], ss.ProbabilitySource | None]


@dataclass(frozen=True)
class SearchConfig:
    """The policies to run and how: the settings ``search``, ``bench search`` and the demo share."""

    style: str
    policies: tuple[str, ...]
    seed: int = 0
    budget_s: float = DEFAULT_BUDGET_S
    rank: Rank = Rank(ss.DEFAULT_RANK)
    truth: Path | None = None  # ground-truth JSON of `ctxsearch truth` for the oracle-prior ones
    truth_samples: int = 200  # rooms sampled for the ground truth when ``truth`` is None
    # flat (the paper's intervals) or backoff (the class's estimate for reference types with
    # fewer than ``min_evidence`` examinations: knowledge.ranking.BackoffProbabilities)
    estimate: Estimate = Estimate(ss.DEFAULT_ESTIMATE)
    min_evidence: int = ss.DEFAULT_MIN_EVIDENCE
    detector: str | None = None  # the detector preset (name or file; None: realistic)
    interval: IntervalMethod = IntervalMethod.WILSON  # how the learned intervals are read
    # The map scenario: built (the default: the robot knows nothing at the start and maps as it
    # searches) or given (the furniture poses are known). The CLI passes given for single-room
    # styles unless --map says otherwise (default_map).
    map: MapMode = MapMode.BUILT
    # type: any instance of the target type ends a search; instance: the world keeps one
    targets: Targets = Targets.TYPE
    # Room context (issue 27): P(SAME-ROOM-AS-F(T)) on the rooms of the robot's map
    # (agent.search.room_prior), learned (the store's) or true (the oracle-prior policies')
    rooms: bool = False

    def __post_init__(self) -> None:
        # the modes parsed once, here (a one-line error for an unknown one)
        object.__setattr__(self, "rank", parse(Rank, self.rank))
        object.__setattr__(self, "estimate", parse(Estimate, self.estimate))
        object.__setattr__(self, "interval", parse(IntervalMethod, self.interval))
        object.__setattr__(self, "map", parse(MapMode, self.map))
        object.__setattr__(self, "targets", parse(Targets, self.targets))

    def detector_model(self, catalog: Catalog) -> DetectorModel:
        """The detector preset, loaded and checked against the catalog (one-line errors)."""
        return default_or_named(self.detector, catalog, DEFAULT_DETECTOR)

    def prior_settings(self) -> PriorSettings:
        """How the priors are read (agent.search.priors)."""
        return PriorSettings(
            self.rank, self.estimate, self.min_evidence, self.interval, self.truth,
            self.truth_samples, self.rooms,
        )  # fmt: skip


def default_map(style: WorldStyle) -> MapMode:
    """The map scenario a style is searched in when ``--map`` is not given: ``built`` in houses,
    ``given`` in single rooms (the small-world reference of the earlier results)."""
    return MapMode.BUILT if isinstance(style, HouseStyle) else MapMode.GIVEN


def load_priors(
    config: SearchConfig,
    style: WorldStyle,
    catalog: Catalog,
    kb: KnowledgeBase | None = None,
    kb_path: Path | str | None = None,
    exclude_seeds: set[int] | frozenset[int] = frozenset(),
    progress: bool = False,
) -> Priors:
    """The priors of ``config``'s policies (agent.search.priors.make_priors): ``kb`` or the store
    at ``kb_path`` (whose learning rooms join ``exclude_seeds``), and the ground truth if an
    oracle-prior policy runs (a progress bar with ``progress``)."""
    source = KnowledgeSource(kb, kb_path, frozenset(exclude_seeds))
    settings = config.prior_settings()
    return make_priors(config.policies, config.map, style, catalog, settings, source, progress)


class EpisodeSensor:
    """The simulated detector as the robot's ``Perception`` during one policy's run: the preset
    of the maps (None: perfect), its random stream indexed by the seconds since the episode
    started (``t0``: the body's clock at the start), not the world's clock, which runs on from
    policy to policy in a shared World: policies compared on an episode draw the same numbers at
    the same second (paired comparison)."""

    name = "camera"
    reads_truth = False

    def __init__(self, body: Body, detector: SimDetector, catalog: Catalog, t0: float):
        self.body, self.detector, self.catalog, self.t0 = body, detector, catalog, float(t0)
        self.last_detections: Sequence[Detection] = ()

    def see(self, frame: Frame | None) -> list[ObjectInstance]:
        """The detector's objects (their estimated poses) in ``frame``."""
        self.last_detections = self.detector(frame, float(self.body.sim_time) - self.t0)
        return [d.pose for d in self.last_detections]

    def related(
        self, obj: ObjectInstance, seen: Sequence[ObjectInstance]
    ) -> list[tuple[str, ObjectInstance]]:
        """RELATED-OBJECTS of ``obj`` among the detected poses ``seen``."""
        return geometry.related(self.catalog, obj, seen)

    def reference(self, obj: ObjectInstance) -> ObjectInstance | None:
        """A search examines nothing: every object may be a reference, ``obj``."""
        return obj

    def close(self) -> None:
        """Nothing to release: the world belongs to the episode."""


@dataclass
class EpisodeRoom:
    """An episode's room, built once and shared by the policies that search it."""

    layout: RoomLayout
    catalog: Catalog
    world: World
    maps: RoomMaps  # the scenario's maps, with the detector preset (None: perfect)
    given: RoomMaps | None = None  # the true layout's maps for the oracle (built scenario)

    def maps_for(self, policy: PolicyInfo) -> RoomMaps:
        """The maps ``policy`` searches on (the oracle plans on the true layout's)."""
        if policy.reads_truth and self.given is not None:
            return self.given
        return self.maps

    def policy(self, name: str, ep: Episode, maps: RoomMaps) -> SearchPolicy:
        """Policy ``name`` (a base name) for episode ``ep``; the oracle gets its view of the
        truth: the world rendered without charging time, the true layout and its grid."""
        if info(name).reads_truth:
            eye = OracleEye(self.world, self.layout, self.catalog, maps.detector, ep.target)
            return Oracle(name, eye, OccupancyGrid.from_layout(self.layout, self.world.spec))
        return make_policy(name, maps.map)

    def sensor(self, maps: RoomMaps) -> EpisodeSensor:
        """The simulated detector of this room with ``maps``' preset, its clock from now."""
        model = maps.detector or load_detector("perfect")
        sim = SimDetector(model, self.layout, self.catalog, self.layout.seed)
        return EpisodeSensor(self.world, sim, self.catalog, self.world.sim_time)

    def prepare(
        self,
        ep: Episode,
        name: str,
        probs: ss.ProbabilitySource | None,
        recorder: Recorder | None = None,
    ) -> tuple[SearchPolicy, SearchContext]:
        """Policy ``name`` (maybe with a rank) and its context for episode ``ep`` in this room,
        sensing through the room's simulated detector."""
        base, _ = split_name(name)
        maps = self.maps_for(info(base))
        policy = self.policy(base, ep, maps)
        ctx = SearchContext(
            ep, self.catalog, self.world, self.sensor(maps), maps, probs=probs,
            recorder=recorder, policy=name,
        )  # fmt: skip
        return policy, ctx

    def judged(self, res: SearchResult) -> SearchResult:
        """``res`` with ``found`` judged against the room's instances of the target."""
        res.found = measures.judge(res.found_id, self.true_ids(res.target))
        return res

    def true_ids(self, target: str) -> set[int]:
        """The instances of ``target`` in the room: what a search must have found."""
        return {o.id for o in self.layout.objects if o.type == target}


def recording_root(policy: str) -> str:
    """The root entity of a policy's search in a shared recording (``location@low`` ->
    ``location_low``)."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", policy)


def _recorder(
    ep: Episode, name: str, layout: RoomLayout, rec_path: Path | None, stream
) -> Recorder:
    """A recording of its own at ``rec_path``, a root in the shared ``stream``, or none."""
    if rec_path is not None:
        return Recorder(
            rec_path,
            SEARCH_APP,
            name=f"search: {ep.style} room {ep.room_seed}, {ep.target}, {name}",
            blueprint=search_blueprint(layout, [("", name)]),
        )
    if stream is not None:
        return Recorder(stream=stream, root=recording_root(name))
    return Recorder(None)


def run_policy(
    ep: Episode,
    name: str,
    room: EpisodeRoom,
    probs: ss.ProbabilitySource | None,
    rec_path: Path | None = None,
    stream=None,
) -> SearchResult:
    """Policy ``name`` searches episode ``ep`` in ``room`` (a rerun recording to ``rec_path``, or
    under the policy's root in the open rerun ``stream``); the result, judged."""
    layout, catalog = room.layout, room.catalog
    with _recorder(ep, name, layout, rec_path, stream) as rec:
        rec.log_room(layout, catalog)
        rec.log_text(f"episode: room {ep.style}/{ep.room_seed}, target {ep.target}, policy {name}")
        policy, ctx = room.prepare(ep, name, probs, rec)
        res = room.judged(policy.run(ctx))
    res.policy = name
    return res


@dataclass(frozen=True)
class RoomRuns:
    """What to run in an episode's room: (policy, probabilities, recording) in order (a policy
    may appear twice with other probabilities), the detector preset (None: perfect), the map
    scenario, and one recording of them all side by side (``shared``)."""

    runs: tuple[tuple[str, ss.ProbabilitySource | None, Path | None], ...]
    detector: DetectorModel | None = None
    map: MapMode = MapMode.GIVEN
    shared: Path | None = None


def search_room(
    ep: Episode,
    style: WorldStyle,
    catalog: Catalog,
    what: RoomRuns,
    progress: Callable[[str], None] | None = None,
) -> list[SearchResult]:
    """Build ``ep``'s room once and run each of ``what.runs`` in it; results in that order."""
    layout = episode_layout(generate_layout(style, ep.room_seed, catalog), ep)
    stream = None
    if what.shared is not None:
        names = [name for name, _, _ in what.runs]
        stream = open_stream(
            what.shared,
            SEARCH_APP,
            name=f"search: {ep.style} room {ep.room_seed}, {ep.target}: {' vs '.join(names)}",
            blueprint=search_blueprint(layout, [(recording_root(n), n) for n in names]),
        )
    try:
        with World(layout, catalog) as world:
            given = RoomMaps.given(layout, catalog, world.spec, what.detector)
            if what.map is MapMode.BUILT:
                built = RoomMaps.built(layout, catalog, world.spec, what.detector)
                room = EpisodeRoom(layout, catalog, world, built, given)
            else:
                room = EpisodeRoom(layout, catalog, world, given)
            out = []
            for name, probs, rec_path in what.runs:
                res = run_policy(ep, name, room, probs, rec_path, stream)
                out.append(res)
                if progress is not None:
                    progress(
                        f"episode {ep.index} ({ep.target}, room {ep.room_seed}): {res.summary()}"
                    )
    finally:
        if stream is not None:
            stream.flush()
            stream.disconnect()
    return out


@dataclass(frozen=True)
class EpisodeSet:
    """Episodes to run every policy on: the style they were drawn in, the policies (by name,
    each maybe with a rank), where each policy's probabilities come from, the detector preset
    (None: perfect) and the map scenario."""

    style: WorldStyle
    policies: tuple[str, ...]
    probs_for: ProbsFor
    detector: DetectorModel | None = None
    map: MapMode = MapMode.GIVEN


def run_episode(
    ep: Episode,
    catalog: Catalog,
    what: EpisodeSet,
    progress: Callable[[str], None] | None = None,
) -> list[SearchResult]:
    """Every policy of ``what`` on episode ``ep`` (one World, shared by the policies), in order."""
    runs = tuple((name, what.probs_for(*split_name(name)), None) for name in what.policies)
    return search_room(ep, what.style, catalog, RoomRuns(runs, what.detector, what.map), progress)


def run_episodes(
    episodes: Sequence[Episode],
    catalog: Catalog,
    what: EpisodeSet,
    progress: Callable[[str], None] | None = None,
) -> dict[str, list[SearchResult]]:
    """Every policy of ``what`` on every episode: results by policy, in episode order."""
    results: dict[str, list[SearchResult]] = {p: [] for p in what.policies}
    for ep in episodes:
        for name, res in zip(what.policies, run_episode(ep, catalog, what, progress), strict=True):
            results[name].append(res)
    return results


@dataclass
class OneSearch:
    """One episode of ``ctxsearch search``: the episode and each policy's result."""

    episode: Episode
    results: list[SearchResult]
    files: list[Path] = field(default_factory=list)


def search_once(
    config: SearchConfig,
    target: str,
    *,
    kb: KnowledgeBase | None = None,
    kb_path: Path | str | None = None,
    records: Sequence[Path | None] | None = None,
    exclude_seeds: set[int] | frozenset[int] = frozenset(),
    catalog: Catalog | None = None,
    record: Path | None = None,
) -> OneSearch:
    """Search for ``target`` in the first held-out room (for ``config.seed``) of ``config.style``
    that holds one, with each of ``config.policies`` in turn from the same start pose
    (``records[i]``: policy i's rerun recording, or None; ``record``: one recording of all of
    them side by side). ``kb`` (a KnowledgeBase) or ``kb_path`` (a store) gives the learned
    probabilities."""
    catalog = catalog or load_catalog()
    style = resolve_style(config.style, catalog)
    check_target(catalog, target, style)  # both before any draw: refused in a second
    check_budget(config.budget_s)
    names = list(config.policies)
    for n in names:
        split_name(n)
    priors = load_priors(config, style, catalog, kb, kb_path, exclude_seeds)
    detector = config.detector_model(catalog)
    spec = DrawSpec.make(
        style, 1, config.seed, catalog, config.budget_s, priors.learned, target, detector
    )
    spec = replace(spec, targets=config.targets)
    ep = make_episodes(spec, catalog)[0]
    records = list(records) if records is not None else [None] * len(names)
    runs = tuple(
        (name, priors.for_name(name), rec) for name, rec in zip(names, records, strict=True)
    )
    out = search_room(ep, style, catalog, RoomRuns(runs, detector, config.map, record))
    files = [Path(p) for p in records if p is not None]
    return OneSearch(ep, out, files + ([Path(record)] if record is not None else []))
