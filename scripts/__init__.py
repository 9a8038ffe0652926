"""Command-line entry points (thin: parse, call into agent/ envs/ knowledge/, print).

Run as the ``ctxsearch`` console script, this package's first lines make Ctrl-C the one line
``ctxsearch: interrupted`` and exit code 130 from here on, while the CLI's modules load
(``scripts/cli.py`` turns it into a KeyboardInterrupt while a command runs). Imported by other
code (tests, a user's script) it changes nothing."""

import os
import signal
import sys

INTERRUPTED = "ctxsearch: interrupted"
interrupt_reported: list[bool] = []  # the one line was printed: a further Ctrl-C adds none


def exit_interrupted(signum, frame) -> None:
    """SIGINT outside a command (imports, Python's exit): the one line, exit 130, no traceback
    (nothing is open then)."""
    if not interrupt_reported:
        os.write(2, (INTERRUPTED + "\n").encode())
    os._exit(130)


if os.path.basename(sys.argv[0]) == "ctxsearch":
    signal.signal(signal.SIGINT, exit_interrupted)
