"""Autonomous acquisition of spatial context: Figure 2 of the paper on the simulated robot.

``learn`` runs procedure learn-spatial-contexts over a sequence of rooms; the knowledge (the
evidence store and the knowledge base derived from it) carries over from room to room. In one
room, faithfully to Figure 2:

- lines 1-2: UNEXAMINED := EXAMINED := {} (objects are the room's instances, by id);
- lines 4-7: when UNEXAMINED is empty, use the camera to find a nearby recognizable object not in
  EXAMINED (agent.exploration's ``Explorer``: look around at the current spot with a pan sweep,
  then drive to the next viewpoint of a deterministic tour of the room's free space and look
  around there); the room is done when the tour is over and nothing unexamined was seen;
- lines 8-13: the strategy picks a type among the UNEXAMINED types, the object is the nearest of
  that type (``agent.strategies``, with travel and examination seconds from agent.grid_costs);
- line 14-16: examine it: its relation volumes (knowledge.geometry.relation_volume for every
  relation of its type) are grouped into few boxes (agent.exam_volumes), the view planner plans
  gazes that cover them, the robot executes them (drive, head, image), the detector reports what
  it sees, and RELATED-OBJECTS / RELATED-TYPES follow from knowledge.geometry.related on the
  detected poses (the examined object's own pose is the reference); an object no reachable
  viewpoint can see into is marked examined without counting as a trial;
- lines 17-20: one transaction in the evidence store and the same counts in the knowledge base
  (intervals are derived from counts on demand, see DESIGN.md);
- line 21: UNEXAMINED := (UNEXAMINED + RELATED-OBJECTS) - EXAMINED.

Perception modes (agent.perception_modes) share this loop and the time model: ``camera`` renders
and runs the detector, ``oracle`` reads the true layout without rendering; both charge the same
simulated seconds for the same motions and images. With ``record``, agent.learn_log's ``RunLog``
writes the run to rerun.

Limited time (``room_budget_s``). The paper's robot "will not have an infinite amount of time to
learn": with a budget of B simulated seconds per room, the robot leaves a room as soon as B
seconds have passed since it entered, whatever is left unexamined. What is in flight is
completed: an examination, or one exploration step (a drive to the next viewpoint, a six-image
look-around), so a room takes at most B plus one of those; nothing new starts once B is
spent. Without a budget (None, the default) every room is run to completion as in Figure 2, and
every strategy examines the same objects per room in another order. The budget is part of the
run's identity: runs with another budget are separate runs in the same store.

Runs, rooms and resume. A run is identified by (strategy, perception, seed, room budget); room
i's seed is derived from (seed, i). Rooms marked done in the store are skipped; the run clock
goes on from the end time the store recorded for them (stores written before end times were
recorded: from their last examination). A room in progress is *replayed* from its start: the
knowledge base as it was before the room, the same rng, the same motions, the same budget
checks; the examinations already in the store are not perceived again but read back (and checked
against the choices), so a resumed run makes exactly the choices of an uninterrupted one. Every
examination is one store transaction: Ctrl-C or a kill loses at most the one in flight.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agent import strategies as strat
from agent.exam_volumes import group_facing, group_volume_members, relation_boxes
from agent.exploration import Explorer
from agent.grid_costs import GridCosts
from agent.learn_log import RunLog
from agent.navigation import OccupancyGrid, nearest_free, plan_path
from agent.perception_modes import PERCEPTION_MODES, make_perception
from agent.strategies import Choice, Strategy
from envs.layout import RoomLayout
from envs.robot_spec import RobotPose, RobotSpec, TimeModel
from envs.rooms import door_entry
from knowledge import geometry
from knowledge.base import KnowledgeBase
from knowledge.catalog import Catalog
from knowledge.errors import CtxsearchError
from knowledge.geometry import ObjectInstance

# Examination gazes prefer the open side of a relation volume (agent.viewplan.facing_for) when
# True. Off: measured on 2 x 3 office rooms in camera mode (results/learning_budget/facing.md),
# it found no more related pairs (recall 0.994 -> 0.994 and 0.992 -> 0.986 of the oracle's) and
# took about as long or longer per examination.
EXAMINE_FACING = False
ROOM_DONE = "done"
ROOM_STARTED = "started"


# =========================================================================== seeds and run ids
def room_seed(seed: int, index: int) -> int:
    """The seed of room ``index`` of a run started with ``seed`` (deterministic, spread out)."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1)[0] & 0x7FFFFFFF)


