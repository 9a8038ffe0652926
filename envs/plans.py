"""Floor plans before furnishing: which rooms a house gets and the rectangle cut into them, with
the doors between rooms (pure data; ``envs.floorplan`` furnishes the plan).

``plan(house, rng)`` draws candidate plans from the house's random stream (steps 1 and 2 of
``envs.floorplan``'s order of work) and keeps the first whose rooms all fit their styles, else
the one that misses least. A house style with layout rules (``envs.house_rules``) has its own
candidates (``_ruled_corridor_plan``, ``_ruled_open_plan``), and the first that meets every
rule and fits is kept, else the one that breaks fewest rules, then misses least; a style
without rules draws exactly the plans it drew before rules existed. A plan is (cells, passages, W, D): the cells' rectangles in plan
coordinates [0, W] x [0, D] (a corridor is a cell of style None) and the passages as
(room a, room b or -1 for the entrance, x, y, axis, width).
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field

import numpy as np

from ctxsearch.envs.house_rules import LayoutRules, violations
from ctxsearch.envs.houses import CORRIDOR, HouseError, HouseStyle
from ctxsearch.envs.styles import Style

WALL = 0.1  # m, wall thickness (the arena's WALL_THICKNESS)
DOOR_MARGIN = 0.35  # m kept between a door's edge and the corner of either room it joins
MIN_SIDE_FRACTION = 0.8  # a room's sides: at least this much of its style's smallest side
MAX_ASPECT = 2.2
PLAN_TRIES = 60
COUNT_TRIES = 100
_E = 1e-6


@dataclass
class _Cell:
    """A room of the plan before furnishing: its style (None: the corridor) and cell rectangle."""

    style: Style | None
    area: float
    rect: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    doors: list[int] = field(default_factory=list)  # indices into the plan's passages


def house_hash(name: str) -> int:
    """A stable (cross-process, cross-platform) hash of a house style name for seeding."""
    return zlib.crc32(("house:" + name).encode("utf-8"))


# -- 1. which rooms -------------------------------------------------------------------------------
def _draw_rooms(house: HouseStyle, rng: np.random.Generator) -> list[_Cell]:
    counts: list[int] = []
    for _ in range(COUNT_TRIES):
        counts = [int(rng.integers(lo, hi + 1)) for _, (lo, hi) in house.rooms]
        if house.total[0] <= sum(counts) <= house.total[1]:
            break
    else:  # clip: drop optional rooms from the end, or add required ones
        while sum(counts) > house.total[1]:
            i = max(i for i, c in enumerate(counts) if c > house.rooms[i][1][0])
            counts[i] -= 1
        while sum(counts) < house.total[0]:
            i = min(i for i, c in enumerate(counts) if c < house.rooms[i][1][1])
            counts[i] += 1
    cells = []
    for (style, _), k in zip(house.rooms, counts, strict=True):
        for _ in range(k):
            w, d = rng.uniform(*style.width), rng.uniform(*style.depth)
            cells.append(_Cell(style, float(w * d)))
    return cells


def _min_side(style: Style) -> float:
    return MIN_SIDE_FRACTION * min(style.width[0], style.depth[0])


def _misfit(cells: list[_Cell]) -> float:
    """How far the plan's rooms are from fitting their styles (0: all fit)."""
    bad = 0.0
    for c in cells:
        x0, y0, x1, y1 = c.rect
        w, d = x1 - x0 - WALL, y1 - y0 - WALL
        if c.style is None:
            continue
        lim = _min_side(c.style)
        bad += max(0.0, lim - w) + max(0.0, lim - d)
        bad += max(0.0, max(w, d) / max(min(w, d), 1e-3) - MAX_ASPECT)
    return bad


