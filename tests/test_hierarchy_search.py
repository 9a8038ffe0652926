"""Searching and choosing with the type hierarchy: the backoff probability source, HIF on the
backed-off counts, the experiment's never-seen Workbench, and ``bench hierarchy``."""

from __future__ import annotations

import csv
import json
from collections import Counter

import numpy as np
import pytest

from ctxsearch.agent.search import space as ss
from ctxsearch.agent.strategies import STRATEGIES, BackoffHIF, HighestImpactFirst, make_strategy
from ctxsearch.knowledge import ranking
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.pooling import Backoff, PooledCounts

EXAMS = [
    ("Desk", [("ON-TOP-OF-DESK", "Cup"), ("ON-TOP-OF-DESK", "Monitor")]),
    ("Desk", [("ON-TOP-OF-DESK", "Cup"), ("UNDER-DESK", "Bottle")]),
    ("Desk", [("ON-TOP-OF-DESK", "Monitor")]),
    ("Table", [("ON-TOP-OF-TABLE", "Cup"), ("NEAR-TABLE", "Chair")]),
    ("Table", [("NEAR-TABLE", "Chair")]),
    ("Shelf", [("ON-SHELF", "Book")]),
    ("Chair", []),
]


def _kb(catalog, exams=EXAMS) -> KnowledgeBase:
    kb = KnowledgeBase(catalog)
    for ref, pairs in exams:
        kb.record_examination(ref, pairs)
    return kb


def test_search_space_uses_the_one_copy_of_the_sources():
    assert ss.KBProbabilities is ranking.KBProbabilities
    assert ss.TableProbabilities is ranking.TableProbabilities
    assert ss.ProbabilitySource is ranking.ProbabilitySource
    assert ss.RANK_MODES == ranking.RANK_MODES and ss.DEFAULT_RANK == ranking.DEFAULT_RANK


def test_no_type_has_two_relations_onto_one_class_relation(catalog):
    h = catalog.hierarchy
    for t in catalog.type_names:
        lifted = Counter(h.lift(r) for r in catalog.type(t).relation_names if h.lift(r))
        assert max(lifted.values(), default=1) == 1, t
    for c in h.classes:
        lifted = Counter(h.lift(r) for r in c.relations if h.lift(r))
        assert max(lifted.values(), default=1) == 1, c.name


def test_pooled_counts_from_a_knowledge_base_match_the_log_for_types(catalog):
    from_log = PooledCounts.from_examinations(catalog.hierarchy, EXAMS)
    from_kb = PooledCounts.from_knowledge_base(_kb(catalog))
    types = set(catalog.type_names)
    assert {k: v for k, v in from_log.y.items() if k[2] in types and v} == {
        k: v for k, v in from_kb.y.items() if v
    }
    assert {k: v for k, v in from_log.via.items() if k[3] in types and v} == {
        k: v for k, v in from_kb.via.items() if v
    }
    assert {k: v for k, v in from_log.n.items() if v} == {k: v for k, v in from_kb.n.items() if v}


def test_backoff_source_searches_a_never_seen_type_from_its_class(catalog):
    kb = _kb(catalog)
    pooled = PooledCounts.from_knowledge_base(kb)
    flat = ss.KBProbabilities(kb, "low")
    bo = ss.BackoffProbabilities(kb, pooled, "low", min_evidence=3)
    # Counter: never examined. Flat its lower bound is 0; backed off it borrows WorkSurface's Cups.
    assert flat.p("ON-TOP-OF-COUNTER", "Cup") == 0.0
    e = Backoff(pooled, kb.alpha).estimate("Counter", "ON-TOP-OF-COUNTER", "Cup")
    assert bo.p("ON-TOP-OF-COUNTER", "Cup") == pytest.approx(e.low) and e.low > 0
    # Desk has 3 examinations: it reads its own interval, exactly as flat does.
    assert bo.p("ON-TOP-OF-DESK", "Cup") == flat.p("ON-TOP-OF-DESK", "Cup")
    # a relation that maps onto nothing keeps the flat value
    assert h_lift_none(catalog, "BEHIND-DESK")
    assert ss.BackoffProbabilities(kb, pooled, "high", min_evidence=100).p(
        "BEHIND-DESK", "Cup"
    ) == ss.KBProbabilities(kb, "high").p("BEHIND-DESK", "Cup")
    assert bo.name == "backoff-low" and bo.kb is kb


def h_lift_none(catalog, rel: str) -> bool:
    return catalog.hierarchy.lift(rel) is None


def test_candidate_volumes_around_a_never_seen_type_only_with_backoff(catalog):
    from ctxsearch.knowledge.geometry import ObjectInstance

    kb = _kb(catalog)
    counter = ObjectInstance("Counter", 7, (0.0, 0.0, 0.45), 0.0, (0.6, 2.0, 0.9))
    flat = ranking.candidate_volumes([counter], "Cup", catalog, ranking.KBProbabilities(kb))
    pooled = PooledCounts.from_knowledge_base(kb)
    bo = ranking.candidate_volumes(
        [counter], "Cup", catalog, ranking.BackoffProbabilities(kb, pooled, min_evidence=1)
    )
    assert flat == []
    assert bo and bo[0].relation == "ON-TOP-OF-COUNTER" and bo[0].ref_id == 7


