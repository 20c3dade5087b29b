"""The viewer's web server (aiohttp): the page, a websocket for frames and the save buttons.

Only the local user gets in:

* it listens on 127.0.0.1 only, on a socket bound before anything slow happens
  (:func:`bind`: a port in use is a one-line error at once);
* it serves its two assets and nothing else from the disk: there is no static-file route, so
  ``/../../etc/passwd`` and ``/%2e%2e/...`` are 404;
* requests whose ``Host`` is not this server's (DNS rebinding) get 403;
* websocket upgrades whose ``Origin`` is not this server's get 403, and the websocket and
  the downloads need the random token embedded in the page (another site cannot read it).

Frames: every websocket client has one slot for its newest frame request; a render task per
client takes it when the device is free, so stale camera positions are dropped.  All device
work (frames, reloads, radius changes) runs in one worker thread, one job at a time, so the
event loop stays responsive.  A resting splat frame is followed by a supersampled one
(:func:`clcsg.viewer.frames.rest_aa`) when no newer request has come in.
"""

from __future__ import annotations

import asyncio
import errno
import html
import importlib.resources
import json
import secrets
import socket
import time
from concurrent.futures import ThreadPoolExecutor

from ..errors import ClcsgError, UsageError
from . import frames
from .watch import watch
from ..progress import using

ASSETS = {"/": ("index.html", "text/html; charset=utf-8"),
          "/viewer.js": ("viewer.js", "text/javascript; charset=utf-8")}
DOWNLOADS = {"view.png": "png", "view.npz": "npz", "samples.ply": "ply"}
HOST = "127.0.0.1"


