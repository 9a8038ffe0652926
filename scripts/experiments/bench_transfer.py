"""``bench transfer``: context that does not fit (the paper's own example).

A store is learned per style (the same rooms, seed and perception; the styles' learning runs are
the units of a sweep: serial, or Ray tasks with ``--workers N``). Then, for every searched-in
style and scenario, ``bench search`` runs the no-context baseline once and the context policy
with each style's store on the same held-out episodes of the searched-in style, with each
interval method (``wilson``, ``clustered``). The paired ratio (``scripts.experiments.scenarios``)
of the context policy to the baseline fills a learned-in x searched-in table; the paired ratio
of mismatched to in-domain context says what the mismatch costs.

Can the robot notice? After the knowledge, a small *probe* is learned in every style (other
rooms: seed + 1, ``probe_rooms`` worlds), what the robot would observe in its first rooms of a
new place. For a (learned-in, probed-in) pair and an interval method: of the (reference type,
relation, type) entries that either has seen (reference types examined in both), the share
whose learned interval excludes the frequency observed in the probe (``excluded_share``), the
share whose interval is disjoint from the probe's own interval (``disjoint_share``), and the
share of probe examinations of reference types the store never examined
(``unknown_type_share``). In-domain pairs give the false-alarm level.

Writes ``DIR/transfer.json``, ``DIR/transfer.md`` and ``DIR/transfer.csv`` (one row per learned-in,
searched-in, interval, scenario, episode and policy; the baseline's rows once per searched-in
style, with no learned-in style and interval); stores in ``DIR/stores/`` (an earlier run's
there are an error, never overwritten), every search's files
in ``DIR/search/LEARNED_to_SEARCHED/MAP/INTERVAL/``. With ``--journal DIR`` (scripts.journal)
the learning runs and the searches' units are kept in DIR and read back by the same command run
again (the stores are then written again from the journal's bytes).
"""

from __future__ import annotations

import functools
import json
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from ctxsearch.agent.learning import LearnConfig, learn
from ctxsearch.agent.search.config import SearchConfig, to_dict
from ctxsearch.agent.search.draw import remembered_draws
from ctxsearch.agent.search.measures import geo_cell
from ctxsearch.envs.houses import resolve_style
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.experiments.bench_curve import snapshot
from ctxsearch.scripts.experiments.bench_search import BenchResult
from ctxsearch.scripts.experiments.journals import learn_journal
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
from ctxsearch.scripts.sweep import SweepOptions, run_units, session

INTERVALS = ("wilson", "clustered")
PROBE_SEED_OFFSET = 1  # the probe's learning seed: seed + 1 (other rooms than the knowledge's)


@dataclass(frozen=True)
class TransferConfig:
    """What ``bench transfer`` learns and searches. ``search`` holds the search settings (seed,
    budget, detector, episodes); style, policies, kb and interval are set per cell."""

    search: SearchConfig
    styles: tuple[str, ...]
    rooms: int
    scenarios: tuple[Scenario, ...]
    intervals: tuple[str, ...] = INTERVALS
    probe_rooms: int = 2
    perception: str = "camera"


@dataclass
class TransferResult:
    """What ``bench_transfer`` produced."""

    doc: dict
    table: str
    files: list[Path] = field(default_factory=list)
    wall_s: float = 0.0


def _slug(style: str) -> str:
    """A style (a name or a TOML path) as a file name."""
    return Path(style).stem


def learn_unit(perception: str, detector: str | None, unit: tuple[str, int, int]) -> dict:
    """A sweep unit: learn ``unit`` = (style, rooms, seed) in a fresh store; its examinations
    and the store's bytes (plain data: the unit may run on another machine)."""
    style, rooms, seed = unit
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "kb.sqlite"
        lc = LearnConfig(style=style, rooms=rooms, kb_path=path, seed=seed,
                         perception=perception, detector=detector, progress=False)  # fmt: skip
        summary = learn(lc)
        if summary.interrupted:
            raise KeyboardInterrupt
        copy = Path(tmp) / "copy.sqlite"
        snapshot(path, copy)  # one self-contained file, whatever the journal left beside it
        return {"examinations": summary.total_examinations, "store": copy.read_bytes()}


