"""Object search: the pure parts (detectability, regions, scores, indirect decision, bootstrap,
episodes) and the policies on a hand-made room (render-marked)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.agent.search import episode as S
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.agent.search.draw import DrawSpec, make_episodes
from ctxsearch.agent.search.maps import WorldMaps
from ctxsearch.agent.search.measures import bootstrap_ci
from ctxsearch.agent.search.policies import SearchPolicy
from ctxsearch.agent.search.registry import POLICIES, parse_policies, resolve
from ctxsearch.agent.search.runner import EpisodeWorld, PolicyRun, WorldRuns, search_world
from ctxsearch.envs.layout import Door, RoomLayout
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, TimeModel
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import Box, ObjectInstance
from ctxsearch.knowledge.options import MapMode
from ctxsearch.scripts.experiments.bench_search import aggregate

# A hand-made room: a desk against the north wall with a cup on it, a shelf against the west wall.
DESK = ObjectInstance("Desk", 1, (0.0, 1.55, 0.37), -math.pi / 2, (0.7, 1.4, 0.74))
SHELF = ObjectInstance("Shelf", 2, (-2.2, -0.2, 0.8), 0.0, (0.35, 1.0, 1.6))
CUP = ObjectInstance("Cup", 3, (0.2, 1.5, 0.79), 0.0, (0.08, 0.08, 0.10))
START = RobotPose(0.0, -0.6, math.pi / 2)  # 2.1 m south of the desk, facing it


def prepare_named(er: EpisodeWorld, ep, name: str, probs=None, rec=None):
    """``er.prepare`` of policy ``name`` in the room's scenario."""
    (spec,) = resolve((name,), er.config.scenario)
    return er.prepare(ep, PolicyRun(spec, probs), rec)


def room(*objects: ObjectInstance) -> RoomLayout:
    return RoomLayout(
        style="test",
        seed=0,
        width=5.0,
        depth=4.0,
        height=2.8,
        door=Door("south", 1.5, 0.9),
        objects=tuple(objects),
        support={},
        placed_by={},
    )


def Cam(position, heading, tilt, width=320, height=240, fovy=58.0):  # noqa: N802
    """A camera for SeenMap.update."""
    from ctxsearch.envs.camera import PinholeCamera, camera_axes

    return PinholeCamera(
        np.asarray(position, float), camera_axes(heading, tilt), fovy, width, height
    )


# =========================================================================== pure parts
def test_effective_range_orders_types_and_respects_max_range(catalog):
    spec = RobotSpec()
    r = {t: ss.effective_range(catalog.type(t), spec) for t in ("Desk", "Cup", "Pen", "Monitor")}
    assert r["Pen"] < r["Cup"] < r["Monitor"] <= r["Desk"]
    for t in catalog.types:
        assert 0 < ss.effective_range(t, spec) <= t.max_range


def test_seen_map_excludes_furniture_solids_and_records_visible_points(catalog):
    seen = ss.SeenMap.for_room(room(DESK, SHELF), catalog)
    # No lattice point inside the desk's top board.
    top = Box(np.array([0.0, 1.55, 0.72]), -math.pi / 2, np.array([0.35, 0.7, 0.02]))
    assert not top.contains_points(seen.points).any()
    cam = Cam((0.0, -0.6, 1.2), math.pi / 2, -0.4)
    depth = np.full((240, 320), 50.0)  # nothing in the way
    mask = seen.update(cam, depth)
    assert mask.sum() > 100
    assert np.isfinite(seen.best[mask]).all()
    assert seen.seen_fraction(100.0) == pytest.approx(mask.mean())
    # A wall 1 m away hides everything behind it.
    seen2 = ss.SeenMap.for_room(room(DESK, SHELF), catalog)
    m2 = seen2.update(cam, np.full((240, 320), 1.0))
    assert m2.sum() < mask.sum()
    assert (
        np.linalg.norm(seen2.points[m2] - cam.position, axis=1) < 1.0 / math.cos(0.9) + 0.2
    ).all()


