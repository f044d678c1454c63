"""Fig. 8: the delay x exposure contact sheet of a stack."""

from __future__ import annotations

import numpy as np
from matplotlib.patches import Rectangle

from ..stack import Stack
from ._common import display_scale, finish, new_figure

__all__ = ["contact_sheet_figure"]


def contact_sheet_figure(
    stack: Stack, *, out=None, gamma: float = 0.5, tile_inches: float = 0.9, max_delays: int | None = None
):
    """Draw the grid of images over delay (x) and exposure (y), like Fig. 8.

    All tiles share one brightening factor (and a display gamma) so that their
    intensities compare.  Non-epipolar images (``|t_d| >= t_e/2``) get a red frame
    as in the paper; images excluded from demultiplexing (boundary images) a
    dashed grey one.

    Parameters
    ----------
    stack : Stack
        The delay x exposure stack.
    out : str or os.PathLike, optional
        Also write the figure to this PNG (110 dpi).
    gamma : float
        Display gamma applied after the common scaling (1 = linear).
    tile_inches : float
        Width of one tile (inches).
    max_delays : int, optional
        Subsample the delays to at most this many columns.

    Returns
    -------
    matplotlib.figure.Figure
        One Axes per (exposure, delay) tile, longest exposure on top.

    Examples
    --------
    >>> import planeray as pr
    >>> from planeray.figures import contact_sheet_figure
    >>> scene = pr.make_scene("diffuse_plane", (16, 16), seed=0)
    >>> stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
    >>> fig = contact_sheet_figure(stack, gamma=1.0)
    >>> type(fig).__name__, len(fig.axes) == stack.exposures().size * stack.delays().size
    ('Figure', True)
    >>> len(contact_sheet_figure(stack, max_delays=3).axes) == stack.exposures().size * 3
    True
    """
    delays, exposures = stack.delays(), stack.exposures()
    if max_delays and delays.size > max_delays:
        delays = delays[np.linspace(0, delays.size - 1, max_delays).round().astype(int)]
    index = {(d, e): stack.index_of(d, e) for d in delays for e in exposures}
    images = {k: stack.image(i) for k, i in index.items() if i is not None}
    scale = display_scale(list(images.values()))
    H, W = stack.shape
    aspect = H / W
    fig = new_figure((tile_inches * delays.size + 1.0, tile_inches * aspect * exposures.size + 1.0))
    axes = fig.subplots(exposures.size, delays.size, squeeze=False)
    for r, e in enumerate(exposures[::-1]):  # longest exposure on top, like the paper
        for c, d in enumerate(delays):
            ax = axes[r, c]
            ax.set_xticks([])
            ax.set_yticks([])
            i = index[(d, e)]
            if i is None:
                ax.set_facecolor("0.85")
            else:
                shown = np.clip(images[(d, e)] * scale, 0, 1) ** gamma
                ax.imshow(shown, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
                if stack.excluded[i]:
                    style = dict(edgecolor="0.6", linestyle="--", linewidth=1.5)
                elif abs(d) >= e / 2:
                    style = dict(edgecolor="red", linestyle="-", linewidth=2.0)
                else:
                    style = None
                if style:
                    ax.add_patch(Rectangle((-0.5, -0.5), W, H, fill=False, **style))
            if r == exposures.size - 1:
                ax.set_xlabel(f"{d:g}", fontsize=7)
            if c == 0:
                ax.set_ylabel(f"{e:g}", fontsize=7)
    fig.supxlabel("delay $t_d$ (µs)   — red: non-epipolar, dashed: boundary (excluded)", fontsize=9)
    fig.supylabel("exposure $t_e$ (µs)", fontsize=9)
    source = stack.metadata.get("scene", {}).get("name") or stack.metadata.get("source", "stack")
    fig.suptitle(f"Delay–exposure stack of {source} (all images equally brightened, gamma {gamma:g})", fontsize=10)
    fig.subplots_adjust(left=0.05, right=0.99, bottom=0.09, top=0.92, wspace=0.04, hspace=0.04)
    return finish(fig, out, dpi=110)
