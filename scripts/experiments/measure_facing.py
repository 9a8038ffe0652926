"""Camera-mode examinations against the oracle, with and without the open-side preference.

For every examination of a camera-mode ``learn`` run (hif, office rooms), the (relation, type)
pairs the camera found are compared with the pairs the true layout holds for the same object:
recall (share of the oracle's pairs found), precision, pairs per examination, and simulated
seconds per examination. Its tables are in results/learning_budget/facing.md. Run from the
repository root:

    MUJOCO_GL=egl .venv/bin/python -m scripts.experiments.measure_facing [ROOMS] [SEED]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import agent.acquisition as acq
from envs.houses import generate_layout, resolve_style
from knowledge import geometry
from knowledge.catalog import load_catalog


def measure(facing: bool, rooms: int, seed: int) -> dict[str, float]:
    """Totals over one camera-mode run with EXAMINE_FACING set to ``facing``."""
    acq.EXAMINE_FACING = facing
    cat = load_catalog()
    style = resolve_style("office", cat)
    layouts: dict[int, object] = {}

    def gen(i, s):
        layouts[s] = generate_layout(style, s, cat)
        return layouts[s]

    tot = {"exams": 0, "cam": 0, "orc": 0, "both": 0, "sim_s": 0.0, "gazes": 0}

    def on_exam(res, kb):
        obj = res.choice.obj
        orc = geometry.related_pairs(geometry.related(cat, obj, layouts[res.room_seed].objects))
        cam = res.pairs
        tot["exams"] += 1
        tot["cam"] += len(cam)
        tot["orc"] += len(orc)
        tot["both"] += len(cam & orc)
        tot["gazes"] += res.gazes

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        s = acq.learn(
            style.name,
            rooms,
            Path(tmp) / "kb.sqlite",
            strategy="hif",
            perception="camera",
            seed=seed,
            progress=False,
            catalog=cat,
            layouts=gen,
            on_examination=on_exam,
        )
        tot["wall_s"] = time.perf_counter() - t0
        tot["sim_s"] = s.sim_s
    return tot


def main() -> None:
    """Print the table of facing off and on for ROOMS rooms (default 3) and SEED (default 0)."""
    rooms = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    print(f"office, {rooms} rooms, seed {seed}, hif, camera perception")
    print(
        "| facing | exams | pairs/exam camera | pairs/exam oracle | recall | precision "
        "| gazes/exam | sim s/exam | exams/wall s |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for facing in (False, True):
        t = measure(facing, rooms, seed)
        n = t["exams"]
        print(
            f"| {'on' if facing else 'off'} | {n} | {t['cam'] / n:.3f} | {t['orc'] / n:.3f} | "
            f"{t['both'] / max(t['orc'], 1):.3f} | {t['both'] / max(t['cam'], 1):.3f} | "
            f"{t['gazes'] / n:.2f} | {t['sim_s'] / n:.2f} | {n / t['wall_s']:.1f} |"
        )


if __name__ == "__main__":
    main()
