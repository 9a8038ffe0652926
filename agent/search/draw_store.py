"""Episode draws kept on disk between commands (``bench search --draw-cache DIR``).

An episode draw (``agent.search.draw.draw_episodes``) is deterministic in its arguments and costs about
2.5 s per world checked, mostly the oracle's feasibility plan: 200 house episodes take about 5
minutes to draw. ``make bench`` searches the same 200 episodes in both map scenarios, in two
commands; with ``--draw-cache DIR`` the second reads the first's draw instead of drawing it
again (the same episodes, counts and oracle first plans, so the same results).

A file ``DIR/<key>.json`` holds one draw. Its key is a SHA-256 over the draw's spec
(``draw.DrawSpec``: the style as loaded, the number of episodes, the seed, the catalog's
fingerprint, the budget, the excluded room seeds, the target, the detector preset) and over the source of the packages the
draw runs (``agent``, ``envs``, ``knowledge``): a changed argument or a changed line of code is
another key, never a stale draw. A file that cannot be read back as a draw (any bytes: a
truncated write, an edit by hand; a FIFO, a device, a file nested too deep: knowledge.files
reads it) or that is not the draw asked for (``draw.check_draw``: held-out worlds only, starts in
the free space, the budget and the number of episodes asked, counts that are counts) is a miss:
the draw is made again and the file replaced
(written to a temporary file first, then renamed, so a reader never sees half a file).
Floats are written with ``repr``: they read back to the same bits.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from collections.abc import Hashable
from pathlib import Path

import numpy as np

from ctxsearch.agent.search.episode import Episode, EpisodeDraw, OracleView
from ctxsearch.agent.viewplan import Gaze
from ctxsearch.envs.robot_spec import RobotPose
from ctxsearch.knowledge.files import InputFileError, read_json, tree_hash, write_bytes

FORMAT = 1
MAX_DRAW_BYTES = 256 * 2**20  # a draw of 10,000 house episodes is about 30 MB
_PACKAGES = ("agent", "envs", "knowledge")


@functools.cache
def code_digest() -> str:
    """SHA-256 over the source files of the packages an episode draw runs (sorted by path)."""
    return tree_hash(_PACKAGES).hexdigest()


def draw_key(spec: Hashable) -> str:
    """The file name stem of the draw made with ``spec`` (a ``draw.DrawSpec``)."""
    h = hashlib.sha256()
    h.update(f"format {FORMAT}\n{code_digest()}\n".encode())
    h.update(repr(spec).encode())
    return h.hexdigest()[:32]


def _pose(p: RobotPose) -> list[float]:
    return [p.x, p.y, p.yaw, p.pan, p.tilt]


def _view_json(v: OracleView | None) -> dict | None:
    if v is None:
        return None
    g = v.gaze
    return {
        "seconds": v.seconds,
        "gaze": {
            "pose": _pose(g.pose),
            "target": [float(x) for x in np.asarray(g.target, float)],
            "coverage": g.coverage,
            "cost": g.cost,
            "path": None if g.path is None else np.asarray(g.path, float).tolist(),
        },
        "instance_id": v.instance_id,
        "renders": v.renders,
        "key": list(v.key),
    }


def _finite(x) -> float:
    v = float(x)
    if not math.isfinite(v):
        raise ValueError("not finite")
    return v


def _view(d: dict | None) -> OracleView | None:
    if d is None:
        return None
    g = d["gaze"]
    path = None if g["path"] is None else np.array(g["path"], float).reshape(-1, 2)
    gaze = Gaze(
        RobotPose(*(_finite(x) for x in g["pose"])),
        np.array([_finite(x) for x in g["target"]], float),
        _finite(g["coverage"]),
        _finite(g["cost"]),
        path,
    )
    k = d["key"]
    key = (float(k[0]), float(k[1]), int(k[2]), int(k[3]))
    return OracleView(_finite(d["seconds"]), gaze, int(d["instance_id"]), int(d["renders"]), key)


def to_json(draw: EpisodeDraw) -> dict:
    """A JSON-serialisable dict of an ``EpisodeDraw``."""
    return {
        "format": FORMAT,
        "visible_at_start": draw.visible_at_start,
        "infeasible": draw.infeasible,
        "start_redraws": draw.start_redraws,
        "episodes": [
            {
                **ep.to_json(),
                "start": _pose(ep.start),
                "first_view": _view_json(ep.first_view),
            }
            for ep in draw.episodes
        ],
    }


def _flag(v: object) -> bool | None:
    if v is not None and not isinstance(v, bool):
        raise TypeError("stayed is not a flag")
    return v


def from_json(doc: dict) -> EpisodeDraw:
    """The ``EpisodeDraw`` ``to_json`` wrote; ValueError, KeyError or TypeError on anything
    else."""
    if doc.get("format") != FORMAT:
        raise ValueError("another format")
    eps = [
        Episode(
            int(e["index"]),
            str(e["style"]),
            int(e["room_seed"]),
            str(e["target"]),
            RobotPose(*(_finite(x) for x in e["start"])),
            _finite(e["budget_s"]),
            instance=None if e.get("instance") is None else int(e["instance"]),
            day=int(e.get("day", 0)),
            first_view=_view(e["first_view"]),
            stayed=_flag(e.get("stayed")),
        )
        for e in doc["episodes"]
    ]
    return EpisodeDraw(
        eps, int(doc["visible_at_start"]), int(doc["infeasible"]), int(doc["start_redraws"])
    )


def load(directory: Path, key: str) -> EpisodeDraw | None:
    """The draw stored under ``key`` in ``directory``, or None (no file, or not a draw: anything
    but a regular file, over ``MAX_DRAW_BYTES``, nested deeper than JSON's ``MAX_NESTING``, or not
    what ``to_json`` writes). Whether it is the draw the command asked for is the caller's check
    (agent.search.draw.check_draw)."""
    path = Path(directory) / f"{key}.json"
    try:
        return from_json(read_json(path, MAX_DRAW_BYTES))
    except (InputFileError, ValueError, KeyError, TypeError, IndexError, AttributeError):
        return None


def save(directory: Path, key: str, draw: EpisodeDraw) -> None:
    """Store ``draw`` under ``key`` in ``directory`` (``write_json``)."""
    write_json(directory, key, to_json(draw), "episode draw")


def write_json(directory: Path, key: str, doc: object, what: str) -> None:
    """Store ``doc`` as ``directory/key.json`` (``write_bytes``)."""
    write_bytes(directory, f"{key}.json", json.dumps(doc).encode("utf-8"), what)
