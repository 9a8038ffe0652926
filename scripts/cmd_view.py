"""``ctxsearch view FILE.rrd``: play a recording back without a display.

``rerun FILE.rrd`` opens rerun's native viewer, which needs a display; on a headless machine (a
server, a container, a remote VM) this command serves rerun's web viewer instead (the rerun
package's own binary serves the viewer over HTTP and the recording over gRPC, idle while no
browser asks: ``scripts.rrd_server``) and prints the address to open in a browser. It runs until
Ctrl-C, which stops the server and exits with 0; SIGTERM or SIGHUP stop it too, with the CLI's
one line and exit code 128 + the signal. rerun's Python SDK is imported only to serve (``--help``
stays fast).
"""

from __future__ import annotations

import argparse
import signal
import sys
import tempfile
from pathlib import Path

from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.scripts.rrd_server import check_recording, free_port, serve


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


def run_view(args: argparse.Namespace) -> int:
    """Handler of ``ctxsearch view``."""
    check_recording(args.file)
    port = args.port or free_port(args.bind)
    grpc = args.grpc_port or free_port(args.bind)
    with tempfile.TemporaryDirectory(prefix="ctxsearch-view-") as tmp:
        try:
            with serve(args.file, args.bind, port, grpc, Path(tmp) / "rerun.log") as served:
                print(f"rerun web viewer for {args.file}: {served.url}", flush=True)
                print("open it in a browser; Ctrl-C stops the viewer", flush=True)
                code = served.process.wait()
                raise CtxsearchError(f"rerun's web viewer stopped (exit {code})")
        except KeyboardInterrupt as exc:  # the server's group is ended by now
            if getattr(exc, "signum", signal.SIGINT) != signal.SIGINT:
                raise  # SIGTERM, SIGHUP: the CLI's one line and exit code
            print("viewer stopped", file=sys.stderr)
            return 0
