"""``ctxsearch bench rooms``: the robot's rooms against the plans.

For every house style and ``houses`` houses (seeds ``ROOMS_SEED`` + i, which no learning run
uses), the camera robot starts at the learning loop's start pose knowing only that pose, explores
until no frontier is left, and cuts its own map into rooms (``scripts.experiments.room_segments``,
agent.room_segmentation). Per room of the plan: the intersection over union with the segment
that overlaps it most, and the share of its floor the robot's map holds (``seen``). A room is
*fully seen* when ``seen`` >= ``FULLY_SEEN``; the goal is an IoU of at least 0.8 for
those. Writes DIR/rooms.json (per style: houses, rooms, segments, median and least IoU of the
fully seen rooms, the share of them at >= 0.8, exploration seconds), DIR/rooms.md and
DIR/rooms.csv (one row per house room).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ctxsearch.agent.learning import style_layouts
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.scripts.experiments.room_segments import explore_and_segment, seen_share
from ctxsearch.scripts.experiments.tables import write_csv
from ctxsearch.scripts.sweep import SweepOptions, run_units

ROOMS_SEED = 20_000_003  # first house seed (held out of learning, truth and search draws)
FULLY_SEEN = 0.9
IOU_GOAL = 0.8
COLUMNS = ("style", "house", "seed", "room", "room_style", "iou", "seen", "segments", "rooms",
           "explore_sim_s")  # fmt: skip


def _house(unit: tuple[str, int]) -> list[dict]:
    """One sweep unit: explore and segment house ``i`` of ``style``; its rows."""
    style, i = unit
    catalog = load_catalog()
    _, generate = style_layouts(style, catalog)
    layout = generate(i, ROOMS_SEED + i)
    seg = explore_and_segment(layout, catalog)
    seen = seen_share(seg)
    segments = int(seg.labels.max() + 1)
    return [
        {
            "style": style,
            "house": i,
            "seed": ROOMS_SEED + i,
            "room": r.index,
            "room_style": r.style,
            "iou": seg.iou.get(r.index, 0.0),
            "seen": seen.get(r.index, 0.0),
            "segments": segments,
            "rooms": len(layout.rooms),
            "explore_sim_s": seg.sim_s,
        }  # fmt: skip
        for r in layout.rooms
    ]


def summary(rows: list[dict]) -> dict:
    """The figures of one style's rows (module docstring)."""
    full = [r["iou"] for r in rows if r["seen"] >= FULLY_SEEN]
    houses = {r["house"]: r for r in rows}
    return {
        "houses": len(houses),
        "rooms": len(rows),
        "fully_seen": len(full),
        "iou_median": float(np.median(full)) if full else float("nan"),
        "iou_min": float(min(full)) if full else float("nan"),
        "share_iou_goal": float(np.mean([v >= IOU_GOAL for v in full])) if full else float("nan"),
        "houses_with_one_segment_per_room": sum(
            h["segments"] == h["rooms"] for h in houses.values()
        ),
        "explore_sim_s_median": float(np.median([h["explore_sim_s"] for h in houses.values()])),
    }


def bench_rooms(
    styles: tuple[str, ...], houses: int, out: Path, sweep: SweepOptions | None = None
) -> dict:
    """Run the benchmark; write rooms.json, rooms.md and rooms.csv; the JSON document."""
    sweep = sweep or SweepOptions()
    units = [(s, i) for s in styles for i in range(houses)]
    done = run_units(_house, units, workers=sweep.workers,
                     ray_address=sweep.ray_address, desc="bench rooms")  # fmt: skip
    rows = [r for unit_rows in done for r in unit_rows]
    doc = {
        "fully_seen": FULLY_SEEN,
        "iou_goal": IOU_GOAL,
        "styles": {s: summary([r for r in rows if r["style"] == s]) for s in styles},
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "rooms.json").write_text(json.dumps(doc, indent=1) + "\n")
    (out / "rooms.md").write_text(markdown(doc))
    write_csv(out / "rooms.csv", COLUMNS, rows)
    return doc


def markdown(doc: dict) -> str:
    """rooms.md: one line per style."""
    lines = [
        "# The robot's rooms against the plans",
        "",
        f"IoU of each plan room with its segment, over the rooms the robot's map holds at least "
        f"{doc['fully_seen']:.0%} of (fully seen); goal {doc['iou_goal']}.",
        "",
        "| style | houses | rooms | fully seen | IoU median | IoU least | share >= goal | "
        "houses with one segment per room | exploration s (median) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for s, d in doc["styles"].items():
        lines.append(
            f"| {s} | {d['houses']} | {d['rooms']} | {d['fully_seen']} | {d['iou_median']:.3f} | "
            f"{d['iou_min']:.3f} | {d['share_iou_goal']:.3f} | "
            f"{d['houses_with_one_segment_per_room']} | {d['explore_sim_s_median']:.0f} |"
        )
    return "\n".join(lines) + "\n"
