"""Reading a user's input file safely: a regular file only, at most a stated number of bytes,
TOML or JSON nested at most a stated depth; any problem is one ``InputFileError`` line.

Every loader of user files (catalog, room and house styles, detector presets, ground-truth files,
an episode draw kept on disk) reads through here, so none of them can hang or exhaust memory:

- ``open_regular`` refuses what is not a regular file after symlinks are resolved (a FIFO would
  block the read forever, ``/dev/zero`` never ends, a directory or a socket is not a file), a
  dangling symlink and a symlink loop, and never blocks (the file is opened ``O_NONBLOCK`` and
  checked again through its descriptor, so a file swapped for a FIFO in between is refused too);
- ``read_bytes`` reads at most ``limit`` bytes (``MAX_FILE_BYTES`` by default) and refuses a larger
  file instead of reading it;
- ``read_toml`` and ``read_json`` decode UTF-8 and refuse a document whose arrays and tables (or
  objects) nest deeper than ``max_depth`` (``MAX_NESTING``) before the parser recurses into it.

Stdlib only.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import stat
import sys
import tempfile
import tomllib
from collections.abc import Callable, Iterable
from pathlib import Path

from ctxsearch.knowledge.errors import CtxsearchError

MAX_FILE_BYTES = 64 * 2**20  # the largest input file read (the shipped ones are under 100 kB)
MAX_NESTING = 64  # arrays/tables (TOML) or arrays/objects (JSON) inside each other (shipped: 3)


class InputFileError(CtxsearchError, ValueError):
    """An input file that cannot be read as asked: ``PATH: problem`` on one line. ``path`` and
    ``problem`` are kept apart for loaders that word it with their own error class; ``missing``
    says the file does not exist (nothing at the path, not even a symlink)."""

    def __init__(self, path: str | Path, problem: str, *, missing: bool = False):
        super().__init__(f"{path}: {problem}")
        self.path, self.problem, self.missing = path, problem, missing


def open_regular(path: str | Path) -> int:
    """A read-only file descriptor of the regular file at ``path`` (symlinks resolved), opened
    without blocking; InputFileError for anything else. The caller closes it."""
    p = _path(path)
    try:
        st = os.stat(p)  # follows symlinks: what would be read
    except FileNotFoundError:
        if os.path.islink(p):
            raise InputFileError(p, "a symlink to a file that does not exist") from None
        raise InputFileError(p, "no such file", missing=True) from None
    except OSError as exc:
        raise InputFileError(p, _os_problem(exc)) from None
    _check_regular(p, st.st_mode)
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise InputFileError(p, _os_problem(exc)) from None
    try:
        _check_regular(p, os.fstat(fd).st_mode)  # the file opened may not be the one stat saw
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return fd


def _path(path: str | Path) -> Path:
    """``path`` as a Path the OS can take (InputFileError for a NUL byte in it)."""
    p = Path(path)
    if "\x00" in str(p):
        raise InputFileError(p, "a file name with a NUL byte in it")
    return p


def regular_file_exists(path: str | Path) -> bool:
    """Whether a regular file is at ``path`` (itself or through symlinks); False if nothing is
    there (not even a symlink); InputFileError for anything else, e.g. a dangling symlink or a
    symlink loop (nothing may be created through one) or a FIFO. For outputs and stores."""
    p = _path(path)
    try:
        os.lstat(p)
    except FileNotFoundError:
        return False
    except OSError as exc:
        raise InputFileError(p, _os_problem(exc)) from None
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise InputFileError(p, "a symlink to a file that does not exist") from None
    except OSError as exc:
        raise InputFileError(p, _os_problem(exc)) from None
    _check_regular(p, st.st_mode)
    return True


def _check_regular(p: Path, mode: int) -> None:
    if stat.S_ISREG(mode):
        return
    kinds = [
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ]
    kind = next((name for test, name in kinds if test(mode)), "not a plain file")
    via = " (through a symlink)" if os.path.islink(p) else ""
    raise InputFileError(p, f"is {kind}{via}, not a regular file")


def _os_problem(exc: OSError) -> str:
    if exc.errno == errno.ELOOP:
        return "a symlink loop"
    if exc.errno == errno.ENOTDIR:
        return "no such file (a part of the path is not a directory)"
    if exc.errno == errno.ENAMETOOLONG:
        return "file name too long"
    return f"cannot read: {exc.strerror or exc}"


def read_bytes(path: str | Path, limit: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of the regular file at ``path``, at most ``limit`` of them (a larger file is an
    InputFileError, not read past the limit)."""
    fd = open_regular(path)
    try:
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise InputFileError(path, _os_problem(exc)) from None
    finally:
        os.close(fd)
    if size > limit:
        raise InputFileError(path, f"larger than {limit:_} bytes; refusing to read it")
    return b"".join(chunks)


def read_text(path: str | Path, limit: int = MAX_FILE_BYTES, what: str = "text") -> str:
    """``read_bytes`` decoded as UTF-8 (InputFileError naming the first bad byte otherwise)."""
    data = read_bytes(path, limit)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputFileError(
            path, f"not UTF-8 text (byte {exc.start}); {what} must be UTF-8"
        ) from None


