"""``ctxsearch``: the command-line interface.

Each sub-command lives in its own thin module ``scripts/cmd_<name>.py`` exposing
``register(subparsers)`` (and, for benchmarks, ``register_bench(bench_subparsers)``); handlers
import heavy modules (MuJoCo, dm_control, rerun, scipy) lazily, so building the parser for
``ctxsearch --help`` or ``ctxsearch kb show`` does not load them.

Errors a user can fix (bad files, unknown names, incompatible stores) are CtxsearchError: they
print one line, ``ctxsearch: error: ...``, and exit with code 2. A stop signal at any moment
(Ctrl-C, SIGTERM, SIGHUP: ``scripts/__init__.py``) prints one line, ``ctxsearch: interrupted``
or ``ctxsearch: terminated by SIGTERM``, and exits with 128 + the signal's number: while a
command runs it is a ``Stopped`` KeyboardInterrupt (the learning loop finishes its bookkeeping:
at most the examination in flight is lost, its transaction rolled back; children's process
groups are ended); before it (the CLI's imports, run as the console script) and after it
(Python's exit) it ends the process at once (nothing is open then). Only a signal in the first
milliseconds, while Python itself starts and before any line of ctxsearch runs, gets Python's
own handling.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading

from ctxsearch.knowledge.errors import CtxsearchError, printable
from ctxsearch.scripts import (
    STOP_SIGNALS,
    exit_interrupted,
    handle_stop_signals,
    interrupt_reported,
    last_stop,
    raise_stopped,
    stop_code,
    stop_line,
)

if __name__ == "__main__":  # python -m ctxsearch.scripts.cli (the console script: scripts/__init__)
    handle_stop_signals(exit_interrupted)

# Sub-command modules, in the order `ctxsearch --help` lists them.
COMMAND_MODULES = [
    "ctxsearch.scripts.cmd_kb",
    "ctxsearch.scripts.cmd_room",
    "ctxsearch.scripts.cmd_truth",
    "ctxsearch.scripts.cmd_learn",
    "ctxsearch.scripts.cmd_search",
    "ctxsearch.scripts.cmd_demo",
    "ctxsearch.scripts.cmd_view",
]
# Benchmark modules (`ctxsearch bench NAME`), each exposing register_bench(bench_subparsers).
BENCH_MODULES = [
    "ctxsearch.scripts.cmd_kb",
    "ctxsearch.scripts.cmd_sim",
    "ctxsearch.scripts.cmd_learn",
    "ctxsearch.scripts.cmd_search",
    "ctxsearch.scripts.cmd_hierarchy",
    "ctxsearch.scripts.cmd_context",
    "ctxsearch.scripts.cmd_room",
]


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="ctxsearch",
        description="A simulated pan-tilt camera robot that learns spatial context as confidence "
        "intervals (Wixson 1991) and uses it to find objects.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    bench = sub.add_parser(
        "bench", help="run a benchmark (prints a table, writes JSON/Markdown/plot)"
    )
    bench_sub = bench.add_subparsers(dest="bench", metavar="BENCHMARK", required=True)
    for name in BENCH_MODULES:
        importlib.import_module(name).register_bench(bench_sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``ctxsearch`` console script."""
    if threading.current_thread() is not threading.main_thread():
        return _run(argv)  # signal handlers belong to the main thread: leave them as they are
    before = handle_stop_signals(raise_stopped)
    try:
        code = _run(argv)
    finally:  # run as the console script, ``before`` covers Python's exit
        for s, handler in before.items():
            signal.signal(s, handler)
    if interrupt_reported and before[signal.SIGINT] is exit_interrupted:
        # Stopped, as a program of its own: everything the command opened is closed, and the
        # libraries' exit handlers (Ray's after an interrupted start) must not change the code
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def _run(argv: list[str] | None) -> int:
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
    try:  # Ctrl-C while the parser imports the sub-commands is an interrupt too, not a traceback
        parser = build_parser()
        args = parser.parse_args(argv)
        return int(args.func(args) or 0)
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signum", None) or last_stop()
        if threading.current_thread() is threading.main_thread():
            for s in STOP_SIGNALS:  # a second signal: not in this print
                signal.signal(s, signal.SIG_IGN)
        print(stop_line(signum), file=sys.stderr)
        interrupt_reported.append(True)
        return stop_code(signum)
    except BrokenPipeError:  # e.g. `ctxsearch kb show ... | head`
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except CtxsearchError as exc:
        print(f"ctxsearch: error: {printable(str(exc))}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
