"""Indirect search against Wixson & Ballard's efficiency model.

Every ``indirect`` result records the intermediate type it searched for first
(``SearchResult.intermediate``, None when no type was worth it) and the model's predicted gain
C_direct / C_via (agent.search.viewpoints.predicted_plan: for that type, else for the best
candidate type). ``indirect_analysis`` groups the paired episodes by that choice and reports,
per group, the episodes, the median predicted gain and the *measured* gain: the paired
per-episode ratio of indirect's time to find to the baseline's (``frontier`` on the built map;
failures counted at the budget), its median with a seeded bootstrap 95% interval, and wins and
losses. Episodes where no intermediate was chosen are split by whether the model predicted a
gain for the best candidate (> 1) or not.

``bench search`` writes ``DIR/indirect.json`` and ``DIR/indirect.md`` when it ran both
``indirect`` and the baseline.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ctxsearch.agent.search.episode import Episode, SearchResult
from ctxsearch.agent.search.measures import bootstrap_ci

NONE_PREDICTED = "(none chosen; model predicts no gain)"
NONE_UNUSED = "(none chosen; model predicts a gain)"


def group_of(r: SearchResult) -> str:
    """The analysis group of an indirect result: its intermediate type, or why none."""
    if r.intermediate is not None:
        return r.intermediate
    return NONE_UNUSED if (r.predicted_gain or 0.0) > 1.0 else NONE_PREDICTED


def indirect_analysis(
    episodes: Sequence[Episode],
    results: dict[str, list[SearchResult]],
    policy: str = "indirect",
    baseline: str = "frontier",
    seed: int = 0,
) -> dict:
    """Predicted against measured gain per intermediate type (module docstring); ``results``
    must hold ``policy`` and ``baseline`` on the same ``episodes``."""
    rows = []
    for i, ep in enumerate(episodes):
        r, b = results[policy][i], results[baseline][i]
        rows.append({
            "episode": ep.index, "target": ep.target, "group": group_of(r),
            "intermediate": r.intermediate,
            "predicted_gain": None if r.predicted_gain is None else round(r.predicted_gain, 4),
            "t": round(r.time_to_find, 3), "t_baseline": round(b.time_to_find, 3),
            "ratio": round(r.time_to_find / max(b.time_to_find, 1e-6), 4),
        })  # fmt: skip
    groups = {}
    for name in sorted({row["group"] for row in rows}) + ["all"]:
        sel = [row for row in rows if name == "all" or row["group"] == name]
        ratio = np.array([row["ratio"] for row in sel], float)
        gains = [row["predicted_gain"] for row in sel if row["predicted_gain"] is not None]
        lo, hi = bootstrap_ci(ratio, np.median, seed=seed)
        groups[name] = {
            "episodes": len(sel),
            "predicted_gain": round(float(np.median(gains)), 4) if gains else None,
            "measured_ratio": round(float(np.median(ratio)), 4),
            "ci": [round(lo, 4), round(hi, 4)],
            "measured_gain": round(1.0 / max(float(np.median(ratio)), 1e-6), 4),
            "wins": int(np.sum(ratio < 1.0)),
            "losses": int(np.sum(ratio > 1.0)),
        }
    return {"policy": policy, "baseline": baseline, "groups": groups, "episodes": rows}


def format_indirect(doc: dict) -> str:
    """indirect.md: the table of ``indirect_analysis``."""
    lines = [
        f"# Indirect search against Wixson & Ballard's efficiency model\n\n"
        f"`{doc['policy']}` against `{doc['baseline']}` on the same episodes. Predicted gain: "
        "C_direct / C_via of the model (> 1: searching for the intermediate type first pays); "
        "measured: the paired median of t(indirect) / t(baseline) (< 1: indirect is faster) "
        "with its bootstrap 95% interval.\n",
        "| intermediate type | episodes | predicted gain | measured ratio [95% CI] | "
        "measured gain | wins | losses |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, g in doc["groups"].items():
        pg = "-" if g["predicted_gain"] is None else f"{g['predicted_gain']:.2f}"
        lines.append(
            f"| {name} | {g['episodes']} | {pg} | {g['measured_ratio']:.2f} "
            f"[{g['ci'][0]:.2f}, {g['ci'][1]:.2f}] | {g['measured_gain']:.2f} | {g['wins']} | "
            f"{g['losses']} |"
        )
    return "\n".join(lines) + "\n"


def write_indirect(out: Path, doc: dict) -> list[Path]:
    """Write ``DIR/indirect.json`` and ``DIR/indirect.md``; their paths."""
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "indirect.json", out / "indirect.md"]
    files[0].write_text(json.dumps(doc, indent=1) + "\n")
    files[1].write_text(format_indirect(doc))
    return files
