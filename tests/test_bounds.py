"""The ladder of bounds on the built map: what each is handed of the true house (the runner's
``EpisodeWorld.maps_for``), the true target density by room kind (envs.truth.RoomKindTruth) and
the fixed room factor it puts on the belief (agent.search.room_prior.HandedRooms)."""

from __future__ import annotations

import numpy as np
import pytest

from ctxsearch.agent.room_segmentation import RoomLabels
from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.agent.search.maps import WorldMaps
from ctxsearch.agent.search.registry import Role, default_policies, info, resolve
from ctxsearch.agent.search.room_prior import HANDED_FLOOR, HandedRooms
from ctxsearch.agent.search.runner import EpisodeWorld
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.envs.truth import RoomKindTruth, room_kind_truth
from ctxsearch.knowledge.options import Handed, MapMode

BOUNDS = ("bound-rooms", "bound-target-room", "bound-plan")


@pytest.fixture(scope="module")
def house(catalog):
    return generate_layout(resolve_style("apartment", catalog), 1234, catalog)


def _world(layout, catalog) -> EpisodeWorld:
    """The episode's maps without a simulated world (``maps_for`` reads only the layout)."""
    spec = RobotSpec()
    built = WorldMaps.built(layout, catalog, spec)
    given = WorldMaps.given(layout, catalog, spec)
    return EpisodeWorld(layout, catalog, None, built, SearchConfig(), given)


def _spec(name: str):
    return resolve([name], MapMode.BUILT)[0]


def test_the_bounds_run_by_default_on_the_built_map_only_before_the_oracle():
    names = default_policies(MapMode.BUILT)
    assert names[-len(BOUNDS) - 1 :] == (*BOUNDS, "oracle")
    for b in BOUNDS:
        assert info(b).role(MapMode.BUILT) is Role.BOUND
        assert info(b).maps == (MapMode.BUILT,)
        assert b not in default_policies(MapMode.GIVEN)
    assert info("bound-plan").handed is Handed.PLAN
    assert info("frontier").handed is Handed.NOTHING


def test_the_density_ratio_by_kind_averages_to_one_over_the_area(catalog):
    kinds = room_kind_truth(resolve_style("apartment", catalog), 20, catalog)
    assert kinds.houses == 20
    area = sum(kinds.area.values())
    for t in ("Cup", "Laptop", "Book", "Fridge"):
        mean = sum(kinds.ratio(k, t) * a for k, a in kinds.area.items()) / area
        assert mean == pytest.approx(1.0)
    assert kinds.ratio("kitchen", "Fridge") > 1.0  # fridges stand in kitchens
    assert kinds.ratio("bedroom", "Fridge") == 0.0
    assert kinds.ratio("no such kind", "Cup") is None
    assert kinds.ratio("kitchen", "Unicorn") is None


def test_the_density_counts_one_house_exactly(house):
    kinds = RoomKindTruth.of_layouts([house])
    for r in house.rooms:
        assert kinds.area[r.style] >= r.area
    cups = [o for o in house.objects if o.type == "Cup"]
    got = sum(v for (_k, t), v in kinds.instances.items() if t == "Cup")
    assert got == len(cups)


def test_handed_rooms_floor_every_point_not_in_a_listed_room(house):
    labels = RoomLabels.of_plan(house)
    room = house.rooms[0]
    hr = HandedRooms(labels, {room.index: 3.0, house.rooms[1].index: 0.0})
    x, y = room.center
    far = (1e3, 1e3, 0.5)
    f = hr.factor(np.array([[x, y, 0.5], far, [*house.rooms[1].center, 0.5]]))
    assert list(f) == [3.0, HANDED_FLOOR, HANDED_FLOOR]  # a 0 is floored too


def test_the_target_room_bound_is_handed_the_target_rooms(house, catalog):
    world = _world(house, catalog)
    maps = world.maps_for(_spec("bound-target-room"), "Cup")
    assert maps.handed is not None and maps.map is MapMode.BUILT
    assert maps.furniture == ()  # nothing else: it builds its map as frontier does
    cups = [o for o in house.objects if o.type == "Cup"]
    assert cups
    f = maps.handed.factor(np.array([o.position for o in cups]))
    assert np.all(f == 1.0)
    empty = [r for r in house.rooms if r.index not in {house.room_of[o.id] for o in cups}]
    if empty:
        assert maps.handed.factor(np.array([[*empty[0].center, 0.5]]))[0] == HANDED_FLOOR


def test_the_rooms_bound_is_handed_each_rooms_kind_ratio(house, catalog):
    kinds = room_kind_truth(resolve_style("apartment", catalog), 10, catalog)
    world = _world(house, catalog)
    with pytest.raises(Exception, match="density by room kind"):
        world.maps_for(_spec("bound-rooms"), "Cup")
    maps = world.maps_for(_spec("bound-rooms"), "Cup", kinds)
    for r in house.rooms:
        want = max(kinds.ratio(r.style, "Cup") or 0.0, HANDED_FLOOR)
        assert maps.handed.factor(np.array([[*r.center, 0.5]]))[0] == pytest.approx(want)


def test_the_plan_bound_is_handed_the_furniture_and_the_others_nothing(house, catalog):
    world = _world(house, catalog)
    maps = world.maps_for(_spec("bound-plan"), "Cup")
    furniture = {o.id for o in house.objects if catalog.type(o.type).is_furniture}
    assert {o.id for o in maps.furniture} == furniture and maps.map is MapMode.BUILT
    assert maps.seen is world.given.seen  # the plan's lattice: its solid parts and surfaces
    assert maps.grid is world.maps.grid  # the free space it maps itself
    assert maps.handed is None
    assert world.maps_for(_spec("frontier"), "Cup") is world.maps
    single = generate_layout(resolve_style("office", catalog), 3, catalog)
    assert _world(single, catalog).maps_for(_spec("bound-target-room"), "Cup").handed is None
