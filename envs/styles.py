"""Room styles: the data that says what a kind of room holds (size, furniture, placement rules,
clutter), loaded from ``assets/styles/<name>.toml`` and validated.

The file format is documented at the top of ``assets/styles/office.toml``. Styles are data: a
user adds one without touching code, and a bad one gets a one-line StyleError naming the file
and the field. The robot never reads a style's probabilities: only the generator, the
ground-truth tool and the oracle baselines do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.knowledge.catalog import ASSETS_DIR, Catalog, asset_file, load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.files import InputFileError, read_toml

STYLES_DIR = ASSETS_DIR / "styles"
TOP_FIELDS = {"name", "description", "room", "furniture", "rule", "clutter", "drift", "stay"}
ROOM_FIELDS = {"width", "depth", "height", "door_width"}
RULE_FIELDS = {"ref", "relation", "type", "p", "count", "on"}
DRIFT_FIELDS = {"rule", "p", "from_day"}
MAX_DAY = 100_000
EVERY_TYPE = "*"  # a [stay] key: every small type the table does not name
ON_CHOICES = ("auto", "floor", "surface")
MAX_COUNT = 50
MAX_ROOM_SIDE = 50.0  # metres: width, depth (and door width) of a room
MAX_ROOM_HEIGHT = 10.0
# The expected furniture (mean counts, largest sizes), each footprint grown by the robot's
# clearance, may cover at most this fraction of the smallest floor the style allows.
MAX_FILL = 0.6


class StyleError(CtxsearchError, ValueError):
    """A room-style file is malformed or inconsistent with the catalog."""

    def __init__(self, path: object, message: str, *, field: str | None = None):
        where = str(path)
        if field:
            where += f": field '{field}'"
        super().__init__(f"{where}: {message}")
        self.path, self.field = path, field


@dataclass(frozen=True)
class Rule:
    """For each instance of ``ref``, with probability ``p``, place ``count`` (a [min, max] range,
    drawn uniformly) instances of ``type`` in relation ``relation`` to it.

    ``on`` says where small objects may rest: 'auto' (on the reference's own surfaces if the
    relation volume reaches one, else on the surface the reference stands on, else the floor),
    'floor' or 'surface'. Furniture always stands on the floor.
    """

    ref: str
    relation: str
    type: str
    p: float
    count: tuple[int, int]
    on: str = "auto"


def rule_name(rule: Rule) -> str:
    """A rule's name in drift schedules: ``REF/RELATION/TYPE`` (e.g. Desk/ON-TOP-OF-DESK/Laptop)."""
    return f"{rule.ref}/{rule.relation}/{rule.type}"


@dataclass(frozen=True)
class Drift:
    """From day ``from_day`` on (days of a world's visits, ``learn --days``), the placement rule
    named ``rule`` (``rule_name``: every rule of that name) places with probability ``p``. The
    furniture of a world stays across days, so only rules placing small objects may drift."""

    rule: str
    p: float
    from_day: int


