"""The system's Chromium, for the browser tests and the frame-rate benchmark (never a downloaded browser).

:func:`measure_painted_fps` opens the page with ``?bench=SECONDS`` in a headless Chromium started
directly, with no debugging protocol attached: the page sweeps the delay slider of its first panel
(one input event per displayed frame, as a hand dragging it), counts the frames it paints and
reports them, with the median time of each step, to the server (``{"type": "report"}``).  A
browser driven over the DevTools protocol (Playwright, Puppeteer) would copy every WebSocket
frame into the protocol, base64-encoded, and measure that instead of the page.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
import time

from ..errors import InputError

__all__ = ["find_chromium", "chromium_args", "measure_painted_fps"]


def find_chromium() -> str | None:
    """Path of a system Chromium: ``$PLANERAY_CHROMIUM``, else ``chromium`` (Debian), ``chromium-browser``,
    ``google-chrome`` on the PATH; None if there is none."""
    for name in (os.environ.get("PLANERAY_CHROMIUM"), "chromium", "chromium-browser", "google-chrome"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def chromium_args() -> list[str]:
    """Command-line flags Chromium needs here (``--no-sandbox`` as root: its sandbox refuses root)."""
    return ["--no-sandbox"] if hasattr(os, "geteuid") and os.geteuid() == 0 else []


def measure_painted_fps(
    server, *, seconds: float = 5.0, chromium: str | None = None, timeout_s: float = 90.0, uncapped: bool = False
) -> dict:
    """Frames painted per second by the page of ``server`` (a started :class:`~planeray.viewer.server.ViewerServer`)
    while its delay slider moves, with the median milliseconds of each step.

    Returns the page's report: ``fps``, ``frames``, ``seconds``, ``display_hz`` (animation frames per
    second of the idle page: the display's refresh rate), ``width``, ``height`` and the medians
    ``render_ms``, ``encode_ms`` (server), ``queue_ms`` (waiting for the renderer), ``transfer_ms``
    (server send to page receive, same clock), ``decode_ms``, ``paint_ms`` (page) and
    ``latency_ms`` (request sent to frame painted).

    ``uncapped``: Chromium without vsync and frame-rate limit, the slider moved 250 times a second
    on a timer: what the whole pipeline delivers beyond a display's refresh rate.
    """
    path = chromium or find_chromium()
    if path is None:
        raise InputError("no chromium found: install it (Debian: apt-get install chromium) or set PLANERAY_CHROMIUM")
    before = len(server.reports)
    with tempfile.TemporaryDirectory(prefix="planeray-chromium-") as profile:
        proc = subprocess.Popen(
            [
                path,
                "--headless=new",
                *chromium_args(),
                f"--user-data-dir={profile}",
                "--window-size=1500,1000",
                "--no-first-run",
                "--mute-audio",
                *(["--disable-frame-rate-limit", "--disable-gpu-vsync"] if uncapped else []),
                f"{server.url}&bench={seconds:g}" + ("&input_hz=250" if uncapped else ""),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,  # its own process group: stopped as a whole below
        )
        try:
            deadline = time.monotonic() + timeout_s
            while len(server.reports) == before and time.monotonic() < deadline and proc.poll() is None:
                time.sleep(0.05)
        finally:
            try:
                os.killpg(proc.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    if len(server.reports) == before:
        raise RuntimeError(f"the page did not report its frame rate within {timeout_s:g} s (chromium: {path})")
    return dict(server.reports[-1])
