"""``bench curve``: does learning pay? The paired search ratio after k learning worlds.

One learning run (``agent.learning.learn``, one seed) goes through the largest k of ``rooms``
worlds; after k1, k2, ... worlds its evidence store is copied (SQLite's backup API), and the next
``learn`` call resumes the same run and extends it (agent.resume). k = 0 is the empty store.
For every snapshot and every scenario (``scripts.experiments.scenarios``), ``bench search`` runs
the context policy on the same held-out episodes; the baseline and the asymptote (which read no
store) run once, at the first k. The episodes are drawn once from the seed and are checked to be
identical at every k and to lie outside every world the largest k learned in.

Writes ``DIR/curve.json`` (per k: examinations, per scenario the paired ratio of the context
policy to the baseline and of the asymptote to the baseline), ``DIR/curve.md``, ``DIR/curve.png``
(the paired ratio's geometric mean against k on a symlog axis with its 95% band, the
asymptote dashed) and
``DIR/curve.csv`` (one row per k, scenario, episode and policy; a baseline or asymptote row
repeats, at every k, the run made at ``measured_at_k``). The snapshots stay in
``DIR/stores/k=K.sqlite`` (stores of an earlier run there are an error, never overwritten),
each snapshot's search files in ``DIR/k=K/MAP/``.

With ``--journal DIR`` (scripts.journal) the command resumes: the searches' finished units are
read back from the journal, the snapshots already taken are kept, and the learning run goes on
from what ``stores/run.sqlite`` holds (agent.resume); ``stores/learning.json`` names the run the
stores belong to (another run's are an error).
"""

from __future__ import annotations

import json
import os
import sqlite3
import time
from dataclasses import dataclass, field
from pathlib import Path

from matplotlib.figure import Figure

from ctxsearch.agent.learning import LearnConfig, learn
from ctxsearch.agent.search.config import SearchConfig, to_dict
from ctxsearch.agent.search.draw import remembered_draws
from ctxsearch.agent.search.measures import geo_cell
from ctxsearch.agent.search.priors import store_seeds
from ctxsearch.envs.houses import resolve_style
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.experiments.bench_search import BenchResult
from ctxsearch.scripts.experiments.scenarios import (
    RESULT_COLUMNS,
    Scenario,
    check_no_stores,
    check_policies,
    paired,
    paired_ratio,
    result_rows,
    same_episodes,
    search,
    times,
)
from ctxsearch.scripts.experiments.tables import write_csv
from ctxsearch.scripts.sweep import SweepOptions, session


def check_rooms(rooms: tuple[int, ...]) -> tuple[int, ...]:
    """``rooms`` if it is a non-empty, strictly increasing list of counts >= 0; else an error."""
    if not rooms:
        raise CtxsearchError("--rooms: give at least one room count")
    if any(k < 0 for k in rooms):
        raise CtxsearchError(f"--rooms: counts must be >= 0, got {','.join(map(str, rooms))}")
    if any(b <= a for a, b in zip(rooms, rooms[1:], strict=False)):
        raise CtxsearchError(
            f"--rooms: counts must increase strictly, got {','.join(map(str, rooms))}"
        )
    return rooms


@dataclass(frozen=True)
class CurveConfig:
    """What ``bench curve`` learns and searches. ``search`` holds the search settings (style,
    seed, budget, detector, interval, episodes); its ``policies`` and ``kb`` are set per
    scenario and snapshot. ``perception``: how the robot perceives while learning (camera, or
    the faster oracle)."""

    search: SearchConfig
    rooms: tuple[int, ...]
    scenarios: tuple[Scenario, ...]
    perception: str = "camera"


@dataclass
class CurvePoint:
    """One snapshot: k worlds learned, the store's examinations, each scenario's search."""

    k: int
    examinations: int
    store: Path | None
    results: dict[str, BenchResult] = field(default_factory=dict)  # scenario name -> search


@dataclass
class CurveResult:
    """What ``bench_curve`` produced."""

    doc: dict
    table: str
    files: list[Path] = field(default_factory=list)
    wall_s: float = 0.0


def snapshot(src: Path, dst: Path) -> None:
    """Copy the (closed) store ``src`` to ``dst`` with SQLite's backup API, into a temporary
    file first, then renamed: ``dst`` is never half a copy."""
    tmp = dst.with_name(f".{dst.name}.tmp")
    tmp.unlink(missing_ok=True)
    with sqlite3.connect(f"file:{src}?mode=ro", uri=True) as a, sqlite3.connect(tmp) as b:
        a.backup(b)
    a.close()
    b.close()
    os.replace(tmp, dst)


