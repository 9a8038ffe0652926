"""learning.md and learning.png of ``ctxsearch bench learning``, from the runs' traces.

Every cell is the median over seeds [inter-quartile range]; differences between strategies are
paired per seed (same rooms) against the reference strategy (``hif`` where it ran).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ctxsearch.scripts.experiments.learning_trace import (
    EXAM_MARKS,
    METRICS,
    TIME_FRACTIONS,
    WIDTH_GOALS,
    Trace,
)

TITLES = {
    "mean_width": "Mean interval width",
    "max_width": "Max interval width",
    "mean_abs_error": "Mean |p0 - p_true|",
    "coverage_informative": "Informative coverage (share of intervals holding p_true, over the "
    "entries with n_A >= 1 and 0.02 <= p_true <= 0.98)",
    "coverage": "Coverage (share of all intervals holding p_true; entries with p_true 0 or "
    "never examined cannot miss)",
}
DECISIONS_TEXT = (
    "Choices among at least two candidate types (all seeds). 'Same as X': the share of "
    "them where the strategy picked what X would have picked from the same knowledge. "
    "'Better-known picks': a less-examined type was on offer. 'Quirk picks': better-known "
    "picks where impact(0, n) (the term that dominates the average, most y being 0) is "
    "larger for the pick's n than for the least-examined candidate's: eq. 3 is not "
    "monotonic in n (impact(0, 2) = 0.101 < impact(0, 4) = 0.115)."
)
Traces = dict[str, list[Trace]]


@dataclass(frozen=True)
class Span:
    """What every strategy's every run reached: the marks the tables compare at."""

    ref: str  # the reference strategy of the paired differences
    t_end: float  # simulated seconds of the shortest run
    k_all: int  # examinations of the shortest run

    @classmethod
    def of(cls, traces: Traces, ref: str = "hif") -> Span:
        """The span of ``traces`` (``ref``: the reference if it ran, else the first strategy)."""
        return cls(
            ref if ref in traces else next(iter(traces)),
            min(t.sim_s[-1] for ts in traces.values() for t in ts if t.sim_s),
            min(len(t.sim_s) for ts in traces.values() for t in ts),
        )

    @property
    def times(self) -> list[float]:
        """The simulated seconds the tables compare at."""
        return [f * self.t_end for f in TIME_FRACTIONS]


def fmt(vals, digits: int = 3, sign: bool = False) -> str:
    """'median [q1, q3]' of the finite ``vals`` ('-' if none)."""
    v = np.asarray(vals, float)
    v = v[np.isfinite(v)]
    if not len(v):
        return "-"
    q1, med, q3 = np.percentile(v, [25, 50, 75])
    f = f"{{:{'+' if sign else ''}.{digits}f}}"
    return f"{f.format(med)} [{f.format(q1)}, {f.format(q3)}]"


def _ahead(diffs) -> str:
    """'k/n': the seeds where the paired difference is positive (the reference is ahead)."""
    v = np.asarray(diffs, float)
    v = v[np.isfinite(v)]
    return f"{int((v > 1e-12).sum())}/{len(v)}"


def _shares(ts: list[Trace]) -> list[float]:
    return [x for t in ts for x in t.examined_shares()]


def _paired(traces: Traces, n: str, ref: str) -> list[tuple[Trace, Trace]]:
    return list(zip(traces[n], traces[ref], strict=True))


def markdown(
    title: str, traces: Traces, truth_samples: int, alpha: float, room_budget_s: float | None
) -> str:
    """learning.md: ``title`` (its first line), the generated reading and the tables."""
    span = Span.of(traces)
    lines = [
        f"# {title}",
        "",
        f"Ground truth from {truth_samples} generated rooms; alpha = {alpha}. Every cell: the median "
        "over seeds [inter-quartile range]. Widths, errors and coverage are over every (A, rel, B) "
        "with ground truth. Every strategy sees the same rooms for a given seed, so differences "
        f"are paired per seed (a strategy minus {span.ref}: positive means {span.ref} is ahead).",
        "",
        *reading(traces, room_budget_s, span.ref),
        *_metric_tables(traces, span),
        *_paired_table(traces, span),
        *_averages_table(traces, span),
        *_decisions_table(traces),
        *_time_table(traces, span),
    ]
    return "\n".join(lines) + "\n"


