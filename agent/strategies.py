"""Which object to examine next: Figure 2, lines 8-13, behind one small interface.

A strategy looks at the UNEXAMINED objects grouped by type (line 8), scores every candidate type
and picks one (lines 9-12); the object of that type is then the nearest one (line 13, shared by
every strategy). Adding a strategy is one small class with a ``name`` and ``choose_type`` plus an
entry in ``STRATEGIES``.

- ``hif``: the paper, exactly: d_A = average impact(y_rel,t, n_A) over rel in RELATIONS(A) and
  t in TYPES (eq. 3), the largest wins, ties to the type first in the catalog. The quirks of eq. 3
  are kept: impact(0, n) is not monotonic in n (0.270, 0.155, 0.101, 0.112, ... for n = 0, 1,
  2, 3 at alpha = 0.10), and a success after many failures widens the interval.
- ``expected-hif``: the same average of ``intervals.expected_width_change`` (each outcome of the
  next trial weighted by its estimated probability), which removes those quirks.
- ``cost-hif``: impact per simulated second of travel and gazes to examine the nearest object of
  the type (the paper's footnote 4).
- ``hif-backoff``: HIF on what the robot would learn with the type hierarchy's backoff
  (knowledge.pooling): a type's impact is the average over (rel, t) of impact(y + kappa p_C,
  n + kappa), what one more examination would change in the *backed-off* interval (kappa and
  p_C, its class's pseudo-examinations, held fixed). A never-examined type of a class that is
  known already starts from kappa pseudo-examinations, so it is less urgent than one of a class
  never seen; types in no class, and relations mapping onto nothing, score as in ``hif``.
- ``random``, ``round-robin`` (over types, in catalog order), ``nearest`` (least travel),
  ``fewest`` (smallest n): baselines.

Every strategy is deterministic given its inputs and the ``rng`` it is handed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np

from ctxsearch.envs.robot_spec import RobotPose, TimeModel
from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.pooling import Backoff, PooledCounts

Candidates = Mapping[str, Sequence[ObjectInstance]]


class Costs(Protocol):
    """Simulated-time estimates the loop hands to strategies (the camera and oracle modes plan
    them the same way, so the numbers are comparable)."""

    def travel_s(self, obj: ObjectInstance) -> float:
        """Seconds to drive from the robot's current pose to where ``obj`` is examined from."""
        ...

    def examine_s(self, obj: ObjectInstance) -> float:
        """Seconds of travel, head moves and images to examine ``obj`` from the current pose."""
        ...


@dataclass
class EuclideanCosts:
    """Costs without a map: straight-line travel at the drive speed, plus a fixed gaze budget."""

    pose: RobotPose
    time_model: TimeModel = TimeModel()
    gazes_per_exam: float = 2.0  # images per examination assumed by the estimate
    standoff: float = 1.0  # m kept from an object's centre when examining it

    def travel_s(self, obj: ObjectInstance) -> float:
        """Straight-line distance to a point ``standoff`` short of the object, over drive speed."""
        dist = math.hypot(obj.position[0] - self.pose.x, obj.position[1] - self.pose.y)
        return self.time_model.travel_time(max(0.0, dist - self.standoff))

    def examine_s(self, obj: ObjectInstance) -> float:
        """travel_s plus ``gazes_per_exam`` images and half-turn head moves."""
        head_s = 0.5 / self.time_model.pan_rate
        return self.travel_s(obj) + self.time_model.looks_estimate(self.gazes_per_exam, head_s)


class Strategy(Protocol):
    """Lines 9-12 of Figure 2: pick the type to examine among the candidate types."""

    name: str

    def choose_type(
        self,
        kb: KnowledgeBase,
        candidates: Candidates,
        robot_pose: RobotPose,
        costs: Costs,
        rng: np.random.Generator,
    ) -> tuple[str, dict[str, float]]:
        """The chosen type and every candidate type's score (larger is better)."""
        ...

    def observe(self, type_name: str) -> None:
        """Told the type of every examination made, in order (round-robin keeps its place)."""
        ...


def _catalog_order(kb: KnowledgeBase, types) -> list[str]:
    order = {name: i for i, name in enumerate(kb.catalog.type_names)}
    return sorted(set(types), key=lambda t: order[t])


def _argmax(scores: dict[str, float], order: list[str]) -> str:
    """The best-scoring type; ties go to the one first in ``order`` (catalog order)."""
    best = order[0]
    for t in order[1:]:
        if scores[t] > scores[best]:
            best = t
    return best


def nearest_object(objs: Sequence[ObjectInstance], costs: Costs) -> ObjectInstance:
    """Figure 2, line 13: the object with the least travel; ties to the smallest id."""
    return min(objs, key=lambda o: (costs.travel_s(o), o.id))


class _Stateless:
    def observe(self, type_name: str) -> None:  # noqa: D401 - nothing to remember
        """Nothing to remember."""


class HighestImpactFirst(_Stateless):
    """The paper's HIF (Figure 2, lines 9-12, eq. 3), quirks included."""

    name: ClassVar[str] = "hif"
    score_fn: ClassVar[Callable] = staticmethod(intervals.impact)

    def choose_type(self, kb, candidates, robot_pose, costs, rng):
        """The candidate type with the largest average impact; ties to catalog order."""
        order = _catalog_order(kb, candidates)
        scores = {t: kb.type_score(t, self.score_fn) for t in order}
        return _argmax(scores, order), scores


class ExpectedHIF(HighestImpactFirst):
    """HIF with the expected (not the largest) change in width: no quirks of eq. 3."""

    name: ClassVar[str] = "expected-hif"
    score_fn: ClassVar[Callable] = staticmethod(intervals.expected_width_change)


