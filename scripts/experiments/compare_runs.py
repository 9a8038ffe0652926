"""Two runs of ``bench search`` on the same episodes, compared per policy: what a change to a policy
did, with the benchmark's own paired statistics (``agent.search.measures.paired_stats``).

    python -m ctxsearch.scripts.experiments.compare_runs NEW/episodes.csv OLD/episodes.csv \\
        indirect frontier:frontier

Each pair ``A[:B]`` compares policy A of the new run with policy B (default: A) of the old run on
the episodes both ran (matched by episode index, room seed and target; give one file twice to
compare two policies of one run, ``--by-target`` for a line per target type), printing the geometric
mean of the per-episode time ratio with its bootstrap interval, the ratio of means, wins, losses
and ties and the Wilcoxon p. A file that is not an ``episodes.csv``, a policy a run lacks or runs
with no episode in common are one-line errors (exit 2).
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

from ctxsearch.agent.search.measures import paired_stats
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.files import read_text

NEEDED = ("episode", "room_seed", "target", "policy", "time_to_find_s")


def load(path: Path) -> dict[str, dict[tuple[int, str, str], float]]:
    """policy -> (episode, room seed, target) -> time to find, from an ``episodes.csv``."""
    text = read_text(path)
    rows = list(csv.DictReader(text.splitlines()))
    if not rows or any(c not in rows[0] for c in NEEDED):
        raise CtxsearchError(f"{path}: not a bench search episodes.csv (needs {', '.join(NEEDED)})")
    out: dict[str, dict[tuple[int, str, str], float]] = {}
    try:
        for r in rows:
            key = (int(r["episode"]), r["room_seed"], r["target"])
            out.setdefault(r["policy"], {})[key] = float(r["time_to_find_s"])
    except ValueError as e:
        raise CtxsearchError(f"{path}: a row does not read as numbers ({e})") from None
    return out


def compare(
    new: Path, old: Path, pairs: list[str], seed: int = 0, by_target: bool = False
) -> list[str]:
    """One line per ``A[:B]`` pair (module docstring); ``by_target``: one per pair and target
    type as well."""
    a_runs, b_runs = load(new), load(old)
    lines = []
    for pair in pairs:
        a, _, b = pair.partition(":")
        b = b or a
        for name, runs, path in ((a, a_runs, new), (b, b_runs, old)):
            if name not in runs:
                raise CtxsearchError(f"{path}: no policy '{name}' (it has {', '.join(runs)})")
        keys = sorted(set(a_runs[a]) & set(b_runs[b]))
        if not keys:
            raise CtxsearchError(f"{new} and {old}: no episode in common")
        groups = [("", keys)]
        if by_target:
            groups += [
                (f" [{t}]", [k for k in keys if k[2] == t]) for t in sorted({k[2] for k in keys})
            ]
        for label, ks in groups:
            s = paired_stats(
                np.array([a_runs[a][k] for k in ks]), np.array([b_runs[b][k] for k in ks]), seed
            ).to_json()
            lo, hi = s["geo_mean_ci"]
            lines.append(
                f"{a} / {b}{label}: {len(ks)} episodes, geometric mean "
                f"{s['geo_mean']:.2f} [{lo:.2f}, {hi:.2f}], ratio of means "
                f"{s['ratio_of_means']:.2f}, wins/losses/ties {s['wins']}/{s['losses']}/"
                f"{s['ties']}, Wilcoxon p {s['wilcoxon_p']:.3f}"
            )
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("new", type=Path, help="the new run's episodes.csv")
    p.add_argument("old", type=Path, help="the old run's episodes.csv (the same episodes)")
    p.add_argument("pairs", nargs="+", help="POLICY or NEW_POLICY:OLD_POLICY")
    p.add_argument("--by-target", action="store_true", help="also one line per target type")
    args = p.parse_args(argv)
    try:
        print("\n".join(compare(args.new, args.old, args.pairs, by_target=args.by_target)))
    except CtxsearchError as e:
        print(f"compare_runs: error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