@dataclass(frozen=True)
class Style:
    """A validated room style."""

    name: str
    path: str
    description: str
    width: tuple[float, float]
    depth: tuple[float, float]
    height: tuple[float, float]
    door_width: tuple[float, float]
    furniture: tuple[tuple[str, tuple[int, int]], ...]  # (type, [min, max]) in file order
    rules: tuple[Rule, ...]
    clutter: tuple[tuple[str, tuple[int, int]], ...]
    drift: tuple[Drift, ...] = ()  # the schedule of changes over days (empty: none)
    # [stay]: (small type or EVERY_TYPE, probability) in file order (empty: the catalog's)
    stays: tuple[tuple[str, float], ...] = ()

    def stay(self, type_name: str, catalog: Catalog) -> float:
        """The probability that an instance of ``type_name`` is still exactly where it was on
        the next day: the style's [stay] value for the type, else its ``"*"`` value, else the
        catalog's ``stay``. Furniture always stays (1)."""
        if catalog.type(type_name).is_furniture:
            return 1.0
        table = dict(self.stays)
        if type_name in table:
            return table[type_name]
        return table.get(EVERY_TYPE, catalog.type(type_name).stay)

    def moves_everything(self, catalog: Catalog) -> bool:
        """True when no small object this style places ever stays to the next day (every stay
        probability 0): each day is then placed from scratch, as before persistence."""
        small = [t for t in self.types if not catalog.type(t).is_furniture]
        return all(self.stay(t, catalog) == 0.0 for t in small)

    def on_day(self, day: int) -> Style:
        """The style as it places small objects on ``day``: every drift entry with ``from_day
        <= day`` applied in order (a later entry for the same rule wins). Day 0 is the style."""
        active = [d for d in self.drift if d.from_day <= day]
        if not active:
            return self
        p = {d.rule: d.p for d in sorted(active, key=lambda d: d.from_day)}
        rules = tuple(
            Rule(r.ref, r.relation, r.type, p.get(rule_name(r), r.p), r.count, r.on)
            for r in self.rules
        )
        return replace(self, rules=rules)

    def with_drift(self, drift: tuple[Drift, ...], catalog: Catalog | None = None) -> Style:
        """The style with another drift schedule (checked like a file's: ``check_drift_rule``;
        two entries for the same rule and day are refused: which one applies would be a guess)."""
        first: dict[tuple[str, int], int] = {}
        for i, d in enumerate(drift):
            check_drift_rule(self.path, f"drift[{i}]", d, self, catalog)
            j = first.setdefault((d.rule, d.from_day), i)
            if j != i:
                raise StyleError(
                    self.path,
                    f"a second entry for {d.rule} from day {d.from_day} (drift[{j}] is the "
                    "first): give each rule at most one p per day",
                    field=f"drift[{i}]",
                )
        return replace(self, drift=tuple(drift))

    @property
    def types(self) -> tuple[str, ...]:
        """Every type that can occur in rooms of this style, in first-mention order."""
        seen: dict[str, None] = {}
        for t, _ in self.furniture:
            seen[t] = None
        for r in self.rules:
            seen[r.type] = None
        for t, _ in self.clutter:
            seen[t] = None
        return tuple(seen)


def available_styles() -> list[str]:
    """Names of the styles shipped in ``assets/styles``."""
    return sorted(p.stem for p in STYLES_DIR.glob("*.toml"))


def style_path(path_or_name: str | Path) -> Path:
    """The file of a style given by path or bare name (``office`` -> assets/styles/office.toml)."""
    return asset_file(path_or_name, STYLES_DIR)


def range_field(
    path,
    field: str,
    value,
    *,
    integer: bool,
    lo_min: float,
    hi_max: float,
    error: type[StyleError] = StyleError,
) -> tuple:
    """A ``[min, max]`` field (a bare number is [v, v]) of a style or house file: finite, of the
    right kind, min <= max, within [lo_min, hi_max]; ``error`` (one line naming file and field)
    otherwise."""
    kind = "integers" if integer else "numbers"

    def ok(v):
        if isinstance(v, bool):
            return False
        if integer:
            return isinstance(v, int)
        return isinstance(v, int | float) and math.isfinite(v)

    if ok(value):
        value = [value, value]
    if not isinstance(value, list) or len(value) != 2 or not all(ok(v) for v in value):
        raise error(
            path, f"expected a number or a [min, max] pair of {kind}, got {value!r}", field=field
        )
    a, b = value
    if a > b:
        raise error(path, f"min {a} is larger than max {b}", field=field)
    if a < lo_min:
        raise error(path, f"must be at least {lo_min}, got {a}", field=field)
    if b > hi_max:
        raise error(path, f"must be at most {hi_max:g}, got {b}", field=field)
    return (int(a), int(b)) if integer else (float(a), float(b))


def _counts(path, section: str, raw, catalog: Catalog, *, furniture: bool) -> tuple:
    if not isinstance(raw, dict):
        raise StyleError(path, "must be a table of Type = [min, max]", field=section)
    out = []
    for tname, val in raw.items():
        field = f"{section}.{tname}"
        if tname not in catalog:
            raise StyleError(
                path,
                f"unknown type '{tname}' (known: {', '.join(catalog.type_names)})",
                field=field,
            )
        if furniture and not catalog.type(tname).is_furniture:
            raise StyleError(
                path, f"'{tname}' is a small object: put it in [clutter] or a [[rule]]", field=field
            )
        rng = range_field(path, field, val, integer=True, lo_min=0, hi_max=MAX_COUNT)
        out.append((tname, rng))
    return tuple(out)


