"""The online decision, on the robot's own map and on a given one: at each step the most belief
mass found per expected second among (a) looking into a relation volume of a known object (the
furniture map given, or what was detected so far), (b) sweeping for an intermediate type I that
Wixson & Ballard's efficiency model says pays (agent.search.viewpoints.predicted_plan), valued as
P(a new I is seen there) q_I and given up after the model's expected seconds to find one, and (c)
sweeping from the viewpoint that finds the most mass per second (agent.search.frontier).

All of them are valued in one currency, the belief of agent.search.belief: the prior density
(``space.target_density``: the known objects' relation volumes spread their P(rel(T)) over their
points, the unexplored rest gets the surveyed part's mean density; every point alike without
knowledge: ``frontier`` and ``uniform``, the fair twins) times the miss field (what every image
so far would have missed of a target there, by the detector's recall at that distance). A
volume's value is its mass times the probability that the planned gazes find it; a sweep's is
the mass times P(found) at each point's distance. No point is ever done: a distant glance
leaves most of a volume's mass, so the robot goes close. The search stops before its budget
only when less than ``belief.stop_mass`` (agent.search.config) of the detectable mass is left, or when no option is
left after mapping the floor around (``Explorer.unstick``); the share left is reported.

The options' seconds come from different estimates (a sweep's drive and images, a volume's
planned gazes, the efficiency model's look), which err differently: each kind's expected seconds
are scaled by the ratio of the seconds its actions took so far in this episode to the seconds
they were expected to take (``online.calibration_prior_s`` of prior weight at ratio 1). The robot
corrects its own estimates; nothing is fitted offline.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ctxsearch.agent.search import belief
from ctxsearch.agent.search import regions as rg
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search import viewpoints as sx
from ctxsearch.agent.search.context import (
    BELIEF_ENTITY,
    BEYOND_ENTITY,
    FRONTIER_ENTITY,
    SearchContext,
)
from ctxsearch.agent.search.coverage import FURNITURE_TILTS
from ctxsearch.agent.search.frontier import Explorer
from ctxsearch.agent.search.memory import memory_prior
from ctxsearch.agent.search.room_prior import Beyond, RoomPrior
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.options import MapMode


@dataclass(frozen=True)
class ViaOption:
    """An intermediate type worth searching for (Wixson & Ballard's model says it pays): its
    q = P(T related to one found), expected instances per world, the height it is found up to,
    the seconds to look into its best relation volume, and the model's predicted gain; and the
    model's expected seconds to find one (half a coverage at its range): the online search stops
    looking for it once it has spent that long on it (the model's expectation) without
    finding one: a world that held the expected instances would most likely have shown one."""

    type: str
    q: float
    instances: float
    zmax: float
    look_s: float
    gain: float
    find_s: float = math.inf


@dataclass(frozen=True)
class Option:
    """One thing the online search may do next: its probability of finding the target per
    expected second, a label for the log, the action, its kind (calibrated apart: ``region``,
    ``explore``, ``via``) and its expected seconds; where it starts and where it leaves the
    robot (base positions, for the look-ahead)."""

    rate: float
    label: str
    act: Callable[[], None]
    kind: str
    seconds: float
    start: tuple[float, float] | None = None
    end: tuple[float, float] | None = None
    finds: tuple[np.ndarray, np.ndarray] | None = None  # (belief points, P(found) of each)

    @property
    def found(self) -> float:
        """The probability it finds the target (its rate times its expected seconds)."""
        return self.rate * self.seconds


@dataclass(frozen=True)
class Belief:
    """Where the target may be: the candidate regions not looked into yet, the probability per
    seen-map point given every image so far (agent.search.belief; None: no point left), the
    prior density's total over the points left times their miss (P(rel(T)) units), and the
    detectable mass left (``belief.mass_left``)."""

    regions: list[ss.Region]
    weights: np.ndarray | None
    mass: float
    left: float = 1.0


class OnlineSearch:
    """One episode's online decision for ``ctx`` with knowledge ``probs`` (None: no context, the
    ``frontier`` policy) and intermediate types ``vias``. At each decision, before the chosen
    option acts, the context's ``observer`` (if any) is called with the search, the belief the
    options were valued on and the chosen option: a read-only hook for diagnostics."""

    def __init__(
        self,
        ctx: SearchContext,
        probs: ss.ProbabilitySource | None,
        vias: Sequence[ViaOption] = (),
    ):
        self.ctx, self.probs, self.vias = ctx, probs, list(vias)
        self.settings = ctx.config.online  # look-ahead, calibration
        self.stop_mass = ctx.config.belief.stop_mass
        self.explorer = Explorer(ctx)
        self.builder = ss.RegionBuilder(ctx.catalog, probs, ctx.seen, ctx.target) if probs else None
        # room context, where the knowledge source has it (agent.search.room_prior)
        know = ctx.config.knowledge
        self.rooms = RoomPrior.for_search(
            probs, ctx.target, ctx.catalog, ctx.seen.points, ctx.maps.plan_rooms,
            Beyond(know.next_room_m, know.glimpse_m) if know.next_rooms else None,
        )  # fmt: skip
        # a bound's room knowledge, handed at the start (agent.search.room_prior.HandedRooms)
        handed = ctx.maps.handed
        self.handed = handed.factor(ctx.seen.points) if handed is not None else None
        # the remembered map's last sightings of the target (agent.search.memory)
        self.sightings = memory_prior(
            ctx.maps.home, ctx.target, ctx.episode.day, ctx.persistence, ctx.seen
        )
        for line in self.sightings.describe() if self.sightings else ():
            ctx.note(line)
        self.gains = {v.type: v.gain for v in self.vias}
        self.via_spent: dict[str, float] = {}  # seconds spent looking for each intermediate type
        # the total a whole world is expected to hold (P(rel(T)) units), or 1
        prior = ss.expected_mass(ctx.catalog, probs, ctx.target) if probs else None
        self.prior = prior or 1.0
        self.took: dict[str, list[float]] = {}  # kind: [expected, measured] seconds so far
        self.sight = [0.0, 0.0]  # the direct viewpoints' shares so far: [traced, nothing hidden]

    def run(self) -> None:
        """Look around (on the built map only: its first images map the floor; a remembered map
        knows its floor, as a given one does), then take the best
        option until none is left or the belief's detectable mass left is below the configured
        ``belief.stop_mass``; the share left is the context's ``mass_left``. On a given map a
        sweep where the robot stands is one of the options, taken when it is worth its seconds."""
        ctx = self.ctx
        first = self.belief()
        self.record(first)
        if ctx.maps.map is MapMode.BUILT:  # a map from nothing starts from the floor it sees
            self.explorer.look_around(first.weights)
        while True:
            ctx.check()
            b = self.belief()
            ctx.mass_left = b.left
            self.record(b)
            if b.left < self.stop_mass:
                ctx.note(f"{100 * b.left:.1f}% of the detectable mass left: stop")
                return
            options = self.region_options(b)
            options += [o for o in [self.direct_option(b.weights)] if o]
            options += [o for o in [self.beyond_option(b.weights)] if o]
            options += [o for o in (self.via_option(v, b.mass) for v in self.vias) if o]
            if not options:
                if self.explorer.unstick():
                    ctx.note("no viewpoint reachable: mapped the floor around")
                    continue
                ctx.note(f"no option left with {100 * b.left:.1f}% of the detectable mass")
                return
            best, then = self.choose(options, b.weights)
            f = self.scale(best.kind)
            ahead = f"; then {then.label}" if then is not None else ""
            ctx.note(
                f"{best.label} ({best.rate / f:.4f}/s, time x{f:.2f}; {len(options)} options{ahead})"
            )
            if ctx.observer is not None:
                ctx.observer(self, b, best)
            t0 = ctx.elapsed
            best.act()
            sums = self.took.setdefault(best.kind, [0.0, 0.0])
            sums[0] += best.seconds
            sums[1] += ctx.elapsed - t0

    def choose(
        self, options: Sequence[Option], weights: np.ndarray | None = None
    ) -> tuple[Option, Option | None]:
        """The option to take now, and the one the plan takes after it (None: none); ``weights``:
        the belief the options were valued on.

        Without ``online.lookahead``: the most probability per expected second (calibrated). With it, a
        two-step look-ahead (a close look costs a drive first, which greedy choice weighs
        against the look alone): option a followed by option b finds the target with
        probability m_a + m_b in expected seconds
        t_a + (1 - m_a) t_b|a, where t_b|a is b's seconds with its drive from where a leaves
        the robot instead of from here (straight lines at the drive speed, the difference added
        to b's own estimate), and m_b what b would find of the mass a leaves: its points'
        belief times P(b finds them) times (1 - P(a finds them)), a share of b's own (a
        detour, which looks for another type, overlaps nothing). Each a is worth its best plan,
        a alone or a then some b, per second; the best a is taken and the next step decided
        again (receding horizon)."""
        if not self.settings.lookahead or len(options) < 2:
            best = max(options, key=lambda o: o.rate / self.scale(o.kind))
            return best, None
        here = self.ctx.body.pose().xy
        speed = self.ctx.time_model.drive_speed
        secs = [o.seconds * self.scale(o.kind) for o in options]
        found = [min(max(o.found, 0.0), 1.0) for o in options]
        away = [_dist(here, o.start) for o in options]
        plans = []
        for i, a in enumerate(options):
            value, then = found[i] / max(secs[i], 1e-6), None
            for j, b in enumerate(options):
                if j == i:
                    continue
                t_b = max(secs[j] + (_dist(a.end, b.start) - away[j]) / speed, 1e-6)
                m_b = found[j] * _left_after(a.finds, b.finds, weights)
                v = (found[i] + m_b) / max(secs[i] + (1.0 - found[i]) * t_b, 1e-6)
                if v > value:
                    value, then = v, b
            plans.append((value, -i, a, then))
        _, _, best, then = max(plans, key=lambda p: (p[0], p[1]))
        return best, then

    def record(self, b: Belief) -> None:
        """The belief on the recording's floor (agent.search.belief.log_belief)."""
        rec = self.ctx.recorder
        if rec.enabled:
            rec.set_time(self.ctx.elapsed)
            belief.log_belief(rec, self.ctx.seen.points, b.weights, BELIEF_ENTITY)
            rec.log_scalar(f"search/mass_left/{self.ctx.policy}", b.left)
            groups = self.rooms.beyond_groups(b.weights) if self.rooms else []
            if groups:  # the mass expected beyond each mapped room (agent.search.room_prior)
                rec.log_points(
                    BEYOND_ENTITY,
                    np.array([c for _, c, _ in groups]),
                    np.tile([0.9, 0.4, 0.9], (len(groups), 1)),
                    np.array([0.05 + 0.25 * np.sqrt(m) for _, _, m in groups]),
                    labels=[f"beyond room {r}: {m:.2f}" for r, _, m in groups],
                )
                rec.log_scalar(
                    f"search/beyond_mass/{self.ctx.policy}", sum(m for _, _, m in groups)
                )

    def scale(self, kind: str) -> float:
        """The calibration of ``kind``'s expected seconds: measured over expected so far, starting
        at 1 with ``online.calibration_prior_s`` expected seconds of weight (after that much of
        a kind was done, its measured ratio weighs as much as the prior)."""
        exp_s, got_s = self.took.get(kind, (0.0, 0.0))
        w = self.settings.calibration_prior_s
        return (got_s + w) / (exp_s + w)

    def belief(self) -> Belief:
        """Where the target may be (``Belief``): the prior (the known objects' relation volumes
        with this search's P(rel(T)), ``space.target_density``; every point alike without
        knowledge or before a known volume has any; times the room factor where the knowledge
        has room context; mixed with the remembered sightings of the target where the policy
        has memory, agent.search.memory) times the miss field, normalised over the points still
        worth a look (agent.search.belief)."""
        ctx = self.ctx
        todo = self.explorer.target_todo()
        keep = ~self.explorer.given_up()
        regions: list[ss.Region] = []
        dens = None
        stand = ctx.seen.standable()
        if self.builder is not None:
            every = self.builder.regions(self.known_objects())
            skip = ctx.looked_into | ctx.waiting
            regions = [r for r in every if r.key not in skip]
            dens = ss.target_density(every, ~ctx.seen.unseen(ctx.sight_cap), stand)
        prior = stand if dens is None else dens
        f = self.rooms.factor(self.known_objects(), ctx.built) if self.rooms else None
        if f is not None:  # the rooms of known furniture (agent.search.room_prior)
            prior = prior * f
        if self.handed is not None:  # a bound's rooms, handed (agent.search.room_prior)
            prior = prior * self.handed
        if self.sightings:  # the last sightings first (agent.search.memory)
            prior = self.sightings.prior(prior, stand)
            regions += self.sightings.regions(ctx.looked_into | ctx.waiting)
        miss = ctx.misses.miss
        weights = belief.belief_weights(prior, miss, todo)
        ctx.belief_now = lambda: belief.belief_weights(prior, ctx.misses.miss, todo)
        left = belief.mass_left(prior, miss, keep)
        mass = self.prior if dens is None else float((dens * miss)[todo].sum())
        return Belief(regions, weights, mass, left)

    def known_objects(self) -> list[ObjectInstance]:
        """The objects whose relation volumes hold the prior: the furniture map given (none on
        the built map) and everything detected so far."""
        objs = {o.id: o for o in self.ctx.furniture_map()}
        objs.update(self.ctx.known)
        return list(objs.values())

    def direct_option(self, weights: np.ndarray | None) -> Option | None:
        """Sweep the viewpoint that finds the most belief mass per second."""
        ctx, ex = self.ctx, self.explorer
        if weights is None:
            return None
        v = ex.target_viewpoint(weights)
        if v is None:
            return None
        if self.settings.beyond:  # how much of what lies in range the map lets a sweep see
            self.sight[0] += v.share
            self.sight[1] += ex.scorer().open_share(
                v.xy, ex.target_todo(), ex.target_sight(), weights
            )
        label = (
            f"explore for {ctx.target} at ({v.xy[0]:.1f}, {v.xy[1]:.1f}): "
            f"P(find)={v.share:.3f}, ~{v.seconds:.0f} s"
        )
        at = (float(v.xy[0]), float(v.xy[1]))
        act = lambda: ex.explore_target(v, weights)  # noqa: E731
        finds = None
        if self.settings.lookahead:
            finds = ex.scorer().sweep_finds(v.xy, ex.target_sight(), ex.target_todo())
        return Option(v.rate, label, act, "explore", v.seconds, at, at, finds)

    def beyond_option(self, weights: np.ndarray | None) -> Option | None:
        """With ``online.beyond``, on the robot's own map: go toward the best place beyond the
        frontier (``Explorer.beyond_viewpoint``), valued by what a sweep there would find per
        second of the whole way there, times the share of what lay in range that the direct
        viewpoints' sweeps could see so far (their traced shares over their shares with nothing
        hidden: the unknown space hides nothing in the estimate, the robot's experience of its
        map says how much is hidden; 1 before any); the act is its first leg, the drive to
        where the way leaves the map and images of the unknown floor around
        (``Explorer.advance``), whose expected seconds calibrate the ``beyond`` kind."""
        ctx, ex = self.ctx, self.explorer
        if not self.settings.beyond or weights is None or ctx.maps.map is not MapMode.BUILT:
            return None
        got = ex.beyond_viewpoint(weights)
        if got is None:
            return None
        v = got.via
        seen = self.sight[0] / self.sight[1] if self.sight[1] > 0.0 else 1.0
        label = (
            f"toward ({got.goal[0]:.1f}, {got.goal[1]:.1f}) beyond the frontier, via "
            f"({v.xy[0]:.1f}, {v.xy[1]:.1f}): P(find there)={got.share:.3f} x{seen:.2f} seen"
        )
        rec = ctx.recorder
        if rec.enabled:
            rec.set_time(ctx.elapsed)
            rec.log_points(
                FRONTIER_ENTITY,
                np.array([[*got.goal, 0.05], [*v.xy, 0.05]]),
                np.array([[0.2, 0.8, 0.9], [0.2, 0.5, 0.9]]),
                np.array([0.05 + 0.25 * np.sqrt(got.share), 0.08]),
                labels=[f"beyond the frontier: {got.share:.2f}", "where the way leaves the map"],
            )
        at = (float(v.xy[0]), float(v.xy[1]))
        act = lambda: ex.advance(v)  # noqa: E731
        return Option(got.rate * seen, label, act, "beyond", got.first_s, at, at)

    def via_option(self, via: ViaOption, mass: float = 1.0) -> Option | None:
        """Sweep for intermediate type ``via`` where a new one is most likely seen per second."""
        ctx, ex = self.ctx, self.explorer
        found = ctx.found_of(via.type)
        left = 1.0 - math.exp(-max(0.0, via.instances - found))
        if left < 0.05 or self.via_spent.get(via.type, 0.0) >= via.find_s:
            return None
        rng = ctx.range_of(via.type)
        v = ex.viewpoint(rng, sx.RING_IMAGES, via.zmax)
        if v is None:
            return None
        m = left * min(1.0, v.share * max(1.0, via.instances - found))
        seconds = v.seconds + m * via.look_s
        rate = m * via.q / mass / seconds

        def act() -> None:
            if ctx.intermediate is None:
                ctx.intermediate, ctx.predicted_gain = via.type, via.gain
            t0 = ctx.elapsed
            try:
                ex.explore_step(
                    v, rng, FURNITURE_TILTS, f"find {via.type}",
                    until=lambda: ctx.found_of(via.type) > found,
                )  # fmt: skip
            finally:
                self.via_spent[via.type] = self.via_spent.get(via.type, 0.0) + (ctx.elapsed - t0)

        label = f"look for {via.type} at ({v.xy[0]:.1f}, {v.xy[1]:.1f})"
        at = (float(v.xy[0]), float(v.xy[1]))
        return Option(rate, label, act, "via", v.seconds, at, at)

    def region_options(self, belief: Belief) -> list[Option]:
        """Look into a candidate region of the belief, re-costed with planned gazes: the best
        one (greedy choice), or each one re-costed (``online.lookahead``: the plan may take another
        first)."""
        ctx = self.ctx
        if not belief.regions:
            return []
        ranked = ss.score_regions(
            belief.regions, ctx.seen, ctx.target_range, rg.cost_model(ctx), ctx.body.pose().xy,
            belief.weights,
        )  # fmt: skip
        ranked = [r for r in ranked if r.score >= rg.MIN_REGION_SCORE]
        if not ranked:
            return []
        rg.log_candidates(ctx, ranked)
        # The cost model's estimate ranks; the best few are re-costed with their planned gazes
        # (on a built map the drive around what is not mapped yet can be much longer).
        planned = []
        for r in ranked[: rg.REPLAN_REGIONS_BUILT]:
            gz = rg.region_gazes(ctx, r)
            if not gz:
                ctx.waiting.add(r.key)
                continue
            cost = rg.planned_seconds(ctx, gz)
            finds = self.gazes_find(r, gz)
            if belief.weights is not None:
                r.score = float((belief.weights[finds[0]] * finds[1]).sum())
            planned.append((r.score / max(cost, 1e-6), cost, r, gz, finds))
        if not self.settings.lookahead and planned:
            planned = [max(planned, key=lambda x: (x[0], -x[1]))]
        return [self._region(*p) for p in planned]

    def _region(self, rate, cost, region: ss.Region, gazes: Sequence, finds) -> Option:
        label = f"look into {region.label}: P={region.score:.2f}, ~{cost:.1f} s"
        start, end = gazes[0].pose, gazes[-1].pose
        ctx = self.ctx

        def act() -> None:
            rg.look_region(ctx, region, gazes, self.gains)

        start_xy, end_xy = (start.x, start.y), (end.x, end.y)
        return Option(rate, label, act, "region", cost, start_xy, end_xy, finds)

    def gazes_find(self, region: ss.Region, gazes: Sequence) -> tuple[np.ndarray, np.ndarray]:
        """(the region's points, the probability a confirmed detection from the planned
        ``gazes``' camera positions finds a target at each: ``belief.gazes_found``); the belief
        mass they are expected to find is the points' mass times these."""
        ctx = self.ctx
        cams = np.array([[g.pose.x, g.pose.y, ctx.spec.camera_height] for g in gazes])
        pts = np.asarray(region.points)
        return pts, belief.gazes_found(ctx.curve, cams, ctx.seen.points[pts])


def _dist(p, q) -> float:
    """The straight line between two base positions (0 if either is unknown)."""
    return 0.0 if p is None or q is None else float(math.hypot(p[0] - q[0], p[1] - q[1]))


def _left_after(first, then, weights: np.ndarray | None) -> float:
    """The share of what ``then`` (points, P(found)) would find that ``first`` leaves: 1 where
    either states no points (a detour) or there is no belief."""
    if first is None or then is None or weights is None:
        return 1.0
    (ia, pa), (ib, pb) = first, then
    alone = weights[ib] * pb
    total = float(alone.sum())
    if total <= 0.0:
        return 1.0
    miss_a = np.ones(len(weights))
    miss_a[ia] = 1.0 - pa
    return float((alone * miss_a[ib]).sum()) / total
