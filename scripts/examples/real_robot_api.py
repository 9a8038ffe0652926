"""Use ctxsearch's knowledge layer from your own robot: no MuJoCo, no simulator.

    python scripts/examples/real_robot_api.py [--store PATH]

Given the same ``--store`` again, it resumes: the objects it examined before are not examined
again, so a second call records nothing new and prints the same intervals.

A robot with its own detector (here: a few hand-written detections standing in for it) does what
Figure 2 of the paper does, with the same code the simulated robot uses:

1. a catalog: object types and their relation volumes (normally a TOML file, ``load_catalog``);
2. Highest Impact First chooses which detected object to examine next (``KnowledgeBase.choose``);
3. an examination: the objects detected in the examined object's relation volumes decide which
   relations hold (``knowledge.geometry.related``: the paper's rel(obj, b)); it is recorded in
   the SQLite evidence store in one transaction (``EvidenceStore.record``);
4. the intervals INT(rel, B) are read back from the log (``EvidenceStore.knowledge_base``);
5. to find a target, the relation volumes of the objects the robot knows are ranked by the
   learned P(rel(T)) (``knowledge.ranking.candidate_volumes``): where to point the camera first.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from ctxsearch.knowledge.catalog import parse_catalog
from ctxsearch.knowledge.geometry import ObjectInstance, related
from ctxsearch.knowledge.ranking import KBProbabilities, candidate_volumes
from ctxsearch.knowledge.store import EvidenceStore

# 1. The catalog as a parsed TOML document (the format of assets/types.toml).
CATALOG = {
    "type": [
        {
            "name": "Table",
            "kind": "furniture",
            "shape": "table",
            "size": [[0.8, 1.0], [0.8, 1.6], [0.72, 0.76]],
            "color": [0.6, 0.5, 0.4],
            "min_pixels": 300,
            "max_range": 12.0,
            "relation": [
                {
                    "name": "ON-TOP-OF-TABLE",
                    "lo": [-0.5, -0.5, 0.5],
                    "hi": [0.5, 0.5, 0.5],
                    "margin_hi": [0.0, 0.0, 0.4],
                },
                {
                    "name": "NEAR-TABLE",
                    "lo": [-0.5, -0.5, -0.5],
                    "hi": [0.5, 0.5, 0.5],
                    "margin_lo": [-1.0, -1.0, 0.0],
                    "margin_hi": [1.0, 1.0, 0.5],
                },
            ],
        },
        {
            "name": "Mug",
            "kind": "object",
            "shape": "mug",
            "size": [0.09, 0.09, 0.1],
            "color": [0.9, 0.9, 0.9],
            "min_pixels": 20,
            "max_range": 4.0,
        },
        {
            "name": "Book",
            "kind": "object",
            "shape": "box",
            "size": [0.2, 0.15, 0.04],
            "color": [0.2, 0.3, 0.7],
            "min_pixels": 20,
            "max_range": 5.0,
        },
    ]
}


def table(i: int, x: float, y: float) -> ObjectInstance:
    """A detected table (its pose as your detector estimates it)."""
    return ObjectInstance("Table", i, (x, y, 0.37), 0.0, (0.9, 1.2, 0.74))


def on_table(kind: str, i: int, t: ObjectInstance, dx: float) -> ObjectInstance:
    """A detected small object standing on table ``t``."""
    size = (0.09, 0.09, 0.1) if kind == "Mug" else (0.2, 0.15, 0.04)
    return ObjectInstance(
        kind, i, (t.position[0] + dx, t.position[1], 0.74 + size[2] / 2), 0.0, size
    )


# What the robot's detector reported in three rooms (ids are unique within a room).
ROOMS = {
    101: [table(1, 0, 0), on_table("Mug", 2, table(1, 0, 0), 0.2)],
    102: [
        table(1, 3, 1),
        on_table("Mug", 2, table(1, 3, 1), -0.1),
        on_table("Book", 3, table(1, 3, 1), 0.2),
    ],
    103: [table(1, 0, 2), ObjectInstance("Mug", 2, (2.0, 2.0, 0.05), 0.0, (0.09, 0.09, 0.1))],
}


def main(argv: list[str] | None = None) -> int:
    """Learn from the detections of ROOMS into a store, print intervals and a search ranking."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--store", type=Path, help="evidence store (default: a temporary file)")
    args = ap.parse_args(argv)
    catalog = parse_catalog(CATALOG, "<example catalog>")
    with tempfile.TemporaryDirectory() as tmp:
        path = args.store or Path(tmp) / "robot.sqlite"
        with EvidenceStore.open(path, catalog) as store:
            for room, detections in ROOMS.items():
                # Run again on the same store, it resumes: what this run examined is not again
                # (the store's key, one examination per run, room and object, would refuse it).
                examined = store.examined("my-robot", "lab", room)
                if examined:
                    print(f"room {room}: {len(examined)} objects examined by an earlier call")
                while True:
                    kb = store.knowledge_base()
                    unexamined = [o for o in detections if o.id not in examined]
                    if not unexamined:
                        break
                    # 2. Highest Impact First (Figure 2, lines 8-13): the type, then an object.
                    ref_type = kb.choose(sorted({o.type for o in unexamined}))
                    obj = next(o for o in unexamined if o.type == ref_type)
                    examined.add(obj.id)
                    # 3. rel(i, obj) for the objects detected around it (lines 15-16), recorded.
                    found = related(catalog, obj, detections)
                    store.record(
                        run="my-robot",
                        style="lab",
                        room_seed=room,
                        object_id=obj.id,
                        ref_type=ref_type,
                        sim_time=0.0,
                        strategy="hif",
                        related=[(rel, o.type, o.id) for rel, o in found],
                    )
                    print(
                        f"room {room}: examined {ref_type} #{obj.id}: "
                        + (
                            ", ".join(sorted({f"{r}({o.type})" for r, o in found}))
                            or "nothing related"
                        )
                    )
            # 4. The intervals, from the log.
            kb = store.knowledge_base()
            print(f"\n{kb.n('Table')} tables examined; 90% intervals of ON-TOP-OF-TABLE:")
            for row in kb.rows("Table"):
                if row.relation == "ON-TOP-OF-TABLE":
                    print(
                        f"  P(ON-TOP-OF-TABLE({row.type})) in [{row.low:.2f}, {row.high:.2f}]  (y={row.y}, n={row.n})"
                    )
            # 5. Where to look for a Mug in a new room where the robot has seen two tables.
            known = [table(1, 5.0, 0.0), table(2, 8.0, 3.0)]
            print("\nwhere to look for a Mug, best first:")
            for c in candidate_volumes(known, "Mug", catalog, KBProbabilities(kb, rank="low")):
                x, y, z = c.box.center
                print(
                    f"  {c.relation} #{c.ref_id}: p >= {c.p:.2f}, volume centred at ({x:.2f}, {y:.2f}, {z:.2f})"
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
