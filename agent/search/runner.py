"""Running search episodes: one policy on one episode, every policy on every episode, and
``ctxsearch search``'s one episode, with their rerun recordings. Shared by the CLI, the benchmarks
and the demo.

A run starts from a ``SearchConfig`` (agent.search.config), made ready once by ``prepare``
(``SearchRun``: the policies resolved, their priors, the detector); each policy's context carries
the configuration to the behaviours.

For each episode the world is built once and shared by the policies (the robot put back at the
same start pose for each, with a fresh seen map and nothing known). The runner is where the true
layout meets the behaviour: it builds the simulated sensor from it (``EpisodeSensor``, the
robot's ``Perception`` during a run), builds the oracle with what it reads, and judges each result
(``measures.judge``). A shared recording holds every policy of an episode side by side, each under
its own root entity, on the same simulated seconds.
"""

from __future__ import annotations

import importlib.metadata
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from ctxsearch.agent.interfaces import Body
from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.agent.recording import Recorder, open_stream
from ctxsearch.agent.rr_layout import SEARCH_APP, search_blueprint
from ctxsearch.agent.search import measures
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search.config import HomeSource, MapConfig, SearchConfig
from ctxsearch.agent.search.context import SearchContext
from ctxsearch.agent.search.draw import DrawSpec, make_episodes
from ctxsearch.agent.search.draw_store import code_digest
from ctxsearch.agent.search.episode import (
    Episode,
    SearchResult,
    check_budget,
    check_target,
    episode_layout,
)
from ctxsearch.agent.search.maps import WorldMaps
from ctxsearch.agent.search.oracle import Oracle, OracleEye
from ctxsearch.agent.search.policies import SearchPolicy, make_policy
from ctxsearch.agent.search.priors import NO_KNOWLEDGE, KnowledgeSource, Priors, make_priors
from ctxsearch.agent.search.registry import PolicySpec, default_policies, resolve
from ctxsearch.agent.search.remembered import log_remembered
from ctxsearch.agent.search.room_prior import HandedRooms
from ctxsearch.agent.search.tour import cached_tour, tour
from ctxsearch.envs.camera import Frame
from ctxsearch.envs.detector import (
    Detection,
    DetectorModel,
    SimDetector,
    load_detector,
)
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import HouseStyle, WorldStyle, resolve_style
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.truth import RoomKindTruth
from ctxsearch.envs.world import World
from ctxsearch.knowledge import geometry
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.home_map import HomeMap
from ctxsearch.knowledge.options import Handed, MapMode
from ctxsearch.knowledge.persistence import Persistence
from ctxsearch.knowledge.store import EvidenceStore


def code_version() -> dict:
    """The code a result was made with: the package's version and the digest of the sources
    an episode runs (agent.search.draw_store.code_digest)."""
    try:
        version = importlib.metadata.version("ctxsearch")
    except importlib.metadata.PackageNotFoundError:  # run from a source tree, not installed
        version = None
    return {"package": version, "sources_sha256": code_digest()}


def default_map(style: WorldStyle) -> MapMode:
    """The map scenario a style is searched in when the configuration names none: ``built`` in
    houses, ``given`` in single rooms (the small-world reference of the earlier results)."""
    return MapMode.BUILT if isinstance(style, HouseStyle) else MapMode.GIVEN


