"""``ctxsearch room``: generate and build one room, then show it: a top-down overview, a few
head-camera views with detections, and (optionally) a rerun recording."""

from __future__ import annotations

import argparse
from pathlib import Path

from ctxsearch.scripts import argtypes


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``room`` sub-command."""
    p = sub.add_parser(
        "room",
        help="generate and build a room or house; write overview.png, view_*.png, layout.json "
        "and a rerun recording",
        description="Generate a room or a house of a style (deterministic by seed), build it in "
        "MuJoCo, drive the robot to viewpoints looking at its furniture and write "
        "DIR/overview.png (top-down; a house's rooms labelled), DIR/view_*.png (head camera, "
        "detections drawn), DIR/layout.json (rooms with style and outline, doors, every object "
        "with type, id, pose, size and room) and, with --record, a rerun recording.",
    )
    p.add_argument(
        "--style",
        default="office",
        help="room style (assets/styles/) or house style (assets/houses/): name or TOML path "
        "(default: office)",
    )
    p.add_argument("--seed", type=argtypes.seed, default=0, help="room seed (default: 0)")
    p.add_argument("--out", required=True, type=argtypes.out_dir, help="output directory")
    p.add_argument("--record", type=Path, default=None, help="write a rerun recording (.rrd) here")
    p.add_argument("--views", type=int, default=4, help="head-camera views to take (default: 4)")
    p.add_argument("--width", type=int, default=320, help="head-camera image width (default: 320)")
    p.add_argument(
        "--height", type=int, default=240, help="head-camera image height (default: 240)"
    )
    p.add_argument(
        "--catalog",
        type=Path,
        default=None,
        help="object-type catalog (default: assets/types.toml)",
    )
    argtypes.add_detector_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch room``."""
    # Imported here: the room views pull in MuJoCo and OpenCV, which `--help` must not wait for.
    from ctxsearch.scripts.room_views import RoomViewConfig, show_room

    config = RoomViewConfig(
        style=args.style,
        seed=args.seed,
        out=args.out,
        record=args.record,
        views=args.views,
        width=args.width,
        height=args.height,
        catalog=args.catalog,
        detector=args.detector,
    )
    for p in show_room(config):
        print(f"wrote {p}")
    return 0