def _head(span: Span) -> list[str]:
    """The header and rule of the tables at the examination and time marks."""
    head = (
        "| strategy | "
        + " | ".join(f"{k} exams" for k in EXAM_MARKS)
        + " | "
        + " | ".join(f"t = {t:.0f} s" for t in span.times)
        + " |"
    )
    return [head, "|---" * (1 + len(EXAM_MARKS) + len(span.times)) + "|"]


def _metric_tables(traces: Traces, span: Span) -> list[str]:
    """One table per metric: its value at the examination and time marks."""
    lines: list[str] = []
    for metric in METRICS:
        lines += [f"## {TITLES[metric]}", "", *_head(span)]
        for n, ts in traces.items():
            cells = [fmt([t.at_exam(k, metric) for t in ts]) for k in EXAM_MARKS]
            cells += [fmt([t.at_time(tt, metric) for t in ts]) for tt in span.times]
            lines.append(f"| {n} | " + " | ".join(cells) + " |")
        lines.append("")
    return lines


def _paired_table(traces: Traces, span: Span) -> list[str]:
    """Every strategy's mean width minus the reference's at the marks."""
    lines = [f"## Mean interval width minus {span.ref}'s (paired per seed)", "", *_head(span)]
    w = "mean_width"
    for n in traces:
        if n == span.ref:
            continue
        pairs = _paired(traces, n, span.ref)
        cells = [
            fmt([a.at_exam(k, w) - b.at_exam(k, w) for a, b in pairs], 4, True) for k in EXAM_MARKS
        ]
        cells += [
            fmt([a.at_time(tt, w) - b.at_time(tt, w) for a, b in pairs], 4, True)
            for tt in span.times
        ]
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    return lines