@dataclass(frozen=True)
class SearchRun:
    """A configuration made ready to run (``prepare``): resolved (its map scenario and
    policies named), the style and catalog, the policies' specs, their priors and the detector
    preset. What ``search``, ``bench search`` and the demo share."""

    config: SearchConfig
    style: WorldStyle
    catalog: Catalog
    specs: tuple[PolicySpec, ...]
    priors: Priors
    detector: DetectorModel
    # called at each online decision of every policy (SearchContext.observer): a read-only hook
    # for diagnostics, in this process only (None: nothing)
    observer: Callable | None = None
    # the remembered map from the store (``map.home`` store): room seed -> its latest map's day
    homes: dict[int, int] = field(default_factory=dict)

    def draw_spec(self, episodes: int, target: str | None = None, split: bool = False) -> DrawSpec:
        """The episode draw this run searches: ``episodes`` episodes (``target``: of that type
        only), never in the worlds the knowledge was learned in. On the remembered map each
        episode records whether its target stayed where an instance stood on the map's day;
        ``split``: half of them did, half did not."""
        c = self.config
        homes = tuple(sorted(self.homes))
        day = max(self.homes.values(), default=0) + days_after(c)
        since = day - days_after(c) if c.scenario is MapMode.REMEMBERED else None
        if split and since is None:
            raise CtxsearchError("a draw split by what moved needs --map remembered")
        return DrawSpec.make(
            self.style, episodes, c.seed, self.catalog, c.budget_s, self.priors.learned, target,
            self.detector, targets=c.targets, day=day, homes=homes, since=since, split=split,
        )  # fmt: skip

    def runs(self, records: Sequence[Path | None] | None = None) -> tuple[PolicyRun, ...]:
        """Each policy with its probabilities and persistence (and ``records[i]``: its own
        recording)."""
        recs = list(records) if records is not None else [None] * len(self.specs)
        p = self.priors
        return tuple(
            PolicyRun(s, p.for_policy(s), r, p.persistence_for(s), p.kinds_for(s))
            for s, r in zip(self.specs, recs, strict=True)
        )


def prepare(
    config: SearchConfig,
    catalog: Catalog | None = None,
    source: KnowledgeSource = NO_KNOWLEDGE,
    *,
    target: str | None = None,
    progress: bool = False,
) -> SearchRun:
    """``config`` made ready to run: the style resolved, the map scenario set (the style's
    default when none is named), the policies named (the scenario's defaults when none are) and
    resolved, the priors of the configuration's knowledge or of ``source`` (the ground truth
    with a progress bar if ``progress``), the detector preset loaded. One-line errors, before
    anything heavy, for an unknown style, ``target``, policy or preset and a bad budget."""
    catalog = catalog or load_catalog()
    style = resolve_style(config.style, catalog)
    if target is not None:
        check_target(catalog, target, style)
    check_budget(config.budget_s)
    mode = config.map.scenario or default_map(style)
    config = config.with_scenario(mode)
    if not config.policies:
        config = replace(config, policies=default_policies(mode))
    specs = resolve(config.policies, mode, config.knowledge.room_context)
    detector = config.detector_model(catalog)
    config, homes = _homes(config, style, catalog)
    priors = make_priors(specs, style, catalog, config.knowledge, source, progress)
    return SearchRun(config, style, catalog, specs, priors, detector, homes=homes)


def days_after(config: SearchConfig | MapConfig) -> int:
    """``map.days_after`` as a run reads it: 1 on the remembered map, 0 otherwise, unless set."""
    m = config.map if isinstance(config, SearchConfig) else config
    if m.days_after is not None:
        return m.days_after
    return 1 if m.scenario is MapMode.REMEMBERED else 0


def _homes(
    config: SearchConfig, style: WorldStyle, catalog: Catalog
) -> tuple[SearchConfig, dict[int, int]]:
    """On the remembered map: the configuration with ``map.home`` resolved (none: ``store`` if
    the knowledge store holds maps of the style, else ``tour``) and, from the store, each
    house's room seed and the day of its latest map; one-line errors for ``store`` without
    such maps."""
    if config.scenario is not MapMode.REMEMBERED:
        return config, {}
    kb, asked = config.knowledge.kb, config.map.home
    homes: dict[int, int] = {}
    if kb is not None and asked is not HomeSource.TOUR and Path(kb).exists():
        with EvidenceStore.open(Path(kb), catalog, read_only=True) as store:
            for _run, st, seed, day in store.home_maps():
                if st == style.name:
                    homes[seed] = max(day, homes.get(seed, day))
    if asked is HomeSource.STORE and not homes:
        raise CtxsearchError(
            f"{kb or 'no knowledge store'}: no remembered map of style '{style.name}' (learn on "
            f"the built map first: ctxsearch learn --style {style.name} --kb FILE; or "
            "--set map.home=tour)"
        )
    source = HomeSource.STORE if homes else HomeSource.TOUR
    return config.updated({"map.home": source}), homes


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


