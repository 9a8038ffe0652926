"""``ctxsearch search`` and ``ctxsearch bench search`` through scripts.cli.main: one-line errors
for unknown targets, missing, empty or foreign stores; a small run writes its files."""

from __future__ import annotations

import csv
import json
import tomllib

import pytest

from ctxsearch.knowledge.catalog import DEFAULT_CATALOG, parse_catalog
from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.cli import main


def _one_line_error(capsys, code: int, pattern: str) -> str:
    out = capsys.readouterr()
    assert code == 2, (out.out, out.err)
    lines = [x for x in out.err.splitlines() if x.strip()]
    assert len(lines) == 1, out.err
    assert lines[0].startswith("ctxsearch: error: ")
    assert pattern in lines[0], lines[0]
    assert "Traceback" not in out.err
    return lines[0]


@pytest.fixture()
def store(tmp_path, desk_cup_store):
    return desk_cup_store(tmp_path / "kb.sqlite")


def test_unknown_target_is_a_one_line_error(store, capsys):
    code = main(["search", "--kb", str(store), "--style", "office", "--target", "Unicorn"])
    _one_line_error(capsys, code, "unknown target type 'Unicorn'")


def test_missing_store_is_a_one_line_error(tmp_path, capsys):
    code = main(
        ["search", "--kb", str(tmp_path / "nope.sqlite"), "--style", "office", "--target", "Cup"]
    )
    _one_line_error(capsys, code, "no such knowledge store")
    assert not (tmp_path / "nope.sqlite").exists()


def test_empty_store_is_a_one_line_error(tmp_path, catalog, capsys):
    path = tmp_path / "empty.sqlite"
    EvidenceStore.open(path, catalog, create=True).close()
    code = main(["search", "--kb", str(path), "--style", "office", "--target", "Cup"])
    _one_line_error(capsys, code, "empty")


def test_store_of_another_catalog_is_a_one_line_error(tmp_path, capsys):
    doc = tomllib.loads(DEFAULT_CATALOG.read_text())
    doc["type"][0]["max_range"] = float(doc["type"][0]["max_range"]) + 1.0  # a different catalog
    other = parse_catalog(doc, "other.toml")
    path = tmp_path / "other.sqlite"
    with EvidenceStore.open(path, other, create=True) as s:
        s.record(
            run="t",
            style="office",
            room_seed=0,
            object_id=1,
            ref_type="Desk",
            sim_time=0.0,
            strategy="t",
            related=[],
        )
    for argv in (
        ["search", "--kb", str(path), "--style", "office", "--target", "Cup"],
        [
            "bench",
            "search",
            "--kb",
            str(path),
            "--style",
            "office",
            "--episodes",
            "1",
            "--out",
            str(tmp_path / "b"),
        ],
    ):
        code = main(argv)
        _one_line_error(capsys, code, str(path))


def test_not_a_store_is_a_one_line_error(tmp_path, capsys):
    path = tmp_path / "notes.sqlite"
    path.write_text("hello\n")
    code = main(["search", "--kb", str(path), "--style", "office", "--target", "Cup"])
    _one_line_error(capsys, code, str(path))


def test_unknown_policy_in_bench_is_a_one_line_error(store, tmp_path, capsys):
    code = main(
        [
            "bench",
            "search",
            "--kb",
            str(store),
            "--episodes",
            "1",
            "--policies",
            "exhaustive,psychic",
            "--out",
            str(tmp_path / "b"),
        ]
    )
    _one_line_error(capsys, code, "unknown search policy 'psychic'")


