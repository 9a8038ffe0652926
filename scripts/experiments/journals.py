"""The journals of the benchmarks' sweeps (scripts.journal): what each kind of unit depends on,
and its result as JSON and back, exactly.

- ``search_journal``: ``bench search``'s batches of episodes (every policy on each): a list per
  episode of a list per policy of ``SearchResult``, every field (the trace and log included);
- ``draw_journal``: an episode draw's world checks (``WorldDraw``, the episode as
  agent.search.draw_store writes it);
- ``learn_journal``: ``bench transfer``'s learning runs (the examinations and the store's bytes).

A decoder accepts only what its encoder writes (types checked, floats finite unless written as
``inf``/``nan`` text, names and indices those of the unit asked for); anything else raises, and
the journal counts it a miss.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
from pathlib import Path

from ctxsearch.agent.search import draw_store
from ctxsearch.agent.search.config import SearchConfig, to_dict
from ctxsearch.agent.search.draw import WorldDraw
from ctxsearch.agent.search.episode import Episode, EpisodeDraw, GazeRecord, SearchResult
from ctxsearch.envs.robot_spec import RobotPose
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.scripts.journal import Journal, context_digest, finite, whole

_NONFINITE = {"inf": math.inf, "-inf": -math.inf, "nan": math.nan}


def _f(x) -> float | str:
    v = float(x)
    return v if math.isfinite(v) else repr(v)


def _uf(v) -> float:
    if isinstance(v, str):
        return _NONFINITE[v]
    return finite(v)


def _opt(v, fn):
    return None if v is None else fn(v)


def _text(v) -> str:
    if not isinstance(v, str):
        raise TypeError("not text")
    return v


def _flag(v) -> bool:
    if not isinstance(v, bool):
        raise TypeError("not a flag")
    return v


def result_json(r: SearchResult) -> dict:
    """A ``SearchResult`` as JSON, every field."""
    return {
        "policy": r.policy, "episode": int(r.episode), "target": r.target, "found": bool(r.found),
        "found_id": _opt(r.found_id, int), "sim_time": _f(r.sim_time), "gazes": int(r.gazes),
        "path_m": _f(r.path_m), "budget_s": _f(r.budget_s),
        "trace": [
            [_f(g.t), [_f(x) for x in (g.pose.x, g.pose.y, g.pose.yaw, g.pose.pan, g.pose.tilt)],
             g.purpose, [[t, int(i)] for t, i in g.detections]]
            for g in r.trace
        ],
        "log": list(r.log), "intermediate": r.intermediate,
        "predicted_gain": _opt(r.predicted_gain, _f), "unconfirmed": int(r.unconfirmed),
        "mass_left": _opt(r.mass_left, _f),
    }  # fmt: skip


def result_from_json(d: dict) -> SearchResult:
    """The ``SearchResult`` ``result_json`` wrote (an exception for anything else)."""
    trace = []
    for t, pose, purpose, dets in d["trace"]:
        if len(pose) != 5:
            raise ValueError("a pose has five numbers")
        detections = tuple((_text(a), whole(b)) for a, b in dets)
        trace.append(GazeRecord(_uf(t), RobotPose(*(_uf(x) for x in pose)), _text(purpose),
                                detections))  # fmt: skip
    return SearchResult(
        _text(d["policy"]), whole(d["episode"]), _text(d["target"]), _flag(d["found"]),
        _opt(d["found_id"], whole), _uf(d["sim_time"]), whole(d["gazes"]), _uf(d["path_m"]),
        _uf(d["budget_s"]), trace, [_text(x) for x in d["log"]],
        _opt(d["intermediate"], _text), _opt(d["predicted_gain"], _uf), whole(d["unconfirmed"]),
        _opt(d["mass_left"], _uf),
    )  # fmt: skip


def _episode_key(ep: Episode) -> list:
    """What identifies an episode, in plain types (a drawn episode and one read back from a
    kept draw give the same text)."""
    s = ep.start
    return [int(ep.index), str(ep.style), int(ep.room_seed), str(ep.target),
            [float(x) for x in (s.x, s.y, s.yaw, s.pan, s.tilt)], float(ep.budget_s),
            _opt(ep.instance, int), int(ep.day), _opt(ep.stayed, bool)]  # fmt: skip


def _batch_key(batch: list[Episode]) -> str:
    return json.dumps([_episode_key(ep) for ep in batch])


def kb_fingerprint(kb: KnowledgeBase | None) -> list | None:
    """The counts of a knowledge base held in memory (None: none), for a journal's context."""
    if kb is None:
        return None
    out = []
    for a in kb.catalog.type_names:
        if kb.n(a):
            out.append([a, kb.n(a), sorted([r, b, y] for (r, b), y in kb.nonzero(a).items())])
    return out


def search_journal(
    directory: Path, config: SearchConfig, names: list[str], kb: KnowledgeBase | None
) -> Journal:
    """The journal of ``bench search``'s batches run with the resolved ``config`` (its store's
    bytes and its truth file's, if any, in the context), policies ``names`` and the knowledge
    ``kb`` held in memory (None: the store's)."""
    k = config.knowledge
    ctx = context_digest(
        "bench search: batch", [to_dict(config), names, kb_fingerprint(kb)], [k.kb, k.truth]
    )

    def encode(batch: list[list[SearchResult]]) -> list:
        return [[result_json(r) for r in per_policy] for per_policy in batch]

    def decode(doc) -> list[list[SearchResult]]:
        out = [[result_from_json(r) for r in per_policy] for per_policy in doc]
        if any([r.policy for r in per_policy] != names for per_policy in out):
            raise ValueError("other policies")
        return out

    return Journal(Path(directory), ctx, encode, decode, _batch_key)


def _world_json(w: WorldDraw) -> dict:
    ep = None
    if w.episode is not None:
        ep = draw_store.to_json(EpisodeDraw([w.episode]))["episodes"][0]
    return {"episode": ep, "dropped": w.dropped, "redraws": int(w.redraws)}


def _world_from_json(d: dict) -> WorldDraw:
    ep = None
    if d["episode"] is not None:
        doc = {"format": draw_store.FORMAT, "visible_at_start": 0, "infeasible": 0,
               "start_redraws": 0, "episodes": [d["episode"]]}  # fmt: skip
        ep = draw_store.from_json(doc).episodes[0]
    return WorldDraw(ep, _opt(d["dropped"], _text), whole(d["redraws"]))


def draw_journal(directory: Path, spec) -> Journal:
    """The journal of the world checks of the episode draw of ``spec`` (a ``draw.DrawSpec``: its
    key, agent.search.draw_store's, covers the spec and the code); a unit is a world's index."""
    ctx = context_digest("episode draw: world", draw_store.draw_key(spec))
    return Journal(Path(directory), ctx, _world_json, _world_from_json)


def learn_journal(directory: Path, what: object) -> Journal:
    """The journal of learning units (``bench transfer``'s: {"examinations", "store" bytes}),
    ``what``: the settings every unit shares (JSON data)."""

    def encode(r: dict) -> dict:
        return {"examinations": int(r["examinations"]),
                "store": base64.b64encode(r["store"]).decode("ascii")}  # fmt: skip

    def decode(d: dict) -> dict:
        try:
            data = base64.b64decode(_text(d["store"]), validate=True)
        except binascii.Error as exc:
            raise ValueError("not base64") from exc
        return {"examinations": whole(d["examinations"]), "store": data}

    return Journal(Path(directory), context_digest("learning run", what), encode, decode)
