"""Ground truth: P(rel(B)) for every (A, rel, B), estimated over generated rooms of a style.

For a reference type A, a relation rel in RELATIONS(A) and a type B, P(rel(B)) is the probability
that an instance of A has at least one B in rel (paper, section 4). It is estimated exactly as
the robot counts, with the same geometry code (``knowledge.geometry.related``) on the
generator's layouts:

    n = number of instances of A over all sampled rooms
    y = how many of them had at least one B in v_rel(a)
    p = y / n,    se = sqrt(p (1 - p) / n)       (binomial Monte Carlo standard error)

Instances in one room are not independent (two desks of one office share its style draw and
compete for the same floor), so ``se`` can be optimistic; ``se_room`` is the room-clustered
(ratio-estimator) standard error, which treats rooms as the independent units:

    se_room = sqrt( R / (R - 1) * sum_r (y_r - p n_r)^2 ) / n      over the R rooms with n_r > 0.

Rooms are ``generate_room(style, seed + i)`` for i = 0 .. samples - 1. For a house style the
samples are houses (``generate_house(style, seed + i)``) and every furnished room of every house is
one unit: relations stay object-centred and are checked among the objects of one room (a volume
reaching through a wall finds nothing behind it), so a house's statistics are the mix of its
rooms', and ``se_room`` treats the rooms as the independent units.

Persistence (``persistence``, ``ctxsearch truth``'s ``persistence``): per small type, the share
of its instances on day d of the sampled worlds that are still at the same type and exact pose
on day d + 1 (``envs.persistence.stayed``), beside the configured stay probability. In
expectation the measured share is at most the configured one, and lower where a type's count
changes from day to day: a day keeps only as many stayers of a type as its rules place
(``envs.rooms``' days).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import HouseStyle, resolve_style
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.persistence import stayed
from ctxsearch.envs.styles import Style
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.files import InputFileError, read_json
from ctxsearch.knowledge.geometry import ObjectInstance, related
from ctxsearch.knowledge.persistence import near_place
from ctxsearch.knowledge.room_context import RoomContext, next_relation_name, relation_name


def room_counts(
    layout: RoomLayout, catalog: Catalog
) -> tuple[dict[str, int], dict[tuple[str, str, str], int]]:
    """One room's counts: instances per type, and per (A, rel, B) how many A instances had a B."""
    return object_counts(layout.objects, catalog)


def object_counts(
    objects: tuple[ObjectInstance, ...] | list[ObjectInstance], catalog: Catalog
) -> tuple[dict[str, int], dict[tuple[str, str, str], int]]:
    """``room_counts`` of the objects of one room."""
    n: dict[str, int] = {}
    y: dict[tuple[str, str, str], int] = {}
    for a in objects:
        n[a.type] = n.get(a.type, 0) + 1
        for rel, b_type in {(rel, o.type) for rel, o in related(catalog, a, objects)}:
            key = (a.type, rel, b_type)
            y[key] = y.get(key, 0) + 1
    return n, y


def world_counts(
    layout: RoomLayout, catalog: Catalog
) -> list[tuple[dict[str, int], dict[tuple[str, str, str], int]]]:
    """The counts of every room of a layout: one entry for a single room, one per furnished room
    of a house (relations checked among the objects of that room)."""
    if not layout.is_house:
        return [room_counts(layout, catalog)]
    by_room: dict[int, list[ObjectInstance]] = {}
    for o in layout.objects:
        by_room.setdefault(layout.room_of[o.id], []).append(o)
    return [object_counts(by_room[r.index], catalog) for r in layout.rooms if r.index in by_room]


