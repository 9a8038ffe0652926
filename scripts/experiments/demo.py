"""The end-to-end demo (``ctxsearch demo``, what ``make demo`` runs).

1. Learn: the robot learns spatial context on its own (Figure 2, Highest Impact First) in a few
   office rooms, writing ``OUT/kb.sqlite`` and the rerun recording ``OUT/learn.rrd`` (one
   recording of the whole run, room after room on the run clock). Perception is the rendered camera
   (segmentation + detector), which takes about a minute for four rooms on a 2-core CPU
   (``--perception oracle`` reads relations from the layout instead, for a faster run).
2. Search: in an office room it never learned in (held-out seed), from the same start pose, it
   looks for the same target (default ``Cup``) twice on its own map (``--map built``: it knows
   nothing of the room at the start and maps it as it searches): with context (``indirect``: the
   learned intervals rank the relation volumes of the furniture it has detected, and say which
   intermediate types are worth looking for first) and without (``frontier``: the field's
   no-context baseline, information gain per expected second).
   Recording: ``OUT/search.rrd``, both searches side by side on the same simulated seconds.
3. Report: ``OUT/report.md`` (what was learned, the two searches side by side, how to open the
   recordings), and a short summary on the terminal.

Re-running: if ``OUT/kb.sqlite`` already holds the demo's learning run with all its rooms done
(and its recording exists), learning is skipped and the store reused; otherwise the store and
the learning recordings are deleted and learning starts over. The searches and the report are
always redone (they take seconds) and overwrite their files.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

from ctxsearch.agent.learning import LearnConfig, learn, room_seed, run_id
from ctxsearch.agent.mapping import default_map_mode
from ctxsearch.agent.perception_modes import perception_label
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.agent.search.episode import SearchResult, check_target
from ctxsearch.agent.search.priors import KnowledgeSource, open_knowledge
from ctxsearch.agent.search.runner import OneSearch, search_once
from ctxsearch.envs.detector import DetectorModel
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import PerceptionMode
from ctxsearch.knowledge.store import EvidenceStore

DEMO_STYLE = "office"
DEMO_TARGET = "Cup"
DEMO_STRATEGY = "hif"
DEMO_SEED = 0
DEMO_BUDGET_S = 300.0
QUICK_BUDGET_S = 120.0
QUICK_ROOMS = 2
CONTEXT_POLICY = "indirect"
BASELINE_POLICY = "frontier"
DEMO_MAP = "built"


@dataclass(frozen=True)
class DemoConfig:
    """What ``ctxsearch demo`` is asked to do (its flags)."""

    out: Path = Path("demo")
    rooms: int = 4
    quick: bool = False  # at most QUICK_ROOMS learning rooms and a QUICK_BUDGET_S search budget
    perception: str = "camera"
    target: str = DEMO_TARGET
    progress: bool = True

    @property
    def learning_rooms(self) -> int:
        """The rooms the demo learns in."""
        return min(self.rooms, QUICK_ROOMS) if self.quick else self.rooms

    @property
    def budget_s(self) -> float:
        """The search budget in simulated seconds."""
        return QUICK_BUDGET_S if self.quick else DEMO_BUDGET_S


@dataclass
class DemoResult:
    """What the demo did and wrote."""

    learn_lines: list[str]
    learned_now: bool
    lines: list[str]
    files: list[Path] = field(default_factory=list)
    wall_s: float = 0.0


@dataclass
class _Learned:
    """The outcome of the learning step."""

    lines: list[str]
    files: list[Path]  # its rerun recordings
    now: bool  # False: a complete store from an earlier run was reused


@dataclass
class _Searched:
    """The outcome of the search step: the two searches and their recordings."""

    one: OneSearch
    kb: KnowledgeBase
    record: Path  # both searches side by side

    @property
    def ratio(self) -> float:
        """Time to find with context over time without (NaN if that is 0)."""
        ctx_res, exh_res = self.one.results
        if exh_res.time_to_find > 0:
            return ctx_res.time_to_find / exh_res.time_to_find
        return math.nan


def _demo_detector(perception: str) -> DetectorModel | None:
    """The detector the demo learns with (camera mode's default; None for the oracle)."""
    return LearnConfig(DEMO_STYLE, 0, "", perception=perception).detector_model(load_catalog())


def _learning_complete(kb_path: Path, rooms: int, perception: str) -> bool:
    """True if the store at ``kb_path`` holds the demo's run with ``rooms`` rooms done."""
    if not kb_path.is_file():
        return False
    try:
        with EvidenceStore.open(kb_path, load_catalog(), create=False) as store:
            label = perception_label(perception, _demo_detector(perception))
            rid = run_id(DEMO_STRATEGY, label, DEMO_SEED, None, default_map_mode(perception))
            return all(
                store.room_status(rid, DEMO_STYLE, room_seed(DEMO_SEED, i)) == "done"
                for i in range(rooms)
            )
    except CtxsearchError:
        return False


def run_demo(config: DemoConfig, echo=print) -> DemoResult:
    """Learn, search with and without context, write the report (module docstring)."""
    t0 = time.perf_counter()
    out = config.out
    out.mkdir(parents=True, exist_ok=True)
    catalog = load_catalog()
    check_target(catalog, config.target)
    learned = _learn_step(config, echo)
    searched = _search_step(config, catalog, echo)
    report = out / "report.md"
    report.write_text(_report(config, learned, searched))
    search_rrd = searched.record
    ctx_res, exh_res = searched.one.results
    ratio = searched.ratio
    files = [out / "kb.sqlite", *learned.files, search_rrd, report]
    lines = [
        f"with context ({CONTEXT_POLICY}): {_outcome(ctx_res)}",
        f"without context ({BASELINE_POLICY}): {_outcome(exh_res)}",
        f"time with context / without: {ratio:.2f}" if math.isfinite(ratio) else "time ratio: n/a",
        f"report: {report}",
        "open the recordings with:",
        f"  rerun {' '.join(str(f) for f in learned.files)}",
        f"  rerun {search_rrd}",
    ]
    echo("[3/3] done")
    for line in lines:
        echo(line)
    return DemoResult(learned.lines, learned.now, lines, files, time.perf_counter() - t0)


def _learn_step(config: DemoConfig, echo) -> _Learned:
    """1. Learn in the demo's rooms, or reuse a complete store of an earlier run."""
    out, rooms, perception, progress = (
        config.out,
        config.learning_rooms,
        config.perception,
        config.progress,
    )
    kb_path = out / "kb.sqlite"
    learn_rrd = out / "learn.rrd"
    learned_now = not (_learning_complete(kb_path, rooms, perception) and learn_rrd.is_file())
    if learned_now:
        stale = [*out.glob("learn*.rrd"), out / "search_exhaustive.rrd"]  # earlier versions' files
        for p in [kb_path, *out.glob("kb.sqlite-*"), *stale]:
            p.unlink(missing_ok=True)
        echo(
            f"[1/3] learning in {rooms} {DEMO_STYLE} rooms ({perception} perception, strategy {DEMO_STRATEGY})"
        )
        s = learn(
            LearnConfig(
                DEMO_STYLE,
                rooms,
                kb_path,
                strategy=DEMO_STRATEGY,
                perception=perception,
                seed=DEMO_SEED,
                record=learn_rrd,
                progress=progress,
            )
        )
        if s.interrupted:
            raise KeyboardInterrupt
        learn_lines = s.lines()
        learn_files = [Path(f) for f in s.files]
    else:
        echo(
            f"[1/3] reusing {kb_path}: its {rooms} learning rooms are done (delete {out}/ to learn again)"
        )
        learn_lines = [f"reused {kb_path} ({rooms} rooms learned earlier)"]
        learn_files = [learn_rrd]
    for line in learn_lines:
        echo(f"      {line}")
    return _Learned(learn_lines, learn_files, learned_now)


def _search_step(config: DemoConfig, catalog: Catalog, echo) -> _Searched:
    """2. Two searches, same held-out room, start and target: with context and without."""
    out, target = config.out, config.target
    kb, learned_seeds = open_knowledge(out / "kb.sqlite", catalog)
    search_rrd = out / "search.rrd"
    echo(
        f"[2/3] searching for a {target} in a held-out {DEMO_STYLE} room on its own map: with "
        f"context ({CONTEXT_POLICY}) and without ({BASELINE_POLICY})"
    )
    search = SearchConfig(
        DEMO_STYLE, (CONTEXT_POLICY, BASELINE_POLICY), seed=DEMO_SEED, budget_s=config.budget_s
    ).with_scenario(DEMO_MAP)
    source = KnowledgeSource(kb, frozenset(learned_seeds))
    one = search_once(search, target, source=source, catalog=catalog, record=search_rrd)
    for r in one.results:
        echo(f"      {r.summary()}")
    return _Searched(one, kb, search_rrd)


def _outcome(r: SearchResult) -> str:
    if r.success:
        return f"found {r.target} #{r.found_id} in {r.sim_time:.1f} simulated s, {r.gazes} gazes, {r.path_m:.1f} m"
    return f"no {r.target} within {r.budget_s:.0f} simulated s ({r.gazes} gazes, {r.path_m:.1f} m)"


def _report(config: DemoConfig, learned: _Learned, searched: _Searched) -> str:
    """report.md: what was learned, the two searches side by side, how to open the recordings."""
    lines = [
        "# ctxsearch demo",
        "",
        *_report_learning(config, learned, searched.kb),
        *_report_search(config, searched),
        "## 3. Recordings",
        "",
        "```",
        f"rerun {' '.join(str(f) for f in learned.files)}   # the learning run, room after room",
        f"rerun {searched.record}   # with context ({CONTEXT_POLICY}, left) and without "
        f"({BASELINE_POLICY}, right): ranked candidate regions, path, every camera view",
        "```",
        "",
    ]
    return "\n".join(lines)


def _report_learning(config: DemoConfig, learned: _Learned, kb: KnowledgeBase) -> list[str]:
    """Section 1 of report.md: the learning run and what it learned about the target."""
    target, perception = config.target, config.perception
    rows = sorted(
        (r for r in kb.rows() if r.type == target and r.n > 0), key=lambda r: (-r.p0, r.relation)
    )[:8]
    why = (
        "rendered segmentation and the detector (the robot only knows what it saw)"
        if perception == PerceptionMode.CAMERA
        else "relations read from the layout (no rendering; faster, for large runs)"
    )
    return [
        "## 1. Learning (Highest Impact First)",
        "",
        f"{config.learning_rooms} {DEMO_STYLE} rooms, strategy `{DEMO_STRATEGY}`, perception `{perception}`: {why}."
        + ("" if learned.now else " (Store reused from an earlier run of the demo.)"),
        "",
        *[f"- {line}" for line in learned.lines],
        "",
        f"What it learned about where a {target} is (the 8 most likely relations with evidence; 90% Wilson "
        "intervals):",
        "",
        "| relation | y / n | p0 | interval |",
        "|---|---|---|---|",
        *[
            f"| {r.relation}({target}) | {r.y} / {r.n} | {r.p0:.2f} | [{r.low:.2f}, {r.high:.2f}] |"
            for r in rows
        ],
        "",
    ]


def _report_search(config: DemoConfig, searched: _Searched) -> list[str]:
    """Section 2 of report.md: the room, the two searches, how the one with context went."""
    ep, ratio = searched.one.episode, searched.ratio
    ctx_res, exh_res = searched.one.results
    return [
        "## 2. Search in a room it never learned in",
        "",
        f"Room: {ep.style} seed {ep.room_seed} (held out); start ({ep.start.x:.2f}, {ep.start.y:.2f}), heading "
        f"{ep.start.yaw:.2f} rad; target: {config.target}; budget {ep.budget_s:.0f} simulated s.",
        "",
        "| search | found | simulated s | gazes | metres driven |",
        "|---|---|---|---|---|",
        *[
            f"| {r.policy} | {'yes' if r.success else 'no'} | {r.sim_time:.1f} | {r.gazes} | {r.path_m:.1f} |"
            for r in (ctx_res, exh_res)
        ],
        "",
        (
            f"With context the robot needed {ratio:.2f} times the time it needed without."
            if math.isfinite(ratio)
            else ""
        ),
        "One episode is an anecdote: `ctxsearch bench search` measures the difference over many paired "
        "episodes (see the README).",
        "",
        f"How the search with context went (`{CONTEXT_POLICY}` on the map it builds (`--map "
        f"{DEMO_MAP}`): the intervals' `{ss.DEFAULT_RANK}` ranks the relation volumes of the "
        "furniture detected so far, per expected second, against exploring for the target and "
        "for intermediate types):",
        "",
        "```",
        *ctx_res.log[:30],
        "```",
        "",
    ]
