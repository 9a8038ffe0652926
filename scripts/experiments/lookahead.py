"""The online search's two-step look-ahead against its greedy choice (issue 26, deliver 2: "a
short look-ahead where greedy choice is myopic (a close look costs a drive first)"):

    python -m ctxsearch.scripts.experiments.lookahead --kb K --style apartment --map given \\
        --episodes 200 --policies location,oracle-prior --draw-cache DRAWS --out D

Runs ``bench search`` itself (serially: the switch is this process's) with
``agent.search.online.LOOKAHEAD`` on (``OnlineSearch.choose``: each option worth its best
two-step plan per second, what the second finds counted from what the first leaves); the rest
is the benchmark's. Compare ``D/episodes.csv`` with ``bench search``'s run of the same episodes
(greedy, the default) by ``compare_runs``: the policies without a choice to make (``frontier``,
``uniform``: one option per step) come out the same. Measured, it loses (README "The online
decision's look-ahead"), so greedy stays the default. Not in ``make bench``.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path
from unittest import mock

from ctxsearch.agent.search import online
from ctxsearch.knowledge.options import MapMode
from ctxsearch.scripts.experiments.bench_search import SearchBenchConfig, bench_search
from ctxsearch.scripts.experiments.plan_rooms import config_of, parser, timed_main


def run(config: SearchBenchConfig, out: Path):
    """``bench search`` of ``config`` with the look-ahead; (result, CPU seconds)."""
    t0 = time.process_time()
    with mock.patch.object(online, "LOOKAHEAD", True):
        res = bench_search(config, out, progress=None, bar=False)
    return res, time.process_time() - t0


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__.split("\n\n")[0], "location,oracle-prior")
    ap.add_argument("--map", choices=[m.value for m in MapMode], default="given",
                    help="map scenario (default: given)")  # fmt: skip
    ap.add_argument("--room-context", action="store_true", help="as bench search's")
    a = ap.parse_args(argv)

    def make():
        return run(replace(config_of(a), map=MapMode(a.map), rooms=a.room_context), a.out)

    return timed_main(make, "look-ahead", a.episodes)


if __name__ == "__main__":
    sys.exit(main())
