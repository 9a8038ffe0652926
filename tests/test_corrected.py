"""The recall-aware interval (``--interval corrected``, issue 28 point 2): the score interval of
a likelihood that knows each examination's chance of showing a related object (knowledge.corrected),
the views the store keeps for it (schema 5), and the robot's model of what its images can show
(agent.exam_views)."""

from __future__ import annotations

import sqlite3

import numpy as np
import pytest

from ctxsearch.agent.exam_views import volume_lattice
from ctxsearch.knowledge import geometry, intervals
from ctxsearch.knowledge.clustered import ClusteredIntervals
from ctxsearch.knowledge.corrected import (
    CorrectedIntervals,
    ExamViews,
    multiplicity,
    score_intervals,
)
from ctxsearch.knowledge.errors import CtxsearchError, StoreError
from ctxsearch.knowledge.pooling import Backoff, PooledCounts, interval_rows
from ctxsearch.knowledge.store import SCHEMA_VERSION, EvidenceStore, NewExamination, merge_stores
from ctxsearch.scripts.cli import main
from tests.old_stores import as_version


# ---- the interval ------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [1, 2, 7, 40, 500])
def test_with_full_recall_and_no_false_reports_it_is_wilson_exactly(n):
    rng = np.random.default_rng(n)
    y = (rng.random((n, 6)) < [0.0, 0.05, 0.3, 0.5, 0.9, 1.0]).astype(float)
    y[:, 0], y[:, 5] = 0, 1
    lo, hi, _, info = score_intervals(y, np.ones_like(y), np.zeros_like(y), 0.1)
    wl, wh = intervals.interval(y.sum(0), np.full(6, n), 0.1)
    assert lo == pytest.approx(wl, abs=1e-12) and hi == pytest.approx(wh, abs=1e-12)
    assert info == pytest.approx(np.full(6, n))
    # with a shrink factor: Wilson on the effective counts, as the clustered interval is
    lo, hi, _, _ = score_intervals(y, np.ones_like(y), np.zeros_like(y), 0.1, shrink=2.5)
    wl, wh = intervals.interval(y.sum(0) / 2.5, np.full(6, n / 2.5), 0.1)
    assert lo == pytest.approx(wl, abs=1e-12) and hi == pytest.approx(wh, abs=1e-12)


@pytest.mark.parametrize("theta", [0.05, 0.3, 0.7])
def test_it_keeps_its_promise_where_the_detector_misses_and_imagines(theta):
    """800 replicates of 150 examinations, each seeing a B that is there with a recall drawn in
    [0.15, 0.95] and imagining one with probability 0.02: the corrected interval covers theta
    about 90% of the time; counting every miss as an absence (Wilson) seldom does where misses
    outweigh the false reports (at 0.05 the two nearly cancel: 0.05 x 0.55 + 0.02)."""
    rng = np.random.default_rng(7)
    n, reps = 150, 800
    q = rng.uniform(0.15, 0.95, (n, reps))
    f = np.full((n, reps), 0.02)
    there = rng.random((n, reps)) < theta
    y = ((there & (rng.random((n, reps)) < q)) | (rng.random((n, reps)) < f)).astype(float)
    lo, hi, _, _ = score_intervals(y, q, f, 0.1)
    covered = float(np.mean((lo <= theta) & (theta <= hi)))
    assert 0.86 <= covered <= 0.94
    wl, wh = intervals.interval(y.sum(0), np.full(reps, n), 0.1)
    if theta >= 0.3:
        assert float(np.mean((wl <= theta) & (theta <= wh))) < 0.5


def test_several_bs_in_a_volume_are_counted_not_taken_for_better_recall():
    """Where a volume holds 1 + Poisson(1.5) pens, each seen with its own recall, at least one
    is seen far more often than one pen's recall says. The corrected intervals estimate the
    multiplicity from how many were reported and keep their promise; taking every volume to hold
    one B would overshoot (the estimate runs into 1)."""
    rng = np.random.default_rng(3)
    n, reps, theta = 150, 600, 0.4
    q = rng.uniform(0.15, 0.9, (n, reps))
    there = rng.random((n, reps)) < theta
    k = np.where(there, 1 + rng.poisson(1.5, (n, reps)), 0)
    d = rng.binomial(k, q)
    views = {"A": ExamViews(d[:, None, :], q[:, None, :], np.zeros((n, 1, reps)))}
    names = tuple(f"B{i}" for i in range(reps))
    ci = CorrectedIntervals(views, ClusteredIntervals({}), {"A": ("REL",)}, names, 0.1)
    lo, hi = np.array([ci.interval("A", "REL", b) for b in names]).T
    assert 0.86 <= float(np.mean((lo <= theta) & (theta <= hi))) <= 0.95
    mu = multiplicity(d, q, np.zeros_like(q))
    assert 1.0 < float(np.median(mu)) < 2.0
    one = score_intervals(d > 0, q, np.zeros_like(q), 0.1)
    assert float(np.mean((one[0] <= theta) & (theta <= one[1]))) < 0.5