def room_rng(seed: int, index: int) -> np.random.Generator:
    """The strategy's rng for room ``index`` (fresh per room, so a replayed room draws the same)."""
    return np.random.default_rng([int(seed), int(index), 0x51])


def run_id(strategy: str, perception: str, seed: int, room_budget_s: float | None = None) -> str:
    """The store's run key: runs with another strategy, perception, seed or room budget are
    separate runs (no budget: the key has no budget part)."""
    key = f"{strategy}/{perception}/seed={int(seed)}"
    return key if room_budget_s is None else f"{key}/budget={float(room_budget_s)!r}s"


# =========================================================================== one room
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


class RoomLearner:
    """Figure 2 in one room (see the module docstring)."""

    def __init__(
        self, run: Run, layout: RoomLayout, room_index: int, prior: Sequence[StoredExam] = ()
    ):
        self.run, self.layout, self.room_index = run, layout, room_index
        self.catalog, self.kb, self.log = run.catalog, run.kb, run.log
        self.spec, self.tm = run.spec, run.time_model
        self.prior = list(prior)
        self.grid = OccupancyGrid.from_layout(layout, self.spec)
        self.start_pose = start_pose(layout, self.grid)
        self.perception = make_perception(
            run.perception, layout, self.catalog, self.spec, self.tm, rgb=self.log.wants_rgb
        )
        self.body = self.perception.body
        self.body.reset_pose(self.start_pose)
        self._t0 = self.body.sim_time
        self.rng = room_rng(run.seed, room_index)
        self._gaze_s: dict[int, float] = {}
        self.costs = GridCosts(self.grid, self.tm, self._gaze_seconds)
        self.explorer = Explorer(self)
        self.examined: set[int] = set()
        self.unexamined: dict[int, ObjectInstance] = {}
        self.last_exam_clock = self.clock  # the run clock after the room's last examination
        self.new_since = self.clock  # the run clock when the replay (if any) was over
        self.budget_s = run.room_budget_s
        self.left_early = False  # the budget ended the room (objects may be left unexamined)

    # ---- time and motion ------------------------------------------------------------------
    @property
    def clock(self) -> float:
        """The run clock: seconds before this room plus the room's own."""
        return self.run.clock_offset + (self.body.sim_time - self._t0)

    @property
    def room_elapsed(self) -> float:
        """Simulated seconds since the robot entered this room."""
        return self.body.sim_time - self._t0

    def budget_spent(self) -> bool:
        """True once the room's time budget (if any) is used up."""
        return self.budget_s is not None and self.room_elapsed >= self.budget_s

    def drive_to(self, xy: np.ndarray) -> None:
        """Drive along a planned path to ``xy``, facing along the last segment."""
        p = self.body.pose()
        path = plan_path(self.grid, p.xy, xy)
        if path is None or len(path) < 2:
            return
        seg = path[-1] - path[-2]
        self.body.drive(path, math.atan2(seg[1], seg[0]))
        self.log.robot(self)

    # ---- examination -------------------------------------------------------------------------
    def plan_examination(self, obj: ObjectInstance, start: RobotPose):
        """The gazes (agent.viewplan) that cover the object's relation volumes, group by group."""
        from agent.viewplan import facing_for, plan_gazes

        rels = self.catalog.type(obj.type).relations
        gazes = []
        pose = start
        for box, members in group_volume_members(relation_boxes(self.catalog, obj)):
            facing = (
                group_facing([facing_for(rels[i], obj) for i in members])
                if EXAMINE_FACING
                else None
            )
            gs = plan_gazes(self.grid, box, pose, self.spec, self.tm, facing=facing)
            gazes.extend(gs)
            if gs:
                pose = gs[-1].pose
        return gazes

    def _gaze_seconds(self, obj: ObjectInstance) -> float:
        """Head moves and images of the object's planned examination, without the first drive
        (cost-hif's estimate; planned once per object from where the robot was then)."""
        t = self._gaze_s.get(obj.id)
        if t is None:
            gazes = self.plan_examination(obj, self.body.pose())
            t = sum(g.cost for g in gazes[1:]) + (self.tm.image_cost if gazes else 0.0)
            self._gaze_s[obj.id] = t
        return t

    def examine(
        self, choice: Choice, stored: StoredExam | None, gazes: Sequence[Any]
    ) -> list[tuple[str, ObjectInstance]]:
        """Lines 15-16: execute the planned gazes, detect, decide the relations. With ``stored``
        (a replay) the motions are made, images are not taken, and the stored result is used."""
        from agent.viewplan import execute_gaze

        obj = choice.obj
        self.log.examine_start(self, obj, gazes)
        seen: dict[int, ObjectInstance] = {}
        replay = stored is not None
        need_images = not (replay or self.perception.reads_truth) or self.log.wants_frames
        for gaze in gazes:
            if replay:
                execute_gaze(_NoCapture(self.body), self.grid, gaze)
                continue
            frame = execute_gaze(self.body, self.grid, gaze, rgb=self.log.wants_rgb, depth=True)
            self.log.robot(self)
            if need_images:
                objs = self.perception.see(frame)
                seen.update((o.id, o) for o in objs)
                self.log.frame(self, frame, objs, purpose="examine")
        if replay:
            by_id = {o.id: o for o in self.layout.objects}
            related = [(rel, by_id[i]) for rel, _t, i in stored.related]
        else:
            related = self.perception.related(obj, list(seen.values()))
        return related

    # ---- Figure 2 ----------------------------------------------------------------------------
    def run_room(self) -> Iterator[ExamResult]:
        """Lines 3-21 until the room is done or its time budget is spent; yields every
        examination."""
        n_room = 0
        while True:
            if self.budget_spent():  # limited time: leave the room
                self.left_early = True
                break
            if not self.unexamined:  # lines 4-7
                obj = self.explorer.find(self.examined)
                if obj is None:
                    break
                self.unexamined[obj.id] = obj
            pose = self.body.pose()
            cands = [self.unexamined[i] for i in sorted(self.unexamined)]
            choice = strat.choose(
                self.run.strategy, self.kb, cands, pose, self.costs.at(pose), self.rng
            )
            stored = self.prior[n_room] if n_room < len(self.prior) else None
            if self.run.on_choice is not None:
                self.run.on_choice(self.kb, choice)
            self.log.choice(self, choice)
            del self.unexamined[choice.obj.id]  # line 14
            self.examined.add(choice.obj.id)
            gazes = self.plan_examination(choice.obj, self.body.pose())
            if not gazes:
                # No reachable viewpoint sees its relation volumes: not a trial, no evidence (so
                # nothing in the store either, and a replay skips it the same way).
                self.log.text(
                    self,
                    f"{choice.obj.type} #{choice.obj.id} cannot be examined: "
                    "no reachable viewpoint sees its relation volumes",
                )
                continue
            if stored is not None and stored.object_id != choice.obj.id:
                raise self._resume_error(
                    f"the store says object {stored.object_id} was examined next, the replay "
                    f"chose {choice.obj.id}"
                )
            related = self.examine(choice, stored, gazes)  # lines 15-16
            n_gazes = len(gazes)
            pairs = geometry.related_pairs(related)
            if stored is None:  # lines 17-20: one transaction, then the same counts in memory
                self.run.store.record(
                    run=self.run.run,
                    style=self.run.style,
                    room_seed=self.layout.seed,
                    object_id=choice.obj.id,
                    ref_type=choice.obj.type,
                    sim_time=self.clock,
                    strategy=self.run.strategy.name,
                    related=sorted({(r, o.type, o.id) for r, o in related}),
                )
            self.kb.record_examination(choice.obj.type, pairs)
            self.run.strategy.observe(choice.obj.type)
            for _, o in related:  # line 21
                if o.id not in self.examined:
                    self.unexamined.setdefault(o.id, o)
            if stored is not None and n_room == 0:
                # The run clock of a replayed room comes from the store: the room started when
                # its first examination was stored minus the time the replay took to get there.
                self.run.clock_offset += stored.sim_time - self.clock
            n_room += 1
            self.run.examinations += 1
            self.last_exam_clock = self.clock
            if n_room == len(self.prior):
                self.new_since = self.clock
            yield ExamResult(
                self.run.examinations,
                self.room_index,
                self.layout.seed,
                choice,
                tuple(related),
                n_gazes,
                self.clock,
                replayed=stored is not None,
            )
        if n_room < len(self.prior):
            raise self._resume_error(
                f"the store holds {len(self.prior)} examinations of it, the replay left it after "
                f"{n_room}"
            )

    def _resume_error(self, what: str) -> CtxsearchError:
        return CtxsearchError(
            f"cannot resume room seed {self.layout.seed}: {what} "
            "(store written by other code or settings?)"
        )

    def close(self) -> None:
        """Release the renderer (camera mode)."""
        self.perception.close()


