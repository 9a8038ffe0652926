"""The object-type catalog: types, their sizes, detectability and relation volumes (paper, 2.2).

A catalog is a TOML file (default ``assets/types.toml``) holding an array of ``[[type]]`` tables,
each with an array of ``[[type.relation]]`` tables, and optionally ``[[class]]`` tables: abstract
classes over the types (format and meaning in ``knowledge/hierarchy.py``).

Object frame (ROS REP 103): the origin is the centre of the object's bounding box, local +x is the
object's FRONT, +y its LEFT (as seen by the object looking out of its front), +z is up. ``size`` is
the full extent along (x, y, z) in metres. Poses are yaw-only (objects stand upright).

A relation volume is a box in that frame. Its bounds are given relative to the object's extents
(the object itself spans -0.5..0.5 on every axis) plus metric margins::

    local_lo = lo * size + margin_lo        local_hi = hi * size + margin_hi

so ON-TOP-OF-DESK = lo [-0.5,-0.5,0.5], hi [0.5,0.5,0.5], margin_hi [0,0,0.4] is the 40 cm slab
resting on the desk top, whatever the desk's size. Relation names follow the paper's convention:
``<REL>-<TYPE>`` with the type's name upper-cased as suffix, which makes every name unique.
Coordinate systems may be partial: a Cup may have ABOVE/NEAR and no FRONT.

``stay`` (optional, default 0) is the probability that an instance of a small-object type is
still exactly where it was on the next day of a world (``envs.rooms``' days; a room style may
override it, ``envs.styles.Style.stay``). Furniture always stays: its ``stay`` is checked like
any other's and has no effect. Like the classes, it is not part of the fingerprint: it says how
the simulated worlds change over days, not what the relation volumes are, so stores stay valid
when it changes.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ctxsearch.knowledge.errors import CatalogError
from ctxsearch.knowledge.files import InputFileError, read_toml
from ctxsearch.knowledge.hierarchy import Hierarchy, parse_hierarchy

ASSETS_DIR = Path(__file__).resolve().parents[1] / "assets"
DEFAULT_CATALOG = ASSETS_DIR / "types.toml"


def asset_file(path_or_name: str | Path, folder: Path) -> Path:
    """The file a ``--style``/``--detector``-like value names: a path as it is, or a bare name
    looked up as ``folder/<name>.toml`` (``office`` -> assets/styles/office.toml)."""
    p = Path(path_or_name)
    if p.suffix == ".toml" or p.parent != Path(".") or p.exists():
        return p
    return folder / f"{p.name}.toml"


KINDS = ("furniture", "object")
# How envs/ builds the type's geometry. knowledge/ only checks the name is one of these.
SHAPES = (
    "box",
    "cylinder",
    "desk",
    "table",
    "chair",
    "shelf",
    "cabinet",
    "sofa",
    "bed",
    "counter",
    "monitor",
    "laptop",
    "plant",
    "mug",
    "keyboard",
    "microscope",
    "bottle",
)
TYPE_FIELDS = {"name", "kind", "shape", "size", "color", "min_pixels", "max_range", "relation",
               "stay"}  # fmt: skip
RELATION_FIELDS = {"name", "lo", "hi", "margin_lo", "margin_hi"}
# Sane ranges of the numbers a catalog holds (finite, and far beyond any real room or camera).
MAX_SIZE = 10.0  # metres per axis
MAX_RELATIVE = 10.0  # |lo|, |hi| of a relation volume, in object extents
MAX_MARGIN = 100.0  # |margin| of a relation volume, metres (rooms are up to 50 m)
MAX_RANGE = 100.0  # max_range, metres
MAX_PIXELS = 1_000_000  # min_pixels
_NAME_RE = re.compile(r"^[A-Z][A-Za-z0-9]*$")
_REL_RE = re.compile(r"^[A-Z][A-Z0-9]*(-[A-Z0-9]+)*$")


@dataclass(frozen=True, slots=True)
class RelationSpec:
    """One relation of a reference type: its name, the reference type, and its volume spec."""

    name: str
    ref: str
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    margin_lo: tuple[float, float, float] = (0.0, 0.0, 0.0)
    margin_hi: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def local_bounds(self, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The volume's (lo, hi) corners in the reference object's frame for an object of ``size``."""
        size = np.asarray(size, dtype=float)
        return (
            np.asarray(self.lo) * size + np.asarray(self.margin_lo),
            np.asarray(self.hi) * size + np.asarray(self.margin_hi),
        )


