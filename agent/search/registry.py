"""The search policies and their facts, in one table: which map scenarios each runs in, what its
probabilities come from, and its role in each scenario (the no-context baseline, the context
policy, its asymptote with the true probabilities, the oracle's bound, a reference). The CLI reads
it to build its parser without importing MuJoCo or scipy; the behaviours are in
``agent.search.policies`` (and ``agent.search.oracle``).

A policy name may carry a rank, ``location@low``: which value of the interval ranks its candidate
regions. A run's names are resolved once (``resolve``) into ``PolicySpec``s, which the priors, the
runner and the behaviours read; nothing downstream parses a name again.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import Handed, MapMode, Needs, Rank, parse, values


class Role(StrEnum):
    """A policy's part in a map scenario's comparison."""

    BASELINE = "baseline"  # no context, the same machinery: the context policy's fair twin
    CONTEXT = "context"  # the learned knowledge
    ASYMPTOTE = "asymptote"  # the context policy with the true probabilities
    # a lower bound on time to find: the oracle, and on the built map the ladder of what exact
    # knowledge of one kind (the rooms, the target's room, the furniture plan) would buy
    BOUND = "bound"
    REFERENCE = "reference"  # run by default for reference, compared with nothing


@dataclass(frozen=True)
class PolicyInfo:
    """One search policy's facts."""

    name: str
    maps: tuple[MapMode, ...]  # the scenarios it runs in
    roles: tuple[tuple[MapMode, Role], ...]  # its role in the scenarios it runs in by default
    needs: Needs = Needs.NONE  # where its probabilities come from
    reads_truth: bool = False  # plans on the true layout and the detector's draws (the oracle)
    summary: str = ""
    # the scenarios in which its belief takes room context (P(SAME-ROOM-AS-F(T))) when it is on
    room_context: tuple[MapMode, ...] = ()
    # where the persistence of its remembered sightings comes from (agent.search.memory): NONE
    # (no memory), KB (learned by the robot: the store's maps' checks) or TRUTH (the true worlds)
    memory: Needs = Needs.NONE
    # what of the true house it is handed at the start (a bound on the built map; NOTHING: none)
    handed: Handed = Handed.NOTHING

    def role(self, mode: MapMode) -> Role | None:
        """Its role in scenario ``mode`` (None: not run there by default)."""
        return dict(self.roles).get(mode)


_B, _G, _R = MapMode.BUILT, MapMode.GIVEN, MapMode.REMEMBERED
# In this order: each scenario's default policies are the entries with a role there, in order.
REGISTRY: tuple[PolicyInfo, ...] = (
    PolicyInfo("frontier", (_B,), ((_B, Role.BASELINE),),
               summary="no context: the belief with every point alike, on the robot's own map"),
    PolicyInfo("uniform", (_G, _R), ((_G, Role.BASELINE), (_R, Role.BASELINE)),
               summary="no context: the belief with every point alike (location's twin)"),
    PolicyInfo("memory", (_R,), ((_R, Role.REFERENCE),), memory=Needs.KB,
               summary="memory only: the last sightings by the learned persistence, the rest "
                       "alike"),
    PolicyInfo("map-only", (_G, _R), ((_G, Role.REFERENCE),),
               summary="no context: every relation volume of the known furniture, a short tour"),
    PolicyInfo("location", (_G, _R), ((_G, Role.CONTEXT), (_R, Role.REFERENCE)), Needs.KB,
               summary="location constraint: the belief over relation volumes by P(rel(T))",
               room_context=(_G, _R)),
    PolicyInfo("memory-location", (_R,), ((_R, Role.CONTEXT),), Needs.KB,
               summary="memory and the location constraint: the last sightings by the learned "
                       "persistence, the rest by P(rel(T))",
               room_context=(_R,), memory=Needs.KB),
    PolicyInfo("indirect", (_B, _G, _R), ((_B, Role.CONTEXT),), Needs.KB,
               summary="detectability-driven: intermediate types, volumes and frontier",
               room_context=(_B, _R)),
    PolicyInfo("oracle-prior", (_G, _R), ((_G, Role.ASYMPTOTE),),
               Needs.TRUTH, summary="location with the true probabilities",
               room_context=(_G, _R)),
    PolicyInfo("oracle-memory", (_R,), ((_R, Role.ASYMPTOTE),), Needs.TRUTH,
               summary="memory-location with the true persistence and the true "
                       "probabilities", room_context=(_R,), memory=Needs.TRUTH),
    PolicyInfo("oracle-prior-indirect", (_B, _G, _R), ((_B, Role.ASYMPTOTE),), Needs.TRUTH,
               summary="indirect with the true probabilities", room_context=(_B, _R)),
    # The ladder of bounds on the built map: what one kind of knowledge of the house, handed
    # at the start and exact, buys with the frontier's machinery (agent.search.room_prior).
    PolicyInfo("bound-rooms", (_B,), ((_B, Role.BOUND),), handed=Handed.ROOMS,
               summary="frontier, handed every room's extent and kind and the true target "
                       "density by room kind"),
    PolicyInfo("bound-target-room", (_B,), ((_B, Role.BOUND),), handed=Handed.TARGET_ROOM,
               summary="frontier, handed which rooms hold the target (not where in them)"),
    PolicyInfo("bound-plan", (_B,), ((_B, Role.BOUND),), Needs.TRUTH, handed=Handed.PLAN,
               summary="the location constraint with the true probabilities, handed the "
                       "furniture plan (the given map's furniture) on the built map",
               room_context=(_B,)),
    PolicyInfo("oracle", (_B, _G, _R), ((_B, Role.BOUND), (_G, Role.BOUND), (_R, Role.BOUND)),
               reads_truth=True,
               summary="knows the target and the detector's draws: the lower bound"),
    PolicyInfo("exhaustive", (_G, _R), ((_G, Role.REFERENCE),),
               summary="no context: coverage of the whole map"),
)  # fmt: skip
POLICIES: dict[str, PolicyInfo] = {p.name: p for p in REGISTRY}


