"""The modes the command line and the configuration files choose among, one enum each.

They live at the bottom layer so that every layer (and the CLI, before it loads MuJoCo or
scipy) reads the same members: ``knowledge`` reads intervals, ranks and estimates; ``agent`` the
map and perception modes and what a search policy needs. A mode is parsed once, where it enters
(``parse``: a one-line error naming the known values), and compared as a member afterwards.
Members are ``StrEnum``: they print, format and serialise as their value, so files written
before the enums read and write the same text.
"""

from __future__ import annotations

from enum import StrEnum
from typing import TypeVar

from ctxsearch.knowledge.errors import CtxsearchError


class MapMode(StrEnum):
    """The map the robot plans on: the true layout's (``given``, furniture poses known), its
    own, built from its depth images (``built``), or, in a search, the map it built of the same
    home on an earlier day and remembers (``remembered``: agent.search.tour, agent.search.remembered)."""

    GIVEN = "given"
    BUILT = "built"
    REMEMBERED = "remembered"


# Camera mode: images of a room that must detect an object before it may be the reference of an
# examination. The paper examines every detected object (1); with the realistic detector that
# makes 11% (offices) to 21% (houses) of examinations ones of phantom references, each counting
# an A without a B. Two images cut that below 1% at no extra image and raise the intervals'
# coverage (docs/results.md, "Detector x interval"), so 2 is the default; ``learn --paper``
# gives the paper's literal loop.
DEFAULT_CONFIRM_REFERENCE = 2
PAPER_CONFIRM_REFERENCE = 1


class PerceptionMode(StrEnum):
    """How the robot recognises objects: rendered images and a detector (``camera``), or the
    true layout with line-of-sight tests (``oracle``)."""

    CAMERA = "camera"
    ORACLE = "oracle"


class IntervalMethod(StrEnum):
    """How counts become an interval: the paper's Wilson score interval, Wilson on a
    room-level effective sample size (``clustered``), or the score interval of a likelihood that
    knows each examination's chance of showing a related object, clustered the same way
    (``corrected``: knowledge.corrected)."""

    WILSON = "wilson"
    CLUSTERED = "clustered"
    CORRECTED = "corrected"


class Rank(StrEnum):
    """Which value of an interval ranks the search's candidate regions."""

    LOW = "low"
    P0 = "p0"
    HIGH = "high"


class Estimate(StrEnum):
    """Where P(rel(T)) comes from: each type's own evidence (``flat``, the paper's), or the
    class's backoff estimate for rarely examined types (``backoff``)."""

    FLAT = "flat"
    BACKOFF = "backoff"


class Forget(StrEnum):
    """How old evidence counts (knowledge.drift): all alike (``none``), down-weighted by its age
    (``half-life``), or dropped before a detected change (``detect``)."""

    NONE = "none"
    HALF_LIFE = "half-life"
    DETECT = "detect"


class Reexamine(StrEnum):
    """Whether an object examined on an earlier day is examined again: never (the paper) or when
    its type's impact per second is worth it."""

    NEVER = "never"
    IMPACT = "impact"


class FrontierRule(StrEnum):
    """How a frontier goal is picked on a built map (agent.frontiers)."""

    NEAREST = "nearest"
    INFO = "info"


class Targets(StrEnum):
    """What a search episode asks for: any instance of the target type (``type``), or the one
    instance the world keeps of it (``instance``: "find my phone")."""

    TYPE = "type"
    INSTANCE = "instance"


class Needs(StrEnum):
    """What a search policy's probabilities come from: nothing (no context), the learned
    knowledge store (``kb``) or the ground truth (``truth``)."""

    NONE = "none"
    KB = "kb"
    TRUTH = "truth"


class Handed(StrEnum):
    """What of the true house a bound on the built map is handed at the start, the rest being as
    on the built map (agent.search.room_prior.HandedRooms, agent.search.runner): nothing; every
    room's extent and kind (``room-kinds``, with the true target density by room kind); which
    rooms hold the target (``target-room``); the furniture plan, every piece's pose
    (``furniture-plan``)."""

    NOTHING = "nothing"
    ROOMS = "room-kinds"
    TARGET_ROOM = "target-room"
    PLAN = "furniture-plan"


E = TypeVar("E", bound=StrEnum)


def parse(kind: type[E], value: str | StrEnum, what: str | None = None) -> E:
    """``value`` as a member of ``kind``; a one-line error naming the known values otherwise
    (``what``: the name used in the message, default the enum's, e.g. 'map mode')."""
    try:
        return kind(value)
    except ValueError:
        name = what or _words(kind.__name__)
        known = ", ".join(m.value for m in kind)
        raise CtxsearchError(f"unknown {name} '{value}' (known: {known})") from None


def values(kind: type[StrEnum]) -> tuple[str, ...]:
    """The members' values, in declaration order (argparse ``choices``)."""
    return tuple(m.value for m in kind)


def _words(name: str) -> str:
    """``MapMode`` -> 'map mode'."""
    out = "".join(f" {c.lower()}" if c.isupper() else c for c in name).strip()
    return out