def test_hif_backoff_is_registered_and_hif_unchanged(catalog):
    assert "hif-backoff" in STRATEGIES and STRATEGIES["hif"] is HighestImpactFirst
    assert isinstance(make_strategy("hif-backoff"), BackoffHIF)
    kb = _kb(catalog)
    bo = Backoff(PooledCounts.from_knowledge_base(kb), kb.alpha)
    # A never-examined member of a known class starts from pseudo-examinations: less impact.
    assert BackoffHIF.type_score(kb, bo, "Counter") < kb.type_score("Counter")
    # A type whose class has no evidence scores as in hif.
    assert BackoffHIF.type_score(kb, bo, "Cup") == pytest.approx(kb.type_score("Cup"))
    cands = {"Counter": [], "Cup": []}
    choice, scores = BackoffHIF().choose_type(kb, cands, None, None, np.random.default_rng(0))
    assert choice == "Cup" and set(scores) == {"Counter", "Cup"}


def test_the_workbench_experiment_leaves_the_catalog_alone():
    from ctxsearch.envs.floorplan import generate_layout
    from ctxsearch.envs.houses import resolve_style
    from ctxsearch.scripts.experiments.bench_hierarchy import (
        NEW_TYPE,
        extended_catalog,
        main_work_surface,
        workbench_style,
    )

    base = load_catalog()
    office = resolve_style("office", base)
    model = main_work_surface(office, base)
    assert model == "Desk"
    ext = extended_catalog(model)
    assert NEW_TYPE in ext and NEW_TYPE not in base
    assert ext.hierarchy.parent(NEW_TYPE) == "WorkSurface"
    assert ext.hierarchy.lift("ON-TOP-OF-WORKBENCH") == "ON-TOP-OF-WORKSURFACE"
    assert ext.type(NEW_TYPE).shape == "table"
    assert load_catalog().fingerprint == base.fingerprint  # assets/types.toml untouched
    variant = workbench_style(resolve_style("office", ext), model, ext)
    types = {o.type for o in generate_layout(variant, 3, ext).objects}
    assert NEW_TYPE in types and "Desk" not in types


def test_bench_hierarchy_writes_its_files(tmp_path):
    from ctxsearch.scripts.cli import main

    out = tmp_path / "h"
    args = ["bench", "hierarchy", "--out", str(out), "--rooms", "3", "--episodes", "2"]
    args += ["--truth-samples", "20", "--ks", "0,1", "--draws", "1", "--quiet"]
    assert main(args) == 0
    doc = json.loads((out / "hierarchy.json").read_text())
    assert doc["k"] == [0, 1]
    for key in ("abs_error_flat", "abs_error_backoff", "coverage_flat", "coverage_backoff"):
        assert len(doc[key]) == 2
    assert doc["coverage_flat"][0] == 1.0  # [0, 1] holds everything
    assert doc["abs_error_backoff"][0] < doc["abs_error_flat"][0]
    s = doc["search"]
    assert s["new_type"] == "Workbench" and s["episodes"] == 2 and len(s["episode_list"]) == 2
    assert (
        s["paired_stats"]["flat"]["n"] == 2
        and "geometric mean" in (out / "hierarchy.md").read_text()
    )
    assert doc["hif_backoff_agreement"]["choices"] > 0
    assert "| k |" in (out / "hierarchy.md").read_text()
    assert (out / "hierarchy.png").stat().st_size > 1000
    with (out / "hierarchy.csv").open(newline="") as f:
        errors = list(csv.DictReader(f))
    assert len(errors) == 2 * len(doc["types"])
    desk = [r for r in errors if r["ref_type"] == doc["types"][0]]
    assert [float(r["coverage_flat"]) for r in desk] == doc["per_type"][doc["types"][0]][
        "coverage_flat"
    ]
    with (out / "hierarchy_search.csv").open(newline="") as f:
        searches = list(csv.DictReader(f))
    assert len(searches) == 2 * 2 * 2  # (workbench, control) x 2 episodes x (flat, backoff)
    first = doc["search"]["episode_list"][0]
    assert float(searches[1]["time_to_find_s"]) == first["backoff_s"]
    assert {r["part"] for r in searches} == {"workbench", "control"}


@pytest.mark.parametrize(
    "argv",
    [
        ["bench", "hierarchy", "--out", "OUT", "--ks", "1,x"],
        ["bench", "hierarchy", "--out", "OUT", "--ks", "-1"],
        ["bench", "hierarchy", "--out", "OUT", "--style", "no_such_style"],
        ["search", "--kb", "KB", "--style", "office", "--target", "Cup", "--estimate", "nope"],
        ["search", "--kb", "KB", "--style", "office", "--target", "Cup", "--min-evidence", "-2"],
    ],
)
def test_bad_flags_are_one_line_errors(argv, tmp_path, capsys):
    from ctxsearch.scripts.cli import main

    argv = [str(tmp_path / a) if a in ("OUT", "KB") else a for a in argv]
    try:
        rc = main(argv)
    except SystemExit as e:  # argparse's own errors
        rc = e.code
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err and err[-1].startswith("ctxsearch") and "error: " in err[-1]
    assert "Traceback" not in "".join(err)


def test_bench_hierarchy_with_no_episodes_measures_the_estimates_only(tmp_path):
    from ctxsearch.scripts.cli import main

    out = tmp_path / "h"
    args = ["bench", "hierarchy", "--out", str(out), "--rooms", "3", "--episodes", "0"]
    assert main([*args, "--truth-samples", "20", "--ks", "0,1", "--draws", "1"]) == 0
    doc = json.loads((out / "hierarchy.json").read_text())
    assert "search" not in doc and len(doc["coverage_backoff"]) == 2
    md = (out / "hierarchy.md").read_text()
    assert "| k |" in md and "Search with" not in md
    assert not (out / "hierarchy_search.csv").read_text().strip().split("\n")[1:]  # header only
