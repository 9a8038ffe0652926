"""One learning run measured against the ground truth after every examination.

``TruthTracker`` keeps the counts of the (A, rel, B) entries that have ground truth and the
metrics of their intervals against p_true; ``run_trace`` runs ``agent.learning.learn`` in a
fresh store and records, per examination, the metrics, the simulated second, and how the
strategy's pick relates to what hif, expected-hif and fewest would have picked.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ctxsearch.agent.learning import LearnConfig, learn, style_layouts
from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.clustered import ClusteredIntervals, RoomCounts
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import DEFAULT_CONFIRM_REFERENCE, IntervalMethod, PerceptionMode

METRICS = ("mean_width", "max_width", "mean_abs_error", "coverage_informative", "coverage")
# Under --interval clustered, the paper's Wilson figures beside the clustered ones.
WILSON_METRICS = tuple(
    f"wilson_{m}" for m in ("mean_width", "mean_abs_error", "coverage_informative")
)
INFORMATIVE_P = (0.02, 0.98)  # p_true range of the entries coverage_informative counts
EXAM_MARKS = (10, 25, 50, 100, 200, 400)
TIME_FRACTIONS = (0.25, 0.5, 1.0)  # of the shortest run's simulated time
WIDTH_GOALS = (0.6, 0.5, 0.4, 0.3)  # mean widths whose first simulated second is tabulated
TIME_GRID = 400  # points of the simulated-time grid for time averages


def informative(p_true: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(E,) bool: the entries coverage_informative counts: their A examined (n_A >= 1) and
    0.02 <= p_true <= 0.98 (an entry with p_true 0 or 1, or never examined, cannot miss)."""
    lo, hi = INFORMATIVE_P
    return (np.asarray(n) >= 1) & (np.asarray(p_true) >= lo) & (np.asarray(p_true) <= hi)


def holds(lo, hi, p_true) -> np.ndarray:
    """(E,) bool: the intervals [lo, hi] that hold p_true (to float rounding)."""
    return (lo <= p_true + 1e-12) & (p_true <= hi + 1e-12)


def interval_metrics(lo, hi, centre, p_true, n) -> dict[str, float]:
    """mean/max width, mean |p0 - p_true|, coverage over all entries and over the informative
    ones (NaN where there are none)."""
    w = hi - lo
    held = holds(lo, hi, p_true)
    inf = informative(p_true, n)
    return {
        "mean_width": float(w.mean()),
        "max_width": float(w.max()),
        "mean_abs_error": float(np.abs(centre - p_true).mean()),
        "coverage": float(held.mean()),
        "coverage_informative": float(held[inf].mean()) if inf.any() else float("nan"),
    }


