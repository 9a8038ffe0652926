"""The search policies (paper, section 3): each puts the behaviours together on a context. Their
facts (scenarios, what they need, roles) are ``agent.search.registry``'s; the oracle is in
``agent.search.oracle``.

- ``frontier`` (built map): no context. The online decision (agent.search.online) with every
  point alike: the frontier viewpoint that shows the most of what is left to see per expected
  second; coverage of what stayed unseen when no viewpoint is left.
- ``map-only`` (given): the value of the map alone: every relation volume of the known
  furniture, no probabilities, in the order of a short tour; then coverage.
- ``exhaustive``: no context. Coverage (agent.search.coverage).
- ``uniform`` (given): no context, ``location``'s fair twin: the online decision
  (agent.search.online) with every point alike on the given map; then coverage.
- ``location`` (given): the location constraint as a belief (agent.search.belief): the online
  decision over the relation volumes of the furniture map and of everything detected so far,
  with P(rel(T)) from the knowledge; coverage when no option is left.
- ``indirect``: detectability-driven, two algorithms by scenario. On the built map
  (``IndirectOnline``) the online decision among known objects' relation volumes, the
  intermediate types Wixson & Ballard's efficiency model says pay, and the frontier; it records
  the intermediate type it used and the model's predicted gain. On the given map
  (``IndirectPlanned``) a plan made once at the start: look for T directly, or first for an
  intermediate type I (``space.indirect_plan`` on the map's coverage costs), then the location
  constraint around what it detected.
- ``oracle-prior``, ``oracle-prior-indirect``: ``location`` and ``indirect`` with the true
  probabilities (the registry's ``needs``: the runner gives them the truth's table).
- ``bound-rooms``, ``bound-target-room``, ``bound-plan`` (built map): bounds, each handed one
  kind of exact knowledge of the house at the start (the registry's ``handed``; the runner
  gives it): ``frontier`` with the prior weighted by every room's kind (the true density of the
  target by room kind) or by which rooms hold the target (agent.search.room_prior.HandedRooms),
  and ``location`` with the true probabilities over the furniture plan.
- ``memory``, ``memory-location``, ``oracle-memory`` (remembered map): ``uniform``,
  ``location`` and ``oracle-prior`` with the remembered sightings of the target in the belief
  (agent.search.memory), weighted by the learned persistence (the world's for the oracle's).

Which value of the interval ranks candidates is the probability source's rank (``low`` by
default, chosen by measurement: docs/results.md, Search).
"""

from __future__ import annotations

import numpy as np

from ctxsearch.agent.search import regions as rg
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search import viewpoints as sx
from ctxsearch.agent.search.context import SearchContext, SearchStopped
from ctxsearch.agent.search.coverage import FURNITURE_TILTS, cover, estimate_cover_seconds
from ctxsearch.agent.search.episode import SearchResult
from ctxsearch.agent.search.online import OnlineSearch, ViaOption
from ctxsearch.agent.search.registry import PolicySpec
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance, relation_volume
from ctxsearch.knowledge.options import MapMode

MIN_Q = 0.05  # intermediate types less related to the target than this are not considered
MAX_VIAS = 3  # intermediate types compared online on the built map


class SearchPolicy:
    """A search policy: ``run(ctx) -> SearchResult`` (subclasses write ``search``)."""

    def __init__(self, name: str):
        self.name = name

    def run(self, ctx: SearchContext) -> SearchResult:
        """Run the episode until found or out of time; the result (not judged yet)."""
        ctx.policy = self.name
        ctx.note(f"looking for {ctx.target} (detection range {ctx.target_range:.1f} m)")
        try:
            self.search(ctx)
            ctx.note("nothing left to look at")
        except SearchStopped:
            pass
        if ctx.found_id is None and ctx.elapsed >= ctx.episode.budget_s:
            ctx.note("time budget spent")
        return ctx.result()

    def search(self, ctx: SearchContext) -> None:  # pragma: no cover - interface
        """The policy's behaviour; raises SearchStopped (via ctx) when done."""
        raise NotImplementedError


def needs_probs(ctx: SearchContext) -> ss.ProbabilitySource:
    """The context's probabilities; a one-line error if the policy was given none."""
    if ctx.probs is None:
        raise CtxsearchError(
            f"policy '{ctx.policy}' needs probabilities (a knowledge base or ground truth)"
        )
    return ctx.probs


class Exhaustive(SearchPolicy):
    """No context: cover the room with sweeps from a short tour of viewpoints."""

    def search(self, ctx: SearchContext) -> None:
        cover(ctx)


