"""``ctxsearch search`` (one object search in a held-out room) and ``ctxsearch bench search``."""

from __future__ import annotations

import argparse
from pathlib import Path

from ctxsearch.agent.search import config as cfg
from ctxsearch.agent.search.config import ConfigError, HomeSource, SearchConfig
from ctxsearch.agent.search.registry import POLICIES, Role, default_policies, with_role
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
from ctxsearch.scripts import argtypes
from ctxsearch.scripts.sweep import add_sweep_arguments

# The policies' facts, the modes and the configuration's defaults come from light modules (no
# MuJoCo, no scipy), so building the parser (``ctxsearch --help``, ``kb show``) stays fast.
POLICY_NAMES = tuple(POLICIES)
DEFAULT_POLICIES = {m: ",".join(default_policies(m)) for m in MapMode}
DEFAULT_POLICY = {m: with_role(m, Role.CONTEXT) for m in MapMode}  # `search --policy`
HOME_ARMS = default_policies(MapMode.REMEMBERED)  # `bench home`'s arms
HOME_GAPS = (1, 2, 4)  # `bench home --days-after`: days between the robot's map and the queries

# Each flag that sets a configuration key: argparse's dest -> the key (agent.search.config).
# A flag not given leaves the key as the defaults and --config set it; --set comes last.
FLAG_KEYS = {
    "style": "style",
    "seed": "seed",
    "episodes": "episodes",
    "budget_seconds": "budget_s",
    "targets": "targets",
    "detector": "detector",
    "draw_cache": "draw_cache",
    "kb": "knowledge.kb",
    "rank": "knowledge.rank",
    "estimate": "knowledge.estimate",
    "min_evidence": "knowledge.min_evidence",
    "interval": "knowledge.interval",
    "room_context": "knowledge.room_context",
    "truth": "knowledge.truth",
    "truth_samples": "knowledge.truth_samples",
    "map": "map.scenario",
}


def add_budget_argument(p: argparse.ArgumentParser) -> None:
    """``--budget-seconds``: an episode's simulated-time budget."""
    p.add_argument(
        "--budget-seconds",
        type=argtypes.seconds,
        default=None,
        metavar="B",
        help="simulated seconds before an episode counts as failed "
        f"(default: {cfg.DEFAULT_BUDGET_S:.0f})",
    )


def _add_common(p: argparse.ArgumentParser) -> None:
    """The flags ``search`` and ``bench search`` share: each sets a key of the configuration
    (``FLAG_KEYS``); ``--config`` and ``--set`` reach every key."""
    p.add_argument(
        "--kb", type=Path, default=None, help="knowledge store made by `ctxsearch learn`"
    )
    add_budget_argument(p)
    p.add_argument("--rank", choices=values(Rank), default=None, help=cfg.help_of("knowledge.rank"))
    p.add_argument(
        "--estimate", choices=values(Estimate), default=None, help=cfg.help_of("knowledge.estimate")
    )
    p.add_argument(
        "--min-evidence",
        type=argtypes.non_negative_int,
        default=None,
        metavar="N",
        help=cfg.help_of("knowledge.min_evidence"),
    )
    p.add_argument(
        "--truth", type=Path, default=None, metavar="FILE.json", help=cfg.help_of("knowledge.truth")
    )
    p.add_argument(
        "--truth-samples",
        type=argtypes.positive_int,
        default=None,
        help=cfg.help_of("knowledge.truth_samples"),
    )
    p.add_argument(
        "--room-context",
        action="store_true",
        default=None,
        help="the context policies also use room context, P(SAME-ROOM-AS-F(T)) on the rooms of "
        "the map (the plan's on the given map, the robot's segmentation of its own on the built "
        "map): the learned ones the store's intervals (learned in houses), the oracle-prior ones "
        "the truth over the --truth-samples worlds; refused for a run in which a policy with "
        "knowledge cannot use it (indirect on the given map) or none uses it",
    )
    p.add_argument("--targets", choices=values(Targets), default=None, help=cfg.help_of("targets"))
    argtypes.add_detector_argument(p)
    p.add_argument(
        "--interval",
        default=None,
        choices=values(IntervalMethod),
        help=cfg.help_of("knowledge.interval"),
    )
    p.add_argument(
        "--map",
        choices=values(MapMode),
        default=None,
        help="the map scenario: built (the robot knows nothing at the start and maps as it "
        "searches: frontier, indirect, oracle-prior-indirect, oracle) or given (the furniture "
        "poses are known: map-only, location, oracle-prior, oracle, exhaustive); default: built "
        "(in houses; single-room styles, the small-world reference, default to given)",
    )
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        metavar="FILE",
        help="read the whole configuration from FILE: TOML (keys and [sections]: see "
        "--show-config) or a result's search.json (its config entry: the run again); the flags "
        "given and --set override it",
    )
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="set any configuration key, e.g. --set online.lookahead=true, --set "
        "map.depth_range_m=10, --set belief.stop_mass=0.01 (repeatable; after --config and "
        f"the flags; default: none). Keys: {', '.join(cfg.keys())}",
    )
    p.add_argument(
        "--show-config",
        action="store_true",
        help="print the configuration these arguments give, as TOML, and exit",
    )


