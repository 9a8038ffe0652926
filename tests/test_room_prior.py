"""Room context (issue 27): the true P(SAME-ROOM-AS-F(T)) from the plans, the rooms of a map
as labels, and the belief's room factor (agent.search.room_prior)."""

from __future__ import annotations

import numpy as np
import pytest

from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.room_segmentation import RoomLabels, wall_mask
from ctxsearch.agent.search.maps import WorldMaps
from ctxsearch.agent.search.room_prior import MAX_FACTOR, MIN_FACTOR, RoomPrior
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec
from ctxsearch.envs.truth import room_truth
from ctxsearch.knowledge.ranking import TableProbabilities, UniformProbabilities


@pytest.fixture(scope="module")
def house(catalog):
    return generate_layout(resolve_style("apartment", catalog), 1234, catalog)


def _rooms_of(layout, catalog):
    """Per plan room: the set of types standing in it."""
    out: dict[int, set[str]] = {}
    for o in layout.objects:
        out.setdefault(layout.room_of[o.id], set()).add(o.type)
    return out


def test_room_truth_counts_furniture_rooms_exactly_on_one_house(house, catalog):
    rt = room_truth("apartment", 1, catalog, seed=1234)
    rooms = _rooms_of(house, catalog)
    for f in {o.type for o in house.objects if catalog.type(o.type).is_furniture}:
        own = {house.room_of[o.id] for o in house.objects if o.type == f}  # rooms, not instances
        for t in ("Cup", "Remote", "Pen"):
            want = sum(t in rooms[r] for r in own) / len(own)
            assert rt.same_room[(f, t)] == pytest.approx(want)
    furnished = [s for s in rooms.values() if any(catalog.type(t).is_furniture for t in s)]
    for t in ("Cup", "Book", "Fridge"):
        assert rt.room_share[t] == pytest.approx(sum(t in s for s in furnished) / len(furnished))
    # a piece of furniture is not in its own room's count unless a second one is there
    fridges = [house.room_of[o.id] for o in house.objects if o.type == "Fridge"]
    if len(fridges) == 1:
        assert rt.same_room[("Fridge", "Fridge")] == 0.0


def test_room_truth_probabilities_are_probabilities_and_only_furniture_refers(catalog):
    rt = room_truth("apartment", 5, catalog)
    assert rt.houses == 5
    assert all(0.0 <= p <= 1.0 for p in rt.same_room.values())
    assert all(0.0 <= p <= 1.0 for p in rt.room_share.values())
    assert {f for f, _ in rt.same_room} <= {t.name for t in catalog.types if t.is_furniture}


def test_labels_of_the_plan_put_each_object_in_its_room(house, catalog):
    labels = RoomLabels.of_plan(house)
    got = labels.at(np.array([o.position[:2] for o in house.objects]))
    assert list(got) == [house.room_of[o.id] for o in house.objects]
    assert list(labels.at(np.array([[1e3, 0.0], [0.0, -1e3]]))) == [-1, -1]


def _table(same: dict, share: dict) -> TableProbabilities:
    return TableProbabilities({}).with_rooms(same, share)


def test_the_factor_is_the_best_furniture_ratio_clipped_and_one_elsewhere(house, catalog):
    maps = WorldMaps.given(house, catalog, RobotSpec())
    rooms = _rooms_of(house, catalog)
    fridge_room = next(house.room_of[o.id] for o in house.objects if o.type == "Fridge")
    others = [r for r in rooms if r != fridge_room]
    bed_room = next(house.room_of[o.id] for o in house.objects if o.type == "Bed")
    same = {("Fridge", "Cup"): 0.9, ("Bed", "Cup"): 0.0}
    probs = _table(same, {"Cup": 0.3})
    rp = RoomPrior.for_search(probs, "Cup", catalog, maps.seen.points, maps.plan_rooms)
    f = rp.factor(list(maps.furniture), None)
    where = maps.plan_rooms.at(maps.seen.points)
    assert np.allclose(f[where == fridge_room], 0.9 / 0.3)
    if bed_room != fridge_room:
        assert np.allclose(f[where == bed_room], MIN_FACTOR)  # ruled out, but not to zero
    rest = ~np.isin(where, [fridge_room, bed_room])
    assert np.allclose(f[rest], 1.0)
    assert others  # the house has more than the kitchen
    # the largest probability of a room's furniture counts, capped
    probs = _table({("Fridge", "Cup"): 0.1, ("Counter", "Cup"): 1.0}, {"Cup": 0.05})
    f = RoomPrior(probs, "Cup", catalog, maps.seen.points, maps.plan_rooms).factor(
        list(maps.furniture), None
    )
    counter_room = next(house.room_of[o.id] for o in house.objects if o.type == "Counter")
    assert np.allclose(f[where == counter_room], MAX_FACTOR)


