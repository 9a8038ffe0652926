"""``ctxsearch bench sim``: how fast the simulated world is (medians over rooms and gazes).

- layouts per second: ``generate_room`` alone (pure data);
- build + compile ms per room: a fresh ``RoomTask`` (arena, robot), the room's MJCF
  (``initialize_episode_mjcf``) and ``mjcf.Physics.from_mjcf_model``; also the per-episode part
  alone (room MJCF + compile, the robot and arena reused) and a whole ``World`` (no renderer);
- gazes per second at the World's image size: ``move_head`` (servos stepped in MuJoCo),
  ``capture`` (segmentation + depth) and ``agent.perception.detect``;
- the same images with a bare ``mujoco.Renderer`` on the same model and scene options: head
  joints written to qpos, ``mj_forward``, a segmentation render and a depth render. The overhead
  ratio is our gaze time over that bare time.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco/dm_control are first imported

import json
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import mujoco
import numpy as np
from dm_control import mjcf

from envs.houses import generate_layout, resolve_style
from envs.layout import RoomLayout
from envs.task import RoomTask, start_pose
from envs.world import World, gl_renderer
from knowledge.catalog import Catalog, load_catalog

TARGETS = {"compile_ms": 150.0, "gazes_per_s": 60.0, "overhead_ratio": 1.3}
WARMUP_GAZES = 5


def _ms(f: Callable[[], object]) -> tuple[float, object]:
    t = time.perf_counter()
    out = f()
    return (time.perf_counter() - t) * 1e3, out


def _build_and_compile(layout: RoomLayout, catalog: Catalog) -> mjcf.Physics:
    task = RoomTask(catalog, layout=layout)
    task.initialize_episode_mjcf(np.random.RandomState(0))
    return mjcf.Physics.from_mjcf_model(task.root_entity.mjcf_model)


def _gaze_targets(rng: np.random.Generator, n: int, world: World) -> np.ndarray:
    pan = rng.uniform(*world.spec.pan_range, n)
    tilt = rng.uniform(-0.9, 0.2, n)  # where gazes at furniture and objects go
    return np.column_stack([pan, tilt])


def _bare_gaze_ms(world: World, targets: np.ndarray) -> list[float]:
    """Per-target ms of the naive way to the same images: qpos, forward, seg render, depth render."""
    m, d = world.physics.model.ptr, world.physics.data.ptr
    qadr = world._qadr[3:]
    option, cam = world._head_option, world._cam_id
    times = []
    with mujoco.Renderer(m, height=world.height, width=world.width) as r:
        for k, (pan, tilt) in enumerate(np.vstack([targets[:WARMUP_GAZES], targets])):
            t = time.perf_counter()
            d.qpos[qadr] = pan, tilt
            mujoco.mj_forward(m, d)
            r.update_scene(d, cam, option)
            r.enable_segmentation_rendering()
            r.render()
            r.enable_depth_rendering()
            r.render()
            if k >= WARMUP_GAZES:
                times.append((time.perf_counter() - t) * 1e3)
    return times


def run(
    out_dir: Path,
    *,
    rooms: int = 5,
    gazes: int = 100,
    style: str = "office",
    seed: int = 0,
    width: int = 320,
    height: int = 240,
) -> dict:
    """Run the benchmark, write ``bench_sim.json`` and ``bench_sim.md`` to ``out_dir``, and return
    the results."""
    from agent.perception import detect

    load_before = os.getloadavg()[0]
    catalog = load_catalog()
    style_obj = resolve_style(style, catalog)
    n_layouts = max(20, rooms)
    gen_ms, layouts = [], []
    for s in range(seed, seed + n_layouts):
        ms, lay = _ms(lambda s=s: generate_layout(style_obj, s, catalog))
        gen_ms.append(ms)
        layouts.append(lay)
    layouts = layouts[:rooms]

    compile_ms, episode_ms, world_ms, renderer_ms = [], [], [], []
    move_ms, capture_ms, detect_ms, gaze_ms, bare_ms = [], [], [], [], []
    n_geoms, n_objects = [], []
    episode_task = RoomTask(catalog, layout=layouts[0])
    rng = np.random.default_rng(seed)
    for lay in layouts:
        compile_ms.append(_ms(lambda lay=lay: _build_and_compile(lay, catalog))[0])
        episode_task.set_layout(lay)  # the per-episode path: same task, a new room
        episode_ms.append(
            _ms(
                lambda: (
                    episode_task.initialize_episode_mjcf(None),
                    mjcf.Physics.from_mjcf_model(episode_task.root_entity.mjcf_model),
                )
            )[0]
        )
        ms, world = _ms(lambda lay=lay: World(lay, catalog, width=width, height=height))
        world_ms.append(ms)
        with world:
            n_geoms.append(world.physics.model.ngeom)
            n_objects.append(len(lay.objects))
            world.reset_pose(start_pose(lay))
            renderer_ms.append(_ms(lambda world=world: world._renderer(width, height))[0])
            targets = _gaze_targets(rng, gazes, world)
            for k, (pan, tilt) in enumerate(np.vstack([targets[:WARMUP_GAZES], targets])):
                t0 = time.perf_counter()
                world.move_head(pan, tilt)
                t1 = time.perf_counter()
                frame = world.capture(depth=True)
                t2 = time.perf_counter()
                detect(frame, lay, catalog)
                t3 = time.perf_counter()
                if k >= WARMUP_GAZES:
                    move_ms.append((t1 - t0) * 1e3)
                    capture_ms.append((t2 - t1) * 1e3)
                    detect_ms.append((t3 - t2) * 1e3)
                    gaze_ms.append((t3 - t0) * 1e3)
            bare_ms.extend(_bare_gaze_ms(world, targets))

    med = statistics.median
    results = {
        "layouts_per_s": 1e3 / med(gen_ms),
        "compile_ms": med(compile_ms),
        "gazes_per_s": 1e3 / med(gaze_ms),
        "overhead_ratio": med(gaze_ms) / med(bare_ms),
        "episode_compile_ms": med(episode_ms),
        "world_ms": med(world_ms),
        "renderer_init_ms": med(renderer_ms),
        "gaze_ms": med(gaze_ms),
        "move_head_ms": med(move_ms),
        "capture_ms": med(capture_ms),
        "detect_ms": med(detect_ms),
        "bare_render_ms": med(bare_ms),
        "detector": "agent.perception.detect",
        "style": style,
        "rooms": len(layouts),
        "layouts_timed": n_layouts,
        "gazes_per_room": gazes,
        "width": width,
        "height": height,
        "median_geoms": med(n_geoms),
        "median_objects": med(n_objects),
        "gl_renderer": gl_renderer(),
        "cpu_count": os.cpu_count(),
        "load_avg_1min": [round(load_before, 2), round(os.getloadavg()[0], 2)],  # before, after
        "machine": platform.machine(),
        "targets": TARGETS,
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "bench_sim.json").write_text(json.dumps(results, indent=2) + "\n")
    table = format_table(results)
    (out_dir / "bench_sim.md").write_text(
        f"# bench sim\n\n{len(layouts)} '{style}' rooms, {gazes} gazes each at {width}x{height}; "
        f"renderer: {results['gl_renderer']}; {results['cpu_count']} CPUs, 1-minute load average "
        f"{results['load_avg_1min'][0]} before and {results['load_avg_1min'][1]} after. Medians. "
        "A gaze is move_head (servos stepped in MuJoCo) + capture (one draw for segmentation and "
        "depth) + detect; the bare renderer needs two draws for the same images, so the ratio "
        f"can fall below 1.\n\n{table}\n\n![time per gaze](bench_sim.png)\n"
    )
    write_plot(results, out_dir / "bench_sim.png")
    return results


def write_plot(r: dict, path: Path) -> None:
    """A bar plot of one gaze's time, by part, against the bare renderer's, and the build time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(9, 3.6), gridspec_kw={"width_ratios": [3, 2]})
    parts = [
        ("move_head", r["move_head_ms"]),
        ("capture", r["capture_ms"]),
        ("detect", r["detect_ms"]),
    ]
    left = 0.0
    for (name, ms), color in zip(parts, ("#8c8c8c", "#1f77b4", "#ff7f0e"), strict=True):
        ax.barh("ours: one gaze", ms, left=left, color=color, label=name)
        left += ms
    ax.barh(
        "bare mujoco.Renderer\n(seg + depth)",
        r["bare_render_ms"],
        color="#2ca02c",
        label="bare render",
    )
    ax.set_xlabel("ms (median)")
    ax.set_title(f"{r['gazes_per_s']:.0f} gazes/s, overhead ratio {r['overhead_ratio']:.2f}")
    ax.legend(fontsize=8, loc="lower right")
    bx.bar(
        ["build + compile", "per episode"],
        [r["compile_ms"], r["episode_compile_ms"]],
        color="#9467bd",
    )
    bx.axhline(r["targets"]["compile_ms"], color="k", ls="--", lw=1, label="target")
    bx.set_ylabel("ms per room (median)")
    bx.legend(fontsize=8)
    fig.suptitle(
        f"bench sim: {r['rooms']} {r['style']} rooms, {r['width']}x{r['height']}, {r['gl_renderer']}",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def format_table(r: dict) -> str:
    """The results as a Markdown table, with the targets."""
    t = r["targets"]
    rows = [
        ("layouts per second (generate_room)", f"{r['layouts_per_s']:.1f}", ""),
        ("build + compile per room (ms)", f"{r['compile_ms']:.1f}", f"< {t['compile_ms']:.0f}"),
        ("  per episode, robot and arena reused (ms)", f"{r['episode_compile_ms']:.1f}", ""),
        ("  whole World, no renderer (ms)", f"{r['world_ms']:.1f}", ""),
        ("  renderer creation (ms)", f"{r['renderer_init_ms']:.1f}", ""),
        (
            f"gazes per second ({r['width']}x{r['height']})",
            f"{r['gazes_per_s']:.1f}",
            f">= {t['gazes_per_s']:.0f}",
        ),
        ("  move_head (ms)", f"{r['move_head_ms']:.2f}", ""),
        ("  capture: segmentation + depth (ms)", f"{r['capture_ms']:.2f}", ""),
        ("  detect (ms)", f"{r['detect_ms']:.2f}", ""),
        ("bare mujoco.Renderer, seg + depth (ms)", f"{r['bare_render_ms']:.2f}", ""),
        ("overhead ratio (gaze / bare)", f"{r['overhead_ratio']:.2f}", f"<= {t['overhead_ratio']}"),
    ]
    lines = ["| measure | value | target |", "| --- | ---: | ---: |"]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in rows]
    return "\n".join(lines)
