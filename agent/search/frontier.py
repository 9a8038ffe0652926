"""Exploration for the online search (agent.search.online), on the robot's own map and on a given
one: drive to the viewpoint that finds the most of what is left per expected second and sweep
there (viewpoint gain and exhaustion: agent.search.viewpoints; for the target, the belief's mass
times the probability of finding it at each point's distance: agent.search.belief), with
near-floor images where the floor around is unknown so the built map grows. ``Explorer`` holds
one episode's exploration state (where it swept, what it gave up on).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ctxsearch.agent.search import belief
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search import viewpoints as sx
from ctxsearch.agent.search.context import SearchContext
from ctxsearch.agent.search.coverage import belief_sweep, sweep
from ctxsearch.agent.sight import NEAR_TILT


class Explorer:
    """One episode's exploration of the built map for ``ctx``: the viewpoint scorer (made on
    first use), the points given up on per detection range (exhausted), and where sweeps for
    each range were made."""

    def __init__(self, ctx: SearchContext):
        self.ctx = ctx
        self._scorer: sx.ViewpointScorer | None = None
        self.exhausted: dict[float, np.ndarray] = {}
        self.swept: dict[float, list[np.ndarray]] = {}
        self.unstuck: list[np.ndarray] = []  # where the floor around was mapped to get unstuck
        self.advanced: list[np.ndarray] = []  # where the robot went toward a place beyond

    def scorer(self) -> sx.ViewpointScorer:
        """The built map's viewpoint scorer (made on first use)."""
        if self._scorer is None:
            c = self.ctx
            views = c.maps.views if c.built is None else None  # the given map never changes
            self._scorer = sx.ViewpointScorer(
                c.occluders, c.seen.points, c.spec, c.time_model, views, c.sight_cap
            )
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

    def given_up(self) -> np.ndarray:
        """(N,) bool: the points given up on for the target (exhausted: hidden from nearby)."""
        ex = self.exhausted.get(self.ctx.target_range)
        return np.zeros(len(self.ctx.seen), bool) if ex is None else ex

    def target_todo(self) -> np.ndarray:
        """(N,) bool: the points still worth a look for the target: not given up on and holding
        at least ``belief.MISS_DONE`` of their mass (agent.search.belief)."""
        return (self.ctx.misses.miss > belief.MISS_DONE) & ~self.given_up()

    def viewpoint(
        self,
        rng: float,
        images: float,
        zmax: float | None = None,
        weights: np.ndarray | None = None,
    ) -> sx.Viewpoint | None:
        """Where to sweep next for range ``rng``: the best share of the points per second
        (``weights``: of their weight); None if none is worth it."""
        return self._best(rng, self.todo(rng, zmax), sx.Sight(rng), images, weights, (rng, zmax))

    def target_viewpoint(self, weights: np.ndarray) -> sx.Viewpoint | None:
        """Where to sweep next for the target: the most belief mass (``weights``) found per
        second, each point's mass times the probability that a sweep there finds it at its
        distance (the detection curve); None if none is worth it."""
        return self._best(self.ctx.target_range, self.target_todo(), self.target_sight(),
                          sx.SWEEP_IMAGES, weights, None)  # fmt: skip

    def beyond_viewpoint(self, weights: np.ndarray) -> sx.Beyond | None:
        """On the robot's own map: the place beyond the frontier whose sweep would find the most
        belief mass (``weights``) per second of the way there, and the viewpoint where that way
        leaves the map (``ViewpointScorer.beyond``); None on a map that does not grow."""
        ctx = self.ctx
        if ctx.occluders is None or ctx.built is None:
            return None
        been = [*self.swept.get(ctx.target_range, []), *self.advanced]
        avoid = np.array(been) if been else None
        return self.scorer().beyond(
            ctx.grid, self.target_todo(), ctx.body.pose().xy, self.target_sight(),
            sx.SWEEP_IMAGES, weights, avoid,
        )  # fmt: skip

    def target_sight(self) -> sx.Sight:
        """What a sweep for the target is scored for: each point's P(found) at its distance
        (the detection curve), up to the curve's reach."""
        curve = self.ctx.curve
        return sx.Sight(curve.reach, curve.found)

    def _best(self, rng, todo, sight, images, weights, key) -> sx.Viewpoint | None:
        ctx = self.ctx
        if ctx.occluders is None:
            return None
        here = ctx.body.pose().xy
        avoid = np.array(self.swept[rng]) if self.swept.get(rng) else None
        return self.scorer().best(ctx.grid, todo, here, sight, images, avoid, key, weights)

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

    def advance(self, vp: sx.Viewpoint) -> None:
        """Drive to ``vp`` (where the way to a place beyond the frontier leaves the map) and
        image the floor around where it is unknown, so the map grows that way; ``vp`` is not
        advanced to again."""
        self.advanced.append(np.asarray(vp.xy, float))
        if self.ctx.drive_to(vp.xy):
            self.map_floor()

    def map_floor(self, tilts: Sequence[float] = (NEAR_TILT,), min_unknown: float = 0.3) -> int:
        """Images at the near-floor ``tilts`` where at least ``min_unknown`` of the floor around
        is still unknown (agent.search.viewpoints.floor_headings); images taken."""
        ctx = self.ctx
        if ctx.built is None:
            return 0
        p = ctx.body.pose()
        n = 0
        for h in sx.floor_headings(ctx.built, p.xy, p.yaw + p.pan, min_unknown=min_unknown):
            for t in tilts:
                ctx.look_heading(h, t, "map the floor")
                n += 1
        return n

    def unstick(self) -> bool:
        """When no viewpoint is reachable on the built map (the robot stands where the floor
        around it was never in view: a doorway, a gap between furniture), images of the floor in
        every heading with any unknown floor, at the near-floor tilt and the steepest one, once
        per place; True if it took any (then the options are worth computing again)."""
        ctx = self.ctx
        if ctx.built is None:
            return False
        here = ctx.body.pose().xy
        if any(np.hypot(*(here - xy)) < sx.VISITED_RADIUS for xy in self.unstuck):
            return False  # once per place
        self.unstuck.append(here)
        return self.map_floor((NEAR_TILT, ctx.spec.tilt_range[0]), min_unknown=0.02) > 0

    def exhaust(self, rng: float, xy: np.ndarray | None = None) -> None:
        """Mark what a sweep at ``xy`` (default: here) left unseen nearby as exhausted for
        ``rng``; regions waiting for a gaze may be reachable now."""
        ctx = self.ctx
        if ctx.occluders is None:
            return
        here = ctx.body.pose().xy if xy is None else np.asarray(xy, float)
        ex = self.scorer().exhaust(here, ctx.seen.unseen(min(rng, sx.EXHAUST_RADIUS)), rng)
        old = self.exhausted.get(rng)
        self.exhausted[rng] = ex if old is None else old | ex
        ctx.waiting.clear()

    def explore_target(self, vp: sx.Viewpoint, weights: np.ndarray) -> None:
        """Drive to ``vp`` and sweep there for the target by the belief ``weights``
        (``coverage.belief_sweep``); what stayed unseen nearby is exhausted."""
        rng = self.ctx.target_range
        self.swept.setdefault(rng, []).append(np.asarray(vp.xy, float))
        if self.ctx.drive_to(vp.xy):
            belief_sweep(self.ctx, weights)
            self.map_floor()
        self.exhaust(rng, vp.xy)

    def look_around(self, weights: np.ndarray | None = None) -> None:
        """A sweep for the target where the robot stands (the first images of a built map); by
        the belief ``weights`` if given."""
        ctx = self.ctx
        self.swept.setdefault(ctx.target_range, []).append(ctx.body.pose().xy)
        if weights is None:
            sweep(ctx, ctx.target_range, purpose="look around")
        else:
            belief_sweep(ctx, weights, purpose="look around")
        self.map_floor()
        self.exhaust(ctx.target_range)
