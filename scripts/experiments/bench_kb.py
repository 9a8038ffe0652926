"""Benchmark of the knowledge base at the paper's scale (``ctxsearch bench kb``).

The paper (section 6) calls 30 000 object types infeasible for its O(T^2) representation. This
benchmark builds synthetic catalogs of T types with 6 relations each and gives every type and
relation min(1% of T, ``MAX_RELATED`` = 100) related types with random counts (each 1 <= y <= n_A,
n_A random in [10, 1000]): 1% of all types while the catalog is small, a bounded number as it grows
(a realistic sparsity: at 100 000 types a fixed 1% would be 600 million counts). It measures:

- ``choose_ms``: one Highest-Impact-First choice among 50 candidate types, *cold*: every
  candidate has just had a ``record_examination`` (which invalidates its cached score), so all 50
  scores are recomputed from the counts. ``choose_cached_ms`` is the same choice again, cached.
- ``record_ms``: one ``record_examination`` with 5 distinct related (relation, type) pairs.
- ``peak_mb``: the peak of memory traced by ``tracemalloc`` (Python objects and numpy buffers)
  while building the catalog and the filled knowledge base and running one choice and one
  record. ``rss_mb`` is the process's maximum resident set size so far (``resource``), which
  includes the interpreter, numpy and tracemalloc's own bookkeeping.
- ``dense_choose_ms``: the same cold choice with a straightforward dense implementation (an n
  vector and a dense y array of shape (T, 6, T), scores from ``intervals.impact`` over all 6*T
  pairs of a candidate), where that array fits (T <= 1000); ``dense_ratio`` = dense / ours.

Times are medians over repetitions, measured with tracemalloc off. Pure numpy: no MuJoCo.
"""

from __future__ import annotations

import gc
import json
import os
import platform
import resource
import statistics
import time
import tracemalloc
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.catalog import Catalog, ObjectType, RelationSpec
from ctxsearch.scripts.experiments.tables import write_csv

DEFAULT_SIZES = (100, 1000, 10_000, 30_000, 100_000)
# At most this many related types per (type, relation): a realistic sparsity as the catalog grows
# (a desk has things on it of a few dozen kinds, not of 1% of every type there is: at 100 000 types
# a fixed 1% would be 600 million counts). None: the fixed density alone.
MAX_RELATED = 100
RELATION_PREFIXES = ("ON-TOP-OF", "UNDER", "NEAR", "LEFT-OF", "RIGHT-OF", "BEHIND")
DENSE_MAX_TYPES = 1000
ROW_KEYS = ("types", "choose_ms", "record_ms", "peak_mb", "dense_choose_ms")


def synthetic_catalog(n_types: int, relations_per_type: int = 6) -> Catalog:
    """An in-memory catalog of ``n_types`` types named T00000, T00001, ... with the same relations.

    Volumes and sizes are shared tuples: the benchmark is about counts, not geometry.
    """
    if not 1 <= relations_per_type <= len(RELATION_PREFIXES):
        raise ValueError(f"relations_per_type must be in 1..{len(RELATION_PREFIXES)}")
    lo, hi, zero = (-0.5, -0.5, -0.5), (0.5, 0.5, 0.5), (0.0, 0.0, 0.0)
    size, color = (0.5, 0.5, 0.5), (0.5, 0.5, 0.5)
    width = max(5, len(str(n_types - 1)))
    prefixes = RELATION_PREFIXES[:relations_per_type]
    types = []
    for i in range(n_types):
        name = f"T{i:0{width}d}"
        suffix = name.upper()
        rels = tuple(RelationSpec(f"{p}-{suffix}", name, lo, hi, zero, zero) for p in prefixes)
        types.append(ObjectType(name, "object", "box", size, size, color, 50, 5.0, rels))
    return Catalog(tuple(types), path=f"<synthetic T={n_types}>")


def fill_random(
    kb: KnowledgeBase,
    density: float,
    rng: np.random.Generator,
    max_related: int | None = MAX_RELATED,
) -> None:
    """Give every type n_A in [10, 1000] and, per relation, min(round(density * T),
    ``max_related``) (at least 1) related types with 1 <= y <= n_A.

    Drawn type by type and loaded through ``add_count_arrays``, so nothing of size O(nonzero)
    exists outside the knowledge base.
    """
    T = len(kb.catalog)
    per_rel = max(1, round(density * T))
    if max_related is not None:
        per_rel = min(per_rel, max_related)
    for t in kb.catalog.types:
        R = len(t.relations)
        n = int(rng.integers(10, 1001))
        rels = np.repeat(np.arange(R), per_rel)
        others = np.concatenate(
            [np.sort(rng.choice(T, size=per_rel, replace=False)) for _ in range(R)]
        )
        kb.add_count_arrays(t.name, n, rels, others, rng.integers(1, n + 1, R * per_rel))


