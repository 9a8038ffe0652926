"""Detector models as data: how the simulated detector errs (``assets/detectors/*.toml``).

The sensor model of the simulation. The renderer says which instance every pixel shows; what a
real detector makes of that is a model with four parts, each a section of the preset file:

``[recall]``  P(detected) as a smooth function of visible pixels and distance, per type::

    recall = max_recall / (1 + (p50 / pixels)^slope) / (1 + exp((d - r50) / (range_width R)))
    p50 = half_pixels * min_pixels(T)      r50 = range_fraction * R      R = max_range(T)

  a logistic in log-pixels (the usual shape of recall against object size) times a logistic
  fall-off near the type's range. ``min_pixels`` and ``max_range`` are the catalog's (at 320x240;
  other resolutions scale the pixel figures by their pixel count).
``[[confusion]]``  pairs of similar types reported as each other with probability p (both ways).
``[false_positives]``  detections on clutter: a Poisson number per image (``per_image``), each
  of a type drawn from ``types``, standing on a surface point the image shows.
``[pose]``  position and yaw noise, Gaussian, with sigmas growing linearly with distance.

Every detection carries a confidence ``score`` in [0, 1], as a real detector's does: a detection
of a true instance scores the model's recall at its pixels and distance (a calibrated detector's
confidence tracks how detectable the box is; a look-alike report scores the same, as confusions
do in practice: confidence cannot filter them); a false positive scores uniformly in
(0, ``false_positives.max_score``] (optional, default 0.5: clutter fires weakly), drawn from a
stream of its own keyed by its id so the image's stream is the same with or without scores. The
perfect detector's detections score 1.

``kind = "perfect"`` is the threshold detector the project started with: an instance is detected
iff it has at least min_pixels visible pixels within max_range, its pose exact, no confusion, no
false positive, and it draws no random numbers (so runs with it are identical to runs before
detector models existed). A preset file holds ``kind`` and, for ``kind = "model"``, the four
sections; every number must be finite and in its range, and a bad file gets a one-line
DetectorError naming the file and the field.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ctxsearch.envs.camera import Frame, PinholeCamera, focal_length
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.knowledge.catalog import ASSETS_DIR, Catalog, ObjectType, asset_file
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.files import InputFileError, read_toml
from ctxsearch.knowledge.geometry import ObjectInstance

DETECTORS_DIR = ASSETS_DIR / "detectors"
REFERENCE_PIXELS = 320 * 240  # the resolution the catalog's min_pixels refers to
KINDS = ("perfect", "model")
SECTIONS = {"recall", "confusion", "false_positives", "pose"}
TOP_FIELDS = {"name", "description", "kind"} | SECTIONS
# field -> (lower bound, upper bound, lower bound inclusive?)
RECALL_FIELDS = {
    "max_recall": (0.0, 1.0, False),
    "half_pixels": (0.0, 1e4, False),
    "slope": (0.0, 100.0, False),
    "range_fraction": (0.0, 10.0, False),
    "range_width": (0.0, 10.0, False),
}
POSE_FIELDS = {
    "position_sigma": (0.0, 10.0, True),
    "position_sigma_per_m": (0.0, 10.0, True),
    "yaw_sigma_deg": (0.0, 180.0, True),
    "yaw_sigma_deg_per_m": (0.0, 180.0, True),
}
FP_FIELDS = {"per_image": (0.0, 100.0, True)}
FP_OPTIONAL = {"max_score": (0.0, 1.0, False)}  # optional fields of [false_positives]
FP_MAX_SCORE = 0.5  # false positives' highest confidence when the preset does not say
CONFUSION_FIELDS = {"a", "b", "p"}


class DetectorError(CtxsearchError, ValueError):
    """A detector preset file is malformed or inconsistent with the catalog."""

    def __init__(self, path: object, message: str, *, field: str | None = None):
        where = str(path) + (f": field '{field}'" if field else "")
        super().__init__(f"{where}: {message}")
        self.path, self.field = path, field


def min_pixels_at(min_pixels: float, width: int, height: int) -> int:
    """A type's pixel threshold at ``width`` x ``height`` (the catalog's is for 320x240)."""
    return max(1, int(math.ceil(min_pixels * (width * height) / REFERENCE_PIXELS)))


@dataclass(frozen=True)
class Recall:
    """The recall curve's parameters (see the module docstring)."""

    max_recall: float
    half_pixels: float
    slope: float
    range_fraction: float
    range_width: float


