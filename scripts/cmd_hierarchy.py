"""``ctxsearch bench hierarchy``: the type hierarchy's backoff against the flat intervals."""

from __future__ import annotations

import argparse

from ctxsearch.scripts import argtypes

DEFAULT_KS = "0,1,3,5,10"


def _ks(text: str) -> tuple[int, ...]:
    """A comma-separated list of distinct examination counts >= 0, ascending."""
    try:
        ks = tuple(sorted({int(x) for x in text.split(",") if x.strip()}))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected integers like 0,1,3, got {text!r}") from None
    if not ks or ks[0] < 0 or ks[-1] > 1000:
        raise argparse.ArgumentTypeError(f"expected integers in [0, 1000], got {text!r}")
    return ks


def register_bench(bench_sub: argparse._SubParsersAction) -> None:
    """Add ``bench hierarchy``."""
    p = bench_sub.add_parser(
        "hierarchy",
        help="type hierarchy: flat vs backoff estimates for rarely examined types, and search "
        "around a never-seen furniture type",
        description="Learn --rooms rooms of --style (hif, oracle perception); hold each concrete "
        "type of a class to k examinations (the others learned fully) and compare the flat and the "
        "backoff estimates with the ground truth (mean |p0 - p_true|, coverage_informative); then "
        "search (location) held-out rooms whose main work surface is a never-seen Workbench, flat "
        "vs backoff, on paired episodes. Writes DIR/hierarchy.json, DIR/hierarchy.md and "
        "DIR/hierarchy.png.",
    )
    p.add_argument(
        "--style",
        default="office",
        help="room style (assets/styles/): name or TOML path; not a house style (default: office)",
    )
    p.add_argument("--out", type=argtypes.out_dir, required=True, help="output directory")
    p.add_argument(
        "--rooms", type=argtypes.positive_int, default=20, help="learning rooms (default: 20)"
    )
    p.add_argument(
        "--episodes",
        type=argtypes.non_negative_int,
        default=40,
        help="paired search episodes (default: 40; 0: the estimates only, no search)",
    )
    p.add_argument(
        "--truth-samples",
        type=argtypes.positive_int,
        default=200,
        help="rooms sampled for the ground truth (default: 200)",
    )
    p.add_argument(
        "--ks", type=_ks, default=_ks(DEFAULT_KS), help=f"held examinations (default: {DEFAULT_KS})"
    )
    p.add_argument(
        "--draws",
        type=argtypes.positive_int,
        default=5,
        help="random subsets of a held type's examinations per k (default: 5)",
    )
    p.add_argument("--seed", type=argtypes.seed, default=0, help="seed (default: 0)")
    p.add_argument("--quiet", action="store_true", help="no line per episode")
    p.set_defaults(func=run_bench)


def run_bench(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench hierarchy``."""
    # Imported here: the benchmark pulls in MuJoCo and the search stack, which `--help` must not
    # wait for.
    from ctxsearch.scripts.experiments.bench_hierarchy import HierarchyBenchConfig, bench_hierarchy

    config = HierarchyBenchConfig(
        style=args.style,
        rooms=args.rooms,
        truth_samples=args.truth_samples,
        episodes=args.episodes,
        ks=args.ks,
        draws=args.draws,
        seed=args.seed,
    )
    res = bench_hierarchy(config, args.out, progress=None if args.quiet else print)
    print(res.markdown)
    for f in res.files:
        print(f"wrote {f}")
    print(f"({res.doc['wall_s']:.0f} s wall)")
    return 0
