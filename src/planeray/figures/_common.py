"""Shared plotting helpers: figures without pyplot, atomic PNG saving, a common brightening.

Figures are plain :class:`matplotlib.figure.Figure` objects, not pyplot-managed
ones: building and saving them needs no backend (``savefig`` renders with Agg by
itself), importing :mod:`planeray.figures` leaves the session's backend alone, and
no figure stays registered with pyplot after a call.  A returned ``Figure``
displays in Jupyter by itself.
"""

from __future__ import annotations

from pathlib import Path

from matplotlib.figure import Figure

from ..io import atomic_file

__all__ = ["new_figure", "figure_for", "finish", "save_png", "display_scale", "save_image"]


def display_scale(images, percentile=99.5):
    """One brightening factor for many images (the paper: "all images equally brightened")."""
    import numpy as np

    vals = np.concatenate([np.asarray(im, np.float32).ravel() for im in images])
    top = np.percentile(vals, percentile)
    return 1.0 / top if top > 0 else 1.0


def new_figure(figsize, **kwargs) -> Figure:
    """A fresh :class:`~matplotlib.figure.Figure`, outside pyplot (nothing to close)."""
    return Figure(figsize=figsize, **kwargs)


def figure_for(ax, figsize):
    """``(fig, ax, own)``: a new single-panel figure, or the figure that holds ``ax``.

    ``own`` tells whether the figure is ours (then its layout may be adjusted) or
    the caller's (then it is left as it is).
    """
    if ax is None:
        fig = new_figure(figsize)
        return fig, fig.subplots(), True
    return ax.figure, ax, False


def finish(fig, out=None, dpi=100):
    """Write ``fig`` to ``out`` (PNG) if given, and return ``fig``."""
    if out is not None:
        save_png(fig, out, dpi=dpi)
    return fig


def save_png(fig, path, dpi=100) -> Path:
    """Save a figure as PNG atomically and return the path.

    ``fig`` may be a :class:`~matplotlib.figure.SubFigure`; its whole figure is saved.
    The figure is not closed: figures built with :func:`new_figure` are not held by
    pyplot and go away with their last reference.
    """
    from ..io.marks import mark_text

    path = Path(path)
    root = fig.figure  # the Figure itself, or the Figure that holds a SubFigure
    with atomic_file(path) as tmp:
        # the mark (PNG Software text) lets a later --overwrite recognize the file as planeray's
        root.savefig(tmp, format="png", dpi=dpi, metadata={"Software": mark_text("figure")})
    return path


def save_image(image, path, scale_to: float | None = None) -> Path:
    """An image as a file: PNG, a display-scaled 8-bit preview; TIFF, the values as 16-bit codes (0..1 -> 0..65535).

    ``scale_to``: the PNG's brightening (default: its 99.5th percentile to white; give one value to
    several images so they compare).  Written atomically, with planeray's mark.
    """
    import numpy as np

    from ..errors import InputError, parameter_name
    from ..io import write_image

    path = Path(path)
    if path.suffix.lower() == ".png":
        from PIL import Image

        from ..io.marks import png_mark_info

        shown = np.clip(image * (scale_to or display_scale([image], percentile=99.5)), 0, 1)
        with atomic_file(path) as tmp:
            Image.fromarray((shown * 255 + 0.5).astype(np.uint8)).save(
                tmp, format="PNG", pnginfo=png_mark_info("image")
            )
        return path
    if path.suffix.lower() in (".tif", ".tiff"):
        return write_image(path, image, bit_depth=16)
    raise InputError(f"{parameter_name('out_path')} must end in .png, .tif or .tiff, got {path.name}")
