"""Check the system libraries that pip cannot install (Mesa EGL for off-screen rendering).

Runs with the system Python before the virtualenv exists: stdlib only. Prints one line
with the install command and exits 1 when something is missing.
"""

from __future__ import annotations

import ctypes.util
import sys

APT = "apt-get install -y libegl1 libgl1-mesa-dri libgles2"


def main() -> int:
    """0 if this Python and the Mesa libraries can run ctxsearch; else one line on stderr and 1."""
    if sys.version_info < (3, 11):  # noqa: UP036 - runs with the system Python, before the venv
        print(f"ctxsearch needs Python >= 3.11 (found {sys.version.split()[0]})", file=sys.stderr)
        return 1
    for lib in ("EGL", "GL"):
        if ctypes.util.find_library(lib) is None:
            print(
                f"ctxsearch: lib{lib} (Mesa) not found, needed for off-screen rendering; install it: {APT}",
                file=sys.stderr,
            )
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
