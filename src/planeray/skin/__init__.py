"""Seeing veins through skin (Sec. 10, Figs. 13, 14, 16): imaging methods, metrics, ambient light, Eq. 7.

* :mod:`~planeray.skin.metrics`   CNR, Weber contrast, per-vein detection on a vein mask (band in mm)
* :mod:`~planeray.skin.enhance`   contrast enhancement from a delay sweep (Eq. 7, Fig. 14)
* :mod:`~planeray.skin.ambient`   ambient light: lux and W/m^2 in band -> ``ambient_e_per_us``
* :mod:`~planeray.skin.imaging`   the methods compared: short-range indirect delay image, photo,
  direct, Nayar global, non-epipolar, flood reflectance; from a transport, a device or a stack

The skin scene itself (layered tissue, veins) is ``make_scene("skin", ...)`` in
:mod:`planeray.scenes`.
"""

from .ambient import AMBIENT_LEVELS, ambient_e_per_us, ambient_table, band_irradiance_w_m2
from .enhance import EnhanceResult, compose, enhance_contrast, paper_patch_px
from .metrics import (
    BAND_GAP_MM,
    BAND_WIDTH_MM,
    background_bands,
    band_definition,
    cnr,
    vein_ids_from_mask,
    vein_metrics,
    weber_contrast,
)

__all__ = [
    "AMBIENT_LEVELS",
    "ambient_e_per_us",
    "ambient_table",
    "band_irradiance_w_m2",
    "EnhanceResult",
    "compose",
    "enhance_contrast",
    "paper_patch_px",
    "BAND_GAP_MM",
    "BAND_WIDTH_MM",
    "band_definition",
    "background_bands",
    "cnr",
    "vein_ids_from_mask",
    "vein_metrics",
    "weber_contrast",
]
