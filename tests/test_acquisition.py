"""The acquisition loop (Figure 2): a tiny hand-made room with hand-computed counts, resume, the
rerun recording, and the camera mode on the same room."""

from __future__ import annotations

import math

import pytest

from ctxsearch.agent import learning
from ctxsearch.agent.acquisition import start_pose
from ctxsearch.agent.exam_volumes import group_volumes, relation_boxes
from ctxsearch.agent.learning import LearnConfig, room_seed
from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.agent.perception_modes import KinematicBody, OraclePerception
from ctxsearch.envs.layout import Door, RoomLayout
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec, TimeModel
from ctxsearch.knowledge.catalog import parse_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance


def learn(*args, **kw):
    """``learning.learn`` with the configuration's fields and the hooks as keywords."""
    names = ("catalog", "layouts", "on_examination", "on_choice", "perceive")
    hooks = {k: kw.pop(k) for k in names if k in kw}
    return learning.learn(LearnConfig(*args, **kw), **hooks)


def _rel(name, lo, hi, mlo=(0, 0, 0), mhi=(0, 0, 0)):
    return {
        "name": name,
        "lo": list(lo),
        "hi": list(hi),
        "margin_lo": list(mlo),
        "margin_hi": list(mhi),
    }


FULL_LO, FULL_HI = (-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)


def tiny_catalog(lamp: bool = False):
    """Four types with a few relations each; volumes chosen so the counts below are easy to verify.
    With ``lamp``, a fifth type whose only relation volume lies 20 m away (beyond any wall)."""

    def typ(name, kind, shape, size, color, rels, min_pixels=20, max_range=8.0):
        return {
            "name": name,
            "kind": kind,
            "shape": shape,
            "size": list(size),
            "color": list(color),
            "min_pixels": min_pixels,
            "max_range": max_range,
            "relation": rels,
        }

    return parse_catalog(
        {
            "type": [
                typ(
                    "Desk",
                    "furniture",
                    "desk",
                    (0.7, 1.4, 0.75),
                    (0.55, 0.38, 0.22),
                    [
                        _rel("ON-TOP-OF-DESK", (-0.5, -0.5, 0.5), FULL_HI, mhi=(0, 0, 0.3)),
                        _rel("IN-FRONT-OF-DESK", (0.5, -0.5, -0.5), FULL_HI, mhi=(0.8, 0, 0)),
                    ],
                    min_pixels=300,
                ),
                typ(
                    "Chair",
                    "furniture",
                    "chair",
                    (0.5, 0.5, 0.9),
                    (0.2, 0.3, 0.55),
                    [
                        _rel(
                            "NEAR-CHAIR", FULL_LO, FULL_HI, mlo=(-0.3, -0.3, 0), mhi=(0.3, 0.3, 0)
                        ),
                    ],
                    min_pixels=200,
                ),
                typ(
                    "Cup",
                    "object",
                    "mug",
                    (0.08, 0.08, 0.1),
                    (0.9, 0.9, 0.85),
                    [
                        _rel(
                            "NEAR-CUP", FULL_LO, FULL_HI, mlo=(-0.3, -0.3, 0), mhi=(0.3, 0.3, 0.1)
                        ),
                    ],
                    max_range=4.0,
                ),
                typ(
                    "Book",
                    "object",
                    "box",
                    (0.2, 0.15, 0.04),
                    (0.7, 0.15, 0.15),
                    [
                        _rel(
                            "NEAR-BOOK", FULL_LO, FULL_HI, mlo=(-0.3, -0.3, 0), mhi=(0.3, 0.3, 0.1)
                        ),
                    ],
                    max_range=5.0,
                ),
            ]
            + (
                [
                    typ(
                        "Lamp",
                        "object",
                        "box",
                        (0.2, 0.2, 0.4),
                        (0.9, 0.8, 0.3),
                        [_rel("FAR-LAMP", (0, 0, 0), (0, 0, 0), (20, 20, 0), (21, 21, 0.5))],
                    )
                ]
                if lamp
                else []
            )
        }
    )


