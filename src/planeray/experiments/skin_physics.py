"""Is the skin scene's fast vein model right?  Brute-force Monte Carlo and adding-doubling checks.

* :func:`vein_validation`: the fast model (background kernel times the perturbation
  table of :func:`planeray.mc.layered.mc_vein_table`) against brute-force Monte Carlo
  with the blood cylinder actually in the medium
  (:func:`planeray.mc.layered.mc_vein_kernel_brute`), vein parallel (0 deg), oblique
  (45 deg) and across (90 deg) the projector rows, over depths and diameters: the vein's
  contrast in the short-range indirect band of the paper (delay 500 us, exposure 200 us:
  offsets 21.6-32.4 rows) and in the epipolar band (``|u| <= 2`` rows).
* :func:`layered_adding_doubling`: the total diffuse reflectance of the vein-free layers
  against adding-doubling (``iadpython``: each layer's reflection/transmission operators
  by doubling, the stack by adding).
* :func:`run_skin_validation`: both, written as ``skin_validation.json`` and the figure
  ``skin_validation.png`` (``planeray skin validate``).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from ..figures.skin_physics import vein_validation_figure
from ..io import jsonable
from ..mc.layered import mc_layered_profile, mc_vein_kernel_brute
from ..optical_data_skin import skin_layers
from ..scenes.skin import _table_slice, _vein_ratio, skin_tables
from ..timing import PAPER_LINES_PER_SECOND, band_bin_weights, band_centre_rows, band_width_rows

__all__ = [
    "VALIDATION_CASES",
    "DARK_CASES",
    "SHORT_RANGE_DELAY_US",
    "SHORT_RANGE_EXPOSURE_US",
    "short_range_weights",
    "vein_validation",
    "layered_adding_doubling",
    "adding_doubling_stack",
    "run_skin_validation",
    "VALIDATION_FORMAT",
]

#: The paper's short-range indirect setting for veins (Sec. 10: delays 400-600 us).
SHORT_RANGE_DELAY_US = 500.0
SHORT_RANGE_EXPOSURE_US = 200.0
#: (angle to the rows in deg, depth of the vein's top mm, diameter mm, pixel's distance from the axis in rows)
VALIDATION_CASES = (
    (0.0, 1.0, 2.0, 0.0),
    (0.0, 2.0, 2.0, 0.0),
    (0.0, 3.0, 2.0, 0.0),
    (0.0, 2.0, 4.0, 0.0),
    (0.0, 2.0, 2.0, -8.0),
    (90.0, 1.0, 2.0, 0.0),
    (90.0, 2.0, 2.0, 0.0),
    (90.0, 3.0, 2.0, 0.0),
    (90.0, 2.0, 4.0, 0.0),
    (45.0, 2.0, 2.0, 0.0),
)


#: Cases checked on dark skin (melanosome fraction 0.3, its own table).
DARK_CASES = ((0.0, 2.0, 2.0, 0.0), (90.0, 2.0, 2.0, 0.0))


def short_range_weights(offsets_rows, *, delay_us=SHORT_RANGE_DELAY_US, exposure_us=SHORT_RANGE_EXPOSURE_US):
    """Illumination weights of the paper's short-range band over ``offsets_rows`` (Eq. 3, exact bins)."""
    lps = PAPER_LINES_PER_SECOND
    return band_bin_weights(offsets_rows, band_centre_rows(delay_us, lps), band_width_rows(exposure_us, lps))


def _contrast(w, vein, bg):
    """``1 - vein / background`` in the band ``w``; NaN where no background light reached the band (too few photons)."""
    total = float((w * bg).sum())
    return float(1.0 - (w * vein).sum() / total) if total > 0 else math.nan


