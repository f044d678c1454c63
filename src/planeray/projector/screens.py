"""The X screens a projector can be plugged into: list them, and read one back pixel for pixel.

A screen here is one head of one X screen of an X display: on a desktop with
the projector as a second monitor, the heads of X screen 0 (RandR outputs);
on a server with separate X screens (``Xvfb :N -screen 0 ... -screen 1 ...``),
each X screen.  They are numbered in that order, X screen by X screen, and that
number is ``--screen N``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import asdict, dataclass

import numpy as np

from ..errors import DeviceError, InputError

__all__ = ["Screen", "display_name", "list_screens", "get_screen", "grab_screen", "window_library_available"]

#: How long listing the screens may take (a child process connects to the X server).
LIST_TIMEOUT_S = 20.0


def window_library_available() -> bool:
    """Whether pyglet, the windowing library of the projector window, is installed.

    Returns
    -------
    bool

    See Also
    --------
    list_screens : needs it.

    Examples
    --------
    >>> isinstance(window_library_available(), bool)
    True
    """
    from importlib.util import find_spec

    return find_spec("pyglet") is not None


def _need_pyglet() -> None:
    if not window_library_available():
        raise InputError(
            "the projector window needs pyglet: pip install 'planeray[rig]' (or pip install 'pyglet>=2.1,<2.2')"
        )


@dataclass(frozen=True)
class Screen:
    """One screen a projector can show: a head of an X screen.

    Attributes
    ----------
    index : int
        Its number, ``--screen N``.
    display : str
        The X display (``":0"``), without a screen number.
    x_screen : int
        The X screen (``":0.1"`` is X screen 1).
    head : int
        The head (RandR output or Xinerama screen) within the X screen.
    x, y, width, height : int
        Its place and size on the X screen, pixels.
    output : str or None
        The RandR output's name (``HDMI-1``), when the server names it.
    refresh_hz : float or None
        Its refresh rate, when the server knows it.

    See Also
    --------
    list_screens : the screens of a display.

    Examples
    --------
    >>> s = Screen(index=1, display=":0", x_screen=0, head=1, x=1920, y=0, width=1280, height=720)
    >>> s.width, s.height
    (1280, 720)
    """

    index: int
    display: str
    x_screen: int
    head: int
    x: int
    y: int
    width: int
    height: int
    output: str | None = None
    refresh_hz: float | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, columns)`` of the screen: the shape a pattern must have."""
        return (self.height, self.width)

    @property
    def x_display(self) -> str:
        """The X display name with its screen (``":0.1"``)."""
        return f"{self.display}.{self.x_screen}"

    def describe(self) -> str:
        """One line for ``--list-screens``."""
        rate = f", {self.refresh_hz:.2f} Hz" if self.refresh_hz else ""
        name = f" {self.output}" if self.output else ""
        return (
            f"screen {self.index}: {self.width}x{self.height} at ({self.x}, {self.y}) of X screen "
            f"{self.x_display}{name}{rate}"
        )

    def to_dict(self) -> dict:
        return asdict(self)


def display_name(display: str | None = None) -> str:
    """The X display to use, without its screen number: ``display``, else ``$DISPLAY``.

    Parameters
    ----------
    display : str, optional
        ``:N`` or ``:N.S`` (default ``$DISPLAY``).

    Returns
    -------
    str

    Raises
    ------
    InputError
        Neither is set.

    See Also
    --------
    list_screens : its screens.

    Examples
    --------
    >>> display_name(":1")
    ':1'
    """
    name = display if display is not None else os.environ.get("DISPLAY")
    if not name:
        raise InputError("no X display: set DISPLAY (e.g. DISPLAY=:0) or give --display")
    host, sep, rest = name.rpartition(":")
    if not sep or not rest.split(".")[0].isdigit():
        raise InputError(f"not an X display name: {name!r} (expected e.g. :0 or host:0)")
    return f"{host}:{rest.split('.')[0]}"