class TruthTracker:
    """Counts for the (A, rel, B) entries that have ground truth, updated per examination, and the
    metrics of their intervals against p_true (vectorised over the entries). With ``interval``
    'clustered' it also keeps every type's per-room counts (all pairs, as the evidence log
    would give them) and measures the clustered intervals, the Wilson figures beside them."""

    def __init__(self, truth: dict, catalog: Catalog, alpha: float, interval: str = "wilson"):
        entries = [
            e
            for e in truth["entries"]
            if e["ref"] in catalog and e["type"] in catalog and catalog.has_relation(e["relation"])
        ]
        if not entries:
            raise CtxsearchError("the ground truth has no entries for this catalog")
        self.alpha = alpha
        self.entries = entries
        self.p = np.array([float(e["p"]) for e in entries])
        self.key = {(e["relation"], e["type"]): i for i, e in enumerate(entries)}
        refs = sorted({e["ref"] for e in entries})
        self.by_ref = {
            r: np.array([i for i, e in enumerate(entries) if e["ref"] == r]) for r in refs
        }
        self.n = np.zeros(len(entries))
        self.y = np.zeros(len(entries))
        self.interval = interval
        self.refs = [e["ref"] for e in entries]
        self.pairs = [(e["relation"], e["type"]) for e in entries]
        # Per reference type: examinations per room, and per pair the examinations per room.
        self.n_room: dict[str, dict[int, int]] = {}
        self.y_room: dict[str, dict[tuple[str, str], dict[int, int]]] = {}
        self._counts: dict[str, RoomCounts] = {}  # clustered(): per type, until it changes

    def record(self, ref_type: str, pairs, room: int = 0) -> None:
        """One examination of a ``ref_type`` object in room ``room`` that saw ``pairs``
        (relation, type)."""
        idx = self.by_ref.get(ref_type)
        if idx is not None:
            self.n[idx] += 1
        for pair in set(pairs):
            i = self.key.get(pair)
            if i is not None:
                self.y[i] += 1
        if self.interval == IntervalMethod.CLUSTERED:
            self._counts.pop(ref_type, None)
            per = self.n_room.setdefault(ref_type, {})
            per[room] = per.get(room, 0) + 1
            ys = self.y_room.setdefault(ref_type, {})
            for pair in set(pairs):
                cell = ys.setdefault(pair, {})
                cell[room] = cell.get(room, 0) + 1

    def clustered(self) -> ClusteredIntervals:
        """The clustered intervals of the evidence so far (knowledge.clustered)."""
        counts = {}
        for ref, per in self.n_room.items():
            if ref in self._counts:  # unchanged since the last call (its design effects kept)
                counts[ref] = self._counts[ref]
                continue
            rooms = sorted(per)
            col = {r: j for j, r in enumerate(rooms)}
            ys = {}
            for pair, cell in self.y_room.get(ref, {}).items():
                arr = np.zeros(len(rooms), np.int64)
                for r, v in cell.items():
                    arr[col[r]] = v
                ys[pair] = arr
            counts[ref] = RoomCounts(np.array([per[r] for r in rooms], np.int64), ys)
            self._counts[ref] = counts[ref]
        return ClusteredIntervals(counts, self.alpha)

    def metrics(self) -> dict[str, float]:
        """The interval's metrics over the entries (``interval_metrics``); under 'clustered',
        the Wilson figures beside them (``WILSON_METRICS``)."""
        lo, hi = intervals.interval(self.y, self.n, self.alpha)
        c = intervals.p0(self.y, self.n, self.alpha)
        wilson = interval_metrics(lo, hi, c, self.p, self.n)
        if self.interval != IntervalMethod.CLUSTERED:
            return wilson
        cl = self.clustered()
        f = np.array(
            [
                cl.shrink(a, k) if n else 1.0
                for a, k, n in zip(self.refs, self.pairs, self.n, strict=True)
            ]
        )
        ye, ne = self.y / f, self.n / f
        lo, hi = intervals.interval(ye, ne, self.alpha)
        c = intervals.p0(ye, ne, self.alpha)
        out = interval_metrics(lo, hi, c, self.p, self.n)
        out.update(
            {
                f"wilson_{k}": wilson[k]
                for k in ("mean_width", "mean_abs_error", "coverage_informative")
            }
        )
        return out