@pytest.mark.render
def test_search_prints_the_outcome_and_records(store, tmp_path, capsys):
    rrd = tmp_path / "s.rrd"
    code = main(
        [
            "search",
            "--kb",
            str(store),
            "--style",
            "office",
            "--target",
            "Cup",
            "--policy",
            "location",
            "--budget-seconds",
            "60",
            "--record",
            str(rrd),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0
    assert "target Cup" in out and "simulated s" in out and "gazes" in out and "m driven" in out
    assert rrd.is_file() and rrd.stat().st_size > 1000


@pytest.mark.render
def test_bench_search_writes_its_four_files(store, tmp_path, capsys):
    out_dir = tmp_path / "bench"
    code = main(
        [
            "bench",
            "search",
            "--kb",
            str(store),
            "--style",
            "office",
            "--episodes",
            "2",
            "--policies",
            "exhaustive,location,oracle",
            "--budget-seconds",
            "30",
            "--out",
            str(out_dir),
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    doc = json.loads((out_dir / "search.json").read_text())
    assert doc["style"] == "office" and doc["episodes"] == 2
    for name in ("exhaustive", "location", "oracle"):
        entry = doc["policies"][name]
        for key in (
            "success_rate",
            "median_s",
            "median_ci",
            "mean_s",
            "gazes",
            "path_m",
            "ratio_to_exhaustive",
            "ratio_to_oracle",
        ):
            assert key in entry
    assert doc["policies"]["exhaustive"]["ratio_to_exhaustive"] == 1.0
    assert "| location |" in (out_dir / "search.md").read_text()
    assert (out_dir / "search.png").stat().st_size > 1000
    with (out_dir / "episodes.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 2 * 3  # episodes x policies
    assert {r["policy"] for r in rows} == {"exhaustive", "location", "oracle"}
    by_ep = {(int(r["episode"]), r["policy"]): r for r in rows}
    for ep in doc["episode_list"]:
        for name, got in ep["results"].items():
            row = by_ep[(ep["index"], name)]
            assert row["target"] == ep["target"] and int(row["room_seed"]) == ep["room_seed"]
            assert row["found"] == ("true" if got["found"] else "false")
            assert float(row["sim_s"]) == pytest.approx(got["t"], abs=1e-3)
            assert int(row["gazes"]) == got["gazes"]
            assert float(row["time_to_find_s"]) <= float(row["budget_s"]) == 30.0


def test_the_parser_reads_the_policy_registry_and_the_modes():
    """The CLI's policy names, defaults and modes are the registry's and the enums' (read, not
    copied), and each default runs in its scenario."""
    from ctxsearch.agent.search.registry import POLICIES, resolve
    from ctxsearch.knowledge.options import MapMode
    from ctxsearch.scripts import cmd_search

    assert tuple(POLICIES) == cmd_search.POLICY_NAMES
    for scenario in MapMode:
        resolve(cmd_search.DEFAULT_POLICIES[scenario].split(","), scenario)
        assert scenario in POLICIES[cmd_search.DEFAULT_POLICY[scenario]].maps
    assert cmd_search.DEFAULT_POLICIES["built"].startswith("frontier,indirect")


@pytest.mark.parametrize(
    ("argv", "pattern"),
    [
        (["--style", "office", "--target", "Desk"], "target 'Desk' is a furniture type"),
        (
            ["--style", "apartment", "--target", "Microscope"],
            "no world of style 'apartment' can hold",
        ),
        (
            ["--style", "office", "--target", "Cup", "--budget-seconds", "1e-300"],
            "too small to find anything",
        ),
        (["--style", "office", "--target", "Cup", "--budget-seconds", "0.4"], "0.25 s each: 0.5 s"),
    ],
)
def test_impossible_requests_are_refused_up_front(store, capsys, argv, pattern):
    """No episode is drawn for a request no world can satisfy (a draw would try 150 rooms and
    more, minutes): refused from the style's definition and the time model, in well under the
    few seconds allowed here."""
    import time

    t = time.perf_counter()
    code = main(["search", "--kb", str(store), *argv])
    assert time.perf_counter() - t < 5.0
    _one_line_error(capsys, code, pattern)


def test_bench_search_refuses_a_budget_below_two_images(store, tmp_path, capsys):
    out = tmp_path / "bench"
    code = main(["bench", "search", "--kb", str(store), "--style", "office", "--episodes", "2",
                 "--budget-seconds", "1e-300", "--out", str(out)])  # fmt: skip
    _one_line_error(capsys, code, "too small to find anything")
    assert not out.exists()