def test_regions_merge_duplicates_and_count_shared_space_once():
    pts_a = np.arange(0, 100)
    pts_b = np.arange(5, 100)  # nearly the same space as a
    pts_c = np.arange(200, 260)
    box = Box(np.zeros(3), 0.0, np.ones(3))
    regs = [
        ss.Region(box, 0.5, [("NEAR-DESK", 1)], pts_a),
        ss.Region(box, 0.4, [("NEAR-MONITOR", 2)], pts_b),
        ss.Region(box, 0.3, [("ON-SHELF", 3)], pts_c),
    ]
    merged = ss.merge_regions(regs)
    assert len(merged) == 2
    assert merged[0].p == pytest.approx(1 - 0.5 * 0.6)
    assert sorted(merged[0].members) == [("NEAR-DESK", 1), ("NEAR-MONITOR", 2)]
    unseen = np.ones(300, bool)
    p = ss.region_probabilities(merged, unseen)
    assert p == pytest.approx([0.7, 0.3])
    # Looking into half of the first region halves what is left there.
    unseen[:50] = False
    p = ss.region_probabilities(merged, unseen)
    assert p[0] == pytest.approx(0.7 * 50 / 100)
    assert p[1] == pytest.approx(0.3)


def test_overlapping_region_gets_mass_of_both():
    box = Box(np.zeros(3), 0.0, np.ones(3))
    near_desk = ss.Region(box, 0.5, [("NEAR-DESK", 1)], np.arange(0, 100))
    near_tw = ss.Region(box, 0.5, [("NEAR-MONITOR", 2)], np.arange(80, 120))  # overlaps 20 points
    p = ss.region_probabilities([near_desk, near_tw], np.ones(200, bool))
    # Each region holds its own mass plus the other's share of their 20 common points.
    assert p[0] == pytest.approx(1 - (1 - 0.5) * (1 - 0.5 * 20 / 40))
    assert p[1] == pytest.approx(1 - (1 - 0.5) * (1 - 0.5 * 20 / 100))


def test_kb_probabilities_rank_modes(catalog):
    kb = KnowledgeBase(catalog)
    for i in range(10):
        kb.record_examination("Desk", [("ON-TOP-OF-DESK", "Cup")] if i < 6 else [])
    lo, hi = kb.interval("ON-TOP-OF-DESK", "Cup")
    assert ss.KBProbabilities(kb, "low").p("ON-TOP-OF-DESK", "Cup") == pytest.approx(lo)
    assert ss.KBProbabilities(kb, "high").p("ON-TOP-OF-DESK", "Cup") == pytest.approx(hi)
    p0 = ss.KBProbabilities(kb, "p0").p("ON-TOP-OF-DESK", "Cup")
    assert lo < p0 < hi
    with pytest.raises(CtxsearchError, match="unknown rank"):
        ss.KBProbabilities(kb, "middle")


def test_indirect_plan_prefers_easy_related_type_when_it_pays(catalog):
    probs = ss.TableProbabilities({("ON-TOP-OF-DESK", "Pen"): 0.8, ("NEAR-CHAIR", "Pen"): 0.05})
    cover = {"Pen": 200.0, "Desk": 10.0, "Chair": 10.0}
    look = {"Desk": 8.0, "Chair": 8.0}
    plans = ss.indirect_plan("Pen", catalog, probs, cover, look, ["Desk", "Chair"])
    assert plans[0].via == "Desk"
    assert plans[0].cost == pytest.approx(5 + 8 + 0.2 * 100)
    # An easy target: looking for it directly is cheaper than any detour.
    cover_easy = {"Pen": 12.0, "Desk": 10.0, "Chair": 10.0}
    assert (
        ss.indirect_plan("Pen", catalog, probs, cover_easy, look, ["Desk", "Chair"])[0].via is None
    )
    # Unrelated intermediates are never proposed.
    none = ss.TableProbabilities({})
    assert [o.via for o in ss.indirect_plan("Pen", catalog, none, cover, look, ["Desk"])] == [None]


def test_indirect_plan_counts_instances_per_room(catalog):
    doc = {
        "samples": 10,
        "entries": [
            {"ref": "Desk", "relation": "ON-TOP-OF-DESK", "type": "Pen", "p": 0.4, "n": 30},
            {"ref": "Chair", "relation": "NEAR-CHAIR", "type": "Pen", "p": 0.4, "n": 2},
        ],
    }
    probs = ss.TableProbabilities.from_truth(doc)
    assert probs.instances("Desk") == pytest.approx(3.0) and probs.instances(
        "Chair"
    ) == pytest.approx(0.2)
    cover = {"Pen": 100.0, "Desk": 10.0, "Chair": 10.0}
    plans = {
        o.via: o
        for o in ss.indirect_plan(
            "Pen", catalog, probs, cover, {"Desk": 2.0, "Chair": 2.0}, ["Desk", "Chair"]
        )
    }
    # Three desks per room: the pen is near one of them with 1 - 0.6^3; chairs are rare.
    assert plans["Desk"].q == pytest.approx(1 - 0.6**3)
    present = 1 - math.exp(-3.0)
    assert plans["Desk"].cost == pytest.approx(
        present * (5 + 2 + 0.6**3 * 50) + (1 - present) * (10 + 50)
    )
    assert plans["Chair"].cost > plans["Desk"].cost