def vein_validation(*, wavelength_nm=638, tone="fair", cases=VALIDATION_CASES, n_photons=200_000, progress=None):
    """Contrast of a vein in the short-range and epipolar bands: fast model against brute force.

    For each case ``(angle_deg, depth_mm, diameter_mm, rho_rows)`` the pixel's kernel is
    traced with the blood cylinder in the medium (``n_photons``, seed 0) and without it
    (same seed: correlated), and looked up in the scene's table.

    Returns
    -------
    list of dict
        Per case: the contrasts ``short_brute``, ``short_fast``, ``epipolar_brute``,
        ``epipolar_fast`` (1 - vein / background; NaN where no traced background light reached
        the band: too few photons), the brute-force standard error of the
        short-range contrast ``short_brute_stderr`` (from the batch spread), and the
        kernels ``offsets_rows``, ``ratio_brute``, ``ratio_fast``.
    """
    skin = skin_layers(wavelength_nm, tone)
    table, k0, _ = skin_tables(wavelength_nm, tone)
    mm = table.mm_per_row
    off = table.offsets_rows
    w_short = short_range_weights(off)
    w_epi = (np.abs(off) <= 2).astype(float)
    bg = mc_layered_profile(skin.layers, n_photons=n_photons, offsets_rows=off, mm_per_row=mm, seed=0)
    rows = []
    for angle, depth, diam, rho in cases:
        t0 = time.perf_counter()
        vein = mc_vein_kernel_brute(
            skin.layers,
            skin.blood,
            depth_mm=depth,
            diameter_mm=diam,
            angle_deg=angle,
            rho_rows=rho,
            offsets_rows=off,
            mm_per_row=mm,
            n_photons=n_photons,
            seed=0,
        )
        sl = _table_slice(table, depth, diam)
        ratio_fast = _vein_ratio(sl, table, np.array([rho]), np.array([angle]), off[None, :].astype(float))[0]
        fast = k0 * ratio_fast
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio_brute = np.where(bg.values > 0, vein.values / bg.values, np.nan)
        # Standard error of the brute-force short-range contrast: its kernel's error (the
        # background run is the same for all cases and correlated with it).
        in_band = float((w_short * bg.values).sum())
        se = float(np.sqrt(((w_short * vein.stderr) ** 2).sum()) / in_band) if in_band > 0 else math.nan
        rows.append(
            dict(
                angle_deg=angle,
                depth_mm=depth,
                diameter_mm=diam,
                rho_rows=rho,
                short_brute=_contrast(w_short, vein.values, bg.values),
                short_fast=_contrast(w_short, fast, k0),
                short_brute_stderr=se,
                epipolar_brute=_contrast(w_epi, vein.values, bg.values),
                epipolar_fast=_contrast(w_epi, fast, k0),
                offsets_rows=off.tolist(),
                ratio_brute=np.nan_to_num(ratio_brute, nan=1.0).tolist(),
                ratio_fast=ratio_fast.tolist(),
                seconds=time.perf_counter() - t0,
            )
        )
        if progress is not None:
            progress(1)
    return rows


