"""``ctxsearch view FILE.rrd``: rerun's web viewer for a recording, on a machine without a
display: it starts, prints an http address that answers, and Ctrl-C stops it (exit 0, nothing
left running); a file that is not a recording is a one-line error."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from ctxsearch.scripts.cli import main

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def rrd(small_rrd) -> Path:
    """A small recording written by rerun's SDK (conftest's)."""
    return small_rrd


def test_view_serves_the_web_viewer_and_stops_on_ctrl_c(rrd):
    p = subprocess.Popen(
        [sys.executable, "-m", "ctxsearch.scripts.cli", "view", str(rrd), "--port", "0",
         "--grpc-port", "0"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        line = p.stdout.readline()  # printed once the viewer answers
        assert line.startswith(f"rerun web viewer for {rrd}: http://127.0.0.1:"), line
        url = line.split(": ", 1)[1].strip()
        assert "?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A" in url
        with urllib.request.urlopen(url, timeout=10) as r:
            assert r.status == 200 and b"<html" in r.read().lower()
        t = time.monotonic()
        p.send_signal(signal.SIGINT)
        assert p.wait(20) == 0 and time.monotonic() - t < 20
        assert "viewer stopped" in p.stderr.read()
        with pytest.raises(OSError):  # nothing serves there any more
            urllib.request.urlopen(url, timeout=2)
    finally:
        if p.poll() is None:
            os.kill(p.pid, signal.SIGKILL)
            p.wait()


def test_view_refuses_what_is_not_a_recording(tmp_path, capsys):
    other = tmp_path / "kb.sqlite"
    other.write_bytes(b"SQLite format 3\x00")
    for path, problem in [
        (tmp_path, "is a directory"),
        (other, "not a rerun recording"),
        (tmp_path / "nope.rrd", "no such file"),
    ]:
        assert main(["view", str(path)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("ctxsearch: error: ") and problem in err and "\n" not in err
