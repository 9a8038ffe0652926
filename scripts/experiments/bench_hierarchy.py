"""The type hierarchy's backoff against the paper's flat intervals (``ctxsearch bench hierarchy``).

Two questions, on one style (``--style S``):

1. **Estimates with little evidence.** The robot learns ``rooms`` rooms of S (Figure 2 with
   ``hif``, oracle perception: fast, and the same evidence a camera run collects in kind). Then
   each concrete type A in a class with at least max(k) examinations is *held* to k = 0, 1, 3, 5,
   10 of its examinations (``draws`` random subsets, seeded) while every other type keeps all of
   its own; A's entries (A, rel, B) for the relations that map onto a relation of A's class, and
   every concrete B, are compared with the ground truth p_true (``envs.truth`` over
   ``truth_samples`` rooms of S):

   - ``abs_error``: mean |estimate - p_true| over those entries, the estimate being the Wilson
     centre p0 of the interval (the value ``--rank p0`` searches by): flat p0(y, k), backoff
     p0(y + kappa p_C, k + kappa) (knowledge.pooling.Backoff).
   - ``coverage``: coverage_informative, the share of the informative entries whose interval
     holds p_true; informative: 0.02 <= p_true <= 0.98 and the type examined at least once. At
     k = 0 the held type has no examination of its own; its entries count as informative where
     the *full* evidence has one (every evaluated type does), so the flat interval [0, 1] covers
     them all trivially (1.0) and the backoff's coverage says how honest the class's borrowed
     interval is.

2. **Search around a never-seen furniture type.** A Workbench is added to the catalog for this
   experiment only (never to ``assets/types.toml``: that would change every store's catalog
   fingerprint): shape ``table``, its relation volumes those of S's main work surface (the
   WorkSurface member S has most of; Desk in an office), renamed, and a member of WorkSurface.
   The robot learns in S, which holds no Workbench (n = 0); held-out episodes are drawn in a
   variant of S whose main work surface is replaced by workbenches (rules and all). ``location``
   searches every episode twice from the same start (agent.search, the project's episode runner,
   paired and seeded): with the flat intervals (a Workbench's lower bounds are 0, so its
   volumes are never candidates) and with ``--estimate backoff`` (types with fewer than
   ``min_evidence`` examinations read their class's backoff). Reported: success, median / mean
   simulated seconds (failures at the budget), the search benchmark's paired statistics of
   backoff against flat (``paired_stats``: the geometric mean of the time ratio with its
   interval, wins/losses/ties, the signed-rank test, the episodes for 80% power), the paired
   differences (flat - backoff) with a bootstrap 95% interval of their mean, and how many
   episodes each was faster. ``--episodes 0`` skips the search. The control
   (``search_control``): the same pair on held-out rooms of S itself, where no type is new.

Also measured, along the way: at every choice of the ``hif`` learning run, whether
``hif-backoff`` (agent.strategies: impact on the backed-off pseudo-counts) would have chosen the
same type from the same knowledge and candidates.

Writes DIR/hierarchy.json, DIR/hierarchy.md and DIR/hierarchy.png, and the per-unit rows as
DIR/hierarchy.csv (per reference type and k) and DIR/hierarchy_search.csv (per episode and
estimate).
"""

from __future__ import annotations

import copy
import json
import math
import tempfile
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ctxsearch.agent.learning import LearnConfig, learn
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.agent.search.draw import DrawSpec, make_episodes
from ctxsearch.agent.search.episode import DEFAULT_BUDGET_S, SearchResult
from ctxsearch.agent.search.measures import bootstrap_ci, geo_cell, paired_stats
from ctxsearch.agent.search.priors import make_priors
from ctxsearch.agent.search.registry import resolve
from ctxsearch.agent.search.runner import PolicyRun, WorldRuns, search_world
from ctxsearch.agent.strategies import BackoffHIF, Choice
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.styles import Style, parse_style
from ctxsearch.envs.truth import ground_truth
from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import DEFAULT_CATALOG, Catalog, load_catalog, parse_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.pooling import Backoff, PooledCounts
from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.experiments.bench_search import aggregate
from ctxsearch.scripts.experiments.tables import write_csv

NEW_TYPE = "Workbench"
NEW_SHAPE = "table"
NEW_COLOR = [0.42, 0.45, 0.50]
WORK_CLASS = "WorkSurface"
KS = (0, 1, 3, 5, 10)
INFORMATIVE = (0.02, 0.98)
SEARCH_POLICY = "location"