def test_no_room_context_without_room_probabilities_or_furniture(house, catalog):
    maps = WorldMaps.given(house, catalog, RobotSpec())
    pts = maps.seen.points
    assert RoomPrior.for_search(None, "Cup", catalog, pts, maps.plan_rooms) is None
    assert (
        RoomPrior.for_search(UniformProbabilities(), "Cup", catalog, pts, maps.plan_rooms) is None
    )
    assert (
        RoomPrior.for_search(TableProbabilities({}), "Cup", catalog, pts, maps.plan_rooms) is None
    )
    rp = RoomPrior.for_search(_table({("Fridge", "Cup"): 0.9}, {"Cup": 0.3}), "Cup", catalog,
                              pts, maps.plan_rooms)  # fmt: skip
    assert rp.factor([], None) is None  # nothing known yet
    assert rp.factor([o for o in house.objects if o.type == "Cup"], None) is None  # no furniture


def test_on_the_built_map_the_rooms_are_its_segmentation_as_it_grows(house, catalog):
    spec = RobotSpec()
    built = BuiltMap.for_layout(house, spec, RobotPose(0.0, 0.0, 0.0))
    seen = WorldMaps.built(house, catalog, spec).seen
    fridge = next(o for o in house.objects if o.type == "Fridge")
    rp = RoomPrior(_table({("Fridge", "Cup"): 0.9}, {"Cup": 0.3}), "Cup", catalog, seen.points,
                   None)  # fmt: skip
    built.floor[:] = False
    assert rp.factor([fridge], built) is None  # its room is not on the map yet
    built.floor[:] = wall_mask(house, built.resolution).free
    built.images += 1  # the map took an image: its rooms are segmented anew
    f = rp.factor([fridge], built)
    kitchen = house.rooms[house.room_of[fridge.id]].outline
    x, y = seen.points[:, 0], seen.points[:, 1]
    inside = (
        (x > kitchen[0] + 0.3)
        & (x < kitchen[2] - 0.3)
        & (y > kitchen[1] + 0.3)
        & (y < kitchen[3] - 0.3)
    )
    assert np.allclose(f[inside], 3.0)
    assert np.allclose(f[~inside & (f != 3.0)], 1.0)
    assert (f == 1.0).sum() > (f == 3.0).sum() > 0


def test_the_oracle_priors_know_room_context_only_when_asked(catalog):
    from ctxsearch.agent.search.priors import truth_probabilities

    plain = truth_probabilities("apartment", catalog, samples=3)
    rooms = truth_probabilities("apartment", catalog, samples=3, rooms=True)
    assert plain.room_share("Cup") is None and plain.same_room("Fridge", "Cup") is None
    rt = room_truth("apartment", 3, catalog)
    assert rooms.room_share("Cup") == rt.room_share["Cup"]
    assert rooms.same_room("Fridge", "Cup") == rt.same_room[("Fridge", "Cup")]
    assert rooms.p("ON-TOP-OF-COUNTER", "Cup") == plain.p("ON-TOP-OF-COUNTER", "Cup")


def test_plan_segments_give_the_built_map_the_plans_rooms_and_nothing_else(house, catalog):
    from ctxsearch.agent.search.config import MapConfig, Segments

    spec = RobotSpec()
    plain = WorldMaps.built(house, catalog, spec)
    assert plain.plan_rooms is None
    got = WorldMaps.built(house, catalog, spec, None, MapConfig(segments=Segments.PLAN))
    assert np.array_equal(got.plan_rooms.labels, RoomLabels.of_plan(house).labels)
    assert (
        got.furniture == ()
        and got.map == plain.map
        and np.array_equal(got.grid.free, plain.grid.free)
    )


def test_the_depth_range_reaches_every_built_map(house, catalog):
    from ctxsearch.agent.search.config import MapConfig

    spec = RobotSpec()
    far = WorldMaps.built(house, catalog, spec, None, MapConfig(depth_range_m=9.5))
    assert far.depth_range == 9.5
    m = far.new_built_map(RobotPose(0.0, 0.0, 0.0), spec)
    assert (
        m.max_range == 9.5
        and m.resolution == BuiltMap((-1, -1, 1, 1), spec, RobotPose(0, 0, 0)).resolution
    )
    plain = WorldMaps.built(house, catalog, spec)
    assert plain.new_built_map(RobotPose(0.0, 0.0, 0.0), spec).max_range == 5.0
    assert np.array_equal(far.grid.free, plain.grid.free)  # the same allocation
