"""Screenshots of recordings as rerun's web viewer shows them, in headless Chromium.

    python scripts/screenshot_rrd.py demo/learn.rrd demo/search.rrd --out demo/screenshots

For every ``.rrd``: serve it with the rerun package's own web viewer (``scripts.rrd_server``,
as ``ctxsearch view`` does, on 127.0.0.1 only), open the viewer in headless Chromium (software WebGL), wait until it has
loaded and laid out the recording by its blueprint, and save ``OUT/<name>.png``. Chromium is
driven over the DevTools protocol with a minimal WebSocket client (standard library only).
Needs ``chromium`` on PATH (Debian: ``apt-get install chromium``). Not part of the test suite:
it checks by eye what the tests check by reading the files back. Ctrl-C, SIGTERM and SIGHUP end it
with one line and exit code 128 + the signal, the viewer's and Chromium's process groups ended.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request
from pathlib import Path

from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.scripts import handle_stop_signals, last_stop, raise_stopped, stop_code, stop_line
from ctxsearch.scripts.rrd_server import end_group, free_port, serve

CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--remote-allow-origins=*",
)


def _wait_http(url: str, timeout: float) -> None:
    t_end = time.monotonic() + timeout
    while True:
        try:
            with urllib.request.urlopen(url, timeout=2):
                return
        except OSError:
            if time.monotonic() > t_end:
                raise
            time.sleep(0.3)


class DevTools:
    """A DevTools-protocol session with one page, over a minimal WebSocket client."""

    def __init__(self, ws_url: str) -> None:
        u = urllib.parse.urlparse(ws_url)
        self.sock = socket.create_connection((u.hostname, u.port), timeout=120)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                f"GET {u.path} HTTP/1.1\r\nHost: {u.hostname}:{u.port}\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                "Sec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        head = b""
        while b"\r\n\r\n" not in head:
            head += self.sock.recv(1)
        if b" 101 " not in head.split(b"\r\n", 1)[0]:
            raise RuntimeError(f"WebSocket upgrade refused: {head[:200]!r}")
        self._id = 0

    def _send(self, text: str) -> None:
        data = text.encode()
        mask = os.urandom(4)
        n = len(data)
        if n < 126:
            header = struct.pack("!BB", 0x81, 0x80 | n)
        elif n < 1 << 16:
            header = struct.pack("!BBH", 0x81, 0x80 | 126, n)
        else:
            header = struct.pack("!BBQ", 0x81, 0x80 | 127, n)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(data))
        self.sock.sendall(header + mask + masked)

    def _exact(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionError("DevTools connection closed")
            buf += chunk
        return buf

    def _recv(self) -> str:
        parts = []
        while True:
            b0, b1 = self._exact(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack("!H", self._exact(2))[0]
            elif n == 127:
                n = struct.unpack("!Q", self._exact(8))[0]
            parts.append(self._exact(n))
            if b0 & 0x80:
                return b"".join(parts).decode()

    def call(self, method: str, **params) -> dict:
        """Send a command and return its result (events in between are skipped)."""
        self._id += 1
        self._send(json.dumps({"id": self._id, "method": method, "params": params}))
        while True:
            msg = json.loads(self._recv())
            if msg.get("id") == self._id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})


def screenshot(rrd: Path, png: Path, wait_s: float, size: tuple[int, int]) -> None:
    """Serve ``rrd`` in rerun's web viewer, open it in headless Chromium, save a PNG."""
    web, grpc, debug = free_port(), free_port(), free_port()
    profile = tempfile.mkdtemp(prefix="ctxsearch-chromium-")
    browser = None
    try:
        with serve(rrd, "127.0.0.1", web, grpc, Path(profile) / "rerun.log") as served:
            browser = subprocess.Popen(
                ["chromium", *CHROMIUM_FLAGS, f"--user-data-dir={profile}/chromium"]
                + [f"--remote-debugging-port={debug}", f"--window-size={size[0]},{size[1]}"]
                + ["about:blank"],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
            _wait_http(f"http://127.0.0.1:{debug}/json/version", 30)
            with urllib.request.urlopen(f"http://127.0.0.1:{debug}/json/list") as r:
                page = next(t for t in json.load(r) if t["type"] == "page")
            dt = DevTools(page["webSocketDebuggerUrl"])
            dt.call(
                "Emulation.setDeviceMetricsOverride",
                width=size[0],
                height=size[1],
                deviceScaleFactor=1,
                mobile=False,
            )
            dt.call("Page.navigate", url=f"{served.url}&renderer=webgl")
            time.sleep(wait_s)
            shot = dt.call("Page.captureScreenshot", format="png")
            png.parent.mkdir(parents=True, exist_ok=True)
            png.write_bytes(base64.b64decode(shot["data"]))
    finally:
        if browser is not None:
            end_group(browser)
        shutil.rmtree(profile, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    """Screenshot every recording given on the command line."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rrd", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, default=Path("screenshots"))
    ap.add_argument("--wait", type=float, default=40.0, help="seconds to let the viewer load")
    ap.add_argument("--size", default="1800x1100", help="window size WxH (default 1800x1100)")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    handle_stop_signals(raise_stopped)
    try:
        for rrd in args.rrd:
            png = args.out / f"{rrd.stem}.png"
            screenshot(rrd, png, args.wait, (w, h))
            print(f"wrote {png}")
    except KeyboardInterrupt as exc:  # the groups are ended by now
        signum = getattr(exc, "signum", None) or last_stop()
        print(stop_line(signum), file=sys.stderr)
        return stop_code(signum)
    except CtxsearchError as exc:
        print(f"ctxsearch: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
