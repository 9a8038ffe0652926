"""``make bench-full``'s summary: per house style, target kind and map scenario, each policy
against the scenario's no-context baseline, and the context policy with room context against
itself without, on the same episodes (scripts.experiments.bench_full wrote them).

Read from each run's ``episodes.csv`` (times to find, failures at the budget); the statistics
are agent.search.measures.paired_stats (geometric mean of the paired ratio with its bootstrap
interval, the ratio of mean times with its interval, wins/losses/ties, the signed-rank p, the
episodes 80% power needs) and each policy's success share (the csv's ``success``). Writes
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


def read_episodes(path: Path) -> dict[str, list[tuple[float, bool]]]:
    """{policy: (time to find, success) per episode, in episode order} of an episodes.csv."""
    out: dict[str, list[tuple[int, float, bool]]] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            ok = row.get("success", row.get("found", "true")).strip().lower() == "true"
            out.setdefault(row["policy"], []).append(
                (int(row["episode"]), float(row["time_to_find_s"]), ok)
            )
    return {p: [(t, ok) for _i, t, ok in sorted(v)] for p, v in out.items()}


def success_share(runs: list[tuple[float, bool]]) -> float:
    """The share of episodes a policy succeeded in (rounded to 4 places)."""
    return round(sum(ok for _t, ok in runs) / len(runs), 4) if runs else float("nan")


def scenario_summary(where: Path, m: str) -> dict | None:
    """One scenario's comparisons against its baseline (``BASELINE``, else the first of bench
    search's ``BASELINES`` that ran; None: the run is missing or has none)."""
    path = where / m / "episodes.csv"
    if not path.exists():
        return None
    runs = read_episodes(path)
    t = {p: [x for x, _ok in v] for p, v in runs.items()}
    base = BASELINE[m] if BASELINE[m] in t else next((b for b in BASELINES if b in t), None)
    if base is None:
        return None
    rows = {p: paired_stats(v, t[base]).to_json() for p, v in t.items() if p != base}
    doc: dict = {"episodes": len(t[base]), "baseline": base, "vs_baseline": rows,
                 "success": {p: success_share(v) for p, v in runs.items()}}  # fmt: skip
    nrc = where / f"{m}-no-room-context" / "episodes.csv"
    ctx = CONTEXT[m]
    if nrc.exists() and ctx in t:
        nrc_runs = read_episodes(nrc)[ctx]
        without = [x for x, _ok in nrc_runs]
        doc["vs_baseline"][f"{ctx} ({NO_RC})"] = paired_stats(without, t[base]).to_json()
        doc["success"][f"{ctx} ({NO_RC})"] = success_share(nrc_runs)
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
                ok = s.get("success", {})
                lines += [f"## {style}, {targets} targets, {m} map: {s['episodes']} paired "
                          "episodes", "", f"| policy | vs {s['baseline']}: geometric mean "
                          "[95% CI] w/l/t p | ratio of means [95% CI] | episodes for 80% power "
                          "| success |", "|---|---|---|---|---|",
                          f"| {s['baseline']} | 1 | 1 | | {_pct(ok.get(s['baseline']))} |"]  # fmt: skip
                for p, r in s["vs_baseline"].items():
                    lines.append(f"| {p} | {geo_cell(r)} | {_means_cell(r)} | "
                                 f"{r.get('episodes_for_power') or '-'} | {_pct(ok.get(p))} |")  # fmt: skip
                rc = s.get("room_context")
                if rc:
                    lines += ["", f"{rc['policy']} with room context against without: "
                              f"{geo_cell(rc['with_vs_without'])}."]  # fmt: skip
                lines.append("")
    lines.append(
        "Per episode, the policy's simulated seconds to find over the baseline's (failures at "
        "the budget); geometric mean with a percentile bootstrap interval, wins/losses/ties, "
        "Wilcoxon signed-rank p; the ratio of the mean times with a paired bootstrap interval; "
        "the episodes an effect of the measured size needs for 80% power at p < 0.05 "
        "(agent.search.measures.paired_stats); success: the share of episodes the policy "
        "found the target within the budget. The learning curve: "
        "curve/curve.md; the transfer table: transfer/transfer.md."
    )
    return "\n".join(lines) + "\n"


def _means_cell(r: dict) -> str:
    """The ratio of mean times [interval] of a ``PairedStats.to_json`` entry ("-": none)."""
    if r.get("ratio_of_means") is None:
        return "-"
    lo, hi = r["ratio_of_means_ci"]
    return f"{r['ratio_of_means']:.2f} [{lo:.2f}, {hi:.2f}]"


def _pct(share: float | None) -> str:
    """A success share as a whole percentage ("-": unknown)."""
    return "-" if share is None or share != share else f"{100 * share:.0f}%"


def write_summary(out: Path) -> list[Path]:
    """Write OUT/summary.json and OUT/summary.md; their paths."""
    doc = summary_doc(Path(out))
    files = [Path(out) / "summary.json", Path(out) / "summary.md"]
    files[0].parent.mkdir(parents=True, exist_ok=True)
    files[0].write_text(json.dumps(doc, indent=1) + "\n")
    files[1].write_text(summary_table(doc))
    return files
