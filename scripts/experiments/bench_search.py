"""The search benchmark: every policy on the same episodes, time to find, and the files.

Paired episodes (``agent.search.draw.draw_episodes``): the episode list is drawn once: held-out rooms
(``agent.search.episode.held_out_seed(seed, i)``, skipping any seed the knowledge store learned in and rooms
without a small object), a target type drawn uniformly among the small (kind=object) types present
in the room, and a start pose (a uniformly drawn free cell, random heading) from which the target
is **not visible** (redrawn while it is; the world dropped after ``MAX_START_TRIES``), in a world
where the oracle's planner finds a view that **detects** it within the budget (else dropped as
infeasible); search.json counts both (``excluded``, ``start_redraws``). Every policy then runs
every episode: the room is built once per episode and the robot is put back at the same start
pose for each policy, with a fresh seen map and nothing known.

Statistics per policy (``aggregate``), failures counted at the budget (so a policy that fails
often cannot look fast):

- ``paired_ratio`` (the headline): for each baseline B of ``BASELINES`` that ran, the median over
  episodes of this policy's time over B's on the same episode, with a seeded percentile bootstrap
  95% interval, and the episodes it was faster (``wins``) and slower (``losses``) in;
- ``success_rate`` within the budget, ``spl`` = mean over episodes of S * t_oracle /
  max(t, t_oracle) (S: success; with ``oracle`` in the run), ``oracle_violations`` (episodes the
  policy beat the oracle: a bound that is not one; must be 0);
- median and mean simulated seconds to find, each with its bootstrap interval; mean gazes and
  metres driven; as secondary fields, the ratio of the median to ``exhaustive``'s and to
  ``oracle``'s (not paired).

Per target type and per group (``detect_group``: small / hard to detect vs large, from the
catalog's detectability) the episodes, success and median time of every policy (``by_target``,
``by_group``).

Policy names may carry a rank, ``location@low``, ``location@p0``, ``location@high``, to compare
the parts of the interval on the same episodes.

Writes ``DIR/search.json``, ``DIR/search.md`` (the tables, paired ratios first),
``DIR/search.png`` (the time-to-find CDF of every policy) and ``DIR/episodes.csv`` (one row per
episode and policy); with ``indirect`` and ``frontier`` also ``DIR/indirect.json`` and
``DIR/indirect.md`` (each intermediate type's predicted gain against the measured paired ratio:
bench_indirect).

The map scenario (``map.scenario`` of the configuration, ``--map``): ``built`` (the robot knows nothing at the
start: frontier, indirect, oracle-prior-indirect, oracle) or ``given`` (the furniture poses are
known: map-only, location, oracle-prior, oracle, exhaustive); search.json's ``map`` says which.

The episode checks and the episodes run as the units of sweeps (``scripts.sweep``: serially, or as
Ray tasks with ``--workers N`` / ``--ray-address``; episodes in batches of ``EPISODES_PER_UNIT``);
the files are the same either way, apart from the wall time. With ``--journal DIR`` every
finished unit (a world of the draw, an episode with every policy) is kept in DIR
(scripts.experiments.journals) and a later run of the same command reads it back instead of
running it again: a run stopped at any moment continues where it stopped, with the same files.
"""

from __future__ import annotations

import functools
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search.config import SearchConfig, to_dict
from ctxsearch.agent.search.draw import DrawSpec, WorldDraw, draw_episodes
from ctxsearch.agent.search.episode import Episode, EpisodeDraw, SearchResult, episode_layout
from ctxsearch.agent.search.measures import (
    BOOTSTRAP_SAMPLES,
    TIE_S,
    PairedRatio,
    PairedStats,
    bootstrap_ci,
    oracle_violations,
    paired_ratio,
    paired_stats,
    r4,
    spl,
)
from ctxsearch.agent.search.priors import KnowledgeSource
from ctxsearch.agent.search.runner import SearchRun, code_version, prepare, run_episode
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import WorldStyle
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import Estimate
from ctxsearch.scripts.experiments.bench_indirect import indirect_analysis, write_indirect
from ctxsearch.scripts.experiments.journals import draw_journal, search_journal
from ctxsearch.scripts.experiments.tables import write_csv
from ctxsearch.scripts.sweep import SweepOptions, run_units, session

