"""Eq. 1-3: the Wilson interval equals scipy's, impact matches the paper's numbers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binomtest

from ctxsearch.knowledge import intervals


def _grid(nmax: int) -> tuple[np.ndarray, np.ndarray]:
    """Every (y, n) with 0 <= y <= n, 1 <= n <= nmax."""
    n, y = np.meshgrid(np.arange(1, nmax + 1), np.arange(0, nmax + 1), indexing="ij")
    keep = y <= n
    return y[keep], n[keep]


@pytest.fixture(scope="module")
def scipy_results():
    """scipy's binomtest result for every 0 <= y <= n <= 200 (n >= 1), computed once (~7 s)."""
    y, n = _grid(200)
    return y, n, [binomtest(int(a), int(b)) for a, b in zip(y, n, strict=True)]


@pytest.mark.parametrize("alpha", [0.10, 0.05])
def test_interval_equals_scipy_wilson_on_whole_grid(alpha, scipy_results):
    y, n, results = scipy_results
    lo, hi = intervals.interval(y, n, alpha)  # ours: the whole grid in one call
    ref = np.array(
        [tuple(r.proportion_ci(confidence_level=1 - alpha, method="wilson")) for r in results]
    )
    assert len(ref) == 201 * 202 // 2 - 1
    np.testing.assert_allclose(lo, ref[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(hi, ref[:, 1], rtol=0, atol=1e-12)


def test_p0_and_d_give_the_interval():
    y, n = _grid(50)
    lo, hi = intervals.interval(y, n)
    c, h = intervals.p0(y, n), intervals.d(y, n)
    np.testing.assert_allclose(c - h, lo, atol=1e-15)
    np.testing.assert_allclose(c + h, hi, atol=1e-15)
    assert np.all((lo >= 0) & (hi <= 1) & (lo < hi))


def test_no_data_interval_is_zero_one():
    assert intervals.interval(0, 0) == (0.0, 1.0)
    assert intervals.d(0, 0) == 0.5
    assert intervals.p0(0, 0) == 0.5
    lo, hi = intervals.interval(np.zeros(3), np.array([0, 0, 4]))
    assert lo[0] == 0.0 and hi[0] == 1.0 and hi[2] < 1.0


def test_impact_matches_the_paper_at_alpha_010():
    got = [round(float(intervals.impact(0, n, 0.10)), 4) for n in range(4)]
    assert got == [0.2699, 0.1552, 0.1008, 0.1117]


def test_impact_is_not_monotonic_in_n():
    imp = intervals.impact(0, np.arange(7))
    np.testing.assert_allclose(imp, [0.270, 0.155, 0.101, 0.112, 0.115, 0.113, 0.109], atol=5e-4)


def test_impact_is_vectorised_and_broadcasts():
    y, n = _grid(30)
    vec = intervals.impact(y, n)
    loop = np.array([intervals.impact(int(a), int(b)) for a, b in zip(y, n, strict=True)])
    np.testing.assert_array_equal(vec, loop)
    # Scalar n against a vector of y.
    np.testing.assert_array_equal(intervals.impact(np.arange(11), 10), vec[n == 10])


def test_impact_is_the_largest_width_change():
    y, n = _grid(40)
    w = lambda a, b: 2 * intervals.d(a, b)  # noqa: E731
    expect = np.maximum(np.abs(w(y, n) - w(y, n + 1)), np.abs(w(y, n) - w(y + 1, n + 1)))
    np.testing.assert_allclose(intervals.impact(y, n), expect, atol=1e-15)


def test_alpha_changes_z_and_is_validated():
    assert intervals.z_value(0.10) == pytest.approx(1.6448536269514722, abs=1e-12)
    assert intervals.z_value(0.05) == pytest.approx(1.959963984540054, abs=1e-12)
    lo10, hi10 = intervals.interval(3, 10, 0.10)
    lo05, hi05 = intervals.interval(3, 10, 0.05)
    assert lo05 < lo10 and hi05 > hi10
    for bad in (0.0, 1.0, -0.1, 2.0):
        with pytest.raises(ValueError):
            intervals.z_value(bad)


def test_bad_counts_are_rejected():
    with pytest.raises(ValueError):
        intervals.interval(3, 2)
    with pytest.raises(ValueError):
        intervals.d(-1, 2)


def test_expected_width_change_is_bounded_by_impact():
    y, n = _grid(40)
    assert np.all(intervals.expected_width_change(y, n) <= intervals.impact(y, n) + 1e-15)
