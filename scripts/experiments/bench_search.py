"""The search benchmark: every policy on the same episodes, time to find, and the files.

Paired episodes (``episodes.make_episodes``, ``episodes.run_episodes``): the episode list is
drawn once: held-out rooms (``search.held_out_seed(seed, i)``, skipping any seed the knowledge
store learned in and rooms without a small object), a start pose (a uniformly drawn free cell,
random heading) and a target type drawn uniformly among the small (kind=object) types present in
the room. Every policy then runs every episode: the room is built once per episode and the robot
is put back at the same start pose for each policy, with a fresh seen map and nothing known.

Statistics per policy: success rate within the budget; median and mean simulated seconds to
find, **a failure counted at the budget** (so a policy that fails often cannot look fast), each
with a seeded percentile bootstrap 95% interval over episodes; mean gazes and metres driven;
the ratio of the median to ``exhaustive``'s and to ``oracle``'s (when they ran), and the paired
ratio (the median over episodes of this policy's time over exhaustive's) with its interval.

Policy names may carry a rank, ``location@low``, ``location@p0``, ``location@high``, to compare
the parts of the interval on the same episodes.

Writes ``DIR/search.json``, ``DIR/search.md`` (the table), ``DIR/search.png`` (the
time-to-find CDF of every policy) and ``DIR/search.csv`` (one row per episode and policy); with
``indirect`` and ``frontier`` also ``DIR/indirect.json`` and ``DIR/indirect.md`` (each
intermediate type's predicted gain against the measured paired ratio: bench_indirect).

The map scenario (``SearchConfig.map``, ``--map``): ``built`` (the robot knows nothing at the
start: frontier, indirect, oracle-prior-indirect, oracle) or ``given`` (the furniture poses are
known: map-only, location, oracle-prior, oracle, exhaustive); search.json's ``map`` says which.

The episodes run in batches of ``EPISODES_PER_UNIT``, the units of a sweep (``scripts.sweep``:
serially, or as Ray tasks with ``--workers N`` / ``--ray-address``); the files are the same
either way, apart from the wall time.
"""

from __future__ import annotations

import functools
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from agent import search as S
from envs.detector import DetectorModel
from envs.houses import resolve_style
from knowledge.base import KnowledgeBase
from knowledge.catalog import load_catalog
from knowledge.errors import CtxsearchError
from scripts.experiments.bench_indirect import indirect_analysis, write_indirect
from scripts.experiments.episodes import (
    Priors,
    SearchConfig,
    load_priors,
    make_episodes,
    run_episode,
    split_name,
)
from scripts.experiments.tables import write_csv
from scripts.sweep import SweepOptions, run_units

BOOTSTRAP_SAMPLES = 2000
EPISODES_PER_UNIT = 2  # episodes per sweep unit (a room is built per episode either way)


def bootstrap_ci(
    values: Sequence[float],
    stat: Callable[[np.ndarray], float] = np.median,
    samples: int = BOOTSTRAP_SAMPLES,
    seed: int = 0,
    level: float = 0.95,
) -> tuple[float, float]:
    """Percentile bootstrap interval of ``stat`` over ``values`` (seeded; (nan, nan) if empty)."""
    v = np.asarray(values, float)
    if len(v) == 0:
        return (math.nan, math.nan)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(v), size=(samples, len(v)))
    stats = np.apply_along_axis(stat, 1, v[idx])
    a = (1 - level) / 2
    return (float(np.quantile(stats, a)), float(np.quantile(stats, 1 - a)))


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
    ratio_to_exhaustive: float | None = None
    ratio_to_oracle: float | None = None
    paired_ratio: float | None = None  # median over episodes of t / t_exhaustive
    paired_ratio_ci: tuple[float, float] | None = None

    def to_json(self) -> dict:
        """The JSON entry of search.json."""

        def r(x):
            return (
                None
                if x is None or (isinstance(x, float) and not math.isfinite(x))
                else round(float(x), 4)
            )

        return {
            "success_rate": r(self.success_rate),
            "median_s": r(self.median_s),
            "median_ci": [r(self.median_ci[0]), r(self.median_ci[1])],
            "mean_s": r(self.mean_s),
            "mean_ci": [r(self.mean_ci[0]), r(self.mean_ci[1])],
            "gazes": r(self.gazes),
            "path_m": r(self.path_m),
            "ratio_to_exhaustive": r(self.ratio_to_exhaustive),
            "ratio_to_oracle": r(self.ratio_to_oracle),
            "paired_ratio_to_exhaustive": r(self.paired_ratio),
            "paired_ratio_ci": None
            if self.paired_ratio_ci is None
            else [r(v) for v in self.paired_ratio_ci],
        }