EPISODES_PER_UNIT = 2  # episodes per sweep unit (a room is built per episode either way)


# The baselines every policy's paired ratio is taken to, when they ran: the no-context policies
# (the nearest-frontier explorer on the built map, the known furniture's volumes without
# probabilities on the given map, exhaustive coverage) and the policies with the true
# probabilities.
BASELINES = (
    "frontier", "uniform", "map-only", "exhaustive", "oracle-prior", "oracle-prior-indirect"
)  # fmt: skip
# On the remembered map with memory arms, also each part alone and the bound: memory and
# relations together against memory only and relations only (and against the true values).
MEMORY_BASELINES = ("memory", "location", "oracle-memory")
ORACLE = "oracle"


def baselines_of(names) -> tuple[str, ...]:
    """The baselines of a run of the policies ``names``, in order (those that ran)."""
    bases = BASELINES
    if "memory" in names or "memory-location" in names:
        bases = bases + MEMORY_BASELINES
    return tuple(b for b in bases if b in names)


# An early stop (before the budget, nothing found) with more than this share of the belief's
# detectable mass left counts as premature (the aim: none).
EARLY_STOP_MASS = 0.10


@dataclass
class PolicyStats:
    """Aggregates of one policy over the episodes."""

    name: str
    success_rate: float
    median_s: float
    median_ci: tuple[float, float]
    mean_s: float
    mean_ci: tuple[float, float]
    gazes: float
    path_m: float
    ratio_to_exhaustive: float | None = None  # ratio of medians (secondary: not paired)
    ratio_to_oracle: float | None = None  # ratio of medians (secondary: not paired)
    paired_ratio: float | None = None  # median over episodes of t / t_exhaustive
    paired_ratio_ci: tuple[float, float] | None = None
    spl: float | None = None  # mean over episodes of S * t_oracle / max(t, t_oracle)
    paired: dict[str, PairedRatio] = field(default_factory=dict)  # baseline -> paired ratio
    oracle_violations: int = 0  # episodes this policy found the target sooner than the oracle
    # baseline -> the statistics that can see a small effect (geometric mean, test, ties, power)
    paired_stats: dict[str, PairedStats] = field(default_factory=dict)
    # episodes the policy stopped before its budget without a find, and of those the ones whose
    # belief still held more than EARLY_STOP_MASS of its detectable mass (agent.search.belief)
    gave_up: int = 0
    gave_up_with_mass: int = 0

    def to_json(self) -> dict:
        """The JSON entry of search.json."""
        return {
            "success_rate": r4(self.success_rate),
            "spl": r4(self.spl),
            "paired": {b: p.to_json() for b, p in self.paired_stats.items()},
            "paired_ratio": {b: p.to_json() for b, p in self.paired.items()},
            "median_s": r4(self.median_s),
            "median_ci": [r4(self.median_ci[0]), r4(self.median_ci[1])],
            "mean_s": r4(self.mean_s),
            "mean_ci": [r4(self.mean_ci[0]), r4(self.mean_ci[1])],
            "gazes": r4(self.gazes),
            "path_m": r4(self.path_m),
            "ratio_to_exhaustive": r4(self.ratio_to_exhaustive),
            "ratio_to_oracle": r4(self.ratio_to_oracle),
            "oracle_violations": self.oracle_violations,
            "gave_up": self.gave_up,
            "gave_up_with_mass": self.gave_up_with_mass,
        }


