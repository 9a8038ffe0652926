"""``ctxsearch bench sim``: how fast the simulated world is (medians over rooms and gazes).

- layouts per second: ``generate_room`` alone (pure data);
- build + compile ms per room: a fresh ``RoomTask`` (arena, robot), the room's MJCF
  (``initialize_episode_mjcf``) and ``mjcf.Physics.from_mjcf_model``; also the per-episode part
  alone (room MJCF + compile, the robot and arena reused) and a whole ``World`` (no renderer);
- a world's build (generate the layout, its MJCF, compile), four ways: through the composer task
  as above (``world_build_composer_ms``), the way a World makes it with nothing kept
  (``world_build_cold_ms``: ``envs.world_store``, memory emptied, no cache on disk), as a later
  process does (``world_build_disk_ms``: memory emptied, the model's XML read from the cache
  directory) and as the same process does again (``world_build_cached_ms``: the layout and the
  compiled model kept in memory; a World copies the model);
- gazes per second at the World's image size: ``move_head`` (servos stepped in MuJoCo),
  ``capture`` (segmentation + depth) and ``envs.detector.detect``;
- the same images with a bare ``mujoco.Renderer`` on the same model and scene options: head
  joints written to qpos, ``mj_forward``, a segmentation render and a depth render. The overhead
  ratio is our gaze time over that bare time.

``bench_sim.csv`` holds every timed gaze, one row each, with its room's build figures
(``GAZE_COLUMNS``).
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco/dm_control are first imported

import json
import platform
import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np
from dm_control import mjcf
from matplotlib.figure import Figure

from ctxsearch.envs import world_store
from ctxsearch.envs.detector import detect
from ctxsearch.envs.floorplan import forget_layouts, generate_layout
from ctxsearch.envs.houses import WorldStyle, resolve_style
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.envs.task import RoomTask, start_pose
from ctxsearch.envs.world import World, gl_renderer
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.scripts.experiments.bench_map import explore_results
from ctxsearch.scripts.experiments.tables import write_csv

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
        for k, (pan, tilt) in enumerate(np.vstack([_warmup(targets), targets])):
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


def _warmup(targets: np.ndarray) -> np.ndarray:
    """The WARMUP_GAZES untimed gazes before the timed ones: the first targets (repeated when
    there are fewer: ``--gazes 3`` is timed on its 3 gazes, not on fewer)."""
    return targets[np.arange(WARMUP_GAZES) % len(targets)]


@dataclass
class _Times:
    """Per-sample milliseconds and sizes, gathered over the rooms."""

    compile: list[float] = field(default_factory=list)
    builds: dict[str, list[float]] = field(default_factory=dict)  # world_build_*_ms per room
    episode: list[float] = field(default_factory=list)
    world: list[float] = field(default_factory=list)
    renderer: list[float] = field(default_factory=list)
    move: list[float] = field(default_factory=list)
    capture: list[float] = field(default_factory=list)
    detect: list[float] = field(default_factory=list)
    gaze: list[float] = field(default_factory=list)
    bare: list[float] = field(default_factory=list)
    geoms: list[int] = field(default_factory=list)
    objects: list[int] = field(default_factory=list)
    room_seeds: list[int] = field(default_factory=list)
    targets: list[np.ndarray] = field(default_factory=list)  # (gazes, 2) pan, tilt per room


def run(
    out_dir: Path,
    *,
    rooms: int = 5,
    gazes: int = 100,
    style: str = "office",
    seed: int = 0,
    size: tuple[int, int] = (320, 240),
    explore: int = 1,
    frontier_rule: str = "info",
) -> dict:
    """Run the benchmark, write ``bench_sim.json``, ``bench_sim.csv``, ``bench_sim.md`` and
    ``bench_sim.png`` to ``out_dir``, and return the results (``size``: the head camera's width
    and height). The first ``explore`` worlds are also explored fully with the robot's own map
    (scripts.experiments.bench_map; ``map_overview.png``)."""
    width, height = size
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
    times = _Times()
    episode_task = RoomTask(catalog, layout=layouts[0])
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory(prefix="ctxsearch-bench-sim-") as tmp:
        for lay in layouts:
            _time_world_builds(times, style_obj, lay.seed, catalog, Path(tmp))
    for lay in layouts:
        _time_builds(times, lay, catalog, episode_task)
        ms, world = _ms(lambda lay=lay: World(lay, catalog, width=width, height=height))
        times.world.append(ms)
        with world:
            targets = _gaze_targets(rng, gazes, world)
            times.room_seeds.append(int(lay.seed))
            times.targets.append(targets)
            _time_gazes(times, world, lay, catalog, targets)
    results = _results(times, gen_ms)
    if explore:
        out_dir.mkdir(parents=True, exist_ok=True)
        results.update(explore_results(layouts[:explore], catalog, out_dir, width=width,
                                       height=height, rule=frontier_rule))  # fmt: skip
    results.update(
        {
            "style": style,
            "rooms": len(layouts),
            "layouts_timed": n_layouts,
            "gazes_per_room": gazes,
            "width": width,
            "height": height,
            "median_geoms": statistics.median(times.geoms),
            "median_objects": statistics.median(times.objects),
            "gl_renderer": gl_renderer(),
            "cpu_count": os.cpu_count(),
            "load_avg_1min": [round(load_before, 2), round(os.getloadavg()[0], 2)],  # before, after
            "machine": platform.machine(),
            "targets": TARGETS,
        }
    )
    _write(results, out_dir)
    write_csv(out_dir / "bench_sim.csv", GAZE_COLUMNS, gaze_rows(times, style, gazes))
    return results


# bench_sim.csv: one row per timed gaze, with its room's build figures (the JSON's medians are
# over these rows, and over the rooms for the build columns).
GAZE_COLUMNS = (
    "style",
    "room",  # 0-based index of the room
    "room_seed",
    "geoms",
    "objects",
    "compile_ms",  # the room's fresh build + MJCF compile
    "episode_compile_ms",  # the same room as a new episode of one task
    "world_ms",
    "renderer_init_ms",
    "gaze",  # 0-based index of the gaze in its room
    "pan_rad",
    "tilt_rad",
    "move_head_ms",
    "capture_ms",
    "detect_ms",
    "gaze_ms",
    "bare_render_ms",  # the bare mujoco.Renderer's two draws for the same gaze
)


def gaze_rows(times: _Times, style: str, gazes: int):
    """The rows of bench_sim.csv (``GAZE_COLUMNS``), room by room, gaze by gaze."""
    for i, (seed, targets) in enumerate(zip(times.room_seeds, times.targets, strict=True)):
        room = {
            "style": style,
            "room": i,
            "room_seed": seed,
            "geoms": times.geoms[i],
            "objects": times.objects[i],
            "compile_ms": times.compile[i],
            "episode_compile_ms": times.episode[i],
            "world_ms": times.world[i],
            "renderer_init_ms": times.renderer[i],
        }
        for g in range(gazes):
            k = i * gazes + g
            yield {
                **room,
                "gaze": g,
                "pan_rad": float(targets[g, 0]),
                "tilt_rad": float(targets[g, 1]),
                "move_head_ms": times.move[k],
                "capture_ms": times.capture[k],
                "detect_ms": times.detect[k],
                "gaze_ms": times.gaze[k],
                "bare_render_ms": times.bare[k],
            }


def _time_builds(times: _Times, lay: RoomLayout, catalog: Catalog, episode_task: RoomTask) -> None:
    """A fresh build + compile of room ``lay``, and the per-episode path (same task, new room)."""
    times.compile.append(_ms(lambda: _build_and_compile(lay, catalog))[0])
    episode_task.set_layout(lay)
    times.episode.append(
        _ms(
            lambda: (
                episode_task.initialize_episode_mjcf(None),
                mjcf.Physics.from_mjcf_model(episode_task.root_entity.mjcf_model),
            )
        )[0]
    )


def _time_world_builds(
    times: _Times, style: WorldStyle, seed: int, catalog: Catalog, cache: Path
) -> None:
    """World ``seed``'s build (layout, MJCF, compiled model) the four ways of the module
    docstring; the process's memory of layouts and worlds is emptied first (and after)."""

    def built(disk: bool, composer: bool = False) -> None:
        lay = generate_layout(style, seed, catalog)
        if composer:
            _build_and_compile(lay, catalog)
        else:
            world_store.world_model(lay, catalog, RobotSpec(), disk=disk, directory=cache)

    def forget() -> None:
        forget_layouts()
        world_store.forget()

    steps = (
        ("composer", lambda: built(False, composer=True)),
        ("cold", lambda: built(False)),
        ("disk", lambda: built(True)),  # a miss: built and written
        ("disk", lambda: built(True)),  # read back from the file
        ("cached", lambda: built(True)),  # kept in memory
    )
    for k, (name, step) in enumerate(steps):
        if name != "cached":
            forget()
        ms = _ms(step)[0]
        if k != 2:
            times.builds.setdefault(name, []).append(ms)
    forget()