def check_config(config: TransferConfig) -> None:
    """One-line errors for bad styles, counts, intervals or policies (before any learning)."""
    catalog = load_catalog()
    if len(config.styles) < 2:
        raise CtxsearchError("--styles: give at least two styles")
    if len(set(config.styles)) != len(config.styles):
        raise CtxsearchError("--styles: a style is listed twice")
    for s in config.styles:
        resolve_style(s, catalog)
    if config.rooms < 1:
        raise CtxsearchError(f"--rooms: expected a positive integer, got {config.rooms}")
    for m in config.intervals:
        if m not in INTERVALS:
            raise CtxsearchError(f"--intervals: unknown '{m}' (known: {', '.join(INTERVALS)})")
    if not config.intervals:
        raise CtxsearchError("--intervals: give at least one interval method")
    config.search.detector_model(catalog)
    check_policies(config.scenarios)


def learn_stores(
    config: TransferConfig, stores: Path, sweep: SweepOptions, bar: bool
) -> dict[str, dict]:
    """Learn the knowledge and the probe of every style (sweep units); {style: {"store", "probe",
    "examinations", "probe_examinations"}}."""
    seed = config.search.seed
    units = [(s, config.rooms, seed) for s in config.styles]
    if config.probe_rooms > 0:
        units += [(s, config.probe_rooms, seed + PROBE_SEED_OFFSET) for s in config.styles]
    journal = None
    if sweep.journal is not None:
        what = ["bench transfer", config.perception, config.search.detector]
        journal = learn_journal(sweep.journal, what)
    done = run_units(
        functools.partial(learn_unit, config.perception, config.search.detector),
        units,
        workers=sweep.workers,
        ray_address=sweep.ray_address,
        desc="bench transfer: learning",
        progress=bar,
        journal=journal,
    )
    stores.mkdir(parents=True, exist_ok=True)
    out: dict[str, dict] = {s: {"probe": None, "probe_examinations": 0} for s in config.styles}
    for (style, _rooms, s), r in zip(units, done, strict=True):
        kind = "store" if s == seed else "probe"
        path = stores / (
            f"{_slug(style)}.sqlite" if kind == "store" else f"{_slug(style)}.probe.sqlite"
        )
        path.write_bytes(r["store"])
        out[style][kind] = path
        out[style]["examinations" if kind == "store" else "probe_examinations"] = r["examinations"]
    return out


def mismatch(learned: KnowledgeBase, probe: KnowledgeBase, probe_own: KnowledgeBase) -> dict:
    """How far the probe's evidence lies from the learned intervals (module docstring);
    ``probe_own`` is the probe read with the learned store's interval method."""
    entries = excluded = disjoint = probe_exams = unknown = 0
    for a in learned.catalog.type_names:
        n_p = probe.n(a)
        if n_p == 0:
            continue
        probe_exams += n_p
        if learned.n(a) == 0:
            unknown += n_p
            continue
        for rel, b in sorted(set(learned.nonzero(a)) | set(probe.nonzero(a))):
            lo, hi = learned.interval(rel, b)
            f = probe.y(rel, b) / n_p
            plo, phi = probe_own.interval(rel, b)
            entries += 1
            excluded += int(f < lo - 1e-12 or f > hi + 1e-12)
            disjoint += int(phi < lo - 1e-12 or plo > hi + 1e-12)
    return {
        "entries": entries,
        "excluded": excluded,
        "excluded_share": round(excluded / entries, 4) if entries else None,
        "disjoint": disjoint,
        "disjoint_share": round(disjoint / entries, 4) if entries else None,
        "probe_examinations": probe_exams,
        "unknown_type_share": round(unknown / probe_exams, 4) if probe_exams else None,
    }


def _read(path: Path, interval: str) -> KnowledgeBase:
    with EvidenceStore.open(path, load_catalog(), read_only=True) as st:
        return st.knowledge_base(interval=interval)


def noticing(config: TransferConfig, stores: dict[str, dict]) -> dict:
    """{interval: {learned-in: {probed-in: mismatch(...)}}} (empty without probes)."""
    if config.probe_rooms == 0:
        return {}
    out: dict = {}
    for m in config.intervals:
        out[m] = {}
        for x in config.styles:
            kb = _read(stores[x]["store"], m)
            out[m][x] = {
                y: mismatch(kb, _read(stores[y]["probe"], "wilson"), _read(stores[y]["probe"], m))
                for y in config.styles
            }
    return out


