"""The knowledge base: counts n_A and y_{rel,B}, intervals on demand, and Highest Impact First.

Counts follow Figure 1-2 of the paper: n_A counts examinations of objects of type A; y_{rel,B}
(rel in RELATIONS(A)) counts those examinations in which at least one B stood in rel to the
examined object.

Storage is O(nonzero y), compact enough for the paper's 30 000 types: per reference type A, the
nonzero y are kept as two small numpy arrays in CSR form over RELATIONS(A) (the related type's
index, uint16 for up to 65 536 types, and y, in the smallest unsigned dtype that holds n_A), plus
the per-relation offsets. A type never examined with a related object costs nothing.

Intervals are derived from the counts whenever they are asked for, for every (rel, B) pair, not
only for the pairs observed in the last examination (Figure 2 line 20 updates only those, though
n_S changed for all pairs of S: deriving them on demand keeps every pair's interval true to
its counts).

The HIF score of a type A (Figure 2, line 11) averages impact(y_{rel,t}, n_A) over rel in
RELATIONS(A) and all t in TYPES. Most y are 0, so the average is
(sum over nonzero y + (R_A*T - nnz_A) * impact(0, n_A)) / (R_A*T), and since the score depends
only on the multiset of y values, impact is evaluated once per distinct y (at most n_A + 1 of
them): O(nnz_A) with a small constant, never O(T). A choice scores all its uncached candidates
in one numpy pass. Scores are cached per type and invalidated only for the type whose counts
change.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.clustered import ClusteredIntervals
from ctxsearch.knowledge.corrected import CorrectedIntervals
from ctxsearch.knowledge.errors import CtxsearchError

# (y, n, alpha) -> per-pair score, vectorised like intervals.impact.
ScoreFn = Callable[..., np.ndarray]


@dataclass(frozen=True)
class IntervalRow:
    """One (reference type, relation, related type) interval with its counts."""

    ref: str
    relation: str
    type: str
    y: int | float  # counts; effective (float) counts under forgetting (knowledge.drift)
    n: int | float
    p0: float
    low: float
    high: float

    @property
    def width(self) -> float:
        """high - low."""
        return self.high - self.low


def _count_dtype(n: int) -> type[np.unsignedinteger]:
    """The smallest unsigned dtype that holds every y <= n."""
    if n <= np.iinfo(np.uint16).max:
        return np.uint16
    if n <= np.iinfo(np.uint32).max:
        return np.uint32
    return np.uint64


class _Counts:
    """The nonzero y of one reference type, CSR over its relations.

    Entries of relation r (local index in RELATIONS(A)) are ``types[offs[r]:offs[r+1]]`` (sorted
    related-type indices) with counts ``ys[offs[r]:offs[r+1]]``.
    """

    __slots__ = ("offs", "types", "ys")

    def __init__(self, n_rel: int, type_dtype, count_dtype):
        self.offs = np.zeros(n_rel + 1, np.int64)
        self.types = np.empty(0, type_dtype)
        self.ys = np.empty(0, count_dtype)

    def find(self, r: int, b: int) -> tuple[int, bool]:
        """(position, present) of (r, b): where it is, or where it would be inserted."""
        lo, hi = int(self.offs[r]), int(self.offs[r + 1])
        i = lo + int(np.searchsorted(self.types[lo:hi], b))
        return i, (i < hi and int(self.types[i]) == b)

    def get(self, r: int, b: int) -> int:
        i, present = self.find(r, b)
        return int(self.ys[i]) if present else 0

    def relation_of_entries(self) -> np.ndarray:
        """The local relation index of every stored entry."""
        return np.repeat(np.arange(len(self.offs) - 1), np.diff(self.offs))

    def increment(self, pairs: Sequence[tuple[int, int]]) -> None:
        """Add 1 to y of every (r, b) in ``pairs`` (distinct), inserting the new ones."""
        new_pos, new_r, new_b = [], [], []
        for r, b in sorted(pairs):
            i, present = self.find(r, b)
            if present:
                self.ys[i] += 1
            else:
                new_pos.append(i)
                new_r.append(r)
                new_b.append(b)
        if new_pos:
            # Positions refer to the arrays before insertion; equal positions keep the (r, b)
            # order, so the segments stay sorted.
            self.types = np.insert(self.types, new_pos, np.asarray(new_b, self.types.dtype))
            self.ys = np.insert(self.ys, new_pos, np.ones(len(new_pos), self.ys.dtype))
            self.offs[1:] += np.cumsum(np.bincount(new_r, minlength=len(self.offs) - 1))

    def replace(self, codes: np.ndarray, ys: np.ndarray, n_types: int, count_dtype) -> None:
        """Set the entries from sorted unique codes r * T + b and their (positive) counts."""
        r = codes // n_types
        self.types = (codes - r * n_types).astype(self.types.dtype)
        self.ys = ys.astype(count_dtype)
        self.offs = np.searchsorted(r, np.arange(len(self.offs)), side="left").astype(np.int64)

    def codes(self, n_types: int) -> np.ndarray:
        """Every stored entry as the code r * T + b (int64, sorted)."""
        return self.relation_of_entries().astype(np.int64) * n_types + self.types.astype(np.int64)


def _d_fixed_n(y: np.ndarray, n: float, z: float) -> np.ndarray:
    """Eq. 2 for a vector of y and one n > 0 (same values as intervals.d, fewer numpy passes)."""
    z2 = z * z
    scale = z / np.sqrt(n) / (1.0 + z2 / n)
    return scale * np.sqrt(y * (n - y) * (1.0 / (n * n)) + z2 / (4.0 * n))


def _d_of_types(y: np.ndarray, n: np.ndarray, lens: np.ndarray, z: float) -> np.ndarray:
    """``_d_fixed_n`` for values ``y`` of several types in runs, run j of ``lens[j]`` values
    with n = ``n[j]``: what depends on n alone is computed once per run, then repeated. The same
    operations on the same operands, so the same bits as ``_d_fixed_n`` run by run."""
    z2 = z * z
    scale = np.repeat(z / np.sqrt(n) / (1.0 + z2 / n), lens)
    inv, c = np.repeat(1.0 / (n * n), lens), np.repeat(z2 / (4.0 * n), lens)
    t = np.repeat(n, lens)
    np.subtract(t, y, out=t)
    np.multiply(t, y, out=t)  # y * (n - y): multiplication commutes bit for bit
    t *= inv
    t += c
    np.sqrt(t, out=t)
    t *= scale
    return t


def _impact_values(k: np.ndarray, n: np.ndarray, lens: np.ndarray, z: float) -> np.ndarray:
    """Eq. 3 for values ``k`` of several types in runs (``_d_of_types``; every n > 0), with
    ``_d_fixed_n``'s operations in their order: only +, -, *, / and sqrt, each correctly
    rounded, so a value's bits do not depend on the other values, and equal those of one n at a
    time (within 1e-14 of intervals.impact)."""
    d0 = _d_of_types(k, n, lens, z)
    d1 = _d_of_types(k, n + 1.0, lens, z)
    d2 = _d_of_types(k + 1.0, n + 1.0, lens, z)
    np.subtract(d1, d0, out=d1)
    np.subtract(d2, d0, out=d2)
    np.abs(d1, out=d1)
    np.abs(d2, out=d2)
    np.maximum(d1, d2, out=d1)
    d1 *= 2.0
    return d1


def _impact_fixed_n(y: np.ndarray, n: int, alpha: float) -> np.ndarray:
    """Eq. 3 for a vector of y and one n (same values as intervals.impact, within round-off)."""
    if n == 0:
        return np.broadcast_to(np.asarray(intervals.impact(0.0, 0.0, alpha)), y.shape)
    y = np.asarray(y, float)
    return _impact_values(y, np.array([float(n)]), np.array([len(y)]), intervals.z_value(alpha))


def _score_terms(ys: np.ndarray | None, m: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(k, w): a score's average over a type's m entries as sum w fn(k, n) / m, from its nonzero
    counts ``ys``: each distinct y once with its multiplicity where few distinct values are
    possible (y <= n), else every nonzero y once and the zeros together."""
    nnz = 0 if ys is None else len(ys)
    if nnz == 0:
        return np.zeros(1), np.array([float(m)])
    if _few_values(n, nnz):
        hist = np.bincount(ys if ys.dtype != np.uint64 else ys.astype(np.int64))
        hist[0] = m - nnz
        k = np.flatnonzero(hist)
        return k.astype(float), hist[k].astype(float)
    w = np.ones(nnz + 1)
    w[0] = m - nnz
    return np.concatenate([[0.0], ys.astype(float)]), w


