"""Relation geometry: object instances, world-frame relation volumes v_rel(b), and holds(rel, obj, b).

This is the one geometry code path: the room generator, the ground-truth statistics, the oracle
perception and the robot's camera-based perception all decide relations here.

All boxes are yaw-only (upright), so the overlap test is exact and cheap: the z intervals must
overlap, and the two rectangles in the ground plane must overlap on all four separating axes
(the edge normals of both rectangles). "Positive volume" means every one of those overlaps is
larger than ``EPS`` (1 mm), so boxes that merely touch (a cup resting on a desk top is *touching*
the desk but not inside it) do not count as overlapping.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ctxsearch.knowledge.catalog import Catalog, RelationSpec

EPS = 1e-3  # metres: overlaps thinner than this count as touching, not overlapping


@dataclass(frozen=True)
class ObjectInstance:
    """An object somewhere: its type, a unique instance id, bounding-box centre, yaw and full size.

    The same value flows from the room generator through perception into relation checks.
    ``position`` is the centre of the bounding box (z included), ``size`` its full extents along
    the object's local (x=front, y=left, z=up) axes, ``yaw`` the rotation about world z in radians.
    """

    type: str
    id: int
    position: tuple[float, float, float]
    yaw: float
    size: tuple[float, float, float]

    @property
    def bottom(self) -> float:
        """z of the underside of the bounding box."""
        return self.position[2] - self.size[2] / 2

    @property
    def top(self) -> float:
        """z of the top of the bounding box."""
        return self.position[2] + self.size[2] / 2

    def box(self) -> Box:
        """The object's own bounding box."""
        return Box(
            np.asarray(self.position, float), float(self.yaw), np.asarray(self.size, float) / 2
        )


@dataclass(frozen=True)
class Box:
    """A yaw-only box in world coordinates: centre (3,), yaw (rad), half extents (3,)."""

    center: np.ndarray
    yaw: float
    half: np.ndarray

    def corners_xy(self) -> np.ndarray:
        """The four ground-plane corners, (4, 2), counter-clockwise."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        hx, hy = self.half[0], self.half[1]
        local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
        rot = np.array([[c, -s], [s, c]])
        return local @ rot.T + self.center[:2]

    def corners(self) -> np.ndarray:
        """All eight corners, (8, 3)."""
        xy = self.corners_xy()
        zlo, zhi = self.center[2] - self.half[2], self.center[2] + self.half[2]
        return np.vstack(
            [np.column_stack([xy, np.full(4, zlo)]), np.column_stack([xy, np.full(4, zhi)])]
        )

    def world_points(self, local: np.ndarray) -> np.ndarray:
        """Points (N, 3) given in the box's frame (x front, y left, z up, origin the centre) in
        world coordinates."""
        local = np.atleast_2d(np.asarray(local, float))
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        x, y = c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]
        return np.column_stack([x, y, local[:, 2]]) + self.center

    def contains_points(self, pts: np.ndarray) -> np.ndarray:
        """Boolean mask of which points (N, 3) lie inside the box (boundary included)."""
        pts = np.atleast_2d(np.asarray(pts, float))
        d = pts - self.center
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        lx = c * d[:, 0] + s * d[:, 1]
        ly = -s * d[:, 0] + c * d[:, 1]
        return (
            (np.abs(lx) <= self.half[0])
            & (np.abs(ly) <= self.half[1])
            & (np.abs(d[:, 2]) <= self.half[2])
        )

    def footprint_distance(self, xy: np.ndarray) -> np.ndarray:
        """Ground-plane distance from points ``xy`` (..., 2) to the box's footprint (0 inside)."""
        xy = np.asarray(xy, float)
        return footprint_distance(self, xy[..., 0], xy[..., 1])

    @property
    def volume(self) -> float:
        """The box's volume in cubic metres."""
        return float(8 * np.prod(self.half))


