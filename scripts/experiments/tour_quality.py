"""What the robot's tour keeps of a house, against the plan: per house, the furniture it
recognised of the plan's, the phantoms (remembered furniture no plan piece has the id of), the
look-alikes (a plan piece remembered under another type), the misses (plan furniture never
reported), the median position error, its rooms against the plan's, the images and simulated
seconds the tour took.

    python -m ctxsearch.scripts.experiments.tour_quality --style apartment --houses 3
    python -m ctxsearch.scripts.experiments.tour_quality --kb K   # the maps learning kept

The houses are generated with seeds ``--seed``, ``--seed`` + 1, ... on day 0 and toured as the
remembered map's search tours them (agent.search.tour, the search configuration's ``map``
defaults), with the detector preset named (default: realistic).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ctxsearch.agent.search.config import MapConfig
from ctxsearch.agent.search.runner import toured
from ctxsearch.envs.detector import load_detector
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.home_map import HomeMap
from ctxsearch.knowledge.store import EvidenceStore


def house_quality(style: str, seed: int, detector: str) -> dict:
    """The figures of one house's tour (module docstring)."""
    catalog = load_catalog()
    st = resolve_style(style, catalog)
    det = load_detector(detector, catalog)
    layout = generate_layout(st, seed, catalog)
    home, seconds = toured(layout, catalog, det, MapConfig(), 0, cached=False)
    return map_quality(home, layout, catalog, seconds)


def store_quality(kb: Path) -> list[dict]:
    """The figures of every remembered map a knowledge store holds (learning's), against the
    plans of their worlds on their days."""
    catalog = load_catalog()
    out = []
    with EvidenceStore.open(kb, catalog, read_only=True) as store:
        for run, style, seed, day in store.home_maps():
            home = store.home_map(style, seed, run=run, upto_day=day)
            layout = generate_layout(resolve_style(style, catalog), seed, catalog, day=day)
            out.append(map_quality(home, layout, catalog, None))
    return out


def map_quality(home: HomeMap, layout: RoomLayout, catalog: Catalog, seconds) -> dict:
    """One remembered map against its world's plan (module docstring)."""
    true = {o.id: o for o in layout.objects if catalog.type(o.type).is_furniture}
    got = {o.id: o for o in home.furniture}
    err = [float(np.hypot(*(np.array(o.position[:2]) - true[i].position[:2])))
           for i, o in got.items() if i in true]  # fmt: skip
    return {
        "style": home.style, "seed": home.seed, "day": home.day,
        "furniture": len(true), "recognised": sum(1 for i in got if i in true),
        "phantoms": sum(1 for i in got if i not in true),
        "lookalikes": sum(1 for i, o in got.items() if i in true and true[i].type != o.type),
        "misses": sum(1 for i in true if i not in got),
        "position_error_m": float(np.median(err)) if err else None,
        "rooms": home.room_count(), "plan_rooms": len(layout.rooms),
        "images": home.images, "seconds": seconds,
    }  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--style", default="apartment", help="house style (default: apartment)")
    ap.add_argument("--houses", type=int, default=3, help="houses toured (default: 3)")
    ap.add_argument("--seed", type=int, default=1000, help="the first house's seed (default: 1000)")
    ap.add_argument("--detector", default="realistic", help="detector preset (default: realistic)")
    ap.add_argument(
        "--kb", type=Path, default=None,
        help="instead of touring: every remembered map this store's learning kept, and a total",
    )  # fmt: skip
    a = ap.parse_args(argv)
    try:
        if a.houses < 1:
            raise CtxsearchError(f"--houses must be at least 1 (got {a.houses})")
        if a.kb is not None:
            rows = store_quality(a.kb)
        else:
            rows = [house_quality(a.style, a.seed + k, a.detector) for k in range(a.houses)]
        for q in rows:
            print(_line(q))
        if a.kb is not None:
            tot = {k: sum(q[k] for q in rows) for k in ("furniture", "recognised", "phantoms",
                                                        "lookalikes", "misses")}  # fmt: skip
            same = sum(1 for q in rows if q["rooms"] == q["plan_rooms"])
            print(f"{len(rows)} maps: {tot['recognised']} of {tot['furniture']} furniture "
                  f"recognised, {tot['phantoms']} phantoms, {tot['lookalikes']} look-alikes, "
                  f"{tot['misses']} misses; the plan's room count in {same}")  # fmt: skip
    except CtxsearchError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


def _line(q: dict) -> str:
    err = q["position_error_m"]
    took = "" if q["seconds"] is None else f", {q['seconds']:.0f} simulated s"
    return (
        f"{q['style']} seed {q['seed']} day {q['day']}: recognised {q['recognised']} of "
        f"{q['furniture']} furniture, {q['phantoms']} phantoms, {q['lookalikes']} look-alikes, "
        f"{q['misses']} misses, median position error "
        f"{'-' if err is None else f'{err:.3f} m'}; {q['rooms']} rooms (plan "
        f"{q['plan_rooms']}); {q['images']} images{took}"
    )


if __name__ == "__main__":
    sys.exit(main())
