"""A type hierarchy over the catalog: abstract classes and their relations (the paper's future
work, section 6). Evidence pooled at a class and backoff for rare types: knowledge/pooling.py.

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
catalog's fingerprint, so stores stay valid when classes are added or changed. Validation: class
names unlike type names, parents exist and form no cycle, each type in at most one class, every
mapped relation a relation of a direct member, every target one of the class's own relations.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from ctxsearch.knowledge.errors import CatalogError

CLASS_FIELDS = {"name", "parent", "types", "relations", "maps"}
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
