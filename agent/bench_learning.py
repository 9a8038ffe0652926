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
at 50, 100, 200 and 400 examinations and at equal simulated time; ``learning.png`` draws the
curves with inter-quartile bands.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from knowledge import intervals
from knowledge.catalog import Catalog
from knowledge.errors import CtxsearchError

METRICS = ("mean_width", "max_width", "mean_abs_error", "coverage")
EXAM_MARKS = (50, 100, 200, 400)
TIME_FRACTIONS = (0.25, 0.5, 1.0)  # of the shortest run's simulated time


class TruthTracker:
    """Counts for the (A, rel, B) entries that have ground truth, updated per examination, and the
    metrics of their intervals against p_true (vectorised over the entries)."""

    def __init__(self, truth: dict, catalog: Catalog, alpha: float):
        entries = [
            e
            for e in truth["entries"]
            if e["ref"] in catalog and e["type"] in catalog and catalog.has_relation(e["relation"])
        ]
        if not entries:
            raise CtxsearchError("the ground truth has no entries for this catalog")
        self.alpha = alpha
        self.p = np.array([float(e["p"]) for e in entries])
        self.key = {(e["relation"], e["type"]): i for i, e in enumerate(entries)}
        refs = sorted({e["ref"] for e in entries})
        self.by_ref = {
            r: np.array([i for i, e in enumerate(entries) if e["ref"] == r]) for r in refs
        }
        self.n = np.zeros(len(entries))
        self.y = np.zeros(len(entries))

    def record(self, ref_type: str, pairs) -> None:
        """One examination of a ``ref_type`` object that saw ``pairs`` (relation, type)."""
        idx = self.by_ref.get(ref_type)
        if idx is not None:
            self.n[idx] += 1
        for pair in set(pairs):
            i = self.key.get(pair)
            if i is not None:
                self.y[i] += 1

    def metrics(self) -> dict[str, float]:
        """mean/max width, mean |p0 - p_true| and coverage over the entries."""
        lo, hi = intervals.interval(self.y, self.n, self.alpha)
        c = intervals.p0(self.y, self.n, self.alpha)
        w = hi - lo
        return {
            "mean_width": float(w.mean()),
            "max_width": float(w.max()),
            "mean_abs_error": float(np.abs(c - self.p).mean()),
            "coverage": float(((lo <= self.p + 1e-12) & (self.p <= hi + 1e-12)).mean()),
        }


@dataclass
class Trace:
    """One (strategy, seed) run: metrics after every examination."""

    sim_s: list[float] = field(default_factory=list)
    metrics: dict[str, list[float]] = field(default_factory=lambda: {m: [] for m in METRICS})
    wall_s: float = 0.0

    def at_exam(self, k: int, metric: str) -> float:
        """The metric after examination k (1-based), or NaN past the end."""
        vals = self.metrics[metric]
        return vals[k - 1] if 0 < k <= len(vals) else float("nan")

    def at_time(self, t: float, metric: str) -> float:
        """The metric after the last examination finished by simulated second t."""
        k = int(np.searchsorted(np.asarray(self.sim_s), t, side="right"))
        return self.at_exam(k, metric) if k > 0 else float("nan")

    def exams_by(self, t: float) -> int:
        """Examinations finished by simulated second t."""
        return int(np.searchsorted(np.asarray(self.sim_s), t, side="right"))


@dataclass
class BenchResult:
    """What ``bench_learning`` wrote and the Markdown table it printed."""

    data: dict
    table: str
    files: list[Path]


def run_trace(
    style: str,
    rooms: int,
    seed: int,
    strategy: str,
    truth: dict,
    catalog: Catalog,
    perception: str,
    alpha: float,
    workdir: Path,
) -> Trace:
    """One learn run in a fresh store, measured after every examination."""
    from agent.acquisition import learn

    tracker = TruthTracker(truth, catalog, alpha)
    tr = Trace()

    def on_exam(res, kb):
        tracker.record(res.choice.obj.type, res.pairs)
        tr.sim_s.append(res.sim_time)
        for k, v in tracker.metrics().items():
            tr.metrics[k].append(v)

    t0 = time.perf_counter()
    learn(
        style,
        rooms,
        workdir / f"{strategy}-{seed}.sqlite",
        strategy=strategy,
        perception=perception,
        alpha=alpha,
        seed=seed,
        progress=False,
        catalog=catalog,
        on_examination=on_exam,
    )
    tr.wall_s = time.perf_counter() - t0
    return tr