class _NoCapture:
    """A body whose capture is a no-op apart from its time (replayed examinations)."""

    def __init__(self, body):
        self._b = body
        self.spec = body.spec

    def pose(self):
        return self._b.pose()

    def drive(self, path, yaw):
        return self._b.drive(path, yaw)

    def move_head(self, pan, tilt):
        return self._b.move_head(pan, tilt)

    def capture(self, rgb=False, depth=True):
        tm = getattr(self._b, "time_model", None) or TimeModel()
        if hasattr(self._b, "charge"):
            self._b.charge(tm.image_cost)
        else:
            self._b.sim_time += tm.image_cost


def start_pose(layout: RoomLayout, grid: OccupancyGrid) -> RobotPose:
    """Where the robot enters: the free cell nearest a point 0.6 m inside the door, facing into
    the room (in the largest free region if the door's side is cut off)."""
    x, y, yaw = door_entry(layout)
    p = nearest_free(grid, np.array([x, y]), grid.largest_region())
    if p is None:
        raise CtxsearchError(f"room {layout.style}/{layout.seed} has no free space for the robot")
    return RobotPose(float(p[0]), float(p[1]), yaw)


# =========================================================================== a run over rooms
@dataclass
class Summary:
    """What a ``learn`` call did and what the knowledge base holds at its end."""

    run: str
    rooms: int  # rooms of the run (done at the end, including rooms done before)
    rooms_done_now: int
    examinations: int  # made by this call (replayed ones not counted)
    total_examinations: int  # in the store
    types_seen: int  # types with n > 0
    mean_width: float
    wall_s: float
    sim_s: float  # simulated seconds of this call (replayed motions not counted)
    interrupted: bool = False
    files: list[Path] = field(default_factory=list)  # recordings written
    room_budget_s: float | None = None  # simulated seconds per room (None: no limit)
    rooms_left_early: int = 0  # rooms done now that the budget ended (objects left unexamined)

    @property
    def exams_per_wall_s(self) -> float:
        """Examinations per wall-clock second of this call."""
        return self.examinations / self.wall_s if self.wall_s > 0 else 0.0

    def lines(self) -> list[str]:
        """Human-readable summary lines."""
        return [
            f"run {self.run}: {self.rooms} rooms done ({self.rooms_done_now} in this call)",
            f"examinations: {self.examinations} now, {self.total_examinations} in the store",
            f"types seen: {self.types_seen}; mean interval width: {self.mean_width:.4f}",
            f"time: {self.wall_s:.1f} s wall, {self.sim_s:.1f} s simulated; "
            f"{self.exams_per_wall_s:.1f} examinations per wall second",
        ] + (
            [
                f"room budget: {self.room_budget_s:g} s simulated per room; the budget ended "
                f"{self.rooms_left_early} of the {self.rooms_done_now} rooms done in this call"
            ]
            if self.room_budget_s is not None
            else []
        )


