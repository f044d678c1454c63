"""Delay profiles: a pixel's intensity as a function of delay (Sec. 8, Fig. 9).

A delay profile tells what kind of light reaches a pixel: a narrow unimodal
peak at ``t_d = 0`` for direct diffuse reflection, a broadened one for
subsurface scattering, a steep one-sided one for diffuse interreflection and a
second, displaced peak for specular interreflection.  Profiles are normalized by
their area to cancel albedo (Sec. 8).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .stack import Stack

__all__ = ["DelayProfiles", "measured_delay_profiles", "area_normalize"]


@dataclass
class DelayProfiles:
    """Delay profiles of a few pixels at each exposure of a stack.

    Attributes
    ----------
    pixels : ndarray (P, 2) int
        ``(row, col)`` of each pixel.
    delay_us : ndarray (D,)
        Sorted delays.
    exposure_us : ndarray (E,)
        Sorted exposures.
    values : ndarray (P, E, D) float32
        Area-normalized intensities (NaN where the sweep has no image).
    raw : ndarray (P, E, D) float32
        Intensities before normalization.
    """

    pixels: np.ndarray
    delay_us: np.ndarray
    exposure_us: np.ndarray
    values: np.ndarray
    raw: np.ndarray


def area_normalize(values, delay_us):
    """Divide each profile (last axis) by its area over delay in milliseconds.

    Missing samples (NaN) are skipped; a profile with no positive area is left at 0.
    """
    values = np.asarray(values, dtype=np.float64)
    x = np.asarray(delay_us, dtype=np.float64) * 1e-3
    out = np.zeros_like(values)
    flat = values.reshape(-1, values.shape[-1])
    res = out.reshape(-1, values.shape[-1])
    for i, v in enumerate(flat):  # a handful of profiles, each vectorized
        ok = np.isfinite(v)
        area = np.trapezoid(np.clip(v[ok], 0, None), x[ok]) if ok.sum() > 1 else 0.0
        res[i] = np.where(ok, v / area, np.nan) if area > 0 else np.where(ok, 0.0, np.nan)
    return out.astype(np.float32)


def measured_delay_profiles(stack: Stack, pixels) -> DelayProfiles:
    """Read the delay profiles of ``pixels`` from a stack, one curve per exposure.

    Parameters
    ----------
    stack : Stack
    pixels : array_like (P, 2)
        ``(row, col)`` pixel coordinates.
    """
    px = np.atleast_2d(np.asarray(pixels, dtype=np.int64))
    if px.shape[1] != 2:
        raise InputError(f"pixels must be (row, col) pairs, got shape {px.shape}")
    H, W = stack.shape
    bad = (px[:, 0] < 0) | (px[:, 0] >= H) | (px[:, 1] < 0) | (px[:, 1] >= W)
    if bad.any():
        raise InputError(f"pixel {tuple(px[bad][0])} outside the {H}x{W} image")
    delays, exposures = stack.delays(), stack.exposures()
    raw = np.full((len(px), exposures.size, delays.size), np.nan, np.float32)
    di = np.searchsorted(delays, stack.delay_us)
    ei = np.searchsorted(exposures, stack.exposure_us)
    for n in range(len(stack)):  # one image at a time: works on lazy stacks
        raw[:, ei[n], di[n]] = stack.image(n)[px[:, 0], px[:, 1]]
    return DelayProfiles(px, delays, exposures, area_normalize(raw, delays), raw)