def _few_values(n, nnz):
    """Whether a type's counts are tallied by value (a histogram over 0..n) rather than listed:
    where n is small against its nonzero counts (scalars or arrays)."""
    return n <= 4 * nnz + 64


def _impact_scores(kb: KnowledgeBase, types: Sequence[int]) -> np.ndarray:
    """The paper's d_A of each type index in ``types`` in one numpy pass (the module docstring's
    sum): the types' value tallies in one bincount, eq. 3 on all of them at once
    (``_impact_values``), each type's weighted sum its own dot product. A type's score depends
    only on its own counts, in the same order, whichever types share the batch: one at a time or
    fifty, the same bits, and the bits of the per-type computation this replaced (so the same
    HIF choices where round-off decides a tie of equal scores: impact(y, n) = impact(n - y, n)).
    Types without relations score 0; never-examined ones impact(0, 0)."""
    idx = np.asarray(types, np.int64)
    m, n = kb._n_rel[idx] * kb._T, kb._n[idx]
    counts = [kb._counts[a] for a in types]
    nnz = np.array([0 if c is None else len(c.ys) for c in counts], np.int64)
    out = np.zeros(len(idx))
    out[(m > 0) & (n == 0)] = _impact_unseen(kb.alpha)
    live = (m > 0) & (n > 0)
    hist = live & _few_values(n, nnz)
    k_parts, w_parts, order = [], [], []  # order: (types, how many values each)
    h = np.flatnonzero(hist)
    if len(h):
        width = n[h] + 1
        off = np.concatenate([[0], np.cumsum(width)[:-1]])
        keys = np.repeat(off, nnz[h])
        ys = [counts[j].ys for j in h if counts[j] is not None]
        if ys:
            keys += np.concatenate(ys).astype(np.int64)
        tally = np.bincount(keys, minlength=int(width.sum()))
        tally[off] = m[h] - nnz[h]  # the zeros (a nonzero y never lands on a type's bin 0)
        at = np.flatnonzero(tally)
        per = np.add.reduceat(tally != 0, off)
        k_parts.append((at - np.repeat(off, per)).astype(float))
        w_parts.append(tally[at].astype(float))
        order.append((h, per))
    r = np.flatnonzero(live & ~hist)  # few nonzero y against a large n: listed, zeros first
    if len(r):
        size = nnz[r] + 1
        first = np.concatenate([[0], np.cumsum(size)[:-1]])
        k = np.zeros(int(size.sum()))
        listed = np.ones(len(k), bool)
        listed[first] = False
        ys = [counts[j].ys for j in r if counts[j] is not None]
        if ys:
            k[listed] = np.concatenate(ys)
        w = np.ones(len(k))
        w[first] = m[r] - nnz[r]
        k_parts.append(k)
        w_parts.append(w)
        order.append((r, size))
    if k_parts:
        k, w = np.concatenate(k_parts), np.concatenate(w_parts)
        runs = np.concatenate([t for t, _ in order])  # the types, in the order of their values
        lens = np.concatenate([c for _, c in order])
        vals = _impact_values(k, n[runs].astype(float), lens, intervals.z_value(kb.alpha))
        start = 0
        for j, end in zip(runs.tolist(), np.cumsum(lens).tolist(), strict=True):
            # its own dot product, as for the type alone: the same bits
            out[j] = float(w[start:end] @ vals[start:end]) / int(m[j])
            start = end
    return out