def aggregate(results: dict[str, list[SearchResult]], seed: int = 0) -> dict[str, PolicyStats]:
    """Per-policy statistics (see the module docstring); episodes must be aligned across policies."""
    out: dict[str, PolicyStats] = {}
    for name, rs in results.items():
        t = np.array([r.time_to_find for r in rs], float)
        out[name] = PolicyStats(
            name=name,
            success_rate=float(np.mean([r.success for r in rs])) if rs else math.nan,
            median_s=float(np.median(t)) if len(t) else math.nan,
            median_ci=bootstrap_ci(t, np.median, seed=seed),
            mean_s=float(np.mean(t)) if len(t) else math.nan,
            mean_ci=bootstrap_ci(t, np.mean, seed=seed),
            gazes=float(np.mean([r.gazes for r in rs])) if rs else math.nan,
            path_m=float(np.mean([r.path_m for r in rs])) if rs else math.nan,
            gave_up=sum(r.stop == "gave-up" for r in rs),
            gave_up_with_mass=sum(
                r.stop == "gave-up" and (r.mass_left or 0.0) > EARLY_STOP_MASS for r in rs
            ),
        )
    for ref, attr in (("exhaustive", "ratio_to_exhaustive"), (ORACLE, "ratio_to_oracle")):
        if ref in out and out[ref].median_s > 0:
            for st in out.values():
                setattr(st, attr, st.median_s / out[ref].median_s)
    times = {n: np.array([r.time_to_find for r in rs], float) for n, rs in results.items()}
    for name in results:
        for base in baselines_of(results):
            if base != name:
                out[name].paired[base] = paired_ratio(times[name], times[base], seed=seed)
                out[name].paired_stats[base] = paired_stats(times[name], times[base], seed=seed)
        if "exhaustive" in results:
            pr = paired_ratio(times[name], times["exhaustive"], seed=seed)
            out[name].paired_ratio, out[name].paired_ratio_ci = pr.median, pr.ci
        if ORACLE in results:
            out[name].spl = spl(results[name], results[ORACLE])
            if name != ORACLE:
                out[name].oracle_violations = oracle_violations(results[name], results[ORACLE])
    return out


def episode_facts(style: WorldStyle, eps: Sequence[Episode], catalog: Catalog) -> list[dict]:
    """What each episode is like, for the strata of search.json's ``paired_by``: the target's
    group (``detect_group``), whether an instance stands in the room the robot starts in (a
    single room: always), and how many instances the world holds (``1``, ``2-3``, ``4+``). Read
    from the true layout: a report, not the robot's knowledge. On the remembered map also
    whether an instance of the target stands where one stood on the map's day (``memory``:
    ``stayed`` or ``moved``; agent.search.draw's ``since``)."""
    out = []
    for ep in eps:
        layout = episode_layout(generate_layout(style, ep.room_seed, catalog, day=ep.day), ep)
        inst = layout.of_type(ep.target)
        start = _room_at(layout, ep.start.x, ep.start.y)
        same = not layout.rooms or any(layout.room_of.get(o.id) == start for o in inst)
        k = len(inst)
        fact = {
            "target_group": detect_group(catalog, ep.target),
            "start_room": "instance in the start room" if same else "none in the start room",
            "instances": "1" if k <= 1 else "2-3" if k <= 3 else "4+",
        }
        if ep.stayed is not None:  # the remembered map: did the target stay where it was seen
            fact["memory"] = "stayed" if ep.stayed else "moved"
        out.append(fact)
    return out


def _room_at(layout: RoomLayout, x: float, y: float) -> int | None:
    """The index of the house room whose outline holds (x, y) (None: none, or a single room)."""
    for r in layout.rooms:
        x0, y0, x1, y1 = r.outline
        if x0 <= x <= x1 and y0 <= y <= y1:
            return r.index
    return None


STRATA = ("target_group", "start_room", "instances", "memory")


