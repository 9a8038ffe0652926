"""A sweep's journal: every finished unit's result kept on disk, so a stopped command resumes
(``--journal DIR`` on ``bench search``, ``bench home``, ``bench curve`` and ``bench transfer``).

``run_units(fn, units, journal=...)`` (scripts.sweep) first reads back every unit the journal
holds, runs only the others, and writes each result as it finishes (with Ray: in the driver, as
it arrives), so a command killed at any moment, even by SIGKILL, runs again only the units it had
not finished, and writes the same files as an uninterrupted run: the results are deterministic by
seed, and a result read back is the result that was written (JSON, floats with ``repr``: the same
bits).

A unit's file is ``DIR/<key>.json``. Its key is a SHA-256 over what the unit's result depends on:
the journal's ``context`` (``context_digest``: what the command computes, its resolved
configuration, the bytes of the files it reads such as the knowledge store, the source of the
packages a unit runs, ``agent.search.draw_store.code_digest``, and the data under ``assets/``)
and the unit itself. A changed configuration, store or line of code is another key, never a stale
result. Files are written to a temporary file first, then renamed (``draw_store.write_bytes``),
so a reader never sees half of one; a file that cannot be read back (any bytes: truncated,
edited, another key's, another format; a FIFO, a device, an oversized file: knowledge.files reads
it) is a miss: the unit runs again and the file is replaced. A directory that cannot keep a file
is a warning, never an error: the journal costs only time.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ctxsearch.agent.search.draw_store import code_digest, write_bytes
from ctxsearch.knowledge.files import InputFileError, read_json, tree_hash

FORMAT = 1
MAX_ENTRY_BYTES = 256 * 2**20  # a unit's result (a learned store's bytes in base64 included)


@functools.cache
def assets_digest() -> str:
    """SHA-256 over the files under ``assets/`` (types, styles, houses, detectors), sorted by
    path: the data every unit reads."""
    return tree_hash(["assets"], "*").hexdigest()


def file_digest(path: Path | str | None) -> str | None:
    """SHA-256 of a file's bytes and of its SQLite write-ahead log beside it (``-wal``), if any;
    None for no path, ``missing`` for a path with no file."""
    if path is None:
        return None
    h = hashlib.sha256()
    found = False
    for p in (Path(path), Path(f"{path}-wal")):
        try:
            h.update(p.read_bytes())
            found = True
        except FileNotFoundError:
            continue
        h.update(b"\0")
    return h.hexdigest() if found else "missing"


def context_digest(what: str, config: object, files: Iterable[Path | str | None] = ()) -> str:
    """The context of a journal: ``what`` (the command and kind of unit), ``config`` (anything
    JSON can write: the resolved configuration), the digests of ``files`` (``file_digest``), the
    code (``code_digest``) and the data (``assets_digest``)."""
    h = hashlib.sha256()
    h.update(f"journal {FORMAT}\n{what}\n{code_digest()}\n{assets_digest()}\n".encode())
    h.update(json.dumps(config, sort_keys=True, default=str).encode())
    for f in files:
        h.update(f"\n{f}: {file_digest(f)}".encode())
    return h.hexdigest()


@dataclass(frozen=True)
class Journal:
    """Where a sweep's finished units are kept (``directory``), under which context
    (``context_digest``), and how a result becomes JSON (``encode``) and back (``decode``: any
    exception for anything that is not a result it wrote). ``unit_key``: the unit as text (its
    ``repr`` unless given), part of its key."""

    directory: Path
    context: str
    encode: Callable[[Any], object]
    decode: Callable[[object], Any]
    unit_key: Callable[[Any], str] = repr

    def key(self, unit: object) -> str:
        """The file name stem of ``unit``'s result."""
        h = hashlib.sha256(f"{self.context}\n".encode())
        h.update(self.unit_key(unit).encode())
        return h.hexdigest()[:40]

    def load(self, unit: object) -> tuple[bool, Any]:
        """(True, the result) if the journal holds ``unit``'s, else (False, None)."""
        key = self.key(unit)
        try:
            doc = read_json(Path(self.directory) / f"{key}.json", MAX_ENTRY_BYTES,
                            parse_constant=_no_constant)  # fmt: skip
            if not isinstance(doc, dict) or doc.get("format") != FORMAT or doc.get("key") != key:
                return False, None
            if doc.get("sha256") != _payload_digest(doc["result"]):
                return False, None
            return True, self.decode(doc["result"])
        except (InputFileError, ValueError, KeyError, TypeError, IndexError, AttributeError):
            return False, None
        except (OverflowError, RecursionError, UnicodeError):
            return False, None

    def save(self, unit: object, result: object, cpu_s: float | None = None) -> None:
        """Keep ``unit``'s ``result`` (atomically; a warning if the directory cannot keep it);
        ``cpu_s``: the CPU seconds the unit took, if known (kept beside it for cost estimates,
        never read back into a result)."""
        key = self.key(unit)
        payload = self.encode(result)
        doc = {"format": FORMAT, "key": key, "sha256": _payload_digest(payload),
               "cpu_s": None if cpu_s is None else round(cpu_s, 3), "result": payload}  # fmt: skip
        write_bytes(Path(self.directory), f"{key}.json", json.dumps(doc).encode(), "sweep journal")


def _no_constant(name: str) -> object:
    raise ValueError(f"{name} in a journal entry")


def _payload_digest(payload: object) -> str:
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def finite(x: object) -> float:
    """``x`` as a finite float (ValueError otherwise, TypeError for a non-number or a bool)."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise TypeError("not a number")
    v = float(x)
    if not math.isfinite(v):
        raise ValueError("not finite")
    return v


def whole(x: object) -> int:
    """``x`` as an int (TypeError for anything but an int; a bool is not one)."""
    if isinstance(x, bool) or not isinstance(x, int):
        raise TypeError("not an integer")
    return x
