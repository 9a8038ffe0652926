"""Where each policy's probabilities come from (the registry's ``needs``): the learned knowledge
store, read as intervals (``open_knowledge``) or pooled over the type hierarchy (backoff), or the
ground truth estimated from the style (``truth_probabilities``, the oracle-prior policies only).
The rooms a store learned in are never searched (``learned_seeds``). The persistence of the
remembered sightings (the registry's ``memory``) comes from the store's maps' checks (learned,
knowledge.persistence) or from the true worlds (``true_persistence``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search.config import KnowledgeConfig
from ctxsearch.agent.search.registry import PolicySpec
from ctxsearch.agent.search.truth_store import cached_ground_truth, cached_room_truth
from ctxsearch.envs.houses import HouseStyle, WorldStyle, resolve_style
from ctxsearch.envs.truth import RoomKindTruth, load_truth, near_counts, room_kind_truth
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.files import InputFileError, regular_file_exists
from ctxsearch.knowledge.options import Estimate, Handed, IntervalMethod, Needs, Rank
from ctxsearch.knowledge.persistence import (
    LearnedPersistence,
    Persistence,
    TruePersistence,
    store_persistence,
)
from ctxsearch.knowledge.pooling import PooledCounts
from ctxsearch.knowledge.room_context import RoomContext
from ctxsearch.knowledge.store import EvidenceStore


def learned_seeds(store: EvidenceStore) -> set[int]:
    """Room seeds the store has evidence from (any run, any style: stricter than needed)."""
    return {int(seed) for _run, _style, seed, _status in store.rooms()}


def store_seeds(path: Path | str | None, catalog: Catalog) -> set[int]:
    """``learned_seeds`` of the store at ``path`` (none for no store)."""
    if path is None:
        return set()
    with EvidenceStore.open(Path(path), catalog, read_only=True) as store:
        return learned_seeds(store)


def open_knowledge(
    path: Path | str,
    catalog: Catalog,
    alpha: float | None = None,
    interval: IntervalMethod | str = IntervalMethod.WILSON,
) -> tuple[KnowledgeBase, set[int]]:
    """The knowledge base of the evidence store at ``path`` and the room seeds it learned in
    (its intervals read with ``interval``).

    One-line errors (CtxsearchError): no such file, not a store or another catalog's (StoreError
    from the store), a store without examinations."""
    p = Path(path)
    try:  # a directory, FIFO or device is named as such, not called missing
        exists = regular_file_exists(p)
    except InputFileError as exc:
        raise CtxsearchError(f"{p}: {exc.problem} (a knowledge store is a file)") from None
    if not exists:
        raise CtxsearchError(
            f"{p}: no such knowledge store (make one with: ctxsearch learn --kb {p} ...)"
        )
    with EvidenceStore.open(p, catalog, alpha=alpha, read_only=True) as store:
        kb = store.knowledge_base(interval=interval)
        learned = learned_seeds(store)
    if kb.total_examinations == 0:
        raise CtxsearchError(
            f"{p}: the knowledge store is empty (no examinations); run ctxsearch learn first"
        )
    return kb, learned


def open_room_context(path: Path | str, catalog: Catalog) -> RoomContext:
    """The room context learned in the store at ``path`` (knowledge.room_context)."""
    with EvidenceStore.open(Path(path), catalog, read_only=True) as store:
        return store.room_context()


def open_pooled(path: Path | str, catalog: Catalog) -> PooledCounts:
    """The evidence of the store at ``path`` pooled over the catalog's hierarchy (for the backoff
    estimate); the store's one-line errors as ``open_knowledge``."""
    with EvidenceStore.open(Path(path), catalog, read_only=True) as store:
        return PooledCounts.from_store(store)


def truth_probabilities(
    style: WorldStyle | str,
    catalog: Catalog,
    samples: int = 200,
    seed: int = 0,
    path: str | Path | None = None,
    progress: bool = False,
    rooms: bool = False,
) -> ss.TableProbabilities:
    """Ground-truth P(rel(B)) for the oracle-prior policies: read from ``ctxsearch truth``'s JSON
    at ``path`` if given, else estimated over ``samples`` generated rooms of ``style`` (a
    progress bar on stderr with ``progress``; kept on disk: agent.search.truth_store). With ``rooms``, also the room context of the
    same ``samples`` worlds (``envs.truth.room_truth``; counted from the plans, also when the
    relations come from ``path``)."""
    world = resolve_style(style, catalog) if isinstance(style, str) else style
    if path is not None:
        doc = load_truth(path, catalog, world.name)
    else:
        doc = cached_ground_truth(world, samples, seed, catalog, progress)
    table = ss.TableProbabilities.from_truth(doc)
    if rooms:
        rt = cached_room_truth(world, samples, seed, catalog)
        table = table.with_rooms(rt.same_room, rt.room_share, rt.next_room)
    return table


TRUE_PERSISTENCE_WORLDS = 60  # sample worlds of the true persistence (``true_persistence``)


def true_persistence(
    style: WorldStyle, catalog: Catalog, worlds: int = TRUE_PERSISTENCE_WORLDS
) -> TruePersistence:
    """The true value of what the robot learns, P(STILL-WHERE-SEEN(T) after 1 day): over
    ``worlds`` sample worlds of the style (seeds 0 .. worlds-1), the share of day 0's instances
    of each small type with an instance of it within the persistence radius on day 1
    (envs.truth.near_counts; a type no sample holds: its stay probability),
    to the power of the days. Not the stay probability itself: a cup that moved is often
    replaced by another where cups go (cups stay with 0.2, and 0.54 of the places where a cup
    stood hold one the next day in apartments)."""
    counts = near_counts(style, catalog, worlds)
    rooms = [st for st, _ in style.rooms] if isinstance(style, HouseStyle) else [style]

    def stay(type_name: str) -> float:
        n, near = counts.get(type_name, (0, 0))
        if n:
            return near / n
        place = [st for st in rooms if type_name in st.types] or rooms
        return sum(st.stay(type_name, catalog) for st in place) / len(place)

    return TruePersistence(stay)


