"""Resuming a stored run: what the evidence store already holds of it, and replaying a room.

A run is identified by (strategy, perception, seed, room budget) (agent.learning's ``run_id``).
A visit is a room on one day (``learn --days``; day 0 alone without it). Visits marked done in
the store are skipped; the run clock goes on from the end time the store
recorded for them (stores written before end times were recorded: from their last examination).
A room in progress is *replayed* from its start: the knowledge base as it was before the room,
the same rng, the same motions, the same budget checks; the examinations already in the store
are not perceived again but read back (and checked against the choices), so a resumed run makes
exactly the choices of an uninterrupted one.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from ctxsearch.agent.interfaces import WrappedBody
from ctxsearch.agent.run_state import ROOM_DONE, StoredExam
from ctxsearch.agent.strategies import Strategy
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.drift import DayEvidence
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.store import EvidenceStore, Examination


@dataclass
class RunHistory:
    """What the store holds of one run in one style: visit statuses, the examinations of its
    visits in progress (to replay) and the last examination time of its done visits. A visit
    is (room seed, day)."""

    status: dict[tuple[int, int], str] = field(default_factory=dict)  # visit -> status
    in_progress: dict[tuple[int, int], list[Examination]] = field(default_factory=dict)
    last_exam: dict[tuple[int, int], float] = field(default_factory=dict)  # visit -> sim_time
    evidence: DayEvidence = field(default_factory=DayEvidence.empty)  # the run's, by day

    @classmethod
    def load(
        cls, store: EvidenceStore, run: str, style: str, kb: KnowledgeBase, strategy: Strategy
    ) -> RunHistory:
        """Read the store: every examination but those of the run's visits in progress goes into
        ``kb`` (and, for the run's own, into ``strategy.observe`` and ``evidence``), as the
        knowledge before the first visit to replay."""
        h = cls({(seed, day): st for _r, sty, seed, day, st in store.visits(run) if sty == style})
        started = {v for v, st in h.status.items() if st != ROOM_DONE}
        h.in_progress = {v: [] for v in started}
        for ex in store.examinations():
            mine = ex.run == run and ex.style == style
            visit = (ex.room_seed, ex.day)
            if mine and visit in started:
                h.in_progress[visit].append(ex)
                continue
            _learn_from(ex, kb, strategy if ex.run == run else None)
            if mine:
                h.evidence.add(ex.type, ex.day, {(r, t) for r, t, _ in ex.related})
                h.last_exam[visit] = max(h.last_exam.get(visit, ex.sim_time), ex.sim_time)
        return h

    def is_done(self, seed: int, day: int = 0) -> bool:
        """Whether room ``seed``'s visit on ``day`` is done in the store."""
        return self.status.get((seed, day)) == ROOM_DONE

    def done_clock(
        self, store: EvidenceStore, run: str, style: str, seed: int, clock: float, day: int = 0
    ) -> float:
        """The run clock after done visit (``seed``, ``day``): its stored end time, else (schema
        version 1 stores) its last examination's time (or ``clock`` without one)."""
        end = store.room_end_time(run, style, seed, day)
        if end is not None:
            return end
        return max(clock, self.last_exam.get((seed, day), clock))

    def replay(self, seed: int, day: int = 0) -> list[StoredExam]:
        """The stored examinations of visit (``seed``, ``day``) in progress (empty for a new
        visit); the visit is then no longer held back."""
        return [
            StoredExam(e.object_id, e.type, e.related, e.sim_time)
            for e in self.in_progress.pop((seed, day), [])
        ]

    def release(self, kb: KnowledgeBase, strategy: Strategy) -> None:
        """Learn from the visits in progress this call did not reach (beyond its rooms or
        days), as a call that goes through all its visits ends knowing all the store's
        evidence."""
        for exams in self.in_progress.values():
            for ex in exams:
                _learn_from(ex, kb, strategy)
                self.evidence.add(ex.type, ex.day, {(r, t) for r, t, _ in ex.related})
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
