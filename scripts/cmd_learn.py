"""``ctxsearch learn`` (Figure 2 on the simulated robot) and ``ctxsearch bench learning``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ctxsearch.agent.strategies import STRATEGIES, make_strategy
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import (
    DEFAULT_CONFIRM_REFERENCE,
    PAPER_CONFIRM_REFERENCE,
    Forget,
    IntervalMethod,
)
from ctxsearch.scripts import argtypes, last_stop, stop_code, stop_line
from ctxsearch.scripts.sweep import SweepOptions, add_sweep_arguments

# bench intervals' default settings (scripts.experiments.bench_intervals.DEFAULT_SETTINGS, kept
# here so that --help need not import the benchmark; a test checks they agree)
INTERVAL_SETTINGS = (
    "perfect,realistic,realistic+confirm2,realistic+score0.5,realistic+ref2,realistic+confirm2+ref2,"
    "realistic+ref2+near0.9"
)

ROOM_BUDGET_HELP = (
    "simulated seconds the robot may spend in each room: when they are spent it leaves the room "
    "(the examination in flight completes), whatever is left unexamined (default: no limit, "
    "every room to completion as in the paper's Figure 2)"
)
WORLD_BUDGET_HELP = (
    ROOM_BUDGET_HELP + "; --world-budget is the same, per room or house (a house the budget "
    "ends records no room contents, so no SAME-ROOM counts)"
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
        "--world-budget",
        dest="room_budget",
        type=argtypes.seconds,
        default=None,
        metavar="SECONDS",
        help=WORLD_BUDGET_HELP,
    )
    p.add_argument(
        "--map",
        choices=("given", "built"),
        default=None,
        help="the grid the robot plans on: built = its own map from depth images (camera "
        "default), given = the true layout's grid (oracle default; an ablation for the camera)",
    )
    p.add_argument(
        "--frontier-rule",
        choices=("nearest", "info"),
        default="info",
        help="built map: which frontier to explore next (nearest by driving distance, or most "
        "unknown cells per second; default: info)",
    )
    _add_camera_args(p)
    argtypes.add_interval_argument(p)
    _add_day_args(p)


def _add_camera_args(p: argparse.ArgumentParser) -> None:
    """What camera mode counts as seen: the detector, confirmation, a minimum score."""
    argtypes.add_detector_argument(p)
    p.add_argument(
        "--confirm",
        type=argtypes.positive_int,
        default=1,
        metavar="K",
        help="camera mode: count a related object only once K images of the room detected it "
        "(default: 1, at once)",
    )
    p.add_argument(
        "--min-score",
        type=argtypes.unit_interval,
        default=0.0,
        metavar="C",
        help="camera mode: count a related object only once one of its detections scored at "
        "least C (0..1; the detector's confidence; default: 0, any detection)",
    )
    p.add_argument(
        "--confirm-reference",
        type=argtypes.positive_int,
        default=None,
        metavar="K",
        help="camera mode: examine an object only once K images of the room detected it (a "
        "false positive, drawn anew in every image, is then almost never examined; 1: at once, "
        f"as published; default: {DEFAULT_CONFIRM_REFERENCE})",
    )
    p.add_argument(
        "--paper",
        action="store_true",
        help="the paper's literal learning loop: every detected object may be examined at once "
        f"(--confirm-reference {PAPER_CONFIRM_REFERENCE})",
    )
    p.add_argument(
        "--exam-recall",
        type=argtypes.unit_interval,
        default=None,
        metavar="R",
        help="camera mode: plan examinations to see: the gaze planner keeps its viewpoints within "
        "the distance at which the catalog's object types are detected with mean single-image "
        "recall R by the run's detector (e.g. 0.9; default: the planner's 2.5 m)",
    )


def _add_day_args(p: argparse.ArgumentParser) -> None:
    """How ``learn`` runs over days: how many, re-examination, forgetting."""
    p.add_argument(
        "--days",
        type=argtypes.positive_int,
        default=1,
        metavar="D",
        help="visit the same rooms on D days (furniture stays; each small object stays where it "
        "was with its type's stay probability, assets/types.toml or the style's [stay], and the "
        "style's rules and its [[drift]] schedule place the day's others); a later call with "
        "more days adds the days not yet done (default: 1, the paper's single visit)",
    )
    p.add_argument(
        "--reexamine",
        choices=("never", "impact"),
        default="never",
        help="on a later day, may an object examined before be examined again? never (the "
        "paper, default); impact: when its type's impact under the --forget counts, per second "
        "of examining it, is at least --reexamine-rate",
    )
    p.add_argument(
        "--reexamine-rate",
        type=argtypes.non_negative_float,
        default=None,
        metavar="IMPACT_PER_S",
        help="impact (eq. 3) per simulated second worth a re-examination (default: 1e-3)",
    )
    argtypes.add_forget_arguments(p)


def confirm_reference(args: argparse.Namespace) -> int:
    """The images that must detect a reference: ``--confirm-reference``, 1 with ``--paper``
    (the two together only where they agree), else the default."""
    k = getattr(args, "confirm_reference", None)
    if getattr(args, "paper", False):
        if k is not None and k != PAPER_CONFIRM_REFERENCE:
            raise CtxsearchError(
                f"--paper examines every detected object (--confirm-reference "
                f"{PAPER_CONFIRM_REFERENCE}); it contradicts --confirm-reference {k}"
            )
        return PAPER_CONFIRM_REFERENCE
    return DEFAULT_CONFIRM_REFERENCE if k is None else k


def run_learn(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch learn``."""
    # Imported here: learning pulls in MuJoCo, which `ctxsearch --help` must not wait for.
    from ctxsearch.agent.learning import LearnConfig, learn
    from ctxsearch.agent.run_state import DEFAULT_REEXAMINE_RATE

    rate = DEFAULT_REEXAMINE_RATE if args.reexamine_rate is None else args.reexamine_rate
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
            map_mode=args.map,
            frontier_rule=args.frontier_rule,
            detector=args.detector,
            confirm=args.confirm,
            min_score=args.min_score,
            confirm_reference=confirm_reference(args),
            exam_recall=args.exam_recall,
            days=args.days,
            reexamine=args.reexamine,
            reexamine_rate=rate,
            forgetting=argtypes.forgetting(args),
        )
    )
    for line in s.lines():
        print(line)
    if args.interval != IntervalMethod.WILSON:
        print(f"mean interval width ({args.interval}): {_mean_width(args.kb, args.interval):.4f}")
    if args.forget != Forget.NONE:
        width = _forget_width(args.kb, s.run, argtypes.forgetting(args))
        print(f"mean interval width ({args.forget}, the run's evidence): {width:.4f}")
    for f in s.files:
        print(f"recording: {f} (open with: rerun {f})")
    print(f"store: {args.kb} (see: ctxsearch kb show {args.kb})")
    if s.interrupted:  # the summary above says what was kept; the one line says why it stopped
        signum = last_stop()
        print(f"{stop_line(signum)} (every examination finished is kept: the same command "
              "resumes)", file=sys.stderr)  # fmt: skip
        return stop_code(signum)
    return 0