@dataclass
class Trace:
    """One (strategy, seed) run: metrics after every examination."""

    sim_s: list[float] = field(default_factory=list)
    metrics: dict[str, list[float]] = field(
        default_factory=lambda: {m: [] for m in METRICS + WILSON_METRICS}
    )
    wall_s: float = 0.0
    initial: dict[str, float] = field(default_factory=dict)  # before any examination
    room_objects: list[int] = field(default_factory=list)  # objects in room i
    room_exams: list[int] = field(default_factory=list)  # examinations made in room i
    rooms_left_early: int = 0  # rooms the time budget ended
    # One row per choice among at least two candidate types: does the pick agree with what
    # hif, expected-hif and fewest would pick from the same knowledge; was a less-examined type
    # on offer; and was it a quirk pick: the pick's n is larger than the least-examined
    # candidate's, yet impact(0, n) - the term that dominates the average, most y being 0 -
    # is larger for it (eq. 3 is not monotonic in n).
    decisions: list[tuple[bool, bool, bool, bool, bool]] = field(default_factory=list)
    # Under --interval clustered, per such choice: would HIF pick the same type with impact on
    # the effective counts (y/f, n/f)?
    effective_same: list[bool] = field(default_factory=list)
    # With run_trace(keep_counts=True): the truth entries and their (y, n) after every exam.
    entries: list[dict] = field(default_factory=list)
    counts: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    # Per examination: was its reference a phantom, an object the room does not hold under the
    # type it was examined as (a false positive, or a look-alike reported as another type)?
    phantom: list[bool] = field(default_factory=list)
    # bench intervals: the corrected intervals' metrics after examination k, read from the run's
    # store (scripts.experiments.bench_intervals.corrected_at).
    corrected: dict[int, dict] = field(default_factory=dict)

    def at_exam(self, k: int, metric: str) -> float:
        """The metric after examination k (1-based), or NaN past the end."""
        vals = self.metrics[metric]
        return vals[k - 1] if 0 < k <= len(vals) else float("nan")

    def at_time(self, t: float, metric: str) -> float:
        """The metric after the last examination finished by simulated second t (before the
        first one: its value for the empty knowledge, NaN if that was not recorded)."""
        k = int(np.searchsorted(np.asarray(self.sim_s), t, side="right"))
        return self.at_exam(k, metric) if k > 0 else self.initial.get(metric, float("nan"))

    def time_mean(self, t_end: float, metric: str) -> float:
        """The metric averaged over simulated time 0..t_end (a uniform grid)."""
        return float(np.mean([self.at_time(t, metric) for t in np.linspace(0, t_end, TIME_GRID)]))

    def time_to(self, goal: float, metric: str = "mean_width") -> float:
        """The simulated second the metric first reaches ``goal`` or below (NaN: never)."""
        vals = np.asarray(self.metrics[metric])
        hit = np.flatnonzero(vals <= goal)
        return float(self.sim_s[hit[0]]) if len(hit) else float("nan")

    def examined_shares(self) -> list[float]:
        """Per room: examinations over the objects in the room."""
        return [e / o for e, o in zip(self.room_exams, self.room_objects, strict=False) if o]

    def exams_by(self, t: float) -> int:
        """Examinations finished by simulated second t."""
        return int(np.searchsorted(np.asarray(self.sim_s), t, side="right"))

    def run_mean(self, metric: str, k: int) -> float:
        """The metric averaged over examinations 1..k (the area under its curve, per exam)."""
        return float(np.mean(self.metrics[metric][:k])) if k else float("nan")


@dataclass(frozen=True)
class LearningBenchConfig:
    """What ``bench learning`` runs: every strategy on the same rooms for every seed."""

    style: str
    rooms: int
    seeds: int
    strategies: tuple[str, ...]
    perception: str = "oracle"
    truth_samples: int = 300
    alpha: float = 0.10
    room_budget_s: float | None = (
        None  # simulated seconds per room (None: every room to completion)
    )
    detector: str | None = None  # camera mode's preset (None: realistic; oracle: none)
    interval: str = "wilson"  # the intervals measured: wilson or clustered
    confirm: int = 1  # camera mode: images that must detect a related object
    confirm_reference: int = (
        DEFAULT_CONFIRM_REFERENCE  # camera mode: images that must detect a reference
    )
    exam_recall: float | None = None  # camera mode: examinations planned to see (agent.exam_views)
    min_score: float = 0.0  # camera mode: the confidence a detection must reach to count

    @property
    def detector_name(self) -> str:
        """The detector the results were made with ('none' for the oracle perception)."""
        if self.perception != PerceptionMode.CAMERA:
            return "none"
        from ctxsearch.envs.detector import load_detector

        return load_detector(self.detector or "realistic").name

    @property
    def budget_note(self) -> str:
        """', room budget B s' when rooms have a budget, else ''."""
        return "" if self.room_budget_s is None else f", room budget {self.room_budget_s:g} s"


