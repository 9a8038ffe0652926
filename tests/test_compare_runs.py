"""scripts.experiments.compare_runs: two bench search runs compared per policy on their common
episodes, with the benchmark's paired statistics; bad input is a one-line error (exit 2)."""

import subprocess
import sys

from ctxsearch.scripts.experiments.compare_runs import compare, main
from ctxsearch.scripts.experiments.tables import write_csv

COLS = ("episode", "room_seed", "target", "policy", "time_to_find_s")


def _run(path, times, policy="p"):
    rows = [{"episode": i, "room_seed": 10 + i, "target": "Cup", "policy": policy,
             "time_to_find_s": t} for i, t in enumerate(times)]  # fmt: skip
    return write_csv(path, COLS, rows)


def test_a_policy_twice_as_fast_on_every_episode(tmp_path):
    new = _run(tmp_path / "new.csv", [10.0, 20.0, 30.0, 40.0, 50.0, 60.0])
    old = _run(tmp_path / "old.csv", [20.0, 40.0, 60.0, 80.0, 100.0, 120.0, 7.0], "q")
    (line,) = compare(new, old, ["p:q"])
    assert line.startswith("p / q: 6 episodes, geometric mean 0.50 [0.50, 0.50]")
    assert "wins/losses/ties 6/0/0" in line
    lines = compare(new, new, ["p"], by_target=True)  # one run against itself, per target
    assert len(lines) == 2 and lines[1].startswith("p / p [Cup]: 6 episodes, geometric mean 1.00")


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    new = _run(tmp_path / "new.csv", [10.0])
    junk = tmp_path / "junk.csv"
    junk.write_bytes(b"\xff\xfe not a table")
    assert main([str(new), str(junk), "p"]) == 2
    assert main([str(new), str(new), "nope"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(x.startswith("compare_runs: error: ") for x in err)
    assert "no policy 'nope'" in err[1]
    p = subprocess.run([sys.executable, "-m", "ctxsearch.scripts.experiments.compare_runs",
                        str(new), str(tmp_path / "missing.csv"), "p"],
                       capture_output=True, text=True, timeout=60)  # fmt: skip
    assert p.returncode == 2 and "Traceback" not in p.stderr and len(p.stderr.splitlines()) == 1