def paired_strata(
    results: dict[str, list[SearchResult]], facts: Sequence[dict], seed: int = 0
) -> dict[str, dict]:
    """``paired_stats`` of every policy against every baseline that ran, within each stratum of
    ``STRATA``: {stratum: {value: {"n": episodes, policy: {baseline: stats}}}}."""
    bases = baselines_of(results)
    out: dict[str, dict] = {}
    for kind in STRATA:
        if not facts or kind not in facts[0]:
            continue
        out[kind] = {}
        for value in sorted({f[kind] for f in facts}):
            idx = [i for i, f in enumerate(facts) if f[kind] == value]
            t = {n: np.array([rs[i].time_to_find for i in idx]) for n, rs in results.items()}
            cell: dict = {"n": len(idx)}
            for name in results:
                cell[name] = {
                    b: paired_stats(t[name], t[b], seed=seed).to_json() for b in bases if b != name
                }
            out[kind][value] = cell
    return out


def detect_group(catalog: Catalog, type_name: str) -> str:
    """``small`` (hard to detect) or ``large``: small if the type's effective detection range
    (agent.search.space.effective_range, from the catalog's sizes, min_pixels and max_range) is
    below the median of the catalog's small-object (kind=object) types', so the rule holds for
    any style and catalog."""
    ranges = {t.name: ss.effective_range(t) for t in catalog.types if not t.is_furniture}
    med = float(np.median(list(ranges.values())))
    r = ranges.get(type_name, ss.effective_range(catalog.type(type_name)))
    return "small" if r < med else "large"


def breakdown(
    eps: Sequence[Episode],
    results: dict[str, list[SearchResult]],
    key: Callable[[Episode], str],
) -> dict[str, dict]:
    """Per value of ``key`` (the target type, its group): episodes, and per policy the success
    rate and the median time to find (failures at the budget)."""
    out: dict[str, dict] = {}
    for k in sorted({key(ep) for ep in eps}):
        idx = [i for i, ep in enumerate(eps) if key(ep) == k]
        out[k] = {
            "n": len(idx),
            "policies": {
                name: {
                    "success_rate": r4(float(np.mean([rs[i].success for i in idx]))),
                    "median_s": r4(float(np.median([rs[i].time_to_find for i in idx]))),
                }
                for name, rs in results.items()
            },
        }
    return out


@dataclass
class BenchResult:
    """What ``bench_search`` produced."""

    episodes: list[Episode]
    results: dict[str, list[SearchResult]]
    stats: dict[str, PolicyStats]
    table: str
    files: list[Path] = field(default_factory=list)
    wall_s: float = 0.0
    draw: EpisodeDraw | None = None  # what the episode draw left out
    config: SearchConfig | None = None  # the configuration as it ran (resolved)
    facts: list[dict] = field(default_factory=list)  # episode_facts, for the strata


def headline_table(stats: dict[str, PolicyStats]) -> str:
    """search.md's first table: each policy against each baseline that ran, by the geometric
    mean of the paired time ratio with its interval, the ratio of means, wins/losses/ties, the
    signed-rank test and the episodes the measured effect needs for 80% power."""

    def f(x, d=2):
        return "-" if x is None or not math.isfinite(x) else f"{x:.{d}f}"

    lines = [
        "| policy | baseline | geometric mean [95% CI] | ratio of means [95% CI] | "
        "wins/losses/ties | Wilcoxon p | episodes for 80% power |",
        "|---|---|---|---|---|---|---|",
    ]
    for st in stats.values():
        for b, p in st.paired_stats.items():
            lines.append(
                f"| {st.name} | {b} | {f(p.geo_mean)} [{f(p.geo_mean_ci[0])}, "
                f"{f(p.geo_mean_ci[1])}] | {f(p.ratio_of_means)} [{f(p.ratio_of_means_ci[0])}, "
                f"{f(p.ratio_of_means_ci[1])}] | {p.wins}/{p.losses}/{p.ties} | "
                f"{f(p.wilcoxon_p, 3)} | {p.episodes_for_power or '-'} |"
            )
    lines.append("")
    lines.append(
        "Per episode, the policy's simulated seconds to find over the baseline's (a failure at "
        f"the budget); a tie is within {TIE_S:g} s and counts as ratio 1; intervals: percentile "
        "bootstrap over episodes; Wilcoxon: signed-rank test on the log ratios, ties dropped; "
        "the last column: the paired episodes an effect of the measured size needs for 80% "
        "power at a two-sided 5% level."
    )
    return "\n".join(lines)


