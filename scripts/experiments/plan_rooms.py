"""Room context on the robot's own map with the plan's rooms in place of its segmentation: an
upper bound on what a better segmentation could give room context (issue 27):

    python -m ctxsearch.scripts.experiments.plan_rooms --kb K --style apartment \\
        --episodes 80 --policies oracle-prior-indirect --out D

Runs ``bench search`` itself (serially) on the built map with ``--room-context``, the search's
``RoomMaps`` given the plan's rooms (``RoomLabels.of_plan``; wrapped for the run, the rest of the
built-map scenario as it is: furniture known only once seen). The points of a room whose
furniture the robot has seen get the room factor even where its map does not reach. Writes the
benchmark's files into ``--out`` (compare them with a run of the same episodes without room
context: ``compare_runs``). Not in ``make bench``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from unittest import mock

from ctxsearch.agent.room_segmentation import RoomLabels
from ctxsearch.agent.search.maps import RoomMaps
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import MapMode
from ctxsearch.scripts.experiments.bench_search import SearchBenchConfig, bench_search

_BUILT = RoomMaps.built.__func__


def _with_plan_rooms(cls, layout, catalog, spec, detector=None) -> RoomMaps:
    """The built-map scenario's maps, their rooms the plan's."""
    return replace(_BUILT(cls, layout, catalog, spec, detector), rooms=RoomLabels.of_plan(layout))


def run(config: SearchBenchConfig, out: Path):
    """``bench search`` of ``config`` (built map, room context) with the plan's rooms."""
    with mock.patch.object(RoomMaps, "built", classmethod(_with_plan_rooms)):
        return bench_search(config, out, progress=None, bar=False)


def parser(description: str, policies: str) -> argparse.ArgumentParser:
    """The arguments of a built-map run with room context (this module's, ``map_range``'s and
    ``lookahead``'s, which sets its own map and room context)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--kb", type=Path, required=True, help="knowledge store (ctxsearch learn)")
    ap.add_argument("--style", default="apartment", help="house style (default: apartment)")
    ap.add_argument("--episodes", type=int, default=40, help="episodes (default: 40)")
    ap.add_argument("--seed", type=int, default=0, help="episode seed (default: 0)")
    ap.add_argument("--policies", default=policies,
                    help="comma-separated policies (default: %(default)s)")  # fmt: skip
    ap.add_argument("--draw-cache", type=Path, help="the episode draw's cache (bench search's)")
    ap.add_argument("--out", type=Path, required=True, help="where the benchmark's files go")
    return ap


def config_of(a: argparse.Namespace) -> SearchBenchConfig:
    """The built-map benchmark with room context that ``parser``'s arguments ask for."""
    if a.episodes < 1:
        raise CtxsearchError(f"--episodes must be at least 1 (got {a.episodes})")
    return SearchBenchConfig(
        style=a.style, kb=a.kb, episodes=a.episodes, seed=a.seed, map=MapMode.BUILT,
        policies=tuple(p for p in a.policies.split(",") if p), rooms=True,
        draw_cache=a.draw_cache,
    )  # fmt: skip


def timed_main(make: Callable[[], tuple], what: str, episodes: int) -> int:
    """``make()`` (a run's result and its CPU seconds: ``map_range``'s and ``lookahead``'s),
    its table printed and the CPU seconds ``what`` took; a one-line error and exit code 2 on bad
    input."""
    try:
        res, cpu = make()
    except CtxsearchError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(res.table)
    print(f"{what}: {cpu:.0f} CPU s for {episodes} episodes")
    return 0


def main(argv: list[str] | None = None) -> int:
    a = parser(__doc__.split("\n\n")[0], "oracle-prior-indirect").parse_args(argv)
    try:
        res = run(config_of(a), a.out)
    except CtxsearchError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(res.table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
