"""The episode draw: paired search episodes in held-out worlds, as the benchmarks, ``ctxsearch
search``, the demo and the Gymnasium task use them.

World i of a draw (room seed ``held_out_seed(seed, i)``, skipped if the store learned in it, it
has no small object, or no instance of a requested target) gets a target drawn uniformly among its
small types and a start drawn uniformly among the free cells (``random_start``), both from the
world's own stream. The start is redrawn while the target is visible from it (``OracleEye``: the
head aimed at each instance from the start, turning in place, and the detector in use would report
a true instance with probability >= ``VISIBLE_MIN_P``; the perfect detector: it does), at most
``MAX_START_TRIES`` starts, then the world is dropped. A world whose target no view of the oracle's
planner detects within the budget (``oracle_view`` from the start, the detector's draws as at the
world's first second) is dropped as infeasible. Worlds are taken in index order until the number
of episodes asked; the counts cover the worlds up to the last one taken. The draw reads the true
layout, as the oracle does.

A draw is named by one typed spec (``DrawSpec``): its arguments, its in-memory memo key
(``remembered_draws``) and its disk cache key (agent.search.draw_store).
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.agent.search import draw_store
from ctxsearch.agent.search.episode import (
    DEFAULT_BUDGET_S,
    Episode,
    EpisodeDraw,
    episode_layout,
    held_out_seed,
    random_start,
    small_types_present,
)
from ctxsearch.agent.search.oracle import VISIBLE_MIN_P, OracleEye, oracle_view
from ctxsearch.envs.detector import DetectorModel
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import WorldStyle
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.envs.world import World
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import Targets
from ctxsearch.knowledge.persistence import still_where_seen

MAX_START_TRIES = 6  # starts drawn in a world before it is dropped as visible from every one
EPISODE_TAG = 0xE915  # the episode stream of world i: (seed, i, EPISODE_TAG)

# Runs a draw's worlds: (check one world, world indices, description) -> the worlds' draws, in
# order. Serial by default; the benchmarks pass their sweep (serial or Ray).
WorldRunner = Callable[[Callable[[int], "WorldDraw"], list[int], str], list["WorldDraw"]]


@dataclass(frozen=True)
class DrawSpec:
    """What a draw is asked for: ``episodes`` episodes of ``style`` for benchmark seed ``seed``
    with the catalog of ``fingerprint`` (its ``world_fingerprint``), each of budget ``budget_s``, never in the rooms of
    ``exclude_seeds`` (sorted), looking for ``target`` (None: a small type drawn per world), the
    checks reading images with ``detector`` (None: perfect). Hashable: the memo and cache key."""

    style: WorldStyle
    episodes: int
    seed: int
    fingerprint: str
    budget_s: float = DEFAULT_BUDGET_S
    exclude_seeds: tuple[int, ...] = ()
    target: str | None = None
    detector: DetectorModel | None = None
    # ``instance``: the world keeps one instance of the target, drawn after the target (``type``,
    # the default, draws any instance)
    targets: Targets = Targets.TYPE
    # ``first_view`` False: the draw asks only whether the oracle finds the target within the
    # budget, not its soonest view (``oracle_view(soonest=False)``): the same worlds, targets and
    # starts, each episode's ``first_view`` None (the Oracle policy then plans it at its first
    # step), several times fewer images (the Gymnasium task, which has no oracle)
    first_view: bool = True
    # the day of the worlds (envs.floorplan's days): a remembered map's search happens on a
    # day after the tour that made the map (agent.search.tour, agent.search.remembered)
    day: int = 0
    # the houses the episodes are drawn in, in turn (the store's remembered homes: room seeds
    # the knowledge was learned in, never excluded); empty: held-out worlds
    homes: tuple[int, ...] = ()
    # the day of the robot's map (a remembered map's): each episode records whether an instance
    # of its target stands where one stood that day (``Episode.stayed``, knowledge.persistence
    # .still_where_seen); None: not asked
    since: int | None = None
    # with ``since``: half the episodes (rounded up) of targets that stayed, half that moved,
    # taken in world order as each half has room
    split: bool = False

    @classmethod
    def make(
        cls,
        style: WorldStyle,
        episodes: int,
        seed: int,
        catalog: Catalog,
        budget_s: float = DEFAULT_BUDGET_S,
        exclude_seeds: Iterable[int] = (),
        target: str | None = None,
        detector: DetectorModel | None = None,
        **more,
    ) -> DrawSpec:
        """The spec with ``catalog``'s fingerprint and, of the excluded seeds, those the draw
        can meet (the room seeds of its ``world_limit`` worlds), sorted: the draw is the same,
        and so is its key, for every store whose learning rooms it never meets (the curve's
        snapshots, the transfer's stores: one draw, not one per store). ``more``: the other
        fields by name (``targets``, ``first_view``, ``day``)."""
        worlds = draw_worlds(int(seed), int(episodes))
        exclude = tuple(sorted({int(s) for s in exclude_seeds} & worlds.keys()))
        return cls(
            style, int(episodes), int(seed), catalog.world_fingerprint, float(budget_s), exclude,
            target, detector, **more,
        )  # fmt: skip


@dataclass(frozen=True)
class WorldDraw:
    """One world's draw: its episode (index to be set), or why it was dropped (None: it holds
    nothing to search for, or the store learned in it), and how many starts were redrawn."""

    episode: Episode | None
    dropped: str | None = None
    redraws: int = 0


def draw_world(spec: DrawSpec, catalog: Catalog, i: int) -> WorldDraw:
    """World ``i``'s episode (module docstring): a start from which the target is not visible
    and from which the oracle's planner detects it within the budget."""
    room_seed = spec.homes[i % len(spec.homes)] if spec.homes else held_out_seed(spec.seed, i)
    rng = np.random.default_rng([int(spec.seed), i, EPISODE_TAG])
    if room_seed in spec.exclude_seeds and not spec.homes:
        return WorldDraw(None)
    layout = generate_layout(spec.style, room_seed, catalog, day=spec.day)
    tgt = episode_target(layout, catalog, spec.target, rng)
    if tgt is None:
        return WorldDraw(None)
    keep = None
    if spec.targets is Targets.INSTANCE:
        instances = layout.of_type(tgt)
        keep = instances[int(rng.integers(len(instances)))].id
        layout = layout.without({o.id for o in instances if o.id != keep})
    robot = RobotSpec()
    grid = OccupancyGrid.from_layout(layout, robot)
    redraws = 0
    with World(layout, catalog, spec=robot) as world:
        eye = OracleEye(world, layout, catalog, spec.detector, tgt)
        for _ in range(MAX_START_TRIES):
            start = random_start(layout, grid, rng)
            if eye.start_visibility(start, enough=VISIBLE_MIN_P) < VISIBLE_MIN_P:
                break
            redraws += 1
        else:
            return WorldDraw(None, "visible_at_start", redraws)
        world.reset_pose(start)
        # planned at the episode's second 0, as the Oracle policy would plan it
        view = oracle_view(
            eye, grid, start, 0.0, world.time_model, deadline_s=spec.budget_s,
            soonest=spec.first_view,
        )  # fmt: skip
    if view is None:
        return WorldDraw(None, "infeasible", redraws)
    if not spec.first_view:
        view = None
    stayed = None
    if spec.since is not None:
        before = generate_layout(spec.style, room_seed, catalog, day=spec.since)
        stayed = still_where_seen(before.objects, layout.objects, tgt)
    ep = Episode(
        -1, spec.style.name, room_seed, tgt, start, spec.budget_s, keep, spec.day,
        first_view=view, stayed=stayed,
    )  # fmt: skip
    return WorldDraw(ep, None, redraws)