def tiny_room(seed: int = 1) -> RoomLayout:
    """A 5 x 5 m room, door in the south wall: a desk against the north wall facing the room (-y),
    a cup and a book on it, a chair in front of it.

    By hand: ON-TOP-OF-DESK holds for the cup and the book (they rest on the top), the chair is
    IN-FRONT-OF-DESK (0.8 m slab in front), the desk is NEAR-CHAIR (0.3 m around the chair reaches
    y = 1.35 > 1.15, the desk's front edge), and nothing else holds: the cup and book are 0.6 m
    apart (NEAR margins 0.3 m), and touching the desk top is not overlapping it."""
    desk = ObjectInstance("Desk", 0, (0.0, 1.5, 0.375), -math.pi / 2, (0.7, 1.4, 0.75))
    cup = ObjectInstance("Cup", 1, (-0.3, 1.5, 0.8), 0.0, (0.08, 0.08, 0.1))
    book = ObjectInstance("Book", 2, (0.3, 1.5, 0.77), 0.0, (0.2, 0.15, 0.04))
    chair = ObjectInstance("Chair", 3, (0.0, 0.8, 0.45), math.pi / 2, (0.5, 0.5, 0.9))
    return RoomLayout(
        style="tiny",
        seed=seed,
        width=5.0,
        depth=5.0,
        height=2.6,
        door=Door("south", 0.0, 1.0),
        objects=(desk, cup, book, chair),
        support={0: None, 1: 0, 2: 0, 3: None},
    )


EXPECTED_PAIRS = {
    "Desk": {("ON-TOP-OF-DESK", "Cup"), ("ON-TOP-OF-DESK", "Book"), ("IN-FRONT-OF-DESK", "Chair")},
    "Chair": {("NEAR-CHAIR", "Desk")},
    "Cup": set(),
    "Book": set(),
}


def _learn(tmp_path, name="kb.sqlite", rooms=1, **kw):
    cat = kw.pop("catalog", None) or tiny_catalog()
    kw.setdefault("perception", "oracle")
    return learn(
        "tiny",
        rooms,
        tmp_path / name,
        catalog=cat,
        layouts=lambda i, s: tiny_room(s),
        progress=False,
        **kw,
    ), cat


def _kb(path, cat):
    from ctxsearch.knowledge.store import EvidenceStore

    with EvidenceStore.open(path, cat, create=False) as st:
        return st.knowledge_base()


def test_hand_made_room_oracle_counts_and_order(tmp_path):
    order = []
    summary, cat = _learn(
        tmp_path, on_examination=lambda res, kb: order.append(res.choice.obj.type)
    )
    # The robot enters at the door (0, -1.9): the chair is the nearest thing it recognizes; the
    # chair's NEAR volume holds the desk; the desk holds the cup, the book and the chair (already
    # examined); cup and book tie at impact(0, 0) and go in catalog order.
    assert order == ["Chair", "Desk", "Cup", "Book"]
    assert summary.examinations == 4 and summary.total_examinations == 4
    assert summary.rooms == 1 and summary.types_seen == 4
    kb = _kb(tmp_path / "kb.sqlite", cat)
    for t, pairs in EXPECTED_PAIRS.items():
        assert kb.n(t) == 1
        assert {k for k, v in kb.nonzero(t).items() if v} == pairs
    assert summary.sim_s > 0


def test_hand_made_room_two_rooms_add_up(tmp_path):
    summary, cat = _learn(tmp_path, rooms=2, strategy="random")
    kb = _kb(tmp_path / "kb.sqlite", cat)
    assert summary.examinations == 8
    for t, pairs in EXPECTED_PAIRS.items():
        assert kb.n(t) == 2
        assert all(kb.y(r, b) == 2 for r, b in pairs)


