"""``ctxsearch room``: generate and build one room, then show it: a top-down overview, a few
head-camera views with detections, and (optionally) a rerun recording."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

FONT = 0  # cv2.FONT_HERSHEY_SIMPLEX


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``room`` sub-command."""
    p = sub.add_parser(
        "room",
        help="generate and build a room; write overview.png, view_*.png and a rerun recording",
        description="Generate a room of a style (deterministic by seed), build it in MuJoCo, drive "
        "the robot to viewpoints looking at its furniture and write DIR/overview.png (top-down), "
        "DIR/view_*.png (head camera, detections drawn) and, with --record, a rerun recording.",
    )
    p.add_argument(
        "--style", default="office", help="room style name or TOML path (default: office)"
    )
    p.add_argument("--seed", type=int, default=0, help="room seed (default: 0)")
    p.add_argument("--out", required=True, type=Path, help="output directory")
    p.add_argument("--record", type=Path, default=None, help="write a rerun recording (.rrd) here")
    p.add_argument("--views", type=int, default=4, help="head-camera views to take (default: 4)")
    p.add_argument("--width", type=int, default=320, help="head-camera image width (default: 320)")
    p.add_argument(
        "--height", type=int, default=240, help="head-camera image height (default: 240)"
    )
    p.add_argument(
        "--catalog",
        type=Path,
        default=None,
        help="object-type catalog (default: assets/types.toml)",
    )
    p.set_defaults(func=run)


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


def _overlaps(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def draw_detections(rgb, detections, catalog, min_height: int = 480):
    """A BGR copy of ``rgb`` (enlarged to at least ``min_height`` rows so labels stay legible)
    with every detection's box, type label, visible pixel count and distance drawn; labels are
    moved up or down so they do not cover each other."""
    import cv2
    import numpy as np

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
    import cv2
    import numpy as np

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


def run(args: argparse.Namespace) -> int:
    """Build the room, take the views, write the images and the recording."""
    import cv2
    import numpy as np

    from agent.navigation import OccupancyGrid, nearest_free
    from agent.perception import detect
    from agent.recording import Recorder
    from agent.viewplan import GazePlanOptions, execute_gaze, plan_gazes
    from envs.arena import MAX_IMAGE_SIZE
    from envs.robot_spec import RobotPose
    from envs.rooms import generate_room
    from envs.styles import load_style
    from envs.world import World
    from knowledge.catalog import load_catalog
    from knowledge.errors import CtxsearchError
    from knowledge.geometry import relation_volume

    if args.views < 0:
        raise CtxsearchError(f"--views must be at least 0, got {args.views}")
    if not (1 <= args.width <= MAX_IMAGE_SIZE[0] and 1 <= args.height <= MAX_IMAGE_SIZE[1]):
        raise CtxsearchError(
            f"--width/--height must be within 1x1..{MAX_IMAGE_SIZE[0]}x{MAX_IMAGE_SIZE[1]}, "
            f"got {args.width}x{args.height}"
        )
    catalog = load_catalog(args.catalog)
    style = load_style(args.style, catalog)
    layout = generate_room(style, args.seed, catalog)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    rec = Recorder(args.record)
    with World(layout, catalog, width=args.width, height=args.height) as world:
        spec = world.spec
        grid = OccupancyGrid.from_layout(layout, spec)
        pose = world.pose()
        if not grid.is_free(pose.xy):
            xy = nearest_free(grid, pose.xy)
            if xy is not None:
                world.reset_pose(RobotPose(float(xy[0]), float(xy[1]), pose.yaw))
        n_furn = sum(catalog.type(o.type).is_furniture for o in layout.objects)
        print(
            f"room: style {layout.style}, seed {layout.seed}, {layout.width:.1f} x {layout.depth:.1f} m, "
            f"{n_furn} furniture, {len(layout.objects) - n_furn} small objects"
        )

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
                )
        rec.set_time(world.sim_time, step=0)
        rec.log_robot(world.pose(), spec)

        path_xy = [world.pose().xy]
        views = []
        for i, target in enumerate(_furniture_targets(layout, catalog, args.views)):
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
                    width=args.width,
                    height=args.height,
                ),
            )
            if not gazes:
                print(
                    f"  view {i}: no reachable viewpoint sees {target.type} #{target.id}, skipped"
                )
                continue
            gaze = gazes[0]
            if gaze.path is not None:
                rec.log_path(gaze.path)
            frame = execute_gaze(world, grid, gaze, rgb=True, depth=True)
            if gaze.path is not None:
                path_xy.extend(gaze.path)
            path_xy.append(frame.pose.xy)
            views.append((i, frame.pose))
            dets = detect(frame, layout, catalog)
            img = draw_detections(frame.rgb, dets, catalog)
            p = out / f"view_{i}.png"
            cv2.imwrite(str(p), img)
            written.append(p)
            rec.set_time(world.sim_time, step=i + 1)
            rec.log_robot(frame.pose, spec, path=gaze.path)
            rec.log_camera(frame, dets)
            seen = ", ".join(f"{d.type}#{d.instance_id}" for d in dets) or "nothing"
            rec.log_text(f"view {i}: looking at {target.type} #{target.id}; detected {seen}")
            print(
                f"  view {i}: {target.type} #{target.id} from ({frame.pose.x:.2f}, {frame.pose.y:.2f}), "
                f"t = {world.sim_time:.1f} s, detected: {seen}"
            )
        over = world.render_overview(640, 480)
        img = draw_overview(over, world, catalog, np.array(path_xy), views)
        p = out / "overview.png"
        cv2.imwrite(str(p), img)
        written.insert(0, p)
    rec.close()
    if args.record is not None:
        written.append(Path(args.record))
    for p in written:
        print(f"wrote {p}")
    return 0
