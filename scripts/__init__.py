"""Command-line entry points (thin: parse, call into agent/ envs/ knowledge/, print).

How a command ends when it is told to: Ctrl-C (SIGINT), SIGTERM (``kill``, ``timeout``, a process
manager) and SIGHUP (a closed terminal) are the stop signals. Each ends a command with one line on
stderr (``ctxsearch: interrupted`` for Ctrl-C, ``ctxsearch: terminated by SIGTERM`` for the
others) and exit code 128 + the signal's number. While a command runs, a stop signal is a
``Stopped`` exception (a ``KeyboardInterrupt``, so every cleanup written for Ctrl-C runs for it:
the learning loop's bookkeeping, the children's process groups ended); ``received`` keeps the
signals that came. Run as the console script, this package's first lines handle them from the
start, while the CLI's modules load, and after the command (nothing is open then: the process
ends at once). Imported by other code (tests, a user's script) it changes nothing.
"""

import os
import signal
import sys
import threading

INTERRUPTED = "ctxsearch: interrupted"
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
interrupt_reported: list[bool] = []  # the one line was printed: a further signal adds none
received: list[int] = []  # the stop signals received while a command ran, in order


class Stopped(KeyboardInterrupt):
    """A stop signal while a command runs (``signum``: which)."""

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)


def stop_line(signum: int) -> str:
    """The one line a command stopped by ``signum`` ends with."""
    if signum == signal.SIGINT:
        return INTERRUPTED
    return f"ctxsearch: terminated by {signal.Signals(signum).name}"


def stop_code(signum: int) -> int:
    """The exit code of a command stopped by ``signum``: 128 + its number."""
    return 128 + int(signum)


def last_stop() -> int:
    """The last stop signal received (SIGINT if none was: a KeyboardInterrupt raised by hand)."""
    return received[-1] if received else int(signal.SIGINT)


DEFER_S = 0.05  # a signal that came where an exception would be ignored comes again this late


def raise_stopped(signum, frame) -> None:
    """The handler while a command runs: the signal as a ``Stopped`` exception. Where Python
    would ignore an exception (a finalizer, or importlib's module-lock callback, both run from a
    garbage collection: it prints "Exception ignored" with a traceback and goes on, the stop
    lost), the signal is sent again ``DEFER_S`` later instead, to land in ordinary code."""
    if _ignores_exceptions(frame):
        threading.Timer(DEFER_S, os.kill, (os.getpid(), int(signum))).start()
        return
    received.append(int(signum))
    raise Stopped(signum)


def _ignores_exceptions(frame) -> bool:
    """Is ``frame`` code whose exceptions Python ignores (``__del__``, a weakref callback of
    importlib's bootstrap)?"""
    code = getattr(frame, "f_code", None)
    if code is None:
        return False
    return code.co_name == "__del__" or code.co_filename.startswith("<frozen importlib")


def exit_interrupted(signum, frame) -> None:
    """A stop signal outside a command (imports, Python's exit): the one line, exit 128 + n, no
    traceback (nothing is open then)."""
    if not interrupt_reported:
        os.write(2, (stop_line(signum) + "\n").encode())
    os._exit(stop_code(signum))


_handlers: dict[int, object] = {}  # what handle_stop_signals last installed, by signal


def handle_stop_signals(handler) -> dict:
    """``handler`` for every stop signal; the handlers it replaced, by signal."""
    before = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    _handlers.update(dict.fromkeys(STOP_SIGNALS, handler))
    return before


def reclaim_stop_signals() -> None:
    """Install the stop signals' handlers again, as ``handle_stop_signals`` last set them: a
    library that installs its own (Ray's driver: ``sys.exit`` on SIGTERM in Python, a stack dump
    in C) must not decide how a command ends. In the main thread only, where handlers live."""
    if threading.current_thread() is not threading.main_thread():
        return
    for s, handler in _handlers.items():
        signal.signal(s, handler)


if os.path.basename(sys.argv[0]) == "ctxsearch":
    handle_stop_signals(exit_interrupted)