def format_table(stats: dict[str, PolicyStats], n: int, budget_s: float) -> str:
    """The Markdown tables of search.md: the headline statistics (``headline_table``), then the
    paired medians, success, spl and times."""
    bases = list(baselines_of(stats))

    def f(x, d=1):
        return "-" if x is None or not math.isfinite(x) else f"{x:.{d}f}"

    def pr(p: PairedRatio | None) -> str:
        if p is None:
            return "-"
        return f"{f(p.median, 2)} [{f(p.ci[0], 2)}, {f(p.ci[1], 2)}] {p.wins}/{p.losses}"

    lines = [
        headline_table(stats),
        "",
        "| policy | "
        + "".join(f"t / t_{b} [95% CI] wins/losses | " for b in bases)
        + "success | spl | median s [95% CI] | mean s [95% CI] | gazes | path m | "
        "median / median exhaustive |",
        "|---|" + "---|" * len(bases) + "---|---|---|---|---|---|---|",
    ]
    for st in stats.values():
        lines.append(
            f"| {st.name} | "
            + "".join(f"{pr(st.paired.get(b))} | " for b in bases)
            + f"{100 * st.success_rate:.0f}% | {f(st.spl, 2)} | {f(st.median_s)} "
            f"[{f(st.median_ci[0])}, {f(st.median_ci[1])}] | {f(st.mean_s)} [{f(st.mean_ci[0])}, "
            f"{f(st.mean_ci[1])}] | {f(st.gazes)} | {f(st.path_m)} | "
            f"{f(st.ratio_to_exhaustive, 2)} |"
        )
    lines.append("")
    lines.append(
        f"{n} paired episodes; simulated seconds to find the target, a failure counted at the "
        f"budget ({budget_s:.0f} s). t / t_B: the median over episodes of the policy's time over "
        f"baseline B's on the same episode, wins/losses the episodes it was faster/slower in; "
        f"spl: the mean of S * t_oracle / max(t, t_oracle); 95% intervals: percentile bootstrap "
        f"over episodes ({BOOTSTRAP_SAMPLES} resamples, seeded)."
    )
    return "\n".join(lines)


def plot_cdf(
    results: dict[str, list[SearchResult]], budget_s: float, path: Path, title: str
) -> None:
    """search.png: the share of episodes found within t simulated seconds, per policy."""
    fig = Figure(figsize=(7, 4.5), dpi=120)
    ax = fig.subplots()
    for name, rs in results.items():
        t = np.sort([r.sim_time for r in rs if r.success])
        n = len(rs)
        xs = np.concatenate([[0.2], t, [budget_s]])
        ys = np.concatenate([[0.0], np.arange(1, len(t) + 1) / n, [len(t) / n]])
        ax.step(xs, ys, where="post", label=name, lw=1.8)
    ax.set_xscale("log")
    ax.set_xlabel("simulated seconds (log scale)")
    ax.set_ylabel("share of episodes with the target found")
    ax.set_xlim(0.2, budget_s)
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)


