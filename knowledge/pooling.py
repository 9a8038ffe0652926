"""Evidence pooled over the type hierarchy (knowledge/hierarchy.py), and backoff for rare types.

Pooled counts (``PooledCounts``), derived from the same evidence log: n_C = the examinations of
any type under C; y_{R,B} for a class relation R of C = the examinations of a type under C in
which at least one object of B (a type, or any type under class B) stood in a relation that maps
onto R. "At least one" is kept per examination, never summed over members.

Backoff (``Backoff``): empirical-Bayes shrinkage of a type A's estimate toward its class C. For
an entry (A, rel, B) with R = the relation rel maps onto in C:

    p_C    = y_{R,B} / n_C over C's *other* members (leave-one-out)
    kappa  = 1 / rho - 1, capped at KAPPA_MAX and at the leave-one-out n_C, where rho says how
             much the members of C differ in this entry: rho_e = the between-member variance of
             p_{R,B} (method of moments, binomial noise removed) over p (1 - p); rho_C = the
             mean of rho_e over C's entries with 0 < p < 1; rho = max(rho_C, rho_e).
             A class with fewer than two members with evidence says nothing about how they
             differ: it takes the mean rho of the classes that do, else DEFAULT_RHO (0.5: one
             pseudo-examination)
    INT    = Wilson(y_A + kappa p_C, n_A + kappa)

Why the max: the class mean alone lends every entry as much as the class's typical entry can
bear, and the entries whose members differ most (a cup's neighbours against a bottle's) then
borrow too much and their intervals miss. Each entry's own spread, estimated from a few members,
is too noisy to use alone (with two or three members it is often 0 by chance), so an entry
borrows the class's amount or less, never more. In the held-out trial of ``bench
hierarchy`` (types held to k = 0-10 examinations) this raised the backoff's coverage in each of
four room styles at an unchanged error (docs/results.md, Type hierarchy).

so a type with much evidence keeps its own interval, one with none gets the class's knowledge as
kappa pseudo-examinations (a never-seen Workbench does not start from [0, 1]), and the more the
members of a class differ, the less a member borrows. Backoff goes one level up (to the parent
class's pooled counts), not recursively. Entries whose relation maps onto nothing, and types in
no class, keep the paper's interval.

On the corrected intervals (``--backoff --interval corrected``; knowledge.corrected):
the same, on effective counts. A type's own (y, n) become the corrected interval's (y', n') of
the entry (the examinations that could have shown a B, over the room clustering's shrink, and
the corrected estimate times that), and p_C the class's other members' pooled effective counts,
sum y' / sum n' (a member examined but without a relation that maps onto R adds its n
examinations and no y, as in the pooled counts). kappa's rho is still measured on the raw
pooled counts (misses shrink every member's rate alike, so their spread is read where it is
counted); kappa's cap is the rest's sum n'. An entry that borrows nothing (kappa = 0) keeps
the corrected interval itself. A class's own rows are Wilson on its members' pooled effective
counts. With full recall, no false reports and one examination per room
(shrink 1) every figure equals the Wilson backoff's (tested); with shrink > 1 it is the backoff
of the clustered interval. Related *classes* have no corrected counts (a view is per type):
with corrected intervals only concrete related types have rows.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.base import IntervalRow, KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.corrected import CorrectedIntervals
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.hierarchy import Hierarchy
from ctxsearch.knowledge.store import EvidenceStore

KAPPA_MAX = 50.0  # at most this many pseudo-examinations are borrowed from a class
# rho where no class has two members with evidence: kappa = 1, a single pseudo-examination.
DEFAULT_RHO = 0.5


# ============================================================================ pooled counts
@dataclass
class PooledCounts:
    """n and y at every level: n[name] for types and classes on the reference side;
    y[(owner, relation, related)] with ``relation`` one of the owner's (a type's own or a class's
    generic ones) and ``related`` a type or a class; ``via[(owner, child, relation, related)]``
    the part of a class's y that came through one direct member (for the backoff)."""

    hierarchy: Hierarchy
    n: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    y: dict[tuple[str, str, str], int] = field(default_factory=lambda: defaultdict(int))
    via: dict[tuple[str, str, str, str], int] = field(default_factory=lambda: defaultdict(int))

    def add(self, ref_type: str, pairs: Iterable[tuple[str, str]]) -> None:
        """Count one examination of an object of ``ref_type`` whose relation volumes held the
        (relation, related type) ``pairs`` (repeats allowed: each count is 'at least one')."""
        h = self.hierarchy
        self.n[ref_type] += 1
        for c in h.ancestors(ref_type):
            self.n[c] += 1
        hits: set[tuple[str, str, str]] = set()
        vias: set[tuple[str, str, str, str]] = set()
        for rel, t in pairs:
            related = (t, *h.ancestors(t))
            owner, child, r = ref_type, None, rel
            while r is not None:
                for b in related:
                    hits.add((owner, r, b))
                    if child is not None:
                        vias.add((owner, child, r, b))
                child, owner, r = owner, h.parent(owner), h.lift(r)
                if owner is None:
                    break
        for k in hits:
            self.y[k] += 1
        for k in vias:
            self.via[k] += 1

    @classmethod
    def from_examinations(
        cls, hierarchy: Hierarchy, exams: Iterable[tuple[str, Iterable[tuple[str, str]]]]
    ) -> PooledCounts:
        """Pooled counts of (reference type, related pairs) examinations."""
        out = cls(hierarchy)
        for ref, pairs in exams:
            out.add(ref, pairs)
        return out

    @classmethod
    def from_store(cls, store: EvidenceStore, run: str | None = None) -> PooledCounts:
        """Pooled counts of a store's evidence log (of one run, or all), over its catalog's
        hierarchy."""
        return cls.from_examinations(
            store.catalog.hierarchy,
            ((e.type, [(r, t) for r, t, _ in e.related]) for e in store.examinations(run)),
        )

    @classmethod
    def from_knowledge_base(cls, kb: KnowledgeBase) -> PooledCounts:
        """Pooled counts of a knowledge base's counts, for concrete related types only (a class
        on the related side needs the log's 'at least one'). Exact where no type or class has
        two relations that map onto one relation of its class (true of assets/types.toml;
        tests/test_hierarchy_search.py checks it): then a class's y for a type B is the sum of
        its members' y. Used where only counts are at hand (the learning loop's strategies)."""
        h = kb.catalog.hierarchy
        out = cls(h)
        for t in kb.catalog.type_names:
            n = kb.n(t)
            if n == 0:
                continue
            out.n[t] += n
            for c in h.ancestors(t):
                out.n[c] += n
            for (rel, b), y in kb.nonzero(t).items():
                owner, child, r = t, None, rel
                while r is not None and owner is not None:
                    out.y[(owner, r, b)] += y
                    if child is not None:
                        out.via[(owner, child, r, b)] += y
                    child, owner, r = owner, h.parent(owner), h.lift(r)
        return out

    def interval(
        self, owner: str, relation: str, related: str, alpha: float
    ) -> tuple[float, float]:
        """The paper's interval on the pooled counts."""
        lo, hi = intervals.interval(
            self.y.get((owner, relation, related), 0), self.n.get(owner, 0), alpha
        )
        return float(lo), float(hi)