Exam = tuple[str, list[tuple[str, str]]]


@dataclass(frozen=True)
class HierarchyBenchConfig:
    """What ``bench hierarchy`` learns from, holds back and searches."""

    style: str = "office"
    rooms: int = 20  # learning rooms (oracle perception)
    truth_samples: int = 200
    episodes: int = 20  # paired search episodes in the Workbench variant
    ks: tuple[int, ...] = KS
    draws: int = 5  # random subsets of a held type's examinations per k
    seed: int = 0
    budget_s: float = DEFAULT_BUDGET_S
    rank: str = ss.DEFAULT_RANK
    min_evidence: int = ss.DEFAULT_MIN_EVIDENCE


# =========================================================================== the new type
def main_work_surface(style: Style, catalog: Catalog) -> str:
    """The WorkSurface member ``style`` has most of (largest maximum count; ties: class order)."""
    members = catalog.hierarchy.get(WORK_CLASS).types
    counts = {t: c[1] for t, c in style.furniture if t in members and c[1] > 0}
    if not counts:
        raise CtxsearchError(
            f"style '{style.name}' has no work surface ({', '.join(members)}) to replace by a "
            f"{NEW_TYPE}"
        )
    return max(members, key=lambda t: (counts.get(t, 0), -members.index(t)))


def _renamed(rel: str, model: str) -> str:
    return rel[: -len(model)] + NEW_TYPE.upper()


def extended_catalog(model: str, path: Path = DEFAULT_CATALOG) -> Catalog:
    """The catalog at ``path`` plus a Workbench: ``model``'s size, relation volumes (renamed)
    and class maps, shape ``table``, a member of ``model``'s class."""
    with open(path, "rb") as f:
        doc = tomllib.load(f)
    raw = next(t for t in doc["type"] if t["name"] == model)
    new = copy.deepcopy(raw)
    new.update(name=NEW_TYPE, shape=NEW_SHAPE, color=NEW_COLOR)
    for r in new.get("relation", []):
        r["name"] = _renamed(r["name"], model.upper())
    doc["type"].append(new)
    for c in doc.get("class", []):
        if model in c.get("types", []):
            c["types"].append(NEW_TYPE)
            maps = c.setdefault("maps", {})
            for src, dst in list(maps.items()):
                if src.endswith("-" + model.upper()):
                    maps[_renamed(src, model.upper())] = dst
    return parse_catalog(doc, f"{path} + {NEW_TYPE}")


def workbench_style(style: Style, model: str, catalog: Catalog) -> Style:
    """``style`` with every ``model`` replaced by a Workbench (furniture, rules and relations)."""
    with open(style.path, "rb") as f:
        doc = tomllib.load(f)
    doc = copy.deepcopy(doc)
    doc["furniture"] = {
        (NEW_TYPE if t == model else t): c for t, c in doc.get("furniture", {}).items()
    }
    for r in doc.get("rule", []):
        for key in ("ref", "type"):
            if r.get(key) == model:
                r[key] = NEW_TYPE
        if r.get("ref") == NEW_TYPE:
            r["relation"] = _renamed(r["relation"], model.upper())
    name = f"{style.name}-{NEW_TYPE.lower()}"
    doc["name"] = name
    doc["description"] = f"{style.name} with its {model}s replaced by {NEW_TYPE}s (held out)"
    return parse_style(doc, style.path, catalog, name=name)


# =========================================================================== estimates
def _truth_table(doc: dict) -> tuple[dict[tuple[str, str, str], float], dict[str, int]]:
    p = {(e["ref"], e["relation"], e["type"]): float(e["p"]) for e in doc["entries"]}
    n = {e["ref"]: int(e["n"]) for e in doc["entries"]}
    return p, n


def evaluated_types(catalog: Catalog, exams: Sequence[Exam], k_max: int) -> list[str]:
    """Concrete types in a class with at least ``k_max`` examinations (catalog order)."""
    h = catalog.hierarchy
    n: dict[str, int] = {}
    for t, _ in exams:
        n[t] = n.get(t, 0) + 1
    return [
        t
        for t in catalog.type_names
        if h.parent(t) is not None and n.get(t, 0) >= max(k_max, 1)
        and any(h.lift(r) for r in catalog.type(t).relation_names)
    ]  # fmt: skip


def _entries(catalog: Catalog, ref: str, p_true: dict) -> list[tuple[str, str, float]]:
    """(relation, B, p_true) of ``ref``'s entries whose relation maps onto its class's."""
    h = catalog.hierarchy
    return [
        (rel, b, p_true[(ref, rel, b)])
        for rel in catalog.type(ref).relation_names
        if h.lift(rel) is not None
        for b in catalog.type_names
        if (ref, rel, b) in p_true
    ]