def estimate(
    rooms: Iterable[tuple[dict[str, int], dict[tuple[str, str, str], int]]], catalog: Catalog
) -> list[dict]:
    """Entries {ref, relation, type, p, se, n, y, se_room} from per-room counts, for every
    (A, rel, B) of the catalog with n > 0 (p = 0 ones included)."""
    rooms = list(rooms)
    n_tot: dict[str, int] = {}
    for n_r, _ in rooms:
        for t, k in n_r.items():
            n_tot[t] = n_tot.get(t, 0) + k
    entries = []
    for a_type in catalog.type_names:
        n = n_tot.get(a_type, 0)
        if n == 0:
            continue
        n_r = np.array([r[0].get(a_type, 0) for r in rooms], float)
        present = n_r > 0
        for rel in catalog.type(a_type).relation_names:
            for b_type in catalog.type_names:
                key = (a_type, rel, b_type)
                y_r = np.array([r[1].get(key, 0) for r in rooms], float)
                y = int(y_r.sum())
                p = y / n
                se = math.sqrt(p * (1 - p) / n)
                k = int(present.sum())
                if k > 1:
                    resid = (y_r - p * n_r)[present]
                    se_room = math.sqrt(k / (k - 1) * float(np.sum(resid**2))) / n
                else:
                    se_room = float("nan")
                entries.append(
                    {
                        "ref": a_type,
                        "relation": rel,
                        "type": b_type,
                        "p": p,
                        "se": se,
                        "n": n,
                        "y": y,
                        "se_room": se_room,
                    }
                )
    return entries


def ground_truth(
    style: Style | HouseStyle | str | Path,
    samples: int,
    seed: int = 0,
    catalog: Catalog | None = None,
    progress: bool = False,
    day: int = 0,
) -> dict:
    """P(rel(B)) for every (A, rel, B) over ``samples`` rooms of ``style`` (seeds seed .. seed+N-1);
    for a house style over the rooms of ``samples`` houses (then ``"rooms"`` says how many). On
    ``day`` >= 1 the worlds are those of that day (made day by day from day 0: some small
    objects stayed where they were, the style's rules as its drift schedule has them that day
    placed the rest); the document then says ``"day"``.

    Returns ``{"style", "samples", "seed", "catalog", "entries": [{"ref", "relation", "type",
    "p", "se", "n", "y", "se_room"}]}`` (``catalog`` is the catalog's fingerprint).
    """
    catalog = catalog or load_catalog()
    if not isinstance(style, Style | HouseStyle):
        style = resolve_style(style, catalog)
    seeds = range(int(seed), int(seed) + int(samples))
    if progress:
        unit = "house" if isinstance(style, HouseStyle) else "room"
        seeds = tqdm(seeds, desc=f"truth {style.name}", unit=unit)
    doc = truth_document(style, samples, seed, catalog, sample_counts(style, seeds, catalog, day))
    if day:
        doc["day"] = int(day)
    return doc


def sample_counts(
    style: Style | HouseStyle, seeds: Iterable[int], catalog: Catalog, day: int = 0
) -> list[tuple[dict[str, int], dict[tuple[str, str, str], int]]]:
    """The per-room counts (``world_counts``) of the worlds of ``seeds`` (on ``day``), in seed
    order: the independent part of ``ground_truth`` (a sweep can split the seeds)."""
    return [
        c for s in seeds for c in world_counts(generate_layout(style, s, catalog, day), catalog)
    ]


def truth_document(
    style: Style | HouseStyle,
    samples: int,
    seed: int,
    catalog: Catalog,
    rooms: list[tuple[dict[str, int], dict[tuple[str, str, str], int]]],
) -> dict:
    """``ground_truth``'s document from the per-room counts of its samples."""
    out = {
        "style": style.name,
        "samples": int(samples),
        "seed": int(seed),
        "catalog": catalog.fingerprint,
        "entries": estimate(rooms, catalog),
    }
    if isinstance(style, HouseStyle):
        out["rooms"] = len(rooms)
    return out


def room_contents(layout: RoomLayout) -> list[tuple[int, str, int]]:
    """(room, type, instances) of every type in every room of ``layout``'s plan (a single-room
    style's world is room 0): the true counterpart of what a learning visit records."""
    counts: dict[tuple[int, str], int] = {}
    for o in layout.objects:
        key = (layout.room_of.get(o.id, 0), o.type)
        counts[key] = counts.get(key, 0) + 1
    return sorted((r, t, k) for (r, t), k in counts.items())