class DenseKB:
    """The straightforward implementation: n (T,) and a dense y array (T, R, T)."""

    def __init__(
        self, n_types: int, relations_per_type: int, alpha: float = intervals.DEFAULT_ALPHA
    ):
        self.alpha = alpha
        self.n = np.zeros(n_types, np.int64)
        self.y = np.zeros((n_types, relations_per_type, n_types), np.int32)

    @classmethod
    def from_kb(cls, kb: KnowledgeBase) -> DenseKB:
        """A dense copy of a knowledge base whose types all have the same number of relations."""
        cat = kb.catalog
        index = {name: i for i, name in enumerate(cat.type_names)}
        dense = cls(len(cat), len(cat.types[0].relations), kb.alpha)
        for a, t in enumerate(cat.types):
            dense.n[a] = kb.n(t.name)
            rels = t.relation_names
            for (rel, b), v in kb.nonzero(t.name).items():
                dense.y[a, rels.index(rel), index[b]] = v
        return dense

    def record_examination(self, a: int, pairs: np.ndarray) -> None:
        """n_a += 1, and y[a, r, b] += 1 for each distinct (r, b) row of ``pairs``."""
        self.n[a] += 1
        pairs = np.unique(pairs, axis=0)
        self.y[a, pairs[:, 0], pairs[:, 1]] += 1

    def type_impact(self, a: int) -> float:
        """Average impact over all R*T pairs of type a."""
        return float(np.mean(intervals.impact(self.y[a], self.n[a], self.alpha)))

    def choose(self, cands: list[int]) -> int:
        """The candidate with the largest average impact (first in index order on ties)."""
        cands = sorted(cands)
        return cands[int(np.argmax([self.type_impact(a) for a in cands]))]


def _median_ms(samples: list[float]) -> float:
    return 1000.0 * statistics.median(samples)


def _rss_mb() -> float:
    """The process's maximum resident set size so far, in MiB (Linux reports KiB)."""
    ru = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return ru / 1024.0 if platform.system() == "Linux" else ru / (1024.0 * 1024.0)


def bench_size(
    n_types: int,
    *,
    relations_per_type: int = 6,
    density: float = 0.01,
    candidates: int = 50,
    pairs_per_record: int = 5,
    reps: int = 21,
    seed: int = 0,
    max_related: int | None = MAX_RELATED,
) -> dict:
    """One row of the benchmark (see the module docstring for what each key means)."""
    rng = np.random.default_rng([seed, n_types])
    cand_idx = np.sort(rng.choice(n_types, size=min(candidates, n_types), replace=False))
    kb, nonzero, peak_mb, build_s = _build_traced(
        n_types, (relations_per_type, density, max_related), cand_idx, rng
    )
    # Pre-drawn examinations: for each rep and candidate, pairs_per_record distinct (r, b).
    m = relations_per_type * n_types
    draws = [
        [np.sort(rng.choice(m, size=min(pairs_per_record, m), replace=False)) for _ in cand_idx]
        for _ in range(reps)
    ]
    record_s, cold_s, cached_s, choice = _time_ours(kb, cand_idx, draws)
    row = {
        "types": n_types,
        "choose_ms": _median_ms(cold_s),
        "record_ms": _median_ms(record_s),
        "peak_mb": peak_mb,
        "dense_choose_ms": None,
        "choose_cached_ms": _median_ms(cached_s),
        "dense_record_ms": None,
        "dense_ratio": None,
        "dense_mb": None,
        "relations_per_type": relations_per_type,
        "nonzero": nonzero,
        "density": nonzero / (m * n_types),
        "max_related": max_related,
        "candidates": len(cand_idx),
        "reps": reps,
        "build_s": build_s,
        "rss_mb": _rss_mb(),
    }
    if n_types <= DENSE_MAX_TYPES:
        row.update(_time_dense(kb, cand_idx, draws, choice))
        row["dense_ratio"] = row["dense_choose_ms"] / row["choose_ms"]
    del kb
    gc.collect()
    return row