def _time_gazes(
    times: _Times, world: World, lay: RoomLayout, catalog: Catalog, targets: np.ndarray
) -> None:
    """Gazes at ``targets`` (move, capture, detect) in ``world``, then the bare renderer's."""
    times.geoms.append(world.physics.model.ngeom)
    times.objects.append(len(lay.objects))
    world.reset_pose(start_pose(lay))
    times.renderer.append(_ms(lambda: world._renderer(world.width, world.height))[0])
    for k, (pan, tilt) in enumerate(np.vstack([_warmup(targets), targets])):
        t0 = time.perf_counter()
        world.move_head(pan, tilt)
        t1 = time.perf_counter()
        frame = world.capture(depth=True)
        t2 = time.perf_counter()
        detect(frame, lay, catalog)
        t3 = time.perf_counter()
        if k >= WARMUP_GAZES:
            times.move.append((t1 - t0) * 1e3)
            times.capture.append((t2 - t1) * 1e3)
            times.detect.append((t3 - t2) * 1e3)
            times.gaze.append((t3 - t0) * 1e3)
    times.bare.extend(_bare_gaze_ms(world, targets))


def _results(times: _Times, gen_ms: list[float]) -> dict:
    """The medians (and the rates and ratio derived from them)."""
    med = statistics.median
    return {
        "layouts_per_s": 1e3 / med(gen_ms),
        "compile_ms": med(times.compile),
        **{f"world_build_{k}_ms": med(v) for k, v in times.builds.items()},
        "world_build_speedup": med(times.builds["composer"]) / med(times.builds["cached"]),
        "gazes_per_s": 1e3 / med(times.gaze),
        "overhead_ratio": med(times.gaze) / med(times.bare),
        "episode_compile_ms": med(times.episode),
        "world_ms": med(times.world),
        "renderer_init_ms": med(times.renderer),
        "gaze_ms": med(times.gaze),
        "move_head_ms": med(times.move),
        "capture_ms": med(times.capture),
        "detect_ms": med(times.detect),
        "bare_render_ms": med(times.bare),
        "detector": "ctxsearch.envs.detector.detect",
    }