@dataclass(frozen=True)
class PolicyRun:
    """One policy to run in an episode's world: its spec, the probabilities it ranks by (None:
    none), its own rerun recording (None: none) and the persistence it weighs the remembered
    sightings by (None: it has no memory)."""

    spec: PolicySpec
    probs: ss.ProbabilitySource | None = None
    record: Path | None = None
    persistence: Persistence | None = None  # of its remembered sightings (None: no memory)
    # the true target density by room kind, for a bound handed the rooms (None: not handed them)
    kinds: RoomKindTruth | None = None


@dataclass
class EpisodeWorld:
    """An episode's world, built once and shared by the policies that search it, with the
    configuration they run under."""

    layout: RoomLayout
    catalog: Catalog
    world: World
    maps: WorldMaps  # the scenario's maps, with the detector preset (None: perfect)
    config: SearchConfig
    given: WorldMaps | None = None  # the true layout's maps for the oracle (built scenario)
    observer: Callable | None = None  # SearchContext.observer

    def maps_for(
        self, spec: PolicySpec, target: str, kinds: RoomKindTruth | None = None
    ) -> WorldMaps:
        """The maps policy ``spec`` searches on for ``target``: the oracle plans on the true
        layout's; a bound on the built map (the registry's ``handed``) gets the scenario's maps
        with what it is handed of the true house: the furniture plan (the given map's furniture
        poses and lattice: which points are solid and which surfaces things stand on), or its
        room knowledge (agent.search.room_prior.HandedRooms: with every room's kind the true
        density ratio of ``target`` by kind from ``kinds``, with the target's rooms 1 there; in a
        single room that knowledge is nothing)."""
        if spec.info.reads_truth and self.given is not None:
            return self.given
        handed = spec.info.handed
        if handed is Handed.NOTHING:
            return self.maps
        if self.given is None:
            raise CtxsearchError(f"policy '{spec.base}' runs on the built map only")
        if handed is not Handed.PLAN and not self.layout.is_house:
            return self.maps  # one room: knowing it tells nothing
        if handed is Handed.PLAN:
            # the given map's furniture and its lattice (no point inside furniture, where
            # things can stand from the plan's surfaces); the robot maps the free space itself
            return replace(self.maps, furniture=self.given.furniture, seen=self.given.seen)
        if handed is Handed.ROOMS:
            if kinds is None:
                raise CtxsearchError(f"policy '{spec.base}' needs the true density by room kind")
            ratio = {r.index: kinds.ratio(r.style, target) for r in self.layout.rooms}
            factors = {i: (1.0 if v is None else v) for i, v in ratio.items()}
        else:
            factors = {self.layout.room_of[o.id]: 1.0 for o in self.layout.objects
                       if o.type == target and o.id in self.layout.room_of}  # fmt: skip
        return replace(self.maps, handed=HandedRooms(self.given.plan_rooms, factors))

    def policy(self, spec: PolicySpec, ep: Episode, maps: WorldMaps) -> SearchPolicy:
        """Policy ``spec`` for episode ``ep``; the oracle gets its view of the truth: the world
        rendered without charging time, the true layout and its grid."""
        if spec.info.reads_truth:
            eye = OracleEye(self.world, self.layout, self.catalog, maps.detector, ep.target)
            return Oracle(spec.name, eye, OccupancyGrid.from_layout(self.layout, self.world.spec))
        return make_policy(spec)

    def sensor(self, maps: WorldMaps) -> EpisodeSensor:
        """The simulated detector of this world with ``maps``' preset, its clock from now."""
        model = maps.detector or load_detector("perfect")
        sim = SimDetector(model, self.layout, self.catalog, self.layout.seed)
        return EpisodeSensor(self.world, sim, self.catalog, self.world.sim_time)

    def prepare(
        self, ep: Episode, run: PolicyRun, recorder: Recorder | None = None
    ) -> tuple[SearchPolicy, SearchContext]:
        """The policy of ``run`` and its context for episode ``ep`` in this world, sensing
        through the world's simulated detector."""
        maps = self.maps_for(run.spec, ep.target, run.kinds)
        policy = self.policy(run.spec, ep, maps)
        ctx = SearchContext(
            ep, self.catalog, self.world, self.sensor(maps), maps, probs=run.probs,
            recorder=recorder, config=self.config,
        )  # fmt: skip
        ctx.observer = self.observer
        ctx.persistence = run.persistence
        return policy, ctx

    def judged(self, res: SearchResult) -> SearchResult:
        """``res`` with ``found`` judged against the world's instances of the target."""
        res.found = measures.judge(res.found_id, self.true_ids(res.target))
        return res

    def true_ids(self, target: str) -> set[int]:
        """The instances of ``target`` in the world: what a search must have found."""
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


