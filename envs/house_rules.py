"""Layout rules of a house style: which room kinds must or may neighbour which (pure data).

A room kind is a room style's name, or ``corridor`` (the hall of a corridor plan). Two rooms
*neighbour* when they share a door (a ``Passage`` between them): what a robot sees through a
doorway, not a wall without an opening. The rules, per room kind (a house style's ``[layout]``
table, documented at the top of ``assets/houses/apartment.toml``):

- ``next_to = [kinds]`` (must): every room of the kind shares a door with a room of at least one
  of the listed kinds;
- ``only_to = [kinds]`` (may): every door between a room of the kind and another room leads to a
  room of one of the listed kinds (the front door is not a door between rooms);
- ``by_entrance = true`` (must): a room of the kind shares a door with the room the front door
  opens into (the corridor in a corridor plan, the entrance room in an open plan), and of that
  room's doors to other rooms its door is the nearest to the front door (door centres, straight
  line): the first door a visitor passes.

A rule about a kind the house happens not to hold is met. The rules are world-generation data:
``envs.plans`` honours them and ``violations`` measures them; the robot never reads them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

CORRIDOR = "corridor"  # the style name of a corridor plan's hall (a room with no furniture)
RULE_FIELDS = ("next_to", "only_to", "by_entrance")


@dataclass(frozen=True)
class LayoutRules:
    """A house style's validated layout rules: ``next_to`` and ``only_to`` as (kind, listed
    kinds) in file order, ``by_entrance`` the kind whose room opens next to the front door."""

    next_to: tuple[tuple[str, tuple[str, ...]], ...] = ()
    only_to: tuple[tuple[str, tuple[str, ...]], ...] = ()
    by_entrance: str | None = None

    def must(self, kind: str) -> tuple[str, ...]:
        """The kinds one of which a room of ``kind`` must share a door with (() : no rule)."""
        return dict(self.next_to).get(kind, ())

    def allowed(self, a: str, b: str) -> bool:
        """Whether a door between a room of kind ``a`` and one of kind ``b`` breaks no
        ``only_to`` rule (of either)."""
        only = dict(self.only_to)
        return (a not in only or b in only[a]) and (b not in only or a in only[b])


# -- checking a plan ------------------------------------------------------------------------------
def violations(
    rules: LayoutRules,
    kinds: Sequence[str],
    doors: Sequence[tuple[int, int, tuple[float, float]]],
) -> list[str]:
    """The rules a plan breaks, one line each starting with the rule (``kitchen.next_to: ...``;
    empty: it meets every rule). ``kinds[i]`` is room i's kind; ``doors`` are (room a, room b,
    door centre) with b = -1 for the front door."""
    nbrs: dict[int, set[int]] = {i: set() for i in range(len(kinds))}
    for a, b, _ in doors:
        if b >= 0:
            nbrs[a].add(b)
            nbrs[b].add(a)
    out = []
    for kind, listed in rules.next_to:
        for i, k in enumerate(kinds):
            if k == kind and not any(kinds[j] in listed for j in nbrs[i]):
                out.append(f"{kind}.next_to: room {i} shares no door with {' or '.join(listed)}")
    only = dict(rules.only_to)
    for i, k in enumerate(kinds):
        for j in sorted(nbrs[i]):
            if k in only and kinds[j] not in only[k]:
                out.append(f"{k}.only_to: room {i} shares a door with {kinds[j]} (room {j})")
    if rules.by_entrance is not None and rules.by_entrance in kinds:
        out += _entrance_violation(rules.by_entrance, kinds, doors)
    return out


def _entrance_violation(kind: str, kinds: Sequence[str], doors) -> list[str]:
    front = [(a, c) for a, b, c in doors if b == -1]
    if len(front) != 1:
        return [f"{kind}.by_entrance: the plan has {len(front)} front doors"]
    hall, (fx, fy) = front[0]
    dist = {}  # room -> distance of its door into the hall from the front door
    for a, b, (x, y) in doors:
        if b >= 0 and hall in (a, b):
            other = b if a == hall else a
            d = math.hypot(x - fx, y - fy)
            dist[other] = min(d, dist.get(other, math.inf))
    if dist and kinds[min(dist, key=lambda r: (dist[r], r))] == kind:
        return []
    return [f"{kind}.by_entrance: no room of it has the door nearest the front door"]


def layout_violations(rules: LayoutRules, layout) -> list[str]:
    """``violations`` of a generated house (an ``envs.layout.RoomLayout``)."""
    kinds = [r.style for r in layout.rooms]
    return violations(rules, kinds, [(p.rooms[0], p.rooms[1], p.center) for p in layout.doors])


# -- parsing --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _House:
    """What the rules are checked against: the room kinds with their [min, max] counts, the plan
    type and the entrance room's kind (None: the largest room's)."""

    path: object
    counts: dict[str, tuple[int, int]]
    plan: str
    entrance: str | None
    error: Callable[..., Exception]

    def fail(self, message: str, field: str) -> Exception:
        return self.error(self.path, message, field=field)


def parse_layout(
    raw,
    path,
    counts: dict[str, tuple[int, int]],
    plan: str,
    entrance: str | None,
    error: Callable[..., Exception],
) -> LayoutRules:
    """Validate a house style's ``[layout]`` table; ``error(path, message, field=...)`` is raised
    (one line naming the field) on a wrong type, an unknown kind or field, a kind the house
    cannot hold, or rules that contradict each other."""
    house = _House(path, counts, plan, entrance, error)
    if not isinstance(raw, dict) or not raw:
        raise house.fail(
            "must be a table of room kind = {next_to = [...], only_to = [...], by_entrance = "
            "true} (leave [layout] out for no rules)",
            "layout",
        )
    next_to, only_to, by_entrance = [], [], None
    for kind, table in raw.items():
        field = f"layout.{kind}"
        if kind == CORRIDOR:
            raise house.fail("the corridor takes no rules of its own (only rooms do)", field)
        if kind not in counts:
            raise house.fail(f"not one of the house's room kinds {sorted(counts)}", field)
        if not isinstance(table, dict) or not table:
            raise house.fail(f"must be a table of one or more of {list(RULE_FIELDS)}", field)
        unknown = sorted(set(table) - set(RULE_FIELDS))
        if unknown:
            raise house.fail(
                f"unknown field (allowed: {list(RULE_FIELDS)})", f"{field}.{unknown[0]}"
            )
        if "next_to" in table:
            next_to.append((kind, _kinds(house, table["next_to"], f"{field}.next_to")))
        if "only_to" in table:
            only_to.append((kind, _kinds(house, table["only_to"], f"{field}.only_to")))
        flag = table.get("by_entrance", False)
        if not isinstance(flag, bool):
            raise house.fail("must be true or false", f"{field}.by_entrance")
        if flag and by_entrance is not None:
            raise house.fail(
                f"only one room kind can open next to the front door (already: {by_entrance})",
                f"{field}.by_entrance",
            )
        if flag:
            by_entrance = kind
    rules = LayoutRules(tuple(next_to), tuple(only_to), by_entrance)
    _check_rules(house, rules)
    return rules


def _kinds(house: _House, value, field: str) -> tuple[str, ...]:
    """A non-empty list of distinct room kinds of the house (``corridor`` in corridor plans)."""
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise house.fail("must be a non-empty list of room kinds", field)
    if len(set(value)) != len(value):
        raise house.fail("lists a room kind twice", field)
    known = sorted(house.counts) + ([CORRIDOR] if house.plan == "corridor" else [])
    for v in value:
        if v == CORRIDOR and house.plan != "corridor":
            raise house.fail("an open plan has no corridor", field)
        if v not in known:
            raise house.fail(f"unknown room kind {v!r} (the house's: {known})", field)
    return tuple(value)


def _guaranteed(house: _House, kind: str, target: str) -> bool:
    """Whether every house with a room of ``kind`` has another room of ``target``."""
    if target == CORRIDOR:
        return house.plan == "corridor"
    return house.counts[target][0] >= (2 if target == kind else 1)


def _check_rules(house: _House, rules: LayoutRules) -> None:
    """Rules that no plan could meet: a must without a kind every house holds, a must that an
    only_to forbids, a room whose only_to leaves it no door, ..."""
    for kind, listed in rules.next_to:
        field = f"layout.{kind}.next_to"
        if not any(_guaranteed(house, kind, t) for t in listed):
            raise house.fail(
                f"needs one of {list(listed)} in every house (their min counts allow a house "
                "without one)",
                field,
            )
        for t in listed:
            if not rules.allowed(kind, t):
                raise house.fail(f"a door to {t} is forbidden by an only_to rule", field)
    for kind, listed in rules.only_to:
        field = f"layout.{kind}.only_to"
        if house.plan == "corridor" and CORRIDOR not in listed:
            raise house.fail("in a corridor plan every room opens onto the corridor", field)
        if not any(rules.allowed(kind, t) for t in listed):
            raise house.fail("no listed kind may have a door to it (their only_to)", field)
    kind = rules.by_entrance
    if kind is None:
        return
    field = f"layout.{kind}.by_entrance"
    hall = CORRIDOR if house.plan == "corridor" else house.entrance
    if house.plan == "open" and kind == house.entrance:
        raise house.fail("the entrance room itself has the front door", field)
    if hall is not None and not rules.allowed(kind, hall):
        raise house.fail(f"a door to the entrance room ({hall}) is forbidden by only_to", field)
