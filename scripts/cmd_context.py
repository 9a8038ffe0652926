"""``ctxsearch bench curve`` (does learning pay?) and ``ctxsearch bench transfer`` (context that
does not fit): the paired search ratio of the context policy to the no-context baseline."""

from __future__ import annotations

import argparse

from ctxsearch.agent.search.registry import Role, with_role
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import MapMode
from ctxsearch.scripts import argtypes
from ctxsearch.scripts.cmd_search import add_budget_argument
from ctxsearch.scripts.sweep import add_sweep_arguments

# Each scenario's baseline, context and asymptote policies, from the registry (light: no MuJoCo).
SCENARIO_POLICIES = {
    m: ",".join(with_role(m, r) for r in (Role.BASELINE, Role.CONTEXT, Role.ASYMPTOTE))
    for m in MapMode
}


def parse_room_marks(text: str) -> tuple[int, ...]:
    """``--rooms 0,1,3,10``: strictly increasing counts >= 0 (one-line errors)."""
    from ctxsearch.scripts.experiments.bench_curve import check_rooms

    parts = [x.strip() for x in text.split(",")]
    try:
        marks = tuple(argtypes.non_negative_int(x) for x in parts if x)
    except argparse.ArgumentTypeError as exc:
        raise CtxsearchError(f"--rooms: {exc}") from None
    if "" in parts[:-1]:
        raise CtxsearchError(f"--rooms: an empty count in {text!r}")
    return check_rooms(marks)


def _add_common(p: argparse.ArgumentParser, rooms_help: str) -> None:
    """The flags ``bench curve`` and ``bench transfer`` share."""
    p.add_argument("--rooms", required=True, help=rooms_help)
    p.add_argument(
        "--episodes",
        type=argtypes.positive_int,
        default=20,
        help="paired episodes per scenario and searched-in style (default: 20)",
    )
    p.add_argument("--out", type=argtypes.out_dir, required=True, help="output directory")
    p.add_argument(
        "--seed",
        type=argtypes.seed,
        default=0,
        help="the learning run's seed and the episodes' (default: 0)",
    )
    p.add_argument(
        "--scenarios",
        default="built,given",
        help="map scenarios: built (the robot builds its map), given (the true furniture plan), "
        "remembered (its own map from a tour on an earlier day) (default: built,given)",
    )
    for name, pols in SCENARIO_POLICIES.items():
        p.add_argument(
            f"--{name}-policies",
            default=None,
            metavar="BASE,CONTEXT,ASYMPTOTE",
            help=f"the {name} scenario's no-context baseline, context policy and asymptote "
            f"(default: {pols})",
        )
    p.add_argument(
        "--perception",
        choices=("camera", "oracle"),
        default="camera",
        help="how the robot perceives while learning (default: camera; oracle: faster, the true "
        "layout and the given map)",
    )
    add_budget_argument(p)
    p.add_argument(
        "--truth-samples",
        type=argtypes.positive_int,
        default=200,
        help="rooms sampled for the asymptote's ground truth (default: 200)",
    )
    argtypes.add_detector_argument(p)
    p.add_argument("--quiet", action="store_true", help="no progress lines or bars")
    add_sweep_arguments(p, journal=True)


