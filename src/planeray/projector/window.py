"""The projector window: borderless, full screen, vsync'd, on a chosen screen, in a process of its own.

The window runs in a child process (:mod:`planeray.projector._window`, pyglet
and OpenGL) that this object drives over a pipe: the caller never loads OpenGL,
every wait on the window has a timeout that says what it waited for, and when
the caller ends -- normally, on an error, on Ctrl-C -- the child ends with it
and the X server removes the window, leaving the screen as it was.
"""

from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import time

import numpy as np

from ..errors import DeviceError, InputError
from .patterns import as_rgb8, place
from .screens import Screen, _child_env, _need_pyglet, get_screen

__all__ = ["ProjectorWindow", "DEFAULT_TIMEOUT_S"]

#: How long the window may take to open, or to show a pattern (seconds).
DEFAULT_TIMEOUT_S = 20.0


class ProjectorWindow:
    """A borderless full-screen window on one screen, showing one pattern at a time.

    Pixel ``(r, c)`` of a pattern is pixel ``(r, c)`` of the screen: no scaling,
    filtering, blending, colour management or gamma; a pattern of another size
    than the screen is refused unless it is placed (``at=(row, column)``).

    Parameters
    ----------
    screen : int or Screen
        The screen (``--screen N``; :func:`planeray.projector.list_screens`).
    display : str, optional
        X display (default ``$DISPLAY``).
    settle_frames : int
        Vsyncs to wait after a pattern is first on the screen before :meth:`show`
        returns (the projector's own input latency; 1 at least).
    timeout_s : float
        Longest wait for the window to open or for a pattern to be shown.

    See Also
    --------
    parse_pattern : patterns to show.
    list_screens : the screens.

    Examples
    --------
    >>> from planeray.projector import ProjectorWindow, comb  # doctest: +SKIP
    >>> with ProjectorWindow(1) as win:  # doctest: +SKIP
    ...     win.show(comb(win.shape, 8, 3))
    """

    def __init__(self, screen=0, *, display: str | None = None, settle_frames: int = 2, timeout_s=DEFAULT_TIMEOUT_S):
        _need_pyglet()
        self.screen: Screen = screen if isinstance(screen, Screen) else get_screen(screen, display)
        self.settle_frames = int(settle_frames)
        self.timeout_s = float(timeout_s)
        self.closed_reason: str | None = None
        self._shown = 0
        self.pattern: np.ndarray | None = None
        s = self.screen
        cmd = [sys.executable, "-m", "planeray.projector._window", "serve", s.display, str(s.x_screen), str(s.head)]
        self._proc = subprocess.Popen(
            cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_child_env()
        )
        try:
            ready = self._answer(f"the projector window to open on screen {s.index} ({s.x_display})")
            if (ready.get("width"), ready.get("height")) != (s.width, s.height):
                raise DeviceError(
                    f"the window on screen {s.index} is {ready.get('width')}x{ready.get('height')}, the screen "
                    f"{s.width}x{s.height}: the window manager did not let it cover the screen"
                )
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------------ the pipe
    def _answer(self, what: str, timeout_s: float | None = None) -> dict:
        """The child's next JSON line, or a DeviceError naming what was waited for."""
        timeout = self.timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout
        out = self._proc.stdout
        line = b""
        while not line.endswith(b"\n"):
            left = deadline - time.monotonic()
            ready, _, _ = select.select([out], [], [], max(0.0, left))
            if not ready:
                raise DeviceError(f"waited {timeout:g} s for {what}: no answer from the window")
            chunk = os.read(out.fileno(), 1)
            if not chunk:
                err = self._stderr_tail()
                raise DeviceError(f"the projector window ended while waiting for {what}" + (f": {err}" if err else ""))
            line += chunk
        msg = json.loads(line)
        if "error" in msg:
            raise DeviceError(f"the projector window failed while waiting for {what}: {msg['error']}")
        if "closed" in msg:
            self.closed_reason = msg["closed"]
            raise DeviceError(f"the projector window was closed ({msg['closed']}) while waiting for {what}")
        return msg

    def _stderr_tail(self) -> str:
        try:
            self._proc.wait(timeout=2.0)
            text = self._proc.stderr.read().decode(errors="replace").strip()
        except Exception:
            return ""
        lines = [ln for ln in text.splitlines() if ln.strip()]
        return lines[-1][:300] if lines else ""

    def _send(self, obj: dict, data: bytes = b"") -> None:
        try:
            self._proc.stdin.write(json.dumps(obj).encode() + b"\n" + data)
            self._proc.stdin.flush()
        except (BrokenPipeError, ValueError, OSError):
            raise DeviceError(f"the projector window on screen {self.screen.index} is gone") from None

    # ------------------------------------------------------------------ the API
    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, columns)`` of the screen and of every pattern shown whole."""
        return self.screen.shape

    @property
    def is_open(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def show(self, pattern, *, at: tuple[int, int] | None = None) -> None:
        """Show ``pattern`` and return once it is on the screen (and ``settle_frames`` vsyncs later).

        Parameters
        ----------
        pattern : array_like
            ``(rows, columns)`` or ``(rows, columns, 3)``, uint8 (0-255), bool or float
            in ``[0, 1]`` (:func:`planeray.projector.as_rgb8`).
        at : (int, int), optional
            Place a pattern of another size with its top-left pixel at ``(row,
            column)`` of a black screen.  Without it, a pattern of another size than
            the screen is refused.

        Raises
        ------
        InputError
            A pattern of the wrong size, or one that does not fit where placed.
        DeviceError
            The window is gone, or did not show the pattern within the timeout.
        """
        rgb = as_rgb8(pattern) if at is None else place(pattern, self.shape, at)
        if rgb.shape[:2] != self.shape:
            h, w = rgb.shape[:2]
            raise InputError(
                f"the pattern is {w}x{h} pixels, screen {self.screen.index} is {self.shape[1]}x{self.shape[0]}: "
                "a projector pixel must be a pattern pixel (no scaling); give a pattern of the screen's size, or "
                "place it (--place ROW COLUMN)"
            )
        if not self.is_open:
            raise DeviceError(f"the projector window on screen {self.screen.index} is closed ({self.closed_reason})")
        self._shown += 1
        h, w = self.shape
        self._send(
            {"cmd": "show", "id": self._shown, "height": h, "width": w, "settle_frames": self.settle_frames},
            rgb.tobytes(),
        )
        msg = self._answer(f"pattern {self._shown} to be shown on screen {self.screen.index}")
        if msg.get("shown") != self._shown:
            raise DeviceError(f"the projector window answered {msg!r} for pattern {self._shown}")
        self.pattern = rgb

    def wait_closed(self, timeout_s: float | None = None) -> str:
        """Wait until the window is closed (Esc in it, or its process ended) and say why.

        ``timeout_s`` None waits as long as the window is open; a KeyboardInterrupt
        (Ctrl-C) closes the window and is raised again.
        """
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        try:
            while True:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    raise DeviceError(f"waited {timeout_s:g} s for the projector window to be closed")
                try:
                    self._answer("the window to be closed", timeout_s=0.5 if left is None else min(0.5, left))
                except DeviceError:
                    if self.closed_reason is not None or not self.is_open:
                        break
                    continue
        finally:
            self.close()
        return self.closed_reason or "closed"

    def close(self) -> None:
        """Close the window (its process ends; the X server removes it); safe to call twice."""
        proc = self._proc
        if proc is None:
            return
        try:
            if proc.poll() is None:
                try:
                    proc.stdin.write(b'{"cmd": "close"}\n')
                    proc.stdin.flush()
                except (BrokenPipeError, ValueError, OSError):
                    pass
                try:
                    proc.wait(timeout=5.0)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(timeout=5.0)
        finally:
            for f in (proc.stdin, proc.stdout, proc.stderr):
                try:
                    f.close()
                except OSError:
                    pass
            if self.closed_reason is None:
                self.closed_reason = "closed by the caller"
            self._proc = None

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):  # a window never outlives its owner
        try:
            self.close()
        except Exception:
            pass
