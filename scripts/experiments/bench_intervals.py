"""``ctxsearch bench intervals``: what detector errors and room correlation do to the intervals.

For every style and every detector setting (``SETTINGS``: ``perfect``, ``realistic``, and
``realistic`` with a related object counted only once two images of the room detected it, only
once a detection of it scored 0.5, with an object examined only once two images detected it, and
with examinations planned to see), HIF learns in camera mode over the same rooms for every seed
(``learning_trace.run_trace`` with clustered intervals, so the paper's Wilson figures are
measured beside them on the same evidence; the corrected intervals are read from the run's store
at the room marks, ``corrected_at``). After the last examination of room r for every r in
``room_marks``, against the ground truth (``envs.truth``):

- coverage_informative: the share of entries with n_A >= 1 and 0.02 <= p_true <= 0.98 whose
  interval holds p_true (nominal: 1 - alpha),
- mean |p0 - p_true| over every entry with ground truth,
- mean interval width over every entry with ground truth,

for ``wilson``, ``clustered`` and ``corrected``, and for the type hierarchy's backoff on the
Wilson and on the corrected intervals (``backoff``, ``backoff_corrected``: knowledge.pooling;
types in a class back off for the relations that map onto the class's); the bias per reference
type: the mean of
p0 - p_true over its informative entries (the detector's misses pull it down, its false
positives and confusions push it up), for Wilson's p0 and the corrected interval's centre; the
simulated seconds per examination and the examinations' expected recall of the object types
(``EXAM_CELLS``). Every cell is the median over seeds. Writes DIR/intervals.json,
DIR/intervals.md, and the same figures per seed in DIR/intervals.csv (``RUN_COLUMNS``) and
DIR/intervals_bias.csv (``BIAS_COLUMNS``). The ground truth's own noise counts against coverage:
its default of 400 rooms keeps its standard error (a median 0.01 in offices) small against the
intervals' half-widths.
"""

from __future__ import annotations

import functools
import json
import math
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.pooling import Backoff, PooledCounts
from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.experiments.bench_learning import ground_truth_units
from ctxsearch.scripts.experiments.learning_trace import (
    LearningBenchConfig,
    Trace,
    holds,
    informative,
    interval_metrics,
    run_trace,
)
from ctxsearch.scripts.experiments.tables import write_csv
from ctxsearch.scripts.sweep import SweepOptions, run_units, session

# (label, detector preset, confirm, min score, confirm reference, exam recall): the detector
# settings compared. ``confirm2`` counts a related object once two images detected it;
# ``score0.5`` once a detection of it scored 0.5; ``ref2`` examines an object once two images
# detected it; ``near0.9`` plans examinations to see (``learn --exam-recall 0.9``).
SETTINGS = (("perfect", "perfect", 1, 0.0, 1, None), ("realistic", "realistic", 1, 0.0, 1, None),
            ("realistic+confirm2", "realistic", 2, 0.0, 1, None),
            ("realistic+score0.5", "realistic", 1, 0.5, 1, None),
            ("realistic+ref2", "realistic", 1, 0.0, 2, None),
            ("realistic+confirm2+ref2", "realistic", 2, 0.0, 2, None),
            ("realistic+ref2+near0.9", "realistic", 1, 0.0, 2, 0.9))  # fmt: skip
DEFAULT_SETTINGS = ("perfect", "realistic", "realistic+confirm2", "realistic+score0.5",
                    "realistic+ref2", "realistic+confirm2+ref2", "realistic+ref2+near0.9")  # fmt: skip
# What an examination cost and could see: simulated seconds per examination (exploring
# included) and the mean expected recall of the object types (``expected_recall``).
EXAM_CELLS = ("seconds_per_examination", "expected_recall")
CELLS = (
    ("coverage_informative", "wilson_coverage_informative"),
    ("mean_abs_error", "wilson_mean_abs_error"),
    ("mean_width", "wilson_mean_width"),
)
# The type hierarchy's backoff (knowledge.pooling) on the Wilson and on the corrected intervals,
# from the same store at the same marks (``backoff_intervals``).
BACKOFFS = ("backoff", "backoff_corrected")


