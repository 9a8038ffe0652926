"""The room generator: determinism, no interpenetration, rules hold, objects rest, free space."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from scipy import ndimage

from ctxsearch.envs.parts import world_parts, world_surfaces
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.envs.rooms import door_entry, generate_room
from ctxsearch.envs.styles import available_styles, load_style
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.geometry import Box, BoxArray, box_overlap, holds, overlap_any, overlaps

STYLES = ("office", "biology_lab", "living_room", "kitchen", "bedroom")
SEEDS = range(30)


@functools.lru_cache(maxsize=1)
def catalog():
    return load_catalog()


@functools.cache
def layouts(style: str):
    st = load_style(style, catalog())
    return [generate_room(st, seed, catalog()) for seed in SEEDS]


def test_shipped_styles_present():
    assert set(STYLES) <= set(available_styles())


@pytest.mark.parametrize("style", STYLES)
def test_same_seed_same_layout(style):
    st = load_style(style, catalog())
    a, b = generate_room(st, 7, catalog()), generate_room(st, 7, catalog())
    assert a == b
    c = generate_room(st, 8, catalog())
    assert c != a and [o.position for o in c.objects] != [o.position for o in a.objects]


@pytest.mark.parametrize("style", STYLES)
def test_ids_and_fields(style):
    for lay in layouts(style):
        ids = [o.id for o in lay.objects]
        assert ids == list(range(1, len(ids) + 1))
        assert set(lay.support) == set(ids)
        assert all(o.type in catalog() for o in lay.objects)
        assert lay.style == style
        types = {o.type for o in lay.objects}
        for t, (lo, _) in load_style(style, catalog()).furniture:
            assert lo == 0 or t in types


@pytest.mark.parametrize("style", STYLES)
def test_nothing_interpenetrates(style):
    cat = catalog()
    for lay in layouts(style):
        boxes, owner = [], []
        for o in lay.objects:
            for b in world_parts(o, cat):
                boxes.append(b)
                owner.append(o.id)
        arr = BoxArray(
            np.array([b.center for b in boxes]),
            np.array([b.yaw for b in boxes]),
            np.array([b.half for b in boxes]),
        )
        owner = np.array(owner)
        for b, oid in zip(boxes, owner, strict=True):
            hit = overlaps(arr, b) & (owner != oid)
            assert not hit.any(), (lay.seed, oid, lay.by_id(int(owner[np.flatnonzero(hit)[0]])))


@pytest.mark.parametrize("style", STYLES)
def test_rule_placements_hold(style):
    cat = catalog()
    n = 0
    for lay in layouts(style):
        for oid, (ref_id, rel) in lay.placed_by.items():
            assert holds(cat.relation(rel), lay.by_id(oid), lay.by_id(ref_id)), (lay.seed, oid, rel)
            n += 1
    assert n > 0


@pytest.mark.parametrize("style", STYLES)
def test_everything_rests_on_floor_or_a_surface(style):
    cat = catalog()
    for lay in layouts(style):
        for o in lay.objects:
            # Inside the room.
            xy = o.box().corners_xy()
            assert np.all(np.abs(xy[:, 0]) <= lay.width / 2 + 1e-6)
            assert np.all(np.abs(xy[:, 1]) <= lay.depth / 2 + 1e-6)
            sup = lay.support[o.id]
            if sup is None:
                assert abs(o.bottom) < 1e-9, o
                continue
            assert not cat.type(o.type).is_furniture
            surfaces = world_surfaces(lay.by_id(sup), cat)
            ok = False
            for s in surfaces:
                c, si = np.cos(s.yaw), np.sin(s.yaw)
                d = np.asarray(o.position[:2]) - np.asarray(s.center[:2])
                u, v = c * d[0] + si * d[1], -si * d[0] + c * d[1]
                if (
                    abs(o.bottom - s.center[2]) < 1e-9
                    and abs(u) <= s.half_xy[0]
                    and abs(v) <= s.half_xy[1]
                ):
                    ok = True
            assert ok, (lay.seed, o)


def _free_grid(lay, clearance, res=0.1):
    """An independent free-space grid: base centres at least ``clearance`` from any obstacle."""
    cat = catalog()
    xs = np.arange(-lay.width / 2 + res / 2, lay.width / 2, res)
    ys = np.arange(-lay.depth / 2 + res / 2, lay.depth / 2, res)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    free = (np.abs(gx) <= lay.width / 2 - clearance) & (np.abs(gy) <= lay.depth / 2 - clearance)
    for o in lay.objects:
        if not (cat.type(o.type).is_furniture or lay.support[o.id] is None):
            continue
        b = o.box()
        c, s = np.cos(b.yaw), np.sin(b.yaw)
        lx = c * (gx - b.center[0]) + s * (gy - b.center[1])
        ly = -s * (gx - b.center[0]) + c * (gy - b.center[1])
        d = np.hypot(np.maximum(np.abs(lx) - b.half[0], 0), np.maximum(np.abs(ly) - b.half[1], 0))
        free &= d > clearance
    return free


@pytest.mark.parametrize("style", STYLES)
def test_robot_free_space_is_connected(style):
    clearance = RobotSpec().clearance
    for lay in layouts(style):
        free = _free_grid(lay, clearance)
        labels, n = ndimage.label(free)
        sizes = np.bincount(labels.ravel())[1:]
        assert n >= 1
        big = sizes >= 40  # pockets under ~0.2 m^2 are not places (x2 for grid discretisation)
        assert big.sum() == 1, (lay.seed, sorted(sizes))
        # The door entry lies in the big region.
        x, y, _ = door_entry(lay)
        i = int(np.argmin(np.abs(np.arange(-lay.width / 2 + 0.05, lay.width / 2, 0.1) - x)))
        j = int(np.argmin(np.abs(np.arange(-lay.depth / 2 + 0.05, lay.depth / 2, 0.1) - y)))
        assert labels[i, j] == 1 + int(np.argmax(sizes)), lay.seed
        # Roughly half the floor or more stays drivable.
        assert sizes.max() * 0.01 > 0.2 * lay.width * lay.depth * 0.5


@pytest.mark.parametrize("style", STYLES)
def test_door_kept_free(style):
    for lay in layouts(style):
        d = lay.door
        W, D = lay.width / 2, lay.depth / 2
        if d.wall in ("north", "south"):
            y = D - 0.4 if d.wall == "north" else -D + 0.4
            zone = Box(np.array([d.center, y, 0.5]), 0.0, np.array([d.width / 2, 0.4, 0.5]))
        else:
            x = W - 0.4 if d.wall == "east" else -W + 0.4
            zone = Box(np.array([x, d.center, 0.5]), 0.0, np.array([0.4, d.width / 2, 0.5]))
        assert not overlaps(BoxArray.from_instances(list(lay.objects)), zone).any(), lay.seed


def test_fast_overlap_matches_geometry():
    rng = np.random.default_rng(0)
    for _ in range(300):
        a = Box(rng.uniform(-1, 1, 3), float(rng.uniform(-3, 3)), rng.uniform(0.05, 0.8, 3))
        b = Box(rng.uniform(-1, 1, 3), float(rng.uniform(-3, 3)), rng.uniform(0.05, 0.8, 3))
        ref = bool(overlaps(BoxArray(a.center[None], np.array([a.yaw]), a.half[None]), b)[0])
        assert box_overlap(a, b) == ref
        assert (
            overlap_any(
                BoxArray(a.center[None], np.array([a.yaw]), a.half[None]),
                BoxArray(b.center[None], np.array([b.yaw]), b.half[None]),
            )
            == ref
        )


def test_styles_differ_in_content():
    office = sum(len(lay.of_type("Monitor")) for lay in layouts("office"))
    lab = sum(len(lay.of_type("Monitor")) for lay in layouts("biology_lab"))
    assert office > 2 * lab
    assert sum(len(lay.of_type("Microscope")) for lay in layouts("biology_lab")) > 0
    assert sum(len(lay.of_type("Microscope")) for lay in layouts("office")) == 0