# -- 2. the plan ------------------------------------------------------------------------------------
def _corridor_plan(house: HouseStyle, rooms: list[_Cell], rng: np.random.Generator):
    """Cells (corridor last) and passages (room, corridor) + the entrance, in plan coordinates
    [0, W] x [0, D]. Returns (cells, passages, W, D)."""
    c = float(rng.uniform(*house.corridor_width))
    bands: list[list[_Cell]] = [[], []]
    area = [0.0, 0.0]
    for cell in sorted(rooms, key=lambda r: -r.area):
        k = int(np.argmin(area)) if area[0] != area[1] else int(rng.integers(2))
        bands[k].append(cell)
        area[k] += cell.area
    for band in bands:
        rng.shuffle(band)  # type: ignore[arg-type]
    return _corridor_cells(house, bands, area, c, rng)


def _corridor_cells(house: HouseStyle, bands: list[list[_Cell]], area: list[float], c: float, rng):
    """The corridor plan of two bands of rooms in order (their areas summed in ``area``) beside
    a corridor ``c`` wide: (cells, passages, W, D) as ``_corridor_plan`` returns them."""
    lengths = [math.sqrt(a * len(b)) for a, b in zip(area, bands, strict=True) if b]
    W = float(np.mean(lengths)) * float(rng.uniform(0.9, 1.15))
    total = sum(area) + c * W
    lo, hi = house.footprint
    scale = 1.0
    if total > hi:
        scale = (hi - c * W) / sum(area)
    elif total < lo:
        scale = (lo - c * W) / sum(area)
    scale = max(scale, 0.3)
    W *= math.sqrt(scale)
    depths = [a * scale / W for a in area]
    D = depths[0] + c + depths[1]
    y_band = [(0.0, depths[0]), (depths[0] + c, D)]
    corridor = _Cell(None, c * W, (0.0, depths[0], W, depths[0] + c))
    cells: list[_Cell] = []
    for k, band in enumerate(bands):
        x = 0.0
        for cell in band:
            w = cell.area * scale / depths[k]
            cell.rect = (x, y_band[k][0], x + w, y_band[k][1])
            x += w
        if band:  # round-off: the last room ends exactly at W
            r = band[-1].rect
            band[-1].rect = (r[0], r[1], W, r[3])
        cells.extend(band)
    cells.append(corridor)
    ci = len(cells) - 1
    passages: list[tuple[int, int, float, float, str, float]] = []  # (a, b, x, y, axis, width)
    for i, cell in enumerate(cells[:-1]):
        x0, _, x1, _ = cell.rect
        y_wall = depths[0] if cell.rect[1] < depths[0] else depths[0] + c
        width = float(rng.uniform(*house.door_width))
        span = (x0 + WALL / 2 + width / 2 + DOOR_MARGIN, x1 - WALL / 2 - width / 2 - DOOR_MARGIN)
        if span[0] > span[1]:
            x = (x0 + x1) / 2
        else:
            x = float(rng.uniform(*span))
        passages.append((i, ci, x, y_wall, "x", width))
    width = float(rng.uniform(*house.door_width))
    x_end = 0.0 if rng.random() < 0.5 else W
    passages.append((ci, -1, x_end, depths[0] + c / 2, "y", min(width, c - 0.3)))
    return cells, passages, W, D


def _split(cells: list[_Cell], rect, rng: np.random.Generator) -> None:
    """Cut ``rect`` into the cells' rectangles (areas in proportion), recursively."""
    if len(cells) == 1:
        cells[0].rect = rect
        return
    order = list(cells)
    rng.shuffle(order)  # type: ignore[arg-type]
    areas = np.array([c.area for c in order])
    cum = np.cumsum(areas)[:-1]
    k = int(np.argmin(np.abs(cum - areas.sum() / 2))) + 1
    if len(order) > 2 and rng.random() < 0.3:
        k = int(rng.integers(1, len(order)))
    a, b = order[:k], order[k:]
    frac = sum(c.area for c in a) / areas.sum()
    x0, y0, x1, y1 = rect
    if (x1 - x0) >= (y1 - y0):
        xm = x0 + frac * (x1 - x0)
        _split(a, (x0, y0, xm, y1), rng)
        _split(b, (xm, y0, x1, y1), rng)
    else:
        ym = y0 + frac * (y1 - y0)
        _split(a, (x0, y0, x1, ym), rng)
        _split(b, (x0, ym, x1, y1), rng)


