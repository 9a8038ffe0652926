"""Parts and support surfaces: inside the bounding box, non-degenerate, consistent in world frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ctxsearch.envs.parts import solid_parts, support_surfaces, world_parts, world_surfaces
from ctxsearch.knowledge.catalog import SHAPES, load_catalog
from ctxsearch.knowledge.geometry import BoxArray, ObjectInstance, overlaps

FURNITURE_SIZES = [
    (0.7, 1.4, 0.74),
    (0.6, 1.2, 0.72),
    (0.35, 1.0, 1.8),
    (0.3, 0.8, 1.2),
    (0.5, 0.5, 0.9),
    (0.9, 2.0, 0.85),
    (2.0, 1.4, 1.0),
    (0.6, 0.6, 0.9),
]
SMALL_SIZES = [
    (0.09, 0.09, 0.11),
    (0.2, 0.5, 0.4),
    (0.3, 0.35, 0.24),
    (0.15, 0.45, 0.03),
    (0.3, 0.25, 0.45),
    (0.07, 0.07, 0.25),
    (0.2, 0.2, 0.3),
]
SMALL_SHAPES = {
    "monitor",
    "laptop",
    "keyboard",
    "microscope",
    "plant",
    "mug",
    "cylinder",
    "bottle",
    "box",
}


def sizes_for(shape):
    """Plausible sizes for a shape (and every size for the generic shapes)."""
    if shape in ("box", "cylinder"):
        return FURNITURE_SIZES + SMALL_SIZES + [(0.02, 0.15, 0.02)]
    return SMALL_SIZES if shape in SMALL_SHAPES else FURNITURE_SIZES


@pytest.mark.parametrize("shape", SHAPES)
def test_parts_inside_bbox(shape):
    for size in sizes_for(shape):
        parts = solid_parts(shape, size)
        assert parts, shape
        half = np.asarray(size) / 2
        for p in parts:
            assert p.geom in ("box", "cylinder")
            assert np.all(np.asarray(p.half) > 0), (shape, size, p)
            assert np.all(p.lo >= -half - 1e-9) and np.all(p.hi <= half + 1e-9), (shape, size, p)
            if p.geom == "cylinder":
                assert p.half[0] == p.half[1]


@pytest.mark.parametrize("shape", SHAPES)
def test_surfaces_inside_bbox_and_on_a_part(shape):
    for size in sizes_for(shape):
        half = np.asarray(size) / 2
        parts = solid_parts(shape, size)
        for s in support_surfaces(shape, size):
            c = np.asarray(s.center)
            assert s.clearance > 0 and min(s.half_xy) > 0
            assert np.all(np.abs(c[:2]) + s.half_xy <= half[:2] + 1e-9)
            assert -half[2] < c[2] <= half[2] + 1e-9
            # Some part's top is at the surface height under its centre.
            assert any(
                abs(p.hi[2] - c[2]) < 1e-9 and np.all(np.abs(c[:2] - p.center[:2]) <= p.half[:2])
                for p in parts
            ), (shape, size, s)


def test_furniture_has_surfaces_and_shelf_boards():
    assert len(support_surfaces("shelf", (0.35, 1.0, 1.8))) >= 2
    for shape in ("desk", "table", "cabinet", "counter", "sofa", "bed", "chair"):
        assert support_surfaces(shape, (0.7, 1.4, 0.8))
    names = {p.name for p in solid_parts("chair", (0.5, 0.5, 0.9))}
    assert {"seat", "back"} <= names
    back = next(p for p in solid_parts("chair", (0.5, 0.5, 0.9)) if p.name == "back")
    assert back.center[0] < 0  # backrest on -x; the chair faces +x


def test_desk_knee_space_is_open():
    size = (0.7, 1.5, 0.74)
    parts = BoxArray(
        np.array([p.center for p in solid_parts("desk", size)]),
        np.zeros(len(solid_parts("desk", size))),
        np.array([p.half for p in solid_parts("desk", size)]),
    )
    from ctxsearch.knowledge.geometry import Box

    knee = Box(np.array([0.0, 0.3, -0.1]), 0.0, np.array([0.2, 0.2, 0.2]))
    assert not overlaps(parts, knee).any()


def test_world_parts_follow_pose():
    cat = load_catalog()
    desk = ObjectInstance("Desk", 1, (1.0, 2.0, 0.37), math.pi / 2, (0.7, 1.4, 0.74))
    boxes = world_parts(desk, cat)
    local = solid_parts("desk", desk.size)
    assert len(boxes) == len(local)
    for b, p in zip(boxes, local, strict=True):
        # yaw 90 deg: local x -> world y, local y -> world -x
        assert np.allclose(b.center, [1.0 - p.center[1], 2.0 + p.center[0], 0.37 + p.center[2]])
        assert b.yaw == desk.yaw
    top = world_surfaces(desk, cat)[0]
    assert np.isclose(top.center[2], 0.74) and top.owner == 1
