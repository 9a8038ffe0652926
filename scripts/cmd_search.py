"""``ctxsearch search`` (one object search in a held-out room) and ``ctxsearch bench search``."""

from __future__ import annotations

import argparse
from pathlib import Path

from ctxsearch.agent.search.registry import (
    DEFAULT_BUDGET_S,
    POLICIES,
    Role,
    default_policies,
    with_role,
)
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import (
    Estimate,
    Forget,
    IntervalMethod,
    MapMode,
    Rank,
    Targets,
    values,
)
from ctxsearch.knowledge.ranking import DEFAULT_ESTIMATE, DEFAULT_MIN_EVIDENCE, DEFAULT_RANK
from ctxsearch.scripts import argtypes
from ctxsearch.scripts.sweep import add_sweep_arguments

# The policies' facts and the modes come from light modules (no MuJoCo, no scipy), so building
# the parser (``ctxsearch --help``, ``kb show``) stays fast.
POLICY_NAMES = tuple(POLICIES)
MAP_MODES = values(MapMode)
DEFAULT_POLICIES = {m: ",".join(default_policies(m)) for m in MapMode}
DEFAULT_POLICY = {m: with_role(m, Role.CONTEXT) for m in MapMode}  # `search --policy`
RANK_MODES = values(Rank)
ESTIMATES = values(Estimate)


def add_budget_argument(p: argparse.ArgumentParser) -> None:
    """``--budget-seconds``: an episode's simulated-time budget."""
    p.add_argument(
        "--budget-seconds",
        type=argtypes.seconds,
        default=DEFAULT_BUDGET_S,
        metavar="B",
        help=f"simulated seconds before an episode counts as failed (default: {DEFAULT_BUDGET_S:.0f})",
    )


def _add_common(p: argparse.ArgumentParser) -> None:
    add_budget_argument(p)
    p.add_argument(
        "--rank",
        choices=RANK_MODES,
        default=DEFAULT_RANK,
        help=f"which part of the interval ranks candidate regions (default: {DEFAULT_RANK}, "
        "chosen by measurement, see README)",
    )
    p.add_argument(
        "--estimate",
        choices=ESTIMATES,
        default=DEFAULT_ESTIMATE,
        help="P(rel(T)) from each type's own evidence (flat, the paper's; default) or, for "
        "reference types with fewer than --min-evidence examinations, from their class "
        "(backoff: the type hierarchy's empirical-Bayes estimate)",
    )
    p.add_argument(
        "--min-evidence",
        type=argtypes.non_negative_int,
        default=DEFAULT_MIN_EVIDENCE,
        metavar="N",
        help=f"with --estimate backoff: types examined fewer than N times back off "
        f"(default: {DEFAULT_MIN_EVIDENCE})",
    )
    p.add_argument(
        "--truth",
        type=Path,
        default=None,
        metavar="FILE.json",
        help="ground truth from `ctxsearch truth` for the oracle-prior policies "
        "(default: estimated over --truth-samples rooms)",
    )
    p.add_argument(
        "--truth-samples",
        type=argtypes.positive_int,
        default=200,
        help="rooms sampled for the ground truth when --truth is not given (default: 200)",
    )
    p.add_argument(
        "--room-context",
        action="store_true",
        help="the context policies also use room context, P(SAME-ROOM-AS-F(T)) on the rooms of "
        "the map (the plan's on the given map, the robot's segmentation of its own on the built "
        "map): the learned ones the store's intervals (learned in houses), the oracle-prior ones "
        "the truth over the --truth-samples worlds",
    )
    p.add_argument(
        "--targets",
        choices=values(Targets),
        default=Targets.TYPE.value,
        help="what an episode asks for: type (any instance of the target type ends the search; "
        "default) or instance (the world keeps one instance of the target, the others taken "
        "out: 'find my phone')",
    )
    argtypes.add_detector_argument(p)
    argtypes.add_interval_argument(p)
    p.add_argument(
        "--map",
        choices=MAP_MODES,
        default=None,
        help="the map scenario: built (the robot knows nothing at the start and maps as it "
        "searches: frontier, indirect, oracle-prior-indirect, oracle) or given (the furniture "
        "poses are known: map-only, location, oracle-prior, oracle, exhaustive); default: built "
        "(in houses; single-room styles, the small-world reference, default to given)",
    )


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``search`` sub-command."""
    p = sub.add_parser(
        "search",
        help="search for an object type in a held-out room, with or without learned context",
        description="Put the robot in a room it never learned in (the first held-out room of --style "
        "for --seed that holds a --target) and let a policy search until the detector reports a "
        "--target or --budget-seconds of simulated time are spent. Prints whether it was found, the "
        "simulated time, the gazes and the distance driven; --record writes a rerun recording with "
        "the ranked candidate regions, the path and every camera view.",
    )
    p.add_argument(
        "--kb", required=True, type=Path, help="knowledge store made by `ctxsearch learn`"
    )
    p.add_argument(
        "--style",
        required=True,
        help="room style (assets/styles/) or house style (assets/houses/): name or TOML path",
    )
    p.add_argument("--target", required=True, help="the object type to find (e.g. Cup)")
    p.add_argument(
        "--policy",
        default=None,
        choices=POLICY_NAMES,
        help="search policy (default: indirect with --map built, location with --map given)",
    )
    p.add_argument(
        "--seed",
        type=argtypes.seed,
        default=0,
        help="which held-out room and start pose (default: 0)",
    )
    p.add_argument(
        "--record", type=Path, default=None, metavar="FILE.rrd", help="write a rerun recording"
    )
    _add_common(p)
    argtypes.add_forget_arguments(p)
    p.set_defaults(func=run_search)


def map_of(args: argparse.Namespace) -> str:
    """The map scenario: ``--map``, else the style's default (episodes.default_map)."""
    if args.map is not None:
        return args.map
    from ctxsearch.agent.search.runner import default_map
    from ctxsearch.envs.houses import resolve_style

    return default_map(resolve_style(args.style))


