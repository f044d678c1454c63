"""A real two-screen X server for the projector tests: Xvfb, started once per test process, never the user's display."""

from __future__ import annotations

import os
import select
import shutil
import subprocess
import time

import pytest

#: Both screens of the test server (the paper's projector: 1280x720).
SCREENS = ("1280x720x24", "1280x720x24")
START_TIMEOUT_S = 15.0


def start_xvfb():
    """Start ``Xvfb -displayfd`` on a free display with two screens; returns (process, ":N")."""
    exe = shutil.which("Xvfb")
    if exe is None:
        pytest.skip("Xvfb is not installed (Debian: apt-get install xvfb; `make test` installs it as root)")
    from planeray.projector import window_library_available

    if not window_library_available():
        pytest.skip("pyglet is not installed (pip install 'planeray[rig]')")
    read, write = os.pipe()
    args = [exe, "-displayfd", str(write), "-nolisten", "tcp", "-noreset"]
    for i, spec in enumerate(SCREENS):
        args += ["-screen", str(i), spec]
    proc = subprocess.Popen(args, pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    os.close(write)
    deadline = time.monotonic() + START_TIMEOUT_S
    number = b""
    try:
        while not number.endswith(b"\n"):
            left = deadline - time.monotonic()
            ready, _, _ = select.select([read], [], [], max(0.0, left))
            if not ready:
                raise RuntimeError(f"Xvfb did not say its display number within {START_TIMEOUT_S:g} s")
            chunk = os.read(read, 16)
            if not chunk:
                raise RuntimeError(
                    f"Xvfb ended before it started: {proc.stderr.read().decode(errors='replace')[-300:]}"
                )
            number += chunk
    except BaseException:
        proc.kill()
        proc.wait(timeout=5)
        raise
    finally:
        os.close(read)
    return proc, f":{int(number)}"


def stop_xvfb(proc) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=5)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=5)
    proc.stderr.close()


def display_for_tests():
    """A module fixture's body: Xvfb started, DISPLAY pointing at it while the tests run, then stopped."""
    proc, name = start_xvfb()
    old = os.environ.get("DISPLAY")
    os.environ["DISPLAY"] = name  # nothing may open on the developer's own display
    try:
        yield name
    finally:
        if old is None:
            os.environ.pop("DISPLAY", None)
        else:
            os.environ["DISPLAY"] = old
        stop_xvfb(proc)


def send_key(display: str, x_screen: int, keysym_name: str) -> None:
    """Press and release a key on ``display`` with the pointer on ``x_screen`` (XTest, as a user's keyboard)."""
    import ctypes
    import ctypes.util

    x11 = ctypes.CDLL(ctypes.util.find_library("X11"))
    xtst = ctypes.CDLL(ctypes.util.find_library("Xtst"))
    x11.XOpenDisplay.restype = ctypes.c_void_p
    x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
    for f in (x11.XFlush, x11.XCloseDisplay, x11.XSync):
        f.argtypes = [ctypes.c_void_p] + ([ctypes.c_int] if f is x11.XSync else [])
    x11.XStringToKeysym.restype = ctypes.c_ulong
    x11.XStringToKeysym.argtypes = [ctypes.c_char_p]
    x11.XKeysymToKeycode.argtypes = [ctypes.c_void_p, ctypes.c_ulong]
    xtst.XTestFakeMotionEvent.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_int, ctypes.c_ulong]
    xtst.XTestFakeKeyEvent.argtypes = [ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_ulong]
    dpy = x11.XOpenDisplay(display.encode())
    assert dpy, f"cannot open {display}"
    try:
        xtst.XTestFakeMotionEvent(dpy, x_screen, 640, 360, 0)  # the pointer onto the window: it gets the keys
        x11.XSync(dpy, 0)
        code = x11.XKeysymToKeycode(dpy, x11.XStringToKeysym(keysym_name.encode()))
        xtst.XTestFakeKeyEvent(dpy, code, 1, 0)
        xtst.XTestFakeKeyEvent(dpy, code, 0, 0)
        x11.XSync(dpy, 0)
    finally:
        x11.XCloseDisplay(dpy)
