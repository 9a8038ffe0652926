"""Rooms from a map (issue 27, point 1: agent.room_segmentation): distance-transform
segmentation cuts a map at its doors; on a perfect survey of every stock house style it finds
the plan's rooms."""

from __future__ import annotations

import numpy as np
import pytest

from ctxsearch.agent.learning import style_layouts
from ctxsearch.agent.room_segmentation import (
    built_mask,
    grow,
    plan_labels,
    room_iou,
    segment_rooms,
    wall_mask,
)


def _two_rooms(door_m: float) -> np.ndarray:
    """Two 4 x 4 m rooms side by side (5 cm cells), a wall between them with a door."""
    mask = np.ones((80, 161), bool)
    mask[:, 80] = False
    half = int(round(door_m / 0.05 / 2))
    mask[40 - half : 40 + half, 80] = True
    return mask


def test_a_door_cuts_two_rooms_and_every_cell_gets_one():
    mask = _two_rooms(0.9)
    labels = segment_rooms(mask, 0.05)
    assert set(np.unique(labels[mask])) == {0, 1} and (labels[~mask] == -1).all()
    left, right = labels[:, :80], labels[:, 81:]
    assert (left == left[0, 0]).mean() > 0.99 and (right == right[0, -1]).mean() > 0.99
    assert left[0, 0] != right[0, -1]  # (a few doorway cells may go either way)


def test_no_room_sized_core_is_one_room_and_nothing_is_nothing():
    thin = np.zeros((40, 40), bool)
    thin[20, :] = True  # a 5 cm corridor: no core
    assert set(np.unique(segment_rooms(thin, 0.05)[thin])) == {0}
    assert (segment_rooms(np.zeros((5, 5), bool), 0.05) == -1).all()


def test_growth_stays_in_the_mask_and_leaves_unreached_cells():
    mask = np.zeros((5, 9), bool)
    mask[:, :4] = mask[:, 5:] = True  # two parts, no passage
    seeds = np.full(mask.shape, -1)
    seeds[2, 0] = 3
    out = grow(seeds, mask)
    assert (out[:, :4] == 3).all() and (out[:, 4:] == -1).all()


def test_iou_matches_each_plan_room_with_its_best_segment():
    truth = np.array([[0, 0, 1, 1, 1]])
    mask = np.ones_like(truth, bool)
    iou = room_iou(np.array([[5, 5, 5, 7, 7]]), truth, mask)
    assert iou == {0: pytest.approx(2 / 3), 1: pytest.approx(2 / 3)}


def test_built_map_walls_reach_the_ceiling_and_furniture_belongs_to_its_room():
    floor = np.array([[True, False, False, False]])
    occupied = np.array([[False, True, True, False]])
    top = np.array([[0.0, 0.9, 2.5, 0.0]])
    assert built_mask(floor, occupied, top).tolist() == [[True, True, False, False]]


@pytest.mark.parametrize("style", ["apartment", "family_house", "office_floor"])
def test_a_perfect_survey_of_every_stock_house_gives_the_plans_rooms(style, catalog):
    _, generate = style_layouts(style, catalog)
    for i in range(3):
        layout = generate(i, 4000 + i)
        grid = wall_mask(layout)
        labels = segment_rooms(grid.free, grid.resolution)
        iou = room_iou(labels, plan_labels(layout, grid), grid.free)
        assert len(iou) == len(layout.rooms) == labels.max() + 1
        assert min(iou.values()) >= 0.95


def test_bench_rooms_summarises_fully_seen_rooms_and_refuses_a_room_style(tmp_path, capsys):
    from ctxsearch.scripts.cli import main
    from ctxsearch.scripts.experiments.bench_rooms import markdown, summary

    rows = [
        {"house": 0, "iou": 0.95, "seen": 0.99, "segments": 2, "rooms": 2, "explore_sim_s": 500.0},
        {"house": 0, "iou": 0.70, "seen": 0.95, "segments": 2, "rooms": 2, "explore_sim_s": 500.0},
        {"house": 1, "iou": 0.10, "seen": 0.30, "segments": 3, "rooms": 1, "explore_sim_s": 700.0},
    ]
    s = summary(rows)  # the half-seen room is not judged
    assert (s["houses"], s["rooms"], s["fully_seen"]) == (2, 3, 2)
    assert s["iou_min"] == 0.70 and s["share_iou_goal"] == 0.5
    assert s["houses_with_one_segment_per_room"] == 1 and s["explore_sim_s_median"] == 600.0
    assert "| apartment | 2 | 3 | 2 | 0.825 |" in markdown(
        {"fully_seen": 0.9, "iou_goal": 0.8, "styles": {"apartment": s}}
    )
    assert main(["bench", "rooms", "--styles", "office", "--out", str(tmp_path / "r")]) == 2
    assert "office" in capsys.readouterr().err


def test_a_room_cut_by_a_thin_obstacle_is_one_room_a_door_still_cuts():
    from ctxsearch.agent.room_segmentation import MERGE_CONTACT_M, merge_touching

    labels = np.zeros((60, 100), np.int64)
    labels[:, 50:] = 1  # two segments side by side along 3 m: one room cut in two
    assert set(np.unique(merge_touching(labels, MERGE_CONTACT_M / 0.05))) == {0}
    labels[:, 50] = -1  # a wall between them with a 1 m door
    labels[20:40, 50] = 1
    assert set(np.unique(merge_touching(labels, MERGE_CONTACT_M / 0.05))) == {-1, 0, 1}
