"""The integer argparse value types (counts, seeds, image sides): each rejects bad input with one
line. A leaf shared by the CLI's value types (scripts.argtypes, which re-exports these) and the
sweep's ``--workers`` flag (scripts.sweep), so the sweep needs nothing of the CLI."""

from __future__ import annotations

import argparse

# Sane upper bounds: far beyond any run on one machine, small enough that nothing sized by a count
# (a list of room seeds, a table of episodes) can exhaust memory before it is needed.
MAX_COUNT = 1_000_000
MAX_SEED = 2**32 - 1
MAX_PIXELS = 4096  # an image side


def _int(text: str) -> int | None:
    try:
        return int(text)
    except ValueError:
        return None


def _count(text: str, minimum: int) -> int:
    v = _int(text)
    if v is None or v < minimum:
        what = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    if v > MAX_COUNT:
        raise argparse.ArgumentTypeError(f"expected at most {MAX_COUNT:_}, got {v:_}")
    return v


def positive_int(text: str) -> int:
    """An integer in [1, MAX_COUNT] (rooms, seeds per strategy, episodes, examinations...)."""
    return _count(text, 1)


def non_negative_int(text: str) -> int:
    """An integer in [0, MAX_COUNT] (a minimum number of examinations)."""
    return _count(text, 0)


def seed(text: str) -> int:
    """A random seed: an integer in [0, 2**32 - 1]."""
    v = _int(text)
    if v is None or not 0 <= v <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"expected a seed in [0, {MAX_SEED}], got {text!r}")
    return v


def pixels(text: str) -> int:
    """An image side in pixels: an integer in [16, MAX_PIXELS]."""
    v = _int(text)
    if v is None or not 16 <= v <= MAX_PIXELS:
        raise argparse.ArgumentTypeError(
            f"expected an image size in [16, {MAX_PIXELS}] pixels, got {text!r}"
        )
    return v
