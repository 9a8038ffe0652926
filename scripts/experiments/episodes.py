"""Search episodes, shared by ``ctxsearch search``, ``ctxsearch bench search`` and the demo.

``make_episodes`` draws paired episodes (``draw_episodes``, which also counts what it left out):
held-out rooms (``search.held_out_seed(seed, i)``, skipping any seed the knowledge store learned
in and rooms without a small object), a target type drawn uniformly among the small (kind=object)
types present in the room, or a given target, and a start pose (a uniformly drawn free cell,
random heading) from which the target is not visible, redrawn while it is, in a world where the
oracle's planner detects the target within the budget (both checked with the detector in use). ``run_episodes`` runs every policy
on every episode (the room built once per episode, the robot put back at the same start pose for
each policy, with a fresh seen map and nothing known); ``search_once`` runs policies on the first
held-out room that holds a given target, with a recording per policy or all of them side by side
in one recording (each under its own root entity, on the same simulated seconds).

A policy name may carry a rank, ``location@low``, ``location@p0``, ``location@high``: which part
of the interval ranks the candidate regions.
"""

from __future__ import annotations

import contextlib
import functools
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from ctxsearch.agent import search as S
from ctxsearch.agent import search_space as ss
from ctxsearch.agent.episode_draw import draw_world
from ctxsearch.agent.perception_modes import DEFAULT_DETECTOR
from ctxsearch.agent.recording import Recorder, open_stream
from ctxsearch.agent.rr_layout import SEARCH_APP, search_blueprint
from ctxsearch.envs.detector import DetectorModel, default_or_named
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import HouseStyle, WorldStyle, resolve_style
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.world import World
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.pooling import PooledCounts
from ctxsearch.scripts.experiments import draw_store
from ctxsearch.scripts.sweep import SweepOptions, run_units

ProbsFor = Callable[[str, str | None], ss.ProbabilitySource | None]


@dataclass(frozen=True)
class SearchConfig:
    """The policies to run and how: the settings ``search``, ``bench search`` and the demo share."""

    style: str
    policies: tuple[str, ...]
    seed: int = 0
    budget_s: float = S.DEFAULT_BUDGET_S
    rank: str = ss.DEFAULT_RANK
    truth: Path | None = (
        None  # ground-truth JSON of `ctxsearch truth` for the oracle-prior policies
    )
    truth_samples: int = 200  # rooms sampled for the ground truth when ``truth`` is None
    # "flat" (the paper's intervals) or "backoff" (the class's estimate for reference types with
    # fewer than ``min_evidence`` examinations: knowledge.ranking.BackoffProbabilities)
    estimate: str = ss.DEFAULT_ESTIMATE
    min_evidence: int = ss.DEFAULT_MIN_EVIDENCE
    detector: str | None = None  # the detector preset (name or file; None: realistic)
    interval: str = "wilson"  # how the learned intervals are read: wilson or clustered
    # The map scenario (agent.mapping.MAP_MODES): "built" (the default: the robot knows nothing
    # at the start and maps as it searches) or "given" (the furniture poses are known). The CLI
    # passes "given" for single-room styles unless --map says otherwise (default_map).
    map: str = "built"

    def detector_model(self, catalog: Catalog) -> DetectorModel:
        """The detector preset, loaded and checked against the catalog (one-line errors)."""
        return default_or_named(self.detector, catalog, DEFAULT_DETECTOR)


def default_map(style: WorldStyle) -> str:
    """The map scenario a style is searched in when ``--map`` is not given: ``built`` in houses,
    ``given`` in single rooms (the small-world reference of the earlier results)."""
    return "built" if isinstance(style, HouseStyle) else "given"


def split_name(name: str) -> tuple[str, str | None]:
    """``location@low`` -> ("location", "low"); ``location`` -> ("location", None)."""
    base, _, rank = name.partition("@")
    if rank and rank not in ss.RANK_MODES:
        raise CtxsearchError(
            f"unknown rank '{rank}' in '{name}' (known: {', '.join(ss.RANK_MODES)})"
        )
    S.make_policy(base)
    return base, rank or None


@dataclass
class EpisodeDraw:
    """The episodes drawn and what was left out: worlds dropped because the target was visible
    from every start tried (``visible_at_start``) or no pose detects it within the budget
    (``infeasible``), and starts redrawn because the target was visible from them."""

    episodes: list[S.Episode]
    visible_at_start: int = 0
    infeasible: int = 0
    start_redraws: int = 0

    def excluded(self) -> dict[str, int]:
        """search.json's ``excluded``: worlds dropped, by reason."""
        return {"visible_at_start": self.visible_at_start, "infeasible": self.infeasible}