@dataclass(frozen=True)
class PoseNoise:
    """Gaussian pose noise: sigma = a + b * distance, for position (m) and yaw (degrees)."""

    position_sigma: float
    position_sigma_per_m: float
    yaw_sigma_deg: float
    yaw_sigma_deg_per_m: float


@dataclass(frozen=True)
class DetectorModel:
    """A validated detector preset. ``kind == 'perfect'`` ignores every other field."""

    name: str
    path: str
    kind: str
    description: str = ""
    recall: Recall | None = None
    confusion: tuple[tuple[str, str, float], ...] = ()
    fp_per_image: float = 0.0
    fp_types: tuple[str, ...] = ()
    pose: PoseNoise | None = None
    fp_max_score: float = FP_MAX_SCORE

    @property
    def perfect(self) -> bool:
        """True for the exact threshold detector (no randomness)."""
        return self.kind == "perfect"

    def check_catalog(self, catalog: Catalog) -> DetectorModel:
        """Every type the preset names must be in ``catalog`` (DetectorError); returns self."""
        for a, b, _ in self.confusion:
            for t in (a, b):
                if t not in catalog:
                    raise DetectorError(self.path, f"unknown type '{t}'", field="confusion")
        for t in self.fp_types:
            if t not in catalog:
                raise DetectorError(self.path, f"unknown type '{t}'", field="false_positives.types")
        return self

    def restricted_to(self, catalog: Catalog) -> DetectorModel:
        """The preset without the confusion pairs and false-positive types ``catalog`` lacks
        (the default preset on a catalog of one's own; a named preset is checked instead)."""
        return replace(
            self,
            confusion=tuple(c for c in self.confusion if c[0] in catalog and c[1] in catalog),
            fp_types=tuple(t for t in self.fp_types if t in catalog),
        )

    # ---- the model --------------------------------------------------------------------------
    def recall_prob(
        self, typ: ObjectType, pixels: np.ndarray, distance: np.ndarray, width: int, height: int
    ) -> np.ndarray:
        """P(detected) for instances of ``typ`` with ``pixels`` visible pixels in a ``width`` x
        ``height`` image at ``distance`` m. The perfect detector: 1 iff pixels >= the type's
        threshold at that resolution and distance <= max_range, else 0."""
        px = np.asarray(pixels, float)
        dist = np.asarray(distance, float)
        if self.perfect or self.recall is None:
            ok = (px >= min_pixels_at(typ.min_pixels, width, height)) & (dist <= typ.max_range)
            return ok.astype(float)
        r = self.recall
        p50 = r.half_pixels * typ.min_pixels * (width * height) / REFERENCE_PIXELS
        r50, spread = r.range_fraction * typ.max_range, r.range_width * typ.max_range
        with np.errstate(divide="ignore", over="ignore"):
            by_size = 1.0 / (1.0 + (p50 / np.maximum(px, 1e-9)) ** r.slope)
            by_range = 1.0 / (1.0 + np.exp((dist - r50) / spread))
        return r.max_recall * by_size * by_range

    def confusions(self, type_name: str) -> list[tuple[str, float]]:
        """The types ``type_name`` may be reported as, with their probabilities."""
        out = []
        for a, b, p in self.confusion:
            if a == type_name:
                out.append((b, p))
            elif b == type_name:
                out.append((a, p))
        return out

    def reported_type(self, type_name: str, rng: np.random.Generator) -> str:
        """The type the detector reports for an instance of ``type_name`` (one uniform draw)."""
        options = self.confusions(type_name)
        if not options:
            return type_name
        u = rng.random()
        acc = 0.0
        for other, p in options:
            acc += p
            if u < acc:
                return other
        return type_name

    def noisy_pose(
        self, obj: ObjectInstance, distance: float, rng: np.random.Generator
    ) -> ObjectInstance:
        """``obj`` with its estimated pose: position and yaw perturbed by the distance's sigmas
        (z kept: objects rest on surfaces the robot's depth shows)."""
        if self.pose is None:
            return obj
        n = self.pose
        sp = n.position_sigma + n.position_sigma_per_m * distance
        sy = math.radians(n.yaw_sigma_deg + n.yaw_sigma_deg_per_m * distance)
        dx, dy, dyaw = rng.normal(0.0, 1.0, 3) * (sp, sp, sy)
        x, y, z = obj.position
        return replace(obj, position=(x + float(dx), y + float(dy), z), yaw=obj.yaw + float(dyaw))

    def false_positives(
        self,
        rng: np.random.Generator,
        sample_point: Callable[[np.random.Generator], tuple[np.ndarray, float] | None],
        catalog: Catalog,
        first_id: int,
    ) -> list[tuple[ObjectInstance, float]]:
        """This image's false detections as (pose, distance): a Poisson number, each of a type
        from ``fp_types`` standing on a surface point drawn by ``sample_point`` (a visible
        point and its distance, or None if the image shows none). Ids count down from
        ``first_id`` (negative ids never collide with the layout's)."""
        if self.perfect or self.fp_per_image <= 0 or not self.fp_types:
            return []
        out = []
        for k in range(int(rng.poisson(self.fp_per_image))):
            hit = sample_point(rng)
            t = self.fp_types[int(rng.integers(len(self.fp_types)))]
            if hit is None:
                continue
            point, dist = hit
            typ = catalog.type(t)
            size = tuple(
                float(v) for v in (np.asarray(typ.size_min) + np.asarray(typ.size_max)) / 2
            )
            pos = (float(point[0]), float(point[1]), float(point[2]) + size[2] / 2)
            yaw = float(rng.uniform(-math.pi, math.pi))
            out.append((ObjectInstance(t, first_id - k, pos, yaw, size), float(dist)))
        return out


