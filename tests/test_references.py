"""Only real references (issue 28, point 3): with ``confirm_reference`` K > 1 an object is
examined only once K images of its room detected it, so the detector's false positives (drawn
anew in every image) are almost never examined; the run resumes exactly; bench intervals counts
the phantom references."""

from __future__ import annotations

import pytest

from ctxsearch.agent.learning import LearnConfig, learn
from ctxsearch.knowledge.store import EvidenceStore

pytestmark = pytest.mark.render


def _rows(path, catalog):
    with EvidenceStore.open(path, catalog, read_only=True) as st:
        return [(e.object_id, e.type, e.related, e.sim_time) for e in st.examinations()]


def _learn(path, catalog, rooms, k, limit=None):
    cfg = LearnConfig("office", rooms, path, perception="camera", progress=False,
                      confirm_reference=k, max_examinations=limit)  # fmt: skip
    return learn(cfg, catalog=catalog)


def test_a_false_positive_is_examined_only_without_confirmation(tmp_path, catalog):
    """Two office rooms, the realistic detector: as published (K = 1) some examined objects
    are false positives (negative ids); with K = 2 none is, and the run has its own key."""
    once = _learn(tmp_path / "a.sqlite", catalog, 2, 1)
    twice = _learn(tmp_path / "b.sqlite", catalog, 2, 2)
    assert once.run == "hif/camera+realistic/seed=0/map=built"
    assert twice.run == "hif/camera+realistic+ref2/seed=0/map=built"
    phantoms = [r for r in _rows(tmp_path / "a.sqlite", catalog) if r[0] < 0]
    assert phantoms  # the detector's false positives were examined
    assert [r for r in _rows(tmp_path / "b.sqlite", catalog) if r[0] < 0] == []
    assert twice.examinations > 0


def test_a_resumed_run_with_confirmed_references_equals_an_uninterrupted_one(tmp_path, catalog):
    whole = _learn(tmp_path / "a.sqlite", catalog, 1, 2, limit=6)
    _learn(tmp_path / "b.sqlite", catalog, 1, 2, limit=3)
    resumed = _learn(tmp_path / "b.sqlite", catalog, 1, 2, limit=3)  # replays 3, then 3 new
    assert whole.examinations == 6 and resumed.examinations == 3
    assert _rows(tmp_path / "a.sqlite", catalog) == _rows(tmp_path / "b.sqlite", catalog)


def test_bench_intervals_counts_phantom_references(tmp_path):
    import csv
    import json

    from ctxsearch.scripts.cli import main

    out = tmp_path / "iv"
    args = ["bench", "intervals", "--styles", "office", "--rooms", "1", "--seeds", "1"]
    args += ["--settings", "realistic,realistic+ref2", "--truth-samples", "10", "--out", str(out)]
    assert main(args) == 0
    rows = {r["detector"]: r for r in json.loads((out / "intervals.json").read_text())["rows"]}
    assert rows["realistic"]["phantom_reference_share"] > 0
    assert (
        rows["realistic+ref2"]["phantom_reference_share"]
        < rows["realistic"]["phantom_reference_share"]
    )
    with open(out / "intervals.csv", newline="") as f:
        runs = list(csv.DictReader(f))
    assert {float(r["phantom_reference_share"]) > 0 for r in runs} == {True, False}
    assert "phantom references" in (out / "intervals.md").read_text()
