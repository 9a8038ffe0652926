"""Occupancy grid and path planning: paths never cross furniture or walls, edge cases, speed."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

import ctxsearch.agent.navigation as navigation
from ctxsearch.agent.navigation import OccupancyGrid, nearest_free, obstacle_boxes, plan_path
from ctxsearch.envs.layout import Door, RoomLayout
from ctxsearch.envs.parts import world_parts
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.envs.rooms import generate_room
from ctxsearch.envs.styles import available_styles, load_style
from ctxsearch.envs.task import start_pose
from ctxsearch.knowledge.geometry import Box, ObjectInstance

SPEC = RobotSpec()


def room(objects: tuple[ObjectInstance, ...], width: float = 6.0, depth: float = 5.0) -> RoomLayout:
    return RoomLayout("test", 0, width, depth, 2.6, Door("south", 0.0, 0.9), objects)


# A hand-made office: a rotated desk in the middle, a shelf, a table, a chair, a cup on the desk
# and a plant on the floor.
OBJECTS = (
    ObjectInstance("Desk", 1, (0.0, 0.0, 0.37), 0.3, (0.7, 1.4, 0.74)),
    ObjectInstance("Shelf", 2, (-1.5, 1.0, 0.9), math.pi / 2, (0.4, 1.0, 1.8)),
    ObjectInstance("Table", 3, (1.5, -1.0, 0.37), 0.0, (0.9, 1.2, 0.74)),
    ObjectInstance("Chair", 4, (0.75, 0.2, 0.45), math.pi + 0.3, (0.5, 0.5, 0.9)),
    ObjectInstance("Cup", 5, (0.0, 0.1, 0.79), 0.0, (0.08, 0.08, 0.10)),
)
OFFICE = room(OBJECTS)


def rect_distance(box: Box, pts: np.ndarray) -> np.ndarray:
    """Ground distance from points (N, 2) to a box's footprint (0 inside)."""
    d = pts - box.center[:2]
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    lx = np.abs(c * d[:, 0] + s * d[:, 1]) - box.half[0]
    ly = np.abs(-s * d[:, 0] + c * d[:, 1]) - box.half[1]
    return np.hypot(np.maximum(lx, 0), np.maximum(ly, 0))


def densify(path: np.ndarray, step: float = 0.005) -> np.ndarray:
    """Points every ``step`` metres along a polyline."""
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:], strict=True):
        n = max(2, int(math.ceil(np.hypot(*(b - a)) / step)) + 1)
        out.append(a + np.linspace(0, 1, n)[1:, None] * (b - a))
    return np.vstack(out)


def assert_path_clear(layout: RoomLayout, grid: OccupancyGrid, path: np.ndarray) -> None:
    """No point of the path brings the base (a disc of radius base_radius) into any solid part or
    wall, and every point keeps the planner's documented clearance."""
    pts = densify(path)
    guaranteed = SPEC.clearance - 0.71 * grid.resolution
    assert guaranteed > SPEC.base_radius
    for obj in layout.objects:
        if obj.bottom >= SPEC.camera_height:
            continue
        for part in world_parts(obj):
            assert rect_distance(part, pts).min() > SPEC.base_radius, (obj, part)
        assert rect_distance(obj.box(), pts).min() >= guaranteed - 1e-9, obj
    w, d = layout.width / 2, layout.depth / 2
    assert np.all(np.abs(pts[:, 0]) <= w - guaranteed + 1e-9)
    assert np.all(np.abs(pts[:, 1]) <= d - guaranteed + 1e-9)


def test_grid_blocks_furniture_footprints_and_walls():
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    assert grid.shape == (100, 120)
    assert not grid.is_free(np.array([0.0, 0.0]))  # the desk
    assert not grid.is_free(np.array([1.5, -1.0]))  # the table
    assert not grid.is_free(np.array([-2.9, 0.0]))  # next to the west wall
    assert not grid.is_free(np.array([10.0, 0.0]))  # outside the room
    assert grid.is_free(np.array([2.2, 1.8]))
    # Under the desk top is blocked too: the head would hit the top (documented choice).
    assert not grid.is_free(np.array([0.05, 0.35]))
    # Objects above the head do not block.
    lamp = ObjectInstance("Cup", 9, (2.2, 1.8, 2.0), 0.0, (0.1, 0.1, 0.1))
    assert len(obstacle_boxes(room((*OBJECTS, lamp)), SPEC)) == len(OBJECTS)


def test_every_free_cell_keeps_the_clearance():
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    xs, ys = grid.cell_centers()
    gx, gy = np.meshgrid(xs, ys)
    pts = np.column_stack([gx[grid.free], gy[grid.free]])
    for obj in OBJECTS:
        assert rect_distance(obj.box(), pts).min() > SPEC.clearance


@pytest.mark.parametrize(
    ("start", "goal"),
    [
        ((-2.5, -2.0), (2.5, 2.0)),
        ((-2.5, 2.0), (2.5, -2.2)),
        ((-0.8, 0.0), (0.9, -2.0)),
        ((2.4, -2.2), (-2.6, 1.6)),
    ],
)
def test_paths_never_cross_furniture(start, goal):
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    path = plan_path(grid, np.array(start), np.array(goal))
    assert path is not None
    np.testing.assert_allclose(path[0], start)
    np.testing.assert_allclose(path[-1], goal)
    assert len(path) <= 8  # a few straight segments, not a staircase of cells
    assert_path_clear(OFFICE, grid, path)


