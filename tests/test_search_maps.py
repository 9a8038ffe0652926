"""The two map scenarios of object search (issue 12, point 2) and indirect search against Wixson
& Ballard's model (point 7): what the built scenario knows, frontier, map-only, the scenario
checks, the recorded intermediate, determinism."""

from __future__ import annotations

import contextlib
import math
import subprocess
import sys
from collections.abc import Sequence

import numpy as np
import pytest

from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.agent.search import episode as S
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search import viewpoints as sx
from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.agent.search.frontier import Explorer
from ctxsearch.agent.search.maps import WorldMaps
from ctxsearch.agent.search.registry import default_policies, resolve
from ctxsearch.agent.search.runner import EpisodeWorld, PolicyRun
from ctxsearch.envs.layout import Door, RoomLayout
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, TimeModel
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.options import MapMode
from ctxsearch.scripts.experiments.bench_indirect import NONE_PREDICTED, indirect_analysis

DESK = ObjectInstance("Desk", 1, (0.0, 1.55, 0.37), -math.pi / 2, (0.7, 1.4, 0.74))
SHELF = ObjectInstance("Shelf", 2, (-2.2, -0.2, 0.8), 0.0, (0.35, 1.0, 1.6))
CUP = ObjectInstance("Cup", 3, (0.2, 1.5, 0.79), 0.0, (0.08, 0.08, 0.10))
PEN = ObjectInstance("Pen", 4, (-0.2, 1.6, 0.75), 0.3, (0.14, 0.012, 0.012))
START = RobotPose(0.0, -1.2, -math.pi / 2)  # facing away from the desk: nothing in view


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


def _room(layout, catalog, world, scenario="built") -> EpisodeWorld:
    """The hand-made room in ``scenario`` (perfect detector), as the episode runner builds it."""
    maps = WorldMaps.for_mode(MapMode(scenario), layout, catalog, world.spec)
    config = SearchConfig().with_scenario(scenario)
    return EpisodeWorld(
        layout, catalog, world, maps, config, WorldMaps.given(layout, catalog, world.spec)
    )


def _run(policy, layout, catalog, world, target="Cup", probs=None, scenario="built", budget=200.0):
    ep = S.Episode(0, "test", 0, target, START, budget)
    er = _room(layout, catalog, world, scenario)
    pol, ctx = prepare_named(er, ep, policy, probs)
    return er.judged(pol.run(ctx)), ctx


# =========================================================================== pure parts
def test_built_scenario_knows_no_furniture_and_no_free_cell(catalog):
    layout = room(DESK, SHELF, CUP)
    maps = WorldMaps.built(layout, catalog, RobotSpec())
    assert maps.map == "built" and maps.furniture == ()
    assert not maps.grid.free.any()
    given = WorldMaps.given(layout, catalog, RobotSpec())
    assert given.map == "given" and {o.id for o in given.furniture} == {DESK.id, SHELF.id}
    # The built seen map's lattice does not know where the furniture's solid parts are.
    assert len(maps.seen) > len(given.seen)


def test_visible_cells_stop_at_the_first_blocked_cell():
    blocked = np.zeros((20, 20), bool)
    blocked[:, 10] = True  # a wall at x in [2.0, 2.2)
    vis = sx.visible_cells(blocked, (0.0, 0.0), np.array([1.0, 2.0]), 3.0)
    assert vis[10, 5] and vis[10, 10]  # open floor and the wall itself
    assert not vis[10, 11:].any()  # nothing behind the wall


def test_efficiency_model_predicts_a_gain_only_for_a_related_easier_type(catalog):
    tm = TimeModel()
    size = sx.WorldSize(120.0, 5)
    ranges = {"Pen": 1.0, "Desk": 9.0}
    related = ss.TableProbabilities({("ON-TOP-OF-DESK", "Pen"): 0.9}, per_room={"Desk": 2.0})
    plan = sx.predicted_plan("Pen", catalog, related, size, ranges, tm, ["Desk"])
    assert sx.predicted_gain(plan, "Desk") > 1.0
    unrelated = ss.TableProbabilities({("ON-TOP-OF-DESK", "Pen"): 0.01}, per_room={"Desk": 2.0})
    plan = sx.predicted_plan("Pen", catalog, unrelated, size, ranges, tm, ["Desk"])
    assert sx.predicted_gain(plan, "Desk") < 1.0


