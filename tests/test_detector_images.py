"""The detector presets applied to segmentation images (envs.detector.detect_ids): the perfect
preset reproduces the threshold detector of before detector models exactly (the old code path,
kept here as the reference), and the realistic one errs at its configured rates over many
images."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ctxsearch.envs.camera import PinholeCamera, camera_axes
from ctxsearch.envs.detector import (
    Detection,
    ImageDraws,
    box_distance,
    detect_ids,
    image_rng,
    load_detector,
    min_pixels_at,
    parse_detector,
    ray_scale,
)
from ctxsearch.knowledge.geometry import ObjectInstance

DESK = ObjectInstance("Desk", 3, (2.0, 0.0, 0.37), 0.0, (0.7, 1.4, 0.74))
CUP = ObjectInstance("Cup", 7, (2.0, 0.2, 0.79), 0.0, (0.08, 0.08, 0.10))
PHONE = ObjectInstance("Phone", 9, (1.5, -0.3, 0.76), 0.3, (0.07, 0.15, 0.01))
PEN = ObjectInstance("Pen", 11, (1.8, 0.4, 0.75), 1.0, (0.14, 0.01, 0.01))
OBJECTS = {o.id: o for o in (DESK, CUP, PHONE, PEN)}


def _old_detect_ids(ids, objects, catalog, depth=None, camera_position=None, fovy_deg=None):
    """The detector as it was before presets (agent/perception.py at 0dff5d5), verbatim."""
    h, w = ids.shape
    flat = ids.ravel()
    depth_flat = None if depth is None else np.asarray(depth).ravel()
    counts = np.bincount((flat.astype(np.int64) + 1).clip(0))
    out = []
    candidates = np.flatnonzero(counts[1:]) if len(counts) > 1 else np.zeros(0, int)
    scale = None
    for oid in candidates:
        oid = int(oid)
        obj = objects.get(oid)
        if obj is None:
            continue
        typ = catalog.type(obj.type)
        n = int(counts[oid + 1])
        if n < min_pixels_at(typ.min_pixels, w, h):
            continue
        idx = np.flatnonzero(flat == oid)
        if depth is not None:
            d = depth_flat[idx]
            if fovy_deg is not None:
                if scale is None:
                    scale = ray_scale(w, h, float(fovy_deg)).ravel()
                d = d * scale[idx]
            dist = float(np.median(d))
        else:
            dist = box_distance(camera_position, obj)
        if dist > typ.max_range:
            continue
        rows, cols = np.divmod(idx, w)
        bbox = (int(cols.min()), int(rows[0]), int(cols.max()), int(rows[-1]))
        out.append(Detection(oid, obj.type, obj, n, dist, bbox))
    out.sort(key=lambda d: (-d.pixels, d.instance_id))
    return out


def _random_image(rng: np.random.Generator, h: int = 60, w: int = 80):
    """A segmentation image of random blobs of the OBJECTS (and unknown ids) with random depth."""
    ids = np.full((h, w), -1, np.int32)
    for oid in [*OBJECTS, 99]:
        for _ in range(int(rng.integers(0, 3))):
            y0, x0 = int(rng.integers(h)), int(rng.integers(w))
            ids[y0 : y0 + int(rng.integers(1, 25)), x0 : x0 + int(rng.integers(1, 25))] = oid
    depth = rng.uniform(0.3, 7.0, (h, w)).astype(np.float32)
    return ids, depth


def _camera(h: int = 60, w: int = 80) -> PinholeCamera:
    return PinholeCamera(np.array([0.0, 0.0, 1.2]), camera_axes(0.0, -0.3), 45.0, w, h)


def test_perfect_preset_is_byte_identical_to_the_old_detector(catalog):
    perfect = load_detector("perfect", catalog)
    rng = np.random.default_rng(11)
    for k in range(300):
        ids, depth = _random_image(rng)
        kw = [
            {"depth": depth, "fovy_deg": 45.0},
            {"depth": depth},
            {"camera_position": np.array([0.0, 0.0, 1.2])},
        ][k % 3]
        old = _old_detect_ids(ids, OBJECTS, catalog, **kw)
        for model in (None, perfect):
            new = detect_ids(ids, OBJECTS, catalog, model=model, **kw)
            assert repr(new) == repr(old)  # the same floats to the last bit, the same order


def test_perfect_preset_draws_no_random_numbers(catalog):
    class NoDraws(np.random.Generator):
        def __getattribute__(self, name):
            raise AssertionError(f"the perfect detector drew from its rng ({name})")

    ids, depth = _random_image(np.random.default_rng(0))
    perfect = load_detector("perfect", catalog)
    rng = NoDraws(np.random.PCG64(0))
    detect_ids(ids, OBJECTS, catalog, depth=depth, model=perfect, draws=ImageDraws(rng, _camera()))


def _rate(dets_per_image, pred) -> float:
    return sum(1 for dets in dets_per_image for d in dets if pred(d)) / len(dets_per_image)


def test_realistic_recall_rises_with_pixels_and_falls_with_distance(catalog):
    model = load_detector("realistic", catalog)
    cup_min = catalog.type("Cup").min_pixels
    cup_range = catalog.type("Cup").max_range

    def share(side: int, dist: float, n: int = 600) -> float:
        ids = np.full((240, 320), -1, np.int32)
        ids[:side, :side] = CUP.id
        depth = np.full(ids.shape, dist, np.float32)
        hits = 0
        for i in range(n):
            dets = detect_ids(ids, OBJECTS, catalog, depth=depth, model=model,
                              draws=ImageDraws(image_rng(1, 2, float(i))))  # fmt: skip
            hits += any(d.instance_id == CUP.id for d in dets)
        return hits / n

    side = int(math.ceil(math.sqrt(3 * cup_min)))
    near_small, near_big = share(side // 2, 1.0), share(3 * side, 1.0)
    far_big = share(3 * side, 0.95 * cup_range)
    assert near_small < near_big - 0.2  # more pixels, more recall
    assert far_big < near_big - 0.2  # farther, less recall
    tol = 4 * math.sqrt(0.25 / 600)
    expected = float(model.recall_prob(catalog.type("Cup"), (3 * side) ** 2, 1.0, 320, 240))
    assert near_big == pytest.approx(expected, abs=tol)


def test_confusion_and_false_positives_at_their_rates(catalog):
    model = load_detector("realistic", catalog)
    ids = np.full((240, 320), -1, np.int32)
    ids[0:120, 0:120] = PHONE.id  # large and near: recall close to max_recall
    depth = np.full(ids.shape, 1.0, np.float32)
    n = 4000
    images = [
        detect_ids(
            ids,
            OBJECTS,
            catalog,
            depth=depth,
            model=model,
            draws=ImageDraws(image_rng(5, 9, float(i)), _camera(240, 320)),
            fovy_deg=45.0,
        )  # fmt: skip
        for i in range(n)
    ]
    phone_hits = [d for dets in images for d in dets if d.instance_id == PHONE.id]
    p_conf = dict(model.confusions("Phone"))["Remote"]
    share = sum(d.type == "Remote" for d in phone_hits) / len(phone_hits)
    assert abs(share - p_conf) < 4 * math.sqrt(p_conf * (1 - p_conf) / len(phone_hits))
    assert {d.pose.type for d in phone_hits if d.type == "Remote"} == {"Remote"}
    fp = _rate(images, lambda d: d.instance_id < 0)
    assert abs(fp - model.fp_per_image) < 4 * math.sqrt(model.fp_per_image / n)
    fps = [d for dets in images for d in dets if d.instance_id < 0]
    assert {d.type for d in fps} <= set(model.fp_types)
    # Only on pixels that show an object or the floor (here: the phone's).
    assert all(d.pose.position[0] > 0 for d in fps)
    assert len({d.instance_id for d in fps}) == len(fps)  # never the same id twice
    # A false positive stands on the surface the image shows: its distance is the pixel's ray.
    cam = _camera(240, 320)
    for d in fps[:20]:
        base = np.array(d.pose.position) - (0, 0, d.pose.size[2] / 2)
        assert np.linalg.norm(base - cam.position) == pytest.approx(d.distance, rel=1e-6)


def test_pose_noise_and_the_same_seed_the_same_detections(catalog):
    model = load_detector("realistic", catalog)
    ids = np.full((60, 80), -1, np.int32)
    ids[0:40, 0:40] = DESK.id
    ids[45:55, 50:60] = CUP.id
    depth = np.full(ids.shape, 1.0, np.float32)
    a = detect_ids(ids, OBJECTS, catalog, depth=depth, model=model, draws=ImageDraws(image_rng(7, 1, 12.5), _camera()))  # fmt: skip
    b = detect_ids(ids, OBJECTS, catalog, depth=depth, model=model, draws=ImageDraws(image_rng(7, 1, 12.5), _camera()))  # fmt: skip
    assert repr(a) == repr(b)
    moved = [
        d for d in a if d.instance_id > 0 and d.pose.position != OBJECTS[d.instance_id].position
    ]
    assert moved  # the realistic preset estimates poses with an error
    other = [
        detect_ids(
            ids,
            OBJECTS,
            catalog,
            depth=depth,
            model=model,
            draws=ImageDraws(image_rng(7, 1, t), _camera()),
        )  # fmt: skip
        for t in (13.5, 14.5, 15.5)
    ]
    assert any(repr(o) != repr(a) for o in other)


def test_a_model_needs_its_rng(catalog):
    model = parse_detector(
        {
            "kind": "model",
            "recall": {
                "max_recall": 0.9,
                "half_pixels": 2.0,
                "slope": 2.0,
                "range_fraction": 0.8,
                "range_width": 0.1,
            },  # fmt: skip
            "pose": {
                "position_sigma": 0.0,
                "position_sigma_per_m": 0.0,
                "yaw_sigma_deg": 0.0,
                "yaw_sigma_deg_per_m": 0.0,
            },  # fmt: skip
            "false_positives": {"per_image": 0.0},
        }
    )
    ids, depth = _random_image(np.random.default_rng(1))
    with pytest.raises(ValueError, match="rng"):
        detect_ids(ids, OBJECTS, catalog, depth=depth, model=model)


@pytest.mark.render
def test_a_resumed_realistic_run_equals_an_uninterrupted_one(tmp_path, catalog):
    from ctxsearch.agent.learning import LearnConfig, learn
    from ctxsearch.knowledge.store import EvidenceStore

    def run(path, limit):
        cfg = LearnConfig("office", 1, path, perception="camera", progress=False,
                          max_examinations=limit)  # fmt: skip
        return learn(cfg, catalog=catalog)

    whole = run(tmp_path / "a.sqlite", 6)
    assert (
        whole.run == "hif/camera+realistic+ref2/seed=0/map=built" and whole.detector == "realistic"
    )
    run(tmp_path / "b.sqlite", 3)
    resumed = run(tmp_path / "b.sqlite", 3)  # replays 3 (with images), then 3 new
    assert resumed.examinations == 3

    def rows(path):
        with EvidenceStore.open(path, catalog, read_only=True) as st:
            return [(e.object_id, e.type, e.related, e.sim_time) for e in st.examinations()]

    assert rows(tmp_path / "a.sqlite") == rows(tmp_path / "b.sqlite")


def test_scores_are_the_recall_for_true_boxes_and_weak_for_clutter(catalog):
    """A true detection scores the model's recall at its pixels and distance (a look-alike report
    the same), a false positive uniformly in (0, max_score]; the perfect detector scores 1."""
    model = load_detector("realistic", catalog)
    ids = np.full((240, 320), -1, np.int32)
    ids[0:120, 0:120] = PHONE.id
    ids[200:206, 300:306] = CUP.id  # small: a low recall
    depth = np.full(ids.shape, 1.0, np.float32)
    images = [
        detect_ids(ids, OBJECTS, catalog, depth=depth, model=model,
                   draws=ImageDraws(image_rng(3, 4, float(i)), _camera(240, 320)), fovy_deg=45.0)
        for i in range(3000)
    ]  # fmt: skip
    dets = [d for im in images for d in im]
    true = [d for d in dets if d.instance_id > 0]
    for d in true[:50]:
        typ = catalog.type(OBJECTS[d.instance_id].type)
        want = model.recall_prob(typ, d.pixels, d.distance, 320, 240)
        assert d.score == pytest.approx(float(want))
    phone = {round(d.score, 12) for d in true if d.instance_id == PHONE.id}
    cup = {round(d.score, 12) for d in true if d.instance_id == CUP.id}
    assert len(phone) == 1 and len(cup) == 1 and min(phone) > 0.9 > 0.5 > max(cup)
    assert any(d.type == "Remote" for d in true)  # confusions keep their box's score
    assert {round(d.score, 12) for d in true if d.type == "Remote"} == phone
    fps = [d.score for d in dets if d.instance_id < 0]
    assert len(fps) > 50 and min(fps) > 0 and max(fps) <= model.fp_max_score == 0.5
    assert abs(np.mean(fps) - 0.25) < 0.05  # uniform on (0, 0.5]
    perfect = detect_ids(ids, OBJECTS, catalog, depth=depth, model=load_detector("perfect"))
    assert perfect and all(d.score == 1.0 for d in perfect)


def test_split_detections_are_the_full_detections_in_two_steps(catalog):
    """``SimDetector.split``: the true detections now and every detection (false positives
    drawn from the same stream afterwards) when asked: the same list ``SimDetector`` gives."""
    from ctxsearch.envs.camera import Frame
    from ctxsearch.envs.detector import SimDetector
    from ctxsearch.envs.layout import RoomLayout

    layout = RoomLayout("t", 4, 5.0, 4.0, 2.6, None, tuple(OBJECTS.values()))
    rng = np.random.default_rng(3)
    for name in ("realistic", "perfect"):
        sim = SimDetector(load_detector(name, catalog), layout, catalog, 7)
        fps = 0
        for i in range(300):
            ids, depth = _random_image(rng)
            frame = Frame(None, depth, ids, _camera(), None)
            true, full = sim.split(frame, 0.25 * i)
            want = sim(frame, 0.25 * i)
            assert full() == want and full() is full()  # drawn once
            assert true == [d for d in want if d.instance_id >= 0]
            fps += sum(d.instance_id < 0 for d in want)
        assert fps > 0 or name == "perfect"