@dataclass(frozen=True)
class BoxArray:
    """Many yaw-only boxes as arrays: centers (N, 3), yaws (N,), halves (N, 3)."""

    centers: np.ndarray
    yaws: np.ndarray
    halves: np.ndarray

    @classmethod
    def from_instances(cls, objs: Sequence[ObjectInstance]) -> BoxArray:
        """Pack object instances' bounding boxes into arrays."""
        if not objs:
            return cls(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)))
        return cls(
            np.array([o.position for o in objs], float),
            np.array([o.yaw for o in objs], float),
            np.array([o.size for o in objs], float) / 2,
        )

    @classmethod
    def of(cls, boxes: Sequence[Box]) -> BoxArray:
        """Pack boxes into arrays."""
        return cls(
            np.array([b.center for b in boxes], float).reshape(-1, 3),
            np.array([b.yaw for b in boxes], float),
            np.array([b.half for b in boxes], float).reshape(-1, 3),
        )

    def __len__(self) -> int:
        return len(self.yaws)


def footprint_distance(box: Box, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Ground-plane distance from points (x, y) (arrays of one shape) to ``box``'s footprint
    rectangle, 0 inside."""
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    dx, dy = x - box.center[0], y - box.center[1]
    lx = np.abs(c * dx + s * dy) - box.half[0]
    ly = np.abs(-s * dx + c * dy) - box.half[1]
    return np.hypot(np.maximum(lx, 0.0), np.maximum(ly, 0.0))


def overlap_matrix(a: BoxArray, b: BoxArray, eps: float = EPS) -> np.ndarray:
    """THE box-overlap test: (Na, Nb) bool, box i of ``a`` and box j of ``b`` overlap with
    positive volume (every axis overlap > ``eps``). Yaw-only boxes: the z intervals overlap and,
    on the ground plane, no edge normal of either rectangle separates them (separating axes)."""
    if len(a) == 0 or len(b) == 0:
        return np.zeros((len(a), len(b)), bool)
    alo, ahi = (
        a.centers[:, None, 2] - a.halves[:, None, 2],
        a.centers[:, None, 2] + a.halves[:, None, 2],
    )
    blo, bhi = (
        b.centers[None, :, 2] - b.halves[None, :, 2],
        b.centers[None, :, 2] + b.halves[None, :, 2],
    )
    ok = np.minimum(ahi, bhi) - np.maximum(alo, blo) > eps
    if not ok.any():
        return ok
    delta = a.yaws[:, None] - b.yaws[None, :]
    C, S = np.abs(np.cos(delta)), np.abs(np.sin(delta))
    dx = b.centers[None, :, 0] - a.centers[:, None, 0]
    dy = b.centers[None, :, 1] - a.centers[:, None, 1]
    ca, sa = np.cos(a.yaws)[:, None], np.sin(a.yaws)[:, None]
    cb, sb = np.cos(b.yaws)[None, :], np.sin(b.yaws)[None, :]
    ha0, ha1 = a.halves[:, None, 0], a.halves[:, None, 1]
    hb0, hb1 = b.halves[None, :, 0], b.halves[None, :, 1]
    ok &= ha0 + C * hb0 + S * hb1 - np.abs(dx * ca + dy * sa) > eps
    ok &= ha1 + S * hb0 + C * hb1 - np.abs(-dx * sa + dy * ca) > eps
    ok &= hb0 + C * ha0 + S * ha1 - np.abs(dx * cb + dy * sb) > eps
    ok &= hb1 + S * ha0 + C * ha1 - np.abs(-dx * sb + dy * cb) > eps
    return ok


def overlaps(boxes: BoxArray, box: Box, eps: float = EPS) -> np.ndarray:
    """Which of ``boxes`` overlap ``box`` with positive volume (``overlap_matrix``). (N,) bool."""
    return overlap_matrix(boxes, BoxArray.of([box]), eps)[:, 0]


def overlap_any(a: BoxArray, b: BoxArray, eps: float = EPS) -> bool:
    """True if some box of ``a`` overlaps some box of ``b`` (``overlap_matrix``)."""
    return bool(overlap_matrix(a, b, eps).any())


def box_overlap(a: Box, b: Box, eps: float = EPS) -> bool:
    """Two boxes overlap with positive volume: ``overlap_matrix``'s test for one pair, the same
    expressions in plain floats (about 20 times faster for the room generator's many single
    checks than going through arrays)."""
    az, bz = float(a.center[2]), float(b.center[2])
    ah, bh = a.half, b.half
    if min(az + ah[2], bz + bh[2]) - max(az - ah[2], bz - bh[2]) <= eps:
        return False
    ca, sa, cb, sb = math.cos(a.yaw), math.sin(a.yaw), math.cos(b.yaw), math.sin(b.yaw)
    C, S = abs(ca * cb + sa * sb), abs(sa * cb - ca * sb)
    dx, dy = float(b.center[0] - a.center[0]), float(b.center[1] - a.center[1])
    ha0, ha1, hb0, hb1 = float(ah[0]), float(ah[1]), float(bh[0]), float(bh[1])
    return (
        ha0 + C * hb0 + S * hb1 - abs(dx * ca + dy * sa) > eps
        and ha1 + S * hb0 + C * hb1 - abs(-dx * sa + dy * ca) > eps
        and hb0 + C * ha0 + S * ha1 - abs(dx * cb + dy * sb) > eps
        and hb1 + S * ha0 + C * ha1 - abs(-dx * sb + dy * cb) > eps
    )


def relation_volume(rel: RelationSpec, ref: ObjectInstance) -> Box:
    """v_rel(b): the world-frame box of relation ``rel`` for the reference object ``ref``."""
    lo, hi = rel.local_bounds(np.asarray(ref.size, float))
    center_local = (lo + hi) / 2
    c, s = np.cos(ref.yaw), np.sin(ref.yaw)
    center = np.array(
        [
            ref.position[0] + c * center_local[0] - s * center_local[1],
            ref.position[1] + s * center_local[0] + c * center_local[1],
            ref.position[2] + center_local[2],
        ]
    )
    return Box(center, float(ref.yaw), (hi - lo) / 2)


def holds(rel: RelationSpec, obj: ObjectInstance, ref: ObjectInstance) -> bool:
    """rel(obj, ref): obj lies at least partly inside v_rel(ref). An object is never related to itself."""
    if obj.id == ref.id:
        return False
    return bool(overlaps(BoxArray.from_instances([obj]), relation_volume(rel, ref))[0])


def related(
    catalog: Catalog, ref: ObjectInstance, objects: Iterable[ObjectInstance]
) -> list[tuple[str, ObjectInstance]]:
    """Every (relation name, object) with rel(object, ref) for rel in RELATIONS(type(ref)).

    Figure 2, lines 15-16: RELATED-OBJECTS are the objects, RELATED-TYPES the (rel, type) pairs.
    """
    others = [o for o in objects if o.id != ref.id]
    if not others:
        return []
    rels = catalog.type(ref.type).relations
    if not rels:
        return []
    # every relation's volume at once (each pair's test is the same elementwise arithmetic)
    hits = overlap_matrix(
        BoxArray.from_instances(others), BoxArray.of([relation_volume(r, ref) for r in rels])
    )
    out: list[tuple[str, ObjectInstance]] = []
    for j, rel in enumerate(rels):
        out.extend((rel.name, others[i]) for i in np.flatnonzero(hits[:, j]))
    return out


def related_pairs(related_list: Iterable[tuple[str, ObjectInstance]]) -> set[tuple[str, str]]:
    """RELATED-TYPES: the distinct (relation, type) pairs of a ``related`` result."""
    return {(rel, o.type) for rel, o in related_list}