def test_policy_scenario_mismatch_is_a_one_line_error():
    with pytest.raises(CtxsearchError, match="policy 'location' needs --map given"):
        resolve(["frontier", "location@low"], "built")
    with pytest.raises(CtxsearchError, match="policy 'frontier' needs --map built"):
        resolve(["frontier"], "given")
    with pytest.raises(CtxsearchError, match="unknown map"):
        resolve(["oracle"], "drawn")
    resolve(["indirect", "oracle"], "given")  # both scenarios
    for scenario in MapMode:
        resolve(default_policies(scenario), scenario)


def test_cli_policy_scenario_mismatch_exits_2_with_one_line(tmp_path):
    cmd = [sys.executable, "-m", "ctxsearch.scripts.cli", "bench", "search", "--kb", str(tmp_path / "k"),
           "--style", "apartment", "--policies", "frontier,location", "--out", str(tmp_path / "o")]  # fmt: skip
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    assert p.stderr.strip() == "ctxsearch: error: policy 'location' needs --map given"


def test_indirect_analysis_groups_by_intermediate():
    eps = [S.Episode(i, "test", i, "Pen", START, 100.0) for i in range(3)]

    def res(name, t, via=None, gain=None):
        return S.SearchResult(name, 0, "Pen", True, 1, t, 1, 0.0, 100.0, [], [], via, gain)

    results = {
        "indirect": [res("indirect", 10, "Desk", 2.0), res("indirect", 30, "Desk", 1.5),
                     res("indirect", 20, None, 0.4)],
        "frontier": [res("frontier", 40), res("frontier", 20), res("frontier", 20)],
    }  # fmt: skip
    doc = indirect_analysis(eps, results)
    g = doc["groups"]
    assert g["Desk"]["episodes"] == 2 and g["Desk"]["wins"] == 1 and g["Desk"]["losses"] == 1
    assert g["Desk"]["predicted_gain"] == pytest.approx(1.75)
    assert g[NONE_PREDICTED]["measured_ratio"] == pytest.approx(1.0)
    assert g["all"]["episodes"] == 3


# =========================================================================== rendered
@pytest.mark.render
def test_frontier_finds_a_cup_out_of_view_and_its_map_starts_unknown(catalog):
    from ctxsearch.envs.world import World

    layout = room(DESK, SHELF, CUP)
    with World(layout, catalog) as world:
        ep = S.Episode(0, "test", 0, "Cup", START, 200.0)
        _, ctx = prepare_named(_room(layout, catalog, world), ep, "frontier", None)
        assert ctx.built is not None and ctx.built.unknown.mean() > 0.95
        assert ctx.known == {} and ctx.furniture_map() == []
        res, ctx = _run("frontier", layout, catalog, world)
        again, _ = _run("frontier", layout, catalog, world)
    assert res.success and res.found_id == CUP.id and res.sim_time < 200.0, res.log
    assert ctx.built.images == res.gazes and ctx.built.floor.sum() > 500
    # Determinism: the same episode gives the same search.
    assert again.sim_time == res.sim_time and again.gazes == res.gazes
    assert [g.pose for g in again.trace] == [g.pose for g in res.trace]


@pytest.mark.render
def test_map_only_looks_into_the_furniture_volumes_without_probabilities(catalog):
    from ctxsearch.envs.world import World

    layout = room(DESK, SHELF, CUP)
    with World(layout, catalog) as world:
        res, _ = _run("map-only", layout, catalog, world, scenario="given")
    assert res.success and res.found_id == CUP.id, res.log
    assert any(g.purpose.startswith("region ") for g in res.trace)
    assert any("tour of" in line for line in res.log)


@pytest.mark.render
def test_indirect_records_the_intermediate_it_searched_for(catalog):
    from ctxsearch.envs.world import World

    layout = room(DESK, SHELF, PEN)
    probs = ss.TableProbabilities(
        {("ON-TOP-OF-DESK", "Pen"): 0.95, ("ON-SHELF", "Pen"): 0.01}, per_room={"Desk": 3.0}
    )
    with World(layout, catalog) as world:
        res, _ = _run("indirect", layout, catalog, world, target="Pen", probs=probs)
    assert res.predicted_gain is not None and res.predicted_gain > 1.0, res.log
    assert res.intermediate == "Desk", res.log
    assert res.success, res.log