def _write(results: dict, out_dir: Path) -> None:
    """bench_sim.json, bench_sim.md and bench_sim.png."""
    r = results
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "bench_sim.json").write_text(json.dumps(r, indent=2) + "\n")
    table = format_table(r)
    (out_dir / "bench_sim.md").write_text(
        f"# bench sim\n\n{r['rooms']} '{r['style']}' rooms, {r['gazes_per_room']} gazes each at "
        f"{r['width']}x{r['height']}; renderer: {r['gl_renderer']}; {r['cpu_count']} CPUs, 1-minute "
        f"load average {r['load_avg_1min'][0]} before and {r['load_avg_1min'][1]} after. Medians. "
        "A gaze is move_head (servos stepped in MuJoCo) + capture (one draw for segmentation and "
        "depth) + detect; the bare renderer needs two draws for the same images, so the ratio "
        f"can fall below 1.\n\n{table}\n\n![time per gaze](bench_sim.png)\n"
    )
    write_plot(r, out_dir / "bench_sim.png")


def write_plot(r: dict, path: Path) -> None:
    """A bar plot of one gaze's time, by part, against the bare renderer's, and the build time."""
    fig = Figure(figsize=(9, 3.6))
    ax, bx = fig.subplots(1, 2, gridspec_kw={"width_ratios": [3, 2]})
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


def format_table(r: dict) -> str:
    """The results as a Markdown table, with the targets."""
    t = r["targets"]
    rows = [
        ("layouts per second (generate_room)", f"{r['layouts_per_s']:.1f}", ""),
        ("build + compile per room (ms)", f"{r['compile_ms']:.1f}", f"< {t['compile_ms']:.0f}"),
        (
            "world build: layout + MJCF + compile, composer task (ms)",
            f"{r['world_build_composer_ms']:.1f}",
            "",
        ),
        ("  cold: World's way, nothing kept (ms)", f"{r['world_build_cold_ms']:.1f}", ""),
        ("  XML from the cache directory (ms)", f"{r['world_build_disk_ms']:.1f}", ""),
        ("  cached: layout and model kept in memory (ms)", f"{r['world_build_cached_ms']:.1f}", ""),
        ("  speed-up, composer / cached", f"{r['world_build_speedup']:.1f}x", ">= 5x"),
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
    if "map_free_recall" in r:
        rows += [
            (f"map_free_recall, full exploration ({r['frontier_rule']}; median of "
             f"{r['map_worlds']})", f"{r['map_free_recall']:.3f}", ""),
            ("map_false_free (cells, summed)", f"{r['map_false_free']}", "0"),
            ("  within the navigation margin of a bounding box", f"{r['map_false_free_margin']}", ""),
            ("planned drive segments too near an obstacle", f"{r['map_unsafe_segments']}", "0"),
            ("explore_sim_s (median, simulated)", f"{r['explore_sim_s']:.0f}", ""),
            ("  wall seconds (median)", f"{r['explore_wall_s']:.1f}", ""),
        ]  # fmt: skip
    lines = ["| measure | value | target |", "| --- | ---: | ---: |"]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in rows]
    return "\n".join(lines)
