"""``bench home``: the changing home. A robot that lives in a house knows it (its remembered map,
agent.search.remembered) and where it saw things (agent.search.memory); it is asked for a type on
a day after its map was made, for objects that may or may not have moved since.

For each gap in days between the robot's map and the query (``--days-after``: 1, 2, 4 by
default, the curve), ``bench search`` runs on the remembered map (``map.days_after`` = the gap)
with the arms side by side on the same episodes: ``uniform`` (the twin), ``memory`` (memory
only), ``location`` (relations only), ``memory-location`` (both), ``oracle-memory`` (the world's
persistence and the true relations: the bound) and ``oracle``. The draw is split: half the
queries for a type an instance of which stands where one stood on the map's day ("stayed"), half
for a type none of which does ("moved"), the Dynamic House Simulator's protocol (Kurenkov et
al., 2023), judged from the true worlds (agent.search.draw's ``split``).

Per gap: each arm against ``uniform``, and ``memory-location`` against ``memory``,
``location`` and the better of the two (the one with the lower geometric mean against
``uniform``), with the geometric mean of the paired ratio and its interval, wins/losses/ties,
the signed-rank p and n; the same within the stayed and the moved queries. And the learned
persistence per type beside the world's (``persistence``: the store's intervals, whether they
hold the measured share, envs.truth's ``still_where_seen``).

Writes ``DIR/home.json``, ``DIR/home.md`` and every gap's ``bench search`` files in
``DIR/d=GAP/``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ctxsearch.agent.search.config import SearchConfig, to_dict
from ctxsearch.agent.search.measures import geo_cell
from ctxsearch.agent.search.registry import default_policies
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import MapMode
from ctxsearch.scripts.experiments.bench_search import BenchResult, bench_search, paired_strata
from ctxsearch.scripts.sweep import SweepOptions

ARMS = default_policies(MapMode.REMEMBERED)  # the remembered map's default policies
CONTEXT = "memory-location"


@dataclass
class HomeResult:
    """What ``bench_home`` produced."""

    gaps: dict[int, BenchResult]
    summary: dict
    table: str
    files: list[Path] = field(default_factory=list)
    wall_s: float = 0.0


def bench_home(
    config: SearchConfig,
    out: Path | str,
    gaps: Sequence[int],
    *,
    progress: Callable[[str], None] | None = None,
    sweep: SweepOptions | None = None,
    bar: bool = True,
) -> HomeResult:
    """The benchmark (module docstring) of ``config`` (its policies: ``ARMS`` unless named) at
    every gap of ``gaps``; files in ``out``."""
    t0 = time.perf_counter()
    if config.knowledge.kb is None:
        raise CtxsearchError("bench home: --kb is required (a store learned over days)")
    if not gaps or any(g < 1 for g in gaps):
        raise CtxsearchError("bench home: --days-after takes whole days >= 1")
    out = Path(out)
    config = config.with_scenario(MapMode.REMEMBERED)
    if not config.policies:
        config = config.updated({"policies": ",".join(ARMS)}, "--policies")
    results: dict[int, BenchResult] = {}
    for g in sorted(set(gaps)):
        c = config.updated({"map.days_after": g}, "--days-after")
        results[g] = bench_search(
            c, out / f"d={g}", progress=progress, sweep=sweep, bar=bar, split=True
        )
    summary = {
        "benchmark": "home",
        "config": to_dict(results[min(results)].config or config),
        "gaps": {str(g): gap_summary(r) for g, r in results.items()},
    }
    table = home_table(summary)
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "home.json", out / "home.md"]
    files[0].write_text(json.dumps(summary, indent=1) + "\n")
    files[1].write_text(table + "\n")
    for r in results.values():
        files += r.files
    return HomeResult(results, summary, table, files, time.perf_counter() - t0)


def gap_summary(res: BenchResult) -> dict:
    """One gap's comparisons (module docstring) from its ``bench search`` result."""
    stats = res.stats
    eps = res.episodes
    out: dict = {
        "episodes": len(eps),
        "stayed": sum(bool(e.stayed) for e in eps),
        "moved": sum(e.stayed is False for e in eps),
        "success": {n: round(s.success_rate, 4) for n, s in stats.items()},
        "vs_uniform": {
            n: s.paired_stats["uniform"].to_json()
            for n, s in stats.items()
            if "uniform" in s.paired_stats
        },
    }
    if CONTEXT in stats:
        ctx = stats[CONTEXT].paired_stats
        parts = [p for p in ("memory", "location") if p in ctx]
        out["context_vs"] = {p: ctx[p].to_json() for p in parts + ["oracle-memory"] if p in ctx}
        vs_u = out["vs_uniform"]
        if parts and all(p in vs_u for p in parts):
            better = min(parts, key=lambda p: vs_u[p]["geo_mean"])
            out["better_part"] = better
    seed = res.config.seed if res.config is not None else 0
    out["by_memory"] = paired_strata(res.results, res.facts, seed).get("memory", {})
    return out


def home_table(summary: dict) -> str:
    """home.md: per gap, the arms against ``uniform`` and the context arm against its parts."""
    lines = ["# The changing home", ""]
    for g, s in summary["gaps"].items():
        lines += [
            f"## {g} day(s) after the robot's map: {s['episodes']} queries "
            f"({s['stayed']} stayed, {s['moved']} moved)",
            "",
            "| policy | vs uniform: geometric mean [95% CI] w/l/t p | success |",
            "|---|---|---|",
        ]
        for n, r in s["vs_uniform"].items():
            lines.append(f"| {n} | {geo_cell(r)} | {100 * s['success'][n]:.0f}% |")
        if "context_vs" in s:
            lines += ["", f"| {CONTEXT} against | geometric mean [95% CI] w/l/t p |", "|---|---|"]
            for p, r in s["context_vs"].items():
                mark = " (the better part)" if p == s.get("better_part") else ""
                lines.append(f"| {p}{mark} | {geo_cell(r)} |")
        for kind, cell in s.get("by_memory", {}).items():
            lines += ["", f"Queries whose target {kind} ({cell['n']}):", ""]
            lines += ["| policy | vs uniform | vs location |", "|---|---|---|"]
            for n in ARMS:
                if n in cell and n != "uniform":
                    u = cell[n].get("uniform")
                    loc = cell[n].get("location")
                    lines.append(
                        f"| {n} | {geo_cell(u) if u else '-'} | {geo_cell(loc) if loc else '-'} |"
                    )
        lines.append("")
    lines.append(
        "Per query, the policy's simulated seconds to find over the baseline's on the same "
        "episode (failures at the budget); geometric mean with a percentile bootstrap interval, "
        "wins/losses/ties, Wilcoxon signed-rank p. Stayed: an instance of the target stands "
        "within the persistence radius of where one stood on the day of the robot's map."
    )
    return "\n".join(lines)
