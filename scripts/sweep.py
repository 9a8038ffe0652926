"""Independent units of a sweep, run serially or as Ray tasks (``--workers N``, ``--ray-address``).

``run_units(fn, units)`` calls ``fn(unit)`` for every unit and returns the results in unit
order, whatever order they finish in, so a sweep's output does not depend on how it was run.
With one worker and no cluster address nothing but a loop runs and Ray is never imported; with
``workers > 1`` a local Ray is started for the call (that many CPUs) and shut down after; with
``ray_address`` the units go to an existing cluster (``ray start --head`` somewhere, then
``--ray-address HOST:PORT``, or ``auto``); ``with session(options):`` keeps one connection for
several sweeps. ``fn`` must be a module-level function and units and
results plain data (numbers, strings, lists, dicts): they travel between processes. A unit that
raises a CtxsearchError ends the sweep with that error (one line, as everywhere). An address where
no cluster answers is a one-line error too, bounded in time (``RAY_CONNECT_TIMEOUT_S``): nothing
listening fails at once, no answer after 5 s, something that is not Ray after about 20 s.
With a journal (``run_units(..., journal=...)``, scripts.journal; ``--journal DIR``), the units
it holds are read back, not run, and every other unit's result is kept as it comes back (with
Ray: in the driver), so a sweep stopped at any moment runs again only what it had not finished.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import os
import signal
import socket
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.scripts import Stopped, received, reclaim_stop_signals
from ctxsearch.scripts.integers import positive_int

if TYPE_CHECKING:  # scripts.journal imports the search's modules, which a loop never needs
    from ctxsearch.scripts.journal import Journal

U = TypeVar("U")
R = TypeVar("R")
# What a worker process needs to render off-screen like the driver.
WORKER_ENV = ("MUJOCO_GL", "PYOPENGL_PLATFORM")
# Connecting to a cluster (--ray-address) fails within a bounded time instead of waiting forever
# (Ray alone retries for minutes): a HOST:PORT must accept a TCP connection within this many
# seconds, and Ray's own GCS connection gets this long per attempt, one attempt (nothing
# listening: at once; no answer: this long; something not Ray listening: about 4x this long).
RAY_CONNECT_TIMEOUT_S = 5
# Ray's settings (environment variables, read when it connects) for that, unless the user set them.
_RAY_CONNECT_ENV = {
    "RAY_py_gcs_connect_timeout_s": str(RAY_CONNECT_TIMEOUT_S),
    "RAY_gcs_server_port_wait_time_s": "1",
}
# Ray's core installs a C handler for SIGTERM and friends that prints a native stack dump (and
# may crash the process) instead of letting the command end as the CLI ends it.
_RAY_SIGNAL_ENV = {"RAY_DISABLE_FAILURE_SIGNAL_HANDLER": "1"}


@dataclass(frozen=True)
class SweepOptions:
    """How a sweep runs (not what it computes: the results are the same either way).
    ``journal``: a directory where every finished unit's result is kept and read back by a
    later run of the same command (scripts.journal; None: not kept)."""

    workers: int = 1
    ray_address: str | None = None
    journal: Path | None = None

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> SweepOptions:
        """From the flags ``add_sweep_arguments`` adds."""
        return cls(args.workers, args.ray_address, args.journal)


def _directory(text: str) -> Path:
    """``--journal DIR``: a directory that exists, or a path where nothing is (made later)."""
    p = Path(text)
    if p.exists() and not p.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: exists and is not a directory")
    return p


def add_sweep_arguments(p: argparse.ArgumentParser, journal: bool = False) -> None:
    """``--workers N`` and ``--ray-address ADDR`` for a command whose units can run in parallel
    (and ``--journal DIR`` with ``journal``: the command resumes, scripts.journal)."""
    p.add_argument(
        "--workers",
        type=positive_int,
        default=1,
        metavar="N",
        help="run the independent units as Ray tasks on N local CPUs (default: 1, serial, no Ray); "
        "the results are the same",
    )
    p.add_argument(
        "--ray-address",
        default=None,
        metavar="ADDR",
        help="run the units on an existing Ray cluster (HOST:PORT, or 'auto') instead",
    )
    if not journal:
        p.set_defaults(journal=None)
    else:
        p.add_argument(
            "--journal",
            type=_directory,
            default=None,
            metavar="DIR",
            help="keep every finished unit's result in DIR; the same command run again (after a "
            "kill, say) reads them back and runs only the rest, with the same files "
            "(default: not kept)",
        )


def _progress(total: int, desc: str, enabled: bool, initial: int = 0):
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, desc=desc, unit="unit", disable=not enabled,
                leave=False)  # fmt: skip


def run_units(
    fn: Callable[[U], R],
    units: Sequence[U],
    *,
    workers: int = 1,
    ray_address: str | None = None,
    desc: str = "units",
    progress: bool = True,
    journal: Journal | None = None,
) -> list[R]:
    """``[fn(u) for u in units]``, serially or as Ray tasks (see the module docstring), with a
    progress bar over finished units. ``fn`` may be a ``functools.partial`` of a module-level
    function. ``journal`` (scripts.journal): the units it holds are read back, not run, and every
    other unit's result is kept in it as soon as it is back (the bar counts from the units read
    back, so its rate and time left are those of the units that run)."""
    if workers < 1:
        raise CtxsearchError(f"--workers must be at least 1, got {workers}")
    out: list = [None] * len(units)
    todo = list(range(len(units)))
    if journal is not None:
        todo = []
        for i, u in enumerate(units):
            hit, res = journal.load(u)
            if hit:
                out[i] = res
            else:
                todo.append(i)
    kept = journal.save if journal is not None else None
    if not todo:
        return out
    if workers == 1 and not ray_address:
        freeze_long_lived()
        with _progress(len(units), desc, progress, len(units) - len(todo)) as bar:
            for i in todo:
                t = time.process_time()
                out[i] = fn(units[i])
                if kept is not None:
                    kept(units[i], out[i], time.process_time() - t)
                bar.update(1)
        return out
    _run_on_ray(fn, units, todo, out, (workers, ray_address, desc, progress, kept))
    return out


def _apply(fn: Callable[[U], R], unit: U) -> R:
    """A Ray task: ``fn(unit)`` (Ray's remote takes functions, not partials), in a session of the
    worker's own (``own_session``)."""
    own_session()
    freeze_long_lived()
    return fn(unit)


_frozen = False


def freeze_long_lived() -> None:
    """Before this process's first unit: collect, then freeze what survives (``gc.freeze``: the
    modules and what the command set up), once. Python's full collections walk every tracked
    object, ~100,000 of them once mujoco, dm_control and the project are loaded, about 90 ms a
    time; frozen ones are skipped (and still freed when their last reference goes). The numbers
    a unit gives do not depend on when garbage is collected."""
    global _frozen
    if not _frozen:
        gc.collect()
        gc.freeze()
        _frozen = True


def own_session() -> bool:
    """Move this process into a session of its own (once; True if it is in one now).

    Linux's scheduler shares the CPU fairly between sessions ("autogroups",
    /proc/sys/kernel/sched_autogroup_enabled), not between processes: Ray starts every worker
    in the driver's session, so on a machine where other users' sessions want the CPU too, N
    workers together get about one session's share. A worker in a session of its own gets a
    share of its own, as N commands started by hand would (measured at a load of 7-10 on 2
    cores, two tasks of 3 CPU-seconds on a fresh local Ray against twice that work serially,
    four alternating pairs: 1.91, 1.58, 1.69, 1.61x in their own sessions, 1.89, 1.27, 1.03,
    1.42x in the driver's). A Ray
    worker leads its own process group, which ``setsid`` refuses, so it first joins its
    parent's group (same session), then starts its session (and group: the worker's pid, so
    Ray still finds it by pid and by group)."""
    pid = os.getpid()
    if os.getsid(0) == pid:
        return True
    try:
        if os.getpgid(0) == pid:
            os.setpgid(0, os.getpgid(os.getppid()))
        os.setsid()
    except OSError:  # not permitted here (another platform, a sandbox): run where it is
        return False
    return True


def _start_ray(workers: int, ray_address: str | None, announce: bool = False) -> bool:
    """Connect to Ray (a local one of ``workers`` CPUs, or the cluster at ``ray_address``) unless
    already connected; True if this call connected (with ``announce``, after a status line on
    stderr: a local start takes seconds). A cluster that cannot be reached is a one-line
    CtxsearchError within a bounded time (``RAY_CONNECT_TIMEOUT_S``)."""
    if ray_address:
        check_reachable(ray_address)  # before Ray's import: nothing listening fails at once
    # Ray reads its C++ settings when it is first imported: the connection limits go first.
    with _env({**_RAY_SIGNAL_ENV, **(_RAY_CONNECT_ENV if ray_address else {})}):
        # Imported here, not at the top: Ray costs ~1.5 s to import and one-worker runs never
        # need it.
        import ray

        if ray.is_initialized():
            return False
        if announce:
            what = f"connecting to the Ray cluster at {ray_address}" if ray_address else (
                "starting a local Ray")  # fmt: skip
            print(f"ctxsearch: {what} ...", file=sys.stderr, flush=True)
        kwargs = dict(log_to_driver=False, configure_logging=False, include_dashboard=False)
        before = _descendants()
        try:
            if ray_address:
                env = {k: os.environ[k] for k in WORKER_ENV if k in os.environ}
                with _stderr_kept_unless_it_fails():
                    ray.init(address=ray_address, runtime_env={"env_vars": env}, **kwargs)
            else:
                # No runtime_env for a local Ray: its workers inherit the driver's environment
                # (WORKER_ENV included), and a job-level runtime_env would make Ray start new
                # workers for the job instead of using the ones it prestarted (measured: the
                # first task then waits 2.3-5.3 s instead of 0.4-0.8 s; the fixed cost of a sweep
                # drops by ~4 s). Ray runs its workers at nice 15 by default: on a machine others
                # use too they then get a fraction of the CPU the serial run gets (measured: 1.5x
                # slower per unit at a load of 8 on 2 cores), so a local sweep's workers run at
                # the driver's priority.
                ray.init(num_cpus=workers, _system_config={"worker_niceness": 0}, **kwargs)
        except SystemExit:  # SIGTERM while Ray starts: its own handlers exit; end as a command
            ray_processes = _descendants() - before
            ray.shutdown()
            _end_processes(ray_processes)
            received.append(int(signal.SIGTERM))
            raise Stopped(signal.SIGTERM) from None
        except (ConnectionError, RuntimeError, ValueError, OSError) as exc:
            if ray_address == "auto" and "Could not find any running Ray" in str(exc):
                # Ray's own text names its --address flag, which ctxsearch does not have
                raise CtxsearchError(
                    "--ray-address auto: no Ray cluster runs on this machine (start one with "
                    "'ray start --head', give --ray-address HOST:PORT, or run a local one with "
                    "--workers N)"
                ) from None
            where = f"--ray-address {ray_address}" if ray_address else "a local Ray"
            raise CtxsearchError(f"cannot start {where}: {' '.join(str(exc).split())}") from None
    # Ray's core installs C handlers for SIGTERM (a stack dump) over the command's: a stop signal
    # must still end the command as the CLI ends it (one line, Ray shut down on the way out)
    reclaim_stop_signals()
    return True


def check_reachable(ray_address: str) -> None:
    """CtxsearchError (one line) unless ``ray_address`` is ``auto``, a ``ray://`` client address
    (Ray checks those itself) or a HOST:PORT that accepts a TCP connection within
    ``RAY_CONNECT_TIMEOUT_S`` seconds."""
    if ray_address == "auto" or ray_address.startswith("ray://"):
        return
    host, sep, port = ray_address.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise CtxsearchError(f"--ray-address: expected HOST:PORT or 'auto', got {ray_address!r}")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), RAY_CONNECT_TIMEOUT_S):
            pass
    except TimeoutError:
        why = f"no answer within {RAY_CONNECT_TIMEOUT_S} s"
    except OSError as exc:
        why = exc.strerror or str(exc) or type(exc).__name__
    else:
        return
    raise CtxsearchError(f"--ray-address {ray_address}: no Ray cluster there ({why})")


