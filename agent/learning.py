"""A learning run: procedure learn-spatial-contexts (Figure 2) over a sequence of rooms.

``learn(LearnConfig(...))`` runs agent.acquisition's ``RoomLearner`` room after room; the
knowledge (the evidence store and the knowledge base derived from it) carries over. Room i's seed
is derived from (seed, i) and its room is generated when the run reaches it; each room's learner,
world and renderer are closed when the room is done, so memory stays flat over any number of
rooms.

A run is identified by (strategy, perception, seed, room budget) (``run_id``): runs with another
budget are separate runs in the same store. With ``days`` the run visits the same rooms (worlds)
on days 0 .. days-1, day after day (the furniture stays, the small objects stay or move by their type's
stay probability: envs ``generate_layout``'s day); the number of days is not part of the run key, so ``--days 5``
after ``--days 3`` adds days 3 and 4. Re-examination of known objects on later days
(``reexamine`` other than ``never``) is part of the key, with its rate and forgetting method. Rooms done in the store are skipped and a room in
progress is replayed (agent.resume), so a resumed run makes exactly the choices of an
uninterrupted one. Every examination is one store transaction: Ctrl-C or a kill loses at most
the one in flight. With ``record``, agent.learn_log's ``RunLog`` writes the run to rerun.
"""

from __future__ import annotations

import ctypes
import gc
import time
from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ctxsearch.agent import strategies as strat
from ctxsearch.agent.acquisition import EXAM_RECALL_NEEDS_A_DETECTOR, RoomLearner
from ctxsearch.agent.learn_log import RunLog
from ctxsearch.agent.perception_modes import perception_label
from ctxsearch.agent.resume import RunHistory
from ctxsearch.agent.run_state import (
    ROOM_DONE,
    ROOM_STARTED,
    ChoiceCallback,
    ExamResult,
    LearnConfig,
    PerceptionFactory,
    Run,
    RunServices,
    RunSettings,
    run_id,
)

__all__ = ["LearnConfig", "Summary", "learn", "room_seed", "run_id"]  # LearnConfig, run_id: the
# configuration lives with the run's state (agent.run_state); learn's callers find it here
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import HouseStyle, resolve_style
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.store import EvidenceStore

ExamCallback = Callable[[ExamResult, KnowledgeBase], None]
# (room index, room seed[, day]) -> layout; the day (>= 1) only in runs over several days
LayoutFn = Callable[..., RoomLayout]


# =========================================================================== seeds and run ids
def room_seed(seed: int, index: int) -> int:
    """The seed of room ``index`` of a run started with ``seed`` (deterministic, spread out)."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1)[0] & 0x7FFFFFFF)


def style_layouts(style: str, catalog: Catalog) -> tuple[str, LayoutFn]:
    """The style's name and its world generator (a room style's rooms or a house style's houses)."""
    st = resolve_style(style, catalog)
    return st.name, lambda index, seed, day=0: generate_layout(st, seed, catalog, day)


def world_noun(style: str, catalog: Catalog) -> str:
    """The word for one world of ``style``: "house" for a house style, else "room"."""
    try:
        return "house" if isinstance(resolve_style(style, catalog), HouseStyle) else "room"
    except CtxsearchError:  # a caller's own layouts (``learn(layouts=...)``) under any name
        return "room"


_frozen = False  # release_memory froze the survivors of its first collection


def release_memory() -> None:
    """Free what a finished room leaves behind. Its MuJoCo model, data and renderer sit in
    reference cycles (dm_control's MJCF objects), so they are collected now rather than at
    Python's next full collection; then glibc is asked to return the freed heap to the system
    (``malloc_trim``; without it the heap of a camera-mode run grows room by room through
    fragmentation). Elsewhere than glibc only the collection is done.

    The first call then freezes what survived it (``gc.freeze``: the modules, the catalog, the
    run's store and caches), so that later collections do not walk them again: the process's
    long-lived objects (mostly the libraries' functions) are most of what a full collection
    walks. Frozen objects are still freed
    when their last reference goes; only a reference cycle among them would now stay."""
    global _frozen
    gc.collect()
    if not _frozen:
        gc.freeze()
        _frozen = True
    if _LIBC is not None:
        _LIBC.malloc_trim(0)


