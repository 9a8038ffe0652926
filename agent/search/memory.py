"""Where did I see it last: the remembered map's last sightings of the target in the belief.

A robot that lives in a home remembers where it saw small objects (knowledge.home_map.HomeMap's
``small``: each with the day it was last seen). For a search on day t for type T, every
remembered sighting s of T (seen on day t_s) is a place where an instance may still stand, with
probability pi_s = P(STILL-WHERE-SEEN(T) after t - t_s days) from the policy's persistence
(knowledge.persistence: the robot's learned intervals, or the true worlds' for the bound).

The prior the online search ranks by (agent.search.online) is a density of instances of T, and
memory splits it in two:

    prior(x) = sum_s pi_s k_s(x) + (max(N - sum_s pi_s, 0) + ELSEWHERE) rel(x) / sum rel

where k_s spreads one instance over the lattice points within ``knowledge.persistence.RADIUS_M``
of s (on the floor plane, and within that height of it; by where an object can stand), N is the
number of instances of T the map remembers (at least 1), and rel the density the policy has
without memory (the relation volumes' P(rel(T)) and room context, or every point alike for the
memory-only arm). The instances the robot remembers are where it saw them with their
persistence; those that moved, plus ``ELSEWHERE`` of an instance (one it never saw: this
module's stated choice, not fitted), are where the relations put them. So a remembered monitor
that stays holds nearly all the mass at its place, a type of many instances that wander keeps
most of it where the relations put it, and after a look at a remembered place finds nothing the
miss field moves the mass to the rest, as it does everywhere. The split is this module's (the
paper has no persistence); the belief normalises the prior and treats "the target" as the first
instance found, as it does everywhere.

Each sighting is also a candidate region (``regions``: a box of the radius around it, its
probability pi_s), so the online decision can plan close gazes into it as it does into a relation
volume, valued by the belief mass its gazes find per expected second.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ctxsearch.agent.search import space as ss
from ctxsearch.knowledge.geometry import Box
from ctxsearch.knowledge.home_map import HomeMap, RememberedObject
from ctxsearch.knowledge.persistence import RADIUS_M, Persistence

LAST_SEEN = "LAST-SEEN"  # the members' relation name of a sighting's region
ELSEWHERE = 0.25  # instances of the type the robot never saw, in the prior (module docstring)


@dataclass(frozen=True)
class Sighting:
    """A remembered sighting of the target: the record, its age in days, its persistence and
    the lattice points of its place."""

    seen: RememberedObject
    age: int
    p: float
    points: np.ndarray

    @property
    def key(self) -> tuple[str, int]:
        """Its region's member: (LAST-SEEN, -1 - index) (never a detected object's id)."""
        return (LAST_SEEN, -1 - int(self.seen.id))


class MemoryPrior:
    """The last sightings of ``target`` on ``home`` for a search on ``day`` (module docstring)."""

    def __init__(
        self,
        home: HomeMap,
        target: str,
        day: int,
        persistence: Persistence,
        seen: ss.SeenMap,
        radius: float = RADIUS_M,
    ):
        self.radius = float(radius)
        pts = seen.points
        items = []
        for s in home.last_seen(target):
            age = max(0, int(day) - home.seen_day(s))
            p = float(np.clip(persistence.p(target, age), 0.0, 1.0))
            x, y, z = s.position
            near = np.hypot(pts[:, 0] - x, pts[:, 1] - y) <= self.radius
            near &= np.abs(pts[:, 2] - z) <= self.radius
            idx = np.flatnonzero(near)
            if p > 0 and len(idx):
                items.append(Sighting(s, age, p, idx))
        self.sightings: list[Sighting] = items
        self.remembered = max(1, len(home.last_seen(target)))  # N of the module docstring

    def __bool__(self) -> bool:
        return bool(self.sightings)

    def prior(self, rel: np.ndarray, stand: np.ndarray) -> np.ndarray:
        """The prior of the module docstring: ``rel`` (the lattice's density without memory)
        scaled to the instances not at remembered places, plus each sighting's persistence
        spread over its points by ``stand`` (where an object can stand)."""
        rel = np.asarray(rel, float)
        total = float(rel.sum())
        rest = max(self.remembered - sum(s.p for s in self.sightings), 0.0) + ELSEWHERE
        out = rest * rel / total if total > 0 else np.zeros(len(rel))
        for s in self.sightings:
            w = np.asarray(stand, float)[s.points]
            w = w / w.sum() if w.sum() > 0 else np.full(len(s.points), 1.0 / len(s.points))
            np.add.at(out, s.points, s.p * w)
        return out

    def regions(self, skip: set | frozenset = frozenset()) -> list[ss.Region]:
        """One candidate region per sighting not in ``skip`` (region keys looked into)."""
        out = []
        for s in self.sightings:
            region = ss.Region(
                Box(np.asarray(s.seen.position, float), 0.0, np.full(3, self.radius)),
                s.p, [s.key], s.points,
            )  # fmt: skip
            if region.key not in skip:
                out.append(region)
        return out

    def describe(self) -> list[str]:
        """One line per sighting, for the search's log."""
        return [
            f"last saw {s.seen.type} at ({s.seen.position[0]:.1f}, {s.seen.position[1]:.1f}, "
            f"{s.seen.position[2]:.1f}) {s.age} day(s) ago: P(still there) {s.p:.2f}"
            for s in self.sightings
        ]


def memory_prior(
    home: HomeMap | None,
    target: str,
    day: int,
    persistence: Persistence | None,
    seen: ss.SeenMap,
) -> MemoryPrior | None:
    """The memory of a search (None: no remembered map or no persistence: the policy has no
    memory, or no sighting of the target)."""
    if home is None or persistence is None:
        return None
    m = MemoryPrior(home, target, day, persistence, seen)
    return m if m else None