@dataclass(frozen=True)
class IntervalsBenchConfig:
    """What ``bench intervals`` runs."""

    styles: tuple[str, ...] = ("office", "apartment")
    room_marks: tuple[int, ...] = (10, 30)
    seeds: int = 3
    truth_samples: int = 400
    alpha: float = 0.10
    settings: tuple[str, ...] = DEFAULT_SETTINGS


def _run(marks: tuple[int, ...], truths: dict, alpha: float, unit: tuple[str, tuple, int]) -> Trace:
    """One sweep unit: the HIF camera run of (style, setting, seed) over max(marks) rooms; its
    trace, with the corrected intervals' figures at the room marks (``corrected_at``)."""
    rooms = max(marks)
    style, setting, seed = unit
    truth = truths[style]
    catalog = load_catalog()
    _, detector, confirm, min_score, confirm_reference, exam_recall = setting
    config = LearningBenchConfig(
        style, rooms, 1, ("hif",), perception="camera", alpha=alpha, detector=detector,
        interval="clustered", confirm=confirm, min_score=min_score,
        confirm_reference=confirm_reference, exam_recall=exam_recall,
    )  # fmt: skip
    shm = Path("/dev/shm")
    tmp_root = str(shm) if shm.is_dir() and os.access(shm, os.W_OK) else None
    with tempfile.TemporaryDirectory(prefix="ctxsearch-intervals-", dir=tmp_root) as tmp:
        tr = run_trace(config, seed, "hif", truth, catalog, Path(tmp), keep_counts=True)
        store = Path(tmp) / f"hif-{seed}.sqlite"
        tr.corrected = corrected_at(store, tr, [_at_room(tr, m) for m in marks], alpha)
        return tr


def corrected_at(store_path: Path, tr: Trace, ks: list[int], alpha: float) -> dict[int, dict]:
    """The corrected intervals (knowledge.corrected, read from the run's store) after each
    examination count k in ``ks``, against the trace's truth entries: {k: the metrics of
    ``interval_metrics`` and ``bias`` (mean estimate - p_true per reference type over its
    informative entries; the estimate is the interval's midpoint, as Wilson's p0 is)}."""
    catalog = load_catalog()
    p = np.array([e["p"] for e in tr.entries])
    refs = [e["ref"] for e in tr.entries]
    out: dict[int, dict] = {}
    with EvidenceStore.open(store_path, catalog, read_only=True) as store:
        exams = [(e.id, e.type, [(r, t) for r, t, _ in e.related]) for e in store.examinations()]
        ids = [e[0] for e in exams]
        for k in sorted(set(ks)):
            if not k:
                continue
            ci = store.corrected_intervals(alpha, upto=ids[k - 1])
            lo, hi = np.array(
                [ci.interval(e["ref"], e["relation"], e["type"]) for e in tr.entries]
            ).T
            centre = (lo + hi) / 2
            n = tr.counts[k - 1][1]
            row = interval_metrics(lo, hi, centre, p, n)
            inf = informative(p, n)
            row["bias"] = {
                r: float(np.mean(centre[m] - p[m]))
                for r in sorted(set(refs))
                if (m := inf & (np.array(refs) == r)).any()
            }
            row["held"] = held_by_type(lo, hi, p, inf, refs)
            pooled = PooledCounts.from_examinations(
                catalog.hierarchy, ((t, pairs) for _, t, pairs in exams[:k])
            )
            for name, bo in (("backoff", Backoff(pooled, alpha)),
                             ("backoff_corrected", Backoff(pooled, alpha, ci))):  # fmt: skip
                lo, hi, centre = backoff_intervals(bo, tr.entries, catalog)
                row.update({f"{name}_{key}": v
                            for key, v in interval_metrics(lo, hi, centre, p, n).items()})  # fmt: skip
            row["expected_recall"] = expected_recall(store.exam_views(upto=ids[k - 1]), catalog)
            row["seconds_per_examination"] = float(tr.sim_s[k - 1]) / k
            out[k] = row
    return out


