"""The forward model of the vein fit: what each image of a delay-exposure sweep records of a skin beside a vein.

A pixel's light in band ``k`` is the skin's background ``B_k`` times ``1 - C_k``, the vein's
contrast: the skin's line kernel ``K0`` (a layered Monte Carlo, :mod:`planeray.kernels.vein`)
changed by the vein's kernel ratio ``R(rho, u)`` (the vein table: depth, diameter, angle and the
pixel's distance ``rho``), weighted by the band's offsets at the pixel's row and averaged over a
camera row's footprint.  :func:`vein_model` builds it for a sweep and a camera geometry;
:func:`vein_signals`, :func:`vein_contrast`, :func:`background_signals` evaluate it;
:func:`usable_bands`, :func:`far_bands`, :func:`image_variance`, :func:`row_jitter_sigma` say what
the images can tell.  :mod:`planeray.skin.depth` fits it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import convolve1d

from ..camera import CameraModel
from ..kernels.vein import VeinTable, vein_ratio, vein_table_slice
from ..scenes.base import DEFAULT_MM_PER_ROW, footprint_kernel
from ..scenes.skin import SKIN_BAND_ROWS, skin_tables
from ..timing import RowGeometry, band_weights_at_row

__all__ = [
    "VeinModel",
    "vein_model",
    "vein_signals",
    "vein_contrast",
    "background_signals",
    "image_variance",
    "usable_bands",
    "far_bands",
    "row_jitter_sigma",
    "model_offsets",
    "row_weights",
]


# ---------------------------------------------------------------- the forward model
@dataclass(frozen=True)
class VeinModel:
    """What the contrast model needs: the skin's vein table, its kernel, the sweep and the geometry."""

    table: VeinTable
    kernel: np.ndarray  # K0 over table.offsets_rows
    geometry: RowGeometry
    bands: tuple  # of timing.Band
    mm_per_row: float
    band_rows: int = SKIN_BAND_ROWS
    params: dict = field(default_factory=dict)

    @property
    def exposures_us(self) -> np.ndarray:
        return np.array([b.exposure_us for b in self.bands])


def vein_model(
    bands,
    geometry: RowGeometry,
    *,
    tone="fair",
    wavelength_nm: int = 638,
    mm_per_row: float = DEFAULT_MM_PER_ROW,
    band_rows: int = SKIN_BAND_ROWS,
    skin=None,
    progress=None,
) -> VeinModel:
    """The contrast model of a skin (tone, wavelength) seen through a sweep's bands.

    Parameters
    ----------
    bands : sequence of planeray.timing.Band
        The images' illumination (e.g. ``stack.bands()``).
    geometry : planeray.timing.RowGeometry
        Camera rows and projector rows.
    tone : str or float
        Skin tone (name or epidermal melanosome fraction).
    wavelength_nm : {638, 850}
        Wavelength, nm.
    mm_per_row : float
        Size of a projector row on the skin, mm.
    band_rows : int
        Half-width of the offset band the scene models (rows).
    skin : planeray.optical_data_skin.SkinLayers, optional
        The skin's layers and blood as the user states them
        (:func:`planeray.optical_data_skin.skin_model`: thicknesses, index, ``g``, optics per layer,
        the blood); default the published layers of ``tone`` at ``wavelength_nm`` with the scene's
        thicknesses.  Its tables are traced once (minutes) and cached
        (:func:`planeray.scenes.skin.skin_tables_to_trace` says which).
    progress : callable, optional
        Called with the photons traced while a table is traced.

    Returns
    -------
    VeinModel
    """
    from ..optical_data_skin import skin_layers

    standard = skin is None or skin == skin_layers(
        skin.wavelength_nm, tone, epidermis_mm=skin.layers[0].thickness_mm, dermis_mm=skin.layers[1].thickness_mm,
        fat_mm=skin.layers[2].thickness_mm,
    )  # fmt: skip
    if skin is None:
        table, kernel, _ = skin_tables(wavelength_nm, tone, mm_per_row=mm_per_row, progress=progress)
    elif standard:  # the published layers at other thicknesses: the tone's tables (interpolated between tones)
        th = dict(epidermis_mm=skin.layers[0].thickness_mm, dermis_mm=skin.layers[1].thickness_mm,
                  fat_mm=skin.layers[2].thickness_mm)  # fmt: skip
        table, kernel, _ = skin_tables(skin.wavelength_nm, tone, mm_per_row=mm_per_row, progress=progress, **th)
    else:
        table, kernel, _ = skin_tables(mm_per_row=mm_per_row, progress=progress, skin=skin)
    params = {"tone": tone, "wavelength_nm": int(wavelength_nm if skin is None else skin.wavelength_nm),
              "mm_per_row": float(mm_per_row)}  # fmt: skip
    if skin is not None:
        params["skin"] = skin.to_json()
    return VeinModel(
        table=table,
        kernel=np.asarray(kernel, float),
        geometry=geometry,
        bands=tuple(bands),
        mm_per_row=float(mm_per_row),
        band_rows=int(band_rows),
        params=params,
    )