class _Hooks:
    """``learn``'s callbacks of one traced run: they fill ``trace``."""

    def __init__(
        self, trace: Trace, tracker: TruthTracker, generate, catalog: Catalog, keep: bool = False
    ):
        self.trace, self.tracker, self.generate, self.keep = trace, tracker, generate, keep
        self.order = {t: i for i, t in enumerate(catalog.type_names)}
        self.types: dict[int, dict[int, str]] = {}  # room index -> its objects' true types

    def layouts(self, index, seed):
        """The room ``index`` (seed ``seed``), its object count noted."""
        tr = self.trace
        layout = self.generate(index, seed)
        self.types[index] = {o.id: o.type for o in layout.objects}
        while len(tr.room_objects) <= index:
            tr.room_objects.append(0)
            tr.room_exams.append(0)
        tr.room_objects[index] = len(layout.objects)
        return layout

    def on_choice(self, kb, choice) -> None:
        """Note how the pick relates to hif's, expected-hif's and fewest's (2+ candidates)."""
        order = self.order
        types = sorted(choice.scores, key=order.__getitem__)
        if len(types) < 2:
            return
        hif = kb.choose(types)
        exp = kb.choose(types, fn=intervals.expected_width_change)
        few = min(types, key=lambda t: (kb.n(t), order[t]))
        c = choice.type
        n_min = min(kb.n(t) for t in types)
        n_c = kb.n(c)
        better_known = n_c > n_min
        quirk = better_known and float(intervals.impact(0, n_c, kb.alpha)) > float(
            intervals.impact(0, n_min, kb.alpha)
        )
        self.trace.decisions.append((c == hif, c == exp, c == few, better_known, quirk))
        if self.tracker.interval == IntervalMethod.CLUSTERED:
            kb.use_clustered(self.tracker.clustered())
            try:
                scores = [kb.type_score_effective(t) for t in types]
            finally:
                kb.use_clustered(None)
            self.trace.effective_same.append(types[int(np.argmax(scores))] == hif)

    def on_exam(self, res, kb) -> None:
        """Record one examination and the metrics after it."""
        tr = self.trace
        tr.room_exams[res.room_index] += 1
        obj = res.choice.obj
        tr.phantom.append(self.types.get(res.room_index, {}).get(obj.id) != obj.type)
        self.tracker.record(res.choice.obj.type, res.pairs, res.room_index)
        tr.sim_s.append(res.sim_time)
        for k, v in self.tracker.metrics().items():
            tr.metrics[k].append(v)
        if self.keep:
            tr.counts.append((self.tracker.y.copy(), self.tracker.n.copy()))


def run_trace(
    config: LearningBenchConfig,
    seed: int,
    strategy: str,
    truth: dict,
    catalog: Catalog,
    workdir: Path,
    keep_counts: bool = False,
) -> Trace:
    """One learn run of ``strategy`` in a fresh store, measured after every examination
    (``keep_counts``: also the truth entries' counts after every examination, in the trace)."""
    rooms, perception, alpha = config.rooms, config.perception, config.alpha
    room_budget_s = config.room_budget_s
    tracker = TruthTracker(truth, catalog, alpha, config.interval)
    tr = Trace(initial=tracker.metrics())
    style, generate = style_layouts(config.style, catalog)
    hooks = _Hooks(tr, tracker, generate, catalog, keep_counts)
    if keep_counts:
        tr.entries = list(tracker.entries)
    layouts, on_exam, on_choice = hooks.layouts, hooks.on_exam, hooks.on_choice
    t0 = time.perf_counter()
    summary = learn(
        LearnConfig(
            style,
            rooms,
            workdir / f"{strategy}-{seed}.sqlite",
            strategy=strategy,
            perception=perception,
            alpha=alpha,
            seed=seed,
            progress=False,
            room_budget_s=room_budget_s,
            detector=config.detector,
            confirm=config.confirm,
            confirm_reference=config.confirm_reference,
            exam_recall=config.exam_recall,
            min_score=config.min_score,
        ),
        catalog=catalog,
        layouts=layouts,
        on_examination=on_exam,
        on_choice=on_choice,
    )
    tr.wall_s = time.perf_counter() - t0
    tr.rooms_left_early = summary.rooms_left_early
    return tr


def median_curve(traces: list[Trace], metric: str) -> list[float]:
    """The median over ``traces`` of ``metric`` (or "sim_s") at every examination all reached."""
    k = min(len(t.sim_s) for t in traces)
    if metric == "sim_s":
        arr = np.array([t.sim_s[:k] for t in traces])
    else:
        arr = np.array([t.metrics[metric][:k] for t in traces])
    if not k:
        return []
    with warnings.catch_warnings():  # all-NaN columns (no informative entry yet) stay NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(arr, axis=0)
    return [None if not np.isfinite(v) else float(v) for v in med]
