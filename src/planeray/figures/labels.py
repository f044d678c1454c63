"""Effect label maps (delay-profile classification, Sec. 8)."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch

from ..scenes import EFFECTS
from ._common import plt, save_png

__all__ = ["label_map_figure", "EFFECT_COLORS"]

#: One colour per effect label (none, diffuse, subsurface, diffuse/specular interreflection).
EFFECT_COLORS = ["#202020", "#9e9e9e", "#f2a541", "#3f88c5", "#d1495b"]


def label_map_figure(labels, out_png, reference=None, title: str = "Light-transport effect per pixel"):
    """Write a label map (keys of :data:`planeray.scenes.EFFECTS`), beside an optional reference image."""
    labels = np.asarray(labels)
    n = 2 if reference is not None else 1
    fig, axes = plt.subplots(1, n, figsize=(5.2 * n + 1.5, 5), squeeze=False)
    if reference is not None:
        ref = np.asarray(reference, np.float32)
        top = np.percentile(ref, 99.5) or 1.0
        axes[0, 0].imshow(np.clip(ref / top, 0, 1) ** 0.5, cmap="gray", vmin=0, vmax=1)
        axes[0, 0].set_title("reference", fontsize=10)
    ax = axes[0, -1]
    ax.imshow(labels, cmap=ListedColormap(EFFECT_COLORS), vmin=-0.5, vmax=len(EFFECT_COLORS) - 0.5, interpolation="nearest")
    ax.set_title(title, fontsize=10)
    counts = np.bincount(labels.ravel(), minlength=len(EFFECTS))
    handles = [Patch(color=EFFECT_COLORS[k], label=f"{EFFECTS[k].replace('_', ' ')} ({counts[k]})") for k in EFFECTS if counts[k]]
    ax.legend(handles=handles, fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5))
    for a in axes.ravel():
        a.set_xticks([])
        a.set_yticks([])
    fig.tight_layout()
    return save_png(fig, out_png, dpi=110)
