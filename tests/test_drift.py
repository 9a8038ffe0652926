"""Forgetting and change detection over days, against simulations with a known change."""

from __future__ import annotations

import numpy as np
import pytest

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.drift import (
    ChangeDetector,
    EntrySeries,
    chi2_1_quantile,
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
