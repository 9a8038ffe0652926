"""A search's configuration: every setting of ``ctxsearch search`` and ``bench search``, typed
once, with its default, its range and its help, in frozen dataclasses.

The configuration is built once where a run starts (``SearchConfig`` from the command line: the
defaults here, then ``--config FILE``, then the flags a user gave, then each ``--set key=value``)
and then only read: the priors read ``knowledge``, the runner reads the style, the policies, the
draw and ``map``, and the behaviours read the sections a ``SearchContext`` carries
(``SearchContext.config``: ``map``, ``online``, ``belief``). Every result records it
(``to_dict``, with ``code_version``), and ``load_file`` reads it back from a TOML file or from
the result's JSON, so a run is repeated from its result file alone.

A key is dotted by section (``online.lookahead``, ``map.depth_range_m``, ``knowledge.rank``);
the top-level keys have no section (``budget_s``). Unknown keys, values of the wrong type and
numbers out of range are one-line errors (``ConfigError``) naming the key and where it came from.

Light on purpose (the standard library and the light ``knowledge`` modules): the command line's
parser reads the defaults and help from here without loading MuJoCo or scipy.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

from ctxsearch.knowledge import settings
from ctxsearch.knowledge.options import Estimate, IntervalMethod, MapMode, Rank, Targets
from ctxsearch.knowledge.ranking import DEFAULT_ESTIMATE, DEFAULT_MIN_EVIDENCE, DEFAULT_RANK

DEFAULT_BUDGET_S = 300.0  # simulated seconds an episode may take before it counts as failed
# m: the built map's depth range and the search's sight cap (nothing further counts as seen)
DEFAULT_DEPTH_RANGE_M = 5.0
MAX_COUNT = 1_000_000
MAX_SEED = 2**32 - 1


ConfigError = settings.SettingsError
setting = settings.setting


class Segments(StrEnum):
    """Where the rooms of the robot's own (built) map come from: its segmentation of what it
    mapped (``robot``), or the plan's true rooms (``plan``: an upper bound on what a better
    segmentation could give room context; the given map always has the plan's)."""

    ROBOT = "robot"
    PLAN = "plan"


class HomeSource(StrEnum):
    """Where the remembered map's houses come from: held-out houses the robot toured the day
    before (``tour``: the knowledge was learned in other houses), or the houses the knowledge
    store's learning visited on the built map (``store``: the knowledge includes their earlier
    days)."""

    TOUR = "tour"
    STORE = "store"


@dataclass(frozen=True)
class KnowledgeConfig:
    """Where a policy's probabilities come from and how they are read (agent.search.priors)."""

    kb: Path | None = setting(None, "the knowledge store made by `ctxsearch learn`")
    rank: Rank = setting(Rank(DEFAULT_RANK), "which value of the interval ranks (low, p0, high)")
    estimate: Estimate = setting(
        Estimate(DEFAULT_ESTIMATE),
        "flat (each type's own evidence, the paper's) or backoff (the class's estimate for types "
        "examined fewer than min_evidence times)",
    )
    min_evidence: int = setting(
        DEFAULT_MIN_EVIDENCE,
        "with backoff: examinations below which a type backs off",
        0,
        MAX_COUNT,
    )
    interval: IntervalMethod = setting(
        IntervalMethod.CORRECTED,
        "how the learned counts become intervals: corrected (the recall-aware interval, the one "
        "whose coverage holds 0.90 with the realistic detector; clustered where the store has "
        "no views, as the oracle's), clustered or wilson (the paper's eq. 1-2)",
    )
    room_context: bool = setting(
        False,
        "the context policies also use P(SAME-ROOM-AS-F(T)) on the rooms of the map: the "
        "learned ones the store's, the oracle-prior ones the truth's",
    )
    next_rooms: bool = setting(
        False,
        "with room_context, on the built map: the space beyond the mapped rooms takes the target "
        "mass P(NEXT-ROOM-OF-F(T)) of the nearest mapped room's furniture implies (the learned "
        "ones the store's, the oracle-prior ones the truth's)",
    )
    next_room_m: float = setting(
        4.0,
        "m: with next_rooms, how far behind a mapped room's edge the room its doors lead to is "
        "taken to reach (unmapped space further on keeps the house's average)",
        0.0,
        50.0,
    )
    glimpse_m: float = setting(
        2.0,
        "m: with next_rooms, the unmapped space this close to furniture seen beyond the mapped "
        "floor takes that furniture's P(SAME-ROOM-AS-F(T))",
        0.0,
        50.0,
    )
    truth: Path | None = setting(None, "ground truth of `ctxsearch truth` for oracle-prior")
    truth_samples: int = setting(
        200, "worlds sampled for the ground truth when truth is not given", 1, MAX_COUNT
    )