@contextlib.contextmanager
def _stderr_kept_unless_it_fails() -> Iterator[None]:
    """What the block writes to file descriptor 2 (Ray's C++ core logs its retries there) is held
    back and written out if the block succeeds; if it fails, the one-line error replaces it."""
    import tempfile

    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no usable stderr: nothing to keep apart
        yield
        return
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            yield
        except BaseException:
            os.dup2(saved, 2)
            raise
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        held.seek(0)
        text = held.read()
    if text:
        os.write(2, text)


@contextlib.contextmanager
def _env(values: dict[str, str]) -> Iterator[None]:
    """``values`` in os.environ (where not already set) for the block's duration."""
    added = {k: v for k, v in values.items() if k not in os.environ}
    os.environ.update(added)
    try:
        yield
    finally:
        for k in added:
            os.environ.pop(k, None)


@contextlib.contextmanager
def session(options: SweepOptions, progress: bool = False) -> Iterator[None]:
    """One Ray connection for several ``run_units`` calls of the same options (each call would
    otherwise start and stop its own); nothing at all for a serial sweep. ``progress``: a status
    line on stderr while Ray starts."""
    if options.workers == 1 and not options.ray_address:
        yield
        return
    before = _descendants()
    started = _start_ray(options.workers, options.ray_address, progress)
    try:
        yield
    finally:
        if started:
            _stop_ray(before)