def config_from_args(args: argparse.Namespace) -> SearchConfig:
    """The configuration of a ``search`` or ``bench search`` command line: the defaults, then
    ``--config``, then the flags given, then each ``--set``; one-line errors naming the key."""
    config = cfg.load_file(args.config) if args.config is not None else SearchConfig()
    for dest, key in FLAG_KEYS.items():
        value = getattr(args, dest, None)
        if value is not None:
            flag = "--" + dest.replace("_", "-")
            config = config.updated({key: value}, flag)
    policies = getattr(args, "policies", None) or getattr(args, "policy", None)
    if policies is not None:
        config = config.updated({"policies": policies}, "--policies")
    for assignment in args.overrides:
        config = cfg.apply_set(config, assignment)
    return config


def show_config(config: SearchConfig) -> int:
    """``--show-config``: the configuration as TOML on stdout."""
    print(cfg.to_toml(config), end="")
    return 0


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
        "--style",
        default=None,
        help="room style (assets/styles/) or house style (assets/houses/): name or TOML path "
        "(required unless --config gives it)",
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
        default=None,
        help="which held-out room and start pose (default: 0)",
    )
    p.add_argument(
        "--record", type=Path, default=None, metavar="FILE.rrd", help="write a rerun recording"
    )
    _add_common(p)
    argtypes.add_forget_arguments(p)
    p.set_defaults(func=run_search)


def _scenario(config: SearchConfig):
    """The configuration's map scenario, the style's default when it names none."""
    if config.map.scenario is not None:
        return config.map.scenario
    from ctxsearch.agent.search.runner import default_map
    from ctxsearch.envs.houses import resolve_style

    return default_map(resolve_style(config.style))


def _forgetting_knowledge(args: argparse.Namespace, config: SearchConfig):
    """The configuration's store read with --forget on its last day (knowledge.drift), and the
    room seeds it learned in (held out of the search)."""
    from ctxsearch.agent.search.priors import learned_seeds
    from ctxsearch.knowledge.catalog import load_catalog
    from ctxsearch.knowledge.drift import ForgetKnowledgeBase, evidence_of
    from ctxsearch.knowledge.store import EvidenceStore

    k = config.knowledge
    if k.kb is None:
        raise CtxsearchError(f"--forget {args.forget} needs a knowledge store (--kb)")
    if args.interval not in (None, IntervalMethod.WILSON):
        raise CtxsearchError(
            f"--forget {args.forget} does not combine with --interval {args.interval}"
        )
    with EvidenceStore.open(k.kb, load_catalog(), read_only=True) as store:
        ev = evidence_of(store.examinations())
        if not store.examinations_count():
            raise CtxsearchError(f"{k.kb}: the store holds no examinations yet")
        kb = ForgetKnowledgeBase(
            store.catalog, store.alpha, ev, ev.last_day, argtypes.forgetting(args)
        )
        seeds = learned_seeds(store)
    return kb, seeds


