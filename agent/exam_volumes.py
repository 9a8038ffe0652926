"""What an examination looks into: an object's relation volumes v_rel(obj), grouped into few boxes
for the view planner (agent.viewplan), and the open side of a group."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ctxsearch.envs.robot_spec import wrap_angle
from ctxsearch.knowledge import geometry
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.geometry import Box, ObjectInstance


def relation_boxes(catalog: Catalog, obj: ObjectInstance) -> list[Box]:
    """v_rel(obj) for every rel in RELATIONS(type(obj)), in catalog order."""
    return [geometry.relation_volume(rel, obj) for rel in catalog.type(obj.type).relations]


def group_volumes(boxes: Sequence[Box], slack: float = 2.0) -> list[Box]:
    """Merge relation volumes that share a frame (all volumes of one object share its yaw) into
    few boxes: two groups merge when their joint bounding box is at most ``slack`` times the sum
    of their volumes (a volume inside another always merges). Greedy, deterministic."""
    return [box for box, _ in group_volume_members(boxes, slack)]


def group_volume_members(boxes: Sequence[Box], slack: float = 2.0) -> list[tuple[Box, list[int]]]:
    """``group_volumes`` with, for every group, the indices of the input boxes merged into it."""
    if not boxes:
        return []
    yaw = float(boxes[0].yaw)
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s], [s, c]])
    origin = np.asarray(boxes[0].center, float)

    def to_local(b: Box) -> tuple[np.ndarray, np.ndarray]:
        d = np.asarray(b.center, float) - origin
        lc = np.array([*(rot.T @ d[:2]), d[2]])
        if abs(wrap_angle(float(b.yaw) - yaw)) > 1e-9:
            raise ValueError("group_volumes needs boxes sharing one yaw")
        return lc - b.half, lc + b.half

    # (lo, hi, summed volume, members)
    groups = [(*to_local(b), float(np.prod(2 * b.half)), [i]) for i, b in enumerate(boxes)]
    merged = True
    while merged and len(groups) > 1:
        merged = False
        best = None
        for i in range(len(groups)):
            for j in range(i + 1, len(groups)):
                lo = np.minimum(groups[i][0], groups[j][0])
                hi = np.maximum(groups[i][1], groups[j][1])
                joint = float(np.prod(hi - lo))
                ratio = joint / max(groups[i][2] + groups[j][2], 1e-12)
                big = max(
                    float(np.prod(groups[i][1] - groups[i][0])),
                    float(np.prod(groups[j][1] - groups[j][0])),
                )
                if (joint <= big * (1 + 1e-9) or ratio <= slack) and (
                    best is None or ratio < best[0]
                ):
                    best = (ratio, i, j, lo, hi)
        if best is not None:
            _, i, j, lo, hi = best
            vol = groups[i][2] + groups[j][2]
            members = sorted(groups[i][3] + groups[j][3])
            groups = [g for k, g in enumerate(groups) if k not in (i, j)] + [(lo, hi, vol, members)]
            merged = True
    out = []
    for lo, hi, _, members in groups:
        lc = (lo + hi) / 2
        center = np.array([*(origin[:2] + rot @ lc[:2]), origin[2] + lc[2]])
        out.append((Box(center, yaw, (hi - lo) / 2), members))
    return out
