"""The configuration of a learning run (``LearnConfig``, its run key), the state it carries from
room to room (``Run``: settings, services, counters), and the records its rooms produce.

Shared by the per-room procedure (agent.acquisition), its recording (agent.learn_log), resume
(agent.resume) and the multi-room run (agent.learning), so none of them imports another.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ctxsearch.agent.frontiers import FRONTIER_RULES
from ctxsearch.agent.interfaces import Perception
from ctxsearch.agent.mapping import MAP_MODES, default_map_mode
from ctxsearch.agent.perception_modes import (
    DEFAULT_DETECTOR,
    PERCEPTION_MODES,
    Sensing,
    make_perception,
)
from ctxsearch.agent.strategies import Choice, Strategy
from ctxsearch.envs.detector import DetectorModel, default_or_named
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotSpec, TimeModel
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.drift import DayEvidence, Forgetting
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.options import (
    DEFAULT_CONFIRM_REFERENCE,
    MapMode,
    PerceptionMode,
    Reexamine,
    values,
)
from ctxsearch.knowledge.store import EvidenceStore

ROOM_DONE = "done"
ROOM_STARTED = "started"
# Whether a known object (examined on an earlier day of the run) may be examined again: never
# (the paper: EXAMINED is never emptied within a run) or when its type's impact under the
# (possibly forgetting) counts is worth the seconds to examine it (agent.acquisition).
REEXAMINE_POLICIES = values(Reexamine)
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


def run_id(
    strategy: str,
    perception: str,
    seed: int,
    room_budget_s: float | None = None,
    map_mode: str = "given",
) -> str:
    """The store's run key: runs with another strategy, perception, seed, room budget or map are
    separate runs (no budget: the key has no budget part; the given map: no map part)."""
    key = f"{strategy}/{perception}/seed={int(seed)}"
    if map_mode != MapMode.GIVEN:
        key = f"{key}/map={map_mode}"
    return key if room_budget_s is None else f"{key}/budget={float(room_budget_s)!r}s"


@dataclass(frozen=True)
class LearnConfig:
    """What to learn from and how (``learn``).

    ``kb_path`` is the evidence store, created or resumed; ``alpha`` defaults to the store's.
    ``max_examinations`` stops the call after that many new examinations (run it again to go
    on). ``room_budget_s`` limits the simulated seconds spent in each room (None: every room to
    completion, Figure 2 as published; in a house it is the house's budget). ``spec`` and
    ``time_model`` are the robot's. ``map_mode`` is the grid the robot plans on
    (agent.mapping.MAP_MODES; None: ``built`` for the camera, ``given`` otherwise); the oracle
    perception needs ``given``. ``frontier_rule`` picks frontier goals on a built map
    (agent.frontiers).
    ``detector``: camera mode's preset, a name in assets/detectors or a file (None: realistic);
    ``confirm``: camera mode counts an object as related once that many images of the room
    detected it (1: at once, Figure 2 as published); ``min_score``: only once one of its
    detections scored at least that confidence (0: any detection counts); ``confirm_reference``:
    an object may be the reference of an examination once that many images of the room detected
    it (``DEFAULT_CONFIRM_REFERENCE``, 2: a false positive, drawn anew in every image, then
    almost never is; 1: at once, as published, ``PAPER_CONFIRM_REFERENCE``); ``exam_recall``:
    camera mode plans examinations to see (agent.exam_views:
    the gaze planner's viewpoints stay within the distance at which the catalog's object types
    are detected with that mean single-image recall; None: the planner's own range, as before).
    ``days``: the rooms are visited on days 0 .. days-1 (1: the paper's single visit);
    ``reexamine`` (agent.run_state.REEXAMINE_POLICIES) and ``reexamine_rate``: whether a known
    object is examined again on a later day; ``forgetting``: how old evidence counts for that
    decision (knowledge.drift).
    """

    style: str
    rooms: int
    kb_path: str | Path
    strategy: str = "hif"
    perception: str = "camera"
    alpha: float | None = None
    seed: int = 0
    record: str | Path | None = None
    max_examinations: int | None = None
    progress: bool = True
    room_budget_s: float | None = None
    spec: RobotSpec = field(default_factory=RobotSpec)
    time_model: TimeModel = field(default_factory=TimeModel)
    map_mode: str | None = None
    frontier_rule: str = "info"
    detector: str | None = None
    confirm: int = 1
    min_score: float = 0.0
    confirm_reference: int = DEFAULT_CONFIRM_REFERENCE
    exam_recall: float | None = None
    days: int = 1
    reexamine: str = "never"
    reexamine_rate: float = DEFAULT_REEXAMINE_RATE
    forgetting: Forgetting = field(default_factory=Forgetting)

    @property
    def map_used(self) -> str:
        """The map mode the run uses (``map_mode`` or the perception's default)."""
        return self.map_mode or default_map_mode(self.perception)

    def detector_model(self, catalog: Catalog) -> DetectorModel | None:
        """The camera mode's preset, loaded and checked (None in oracle mode)."""
        if self.perception != PerceptionMode.CAMERA:
            return None
        return default_or_named(self.detector, catalog, DEFAULT_DETECTOR)

    def checked(self, own_perception: bool = False) -> LearnConfig:
        """The configuration with the budget as a float; a one-line error for bad values
        (``own_perception``: ``perception`` names the caller's own, any name goes)."""
        if self.rooms < 0:
            raise CtxsearchError(f"rooms must be >= 0, got {self.rooms}")
        if self.max_examinations is not None and self.max_examinations < 0:
            raise CtxsearchError(f"max_examinations must be >= 0, got {self.max_examinations}")
        budget = self.room_budget_s
        if budget is not None:
            try:
                budget = float(budget)
            except (TypeError, ValueError):
                raise CtxsearchError(
                    f"room budget must be a number of seconds, got {budget!r}"
                ) from None
            if not (math.isfinite(budget) and budget > 0):
                raise CtxsearchError(
                    f"room budget must be a positive number of seconds, got {budget}"
                )
        if self.confirm < 1:
            raise CtxsearchError(f"confirm must be >= 1 images, got {self.confirm}")
        if self.confirm_reference < 1:
            raise CtxsearchError(
                f"confirm reference must be >= 1 images, got {self.confirm_reference}"
            )
        r = self.exam_recall
        if r is not None and not (isinstance(r, int | float) and 0.0 < r < 1.0):
            raise CtxsearchError(f"exam recall must be in (0, 1), got {r!r}")
        if not (isinstance(self.min_score, int | float) and 0.0 <= self.min_score <= 1.0):
            raise CtxsearchError(f"min score must be in [0, 1], got {self.min_score!r}")
        if self.days < 1:
            raise CtxsearchError(f"days must be >= 1, got {self.days}")
        if self.reexamine not in REEXAMINE_POLICIES:
            raise CtxsearchError(
                f"unknown re-examination policy '{self.reexamine}' "
                f"(known: {', '.join(REEXAMINE_POLICIES)})"
            )
        if not (math.isfinite(self.reexamine_rate) and self.reexamine_rate >= 0):
            raise CtxsearchError(
                f"re-examination rate must be a number >= 0, got {self.reexamine_rate}"
            )
        if not own_perception and self.perception not in PERCEPTION_MODES:
            raise CtxsearchError(
                f"unknown perception mode '{self.perception}' "
                f"(known: {', '.join(PERCEPTION_MODES)})"
            )
        if self.map_used not in MAP_MODES:
            raise CtxsearchError(
                f"unknown map mode '{self.map_used}' (known: {', '.join(MAP_MODES)})"
            )
        if self.map_used == MapMode.BUILT and self.perception == PerceptionMode.ORACLE:
            raise CtxsearchError("the oracle perception renders no depth: it needs --map given")
        if self.frontier_rule not in FRONTIER_RULES:
            raise CtxsearchError(
                f"unknown frontier rule '{self.frontier_rule}' (known: {', '.join(FRONTIER_RULES)})"
            )
        return replace(self, room_budget_s=budget, map_mode=self.map_used)

    def run_key(self, label: str) -> str:
        """The store's run key (``run_id``, examinations planned to see, and the re-examination
        policy where it is not the paper's) for the perception ``label``."""
        rid = run_id(self.strategy, label, self.seed, self.room_budget_s, self.map_used)
        if self.exam_recall is not None:
            rid = f"{rid}/exam-recall={self.exam_recall:g}"
        if self.reexamine == Reexamine.NEVER:
            return rid
        return f"{rid}/reexamine={self.reexamine}:{self.reexamine_rate:g}/forget={self.forgetting.label}"

    def limit_reached(self, examinations: int) -> bool:
        """Whether ``examinations`` new examinations end the call."""
        return self.max_examinations is not None and examinations >= self.max_examinations


@dataclass(frozen=True)
class RunSettings:
    """What a run was asked to do: its configuration as given (``config``, checked), and what
    was resolved from it: the style's name, the store's run key, the perception's label, the map
    and the camera mode's detector preset (None: perfect, or a perception of one's own)."""

    config: LearnConfig
    style: str
    key: str
    perception: str
    map_mode: MapMode
    detector: DetectorModel | None = None


@dataclass
class RunServices:
    """What a run works with: the catalog, the knowledge base and its store, the strategy, the
    evidence by day, and the caller's hooks (``on_choice`` before each examination;
    ``perceive``: the robot's perception of one's own, None: the mode the settings name)."""

    catalog: Catalog
    kb: KnowledgeBase
    store: EvidenceStore
    strategy: Strategy
    evidence: DayEvidence = field(default_factory=DayEvidence.empty)
    on_choice: ChoiceCallback | None = None
    perceive: PerceptionFactory | None = None


@dataclass
class RunCounters:
    """What a run has done so far: the run clock when the current room started, the
    examinations made (replayed ones included) and the simulated seconds of new work."""

    clock_offset: float = 0.0
    examinations: int = 0
    sim_new: float = 0.0


@dataclass
class Run:
    """Run-level state shared by the rooms: its settings, services and counters."""

    settings: RunSettings
    services: RunServices
    counters: RunCounters = field(default_factory=RunCounters)

    def perception_in(self, layout: RoomLayout, rgb: bool) -> Perception:
        """The robot's perception (and body) in the room ``layout``."""
        st, c = self.settings, self.settings.config
        if self.services.perceive is not None:
            return self.services.perceive(layout, self.services.catalog, c.spec, c.time_model, rgb)
        mode = st.perception.split("+")[0]
        sensing = Sensing(st.detector, c.seed, c.confirm, c.min_score, c.confirm_reference)
        return make_perception(
            mode, layout, self.services.catalog, c.spec, c.time_model, rgb=rgb, sensing=sensing
        )