# ============================================================================= loading
def available_detectors() -> list[str]:
    """Names of the presets shipped in ``assets/detectors``."""
    return sorted(p.stem for p in DETECTORS_DIR.glob("*.toml"))


def detector_path(path_or_name: str | Path) -> Path:
    """The file of a preset given by path or bare name (``realistic`` -> assets/detectors/...)."""
    return asset_file(path_or_name, DETECTORS_DIR)


def _number(path, field: str, value, lo: float, hi: float, lo_inclusive: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise DetectorError(path, f"expected a number, got {value!r}", field=field)
    v = float(value)
    below = v < lo if lo_inclusive else v <= lo
    if not math.isfinite(v) or below or v > hi:
        bracket = "[" if lo_inclusive else "("
        raise DetectorError(
            path, f"must be a finite number in {bracket}{lo}, {hi}], got {value!r}", field=field
        )
    return v


def _table(path, doc: dict, name: str, spec: dict) -> dict[str, float]:
    raw = doc.get(name)
    if not isinstance(raw, dict):
        raise DetectorError(path, "missing or not a table", field=name)
    extra = ({"types"} | set(FP_OPTIONAL)) if name == "false_positives" else set()
    unknown = set(raw) - set(spec) - extra
    if unknown:
        raise DetectorError(path, f"unknown field(s) {sorted(unknown)}", field=name)
    out = {}
    for f, (lo, hi, inc) in spec.items():
        if f not in raw:
            raise DetectorError(path, "missing", field=f"{name}.{f}")
        out[f] = _number(path, f"{name}.{f}", raw[f], lo, hi, inc)
    return out


def _confusion(path, raw) -> tuple[tuple[str, str, float], ...]:
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise DetectorError(path, "must be an array of tables [[confusion]]", field="confusion")
    out = []
    total: dict[str, float] = {}
    for i, item in enumerate(raw):
        where = f"confusion[{i}]"
        if not isinstance(item, dict) or set(item) != CONFUSION_FIELDS:
            raise DetectorError(
                path, f"needs exactly the fields {sorted(CONFUSION_FIELDS)}", field=where
            )
        a, b = item["a"], item["b"]
        if not (isinstance(a, str) and isinstance(b, str)) or a == b:
            raise DetectorError(path, "a and b must be two different type names", field=where)
        p = _number(path, f"{where}.p", item["p"], 0.0, 1.0, True)
        for t in (a, b):
            total[t] = total.get(t, 0.0) + p
            if total[t] > 1.0:
                raise DetectorError(
                    path, f"confusion probabilities of {t} add up to more than 1", field=where
                )
        out.append((a, b, p))
    return tuple(out)


def parse_detector(doc: dict, path: str | Path = "<memory>") -> DetectorModel:
    """Validate a parsed preset document; DetectorError on any problem."""
    unknown = set(doc) - TOP_FIELDS
    if unknown:
        raise DetectorError(path, f"unknown top-level field(s) {sorted(unknown)}")
    name = doc.get("name", Path(str(path)).stem)
    kind = doc.get("kind")
    if not isinstance(name, str) or not name:
        raise DetectorError(path, "must be a non-empty string", field="name")
    if kind not in KINDS:
        raise DetectorError(path, f"must be one of {list(KINDS)}, got {kind!r}", field="kind")
    description = doc.get("description", "")
    if not isinstance(description, str):
        raise DetectorError(path, "must be a string", field="description")
    if kind == "perfect":
        extra = set(doc) & SECTIONS
        if extra:
            raise DetectorError(path, f"a perfect detector takes no {sorted(extra)}", field="kind")
        return DetectorModel(name, str(path), kind, description)
    recall = Recall(**_table(path, doc, "recall", RECALL_FIELDS))
    pose = PoseNoise(**_table(path, doc, "pose", POSE_FIELDS))
    fp = _table(path, doc, "false_positives", FP_FIELDS)
    raw_fp = doc["false_positives"]
    max_score = FP_MAX_SCORE
    if "max_score" in raw_fp:
        lo, hi, inc = FP_OPTIONAL["max_score"]
        max_score = _number(path, "false_positives.max_score", raw_fp["max_score"], lo, hi, inc)
    types = raw_fp.get("types", [])
    if not isinstance(types, list) or not all(isinstance(t, str) for t in types):
        raise DetectorError(path, "must be a list of type names", field="false_positives.types")
    return DetectorModel(
        name,
        str(path),
        kind,
        description,
        recall,
        _confusion(path, doc.get("confusion")),
        fp["per_image"],
        tuple(types),
        pose,
        max_score,
    )


def load_detector(path_or_name: str | Path, catalog: Catalog | None = None) -> DetectorModel:
    """Load and validate a preset (a name in assets/detectors or a path); with ``catalog``, its
    type names are checked too. DetectorError (one line) on any problem."""
    path = detector_path(path_or_name)
    try:
        doc = read_toml(path)  # a regular file, size and nesting limited
    except InputFileError as exc:
        if exc.missing:
            known = ", ".join(available_detectors())
            raise DetectorError(path, f"no such detector preset (shipped: {known})") from None
        raise DetectorError(path, exc.problem) from None
    model = parse_detector(doc, path)
    return model.check_catalog(catalog) if catalog is not None else model


def default_or_named(name: str | Path | None, catalog: Catalog, default: str) -> DetectorModel:
    """``name``'s preset checked against ``catalog`` (one-line errors), or with None the
    ``default`` preset restricted to the catalog's types."""
    if name is None:
        return load_detector(default).restricted_to(catalog)
    return load_detector(name, catalog)


def detection_rng(seed: int, image_index: int) -> np.random.Generator:
    """The detector's own random stream for one image: the same seed and image, the same draws,
    independent of every other stream of the run."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, 0xDE7EC7, int(image_index)])


def recall_probs(
    model: DetectorModel,
    types: Sequence[ObjectType],
    pixels: np.ndarray,
    distances: np.ndarray,
    size: tuple[int, int],
) -> np.ndarray:
    """P(detected) of each candidate instance (``size``: the image's (width, height))."""
    w, h = size
    return np.array(
        [
            float(model.recall_prob(t, px, d, w, h))
            for t, px, d in zip(types, pixels, distances, strict=True)
        ]
    )


def keep(
    model: DetectorModel,
    types: Sequence[ObjectType],
    pixels: np.ndarray,
    distances: np.ndarray,
    size: tuple[int, int],
    rng: np.random.Generator | None,
) -> np.ndarray:
    """Which candidate instances the detector reports (bool mask over the candidates): each kept
    with its recall probability, one uniform draw per candidate in order (none at all for the
    perfect detector, which needs no ``rng``). ``size``: the image's (width, height)."""
    probs = recall_probs(model, types, pixels, distances, size)
    if model.perfect:
        return probs >= 1.0
    if rng is None:
        raise ValueError(f"detector '{model.name}' draws random numbers: give it its rng")
    return rng.random(len(probs)) < probs


# ============================================================================= detection
# From a segmentation frame to detections (paper, section 4: recognition and pose estimation
# are assumed; what the robot cannot assume is *seeing* an object). The renderer labels every
# pixel with the instance id of the object it shows (-1: wall, floor, robot, nothing); occlusion
# comes from the rendering. An instance's distance is the median, over its visible pixels, of the
# Euclidean camera-to-surface distance (the depth image holds distance along the optical axis;
# each pixel's ray length follows from the intrinsics); without a depth image, the distance from
# the camera to the nearest point of its bounding box. The preset then decides what is reported:
# the perfect one keeps an instance iff it has its type's min_pixels within max_range, with the
# simulator's pose; a model keeps it with its recall, may report a look-alike type, perturbs its
# pose and adds false positives on surfaces the image shows.


@dataclass(frozen=True)
class Detection:
    """One detection: instance id (negative: a false positive), the reported type, the estimated
    pose (the simulator's for the perfect detector), visible pixels, distance (m) from the camera,
    the pixel bounding box (x0, y0, x1, y1), inclusive, and the confidence score in [0, 1]."""

    instance_id: int
    type: str
    pose: ObjectInstance
    pixels: int
    distance: float
    bbox: tuple[int, int, int, int]
    score: float = 1.0  # the detector's confidence (module docstring)


@functools.lru_cache(maxsize=8)
def ray_scale(width: int, height: int, fovy_deg: float) -> np.ndarray:
    """(H, W) factor turning optical-axis depth into ray length for a centred pinhole camera
    (cached; read-only)."""
    f = focal_length(fovy_deg, height)
    u = (np.arange(width) + 0.5 - width / 2) / f
    v = (np.arange(height) + 0.5 - height / 2) / f
    out = np.sqrt(1.0 + u[None, :] ** 2 + v[:, None] ** 2)
    out.flags.writeable = False
    return out


def box_distance(point: np.ndarray, obj: ObjectInstance) -> float:
    """Euclidean distance from ``point`` (3,) to the nearest point of ``obj``'s bounding box."""
    return float(box_distances(np.asarray(point, float).reshape(1, 3), obj)[0])


def box_distances(points: np.ndarray, obj: ObjectInstance) -> np.ndarray:
    """(N,) ``box_distance`` of each of ``points`` (N, 3)."""
    d = np.asarray(points, float).reshape(-1, 3) - np.asarray(obj.position, float)
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
    out = np.maximum(np.abs(local) - np.asarray(obj.size, float) / 2, 0.0)
    return np.sqrt((out * out).sum(axis=1))


@dataclass(frozen=True)
class _Image:
    """One segmentation image prepared for detection."""

    flat: np.ndarray  # instance ids, raveled
    width: int
    height: int
    counts: np.ndarray  # pixels per id + 1
    depth_flat: np.ndarray | None
    scale: np.ndarray | None  # ray scale, raveled (None: depth used as is)
    surface: list = field(default_factory=list)  # ``_surface``, once made

    def candidates(self) -> np.ndarray:
        """The instance ids (>= 0) with at least one pixel, ascending."""
        c = self.counts
        return np.flatnonzero(c[1:]) if len(c) > 1 else np.zeros(0, int)

    def distance(self, oid: int, idx: np.ndarray, obj: ObjectInstance, camera_position) -> float:
        """The instance's distance (module comment above)."""
        if self.depth_flat is not None:
            d = self.depth_flat[idx]
            if self.scale is not None:
                d = d * self.scale[idx]
            return float(np.median(d))
        if camera_position is not None:
            return box_distance(camera_position, obj)
        raise ValueError("detect_ids needs depth or camera_position to measure distance")

    def bbox(self, idx: np.ndarray) -> tuple[int, int, int, int]:
        """The inclusive pixel bounding box of the pixels ``idx``."""
        rows, cols = np.divmod(idx, self.width)
        return (int(cols.min()), int(rows[0]), int(cols.max()), int(rows[-1]))


@dataclass(frozen=True)
class ImageDraws:
    """What a detector that errs needs for one image: its random stream (``image_rng``) and the
    camera (an envs.camera.PinholeCamera) to put false positives on surfaces (None: none)."""

    rng: np.random.Generator
    camera: PinholeCamera | None = None
    false_positives: bool = True  # False: the true detections only (SimDetector.split)


def detect_ids(
    instance_ids: np.ndarray,
    objects: Mapping[int, ObjectInstance],
    catalog: Catalog,
    *,
    depth: np.ndarray | None = None,
    camera_position: np.ndarray | None = None,
    fovy_deg: float | None = None,
    model: DetectorModel | None = None,
    draws: ImageDraws | None = None,
) -> list[Detection]:
    """Detections in one segmentation image (H, W) of instance ids (-1: nothing of interest).

    ``objects`` maps instance ids to their (simulator) poses; ids not in it are ignored. Distance
    is the median ray length of the instance's pixels when ``depth`` (H, W) is given (optical-axis
    depth; with ``fovy_deg`` it is converted to ray length, without it used as is), else the
    distance from ``camera_position`` to the object's bounding box. ``model``: the preset (None:
    perfect); a model that errs needs its ``draws`` (and, for false positives, ``depth`` and the
    draws' camera). Sorted by pixel count, largest first (false positives, which cover no
    pixel, last); without them if ``draws.false_positives`` is False (``SimDetector.split``
    draws them afterwards from the same stream, which continues where the true detections left
    it).
    """
    img = _image(instance_ids, depth, fovy_deg)
    candidates = img.candidates()
    if model is None or model.perfect:
        out = _detect_perfect(img, candidates, objects, catalog, camera_position)
    else:
        if draws is None:
            raise ValueError(f"detector '{model.name}' draws random numbers: give it its rng")
        out = _detect_model(img, candidates, objects, catalog, camera_position, model, draws.rng)
        if draws.false_positives:
            out += _false_positives(img, model, draws.rng, catalog, draws.camera, depth)
    out.sort(key=by_pixels)
    return out


def by_pixels(d: Detection) -> tuple[int, int]:
    """The order of an image's detections: most pixels first (false positives, none, last)."""
    return (-d.pixels, d.instance_id)


def _image(instance_ids: np.ndarray, depth: np.ndarray | None, fovy_deg: float | None) -> _Image:
    ids = np.asarray(instance_ids)
    h, w = ids.shape
    flat = ids.ravel()
    depth_flat = None if depth is None else np.asarray(depth).ravel()
    scale = None
    if depth is not None and fovy_deg is not None:
        scale = ray_scale(w, h, float(fovy_deg)).ravel()
    counts = np.bincount((flat.astype(np.int64) + 1).clip(0))
    return _Image(flat, w, h, counts, depth_flat, scale)


def _detect_perfect(img: _Image, candidates, objects, catalog, camera_position) -> list[Detection]:
    """The threshold detector (no random numbers; the pixel test before any distance)."""
    out: list[Detection] = []
    for oid in candidates:
        oid = int(oid)
        obj = objects.get(oid)
        if obj is None:
            continue
        typ = catalog.type(obj.type)
        n = int(img.counts[oid + 1])
        if n < min_pixels_at(typ.min_pixels, img.width, img.height):
            continue
        idx = np.flatnonzero(img.flat == oid)
        dist = img.distance(oid, idx, obj, camera_position)
        if dist > typ.max_range:
            continue
        out.append(Detection(oid, obj.type, obj, n, dist, img.bbox(idx)))
    return out


def _detect_model(
    img: _Image, candidates, objects, catalog, camera_position, model: DetectorModel, rng
) -> list[Detection]:
    """A detector that errs: every visible instance kept with its recall (one uniform each, in
    id order), then per kept instance in order: its reported type (one uniform if it has
    look-alikes) and its pose noise (three normals)."""
    return _draw_model(
        _visible(img, candidates, objects, catalog, camera_position, model), model, rng
    )


@dataclass(frozen=True)
class _Visible:
    """What a detector that errs draws on in one image: each visible instance (id, pose, pixel
    indices, distance) in id order and its recall; no random numbers yet."""

    found: list[tuple[int, ObjectInstance, np.ndarray, float]]
    probs: np.ndarray
    bboxes: list[tuple[int, int, int, int]]


def _visible(img: _Image, candidates, objects, catalog, camera_position, model) -> _Visible:
    found = []
    for oid in candidates:
        oid = int(oid)
        obj = objects.get(oid)
        if obj is None:
            continue
        idx = np.flatnonzero(img.flat == oid)
        dist = img.distance(oid, idx, obj, camera_position)
        found.append((oid, obj, idx, dist))
    if not found:
        return _Visible([], np.zeros(0), [])
    types = [catalog.type(o.type) for _, o, _, _ in found]
    pixels = np.array([len(idx) for _, _, idx, _ in found])
    dists = np.array([d for _, _, _, d in found])
    probs = recall_probs(model, types, pixels, dists, (img.width, img.height))
    return _Visible(found, probs, [img.bbox(idx) for _, _, idx, _ in found])


def _draw_model(vis: _Visible, model: DetectorModel, rng) -> list[Detection]:
    if not vis.found:
        return []
    mask = rng.random(len(vis.probs)) < vis.probs
    out: list[Detection] = []
    for (oid, obj, idx, dist), kept, p, box in zip(
        vis.found, mask, vis.probs, vis.bboxes, strict=True
    ):
        if not kept:
            continue
        reported = model.reported_type(obj.type, rng)
        pose = model.noisy_pose(obj, dist, rng)
        if reported != obj.type:
            pose = replace(pose, type=reported)
        out.append(Detection(oid, reported, pose, len(idx), dist, box, float(p)))
    return out


FP_MAX_DEPTH = 10.0  # m: farther pixels (the far plane, through a door into nothing) hold none
FLOOR_Z = 0.05  # m: a pixel whose point is this low shows the floor


def _false_positives(
    img: _Image, model: DetectorModel, rng, catalog: Catalog, camera, depth
) -> list[Detection]:
    """The image's false detections, each on a random pixel that shows an object or the floor
    (clutter stands on surfaces, not on walls), back-projected with the camera (none without
    depth or camera). Ids are negative and drawn from the stream, so they differ between
    images."""
    if model.fp_per_image <= 0 or camera is None or depth is None:
        return []
    base = -(1 + 64 * int(rng.integers(1 << 40)))

    def sample(r: np.random.Generator):
        points, valid, flat_d = _surface(img, camera, depth)
        if not len(valid):
            return None
        k = int(valid[int(r.integers(len(valid)))])
        dist = float(flat_d[k] * (img.scale[k] if img.scale is not None else 1.0))
        return points[k], dist

    fps = model.false_positives(rng, sample, catalog, base)
    return [
        Detection(o.id, o.type, o, 0, dist, (0, 0, 0, 0), false_positive_score(model, o.id))
        for o, dist in fps
    ]


def _surface(img: _Image, camera, depth) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``false_positive_sites`` of the image, made at its first false positive, kept."""
    if not img.surface:
        img.surface.append(false_positive_sites(img.flat, camera, depth))
    return img.surface[0]


def false_positive_sites(ids, camera, depth) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where a false positive may stand: the image's points (H*W, 3) back-projected with
    ``camera``, the pixels showing an object or the floor nearer than ``FP_MAX_DEPTH`` (clutter
    stands on surfaces, not walls) and the raveled depth (also agent.exam_views' model)."""
    d = np.asarray(depth, float)
    flat_d = d.ravel()
    ok = np.isfinite(flat_d) & (flat_d > 0) & (flat_d < FP_MAX_DEPTH)
    points = np.asarray(camera.backproject(np.where(ok.reshape(d.shape), d, 0.0))).reshape(-1, 3)
    ids = np.asarray(ids).ravel()  # the image's instance ids
    valid = np.flatnonzero(ok & ((ids >= 0) | (points[:, 2] < FLOOR_Z)))
    return points, valid, flat_d


def false_positive_score(model: DetectorModel, fp_id: int) -> float:
    """A false positive's confidence: uniform in (0, max_score], from a stream keyed by its id
    (not the image's stream, which stays as it was before detections had scores)."""
    u = np.random.default_rng([abs(int(fp_id)) & 0xFFFFFFFFFFFFFFFF, 0x5C0E]).random()
    return float(model.fp_max_score * (1.0 - u))


def image_rng(seed: int, room_seed: int, sim_time: float) -> np.random.Generator:
    """The detector's stream for the image a body took at simulated second ``sim_time`` in room
    ``room_seed`` of a run seeded ``seed``: ``detection_rng`` with an image index made of the room
    and the image's time in whole microseconds (the same in a resumed run, whose replay charges
    the same seconds: rounding makes it immune to the last bits of float sums taken in another
    order)."""
    micros = int(round(float(sim_time) * 1e6)) & 0xFFFFFFFFFFFFFFFF
    return detection_rng(seed, (int(room_seed) & 0xFFFFFFFF) << 64 | micros)


def objects_by_id(
    layout_or_objects: RoomLayout | Iterable[ObjectInstance] | Mapping[int, ObjectInstance],
) -> dict[int, ObjectInstance]:
    """An id -> instance map from a layout, a sequence of instances or such a map."""
    if isinstance(layout_or_objects, RoomLayout):
        return {o.id: o for o in layout_or_objects.objects}
    if isinstance(layout_or_objects, Mapping):
        return dict(layout_or_objects)
    return {o.id: o for o in layout_or_objects}


def detect(
    frame: Frame,
    layout_or_objects: RoomLayout | Iterable[ObjectInstance] | Mapping[int, ObjectInstance],
    catalog: Catalog,
    model: DetectorModel | None = None,
    rng: np.random.Generator | None = None,
    false_positives: bool = True,
) -> list[Detection]:
    """Detections in a rendered ``Frame`` (its ``instance_ids``, ``depth`` if present, and the
    camera it came from) by the preset ``model`` (None: perfect; one that errs needs ``rng``);
    ``false_positives``: as ``detect_ids``."""
    cam = frame.camera
    return detect_ids(
        frame.instance_ids,
        objects_by_id(layout_or_objects),
        catalog,
        depth=frame.depth,
        camera_position=np.asarray(cam.position, float),
        fovy_deg=float(cam.fovy_deg),
        model=model,
        draws=None if rng is None else ImageDraws(rng, cam, false_positives),
    )


class SimDetector:
    """The simulated detector of one room: a preset, the room's objects and the run's seed; called
    with a frame and the body's simulated second after it, it gives the detections."""

    def __init__(
        self,
        model: DetectorModel,
        layout: RoomLayout,
        catalog: Catalog,
        seed: int = 0,
    ):
        self.model, self.catalog, self.seed = model, catalog, int(seed)
        self.room_seed = int(layout.seed)
        self.objects = objects_by_id(layout)
        self._last: tuple[Frame, _Image, _Visible] | None = None

    def __call__(self, frame: Frame, sim_time: float) -> list[Detection]:
        """The detections in ``frame`` (taken at ``sim_time``)."""
        rng = None if self.model.perfect else image_rng(self.seed, self.room_seed, sim_time)
        return detect(frame, self.objects, self.catalog, self.model, rng)

    def split(
        self, frame: Frame, sim_time: float
    ) -> tuple[list[Detection], Callable[[], list[Detection]]]:
        """``self(frame, sim_time)`` in two steps: the detections of true objects now, and a
        function giving all of them, false positives included, drawn only when it is called
        (they cost more than the rest: they back-project the whole depth image)."""
        if self.model.perfect:
            dets = detect(frame, self.objects, self.catalog, self.model)
            return dets, lambda: dets
        rng = image_rng(self.seed, self.room_seed, sim_time)
        img, vis = self._prepared(frame)
        true = sorted(_draw_model(vis, self.model, rng), key=by_pixels)
        done: list[list[Detection]] = []

        def full() -> list[Detection]:
            if not done:
                cam = frame.camera
                fps = _false_positives(img, self.model, rng, self.catalog, cam, frame.depth)
                done.append(sorted(true + fps, key=by_pixels))
            return done[0]

        return true, full

    def _prepared(self, frame: Frame) -> tuple[_Image, _Visible]:
        """The frame's image and visible instances, kept for the last frame read: the oracle
        reads one frame at many seconds (``split``'s draws are then all that is new)."""
        if self._last is None or self._last[0] is not frame:
            cam = frame.camera
            img = _image(frame.instance_ids, frame.depth, float(cam.fovy_deg))
            pos = np.asarray(cam.position, float)
            vis = _visible(img, img.candidates(), self.objects, self.catalog, pos, self.model)
            self._last = (frame, img, vis)
        return self._last[1], self._last[2]
