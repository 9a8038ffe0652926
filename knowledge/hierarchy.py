"""A type hierarchy over the catalog: abstract classes, evidence pooled at a class, and backoff
for rare types (the paper's future work, section 6).

Classes are ``[[class]]`` tables of the catalog file::

    [[class]]
    name = "WorkSurface"                  # capitalised; not a type's name
    parent = "HorizontalSurface"          # optional: another class
    types = ["Desk", "Table", "Counter", "LabBench"]   # concrete members (each in one class)
    relations = ["ON-TOP-OF-WORKSURFACE", "NEAR-WORKSURFACE"]   # generic relations, -<NAME>
    [class.maps]                          # a direct member's relation -> one of this class's
    "ON-TOP-OF-DESK" = "ON-TOP-OF-WORKSURFACE"

A class has no instances and no volumes: its relations are names that the relations of its
members map onto (ON-TOP-OF-DESK -> ON-TOP-OF-WORKSURFACE -> ON-TOP-OF-HORIZONTALSURFACE), and the
paper's naming convention holds at every level. A class may also stand on the related side:
P(ON-TOP-OF-DESK(Container)) is the probability that at least one Cup, Bottle or Beaker is on a
desk. The hierarchy is a way of *reading* the evidence, like alpha: it is not part of the
catalog's fingerprint, so stores stay valid when classes are added or changed.

Pooled counts (``PooledCounts``), derived from the same evidence log: n_C = the examinations of
any type under C; y_{R,B} for a class relation R of C = the examinations of a type under C in
which at least one object of B (a type, or any type under class B) stood in a relation that maps
onto R. "At least one" is kept per examination, never summed over members.

Backoff (``Backoff``): empirical-Bayes shrinkage of a type A's estimate toward its class C. For
an entry (A, rel, B) with R = the relation rel maps onto in C:

    p_C    = y_{R,B} / n_C over C's *other* members (leave-one-out)
    kappa  = 1 / rho - 1, rho = the mean, over C's entries with 0 < p < 1, of the between-member
             variance of p (method of moments, binomial noise removed) over p (1 - p), i.e. how
             much the members of C differ; capped at KAPPA_MAX and at the leave-one-out n_C.
             A class with fewer than two members with evidence says nothing about how they
             differ: it takes the mean rho of the classes that do, else DEFAULT_RHO (0.5: one
             pseudo-examination)
    INT    = Wilson(y_A + kappa p_C, n_A + kappa)

so a type with much evidence keeps its own interval, one with none gets the class's knowledge as
kappa pseudo-examinations (a never-seen Workbench does not start from [0, 1]), and the more the
members of a class differ, the less a member borrows. Backoff goes one level up (to the parent
class's pooled counts), not recursively. Entries whose relation maps onto nothing, and types in
no class, keep the paper's interval.
"""

from __future__ import annotations

import re
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from knowledge import intervals
from knowledge.errors import CatalogError

CLASS_FIELDS = {"name", "parent", "types", "relations", "maps"}
KAPPA_MAX = 50.0  # at most this many pseudo-examinations are borrowed from a class
# rho where no class has two members with evidence: kappa = 1, a single pseudo-examination.
DEFAULT_RHO = 0.5
_NAME_RE = re.compile(r"^[A-Z][A-Za-z0-9]*$")
_REL_RE = re.compile(r"^[A-Z][A-Z0-9]*(-[A-Z0-9]+)*$")


@dataclass(frozen=True)
class TypeClass:
    """An abstract class: its parent class, concrete member types, generic relations, and the
    map from its direct members' relations onto its own."""

    name: str
    parent: str | None
    types: tuple[str, ...]
    relations: tuple[str, ...]
    maps: Mapping[str, str]


