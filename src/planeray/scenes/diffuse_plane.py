"""A textured Lambertian plane facing the projector-camera: direct light only.

The reference for everything else: its transport is the albedo on the camera
row's own epipolar plane (offset 0) and nothing elsewhere, so its epipolar image
equals its albedo and every non-epipolar image is black.
"""

from __future__ import annotations

import numpy as np

from ..timing import RowGeometry
from ..transport import Transport
from ._textures import printed_page, smooth_noise
from .base import Scene, footprint_kernel, register_scene, scene_offsets


@register_scene("diffuse_plane", "textured Lambertian plane: direct light only (epipolar image = albedo)")
def build(shape, projector_rows, seed, band_rows: int = 16, shading: float = 1.0):
    """Build the scene.

    Parameters
    ----------
    band_rows : int
        Half-width of the dense offset band; nothing but offset 0 is non-zero.
    shading : float
        Irradiance factor ``cos(theta)`` of the plane (1: facing the projector).
    """
    rng = np.random.default_rng(seed)
    geometry = RowGeometry(shape[0], projector_rows)
    albedo = printed_page(shape, rng) * (1.0 + smooth_noise(shape, rng, shape[0] / 8, 0.05))
    albedo = np.clip(albedo * shading, 0.0, 1.0).astype(np.float32)
    offsets = scene_offsets(max(band_rows, int(np.ceil(geometry.rows_per_camera_row))))
    kernel = footprint_kernel(offsets, geometry.rows_per_camera_row).astype(np.float32)
    dense = albedo[:, :, None] * kernel[None, None, :]
    transport = Transport(dense, offsets, geometry)
    labels = np.ones(shape, np.uint8)
    return Scene(
        "diffuse_plane", transport, albedo, albedo.copy(), labels, {"band_rows": band_rows, "shading": shading}
    )