def test_coverage_viewpoints_cover_the_room_within_range(catalog):
    lay = room(DESK, SHELF)
    grid = OccupancyGrid.from_layout(lay)
    seen = ss.SeenMap.for_room(lay, catalog)
    for rng in (1.5, 3.0):
        sites = ss.coverage_viewpoints(grid, seen.points, START.xy, rng)
        assert len(sites) >= 1 and grid.free_mask(sites).all()
        cams = np.column_stack([sites, np.full(len(sites), RobotSpec().camera_height)])
        d = np.linalg.norm(cams[:, None, :] - seen.points[None], axis=-1).min(0)
        assert np.mean(d <= rng) >= 0.9
    assert len(ss.coverage_viewpoints(grid, seen.points, START.xy, 1.5)) > len(
        ss.coverage_viewpoints(grid, seen.points, START.xy, 3.0)
    )


def _dense_coverage_choice(grid, points, start_xy, max_range, goal=0.95):
    """The greedy cover as first written: every candidate against every point, candidates by
    rows (the definition ``coverage_viewpoints`` must equal)."""
    cand = ss.lattice_candidates(grid, start_xy, 0.5)
    cams = np.column_stack([cand, np.full(len(cand), RobotSpec().camera_height)])
    d = np.sqrt(((cams[:, None, :2] - points[None, :, :2]) ** 2).sum(-1)
                + (cams[:, None, 2] - points[None, :, 2]) ** 2)  # fmt: skip
    cover = d <= max_range
    need, got, gain, chosen = (
        math.ceil(goal * cover.any(0).sum()),
        ~cover[0] & False,
        cover.sum(1),
        [],
    )
    while got.sum() < need and len(chosen) < 40 and gain.max() > 0:
        chosen.append(int(np.argmax(gain)))
        new = cover[chosen[-1]] & ~got
        got, gain = got | new, gain - cover[:, new].sum(1)
    return ss.tour_order(grid, cand[chosen], start_xy)


def test_coverage_viewpoints_are_the_dense_greedy_cover(catalog):
    """The cover measured only for the points near each chunk of candidates, by points' rows,
    chooses the sites of the dense greedy cover, in the same tour order."""
    big = dataclasses.replace(room(DESK, SHELF), width=12.0, depth=9.0)  # 7 chunks of candidates
    for seed, lay in enumerate((big, room(DESK))):
        grid = OccupancyGrid.from_layout(lay)
        rand = np.random.default_rng(seed)  # points anywhere, so each near-miss counts
        pts = rand.uniform(-1.0, 1.0, (3000, 3)) * (lay.width / 2, lay.depth / 2, 1.0) + (0, 0, 1)
        for rng, goal in ((0.8, 1.0), (1.5, 1.0), (3.0, 0.95)):
            got = ss.coverage_viewpoints(grid, pts, START.xy, rng, goal=goal)
            want = _dense_coverage_choice(grid, pts, START.xy, rng, goal)
            assert np.array_equal(got, want), rng
            assert len(got) >= 1


def test_sweep_skips_seen_directions():
    spec = RobotSpec()
    pts = np.array([[2.0, 0.0, 1.0]] * 20 + [[-2.0, 0.0, 1.0]] * 20, float)
    unseen = np.ones(len(pts), bool)
    g = ss.sweep_gazes(np.zeros(2), 0.0, pts, unseen, spec, 3.0)
    assert len(g) == 2
    unseen[:20] = False
    g = ss.sweep_gazes(np.zeros(2), 0.0, pts, unseen, spec, 3.0)
    assert len(g) == 1 and abs(abs(g[0].heading) - math.pi) < 0.6


def test_bootstrap_is_seeded_and_brackets_the_median():
    v = np.arange(1, 41, dtype=float)
    a = bootstrap_ci(v, seed=3)
    assert a == bootstrap_ci(v, seed=3)
    assert a[0] <= np.median(v) <= a[1]
    assert math.isnan(bootstrap_ci([], seed=0)[0])