def _search_config(args: argparse.Namespace) -> SearchConfig:
    """``search``'s configuration: its arguments, the scenario's context policy when none is
    named."""
    config = config_from_args(args)
    if args.style is None and args.config is None:
        raise ConfigError("--style: required (or a --config that names a style)")
    if not config.policies:
        config = config.updated({"policies": (DEFAULT_POLICY[_scenario(config)],)})
    return config


def _memory_and_first_step(log: list[str]) -> list[str]:
    """What the search remembered of the target (its last sightings) and its first step, from
    the result's log."""
    memory = [line for line in log if "] last saw " in line]
    if len(memory) > 5:
        memory = memory[:5] + [f"  ... and {len(memory) - 5} more sightings"]
    first = next((line for line in log if "] look into " in line or "] explore " in line), None)
    return memory + ([f"{first} (the first step)"] if first else [])


def run_search(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch search``."""
    # Imported here: the search stack pulls in MuJoCo and scipy, which `--help` must not wait for.
    from ctxsearch.agent.search.episode import check_budget, check_target
    from ctxsearch.envs.houses import resolve_style
    from ctxsearch.knowledge.catalog import load_catalog

    config = _search_config(args)
    if args.show_config:
        return show_config(config)
    catalog = load_catalog()  # an impossible request is refused before the search stack loads
    check_target(catalog, args.target, resolve_style(config.style, catalog))
    check_budget(config.budget_s)
    from ctxsearch.agent.search.priors import KnowledgeSource
    from ctxsearch.agent.search.runner import search_once

    source = KnowledgeSource()
    if args.forget != Forget.NONE:
        kb, seeds = _forgetting_knowledge(args, config)
        source = KnowledgeSource(kb, frozenset(seeds))
        # Forgetting reads Wilson intervals on its weighted counts (knowledge.drift): recorded so.
        config = config.updated({"knowledge.kb": None, "knowledge.interval": "wilson"})
    one = search_once(config, args.target, source=source, records=[args.record], catalog=catalog)
    if args.forget != Forget.NONE:
        print(f"knowledge: {args.kb} read with forgetting {argtypes.forgetting(args).label} "
              f"on day {source.kb.today}")  # fmt: skip
    ep, res = one.episode, one.results[0]
    s, c = ep.start, one.config
    print(
        f"room: {ep.style} seed {ep.room_seed} ({_provenance(c, ep.day)}); start ({s.x:.2f}, "
        f"{s.y:.2f}) heading {s.yaw:.2f} rad; target {ep.target}; policy {res.policy}"
    )
    for line in _memory_and_first_step(res.log):
        print(line)
    print(f"{'FOUND' if res.success else 'NOT FOUND'}: {res.summary()}")
    detector = c.detector_model(catalog).name
    print(f"detector: {detector}; intervals: {c.knowledge.interval}; map: {c.scenario}")
    if args.record is not None:
        print(f"recording: {args.record} (open with: rerun {args.record})")
    return 0


def _provenance(config, day: int) -> str:
    """Where the searched world comes from, in words."""
    if config.scenario is not MapMode.REMEMBERED:
        return "held out"
    tour = config.map.home is HomeSource.TOUR
    where = "held out, toured" if tour else "a house it learned in, its map"
    from ctxsearch.agent.search.runner import days_after  # lazy: the runner loads MuJoCo

    return f"{where} {days_after(config)} day(s) before; day {day}"


def register_bench(bench_sub: argparse._SubParsersAction) -> None:
    """Add ``bench search`` and ``bench home``."""
    _register_bench_search(bench_sub)
    register_home(bench_sub)


def _register_bench_search(bench_sub: argparse._SubParsersAction) -> None:
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
    _add_bench_flags(
        p,
        "paired episodes (default: 40)",
        "comma-separated policies (default with --map built: "
        f"{DEFAULT_POLICIES['built']}; with --map given: {DEFAULT_POLICIES['given']})",
    )
    p.set_defaults(func=run_bench)


def _add_bench_flags(p: argparse.ArgumentParser, episodes_help: str, policies_help: str) -> None:
    """The flags ``bench search`` and ``bench home`` share (then ``_add_common``'s and the
    sweep's)."""
    p.add_argument(
        "--style",
        default=None,
        help="room style (assets/styles/) or house style (assets/houses/): name or TOML path "
        "(default: office)",
    )
    p.add_argument("--episodes", type=argtypes.positive_int, default=None, help=episodes_help)
    p.add_argument("--policies", default=None, help=policies_help)
    p.add_argument("--out", type=argtypes.out_dir, default=None, help="output directory (required)")
    p.add_argument("--seed", type=argtypes.seed, default=None, help="episode seed (default: 0)")
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
    add_sweep_arguments(p, journal=True)


def run_bench(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench search``."""
    config = config_from_args(args)
    if args.show_config:
        return show_config(config)
    if args.out is None:
        raise CtxsearchError("bench search: --out DIR is required")
    # Imported here: the search stack pulls in MuJoCo and scipy, which `--help` must not wait for.
    from ctxsearch.agent.search.episode import check_budget

    check_budget(config.budget_s)  # refused before the benchmark's imports
    from ctxsearch.scripts.experiments.bench_search import bench_search
    from ctxsearch.scripts.sweep import SweepOptions

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


def register_home(bench_sub: argparse._SubParsersAction) -> None:
    """Add ``bench home``."""
    p = bench_sub.add_parser(
        "home",
        help="the changing home: memory and context on the remembered map, days after",
        description="The robot lives in the houses of --kb (learned with ctxsearch learn --days "
        "on the built map: its remembered maps and the persistence it learned) and is asked for "
        "a small type on a day --days-after its latest map, half the queries for a type an "
        "instance of which stands where one stood on the map's day, half for one that moved. "
        f"Runs the arms ({', '.join(HOME_ARMS)}) on the same episodes at each gap and prints each "
        "against uniform, and memory-location against memory only and relations only, with the "
        "geometric mean of the paired ratio, its interval, wins/losses/ties and the signed-rank "
        "p, overall and within the stayed and moved queries. Writes DIR/home.json, DIR/home.md "
        "and each gap's bench search files in DIR/d=GAP/.",
    )
    _add_bench_flags(
        p, "queries per gap (default: 40)", f"comma-separated (default: {','.join(HOME_ARMS)})"
    )
    p.add_argument(
        "--days-after",
        type=argtypes.positive_ints,
        default=HOME_GAPS,
        metavar="D[,D...]",
        help="days between the robot's latest map and the queries (default: "
        f"{','.join(map(str, HOME_GAPS))})",
    )
    p.set_defaults(func=run_home)


def run_home(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch bench home``."""
    if args.map not in (None, MapMode.REMEMBERED.value):
        raise CtxsearchError(f"bench home: --map {args.map}: the home is the remembered map")
    config = config_from_args(args).updated({"map.scenario": "remembered"}, "bench home")
    if args.show_config:
        return show_config(config)
    if args.out is None:
        raise CtxsearchError("bench home: --out DIR is required")
    if config.knowledge.kb is None:
        raise CtxsearchError("bench home: --kb is required (learn with ctxsearch learn --days)")
    from ctxsearch.agent.search.episode import check_budget

    check_budget(config.budget_s)
    from ctxsearch.scripts.experiments.bench_home import bench_home
    from ctxsearch.scripts.sweep import SweepOptions

    res = bench_home(
        config, args.out, args.days_after, progress=None if args.quiet else print,
        sweep=SweepOptions.from_args(args), bar=not args.quiet,
    )  # fmt: skip
    print(res.table)
    print(f"wrote {args.out / 'home.json'}, {args.out / 'home.md'} and each gap's files")
    print(f"({res.wall_s:.0f} s wall)")
    return 0
