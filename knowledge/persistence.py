"""Object persistence as the paper's intervals: P(STILL-WHERE-SEEN(T) after d days).

A relation like any other, with the last sighting as its reference: an instance of T seen at a
place on one day is "still where seen" on a later day when an instance of T stands within
``RADIUS_M`` of that place (the detector's pose noise and a nudge aside, not a move). The trials
are the robot's own: a visit that looks again at the place of a small object an earlier day's
map remembers makes one ``PersistenceCheck`` (knowledge.home_map) per such place, kept in that
visit's map, so the store counts each once (one map per visit, the first kept) and a visit
interrupted before its end counts none.

A check is not a plain Bernoulli trial: the detector misses. Its images would have reported an
instance standing there with probability ``recall`` (one minus the product of each image's miss
at its distance, by the detector's recall curve the robot knows), and report one that is not
there with ``false_rate`` (taken as 0: a false report of T lands within half a metre of the
place with negligible probability; look-alikes are not modelled). So a check reports "still"
with probability theta recall (1 - f) + f, and the interval is the score interval of that
likelihood (knowledge.corrected.score_intervals: with recall 1 and f 0, Wilson's interval, eq.
1-2), one per (type, days since the sighting), at the store's alpha. Checks are not clustered
by house (a house's books stay or go independently day to day in the world model).

The estimate for a sighting ``d`` days old is that of its own age where the robot has made such
checks, else the one-day estimate to the power d (a day-to-day Markov chain: each day an
instance stays or moves independently, as the simulated homes do, envs.rooms), else nothing
known (the interval [0, 1], its midpoint 1/2).

``TruePersistence`` is a one-day probability per type to the power d: the bound arm's, the true
share of places where an instance stood that hold one the next day (agent.search.priors
.true_persistence).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.corrected import score_intervals
from ctxsearch.knowledge.home_map import PersistenceCheck

RADIUS_M = 0.5  # "still where seen": an instance of the type within this of the place (m)
STILL = "STILL-WHERE-SEEN"  # the relation's name in listings


class Persistence(Protocol):
    """P(an instance of a type seen ``age`` days ago is still where it was seen)."""

    def p(self, type_name: str, age: int) -> float: ...


@dataclass(frozen=True)
class PersistenceEstimate:
    """P(STILL-WHERE-SEEN(type) after ``age`` days): the interval, its point estimate (the
    interval's midpoint, as Wilson's p0), the checks, those that reported it still there, and
    the expected recall they summed to (the evidence the checks carry)."""

    type: str
    age: int
    low: float
    high: float
    p: float
    checks: int
    still: int
    information: float

    def line(self) -> str:
        """One listing line: ``STILL-WHERE-SEEN(Cup) after 1 day: [0.10, 0.31] ...``."""
        days = "day" if self.age == 1 else "days"
        return (
            f"{STILL}({self.type}) after {self.age} {days}: [{self.low:.3f}, {self.high:.3f}] "
            f"p0={self.p:.3f}  ({self.still} of {self.checks} checks still, expected recall "
            f"{self.information:.1f})"
        )


def estimates(
    checks: Iterable[PersistenceCheck], alpha: float = intervals.DEFAULT_ALPHA
) -> dict[tuple[str, int], PersistenceEstimate]:
    """One estimate per (type, age) of ``checks`` (module docstring), sorted by key."""
    groups: dict[tuple[str, int], list[PersistenceCheck]] = {}
    for c in checks:
        groups.setdefault((c.type, int(c.age)), []).append(c)
    out = {}
    for key in sorted(groups):
        g = groups[key]
        y = np.array([[float(c.still)] for c in g])
        q = np.array([[c.recall] for c in g])
        f = np.array([[c.false_rate] for c in g])
        low, high, _theta, info = score_intervals(y, q, f, alpha)
        lo, hi = float(low[0]), float(high[0])
        out[key] = PersistenceEstimate(
            key[0], key[1], lo, hi, (lo + hi) / 2, len(g), sum(c.still for c in g), float(info[0])
        )
    return out


class LearnedPersistence:
    """The robot's persistence estimates (module docstring): ``p(type, age)``."""

    def __init__(self, checks: Iterable[PersistenceCheck], alpha: float = intervals.DEFAULT_ALPHA):
        self.table = estimates(checks, alpha)

    def estimate(self, type_name: str, age: int) -> PersistenceEstimate | None:
        """The estimate of ``type_name`` at exactly ``age`` days, if any check was made."""
        return self.table.get((type_name, int(age)))

    def p(self, type_name: str, age: int) -> float:
        """P(an instance of ``type_name`` seen ``age`` >= 1 days ago is still where seen):
        the estimate of that age, the one-day estimate to the power ``age``, or 1/2 (age 0:
        seen today, 1)."""
        if age <= 0:
            return 1.0
        e = self.estimate(type_name, age)
        if e is not None and e.information > 0:
            return e.p
        one = self.estimate(type_name, 1)
        if one is not None and one.information > 0:
            return one.p**age
        return 0.5

    def types(self) -> list[str]:
        """The types with at least one check."""
        return sorted({t for t, _ in self.table})

    def of_type(self, type_name: str) -> list[PersistenceEstimate]:
        """The estimates of ``type_name``, by age."""
        return [e for (t, _a), e in self.table.items() if t == type_name]


class TruePersistence:
    """A known one-day persistence (module docstring): ``stay(type)`` to the power ``age``."""

    def __init__(self, stay: Callable[[str], float]):
        self.stay = stay

    def p(self, type_name: str, age: int) -> float:
        """P(still where seen after ``age`` days)."""
        return 1.0 if age <= 0 else float(self.stay(type_name)) ** int(age)


def store_checks(store, style: str | None = None) -> list[PersistenceCheck]:
    """Every persistence check kept in ``store``'s remembered maps (of worlds of ``style``, or
    all), in the maps' order (run, style, seed, day)."""
    out: list[PersistenceCheck] = []
    for run, st, seed, day in store.home_maps():
        if style is not None and st != style:
            continue
        m = store.home_map(st, seed, run=run, upto_day=day)
        if m is not None and m.day == day:
            out.extend(m.checks)
    return out


def store_persistence(store, style: str | None = None) -> LearnedPersistence:
    """The persistence learned in ``store`` (its alpha)."""
    return LearnedPersistence(store_checks(store, style), store.alpha)


def listing(estimates_: Sequence[PersistenceEstimate]) -> list[str]:
    """The lines ``kb show --type`` prints."""
    return [e.line() for e in estimates_]


def near_place(place: Sequence[float], objects: Iterable, type_name: str) -> bool:
    """Whether one of ``objects`` (ObjectInstances) of ``type_name`` stands within ``RADIUS_M``
    of ``place`` (x, y, z) on the floor plane and in height: the relation's test."""
    x, y, z = (float(v) for v in place)
    for o in objects:
        if o.type != type_name:
            continue
        ox, oy, oz = o.position
        if np.hypot(ox - x, oy - y) <= RADIUS_M and abs(oz - z) <= RADIUS_M:
            return True
    return False


def still_where_seen(before: Iterable, after: Sequence, type_name: str) -> bool:
    """Whether an instance of ``type_name`` among ``after`` (a later day's objects) stands where
    one of ``before`` (an earlier day's) stood: the truth of STILL-WHERE-SEEN for a query."""
    return any(near_place(o.position, after, type_name) for o in before if o.type == type_name)