def model_offsets(model: VeinModel):
    """``(offsets, wide, half, foot)`` of a vein model: the band's offsets (rows), the offsets a camera row's
    footprint reaches, the footprint's half width and its weights (:func:`planeray.kernels.footprint.footprint_kernel`)."""
    rpc = model.geometry.rows_per_camera_row
    band = max(int(model.band_rows), int(np.ceil(rpc)) + 1)
    offsets = np.arange(-band, band + 1)
    half = int(np.ceil(0.5 * rpc + 0.5))
    wide = np.arange(offsets[0] - half, offsets[-1] + half + 1)
    foot = footprint_kernel(np.arange(-half, half + 1), rpc)
    return offsets, wide, half, foot


def row_weights(model: VeinModel, rows, offsets):
    """``(n_rows, K, U)``: band weights times the edge rule's coverage, per distinct camera row.

    ``rows`` are camera rows, ``offsets`` projector-row offsets (:func:`model_offsets`).
    """
    out = []
    for t in rows:
        w = band_weights_at_row(model.bands, model.geometry, int(t), offsets)
        w = w * model.geometry.coverage(int(t), offsets)[None, :]
        out.append(w)
    return np.stack(out) if out else np.zeros((0, len(model.bands), offsets.size))


def vein_signals(model: VeinModel, rows, rho_mm, angle_deg, depth_mm, diameter_mm, *, _cache=None):
    """Subsurface signal of each image at pixels near one vein, relative to the vein-free skin.

    Parameters
    ----------
    model : VeinModel
    rows : array_like of int, shape (n,)
        Camera row of each pixel.
    rho_mm : array_like, shape (n,)
        Signed distance of each pixel from the vein's axis, mm (the scene's convention:
        ``rho = (x, y) . (cos a, -sin a)``, ``x`` down, ``y`` right).
    angle_deg : array_like, shape (n,)
        Angle between the vein and the projector rows, degrees in [0, 180).
    depth_mm : float
        Depth of the vessel's top, mm (1-5, the tables' range).
    diameter_mm : float
        Vessel diameter, mm (1-4).

    Returns
    -------
    ratio : ndarray (K, n)
        ``S_k(rho) / S_k(no vein)`` for every band ``k``: one minus the contrast (Sec. 10's
        short-range images; NaN where the band holds no light).
    flood : ndarray (n,)
        The same ratio for flood (ambient) light, all offsets summed.
    """
    rows = np.asarray(rows, dtype=np.int64)
    rho = np.asarray(rho_mm, float) / model.mm_per_row
    ang = np.broadcast_to(np.asarray(angle_deg, float), rho.shape)
    offsets, wide, half, foot = model_offsets(model)
    cache = _cache if _cache is not None else {}
    if "W" not in cache:
        urows, inv = np.unique(rows, return_inverse=True)
        cache["W"] = row_weights(model, urows, offsets)
        cache["inv"] = inv
        k_row = np.interp(wide.astype(float), model.table.offsets_rows, model.kernel, left=0.0, right=0.0)
        cache["k_row"] = k_row
        base = convolve1d(k_row[None, :], foot[::-1], axis=1, mode="constant")[:, half:-half][0]
        cache["base"] = base
        cache["S0"] = np.einsum("rku,u->rk", cache["W"], base)  # (n_rows, K)
    sl = vein_table_slice(model.table, float(depth_mm), float(diameter_mm))
    r = vein_ratio(sl, model.table, rho, ang, wide.astype(float))  # the same offsets for every pixel
    sub = convolve1d(cache["k_row"][None, :] * r, foot[::-1], axis=1, mode="constant")[:, half:-half]
    W = cache["W"][cache["inv"]]  # (n, K, U)
    S = np.einsum("nku,nu->kn", W, sub)
    S0 = cache["S0"][cache["inv"]].T
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(S0 > 0, S / S0, np.nan)
    flood = sub.sum(axis=1) / cache["base"].sum()
    return ratio, flood


