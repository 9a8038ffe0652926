"""argparse value types shared by the sub-commands: each rejects bad input with one line."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from ctxsearch.knowledge.options import IntervalMethod

# The integer types live in scripts.integers (shared with scripts.sweep); re-exported here.
from ctxsearch.scripts.integers import (  # noqa: F401
    MAX_COUNT,
    MAX_PIXELS,
    MAX_SEED,
    non_negative_int,
    pixels,
    positive_int,
    seed,
)

# A sane upper bound on seconds, like the integers' bounds (scripts.integers).
MAX_SECONDS = 1e9


def positive_ints(text: str) -> tuple[int, ...]:
    """``1,2,4``: strictly increasing whole numbers >= 1 (one-line errors)."""
    parts = [x.strip() for x in text.split(",")]
    if not text.strip() or "" in parts:
        raise argparse.ArgumentTypeError(f"a comma-separated list of whole numbers, got {text!r}")
    values = tuple(positive_int(x) for x in parts)
    if any(b <= a for a, b in zip(values, values[1:], strict=False)):
        raise argparse.ArgumentTypeError(f"numbers must increase, got {text!r}")
    return values


def out_dir(text: str) -> Path:
    """An output directory: one that exists, or a path where none is (it is created later)."""
    p = Path(text)
    if p.exists() and not p.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: exists and is not a directory")
    return p


def seconds(text: str) -> float:
    """A finite, positive number of (simulated) seconds."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a positive number of seconds, got {text!r}"
        ) from None
    if not (v > 0 and math.isfinite(v)) or v > MAX_SECONDS:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text}")
    return v


def positive_float(text: str) -> float:
    """A finite number > 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text}")
    return v


def non_negative_float(text: str) -> float:
    """A finite number >= 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}") from None
    if not (v >= 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text}")
    return v


def alpha(text: str) -> float:
    """A confidence parameter alpha in (0, 1)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 1), got {text!r}") from None
    if not 0.0 < v < 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 1), got {v}")
    return v


def unit_interval(text: str) -> float:
    """A number in [0, 1] (a detection confidence)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text!r}") from None
    if not 0.0 <= v <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {v}")
    return v


def out_file(text: str) -> Path:
    """An output file: a path that is not a directory (an existing file is replaced)."""
    p = Path(text)
    if p.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: is a directory, expected a file")
    return p


DETECTOR_HELP = (
    "camera mode's detector: a preset of assets/detectors (perfect, realistic) or a TOML file "
    "(default: realistic; the oracle perception has none)"
)
INTERVAL_HELP = (
    "interval method: wilson (the paper's eq. 1-2, default), clustered (Wilson on a room-level "
    "effective sample size: examinations in one room are correlated) or corrected (clustered, and "
    "each examination weighted by the chance its images would have shown a related object: the "
    "detector's misses and false reports; stores of schema 5 learned with the camera)"
)


def add_detector_argument(p: argparse.ArgumentParser) -> None:
    """``--detector NAME|FILE`` (checked by the handler: a bad file gets the one-line error)."""
    p.add_argument("--detector", default=None, metavar="NAME|FILE", help=DETECTOR_HELP)


FORGET_HELP = (
    "how evidence of earlier days counts (knowledge/drift.py): none (the paper: forever), "
    "half-life (an examination d days old weighs 2^(-d/H), --half-life H), detect (a per-entry "
    "change test at --false-alarm rate per entry and run; on an alarm only the evidence since the "
    "change counts) (default: none)"
)


def add_forget_arguments(p: argparse.ArgumentParser) -> None:
    """``--forget none|half-life|detect``, ``--half-life H``, ``--false-alarm RATE``."""
    p.add_argument(
        "--forget", default="none", choices=("none", "half-life", "detect"), help=FORGET_HELP
    )
    p.add_argument(
        "--half-life",
        type=positive_float,
        default=7.0,
        metavar="DAYS",
        help="half-life: days after which an examination weighs half (default: 7)",
    )
    p.add_argument(
        "--false-alarm",
        type=alpha,
        default=0.05,
        metavar="RATE",
        help="detect: probability that an entry which does not change raises an alarm in a run "
        "(default: 0.05)",
    )


def forgetting(args: argparse.Namespace):
    """The knowledge.drift.Forgetting of ``add_forget_arguments``'s options."""
    from ctxsearch.knowledge.drift import Forgetting

    return Forgetting(args.forget, args.half_life, args.false_alarm)


SEARCH_INTERVAL_HELP = (
    "interval method the search ranks by: corrected (the default, the search's: clustered, and "
    "each examination weighted by the chance its images would have shown a related object), "
    "clustered (Wilson on a room-level effective sample size) or wilson (the paper's eq. 1-2)"
)


def add_interval_argument(p: argparse.ArgumentParser, search: bool = False) -> None:
    """``--interval wilson|clustered|corrected``: Wilson by default (the paper's, what ``kb``
    and ``learn`` print), or with ``search`` the search configuration's default
    (``knowledge.interval``; the option's value is then None unless given)."""
    p.add_argument(
        "--interval",
        default=None if search else "wilson",
        choices=tuple(IntervalMethod),
        help=SEARCH_INTERVAL_HELP if search else INTERVAL_HELP,
    )
