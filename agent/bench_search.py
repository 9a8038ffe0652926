"""The search benchmark: every policy on the same episodes, time to find, and the files.

Paired episodes. ``make_episodes`` draws the episode list once: held-out rooms
(``search.held_out_seed(seed, i)``, skipping any seed the knowledge store learned in and rooms
without a small object), a start pose (a uniformly drawn free cell, random heading) and a
target type drawn uniformly among the small (kind=object) types present in the room. Every
policy then runs every episode: the room is built once per episode and the robot is put back at
the same start pose for each policy, with a fresh seen map and nothing known.

Statistics per policy: success rate within the budget; median and mean simulated seconds to
find, **a failure counted at the budget** (so a policy that fails often cannot look fast), each
with a seeded percentile bootstrap 95% interval over episodes; mean gazes and metres driven;
the ratio of the median to ``exhaustive``'s and to ``oracle``'s (when they ran), and the paired
ratio (the median over episodes of this policy's time over exhaustive's) with its interval.

Policy names may carry a rank, ``location@low``, ``location@p0``, ``location@high``, to compare
the parts of the interval on the same episodes.

Writes ``DIR/search.json``, ``DIR/search.md`` (the table) and ``DIR/search.png`` (the
time-to-find CDF of every policy).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agent import search as S
from agent import search_space as ss
from agent.navigation import OccupancyGrid
from envs.robot_spec import RobotSpec
from knowledge.catalog import Catalog
from knowledge.errors import CtxsearchError

BOOTSTRAP_SAMPLES = 2000


# =========================================================================== episodes
def make_episodes(
    style,
    n: int,
    seed: int,
    catalog: Catalog,
    budget_s: float = S.DEFAULT_BUDGET_S,
    exclude_seeds: set[int] | frozenset[int] = frozenset(),
    spec: RobotSpec | None = None,
    target: str | None = None,
    max_tries: int | None = None,
) -> list[S.Episode]:
    """``n`` episodes in held-out rooms of ``style`` (a Style), deterministic in ``seed``.

    ``target``: only rooms holding that type, always looking for it (``ctxsearch search``);
    otherwise the target is drawn among the room's small types."""
    from envs.rooms import generate_room

    spec = spec or RobotSpec()
    out: list[S.Episode] = []
    i = 0
    limit = max_tries if max_tries is not None else 50 * n + 100
    while len(out) < n:
        if i >= limit:
            what = f"a {target}" if target else "a small object"
            raise CtxsearchError(
                f"no held-out room of style '{style.name}' holds {what} (tried {limit} rooms)"
            )
        room_seed = S.held_out_seed(seed, i)
        rng = np.random.default_rng([int(seed), i, 0xE915])
        i += 1
        if room_seed in exclude_seeds:
            continue
        layout = generate_room(style, room_seed, catalog)
        small = S.small_types_present(layout, catalog)
        if target is not None:
            if target not in {o.type for o in layout.objects}:
                continue
            tgt = target
        elif small:
            tgt = small[int(rng.integers(len(small)))]
        else:
            continue
        grid = OccupancyGrid.from_layout(layout, spec)
        start = S.random_start(layout, grid, rng)
        out.append(S.Episode(len(out), style.name, room_seed, tgt, start, float(budget_s)))
    return out


# =========================================================================== statistics
def bootstrap_ci(
    values: Sequence[float],
    stat: Callable[[np.ndarray], float] = np.median,
    samples: int = BOOTSTRAP_SAMPLES,
    seed: int = 0,
    level: float = 0.95,
) -> tuple[float, float]:
    """Percentile bootstrap interval of ``stat`` over ``values`` (seeded; (nan, nan) if empty)."""
    v = np.asarray(values, float)
    if len(v) == 0:
        return (math.nan, math.nan)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(v), size=(samples, len(v)))
    stats = np.apply_along_axis(stat, 1, v[idx])
    a = (1 - level) / 2
    return (float(np.quantile(stats, a)), float(np.quantile(stats, 1 - a)))


