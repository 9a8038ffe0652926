"""The detection-aware belief (agent.search.belief): the detector's curve as the robot models it,
the miss field, the belief's weights, the mass left, and the value of planned gazes."""

import math

import numpy as np
import pytest

from ctxsearch.agent.search import belief as B
from ctxsearch.agent.search import space as ss
from ctxsearch.envs.detector import load_detector
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.knowledge.catalog import load_catalog


@pytest.fixture(scope="module")
def catalog():
    return load_catalog()


def _curve(catalog, name="Cup", preset="realistic"):
    return B.detection_curve(catalog.type(name), load_detector(preset), RobotSpec(), 320, 240)


def test_the_curve_is_the_detector_models_recall_at_the_pixels_a_type_covers(catalog):
    """p(d) is DetectorModel.recall_prob at f^2 A / d^2 pixels (one function for the robot's
    model and the simulation), falls with distance, and found = p^2 (confirmed)."""
    c = _curve(catalog)
    typ = catalog.type("Cup")
    d = np.array([0.5, 1.0, 2.0, 3.0, 4.0])
    px = ss.focal_px(RobotSpec()) ** 2 * ss.mean_face_area(typ) / d**2
    want = load_detector("realistic").recall_prob(typ, px, d, 320, 240)
    assert np.allclose(c.p(d), want)
    assert np.all(np.diff(c.p(d)) < 0) and c.p(0.5) > 0.8
    assert np.allclose(c.found(d), c.p(d) ** 2)
    assert float(c.found(c.reach)) >= B.P_REACH > float(c.found(c.reach + 0.05))


def test_the_perfect_detectors_curve_is_a_step_at_its_pixel_range(catalog):
    """The threshold detector: found is 1 up to the pixel rule's range (the effective range
    without its safety factor, capped at max_range) and 0 beyond."""
    c = _curve(catalog, "Pen", "perfect")
    r = ss.effective_range(catalog.type("Pen"), safety=1.0)
    assert c.found(r - 0.05) == 1.0 and c.found(r + 0.05) == 0.0
    assert abs(c.reach - r) < 0.02


def test_a_distant_glance_keeps_most_of_the_mass_a_close_look_removes_it(catalog):
    """The miss field multiplies each shown point by 1 - p(d): far points keep most of their
    mass, near ones little, points not shown all of it; no point reaches zero."""
    c = _curve(catalog, "Phone")
    pts = np.array([[0.6, 0, 0.8], [2.5, 0, 0.8], [9.0, 0, 0.8]])
    f = B.MissField(pts, c)
    f.observe(np.array([0.0, 0.0, 1.2]), np.array([True, True, False]))
    assert f.miss[0] < 0.2 and f.miss[1] > 0.7 and f.miss[2] == 1.0
    f.observe(np.array([0.0, 0.0, 1.2]), np.array([0, 1]))
    assert f.miss[0] > 0 and f.miss[1] < 0.95 * 0.95
    assert list(f.near(np.array([0.5, 0.0]), 0.5)) == [0]


def test_belief_weights_and_the_mass_left(catalog):
    """The belief is prior times miss over the points still worth a look, normalised; the mass
    left is the prior's share the miss field still holds over the points kept."""
    prior = np.array([0.5, 0.25, 0.25, 0.0])
    miss = np.array([0.2, 1.0, 0.5, 1.0])
    todo = np.array([True, True, False, True])
    w = B.belief_weights(prior, miss, todo)
    assert np.allclose(w, np.array([0.1, 0.25, 0.0, 0.0]) / 0.35)
    keep = np.ones(4, bool)
    assert math.isclose(B.mass_left(prior, miss, keep), 0.1 + 0.25 + 0.125)
    assert B.belief_weights(prior, miss, np.zeros(4, bool)) is None


def test_planned_gazes_find_near_points_and_their_misses_multiply(catalog):
    """gazes_found: one minus the product of each camera's miss of a confirmed detection."""
    c = _curve(catalog, "Cup")
    pts = np.array([[1.0, 0, 0.8], [4.5, 0, 0.8]])
    one = B.gazes_found(c, np.array([[0.0, 0, 1.2]]), pts)
    two = B.gazes_found(c, np.array([[0.0, 0, 1.2], [0.0, 0, 1.2]]), pts)
    assert one[0] > 0.5 and one[1] < one[0]
    assert np.allclose(two, 1 - (1 - one) ** 2)
    assert (
        len(B.gazes_found(c, np.zeros((0, 3)), pts)) == 2
        and B.gazes_found(c, np.zeros((0, 3)), pts).sum() == 0
    )


# =========================================================================== in a search
def _layout():
    from tests.test_search_maps import CUP, DESK, SHELF, room

    return room(DESK, SHELF, CUP)


def test_the_given_maps_supports_are_the_floor_and_the_furniture_tops(catalog):
    """Where an object can stand on the given map: the floor layer and the lattice points just
    above a part of furniture (the desk's top, the shelf's boards); free air keeps AIR_WEIGHT."""
    from ctxsearch.agent.search.maps import WorldMaps
    from tests.test_search_maps import DESK

    seen = WorldMaps.given(_layout(), catalog, RobotSpec()).seen
    w = seen.standable()
    z = seen.points[:, 2]
    assert np.all(w[z < 0.1] == 1.0)
    over_desk = (np.abs(seen.points[:, 0] - DESK.position[0]) < 0.5) & (
        np.abs(seen.points[:, 1] - DESK.position[1]) < 0.25
    )  # the desk is turned: 1.4 m along x, 0.7 m along y
    top = DESK.position[2] + DESK.size[2] / 2
    just_above = over_desk & (z > top) & (z < top + ss.LATTICE_Z[2])
    assert just_above.any() and np.all(w[just_above] == 1.0)
    assert np.all(w[over_desk & (z > top + 0.3)] == ss.AIR_WEIGHT)
    assert 0.05 < (w == 1.0).mean() < 0.2  # a small share of the volume


