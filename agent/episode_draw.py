"""One world's search episode, as the benchmark draws it (``scripts.experiments.episodes``
draws a list of them, in parallel; the Gymnasium task (agent.gym_env) draws one): a held-out
room, a target drawn among its small types, a start from which the target is not visible, and a
check that the oracle's planner detects it within the budget.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ctxsearch.agent import search as S
from ctxsearch.agent.navigation import OccupancyGrid
from ctxsearch.envs.detector import DetectorModel
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import WorldStyle
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.envs.world import World
from ctxsearch.knowledge.catalog import Catalog

MAX_START_TRIES = 6  # starts drawn in a world before it is dropped as visible from every one
EPISODE_TAG = 0xE915  # the episode stream of world i: (seed, i, EPISODE_TAG)


@dataclass(frozen=True)
class WorldDraw:
    """One world's draw: its episode (index to be set), or why it was dropped (None: it holds
    nothing to search for, or the store learned in it), and how many starts were redrawn."""

    episode: S.Episode | None
    dropped: str | None = None
    redraws: int = 0


def draw_world(
    style: WorldStyle,
    seed: int,
    catalog: Catalog,
    budget_s: float,
    exclude_seeds: frozenset[int],
    target: str | None,
    detector: DetectorModel | None,
    i: int,
) -> WorldDraw:
    """World ``i``'s episode (see ``draw_episodes``): a start from which the target is not
    visible and from which the oracle's planner detects it within ``budget_s``."""
    room_seed = S.held_out_seed(seed, i)
    rng = np.random.default_rng([int(seed), i, EPISODE_TAG])
    if room_seed in exclude_seeds:
        return WorldDraw(None)
    layout = generate_layout(style, room_seed, catalog)
    tgt = episode_target(layout, catalog, target, rng)
    if tgt is None:
        return WorldDraw(None)
    spec = RobotSpec()
    grid = OccupancyGrid.from_layout(layout, spec)
    redraws = 0
    with World(layout, catalog, spec=spec) as world:
        eye = S.OracleEye(world, layout, catalog, detector, tgt)
        for _ in range(MAX_START_TRIES):
            start = S.random_start(layout, grid, rng)
            if eye.start_visibility(start) < S.VISIBLE_MIN_P:
                break
            redraws += 1
        else:
            return WorldDraw(None, "visible_at_start", redraws)
        world.reset_pose(start)
        # planned at the episode's second 0, as the Oracle policy would plan it
        view = S.oracle_view(eye, grid, start, 0.0, world.time_model, deadline_s=budget_s)
    if view is None:
        return WorldDraw(None, "infeasible", redraws)
    ep = S.Episode(-1, style.name, room_seed, tgt, start, budget_s, first_view=view)
    return WorldDraw(ep, None, redraws)


def episode_target(
    layout: RoomLayout, catalog: Catalog, target: str | None, rng: np.random.Generator
) -> str | None:
    """The episode's target in ``layout``: ``target`` if the room holds one, else a small type
    drawn from ``rng``; None: the room does not serve."""
    if target is not None:
        return target if target in {o.type for o in layout.objects} else None
    small = S.small_types_present(layout, catalog)
    return small[int(rng.integers(len(small)))] if small else None
