"""The sweep journal (scripts.journal): finished units read back and never run again, a damaged
or foreign file a miss, another configuration or store another key, results exact; and a bench
search killed with SIGKILL part-way and run again writes the files an uninterrupted run writes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.agent.search.episode import GazeRecord, SearchResult
from ctxsearch.envs.robot_spec import RobotPose
from ctxsearch.scripts.experiments.journals import (
    result_from_json,
    result_json,
    search_journal,
)
from ctxsearch.scripts.journal import Journal, context_digest
from ctxsearch.scripts.sweep import run_units

ROOT = Path(__file__).resolve().parents[1]


def _journal(directory: Path, context: str = "c") -> Journal:
    return Journal(directory, context, lambda r: r, lambda d: [float(x) for x in d])


def _third(x: int) -> list[float]:
    return [x / 3, 0.1 * x, 1e-300 * x]


def test_finished_units_are_read_back_not_run_again(tmp_path):
    j = _journal(tmp_path / "j")
    first = run_units(_third, [1, 2, 3], progress=False, journal=j)
    ran = []

    def spy(x):
        ran.append(x)
        return _third(x)

    again = run_units(spy, [1, 2, 3, 4], progress=False, journal=j)
    assert ran == [4]  # only the unit it did not hold
    assert again[:3] == first  # the same bits: floats written with repr
    assert again == [_third(x) for x in [1, 2, 3, 4]]


def test_a_damaged_or_foreign_file_is_a_miss(tmp_path):
    d = tmp_path / "j"
    j = _journal(d)
    run_units(_third, [1, 2, 3, 4, 5], progress=False, journal=j)
    files = {u: d / f"{j.key(u)}.json" for u in (1, 2, 3, 4, 5)}
    text = files[1].read_text()
    files[1].write_text(text[: len(text) // 2])  # truncated
    files[2].write_bytes(b"\xff\x00garbage")  # not JSON, not UTF-8
    files[3].write_text(files[4].read_text())  # another unit's file under this name
    doc = json.loads(files[5].read_text())
    doc["result"][0] = 7.0  # edited: its digest no longer holds
    files[5].write_text(json.dumps(doc))
    files[4].unlink()
    files[4].mkdir()  # not a regular file
    ran = []

    def spy(x):
        ran.append(x)
        return _third(x)

    out = run_units(spy, [1, 2, 3, 4, 5], progress=False, journal=j)
    assert ran == [1, 2, 3, 4, 5]
    assert out == [_third(x) for x in [1, 2, 3, 4, 5]]
    assert run_units(spy, [1, 2, 3], progress=False, journal=j) == out[:3]  # rewritten
    assert ran == [1, 2, 3, 4, 5]


def test_another_configuration_or_store_is_another_key(tmp_path, desk_cup_store):
    store = desk_cup_store(tmp_path / "kb.sqlite")
    c = SearchConfig().updated({"style": "office", "knowledge.kb": store, "episodes": 4})
    names = ["uniform", "location"]
    key = search_journal(tmp_path, c, names, None).key([])
    assert search_journal(tmp_path, c, names, None).key([]) == key  # deterministic
    assert search_journal(tmp_path, c.updated({"seed": 1}), names, None).key([]) != key
    assert search_journal(tmp_path, c.updated({"budget_s": 100.0}), names, None).key([]) != key
    assert search_journal(tmp_path, c, ["uniform"], None).key([]) != key
    store.write_bytes(desk_cup_store(tmp_path / "other.sqlite", rooms=6).read_bytes())
    assert search_journal(tmp_path, c, names, None).key([]) != key
    assert context_digest("a", {"x": 1}) != context_digest("b", {"x": 1})


def test_a_search_result_reads_back_exactly():
    r = SearchResult(
        "location", 3, "Cup", True, 17, 12.345678901234567, 4, 0.1 + 0.2, 300.0,
        [GazeRecord(1 / 3, RobotPose(0.1, 0.2, 0.3, -0.4, 1e-17), "region", (("Cup", 17),))],
        ["a line"], "Desk", float("inf"), 1, None,
    )  # fmt: skip
    back = result_from_json(json.loads(json.dumps(result_json(r))))
    assert back == r
    assert back.predicted_gain == float("inf")


def _tree(d: Path) -> dict[str, bytes]:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def test_a_bench_search_killed_part_way_resumes_with_the_same_files(tmp_path, desk_cup_store):
    """SIGKILL after the first of four episodes is kept; the same command again runs only the
    other three and writes byte-identical files (search.json, search.md, search.png,
    episodes.csv: none holds a wall-clock field)."""
    store = desk_cup_store(tmp_path / "kb.sqlite")
    cmd = [sys.executable, "-m", "ctxsearch.scripts.cli", "bench", "search", "--kb", str(store),
           "--style", "office", "--episodes", "4", "--policies", "uniform,location", "--quiet",
           "--draw-cache", str(tmp_path / "draws")]  # fmt: skip
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    whole = subprocess.run([*cmd, "--out", str(tmp_path / "a")], cwd=ROOT, env=env,
                           capture_output=True, text=True)  # fmt: skip
    assert whole.returncode == 0, whole.stderr
    journal, out = tmp_path / "journal", tmp_path / "b"
    resumed = [*cmd, "--out", str(out), "--journal", str(journal)]
    p = subprocess.Popen(resumed, cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL, start_new_session=True)  # fmt: skip
    deadline = time.monotonic() + 120
    while not any(journal.glob("*.json")) and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    os.killpg(p.pid, signal.SIGKILL)
    assert p.wait() == -signal.SIGKILL
    kept = len(list(journal.glob("*.json")))
    assert 1 <= kept < 4  # the first episode, maybe the next, not all
    assert not (out / "search.json").exists()
    again = subprocess.run(resumed, cwd=ROOT, env=env, capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    assert len(list(journal.glob("*.json"))) == 4
    assert _tree(out) == _tree(tmp_path / "a")


def test_on_ray_only_the_missing_units_run_and_the_driver_keeps_them(tmp_path):
    j = _journal(tmp_path / "j")
    j.save(1, [9.0, 9.0, 9.0])  # a unit already kept: read back, not run
    out = run_units(_third, [1, 2, 3], workers=2, progress=False, journal=j)
    assert out == [[9.0, 9.0, 9.0], _third(2), _third(3)]
    assert len(list((tmp_path / "j").glob("*.json"))) == 3  # each result kept as it arrived
    assert run_units(_third, [1, 2, 3], progress=False, journal=j) == out
