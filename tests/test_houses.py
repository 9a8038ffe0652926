"""House styles and floor plans: shipped houses load, bad files give one-line errors, plans are
deterministic, every room is reachable through doors, nothing interpenetrates, rule placements
hold, and ground truth counts a house as the mix of its rooms."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from scipy import ndimage

from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.envs.floorplan import (
    generate_house,
    generate_layout,
    layout_dict,
    room_at,
    wall_boxes,
    wall_obstacles,
)
from ctxsearch.envs.houses import (
    CORRIDOR,
    HouseError,
    HouseStyle,
    available_houses,
    load_house,
    resolve_style,
)
from ctxsearch.envs.layout import Door
from ctxsearch.envs.parts import world_parts
from ctxsearch.envs.plans import _shared_edge
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.envs.rooms import RoomShell, door_entry, generate_room
from ctxsearch.envs.styles import Style, StyleError, available_styles, load_style
from ctxsearch.envs.truth import estimate, ground_truth, world_counts
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.geometry import BoxArray, holds, overlaps

HOUSES = ["apartment", "family_house", "office_floor"]
SEEDS = {"apartment": range(6), "family_house": range(4), "office_floor": range(3)}


@functools.cache
def cat():
    return load_catalog()


def reachable_rooms(lay) -> set[int]:
    """The rooms with free floor in the navigation grid's free region that holds the entrance's
    front (the grid the robot plans on: walls with their door gaps, furniture, clearance)."""
    grid = OccupancyGrid.from_layout(lay, RobotSpec(), resolution=0.1)
    labels, _ = ndimage.label(grid.free)
    x, y, _ = door_entry(lay)
    entry = labels[grid.to_cell(np.array([x, y]))]
    if entry == 0:
        return set()
    xs, ys = grid.cell_centers()
    out = set()
    for r in lay.rooms:
        x0, y0, x1, y1 = r.outline
        block = labels[np.ix_((ys >= y0) & (ys <= y1), (xs >= x0) & (xs <= x1))]
        if np.any(block == entry):
            out.add(r.index)
    return out


@functools.cache
def houses(name: str):
    st = load_house(name, cat())
    return tuple(generate_house(st, s, cat()) for s in SEEDS[name])


def test_shipped_houses_load_and_names_do_not_collide():
    assert set(HOUSES) <= set(available_houses())
    assert not set(available_houses()) & set(available_styles())
    for name in available_houses():
        st = resolve_style(name, cat())
        assert isinstance(st, HouseStyle) and st.name == name
    assert isinstance(resolve_style("office", cat()), Style)
    office_floor = load_house("office_floor", cat())
    assert {s.name for s, _ in office_floor.rooms} >= {"office", "biology_lab", "kitchen"}
    assert office_floor.plan == "corridor"
    assert 3 <= load_house("apartment", cat()).total[0] <= load_house("apartment").total[1] <= 5
    assert load_house("family_house", cat()).total == (5, 8)


def test_resolve_paths(tmp_path):
    p = tmp_path / "h.toml"
    p.write_text(
        'name = "tiny_house"\n[house]\nrooms = 2\nfootprint = [40, 60]\nplan = "open"\n'
        "[rooms]\nbedroom = 1\nkitchen = 1\n"
    )
    st = resolve_style(p, cat())
    assert isinstance(st, HouseStyle) and st.plan == "open"
    lay = generate_layout(st, 3, cat())
    assert lay.is_house and {r.style for r in lay.rooms} == {"bedroom", "kitchen"}
    assert isinstance(resolve_style(load_style("office").path, cat()), Style)


BAD = [
    ("[house]\nrooms = 3\nfootprint = 80\n[rooms]\nbedroom = 3\nsauna = 1\n", "rooms.sauna"),
    ("[house]\nrooms = 3\nfootprint = 80\nwindows = 2\n[rooms]\nbedroom = 3\n", "house.windows"),
    ("[house]\nrooms = 3\nfootprint = 900\n[rooms]\nbedroom = 3\n", "house.footprint"),
    ("[house]\nrooms = 3\nfootprint = [90, 80]\n[rooms]\nbedroom = 3\n", "house.footprint"),
    ("[house]\nrooms = 3\nfootprint = 80\nplan = 'maze'\n[rooms]\nbedroom = 3\n", "house.plan"),
    ("[house]\nrooms = [6, 7]\nfootprint = 150\n[rooms]\nbedroom = 3\n", "field 'rooms'"),
    ("[house]\nrooms = 3\nfootprint = 80\n[rooms]\nbedroom = 'three'\n", "rooms.bedroom"),
    ("[house]\nrooms = 3\nfootprint = 80\n[rooms]\nbedroom = -1\n", "rooms.bedroom"),
    ("[house]\nrooms = 3\nfootprint = 'nan'\n[rooms]\nbedroom = 3\n", "house.footprint"),
    ("[house]\nfootprint = 80\n[rooms]\nbedroom = 3\n", "house.rooms"),
    ("[house]\nrooms = 3\nfootprint = 80\nentrance = 'hall'\n[rooms]\nbedroom = 3\n", "entrance"),
    ("[house]\nrooms = 3\nfootprint = 20\n[rooms]\nbedroom = 3\n", "house.footprint"),
    ("[house]\nrooms = 3\nfootprint = 80\n[rooms]\n'missing.toml' = 3\n", "rooms.missing"),
    ("name = 'office'\n[house]\nrooms = 1\nfootprint = 40\n[rooms]\nbedroom = 1\n", "'name'"),
    ("[house]\nrooms = 3\nfootprint = 80\n[rooms]\n", "field 'rooms'"),
    ("[house\nrooms = 3\n", "TOML syntax error"),
]


@pytest.mark.parametrize("text,where", BAD)
def test_bad_house_files_give_one_line_errors(tmp_path, text, where):
    p = tmp_path / "bad_house.toml"
    p.write_text(text)
    with pytest.raises(StyleError) as exc:
        load_house(p, cat())
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(str(p)) and where in msg, msg
    if "TOML" not in where:  # the resolver sees the [house] table and reports the same
        with pytest.raises(HouseError) as exc2:
            resolve_style(p, cat())
        assert str(exc2.value) == msg


def test_bad_house_style_through_the_cli(tmp_path, capsys):
    from ctxsearch.scripts import cli

    p = tmp_path / "bad_house.toml"
    p.write_text("[house]\nrooms = 3\nfootprint = 80\n[rooms]\nbedroom = 3\nsauna = 1\n")
    for argv in (
        ["room", "--style", str(p), "--out", str(tmp_path / "o")],
        ["truth", "--style", str(p), "--samples", "1", "--out", str(tmp_path / "t.json")],
        ["room", "--style", "no_such_style", "--out", str(tmp_path / "o")],
    ):
        assert cli.main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("ctxsearch: error: ") and "\n" not in err
    assert "house styles: apartment" in err


@pytest.mark.parametrize("name", HOUSES)
def test_same_seed_same_plan(name):
    st = load_house(name, cat())
    a, b = generate_house(st, 7, cat()), generate_house(st, 7, cat())
    assert layout_dict(a) == layout_dict(b)
    assert layout_dict(a) != layout_dict(generate_house(st, 8, cat()))


@pytest.mark.parametrize("name", HOUSES)
def test_plan_shape(name):
    st = load_house(name, cat())
    for lay in houses(name):
        rooms = [r for r in lay.rooms if r.style != CORRIDOR]
        assert st.total[0] <= len(rooms) <= st.total[1]
        assert (lay.rooms[-1].style == CORRIDOR) == (st.plan == "corridor")
        assert st.footprint[0] - 1e-6 <= lay.width * lay.depth <= st.footprint[1] + 1e-6
        assert 40 <= lay.width * lay.depth <= 200
        counts = {s.name: sum(r.style == s.name for r in rooms) for s, _ in st.rooms}
        for s, (lo, hi) in st.rooms:
            assert lo <= counts[s.name] <= hi
        # Room outlines lie inside the footprint and do not overlap.
        for r in lay.rooms:
            x0, y0, x1, y1 = r.outline
            assert -lay.width / 2 - 1e-9 <= x0 < x1 <= lay.width / 2 + 1e-9
            assert -lay.depth / 2 - 1e-9 <= y0 < y1 <= lay.depth / 2 + 1e-9
            for q in lay.rooms:
                if q.index > r.index:
                    a0, b0, a1, b1 = q.outline
                    ox = min(x1, a1) - max(x0, a0)
                    oy = min(y1, b1) - max(y0, b0)
                    assert ox <= 1e-9 or oy <= 1e-9


@pytest.mark.parametrize("name", HOUSES)
def test_all_rooms_reachable_through_doors(name):
    for lay in houses(name):
        n = len(lay.rooms)
        # Doors form a connected graph over the rooms, with exactly one entrance.
        assert sum(p.rooms[1] == -1 for p in lay.doors) == 1
        adj = {i: set() for i in range(n)}
        for p in lay.doors:
            a, b = p.rooms
            if b >= 0:
                adj[a].add(b)
                adj[b].add(a)
                # The door lies on the wall the two rooms share.
                ra, rb = lay.rooms[a].outline, lay.rooms[b].outline
                grow = 0.05  # back to the cells: the wall's centre line
                edge = _shared_edge(
                    (ra[0] - grow, ra[1] - grow, ra[2] + grow, ra[3] + grow),
                    (rb[0] - grow, rb[1] - grow, rb[2] + grow, rb[3] + grow),
                )
                assert edge is not None and edge[0] == p.axis
        seen, todo = {0}, [0]
        while todo:
            for j in adj[todo.pop()] - seen:
                seen.add(j)
                todo.append(j)
        assert seen == set(range(n))
        # And the robot can drive from the entrance into every room (walls, furniture, doors).
        assert reachable_rooms(lay) == set(range(n)), lay.seed


def test_reachability_check_sees_a_closed_door():
    lay = houses("family_house")[0]
    import dataclasses

    room = lay.doors[0].rooms[0]  # every door of it shut (the corridor's, a neighbour's)
    shut = dataclasses.replace(lay, doors=tuple(p for p in lay.doors if room not in p.rooms))
    assert reachable_rooms(shut) == set(range(len(lay.rooms))) - {room}


@pytest.mark.parametrize("name", HOUSES)
def test_nothing_interpenetrates_and_objects_know_their_room(name):
    for lay in houses(name):
        boxes, owner = [], []
        for o in lay.objects:
            for b in world_parts(o, cat()):
                boxes.append(b)
                owner.append(o.id)
        walls = wall_obstacles(lay)
        arr = BoxArray(
            np.array([b.center for b in boxes]),
            np.array([b.yaw for b in boxes]),
            np.array([b.half for b in boxes]),
        )
        owner = np.array(owner)
        for b, oid in zip(boxes, owner, strict=True):
            assert not (overlaps(arr, b) & (owner != oid)).any(), (lay.seed, oid)
        wall_arr = BoxArray(
            np.array([w.center for w in walls]),
            np.zeros(len(walls)),
            np.array([w.half for w in walls]),
        )
        for b in boxes:
            assert not overlaps(wall_arr, b).any()
        ids = [o.id for o in lay.objects]
        assert len(set(ids)) == len(ids) and set(lay.room_of) == set(ids)
        for o in lay.objects:
            r = lay.rooms[lay.room_of[o.id]]
            assert r.style != CORRIDOR
            xy = o.box().corners_xy()
            x0, y0, x1, y1 = r.outline
            assert np.all((xy[:, 0] >= x0 - 1e-6) & (xy[:, 0] <= x1 + 1e-6))
            assert np.all((xy[:, 1] >= y0 - 1e-6) & (xy[:, 1] <= y1 + 1e-6))
            assert room_at(lay, o.position[0], o.position[1]) == r.index
            sup = lay.support[o.id]
            assert sup is None or lay.room_of[sup] == r.index


@pytest.mark.parametrize("name", HOUSES)
def test_rule_placements_hold(name):
    n = 0
    for lay in houses(name):
        for oid, (ref_id, rel) in lay.placed_by.items():
            assert holds(cat().relation(rel), lay.by_id(oid), lay.by_id(ref_id))
            assert lay.room_of[oid] == lay.room_of[ref_id]
            n += 1
    assert n > 0


@pytest.mark.parametrize("name", HOUSES)
def test_doors_kept_clear(name):
    for lay in houses(name):
        grid = OccupancyGrid.from_layout(lay, RobotSpec(), resolution=0.1)
        for p in lay.doors:
            # Both sides of every door opening (0.6 m out) are free floor.
            nx, ny = (0.0, 1.0) if p.axis == "x" else (1.0, 0.0)
            for side in (1, -1) if p.rooms[1] >= 0 else ():
                x, y = p.center[0] + side * 0.6 * nx, p.center[1] + side * 0.6 * ny
                assert grid.is_free(np.array([x, y])), (lay.seed, p)


def test_room_shell_with_two_doors_keeps_both_entries_free():
    st = load_style("bedroom", cat())
    doors = (Door("south", 0.0, 0.9), Door("east", 0.5, 0.9))
    for seed in range(4):
        lay = generate_room(st, seed, cat(), shell=RoomShell(4.5, 4.0, 2.6, doors))
        assert (lay.width, lay.depth, lay.height, lay.door) == (4.5, 4.0, 2.6, doors[0])
        for x, y in ((0.0, -2.0 + 0.6), (2.25 - 0.6, 0.5)):
            for o in lay.objects:
                if o.bottom < 1.2:
                    assert o.box().footprint_distance(np.array([[x, y]]))[0] > 0.27


def test_wall_boxes_have_the_door_gaps():
    lay = houses("office_floor")[0]
    boxes = wall_boxes(lay)
    assert wall_boxes(generate_room(load_style("office"), 0, cat())) == []
    full = [b for b in boxes if not b[0].endswith("lintel")]
    lintels = [b for b in boxes if b[0].endswith("lintel")]
    assert len(lintels) == len(lay.doors)  # every opening has a lintel (ceilings above 2.1 m)
    for p in lay.doors:  # no full-height wall crosses an opening's centre
        for _, c, h in full:
            inside = abs(p.center[0] - c[0]) < h[0] - 1e-6 and abs(p.center[1] - c[1]) < h[1]
            assert not inside or abs(p.center[1] - c[1]) > h[1] - 1e-6


def test_truth_of_a_house_is_the_mix_of_its_rooms():
    st = load_house("apartment", cat())
    truth = ground_truth(st, 2, seed=0, catalog=cat())
    lays = [generate_house(st, s, cat()) for s in range(2)]
    units = [c for lay in lays for c in world_counts(lay, cat())]
    assert truth["rooms"] == len(units) == sum(len(lay.rooms) for lay in lays)
    assert repr(truth["entries"]) == repr(estimate(units, cat()))  # repr: nan == nan
    desk = [e for e in truth["entries"] if e["ref"] == "Sofa"]
    assert desk and desk[0]["n"] == sum(o.type == "Sofa" for lay in lays for o in lay.objects)
    assert "rooms" not in ground_truth("office", 1, catalog=cat())


@pytest.mark.render
def test_house_world_builds_with_robot_at_the_entrance():
    import time

    from ctxsearch.envs.task import start_pose
    from ctxsearch.envs.world import World

    lay = next(h for h in houses("family_house") if len(h.rooms) == 6)
    t0 = time.perf_counter()
    with World(lay, cat()) as w:
        build_s = time.perf_counter() - t0
        names = [w._m.geom(i).name for i in range(w._m.ngeom)]
        assert sum(n.startswith("floor_room") for n in names) == len(lay.rooms)
        assert sum("hwall" in n for n in names) == len(wall_boxes(lay))
        pose = w.pose()
        entrance = next(p for p in lay.doors if p.rooms[1] == -1)
        assert room_at(lay, pose.x, pose.y) == entrance.rooms[0]
        assert np.allclose([pose.x, pose.y], [start_pose(lay).x, start_pose(lay).y], atol=1e-3)
        frame = w.capture()
        assert (frame.instance_ids >= 0).any() or (frame.depth > 0).all()
    assert build_s < 3.0  # measured ~0.15-0.3 s on the 2-core VM; generous for CI


def test_truth_cli_on_a_house(tmp_path, capsys):
    import json

    from ctxsearch.scripts import cli

    out = tmp_path / "t.json"
    assert cli.main(["truth", "--style", "apartment", "--samples", "2", "--out", str(out)]) == 0
    truth = json.loads(out.read_text())
    assert truth["style"] == "apartment" and truth["samples"] == 2 and truth["rooms"] >= 6
    out_text = capsys.readouterr().out
    assert "2 houses (" in out_text and "SAME-ROOM-AS-" in out_text
    # SAME-ROOM-AS-F(T), counted here straight from the two plans: of the rooms holding an F,
    # those holding a T other than that F (a second F for T = F)
    lays = [generate_layout(resolve_style("apartment", cat()), s, cat()) for s in (0, 1)]
    n, y = {}, {}
    for lay in lays:
        rooms = {}
        for o in lay.objects:
            rooms.setdefault(lay.room_of.get(o.id, 0), []).append(o.type)
        for types in rooms.values():
            for f in {t for t in types if cat().type(t).is_furniture}:
                n[f] = n.get(f, 0) + 1
                rest = list(types)
                rest.remove(f)
                for t in set(rest):
                    y[(f, t)] = y.get((f, t), 0) + 1
    same = {(e["ref"], e["type"]): e for e in truth["same_room"]}
    assert {f for f, _ in same} == set(n)
    for (f, t), e in same.items():
        assert e["relation"] == f"SAME-ROOM-AS-{f.upper()}" and e["n"] == n[f]
        assert e["y"] == y.get((f, t), 0) and e["p"] == pytest.approx(y.get((f, t), 0) / n[f])
    assert any(e["p"] > 0 for e in same.values()) and any(e["p"] == 0 for e in same.values())
    assert 0 < truth["furnished_rooms"] <= truth["rooms"]
    assert all(0 < v <= 1 for v in truth["room_share"].values())


def test_every_style_flag_says_house(capsys):
    from ctxsearch.scripts import cli

    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    seen = 0
    for name, p in sub.choices.items():
        for parsers in [p, *(getattr(a, "choices", None) or {} for a in p._actions)]:
            items = parsers.values() if isinstance(parsers, dict) else [parsers]
            for q in items:
                if not hasattr(q, "_actions"):
                    continue
                for a in q._actions:
                    if "--style" in a.option_strings:
                        assert "house style" in a.help, (name, q.prog)
                        seen += 1
    assert seen >= 6


@pytest.mark.render
def test_room_cli_on_a_house_writes_plan_views_and_layout(tmp_path, capsys):
    import json

    import cv2

    from ctxsearch.scripts import cli

    out = tmp_path / "house"
    argv = ["room", "--style", "apartment", "--seed", "1", "--out", str(out), "--views", "1"]
    assert cli.main(argv) == 0
    assert "house (" in capsys.readouterr().out
    img = cv2.imread(str(out / "overview.png"))
    assert img.shape == (720, 960, 3)
    assert (out / "view_0.png").exists()
    data = json.loads((out / "layout.json").read_text())
    lay = generate_house(load_house("apartment", cat()), 1, cat())
    assert data == json.loads(json.dumps(layout_dict(lay)))
    assert data["kind"] == "house" and len(data["rooms"]) == len(lay.rooms)
    assert {"style", "outline"} <= set(data["rooms"][0])
    assert {"type", "id", "position", "yaw", "size", "room"} <= set(data["objects"][0])
    assert all(0 <= o["room"] < len(data["rooms"]) for o in data["objects"])
    # the robot's own rooms (issue 27): it explored the house and cut its map at the doors
    rooms = json.loads((out / "rooms.json").read_text())
    assert rooms["segments"] == len(lay.rooms) and rooms["explore_sim_s"] > 0
    assert all(r["iou"] >= 0.8 for r in rooms["rooms"] if r["seen"] >= 0.9)
    plan_and_robot = cv2.imread(str(out / "rooms.png"))  # side by side
    assert plan_and_robot.shape[1] > plan_and_robot.shape[0]


def test_visible_rooms_by_portals():
    from ctxsearch.envs.floorplan import visible_rooms

    lay = houses("office_floor")[0]
    corridor = lay.rooms[-1]
    assert corridor.style == CORRIDOR
    everyone = set(range(len(lay.rooms)))
    cx, cy = corridor.center
    assert visible_rooms(lay, cx, cy) <= everyone and corridor.index in visible_rooms(lay, cx, cy)
    for r in lay.rooms[:-1]:
        seen = visible_rooms(lay, *r.center)
        assert r.index in seen and corridor.index in seen  # every office opens on the corridor
    assert visible_rooms(lay, 1e3, 1e3) is None  # outside any room: cannot tell
    # A room whose door is closed (the door removed) sees nothing else.
    import dataclasses

    first = next(p for p in lay.doors if p.rooms[1] != -1)
    shut = dataclasses.replace(lay, doors=tuple(p for p in lay.doors if p is not first))
    assert visible_rooms(shut, *lay.rooms[first.rooms[0]].center) == {first.rooms[0]}


@pytest.mark.render
def test_room_culling_leaves_the_images_unchanged():
    from ctxsearch.envs.robot_spec import RobotPose
    from ctxsearch.envs.world import World

    rng = np.random.default_rng(5)
    hidden = 0
    for lay in (houses("office_floor")[0], houses("apartment")[1]):
        grid = OccupancyGrid.from_layout(lay)
        rows, cols = np.nonzero(grid.free)
        with World(lay, cat()) as w:
            cull = w._culling
            assert cull is not None
            for _ in range(15):
                i = rng.integers(len(rows))
                x, y = grid.to_xy(rows[i], cols[i])
                w.reset_pose(RobotPose(float(x), float(y), float(rng.uniform(-np.pi, np.pi))))
                w.move_head(float(rng.uniform(-2.5, 2.5)), float(rng.uniform(-0.9, 0.3)))
                w._culling = cull
                a = w.capture()
                cam = (w._d.cam_xpos[w._cam_id], w._d.cam_xmat[w._cam_id])
                hidden += cull.hide(*cam, float(w._m.cam_fovy[w._cam_id]), w.width, w.height)
                cull.restore()
                w._culling = None
                b = w.capture()
                assert np.array_equal(a.instance_ids, b.instance_ids)
                assert np.allclose(a.depth, b.depth)
            w._culling = cull
            assert np.all(w._m.geom_rgba[:, 3] > 0)  # restored
    assert hidden > 0


GOOD_HOUSE = {
    "name": "fuzz_house",
    "house": {
        "rooms": [2, 3],
        "footprint": [50, 90],
        "height": [2.5, 2.8],
        "plan": "open",
        "corridor_width": [1.3, 1.5],
        "door_width": [0.85, 0.95],
        "entrance": "living_room",
    },
    "rooms": {"living_room": 1, "bedroom": [1, 2]},
    "layout": {"bedroom": {"only_to": ["living_room"], "by_entrance": True}},
}
ODD_VALUES = [-1, 0, 1e9, float("nan"), float("inf"), "x", [], [1], [1, 2, 3], [2, 1], True, {}]


def _toml(doc: dict) -> str:
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, float) and v != v:
            return "nan"
        if isinstance(v, float) and v in (float("inf"), float("-inf")):
            return "inf" if v > 0 else "-inf"
        if isinstance(v, str):
            return f'"{v}"'
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        if isinstance(v, dict):
            return "{" + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + "}"
        return repr(v)

    lines = [f"{k} = {val(v)}" for k, v in doc.items() if not isinstance(v, dict)]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines.append(f"[{k}]")
            lines += [f"{kk} = {val(vv)}" for kk, vv in v.items()]
    return "\n".join(lines) + "\n"


def test_any_house_file_gives_a_style_or_a_one_line_error(tmp_path):
    import copy

    rng = np.random.default_rng(0)
    p = tmp_path / "fuzz.toml"
    p.write_text(_toml(GOOD_HOUSE))
    assert isinstance(load_house(p, cat()), HouseStyle)
    cases = []
    for section in ("house", "rooms", "layout"):
        for key in GOOD_HOUSE[section]:
            for v in ODD_VALUES:
                doc = copy.deepcopy(GOOD_HOUSE)
                doc[section][key] = v
                cases.append(_toml(doc))
    for rule in GOOD_HOUSE["layout"]["bedroom"]:  # the layout rules' own fields
        for v in [*ODD_VALUES, ["sauna"], ["corridor"], ["bedroom", "bedroom"]]:
            doc = copy.deepcopy(GOOD_HOUSE)
            doc["layout"]["bedroom"][rule] = v
            cases.append(_toml(doc))
    for _ in range(40):
        text = bytes(rng.integers(0, 256, int(rng.integers(0, 80))).tolist())
        cases.append(text)
        good = _toml(GOOD_HOUSE).encode()
        cut = int(rng.integers(len(good)))
        cases.append(good[:cut] + text[:5] + good[cut + 5 :])
    n_err = 0
    for text in cases:
        if isinstance(text, str):
            p.write_text(text)
        else:
            p.write_bytes(text)
        try:
            st = load_house(p, cat())
        except StyleError as exc:
            assert "\n" not in str(exc) and str(exc).startswith(str(p))
            n_err += 1
        else:
            assert isinstance(st, HouseStyle)
    assert n_err > len(cases) // 2