@pytest.mark.parametrize("strategy", ["random", "round-robin", "cost-hif"])
def test_resume_gives_the_same_counts_as_an_uninterrupted_run(tmp_path, strategy):
    from ctxsearch.envs.rooms import generate_room
    from ctxsearch.envs.styles import load_style
    from ctxsearch.knowledge.catalog import load_catalog

    cat = load_catalog()
    style = load_style("office", cat)
    rooms = {}

    def layouts(i, s):
        if s not in rooms:
            rooms[s] = generate_room(style, s, cat)
        return rooms[s]

    def go(path, **kw):
        seq = []
        s = learn(
            "office",
            2,
            path,
            strategy=strategy,
            perception="oracle",
            seed=3,
            catalog=cat,
            layouts=layouts,
            progress=False,
            on_examination=lambda res, kb: seq.append((res.choice.obj.id, round(res.sim_time, 6))),
            **kw,
        )
        return s, seq

    full, seq_full = go(tmp_path / "full.sqlite")
    n1 = len(rooms[room_seed(3, 0)].objects)
    # Interrupt in the middle of the second room, then again right at a room's start, then finish.
    part1, seq1 = go(tmp_path / "part.sqlite", max_examinations=n1 + 5)
    assert part1.examinations == n1 + 5 and part1.rooms == 1
    part2, seq2 = go(tmp_path / "part.sqlite", max_examinations=3)
    part3, seq3 = go(tmp_path / "part.sqlite")
    assert part3.rooms == 2 and part3.total_examinations == full.total_examinations
    # The replayed examinations come back first, with the same choices and clock.
    assert seq1 == seq_full[: n1 + 5]
    assert seq2 == seq_full[n1 : n1 + 8]
    assert seq3 == seq_full[n1:]
    assert part2.examinations == 3 and part3.examinations == full.examinations - n1 - 8
    kb_full, kb_part = _kb(tmp_path / "full.sqlite", cat), _kb(tmp_path / "part.sqlite", cat)
    for t in cat.type_names:
        assert kb_full.n(t) == kb_part.n(t)
        assert kb_full.nonzero(t) == kb_part.nonzero(t)
    # A finished run resumed does nothing.
    again, seq4 = go(tmp_path / "part.sqlite")
    assert again.examinations == 0 and seq4 == []


def test_ctrl_c_loses_at_most_the_examination_in_flight(tmp_path):
    def interrupt_after_two(res, kb):
        if res.index == 2:
            raise KeyboardInterrupt

    summary, cat = _learn(tmp_path, on_examination=interrupt_after_two)
    assert summary.interrupted and summary.total_examinations == 2
    summary, cat = _learn(tmp_path)
    assert summary.rooms == 1 and summary.total_examinations == 4
    kb = _kb(tmp_path / "kb.sqlite", cat)
    for t, pairs in EXPECTED_PAIRS.items():
        assert kb.n(t) == 1 and {k for k, v in kb.nonzero(t).items() if v} == pairs


def test_bad_arguments_are_one_line_errors(tmp_path):
    with pytest.raises(CtxsearchError, match="unknown strategy 'nope'"):
        _learn(tmp_path, strategy="nope")
    with pytest.raises(CtxsearchError, match="unknown perception mode 'sonar'"):
        _learn(tmp_path, perception="sonar")


def test_group_volumes_merges_nested_and_adjacent_volumes():
    cat = tiny_catalog()
    desk = tiny_room().objects[0]
    boxes = relation_boxes(cat, desk)
    groups = group_volumes(boxes)
    # ON-TOP-OF (on the desk) and IN-FRONT-OF (in front of it) touch; their joint box is not much
    # bigger than the two together: one group covering both.
    assert len(groups) == 1
    g = groups[0]
    g = type(g)(g.center, g.yaw, g.half + 1e-9)
    for b in boxes:
        assert all(g.contains_points(b.corners()))


def test_oracle_sees_within_range_and_not_through_furniture():
    cat = tiny_catalog()
    lay = tiny_room()
    per = OraclePerception(lay, cat, RobotSpec(), TimeModel())
    # At the door looking north (towards the desk), slightly down: everything is in view.
    per.body.reset_pose(RobotPose(0.0, -1.9, math.pi / 2, 0.0, -0.35))
    assert {o.type for o in per.see(None)} == {"Desk", "Chair", "Cup", "Book"}
    # Looking south (away): nothing.
    per.body.reset_pose(RobotPose(0.0, -1.9, -math.pi / 2, 0.0, -0.35))
    assert per.see(None) == []
    # The cup's max range is 4 m: from the far corner (about 4.3 m away) it is not recognized.
    per.body.reset_pose(RobotPose(2.2, -2.2, math.atan2(3.7, -2.5), 0.0, -0.2))
    assert "Cup" not in {o.type for o in per.see(None)}


