"""How a command ends when it is told to (scripts/__init__.py): SIGTERM and SIGHUP end a command
as Ctrl-C does, with one line on stderr and exit code 128 + the signal, the same guarantees for
learned knowledge, and no child left running; the web viewer idles while it serves; the Python
API's argument errors are ValueError or TypeError too."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.procs import wait_until_importing

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "ctxsearch.scripts.cli"]


def _start(*argv: str) -> subprocess.Popen:
    """The CLI in a process group of its own (so the test can see what is left in it)."""
    return subprocess.Popen(
        [*CLI, *argv], cwd=ROOT, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True, start_new_session=True,
        env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
    )  # fmt: skip


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def _ended_alone(p: subprocess.Popen, timeout: float = 30.0) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) once ``p`` ends; its group checked empty a moment later."""
    out, err = p.communicate(timeout=timeout)
    deadline = time.monotonic() + 5.0
    while _group_alive(p.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    alive = _group_alive(p.pid)
    if alive:
        os.killpg(p.pid, signal.SIGKILL)
    assert not alive, "a process of the command's group outlived it"
    return p.returncode, out, err


def _cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _children(pid: int) -> list[int]:
    out = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout
    kids = [int(x) for x in out.split()]
    return kids + [g for k in kids for g in _children(k)]


def _rerun_servers(port: str) -> list[int]:
    out = subprocess.run(["pgrep", "-f", f"web-viewer-port {port}"], capture_output=True, text=True)
    return [int(x) for x in out.stdout.split()]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_view_idles_and_a_stop_signal_ends_it_with_its_server(small_rrd, sig):
    p = _start("view", str(small_rrd), "--port", "0", "--grpc-port", "0")
    try:
        line = p.stdout.readline()  # printed once the viewer answers and holds the recording
        assert line.startswith("rerun web viewer for "), line
        port = line.split("http://127.0.0.1:", 1)[1].split("/", 1)[0]
        servers = _rerun_servers(port)
        assert servers, "no rerun server found"
        procs = [p.pid, *servers, *(k for s in servers for k in _children(s))]
        time.sleep(1.0)
        before = sum(_cpu_seconds(x) for x in procs)
        time.sleep(4.0)
        busy = (sum(_cpu_seconds(x) for x in procs) - before) / 4.0
        assert busy < 0.05, f"the viewer keeps {100 * busy:.0f}% of a core busy while idle"
        p.send_signal(sig)
        code, _, err = _ended_alone(p)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert code == 128 + sig
    assert err.strip().splitlines() == [f"ctxsearch: terminated by {signal.Signals(sig).name}"]
    assert _rerun_servers(port) == []  # the server's own group is ended too


def _examinations(kb: Path) -> list[tuple]:
    with sqlite3.connect(f"file:{kb}?mode=ro", uri=True) as db:
        cols = [r[1] for r in db.execute("PRAGMA table_info(examinations)")]
        keep = [c for c in cols if c not in ("id", "created", "wall_time")]
        return sorted(db.execute(f"SELECT {', '.join(keep)} FROM examinations").fetchall())


def _count(kb: Path) -> int:
    if not kb.exists():
        return 0
    try:
        with sqlite3.connect(f"file:{kb}?mode=ro", uri=True) as db:
            return db.execute("SELECT COUNT(*) FROM examinations").fetchone()[0]
    except sqlite3.Error:
        return 0


LEARN = ("learn", "--style", "office", "--rooms", "12", "--perception", "oracle", "--no-progress")


def test_sigterm_mid_learning_keeps_every_finished_examination_and_the_run_resumes(tmp_path):
    whole = tmp_path / "whole.sqlite"
    r = subprocess.run([*CLI, *LEARN, "--kb", str(whole)], cwd=ROOT, capture_output=True)
    assert r.returncode == 0, r.stderr
    kb = tmp_path / "stopped.sqlite"
    p = _start(*LEARN, "--kb", str(kb))
    try:
        deadline = time.monotonic() + 60
        while _count(kb) < 3 and p.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert p.poll() is None, "the run ended before it could be stopped"
        p.send_signal(signal.SIGTERM)
        code, out, err = _ended_alone(p)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert code == 128 + signal.SIGTERM
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ctxsearch: terminated by SIGTERM"), err
    kept = _count(kb)
    assert 3 <= kept < _count(whole)
    r = subprocess.run([*CLI, *LEARN, "--kb", str(kb)], cwd=ROOT, capture_output=True)
    assert r.returncode == 0, r.stderr
    assert _examinations(kb) == _examinations(whole)  # resumed: as if never stopped


def test_sighup_before_the_store_exists_is_one_line_and_nothing_is_learned(tmp_path):
    kb = tmp_path / "kb.sqlite"
    script = Path(sys.executable).parent / "ctxsearch"  # the console script, as a user runs it
    p = subprocess.Popen(
        [str(script), *LEARN, "--kb", str(kb)], cwd=ROOT, stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    wait_until_importing(p)  # loading its modules: the store is made after them
    p.send_signal(signal.SIGHUP)
    code, _, err = _ended_alone(p)
    assert code == 128 + signal.SIGHUP
    assert err.strip().splitlines()[-1].startswith("ctxsearch: terminated by SIGHUP")
    assert len(err.strip().splitlines()) == 1
    assert _count(kb) == 0


def test_stopped_is_a_keyboard_interrupt_with_its_signal():
    from ctxsearch.scripts import Stopped, stop_code, stop_line

    e = Stopped(signal.SIGTERM)
    assert isinstance(e, KeyboardInterrupt) and e.signum == signal.SIGTERM
    assert stop_line(signal.SIGINT) == "ctxsearch: interrupted"
    assert stop_line(signal.SIGHUP) == "ctxsearch: terminated by SIGHUP"
    assert stop_code(signal.SIGTERM) == 143


@pytest.mark.slow
def test_sigterm_during_ray_is_one_line_and_leaves_no_worker(tmp_path, desk_cup_store):
    kb = desk_cup_store(tmp_path / "kb.sqlite")
    p = _start(
        "bench", "search", "--kb", str(kb), "--style", "office", "--map", "given",
        "--policies", "uniform,location", "--episodes", "6", "--budget-seconds", "20",
        "--out", str(tmp_path / "out"), "--workers", "2", "--quiet",
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 90
        started = False
        while time.monotonic() < deadline and p.poll() is None:  # Ray's workers running
            started = any("ray::" in _cmdline(k) for k in _children(p.pid))
            if started:
                break
            time.sleep(0.2)
        assert started, "Ray never started"
        ray_procs = _children(p.pid)
        p.send_signal(signal.SIGTERM)
        code, _, err = _ended_alone(p, timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert code == 128 + signal.SIGTERM
    assert "logging.cc" not in err and "SIGTERM received" not in err, err
    assert err.strip().splitlines()[-1] == "ctxsearch: terminated by SIGTERM", err
    time.sleep(2.0)
    assert [k for k in ray_procs if Path(f"/proc/{k}").exists()] == []


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def test_gym_argument_errors_are_value_and_type_errors():
    from ctxsearch.agent.gym_env import ObjectSearchEnv
    from ctxsearch.knowledge.errors import CtxsearchError

    for kwargs, kind in [
        ({"budget_s": float("inf")}, ValueError),
        ({"budget_s": "10"}, TypeError),
        ({"top_k": True}, TypeError),
        ({"top_k": 0}, ValueError),
        ({"width": 0}, ValueError),
        ({"style": "no_such_style"}, ValueError),
        ({"style": 3}, TypeError),
        ({"render_mode": "human"}, ValueError),
    ]:
        with pytest.raises(kind) as e:
            ObjectSearchEnv(**kwargs)
        assert isinstance(e.value, CtxsearchError) and "\n" not in str(e.value)
