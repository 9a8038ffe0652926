"""Knowledge over days: how evidence gathered on earlier days counts today (``--forget``).

The paper's question (section 6): if desk5 was examined yesterday, may it be examined again
today, since the objects on top of it may have changed? Across days every examination is a new
trial, and the statistics themselves may drift (a department moves from workstations to
laptops). Three ways to turn one entry's evidence, a chronological series of examinations of an
A (their day and whether a B stood in rel), into counts for the paper's interval:

``none``       the paper: every examination counts forever (y, n).
``half-life``  exponential forgetting: an examination d days old weighs 2^(-d / H); Wilson on
               the effective counts (sum of weights of the successes, sum of all weights).
``detect``     a change test per entry: at the end of every day, the last ``window`` days are
               compared with everything before them (each side needs ``min_evidence``
               examinations) by Fisher's exact test; an alarm is raised when its two-sided
               p-value is below ``alpha / looks`` (Bonferroni over the days tested, so an entry
               that does not change raises a false alarm in a run with probability at most
               ``alpha``, 5% by default). The likelihood-ratio G statistic screens first (its
               chi-square tail is anti-conservative here: measured 0.0019-0.0023 at a nominal
               0.0017 per look, which over 30 looks gave 5-6% false alarms; the exact test is
               conservative). On an alarm, evidence before the recent window is dropped and
               monitoring restarts from there.

Everything is derived from the evidence log's day stamps, so one store can be re-read with any
method. Pure numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

FORGET_METHODS = ("none", "half-life", "detect")
DEFAULT_HALF_LIFE = 7.0  # days
DEFAULT_WINDOW = 3  # days compared against the older evidence
DEFAULT_FALSE_ALARM = 0.05  # per entry and run


@dataclass(frozen=True)
class EntrySeries:
    """One entry's evidence: for each examination of an A (chronological), its day and whether
    at least one B stood in rel to it."""

    days: np.ndarray  # (n,) int
    hits: np.ndarray  # (n,) bool

    def __post_init__(self) -> None:
        d = np.asarray(self.days, np.int64)
        h = np.asarray(self.hits, bool)
        if d.shape != h.shape or d.ndim != 1:
            raise ValueError("days and hits must be 1-D arrays of one length")
        if len(d) and np.any(np.diff(d) < 0):
            raise ValueError("examinations must be in chronological order")
        object.__setattr__(self, "days", d)
        object.__setattr__(self, "hits", h)

    def until(self, day: int) -> EntrySeries:
        """The evidence gathered up to and including ``day``."""
        k = int(np.searchsorted(self.days, day, side="right"))
        return EntrySeries(self.days[:k], self.hits[:k])


def half_life_counts(series: EntrySeries, today: int, half_life: float) -> tuple[float, float]:
    """(y_eff, n_eff) with every examination weighted 2^(-(today - day) / half_life)."""
    if not half_life > 0 or not math.isfinite(half_life):
        raise ValueError(f"half-life must be a positive number of days, got {half_life}")
    w = np.exp2(-(today - series.days) / half_life)
    return float(w[series.hits].sum()), float(w.sum())


def chi2_1_quantile(p_upper: float) -> float:
    """The chi-square(1) value exceeded with probability ``p_upper`` (= z_{p/2}^2)."""
    return NormalDist().inv_cdf(1.0 - p_upper / 2.0) ** 2


def _loglik(y: float, n: float) -> float:
    if n <= 0:
        return 0.0
    out = 0.0
    if y > 0:
        out += y * math.log(y / n)
    if y < n:
        out += (n - y) * math.log((n - y) / n)
    return out


def g_statistic(y1: float, n1: float, y2: float, n2: float) -> float:
    """The binomial likelihood-ratio statistic for p1 != p2 (0 when either side is empty)."""
    if n1 <= 0 or n2 <= 0:
        return 0.0
    return 2.0 * (_loglik(y1, n1) + _loglik(y2, n2) - _loglik(y1 + y2, n1 + n2))


def fisher_p(y1: int, n1: int, y2: int, n2: int) -> float:
    """Fisher's exact two-sided p-value for p1 == p2 (successes y of n on each side)."""
    total, ys = n1 + n2, y1 + y2
    lo, hi = max(0, ys - n2), min(ys, n1)
    k = np.arange(lo, hi + 1)
    lgam = np.vectorize(math.lgamma)
    logp = (
        lgam(ys + 1)
        - lgam(k + 1)
        - lgam(ys - k + 1)
        + lgam(total - ys + 1)
        - lgam(n1 - k + 1)
        - lgam(total - ys - n1 + k + 1)
        - (math.lgamma(total + 1) - math.lgamma(n1 + 1) - math.lgamma(n2 + 1))
    )
    pmf = np.exp(logp)
    obs = pmf[y1 - lo]
    return float(min(1.0, pmf[pmf <= obs * (1 + 1e-7)].sum()))