def info(name: str) -> PolicyInfo:
    """A policy's facts by base name; a one-line error naming the known ones otherwise."""
    p = POLICIES.get(name)
    if p is None:
        raise CtxsearchError(f"unknown search policy '{name}' (known: {', '.join(POLICIES)})")
    return p


def default_policies(mode: MapMode) -> tuple[str, ...]:
    """The policies ``bench search`` runs in scenario ``mode`` when none are named."""
    return tuple(p.name for p in REGISTRY if p.role(mode) is not None)


def with_role(mode: MapMode, role: Role) -> str:
    """The policy that plays ``role`` in scenario ``mode``."""
    for p in REGISTRY:
        if p.role(mode) is role:
            return p.name
    raise CtxsearchError(f"no policy is the {role} of the {mode} map")


@dataclass(frozen=True)
class PolicySpec:
    """A policy of a run, resolved once: the name as given (``location@low``, what results and
    recordings are keyed by), the registry's facts of its base name, its rank (None: the run's
    default) and the map scenario it runs in."""

    name: str
    info: PolicyInfo
    rank: Rank | None
    scenario: MapMode

    @property
    def base(self) -> str:
        """The registry's name (``location``)."""
        return self.info.name

    @property
    def needs(self) -> Needs:
        """Where its probabilities come from."""
        return self.info.needs

    @property
    def memory(self) -> Needs:
        """Where the persistence of its remembered sightings comes from (NONE: no memory)."""
        return self.info.memory

    @property
    def uses_room_context(self) -> bool:
        """Whether its belief takes room context in its scenario."""
        return self.scenario in self.info.room_context


def resolve(
    names: Sequence[str], mode: MapMode | str, room_context: bool = False
) -> tuple[PolicySpec, ...]:
    """The policies ``names`` (each ``name`` or ``name@rank``) of a run in scenario ``mode``,
    resolved; one-line errors for an unknown policy or rank, a policy listed twice or one that
    does not run in ``mode``, and for room context (``room_context``) asked of a run in which a
    policy with knowledge cannot use it, or no policy uses it at all. (The no-context baselines
    run unchanged beside room context: they are the context policies' twins.)"""
    mode = parse(MapMode, mode, "map")
    _checked(list(names), ",".join(names))
    specs = []
    for name in names:
        base, rank = split_name(name)
        p = info(base)
        if mode not in p.maps:
            raise CtxsearchError(f"policy '{base}' needs --map {p.maps[0]}")
        specs.append(PolicySpec(name, p, rank, mode))
    if room_context:
        for s in specs:
            if s.needs is not Needs.NONE and not s.uses_room_context:
                raise CtxsearchError(
                    f"policy '{s.base}' cannot use room context on the {mode} map "
                    "(knowledge.room_context / --room-context)"
                )
        if not any(s.uses_room_context for s in specs):
            raise CtxsearchError(
                f"no policy of {','.join(names)} uses room context (knowledge.room_context / "
                "--room-context): it applies to the context policies"
            )
    return tuple(specs)


def split_name(name: str) -> tuple[str, Rank | None]:
    """``location@low`` -> ("location", Rank.LOW); ``location`` -> ("location", None); one-line
    errors for an unknown policy or rank."""
    base, _, rank = name.partition("@")
    info(base)
    if not rank:
        return base, None
    if rank not in values(Rank):
        raise CtxsearchError(
            f"unknown rank '{rank}' in '{name}' (known: {', '.join(values(Rank))})"
        )
    return base, Rank(rank)


def parse_policies(text: str) -> list[str]:
    """A comma-separated list of policy names (each optionally ``name@rank``), checked."""
    return _checked([n.strip() for n in text.split(",") if n.strip()], text)


def _checked(names: list[str], shown: str) -> list[str]:
    """``names``; one-line errors for none, an unknown policy or rank, or a name twice."""
    if not names:
        raise CtxsearchError("no search policy given")
    for n in names:
        split_name(n)
    if len(set(names)) != len(names):
        raise CtxsearchError(f"a policy is listed twice in '{shown}'")
    return names
