"""The location constraint: look into the relation volumes of known objects, the most likely per
second first (``search_regions``), or all of them in a short tour without probabilities
(``tour_regions``, the value of the map alone). Candidate regions, their probabilities and costs
come from agent.search.space; the gazes from the view planner (agent.viewplan).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from ctxsearch.agent.navigation import nearest_free
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search.context import SearchContext
from ctxsearch.agent.viewplan import Gaze, GazePlanOptions, plan_gazes
from ctxsearch.knowledge.geometry import ObjectInstance

MIN_REGION_SCORE = 0.01  # regions with less probability left are not worth a look
# The best few regions by the cost model are re-costed with their planned gazes before one is
# chosen (the estimate misses detours: furniture in the way, on a built map what is not mapped);
# measured on the given map (docs/results.md, Search).
REPLAN_REGIONS = 6
# On the built map (the online search's region option) 3 (docs/results.md, Search).
REPLAN_REGIONS_BUILT = 3
LOOK_DISTANCE_M = 2.5  # the farthest a gaze into a region stands from it


def cost_model(ctx: SearchContext) -> ss.CostModel:
    """The cost model of looking into regions for the target from ``ctx``'s map."""
    return ss.CostModel(
        ctx.grid, ctx.time_model, view_distance=min(ctx.target_range, LOOK_DISTANCE_M)
    )


def region_gazes(ctx: SearchContext, region: ss.Region) -> list[Gaze]:
    """The view planner's gazes into ``region`` from where the robot stands."""
    return plan_gazes(
        ctx.grid, region.box, ctx.body.pose(), ctx.spec, ctx.time_model,
        GazePlanOptions(max_distance=min(ctx.target_range, LOOK_DISTANCE_M)),
        facing=region.facing,
    )  # fmt: skip


def planned_seconds(ctx: SearchContext, gazes: Sequence[Gaze]) -> float:
    """The seconds the planned ``gazes`` take, images included."""
    return sum(g.cost for g in gazes) + ctx.time_model.image_cost * len(gazes)


def search_regions(
    ctx: SearchContext,
    probs: ss.ProbabilitySource,
    *,
    known: Callable[[], Sequence[ObjectInstance]],
    replan: int = 0,
) -> None:
    """Look into the best candidate region (probability per second) until none has probability
    left; with ``replan`` > 0 the best ``replan`` regions by the cost model are re-costed with
    their planned gazes."""
    costs = cost_model(ctx)
    builder = ss.RegionBuilder(ctx.catalog, probs, ctx.seen, ctx.target)
    while True:
        ctx.check()
        regions = [r for r in builder.regions(known()) if r.key not in ctx.looked_into]
        ranked = ss.score_regions(regions, ctx.seen, ctx.target_range, costs, ctx.body.pose().xy)
        ranked = [r for r in ranked if r.score >= MIN_REGION_SCORE]
        log_candidates(ctx, ranked)
        if not ranked:
            ctx.note("no candidate region left")
            return
        best, gazes = _best_planned(ctx, ranked, replan)
        ctx.looked_into.add(best.key)
        ctx.note(
            f"look into {best.label}: P={best.score:.2f}, ~{best.cost:.1f} s, {len(gazes)} gazes "
            f"({len(ranked)} candidates)"
        )
        for g in gazes:
            ctx.look_gaze(g, f"region {best.label}")


def _best_planned(
    ctx: SearchContext, ranked: Sequence[ss.Region], replan: int
) -> tuple[ss.Region, list[Gaze]]:
    """The region to look into and its gazes: ``ranked[0]``, or with ``replan`` > 0 the best
    probability per planned second among the first ``replan``."""
    if replan <= 0:
        return ranked[0], region_gazes(ctx, ranked[0])
    planned = []
    for r in ranked[:replan]:
        gz = region_gazes(ctx, r)
        cost = planned_seconds(ctx, gz)
        planned.append((r.score / max(cost, 1e-6) if gz else -1.0, -cost, r.key, r, gz))
    best = max(planned, key=lambda x: x[:3])
    return best[3], best[4]


def look_region(
    ctx: SearchContext,
    region: ss.Region,
    gazes: Sequence[Gaze] | None = None,
    vias: Mapping[str, float] | None = None,
) -> None:
    """Look into a candidate region with the view planner's gazes (``gazes`` if planned
    already; a region no gaze reaches on the map as it stands waits for the next exploration
    step). ``vias``: the intermediate types the online search considers (type: predicted gain);
    looking into the volume of one of them makes it the search's intermediate type."""
    gazes = region_gazes(ctx, region) if gazes is None else gazes
    if not gazes:
        ctx.waiting.add(region.key)
        return
    ctx.looked_into.add(region.key)
    if ctx.intermediate is None and vias:  # indirect search via a type found before
        for _rel, ref in region.members:
            ref_type = ctx.known[ref].type if ref in ctx.known else None
            if ref_type in vias:
                ctx.intermediate, ctx.predicted_gain = ref_type, vias[ref_type]
                break
    for g in gazes:
        ctx.look_gaze(g, f"region {region.label}")


def tour_regions(ctx: SearchContext, objects: Sequence[ObjectInstance]) -> None:
    """``map-only``: look into every relation volume of ``objects`` (no probabilities) in the
    order of a short tour from here, skipping volumes already mostly seen."""
    regions = ss.build_regions(
        objects, ctx.target, ctx.catalog, ss.UniformProbabilities(), ctx.seen
    )
    if not regions:
        return
    grid = ctx.grid
    here = ctx.body.pose().xy
    sites = []
    for r in regions:
        p = nearest_free(grid, np.asarray(r.box.center[:2], float))
        sites.append(p if p is not None else np.asarray(r.box.center[:2], float))
    by_site: dict[tuple[float, float], list[ss.Region]] = {}
    for xy, r in zip(sites, regions, strict=True):
        by_site.setdefault((round(float(xy[0]), 6), round(float(xy[1]), 6)), []).append(r)
    order = ss.tour_order(grid, np.array(list(by_site)), here)
    ctx.note(f"tour of {len(regions)} relation volumes of the map")
    for xy in order:
        for r in by_site[(round(float(xy[0]), 6), round(float(xy[1]), 6))]:
            if ctx.seen.unseen(ctx.target_range)[r.points].mean() >= 0.5:
                look_region(ctx, r)


def log_candidates(
    ctx: SearchContext, ranked: Sequence[ss.Region], show: int = 12, labelled: int = 3
) -> None:
    """Record the best ``show`` candidate regions; only the best ``labelled`` carry a short label
    (the next one, in red: its region and P; the others: rank and P)."""
    rec = ctx.recorder
    if not rec.enabled:
        return
    rec.set_time(ctx.elapsed)
    best = list(ranked[:labelled])
    rec.log_volumes(
        "world/search/candidates", [r.box for r in ranked[labelled:show]], color=(0.85, 0.7, 0.3)
    )
    rec.log_volumes(
        "world/search/top",
        [r.box for r in best[1:]],
        [f"#{i + 2} P={r.score:.2f}" for i, r in enumerate(best[1:])],
        color=(0.95, 0.75, 0.1),
    )
    rec.log_volumes(
        "world/search/best",
        [r.box for r in best[:1]],
        [f"next: {r.label} P={r.score:.2f}" for r in best[:1]],
        color=(0.95, 0.2, 0.1),
    )
