"""The state a learning run carries from room to room, and the records its rooms produce.

Shared by the per-room procedure (agent.acquisition), its recording (agent.learn_log), resume
(agent.resume) and the multi-room run (agent.learning), so none of them imports another.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ctxsearch.agent.interfaces import Perception
from ctxsearch.agent.perception_modes import Sensing, make_perception
from ctxsearch.agent.strategies import Choice, Strategy
from ctxsearch.envs.detector import DetectorModel
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotSpec, TimeModel
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.drift import DayEvidence, Forgetting
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.store import EvidenceStore

ROOM_DONE = "done"
ROOM_STARTED = "started"
# Whether a known object (examined on an earlier day of the run) may be examined again: never
# (the paper: EXAMINED is never emptied within a run) or when its type's impact under the
# (possibly forgetting) counts is worth the seconds to examine it (agent.acquisition).
REEXAMINE_POLICIES = ("never", "impact")
# impact / second below which a known object is not examined again (``--reexamine-rate``): d_A
# is mostly eq. 3's impact(0, n) of the entries never seen (0.058 at n = 20, 0.015 at n = 100),
# an examination costs 5-20 s from the door, so under ``none`` a type stops being re-examined
# after about 100 examinations; forgetting keeps its effective n (and so d_A) from growing.
DEFAULT_REEXAMINE_RATE = 1e-3

ChoiceCallback = Callable[[KnowledgeBase, Choice], None]
# (layout, catalog, spec, time model, render RGB) -> the robot's perception in that room
PerceptionFactory = Callable[[RoomLayout, Catalog, RobotSpec, TimeModel, bool], Perception]


def room_rng(seed: int, index: int, day: int = 0) -> np.random.Generator:
    """The strategy's rng for room ``index`` on ``day`` (fresh per visit, so a replayed visit
    draws the same; day 0's is the one of runs without days)."""
    key = [int(seed), int(index), 0x51] + ([int(day)] if day else [])
    return np.random.default_rng(key)


@dataclass(frozen=True)
class StoredExam:
    """An examination read back from the store: the object, its type and the related rows."""

    object_id: int
    ref_type: str
    related: tuple[tuple[str, str, int], ...]  # (relation, type, related object id)
    sim_time: float = 0.0


@dataclass(frozen=True)
class ExamResult:
    """One examination as the loop made it (what callbacks and the recorder get)."""

    index: int  # examinations so far in this run, this one included
    room_index: int
    room_seed: int
    choice: Choice
    related: tuple[tuple[str, ObjectInstance], ...]
    gazes: int
    sim_time: float  # run clock after the examination
    replayed: bool = False

    @property
    def pairs(self) -> set[tuple[str, str]]:
        """RELATED-TYPES: the distinct (relation, type) pairs."""
        return {(r, o.type) for r, o in self.related}


@dataclass
class Run:
    """Run-level state shared by the rooms: knowledge, store, strategy, robot, clock."""

    catalog: Catalog
    kb: KnowledgeBase
    store: EvidenceStore
    strategy: Strategy
    perception: str  # the perception mode's name (agent.perception_modes, or the user's)
    style: str
    seed: int
    run: str  # the store's run key
    spec: RobotSpec = field(default_factory=RobotSpec)
    time_model: TimeModel = field(default_factory=TimeModel)
    clock_offset: float = 0.0  # the run clock when the current room started
    examinations: int = 0  # made in this run so far (replayed ones included)
    sim_new: float = 0.0  # simulated seconds of new (not replayed) work in this call
    room_budget_s: float | None = None  # simulated seconds per room (None: each to completion)
    on_choice: ChoiceCallback | None = None  # before each examination
    perceive: PerceptionFactory | None = None  # None: the mode ``perception`` names
    map_mode: str = "given"  # agent.mapping.MAP_MODES: the true layout's grid or the robot's own
    frontier_rule: str = "info"  # agent.frontiers.FRONTIER_RULES (built maps only)
    detector: DetectorModel | None = None  # camera mode's preset (None: perfect)
    confirm: int = 1  # camera mode: images of a room that must detect an object to count it
    min_score: float = 0.0  # camera mode: the confidence a detection must reach to count
    reexamine: str = "never"  # REEXAMINE_POLICIES
    reexamine_rate: float = DEFAULT_REEXAMINE_RATE  # impact per second worth a re-examination
    forgetting: Forgetting = field(default_factory=Forgetting)  # how old evidence counts
    evidence: DayEvidence = field(default_factory=DayEvidence.empty)  # the run's, by day
    days: int = 1  # days the run visits its rooms on (the change test's looks)

    def perception_in(self, layout: RoomLayout, rgb: bool) -> Perception:
        """The robot's perception (and body) in the room ``layout``."""
        if self.perceive is not None:
            return self.perceive(layout, self.catalog, self.spec, self.time_model, rgb)
        mode = self.perception.split("+")[0]
        return make_perception(mode, layout, self.catalog, self.spec, self.time_model, rgb=rgb,
                               sensing=Sensing(self.detector, self.seed,
                                               self.confirm, self.min_score))  # fmt: skip