@dataclass(frozen=True, slots=True)
class ObjectType:
    """An object type: name, kind, builder shape, size range, colour, detectability, relations,
    and ``stay``: the probability that a small object of this type is still exactly where it was
    on the next day (without effect for furniture, which always stays)."""

    name: str
    kind: str
    shape: str
    size_min: tuple[float, float, float]
    size_max: tuple[float, float, float]
    color: tuple[float, float, float]
    min_pixels: int
    max_range: float
    relations: tuple[RelationSpec, ...] = ()
    stay: float = 0.0

    @property
    def is_furniture(self) -> bool:
        """True for furniture (large, rests on the floor), False for small objects."""
        return self.kind == "furniture"

    def sample_size(self, rng: np.random.Generator) -> tuple[float, float, float]:
        """A size drawn uniformly per axis from the type's size range."""
        lo, hi = np.asarray(self.size_min), np.asarray(self.size_max)
        return tuple(float(v) for v in lo + (hi - lo) * rng.random(3))

    @property
    def relation_names(self) -> tuple[str, ...]:
        """RELATIONS(type), in catalog order."""
        return tuple(r.name for r in self.relations)


@dataclass(frozen=True)
class Catalog:
    """An immutable, validated set of object types with fast name look-ups."""

    types: tuple[ObjectType, ...]
    path: str = "<memory>"
    # Abstract classes over the types (knowledge/hierarchy.py); not part of the fingerprint.
    hierarchy: Hierarchy = field(default_factory=Hierarchy, compare=False)
    _by_name: dict[str, ObjectType] = field(init=False, repr=False, compare=False)
    _rel_by_name: dict[str, RelationSpec] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_by_name", {t.name: t for t in self.types})
        object.__setattr__(
            self, "_rel_by_name", {r.name: r for t in self.types for r in t.relations}
        )

    @property
    def type_names(self) -> tuple[str, ...]:
        """Type names in catalog order."""
        return tuple(t.name for t in self.types)

    @property
    def relations(self) -> tuple[RelationSpec, ...]:
        """Every relation of every type, in catalog order."""
        return tuple(r for t in self.types for r in t.relations)

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def __len__(self) -> int:
        return len(self.types)

    def type(self, name: str) -> ObjectType:
        """The type called ``name``; a CatalogError naming the known types if there is none."""
        try:
            return self._by_name[name]
        except KeyError:
            names = self.type_names
            known = ", ".join(names[:30]) + (
                f", ... ({len(names) - 30} more)" if len(names) > 30 else ""
            )
            raise CatalogError(self.path, f"unknown type '{name}' (known: {known})") from None

    def relation(self, name: str) -> RelationSpec:
        """The relation called ``name`` (e.g. ``ON-TOP-OF-DESK``)."""
        try:
            return self._rel_by_name[name]
        except KeyError:
            raise CatalogError(self.path, f"unknown relation '{name}'") from None

    def has_relation(self, name: str) -> bool:
        """True if some type defines relation ``name``."""
        return name in self._rel_by_name

    @property
    def world_fingerprint(self) -> str:
        """``fingerprint`` and every type's ``stay``: what makes the simulated worlds of every
        day (the episode draws' key: a changed ``stay`` changes the worlds after day 0)."""
        stays = ",".join(f"{t.name}={t.stay!r}" for t in self.types)
        return hashlib.sha256(f"{self.fingerprint}\n{stays}".encode()).hexdigest()[:16]

    @property
    def fingerprint(self) -> str:
        """A hash of the catalog's content (types, sizes, detectability, relation volumes).

        Stores record it: evidence gathered with other relation volumes is not comparable.
        ``stay`` (how the simulated worlds change over days) and the classes are not part of it.
        """
        doc = [
            {
                "name": t.name,
                "kind": t.kind,
                "shape": t.shape,
                "size_min": t.size_min,
                "size_max": t.size_max,
                "color": t.color,
                "min_pixels": t.min_pixels,
                "max_range": t.max_range,
                "relations": [[r.name, r.lo, r.hi, r.margin_lo, r.margin_hi] for r in t.relations],
            }
            for t in self.types
        ]
        blob = json.dumps(doc, sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


def relation_suffix(type_name: str) -> str:
    """The suffix every relation of ``type_name`` must carry, e.g. ``-DESK`` for ``Desk``."""
    return "-" + type_name.upper()


def _is_number(v: object, bound: float) -> bool:
    """A finite int or float (not a bool) with |v| <= bound."""
    return (
        isinstance(v, int | float)
        and not isinstance(v, bool)
        and math.isfinite(v)
        and abs(v) <= bound
    )


def _vec3(
    path: Path, tname: str | None, fname: str, value: object, bound: float
) -> tuple[float, float, float]:
    if (
        not isinstance(value, list)
        or len(value) != 3
        or not all(_is_number(v, bound) for v in value)
    ):
        raise CatalogError(
            path,
            f"expected 3 finite numbers in [-{bound:g}, {bound:g}], got {value!r}",
            type_name=tname,
            field=fname,
        )
    return (float(value[0]), float(value[1]), float(value[2]))


def _parse_size(path: Path, tname: str, value: object) -> tuple[tuple, tuple]:
    if isinstance(value, list) and len(value) == 3 and all(isinstance(v, list) for v in value):
        pairs = []
        for v in value:
            if len(v) != 2 or not all(_is_number(x, MAX_SIZE) for x in v) or v[0] > v[1]:
                raise CatalogError(
                    path,
                    f"each axis range must be [min, max] of finite sizes up to {MAX_SIZE:g} m, "
                    f"got {v!r}",
                    type_name=tname,
                    field="size",
                )
            pairs.append((float(v[0]), float(v[1])))
        lo = tuple(p[0] for p in pairs)
        hi = tuple(p[1] for p in pairs)
    else:
        lo = hi = _vec3(path, tname, "size", value, MAX_SIZE)
    if min(lo) <= 0:
        raise CatalogError(
            path, f"sizes must be positive, got {list(lo)}", type_name=tname, field="size"
        )
    return lo, hi


def _parse_relation(path: Path, tname: str, raw: object, size_lo, size_hi) -> RelationSpec:
    if not isinstance(raw, dict):
        raise CatalogError(path, "a relation must be a table", type_name=tname, field="relation")
    unknown = set(raw) - RELATION_FIELDS
    if unknown:
        raise CatalogError(
            path,
            f"unknown field(s) {sorted(unknown)} in a relation "
            f"(allowed: {sorted(RELATION_FIELDS)})",
            type_name=tname,
            field="relation",
        )
    name = raw.get("name")
    if not isinstance(name, str) or not _REL_RE.match(name):
        raise CatalogError(
            path,
            f"relation name must be upper-case words joined by '-', got {name!r}",
            type_name=tname,
            field="relation.name",
        )
    suffix = relation_suffix(tname)
    if not name.endswith(suffix) or name == suffix[1:]:
        raise CatalogError(
            path,
            f"relation '{name}' must end in '{suffix}' (paper's convention)",
            type_name=tname,
            field="relation.name",
        )
    for req in ("lo", "hi"):
        if req not in raw:
            raise CatalogError(
                path, f"relation '{name}' lacks '{req}'", type_name=tname, field=f"relation.{req}"
            )
    spec = RelationSpec(
        name=name,
        ref=tname,
        lo=_vec3(path, tname, f"{name}.lo", raw["lo"], MAX_RELATIVE),
        hi=_vec3(path, tname, f"{name}.hi", raw["hi"], MAX_RELATIVE),
        margin_lo=_vec3(
            path, tname, f"{name}.margin_lo", raw.get("margin_lo", [0, 0, 0]), MAX_MARGIN
        ),
        margin_hi=_vec3(
            path, tname, f"{name}.margin_hi", raw.get("margin_hi", [0, 0, 0]), MAX_MARGIN
        ),
    )
    # The bounds are affine in each size axis, so checking both ends of the range is enough.
    for size in (size_lo, size_hi):
        lo, hi = spec.local_bounds(np.asarray(size))
        if np.any(hi - lo <= 0):
            raise CatalogError(
                path,
                f"relation '{name}' has an empty volume for size {list(size)}",
                type_name=tname,
                field=f"relation.{name}",
            )
    return spec


def _type_name(path: Path, i: int, raw: object, seen: set[str]) -> str:
    """The i-th type table's name, checked (capitalised word, not seen before)."""
    name = raw.get("name") if isinstance(raw, dict) else None
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise CatalogError(
            path, f"type #{i + 1}: name must be a capitalised word, got {name!r}", field="name"
        )
    if name in seen:
        raise CatalogError(path, "duplicate type name", type_name=name, field="name")
    return name


def _type_fields(path: Path, name: str, raw: dict) -> None:
    """No unknown field, every required one there, kind and shape known."""
    unknown = set(raw) - TYPE_FIELDS
    if unknown:
        raise CatalogError(
            path,
            f"unknown field(s) {sorted(unknown)} (allowed: {sorted(TYPE_FIELDS)})",
            type_name=name,
            field=sorted(unknown)[0],
        )
    for req in ("kind", "shape", "size", "color", "min_pixels", "max_range"):
        if req not in raw:
            raise CatalogError(path, "missing", type_name=name, field=req)
    if raw["kind"] not in KINDS:
        raise CatalogError(
            path, f"must be one of {KINDS}, got {raw['kind']!r}", type_name=name, field="kind"
        )
    if raw["shape"] not in SHAPES:
        raise CatalogError(
            path, f"must be one of {SHAPES}, got {raw['shape']!r}", type_name=name, field="shape"
        )


def _detectability(path: Path, name: str, raw: dict) -> tuple[int, float]:
    """(min_pixels, max_range), each finite and in range."""
    mp, mr = raw["min_pixels"], raw["max_range"]
    if not isinstance(mp, int) or isinstance(mp, bool) or not 1 <= mp <= MAX_PIXELS:
        raise CatalogError(
            path,
            f"must be an integer in [1, {MAX_PIXELS}], got {mp!r}",
            type_name=name,
            field="min_pixels",
        )
    if not _is_number(mr, MAX_RANGE) or mr <= 0:
        raise CatalogError(
            path,
            f"must be a positive number of metres up to {MAX_RANGE:g}, got {mr!r}",
            type_name=name,
            field="max_range",
        )
    return mp, float(mr)


def _stay(path: Path, name: str, raw: dict) -> float:
    """The type's ``stay``: a probability (default 0: placed anew every day)."""
    v = raw.get("stay", 0.0)
    if not _is_number(v, 1.0) or v < 0:
        raise CatalogError(
            path,
            f"must be a probability in [0, 1] (the chance an instance is still where it was "
            f"the next day), got {v!r}",
            type_name=name,
            field="stay",
        )
    return float(v)


def _relations(path: Path, name: str, raw: dict, size_lo, size_hi) -> tuple[RelationSpec, ...]:
    """The type's [[type.relation]] tables, each validated, no name twice."""
    raw_rels = raw.get("relation", [])
    if not isinstance(raw_rels, list):
        raise CatalogError(
            path, "must be an array of tables [[type.relation]]", type_name=name, field="relation"
        )
    rels = [_parse_relation(path, name, r, size_lo, size_hi) for r in raw_rels]
    names = [r.name for r in rels]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise CatalogError(
            path, f"duplicate relation '{dup}'", type_name=name, field="relation.name"
        )
    return tuple(rels)


def _parse_type(path: Path, name: str, raw: dict) -> ObjectType:
    """One validated [[type]] table."""
    _type_fields(path, name, raw)
    size_lo, size_hi = _parse_size(path, name, raw["size"])
    color = _vec3(path, name, "color", raw["color"], 1.0)
    if not all(0.0 <= c <= 1.0 for c in color):
        raise CatalogError(
            path, f"components must be in [0, 1], got {list(color)}", type_name=name, field="color"
        )
    mp, mr = _detectability(path, name, raw)
    return ObjectType(
        name=name,
        kind=raw["kind"],
        shape=raw["shape"],
        size_min=size_lo,
        size_max=size_hi,
        color=color,
        min_pixels=mp,
        max_range=mr,
        relations=_relations(path, name, raw, size_lo, size_hi),
        stay=_stay(path, name, raw),
    )


def parse_catalog(doc: dict, path: str | Path = "<memory>") -> Catalog:
    """Validate a parsed TOML document and build a Catalog; CatalogError on any problem."""
    path = Path(path) if not isinstance(path, Path) else path
    unknown_top = set(doc) - {"type", "schema", "class"}
    if unknown_top:
        raise CatalogError(path, f"unknown top-level field(s) {sorted(unknown_top)}")
    raw_types = doc.get("type")
    if not isinstance(raw_types, list) or not raw_types:
        raise CatalogError(path, "no [[type]] tables", field="type")
    types: list[ObjectType] = []
    seen: set[str] = set()
    for i, raw in enumerate(raw_types):
        name = _type_name(path, i, raw, seen)
        seen.add(name)
        types.append(_parse_type(path, name, raw))
    hierarchy = parse_hierarchy(doc.get("class"), {t.name: t.relation_names for t in types}, path)
    return Catalog(types=tuple(types), path=str(path), hierarchy=hierarchy)


def load_catalog(path: str | Path | None = None) -> Catalog:
    """Load and validate a catalog TOML file (default ``assets/types.toml``): a regular file of at
    most ``files.MAX_FILE_BYTES`` bytes, nested at most ``files.MAX_NESTING`` deep."""
    path = Path(path) if path is not None else DEFAULT_CATALOG
    try:
        doc = read_toml(path)
    except InputFileError as exc:
        raise CatalogError(path, exc.problem) from None
    return parse_catalog(doc, path)
