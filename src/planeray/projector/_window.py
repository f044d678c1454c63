"""The projector window's own process: pyglet, one borderless full-screen window, driven over a pipe.

Run by :mod:`planeray.projector.window` (never imported by the calling process,
which so never loads OpenGL): ``python -m planeray.projector._window list
DISPLAY`` prints the X screens and their heads as JSON; ``... serve DISPLAY
X_SCREEN HEAD`` opens the window and answers commands on stdin, one JSON line
each, a pattern's ``H * W * 3`` bytes after its line:

* ``{"cmd": "show", "id": N, "height": H, "width": W, "settle_frames": F}`` +
  bytes: draws the pattern texel for pixel (nearest filtering, no blending, no
  colour conversion), swaps buffers on vsync ``1 + F`` times and answers
  ``{"shown": N, "frames": n}`` once the pattern is on the screen;
* ``{"cmd": "close"}``: closes the window and exits.

It exits too on Esc, on Ctrl-C, when stdin closes (the caller is gone) or on
any error, saying why on stdout as ``{"closed": REASON}`` (or ``{"error": ...}``);
when the process ends the X server destroys its window, so the screen shows
again what it showed before.
"""

from __future__ import annotations

import json
import os
import select
import signal
import sys


def _say(obj) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def _pyglet():
    import pyglet

    pyglet.options["shadow_window"] = False  # no hidden GL context on the default screen
    pyglet.options["vsync"] = True
    return pyglet


def _display(pyglet, name: str, x_screen: int):
    """The X display opened on screen ``x_screen`` (its default root is that screen's: RandR reads it)."""
    base = name.rsplit(".", 1)[0] if "." in name.rsplit(":", 1)[-1] else name
    return pyglet.display.xlib.XlibDisplay(name=f"{base}.{x_screen}", x_screen=x_screen)


def list_screens(name: str) -> list[dict]:
    """Every head of every X screen of display ``name``: what ``--list-screens`` shows."""
    pyglet = _pyglet()
    from pyglet.libs.x11 import xlib

    probe = xlib.XOpenDisplay(name.encode())
    if not probe:
        raise RuntimeError(f"cannot connect to the X display {name!r}")
    count = xlib.XScreenCount(probe)
    xlib.XCloseDisplay(probe)
    heads = []
    for s in range(count):
        display = _display(pyglet, name, s)
        for h, screen in enumerate(display.get_screens()):
            rate = None
            try:
                mode = screen.get_mode()
                rate = float(mode.rate) if mode is not None and mode.rate else None
            except Exception:  # a server without mode information (Xvfb's RandR may have none)
                rate = None
            heads.append(
                {
                    "x_screen": s,
                    "head": h,
                    "x": int(screen.x),
                    "y": int(screen.y),
                    "width": int(screen.width),
                    "height": int(screen.height),
                    "output": getattr(screen, "name", None),
                    "refresh_hz": rate,
                }
            )
    return heads


def _read_exact(fd: int, n: int) -> bytes:
    chunks, got = [], 0
    while got < n:
        chunk = os.read(fd, min(n - got, 1 << 20))
        if not chunk:
            raise EOFError
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks)


def _read_line(fd: int) -> bytes:
    out = bytearray()
    while True:
        c = os.read(fd, 1)
        if not c:
            raise EOFError
        if c == b"\n":
            return bytes(out)
        out += c