def room_doors(layout: RoomLayout) -> list[tuple[int, int]]:
    """The pairs (a, b), a < b, of ``layout``'s plan rooms that share a door (the entrance to
    the outside is none); empty for a single room."""
    return sorted({(min(p.rooms), max(p.rooms)) for p in layout.doors if min(p.rooms) >= 0})


def sample_counts_and_rooms(
    style: Style | HouseStyle, seeds: Iterable[int], catalog: Catalog
) -> tuple[list, list[list[tuple[int, str, int]]], dict[tuple[str, str], list[int]]]:
    """``sample_counts`` of ``seeds``, each world's ``room_contents`` and the worlds' persistence
    counts from day 0 to day 1 (``persistence_counts``), every day-0 world generated once
    (``ctxsearch truth``'s sweep unit)."""
    counts, rooms, kept = [], [], {}
    for s in seeds:
        layout = generate_layout(style, s, catalog)
        counts.extend(world_counts(layout, catalog))
        rooms.append(room_contents(layout))
        later = generate_layout(style, s, catalog, 1)
        for key, row in persistence_counts(layout, later, catalog).items():
            acc = kept.setdefault(key, [0] * len(row))
            for i, v in enumerate(row):
                acc[i] += v
    return counts, rooms, kept


def persistence_counts(
    before: RoomLayout, after: RoomLayout, catalog: Catalog
) -> dict[tuple[str, str], tuple[int, int, int]]:
    """Per (room style, small type): (n, y, near), n the instances in ``before``, y those of
    them at the same type and exact pose in ``after`` and ``near`` those with an instance of
    their type within ``knowledge.persistence.RADIUS_M`` of them in ``after`` (the robot's
    relation STILL-WHERE-SEEN: another instance put there counts) (a world on two days; a
    single room's style is the layout's)."""
    kept = stayed(after, before)  # the ids in before of the objects still there after
    out: dict[tuple[str, str], tuple[int, int, int]] = {}
    for o in before.objects:
        if catalog.type(o.type).is_furniture:
            continue
        room = before.rooms[before.room_of[o.id]].style if before.is_house else before.style
        n, y, m = out.get((room, o.type), (0, 0, 0))
        near = near_place(o.position, after.objects, o.type)
        out[(room, o.type)] = (n + 1, y + int(o.id in kept), m + int(near))
    return out


def near_counts(
    style: Style | HouseStyle, catalog: Catalog, worlds: int, last_day: int = 1
) -> dict[str, tuple[int, int]]:
    """Per small type, (n, near) summed over ``worlds`` sample worlds of ``style`` (seeds 0 ..
    worlds-1) and each day d < ``last_day`` to d + 1 (``persistence_counts``): the instances and
    those with an instance of their type within the persistence radius the next day."""
    out: dict[str, list[int]] = {}
    for seed in range(worlds):
        days = [generate_layout(style, seed, catalog, day=d) for d in range(max(last_day, 1) + 1)]
        for before, after in zip(days, days[1:], strict=False):
            for (_room, t), (n, _y, near) in persistence_counts(before, after, catalog).items():
                acc = out.setdefault(t, [0, 0])
                acc[0] += n
                acc[1] += near
    return {t: (n, near) for t, (n, near) in out.items()}


