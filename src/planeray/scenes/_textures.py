"""Deterministic albedo textures shared by the built-in scenes."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter

__all__ = ["smooth_noise", "printed_page", "image_grid", "floor_tiles", "wood_grain", "wallpaper"]


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


def floor_tiles(
    shape, rng: np.random.Generator, tiles=6, mean=0.6, spread=0.12, grout=0.25, grout_frac=0.08
) -> np.ndarray:
    """Square tiles of random albedo ``mean +- spread`` separated by dark grout lines.

    ``tiles`` is the number of tiles across the image width; tiles are square in
    pixels.  Sharp tile edges make interreflection blur easy to see.
    """
    H, W = shape
    size = max(2.0, W / float(tiles))
    y = (np.arange(H) + 0.5) / size
    x = (np.arange(W) + 0.5) / size
    iy, ix = np.floor(y).astype(int), np.floor(x).astype(int)
    values = mean + spread * rng.uniform(-1.0, 1.0, (iy.max() + 1, ix.max() + 1))
    albedo = values[iy[:, None], ix[None, :]]
    fy, fx = y - iy, x - ix
    line = (np.minimum(fy, 1 - fy)[:, None] < 0.5 * grout_frac) | (np.minimum(fx, 1 - fx)[None, :] < 0.5 * grout_frac)
    return np.where(line, grout, albedo)


def wood_grain(shape, rng: np.random.Generator, mean=0.2, amplitude=0.05, rings=9.0) -> np.ndarray:
    """Dark table-top "wood": wavy horizontal grain lines of albedo ``mean +- amplitude``."""
    H, W = shape
    y, x = image_grid(shape)
    warp = smooth_noise(shape, rng, max(H, W) / 6.0, 0.35)
    phase = rings * (y + 0.15 * np.sin(2 * np.pi * (x + rng.uniform())) + 0.1 * warp)
    grain = 0.5 + 0.5 * np.cos(2 * np.pi * phase)
    fine = smooth_noise(shape, rng, 1.0, 0.15)
    return mean + amplitude * (2.0 * grain - 1.0 + fine)


def wallpaper(shape, rng: np.random.Generator, mean=0.65, amplitude=0.12, stripes=10.0) -> np.ndarray:
    """Painted wall with vertical stripes and a soft mottle, albedo ``mean +- amplitude``."""
    y, x = image_grid(shape)
    stripe = np.where(np.floor(x * stripes + rng.uniform()) % 2 == 0, 1.0, -1.0)
    mottle = smooth_noise(shape, rng, max(shape) / 10.0, 0.5)
    return mean + amplitude * (0.6 * stripe + 0.4 * np.clip(mottle, -1.0, 1.0))