def _config_fields(args: argparse.Namespace) -> dict:
    """The SearchConfig fields ``search`` and ``bench search`` share, from their flags (``map``
    resolved)."""
    return {
        "map": map_of(args),
        "style": args.style,
        "seed": args.seed,
        "budget_s": args.budget_seconds,
        "rank": args.rank,
        "truth": args.truth,
        "truth_samples": args.truth_samples,
        "estimate": args.estimate,
        "min_evidence": args.min_evidence,
        "detector": args.detector,
        "interval": args.interval,
        "targets": args.targets,
        "rooms": args.room_context,
    }


def _forgetting_knowledge(args: argparse.Namespace):
    """The store at --kb read with --forget on its last day (knowledge.drift), and the room seeds
    it learned in (held out of the search)."""
    from ctxsearch.agent.search.priors import learned_seeds
    from ctxsearch.knowledge.catalog import load_catalog
    from ctxsearch.knowledge.drift import ForgetKnowledgeBase, evidence_of
    from ctxsearch.knowledge.store import EvidenceStore

    if args.interval != IntervalMethod.WILSON:
        raise CtxsearchError(
            f"--forget {args.forget} does not combine with --interval {args.interval}"
        )
    with EvidenceStore.open(args.kb, load_catalog(), read_only=True) as store:
        ev = evidence_of(store.examinations())
        if not store.examinations_count():
            raise CtxsearchError(f"{args.kb}: the store holds no examinations yet")
        kb = ForgetKnowledgeBase(
            store.catalog, store.alpha, ev, ev.last_day, argtypes.forgetting(args)
        )
        seeds = learned_seeds(store)
    return kb, seeds


