"""make bench-full's steps (scripts.experiments.bench_full): the plan fits the time it is sized
for, finished steps are skipped, a failed step stops the run and runs again next time, and the
summary pairs each run's episodes."""

from __future__ import annotations

import json
from pathlib import Path

from ctxsearch.scripts.experiments import bench_full as bf
from ctxsearch.scripts.experiments.full_summary import write_summary


def test_the_plan_is_sized_to_four_hours_on_two_cores(tmp_path):
    steps = bf.plan(tmp_path / "out", tmp_path / "build")
    assert sum(s.estimate_s for s in steps) <= 4 * 3600
    names = [s.name for s in steps]
    assert len(set(names)) == len(names)
    assert names[0] == "curve" and names[1] == "apartment-instance-built"  # the headline first
    headline = next(s for s in steps if s.name == "apartment-instance-remembered")
    assert headline.argv is not None and "--room-context" in headline.argv
    assert "400" in headline.argv and "map.home=tour" in headline.argv
    full = bf.command(headline, tmp_path / "build", ["--workers", "2"])
    assert full[-4:] == ["--workers", "2", "--journal", str(tmp_path / "build" / "journal")]


def test_finished_steps_are_skipped_and_a_failed_one_runs_again(tmp_path, monkeypatch, capsys):
    ok = bf.Step("ok", ("kb", "--help"), 1.0, sweep=False)
    bad = bf.Step("bad", ("kb", "no-such-command"), 1.0, sweep=False)
    monkeypatch.setattr(bf, "plan", lambda out, build, counts: [ok, bad])
    argv = ["--out", str(tmp_path / "out"), "--build", str(tmp_path / "build")]
    assert bf.main(argv) == 2
    assert (tmp_path / "build" / "steps" / "ok.json").exists()
    assert not (tmp_path / "build" / "steps" / "bad.json").exists()
    capsys.readouterr()
    fixed = bf.Step("bad", ("kb", "--help"), 1.0, sweep=False)
    monkeypatch.setattr(bf, "plan", lambda out, build, counts: [ok, fixed])
    assert bf.main(argv) == 0
    out = capsys.readouterr().out
    assert "step 1/2 ok: finished before, skipped" in out
    assert "step 2/2 bad: starting" in out and "all steps done" in out


def _episodes(path: Path, times: dict[str, list[float]]) -> None:
    path.mkdir(parents=True)
    lines = ["episode,policy,time_to_find_s"]
    for p, ts in times.items():
        lines += [f"{i},{p},{t!r}" for i, t in enumerate(ts)]
    (path / "episodes.csv").write_text("\n".join(lines) + "\n")


def test_the_summary_pairs_room_context_with_and_without(tmp_path):
    where = tmp_path / "apartment" / "instance"
    _episodes(where / "given", {"uniform": [10.0, 20.0, 30.0, 40.0],
                                "location": [5.0, 10.0, 15.0, 20.0]})  # fmt: skip
    _episodes(where / "given-no-room-context", {"location": [10.0, 20.0, 30.0, 40.0]})
    write_summary(tmp_path)
    doc = json.loads((tmp_path / "summary.json").read_text())
    s = doc["apartment"]["instance"]["given"]
    assert s["episodes"] == 4 and s["baseline"] == "uniform"
    assert s["vs_baseline"]["location"]["geo_mean"] == 0.5
    assert s["vs_baseline"]["location (no room context)"]["geo_mean"] == 1.0
    assert s["room_context"]["with_vs_without"]["geo_mean"] == 0.5
    assert s["success"] == {"uniform": 1.0, "location": 1.0, "location (no room context)": 1.0}
    md = (tmp_path / "summary.md").read_text()
    assert "with room context against without" in md
    assert "| location | 0.50 [0.50, 0.50] 4/0/0" in md and "| 0.50 [0.50, 0.50] |" in md


def test_the_summary_counts_each_policy_s_successes(tmp_path):
    path = tmp_path / "apartment" / "instance" / "built"
    path.mkdir(parents=True)
    rows = ["episode,policy,success,time_to_find_s", "0,frontier,true,10.0",
            "1,frontier,false,300.0", "0,indirect,true,5.0", "1,indirect,true,20.0"]  # fmt: skip
    (path / "episodes.csv").write_text("\n".join(rows) + "\n")
    write_summary(tmp_path)
    s = json.loads((tmp_path / "summary.json").read_text())["apartment"]["instance"]["built"]
    assert s["success"] == {"frontier": 0.5, "indirect": 1.0}
    assert "| frontier | 1 | 1 | | 50% |" in (tmp_path / "summary.md").read_text()


def test_every_step_parses_and_its_policies_resolve(tmp_path):
    """Each step's command line is one the CLI takes, and its policies run in its map scenario
    with (or without) room context."""
    from ctxsearch.agent.search.registry import resolve
    from ctxsearch.scripts.cli import build_parser
    from ctxsearch.scripts.cmd_search import config_from_args

    parser = build_parser()
    for step in bf.plan(tmp_path / "out", tmp_path / "build"):
        if step.argv is None:
            continue
        args = parser.parse_args(bf.command(step, tmp_path / "build", ["--workers", "2"]))
        if step.argv[:2] == ("bench", "search"):
            c = config_from_args(args)
            assert resolve(c.policies, c.map.scenario, c.knowledge.room_context)


def test_the_summary_falls_back_to_a_baseline_that_ran(tmp_path):
    _episodes(tmp_path / "family_house" / "type" / "given",
              {"map-only": [10.0, 20.0], "location": [5.0, 10.0]})  # fmt: skip
    write_summary(tmp_path)
    s = json.loads((tmp_path / "summary.json").read_text())["family_house"]["type"]["given"]
    assert s["baseline"] == "map-only" and s["vs_baseline"]["location"]["geo_mean"] == 0.5
