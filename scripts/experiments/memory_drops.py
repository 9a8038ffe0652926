"""How often the remembered map's search drops furniture it remembered (agent.search.remembered's
``FurnitureMemory``: a piece that three close images show without a report), and whether what it
dropped was really not there: per episode of ``bench search --map remembered``'s draw, the
pieces each policy dropped, counted as true pieces of the world (a wrong drop) or not (a phantom
rightly dropped).

    python -m ctxsearch.scripts.experiments.memory_drops --style apartment --episodes 20 \
        --policies uniform,location --kb K

Read from each result's log (``... of the remembered map is not there: dropped``) against the
episode's true layout: a report, not the robot's knowledge.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.agent.search.draw import make_episodes
from ctxsearch.agent.search.episode import episode_layout
from ctxsearch.agent.search.runner import prepare, run_episode
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import MapMode

DROPPED = re.compile(r"(\w+) #(-?\d+) of the remembered map is not there: dropped")


def count_drops(
    style: str, episodes: int, policies: tuple[str, ...], seed: int, kb: Path | None
) -> dict:
    """Drops per policy over ``episodes`` episodes (module docstring; ``kb``: the knowledge
    store the context policies read)."""
    config = SearchConfig(style=style, policies=policies, seed=seed, episodes=episodes)
    config = config.updated({"knowledge.kb": kb})
    run = prepare(config.with_scenario(MapMode.REMEMBERED))
    out = {p: {"true": 0, "phantom": 0} for p in policies}
    for ep in make_episodes(run.draw_spec(episodes), run.catalog):
        layout = episode_layout(generate_layout(run.style, ep.room_seed, run.catalog, ep.day), ep)
        ids = {o.id for o in layout.objects}
        for res in run_episode(ep, run):
            for line in res.log:
                m = DROPPED.search(line)
                if m:
                    out[res.policy]["true" if int(m.group(2)) in ids else "phantom"] += 1
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--style", default="apartment", help="house style (default: apartment)")
    ap.add_argument("--episodes", type=int, default=20, help="episodes (default: 20)")
    ap.add_argument("--seed", type=int, default=0, help="the draw's seed (default: 0)")
    ap.add_argument("--policies", default="uniform", help="comma-separated (default: uniform)")
    ap.add_argument("--kb", type=Path, default=None, help="knowledge store (for location)")
    a = ap.parse_args(argv)
    try:
        if a.episodes < 1:
            raise CtxsearchError(f"--episodes must be at least 1 (got {a.episodes})")
        pols = tuple(p.strip() for p in a.policies.split(",") if p.strip())
        got = count_drops(a.style, a.episodes, pols, a.seed, a.kb)
    except CtxsearchError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for p, c in got.items():
        print(f"{p}: {a.episodes} episodes, dropped {c['true']} true pieces of furniture and "
              f"{c['phantom']} phantoms")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
