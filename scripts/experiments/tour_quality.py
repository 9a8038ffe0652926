"""What the robot's tour keeps of a house, against the plan: per house, the furniture it
recognised of the plan's, the phantoms (remembered furniture no plan piece has the id of), the
look-alikes (a plan piece remembered under another type), the misses (plan furniture never
reported), the median position error, its rooms against the plan's, the images and simulated
seconds the tour took.

    python -m ctxsearch.scripts.experiments.tour_quality --style apartment --houses 3

The houses are generated with seeds ``--seed``, ``--seed`` + 1, ... on day 0 and toured as the
remembered map's search tours them (agent.search.tour, the search configuration's ``map``
defaults), with the detector preset named (default: realistic).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ctxsearch.agent.search.config import MapConfig
from ctxsearch.agent.search.runner import toured
from ctxsearch.envs.detector import load_detector
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import resolve_style
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.errors import CtxsearchError


def house_quality(style: str, seed: int, detector: str) -> dict:
    """The figures of one house's tour (module docstring)."""
    catalog = load_catalog()
    st = resolve_style(style, catalog)
    det = load_detector(detector, catalog)
    layout = generate_layout(st, seed, catalog)
    home, seconds = toured(layout, catalog, det, MapConfig(), 0, cached=False)
    true = {o.id: o for o in layout.objects if catalog.type(o.type).is_furniture}
    got = {o.id: o for o in home.furniture}
    err = [float(np.hypot(*(np.array(o.position[:2]) - true[i].position[:2])))
           for i, o in got.items() if i in true]  # fmt: skip
    return {
        "seed": seed, "furniture": len(true), "recognised": len(got),
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
    a = ap.parse_args(argv)
    try:
        if a.houses < 1:
            raise CtxsearchError(f"--houses must be at least 1 (got {a.houses})")
        for k in range(a.houses):
            q = house_quality(a.style, a.seed + k, a.detector)
            print(
                f"{a.style} seed {q['seed']}: recognised {q['recognised']} of {q['furniture']} "
                f"furniture, {q['phantoms']} phantoms, {q['lookalikes']} look-alikes, "
                f"{q['misses']} misses, median position error {q['position_error_m']:.3f} m; "
                f"{q['rooms']} rooms (plan {q['plan_rooms']}); {q['images']} images, "
                f"{q['seconds']:.0f} simulated s"
            )
    except CtxsearchError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