def run_policy(ep: Episode, run: PolicyRun, world: EpisodeWorld, stream=None) -> SearchResult:
    """The policy of ``run`` searches episode ``ep`` in ``world`` (a rerun recording to
    ``run.record``, or under the policy's root in the open rerun ``stream``); the result,
    judged."""
    layout, catalog, name = world.layout, world.catalog, run.spec.name
    with _recorder(ep, name, layout, run.record, stream) as rec:
        rec.log_room(layout, catalog)
        rec.log_text(f"episode: room {ep.style}/{ep.room_seed}, target {ep.target}, policy {name}")
        policy, ctx = world.prepare(ep, run, rec)
        if ctx.maps.home is not None:
            log_remembered(rec, ctx.maps.home)
        return world.judged(policy.run(ctx))


@dataclass(frozen=True)
class WorldRuns:
    """What to run in an episode's world: the policies in order (one may appear twice with
    other probabilities), the configuration they run under (its map scenario and the
    behaviours' settings), the detector preset (None: perfect), and one recording of them all
    side by side (``shared``)."""

    runs: tuple[PolicyRun, ...]
    config: SearchConfig
    detector: DetectorModel | None = None
    shared: Path | None = None
    observer: Callable | None = None  # SearchContext.observer


def search_world(
    ep: Episode,
    style: WorldStyle,
    catalog: Catalog,
    what: WorldRuns,
    progress: Callable[[str], None] | None = None,
) -> list[SearchResult]:
    """Build ``ep``'s world once and run each of ``what.runs`` in it; results in that order."""
    layout = episode_layout(generate_layout(style, ep.room_seed, catalog, day=ep.day), ep)
    stream = None
    if what.shared is not None:
        names = [r.spec.name for r in what.runs]
        stream = open_stream(
            what.shared,
            SEARCH_APP,
            name=f"search: {ep.style} room {ep.room_seed}, {ep.target}: {' vs '.join(names)}",
            blueprint=search_blueprint(layout, [(recording_root(n), n) for n in names]),
        )
    try:
        with World(layout, catalog) as world:
            here = _episode_world(ep, style, layout, world, what)
            out = []
            for run in what.runs:
                res = run_policy(ep, run, here, stream)
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


def _episode_world(
    ep: Episode, style: WorldStyle, layout: RoomLayout, world: World, what: WorldRuns
) -> EpisodeWorld:
    """The episode's world with the scenario's maps (the true layout's for the oracle)."""
    catalog, m, scenario = world.catalog, what.config.map, what.config.scenario
    given = WorldMaps.given(layout, catalog, world.spec, what.detector, m)
    if scenario is MapMode.GIVEN:
        return EpisodeWorld(layout, catalog, world, given, what.config, None, what.observer)
    if scenario is MapMode.BUILT:
        maps = WorldMaps.built(layout, catalog, world.spec, what.detector, m)
    elif m.home is HomeSource.STORE:
        home = stored_home(ep, style, catalog, what.config)
        maps = WorldMaps.remembered(home, layout, world.spec, what.detector, m)
    else:
        home = remembered_home(ep, style, catalog, what.detector, m)
        maps = WorldMaps.remembered(home, layout, world.spec, what.detector, m)
    return EpisodeWorld(layout, catalog, world, maps, what.config, given, what.observer)