def _mean_width(kb_path: Path, interval: str) -> float:
    """The store's mean interval width read with ``interval``."""
    from ctxsearch.knowledge.catalog import load_catalog
    from ctxsearch.knowledge.store import EvidenceStore

    with EvidenceStore.open(kb_path, load_catalog(), read_only=True) as store:
        return store.knowledge_base(interval=interval).mean_width()


def _forget_width(kb_path: Path, run: str, forgetting) -> float:
    """The run's mean interval width on its last day, read with ``forgetting``."""
    from ctxsearch.knowledge.catalog import load_catalog
    from ctxsearch.knowledge.drift import ForgetKnowledgeBase, evidence_of
    from ctxsearch.knowledge.store import EvidenceStore

    with EvidenceStore.open(kb_path, load_catalog(), read_only=True) as store:
        ev = evidence_of(store.examinations(run))
        kb = ForgetKnowledgeBase(store.catalog, store.alpha, ev, ev.last_day, forgetting)
        return kb.mean_width()


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
        "--world-budget",
        dest="room_budget",
        type=argtypes.seconds,
        default=None,
        metavar="SECONDS",
        help=WORLD_BUDGET_HELP,
    )
    argtypes.add_detector_argument(p)
    argtypes.add_interval_argument(p)
    add_sweep_arguments(p)
    p.set_defaults(func=run_bench)
    register_intervals(bench_sub)
    register_drift(bench_sub)


