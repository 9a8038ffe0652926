"""Rooms from a map: the robot cuts its own map into rooms at the doors.

Method: distance-transform segmentation, the "distance" method of Bormann, Jordan, Li, Hampp and
Hägele (2016), "Room segmentation: survey, implementation, and analysis" (ICRA), as their
ipa_room_segmentation implements it:

1. the map's room space (``mask``: where the floor is, furniture included, walls not) and its
   distance transform d (metres to the nearest wall or unknown cell);
2. for every threshold t in ``THRESHOLDS_M``, the connected parts of {d > t} whose area is at
   least ``MIN_ROOM_M2`` (doors, 0.8-1 m wide, vanish at t above half their width; rooms stay);
   the threshold with the most such parts is kept (ties: the lowest), its parts are the rooms'
   cores;
3. the rest of the room space joins the core it reaches first through the room space (a
   breadth-first growth, 8-connected, one ring of cells at a time);
4. two segments whose shared boundary extends over more than ``MERGE_CONTACT_M`` are one room
   (a door's boundary spans its width, at most about 1.2 m, and its wall's thickness; a room cut
   in two by a thin obstacle, or by a stretch its map does not hold yet, touches itself along
   the rest of its width). Measured before this step, 2 of 30
   explored houses (10 of each stock style) had a room cut in two (IoU 0.51 and 0.52).

Inputs. On the robot's built map (agent.mapping.BuiltMap, ``built_mask``): cells seen as floor or
occupied by something lower than ``WALL_Z`` (furniture belongs to its room; a wall reaches the
ceiling); unknown space is outside, so rooms grow as the map grows. On a true layout
(``wall_mask``): everything but the walls (the given map's rooms are the plan's: this mask is
for testing the method against the plan).

Quality (``room_iou``): for every room of the plan, the intersection over union of its cells
with the segment that overlaps it most, over the mask's cells.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, replace

import cv2
import numpy as np

from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.envs.detector import Detection
from ctxsearch.envs.floorplan import wall_obstacles
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.geometry import ObjectInstance

MIN_ROOM_M2 = 1.5  # the smallest core counted as a room (a corridor's core included)
MERGE_CONTACT_M = 1.5  # segments whose shared boundary extends over more than this are one room
THRESHOLDS_M = np.round(np.arange(0.25, 2.01, 0.05), 2)  # distance thresholds tried
WALL_Z = 2.1  # m: an occupied cell whose highest point is above this is a wall, not furniture


def segment_rooms(mask: np.ndarray, resolution: float) -> np.ndarray:
    """Room labels (H, W) int of ``mask``'s cells (0, 1, ...; -1 outside the mask), by the
    module's method; a mask without any core is one room."""
    mask = np.asarray(mask, bool)
    labels = np.full(mask.shape, -1, np.int64)
    if not mask.any():
        return labels
    dist = (
        cv2.distanceTransform(np.pad(mask, 1).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[
            1:-1, 1:-1
        ]
        * resolution
    )
    min_cells = MIN_ROOM_M2 / resolution**2
    best: np.ndarray | None = None
    best_n = 0
    for t in THRESHOLDS_M:
        core = (dist > t).astype(np.uint8)
        n, comp, stats, _ = cv2.connectedComponentsWithStats(core, connectivity=8)
        big = [i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= min_cells]
        if len(big) > best_n:
            best_n = len(big)
            best = np.full(mask.shape, -1, np.int64)
            for k, i in enumerate(big):
                best[comp == i] = k
    if best is None:
        labels[mask] = 0
        return labels
    return merge_touching(grow(best, mask), MERGE_CONTACT_M / resolution)


def merge_touching(labels: np.ndarray, min_extent: float) -> np.ndarray:
    """``labels`` with every two segments whose shared boundary extends over more than
    ``min_extent`` cells (the diagonal of the boundary's bounding box; a door's is its width and
    its wall's thickness) made one, transitively, renumbered 0, 1, ... in order of their
    smallest old label."""
    box: dict[tuple[int, int], list[int]] = {}  # pair -> [row min, row max, col min, col max]
    h, w = labels.shape
    rows, cols = np.mgrid[0:h, 0:w]
    for a, b, r, c in ((labels[:, :-1], labels[:, 1:], rows[:, :-1], cols[:, :-1]),
                       (labels[:-1, :], labels[1:, :], rows[:-1, :], cols[:-1, :])):  # fmt: skip
        m = (a >= 0) & (b >= 0) & (a != b)
        lo, hi, r, c = np.minimum(a[m], b[m]), np.maximum(a[m], b[m]), r[m], c[m]
        for x, y, rr, cc in zip(lo.tolist(), hi.tolist(), r.tolist(), c.tolist(), strict=True):
            e = box.setdefault((x, y), [rr, rr, cc, cc])
            e[0], e[1], e[2], e[3] = min(e[0], rr), max(e[1], rr), min(e[2], cc), max(e[3], cc)
    parent = {int(k): int(k) for k in np.unique(labels[labels >= 0])}

    def root(k: int) -> int:
        while parent[k] != k:
            k = parent[k]
        return k

    for (a, b), (r0, r1, c0, c1) in sorted(box.items()):
        if np.hypot(r1 - r0 + 1, c1 - c0 + 1) > min_extent:
            ra, rb = root(a), root(b)
            parent[max(ra, rb)] = min(ra, rb)
    new = {r: i for i, r in enumerate(sorted({root(k) for k in parent}))}
    out = labels.copy()
    for k in parent:
        out[labels == k] = new[root(k)]
    return out


def grow(seeds: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``seeds`` (labels >= 0, -1 elsewhere) grown over ``mask`` one 8-connected ring at a
    time (a cell reached by two labels in one ring takes the smaller); mask cells no seed
    reaches stay -1."""
    labels = np.where(mask, seeds, -1)
    big = np.iinfo(np.int64).max
    while True:
        free = mask & (labels < 0)
        if not free.any():
            return labels
        lab = np.where(labels >= 0, labels, big)
        pad = np.pad(lab, 1, constant_values=big)
        h, w = labels.shape
        near = np.full(labels.shape, big)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                if dr or dc:
                    near = np.minimum(near, pad[1 + dr : 1 + dr + h, 1 + dc : 1 + dc + w])
        new = free & (near < big)
        if not new.any():
            return labels
        labels[new] = near[new]


def wall_mask(layout: RoomLayout, resolution: float = 0.05) -> OccupancyGrid:
    """The layout's room space on a grid (True: not a wall; furniture ignored): the map the
    segmentation would get from a perfect survey."""
    bounds = (-layout.width / 2, -layout.depth / 2, layout.width / 2, layout.depth / 2)
    return OccupancyGrid.from_boxes(wall_obstacles(layout), bounds, 0.0, resolution)


def built_mask(floor: np.ndarray, occupied: np.ndarray, top_z: np.ndarray) -> np.ndarray:
    """A built map's room space: cells seen as floor, or occupied by something lower than
    ``WALL_Z`` (agent.mapping.BuiltMap's ``floor``, ``occupied`` and ``top_z``)."""
    return (np.asarray(floor, bool) | np.asarray(occupied, bool)) & ~(
        np.asarray(occupied, bool) & (np.asarray(top_z) > WALL_Z)
    )


def plan_labels(layout: RoomLayout, grid: OccupancyGrid) -> np.ndarray:
    """The plan's rooms on ``grid``'s cells (room index; -1 where no room's outline is)."""
    xs, ys = grid.cell_centers()
    labels = np.full(grid.shape, -1, np.int64)
    for room in layout.rooms:
        x0, y0, x1, y1 = room.outline
        inside = (
            (ys[:, None] >= y0) & (ys[:, None] <= y1) & (xs[None, :] >= x0) & (xs[None, :] <= x1)
        )
        labels[inside] = room.index
    return labels


def room_iou(pred: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> dict[int, float]:
    """Per room of ``truth`` (labels >= 0): the intersection over union, over ``mask``'s cells,
    of its cells with the predicted segment that overlaps it most (0 where none does)."""
    mask = np.asarray(mask, bool)
    out = {}
    for r in np.unique(truth[mask & (truth >= 0)]):
        room = mask & (truth == r)
        segs, counts = np.unique(pred[room & (pred >= 0)], return_counts=True)
        if not len(segs):
            out[int(r)] = 0.0
            continue
        seg = mask & (pred == segs[int(np.argmax(counts))])
        out[int(r)] = float((room & seg).sum() / (room | seg).sum())
    return out


@dataclass(frozen=True)
class RoomLabels:
    """Rooms on a grid of cells: ``labels`` (H, W) (-1: no room), the grid's lower-left corner
    (``x0``, ``y0``) and cell size (m)."""

    labels: np.ndarray
    x0: float
    y0: float
    resolution: float

    def at(self, xy: np.ndarray) -> np.ndarray:
        """The room of each point (M, 2+) (x, y first): -1 outside the grid or any room."""
        xy = np.asarray(xy, float).reshape(-1, np.shape(xy)[-1])
        h, w = self.labels.shape
        col = np.floor((xy[:, 0] - self.x0) / self.resolution).astype(np.int64)
        row = np.floor((xy[:, 1] - self.y0) / self.resolution).astype(np.int64)
        inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
        out = np.full(len(xy), -1, np.int64)
        out[inside] = self.labels[row[inside], col[inside]]
        return out

    def of_objects(self, objects: list[ObjectInstance], margin: float = 0.3) -> np.ndarray:
        """The room each object stands in: the label at its centre, or, where that cell is in
        no room (a tall cabinet or fridge is mapped like a wall), the most frequent label within
        its footprint's half-diagonal plus ``margin`` m of it (-1 if none)."""
        if not objects:
            return np.zeros(0, np.int64)
        out = self.at(np.array([o.position[:2] for o in objects]))
        h, w = self.labels.shape
        for i in np.flatnonzero(out < 0):
            o = objects[i]
            r = 0.5 * float(np.hypot(o.size[0], o.size[1])) + margin
            c0, r0 = ((o.position[0] - r - self.x0) / self.resolution,
                      (o.position[1] - r - self.y0) / self.resolution)  # fmt: skip
            c1, r1 = c0 + 2 * r / self.resolution, r0 + 2 * r / self.resolution
            win = self.labels[max(0, int(r0)) : min(h, int(r1) + 1),
                              max(0, int(c0)) : min(w, int(c1) + 1)]  # fmt: skip
            got, counts = np.unique(win[win >= 0], return_counts=True)
            if len(got):
                out[i] = got[int(np.argmax(counts))]
        return out

    @classmethod
    def of_plan(cls, layout: RoomLayout, resolution: float = 0.05) -> RoomLabels:
        """The plan's rooms (the given map's: ``plan_labels`` on the layout's footprint)."""
        grid = wall_mask(layout, resolution)
        return cls(plan_labels(layout, grid), grid.x0, grid.y0, grid.resolution)

    @classmethod
    def of_built(cls, built: BuiltMap) -> RoomLabels:
        """The rooms of the robot's own map as it stands (``segment_rooms`` of ``built_mask``)."""
        mask = built_mask(built.floor, built.occupied, built.top_z)
        return cls(segment_rooms(mask, built.resolution), built.x0, built.y0, built.resolution)


class Recognized:
    """The objects a learning visit recognized, for its room contents (knowledge.room_context):
    every examined object and every object reported in an examination's relation volumes, under
    the type reported most often (ties: the first by name), and, where the run's detector has
    false positives, only those whose best confidence over the visit's images exceeds the
    highest a false positive scores (``min_score``: the preset's ``fp_max_score``; clutter
    fires weakly). Without it the realistic detector's false positives (0.05 per image; one
    image serves several examinations, so a phantom is reported by several) put a phantom Remote
    or Pen in most rooms: measured on 30 apartments, 0.73 of the robot's rooms with furniture
    held a Remote against 0.45 of the plans' (and 25 of 131 objects counted in one house were
    phantoms). Scores come from the examinations' images, which a resumed run with such a
    detector takes again, so the contents do not depend on where a run was interrupted."""

    def __init__(self, min_score: float = 0.0) -> None:
        self.min_score = float(min_score)
        self.reports: dict[int, dict[str, int]] = {}
        self.poses: dict[int, ObjectInstance] = {}
        self.best: dict[int, float] = {}

    def scores(self, detections: Iterable[Detection]) -> None:
        """Keep each object's best confidence (an image's ``last_detections``)."""
        for d in detections:
            self.best[d.instance_id] = max(self.best.get(d.instance_id, 0.0), float(d.score))

    def add(self, examined: ObjectInstance, related: list[tuple[str, ObjectInstance]]) -> None:
        """One examination: its reference and the objects in its relation volumes (once each)."""
        for o in {examined.id: examined, **{o.id: o for _, o in related}}.values():
            counts = self.reports.setdefault(o.id, {})
            counts[o.type] = counts.get(o.type, 0) + 1
            self.poses.setdefault(o.id, o)

    def objects(self) -> list[ObjectInstance]:
        """The recognized objects (class docstring)."""
        out = []
        for i, counts in self.reports.items():
            if self.min_score > 0 and self.best.get(i, 0.0) <= self.min_score:
                continue
            best = max(sorted(counts), key=counts.__getitem__)
            o = self.poses[i]
            out.append(o if o.type == best else replace(o, type=best))
        return out


def segment_contents(
    labels: RoomLabels, objects: list[ObjectInstance], catalog: Catalog
) -> list[tuple[int, str, int]]:
    """What each room of ``labels`` holds of ``objects`` (the objects the robot recognized):
    (segment, type, instances) rows, sorted, for the segments holding furniture only (the room
    contents a learning visit records: knowledge.room_context)."""
    objs = sorted(objects, key=lambda o: o.id)
    if not objs:
        return []
    where = labels.of_objects(objs)
    counts: dict[tuple[int, str], int] = {}
    for o, s in zip(objs, where, strict=True):
        if s >= 0:
            counts[(int(s), o.type)] = counts.get((int(s), o.type), 0) + 1
    furnished = {s for s, t in counts if catalog.type(t).is_furniture}
    return sorted((s, t, k) for (s, t), k in counts.items() if s in furnished)
