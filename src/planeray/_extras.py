"""The optional dependencies (pip extras) and the one-line message when one is missing.

The core (simulate, demultiplex, view, materials, the figures) needs none of them; each extra serves a
few commands:

========  ==========================  ==========================================================
extra     package                     what needs it
========  ==========================  ==========================================================
``cv``    opencv-python-headless      ``planeray skin`` (Eq. 7's bilateral filter, the vein
                                      viewer's CLAHE), ``planeray skin pulse`` (decoding videos,
                                      the pyramids of Eulerian magnification), ``planeray paper``
                                      (Figs. 13-16)
``video`` imageio-ffmpeg (ffmpeg)     writing videos: ``planeray video``, ``planeray skin video``,
                                      ``skin pulse --magnified x.mp4`` (TIFF stacks need nothing)
========  ==========================  ==========================================================
"""

from __future__ import annotations

import importlib

from .errors import PlanerayError

__all__ = ["EXTRAS", "MissingExtraError", "import_extra"]

#: module -> (pip extra, distribution) of each optional dependency.
EXTRAS = {
    "cv2": ("cv", "opencv-python-headless"),
    "imageio_ffmpeg": ("video", "imageio-ffmpeg"),
}


class MissingExtraError(PlanerayError, ImportError):
    """An optional dependency is not installed; the message names the pip extra that brings it."""


def import_extra(module: str, what: str):
    """Import optional ``module`` (a key of :data:`EXTRAS`), or raise one line naming the extra to install.

    Parameters
    ----------
    module : str
        ``"cv2"`` or ``"imageio_ffmpeg"``.
    what : str
        What needs it, in words (``"planeray video"``): the start of the message.

    Returns
    -------
    module

    Raises
    ------
    MissingExtraError
        ``module`` cannot be imported.

    Examples
    --------
    >>> import_extra("cv2", "the bilateral filter").__name__
    'cv2'
    """
    extra, dist = EXTRAS[module]
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise MissingExtraError(
            f"{what} needs {dist}, an optional dependency: pip install 'planeray[{extra}]'"
        ) from exc