def persistence(
    style: Style | HouseStyle,
    counts: dict[tuple[str, str], list[int] | tuple[int, int]],
    catalog: Catalog,
    day: int = 0,
) -> dict:
    """``ctxsearch truth``'s ``persistence`` from summed ``persistence_counts`` of its worlds on
    ``day`` and ``day`` + 1: per small type of the style, the configured stay probability
    (``stay``; a house style's: the mean of its room styles' weighted by the day's instances in
    their rooms, each in ``stay_by_style``), the day's instances ``n``, those still at the same
    type and pose the next day ``y``, their share ``p`` (None without instances) and its binomial
    ``se`` (instances of one world are not independent: optimistic), and ``near``, ``p_near``:
    those with an instance of the type within the persistence radius the next day (the true
    value of the robot's P(STILL-WHERE-SEEN(T) after 1 day), knowledge.persistence)."""
    rooms = [s for s, _ in style.rooms] if isinstance(style, HouseStyle) else [style]
    by_name = {s.name: s for s in rooms}
    types = [t for t in style.types if not catalog.type(t).is_furniture]
    out = []
    for t in types:
        per = {r: tuple(counts.get((r, t), (0, 0, 0))) + (0,) for r in by_name}
        n = sum(v[0] for v in per.values())
        y = sum(v[1] for v in per.values())
        near = sum(v[2] for v in per.values())
        cfg = {r: by_name[r].stay(t, catalog) for r in by_name if t in by_name[r].types}
        if n and isinstance(style, HouseStyle):
            stay = sum(per[r][0] * cfg.get(r, 0.0) for r in per) / n
        else:
            stay = sum(cfg.values()) / len(cfg)
        e = {"type": t, "stay": stay, "n": n, "y": y, "p": y / n if n else None,
             "se": math.sqrt(y / n * (1 - y / n) / n) if n else None,
             "near": near, "p_near": near / n if n else None}  # fmt: skip
        if isinstance(style, HouseStyle):
            e["stay_by_style"] = cfg
        out.append(e)
    return {"from_day": int(day), "to_day": int(day) + 1, "types": out}


@dataclass(frozen=True)
class RoomTruth:
    """Room context from the true plans: ``same_room[(F, T)]`` = P(SAME-ROOM-AS-F(T)),
    the share of the rooms holding furniture type F that hold at least one T (T = F: a second
    F), and ``room_share[T]`` = the share of the plans' rooms with furniture holding at least one
    T. Counted by ``knowledge.room_context.RoomContext``, as the robot's own rooms are (the room
    is the unit), over the rooms of ``houses`` houses (a single-room style's room is its world);
    ``counts``: those counts (n: the rooms holding each F, y: those also holding T)."""

    same_room: dict[tuple[str, str], float]
    room_share: dict[str, float]
    houses: int
    counts: RoomContext
    # P(NEXT-ROOM-OF-F(T)): of the pairs (a room holding F, a room sharing a door with it), the
    # share whose second room holds a T (knowledge.room_context; empty without the doors)
    next_room: dict[tuple[str, str], float] = field(default_factory=dict)

    @classmethod
    def of_contents(
        cls,
        worlds: Sequence[Sequence[tuple[int, str, int]]],
        catalog: Catalog,
        doors: Sequence[Iterable[tuple[int, int]]] | None = None,
    ) -> RoomTruth:
        """From each world's ``room_contents`` and, for the next-room relations, each world's
        ``room_doors``."""
        rows = [(i, r, t, k) for i, rooms in enumerate(worlds) for r, t, k in rooms]
        pairs = None if doors is None else {(i,): d for i, d in enumerate(doors)}
        rc = RoomContext.from_rows(rows, catalog, alpha=0.05, doors=pairs)  # no interval read
        same = {(f, t): y / rc.n[f] for (f, t), y in rc.y.items()}
        for f in rc.n:  # a pair never seen together is a measured 0, not unknown
            for t in catalog.type_names:
                same.setdefault((f, t), 0.0)
        share = {t: rc.holding.get(t, 0) / max(rc.rooms, 1) for t in catalog.type_names}
        nxt = {(f, t): rc.next_y.get((f, t), 0) / m for f, m in rc.next_n.items()
               for t in catalog.type_names}  # fmt: skip
        return cls(same, share, len(worlds), rc, nxt)

    def entries(self) -> list[dict]:
        """``same_room`` as ``ctxsearch truth`` writes it: one {ref, relation, type, p, se, n, y}
        per pair, n the rooms holding ref (relation ``SAME-ROOM-AS-<REF>``; se: binomial over
        the rooms)."""
        c = self.counts
        return _entries(self.same_room, c.n, c.y, relation_name)

    def next_entries(self) -> list[dict]:
        """``next_room`` as ``entries`` gives ``same_room``: n the pairs of a room holding ref
        and a room its doors lead to (relation ``NEXT-ROOM-OF-<REF>``)."""
        c = self.counts
        return _entries(self.next_room, c.next_n, c.next_y, next_relation_name)


