"""The room context a store learned against the plans': every
SAME-ROOM-AS-F interval of the store (knowledge.room_context) against P(SAME-ROOM-AS-F(T)) over
generated worlds of the style (envs.truth.room_truth), and each type's share of furnished rooms.

    python -m ctxsearch.scripts.experiments.room_coverage --kb K --style apartment

Prints the entries' interval metrics as the interval benchmark measures them
(learning_trace.interval_metrics: coverage over all entries and over the informative ones,
n_F >= 1 and 0.02 <= p_true <= 0.98; mean width; mean |p0 - p_true|), the mean learned and true
shares, and with ``--json`` writes them.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from ctxsearch.envs.truth import room_truth
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import Rank
from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.experiments.learning_trace import interval_metrics


def measure(kb: Path, style: str, samples: int) -> dict:
    """The metrics (module docstring) of the store at ``kb`` against ``samples`` worlds."""
    catalog = load_catalog()
    with EvidenceStore.open(kb, catalog, read_only=True) as store:
        rc = store.room_context()
    if rc.rooms == 0:
        raise CtxsearchError(f"{kb}: the store holds no room context (learned in houses)")
    truth = room_truth(style, samples, catalog)
    rows = []
    for (f, t), p in sorted(truth.same_room.items()):
        got = rc.interval(f, t)
        if got is not None:
            lo, hi, _, n = got
            rows.append((lo, hi, rc.same_room(f, t, Rank.P0), p, n))
    lo, hi, p0, p_true, n = (np.array(c, float) for c in zip(*rows, strict=True))
    out = {"style": style, "truth_samples": samples, "rooms": rc.rooms, "entries": len(rows)}
    out.update(interval_metrics(lo, hi, p0, p_true, n))
    learned = [rc.room_share(t) for t in catalog.type_names]
    out["mean_share_learned"] = float(np.mean(learned))
    out["mean_share_true"] = float(np.mean([truth.room_share[t] for t in catalog.type_names]))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kb", type=Path, required=True, help="knowledge store (ctxsearch learn)")
    ap.add_argument("--style", default="apartment", help="house style (default: apartment)")
    ap.add_argument("--truth-samples", type=int, default=200, help="worlds (default: 200)")
    ap.add_argument("--json", type=Path, help="write the figures to this file")
    a = ap.parse_args(argv)
    try:
        if a.truth_samples < 1:
            raise CtxsearchError(f"--truth-samples must be at least 1 (got {a.truth_samples})")
        out = measure(a.kb, a.style, a.truth_samples)
    except CtxsearchError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(
        f"{a.kb}: {out['rooms']} rooms, {out['entries']} SAME-ROOM entries against "
        f"{a.truth_samples} worlds of {a.style}: coverage {out['coverage']:.3f}, on informative "
        f"entries {out['coverage_informative']:.3f}; mean width {out['mean_width']:.3f}; mean |p0 - p_true| "
        f"{out['mean_abs_error']:.3f}; mean share of rooms holding a type {out['mean_share_learned']:.3f} "
        f"learned, {out['mean_share_true']:.3f} true"
    )
    if a.json is not None:
        a.json.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
