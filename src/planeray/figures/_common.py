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
    """One brightening factor for many images (the paper: "all images equally brightened").

    Parameters
    ----------
    images : sequence of array_like
        The images (any shapes), in the same units.
    percentile : float
        The percentile of all their pixels that the factor maps to 1 (white).

    Returns
    -------
    float
        ``1 / p`` for that percentile ``p`` of the pooled pixels (1 when ``p <= 0``).

    See Also
    --------
    save_image : writes an image as a PNG brightened by such a factor.

    Examples
    --------
    >>> import numpy as np
    >>> float(display_scale([np.full((2, 2), 0.5), np.full((2, 2), 0.25)], percentile=100))
    2.0
    """
    import numpy as np

    vals = np.concatenate([np.asarray(im, np.float32).ravel() for im in images])
    top = np.percentile(vals, percentile)
    return 1.0 / top if top > 0 else 1.0


def new_figure(figsize, **kwargs) -> Figure:
    """A fresh :class:`~matplotlib.figure.Figure`, outside pyplot (nothing to close).

    Parameters
    ----------
    figsize : tuple of float
        Width and height, inches.
    **kwargs
        Passed to :class:`~matplotlib.figure.Figure` (``dpi``, ``layout``, ...).

    Returns
    -------
    matplotlib.figure.Figure

    See Also
    --------
    save_png : writes it atomically, with planeray's mark.

    Examples
    --------
    >>> fig = new_figure((4, 3))
    >>> ax = fig.subplots()
    >>> fig.get_size_inches().tolist()
    [4.0, 3.0]
    """
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

    Parameters
    ----------
    fig : matplotlib.figure.Figure or matplotlib.figure.SubFigure
        The figure.
    path : str or Path
        The PNG to write (replaced atomically).
    dpi : float
        Dots per inch.

    Returns
    -------
    Path
        ``path``.

    See Also
    --------
    new_figure : a figure outside pyplot.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> fig = new_figure((2, 2))
    >>> _ = fig.subplots().plot([0, 1], [1, 0])
    >>> save_png(fig, pathlib.Path(tempfile.mkdtemp()) / "line.png").name
    'line.png'
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

    Parameters
    ----------
    image : ndarray (H, W)
        The image (normalized units: 0..1 is the full range of a TIFF).
    path : str or Path
        ``.png``, ``.tif`` or ``.tiff``.
    scale_to : float, optional
        The PNG's brightening factor (:func:`display_scale`).

    Returns
    -------
    Path
        ``path``.

    See Also
    --------
    display_scale : one brightening factor for several images.
    planeray.io.write_image : the 16-bit TIFF writer.

    Examples
    --------
    >>> import numpy as np, tempfile, pathlib
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> save_image(np.linspace(0, 1, 16).reshape(4, 4), folder / "ramp.png").suffix
    '.png'
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