def _entries(probs: dict, n: dict, y: dict, name) -> list[dict]:
    """One {ref, relation, type, p, se, n, y} per (ref, type) of ``probs``, its trials ``n[ref]``
    and successes ``y[(ref, type)]``, the relation named by ``name(ref)``."""
    return [
        {"ref": f, "relation": name(f), "type": t, "p": p,
         "se": math.sqrt(p * (1.0 - p) / n[f]), "n": n[f], "y": y.get((f, t), 0)}
        for (f, t), p in sorted(probs.items())
    ]  # fmt: skip


def room_truth(
    style: Style | HouseStyle | str, samples: int, catalog: Catalog, seed: int = 0
) -> RoomTruth:
    """``RoomTruth`` over the worlds of ``style`` of seeds seed .. seed + samples - 1 (the same
    worlds ``ground_truth`` counts)."""
    if not isinstance(style, Style | HouseStyle):
        style = resolve_style(style, catalog)
    layouts = [
        generate_layout(style, s, catalog) for s in range(int(seed), int(seed) + int(samples))
    ]
    return RoomTruth.of_contents(
        [room_contents(w) for w in layouts], catalog, [room_doors(w) for w in layouts]
    )


@dataclass(frozen=True)
class RoomKindTruth:
    """The true density of each type by room kind over sample houses: ``instances[(K, T)]`` the
    instances of T in the rooms of kind (room style) K, ``area[K]`` those rooms' floor area
    (m^2). The density ratio (``ratio``) is what a belief over points needs of a room's kind:
    how much likelier a point of a room of kind K holds T than a point of the house at large.
    Instances per area, not the share of rooms holding one: a belief's prior is a density, and
    a large room of a kind holds more than a small one."""

    instances: dict[tuple[str, str], int]
    area: dict[str, float]
    houses: int

    @classmethod
    def of_layouts(cls, layouts: Iterable[RoomLayout]) -> RoomKindTruth:
        """Counted over ``layouts``' plans (a single-room world is one room of its style)."""
        inst: dict[tuple[str, str], int] = {}
        area: dict[str, float] = {}
        n = 0
        for layout in layouts:
            n += 1
            if not layout.is_house:
                area[layout.style] = area.get(layout.style, 0.0) + layout.width * layout.depth
                kinds = {0: layout.style}
            else:
                for r in layout.rooms:
                    area[r.style] = area.get(r.style, 0.0) + r.area
                kinds = {r.index: r.style for r in layout.rooms}
            for o in layout.objects:
                key = (kinds.get(layout.room_of.get(o.id, 0), layout.style), o.type)
                inst[key] = inst.get(key, 0) + 1
        return cls(inst, area, n)

    def ratio(self, kind: str, type_name: str) -> float | None:
        """The density of ``type_name`` in rooms of ``kind`` over its density in every room
        (0: never there); None where no sample held the type or no room of the kind."""
        total = sum(v for (_k, t), v in self.instances.items() if t == type_name)
        area = sum(self.area.values())
        if not total or self.area.get(kind, 0.0) <= 0.0 or area <= 0.0:
            return None
        here = self.instances.get((kind, type_name), 0) / self.area[kind]
        return here / (total / area)


def room_kind_truth(
    style: Style | HouseStyle, samples: int, catalog: Catalog, seed: int = 0
) -> RoomKindTruth:
    """``RoomKindTruth`` over the worlds of ``style`` of seeds seed .. seed + samples - 1 (the
    same worlds ``ground_truth`` counts)."""
    seeds = range(int(seed), int(seed) + int(samples))
    return RoomKindTruth.of_layouts(generate_layout(style, s, catalog) for s in seeds)