def episode_target(
    layout: RoomLayout, catalog: Catalog, target: str | None, rng: np.random.Generator
) -> str | None:
    """The episode's target in ``layout``: ``target`` if the room holds one, else a small type
    drawn from ``rng``; None: the room does not serve."""
    if target is not None:
        return target if target in {o.type for o in layout.objects} else None
    small = small_types_present(layout, catalog)
    return small[int(rng.integers(len(small)))] if small else None


def serial_worlds(check: Callable[[int], WorldDraw], indices: list[int], desc: str):
    """A ``WorldRunner`` that checks the worlds one after the other here."""
    return [check(i) for i in indices]


def draw_episodes(
    spec: DrawSpec,
    catalog: Catalog,
    *,
    workers: int = 1,
    runner: WorldRunner = serial_worlds,
    cache: Path | None = None,
) -> EpisodeDraw:
    """The draw of ``spec`` with the counts of what was left out (module docstring). ``runner``
    checks a round of worlds (``workers``: how many it runs at once, which sizes the rounds; the
    same episodes and counts for any number); ``cache``: a directory where the draw is kept and
    read back by later commands with the same spec and code (agent.search.draw_store). Inside
    ``remembered_draws`` a draw of the same spec is not made again."""
    if _drawn is not None and spec in _drawn:
        return replace(_drawn[spec], episodes=list(_drawn[spec].episodes))
    stored = draw_store.draw_key(spec) if cache is not None else None
    draw = draw_store.load(cache, stored) if stored is not None else None
    if draw is not None and not check_draw(draw, spec, catalog):
        draw = None  # not the draw asked for: a miss, made again and the file replaced
    if draw is None:
        draw = _draw_worlds(spec, catalog, workers, runner)
        if stored is not None:
            draw_store.save(cache, stored, draw)
    if _drawn is not None:
        _drawn[spec] = replace(draw, episodes=list(draw.episodes))
    return draw