def adding_doubling_stack(layers, *, quad_pts=16):
    """Total reflectance and transmittance of a stack of index-matched layers by adding-doubling.

    Each layer's reflection/transmission operators come from iadpython's doubling
    (``simple_layer_matrices``: albedo, optical thickness, ``g``), the layers are
    combined with its (asymmetric) adding and the air boundary of index ``n`` goes on
    top (``boundary_matrices``); the bottom of the last layer is index matched, so light
    leaving it is lost -- the geometry of :func:`planeray.mc.layered.mc_layered_profile`.

    Returns ``(UR1, UT1)``: reflectance (specular included) and transmittance for
    collimated normal incidence.
    """
    import copy

    import iadpython as iad

    n = layers[0].n
    if any(m.n != n for m in layers):
        raise ValueError("adding_doubling_stack handles index-matched layers only")
    base = iad.Sample(a=0.5, b=1.0, g=0.0, d=1.0, n=n, n_above=1.0, n_below=n, quad_pts=quad_pts)
    base.update_quadrature()
    R = Rr = T = Tr = None
    for m in layers:
        s = copy.deepcopy(base)
        s.a = m.sigma_s / (m.sigma_s + m.sigma_a)
        s.b = (m.sigma_s + m.sigma_a) * m.thickness_mm
        s.g = m.g
        s.d = m.thickness_mm
        r, t = iad.simple_layer_matrices(s)
        R, Rr, T, Tr = (r, r, t, t) if R is None else iad.add_layers(base, R, Rr, T, Tr, r, r, t, t)
    R01, R10, T01, T10 = iad.boundary_matrices(base, top=True)
    R, Rr, T, Tr = iad.add_layers(base, R01, R10, T01, T10, R, Rr, T, Tr)
    ur1, _, _, _ = base.UX1_and_UXU(R, T)
    # Transmission into the index-matched medium below, over all its angles (not only the
    # escape cone to air that UX1_and_UXU integrates): light leaving the stack is lost.
    ut1 = (base.twonuw @ T)[-1]
    return float(ur1), float(ut1)


def layered_adding_doubling(*, wavelength_nm=638, tone="fair", n_photons=200_000):
    """Total diffuse reflectance of the skin layers: Monte Carlo against adding-doubling (iadpython).

    Returns ``dict(mc, mc_stderr, ad)``: diffuse reflectance (specular excluded) of
    :func:`planeray.mc.layered.mc_layered_profile` and of :func:`adding_doubling_stack`.
    """
    skin = skin_layers(wavelength_nm, tone)
    mc = mc_layered_profile(skin.layers, n_photons=n_photons, offsets_rows=np.arange(-1, 2), seed=0)
    ur1, _ = adding_doubling_stack(skin.layers)
    return dict(mc=mc.total_reflectance, mc_stderr=mc.total_reflectance_stderr, ad=ur1 - mc.specular_reflectance)


#: ``format`` of the ``planeray.json`` of a validation folder (``planeray skin validate --out DIR``).
VALIDATION_FORMAT = "planeray-skin-validation"


def run_skin_validation(
    out=None, *, n_photons=200_000, wavelength_nm=638, overwrite: bool = False, progress=None
) -> dict:
    """Both checks; with ``out`` (a folder) writes ``skin_validation.json`` and ``skin_validation.png``.

    ``out`` is checked before any Monte Carlo: an existing folder is replaced only with
    ``overwrite`` and only if it is a validation folder planeray wrote (its ``planeray.json``);
    it is written atomically (a folder that appears meanwhile is refused, never merged into).
    """
    from ..io import atomic_directory
    from ..io.atomic import MARKER, check_replaceable

    if out is not None:
        check_replaceable(out, overwrite=overwrite, kind="skin validation")
    rows = vein_validation(wavelength_nm=wavelength_nm, n_photons=n_photons, progress=progress)
    # Dark skin has its own vein table (melanin changes the contrast): check it too.
    dark = vein_validation(
        wavelength_nm=wavelength_nm, tone="dark", cases=DARK_CASES, n_photons=n_photons, progress=progress
    )
    ad = layered_adding_doubling(wavelength_nm=wavelength_nm, n_photons=n_photons)
    if progress is not None:
        progress(1)
    report = dict(
        wavelength_nm=wavelength_nm, n_photons=n_photons, adding_doubling=ad, cases=rows, dark_skin_cases=dark
    )
    if out is not None:
        with atomic_directory(Path(out), overwrite=overwrite, kind="skin validation") as tmp:
            # a contrast without background light in its band (too few photons) is null
            (tmp / "skin_validation.json").write_text(json.dumps(jsonable(report), indent=1, allow_nan=False))
            vein_validation_figure(rows, out=tmp / "skin_validation.png")
            (tmp / MARKER).write_text(json.dumps({"format": VALIDATION_FORMAT, "format_version": 1}, indent=1))
    return report