def _rule(path, i: int, raw, catalog: Catalog, present: set[str]) -> Rule:
    where = f"rule[{i}]"
    if not isinstance(raw, dict):
        raise StyleError(path, "a rule must be a table [[rule]]", field=where)
    unknown = set(raw) - RULE_FIELDS
    if unknown:
        raise StyleError(
            path,
            f"unknown field(s) {sorted(unknown)} (allowed: {sorted(RULE_FIELDS)})",
            field=f"{where}.{sorted(unknown)[0]}",
        )
    for req in ("ref", "relation", "type", "p"):
        if req not in raw:
            raise StyleError(path, "missing", field=f"{where}.{req}")
    ref, rel, tname = raw["ref"], raw["relation"], raw["type"]
    for fname, v in (("ref", ref), ("type", tname)):
        if not isinstance(v, str) or v not in catalog:
            raise StyleError(
                path,
                f"unknown type {v!r} (known: {', '.join(catalog.type_names)})",
                field=f"{where}.{fname}",
            )
    if not isinstance(rel, str) or not catalog.has_relation(rel):
        raise StyleError(path, f"unknown relation {rel!r}", field=f"{where}.relation")
    if catalog.relation(rel).ref != ref:
        raise StyleError(
            path,
            f"'{rel}' is not a relation of {ref} (its relations: "
            f"{', '.join(catalog.type(ref).relation_names)})",
            field=f"{where}.relation",
        )
    p = raw["p"]
    if (
        isinstance(p, bool)
        or not isinstance(p, int | float)
        or not (0.0 <= p <= 1.0)
        or math.isnan(p)
    ):
        raise StyleError(path, f"probability must be in [0, 1], got {p!r}", field=f"{where}.p")
    count = range_field(
        path, f"{where}.count", raw.get("count", 1), integer=True, lo_min=0, hi_max=MAX_COUNT
    )
    on = raw.get("on", "auto")
    if on not in ON_CHOICES:
        raise StyleError(path, f"must be one of {ON_CHOICES}, got {on!r}", field=f"{where}.on")
    if catalog.type(tname).is_furniture and on == "surface":
        raise StyleError(
            path, f"furniture ({tname}) stands on the floor, not on a surface", field=f"{where}.on"
        )
    if ref not in present:
        raise StyleError(
            path,
            f"'{ref}' never occurs before this rule (not in [furniture] "
            "nor placed by an earlier rule)",
            field=f"{where}.ref",
        )
    return Rule(ref=ref, relation=rel, type=tname, p=float(p), count=count, on=on)


def check_drift_rule(path, where: str, d: Drift, style: Style, catalog: Catalog | None = None):
    """StyleError unless ``d.rule`` names a rule of ``style`` that places a small object."""
    rules = [r for r in style.rules if rule_name(r) == d.rule]
    if not rules:
        names = ", ".join(dict.fromkeys(rule_name(r) for r in style.rules)) or "none"
        raise StyleError(
            path, f"no placement rule named {d.rule!r} (its rules: {names})", field=f"{where}.rule"
        )
    catalog = catalog or load_catalog()
    if catalog.type(rules[0].type).is_furniture:
        raise StyleError(
            path,
            f"{d.rule} places furniture, which stays across days: only small objects may drift",
            field=f"{where}.rule",
        )