def register_drift(bench_sub: argparse._SubParsersAction) -> None:
    """Add ``bench drift``."""
    p = bench_sub.add_parser(
        "drift",
        help="a world set that changes over days: how fast none / half-life / detect notice it, "
        "their false alarms and errors, and the search on the last day with each",
        description="Learn in --rooms rooms of a style on --days days (the furniture stays; an "
        "small objects are placed anew each day, so that what changes is the rules alone) while the style "
        "drifts (its [[drift]] schedule, or --drift RULE:P:FROM_DAY, applied in memory), once "
        "re-examining every known object daily (one store read by each forgetting method) and "
        "once per method with --reexamine impact. "
        "Writes DIR/drift.json, DIR/drift.md, DIR/drift.csv (per day x entry x method) and "
        "DIR/drift.png (p_true(day) against each method's interval for the changed entries).",
    )
    p.add_argument(
        "--style",
        default="office",
        help="room style: name or TOML path (default: office); not a house style (a drift "
        "schedule belongs to a room style: the rooms of a house drift with theirs in learn --days)",
    )
    p.add_argument("--days", type=argtypes.positive_int, default=12, help="days (default: 12)")
    p.add_argument(
        "--rooms", type=argtypes.positive_int, default=4, help="rooms visited per day (default: 4)"
    )
    p.add_argument("--seed", type=argtypes.seed, default=0, help="run seed (default: 0)")
    p.add_argument(
        "--drift",
        action="append",
        default=None,
        metavar="RULE:P:FROM_DAY",
        help="a change (repeatable): from FROM_DAY on (an integer, or 'half' for days // 2) the "
        "rule REF/RELATION/TYPE places with probability P (default: the style's own schedule, "
        "else Desk/ON-TOP-OF-DESK/Laptop:0.9:half and Desk/ON-TOP-OF-DESK/Monitor:0.3:half)",
    )
    p.add_argument(
        "--half-life", type=argtypes.positive_float, default=3.0, metavar="DAYS",
        help="half-life of the half-life method (default: 3)",
    )  # fmt: skip
    p.add_argument(
        "--false-alarm", type=argtypes.alpha, default=0.05, metavar="RATE",
        help="detect's false-alarm rate per entry and run (default: 0.05)",
    )  # fmt: skip
    p.add_argument(
        "--truth-samples", type=argtypes.positive_int, default=30,
        help="day draws of the bench's worlds per phase of the schedule for p_true (default: 30)",
    )  # fmt: skip
    p.add_argument(
        "--episodes", type=argtypes.non_negative_int, default=4,
        help="search episodes on the last day per method (default: 4; 0: no search)",
    )  # fmt: skip
    p.add_argument(
        "--perception",
        default="oracle",
        choices=("camera", "oracle"),
        help="perception mode (default: oracle: D days of camera learning are slow on 2 cores)",
    )
    p.add_argument("--out", type=argtypes.out_dir, required=True, help="output directory")
    add_sweep_arguments(p)
    p.set_defaults(func=run_drift)


