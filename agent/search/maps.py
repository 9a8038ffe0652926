"""What the robot is given of a world before it searches it: the two map scenarios.

- ``built`` (``WorldMaps.built``, the default in houses): the robot knows nothing at the start:
  no furniture, no free cell. Each policy's context builds its own agent.mapping ``BuiltMap``
  from its depth images (the same map and rules as learning's ``--map built``: it plans only
  through cells seen to be floor with nothing within the clearance), objects are known only once
  detected, and the seen map's lattice covers the footprint without knowing the furniture.
- ``given`` (``WorldMaps.given``): the furniture poses and the true layout's grid are known (the
  true plan: an upper reference for a robot's own map).
- ``remembered`` (``WorldMaps.remembered``): the map the robot made of the house on an earlier day
  (agent.search.remembered: its occupancy, surfaces, rooms and the furniture it recognised, with its
  misses and look-alikes); each policy's context starts a built map from it and updates the
  remembered furniture with what it sees.

These constructors and the episode runner's sensor are where the true layout becomes what the
robot is given; the behaviours read only ``WorldMaps``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ctxsearch.agent.mapping import TALL_M, BuiltMap
from ctxsearch.agent.navigation import OccupancyGrid, obstacle_boxes
from ctxsearch.agent.room_segmentation import RoomLabels
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search import viewpoints as sx
from ctxsearch.agent.search.config import MapConfig, Segments
from ctxsearch.agent.search.remembered import FurnitureMemory, home_rooms, home_seen, restored_map
from ctxsearch.agent.search.room_prior import HandedRooms
from ctxsearch.envs.detector import DetectorModel
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.home_map import HomeMap
from ctxsearch.knowledge.options import MapMode

_DEFAULT_MAP = MapConfig()


@dataclass(frozen=True)
class Occluders:
    """What blocks the view on the given map, for agent.search.viewpoints' ray casting (the
    arrays a ``BuiltMap`` offers): the footprints of the walls and of everything reaching below
    the head, not inflated (``occupied`` (H, W) bool, cells of ``resolution`` m from
    (``x0``, ``y0``))."""

    occupied: np.ndarray
    tall: np.ndarray  # the occupied cells of obstacles reaching agent.mapping.TALL_M
    x0: float
    y0: float
    resolution: float

    @classmethod
    def from_layout(cls, layout: RoomLayout, spec: RobotSpec) -> Occluders:
        """The given map's occluders (read from the true layout, as the given grid is)."""
        boxes = obstacle_boxes(layout, spec)
        tall = [b for b in boxes if float(b.center[2]) + float(b.half[2]) >= TALL_M]
        g = OccupancyGrid.from_boxes(boxes, _bounds(layout), 0.0)
        t = OccupancyGrid.from_boxes(tall, _bounds(layout), 0.0)
        return cls(~g.free, ~t.free, g.x0, g.y0, g.resolution)


