"""Relation geometry with hand-built cases, and the vectorised overlap test against a loop and an
independent polygon-clipping reference."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ctxsearch.knowledge.catalog import Catalog, ObjectType, RelationSpec
from ctxsearch.knowledge.geometry import (
    EPS,
    Box,
    BoxArray,
    ObjectInstance,
    holds,
    overlaps,
    related,
    related_pairs,
    relation_volume,
)

# Hand-built relations (independent of assets/types.toml, which later issues grow).
ON_TOP = RelationSpec(
    "ON-TOP-OF-DESK", "Desk", (-0.5, -0.5, 0.5), (0.5, 0.5, 0.5), margin_hi=(0, 0, 0.4)
)
UNDER = RelationSpec(
    "UNDER-DESK", "Desk", (-0.5, -0.5, -0.5), (0.5, 0.5, 0.5), margin_hi=(0, 0, -0.05)
)
FRONT = RelationSpec(
    "IN-FRONT-OF-DESK", "Desk", (0.5, -0.5, -0.5), (0.5, 0.5, 0.5), margin_hi=(0.8, 0, 0)
)
NEAR_CUP = RelationSpec(
    "NEAR-CUP",
    "Cup",
    (-0.5, -0.5, -0.5),
    (0.5, 0.5, 0.5),
    margin_lo=(-0.3, -0.3, 0),
    margin_hi=(0.3, 0.3, 0),
)

DESK = ObjectInstance("Desk", 1, (0.0, 0.0, 0.37), 0.0, (0.8, 1.4, 0.74))


def cup(x: float, y: float, z_bottom: float, oid: int = 2, yaw: float = 0.0) -> ObjectInstance:
    return ObjectInstance("Cup", oid, (x, y, z_bottom + 0.05), yaw, (0.08, 0.08, 0.10))


def _box(obj: ObjectInstance) -> Box:
    return obj.box()


def _one(a: ObjectInstance, b: Box) -> bool:
    return bool(overlaps(BoxArray.from_instances([a]), b)[0])


def test_resting_on_top():
    c = cup(0.1, -0.2, DESK.top)
    assert holds(ON_TOP, c, DESK)
    # Touching the desk's top is not overlapping the desk's own box ...
    assert not _one(c, DESK.box())
    # ... nor is a cup on the desk under it.
    assert not holds(UNDER, c, DESK)
    # A cup hovering above the slab is not on top.
    assert not holds(ON_TOP, cup(0.1, -0.2, DESK.top + 0.5), DESK)


def test_touching_without_overlap():
    a = Box(np.array([0.0, 0.0, 0.5]), 0.0, np.array([0.5, 0.5, 0.5]))
    side = ObjectInstance(
        "Cup", 3, (1.0, 0.0, 0.5), 0.0, (1.0, 1.0, 1.0)
    )  # shares the x = 0.5 face
    corner = ObjectInstance("Cup", 4, (1.0, 1.0, 0.5), 0.0, (1.0, 1.0, 1.0))  # shares one edge
    above = ObjectInstance("Cup", 5, (0.0, 0.0, 1.5), 0.0, (1.0, 1.0, 1.0))  # shares the top face
    assert not overlaps(BoxArray.from_instances([side, corner, above]), a).any()
    # Overlaps thinner than EPS count as touching; thicker ones as overlapping.
    thin = ObjectInstance("Cup", 6, (1.0 - EPS / 2, 0.0, 0.5), 0.0, (1.0, 1.0, 1.0))
    thick = ObjectInstance("Cup", 7, (1.0 - 3 * EPS, 0.0, 0.5), 0.0, (1.0, 1.0, 1.0))
    assert list(overlaps(BoxArray.from_instances([thin, thick]), a)) == [False, True]


def test_rotated_45_degrees_needs_the_separating_axes():
    # A unit square turned 45 degrees is the diamond |x| + |y| <= 0.707. An axis-aligned unit
    # square centred at (0.9, 0.9) overlaps its bounding box but not the diamond itself.
    diamond = Box(np.array([0.0, 0.0, 0.5]), math.pi / 4, np.array([0.5, 0.5, 0.5]))
    out = ObjectInstance("Cup", 8, (0.9, 0.9, 0.5), 0.0, (1.0, 1.0, 1.0))
    inside = ObjectInstance("Cup", 9, (0.7, 0.7, 0.5), 0.0, (1.0, 1.0, 1.0))
    assert list(overlaps(BoxArray.from_instances([out, inside]), diamond)) == [False, True]
    # Same with the rotation on the many-boxes side.
    square = Box(np.array([0.9, 0.9, 0.5]), 0.0, np.array([0.5, 0.5, 0.5]))
    rot = ObjectInstance("Cup", 10, (0.0, 0.0, 0.5), math.pi / 4, (1.0, 1.0, 1.0))
    assert not _one(rot, square)


def test_rotated_reference_turns_its_volumes():
    desk = ObjectInstance("Desk", 11, (2.0, 1.0, 0.37), math.pi / 2, (0.8, 1.4, 0.74))
    # The desk faces +y now: its front volume spans y in [1.4, 2.2].
    vol = relation_volume(FRONT, desk)
    np.testing.assert_allclose(vol.center, [2.0, 1.8, 0.37], atol=1e-12)
    np.testing.assert_allclose(vol.half, [0.4, 0.7, 0.37], atol=1e-12)
    chair = ObjectInstance("Chair", 12, (2.0, 1.8, 0.45), 0.0, (0.5, 0.5, 0.9))
    assert holds(FRONT, chair, desk)
    # Where the front would be without the rotation is empty.
    assert not holds(
        FRONT, ObjectInstance("Chair", 13, (2.8, 1.0, 0.45), 0.0, (0.5, 0.5, 0.9)), desk
    )


def test_partial_overlap():
    # A book sticking out over the desk's edge still lies partly on top of it.
    book = ObjectInstance("Book", 14, (0.42, 0.0, DESK.top + 0.02), 0.3, (0.2, 0.3, 0.04))
    assert holds(ON_TOP, book, DESK)
    # A chair pushed half under the desk is under it and in front of it.
    chair = ObjectInstance("Chair", 15, (0.4, 0.0, 0.45), 0.0, (0.5, 0.5, 0.9))
    assert holds(UNDER, chair, DESK)
    assert holds(FRONT, chair, DESK)


def test_far_away():
    far = cup(25.0, -40.0, DESK.top)
    assert not any(holds(r, far, DESK) for r in (ON_TOP, UNDER, FRONT))


def test_an_object_is_never_related_to_itself():
    big_near = RelationSpec(
        "NEAR-DESK",
        "Desk",
        (-0.5, -0.5, -0.5),
        (0.5, 0.5, 0.5),
        margin_lo=(-1, -1, 0),
        margin_hi=(1, 1, 0),
    )
    assert not holds(big_near, DESK, DESK)


def test_relation_volume_follows_the_size():
    vol = relation_volume(ON_TOP, DESK)
    np.testing.assert_allclose(vol.center, [0, 0, 0.74 + 0.2], atol=1e-12)
    np.testing.assert_allclose(vol.half, [0.4, 0.7, 0.2], atol=1e-12)
    assert vol.volume == pytest.approx(0.8 * 1.4 * 0.4)


def test_related_and_related_pairs():
    types = (
        ObjectType(
            "Desk",
            "furniture",
            "desk",
            (0.8, 1.4, 0.74),
            (0.8, 1.4, 0.74),
            (0.5, 0.4, 0.2),
            100,
            10.0,
            (ON_TOP, UNDER, FRONT),
        ),
        ObjectType(
            "Cup",
            "object",
            "mug",
            (0.08, 0.08, 0.1),
            (0.08, 0.08, 0.1),
            (1, 1, 1),
            20,
            4.0,
            (NEAR_CUP,),
        ),
    )
    cat = Catalog(types)
    c1, c2 = cup(0.1, 0.1, DESK.top, oid=2), cup(-0.2, 0.3, DESK.top, oid=3)
    chair = ObjectInstance("Chair", 4, (0.4, 0.0, 0.3), 0.0, (0.5, 0.5, 0.6))  # seat below the top
    far = cup(9.0, 9.0, 0.0, oid=5)
    rel = related(cat, DESK, [DESK, c1, c2, chair, far])
    assert sorted((r, o.id) for r, o in rel) == [
        ("IN-FRONT-OF-DESK", 4),
        ("ON-TOP-OF-DESK", 2),
        ("ON-TOP-OF-DESK", 3),
        ("UNDER-DESK", 4),
    ]
    # Two cups on the desk give one (relation, type) pair.
    assert related_pairs(rel) == {
        ("ON-TOP-OF-DESK", "Cup"),
        ("UNDER-DESK", "Chair"),
        ("IN-FRONT-OF-DESK", "Chair"),
    }
    assert related(cat, DESK, [DESK]) == []
    assert {(r, o.id) for r, o in related(cat, c1, [DESK, c1, c2])} == {("NEAR-CUP", 3)}


# ---- vectorised == loop == independent reference ------------------------------------------------
def _side(a: np.ndarray, b: np.ndarray, v: np.ndarray) -> float:
    """> 0 when v is left of the directed line a -> b."""
    return (b[0] - a[0]) * (v[1] - a[1]) - (b[1] - a[1]) * (v[0] - a[0])


def _clip_area(p: np.ndarray, q: np.ndarray) -> float:
    """Area of the intersection of two convex CCW polygons (Sutherland-Hodgman)."""
    out = list(p)
    for i in range(len(q)):
        a, b = q[i], q[(i + 1) % len(q)]
        inp, out = out, []
        if not inp:
            break
        for j in range(len(inp)):
            cur, prev = inp[j], inp[j - 1]
            sc, sp = _side(a, b, cur), _side(a, b, prev)
            if sc >= 0:
                if sp < 0:
                    out.append(prev + (cur - prev) * sp / (sp - sc))
                out.append(cur)
            elif sp >= 0:
                out.append(prev + (cur - prev) * sp / (sp - sc))
    if len(out) < 3:
        return 0.0
    xy = np.array(out)
    return 0.5 * abs(
        np.dot(xy[:, 0], np.roll(xy[:, 1], 1)) - np.dot(xy[:, 1], np.roll(xy[:, 0], 1))
    )


def test_vectorised_equals_loop_and_polygon_reference():
    rng = np.random.default_rng(7)
    N = 400
    arr = BoxArray(
        rng.uniform(-2, 2, (N, 3)), rng.uniform(-np.pi, np.pi, N), rng.uniform(0.05, 1.0, (N, 3))
    )
    decided = 0
    for k in range(20):
        b = Box(rng.uniform(-1, 1, 3), float(rng.uniform(-np.pi, np.pi)), rng.uniform(0.1, 1.2, 3))
        vec = overlaps(arr, b)
        loop = np.array(
            [
                overlaps(
                    BoxArray(arr.centers[i : i + 1], arr.yaws[i : i + 1], arr.halves[i : i + 1]), b
                )[0]
                for i in range(N)
            ]
        )
        np.testing.assert_array_equal(vec, loop)
        for i in range(N):
            zov = min(arr.centers[i, 2] + arr.halves[i, 2], b.center[2] + b.half[2]) - max(
                arr.centers[i, 2] - arr.halves[i, 2], b.center[2] - b.half[2]
            )
            bi = Box(arr.centers[i], float(arr.yaws[i]), arr.halves[i])
            area = _clip_area(bi.corners_xy(), b.corners_xy())
            if zov <= 0 or area == 0.0:
                assert not vec[i], (k, i)
                decided += 1
            elif zov > 0.01 and area > 0.01:
                assert vec[i], (k, i)
                decided += 1
    assert decided > 0.95 * 20 * N


def test_empty_box_array():
    b = Box(np.zeros(3), 0.0, np.ones(3))
    assert overlaps(BoxArray.from_instances([]), b).shape == (0,)


def test_box_helpers():
    b = Box(np.array([1.0, 2.0, 0.5]), math.pi / 2, np.array([0.5, 0.25, 0.5]))
    xy = b.corners_xy()
    np.testing.assert_allclose(np.sort(xy[:, 0]), [0.75, 0.75, 1.25, 1.25], atol=1e-12)
    np.testing.assert_allclose(np.sort(xy[:, 1]), [1.5, 1.5, 2.5, 2.5], atol=1e-12)
    assert b.corners().shape == (8, 3)
    assert list(b.contains_points([[1.0, 2.4, 0.5], [1.4, 2.0, 0.5]])) == [True, False]