def test_kinematic_body_charges_the_time_model():
    tm = TimeModel()
    b = KinematicBody(RobotSpec(), tm)
    b.reset_pose(RobotPose(0, 0, 0))
    t = b.drive([[0, 0], [1, 0], [1, 1]], math.pi)
    assert t == pytest.approx(tm.drive_time([[0, 0], [1, 0], [1, 1]], 0.0, math.pi))
    assert b.move_head(1.0, -0.5) == pytest.approx(tm.head_time(0, 0, 1.0, -0.5))
    b.capture()
    assert b.sim_time == pytest.approx(t + tm.head_time(0, 0, 1.0, -0.5) + tm.image_cost)
    assert b.pose() == RobotPose(1.0, 1.0, math.pi, 1.0, -0.5)


def test_start_pose_is_inside_the_door():
    lay = tiny_room()
    grid = OccupancyGrid.from_layout(lay, RobotSpec())
    p = start_pose(lay, grid)
    assert (p.x, p.y) == pytest.approx((0.0, -1.9), abs=0.05)
    assert p.yaw == pytest.approx(math.pi / 2)


def _read_rrd(path):
    """(entity paths, text log lines) of a recording, read back with rerun's own reader."""
    import rerun as rr

    chunks = list(rr.chunk.RrdReader(path).stream())
    texts = []
    for c in chunks:
        if c.entity_path == "/log":
            texts += [row[0] for row in c.to_record_batch().column("TextLog:text").to_pylist()]
    return {c.entity_path for c in chunks}, texts


def test_recording_holds_the_story(tmp_path):
    rrd = tmp_path / "run.rrd"
    _learn(tmp_path, record=rrd)
    entities, texts = _read_rrd(rrd)
    for e in [
        "/world/objects/Desk_0",  # the room, labelled boxes
        "/world/robot",  # base pose over time
        "/world/robot_path",
        "/world/camera",  # head pose (the camera) over time
        "/world/camera/image",  # pinhole
        "/world/volumes/examined",  # the examined object's relation volumes
        "/log",
        "/knowledge/mean_width",
        "/knowledge/n/Desk",
    ]:
        assert e in entities, (e, sorted(entities))
    choices = [t for t in texts if " chooses " in t]
    assert len(choices) == 4
    assert choices[2].startswith("exam 3: hif chooses Cup (object #1) among 2 unexamined")
    assert "scores: Cup 0.2699, Book 0.2699" in choices[2]


@pytest.mark.render
def test_camera_mode_on_the_hand_made_room_with_recording(tmp_path):
    rrd = tmp_path / "cam.rrd"
    order = []
    summary, cat = _learn(
        tmp_path,
        perception="camera",
        detector="perfect",
        record=rrd,
        on_examination=lambda res, kb: order.append((res.choice.obj.type, res.pairs)),
    )
    assert sorted(t for t, _ in order) == ["Book", "Chair", "Cup", "Desk"]
    # The camera sees what the oracle reads from the layout.
    for t, pairs in order:
        assert pairs == EXPECTED_PAIRS[t], t
    entities, texts = _read_rrd(rrd)
    for e in [
        "/world/camera/image/rgb",
        "/world/camera/image/segmentation",
        "/world/volumes/examined",
    ]:
        assert e in entities


def test_group_volumes_keeps_far_apart_volumes_apart():
    import numpy as np

    from ctxsearch.knowledge.geometry import Box

    a = Box(np.array([0.0, 0.0, 0.5]), 0.3, np.array([0.2, 0.2, 0.2]))
    b = Box(np.array([3.0, 0.0, 0.5]), 0.3, np.array([0.2, 0.2, 0.2]))
    inner = Box(np.array([0.05, 0.0, 0.5]), 0.3, np.array([0.1, 0.1, 0.1]))
    groups = group_volumes([a, b, inner])
    assert len(groups) == 2


