"""How long a command stays silent (no silence over ~5 s):

    python scripts/examples/longest_silence.py ctxsearch bench search --kb K --style office ...

Runs the command on a pseudo-terminal of 150 columns (progress bars draw as they would for a
user; on a pipe, or a terminal of width 0, tqdm draws nothing), timestamps everything it writes
(stdout and stderr together) and prints, on stderr, its exit code, its wall time, the seconds
before its first output and the longest gaps between two outputs with what came before each.
A progress bar redrawn counts as output; one that stays on screen without moving does not.
Exits with the command's exit code. POSIX only (``pty``).
"""

from __future__ import annotations

import fcntl
import os
import pty
import select
import struct
import subprocess
import sys
import termios
import time

COLUMNS, ROWS = 150, 40
SHOWN = 4  # gaps printed


def watch(cmd: list[str]) -> tuple[int, float, float | None, list[tuple[float, str]]]:
    """Run ``cmd`` on a pseudo-terminal: exit code, wall seconds, seconds to the first output
    (None: none), and (gap seconds, the last characters before it) for every gap."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", ROWS, COLUMNS, 0, 0))
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=slave, stderr=slave, close_fds=True)
    os.close(slave)
    last, first, gaps, tail = t0, None, [], b""
    while True:
        ready, _, _ = select.select([master], [], [], 0.5)
        if ready:
            try:
                data = os.read(master, 4096)
            except OSError:  # the command closed the terminal
                break
            if not data:
                break
            now = time.perf_counter()
            first = now - t0 if first is None else first
            gaps.append((now - last, tail[-120:].decode(errors="replace")))
            last, tail = now, (tail + data)[-400:]
        elif proc.poll() is not None:
            break
    rc = proc.wait()
    os.close(master)
    end = time.perf_counter()
    gaps.append((end - last, "(end)"))
    return rc, end - t0, first, gaps


def main(argv: list[str] | None = None) -> int:
    """Measure and print; the command's exit code."""
    cmd = sys.argv[1:] if argv is None else argv
    if not cmd or cmd[0] in ("-h", "--help"):
        print(__doc__.strip(), file=sys.stderr)
        return 2
    rc, wall, first, gaps = watch(cmd)
    first_s = "never" if first is None else f"{first:.1f} s"
    print(f"exit {rc}, {wall:.1f} s wall, first output after {first_s}", file=sys.stderr)
    for gap, before in sorted(gaps, key=lambda g: -g[0])[:SHOWN]:
        print(f"  silent {gap:.1f} s after {before[-80:]!r}", file=sys.stderr)
    return rc


if __name__ == "__main__":
    raise SystemExit(main())
