"""What the robot keeps of a house it visited: its built map made into a remembered map
(knowledge.home_map.HomeMap), by a learning visit (agent.acquisition.RoomLearner.home_map) or a
search's tour (agent.search.tour).

Kept: the built map's occupancy (agent.mapping.BuiltMap), its own room segmentation of it
(agent.room_segmentation.RoomLabels.of_built), the furniture it recognised and, where the visit
kept a search lattice, which of its points rest on a surface.
"""

from __future__ import annotations

import numpy as np

from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.room_segmentation import RoomLabels
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.knowledge.home_map import HomeMap, RememberedObject


def home_map(
    built: BuiltMap,
    layout: RoomLayout,
    day: int,
    furniture: list[RememberedObject],
    support: np.ndarray | None = None,
) -> HomeMap:
    """The remembered map of ``layout``'s world on ``day`` from the visit's ``built`` map
    (over the layout's footprint, up to its height), with the ``furniture`` it recognised and
    the lattice's ``support`` (None: the visit kept none). The layout gives only the world's
    name and extent, what the robot knew before it looked."""
    sup = np.zeros(0, bool) if support is None else np.asarray(support, bool)
    hw, hd = layout.width / 2, layout.depth / 2
    return HomeMap(
        layout.style, int(layout.seed), int(day), (-hw, -hd, hw, hd), float(layout.height),
        built.x0,
        built.y0, built.resolution, built.floor.copy(), built.occupied.copy(),
        built.top_z.copy(), RoomLabels.of_built(built).labels.astype(np.int16),
        tuple(sorted(furniture, key=lambda o: o.id)), sup, built.images,
    )  # fmt: skip