@pytest.mark.render
def test_the_built_map_learns_supports_from_level_surfaces_in_depth(catalog):
    """On the built map only the floor layer is known at first; a depth image of the desk marks
    the points just above its top (a level surface), not those beside the walls; a point not
    seen yet weighs the share of seen points of its height that had a surface below."""
    from ctxsearch.agent.search.maps import WorldMaps
    from ctxsearch.envs.robot_spec import RobotPose
    from ctxsearch.envs.world import World
    from tests.test_search_maps import DESK

    layout = _layout()
    seen = WorldMaps.built(layout, catalog, RobotSpec()).seen.copy()
    w0 = seen.standable()
    assert seen.learn_support and np.all(w0[seen.points[:, 2] > 0.1] == 0.5)  # Laplace, unseen
    with World(layout, catalog) as world:
        world.reset_pose(RobotPose(0.0, 0.0, math.pi / 2))
        world.move_head(0.0, -0.5)
        frame = world.capture(rgb=False, depth=True)
    seen.update(frame.camera, frame.depth)
    top = DESK.position[2] + DESK.size[2] / 2
    z = seen.points[:, 2]
    above = seen.support & (z > top) & (z < top + ss.LATTICE_Z[2])
    assert above.sum() > 10
    xy = seen.points[above, :2]
    assert np.all(np.abs(xy[:, 1] - DESK.position[1]) < 0.6)
    w = seen.standable()
    seen_air = np.isfinite(seen.best) & ~seen.support
    assert np.all(w[seen_air] == ss.AIR_WEIGHT)
    unseen_high = ~np.isfinite(seen.best) & ~seen.support & (np.abs(z - 0.8) < 0.01)
    assert unseen_high.any() and 0.0 < w[unseen_high][0] < 0.5


@pytest.mark.render
def test_uniform_is_the_online_search_with_every_point_alike_on_the_given_map(catalog):
    """``uniform`` (location's twin) finds the cup on the given map with the belief (a look
    around, then sweeps from viewpoints), no relation volume looked into; its images thinned the
    miss field; its occluders are the given map's."""
    from ctxsearch.envs.world import World
    from tests.test_search_maps import CUP, _run

    with World(_layout(), catalog) as world:
        res, ctx = _run("uniform", _layout(), catalog, world, scenario="given")
    assert res.success and res.found_id == CUP.id, res.log
    assert not any(g.purpose.startswith("region") for g in res.trace)
    assert ctx.misses.miss.min() < 0.5 and ctx.occluders is ctx.maps.occluders


def test_stops_are_counted_per_policy():
    """bench search's aggregates: an episode stopped before the budget with nothing found is a
    give-up, premature when more than EARLY_STOP_MASS of the belief was left."""
    from ctxsearch.agent.search.episode import SearchResult
    from ctxsearch.scripts.experiments.bench_search import EARLY_STOP_MASS, aggregate

    def r(t, found, left=None):
        return SearchResult("p", 0, "Cup", found, 1 if found else None, t, 1, 0.0, 100.0,
                            mass_left=left)  # fmt: skip

    rs = [r(10, True), r(100.5, False), r(40, False, 0.01), r(50, False, EARLY_STOP_MASS + 0.1)]
    st = aggregate({"p": rs})["p"]
    assert [x.stop for x in rs] == ["found", "budget", "gave-up", "gave-up"]
    assert (st.gave_up, st.gave_up_with_mass) == (2, 1)
    assert st.to_json()["gave_up_with_mass"] == 1


def test_a_detour_is_worth_the_share_of_the_belief_its_volumes_would_hold(catalog):
    """A detour for an intermediate type I: P(a new I is seen from the viewpoint: one expected
    present, the sweep's share of I's places within I's range) times the share of the belief
    I's relation volumes would hold (q over the mass left), per expected second (the sweep and,
    if an I is found, the look); given up once the model's seconds to find one are spent."""
    from types import SimpleNamespace

    from ctxsearch.agent.search import online as on
    from ctxsearch.agent.search.viewpoints import Viewpoint

    s = on.OnlineSearch.__new__(on.OnlineSearch)
    s.ctx = SimpleNamespace(found_of=lambda t: 0, range_of=lambda t: 4.0)
    vp = Viewpoint(np.array([1.0, 2.0]), 50, 0.5, 20.0)
    s.explorer = SimpleNamespace(viewpoint=lambda rng, images, zmax: vp)
    s.via_spent = {}
    via = on.ViaOption("Desk", q=0.4, instances=1.0, zmax=1.0, look_s=10.0, gain=1.5, find_s=99)
    o = s.via_option(via, mass=0.8)
    m = (1.0 - math.exp(-1.0)) * 0.5
    assert o.kind == "via" and o.seconds == 20.0
    assert o.rate == pytest.approx(m * 0.4 / 0.8 / (20.0 + m * 10.0))
    s.ctx.found_of = lambda t: 1  # the one expected is found: little left to find
    assert s.via_option(via, mass=0.8) is None
    s.ctx.found_of = lambda t: 0
    s.via_spent = {"Desk": 99.0}  # the model's expected seconds to find one are spent
    assert s.via_option(via, mass=0.8) is None
