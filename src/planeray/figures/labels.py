"""Effect label maps (delay-profile classification, Sec. 8)."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch

from ..scenes import EFFECTS
from ._common import finish, new_figure

__all__ = ["label_map_figure", "EFFECT_COLORS"]

#: One colour per effect label (none, diffuse, subsurface, diffuse/specular interreflection).
EFFECT_COLORS = ["#202020", "#9e9e9e", "#f2a541", "#3f88c5", "#d1495b"]


def label_map_figure(labels, *, out=None, reference=None, title: str = "Light-transport effect per pixel", ax=None):
    """Draw a label map (keys of :data:`planeray.scenes.EFFECTS`), beside an optional reference image.

    Parameters
    ----------
    labels : array_like of int, (H, W)
        Effect label per pixel, e.g. from :func:`planeray.classify.classify_transport`.
    out : str or os.PathLike, optional
        Also write the figure to this PNG (110 dpi).
    reference : array_like (H, W), optional
        An image shown to the left of the labels (brightened, gamma 0.5).
    title : str
        Title of the label panel.
    ax : matplotlib.axes.Axes, optional
        Draw the label map into this Axes (without ``reference``) instead of a new figure.

    Returns
    -------
    matplotlib.figure.Figure
        The new figure (one Axes, two with ``reference``), or ``ax.figure``.

    See Also
    --------
    planeray.classify_transport : labels to draw.

    Examples
    --------
    >>> import planeray as pr
    >>> from planeray.figures import label_map_figure
    >>> scene = pr.make_scene("diffuse_plane", (16, 16), seed=0)
    >>> fig = label_map_figure(scene.labels, reference=scene.direct)
    >>> type(fig).__name__, len(fig.axes)
    ('Figure', 2)
    >>> from matplotlib.figure import Figure
    >>> ax = Figure().subplots()
    >>> label_map_figure(scene.labels, ax=ax, title="ground truth") is ax.figure
    True
    """
    labels = np.asarray(labels)
    own = ax is None  # a caller's figure keeps its own layout
    if not own:
        if reference is not None:
            raise ValueError("label_map_figure: pass either ax (a single panel) or reference (two panels), not both")
        fig, axes = ax.figure, np.array([[ax]], dtype=object)
    else:
        n = 2 if reference is not None else 1
        fig = new_figure((5.2 * n + 1.5, 5))
        axes = fig.subplots(1, n, squeeze=False)
    if reference is not None:
        ref = np.asarray(reference, np.float32)
        top = np.percentile(ref, 99.5) or 1.0
        axes[0, 0].imshow(np.clip(ref / top, 0, 1) ** 0.5, cmap="gray", vmin=0, vmax=1)
        axes[0, 0].set_title("reference", fontsize=10)
    ax = axes[0, -1]
    ax.imshow(
        labels, cmap=ListedColormap(EFFECT_COLORS), vmin=-0.5, vmax=len(EFFECT_COLORS) - 0.5, interpolation="nearest"
    )
    ax.set_title(title, fontsize=10)
    counts = np.bincount(labels.ravel(), minlength=len(EFFECTS))
    handles = [
        Patch(color=EFFECT_COLORS[k], label=f"{EFFECTS[k].replace('_', ' ')} ({counts[k]})")
        for k in EFFECTS
        if counts[k]
    ]
    ax.legend(handles=handles, fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5))
    for a in axes.ravel():
        a.set_xticks([])
        a.set_yticks([])
    if own:
        fig.tight_layout()
    return finish(fig, out, dpi=110)