def remembered_home(
    ep: Episode, style: WorldStyle, catalog: Catalog, detector: DetectorModel | None, m: MapConfig
) -> HomeMap:
    """The map the robot made of episode ``ep``'s house on the day of its tour
    (``ep.day - map.days_after``; agent.search.tour), from the cache or toured now."""
    day = ep.day - days_after(m)
    if day < 0:
        raise CtxsearchError(f"episode {ep.index} is on day {ep.day}: no day to tour before it")
    layout = generate_layout(style, ep.room_seed, catalog, day=day)
    return toured(layout, catalog, detector, m, day)[0]


def toured(
    layout: RoomLayout,
    catalog: Catalog,
    detector: DetectorModel | None,
    m: MapConfig,
    day: int,
    cached: bool = True,
) -> tuple[HomeMap, float]:
    """The robot's tour of ``layout`` (the world on ``day``) in a world of its own, sensing
    with ``detector`` (None: perfect): the map it leaves and the simulated seconds it took
    (agent.search.tour; ``cached``: read from and kept in the cache, the seconds then 0 for a
    map read back)."""
    with World(layout, catalog) as world:
        model = detector or load_detector("perfect")
        sensor = EpisodeSensor(
            world, SimDetector(model, layout, catalog, layout.seed), catalog, world.sim_time
        )
        t0 = world.sim_time
        run = cached_tour if cached else tour
        home = run(layout, catalog, detector, m, day, body=world, sensor=sensor)
        return home, float(world.sim_time - t0)


def stored_home(ep: Episode, style: WorldStyle, catalog: Catalog, config: SearchConfig) -> HomeMap:
    """The remembered map of episode ``ep``'s house in the knowledge store, of the latest day at
    least ``map.days_after`` before the episode's."""
    kb = config.knowledge.kb
    day = ep.day - days_after(config)
    home = None
    if kb is not None:
        with EvidenceStore.open(Path(kb), catalog, read_only=True) as store:
            home = store.home_map(style.name, ep.room_seed, upto_day=day)
    if home is None:
        raise CtxsearchError(f"{kb}: no remembered map of {style.name}/{ep.room_seed} by day {day}")
    return home


def run_episode(
    ep: Episode, run: SearchRun, progress: Callable[[str], None] | None = None
) -> list[SearchResult]:
    """Every policy of ``run`` on episode ``ep`` (one World, shared by the policies), in order."""
    what = WorldRuns(run.runs(), run.config, run.detector, observer=run.observer)
    return search_world(ep, run.style, run.catalog, what, progress)


def run_episodes(
    episodes: Sequence[Episode], run: SearchRun, progress: Callable[[str], None] | None = None
) -> dict[str, list[SearchResult]]:
    """Every policy of ``run`` on every episode: results by policy name, in episode order."""
    results: dict[str, list[SearchResult]] = {s.name: [] for s in run.specs}
    for ep in episodes:
        for s, res in zip(run.specs, run_episode(ep, run, progress), strict=True):
            results[s.name].append(res)
    return results


@dataclass
class OneSearch:
    """One episode of ``ctxsearch search``: the episode and each policy's result."""

    episode: Episode
    results: list[SearchResult]
    files: list[Path] = field(default_factory=list)
    config: SearchConfig | None = None  # as resolved


def search_once(
    config: SearchConfig,
    target: str,
    *,
    source: KnowledgeSource = NO_KNOWLEDGE,
    records: Sequence[Path | None] | None = None,
    catalog: Catalog | None = None,
    record: Path | None = None,
) -> OneSearch:
    """Search for ``target`` in the first held-out world (for ``config.seed``) of
    ``config.style`` that holds one, with each of ``config``'s policies in turn from the same
    start pose (``records[i]``: policy i's rerun recording, or None; ``record``: one recording
    of all of them side by side). The knowledge is ``config.knowledge``'s store, or
    ``source``'s in memory."""
    run = prepare(config, catalog, source, target=target)
    ep = make_episodes(run.draw_spec(1, target), run.catalog)[0]
    what = WorldRuns(run.runs(records), run.config, run.detector, record)
    out = search_world(ep, run.style, run.catalog, what)
    files = [Path(p) for p in records or () if p is not None]
    return OneSearch(ep, out, files + ([Path(record)] if record is not None else []), run.config)
