"""``ctxsearch truth``: ground-truth P(rel(B)) of a room style, estimated over generated rooms."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from scripts import argtypes


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``truth`` sub-command."""
    p = sub.add_parser(
        "truth",
        help="ground-truth P(rel(B)) of a room style over generated rooms (JSON)",
        description="Generate --samples rooms of a style (seeds SEED .. SEED+N-1) and estimate, with "
        "the robot's own relation geometry, P(rel(B)) for every reference type A, relation rel of A "
        "and type B: the fraction of A instances with at least one B in rel, its binomial standard "
        "error se and a room-clustered se_room. Writes {style, samples, entries: [{ref, relation, "
        "type, p, se, n}]} to --out.",
    )
    p.add_argument(
        "--style", required=True, help="room style name (see assets/styles/) or TOML path"
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
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Estimate the ground truth, write the JSON, print a short table."""
    from envs.styles import load_style
    from envs.truth import ground_truth
    from knowledge.catalog import load_catalog

    catalog = load_catalog(args.catalog)
    style = load_style(args.style, catalog)
    t0 = time.perf_counter()
    truth = ground_truth(
        style,
        args.samples,
        args.seed,
        catalog,
        progress=not args.no_progress and sys.stderr.isatty(),
    )
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
    print(
        f"{style.name}: {args.samples} rooms in {dt:.1f} s ({args.samples / dt:.0f} rooms/s), "
        f"{len(truth['entries'])} entries -> {args.out}"
    )
    print(f"{'relation':<24} {'type':<12} {'p':>6} {'se':>6} {'n':>6}")
    for e in entries[: max(0, args.top)]:
        print(f"{e['relation']:<24} {e['type']:<12} {e['p']:6.3f} {e['se']:6.3f} {e['n']:6d}")
    return 0