def bench_search(
    config: SearchConfig,
    out: Path | str,
    *,
    progress: Callable[[str], None] | None = print,
    sweep: SweepOptions | None = None,
    bar: bool = True,
    kb: KnowledgeBase | None = None,
    observer: Callable | None = None,
    split: bool = False,
) -> BenchResult:
    """The benchmark of ``config`` (module docstring): run, aggregate, write the four files to
    ``out``. ``progress`` gets a line per episode and policy (in episode order, as batches
    finish), ``bar`` shows a progress bar over the sweep's units; ``kb``: the knowledge in
    memory instead of the store ``config.knowledge.kb`` (``bench curve``'s empty store at
    k = 0); ``observer``: called at every online decision (``SearchContext.observer``; the
    episodes then run in this process); ``split``: on the remembered map, half the episodes of
    targets that stayed where an instance stood on the map's day, half of targets that moved."""
    t_wall = time.perf_counter()
    sweep = sweep or SweepOptions()
    if observer is not None and (sweep.workers > 1 or sweep.ray_address):
        raise CtxsearchError("an observer of the decisions needs the episodes in this process")
    run = prepare(config, source=KnowledgeSource(kb), progress=bar)
    run = replace(run, observer=observer)
    config = run.config
    spec = run.draw_spec(config.episodes, split=split)
    runner = sweep_worlds(sweep, bar, spec)
    with session(sweep, bar):  # one Ray for the draw's rounds and the searches
        draw = draw_episodes(
            spec, run.catalog, workers=sweep.workers, runner=runner, cache=config.draw_cache
        )
        eps = draw.episodes
        results = _run_batches(eps, run, sweep, bar, kb)
    names = [s.name for s in run.specs]
    if progress is not None:
        for i, ep in enumerate(eps):
            for n in names:
                r = results[n][i]
                progress(f"episode {ep.index} ({ep.target}, room {ep.room_seed}): {r.summary()}")
    stats = aggregate(results, seed=config.seed)
    res = BenchResult(eps, results, stats, format_table(stats, len(eps), config.budget_s))
    res.draw = draw
    res.config = config
    res.facts = episode_facts(run.style, eps, run.catalog)
    res.files = _write_files(run, Path(out), res)
    if "indirect" in results and "frontier" in results:  # scripts.experiments.bench_indirect
        res.files += write_indirect(Path(out), indirect_analysis(eps, results, seed=config.seed))
    res.wall_s = time.perf_counter() - t_wall
    return res


def sweep_worlds(sweep: SweepOptions, bar: bool = False, spec: DrawSpec | None = None):
    """An episode draw's world runner (agent.search.draw.WorldRunner) on ``sweep``'s workers
    (serial, or Ray tasks), a progress bar over each round's worlds with ``bar``; with
    ``sweep.journal``, each world checked for the draw of ``spec`` is kept there
    (scripts.experiments.journals.draw_journal)."""
    journal = None
    if sweep.journal is not None and spec is not None:
        journal = draw_journal(sweep.journal, spec)

    def run(check: Callable[[int], WorldDraw], indices: list[int], desc: str) -> list[WorldDraw]:
        return run_units(
            check, indices, workers=sweep.workers, ray_address=sweep.ray_address, desc=desc,
            progress=bar, journal=journal,
        )  # fmt: skip

    return run


def _run_batches(
    eps: list[Episode],
    run: SearchRun,
    sweep: SweepOptions,
    bar: bool,
    kb: KnowledgeBase | None = None,
) -> dict[str, list[SearchResult]]:
    """Every policy of ``run`` on every episode, ``EPISODES_PER_UNIT`` episodes per sweep
    unit; with ``sweep.journal`` one episode per unit, each kept there as it finishes (so a
    run stopped part-way never runs a finished episode again; ``kb``: the knowledge held in
    memory, None for the store's)."""
    per = 1 if sweep.journal is not None else EPISODES_PER_UNIT
    batches = [eps[i : i + per] for i in range(0, len(eps), per)]
    names = [s.name for s in run.specs]
    journal = None
    if sweep.journal is not None:
        journal = search_journal(sweep.journal, run.config, names, kb)
    done = run_units(
        functools.partial(_batch_unit, run),
        batches,
        workers=sweep.workers,
        ray_address=sweep.ray_address,
        desc=f"bench search {run.style.name}",
        progress=bar,
        journal=journal,
    )
    results: dict[str, list[SearchResult]] = {n: [] for n in names}
    for batch in done:
        for per_policy in batch:
            for n, r in zip(names, per_policy, strict=True):
                results[n].append(r)
    return results


