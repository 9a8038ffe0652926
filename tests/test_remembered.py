"""The remembered map: the robot's tour of a world, the map it keeps, the search on a later day
that starts from it and updates its furniture, and the cache of tours."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ctxsearch.agent.search import remembered as rm
from ctxsearch.agent.search.config import HomeSource, MapConfig, SearchConfig
from ctxsearch.agent.search.maps import WorldMaps
from ctxsearch.agent.search.registry import Role, default_policies, resolve, with_role
from ctxsearch.agent.search.runner import EpisodeSensor, search_once
from ctxsearch.agent.search.tour import Sightings, cached_tour, tour, tour_key
from ctxsearch.envs.camera import Frame, camera_at
from ctxsearch.envs.detector import Detection, SimDetector, load_detector
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec
from ctxsearch.envs.world import World
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.home_map import HomeMap
from ctxsearch.knowledge.options import MapMode, Needs
from tests.rrd_files import read_rrd

DESK = ObjectInstance("Desk", 7, (2.0, 0.0, 0.37), 0.0, (0.7, 1.4, 0.74))


@pytest.fixture(scope="module")
def office_tour(catalog):
    """The tour of an office room with the realistic detector, day 0, and its layout."""
    style = resolve_style("office", catalog)
    layout = generate_layout(style, 11, catalog)
    det = load_detector("realistic", catalog)
    with World(layout, catalog) as world:
        sensor = EpisodeSensor(world, SimDetector(det, layout, catalog, 11), catalog, 0.0)
        home = tour(layout, catalog, det, MapConfig(), 0, body=world, sensor=sensor)
    return layout, home


def test_the_registry_runs_memory_and_location_against_their_twin_on_the_remembered_map():
    r = MapMode.REMEMBERED
    assert default_policies(r) == (
        "uniform", "memory", "location", "memory-location", "oracle-memory", "oracle",
    )  # fmt: skip
    assert with_role(r, Role.BASELINE) == "uniform"
    assert with_role(r, Role.CONTEXT) == "memory-location"
    assert with_role(r, Role.ASYMPTOTE) == "oracle-memory"
    (spec,) = resolve(("location",), r, room_context=True)
    assert spec.uses_room_context and spec.memory is Needs.NONE
    mem, both, bound = resolve(("memory", "memory-location", "oracle-memory"), r, True)
    assert (mem.memory, both.memory, bound.memory) == (Needs.KB, Needs.KB, Needs.TRUTH)
    assert not mem.uses_room_context and both.uses_room_context and bound.needs is Needs.TRUTH
    with pytest.raises(CtxsearchError, match="needs --map"):
        resolve(("memory",), MapMode.GIVEN)
    with pytest.raises(CtxsearchError, match="needs --map"):
        resolve(("frontier",), r)


def test_a_tour_keeps_the_furniture_it_saw_and_its_own_map(office_tour, catalog):
    layout, home = office_tour
    true = {o.id: o for o in layout.objects if catalog.type(o.type).is_furniture}
    got = {o.id: o for o in home.furniture}
    assert got and set(got) <= set(true)  # no phantom furniture with this detector
    assert len(got) >= 0.8 * len(true)
    for i, o in got.items():
        assert math.dist(o.position[:2], true[i].position[:2]) < 0.2
        assert 0 < o.confidence <= 1 and o.sightings >= 1
    assert home.images > 10 and home.floor.mean() > 0.3
    assert (home.style, home.seed, home.day) == ("office", 11, 0)
    again = HomeMap.from_bytes(home.to_bytes())
    assert again.furniture == home.furniture and np.array_equal(again.occupied, home.occupied)


def test_sightings_keep_the_type_reported_most_often_and_the_mean_pose(catalog):
    s = Sightings()
    a = ObjectInstance("Table", 5, (1.0, 2.0, 0.4), 0.1, (1.2, 0.8, 0.75))
    b = ObjectInstance("Desk", 5, (1.2, 2.2, 0.4), 0.1, (1.2, 0.8, 0.75))
    s.add([Detection(5, "Table", a, 900, 2.0, (0, 0, 1, 1), 0.9)])
    s.add([Detection(5, "Table", a, 900, 2.0, (0, 0, 1, 1), 0.8)])
    s.add([Detection(5, "Desk", b, 900, 2.0, (0, 0, 1, 1), 0.7)])
    s.add([Detection(-3, "Cup", a, 0, 2.0, (0, 0, 0, 0), 0.3)])  # small: not furniture
    (o,) = s.furniture(catalog)
    assert (o.type, o.id, o.sightings, o.confidence) == ("Table", 5, 3, 0.9)
    assert o.position[0] == pytest.approx((1.0 + 1.0 + 1.2) / 3)
    assert s.furniture(catalog, min_score=0.95) == []


def test_a_remembered_piece_shown_up_close_without_a_report_is_dropped():
    spec = RobotSpec()
    pose = RobotPose(0.0, 0.0, 0.0, 0.0, -0.3)
    cam = camera_at(pose, spec)
    ids = np.full((cam.height, cam.width), -1)
    depth = np.full((cam.height, cam.width), 10.0)  # nothing in front of the desk
    frame = Frame(None, depth, ids, cam, pose)
    mem = rm.FurnitureMemory([DESK], lambda t: 8.0)
    for _ in range(rm.DROP_AFTER - 1):
        assert mem.observe(frame, []) == [] and mem.objects() == [DESK]
    assert mem.observe(frame, []) == [DESK] and mem.objects() == []
    # reported once: never dropped
    mem = rm.FurnitureMemory([DESK], lambda t: 8.0)
    mem.observe(frame, [Detection(7, "Desk", DESK, 900, 2.0, (0, 0, 1, 1), 0.9)])
    for _ in range(2 * rm.DROP_AFTER):
        mem.observe(frame, [])
    assert mem.objects() == [DESK]
    # hidden behind a surface nearer than it: not counted
    mem = rm.FurnitureMemory([DESK], lambda t: 8.0)
    near = Frame(None, np.full((cam.height, cam.width), 1.0), ids, cam, pose)
    for _ in range(2 * rm.DROP_AFTER):
        mem.observe(near, [])
    assert mem.objects() == [DESK]


def test_the_remembered_scenario_starts_from_the_map_not_the_truth(office_tour, catalog):
    layout, home = office_tour
    spec = RobotSpec()
    fake = HomeMap(**{**home.__dict__, "furniture": ()})  # a map that recognised nothing
    maps = WorldMaps.remembered(fake, layout, spec)
    assert maps.map is MapMode.REMEMBERED and maps.furniture == ()
    built = maps.new_built_map(RobotPose(0.0, 0.0, 0.0), spec)
    assert np.array_equal(built.occupied, home.occupied) and built is not maps.new_built_map(
        RobotPose(0.0, 0.0, 0.0), spec
    )
    maps = WorldMaps.remembered(home, layout, spec)
    assert {o.id for o in maps.furniture} == {o.id for o in home.furniture}
    assert maps.plan_rooms is not None and maps.seen.support is not None


def test_a_search_on_the_remembered_map_finds_on_a_later_day_and_repeats(catalog, tmp_path):
    cfg = SearchConfig(style="office", policies=("uniform",), detector="perfect", seed=3)
    cfg = cfg.with_scenario(MapMode.REMEMBERED)
    one = search_once(cfg, "Cup", catalog=catalog, records=[tmp_path / "s.rrd"])
    two = search_once(cfg, "Cup", catalog=catalog)
    assert one.episode.day == 1 and one.results[0].success
    assert one.results[0].sim_time == two.results[0].sim_time
    assert one.config.map.home is HomeSource.TOUR  # no store: a held-out house toured on day 0
    entities = read_rrd(tmp_path / "s.rrd").entities
    assert "/world/search/remembered" in entities
    assert "/world/search/last_seen" in entities  # the small objects the tour saw


def test_a_tour_is_kept_and_a_damaged_file_is_a_miss(catalog, tmp_path, monkeypatch):
    monkeypatch.setenv("CTXSEARCH_CACHE_DIR", str(tmp_path))
    style = resolve_style("office", catalog)
    layout = generate_layout(style, 12, catalog)
    det = load_detector("perfect", catalog)
    cfg = MapConfig(tour_budget_s=120.0)

    def run():
        with World(layout, catalog) as world:
            sensor = EpisodeSensor(world, SimDetector(det, layout, catalog, 12), catalog, 0.0)
            return cached_tour(layout, catalog, det, cfg, 0, body=world, sensor=sensor)

    first = run()
    path = tmp_path / "tours" / f"{tour_key(layout, 0, det, cfg)}.npz"
    assert path.is_file()
    assert run().furniture == first.furniture
    path.write_bytes(b"\x00garbage")
    assert run().furniture == first.furniture  # made again
    assert HomeMap.from_bytes(path.read_bytes()).furniture == first.furniture


def test_learn_then_search_in_a_house_the_robot_knows_and_a_damaged_map_is_refused(
    tmp_path, capsys, catalog
):
    import sqlite3

    from ctxsearch.scripts.cli import main

    kb = tmp_path / "k.sqlite"
    assert main(["learn", "--style", "office", "--rooms", "1", "--kb", str(kb),
                 "--no-progress"]) == 0  # fmt: skip
    with sqlite3.connect(kb) as c:
        ((seed, day),) = c.execute("SELECT seed, day FROM home_maps").fetchall()
    capsys.readouterr()
    assert main(["kb", "maps", str(kb)]) == 0
    listed = capsys.readouterr().out
    assert "1 remembered map(s)" in listed and f"office seed {seed} day {day}" in listed
    later = generate_layout(resolve_style("office", catalog), seed, catalog, day=day + 1)
    counts: dict[str, int] = {}
    for o in later.objects:
        if not catalog.type(o.type).is_furniture:
            counts[o.type] = counts.get(o.type, 0) + 1
    rarest = min(sorted(counts), key=counts.__getitem__)  # the least likely seen from the start
    args = ["search", "--kb", str(kb), "--style", "office", "--map", "remembered",
            "--target", rarest, "--policy", "uniform"]  # fmt: skip
    assert main(args) == 0
    out = capsys.readouterr().out
    assert f"seed {seed} (a house it learned in, its map 1 day(s) before; day {day + 1})" in out
    with sqlite3.connect(kb) as c:
        c.execute("UPDATE home_maps SET map = ?", (b"PK\x03\x04 not a map",))
    before = kb.read_bytes()
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "remembered map" in err and str(kb) in err
    assert kb.read_bytes() == before