# ------------------------------------------------------------------ limited time per room
def _office_layouts():
    from ctxsearch.envs.rooms import generate_room
    from ctxsearch.envs.styles import load_style
    from ctxsearch.knowledge.catalog import load_catalog

    cat = load_catalog()
    style = load_style("office", cat)
    rooms = {}

    def layouts(i, s):
        if s not in rooms:
            rooms[s] = generate_room(style, s, cat)
        return rooms[s]

    return cat, layouts, rooms


def _office_learn(path, cat, layouts, rooms=1, **kw):
    seq = []
    kw.setdefault("seed", 3)
    s = learn(
        "office",
        rooms,
        path,
        perception="oracle",
        catalog=cat,
        layouts=layouts,
        progress=False,
        on_examination=lambda res, kb: seq.append(
            (res.room_index, res.choice.obj.id, round(res.sim_time, 6))
        ),
        **kw,
    )
    return s, seq


def _end_times(path, cat, run):
    from ctxsearch.knowledge.store import EvidenceStore

    with EvidenceStore.open(path, cat, create=False) as st:
        return [st.room_end_time(r, sty, seed) for r, sty, seed, _ in st.rooms(run)]


def test_a_budgeted_room_stops_within_budget_plus_one_examination(tmp_path):
    cat, layouts, rooms = _office_layouts()
    full, seq_full = _office_learn(tmp_path / "full.sqlite", cat, layouts)
    budget = 60.0
    s, seq = _office_learn(tmp_path / "b.sqlite", cat, layouts, room_budget_s=budget)
    assert s.run.endswith("/budget=60.0s") and s.room_budget_s == budget
    assert s.rooms == 1 and s.rooms_done_now == 1 and s.rooms_left_early == 1
    assert 2 <= len(seq) < len(seq_full)
    times = [t for _, _, t in seq]
    # The same choices as the unlimited run until the budget ends the room ...
    assert seq == seq_full[: len(seq)]
    # ... every examination but the last ended within the budget (so the last started within
    # it), and the room ended with the last examination, after the budget was spent.
    assert times[-2] < budget <= times[-1]
    longest = max(b - a for a, b in zip([0.0, *times], times, strict=False))
    assert times[-1] <= budget + longest
    (end,) = _end_times(tmp_path / "b.sqlite", cat, s.run)
    assert end == pytest.approx(times[-1])
    assert "the budget ended 1 of the 1 rooms" in "\n".join(s.lines())


def test_resume_with_a_budget_equals_an_uninterrupted_run_with_it(tmp_path):
    cat, layouts, rooms = _office_layouts()
    kw = {"room_budget_s": 40.0, "strategy": "cost-hif"}
    full, seq_full = _office_learn(tmp_path / "full.sqlite", cat, layouts, rooms=3, **kw)
    n0 = sum(1 for r, _, _ in seq_full if r == 0)
    assert full.rooms_left_early == 3 and n0 < len(rooms[room_seed(3, 0)].objects)
    part = tmp_path / "part.sqlite"
    # Interrupted inside room 0, then a call that ends room 0 exactly (rooms=1), then inside
    # room 1 (replaying room 1 from the store's end time of room 0), then to the end.
    _, seq1 = _office_learn(part, cat, layouts, max_examinations=n0 - 2, **kw)
    s2, seq2 = _office_learn(part, cat, layouts, rooms=1, **kw)
    assert s2.rooms == 1
    _, seq3 = _office_learn(part, cat, layouts, rooms=3, max_examinations=3, **kw)
    s4, seq4 = _office_learn(part, cat, layouts, rooms=3, **kw)
    assert seq1 == seq_full[: n0 - 2]
    assert seq2 == seq_full[:n0]  # replayed, then finished
    assert seq3 == seq_full[n0 : n0 + 3]  # the run clock goes on from room 0's end time
    assert seq4 == seq_full[n0:]
    assert s4.rooms == 3 and s4.total_examinations == full.total_examinations
    assert _end_times(part, cat, full.run) == pytest.approx(
        _end_times(tmp_path / "full.sqlite", cat, full.run)
    )
    kb_full, kb_part = _kb(tmp_path / "full.sqlite", cat), _kb(part, cat)
    for t in cat.type_names:
        assert kb_full.n(t) == kb_part.n(t) and kb_full.nonzero(t) == kb_part.nonzero(t)
    # The same rooms without the budget would be another run over the same worlds, their
    # objects counted twice: refused before anything is written.
    before = _kb(part, cat)
    with pytest.raises(CtxsearchError, match="count twice"):
        _office_learn(part, cat, layouts, max_examinations=1, strategy="cost-hif")
    after = _kb(part, cat)
    assert all(before.n(t) == after.n(t) for t in cat.type_names)


