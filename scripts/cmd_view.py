"""``ctxsearch view FILE.rrd``: play a recording back without a display.

``rerun FILE.rrd`` opens rerun's native viewer, which needs a display; on a headless machine (a
server, a container, a remote VM) this command serves rerun's web viewer instead (the rerun
package's own binary: ``rerun --web-viewer``, which serves the viewer over HTTP and the recording
over gRPC) and prints the address to open in a browser. It runs until Ctrl-C, which stops the
server and exits with 0. Nothing is imported from rerun's Python SDK (``--help`` stays fast).
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request
from pathlib import Path

from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.files import InputFileError, open_regular

RRD_MAGIC = b"RRF2"  # the first bytes of an .rrd file (rerun >= 0.19)
START_TIMEOUT_S = 30.0  # the viewer answers on its HTTP port within this, or it is an error


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``ctxsearch view``."""
    p = sub.add_parser(
        "view",
        help="serve a recording in rerun's web viewer (no display needed); prints its address",
        description="Serve FILE.rrd (from --record) in rerun's web viewer and print the address "
        "to open in a browser; runs until Ctrl-C. For a machine without a display, where "
        "`rerun FILE.rrd` cannot open its window. On a remote machine, forward both ports "
        "(ssh -L PORT:localhost:PORT -L GRPC:localhost:GRPC HOST) or pass --bind 0.0.0.0.",
    )
    p.add_argument("file", type=Path, metavar="FILE.rrd", help="a rerun recording")
    p.add_argument(
        "--port",
        type=_port,
        default=9090,
        help="HTTP port of the web viewer (default: 9090; 0: a free one)",
    )
    p.add_argument(
        "--grpc-port",
        type=_port,
        default=9876,
        help="port the recording is served on to the viewer (default: 9876; 0: a free one)",
    )
    p.add_argument(
        "--bind",
        default="127.0.0.1",
        help="address to listen on (default: 127.0.0.1, this machine only; 0.0.0.0: every "
        "interface)",
    )
    p.set_defaults(func=run_view)


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number, got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"a port is in [0, 65535], got {value}")
    return value


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


def _free_port(bind: str) -> int:
    with socket.socket() as s:
        s.bind((bind, 0))
        return s.getsockname()[1]


def _rerun_binary() -> str:
    found = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")
    if found is None:
        raise CtxsearchError("the rerun viewer is not installed (pip install rerun-sdk)")
    return found


def viewer_url(host: str, port: int, grpc_port: int) -> str:
    """The address that opens the web viewer on the served recording."""
    proxy = urllib.parse.quote(f"rerun+http://{host}:{grpc_port}/proxy", safe="")
    return f"http://{host}:{port}/?url={proxy}"


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


def _stop(server: subprocess.Popen) -> None:
    """End the viewer's process group (the rerun wrapper and the binary it starts)."""
    for sig, wait in ((signal.SIGTERM, 10), (signal.SIGKILL, 5)):
        try:
            os.killpg(server.pid, sig)
            server.wait(wait)
            return
        except ProcessLookupError:
            return
        except subprocess.TimeoutExpired:
            continue


def run_view(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch view``."""
    check_recording(args.file)
    rerun = _rerun_binary()
    port = args.port or _free_port(args.bind)
    grpc = args.grpc_port or _free_port(args.bind)
    host = "127.0.0.1" if args.bind in ("0.0.0.0", "::") else args.bind
    cmd = [rerun, "--web-viewer", "--bind", args.bind, "--web-viewer-port", str(port)]
    cmd += ["--port", str(grpc), str(args.file)]
    env = {**os.environ, "BROWSER": "true"}  # rerun must not try to open a browser itself
    with tempfile.TemporaryDirectory(prefix="ctxsearch-view-") as tmp:
        log = Path(tmp) / "rerun.log"
        with open(log, "wb") as out:
            server = subprocess.Popen(
                cmd, env=env, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                start_new_session=True,  # its own group: Ctrl-C reaches this process only
            )  # fmt: skip
        try:
            _wait_ready(server, f"http://{host}:{port}/", log)
            print(f"rerun web viewer for {args.file}: {viewer_url(host, port, grpc)}", flush=True)
            print("open it in a browser; Ctrl-C stops the viewer", file=sys.stderr, flush=True)
            code = server.wait()
            raise CtxsearchError(f"rerun's web viewer stopped (exit {code})")
        except KeyboardInterrupt:
            print("viewer stopped", file=sys.stderr)
            return 0
        finally:
            _stop(server)
