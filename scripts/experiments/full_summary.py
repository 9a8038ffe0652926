"""``make bench-full``'s summary: per house style, target kind and map scenario, each policy
against the scenario's no-context baseline, and the context policy with room context against
itself without, on the same episodes (scripts.experiments.bench_full wrote them).

Read from each run's ``episodes.csv`` (times to find, failures at the budget); the statistics
are agent.search.measures.paired_stats (geometric mean of the paired ratio with its bootstrap
interval, wins/losses/ties, the signed-rank p, the episodes 80% power needs). Writes
``OUT/summary.json`` and ``OUT/summary.md``; a run that is missing is left out.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

from ctxsearch.agent.search.measures import geo_cell, paired_stats
from ctxsearch.scripts.experiments.bench_full import BASELINE, CONTEXT, MAPS, TARGETS
from ctxsearch.scripts.experiments.bench_search import BASELINES

STYLES = ("apartment", "family_house")
NO_RC = "no room context"


def read_times(path: Path) -> dict[str, list[float]]:
    """{policy: time to find per episode, in episode order} of an episodes.csv."""
    out: dict[str, list[tuple[int, float]]] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            out.setdefault(row["policy"], []).append(
                (int(row["episode"]), float(row["time_to_find_s"]))
            )
    return {p: [t for _i, t in sorted(v)] for p, v in out.items()}


def scenario_summary(where: Path, m: str) -> dict | None:
    """One scenario's comparisons against its baseline (``BASELINE``, else the first of bench
    search's ``BASELINES`` that ran; None: the run is missing or has none)."""
    path = where / m / "episodes.csv"
    if not path.exists():
        return None
    t = read_times(path)
    base = BASELINE[m] if BASELINE[m] in t else next((b for b in BASELINES if b in t), None)
    if base is None:
        return None
    rows = {p: paired_stats(v, t[base]).to_json() for p, v in t.items() if p != base}
    doc: dict = {"episodes": len(t[base]), "baseline": base, "vs_baseline": rows}
    nrc = where / f"{m}-no-room-context" / "episodes.csv"
    ctx = CONTEXT[m]
    if nrc.exists() and ctx in t:
        without = read_times(nrc)[ctx]
        doc["vs_baseline"][f"{ctx} ({NO_RC})"] = paired_stats(without, t[base]).to_json()
        doc["room_context"] = {"policy": ctx,
                               "with_vs_without": paired_stats(t[ctx], without).to_json()}  # fmt: skip
    return doc


def summary_doc(out: Path) -> dict:
    """summary.json's content."""
    doc: dict = {}
    for style in STYLES:
        for targets in TARGETS:
            for m in MAPS:
                s = scenario_summary(out / style / targets, m)
                if s is not None:
                    doc.setdefault(style, {}).setdefault(targets, {})[m] = s
    return doc


def summary_table(doc: dict) -> str:
    """summary.md."""
    lines = ["# make bench-full: summary", ""]
    for style, by_targets in doc.items():
        for targets, by_map in by_targets.items():
            for m, s in by_map.items():
                lines += [f"## {style}, {targets} targets, {m} map: {s['episodes']} paired "
                          "episodes", "", f"| policy | vs {s['baseline']}: geometric mean "
                          "[95% CI] w/l/t p | episodes for 80% power |", "|---|---|---|"]  # fmt: skip
                for p, r in s["vs_baseline"].items():
                    lines.append(f"| {p} | {geo_cell(r)} | {r.get('episodes_for_power') or '-'} |")
                rc = s.get("room_context")
                if rc:
                    lines += ["", f"{rc['policy']} with room context against without: "
                              f"{geo_cell(rc['with_vs_without'])}."]  # fmt: skip
                lines.append("")
    lines.append(
        "Per episode, the policy's simulated seconds to find over the baseline's (failures at "
        "the budget); geometric mean with a percentile bootstrap interval, wins/losses/ties, "
        "Wilcoxon signed-rank p (agent.search.measures.paired_stats). The learning curve: "
        "curve/curve.md; the transfer table: transfer/transfer.md."
    )
    return "\n".join(lines) + "\n"


def write_summary(out: Path) -> list[Path]:
    """Write OUT/summary.json and OUT/summary.md; their paths."""
    doc = summary_doc(Path(out))
    files = [Path(out) / "summary.json", Path(out) / "summary.md"]
    files[0].parent.mkdir(parents=True, exist_ok=True)
    files[0].write_text(json.dumps(doc, indent=1) + "\n")
    files[1].write_text(summary_table(doc))
    return files