def test_bad_room_budget_is_a_one_line_error(tmp_path):
    for bad in (0, -5.0, float("nan"), "soon"):
        with pytest.raises(CtxsearchError, match="room budget must be"):
            _learn(tmp_path, room_budget_s=bad)


def test_resume_replays_an_object_that_could_not_be_examined(tmp_path):
    # The lamp by the door is recognized first and chosen first, but no viewpoint sees its
    # volume: it is skipped (no trial, nothing stored). A resumed run must skip it the same way.
    cat = tiny_catalog(lamp=True)
    lamp = ObjectInstance("Lamp", 4, (0.8, -1.5, 0.2), 0.0, (0.2, 0.2, 0.4))
    base = tiny_room(room_seed(0, 0))
    room = RoomLayout(
        style=base.style,
        seed=base.seed,
        width=base.width,
        depth=base.depth,
        height=base.height,
        door=base.door,
        objects=(*base.objects, lamp),
        support={**base.support, 4: None},
    )

    def go(path, **kw):
        order = []
        s = learn(
            "tiny",
            1,
            path,
            perception="oracle",
            catalog=cat,
            layouts=lambda i, sd: room,
            progress=False,
            on_choice=lambda kb, c: order.append(c.obj.type),
            **kw,
        )
        return s, order

    full, order_full = go(tmp_path / "full.sqlite")
    assert order_full[0] == "Lamp" and full.examinations == 4
    part, _ = go(tmp_path / "part.sqlite", max_examinations=2)
    assert part.examinations == 2
    rest, order_rest = go(tmp_path / "part.sqlite")
    assert rest.examinations == 2 and rest.rooms == 1 and order_rest == order_full
    kb_full, kb_part = _kb(tmp_path / "full.sqlite", cat), _kb(tmp_path / "part.sqlite", cat)
    assert kb_part.n("Lamp") == kb_full.n("Lamp") == 0
    for t in cat.type_names:
        assert kb_full.n(t) == kb_part.n(t) and kb_full.nonzero(t) == kb_part.nonzero(t)


@pytest.mark.render
def test_camera_mode_charges_the_given_time_model_and_robot(tmp_path):
    from ctxsearch.agent.perception_modes import CameraPerception

    cat = tiny_catalog()
    room = tiny_room(0)
    spec = RobotSpec(camera_height=1.0, fovy_deg=70.0)
    tm = TimeModel(drive_speed=0.2, turn_rate=0.5, pan_rate=0.7, tilt_rate=0.6, image_cost=0.9)
    cam = CameraPerception(room, cat, spec, tm)
    try:
        body = cam.body
        assert body.spec is spec and body.time_model is tm
        body.reset_pose(RobotPose(0.0, 0.0, 0.0))
        frame = body.capture()
        assert body.sim_time == pytest.approx(0.9)
        assert frame.camera.fovy_deg == pytest.approx(70.0)
        assert frame.camera.position[2] == pytest.approx(1.0, abs=0.02)
        assert body.move_head(0.7, 0.0) == pytest.approx(1.0)  # 0.7 rad at 0.7 rad/s
    finally:
        cam.close()
    # A whole run: halving every rate and doubling the image cost doubles the seconds charged
    # (the same motions; the camera mode used to charge the default TimeModel whatever it got).
    base = TimeModel()
    slow = TimeModel(
        base.drive_speed / 2, base.turn_rate / 2, base.pan_rate / 2, base.tilt_rate / 2,
        2 * base.image_cost,
    )  # fmt: skip
    # (On the given map: on a built map the drives depend on the images, and the images on the
    # servos' motions, which the time model paces, so the paths may differ a little.)
    s0, _ = _learn(tmp_path, "a.sqlite", perception="camera", map_mode="given", detector="perfect")
    s1, _ = _learn(
        tmp_path,
        "b.sqlite",
        perception="camera",
        time_model=slow,
        map_mode="given",
        detector="perfect",
    )
    assert s0.examinations == s1.examinations == 4
    assert s1.sim_s == pytest.approx(2 * s0.sim_s, rel=0.02)


