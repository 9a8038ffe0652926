"""How long the Gymnasium task's reset and step take:

    python scripts/examples/gym_timing.py [--style office] [--detector realistic] [--seeds 20]
                                          [--size 64x48]

Resets with ``--seeds`` new seeds (each draws the benchmark's episode: the worlds' checks, with
the oracle's planner asked only whether the target can be found within the budget), then the
same seeds again (the process keeps its draws), taking five actions after each; prints the
medians and the slowest new-seed reset. Wall-clock: the machine's load moves them.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("MUJOCO_GL", "egl")  # before MuJoCo is first imported

import gymnasium

from ctxsearch.agent.gym_env import ENV_ID

ACTIONS = (7, 1, 3, 0, 7)  # look, turn left, pan left, forward, look


def timings(style: str, detector: str, seeds: int, size: tuple[int, int]) -> dict[str, float]:
    """Median seconds of a reset with a new seed, a reset with a seed drawn before, and a step;
    the slowest reset with a new seed."""
    env = gymnasium.make(ENV_ID, style=style, detector=detector, width=size[0], height=size[1])
    new, again, steps = [], [], []
    for s in range(seeds):
        t = time.perf_counter()
        env.reset(seed=s)
        new.append(time.perf_counter() - t)
    for s in range(seeds):
        t = time.perf_counter()
        env.reset(seed=s)
        again.append(time.perf_counter() - t)
        for a in ACTIONS:
            t = time.perf_counter()
            env.step(a)
            steps.append(time.perf_counter() - t)
    env.close()
    return {
        "reset_new_seed_s": statistics.median(new),
        "reset_new_seed_max_s": max(new),
        "reset_seed_drawn_before_s": statistics.median(again),
        "step_s": statistics.median(steps),
    }


def main(argv: list[str] | None = None) -> int:
    """Measure and print the medians."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--style", default="office", help="room or house style (default office)")
    ap.add_argument("--detector", default="realistic", help="detector preset (default realistic)")
    ap.add_argument("--seeds", type=int, default=20, help="new seeds reset (default 20)")
    ap.add_argument("--size", default="64x48", help="image size WxH (default 64x48)")
    args = ap.parse_args(argv)
    w, _, h = args.size.partition("x")
    for k, v in timings(args.style, args.detector, args.seeds, (int(w), int(h))).items():
        print(f"{k}: {v:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
