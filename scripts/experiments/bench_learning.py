"""``ctxsearch bench learning``: does Highest Impact First learn faster than the alternatives?

Every strategy runs ``learn`` on the same rooms (room seeds derive from the run seed) for every
seed, in a temporary store. After every examination the intervals of every (A, rel, B) that has
ground truth (``envs.truth.ground_truth``, estimated over generated rooms with the robot's own
geometry) are compared with it:

- mean and max interval width,
- mean |p0 - p_true| (p0: the interval's centre, eq. 1),
- coverage_informative: the share of intervals that hold p_true among the entries that carry
  information (n_A >= 1 and 0.02 <= p_true <= 0.98; nominally 1 - alpha, but examinations in one
  room are not independent trials and HIF picks what it examines, so it is measured, not assumed),
- coverage: the same share over every entry (inflated: an entry with p_true = 0 or one never
  examined cannot miss),

``interval`` 'clustered' measures the clustered intervals (knowledge.clustered: Wilson on a
room-level effective sample size) and keeps the paper's Wilson figures beside them
(``wilson_mean_width``, ``wilson_mean_abs_error``, ``wilson_coverage_informative``), and notes per
choice whether HIF on the effective counts would pick the same type (``effective_same_hif``).
Camera perception uses ``detector`` (default realistic); every result names it.
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

import functools
import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

from ctxsearch.agent.mapping import default_map_mode
from ctxsearch.agent.perception_modes import DEFAULT_DETECTOR
from ctxsearch.envs.detector import default_or_named
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.truth import sample_counts, truth_document
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.options import IntervalMethod, PerceptionMode
from ctxsearch.scripts.experiments.learning_report import decision_stats, fmt, markdown, plot
from ctxsearch.scripts.experiments.learning_trace import (
    EXAM_MARKS,
    METRICS,
    WILSON_METRICS,
    LearningBenchConfig,
    Trace,
    median_curve,
    run_trace,
)
from ctxsearch.scripts.experiments.tables import write_csv
from ctxsearch.scripts.sweep import SweepOptions, run_units, session

TRUTH_SEED = 10_000_019  # first room seed of the ground truth (no learning run uses it)
TRUTH_ROOMS_PER_UNIT = 10  # rooms of the ground truth per sweep unit


@dataclass
class BenchResult:
    """What ``bench_learning`` wrote and the Markdown table it printed."""

    data: dict
    table: str
    files: list[Path]


def bench_learning(
    config: LearningBenchConfig,
    out: str | Path,
    progress: bool = True,
    sweep: SweepOptions | None = None,
) -> BenchResult:
    """Run the benchmark and write DIR/learning.json, DIR/learning.md, DIR/learning.png and
    DIR/learning.csv (one row per examination of every run, ``exam_rows``); the (strategy, seed)
    runs are the sweep's units (serial, or Ray tasks with ``sweep.workers``)."""
    catalog = load_catalog()
    if (
        config.perception == PerceptionMode.CAMERA
    ):  # a bad preset: the one-line error before any run
        default_or_named(config.detector, catalog, DEFAULT_DETECTOR)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    sweep = sweep or SweepOptions()
    with session(sweep):  # one Ray for both sweeps
        truth = ground_truth_units(config.style, config.truth_samples, catalog, sweep, progress)
        traces = _run_all(config, truth, catalog, progress, sweep)
    data = _data(config, truth, traces)
    c = config
    title = (
        f"Learning benchmark: {c.style}, {c.rooms} rooms x {c.seeds} seeds, {c.perception} "
        f"perception{c.budget_note}, detector {c.detector_name}, {c.interval} intervals"
    )
    table = markdown(title, traces, data["truth_samples"], c.alpha, c.room_budget_s)
    if c.interval == IntervalMethod.CLUSTERED:
        table += _wilson_beside(traces)
    files = [out / "learning.json", out / "learning.md", out / "learning.png"]
    files[0].write_text(json.dumps(data, indent=1) + "\n")
    files[1].write_text(table)
    plot_title = f"{c.style}: {c.rooms} rooms x {c.seeds} seeds ({c.perception}{c.budget_note})"
    plot(files[2], traces, plot_title)
    files.append(write_csv(out / "learning.csv", EXAM_COLUMNS, exam_rows(config, traces)))
    return BenchResult(data, table, files)


# learning.csv: one row per examination of every (strategy, seed) run.
EXAM_COLUMNS = (
    "style",
    "perception",
    "strategy",
    "seed",
    "examination",  # 1-based, over the run
    "room",  # 0-based index of the room it was made in
    "sim_s",  # the run clock after it, simulated seconds
    *METRICS,  # of the intervals against the ground truth after it
)


def exam_rows(config: LearningBenchConfig, traces: dict[str, list[Trace]]):
    """The rows of learning.csv (``EXAM_COLUMNS``), strategy by strategy, seed by seed."""
    for strategy, ts in traces.items():
        for seed, tr in enumerate(ts):
            rooms = [i for i, n in enumerate(tr.room_exams) for _ in range(n)]
            for k, t in enumerate(tr.sim_s):
                yield {
                    "style": config.style,
                    "perception": config.perception,
                    "strategy": strategy,
                    "seed": seed,
                    "examination": k + 1,
                    "room": rooms[k],
                    "sim_s": float(t),
                    **{m: float(tr.metrics[m][k]) for m in METRICS},
                }