def _brute_best(scorer, grid, todo, here, rng, images, weights=None):
    """Every candidate traced: the viewpoint ``ViewpointScorer.best`` must pick (``rng``: a
    range or a ``Sight``)."""
    sight = rng if isinstance(rng, sx.Sight) else sx.Sight(rng)
    blocked = sx.coarse_blocked(scorer.built)
    dist = grid.distances_from(here)
    sub = np.flatnonzero(todo)
    w = None if weights is None else weights[sub]
    left = len(sub) if w is None else float(w.sum())
    out = []
    for xy in ss.lattice_candidates(grid, here, 0.5):
        r, c = grid.to_cell(xy)
        d = float(dist[r, c]) if grid.in_grid(r, c) else math.inf
        g, m = scorer._gain(blocked, xy, sight, sub, scorer.points[sub], w)
        if math.isfinite(d) and g >= sx.MIN_GAIN:
            s = scorer.tm.leg_estimate(d) + scorer.tm.looks_estimate(images, sx.HEAD_S)
            out.append(sx.Viewpoint(xy, g, m / left, s))
    return min(out, key=sx._order) if out else None


@contextlib.contextmanager
def _looked_around(catalog):
    """A built-map search for the Pen in a room with a desk, a shelf and a cup, after the first
    look around (the World closed on exit)."""
    from ctxsearch.envs.world import World

    layout = room(DESK, SHELF, CUP, PEN)
    with World(layout, catalog) as world:
        ep = S.Episode(0, "test", 0, "Pen", START, 200.0)
        _, ctx = prepare_named(_room(layout, catalog, world), ep, "frontier", None)
        ex = Explorer(ctx)
        ex.look_around()
        yield ctx, ex


@pytest.mark.render
def test_lazy_viewpoint_choice_is_the_exhaustive_one(catalog):
    """``ViewpointScorer.best`` traces few candidates (bounds, gains cached between calls) and
    picks what tracing every candidate picks, also after the todo points shrank."""
    with _looked_around(catalog) as (ctx, ex):
        scorer, here, rng = ex.scorer(), ctx.body.pose().xy, ctx.target_range
        todo = ex.todo(rng)
        for step in range(3):
            got = scorer.best(ctx.grid, todo, here, sx.Sight(rng), sx.SWEEP_IMAGES, key="k")
            want = _brute_best(scorer, ctx.grid, todo, here, rng, sx.SWEEP_IMAGES)
            assert (got is None) == (want is None) and (step > 0 or got is not None)
            if got is not None:
                assert (tuple(got.xy), got.gain, got.seconds) == (
                    tuple(want.xy), want.gain, want.seconds)  # fmt: skip
                todo = todo & (np.linalg.norm(ctx.seen.points[:, :2] - got.xy, axis=1) > 1.0)


@pytest.mark.render
def test_weighted_viewpoint_choice_is_the_exhaustive_one_and_follows_the_weight(catalog):
    """With weights (where the target is likely) the lazy choice is still the exhaustive one, and
    weight put around one place draws the viewpoint there (uniform weights choose as no weights)."""
    with _looked_around(catalog) as (ctx, ex):
        scorer, here, rng = ex.scorer(), ctx.body.pose().xy, ctx.target_range
        todo = ex.todo(rng)
        plain = scorer.best(ctx.grid, todo, here, sx.Sight(rng), sx.SWEEP_IMAGES)
        flat = scorer.best(
            ctx.grid, todo, here, sx.Sight(rng), sx.SWEEP_IMAGES, weights=np.ones(len(todo))
        )
        assert plain is not None and flat is not None
        assert (tuple(flat.xy), flat.gain) == (tuple(plain.xy), plain.gain)
        # All the weight on the todo points far from the unweighted choice.
        pts = ctx.seen.points
        far = todo & (np.linalg.norm(pts[:, :2] - plain.xy, axis=1) > 2.5)
        assert far.sum() >= sx.MIN_GAIN
        w = np.where(far, 1.0, 1e-6)
        got = scorer.best(ctx.grid, todo, here, sx.Sight(rng), sx.SWEEP_IMAGES, weights=w)
        want = _brute_best(scorer, ctx.grid, todo, here, rng, sx.SWEEP_IMAGES, w)
        assert got is not None and want is not None
        assert (tuple(got.xy), got.gain, got.seconds) == (tuple(want.xy), want.gain, want.seconds)
        assert abs(got.share - want.share) < 1e-12
        assert tuple(got.xy) != tuple(plain.xy)
        assert np.linalg.norm(pts[far, :2] - got.xy, axis=1).min() < rng