class Online(SearchPolicy):
    """The online search (agent.search.online), then coverage of what stayed unseen. Without
    context (``context`` False) every standable point is alike: ``frontier`` on the built map and
    ``uniform`` on the given map, the fair twins; with it, the knowledge's P(rel(T)) over the
    known objects' relation volumes (``Location``)."""

    context = False

    def search(self, ctx: SearchContext) -> None:
        OnlineSearch(ctx, needs_probs(ctx) if self.context else None).run()
        ctx.note("no option left; coverage of what stayed unseen")
        cover(ctx)


class MapOnly(SearchPolicy):
    """The relation volumes of the known furniture in a short tour, no probabilities; then
    coverage."""

    def search(self, ctx: SearchContext) -> None:
        rg.tour_regions(ctx, ctx.furniture_map())
        ctx.note("falling back to exhaustive coverage")
        cover(ctx)


class Location(Online):
    """The location constraint as a belief: the online search over the relation volumes of the
    furniture map and of everything detected so far, with P(rel(T)) from the knowledge (no
    intermediate types), then coverage."""

    context = True


def candidate_types(ctx: SearchContext, probs: ss.ProbabilitySource) -> list[str]:
    """Types worth finding before the target: related to it with P >= ``MIN_Q`` and, where the
    knowledge comes from a store, examined at least once."""
    cat = ctx.catalog
    kb = ctx.probs.kb if ctx.probs is not None else None
    return [
        t.name
        for t in cat.types
        if t.name != ctx.target
        and ss.relation_probability(cat, probs, t.name, ctx.target) >= MIN_Q
        and (kb is None or kb.n(t.name) > 0)
    ]


class IndirectOnline(SearchPolicy):
    """``indirect`` on the built map: the online decision among known objects' relation volumes,
    the intermediate types Wixson & Ballard's model says pay, and the frontier."""

    def search(self, ctx: SearchContext) -> None:
        probs = needs_probs(ctx)
        OnlineSearch(ctx, probs, self.worth(ctx, probs)).run()
        ctx.note("no option left; coverage of what stayed unseen")
        cover(ctx)

    @staticmethod
    def worth(ctx: SearchContext, probs: ss.ProbabilitySource) -> list[ViaOption]:
        """The intermediate types whose predicted gain (agent.search.viewpoints.predicted_plan)
        exceeds 1, best first (at most ``MAX_VIAS``); sets the context's predicted gain to the
        best candidate's."""
        cat = ctx.catalog
        cands = candidate_types(ctx, probs)
        ranges = {n: min(ctx.range_of(n), ctx.sight_cap) for n in [ctx.target, *cands]}
        plan = sx.predicted_plan(
            ctx.target, cat, probs, ctx.maps.size, ranges, ctx.time_model, cands
        )
        gains = {o.via: sx.predicted_gain(plan, o.via) or 0.0 for o in plan if o.via}
        ctx.note("predicted gains: " + ", ".join(f"{k} {v:.2f}" for k, v in gains.items()))
        best = max(gains.items(), key=lambda kv: kv[1], default=None)
        ctx.predicted_gain = best[1] if best else None
        out = []
        for o in sorted(
            (o for o in plan if o.via and gains[o.via] > 1.0), key=lambda o: -gains[o.via]
        ):
            typ = cat.type(o.via)
            k = probs.instances(o.via)
            zmax = max(typ.size_max[2], 0.3) if typ.is_furniture else None
            out.append(ViaOption(o.via, o.q, 1.0 if k is None else k, zmax or 9.0, o.look_s,
                                 gains[o.via], o.find_s))  # fmt: skip
        return out[:MAX_VIAS]


