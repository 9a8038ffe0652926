"""The rerun recording of a learning run (agent.acquisition): one recording for the whole run."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Protocol

from ctxsearch.agent.exam_volumes import relation_boxes
from ctxsearch.agent.interfaces import Body, Perception
from ctxsearch.agent.recording import Recorder, Shot
from ctxsearch.agent.rr_layout import LEARN_APP, learn_blueprint
from ctxsearch.agent.run_state import ExamResult, Run
from ctxsearch.agent.strategies import Choice
from ctxsearch.agent.viewplan import Gaze
from ctxsearch.envs.camera import Frame, camera_at
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.geometry import ObjectInstance


class LoggedRoom(Protocol):
    """What the recording reads of a room being learned (agent.acquisition's RoomLearner)."""

    run: Run
    layout: RoomLayout
    room_index: int
    catalog: Catalog
    kb: KnowledgeBase
    spec: RobotSpec
    body: Body
    perception: Perception
    unexamined: Mapping[int, ObjectInstance]
    left_early: bool

    @property
    def clock(self) -> float:
        """The run clock."""
        ...


class RunLog:
    """What a run writes to rerun (agent.recording.Recorder): one file, one named recording,
    laid out by agent.rr_layout's ``learn_blueprint``.

    Every room in turn, on the run clock (``sim_time``): the room in 3D (furniture labelled),
    logged when the robot enters it and replacing the last one, the robot's path and head
    (camera pose), the camera as a pinhole with its RGB, segmentation and depth images and the
    detections for every gaze, the examined object's relation volumes highlighted, a text log of
    every choice with each candidate type's score, and time series of the mean interval width
    and of n for every type present in the rooms so far. Without a path nothing is recorded.
    """

    def __init__(self, path: str | Path | None):
        self.path = Path(path) if path is not None else None
        self.rec: Recorder | None = None
        self.files: list[Path] = []
        self._types: set[str] = set()
        self._in_room = False

    @property
    def recording(self) -> bool:
        """True while a room's recording is open: render RGB and look at every image."""
        return self.rec is not None and self._in_room

    def start_room(self, L: LoggedRoom) -> None:
        """Open the run's recording (the first room) and log the room, its start and the
        knowledge so far."""
        if self.path is None:
            return
        if self.rec is None:
            name = f"learn: {L.layout.style}, strategy {L.run.services.strategy.name}, run {L.run.settings.key}"
            self.rec = Recorder(
                self.path, LEARN_APP, name=name, blueprint=learn_blueprint(L.layout)
            )
            self.files.append(self.path)
        self._in_room = True
        self.rec.set_time(L.clock)
        self.rec.log_room(L.layout, L.catalog, static=False)
        self._types |= {o.type for o in L.layout.objects}
        self.rec.log_text(
            f"room {L.room_index} (style {L.layout.style}, seed {L.layout.seed}): "
            f"{len(L.layout.objects)} objects; run {L.run.settings.key}"
        )
        self.robot(L)
        self.knowledge(L)

    def end_room(self, L: LoggedRoom, n_exams: int) -> None:
        """The room's last line; the recording stays open for the next room."""
        if self.rec is None:
            return
        self.rec.set_time(L.clock)
        self.rec.log_text(
            f"room {L.room_index} done: {n_exams} examinations, "
            f"{L.clock - L.run.counters.clock_offset:.1f} s simulated"
            + (" (time budget spent: leaving)" if L.left_early else "")
        )
        self.rec.flush()
        self._in_room = False

    def robot(self, L: LoggedRoom) -> None:
        """The robot's base pose and path, and where the head points (camera pose)."""
        if self.rec is None:
            return
        pose = L.body.pose()
        self.rec.set_time(L.clock)
        self.rec.log_robot(pose, L.spec)
        self.rec.log_camera(Shot(camera_at(pose, L.spec)))

    def frame(
        self, L: LoggedRoom, frame: Frame | None, objs: Sequence[ObjectInstance], purpose: str
    ) -> None:
        """One image: the camera pinhole, RGB and segmentation (camera mode), detections."""
        if self.rec is None:
            return
        self.rec.set_time(L.clock)
        self.rec.log_robot(L.body.pose(), L.spec)
        if frame is None:  # oracle: the pose of the camera, no pixels
            self.rec.log_camera(Shot(camera_at(L.body.pose(), L.spec)))
        else:
            shot = Shot(
                frame.camera, rgb=frame.rgb, depth=frame.depth, instance_ids=frame.instance_ids
            )
            self.rec.log_camera(shot, L.perception.last_detections)
        if purpose == "look" and objs:
            self.rec.log_text(
                "look-around recognizes " + ", ".join(f"{o.type} #{o.id}" for o in objs),
                level="DEBUG",
            )

    def choice(self, L: LoggedRoom, choice: Choice) -> None:
        """The decision of lines 8-13 with every candidate type's score."""
        if self.rec is None:
            return
        self.rec.set_time(L.clock)
        ranked = sorted(choice.scores.items(), key=lambda kv: -kv[1])
        scores = ", ".join(f"{t} {s:.4f}" for t, s in ranked)
        n_unex = len(L.unexamined)
        self.rec.log_text(
            f"exam {L.run.counters.examinations + 1}: {L.run.services.strategy.name} chooses {choice.type} "
            f"(object #{choice.obj.id}) among {n_unex} unexamined; scores: {scores}"
        )

    def examine_start(self, L: LoggedRoom, obj: ObjectInstance, gazes: Sequence[Gaze]) -> None:
        """Highlight the examined object's relation volumes and show its planned gazes."""
        if self.rec is None:
            return
        rels = L.catalog.type(obj.type).relations
        self.rec.log_volumes(
            "world/volumes/examined",
            relation_boxes(L.catalog, obj),
            labels=[r.name for r in rels],
            color=(1.0, 0.85, 0.1),
            show_labels=False,  # on hover: the examined object's label says what is examined
        )
        self.rec.log_volumes(
            "world/volumes/examined_object",
            [obj.box()],
            labels=[f"examining {obj.type} #{obj.id}"],
            color=(1.0, 0.3, 0.1),
        )
        self.rec.log_text(
            f"examining {obj.type} #{obj.id}: {len(rels)} relation volumes, "
            f"{len(gazes)} gazes planned",
            level="DEBUG",
        )

    def examination(self, L: LoggedRoom, res: ExamResult) -> None:
        """The examination's outcome and the knowledge's new state."""
        if self.rec is None:
            return
        self.rec.set_time(L.clock)
        found = ", ".join(f"{r}({o.type} #{o.id})" for r, o in res.related) or "nothing"
        self.rec.log_text(f"{res.choice.obj.type} #{res.choice.obj.id}: {found}")
        self.knowledge(L)

    def text(self, L: LoggedRoom, msg: str) -> None:
        """A line in the text log."""
        if self.rec is None:
            return
        self.rec.set_time(L.clock)
        self.rec.log_text(msg, level="WARN")

    def knowledge(self, L: LoggedRoom) -> None:
        """Time series: mean interval width and n of every type present in the rooms so far."""
        if self.rec is None:
            return
        self.rec.log_scalar("knowledge/mean_width", L.kb.mean_width())
        for t in L.catalog.type_names:
            if t in self._types:
                self.rec.log_scalar(f"knowledge/n/{t}", L.kb.n(t))

    def __enter__(self) -> RunLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Close the recording (interrupted runs keep what was logged)."""
        if self.rec is not None:
            self.rec.close()
            self.rec = None
        self._in_room = False
