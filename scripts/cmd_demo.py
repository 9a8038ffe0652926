"""``ctxsearch demo``: learn in a few rooms, then search with and without context (``make demo``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ctxsearch.scripts import argtypes


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``demo`` sub-command."""
    p = sub.add_parser(
        "demo",
        help="learn in a few office rooms, then search a held-out room with and without context",
        description="The end-to-end demo: the robot learns spatial context on its own (Highest "
        "Impact First) in --rooms office rooms, then looks for a Cup in a room it never learned in, "
        "once with the learned context (indirect) and once without (frontier), both on the map it "
        "builds as it searches. Writes OUT/kb.sqlite, OUT/learn.rrd, OUT/search.rrd (both "
        "searches side by side) and OUT/report.md. Re-running "
        "reuses a complete store (delete OUT/ to learn again) and redoes the searches.",
    )
    p.add_argument(
        "--out",
        type=argtypes.out_dir,
        default=Path("demo"),
        help="output directory (default: demo)",
    )
    p.add_argument(
        "--rooms", type=argtypes.positive_int, default=6, help="rooms to learn in (default: 6)"
    )
    p.add_argument(
        "--quick", action="store_true", help="at most 2 learning rooms and a shorter search budget"
    )
    p.add_argument(
        "--perception",
        choices=("camera", "oracle"),
        default="camera",
        help="learning perception (default: camera, rendered segmentation)",
    )
    p.add_argument("--target", default="Cup", help="what to search for (default: Cup)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch demo``."""
    # Imported here: the demo pulls in MuJoCo, which `ctxsearch --help` must not wait for.
    from ctxsearch.scripts.experiments.demo import DemoConfig, run_demo

    config = DemoConfig(
        out=args.out,
        rooms=args.rooms,
        quick=args.quick,
        perception=args.perception,
        target=args.target,
        progress=not args.no_progress,
    )
    res = run_demo(config)
    print(f"({res.wall_s:.0f} s wall)")
    return 0
