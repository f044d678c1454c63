"""Fig. 8: the delay x exposure contact sheet of a stack."""

from __future__ import annotations

import numpy as np
from matplotlib.collections import PatchCollection
from matplotlib.colors import to_rgb
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
        One Axes holding the grid as one image (the tiles with gaps between them, longest
        exposure on top, delays left to right), the frames drawn over it, delays and
        exposures as its tick labels.  One image instead of an Axes per tile: a paper sweep's
        85 tiles drew in ~0.3 s instead of ~1.7 s.

    See Also
    --------
    planeray.simulate_stack : a stack to draw.

    Examples
    --------
    >>> import planeray as pr
    >>> from planeray.figures import contact_sheet_figure
    >>> scene = pr.make_scene("diffuse_plane", (16, 16), seed=0)
    >>> stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
    >>> fig = contact_sheet_figure(stack, gamma=1.0)
    >>> type(fig).__name__, len(fig.axes)
    ('Figure', 1)
    >>> [len(t) for t in (fig.axes[0].get_xticks(), fig.axes[0].get_yticks())] == [
    ...     stack.delays().size,
    ...     stack.exposures().size,
    ... ]
    True
    >>> len(contact_sheet_figure(stack, max_delays=3).axes[0].get_xticks())
    3
    """
    delays, exposures = stack.delays(), stack.exposures()
    if max_delays and delays.size > max_delays:
        delays = delays[np.linspace(0, delays.size - 1, max_delays).round().astype(int)]
    index = {(d, e): stack.index_of(d, e) for d in delays for e in exposures}
    images = {k: stack.image(i) for k, i in index.items() if i is not None}
    scale = display_scale(list(images.values()))
    H, W = stack.shape
    gap = max(1, round(0.04 * max(H, W)))  # between tiles, in image pixels (4 % of a tile)
    rows, cols = exposures.size, delays.size
    fig = new_figure((tile_inches * cols + 1.0, tile_inches * (H / W) * rows + 1.0))
    ax = fig.subplots()
    mosaic = np.empty((rows * (H + gap) - gap, cols * (W + gap) - gap, 3), np.float32)
    mosaic[:] = to_rgb(fig.get_facecolor())
    frames = []
    for r, e in enumerate(exposures[::-1]):  # longest exposure on top, like the paper
        for c, d in enumerate(delays):
            y, x = r * (H + gap), c * (W + gap)
            i = index[(d, e)]
            if i is None:
                mosaic[y : y + H, x : x + W] = 0.85  # no image at this delay and exposure
                continue
            shown = np.clip(images[(d, e)] * scale, 0, 1) ** gamma
            mosaic[y : y + H, x : x + W] = shown[:, :, None]
            frames.append(Rectangle((x - 0.5, y - 0.5), W, H, fill=False, edgecolor="black", linewidth=0.8))
            if stack.excluded[i]:
                style = dict(edgecolor="0.6", linestyle="--", linewidth=1.5)
            elif abs(d) >= e / 2:
                style = dict(edgecolor="red", linestyle="-", linewidth=1.5)
            else:
                continue
            frames.append(Rectangle((x - 0.5, y - 0.5), W, H, fill=False, **style))
    ax.imshow(mosaic, interpolation="nearest")
    ax.add_collection(PatchCollection(frames, match_original=True))
    ax.set_xticks(np.arange(cols) * (W + gap) + (W - 1) / 2, [f"{d:g}" for d in delays], fontsize=7)
    ax.set_yticks(
        np.arange(rows) * (H + gap) + (H - 1) / 2,
        [f"{e:g}" for e in exposures[::-1]],
        fontsize=7,
        rotation=90,
        va="center",
    )
    ax.tick_params(length=0, pad=2)
    for spine in ax.spines.values():
        spine.set_visible(False)
    fig.supxlabel("delay $t_d$ (µs)   — red: non-epipolar, dashed: boundary (excluded)", fontsize=9)
    fig.supylabel("exposure $t_e$ (µs)", fontsize=9)
    source = stack.metadata.get("scene", {}).get("name") or stack.metadata.get("source", "stack")
    fig.suptitle(f"Delay–exposure stack of {source} (all images equally brightened, gamma {gamma:g})", fontsize=10)
    w_in, h_in = fig.get_size_inches()  # margins in inches: room for the labels at any size
    fig.subplots_adjust(left=0.6 / w_in, right=1 - 0.1 / w_in, bottom=0.55 / h_in, top=1 - 0.45 / h_in)
    return finish(fig, out, dpi=110)