def make_episodes(
    style: WorldStyle,
    n: int,
    seed: int,
    catalog: Catalog,
    budget_s: float = S.DEFAULT_BUDGET_S,
    exclude_seeds: set[int] | frozenset[int] = frozenset(),
    target: str | None = None,
    detector: DetectorModel | None = None,
) -> list[S.Episode]:
    """``n`` episodes in held-out rooms of ``style``, deterministic in ``seed``: the target not
    visible from the start, and detectable within the budget (``draw_episodes``; ``detector``:
    the preset the checks read images with, None: perfect).

    ``target``: only rooms holding that type, always looking for it (``ctxsearch search``);
    otherwise the target is drawn among the room's small types."""
    return draw_episodes(
        style, n, seed, catalog, budget_s, exclude_seeds, target, detector
    ).episodes


def draw_episodes(
    style: WorldStyle,
    n: int,
    seed: int,
    catalog: Catalog,
    budget_s: float = S.DEFAULT_BUDGET_S,
    exclude_seeds: set[int] | frozenset[int] = frozenset(),
    target: str | None = None,
    detector: DetectorModel | None = None,
    sweep: SweepOptions | None = None,
    cache: Path | None = None,
) -> EpisodeDraw:
    """``make_episodes`` with the counts of what was left out; ``sweep``: check the worlds in
    parallel (the same episodes and counts for any number of workers); ``cache``: a directory
    where the draw is kept and read back by later commands with the same arguments and code
    (scripts.experiments.draw_store).

    World i (room seed ``held_out_seed(seed, i)``, skipped if the store learned in it or it has
    no small object, or no ``target``) gets a target drawn uniformly among its small types and a
    start drawn uniformly among the free cells (``random_start``), both from the world's own
    stream. The start is redrawn while the target is visible from it (``S.OracleEye``: the head
    aimed at each instance from the start, turning in place, and the detector in use would report
    a true instance with probability >= ``S.VISIBLE_MIN_P``; the perfect detector: it does), at
    most ``MAX_START_TRIES`` starts, then the world is dropped. A world whose target no view of
    the oracle's planner detects within the budget (``S.oracle_view`` from the start, the
    detector's draws as at the world's first second) is dropped as infeasible. Worlds are taken
    in index order until ``n`` episodes; the counts cover the worlds up to the last one taken.
    Inside ``remembered_draws`` a draw with the same arguments is not made again."""
    key = (style, int(n), int(seed), catalog.fingerprint, float(budget_s),
           tuple(sorted(exclude_seeds)), target, detector)  # fmt: skip
    if _drawn is not None and key in _drawn:
        return replace(_drawn[key], episodes=list(_drawn[key].episodes))
    stored = draw_store.draw_key(key) if cache is not None else None
    draw = draw_store.load(cache, stored, EpisodeDraw) if stored is not None else None
    if draw is None:
        draw = _draw_worlds(key, catalog, sweep or SweepOptions())
        if stored is not None:
            draw_store.save(cache, stored, draw)
    if _drawn is not None:
        _drawn[key] = replace(draw, episodes=list(draw.episodes))
    return draw


def _draw_worlds(key: tuple, catalog: Catalog, sweep: SweepOptions) -> EpisodeDraw:
    """``draw_episodes``' worlds checked in rounds (``key``: its arguments, in its order)."""
    style, n, seed, _fingerprint, budget_s, exclude_seeds, target, detector = key
    draw = EpisodeDraw([])
    limit = 50 * n + 100
    check = functools.partial(
        draw_world, style, seed, catalog, budget_s, frozenset(exclude_seeds), target, detector
    )
    i = 0
    while len(draw.episodes) < n:
        if i >= limit:
            what = f"a {target}" if target else "a small object"
            raise CtxsearchError(
                f"no held-out room of style '{style.name}' holds {what} that can be searched "
                f"for (tried {limit} rooms)"
            )
        # A round: as many worlds as episodes still needed (at least two per worker).
        m = min(limit - i, max(n - len(draw.episodes), 2 * sweep.workers))
        rounds = run_units(
            check,
            list(range(i, i + m)),
            workers=sweep.workers,
            ray_address=sweep.ray_address,
            desc=f"episodes {style.name}",
            progress=False,
        )
        i += m
        for world in rounds:
            if len(draw.episodes) >= n:
                break
            draw.start_redraws += world.redraws
            if world.dropped == "visible_at_start":
                draw.visible_at_start += 1
            elif world.dropped == "infeasible":
                draw.infeasible += 1
            elif world.episode is not None:
                draw.episodes.append(replace(world.episode, index=len(draw.episodes)))
    return draw


_drawn: dict[tuple, EpisodeDraw] | None = None  # inside remembered_draws: the draws so far