def _shared_edge(a, b) -> tuple[str, float, float, float] | None:
    """The wall two cells share: (axis it runs along, its fixed coordinate, lo, hi), or None."""
    ax0, ay0, ax1, ay1 = a
    bx0, by0, bx1, by1 = b
    for xa, xb in ((ax1, bx0), (bx1, ax0)):
        if abs(xa - xb) < _E:
            lo, hi = max(ay0, by0), min(ay1, by1)
            if hi > lo:
                return "y", xa, lo, hi
    for ya, yb in ((ay1, by0), (by1, ay0)):
        if abs(ya - yb) < _E:
            lo, hi = max(ax0, bx0), min(ax1, bx1)
            if hi > lo:
                return "x", ya, lo, hi
    return None


def _open_plan(house: HouseStyle, rooms: list[_Cell], rng: np.random.Generator):
    """Recursive subdivision with a spanning tree of doors from the entrance room; None if the
    entrance room has no outside wall long enough or the rooms are not all joined."""
    W, D = _open_rect(house, rooms, rng)
    _split(rooms, (0.0, 0.0, W, D), rng)
    hub = _hub(house, rooms)
    entrance = _front_door(house, rooms, hub, W, D, rng)
    if entrance is None:
        return None
    passages: list[tuple[int, int, float, float, str, float]] = []
    # Doors: breadth-first from the hub over walls long enough for one.
    joined, queue = {hub}, [hub]
    while queue:
        i = queue.pop(0)
        nbrs = [j for j in range(len(rooms)) if j not in joined]
        rng.shuffle(nbrs)  # type: ignore[arg-type]
        for j in nbrs:
            edge = _shared_edge(rooms[i].rect, rooms[j].rect)
            width = float(rng.uniform(*house.door_width))
            need = width + 2 * DOOR_MARGIN + WALL
            if edge is None or edge[3] - edge[2] < need:
                continue
            axis, fixed, a, b = edge
            along = float(rng.uniform(a + need / 2, b - need / 2))
            xy = (along, fixed) if axis == "x" else (fixed, along)
            passages.append((i, j, xy[0], xy[1], axis, width))
            joined.add(j)
            queue.append(j)
    if len(joined) < len(rooms):
        return None
    passages.append(entrance)
    return rooms, passages, W, D


def _open_rect(house: HouseStyle, rooms: list[_Cell], rng: np.random.Generator):
    """An open plan's (W, D): the rooms' areas scaled into the footprint, a random aspect."""
    total = sum(r.area for r in rooms)
    lo, hi = house.footprint
    scale = min(max(total, lo), hi) / total
    for r in rooms:
        r.area *= scale
    total *= scale
    aspect = float(rng.uniform(1.0, 1.6))
    W, D = math.sqrt(total * aspect), math.sqrt(total / aspect)
    if rng.random() < 0.5:
        W, D = D, W
    return W, D


def _hub(house: HouseStyle, rooms: list[_Cell]) -> int:
    """The entrance room of an open plan: ``house.entrance``'s, else the largest."""
    names = [r.style.name if r.style else CORRIDOR for r in rooms]
    if house.entrance in names:
        return names.index(house.entrance)
    return int(np.argmax([r.area for r in rooms]))


