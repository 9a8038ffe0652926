"""The home the robot lives in: the map it made of a house on an earlier day, and the search on it.

A robot that lives in a home has toured it before. ``tour`` is that visit, on a day of its own:
the robot starts where it docks (agent.navigation.start_pose) knowing nothing, and explores the
house on its own built map (agent.mapping.BuiltMap from its depth images) with the detector of
the run, sweeping at the furniture ring's tilt from the viewpoint that shows the most of what no
image has shown within the furniture's detection range per expected second (the search's own
exploration, agent.search.frontier.Explorer), until no viewpoint is left or the tour's budget
(``map.tour_budget_s`` simulated seconds) is spent. It looks for nothing: a tour ends on the
map, never on a detection.

What it keeps is a ``knowledge.home_map.HomeMap``: the built map's occupancy, which search-lattice
points rest on a surface (those the tour never saw count as possible surfaces), its own room
segmentation of the map (agent.room_segmentation), the small objects it recognised by the same
rule (the map's last sightings, for the search's memory: agent.search.memory), and the furniture
it recognised (``Sightings``): every instance the detector reported, under the type reported most often (ties:
the first by name), at the mean of its estimated positions (the circular mean of its yaws), with
its best confidence and how many images reported it, kept if that type is furniture and, where
the detector has false positives, if its best confidence beats the highest a false positive
scores (clutter fires weakly; agent.room_segmentation.Recognized's rule). Misses (furniture no
image reported) and look-alikes (a Table kept as a Desk) stay in it, as they would for a robot.

The search on the map it leaves is agent.search.remembered's.

Tours are deterministic in (style, seed, day, detector, budget, code) and are kept in the user's
cache directory (knowledge.files.cache_dir, ``tours/``) under a key over all of them;
a file that does not read back as such a map is a miss (made again, replaced).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ctxsearch.agent.home import home_map
from ctxsearch.agent.navigation import OccupancyGrid, start_pose
from ctxsearch.agent.search import viewpoints as sx
from ctxsearch.agent.search.config import MapConfig
from ctxsearch.agent.search.context import SearchContext, SearchStopped
from ctxsearch.agent.search.coverage import FURNITURE_TILTS, sweep
from ctxsearch.agent.search.draw_store import code_digest
from ctxsearch.agent.search.episode import Episode
from ctxsearch.agent.search.frontier import Explorer
from ctxsearch.agent.search.maps import WorldMaps
from ctxsearch.envs.detector import Detection, DetectorModel
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.files import cache_dir, write_bytes
from ctxsearch.knowledge.home_map import HomeMap, HomeMapError, RememberedObject, check_types

TOUR_FORMAT = 2  # 2: the map keeps the small objects seen


# ============================================================================= what a tour saw
@dataclass
class _Seen:
    types: dict[str, int] = field(default_factory=dict)
    xyz: list[tuple[float, float, float]] = field(default_factory=list)
    yaws: list[float] = field(default_factory=list)
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    best: float = 0.0


class Sightings:
    """Every detection of a visit by instance id: the types reported, the estimated poses, the
    best confidence (module docstring)."""

    def __init__(self) -> None:
        self.by_id: dict[int, _Seen] = {}

    def add(self, detections: Sequence[Detection]) -> None:
        """One image's detections."""
        for d in detections:
            s = self.by_id.setdefault(int(d.instance_id), _Seen())
            s.types[d.type] = s.types.get(d.type, 0) + 1
            s.xyz.append(tuple(float(v) for v in d.pose.position))
            s.yaws.append(float(d.pose.yaw))
            s.size = tuple(float(v) for v in d.pose.size)
            s.best = max(s.best, float(d.score))

    def furniture(self, catalog: Catalog, min_score: float = 0.0) -> list[RememberedObject]:
        """The recognised furniture (module docstring), by id."""
        return self.recognised(catalog, min_score, furniture=True)

    def small(self, catalog: Catalog, min_score: float = 0.0) -> list[RememberedObject]:
        """The recognised small objects (the same rule as the furniture's), by id."""
        return self.recognised(catalog, min_score, furniture=False)

    def recognised(
        self, catalog: Catalog, min_score: float, furniture: bool
    ) -> list[RememberedObject]:
        """The recognised objects of the kind ``furniture`` says, by id."""
        out = []
        for i in sorted(self.by_id):
            s = self.by_id[i]
            kind = max(sorted(s.types), key=s.types.__getitem__)
            if catalog.type(kind).is_furniture != furniture or (
                min_score > 0 and s.best <= min_score
            ):
                continue
            xyz = tuple(float(v) for v in np.mean(np.array(s.xyz), axis=0))
            yaw = math.atan2(float(np.mean(np.sin(s.yaws))), float(np.mean(np.cos(s.yaws))))
            n = sum(s.types.values())
            out.append(RememberedObject(kind, i, xyz, yaw, s.size, min(1.0, s.best), n))
        return out


