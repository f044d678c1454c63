"""The live explorer: ``planeray view PATH`` in the browser, ``planeray video PATH`` to a file.

* :mod:`~planeray.viewer.session` -- what a ``PATH`` is (scene, transport store, stack) and what it
  renders for a panel's settings, and the data of a pixel's plots (no web);
* :mod:`~planeray.viewer.display` -- values to colours (white level, gamma, colormap), shared by the
  page, its snapshots and the videos;
* :mod:`~planeray.viewer.server` -- the ASGI app (Starlette) and its uvicorn server: the page,
  frames over a WebSocket, an access token, loopback by default;
* :mod:`~planeray.viewer.video` -- a delay or exposure sweep written as a video (imageio-ffmpeg);
* ``static/`` -- the page (HTML, CSS, JavaScript; no library, no network).
"""

from .display import COLORMAPS, auto_white, to_rgb
from .session import MODES, PATTERNS, StackSource, TransportSource, ViewSettings, ViewSource, open_source

__all__ = [
    "COLORMAPS",
    "MODES",
    "PATTERNS",
    "StackSource",
    "TransportSource",
    "ViewSettings",
    "ViewSource",
    "auto_white",
    "open_source",
    "to_rgb",
]