@contextlib.contextmanager
def remembered_draws() -> Iterator[None]:
    """Within it, ``draw_episodes`` called again with the same arguments returns the draw it
    made (deterministic in them) instead of drawing anew: the curve searches the same episodes at
    every k, the transfer benchmark with every store."""
    global _drawn
    outer = _drawn
    _drawn = {} if outer is None else outer
    try:
        yield
    finally:
        _drawn = outer


@dataclass(frozen=True)
class Priors:
    """Where each policy's probabilities come from: the learned knowledge or the ground truth."""

    kb: KnowledgeBase | None
    learned: frozenset[int]  # room seeds the knowledge was learned in (never searched)
    rank: str  # the rank of policies named without one
    truth: ss.ProbabilitySource | None
    pooled: PooledCounts | None = None  # evidence over the hierarchy: the backoff estimate
    min_evidence: int = ss.DEFAULT_MIN_EVIDENCE

    def check(self, names: Sequence[str]) -> None:
        """A one-line error if a policy needs a knowledge store and none was given."""
        for name in names:
            base, _ = split_name(name)
            if S.POLICIES[base].needs == "kb" and self.kb is None:
                raise CtxsearchError(f"policy '{base}' needs a knowledge store (--kb)")

    def for_policy(self, base: str, r: str | None) -> ss.ProbabilitySource | None:
        """The probabilities policy ``base`` ranks by (rank ``r`` or the default), if any."""
        needs = S.POLICIES[base].needs
        if needs == "kb":
            rooms = len(self.learned) or None
            if self.pooled is not None:
                return ss.BackoffProbabilities(
                    self.kb, self.pooled, r or self.rank, rooms, self.min_evidence
                )
            return ss.KBProbabilities(self.kb, r or self.rank, rooms=rooms)
        if needs == "truth":
            return self.truth
        return None


def load_priors(
    config: SearchConfig,
    style: WorldStyle,
    catalog: Catalog,
    kb: KnowledgeBase | None = None,
    kb_path: Path | str | None = None,
    exclude_seeds: set[int] | frozenset[int] = frozenset(),
) -> Priors:
    """The priors of ``config.policies``: ``kb`` or the store at ``kb_path`` (whose learning rooms
    join ``exclude_seeds``), and the ground truth if an oracle-prior policy runs. With
    ``config.estimate == "backoff"`` the evidence is also pooled over the hierarchy (from the
    store's log, or from ``kb``'s counts)."""
    if config.estimate not in ss.ESTIMATES:
        raise CtxsearchError(
            f"unknown estimate '{config.estimate}' (known: {', '.join(ss.ESTIMATES)})"
        )
    S.check_scenario(config.policies, config.map)
    learned = set(exclude_seeds)
    pooled = None
    if kb is None and kb_path is not None:
        kb, seeds = S.open_knowledge(kb_path, catalog, interval=config.interval)
        learned |= seeds
        if config.estimate == "backoff":
            pooled = S.open_pooled(kb_path, catalog)
    elif kb is not None and config.estimate == "backoff":
        pooled = PooledCounts.from_knowledge_base(kb)
    truth = None
    if any(S.POLICIES[split_name(n)[0]].needs == "truth" for n in config.policies):
        truth = S.truth_probabilities(style, catalog, config.truth_samples, path=config.truth)
    priors = Priors(kb, frozenset(learned), config.rank, truth, pooled, config.min_evidence)
    priors.check(config.policies)
    return priors


@dataclass
class EpisodeRoom:
    """An episode's room, built once and shared by the policies that search it."""

    layout: RoomLayout
    catalog: Catalog
    world: World
    maps: S.RoomMaps  # the scenario's maps, with the detector preset (None: perfect)
    given: S.RoomMaps | None = None  # the true layout's maps for TRUE_MAP_POLICIES (built)

    def maps_for(self, policy: str) -> S.RoomMaps:
        """The maps policy ``policy`` (a base name) searches on."""
        if policy in S.TRUE_MAP_POLICIES and self.given is not None:
            return self.given
        return self.maps


