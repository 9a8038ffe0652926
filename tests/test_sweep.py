"""Sweeps: the same results serially and on a local Ray, errors as one line, no Ray import for
one worker."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.scripts.sweep import run_units

ROOT = Path(__file__).resolve().parents[1]


def square_with_pid(x: int) -> dict:
    import os

    gl = os.environ.get("MUJOCO_GL"), os.environ.get("PYOPENGL_PLATFORM")
    return {"x": x, "y": x * x, "pid": os.getpid(), "nice": os.nice(0), "gl": list(gl),
            "own_session": os.getsid(0) == os.getpid()}  # fmt: skip


def refuse_three(x: int) -> int:
    if x == 3:
        raise CtxsearchError("unit 3: bad input")
    return x


def test_one_worker_is_a_loop_without_ray():
    code = (
        "import sys; from ctxsearch.scripts.sweep import SweepOptions, run_units, session; "
        "from tests.test_sweep import square_with_pid as f; "
        "s = session(SweepOptions()); s.__enter__(); "
        "r = run_units(f, [1, 2, 3], progress=False); assert [u['y'] for u in r] == [1, 4, 9]; "
        "s.__exit__(None, None, None); assert 'ray' not in sys.modules"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_the_first_unit_runs_with_the_long_lived_objects_frozen(monkeypatch):
    """A full collection skips what existed before the first unit (``freeze_long_lived``)."""
    import gc

    from ctxsearch.scripts import sweep

    monkeypatch.setattr(sweep, "_frozen", False)
    before = [[]]  # a tracked container made before the sweep
    seen = []

    def unit(u):
        seen.append(any(o is before for o in gc.get_objects()))
        return u

    try:
        assert run_units(unit, [1, 2], progress=False) == [1, 2]
        assert seen == [False, False]  # frozen: no longer among the collected generations
        assert gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()


@pytest.mark.slow
def test_two_workers_give_the_serial_results_in_order():
    units = list(range(8))
    serial = run_units(square_with_pid, units, progress=False)
    parallel = run_units(square_with_pid, units, workers=2, progress=False)
    drop = {"pid", "own_session"}
    strip = [{k: v for k, v in d.items() if k not in drop} for d in parallel]
    assert strip == [{k: v for k, v in d.items() if k not in drop} for d in serial]  # nice too:
    # the workers run at the driver's priority, not Ray's default nice 15
    assert all(d["own_session"] for d in parallel)  # a CPU share each (scripts.sweep.own_session)
    assert {d["pid"] for d in parallel}.isdisjoint({d["pid"] for d in serial})  # other processes
    assert parallel[0]["gl"] == [os.environ.get(k) for k in ("MUJOCO_GL", "PYOPENGL_PLATFORM")]
    assert parallel[0]["gl"][0] == "egl"  # the workers render off-screen like the driver
    with pytest.raises(CtxsearchError, match="unit 3: bad input"):
        run_units(refuse_three, units, workers=2, progress=False)


@pytest.mark.slow
def test_a_session_keeps_one_ray_for_several_sweeps():
    import ray

    from ctxsearch.scripts.sweep import SweepOptions, session

    with session(SweepOptions(workers=2)):
        a = run_units(square_with_pid, [1, 2], workers=2, progress=False)
        assert ray.is_initialized()
        b = run_units(square_with_pid, [3, 4], workers=2, progress=False)
        assert ray.is_initialized()  # the sweeps did not shut the session's Ray down
    assert not ray.is_initialized()
    assert [d["y"] for d in a + b] == [1, 4, 9, 16]


def test_bad_worker_count():
    with pytest.raises(CtxsearchError, match="at least 1"):
        run_units(square_with_pid, [1], workers=0)


def _strip_timing(x):
    if isinstance(x, dict):
        return {
            k: _strip_timing(v)
            for k, v in x.items()
            if not any(t in k for t in ("wall", "_per_s", "per_wall"))
        }
    if isinstance(x, list):
        return [_strip_timing(v) for v in x]
    return x


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray of two workers for the commands' serial-vs-Ray checks below (each command
    would otherwise start and stop its own: ~7 s each; a command finds it running and keeps it,
    as inside ``session``). The tests above start and stop their own, as a command does."""
    import ray

    from ctxsearch.scripts.sweep import SweepOptions, session

    assert not ray.is_initialized()
    with session(SweepOptions(workers=2)):
        yield
    assert not ray.is_initialized()


@pytest.mark.slow
def test_bench_learning_on_two_workers_gives_the_serial_json(tmp_path, local_ray):
    import json

    from ctxsearch.scripts.cli import main

    args = ["bench", "learning", "--style", "office", "--rooms", "2", "--seeds", "2"]
    args += ["--strategies", "hif,random", "--truth-samples", "10"]
    assert main([*args, "--out", str(tmp_path / "serial")]) == 0
    assert main([*args, "--out", str(tmp_path / "ray"), "--workers", "2"]) == 0
    a = json.loads((tmp_path / "serial" / "learning.json").read_text())
    b = json.loads((tmp_path / "ray" / "learning.json").read_text())
    assert _strip_timing(a) == _strip_timing(b)
    csv_a = (tmp_path / "serial" / "learning.csv").read_text()
    assert csv_a == (tmp_path / "ray" / "learning.csv").read_text()


