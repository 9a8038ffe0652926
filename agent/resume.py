"""Resuming a stored run: what the evidence store already holds of it, and replaying a room.

A run is identified by (strategy, perception, seed, room budget) (agent.learning's ``run_id``).
Rooms marked done in the store are skipped; the run clock goes on from the end time the store
recorded for them (stores written before end times were recorded: from their last examination).
A room in progress is *replayed* from its start: the knowledge base as it was before the room,
the same rng, the same motions, the same budget checks; the examinations already in the store
are not perceived again but read back (and checked against the choices), so a resumed run makes
exactly the choices of an uninterrupted one.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from agent.interfaces import WrappedBody
from agent.run_state import ROOM_DONE, StoredExam
from agent.strategies import Strategy
from envs.layout import RoomLayout
from knowledge.base import KnowledgeBase
from knowledge.errors import CtxsearchError
from knowledge.geometry import ObjectInstance
from knowledge.store import EvidenceStore, Examination


@dataclass
class RunHistory:
    """What the store holds of one run in one style: room statuses, the examinations of its
    rooms in progress (to replay) and the last examination time of its done rooms."""

    status: dict[int, str] = field(default_factory=dict)  # room seed -> status
    in_progress: dict[int, list[Examination]] = field(default_factory=dict)
    last_exam: dict[int, float] = field(default_factory=dict)  # room seed -> last sim_time

    @classmethod
    def load(
        cls, store: EvidenceStore, run: str, style: str, kb: KnowledgeBase, strategy: Strategy
    ) -> RunHistory:
        """Read the store: every examination but those of the run's rooms in progress goes into
        ``kb`` (and, for the run's own, into ``strategy.observe``), as the knowledge before the
        first room to replay."""
        h = cls({seed: st for _r, sty, seed, st in store.rooms(run) if sty == style})
        started = {s for s, st in h.status.items() if st != ROOM_DONE}
        h.in_progress = {s: [] for s in started}
        for ex in store.examinations():
            mine = ex.run == run and ex.style == style
            if mine and ex.room_seed in started:
                h.in_progress[ex.room_seed].append(ex)
                continue
            _learn_from(ex, kb, strategy if ex.run == run else None)
            if mine:
                h.last_exam[ex.room_seed] = max(
                    h.last_exam.get(ex.room_seed, ex.sim_time), ex.sim_time
                )
        return h

    def is_done(self, seed: int) -> bool:
        """Whether room ``seed`` is done in the store."""
        return self.status.get(seed) == ROOM_DONE

    def done_clock(
        self, store: EvidenceStore, run: str, style: str, seed: int, clock: float
    ) -> float:
        """The run clock after done room ``seed``: its stored end time, else (schema version 1
        stores) its last examination's time (or ``clock`` without one)."""
        end = store.room_end_time(run, style, seed)
        if end is not None:
            return end
        return max(clock, self.last_exam.get(seed, clock))

    def replay(self, seed: int) -> list[StoredExam]:
        """The stored examinations of room ``seed`` in progress (empty for a new room); the room
        is then no longer held back."""
        return [
            StoredExam(e.object_id, e.type, e.related, e.sim_time)
            for e in self.in_progress.pop(seed, [])
        ]

    def release(self, kb: KnowledgeBase, strategy: Strategy) -> None:
        """Learn from the rooms in progress this call did not reach (beyond its rooms), as a
        call that goes through all its rooms ends knowing all the store's evidence."""
        for exams in self.in_progress.values():
            for ex in exams:
                _learn_from(ex, kb, strategy)
        self.in_progress.clear()


def _learn_from(ex: Examination, kb: KnowledgeBase, strategy: Strategy | None) -> None:
    kb.record_examination(ex.type, {(r, t) for r, t, _ in ex.related})
    if strategy is not None:
        strategy.observe(ex.type)


def replayed_related(
    stored: StoredExam, objects: Iterable[ObjectInstance]
) -> list[tuple[str, ObjectInstance]]:
    """RELATED-OBJECTS of a stored examination, as the room's objects."""
    by_id = {o.id: o for o in objects}
    return [(rel, by_id[i]) for rel, _t, i in stored.related]


def resume_error(layout: RoomLayout, what: str) -> CtxsearchError:
    """The one-line error of a replay that does not match the store."""
    return CtxsearchError(
        f"cannot resume room seed {layout.seed}: {what} (store written by other code or settings?)"
    )


class ReplayBody(WrappedBody):
    """A body whose images are not taken but charged (replayed examinations): it moves the
    wrapped body and charges its time model's ``image_cost`` per capture."""

    def capture(self, rgb: bool = False, depth: bool = True) -> None:
        """Charge one image; nothing is rendered."""
        self._b.sim_time += self.time_model.image_cost

    def close(self) -> None:
        """The wrapped body stays open (the room closes it)."""
