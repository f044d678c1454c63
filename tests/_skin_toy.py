"""A synthetic vein scene for the skin tests (not skin physics: a fixture with known answers).

Every pixel has direct light on its own epipolar plane (albedo ``a``, no vein contrast) and an
exponential subsurface kernel over offsets; a vein at depth ``d`` removes a fraction ``c`` of
the light that travelled farther than ``2 d`` (mm) under the skin -- light that reached the
vein's depth -- so short delays do not see deep veins and the direct image sees no vein.
"""

from __future__ import annotations

import numpy as np

from planeray.scenes.base import Scene, scene_offsets
from planeray.timing import RowGeometry
from planeray.transport import Transport

MM_PER_ROW = 0.3


def toy_vein_scene(
    shape=(64, 64),
    *,
    projector_rows=360,
    depths_mm=(1.5, 3.0, 30.0),
    columns=(12, 32, 52),
    width_px=3,
    contrast=0.5,
    albedo=0.6,
    kernel_mm=6.0,
    indirect=0.4,
    ambient_contrast=0.0,
):
    H, W = shape
    g = RowGeometry(H, projector_rows)
    u = scene_offsets(96).astype(np.float64)
    dist_mm = np.abs(u) * MM_PER_ROW
    kernel = np.exp(-dist_mm / kernel_mm)
    kernel[u == 0] = 0.0
    kernel *= indirect / kernel.sum()
    ids = np.zeros(shape, np.int32)
    depth = np.full(shape, np.nan)
    diam = np.full(shape, np.nan)
    atten = np.zeros((H, W, u.size))
    for k, (d, c0) in enumerate(zip(depths_mm, columns), start=1):
        cols = slice(c0 - width_px // 2, c0 - width_px // 2 + width_px)
        ids[:, cols] = k
        depth[:, cols] = d
        diam[:, cols] = width_px * 0.3 * projector_rows / H
        atten[:, cols, :] = contrast / (1.0 + np.exp(-(dist_mm - 2.0 * d) / 0.5))
    dense = albedo * kernel[None, None, :] * (1.0 - atten)
    dense[:, :, u == 0] += albedo
    T = Transport(dense.astype(np.float32), u.astype(int), g)
    vein = ids > 0
    amb = np.full(shape, albedo, np.float32) * (1.0 - ambient_contrast * vein)
    return Scene(
        "toy_veins",
        T,
        np.full(shape, albedo, np.float32),
        amb,
        np.ones(shape, np.uint8),
        params={"mm_per_row": MM_PER_ROW, "wavelength_nm": 638.0},
        maps={
            "vein_mask": vein,
            "vein_id": ids,
            "vein_depth_mm": depth,
            "vein_diameter_mm": diam,
            "hair": np.zeros(shape, bool),
        },
    )