def _drift(path, i: int, raw, style: Style, catalog: Catalog) -> Drift:
    where = f"drift[{i}]"
    if not isinstance(raw, dict):
        raise StyleError(path, "a drift entry must be a table [[drift]]", field=where)
    unknown = set(raw) - DRIFT_FIELDS
    if unknown:
        raise StyleError(
            path,
            f"unknown field(s) {sorted(unknown)} (allowed: {sorted(DRIFT_FIELDS)})",
            field=f"{where}.{sorted(unknown)[0]}",
        )
    for req in ("rule", "p", "from_day"):
        if req not in raw:
            raise StyleError(path, "missing", field=f"{where}.{req}")
    rule, p, day = raw["rule"], raw["p"], raw["from_day"]
    if not isinstance(rule, str):
        raise StyleError(path, f"must be a rule name REF/RELATION/TYPE, got {rule!r}",
                         field=f"{where}.rule")  # fmt: skip
    if isinstance(p, bool) or not isinstance(p, int | float) or not (0.0 <= p <= 1.0):
        raise StyleError(path, f"probability must be in [0, 1], got {p!r}", field=f"{where}.p")
    if isinstance(day, bool) or not isinstance(day, int) or not 1 <= day <= MAX_DAY:
        raise StyleError(
            path,
            f"must be an integer day in [1, {MAX_DAY}] (day 0 is the style as written), got {day!r}",
            field=f"{where}.from_day",
        )
    d = Drift(rule, float(p), int(day))
    check_drift_rule(path, where, d, style, catalog)
    return d


def _stays(path, raw, catalog: Catalog) -> tuple[tuple[str, float], ...]:
    """The [stay] table: small type (or ``"*"``) = the probability that an instance is still
    exactly where it was on the next day."""
    if not isinstance(raw, dict):
        raise StyleError(path, 'must be a table of Type = probability (or "*" = p)', field="stay")
    out = []
    for tname, p in raw.items():
        field = f"stay.{tname}"
        if tname != EVERY_TYPE and tname not in catalog:
            raise StyleError(
                path,
                f"unknown type '{tname}' (known: {', '.join(catalog.type_names)}, or \"*\" for "
                "every small type not named)",
                field=field,
            )
        if tname != EVERY_TYPE and catalog.type(tname).is_furniture:
            raise StyleError(
                path, f"'{tname}' is furniture, which stays across days: only small objects move",
                field=field,
            )  # fmt: skip
        if (
            isinstance(p, bool)
            or not isinstance(p, int | float)
            or not (0.0 <= p <= 1.0)
            or math.isnan(p)
        ):
            raise StyleError(path, f"probability must be in [0, 1], got {p!r}", field=field)
        out.append((tname, float(p)))
    return tuple(out)


def _check_fill(path, style: Style, catalog: Catalog, clearance: float) -> None:
    """Raise if the expected furniture (largest sizes) cannot fit in the smallest room with room
    for the robot to drive, or a single piece cannot fit at all."""
    n_mean: dict[str, float] = {t: (c[0] + c[1]) / 2 for t, c in style.furniture}
    for r in style.rules:
        if catalog.type(r.type).is_furniture:
            n_mean[r.type] = (
                n_mean.get(r.type, 0.0) + n_mean.get(r.ref, 0.0) * r.p * sum(r.count) / 2
            )
    need = 0.0
    for t, n in n_mean.items():
        sx, sy = catalog.type(t).size_max[0], catalog.type(t).size_max[1]
        need += n * (sx + clearance) * (sy + clearance)
        if min(sx, sy) + 2 * clearance > min(style.width[0], style.depth[0]) - 0.2:
            raise StyleError(
                path,
                f"a {t} does not fit in a {style.width[0]} x {style.depth[0]} m room "
                "with room to drive around it",
                field="room",
            )
    floor = style.width[0] * style.depth[0]
    if need > MAX_FILL * floor:
        raise StyleError(
            path,
            f"room too small for its furniture: {need:.1f} m^2 of furniture on "
            f"average (largest sizes, with robot clearance) on a {floor:.1f} m^2 floor "
            f"(max {MAX_FILL:.0%})",
            field="furniture",
        )


