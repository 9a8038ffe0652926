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
method: ``DayEvidence`` (built by ``evidence_of`` from ``EvidenceStore.examinations()``) holds
a run's examinations by day, ``Forgetting`` names a method and its parameters, and
``ForgetKnowledgeBase`` is a KnowledgeBase whose intervals read the method's counts (``kb show
--forget``, the search, re-examination in ``learn --reexamine impact``). Pure numpy.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.base import IntervalRow, KnowledgeBase
from ctxsearch.knowledge.options import Forget, values

FORGET_METHODS = values(Forget)
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
    """The chi-square(1) value exceeded with probability ``p_upper`` (= z_{p/2}^2), for any
    ``p_upper`` in (0, 1], however small (read from the lower tail, which 1 - p/2 would round
    away: a rate of 1e-300 gives z^2 of about 1380, not an error)."""
    if not 0.0 < p_upper <= 1.0:
        raise ValueError(f"a tail probability must be in (0, 1], got {p_upper}")
    return NormalDist().inv_cdf(max(p_upper / 2.0, sys.float_info.min)) ** 2


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
        [first_day, last_day]; after each alarm only the recent window's evidence is kept.

        Only the days on which the test's counts can change are tested: an examination's day
        (it joins the recent window), the day it leaves the window (its day + ``window``) and
        the day after an alarm. On any other day both sides hold what they held on the last
        day tested, so the test says the same (no alarm): the result is that of testing every
        day, in time that grows with the examinations, not with the days they span."""
        alarms: list[int] = []
        start = first_day  # evidence before this day was dropped
        days, hits = series.days, series.hits
        level = self.false_alarm / self.looks
        # Screen with G: far below the exact test's cut it is never an alarm, and G is cheap.
        thr = chi2_1_quantile(level) * 0.8
        events = np.unique(np.concatenate([days, days + self.window]))
        events = events[(events >= first_day) & (events <= last_day)].tolist()
        k, today, after_alarm = 0, first_day - 1, None
        while True:
            if after_alarm is not None:
                today, after_alarm = after_alarm, None
            else:
                while k < len(events) and events[k] <= today:
                    k += 1
                if k == len(events):
                    break
                today = int(events[k])
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
                if today < last_day:
                    after_alarm = today + 1
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
    if method == Forget.NONE:
        return float(s.hits.sum()), float(len(s.hits))
    if method == Forget.HALF_LIFE:
        return half_life_counts(s, today, half_life)
    if method == Forget.DETECT:
        y, n = (detector or ChangeDetector()).counts(s, first_day, today)
        return float(y), float(n)
    raise ValueError(f"unknown forgetting method '{method}' (known: {', '.join(FORGET_METHODS)})")


# =========================================================================== a run's evidence by day
@dataclass(frozen=True)
class Forgetting:
    """How counts become intervals over days (``--forget``): ``method`` (FORGET_METHODS), the
    half-life in days, and the change test's false-alarm rate per entry and run over ``looks``
    days tested (the Bonferroni divisor; None: the days the evidence spans)."""

    method: str = "none"
    half_life: float = DEFAULT_HALF_LIFE
    false_alarm: float = DEFAULT_FALSE_ALARM
    window: int = DEFAULT_WINDOW
    looks: int | None = None

    def __post_init__(self) -> None:
        if self.method not in FORGET_METHODS:
            raise ValueError(
                f"unknown forgetting method '{self.method}' (known: {', '.join(FORGET_METHODS)})"
            )
        if not self.half_life > 0 or not math.isfinite(self.half_life):
            raise ValueError(f"half-life must be a positive number of days, got {self.half_life}")
        if not 0.0 < self.false_alarm < 1.0:
            raise ValueError(f"false-alarm rate must be in (0, 1), got {self.false_alarm}")

    @property
    def label(self) -> str:
        """The method with its parameter (``half-life:7``, ``detect:0.05``, ``none``)."""
        if self.method == Forget.HALF_LIFE:
            return f"half-life:{self.half_life:g}"
        if self.method == Forget.DETECT:
            return f"detect:{self.false_alarm:g}"
        return "none"

    def detector(self, last_day: int) -> ChangeDetector:
        """The change test for evidence up to ``last_day``."""
        looks = self.looks if self.looks is not None else max(1, last_day + 1)
        return ChangeDetector(self.window, self.false_alarm, looks)

    def counts(self, series: EntrySeries, today: int, last_day: int) -> tuple[float, float]:
        """The (y, n) this method makes of ``series`` on ``today``."""
        return forget_counts(
            series,
            today,
            self.method,
            half_life=self.half_life,
            detector=self.detector(last_day) if self.method == Forget.DETECT else None,
        )


@dataclass
class DayEvidence:
    """Evidence by day: per reference type, the day of each of its examinations and the
    (relation, B) pairs each found (at least one B in rel). Built from the evidence log's day
    stamps; examinations may be added in any order (series are ordered by day, stably)."""

    days: dict[str, list[int]]
    pairs: dict[str, list[frozenset[tuple[str, str]]]]

    @classmethod
    def empty(cls) -> DayEvidence:
        """No evidence yet."""
        return cls({}, {})

    def add(self, ref: str, day: int, pairs) -> None:
        """One examination of a ``ref`` on ``day`` and the (relation, B) pairs it found."""
        self.days.setdefault(ref, []).append(int(day))
        self.pairs.setdefault(ref, []).append(frozenset(pairs))

    @property
    def last_day(self) -> int:
        """The latest day with evidence (0 without any)."""
        return max((max(d) for d in self.days.values() if d), default=0)

    def keys(self, ref: str) -> list[tuple[str, str]]:
        """The (relation, B) pairs found at least once in examinations of ``ref``, sorted."""
        return sorted(set().union(*self.pairs.get(ref, [])))

    def series(self, ref: str, key: tuple[str, str] | None) -> EntrySeries:
        """The entry (ref, key)'s series, ordered by day (``key`` None or unseen: all misses)."""
        days = np.asarray(self.days.get(ref, []), np.int64)
        order = np.argsort(days, kind="stable")
        found = self.pairs.get(ref, [])
        hits = np.array([key is not None and key in found[i] for i in order], bool)
        return EntrySeries(days[order], hits.reshape(len(order)))

    def table(
        self, forgetting: Forgetting, today: int, last_day: int | None = None
    ) -> dict[str, tuple[float, dict[tuple[str, str], tuple[float, float]]]]:
        """Per examined reference type: (n of an entry never hit, {(rel, B): (y, n)} of its
        entries with a hit), as ``forgetting`` counts them on ``today``."""
        last = self.last_day if last_day is None else last_day
        out = {}
        for ref in self.days:
            _y0, n0 = forgetting.counts(self.series(ref, None), today, last)
            entries = {
                key: forgetting.counts(self.series(ref, key), today, last) for key in self.keys(ref)
            }
            out[ref] = (n0, entries)
        return out

    def alarms(
        self, forgetting: Forgetting, ref: str, key: tuple[str, str], today: int
    ) -> list[int]:
        """The days ``detect`` raised an alarm on entry (ref, key) up to ``today``."""
        det = forgetting.detector(self.last_day)
        return det.changes(self.series(ref, key).until(today), 0, today)


