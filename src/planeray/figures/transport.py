"""Demultiplexed transport against ground truth, per pixel, over row offsets."""

from __future__ import annotations

import numpy as np

from ..transport import Transport
from ._common import finish, new_figure

__all__ = ["transport_profiles_figure"]

_COLORS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown"]


def transport_profiles_figure(
    estimate: Transport,
    pixels,
    *,
    out=None,
    truth: Transport | None = None,
    truth_scale: float = 1.0,
    names=None,
    title: str | None = None,
    resolution_rows: float | None = None,
    ax=None,
):
    """Plot ``T(u)`` of a few pixels: the estimate (solid) and, if given, the truth (dashed).

    Parameters
    ----------
    estimate : Transport
        E.g. ``planeray.demultiplex(stack).transport``.
    pixels : array_like (P, 2)
        ``(row, col)`` of each pixel; one panel per pixel.
    out : str or os.PathLike, optional
        Also write the figure to this PNG (110 dpi).
    truth : Transport, optional
        Ground truth, multiplied by ``truth_scale`` (the camera's signal scale).
    truth_scale : float
        Factor applied to ``truth``.
    names : list of str, optional
        A label per pixel (beside its row and column).
    title : str, optional
        Figure title (the title of ``ax`` when drawing into one).
    resolution_rows : float, optional
        Shade the cell around the epipolar plane that the sweep cannot split.
    ax : matplotlib.axes.Axes, optional
        Draw into this Axes instead of a new figure (``pixels`` must then hold one pixel).

    Returns
    -------
    matplotlib.figure.Figure
        The new figure (one Axes per pixel, sharing the offset axis), or ``ax.figure``.

    See Also
    --------
    planeray.demultiplex : the estimate.

    Examples
    --------
    >>> import planeray as pr
    >>> from planeray.figures import transport_profiles_figure
    >>> scene = pr.make_scene("diffuse_plane", (16, 16), seed=0)
    >>> fig = transport_profiles_figure(scene.transport, [(4, 5), (10, 12), (8, 8)], resolution_rows=2.0)
    >>> type(fig).__name__, len(fig.axes)
    ('Figure', 3)
    >>> from matplotlib.figure import Figure
    >>> ax = Figure().subplots()
    >>> transport_profiles_figure(scene.transport, [(8, 8)], truth=scene.transport, ax=ax) is ax.figure
    True
    """
    pixels = np.atleast_2d(pixels)
    own = ax is None  # a caller's figure keeps its own layout and title
    if own:
        fig = new_figure((9, 1.9 * len(pixels) + 0.6))
        axes = fig.subplots(len(pixels), 1, sharex=True, squeeze=False)
    else:
        if len(pixels) != 1:
            raise ValueError(f"transport_profiles_figure: ax holds one pixel's panel, got {len(pixels)} pixels")
        fig, axes = ax.figure, np.array([[ax]], dtype=object)
    u = estimate.offsets_rows
    for p, (r, c) in enumerate(pixels):
        ax = axes[p, 0]
        color = _COLORS[p % len(_COLORS)]
        if resolution_rows:
            ax.axvspan(-resolution_rows, resolution_rows, color="0.9", lw=0)
        if truth is not None:
            keep = (truth.offsets_rows >= u[0]) & (truth.offsets_rows <= u[-1])
            ax.plot(
                truth.offsets_rows[keep],
                truth.dense[r, c, keep] * truth_scale,
                "--",
                color="0.3",
                lw=1,
                label="ground truth",
            )
        ax.plot(u, estimate.dense[r, c], "-", color=color, lw=1.6, label="demultiplexed")
        label = names[p] if names else ""
        ax.set_ylabel(f"({r}, {c})\n{label}", fontsize=8)
        ax.grid(alpha=0.3)
        if p == 0:
            ax.legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("offset u = v - t (projector rows)")
    if own:
        fig.suptitle(title or "Plane-to-ray transport T(u) per pixel", fontsize=10)
        fig.tight_layout()
    elif title:
        ax.set_title(title, fontsize=10)
    return finish(fig, out, dpi=110)
