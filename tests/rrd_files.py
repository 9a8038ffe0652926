"""Reading .rrd files back with rerun's own reader (``rerun.chunk.RrdReader``), for the tests."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


def _columns(chunk) -> dict[str, list]:
    """A chunk's columns as lists (time columns as integer nanoseconds)."""
    import pyarrow as pa

    b = chunk.to_record_batch()
    return {
        name: (col.cast("int64") if pa.types.is_temporal(col.type) else col).to_pylist()
        for name, col in zip(b.schema.names, b.columns, strict=True)
    }


@dataclass
class RrdFile:
    """What a recording file holds: its recordings, their entities, timelines and blueprint."""

    recordings: list  # rerun StoreEntry of every recording
    blueprints: list  # and of every blueprint
    name: str | None  # the (first) recording's name
    entities: set[str] = field(default_factory=set)
    static: set[str] = field(default_factory=set)  # entities with static data
    timelines: set[tuple[str, ...]] = field(default_factory=set)  # of the temporal chunks
    times: dict[str, list[int]] = field(default_factory=dict)  # entity -> sim_time ns of rows
    texts: list[tuple[int, str]] = field(default_factory=list)  # (sim_time ns, text) of logs
    views: list[dict] = field(default_factory=list)  # blueprint views: class, name, origin
    blueprint_timeline: str | None = None


def read_rrd(path: Path | str) -> RrdFile:
    """Read ``path`` back: the first recording and the first blueprint in it."""
    from rerun.chunk import RrdReader

    r = RrdReader(path)
    out = RrdFile(r.recordings(), r.blueprints(), None)
    for c in r.stream():
        cols = _columns(c)
        e = c.entity_path
        out.entities.add(e)
        if e == "/__properties" and "RecordingInfo:name" in cols:
            out.name = cols["RecordingInfo:name"][0][0]
        if c.is_static:
            out.static.add(e)
            continue
        out.timelines.add(tuple(c.timeline_names))
        times = cols.get("sim_time", [])
        out.times.setdefault(e, []).extend(times)
        for t, text in zip(times, cols.get("TextLog:text", []), strict=False):
            out.texts.append((t, text[0]))
    out.texts.sort(key=lambda tx: tx[0])  # stable: log order within a time
    if out.blueprints:
        views: dict[str, dict] = {}
        for c in r.stream(store=out.blueprints[0]):
            cols = _columns(c)
            if c.entity_path.startswith("/view/") and "ViewBlueprint:class_identifier" in cols:
                views[c.entity_path] = {
                    "class": cols["ViewBlueprint:class_identifier"][0][0],
                    "name": cols["ViewBlueprint:display_name"][0][0],
                    "origin": cols["ViewBlueprint:space_origin"][0][0],
                }
            if c.entity_path == "/time_panel" and "TimePanelBlueprint:timeline" in cols:
                out.blueprint_timeline = cols["TimePanelBlueprint:timeline"][0][0]
        out.views = list(views.values())
    return out
