"""The robot's rooms beside the plan's (``ctxsearch room`` with a house style).

The robot starts where the learning loop starts it, knowing only its pose, explores the house's
frontiers (agent.frontiers ``explore_world``) until no goal is left, building its own map from
depth (agent.mapping.BuiltMap), and cuts that map into rooms (agent.room_segmentation;
exploring and segmenting: scripts.experiments.room_segments, shared with ``bench rooms``). Its
images for the map are ``MAP_IMAGE`` (160 x 120: the map needs depth, not detail; a quarter of
the pixels of the default views). Written: ``rooms.png`` (left: the plan's rooms; right: the
robot's segments, each coloured as the plan room it overlaps most, unknown space black) and
``rooms.json`` (per plan room: the IoU with its segment and the share of its floor the robot
saw; the segment count; the exploration's simulated seconds).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from ctxsearch.envs.layout import RoomLayout
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.scripts.experiments.room_segments import Segmented, explore_and_segment, seen_share

PIXELS_PER_CELL = 3  # rooms.png: each 5 cm map cell drawn as a 3 x 3 block
# Colours (BGR) for rooms 0, 1, ...: distinct, none black (unknown) or white (walls).
PALETTE = np.array(
    [(180, 119, 31), (14, 127, 255), (44, 160, 44), (40, 39, 214), (189, 103, 148),
     (75, 86, 140), (194, 119, 227), (34, 189, 188), (207, 190, 23), (127, 127, 127)],
    np.uint8,
)  # fmt: skip


def draw(seg: Segmented) -> np.ndarray:
    """rooms.png: the plan's rooms (left) and the robot's segments (right), north up."""
    match = {}
    for s in np.unique(seg.labels[seg.labels >= 0]):
        rooms, counts = np.unique(
            seg.truth[(seg.labels == s) & (seg.truth >= 0)], return_counts=True
        )
        match[int(s)] = int(rooms[np.argmax(counts)]) if len(rooms) else int(s)

    def paint(labels: np.ndarray, inside: np.ndarray, colour_of, outside) -> np.ndarray:
        img = np.full((*labels.shape, 3), 200, np.uint8)  # grey: a doorway (no room's)
        img[~inside] = outside
        for k in np.unique(labels[labels >= 0]):
            img[(labels == k) & inside] = PALETTE[colour_of(int(k)) % len(PALETTE)]
        return img[::-1]  # row 0 is the map's south edge

    left = paint(seg.truth, seg.true_space, lambda k: k, (255, 255, 255))  # walls white
    right = paint(seg.labels, seg.mask, lambda k: match.get(k, k), (0, 0, 0))  # unknown black
    gap = np.full((left.shape[0], 8, 3), 255, np.uint8)
    img = np.concatenate([left, gap, right], axis=1)
    img = np.kron(img, np.ones((PIXELS_PER_CELL, PIXELS_PER_CELL, 1), np.uint8))
    head = np.full((28, img.shape[1], 3), 255, np.uint8)
    cv2.putText(head, "plan", (6, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
    u = (left.shape[1] + 8) * PIXELS_PER_CELL + 6
    cv2.putText(head, "the robot's rooms (its own map)", (u, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6,
                (0, 0, 0), 1, cv2.LINE_AA)  # fmt: skip
    return np.concatenate([head, img], axis=0)


def write_segments(layout: RoomLayout, catalog: Catalog, out: Path) -> list[Path]:
    """Explore, segment, write rooms.png and rooms.json into ``out``; print one line."""
    seg = explore_and_segment(layout, catalog)
    seen = seen_share(seg)
    png, js = out / "rooms.png", out / "rooms.json"
    cv2.imwrite(str(png), draw(seg))
    doc = {
        "segments": int(seg.labels.max() + 1),
        "rooms": [{"room": r, "iou": seg.iou.get(r, 0.0), "seen": seen[r]} for r in sorted(seen)],
        "explore_sim_s": seg.sim_s,
    }
    js.write_text(json.dumps(doc, indent=1) + "\n")
    ious = [seg.iou.get(r, 0.0) for r in sorted(seen)]
    print(f"the robot's rooms: {doc['segments']} segments for {len(seen)} rooms after exploring "
          f"{seg.sim_s:.0f} simulated s; IoU with the plan min {min(ious):.2f}, "
          f"mean {np.mean(ious):.2f}")  # fmt: skip
    return [png, js]
