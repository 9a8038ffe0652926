"""The remembered map in a search: the robot's own map of a house from an earlier day
(knowledge.home_map.HomeMap, made by agent.search.tour) made ready for one policy's run.

The search starts from it (agent.search.maps.WorldMaps.remembered): it plans on the remembered
occupancy (a built map restored from it, which the search's new depth images extend, as on the
built map), ranks the relation volumes of the remembered furniture, and keeps the remembered
rooms. What it sees updates the furniture (``FurnitureMemory``): a detection of a remembered
piece replaces it (its type and pose as seen today: the context's known objects override the
furniture map by id), a piece not remembered is added when detected, and a remembered piece that
``DROP_AFTER`` images showed up close (its centre in the image with nothing in front of it, within
``DROP_RANGE`` of its type's detection range) without a report is dropped: a phantom, or
furniture that left.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.recording import Recorder
from ctxsearch.agent.room_segmentation import RoomLabels
from ctxsearch.agent.search import space as ss
from ctxsearch.envs.camera import Frame
from ctxsearch.envs.detector import Detection
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.home_map import HomeMap, HomeMapError

DROP_AFTER = 3  # images that showed a remembered piece up close without a report drop it
DROP_RANGE = 0.6  # "up close": within this share of the type's detection range


# ============================================================================= the map restored
def restored_map(home: HomeMap, spec: RobotSpec, max_range: float) -> BuiltMap:
    """A built map that starts from ``home``'s occupancy (the search's own copy: its images
    extend it)."""
    b = BuiltMap(home.bounds, spec, _origin(home), home.resolution, max_range, home.top)
    if b.floor.shape != home.shape:
        raise HomeMapError(f"{home.style}/{home.seed}", "the occupancy grid is not the house's")
    b.floor[:] = home.floor
    b.occupied[:] = home.occupied
    b.top_z[:] = home.top_z
    b.images = home.images
    return b


def _origin(home: HomeMap) -> RobotPose:
    return RobotPose(home.bounds[0] - 10.0, home.bounds[1] - 10.0, 0.0)  # marks no cell


def home_rooms(home: HomeMap) -> RoomLabels:
    """The remembered room segmentation."""
    return RoomLabels(home.rooms.astype(np.int64), home.x0, home.y0, home.resolution)


def home_seen(home: HomeMap, layout: RoomLayout) -> ss.SeenMap:
    """The search lattice of the house with nothing seen today and the remembered surfaces (a
    map kept without them, a learning visit's, learns them anew from today's images as the
    built map does)."""
    seen = ss.SeenMap.for_footprint(layout)
    if not len(home.support):
        return seen
    if len(home.support) != len(seen):
        raise HomeMapError(f"{home.style}/{home.seed}", "its surfaces are not the house's lattice")
    return ss.SeenMap(seen.points, seen.best, home.support.copy(), False)


# ============================================================================= the search's memory
class FurnitureMemory:
    """The remembered furniture as a search updates it (module docstring): ``objects()`` is
    what the location constraint may assume now."""

    def __init__(self, furniture: Sequence[ObjectInstance], ranges: Callable[[str], float]):
        self.remembered = {o.id: o for o in furniture}
        self.ranges = ranges
        self.unreported: dict[int, int] = {}
        self.confirmed: set[int] = set()
        self.dropped: set[int] = set()

    def objects(self) -> list[ObjectInstance]:
        """The remembered furniture not dropped."""
        return [o for i, o in self.remembered.items() if i not in self.dropped]

    def observe(self, frame: Frame, dets: Sequence[Detection]) -> list[ObjectInstance]:
        """One image: the remembered pieces it showed up close without a report count towards
        their drop; those dropped now are returned."""
        if frame.depth is None or not self.remembered:
            return []
        reported = {d.instance_id for d in dets}
        self.confirmed |= reported & self.remembered.keys()
        todo = [o for i, o in self.remembered.items()
                if i not in reported and i not in self.confirmed and i not in self.dropped]  # fmt: skip
        if not todo:
            return []
        cam = frame.camera
        pts = np.array([o.position for o in todo], float)
        near = np.linalg.norm(pts - np.asarray(cam.position, float), axis=1)
        reach = np.array([DROP_RANGE * self.ranges(o.type) for o in todo])
        shown = cam.visible(pts, frame.depth, tol=0.25) & (near <= reach)
        out = []
        for o in (o for o, s in zip(todo, shown, strict=True) if s):
            k = self.unreported[o.id] = self.unreported.get(o.id, 0) + 1
            if k >= DROP_AFTER:
                self.dropped.add(o.id)
                out.append(o)
        return out


REMEMBERED_ENTITY = "world/search/remembered"  # the recording's remembered furniture
LAST_SEEN_ENTITY = "world/search/last_seen"  # the remembered small objects (where seen last)


def confidence_color(c: float) -> tuple[float, float, float]:
    """Red (confidence 0) through yellow to green (1)."""
    c = float(np.clip(c, 0.0, 1.0))
    return (min(1.0, 2.0 * (1.0 - c)), min(1.0, 2.0 * c), 0.1)


def log_remembered(rec: Recorder, home: HomeMap) -> None:
    """The remembered furniture as boxes coloured by the detector's best confidence, labelled
    with its type, id, confidence and the images that showed it, and the remembered small
    objects in blue, labelled with the day each was last seen (static: the map at the
    start)."""
    if not rec.enabled:
        return
    if home.small:
        rec.log_volumes(
            LAST_SEEN_ENTITY,
            [o.instance().box() for o in home.small],
            [f"{o.type} last seen day {home.seen_day(o)}" for o in home.small],
            static=True,
            show_labels=False,
            colors=[(0.3, 0.6, 1.0)] * len(home.small),
        )
    if not home.furniture:
        return
    objs = home.furniture
    rec.log_volumes(
        REMEMBERED_ENTITY,
        [o.instance().box() for o in objs],
        [f"{o.type} #{o.id} ({o.confidence:.2f}, {o.sightings} images)" for o in objs],
        static=True,
        show_labels=False,
        colors=[confidence_color(o.confidence) for o in objs],
    )
