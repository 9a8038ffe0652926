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
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from tqdm import tqdm

from envs.houses import HouseStyle, generate_layout, resolve_style
from envs.layout import RoomLayout
from envs.styles import Style
from knowledge.catalog import Catalog, load_catalog
from knowledge.geometry import ObjectInstance, related


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
) -> dict:
    """P(rel(B)) for every (A, rel, B) over ``samples`` rooms of ``style`` (seeds seed .. seed+N-1);
    for a house style over the rooms of ``samples`` houses (then ``"rooms"`` says how many).

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
    rooms = [c for s in seeds for c in world_counts(generate_layout(style, s, catalog), catalog)]
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


def lookup(truth: dict, ref: str, relation: str, type_name: str) -> dict | None:
    """The entry for (ref, relation, type) in a ground-truth result, or None if n was 0."""
    for e in truth["entries"]:
        if e["ref"] == ref and e["relation"] == relation and e["type"] == type_name:
            return e
    return None