def _front_door(
    house: HouseStyle, rooms: list[_Cell], hub: int, W: float, D: float, rng, near=None
):
    """The entrance passage on the hub's longest outside wall (anywhere along it), or with
    ``near`` (x, y) at the point of the hub's outside walls nearest it; None if no outside wall
    is long enough."""
    width = float(rng.uniform(*house.door_width))
    need = width + 2 * DOOR_MARGIN + WALL
    x0, y0, x1, y1 = rooms[hub].rect
    outside = [
        (x1 - x0, "x", y, x0, x1) for y in (0.0, D) if abs(y0 - y) < _E or abs(y1 - y) < _E
    ] + [(y1 - y0, "y", x, y0, y1) for x in (0.0, W) if abs(x0 - x) < _E or abs(x1 - x) < _E]
    outside = [o for o in outside if o[0] >= need]
    if not outside:
        return None
    if near is None:
        _, axis, fixed, a, b = max(outside, key=lambda o: (o[0], o[1]))
        along = float(rng.uniform(a + need / 2, b - need / 2))
    else:

        def nearest(o) -> tuple[float, float]:  # (the point along the wall, its distance)
            _, axis, fixed, a, b = o
            u, v = (near[0], near[1]) if axis == "x" else (near[1], near[0])
            t = min(max(u, a + need / 2), b - need / 2)
            return t, math.hypot(t - u, fixed - v)

        wall = min(outside, key=lambda o: (nearest(o)[1], o[1], o[2]))
        _, axis, fixed, _, _ = wall
        along = nearest(wall)[0]
    xy = (along, fixed) if axis == "x" else (fixed, along)
    return (hub, -1, xy[0], xy[1], axis, width)


# -- 2'. a plan by the house's layout rules --------------------------------------------------------
RULED_PLAN_TRIES = 300  # candidate plans of a house style with [layout] rules
Passages = list[tuple[int, int, float, float, str, float]]


def _kinds(cells: list[_Cell]) -> list[str]:
    return [c.style.name if c.style else CORRIDOR for c in cells]


def broken(rules: LayoutRules, cells: list[_Cell], passages) -> list[str]:
    """The rules a plan breaks (``envs.house_rules.violations`` on its cells and passages)."""
    return violations(rules, _kinds(cells), [(a, b, (x, y)) for a, b, x, y, _, _ in passages])


def _chains(rules: LayoutRules, rooms: list[_Cell], rng: np.random.Generator):
    """Rooms that must stand side by side in a band: chains joined by ``next_to`` pairs (a room
    has at most two sides in a band; the room by the entrance keeps one free, for the band's end).
    Returns (chains, pairs), pairs as (i, j) room indices."""
    kinds = _kinds(rooms)
    n = len(rooms)
    chain = {i: [i] for i in range(n)}
    deg = [0] * n
    cap = [1 if k == rules.by_entrance else 2 for k in kinds]
    pairs: list[tuple[int, int]] = []
    for i in (int(x) for x in rng.permutation(n)):
        must = rules.must(kinds[i])
        if not must or CORRIDOR in must or deg[i] >= cap[i]:
            continue
        if any(kinds[b if a == i else a] in must for a, b in pairs if i in (a, b)):
            continue
        cands = [j for j in range(n) if j != i and kinds[j] in must and deg[j] < cap[j]
                 and chain[j] is not chain[i] and rules.allowed(kinds[i], kinds[j])]  # fmt: skip
        if not cands:
            continue
        j = cands[int(rng.integers(len(cands)))]
        a, b = chain[i], chain[j]
        if a[-1] != i:
            a.reverse()
        if b[0] != j:
            b.reverse()
        merged = a + b
        for k in merged:
            chain[k] = merged
        deg[i] += 1
        deg[j] += 1
        pairs.append((i, j))
    seen: dict[int, list[int]] = {}
    for i in range(n):
        seen.setdefault(id(chain[i]), chain[i])
    return list(seen.values()), pairs


