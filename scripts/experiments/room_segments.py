"""A house explored and cut into rooms, beside its plan: what ``ctxsearch room`` draws and
``bench rooms`` measures (the CLI's drawing and files: scripts.room_segments).

The robot starts where the learning loop starts it, knowing only its pose, explores the house's
frontiers (agent.frontiers ``explore_world``) until no goal is left, building its own map from
depth (agent.mapping.BuiltMap), and cuts that map into rooms (agent.room_segmentation). Its
images for the map are ``MAP_IMAGE`` (160 x 120: the map needs depth, not detail; a quarter of
the pixels of the default views). Per plan room: the IoU with its segment and the share of its
room space the robot's map holds (``seen_share``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ctxsearch.agent.acquisition import start_pose
from ctxsearch.agent.frontiers import explore_world
from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.agent.room_segmentation import (
    built_mask,
    plan_labels,
    room_iou,
    segment_rooms,
    wall_mask,
)
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotSpec, TimeModel
from ctxsearch.envs.world import World
from ctxsearch.knowledge.catalog import Catalog

MAP_IMAGE = (160, 120)


@dataclass(frozen=True)
class Segmented:
    """A house explored and segmented: the robot's segments and the plan's rooms on the built
    map's cells, the room space it saw, the IoU and seen share per plan room."""

    labels: np.ndarray
    truth: np.ndarray
    mask: np.ndarray
    true_space: np.ndarray  # the plan's room space on the same cells (walls excluded)
    iou: dict[int, float]
    sim_s: float


def explore_and_segment(layout: RoomLayout, catalog: Catalog) -> Segmented:
    """Explore ``layout`` from the learning loop's start pose and segment the built map."""
    spec, tm = RobotSpec(), TimeModel()
    start = start_pose(layout, OccupancyGrid.from_layout(layout, spec))
    w, h = MAP_IMAGE
    with World(layout, catalog, width=w, height=h, spec=spec, time_model=tm) as world:
        world.reset_pose(start)
        built = BuiltMap.for_layout(layout, spec, start)
        ex = explore_world(world, built, tm)
    mask = built_mask(built.floor, built.occupied, built.top_z)
    walls = wall_mask(layout, built.resolution)  # the built map's cells (the layout's footprint)
    truth = plan_labels(layout, walls)
    labels = segment_rooms(mask, built.resolution)
    return Segmented(labels, truth, mask, walls.free, room_iou(labels, truth, mask), ex.sim_s)


def seen_share(seg: Segmented) -> dict[int, float]:
    """Per plan room: the share of its room space (walls excluded) the robot's map holds."""
    out = {}
    for r in np.unique(seg.truth[seg.truth >= 0]):
        room = seg.true_space & (seg.truth == r)
        out[int(r)] = float((room & seg.mask).sum() / max(1, room.sum()))
    return out