def _child(args: list[str], timeout_s: float) -> dict:
    """Run the window module in its own process for a one-shot answer (a JSON line)."""
    cmd = [sys.executable, "-m", "planeray.projector._window", *args]
    env = _child_env()
    try:
        done = subprocess.run(cmd, capture_output=True, timeout=timeout_s, env=env, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        raise DeviceError(f"the X server did not answer within {timeout_s:g} s while listing its screens") from None
    for line in reversed(done.stdout.decode(errors="replace").splitlines()):
        try:
            return json.loads(line)
        except json.JSONDecodeError:
            continue
    raise DeviceError(f"listing the X screens failed: {done.stderr.decode(errors='replace').strip()[-300:]}")


def _child_env() -> dict:
    """The child's environment: this process's, with planeray's sources first on the path."""
    env = dict(os.environ)
    src = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # the folder of planeray/
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


_CACHE: dict[str, list[Screen]] = {}


def list_screens(display: str | None = None, *, refresh: bool = False) -> list[Screen]:
    """The screens of an X display, numbered as ``--screen`` takes them.

    Parameters
    ----------
    display : str, optional
        X display (default ``$DISPLAY``).
    refresh : bool
        Ask the X server again (the list is kept per display for the process).

    Returns
    -------
    list of Screen

    Raises
    ------
    InputError
        No display, no pyglet, or the display cannot be reached.

    See Also
    --------
    get_screen : one by number.

    Examples
    --------
    The screens of the X display (needs a display: the projector is one of them)

    >>> [(s.index, s.width, s.height) for s in list_screens()]  # doctest: +SKIP
    [(0, 1920, 1080), (1, 1280, 720)]
    """
    name = display_name(display)
    if name in _CACHE and not refresh:
        return list(_CACHE[name])
    _need_pyglet()
    answer = _child(["list", name], LIST_TIMEOUT_S)
    if "error" in answer:
        raise InputError(f"cannot list the screens of X display {name}: {answer['error']}")
    screens = [Screen(index=i, display=name, **s) for i, s in enumerate(answer["screens"])]
    _CACHE[name] = screens
    return list(screens)


def get_screen(index: int, display: str | None = None) -> Screen:
    """Screen ``index`` of the display, or a one-line refusal naming the screens there are.

    Parameters
    ----------
    index : int
        The screen's number (as ``--screen`` takes it).
    display : str, optional
        The X display.

    Returns
    -------
    Screen

    See Also
    --------
    list_screens : every screen.

    Examples
    --------
    >>> get_screen(1).height  # doctest: +SKIP
    720
    """
    screens = list_screens(display)
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or not 0 <= index < len(screens):
        have = ", ".join(f"{s.index} ({s.width}x{s.height})" for s in screens)
        raise InputError(f"no screen {index!r} on X display {display_name(display)}; it has screen {have}")
    return screens[int(index)]


def grab_screen(screen: Screen) -> np.ndarray:
    """What the screen shows now, read back from the X server: ``(height, width, 3)`` uint8 RGB.

    A screenshot of the screen itself (the X server's root window of its X
    screen, cut to the head), not of any window's buffer: what the projector's
    input receives.

    Parameters
    ----------
    screen : Screen
        The screen.

    Returns
    -------
    ndarray (height, width, 3) uint8

    Raises
    ------
    DeviceError
        The X server cannot be read.

    See Also
    --------
    get_screen : a screen by number.

    Examples
    --------
    >>> grab_screen(get_screen(1)).shape  # doctest: +SKIP
    (720, 1280, 3)
    """
    from PIL import ImageGrab

    box = (screen.x, screen.y, screen.x + screen.width, screen.y + screen.height)
    try:
        image = ImageGrab.grab(bbox=box, xdisplay=screen.x_display)
    except OSError as exc:
        raise DeviceError(f"cannot read screen {screen.index} ({screen.x_display}) back: {exc}") from None
    return np.asarray(image.convert("RGB"))
