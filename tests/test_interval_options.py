"""``--interval clustered`` at the store and knowledge-base level, and coverage_informative."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.experiments.learning_trace import TruthTracker, informative, interval_metrics

REL = "ON-TOP-OF-DESK"


def _fill(store: EvidenceStore, rooms: list[list[bool]]) -> None:
    """Desk examinations: rooms[j][i] says whether examination i of room j saw a Cup on it."""
    k = 0
    for j, exams in enumerate(rooms):
        for i, hit in enumerate(exams):
            store.record(
                run="r", style="office", room_seed=1000 + j, object_id=i, ref_type="Desk",
                sim_time=float(k), strategy="hif",
                related=[(REL, "Cup", 50 + i)] if hit else [],
            )  # fmt: skip
            k += 1


def test_clustered_reduces_to_wilson_with_one_examination_per_room(catalog, tmp_path):
    with EvidenceStore.open(tmp_path / "kb.sqlite", catalog, create=True) as store:
        _fill(store, [[h] for h in (True, False, True, True, False, False, True, False)])
        wilson = store.knowledge_base()
        clustered = store.knowledge_base(interval="clustered")
        assert clustered.interval_method == "clustered" and wilson.interval_method == "wilson"
        assert clustered.interval(REL, "Cup") == pytest.approx(wilson.interval(REL, "Cup"))
        assert clustered.interval(REL, "Pen") == pytest.approx(wilson.interval(REL, "Pen"))
        assert clustered.mean_width() == pytest.approx(wilson.mean_width())
        for a, b in zip(clustered.rows("Desk"), wilson.rows("Desk"), strict=True):
            assert (a.relation, a.type) == (b.relation, b.type)
            assert (a.low, a.high, a.p0) == pytest.approx((b.low, b.high, b.p0))
        assert clustered.type_score_effective("Desk") == pytest.approx(wilson.type_score("Desk"))


def test_clustered_widens_correlated_rooms_and_leaves_hif_alone(catalog, tmp_path):
    with EvidenceStore.open(tmp_path / "kb.sqlite", catalog, create=True) as store:
        _fill(store, [[True] * 5, [False] * 5, [True] * 5, [False] * 5])
        counts = store.room_counts()
        assert counts["Desk"].n_room.tolist() == [5, 5, 5, 5]
        assert counts["Desk"].y_room[(REL, "Cup")].tolist() == [5, 0, 5, 0]
        wilson = store.knowledge_base()
        clustered = store.knowledge_base(interval="clustered")
    lo_w, hi_w = wilson.interval(REL, "Cup")
    lo_c, hi_c = clustered.interval(REL, "Cup")
    assert lo_c < lo_w and hi_c > hi_w  # four rooms' worth of evidence, not twenty trials'
    assert clustered.mean_width() > wilson.mean_width()
    # The counts and the HIF score read raw counts: unchanged.
    assert clustered.n("Desk") == wilson.n("Desk") == 20
    assert clustered.type_score("Desk") == wilson.type_score("Desk")


def test_unknown_interval_method_is_refused(catalog, tmp_path):
    with (
        EvidenceStore.open(tmp_path / "kb.sqlite", catalog, create=True) as store,
        pytest.raises(CtxsearchError, match="unknown interval method 'bogus'"),
    ):
        store.knowledge_base(interval="bogus")


def test_coverage_informative_excludes_exactly_the_uninformative_entries():
    p_true = np.array([0.0, 0.01, 0.02, 0.5, 0.98, 0.99, 1.0, 0.5])
    n = np.array([10, 10, 10, 10, 10, 10, 10, 0])
    assert informative(p_true, n).tolist() == [False, False, True, True, True, False, False, False]
    # Intervals: the informative entries 2, 3, 4 hold p_true, miss it, hold it; every
    # uninformative one misses (so plain coverage would count them, informative must not).
    lo = np.array([0.5, 0.5, 0.0, 0.6, 0.9, 0.0, 0.0, 0.6])
    hi = np.array([0.6, 0.6, 0.1, 0.7, 1.0, 0.5, 0.5, 0.7])
    m = interval_metrics(lo, hi, (lo + hi) / 2, p_true, n)
    assert m["coverage_informative"] == pytest.approx(2 / 3)
    assert m["coverage"] == pytest.approx(2 / 8)
    none = interval_metrics(lo, hi, lo, p_true, np.zeros(8))
    assert math.isnan(none["coverage_informative"])


def test_truth_tracker_clustered_beside_wilson(catalog):
    truth = {
        "entries": [
            {"ref": "Desk", "relation": REL, "type": "Cup", "p": 0.5},
            {"ref": "Desk", "relation": REL, "type": "Pen", "p": 0.0},
        ]
    }
    wilson = TruthTracker(truth, catalog, 0.1)
    clustered = TruthTracker(truth, catalog, 0.1, "clustered")
    for room in range(4):
        for _ in range(5):
            pairs = [(REL, "Cup")] if room % 2 == 0 else []
            wilson.record("Desk", pairs, room)
            clustered.record("Desk", pairs, room)
    w, c = wilson.metrics(), clustered.metrics()
    assert "wilson_coverage_informative" not in w
    assert c["wilson_mean_width"] == pytest.approx(w["mean_width"])
    assert c["mean_width"] > w["mean_width"]
    # Against the store's reading of the same evidence.
    lo, hi = intervals.interval(10, 20, 0.1)
    assert w["mean_width"] == pytest.approx(
        ((hi - lo) + float(np.subtract(*intervals.interval(0, 20, 0.1)[::-1]))) / 2
    )


def test_bench_learning_clustered_writes_coverage_informative(tmp_path):
    from ctxsearch.scripts.cli import main

    out = tmp_path / "bench"
    rc = main(
        ["bench", "learning", "--style", "office", "--rooms", "2", "--seeds", "1",
         "--strategies", "hif", "--truth-samples", "10", "--interval", "clustered",
         "--out", str(out)]
    )  # fmt: skip
    assert rc == 0
    doc = json.loads((out / "learning.json").read_text())
    assert doc["interval"] == "clustered" and doc["detector"] == "none"
    hif = doc["strategies"]["hif"]
    for key in ("coverage_informative", "wilson_coverage_informative", "wilson_mean_width"):
        assert len(hif[key]) == len(hif["examinations"])
    assert 0.0 <= hif["effective_same_hif"] <= 1.0
    # The clustered interval is never narrower than the paper's.
    assert all(
        c >= w - 1e-12 for c, w in zip(hif["mean_width"], hif["wilson_mean_width"], strict=True)
    )
    md = (out / "learning.md").read_text()
    assert md.index("Informative coverage") < md.index("## Coverage")


@pytest.mark.parametrize(
    "argv",
    [
        ["learn", "--style", "office", "--rooms", "1", "--kb", "KB"],
        ["bench", "learning", "--rooms", "1", "--seeds", "1", "--strategies", "hif",
         "--perception", "camera", "--out", "OUT"],
        ["search", "--kb", "KB", "--style", "office", "--target", "Cup", "--policy", "exhaustive"],
        ["bench", "search", "--kb", "KB", "--episodes", "1", "--policies", "exhaustive",
         "--out", "OUT"],
        ["room", "--style", "office", "--views", "0", "--out", "OUT"],
    ],
)  # fmt: skip
def test_a_bad_detector_file_gets_the_one_line_error(tmp_path, capsys, argv):
    from ctxsearch.scripts.cli import main

    bad = tmp_path / "bad.toml"
    bad.write_text('kind = "model"\n[recall]\nmax_recall = 2.0\n')
    kb = tmp_path / "kb.sqlite"
    if argv[0] in ("search", "bench"):
        main(["learn", "--style", "office", "--rooms", "1", "--perception", "oracle",
              "--kb", str(kb), "--no-progress"])  # fmt: skip
        capsys.readouterr()
    argv = [str(kb) if a == "KB" else str(tmp_path / "out") if a == "OUT" else a for a in argv]
    assert main([*argv, "--detector", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("ctxsearch: error: ")
    assert str(bad) in err and "max_recall" in err
    assert not (argv[0] == "learn" and kb.exists())  # nothing learned, nothing created


@pytest.mark.render
def test_a_confidence_threshold_counts_fewer_related_objects(catalog, tmp_path):
    """``min_score`` counts a related object only once one of its detections scored that
    confidence: at 1.0 (above the realistic preset's best, 0.95) nothing is ever related; the run
    key says the threshold; at 0 the run is the default one."""
    from ctxsearch.agent.learning import LearnConfig, learn
    from ctxsearch.knowledge.store import EvidenceStore

    def run(path, score):
        cfg = LearnConfig("office", 1, path, progress=False, max_examinations=4, min_score=score)
        return learn(cfg, catalog=catalog)

    high = run(tmp_path / "high.sqlite", 1.0)
    assert high.run == "hif/camera+realistic+score1+ref2/seed=0/map=built"
    low = run(tmp_path / "low.sqlite", 0.0)
    assert low.run == "hif/camera+realistic+ref2/seed=0/map=built"

    def related(path):
        with EvidenceStore.open(path, catalog, read_only=True) as st:
            return [e.related for e in st.examinations()]

    assert all(not r for r in related(tmp_path / "high.sqlite"))
    assert any(r for r in related(tmp_path / "low.sqlite"))


@pytest.mark.parametrize("bad", ["1.5", "-0.1", "x"])
def test_min_score_outside_0_1_is_refused(capsys, tmp_path, bad):
    from ctxsearch.scripts.cli import main

    kb = tmp_path / "kb.sqlite"
    with pytest.raises(SystemExit) as exc:
        main(["learn", "--style", "office", "--rooms", "1", "--kb", str(kb), "--min-score", bad])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--min-score" in err and "[0, 1]" in err
    assert not kb.exists()