def _build_traced(
    n_types: int,
    sparsity: tuple[int, float, int | None],
    cand_idx: np.ndarray,
    rng: np.random.Generator,
) -> tuple[KnowledgeBase, int, float, float]:
    """The filled knowledge base (``sparsity``: relations per type, density, related types per
    relation at most), its nonzero counts, the peak traced MiB of building it and running one
    choice and one record, and the seconds the build took."""
    relations_per_type, density, max_related = sparsity
    gc.collect()
    tracemalloc.start()
    tracemalloc.reset_peak()
    t0 = time.perf_counter()
    catalog = synthetic_catalog(n_types, relations_per_type)
    kb = KnowledgeBase(catalog)
    fill_random(kb, density, rng, max_related)
    build_s = time.perf_counter() - t0
    nonzero = kb.nnz()  # the synthetic counts, before the records add more
    names = catalog.type_names
    cand_names = [names[a] for a in cand_idx]
    kb.choose(cand_names)
    rels0 = catalog.types[int(cand_idx[0])].relation_names
    kb.record_examination(cand_names[0], [(rels0[0], names[0])])
    peak_mb = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    gc.collect()
    return kb, nonzero, peak_mb, build_s


def _time_ours(kb: KnowledgeBase, cand_idx: np.ndarray, draws: list) -> tuple:
    """Per rep: a record_examination per candidate, then a cold and a cached choice. The
    seconds of each (record, cold, cached) and the last choice."""
    catalog = kb.catalog
    n_types = len(catalog)
    names = catalog.type_names
    cand_names = [names[a] for a in cand_idx]
    record_s, cold_s, cached_s = [], [], []
    choice = None
    for rep_draws in draws:
        for j, a in enumerate(cand_idx):
            rels = catalog.types[int(a)].relation_names
            pairs = [(rels[c // n_types], names[c % n_types]) for c in rep_draws[j]]
            t = time.perf_counter()
            kb.record_examination(names[a], pairs)
            record_s.append(time.perf_counter() - t)
        t = time.perf_counter()
        choice = kb.choose(cand_names)  # cold: every candidate's score was invalidated above
        cold_s.append(time.perf_counter() - t)
        t = time.perf_counter()
        kb.choose(cand_names)
        cached_s.append(time.perf_counter() - t)
    return record_s, cold_s, cached_s, choice


def _time_dense(kb: KnowledgeBase, cand_idx: np.ndarray, draws: list, choice: str) -> dict:
    """The dense implementation on the same counts as ``kb`` now holds (after the timed records,
    so both choose alike): its choose and record times and its size."""
    names = kb.catalog.type_names
    n_types = len(names)
    dense = DenseKB.from_kb(kb)
    d_choice = dense.choose([int(a) for a in cand_idx])
    if names[d_choice] != choice:
        ours = kb.type_impact(choice)
        theirs = dense.type_impact(d_choice)
        if abs(ours - theirs) > 1e-9:
            raise AssertionError(f"dense and sparse disagree: {names[d_choice]} vs {choice}")
    dense_s, dense_rec_s = [], []
    for rep_draws in draws:
        t = time.perf_counter()
        dense.choose([int(a) for a in cand_idx])
        dense_s.append(time.perf_counter() - t)
        for j, a in enumerate(cand_idx):
            c = rep_draws[j]
            pairs = np.column_stack([c // n_types, c % n_types])
            t = time.perf_counter()
            dense.record_examination(int(a), pairs)
            dense_rec_s.append(time.perf_counter() - t)
    return {
        "dense_choose_ms": _median_ms(dense_s),
        "dense_record_ms": _median_ms(dense_rec_s),
        "dense_mb": dense.y.nbytes / 2**20,
    }


def run(
    sizes: tuple[int, ...] = DEFAULT_SIZES,
    *,
    reps: int = 21,
    candidates: int = 50,
    density: float = 0.01,
    seed: int = 0,
    progress=None,
    max_related: int | None = MAX_RELATED,
) -> list[dict]:
    """Every size's row, smallest first. ``progress(row)`` is called after each size."""
    rows = []
    for T in sizes:
        row = bench_size(
            int(T), density=density, candidates=candidates, reps=reps, seed=seed,
            max_related=max_related,
        )  # fmt: skip
        rows.append(row)
        if progress is not None:
            progress(row)
    return rows


def _fmt(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def markdown_table(rows: list[dict]) -> str:
    """The rows as a Markdown table."""
    head = (
        "| types | nonzero y | choose (cold) ms | choose (cached) ms | record ms | peak MB "
        "| dense choose ms | dense / ours | dense y MB | max RSS MB |"
    )
    sep = "|" + "---:|" * 10
    lines = [head, sep]
    for r in rows:
        lines.append(
            f"| {r['types']:,} | {r['nonzero']:,} | {r['choose_ms']:.3f} | {r['choose_cached_ms']:.4f} "
            f"| {r['record_ms']:.3f} | {r['peak_mb']:.1f} | {_fmt(r['dense_choose_ms'], '.3f')} "
            f"| {_fmt(r['dense_ratio'], '.1f')} | {_fmt(r['dense_mb'], '.1f')} | {r['rss_mb']:.0f} |"
        )
    return "\n".join(lines)


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def _environment() -> str:
    return (
        f"Python {platform.python_version()}, numpy {np.__version__}, {platform.system()} "
        f"{platform.machine()}, {_cpu_model()} ({os.cpu_count()} logical CPUs)"
    )


# bench_kb.csv: one row per catalog size, the keys of ``bench_size``'s row (empty: not run).
KB_COLUMNS = (
    "types",
    "relations_per_type",
    "nonzero",
    "density",
    "max_related",
    "candidates",
    "reps",
    "choose_ms",
    "choose_cached_ms",
    "record_ms",
    "peak_mb",
    "rss_mb",
    "build_s",
    "dense_choose_ms",
    "dense_record_ms",
    "dense_ratio",
    "dense_mb",
)


def write_results(
    rows: list[dict], out_dir: str | Path, command: str = "ctxsearch bench kb"
) -> dict[str, Path]:
    """Write bench_kb.json (the rows), bench_kb.csv (the same rows: one per catalog size,
    ``KB_COLUMNS``), bench_kb.md (table + method) and bench_kb.png (plot)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / "bench_kb.json", "md": out / "bench_kb.md", "png": out / "bench_kb.png"}
    paths["json"].write_text(json.dumps(rows, indent=2) + "\n")
    paths["csv"] = write_csv(out / "bench_kb.csv", KB_COLUMNS, rows)
    r0 = rows[0] if rows else {}
    md = [
        "# Knowledge-base benchmark",
        "",
        f"Command: `{command}`  ",
        f"Environment: {_environment()}",
        "",
        f"Synthetic catalogs of T types with {r0.get('relations_per_type', 6)} relations each; per "
        f"type and relation min(1% of T, {r0.get('max_related') or 'no cap'}) related types with a "
        "nonzero y (1 <= y <= n_A, n_A random in [10, 1000]). "
        f"Medians over {r0.get('reps', '?')} repetitions.",
        "",
        markdown_table(rows),
        "",
        "- *choose (cold)*: one Highest-Impact-First choice among "
        f"{r0.get('candidates', 50)} candidate types right after each candidate had a "
        "`record_examination`, so every candidate's score is recomputed from the counts.",
        "- *choose (cached)*: the same choice again (scores cached per type).",
        "- *record*: one `record_examination` with 5 distinct (relation, type) pairs.",
        "- *peak MB*: peak memory traced by `tracemalloc` (Python objects and numpy buffers) while "
        "building the catalog and the filled knowledge base and running one choice and one record.",
        "- *max RSS MB*: the process's maximum resident set size so far (`resource.getrusage`), "
        "interpreter, numpy and tracemalloc's own bookkeeping included.",
        f"- *dense*: an n vector and a dense (T, 6, T) int32 y array, scored with `intervals.impact` "
        f"over all 6T pairs of each candidate; run where it fits (T <= {DENSE_MAX_TYPES}).",
        "",
    ]
    paths["md"].write_text("\n".join(md))
    _plot(rows, paths["png"])
    return paths


def _plot(rows: list[dict], path: Path) -> None:
    T = [r["types"] for r in rows]
    fig = Figure(figsize=(10, 4))
    ax1, ax2 = fig.subplots(1, 2)
    ax1.plot(T, [r["choose_ms"] for r in rows], "o-", label="choose, cold (ours)")
    ax1.plot(T, [r["choose_cached_ms"] for r in rows], "o:", label="choose, cached (ours)")
    ax1.plot(T, [r["record_ms"] for r in rows], "s-", label="record_examination (ours)")
    dense = [(r["types"], r["dense_choose_ms"]) for r in rows if r["dense_choose_ms"] is not None]
    if dense:
        ax1.plot(*zip(*dense, strict=True), "^--", label="choose, dense (T, 6, T)")
    ax1.axhline(5.0, color="grey", lw=0.8, ls="--", label="target: 5 ms")
    ax1.set(
        xscale="log", yscale="log", xlabel="types T", ylabel="ms", title="HIF choice among 50 types"
    )
    ax1.legend(fontsize=8)
    ax2.plot(T, [r["peak_mb"] for r in rows], "o-", label="peak traced (tracemalloc)")
    ax2.plot(T, [r["rss_mb"] for r in rows], "s:", label="process max RSS")
    ax2.axhline(500.0, color="grey", lw=0.8, ls="--", label="target: 500 MB")
    ax2.set(xscale="log", xlabel="types T", ylabel="MB", title="memory")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
