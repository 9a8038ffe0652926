"""Intervals that know what the detector could see (``--interval corrected``).

The paper counts an examination of an A as a trial of rel(B) that failed whenever no B was
reported in v_rel(A). With a detector that misses (the realistic preset's recall of a pen at 2 m
is about 0.2), a failed trial is often a B that was there and not seen, and the Wilson interval
is biased low and covers P(rel(B)) less often than promised, the more so the more evidence there
is. The robot knows its detector (the preset's recall curve: a real robot calibrates its own), so
for every examination e it can say, from the images it took, how likely a B standing in
v_rel(A) was to be reported (``q_e``, the *expected recall*), and how likely a B was reported
there when none stood in it (``f_e``, the false-report rate: clutter false positives). The log
keeps both per examination, relation and related type (``agent.exam_views`` computes them;
``knowledge.store``'s ``views`` table, schema 5).

Model. With theta = P(rel(B) | A), examination e reports a B in v_rel(A) with probability

    pi_e(theta) = theta q_e (1 - f_e) + f_e     (a real B reported, or a false one)

independently across examinations. With q_e = 1 and f_e = 0 this is the paper's Bernoulli trial.

Several Bs in one volume. A desk with a pen often has three; at least one of them is reported far
more often than one pen's recall says (in 30 office rooms, pens on desks were found in about 95%
of the desks that had one, where one pen's expected recall was 0.6). A volume that holds a B
holds 1 + M of them, M ~ Poisson(mu) (mu per entry), each reported independently, so at least
one is reported with q'_e = 1 - (1 - q_e) e^{-mu q_e}, which replaces q_e above. The log counts
the objects each examination reported (its observation rows), and mu is estimated per entry by
the method of moments (``multiplicity``): expected reports over expected volumes with a report,
(1 + mu) sum q / sum q'(mu), set equal to the observed (sum d - sum lambda) / (sum y - sum f),
lambda = -ln(1 - f) the false reports; mu is then taken as known (its own uncertainty is not
carried into the interval). With q = 1, q' = 1 whatever mu.

Interval. The score (Rao) interval of this likelihood: every theta with

    U(theta)^2 <= z^2 shrink I(theta),
    U = sum_e (y_e - pi_e) a_e / (pi_e (1 - pi_e)),  I = sum_e a_e^2 / (pi_e (1 - pi_e)),
    a_e = q_e (1 - f_e),

z = z_{alpha/2}. With q_e = 1, f_e = 0 it is exactly Wilson's interval (eq. 1-2; tested), so the
correction is the only difference. ``shrink`` is the clustered interval's n / n_effective of the
entry (``knowledge.clustered``: Kish's design effect times Korn & Graubard's df factor, from the
same per-room counts): examinations in one room are correlated whether or not the detector
misses, so the corrected interval is clustered by room as ``clustered`` is. U is decreasing in
theta; U / sqrt(I) is solved for its bounds by bisection (vectorised over every entry of a
reference type). The point estimate (``kb show``'s p0 column, ``bench intervals``' error and
bias) is the interval's midpoint, as Wilson's p0 (eq. 1) is his interval's: with q_e = 1 and
f_e = 0 the corrected interval and its estimate are the clustered interval's exactly, so a
comparison of the two measures the correction and nothing else. An examination that could not
have shown a B (q_e = 0) carries no evidence about it, and an entry without any is [0, 1] with
estimate 1/2.

What the model leaves out (stated, measured by ``bench intervals``): detections of a related
object in images of the room other than the examination's own (with ``--confirm`` k > 1 an
object confirmed earlier in the room counts with one detection in the examination: q is then a
lower bound); look-alike types reported as B (confusion: a few percent of the look-alike's
recall); pose noise moving a detected B in or out of the volume, or the examined object's own
estimated pose moving the volume (in 30 offices, monitors near cups were found in 36% of the
examinations where 60% of cups have one); a B partly hidden (the recall is read at its whole
face area); the robot examining only the As it detected (those easy to see may stand elsewhere
than the rest). A store written before schema 5,
or by the oracle perception (no detector), has no views: its examinations count with q = 1, f = 0.

HIF on the corrected interval (``KnowledgeBase.type_score_effective``): eq. 3 on the effective
counts n' = sum_e a_e / shrink (the examinations that could have shown a B) and y' = theta_hat n'
(theta_hat: the root of U). Pure numpy.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.clustered import ClusteredIntervals

BISECTIONS = 60  # halvings of [0, 1]: bounds to 1e-18, below float round-off
MU_MAX = 20.0  # the most extra Bs per volume the multiplicity estimate allows
_EPS = 1e-12  # pi is kept in [_EPS, 1 - _EPS]


@dataclass(frozen=True)
class ExamViews:
    """The examinations of one reference type A, in log order: ``d`` (n, R, T) how many
    objects of type t were reported in relation r; ``q`` (n, R, T) the expected recall of a B
    there; ``f`` (n, R, T) the false-report rate there. R: RELATIONS(A) in catalog order, T: the
    catalog's types in catalog order."""

    d: np.ndarray
    q: np.ndarray
    f: np.ndarray

    @property
    def y(self) -> np.ndarray:
        """(n, R, T) bool: at least one B reported (the paper's trial outcome)."""
        return self.d > 0

    @property
    def n(self) -> int:
        """n_A."""
        return int(self.d.shape[0])


