"""Detector presets: validation, the recall curve's shape, confusion and false-positive rates,
pose noise, and the perfect preset's exact thresholds."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from ctxsearch.envs.detector import (
    DetectorError,
    detection_rng,
    keep,
    load_detector,
    min_pixels_at,
    parse_detector,
)
from ctxsearch.knowledge.geometry import ObjectInstance


@pytest.fixture(scope="module")
def realistic(catalog):
    return load_detector("realistic", catalog)


def test_shipped_presets_load(catalog):
    assert load_detector("perfect", catalog).perfect
    assert not load_detector("realistic", catalog).perfect


def test_perfect_thresholds_exactly(catalog):
    perfect = load_detector("perfect")
    cup = catalog.type("Cup")
    for w, h in ((320, 240), (640, 480), (160, 120)):
        need = min_pixels_at(cup.min_pixels, w, h)
        assert perfect.recall_prob(cup, need, cup.max_range, w, h) == 1.0
        assert perfect.recall_prob(cup, need - 1, 0.5, w, h) == 0.0
        assert perfect.recall_prob(cup, 10 * need, cup.max_range + 1e-9, w, h) == 0.0
    # It draws nothing: no rng needed, and a false positive never appears.
    mask = keep(perfect, [cup, cup], np.array([100, 3]), np.array([1.0, 1.0]), (320, 240), None)
    assert mask.tolist() == [True, False]
    assert perfect.false_positives(None, lambda r: None, catalog, -2) == []


def test_recall_rises_with_pixels_and_falls_with_distance(catalog, realistic):
    for name in ("Cup", "Pen", "Desk"):
        t = catalog.type(name)
        by_px = realistic.recall_prob(t, np.geomspace(1, 5000, 40), 1.0, 320, 240)
        assert np.all(np.diff(by_px) > 0) and by_px[0] < 0.05 and by_px[-1] > 0.85
        by_d = realistic.recall_prob(
            t, 50 * t.min_pixels, np.linspace(0, 2 * t.max_range, 40), 320, 240
        )
        assert np.all(np.diff(by_d) < 0) and by_d[-1] < 0.01
    # The curve is in pixels at 320x240: the same share of the image, the same recall.
    cup = catalog.type("Cup")
    assert realistic.recall_prob(cup, 40, 1.0, 320, 240) == pytest.approx(
        realistic.recall_prob(cup, 160, 1.0, 640, 480)
    )


def test_detections_follow_recall_at_its_rate(catalog, realistic):
    cup = catalog.type("Cup")
    p = float(realistic.recall_prob(cup, 50, 2.0, 320, 240))
    n = 4000
    mask = keep(
        realistic, [cup] * n, np.full(n, 50), np.full(n, 2.0), (320, 240), detection_rng(3, 0)
    )
    assert abs(mask.mean() - p) < 4 * math.sqrt(p * (1 - p) / n)


def test_confusion_at_its_rate(realistic):
    rng = np.random.default_rng(0)
    n = 20000
    reported = [realistic.reported_type("Phone", rng) for _ in range(n)]
    share = reported.count("Remote") / n
    assert abs(share - 0.05) < 4 * math.sqrt(0.05 * 0.95 / n)
    assert set(reported) == {"Phone", "Remote"}
    assert realistic.reported_type("Monitor", rng) == "Monitor"  # no look-alike configured


def test_false_positives_at_their_rate(catalog, realistic):
    rng = np.random.default_rng(1)
    point = (np.array([1.0, 2.0, 0.75]), 2.5)
    counts = [
        len(realistic.false_positives(rng, lambda r: point, catalog, -2)) for _ in range(8000)
    ]
    mean = float(np.mean(counts))
    assert abs(mean - 0.05) < 4 * math.sqrt(0.05 / 8000)
    fps = [
        fp
        for _ in range(2000)
        for fp in realistic.false_positives(rng, lambda r: point, catalog, -2)
    ]
    assert fps and all(o.type in realistic.fp_types and o.id <= -2 for o, _ in fps)
    assert all(o.bottom == pytest.approx(0.75) for o, _ in fps)  # standing on the surface point


def test_pose_noise_grows_with_distance(realistic):
    obj = ObjectInstance("Cup", 3, (1.0, 1.0, 0.8), 0.0, (0.08, 0.08, 0.1))
    rng = np.random.default_rng(2)

    def spread(d):
        return np.std([realistic.noisy_pose(obj, d, rng).position[0] for _ in range(3000)])

    near, far = spread(0.5), spread(5.0)
    assert near == pytest.approx(0.02 + 0.02 * 0.5, rel=0.1)
    assert far == pytest.approx(0.02 + 0.02 * 5.0, rel=0.1)
    assert realistic.noisy_pose(obj, 5.0, rng).position[2] == 0.8


def test_seeded_streams_repeat():
    a = detection_rng(7, 12).random(5)
    assert np.array_equal(a, detection_rng(7, 12).random(5))
    assert not np.array_equal(a, detection_rng(7, 13).random(5))


@pytest.mark.parametrize(
    "doc, field",
    [
        ({"kind": "fancy"}, "kind"),
        ({"kind": "perfect", "recall": {}}, "kind"),
        ({"kind": "model"}, "recall"),
        ({"kind": "model", "recall": {"max_recall": float("nan")}}, "recall"),
        ({"kind": "perfect", "colour": 1}, None),
    ],
)
def test_bad_presets_name_the_field(doc, field):
    with pytest.raises(DetectorError) as exc:
        parse_detector(doc, "x.toml")
    msg = str(exc.value)
    assert msg.startswith("x.toml") and "\n" not in msg
    if field:
        assert f"field '{field}" in msg


def test_bad_numbers_and_types_are_refused(catalog, tmp_path):
    with open(load_detector("realistic").path) as fh:
        good = fh.read()
    for old, new, expect in [
        ("max_recall = 0.95", "max_recall = 1.5", "recall.max_recall"),
        ("slope = 2.5", "slope = inf", "recall.slope"),
        ("per_image = 0.05", "per_image = -1", "false_positives.per_image"),
        ("max_score = 0.5", "max_score = 0", "false_positives.max_score"),
        ("max_score = 0.5", 'max_score = "high"', "false_positives.max_score"),
        ('b = "Remote"', 'b = "Walkman"', "confusion"),
        ("p = 0.05", "p = 1.5", "confusion[1].p"),
        ("p = 0.04", "p = 0.99", "add up to more than 1"),
    ]:
        f = tmp_path / "d.toml"
        f.write_text(good.replace(old, new, 1))
        with pytest.raises(DetectorError, match=re.escape(expect)):
            load_detector(f, catalog)
    f = tmp_path / "bin.toml"
    f.write_bytes(b"\xff\xfe k\x00i\x00")
    with pytest.raises(DetectorError, match="UTF-8"):
        load_detector(f)
    with pytest.raises(DetectorError, match="no such detector preset"):
        load_detector("nonexistent")


def test_special_files_as_detector_get_their_own_message(tmp_path, monkeypatch):
    """A FIFO or a device given as --detector is named as what it is (and never read: a FIFO
    would block), not called a missing preset; so is a FIFO given by a bare name."""
    import os

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    monkeypatch.chdir(tmp_path)
    for given, kind in [(fifo, "a FIFO"), ("pipe", "a FIFO"), ("/dev/null", "a character device")]:
        with pytest.raises(DetectorError) as err:
            load_detector(given)
        assert f"is {kind}" in str(err.value) and "no such detector preset" not in str(err.value)