def world_limit(episodes: int) -> int:
    """How many worlds a draw of ``episodes`` episodes checks before it gives up."""
    return 50 * episodes + 100


def draw_worlds(seed: int, episodes: int) -> dict[int, int]:
    """Room seed -> world index of every world a draw of ``episodes`` episodes for benchmark
    seed ``seed`` may check."""
    return {held_out_seed(seed, i): i for i in range(world_limit(episodes))}


def check_draw(draw: EpisodeDraw, spec: DrawSpec, catalog: Catalog) -> bool:
    """Whether ``draw`` (read from a file) can be the draw of ``spec``: ``spec.episodes``
    episodes indexed in order, of the style, budget and target asked, in held-out worlds taken in
    index order (none a room the store learned in), each with a small target the world holds and
    a start on a free cell of its grid, a first oracle view (if any) of a true instance within the
    budget, the one instance kept where ``spec.targets`` asks for it, and counts that are
    counts."""
    counts = (draw.visible_at_start, draw.infeasible, draw.start_redraws)
    if len(draw.episodes) != spec.episodes or min(counts) < 0:
        return False
    seeds = draw_worlds(spec.seed, spec.episodes)
    room = split_quota(spec)
    if room is not None and any(
        sum(ep.stayed is s for ep in draw.episodes) != room[s] for s in (True, False)
    ):
        return False
    last = -1
    for k, ep in enumerate(draw.episodes):
        asked = (ep.index, ep.style, ep.budget_s) == (k, spec.style.name, spec.budget_s)
        if spec.homes:  # the homes in turn, several episodes each, none excluded
            world, fits = k, ep.room_seed in spec.homes
        else:  # held-out worlds in index order, none a learned one
            world = seeds.get(ep.room_seed, -1)
            fits = world > last and ep.room_seed not in spec.exclude_seeds
        if not (asked and fits):
            return False
        if spec.target is not None and ep.target != spec.target:
            return False
        if (ep.instance is not None) != (spec.targets is Targets.INSTANCE) or ep.day != spec.day:
            return False
        if (ep.stayed is None) != (spec.since is None):
            return False
        last = world
        if not _episode_fits(ep, spec, catalog):
            return False
    return True


