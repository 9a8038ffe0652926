"""The built map's depth range and room context (issue 27, point 3: "the depth used for mapping
may reach further than today where it helps; say what the range costs"):

    python -m ctxsearch.scripts.experiments.map_range --kb K --style apartment --range 10 \\
        --episodes 80 --policies frontier,oracle-prior-indirect --draw-cache DRAWS --out D

Runs ``bench search`` itself (serially) on the built map with ``--room-context``, every built
map's depth range (``BuiltMap``'s ``max_range``, 5 m) and the search's sight cap
(``agent.search.viewpoints.MAX_VIEW``, 5 m: nothing further counts as seen) set to ``--range``
for the run; the rest is the benchmark's. Further depth maps the rooms behind a door sooner, so
their segments, and the furniture seen in them, can give the room factor before the robot
enters. Prints the benchmark's table and the CPU seconds the run took (the range's cost: every
depth image back-projects and ray-casts further). Compare ``D/episodes.csv`` with a run of the
same episodes at 5 m (``bench search --room-context``) by ``compare_runs``. Not in ``make
bench``.
"""

from __future__ import annotations

import inspect
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from unittest import mock

from ctxsearch.agent import mapping
from ctxsearch.agent.search import viewpoints as sx
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.scripts.experiments.bench_search import SearchBenchConfig, bench_search
from ctxsearch.scripts.experiments.plan_rooms import config_of, parser, timed_main

MIN_RANGE, MAX_RANGE = 1.0, 30.0  # m


@contextmanager
def depth_range(metres: float) -> Iterator[None]:
    """Every ``BuiltMap`` made inside, and the search's sight cap, reach ``metres``."""
    init = mapping.BuiltMap.__init__
    params = [p for p in inspect.signature(init).parameters.values() if p.default is not p.empty]
    defaults = tuple(metres if p.name == "max_range" else p.default for p in params)
    with ExitStack() as stack:
        stack.enter_context(mock.patch.object(init, "__defaults__", defaults))
        stack.enter_context(mock.patch.object(sx, "MAX_VIEW", float(metres)))
        yield


def run(config: SearchBenchConfig, out: Path, metres: float):
    """``bench search`` of ``config`` with the depth range ``metres``; (result, CPU seconds)."""
    t0 = time.process_time()
    with depth_range(metres):
        res = bench_search(config, out, progress=None, bar=False)
    return res, time.process_time() - t0


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__.split("\n\n")[0], "frontier,oracle-prior-indirect")
    ap.add_argument("--range", type=float, default=10.0, help="depth range, m (default: 10)")
    a = ap.parse_args(argv)

    def make():
        config = config_of(a)
        if not MIN_RANGE <= a.range <= MAX_RANGE:
            raise CtxsearchError(
                f"--range must be in [{MIN_RANGE:g}, {MAX_RANGE:g}] m (got {a.range})"
            )
        return run(config, a.out, a.range)

    return timed_main(make, f"depth range {a.range:g} m", a.episodes)


if __name__ == "__main__":
    sys.exit(main())