def _load_libc() -> ctypes.CDLL | None:
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.malloc_trim.argtypes = [ctypes.c_size_t]
        return libc
    except (OSError, AttributeError):
        return None


_LIBC = _load_libc()


# =========================================================================== configuration
@dataclass
class Summary:
    """What a ``learn`` call did and what the knowledge base holds at its end."""

    run: str
    rooms: int = 0  # rooms of the run done (the call's rooms, up to where it stopped)
    rooms_done_now: int = 0
    examinations: int = 0  # made by this call (replayed ones not counted)
    total_examinations: int = 0  # in the store
    types_seen: int = 0  # types with n > 0
    mean_width: float = 0.0
    wall_s: float = 0.0
    sim_s: float = 0.0  # simulated seconds of this call (replayed motions not counted)
    interrupted: bool = False
    files: list[Path] = field(default_factory=list)  # recordings written
    room_budget_s: float | None = None  # simulated seconds per room (None: no limit)
    rooms_left_early: int = 0  # rooms done now that the budget ended (objects left unexamined)
    map_mode: str = "given"  # the grid the robot planned on (agent.mapping.MAP_MODES)
    detector: str | None = None  # camera mode's detector preset (None: the oracle has none)
    days: int = 1  # days the rooms were visited on
    revisits: int = 0  # known objects examined again on a later day (this call)
    world: str = "room"  # what one world is called: "room", or "house" in a house style

    @property
    def exams_per_wall_s(self) -> float:
        """Examinations per wall-clock second of this call."""
        return self.examinations / self.wall_s if self.wall_s > 0 else 0.0

    def lines(self) -> list[str]:
        """Human-readable summary lines: worlds named as the style's ("houses", "rooms"), and
        with --days, the visits (a world on one day) apart from the worlds."""
        w = self.world

        def n(count: int, noun: str) -> str:
            return f"{count} {noun}" + ("" if count == 1 else "s")

        if self.days > 1:
            head = (
                f"run {self.run}: {n(self.rooms, w)} done on day 0; "
                f"{n(self.rooms_done_now, 'visit')} (a {w} on one day) done in this call"
            )
            days = [
                f"days: {self.days} (known objects put back for re-examination in this call: "
                f"{self.revisits})"
            ]
        else:
            head = f"run {self.run}: {n(self.rooms, w)} done ({self.rooms_done_now} in this call)"
            days = []
        done_now = f"{self.rooms_done_now} {'visit' if self.days > 1 else w}s"  # "of the 1 rooms"
        return [
            head,
            *days,
            f"map: {self.map_mode}",
            f"detector: {self.detector or 'none (oracle perception reads the layout)'}",
            f"examinations: {self.examinations} now, {self.total_examinations} in the store",
            f"types seen: {self.types_seen}; mean interval width: {self.mean_width:.4f}",
            f"time: {self.wall_s:.1f} s wall, {self.sim_s:.1f} s simulated; "
            f"{self.exams_per_wall_s:.1f} examinations per wall second",
        ] + (
            [
                f"{w} budget: {self.room_budget_s:g} s simulated per {w}; the budget ended "
                f"{self.rooms_left_early} of the {done_now} done in this call"
                + (
                    " (they record no room contents: no SAME-ROOM counts)"
                    if w == "house" and self.rooms_left_early
                    else ""
                )
            ]
            if self.room_budget_s is not None
            else []
        )  # fmt: skip


