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
hold the share measured in sample worlds of the style over the days the robot checked:
``persistence_coverage``).

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
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.truth import near_counts
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import MapMode
from ctxsearch.knowledge.persistence import near_place, store_persistence
from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.experiments.bench_search import BenchResult, bench_search, paired_strata
from ctxsearch.scripts.sweep import SweepOptions

ARMS = default_policies(MapMode.REMEMBERED)  # the remembered map's default policies
CONTEXT = "memory-location"
PERSISTENCE_WORLDS = 60  # sample worlds of the truth's persistence (persistence_coverage)


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
    first = results[min(results)]
    summary = {
        "benchmark": "home",
        "config": to_dict(first.config or config),
        "gaps": {str(g): gap_summary(r) for g, r in results.items()},
        "persistence": persistence_coverage(first, PERSISTENCE_WORLDS),
    }
    table = home_table(summary)
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "home.json", out / "home.md"]
    files[0].write_text(json.dumps(summary, indent=1) + "\n")
    files[1].write_text(table + "\n")
    for r in results.values():
        files += r.files
    return HomeResult(results, summary, table, files, time.perf_counter() - t0)


def persistence_coverage(res: BenchResult, worlds: int) -> dict:
    """The store's learned one-day persistence per type against the truth (module docstring).
    ``true``: over the places the robot's maps remembered a small object on one day and a map
    of the next day exists (the places its checks were drawn from), the share where an instance
    of the type stood within the radius on that next day in the true world: the value the
    checks estimate, without the detector. ``true_all``: the same share over every instance of
    ``worlds`` sample worlds of the style (seeds 0 .. worlds-1) from day 0 to the store's
    latest map day (objects the robot never remembers included: clutter wanders more). An
    interval ``covered`` its type's ``true``."""
    c = res.config
    assert c is not None and c.knowledge.kb is not None
    catalog = load_catalog()
    style = resolve_style(c.style, catalog)
    places: dict[str, list[int]] = {}
    with EvidenceStore.open(Path(c.knowledge.kb), catalog, read_only=True) as store:
        learned = store_persistence(store)
        visits = [v for v in store.home_maps() if v[1] == style.name]
        last = max((d for *_, d in visits), default=1)
        for run, st, seed, day in visits:
            prev = store.home_map(st, seed, run, upto_day=day - 1) if day else None
            if prev is None or prev.day != day - 1:
                continue
            world = generate_layout(style, seed, catalog, day=day)
            for o in prev.small:
                acc = places.setdefault(o.type, [0, 0])
                acc[0] += 1
                acc[1] += near_place(o.position, world.objects, o.type)
    every = near_counts(style, catalog, worlds, last)
    rows = []
    for t in sorted(set(every) | set(places)):
        n, near = places.get(t, (0, 0))
        n_all, near_all = every.get(t, (0, 0))
        row = {"type": t, "true": near / n if n else None, "places": n,
               "true_all": near_all / n_all if n_all else None, "instances": n_all}  # fmt: skip
        e = learned.estimate(t, 1)
        if e is not None:
            row |= {"low": e.low, "high": e.high, "p": e.p, "checks": e.checks}
            if row["true"] is not None:
                row["covered"] = e.low <= row["true"] <= e.high
        rows.append(row)
    judged = [r for r in rows if "covered" in r]
    return {
        "worlds": worlds, "days": [0, max(last, 1)], "types": rows,
        "covered": sum(r["covered"] for r in judged), "judged": len(judged),
    }  # fmt: skip


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
    pc = summary.get("persistence")
    if pc:
        lines += [
            f"## Learned persistence against the worlds' ({pc['covered']} of {pc['judged']} "
            f"types covered; truth: {pc['worlds']} worlds, days {pc['days'][0]}-{pc['days'][1]})",
            "",
            "| type | learned P(STILL-WHERE-SEEN after 1 day) | checks | true at the remembered "
            "places (places) | covered | true over every instance |",
            "|---|---|---|---|---|---|",
        ]

        def f(x):
            return "-" if x is None else f"{x:.3f}"

        for r in pc["types"]:
            learned = f"[{r['low']:.3f}, {r['high']:.3f}]" if r.get("checks") else "-"
            cov = {True: "yes", False: "no"}.get(r.get("covered"), "-")
            lines.append(
                f"| {r['type']} | {learned} | {r.get('checks', 0)} | {f(r['true'])} "
                f"({r['places']}) | {cov} | {f(r['true_all'])} |"
            )
        lines.append("")
    lines.append(
        "Per query, the policy's simulated seconds to find over the baseline's on the same "
        "episode (failures at the budget); geometric mean with a percentile bootstrap interval, "
        "wins/losses/ties, Wilcoxon signed-rank p. Stayed: an instance of the target stands "
        "within the persistence radius of where one stood on the day of the robot's map."
    )
    return "\n".join(lines)