@dataclass(frozen=True)
class WorldMaps:
    """What the robot is given of a room before it searches it, built once and shared by the
    policies run in it: the occupancy grid, the seen map's lattice (each policy gets a copy),
    the furniture poses the location constraint may assume, the detector preset its images
    are read with (None: perfect), and the scenario (``map``: ``given`` or ``built``; in
    ``built`` each policy's SearchContext builds its own agent.mapping ``BuiltMap`` from its
    depth images, starting from nothing but its pose)."""

    grid: OccupancyGrid
    seen: ss.SeenMap
    furniture: tuple[ObjectInstance, ...] = ()
    detector: DetectorModel | None = None
    map: MapMode = MapMode.GIVEN
    # What the efficiency model of indirect search assumes of the world before seeing it: its
    # footprint (m^2) and room count (a house style says how many rooms it has).
    size: sx.WorldSize = sx.WorldSize(0.0, 1)
    # The footprint's extent (x0, y0, x1, y1) and height: the allocation of a built map
    bounds: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    top: float = 3.0
    occluders: Occluders | None = None  # what blocks the view on the given map
    # the plan's rooms, where the robot is given them: on the given map; on the built map None
    # (the robot segments its own map) or, with ``MapConfig.segments`` plan, the plan's (a bound)
    plan_rooms: RoomLabels | None = None
    # The given map's viewpoint views, kept for every policy run in the room (the occluders and
    # the lattice do not change: agent.search.viewpoints.ViewpointScorer's ``views``)
    views: dict = field(default_factory=dict, compare=False, repr=False)
    depth_range: float = _DEFAULT_MAP.depth_range_m  # m: how far a built map reads depth
    home: HomeMap | None = None  # the remembered map (``remembered``)
    # a bound's room knowledge, handed at the start (agent.search.room_prior; None: none)
    handed: HandedRooms | None = None

    def new_built_map(self, start: RobotPose, spec: RobotSpec) -> BuiltMap | None:
        """The robot's own map for one policy's run: empty over the footprint (``built``), the
        remembered one's copy (``remembered``), None on a given map."""
        if self.home is not None:
            return restored_map(self.home, spec, self.depth_range)
        if self.map is not MapMode.BUILT:
            return None
        return BuiltMap(self.bounds, spec, start, max_range=self.depth_range, top=self.top)

    def furniture_memory(self, ranges) -> FurnitureMemory | None:
        """The remembered furniture as one policy's run updates it (None: not ``remembered``);
        ``ranges``: a type's detection range."""
        if self.home is None:
            return None
        return FurnitureMemory(self.furniture, ranges)

    @classmethod
    def built(
        cls,
        layout: RoomLayout,
        catalog: Catalog,
        spec: RobotSpec,
        detector: DetectorModel | None = None,
        config: MapConfig = _DEFAULT_MAP,
    ) -> WorldMaps:
        """The ``built`` map scenario: the robot knows nothing at the start, no furniture, no
        free cell (``grid`` is all unknown); only the footprint's extent (the map's allocation,
        as in learning's built map) and height bound the seen map's lattice. Objects become
        known when detected; the robot plans on what its depth images mapped, read up to
        ``config.depth_range_m``; its rooms are its own segmentation's, or the plan's with
        ``config.segments`` plan."""
        hw, hd = layout.width / 2, layout.depth / 2
        empty = BuiltMap(
            (-hw, -hd, hw, hd), spec, RobotPose(0.0, 0.0, 0.0), max_range=config.depth_range_m
        )
        empty.floor[:] = False
        grid = OccupancyGrid(
            free=np.zeros_like(empty.floor), x0=empty.x0, y0=empty.y0,
            resolution=empty.resolution, clearance=spec.clearance,
        )  # fmt: skip
        size = sx.WorldSize(layout.width * layout.depth, max(1, len(layout.rooms)))
        seen = ss.SeenMap.for_footprint(layout)
        plan = RoomLabels.of_plan(layout) if config.segments is Segments.PLAN else None
        return cls(
            grid, seen, (), detector, MapMode.BUILT, size, _bounds(layout), layout.height,
            plan_rooms=plan, depth_range=config.depth_range_m,
        )  # fmt: skip

    @classmethod
    def given(
        cls,
        layout: RoomLayout,
        catalog: Catalog,
        spec: RobotSpec,
        detector: DetectorModel | None = None,
        config: MapConfig = _DEFAULT_MAP,
    ) -> WorldMaps:
        """The ``given`` map scenario: the maps of the true layout (walls, furniture poses);
        ``config.depth_range_m`` caps what counts as seen.
        The furniture poses are read from the true layout here and nowhere else in the
        behaviour."""
        furniture = tuple(o for o in layout.objects if catalog.type(o.type).is_furniture)
        grid = OccupancyGrid.from_layout(layout, spec)
        size = sx.WorldSize(layout.width * layout.depth, max(1, len(layout.rooms)))
        seen = ss.SeenMap.for_room(layout, catalog)
        return cls(
            grid, seen, furniture, detector, MapMode.GIVEN, size, _bounds(layout), layout.height,
            Occluders.from_layout(layout, spec), RoomLabels.of_plan(layout),
            depth_range=config.depth_range_m,
        )  # fmt: skip

    @classmethod
    def remembered(
        cls,
        home: HomeMap,
        layout: RoomLayout,
        spec: RobotSpec,
        detector: DetectorModel | None = None,
        config: MapConfig = _DEFAULT_MAP,
    ) -> WorldMaps:
        """The ``remembered`` map scenario: ``home``, the map of an earlier day's tour
        (agent.search.tour, agent.search.remembered); the layout gives only the footprint (the lattice's extent, as on
        the built map) and the room count the efficiency model assumes."""
        built = restored_map(home, spec, config.depth_range_m)
        size = sx.WorldSize(layout.width * layout.depth, max(1, home.room_count()))
        plan = config.segments is Segments.PLAN
        rooms = RoomLabels.of_plan(layout) if plan else home_rooms(home)
        return cls(
            built.refresh(), home_seen(home, layout), tuple(home.objects()), detector,
            MapMode.REMEMBERED, size, home.bounds, home.top, plan_rooms=rooms,
            depth_range=config.depth_range_m, home=home,
        )  # fmt: skip

    @classmethod
    def for_mode(
        cls,
        mode: MapMode,
        layout: RoomLayout,
        catalog: Catalog,
        spec: RobotSpec,
        detector: DetectorModel | None = None,
        config: MapConfig = _DEFAULT_MAP,
    ) -> WorldMaps:
        """The maps of scenario ``mode``."""
        make = cls.built if mode is MapMode.BUILT else cls.given
        return make(layout, catalog, spec, detector, config)


def _bounds(layout: RoomLayout) -> tuple[float, float, float, float]:
    """A layout's footprint extent (x0, y0, x1, y1), centred on the origin."""
    hw, hd = layout.width / 2, layout.depth / 2
    return (-hw, -hd, hw, hd)