@dataclass(frozen=True)
class Priors:
    """Where each policy's probabilities come from: the learned knowledge or the ground truth."""

    kb: KnowledgeBase | None
    learned: frozenset[int]  # room seeds the knowledge was learned in (never searched)
    rank: Rank  # the rank of policies named without one
    truth: ss.ProbabilitySource | None
    pooled: PooledCounts | None = None  # evidence over the hierarchy: the backoff estimate
    min_evidence: int = ss.DEFAULT_MIN_EVIDENCE
    room_context: RoomContext | None = None  # learned room context (knowledge.room_context)
    persistence: Persistence | None = None  # learned (the store's maps' checks), if a policy has it
    true_persistence: Persistence | None = None  # the true worlds', if a policy has it
    # the true target density by room kind, if a bound is handed the rooms (envs.truth)
    kinds: RoomKindTruth | None = None

    def check(self, specs: tuple[PolicySpec, ...]) -> None:
        """A one-line error if a policy needs a knowledge store and none was given."""
        for s in specs:
            if s.needs is Needs.KB and self.kb is None:
                raise CtxsearchError(f"policy '{s.base}' needs a knowledge store (--kb)")

    def for_policy(self, spec: PolicySpec) -> ss.ProbabilitySource | None:
        """The probabilities policy ``spec`` ranks by (its rank or the run's), if any."""
        if spec.needs is Needs.KB:
            rooms = len(self.learned) or None
            r = spec.rank or self.rank
            if self.pooled is not None:
                probs = ss.BackoffProbabilities(self.kb, self.pooled, r, rooms, self.min_evidence)
            else:
                probs = ss.KBProbabilities(self.kb, r, rooms=rooms)
            return probs.with_room_context(self.room_context)
        if spec.needs is Needs.TRUTH:
            return self.truth
        return None

    def kinds_for(self, spec: PolicySpec) -> RoomKindTruth | None:
        """The true density by room kind, for a bound handed the rooms (else None)."""
        return self.kinds if spec.info.handed is Handed.ROOMS else None

    def persistence_for(self, spec: PolicySpec) -> Persistence | None:
        """The persistence policy ``spec`` weighs its remembered sightings by (None: no memory)."""
        if spec.memory is Needs.KB:
            return self.persistence
        if spec.memory is Needs.TRUTH:
            return self.true_persistence
        return None


@dataclass(frozen=True)
class KnowledgeSource:
    """Knowledge given in memory (a KnowledgeBase) instead of the configuration's store, and
    room seeds never to search besides the store's."""

    kb: KnowledgeBase | None = None
    exclude_seeds: frozenset[int] = frozenset()


NO_KNOWLEDGE = KnowledgeSource()  # the configuration's store alone


def make_priors(
    specs: tuple[PolicySpec, ...],
    style: WorldStyle,
    catalog: Catalog,
    knowledge: KnowledgeConfig,
    source: KnowledgeSource = NO_KNOWLEDGE,
    progress: bool = False,
) -> Priors:
    """The priors of the policies ``specs``: the knowledge of ``source`` or else of the store
    ``knowledge.kb`` (whose learning rooms join ``source.exclude_seeds``), read as
    ``knowledge`` says, and the ground truth if an oracle-prior policy runs (estimated with a
    progress bar on stderr if ``progress``). With the backoff estimate the evidence is also
    pooled over the hierarchy (from the store's log, or from the knowledge base's counts)."""
    learned = set(source.exclude_seeds)
    kb, pooled, path = source.kb, None, knowledge.kb
    backoff = knowledge.estimate is Estimate.BACKOFF
    if kb is None and path is not None:
        kb, seeds = open_knowledge(path, catalog, interval=knowledge.interval)
        learned |= seeds
        if backoff:
            pooled = open_pooled(path, catalog)
    elif kb is not None and backoff:
        pooled = PooledCounts.from_knowledge_base(kb)
    truth = None
    if any(s.needs is Needs.TRUTH for s in specs):
        truth = truth_probabilities(
            style, catalog, knowledge.truth_samples, path=knowledge.truth, progress=progress,
            rooms=knowledge.room_context,
        )  # fmt: skip
    rooms = None
    if knowledge.room_context and path is not None and kb is not None:
        rooms = open_room_context(path, catalog)
        if rooms.rooms == 0 and any(s.needs is Needs.KB for s in specs):
            raise CtxsearchError(
                f"{path}: --room-context: the store holds no room context (it is "
                "learned in houses, by ctxsearch learn from schema 6 on)"
            )
    persistence = true = None
    if any(s.memory is Needs.KB for s in specs):
        persistence = LearnedPersistence(())  # nothing learned: every sighting at 1/2
        if path is not None:
            with EvidenceStore.open(Path(path), catalog, read_only=True) as store:
                persistence = store_persistence(store)
    if any(s.memory is Needs.TRUTH for s in specs):
        true = true_persistence(style, catalog)
    kinds = None
    if any(s.info.handed is Handed.ROOMS for s in specs) and isinstance(style, HouseStyle):
        kinds = room_kind_truth(style, knowledge.truth_samples, catalog)
    priors = Priors(
        kb, frozenset(learned), knowledge.rank, truth, pooled, knowledge.min_evidence, rooms,
        persistence, true, kinds,
    )  # fmt: skip
    priors.check(specs)
    return priors
