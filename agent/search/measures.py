"""Every measure of a search, defined once: success, time to find, the time-weighted success
(spl), the paired ratio to a baseline with its tie rule, and the oracle's violations. The
benchmarks, the CLI, the demo and the Gymnasium task read them from here.

- **Success**: the search ended on a *confirmed* detection (a second image from the same pose
  detected the target again near the first one's position: ``agent.search.context``) of a true
  instance of the target, within the budget. A confirmed look-alike or false positive ends the
  search as a failure. Who knows the truth judges (``judge``): the episode runner, the
  Gymnasium task; the robot's behaviour never does.
- **Time to find**: the simulated seconds to the confirmed detection; a failure counts as the
  budget.
- **Ties**: two times closer than ``TIE_S`` seconds are equal: no win, no loss, no violation.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from statistics import NormalDist
from typing import Protocol

import numpy as np

TIE_S = 1e-6  # seconds: closer than this counts as a tie (no win, no loss, no violation)
BOOTSTRAP_SAMPLES = 2000


class Outcome(Protocol):
    """What the measures read of a search's result (``episode.SearchResult``)."""

    sim_time: float

    @property
    def success(self) -> bool:
        """Found within the budget (``success``)."""
        ...

    @property
    def time_to_find(self) -> float:
        """Seconds to find, the budget for a failure (``time_to_find``)."""
        ...


def judge(found_id: int | None, true_ids: Iterable[int]) -> bool:
    """Whether a search that ended on the confirmed detection of ``found_id`` (None: it did not
    end on one) found the target: the instance is one of the target's ``true_ids``."""
    return found_id is not None and found_id in set(true_ids)


def success(found: bool, sim_time: float, budget_s: float) -> bool:
    """Found (``judge``) within the budget."""
    return bool(found) and sim_time <= budget_s + 1e-9


def time_to_find(found: bool, sim_time: float, budget_s: float) -> float:
    """Seconds to find; a failure counts as the budget."""
    return float(sim_time) if success(found, sim_time, budget_s) else float(budget_s)


def bootstrap_ci(
    values: Sequence[float],
    stat: Callable[[np.ndarray], float] = np.median,
    samples: int = BOOTSTRAP_SAMPLES,
    seed: int = 0,
    level: float = 0.95,
) -> tuple[float, float]:
    """Percentile bootstrap interval of ``stat`` over ``values`` (seeded; (nan, nan) if empty).
    ``np.mean`` and ``np.median`` reduce all resamples in one call (the same numbers as one
    resample at a time, which any other ``stat`` gets)."""
    v = np.asarray(values, float)
    if len(v) == 0:
        return (math.nan, math.nan)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(v), size=(samples, len(v)))
    if stat is np.mean or stat is np.median:
        stats = stat(v[idx], axis=1)
    else:
        stats = np.apply_along_axis(stat, 1, v[idx])
    a = (1 - level) / 2
    return (float(np.quantile(stats, a)), float(np.quantile(stats, 1 - a)))


def r4(x):
    """A JSON number rounded to 4 decimals (None for None, nan, inf)."""
    return (
        None if x is None or (isinstance(x, float) and not math.isfinite(x)) else round(float(x), 4)
    )


@dataclass(frozen=True)
class PairedRatio:
    """The per-episode ratio of a policy's time to find to a baseline's over paired episodes:
    its median with a bootstrap interval, and the episodes it was faster in (wins), slower in
    (losses) and within ``TIE_S`` of the baseline (ties)."""

    median: float
    ci: tuple[float, float]
    wins: int
    losses: int
    ties: int
    n: int

    def to_json(self) -> dict:
        """The entry of search.json's ``paired_ratio`` (and the curve's, the transfer's)."""
        return {
            "median": r4(self.median),
            "ci": [r4(self.ci[0]), r4(self.ci[1])],
            "wins": self.wins,
            "losses": self.losses,
            "ties": self.ties,
            "n": self.n,
        }


def _paired(t: Sequence[float], t_base: Sequence[float]):
    """``t`` and ``t_base`` as aligned arrays, which episodes are ties (within ``TIE_S``), and
    the wins and losses (the one tie rule of every paired statistic)."""
    a, b = np.asarray(t, float), np.asarray(t_base, float)
    if a.shape != b.shape:
        raise ValueError(f"unpaired times: {a.shape} vs {b.shape}")
    tie = np.abs(a - b) <= TIE_S
    return a, b, tie, int(np.sum((a < b) & ~tie)), int(np.sum((a > b) & ~tie))


def paired_ratio(t: Sequence[float], t_base: Sequence[float], seed: int = 0) -> PairedRatio:
    """The paired ratio of times ``t`` to ``t_base`` (aligned episodes; see ``PairedRatio``)."""
    a, b, _tie, wins, losses = _paired(t, t_base)
    ratio = a / np.maximum(b, TIE_S)
    n = len(ratio)
    return PairedRatio(
        float(np.median(ratio)) if n else math.nan,
        bootstrap_ci(ratio, np.median, seed=seed),
        wins,
        losses,
        n - wins - losses,
        n,
    )