# ============================================================================ backoff
@dataclass(frozen=True)
class BackoffEstimate:
    """A type's estimate for one entry: the interval, the pseudo-counts it rests on, and what it
    borrowed (kappa pseudo-examinations at the class's rate p_class)."""

    low: float
    high: float
    p: float
    y_eff: float
    n_eff: float
    kappa: float
    p_class: float | None


class Backoff:
    """Empirical-Bayes backoff of types toward their classes (see the module docstring)."""

    def __init__(
        self,
        pooled: PooledCounts,
        alpha: float = intervals.DEFAULT_ALPHA,
        corrected: CorrectedIntervals | None = None,
    ):
        """``corrected``: back off on the corrected intervals' effective counts (module
        docstring), which must come from the same log as ``pooled``."""
        self.pooled, self.alpha, self.corrected = pooled, float(alpha), corrected
        self._rho: dict[str, float | None] = {}
        self._entry_rho: dict[tuple[str, str, str], float | None] = {}

    def rho(self, cname: str) -> float:
        """How much the members of a class differ: the mean share of between-member variance,
        rho = tau^2 / (p (1 - p)), over its entries with 0 < p < 1; where the class has no such
        entry, the mean over the classes that have, else DEFAULT_RHO."""
        if not self._rho:
            self._rho = {c.name: self._estimate_rho(c.name) for c in self.pooled.hierarchy.classes}
        own = self._rho.get(cname)
        if own is not None:
            return own
        known = [r for r in self._rho.values() if r is not None]
        return float(np.mean(known)) if known else DEFAULT_RHO

    def _estimate_rho(self, cname: str) -> float | None:
        """rho_C: the mean rho_e over the class's estimable entries (None: none)."""
        h, pc = self.pooled.hierarchy, self.pooled
        rhos = []
        for rel in h.get(cname).relations:
            related = {b for (o, r, b) in pc.y if o == cname and r == rel}
            for b in sorted(related):
                r = self.entry_rho(cname, rel, b)
                if r is not None:
                    rhos.append(r)
        return float(np.mean(rhos)) if rhos else None

    def entry_rho(self, cname: str, crel: str, related: str) -> float | None:
        """rho_e of class entry (C, R, B): how much C's direct members differ in it (module
        docstring); None where fewer than two members have evidence or p is 0 or 1."""
        key = (cname, crel, related)
        if key in self._entry_rho:
            return self._entry_rho[key]
        h, pc = self.pooled.hierarchy, self.pooled
        kids = [k for k in h.children(cname) if pc.n.get(k, 0) > 0]
        out = None
        if len(kids) >= 2:
            n = np.array([pc.n[k] for k in kids], float)
            y = np.array([pc.via.get((cname, k, crel, related), 0) for k in kids], float)
            total = n.sum()
            p = y.sum() / total
            denom = total - float((n * n).sum()) / total
            if 0.0 < p < 1.0 and denom > 0:
                spread = float((n * (y / n - p) ** 2).sum())
                tau2 = max(0.0, (spread - (len(kids) - 1) * p * (1 - p)) / denom)
                out = min(1.0, tau2 / (p * (1 - p)))
        self._entry_rho[key] = out
        return out

    def pseudo_counts(
        self, ref_type: str, relation: str, related: str
    ) -> tuple[float, float, float, float | None]:
        """(y_eff, n_eff, kappa, p_class) of entry (ref_type, relation, related): the type's own
        counts plus kappa pseudo-examinations at its class's leave-one-out rate."""
        h = self.pooled.hierarchy
        y, n = self._own(ref_type, relation, related)
        cname, crel = h.parent(ref_type), h.lift(relation)
        kappa, p_class = 0.0, None
        if cname is not None and crel is not None:
            y_rest, n_rest = self._rest(cname, crel, related, ref_type)
            if n_rest > 0:
                p_class = y_rest / n_rest
                rho = max(self.rho(cname), self.entry_rho(cname, crel, related) or 0.0)
                kappa = KAPPA_MAX if rho <= 0 else min(KAPPA_MAX, 1.0 / rho - 1.0)
                kappa = max(0.0, min(kappa, float(n_rest)))
        return y + kappa * (p_class or 0.0), n + kappa, kappa, p_class

    def _own(self, ref_type: str, relation: str, related: str) -> tuple[float, float]:
        """A type's own (y, n) of an entry: its counts, or its effective counts."""
        pc = self.pooled
        if self.corrected is None:
            return pc.y.get((ref_type, relation, related), 0), pc.n.get(ref_type, 0)
        self._concrete(related)
        return self.corrected.effective(ref_type, relation, related) or (0.0, 0.0)

    def _rest(
        self, cname: str, crel: str, related: str, leave_out: str | None
    ) -> tuple[float, float]:
        """(y, n) of class ``cname``'s relation ``crel`` and ``related`` over its examinations
        except those of its direct member ``leave_out``: pooled counts, or the members' summed
        effective counts (module docstring)."""
        pc, h = self.pooled, self.pooled.hierarchy
        if self.corrected is None:
            y = pc.y.get((cname, crel, related), 0)
            n = pc.n.get(cname, 0)
            if leave_out is not None:
                y -= pc.via.get((cname, leave_out, crel, related), 0)
                n -= pc.n.get(leave_out, 0)
            return y, n
        self._concrete(related)
        skip = set(h.members(leave_out)) if leave_out is not None else set()
        y_sum = n_sum = 0.0
        for t in h.members(cname):
            if t in skip or pc.n.get(t, 0) == 0:
                continue
            rel = self._mapped(t, crel)
            eff = self.corrected.effective(t, rel, related) if rel is not None else None
            y_t, n_t = eff if eff is not None else (0.0, float(pc.n[t]))
            y_sum, n_sum = y_sum + y_t, n_sum + n_t
        return y_sum, n_sum

    def _mapped(self, type_name: str, crel: str) -> str | None:
        """The relation of ``type_name`` that maps (through its classes) onto ``crel``."""
        h = self.pooled.hierarchy
        for rel in self.corrected.relations.get(type_name, ()):
            r = rel
            while r is not None and r != crel:
                r = h.lift(r)
            if r == crel:
                return rel
        return None

    def _concrete(self, related: str) -> None:
        if related in self.pooled.hierarchy:
            raise CtxsearchError(
                f"the corrected intervals count concrete related types, not the class {related}"
            )

    def class_interval(self, cname: str, crel: str, related: str) -> tuple[float, float, float]:
        """(p0, low, high) of a class's own entry: the pooled counts' interval, or, on the
        corrected intervals, Wilson on the members' pooled effective counts."""
        y, n = self._rest(cname, crel, related, None)
        lo, hi = intervals.interval(y, n, self.alpha)
        return float(intervals.p0(y, n, self.alpha)), float(lo), float(hi)

    def estimate(self, ref_type: str, relation: str, related: str) -> BackoffEstimate:
        """The backed-off interval of entry (ref_type, relation, related). An entry that borrows
        nothing (no class, no other examined member, or members too different: kappa = 0) reads
        its own interval: Wilson on its counts, or on the corrected intervals the corrected
        interval itself (estimate: its midpoint), not Wilson on the effective counts."""
        y_eff, n_eff, kappa, p_class = self.pseudo_counts(ref_type, relation, related)
        if self.corrected is not None and kappa == 0.0:
            lo, hi = self.corrected.interval(ref_type, relation, related)
            p = (lo + hi) / 2
        else:
            lo, hi = intervals.interval(y_eff, n_eff, self.alpha)
            p = y_eff / n_eff if n_eff > 0 else 0.5
        return BackoffEstimate(float(lo), float(hi), float(p), y_eff, n_eff, kappa, p_class)