@dataclass
class Cell:
    """The searches in one searched-in style and scenario: the baseline's run and the context
    policy's per (learned-in style, interval)."""

    baseline: BenchResult
    context: dict[tuple[str, str], BenchResult] = field(default_factory=dict)


def search_cells(
    config: TransferConfig, stores: dict[str, dict], out: Path, sweep: SweepOptions, bar: bool
) -> dict[tuple[str, str], Cell]:
    """{(searched-in style, scenario): Cell}: every store's context on every style's episodes."""
    cells: dict[tuple[str, str], Cell] = {}
    for y in config.styles:
        others = [x for x in config.styles if x != y]
        for sc in config.scenarios:
            cell = None
            for m in config.intervals:
                for x in [y, *others]:
                    base = config.search.updated(
                        {"style": y, "knowledge.kb": stores[x]["store"], "knowledge.interval": m}
                    )
                    first = cell is None
                    pols = (sc.baseline, sc.context) if first else (sc.context,)
                    where = out / "search" / f"{_slug(x)}_to_{_slug(y)}" / sc.name / m
                    res = search(base, sc, where, policies=pols, sweep=sweep, bar=bar)
                    if first:
                        cell = Cell(res)
                    same_episodes(cell.baseline.episodes, res.episodes, f"{x} -> {y}, {sc.name}")
                    cell.context[(x, m)] = res
            cells[(y, sc.name)] = cell
    return cells


def bench_transfer(
    config: TransferConfig,
    out: Path | str,
    *,
    sweep: SweepOptions | None = None,
    bar: bool = True,
    progress=print,
) -> TransferResult:
    """The transfer benchmark (module docstring): learn, search, measure, write three files."""
    t0 = time.perf_counter()
    out = Path(out)
    sweep = sweep or SweepOptions()
    check_config(config)
    if sweep.journal is None:  # with a journal the stores are its learning units' bytes again
        check_no_stores(out / "stores")
    with session(sweep), remembered_draws():
        stores = learn_stores(config, out / "stores", sweep, bar)
        if progress is not None:
            progress("learned: " + ", ".join(f"{s} {v['examinations']} examinations"
                                             for s, v in stores.items()))  # fmt: skip
        cells = search_cells(config, stores, out, sweep, bar)
    doc = transfer_doc(config, stores, cells, noticing(config, stores))
    table = format_tables(doc)
    res = TransferResult(doc, table)
    res.files = write_files(out, doc, table, cells, config)
    res.wall_s = time.perf_counter() - t0
    return res


def transfer_doc(config: TransferConfig, stores: dict, cells: dict, notice: dict) -> dict:
    """transfer.json's content."""
    s = config.search
    ratios: dict = {}
    cost: dict = {}
    stats: dict = {}
    for sc in config.scenarios:
        stats[sc.name] = {m: {x: {} for x in config.styles} for m in config.intervals}
        ratios[sc.name] = {m: {x: {} for x in config.styles} for m in config.intervals}
        cost[sc.name] = {m: {x: {} for x in config.styles} for m in config.intervals}
        for y in config.styles:
            cell = cells[(y, sc.name)]
            tb = times(cell.baseline, sc.baseline)
            for m in config.intervals:
                t_in = times(cell.context[(y, m)], sc.context)
                for x in config.styles:
                    t = times(cell.context[(x, m)], sc.context)
                    ratios[sc.name][m][x][y] = paired_ratio(t, tb, seed=s.seed)
                    stats[sc.name][m][x][y] = paired(t, tb, seed=s.seed)
                    if x != y:
                        cost[sc.name][m][x][y] = paired_ratio(t, t_in, seed=s.seed)
    first = next(iter(cells.values())).baseline
    return {
        # the search configuration every cell starts from (each cell's search.json: its own)
        "search_config": to_dict(s),
        "styles": list(config.styles),
        "rooms": config.rooms,
        "probe_rooms": config.probe_rooms,
        "seed": s.seed,
        "episodes": len(first.episodes),
        "budget_s": s.budget_s,
        "detector": s.detector_model(load_catalog()).name,
        "learning_perception": config.perception,
        "failures_counted_at_budget": True,
        "stores": {
            x: {k: v for k, v in d.items() if k.endswith("examinations")} for x, d in stores.items()
        },  # fmt: skip
        "scenarios": {sc.name: sc.to_json() for sc in config.scenarios},
        # paired[map][interval][learned-in][searched-in]: context / baseline, the statistics
        # that can see a small effect (geometric mean, ratio of means, Wilcoxon, ties, power)
        "paired": stats,
        # paired_ratio[map][interval][learned-in][searched-in]: context / baseline (the median)
        "paired_ratio": ratios,
        # mismatched_to_in_domain[map][interval][learned-in][searched-in]: t(mismatched context)
        # / t(in-domain context), episode by episode
        "mismatched_to_in_domain": cost,
        # noticing[interval][learned-in][probed-in]
        "noticing": notice,
    }


