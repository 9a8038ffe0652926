"""Where the online search's belief holds its mass when it decides:

    python -m ctxsearch.scripts.experiments.belief_shares --kb K --style apartment \\
        --map built --episodes 20 --policies frontier,oracle-prior-indirect

Runs ``bench search`` itself (serially; same seed, same episodes, its files in a temporary
directory); at every decision of the online search (``agent.search.online``) it reads the
belief (prior times miss field, normalised over the points still worth a look) and records its
share in the known objects' relation volumes (what context can point at), its share in points
not yet seen from within the map's depth range (what only exploring can reach), and the share
the chosen option expects to find (the first two overlap where a volume is not yet surveyed; a
policy without knowledge has no volumes). With ``--room-context`` also the share in rooms whose
known furniture sets a room factor (``agent.search.room_prior``) and, of it, the part not yet
surveyed: room context pays before the robot has entered. Prints, per policy, the decisions'
medians and quartiles of those shares and the episodes' median time to find; ``--csv FILE``
writes one row per decision. Nothing is written into tracked files.

The belief is read through the online search's decision hook (``SearchContext.observer``: the
search, the belief its options were valued on, the chosen option), which changes nothing in
the behaviour: the episodes' times are the benchmark's. The share an option expects is its rate
times its seconds (P(find) of a sweep, the planned gazes' share of a look into a volume); a
detour for an intermediate type states none.
"""

from __future__ import annotations

import argparse
import csv
import sys
import tempfile
from pathlib import Path

import numpy as np

from ctxsearch.agent.search import online as on
from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.scripts.experiments.bench_search import bench_search

FIELDS = (
    "policy", "episode", "target", "t_s", "kind", "volumes", "unexplored", "rooms",
    "rooms_unexplored", "expects",
)  # fmt: skip


def _shares(search: on.OnlineSearch, b: on.Belief) -> tuple[float, float, float, float]:
    """The belief's share in the known relation volumes, in the points not yet surveyed, in the
    rooms with a room factor and in their points not yet surveyed (NaN: not defined)."""
    w = b.weights
    nan = float("nan")
    if w is None:
        return nan, nan, nan, nan
    vols = float("nan")  # a policy without knowledge has no volumes
    if search.builder is not None:
        vols = 0.0
        every = search.builder.regions(search.known_objects())
        if every:
            vols = float(w[np.unique(np.concatenate([r.points for r in every]))].sum())
    away = search.ctx.seen.unseen(search.ctx.sight_cap)
    rooms = rooms_away = nan  # without room context
    if search.rooms is not None:
        f = search.rooms.factor(search.known_objects(), search.ctx.built)
        ruled = np.zeros(len(w), bool) if f is None else f != 1.0
        rooms, rooms_away = float(w[ruled].sum()), float(w[ruled & away].sum())
    return vols, float(w[away].sum()), rooms, rooms_away


def measure(config: SearchConfig) -> tuple[list[dict], dict]:
    """(one row per decision, policy -> times to find): ``bench search`` of ``config`` itself,
    serially, its files in a temporary directory, each decision read by the online search's
    hook (``SearchContext.observer``) before the chosen option acts."""
    rows: list[dict] = []

    def observe(search: on.OnlineSearch, b: on.Belief, o: on.Option) -> None:
        ctx = search.ctx
        vols, unexplored, rooms, rooms_away = _shares(search, b)
        # P(find) of a sweep or a look (rate times its seconds); a detour states none
        expects = o.rate * o.seconds if o.kind != "via" else float("nan")
        rows.append({
            "policy": ctx.policy, "episode": ctx.episode.index, "target": ctx.target,
            "t_s": round(ctx.elapsed, 1), "kind": o.kind, "volumes": round(vols, 4),
            "unexplored": round(unexplored, 4), "rooms": round(rooms, 4),
            "rooms_unexplored": round(rooms_away, 4), "expects": round(expects, 4),
        })  # fmt: skip

    with tempfile.TemporaryDirectory() as out:
        res = bench_search(config, out, progress=None, bar=False, observer=observe)
    times = {p: [float(r.time_to_find) for r in rs] for p, rs in res.results.items()}
    return rows, times


def _quartiles(rows: list[dict], key: str) -> str:
    """The median [first, third quartile] of ``key`` over ``rows`` (its finite values)."""
    v = np.array([r[key] for r in rows], float)
    v = v[np.isfinite(v)]
    if len(v) == 0:
        return "-"
    a, m, b = np.percentile(v, [25, 50, 75])
    return f"{m:.3f} [{a:.3f}, {b:.3f}]"


def summary(rows: list[dict], times: dict[str, list[float]]) -> list[str]:
    """One line per policy: decisions, the shares' medians and quartiles, median time."""
    out = []
    for p, ts in times.items():
        mine = [r for r in rows if r["policy"] == p]
        if not mine:
            out.append(f"{p}: no online decisions (not an online policy)")
            continue

        region = sum(r["kind"] == "region" for r in mine)
        vols, away = _quartiles(mine, "volumes"), _quartiles(mine, "unexplored")
        out.append(
            f"{p}: {len(mine)} decisions ({region} looks into volumes); belief in known volumes "
            f"{vols}, in unexplored space {away}; the chosen option expects "
            f"{_quartiles(mine, 'expects')} (median [quartiles]); median time to find "
            f"{np.median(ts):.1f} s over {len(ts)} episodes"
        )
        if any(np.isfinite(r["rooms"]) for r in mine):
            out.append(
                f"{p}: belief in rooms with a room factor {_quartiles(mine, 'rooms')}, of it not "
                f"yet surveyed {_quartiles(mine, 'rooms_unexplored')}; decisions with any room "
                f"factor {sum(r['rooms'] > 0 for r in mine)} of {len(mine)}"
            )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kb", type=Path, required=True, help="knowledge store (ctxsearch learn)")
    ap.add_argument("--style", default="apartment", help="house or room style (default: apartment)")
    ap.add_argument("--map", default="built", help="map scenario: built or given (default: built)")
    ap.add_argument("--episodes", type=int, default=20, help="episodes (default: 20)")
    ap.add_argument("--seed", type=int, default=0, help="episode seed (default: 0)")
    ap.add_argument(
        "--policies",
        default="frontier,oracle-prior-indirect",
        help="comma-separated online policies (default: %(default)s)",
    )
    ap.add_argument("--room-context", action="store_true", help="room context in the belief")
    ap.add_argument("--csv", type=Path, help="write one row per decision to this file")
    a = ap.parse_args(argv)
    try:
        if a.episodes < 1:
            raise CtxsearchError(f"--episodes must be at least 1 (got {a.episodes})")
        config = SearchConfig().updated({
            "style": a.style, "knowledge.kb": a.kb, "episodes": a.episodes, "seed": a.seed,
            "policies": a.policies, "map.scenario": a.map, "knowledge.room_context": a.room_context,
        })  # fmt: skip
        rows, times = measure(config)
    except CtxsearchError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print("\n".join(summary(rows, times)))
    if a.csv is not None:
        with open(a.csv, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=FIELDS)
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
