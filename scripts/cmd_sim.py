"""``ctxsearch bench sim``: speed of the simulated world (layouts, compile, gazes, render overhead)."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from ctxsearch.scripts import argtypes


def register_bench(sub: argparse._SubParsersAction) -> None:
    """Add the ``bench sim`` benchmark."""
    p = sub.add_parser(
        "sim",
        help="simulator speed: layouts/s, build+compile ms, gazes/s, render overhead",
        description="Time the room generator, the MJCF build and compile per room, and gazes "
        "(move the head in MuJoCo, render segmentation and depth, detect) against the same "
        "renders with a bare mujoco.Renderer. With --out DIR, writes DIR/bench_sim.json, "
        "DIR/bench_sim.md, DIR/bench_sim.csv and DIR/bench_sim.png; without, prints the table only.",
    )
    p.add_argument(
        "--out",
        type=argtypes.out_dir,
        default=None,
        help="output directory (default: none, only the table is printed)",
    )
    p.add_argument(
        "--rooms", type=argtypes.positive_int, default=5, help="rooms to build (default: 5)"
    )
    p.add_argument(
        "--gazes", type=argtypes.positive_int, default=100, help="gazes per room (default: 100)"
    )
    p.add_argument(
        "--style",
        default="office",
        help="room style (assets/styles/) or house style (assets/houses/): name or TOML path "
        "(default: office)",
    )
    p.add_argument("--seed", type=argtypes.seed, default=0, help="first room seed (default: 0)")
    p.add_argument("--width", type=argtypes.pixels, default=320, help="image width (default: 320)")
    p.add_argument(
        "--height", type=argtypes.pixels, default=240, help="image height (default: 240)"
    )
    p.add_argument(
        "--explore",
        type=argtypes.non_negative_int,
        default=1,
        help="worlds explored fully with the robot's own map, for map_free_recall, "
        "map_false_free and explore_sim_s (default: 1; 0: none)",
    )
    p.add_argument(
        "--frontier-rule",
        choices=("nearest", "info"),
        default="info",
        help="which frontier the exploration goes to next (default: info)",
    )
    p.set_defaults(func=run_bench)


def run_bench(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench sim``."""
    # Imported here: the benchmark pulls in MuJoCo, which `ctxsearch --help` must not wait for.
    from ctxsearch.scripts.experiments.bench_sim import format_table, run

    if args.out is None:  # a benchmark without --out writes nothing: its files go to a temp dir
        with tempfile.TemporaryDirectory(prefix="ctxsearch-bench-sim-") as tmp:
            print(format_table(_run(run, args, Path(tmp))))
        print("no files written (--out DIR writes bench_sim.json, .md, .csv and .png)")
        return 0
    print(format_table(_run(run, args, args.out)))
    print(
        f"wrote {args.out / 'bench_sim.json'}, {args.out / 'bench_sim.md'} and {args.out / 'bench_sim.png'}"
    )
    return 0


def _run(run, args: argparse.Namespace, out: Path) -> dict:
    return run(
        out,
        rooms=args.rooms,
        gazes=args.gazes,
        style=args.style,
        seed=args.seed,
        size=(args.width, args.height),
        explore=min(args.explore, args.rooms),
        frontier_rule=args.frontier_rule,
    )