def _fmt(r: dict) -> str:
    if r["median"] is None:
        return "-"
    return f"{r['median']:.2f} [{r['ci'][0]:.2f}, {r['ci'][1]:.2f}] ({r['wins']}/{r['losses']})"


def format_tables(doc: dict) -> str:
    """transfer.md's tables: per scenario and interval, learned-in rows x searched-in columns;
    then the mismatch measures."""
    styles = doc["styles"]
    lines = []
    # The geometric mean leads (the search benchmark's statistics); a document written before
    # transfer.json had its ``paired`` grid shows the medians.
    key, cell = ("paired", geo_cell) if "paired" in doc else ("paired_ratio", _fmt)
    for name, sc in doc["scenarios"].items():
        for m, grid in doc[key][name].items():
            lines += [f"### {name} map, {m} intervals: {sc['context']} / {sc['baseline']}", ""]
            lines += ["| learned in \\ searched in | " + " | ".join(styles) + " |"]
            lines += ["|---|" + "---|" * len(styles)]
            lines += [f"| {x} | " + " | ".join(cell(grid[x][y]) for y in styles) + " |"
                      for x in styles]  # fmt: skip
            lines.append("")
    if doc["noticing"]:
        lines += [f"### Noticing the mismatch ({doc['probe_rooms']} probe worlds per style)", ""]
        lines += ["| interval | learned in | probed in | excluded share | disjoint share | "
                  "unknown-type share |", "|---|---|---|---|---|---|"]  # fmt: skip
        for m, per in doc["noticing"].items():
            for x, row in per.items():
                for y, d in row.items():
                    lines.append(
                        f"| {m} | {x} | {y} | {d['excluded_share']} ({d['excluded']}/"
                        f"{d['entries']}) | {d['disjoint_share']} | {d['unknown_type_share']} |"
                    )
        lines.append("")
    what = (
        "the geometric mean over episodes of t_context / t_baseline [95% bootstrap interval] "
        "wins/losses/ties and the signed-rank p (the medians: transfer.json's paired_ratio)"
        if key == "paired"
        else "the median over episodes of t_context / t_baseline [95% bootstrap interval] "
        "(episodes won / lost)"
    )
    lines.append(
        f"{doc['episodes']} paired episodes per searched-in style; cells: {what}; a failure "
        f"counted at the budget ({doc['budget_s']:.0f} s)."
    )
    return "\n".join(lines)


TRANSFER_COLUMNS = ("learned_in", "searched_in", "interval", *RESULT_COLUMNS)


def transfer_rows(cells: dict[tuple[str, str], Cell], config: TransferConfig):
    """transfer.csv's rows (TRANSFER_COLUMNS)."""
    by_name = {sc.name: sc for sc in config.scenarios}
    for (y, name), cell in cells.items():
        sc = by_name[name]
        for row in result_rows(sc, cell.baseline, sc.baseline, "baseline"):
            yield {"learned_in": None, "searched_in": y, "interval": None, **row}
        for (x, m), res in cell.context.items():
            for row in result_rows(sc, res, sc.context, "context"):
                yield {"learned_in": x, "searched_in": y, "interval": m, **row}


def write_files(
    out: Path, doc: dict, table: str, cells: dict, config: TransferConfig
) -> list[Path]:
    """Write transfer.json, transfer.md and transfer.csv; their paths."""
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "transfer.json", out / "transfer.md"]
    files[0].write_text(json.dumps(doc, indent=1) + "\n")
    files[1].write_text(
        f"# Context transfer: {', '.join(doc['styles'])}\n\nA store per style ({doc['rooms']} "
        f"worlds, seed {doc['seed']}, {doc['learning_perception']} perception); detector "
        f"`{doc['detector']}`.\n\n{table}\n"
    )
    files.append(write_csv(out / "transfer.csv", TRANSFER_COLUMNS, transfer_rows(cells, config)))
    return files