class IndirectPlanned(SearchPolicy):
    """``indirect`` on the given map: the plan of ``options`` made once at the start."""

    def search(self, ctx: SearchContext) -> None:
        probs = needs_probs(ctx)
        options = self.options(ctx, probs)
        best = options[0]
        ctx.note(
            "plans: "
            + "; ".join(
                f"{o.via or 'direct'} {o.cost:.0f} s" + (f" (q={o.q:.2f})" if o.via else "")
                for o in options[:5]
            )
        )
        if best.via is None:
            ctx.note(f"look for {ctx.target} directly")
            cover(ctx)
            return
        via = best.via
        ctx.note(f"look first for {via} (q={best.q:.2f}, find ~{best.find_s:.0f} s)")
        tilts = FURNITURE_TILTS if ctx.catalog.type(via).is_furniture else ss.SWEEP_TILTS
        # Find an instance of ``via`` (stop at the first image showing a new one), search around
        # everything detected so far, and repeat while the sweeps find new instances.
        while True:
            before = ctx.found_of(via)
            cover(ctx, via, tilts=tilts, until=lambda b=before: ctx.found_of(via) > b, rounds=1,
                  purpose=f"find {via}")  # fmt: skip
            new = ctx.found_of(via) > before
            rg.search_regions(ctx, probs, known=lambda: list(ctx.known.values()))
            if not new:
                break
        ctx.note("falling back to exhaustive coverage")
        cover(ctx)

    def options(self, ctx: SearchContext, probs: ss.ProbabilitySource) -> list[ss.IndirectOption]:
        """The candidate plans with their expected costs, cheapest first."""
        cat = ctx.catalog
        start = ctx.body.pose().xy
        cands = candidate_types(ctx, probs)
        cover_s: dict[str, float] = {}
        cache: dict[tuple, float] = {}
        for name in [ctx.target, *cands]:
            typ = cat.type(name)
            furniture = typ.is_furniture and name != ctx.target
            key = (round(ctx.range_of(name) * 4) / 4, furniture)
            if key not in cache:
                # Furniture is found by one ring of images at its height.
                cache[key] = estimate_cover_seconds(
                    ctx, start, key[0], tilts=FURNITURE_TILTS if furniture else ss.SWEEP_TILTS,
                    zmax=max(typ.size_max[2], 0.3) if furniture else None,
                )  # fmt: skip
            cover_s[name] = cache[key]
        mean_drive = self._mean_drive(ctx) if cands else 0.0
        look_s = {name: self._look_seconds(ctx, probs, name, mean_drive) for name in cands}
        return ss.indirect_plan(ctx.target, cat, probs, cover_s, look_s, cands)

    @staticmethod
    def _mean_drive(ctx: SearchContext) -> float:
        """The mean driving distance from the start to the free cells beyond the target's
        detection range (m)."""
        d = ctx.grid.distances_from(ctx.episode.start.xy)
        d = d[np.isfinite(d)]
        return float(np.mean(np.maximum(d - ctx.target_range, 0.0))) if len(d) else 0.0

    @staticmethod
    def _look_seconds(
        ctx: SearchContext, probs: ss.ProbabilitySource, via: str, mean_drive: float
    ) -> float:
        """Seconds to look into the most likely relation volume of a found ``via``: the drive
        to within the target's detection range of it (half of ``mean_drive``: the nearest
        instance found is visited first) with a quarter turn if it drives, and the images that
        volume needs for an instance of mid-range size."""
        tm = ctx.time_model
        typ = ctx.catalog.type(via)
        size = tuple((np.asarray(typ.size_min) + np.asarray(typ.size_max)) / 2)
        mid = ObjectInstance(via, -1, (0.0, 0.0, size[2] / 2), 0.0, size)
        best = max(typ.relations, key=lambda r: (probs.p(r.name, ctx.target), r.name))
        costs = ss.CostModel(ctx.grid, tm, view_distance=ctx.target_range)
        images = costs.images(relation_volume(best, mid))
        return tm.leg_estimate(0.5 * mean_drive) + tm.looks_estimate(images, costs.head_s)


# indirect search by scenario: online where the map is the robot's own (built, remembered)
_INDIRECT = {
    MapMode.BUILT: IndirectOnline,
    MapMode.GIVEN: IndirectPlanned,
    MapMode.REMEMBERED: IndirectOnline,
}
# The algorithm behind each policy name, by scenario (the oracle: agent.search.oracle.Oracle,
# built by the episode runner with what it reads of the truth).
_CLASSES: dict[str, type[SearchPolicy] | dict[MapMode, type[SearchPolicy]]] = {
    "frontier": Online,
    "map-only": MapOnly,
    "exhaustive": Exhaustive,
    "uniform": Online,
    "memory": Online,
    "location": Location,
    "memory-location": Location,
    "oracle-prior": Location,
    "oracle-memory": Location,
    "indirect": _INDIRECT,
    "oracle-prior-indirect": _INDIRECT,
    "bound-rooms": Online,
    "bound-target-room": Online,
    "bound-plan": Location,
}


def make_policy(spec: PolicySpec) -> SearchPolicy:
    """Policy ``spec`` as it runs in its scenario, named as the run names it; a one-line error
    for the oracle (which the runner builds)."""
    cls = _CLASSES.get(spec.base)
    if cls is None:
        raise CtxsearchError(f"policy '{spec.base}' reads the truth: the episode runner builds it")
    return (cls[spec.scenario] if isinstance(cls, dict) else cls)(spec.name)