def _ruled_corridor_plan(house: HouseStyle, rules: LayoutRules, rooms: list[_Cell], rng):
    """A corridor plan whose bands hold each ``next_to`` pair side by side with a door between
    them, and the room by the entrance first in its band at the front door's end with its door
    at the band's end."""
    c = float(rng.uniform(*house.corridor_width))
    chains, pairs = _chains(rules, rooms, rng)
    kinds = _kinds(rooms)
    first = next((i for i in (int(x) for x in rng.permutation(len(rooms)))
                  if kinds[i] == rules.by_entrance), None)  # fmt: skip
    bands: list[list[list[int]]] = [[], []]
    area = [0.0, 0.0]
    for ch in sorted(chains, key=lambda ch: -sum(rooms[i].area for i in ch)):
        k = int(np.argmin(area)) if area[0] != area[1] else int(rng.integers(2))
        bands[k].append(ch)
        area[k] += sum(rooms[i].area for i in ch)
    for band in bands:
        rng.shuffle(band)  # type: ignore[arg-type]
        for ch in band:
            if rng.random() < 0.5:
                ch.reverse()
        for ch in band:
            if first in ch:
                band.remove(ch)
                band.insert(0, ch if ch[0] == first else ch[::-1])
                break
    order = [[rooms[i] for ch in band for i in ch] for band in bands]
    cells, passages, W, D = _corridor_cells(house, order, area, c, rng)
    index = {id(cell): k for k, cell in enumerate(cells)}
    if first is not None:  # its door at the end of its span nearest the front door (x = 0)
        k = index[id(rooms[first])]
        a, b, x, y, axis, width = passages[k]
        x0 = cells[k].rect[0]
        passages[k] = (a, b, min(x, x0 + WALL / 2 + width / 2 + DOOR_MARGIN), y, axis, width)
    front = passages.pop()
    passages.append((front[0], front[1], 0.0, *front[3:]))
    for i, j in pairs:
        door = _wall_door(house, cells, index[id(rooms[i])], index[id(rooms[j])], rng)
        if door is not None:
            passages.insert(-1, door)
    if rng.random() < 0.5:  # the front door at either end
        for cell in cells:
            x0, y0, x1, y1 = cell.rect
            cell.rect = (W - x1, y0, W - x0, y1)
        passages = [(a, b, W - x, y, axis, w) for a, b, x, y, axis, w in passages]
    return cells, passages, W, D


def _wall_door(house: HouseStyle, cells: list[_Cell], i: int, j: int, rng, near=None):
    """A door between cells i and j on the wall they share (at ``near`` along it, as far as the
    wall allows, else anywhere), or None if the wall is too short."""
    edge = _shared_edge(cells[i].rect, cells[j].rect)
    width = float(rng.uniform(*house.door_width))
    need = width + 2 * DOOR_MARGIN + WALL
    if edge is None or edge[3] - edge[2] < need:
        return None
    axis, fixed, a, b = edge
    lo, hi = a + need / 2, b - need / 2
    along = float(rng.uniform(lo, hi)) if near is None else min(max(near, lo), hi)
    xy = (along, fixed) if axis == "x" else (fixed, along)
    return (i, j, xy[0], xy[1], axis, width)


def _rows(rooms: list[_Cell], W: float, D: float, rng: np.random.Generator) -> None:
    """Cut [0, W] x [0, D] into two rows along its longer side and each row across into its rooms
    (which rooms in which row and their order drawn; areas in proportion): the plans where a room
    in the middle of one row opens into several rooms of the other, which ``_split``'s first cut
    across the longer side rarely makes."""
    order = list(range(len(rooms)))
    rng.shuffle(order)  # type: ignore[arg-type]
    k = int(rng.integers(1, len(order))) if len(order) > 1 else 1
    along = W >= D
    L, H = (W, D) if along else (D, W)
    total = sum(r.area for r in rooms)
    y = 0.0
    for n, row in enumerate((order[:k], order[k:])):
        if not row:
            continue
        area = sum(rooms[i].area for i in row)
        y1 = H if n == 1 or k == len(order) else y + H * area / total
        x = 0.0
        for j, i in enumerate(row):
            x1 = L if j == len(row) - 1 else x + L * rooms[i].area / area
            rooms[i].rect = (x, y, x1, y1) if along else (y, x, y1, x1)
            x = x1
        y = y1


