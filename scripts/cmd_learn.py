"""``ctxsearch learn`` (Figure 2 on the simulated robot) and ``ctxsearch bench learning``."""

from __future__ import annotations

import argparse
from pathlib import Path

from agent.strategies import STRATEGIES, make_strategy
from knowledge.errors import CtxsearchError
from scripts import argtypes
from scripts.sweep import SweepOptions, add_sweep_arguments

ROOM_BUDGET_HELP = (
    "simulated seconds the robot may spend in each room: when they are spent it leaves the room "
    "(the examination in flight completes), whatever is left unexamined (default: no limit, "
    "every room to completion as in the paper's Figure 2)"
)


def _strategy_names() -> list[str]:
    return list(STRATEGIES)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``learn`` sub-command."""
    p = sub.add_parser(
        "learn",
        help="learn spatial context autonomously over rooms (Figure 2: Highest Impact First)",
        description="Let the robot learn on its own over --rooms rooms of a style: explore, choose "
        "what to examine by a strategy (default: the paper's Highest Impact First), examine it, and "
        "record every examination in the evidence store --kb. An existing store is resumed: rooms "
        "done are skipped, a room in progress is replayed and continued. Ctrl-C loses at most the "
        "examination in flight.",
    )
    p.add_argument(
        "--style",
        required=True,
        help="room style (assets/styles/) or house style (assets/houses/): name or TOML path",
    )
    p.add_argument(
        "--rooms", required=True, type=argtypes.positive_int, help="how many rooms to learn in"
    )
    p.add_argument(
        "--kb", required=True, type=Path, help="evidence store (SQLite); created or resumed"
    )
    _add_learning_args(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_learn)


def _add_learning_args(p: argparse.ArgumentParser) -> None:
    """How ``learn`` learns: strategy, perception, alpha, seed, recording, limits."""
    p.add_argument(
        "--strategy",
        default="hif",
        choices=_strategy_names(),
        help="what to examine next (default: hif)",
    )
    p.add_argument(
        "--perception",
        default="camera",
        choices=("camera", "oracle"),
        help="camera: rendered segmentation (default); oracle: relations from the layout",
    )
    p.add_argument(
        "--alpha",
        type=argtypes.alpha,
        default=None,
        help="confidence level of the intervals (default: the store's, 0.10 for a new one)",
    )
    p.add_argument(
        "--seed",
        type=argtypes.seed,
        default=0,
        help="run seed: room seeds derive from it (default: 0)",
    )
    p.add_argument(
        "--record",
        type=Path,
        default=None,
        metavar="FILE.rrd",
        help="write a rerun recording of the whole run (one file, room after room, laid out by "
        "its blueprint)",
    )
    p.add_argument(
        "--max-examinations",
        type=argtypes.positive_int,
        default=None,
        metavar="K",
        help="stop after K examinations (resume later with the same command)",
    )
    p.add_argument(
        "--room-budget",
        type=argtypes.seconds,
        default=None,
        metavar="SECONDS",
        help=ROOM_BUDGET_HELP,
    )


def run_learn(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch learn``."""
    # Imported here: learning pulls in MuJoCo, which `ctxsearch --help` must not wait for.
    from agent.learning import LearnConfig, learn

    s = learn(
        LearnConfig(
            args.style,
            args.rooms,
            args.kb,
            strategy=args.strategy,
            perception=args.perception,
            alpha=args.alpha,
            seed=args.seed,
            record=args.record,
            max_examinations=args.max_examinations,
            progress=not args.no_progress,
            room_budget_s=args.room_budget,
        )
    )
    for line in s.lines():
        print(line)
    for f in s.files:
        print(f"recording: {f} (open with: rerun {f})")
    print(f"store: {args.kb} (see: ctxsearch kb show {args.kb})")
    return 130 if s.interrupted else 0


def register_bench(bench_sub: argparse._SubParsersAction) -> None:
    """Add ``bench learning``."""
    p = bench_sub.add_parser(
        "learning",
        help="every strategy on the same rooms and seeds, measured against the ground truth",
        description="Run every strategy on the same rooms and seeds and measure, after every "
        "examination, the intervals against the ground truth of `ctxsearch truth`: mean and max "
        "width, mean |p0 - p_true|, coverage, simulated seconds. Writes DIR/learning.json, "
        "DIR/learning.md, DIR/learning.png and DIR/learning.csv (one row per examination).",
    )
    p.add_argument(
        "--style",
        default="office",
        help="room style (assets/styles/) or house style (assets/houses/): name or TOML path (default: office)",
    )
    p.add_argument(
        "--rooms", type=argtypes.positive_int, default=20, help="rooms per run (default: 20)"
    )
    p.add_argument(
        "--seeds", type=argtypes.positive_int, default=5, help="seeds per strategy (default: 5)"
    )
    p.add_argument(
        "--strategies",
        default=",".join(_strategy_names()),
        help="comma-separated strategies (default: all)",
    )
    p.add_argument("--out", type=argtypes.out_dir, required=True, help="output directory")
    p.add_argument(
        "--perception",
        default="oracle",
        choices=("camera", "oracle"),
        help="perception mode (default: oracle, fast)",
    )
    p.add_argument(
        "--truth-samples",
        type=argtypes.positive_int,
        default=300,
        help="rooms sampled for the ground truth (default: 300)",
    )
    p.add_argument(
        "--alpha", type=argtypes.alpha, default=0.10, help="interval confidence (default: 0.10)"
    )
    p.add_argument(
        "--room-budget",
        type=argtypes.seconds,
        default=None,
        metavar="SECONDS",
        help=ROOM_BUDGET_HELP,
    )
    add_sweep_arguments(p)
    p.set_defaults(func=run_bench)


def run_bench(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench learning``."""
    # Imported here: the benchmark pulls in MuJoCo, which `ctxsearch --help` must not wait for.
    from scripts.experiments.bench_learning import LearningBenchConfig, bench_learning

    names = [s.strip() for s in args.strategies.split(",") if s.strip()]
    if not names:
        raise CtxsearchError("--strategies: give at least one strategy")
    for n in names:
        make_strategy(n)  # one-line error for unknown names
    if len(set(names)) != len(names):
        raise CtxsearchError(f"--strategies: a strategy is listed twice in {args.strategies!r}")
    config = LearningBenchConfig(
        style=args.style,
        rooms=args.rooms,
        seeds=args.seeds,
        strategies=tuple(names),
        perception=args.perception,
        truth_samples=args.truth_samples,
        alpha=args.alpha,
        room_budget_s=args.room_budget,
    )
    result = bench_learning(config, args.out, sweep=SweepOptions.from_args(args))
    print(result.table)
    for f in result.files:
        print(f"wrote {f}")
    return 0