def _averages_table(traces: Traces, span: Span) -> list[str]:
    """The metrics averaged over the run, per examination and per simulated second."""
    ref, k, t_end = span.ref, span.k_all, span.t_end
    lines = [
        "",
        f"## Averaged over examinations 1..{k} (area under the curve per examination)",
        "",
        f"| strategy | mean width | minus {ref} | mean abs error | minus {ref} | coverage "
        f"| mean width over 0..{t_end:.0f} s | minus {ref} |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for n, ts in traces.items():
        pairs = _paired(traces, n, ref)
        cells = []
        for metric in ("mean_width", "mean_abs_error"):
            cells.append(fmt([t.run_mean(metric, k) for t in ts], 4))
            cells.append(
                fmt([a.run_mean(metric, k) - b.run_mean(metric, k) for a, b in pairs], 4, True)
            )
        cells.append(fmt([t.run_mean("coverage", k) for t in ts], 3))
        cells.append(fmt([t.time_mean(t_end, "mean_width") for t in ts], 4))
        cells.append(
            fmt(
                [
                    a.time_mean(t_end, "mean_width") - b.time_mean(t_end, "mean_width")
                    for a, b in pairs
                ],
                4,
                True,
            )
        )
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    return lines


def _decisions_table(traces: Traces) -> list[str]:
    """How each strategy's picks relate to hif's, expected-hif's and fewest's."""
    lines = [
        "",
        "## Decisions",
        "",
        DECISIONS_TEXT,
        "",
        "| strategy | choices | same as hif | same as expected-hif | same as fewest "
        "| better-known picks | quirk picks |",
        "|---|---|---|---|---|---|---|",
    ]
    for n, ts in traces.items():
        d = decision_stats(ts)
        lines.append(
            f"| {n} | {d['choices']} | {d['same_hif']:.1%} | {d['same_expected']:.1%} | "
            f"{d['same_fewest']:.1%} | {d['better_known']:.1%} | {d['quirk']:.1%} |"
        )
    return lines


def _time_table(traces: Traces, span: Span) -> list[str]:
    """Simulated seconds at the examination marks, examinations by the time marks, and more."""
    times = span.times
    lines = [
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
    for n, ts in traces.items():
        cells = [
            fmt([t.sim_s[k - 1] if k <= len(t.sim_s) else np.nan for t in ts], 0)
            for k in EXAM_MARKS
        ]
        cells += [fmt([t.exams_by(tt) for t in ts], 0) for tt in times]
        cells += [
            fmt([len(t.sim_s) for t in ts], 0),
            fmt(_shares(ts), 2),
            fmt([t.rooms_left_early for t in ts], 0),
            fmt([t.wall_s for t in ts], 1),
        ]
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    return lines


def decision_stats(ts: list[Trace]) -> dict[str, float]:
    """The share of the runs' choices that agree with each reference pick, and of quirk picks."""
    rows = [d for t in ts for d in t.decisions]
    n = len(rows)
    a = np.array(rows, bool).reshape(-1, 5)
    keys = ("same_hif", "same_expected", "same_fewest", "better_known", "quirk")
    return {
        "choices": n,
        **{k: float(a[:, i].mean()) if n else float("nan") for i, k in enumerate(keys)},
    }


# ---- the generated reading ---------------------------------------------------------------
def reading(traces: Traces, room_budget_s: float | None, ref: str = "hif") -> list[str]:
    """The generated "Reading" section of learning.md: every number comes from ``traces``."""
    span = Span.of(traces, ref)
    ref, t_end, k_all = span.ref, span.t_end, span.k_all
    k_mid = max(1, min(100, k_all // 2))
    lines = [
        *_reading_intro(traces, room_budget_s, ref),
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
    for n in traces:
        if n == ref:
            continue
        cols = _reading_columns(_paired(traces, n, ref), k_mid, span)
        lines.append(
            f"| {n} | " + " | ".join(f"{fmt(c, 4, True)} ({_ahead(c)})" for c in cols) + " |"
        )
        per_exam, per_s = np.asarray(cols[3]), np.asarray(cols[4])
        verdicts.append(
            f"- {ref} vs {n}: per examination {ref} is ahead in {_ahead(per_exam)} seeds "
            f"(median {np.median(per_exam):+.4f}), per simulated second in {_ahead(per_s)} "
            f"(median {np.median(per_s):+.4f})."
        )
    lines += ["", *verdicts, *_quirk_line(traces, ref), _goals_line(traces), ""]
    return lines


def _reading_intro(traces: Traces, room_budget_s: float | None, ref: str) -> list[str]:
    """The reading's heading and its sentence on the budget and the share examined."""
    n_rooms = sum(len(t.room_objects) for t in traces[ref])
    budget = (
        f"a budget of {room_budget_s:g} simulated seconds per room (the robot leaves a room when it "
        "is spent; the examination in flight completes)"
        if room_budget_s is not None
        else "no time budget (every room to completion, Figure 2 as published)"
    )
    share_cells = ", ".join(f"{n} {fmt(_shares(ts), 2)}" for n, ts in traces.items())
    return [
        "## Reading",
        "",
        f"Generated from this run. With {budget}, the share of a room's objects examined (median "
        f"over rooms and seeds [IQR]): {share_cells}. The budget ended "
        f"{sum(t.rooms_left_early for t in traces[ref])} of {n_rooms} rooms for {ref}.",
        "",
    ]


def _reading_columns(pairs: list[tuple[Trace, Trace]], k_mid: int, span: Span) -> list[list[float]]:
    """Paired mean-width differences: at k_mid exams, at half and all of the shortest run's
    time, averaged per examination and per simulated second."""
    w, t_end, k_all = "mean_width", span.t_end, span.k_all
    return [
        [a.at_exam(k_mid, w) - b.at_exam(k_mid, w) for a, b in pairs],
        [a.at_time(t_end / 2, w) - b.at_time(t_end / 2, w) for a, b in pairs],
        [a.at_time(t_end, w) - b.at_time(t_end, w) for a, b in pairs],
        [a.run_mean(w, k_all) - b.run_mean(w, k_all) for a, b in pairs],
        [a.time_mean(t_end, w) - b.time_mean(t_end, w) for a, b in pairs],
    ]


def _quirk_line(traces: Traces, ref: str) -> list[str]:
    """The share of hif's quirk picks, where expected-hif ran too."""
    if "expected-hif" not in traces or ref != "hif":
        return []
    d_h, d_e = decision_stats(traces["hif"]), decision_stats(traces["expected-hif"])
    return [
        f"- The impact quirk (eq. 3 is not monotonic in n): {d_h['quirk']:.1%} of hif's "
        f"choices among two or more types are quirk picks ({d_e['quirk']:.1%} for "
        f"expected-hif); hif and expected-hif agree on {d_h['same_expected']:.1%} of hif's "
        "choices."
    ]


def _goals_line(traces: Traces) -> str:
    """Simulated seconds to reach each of WIDTH_GOALS, per strategy."""

    def goal_cell(ts: list[Trace], g: float) -> str:
        v = np.array([t.time_to(g) for t in ts])
        med = float(np.median(np.where(np.isfinite(v), v, np.inf)))  # never reached: infinite
        return f"{med:.0f}" if math.isfinite(med) else "-"

    goals = ", ".join(
        f"{n} " + " / ".join(goal_cell(ts, g) for g in WIDTH_GOALS) for n, ts in traces.items()
    )
    return (
        "- Simulated seconds to reach a mean width of "
        + " / ".join(f"{g:g}" for g in WIDTH_GOALS)
        + f" (median over seeds; '-': the median seed never does): {goals}."
    )


# ---- the plot -----------------------------------------------------------------------------
PLOT_LABELS = {
    (0, 0): ("examinations", "mean interval width"),
    (0, 1): ("examinations", "mean width minus {ref}'s (paired)"),
    (0, 2): ("simulated seconds", "mean width minus {ref}'s (paired)"),
    (1, 0): ("examinations", "mean |p0 - p_true|"),
    (1, 1): ("examinations", "coverage"),
    (1, 2): ("simulated seconds", "mean interval width"),
}


def _band(ax, x, arr, name, ref, lw=1.4):
    with warnings.catch_warnings():  # NaN before the first examination
        warnings.simplefilter("ignore", RuntimeWarning)
        q1, med, q3 = np.nanpercentile(arr, [25, 50, 75], axis=0)
    (line,) = ax.plot(x, med, label=name, lw=2.4 if name == ref else lw)
    ax.fill_between(x, q1, q3, color=line.get_color(), alpha=0.15, lw=0)


def plot(path: Path, traces: Traces, title: str) -> None:
    """Curves (median over seeds) with inter-quartile bands: mean width, error and coverage
    against examinations, mean width against simulated time, and every strategy's mean width
    minus HIF's (paired per seed) against examinations and time."""
    span = Span.of(traces)
    k = span.k_all
    xk = np.arange(1, k + 1)
    xt = np.linspace(0, span.t_end, 400)
    fig = Figure(figsize=(17, 9))
    axes = fig.subplots(2, 3)
    for n, ts in traces.items():
        _plot_strategy(axes, n, ts, traces[span.ref], (xk, xt), span.ref)
    for (r, c), (xl, yl) in PLOT_LABELS.items():
        ax = axes[r, c]
        ax.set_xlabel(xl)
        ax.set_ylabel(yl.format(ref=span.ref))
        ax.grid(alpha=0.3)
        if xl == "examinations":
            ax.set_xscale("log")
    for ax in (axes[0, 1], axes[0, 2]):
        ax.axhline(0.0, color="k", lw=0.8)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def _plot_strategy(axes, n: str, ts: list[Trace], refs: list[Trace], xs, ref: str) -> None:
    """Strategy ``n``'s bands in every panel (``xs``: the examination and time axes)."""
    xk, xt = xs
    k = len(xk)
    for ax, metric in (
        (axes[0, 0], "mean_width"),
        (axes[1, 0], "mean_abs_error"),
        (axes[1, 1], "coverage"),
    ):
        _band(ax, xk, np.array([t.metrics[metric][:k] for t in ts]), n, ref)
    _band(axes[1, 2], xt, np.array([[t.at_time(v, "mean_width") for v in xt] for t in ts]), n, ref)
    pairs = list(zip(ts, refs, strict=True))
    d_k = np.array(
        [
            np.array(a.metrics["mean_width"][:k]) - np.array(b.metrics["mean_width"][:k])
            for a, b in pairs
        ]
    )
    d_t = np.array(
        [[a.at_time(v, "mean_width") - b.at_time(v, "mean_width") for v in xt] for a, b in pairs]
    )
    _band(axes[0, 1], xk, d_k, n, ref)
    _band(axes[0, 2], xt, d_t, n, ref)