@dataclass(frozen=True)
class Hierarchy:
    """Validated classes over a catalog's types, with the tree's look-ups."""

    classes: tuple[TypeClass, ...] = ()
    _by_name: dict[str, TypeClass] = field(init=False, repr=False, compare=False)
    _parent: dict[str, str] = field(init=False, repr=False, compare=False)
    _lift: dict[str, str] = field(init=False, repr=False, compare=False)
    _owner: dict[str, str] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        parent = {t: c.name for c in self.classes for t in c.types}
        parent.update({c.name: c.parent for c in self.classes if c.parent})
        object.__setattr__(self, "_by_name", {c.name: c for c in self.classes})
        object.__setattr__(self, "_parent", parent)
        object.__setattr__(self, "_lift", {k: v for c in self.classes for k, v in c.maps.items()})
        object.__setattr__(self, "_owner", {r: c.name for c in self.classes for r in c.relations})

    def __bool__(self) -> bool:
        return bool(self.classes)

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def get(self, name: str) -> TypeClass:
        """The class called ``name`` (KeyError if none)."""
        return self._by_name[name]

    def parent(self, name: str) -> str | None:
        """The class a type or class belongs to directly, or None."""
        return self._parent.get(name)

    def ancestors(self, name: str) -> tuple[str, ...]:
        """The classes above a type or class, nearest first."""
        out = []
        p = self._parent.get(name)
        while p is not None:
            out.append(p)
            p = self._parent.get(p)
        return tuple(out)

    def children(self, name: str) -> tuple[str, ...]:
        """A class's direct members: its types, then its child classes (file order)."""
        c = self._by_name[name]
        return c.types + tuple(k.name for k in self.classes if k.parent == name)

    def members(self, name: str) -> tuple[str, ...]:
        """Every concrete type under a class (a type's own name for a type)."""
        if name not in self._by_name:
            return (name,)
        return tuple(t for k in self.children(name) for t in self.members(k))

    def lift(self, relation: str) -> str | None:
        """The relation one level up that ``relation`` maps onto, or None."""
        return self._lift.get(relation)

    def relation_owner(self, relation: str) -> str | None:
        """The class that declares a generic relation (None for a type's own relation)."""
        return self._owner.get(relation)


def _fail(path, cname: str | None, field_: str, msg: str) -> CatalogError:
    return CatalogError(path, msg, type_name=f"class {cname}" if cname else None, field=field_)


def _str_list(path, cname, fname, value) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise _fail(path, cname, fname, f"must be a list of names, got {value!r}")
    if len(set(value)) != len(value):
        raise _fail(path, cname, fname, "lists a name twice")
    return tuple(value)


def _parse_class(path, raw, type_relations: Mapping[str, Sequence[str]]) -> TypeClass:
    name = raw.get("name") if isinstance(raw, dict) else None
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise _fail(path, None, "class.name", f"must be a capitalised word, got {name!r}")
    if name in type_relations:
        raise _fail(path, name, "name", "a class cannot have a type's name")
    unknown = set(raw) - CLASS_FIELDS
    if unknown:
        raise _fail(path, name, sorted(unknown)[0], f"unknown field(s) {sorted(unknown)}")
    parent = raw.get("parent")
    if parent is not None and (not isinstance(parent, str) or parent == name):
        raise _fail(path, name, "parent", f"must be another class's name, got {parent!r}")
    types = _str_list(path, name, "types", raw.get("types", []))
    for t in types:
        if t not in type_relations:
            raise _fail(path, name, "types", f"unknown type '{t}'")
    rels = _str_list(path, name, "relations", raw.get("relations", []))
    suffix = "-" + name.upper()
    for r in rels:
        if not _REL_RE.match(r) or not r.endswith(suffix) or r == suffix[1:]:
            raise _fail(path, name, "relations", f"relation '{r}' must end in '{suffix}'")
    maps = raw.get("maps", {})
    if not isinstance(maps, dict) or not all(isinstance(v, str) for v in maps.values()):
        raise _fail(path, name, "maps", "must be a table of relation = relation")
    for src, dst in maps.items():
        if dst not in rels:
            raise _fail(path, name, "maps", f"'{src}' maps onto '{dst}', not one of its relations")
    return TypeClass(name, parent, types, rels, dict(maps))