def lookup(truth: dict, ref: str, relation: str, type_name: str) -> dict | None:
    """The entry for (ref, relation, type) in a ground-truth result, or None if n was 0."""
    for e in truth["entries"]:
        if e["ref"] == ref and e["relation"] == relation and e["type"] == type_name:
            return e
    return None


MAX_SAMPLES = 10**9


class TruthError(CtxsearchError, ValueError):
    """A ground-truth file that cannot be used (not JSON, wrong shape, another style or catalog)."""


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number")


def parse_truth(doc: object, path: str | Path, catalog: Catalog, style: str | None = None) -> dict:
    """Validate a ground-truth document (as ``ground_truth`` returns and ``ctxsearch truth``
    writes) against ``catalog`` (and ``style``, if given); TruthError naming the file otherwise.

    It must be an object with ``style`` (a name), ``samples`` (rooms, >= 1), ``catalog`` (the
    catalog's fingerprint) and a non-empty ``entries`` list of {ref, relation, type, p, n, ...}
    with names of the catalog (relation a relation of ref), 0 <= p <= 1 and n >= 1 instances.
    """

    def bad(msg: str) -> TruthError:
        return TruthError(f"{path}: not a usable ground-truth file: {msg}")

    if not isinstance(doc, dict):
        raise bad(f"expected a JSON object, got {type(doc).__name__}")
    name = doc.get("style")
    if not isinstance(name, str) or not name:
        raise bad("no 'style' name")
    if style is not None and name != style:
        raise TruthError(f"{path}: ground truth of style {name!r}, not {style!r}")
    samples = doc.get("samples")
    if isinstance(samples, bool) or not isinstance(samples, int) or not 1 <= samples <= MAX_SAMPLES:
        raise bad(f"'samples' must be an integer in [1, {MAX_SAMPLES}], got {samples!r}")
    if doc.get("catalog") != catalog.fingerprint:
        raise TruthError(
            f"{path}: ground truth of catalog fingerprint {doc.get('catalog')!r}, but the catalog "
            f"in use ({catalog.path}) has {catalog.fingerprint}; recompute it with ctxsearch truth"
        )
    entries = doc.get("entries")
    if not isinstance(entries, list) or not entries:
        raise bad("no 'entries'")
    for i, e in enumerate(entries):
        where = f"entry {i}"
        if not isinstance(e, dict):
            raise bad(f"{where} is not an object")
        ref, rel, t = e.get("ref"), e.get("relation"), e.get("type")
        if not (isinstance(ref, str) and ref in catalog and isinstance(t, str) and t in catalog):
            raise bad(f"{where}: types {ref!r}, {t!r} are not both in the catalog")
        if not (isinstance(rel, str) and rel in catalog.type(ref).relation_names):
            raise bad(f"{where}: {rel!r} is not a relation of {ref}")
        p, n = e.get("p"), e.get("n")
        if isinstance(p, bool) or not isinstance(p, int | float) or not 0.0 <= p <= 1.0:
            raise bad(f"{where}: p must be a number in [0, 1], got {p!r}")
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_SAMPLES * 1000:
            raise bad(f"{where}: n must be a positive integer, got {n!r}")
    return doc


def load_truth(path: str | Path, catalog: Catalog, style: str | None = None) -> dict:
    """Read and validate a ground-truth JSON file (``parse_truth``); TruthError (one line,
    naming the file) for a missing, unreadable, non-UTF-8, non-JSON or wrong-shaped file."""
    p = Path(path)
    try:
        # a regular file, at most files.MAX_FILE_BYTES, nested at most files.MAX_NESTING deep
        doc = read_json(p, parse_constant=_reject_constant)
    except InputFileError as exc:
        if exc.missing:
            raise TruthError(
                f"{p}: no such ground-truth file (make one with: ctxsearch truth)"
            ) from None
        raise TruthError(f"{p}: not a ground-truth JSON file ({exc.problem})") from None
    return parse_truth(doc, p, catalog, style)