@functools.lru_cache(maxsize=16)
def _impact_unseen(alpha: float) -> float:
    """impact(0, 0): eq. 3 for an entry of a never-examined type."""
    return float(np.asarray(intervals.impact(0.0, 0.0, alpha)))


class KnowledgeBase:
    """Counts over a catalog, with intervals, HIF impacts and the HIF choice derived on demand."""

    def __init__(self, catalog: Catalog, alpha: float = intervals.DEFAULT_ALPHA):
        intervals.z_value(alpha)  # validates alpha
        self.catalog = catalog
        self.alpha = float(alpha)
        names = catalog.type_names
        self._names = names
        self._T = len(names)
        self._order = {name: i for i, name in enumerate(names)}
        self._n_rel = np.array([len(t.relations) for t in catalog.types], np.int64)
        self._n = np.zeros(self._T, np.int64)
        self._type_dtype = np.uint16 if self._T <= 1 << 16 else np.uint32
        # Per reference type (catalog order): its nonzero y, or None while it has none.
        self._counts: list[_Counts | None] = [None] * self._T
        self._score_cache: dict[int, dict[object, float]] = {}  # type index -> {score fn: score}
        # The interval reads (interval, rows, mean_width): None is the paper's Wilson; else the
        # clustered intervals (knowledge.clustered), or the corrected ones. HIF reads raw counts.
        self.clustered: ClusteredIntervals | None = None
        self.corrected: CorrectedIntervals | None = None

    def use_clustered(self, clustered: ClusteredIntervals | None) -> None:
        """Read intervals with ``clustered`` (its per-room counts must be this KB's evidence), or
        with Wilson again (None). The counts and the HIF choice are unchanged."""
        self.clustered, self.corrected = clustered, None

    def use_corrected(self, corrected: CorrectedIntervals | None) -> None:
        """``use_clustered`` for the corrected intervals (knowledge.corrected) of this KB's log."""
        self.clustered, self.corrected = None, corrected

    @property
    def interval_method(self) -> str:
        """'wilson', 'clustered' or 'corrected': how ``interval``, ``rows``, ``mean_width`` read."""
        on = self.corrected is not None
        return "corrected" if on else ("wilson" if self.clustered is None else "clustered")

    def _shrink(self, ref: str, relation: str, type_names: Sequence[str]) -> np.ndarray:
        """n / n_effective of the entries (ref, relation, t) (ones under Wilson)."""
        if self.clustered is None:
            return np.ones(len(type_names))
        return np.array([self.clustered.shrink(ref, (relation, t)) for t in type_names])

    # ---- counts -------------------------------------------------------------------------------
    def n(self, ref_type: str) -> int:
        """n_A: how many objects of type A have been examined."""
        return int(self._n[self._idx(ref_type)])

    def y(self, relation: str, type_name: str) -> int:
        """y_{rel,B}: examinations of rel's reference type with at least one B in rel."""
        a, r = self._rel(relation)
        b = self._idx(type_name)
        c = self._counts[a]
        return 0 if c is None else c.get(r, b)

    def nonzero(self, ref_type: str) -> dict[tuple[str, str], int]:
        """The nonzero y of reference type A, {(relation, type): y} (a copy)."""
        a = self._idx(ref_type)
        c = self._counts[a]
        if c is None:
            return {}
        rels = self.catalog.types[a].relation_names
        names = self._names
        return {
            (rels[r], names[b]): int(v)
            for r, b, v in zip(c.relation_of_entries(), c.types, c.ys, strict=True)
        }

    def nnz(self, ref_type: str | None = None) -> int:
        """How many y are nonzero (of one reference type, or in all)."""
        if ref_type is not None:
            c = self._counts[self._idx(ref_type)]
            return 0 if c is None else len(c.ys)
        return sum(len(c.ys) for c in self._counts if c is not None)

    @property
    def total_examinations(self) -> int:
        """Sum of n over all types."""
        return int(self._n.sum())

    def record_examination(self, ref_type: str, related_pairs: Iterable[tuple[str, str]]) -> None:
        """Figure 2, lines 17-19: increment n_S and, once per distinct (rel, type) pair, y_{rel,type}.

        Every relation must belong to ``ref_type`` and every type must be in the catalog; a pair
        given several times counts once ("at least one B"). Nothing changes if any pair is bad.
        """
        a = self._idx(ref_type)
        local = set()
        for rel_name, t in set(related_pairs):
            ra, r = self._rel(rel_name)
            if ra != a:
                raise CtxsearchError(f"relation {rel_name} is not a relation of {ref_type}")
            local.add((r, self._idx(t)))
        self._n[a] += 1
        c = self._counts[a]
        if c is None and local:
            c = self._counts[a] = _Counts(int(self._n_rel[a]), self._type_dtype, np.uint16)
        if c is not None:
            need = _count_dtype(int(self._n[a]))
            if np.dtype(need).itemsize > c.ys.dtype.itemsize:
                c.ys = c.ys.astype(need)
            if local:
                c.increment(list(local))
        self._invalidate(a)

    def add_counts(self, ref_type: str, n: int, ys: dict[tuple[str, str], int]) -> None:
        """Add pre-aggregated counts (merging or rebuilding from a store)."""
        a = self._idx(ref_type)
        rel_idx, type_idx, vals = [], [], []
        for (rel_name, t), v in ys.items():
            ra, r = self._rel(rel_name)
            if ra != a:
                raise CtxsearchError(f"relation {rel_name} is not a relation of {ref_type}")
            rel_idx.append(r)
            type_idx.append(self._idx(t))
            vals.append(int(v))
        self.add_count_arrays(ref_type, n, rel_idx, type_idx, vals)

    def add_count_arrays(self, ref_type: str, n: int, rel_index, type_index, y) -> None:
        """Add pre-aggregated counts given as arrays, vectorised (bulk loading, benchmarks).

        ``rel_index`` is each entry's relation as an index into RELATIONS(ref_type), ``type_index``
        the related type's index in catalog order, ``y`` its count; repeated entries are summed.
        Raises CtxsearchError (and changes nothing) on out-of-range indices, negative counts, or a
        resulting y larger than n.
        """
        a = self._idx(ref_type)
        n = int(n)
        rel_index = np.asarray(rel_index, np.int64).ravel()
        type_index = np.asarray(type_index, np.int64).ravel()
        y = np.asarray(y, np.int64).ravel()
        if not len(rel_index) == len(type_index) == len(y):
            raise CtxsearchError("add_count_arrays: rel_index, type_index and y differ in length")
        n_rel, T = int(self._n_rel[a]), self._T
        if n < 0 or (
            len(y)
            and (
                y.min() < 0
                or rel_index.min() < 0
                or rel_index.max() >= n_rel
                or type_index.min() < 0
                or type_index.max() >= T
            )
        ):
            raise CtxsearchError(f"counts for {ref_type} out of range (negative or unknown index)")
        new_n = int(self._n[a]) + n
        keep = y > 0
        codes, y = rel_index[keep] * T + type_index[keep], y[keep]
        c = self._counts[a]
        if c is not None and len(c.ys):
            codes = np.concatenate([c.codes(T), codes])
            y = np.concatenate([c.ys.astype(np.int64), y])
        if len(codes):
            if len(codes) > 1 and not np.all(codes[1:] > codes[:-1]):
                codes, inverse = np.unique(codes, return_inverse=True)
                y = np.bincount(inverse, weights=y, minlength=len(codes)).astype(np.int64)
            if int(y.max()) > new_n:
                raise CtxsearchError(f"inconsistent counts for {ref_type}: some y exceeds n")
            if c is None:
                c = self._counts[a] = _Counts(n_rel, self._type_dtype, np.uint16)
            c.replace(codes, y, T, _count_dtype(new_n))
        elif c is not None:
            c.ys = c.ys.astype(_count_dtype(new_n))
        self._n[a] = new_n
        self._invalidate(a)

    # ---- intervals ----------------------------------------------------------------------------
    def interval(self, relation: str, type_name: str) -> tuple[float, float]:
        """INT(rel, B) = p0 -/+ d from the current counts; [0, 1] before any data."""
        a, _ = self._rel(relation)
        y, n = self.y(relation, type_name), int(self._n[a])
        if self.corrected is not None:
            return self.corrected.interval(self._names[a], relation, type_name)
        if self.clustered is not None:
            return self.clustered.interval(self._names[a], (relation, type_name), y, n)
        lo, hi = intervals.interval(y, n, self.alpha)
        return float(lo), float(hi)

    def rows(self, ref_type: str | None = None, include_zero: bool = True) -> list[IntervalRow]:
        """All intervals (of one reference type, or every type), sorted by lower bound, descending.

        Ties go by relation, then type name. ``include_zero=False`` keeps only the pairs with y > 0.
        """
        refs = [self._idx(ref_type)] if ref_type is not None else range(self._T)
        out: list[IntervalRow] = []
        names = self._names
        for a in refs:
            n_rel = int(self._n_rel[a])
            if n_rel == 0:
                continue
            n = int(self._n[a])
            c = self._counts[a]
            rels = self.catalog.types[a].relation_names
            if include_zero:
                dense = np.zeros((n_rel, self._T), np.int64)
                if c is not None:
                    dense[c.relation_of_entries(), c.types.astype(np.int64)] = c.ys
                r_idx = np.repeat(np.arange(n_rel), self._T)
                b_idx = np.tile(np.arange(self._T), n_rel)
                yv = dense.ravel()
            elif c is None or not len(c.ys):
                continue
            else:
                r_idx, b_idx, yv = (
                    c.relation_of_entries(),
                    c.types.astype(np.int64),
                    c.ys.astype(np.int64),
                )
            yf = yv.astype(float)
            nf = np.full_like(yf, n)
            if self.clustered is not None and n:
                f = self._shrink_entries(a, r_idx, b_idx)
                yf, nf = yf / f, nf / f
            centre = np.atleast_1d(intervals.p0(yf, nf, self.alpha))
            lo, hi = (np.atleast_1d(v) for v in intervals.interval(yf, nf, self.alpha))
            if self.corrected is not None:
                lo, hi, centre = self.corrected.entries(names[a], r_idx, b_idx)
            out.extend(
                IntervalRow(
                    names[a], rels[r], names[b], int(yy), n, float(cc), float(ll), float(hh)
                )
                for r, b, yy, cc, ll, hh in zip(r_idx, b_idx, yv, centre, lo, hi, strict=True)
            )
        out.sort(key=lambda row: (-row.low, row.relation, row.type))
        return out

    def _shrink_entries(self, a: int, r_idx: np.ndarray, b_idx: np.ndarray) -> np.ndarray:
        """Shrink factors of reference type a's entries (relation index, type index); the
        entries with y = 0 share one factor (knowledge.clustered)."""
        cl = self.clustered
        assert cl is not None
        ref, rels = self._names[a], self.catalog.types[a].relation_names
        zero = cl.shrink(ref, ("", ""))  # no per-room y: the type's pooled correlation
        out = np.full(len(r_idx), zero)
        counts = cl.counts.get(ref)
        if counts is None:
            return out
        pos = {
            (rels[int(r)], self._names[int(b)]): i
            for i, (r, b) in enumerate(zip(r_idx, b_idx, strict=True))
        }
        for key in counts.y_room:
            i = pos.get(key)
            if i is not None:
                out[i] = cl.shrink(ref, key)
        return out

    def mean_width(self) -> float:
        """Mean interval width over every (A, rel, B) of the catalog (O(nonzero), not O(T^2))."""
        if self.corrected is not None:
            return self.corrected.mean_width()
        if self.clustered is not None:
            return self._mean_width_clustered()
        total, count = 0.0, 0
        z = intervals.z_value(self.alpha)
        for a in range(self._T):
            m = int(self._n_rel[a]) * self._T
            if m == 0:
                continue
            n = int(self._n[a])
            c = self._counts[a]
            nnz = 0 if c is None else len(c.ys)
            if n == 0:
                total += m * 1.0
            else:
                w0 = 2 * float(_d_fixed_n(np.zeros(1), float(n), z)[0])
                s_nz = (
                    2 * float(np.sum(_d_fixed_n(c.ys.astype(float), float(n), z))) if nnz else 0.0
                )
                total += s_nz + (m - nnz) * w0
            count += m
        return total / count if count else 0.0

    def _mean_width_clustered(self) -> float:
        """``mean_width`` on the clustered intervals' effective counts."""
        cl = self.clustered
        assert cl is not None
        total, count = 0.0, 0
        for a in range(self._T):
            m = int(self._n_rel[a]) * self._T
            if m == 0:
                continue
            n = int(self._n[a])
            c = self._counts[a]
            nnz = 0 if c is None else len(c.ys)
            if n == 0:
                total += m * 1.0
            else:
                f0 = cl.shrink(self._names[a], ("", ""))
                lo, hi = intervals.interval(0.0, n / f0, self.alpha)
                total += (m - nnz) * float(hi - lo)
                if nnz:
                    r_idx, b_idx = c.relation_of_entries(), c.types.astype(np.int64)
                    f = self._shrink_entries(a, r_idx, b_idx)
                    lo, hi = intervals.interval(c.ys.astype(float) / f, n / f, self.alpha)
                    total += float(np.sum(np.asarray(hi) - np.asarray(lo)))
            count += m
        return total / count if count else 0.0

    def type_score_effective(self, ref_type: str, fn: ScoreFn = intervals.impact) -> float:
        """``type_score`` with impact on the clustered intervals' effective counts (y/f, n/f) or
        the corrected ones' (Wilson: ``type_score``). Not cached: a measurement, not HIF's path."""
        if self.corrected and (score := self.corrected.type_score(ref_type, fn)) is not None:
            return score  # (never examined: raw counts, as below: clustered is None then)
        if self.clustered is None:
            return self.type_score(ref_type, fn)
        a = self._idx(ref_type)
        m = int(self._n_rel[a]) * self._T
        n = int(self._n[a])
        if m == 0:
            return 0.0
        c = self._counts[a]
        f0 = self.clustered.shrink(ref_type, ("", ""))
        nnz = 0 if c is None else len(c.ys)
        total = (m - nnz) * float(fn(0.0, n / f0, self.alpha))
        if nnz:
            f = self._shrink_entries(a, c.relation_of_entries(), c.types.astype(np.int64))
            total += float(np.sum(fn(c.ys.astype(float) / f, n / f, self.alpha)))
        return total / m

    # ---- Highest Impact First -----------------------------------------------------------------
    def type_score(self, ref_type: str, fn: ScoreFn = intervals.impact) -> float:
        """Figure 2, line 11: d_A = average of fn(y_{rel,t}, n_A) over rel in RELATIONS(A), t in TYPES.

        With the default ``fn`` this is the paper's average impact. A type without relations
        scores 0 (examining it teaches nothing). ``fn`` must be vectorised over y for a scalar n.
        """
        a = self._idx(ref_type)
        cache = self._score_cache.get(a)
        if cache is not None and fn in cache:
            return cache[fn]
        score = self._compute_score(a, fn)
        self._score_cache.setdefault(a, {})[fn] = score
        return score

    def type_impact(self, ref_type: str) -> float:
        """The paper's d_A (average impact) for type A."""
        return self.type_score(ref_type, intervals.impact)

    def choose(self, candidate_types: Sequence[str], fn: ScoreFn = intervals.impact) -> str:
        """Figure 2, line 12: the candidate type with the largest score.

        Ties (common: all unseen types score impact(0, 0)) go to the type listed first in the
        catalog, so the choice is deterministic and independent of the candidates' order. Scores
        equal only in exact arithmetic (impact(y, n) = impact(n - y, n), so two types with n = 1
        tie whatever they saw) can differ in the last bit, which then decides; kept as it is
        because making them exact ties would change every learned store's order.
        """
        cands = sorted({self._idx(t) for t in candidate_types})
        if not cands:
            raise CtxsearchError("no candidate types to choose from")
        names = self._names
        if fn is intervals.impact:
            scores = _cached_impacts(self, cands)
        else:
            scores = [self.type_score(names[a], fn) for a in cands]
        return names[cands[max(range(len(cands)), key=scores.__getitem__)]]

    def clear_cache(self) -> None:
        """Forget every cached type score (benchmarks use it to time cold choices)."""
        self._score_cache.clear()

    # ---- internals ----------------------------------------------------------------------------
    def _compute_score(self, a: int, fn: ScoreFn) -> float:
        if fn is intervals.impact:
            return float(_impact_scores(self, [a])[0])
        m = int(self._n_rel[a]) * self._T
        if m == 0:
            return 0.0
        n = int(self._n[a])
        c = self._counts[a]
        k, w = _score_terms(c.ys if c is not None else None, m, n)
        vals = np.broadcast_to(np.asarray(fn(k, float(n), self.alpha), float), k.shape)
        return float(w @ vals) / m

    def _idx(self, name: str) -> int:
        """The catalog index of type ``name`` (CatalogError naming the known types if unknown)."""
        i = self._order.get(name)
        if i is None:
            self.catalog.type(name)  # raises a CatalogError naming the known types
            raise AssertionError(name)  # pragma: no cover
        return i

    def _rel(self, relation: str) -> tuple[int, int]:
        """(reference type index, local index in RELATIONS(ref)) of relation ``relation``."""
        rel = self.catalog.relation(relation)
        a = self._order[rel.ref]
        return a, self.catalog.types[a].relations.index(rel)

    def _invalidate(self, a: int) -> None:
        self._score_cache.pop(a, None)


def _cached_impacts(kb: KnowledgeBase, types: Sequence[int]) -> list[float]:
    """The paper's d_A of several types of ``kb``, those not cached computed at once
    (``_impact_scores``, the same bits as one at a time) and cached."""
    cache = kb._score_cache
    todo = [a for a in types if intervals.impact not in cache.get(a, ())]
    if todo:
        for a, score in zip(todo, _impact_scores(kb, todo).tolist(), strict=True):
            cache.setdefault(a, {})[intervals.impact] = score
    return [cache[a][intervals.impact] for a in types]