@dataclass
class PolicyStats:
    """Aggregates of one policy over the episodes."""

    name: str
    success_rate: float
    median_s: float
    median_ci: tuple[float, float]
    mean_s: float
    mean_ci: tuple[float, float]
    gazes: float
    path_m: float
    ratio_to_exhaustive: float | None = None
    ratio_to_oracle: float | None = None
    paired_ratio: float | None = None  # median over episodes of t / t_exhaustive
    paired_ratio_ci: tuple[float, float] | None = None

    def to_json(self) -> dict:
        """The JSON entry of search.json."""

        def r(x):
            return (
                None
                if x is None or (isinstance(x, float) and not math.isfinite(x))
                else round(float(x), 4)
            )

        return {
            "success_rate": r(self.success_rate),
            "median_s": r(self.median_s),
            "median_ci": [r(self.median_ci[0]), r(self.median_ci[1])],
            "mean_s": r(self.mean_s),
            "mean_ci": [r(self.mean_ci[0]), r(self.mean_ci[1])],
            "gazes": r(self.gazes),
            "path_m": r(self.path_m),
            "ratio_to_exhaustive": r(self.ratio_to_exhaustive),
            "ratio_to_oracle": r(self.ratio_to_oracle),
            "paired_ratio_to_exhaustive": r(self.paired_ratio),
            "paired_ratio_ci": None
            if self.paired_ratio_ci is None
            else [r(v) for v in self.paired_ratio_ci],
        }


def aggregate(results: dict[str, list[S.SearchResult]], seed: int = 0) -> dict[str, PolicyStats]:
    """Per-policy statistics (see the module docstring); episodes must be aligned across policies."""
    out: dict[str, PolicyStats] = {}
    for name, rs in results.items():
        t = np.array([r.time_to_find for r in rs], float)
        out[name] = PolicyStats(
            name=name,
            success_rate=float(np.mean([r.success for r in rs])) if rs else math.nan,
            median_s=float(np.median(t)) if len(t) else math.nan,
            median_ci=bootstrap_ci(t, np.median, seed=seed),
            mean_s=float(np.mean(t)) if len(t) else math.nan,
            mean_ci=bootstrap_ci(t, np.mean, seed=seed),
            gazes=float(np.mean([r.gazes for r in rs])) if rs else math.nan,
            path_m=float(np.mean([r.path_m for r in rs])) if rs else math.nan,
        )
    for ref, attr in (("exhaustive", "ratio_to_exhaustive"), ("oracle", "ratio_to_oracle")):
        if ref in out and out[ref].median_s > 0:
            for st in out.values():
                setattr(st, attr, st.median_s / out[ref].median_s)
    if "exhaustive" in results:
        te = np.array([r.time_to_find for r in results["exhaustive"]], float)
        for name, rs in results.items():
            t = np.array([r.time_to_find for r in rs], float)
            ratio = t / np.maximum(te, 1e-6)
            out[name].paired_ratio = float(np.median(ratio))
            out[name].paired_ratio_ci = bootstrap_ci(ratio, np.median, seed=seed)
    return out


# =========================================================================== running
@dataclass
class BenchResult:
    """What ``bench_search`` produced."""

    episodes: list[S.Episode]
    results: dict[str, list[S.SearchResult]]
    stats: dict[str, PolicyStats]
    table: str
    files: list[Path] = field(default_factory=list)
    wall_s: float = 0.0


def split_name(name: str) -> tuple[str, str | None]:
    """``location@low`` -> ("location", "low"); ``location`` -> ("location", None)."""
    base, _, rank = name.partition("@")
    if rank and rank not in ss.RANK_MODES:
        raise CtxsearchError(
            f"unknown rank '{rank}' in '{name}' (known: {', '.join(ss.RANK_MODES)})"
        )
    S.make_policy(base)
    return base, rank or None


def run_episodes(
    episodes: Sequence[S.Episode],
    policies: Sequence[str],
    catalog: Catalog,
    style,
    probs_for: Callable[[str, str | None], ss.ProbabilitySource | None],
    progress: Callable[[str], None] | None = None,
    record_dir: Path | None = None,
) -> dict[str, list[S.SearchResult]]:
    """Run every policy on every episode (one World per episode, shared by the policies)."""
    from agent.recording import Recorder
    from envs.rooms import generate_room
    from envs.world import World

    results: dict[str, list[S.SearchResult]] = {p: [] for p in policies}
    for ep in episodes:
        layout = generate_room(style, ep.room_seed, catalog)
        world = World(layout, catalog)
        try:
            grid = OccupancyGrid.from_layout(layout, world.spec)
            seen = ss.SeenMap.for_room(layout, catalog)
            for name in policies:
                base, rank = split_name(name)
                policy = S.make_policy(base)
                rec_path = None
                if record_dir is not None:
                    rec_path = Path(record_dir) / f"ep{ep.index:03d}_{name.replace('@', '_')}.rrd"
                with Recorder(rec_path) as rec:
                    rec.log_room(layout, catalog)
                    ctx = S.SearchContext(
                        ep,
                        layout,
                        catalog,
                        world,
                        maps=S.RoomMaps(grid, seen),
                        probs=probs_for(base, rank),
                        recorder=rec,
                        policy=name,
                    )
                    res = policy.run(ctx)
                res.policy = name
                results[name].append(res)
                if progress is not None:
                    progress(
                        f"episode {ep.index} ({ep.target}, room {ep.room_seed}): {res.summary()}"
                    )
        finally:
            world.close()
    return results