@dataclass
class Run:
    """Run-level state shared by the rooms: knowledge, store, strategy, clock, logging."""

    catalog: Catalog
    kb: KnowledgeBase
    store: Any
    strategy: Strategy
    perception: str
    style: str
    seed: int
    run: str
    log: Any
    spec: RobotSpec = field(default_factory=RobotSpec)
    time_model: TimeModel = field(default_factory=TimeModel)
    clock_offset: float = 0.0  # the run clock when the current room started
    examinations: int = 0  # made in this run so far (replayed ones included)
    sim_new: float = 0.0  # simulated seconds of new (not replayed) work in this call
    room_budget_s: float | None = None  # simulated seconds per room (None: each to completion)
    on_choice: Callable[[KnowledgeBase, Choice], None] | None = None  # before each examination


# =========================================================================== learn
ExamCallback = Callable[[ExamResult, KnowledgeBase], None]
LayoutFn = Callable[[int, int], RoomLayout]  # (room index, room seed) -> layout


def style_layouts(style: str, catalog: Catalog) -> tuple[str, LayoutFn]:
    """The style's name and its world generator (a room style's rooms or a house style's houses)."""
    from envs.houses import generate_layout, resolve_style

    st = resolve_style(style, catalog)
    return st.name, lambda index, seed: generate_layout(st, seed, catalog)


