"""Shared plotting helpers: a headless backend and atomic PNG saving."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from ..io import atomic_file  # noqa: E402

__all__ = ["plt", "save_png", "display_scale"]


def display_scale(images, percentile=99.5):
    """One brightening factor for many images (the paper: "all images equally brightened")."""
    import numpy as np

    vals = np.concatenate([np.asarray(im, np.float32).ravel() for im in images])
    top = np.percentile(vals, percentile)
    return 1.0 / top if top > 0 else 1.0


def save_png(fig, path, dpi=100) -> Path:
    """Save a figure as PNG atomically and close it."""
    path = Path(path)
    with atomic_file(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    plt.close(fig)
    return path