def test_an_examination_that_could_not_have_shown_it_says_nothing():
    y = np.zeros((5, 2))
    q = np.array([[0.0, 1.0]] * 5)
    lo, hi, theta, info = score_intervals(y, q, np.zeros_like(q), 0.1)
    assert (lo[0], hi[0], theta[0], info[0]) == (0.0, 1.0, 0.5, 0.0)
    assert lo[1] == 0.0 and hi[1] == pytest.approx(float(intervals.interval(0, 5, 0.1)[1]))


# ---- the store: views (schema 5) ---------------------------------------------------------------
def _views(catalog, ref="Desk", recall=0.4, false_rate=0.01):
    t = len(catalog.type_names)
    return tuple(
        (rel, np.full(t, recall), np.full(t, false_rate))
        for rel in catalog.type(ref).relation_names
    )


def _exam(oid, related=(), views=(), run="r1", seed=1):
    return NewExamination(run, "office", seed, oid, "Desk", float(oid), "hif", tuple(related), 0,
                          views)  # fmt: skip


def _store(path, catalog, views=True):
    with EvidenceStore.open(path, catalog) as s:
        for oid in range(1, 9):
            cup = (("ON-TOP-OF-DESK", "Cup", 100 + oid),) if oid % 3 == 0 else ()
            s.append(_exam(oid, cup, _views(catalog) if views else (), seed=oid % 3))
    return path


def test_views_round_trip_and_the_corrected_interval_reads_them(tmp_path, catalog):
    path = _store(tmp_path / "s.sqlite", catalog)
    with EvidenceStore.open(path, catalog, read_only=True) as s:
        assert s.version == SCHEMA_VERSION >= 5
        v = s.exam_views()["Desk"]
        kb = s.knowledge_base(interval="corrected")
        clustered = s.knowledge_base(interval="clustered")
    r = catalog.type("Desk").relation_names.index("ON-TOP-OF-DESK")
    cup = catalog.type_names.index("Cup")
    assert v.n == 8 and v.y[:, r, cup].sum() == 2
    assert v.q == pytest.approx(0.4, abs=1e-4) and v.f == pytest.approx(0.01, abs=1e-4)
    lo, hi = kb.interval("ON-TOP-OF-DESK", "Cup")
    cl = clustered.interval("ON-TOP-OF-DESK", "Cup")
    assert hi > cl[1] + 0.2  # a recall of 0.4: two cups seen say more cups stood there
    row = next(x for x in kb.rows("Desk") if (x.relation, x.type) == ("ON-TOP-OF-DESK", "Cup"))
    assert (row.low, row.high, row.p0) == pytest.approx((lo, hi, (lo + hi) / 2))
    assert 0 < kb.mean_width() < 1
    assert kb.type_score_effective("Desk") > 0


def test_without_views_corrected_equals_clustered(tmp_path, catalog):
    path = _store(tmp_path / "s.sqlite", catalog, views=False)
    with EvidenceStore.open(path, catalog, read_only=True) as s:
        a = s.knowledge_base(interval="corrected").rows("Desk")
        b = s.knowledge_base(interval="clustered").rows("Desk")
    assert [(x.relation, x.type) for x in a] == [(x.relation, x.type) for x in b]
    assert np.array([[x.low, x.high, x.p0] for x in a]) == pytest.approx(
        np.array([[x.low, x.high, x.p0] for x in b]), abs=1e-9
    )


