"""House styles: what a kind of home or floor holds (which room styles and how many of each, the
footprint, the plan type, corridor and door widths), loaded from ``assets/houses/<name>.toml``.

The format is documented at the top of ``assets/houses/apartment.toml``. Like room styles, house
styles are data: a user adds one without code, and a bad one gets a one-line error naming file and
field. ``resolve_style`` turns any ``--style`` value (a room style or a house style, by name or
path) into a ``Style`` or a ``HouseStyle``; ``generate_layout`` makes the layout of either.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ctxsearch.envs.house_rules import CORRIDOR as CORRIDOR  # re-exported: the hall's style name
from ctxsearch.envs.house_rules import LayoutRules, parse_layout
from ctxsearch.envs.styles import (
    STYLES_DIR,
    Style,
    StyleError,
    available_styles,
    load_style,
    range_field,
)
from ctxsearch.knowledge.catalog import ASSETS_DIR, Catalog, asset_file, load_catalog
from ctxsearch.knowledge.files import InputFileError, read_toml

HOUSES_DIR = ASSETS_DIR / "houses"
TOP_FIELDS = {"name", "description", "house", "rooms", "layout"}
HOUSE_FIELDS = {
    "rooms",
    "footprint",
    "height",
    "plan",
    "corridor_width",
    "door_width",
    "entrance",
    "seed_name",
}
PLANS = ("corridor", "open")
FOOTPRINT_LIMITS = (20.0, 400.0)  # m^2: what the plan generator is built for
MAX_ROOMS = 12


class HouseError(StyleError):
    """A house-style file is malformed or inconsistent with its room styles."""


@dataclass(frozen=True)
class HouseStyle:
    """A validated house style: ``rooms`` is (room style, [min, max] count) in file order."""

    name: str
    path: str
    description: str
    rooms: tuple[tuple[Style, tuple[int, int]], ...]
    total: tuple[int, int]  # how many rooms (the corridor not counted)
    footprint: tuple[float, float]  # m^2, the whole plan (corridor included)
    height: tuple[float, float]
    plan: str  # 'corridor' (rooms on both sides of one corridor) or 'open' (rooms open into rooms)
    corridor_width: tuple[float, float]
    door_width: tuple[float, float]
    entrance: str | None  # the room style whose room has the entrance ('open' plans)
    layout_rules: LayoutRules | None = None  # which room kinds must or may share doors (None: none)
    seed_name: str = ""  # the name the random stream is keyed by ('': the style's own name)

    @property
    def types(self) -> tuple[str, ...]:
        """Every object type that can occur in houses of this style, in first-mention order."""
        seen: dict[str, None] = {}
        for style, _ in self.rooms:
            for t in style.types:
                seen[t] = None
        return tuple(seen)


# What a --style names: a room style or a house style.
WorldStyle = Style | HouseStyle


def available_houses() -> list[str]:
    """Names of the house styles shipped in ``assets/houses``."""
    return sorted(p.stem for p in HOUSES_DIR.glob("*.toml"))


def _is_name(value: str | Path) -> bool:
    return asset_file(value, HOUSES_DIR) != Path(value)


def _range(path, field: str, value, *, integer: bool, lo_min: float, hi_max: float) -> tuple:
    return range_field(
        path, field, value, integer=integer, lo_min=lo_min, hi_max=hi_max, error=HouseError
    )


def _room_style(path, key: str, catalog: Catalog) -> Style:
    field = f"rooms.{key}"
    if _is_name(key):
        if not (STYLES_DIR / f"{key}.toml").exists():
            raise HouseError(
                path,
                f"unknown room style '{key}' (available: {', '.join(available_styles())})",
                field=field,
            )
        return load_style(key, catalog)
    p = Path(key)
    if not p.is_absolute():
        p = Path(path).parent / p
    if not p.exists() and not p.is_symlink():
        raise HouseError(path, f"no such room style file {str(p)!r}", field=field)
    try:
        return load_style(p, catalog)
    except StyleError as exc:  # its one line, and where the house names it
        raise HouseError(path, str(exc), field=field) from None


def _unknown(path, given: dict, allowed: set[str], prefix: str = "") -> None:
    unknown = set(given) - allowed
    if unknown:
        raise HouseError(
            path,
            f"unknown field(s) {sorted(unknown)} (allowed: {sorted(allowed)})",
            field=prefix + sorted(unknown)[0],
        )


def _header(doc: dict, path) -> tuple[str, str]:
    """The house style's (name, description)."""
    _unknown(path, doc, TOP_FIELDS)
    name = doc.get("name", Path(path).stem)
    if not isinstance(name, str) or not name:
        raise HouseError(path, "must be a non-empty string", field="name")
    if name in available_styles():
        raise HouseError(path, f"'{name}' is already a room style's name", field="name")
    desc = doc.get("description", "")
    if not isinstance(desc, str):
        raise HouseError(path, "must be a string", field="description")
    return name, desc