@pytest.mark.render
def test_viewpoint_choice_by_detection_probability_is_the_exhaustive_one(catalog):
    """Weighed by the detection curve (each point's mass times P(found) at its distance), the
    lazy choice is still the one tracing every candidate picks, and it values a point by its
    distance: its share is below the unweighted one."""
    with _looked_around(catalog) as (ctx, ex):
        scorer, here, curve = ex.scorer(), ctx.body.pose().xy, ctx.curve
        todo = ex.target_todo()
        w = np.where(todo, ctx.misses.miss, 0.0)
        sight = sx.Sight(curve.reach, curve.found)
        got = scorer.best(ctx.grid, todo, here, sight, sx.SWEEP_IMAGES, weights=w)
        want = _brute_best(scorer, ctx.grid, todo, here, sight, sx.SWEEP_IMAGES, w)
        assert got is not None and want is not None
        assert (tuple(got.xy), got.gain, got.seconds) == (tuple(want.xy), want.gain, want.seconds)
        assert abs(got.share - want.share) < 1e-12
        sub = np.flatnonzero(todo)
        blocked = sx.coarse_blocked(scorer.built)
        args = (sub, scorer.points[sub], w[sub])
        g1, m1 = scorer._gain(blocked, got.xy, sight, *args)
        g0, m0 = scorer._gain(blocked, got.xy, sx.Sight(curve.reach), *args)
        assert g1 == g0 == got.gain and 0 < m1 <= m0  # equal for the perfect detector


def test_target_density_spreads_each_volume_and_does_not_count_overlaps_twice():
    """A volume's P(rel(T)) spread over its points, the larger density where volumes overlap,
    the surveyed part's mean elsewhere; nothing known: None (every point alike)."""
    n = 10
    a = ss.Region(None, 0.6, [("ON-TOP-OF-DESK", 1)], np.array([0, 1, 2]))
    b = ss.Region(None, 0.2, [("NEAR-DESK", 1)], np.array([2, 3]))
    surveyed = np.zeros(n, bool)
    surveyed[:8] = True
    w = ss.target_density([a, b], surveyed)
    assert np.allclose(w[:3], 0.2)  # 0.6 / 3 beats 0.2 / 2 at the shared point 2
    assert np.isclose(w[3], 0.1)
    # The mass the volumes give the surveyed part, the shared point once: 3 * 0.2 + 0.1 = 0.7
    # (not 0.6 + 0.2), over its 8 points.
    assert np.allclose(w[4:], 0.7 / 8)
    assert ss.target_density([], surveyed) is None
    assert ss.target_density([ss.Region(None, 0.0, [("NEAR-DESK", 1)], np.array([1]))],
                             surveyed) is None  # fmt: skip


def test_expected_mass_sums_the_volumes_over_a_worlds_objects(catalog):
    probs = ss.TableProbabilities(
        {("ON-TOP-OF-DESK", "Pen"): 0.5, ("NEAR-SHELF", "Pen"): 0.25},
        per_room={"Desk": 2.0, "Shelf": 1.0},
    )
    assert ss.expected_mass(catalog, probs, "Pen") == pytest.approx(2.0 * 0.5 + 1.0 * 0.25)
    assert ss.expected_mass(catalog, ss.TableProbabilities({}), "Pen") is None


# ===================================== exact shortcuts (issue 23: the same numbers, less work)
def _rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


def test_backprojecting_some_pixels_gives_the_whole_images_numbers_there():
    """SeenMap's support marking back-projects only the strided pixels and their neighbours."""
    from ctxsearch.envs.camera import PinholeCamera

    rng = np.random.default_rng(0)
    for _ in range(20):
        cam = PinholeCamera(rng.normal(size=3), _rotation(rng), 58.0, 320, 240)
        depth = rng.uniform(0.2, 8.0, size=(240, 320))
        depth[rng.random(depth.shape) < 0.05] = np.inf  # no return
        rows = np.sort(rng.choice(240, 60, replace=False))
        cols = np.sort(rng.choice(320, 80, replace=False))
        with np.errstate(invalid="ignore"):  # inf depth: NaN points, in both
            whole = cam.backproject(depth)[np.ix_(rows, cols)]
            part = cam.backproject(depth, rows, cols)
        assert np.array_equal(whole, part, equal_nan=True)


