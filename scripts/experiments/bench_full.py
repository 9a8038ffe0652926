"""``make bench-full``: the benchmark at the counts that give its comparisons their power, in
steps that resume.

The steps (``plan``), each one ``ctxsearch`` command run as a child process:

- the learning curve in apartments (``bench curve``, k = 0, 1, 3, 10, 30, ``Counts.curve`` paired
  episodes per k and map scenario); its store after 30 apartments is the apartments' knowledge;
- a family-house store (``learn``, ``Counts.family_houses`` houses, realistic detector);
- per house style (paired episodes: ``Counts.apartment``, ``Counts.family``; on type targets
  ``Counts.apartment_type``, ``Counts.family_type``), per target kind (``instance``, "find my
  phone", the headline; ``type`` beside it) and per map scenario (``built``, ``given``,
  ``remembered``: ``POLICIES``), ``bench search`` with room context for the context policies;
  and, on the instance targets, the context policies without room context on the same episodes
  (the draw is kept in ``BUILD/draws``);
- the transfer table (``bench transfer``, ``Counts.transfer`` paired episodes per cell);
- ``summary.md`` / ``summary.json``: per style, target kind and scenario, each policy against the
  scenario's no-context baseline, and the context policy with room context against itself
  without (paired on the same episodes).

Every command gets ``--journal BUILD/journal`` (scripts.journal), so a step stopped at any moment
(a kill, even SIGKILL, a crash, a reboot) goes on where it stopped when ``make bench-full`` is run
again: its finished units are read back, never run again, and the files are the same as an
uninterrupted run's. A step that finished is skipped (its stamp ``BUILD/steps/NAME.json`` holds
its command line; another command line runs it again). The learning steps resume as
``ctxsearch learn`` does (agent.resume), the curve's as ``bench curve --journal`` does.

Progress: a line per step with the time spent and an estimate of the time left (the steps'
estimates from the measured costs, ``CPU_S`` and the others below, scaled by how the steps run
so far compared with theirs), and each command's own progress bars (their time left per step).
The default counts are sized to about 3.8 hours on 2 cores (docs/usage.md: the measured costs,
the estimate and the power the counts give). Runs unchanged on a Ray cluster: ``--ray-address
ADDR`` goes to every sweep.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from ctxsearch.knowledge.options import MapMode, Targets

CURVE_ROOMS = "0,1,3,10,30"
FAMILY_HOUSES = 10
TARGETS = (Targets.INSTANCE, Targets.TYPE)
MAPS = (MapMode.BUILT, MapMode.GIVEN, MapMode.REMEMBERED)
# The policies of each map scenario (the remembered map's: make bench's "find my phone"; the built
# map's: without make bench's three bounds; the given map's: with uniform, location's twin and its
# baseline, instead of exhaustive coverage), and each scenario's baseline and context policy (the
# one run again without room context).
POLICIES = {
    "built": "frontier,indirect,oracle-prior-indirect,oracle",
    "given": "uniform,map-only,location,oracle-prior,oracle",
    "remembered": "uniform,location,oracle-prior,oracle",
}
BASELINE = {"built": "frontier", "given": "uniform", "remembered": "uniform"}
CONTEXT = {"built": "indirect", "given": "location", "remembered": "location"}


@dataclass(frozen=True)
class Counts:
    """Paired episodes per step: per house style and target kind (per map scenario each), the
    curve's per k and scenario, the transfer's per cell."""

    apartment: int = 400
    apartment_type: int = 150
    family: int = 120
    family_type: int = 60
    curve: int = 100
    transfer: int = 100
    # the worlds learned: the curve's marks (its last is the apartments' store), the family
    # houses, each transfer style's rooms (smaller for a quick run of the whole, not the benchmark)
    curve_rooms: str = CURVE_ROOMS
    family_houses: int = FAMILY_HOUSES
    transfer_rooms: int = 10


# CPU seconds per paired episode (every policy of POLICIES, the draw's worlds and the remembered
# map's tour of the house included), measured with --workers 1 on 4 episodes each (the journal's
# cpu_s per unit; docs/usage.md, "make bench-full"), per (style, target kind, map); and of the
# context policy alone without room context (instance targets).
CPU_S = {
    ("apartment", "instance", "built"): 9.0,
    ("apartment", "instance", "given"): 3.9,
    ("apartment", "instance", "remembered"): 13.7,
    ("apartment", "type", "built"): 3.2,
    ("apartment", "type", "given"): 2.3,
    ("apartment", "type", "remembered"): 5.0,
    ("family_house", "instance", "built"): 11.2,
    ("family_house", "instance", "given"): 8.1,
    ("family_house", "instance", "remembered"): 33.8,
    ("family_house", "type", "built"): 4.8,
    ("family_house", "type", "given"): 4.0,
    ("family_house", "type", "remembered"): 8.0,
}
NO_ROOM_CONTEXT_CPU_S = {
    ("apartment", "built"): 2.4,
    ("apartment", "given"): 1.1,
    ("apartment", "remembered"): 1.2,
    ("family_house", "built"): 4.0,
    ("family_house", "given"): 2.3,
    ("family_house", "remembered"): 2.4,
}
CORES = 2  # the sweeps' units on two workers: wall = CPU / 2
STEP_FIXED_S = 30.0  # each command's start: imports, the ground truth of the oracle priors
# Wall seconds on 2 cores of the other steps (the curve's learning of 30 apartments and the
# family-house learning are one core's): curve per episode and fixed, transfer likewise.
CURVE_S = (4.0, 400.0)
TRANSFER_S = (6.5, 100.0)
LEARN_FAMILY_S = 300.0


@dataclass(frozen=True)
class Step:
    """One command of the plan: its name, ``ctxsearch``'s arguments (the sweep's added by
    ``main``, None for the summary, done here), and its estimated wall seconds on 2 cores."""

    name: str
    argv: tuple[str, ...] | None
    estimate_s: float
    sweep: bool = True  # takes --workers, --ray-address and --journal


def search_steps(
    out: Path, build: Path, style: str, kb: Path, counts: dict[str, int]
) -> list[Step]:
    """``bench search`` of ``style`` in every target kind (``counts``: its episodes) and map
    scenario, room context on; on the instance targets also the context policies without it."""
    steps = []
    for targets in TARGETS:
        n = counts[targets]
        for m in MAPS:
            where = out / style / targets
            base = ("bench", "search", "--kb", str(kb), "--style", style, "--map", str(m),
                    "--targets", str(targets), "--episodes", str(n),
                    "--draw-cache", str(build / "draws"))  # fmt: skip
            if m is MapMode.REMEMBERED:  # held-out houses toured the day before (make bench's)
                base = (*base, "--set", "map.home=tour")
            cpu = CPU_S[(style, targets, m)]
            steps.append(Step(f"{style}-{targets}-{m}",
                              (*base, "--policies", POLICIES[m], "--room-context", "--out",
                               str(where / m)), STEP_FIXED_S + n * cpu / CORES))  # fmt: skip
            if targets is Targets.INSTANCE:
                cpu = NO_ROOM_CONTEXT_CPU_S[(style, m)]
                steps.append(Step(f"{style}-{targets}-{m}-no-room-context",
                                  (*base, "--policies", CONTEXT[m], "--out",
                                   str(where / f"{m}-no-room-context")),
                                  STEP_FIXED_S + n * cpu / CORES))  # fmt: skip
    return steps


def plan(out: Path, build: Path, counts: Counts = Counts()) -> list[Step]:
    """Every step of ``make bench-full``, in order (the headline first)."""
    c = counts
    last = int(c.curve_rooms.split(",")[-1])
    apt_kb = out / "curve" / "stores" / f"k={last:04d}.sqlite"
    fam_kb = build / "kb_family_house.sqlite"
    apt = {"instance": c.apartment, "type": c.apartment_type}
    fam = {"instance": c.family, "type": c.family_type}
    steps = [
        Step("curve", ("bench", "curve", "--style", "apartment", "--rooms", c.curve_rooms,
                       "--seed", "0", "--episodes", str(c.curve),
                       "--out", str(out / "curve")), CURVE_S[1] + c.curve * CURVE_S[0]),
        *search_steps(out, build, "apartment", apt_kb, apt),
        Step("learn-family", ("learn", "--style", "family_house", "--rooms", str(c.family_houses),
                              "--detector", "realistic", "--seed", "0", "--kb", str(fam_kb)),
             LEARN_FAMILY_S, sweep=False),
        *search_steps(out, build, "family_house", fam_kb, fam),
        Step("transfer", ("bench", "transfer", "--styles", "office,biology_lab", "--rooms", str(c.transfer_rooms),
                          "--episodes", str(c.transfer),
                          "--out", str(out / "transfer")), TRANSFER_S[1] + c.transfer
                                                           * TRANSFER_S[0]),
        Step("summary", None, 5.0, sweep=False),
    ]  # fmt: skip
    return steps


def _hms(s: float) -> str:
    s = max(0, int(round(s)))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


def _say(line: str) -> None:
    print(f"[bench-full] {line}", flush=True)


def _stamp(build: Path, step: Step) -> Path:
    return build / "steps" / f"{step.name}.json"


def _finished(build: Path, step: Step, argv: list[str]) -> bool:
    try:
        return json.loads(_stamp(build, step).read_text()) == argv
    except (OSError, ValueError, UnicodeError):
        return False


def _write_stamp(build: Path, step: Step, argv: list[str]) -> None:
    path = _stamp(build, step)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(argv) + "\n")
    os.replace(tmp, path)


def _die_with_parent() -> None:
    """In the child: a SIGTERM when the parent (this script) ends, however it ends (Linux's
    PR_SET_PDEATHSIG; elsewhere nothing)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, int(signal.SIGTERM))
    except (OSError, AttributeError):
        pass