def _batch_unit(run: SearchRun, batch: list[Episode]) -> list[list[SearchResult]]:
    """One sweep unit: every policy of ``run`` on each episode of ``batch``."""
    return [run_episode(ep, run) for ep in batch]


# episodes.csv: one row per episode and policy.
EPISODE_COLUMNS = (
    "style",
    "episode",
    "room_seed",
    "target",
    "target_group",  # small (hard to detect) or large: detect_group
    "start_x_m",
    "start_y_m",
    "start_yaw_rad",
    "budget_s",
    "policy",
    "found",  # the target was detected (maybe after the budget)
    "success",  # found within the budget
    "sim_s",  # simulated seconds until found, or until the policy stopped
    "time_to_find_s",  # sim_s if success, else the budget
    "gazes",
    "path_m",
    "stop",  # found, budget, false-find (a confirmed detection of no target) or gave-up
    "mass_left",  # at a stop before the budget: the belief's detectable mass left (else empty)
)


def episode_rows(
    eps: Sequence[Episode],
    results: dict[str, list[SearchResult]],
    catalog: Catalog | None = None,
):
    """The rows of episodes.csv (``EPISODE_COLUMNS``), episode by episode, policy by policy."""
    catalog = catalog or load_catalog()
    for i, ep in enumerate(eps):
        group = detect_group(catalog, ep.target)
        for name, rs in results.items():
            r = rs[i]
            yield {
                "style": ep.style,
                "episode": ep.index,
                "room_seed": ep.room_seed,
                "target": ep.target,
                "target_group": group,
                "start_x_m": float(ep.start.x),
                "start_y_m": float(ep.start.y),
                "start_yaw_rad": float(ep.start.yaw),
                "budget_s": float(ep.budget_s),
                "policy": name,
                "found": bool(r.found),
                "success": bool(r.success),
                "sim_s": float(r.sim_time),
                "time_to_find_s": float(r.time_to_find),
                "gazes": int(r.gazes),
                "path_m": float(r.path_m),
                "stop": r.stop,
                "mass_left": "" if r.mass_left is None else float(r.mass_left),
            }


def _episode_json(ep: Episode, i: int, results: dict[str, list[SearchResult]]) -> dict:
    """Episode ``ep`` (the i-th) and every policy's outcome on it, for search.json."""
    return {
        **ep.to_json(),
        "results": {
            n: {
                "found": rs[i].success,
                "t": round(rs[i].sim_time, 3),
                "gazes": rs[i].gazes,
                "path_m": round(rs[i].path_m, 3),
            }
            for n, rs in results.items()
        },
    }