def _score(theta: np.ndarray, y: np.ndarray, a: np.ndarray, f: np.ndarray):
    """(U, I) at ``theta`` (E,) for examinations (n, E) of every entry."""
    pi = np.clip(theta[None, :] * a + f, _EPS, 1.0 - _EPS)
    v = pi * (1.0 - pi)
    u = ((y - pi) * a / v).sum(axis=0)
    info = (a * a / v).sum(axis=0)
    return u, info


def multiplicity(d: np.ndarray, q: np.ndarray, f: np.ndarray) -> np.ndarray:
    """mu (E,): the mean number of *extra* Bs in a volume that holds at least one, per entry,
    from examinations (n, E) that reported ``d`` Bs with expected recall ``q`` and false-report
    rate ``f`` (module docstring): the root of
    (1 + mu) sum q / sum (1 - (1 - q) e^{-mu q}) = (sum d - sum lambda) / (sum y - sum f),
    lambda = -ln(1 - f); 0 where no more Bs were reported than volumes with one, ``MU_MAX`` at
    most."""
    d = np.asarray(d, float)
    y = (d > 0).astype(float)
    lam = -np.log1p(-np.minimum(f, 1.0 - 1e-12))
    hits = np.maximum(y.sum(0) - f.sum(0), 0.0)
    count = np.maximum(d.sum(0) - lam.sum(0), 0.0)
    sum_q = q.sum(0)

    def gap(mu: np.ndarray) -> np.ndarray:  # increasing in mu; its root is the estimate
        found = (1.0 - (1.0 - q) * np.exp(-mu[None, :] * q)).sum(0)
        return (1.0 + mu) * sum_q * hits - count * found

    e = d.shape[1]
    lo, hi = np.zeros(e), np.full(e, MU_MAX)
    mu = _bisect(lambda m: -gap(m), lo, hi)
    mu = np.where(gap(lo) >= 0, 0.0, mu)
    return np.where(gap(hi) <= 0, MU_MAX, mu)