def learn(
    style: str,
    rooms: int,
    kb_path: str | Path,
    strategy: str = "hif",
    perception: str = "camera",
    alpha: float | None = None,
    seed: int = 0,
    record: str | Path | None = None,
    max_examinations: int | None = None,
    progress: bool = True,
    room_budget_s: float | None = None,
    *,
    catalog: Catalog | None = None,
    layouts: LayoutFn | None = None,
    on_examination: ExamCallback | None = None,
    on_choice: Callable[[KnowledgeBase, Choice], None] | None = None,
) -> Summary:
    """Run learn-spatial-contexts (Figure 2) over ``rooms`` rooms of ``style``.

    ``kb_path`` is the evidence store, created or resumed (see the module docstring); ``alpha``
    defaults to the store's. ``max_examinations`` stops the call after that many new
    examinations (run it again to go on). ``layouts`` replaces the room generator (tests);
    ``on_examination(result, kb)`` is called after every examination, replayed ones included,
    and ``on_choice(kb, choice)`` after every choice, before the examination (benchmarks).
    ``room_budget_s`` limits the simulated seconds spent in each room (see the module
    docstring; None: every room to completion, Figure 2 as published).
    Ctrl-C ends the call at once (the examination in flight is lost) with
    ``Summary.interrupted`` set.

    The run clock (``sim_time`` in the store) runs on from room to room. A room done in an
    earlier call resumes the clock from the end time the store recorded for it, a replayed room
    takes its clock from its stored examinations, so a resumed run's clock equals an
    uninterrupted one's. (Rooms done by a store of schema version 1, which has no end times,
    resume it from their last examination: their final exploration is missing from the clock.)
    """
    from knowledge.catalog import load_catalog
    from knowledge.store import EvidenceStore

    if rooms < 0:
        raise CtxsearchError(f"rooms must be >= 0, got {rooms}")
    if max_examinations is not None and max_examinations < 0:
        raise CtxsearchError(f"max_examinations must be >= 0, got {max_examinations}")
    if room_budget_s is not None:
        try:
            room_budget_s = float(room_budget_s)
        except (TypeError, ValueError):
            raise CtxsearchError(
                f"room budget must be a number of seconds, got {room_budget_s!r}"
            ) from None
        if not (math.isfinite(room_budget_s) and room_budget_s > 0):
            raise CtxsearchError(
                f"room budget must be a positive number of seconds, got {room_budget_s}"
            )
    if perception not in PERCEPTION_MODES:
        raise CtxsearchError(
            f"unknown perception mode '{perception}' (known: {', '.join(PERCEPTION_MODES)})"
        )
    strategy_obj = strat.make_strategy(strategy)
    catalog = catalog or load_catalog()
    if layouts is None:
        style, layouts = style_layouts(style, catalog)
    rid = run_id(strategy, perception, seed, room_budget_s)
    seeds = [room_seed(seed, i) for i in range(rooms)]
    t_wall = time.perf_counter()
    log = RunLog(record)
    summary = Summary(rid, 0, 0, 0, 0, 0, 0.0, 0.0, 0.0, room_budget_s=room_budget_s)
    with ExitStack() as stack:
        store = stack.enter_context(EvidenceStore.open(kb_path, catalog, alpha=alpha, create=True))
        stack.callback(log.close)
        done = {s for s in seeds if store.room_status(rid, style, s) == ROOM_DONE}
        history = list(store.examinations())
        mine = {
            s: [e for e in history if e.run == rid and e.style == style and e.room_seed == s]
            for s in seeds
        }
        # The knowledge before the first unfinished room: all evidence but that of this run's
        # unfinished rooms, which are replayed.
        kb = KnowledgeBase(catalog, store.alpha)
        replay_seeds = {s for s in seeds if s not in done}
        for ex in history:
            if ex.run == rid and ex.style == style and ex.room_seed in replay_seeds:
                continue
            kb.record_examination(ex.type, {(r, t) for r, t, _ in ex.related})
            if ex.run == rid:
                strategy_obj.observe(ex.type)
        run = Run(
            catalog,
            kb,
            store,
            strategy_obj,
            perception,
            style,
            seed,
            rid,
            log,
            on_choice=on_choice,
            room_budget_s=room_budget_s,
        )
        bar = None
        if progress:
            from tqdm import tqdm

            bar = stack.enter_context(
                tqdm(
                    total=rooms,
                    initial=len(done),
                    unit="room",
                    desc=f"learn {style}",
                    dynamic_ncols=True,
                )
            )
        last_post = 0.0
        try:
            for i, s in enumerate(seeds):
                if s in done:
                    end = store.room_end_time(rid, style, s)
                    run.clock_offset = (
                        end
                        if end is not None
                        else max([run.clock_offset] + [e.sim_time for e in mine[s]])
                    )
                    continue
                if max_examinations is not None and summary.examinations >= max_examinations:
                    break
                L = RoomLearner(
                    run,
                    layouts(i, s),
                    i,
                    [StoredExam(e.object_id, e.type, e.related, e.sim_time) for e in mine[s]],
                )
                stack.callback(L.close)
                if store.room_status(rid, style, s) is None:
                    store.mark_room(rid, style, s, ROOM_STARTED)
                log.start_room(L)
                n_room, stopped = 0, False
                for res in L.run_room():
                    n_room += 1
                    log.examination(L, res)
                    if not res.replayed:
                        summary.examinations += 1
                        summary.sim_s = run.sim_new + (L.clock - L.new_since)
                    if on_examination is not None:
                        on_examination(res, kb)
                    if bar is not None and time.perf_counter() - last_post > 0.2:
                        last_post = time.perf_counter()
                        bar.set_postfix_str(
                            f"exams {run.examinations}, sim {res.sim_time:.0f} s", refresh=True
                        )
                    if max_examinations is not None and summary.examinations >= max_examinations:
                        stopped = True
                        break
                log.end_room(L, n_room)
                L.close()
                run.sim_new += L.clock - L.new_since
                summary.sim_s = run.sim_new
                if stopped:
                    break
                store.mark_room(rid, style, s, ROOM_DONE, end_time=L.clock)
                run.clock_offset = L.clock
                summary.rooms_done_now += 1
                summary.rooms_left_early += int(L.left_early)
                if bar is not None:
                    bar.update(1)
                    bar.set_postfix_str(
                        f"exams {run.examinations}, sim {run.clock_offset:.0f} s", refresh=True
                    )
        except KeyboardInterrupt:
            summary.interrupted = True
        summary.rooms = sum(1 for s in seeds if store.room_status(rid, style, s) == ROOM_DONE)
        summary.total_examinations = store.examinations_count()
        summary.types_seen = sum(1 for t in catalog.type_names if kb.n(t) > 0)
        summary.mean_width = kb.mean_width()
        summary.files = list(log.files)
    summary.wall_s = time.perf_counter() - t_wall
    return summary
