"""Test helpers for ``clcsg view``: the server as a real subprocess, and a websocket client that
speaks the page's protocol (the messages ``clcsg/viewer/assets/viewer.js`` sends)."""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

#: seconds a test waits for the server, a frame or a reload
TIMEOUT = 60.0


class ViewProcess:
    """``clcsg view SCENE --no-browser`` in a subprocess; stdout and stderr go to files."""

    def __init__(self, scene, workdir: Path, *extra: str, env=None):
        self.workdir = Path(workdir)
        self.out_path = self.workdir / "view.out"
        self.err_path = self.workdir / "view.err"
        self.cmd = [sys.executable, "-m", "clcsg", "view", str(scene), "--no-browser", *extra]
        self.env = {**os.environ, **(env or {})}
        self.proc = None
        self.url = None

    def start(self) -> "ViewProcess":
        self.proc = subprocess.Popen(self.cmd, stdout=open(self.out_path, "w"), stderr=open(self.err_path, "w"),
                                     stdin=subprocess.DEVNULL, env=self.env, cwd=self.workdir)
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            m = re.search(r"at (http://127\.0\.0\.1:\d+/)", self.out_path.read_text())
            if m:
                self.url = m.group(1)
                return self
            if self.proc.poll() is not None:
                raise AssertionError(f"clcsg view exited with {self.proc.returncode}: {self.stderr()}")
            time.sleep(0.1)
        self.stop()
        raise AssertionError(f"clcsg view did not start within {TIMEOUT} s: {self.stderr()}")

    @property
    def port(self) -> int:
        return int(self.url.rstrip("/").rsplit(":", 1)[1])

    def stdout(self) -> str:
        return self.out_path.read_text()

    def stderr(self) -> str:
        return self.err_path.read_text()

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self) -> int:
        if self.alive():
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()


def run_view(scene, workdir, *extra, env=None, timeout=TIMEOUT) -> subprocess.CompletedProcess:
    """``clcsg view`` expected to exit by itself (an error): the finished process."""
    cmd = [sys.executable, "-m", "clcsg", "view", str(scene), "--no-browser", *extra]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=workdir, stdin=subprocess.DEVNULL,
                          env={**os.environ, **(env or {})})


def http_get(url: str, headers=None) -> tuple[int, bytes, dict]:
    """(status, body, headers) of a GET, errors included."""
    req = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=TIMEOUT) as r:
            return r.status, r.read(), dict(r.headers)
    except urllib.error.HTTPError as e:
        return e.code, e.read(), dict(e.headers)


def page_token(url: str) -> str:
    status, body, _ = http_get(url)
    assert status == 200
    return re.search(r'name="clcsg-token" content="([^"]+)"', body.decode()).group(1)


class Page:
    """An async websocket client of the viewer: ``async with Page(url) as page: ...``."""

    def __init__(self, url: str, origin: str | None = None):
        self.url = url
        self.origin = url.rstrip("/") if origin is None else origin
        self.token = page_token(url)
        self.next_id = 0

    async def __aenter__(self):
        import aiohttp

        self.session = aiohttp.ClientSession()
        self.ws = await self.session.ws_connect(f"{self.url.replace('http', 'ws')}ws?token={self.token}",
                                                origin=self.origin)
        return self

    async def __aexit__(self, *exc):
        await self.ws.close()
        await self.session.close()

    async def send(self, **msg) -> None:
        await self.ws.send_str(json.dumps(msg))

    async def receive(self, kinds=("scene", "view", "error", "frame"), timeout=TIMEOUT):
        """The next message whose type is in ``kinds`` (a frame as (header, image bytes))."""
        import aiohttp

        from clcsg.viewer.frames import unpack

        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"no {kinds} message within {timeout} s")
            msg = await asyncio.wait_for(self.ws.receive(), left)
            if msg.type == aiohttp.WSMsgType.BINARY:
                header, data = unpack(msg.data)
                if "frame" in kinds:
                    return header, data
            elif msg.type == aiohttp.WSMsgType.TEXT:
                m = json.loads(msg.data)
                if m["type"] in kinds:
                    return m
            else:
                raise AssertionError(f"websocket closed: {msg}")

    async def hello(self, width=160, height=120) -> tuple[dict, dict]:
        """(scene message, fitted view) for a canvas of width x height."""
        await self.send(type="hello", width=width, height=height)
        scene = await self.receive(("scene",))
        view = (await self.receive(("view",)))["view"]
        return scene, view

    async def frame(self, view, width=160, height=120, quality="rest", method="splat"):
        """(header, image bytes) of the first answer to a frame request (or an error message)."""
        self.next_id += 1
        await self.send(type="frame", id=self.next_id, view=view, width=width, height=height, quality=quality,
                        method=method)
        while True:
            got = await self.receive(("frame", "error"))
            if isinstance(got, dict) or got[0]["id"] == self.next_id:
                return got


def decode(data: bytes):
    """An encoded frame as an (H, W, 3) uint8 array."""
    import io

    import numpy as np
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))