def parse_style(doc: dict, path: str | Path, catalog: Catalog, name: str | None = None) -> Style:
    """Validate a parsed style document; StyleError naming file and field on any problem."""
    unknown = set(doc) - TOP_FIELDS
    if unknown:
        raise StyleError(
            path,
            f"unknown field(s) {sorted(unknown)} (allowed: {sorted(TOP_FIELDS)})",
            field=sorted(unknown)[0],
        )
    sname = doc.get("name", name or Path(path).stem)
    if not isinstance(sname, str) or not sname:
        raise StyleError(path, "must be a non-empty string", field="name")
    desc = doc.get("description", "")
    if not isinstance(desc, str):
        raise StyleError(path, "must be a string", field="description")
    room = doc.get("room")
    if not isinstance(room, dict):
        raise StyleError(
            path, "missing [room] table (width, depth, height, door_width)", field="room"
        )
    unknown = set(room) - ROOM_FIELDS
    if unknown:
        raise StyleError(
            path,
            f"unknown field(s) {sorted(unknown)} (allowed: {sorted(ROOM_FIELDS)})",
            field=f"room.{sorted(unknown)[0]}",
        )
    for req in ("width", "depth"):
        if req not in room:
            raise StyleError(path, "missing", field=f"room.{req}")
    width = range_field(
        path, "room.width", room["width"], integer=False, lo_min=2.5, hi_max=MAX_ROOM_SIDE
    )
    depth = range_field(
        path, "room.depth", room["depth"], integer=False, lo_min=2.5, hi_max=MAX_ROOM_SIDE
    )
    height = range_field(
        path,
        "room.height",
        room.get("height", [2.6, 3.0]),
        integer=False,
        lo_min=2.2,
        hi_max=MAX_ROOM_HEIGHT,
    )
    door = range_field(
        path,
        "room.door_width",
        room.get("door_width", 0.9),
        integer=False,
        lo_min=0.7,
        hi_max=MAX_ROOM_SIDE,
    )
    if door[1] > min(width[0], depth[0]) - 1.0:
        raise StyleError(
            path,
            f"a {door[1]} m door does not fit a {min(width[0], depth[0])} m wall",
            field="room.door_width",
        )
    furniture = _counts(path, "furniture", doc.get("furniture", {}), catalog, furniture=True)
    present = {t for t, c in furniture if c[1] > 0}
    raw_rules = doc.get("rule", [])
    if not isinstance(raw_rules, list):
        raise StyleError(path, "must be an array of tables [[rule]]", field="rule")
    rules = []
    for i, raw in enumerate(raw_rules):
        r = _rule(path, i, raw, catalog, present)
        rules.append(r)
        if r.p > 0 and r.count[1] > 0:
            present.add(r.type)
    clutter = _counts(path, "clutter", doc.get("clutter", {}), catalog, furniture=False)
    for t, _ in clutter:
        if catalog.type(t).is_furniture:
            raise StyleError(
                path, f"'{t}' is furniture: put it in [furniture]", field=f"clutter.{t}"
            )
    style = Style(
        name=sname,
        path=str(path),
        description=desc,
        width=width,
        depth=depth,
        height=height,
        door_width=door,
        furniture=furniture,
        rules=tuple(rules),
        clutter=clutter,
        stays=_stays(path, doc.get("stay", {}), catalog),
    )
    _check_fill(path, style, catalog, RobotSpec().clearance)
    raw_drift = doc.get("drift", [])
    if not isinstance(raw_drift, list):
        raise StyleError(path, "must be an array of tables [[drift]]", field="drift")
    if raw_drift:
        drift = tuple(_drift(path, i, raw, style, catalog) for i, raw in enumerate(raw_drift))
        style = style.with_drift(drift, catalog)
    return style


def load_style(path_or_name: str | Path, catalog: Catalog | None = None) -> Style:
    """Load and validate a style by path or bare name (see ``available_styles()``); the file is
    read as ``knowledge.files.read_toml`` reads (a regular file, size and nesting limited)."""
    path = style_path(path_or_name)
    catalog = catalog or load_catalog()
    try:
        doc = read_toml(path)
    except InputFileError as exc:
        hint = (
            f" (available: {', '.join(available_styles())})"
            if exc.missing and not Path(path_or_name).suffix
            else ""
        )
        raise StyleError(
            path, "no such style file" + hint if exc.missing else exc.problem
        ) from None
    return parse_style(doc, path, catalog)