def recording_root(policy: str) -> str:
    """The root entity of a policy's search in a shared recording (``location@low`` ->
    ``location_low``)."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", policy)


def _recorder(
    ep: S.Episode, name: str, layout: RoomLayout, rec_path: Path | None, stream
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
    ep: S.Episode,
    name: str,
    room: EpisodeRoom,
    probs: ss.ProbabilitySource | None,
    rec_path: Path | None = None,
    stream=None,
) -> S.SearchResult:
    """Policy ``name`` searches episode ``ep`` in ``room`` (a rerun recording to ``rec_path``, or
    under the policy's root in the open rerun ``stream``)."""
    layout, catalog, world = room.layout, room.catalog, room.world
    base, _ = split_name(name)
    with _recorder(ep, name, layout, rec_path, stream) as rec:
        rec.log_room(layout, catalog)
        rec.log_text(f"episode: room {ep.style}/{ep.room_seed}, target {ep.target}, policy {name}")
        ctx = S.SearchContext(
            ep,
            layout,
            catalog,
            world,
            maps=room.maps_for(base),
            probs=probs,
            recorder=rec,
            policy=name,
        )
        res = S.make_policy(base).run(ctx)
    res.policy = name
    return res


def search_room(
    ep: S.Episode,
    style: WorldStyle,
    catalog: Catalog,
    runs: Sequence[tuple[str, ss.ProbabilitySource | None, Path | None]],
    progress: Callable[[str], None] | None = None,
    detector: DetectorModel | None = None,
    shared: Path | None = None,
    map_mode: str = "given",
) -> list[S.SearchResult]:
    """Build ``ep``'s room once and run each (policy, probabilities, recording) of ``runs`` (a
    policy may appear twice with other probabilities: results are in ``runs``' order) with the
    ``detector`` preset (None: perfect) in map scenario ``map_mode``; ``shared``: one recording
    of them all, side by side."""
    layout = generate_layout(style, ep.room_seed, catalog)
    stream = None
    if shared is not None:
        names = [name for name, _, _ in runs]
        stream = open_stream(
            shared,
            SEARCH_APP,
            name=f"search: {ep.style} room {ep.room_seed}, {ep.target}: {' vs '.join(names)}",
            blueprint=search_blueprint(layout, [(recording_root(n), n) for n in names]),
        )
    try:
        with World(layout, catalog) as world:
            given = S.RoomMaps.given(layout, catalog, world.spec, detector)
            if map_mode == "built":
                built = S.RoomMaps.built(layout, catalog, world.spec, detector)
                room = EpisodeRoom(layout, catalog, world, built, given)
            else:
                room = EpisodeRoom(layout, catalog, world, given)
            out = []
            for name, probs, rec_path in runs:
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


def run_episodes(
    episodes: Sequence[S.Episode],
    policies: Sequence[str],
    catalog: Catalog,
    style: WorldStyle,
    probs_for: ProbsFor,
    progress: Callable[[str], None] | None = None,
    detector: DetectorModel | None = None,
    map_mode: str = "given",
) -> dict[str, list[S.SearchResult]]:
    """Run every policy on every episode (one World per episode, shared by the policies) with
    the ``detector`` preset (None: perfect) in map scenario ``map_mode``."""
    results: dict[str, list[S.SearchResult]] = {p: [] for p in policies}
    for ep in episodes:
        for name, res in zip(
            policies,
            run_episode(ep, policies, catalog, style, probs_for, progress, detector, map_mode),
            strict=True,
        ):
            results[name].append(res)
    return results


def run_episode(
    ep: S.Episode,
    policies: Sequence[str],
    catalog: Catalog,
    style: WorldStyle,
    probs_for: ProbsFor,
    progress: Callable[[str], None] | None = None,
    detector: DetectorModel | None = None,
    map_mode: str = "given",
) -> list[S.SearchResult]:
    """Every policy on episode ``ep`` (one World, shared by the policies), in ``policies`` order,
    with the ``detector`` preset (None: perfect) in map scenario ``map_mode``."""
    runs = [(name, probs_for(*split_name(name)), None) for name in policies]
    return search_room(ep, style, catalog, runs, progress, detector, map_mode=map_mode)


@dataclass
class OneSearch:
    """One episode of ``ctxsearch search``: the episode and each policy's result."""

    episode: S.Episode
    results: list[S.SearchResult]
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
    S.check_target(catalog, target)
    names = list(config.policies)
    for n in names:
        split_name(n)
    style = resolve_style(config.style, catalog)
    priors = load_priors(config, style, catalog, kb, kb_path, exclude_seeds)
    ep = make_episodes(
        style,
        1,
        config.seed,
        catalog,
        config.budget_s,
        exclude_seeds=priors.learned,
        target=target,
        detector=config.detector_model(catalog),
    )[0]
    records = list(records) if records is not None else [None] * len(names)
    runs = [
        (name, priors.for_policy(*split_name(name)), rec)
        for name, rec in zip(names, records, strict=True)
    ]
    out = search_room(
        ep,
        style,
        catalog,
        runs,
        detector=config.detector_model(catalog),
        shared=record,
        map_mode=config.map,
    )
    files = [Path(p) for p in records if p is not None]
    return OneSearch(ep, out, files + ([Path(record)] if record is not None else []))