def _snapshot_path(stores: Path, k: int) -> Path:
    return stores / f"k={k:04d}.sqlite"


def _examinations(path: Path) -> int:
    with EvidenceStore.open(path, load_catalog(), read_only=True) as st:
        return st.examinations_count()


def _check_resumable(config: CurveConfig, stores: Path) -> None:
    """Before learning on in ``stores`` (``--journal``): the run there must be this one (its
    settings in ``stores/learning.json``, written at its start), and no snapshot may be missing
    before a present one (a snapshot is taken before the run learns past it)."""
    s = config.search
    mine = {"style": str(s.style), "seed": s.seed, "perception": config.perception,
            "detector": None if s.detector is None else str(s.detector),
            "rooms": list(config.rooms)}  # fmt: skip
    marker = stores / "learning.json"
    if marker.exists():
        try:
            theirs = json.loads(marker.read_text())
        except (OSError, ValueError, UnicodeError):
            theirs = None
        if theirs != mine:
            raise CtxsearchError(
                f"{stores}: holds another learning run's stores (learning.json); remove it or "
                "choose another --out"
            )
    else:
        check_no_stores(stores)
        stores.mkdir(parents=True, exist_ok=True)
        marker.write_text(json.dumps(mine) + "\n")
    present = [k for k in config.rooms if k > 0 and _snapshot_path(stores, k).exists()]
    missing = [k for k in config.rooms if k > 0 and k not in present]
    if present and missing and min(missing) < max(present):
        raise CtxsearchError(
            f"{stores}: the snapshot after k={min(missing)} is missing but a later one is there; "
            f"remove {stores} to learn anew"
        )


def learn_snapshots(
    config: CurveConfig, stores: Path, bar: bool = True, resume: bool = False
) -> list[tuple[int, int, Path | None]]:
    """Learn through the largest k, copying the store after each k of ``config.rooms``:
    (k, examinations, snapshot path or None for k = 0) per k. ``resume``: a snapshot already in
    ``stores`` is kept (it was taken before the run learned past it), and the run goes on from
    what its store holds (agent.resume: a visit stopped half-way is replayed, the same choices
    as an uninterrupted run)."""
    s = config.search
    stores.mkdir(parents=True, exist_ok=True)
    run = stores / "run.sqlite"  # a fresh run (bench_curve checked that none is there) or resumed
    out: list[tuple[int, int, Path | None]] = []
    for k in config.rooms:
        if k == 0:
            out.append((0, 0, None))
            continue
        dst = _snapshot_path(stores, k)
        if resume and dst.exists():
            out.append((k, _examinations(dst), dst))
            continue
        lc = LearnConfig(style=s.style, rooms=k, kb_path=run, seed=s.seed,
                         perception=config.perception, detector=s.detector,
                         progress=bar)  # fmt: skip
        summary = learn(lc)
        if summary.interrupted:
            raise KeyboardInterrupt
        snapshot(run, dst)
        out.append((k, summary.total_examinations, dst))
    return out


def bench_curve(
    config: CurveConfig,
    out: Path | str,
    *,
    sweep: SweepOptions | None = None,
    bar: bool = True,
    progress=print,
) -> CurveResult:
    """The learning curve (module docstring): learn, snapshot, search, write the four files."""
    t0 = time.perf_counter()
    out = Path(out)
    catalog = load_catalog()
    check_rooms(config.rooms)
    resolve_style(config.search.style, catalog)  # one-line errors before any learning
    config.search.detector_model(catalog)
    check_policies(config.scenarios)
    resume = sweep is not None and sweep.journal is not None
    if resume:
        _check_resumable(config, out / "stores")
    else:
        check_no_stores(out / "stores")
    snaps = learn_snapshots(config, out / "stores", bar, resume)
    points: list[CurvePoint] = []
    with session(sweep or SweepOptions()), remembered_draws():
        for i, (k, exams, path) in enumerate(snaps):
            point = CurvePoint(k, exams, path)
            for sc in config.scenarios:
                point.results[sc.name] = _search_snapshot(
                    config, sc, point, i == 0, out, sweep, bar
                )
                if progress is not None:
                    progress(f"k={k}: {sc.name} searched ({exams} examinations)")
            points.append(point)
    _check_pairing(points, store_seeds(snaps[-1][2], load_catalog()))
    doc = curve_doc(config, points)
    table = format_table(doc)
    res = CurveResult(doc, table)
    res.files = write_files(out, doc, table, points, config.scenarios)
    res.wall_s = time.perf_counter() - t0
    return res


