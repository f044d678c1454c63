"""Deterministic albedo textures shared by the built-in scenes."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter

__all__ = ["smooth_noise", "printed_page", "image_grid"]


def image_grid(shape):
    """Pixel-centre coordinates ``(y, x)`` in [0, 1) (row, column), arrays of ``shape``."""
    H, W = shape
    y = (np.arange(H) + 0.5) / H
    x = (np.arange(W) + 0.5) / W
    return np.meshgrid(y, x, indexing="ij")


def smooth_noise(shape, rng: np.random.Generator, scale_px: float, amplitude: float = 1.0) -> np.ndarray:
    """Zero-mean Gaussian-filtered white noise with unit standard deviation times ``amplitude``."""
    n = gaussian_filter(rng.standard_normal(shape), scale_px, mode="wrap")
    return amplitude * (n - n.mean()) / (n.std() + 1e-12)


def printed_page(shape, rng: np.random.Generator, paper=0.85, ink=0.08, line_px=None) -> np.ndarray:
    """A page of "text": rows of random dark word blocks on bright paper.

    Sharp horizontal and vertical edges make the texture a good target for
    judging sharpness (epipolar vs. glowing images).
    """
    H, W = shape
    line_px = line_px or max(3, H // 24)
    albedo = np.full(shape, paper, dtype=np.float64)
    glyph_h = max(1, int(round(0.55 * line_px)))
    for top in range(line_px, H - line_px, line_px):
        x = int(W * 0.08)
        while x < W * 0.92:
            word = int(rng.integers(max(2, W // 40), max(3, W // 12)))
            albedo[top : top + glyph_h, x : min(x + word, int(W * 0.92))] = ink
            x += word + max(2, W // 60)
    return albedo