def _episode_fits(ep: Episode, spec: DrawSpec, catalog: Catalog) -> bool:
    """The episode's world holds its target, the start is on a free cell, and its first oracle
    view (if any) sees a true instance within the budget."""
    whole = generate_layout(spec.style, ep.room_seed, catalog, day=ep.day)
    if ep.target not in small_types_present(whole, catalog):
        return False
    if ep.instance is not None and ep.instance not in {o.id for o in whole.of_type(ep.target)}:
        return False
    layout = episode_layout(whole, ep)
    grid = OccupancyGrid.from_layout(layout, RobotSpec())
    r, c = grid.to_cell(ep.start.xy)
    if not (grid.in_grid(r, c) and grid.free[r, c]):
        return False
    v = ep.first_view
    ids = {o.id for o in layout.of_type(ep.target)}
    return v is None or (0.0 <= v.seconds <= spec.budget_s and v.instance_id in ids)


def make_episodes(spec: DrawSpec, catalog: Catalog) -> list[Episode]:
    """The episodes of ``spec``'s draw, checked here one world after the other."""
    return draw_episodes(spec, catalog).episodes


def _draw_worlds(
    spec: DrawSpec, catalog: Catalog, workers: int, runner: WorldRunner
) -> EpisodeDraw:
    """The worlds of a draw checked in rounds."""
    n = spec.episodes
    room = split_quota(spec)
    draw = EpisodeDraw([])
    limit = world_limit(n)
    check = functools.partial(draw_world, spec, catalog)
    i = 0
    while len(draw.episodes) < n:
        if i >= limit:
            what = f"a {spec.target}" if spec.target else "a small object"
            where = (
                f"none of the {len(spec.homes)} remembered house(s)" if spec.homes
                else "no held-out room"
            )  # fmt: skip
            half = (
                f" ({room[True]} more that stayed and {room[False]} more that moved since day "
                f"{spec.since} wanted)" if room is not None else ""
            )  # fmt: skip
            raise CtxsearchError(
                f"{where} of style '{spec.style.name}' holds {what} on day {spec.day} that can be "
                f"searched for (tried {limit} draws){half}"
            )
        # A round: as many worlds as episodes still needed (with several workers, at least two
        # per worker; with one, no world is checked beyond the last episode taken)
        m = min(limit - i, max(n - len(draw.episodes), 2 * workers if workers > 1 else 1))
        rounds = runner(check, list(range(i, i + m)), f"episode draw {spec.style.name}")
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
                if room is not None:
                    if room[world.episode.stayed] <= 0:
                        continue
                    room[world.episode.stayed] -= 1
                draw.episodes.append(replace(world.episode, index=len(draw.episodes)))
    return draw


def split_quota(spec: DrawSpec) -> dict[bool | None, int] | None:
    """How many episodes of targets that stayed (True) and moved (False) a split draw takes."""
    if not spec.split:
        return None
    if spec.since is None:
        raise CtxsearchError("a draw split by what moved needs the day of the robot's map")
    return {True: spec.episodes - spec.episodes // 2, False: spec.episodes // 2, None: 0}


_drawn: dict[DrawSpec, EpisodeDraw] | None = None  # inside remembered_draws: the draws so far


@contextlib.contextmanager
def remembered_draws() -> Iterator[None]:
    """Within it, ``draw_episodes`` called again with the same spec returns the draw it made
    (deterministic in it) instead of drawing anew: the curve searches the same episodes at every
    k, the transfer benchmark with every store."""
    global _drawn
    outer = _drawn
    _drawn = {} if outer is None else outer
    try:
        yield
    finally:
        _drawn = outer