@dataclass(frozen=True)
class ChangeDetector:
    """The ``detect`` method's test (see the module docstring)."""

    window: int = DEFAULT_WINDOW
    false_alarm: float = DEFAULT_FALSE_ALARM
    looks: int = 30  # days the run tests on (the Bonferroni divisor)
    min_evidence: int = 5  # examinations each side needs before it is tested

    def __post_init__(self) -> None:
        if self.window < 1 or self.looks < 1 or not 0.0 < self.false_alarm < 1.0:
            raise ValueError("need window >= 1, looks >= 1 and 0 < false_alarm < 1")

    def changes(self, series: EntrySeries, first_day: int, last_day: int) -> list[int]:
        """The days on which alarms were raised, testing at the end of every day in
        [first_day, last_day]; after each alarm only the recent window's evidence is kept."""
        alarms: list[int] = []
        start = first_day  # evidence before this day was dropped
        days, hits = series.days, series.hits
        level = self.false_alarm / self.looks
        # Screen with G: far below the exact test's cut it is never an alarm, and G is cheap.
        thr = chi2_1_quantile(level) * 0.8
        for today in range(first_day, last_day + 1):
            cut = today - self.window + 1  # the recent window is [cut, today]
            if cut <= start:
                continue
            old = (days >= start) & (days < cut)
            new = (days >= cut) & (days <= today)
            if old.sum() < self.min_evidence or new.sum() < self.min_evidence:
                continue
            y1, n1, y2, n2 = (
                int(hits[old].sum()),
                int(old.sum()),
                int(hits[new].sum()),
                int(new.sum()),
            )
            if g_statistic(y1, n1, y2, n2) > thr and fisher_p(y1, n1, y2, n2) < level:
                alarms.append(today)
                start = cut
        return alarms

    def counts(self, series: EntrySeries, first_day: int, today: int) -> tuple[int, int]:
        """(y, n) of the evidence kept today: everything since the window of the last alarm."""
        alarms = self.changes(series, first_day, today)
        start = alarms[-1] - self.window + 1 if alarms else first_day
        keep = (series.days >= start) & (series.days <= today)
        return int(series.hits[keep].sum()), int(keep.sum())


def forget_counts(
    series: EntrySeries,
    today: int,
    method: str = "none",
    *,
    first_day: int = 0,
    half_life: float = DEFAULT_HALF_LIFE,
    detector: ChangeDetector | None = None,
) -> tuple[float, float]:
    """The (y, n) that ``method`` makes of an entry's evidence up to ``today``."""
    s = series.until(today)
    if method == "none":
        return float(s.hits.sum()), float(len(s.hits))
    if method == "half-life":
        return half_life_counts(s, today, half_life)
    if method == "detect":
        y, n = (detector or ChangeDetector()).counts(s, first_day, today)
        return float(y), float(n)
    raise ValueError(f"unknown forgetting method '{method}' (known: {', '.join(FORGET_METHODS)})")
