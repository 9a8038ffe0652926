"""Map quality after a full exploration (part of ``ctxsearch bench sim``).

In each of the first ``worlds`` layouts the camera robot starts at the learning loop's start pose
knowing only that pose, explores frontiers (agent.frontiers ``explore_world``) until no goal is
left, and its built map (agent.mapping) is compared with the true layout's grid:

- ``map_free_recall``: the share of the true grid's free cells reachable from the start that the
  built map calls free (median over the worlds);
- ``map_false_free``: cells the built map calls free where the base would overlap an obstacle's
  bounding box (summed over the worlds; must be 0); ``map_false_free_margin``: those within the
  navigation margin of one (agent.mapping ``map_quality``);
- ``explore_sim_s``: simulated seconds of the exploration (median); ``explore_wall_s`` the wall
  seconds (median); ``map_unsafe_segments``: planned drive segments that come nearer than the base
  radius to an obstacle of the true layout (summed; must be 0).

``map_overview.png`` shows the first world's built map over the true plan.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from ctxsearch.agent.acquisition import start_pose
from ctxsearch.agent.frontiers import Exploration, explore_world
from ctxsearch.agent.mapping import BuiltMap, MapQuality, map_quality
from ctxsearch.agent.navigation import OccupancyGrid, obstacle_boxes
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotSpec, TimeModel
from ctxsearch.envs.world import World
from ctxsearch.knowledge.catalog import Catalog


def body_grid(layout: RoomLayout, spec: RobotSpec) -> OccupancyGrid:
    """The true layout's grid at the bare base radius: a base centre in a free cell touches
    nothing (drives are checked against it)."""
    bounds = (-layout.width / 2, -layout.depth / 2, layout.width / 2, layout.depth / 2)
    return OccupancyGrid.from_boxes(obstacle_boxes(layout, spec), bounds, spec.base_radius)


def unsafe_segments(paths: list[np.ndarray], body: OccupancyGrid) -> int:
    """How many segments of ``paths`` leave ``body``'s free cells."""
    return sum(
        not body.line_of_sight(a, b) for p in paths for a, b in zip(p[:-1], p[1:], strict=True)
    )


def explore_results(
    layouts: list[RoomLayout],
    catalog: Catalog,
    out_dir: Path,
    *,
    width: int = 320,
    height: int = 240,
    rule: str = "info",
) -> dict:
    """Explore every layout fully; the map-quality keys (module docstring). Writes
    ``map_overview.png`` for the first."""
    spec, tm = RobotSpec(), TimeModel()
    recall, false_free, margin, sim_s, wall_s, unsafe = [], 0, 0, [], [], 0
    for k, lay in enumerate(layouts):
        given = OccupancyGrid.from_layout(lay, spec)
        start = start_pose(lay, given)
        with World(lay, catalog, width=width, height=height, spec=spec, time_model=tm) as world:
            world.reset_pose(start)
            built = BuiltMap.for_layout(lay, spec, start)
            t0 = time.perf_counter()
            ex = explore_world(world, built, tm, rule)
            wall_s.append(time.perf_counter() - t0)
        body = body_grid(lay, spec)
        q = map_quality(built.refresh(), given, body, start.xy)
        recall.append(q.free_recall)
        false_free += q.false_free
        margin += q.false_free_margin
        sim_s.append(ex.sim_s)
        unsafe += unsafe_segments(ex.paths, body)
        if k == 0:
            write_map_overview(lay, given, q, ex, out_dir / "map_overview.png")
    med = statistics.median
    return {
        "map_worlds": len(layouts),
        "frontier_rule": rule,
        "map_free_recall": med(recall),
        "map_free_recall_min": min(recall),
        "map_false_free": false_free,
        "map_false_free_margin": margin,
        "map_unsafe_segments": unsafe,
        "explore_sim_s": med(sim_s),
        "explore_wall_s": med(wall_s),
    }


def write_map_overview(
    layout: RoomLayout, given: OccupancyGrid, q: MapQuality, ex: Exploration, path: Path
) -> None:
    """The built map over the true plan: object footprints (green), the true blocked area
    (grey), floor seen (pale blue), navigable (blue), occupied (black), false free (red), and the
    robot's drives (magenta)."""
    m = ex.built
    img = np.ones(m.floor.shape + (3,))
    img[~given.free] = (0.85, 0.85, 0.85)
    img[m.floor] = (0.75, 0.9, 1.0)
    img[m.grid.free] = (0.3, 0.7, 1.0)
    img[m.occupied] = (0.1, 0.1, 0.1)
    img[m.grid.free & ~given.free] = (1.0, 0.0, 0.0)
    w, d = layout.width, layout.depth
    fig = Figure(figsize=(9, 7 * d / w + 0.9))
    ax = fig.subplots()
    ax.imshow(img, origin="lower", extent=(-w / 2, w / 2, -d / 2, d / 2), interpolation="nearest")
    for o in layout.objects:
        c = o.box().corners_xy()
        c = np.vstack([c, c[:1]])
        ax.plot(c[:, 0], c[:, 1], "-", color="#2ca02c", lw=0.6)
    for p in ex.paths:
        ax.plot(p[:, 0], p[:, 1], "-", color="m", lw=0.9)
    ax.legend(
        handles=[
            Patch(color=(0.75, 0.9, 1.0), label="floor seen"),
            Patch(color=(0.3, 0.7, 1.0), label="navigable (built)"),
            Patch(color=(0.1, 0.1, 0.1), label="occupied (seen)"),
            Patch(color=(0.85, 0.85, 0.85), label="blocked (true), unknown"),
            Patch(color=(1.0, 0.0, 0.0), label="false free"),
        ],
        fontsize=7,
        loc="upper left",
        bbox_to_anchor=(1.0, 1.0),
    )
    ax.set_title(
        f"{layout.style} seed {layout.seed}: the built map after {ex.looks} look-arounds, "
        f"{m.images} images, {ex.sim_s:.0f} s simulated\n"
        f"free recall {q.free_recall:.2f}, false free {q.false_free} "
        f"(within the margin: {q.false_free_margin}); the drives in magenta",
        fontsize=9,
    )
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    fig.savefig(path, dpi=110, bbox_inches="tight")