def _house_table(doc: dict, path) -> dict:
    """The validated ``[house]`` table: total, footprint, height, plan, corridor and door widths,
    entrance (still unchecked against the rooms)."""
    house = doc.get("house")
    if not isinstance(house, dict):
        raise HouseError(path, "missing [house] table (rooms, footprint, plan...)", field="house")
    _unknown(path, house, HOUSE_FIELDS, "house.")
    for req in ("rooms", "footprint"):
        if req not in house:
            raise HouseError(path, "missing", field=f"house.{req}")

    def num(key, default, lo, hi):
        return _range(
            path, f"house.{key}", house.get(key, default), integer=False, lo_min=lo, hi_max=hi
        )

    out = {
        "total": _range(
            path, "house.rooms", house["rooms"], integer=True, lo_min=1, hi_max=MAX_ROOMS
        ),
        "footprint": num("footprint", None, *FOOTPRINT_LIMITS),
        "height": num("height", [2.6, 2.9], 2.3, 5),
        "plan": house.get("plan", "corridor"),
        "corridor_width": num("corridor_width", [1.3, 1.6], 1.2, 4.0),
        "door_width": num("door_width", [0.85, 1.0], 0.75, 1.6),
        "entrance": house.get("entrance"),
        "seed_name": house.get("seed_name", ""),
    }
    if not isinstance(out["seed_name"], str):
        raise HouseError(path, "must be a house style's name", field="house.seed_name")
    if out["plan"] not in PLANS:
        raise HouseError(path, f"must be one of {PLANS}, got {out['plan']!r}", field="house.plan")
    door, corridor = out["door_width"], out["corridor_width"]
    if out["plan"] == "corridor" and door[1] > corridor[0] - 0.3:
        raise HouseError(
            path,
            f"a {door[1]} m entrance does not fit the end of a {corridor[0]} m corridor",
            field="house.door_width",
        )
    return out


def _rooms(doc: dict, path, catalog: Catalog) -> list[tuple[Style, tuple[int, int]]]:
    """The ``[rooms]`` table: (room style, [min, max] count) in file order."""
    raw = doc.get("rooms")
    if not isinstance(raw, dict) or not raw:
        raise HouseError(path, "must be a table of room_style = [min, max]", field="rooms")
    rooms = []
    for key, val in raw.items():
        count = _range(path, f"rooms.{key}", val, integer=True, lo_min=0, hi_max=MAX_ROOMS)
        rooms.append((_room_style(path, key, catalog), count))
    return rooms