@pytest.mark.slow
def test_truth_on_two_workers_gives_the_serial_file(tmp_path, local_ray):
    from ctxsearch.scripts.cli import main

    args = ["truth", "--style", "office", "--samples", "25", "--no-progress"]
    assert main([*args, "--out", str(tmp_path / "a.json")]) == 0
    assert main([*args, "--out", str(tmp_path / "b.json"), "--workers", "2"]) == 0
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()


@pytest.mark.slow
def test_bench_search_on_two_workers_gives_the_serial_files(tmp_path, desk_cup_store, local_ray):
    import json

    from ctxsearch.scripts.cli import main

    kb = desk_cup_store(tmp_path / "kb.sqlite", rooms=3)
    args = ["bench", "search", "--kb", str(kb), "--style", "office", "--episodes", "2"]
    args += ["--policies", "exhaustive,location", "--budget-seconds", "20", "--quiet"]
    args += ["--detector", "perfect"]  # the realistic detector's episode checks take longer
    assert main([*args, "--out", str(tmp_path / "serial")]) == 0
    assert main([*args, "--out", str(tmp_path / "ray"), "--workers", "2"]) == 0
    a = json.loads((tmp_path / "serial" / "search.json").read_text())
    b = json.loads((tmp_path / "ray" / "search.json").read_text())
    assert len(a["episode_list"]) == 2
    assert _strip_timing(a) == _strip_timing(b)
    csv_a = (tmp_path / "serial" / "episodes.csv").read_text()
    assert csv_a == (tmp_path / "ray" / "episodes.csv").read_text()


# ---- an unreachable cluster (issue 24) ------------------------------------------------------------
def test_a_ray_address_where_nothing_listens_fails_at_once_with_one_line(capsys, tmp_path):
    import time

    from ctxsearch.scripts.cli import main

    t = time.perf_counter()
    with pytest.raises(CtxsearchError, match=r"--ray-address 127.0.0.1:1: no Ray cluster there"):
        run_units(refuse_three, [1, 2], ray_address="127.0.0.1:1", progress=False)
    out = str(tmp_path / "t.json")
    argv = ["truth", "--style", "office", "--samples", "2", "--out", out]
    assert main([*argv, "--ray-address", "127.0.0.1:1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no Ray cluster there (Connection refused)" in err, err
    assert time.perf_counter() - t < 10 and not Path(out).exists()


@pytest.mark.parametrize("address", ["nonsense", "host:", ":6379", "localhost:99999", "h:x"])
def test_a_ray_address_that_is_not_host_port_is_a_one_line_error(address):
    from ctxsearch.scripts.sweep import check_reachable

    with pytest.raises(CtxsearchError, match="expected HOST:PORT or 'auto'"):
        check_reachable(address)


def test_a_ray_address_that_does_not_answer_fails_within_the_stated_timeout(monkeypatch):
    import socket

    from ctxsearch.scripts import sweep

    seen = {}

    def silent(address, timeout):
        seen["timeout"] = timeout
        raise TimeoutError("timed out")

    monkeypatch.setattr(socket, "create_connection", silent)
    with pytest.raises(CtxsearchError, match=r"no answer within 5 s"):
        sweep.check_reachable("192.0.2.1:6379")
    assert seen["timeout"] == sweep.RAY_CONNECT_TIMEOUT_S == 5


def test_a_listening_address_passes_the_check_and_ray_gets_bounded_settings(monkeypatch):
    import socket

    from ctxsearch.scripts import sweep

    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        sweep.check_reachable(f"127.0.0.1:{server.getsockname()[1]}")  # no error
    timeout, wait = sweep._RAY_CONNECT_ENV  # Ray's own (lower-case) variable names
    monkeypatch.delenv(timeout, raising=False)
    monkeypatch.setenv(wait, "7")  # the user's own wins
    with sweep._env(sweep._RAY_CONNECT_ENV):
        assert os.environ[timeout] == "5" and os.environ[wait] == "7"
    assert timeout not in os.environ and os.environ[wait] == "7"


def test_ray_address_auto_without_a_cluster_names_ctxsearchs_own_flag(monkeypatch, capsys):
    """Ray's text for 'auto' with nothing running tells the user to set its ``--address`` flag;
    ctxsearch's error names its own flags instead (Ray's failure is simulated: a real 'auto'
    could find another test's Ray)."""
    import ray

    from ctxsearch.scripts.cli import main

    def nothing_runs(*_a, **_k):
        raise ConnectionError(
            "Could not find any running Ray instance. Please specify the one to connect to by "
            "setting `--address` flag or `RAY_ADDRESS` environment variable."
        )

    monkeypatch.setattr(ray, "init", nothing_runs)
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    argv = ["truth", "--style", "office", "--samples", "2", "--out", "/nonexistent/t.json"]
    assert main([*argv, "--ray-address", "auto", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--ray-address auto: no Ray cluster runs" in err, err
    assert "--address` flag" not in err and "--workers N" in err