# =========================================================================== learn
def learn(
    config: LearnConfig,
    *,
    catalog: Catalog | None = None,
    layouts: LayoutFn | None = None,
    on_examination: ExamCallback | None = None,
    on_choice: ChoiceCallback | None = None,
    perceive: PerceptionFactory | None = None,
) -> Summary:
    """Run learn-spatial-contexts (Figure 2) over ``config.rooms`` rooms of ``config.style``.

    ``layouts`` replaces the room generator (tests); ``on_examination(result, kb)`` is called
    after every examination, replayed ones included, and ``on_choice(kb, choice)`` after every
    choice, before the examination (benchmarks). ``perceive(layout, catalog, spec, time_model,
    rgb)`` gives the robot's agent.interfaces ``Perception`` in a room, for a perception of one's
    own (``config.perception`` is then only its name in the run key). Ctrl-C ends the call at once (the examination
    in flight is lost) with ``Summary.interrupted`` set.

    The run clock (``sim_time`` in the store) runs on from room to room. A room done in an
    earlier call resumes the clock from the end time the store recorded for it, a replayed room
    takes its clock from its stored examinations, so a resumed run's clock equals an
    uninterrupted one's (agent.resume).
    """
    config = config.checked(own_perception=perceive is not None)
    strategy = strat.make_strategy(config.strategy)
    catalog = catalog or load_catalog()
    style = config.style
    if layouts is None:
        style, layouts = style_layouts(style, catalog)
    map_mode = config.map_used
    detector = config.detector_model(catalog) if perceive is None else None
    if config.exam_recall is not None and detector is None:  # refused before the store opens
        raise CtxsearchError(EXAM_RECALL_NEEDS_A_DETECTOR)
    label = perception_label(
        config.perception, detector, config.confirm, config.min_score, config.confirm_reference
    )
    rid = config.run_key(label)
    t_wall = time.perf_counter()
    summary = Summary(rid, room_budget_s=config.room_budget_s, map_mode=map_mode,
                      detector=detector.name if detector is not None else None,
                      days=config.days, world=world_noun(config.style, catalog))  # fmt: skip
    store_cm = EvidenceStore.open(config.kb_path, catalog, alpha=config.alpha, create=True)
    with store_cm as store, RunLog(config.record) as log, _progress(config, style) as bar:
        others = _refuse_counting_twice(store, config, style, rid)
        kb = KnowledgeBase(catalog, store.alpha)
        history = RunHistory.load(store, rid, style, kb, strategy)
        run = Run(RunSettings(config, style, rid, label, map_mode, detector),
                  RunServices(catalog, kb, store, strategy, history.evidence, on_choice, perceive))  # fmt: skip
        rooms = _Rooms(run, log, history, layouts, summary, bar, on_examination, others)
        try:
            if rooms.learn(config):
                history.release(kb, strategy)
        except KeyboardInterrupt:
            summary.interrupted = True
        summary.total_examinations = store.examinations_count()
        summary.types_seen = sum(1 for t in catalog.type_names if kb.n(t) > 0)
        summary.mean_width = kb.mean_width()
        summary.files = list(log.files)
    summary.wall_s = time.perf_counter() - t_wall
    return summary


UP_FRONT_ROOMS = 4096  # rooms whose seeds ``_refuse_counting_twice`` checks before anything runs


def _refuse_counting_twice(
    store: EvidenceStore, config: LearnConfig, style: str, rid: str
) -> dict[int, str]:
    """The worlds of ``style`` another run of the store learned ({room seed: its run}), and a
    one-line error, before anything is written, where this run would visit one of them among
    its first ``UP_FRONT_ROOMS`` rooms (``_Rooms`` checks every later room before entering it):
    the store's knowledge reads every run, so a world learned under two settings (``--paper``
    and the default, two strategies) would count its objects twice. A run resumes its own
    rooms; other seeds give other worlds."""
    others = {seed: r for r, st, seed, _ in store.rooms() if st == style and r != rid}
    for i in range(min(config.rooms, UP_FRONT_ROOMS) if others else 0):
        _check_not_counted(others, room_seed(config.seed, i), config, style, rid)
    return others


def _check_not_counted(others: dict[int, str], seed: int, config, style: str, rid: str) -> None:
    """The one-line error of ``_refuse_counting_twice`` if world ``seed`` is another run's."""
    if seed in others:
        raise CtxsearchError(
            f"{config.kb_path}: run {others[seed]} already learned {style} worlds this run "
            f"({rid}) would visit; learned again under other settings they would count twice "
            "(use another store, or another --seed for other worlds)"
        )


def _progress(config: LearnConfig, style: str):
    """The progress bar over the rooms, or a context giving None."""
    if not config.progress:
        return nullcontext(None)
    return tqdm(
        total=config.rooms * config.days, unit="room", desc=f"learn {style}", dynamic_ncols=True
    )


