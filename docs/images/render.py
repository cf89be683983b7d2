"""Render a run's recording in the Rerun web viewer, headless, and save screenshots of its layout.

    python docs/images/render.py RUN_DIR [--out docs/images] [--name quickstart] [--wait 40]
    python docs/images/render.py RUN_DIR --name chapter5 --timelines trial sim_time

For each of the ``trial`` and ``sim_time`` timelines: the run's default blueprint
(:func:`sfl_brain.recording.rrlog.blueprint` with the run's layout, :func:`sfl_brain.recording.rrlog.layout_of` of
the scenario the run folder holds: the planar walker's, or the humanoid's of chapter 5) with that timeline selected
is written to a ``.rbl`` file,
merged with the recording (whose own layout is only a default, so this one is shown), served over
HTTP on 127.0.0.1 to the Rerun web viewer (``rerun --web-viewer``), and headless Chromium (software GL:
``--use-angle=swiftshader``), driven over its DevTools protocol, opens it and saves
``<name>-<timeline>.png``. The layout follows the newest data, so the time cursor is at the end of
the run.

Needs Debian's ``chromium`` (``apt-get install chromium``); uses only the standard library besides
the project. The viewer loads the recording in the page, so the screenshot is taken after ``--wait``
seconds (about 40 for the quickstart on 2 software-rendering cores).
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
import urllib.request
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from sfl_brain.recording.rrlog import blueprint, layout_of
from sfl_brain.scenario import load


class _Files(SimpleHTTPRequestHandler):
    """The recording and the blueprint, to a page on another port (CORS allowed), quietly."""

    def end_headers(self) -> None:
        self.send_header("Access-Control-Allow-Origin", "*")
        super().end_headers()

    def log_message(self, *args) -> None:
        pass


def _rerun() -> list[str]:
    return [shutil.which("rerun")] if shutil.which("rerun") else [sys.executable, "-m", "rerun"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class DevTools:
    """The smallest WebSocket client the DevTools protocol needs (text frames, one page)."""

    def __init__(self, ws_url: str) -> None:
        host, path = ws_url.removeprefix("ws://").split("/", 1)
        name, port = host.split(":")
        self.sock = socket.create_connection((name, int(port)), timeout=120)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                f"GET /{path} HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        reply = b""
        while b"\r\n\r\n" not in reply:
            reply += self.sock.recv(4096)
        self.ids = 0

    def _send(self, text: str) -> None:
        data, mask = text.encode(), os.urandom(4)
        n = len(data)
        head = bytes([0x81]) + (
            bytes([0x80 | n])
            if n < 126
            else bytes([0x80 | 126]) + struct.pack(">H", n)
            if n < 65536
            else bytes([0x80 | 127]) + struct.pack(">Q", n)
        )
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def _exact(self, n: int) -> bytes:
        out = b""
        while len(out) < n:
            chunk = self.sock.recv(n - len(out))
            if not chunk:
                raise EOFError("the browser closed the DevTools connection")
            out += chunk
        return out

    def _receive(self) -> str:
        message = b""
        while True:
            first, second = self._exact(2)
            n = second & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._exact(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._exact(8))[0]
            message += self._exact(n)
            if first & 0x80:
                return message.decode(errors="replace")

    def call(self, method: str, **params) -> dict:
        self.ids += 1
        self._send(json.dumps({"id": self.ids, "method": method, "params": params}))
        while True:
            reply = json.loads(self._receive())
            if reply.get("id") == self.ids:
                return reply.get("result", reply)


def screenshot(url: str, out: Path, wait: float, size=(1600, 1000)) -> None:
    port = free_port()
    profile = tempfile.mkdtemp(prefix="sfl-chromium-")
    browser = subprocess.Popen(
        [
            shutil.which("chromium") or "chromium",
            "--headless",
            "--no-sandbox",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={profile}",
            f"--window-size={size[0]},{size[1]}",
            "--remote-debugging-address=127.0.0.1",
            f"--remote-debugging-port={port}",
            "about:blank",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                tabs = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json"))
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        page = DevTools(next(t for t in tabs if t["type"] == "page")["webSocketDebuggerUrl"])
        page.call(
            "Emulation.setDeviceMetricsOverride", width=size[0], height=size[1], deviceScaleFactor=1, mobile=False
        )
        page.call("Page.navigate", url=url)
        time.sleep(wait)  # the viewer loads the recording inside the page: no event says it is done
        shot = page.call("Page.captureScreenshot", format="png")
        out.write_bytes(base64.b64decode(shot["data"]))
    finally:
        browser.terminate()
        browser.wait()
        shutil.rmtree(profile, ignore_errors=True)


def render(rrd: Path, timeline: str, out: Path, wait: float, layout: dict | None = None) -> None:
    """Serve ``rrd`` with the layout for ``timeline`` (``layout``: :func:`blueprint`'s arguments) over HTTP, host the
    web viewer, screenshot it."""
    grpc, web, files = free_port(), free_port(), free_port()
    with tempfile.TemporaryDirectory() as tmp:
        # the recording with the layout for this timeline (active; the recording's own is a default)
        layout_file, merged = Path(tmp) / "layout.rbl", Path(tmp) / "recording.rrd"
        blueprint(timeline, **(layout or {})).save("sfl-brain", layout_file)
        subprocess.run([*_rerun(), "rrd", "merge", str(rrd), str(layout_file), "-o", str(merged)], check=True)
        server = ThreadingHTTPServer(("127.0.0.1", files), partial(_Files, directory=tmp))
        threading.Thread(target=server.serve_forever, daemon=True).start()
        started = []
        try:
            started.append(
                subprocess.Popen(
                    [
                        *_rerun(),
                        "--web-viewer",
                        "--bind",
                        "127.0.0.1",
                        "--port",
                        str(grpc),
                        "--web-viewer-port",
                        str(web),
                        "--renderer",
                        "webgl",
                    ],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    start_new_session=True,  # the rerun wrapper and the viewer it starts: stopped together
                )
            )
            for port in (files, web):
                deadline = time.monotonic() + 30
                while True:
                    try:
                        urllib.request.urlopen(f"http://127.0.0.1:{port}/")
                        break
                    except OSError:
                        if time.monotonic() > deadline:
                            raise
                        time.sleep(0.2)
            data = f"http://127.0.0.1:{files}/recording.rrd"
            query = urllib.parse.urlencode([("url", data), ("renderer", "webgl")])
            screenshot(f"http://127.0.0.1:{web}/?{query}", out, wait)
        finally:
            for proc in started:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait()
            server.shutdown()
            server.server_close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent)
    parser.add_argument("--name", default="quickstart")
    parser.add_argument("--wait", type=float, default=40.0)
    parser.add_argument("--timelines", nargs="+", default=["trial", "sim_time"], choices=["trial", "sim_time"])
    args = parser.parse_args()
    layout = layout_of(load(args.run_dir / "scenario.yaml"))  # the layout the run itself sent
    for timeline in args.timelines:
        out = args.out / f"{args.name}-{timeline}.png"
        render(args.run_dir / "recording.rrd", timeline, out, args.wait, layout)
        print(out)


if __name__ == "__main__":
    main()