def _check_tree(path, classes: Sequence[TypeClass], type_relations) -> None:
    by_name = {c.name: c for c in classes}
    if len(by_name) != len(classes):
        dup = next(c.name for c in classes if [k.name for k in classes].count(c.name) > 1)
        raise _fail(path, dup, "name", "duplicate class name")
    owner: dict[str, str] = {}
    for c in classes:
        if c.parent is not None and c.parent not in by_name:
            raise _fail(path, c.name, "parent", f"unknown class '{c.parent}'")
        for t in c.types:
            if t in owner:
                raise _fail(path, c.name, "types", f"'{t}' is already in class {owner[t]}")
            owner[t] = c.name
    for c in classes:  # no cycles: walking up ends
        seen, p = {c.name}, c.parent
        while p is not None:
            if p in seen:
                raise _fail(path, c.name, "parent", "the classes' parents form a cycle")
            seen.add(p)
            p = by_name[p].parent
    for c in classes:  # maps: keys are relations of direct members, each mapped once
        own = {r for t in c.types for r in type_relations[t]}
        own |= {r for k in classes if k.parent == c.name for r in k.relations}
        for src in c.maps:
            if src not in own:
                raise _fail(path, c.name, "maps", f"'{src}' is not a relation of a member")


def parse_hierarchy(
    raw_classes: object, type_relations: Mapping[str, Sequence[str]], path="<memory>"
) -> Hierarchy:
    """Validate ``[[class]]`` tables against the types (name -> relation names); CatalogError
    (one line, naming the class and field) on any problem."""
    if raw_classes is None:
        return Hierarchy()
    if not isinstance(raw_classes, list):
        raise _fail(path, None, "class", "must be an array of tables [[class]]")
    classes = [_parse_class(path, raw, type_relations) for raw in raw_classes]
    _check_tree(path, classes, type_relations)
    return Hierarchy(tuple(classes))


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

    def __init__(self, pooled: PooledCounts, alpha: float = intervals.DEFAULT_ALPHA):
        self.pooled, self.alpha = pooled, float(alpha)
        self._rho: dict[str, float | None] = {}

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
        h, pc = self.pooled.hierarchy, self.pooled
        kids = [k for k in h.children(cname) if pc.n.get(k, 0) > 0]
        if len(kids) < 2:
            return None
        n = np.array([pc.n[k] for k in kids], float)
        N = n.sum()
        rhos = []
        for rel in h.get(cname).relations:
            related = {b for (o, r, b) in pc.y if o == cname and r == rel}
            for b in sorted(related):
                y = np.array([pc.via.get((cname, k, rel, b), 0) for k in kids], float)
                p = y.sum() / N
                if not 0.0 < p < 1.0:
                    continue
                spread = float((n * (y / n - p) ** 2).sum())
                denom = N - float((n * n).sum()) / N
                if denom <= 0:
                    continue
                tau2 = max(0.0, (spread - (len(kids) - 1) * p * (1 - p)) / denom)
                rhos.append(min(1.0, tau2 / (p * (1 - p))))
        return float(np.mean(rhos)) if rhos else None

    def estimate(self, ref_type: str, relation: str, related: str) -> BackoffEstimate:
        """The backed-off interval of entry (ref_type, relation, related)."""
        pc, h = self.pooled, self.pooled.hierarchy
        y = pc.y.get((ref_type, relation, related), 0)
        n = pc.n.get(ref_type, 0)
        cname, crel = h.parent(ref_type), h.lift(relation)
        kappa, p_class = 0.0, None
        if cname is not None and crel is not None:
            n_rest = pc.n.get(cname, 0) - n
            if n_rest > 0:
                y_rest = pc.y.get((cname, crel, related), 0) - pc.via.get(
                    (cname, ref_type, crel, related), 0
                )
                p_class = y_rest / n_rest
                rho = self.rho(cname)
                kappa = KAPPA_MAX if rho <= 0 else min(KAPPA_MAX, 1.0 / rho - 1.0)
                kappa = max(0.0, min(kappa, float(n_rest)))
        y_eff, n_eff = y + kappa * (p_class or 0.0), n + kappa
        lo, hi = intervals.interval(y_eff, n_eff, self.alpha)
        p = y_eff / n_eff if n_eff > 0 else 0.5
        return BackoffEstimate(float(lo), float(hi), float(p), y_eff, n_eff, kappa, p_class)
