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

``room_budget_s`` gives every room a simulated-time budget (agent.acquisition): the robot leaves a
room when it is spent, so the strategies examine different objects, not only the same objects in
another order. Then ``learning.md`` opens with a generated "Reading": the share of each room's
objects examined, and every strategy's mean width minus HIF's (paired per seed) at marks in
examinations and simulated time and averaged over the run, with the number of seeds where HIF is
ahead. The time-averaged width is the mean over a uniform grid of simulated seconds from 0 to the
shortest run's end (before the first examination: the width of the empty knowledge).
"""

from __future__ import annotations

import json
import math
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
EXAM_MARKS = (10, 25, 50, 100, 200, 400)
TIME_FRACTIONS = (0.25, 0.5, 1.0)  # of the shortest run's simulated time
WIDTH_GOALS = (0.6, 0.5, 0.4, 0.3)  # mean widths whose first simulated second is tabulated
TIME_GRID = 400  # points of the simulated-time grid for time averages


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
    initial: dict[str, float] = field(default_factory=dict)  # before any examination
    room_objects: list[int] = field(default_factory=list)  # objects in room i
    room_exams: list[int] = field(default_factory=list)  # examinations made in room i
    rooms_left_early: int = 0  # rooms the time budget ended
    # One row per choice among at least two candidate types: does the pick agree with what
    # hif, expected-hif and fewest would pick from the same knowledge; was a less-examined type
    # on offer; and was it a quirk pick: the pick's n is larger than the least-examined
    # candidate's, yet impact(0, n) - the term that dominates the average, most y being 0 -
    # is larger for it (eq. 3 is not monotonic in n).
    decisions: list[tuple[bool, bool, bool, bool, bool]] = field(default_factory=list)

    def at_exam(self, k: int, metric: str) -> float:
        """The metric after examination k (1-based), or NaN past the end."""
        vals = self.metrics[metric]
        return vals[k - 1] if 0 < k <= len(vals) else float("nan")

    def at_time(self, t: float, metric: str) -> float:
        """The metric after the last examination finished by simulated second t (before the
        first one: its value for the empty knowledge, NaN if that was not recorded)."""
        k = int(np.searchsorted(np.asarray(self.sim_s), t, side="right"))
        return self.at_exam(k, metric) if k > 0 else self.initial.get(metric, float("nan"))

    def time_mean(self, t_end: float, metric: str) -> float:
        """The metric averaged over simulated time 0..t_end (a uniform grid)."""
        return float(np.mean([self.at_time(t, metric) for t in np.linspace(0, t_end, TIME_GRID)]))

    def time_to(self, goal: float, metric: str = "mean_width") -> float:
        """The simulated second the metric first reaches ``goal`` or below (NaN: never)."""
        vals = np.asarray(self.metrics[metric])
        hit = np.flatnonzero(vals <= goal)
        return float(self.sim_s[hit[0]]) if len(hit) else float("nan")

    def examined_shares(self) -> list[float]:
        """Per room: examinations over the objects in the room."""
        return [e / o for e, o in zip(self.room_exams, self.room_objects, strict=False) if o]

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
    room_budget_s: float | None = None,
) -> Trace:
    """One learn run in a fresh store, measured after every examination."""
    from agent.learning import LearnConfig, learn, style_layouts

    tracker = TruthTracker(truth, catalog, alpha)
    tr = Trace(initial=tracker.metrics())
    style, generate = style_layouts(style, catalog)

    def layouts(index, seed):
        layout = generate(index, seed)
        while len(tr.room_objects) <= index:
            tr.room_objects.append(0)
            tr.room_exams.append(0)
        tr.room_objects[index] = len(layout.objects)
        return layout

    order = {t: i for i, t in enumerate(catalog.type_names)}

    def on_choice(kb, choice):
        types = sorted(choice.scores, key=order.__getitem__)
        if len(types) < 2:
            return
        hif = kb.choose(types)
        exp = kb.choose(types, fn=intervals.expected_width_change)
        few = min(types, key=lambda t: (kb.n(t), order[t]))
        c = choice.type
        n_min = min(kb.n(t) for t in types)
        n_c = kb.n(c)
        better_known = n_c > n_min
        quirk = better_known and float(intervals.impact(0, n_c, kb.alpha)) > float(
            intervals.impact(0, n_min, kb.alpha)
        )
        tr.decisions.append((c == hif, c == exp, c == few, better_known, quirk))

    def on_exam(res, kb):
        tr.room_exams[res.room_index] += 1
        tracker.record(res.choice.obj.type, res.pairs)
        tr.sim_s.append(res.sim_time)
        for k, v in tracker.metrics().items():
            tr.metrics[k].append(v)

    t0 = time.perf_counter()
    summary = learn(
        LearnConfig(
            style,
            rooms,
            workdir / f"{strategy}-{seed}.sqlite",
            strategy=strategy,
            perception=perception,
            alpha=alpha,
            seed=seed,
            progress=False,
            room_budget_s=room_budget_s,
        ),
        catalog=catalog,
        layouts=layouts,
        on_examination=on_exam,
        on_choice=on_choice,
    )
    tr.wall_s = time.perf_counter() - t0
    tr.rooms_left_early = summary.rooms_left_early
    return tr


def _median_curve(traces: list[Trace], metric: str) -> list[float]:
    k = min(len(t.sim_s) for t in traces)
    if metric == "sim_s":
        arr = np.array([t.sim_s[:k] for t in traces])
    else:
        arr = np.array([t.metrics[metric][:k] for t in traces])
    return [float(v) for v in np.median(arr, axis=0)] if k else []


def _fmt(vals, digits: int = 3, sign: bool = False) -> str:
    v = np.asarray(vals, float)
    v = v[np.isfinite(v)]
    if not len(v):
        return "-"
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    f = f"{{:{'+' if sign else ''}.{digits}f}}"
    return f"{f.format(med)} [{f.format(q1)}, {f.format(q3)}]"


def _run_mean(t: Trace, metric: str, k: int) -> float:
    """The metric averaged over examinations 1..k (the area under its curve, per examination)."""
    return float(np.mean(t.metrics[metric][:k])) if k else float("nan")


def _decision_stats(ts: list[Trace]) -> dict[str, float]:
    rows = [d for t in ts for d in t.decisions]
    n = len(rows)
    a = np.array(rows, bool).reshape(-1, 5)
    keys = ("same_hif", "same_expected", "same_fewest", "better_known", "quirk")
    return {
        "choices": n,
        **{k: float(a[:, i].mean()) if n else float("nan") for i, k in enumerate(keys)},
    }


def _ahead(diffs) -> str:
    """'k/n': the seeds where the paired difference is positive (the reference is ahead)."""
    v = np.asarray(diffs, float)
    v = v[np.isfinite(v)]
    return f"{int((v > 1e-12).sum())}/{len(v)}"


def _shares(ts: list[Trace]) -> list[float]:
    return [x for t in ts for x in t.examined_shares()]


def reading(
    traces: dict[str, list[Trace]], room_budget_s: float | None, ref: str = "hif"
) -> list[str]:
    """The generated "Reading" section of learning.md: every number comes from ``traces``."""
    names = list(traces)
    if ref not in traces:
        ref = names[0]
    t_end = min(t.sim_s[-1] for ts in traces.values() for t in ts if t.sim_s)
    k_all = min(len(t.sim_s) for ts in traces.values() for t in ts)
    k_mid = max(1, min(100, k_all // 2))
    n_rooms = sum(len(t.room_objects) for t in traces[ref])
    budget = (
        f"a budget of {room_budget_s:g} simulated seconds per room (the robot leaves a room when it "
        "is spent; the examination in flight completes)"
        if room_budget_s is not None
        else "no time budget (every room to completion, Figure 2 as published)"
    )
    share_cells = ", ".join(f"{n} {_fmt(_shares(traces[n]), 2)}" for n in names)
    lines = [
        "## Reading",
        "",
        f"Generated from this run. With {budget}, the share of a room's objects examined (median "
        f"over rooms and seeds [IQR]): {share_cells}. The budget ended "
        f"{sum(t.rooms_left_early for t in traces[ref])} of {n_rooms} rooms for {ref}.",
        "",
        f"Mean interval width minus {ref}'s, paired per seed: median [IQR] and the seeds where "
        f"{ref} is ahead (positive: {ref} has the narrower intervals). 'Per exam' averages over "
        f"examinations 1..{k_all}; 'per second' over simulated seconds 0..{t_end:.0f} (the "
        "shortest run), which charges every strategy for its travel.",
        "",
        f"| strategy | at {k_mid} exams | at t = {t_end / 2:.0f} s | at t = {t_end:.0f} s "
        "| averaged per exam | averaged per second |",
        "|---|---|---|---|---|---|",
    ]
    verdicts = []
    for n in names:
        if n == ref:
            continue
        pairs = list(zip(traces[n], traces[ref], strict=True))
        cols = [
            [a.at_exam(k_mid, "mean_width") - b.at_exam(k_mid, "mean_width") for a, b in pairs],
            [
                a.at_time(t_end / 2, "mean_width") - b.at_time(t_end / 2, "mean_width")
                for a, b in pairs
            ],
            [a.at_time(t_end, "mean_width") - b.at_time(t_end, "mean_width") for a, b in pairs],
            [
                _run_mean(a, "mean_width", k_all) - _run_mean(b, "mean_width", k_all)
                for a, b in pairs
            ],
            [a.time_mean(t_end, "mean_width") - b.time_mean(t_end, "mean_width") for a, b in pairs],
        ]
        lines.append(
            f"| {n} | " + " | ".join(f"{_fmt(c, 4, True)} ({_ahead(c)})" for c in cols) + " |"
        )
        per_exam, per_s = np.asarray(cols[3]), np.asarray(cols[4])
        verdicts.append(
            f"- {ref} vs {n}: per examination {ref} is ahead in {_ahead(per_exam)} seeds "
            f"(median {np.median(per_exam):+.4f}), per simulated second in {_ahead(per_s)} "
            f"(median {np.median(per_s):+.4f})."
        )
    lines += ["", *verdicts]
    if "expected-hif" in traces and ref == "hif":
        d_h, d_e = _decision_stats(traces["hif"]), _decision_stats(traces["expected-hif"])
        lines += [
            f"- The impact quirk (eq. 3 is not monotonic in n): {d_h['quirk']:.1%} of hif's "
            f"choices among two or more types are quirk picks ({d_e['quirk']:.1%} for "
            f"expected-hif); hif and expected-hif agree on {d_h['same_expected']:.1%} of hif's "
            "choices."
        ]

    def goal_cell(ts: list[Trace], g: float) -> str:
        v = np.array([t.time_to(g) for t in ts])
        med = float(np.median(np.where(np.isfinite(v), v, np.inf)))  # never reached: infinite
        return f"{med:.0f}" if math.isfinite(med) else "-"

    goals = ", ".join(
        f"{n} " + " / ".join(goal_cell(traces[n], g) for g in WIDTH_GOALS) for n in names
    )
    lines += [
        "- Simulated seconds to reach a mean width of "
        + " / ".join(f"{g:g}" for g in WIDTH_GOALS)
        + f" (median over seeds; '-': the median seed never does): {goals}.",
        "",
    ]
    return lines


def markdown(
    style: str,
    seeds: int,
    rooms: int,
    perception: str,
    traces: dict[str, list[Trace]],
    truth_samples: int,
    alpha: float,
    room_budget_s: float | None = None,
) -> str:
    """The tables of learning.md (medians over seeds, [inter-quartile range])."""
    names = list(traces)
    ref = "hif" if "hif" in traces else names[0]
    t_end = min(t.sim_s[-1] for ts in traces.values() for t in ts if t.sim_s)
    times = [f * t_end for f in TIME_FRACTIONS]
    k_all = min(len(t.sim_s) for ts in traces.values() for t in ts)
    budget = "" if room_budget_s is None else f", room budget {room_budget_s:g} s"
    lines = [
        f"# Learning benchmark: {style}, {rooms} rooms x {seeds} seeds, {perception} perception"
        + budget,
        "",
        f"Ground truth from {truth_samples} generated rooms; alpha = {alpha}. Every cell: the median "
        "over seeds [inter-quartile range]. Widths, errors and coverage are over every (A, rel, B) "
        "with ground truth. Every strategy sees the same rooms for a given seed, so differences "
        f"are paired per seed (a strategy minus {ref}: positive means {ref} is ahead).",
        "",
        *reading(traces, room_budget_s, ref),
    ]
    titles = {
        "mean_width": "Mean interval width",
        "max_width": "Max interval width",
        "mean_abs_error": "Mean |p0 - p_true|",
        "coverage": "Coverage (share of intervals holding p_true)",
    }
    head = (
        "| strategy | "
        + " | ".join(f"{k} exams" for k in EXAM_MARKS)
        + " | "
        + " | ".join(f"t = {t:.0f} s" for t in times)
        + " |"
    )
    rule = "|---" * (1 + len(EXAM_MARKS) + len(times)) + "|"
    for metric in METRICS:
        lines += [f"## {titles[metric]}", "", head, rule]
        for n in names:
            cells = [_fmt([t.at_exam(k, metric) for t in traces[n]]) for k in EXAM_MARKS]
            cells += [_fmt([t.at_time(tt, metric) for t in traces[n]]) for tt in times]
            lines.append(f"| {n} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += [f"## Mean interval width minus {ref}'s (paired per seed)", "", head, rule]
    for n in names:
        if n == ref:
            continue
        pairs = list(zip(traces[n], traces[ref], strict=True))
        cells = [
            _fmt(
                [a.at_exam(k, "mean_width") - b.at_exam(k, "mean_width") for a, b in pairs], 4, True
            )
            for k in EXAM_MARKS
        ]
        cells += [
            _fmt(
                [a.at_time(tt, "mean_width") - b.at_time(tt, "mean_width") for a, b in pairs],
                4,
                True,
            )
            for tt in times
        ]
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    lines += [
        "",
        f"## Averaged over examinations 1..{k_all} (area under the curve per examination)",
        "",
        f"| strategy | mean width | minus {ref} | mean abs error | minus {ref} | coverage "
        f"| mean width over 0..{t_end:.0f} s | minus {ref} |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for n in names:
        pairs = list(zip(traces[n], traces[ref], strict=True))
        lines.append(
            f"| {n} | {_fmt([_run_mean(t, 'mean_width', k_all) for t in traces[n]], 4)} | "
            + _fmt(
                [
                    _run_mean(a, "mean_width", k_all) - _run_mean(b, "mean_width", k_all)
                    for a, b in pairs
                ],
                4,
                True,
            )
            + f" | {_fmt([_run_mean(t, 'mean_abs_error', k_all) for t in traces[n]], 4)} | "
            + _fmt(
                [
                    _run_mean(a, "mean_abs_error", k_all) - _run_mean(b, "mean_abs_error", k_all)
                    for a, b in pairs
                ],
                4,
                True,
            )
            + f" | {_fmt([_run_mean(t, 'coverage', k_all) for t in traces[n]], 3)} | "
            + _fmt([t.time_mean(t_end, "mean_width") for t in traces[n]], 4)
            + " | "
            + _fmt(
                [
                    a.time_mean(t_end, "mean_width") - b.time_mean(t_end, "mean_width")
                    for a, b in pairs
                ],
                4,
                True,
            )
            + " |"
        )
    lines += [
        "",
        "## Decisions",
        "",
        "Choices among at least two candidate types (all seeds). 'Same as X': the share of "
        "them where the strategy picked what X would have picked from the same knowledge. "
        "'Better-known picks': a less-examined type was on offer. 'Quirk picks': better-known "
        "picks where impact(0, n) (the term that dominates the average, most y being 0) is "
        "larger for the pick's n than for the least-examined candidate's: eq. 3 is not "
        "monotonic in n (impact(0, 2) = 0.101 < impact(0, 4) = 0.115).",
        "",
        "| strategy | choices | same as hif | same as expected-hif | same as fewest "
        "| better-known picks | quirk picks |",
        "|---|---|---|---|---|---|---|",
    ]
    for n in names:
        d = _decision_stats(traces[n])
        lines.append(
            f"| {n} | {d['choices']} | {d['same_hif']:.1%} | {d['same_expected']:.1%} | "
            f"{d['same_fewest']:.1%} | {d['better_known']:.1%} | {d['quirk']:.1%} |"
        )
    lines += [
        "",
        "## Examinations and time",
        "",
        "| strategy | sim s at "
        + " | sim s at ".join(str(k) for k in EXAM_MARKS)
        + " | "
        + " | ".join(f"exams by {t:.0f} s" for t in times)
        + " | exams in all | share of room objects examined | rooms ended by the budget | wall s |",
        "|---" * (2 + len(EXAM_MARKS) + len(times) + 3) + "|",
    ]
    for n in names:
        cells = [
            _fmt([t.sim_s[k - 1] if k <= len(t.sim_s) else np.nan for t in traces[n]], 0)
            for k in EXAM_MARKS
        ]
        cells += [_fmt([t.exams_by(tt) for t in traces[n]], 0) for tt in times]
        cells += [
            _fmt([len(t.sim_s) for t in traces[n]], 0),
            _fmt(_shares(traces[n]), 2),
            _fmt([t.rooms_left_early for t in traces[n]], 0),
            _fmt([t.wall_s for t in traces[n]], 1),
        ]
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _band(ax, x, arr, name, ref, lw=1.4):
    with warnings.catch_warnings():  # NaN before the first examination
        warnings.simplefilter("ignore", RuntimeWarning)
        q1, med, q3 = np.nanpercentile(arr, [25, 50, 75], axis=0)
    (line,) = ax.plot(x, med, label=name, lw=2.4 if name == ref else lw)
    ax.fill_between(x, q1, q3, color=line.get_color(), alpha=0.15, lw=0)


def plot(path: Path, traces: dict[str, list[Trace]], title: str) -> None:
    """Curves (median over seeds) with inter-quartile bands: mean width, error and coverage
    against examinations, mean width against simulated time, and every strategy's mean width
    minus HIF's (paired per seed) against examinations and time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(traces)
    ref = "hif" if "hif" in traces else names[0]
    k = min(len(t.sim_s) for ts in traces.values() for t in ts)
    t_end = min(t.sim_s[-1] for ts in traces.values() for t in ts)
    xk = np.arange(1, k + 1)
    xt = np.linspace(0, t_end, 400)
    fig, axes = plt.subplots(2, 3, figsize=(17, 9))
    for n, ts in traces.items():
        for ax, metric in (
            (axes[0, 0], "mean_width"),
            (axes[1, 0], "mean_abs_error"),
            (axes[1, 1], "coverage"),
        ):
            _band(ax, xk, np.array([t.metrics[metric][:k] for t in ts]), n, ref)
        _band(
            axes[1, 2], xt, np.array([[t.at_time(v, "mean_width") for v in xt] for t in ts]), n, ref
        )
        pairs = list(zip(ts, traces[ref], strict=True))
        d_k = np.array(
            [
                np.array(a.metrics["mean_width"][:k]) - np.array(b.metrics["mean_width"][:k])
                for a, b in pairs
            ]
        )
        d_t = np.array(
            [
                [a.at_time(v, "mean_width") - b.at_time(v, "mean_width") for v in xt]
                for a, b in pairs
            ]
        )
        _band(axes[0, 1], xk, d_k, n, ref)
        _band(axes[0, 2], xt, d_t, n, ref)
    labels = {
        (0, 0): ("examinations", "mean interval width"),
        (0, 1): ("examinations", f"mean width minus {ref}'s (paired)"),
        (0, 2): ("simulated seconds", f"mean width minus {ref}'s (paired)"),
        (1, 0): ("examinations", "mean |p0 - p_true|"),
        (1, 1): ("examinations", "coverage"),
        (1, 2): ("simulated seconds", "mean interval width"),
    }
    for (r, c), (xl, yl) in labels.items():
        ax = axes[r, c]
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.grid(alpha=0.3)
        if xl == "examinations":
            ax.set_xscale("log")
    for ax in (axes[0, 1], axes[0, 2]):
        ax.axhline(0.0, color="k", lw=0.8)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
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
    room_budget_s: float | None = None,
) -> BenchResult:
    """Run the benchmark and write DIR/learning.json, DIR/learning.md and DIR/learning.png.

    ``room_budget_s``: simulated seconds per room (None: every room to completion)."""
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
            tr = run_trace(
                style, rooms, k, s, truth, catalog, perception, alpha, Path(tmp), room_budget_s
            )
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
        "room_budget_s": room_budget_s,
        "truth_samples": truth.get("samples", truth_samples),
        "strategies": {
            s: {
                "examinations": list(range(1, min(len(t.sim_s) for t in ts) + 1)),
                "sim_s": _median_curve(ts, "sim_s"),
                **{m: _median_curve(ts, m) for m in METRICS},
                "wall_s": [t.wall_s for t in ts],
                "examined_share": [t.examined_shares() for t in ts],  # per seed, per room
                "rooms_left_early": [t.rooms_left_early for t in ts],
                "decisions": {k: float(v) for k, v in _decision_stats(ts).items()},
            }
            for s, ts in traces.items()
        },
    }
    table = markdown(
        style, seeds, rooms, perception, traces, data["truth_samples"], alpha, room_budget_s
    )
    files = [out / "learning.json", out / "learning.md", out / "learning.png"]
    files[0].write_text(json.dumps(data, indent=1) + "\n")
    files[1].write_text(table)
    budget = "" if room_budget_s is None else f", room budget {room_budget_s:g} s"
    plot(files[2], traces, f"{style}: {rooms} rooms x {seeds} seeds ({perception}{budget})")
    return BenchResult(data, table, files)