def test_a_schema_4_store_is_read_with_recall_one_and_gains_views_on_its_first_write(
    tmp_path, catalog
):
    path = _store(tmp_path / "s.sqlite", catalog, views=False)
    as_version(path, 4)
    before = path.read_bytes()
    with EvidenceStore.open(path, catalog, read_only=True) as s:
        assert s.version == 4 and (s.exam_views()["Desk"].q == 1).all()
        s.knowledge_base(interval="corrected")
    assert main(["kb", "show", str(path), "--interval", "corrected"]) == 0
    assert path.read_bytes() == before  # reading never migrates
    with EvidenceStore.open(path, catalog) as s:
        s.append(_exam(20, views=_views(catalog)))
        assert s.version == SCHEMA_VERSION and s.exam_views()["Desk"].n == 9
    conn = sqlite3.connect(path)
    assert conn.execute("SELECT COUNT(*) FROM views").fetchone()[0] == len(
        catalog.type("Desk").relations
    )
    conn.close()


@pytest.mark.parametrize(
    "views, problem",
    [
        ((("ON-TOP-OF-TABLE", [0.5], [0.0]),), "not a relation of Desk"),
        ((("ON-TOP-OF-DESK", [0.5, 0.5], [0.0, 0.0]),), "numbers in \\[0, 1\\]"),
        ((("ON-TOP-OF-DESK", None, None),), "numbers in \\[0, 1\\]"),
        (("ON-TOP-OF-DESK",), "views must be"),
    ],
)
def test_bad_views_are_refused_and_nothing_is_written(tmp_path, catalog, views, problem):
    path = _store(tmp_path / "s.sqlite", catalog)
    with EvidenceStore.open(path, catalog) as s:
        with pytest.raises(CtxsearchError, match=problem):
            s.append(_exam(50, views=views))
        assert s.examinations_count() == 8


