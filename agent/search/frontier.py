"""Exploration on the robot's own map (``--map built``): drive to the viewpoint that shows the
largest share of what is left to see per expected second and sweep there (viewpoint gain and
exhaustion: agent.search.viewpoints), with near-floor images where the floor around is unknown so
the map grows. ``Explorer`` holds one episode's exploration state (where it swept, what it gave
up on); the online decision (agent.search.online) makes one per episode.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ctxsearch.agent.frontiers import NEAR_TILT
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search import viewpoints as sx
from ctxsearch.agent.search.context import SearchContext
from ctxsearch.agent.search.coverage import sweep


class Explorer:
    """One episode's exploration of the built map for ``ctx``: the viewpoint scorer (made on
    first use), the points given up on per detection range (exhausted), and where sweeps for
    each range were made."""

    def __init__(self, ctx: SearchContext):
        self.ctx = ctx
        self._scorer: sx.ViewpointScorer | None = None
        self.exhausted: dict[float, np.ndarray] = {}
        self.swept: dict[float, list[np.ndarray]] = {}

    def scorer(self) -> sx.ViewpointScorer:
        """The built map's viewpoint scorer (made on first use)."""
        if self._scorer is None:
            c = self.ctx
            self._scorer = sx.ViewpointScorer(c.built, c.seen.points, c.spec, c.time_model)
        return self._scorer

    def todo(self, rng: float, zmax: float | None = None) -> np.ndarray:
        """(N,) bool: seen-map points still to be seen for range ``rng`` (not seen from within
        it, not exhausted), up to height ``zmax`` if given."""
        m = self.ctx.seen.unseen(rng)
        ex = self.exhausted.get(rng)
        if ex is not None:
            m &= ~ex
        if zmax is not None:
            m &= self.ctx.seen.points[:, 2] <= zmax
        return m

    def viewpoint(
        self,
        rng: float,
        images: float,
        zmax: float | None = None,
        weights: np.ndarray | None = None,
    ) -> sx.Viewpoint | None:
        """Where to sweep next for range ``rng``: the best share per second (``weights``: of the
        target's probability over the points, else of the points); None on a given map or if
        none is worth it."""
        ctx = self.ctx
        if ctx.built is None:
            return None
        here = ctx.body.pose().xy
        avoid = np.array(self.swept[rng]) if self.swept.get(rng) else None
        return self.scorer().best(
            ctx.grid, self.todo(rng, zmax), here, rng, images, avoid, key=(rng, zmax),
            weights=weights,
        )  # fmt: skip

    def explore_step(
        self,
        vp: sx.Viewpoint,
        rng: float,
        tilts: Sequence[float] = ss.SWEEP_TILTS,
        purpose: str = "explore",
        until: Callable[[], bool] | None = None,
    ) -> None:
        """Drive to ``vp`` and sweep there for range ``rng``; what stayed unseen nearby is
        exhausted."""
        self.swept.setdefault(rng, []).append(np.asarray(vp.xy, float))
        if self.ctx.drive_to(vp.xy):
            sweep(self.ctx, rng, tilts=tilts, purpose=purpose, until=until)
            if until is None or not until():
                self.map_floor()
        self.exhaust(rng, vp.xy)

    def map_floor(self) -> None:
        """Images at the near-floor tilt where the floor around is still unknown
        (agent.search.viewpoints.floor_headings)."""
        ctx = self.ctx
        if ctx.built is None:
            return
        p = ctx.body.pose()
        for h in sx.floor_headings(ctx.built, p.xy, p.yaw + p.pan):
            ctx.look_heading(h, NEAR_TILT, "map the floor")

    def exhaust(self, rng: float, xy: np.ndarray | None = None) -> None:
        """Mark what a sweep at ``xy`` (default: here) left unseen nearby as exhausted for
        ``rng``; regions waiting for a gaze may be reachable now."""
        ctx = self.ctx
        if ctx.built is None:
            return
        here = ctx.body.pose().xy if xy is None else np.asarray(xy, float)
        ex = self.scorer().exhaust(here, ctx.seen.unseen(rng), rng)
        old = self.exhausted.get(rng)
        self.exhausted[rng] = ex if old is None else old | ex
        ctx.waiting.clear()

    def look_around(self) -> None:
        """A sweep for the target where the robot stands (the first images of a built map)."""
        ctx = self.ctx
        self.swept.setdefault(ctx.target_range, []).append(ctx.body.pose().xy)
        sweep(ctx, ctx.target_range, purpose="look around")
        self.map_floor()
        self.exhaust(ctx.target_range)