@dataclass(frozen=True)
class MapConfig:
    """What the robot knows of the world at the start and how far its map reaches."""

    scenario: MapMode | None = setting(
        None,
        "built (the robot maps as it searches), given (the true furniture plan is known) or "
        "remembered (the robot's own map of the house from a tour on an earlier day); none: "
        "built in houses, given in single rooms",
    )
    depth_range_m: float = setting(
        DEFAULT_DEPTH_RANGE_M,
        "m: how far the built map reads depth, and the search's sight cap (nothing further "
        "counts as seen)",
        1.0,
        30.0,
    )
    segments: Segments = setting(
        Segments.ROBOT,
        "the built and remembered maps' rooms: the robot's segmentation (robot) or the plan's "
        "(a bound)",
    )
    tour_budget_s: float = setting(
        1800.0,
        "remembered map: simulated seconds the tour that made it may take (agent.search.tour)",
        1.0,
        1e6,
    )
    home: HomeSource | None = setting(
        None,
        "remembered map: tour (held-out houses toured the day before) or store (the store's "
        "learned houses and their maps); none: store if the knowledge store holds maps of the "
        "style, else tour",
    )
    days_after: int | None = setting(
        None,
        "the search happens this many days after day 0 (on the remembered map: after the day "
        "its map was made); furniture stays, small objects stay or move by their type's stay "
        "probability; none: 1 on "
        "the remembered map, 0 otherwise",
        0,
        1000,
    )


@dataclass(frozen=True)
class OnlineConfig:
    """The online decision (agent.search.online)."""

    lookahead: bool = setting(
        False, "choose by a two-step look-ahead instead of the most mass per second"
    )
    beyond: bool = setting(
        False,
        "on the robot's own map, also value places not mapped yet: a sweep from any cell "
        "reachable through unknown space, by the belief it would find per second of the way "
        "there (frontier potentials); the robot drives to where that way leaves its map",
    )
    calibration_prior_s: float = setting(
        30.0,
        "expected seconds of weight the calibration of each option kind's estimates starts with",
        1e-3,
        1e6,
    )


@dataclass(frozen=True)
class BeliefConfig:
    """The search's belief (agent.search.belief)."""

    stop_mass: float = setting(
        0.02,
        "stop before the budget when less than this share of detectable mass is left",
        0.0,
        1.0,
    )


@dataclass(frozen=True)
class SearchConfig:
    """Everything a search or a search benchmark runs with (module docstring)."""

    style: str = setting("office", "room or house style: a name or a TOML path")
    policies: tuple[str, ...] = setting(
        (), "policies (name or name@rank); empty: the map scenario's defaults"
    )
    seed: int = setting(0, "which held-out worlds and start poses", 0, MAX_SEED)
    episodes: int = setting(40, "paired episodes (bench search)", 1, MAX_COUNT)
    budget_s: float = setting(
        DEFAULT_BUDGET_S, "simulated seconds before an episode counts as failed", None, 1e9
    )
    targets: Targets = setting(
        Targets.TYPE, "type (any instance ends a search) or instance (one kept: find my phone)"
    )
    detector: str | None = setting(None, "detector preset: name or TOML path; none: realistic")
    draw_cache: Path | None = setting(None, "where the episode draw is kept and reused")
    knowledge: KnowledgeConfig = field(default_factory=KnowledgeConfig)
    map: MapConfig = field(default_factory=MapConfig)
    online: OnlineConfig = field(default_factory=OnlineConfig)
    belief: BeliefConfig = field(default_factory=BeliefConfig)

    def __post_init__(self) -> None:
        settings.check(self)
        if self.knowledge.next_rooms and not self.knowledge.room_context:
            raise ConfigError(
                "knowledge.next_rooms needs knowledge.room_context (--room-context): the space "
                "beyond the rooms is part of room context"
            )

    # ------------------------------------------------------------------ derived
    @property
    def scenario(self) -> MapMode:
        """The map scenario (``map.scenario``, as ``runner.prepare`` resolves it)."""
        if self.map.scenario is None:
            raise ConfigError("map.scenario is not resolved (agent.search.runner.prepare)")
        return self.map.scenario

    def detector_model(self, catalog):
        """The detector preset, loaded and checked against ``catalog`` (one-line errors)."""
        from ctxsearch.agent.perception_modes import DEFAULT_DETECTOR
        from ctxsearch.envs.detector import default_or_named

        return default_or_named(self.detector, catalog, DEFAULT_DETECTOR)

    def with_scenario(self, mode: MapMode | str) -> SearchConfig:
        """This configuration on map scenario ``mode``."""
        return self.updated({"map.scenario": mode})

    def updated(self, changes: dict[str, object], where: str = "configuration") -> SearchConfig:
        """This configuration with the dotted keys of ``changes`` set (checked as a file's
        values are)."""
        return settings.updated(self, changes, where)


def keys() -> dict:
    """Every key of the search configuration (dotted) and its field."""
    return settings.keys(SearchConfig)


def apply_set(config: SearchConfig, assignment: str) -> SearchConfig:
    """``config`` with one ``key=value`` from the command line applied."""
    return settings.apply_set(config, assignment)


def load_file(path: Path | str, base: SearchConfig | None = None) -> SearchConfig:
    """The search configuration in the TOML or JSON file at ``path`` over ``base`` (default:
    the defaults): knowledge.settings.load_file."""
    return settings.load_file(path, base or SearchConfig())


def help_of(key: str) -> str:
    """A key's help line with its default."""
    return settings.help_of(SearchConfig(), key)


to_dict, to_toml = settings.to_dict, settings.to_toml