def _stop_ray(before: set[int]) -> None:
    """Shut the Ray this process started down, and end what of it outlives that (the
    descendants this process did not have before, ``before``: the raylet's agents)."""
    import ray

    ray_processes = _descendants() - before
    ray.shutdown()
    _end_processes(ray_processes)


def _descendants() -> set[int]:
    """This process's descendants now: children, theirs, ... (Linux /proc; empty elsewhere)."""
    parent: dict[int, int] = {}
    try:
        entries = [e for e in os.listdir("/proc") if e.isdigit()]
    except OSError:
        return set()
    for entry in entries:
        try:
            with open(f"/proc/{entry}/stat", "rb") as f:
                parent[int(entry)] = int(f.read().rsplit(b")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
    out, frontier = set(), {os.getpid()}
    while frontier:
        frontier = {pid for pid, pp in parent.items() if pp in frontier} - out
        out |= frontier
    return out


def _end_processes(pids: set[int], wait_s: float = 5.0) -> None:
    """End the processes ``pids`` that are still running (Ray's that ``ray.shutdown`` left
    behind, such as the raylet's agents): SIGTERM, then SIGKILL after ``wait_s``; this
    process's children among them reaped."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in pids:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, sig)
        deadline = time.monotonic() + wait_s
        while pids and time.monotonic() < deadline:
            for pid in list(pids):
                with contextlib.suppress(ChildProcessError):
                    if os.waitpid(pid, os.WNOHANG)[0] != 0:
                        pids.discard(pid)
                        continue
                if not _running(pid):
                    pids.discard(pid)
            time.sleep(0.05)
        if not pids:
            return


def _running(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie does not)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except (OSError, IndexError):
        return False


def _run_on_ray(fn, units, todo, out, how) -> None:
    """The units ``todo`` (indices into ``units``) as Ray tasks, their results into ``out``;
    ``how``: workers, cluster address, the bar's description and whether it shows, and where a
    result goes as it arrives (a journal's ``save``, or None)."""
    workers, ray_address, desc, progress, kept = how
    # first: it imports Ray with its settings
    before = _descendants()
    started = _start_ray(workers, ray_address, progress)
    import ray
    from ray.exceptions import RayTaskError

    try:
        task = ray.remote(num_cpus=1, max_retries=0)(_apply)
        fn_ref = ray.put(fn)  # shipped to the workers once, not with every unit
        pending = {task.remote(fn_ref, units[i]): i for i in todo}
        with _progress(len(units), desc, progress, len(units) - len(todo)) as bar:
            while pending:
                reclaim_stop_signals()  # Ray's core may install its handlers after its start
                done, _ = ray.wait(list(pending), num_returns=1)
                for ref in done:
                    i = pending.pop(ref)
                    try:
                        out[i] = ray.get(ref)
                    except RayTaskError as exc:
                        cause = exc.cause if isinstance(exc.cause, CtxsearchError) else None
                        if cause is not None:
                            raise cause from None
                        raise
                    if kept is not None:
                        kept(units[i], out[i])
                    bar.update(1)
    finally:
        if started:
            _stop_ray(before)
