"""Helpers for tests that signal a child process as a user would."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path


def wait_until_importing(proc: subprocess.Popen, timeout_s: float = 60.0) -> None:
    """Return once ``proc`` runs the program's imports (numpy mapped into it, where /proc
    says), it ended (polled, so an exited child is not waited on as a zombie whose maps file
    stays), or ``timeout_s`` passed. A signal before that lands in CPython's own
    start-up (``site``), which no program can catch; on a loaded machine a fixed delay after the
    fork may still be there, or already past what a test means to interrupt."""
    maps = Path(f"/proc/{proc.pid}/maps")
    until = time.monotonic() + timeout_s
    while maps.exists() and proc.poll() is None and time.monotonic() < until:
        try:
            if "numpy" in maps.read_text(errors="replace"):
                return
        except OSError:
            return
        time.sleep(0.01)