def register_bench(bench_sub: argparse._SubParsersAction) -> None:
    """Add ``bench curve`` and ``bench transfer``."""
    p = bench_sub.add_parser(
        "curve",
        help="the learning curve: paired search ratio to the no-context baseline after k worlds",
        description="One learning run in --style (seed --seed) whose store is copied after k "
        "worlds for each k of --rooms (0: the empty store); for each copy and scenario, the "
        "context policy searches the same held-out episodes (outside every learned world) as "
        "the no-context baseline and the oracle-prior asymptote. Writes DIR/curve.json, "
        "curve.md, curve.png (the paired ratio against k with its 95% band) and curve.csv.",
    )
    p.add_argument(
        "--style",
        required=True,
        help="room or house style (assets/styles/, assets/houses/): name or TOML path",
    )
    _add_common(p, "strictly increasing world counts to snapshot at, e.g. 0,1,3,10,30")
    p.add_argument(
        "--truth",
        default=None,
        metavar="FILE.json",
        help="ground truth from `ctxsearch truth` for the asymptote (default: sampled)",
    )
    argtypes.add_interval_argument(p, search=True)
    p.set_defaults(func=run_curve)
    p = bench_sub.add_parser(
        "transfer",
        help="context learned in one style, used in another: a learned-in x searched-in table",
        description="Learn a store per style (--rooms worlds each) and a small probe (other "
        "worlds); search every style's held-out episodes with every store's context and the "
        "no-context baseline, with wilson and clustered intervals. Reports the paired ratio per "
        "(learned-in, searched-in) pair, what the mismatch costs, and whether the probe's "
        "evidence lies outside the learned intervals (can the robot notice?). Writes "
        "DIR/transfer.json, transfer.md and transfer.csv.",
    )
    p.add_argument(
        "--styles",
        default="office,biology_lab",
        help="comma-separated styles (default: office,biology_lab)",
    )
    _add_common(p, "worlds learned per style")
    p.add_argument(
        "--probe-rooms",
        type=argtypes.non_negative_int,
        default=2,
        metavar="N",
        help="worlds of each style learned as the probe (default: 2; 0: no mismatch measure)",
    )
    p.add_argument(
        "--intervals",
        default="wilson,clustered",
        help="interval methods the context reads (default: wilson,clustered)",
    )
    p.set_defaults(func=run_transfer)


def _scenarios(args: argparse.Namespace):
    from ctxsearch.scripts.experiments.scenarios import parse_scenarios

    overrides = {"built": args.built_policies, "given": args.given_policies}
    return parse_scenarios(args.scenarios, overrides)


def _search_base(args: argparse.Namespace, style: str | None, extra: dict | None = None):
    """The search configuration the curve's and the transfer's searches start from (``extra``:
    more dotted keys)."""
    from ctxsearch.agent.search.config import SearchConfig

    given = {
        "style": style, "seed": args.seed, "budget_s": args.budget_seconds,
        "knowledge.truth_samples": args.truth_samples, "detector": args.detector,
        "episodes": args.episodes, **(extra or {}),
    }  # fmt: skip
    return SearchConfig().updated({k: v for k, v in given.items() if v is not None})


def _report(res) -> int:
    print(res.table)
    for f in res.files:
        print(f"wrote {f}")
    print(f"({res.wall_s:.0f} s wall)")
    return 0


def run_curve(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench curve``."""
    # Imported here: the benchmark pulls in MuJoCo, which `ctxsearch --help` must not wait for.
    from pathlib import Path

    from ctxsearch.scripts.experiments.bench_curve import CurveConfig, bench_curve
    from ctxsearch.scripts.sweep import SweepOptions

    marks = parse_room_marks(args.rooms)
    truth = Path(args.truth) if args.truth else None
    base = _search_base(  # --interval None: the search configuration's default
        args, args.style, {"knowledge.truth": truth, "knowledge.interval": args.interval}
    )
    config = CurveConfig(base, marks, _scenarios(args), perception=args.perception)
    res = bench_curve(
        config,
        args.out,
        sweep=SweepOptions.from_args(args),
        bar=not args.quiet,
        progress=None if args.quiet else print,
    )
    return _report(res)


def run_transfer(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench transfer``."""
    # Imported here: the benchmark pulls in MuJoCo, which `ctxsearch --help` must not wait for.
    from ctxsearch.scripts.experiments.bench_transfer import TransferConfig, bench_transfer
    from ctxsearch.scripts.sweep import SweepOptions

    try:
        rooms = argtypes.positive_int(args.rooms)
    except argparse.ArgumentTypeError as exc:
        raise CtxsearchError(f"--rooms: {exc}") from None
    styles = tuple(x.strip() for x in args.styles.split(",") if x.strip())
    intervals = tuple(x.strip() for x in args.intervals.split(",") if x.strip())
    base = _search_base(args, styles[0] if styles else None)
    config = TransferConfig(base, styles, rooms, _scenarios(args), intervals,
                            args.probe_rooms, args.perception)  # fmt: skip
    res = bench_transfer(
        config,
        args.out,
        sweep=SweepOptions.from_args(args),
        bar=not args.quiet,
        progress=None if args.quiet else print,
    )
    return _report(res)