def _check_consistent(path, house: dict, rooms: list[tuple[Style, tuple[int, int]]]) -> None:
    """The room counts, the entrance and the footprint agree with each other."""
    total, entrance = house["total"], house["entrance"]
    lo = sum(c[0] for _, c in rooms)
    hi = sum(c[1] for _, c in rooms)
    if lo > total[1] or hi < total[0]:
        raise HouseError(
            path,
            f"the room counts give {lo}..{hi} rooms, outside house.rooms {list(total)}",
            field="rooms",
        )
    if house["plan"] == "open" and total[0] < 1:
        raise HouseError(path, "an open plan needs at least one room", field="house.rooms")
    names = [s.name for s, _ in rooms]
    if entrance is not None:
        if entrance not in names:
            raise HouseError(
                path, f"must be one of the house's room styles {names}", field="house.entrance"
            )
        if next(c for s, c in rooms if s.name == entrance)[0] < 1:
            raise HouseError(
                path,
                f"every house needs its entrance room: rooms.{entrance} min >= 1",
                field="house.entrance",
            )
    smallest = sum(c[0] * s.width[0] * s.depth[0] for s, c in rooms)
    if smallest * 0.7 > house["footprint"][1]:
        raise HouseError(
            path,
            f"the fewest rooms need about {smallest:.0f} m^2, the footprint allows "
            f"{house['footprint'][1]:.0f} m^2",
            field="house.footprint",
        )


def parse_house(doc: dict, path: str | Path, catalog: Catalog) -> HouseStyle:
    """Validate a parsed house document; HouseError naming file and field on any problem."""
    name, desc = _header(doc, path)
    house = _house_table(doc, path)
    rooms = _rooms(doc, path, catalog)
    _check_consistent(path, house, rooms)
    rules = None
    if "layout" in doc:
        counts: dict[str, tuple[int, int]] = {}
        for s, (lo, hi) in rooms:  # a room style listed twice (by name and path) adds up
            c = counts.get(s.name, (0, 0))
            counts[s.name] = (c[0] + lo, c[1] + hi)
        rules = parse_layout(
            doc["layout"], path, counts, house["plan"], house["entrance"], HouseError
        )
    return HouseStyle(
        name=name, path=str(path), description=desc, rooms=tuple(rooms), layout_rules=rules, **house
    )


def _read(path: Path, cls: type[StyleError]) -> dict:
    """The TOML document of a house or room style file (``knowledge.files.read_toml``: a regular
    file, size and nesting limited); ``cls`` words the error."""
    try:
        return read_toml(path)
    except InputFileError as exc:
        raise cls(path, exc.problem) from None


def load_house(path_or_name: str | Path, catalog: Catalog | None = None) -> HouseStyle:
    """Load and validate a house style by path or bare name (see ``available_houses()``)."""
    catalog = catalog or load_catalog()
    if _is_name(path_or_name):
        path = HOUSES_DIR / f"{Path(path_or_name).name}.toml"
        if not path.exists():
            raise HouseError(
                path, f"no such house style (available: {', '.join(available_houses())})"
            )
    else:
        path = Path(path_or_name)
    return parse_house(_read(path, HouseError), path, catalog)


def resolve_style(path_or_name: str | Path, catalog: Catalog | None = None) -> WorldStyle:
    """The room style or house style a ``--style`` value names: a bare name is looked up in
    ``assets/styles`` and ``assets/houses`` (names never collide), a path is a house style if
    it has a ``[house]`` table, else a room style."""
    catalog = catalog or load_catalog()
    if _is_name(path_or_name):
        name = Path(path_or_name).name
        room, house = (STYLES_DIR / f"{name}.toml").exists(), (HOUSES_DIR / f"{name}.toml").exists()
        if room and house:
            raise HouseError(
                HOUSES_DIR / f"{name}.toml", f"'{name}' is both a room style and a house style"
            )
        if house:
            return load_house(name, catalog)
        if room:
            return load_style(name, catalog)
        raise StyleError(
            name,
            f"no such style (room styles: {', '.join(available_styles())}; "
            f"house styles: {', '.join(available_houses())})",
        )
    path = Path(path_or_name)
    try:
        doc = read_toml(path)
    except InputFileError:
        doc = None  # load_style reports the problem in its words (reading it once more)
    if isinstance(doc, dict) and "house" in doc:
        return parse_house(doc, path, catalog)
    return load_style(path, catalog)