# What opens or closes a level, or starts a string or a comment, in TOML and JSON text.
_TOML_TOKEN = re.compile(r"\"\"\"|'''|[\"'#\[\]{}]")
_JSON_TOKEN = re.compile(r'["\[\]{}]')
_BASIC_END = re.compile(r'\\.|"|\n', re.S)  # a basic string ends at " (or, unclosed, a newline)
_ML_BASIC_END = re.compile(r'\\.|"""', re.S)


def nesting_depth(text: str, kind: str, stop: int | None = None) -> int:
    """How deep arrays and tables (``kind`` "toml") or arrays and objects ("json") nest in
    ``text``, brackets inside strings and comments not counted; it stops counting once past
    ``stop``. A conservative scan, not a parser: the parser still reports syntax errors."""
    token = _TOML_TOKEN if kind == "toml" else _JSON_TOKEN
    depth = deepest = i = 0
    n = len(text)
    while (m := token.search(text, i)) is not None:
        t, i = m.group(), m.end()
        if t in "[{":
            depth += 1
            deepest = max(deepest, depth)
            if stop is not None and deepest > stop:
                break
        elif t in "]}":
            depth = max(0, depth - 1)
        elif t == '"':
            i = _skip(text, i, _BASIC_END, '"', n)
        elif t == '"""':
            i = _skip(text, i, _ML_BASIC_END, '"""', n)
        elif t == "'":  # a TOML literal string: no escapes, one line
            j = min(k if k >= 0 else n for k in (text.find("'", i), text.find("\n", i)))
            i = j + 1
        elif t == "'''":
            j = text.find("'''", i)
            i = n if j < 0 else j + 3
        else:  # "#": a TOML comment, to the end of the line
            j = text.find("\n", i)
            i = n if j < 0 else j + 1
    return deepest


def _skip(text: str, i: int, end: re.Pattern, close: str, n: int) -> int:
    """The index just past the string that starts at ``i`` (escapes skipped)."""
    while (m := end.search(text, i)) is not None:
        i = m.end()
        if m.group() in (close, "\n"):
            return i
    return n


def _check_depth(path, text: str, kind: str, max_depth: int) -> None:
    depth = nesting_depth(text, kind, stop=max_depth)
    if depth > max_depth:
        raise InputFileError(
            path,
            f"{kind.upper()} nested more than {max_depth} levels deep; refusing to parse it",
        )


def read_toml(path: str | Path, limit: int = MAX_FILE_BYTES, max_depth: int = MAX_NESTING) -> dict:
    """The TOML document in the file at ``path``: a regular file of at most ``limit`` bytes,
    UTF-8, nested at most ``max_depth`` deep, valid TOML; InputFileError otherwise."""
    text = read_text(path, limit, "TOML")
    _check_depth(path, text, "toml", max_depth)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputFileError(path, f"TOML syntax error: {' '.join(str(exc).split())}") from None
    except RecursionError:  # past the scan (it is conservative, not a parser)
        raise InputFileError(path, "TOML nested too deeply") from None


def read_json(
    path: str | Path,
    limit: int = MAX_FILE_BYTES,
    max_depth: int = MAX_NESTING,
    parse_constant: Callable[[str], object] | None = None,
) -> object:
    """The JSON document in the file at ``path`` (as ``read_toml``); ``parse_constant`` as
    ``json.loads`` takes it (e.g. to refuse NaN). A ValueError that ``parse_constant`` raises is
    an InputFileError too."""
    text = read_text(path, limit, "JSON")
    _check_depth(path, text, "json", max_depth)
    try:
        return json.loads(text, parse_constant=parse_constant)
    except RecursionError:
        raise InputFileError(path, "JSON nested too deeply") from None
    except ValueError as exc:
        raise InputFileError(path, f"not valid JSON ({' '.join(str(exc).split())})") from None


def write_bytes(directory: Path, name: str, data: bytes, what: str) -> None:
    """Store ``data`` as ``directory/name`` (the directory created if needed), atomically; a
    directory that cannot keep it (read-only, full) is a warning on stderr naming ``what``: the
    work is done, the cache costs only time."""
    directory = Path(directory)
    tmp = None
    try:
        directory.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=directory)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, directory / name)
    except OSError as e:
        print(f"ctxsearch: warning: {directory}: {what} not kept: {e.strerror or e}",
              file=sys.stderr)  # fmt: skip
    finally:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)


def cache_dir() -> Path | None:
    """The user's ctxsearch cache directory, where work is kept between commands (the episode
    oracle-prior's ground truth, the remembered map's tours, the worlds' models): ``$CTXSEARCH_CACHE_DIR`` if set (empty: None, no cache),
    else ``$XDG_CACHE_HOME/ctxsearch`` (default ``~/.cache/ctxsearch``)."""
    own = os.environ.get("CTXSEARCH_CACHE_DIR")
    if own is not None:
        return Path(own) if own.strip() else None
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "ctxsearch"


_ROOT = Path(__file__).resolve().parents[1]  # the package's source tree


def tree_hash(folders: Iterable[str], pattern: str = "*.py"):
    """A SHA-256 (hashlib) object over the files matching ``pattern`` under each of ``folders``
    (relative to the package's source tree), sorted by path, each its relative path and bytes:
    what a cache key takes of the code or data a result depends on; the caller may add more."""
    h = hashlib.sha256()
    for folder in folders:
        for p in sorted((_ROOT / folder).rglob(pattern)):
            if p.is_file():
                h.update(str(p.relative_to(_ROOT)).encode())
                h.update(p.read_bytes())
    return h
