"""The robot's remembered map of a home: what it built on a visit and keeps for later days.

A ``HomeMap`` holds what the robot made of one world (style, seed) on the day it was there:

- its occupancy from depth (``floor``, ``occupied``, ``top_z``: agent.mapping.BuiltMap's arrays,
  cells of ``resolution`` m from (``x0``, ``y0``)), over the footprint ``bounds`` up to ``top``;
- which points of the search lattice rest on a surface it saw (``support``: agent.search.space's
  SeenMap of the footprint; empty when the map was made without one);
- its own room segmentation (``rooms``: labels on the occupancy grid's cells, -1 none);
- the furniture it recognised (``RememberedObject``: the type reported most often, the mean of
  its estimated poses, its best detector confidence, the images that showed it). The ids are the
  detector's instance ids: in simulation the renderer's, so a later detection of the same piece
  is known as the same piece;
- the small objects it recognised (``small``: the same records, each with the day it was last
  seen: a visit keeps what it saw today and carries over the earlier sightings it did not look
  at again), the robot's "where did I see it last";
- what it found when it looked again at a place where an earlier day's map had a small object
  (``checks``: ``PersistenceCheck``, one per remembered sighting whose place its images showed),
  the trials of the learned persistence (knowledge.persistence).

It is data, in numpy and the standard library: ``to_bytes`` and ``from_bytes`` write and read it
as a NumPy ``.npz`` archive without pickles (a JSON header and plain arrays), and ``from_bytes``
refuses, in one line naming where the bytes came from, anything that is not a map this module
wrote: a truncated or hostile blob, arrays of the wrong shape or kind, numbers that are not
finite, ids or counts out of range.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import ObjectInstance

FORMAT = "ctxsearch-home-map"
VERSION = 2  # 2: small objects and persistence checks; version 1 (neither) is read as well
READS = (1, 2)
MAX_CELLS = 4_000_000  # a map larger than this (cells) is not one this project writes
MAX_OBJECTS = 10_000
MAX_BYTES = 64 * 1024 * 1024
_ARRAYS = {"floor": np.bool_, "occupied": np.bool_, "top_z": np.float32, "rooms": np.int16,
           "support": np.bool_}  # fmt: skip
# The most bytes each archive member may hold unpacked (checked before it is read: a small
# compressed blob must not unpack to gigabytes): the JSON header, and an array of the most cells
# a map has (the support lattice: 50 points a cell) with room for its .npy header.
_MEMBER_BYTES = {"header": MAX_BYTES} | {
    k: (50 if k == "support" else 1) * MAX_CELLS * np.dtype(t).itemsize + 4096
    for k, t in _ARRAYS.items()
}


class HomeMapError(CtxsearchError, ValueError):
    """A remembered map that cannot be read: one line naming where it came from."""

    def __init__(self, where: object, message: str):
        super().__init__(f"{where}: remembered map: {message}")


@dataclass(frozen=True)
class RememberedObject:
    """A piece of furniture as the robot remembers it: the type reported most often, the
    detector's instance id, the mean estimated pose and size, its best confidence and in how
    many images it was detected."""

    type: str
    id: int
    position: tuple[float, float, float]
    yaw: float
    size: tuple[float, float, float]
    confidence: float
    sightings: int
    day: int | None = None  # the day it was last seen (None: the map's own day)

    def instance(self) -> ObjectInstance:
        """As an ObjectInstance (what the location constraint reads)."""
        return ObjectInstance(self.type, self.id, self.position, self.yaw, self.size)


@dataclass(frozen=True)
class PersistenceCheck:
    """A visit looked again at the place where an earlier map had a small object of ``type``
    (seen ``age`` days before): ``recall`` is the probability that its images would have
    reported an instance standing there (one minus the product of each image's miss, by the
    detector's recall at that distance), ``false_rate`` the probability they reported one there
    that was not (0: the model's choice, knowledge.persistence), and ``still`` whether one of
    them reported an instance of the type within the persistence radius of the place."""

    type: str
    age: int
    recall: float
    false_rate: float
    still: bool


@dataclass(frozen=True, eq=False)
class HomeMap:
    """One world's remembered map (module docstring)."""

    style: str
    seed: int
    day: int
    bounds: tuple[float, float, float, float]
    top: float
    x0: float
    y0: float
    resolution: float
    floor: np.ndarray
    occupied: np.ndarray
    top_z: np.ndarray
    rooms: np.ndarray
    furniture: tuple[RememberedObject, ...] = ()
    support: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    images: int = 0  # the depth images it was built from
    small: tuple[RememberedObject, ...] = ()  # small objects, each with its last day seen
    checks: tuple[PersistenceCheck, ...] = ()  # places of earlier sightings looked at again

    def __post_init__(self) -> None:
        _check(self, "HomeMap")

    @property
    def shape(self) -> tuple[int, int]:
        """The occupancy grid's (rows, columns)."""
        return tuple(self.floor.shape)  # type: ignore[return-value]

    def objects(self) -> list[ObjectInstance]:
        """The remembered furniture as ObjectInstances."""
        return [o.instance() for o in self.furniture]

    def seen_day(self, o: RememberedObject) -> int:
        """The day ``o`` was last seen."""
        return self.day if o.day is None else o.day

    def last_seen(self, type_name: str) -> list[RememberedObject]:
        """The remembered small objects of ``type_name``."""
        return [o for o in self.small if o.type == type_name]

    def room_count(self) -> int:
        """How many rooms its segmentation holds."""
        return len(np.unique(self.rooms[self.rooms >= 0]))

    # ------------------------------------------------------------------ bytes
    def to_bytes(self) -> bytes:
        """The map as a pickle-free ``.npz`` archive (``from_bytes`` reads it back)."""
        head = {
            "format": FORMAT, "version": VERSION, "style": self.style, "seed": int(self.seed),
            "day": int(self.day), "bounds": [float(v) for v in self.bounds],
            "top": float(self.top), "x0": float(self.x0), "y0": float(self.y0),
            "resolution": float(self.resolution), "images": int(self.images),
            "furniture": [_record(o) for o in self.furniture],
            "small": [_record(o) for o in self.small],
            "checks": [
                {"type": c.type, "age": int(c.age), "recall": float(c.recall),
                 "false_rate": float(c.false_rate), "still": bool(c.still)}
                for c in self.checks
            ],
        }  # fmt: skip
        buf = io.BytesIO()
        arrays = {k: np.ascontiguousarray(getattr(self, k), dtype=t) for k, t in _ARRAYS.items()}
        header = np.frombuffer(json.dumps(head, sort_keys=True).encode(), np.uint8)
        np.savez_compressed(buf, header=header, **arrays)
        return buf.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes, where: object = "<memory>") -> HomeMap:
        """The map in ``data``; a one-line ``HomeMapError`` naming ``where`` for anything that
        is not a map ``to_bytes`` wrote."""
        if not isinstance(data, (bytes, bytearray, memoryview)):
            raise HomeMapError(where, "not bytes")
        if len(data) > MAX_BYTES:
            raise HomeMapError(where, f"larger than {MAX_BYTES} bytes")
        try:
            with np.load(io.BytesIO(bytes(data)), allow_pickle=False) as z:
                names = set(z.files)
                if names != {"header", *_ARRAYS}:
                    raise HomeMapError(where, "not a ctxsearch remembered map (its arrays differ)")
                for info in z.zip.infolist():
                    name = info.filename.removesuffix(".npy")
                    if info.file_size > _MEMBER_BYTES.get(name, 0):
                        raise HomeMapError(where, f"array '{name}' is too large")
                arrays = {k: z[k] for k in names}
                if not all(isinstance(a, np.ndarray) for a in arrays.values()):
                    raise HomeMapError(where, "not a ctxsearch remembered map (not .npy arrays)")
        except HomeMapError:
            raise
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as e:
            raise HomeMapError(where, f"unreadable ({type(e).__name__})") from None
        except Exception as e:  # noqa: BLE001 - zlib and zipfile raise their own kinds
            raise HomeMapError(where, f"unreadable ({type(e).__name__})") from None
        return _from_parts(arrays, where)


def _from_parts(arrays: dict, where: object) -> HomeMap:
    """The map of the archive's arrays (checked)."""
    h = arrays["header"]
    if h.dtype != np.uint8 or h.ndim != 1:
        raise HomeMapError(where, "bad header")
    try:
        head = json.loads(h.tobytes().decode())
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise HomeMapError(where, "bad header") from None
    if not isinstance(head, dict) or head.get("format") != FORMAT:
        raise HomeMapError(where, "not a ctxsearch remembered map")
    version = head.get("version")
    if isinstance(version, bool) or version not in READS:
        raise HomeMapError(where, f"version {version!r} (this code reads {READS})")
    for k, t in _ARRAYS.items():
        if arrays[k].dtype != np.dtype(t):
            raise HomeMapError(where, f"array '{k}' is {arrays[k].dtype}, not {np.dtype(t)}")
    try:
        furniture = tuple(_object(o) for o in _list(head, "furniture"))
        small = () if version < 2 else tuple(_object(o) for o in _list(head, "small"))
        checks = () if version < 2 else tuple(_check_entry(c) for c in _list(head, "checks"))
        return HomeMap(
            _str(head, "style"), _int(head, "seed", 0, 2**63 - 1), _int(head, "day", 0, 10**6),
            tuple(_num(v, "bounds") for v in _list(head, "bounds")),  # type: ignore[arg-type]
            _num(head.get("top"), "top"), _num(head.get("x0"), "x0"), _num(head.get("y0"), "y0"),
            _num(head.get("resolution"), "resolution"), arrays["floor"], arrays["occupied"],
            arrays["top_z"], arrays["rooms"], furniture, arrays["support"],
            _int(head, "images", 0, 2**31), small, checks,
        )  # fmt: skip
    except HomeMapError as e:
        raise HomeMapError(where, str(e).split("remembered map: ", 1)[-1]) from None
    except (TypeError, ValueError, KeyError) as e:
        raise HomeMapError(where, f"bad field ({e})") from None


def _check(m: HomeMap, where: str) -> None:
    """The invariants of a map (module docstring)."""
    if len(m.bounds) != 4 or not all(math.isfinite(v) for v in m.bounds):
        raise HomeMapError(where, "bounds must be four finite numbers")
    x0, y0, x1, y1 = m.bounds
    if not (x1 > x0 and y1 > y0):
        raise HomeMapError(where, "bounds are empty")
    for name in ("top", "x0", "y0", "resolution"):
        if not math.isfinite(getattr(m, name)):
            raise HomeMapError(where, f"{name} is not finite")
    if not 0.005 <= m.resolution <= 1.0 or m.top <= 0:
        raise HomeMapError(where, "resolution or height out of range")
    shape = np.shape(m.floor)
    if len(shape) != 2 or not 0 < shape[0] * shape[1] <= MAX_CELLS:
        raise HomeMapError(where, "occupancy grid of a bad shape")
    for name in ("occupied", "top_z", "rooms"):
        if np.shape(getattr(m, name)) != shape:
            raise HomeMapError(where, f"'{name}' is not the occupancy grid's shape")
    if not np.isfinite(m.top_z).all():
        raise HomeMapError(where, "heights that are not finite")
    if np.ndim(m.support) != 1 or len(m.support) > 50 * MAX_CELLS:
        raise HomeMapError(where, "support of a bad shape")
    if m.rooms.size and int(m.rooms.min()) < -1:
        raise HomeMapError(where, "room labels below -1")
    if len(m.furniture) + len(m.small) > MAX_OBJECTS or len(m.checks) > MAX_OBJECTS:
        raise HomeMapError(where, f"more than {MAX_OBJECTS} objects")
    if len({o.id for o in m.furniture}) != len(m.furniture):
        raise HomeMapError(where, "an object id twice")
    if any(o.day is not None and not 0 <= o.day <= m.day for o in m.small):
        raise HomeMapError(where, "a small object last seen after the map's day")


def _list(head: dict, key: str) -> list:
    v = head.get(key)
    if not isinstance(v, list):
        raise HomeMapError("", f"'{key}' is not a list")
    return v


def _str(head: dict, key: str) -> str:
    v = head.get(key)
    if not isinstance(v, str) or not v or len(v) > 1000:
        raise HomeMapError("", f"'{key}' is not a name")
    return v


def _int(head: dict, key: str, lo: int, hi: int) -> int:
    v = head.get(key)
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise HomeMapError("", f"'{key}' is not an integer in [{lo}, {hi}]")
    return v


def _num(v: object, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise HomeMapError("", f"'{what}' is not a finite number")
    return float(v)


def _triple(v: object, what: str) -> tuple[float, float, float]:
    if not isinstance(v, list) or len(v) != 3:
        raise HomeMapError("", f"'{what}' is not three numbers")
    return tuple(_num(x, what) for x in v)  # type: ignore[return-value]


def _record(o: RememberedObject) -> dict:
    out = {"type": o.type, "id": int(o.id), "position": [float(v) for v in o.position],
           "yaw": float(o.yaw), "size": [float(v) for v in o.size],
           "confidence": float(o.confidence), "sightings": int(o.sightings)}  # fmt: skip
    if o.day is not None:
        out["day"] = int(o.day)
    return out


def _object(o: object) -> RememberedObject:
    if not isinstance(o, dict):
        raise HomeMapError("", "an object entry is not a table")
    size = _triple(o.get("size"), "size")
    conf = _num(o.get("confidence"), "confidence")
    if min(size) <= 0 or not 0.0 <= conf <= 1.0:
        raise HomeMapError("", "an object entry's size or confidence is out of range")
    day = None if o.get("day") is None else _int(o, "day", 0, 10**6)
    return RememberedObject(
        _str(o, "type"), _int(o, "id", -(2**63), 2**63 - 1), _triple(o.get("position"), "position"),
        _num(o.get("yaw"), "yaw"), size, conf, _int(o, "sightings", 0, 2**31), day,
    )  # fmt: skip


def _check_entry(c: object) -> PersistenceCheck:
    if not isinstance(c, dict):
        raise HomeMapError("", "a check entry is not a table")
    recall, false = _num(c.get("recall"), "recall"), _num(c.get("false_rate"), "false_rate")
    still = c.get("still")
    if not (0.0 <= recall <= 1.0 and 0.0 <= false <= 1.0) or not isinstance(still, bool):
        raise HomeMapError("", "a check entry's recall, false rate or outcome is out of range")
    return PersistenceCheck(_str(c, "type"), _int(c, "age", 1, 10**6), recall, false, still)


def check_types(m: HomeMap, known: Iterable[str], where: object) -> HomeMap:
    """``m`` if every remembered type is one of ``known`` (the catalog's); a one-line error
    naming the first that is not."""
    names = set(known)
    for o in (*m.furniture, *m.small, *m.checks):
        if o.type not in names:
            raise HomeMapError(where, f"unknown type {o.type!r}")
    return m