def background_signals(model: VeinModel, rows) -> np.ndarray:
    """Subsurface signal of each image of vein-free skin at camera rows ``rows``, ``(K, n)``.

    ``sum_u w_k(t, u) c(t, u) (K0 * F)(u)`` in transport units (light per unit of the
    projector's line power; multiply by the camera's ``signal_scale`` for a normalized image).
    """
    rows = np.asarray(rows, dtype=np.int64)
    offsets, wide, half, foot = model_offsets(model)
    urows, inv = np.unique(rows, return_inverse=True)
    W = row_weights(model, urows, offsets)
    k_row = np.interp(wide.astype(float), model.table.offsets_rows, model.kernel, left=0.0, right=0.0)
    base = convolve1d(k_row[None, :], foot[::-1], axis=1, mode="constant")[:, half:-half][0]
    return np.einsum("rku,u->kr", W, base)[:, inv]


def vein_contrast(model: VeinModel, rho_mm, angle_deg, depth_mm, diameter_mm, *, row=None) -> np.ndarray:
    """Contrast ``1 - vein / background`` of a vein in each image, ``(K, n)``, at camera row ``row``.

    ``row`` defaults to the middle camera row (where no band is cut by the projector's end).
    """
    rho = np.atleast_1d(np.asarray(rho_mm, float))
    t = model.geometry.camera_rows // 2 if row is None else int(row)
    ratio, _ = vein_signals(model, np.full(rho.size, t), rho, angle_deg, depth_mm, diameter_mm)
    return 1.0 - ratio


# ---------------------------------------------------------------- noise
def image_variance(image, camera: CameraModel) -> np.ndarray:
    """Variance of a stack image's pixels (normalized units) under the camera's noise model.

    ``frames_averaged`` frames of Poisson electrons (``image * full_well``), Gaussian read
    noise and a uniform rounding to ADC codes per frame, averaged:
    ``var = (e + r^2) / (n FW^2) + 1 / (12 n span^2)``.
    """
    return camera.pixel_variance(image)


def row_jitter_sigma(model: VeinModel, camera: CameraModel) -> np.ndarray:
    """Relative standard deviation of each image's signal, per camera row, from the device's row jitter.

    The trigger of every frame and camera row is offset by ``camera.row_jitter_us`` (Gaussian sigma),
    moving the band by ``sigma_rows = row_jitter_us * lines_per_second`` projector rows along the
    kernel; averaged over ``frames_averaged`` frames, the signal of the whole camera row changes by
    ``|d ln S_k / du| sigma_rows / sqrt(frames)`` (the slope from the vein-free model, +-1 row).
    """
    t = model.geometry.camera_rows // 2
    out = []
    for b in model.bands:
        step_us = 1e6 / b.lines_per_second
        s = [
            background_signals(
                dataclasses.replace(model, bands=(dataclasses.replace(b, delay_us=b.delay_us + d),)), [t]
            )[0, 0]
            for d in (-step_us, step_us)
        ]
        slope = abs(math.log(max(s[1], 1e-300)) - math.log(max(s[0], 1e-300))) / 2.0
        out.append(slope * camera.row_jitter_us * 1e-6 * b.lines_per_second / math.sqrt(camera.frames_averaged))
    return np.array(out)


def far_bands(model: VeinModel, *, excluded=None, level: float = 1e-4) -> np.ndarray:
    """Images that see (almost) only ambient light: their band holds less than ``level`` of the
    vein-free skin's signal in the brightest image of the sweep (the middle camera row)."""
    s0 = background_signals(model, [model.geometry.camera_rows // 2])[:, 0]
    ok = s0 < level * s0.max()
    if excluded is not None:
        ok &= ~np.asarray(excluded, bool)
    return ok


def usable_bands(bands, geometry: RowGeometry, *, excluded=None, band_rows: int = SKIN_BAND_ROWS) -> np.ndarray:
    """Which images the depth fit uses: not excluded, no direct light, inside the modelled offsets.

    An image carries direct (surface) light when its band, widened by 3 jitter sigmas, reaches
    the camera row's footprint (``|u| <= rows_per_camera_row / 2 + 1``); its band must end
    within ``band_rows`` (where the model has the kernel).
    """
    reach = 0.5 * geometry.rows_per_camera_row + 1.0
    ok = []
    for b in bands:
        sigma = 3.0 * b.jitter_us * 1e-6 * b.lines_per_second
        lo = abs(b.centre_rows) - 0.5 * b.width_rows - sigma
        hi = abs(b.centre_rows) + 0.5 * b.width_rows + sigma
        ok.append(lo > reach and hi <= band_rows)
    ok = np.array(ok, bool)
    if excluded is not None:
        ok &= ~np.asarray(excluded, bool)
    return ok