def test_the_cost_models_reach_test_finds_the_cells_every_cell_would():
    """CostModel.seconds looks only at the cells in a square around the box first."""
    from ctxsearch.agent.navigation import OccupancyGrid
    from ctxsearch.knowledge.geometry import Box

    rng = np.random.default_rng(1)
    grid = OccupancyGrid(rng.random((80, 100)) < 0.7, -2.5, -2.0, 0.05)
    field_ = rng.uniform(0.0, 9.0, size=grid.free.size)
    for vd in (0.3, 1.2, 3.0):
        cm = ss.CostModel(grid, TimeModel(), view_distance=vd)
        for _ in range(30):
            c = np.array([*rng.uniform(-3.0, 3.0, 2), 0.4])
            box = Box(c, float(rng.uniform(-3, 3)), np.array([*rng.uniform(0.05, 1.0, 2), 0.3]))
            near = cm._free & (box.footprint_distance(cm._cells) <= vd)
            d = float(field_[near].min()) if near.any() else math.inf
            if not math.isfinite(d):
                d = float(np.hypot(*(box.center[:2] - np.zeros(2))))
            tm = TimeModel()
            want = tm.leg_estimate(d) + tm.looks_estimate(cm.images(box), cm.head_s)
            assert cm.seconds(box, np.zeros(2), field_) == want


def test_viewpoint_bounds_sum_the_found_mass_as_over_every_point():
    """The bounds' P(found) is computed for the points within range only; the sums are the
    same numbers as with every point's."""

    class _Map:
        x0, y0 = -6.0, -6.0

    rng = np.random.default_rng(2)
    spec = RobotSpec()
    pts = rng.uniform(-6.0, 6.0, size=(5000, 3)) * np.array([1.0, 1.0, 0.2])
    scorer = sx.ViewpointScorer(_Map(), pts, spec, TimeModel())
    cand = rng.uniform(-6.0, 6.0, size=(40, 2))
    w = rng.random(len(pts))
    sight = sx.Sight(3.5, lambda d: 1.0 / (1.0 + np.exp(2.0 * (d - 2.0))))
    upper, mass = scorer._bounds(cand, pts, sight, w)
    cams = np.column_stack([cand, np.full(len(cand), spec.camera_height)])
    d2 = ((pts[None, :, :] - cams[:, None, :]) ** 2).sum(-1)
    near = d2 <= 3.5**2
    assert np.array_equal(upper, near.sum(1))
    for k in range(0, len(cand), 16):  # the reference: P(found) at every point, batch by batch
        s = slice(k, k + 16)
        assert np.array_equal(mass[s], (near[s] * sight.found(np.sqrt(d2[s])) * w).sum(1))


def _lattice_scorer(step: float = 0.2, zs: Sequence[float] = tuple(np.arange(0.05, 1.86, 0.15))):
    """A scorer over a lattice of points ``step`` m apart on a 12 m square, at the heights
    ``zs`` (default: the seen map's)."""

    class _Map:
        x0, y0 = -6.0, -6.0

    xs = np.arange(-6.0, 6.0, step) + step / 2
    pts = np.stack(np.meshgrid(xs, xs, np.asarray(zs), indexing="ij"), -1).reshape(-1, 3)
    return sx.ViewpointScorer(_Map(), pts, RobotSpec(), TimeModel())


def _found(d):
    return 1.0 / (1.0 + np.exp(2.0 * (d - 2.0))) ** 2


def test_bin_distance_is_at_most_every_points_and_reached_by_one():
    """A bin's distance is the nearest point of the box around its points: at most any of its
    points' distances, and equal to it for a camera standing over a point at its own height."""
    scorer = _lattice_scorer(zs=(*np.arange(0.05, 1.86, 0.15), RobotSpec().camera_height))
    rng = np.random.default_rng(4)
    cand = np.vstack([rng.uniform(-7.0, 7.0, size=(40, 2)), scorer.points[::997, :2]])
    bins = np.arange(len(scorer._boxes()[0]))
    d2 = scorer._bin_d2(cand, bins)
    cam = np.column_stack([cand, np.full(len(cand), scorer.spec.camera_height)])
    pd2 = ((scorer.points[None, :, :] - cam[:, None, :]) ** 2).sum(-1)
    nearest = np.full((len(cand), len(bins)), np.inf)
    np.minimum.at(nearest.T, scorer._bin, pd2.T)
    assert (d2 <= nearest + 1e-12).all()
    assert np.isclose(d2, nearest, rtol=0, atol=1e-12).mean() > 0.05  # a box's face reached
    assert (d2[40:, :] == 0.0).any(axis=1).all()  # a camera over a bin is in its box's xy