def _search_snapshot(config, sc, point, first, out, sweep, bar) -> BenchResult:
    """``bench search`` of scenario ``sc`` on snapshot ``point`` (every policy at the first k,
    the context policy only afterwards)."""
    base = config.search
    kb = KnowledgeBase(load_catalog()) if point.store is None else None
    cfg = base.updated({"knowledge.kb": point.store})
    policies = sc.policies if first else (sc.context,)
    where = out / f"k={point.k:04d}" / sc.name
    return search(cfg, sc, where, policies=policies, kb=kb, sweep=sweep, bar=bar)


def _check_pairing(points: list[CurvePoint], last_learned: set[int]) -> None:
    """Errors unless every snapshot searched the first one's episodes, all held out."""
    for sc in points[0].results:
        first = points[0].results[sc].episodes
        for p in points[1:]:
            same_episodes(first, p.results[sc].episodes, f"k={p.k}, {sc}")
        seen = {ep.room_seed for ep in first} & last_learned
        if seen:
            raise CtxsearchError(f"{sc}: episode rooms {sorted(seen)} were learned in")


def curve_doc(config: CurveConfig, points: list[CurvePoint]) -> dict:
    """curve.json's content."""
    s = config.search
    first = points[0].results
    per_k = []
    for p in points:
        entry: dict = {"k": p.k, "examinations": p.examinations, "scenarios": {}}
        for sc in config.scenarios:
            tb = times(first[sc.name], sc.baseline)
            t_ctx, t_ctx0 = times(p.results[sc.name], sc.context), times(first[sc.name], sc.context)
            entry["scenarios"][sc.name] = {
                # the statistics that can see a small effect: against the baseline, and the
                # context policy against itself with the empty store of k = 0
                "paired": {
                    "context_to_baseline": paired(t_ctx, tb, seed=s.seed),
                    "context_to_k0": paired(t_ctx, t_ctx0, seed=s.seed),
                    "asymptote_to_baseline": paired(
                        times(first[sc.name], sc.asymptote), tb, seed=s.seed
                    ),
                },
                "context_to_baseline": paired_ratio(
                    times(p.results[sc.name], sc.context), tb, seed=s.seed
                ),
                "asymptote_to_baseline": paired_ratio(
                    times(first[sc.name], sc.asymptote), tb, seed=s.seed
                ),
            }
        per_k.append(entry)
    return {
        # the search configuration every snapshot starts from (each run's search.json: its own)
        "search_config": to_dict(s),
        "style": s.style,
        "seed": s.seed,
        "rooms": list(config.rooms),
        "episodes": len(first[config.scenarios[0].name].episodes),
        "budget_s": s.budget_s,
        "detector": s.detector_model(load_catalog()).name,
        "interval": s.knowledge.interval,
        "learning_perception": config.perception,
        "failures_counted_at_budget": True,
        "scenarios": {sc.name: sc.to_json() for sc in config.scenarios},
        "curve": per_k,
    }


def _fmt(r: dict) -> str:
    if r["median"] is None:
        return "-"
    return f"{r['median']:.2f} [{r['ci'][0]:.2f}, {r['ci'][1]:.2f}] ({r['wins']}/{r['losses']})"


def format_table(doc: dict) -> str:
    """curve.md's table: one row per k, the paired ratios of each scenario."""
    names = list(doc["scenarios"])
    head = "| k | examinations | " + " | ".join(
        f"{n}: {doc['scenarios'][n]['context']} / {doc['scenarios'][n]['baseline']}" for n in names
    )
    lines = [head + " |", "|---|---|" + "---|" * len(names)]
    for e in doc["curve"]:
        cells = [_fmt(e["scenarios"][n]["context_to_baseline"]) for n in names]
        lines.append(f"| {e['k']} | {e['examinations']} | " + " | ".join(cells) + " |")
    last = doc["curve"][-1]["scenarios"]
    lines.append("| asymptote | - | " + " | ".join(
        f"{doc['scenarios'][n]['asymptote']}: {_fmt(last[n]['asymptote_to_baseline'])}"
        for n in names) + " |")  # fmt: skip
    lines += [
        "",
        f"{doc['episodes']} paired episodes per scenario, the same at every k; cells: the median "
        "over episodes of t_context / t_baseline [95% bootstrap interval] (episodes won / lost); "
        f"a failure counted at the budget ({doc['budget_s']:.0f} s).",
    ]
    if "paired" in doc["curve"][0]["scenarios"][names[0]]:
        lines = [*_paired_table(doc, names), "", *lines]
    return "\n".join(lines)


