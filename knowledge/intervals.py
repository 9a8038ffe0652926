"""Confidence intervals and impact, exactly the paper's eq. 1-3 (Wilson score interval).

    p0(y, n) = (y/n + z^2/2n) / (1 + z^2/n)                                          (1)
    d(y, n)  = (z/sqrt(n)) * sqrt((y/n)(1 - y/n) + z^2/4n) / (1 + z^2/n)             (2)
    impact(y, n) = 2 * max(|d(y,n) - d(y,n+1)|, |d(y,n) - d(y+1,n+1)|)               (3)

with z = z_{alpha/2}, the upper alpha/2 point of the standard normal. d(y, 0) is undefined in the
paper; the no-data interval is [0, 1] (Figure 1), so we define p0(y, 0) = d(y, 0) = 0.5. The
interval is p0 -/+ d, which is always inside [0, 1] for the Wilson interval (we clip only float
round-off). Every function is vectorised over numpy arrays (broadcasting y against n).
"""

from __future__ import annotations

from functools import lru_cache
from statistics import NormalDist

import numpy as np

DEFAULT_ALPHA = 0.10


@lru_cache(maxsize=64)
def z_value(alpha: float = DEFAULT_ALPHA) -> float:
    """z_{alpha/2}: P(Z >= z) = alpha/2 for a standard normal Z."""
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
    return NormalDist().inv_cdf(1.0 - alpha / 2.0)


def _prep(y, n):
    y = np.asarray(y, dtype=float)
    n = np.asarray(n, dtype=float)
    if np.any(y < 0) or np.any(y > n):
        raise ValueError("need 0 <= y <= n")
    return y, n


def p0(y, n, alpha: float = DEFAULT_ALPHA):
    """Eq. 1: the interval's centre. 0.5 where n = 0."""
    y, n = _prep(y, n)
    z2 = z_value(alpha) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        out = (y / n + z2 / (2 * n)) / (1 + z2 / n)
    return np.where(n > 0, out, 0.5)[()]


def d(y, n, alpha: float = DEFAULT_ALPHA):
    """Eq. 2: the interval's half-width. 0.5 where n = 0 (the [0, 1] no-data interval)."""
    y, n = _prep(y, n)
    z = z_value(alpha)
    z2 = z * z
    with np.errstate(divide="ignore", invalid="ignore"):
        ph = y / n
        out = (
            (z / np.sqrt(n)) * np.sqrt(np.maximum(ph * (1 - ph), 0.0) + z2 / (4 * n)) / (1 + z2 / n)
        )
    return np.where(n > 0, out, 0.5)[()]


def interval(y, n, alpha: float = DEFAULT_ALPHA):
    """The (low, high) confidence interval p0 -/+ d for P(rel(B)), clipped to [0, 1] for round-off.

    The Wilson bounds are exactly 0 at y = 0 and exactly 1 at y = n; they are returned as such
    (p0 - d alone leaves ~1e-17 of round-off, which would make sorting by lower bound arbitrary).
    """
    c, h = p0(y, n, alpha), d(y, n, alpha)
    y, n = np.asarray(y, float), np.asarray(n, float)
    lo = np.where(y == 0, 0.0, np.clip(c - h, 0.0, 1.0))
    hi = np.where(y == n, 1.0, np.clip(c + h, 0.0, 1.0))
    return lo[()], hi[()]


def impact(y, n, alpha: float = DEFAULT_ALPHA):
    """Eq. 3: the largest change in interval width one more trial can cause.

    Kept exactly as published, quirks included: impact(0, n) is not monotonic in n
    (0.270, 0.155, 0.101, 0.112, ... at alpha 0.10).
    """
    y, n = _prep(y, n)
    dn = d(y, n, alpha)
    return 2 * np.maximum(np.abs(dn - d(y, n + 1, alpha)), np.abs(dn - d(y + 1, n + 1, alpha)))


def expected_width_change(y, n, alpha: float = DEFAULT_ALPHA, prior: float = 0.5):
    """The expected change of the width under the current estimate (for the ``expected-hif`` baseline).

    E[|w(n) - w(n+1)|] with P(success) = the Laplace-smoothed estimate (y + prior)/(n + 2*prior).
    Unlike eq. 3 this weighs the two outcomes by their likelihood, so a rare success after many
    failures no longer dominates. Not the paper's method; a baseline to compare against.
    """
    y, n = _prep(y, n)
    p = (y + prior) / (n + 2 * prior)
    dn = d(y, n, alpha)
    return 2 * ((1 - p) * np.abs(dn - d(y, n + 1, alpha)) + p * np.abs(dn - d(y + 1, n + 1, alpha)))