@dataclass
class _Tally:
    err: list[float]
    covered: list[bool]

    def add(self, est: float, lo: float, hi: float, p: float) -> None:
        self.err.append(abs(est - p))
        if INFORMATIVE[0] <= p <= INFORMATIVE[1]:
            self.covered.append(bool(lo - 1e-12 <= p <= hi + 1e-12))


def held_out_errors(
    catalog: Catalog,
    exams: Sequence[Exam],
    p_true: dict[tuple[str, str, str], float],
    config: HierarchyBenchConfig,
) -> dict:
    """Mean |p0 - p_true| and coverage_informative, flat and backoff, per k (module docstring)."""
    alpha = intervals.DEFAULT_ALPHA
    types = evaluated_types(catalog, exams, max(config.ks))
    rng = np.random.default_rng([config.seed, 0x41E7])
    out: dict = {"k": list(config.ks), "types": types, "per_type": {}}
    for key in ("abs_error_flat", "abs_error_backoff", "coverage_flat", "coverage_backoff"):
        out[key] = []
    tallies = {(k, m, t): _Tally([], []) for k in config.ks for m in (0, 1) for t in types}
    for t in types:
        own = [i for i, (ref, _) in enumerate(exams) if ref == t]
        rest = [e for e in exams if e[0] != t]
        entries = _entries(catalog, t, p_true)
        for k in config.ks:
            for _ in range(config.draws if 0 < k < len(own) else 1):
                keep = sorted(rng.choice(own, size=k, replace=False)) if k else []
                pooled = PooledCounts.from_examinations(
                    catalog.hierarchy, [*rest, *(exams[i] for i in keep)]
                )
                bo = Backoff(pooled, alpha)
                for rel, b, p in entries:
                    y = pooled.y.get((t, rel, b), 0)
                    lo, hi = intervals.interval(y, k, alpha)
                    tallies[(k, 0, t)].add(float(intervals.p0(y, k, alpha)), lo, hi, p)
                    y_eff, n_eff, _, _ = bo.pseudo_counts(t, rel, b)
                    lo, hi = intervals.interval(y_eff, n_eff, alpha)
                    tallies[(k, 1, t)].add(float(intervals.p0(y_eff, n_eff, alpha)), lo, hi, p)
    for k in config.ks:
        for m, name in ((0, "flat"), (1, "backoff")):
            err = [e for t in types for e in tallies[(k, m, t)].err]
            cov = [c for t in types for c in tallies[(k, m, t)].covered]
            out[f"abs_error_{name}"].append(_mean(err))
            out[f"coverage_{name}"].append(_mean(cov))
    ents = {t: _entries(catalog, t, p_true) for t in types}
    out["entries"] = sum(len(e) for e in ents.values())  # distinct (A, rel, B), one draw
    out["informative_entries"] = sum(
        1 for e in ents.values() for _, _, p in e if INFORMATIVE[0] <= p <= INFORMATIVE[1]
    )
    for t in types:
        out["per_type"][t] = {
            f"{what}_{name}": [_mean(_tally_values(tallies[(k, m, t)], what)) for k in config.ks]
            for what in ("abs_error", "coverage")
            for m, name in ((0, "flat"), (1, "backoff"))
        }
    return out


def _tally_values(t: _Tally, what: str) -> list:
    """A tally's errors (``abs_error``) or coverage flags (``coverage``)."""
    return t.err if what == "abs_error" else t.covered


def _mean(xs: Sequence[float | bool]) -> float:
    return float(np.mean(xs)) if len(xs) else math.nan


# =========================================================================== HIF with backoff
@dataclass
class ChoiceAgreement:
    """At each of a run's choices: would ``hif-backoff`` have chosen the same type?"""

    choices: int = 0
    same: int = 0

    def __call__(self, kb: KnowledgeBase, choice: Choice) -> None:
        order = [t for t in kb.catalog.type_names if t in choice.scores]
        backoff = Backoff(PooledCounts.from_knowledge_base(kb), kb.alpha)
        scores = {t: BackoffHIF.type_score(kb, backoff, t) for t in order}
        best = max(order, key=lambda t: (scores[t], -order.index(t)))
        self.choices += 1
        self.same += int(best == choice.type)


