"""What lies through a door: the next-room relations learned in hindsight from the robot's own
maps (knowledge.room_context), their truth from the plans (envs.truth), and the mass the search
gives the space beyond its mapped rooms (agent.search.room_prior)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.room_segmentation import RoomLabels, wall_mask
from ctxsearch.agent.search.config import ConfigError, KnowledgeConfig, SearchConfig
from ctxsearch.agent.search.maps import WorldMaps
from ctxsearch.agent.search.room_prior import MAX_FACTOR, MIN_FACTOR, Beyond, RoomPrior
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec
from ctxsearch.envs.truth import room_contents, room_doors, room_truth
from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.options import Rank
from ctxsearch.knowledge.ranking import TableProbabilities
from ctxsearch.knowledge.room_context import (
    RoomContext,
    next_relation_name,
    segment_neighbours,
)
from ctxsearch.knowledge.store import EvidenceStore
from tests.test_home_map import make_map


def test_segments_are_neighbours_where_their_cells_touch_not_across_a_wall():
    lab = np.full((6, 9), -1)
    lab[:, 0:3] = 0
    lab[:, 3:6] = 1  # touches 0
    lab[:, 7:9] = 2  # a wall column (-1) between 1 and 2
    assert segment_neighbours(lab) == {(0, 1)}
    lab[2, 6] = 2  # a door: 1 and 2 side by side in one row
    lab[2, 5] = 1
    assert segment_neighbours(lab) == {(0, 1), (1, 2)}
    assert segment_neighbours(np.full((3, 3), -1)) == frozenset()


KITCHEN = [(0, "Fridge", 1), (0, "Cup", 2)]
LIVING = [(1, "Sofa", 1), (1, "Remote", 1)]
BATH = [(2, "Plant", 1)]  # no furniture: counted as what lies beyond, never as a reference


def test_next_room_counts_the_pairs_through_each_door_with_wilson_intervals(catalog):
    bedroom = [(4, "Bed", 1), (4, "Cup", 1)]
    rows = [("r", "apartment", 1, 0, *row) for row in (*KITCHEN, *LIVING, *BATH, *bedroom)]
    # 2 (the bath) holds no furniture: a way through, not a room the counts know; 3 is an empty
    # hall between the living room and the bedroom, and a dead end off the bath
    doors = {("r", "apartment", 1, 0): [(0, 1), (1, 2), (1, 3), (3, 4), (2, 5)]}
    rc = RoomContext.from_rows(rows, catalog, 0.05, doors)
    # the kitchen's door leads to the living room; the living room's to the kitchen and,
    # through the hall, to the bedroom; the bedroom's, through the hall, to the living room
    assert rc.next_n == {"Fridge": 1, "Sofa": 2, "Bed": 1}
    assert rc.next_y[("Fridge", "Sofa")] == rc.next_y[("Fridge", "Remote")] == 1
    assert rc.next_y[("Sofa", "Cup")] == 2 and rc.next_y[("Sofa", "Bed")] == 1
    assert ("Sofa", "Plant") not in rc.next_y  # the bath is passed through, never counted
    assert ("Sofa", "Remote") not in rc.next_y  # the living room's own remote is not beyond
    assert rc.next_y[("Bed", "Remote")] == 1 and ("Bed", "Fridge") not in rc.next_y
    lo, hi = intervals.interval(1, 2, 0.05)
    assert rc.next_interval("Sofa", "Bed") == (pytest.approx(lo), pytest.approx(hi), 1, 2)
    assert rc.next_room("Sofa", "Bed", Rank.LOW) == pytest.approx(lo)
    assert rc.next_room("Sofa", "Bed", Rank.HIGH) == pytest.approx(hi)
    assert rc.next_room("Sofa", "Bed", Rank.P0) == pytest.approx(intervals.p0(1, 2, 0.05))
    assert rc.next_room("Desk", "Cup", Rank.LOW) is None
    # no doors: the same-room counts, and no next-room ones
    plain = RoomContext.from_rows(rows, catalog, 0.05)
    assert plain.n == rc.n and plain.y == rc.y and plain.next_n == {}
    assert next_relation_name("Sofa") == "NEXT-ROOM-OF-SOFA"


def test_the_store_reads_doors_from_each_visits_remembered_map(tmp_path, catalog):
    m = make_map(seed=3)  # segments 0 (columns 0-24) and 1 (25-49) wherever there is floor
    lab = np.full(m.rooms.shape, -1, np.int16)
    lab[:, :25], lab[:, 25:] = 0, 1
    m = dataclasses.replace(m, rooms=lab)
    path = tmp_path / "k.sqlite"
    with EvidenceStore.open(path, catalog) as s:
        s.mark_room("r", "apartment", 3, "started")
        s.mark_room("r", "apartment", 3, "done", end_time=1.0, contents=[*KITCHEN, *LIVING],
                    home_map=m)  # fmt: skip
        s.mark_room("r", "apartment", 4, "started")  # a visit without a map: no pairs
        s.mark_room("r", "apartment", 4, "done", end_time=1.0, contents=[*KITCHEN, *LIVING])
    with EvidenceStore.open(path, catalog, read_only=True) as s:
        assert s.segment_doors() == {("r", "apartment", 3, 0): frozenset({(0, 1)})}
        rc = s.room_context()
    assert rc.rooms == 4 and rc.next_n == {"Fridge": 1, "Sofa": 1}
    assert rc.next_y[("Fridge", "Remote")] == 1 and rc.next_y[("Sofa", "Cup")] == 1


def test_kb_show_lists_what_lay_through_the_doors(tmp_path, catalog):
    m = make_map(seed=3)
    lab = np.full(m.rooms.shape, -1, np.int16)
    lab[:, :25], lab[:, 25:] = 0, 1
    path = tmp_path / "k.sqlite"
    with EvidenceStore.open(path, catalog) as s:
        s.mark_room("r", "apartment", 3, "started")
        s.mark_room("r", "apartment", 3, "done", end_time=1.0, contents=[*KITCHEN, *LIVING],
                    home_map=dataclasses.replace(m, rooms=lab))  # fmt: skip
    cmd = [sys.executable, "-m", "ctxsearch.scripts.cli", "kb", "show", str(path), "--type"]
    out = subprocess.run([*cmd, "Sofa"], capture_output=True, text=True, check=True).stdout
    assert "next rooms: what the room through a door" in out
    rows = [line.split()[:3] for line in out.splitlines() if line.startswith("NEXT-ROOM-OF")]
    assert ["NEXT-ROOM-OF-SOFA", "Cup", "1/1"] in rows
    assert ["NEXT-ROOM-OF-SOFA", "Fridge", "1/1"] in rows
    assert all(r[0] == "NEXT-ROOM-OF-SOFA" for r in rows)


def test_the_truth_counts_the_plans_doors(catalog):
    style = resolve_style("apartment", catalog)
    house = generate_layout(style, 7, catalog)
    doors = room_doors(house)
    assert doors and all(0 <= a < b < len(house.rooms) for a, b in doors)
    assert len(doors) == len({tuple(sorted(p.rooms)) for p in house.doors if min(p.rooms) >= 0})
    rt = room_truth(style, 1, catalog, seed=7)
    held: dict[int, set[str]] = {}
    for r, t, _ in room_contents(house):
        held.setdefault(r, set()).add(t)
    furnished = {r for r, t, _ in room_contents(house) if catalog.type(t).is_furniture}
    # an apartment's rooms all hold furniture: the next rooms are those sharing a door
    assert all(a in furnished and b in furnished for a, b in doors)
    for f in rt.counts.next_n:
        pairs = [
            (here, there)
            for a, b in doors
            for here, there in ((a, b), (b, a))
            if f in held.get(here, ()) and there in furnished
        ]
        assert rt.counts.next_n[f] == len(pairs)
        for t in catalog.type_names:
            want = sum(t in held.get(there, ()) for _, there in pairs) / len(pairs)
            assert rt.next_room[(f, t)] == pytest.approx(want)
    assert {e["relation"] for e in rt.next_entries()} == {
        next_relation_name(f) for f in rt.counts.next_n
    }


def _probs(same, nxt, share):
    return TableProbabilities({}).with_rooms(same, share, nxt)


def test_the_space_beyond_the_mapped_rooms_takes_the_next_room_ratio(catalog):
    house = generate_layout(resolve_style("apartment", catalog), 1234, catalog)
    spec = RobotSpec()
    built = BuiltMap.for_layout(house, spec, RobotPose(0.0, 0.0, 0.0))
    seen = WorldMaps.built(house, catalog, spec).seen
    fridge = next(o for o in house.objects if o.type == "Fridge")
    k = house.room_of[fridge.id]
    probs = _probs({("Fridge", "Cup"): 0.3}, {("Fridge", "Cup"): 0.9}, {"Cup": 0.3})
    off = RoomPrior(probs, "Cup", catalog, seen.points, None)  # next rooms off
    on = RoomPrior(probs, "Cup", catalog, seen.points, None, beyond=Beyond(next_room_m=50.0))
    # only the kitchen is mapped
    plan = RoomLabels.of_plan(house, built.resolution)
    assert plan.labels.shape == built.floor.shape
    built.floor[:] = wall_mask(house, built.resolution).free & (plan.labels == k)
    built.images += 1
    f_off = off.factor([fridge], built)
    f_on = on.factor([fridge], built)
    rooms = RoomLabels.of_built(built).at(seen.points)
    mapped = rooms >= 0
    assert mapped.any() and (~mapped).any()
    assert np.allclose(f_off[mapped], 1.0) and np.allclose(f_off[~mapped], 1.0)  # 0.3 / 0.3
    assert np.allclose(f_on[mapped], 1.0)  # the kitchen's own: SAME-ROOM, as without
    assert np.allclose(f_on[~mapped], 3.0)  # beyond its doors: 0.9 / 0.3
    # the next room reaches next_room_m behind the kitchen's edge; further on, the average
    short = RoomPrior(probs, "Cup", catalog, seen.points, None, beyond=Beyond(next_room_m=1.5))
    f = short.factor([fridge], built)
    _, dist = short.nearest()
    near, far = ~mapped & (dist <= 1.5), ~mapped & (dist > 1.5)
    assert near.any() and far.any()
    assert np.allclose(f[near], 3.0) and np.allclose(f[far], 1.0)
    # a sofa glimpsed beyond the mapped floor: the space near it is its room
    sofa = next(o for o in house.objects if o.type == "Sofa")
    probs = _probs({("Fridge", "Cup"): 0.3, ("Sofa", "Cup"): 0.03},
                   {("Fridge", "Cup"): 0.9}, {"Cup": 0.3})  # fmt: skip
    on = RoomPrior(probs, "Cup", catalog, seen.points, None, beyond=Beyond(next_room_m=50.0))
    f = on.factor([fridge, sofa], built)
    near = np.hypot(seen.points[:, 0] - sofa.position[0], seen.points[:, 1] - sofa.position[1])
    assert np.allclose(f[~mapped & (near <= 2.0)], MIN_FACTOR)  # 0.03 / 0.3, clipped
    assert np.allclose(f[~mapped & (near > 2.0)], 3.0)
    # the recording's groups: the belief beyond the kitchen, in one group, summed
    w = np.ones(len(seen.points)) / len(seen.points)
    (group,) = on.beyond_groups(w)
    assert group[0] == int(np.unique(RoomLabels.of_built(built).labels[built.floor])[0])
    assert group[2] == pytest.approx((~mapped).sum() / len(seen.points))
    # the ratio is clipped like the room's own
    big = _probs({}, {("Fridge", "Cup"): 1.0}, {"Cup": 0.01})
    f = RoomPrior(big, "Cup", catalog, seen.points, None, beyond=Beyond(next_room_m=50.0)).factor(
        [fridge], built
    )
    assert np.allclose(f[~mapped], MAX_FACTOR)
    # the given map's rooms are the plan's: nothing lies beyond them
    maps = WorldMaps.given(house, catalog, spec)
    given = RoomPrior.for_search(probs, "Cup", catalog, maps.seen.points, maps.plan_rooms, Beyond())
    assert given.next is None


def test_next_rooms_is_part_of_room_context():
    with pytest.raises(ConfigError, match="knowledge.next_rooms needs knowledge.room_context"):
        SearchConfig(knowledge=KnowledgeConfig(next_rooms=True))
    cfg = SearchConfig(knowledge=KnowledgeConfig(next_rooms=True, room_context=True))
    assert (cfg.knowledge.glimpse_m, cfg.knowledge.next_room_m) == (Beyond().glimpse_m,
                                                                   Beyond().next_room_m)  # fmt: skip


def test_a_built_map_search_records_the_mass_beyond_each_mapped_room(tmp_path):
    from rerun.chunk import RrdReader

    from tests.rrd_files import _columns

    rrd = tmp_path / "s.rrd"
    cmd = [sys.executable, "-m", "ctxsearch.scripts.cli", "search", "--style", "apartment",
           "--map", "built", "--target", "Cup", "--policy", "oracle-prior-indirect",
           "--room-context", "--set", "knowledge.next_rooms=true", "--truth-samples", "3",
           "--budget-seconds", "30", "--record", str(rrd)]  # fmt: skip
    subprocess.run(cmd, capture_output=True, text=True, check=True)
    labels, masses = [], []
    for c in RrdReader(rrd).stream():
        cols = _columns(c)
        if c.entity_path == "/world/search/beyond":
            labels += [lab for row in cols.get("Points3D:labels", []) for lab in row]
        if c.entity_path == "/search/beyond_mass/oracle-prior-indirect":
            masses += [v[0] for v in cols["Scalars:scalars"]]
    assert labels and all(lab.startswith("beyond room ") for lab in labels)
    assert masses and all(0.0 < m <= 1.0 + 1e-9 for m in masses)