def _write_files(run: SearchRun, out: Path, res: BenchResult) -> list[Path]:
    """Write search.json, search.md, search.png and episodes.csv of ``res`` to ``out``; their
    paths. search.json holds the run's whole configuration and the code's version: ``bench
    search --config search.json`` runs it again."""
    eps, results, stats, table = res.episodes, res.results, res.stats, res.table
    config, catalog, kb, style = run.config, run.catalog, run.priors.kb, run.style.name
    draw = res.draw or EpisodeDraw(list(eps))
    out.mkdir(parents=True, exist_ok=True)
    doc = {
        "config": to_dict(config),
        "code_version": code_version(),
        "style": style,
        "episodes": len(eps),
        "budget_s": config.budget_s,
        "seed": config.seed,
        "rank": config.knowledge.rank,
        "detector": run.detector.name,
        "interval": config.knowledge.interval,
        "map": config.scenario,  # the scenario: WorldMaps.given or WorldMaps.built
        "targets": config.targets,  # type: any instance ends a search; instance: one kept
        "room_context": config.knowledge.room_context,
        "kb": str(config.knowledge.kb) if config.knowledge.kb is not None else None,
        "kb_examinations": kb.total_examinations if kb is not None else 0,
        "failures_counted_at_budget": True,
        "excluded": draw.excluded(),
        "start_redraws": draw.start_redraws,
        "oracle_violations": sum(st.oracle_violations for st in stats.values())
        if ORACLE in stats
        else None,
        "baselines": list(baselines_of(stats)),
        "policies": {n: st.to_json() for n, st in stats.items()},
        "paired_by": paired_strata(results, res.facts, config.seed) if res.facts else {},
        "by_target": breakdown(eps, results, lambda ep: ep.target),
        "by_group": breakdown(eps, results, lambda ep: detect_group(catalog, ep.target)),
        "episode_list": [_episode_json(ep, i, results) for i, ep in enumerate(eps)],
    }
    for k, entry in doc["by_target"].items():
        entry["group"] = detect_group(catalog, k)
    k = config.knowledge
    if k.estimate != Estimate.FLAT:  # flat (the default) documents stay as they were
        doc["estimate"] = {"name": k.estimate, "min_evidence": k.min_evidence}
    files = [out / "search.json", out / "search.md", out / "search.png"]
    files[0].write_text(json.dumps(doc, indent=1) + "\n")
    kb_line = (
        f"knowledge base `{k.kb}` ({doc['kb_examinations']} examinations), "
        if kb is not None
        else ""
    )
    ex = draw.excluded()
    files[1].write_text(
        f"# Object search: {style}\n\n{kb_line}ranking by the {k.interval} interval's "
        f"`{k.rank}`"
        + (
            f" (backoff for types with < {k.min_evidence} examinations)"
            if k.estimate == Estimate.BACKOFF
            else ""
        )
        + f", detector `{doc['detector']}`, map `{doc['map']}`, "
        f"budget {config.budget_s:.0f} simulated s, seed {config.seed}.\n\n{table}\n\n"
        f"Episodes: the target not visible from the start ({draw.start_redraws} starts redrawn; "
        f"{ex['visible_at_start']} worlds dropped as visible from every start tried) and "
        f"detectable within the budget ({ex['infeasible']} worlds dropped as infeasible); "
        f"oracle violations (a policy faster than the oracle): {doc['oracle_violations']}.\n\n"
        + _stops_line(stats)
        + _breakdown_table(doc["by_group"], "target group")
        + "\n"
        + _breakdown_table(doc["by_target"], "target")
    )
    title = f"time to find ({style}, {len(eps)} paired episodes)"
    plot_cdf(results, config.budget_s, files[2], title)
    files.append(
        write_csv(out / "episodes.csv", EPISODE_COLUMNS, episode_rows(eps, results, catalog))
    )
    return files


def _stops_line(stats: dict[str, PolicyStats]) -> str:
    """A line on the early stops: per policy, the episodes it gave up before the budget and
    those with more than ``EARLY_STOP_MASS`` of its belief's detectable mass left."""
    parts = [f"{n} {st.gave_up} ({st.gave_up_with_mass})" for n, st in stats.items()]
    return (
        "Stops before the budget with nothing found (in brackets: with more than "
        f"{100 * EARLY_STOP_MASS:.0f}% of the belief's detectable mass left): "
        + ", ".join(parts)
        + ".\n\n"
    )


def _breakdown_table(rows: dict[str, dict], what: str) -> str:
    """search.md's table of a breakdown: per row, episodes and each policy's success and median
    seconds."""
    if not rows:
        return ""
    names = list(next(iter(rows.values()))["policies"])
    head = f"| {what} | n | " + " | ".join(f"{n}: success, median s" for n in names) + " |"
    lines = [head, "|---|---|" + "---|" * len(names)]
    for k, row in rows.items():
        cells = []
        for n in names:
            p = row["policies"][n]
            cells.append(f"{100 * p['success_rate']:.0f}%, {p['median_s']:.1f}")
        lines.append(f"| {k} | {row['n']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