# =========================================================================== search
def paired_search(
    config: HierarchyBenchConfig,
    variant: Style,
    catalog: Catalog,
    kb_path: Path,
    progress: Callable[[str], None] | None = None,
) -> dict:
    """``location`` flat vs backoff on paired episodes of ``variant`` (module docstring)."""
    sc = SearchConfig(
        style=variant.name, policies=(SEARCH_POLICY,), seed=config.seed, budget_s=config.budget_s
    ).updated({
        "knowledge.kb": kb_path, "knowledge.rank": config.rank, "knowledge.estimate": "backoff",
        "knowledge.min_evidence": config.min_evidence, "map.scenario": "given",
    })  # fmt: skip
    (policy,) = resolve(sc.policies, sc.scenario)
    priors = make_priors((policy,), variant, catalog, sc.knowledge)
    rooms = len(priors.learned) or None
    probs = {
        "flat": ss.KBProbabilities(priors.kb, config.rank, rooms=rooms),
        "backoff": priors.for_policy(policy),
    }
    spec = DrawSpec.make(
        variant, config.episodes, config.seed, catalog, config.budget_s, priors.learned
    )
    eps = make_episodes(spec, catalog)
    results: dict[str, list[SearchResult]] = {m: [] for m in probs}
    for ep in eps:
        runs = WorldRuns(tuple(PolicyRun(policy, p) for p in probs.values()), sc)
        for m, res in zip(probs, search_world(ep, variant, catalog, runs), strict=True):
            res.policy = f"{SEARCH_POLICY} ({m})"
            results[m].append(res)
            if progress is not None:
                progress(f"episode {ep.index} ({ep.target}, {m}): {res.summary()}")
    return _search_doc(config, variant, eps, results)


def _search_doc(config, variant: Style, eps, results) -> dict:
    stats = aggregate(results, seed=config.seed)
    t = {m: np.array([r.time_to_find for r in rs], float) for m, rs in results.items()}
    diff = t["flat"] - t["backoff"]
    lo, hi = bootstrap_ci(diff, np.mean, seed=config.seed) if len(diff) else (math.nan,) * 2
    mean_flat, mean_bo = float(t["flat"].mean()), float(t["backoff"].mean())
    return {
        "style": variant.name,
        "new_type": NEW_TYPE,
        "policy": SEARCH_POLICY,
        "rank": config.rank,
        "min_evidence": config.min_evidence,
        "episodes": len(eps),
        "budget_s": config.budget_s,
        "flat": stats["flat"].to_json(),
        "backoff": stats["backoff"].to_json(),
        # The search benchmark's statistics (agent.search.measures): backoff against flat.
        "paired_stats": {"flat": paired_stats(t["backoff"], t["flat"], config.seed).to_json()},
        "paired": {
            "mean_diff_s": float(diff.mean()) if len(diff) else math.nan,
            "mean_diff_ci95": [float(lo), float(hi)],
            "ratio_of_means": mean_bo / mean_flat if mean_flat > 0 else math.nan,
            "backoff_faster": int((diff > 1e-9).sum()),
            "flat_faster": int((diff < -1e-9).sum()),
            "ties": int((np.abs(diff) <= 1e-9).sum()),
        },
        "episode_list": [
            {
                "index": ep.index,
                "room_seed": ep.room_seed,
                "target": ep.target,
                "flat_s": float(t["flat"][i]),
                "backoff_s": float(t["backoff"][i]),
            }
            for i, ep in enumerate(eps)
        ],
    }


# =========================================================================== the benchmark
@dataclass
class HierarchyResult:
    """The benchmark's document, its Markdown and the files written."""

    doc: dict
    markdown: str
    files: list[Path]