def aggregate(results: dict[str, list[S.SearchResult]], seed: int = 0) -> dict[str, PolicyStats]:
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
        )
    for ref, attr in (("exhaustive", "ratio_to_exhaustive"), ("oracle", "ratio_to_oracle")):
        if ref in out and out[ref].median_s > 0:
            for st in out.values():
                setattr(st, attr, st.median_s / out[ref].median_s)
    if "exhaustive" in results:
        te = np.array([r.time_to_find for r in results["exhaustive"]], float)
        for name, rs in results.items():
            t = np.array([r.time_to_find for r in rs], float)
            ratio = t / np.maximum(te, 1e-6)
            out[name].paired_ratio = float(np.median(ratio))
            out[name].paired_ratio_ci = bootstrap_ci(ratio, np.median, seed=seed)
    return out


@dataclass
class BenchResult:
    """What ``bench_search`` produced."""

    episodes: list[S.Episode]
    results: dict[str, list[S.SearchResult]]
    stats: dict[str, PolicyStats]
    table: str
    files: list[Path] = field(default_factory=list)
    wall_s: float = 0.0


def format_table(stats: dict[str, PolicyStats], n: int, budget_s: float) -> str:
    """The Markdown table of search.md."""
    lines = [
        "| policy | success | median s [95% CI] | mean s [95% CI] | gazes | path m | median / exhaustive "
        "| paired ratio [95% CI] | median / oracle |",
        "|---|---|---|---|---|---|---|---|---|",
    ]

    def f(x, d=1):
        return "-" if x is None or not math.isfinite(x) else f"{x:.{d}f}"

    for st in stats.values():
        pr = (
            "-"
            if st.paired_ratio is None
            else (
                f"{st.paired_ratio:.2f} [{f(st.paired_ratio_ci[0], 2)}, {f(st.paired_ratio_ci[1], 2)}]"
            )
        )
        lines.append(
            f"| {st.name} | {100 * st.success_rate:.0f}% | {f(st.median_s)} [{f(st.median_ci[0])}, "
            f"{f(st.median_ci[1])}] | {f(st.mean_s)} [{f(st.mean_ci[0])}, {f(st.mean_ci[1])}] | "
            f"{f(st.gazes)} | {f(st.path_m)} | {f(st.ratio_to_exhaustive, 2)} | {pr} | "
            f"{f(st.ratio_to_oracle, 2)} |"
        )
    lines.append("")
    lines.append(
        f"{n} paired episodes; simulated seconds to find the target, a failure counted at the "
        f"budget ({budget_s:.0f} s); 95% intervals: percentile bootstrap over episodes "
        f"({BOOTSTRAP_SAMPLES} resamples, seeded)."
    )
    return "\n".join(lines)


