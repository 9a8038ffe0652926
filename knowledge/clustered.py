"""Intervals that account for examinations in one room being correlated (``--interval clustered``).

The paper treats every examination of an A as an independent Bernoulli trial. In a room,
they are not: a style may put monitors on every desk of one room and on none of the next, and
one cup may stand near two desks. Counting the examinations of a room as independent then
overstates the evidence, and the Wilson interval (eq. 1-2) covers p_true less often than
promised, the more so the more evidence there is.

Method: Wilson's interval on an effective sample size (Kish's design effect for cluster
samples; Korn & Graubard 1998, "Confidence intervals for proportions with small expected
number of positive counts estimated from survey data", Survey Methodology 24:193-201; compared
favourably with its alternatives for clustered binomial data by Dean & Pagano 2015, J. Survey
Statistics and Methodology 3:484-503). For one entry (A, rel, B), with rooms j = 1..k, n_j
examinations of an A in room j and y_j of them with a B in rel:

    p = y / n                                y = sum y_j, n = sum n_j
    var_room = sum_j (y_j - p n_j)^2 / n^2   the ratio estimator's variance under cluster sampling
    deff = max(1, var_room / (p (1 - p) / n))
    df = (t_{k-1} / t_{n-1})^2               t_nu: Student's t quantile at 1 - alpha/2
    INT_clustered = Wilson(y / (deff df), n / (deff df))

``var_room`` uses the moment form without the k / (k - 1) small-sample factor, so that with one
examination per room it equals p(1 - p)/n exactly. The factor ``df`` is Korn & Graubard's
degrees-of-freedom adjustment: the between-room variance is estimated from k rooms, not n trials,
so the effective sample shrinks further when there are few rooms (k = 1 counts as k = 2: one room
says nothing about the next). With one examination per room k = n, both factors are 1 and the
interval is exactly the paper's. The design effect is never below 1: clustering is never taken to
add information. Without the df factor, a simulation with rho = 0.5, 5 examinations in each of 10
rooms gave coverage 0.87 at nominal 0.90 (``tests/test_clustered.py``).

Where p is 0 or 1 the entry carries no estimate of its own clustering (every room agrees). It
borrows the intra-room correlation of its reference type: rho_e = (deff_e - 1) / (m - 1) for
every entry of A with 0 < y < n, where m = sum n_j^2 / n is A's mean room size weighted by
examinations; rho_A is their mean (clipped to [0, 1]), falling back to the mean over all types,
then 0; such an entry gets deff = 1 + (m - 1) rho_A. This matters: an entry whose B is absent
from most rooms has y = 0 for many examinations that are really a few rooms' worth.

The per-room counts come from the evidence log (``EvidenceStore.room_counts``), which records each
examination's room; nothing here is stored, so any store can be re-read with either method.
Pure numpy.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from ctxsearch.knowledge import intervals


def t_quantile(q: float, nu: int) -> float:
    """Student's t quantile: exact for nu = 1, 2; the Cornish-Fisher expansion in the normal
    quantile (Abramowitz & Stegun 26.7.5, four terms) above, within 0.05% of the exact value at
    q = 0.95 for nu >= 3 and within 1e-5 for nu >= 8."""
    if not 0.0 < q < 1.0 or nu < 1:
        raise ValueError(f"need 0 < q < 1 and nu >= 1, got q={q}, nu={nu}")
    if nu == 1:
        return math.tan(math.pi * (q - 0.5))
    if nu == 2:
        return (2 * q - 1) / math.sqrt(2 * q * (1 - q))
    z = NormalDist().inv_cdf(q)
    g1 = (z**3 + z) / 4
    g2 = (5 * z**5 + 16 * z**3 + 3 * z) / 96
    g3 = (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / 384
    g4 = (79 * z**9 + 776 * z**7 + 1482 * z**5 - 1920 * z**3 - 945 * z) / 92160
    return z + g1 / nu + g2 / nu**2 + g3 / nu**3 + g4 / nu**4


def df_factor(rooms: int, n: int, alpha: float = intervals.DEFAULT_ALPHA) -> float:
    """Korn & Graubard's (t_{k-1} / t_{n-1})^2 at 1 - alpha/2 (>= 1; 1 where k = n)."""
    if n <= 1 or rooms >= n:
        return 1.0
    q = 1.0 - alpha / 2.0
    return (t_quantile(q, max(rooms - 1, 1)) / t_quantile(q, n - 1)) ** 2