def bench_hierarchy(
    config: HierarchyBenchConfig, out: Path, progress: Callable[[str], None] | None = None
) -> HierarchyResult:
    """Run both parts (module docstring) and write hierarchy.json / .md / .png / .csv and
    hierarchy_search.csv to ``out``."""
    t0 = time.perf_counter()
    style = resolve_style(config.style)
    if not isinstance(style, Style):
        raise CtxsearchError(f"bench hierarchy needs a room style, not house style '{style.name}'")
    model = main_work_surface(style, load_catalog())
    catalog = extended_catalog(model)
    style = resolve_style(config.style, catalog)
    variant = workbench_style(style, model, catalog)
    agree = ChoiceAgreement()
    with tempfile.TemporaryDirectory(prefix="ctxsearch-hierarchy-") as tmp:
        kb_path = Path(tmp) / "kb.sqlite"
        lc = LearnConfig(
            style=config.style,
            rooms=config.rooms,
            kb_path=kb_path,
            perception="oracle",
            seed=config.seed,
            progress=False,
        )
        learn(lc, catalog=catalog, on_choice=agree)
        with EvidenceStore.open(kb_path, catalog, read_only=True) as store:
            exams = [(e.type, [(r, t) for r, t, _ in e.related]) for e in store.examinations()]
        if progress is not None:
            progress(f"learned {config.rooms} {style.name} rooms: {len(exams)} examinations")
        p_true, _ = _truth_table(ground_truth(style, config.truth_samples, 0, catalog))
        doc = {
            "style": style.name,
            "rooms": config.rooms,
            "examinations": len(exams),
            "truth_samples": config.truth_samples,
            "draws": config.draws,
            "seed": config.seed,
            "informative": list(INFORMATIVE),
            "estimate": "p0 (Wilson centre) of each interval",
        }
        doc.update(held_out_errors(catalog, exams, p_true, config))
        doc["hif_backoff_agreement"] = {
            "choices": agree.choices,
            "same": agree.same,
            "share_same": agree.same / agree.choices if agree.choices else math.nan,
        }
        if config.episodes > 0:
            doc["search"] = paired_search(config, variant, catalog, kb_path, progress)
            doc["search"]["modelled_on"] = model
            # The control: the styles the robot learned in, no new type (what backoff costs there).
            doc["search_control"] = paired_search(config, style, catalog, kb_path, progress)
    doc["wall_s"] = round(time.perf_counter() - t0, 1)
    return _write(doc, out)


def _f(x: float, d: int = 3) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{d}f}"


def format_markdown(doc: dict) -> str:
    """The benchmark's report as Markdown."""
    lines = [
        f"# Type hierarchy: flat vs backoff ({doc['style']})",
        "",
        f"{doc['rooms']} learning rooms ({doc['examinations']} examinations, hif, oracle "
        f"perception); ground truth over {doc['truth_samples']} rooms. Each of "
        f"{', '.join(doc['types'])} held to k examinations ({doc['draws']} random draws per k), "
        "the others learned fully. Estimate: the interval's Wilson centre p0. "
        f"{doc['entries']} entries (A, rel, B) whose relation maps onto A's class, "
        f"{doc['informative_entries']} informative ({doc['informative'][0]} <= p_true <= "
        f"{doc['informative'][1]}).",
        "",
        "| k | abs error flat | abs error backoff | coverage flat | coverage backoff |",
        "|---|---|---|---|---|",
    ]
    for i, k in enumerate(doc["k"]):
        lines.append(
            f"| {k} | {_f(doc['abs_error_flat'][i])} | {_f(doc['abs_error_backoff'][i])} | "
            f"{_f(doc['coverage_flat'][i])} | {_f(doc['coverage_backoff'][i])} |"
        )
    a = doc["hif_backoff_agreement"]
    lines += [
        "",
        "At k = 0 the flat interval is [0, 1]: it holds every p_true (coverage 1 by construction).",
        "",
        f"HIF with backoff (`hif-backoff`): at {a['same']} of the {a['choices']} choices of the "
        f"hif run ({_f(a['share_same'] * 100, 1)}%) it would have chosen the same type.",
    ]
    if "search" not in doc:  # --episodes 0
        return "\n".join(lines)
    lines += [
        "",
        *_search_lines(
            doc["search"],
            f"Search with a never-seen {doc['search']['new_type']} ({doc['search']['style']}, "
            f"modelled on {doc['search'].get('modelled_on', '?')})",
        ),
        *_search_lines(
            doc["search_control"],
            f"Control: search in held-out {doc['search_control']['style']} rooms (no new type)",
        ),
    ]
    return "\n".join(lines)


def _search_lines(s: dict, title: str) -> list[str]:
    pr = s["paired"]
    lines = [
        f"## {title}",
        "",
        f"`{s['policy']}` by the interval's `{s['rank']}`, {s['episodes']} paired episodes, "
        f"budget {s['budget_s']:.0f} simulated s; backoff for reference types with fewer than "
        f"{s['min_evidence']} examinations.",
        "",
        "| estimate | success | median s | mean s |",
        "|---|---|---|---|",
    ]
    for m in ("flat", "backoff"):
        st = s[m]
        lines.append(
            f"| {m} | {_f(st['success_rate'], 2)} | {_f(st['median_s'], 1)} | "
            f"{_f(st['mean_s'], 1)} |"
        )
    ps = s["paired_stats"]["flat"]
    return lines + [
        "",
        f"Backoff / flat, the geometric mean of the paired time ratio [95% bootstrap interval] "
        f"wins/losses/ties and the signed-rank p: {geo_cell(ps)}; an effect this size needs "
        f"{ps['episodes_for_power'] or '-'} episodes for 80% power.",
        "",
        f"Paired: mean (flat - backoff) {_f(pr['mean_diff_s'], 1)} s (95% CI "
        f"{_f(pr['mean_diff_ci95'][0], 1)} .. {_f(pr['mean_diff_ci95'][1], 1)}), ratio of means "
        f"backoff / flat {_f(pr['ratio_of_means'], 2)}; backoff faster in {pr['backoff_faster']}, "
        f"flat faster in {pr['flat_faster']}, ties {pr['ties']}.",
        "",
    ]