def _bisect(fn, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The root of the decreasing ``fn`` (E,) -> (E,) in [lo, hi] per entry (lo where fn(lo) <=
    0, hi where fn(hi) >= 0)."""
    lo, hi = lo.copy(), hi.copy()
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        pos = fn(mid) > 0
        lo = np.where(pos, mid, lo)
        hi = np.where(pos, hi, mid)
    return 0.5 * (lo + hi)


def score_intervals(
    y: np.ndarray, q: np.ndarray, f: np.ndarray, alpha: float, shrink: np.ndarray | float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(low, high, theta_hat, information) per entry for examinations ``y``, ``q``, ``f`` (n, E)
    (module docstring); ``shrink`` (E,) or a scalar. ``information`` is sum_e a_e: the
    examinations that could have shown a B. Entries without information get [0, 1], theta 0.5."""
    y = np.asarray(y, float)
    a = np.asarray(q, float) * (1.0 - np.asarray(f, float))
    f = np.asarray(f, float)
    e = y.shape[1]
    c = intervals.z_value(alpha) * np.sqrt(np.broadcast_to(np.asarray(shrink, float), (e,)))
    zeros, ones = np.zeros(e), np.ones(e)
    theta = _bisect(lambda t: _score(t, y, a, f)[0], zeros, ones)

    def standardised(t: np.ndarray) -> np.ndarray:
        u, info = _score(t, y, a, f)
        return u / np.sqrt(np.maximum(info, 1e-300))

    low = _bisect(lambda t: standardised(t) - c, zeros, theta)
    high = _bisect(lambda t: standardised(t) + c, theta, ones)
    low = np.where(standardised(zeros) <= c, 0.0, low)
    high = np.where(standardised(ones) >= -c, 1.0, high)
    information = a.sum(axis=0)
    none = information <= 0
    return (
        np.where(none, 0.0, low),
        np.where(none, 1.0, high),
        np.where(none, 0.5, theta),
        information,
    )


@dataclass(frozen=True)
class _TypeIntervals:
    low: np.ndarray  # (R, T)
    high: np.ndarray
    theta: np.ndarray
    n_eff: np.ndarray  # effective counts for eq. 3 (module docstring)
    y_eff: np.ndarray


class CorrectedIntervals:
    """The corrected intervals of every (A, rel, B) of the reference types in ``views``
    (module docstring), clustered with ``clustered``'s shrink factors; all computed at once."""

    def __init__(
        self,
        views: Mapping[str, ExamViews],
        clustered: ClusteredIntervals,
        relations: Mapping[str, tuple[str, ...]],
        types: tuple[str, ...],
        alpha: float = intervals.DEFAULT_ALPHA,
    ):
        self.alpha, self.types = float(alpha), tuple(types)
        self.relations = dict(relations)  # RELATIONS(A) per reference type, catalog order
        self._by_ref: dict[str, _TypeIntervals] = {}
        for ref, v in views.items():
            if v.n == 0:
                continue
            rels = relations[ref]
            r_n, t_n = len(rels), len(types)
            shrink = np.array(
                [clustered.shrink(ref, (rel, t)) for rel in rels for t in types], float
            )
            d, q, f = (x.reshape(v.n, -1) for x in (v.d, v.q, v.f))
            mu = multiplicity(d, q, f)
            q_any = 1.0 - (1.0 - q) * np.exp(-mu[None, :] * q)  # at least one of 1 + M seen
            lo, hi, th, info = score_intervals(d > 0, q_any, f, alpha, shrink)
            n_eff = info / shrink
            self._by_ref[ref] = _TypeIntervals(
                *(x.reshape(r_n, t_n) for x in (lo, hi, th, n_eff, th * n_eff))
            )
        self._rel_index = {
            ref: {r: i for i, r in enumerate(rels)} for ref, rels in relations.items()
        }
        self._type_index = {t: i for i, t in enumerate(types)}

    def _at(self, ref: str, relation: str, type_name: str):
        ti = self._by_ref.get(ref)
        if ti is None:
            return None
        return ti, self._rel_index[ref][relation], self._type_index[type_name]

    def interval(self, ref: str, relation: str, type_name: str) -> tuple[float, float]:
        """The corrected interval of (A, rel, B); [0, 1] where A was never examined."""
        at = self._at(ref, relation, type_name)
        if at is None:
            return 0.0, 1.0
        ti, r, b = at
        return float(ti.low[r, b]), float(ti.high[r, b])

    def effective(self, ref: str, relation: str, type_name: str) -> tuple[float, float] | None:
        """(y', n') of (A, rel, B): the effective counts eq. 3 reads (module docstring; the
        backoff's, knowledge.pooling); None where A was never examined."""
        at = self._at(ref, relation, type_name)
        if at is None:
            return None
        ti, r, b = at
        return float(ti.y_eff[r, b]), float(ti.n_eff[r, b])

    def arrays(self, ref: str) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(low, high, estimate), each (R, T), of reference type ``ref`` (the estimate: the
        interval's midpoint, module docstring; None: never examined)."""
        ti = self._by_ref.get(ref)
        return None if ti is None else (ti.low, ti.high, (ti.low + ti.high) / 2)

    def entries(
        self, ref: str, r_idx: np.ndarray, b_idx: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(low, high, estimate) of ``ref``'s entries (relation index, type index): [0, 1]
        and 1/2 where ``ref`` was never examined."""
        arrs = self.arrays(ref)
        if arrs is None:
            k = len(r_idx)
            return np.zeros(k), np.ones(k), np.full(k, 0.5)
        lo, hi, est = (x[r_idx, b_idx] for x in arrs)
        return lo, hi, est

    def mean_width(self) -> float:
        """The mean width over every (A, rel, B) of the catalog (a never-examined A: 1)."""
        total, count = 0.0, 0
        for ref, rels in self._rel_index.items():
            m = len(rels) * len(self.types)
            arrs = self.arrays(ref)
            total += m * 1.0 if arrs is None else float(np.sum(arrs[1] - arrs[0]))
            count += m
        return total / count if count else 0.0

    def type_score(self, ref: str, fn) -> float | None:
        """Eq. 3's average (``fn(y, n, alpha)``, vectorised) over ``ref``'s entries on the
        effective counts (y', n') (module docstring); None where ``ref`` was never examined."""
        ti = self._by_ref.get(ref)
        if ti is None or not ti.n_eff.size:
            return None
        return float(np.mean(fn(ti.y_eff, ti.n_eff, self.alpha)))