def test_aggregate_counts_failures_at_the_budget():
    def res(policy, t, found):
        return S.SearchResult(policy, 0, "Cup", found, 1 if found else None, t, 3, 1.0, 100.0)

    stats = aggregate(
        {
            "exhaustive": [res("exhaustive", 40, True), res("exhaustive", 80, True)],
            "location": [res("location", 10, True), res("location", 150, False)],
        }
    )
    assert stats["location"].success_rate == 0.5
    assert stats["location"].median_s == pytest.approx((10 + 100) / 2)
    assert stats["location"].ratio_to_exhaustive == pytest.approx(55 / 60)


def test_held_out_seeds_differ_from_learning_seeds():
    from ctxsearch.agent.learning import room_seed

    learn = {room_seed(0, i) for i in range(200)}
    search = {S.held_out_seed(0, i) for i in range(200)}
    assert not learn & search
    assert S.held_out_seed(0, 5) == S.held_out_seed(0, 5) != S.held_out_seed(1, 5)


def test_episodes_are_deterministic_and_skip_excluded_rooms(catalog):
    from ctxsearch.envs.styles import load_style

    style = load_style("office", catalog)
    a = make_episodes(DrawSpec.make(style, 2, 7, catalog, 60.0), catalog)
    assert a == make_episodes(DrawSpec.make(style, 2, 7, catalog, 60.0), catalog)
    assert all(not catalog.type(e.target).is_furniture for e in a)
    b = make_episodes(DrawSpec.make(style, 2, 7, catalog, 60.0, {a[0].room_seed}), catalog)
    assert a[0].room_seed not in {e.room_seed for e in b}
    c = make_episodes(DrawSpec.make(style, 1, 7, catalog, 60.0, target="Pen"), catalog)
    assert all(e.target == "Pen" for e in c)


def test_a_draw_checks_no_world_beyond_its_last_episode_unless_workers_share_it(catalog):
    """One after the other, a draw checks the worlds up to the last episode it takes; with
    several workers a round is at least two per worker. The same episodes and counts either way."""
    from ctxsearch.agent.search.draw import draw_episodes, serial_worlds
    from ctxsearch.envs.styles import load_style

    spec = DrawSpec.make(load_style("office", catalog), 1, 7, catalog, 60.0)
    checked: dict[int, list[int]] = {}

    def counting(workers):
        def run(check, indices, desc):
            checked.setdefault(workers, []).extend(indices)
            return serial_worlds(check, indices, desc)

        return draw_episodes(spec, catalog, workers=workers, runner=run)

    one, two = counting(1), counting(2)
    assert one == two
    last = S.held_out_seed(7, max(checked[1]))
    assert last == one.episodes[-1].room_seed  # the last world checked is the one taken
    assert len(checked[2]) % 4 == 0 and len(checked[2]) >= len(checked[1])  # rounds of 4


def test_unknown_policy_and_rank_are_one_line_errors():
    with pytest.raises(CtxsearchError, match="unknown search policy 'psychic'"):
        resolve(("psychic",), MapMode.GIVEN)
    with pytest.raises(CtxsearchError, match="unknown rank"):
        parse_policies("location@middle")
    assert parse_policies("exhaustive, location@low") == ["exhaustive", "location@low"]


# =========================================================================== policies (rendered)
def _episode_room(layout: RoomLayout, catalog, world, mode=MapMode.GIVEN) -> EpisodeWorld:
    """The hand-made room in scenario ``mode`` (perfect detector), as the episode runner builds
    it."""
    maps = WorldMaps.for_mode(mode, layout, catalog, world.spec)
    config = SearchConfig().with_scenario(mode)
    given = WorldMaps.given(layout, catalog, world.spec)
    return EpisodeWorld(layout, catalog, world, maps, config, given)


def _run(policy: str, layout: RoomLayout, catalog, probs=None, budget=120.0, world=None, mode=None):
    from ctxsearch.envs.world import World

    ep = S.Episode(0, "test", 0, "Cup", START, budget)
    own = world is None
    world = world or World(layout, catalog)
    try:
        mode = mode or POLICIES[policy].maps[-1]
        er = _episode_room(layout, catalog, world, mode)
        (spec,) = resolve((policy,), mode)
        pol, ctx = er.prepare(ep, PolicyRun(spec, probs))
        return er.judged(pol.run(ctx)), ctx
    finally:
        if own:
            world.close()