def plot(doc: dict, path: Path) -> None:
    """Error and coverage against k (flat vs backoff), and the paired search times."""
    fig = Figure(figsize=(12, 3.8))
    ax1, ax2, ax3 = fig.subplots(1, 3)
    k = doc["k"]
    for m, style in (("flat", "o-"), ("backoff", "s-")):
        ax1.plot(k, doc[f"abs_error_{m}"], style, label=m)
        ax2.plot(k, doc[f"coverage_{m}"], style, label=m)
    ax1.set(xlabel="examinations of the held type (k)", ylabel="mean |p0 - p_true|")
    ax2.set(xlabel="examinations of the held type (k)", ylabel="coverage (informative)")
    ax2.axhline(1 - intervals.DEFAULT_ALPHA, color="grey", ls=":", lw=0.8, label="nominal")
    ax2.set_ylim(0, 1.05)
    ax1.legend()
    ax2.legend()
    eps = doc["search"]["episode_list"] if "search" in doc else []
    if eps:
        f = [e["flat_s"] for e in eps]
        b = [e["backoff_s"] for e in eps]
        top = max(max(f), max(b), 1.0)
        ax3.scatter(f, b, s=14)
        ax3.plot([0, top], [0, top], "k--", lw=0.8)
    ax3.set(
        xlabel="flat: seconds to find",
        ylabel="backoff: seconds to find",
        title=f"never-seen {doc['search']['new_type']}" if "search" in doc else "no search",
    )
    fig.suptitle(f"type hierarchy ({doc['style']})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _write(doc: dict, out: Path) -> HierarchyResult:
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "hierarchy.json", out / "hierarchy.md", out / "hierarchy.png"]
    files[0].write_text(json.dumps(doc, indent=1) + "\n")
    md = format_markdown(doc)
    files[1].write_text(md)
    plot(doc, files[2])
    files.append(write_csv(out / "hierarchy.csv", ERROR_COLUMNS, error_rows(doc)))
    files.append(write_csv(out / "hierarchy_search.csv", SEARCH_COLUMNS, search_rows(doc)))
    return HierarchyResult(doc, md, files)


# hierarchy.csv: one row per held-out reference type and k (its examinations kept), both
# estimates side by side (the JSON's per_type lists).
ERROR_COLUMNS = (
    "style",
    "ref_type",
    "k",
    "abs_error_flat",
    "abs_error_backoff",
    "coverage_flat",
    "coverage_backoff",
)
# hierarchy_search.csv: one row per search episode and estimate, for the styles with the new
# type ("workbench") and without it ("control").
SEARCH_COLUMNS = (
    "part",
    "style",
    "policy",
    "episode",
    "room_seed",
    "target",
    "estimate",
    "time_to_find_s",
)


def error_rows(doc: dict):
    """The rows of hierarchy.csv (``ERROR_COLUMNS``), type by type, k by k."""
    for t, d in doc["per_type"].items():
        for i, k in enumerate(doc["k"]):
            yield {"style": doc["style"], "ref_type": t, "k": k,
                   **{c: d[c][i] for c in ERROR_COLUMNS[3:]}}  # fmt: skip


def search_rows(doc: dict):
    """The rows of hierarchy_search.csv (``SEARCH_COLUMNS``)."""
    for part, key in (("workbench", "search"), ("control", "search_control")):
        s = doc.get(key)
        if s is None:
            continue
        for e in s["episode_list"]:
            for estimate in ("flat", "backoff"):
                yield {"part": part, "style": s["style"], "policy": s["policy"],
                       "episode": e["index"], "room_seed": e["room_seed"], "target": e["target"],
                       "estimate": estimate, "time_to_find_s": e[f"{estimate}_s"]}  # fmt: skip
