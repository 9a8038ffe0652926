"""``ctxsearch room``: generate and build one room, then show it: a top-down overview, a few
head-camera views with detections, and (optionally) a rerun recording."""

from __future__ import annotations

import argparse
from pathlib import Path

from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.scripts import argtypes
from ctxsearch.scripts.sweep import SweepOptions, add_sweep_arguments


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
        "with type, id, pose, size and room) and, with --record, a rerun recording. For a house, "
        "the robot also explores it from the door with its own depth map and cuts the map into "
        "rooms: DIR/rooms.png (the plan beside the robot's rooms) and DIR/rooms.json (the "
        "intersection over union of each plan room with its segment).",
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
    p.add_argument(
        "--no-segment",
        action="store_true",
        help="a house: skip the exploration and the robot's rooms (rooms.png, rooms.json)",
    )
    p.add_argument(
        "--remembered",
        action="store_true",
        help="also tour it on day 0 as a remembered map's search does and draw what the robot "
        "keeps beside the plan (remembered.png: misses, look-alikes and phantoms marked; "
        "remembered.json: the counts)",
    )
    argtypes.add_detector_argument(p)
    p.set_defaults(func=run)


def register_bench(bench_sub: argparse._SubParsersAction) -> None:
    """Add ``bench rooms``."""
    p = bench_sub.add_parser(
        "rooms",
        help="the robot's room segmentation of its own map against the house plans (IoU)",
        description="In each house the robot explores from the door until no frontier is left, "
        "builds its own map from depth and cuts it into rooms at the doors (distance-transform "
        "segmentation); each plan room's intersection over union with its segment is measured. "
        "Writes DIR/rooms.json, DIR/rooms.md and DIR/rooms.csv (one row per house room).",
    )
    p.add_argument(
        "--styles",
        default="apartment,family_house,office_floor",
        help="comma-separated house styles (default: apartment,family_house,office_floor)",
    )
    p.add_argument(
        "--houses", type=argtypes.positive_int, default=10, help="houses per style (default: 10)"
    )
    p.add_argument("--out", type=argtypes.out_dir, required=True, help="output directory")
    add_sweep_arguments(p)
    p.set_defaults(func=run_rooms)


def run_rooms(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench rooms``."""
    # Imported here: the benchmark pulls in MuJoCo, which `--help` must not wait for.
    from ctxsearch.envs.houses import load_house
    from ctxsearch.knowledge.catalog import load_catalog
    from ctxsearch.scripts.experiments.bench_rooms import bench_rooms, markdown

    styles = tuple(x.strip() for x in args.styles.split(",") if x.strip())
    if not styles:
        raise CtxsearchError("--styles: give at least one house style")
    catalog = load_catalog()
    for s in styles:
        load_house(s, catalog)  # a one-line error for a room style or an unknown name
    doc = bench_rooms(styles, args.houses, args.out, SweepOptions.from_args(args))
    print(markdown(doc))
    print(f"wrote {', '.join(str(args.out / f'rooms.{x}') for x in ('json', 'md', 'csv'))}")
    return 0


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
        segment=not args.no_segment,
        remembered=args.remembered,
    )
    for p in show_room(config):
        print(f"wrote {p}")
    return 0
