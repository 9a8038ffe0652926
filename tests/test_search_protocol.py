"""The search benchmark's protocol: episodes whose target is not visible from the start and can be
found, an oracle that is a lower bound, and the metrics (spl, paired ratios, episodes.csv)."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.agent.search import draw as D
from ctxsearch.agent.search import draw_store
from ctxsearch.agent.search import episode as S
from ctxsearch.agent.search import oracle as O
from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.agent.search.draw import DrawSpec, draw_world
from ctxsearch.agent.search.registry import resolve
from ctxsearch.agent.search.runner import PolicyRun, WorldRuns, search_world
from ctxsearch.envs.detector import SimDetector, load_detector
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.robot_spec import RobotPose
from ctxsearch.envs.styles import load_style
from ctxsearch.envs.world import World
from ctxsearch.scripts.experiments.bench_search import (
    aggregate,
    bench_search,
    detect_group,
    paired_ratio,
)


def draw(style, n, seed, catalog, budget, *, detector=None, cache=None):
    """The episode draw of these arguments (serial)."""
    spec = DrawSpec.make(style, n, seed, catalog, budget, detector=detector)
    return D.draw_episodes(spec, catalog, cache=cache)


def run_ep(ep, policies, catalog, style, detector):
    """Every policy of ``policies`` on ``ep`` (no probabilities), on the given map."""
    config = SearchConfig(style.name, tuple(policies)).with_scenario("given")
    runs = tuple(PolicyRun(s) for s in resolve(policies, "given"))
    return search_world(ep, style, catalog, WorldRuns(runs, config, detector))


def res(policy: str, t: float, found: bool = True, budget: float = 100.0) -> S.SearchResult:
    return S.SearchResult(policy, 0, "Cup", found, 1 if found else None, t, 3, 1.0, budget)


# =========================================================================== metrics (pure)
def test_paired_ratio_counts_wins_and_losses_per_episode():
    t = np.array([10.0, 20.0, 30.0, 40.0, 50.0])
    base = np.array([20.0, 20.0, 15.0, 80.0, 100.0])
    p = paired_ratio(t, base)
    assert (p.wins, p.losses, p.ties, p.n) == (3, 1, 1, 5)  # 10<20, 40<80, 50<100; 30>15; 20=20
    assert p.median == pytest.approx(0.5)
    assert p.ci[0] <= p.median <= p.ci[1]


def test_aggregate_gives_paired_ratios_to_every_baseline_spl_and_violations():
    results = {
        "exhaustive": [res("exhaustive", 40), res("exhaustive", 80), res("exhaustive", 30)],
        "location": [res("location", 10), res("location", 150, False), res("location", 15)],
        "oracle": [res("oracle", 5), res("oracle", 20), res("oracle", 20)],
    }
    stats = aggregate(results)
    loc = stats["location"]
    assert set(loc.paired) == {"exhaustive"}  # the baselines that ran, never itself
    pr = loc.paired["exhaustive"]
    assert (pr.wins, pr.losses) == (2, 1)  # 10 < 40, 15 < 30; the failure (100) > 80
    assert pr.median == pytest.approx(0.5)  # ratios 0.25, 1.25, 0.5
    assert stats["oracle"].spl == pytest.approx(1.0)
    assert loc.spl == pytest.approx((5 / 10 + 0 + 1.0) / 3)  # 15 s beat the oracle's 20 s
    assert loc.oracle_violations == 1 and stats["exhaustive"].oracle_violations == 0
    for st in stats.values():
        assert 0.0 <= st.spl <= 1.0
    doc = loc.to_json()
    entry = doc["paired_ratio"]["exhaustive"]
    assert (entry["median"], entry["wins"], entry["losses"], entry["n"]) == (0.5, 2, 1, 3)
    assert entry["ci"][0] <= 0.5 <= entry["ci"][1]


def test_detect_group_comes_from_the_catalog(catalog):
    assert detect_group(catalog, "Pen") == "small"
    assert detect_group(catalog, "Monitor") == "large"
    groups = {detect_group(catalog, t.name) for t in catalog.types if not t.is_furniture}
    assert groups == {"small", "large"}


# =========================================================================== episodes
@pytest.fixture(scope="module")
def office(catalog):
    return load_style("office", catalog)


@pytest.fixture(scope="module")
def drawn(office, catalog):
    return draw(office, 2, 5, catalog, 60.0)


def test_episodes_are_reproducible_and_count_what_they_leave_out(drawn, office, catalog):
    again = draw(office, 2, 5, catalog, 60.0)
    assert again.episodes == drawn.episodes
    assert again.excluded() == drawn.excluded() and again.start_redraws == drawn.start_redraws
    assert [e.index for e in drawn.episodes] == [0, 1]
    assert drawn.start_redraws + drawn.visible_at_start > 0  # most office starts see the target
    other = draw(office, 1, 6, catalog, 60.0)
    assert other.episodes[0] not in drawn.episodes


@pytest.mark.render
def test_the_target_is_never_visible_from_the_start(drawn, catalog):
    """A direct check: images from the start position, the head aimed at every target instance
    and a ring of headings at three tilts (turning in place), read by the perfect detector."""
    perfect = load_detector("perfect")
    for ep in drawn.episodes:
        layout = generate_layout(load_style(ep.style, catalog), ep.room_seed, catalog)
        with World(layout, catalog) as world:
            sim = SimDetector(perfect, layout, catalog, layout.seed)
            spec = world.spec
            views = [
                (h, t)
                for h in np.linspace(-math.pi, math.pi, 12, endpoint=False)
                for t in (-0.6, -0.25, 0.1)
            ]
            for o in layout.of_type(ep.target):
                d = np.asarray(o.position) - np.array([ep.start.x, ep.start.y, spec.camera_height])
                views.append((math.atan2(d[1], d[0]), math.atan2(d[2], math.hypot(d[0], d[1]))))
            for heading, tilt in views:
                world.reset_pose(RobotPose(ep.start.x, ep.start.y, heading, 0.0, tilt))
                dets = sim(world.capture(depth=True), world.sim_time)
                assert not [d for d in dets if d.type == ep.target], (ep, heading, tilt)


def test_an_infeasible_world_is_dropped_and_counted(office, catalog, monkeypatch):
    # A budget no view can meet: the target is not visible from the start, and every other
    # view needs a drive or a head move longer than 0.3 s.
    w = draw_world(DrawSpec.make(office, 1, 5, catalog, 0.3), catalog, 0)
    assert w.episode is None and w.dropped in ("infeasible", "visible_at_start")
    # The count: the first world's oracle finds nothing, the others are as they are.
    real = O.oracle_view
    calls = {"n": 0}

    def first_fails(*a, **kw):
        calls["n"] += 1
        return None if calls["n"] == 1 else real(*a, **kw)

    monkeypatch.setattr(D, "oracle_view", first_fails)
    d = draw(office, 1, 5, catalog, 60.0)
    assert d.infeasible == 1 and len(d.episodes) == 1


def test_a_draw_that_asks_only_whether_keeps_the_same_worlds_starts_and_drops(
    office, catalog, monkeypatch
):
    """``DrawSpec.first_view`` False (the Gymnasium task's draw): the oracle's planner stops at
    its first view that ends the search, so the same worlds are kept or dropped (one kept at a
    6 s budget, one infeasible at 3 s, realistic detector: its draws decide) from the same
    starts, with no first view kept, in fewer images."""
    from dataclasses import replace

    realistic = load_detector("realistic")
    renders = {True: 0, False: 0}
    real = O.oracle_view

    def counted(eye, *a, **kw):
        r0 = eye.renders
        out = real(eye, *a, **kw)
        renders[kw.get("soonest", True)] += eye.renders - r0
        return out

    monkeypatch.setattr(D, "oracle_view", counted)
    for budget, world, dropped in ((6.0, 2, None), (3.0, 6, "infeasible")):
        spec = DrawSpec.make(office, 1, 5, catalog, budget, detector=realistic)
        a = draw_world(spec, catalog, world)
        b = draw_world(replace(spec, first_view=False), catalog, world)
        assert (a.dropped, b.dropped) == (dropped, dropped)
        assert a.redraws == b.redraws and a.episode == b.episode
        if dropped is None:
            assert a.episode.first_view is not None and b.episode.first_view is None
            assert (a.episode.start, a.episode.target) == (b.episode.start, b.episode.target)
    assert renders[False] < renders[True]


# =========================================================================== the oracle bound
@pytest.mark.render
@pytest.mark.parametrize(
    ("detector", "n", "map_mode"),
    [("perfect", 8, "given"), ("realistic", 4, "given"), ("perfect", 4, "built")],
)
def test_no_policy_beats_the_oracle(tmp_path, detector, n, map_mode, desk_cup_store):
    """16 small episodes in both map scenarios (30 per detector with five policies on the given
    map: 0 violations, measured by hand)."""
    policies = {"given": ("exhaustive", "location", "oracle"),
                "built": ("frontier", "indirect", "oracle")}[map_mode]  # fmt: skip
    config = SearchConfig(
        style="office", policies=policies, seed=3, budget_s=15.0, detector=detector, episodes=n
    ).updated({"map.scenario": map_mode, "knowledge.kb": desk_cup_store(tmp_path / "kb.sqlite")})
    out = tmp_path / detector
    r = bench_search(config, out, progress=None, bar=False)
    doc = json.loads((out / "search.json").read_text())
    assert doc["oracle_violations"] == 0
    o = r.results["oracle"]
    assert all(x.success for x in o)  # every episode is feasible
    for name, rs in r.results.items():
        for a, b in zip(rs, o, strict=True):
            assert not a.success or a.sim_time >= b.sim_time - 1e-6, (name, a.summary(), b.log)
    assert r.stats["oracle"].spl == pytest.approx(1.0)
    assert all(0.0 <= st.spl <= 1.0 for st in r.stats.values())
    # search.json's keys and episodes.csv: one row per episode and policy
    assert doc["detector"] == detector and doc["map"] == map_mode
    assert set(doc["excluded"]) == {"visible_at_start", "infeasible"}
    assert doc["start_redraws"] >= 0
    ctx_policy, baseline = policies[1], policies[0]
    assert doc["policies"][ctx_policy]["paired_ratio"][baseline]["wins"] >= 0
    head = doc["policies"][ctx_policy]["paired"][baseline]
    assert head["n"] == n and head["wins"] + head["losses"] + head["ties"] == n
    assert set(doc["paired_by"]) == {"target_group", "start_room", "instances"}
    assert sum(c["n"] for c in doc["paired_by"]["instances"].values()) == n
    assert (out / "search.md").read_text().index("geometric mean") < (
        out / "search.md"
    ).read_text().index("t / t_")
    assert set(doc["by_group"]) <= {"small", "large"}
    assert sum(v["n"] for v in doc["by_target"].values()) == n
    with (out / "episodes.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == n * 3
    assert {(int(x["episode"]), x["policy"]) for x in rows} == {
        (i, p) for i in range(n) for p in config.policies
    }


@pytest.fixture(scope="module")
def drawn_realistic(office, catalog):
    """Two episodes drawn with the realistic detector (the first is also the one-episode draw:
    a draw's episodes are the first kept worlds in index order)."""
    return draw(office, 2, 5, catalog, 60.0, detector=load_detector("realistic", catalog))


@pytest.mark.render
def test_the_oracle_plans_on_the_episodes_clock(office, catalog, drawn_realistic):
    """The detector's draws are indexed by the seconds since the episode started, and the
    oracle plans with those: planning itself (no plan from the draw), it searches the same
    after another policy ran in the shared world (whose clock ran on) as alone."""
    from dataclasses import replace

    real = load_detector("realistic", catalog)
    eps = drawn_realistic.episodes
    for ep in (replace(e, first_view=None) for e in eps):
        alone = run_ep(ep, ["oracle"], catalog, office, real)[0]
        after = run_ep(ep, ["map-only", "oracle"], catalog, office, real)
        assert alone.success and alone.unconfirmed == 0, alone.log
        assert after[1].gazes == alone.gazes, after[1].log
        assert after[1].sim_time == pytest.approx(alone.sim_time, abs=1e-6)


@pytest.mark.render
def test_the_oracle_reads_a_view_as_the_robot_will_take_its_images(
    office, catalog, drawn_realistic
):
    """``first_success`` walks the images the robot takes one after the other at one pose: an
    image that shows the target is followed by its confirming image (two images' seconds to the
    next), the first pair that confirms a true instance ends it; none after ``until`` and at
    most ``images`` of them. And the Oracle policy, executing its first view, finds the target
    at that second plus the confirming image when its drive ends where it planned."""
    from ctxsearch.envs.floorplan import generate_layout

    real = load_detector("realistic", catalog)
    ep = drawn_realistic.episodes[0]
    layout = generate_layout(office, ep.room_seed, catalog)
    with World(layout, catalog) as w:
        eye = O.OracleEye(w, layout, catalog, real, ep.target)
        ic = w.time_model.image_cost
        # a view that shows the target well: the aimed view of the grid's cell that does best
        o = eye.instances[0]
        grid = OccupancyGrid.from_layout(layout, w.spec)
        xs, ys = grid.cell_centers()
        rows, cols = grid.lattice_cells(10)
        views = []
        for xy in np.column_stack([xs[cols], ys[rows]]):
            g = O._exact_gaze(grid, ep.start, xy, np.asarray(o.position), w.spec, w.time_model)
            if g is not None:
                views.append((eye.probability(eye.frame_at(g.pose)), g.pose))
        p, pose = max(views, key=lambda v: v[0])
        assert 0.2 < p < 0.95, p
        frame = eye.frame_at(pose)
        found = []
        for t0 in np.arange(1.0, 30.0, 1.37):
            t, steps = t0, []
            while len(steps) < 40:
                ok, seen = eye.ends_search(frame, t)
                steps.append(t)
                if ok:
                    break
                t += 2 * ic if seen else ic
            if not ok:
                assert eye.first_success(frame, t0, 1e9, 40) is None
                continue
            found.append(len(steps))
            assert eye.first_success(frame, t0, 1e9, 40) == pytest.approx(t)
            assert eye.first_success(frame, t0, t - 1e-3, 40) is None
            assert eye.first_success(frame, t0, 1e9, len(steps) - 1) is None
        assert len(found) >= 5 and min(found) == 1 and max(found) > 1, found
    res = run_ep(ep, ["oracle"], catalog, office, real)[0]
    assert res.success
    assert res.sim_time <= ep.first_view.seconds + ic + 1e-6


def _view_state(v):
    if v is None:
        return None
    g = v.gaze
    path = None if g.path is None else g.path.tolist()
    return (v.seconds, g.pose, g.target.tolist(), g.coverage, g.cost, path, v.instance_id,
            v.renders, v.key)  # fmt: skip


def test_a_kept_draw_reads_back_bit_for_bit_and_a_spoilt_one_is_drawn_again(
    drawn, office, catalog, tmp_path, monkeypatch
):
    """``--draw-cache``: the second command reads the first's draw (episodes, counts and the
    oracle's first plans, to the last bit) instead of drawing; a file of any other bytes is a
    miss, drawn again and replaced."""
    first = draw(office, 2, 5, catalog, 60.0, cache=tmp_path)
    files = list(tmp_path.glob("*.json"))
    assert len(files) == 1
    assert first.episodes == drawn.episodes
    assert any(e.first_view is not None for e in first.episodes)

    def no_draw(*a, **k):
        raise AssertionError("drew again")

    with monkeypatch.context() as m:
        m.setattr(D, "draw_world", no_draw)
        kept = draw(office, 2, 5, catalog, 60.0, cache=tmp_path)
    assert kept.episodes == first.episodes
    assert [e.start for e in kept.episodes] == [e.start for e in first.episodes]
    assert [_view_state(e.first_view) for e in kept.episodes] == [
        _view_state(e.first_view) for e in first.episodes
    ]
    assert (kept.excluded(), kept.start_redraws) == (first.excluded(), first.start_redraws)
    # Other arguments are another key.
    assert draw_store.draw_key(DrawSpec.make(office, 2, 5, catalog, 60.0)) != draw_store.draw_key(
        DrawSpec.make(office, 2, 6, catalog, 60.0)
    )
    for junk in (b"\xff\xfe[", b'{"format": 1, "episodes": [{"index": "x"}]}'):
        files[0].write_bytes(junk)
        again = draw(office, 2, 5, catalog, 60.0, cache=tmp_path)
        assert again.episodes == first.episodes
        assert draw_store.load(tmp_path, files[0].stem) is not None


def _edited(doc: dict, how: str) -> dict:
    """A kept draw's JSON changed as a hostile or stale file might be."""
    doc = json.loads(json.dumps(doc))
    eps = doc["episodes"]
    if how == "learned room":
        eps[0]["room_seed"] = eps[1]["room_seed"]  # not in index order; also the store's below
    elif how == "budget":
        for e in eps:
            e["budget_s"] = 1e-9
    elif how == "negative count":
        doc["visible_at_start"] = -3
    elif how == "one of two":
        del eps[1]
    elif how == "start far away":
        eps[0]["start"] = [1e6, -1e6, 0.0, 0.0, 0.0]
    elif how == "not held out":
        eps[0]["room_seed"] = 12345
    elif how == "another target":
        eps[0]["target"] = "Desk"
    return doc


@pytest.mark.parametrize(
    "how",
    ["learned room", "budget", "negative count", "one of two", "start far away", "not held out",
     "another target", "fifo", "deep", "zero"],
)  # fmt: skip
def test_a_kept_draw_that_is_not_the_one_asked_for_is_never_used(
    how, drawn, office, catalog, tmp_path, monkeypatch
):
    """Issue 24: a draw file is checked like any input against what the command asked (held-out
    worlds, starts in the free space, the budget and episode count, counts >= 0); a FIFO, a
    deeply nested file or an endless one is refused without blocking. Each is a miss: drawn
    again, never used."""
    import os

    spec = DrawSpec.make(office, 2, 5, catalog, 60.0)
    key = draw_store.draw_key(spec)
    path = tmp_path / f"{key}.json"
    if how == "fifo":
        os.mkfifo(path)
    elif how == "deep":
        path.write_text("[" * 100_000 + "]" * 100_000)
    elif how == "zero":
        path.symlink_to("/dev/zero")
    else:
        path.write_text(json.dumps(_edited(draw_store.to_json(drawn), how)))
    assert draw_store.load(tmp_path, key) is None or not D.check_draw(
        draw_store.load(tmp_path, key), spec, catalog
    )
    drew = []

    def fresh(*a, **k):
        drew.append(1)
        return drawn

    monkeypatch.setattr(D, "_draw_worlds", fresh)
    got = D.draw_episodes(spec, catalog, cache=tmp_path)
    assert drew == [1] and got.episodes == drawn.episodes
    assert D.check_draw(draw_store.load(tmp_path, key), spec, catalog)  # the file replaced


def test_the_kept_draw_of_the_same_spec_passes_its_check(drawn, office, catalog):
    spec = DrawSpec.make(office, 2, 5, catalog, 60.0)
    assert D.check_draw(draw_store.from_json(draw_store.to_json(drawn)), spec, catalog)
    learned = DrawSpec.make(office, 2, 5, catalog, 60.0, {drawn.episodes[0].room_seed})
    assert not D.check_draw(drawn, learned, catalog)  # a room the store learned in


def test_paired_stats_see_what_a_median_pinned_by_ties_cannot():
    """Issue 25: with half the episodes tied, the paired median sits at 1.00 while the geometric
    mean shows the effect; ties are counted apart and dropped by the signed-rank test; the power
    line grows as the effect shrinks."""
    from ctxsearch.agent.search.measures import paired_stats

    rng = np.random.default_rng(0)
    base = rng.uniform(20.0, 200.0, 300)
    t = base * np.exp(rng.normal(-0.3, 0.5, 300))
    t[:160] = base[:160]  # ties: both found in the same first image
    p = paired_stats(t, base)
    assert paired_ratio(t, base).median == pytest.approx(1.0)
    assert (p.wins + p.losses + p.ties, p.ties) == (300, 160)
    assert 0.8 < p.geo_mean < 0.9 and p.geo_mean_ci[1] < 1.0
    assert p.wilcoxon_p < 1e-6
    assert p.ratio_of_means_ci[0] <= p.ratio_of_means <= p.ratio_of_means_ci[1]
    weaker = paired_stats(np.where(t < base, (t + base) / 2, t), base)
    assert weaker.episodes_for_power > p.episodes_for_power
    same = paired_stats(base, base)
    assert (same.geo_mean, same.ties, same.wilcoxon_p, same.episodes_for_power) == (
        1.0,
        300,
        1.0,
        None,
    )
    doc = p.to_json()
    assert set(doc) == {"geo_mean", "geo_mean_ci", "ratio_of_means", "ratio_of_means_ci",
                        "wilcoxon_p", "wins", "losses", "ties", "n", "episodes_for_power"}  # fmt: skip
    from ctxsearch.agent.search.measures import geo_cell

    assert geo_cell(doc).endswith(f"{p.wins}/{p.losses}/{p.ties} p<0.001")
    assert geo_cell(weaker.to_json()).split(" p")[-1].startswith(("=", "<"))
    assert geo_cell(same.to_json()).endswith("0/0/300 p=1.000")


def test_instance_targets_keep_one_instance_of_the_target_in_the_same_worlds(office, catalog):
    """``--targets instance`` ("find my phone"): every episode's world keeps exactly one instance
    of its target (what rests on the others goes with them), drawn from the same held-out worlds
    in the same order as ``type``; ``type`` draws as before (the episode has no kept instance)."""
    from dataclasses import replace

    from ctxsearch.knowledge.options import Targets

    spec = DrawSpec.make(office, 3, 5, catalog, 60.0)
    by_type = D.draw_episodes(spec, catalog)
    inst = D.draw_episodes(replace(spec, targets=Targets.INSTANCE), catalog)
    assert all(e.instance is None for e in by_type.episodes)
    held = [S.held_out_seed(5, i) for i in range(300)]
    order = [held.index(e.room_seed) for e in inst.episodes]
    assert order == sorted(order) and len(inst.episodes) == 3
    for ep in inst.episodes:
        whole = generate_layout(office, ep.room_seed, catalog)
        world = S.episode_layout(whole, ep)
        assert [o.id for o in world.of_type(ep.target)] == [ep.instance]
        assert {o.id for o in whole.objects} - {o.id for o in world.objects} >= {
            o.id for o in whole.of_type(ep.target) if o.id != ep.instance
        }
        assert all(s in {o.id for o in world.objects} or s is None for s in world.support.values())
    assert D.check_draw(inst, replace(spec, targets=Targets.INSTANCE), catalog)
    assert not D.check_draw(inst, spec, catalog)  # not the type draw
