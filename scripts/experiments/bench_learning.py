"""``ctxsearch bench learning``: does Highest Impact First learn faster than the alternatives?

Every strategy runs ``learn`` on the same rooms (room seeds derive from the run seed) for every
seed, in a temporary store. After every examination the intervals of every (A, rel, B) that has
ground truth (``envs.truth.ground_truth``, estimated over generated rooms with the robot's own
geometry) are compared with it:

- mean and max interval width,
- mean |p0 - p_true| (p0: the interval's centre, eq. 1),
- coverage: the share of intervals that hold p_true (nominally 1 - alpha, but examinations in one
  room are not independent trials and HIF picks what it examines, so it is measured, not assumed),
- simulated seconds (the run clock of the time model).

Per strategy, each list in ``learning.json`` is the median over seeds at every examination count
(as far as every seed got). ``learning.md`` tabulates the medians with their inter-quartile range
at 10, 25, 50, 100, 200 and 400 examinations and at equal simulated time, the paired (same rooms,
same seed) difference of every strategy's mean width from HIF's, the averages over the whole run,
and how the strategies' decisions relate: how often a pick agrees with what hif, expected-hif and
fewest would pick from the same knowledge, and how often HIF's pick can only come from the quirk
of eq. 3 (impact(0, n) is not monotonic in n). ``learning.png`` draws the curves with
inter-quartile bands.

``room_budget_s`` gives every room a simulated-time budget (agent.learning): the robot leaves a
room when it is spent, so the strategies examine different objects, not only the same objects in
another order. Then ``learning.md`` opens with a generated "Reading": the share of each room's
objects examined, and every strategy's mean width minus HIF's (paired per seed) at marks in
examinations and simulated time and averaged over the run, with the number of seeds where HIF is
ahead. The time-averaged width is the mean over a uniform grid of simulated seconds from 0 to the
shortest run's end (before the first examination: the width of the empty knowledge).
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from envs.truth import ground_truth
from knowledge.catalog import Catalog, load_catalog
from scripts.experiments.learning_report import decision_stats, markdown, plot
from scripts.experiments.learning_trace import (
    METRICS,
    LearningBenchConfig,
    Trace,
    median_curve,
    run_trace,
)

TRUTH_SEED = 10_000_019  # first room seed of the ground truth (no learning run uses it)


@dataclass
class BenchResult:
    """What ``bench_learning`` wrote and the Markdown table it printed."""

    data: dict
    table: str
    files: list[Path]


def bench_learning(
    config: LearningBenchConfig, out: str | Path, progress: bool = True
) -> BenchResult:
    """Run the benchmark and write DIR/learning.json, DIR/learning.md and DIR/learning.png."""
    catalog = load_catalog()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    truth = ground_truth(config.style, config.truth_samples, TRUTH_SEED, catalog)
    traces = _run_all(config, truth, catalog, progress)
    data = _data(config, truth, traces)
    c = config
    title = (
        f"Learning benchmark: {c.style}, {c.rooms} rooms x {c.seeds} seeds, {c.perception} "
        f"perception{c.budget_note}"
    )
    table = markdown(title, traces, data["truth_samples"], c.alpha, c.room_budget_s)
    files = [out / "learning.json", out / "learning.md", out / "learning.png"]
    files[0].write_text(json.dumps(data, indent=1) + "\n")
    files[1].write_text(table)
    plot_title = f"{c.style}: {c.rooms} rooms x {c.seeds} seeds ({c.perception}{c.budget_note})"
    plot(files[2], traces, plot_title)
    return BenchResult(data, table, files)


def _run_all(
    config: LearningBenchConfig, truth: dict, catalog: Catalog, progress: bool
) -> dict[str, list[Trace]]:
    """Every strategy's trace for every seed (seed-major order)."""
    traces: dict[str, list[Trace]] = {s: [] for s in config.strategies}
    jobs = [(s, k) for k in range(config.seeds) for s in config.strategies]
    bar = None
    if progress:
        desc = f"bench learning {config.style}"
        bar = tqdm(total=len(jobs), unit="run", desc=desc, dynamic_ncols=True)
    # Throw-away stores: on a RAM disk where there is one (no fsync per examination to wait for).
    shm = Path("/dev/shm")
    tmp_root = str(shm) if shm.is_dir() and os.access(shm, os.W_OK) else None
    with tempfile.TemporaryDirectory(prefix="ctxsearch-bench-", dir=tmp_root) as tmp:
        for s, k in jobs:
            tr = run_trace(config, k, s, truth, catalog, Path(tmp))
            traces[s].append(tr)
            if bar is not None:
                bar.set_postfix_str(
                    f"{s} seed {k}: {len(tr.sim_s)} exams, {len(tr.sim_s) / max(tr.wall_s, 1e-9):.0f}/s"
                )
                bar.update(1)
    if bar is not None:
        bar.close()
    return traces


def _data(config: LearningBenchConfig, truth: dict, traces: dict[str, list[Trace]]) -> dict:
    """learning.json: the settings and, per strategy, the median curves and per-seed figures."""
    return {
        "style": config.style,
        "seeds": list(range(config.seeds)),
        "rooms": config.rooms,
        "perception": config.perception,
        "alpha": config.alpha,
        "room_budget_s": config.room_budget_s,
        "truth_samples": truth.get("samples", config.truth_samples),
        "strategies": {
            s: {
                "examinations": list(range(1, min(len(t.sim_s) for t in ts) + 1)),
                "sim_s": median_curve(ts, "sim_s"),
                **{m: median_curve(ts, m) for m in METRICS},
                "wall_s": [t.wall_s for t in ts],
                "examined_share": [t.examined_shares() for t in ts],  # per seed, per room
                "rooms_left_early": [t.rooms_left_early for t in ts],
                "decisions": {k: float(v) for k, v in decision_stats(ts).items()},
            }
            for s, ts in traces.items()
        },
    }