class TourContext(SearchContext):
    """A search context that looks for nothing (a tour): no detection ends it; every image's
    detections go to ``sightings``."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.sightings = Sightings()

    def _target_hit(self, dets: Sequence[Detection]) -> Detection | None:
        self.sightings.add(dets)
        return None


def furniture_range(ctx: SearchContext) -> float:
    """The detection range a tour explores for: the smallest of the catalog's furniture types'
    (every piece is then seen from within its range), capped by the sight cap."""
    ranges = [ctx.range_of(t.name) for t in ctx.catalog.types if t.is_furniture]
    return min([*ranges, ctx.sight_cap]) if ranges else ctx.sight_cap


def tour(
    layout: RoomLayout,
    catalog: Catalog,
    detector: DetectorModel | None,
    config: MapConfig,
    day: int,
    *,
    body,
    sensor,
) -> HomeMap:
    """The robot's tour of ``layout`` (the world on ``day``; module docstring) in the running
    world ``body`` with the perception ``sensor`` (an episode runner's): the remembered map it
    leaves."""
    spec: RobotSpec = body.spec
    maps = WorldMaps.built(layout, catalog, spec, detector, config)
    grid = OccupancyGrid.from_layout(layout, spec)
    start = start_pose(layout, grid)
    furniture = [t.name for t in catalog.types if t.is_furniture]
    ep = Episode(-1, layout.style, layout.seed, furniture[0], start, config.tour_budget_s,
                 day=day)  # fmt: skip
    ctx = TourContext(ep, catalog, body, sensor, maps)
    ctx.policy = "tour"
    rng = furniture_range(ctx)
    ex = Explorer(ctx)
    try:
        sweep(ctx, rng, tilts=FURNITURE_TILTS, purpose="tour")
        ex.map_floor()
        ex.exhaust(rng)
        while True:
            vp = ex.viewpoint(rng, sx.RING_IMAGES)
            if vp is None:
                if ex.unstick():
                    continue
                break
            ex.explore_step(vp, rng, FURNITURE_TILTS, "tour")
    except SearchStopped:
        pass
    built = ctx.built
    assert built is not None
    min_score = detector.fp_max_score if detector is not None and not detector.perfect else 0.0
    support = ctx.seen.support | ~np.isfinite(ctx.seen.best)  # a place never seen may hold one
    seen = ctx.sightings
    home = home_map(built, layout, day, seen.furniture(catalog, min_score), support)
    return replace(home, small=tuple(seen.small(catalog, min_score)))


# ============================================================================= tours kept on disk
def tour_key(
    layout: RoomLayout, day: int, detector: DetectorModel | None, config: MapConfig
) -> str:
    """The file name stem of the tour of ``layout`` with these inputs (module docstring)."""
    h = hashlib.sha256()
    h.update(f"tour format {TOUR_FORMAT}\n{code_digest()}\n".encode())
    h.update(f"{layout.style}\n{layout.seed}\n{int(day)}\n{detector!r}\n".encode())
    h.update(f"{config.tour_budget_s!r}\n{config.depth_range_m!r}\n".encode())
    h.update(repr([(o.type, o.id, o.position, o.yaw, o.size) for o in layout.objects]).encode())
    return h.hexdigest()[:32]


def cached_tour(layout, catalog, detector, config, day, *, body, sensor) -> HomeMap:
    """``tour(...)``, read from the cache when it holds it (module docstring)."""
    root = cache_dir()
    key = tour_key(layout, day, detector, config)
    path = None if root is None else root / "tours" / f"{key}.npz"
    if path is not None:
        got = _read_tour(path, layout, day, catalog)
        if got is not None:
            return got
    home = tour(layout, catalog, detector, config, day, body=body, sensor=sensor)
    if path is not None:
        write_bytes(path.parent, path.name, home.to_bytes(), "remembered-map tour")
    return home


def _read_tour(path: Path, layout: RoomLayout, day: int, catalog: Catalog) -> HomeMap | None:
    try:
        data = path.read_bytes()
    except OSError:
        return None
    try:
        home = check_types(HomeMap.from_bytes(data, path), catalog.type_names, path)
    except HomeMapError:
        return None
    if (home.style, home.seed, home.day) != (layout.style, layout.seed, int(day)):
        return None
    return home