def run_command(argv: list[str]) -> int:
    """``ctxsearch argv`` as a child process; its stdout passed on without the per-episode lines
    (its progress bars, on stderr, as they are); its exit status."""
    cmd = [sys.executable, "-m", "ctxsearch.scripts.cli", *argv]
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True,
                          preexec_fn=_die_with_parent) as p:  # fmt: skip
        assert p.stdout is not None
        for line in p.stdout:
            if not line.startswith("episode "):
                sys.stdout.write(line)
                sys.stdout.flush()
        return p.wait()


def command(step: Step, build: Path, sweep: list[str]) -> list[str]:
    """The step's full ``ctxsearch`` arguments (the sweep's and the journal's added)."""
    assert step.argv is not None
    if not step.sweep:
        return list(step.argv)
    return [*step.argv, *sweep, "--journal", str(build / "journal")]


def main(argv: list[str] | None = None) -> int:
    """Run (or, with ``--list``, list) the steps not finished yet; the exit status of the first
    that fails, else 0."""
    a = _parser().parse_args(argv)
    sweep = ["--workers", str(a.workers)] + (["--ray-address", a.ray_address]
                                             if a.ray_address else [])  # fmt: skip
    counts = Counts(a.apartment_episodes, a.apartment_type_episodes, a.family_episodes,
                    a.family_type_episodes, a.curve_episodes, a.transfer_episodes,
                    a.curve_rooms, a.family_houses, a.transfer_rooms)  # fmt: skip
    steps = plan(a.out, a.build, counts)
    todo = []
    for s in steps:
        full = command(s, a.build, sweep) if s.argv is not None else []
        done = _finished(a.build, s, full)
        todo.append((s, full, done))
    left = sum(s.estimate_s for s, _f, done in todo if not done)
    _say(f"{len(steps)} steps, {sum(not d for *_, d in todo)} to run; estimated "
         f"{_hms(left)} on 2 cores (the whole: {_hms(sum(s.estimate_s for s in steps))})")  # fmt: skip
    if a.list:
        for i, (s, full, done) in enumerate(todo, 1):
            what = "done" if done else f"~{_hms(s.estimate_s)}"
            _say(f"{i:2d} {s.name} ({what}): ctxsearch {' '.join(full) or '(summary)'}")
        return 0
    t0 = time.monotonic()
    spent = estimated = 0.0
    for i, (s, full, done) in enumerate(todo, 1):
        if done:
            _say(f"step {i}/{len(steps)} {s.name}: finished before, skipped")
            continue
        scale = min(2.0, max(0.5, spent / estimated)) if estimated > 0 else 1.0
        _say(f"step {i}/{len(steps)} {s.name}: starting; {_hms(time.monotonic() - t0)} spent, "
             f"about {_hms(left * scale)} left")  # fmt: skip
        t = time.monotonic()
        if s.argv is None:
            from ctxsearch.scripts.experiments.full_summary import write_summary

            write_summary(a.out)
            code = 0
        else:
            code = run_command(full)
        took = time.monotonic() - t
        if code != 0:
            _say(f"step {s.name} failed (exit {code}) after {_hms(took)}; run again to resume")
            return code
        _write_stamp(a.build, s, full)
        spent, estimated, left = spent + took, estimated + s.estimate_s, left - s.estimate_s
        _say(f"step {i}/{len(steps)} {s.name}: done in {_hms(took)} (estimated "
             f"{_hms(s.estimate_s)})")  # fmt: skip
    _say(f"all steps done ({_hms(time.monotonic() - t0)} in this run)")
    return 0


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bench_full", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=Path("results/full"), help="results (default: "
                   "results/full)")  # fmt: skip
    p.add_argument("--build", type=Path, default=Path("build/full"),
                   help="the journal, the step stamps, the draws and the family-house store "
                   "(default: build/full)")  # fmt: skip
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="local CPUs")
    p.add_argument("--ray-address", default=None, help="an existing Ray cluster instead")
    p.add_argument("--list", action="store_true", help="list the steps and estimates, run none")
    d = Counts()
    for name, default in (("apartment", d.apartment), ("apartment-type", d.apartment_type),
                          ("family", d.family), ("family-type", d.family_type),
                          ("curve", d.curve), ("transfer", d.transfer)):  # fmt: skip
        p.add_argument(f"--{name}-episodes", type=int, default=default, metavar="N",
                       help=f"paired episodes (default: {default})")  # fmt: skip
    p.add_argument(
        "--curve-rooms",
        default=d.curve_rooms,
        help="the curve's k (default: "
        f"{d.curve_rooms}; the last one's store is the apartments' knowledge)",
    )
    p.add_argument(
        "--family-houses",
        type=int,
        default=d.family_houses,
        metavar="N",
        help=f"family houses learned (default: {d.family_houses})",
    )
    p.add_argument(
        "--transfer-rooms",
        type=int,
        default=d.transfer_rooms,
        metavar="N",
        help=f"rooms learned per transfer style (default: {d.transfer_rooms})",
    )
    return p


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        _say("interrupted; run again to resume")
        sys.exit(130)
