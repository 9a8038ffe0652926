"""Only real references (issue 28, point 3): with ``confirm_reference`` K > 1 an object is
examined only once K images of its room detected it, so the detector's false positives (drawn
anew in every image) are almost never examined; the run resumes exactly; bench intervals counts
the phantom references."""

from __future__ import annotations

import numpy as np
import pytest

from ctxsearch.agent.learning import LearnConfig, learn
from ctxsearch.knowledge.store import EvidenceStore

pytestmark = pytest.mark.render


def _rows(path, catalog):
    """Every examination, and what its images could show (the views, issue 28 point 2)."""
    with EvidenceStore.open(path, catalog, read_only=True) as st:
        views = st.conn.execute(
            "SELECT examination_id, relation, recall, false_rate FROM views ORDER BY 1, 2"
        ).fetchall()
        return [(e.object_id, e.type, e.related, e.sim_time) for e in st.examinations()], views


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
    phantoms = [r for r in _rows(tmp_path / "a.sqlite", catalog)[0] if r[0] < 0]
    assert phantoms  # the detector's false positives were examined
    assert [r for r in _rows(tmp_path / "b.sqlite", catalog)[0] if r[0] < 0] == []
    assert twice.examinations > 0
    _views_tell_what_the_images_could_show(tmp_path / "a.sqlite", catalog)


def _views_tell_what_the_images_could_show(path, catalog):
    """Every examination of a camera run keeps one view per relation of its type: a pen is
    harder to see than a chair, clutter false positives are expected of the preset's types only
    (Cup, not Chair), and the corrected intervals read them (knowledge.corrected)."""
    with EvidenceStore.open(path, catalog, read_only=True) as st:
        views = st.exam_views()
        exams = list(st.examinations())
        kb = st.knowledge_base(interval="corrected")
    assert sum(v.n for v in views.values()) == len(exams)
    names = catalog.type_names
    pen, chair, cup = names.index("Pen"), names.index("Chair"), names.index("Cup")
    q = np.concatenate([v.q.reshape(-1, len(names)) for v in views.values()])
    f = np.concatenate([v.f.reshape(-1, len(names)) for v in views.values()])
    assert ((q >= 0) & (q <= 1)).all() and (q < 1).any()  # recorded, not the default of 1
    assert q[:, pen].mean() < q[:, chair].mean() - 0.2
    assert f[:, chair].max() == 0 and f[:, cup].max() > 0
    assert kb.interval_method == "corrected" and 0 < kb.mean_width() < 1


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
    assert "Coverage per reference type" in (out / "intervals.md").read_text()
    for r in rows.values():  # per type: [coverage pooled over seeds, informative entries]
        for key in ("coverage_by_type", "coverage_by_type_corrected"):
            assert r[key] and all(0 <= c <= 1 and n >= 1 for c, n in r[key].values())
    for r in [*rows.values(), *runs]:  # the corrected interval, read from each run's store
        for key in ("coverage_informative", "mean_abs_error", "mean_width", "expected_recall"):
            assert 0 <= float(r[f"corrected_{key}" if "recall" not in key else key]) <= 1
        assert float(r["seconds_per_examination"]) > 0


def test_examinations_planned_to_see_see_better_at_a_cost(tmp_path, catalog):
    """``exam_recall`` (issue 28 point 1): the gaze planner keeps to the range where the object
    types are detected with mean recall 0.9: the examinations' expected recall of the object
    types rises, and the robot spends more simulated seconds on them."""
    from ctxsearch.scripts.experiments.bench_intervals import expected_recall

    def run(path, recall):
        cfg = LearnConfig("office", 1, path, perception="camera", progress=False,
                          exam_recall=recall, max_examinations=5)  # fmt: skip
        s = learn(cfg, catalog=catalog)
        with EvidenceStore.open(path, catalog, read_only=True) as st:
            exams = list(st.examinations())
            return s.run, expected_recall(st.exam_views(), catalog), exams[-1].sim_time

    key, far, far_s = run(tmp_path / "a.sqlite", None)
    near_key, near, near_s = run(tmp_path / "b.sqlite", 0.9)
    assert near_key == f"{key}/exam-recall=0.9"
    assert near > far + 0.03 and near > 0.9
    assert near_s > far_s


def test_learn_confirms_references_by_default_and_paper_gives_the_literal_loop(tmp_path, capsys):
    """``ctxsearch learn`` examines an object once two images saw it (the default); ``--paper``
    is the paper's loop (every detected object at once, its own run key); the two flags that
    contradict each other are a one-line error with exit code 2 and no store written."""
    from ctxsearch.scripts.cli import main

    base = ["learn", "--style", "office", "--rooms", "1", "--max-examinations", "1"]
    assert main([*base, "--kb", str(tmp_path / "d.sqlite"), "--no-progress"]) == 0
    assert "hif/camera+realistic+ref2/seed=0/map=built" in capsys.readouterr().out
    assert main([*base, "--kb", str(tmp_path / "p.sqlite"), "--no-progress", "--paper"]) == 0
    out = capsys.readouterr().out
    assert "hif/camera+realistic/seed=0/map=built" in out and "+ref" not in out
    bad = tmp_path / "bad.sqlite"
    code = main([*base, "--kb", str(bad), "--paper", "--confirm-reference", "2"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--paper" in err
    assert not bad.exists()
    # The default's rooms learned again by the paper's loop would count twice: refused, the
    # store's bytes untouched.
    before = (tmp_path / "d.sqlite").read_bytes()
    code = main([*base, "--kb", str(tmp_path / "d.sqlite"), "--no-progress", "--paper"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "count twice" in err
    assert (tmp_path / "d.sqlite").read_bytes() == before
