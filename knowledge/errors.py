"""Errors that the CLI reports as one line (``ctxsearch: error: ...``) with exit code 2."""

from __future__ import annotations


def printable(text: str) -> str:
    """``text`` on one line with every control or unprintable character written as an escape
    (what a crafted file puts in a message cannot move the cursor or fake a second line)."""
    return "".join(c if c.isprintable() else ascii(c)[1:-1] for c in text)


class CtxsearchError(Exception):
    """A user-facing error: bad input file, unknown name, incompatible store. One line, no
    traceback: control characters in the message (echoed from a file) are escaped."""

    def __init__(self, message: object = ""):
        super().__init__(printable(str(message)))


class CatalogError(CtxsearchError, ValueError):
    """The object-type catalog is malformed or inconsistent."""

    def __init__(
        self, path: object, message: str, *, type_name: str | None = None, field: str | None = None
    ):
        where = str(path)
        if type_name:
            where += f": type {type_name}"
        if field:
            where += f": field '{field}'"
        super().__init__(f"{where}: {message}")
        self.path, self.type_name, self.field = path, type_name, field


class ArgumentValueError(CtxsearchError, ValueError):
    """A Python API argument with a value the project cannot use (out of range, unknown name, a
    file that is not what it should be): ``except ValueError`` catches it too."""


class ArgumentTypeError(CtxsearchError, TypeError):
    """A Python API argument of the wrong type: ``except TypeError`` catches it too."""


class StoreError(CtxsearchError, ValueError):
    """A knowledge store that cannot be used (not ours, newer schema, other catalog)."""