def serve(name: str, x_screen: int, head: int) -> str:
    pyglet = _pyglet()
    from pyglet import gl
    from pyglet.window import key

    display = _display(pyglet, name, x_screen)
    heads = display.get_screens()
    screen = heads[head]
    config = gl.Config(double_buffer=True, sample_buffers=0, samples=0)
    window = pyglet.window.Window(
        fullscreen=True,
        screen=screen,
        display=display,
        vsync=True,
        config=config,
        style=pyglet.window.Window.WINDOW_STYLE_BORDERLESS,
        caption="planeray projector",
    )
    window.set_mouse_visible(False)
    state = {"texture": None, "closed": None, "exposed": False}

    @window.event
    def on_expose():  # uncovered (a window above closed): the X server does not keep what was under it
        state["exposed"] = True

    @window.event
    def on_draw():
        state["exposed"] = True

    @window.event
    def on_key_press(symbol, modifiers):
        if symbol == key.ESCAPE or (symbol == key.C and modifiers & key.MOD_CTRL):
            state["closed"] = "escape"
        return pyglet.event.EVENT_HANDLED  # pyglet's default handler would close on Esc by itself

    @window.event
    def on_close():
        state["closed"] = "window closed"
        return pyglet.event.EVENT_HANDLED

    def draw():
        gl.glDisable(gl.GL_BLEND)
        gl.glDisable(gl.GL_DITHER)
        gl.glDisable(gl.GL_FRAMEBUFFER_SRGB)
        gl.glViewport(0, 0, window.width, window.height)
        gl.glClearColor(0.0, 0.0, 0.0, 1.0)
        window.clear()
        tex = state["texture"]
        if tex is not None:
            tex.blit(0, window.height - tex.height)  # pattern row 0 at the screen's top row

    def show(height: int, width: int, data: bytes, settle: int) -> int:
        image = pyglet.image.ImageData(width, height, "RGB", data, pitch=-3 * width)  # row 0 first: top down
        tex = image.get_texture()
        gl.glBindTexture(tex.target, tex.id)
        gl.glTexParameteri(tex.target, gl.GL_TEXTURE_MIN_FILTER, gl.GL_NEAREST)
        gl.glTexParameteri(tex.target, gl.GL_TEXTURE_MAG_FILTER, gl.GL_NEAREST)
        old, state["texture"] = state["texture"], tex
        if old is not None:
            old.delete()
        frames = 0
        for _ in range(1 + max(0, settle)):  # every back buffer holds the pattern, then `settle` vsyncs more
            draw()
            window.flip()
            frames += 1
        gl.glFinish()
        return frames

    window.dispatch_events()
    draw()
    window.flip()
    gl.glFinish()
    _say({"ready": True, "width": window.width, "height": window.height, "x": screen.x, "y": screen.y})
    fd = sys.stdin.fileno()
    try:
        while state["closed"] is None:
            window.dispatch_events()
            if state["closed"] is not None:
                break
            if state["exposed"]:
                state["exposed"] = False
                draw()
                window.flip()
            ready, _, _ = select.select([fd], [], [], 0.01)
            if not ready:
                continue
            msg = json.loads(_read_line(fd))
            if msg.get("cmd") == "close":
                state["closed"] = "closed by the caller"
            elif msg.get("cmd") == "show":
                h, w = int(msg["height"]), int(msg["width"])
                data = _read_exact(fd, h * w * 3)
                frames = show(h, w, data, int(msg.get("settle_frames", 1)))
                _say({"shown": msg["id"], "frames": frames})
            elif msg.get("cmd") == "redraw":
                draw()
                window.flip()
            else:
                raise ValueError(f"unknown command {msg!r}")
    except EOFError:
        state["closed"] = "the caller went away"
    except KeyboardInterrupt:
        state["closed"] = "interrupted"
    finally:
        window.close()
    return state["closed"]


def main(argv: list[str]) -> int:
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        if argv[0] == "list":
            _say({"screens": list_screens(argv[1])})
            return 0
        if argv[0] == "serve":
            reason = serve(argv[1], int(argv[2]), int(argv[3]))
            _say({"closed": reason})
            return 0
        raise ValueError(f"unknown mode {argv[0]!r}")
    except KeyboardInterrupt:
        _say({"closed": "interrupted"})
        return 0
    except Exception as exc:  # said to the caller in one line; it turns it into its own error
        _say({"error": f"{type(exc).__name__}: {exc}"})
        return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