def backoff_intervals(
    bo: Backoff, entries: list[dict], catalog
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(low, high, estimate) of every truth entry under the backoff ``bo`` (on the Wilson or the
    corrected intervals): a type in a class whose relation maps onto the class's reads its
    backed-off interval (estimate: its midpoint), every other entry its own interval: on the
    corrected intervals ``bo.estimate`` gives it (an entry that borrows nothing keeps its
    corrected interval), on Wilson's the interval with its centre p0."""
    h, out = catalog.hierarchy, []
    for e in entries:
        ref, rel, b = e["ref"], e["relation"], e["type"]
        if bo.corrected is not None or (h.parent(ref) is not None and h.lift(rel) is not None):
            est = bo.estimate(ref, rel, b)
            out.append((est.low, est.high, (est.low + est.high) / 2))
        else:
            y, n = bo.pooled.y.get((ref, rel, b), 0), bo.pooled.n.get(ref, 0)
            lo, hi = intervals.interval(y, n, bo.alpha)
            out.append((float(lo), float(hi), float(intervals.p0(y, n, bo.alpha))))
    lo, hi, centre = np.array(out, float).T
    return lo, hi, centre


def expected_recall(views: dict, catalog) -> float:
    """The mean, over examinations, of the expected recall of the catalog's object (not
    furniture) types averaged over the examination's relation volumes (agent.exam_views; NaN
    without views)."""
    objects = [i for i, t in enumerate(catalog.types) if not t.is_furniture]
    per_exam = [v.q[:, :, objects].mean(axis=(1, 2)) for v in views.values() if v.n]
    return float(np.mean(np.concatenate(per_exam))) if per_exam else math.nan


def _corrected(tr: Trace, k: int, metric: str) -> float:
    """The corrected intervals' ``metric`` after examination k (NaN if not measured)."""
    return float(tr.corrected.get(k, {}).get(metric, math.nan))


def _at_room(tr: Trace, room: int) -> int:
    """Examinations made by the end of room ``room`` (1-based; all if the run was shorter)."""
    return int(sum(tr.room_exams[:room]))


def phantom_share(tr: Trace, k: int) -> float:
    """The share of the first ``k`` examinations whose reference the room does not hold under
    the type it was examined as (a false positive or a look-alike; NaN before any)."""
    return float(np.mean(tr.phantom[:k])) if k else math.nan


def held_by_type(lo, hi, p_true, inf, refs: list[str]) -> dict[str, list[int]]:
    """Per reference type, [informative entries whose interval holds p_true, informative
    entries]: coverage per type, pooled over seeds by summing."""
    held = holds(lo, hi, p_true)
    r = np.array(refs)
    return {
        t: [int((held & m).sum()), int(m.sum())]
        for t in sorted(set(refs))
        if (m := inf & (r == t)).any()
    }


def _held_wilson(tr: Trace, k: int, truth_p: np.ndarray, refs: list[str], alpha: float) -> dict:
    """``held_by_type`` of Wilson's intervals after examination k."""
    y, n = tr.counts[k - 1]
    lo, hi = intervals.interval(y, n, alpha)
    return held_by_type(np.asarray(lo), np.asarray(hi), truth_p, informative(truth_p, n), refs)


def _pooled_coverage(helds: list[dict[str, list[int]]]) -> dict[str, list[float]]:
    """Per reference type, [coverage pooled over the seeds, informative entries summed]."""
    out: dict[str, list[float]] = {}
    for t in sorted({t for h in helds for t in h}):
        a = sum(h[t][0] for h in helds if t in h)
        b = sum(h[t][1] for h in helds if t in h)
        out[t] = [a / b, b]
    return out


def _bias(tr: Trace, k: int, truth_p: np.ndarray, refs: list[str], alpha: float) -> dict:
    """Mean p0 - p_true per reference type over its informative entries after examination k."""
    y, n = tr.counts[k - 1]
    p0 = intervals.p0(y, n, alpha)
    inf = informative(truth_p, n)
    out = {}
    for r in sorted(set(refs)):
        m = inf & (np.array(refs) == r)
        if m.any():
            out[r] = float(np.mean(p0[m] - truth_p[m]))
    return out


def bench_intervals(
    config: IntervalsBenchConfig,
    out: str | Path,
    progress: bool = True,
    sweep: SweepOptions | None = None,
) -> dict:
    """Run the benchmark; write DIR/intervals.json, DIR/intervals.md, DIR/intervals.csv and
    DIR/intervals_bias.csv; the JSON document. The runs (style x setting x
    seed) are the units of a sweep (scripts.sweep: serial, or Ray tasks with ``sweep.workers``);
    the files are the same either way."""
    catalog = load_catalog()
    sweep = sweep or SweepOptions()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    settings = [s for s in SETTINGS if s[0] in config.settings]
    doc: dict = {
        "alpha": config.alpha,
        "seeds": config.seeds,
        "room_marks": list(config.room_marks),
        "truth_samples": config.truth_samples,
        "strategy": "hif",
        "perception": "camera",
        "rows": [],
    }
    units = [
        (st, se, seed) for st in config.styles for se in settings for seed in range(config.seeds)
    ]
    with session(sweep):  # one Ray start for the truths' units and the runs
        truths = {
            s: ground_truth_units(s, config.truth_samples, catalog, sweep, progress)
            for s in config.styles
        }
        t0 = time.perf_counter()
        done = run_units(
            functools.partial(_run, tuple(config.room_marks), truths, config.alpha),
            units,
            workers=sweep.workers,
            ray_address=sweep.ray_address,
            desc="bench intervals",
            progress=progress,
        )
    by_unit = dict(zip(units, done, strict=True))
    runs: list[dict] = []  # intervals.csv: one row per (style, detector, seed, room mark)
    bias_rows: list[dict] = []  # intervals_bias.csv: one row per those and reference type
    for style in config.styles:
        for setting in settings:
            traces = [by_unit[(style, setting, s)] for s in range(config.seeds)]
            for mark in config.room_marks:
                head = {"style": style, "detector": setting[0], "rooms": mark}
                doc["rows"].append(_mark_row(head, traces, config.alpha, runs, bias_rows))
    if progress:
        print(f"bench intervals: {time.perf_counter() - t0:.0f} s wall", flush=True)
    (out / "intervals.json").write_text(json.dumps(doc, indent=1) + "\n")
    (out / "intervals.md").write_text(markdown(doc))
    write_csv(out / "intervals.csv", RUN_COLUMNS, runs)
    write_csv(out / "intervals_bias.csv", BIAS_COLUMNS, bias_rows)
    return doc


# intervals.csv: the cells of intervals.json per seed (the JSON holds their medians).
RUN_COLUMNS = (
    "style",
    "detector",
    "seed",
    "rooms",  # the room mark: figures after this many rooms
    "examinations",
    *(f"{name}_{key}" for key, _ in CELLS for name in ("clustered", "wilson", "corrected")),
    *(f"{name}_{key}" for key, _ in CELLS for name in BACKOFFS),
    "phantom_reference_share",
    *EXAM_CELLS,
)
# intervals_bias.csv: mean p0 - p_true over a reference type's informative entries, per seed
# (Wilson's p0; ``bias_corrected``: the corrected interval's centre).
BIAS_COLUMNS = ("style", "detector", "seed", "rooms", "examinations", "ref_type", "bias",
                "bias_corrected")  # fmt: skip


def _seed_cells(tr: Trace, k: int) -> dict[str, float]:
    """One seed's figures after examination k: the phantom share, each cell under the clustered,
    Wilson and corrected intervals, and ``EXAM_CELLS``."""
    cells = {"phantom_reference_share": phantom_share(tr, k)}
    for ck, wk in CELLS:
        cells[f"clustered_{ck}"] = float(tr.at_exam(k, ck))
        cells[f"wilson_{ck}"] = float(tr.at_exam(k, wk))
        cells[f"corrected_{ck}"] = _corrected(tr, k, ck)
        cells.update({f"{b}_{ck}": _corrected(tr, k, f"{b}_{ck}") for b in BACKOFFS})
    cells.update({name: _corrected(tr, k, name) for name in EXAM_CELLS})
    return cells


def _median_by_type(biases: list[dict[str, float]]) -> dict[str, float]:
    """Per reference type, the median over seeds of the biases that have it."""
    types = sorted({r for b in biases for r in b})
    return {r: float(np.median([b[r] for b in biases if r in b])) for r in types}


def _mark_row(
    head: dict, traces: list[Trace], alpha: float, runs: list[dict], bias_rows: list[dict]
) -> dict:
    """intervals.json's row of one (style, setting, room mark) ``head``: every cell the median
    over the seeds' ``traces``; each seed's figures appended to ``runs`` (intervals.csv) and its
    bias per type to ``bias_rows`` (intervals_bias.csv)."""
    refs = [e["ref"] for e in traces[0].entries]
    truth_p = np.array([e["p"] for e in traces[0].entries])
    ks = [_at_room(t, head["rooms"]) for t in traces]
    seeds = [_seed_cells(t, k) for t, k in zip(traces, ks, strict=True)]
    biases = [_bias(t, k, truth_p, refs, alpha) for t, k in zip(traces, ks, strict=True)]
    cbias = [t.corrected.get(k, {}).get("bias", {}) for t, k in zip(traces, ks, strict=True)]
    row = {**head, "examinations": float(np.median(ks))}
    row.update({name: float(np.nanmedian([c[name] for c in seeds])) for name in seeds[0]})
    row["bias_by_type_corrected"] = _median_by_type(cbias)
    row["bias_by_type"] = _median_by_type(biases)
    row["coverage_by_type"] = _pooled_coverage(
        [_held_wilson(t, k, truth_p, refs, alpha) for t, k in zip(traces, ks, strict=True)]
    )
    row["coverage_by_type_corrected"] = _pooled_coverage(
        [t.corrected.get(k, {}).get("held", {}) for t, k in zip(traces, ks, strict=True)]
    )
    for seed, (k, cells, bias, cb) in enumerate(zip(ks, seeds, biases, cbias, strict=True)):
        key = {"style": head["style"], "detector": head["detector"], "seed": seed,
               "rooms": head["rooms"], "examinations": k}  # fmt: skip
        runs.append({**key, **cells})
        bias_rows.extend({**key, "ref_type": ref, "bias": b,
                          "bias_corrected": cb.get(ref, math.nan)} for ref, b in bias.items())  # fmt: skip
    return row


def markdown(doc: dict) -> str:
    """intervals.md: the table of coverage_informative, mean |p0 - p_true| and mean width."""
    lines = [
        "# Intervals against the ground truth: detector x interval method",
        "",
        f"HIF in camera mode, {doc['seeds']} seeds (medians), alpha {doc['alpha']} (nominal "
        f"coverage {1 - doc['alpha']:.2f}), ground truth from {doc['truth_samples']} rooms. "
        "Coverage is over the informative entries (n_A >= 1, 0.02 <= p_true <= 0.98); error and "
        "width over every entry with ground truth. Phantom references: the share of "
        "examinations whose reference the room does not hold under the type it was examined as "
        "(false positives, look-alikes). Corrected: the recall-aware interval (knowledge.corrected, "
        "read from each run's store). s per exam: simulated seconds per examination, exploring "
        "included; expected recall: the mean over examinations of the object types' expected "
        "recall in the relation volumes (agent.exam_views).",
        "",
        "| style | detector | rooms | exams | coverage_informative wilson | clustered | "
        "corrected | mean abs(p0 - p_true) wilson | clustered | corrected | mean width wilson | "
        "clustered | corrected | phantom references | s per exam | expected recall |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in doc["rows"]:
        cells = [
            f"{r.get(f'{m}_{key}', math.nan):{fmt}}"
            for key, fmt in (
                ("coverage_informative", ".3f"),
                ("mean_abs_error", ".4f"),
                ("mean_width", ".3f"),
            )  # fmt: skip
            for m in ("wilson", "clustered", "corrected")
        ]
        lines.append(
            f"| {r['style']} | {r['detector']} | {r['rooms']} | {r['examinations']:.0f} | "
            + " | ".join(cells)
            + f" | {r.get('phantom_reference_share', math.nan):.3f}"
            + f" | {r.get('seconds_per_examination', math.nan):.1f}"
            + f" | {r.get('expected_recall', math.nan):.3f} |"
        )
    lines += ["", "## The type hierarchy's backoff, on the Wilson and on the corrected intervals",
              "", "Types in a class read their backed-off interval for the relations that map "
              "onto the class's (knowledge.pooling; every type keeps all its evidence), every "
              "other entry its own interval.", "",
              "| style | detector | rooms | coverage_informative backoff | backoff corrected | "
              "mean abs(p0 - p_true) backoff | backoff corrected | mean width backoff | "
              "backoff corrected |", "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in doc["rows"]:
        cells = [f"{r.get(f'{b}_{key}', math.nan):{fmt}}"
                 for key, fmt in (("coverage_informative", ".3f"), ("mean_abs_error", ".4f"),
                                  ("mean_width", ".3f")) for b in BACKOFFS]  # fmt: skip
        lines.append(
            f"| {r['style']} | {r['detector']} | {r['rooms']} | " + " | ".join(cells) + " |"
        )
    lines += ["", "## Bias of p0 (Wilson centre) per reference type: mean p0 - p_true over its "
              "informative entries, at the last room mark", ""]  # fmt: skip
    last = max(doc["room_marks"])
    rows = [r for r in doc["rows"] if r["rooms"] == last]
    types = sorted({t for r in rows for t in r["bias_by_type"]})
    lines.append("| style | detector | " + " | ".join(types) + " |")
    lines.append("|---" * (2 + len(types)) + "|")
    for r in rows:
        cells = [f"{r['bias_by_type'][t]:+.3f}" if t in r["bias_by_type"] else "-" for t in types]
        lines.append(f"| {r['style']} | {r['detector']} | " + " | ".join(cells) + " |")
    lines += ["", "## Bias of the corrected interval's centre per reference type: mean centre - "
              "p_true over the same entries",
              "", "| style | detector | " + " | ".join(types) + " |",
              "|---" * (2 + len(types)) + "|"]  # fmt: skip
    for r in rows:
        b = r.get("bias_by_type_corrected", {})
        cells = [f"{b[t]:+.3f}" if t in b else "-" for t in types]
        lines.append(f"| {r['style']} | {r['detector']} | " + " | ".join(cells) + " |")
    lines += ["", "## Coverage per reference type at the last room mark: the share of its "
              "informative entries (pooled over the seeds; their count in brackets) whose "
              "interval holds p_true, Wilson / corrected; below 0.90 in bold", "",
              "| style | detector | " + " | ".join(types) + " |",
              "|---" * (2 + len(types)) + "|"]  # fmt: skip
    for r in rows:
        w, c = r.get("coverage_by_type", {}), r.get("coverage_by_type_corrected", {})
        cells = [_coverage_cell(w.get(t), c.get(t)) for t in types]
        lines.append(f"| {r['style']} | {r['detector']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _coverage_cell(wilson: list[float] | None, corrected: list[float] | None) -> str:
    """'0.85 / **0.88** (40)': a type's Wilson and corrected coverage (below 0.90 in bold) and
    its informative entries."""
    if wilson is None:
        return "-"

    def one(x: list[float] | None) -> str:
        if x is None:
            return "-"
        return f"**{x[0]:.2f}**" if x[0] < 0.90 else f"{x[0]:.2f}"

    return f"{one(wilson)} / {one(corrected)} ({int(wilson[1])})"