class ForgetKnowledgeBase(KnowledgeBase):
    """A KnowledgeBase whose intervals (``interval``, ``rows``, ``mean_width``, and so the search's
    P(rel(T))) read the counts a forgetting method makes of the evidence on ``today``; its raw
    counts (``n``, ``y``, the HIF choice) are the paper's, all evidence counted."""

    def __init__(
        self,
        catalog,
        alpha: float,
        evidence: DayEvidence,
        today: int,
        forgetting: Forgetting,
        last_day: int | None = None,
    ):
        super().__init__(catalog, alpha)
        self.evidence, self.today, self.forgetting = evidence, int(today), forgetting
        for ref, days in evidence.days.items():
            now = [i for i, d in enumerate(days) if d <= today]
            ys: dict[tuple[str, str], int] = {}
            for i in now:
                for key in evidence.pairs[ref][i]:
                    ys[key] = ys.get(key, 0) + 1
            self.add_counts(ref, len(now), ys)
        self.table = evidence.table(forgetting, today, last_day)

    def counts(self, ref: str, key: tuple[str, str]) -> tuple[float, float]:
        """(y, n) of entry (ref, key) under the forgetting method."""
        n0, entries = self.table.get(ref, (0.0, {}))
        return entries.get(key, (0.0, n0))

    def interval(self, relation: str, type_name: str) -> tuple[float, float]:
        """Wilson's interval on the forgetting method's counts ([0, 1] without evidence)."""
        ref = self.catalog.relation(relation).ref
        y, n = self.counts(ref, (relation, type_name))
        lo, hi = intervals.interval(y, n, self.alpha)
        return float(lo), float(hi)

    def rows(self, ref_type: str | None = None, include_zero: bool = True) -> list[IntervalRow]:
        """``KnowledgeBase.rows`` on the forgetting method's (effective) counts."""
        refs = [ref_type] if ref_type is not None else list(self.catalog.type_names)
        out = []
        for ref in refs:
            t = self.catalog.type(ref)
            n0, entries = self.table.get(ref, (0.0, {}))
            keys = (
                [(r, b) for r in t.relation_names for b in self.catalog.type_names]
                if include_zero
                else [k for k, (y, _n) in entries.items() if y > 0]
            )
            for key in keys:
                y, n = entries.get(key, (0.0, n0))
                lo, hi = intervals.interval(y, n, self.alpha)
                c = float(intervals.p0(y, n, self.alpha))
                out.append(IntervalRow(ref, key[0], key[1], y, n, c, float(lo), float(hi)))
        out.sort(key=lambda row: (-row.low, row.relation, row.type))
        return out

    def mean_width(self) -> float:
        """Mean interval width over every (A, rel, B) of the catalog, on the forgetting counts."""
        rows = self.rows(include_zero=True)
        return float(np.mean([r.width for r in rows])) if rows else 0.0

    def type_impact_now(self, ref: str) -> float:
        """Figure 2's d_A (average eq. 3 impact over RELATIONS(A) x TYPES) on the forgetting
        method's counts: what one more examination of an A would teach today."""
        t = self.catalog.type(ref)
        m = len(t.relation_names) * len(self.catalog.type_names)
        if m == 0:
            return 0.0
        n0, entries = self.table.get(ref, (0.0, {}))
        ys = np.array([y for y, _ in entries.values()], float)
        ns = np.array([n for _, n in entries.values()], float)
        total = (m - len(entries)) * float(intervals.impact(0.0, n0, self.alpha))
        if len(entries):
            total += float(np.sum(intervals.impact(ys, ns, self.alpha)))
        return total / m


def evidence_of(examinations, run: str | None = None) -> DayEvidence:
    """The DayEvidence of an evidence log's examinations (``EvidenceStore.examinations()``), of
    one run or all, ordered by day (stable within a day)."""
    ev = DayEvidence.empty()
    for e in examinations:
        if run is None or e.run == run:
            ev.add(e.type, e.day, {(r, t) for r, t, _ in e.related})
    return ev