def run_drift(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench drift``."""
    # Imported here: the benchmark pulls in MuJoCo, which `ctxsearch --help` must not wait for.
    from ctxsearch.knowledge.catalog import load_catalog
    from ctxsearch.scripts.experiments.bench_drift import (
        DriftBenchConfig,
        bench_drift,
        drifting_style,
        markdown,
    )

    config = DriftBenchConfig(
        style=args.style,
        days=args.days,
        rooms=args.rooms,
        seed=args.seed,
        drift=tuple(args.drift or ()),
        half_life=args.half_life,
        false_alarm=args.false_alarm,
        truth_samples=args.truth_samples,
        episodes=args.episodes,
        perception=args.perception,
    )
    if args.days < 2:
        raise CtxsearchError("--days: a world that changes needs at least 2 days")
    drifting_style(config, load_catalog())  # one-line errors before anything runs
    doc = bench_drift(config, args.out, sweep=SweepOptions.from_args(args))
    print(markdown(doc))
    for name in ("drift.json", "drift.md", "drift.csv", "drift.png"):
        print(f"wrote {args.out / name}")
    return 0


def register_intervals(bench_sub: argparse._SubParsersAction) -> None:
    """Add ``bench intervals``."""
    p = bench_sub.add_parser(
        "intervals",
        help="detector (perfect, realistic) x interval (wilson, clustered, corrected) against the "
        "ground truth: informative coverage, mean |p0 - p_true|, mean width, bias per type",
        description="HIF learns in camera mode with each detector setting over the same rooms "
        "and seeds; after the given room counts, the intervals (wilson, clustered and corrected, "
        "on the same evidence, and the type hierarchy's backoff on the wilson and on the "
        "corrected ones) are measured against the ground truth, with each examination's "
        "simulated seconds and expected recall. Writes DIR/intervals.json, DIR/intervals.md and, "
        "per seed, DIR/intervals.csv and DIR/intervals_bias.csv.",
    )
    p.add_argument(
        "--styles",
        default="office,apartment",
        help="comma-separated styles (default: office,apartment)",
    )
    p.add_argument("--rooms", default="10,30", help="comma-separated room marks (default: 10,30)")
    p.add_argument("--seeds", type=argtypes.positive_int, default=3, help="seeds (default: 3)")
    p.add_argument(
        "--settings",
        default=INTERVAL_SETTINGS,
        help=f"detector settings (default: {INTERVAL_SETTINGS})",
    )
    p.add_argument(
        "--truth-samples",
        type=argtypes.positive_int,
        default=400,
        help="rooms sampled for the ground truth (default: 400: the truth's own standard error, "
        "a median 0.01 in offices, must be small against the intervals it checks)",
    )
    p.add_argument("--out", type=argtypes.out_dir, required=True, help="output directory")
    add_sweep_arguments(p)
    p.set_defaults(func=run_intervals)


def run_intervals(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench intervals``."""
    # Imported here: the benchmark pulls in MuJoCo, which `ctxsearch --help` must not wait for.
    from ctxsearch.scripts.experiments.bench_intervals import (
        SETTINGS,
        IntervalsBenchConfig,
        bench_intervals,
        markdown,
    )

    try:
        marks = tuple(argtypes.positive_int(x) for x in args.rooms.split(",") if x.strip())
    except argparse.ArgumentTypeError as exc:
        raise CtxsearchError(f"--rooms: {exc}") from None
    settings = tuple(x.strip() for x in args.settings.split(",") if x.strip())
    known = [s[0] for s in SETTINGS]
    for s in settings:
        if s not in known:
            raise CtxsearchError(f"--settings: unknown setting '{s}' (known: {', '.join(known)})")
    if not marks:
        raise CtxsearchError("--rooms: give at least one room count")
    config = IntervalsBenchConfig(
        styles=tuple(x.strip() for x in args.styles.split(",") if x.strip()),
        room_marks=marks,
        seeds=args.seeds,
        truth_samples=args.truth_samples,
        settings=settings,
    )
    doc = bench_intervals(config, args.out, sweep=SweepOptions.from_args(args))
    print(markdown(doc))
    files = ", ".join(str(args.out / f"intervals.{x}") for x in ("json", "md", "csv"))
    print(f"wrote {files}")
    return 0


def run_bench(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench learning``."""
    # Imported here: the benchmark pulls in MuJoCo, which `ctxsearch --help` must not wait for.
    from ctxsearch.scripts.experiments.bench_learning import LearningBenchConfig, bench_learning

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
        detector=args.detector,
        interval=args.interval,
    )
    result = bench_learning(config, args.out, sweep=SweepOptions.from_args(args))
    print(result.table)
    for f in result.files:
        print(f"wrote {f}")
    return 0