@dataclass(frozen=True)
class RoomCounts:
    """The per-room evidence of one reference type A.

    ``n_room``: examinations of an A in each room (k,). ``y_room``: for each (relation, type) with
    y > 0, the examinations in each room with at least one such object in the relation (k,).
    """

    n_room: np.ndarray
    y_room: Mapping[tuple[str, str], np.ndarray]

    # Cached (the counts are frozen): an entry's interval reads them for every entry of A.
    @functools.cached_property
    def n(self) -> int:
        """n_A."""
        return int(self.n_room.sum())

    @functools.cached_property
    def mean_room_size(self) -> float:
        """m = sum n_j^2 / n: the mean number of A-examinations a room contributes, per exam."""
        n = self.n
        return float((self.n_room.astype(float) ** 2).sum() / n) if n else 0.0

    @functools.cached_property
    def design_effects(self) -> dict[tuple[str, str], float | None]:
        """Each pair's ``design_effect`` (None where not estimable), in sorted pair order: the
        type's mean correlation (``type_rho``) sums them in this order, whatever order the counts
        came in (a set's order varies from process to process with the strings' hashes)."""
        return {key: design_effect(self.y_room[key], self.n_room) for key in sorted(self.y_room)}


def design_effect(y_room: np.ndarray, n_room: np.ndarray) -> float | None:
    """Kish's design effect of one entry (>= 1), or None where p is 0 or 1 (not estimable)."""
    n_room = np.asarray(n_room, float)
    y_room = np.asarray(y_room, float)
    n, y = n_room.sum(), y_room.sum()
    if n <= 0 or y <= 0 or y >= n:
        return None
    p = y / n
    var_room = float(((y_room - p * n_room) ** 2).sum()) / (n * n)
    return max(1.0, var_room / (p * (1.0 - p) / n))


def type_rho(counts: RoomCounts) -> float | None:
    """The mean intra-room correlation of A's estimable entries, in [0, 1] (None if none)."""
    m = counts.mean_room_size
    if m <= 1.0:
        return None
    rhos = []
    for deff in counts.design_effects.values():
        if deff is not None:
            rhos.append(min(1.0, (deff - 1.0) / (m - 1.0)))
    return float(np.mean(rhos)) if rhos else None


@dataclass(frozen=True)
class ClusteredIntervals:
    """Design effects for every entry of a set of reference types, and their intervals."""

    counts: Mapping[str, RoomCounts]  # reference type -> its per-room counts
    alpha: float = intervals.DEFAULT_ALPHA

    def __post_init__(self) -> None:
        rhos = {a: type_rho(c) for a, c in self.counts.items()}
        known = [r for r in rhos.values() if r is not None]
        fallback = float(np.mean(known)) if known else 0.0
        object.__setattr__(self, "_rho", {a: fallback if r is None else r for a, r in rhos.items()})
        object.__setattr__(  # the df factor of each type's entries (one per type)
            self,
            "_df",
            {a: df_factor(len(c.n_room), c.n, self.alpha) for a, c in self.counts.items() if c.n},
        )

    def rho(self, ref_type: str) -> float:
        """The intra-room correlation used for A's entries with y = 0 or y = n."""
        return self._rho.get(ref_type, 0.0)  # type: ignore[attr-defined]

    def deff(self, ref_type: str, key: tuple[str, str]) -> float:
        """The design effect of entry (A, rel, B) (1 where A was never examined)."""
        c = self.counts.get(ref_type)
        if c is None or c.n == 0:
            return 1.0
        own = c.design_effects.get(key)
        if own is not None:
            return own
        return max(1.0, 1.0 + (c.mean_room_size - 1.0) * self.rho(ref_type))

    def shrink(self, ref_type: str, key: tuple[str, str]) -> float:
        """n / n_effective of entry (A, rel, B): its design effect times the df factor."""
        c = self.counts.get(ref_type)
        if c is None or c.n == 0:
            return 1.0
        return self.deff(ref_type, key) * self._df[ref_type]  # type: ignore[attr-defined]

    def interval(self, ref_type: str, key: tuple[str, str], y: int, n: int) -> tuple[float, float]:
        """Wilson's interval on the effective counts (y, n) / shrink; [0, 1] with no data."""
        f = self.shrink(ref_type, key) if n else 1.0
        lo, hi = intervals.interval(y / f, n / f, self.alpha)
        return float(lo), float(hi)


def room_counts_from_rows(
    exam_rows: Sequence[tuple[str, object]],
    obs_rows: Sequence[tuple[str, object, str, str]],
) -> dict[str, RoomCounts]:
    """Build RoomCounts from (ref type, room) per examination and (ref type, room, relation,
    type) per examination with at least one such observation (one row per examination and pair)."""
    rooms: dict[str, dict[object, int]] = {}
    for ref, room in exam_rows:
        per = rooms.setdefault(ref, {})
        per[room] = per.get(room, 0) + 1
    index = {a: {r: i for i, r in enumerate(sorted(per, key=repr))} for a, per in rooms.items()}
    ys: dict[str, dict[tuple[str, str], np.ndarray]] = {a: {} for a in rooms}
    for ref, room, rel, t in obs_rows:
        arr = ys[ref].setdefault((rel, t), np.zeros(len(index[ref]), np.int64))
        arr[index[ref][room]] += 1
    return {
        a: RoomCounts(np.array([per[r] for r in sorted(per, key=repr)], np.int64), ys[a])
        for a, per in rooms.items()
    }