def _median_curve(traces: list[Trace], metric: str) -> list[float]:
    k = min(len(t.sim_s) for t in traces)
    if metric == "sim_s":
        arr = np.array([t.sim_s[:k] for t in traces])
    else:
        arr = np.array([t.metrics[metric][:k] for t in traces])
    return [float(v) for v in np.median(arr, axis=0)] if k else []


def _fmt(vals: list[float], digits: int = 3) -> str:
    v = np.asarray(vals, float)
    v = v[np.isfinite(v)]
    if not len(v):
        return "-"
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    return f"{med:.{digits}f} [{q1:.{digits}f}, {q3:.{digits}f}]"


def markdown(
    style: str,
    seeds: int,
    rooms: int,
    perception: str,
    traces: dict[str, list[Trace]],
    truth_samples: int,
    alpha: float,
) -> str:
    """The tables of learning.md (medians over seeds, [IQR])."""
    names = list(traces)
    t_end = min(t.sim_s[-1] for ts in traces.values() for t in ts if t.sim_s)
    times = [f * t_end for f in TIME_FRACTIONS]
    lines = [
        f"# Learning benchmark: {style}, {rooms} rooms x {seeds} seeds, {perception} perception",
        "",
        f"Ground truth from {truth_samples} generated rooms; alpha = {alpha}. Every cell: the median "
        "over seeds [inter-quartile range]. Widths, errors and coverage are over every (A, rel, B) "
        "with ground truth.",
        "",
    ]
    titles = {
        "mean_width": "Mean interval width",
        "max_width": "Max interval width",
        "mean_abs_error": "Mean |p0 - p_true|",
        "coverage": "Coverage (share of intervals holding p_true)",
    }
    for metric in METRICS:
        lines += [
            f"## {titles[metric]}",
            "",
            "| strategy | "
            + " | ".join(f"{k} exams" for k in EXAM_MARKS)
            + " | "
            + " | ".join(f"t = {t:.0f} s" for t in times)
            + " |",
            "|---" * (1 + len(EXAM_MARKS) + len(times)) + "|",
        ]
        for n in names:
            cells = [_fmt([t.at_exam(k, metric) for t in traces[n]]) for k in EXAM_MARKS]
            cells += [_fmt([t.at_time(tt, metric) for t in traces[n]]) for tt in times]
            lines.append(f"| {n} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += [
        "## Examinations and time",
        "",
        "| strategy | sim s at "
        + " | sim s at ".join(str(k) for k in EXAM_MARKS)
        + " | "
        + " | ".join(f"exams by {t:.0f} s" for t in times)
        + " | exams in all | wall s |",
        "|---" * (2 + len(EXAM_MARKS) + len(times) + 1) + "|",
    ]
    for n in names:
        cells = [
            _fmt([t.sim_s[k - 1] if k <= len(t.sim_s) else np.nan for t in traces[n]], 0)
            for k in EXAM_MARKS
        ]
        cells += [_fmt([t.exams_by(tt) for t in traces[n]], 0) for tt in times]
        cells += [
            _fmt([len(t.sim_s) for t in traces[n]], 0),
            _fmt([t.wall_s for t in traces[n]], 1),
        ]
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot(path: Path, traces: dict[str, list[Trace]], title: str) -> None:
    """Curves (median over seeds) with inter-quartile bands: three metrics against examinations
    and the mean width against simulated time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    panels = [
        ("mean_width", "examinations", axes[0, 0]),
        ("mean_abs_error", "examinations", axes[0, 1]),
        ("coverage", "examinations", axes[1, 0]),
        ("mean_width", "time", axes[1, 1]),
    ]
    for metric, xaxis, ax in panels:
        for name, ts in traces.items():
            k = min(len(t.sim_s) for t in ts)
            if not k:
                continue
            arr = np.array([t.metrics[metric][:k] for t in ts])
            if xaxis == "examinations":
                x = np.arange(1, k + 1)
                q1, med, q3 = np.percentile(arr, [25, 50, 75], axis=0)
            else:
                t_end = min(t.sim_s[-1] for t in ts)
                x = np.linspace(0, t_end, 300)
                arr = np.array([[t.at_time(v, metric) for v in x] for t in ts])
                with warnings.catch_warnings():  # before the first examination: all NaN
                    warnings.simplefilter("ignore", RuntimeWarning)
                    q1, med, q3 = np.nanpercentile(arr, [25, 50, 75], axis=0)
            (line,) = ax.plot(x, med, label=name, lw=1.4 if name != "hif" else 2.2)
            ax.fill_between(x, q1, q3, color=line.get_color(), alpha=0.15, lw=0)
        ax.set_xlabel("examinations" if xaxis == "examinations" else "simulated seconds")
        ax.set_ylabel(metric.replace("_", " "))
        ax.grid(alpha=0.3)
        if xaxis == "examinations":
            ax.set_xscale("log")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def bench_learning(
    style: str,
    rooms: int,
    seeds: int,
    strategies: list[str],
    out: str | Path,
    perception: str = "oracle",
    truth_samples: int = 300,
    alpha: float = 0.10,
    catalog: Catalog | None = None,
    truth: dict | None = None,
    progress: bool = True,
) -> BenchResult:
    """Run the benchmark and write DIR/learning.json, DIR/learning.md and DIR/learning.png."""
    from knowledge.catalog import load_catalog

    catalog = catalog or load_catalog()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if truth is None:
        from envs.truth import ground_truth

        truth = ground_truth(style, truth_samples, 10_000_019, catalog)
    traces: dict[str, list[Trace]] = {s: [] for s in strategies}
    jobs = [(s, k) for k in range(seeds) for s in strategies]
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), unit="run", desc=f"bench learning {style}", dynamic_ncols=True)
    # Throw-away stores: on a RAM disk where there is one (no fsync per examination to wait for).
    shm = Path("/dev/shm")
    tmp_root = str(shm) if shm.is_dir() and os.access(shm, os.W_OK) else None
    with tempfile.TemporaryDirectory(prefix="ctxsearch-bench-", dir=tmp_root) as tmp:
        for s, k in jobs:
            tr = run_trace(style, rooms, k, s, truth, catalog, perception, alpha, Path(tmp))
            traces[s].append(tr)
            if bar is not None:
                bar.set_postfix_str(
                    f"{s} seed {k}: {len(tr.sim_s)} exams, {len(tr.sim_s) / max(tr.wall_s, 1e-9):.0f}/s"
                )
                bar.update(1)
    if bar is not None:
        bar.close()
    data = {
        "style": style,
        "seeds": list(range(seeds)),
        "rooms": rooms,
        "perception": perception,
        "alpha": alpha,
        "truth_samples": truth.get("samples", truth_samples),
        "strategies": {
            s: {
                "examinations": list(range(1, min(len(t.sim_s) for t in ts) + 1)),
                "sim_s": _median_curve(ts, "sim_s"),
                **{m: _median_curve(ts, m) for m in METRICS},
                "wall_s": [t.wall_s for t in ts],
            }
            for s, ts in traces.items()
        },
    }
    table = markdown(style, seeds, rooms, perception, traces, data["truth_samples"], alpha)
    files = [out / "learning.json", out / "learning.md", out / "learning.png"]
    files[0].write_text(json.dumps(data, indent=1) + "\n")
    files[1].write_text(table)
    plot(files[2], traces, f"{style}: {rooms} rooms x {seeds} seeds ({perception})")
    return BenchResult(data, table, files)
