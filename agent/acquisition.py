"""Autonomous acquisition of spatial context: Figure 2 of the paper in one room, on the robot.

``RoomLearner.run_room`` is procedure learn-spatial-contexts for one room (agent.learning runs
it room after room; the knowledge carries over). Faithfully to Figure 2:

- lines 1-2: UNEXAMINED := EXAMINED := {} (objects are the room's instances, by id);
- lines 4-7: when UNEXAMINED is empty, use the camera to find a nearby recognizable object not in
  EXAMINED (agent.exploration's ``Explorer``: look around at the current spot with a pan sweep,
  then drive to the next viewpoint of a deterministic tour of the room's free space and look
  around there); the room is done when the tour is over and nothing unexamined was seen;
- lines 8-13: the strategy picks a type among the UNEXAMINED types, the object is the nearest of
  that type (``agent.strategies``, with travel and examination seconds from agent.grid_costs);
- line 14-16: examine it: its relation volumes (knowledge.geometry.relation_volume for every
  relation of its type) are grouped into few boxes (agent.exam_volumes), the view planner plans
  gazes that cover them, the robot executes them (drive, head, image), the perception reports what
  it sees, and RELATED-OBJECTS / RELATED-TYPES follow from knowledge.geometry.related on the
  detected poses (the examined object's own pose is the reference); an object no reachable
  viewpoint can see into is marked examined without counting as a trial;
- lines 17-20: one transaction in the evidence store and the same counts in the knowledge base
  (intervals are derived from the counts on demand, so every pair of the examined type sees
  its new n_S, not only the observed pairs Figure 2's line 20 updates); with the camera perception the
  examination's row carries what its images could show (agent.exam_views: per relation volume
  and type, the expected recall and false-report rate), which ``--interval corrected`` reads;
- line 21: UNEXAMINED := (UNEXAMINED + RELATED-OBJECTS) - EXAMINED.

The robot is an agent.interfaces ``Body`` and ``Perception`` (agent.perception_modes: ``camera``
renders and runs the detector, ``oracle`` reads the true layout without rendering; both charge
the same TimeModel seconds for the same motions and images).

Limited time (``Run.room_budget_s``). The paper's robot "will not have an infinite amount of time
to learn": with a budget of B simulated seconds per room, the robot leaves a room as soon as B
seconds have passed since it entered, whatever is left unexamined. What is in flight is
completed: an examination, or one exploration step (a drive to the next viewpoint, a six-image
look-around), so a room takes at most B plus one of those; nothing new starts once B is spent.
Without a budget every room is run to completion as in Figure 2.

A room in progress in the store is replayed (agent.resume): its stored examinations are read
back instead of perceived, with the same choices, motions and clock.

Days (``learn --days``). A world persists across days: its furniture stays (same ids and poses),
its small objects stay or move by their type's stay probability (the checks of the places
where the previous day's map saw them: agent.home.PlaceChecks). On a later day the objects of the room examined on earlier
days (``known``: furniture) start in EXAMINED (lines 1-2): the paper's robot never examines an
object twice in a run (``Run.reexamine`` ``never``). With ``impact``, a known object starts in
UNEXAMINED instead when its type's d_A (eq. 3 averaged as in line 11) under the run's forgetting
counts today (knowledge.drift, ``ForgetKnowledgeBase.type_impact_now``), per simulated second
of examining it from the door (a straight-line estimate, ``EuclideanCosts``), is at least
``Run.reexamine_rate``: yesterday's desk is worth a look today when what one more trial would
teach, as the knowledge stands now, pays for the trip.

The map (``Run.map_mode``). ``given``: the occupancy grid of the true layout (the oracle's, and an
ablation of the camera mode). ``built``: the robot starts knowing only its pose; every depth image
updates its own map (agent.mapping's ``BuiltMap``), navigation, gaze planning and the cost model
use that map's grid as it stands, and lines 4-7 explore its frontiers (agent.frontiers). An
object recognized but not examinable from the map known so far is deferred until the next
look-around, and is unexaminable only once no frontier is left. A replay in a built map renders
depth images for the map (charged as the stored run was), so it rebuilds the same map.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import replace

import numpy as np

from ctxsearch.agent import strategies as strat
from ctxsearch.agent.exam_views import ViewModel, Views
from ctxsearch.agent.exam_volumes import group_volume_members, relation_boxes
from ctxsearch.agent.exploration import Explorer
from ctxsearch.agent.frontiers import FrontierExplorer
from ctxsearch.agent.grid_costs import GridCosts
from ctxsearch.agent.home import PlaceChecks, home_map
from ctxsearch.agent.interfaces import Body
from ctxsearch.agent.learn_log import RunLog
from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.navigation import OccupancyGrid, drive_along, start_pose
from ctxsearch.agent.resume import ReplayBody, replayed_related, resume_error
from ctxsearch.agent.room_segmentation import Recognized, RoomLabels, segment_contents
from ctxsearch.agent.run_state import ExamResult, Run, StoredExam, room_rng
from ctxsearch.agent.strategies import Choice, EuclideanCosts
from ctxsearch.agent.viewplan import Gaze, GazePlanOptions, execute_gaze, plan_gazes
from ctxsearch.envs.camera import Frame, focal_length
from ctxsearch.envs.detector import load_detector
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotPose
from ctxsearch.knowledge import geometry
from ctxsearch.knowledge.drift import ForgetKnowledgeBase
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.home_map import HomeMap, RememberedObject
from ctxsearch.knowledge.options import MapMode, Reexamine
from ctxsearch.knowledge.store import NewExamination

Related = list[tuple[str, ObjectInstance]]
EXAM_RECALL_NEEDS_A_DETECTOR = (
    "--exam-recall needs the camera perception with the simulated detector (the robot plans "
    "with its detector's recall curve)"
)


class RoomLearner:
    """Figure 2 in one room (see the module docstring)."""

    def __init__(
        self,
        run: Run,
        log: RunLog,
        layout: RoomLayout,
        room_index: int,
        prior: Sequence[StoredExam] = (),
        day: int = 0,
        known: Sequence[ObjectInstance] = (),
        previous: HomeMap | None = None,
    ):
        self.run, self.log, self.layout, self.room_index = run, log, layout, room_index
        self.day = int(day)
        self.catalog, self.kb, self.spec = (
            run.services.catalog,
            run.services.kb,
            run.settings.config.spec,
        )
        self.prior = list(prior)  # stored examinations to replay
        self.given_grid = OccupancyGrid.from_layout(layout, self.spec)  # the true layout's
        self.start_pose = start_pose(layout, self.given_grid)
        self.built = (
            BuiltMap.for_layout(layout, self.spec, self.start_pose)
            if run.settings.map_mode == MapMode.BUILT
            else None
        )
        self.perception = run.perception_in(layout, rgb=log.recording)
        self.body = self.perception.body
        self.view_model = view_model(run, self.perception.reads_truth)
        self._views: Views = ()  # what the last examination's images could show
        self.exam_options = exam_options(run, self.view_model, self.body)
        self.body.reset_pose(self.start_pose)
        self._t0 = self.body.sim_time
        self.rng = room_rng(run.settings.config.seed, room_index, self.day)
        self._gaze_s: dict[int, float] = {}
        self._costs = GridCosts(self.grid, run.settings.config.time_model, self._gaze_seconds)
        self.explorer: Explorer | FrontierExplorer = (
            Explorer(self, self.start_pose.xy)
            if self.built is None
            else FrontierExplorer(
                self, self.built, run.settings.config.time_model, run.settings.config.frontier_rule
            )
        )
        self.examined: set[int] = set()  # line 1
        self.unexamined: dict[int, ObjectInstance] = {}  # line 2
        self.revisits = self._remember(known)  # known objects back in UNEXAMINED
        self.n_room = 0  # examinations made in this room
        self.last_exam_clock = self.clock  # the run clock after the room's last examination
        self.new_since = self.clock  # the run clock when the replay (if any) was over
        self.left_early = False  # the budget ended the room (objects may be left unexamined)
        # what the examinations recognized (replays included): what the visit's rooms held
        det = run.settings.detector
        fp = det is not None and not det.perfect and det.fp_per_image > 0
        self.recognized = Recognized(det.fp_max_score if fp else 0.0)
        # the places of the small objects the run's previous map of this world remembers,
        # checked by this visit's images (agent.home.PlaceChecks; nothing on a given map)
        self.places = PlaceChecks(
            previous if self.built is not None else None, self.day, self.catalog, det,
            self.spec, self.body.width, self.body.height,
        )  # fmt: skip

    def _remember(self, known: Sequence[ObjectInstance]) -> int:
        """Lines 1-2 on a later day (see the module docstring): each known object goes into
        EXAMINED, or (``reexamine`` ``impact``) into UNEXAMINED when it is worth examining again;
        returns how many did."""
        if not known:
            return 0
        run = self.run
        if run.settings.config.reexamine == Reexamine.NEVER:
            self.examined.update(o.id for o in known)
            return 0
        kb = ForgetKnowledgeBase(self.catalog, self.kb.alpha, run.services.evidence, self.day,
                                 run.settings.config.forgetting, last_day=run.settings.config.days - 1)  # fmt: skip
        costs = EuclideanCosts(self.start_pose, run.settings.config.time_model)
        for o in sorted(known, key=lambda o: o.id):
            rate = kb.type_impact_now(o.type) / max(costs.examine_s(o), 1e-6)
            if rate >= run.settings.config.reexamine_rate:
                self.unexamined[o.id] = o
            else:
                self.examined.add(o.id)
        return len(self.unexamined)

    # ---- the map -----------------------------------------------------------------------------
    @property
    def grid(self) -> OccupancyGrid:
        """The grid the robot plans on: the true layout's, or its own map's as it stands."""
        return self.given_grid if self.built is None else self.built.grid

    @property
    def costs(self) -> GridCosts:
        """The strategies' cost model on the current grid."""
        if self._costs.grid is not self.grid:
            self._costs = GridCosts(
                self.grid, self.run.settings.config.time_model, self._gaze_seconds
            )
        return self._costs

    def _mapped(self, frame: Frame | None) -> None:
        """Add an image to the robot's own map (nothing on a given map)."""
        if self.built is not None:
            self.built.update(frame)

    # ---- time and motion ------------------------------------------------------------------
    @property
    def clock(self) -> float:
        """The run clock: seconds before this room plus the room's own."""
        return self.run.counters.clock_offset + (self.body.sim_time - self._t0)

    @property
    def room_elapsed(self) -> float:
        """Simulated seconds since the robot entered this room."""
        return self.body.sim_time - self._t0

    def budget_spent(self) -> bool:
        """True once the room's time budget (if any) is used up."""
        budget = self.run.settings.config.room_budget_s
        return budget is not None and self.room_elapsed >= budget

    def drive_to(self, xy: np.ndarray) -> None:
        """Drive along a planned path to ``xy``, facing along the last segment."""
        if drive_along(self.body, self.grid, xy):
            self.log.robot(self)

    def reference(self, obj: ObjectInstance) -> ObjectInstance | None:
        """``obj`` as a candidate reference (the perception's ``reference``: confirmed by as
        many images as the run asks), None while it may not be one."""
        return self.perception.reference(obj)

    def look(self, purpose: str) -> list[ObjectInstance]:
        """Take an image where the head points; what the perception recognizes in it."""
        frame = self.body.capture(rgb=self.log.recording, depth=True)
        self._mapped(frame)
        objs = self.perception.see(frame)
        self.places.observe(frame, self.perception.last_detections)
        self.log.frame(self, frame, objs, purpose=purpose)
        return objs

    # ---- Figure 2 ----------------------------------------------------------------------------
    def run_room(self) -> Iterator[ExamResult]:
        """Lines 3-21 until the room is done or its time budget is spent; yields every
        examination."""
        while not self._out_of_time():  # line 3, and limited time: leave the room
            if not self.unexamined and not self._find_unexamined():  # lines 4-7
                break
            choice = self._choose()  # lines 8-13
            del self.unexamined[choice.obj.id]  # line 14
            self.examined.add(choice.obj.id)
            gazes = self.plan_examination(choice.obj, self.body.pose())
            if not gazes and self._defer(choice.obj):  # a built map may still grow
                self.examined.discard(choice.obj.id)
                continue
            if not gazes:  # not a trial, no evidence (nor in the store: a replay skips it too)
                self._unexaminable(choice.obj)
                continue
            stored = self._stored_next(choice.obj)  # a replay: the store's examination
            related = self.examine(choice.obj, stored, gazes)  # lines 15-16
            self.recognized.add(choice.obj, related)
            self._record(choice, related, stored)  # lines 17-20
            for _, o in related:  # line 21 (a related object a reference only once confirmed)
                ref = self.reference(o) if o.id not in self.examined else None
                if ref is not None:
                    self.unexamined.setdefault(o.id, ref)
            yield self._done_exam(choice, related, len(gazes), stored)
        if self.n_room < len(self.prior):
            raise resume_error(
                self.layout,
                f"the store holds {len(self.prior)} examinations "
                f"of it, the replay left it after {self.n_room}",
            )

    def _defer(self, obj: ObjectInstance) -> bool:
        """On a built map with frontiers left: put ``obj`` aside until the next look-around."""
        if not isinstance(self.explorer, FrontierExplorer):
            return False
        self.explorer.seen.setdefault(obj.id, obj)  # it may have come from RELATED-OBJECTS
        return self.explorer.defer(obj.id)

    def _unexaminable(self, obj: ObjectInstance) -> None:
        self.log.text(
            self,
            f"{obj.type} #{obj.id} cannot be examined: "
            "no reachable viewpoint sees its relation volumes",
        )

    def _stored_next(self, obj: ObjectInstance) -> StoredExam | None:
        """The stored examination a replay makes next (None past the replay), checked to be of
        ``obj``."""
        if self.n_room >= len(self.prior):
            return None
        stored = self.prior[self.n_room]
        if stored.object_id != obj.id:
            raise resume_error(
                self.layout,
                f"the store says object {stored.object_id} was examined next, the replay chose "
                f"{obj.id}",
            )
        return stored

    def _out_of_time(self) -> bool:
        if self.budget_spent():
            self.left_early = True
        return self.left_early

    def _find_unexamined(self) -> bool:
        """Lines 4-7: find a recognizable object not in EXAMINED and put it in UNEXAMINED."""
        obj = self.explorer.find(self.examined)
        self.left_early |= self.explorer.out_of_time
        if obj is not None:
            self.unexamined[obj.id] = obj
        return obj is not None

    def _choose(self) -> Choice:
        """Lines 8-13: the strategy's choice among the UNEXAMINED objects."""
        if self.built is not None:
            self.built.refresh()  # plan and cost the choice on the map as it stands
        pose = self.body.pose()
        cands = [self.unexamined[i] for i in sorted(self.unexamined)]
        choice = strat.choose(
            self.run.services.strategy, self.kb, cands, pose, self.costs.at(pose), self.rng
        )
        if self.run.services.on_choice is not None:
            self.run.services.on_choice(self.kb, choice)
        self.log.choice(self, choice)
        return choice

    def plan_examination(self, obj: ObjectInstance, start: RobotPose) -> list[Gaze]:
        """The gazes (agent.viewplan) that cover the object's relation volumes, group by group;
        with ``exam_recall``, from viewpoints within the range it asks for where any sees the
        group (agent.exam_views), else from the planner's own range."""
        gazes: list[Gaze] = []
        pose = start
        tm = self.run.settings.config.time_model
        for box, _members in group_volume_members(relation_boxes(self.catalog, obj)):
            gs = []
            if self.exam_options is not None:
                gs = plan_gazes(self.grid, box, pose, self.spec, tm, self.exam_options)
            if not gs:
                gs = plan_gazes(self.grid, box, pose, self.spec, tm)
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
            t = sum(g.cost for g in gazes[1:]) + (
                self.run.settings.config.time_model.image_cost if gazes else 0.0
            )
            self._gaze_s[obj.id] = t
        return t

    def examine(
        self, obj: ObjectInstance, stored: StoredExam | None, gazes: Sequence[Gaze]
    ) -> Related:
        """Lines 15-16: execute the planned gazes, detect, decide the relations. With ``stored``
        (a replay) the motions are made, images are not taken, and the stored result is used."""
        self.log.examine_start(self, obj, gazes)
        if stored is not None and self._replays_by_images():
            return self._reexamine(obj, stored, gazes)
        if stored is not None:
            # A built map needs the depth images (the same clock: World.capture charges what
            # ReplayBody does); the given map needs none.
            body = self.body if self.built is not None else ReplayBody(self.body)
            for gaze in gazes:
                self._mapped(execute_gaze(body, self.grid, gaze, depth=True))
            return replayed_related(stored, self.layout.objects)
        seen: dict[int, ObjectInstance] = {}
        need_images = not self.perception.reads_truth or self.log.recording
        frames = []
        for gaze in gazes:
            frame = execute_gaze(self.body, self.grid, gaze, rgb=self.log.recording, depth=True)
            self._mapped(frame)
            self.log.robot(self)
            if need_images:
                objs = self.perception.see(frame)
                self.recognized.scores(self.perception.last_detections)
                self.places.observe(frame, self.perception.last_detections)
                seen.update((o.id, o) for o in objs)
                self.log.frame(self, frame, objs, purpose="examine")
                frames.append(frame)
        self._views = () if self.view_model is None else self.view_model.views(obj, frames)
        return self.perception.related(obj, list(seen.values()))

    def room_contents(self) -> list[tuple[int, str, int]]:
        """What the rooms of the robot's map held at the end of a house visit done to the end
        (knowledge.room_context): the recognized objects per segment of its map (the plan's
        rooms on a given map); none in a single room or a visit the budget ended early."""
        if not self.layout.is_house or self.left_early:
            return []
        b = self.built
        labels = RoomLabels.of_built(b) if b is not None else RoomLabels.of_plan(self.layout)
        return segment_contents(labels, self.recognized.objects(), self.catalog)

    def home_map(self) -> HomeMap | None:
        """What the robot keeps of the world at the end of a visit on its own map done to the
        end (agent.home): its built map, its rooms, the furniture and the small objects it
        recognised (each with its best confidence and the examinations that reported it), the
        remembered small objects no image showed, and its checks of the places of those the
        images showed (agent.home.PlaceChecks); None on a given map or a visit the budget ended
        early."""
        if self.built is None or self.left_early:
            return None
        rec, lay = self.recognized, self.layout
        seen = [
            RememberedObject(o.type, o.id, o.position, o.yaw, o.size,
                             min(1.0, rec.best.get(o.id, 1.0)), sum(rec.reports[o.id].values()))
            for o in rec.objects()
        ]  # fmt: skip
        furniture = [o for o in seen if self.catalog.type(o.type).is_furniture]
        small = [o for o in seen if not self.catalog.type(o.type).is_furniture]
        home = home_map(self.built, lay, self.day, furniture)
        return replace(
            home,
            small=tuple(sorted(small, key=lambda o: o.id)) + tuple(self.places.carried()),
            checks=tuple(self.places.checks()),
        )

    def _replays_by_images(self) -> bool:
        """A detector that errs reports poses and objects (false positives, look-alikes) the
        store does not hold (and ``confirm`` counts sightings): such a replay takes the images
        again (the same draws: the stream is keyed by the image's simulated second) instead of
        reading the stored relations."""
        det, run = self.run.settings.detector, self.run
        errs = det is not None and not det.perfect
        c = run.settings.config
        return run.services.perceive is None and (
            errs or c.confirm > 1 or c.min_score > 0 or c.confirm_reference > 1
        )

    def _reexamine(self, obj: ObjectInstance, stored: StoredExam, gazes: Sequence[Gaze]) -> Related:
        """A replayed examination made again with images, checked against the store."""
        seen: dict[int, ObjectInstance] = {}
        for gaze in gazes:
            frame = execute_gaze(self.body, self.grid, gaze, rgb=self.log.recording, depth=True)
            self._mapped(frame)  # the built map learns from these images as it did the first time
            seen.update((o.id, o) for o in self.perception.see(frame))
            self.recognized.scores(self.perception.last_detections)
            self.places.observe(frame, self.perception.last_detections)
        related = self.perception.related(obj, list(seen.values()))
        if sorted({(r, o.type, o.id) for r, o in related}) != sorted(set(stored.related)):
            raise resume_error(self.layout, f"examination of object {obj.id} saw other objects")
        return related

    def _record(self, choice: Choice, related: Related, stored: StoredExam | None) -> None:
        """Lines 17-20: one store transaction (not for a replayed examination), then the same
        counts in the knowledge base and the strategy."""
        obj, run = choice.obj, self.run
        if stored is None:
            run.services.store.append(
                NewExamination(
                    run.settings.key,
                    run.settings.style,
                    self.layout.seed,
                    obj.id,
                    obj.type,
                    self.clock,
                    run.services.strategy.name,
                    tuple(sorted({(r, o.type, o.id) for r, o in related})),
                    self.day,
                    self._views,
                )  # fmt: skip
            )
        self.kb.record_examination(obj.type, geometry.related_pairs(related))
        run.services.evidence.add(obj.type, self.day, geometry.related_pairs(related))
        run.services.strategy.observe(obj.type)

    def _done_exam(
        self, choice: Choice, related: Related, n_gazes: int, stored: StoredExam | None
    ) -> ExamResult:
        """Count the examination and advance the clocks; its result."""
        if stored is not None and self.n_room == 0:
            # The run clock of a replayed room comes from the store: the room started when its
            # first examination was stored minus the time the replay took to get there.
            self.run.counters.clock_offset += stored.sim_time - self.clock
        self.n_room += 1
        self.run.counters.examinations += 1
        self.last_exam_clock = self.clock
        if self.n_room == len(self.prior):
            self.new_since = self.clock
        return ExamResult(
            self.run.counters.examinations,
            self.room_index,
            self.layout.seed,
            choice,
            tuple(related),
            n_gazes,
            self.clock,
            replayed=stored is not None,
        )

    def close(self) -> None:
        """Release the perception's body (the renderer in camera mode)."""
        self.perception.close()


def view_model(run: Run, reads_truth: bool) -> ViewModel | None:
    """The model of what the run's images can show (agent.exam_views): for the camera
    perception with the simulated detector; None for the oracle and a user's own perception."""
    if reads_truth or run.services.perceive is not None:
        return None
    c = run.settings.config
    model = run.settings.detector or load_detector("perfect")
    return ViewModel(run.services.catalog, model, c.confirm, c.min_score)


def exam_options(run: Run, model: ViewModel | None, body: Body) -> GazePlanOptions | None:
    """The gaze planner's options for examinations planned to see (``exam_recall``; None:
    the planner's defaults). A one-line error without a model of the detector."""
    recall = run.settings.config.exam_recall
    if recall is None:
        return None
    if model is None:
        raise CtxsearchError(EXAM_RECALL_NEEDS_A_DETECTOR)
    spec = run.settings.config.spec
    w, h = body.width, body.height
    return GazePlanOptions(
        max_distance=model.exam_range(recall, focal_length(spec.fovy_deg, h), w, h)
    )