@dataclass
class _Rooms:
    """The rooms of one call, in order (``learn``)."""

    run: Run
    log: RunLog
    history: RunHistory
    layouts: LayoutFn
    summary: Summary
    bar: tqdm | None
    on_examination: ExamCallback | None
    others: dict[int, str] = field(default_factory=dict)  # worlds other runs of the store learned
    _last_post: float = 0.0

    def learn(self, config: LearnConfig) -> bool:
        """Go through rooms 0 .. rooms-1 (seeds made one at a time) on day 0, then on each later
        day; True when all were gone through, False when ``max_examinations`` stopped the call."""
        run, summary = self.run, self.summary
        for day in range(config.days):
            for i in range(config.rooms):
                s = room_seed(config.seed, i)
                if self.history.is_done(s, day):
                    run.counters.clock_offset = self.history.done_clock(run.services.store, run.settings.key, run.settings.style, s,
                                                               run.counters.clock_offset, day)  # fmt: skip
                    summary.rooms += int(day == 0)
                    self._advance(run.counters.clock_offset)
                    continue
                if config.limit_reached(summary.examinations):
                    return False
                _check_not_counted(self.others, s, config, run.settings.style, run.settings.key)
                if not self.room(config, i, s, day):
                    return False
        return True

    def _layout(self, index: int, seed: int, day: int) -> RoomLayout:
        return self.layouts(index, seed) if day == 0 else self.layouts(index, seed, day)

    def _known(self, layout: RoomLayout, seed: int, day: int) -> list:
        """The room's furniture examined on an earlier day of the run (it stays; small objects
        that stayed are found again, their places checked: agent.home.PlaceChecks)."""
        run = self.run
        if day == 0:
            return []
        ids = run.services.store.examined_before(run.settings.key, run.settings.style, seed, day)
        return [o for o in layout.objects
                if o.id in ids and run.services.catalog.type(o.type).is_furniture]  # fmt: skip

    def room(self, config: LearnConfig, index: int, seed: int, day: int = 0) -> bool:
        """Learn in room ``index`` on ``day`` (a replay first, if it is in progress); False when
        the call's examination limit stopped it before the room was done."""
        run, store, summary = self.run, self.run.services.store, self.summary
        layout = self._layout(index, seed, day)
        previous = None
        if day > 0:  # the run's latest map of this world: the places its small objects were seen
            previous = store.home_map(run.settings.style, seed, run.settings.key, upto_day=day - 1)
        L = RoomLearner(run, self.log, layout, index, self.history.replay(seed, day), day,
                        self._known(layout, seed, day), previous)  # fmt: skip
        summary.revisits += L.revisits
        try:
            if store.room_status(run.settings.key, run.settings.style, seed, day) is None:
                store.mark_room(run.settings.key, run.settings.style, seed, ROOM_STARTED, day=day)
            self.log.start_room(L)
            stopped = False
            for res in L.run_room():
                self._examined(L, res)
                if not res.replayed and config.limit_reached(summary.examinations):
                    stopped = True
                    break
            self.log.end_room(L, L.n_room)
            contents = [] if stopped else L.room_contents()
            home = None if stopped else L.home_map()
        finally:
            L.close()
            release_memory()
        run.counters.sim_new += L.clock - L.new_since
        summary.sim_s = run.counters.sim_new
        if stopped:
            return False
        store.mark_room(
            run.settings.key, run.settings.style, seed, ROOM_DONE, end_time=L.clock, day=day,
            contents=contents, home_map=home,
        )  # fmt: skip
        run.counters.clock_offset = L.clock
        summary.rooms += int(day == 0)
        summary.rooms_done_now += 1
        summary.rooms_left_early += int(L.left_early)
        self._advance(run.counters.clock_offset)
        return True

    def _examined(self, L: RoomLearner, res: ExamResult) -> None:
        """Log, count and report one examination."""
        self.log.examination(L, res)
        if not res.replayed:
            self.summary.examinations += 1
            self.summary.sim_s = self.run.counters.sim_new + (L.clock - L.new_since)
        if self.on_examination is not None:
            self.on_examination(res, self.run.services.kb)
        if self.bar is not None and time.perf_counter() - self._last_post > 0.2:
            self._last_post = time.perf_counter()
            self.bar.set_postfix_str(
                f"exams {self.run.counters.examinations}, sim {res.sim_time:.0f} s", refresh=True
            )

    def _advance(self, clock: float) -> None:
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix_str(
                f"exams {self.run.counters.examinations}, sim {clock:.0f} s", refresh=True
            )
