"""Typed settings read from files and command lines: frozen dataclasses whose fields carry
their default, help line and range (``setting``), with the conversions every configuration
needs. A key is dotted by section (``online.lookahead``); the top-level keys have none.

- ``keys``: every leaf key of a configuration class and its field;
- ``apply_dict`` (a TOML or JSON document's nested tables), ``apply_set`` (one ``key=value`` as
  typed on a command line) and ``updated`` (a mapping of dotted keys, from code): a new
  configuration, each value converted to its field's type (``coerce``) and checked against its
  range (``check``); every problem is one ``SettingsError`` line naming the key and where it
  came from;
- ``to_dict`` (JSON-able, as results record it), ``to_toml`` (what ``load_file`` reads back) and
  ``load_file`` (a TOML file, or a JSON document: a result whose ``config`` entry is read);
- ``help_of``: a key's help with its default, for a command line's help text.

Standard library only; the files are read through ``knowledge.files`` (regular files only,
bounded size and nesting).
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import field
from enum import StrEnum
from pathlib import Path
from typing import Any

from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.files import InputFileError, read_json, read_toml

MAX_SETTINGS_BYTES = 1 << 20  # a configuration file is a few hundred bytes


class SettingsError(CtxsearchError, ValueError):
    """A configuration value or file that cannot be used: one line naming the key (a
    ``ValueError`` too, for Python callers)."""


def setting(default, help: str, lo: float | None = None, hi: float | None = None):
    """A configuration field: its default, its help line and its closed range (numbers)."""
    return field(default=default, metadata={"help": help, "range": (lo, hi)})


def _hints(cls) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def keys(cls, prefix: str = "") -> dict[str, dataclasses.Field]:
    """Every leaf key of configuration class ``cls`` (dotted) and its field."""
    out: dict[str, dataclasses.Field] = {}
    hints = _hints(cls)
    for f in dataclasses.fields(cls):
        t = hints[f.name]
        if dataclasses.is_dataclass(t):
            out.update(keys(t, f"{prefix}{f.name}."))
        else:
            out[prefix + f.name] = f
    return out


def _optional(t) -> tuple[Any, bool]:
    """(the type inside ``X | None``, whether None is allowed)."""
    args = typing.get_args(t)
    if isinstance(t, types.UnionType) or typing.get_origin(t) is typing.Union:
        inner = [a for a in args if a is not type(None)]
        return inner[0], len(inner) < len(args)
    return t, False


_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")
_NONE = ("none", "")


def coerce(value: object, t, key: str, where: str, *, text: bool = False) -> object:
    """``value`` as a value of field type ``t`` (``text``: it comes from a command line as a
    string); a SettingsError naming ``key`` and ``where`` otherwise."""
    inner, nullable = _optional(t)
    if value is None or (text and nullable and str(value).strip().lower() in _NONE):
        if nullable:
            return None
        raise SettingsError(f"{where}: {key}: a value is required")
    if isinstance(inner, type) and issubclass(inner, StrEnum):
        try:
            return inner(value)
        except ValueError:
            known = ", ".join(m.value for m in inner)
            raise SettingsError(
                f"{where}: {key}: unknown value {value!r} (known: {known})"
            ) from None
    convert = _CONVERTERS.get(inner) or _CONVERTERS[typing.get_origin(inner)]
    got = convert(value, text)
    if isinstance(got, str) and got.startswith("expected"):
        raise SettingsError(f"{where}: {key}: {got}, got {value!r}")
    return got


def _bool(value: object, text: bool) -> object:
    if isinstance(value, bool):
        return value
    word = str(value).strip().lower() if text else None
    return True if word in _TRUE else False if word in _FALSE else "expected true or false"


def _int(value: object, text: bool) -> object:
    if isinstance(value, int) and not isinstance(value, bool):
        return value
    if text and isinstance(value, str):
        try:
            return int(value)
        except ValueError:
            pass
    return "expected an integer"


def _float(value: object, text: bool) -> object:
    ok = isinstance(value, int | float) or (text and isinstance(value, str))
    if isinstance(value, bool) or not ok:
        return "expected a number"
    try:
        v = float(value)
    except ValueError:
        return "expected a number"
    return v if math.isfinite(v) else "expected a finite number"


def _str(value: object, text: bool) -> object:
    if not isinstance(value, str) or not value or "\x00" in value:
        return "expected a non-empty string"
    return value


def _path(value: object, text: bool) -> object:
    if not isinstance(value, str | Path) or not str(value) or "\x00" in str(value):
        return "expected a path"
    return Path(value)


def _names(value: object, text: bool) -> object:
    items = value.split(",") if isinstance(value, str) else value
    if not isinstance(items, list | tuple) or not all(isinstance(x, str) for x in items):
        return "expected a list of names"
    return tuple(x.strip() for x in items if x.strip())


_CONVERTERS = {bool: _bool, int: _int, float: _float, str: _str, Path: _path, tuple: _names}


def check(config) -> None:
    """A SettingsError for a number of ``config`` out of its field's range."""
    for key, f in keys(type(config)).items():
        lo, hi = f.metadata.get("range", (None, None))
        v = get(config, key)
        if (lo is None and hi is None) or isinstance(v, bool) or not isinstance(v, int | float):
            continue
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            span = f"[{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}]"
            raise SettingsError(f"{key}: {v!r} is out of range {span}")


