"""The viewer's web server: a small ASGI app (Starlette) served by uvicorn, frames over a WebSocket.

Routes (every one but the page's own assets needs the access token, ``?token=...``):

====================  ===========================================================
``GET /``             the page (``static/index.html``)
``GET /static/X``     the page's assets, from a fixed list shipped in the package
``GET /api/info``     what is shown (:meth:`~planeray.viewer.session.ViewSource.describe`) and the colormaps
``GET /api/reports``  the frame-rate reports of pages opened with ``?bench=SECONDS`` (the last 20, JSON)
``WS  /ws``           the live protocol (below)
====================  ===========================================================

Protocol on ``/ws`` (JSON text messages from the page; the server answers JSON text
or binary frames):

* on connecting, the server sends ``{"type": "hello", "source": {...}, "colormaps": {...}, "version": ...}``;
* ``{"type": "render", "panel": P, "id": N, "settings": {...}}`` (settings: the fields of
  :class:`~planeray.viewer.session.ViewSettings`, any subset) is answered by one **binary
  frame**: a little-endian uint32 ``n``, ``n`` bytes of JSON header (``type: "frame"``,
  ``panel``, ``id``, ``width``, ``height``, ``label``, ``auto_white``, ``render_ms``,
  ``encode_ms``, ``queue_ms``, ``sent_at_ms`` -- the server's clock, ms since the epoch
  -- padded with spaces to a multiple of 4 bytes), then the image as ``height * width``
  little-endian float32 values, row by row.  Render requests of a panel that arrive
  while one is being rendered replace each other: only the newest is rendered
  (dragging a slider never builds a queue).  A live device answers with the first frame newer than
  the last one sent, captured at the request's settings (the page keeps asking: frames are shown
  as they arrive);
* ``{"type": "pixel", "panel": P, "id": N, "row": R, "col": C, "settings": {...}}`` is
  answered by ``{"type": "pixel", "panel": P, "id": N, "data": {...}}`` (the plot data of
  :meth:`~planeray.viewer.session.ViewSource.pixel`);
* ``{"type": "ping", "id": N}`` by ``{"type": "pong", "id": N, "server_ms": ...}``;
* ``{"type": "snapshot", "id": N, "settings": {...}}`` (a live device, :mod:`planeray.viewer.live`) by
  ``{"type": "snapshot", "id": N, "data": {"path": ..., "images": ...}}``: what was shown written as a
  stack into the folder the command line named (the page names no path);
* ``{"type": "report", "stats": {...}}`` (a page opened with ``?bench=SECONDS``: its measured frame
  rate and timings) is kept in memory for the benchmark (the last 20), not answered;
* anything wrong (not JSON, an unknown type, a bad setting, a pixel outside the image)
  by ``{"type": "error", "id": N, "panel": P, "message": "..."}``; the connection stays
  open and the server never stops on a bad request.

Safety: the server binds to 127.0.0.1 by default; it reads no path from a request
(the data is what the command line named, opened before serving; assets come from
a fixed table); every data route and the WebSocket need a random token
(:func:`secrets.token_urlsafe`, compared in constant time); on a loopback address
only loopback ``Host`` headers are accepted (no DNS rebinding) and a WebSocket from
another origin is refused.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import logging
import secrets
import socket
import struct
import threading
import time
from importlib import resources
from urllib.parse import urlsplit

import numpy as np

from ..errors import InputError, PlanerayError
from .display import auto_white, colormap_tables
from .session import ViewSettings, ViewSource

__all__ = [
    "make_app",
    "ViewerServer",
    "encode_frame",
    "decode_frame",
    "render_frame",
    "keep_freed_memory",
    "STATIC_FILES",
]

log = logging.getLogger("planeray.viewer")

#: The page's assets: URL name -> (package file, content type).  Nothing else is served.
STATIC_FILES = {
    "index.html": "text/html; charset=utf-8",
    "app.js": "text/javascript; charset=utf-8",
    "plot.js": "text/javascript; charset=utf-8",
    "style.css": "text/css; charset=utf-8",
}

#: Largest message the page may send (a render request is ~300 bytes).
MAX_MESSAGE_BYTES = 64 * 1024
MAX_PANELS = 4
#: Pixel and ping requests that may wait for an answer (render requests replace each other instead).
MAX_WAITING = 64

_LOOPBACK_NAMES = {"127.0.0.1", "localhost", "::1", "[::1]"}
_HEADERS = {
    "Cache-Control": "no-store",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Content-Security-Policy": (
        "default-src 'self'; img-src 'self' data: blob:; style-src 'self'; script-src 'self'; "
        "connect-src 'self'; frame-ancestors 'none'"
    ),
}


def _load_static() -> dict[str, bytes]:
    root = resources.files("planeray.viewer") / "static"
    return {name: (root / name).read_bytes() for name in STATIC_FILES}


def encode_frame(image: np.ndarray, header: dict, *, pixels: bytes | None = None) -> bytes:
    """One binary frame of the protocol: uint32 header length, JSON header (padded), float32 pixels.

    ``pixels``: the image's little-endian float32 bytes, when already made.
    """
    if pixels is None:
        pixels = np.ascontiguousarray(image, dtype="<f4").tobytes()
    head = json.dumps({**header, "height": image.shape[0], "width": image.shape[1]}, separators=(",", ":")).encode()
    head += b" " * (-(4 + len(head)) % 4)
    return b"".join((struct.pack("<I", len(head)), head, pixels))


def decode_frame(data: bytes) -> tuple[dict, np.ndarray]:
    """The header and image of a binary frame (what the page does in JavaScript)."""
    (n,) = struct.unpack_from("<I", data)
    header = json.loads(data[4 : 4 + n])
    image = np.frombuffer(data, dtype="<f4", offset=4 + n).reshape(header["height"], header["width"])
    return header, image


def _check_request(msg) -> tuple[str, int | None, int]:
    if not isinstance(msg, dict):
        raise InputError("a message must be a JSON object")
    kind = msg.get("type")
    if kind not in ("render", "pixel", "ping", "report", "snapshot"):
        raise InputError(f"unknown message type {kind!r} (known: render, pixel, ping, report, snapshot)")
    mid = msg.get("id")
    if mid is not None and (isinstance(mid, bool) or not isinstance(mid, int)):
        raise InputError(f"message id must be an integer, got {mid!r}")
    panel = msg.get("panel", 0)
    if isinstance(panel, bool) or not isinstance(panel, int) or not 0 <= panel < MAX_PANELS:
        raise InputError(f"panel must be an integer 0..{MAX_PANELS - 1}, got {panel!r}")
    return kind, mid, panel


def _gone_errors() -> tuple[type[BaseException], ...]:
    """What a send to a page that went away raises (Starlette's disconnect, uvicorn's, the socket's)."""
    from starlette.websockets import WebSocketDisconnect

    return (WebSocketDisconnect, OSError)


_GONE = _gone_errors()


def render_frame(source: ViewSource, settings: ViewSettings, header: dict) -> bytes:
    """One binary frame of ``settings`` (:func:`encode_frame`), rendered in the source's reused frame
    buffers and encoded while they are held; ``header`` gets the frame's ``auto_white``, ``render_ms``,
    ``encode_ms``, ``sent_at_ms`` and what the source says about the image."""
    t0 = time.perf_counter()
    with source.frame(settings) as (image, info):
        t1 = time.perf_counter()
        header = {**header, "auto_white": auto_white(image), "render_ms": (t1 - t0) * 1e3, **info}
        pixels = np.ascontiguousarray(image, dtype="<f4").tobytes()
        header["encode_ms"] = (time.perf_counter() - t1) * 1e3
        header["sent_at_ms"] = time.time() * 1000
        return encode_frame(image, header, pixels=pixels)


def keep_freed_memory(*, mmap_threshold_bytes: int = 32 << 20, trim_threshold_bytes: int = 256 << 20) -> bool:
    """Ask glibc's allocator to keep freed memory for reuse instead of returning it at once (the serving
    process only: :meth:`ViewerServer.run`).  Returns whether it was set (False off glibc).

    By default glibc maps every block above 128 KiB afresh and returns the top of its heap once more
    than twice that is free (it raises both limits only after a large block has been freed).  The
    frame buffers are the source's own (:class:`~planeray.viewer.session.FrameBuffers`), but each
    frame still computes temporaries outside the viewer: the ``(H, U)`` float64 illumination weights
    of the band and what the renderer makes of them, 1 MiB each at 512 rows and 257 offsets.  A
    freshly started server returned them to the system and faulted them in again page by page, every
    frame (1000 page faults per 512x512 wax frame, 2000 before the frame buffers were reused; twice
    the time per frame of a process that had once freed a large block).  With blocks up to
    ``mmap_threshold_bytes`` (32 MiB, glibc's largest) served from the heap and up to
    ``trim_threshold_bytes`` of free heap kept, every frame reuses the memory of the one before:
    0 page faults per frame from the first.
    """
    import ctypes
    import platform

    if platform.libc_ver()[0] != "glibc":
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # pragma: no cover - glibc always has it
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # <malloc.h>
    return bool(mallopt(M_MMAP_THRESHOLD, int(mmap_threshold_bytes))) and bool(
        mallopt(M_TRIM_THRESHOLD, int(trim_threshold_bytes))
    )


class _Connection:
    """One page: a receiver that keeps the newest request per panel and a worker that answers."""

    def __init__(self, websocket, source: ViewSource, reports: list, executor):
        self.ws = websocket
        self.source = source
        self.reports = reports
        self.executor = executor
        self.latest: dict[int, dict] = {}
        self.others: list[dict] = []
        self.wake = asyncio.Event()
        self.send_lock = asyncio.Lock()
        self.closed = False

    async def send_text(self, obj) -> None:
        await self._send(text=json.dumps(obj, separators=(",", ":"), allow_nan=False))

    async def _send(self, *, text: str | None = None, data: bytes | None = None) -> None:
        """Send, unless the page went away (then the connection is closed and nothing is raised)."""
        if self.closed:
            return
        try:
            async with self.send_lock:
                if text is not None:
                    await self.ws.send_text(text)
                else:
                    await self.ws.send_bytes(data)
        except _GONE:
            self.closed = True

    async def send_error(self, message: str, mid=None, panel=None) -> None:
        await self.send_text({"type": "error", "id": mid, "panel": panel, "message": message})

    async def receive_loop(self) -> None:
        while True:
            msg = await self.ws.receive()
            if msg["type"] == "websocket.disconnect":
                break
            text = msg.get("text")
            if text is None:
                await self.send_error("binary messages are not understood; send JSON text")
                continue
            req = None
            try:
                req = json.loads(text)
                kind, mid, panel = _check_request(req)
            except (ValueError, InputError) as exc:
                mid = req.get("id") if isinstance(req, dict) else None
                await self.send_error(
                    f"bad request: {exc}", mid=mid if isinstance(mid, int) and not isinstance(mid, bool) else None
                )
                continue
            req["_received"] = time.perf_counter()
            if kind == "report":
                if isinstance(req.get("stats"), dict):
                    self.reports.append(req["stats"])
                    del self.reports[:-20]
                continue
            if kind == "render":
                self.latest[panel] = req  # the newest request of a panel wins
                self._hint(req)
            elif len(self.others) >= MAX_WAITING:
                await self.send_error(
                    f"too many requests waiting (at most {MAX_WAITING}); wait for answers", mid, panel
                )
                continue
            else:
                self.others.append(req)
            self.wake.set()
        self.closed = True
        self.wake.set()

    def _hint(self, req: dict) -> None:
        """Tell a live source what the newest request will want, before its turn (a camera starts now)."""
        hint = getattr(self.source, "hint", None)
        if hint is None:
            return
        try:
            hint(self.source.check(ViewSettings.from_dict(req.get("settings"))))
        except PlanerayError:
            pass  # the render itself answers with the error

    async def work_loop(self) -> None:
        while not self.closed:
            await self.wake.wait()
            self.wake.clear()
            while (self.others or self.latest) and not self.closed:
                if self.others:
                    await self.answer(self.others.pop(0))
                else:
                    panel = min(self.latest)
                    await self.answer(self.latest.pop(panel))

    async def answer(self, req: dict) -> None:
        kind, mid, panel = req["type"], req.get("id"), req.get("panel", 0)
        try:
            if kind == "ping":
                await self.send_text({"type": "pong", "id": mid, "server_ms": time.time() * 1000})
                return
            settings = ViewSettings.from_dict(req.get("settings"))
            loop = asyncio.get_running_loop()
            if kind == "snapshot":
                snapshot = getattr(self.source, "snapshot", None)
                if snapshot is None:
                    raise InputError("this source captures nothing to write (the page's PNG snapshot saves the view)")
                data = await loop.run_in_executor(self.executor, snapshot, settings)
                await self.send_text({"type": "snapshot", "id": mid, "panel": panel, "data": data})
                return
            if kind == "pixel":
                row, col = req.get("row"), req.get("col")
                data = await loop.run_in_executor(self.executor, self.source.pixel, row, col, settings)
                await self.send_text({"type": "pixel", "id": mid, "panel": panel, "data": data})
                return
            header = {"type": "frame", "panel": panel, "id": mid, "settings": settings.to_dict()}
            header["queue_ms"] = (time.perf_counter() - req["_received"]) * 1e3
            frame = await loop.run_in_executor(self.executor, render_frame, self.source, settings, header)
            await self._send(data=frame)
        except PlanerayError as exc:  # a bad setting, a device that stopped: one line to the page
            await self.send_error(str(exc), mid=mid, panel=panel)
        except Exception as exc:  # never let one request take the server down
            log.exception("viewer: %s request failed", kind)
            await self.send_error(f"internal error ({type(exc).__name__}: {exc})", mid=mid, panel=panel)


def make_app(source: ViewSource, *, token: str, loopback_only: bool = True, reports: list | None = None, executor=None):
    """The ASGI application showing ``source``.

    Parameters
    ----------
    source : ViewSource
    token : str
        Access token every data route and the WebSocket need (``?token=``).
    loopback_only : bool
        Accept only loopback ``Host`` headers (the server is bound to a loopback address).
    reports : list, optional
        Receives the frame-rate reports of pages opened with ``?bench=SECONDS`` (the last 20).
    executor : concurrent.futures.Executor, optional
        Runs the renders (the source renders one at a time); default: one thread of its own, so
        every frame is rendered by the thread that rendered the one before (and reuses its memory).
    """
    if executor is None:
        executor = _render_executor()
    if reports is None:
        reports = []
    from starlette.applications import Starlette
    from starlette.exceptions import HTTPException
    from starlette.responses import JSONResponse, PlainTextResponse, Response
    from starlette.routing import Route, WebSocketRoute
    from starlette.websockets import WebSocketDisconnect

    from ..io import planeray_version

    static = _load_static()
    hello = {
        "type": "hello",
        "source": source.describe(),
        "colormaps": colormap_tables(),
        "version": planeray_version(),
    }

    def token_ok(given) -> bool:
        return isinstance(given, str) and hmac.compare_digest(given.encode(), token.encode())

    def host_ok(headers) -> bool:
        if not loopback_only:
            return True
        host = headers.get("host", "")
        name = urlsplit(f"//{host}").hostname or ""
        return name in _LOOPBACK_NAMES or f"[{name}]" in _LOOPBACK_NAMES

    def refuse(request) -> Response | None:
        if not host_ok(request.headers):
            return PlainTextResponse("planeray viewer: Host not allowed (use the URL the server printed)\n", 403)
        if not token_ok(request.query_params.get("token")):
            return PlainTextResponse(
                "planeray viewer: missing or wrong access token -- open the URL that `planeray view` printed "
                "(it ends in ?token=...)\n",
                403,
            )
        return None

    async def index(request):
        return refuse(request) or Response(static["index.html"], media_type=STATIC_FILES["index.html"])

    async def asset(request):
        name = request.path_params["name"]
        if name not in static or not host_ok(request.headers):
            return PlainTextResponse(f"planeray viewer: no such asset {name!r}\n", 404)
        return Response(static[name], media_type=STATIC_FILES[name])

    async def favicon(request):
        return Response(status_code=204)

    async def info(request):
        return refuse(request) or JSONResponse(hello)

    async def bench_reports(request):
        return refuse(request) or JSONResponse(list(reports))

    async def ws_endpoint(websocket):
        origin = websocket.headers.get("origin")
        host = websocket.headers.get("host", "")
        if not host_ok(websocket.headers) or not token_ok(websocket.query_params.get("token")):
            await websocket.close(code=1008, reason="missing or wrong access token")
            return
        if origin is not None and urlsplit(origin).netloc != host:
            await websocket.close(code=1008, reason="cross-origin connection refused")
            return
        await websocket.accept()
        conn = _Connection(websocket, source, reports, executor)
        try:
            await websocket.send_text(json.dumps(hello, separators=(",", ":")))
            worker = asyncio.create_task(conn.work_loop())
            try:
                await conn.receive_loop()
            finally:
                conn.closed = True
                conn.wake.set()
                worker.cancel()
                try:
                    await worker
                except (asyncio.CancelledError, WebSocketDisconnect, RuntimeError, OSError):
                    pass
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass  # the page went away mid-send

    async def not_found(request, exc):
        return PlainTextResponse(
            f"planeray viewer: {exc.status_code} {exc.detail} ({request.url.path})\n", exc.status_code
        )

    async def server_error(request, exc):
        log.exception("viewer: request failed")
        return PlainTextResponse(f"planeray viewer: internal error ({type(exc).__name__})\n", 500)

    class _Headers:
        """Security headers on every HTTP response."""

        def __init__(self, app):
            self.app = app

        async def __call__(self, scope, receive, send):
            if scope["type"] != "http":
                return await self.app(scope, receive, send)

            async def send_with_headers(message):
                if message["type"] == "http.response.start":
                    headers = list(message.get("headers", []))
                    headers += [(k.lower().encode(), v.encode()) for k, v in _HEADERS.items()]
                    message = {**message, "headers": headers}
                await send(message)

            return await self.app(scope, receive, send_with_headers)

    app = Starlette(
        routes=[
            Route("/", index),
            Route("/static/{name}", asset),
            Route("/api/info", info),
            Route("/api/reports", bench_reports),
            Route("/favicon.ico", favicon),
            WebSocketRoute("/ws", ws_endpoint),
        ],
        exception_handlers={HTTPException: not_found, Exception: server_error},
    )
    return _Headers(app)


def _render_executor():
    from concurrent.futures import ThreadPoolExecutor

    return ThreadPoolExecutor(max_workers=1, thread_name_prefix="planeray-render")


class ViewerServer:
    """The viewer served by uvicorn: in a background thread (:meth:`start`, tests, benchmarks) or
    in the foreground (:meth:`run`, the command line).

    Parameters
    ----------
    source : ViewSource
    host : str
        Address to bind (default 127.0.0.1: this machine only).
    port : int
        Port; 0 picks a free one.  A port in use falls back to a free one.
    token : str, optional
        Access token (default: 24 random bytes, URL-safe).
    """

    def __init__(self, source: ViewSource, *, host: str = "127.0.0.1", port: int = 0, token: str | None = None):
        import ipaddress

        self.source = source
        self.host = host
        self.token = token or secrets.token_urlsafe(24)
        try:
            self.loopback = host == "localhost" or ipaddress.ip_address(host).is_loopback
        except ValueError:
            self.loopback = False
        self.port_fallback = False
        self.sock = self._bind(host, port)
        self.port = self.sock.getsockname()[1]
        #: Frame-rate reports of pages opened with ``?bench=SECONDS`` (benchmarks).
        self.reports: list[dict] = []
        self.executor = _render_executor()
        self.app = make_app(
            source, token=self.token, loopback_only=self.loopback, reports=self.reports, executor=self.executor
        )
        self._server = None
        self._thread = None

    def warm(self) -> None:
        """Render and encode the page's first frame once in the render thread (its buffers allocated,
        compiled kernels loaded), so that the first frames a page asks for are as fast as the later ones."""
        self.executor.submit(self.source.warm).result()
        settings = ViewSettings.from_dict(self.source.describe()["defaults"])
        self.executor.submit(render_frame, self.source, settings, {"type": "frame"}).result()

    def _bind(self, host: str, port: int) -> socket.socket:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        for attempt in (port, 0) if port else (0,):
            sock = socket.socket(family, socket.SOCK_STREAM)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind((host, attempt))
            except OSError as exc:
                sock.close()
                if attempt == 0:
                    raise InputError(f"cannot listen on {host}: {exc.strerror or exc}") from None
                self.port_fallback = True
                continue
            sock.listen(64)
            sock.set_inheritable(True)
            return sock
        raise InputError(f"cannot listen on {host}")  # pragma: no cover - the loop returns or raises

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/?token={self.token}"

    def _config(self):
        import uvicorn

        return uvicorn.Config(
            self.app,
            log_level="warning",
            ws="websockets-sansio",
            ws_max_size=MAX_MESSAGE_BYTES,
            ws_per_message_deflate=False,  # frames are float32 noise to deflate: it only costs time
            lifespan="off",
            timeout_graceful_shutdown=2,
        )

    def run(self) -> None:
        """Serve in the foreground until interrupted (Ctrl-C); this process serves and nothing else, so
        its allocator keeps freed memory for the next frame (:func:`keep_freed_memory`)."""
        import uvicorn

        keep_freed_memory()
        self.warm()
        self._server = uvicorn.Server(self._config())
        self._server.run(sockets=[self.sock])

    def start(self) -> ViewerServer:
        """Serve in a background thread; returns once the server accepts connections."""
        import uvicorn

        self.warm()
        self._server = uvicorn.Server(self._config())
        self._thread = threading.Thread(target=self._server.run, kwargs={"sockets": [self.sock]}, daemon=True)
        self._thread.start()
        deadline = time.monotonic() + 20
        while not self._server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError("the viewer server did not start")
            time.sleep(0.01)
        return self

    def stop(self) -> None:
        """Stop a server started with :meth:`start` (idempotent)."""
        if self._server is not None:
            self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=10)
            self._thread = None
        self.executor.shutdown(wait=False, cancel_futures=True)
        self.sock.close()
        close = getattr(self.source, "close", None)
        if close is not None:  # a live source releases its device
            close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()
