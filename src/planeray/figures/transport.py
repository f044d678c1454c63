"""Demultiplexed transport against ground truth, per pixel, over row offsets."""

from __future__ import annotations

import numpy as np

from ..transport import Transport
from ._common import plt, save_png

__all__ = ["transport_profiles_figure"]

_COLORS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown"]


def transport_profiles_figure(estimate: Transport, pixels, out_png, truth: Transport | None = None, truth_scale: float = 1.0,
                              names=None, title: str | None = None, resolution_rows: float | None = None):
    """Plot ``T(u)`` of a few pixels: the estimate (solid) and, if given, the truth (dashed).

    Parameters
    ----------
    estimate : Transport
    pixels : array_like (P, 2)
        ``(row, col)`` of each pixel.
    truth : Transport, optional
        Ground truth, multiplied by ``truth_scale`` (the camera's signal scale).
    resolution_rows : float, optional
        Shade the cell around the epipolar plane that the sweep cannot split.
    """
    pixels = np.atleast_2d(pixels)
    fig, axes = plt.subplots(len(pixels), 1, figsize=(9, 1.9 * len(pixels) + 0.6), sharex=True, squeeze=False)
    u = estimate.offsets_rows
    for p, (r, c) in enumerate(pixels):
        ax = axes[p, 0]
        color = _COLORS[p % len(_COLORS)]
        if resolution_rows:
            ax.axvspan(-resolution_rows, resolution_rows, color="0.9", lw=0)
        if truth is not None:
            keep = (truth.offsets_rows >= u[0]) & (truth.offsets_rows <= u[-1])
            ax.plot(truth.offsets_rows[keep], truth.dense[r, c, keep] * truth_scale, "--", color="0.3", lw=1, label="ground truth")
        ax.plot(u, estimate.dense[r, c], "-", color=color, lw=1.6, label="demultiplexed")
        label = names[p] if names else ""
        ax.set_ylabel(f"({r}, {c})\n{label}", fontsize=8)
        ax.grid(alpha=0.3)
        if p == 0:
            ax.legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("offset u = v - t (projector rows)")
    fig.suptitle(title or "Plane-to-ray transport T(u) per pixel", fontsize=10)
    fig.tight_layout()
    return save_png(fig, out_png, dpi=110)
