"""What ``ctxsearch room`` shows of one room: a top-down overview with the path and the
viewpoints, head-camera views with the detections drawn, and (optionally) a rerun recording."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ctxsearch.agent.navigation import OccupancyGrid, nearest_free
from ctxsearch.agent.recording import Recorder
from ctxsearch.agent.rr_layout import ROOM_APP, room_blueprint
from ctxsearch.agent.viewplan import GazePlanOptions, execute_gaze, plan_gazes
from ctxsearch.envs.arena import MAX_IMAGE_SIZE
from ctxsearch.envs.detector import SimDetector, default_or_named
from ctxsearch.envs.floorplan import generate_layout, layout_dict
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotPose
from ctxsearch.envs.world import World
from ctxsearch.knowledge.catalog import Catalog, load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.geometry import relation_volume
from ctxsearch.scripts.overview_rooms import draw_room_labels
from ctxsearch.scripts.remembered_view import write_remembered
from ctxsearch.scripts.room_segments import write_segments

FONT = cv2.FONT_HERSHEY_SIMPLEX


def _furniture_targets(layout, catalog, k: int) -> list:
    """Up to ``k`` furniture pieces, round-robin over types (largest pieces first in each type)."""
    by_type: dict[str, list] = {}
    for o in layout.objects:
        if catalog.type(o.type).is_furniture:
            by_type.setdefault(o.type, []).append(o)
    for objs in by_type.values():
        objs.sort(key=lambda o: (-o.size[0] * o.size[1], o.id))
    out: list = []
    while len(out) < k and any(by_type.values()):
        for t in list(by_type):
            if by_type[t] and len(out) < k:
                out.append(by_type[t].pop(0))
    return out


def detection_label(d) -> str:
    """How a person reads a detection: ``Cup#11``, or ``a false detection (Remote)`` for one of
    no object (clutter: its negative id means nothing to a reader)."""
    if d.instance_id < 0:
        return f"a false detection ({d.type})"
    return f"{d.type}#{d.instance_id}"


def _overlaps(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def draw_detections(rgb, detections, catalog, min_height: int = 480):
    """A BGR copy of ``rgb`` (enlarged to at least ``min_height`` rows so labels stay legible)
    with every detection's box, type label, visible pixel count and distance drawn; labels are
    moved up or down so they do not cover each other."""

    img = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR)
    k = max(1, int(math.ceil(min_height / img.shape[0])))
    if k > 1:
        img = cv2.resize(img, None, fx=k, fy=k, interpolation=cv2.INTER_NEAREST)
    h, w = img.shape[:2]
    scale = 0.4 * max(1.0, h / 480)
    placed: list[tuple[int, int, int, int]] = []
    boxes = []
    for det in detections:
        x0, y0, x1, y1 = (v * k for v in det.bbox)
        x1, y1 = x1 + k - 1, y1 + k - 1
        color = tuple(int(255 * c) for c in catalog.type(det.type).color[::-1])
        # A dark outline under the coloured box keeps it readable on any background.
        cv2.rectangle(img, (x0, y0), (x1, y1), (0, 0, 0), 3)
        cv2.rectangle(img, (x0, y0), (x1, y1), color, 1)
        boxes.append((det, x0, y0, x1, y1, color))
    for det, x0, y0, _x1, _y1, color in boxes:
        label = f"{det.type} {det.pixels}px {det.distance:.1f}m"
        (tw, th), base = cv2.getTextSize(label, FONT, scale, 1)
        lh = th + base + 3
        x = int(np.clip(x0, 0, max(0, w - tw - 4)))
        # Preferred: just above the box; else inside its top edge; then search down and up.
        first = y0 - lh if y0 - lh >= 0 else y0
        candidates = [first] + [
            first + d * lh * s for d in range(1, 2 * h // lh + 1) for s in (1, -1)
        ]
        for y in candidates:
            rect = (x, int(y), x + tw + 4, int(y) + lh)
            if rect[1] >= 0 and rect[3] <= h and not any(_overlaps(rect, r) for r in placed):
                break
        else:
            rect = (
                x,
                int(np.clip(first, 0, h - lh)),
                x + tw + 4,
                int(np.clip(first, 0, h - lh)) + lh,
            )
        placed.append(rect)
        cv2.rectangle(img, rect[:2], (rect[2], rect[3]), (0, 0, 0), -1)
        cv2.rectangle(img, (rect[0], rect[1]), (rect[0] + 3, rect[3]), color, -1)
        cv2.putText(
            img,
            label,
            (rect[0] + 5, rect[3] - base - 1),
            FONT,
            scale,
            (255, 255, 255),
            1,
            cv2.LINE_AA,
        )
    return img


def draw_overview(img_rgb, world, catalog, path_xy, views):
    """The overview with object labels, the driven path and the viewpoints ``views`` ((index,
    pose) pairs) drawn (BGR)."""

    img = cv2.cvtColor(np.ascontiguousarray(img_rgb), cv2.COLOR_RGB2BGR)
    h, w = img.shape[:2]

    def proj(pts):
        return world.overview_pixels(pts, w, h)

    scale = 0.36 * max(1.0, h / 480)
    # Furniture labels first (always drawn), then small objects' where they do not cover another.
    placed: list[tuple[int, int, int, int]] = []
    order = sorted(
        world.layout.objects, key=lambda o: (not catalog.type(o.type).is_furniture, o.id)
    )
    for o in order:
        furniture = catalog.type(o.type).is_furniture
        u, v = proj([[o.position[0], o.position[1], o.top]])[0]
        label = o.type if furniture else o.type.lower()
        (tw, th), _ = cv2.getTextSize(label, FONT, scale, 1)
        org = (int(u - tw / 2), int(v + th / 2))
        rect = (org[0] - 1, org[1] - th - 1, org[0] + tw + 1, org[1] + 2)
        if not furniture and any(_overlaps(rect, r) for r in placed):
            continue
        placed.append(rect)
        # Text on a dark backing, blended so the object under it still shows.
        x0, y0 = max(rect[0], 0), max(rect[1], 0)
        x1, y1 = min(rect[2], w), min(rect[3], h)
        if x1 > x0 and y1 > y0:
            img[y0:y1, x0:x1] = (img[y0:y1, x0:x1] * 0.35).astype(np.uint8)
        color = (255, 255, 255) if furniture else (170, 240, 255)
        cv2.putText(img, label, org, FONT, scale, color, 1, cv2.LINE_AA)
    if len(path_xy) >= 2:
        pts = proj(np.column_stack([path_xy, np.zeros(len(path_xy))])).round().astype(np.int32)
        cv2.polylines(img, [pts], False, (25, 128, 230), 2, cv2.LINE_AA)
    names: dict[tuple[int, int], list[str]] = {}
    for i, pose in views:
        u, v = (int(x) for x in proj([[pose.x, pose.y, 0.0]])[0].round())
        names.setdefault((u, v), []).append(str(i))
        heading = pose.yaw + pose.pan
        tip = proj([[pose.x + 0.5 * math.cos(heading), pose.y + 0.5 * math.sin(heading), 0.0]])[0]
        cv2.circle(img, (u, v), 6, (25, 128, 230), -1, cv2.LINE_AA)
        tip_px = tuple(int(x) for x in tip.round())
        cv2.arrowedLine(img, (u, v), tip_px, (25, 128, 230), 2, cv2.LINE_AA, tipLength=0.3)
    for (u, v), idx in names.items():  # views taken from the same spot share one label: "1,2"
        text = ",".join(idx)
        cv2.putText(img, text, (u + 7, v - 7), FONT, 0.45, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(img, text, (u + 7, v - 7), FONT, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    return img


@dataclass(frozen=True)
class RoomViewConfig:
    """Which room ``ctxsearch room`` shows and how (its flags)."""

    style: str
    seed: int
    out: Path
    record: Path | None = None
    views: int = 4
    width: int = 320
    height: int = 240
    catalog: Path | None = None  # object-type catalog (None: assets/types.toml)
    detector: str | None = None  # detector preset, name or file (None: realistic)
    segment: bool = True  # a house: explore it and draw the robot's rooms (scripts.room_segments)
    remembered: bool = False  # tour it and draw the remembered map (scripts.remembered_view)

    def check(self) -> None:
        """A one-line error for a negative view count or an image size MuJoCo cannot render."""
        if self.views < 0:
            raise CtxsearchError(f"--views must be at least 0, got {self.views}")
        w, h = MAX_IMAGE_SIZE
        if not (1 <= self.width <= w and 1 <= self.height <= h):
            raise CtxsearchError(
                f"--width/--height must be within 1x1..{w}x{h}, got {self.width}x{self.height}"
            )


def show_room(config: RoomViewConfig) -> list[Path]:
    """Build the room, take the views, write the images and the recording; the files written."""
    config.check()
    catalog = load_catalog(config.catalog)
    style = resolve_style(config.style, catalog)
    layout = generate_layout(style, config.seed, catalog)
    config.out.mkdir(parents=True, exist_ok=True)
    rec = Recorder(
        config.record,
        ROOM_APP,
        name=f"room: {layout.style}, seed {layout.seed}",
        blueprint=room_blueprint(layout) if config.record is not None else None,
    )
    with World(layout, catalog, width=config.width, height=config.height) as world:
        viewer = _Viewer(config, layout, catalog, world, _start_grid(world, layout), rec)
        _print_room(layout, catalog)
        _log_scene(rec, world, layout, catalog)
        for i, target in enumerate(_furniture_targets(layout, catalog, config.views)):
            viewer.take(i, target)
        ow, oh = (960, 720) if layout.is_house else (640, 480)
        over = world.render_overview(ow, oh)
        img = draw_overview(over, world, catalog, np.array(viewer.path_xy), viewer.views)
        img = draw_room_labels(img, world, layout)
        p = config.out / "overview.png"
        cv2.imwrite(str(p), img)
    rec.close()
    lp = config.out / "layout.json"
    lp.write_text(json.dumps(layout_dict(layout), indent=1) + "\n")
    written = [p, lp, *viewer.written]
    if layout.is_house and config.segment:
        written += write_segments(layout, catalog, config.out)
    if config.remembered:
        detector = default_or_named(config.detector, catalog, "realistic")
        written += write_remembered(layout, catalog, detector, config.out)
    if config.record is not None:
        written.append(Path(config.record))
    return written


def _start_grid(world: World, layout: RoomLayout) -> OccupancyGrid:
    """The room's occupancy grid; the robot moved to the nearest free cell if it starts in an
    occupied one."""
    spec = world.spec
    grid = OccupancyGrid.from_layout(layout, spec)
    pose = world.pose()
    if not grid.is_free(pose.xy):
        xy = nearest_free(grid, pose.xy)
        if xy is not None:
            world.reset_pose(RobotPose(float(xy[0]), float(xy[1]), pose.yaw))
    return grid


def _print_room(layout: RoomLayout, catalog: Catalog) -> None:
    n_furn = sum(catalog.type(o.type).is_furniture for o in layout.objects)
    kind = f"house ({len(layout.rooms)} rooms)" if layout.is_house else "room"
    print(
        f"{kind}: style {layout.style}, seed {layout.seed}, {layout.width:.1f} x {layout.depth:.1f} m, "
        f"{n_furn} furniture, {len(layout.objects) - n_furn} small objects"
    )


def _log_scene(rec: Recorder, world: World, layout: RoomLayout, catalog: Catalog) -> None:
    """The room, the furniture's relation volumes and the robot at step 0."""
    rec.log_room(layout, catalog)
    for o in layout.objects:
        typ = catalog.type(o.type)
        if typ.is_furniture and typ.relations:
            rec.log_volumes(
                f"world/volumes/{o.type}_{o.id}",
                [relation_volume(r, o) for r in typ.relations],
                labels=list(typ.relation_names),
                color=typ.color,
                static=True,
                show_labels=False,
            )
    rec.set_time(world.sim_time)
    rec.log_robot(world.pose(), world.spec)


