"""Coverage: look everywhere a type could be seen from, with no context (``exhaustive``, and
every policy's fall-back). Coverage viewpoints from a greedy set cover, visited in a short tour,
with pan/tilt sweeps that skip what the depth images already showed (agent.search.space).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search.context import SearchContext
from ctxsearch.envs.camera import frustum_mask
from ctxsearch.envs.robot_spec import wrap_angle

FURNITURE_TILTS = (-0.35,)  # one ring of images finds furniture (detected from metres away)


def cover(
    ctx: SearchContext,
    type_name: str | None = None,
    *,
    tilts: Sequence[float] = ss.SWEEP_TILTS,
    until: Callable[[], bool] | None = None,
    rounds: int = 6,
    purpose: str = "sweep",
) -> None:
    """Exhaustive coverage for ``type_name`` (default: the target): tour the coverage viewpoints
    and sweep at each. Returns when ``until()`` turns true after an image, or when nothing
    coverable is left: a round whose sweeps found no image worth ``SWEEP_MIN_SHARE`` of what is
    unseen is followed by one that takes every image showing at least a few unseen points."""
    name = type_name or ctx.target
    rng = ctx.range_of(name)
    share = ss.SWEEP_MIN_SHARE
    for _ in range(rounds):
        unseen = ctx.seen.unseen(rng)
        sites = ss.coverage_viewpoints(
            ctx.grid, ctx.seen.points[unseen], ctx.body.pose().xy, rng, ctx.spec
        )
        if len(sites) == 0:
            return
        ctx.note(
            f"coverage for {name} (range {rng:.1f} m): {len(sites)} viewpoints, "
            f"{100 * ctx.seen.seen_fraction(rng):.0f}% seen"
        )
        took = 0
        for xy in sites:
            unseen = ctx.seen.unseen(rng)
            cam = np.array([xy[0], xy[1], ctx.spec.camera_height])
            if (np.linalg.norm(ctx.seen.points[unseen] - cam, axis=1) <= rng).sum() < 8:
                continue
            if not ctx.drive_to(xy):
                continue
            took += sweep(ctx, rng, tilts=tilts, purpose=purpose, until=until, share=share)
            if until is not None and until():
                return
        if took == 0:
            if share == 0.0:
                return
            share = 0.0


def sweep(
    ctx: SearchContext,
    rng: float,
    *,
    tilts: Sequence[float] = ss.SWEEP_TILTS,
    purpose: str = "sweep",
    until: Callable[[], bool] | None = None,
    share: float = ss.SWEEP_MIN_SHARE,
) -> int:
    """A pan/tilt sweep here, skipping images predicted to add little (and stopping early when
    ``until()`` turns true after an image); images taken."""
    pose = ctx.body.pose()
    cam = np.array([pose.x, pose.y, ctx.spec.camera_height])
    seen = ctx.seen
    unseen = seen.unseen(rng)
    plan = ss.sweep_gazes(
        pose.xy,
        pose.yaw + pose.pan,
        seen.points,
        unseen,
        ctx.spec,
        rng,
        ss.SweepOptions(tilts=tuple(tilts), min_share=share),
    )
    near = np.linalg.norm(seen.points - cam, axis=1) <= rng
    need = max(8, int(math.ceil(share * np.count_nonzero(unseen & near))))
    n = 0
    for g in plan:
        # Re-check against what the images so far really showed.
        m = frustum_mask(cam, g.heading, g.tilt, seen.points, ctx.spec, rng) & seen.unseen(rng)
        if m.sum() < need:
            continue
        ctx.look_heading(g.heading, g.tilt, purpose)
        n += 1
        if until is not None and until():
            break
    return n


def belief_sweep(
    ctx: SearchContext,
    weights: np.ndarray,
    *,
    purpose: str = "explore",
    min_share: float = ss.SWEEP_MIN_SHARE,
) -> int:
    """A pan/tilt sweep here for the target, by the belief (agent.search.belief): of the images
    at headings 60 degrees apart and ``SWEEP_TILTS``, the one that finds the most belief mass
    next (``weights`` (N,), each point's mass as the miss field holds it now, times the
    probability a confirmed detection finds it at its distance, inside the frustum) is taken,
    until the best left would find less than ``min_share`` of what the first image was expected
    to find; images taken."""
    pose = ctx.body.pose()
    cam = np.array([pose.x, pose.y, ctx.spec.camera_height])
    curve, pts = ctx.curve, ctx.seen.points
    d = np.linalg.norm(pts - cam, axis=1)
    idx = np.flatnonzero((d <= curve.reach) & (weights > 0))
    if len(idx) == 0:
        return 0
    found, w0, m0 = curve.found(d[idx]), weights[idx], ctx.misses.miss[idx].copy()
    h0 = pose.yaw + pose.pan
    gazes = [(wrap_angle(h0 + i * math.pi / 3), t) for i in range(6) for t in ss.SWEEP_TILTS]
    masks = np.array([frustum_mask(cam, h, t, pts[idx], ctx.spec, curve.reach) for h, t in gazes])
    taken: set[int] = set()
    first, n = None, 0
    while len(taken) < len(gazes):
        w = w0 * ctx.misses.miss[idx] / np.maximum(m0, 1e-12) * found
        vals = (masks * w).sum(axis=1)  # not BLAS: the same sums on any thread count
        vals[list(taken)] = -1.0
        best = int(np.argmax(vals))
        first = vals[best] if first is None else first
        if vals[best] <= 0.0 or vals[best] < min_share * first:
            break
        taken.add(best)
        ctx.look_heading(*gazes[best], purpose)
        n += 1
    return n


def estimate_cover_seconds(
    ctx: SearchContext,
    start_xy: np.ndarray,
    rng: float,
    head_s: float = 0.6,
    tilts: Sequence[float] = ss.SWEEP_TILTS,
    zmax: float | None = None,
) -> float:
    """Seconds a coverage of the room for detection range ``rng`` would take from ``start_xy``
    on ``ctx``'s grid and seen map: the tour plus the sweeps' images (predicted without
    occlusion), sweeping ``tilts`` and counting only lattice points up to ``zmax`` (furniture:
    its height) if given."""
    grid, seen, spec, tm = ctx.grid, ctx.seen, ctx.spec, ctx.time_model
    pts = seen.points if zmax is None else seen.points[seen.points[:, 2] <= zmax]
    unseen = seen.unseen(rng) if zmax is None else seen.unseen(rng)[seen.points[:, 2] <= zmax]
    sites = ss.coverage_viewpoints(grid, pts[unseen], start_xy, rng, spec)
    t = ss.tour_seconds(grid, sites, start_xy, tm)
    todo = unseen.copy()
    heading = 0.0
    for xy in sites:
        g = ss.sweep_gazes(xy, heading, pts, todo, spec, rng, ss.SweepOptions(tilts=tuple(tilts)))
        t += tm.looks_estimate(len(g), head_s)
        cam = np.array([xy[0], xy[1], spec.camera_height])
        for x in g:
            todo &= ~frustum_mask(cam, x.heading, x.tilt, pts, spec, rng)
    return t