def spl(results: Sequence[Outcome], oracle: Sequence[Outcome]) -> float:
    """The time-weighted success: the mean over episodes of S * t_oracle / max(t, t_oracle), S
    success within the budget, t the simulated seconds to find, t_oracle the oracle's time to
    find on the same episode (the budget where it failed)."""
    if not results:
        return math.nan
    vals = []
    for r, o in zip(results, oracle, strict=True):
        t_o = o.time_to_find
        vals.append(t_o / max(r.sim_time, t_o, TIE_S) if r.success else 0.0)
    return float(np.mean(vals))


def oracle_violations(results: Sequence[Outcome], oracle: Sequence[Outcome]) -> int:
    """Episodes in which ``results`` found the target sooner than the oracle (or found it when
    the oracle did not): a bound that is not one. Must be 0."""
    return sum(
        1
        for r, o in zip(results, oracle, strict=True)
        if r.success and (not o.success or r.sim_time < o.sim_time - TIE_S)
    )


POWER = 0.8  # the power the episode count of ``PairedStats.episodes_for_power`` is sized for
TEST_ALPHA = 0.05  # two-sided level of the signed-rank test and of that count


@dataclass(frozen=True)
class PairedStats:
    """A policy against a baseline over paired episodes, the statistics that can see a small
    effect: the geometric mean of the per-episode time ratio with a bootstrap interval (the
    headline: ties count as ratio 1 and do not pin it as they pin a median), the ratio of mean
    times with a paired bootstrap interval, the Wilcoxon signed-rank test on the log ratios
    (ties dropped, two-sided), wins, losses and ties (within ``TIE_S``), and the episodes an
    effect of the measured size would need for ``POWER`` at ``TEST_ALPHA`` (normal
    approximation on the log ratio; None when there is no effect)."""

    geo_mean: float
    geo_mean_ci: tuple[float, float]
    ratio_of_means: float
    ratio_of_means_ci: tuple[float, float]
    wilcoxon_p: float
    wins: int
    losses: int
    ties: int
    n: int
    episodes_for_power: int | None

    def to_json(self) -> dict:
        """search.json's ``paired[baseline]`` entry."""
        return {
            "geo_mean": r4(self.geo_mean),
            "geo_mean_ci": [r4(self.geo_mean_ci[0]), r4(self.geo_mean_ci[1])],
            "ratio_of_means": r4(self.ratio_of_means),
            "ratio_of_means_ci": [r4(self.ratio_of_means_ci[0]), r4(self.ratio_of_means_ci[1])],
            "wilcoxon_p": r4(self.wilcoxon_p),
            "wins": self.wins,
            "losses": self.losses,
            "ties": self.ties,
            "n": self.n,
            "episodes_for_power": self.episodes_for_power,
        }


def paired_stats(t: Sequence[float], t_base: Sequence[float], seed: int = 0) -> PairedStats:
    """``PairedStats`` of times ``t`` against ``t_base`` (aligned episodes; failures at the
    budget). The bootstrap resamples episodes (seeded); scipy is imported here, not with the
    module, which the episode types use."""
    from scipy import stats as sps

    a, b, tie, wins, losses = _paired(t, t_base)
    n = len(a)
    if n == 0:
        nan2 = (math.nan, math.nan)
        return PairedStats(math.nan, nan2, math.nan, nan2, math.nan, 0, 0, 0, 0, None)
    logr = np.where(tie, 0.0, np.log(np.maximum(a, TIE_S) / np.maximum(b, TIE_S)))
    lo, hi = bootstrap_ci(logr, np.mean, seed=seed)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, n, size=(BOOTSTRAP_SAMPLES, n))
    rom = a[idx].mean(1) / np.maximum(b[idx].mean(1), TIE_S)
    rom_ci = (float(np.quantile(rom, 0.025)), float(np.quantile(rom, 0.975)))
    nonzero = logr[logr != 0.0]
    p = float(sps.wilcoxon(nonzero).pvalue) if len(nonzero) else 1.0
    sd, mean = float(np.std(logr, ddof=1)) if n > 1 else 0.0, float(np.mean(logr))
    need = None
    if mean != 0.0 and sd > 0.0:
        z = NormalDist().inv_cdf(1 - TEST_ALPHA / 2) + NormalDist().inv_cdf(POWER)
        need = int(math.ceil((z * sd / abs(mean)) ** 2))
    return PairedStats(
        float(np.exp(mean)), (float(np.exp(lo)), float(np.exp(hi))),
        float(a.mean() / max(b.mean(), TIE_S)), rom_ci, p, wins, losses, n - wins - losses, n,
        need,
    )  # fmt: skip


def geo_cell(r: dict) -> str:
    """A Markdown cell of a ``PairedStats.to_json`` entry: the geometric mean [interval],
    wins/losses/ties and the signed-rank p ("p<0.001" below that; "-" where there is no
    estimate)."""
    if r["geo_mean"] is None:
        return "-"
    lo, hi = r["geo_mean_ci"]
    p = r["wilcoxon_p"]
    p_text = "p<0.001" if p is not None and p < 0.001 else f"p={p:.3f}"
    return (f"{r['geo_mean']:.2f} [{lo:.2f}, {hi:.2f}] {r['wins']}/{r['losses']}/{r['ties']} "
            f"{p_text}")  # fmt: skip
