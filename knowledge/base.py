"""The knowledge base: counts n_A and y_{rel,B}, intervals on demand, and Highest Impact First.

Counts follow Figure 1-2 of the paper: n_A counts examinations of objects of type A; y_{rel,B}
(rel in RELATIONS(A)) counts those examinations in which at least one B stood in rel to the
examined object. Only nonzero y are stored (a dict per reference type), so memory is O(nonzero).

Intervals are derived from the counts whenever they are asked for, for every (rel, B) pair, not
only for the pairs observed in the last examination (Figure 2 line 20 updates only those, though
n_S changed for all pairs of S; see DESIGN.md).

The HIF score of a type A (Figure 2, line 11) averages impact(y_{rel,t}, n_A) over rel in
RELATIONS(A) and all t in TYPES. Since most y are 0 the average is computed as
(sum over nonzero y + (R_A*T - nnz_A) * impact(0, n_A)) / (R_A*T): O(nnz of A), not O(T). Scores
are cached per type and invalidated only for the type whose counts change.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from knowledge import intervals
from knowledge.catalog import Catalog
from knowledge.errors import CtxsearchError

ScoreFn = Callable[..., np.ndarray]  # (y, n, alpha) -> per-pair score, vectorised like intervals.impact


@dataclass(frozen=True)
class IntervalRow:
    """One (reference type, relation, related type) interval with its counts."""

    ref: str
    relation: str
    type: str
    y: int
    n: int
    p0: float
    low: float
    high: float

    @property
    def width(self) -> float:
        """high - low."""
        return self.high - self.low


class KnowledgeBase:
    """Counts over a catalog, with intervals, HIF impacts and the HIF choice derived on demand."""

    def __init__(self, catalog: Catalog, alpha: float = intervals.DEFAULT_ALPHA):
        intervals.z_value(alpha)  # validates alpha
        self.catalog = catalog
        self.alpha = float(alpha)
        self._order = {name: i for i, name in enumerate(catalog.type_names)}
        self._n: dict[str, int] = dict.fromkeys(catalog.type_names, 0)
        # ref type -> {(relation, related type): y}, only nonzero entries.
        self._y: dict[str, dict[tuple[str, str], int]] = {name: {} for name in catalog.type_names}
        self._score_cache: dict[str, dict[object, float]] = {}  # ref type -> {score fn: score}

    # ---- counts -------------------------------------------------------------------------------
    def n(self, ref_type: str) -> int:
        """n_A: how many objects of type A have been examined."""
        self._check_type(ref_type)
        return self._n[ref_type]

    def y(self, relation: str, type_name: str) -> int:
        """y_{rel,B}: examinations of rel's reference type with at least one B in rel."""
        rel = self.catalog.relation(relation)
        self._check_type(type_name)
        return self._y[rel.ref].get((relation, type_name), 0)

    def nonzero(self, ref_type: str) -> dict[tuple[str, str], int]:
        """The nonzero y of reference type A, {(relation, type): y} (a copy)."""
        self._check_type(ref_type)
        return dict(self._y[ref_type])

    @property
    def total_examinations(self) -> int:
        """Sum of n over all types."""
        return sum(self._n.values())

    def record_examination(self, ref_type: str, related_pairs: Iterable[tuple[str, str]]) -> None:
        """Figure 2, lines 17-19: increment n_S and, once per distinct (rel, type) pair, y_{rel,type}.

        Every relation must belong to ``ref_type`` and every type must be in the catalog; a pair
        given several times counts once ("at least one B").
        """
        self._check_type(ref_type)
        pairs = set(related_pairs)
        for rel_name, t in pairs:
            rel = self.catalog.relation(rel_name)
            if rel.ref != ref_type:
                raise CtxsearchError(f"relation {rel_name} is not a relation of {ref_type}")
            self._check_type(t)
        self._n[ref_type] += 1
        ys = self._y[ref_type]
        for key in pairs:
            ys[key] = ys.get(key, 0) + 1
        self._invalidate(ref_type)

    def add_counts(self, ref_type: str, n: int, ys: dict[tuple[str, str], int]) -> None:
        """Add pre-aggregated counts (merging or rebuilding from a store)."""
        self._check_type(ref_type)
        self._n[ref_type] += int(n)
        dst = self._y[ref_type]
        for key, v in ys.items():
            if v:
                dst[key] = dst.get(key, 0) + int(v)
        if any(v > self._n[ref_type] for v in dst.values()):
            raise CtxsearchError(f"inconsistent counts for {ref_type}: some y exceeds n")
        self._invalidate(ref_type)

    # ---- intervals ----------------------------------------------------------------------------
    def interval(self, relation: str, type_name: str) -> tuple[float, float]:
        """INT(rel, B) = p0 -/+ d from the current counts; [0, 1] before any data."""
        rel = self.catalog.relation(relation)
        lo, hi = intervals.interval(self.y(relation, type_name), self._n[rel.ref], self.alpha)
        return float(lo), float(hi)

    def rows(self, ref_type: str | None = None, include_zero: bool = True) -> list[IntervalRow]:
        """All intervals (of one reference type, or every type), sorted by lower bound, descending."""
        refs = [ref_type] if ref_type is not None else list(self.catalog.type_names)
        out: list[IntervalRow] = []
        for a in refs:
            self._check_type(a)
            n = self._n[a]
            ys = self._y[a]
            rels = self.catalog.type(a).relation_names
            keys = [(r, t) for r in rels for t in self.catalog.type_names] if include_zero else sorted(ys)
            if not keys:
                continue
            yv = np.array([ys.get(k, 0) for k in keys], float)
            c = np.atleast_1d(intervals.p0(yv, np.full_like(yv, n), self.alpha))
            lo, hi = (np.atleast_1d(v) for v in intervals.interval(yv, np.full_like(yv, n), self.alpha))
            out.extend(
                IntervalRow(a, r, t, int(yy), n, float(cc), float(ll), float(hh))
                for (r, t), yy, cc, ll, hh in zip(keys, yv, c, lo, hi, strict=True)
            )
        out.sort(key=lambda row: (-row.low, row.relation, row.type))
        return out

    def mean_width(self) -> float:
        """Mean interval width over every (A, rel, B) of the catalog (O(nonzero), not O(T^2))."""
        total, count = 0.0, 0
        T = len(self.catalog)
        for a in self.catalog.type_names:
            m = len(self.catalog.type(a).relations) * T
            if m == 0:
                continue
            n = self._n[a]
            yv = np.fromiter(self._y[a].values(), float)
            w0 = 2 * float(intervals.d(0, n, self.alpha))
            total += 2 * float(np.sum(intervals.d(yv, np.full_like(yv, n), self.alpha))) + (m - len(yv)) * w0
            count += m
        return total / count if count else 0.0

    # ---- Highest Impact First -----------------------------------------------------------------
    def type_score(self, ref_type: str, fn: ScoreFn = intervals.impact) -> float:
        """Figure 2, line 11: d_A = average of fn(y_{rel,t}, n_A) over rel in RELATIONS(A), t in TYPES.

        With the default ``fn`` this is the paper's average impact. A type without relations
        scores 0 (examining it teaches nothing).
        """
        cached = self._score_cache.get(ref_type, {}).get(fn)
        if cached is not None:
            return cached
        self._check_type(ref_type)
        m = len(self.catalog.type(ref_type).relations) * len(self.catalog)
        if m == 0:
            score = 0.0
        else:
            n = self._n[ref_type]
            yv = np.fromiter(self._y[ref_type].values(), float)
            s_nz = float(np.sum(fn(yv, np.full_like(yv, n), self.alpha))) if len(yv) else 0.0
            score = (s_nz + (m - len(yv)) * float(fn(0.0, float(n), self.alpha))) / m
        self._score_cache.setdefault(ref_type, {})[fn] = score
        return score

    def type_impact(self, ref_type: str) -> float:
        """The paper's d_A (average impact) for type A."""
        return self.type_score(ref_type, intervals.impact)

    def choose(self, candidate_types: Sequence[str], fn: ScoreFn = intervals.impact) -> str:
        """Figure 2, line 12: the candidate type with the largest score.

        Ties (common: all unseen types score impact(0, 0)) go to the type listed first in the
        catalog, so the choice is deterministic and independent of the candidates' order.
        """
        cands = sorted(set(candidate_types), key=self._order_of)
        if not cands:
            raise CtxsearchError("no candidate types to choose from")
        scores = [self.type_score(t, fn) for t in cands]
        return cands[int(np.argmax(scores))]

    # ---- internals ----------------------------------------------------------------------------
    def _order_of(self, name: str) -> int:
        self._check_type(name)
        return self._order[name]

    def _check_type(self, name: str) -> None:
        if name not in self._n:
            self.catalog.type(name)  # raises a CatalogError naming the known types

    def _invalidate(self, ref_type: str) -> None:
        self._score_cache.pop(ref_type, None)
