"""Serving a rerun recording to rerun's web viewer, idle while it waits for a browser.

rerun's own binary serves the viewer over HTTP and the recording over gRPC (``rerun --web-viewer``).
Given the file on its command line, rerun 0.41 keeps a core busy for as long as it serves (its
file source polls the file: 96-99% of a core with no browser connected); started without a file,
its server idles. So the server starts empty, and the recording is sent to it over gRPC by the
Python SDK with the file's own application and recording ids, so the server holds exactly what
the file holds, its blueprint included (``rerun rrd compare`` of the file and the stream saved
back from the server: equal). The server keeps what it was sent for late viewers, up to its
memory limit (``SERVER_MEMORY``).

The server runs in a process group of its own (the ``rerun`` wrapper starts the viewer binary):
``end_group`` ends the group, waits for it and kills what does not end.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.parse
import urllib.request
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.files import InputFileError, open_regular

RRD_MAGIC = b"RRF2"  # the first bytes of an .rrd file (rerun >= 0.19)
START_TIMEOUT_S = 30.0  # the viewer answers on its HTTP port within this, or it is an error
SERVER_MEMORY = "25%"  # of the machine's memory: what the server may hold for late viewers


def check_recording(path: Path) -> None:
    """A one-line error unless ``path`` is a regular file that starts as an .rrd file does."""
    try:
        fd = open_regular(path)  # a directory, FIFO or device is named as such, never read
    except InputFileError as exc:
        raise CtxsearchError(f"{path}: {exc.problem}") from None
    with os.fdopen(fd, "rb") as f:
        head = f.read(len(RRD_MAGIC))
    if head != RRD_MAGIC:
        raise CtxsearchError(
            f"{path}: not a rerun recording (an .rrd file starts with {RRD_MAGIC.decode()})"
        )


def free_port(bind: str = "127.0.0.1") -> int:
    """A TCP port free on ``bind`` now."""
    with socket.socket() as s:
        s.bind((bind, 0))
        return s.getsockname()[1]


def rerun_binary() -> str:
    """The rerun package's viewer binary (beside this Python's, else on PATH)."""
    found = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")
    if found is None:
        raise CtxsearchError("the rerun viewer is not installed (pip install rerun-sdk)")
    return found


def viewer_url(host: str, port: int, grpc_port: int) -> str:
    """The address that opens the web viewer on the served recording."""
    proxy = urllib.parse.quote(f"rerun+http://{host}:{grpc_port}/proxy", safe="")
    return f"http://{host}:{port}/?url={proxy}"


def end_group(p: subprocess.Popen) -> None:
    """End the process group started for ``p`` (the process and its children): SIGTERM, then
    SIGKILL to what is left after 10 s, waited for."""
    for sig, wait in ((signal.SIGTERM, 10), (signal.SIGKILL, 5)):
        try:
            os.killpg(p.pid, sig)
            p.wait(wait)
            return
        except ProcessLookupError:
            return
        except subprocess.TimeoutExpired:
            continue


@dataclass(frozen=True)
class Served:
    """A recording being served: the server's process and the viewer's address."""

    process: subprocess.Popen
    url: str


def push_recording(path: Path, grpc_url: str) -> None:
    """Send the recording in ``path`` to the rerun server at ``grpc_url``, under the file's own
    application and recording ids (its blueprint goes with it)."""
    import rerun as rr  # imported here: the SDK is slow to import and only serving needs it

    with warnings.catch_warnings():  # a file without a footer is read by a scan: fine here
        warnings.simplefilter("ignore")
        recordings = rr.chunk.RrdReader(path).recordings()
    if not recordings:
        raise CtxsearchError(f"{path}: holds no recording")
    first = recordings[0]
    rec = rr.RecordingStream(
        first.application_id, recording_id=first.recording_id, send_properties=False
    )
    rec.connect_grpc(grpc_url)
    rec.log_file_from_path(path)
    rec.flush()
    rec.disconnect()


@contextlib.contextmanager
def serve(path: Path, bind: str, port: int, grpc_port: int, log: Path) -> Iterator[Served]:
    """rerun's web viewer on ``bind``:``port`` (HTTP) and ``grpc_port``, holding the recording
    in ``path`` (module docstring), its output in ``log``; the server's group is ended when the
    block ends, however it ends (a stop signal included)."""
    host = "127.0.0.1" if bind in ("0.0.0.0", "::") else bind
    cmd = [rerun_binary(), "--web-viewer", "--bind", bind, "--web-viewer-port", str(port)]
    cmd += ["--port", str(grpc_port), "--server-memory-limit", SERVER_MEMORY]
    env = {**os.environ, "BROWSER": "true"}  # rerun must not try to open a browser itself
    with open(log, "wb") as out:
        server = subprocess.Popen(
            cmd, env=env, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
            start_new_session=True,  # its own group: a signal to this process reaches it not
        )  # fmt: skip
    try:
        _wait_ready(server, f"http://{host}:{port}/", log)
        push_recording(path, f"rerun+http://{host}:{grpc_port}/proxy")
        yield Served(server, viewer_url(host, port, grpc_port))
    finally:
        end_group(server)


def _wait_ready(server: subprocess.Popen, url: str, log: Path) -> None:
    """Return once ``url`` answers; a one-line error if the server exits or never answers."""
    t_end = time.monotonic() + START_TIMEOUT_S
    while True:
        if server.poll() is not None:
            lines = [ln for ln in log.read_text(errors="replace").splitlines() if ln.strip()]
            why = lines[-1].strip() if lines else "no message"
            raise CtxsearchError(
                f"rerun's web viewer stopped at start (exit {server.returncode}: {why}); "
                "is a port taken? (--port, --grpc-port; 0 picks a free one)"
            )
        try:
            with urllib.request.urlopen(url, timeout=2):
                return
        except OSError:
            if time.monotonic() > t_end:
                raise CtxsearchError(
                    f"rerun's web viewer did not answer on {url} within {START_TIMEOUT_S:.0f} s"
                ) from None
            time.sleep(0.1)