def plot_cdf(
    results: dict[str, list[S.SearchResult]], budget_s: float, path: Path, title: str
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


@dataclass(frozen=True)
class SearchBenchConfig(SearchConfig):
    """``bench search``: the shared search settings, the knowledge store and how many episodes."""

    kb: Path | None = None  # knowledge store made by `ctxsearch learn`
    episodes: int = 40


def bench_search(
    config: SearchBenchConfig,
    out: Path | str,
    *,
    progress: Callable[[str], None] | None = print,
    sweep: SweepOptions | None = None,
    bar: bool = True,
    kb: KnowledgeBase | None = None,
) -> BenchResult:
    """The benchmark (module docstring): run, aggregate, write the four files to ``out``.
    ``progress`` gets a line per episode and policy (in episode order, as batches finish),
    ``bar`` shows a progress bar over the sweep's units; ``kb``: the knowledge in memory
    instead of the store ``config.kb`` (``bench curve``'s empty store at k = 0)."""
    t_wall = time.perf_counter()
    catalog = load_catalog()
    names = list(config.policies)
    for n in names:
        split_name(n)
    if len(set(names)) != len(names):
        raise CtxsearchError(f"a policy is listed twice in {','.join(names)}")
    style = resolve_style(config.style, catalog)
    priors = load_priors(config, style, catalog, kb=kb, kb_path=config.kb)
    eps = make_episodes(
        style, config.episodes, config.seed, catalog, config.budget_s, exclude_seeds=priors.learned
    )
    detector = config.detector_model(catalog)
    results = _run_batches(
        eps, names, style, priors, sweep or SweepOptions(), bar, (detector, config.map)
    )
    if progress is not None:
        for i, ep in enumerate(eps):
            for n in names:
                r = results[n][i]
                progress(f"episode {ep.index} ({ep.target}, room {ep.room_seed}): {r.summary()}")
    stats = aggregate(results, seed=config.seed)
    res = BenchResult(eps, results, stats, format_table(stats, len(eps), config.budget_s))
    res.files = _write_files(config, Path(out), style.name, priors.kb, res)
    if (
        "indirect" in results and "frontier" in results
    ):  # point 7: scripts.experiments.bench_indirect
        res.files += write_indirect(Path(out), indirect_analysis(eps, results, seed=config.seed))
    res.wall_s = time.perf_counter() - t_wall
    return res


def _run_batches(
    eps: list[S.Episode],
    names: list[str],
    style,
    priors: Priors,
    sweep: SweepOptions,
    bar: bool,
    sensing: tuple[DetectorModel | None, str],
) -> dict[str, list[S.SearchResult]]:
    """Every policy on every episode, ``EPISODES_PER_UNIT`` episodes per sweep unit, with
    ``sensing``: the detector preset and the map scenario."""
    batches = [eps[i : i + EPISODES_PER_UNIT] for i in range(0, len(eps), EPISODES_PER_UNIT)]
    done = run_units(
        functools.partial(_batch_unit, tuple(names), style, priors, sensing),
        batches,
        workers=sweep.workers,
        ray_address=sweep.ray_address,
        desc=f"bench search {style.name}",
        progress=bar,
    )
    results: dict[str, list[S.SearchResult]] = {n: [] for n in names}
    for batch in done:
        for per_policy in batch:
            for n, r in zip(names, per_policy, strict=True):
                results[n].append(r)
    return results


def _batch_unit(
    names: tuple[str, ...],
    style,
    priors: Priors,
    sensing: tuple[DetectorModel | None, str],
    batch: list[S.Episode],
) -> list[list[S.SearchResult]]:
    """One sweep unit: every policy on each episode of ``batch`` (``sensing``: the detector
    preset and the map scenario)."""
    catalog = load_catalog()
    detector, map_mode = sensing
    return [
        run_episode(
            ep, names, catalog, style, priors.for_policy, detector=detector, map_mode=map_mode
        )
        for ep in batch
    ]


# search.csv: one row per episode and policy.
EPISODE_COLUMNS = (
    "style",
    "episode",
    "room_seed",
    "target",
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
)


def episode_rows(eps: Sequence[S.Episode], results: dict[str, list[S.SearchResult]]):
    """The rows of search.csv (``EPISODE_COLUMNS``), episode by episode, policy by policy."""
    for i, ep in enumerate(eps):
        for name, rs in results.items():
            r = rs[i]
            yield {
                "style": ep.style,
                "episode": ep.index,
                "room_seed": ep.room_seed,
                "target": ep.target,
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
            }


def _episode_json(ep: S.Episode, i: int, results: dict[str, list[S.SearchResult]]) -> dict:
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


def _write_files(
    config: SearchBenchConfig,
    out: Path,
    style: str,
    kb: KnowledgeBase | None,
    res: BenchResult,
) -> list[Path]:
    """Write search.json, search.md, search.png and search.csv of ``res`` to ``out``; their
    paths."""
    eps, results, stats, table = res.episodes, res.results, res.stats, res.table
    out.mkdir(parents=True, exist_ok=True)
    doc = {
        "style": style,
        "episodes": len(eps),
        "budget_s": config.budget_s,
        "seed": config.seed,
        "rank": config.rank,
        "detector": config.detector_model(load_catalog()).name,
        "interval": config.interval,
        "map": config.map,  # the scenario: RoomMaps.given or RoomMaps.built
        "kb": str(config.kb) if config.kb is not None else None,
        "kb_examinations": kb.total_examinations if kb is not None else 0,
        "failures_counted_at_budget": True,
        "policies": {n: st.to_json() for n, st in stats.items()},
        "episode_list": [_episode_json(ep, i, results) for i, ep in enumerate(eps)],
    }
    if config.estimate != "flat":  # flat (the default) documents stay as they were
        doc["estimate"] = {"name": config.estimate, "min_evidence": config.min_evidence}
    files = [out / "search.json", out / "search.md", out / "search.png"]
    files[0].write_text(json.dumps(doc, indent=1) + "\n")
    kb_line = (
        f"knowledge base `{config.kb}` ({doc['kb_examinations']} examinations), "
        if kb is not None
        else ""
    )
    files[1].write_text(
        f"# Object search: {style}\n\n{kb_line}ranking by the {config.interval} interval's "
        f"`{config.rank}`"
        + (
            f" (backoff for types with < {config.min_evidence} examinations)"
            if config.estimate == "backoff"
            else ""
        )
        + f", detector `{doc['detector']}`, "
        f"budget {config.budget_s:.0f} simulated s, seed {config.seed}.\n\n{table}\n"
    )
    title = f"time to find ({style}, {len(eps)} paired episodes)"
    plot_cdf(results, config.budget_s, files[2], title)
    files.append(write_csv(out / "search.csv", EPISODE_COLUMNS, episode_rows(eps, results)))
    return files