def test_a_perception_of_ones_own_plugs_into_learn(tmp_path):
    """Any agent.interfaces Perception works: here the oracle's, wrapped to count its calls."""

    class Counting:
        name, reads_truth, last_detections = "mine", True, ()

        def __init__(self, layout, catalog, spec, time_model, rgb):
            self._inner = OraclePerception(layout, catalog, spec, time_model)
            self.body = self._inner.body
            self.calls = calls

        def see(self, frame):
            self.calls["see"] += 1
            return self._inner.see(frame)

        def related(self, obj, seen):
            self.calls["related"] += 1
            return self._inner.related(obj, seen)

        def reference(self, obj):
            return obj

        def close(self):
            self._inner.close()

    calls = {"see": 0, "related": 0}
    mine, _ = _learn(tmp_path, "mine.sqlite", perception="mine", perceive=Counting)
    oracle, _ = _learn(tmp_path, "oracle.sqlite")
    assert mine.run == "hif/mine/seed=0" and mine.examinations == oracle.examinations == 4
    assert calls["related"] == 4 and calls["see"] >= 6  # one look-around at least
    assert mine.sim_s == oracle.sim_s
    with pytest.raises(CtxsearchError, match="unknown perception mode 'mine'"):
        _learn(tmp_path, "no.sqlite", perception="mine")


def test_a_huge_room_count_builds_nothing_up_front(tmp_path):
    # Room seeds are made as the run reaches them: asking for 10**12 rooms costs nothing more.
    s, _ = _learn(tmp_path, rooms=10**12, max_examinations=2)
    assert s.examinations == 2 and s.rooms == 0 and s.rooms_done_now == 0


def test_each_rooms_perception_is_closed_and_released_when_the_room_is_done(tmp_path):
    import gc
    import weakref

    made: list[weakref.ref] = []
    closed: list[bool] = []

    class Tracked(OraclePerception):
        def __init__(self, layout, catalog, spec, time_model, rgb):
            super().__init__(layout, catalog, spec, time_model)
            made.append(weakref.ref(self))
            closed.append(False)
            self._k = len(closed) - 1

        def close(self):
            closed[self._k] = True

    alive_before: list[int] = []

    def on_exam(res, kb):
        gc.collect()
        alive_before.append(sum(r() is not None for r in made[:-1]))

    s, _ = _learn(tmp_path, rooms=3, perception="tracked", perceive=Tracked, on_examination=on_exam)
    assert s.rooms == 3 and len(made) == 3 and all(closed)
    assert alive_before and max(alive_before) == 0  # no earlier room's perception kept alive


def test_the_summary_says_a_house_the_budget_ended_records_no_room_contents():
    from ctxsearch.agent.learning import Summary

    s = Summary(run="r", room_budget_s=600.0, rooms_done_now=3, rooms_left_early=2)
    s.world = "house"
    assert "the budget ended 2 of the 3 houses done in this call (they record no room" in "\n".join(
        s.lines()
    )
    s.rooms_left_early = 0
    assert "room contents" not in "\n".join(s.lines())
    s.world, s.rooms_left_early = "room", 2  # a single room records none anyway: not said
    assert "room contents" not in "\n".join(s.lines())