def get(config, key: str) -> object:
    """The value at dotted ``key``."""
    for part in key.split("."):
        config = getattr(config, part)
    return config


def replace_key(config, key: str, value: object):
    """``config`` with dotted ``key`` set to ``value`` (as it is: coerce it first)."""
    head, _, rest = key.partition(".")
    if rest:
        return dataclasses.replace(
            config, **{head: replace_key(getattr(config, head), rest, value)}
        )
    return dataclasses.replace(config, **{head: value})


def _unknown(config, key: str, where: str) -> SettingsError:
    known = ", ".join(keys(type(config)))
    return SettingsError(f"{where}: unknown key '{key}' (known: {known})")


def _set(config, key: str, value: object, where: str, text: bool):
    """``config`` with ``key`` set to ``value`` converted to the field's type and checked."""
    section, _, name = key.rpartition(".")
    owner = type(get(config, section)) if section else type(config)
    v = coerce(value, _hints(owner)[name], key, where, text=text)
    try:
        return replace_key(config, key, v)
    except SettingsError as exc:
        raise SettingsError(f"{where}: {exc}") from None


def apply_set(config, assignment: str, where: str = "--set"):
    """``config`` with one ``key=value`` applied (the value as typed on a command line)."""
    key, eq, value = assignment.partition("=")
    key = key.strip()
    if not eq or not key:
        raise SettingsError(f"{where}: expected key=value, got {assignment!r}")
    if key not in keys(type(config)):
        raise _unknown(config, key, where)
    return _set(config, key, value.strip(), where, text=True)


def apply_dict(config, doc: object, where: str, prefix: str = ""):
    """``config`` with every key of ``doc`` (nested tables, as TOML or JSON gives them)
    applied; a SettingsError naming the first unknown key or bad value."""
    if not isinstance(doc, dict):
        what = prefix.rstrip(".") or "the configuration"
        raise SettingsError(f"{where}: {what}: expected a table")
    known = keys(type(config))
    for k, v in doc.items():
        key = prefix + str(k)
        if isinstance(v, dict) and any(n.startswith(key + ".") for n in known):
            config = apply_dict(config, v, where, key + ".")
        elif key in known:
            config = _set(config, key, v, where, text=False)
        else:
            raise _unknown(config, key, where)
    return config


def updated(config, changes: dict[str, object], where: str = "configuration"):
    """``config`` with the dotted keys of ``changes`` set (checked as a file's values are)."""
    doc: dict = {}
    for key, value in changes.items():
        *sections, name = key.split(".")
        d = doc
        for part in sections:
            d = d.setdefault(part, {})
        d[name] = value
    return apply_dict(config, doc, where)


def to_dict(config) -> dict:
    """The configuration as JSON-able nested dicts (enums and paths as strings)."""
    out: dict = {}
    for f in dataclasses.fields(config):
        v = getattr(config, f.name)
        if dataclasses.is_dataclass(v):
            out[f.name] = to_dict(v)
        elif isinstance(v, tuple):
            out[f.name] = list(v)
        elif isinstance(v, Path | StrEnum):
            out[f.name] = str(v)
        else:
            out[f.name] = v
    return out


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"') + '"'


def to_toml(config) -> str:
    """The configuration as a TOML document ``load_file`` reads back (None values left out)."""
    doc = to_dict(config)
    top = [(k, v) for k, v in doc.items() if not isinstance(v, dict)]
    lines = [f"{k} = {_toml_value(v)}" for k, v in top if v is not None]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines += ["", f"[{k}]"]
            lines += [f"{n} = {_toml_value(x)}" for n, x in v.items() if x is not None]
    return "\n".join(lines) + "\n"


def load_file(path: Path | str, base):
    """The configuration in the file at ``path`` over ``base``: a TOML file of keys and
    sections, or a JSON document (a result whose ``config`` entry is read, or the configuration
    itself). One-line errors for anything else."""
    p = Path(path)
    try:
        if p.suffix.lower() == ".json":
            doc = read_json(p, MAX_SETTINGS_BYTES * 64, parse_constant=_no_constant)
            if isinstance(doc, dict) and isinstance(doc.get("config"), dict):
                doc = doc["config"]
        else:
            doc = read_toml(p, MAX_SETTINGS_BYTES)
    except InputFileError as exc:
        raise SettingsError(str(exc)) from None
    return apply_dict(base, doc, str(p))


def _no_constant(name: str) -> object:
    raise ValueError(f"{name} is not a number a configuration can hold")


def help_of(config, key: str) -> str:
    """A key's help line with its default in ``config`` (a command line's help texts)."""
    f = keys(type(config))[key]
    default = get(config, key)
    shown = ",".join(default) if isinstance(default, tuple) else default
    return f"{f.metadata.get('help', '')} (default: {'none' if default is None else shown})"