def bind(port: int = 0) -> socket.socket:
    """A listening TCP socket on 127.0.0.1:``port`` (0: a free port)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((HOST, int(port)))
        sock.listen(128)
    except OSError as e:
        sock.close()
        if e.errno == errno.EADDRINUSE:
            raise UsageError(f"--port {port}: {HOST}:{port} is already in use (another clcsg view?); pick another "
                             "port or leave out --port for a free one") from None
        raise UsageError(f"--port {port}: cannot listen on {HOST}:{port}: {e.strerror or e}") from None
    sock.setblocking(False)
    return sock


def _one_line(e: BaseException) -> str:
    return " ".join(str(e).split()) or type(e).__name__


class Client:
    """One websocket connection: its newest frame request and its canvas size."""

    def __init__(self, ws):
        self.ws = ws
        self.pending: dict | None = None
        self.wake = asyncio.Event()
        self.closed = False

    def request(self, req: dict) -> None:
        self.pending = req
        self.wake.set()

    async def send(self, payload) -> None:
        if self.closed or self.ws.closed:
            return
        try:
            if isinstance(payload, bytes):
                await self.ws.send_bytes(payload)
            else:
                await self.ws.send_str(json.dumps(payload))
        except (ConnectionError, RuntimeError):
            self.closed = True


class ViewerServer:
    """Serves a :class:`~clcsg.viewer.session.Session` on a socket from :func:`bind`.

    ``log(kind, message)``: one line for the terminal, ``kind`` ``"info"`` or ``"error"``.
    ``reporter``: the progress reporter reloads run their step on (None: none).
    """

    def __init__(self, session, sock: socket.socket, log=None, reporter=None, force_polling: bool | None = None):
        self.session = session
        self.sock = sock
        self.port = sock.getsockname()[1]
        self.token = secrets.token_urlsafe(18)
        self.log = log or (lambda kind, message: None)
        self.reporter = reporter
        self.force_polling = force_polling
        self.clients: set[Client] = set()
        self.device = ThreadPoolExecutor(1, thread_name_prefix="clcsg-device")
        self.hosts = {f"{HOST}:{self.port}", f"localhost:{self.port}"}
        self.origins = {f"http://{h}" for h in self.hosts}
        self.stop = asyncio.Event()
        self.frames_sent = 0
        self._tasks: set = set()
        #: seconds a resting frame may spend on supersampling (0: never)
        self.rest_budget = frames.REST_BUDGET
        self._assets = {route: self._asset(name) for route, (name, _) in ASSETS.items()}

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.port}/"

    # -- the app ----------------------------------------------------------------------------------
    def app(self):
        from aiohttp import web

        @web.middleware
        async def guard(request, handler):
            return await self._guard(request, handler)

        app = web.Application(middlewares=[guard], client_max_size=1 << 16)
        for route in ASSETS:
            app.router.add_get(route, self._serve_asset)
        app.router.add_get("/ws", self._websocket)
        for name in DOWNLOADS:
            app.router.add_get(f"/save/{name}", self._download)
        return app

    def _asset(self, name: str) -> bytes:
        text = importlib.resources.files("clcsg.viewer").joinpath("assets", name).read_text(encoding="utf-8")
        text = text.replace("{{TOKEN}}", self.token).replace("{{NAME}}", html.escape(self.session.name))
        return text.encode("utf-8")

    def _csp(self) -> str:
        ws = " ".join(f"ws://{h}" for h in sorted(self.hosts))
        return (f"default-src 'self'; img-src 'self' blob: data:; connect-src 'self' {ws}; "
                "style-src 'self' 'unsafe-inline'; frame-ancestors 'none'; base-uri 'none'")

    async def _guard(self, request, handler):
        from aiohttp import web

        if request.host not in self.hosts:
            return web.Response(status=403, text="403: this server answers only to its own address\n")
        try:
            resp = await handler(request)
        except web.HTTPException as e:
            resp = web.Response(status=e.status, text=f"{e.status}: {e.reason}\n")
        resp.headers.setdefault("X-Content-Type-Options", "nosniff")
        resp.headers.setdefault("Cache-Control", "no-store")
        resp.headers.setdefault("Referrer-Policy", "no-referrer")
        resp.headers.setdefault("Content-Security-Policy", self._csp())
        return resp

    def _token_ok(self, request) -> bool:
        return secrets.compare_digest(request.query.get("token", ""), self.token)

    async def _serve_asset(self, request):
        from aiohttp import web

        return web.Response(body=self._assets[request.path], content_type=ASSETS[request.path][1].split(";")[0],
                            charset="utf-8")

    async def _download(self, request):
        from aiohttp import web

        if not self._token_ok(request):
            return web.Response(status=403, text="403: bad token\n")
        model = self.session.model
        if model is None:
            return web.Response(status=503, text="503: no model yet\n")
        name = request.path.rsplit("/", 1)[1]
        try:
            body, ctype = await asyncio.get_running_loop().run_in_executor(
                self.device, frames.download, self.session.context, model, dict(request.query), DOWNLOADS[name])
        except ClcsgError as e:
            return web.Response(status=400, text=f"400: {_one_line(e)}\n")
        stem = self.session.name.rsplit(".", 1)[0] or "scene"
        filename = f"{stem}-samples.ply" if name == "samples.ply" else f"{stem}.{name.rsplit('.', 1)[1]}"
        return web.Response(body=body, content_type=ctype,
                            headers={"Content-Disposition": f'attachment; filename="{filename}"'})

    # -- the websocket ----------------------------------------------------------------------------
    async def _websocket(self, request):
        from aiohttp import WSMsgType, web

        if request.headers.get("Origin") not in self.origins:
            return web.Response(status=403, text="403: websocket from another origin\n")
        if not self._token_ok(request):
            return web.Response(status=403, text="403: bad token\n")
        # no permessage-deflate: the frames are PNG or JPEG already, deflating them again costs
        # milliseconds per frame and saves nothing
        ws = web.WebSocketResponse(max_msg_size=1 << 16, compress=False)
        await ws.prepare(request)
        client = Client(ws)
        self.clients.add(client)
        worker = asyncio.create_task(self._render_loop(client))
        try:
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    await self._on_message(client, msg.data)
                elif msg.type == WSMsgType.ERROR:
                    break
        finally:
            client.closed = True
            client.wake.set()
            self.clients.discard(client)
            worker.cancel()
        return ws

    async def _on_message(self, client: Client, text: str) -> None:
        try:
            msg = json.loads(text)
            kind = msg.get("type") if isinstance(msg, dict) else None
        except ValueError:
            kind = None
        if kind == "frame":
            client.request(msg)
        elif kind in ("hello", "fit"):
            await self._send_view(client, msg, kind)
        elif kind == "radius":  # in a task: the client's frame requests keep coming in meanwhile
            self._spawn(self._device_job("radius", f"sampling {self.session.name} again at radius {msg.get('value')}",
                                         self.session.set_radius, msg.get("value")))
        elif kind == "reload":
            self._spawn(self.reload())
        else:
            await client.send({"type": "error", "message": f"unknown message {text[:80]!r}"})

    async def _send_view(self, client: Client, msg: dict, kind: str) -> None:
        model = self.session.model
        if kind == "hello":
            await client.send(self.scene_message())
        if model is None:
            return
        try:
            view = await asyncio.get_running_loop().run_in_executor(
                None, frames.fitted_view, model.samples, msg.get("width", 640), msg.get("height", 480))
        except ClcsgError as e:
            await client.send({"type": "error", "message": _one_line(e)})
            return
        await client.send({"type": "view", "view": view})

    def _spawn(self, coro) -> None:
        task = asyncio.create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def scene_message(self) -> dict:
        s = self.session
        return {"type": "scene", "name": s.name, "model": None if s.model is None else s.model.summary(),
                "error": s.error, "files": [f.rsplit("/", 1)[-1] for f in s.files]}

    async def _render_loop(self, client: Client) -> None:
        loop = asyncio.get_running_loop()
        ctx = self.session.context
        while not client.closed:
            await client.wake.wait()
            client.wake.clear()
            req, client.pending = client.pending, None
            model = self.session.model
            if req is None or model is None:
                continue
            try:
                data, header = await loop.run_in_executor(self.device, frames.frame, ctx, model, req, 1)
                await client.send(data)
                self.frames_sent += 1
                if header["quality"] == "rest" and header["method"] == "splat":
                    aa = frames.rest_aa(header["render_ms"], self.rest_budget)
                    if aa > 1 and client.pending is None:
                        data, _ = await loop.run_in_executor(self.device, frames.frame, ctx, model, req, aa)
                        if client.pending is None:
                            await client.send(data)
                            self.frames_sent += 1
            except ClcsgError as e:
                await client.send({"type": "error", "message": _one_line(e), "frame": req.get("id")})
            except Exception as e:  # a bug: say so in the page and on the terminal, keep serving
                self.log("error", f"internal error while rendering: {type(e).__name__}: {_one_line(e)}")
                await client.send({"type": "error", "message": f"internal error: {type(e).__name__}: {_one_line(e)}"})

    # -- reloads ----------------------------------------------------------------------------------
    async def reload(self, changed=None) -> None:
        """Load the scene again (in the device thread) and tell every page."""
        await self._device_job("reload", f"reloading {self.session.name}", self.session.reload)

    async def _device_job(self, name: str, label: str, fn, *args) -> None:
        t0 = time.perf_counter()
        model = await asyncio.get_running_loop().run_in_executor(self.device, self._in_step, name, label, fn, *args)
        if model is None:
            self.log("error", f"{name} failed, still showing the last good model: {self.session.error}")
            await self._broadcast({"type": "error", "message": self.session.error})
            return
        self.log("info", f"{self.session.name}: {len(model.samples):,} samples (r = {model.radius:.6g}) in "
                         f"{time.perf_counter() - t0:.2f} s")
        await self._broadcast(self.scene_message())

    def _in_step(self, name, label, fn, *args):
        """``fn(*args)`` (a new model or None) as a progress step, then the model's warm-up."""
        import contextlib


        with contextlib.ExitStack() as stack:
            if self.reporter is not None:
                stack.enter_context(using(self.reporter))
                stack.enter_context(self.reporter.step(name, label))
            model = fn(*args)
            if model is not None:
                frames.warm_up(self.session.context, model)
            return model

    async def _broadcast(self, msg: dict) -> None:
        for c in list(self.clients):
            await c.send(msg)

    # -- running ----------------------------------------------------------------------------------
    async def serve(self, ready=None) -> None:
        """Serve until :attr:`stop` is set; ``ready()`` is called once the page can be loaded."""
        from aiohttp import web

        runner = web.AppRunner(self.app(), access_log=None, handle_signals=False)
        await runner.setup()
        site = web.SockSite(runner, self.sock, shutdown_timeout=1.0)
        await site.start()
        watcher = asyncio.create_task(watch(lambda: self.session.files, self.reload, self.stop, self.force_polling))
        try:
            if ready is not None:
                ready()
            await self.stop.wait()
        finally:
            watcher.cancel()
            for task in list(self._tasks):
                task.cancel()
            for c in list(self.clients):
                c.closed = True
                await c.ws.close()
            await runner.cleanup()
            self.device.shutdown(wait=False, cancel_futures=True)