def _paired_table(doc: dict, names: list[str]) -> list[str]:
    """curve.md's first table: by k, the geometric mean of the paired time ratio of the context
    policy to the baseline and to itself at k = 0, with the ties and the signed-rank test."""
    head = "| k | " + " | ".join(
        f"{n}: {doc['scenarios'][n]['context']} / {doc['scenarios'][n]['baseline']} | "
        f"{n}: / itself at k = 0"
        for n in names
    )
    lines = [head + " |", "|---|" + "---|---|" * len(names)]
    for e in doc["curve"]:
        cells = []
        for n in names:
            pr = e["scenarios"][n]["paired"]
            cells += [geo_cell(pr["context_to_baseline"]), geo_cell(pr["context_to_k0"])]
        lines.append(f"| {e['k']} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Cells: the geometric mean over episodes of the paired time ratio [95% bootstrap "
        "interval], wins/losses/ties (a tie within 1e-6 s counts as ratio 1), and the Wilcoxon "
        "signed-rank p on the log ratios (agent.search.measures.paired_stats).",
    ]
    return lines


def plot_curve(doc: dict, path: Path) -> None:
    """curve.png: the geometric mean of the paired ratio against k (symlog) with its 95%
    bootstrap band, the headline statistic of the tables (a median is pinned at 1 by ties), and
    the asymptote's dashed."""
    fig = Figure(figsize=(7, 4.5), dpi=120)
    ax = fig.subplots()
    ks = [e["k"] for e in doc["curve"]]
    for i, (name, sc) in enumerate(doc["scenarios"].items()):
        color = f"C{i}"
        rs = [e["scenarios"][name]["paired"]["context_to_baseline"] for e in doc["curve"]]
        geo = [r["geo_mean"] for r in rs]
        ax.plot(ks, geo, "o-", color=color, label=f"{name} map: {sc['context']} / {sc['baseline']}")
        ax.fill_between(ks, [r["geo_mean_ci"][0] for r in rs], [r["geo_mean_ci"][1] for r in rs],
                        color=color, alpha=0.2, lw=0)  # fmt: skip
        asym = doc["curve"][-1]["scenarios"][name]["paired"]["asymptote_to_baseline"]["geo_mean"]
        ax.axhline(asym, color=color, ls="--", lw=1.2, label=f"{sc['asymptote']} (asymptote)")
    ax.axhline(1.0, color="grey", ls=":", lw=1)
    ax.set_xscale("symlog", linthresh=1)
    ax.set_xlim(left=0)
    ax.set_xticks(ks, [str(k) for k in ks])
    ax.set_xlabel("worlds learned k (symlog)")
    ax.set_ylabel("paired ratio t_context / t_baseline (geometric mean)")
    ax.set_title(
        f"learning curve: {doc['style']}, {doc['episodes']} paired episodes, detector "
        f"{doc['detector']}",
        fontsize=10,
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)


CURVE_COLUMNS = ("k", "examinations", "measured_at_k", *RESULT_COLUMNS)


def curve_rows(points: list[CurvePoint], scenarios: tuple[Scenario, ...]):
    """curve.csv's rows (CURVE_COLUMNS)."""
    for p in points:
        for sc in scenarios:
            runs = [(p, sc.context, "context"), (points[0], sc.baseline, "baseline"),
                    (points[0], sc.asymptote, "asymptote")]  # fmt: skip
            for src, policy, role in runs:
                for row in result_rows(sc, src.results[sc.name], policy, role):
                    yield {"k": p.k, "examinations": p.examinations, "measured_at_k": src.k, **row}


def write_files(
    out: Path, doc: dict, table: str, points: list[CurvePoint], scenarios: tuple[Scenario, ...]
) -> list[Path]:
    """Write curve.json, curve.md, curve.png and curve.csv; their paths."""
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "curve.json", out / "curve.md", out / "curve.png"]
    files[0].write_text(json.dumps(doc, indent=1) + "\n")
    files[1].write_text(
        f"# Learning curve: {doc['style']}\n\nOne learning run (seed {doc['seed']}, "
        f"{doc['learning_perception']} perception) snapshotted after k worlds; detector "
        f"`{doc['detector']}`, {doc['interval']} intervals.\n\n{table}\n"
    )
    plot_curve(doc, files[2])
    files.append(write_csv(out / "curve.csv", CURVE_COLUMNS, curve_rows(points, scenarios)))
    return files