def _ruled_open_plan(house: HouseStyle, rules: LayoutRules, rooms: list[_Cell], rng):
    """An open plan whose doors follow the rules: the room by the entrance opens into the
    entrance room at the end of their wall nearer the plan's edge and the front door is placed
    on the entrance room's outside wall nearest that door, every ``next_to`` is a door where the
    rooms share a wall, and the rest join the entrance room's breadth-first over allowed pairs
    only. Half the candidates are cut as ``_rows``, half as ``_split``. None if the entrance room
    has no outside wall long enough or some room cannot be joined."""
    W, D = _open_rect(house, rooms, rng)
    if rng.random() < 0.5:
        _rows(rooms, W, D, rng)
    else:
        _split(rooms, (0.0, 0.0, W, D), rng)
    hub = _hub(house, rooms)
    kinds = _kinds(rooms)
    n = len(rooms)
    passages: Passages = []
    links: dict[int, set[int]] = {i: set() for i in range(n)}

    def add(i: int, j: int, near=None) -> bool:
        door = _wall_door(house, rooms, i, j, rng, near)
        if door is not None:
            passages.append(door)
            links[i].add(j)
            links[j].add(i)
        return door is not None

    near = None  # the front door goes next to the door of the room by the entrance
    if rules.by_entrance is not None and rules.allowed(rules.by_entrance, kinds[hub]):
        for i in (int(x) for x in rng.permutation(n)):
            edge = _shared_edge(rooms[i].rect, rooms[hub].rect)
            if i == hub or kinds[i] != rules.by_entrance or edge is None:
                continue
            axis, _, a, b = edge  # its door at the end of the wall nearer the plan's edge
            size = W if axis == "x" else D
            if add(i, hub, a if min(a, size - a) <= min(b, size - b) else b):
                near = passages[-1][2:4]
                break
    entrance = _front_door(house, rooms, hub, W, D, rng, near)
    if entrance is None:
        return None
    for i in (int(x) for x in rng.permutation(n)):
        must = rules.must(kinds[i])
        if not must or any(kinds[j] in must for j in links[i]):
            continue
        for j in (int(x) for x in rng.permutation(n)):
            if j != i and kinds[j] in must and rules.allowed(kinds[i], kinds[j]) and add(i, j):
                break
    joined, queue = {hub}, [hub]
    while queue:
        i = queue.pop(0)
        for j in (int(x) for x in rng.permutation(n)):
            if j in joined:
                continue
            if j not in links[i] and not (rules.allowed(kinds[i], kinds[j]) and add(i, j)):
                continue
            todo = [j]  # j and every room its doors already join
            while todo:
                k = todo.pop()
                if k not in joined:
                    joined.add(k)
                    queue.append(k)
                    todo.extend(links[k])
    if len(joined) < n:
        return None
    passages.append(entrance)
    return rooms, passages, W, D


def plan(house: HouseStyle, rng: np.random.Generator):
    """The house's plan: candidates drawn in turn until one meets every layout rule and fits
    every room's style; else the best one found, fewest broken rules first, then least misfit.
    With rules, the rooms (kinds and areas) are drawn once and only their arrangement is drawn
    again (the rules would otherwise favour houses without the rooms they constrain). Without
    rules it is the first that fits of ``PLAN_TRIES`` (else the one that misses least), each
    try with rooms drawn anew."""
    rules = house.layout_rules
    tries = PLAN_TRIES if rules is None else RULED_PLAN_TRIES
    best, best_bad = None, (math.inf, math.inf)
    drawn = None if rules is None else _draw_rooms(house, rng)
    for _ in range(tries):
        if drawn is None:
            rooms = _draw_rooms(house, rng)
        else:  # the same rooms in every try: the rules never choose which rooms a house has
            rooms = [_Cell(c.style, c.area) for c in drawn]
        if rules is not None and house.plan == "corridor":
            candidate = _ruled_corridor_plan(house, rules, rooms, rng)
        elif rules is not None:
            candidate = _ruled_open_plan(house, rules, rooms, rng)
        elif house.plan == "corridor":
            candidate = _corridor_plan(house, rooms, rng)
        else:
            candidate = _open_plan(house, rooms, rng)
        if candidate is None:
            continue
        bad = (0 if rules is None else len(broken(rules, *candidate[:2])), _misfit(candidate[0]))
        if bad < best_bad:
            best, best_bad = candidate, bad
        if bad == (0, 0.0):
            break
    if best is None:
        raise HouseError(
            house.path,
            f"no plan of {tries} tried gives every room a door (rooms too small or "
            "too many for the footprint?)",
            field="rooms",
        )
    return best