@pytest.mark.render
def test_every_policy_finds_a_cup_in_plain_sight(catalog):
    from ctxsearch.envs.world import World

    layout = room(DESK, SHELF, CUP)
    probs = ss.TableProbabilities({("ON-TOP-OF-DESK", "Cup"): 0.8, ("ON-SHELF", "Cup"): 0.2})
    with World(layout, catalog) as world:
        for name in POLICIES:
            res, _ = _run(name, layout, catalog, probs, world=world)
            assert res.success, (name, res.log)
            assert res.found_id == CUP.id
            assert 0 < res.sim_time < 60 and res.gazes >= 1
            assert len(res.trace) == res.gazes
            assert res.trace[-1].detections and ("Cup", CUP.id) in res.trace[-1].detections


@pytest.mark.render
def test_location_puts_the_belief_where_the_store_ranks_highest(catalog, tmp_path):
    from ctxsearch.knowledge.store import EvidenceStore

    # A crafted store: cups are always on shelves, never on desks.
    with EvidenceStore.open(tmp_path / "kb.sqlite", catalog, create=True) as store:
        for i in range(12):
            store.record(
                run="t",
                style="test",
                room_seed=i,
                object_id=1,
                ref_type="Shelf",
                sim_time=0.0,
                strategy="t",
                related=[("ON-SHELF", "Cup", 9)],
            )
            store.record(
                run="t",
                style="test",
                room_seed=i,
                object_id=2,
                ref_type="Desk",
                sim_time=0.0,
                strategy="t",
                related=[],
            )
        kb = store.knowledge_base()
    layout = room(DESK, SHELF)  # no cup: what matters is where the belief puts the mass

    def masses(kb) -> tuple[float, float]:
        """The belief's mass on the shelf's boards and on the desk's top before any image."""
        from ctxsearch.agent.search.online import OnlineSearch
        from ctxsearch.envs.world import World
        from ctxsearch.knowledge.geometry import relation_volume

        probs = ss.KBProbabilities(kb, "p0")
        with World(layout, catalog) as world:
            er = _episode_room(layout, catalog, world, "given")
            ep = S.Episode(0, "test", 0, "Cup", START, 30.0)
            _, ctx = prepare_named(er, ep, "location", probs)
            w = OnlineSearch(ctx, probs).belief().weights
        rels = {r.name: r for t in ("Shelf", "Desk") for r in catalog.type(t).relations}
        shelf = ctx.seen.in_box(relation_volume(rels["ON-SHELF"], SHELF))
        desk = ctx.seen.in_box(relation_volume(rels["ON-TOP-OF-DESK"], DESK))
        return float(w[shelf].sum()), float(w[desk].sum())

    on_shelf, on_desk = masses(kb)
    assert on_shelf > 3 * on_desk
    # With the evidence reversed (cups on desks), the desk top holds the mass.
    kb2 = KnowledgeBase(catalog)
    for _ in range(12):
        kb2.record_examination("Desk", [("ON-TOP-OF-DESK", "Cup")])
        kb2.record_examination("Shelf", [])
    on_shelf, on_desk = masses(kb2)
    assert on_desk > 3 * on_shelf


@pytest.mark.render
def test_paired_benchmark_gives_every_policy_the_same_episodes(catalog, monkeypatch):
    from ctxsearch.envs.styles import load_style

    style = load_style("office", catalog)
    eps = make_episodes(DrawSpec.make(style, 2, 11, catalog, budget_s=6.0), catalog)
    seen: list[tuple] = []
    orig = SearchPolicy.run

    def spy(self, ctx):
        episode, p, maps = ctx.episode, ctx.body.pose(), ctx.maps
        seen.append(
            (
                self.name,
                episode.index,
                episode.room_seed,
                episode.target,
                (episode.start.x, episode.start.y),
                (round(p.x, 4), round(p.y, 4), round(p.yaw, 4)),
                len(ctx.known),
                ctx.seen.seen_fraction(99.0),
                tuple(sorted(o.id for o in maps.furniture)),
                round(ctx.elapsed, 6),
            )
        )
        return orig(self, ctx)

    monkeypatch.setattr(SearchPolicy, "run", spy)
    kb = KnowledgeBase(catalog)
    kb.record_examination("Desk", [("ON-TOP-OF-DESK", "Cup")])
    policies = ["exhaustive", "location", "oracle"]

    specs = resolve(policies, MapMode.GIVEN)
    config = SearchConfig(style.name, tuple(policies)).with_scenario(MapMode.GIVEN)
    probs = {"location": ss.KBProbabilities(kb, "p0")}
    runs = tuple(PolicyRun(s, probs.get(s.name)) for s in specs)
    results = {p: [] for p in policies}
    for ep in eps:
        for p, r in zip(
            policies, search_world(ep, style, catalog, WorldRuns(runs, config)), strict=True
        ):
            results[p].append(r)
    assert [len(results[p]) for p in policies] == [2, 2, 2]
    for i, ep in enumerate(eps):
        rows = [r for r in seen if r[1] == i]
        assert [r[0] for r in rows] == policies
        assert (
            len({r[1:] for r in rows}) == 1
        )  # same room, target, start pose, nothing known or seen
        assert rows[0][2] == ep.room_seed
        assert rows[0][5] == pytest.approx((ep.start.x, ep.start.y, ep.start.yaw), abs=1e-3)
        assert {results[p][i].target for p in policies} == {ep.target}


