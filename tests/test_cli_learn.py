"""``ctxsearch learn`` and ``ctxsearch bench learning`` as a user runs them."""

from __future__ import annotations

import csv
import json

import pytest

from ctxsearch.scripts.cli import main


def test_learn_then_resume_then_kb_show(tmp_path, capsys):
    kb = tmp_path / "office.sqlite"
    args = [
        "learn",
        "--style",
        "office",
        "--rooms",
        "1",
        "--kb",
        str(kb),
        "--perception",
        "oracle",
        "--no-progress",
    ]
    assert main([*args, "--max-examinations", "5"]) == 0
    out = capsys.readouterr().out
    assert "examinations: 5 now, 5 in the store" in out
    assert "0 rooms done" in out
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "1 room done (1 in this call)" in out
    assert "examinations per wall second" in out and "mean interval width" in out
    n_total = int(out.split(" in the store")[0].split()[-1])
    assert n_total > 5
    # A finished run again: nothing to do.
    assert main(args) == 0
    assert "examinations: 0 now" in capsys.readouterr().out
    # The store lists in `kb show`.
    assert main(["kb", "show", str(kb), "--json"]) == 0
    shown = capsys.readouterr().out
    assert shown.strip()


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--rooms", "0"], "expected a positive integer"),
        (["--rooms", "x"], "expected a positive integer"),
        (["--strategy", "best"], "invalid choice: 'best'"),
        (["--perception", "lidar"], "invalid choice: 'lidar'"),
        (["--alpha", "1.5"], "expected a number in (0, 1)"),
        (["--max-examinations", "-3"], "expected a positive integer"),
        (["--room-budget", "0"], "expected a positive number of seconds"),
        (["--room-budget", "soon"], "expected a positive number of seconds"),
    ],
)
def test_learn_bad_flags_are_argparse_errors(tmp_path, capsys, argv, message):
    base = {"--style": "office", "--rooms": "1", "--kb": str(tmp_path / "k.sqlite")}
    for k, v in zip(argv[::2], argv[1::2], strict=True):
        base[k] = v
    flat = [x for kv in base.items() for x in kv]
    with pytest.raises(SystemExit) as exc:
        main(["learn", *flat, *[a for a in argv if a not in flat]])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_learn_unknown_style_and_bad_store_are_one_line_errors(tmp_path, capsys):
    assert (
        main(
            [
                "learn",
                "--style",
                "nowhere",
                "--rooms",
                "1",
                "--kb",
                str(tmp_path / "k.sqlite"),
                "--perception",
                "oracle",
                "--no-progress",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ctxsearch: error:") and "nowhere" in err[0]
    bad = tmp_path / "not_a_store.sqlite"
    bad.write_text("hello")
    assert (
        main(
            [
                "learn",
                "--style",
                "office",
                "--rooms",
                "1",
                "--kb",
                str(bad),
                "--perception",
                "oracle",
                "--no-progress",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a ctxsearch knowledge store" in err[0]
    assert bad.read_text() == "hello"


def test_learn_with_a_room_budget(tmp_path, capsys):
    kb = tmp_path / "office.sqlite"
    base = ["learn", "--style", "office", "--rooms", "2", "--kb", str(kb), "--perception", "oracle"]
    assert main([*base, "--room-budget", "45", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "2 rooms done (2 in this call)" in out
    assert "room budget: 45 s simulated per room; the budget ended 2 of the 2 rooms" in out
    n_budget = int(out.split(" in the store")[0].split()[-1])
    # Without the budget it would be another run over the same rooms in the same store, their
    # objects counted twice: refused in one line. In a store of its own, every room to completion.
    assert main([*base, "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "count twice" in err[0]
    other = ["--kb", str(tmp_path / "whole.sqlite"), "--no-progress"]
    assert main([*base, *other]) == 0
    out = capsys.readouterr().out
    assert "room budget" not in out
    n_now = int(out.split("examinations: ")[1].split()[0])
    assert n_now > 2 * n_budget


@pytest.mark.parametrize("budget", [None, "60"])
def test_bench_learning_writes_its_four_files(tmp_path, capsys, budget):
    out = tmp_path / "bench"
    argv = [
        "bench",
        "learning",
        "--style",
        "office",
        "--rooms",
        "1",
        "--seeds",
        "2",
        "--strategies",
        "hif,random",
        "--out",
        str(out),
        "--truth-samples",
        "8",
    ]
    assert main(argv + (["--room-budget", budget] if budget else [])) == 0
    printed = capsys.readouterr().out
    assert "| hif |" in printed and "| random |" in printed
    assert "## Reading" in printed and "hif vs random: per examination hif is ahead in" in printed
    data = json.loads((out / "learning.json").read_text())
    assert data["style"] == "office" and data["seeds"] == [0, 1]
    assert data["room_budget_s"] == (float(budget) if budget else None)
    for name in ("hif", "random"):
        s = data["strategies"][name]
        k = len(s["examinations"])
        assert k > (4 if budget else 10)
        shares = [x for seed in s["examined_share"] for x in seed]
        assert len(shares) == 2 and all(0 < x <= 1 for x in shares)
        assert s["rooms_left_early"] == ([1, 1] if budget else [0, 0])
        if budget:
            assert max(shares) < 0.9
        for key in ("sim_s", "mean_width", "max_width", "mean_abs_error", "coverage"):
            assert len(s[key]) == k
        assert s["mean_width"][0] > s["mean_width"][-1]
        assert all(0.0 <= c <= 1.0 for c in s["coverage"])
    assert "Mean interval width" in (out / "learning.md").read_text()
    assert (out / "learning.png").stat().st_size > 10_000
    with (out / "learning.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert set(rows[0]) >= {"strategy", "seed", "examination", "room", "sim_s", "mean_width"}
    for name in ("hif", "random"):
        runs = {
            seed: [r for r in rows if r["strategy"] == name and r["seed"] == seed] for seed in "01"
        }
        k = len(data["strategies"][name]["examinations"])
        assert min(len(v) for v in runs.values()) == k  # the JSON's curves end at the shortest run
        for v in runs.values():
            assert [int(r["examination"]) for r in v] == list(range(1, len(v) + 1))
            assert {r["room"] for r in v} == {"0"}
            sim = [float(r["sim_s"]) for r in v]
            assert sim == sorted(sim) and sim[0] > 0
        first = sorted(float(v[0]["mean_width"]) for v in runs.values())
        assert data["strategies"][name]["mean_width"][0] == pytest.approx(sum(first) / 2)


def test_bench_learning_bad_strategy_list(tmp_path, capsys):
    assert main(["bench", "learning", "--strategies", "hif,nope", "--out", str(tmp_path)]) == 2
    assert "unknown strategy 'nope'" in capsys.readouterr().err


def test_summary_names_houses_visits_and_days():
    """Houses are counted as houses, rooms as rooms; with --days the visits (a world on one
    day) are told apart from the worlds."""
    from ctxsearch.agent.learning import Summary, world_noun
    from ctxsearch.knowledge.catalog import load_catalog

    catalog = load_catalog()
    assert world_noun("apartment", catalog) == "house"
    assert world_noun("office", catalog) == "room"
    houses = Summary("r", rooms=3, rooms_done_now=3, world="house").lines()
    assert houses[0] == "run r: 3 houses done (3 in this call)"
    days = Summary("r", rooms=4, rooms_done_now=20, days=5, world="room", room_budget_s=60.0)
    text = "\n".join(days.lines())
    assert "4 rooms done on day 0; 20 visits (a room on one day) done in this call" in text
    assert "days: 5" in text and "of the 20 visits done in this call" in text
    assert (
        Summary("r", rooms=1, rooms_done_now=1).lines()[0] == "run r: 1 room done (1 in this call)"
    )