def run_search(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch search``."""
    # Imported here: the search stack pulls in MuJoCo and scipy, which `--help` must not wait for.
    from ctxsearch.agent.search.episode import check_budget, check_target
    from ctxsearch.envs.houses import resolve_style
    from ctxsearch.knowledge.catalog import load_catalog

    catalog = load_catalog()  # an impossible request is refused before the search stack loads
    check_target(catalog, args.target, resolve_style(args.style, catalog))
    check_budget(args.budget_seconds)
    from ctxsearch.agent.search.runner import SearchConfig, search_once

    fields = _config_fields(args)
    policy = args.policy or DEFAULT_POLICY[fields["map"]]
    config = SearchConfig(policies=(policy,), **fields)
    if args.forget == Forget.NONE:
        one = search_once(config, args.target, kb_path=args.kb, records=[args.record])
    else:
        kb, seeds = _forgetting_knowledge(args)
        one = search_once(config, args.target, kb=kb, exclude_seeds=seeds, records=[args.record])
        print(f"knowledge: {args.kb} read with forgetting {argtypes.forgetting(args).label} "
              f"on day {kb.today}")  # fmt: skip
    ep, res = one.episode, one.results[0]
    s = ep.start
    print(
        f"room: {ep.style} seed {ep.room_seed} (held out); start ({s.x:.2f}, {s.y:.2f}) heading "
        f"{s.yaw:.2f} rad; target {ep.target}; policy {res.policy}"
    )
    print(f"{'FOUND' if res.success else 'NOT FOUND'}: {res.summary()}")
    print(
        f"detector: {config.detector_model(load_catalog()).name}; intervals: {config.interval}; "
        f"map: {config.map}"
    )
    if args.record is not None:
        print(f"recording: {args.record} (open with: rerun {args.record})")
    return 0


def register_bench(bench_sub: argparse._SubParsersAction) -> None:
    """Add ``bench search``."""
    p = bench_sub.add_parser(
        "search",
        help="search policies on the same held-out episodes: time to find, success, ratios",
        description="Draw --episodes paired episodes once (held-out room, a small target type "
        "present in the room, a start pose from which the target is not visible, in a world where "
        "the oracle's planner detects it within the budget; the worlds and starts left out are "
        "counted) and run every policy on each. Reports per policy the paired per-episode ratio of "
        "time to each baseline that ran (median, bootstrap 95% interval, wins, losses), the "
        "success rate within the budget, spl (mean of S * t_oracle / max(t, t_oracle)), median and "
        "mean simulated seconds to find (failures counted at the budget) with bootstrap 95% "
        "intervals, gazes, path length, oracle violations and a per-target breakdown. Writes "
        "DIR/search.json, DIR/search.md, DIR/search.png and DIR/episodes.csv (one row per episode "
        "and policy). A policy name may carry a rank: "
        "location@low,location@p0,location@high. With --workers N the episodes run in batches "
        "as Ray tasks (same files).",
    )
    p.add_argument(
        "--kb", required=True, type=Path, help="knowledge store made by `ctxsearch learn`"
    )
    p.add_argument(
        "--style",
        default="office",
        help="room style (assets/styles/) or house style (assets/houses/): name or TOML path (default: office)",
    )
    p.add_argument(
        "--episodes", type=argtypes.positive_int, default=40, help="paired episodes (default: 40)"
    )
    p.add_argument(
        "--policies",
        default=None,
        help="comma-separated policies (default with --map built: "
        f"{DEFAULT_POLICIES['built']}; with --map given: {DEFAULT_POLICIES['given']})",
    )
    p.add_argument("--out", type=argtypes.out_dir, required=True, help="output directory")
    p.add_argument("--seed", type=argtypes.seed, default=0, help="episode seed (default: 0)")
    p.add_argument("--quiet", action="store_true", help="no line per episode, no progress bar")
    p.add_argument(
        "--draw-cache",
        type=argtypes.out_dir,
        default=None,
        metavar="DIR",
        help="keep the episode draw in DIR and reuse it when the same draw (same arguments, "
        "same code) is asked for again, e.g. by the other --map scenario (default: not kept)",
    )
    _add_common(p)
    add_sweep_arguments(p)
    p.set_defaults(func=run_bench)


def run_bench(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench search``."""
    # Imported here: the search stack pulls in MuJoCo and scipy, which `--help` must not wait for.
    from ctxsearch.agent.search.episode import check_budget

    check_budget(args.budget_seconds)  # refused before the benchmark's imports
    from ctxsearch.agent.search.registry import parse_policies
    from ctxsearch.scripts.experiments.bench_search import SearchBenchConfig, bench_search
    from ctxsearch.scripts.sweep import SweepOptions

    fields = _config_fields(args)
    names = parse_policies(args.policies or DEFAULT_POLICIES[fields["map"]])
    config = SearchBenchConfig(
        policies=tuple(names),
        kb=args.kb,
        episodes=args.episodes,
        draw_cache=args.draw_cache,
        **fields,
    )
    res = bench_search(
        config,
        args.out,
        progress=None if args.quiet else print,
        sweep=SweepOptions.from_args(args),
        bar=not args.quiet,
    )
    print(res.table)
    for f in res.files:
        if f.name == "indirect.md":
            print(f.read_text())
    for f in res.files:
        print(f"wrote {f}")
    print(f"({res.wall_s:.0f} s wall)")
    return 0