@pytest.mark.render
def test_budget_ends_an_episode(catalog):
    layout = room(DESK, SHELF)  # no cup anywhere
    res, _ = _run("exhaustive", layout, catalog, budget=5.0)
    assert not res.found and not res.success
    assert res.time_to_find == 5.0
    assert res.sim_time < 5.0 + 5.0  # stops at the first check after the budget


def test_time_model_charges_match_result(catalog):
    """SearchResult.time_to_find is the budget for failures and the time for successes."""
    r = S.SearchResult("x", 0, "Cup", True, 3, 12.5, 4, 2.0, 60.0)
    assert r.success and r.time_to_find == 12.5
    r = S.SearchResult("x", 0, "Cup", True, 3, 70.0, 4, 2.0, 60.0)
    assert not r.success and r.time_to_find == 60.0
    assert TimeModel().image_cost > 0


@pytest.mark.render
def test_search_recording_shows_candidates_path_and_camera_views(catalog, tmp_path):
    import rerun as rr

    from ctxsearch.agent.recording import Recorder
    from ctxsearch.envs.world import World

    layout = room(DESK, SHELF, CUP)
    probs = ss.TableProbabilities({("ON-TOP-OF-DESK", "Cup"): 0.8, ("ON-SHELF", "Cup"): 0.2})
    path = tmp_path / "search.rrd"
    ep = S.Episode(0, "test", 0, "Cup", RobotPose(-1.5, -1.2, 0.0), 120.0)
    with World(layout, catalog) as world, Recorder(path) as rec:
        rec.log_room(layout, catalog)
        er = _episode_room(layout, catalog, world)
        pol, ctx = prepare_named(er, ep, "location", probs, rec)
        res = er.judged(pol.run(ctx))
    assert res.success
    entities = {c.entity_path for c in rr.chunk.RrdReader(path).stream()}
    expected = {  # found in the look around: the belief, no candidate volume yet
        "/world/search/belief",
        "/world/search/found",
        "/world/robot",
        "/world/camera/image/rgb",
        "/world/camera/image/segmentation",
        "/log",
    }
    assert expected <= entities, expected - entities


@pytest.mark.render
def test_a_detection_of_the_target_ends_the_search_only_once_a_second_image_confirms_it(catalog):
    """A false positive of the target type seen once is forgotten (the search goes on and finds
    the real cup); the confirming image costs one image's seconds."""
    from dataclasses import replace as dc_replace

    from ctxsearch.envs.detector import Detection
    from ctxsearch.envs.world import World

    layout = room(DESK, SHELF, CUP)
    fake_pose = dc_replace(CUP, id=-7, position=(-1.5, 1.0, 0.79))
    fake = Detection(-7, "Cup", fake_pose, 0, 2.0, (0, 0, 0, 0), 0.3)
    with World(layout, catalog) as world:
        ep = S.Episode(0, "test", 0, "Cup", START, 120.0)
        er = _episode_room(layout, catalog, world)
        pol, ctx = prepare_named(er, ep, "exhaustive", None)
        real = ctx.perception.detector
        calls = []

        def detector(frame, t):
            calls.append(ctx.elapsed)
            dets = real(frame, t)
            return [fake, *[d for d in dets if d.type != "Cup"]] if len(calls) == 1 else dets

        ctx.perception.detector = detector
        res = er.judged(pol.run(ctx))
    assert res.unconfirmed == 1 and len(calls) >= 4
    assert res.success and res.found_id == CUP.id
    assert -7 not in ctx.known
    assert any("not confirmed" in line for line in res.log)
    # the last two images: the one that saw the cup and the one that confirmed it
    assert [g.purpose for g in res.trace[-1:]] == ["confirm"]
    assert ("Cup", CUP.id) in res.trace[-2].detections
    assert res.trace[-1].t - res.trace[-2].t == pytest.approx(TimeModel().image_cost)