def format_table(stats: dict[str, PolicyStats], n: int, budget_s: float) -> str:
    """The Markdown table of search.md."""
    lines = [
        "| policy | success | median s [95% CI] | mean s [95% CI] | gazes | path m | median / exhaustive "
        "| paired ratio [95% CI] | median / oracle |",
        "|---|---|---|---|---|---|---|---|---|",
    ]

    def f(x, d=1):
        return "-" if x is None or not math.isfinite(x) else f"{x:.{d}f}"

    for st in stats.values():
        pr = (
            "-"
            if st.paired_ratio is None
            else (
                f"{st.paired_ratio:.2f} [{f(st.paired_ratio_ci[0], 2)}, {f(st.paired_ratio_ci[1], 2)}]"
            )
        )
        lines.append(
            f"| {st.name} | {100 * st.success_rate:.0f}% | {f(st.median_s)} [{f(st.median_ci[0])}, "
            f"{f(st.median_ci[1])}] | {f(st.mean_s)} [{f(st.mean_ci[0])}, {f(st.mean_ci[1])}] | "
            f"{f(st.gazes)} | {f(st.path_m)} | {f(st.ratio_to_exhaustive, 2)} | {pr} | "
            f"{f(st.ratio_to_oracle, 2)} |"
        )
    lines.append("")
    lines.append(
        f"{n} paired episodes; simulated seconds to find the target, a failure counted at the "
        f"budget ({budget_s:.0f} s); 95% intervals: percentile bootstrap over episodes "
        f"({BOOTSTRAP_SAMPLES} resamples, seeded)."
    )
    return "\n".join(lines)


def plot_cdf(
    results: dict[str, list[S.SearchResult]], budget_s: float, path: Path, title: str
) -> None:
    """search.png: the share of episodes found within t simulated seconds, per policy."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=120)
    for name, rs in results.items():
        t = np.sort([r.sim_time for r in rs if r.success])
        n = len(rs)
        xs = np.concatenate([[0.2], t, [budget_s]])
        ys = np.concatenate([[0.0], np.arange(1, len(t) + 1) / n, [len(t) / n]])
        ax.step(xs, ys, where="post", label=name, lw=1.8)
    ax.set_xscale("log")
    ax.set_xlabel("simulated seconds (log scale)")
    ax.set_ylabel("share of episodes with the target found")
    ax.set_xlim(0.2, budget_s)
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def bench_search(
    kb_path: Path | str,
    style_name: str,
    episodes: int,
    policies: Sequence[str],
    out: Path | str,
    *,
    budget_s: float = S.DEFAULT_BUDGET_S,
    seed: int = 0,
    rank: str = ss.DEFAULT_RANK,
    truth=None,
    truth_samples: int = 200,
    catalog: Catalog | None = None,
    progress: Callable[[str], None] | None = print,
) -> BenchResult:
    """The benchmark (module docstring): run, aggregate, write the three files."""
    from envs.styles import load_style
    from knowledge.catalog import load_catalog

    t_wall = time.perf_counter()
    catalog = catalog or load_catalog()
    names = list(policies)
    for n in names:
        split_name(n)
    if len(set(names)) != len(names):
        raise CtxsearchError(f"a policy is listed twice in {','.join(names)}")
    style = load_style(style_name, catalog)
    need_kb = any(S.POLICIES[split_name(n)[0]].needs == "kb" for n in names)
    need_truth = any(S.POLICIES[split_name(n)[0]].needs == "truth" for n in names)
    kb, learned = (None, set())
    if need_kb or kb_path is not None:
        kb, learned = S.open_knowledge(kb_path, catalog)
    truth = S.truth_probabilities(style, catalog, truth_samples, path=truth) if need_truth else None

    def probs_for(base: str, r: str | None) -> ss.ProbabilitySource | None:
        needs = S.POLICIES[base].needs
        if needs == "kb":
            return ss.KBProbabilities(kb, r or rank, rooms=len(learned) or None)
        if needs == "truth":
            return truth
        return None

    eps = make_episodes(style, episodes, seed, catalog, budget_s, exclude_seeds=learned)
    results = run_episodes(eps, names, catalog, style, probs_for, progress=progress)
    stats = aggregate(results, seed=seed)
    table = format_table(stats, len(eps), budget_s)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    doc = {
        "style": style.name,
        "episodes": len(eps),
        "budget_s": budget_s,
        "seed": seed,
        "rank": rank,
        "kb": str(kb_path) if kb_path is not None else None,
        "kb_examinations": kb.total_examinations if kb is not None else 0,
        "failures_counted_at_budget": True,
        "policies": {n: stats[n].to_json() for n in names},
        "episode_list": [
            {
                **ep.to_json(),
                "results": {
                    n: {
                        "found": results[n][i].success,
                        "t": round(results[n][i].sim_time, 3),
                        "gazes": results[n][i].gazes,
                        "path_m": round(results[n][i].path_m, 3),
                    }
                    for n in names
                },
            }
            for i, ep in enumerate(eps)
        ],
    }
    files = [out / "search.json", out / "search.md", out / "search.png"]
    files[0].write_text(json.dumps(doc, indent=1) + "\n")
    kb_line = (
        f"knowledge base `{kb_path}` ({doc['kb_examinations']} examinations), "
        if kb is not None
        else ""
    )
    md = (
        f"# Object search: {style.name}\n\n{kb_line}ranking by the interval's `{rank}`, "
        f"budget {budget_s:.0f} simulated s, seed {seed}.\n\n{table}\n"
    )
    files[1].write_text(md)
    plot_cdf(
        results, budget_s, files[2], f"time to find ({style.name}, {len(eps)} paired episodes)"
    )
    return BenchResult(eps, results, stats, table, files, time.perf_counter() - t_wall)


# =========================================================================== one episode (CLI, demo)
@dataclass
class OneSearch:
    """One episode of ``ctxsearch search``: the episode and each policy's result."""

    episode: S.Episode
    results: list[S.SearchResult]
    files: list[Path] = field(default_factory=list)


