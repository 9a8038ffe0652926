"""The Gymnasium search task with a random agent and with one of the project's own policies.

    python scripts/examples/gym_random_agent.py [--style office] [--detector perfect]
        [--kb STORE] [--seed 0] [--steps 200] [--size 64x48]

1. A random agent: ``env.action_space.sample()`` until the target is found, the budget is spent
   or ``--steps`` steps were taken; the simulated seconds it needed (minus the summed reward).
2. The project's ``exhaustive`` search policy (agent.search) on the same episode: reset with the
   same seed, then the policy drives the environment's own body (its World, charged by the same
   time model, read by the same detector preset) through ``SearchContext``. A policy acts on
   paths and gazes rather than on the eight discrete actions, so this adapter runs it on the
   env's body, not through ``env.step``; the result is the benchmark's figure for the episode at
   this image size.
"""

from __future__ import annotations

import argparse
import os
import sys

os.environ.setdefault("MUJOCO_GL", "egl")  # before MuJoCo is first imported

import gymnasium

from ctxsearch.agent.gym_env import ENV_ID, ObjectSearchEnv
from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.agent.search.episode import SearchResult
from ctxsearch.agent.search.maps import WorldMaps
from ctxsearch.agent.search.registry import resolve
from ctxsearch.agent.search.runner import EpisodeWorld, PolicyRun, run_policy
from ctxsearch.knowledge.errors import CtxsearchError


def random_agent(env: gymnasium.Env, seed: int, steps: int) -> dict:
    """Random actions from ``reset(seed=seed)`` until the episode ends or ``steps`` were taken:
    steps, simulated seconds, whether it found the target."""
    obs, info = env.reset(seed=seed)
    env.action_space.seed(seed)
    seconds, n, found = 0.0, 0, False
    for n in range(1, steps + 1):  # noqa: B007 - n is the count after the loop
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        seconds -= reward
        if terminated or truncated:
            found = bool(info["success"])
            break
    return {"target": info["target"], "steps": n, "sim_s": seconds, "found": found}


def exhaustive_on_env(env: gymnasium.Env, seed: int) -> SearchResult:
    """The ``exhaustive`` policy on the episode ``env.reset(seed=seed)`` draws, on the env's body
    (judged as the benchmark judges it)."""
    env.reset(seed=seed)
    base: ObjectSearchEnv = env.unwrapped
    maps = WorldMaps.given(base.layout, base.catalog, base.robot_spec, base.detector_model)
    config = SearchConfig().with_scenario("given")
    world = EpisodeWorld(base.layout, base.catalog, base.world, maps, config)
    (exhaustive,) = resolve(("exhaustive",), "given")
    return run_policy(base.episode, PolicyRun(exhaustive), world)


def _size(text: str) -> tuple[int, int]:
    w, _, h = text.partition("x")
    try:
        return int(w), int(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not WIDTHxHEIGHT") from None


def main(argv: list[str] | None = None) -> int:
    """Run both agents on one episode and print what each needed."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--style", default="office")
    ap.add_argument("--detector", default="perfect", help="detector preset (name or TOML file)")
    ap.add_argument("--kb", default=None, help="an evidence store: adds the context observation")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--steps", type=int, default=200, help="the random agent's step limit")
    ap.add_argument("--size", type=_size, default=(64, 48), help="image size WxH (default 64x48)")
    args = ap.parse_args(argv)
    w, h = args.size
    try:
        env = gymnasium.make(
            ENV_ID, style=args.style, detector=args.detector, kb=args.kb, width=w, height=h
        )
    except CtxsearchError as exc:
        print(f"gym_random_agent: error: {exc}", file=sys.stderr)
        return 2
    with env:
        r = random_agent(env, args.seed, args.steps)
        print(
            f"random agent: {'found' if r['found'] else 'did not find'} {r['target']} after "
            f"{r['steps']} steps, {r['sim_s']:.1f} simulated s"
        )
        print(exhaustive_on_env(env, args.seed).summary())
    return 0


if __name__ == "__main__":
    sys.exit(main())