def test_a_damaged_view_is_a_one_line_error(tmp_path, catalog, capsys):
    path = _store(tmp_path / "s.sqlite", catalog)
    conn = sqlite3.connect(path)
    conn.execute("UPDATE views SET recall = X'0102' WHERE examination_id = 3")
    conn.commit()
    conn.close()
    damaged = "damaged knowledge store: examination 3: recall"
    with (
        EvidenceStore.open(path, catalog, read_only=True) as s,
        pytest.raises(StoreError, match=damaged),
    ):
        s.exam_views()
    assert main(["kb", "show", str(path), "--interval", "corrected"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "examination 3" in err


def test_merge_keeps_the_views(tmp_path, catalog):
    a = _store(tmp_path / "a.sqlite", catalog)
    with EvidenceStore.open(tmp_path / "b.sqlite", catalog) as s:
        s.append(_exam(1, views=_views(catalog, recall=0.9), run="r2"))
    merge_stores(tmp_path / "m.sqlite", [a, tmp_path / "b.sqlite"], catalog)
    with EvidenceStore.open(tmp_path / "m.sqlite", catalog, read_only=True) as s:
        q = s.exam_views()["Desk"].q
    assert q.shape[0] == 9 and q[:8] == pytest.approx(0.4, abs=1e-4)
    assert q[8] == pytest.approx(0.9, abs=1e-4)


# ---- what the images could show ----------------------------------------------------------------
def test_the_volume_lattice_fills_its_box():
    box = geometry.Box(np.array([1.0, 2.0, 0.8]), 0.7, np.array([0.6, 0.2, 0.05]))
    pts = volume_lattice(box)
    c, s = np.cos(box.yaw), np.sin(box.yaw)
    d = pts - box.center
    local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
    assert (np.abs(local) <= box.half + 1e-9).all()
    assert len(pts) == 8 * 4 * 1  # at most 8 per axis, 10 cm apart
    assert np.ptp(local[:, 0]) > 0.9


@pytest.mark.parametrize("yaw", [0.0, 0.4, np.pi / 2, 2.5, -1.2])
def test_the_false_report_rate_counts_every_point_its_bounds_could_hold(catalog, yaw):
    """f from the prefiltered points (``ViewModel._grown``, then the exact test) against the
    definition over every point: 1 - exp(-sum over images of rate_B * (points whose lifted
    position lies in the volume grown by B's half size) / the image's count). The points crowd
    the grown boxes' faces, where a prefilter too tight would drop some."""
    from ctxsearch.agent.exam_views import ViewModel, _within
    from ctxsearch.envs.detector import load_detector

    vm = ViewModel(catalog, load_detector("realistic"), 1, 0.0)
    box = geometry.Box(np.array([1.0, -0.5, 0.9]), yaw, np.array([0.5, 0.3, 0.2]))
    fp = np.flatnonzero(vm._fp_rate)
    rng = np.random.default_rng(7)
    c, s = np.cos(yaw), np.sin(yaw)
    surfaces, expected = [], np.zeros(len(fp))
    for total in (4000, 9000):
        # local points on and near the grown faces of each type, and some anywhere around
        g = box.half + vm._half[fp][rng.integers(len(fp), size=total)]
        local = rng.uniform(-1.3, 1.3, (total, 3)) * g
        face = rng.integers(3, size=total)
        local[np.arange(total), face] = (
            np.sign(local[np.arange(total), face])
            * g[np.arange(total), face]
            * rng.choice([0.999, 1.0, 1.001], total)
        )
        world = (
            np.column_stack(
                [c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1], local[:, 2]]
            )
            + box.center
        )
        world[:, 2] -= vm._half[fp][rng.integers(len(fp), size=total), 2]  # as lifted points
        d = world - box.center
        lx, ly = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
        for j, t in enumerate(fp):
            hb = vm._half[t]
            lz = (world[:, 2] + hb[2]) - box.center[2]
            inside = (
                (np.abs(lx) <= box.half[0] + hb[0])
                & (np.abs(ly) <= box.half[1] + hb[1])
                & (np.abs(lz) <= box.half[2] + hb[2])
            )
            expected[j] += vm._fp_rate[t] * inside.sum() / total
        lo, hi = vm._grown(box)
        kept = world[_within(world[:, 0], world[:, 1], world[:, 2], lo, hi)]
        surfaces.append((tuple(np.ascontiguousarray(kept.T)), total))
    f = vm._false_rate(box, surfaces)
    assert (expected > 0).all()  # every false-positive type has points inside
    np.testing.assert_allclose(f[fp], 1.0 - np.exp(-expected), rtol=1e-12)
    assert (np.delete(f, fp) == 0).all()


def test_the_range_planned_to_see_shrinks_as_the_recall_asked_grows(catalog):
    from ctxsearch.agent.exam_views import EXAM_MIN_RANGE, ViewModel
    from ctxsearch.envs.camera import focal_length
    from ctxsearch.envs.detector import load_detector

    f = focal_length(58.0, 240)
    realistic = ViewModel(catalog, load_detector("realistic"), 1, 0.0)
    ranges = [realistic.exam_range(r, f, 320, 240) for r in (0.5, 0.8, 0.9, 0.94, 0.99)]
    assert ranges == sorted(ranges, reverse=True) and ranges[0] > ranges[2] > EXAM_MIN_RANGE
    assert ranges[-1] == EXAM_MIN_RANGE  # above the preset's best recall: as near as allowed
    # the threshold detector sees every object type with certainty up to its pixel limit (a pen's
    # ends near 2.3 m)
    perfect = ViewModel(catalog, load_detector("perfect"), 1, 0.0)
    assert 2.0 < perfect.exam_range(0.99, f, 320, 240) < 2.5


def test_planning_to_see_needs_a_model_of_the_detector(tmp_path, capsys):
    out = tmp_path / "k.sqlite"
    args = ["learn", "--style", "office", "--rooms", "1", "--kb", str(out)]
    assert main([*args, "--perception", "oracle", "--exam-recall", "0.9"]) == 2
    assert "--exam-recall needs the camera perception" in capsys.readouterr().err
    assert not out.exists()  # refused before the store is created
    with pytest.raises(SystemExit) as e:
        main([*args, "--exam-recall", "1.5"])
    assert e.value.code == 2


# ---- the backoff on the corrected intervals (knowledge.pooling) --------------------------------
def _surfaces(path, catalog, recall=None, tables=4):
    """Desks (20) and ``tables`` tables, one examination per room, a cup on a third of them;
    views of ``recall`` (none: no views, recall 1)."""
    with EvidenceStore.open(path, catalog) as s:
        for oid in range(1, 21 + tables):
            ref = "Desk" if oid <= 20 else "Table"
            rel = f"ON-TOP-OF-{ref.upper()}"
            cup = ((rel, "Cup", 100 + oid),) if oid % 3 == 0 else ()
            views = () if recall is None else _views(catalog, ref, recall, 0.0)
            s.append(NewExamination("r", "office", oid, oid, ref, float(oid), "hif", cup, 0, views))
    return path


def _backoffs(path, catalog):
    with EvidenceStore.open(path, catalog, read_only=True) as s:
        pooled = PooledCounts.from_store(s)
        return Backoff(pooled, 0.1), Backoff(pooled, 0.1, s.corrected_intervals(0.1)), pooled


def test_with_full_recall_and_a_room_per_examination_the_corrected_backoff_is_the_backoff(
    tmp_path, catalog
):
    plain, corr, pooled = _backoffs(_surfaces(tmp_path / "s.sqlite", catalog), catalog)
    for ref in ("Desk", "Table"):
        for rel in catalog.type(ref).relation_names:
            for b in ("Cup", "Pen", "Monitor"):
                assert corr.pseudo_counts(ref, rel, b) == pytest.approx(
                    plain.pseudo_counts(ref, rel, b), abs=1e-9
                )
    kw = {"ref": "Table", "backoff": True, "include_zero": True}
    a = interval_rows(pooled, catalog, 0.1, **kw)
    b = interval_rows(pooled, catalog, 0.1, corrected=corr.corrected, **kw)
    a = [r for r in a if r.type in catalog]  # a class on the related side has no corrected rows
    assert [(r.relation, r.type) for r in a] == [(r.relation, r.type) for r in b]
    assert np.array([[r.low, r.high] for r in a]) == pytest.approx(
        np.array([[r.low, r.high] for r in b]), abs=1e-9
    )
    ws = interval_rows(
        pooled, catalog, 0.1, ref="WorkSurface", related="Cup", corrected=corr.corrected
    )
    assert ws[0].low == pytest.approx(intervals.interval(8, 24, 0.1)[0], abs=1e-9)


def test_the_corrected_backoff_reads_the_misses_of_type_and_class(tmp_path, catalog):
    plain, corr, _ = _backoffs(_surfaces(tmp_path / "s.sqlite", catalog, recall=0.4), catalog)
    key = ("Table", "ON-TOP-OF-TABLE", "Cup")
    y, n, kappa, p_class = plain.pseudo_counts(*key)
    yc, nc, kc, pc = corr.pseudo_counts(*key)
    assert pc > p_class + 0.3  # cups were seen on a third of the desks with recall 0.4
    assert corr.estimate(*key).p > plain.estimate(*key).p + 0.2
    assert nc < n and 0 < kc <= kappa  # a look with recall 0.4 is 0.4 of an examination
    with pytest.raises(CtxsearchError, match="concrete related types"):
        corr.pseudo_counts("Table", "ON-TOP-OF-TABLE", "Container")


def test_an_entry_that_borrows_nothing_reads_its_corrected_interval(tmp_path, catalog):
    """No other work surface was examined: the desk's entries borrow nothing, and the backoff
    on the corrected intervals is the corrected interval, not Wilson on the effective counts."""
    path = _surfaces(tmp_path / "s.sqlite", catalog, recall=0.4, tables=0)
    _, corr, _ = _backoffs(path, catalog)
    key = ("Desk", "ON-TOP-OF-DESK", "Cup")
    est = corr.estimate(*key)
    assert est.kappa == 0.0 and est.p_class is None
    lo, hi = corr.corrected.interval(*key)
    assert (est.low, est.high, est.p) == (lo, hi, (lo + hi) / 2)
    wilson = intervals.interval(est.y_eff, est.n_eff, 0.1)
    assert abs(wilson[0] - lo) + abs(wilson[1] - hi) > 1e-3  # what it read before
    row = interval_rows(corr.pooled, catalog, 0.1, ref="Desk", related="Cup", backoff=True,
                        corrected=corr.corrected)  # fmt: skip
    assert {(r.low, r.high) for r in row if r.relation == key[1]} == {(lo, hi)}


def test_kb_show_backs_off_on_the_corrected_intervals(tmp_path, catalog, capsys):
    path = str(_surfaces(tmp_path / "s.sqlite", catalog, recall=0.4))
    assert (
        main(["kb", "show", path, "--type", "Table", "--backoff", "--interval", "corrected"]) == 0
    )
    out = capsys.readouterr().out
    assert "corrected intervals" in out and "ON-TOP-OF-TABLE" in out and "Container" not in out
    for bad in (["--related", "Container", "--interval", "corrected"],
                ["--backoff", "--interval", "clustered"]):  # fmt: skip
        assert main(["kb", "show", path, *bad]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err