def test_bin_bounds_bound_the_point_bounds_and_keep_the_cached_gains():
    """``best``'s first bounds, per bin, are never below the points' bounds they stand for
    (count and mass, with and without weights and P(found)); with one point per bin they are
    those bounds; a candidate's cached gain is taken as it is; nothing near counts nothing."""
    rng = np.random.default_rng(3)
    for step, zs in ((0.2, None), (0.4, (0.8,))):  # 0.4 m at one height: one point per bin
        scorer = _lattice_scorer(step) if zs is None else _lattice_scorer(step, zs)
        share = 0.5 if zs is None else 1.0
        sub = np.flatnonzero(rng.random(len(scorer.points)) < share)
        cand = np.vstack([rng.uniform(-7.0, 7.0, size=(60, 2)), scorer.points[sub[:20], :2]])
        w = rng.random(len(sub))
        for sight in (sx.Sight(3.5, _found), sx.Sight(2.0)):
            for weights in (w, None):
                fine = scorer._bounds(cand, scorer.points[sub], sight, weights)
                up, mass, exact = scorer._bin_bounds(cand, sub, sight, weights, [-1] * len(cand))
                assert not exact.any() and (fine[0] > 0).sum() > 10
                assert (up >= fine[0]).all() and (mass >= fine[1]).all()
                if zs is not None:  # one point per bin: the points' bounds
                    assert np.array_equal(up, fine[0])
                    assert np.allclose(mass, fine[1], rtol=1e-8, atol=0)
    cached = [-1] * len(cand)
    cached[3] = 7
    up, mass, exact = scorer._bin_bounds(cand, sub, sx.Sight(3.5, _found), w, cached)
    assert exact.tolist() == [i == 3 for i in range(len(cand))]
    assert up[3] == 7 and mass[3] == 7.0
    up, mass, _ = scorer._bin_bounds(
        np.array([[100.0, 100.0]]), sub, sx.Sight(3.5, _found), w, [-1]
    )
    assert up[0] == 0 and mass[0] == 0.0


def test_the_lattice_over_a_furnished_room_is_its_definition(catalog):
    """``SeenMap.for_room`` tests each furniture part against the points within its x extent
    only: the points and supports are those of testing every point against every part (an
    apartment, whose parts stand at every yaw, and the hand-made room)."""
    from ctxsearch.envs.floorplan import generate_layout
    from ctxsearch.envs.houses import resolve_style
    from ctxsearch.envs.parts import world_parts_array
    from ctxsearch.knowledge.geometry import Box

    z = ss.LATTICE_Z
    layouts = [room(DESK, SHELF), generate_layout(resolve_style("apartment", catalog), 7, catalog)]
    for lay in layouts:
        pts = ss.SeenMap._lattice(lay, ss.LATTICE_XY, z)
        keep, rests = np.ones(len(pts), bool), pts[:, 2] < z[0] + z[2] / 2
        for o in (o for o in lay.objects if catalog.type(o.type).is_furniture):
            arr = world_parts_array(o, catalog)
            for c, yaw, h in zip(arr.centers, arr.yaws, arr.halves, strict=True):
                keep &= ~Box(c, float(yaw), h).contains_points(pts)
                slab = Box((c[0], c[1], c[2] + h[2] + z[2] / 2), float(yaw), (*h[:2], z[2] / 2))
                rests |= slab.contains_points(pts)
        seen = ss.SeenMap.for_room(lay, catalog)
        assert (~keep).sum() > 10 and rests[keep].sum() > (pts[keep, 2] < z[0] + 0.01).sum()
        assert np.array_equal(seen.points, pts[keep]) and np.array_equal(seen.support, rests[keep])