@dataclass
class _Viewer:
    """Takes the head-camera views one by one, noting the path driven and the files written."""

    config: RoomViewConfig
    layout: RoomLayout
    catalog: Catalog
    world: World
    grid: OccupancyGrid
    rec: Recorder
    path_xy: list = field(default_factory=list)
    views: list = field(default_factory=list)  # (index, pose) of every view taken
    written: list[Path] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.path_xy.append(self.world.pose().xy)
        model = default_or_named(self.config.detector, self.catalog, "realistic")
        self.detector = SimDetector(model, self.layout, self.catalog, self.config.seed)
        print(f"detector: {model.name}")

    def take(self, i: int, target) -> None:
        """Drive to a viewpoint that sees ``target``, look, detect, write view_<i>.png."""
        world, grid, rec, cfg = self.world, self.grid, self.rec, self.config
        catalog, spec = self.catalog, world.spec
        gazes = plan_gazes(
            grid,
            target.box(),
            world.pose(),
            spec,
            world.time_model,
            GazePlanOptions(
                max_distance=3.5,
                max_gazes=1,
                min_gain=0.0,
                cost_weight=0.3,
                width=cfg.width,
                height=cfg.height,
            ),
        )
        if not gazes:
            print(f"  view {i}: no reachable viewpoint sees {target.type} #{target.id}, skipped")
            return
        gaze = gazes[0]
        if gaze.path is not None:
            rec.log_path(gaze.path)
        frame = execute_gaze(world, grid, gaze, rgb=True, depth=True)
        if gaze.path is not None:
            self.path_xy.extend(gaze.path)
        self.path_xy.append(frame.pose.xy)
        self.views.append((i, frame.pose))
        dets = self.detector(frame, world.sim_time)
        p = cfg.out / f"view_{i}.png"
        cv2.imwrite(str(p), draw_detections(frame.rgb, dets, catalog))
        self.written.append(p)
        rec.set_time(world.sim_time)
        rec.log_robot(frame.pose, spec, path=gaze.path)
        rec.log_camera(frame, dets)
        seen = ", ".join(detection_label(d) for d in dets) or "nothing"
        rec.log_text(f"view {i}: looking at {target.type} #{target.id}; detected {seen}")
        print(
            f"  view {i}: {target.type} #{target.id} from ({frame.pose.x:.2f}, {frame.pose.y:.2f}), "
            f"t = {world.sim_time:.1f} s, detected: {seen}"
        )
