"""The robot's remembered map beside the plan (``ctxsearch room --remembered``).

The robot tours the world on day 0 as the remembered map's search tours a held-out house
(agent.search.tour: its own built map, the detector preset of the command, the search
configuration's tour budget). Written: ``remembered.png`` (left: the plan, its walls dark, its furniture
filled grey and each piece the tour missed outlined red; right: the robot's map, floor light, occupied
dark, unknown black, its rooms' borders, each remembered piece's footprint coloured by its best
confidence from red (0) to green (1), a look-alike (remembered under another type than the
plan's) labelled with the type it was remembered as, a phantom (no plan piece has its id)
crossed in magenta) and ``remembered.json`` (the counts: furniture, recognised, misses,
look-alikes, phantoms; the rooms against the plan's; the tour's images and simulated seconds).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from ctxsearch.agent.room_segmentation import wall_mask
from ctxsearch.agent.search.config import MapConfig
from ctxsearch.agent.search.remembered import confidence_color
from ctxsearch.agent.search.runner import toured
from ctxsearch.envs.detector import DetectorModel
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.home_map import HomeMap

PIXELS_PER_CELL = 3  # each 5 cm cell drawn as a 3 x 3 block


def _corners(o: ObjectInstance) -> np.ndarray:
    """(4, 2) footprint corners of ``o`` in metres."""
    c, s = np.cos(o.yaw), np.sin(o.yaw)
    hx, hy = o.size[0] / 2, o.size[1] / 2
    local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
    return local @ np.array([[c, s], [-s, c]]) + np.asarray(o.position[:2])


def _px(home: HomeMap, xy: np.ndarray) -> np.ndarray:
    """Pixel coordinates (north up) of points in metres."""
    h = home.shape[0]
    col = (np.asarray(xy)[:, 0] - home.x0) / home.resolution
    row = h - (np.asarray(xy)[:, 1] - home.y0) / home.resolution
    return np.round(np.column_stack([col, row]) * PIXELS_PER_CELL).astype(np.int32)


def _bgr(rgb) -> tuple[int, int, int]:
    r, g, b = (int(255 * v) for v in rgb)
    return (b, g, r)


def draw(home: HomeMap, layout: RoomLayout, catalog: Catalog) -> tuple[np.ndarray, dict]:
    """remembered.png and its counts (module docstring)."""
    true = {o.id: o for o in layout.objects if catalog.type(o.type).is_furniture}
    got = {o.id: o for o in home.furniture}
    base = np.full((*home.shape, 3), 0, np.uint8)
    base[home.floor] = (235, 235, 235)
    base[home.occupied] = (90, 90, 90)
    edges = np.zeros(home.shape, bool)
    r = home.rooms
    edges[1:] |= (r[1:] != r[:-1]) & (r[1:] >= 0) & (r[:-1] >= 0)
    edges[:, 1:] |= (r[:, 1:] != r[:, :-1]) & (r[:, 1:] >= 0) & (r[:, :-1] >= 0)
    base[edges] = (200, 120, 40)
    big = np.kron(base[::-1], np.ones((PIXELS_PER_CELL, PIXELS_PER_CELL, 1), np.uint8))
    plan = np.full((*home.shape, 3), 255, np.uint8)
    walls = ~wall_mask(layout, home.resolution).free
    if walls.shape == home.shape:
        plan[walls] = (60, 60, 60)
    plan = np.kron(plan[::-1], np.ones((PIXELS_PER_CELL, PIXELS_PER_CELL, 1), np.uint8))
    for o in true.values():
        pts = _px(home, _corners(o))
        cv2.fillPoly(plan, [pts], (170, 170, 170))
        if o.id not in got:
            cv2.polylines(plan, [pts], True, (0, 0, 230), 2)
    robot = big.copy()
    for o in got.values():
        pts = _px(home, _corners(o.instance()))
        cv2.polylines(robot, [pts], True, _bgr(confidence_color(o.confidence)), 2)
        at = tuple(int(v) for v in pts.mean(axis=0))
        if o.id not in true:
            cv2.drawMarker(robot, at, (255, 0, 255), cv2.MARKER_TILTED_CROSS, 14, 2)
        elif true[o.id].type != o.type:
            cv2.putText(robot, f"{o.type}?", at, cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 0, 255), 1)
    gap = np.full((big.shape[0], 8, 3), 255, np.uint8)
    img = np.concatenate([plan, gap, robot], axis=1)
    head = np.full((28, img.shape[1], 3), 255, np.uint8)
    font = cv2.FONT_HERSHEY_SIMPLEX
    cv2.putText(head, "plan (red: missed)", (6, 20), font, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
    u = plan.shape[1] + 14
    cv2.putText(head, "the robot's remembered map (by confidence)", (u, 20), font, 0.6,
                (0, 0, 0), 1, cv2.LINE_AA)  # fmt: skip
    counts = {
        "furniture": len(true), "recognised": sum(1 for i in got if i in true),
        "misses": sum(1 for i in true if i not in got),
        "lookalikes": sum(1 for i, o in got.items() if i in true and true[i].type != o.type),
        "phantoms": sum(1 for i in got if i not in true),
        "rooms": home.room_count(), "plan_rooms": len(layout.rooms), "images": home.images,
    }  # fmt: skip
    return np.concatenate([head, img], axis=0), counts


def write_remembered(
    layout: RoomLayout, catalog: Catalog, detector: DetectorModel, out: Path
) -> list[Path]:
    """Tour the world on day 0, write remembered.png and remembered.json into ``out``; print
    one line."""
    home, seconds = toured(layout, catalog, detector, MapConfig(), 0, cached=False)
    img, counts = draw(home, layout, catalog)
    png, js = out / "remembered.png", out / "remembered.json"
    cv2.imwrite(str(png), img)
    js.write_text(json.dumps({**counts, "tour_sim_s": seconds}, indent=1) + "\n")
    print(f"the robot's remembered map: {counts['recognised']} of {counts['furniture']} "
          f"furniture recognised, {counts['misses']} missed, {counts['lookalikes']} look-alikes, "
          f"{counts['phantoms']} phantoms; {counts['rooms']} rooms (plan {counts['plan_rooms']}); "
          f"tour {seconds:.0f} simulated s, {counts['images']} images")  # fmt: skip
    return [png, js]