def ground_truth_units(
    style_name: str, samples: int, catalog: Catalog, sweep: SweepOptions, progress: bool
) -> dict:
    """``envs.truth.ground_truth`` of ``style_name`` over ``samples`` rooms from ``TRUTH_SEED``,
    its rooms counted in sweep units of ``TRUTH_ROOMS_PER_UNIT`` (the same document as the
    serial call)."""
    style = resolve_style(style_name, catalog)
    seeds = list(range(TRUTH_SEED, TRUTH_SEED + samples))
    chunks = [
        seeds[i : i + TRUTH_ROOMS_PER_UNIT] for i in range(0, len(seeds), TRUTH_ROOMS_PER_UNIT)
    ]
    parts = run_units(
        functools.partial(sample_counts, style, catalog=catalog),
        chunks,
        workers=sweep.workers,
        ray_address=sweep.ray_address,
        desc=f"ground truth {style.name}",
        progress=progress,
    )
    rooms = [c for part in parts for c in part]
    return truth_document(style, samples, TRUTH_SEED, catalog, rooms)


def _run_all(
    config: LearningBenchConfig,
    truth: dict,
    catalog: Catalog,
    progress: bool,
    sweep: SweepOptions,
) -> dict[str, list[Trace]]:
    """Every strategy's trace for every seed (seed-major order), one sweep unit per run."""
    jobs = [(s, k) for k in range(config.seeds) for s in config.strategies]
    results = run_units(
        functools.partial(_trace_unit, config, truth, catalog),
        jobs,
        workers=sweep.workers,
        ray_address=sweep.ray_address,
        desc=f"bench learning {config.style}",
        progress=progress,
    )
    traces: dict[str, list[Trace]] = {s: [] for s in config.strategies}
    for (s, _), tr in zip(jobs, results, strict=True):
        traces[s].append(tr)
    return traces


def _trace_unit(
    config: LearningBenchConfig, truth: dict, catalog: Catalog, job: tuple[str, int]
) -> Trace:
    """One sweep unit: ``run_trace`` of (strategy, seed) in a throw-away store, on a RAM disk
    where there is one (no fsync per examination to wait for)."""
    strategy, seed = job
    shm = Path("/dev/shm")
    tmp_root = str(shm) if shm.is_dir() and os.access(shm, os.W_OK) else None
    with tempfile.TemporaryDirectory(prefix="ctxsearch-bench-", dir=tmp_root) as tmp:
        return run_trace(config, seed, strategy, truth, catalog, Path(tmp))


def _data(config: LearningBenchConfig, truth: dict, traces: dict[str, list[Trace]]) -> dict:
    """learning.json: the settings and, per strategy, the median curves and per-seed figures."""
    return {
        "style": config.style,
        "seeds": list(range(config.seeds)),
        "rooms": config.rooms,
        "perception": config.perception,
        "alpha": config.alpha,
        "room_budget_s": config.room_budget_s,
        "detector": config.detector_name,
        "map": default_map_mode(config.perception),  # the grid the runs planned on
        "interval": config.interval,
        "confirm": config.confirm,
        "min_score": config.min_score,
        "truth_samples": truth.get("samples", config.truth_samples),
        "strategies": {
            s: {
                "examinations": list(range(1, min(len(t.sim_s) for t in ts) + 1)),
                "sim_s": median_curve(ts, "sim_s"),
                **{m: median_curve(ts, m) for m in METRICS},
                **(
                    {m: median_curve(ts, m) for m in WILSON_METRICS}
                    | {"effective_same_hif": _share([x for t in ts for x in t.effective_same])}
                    if config.interval == IntervalMethod.CLUSTERED
                    else {}
                ),
                "wall_s": [t.wall_s for t in ts],
                "examined_share": [t.examined_shares() for t in ts],  # per seed, per room
                "rooms_left_early": [t.rooms_left_early for t in ts],
                "decisions": {k: float(v) for k, v in decision_stats(ts).items()},
            }
            for s, ts in traces.items()
        },
    }


def _wilson_beside(traces: dict[str, list[Trace]]) -> str:
    """learning.md's section under --interval clustered: clustered against the paper's Wilson on
    the same evidence at the examination marks, and how often HIF on the effective counts picks
    what HIF picks."""
    lines = [
        "",
        "## Clustered against Wilson (same evidence)",
        "",
        "| strategy | figure | " + " | ".join(f"{k} exams" for k in EXAM_MARKS) + " |",
        "|---" * (2 + len(EXAM_MARKS)) + "|",
    ]
    pairs = (
        ("coverage_informative", "wilson_coverage_informative"),
        ("mean_width", "wilson_mean_width"),
        ("mean_abs_error", "wilson_mean_abs_error"),
    )
    for name, ts in traces.items():
        for clustered, wilson in pairs:
            for label, key in (
                (f"{clustered} clustered", clustered),
                (f"{clustered} wilson", wilson),
            ):
                cells = [fmt([t.at_exam(k, key) for t in ts]) for k in EXAM_MARKS]
                lines.append(f"| {name} | {label} | " + " | ".join(cells) + " |")
        same = _share([x for t in ts for x in t.effective_same])
        if same is not None:
            lines.append(f"| {name} | HIF on effective counts picks the same type | {same:.1%} |")
    return "\n".join(lines) + "\n"


def _share(flags: list[bool]) -> float | None:
    """The share of True among ``flags`` (None if empty)."""
    return float(sum(flags) / len(flags)) if flags else None
