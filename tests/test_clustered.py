"""The clustered interval: exactly Wilson with one examination per room, and close to its promise
where examinations in a room are correlated (a simulation with known truth)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.clustered import (
    ClusteredIntervals,
    RoomCounts,
    design_effect,
    room_counts_from_rows,
    t_quantile,
)

KEY = ("ON-TOP-OF-DESK", "Monitor")


def _coverage(p: float, rho: float, m: int, k: int, reps: int = 800, seed: int = 0):
    """Coverage and mean width of (wilson, clustered) over simulated runs: k rooms, about m
    examinations each, room-level p_j ~ Beta with intra-room correlation rho."""
    rng = np.random.default_rng(seed)
    hit = np.zeros(2)
    width = np.zeros(2)
    for _ in range(reps):
        n_room = rng.integers(max(1, m - 2), m + 3, size=k)
        pj = rng.beta(p * (1 - rho) / rho, (1 - p) * (1 - rho) / rho, k) if rho else np.full(k, p)
        y_room = rng.binomial(n_room, pj)
        y, n = int(y_room.sum()), int(n_room.sum())
        ci = ClusteredIntervals({"Desk": RoomCounts(n_room, {KEY: y_room})})
        for i, (lo, hi) in enumerate((intervals.interval(y, n), ci.interval("Desk", KEY, y, n))):
            hit[i] += lo <= p <= hi
            width[i] += hi - lo
    return hit / reps, width / reps


def test_one_examination_per_room_is_exactly_wilson():
    rng = np.random.default_rng(1)
    for _ in range(200):
        n = int(rng.integers(1, 60))
        x = rng.integers(0, 2, n)
        ci = ClusteredIntervals({"Desk": RoomCounts(np.ones(n, np.int64), {KEY: x})})
        y = int(x.sum())
        got = ci.interval("Desk", KEY, y, n)
        want = tuple(float(v) for v in intervals.interval(y, n))
        assert got == pytest.approx(want, abs=1e-12)


def test_correlated_rooms_wilson_undercovers_clustered_keeps_the_promise():
    (cov_w, cov_c), (w_w, w_c) = _coverage(p=0.3, rho=0.3, m=4, k=20)
    assert cov_w < 0.80  # the paper's interval, trials taken as independent
    assert cov_c >= 0.87  # nominal 0.90, within simulation error
    assert w_c > w_w  # the price: wider intervals


def test_few_rooms_strong_correlation():
    (cov_w, cov_c), _ = _coverage(p=0.5, rho=0.5, m=5, k=10)
    assert cov_w < 0.70 and cov_c >= 0.86


def test_independent_trials_cost_little_width():
    (cov_w, cov_c), (w_w, w_c) = _coverage(p=0.3, rho=0.0, m=4, k=20)
    assert cov_c >= 0.88
    assert w_c < 1.15 * w_w


def test_entry_without_successes_borrows_its_types_correlation():
    n_room = np.array([4, 4, 4, 4, 4, 4])
    clustered = np.array([4, 0, 4, 0, 4, 0])  # all or nothing per room: rho = 1
    counts = RoomCounts(n_room, {("NEAR-DESK", "Chair"): clustered})
    ci = ClusteredIntervals({"Desk": counts})
    assert design_effect(clustered, n_room) == pytest.approx(4.0)
    assert ci.rho("Desk") == pytest.approx(1.0)
    # (ON-TOP-OF-DESK, Monitor) was never seen: y = 0 carries no clustering of its own.
    assert design_effect(np.zeros(6), n_room) is None
    assert ci.deff("Desk", KEY) == pytest.approx(4.0)
    lo, hi = ci.interval("Desk", KEY, 0, 24)
    assert lo == 0.0 and hi > intervals.interval(0, 24)[1]
    # A type never examined: the no-data interval.
    assert ci.interval("Table", KEY, 0, 0) == (0.0, 1.0)


@pytest.mark.parametrize("nu", [1, 2, 3, 5, 10, 40, 300])
def test_t_quantile_matches_scipy(nu):
    for q in (0.9, 0.95, 0.975):
        assert t_quantile(q, nu) == pytest.approx(stats.t.ppf(q, nu), rel=2e-3)


def test_room_counts_from_rows():
    exams = [("Desk", 1), ("Desk", 1), ("Desk", 2), ("Cup", 2)]
    obs = [("Desk", 1, "ON-TOP-OF-DESK", "Monitor"), ("Desk", 2, "ON-TOP-OF-DESK", "Monitor")]
    rc = room_counts_from_rows(exams, obs)
    assert rc["Desk"].n == 3 and list(rc["Desk"].n_room) == [2, 1]
    assert list(rc["Desk"].y_room[KEY]) == [1, 1]
    assert rc["Cup"].n == 1 and not rc["Cup"].y_room
    assert rc["Desk"].mean_room_size == pytest.approx((4 + 1) / 3)


def test_intervals_do_not_depend_on_the_order_the_pairs_came_in():
    """The type's mean correlation sums its entries' in one fixed order: pairs recorded in any
    order (a set's order changes from process to process) give the same bits."""
    rng = np.random.default_rng(0)  # reversed, the unsorted sum differs in the last bit
    n_room = rng.integers(1, 9, 12)
    ys = {("NEAR-DESK", f"T{j}"): np.minimum(n_room, rng.integers(0, 9, 12)) for j in range(20)}
    shrinks = set()
    for order in (sorted(ys), sorted(ys, reverse=True)):
        ci = ClusteredIntervals({"Desk": RoomCounts(n_room, {k: ys[k] for k in order})})
        shrinks.add((ci.rho("Desk"), ci.shrink("Desk", ("NEAR-DESK", "absent"))))
    assert len(shrinks) == 1