class BackoffHIF(_Stateless):
    """HIF on the backed-off pseudo-counts (see the module docstring): ``hif`` unchanged where
    the hierarchy says nothing."""

    name: ClassVar[str] = "hif-backoff"

    def choose_type(self, kb, candidates, robot_pose, costs, rng):
        """The candidate type with the largest average impact on its backed-off counts."""
        order = _catalog_order(kb, candidates)
        backoff = Backoff(PooledCounts.from_knowledge_base(kb), kb.alpha)
        scores = {t: self.type_score(kb, backoff, t) for t in order}
        return _argmax(scores, order), scores

    @staticmethod
    def type_score(kb: KnowledgeBase, backoff: Backoff, ref_type: str) -> float:
        """Mean over rel in RELATIONS(A), t in TYPES of impact(y_eff, n_eff)."""
        cat = kb.catalog
        ys, ns = [], []
        for rel in cat.type(ref_type).relation_names:
            for t in cat.type_names:
                y_eff, n_eff, _, _ = backoff.pseudo_counts(ref_type, rel, t)
                ys.append(y_eff)
                ns.append(n_eff)
        if not ys:
            return 0.0
        return float(np.mean(intervals.impact(np.array(ys), np.array(ns), kb.alpha)))


class CostHIF(_Stateless):
    """Impact per simulated second to examine the nearest object of the type (footnote 4)."""

    name: ClassVar[str] = "cost-hif"
    min_seconds: ClassVar[float] = 0.1  # guards the division when the robot is already there

    def choose_type(self, kb, candidates, robot_pose, costs, rng):
        """argmax over types of impact(A) / examine_s(nearest object of A)."""
        order = _catalog_order(kb, candidates)
        scores = {}
        for t in order:
            obj = nearest_object(candidates[t], costs)
            scores[t] = kb.type_impact(t) / max(costs.examine_s(obj), self.min_seconds)
        return _argmax(scores, order), scores


class RandomChoice(_Stateless):
    """A type drawn uniformly from the candidate types with the run's rng."""

    name: ClassVar[str] = "random"

    def choose_type(self, kb, candidates, robot_pose, costs, rng):
        """Uniform over the candidate types (catalog order, so the draw is reproducible)."""
        order = _catalog_order(kb, candidates)
        pick = order[int(rng.integers(len(order)))]
        return pick, {t: float(t == pick) for t in order}


class RoundRobin:
    """Cycle through the types in catalog order: the next candidate type after the last examined."""

    name: ClassVar[str] = "round-robin"

    def __init__(self) -> None:
        self.last: str | None = None

    def observe(self, type_name: str) -> None:
        """Remember the type last examined."""
        self.last = type_name

    def choose_type(self, kb, candidates, robot_pose, costs, rng):
        """The first candidate type after ``last`` in cyclic catalog order."""
        names = kb.catalog.type_names
        T = len(names)
        start = names.index(self.last) + 1 if self.last in names else 0
        order = _catalog_order(kb, candidates)
        # score: how soon the type's turn comes (larger = sooner)
        scores = {t: float(T - (names.index(t) - start) % T) for t in order}
        return _argmax(scores, order), scores


class Nearest(_Stateless):
    """The type whose nearest unexamined object is the least travel away."""

    name: ClassVar[str] = "nearest"

    def choose_type(self, kb, candidates, robot_pose, costs, rng):
        """argmin over types of the travel seconds to the type's nearest object."""
        order = _catalog_order(kb, candidates)
        scores = {t: -min(costs.travel_s(o) for o in candidates[t]) for t in order}
        return _argmax(scores, order), scores


class Fewest(_Stateless):
    """The type examined least often so far (smallest n)."""

    name: ClassVar[str] = "fewest"

    def choose_type(self, kb, candidates, robot_pose, costs, rng):
        """argmin over types of n; ties to catalog order."""
        order = _catalog_order(kb, candidates)
        scores = {t: -float(kb.n(t)) for t in order}
        return _argmax(scores, order), scores


STRATEGIES: dict[str, type] = {
    cls.name: cls
    for cls in (
        HighestImpactFirst,
        RandomChoice,
        RoundRobin,
        Nearest,
        Fewest,
        ExpectedHIF,
        CostHIF,
        BackoffHIF,
    )
}


def make_strategy(name: str) -> Strategy:
    """A fresh strategy by name; a one-line CtxsearchError listing the known names otherwise."""
    try:
        return STRATEGIES[name]()
    except KeyError:
        raise CtxsearchError(
            f"unknown strategy '{name}' (known: {', '.join(STRATEGIES)})"
        ) from None


@dataclass(frozen=True)
class Choice:
    """One decision of lines 8-13: the chosen type and object, and every candidate type's score."""

    type: str
    obj: ObjectInstance
    scores: dict[str, float]


def choose(
    strategy: Strategy,
    kb: KnowledgeBase,
    unexamined: Sequence[ObjectInstance],
    robot_pose: RobotPose,
    costs: Costs | None,
    rng: np.random.Generator,
) -> Choice:
    """Figure 2, lines 8-13: group UNEXAMINED by type, let the strategy pick a type, then take the
    nearest object of that type."""
    if not unexamined:
        raise CtxsearchError("nothing to choose from: UNEXAMINED is empty")
    costs = costs if costs is not None else EuclideanCosts(robot_pose)
    candidates: dict[str, list[ObjectInstance]] = {}
    for o in unexamined:
        candidates.setdefault(o.type, []).append(o)
    t, scores = strategy.choose_type(kb, candidates, robot_pose, costs, rng)
    return Choice(t, nearest_object(candidates[t], costs), scores)
