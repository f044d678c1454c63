"""The projector's output: patterns shown pixel for pixel in a full-screen window on a chosen screen.

The laser projector of an Episcan-style rig (Sec. 6 of Kubo et al.; O'Toole et
al. 2015) is a monitor on the computer's HDMI output: what the rig projects is
what a full-screen window on that screen shows.  :class:`ProjectorWindow` opens
a borderless full-screen window there (pyglet, vsync'd, in a process of its own)
and shows any pattern with its pixel ``(r, c)`` on the projector's pixel ``(r, c)``;
:mod:`~planeray.projector.patterns` makes the patterns of the rig (white for the
sweep, black, the comb of the line-velocity calibration, one row or a band,
a rectification card, any image); :func:`list_screens` and :func:`grab_screen`
find the screens and read one back from the X server.

Why pyglet: it is pure Python over the system's own X11/GLX libraries (no
binary wheel, nothing downloaded), picks an X screen and a RandR head
directly, swaps on vsync, and is actively maintained; see the docs page
"Build and run the rig".
"""

from .patterns import (
    PATTERN_NAMES,
    as_rgb8,
    black,
    comb,
    load_pattern,
    parse_pattern,
    place,
    rectification_card,
    rows,
    white,
)
from .screens import Screen, display_name, get_screen, grab_screen, list_screens, window_library_available
from .window import ProjectorWindow

__all__ = [
    "PATTERN_NAMES",
    "ProjectorWindow",
    "Screen",
    "as_rgb8",
    "black",
    "comb",
    "display_name",
    "get_screen",
    "grab_screen",
    "list_screens",
    "load_pattern",
    "parse_pattern",
    "place",
    "rectification_card",
    "rows",
    "white",
    "window_library_available",
]