def test_floor_headings_read_the_cells_near_the_robot_as_the_whole_map_would():
    """``floor_headings`` reads only the map's window within ``near`` of the robot: the same
    headings as over the whole map, on maps of every size and at positions inside, at the
    edge of and outside them."""
    from types import SimpleNamespace

    from ctxsearch.agent.mapping import BuiltMap

    def whole(built, xy, heading0, near=(0.4, 2.0), min_unknown=0.3):
        xs, ys = built._centers()
        dx, dy = xs[None, :] - xy[0], ys[:, None] - xy[1]
        d, ang = np.hypot(dx, dy), np.arctan2(dy, dx)
        ring, unknown, out = (d >= near[0]) & (d <= near[1]), built.unknown, []
        for i in range(6):
            h = heading0 + i * math.pi / 3
            wedge = ring & (np.abs(np.angle(np.exp(1j * (ang - h)))) <= math.radians(25))
            if wedge.any() and unknown[wedge].mean() >= min_unknown:
                out.append(float(np.angle(np.exp(1j * h))))
        return out

    rng = np.random.default_rng(0)
    seen = set()
    for _ in range(60):
        h, w = (int(n) for n in rng.integers(20, 200, 2))
        floor = rng.random((h, w)) < rng.random()
        occupied = (rng.random((h, w)) < 0.2) & ~floor
        x0, y0 = -w * 0.025 + rng.normal(), -h * 0.025 + rng.normal()
        b = SimpleNamespace(resolution=0.05, x0=x0, y0=y0, floor=floor, occupied=occupied)
        b._centers = BuiltMap._centers.__get__(b)
        b.unknown = ~floor & ~occupied
        for _ in range(4):
            xy = np.array(
                [rng.uniform(x0 - 1, x0 + w * 0.05 + 1), rng.uniform(y0 - 1, y0 + h * 0.05 + 1)]
            )
            h0, share = rng.uniform(-4, 4), rng.uniform(0.0, 0.8)
            got = sx.floor_headings(b, xy, h0, min_unknown=share)
            assert got == whole(b, xy, h0, min_unknown=share)
            seen.add(len(got))
    assert {0, 6} <= seen and len(seen) >= 4  # none, all and some of the six


def test_kept_views_give_the_gains_and_choices_of_tracing_afresh(catalog):
    """On the given map a candidate's view is traced once over all points and kept
    (``ViewpointScorer``'s ``views``, shared by the policies of a room): its count and weight for
    any todo points are those of tracing the todo points afresh, bit for bit, and ``best`` picks
    what it picks without kept views, in an apartment (walls between rooms) as the todo points
    shrink and the weights change, and with views another scorer kept."""
    from ctxsearch.envs.floorplan import generate_layout
    from ctxsearch.envs.houses import resolve_style

    spec, tm = RobotSpec(), TimeModel()
    layout = generate_layout(resolve_style("apartment", catalog), 7, catalog)
    maps = WorldMaps.given(layout, catalog, spec)
    pts, grid = maps.seen.points, maps.grid
    sight = sx.Sight(3.0, lambda d: np.exp(-np.asarray(d) / 2.0))
    fresh = sx.ViewpointScorer(maps.occluders, pts, spec, tm)
    views: dict = {}
    kept = sx.ViewpointScorer(maps.occluders, pts, spec, tm, views)
    blocked = sx.coarse_blocked(maps.occluders)
    rng = np.random.default_rng(3)
    here = np.array(ss.lattice_candidates(grid, np.array(layout.rooms[0].center), 0.5)[0])
    cand = ss.lattice_candidates(grid, here, 0.5)
    todo = np.ones(len(pts), bool)
    shown_some = 0
    for step in range(6):
        w = rng.random(len(pts)) * (rng.random(len(pts)) < 0.7)
        sub = np.flatnonzero(todo)
        for xy in cand[rng.choice(len(cand), 12, replace=False)]:
            want = fresh._gain(blocked, xy, sight, sub, pts[sub], w[sub])
            got = kept._gain(blocked, xy, sight, sub, pts[sub], w[sub], (todo, np.cumsum(todo) - 1))
            assert got == want, (step, xy)
            shown_some += want[0] >= sx.MIN_GAIN
        a = fresh.best(grid, todo, here, sight, sx.SWEEP_IMAGES, weights=w)
        b = kept.best(grid, todo, here, sight, sx.SWEEP_IMAGES, weights=w)
        assert (a is None) == (b is None) and (step > 0 or a is not None)
        if a is not None:
            assert (tuple(a.xy), a.gain, a.share, a.seconds) == (
                tuple(b.xy), b.gain, b.share, b.seconds)  # fmt: skip
            todo = todo & (np.linalg.norm(pts[:, :2] - a.xy, axis=1) > 1.5)
    assert shown_some > 20 and len(views) > 20
    # another policy's scorer in the same room reads the views the first one kept
    other = sx.ViewpointScorer(maps.occluders, pts, spec, tm, views)
    before = len(views)
    w = rng.random(len(pts))
    a = fresh.best(grid, todo, here, sight, sx.SWEEP_IMAGES, weights=w)
    b = other.best(grid, todo, here, sight, sx.SWEEP_IMAGES, weights=w)
    assert a is not None and b is not None
    assert (tuple(a.xy), a.gain, a.share) == (tuple(b.xy), b.gain, b.share)
    assert len(views) - before < before


