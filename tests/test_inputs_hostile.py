"""Hostile inputs where data enters (issue 9): catalog and style files, ground-truth files, flags.
Each gets a one-line ``ctxsearch: error: ...`` (or argparse's usage error), exit 2, never a
traceback or a silently wrong value."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from ctxsearch.envs.styles import STYLES_DIR, StyleError, load_style
from ctxsearch.envs.truth import TruthError, load_truth
from ctxsearch.knowledge.catalog import DEFAULT_CATALOG, load_catalog
from ctxsearch.knowledge.errors import CatalogError, CtxsearchError
from ctxsearch.scripts.cli import main


def _one_line_error(capsys, *fragments: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for f in fragments:
        assert f in err, err
    return err


# ---- encodings --------------------------------------------------------------------------------
ENCODINGS = {
    "binary": b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe\xfd",
    "utf-16": DEFAULT_CATALOG.read_text().encode("utf-16"),
    "latin-1": '[[type]]\nname = "Caf\xe9"\n'.encode("latin-1"),
}


@pytest.mark.parametrize("kind", sorted(ENCODINGS))
def test_catalog_and_style_files_that_are_not_utf8_are_one_line_errors(tmp_path, capsys, kind):
    bad = tmp_path / "bad.toml"
    bad.write_bytes(ENCODINGS[kind])
    with pytest.raises(CatalogError, match=r"bad.toml: not UTF-8 text|bad.toml: TOML syntax"):
        load_catalog(bad)
    with pytest.raises(StyleError, match=r"bad.toml: not UTF-8 text|bad.toml: TOML syntax"):
        load_style(bad, load_catalog())
    assert main(["kb", "show", str(tmp_path / "x.sqlite"), "--catalog", str(bad)]) == 2
    _one_line_error(capsys, "bad.toml")
    assert main(["truth", "--style", str(bad), "--samples", "1", "--out", str(tmp_path / "t")]) == 2
    _one_line_error(capsys, "bad.toml")


# ---- numbers in the catalog -------------------------------------------------------------------
def _catalog_with(tmp_path: Path, old: str, new: str) -> Path:
    text = DEFAULT_CATALOG.read_text()
    assert old in text
    p = tmp_path / "types.toml"
    p.write_text(text.replace(old, new, 1))
    return p


def _first_type_block() -> str:
    text = DEFAULT_CATALOG.read_text()
    start = text.index("[[type]]")
    return text[start : text.index("[[type]]", start + 1)]


def _field_line(field: str) -> str:
    return next(ln for ln in _first_type_block().splitlines() if ln.split("=")[0].strip() == field)


@pytest.mark.parametrize(
    "field, value, match",
    [
        ("size", "[nan, 1.0, 0.7]", "finite numbers"),
        ("size", "[inf, 1.0, 0.7]", "finite numbers"),
        ("size", "[1e300, 1.0, 0.7]", "finite numbers"),
        ("size", "[[1.0, nan], [0.5, 0.7], [0.7, 0.8]]", "finite sizes"),
        ("size", "[[nan, 1.0], [0.5, 0.7], [0.7, 0.8]]", "finite sizes"),
        ("max_range", "nan", "positive number of metres"),
        ("max_range", "inf", "positive number of metres"),
        ("max_range", "1e300", "positive number of metres"),
        ("min_pixels", "10000000000000", "must be an integer in"),
        ("color", "[nan, 0.2, 0.2]", "finite numbers"),
    ],
)
def test_non_finite_or_absurd_catalog_numbers_are_refused(tmp_path, field, value, match):
    line = _field_line(field)
    p = _catalog_with(tmp_path, line, f"{field} = {value}")
    with pytest.raises(CatalogError, match=match):
        load_catalog(p)


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e300"])
@pytest.mark.parametrize("field", ["margin_hi", "lo"])
def test_a_non_finite_relation_volume_is_refused(tmp_path, field, value):
    """A NaN margin used to pass and make P(ON-TOP-OF-DESK(Monitor)) 0.00 (no overlap ever)."""
    text = DEFAULT_CATALOG.read_text()
    i = text.index('name = "ON-TOP-OF-DESK"')
    j = text.index(f"{field} = [", i)
    k = text.index("]", j)
    p = tmp_path / "types.toml"
    p.write_text(text[:j] + f"{field} = [0, 0, {value}" + text[k:])
    with pytest.raises(CatalogError, match="ON-TOP-OF-DESK.*finite numbers"):
        load_catalog(p)


# ---- numbers in a style -----------------------------------------------------------------------
@pytest.mark.parametrize(
    "room, match",
    [
        ("width = [nan, 5.0]", "expected a number or a"),
        ("width = [4.0, inf]", "expected a number or a"),
        ("depth = nan", "expected a number or a"),
        ("width = [4.0, 1e300]", "must be at most 50"),
        ("height = [2.5, 1e9]", "must be at most 10"),
        ("door_width = inf", "expected a number or a"),
    ],
)
def test_non_finite_or_absurd_room_dimensions_are_refused(tmp_path, room, match):
    text = (STYLES_DIR / "office.toml").read_text()
    key = room.split("=")[0].strip()
    lines = text.splitlines()
    i = next(i for i, ln in enumerate(lines) if ln.split("=")[0].strip() == key)
    p = tmp_path / "office.toml"
    p.write_text("\n".join([*lines[:i], room, *lines[i + 1 :]]))
    with pytest.raises(StyleError, match=match):
        load_style(p, load_catalog())


# ---- ground-truth files -----------------------------------------------------------------------
@pytest.fixture(scope="module")
def truth_doc() -> dict:
    from ctxsearch.envs.truth import ground_truth

    return ground_truth("office", 3, 0)


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda d: {}, "no 'style'"),
        (lambda d: [], "expected a JSON object"),
        (lambda d: d | {"entries": []}, "no 'entries'"),
        (lambda d: d | {"entries": {"a": 1}}, "no 'entries'"),
        (lambda d: d | {"samples": -3}, "'samples' must be"),
        (lambda d: d | {"catalog": "0000"}, "catalog fingerprint"),
        (lambda d: d | {"style": "kitchen"}, "style 'kitchen', not 'office'"),
        (lambda d: d | {"entries": [1, 2]}, "entry 0 is not an object"),
        (lambda d: d | {"entries": [d["entries"][0] | {"p": 7}]}, "p must be a number in"),
        (lambda d: d | {"entries": [d["entries"][0] | {"p": None}]}, "p must be a number in"),
        (lambda d: d | {"entries": [d["entries"][0] | {"n": 0}]}, "n must be a positive"),
        (lambda d: d | {"entries": [d["entries"][0] | {"ref": "Ghost"}]}, "not both in"),
        (lambda d: d | {"entries": [d["entries"][0] | {"relation": "X"}]}, "not a relation of"),
    ],
)
def test_a_ground_truth_file_of_the_wrong_shape_is_refused(tmp_path, truth_doc, mutate, match):
    p = tmp_path / "truth.json"
    p.write_text(json.dumps(mutate(json.loads(json.dumps(truth_doc)))))
    with pytest.raises(TruthError, match=match) as err:
        load_truth(p, load_catalog(), "office")
    assert str(err.value).startswith(str(p)) and "\n" not in str(err.value)


@pytest.mark.parametrize(
    "raw, match",
    [
        (b'{"style": "office", "p": NaN}', "NaN is not a number"),
        (b"\xff\xfe{\x00", "not UTF-8"),
        (b"[" * 100_000, "nested too deeply|not a ground-truth JSON"),
        (b"", "not a ground-truth JSON file"),
    ],
)
def test_a_ground_truth_file_that_is_not_json_is_refused(tmp_path, raw, match):
    p = tmp_path / "truth.json"
    p.write_bytes(raw)
    with pytest.raises(TruthError, match=match):
        load_truth(p, load_catalog())


def test_search_reads_a_valid_truth_file_and_refuses_an_empty_one(tmp_path, truth_doc):
    from ctxsearch.agent.search.priors import truth_probabilities

    catalog = load_catalog()
    p = tmp_path / "truth.json"
    p.write_text(json.dumps(truth_doc))
    probs = truth_probabilities("office", catalog, path=p)
    e = max(truth_doc["entries"], key=lambda e: e["p"])
    assert math.isclose(probs.p(e["relation"], e["type"]), e["p"])
    p.write_text("{}")
    with pytest.raises(CtxsearchError, match="not a usable ground-truth file"):
        truth_probabilities("office", catalog, path=p)


# ---- flags ------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv, message",
    [
        (["learn", "--style", "office", "--rooms", "1", "--kb", "k", "--seed", "-1"], "seed in"),
        (["learn", "--style", "office", "--rooms", "1000000000000", "--kb", "k"], "at most"),
        (["truth", "--style", "office", "--samples", "1", "--out", "o", "--seed", "-5"], "seed"),
        (["truth", "--style", "office", "--samples", "10000000000", "--out", "o"], "at most"),
        (["search", "--kb", "k", "--style", "office", "--target", "Cup", "--seed", "-2"], "seed"),
        (
            ["learn", "--style", "office", "--rooms", "1", "--kb", "k", "--room-budget", "1e300"],
            "sec",
        ),
    ],
)
def test_negative_seeds_and_absurd_counts_are_usage_errors(capsys, argv, message):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert message in err.splitlines()[-1] and "Traceback" not in err


def test_room_out_naming_an_existing_file_is_a_usage_error(tmp_path, capsys):
    f = tmp_path / "taken"
    f.write_text("keep me")
    with pytest.raises(SystemExit) as e:
        main(["room", "--style", "office", "--out", str(f)])
    assert e.value.code == 2
    assert "exists and is not a directory" in capsys.readouterr().err
    assert f.read_text() == "keep me"


def test_truth_out_naming_a_directory_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["truth", "--style", "office", "--samples", "1", "--out", str(tmp_path)])
    assert "is a directory" in capsys.readouterr().err


def test_ctrl_c_during_start_up_exits_130_without_a_traceback(monkeypatch, capsys):
    import ctxsearch.scripts.cli as cli

    def interrupted():
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "build_parser", interrupted)
    assert cli.main(["kb", "show", "x"]) == 130
    assert capsys.readouterr().err == "ctxsearch: interrupted\n"