def search_once(
    style_name: str,
    target: str,
    policies: Sequence[str],
    *,
    kb=None,
    kb_path=None,
    seed: int = 0,
    budget_s: float = S.DEFAULT_BUDGET_S,
    rank: str = ss.DEFAULT_RANK,
    records: Sequence[Path | None] | None = None,
    truth=None,
    truth_samples: int = 200,
    exclude_seeds: set[int] | frozenset[int] = frozenset(),
    catalog: Catalog | None = None,
    rgb: bool = True,
) -> OneSearch:
    """Search for ``target`` in the first held-out room (for ``seed``) of ``style_name`` that holds
    one, with each of ``policies`` in turn from the same start pose (``records[i]``: policy i's
    rerun recording, or None). ``kb`` (a KnowledgeBase) or ``kb_path`` (a store) gives the learned
    probabilities; ``truth`` a ground-truth JSON path for the oracle-prior policies."""
    from agent.recording import Recorder
    from envs.rooms import generate_room
    from envs.styles import load_style
    from envs.world import World
    from knowledge.catalog import load_catalog

    catalog = catalog or load_catalog()
    S.check_target(catalog, target)
    names = list(policies)
    for n in names:
        split_name(n)
    style = load_style(style_name, catalog)
    learned = set(exclude_seeds)
    if kb is None and kb_path is not None:
        kb, seeds = S.open_knowledge(kb_path, catalog)
        learned |= seeds
    truth_probs = None
    if any(S.POLICIES[split_name(n)[0]].needs == "truth" for n in names):
        truth_probs = S.truth_probabilities(style, catalog, truth_samples, path=truth)
    ep = make_episodes(style, 1, seed, catalog, budget_s, exclude_seeds=learned, target=target)[0]
    layout = generate_room(style, ep.room_seed, catalog)
    records = list(records) if records is not None else [None] * len(names)
    out: list[S.SearchResult] = []
    with World(layout, catalog) as world:
        grid = OccupancyGrid.from_layout(layout, world.spec)
        seen = ss.SeenMap.for_room(layout, catalog)
        for name, rec_path in zip(names, records, strict=True):
            base, r = split_name(name)
            needs = S.POLICIES[base].needs
            if needs == "kb" and kb is None:
                raise CtxsearchError(f"policy '{base}' needs a knowledge store (--kb)")
            probs = (
                ss.KBProbabilities(kb, r or rank, rooms=len(learned) or None)
                if needs == "kb"
                else truth_probs
                if needs == "truth"
                else None
            )
            with Recorder(rec_path) as rec:
                rec.log_room(layout, catalog)
                rec.log_text(
                    f"episode: room {style.name}/{ep.room_seed}, target {target}, policy {name}"
                )
                ctx = S.SearchContext(
                    ep,
                    layout,
                    catalog,
                    world,
                    maps=S.RoomMaps(grid, seen),
                    probs=probs,
                    recorder=rec,
                    policy=name,
                )
                res = S.make_policy(base).run(ctx)
            res.policy = name
            out.append(res)
    return OneSearch(ep, out, [Path(p) for p in records if p is not None])