def _relations_of(catalog: Catalog, owner: str) -> tuple[str, ...]:
    h = catalog.hierarchy
    return h.get(owner).relations if owner in h else catalog.type(owner).relation_names


def interval_rows(
    pooled: PooledCounts,
    catalog: Catalog,
    alpha: float,
    *,
    ref: str | None = None,
    related: str | None = None,
    include_zero: bool = False,
    backoff: bool = False,
    corrected: CorrectedIntervals | None = None,
) -> list[IntervalRow]:
    """Interval rows over types and classes, both sides: of reference ``ref`` (a type or a class;
    default every one with relations) and related ``related`` (default every type and class),
    sorted by lower bound like ``KnowledgeBase.rows``. With ``backoff``, a concrete type's rows
    are its backed-off estimates (``Backoff``; y and n stay its own counts); rows with y = 0 are
    kept where ``include_zero`` or where backoff gives them a lower bound above 0. With
    ``corrected`` (from the same log), every interval is read on the corrected intervals (a
    type's own, a class's pooled effective counts, the backoff's; module docstring) and only
    concrete related types have rows."""
    h = catalog.hierarchy
    names = (*catalog.type_names, *(c.name for c in h.classes))
    owners = [ref] if ref else [o for o in names if _relations_of(catalog, o)]
    targets = [related] if related else list(catalog.type_names if corrected else names)
    bo = Backoff(pooled, alpha, corrected) if backoff or corrected is not None else None
    out = []
    for owner in owners:
        n = pooled.n.get(owner, 0)
        for rel in _relations_of(catalog, owner):
            for b in targets:
                y = pooled.y.get((owner, rel, b), 0)
                p0, lo, hi = _row_interval(bo, (owner, rel, b), backoff, (y, n), alpha)
                if y > 0 or include_zero or lo > 0:
                    out.append(IntervalRow(owner, rel, b, y, n, p0, lo, hi))
    out.sort(key=lambda r: (-r.low, r.relation, r.type))
    return out


def _row_interval(
    bo: Backoff | None,
    entry: tuple[str, str, str],
    backoff: bool,
    counts: tuple[int, int],
    alpha: float,
) -> tuple[float, float, float]:
    """(p0, low, high) of one row (owner, relation, related) ``entry`` of ``interval_rows``, whose
    pooled counts are ``counts`` (y, n)."""
    owner, rel, b = entry
    is_class = bo is not None and owner in bo.pooled.hierarchy
    if bo is not None and backoff and not is_class:
        e = bo.estimate(owner, rel, b)
        return e.p, e.low, e.high
    if bo is not None and bo.corrected is not None:
        if is_class:
            return bo.class_interval(owner, rel, b)
        bo._concrete(b)
        lo, hi = bo.corrected.interval(owner, rel, b)
        return (lo + hi) / 2, lo, hi
    y, n = counts
    lo, hi = (float(v) for v in intervals.interval(y, n, alpha))
    return float(intervals.p0(y, n, alpha)), lo, hi