def test_coarse_paths_go_around_a_wall_through_its_door():
    passable = np.ones((5, 7), bool)
    passable[:, 3] = False
    passable[4, 3] = True  # the door, in the bottom row
    dist, pred = sx._coarse_paths(passable, (0, 0), 0.2)
    assert dist[0, 0] == 0.0 and np.isinf(dist[2, 3])
    # to (0, 6): down to the door and up again, 8-connected
    assert dist[0, 6] == pytest.approx(0.2 * (2 + 6 * math.sqrt(2)))
    known = np.zeros_like(passable)
    known[:, :3] = True
    assert sx._crossing(pred, (0, 6), (0, 0), known, 7) in {(3, 2), (4, 2)}  # by the door


def _beyond_world(door: bool = True):
    """A 12 m square: the robot's room (x < 0) mapped and free, a wall at x = 0 (with a door at
    y in [2, 3] if ``door``), the rest unknown; a scorer over its lattice."""

    class _Built:
        x0, y0, resolution = -6.0, -6.0, 0.05
        occupied = np.zeros((240, 240), bool)

    built = _Built()
    built.occupied[:, 120:122] = True
    if door:
        built.occupied[160:180, 120:122] = False
    free = np.zeros((240, 240), bool)
    free[10:230, 10:120] = True
    grid = OccupancyGrid(free=free, x0=-6.0, y0=-6.0, resolution=0.05)
    xs = np.arange(-6.0, 6.0, 0.2) + 0.1
    pts = np.stack(np.meshgrid(xs, xs, [0.5], indexing="ij"), -1).reshape(-1, 3)
    return sx.ViewpointScorer(built, pts, RobotSpec(), TimeModel()), grid, pts


def test_beyond_values_mass_out_of_every_viewpoints_range_through_the_door():
    scorer, grid, pts = _beyond_world()
    sight = sx.Sight(3.0, _found)
    w = np.where((pts[:, 0] > 4.0) & (pts[:, 1] < -3.0), 1.0, 0.0)  # far right, low
    todo = np.ones(len(pts), bool)
    here = np.array([-3.0, -3.0])
    got = scorer.beyond(grid, todo, here, sight, sx.SWEEP_IMAGES, w)
    assert got is not None
    assert got.via.xy[0] < 0.0 and abs(got.via.xy[1] - 2.5) < 1.0  # where the way leaves: the door
    assert got.goal[0] > 0.0 and 0.0 < got.share <= 1.0 and got.rate > 0.0
    assert got.first_s < got.share / got.rate  # the first leg is part of the way
    # mass a reachable viewpoint can find is left to ``best``: none beyond
    near = np.where((pts[:, 0] < -1.0) & (pts[:, 1] < -3.0), 1.0, 0.0)
    assert scorer.beyond(grid, todo, here, sight, sx.SWEEP_IMAGES, near) is None


def test_beyond_without_a_way_through_the_wall_offers_nothing():
    scorer, grid, pts = _beyond_world(door=False)
    w = np.where(pts[:, 0] > 4.0, 1.0, 0.0)
    todo = np.ones(len(pts), bool)
    got = scorer.beyond(grid, todo, np.array([-3.0, -3.0]), sx.Sight(3.0, _found), 10.0, w)
    assert got is None


@pytest.mark.render
def test_a_built_map_search_goes_beyond_the_frontier_and_repeats(catalog, tmp_path):
    """With ``online.beyond`` the online decision offers the place beyond the frontier, the
    robot takes it, the recording marks it, and the same episode gives the same search."""
    from dataclasses import replace

    from ctxsearch.agent.search.runner import search_once
    from tests.rrd_files import read_rrd

    cfg = SearchConfig(style="apartment", policies=("frontier",), detector="realistic", seed=2)
    cfg = cfg.with_scenario(MapMode.BUILT)
    cfg = replace(cfg, online=replace(cfg.online, beyond=True))
    one = search_once(cfg, "Cup", catalog=catalog, records=[tmp_path / "b.rrd"]).results[0]
    two = search_once(cfg, "Cup", catalog=catalog).results[0]
    assert any("beyond the frontier" in line for line in one.log), one.log
    assert "/world/search/beyond_frontier" in read_rrd(tmp_path / "b.rrd").entities
    assert one.sim_time == two.sim_time and one.gazes == two.gazes
