"""A rendered scene at a glance: full, epipolar, non-epipolar images, effect labels and delay images."""

from __future__ import annotations

import numpy as np

from ..timing import PAPER_LINES_PER_SECOND, Band
from ..transport import Transport
from ._common import display_scale, finish, new_figure
from .labels import label_map_figure

__all__ = ["rendered_scene_figure"]


def rendered_scene_figure(
    transport: Transport,
    labels=None,
    *,
    delays_us=(-1500.0, -750.0, 375.0, 1500.0),
    exposure_us: float = 600.0,
    lines_per_second: float = PAPER_LINES_PER_SECOND,
    title: str | None = None,
    out=None,
):
    """Two rows of panels: what an Episcan sees in a (rendered) scene.

    Top: the full image (all rows lit), the epipolar and non-epipolar images
    (Eqs. 5, 6) and the ground-truth effect labels; bottom: band images at
    ``delays_us`` with ``exposure_us`` (Eq. 4), each brightened on its own (the
    factor is printed) so that weak indirect light shows.

    Parameters
    ----------
    transport : Transport
        E.g. ``planeray.render.render_transport(...).transport``.
    labels : ndarray (H, W), optional
        Effect labels (:data:`planeray.scenes.EFFECTS`); the panel is left out without them.
    delays_us : sequence of float
        Delays of the bottom row (four fit).
    exposure_us, lines_per_second : float
        Exposure of the band images and the projector's line velocity.
    title : str, optional
    out : str or os.PathLike, optional
        Also write the PNG.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> import planeray as pr
    >>> from planeray.figures.render import rendered_scene_figure
    >>> scene = pr.make_scene("corner", (16, 16), seed=0)
    >>> fig = rendered_scene_figure(scene.transport, scene.labels, title="corner")
    >>> len(fig.axes) >= 8
    True
    """
    delays_us = list(delays_us)
    ncols = max(4, len(delays_us))
    fig = new_figure((3.0 * ncols, 6.6))
    axes = fig.subplots(2, ncols, squeeze=False)
    full = transport.full_image()
    top = [("full image", full), ("epipolar (Eq. 5)", transport.epipolar_image())]
    top.append(("non-epipolar (Eq. 6)", transport.non_epipolar_image()))
    scale = display_scale([full])
    for ax, (name, img) in zip(axes[0], top, strict=False):
        ax.imshow(np.clip(img * scale, 0, 1) ** (1 / 2.2), cmap="gray", vmin=0, vmax=1)
        ax.set_title(name, fontsize=9)
    if labels is not None:
        label_map_figure(labels, ax=axes[0, 3], title="effect labels")
    for ax in axes[0, 3 if labels is None else 4 :]:
        ax.set_visible(False)
    for ax, d in zip(axes[1], delays_us, strict=False):
        img = transport.render(Band(float(d), float(exposure_us), float(lines_per_second)))
        s = display_scale([img])
        ax.imshow(np.clip(img * s, 0, 1) ** (1 / 2.2), cmap="gray", vmin=0, vmax=1)
        ax.set_title(f"t_d {d:+.0f} us, t_e {exposure_us:.0f} us (x{s / scale:.3g})", fontsize=9)
    for ax in axes[1, len(delays_us) :]:
        ax.set_visible(False)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return finish(fig, out)
