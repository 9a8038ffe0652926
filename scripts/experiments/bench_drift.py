"""``ctxsearch bench drift``: a world set that changes over days, and how each forgetting method
(knowledge.drift: none, half-life, detect) notices it.

One drifting world set: ``rooms`` rooms of a style visited on ``days`` days (``learn --days``), the
style carrying a drift schedule (its own ``[[drift]]`` entries, or ``--drift RULE:P:FROM_DAY``
given here, applied in memory: committed styles are never changed). Two kinds of evidence, on the
same days and seeds:

- ``every-day``: one learning run that examines every known object again every day
  (``--reexamine impact --reexamine-rate 0``): the same store is read by every method, so the
  detection figures compare the methods on identical evidence;
- ``impact``: one learning run per method with ``--reexamine impact`` at the default rate and
  ``--forget`` that method: the acquisition itself decides (by the method's counts) whether
  yesterday's desk is worth examining today, so this measures the whole loop.

Ground truth per day: the bench's own worlds (their furniture as it is) over ``truth_samples``
day draws of their small objects under each phase's rules (day 0 and every ``from_day``: envs.truth
on those days), p_true(day) that of the latest phase: what a robot visiting these worlds can learn
(their few desks are not the style's population). An entry (A, rel, B)
is *changed* when |p_true(last day) - p_true(0)| >= ``CHANGE_MIN`` and *unchanged* when it moves
by at most ``STABLE_MAX`` and 0.02 <= p_true <= 0.98 (entries that are always or never true
teach nothing about false alarms). For each method and entry:

- ``detection_delay_days`` (changed): days from the change until the method's interval (at the
  store's alpha) first excludes the old value p_true(from_day - 1); None if it never did;
- ``recovery_delay_days`` (changed): days from the change until the interval first contains the
  new value (the knowledge is right again); None if it never did within the run;
- ``false_alarm_rate`` (unchanged): the share of (entry, day) pairs, from the first change on,
  whose interval excludes the entry's (constant) true value;
- ``alarm_rate`` (detect only, unchanged): the share of entries on which the change test raised
  an alarm in the run (its stated rate: ``false_alarm``);
- ``abs_error``: mean over days of |p0 - p_true(day)| (p0: the Wilson centre of the method's
  counts), over the changed and over the unchanged entries;
- search: ``location`` searches (the paper's location constraint ranked by each method's
  intervals on the last day) for ``episodes`` targets in held-out rooms of the style as it
  stands on the last day, with each method's ``impact`` store.

Writes DIR/drift.json, DIR/drift.md, DIR/drift.csv (one row per day x entry x method x evidence)
and DIR/drift.png (p_true(day) against each method's interval, for the changed entries).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ctxsearch.agent.learning import LearnConfig, learn, room_seed
from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.agent.search.draw import DrawSpec, make_episodes
from ctxsearch.agent.search.priors import KnowledgeSource, make_priors
from ctxsearch.agent.search.registry import resolve
from ctxsearch.agent.search.runner import PolicyRun, WorldRuns, search_world
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.styles import EVERY_TYPE, Drift, Style, load_style
from ctxsearch.envs.truth import estimate, sample_counts
from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.drift import FORGET_METHODS, ForgetKnowledgeBase, Forgetting, evidence_of
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import Forget, MapMode
from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.experiments.tables import write_csv
from ctxsearch.scripts.sweep import SweepOptions, run_units

CHANGE_MIN = 0.10  # |p_true(last) - p_true(0)| of a changed entry
STABLE_MAX = 0.02  # at most this much for an unchanged one
EVIDENCE = ("every-day", "impact")
CSV_COLUMNS = ("evidence", "method", "day", "ref", "relation", "type", "status", "y", "n", "p0",
               "low", "high", "p_true", "excludes_old")  # fmt: skip


def parse_drift(text: str, days: int) -> Drift:
    """``RULE:P:FROM_DAY`` (e.g. ``Desk/ON-TOP-OF-DESK/Laptop:0.9:6``) as a Drift; FROM_DAY may be
    ``half`` (days // 2). One-line CtxsearchError otherwise."""
    parts = text.rsplit(":", 2)
    if len(parts) != 3:
        raise CtxsearchError(f"--drift {text!r}: expected RULE:P:FROM_DAY")
    rule, p, day = parts
    try:
        pv = float(p)
        dv = max(1, days // 2) if day == "half" else int(day)
    except ValueError:
        raise CtxsearchError(f"--drift {text!r}: P must be a number, FROM_DAY an integer") from None
    if not 0.0 <= pv <= 1.0:
        raise CtxsearchError(f"--drift {text!r}: P must be in [0, 1]")
    if not 1 <= dv < days:
        raise CtxsearchError(
            f"--drift {text!r}: FROM_DAY must be in [1, {days - 1}] (--days {days})"
        )
    return Drift(rule, pv, dv)


# The default schedule on office: half way, the department moves from workstations to laptops.
DEFAULT_DRIFT = ("Desk/ON-TOP-OF-DESK/Laptop:0.9:half", "Desk/ON-TOP-OF-DESK/Monitor:0.3:half")


@dataclass(frozen=True)
class DriftBenchConfig:
    """What ``bench drift`` measures (see the module docstring)."""

    style: str = "office"
    days: int = 12
    rooms: int = 4
    seed: int = 0
    drift: tuple[str, ...] = ()  # RULE:P:FROM_DAY; empty: the style's own schedule or DEFAULT
    half_life: float = 3.0
    false_alarm: float = 0.05
    truth_samples: int = 30  # day draws of the worlds per phase for p_true
    episodes: int = 4
    perception: str = "oracle"
    # every small type's stay probability in the drifting worlds (the style's [stay] "*"): 0, the
    # small objects placed anew each day, isolates the rules' drift from persistence (the set the
    # forgetting methods were measured on); None: the style's own
    stay: float | None = 0.0

    def forgettings(self) -> dict[str, Forgetting]:
        """Each method with this configuration's parameters (detect tests on every day)."""
        return {
            m: Forgetting(m, self.half_life, self.false_alarm, looks=self.days)
            for m in FORGET_METHODS
        }


def drifting_style(config: DriftBenchConfig, catalog: Catalog) -> Style:
    """The style with its drift schedule (``config.drift``, its own, or DEFAULT_DRIFT) and
    ``config.stay`` for every small type (if set)."""
    st = load_style(config.style, catalog)
    if config.stay is not None:
        st = replace(st, stays=((EVERY_TYPE, float(config.stay)),))
    if config.drift:
        specs = config.drift
    elif st.drift:
        return st
    else:
        specs = DEFAULT_DRIFT
    return st.with_drift(tuple(parse_drift(s, config.days) for s in specs), catalog)


def _learn_unit(unit: dict) -> dict:
    """One learning run of the bench (a sweep unit): plain data in and out."""
    catalog = load_catalog()
    config = DriftBenchConfig(**unit["config"])
    st = drifting_style(config, catalog)
    f = config.forgettings()[unit["method"]]
    lc = LearnConfig(st.name, config.rooms, unit["kb"], perception=config.perception,
                     seed=config.seed, progress=False, days=config.days, reexamine="impact",
                     forgetting=f, **({"reexamine_rate": 0.0} if unit["rate0"] else {}))  # fmt: skip
    t0 = time.perf_counter()
    s = learn(
        lc, catalog=catalog, layouts=lambda i, seed, day=0: generate_layout(st, seed, catalog, day)
    )
    return {"run": s.run, "examinations": s.examinations, "sim_s": s.sim_s,
            "revisits": s.revisits, "wall_s": time.perf_counter() - t0}  # fmt: skip


@dataclass
class Truth:
    """p_true per entry on every day (from the schedule's phases)."""

    phases: dict[int, dict[tuple[str, str, str], float]]  # first day of a phase -> entry -> p
    se: dict[int, dict[tuple[str, str, str], float]]  # its binomial standard error

    def p(self, key: tuple[str, str, str], day: int) -> float:
        """p_true of ``key`` on ``day`` (0 where the entry's reference type never occurs)."""
        start = max(d for d in self.phases if d <= day)
        return self.phases[start].get(key, 0.0)

    def entries(self) -> list[tuple[str, str, str]]:
        """Every entry with an instance of its reference type in some phase."""
        return sorted(set().union(*(set(p) for p in self.phases.values())))


def _truth(st: Style, config: DriftBenchConfig, catalog: Catalog) -> Truth:
    """p_true of the bench's own worlds in each phase of the schedule: their furniture as it is,
    their small objects over ``truth_samples`` day draws of that phase's rules (days 1..K of the
    style with the phase's drift entries in force from day 1), so the truth is what a robot
    visiting these worlds can learn. The phases share their day draws (common random numbers)."""
    starts = sorted({0} | {d.from_day for d in st.drift if d.from_day < config.days})
    seeds = [room_seed(config.seed, i) for i in range(config.rooms)]
    phases, se = {}, {}
    for day in starts:
        active = tuple(Drift(d.rule, d.p, 1) for d in st.drift if d.from_day <= day)
        phase = st.with_drift(active, catalog)
        rooms = [c for k in range(1, config.truth_samples + 1)
                 for c in sample_counts(phase, seeds, catalog, k)]  # fmt: skip
        entries = estimate(rooms, catalog)
        phases[day] = {(e["ref"], e["relation"], e["type"]): e["p"] for e in entries}
        se[day] = {(e["ref"], e["relation"], e["type"]): e["se_room"] for e in entries}
    return Truth(phases, se)


def classify(truth: Truth, last_day: int) -> dict[tuple[str, str, str], str]:
    """'changed' / 'unchanged' per entry (others left out: see the module docstring); a change
    must also exceed 3 standard errors of the two truths' difference."""
    out = {}
    last = max(d for d in truth.phases if d <= last_day)
    for key in truth.entries():
        p0, p1 = truth.p(key, 0), truth.p(key, last_day)
        ps = [truth.p(key, d) for d in truth.phases]
        noise = 3 * np.hypot(truth.se[0].get(key, 0.0), truth.se[last].get(key, 0.0))
        if abs(p1 - p0) >= max(CHANGE_MIN, noise):
            out[key] = "changed"
        elif max(ps) - min(ps) <= STABLE_MAX and 0.02 <= p0 <= 0.98:
            out[key] = "unchanged"
    return out


@dataclass
class Trace:
    """One method's reading of one store, per day and entry: (y, n, p0, low, high)."""

    rows: dict[tuple[str, str, str], list[tuple[float, float, float, float, float]]] = field(
        default_factory=dict
    )
    alarms: dict[tuple[str, str, str], list[int]] = field(default_factory=dict)


def read_store(path: Path, run: str, f: Forgetting, keys, days: int, catalog: Catalog) -> Trace:
    """The intervals ``f`` makes of the run's evidence at the end of every day, for ``keys``."""
    with EvidenceStore.open(path, catalog, read_only=True) as store:
        ev = evidence_of(store.examinations(run))
        alpha = store.alpha
    tr = Trace({k: [] for k in keys})
    for day in range(days):
        kb = ForgetKnowledgeBase(catalog, alpha, ev, day, f, last_day=days - 1)
        for k in keys:
            y, n = kb.counts(k[0], (k[1], k[2]))
            lo, hi = intervals.interval(y, n, alpha)
            tr.rows[k].append((y, n, float(intervals.p0(y, n, alpha)), float(lo), float(hi)))
    if f.method == Forget.DETECT:
        tr.alarms = {k: ev_alarms for k in keys
                     if (ev_alarms := ev.alarms(f, k[0], (k[1], k[2]), days - 1))}  # fmt: skip
    return tr


def _first_change(truth: Truth, key) -> int:
    days = sorted(truth.phases)
    for a, b in zip(days, days[1:], strict=False):
        if truth.phases[a].get(key, 0.0) != truth.phases[b].get(key, 0.0):
            return b
    return days[-1]


def measure(tr: Trace, truth: Truth, status: dict, days: int, f: Forgetting) -> dict:
    """The method's figures on one store (see the module docstring)."""
    change_day = min((d for d in truth.phases if d > 0), default=days)
    delays, recover, fa, err = {}, {}, [], {"changed": [], "unchanged": []}
    for key, st in status.items():
        rows = tr.rows[key]
        err[st].append(np.mean([abs(r[2] - truth.p(key, d)) for d, r in enumerate(rows)]))
        if st == "changed":
            start = _first_change(truth, key)
            old = truth.p(key, start - 1)
            hit = [d for d in range(start, days) if not rows[d][3] <= old <= rows[d][4]]
            delays["/".join(key)] = hit[0] - start if hit else None
            new = truth.p(key, days - 1)
            ok = [d for d in range(start, days) if rows[d][3] <= new <= rows[d][4]]
            recover["/".join(key)] = ok[0] - start if ok else None
        else:
            p = truth.p(key, 0)
            fa += [not rows[d][3] <= p <= rows[d][4] for d in range(change_day, days)]
    unchanged = [k for k, s in status.items() if s == "unchanged"]
    found = [v for v in delays.values() if v is not None]
    back = [v for v in recover.values() if v is not None]
    out = {
        "detection_delay_days": delays,
        "detected": len(found),
        "changed": len(delays),
        "mean_delay_days": float(np.mean(found)) if found else None,
        "recovery_delay_days": recover,
        "recovered": len(back),
        "mean_recovery_days": float(np.mean(back)) if back else None,
        "false_alarm_rate": float(np.mean(fa)) if fa else 0.0,
        "abs_error_changed": float(np.mean(err["changed"])) if err["changed"] else None,
        "abs_error_unchanged": float(np.mean(err["unchanged"])) if err["unchanged"] else None,
    }
    if f.method == Forget.DETECT:
        out["alarm_rate"] = (
            sum(1 for k in unchanged if tr.alarms.get(k)) / len(unchanged) if unchanged else 0.0
        )
    return out


def _search(st_last: Style, config: DriftBenchConfig, kbs: dict, learned: set, catalog) -> dict:
    """Each method's ``location`` search on the last day's style (one room per episode, shared)."""
    sc = SearchConfig(style=st_last.name, policies=("location",), seed=config.seed,
                      detector="perfect").with_scenario(MapMode.GIVEN)  # fmt: skip
    spec = DrawSpec.make(st_last, config.episodes, config.seed, catalog, sc.budget_s, learned)
    eps = make_episodes(spec, catalog)
    (location,) = resolve(sc.policies, sc.scenario)
    probs = {
        m: make_priors((location,), st_last, catalog, sc.knowledge, KnowledgeSource(kb)).for_policy(
            location
        )
        for m, kb in kbs.items()
    }
    times: dict[str, list[float]] = {m: [] for m in kbs}
    found: dict[str, list[bool]] = {m: [] for m in kbs}
    for ep in eps:
        runs = WorldRuns(tuple(PolicyRun(location, probs[m]) for m in kbs), sc,
                        sc.detector_model(catalog))  # fmt: skip
        for m, res in zip(kbs, search_world(ep, st_last, catalog, runs), strict=True):
            times[m].append(res.time_to_find)
            found[m].append(res.success)
    return {m: {"mean_time_s": float(np.mean(times[m])), "success": float(np.mean(found[m])),
                "episodes": len(eps)} for m in kbs}  # fmt: skip


def bench_drift(config: DriftBenchConfig, out: Path, sweep: SweepOptions | None = None) -> dict:
    """Run the benchmark (see the module docstring); writes its four files into ``out``."""
    sweep = sweep or SweepOptions()
    catalog = load_catalog()
    st = drifting_style(config, catalog)
    out = Path(out)
    (out / "stores").mkdir(parents=True, exist_ok=True)
    units = [{"config": asdict(config), "method": "none", "rate0": True,
              "kb": str(out / "stores" / "every-day.sqlite")}]  # fmt: skip
    units += [{"config": asdict(config), "method": m, "rate0": False,
               "kb": str(out / "stores" / f"impact-{m}.sqlite")} for m in FORGET_METHODS]  # fmt: skip
    for u in units:
        Path(u["kb"]).unlink(missing_ok=True)
    t0 = time.perf_counter()
    runs = run_units(_learn_unit, units, workers=sweep.workers, ray_address=sweep.ray_address,
                     desc="bench drift")  # fmt: skip
    truth = _truth(st, config, catalog)
    status = classify(truth, config.days - 1)
    fs = config.forgettings()
    traces: dict[tuple[str, str], Trace] = {}
    results: dict[str, dict] = {}
    for ev_name in EVIDENCE:
        for m, f in fs.items():
            unit = units[0] if ev_name == "every-day" else units[1 + FORGET_METHODS.index(m)]
            run = runs[units.index(unit)]
            tr = read_store(Path(unit["kb"]), run["run"], f, list(status), config.days, catalog)
            traces[(ev_name, m)] = tr
            results[f"{ev_name}/{m}"] = {**measure(tr, truth, status, config.days, f),
                                         "examinations": run["examinations"],
                                         "revisits": run["revisits"], "sim_s": run["sim_s"]}  # fmt: skip
    kbs = {}
    learned = {room_seed(config.seed, i) for i in range(config.rooms)}
    for m, f in fs.items():
        unit = units[1 + FORGET_METHODS.index(m)]
        with EvidenceStore.open(unit["kb"], catalog, read_only=True) as store:
            ev = evidence_of(store.examinations(runs[units.index(unit)]["run"]))
            kbs[m] = ForgetKnowledgeBase(catalog, store.alpha, ev, config.days - 1, f)
    search = (
        _search(st.on_day(config.days - 1), config, kbs, learned, catalog)
        if config.episodes
        else {}
    )
    doc = _document(config, st, truth, status, results, search, time.perf_counter() - t0)
    _write(out, doc, traces, truth, status, config)
    return doc


def _document(config, st: Style, truth: Truth, status, results, search, wall_s: float) -> dict:
    changed = sorted(
        (k for k, s in status.items() if s == "changed"),
        key=lambda k: (-abs(truth.p(k, config.days - 1) - truth.p(k, 0)), k),
    )
    return {
        "benchmark": "drift",
        "config": asdict(config),
        "style": st.name,
        "drift": [asdict(d) for d in st.drift],
        "entries": {"changed": len(changed), "unchanged": len(status) - len(changed)},
        "changed": [
            {
                "entry": "/".join(k),
                "p_before": truth.p(k, 0),
                "p_after": truth.p(k, config.days - 1),
            }
            for k in changed
        ],
        "results": results,
        "search": search,
        "wall_s": wall_s,
    }


def _write(out: Path, doc: dict, traces, truth: Truth, status, config) -> None:
    (out / "drift.json").write_text(json.dumps(doc, indent=1) + "\n")
    (out / "drift.md").write_text(markdown(doc) + "\n")
    rows = []
    for (ev_name, m), tr in traces.items():
        for key, seq in tr.rows.items():
            start = _first_change(truth, key)
            old = truth.p(key, start - 1) if status[key] == "changed" else truth.p(key, 0)
            for day, (y, n, c, lo, hi) in enumerate(seq):
                rows.append({"evidence": ev_name, "method": m, "day": day, "ref": key[0],
                             "relation": key[1], "type": key[2], "status": status[key],
                             "y": y, "n": n, "p0": c, "low": lo, "high": hi,
                             "p_true": truth.p(key, day), "excludes_old": not lo <= old <= hi})  # fmt: skip
    write_csv(out / "drift.csv", CSV_COLUMNS, rows)
    _plot(out / "drift.png", traces, truth, status, config)


PLOTTED = 6  # changed entries in drift.png (the largest changes)
LISTED = 12  # changed entries in drift.md's per-entry table


def _plot(path: Path, traces, truth: Truth, status, config) -> None:
    changed = sorted(
        (k for k, s in status.items() if s == "changed"),
        key=lambda k: (-abs(truth.p(k, config.days - 1) - truth.p(k, 0)), k),
    )[:PLOTTED]
    fig = Figure(figsize=(5 * max(1, len(changed)), 7))
    axes = fig.subplots(2, max(1, len(changed)), squeeze=False)
    xs = np.arange(config.days)
    colours = {"none": "tab:blue", "half-life": "tab:orange", "detect": "tab:green"}
    for r, ev_name in enumerate(EVIDENCE):
        for c, key in enumerate(changed):
            ax = axes[r, c]
            ax.step(xs, [truth.p(key, d) for d in xs], "k-", lw=2, where="post", label="p_true")
            for m, col in colours.items():
                seq = traces[(ev_name, m)].rows[key]
                ax.fill_between(xs, [s[3] for s in seq], [s[4] for s in seq], color=col, alpha=0.2)
                ax.plot(xs, [s[2] for s in seq], color=col, label=m)
            ax.set_title(f"{ev_name}: {'/'.join(key)}", fontsize=9)
            ax.set_xlabel("day")
            ax.set_ylim(0, 1)
            ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("P(rel(B)): truth and interval")
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)


def _fmt(v, spec: str = ".3f") -> str:
    return "-" if v is None else format(v, spec)


def markdown(doc: dict) -> str:
    """The benchmark's tables as Markdown."""
    c = doc["config"]
    lines = [
        f"# bench drift: {doc['style']}, {c['rooms']} rooms x {c['days']} days, seed {c['seed']}, "
        f"{c['perception']} perception",
        "",
        "Drift: "
        + "; ".join(
            f"{d['rule']} p -> {d['p']:g} from day {d['from_day']}" for d in doc["drift"]
        ),  # fmt: skip
        f"Entries: {doc['entries']['changed']} changed, {doc['entries']['unchanged']} unchanged "
        f"(half-life {c['half_life']:g} days, detect false-alarm rate {c['false_alarm']:g}).",
        "",
        "| evidence / method | detected | mean delay (days) | recovered | mean recovery (days) | "
        "false-alarm rate | alarm rate | abs error changed | abs error unchanged | examinations | "
        "re-examined |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in doc["results"].items():
        lines.append(
            f"| {name} | {r['detected']}/{r['changed']} | {_fmt(r['mean_delay_days'], '.1f')} | "
            f"{r['recovered']}/{r['changed']} | {_fmt(r['mean_recovery_days'], '.1f')} | "
            f"{r['false_alarm_rate']:.3f} | {_fmt(r.get('alarm_rate'))} | "
            f"{_fmt(r['abs_error_changed'])} | {_fmt(r['abs_error_unchanged'])} | "
            f"{r['examinations']} | {r['revisits']} |"
        )
    lines += ["", f"Days until the interval excludes the old value ({min(LISTED, len(doc['changed']))} "
              "largest changes; all in drift.json):", ""]  # fmt: skip
    lines += ["| entry | p before -> after | " + " | ".join(doc["results"]) + " |",
              "|---|---|" + "---|" * len(doc["results"])]  # fmt: skip
    for ch in doc["changed"][:LISTED]:
        cells = [_fmt(r["detection_delay_days"][ch["entry"]], "d") for r in doc["results"].values()]
        lines.append(f"| {ch['entry']} | {ch['p_before']:.2f} -> {ch['p_after']:.2f} | "
                     + " | ".join(cells) + " |")  # fmt: skip
    if doc["search"]:
        lines += ["", "Search on the last day (location policy, each method's impact store):", "",
                  "| method | mean time to find (s) | success |", "|---|---|---|"]  # fmt: skip
        for m, s in doc["search"].items():
            lines.append(f"| {m} | {s['mean_time_s']:.1f} | {s['success']:.2f} |")
    return "\n".join(lines)
