"""Forgetting and change detection over days, against simulations with a known change."""

from __future__ import annotations

import numpy as np
import pytest

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.drift import (
    ChangeDetector,
    EntrySeries,
    chi2_1_quantile,
    fisher_p,
    forget_counts,
    g_statistic,
    half_life_counts,
)

DAYS = 30


def _series(p_of_day, per_day=5, seed=0) -> EntrySeries:
    rng = np.random.default_rng(seed)
    days = np.repeat(np.arange(DAYS), per_day)
    hits = rng.random(len(days)) < np.array([p_of_day(d) for d in days])
    return EntrySeries(days, hits)


def test_none_is_the_paper():
    s = EntrySeries(np.array([0, 0, 1, 3]), np.array([True, False, True, True]))
    assert forget_counts(s, 3, "none") == (3.0, 4.0)
    assert forget_counts(s, 1, "none") == (2.0, 3.0)  # nothing from the future


def test_half_life_weights():
    s = EntrySeries(np.array([0, 7, 14]), np.array([True, False, True]))
    y, n = half_life_counts(s, 14, 7.0)
    assert n == pytest.approx(0.25 + 0.5 + 1.0) and y == pytest.approx(1.25)
    with pytest.raises(ValueError):
        half_life_counts(s, 14, 0.0)


def test_g_statistic():
    assert g_statistic(5, 10, 5, 10) == pytest.approx(0.0)
    assert g_statistic(9, 10, 1, 10) > chi2_1_quantile(0.001)
    assert g_statistic(3, 0, 1, 10) == 0.0
    assert chi2_1_quantile(0.05) == pytest.approx(3.841, abs=1e-3)


def test_detect_keeps_false_alarms_below_its_rate():
    det = ChangeDetector(looks=DAYS)
    flagged = [
        bool(det.changes(_series(lambda d, p=p: p, seed=i), 0, DAYS - 1))
        for i, p in enumerate(np.random.default_rng(9).uniform(0.05, 0.95, 400))
    ]
    assert np.mean(flagged) <= 0.05


def test_detect_finds_a_change_fast_and_forgets_the_old_value():
    det = ChangeDetector(looks=DAYS)
    delays = []
    for seed in range(40):
        s = _series(lambda d: 0.8 if d < 15 else 0.2, seed=seed)
        alarms = det.changes(s, 0, DAYS - 1)
        if not alarms:
            continue
        delays.append(alarms[0] - 15)
        y, n = forget_counts(s, DAYS - 1, "detect", detector=det)
        assert intervals.interval(y, n)[1] < 0.8  # the old value is out of the interval
    assert len(delays) >= 36  # noticed in at least 90% of the runs
    assert np.median(delays) <= 3 and min(delays) >= 0


def test_none_is_slow_to_exclude_the_old_value_half_life_faster():
    def days_to_exclude(method):
        s = _series(lambda d: 0.8 if d < 15 else 0.2, seed=3)
        for today in range(15, DAYS):
            y, n = forget_counts(s, today, method, half_life=3.0)
            if intervals.interval(y, n)[1] < 0.8:
                return today - 15
        return None

    none, half = days_to_exclude("none"), days_to_exclude("half-life")
    assert half is not None and (none is None or half < none)


def test_series_validation():
    with pytest.raises(ValueError):
        EntrySeries(np.array([2, 1]), np.array([True, False]))
    with pytest.raises(ValueError):
        forget_counts(EntrySeries(np.array([0]), np.array([True])), 0, "sometimes")


def _changes_testing_every_day(det: ChangeDetector, series, first_day, last_day) -> list[int]:
    """The change test as defined: tested at the end of every day (the reference)."""
    alarms, start = [], first_day
    days, hits = series.days, series.hits
    level = det.false_alarm / det.looks
    for today in range(first_day, last_day + 1):
        cut = today - det.window + 1
        old, new = (days >= start) & (days < cut), (days >= cut) & (days <= today)
        if cut <= start or old.sum() < det.min_evidence or new.sum() < det.min_evidence:
            continue
        y1, n1, y2, n2 = hits[old].sum(), old.sum(), hits[new].sum(), new.sum()
        g_ok = g_statistic(y1, n1, y2, n2) > chi2_1_quantile(level) * 0.8
        if g_ok and fisher_p(y1, n1, y2, n2) < level:
            alarms.append(today)
            start = cut
    return alarms


def test_testing_only_the_days_with_evidence_gives_the_alarms_of_testing_every_day():
    rng = np.random.default_rng(24)
    alarmed = 0
    for _ in range(600):
        span = int(rng.integers(1, 60))
        days = np.sort(rng.integers(0, span, int(rng.integers(0, 50))))
        p = np.where(days < rng.integers(0, span), rng.random(), rng.random())
        series = EntrySeries(days, rng.random(len(days)) < p)
        det = ChangeDetector(
            window=int(rng.integers(1, 8)),
            false_alarm=float(rng.choice([0.05, 0.5, 0.9])),
            looks=int(rng.integers(1, 4)),
            min_evidence=int(rng.integers(0, 6)),
        )
        first, last = int(rng.integers(0, 4)), int(rng.integers(0, span + 8))
        expected = _changes_testing_every_day(det, series, first, last)
        assert det.changes(series, first, last) == expected
        alarmed += bool(expected)
    assert alarmed > 100  # the comparison saw many alarms, not only quiet series


def test_the_change_test_over_a_million_days_is_quick_and_any_rate_has_a_quantile():
    import time

    days = np.array([0] * 10 + [500_000] * 10 + [1_000_000] * 10)
    series = EntrySeries(days, np.array([True] * 10 + [False] * 20))
    t = time.perf_counter()
    assert ChangeDetector(window=3, looks=30).changes(series, 0, 1_000_000) == [500_000]
    assert time.perf_counter() - t < 1.0
    assert chi2_1_quantile(1e-300) == pytest.approx(1373.87, abs=0.01)  # 1 - p/2 rounds to 1
    assert chi2_1_quantile(5e-324) > chi2_1_quantile(1e-300)
    with pytest.raises(ValueError):
        chi2_1_quantile(0.0)
