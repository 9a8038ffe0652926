"""The Python API for other robots (docs/python-api.md): the example runs, learns what its detections say,
ranks search volumes with the learned intervals, and never imports a simulator."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.examples import real_robot_api

ROOT = Path(__file__).resolve().parents[1]


def test_example_learns_and_ranks(tmp_path, capsys):
    store = tmp_path / "robot.sqlite"
    assert real_robot_api.main(["--store", str(store)]) == 0
    out = capsys.readouterr().out
    assert "3 tables examined" in out
    # Two of three tables had a mug on top: y=2, n=3.
    assert "P(ON-TOP-OF-TABLE(Mug)) in [0.25, 0.92]  (y=2, n=3)" in out
    ranking = out.split("where to look for a Mug, best first:")[1].strip().splitlines()
    assert len(ranking) == 4 and all("p >= 0.25" in line for line in ranking)
    # The store it wrote is an ordinary evidence store, readable again.
    with EvidenceStore.open(store, real_robot_api.parse_catalog(real_robot_api.CATALOG)) as s:
        assert s.examinations_count() == 7
        assert s.knowledge_base().y("ON-TOP-OF-TABLE", "Book") == 1


def test_example_imports_no_simulator():
    code = (
        "import sys; from ctxsearch.scripts.examples import real_robot_api as m; m.main([]); "
        "bad = [k for k in ('mujoco', 'dm_control', 'rerun', 'cv2', 'agent', 'envs') "
        "if k in sys.modules]; assert not bad, bad"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_example_runs_twice_on_one_store(tmp_path, capsys):
    """The second call on the same store resumes: nothing examined again, the same intervals
    (not 'another process is learning the same run')."""
    store = tmp_path / "robot.sqlite"
    assert real_robot_api.main(["--store", str(store)]) == 0
    first = capsys.readouterr().out
    assert real_robot_api.main(["--store", str(store)]) == 0
    second = capsys.readouterr().out
    assert "examined Table" in first and "examined Table" not in second
    assert "room 102: 3 objects examined by an earlier call" in second
    assert first.split("tables examined")[1] == second.split("tables examined")[1]
    with EvidenceStore.open(store, real_robot_api.parse_catalog(real_robot_api.CATALOG)) as s:
        assert s.examinations_count() == 7


def test_readme_api_snippet_runs_twice(tmp_path, monkeypatch, capsys):
    text = (ROOT / "docs" / "python-api.md").read_text()
    code = text.split("```python\n")[1].split("```")[0]
    monkeypatch.chdir(tmp_path)
    outs = []
    for _ in range(2):
        exec(compile(code, "docs/python-api.md", "exec"), {})
        outs.append(capsys.readouterr().out)
    assert (tmp_path / "robot.sqlite").exists()
    assert outs[0] == outs[1] and "ON-TOP-OF-DESK" in outs[0]
    from ctxsearch.knowledge.catalog import load_catalog

    with EvidenceStore.open(tmp_path / "robot.sqlite", load_catalog()) as s:
        assert s.examinations_count() == 1


def test_longest_silence_times_a_commands_gaps(capsys):
    """scripts/examples/longest_silence.py (issue 29's measure): the gap between two outputs and
    the command's exit code."""
    import sys

    from ctxsearch.scripts.examples import longest_silence

    code = "import sys, time; print(1, flush=True); time.sleep(1.0); print(2); sys.exit(3)"
    assert longest_silence.main([sys.executable, "-c", code]) == 3
    err = capsys.readouterr().err
    assert err.startswith("exit 3, ") and "first output after" in err
    first_gap = err.splitlines()[1]
    assert first_gap.startswith("  silent 1.") and "'1\\r\\n'" in first_gap, err
