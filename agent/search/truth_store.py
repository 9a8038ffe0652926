"""The ground-truth estimate of the oracle-prior policies kept on disk between commands.

``envs.truth.ground_truth`` over a style's sample worlds is deterministic in its inputs and costs
seconds to tens of seconds (it generates every sample world); every ``bench search`` with an
oracle-prior policy needs it. ``cached_ground_truth`` keeps each estimate in the user's cache
directory (``cache_dir``) under a key that is a SHA-256 over the style as loaded (its ``repr``:
every field of the style, so an edited style file is another key), the number of samples, the
seed, the catalog's fingerprint and the source of the packages the estimate runs
(``draw_store.code_digest``): a changed input or a changed line of code is another key, never a
stale estimate. A file that does not read back as a ground truth of that style, catalog,
sample count and seed (any bytes: knowledge.files and ``envs.truth.parse_truth`` read it) is a
miss: the estimate is made again and the file replaced (written to a temporary file first, then
renamed). Floats are written with ``repr``: they read back to the same bits, so a cached
estimate gives the same searches as a fresh one.

The cache directory is ``$CTXSEARCH_CACHE_DIR`` if set (empty: no cache), else
``$XDG_CACHE_HOME/ctxsearch`` (default ``~/.cache/ctxsearch``); its ``truth/`` folder holds
these files and may be deleted at any time.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from ctxsearch.agent.search.draw_store import code_digest, write_json
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import WorldStyle
from ctxsearch.envs.truth import (
    RoomTruth,
    TruthError,
    ground_truth,
    load_truth,
    room_contents,
    room_doors,
)
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.files import InputFileError, cache_dir, read_json

FORMAT = 2  # 2: the room truth keeps each world's doors


def truth_key(
    style: WorldStyle, samples: int, seed: int, catalog: Catalog, what: str = "truth"
) -> str:
    """The file name stem of the estimate ``what`` (``truth``, ``rooms``) with these inputs."""
    h = hashlib.sha256()
    h.update(f"{what} format {FORMAT}\n{code_digest()}\n{catalog.fingerprint}\n".encode())
    h.update(f"{int(samples)}\n{int(seed)}\n{style!r}".encode())
    return h.hexdigest()[:32]


def cached_ground_truth(
    style: WorldStyle, samples: int, seed: int, catalog: Catalog, progress: bool = False
) -> dict:
    """``envs.truth.ground_truth(style, samples, seed, catalog)``, read from the cache when it
    holds it, made (with a progress bar on stderr if ``progress``) and kept otherwise."""
    root = cache_dir()
    path = (
        None
        if root is None
        else root / "truth" / f"{truth_key(style, samples, seed, catalog)}.json"
    )
    if path is not None:
        try:
            doc = load_truth(path, catalog, style.name)
        except TruthError:
            doc = None
        if doc is not None and (doc.get("samples"), doc.get("seed")) == (samples, seed):
            return doc
    doc = ground_truth(style, samples, seed, catalog, progress=progress)
    if path is not None:
        write_json(path.parent, path.stem, doc, "ground-truth estimate")
    return doc


def cached_room_truth(style: WorldStyle, samples: int, seed: int, catalog: Catalog) -> RoomTruth:
    """``envs.truth.room_truth(style, samples, catalog, seed)``: the same numbers, from each
    sample world's true room contents and doors (``envs.truth.room_contents``, ``room_doors``),
    kept in the cache; a file that is not those for this catalog is a miss."""
    path = _path(truth_key(style, samples, seed, catalog, "rooms"))
    got = None if path is None else _read_contents(path, samples, catalog)
    if got is None:
        seeds = range(int(seed), int(seed) + int(samples))
        layouts = [generate_layout(style, s, catalog) for s in seeds]
        got = ([room_contents(w) for w in layouts], [room_doors(w) for w in layouts])
        if path is not None:
            doc = [{"rooms": r, "doors": d} for r, d in zip(*got, strict=True)]
            write_json(path.parent, path.stem, doc, "ground-truth room contents")
    return RoomTruth.of_contents(got[0], catalog, got[1])


def _path(key: str) -> Path | None:
    root = cache_dir()
    return None if root is None else root / "truth" / f"{key}.json"


def _read_contents(path: Path, samples: int, catalog: Catalog) -> tuple[list, list] | None:
    """The room contents and doors kept at ``path`` (per world {"rooms": [(room, type,
    instances)], "doors": [(a, b)]}), or None if the file is missing or is not that."""
    try:
        doc = read_json(path)
    except InputFileError:
        return None
    if not isinstance(doc, list) or len(doc) != samples:
        return None
    worlds, doors = [], []
    for world in doc:
        if not isinstance(world, dict) or set(world) != {"rooms", "doors"}:
            return None
        rooms, pairs = world["rooms"], world["doors"]
        if not isinstance(rooms, list) or not isinstance(pairs, list):
            return None
        rows = []
        for row in rooms:
            ok = isinstance(row, list) and len(row) == 3
            room, name, k = row if ok else (None, None, None)
            if not (
                ok and type(room) is int and room >= 0 and isinstance(name, str)
                and name in catalog and type(k) is int and k >= 1
            ):  # fmt: skip
                return None
            rows.append((room, name, k))
        if not all(
            isinstance(p, list) and len(p) == 2 and all(type(v) is int and v >= 0 for v in p)
            for p in pairs
        ):
            return None
        worlds.append(rows)
        doors.append([(p[0], p[1]) for p in pairs])
    return worlds, doors
