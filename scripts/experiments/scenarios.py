"""Search scenarios and the paired ratio, shared by ``bench curve`` and ``bench transfer``.

A scenario names what the robot knows at the start of an episode (``built``: nothing, it builds
its map; ``given``: the true furniture poses; ``remembered``: its own map from a tour on an
earlier day) and three policies: the no-context baseline, the
context policy (the learned intervals) and the asymptote (the same policy with the true
probabilities). ``scenario_config`` turns a scenario into a ``bench search`` configuration.

The headline statistic is the **paired** ratio: per episode, the context policy's simulated
seconds to find over the baseline's (a failure counted at the budget), summarised by its median
over episodes with a seeded percentile bootstrap 95% interval, and the episodes the context
policy won, lost and tied (agent.search.measures: within ``TIE_S`` seconds is a tie).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ctxsearch.agent.search import measures
from ctxsearch.agent.search.config import HomeSource, SearchConfig
from ctxsearch.agent.search.episode import Episode
from ctxsearch.agent.search.registry import Role, parse_policies, with_role
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import MapMode
from ctxsearch.scripts.experiments.bench_search import BenchResult, bench_search
from ctxsearch.scripts.sweep import SweepOptions

SCENARIO_NAMES = tuple(m.value for m in (MapMode.BUILT, MapMode.GIVEN, MapMode.REMEMBERED))


@dataclass(frozen=True)
class Scenario:
    """A map scenario and its three policies (module docstring)."""

    name: str  # "built", "given" or "remembered": the map the robot searches on
    baseline: str  # no context
    context: str  # ranks by the learned intervals
    asymptote: str  # the context policy with the true probabilities

    @property
    def policies(self) -> tuple[str, str, str]:
        """(baseline, context, asymptote)."""
        return (self.baseline, self.context, self.asymptote)

    def to_json(self) -> dict:
        """The scenario as JSON."""
        return {
            "map": self.name,
            "baseline": self.baseline,
            "context": self.context,
            "asymptote": self.asymptote,
        }


def registry_scenario(mode: MapMode) -> Scenario:
    """Scenario ``mode`` with the policies the registry gives its roles."""
    roles = (Role.BASELINE, Role.CONTEXT, Role.ASYMPTOTE)
    return Scenario(mode.value, *(with_role(mode, r) for r in roles))


# The built map against frontier exploration, the given map against the map alone.
DEFAULT_SCENARIOS = {name: registry_scenario(MapMode(name)) for name in SCENARIO_NAMES}


def scenario_config(
    base: SearchConfig, scenario: Scenario, policies: Sequence[str] | None = None
) -> SearchConfig:
    """``base`` set up for ``scenario``: its policies (or ``policies``, a subset) and its map;
    on the remembered map the houses are held-out ones toured the day before (``map.home``
    tour, unless set): the stores compared learned maps of their own houses or none, and every
    store must search the same episodes."""
    changes: dict[str, object] = {
        "policies": tuple(policies or scenario.policies),
        "map.scenario": scenario.name,
    }
    if scenario.name == MapMode.REMEMBERED.value and base.map.home is None:
        changes["map.home"] = HomeSource.TOUR
    return base.updated(changes)


def parse_scenarios(names: str, overrides: dict[str, str | None]) -> tuple[Scenario, ...]:
    """The scenarios named in ``names`` (comma-separated, of SCENARIO_NAMES), each with its
    policies from ``overrides[name]`` ("baseline,context,asymptote") when given; one-line errors
    for unknown scenarios or policies."""
    out = []
    for name in (n.strip() for n in names.split(",") if n.strip()):
        if name not in DEFAULT_SCENARIOS:
            raise CtxsearchError(
                f"--scenarios: unknown scenario '{name}' (known: {', '.join(SCENARIO_NAMES)})"
            )
        if any(s.name == name for s in out):
            raise CtxsearchError(f"--scenarios: '{name}' is listed twice")
        text = overrides.get(name)
        sc = DEFAULT_SCENARIOS[name]
        if text is not None:
            try:
                names3 = parse_policies(text)
            except CtxsearchError as exc:
                raise CtxsearchError(f"--{name}-policies: {exc}") from None
            if len(names3) != 3:
                raise CtxsearchError(
                    f"--{name}-policies: give three policies, baseline,context,asymptote "
                    f"(got {len(names3)})"
                )
            sc = Scenario(name, *names3)
        out.append(sc)
    if not out:
        raise CtxsearchError("--scenarios: give at least one scenario")
    return tuple(out)


def check_policies(scenarios: Iterable[Scenario]) -> None:
    """A one-line error naming the first unknown policy of ``scenarios`` (before any learning)."""
    for sc in scenarios:
        try:
            parse_policies(",".join(sc.policies))
        except CtxsearchError as exc:
            raise CtxsearchError(
                f"scenario '{sc.name}': {exc} (choose others with --{sc.name}-policies)"
            ) from None


def check_no_stores(stores: Path) -> None:
    """A one-line error if ``stores`` holds knowledge stores already (an earlier run's
    learning): a benchmark never overwrites learned evidence."""
    old = sorted(stores.glob("*.sqlite")) if stores.is_dir() else []
    if old:
        raise CtxsearchError(
            f"{old[0]}: a knowledge store of an earlier run is in the way; remove {stores} or "
            "choose another --out"
        )


def times(res: BenchResult, policy: str) -> np.ndarray:
    """Simulated seconds to find per episode of ``policy`` in ``res`` (failures at the budget)."""
    return np.array([r.time_to_find for r in res.results[policy]], float)


def paired_ratio(t: Sequence[float], t_baseline: Sequence[float], seed: int = 0) -> dict:
    """The paired ratio of ``t`` to ``t_baseline`` as JSON (agent.search.measures.paired_ratio:
    median, bootstrap interval, wins, losses, ties, n)."""
    return measures.paired_ratio(t, t_baseline, seed=seed).to_json()


def paired(t: Sequence[float], t_baseline: Sequence[float], seed: int = 0) -> dict:
    """The paired statistics of ``t`` against ``t_baseline`` as JSON (agent.search.measures.
    paired_stats: geometric mean and ratio of means with intervals, Wilcoxon p, wins, losses,
    ties, n, the episodes for 80% power)."""
    return measures.paired_stats(t, t_baseline, seed=seed).to_json()


def episode_key(ep: Episode) -> tuple:
    """What makes two episodes the same: room, target, start pose and budget."""
    return (ep.style, ep.room_seed, ep.target, ep.start.x, ep.start.y, ep.start.yaw, ep.budget_s)


def same_episodes(a: Sequence[Episode], b: Sequence[Episode], what: str) -> None:
    """An error unless ``a`` and ``b`` are the same episodes (the pairing would be broken)."""
    if [episode_key(e) for e in a] != [episode_key(e) for e in b]:
        raise CtxsearchError(f"{what}: the episodes differ, the comparison would not be paired")


def search(
    base: SearchConfig,
    scenario: Scenario,
    out: Path,
    *,
    policies: Sequence[str] | None = None,
    kb: KnowledgeBase | None = None,
    sweep: SweepOptions | None = None,
    bar: bool = True,
) -> BenchResult:
    """``bench search`` of ``scenario`` (``policies``: a subset of its policies) on the store
    ``base.knowledge.kb`` or the in-memory ``kb`` (an empty store: k = 0), files in ``out``."""
    config = scenario_config(base, scenario, policies)
    return bench_search(config, out, progress=None, sweep=sweep, bar=bar, kb=kb)


# Per-episode rows of the curve's and the transfer's CSVs (after their own key columns).
RESULT_COLUMNS = (
    "map",
    "episode",
    "room_seed",
    "target",
    "policy",
    "role",  # baseline, context or asymptote
    "success",
    "sim_s",
    "time_to_find_s",
    "gazes",
    "path_m",
)


def result_rows(scenario: Scenario, res: BenchResult, policy: str, role: str):
    """One row (RESULT_COLUMNS) per episode of ``policy`` in ``res``."""
    for ep, r in zip(res.episodes, res.results[policy], strict=True):
        yield {
            "map": scenario.name,
            "episode": ep.index,
            "room_seed": ep.room_seed,
            "target": ep.target,
            "policy": policy,
            "role": role,
            "success": bool(r.success),
            "sim_s": float(r.sim_time),
            "time_to_find_s": float(r.time_to_find),
            "gazes": int(r.gazes),
            "path_m": float(r.path_m),
        }