def test_random_queries_are_clear_and_fast():
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    rng = np.random.default_rng(0)
    xs, ys = grid.cell_centers()
    rows, cols = np.nonzero(grid.free & grid.reachable_mask(np.array([2.2, 1.8])))
    times = []
    for _ in range(30):
        i, j = rng.integers(len(rows), size=2)
        a, b = np.array([xs[cols[i]], ys[rows[i]]]), np.array([xs[cols[j]], ys[rows[j]]])
        t = time.perf_counter()
        path = plan_path(grid, a, b)
        times.append(time.perf_counter() - t)
        assert path is not None
        assert_path_clear(OFFICE, grid, path)
    assert np.median(times) < 0.02


def test_start_equals_goal():
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    p = np.array([2.2, 1.8])
    path = plan_path(grid, p, p)
    assert path.shape == (1, 2)
    np.testing.assert_allclose(path[0], p)


def test_blocked_or_unreachable_goal_gives_none():
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    assert plan_path(grid, np.array([2.2, 1.8]), np.array([0.0, 0.0])) is None  # inside the desk
    # A wall of shelves cutting the room in two: the far side is free but unreachable.
    wall = ObjectInstance("Shelf", 7, (1.0, 0.0, 0.9), 0.0, (0.4, 5.0, 1.8))
    split = room((wall,))
    g2 = OccupancyGrid.from_layout(split, SPEC)
    a, b = np.array([-2.0, 0.0]), np.array([2.5, 0.0])
    assert g2.is_free(a) and g2.is_free(b)
    assert plan_path(g2, a, b) is None
    assert not g2.reachable_mask(a)[g2.to_cell(b)]
    assert np.isinf(g2.distances_from(a)[g2.to_cell(b)])


def test_start_inside_inflation_escapes():
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    start = np.array([-2.85, -2.0])  # too close to the west wall
    assert not grid.is_free(start)
    path = plan_path(grid, start, np.array([2.2, 1.8]))
    assert path is not None
    np.testing.assert_allclose(path[0], start)
    assert grid.is_free(path[1])


def test_nearest_free_and_distances():
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    q = nearest_free(grid, np.array([0.0, 0.0]))
    assert grid.is_free(q)
    assert np.hypot(*q) < 1.2
    dist = grid.distances_from(np.array([2.2, 1.8]))
    r, c = grid.to_cell(np.array([2.2, 1.3]))
    assert dist[r, c] == pytest.approx(0.5, abs=0.06)


def test_search_cache_is_exact_read_only_and_bounded(monkeypatch):
    monkeypatch.setattr(navigation, "SEARCH_CACHE_SIZE", 3)
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    fresh = OccupancyGrid.from_layout(OFFICE, SPEC)
    xs = [
        np.array([2.22, 1.82]),
        np.array([-2.4, -2.0]),
        np.array([2.2, -2.2]),
        np.array([-0.8, 0.0]),
    ]
    first = grid.distances_from(xs[0])
    assert np.shares_memory(grid.distances_from(xs[0] + 0.01), first)  # same cell: a cache hit
    with pytest.raises(ValueError):
        first[0, 0] = 1.0  # cached fields are read-only
    for x in xs[1:]:
        grid.distances_from(x)
    assert len(grid._searches) == 3  # the least recently used search was dropped
    for x in xs:  # hits, misses and evictions all give what a fresh search gives
        np.testing.assert_array_equal(grid.distances_from(x), fresh.distances_from(x))
        fresh._searches.clear()
    goal = np.array([-2.4, 2.0])
    np.testing.assert_array_equal(plan_path(grid, xs[1], goal), plan_path(fresh, xs[1], goal))


def test_lattice_cells():
    grid = OccupancyGrid.from_layout(OFFICE, SPEC)
    rows, cols = grid.lattice_cells(6)
    lattice = np.zeros(grid.shape, bool)
    lattice[3::6, 3::6] = True
    want_r, want_c = np.nonzero(grid.free & lattice)
    np.testing.assert_array_equal(rows, want_r)
    np.testing.assert_array_equal(cols, want_c)
    assert grid.lattice_cells(6)[0] is rows  # cached


@pytest.mark.parametrize("style_name", available_styles())
def test_generated_rooms_paths_clear_and_connected(catalog, style_name):
    style = load_style(style_name, catalog)
    for seed in range(3):
        layout = generate_room(style, seed, catalog)
        grid = OccupancyGrid.from_layout(layout, SPEC)
        start = start_pose(layout)
        assert grid.is_free(start.xy)
        reach = grid.reachable_mask(start.xy)
        assert reach.sum() >= 0.95 * grid.free.sum()  # the robot can get (almost) everywhere
        rng = np.random.default_rng(seed)
        xs, ys = grid.cell_centers()
        rows, cols = np.nonzero(reach)
        for _ in range(8):
            j = rng.integers(len(rows))
            goal = np.array([xs[cols[j]], ys[rows[j]]])
            path = plan_path(grid, start.xy, goal)
            assert path is not None
            assert_path_clear(layout, grid, path)
