"""``ctxsearch truth``: ground-truth P(rel(B)) of a room style, estimated over generated rooms,
and how many of each small type's instances stay from day 0 to day 1."""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
import time
from pathlib import Path

from ctxsearch.envs.houses import HouseStyle, resolve_style
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.scripts import argtypes
from ctxsearch.scripts.sweep import SweepOptions, add_sweep_arguments, run_units

SEEDS_PER_UNIT = 10  # worlds per sweep unit (one unit: ~0.3 s for single rooms)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``truth`` sub-command."""
    p = sub.add_parser(
        "truth",
        help="ground-truth P(rel(B)) of a room style over generated rooms (JSON)",
        description="Generate --samples rooms of a style (seeds SEED .. SEED+N-1) and estimate, with "
        "the robot's own relation geometry, P(rel(B)) for every reference type A, relation rel of A "
        "and type B: the fraction of A instances with at least one B in rel, its binomial standard "
        "error se and a room-clustered se_room. Writes {style, samples, entries: [{ref, relation, "
        "type, p, se, n}]} to --out; for a house style also the room context: same_room "
        "(P(SAME-ROOM-AS-F(T)) for each furniture type F, the share of the rooms holding an F "
        "that hold a T), room_share (the share of furnished rooms holding each type) and "
        "furnished_rooms. persistence: per small type, its configured stay probability (the "
        "chance an instance is still exactly where it was the next day: assets/types.toml, a "
        "style's [stay]) and the measured share of its day-0 instances still at the same pose on "
        "day 1 (y of n), which is lower where the type's count changes from day to day.",
    )
    p.add_argument(
        "--style",
        required=True,
        help="room style (assets/styles/) or house style (assets/houses/): name or TOML path; "
        "a house style samples houses and counts over their rooms",
    )
    p.add_argument(
        "--samples", required=True, type=argtypes.positive_int, help="how many rooms to generate"
    )
    p.add_argument("--out", required=True, type=argtypes.out_file, help="output JSON file")
    p.add_argument("--seed", type=argtypes.seed, default=0, help="first room seed (default: 0)")
    p.add_argument(
        "--catalog",
        type=Path,
        default=None,
        help="object-type catalog (default: assets/types.toml)",
    )
    p.add_argument(
        "--top", type=int, default=12, help="print the K most likely relations (default: 12)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_sweep_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Estimate the ground truth, write the JSON, print a short table."""
    # Imported here: the ground truth pulls in scipy, which `ctxsearch --help` must not wait for.
    from ctxsearch.envs.truth import (
        RoomTruth,
        persistence,
        sample_counts_and_rooms,
        truth_document,
    )

    catalog = load_catalog(args.catalog)
    style = resolve_style(args.style, catalog)
    t0 = time.perf_counter()
    seeds = list(range(args.seed, args.seed + args.samples))
    chunks = [seeds[i : i + SEEDS_PER_UNIT] for i in range(0, len(seeds), SEEDS_PER_UNIT)]
    sweep = SweepOptions.from_args(args)
    parts = run_units(
        functools.partial(sample_counts_and_rooms, style, catalog=catalog),
        chunks,
        workers=sweep.workers,
        ray_address=sweep.ray_address,
        desc=f"truth {style.name} ({SEEDS_PER_UNIT} worlds per unit)",
        progress=not args.no_progress and sys.stderr.isatty(),
    )
    rooms = [c for counts, _, _ in parts for c in counts]
    truth = truth_document(style, args.samples, args.seed, catalog, rooms)
    kept: dict[tuple[str, str], list[int]] = {}
    for _, _, k in parts:
        for key, row in k.items():
            acc = kept.setdefault(key, [0] * len(row))
            for i, v in enumerate(row):
                acc[i] += v
    truth["persistence"] = persistence(style, kept, catalog)
    if isinstance(style, HouseStyle):  # room context over the same houses
        rt = RoomTruth.of_contents([w for _, worlds, _ in parts for w in worlds], catalog)
        truth["furnished_rooms"] = rt.counts.rooms
        truth["room_share"] = {t: s for t, s in sorted(rt.room_share.items()) if s > 0}
        truth["same_room"] = rt.entries()
    dt = time.perf_counter() - t0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    # NaN (se_room of a type seen in one room only) is written as null: strict JSON.
    for e in truth["entries"]:
        if isinstance(e.get("se_room"), float) and math.isnan(e["se_room"]):
            e["se_room"] = None
    args.out.write_text(json.dumps(truth, indent=1) + "\n")
    entries = sorted(
        (e for e in truth["entries"] if e["ref"] != e["type"] or e["p"] > 0),
        key=lambda e: (-e["p"], e["relation"], e["type"]),
    )
    unit = "houses" if "rooms" in truth else "rooms"
    rooms = f" ({truth['rooms']} rooms)" if "rooms" in truth else ""
    print(
        f"{style.name}: {args.samples} {unit}{rooms} in {dt:.1f} s "
        f"({args.samples / dt:.0f} {unit}/s), "
        f"{len(truth['entries'])} entries -> {args.out}"
    )
    print(f"{'relation':<24} {'type':<12} {'p':>6} {'se':>6} {'n':>6}")
    for e in entries[: max(0, args.top)]:
        print(f"{e['relation']:<24} {e['type']:<12} {e['p']:6.3f} {e['se']:6.3f} {e['n']:6d}")
    if "same_room" in truth:
        print(f"room context over {truth['furnished_rooms']} furnished rooms (p / share of rooms):")
        share = truth["room_share"]
        same = sorted(
            (e for e in truth["same_room"] if e["p"] > 0 and share.get(e["type"], 0) > 0),
            key=lambda e: (-e["p"] / share[e["type"]], e["relation"], e["type"]),
        )
        for e in same[: max(0, args.top)]:
            print(
                f"{e['relation']:<24} {e['type']:<12} {e['p']:6.3f} {e['se']:6.3f} {e['n']:6d}"
                f"  / {share[e['type']]:.3f}"
            )
    _print_persistence(truth["persistence"])
    return 0


def _print_persistence(doc: dict) -> None:
    """The persistence table: per small type, configured stay and measured share (y of n)."""
    print(
        f"persistence, day {doc['from_day']} -> {doc['to_day']} (measured: same type and pose; "
        "near: an instance of the type within 0.5 m, STILL-WHERE-SEEN):"
    )
    print(f"{'type':<12} {'stay':>6} {'measured':>8} {'se':>6} {'y':>6} {'n':>6} {'near':>6}")
    for e in doc["types"]:
        p = "-" if e["p"] is None else f"{e['p']:.3f}"
        se = "-" if e["se"] is None else f"{e['se']:.3f}"
        near = "-" if e.get("p_near") is None else f"{e['p_near']:.3f}"
        print(f"{e['type']:<12} {e['stay']:6.3f} {p:>8} {se:>6} {e['y']:6d} {e['n']:6d} {near:>6}")
