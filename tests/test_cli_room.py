"""``ctxsearch room``: builds a room and writes the overview, views and recording (render-marked)."""

from __future__ import annotations

import argparse

import cv2
import numpy as np
import pytest

from ctxsearch.scripts import cli, cmd_room, room_views


def test_room_is_registered():
    assert "ctxsearch.scripts.cmd_room" in cli.COMMAND_MODULES


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="ctxsearch")
    cmd_room.register(parser.add_subparsers(dest="command"))
    return parser.parse_args(argv)


def test_arguments_and_defaults(tmp_path):
    args = _parse(["room", "--out", str(tmp_path)])
    assert (args.style, args.seed, args.views, args.width, args.height, args.record) == (
        "office",
        0,
        4,
        320,
        240,
        None,
    )


def test_bad_arguments_are_one_line_errors(tmp_path):
    from ctxsearch.knowledge.errors import CtxsearchError

    for argv in (["--views", "-1"], ["--width", "100000"]):
        args = _parse(["room", "--out", str(tmp_path), *argv])
        with pytest.raises(CtxsearchError):
            args.func(args)


@pytest.mark.render
def test_room_writes_overview_views_and_recording(tmp_path, capsys):
    import rerun as rr

    out = tmp_path / "room"
    rrd = tmp_path / "room.rrd"
    args = _parse(
        [
            "room",
            "--style",
            "office",
            "--seed",
            "1",
            "--out",
            str(out),
            "--views",
            "2",
            "--record",
            str(rrd),
        ]
    )
    assert args.func(args) == 0
    printed = capsys.readouterr().out
    overview = cv2.imread(str(out / "overview.png"))
    assert overview is not None and overview.shape == (480, 640, 3)
    assert overview.std() > 10  # not a blank image
    views = sorted(out.glob("view_*.png"))
    assert len(views) == 2
    for v in views:
        img = cv2.imread(str(v))
        assert img is not None and img.shape[0] >= 240 and img.std() > 10
        assert f"wrote {v}" in printed
    # Every view shows furniture: the printed detections name at least one furniture type.
    for line in (ln for ln in printed.splitlines() if ln.strip().startswith("view ")):
        assert any(
            t in line.split("detected:")[1] for t in ("Desk", "Shelf", "Cabinet", "Table", "Chair")
        )
    entities = {c.entity_path for c in rr.chunk.RrdReader(rrd).stream()}
    assert {
        "/world/room/walls",
        "/world/camera/image/rgb",
        "/world/camera/image/detections",
    } <= entities
    assert any(e.startswith("/world/objects/Desk_") for e in entities)
    assert any(e.startswith("/world/volumes/Desk_") for e in entities)
    from tests.rrd_files import read_rrd

    f = read_rrd(rrd)
    assert f.name == "room: office, seed 1" and f.timelines == {("sim_time",)}
    assert f.recordings[0].application_id == "ctxsearch-room"
    assert {
        ("3D", "world"),
        ("2D", "world/camera/image"),
        ("2D", "world/camera/depth"),
        ("TextLog", "log"),
    } == {(v["class"], v["origin"]) for v in f.views}
    assert [t for t, x in f.texts if x.startswith("view 1:")] > [0]  # views at their sim_time


@pytest.mark.render
def test_room_without_record_or_views(tmp_path):
    args = _parse(["room", "--seed", "2", "--out", str(tmp_path), "--views", "0"])
    assert args.func(args) == 0
    assert (tmp_path / "overview.png").exists()
    assert not list(tmp_path.glob("view_*.png"))
    assert not list(tmp_path.glob("*.rrd"))


def test_draw_detections_enlarges_and_labels(catalog):
    from ctxsearch.envs.detector import Detection
    from ctxsearch.knowledge.geometry import ObjectInstance

    desk = ObjectInstance("Desk", 1, (0, 0, 0.37), 0.0, (0.7, 1.4, 0.74))
    dets = [
        Detection(1, "Desk", desk, 500, 2.0, (10, 20, 100, 120)),
        Detection(1, "Desk", desk, 400, 2.5, (12, 22, 90, 110)),
    ]
    img = room_views.draw_detections(np.zeros((240, 320, 3), np.uint8), dets, catalog)
    assert img.shape == (480, 640, 3)
    assert img.any()


@pytest.mark.render
def test_room_names_a_false_detection_as_such(tmp_path, capsys):
    """Office seed 0's third view holds a detection of clutter: printed as "a false detection
    (TYPE)", never by its raw negative id."""
    args = _parse(["room", "--seed", "0", "--out", str(tmp_path), "--views", "3"])
    assert args.func(args) == 0
    printed = capsys.readouterr().out
    assert "detected: " in printed and "a false detection (" in printed
    assert "#-" not in printed


def test_a_detection_is_labelled_for_a_reader():
    from ctxsearch.envs.detector import Detection
    from ctxsearch.knowledge.geometry import ObjectInstance

    pose = ObjectInstance("Remote", -38876137650113, (0.0, 0.0, 0.0), 0.0, (0.1, 0.05, 0.02))
    false = Detection(-38876137650113, "Remote", pose, 40, 2.0, (0, 0, 5, 5), 0.3)
    true = Detection(11, "Cup", pose, 40, 2.0, (0, 0, 5, 5))
    assert room_views.detection_label(false) == "a false detection (Remote)"
    assert room_views.detection_label(true) == "Cup#11"


def test_room_remembered_draws_the_tour_beside_the_plan(tmp_path, capsys):
    import json

    from ctxsearch.scripts.cli import main

    out = tmp_path / "r"
    args = ["room", "--style", "office", "--seed", "3", "--out", str(out), "--views", "0",
            "--remembered", "--detector", "perfect"]  # fmt: skip
    assert main(args) == 0
    doc = json.loads((out / "remembered.json").read_text())
    assert doc["furniture"] == doc["recognised"] + doc["misses"] and doc["furniture"] > 0
    assert doc["phantoms"] == 0 and doc["lookalikes"] == 0  # the perfect detector
    assert (out / "remembered.png").stat().st_size > 1000
    assert "the robot's remembered map:" in capsys.readouterr().out
