"""Vein depth and diameter from how a vein's contrast changes over a delay-exposure sweep.

Model
-----
The forward model is the skin scene's own (:mod:`planeray.scenes.skin`): a pixel at the
signed distance ``rho`` from a vein's axis, whose direction makes the angle ``a`` with the
projector rows, receives in the image of band ``k``::

    S_k(rho) = sum_u w_k(t, u) c(t, u) [(K0 R(rho, . ; a, depth, diameter)) * F](u)

``K0`` the background line kernel of the skin's layers (tone, wavelength), ``R`` the
vein's perturbation table (:class:`planeray.mc.layered.VeinTable`, bilinear in depth and
diameter, the same interpolation the simulator uses), ``F`` the camera row's footprint,
``w_k`` the band's weights (Eq. 3 with the recorded jitter) and ``c`` the projector's
edge rule.  The vein's **contrast** in image ``k`` is ``C_k(rho) = 1 - S_k(rho) /
S_k(no vein)``.  ``depth`` is the depth of the vessel's **top** (its wall nearest the
surface), as in the tables and the scene's ground truth; the axis lies ``diameter / 2``
deeper.

Fit (per vein)
--------------
A vein is a connected component of a mask.  Its centre line is traced by the local centroid of
the mask (within 5 mm or 2.5 pixels); each pixel within ``reach_mm`` of it (and at least ``guard_mm`` from every
other vein) gets its signed distance ``rho`` from the nearest centre-line point, measured
along the local normal (the principal direction of the mask in the same disc), and the
local angle to the rows.  The images of the sweep that carry no direct light (band clear
of the camera row's footprint) and are not excluded are fitted together::

    I_k(p) = B_k (1 + g . phi(p)) (1 - C_k(rho_p + delta)) + A t_e,k (1 - C_amb(rho_p))

``B_k`` (background of image ``k``) and ``A`` (ambient light per microsecond of exposure,
whose flood-lit contrast ``C_amb`` is the same model summed over all offsets) are linear
and solved exactly for each trial of the nonlinear parameters (variable projection):
``depth``, ``diameter``, ``delta`` (the vein's offset from the mask's centre line, +-1
pixel) and ``g`` (the skin's smooth tint over the neighbourhood: a quadratic in the
coordinates along and across the vein; the skin scene's tint varies ~5 % over ~3 cm).
Weights are the camera's noise model (shot, read and quantization noise of the averaged
frames; :func:`image_variance`); the device's row jitter, which moves a whole camera row's band
(a few per cent of a short-range image), enters as a factor ``1 + f_kt`` per image and camera
row with a Gaussian prior (:func:`row_jitter_sigma`), fitted with the rest.  Ambient light is
measured per pixel from the sweep's images whose band lies beyond the skin's kernel
(:func:`far_bands`) and subtracted by :func:`fit_veins`; without such images it is fitted.  Standard errors come from the Jacobian of all parameters
at the optimum, scaled by the reduced chi-square when it exceeds 1.

Identifiability: a vein is **unresolved** (depth and diameter NaN, with the reason) when
the delay images do not detect it (the vein model improves chi-square over "no vein" by
less than ``detect_dchi2`` after scaling by the reduced chi-square), when the fit sits on
the edge of the tabulated range, or when depth and diameter trade off (standard error of
the depth above ``max_depth_se_mm``, or their correlation above ``max_correlation``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.ndimage import binary_dilation, convolve1d, distance_transform_edt, label
from scipy.optimize import least_squares
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from ..camera import CameraModel
from ..errors import InputError
from ..goodness import DEFAULT_P_MISFIT, FLAG_EDGE, FLAG_MISFIT, FitQuality, describe_flags, fit_quality
from ..mc.layered import VeinTable
from ..scenes.base import DEFAULT_MM_PER_ROW, footprint_kernel
from ..scenes.skin import SKIN_BAND_ROWS, _table_slice, _vein_ratio, skin_tables
from ..timing import Band, RowGeometry, band_weights_at_row

__all__ = [
    "VeinModel",
    "VeinFit",
    "vein_model",
    "vein_signals",
    "vein_contrast",
    "background_signals",
    "image_variance",
    "usable_bands",
    "far_bands",
    "row_jitter_sigma",
    "vein_geometry",
    "centre_line",
    "other_vein_ratio",
    "fit_vein",
    "fit_veins",
]


#: A larger standard error of the depth reports the vein unresolved, mm: a resolved vein's depth is then within
#: the target's 0.5 mm at 2.5 standard errors (on the seeded forearm, fits with standard errors of 0.26-0.48 mm
#: were off by up to 0.52 mm; at a 0.25 mm threshold two fits at 0.20 and 0.23 mm were off by 0.57 and 0.56 mm).
MAX_DEPTH_SE_MM = 0.2
#: The forward model's error, measured against forward models it was not built from -- brute-force Monte
#: Carlo with the blood in the medium (docs/user_guide/skin_scene.md, "What the checks say": the fast model's short-range
#: contrast within 0-9 % for veins 1-2 mm deep, 18-25 % low for 3 mm, 12-16 % low on dark skin):
#: the vein's contrast is off by a common factor ``1 + s``, ``s`` a nuisance parameter of the fit with a Gaussian prior
#: of this standard deviation (its uncertainty enters every standard error) ...
MODEL_CONTRAST_SD = 0.15
#: ... and each sample's laser light by this share, independently (the vein table's own Monte Carlo error, 4e5 photons).
MODEL_RELATIVE_SD = 0.02
#: The background kernel's error per image, relative (K0's Monte Carlo error is added to it): the images' vein-free
#: backgrounds ``B_k`` must follow the skin model's kernel through the sweep within it, else the skin model is wrong.
BACKGROUND_RELATIVE_SD = 0.03


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


def _offsets(model: VeinModel):
    rpc = model.geometry.rows_per_camera_row
    band = max(int(model.band_rows), int(np.ceil(rpc)) + 1)
    offsets = np.arange(-band, band + 1)
    half = int(np.ceil(0.5 * rpc + 0.5))
    wide = np.arange(offsets[0] - half, offsets[-1] + half + 1)
    foot = footprint_kernel(np.arange(-half, half + 1), rpc)
    return offsets, wide, half, foot


def _row_weights(model: VeinModel, rows, offsets):
    """``(n_rows, K, U)``: band weights times the edge rule's coverage, per distinct camera row."""
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
    offsets, wide, half, foot = _offsets(model)
    cache = _cache if _cache is not None else {}
    if "W" not in cache:
        urows, inv = np.unique(rows, return_inverse=True)
        cache["W"] = _row_weights(model, urows, offsets)
        cache["inv"] = inv
        k_row = np.interp(wide.astype(float), model.table.offsets_rows, model.kernel, left=0.0, right=0.0)
        cache["k_row"] = k_row
        base = convolve1d(k_row[None, :], foot[::-1], axis=1, mode="constant")[:, half:-half][0]
        cache["base"] = base
        cache["S0"] = np.einsum("rku,u->rk", cache["W"], base)  # (n_rows, K)
    sl = _table_slice(model.table, float(depth_mm), float(diameter_mm))
    r = _vein_ratio(sl, model.table, rho, ang, wide.astype(float))  # the same offsets for every pixel
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
    offsets, wide, half, foot = _offsets(model)
    urows, inv = np.unique(rows, return_inverse=True)
    W = _row_weights(model, urows, offsets)
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


# ---------------------------------------------------------------- the vein's geometry from a mask
@dataclass
class VeinPixels:
    """Pixels around one vein: index, row, signed distance from the centre line and local angle."""

    rows: np.ndarray
    cols: np.ndarray
    rho_mm: np.ndarray
    angle_deg: np.ndarray
    x_mm: np.ndarray  # position (for the tint gradient), mm, relative to the vein's centre
    y_mm: np.ndarray
    width_mm: float  # the mask's width across the vein (area / centre-line length)
    line: CentreLine | None = None  # the centre line the distances are measured from


def _pixel_mm(geometry: RowGeometry, mm_per_row: float, shape):
    H, W = shape
    x = (geometry.projector_row_of(np.arange(H)) + 0.5) * mm_per_row
    col = geometry.projector_rows * mm_per_row / H
    y = (np.arange(W) + 0.5) * col
    return x, y, col


@dataclass(frozen=True)
class CentreLine:
    """A vein's centre line from its mask: points (mm, surface ``(x down, y right)``) and local angles."""

    points_mm: np.ndarray  # (m, 2), one per mask pixel: the local centroid
    angle_deg: np.ndarray  # (m,), direction to the rows, in [0, 180)
    px_mm: float  # the larger side of a camera pixel on the skin, mm
    mask_points_mm: np.ndarray  # (m, 2), the mask's pixel centres


def centre_line(component, geometry: RowGeometry, *, mm_per_row: float) -> CentreLine:
    """The centre line of one vein's mask: the local centroid of the mask within a disc (on the axis of a
    locally straight band; radius ``max(5 mm, 2.5 pixels)``) and the local direction, the principal axis of
    the mask in the same disc.

    Parameters
    ----------
    component : ndarray (H, W) bool
        The vein's pixels.
    geometry : RowGeometry
    mm_per_row : float
        Size of a projector row on the skin, mm.
    """
    xs, ys, col_mm = _pixel_mm(geometry, mm_per_row, component.shape)
    row_mm = geometry.rows_per_camera_row * mm_per_row
    ci_, cj_ = np.nonzero(component)
    comp_pts = np.stack([xs[ci_], ys[cj_]], axis=1)
    radius = max(5.0, 2.5 * max(row_mm, col_mm))
    ctree = cKDTree(comp_pts)
    S = np.empty_like(comp_pts)
    dirs = np.empty_like(comp_pts)
    for k, nb in enumerate(ctree.query_ball_point(comp_pts, r=radius)):
        P = comp_pts[nb] if len(nb) >= 3 else comp_pts
        S[k] = P.mean(axis=0)
        _, _, vt = np.linalg.svd(P - P.mean(axis=0), full_matrices=False)
        dirs[k] = vt[0]
    ang = np.degrees(np.arctan2(dirs[:, 0], dirs[:, 1])) % 180.0
    return CentreLine(S, ang, float(max(row_mm, col_mm)), comp_pts)


def _line_coords(line: CentreLine, P):
    """Distance (mm) of points ``P`` (n, 2) from the nearest centre-line point, their signed ``rho`` (mm)
    along its normal, its angle, and whether they lie beside the line (not beyond its ends)."""
    S = line.points_mm
    d, idx = cKDTree(S).query(P)
    a = np.radians(line.angle_deg[idx])
    dx, dy = P[:, 0] - S[idx, 0], P[:, 1] - S[idx, 1]
    rho = dx * np.cos(a) - dy * np.sin(a)
    along = dx * np.sin(a) + dy * np.cos(a)
    return d, rho, line.angle_deg[idx], np.abs(along) <= 0.75 * line.px_mm


def other_vein_ratio(model: VeinModel, line: CentreLine, rows, cols, depth_mm, diameter_mm):
    """Ratio (K, n) and flood ratio (n,) of another vein (its centre line, depth, diameter) at pixels
    ``(rows, cols)``: 1 beyond its ends and beyond the vein table's reach (the skin scene multiplies the
    ratios of all veins)."""
    rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
    K = len(model.bands)
    ratio, flood = np.ones((K, rows.size)), np.ones(rows.size)
    xs, ys, _ = _pixel_mm(model.geometry, model.mm_per_row, (model.geometry.camera_rows, cols.max(initial=0) + 1))
    P = np.stack([xs[rows], ys[cols]], axis=1)
    _, rho, angle, ok = _line_coords(line, P)
    ok &= np.abs(rho) <= (model.table.rho_rows[-1] + 1) * model.mm_per_row
    if ok.any():
        r, f = vein_signals(model, rows[ok], rho[ok], angle[ok], depth_mm, diameter_mm)
        ratio[:, ok] = np.nan_to_num(r, nan=1.0)
        flood[ok] = f
    return ratio, flood


def vein_geometry(
    component, others, geometry: RowGeometry, *, mm_per_row: float, reach_mm: float = 12.0, guard_mm: float = 5.0
) -> VeinPixels:
    """Centre line of one vein's mask and the signed distance of every pixel near it.

    Parameters
    ----------
    component : ndarray (H, W) bool
        The vein's pixels (one connected component of a mask).
    others : ndarray (H, W) bool
        Every other vein's pixels: pixels within ``guard_mm`` of them are left out.
    geometry : RowGeometry
    mm_per_row : float
        Size of a projector row on the skin, mm.
    reach_mm : float
        Pixels up to this distance from the centre line are used, mm.
    guard_mm : float
        Distance kept from other veins, mm.
    """
    shape = component.shape
    xs, ys, col_mm = _pixel_mm(geometry, mm_per_row, shape)
    row_mm = geometry.rows_per_camera_row * mm_per_row
    line = centre_line(component, geometry, mm_per_row=mm_per_row)
    S = line.points_mm
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    dist_other = distance_transform_edt(~others, sampling=(row_mm, col_mm)) if others.any() else np.full(shape, np.inf)
    near = dist_other > guard_mm
    P = np.stack([X[near], Y[near]], axis=1)
    d, rho, angle, ok = _line_coords(line, P)
    keep = d <= reach_mm
    P, rho, angle, ok = P[keep], rho[keep], angle[keep], ok[keep]
    ri, ci = np.nonzero(near)
    ri, ci = ri[keep][ok], ci[keep][ok]
    centre = S.mean(axis=0)
    comp_pts = line.mask_points_mm
    _, _, vt = np.linalg.svd(comp_pts - comp_pts.mean(axis=0), full_matrices=False)
    along_all = comp_pts @ vt[0]
    length = float(along_all.max() - along_all.min()) + min(row_mm, col_mm)
    return VeinPixels(
        rows=ri,
        cols=ci,
        rho_mm=rho[ok],
        angle_deg=angle[ok],
        x_mm=P[ok, 0] - centre[0],
        y_mm=P[ok, 1] - centre[1],
        width_mm=float(component.sum() * row_mm * col_mm / length),
        line=line,
    )


# ---------------------------------------------------------------- the fit
@dataclass
class VeinFit:
    """Depth and diameter of one vein, with standard errors, or why they are not resolved."""

    id: int
    resolved: bool
    reason: str
    depth_mm: float  # of the top of the vessel
    diameter_mm: float
    depth_se_mm: float
    diameter_se_mm: float
    correlation: float
    delta_chi2: float  # chi-square of "no vein" minus the fit's (scaled by the reduced chi-square)
    reduced_chi2: float
    n_pixels: int
    n_images: int
    fit_depth_mm: float = math.nan  # the fit's values even when unresolved (for diagnosis)
    fit_diameter_mm: float = math.nan
    flags: int = 0  # bits of planeray.goodness.FLAGS
    quality: FitQuality | None = None  # the contrast fit's chi-square (noise model and model error)
    background_quality: FitQuality | None = None  # the backgrounds B_k against the skin model's kernel
    contrast_scale: float = math.nan  # 1 + s: the model's contrast scale the fit needed
    curves: dict = field(default_factory=dict, repr=False)

    @property
    def model_fits(self) -> bool | None:
        """False when the skin model does not fit the data (either chi-square past its threshold)."""
        qs = [q for q in (self.quality, self.background_quality) if q is not None]
        return None if not qs else all(q.fits for q in qs)

    @property
    def axis_depth_mm(self) -> float:
        return self.depth_mm + 0.5 * self.diameter_mm

    def to_json(self) -> dict:
        def num(x):
            return None if not np.isfinite(x) else round(float(x), 4)

        return {
            "id": self.id,
            "resolved": self.resolved,
            "reason": self.reason,
            "depth_mm": num(self.depth_mm),
            "depth_se_mm": num(self.depth_se_mm),
            "axis_depth_mm": num(self.axis_depth_mm),
            "diameter_mm": num(self.diameter_mm),
            "diameter_se_mm": num(self.diameter_se_mm),
            "correlation": num(self.correlation),
            "delta_chi2": num(self.delta_chi2),
            "reduced_chi2": num(self.reduced_chi2),
            "n_pixels": self.n_pixels,
            "n_images": self.n_images,
            "fit_depth_mm": num(self.fit_depth_mm),
            "fit_diameter_mm": num(self.fit_diameter_mm),
            "contrast_scale": num(self.contrast_scale),
            "model_fits": self.model_fits,
            "flags": describe_flags(self.flags),
            "fit_quality": None if self.quality is None else self.quality.to_json(),
            "background_quality": None if self.background_quality is None else self.background_quality.to_json(),
        }


def _linear_solve(cols_k, amb, data, wts, te):
    """Weighted least squares of ``data[k, n] = B_k cols_k[k, n] + A te_k amb[n]``; returns residuals, B, A."""
    amb2 = te[:, None] * (amb if np.ndim(amb) == 2 else amb[None, :])
    # normal equations: block structure (K diagonal entries + one shared column)
    a_kk = np.sum(wts * cols_k * cols_k, axis=1)
    a_kA = np.sum(wts * cols_k * amb2, axis=1)
    a_AA = float(np.sum(wts * amb2**2))
    b_k = np.sum(wts * cols_k * data, axis=1)
    b_A = float(np.sum(wts * amb2 * data))
    B, A = _arrow_solve(a_kk, a_kA, a_AA, b_k, b_A)
    pred = B[:, None] * cols_k + A * amb2
    return (data - pred) * np.sqrt(wts), B, A


def _arrow_solve(d, e, s, b, c):
    """``[[diag(d), e], [e^T, s]] [B; A] = [b; c]``: the minimum-norm least-squares solution (``lstsq``'s).

    The matrix (the normal equations of :func:`_linear_solve`, positive semi-definite) is an arrow: where
    every ``d_k`` and the Schur complement ``s - e^T diag(d)^-1 e`` are well above rounding it is solved
    in O(K) by that complement; an ambient column below ``lstsq``'s cutoff (none fitted, ``s = 0``) gives
    ``A = 0`` as ``lstsq`` does (to ~1e-9 of the solution where ``s`` is not exactly 0); anything else (a
    zero background column, an ambient column the backgrounds can imitate) goes to ``lstsq``.
    """
    K = d.size
    cutoff = np.finfo(float).eps * (K + 1) * max(float(d.max(initial=0.0)), s)  # lstsq's rcond=None
    if d.min(initial=np.inf) > cutoff:
        inv = 1.0 / d
        if s <= cutoff:  # no ambient column (then e = 0 and c = 0: Cauchy-Schwarz): A = 0
            return b * inv, 0.0
        schur = s - float(np.dot(e * inv, e))
        if schur > 1e-8 * s:
            A = (c - float(np.dot(e * inv, b))) / schur
            return (b - e * A) * inv, A
    M = np.zeros((K + 1, K + 1))
    M[np.arange(K), np.arange(K)] = d
    M[:K, K] = M[K, :K] = e
    M[K, K] = s
    sol = np.linalg.lstsq(M, np.concatenate([b, [c]]), rcond=None)[0]
    return sol[:K], float(sol[K])


def _spd_solve(N, rhs):
    """``N x = rhs`` for a symmetric positive semi-definite ``N``: by Cholesky where ``N`` is well
    conditioned (its factor's diagonal within 1e6, so a condition number below ~1e12), else ``lstsq``'s
    minimum-norm solution."""
    try:
        factor = cho_factor(N, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        factor = None
    if factor is not None:
        diag = np.abs(np.diagonal(factor[0]))
        if diag.min() > 1e-6 * diag.max():
            return cho_solve(factor, rhs, check_finite=False)
    return np.linalg.lstsq(N, rhs, rcond=None)[0]


def fit_vein(
    model: VeinModel,
    images,
    variance,
    pix: VeinPixels,
    *,
    vein_id: int = 1,
    detect_dchi2: float = 25.0,
    max_depth_se_mm: float = MAX_DEPTH_SE_MM,
    max_correlation: float = 0.98,
    ambient: bool = True,
    max_pixels: int = 600,
    tint_knot_mm: float = 10.0,
    row_sigma=None,
    other=None,
    model_contrast_sd: float = MODEL_CONTRAST_SD,
    model_relative_sd: float = MODEL_RELATIVE_SD,
    background_relative_sd: float = BACKGROUND_RELATIVE_SD,
    p_misfit: float = DEFAULT_P_MISFIT,
) -> VeinFit:
    """Fit one vein's depth and diameter to the images of a sweep (see the module's docstring).

    Parameters
    ----------
    model : VeinModel
        The skin and the bands of ``images`` (one band per image).
    images : ndarray (K, H, W)
        The sweep's usable images (normalized).
    variance : ndarray (K, H, W)
        Their noise variance (:func:`image_variance`).
    pix : VeinPixels
        The vein's neighbourhood (:func:`vein_geometry`).
    vein_id : int
    detect_dchi2 : float
        Least improvement of chi-square over "no vein" (scaled by the reduced chi-square)
        for the vein to count as detected.
    max_depth_se_mm : float
        (default :data:`MAX_DEPTH_SE_MM`)
        A larger standard error of the depth (mm) reports the vein unresolved.
    max_correlation : float
        A larger absolute correlation of depth and diameter reports the vein unresolved.
    ambient : bool
        Fit an ambient term proportional to the exposure.
    max_pixels : int
        At most this many pixels of the neighbourhood are used (evenly spread, for speed).
    tint_knot_mm : float
        Spacing of the knots of the skin's tint along the vein, mm.
    row_sigma : array_like (K,), optional
        Relative standard deviation of each image's per-camera-row factor from the device's row
        jitter (:func:`row_jitter_sigma`); ``None``: no row factors.
    other : tuple of ndarray, optional
        ``(ratio (K, n), flood (n,))`` of the other veins at the pixels of ``pix``
        (:func:`other_vein_ratio`, multiplied over the veins), multiplied into the model (and into
        "no vein" for the detection); ``None``: no other vein.
    model_contrast_sd, model_relative_sd : float
        The forward model's error (:data:`MODEL_CONTRAST_SD`, :data:`MODEL_RELATIVE_SD`): the vein's
        contrast scaled by ``1 + s`` (``s`` fitted with a Gaussian prior of this sd; 0: fixed at 0) and
        an independent share of each sample's laser light added to its variance.
    background_relative_sd : float
        The background kernel's error per image (:data:`BACKGROUND_RELATIVE_SD`), for the test of the
        images' backgrounds against the skin model.
    p_misfit : float
        Chi-square probability below which the skin model is said not to fit (flagged;
        :mod:`planeray.goodness`).

    Returns
    -------
    VeinFit
        With its ``quality`` (the contrast fit's chi-square at its degrees of freedom),
        ``background_quality`` (the images' backgrounds against the model's kernel) and ``flags``.
    """
    # small matrices in a loop: one BLAS thread (a spinning pool made the fit 7x slower on 2 busy cores)
    with threadpool_limits(1, user_api="blas"):
        return _fit_vein(
            model,
            images,
            variance,
            pix,
            vein_id=vein_id,
            detect_dchi2=detect_dchi2,
            max_depth_se_mm=max_depth_se_mm,
            max_correlation=max_correlation,
            ambient=ambient,
            max_pixels=max_pixels,
            tint_knot_mm=tint_knot_mm,
            row_sigma=row_sigma,
            other=other,
            model_contrast_sd=model_contrast_sd,
            model_relative_sd=model_relative_sd,
            background_relative_sd=background_relative_sd,
            p_misfit=p_misfit,
        )


def _fit_vein(
    model,
    images,
    variance,
    pix,
    *,
    vein_id,
    detect_dchi2,
    max_depth_se_mm,
    max_correlation,
    ambient,
    max_pixels,
    tint_knot_mm,
    row_sigma,
    other,
    model_contrast_sd,
    model_relative_sd,
    background_relative_sd,
    p_misfit,
):
    images = np.asarray(images, float)
    K = images.shape[0]
    if other is None:
        other = (np.ones((K, pix.rows.size)), np.ones(pix.rows.size))
    if pix.rows.size > max_pixels:
        pick = np.unique(np.linspace(0, pix.rows.size - 1, int(max_pixels)).astype(np.int64))
        other = (other[0][:, pick], other[1][pick])
        pix = VeinPixels(
            pix.rows[pick],
            pix.cols[pick],
            pix.rho_mm[pick],
            pix.angle_deg[pick],
            pix.x_mm[pick],
            pix.y_mm[pick],
            pix.width_mm,
            pix.line,
        )
    n = pix.rows.size
    nan = math.nan

    def unresolved(reason, **kw):
        return VeinFit(vein_id, False, reason, nan, nan, nan, nan, nan, nan, nan, n, K, **kw)

    if n < 8:
        return unresolved(f"too few pixels near the vein's centre line ({n})")
    if K < 2:
        return unresolved(f"too few usable delay images ({K}; need 2 without direct light)")
    data = images[:, pix.rows, pix.cols]
    wts = 1.0 / np.maximum(variance[:, pix.rows, pix.cols], 1e-30)
    te = model.exposures_us / 1000.0  # ms, to keep A of order 1
    cache: dict = {}
    row_mm = model.geometry.rows_per_camera_row * model.mm_per_row
    col_mm = model.geometry.projector_rows * model.mm_per_row / model.geometry.camera_rows
    px = max(row_mm, col_mm)
    ang = pix.angle_deg
    d_lo, d_hi = float(model.table.depths_mm[0]), float(model.table.depths_mm[-1])
    D_lo, D_hi = float(model.table.diameters_mm[0]), float(model.table.diameters_mm[-1])
    amb_on = 1.0 if ambient else 0.0

    # the skin's smooth tint over the neighbourhood: piecewise linear along the vein (knots every
    # ``tint_knot_mm``) times a quadratic across it (units of 10 mm); solved with B and A for each trial
    xy = np.stack([pix.x_mm, pix.y_mm], axis=1)
    _, _, vt = np.linalg.svd(xy - xy.mean(axis=0), full_matrices=False)
    al, ac = xy @ vt[0], (xy @ vt[1]) / 10.0
    knots = np.arange(al.min(), al.max() + tint_knot_mm, tint_knot_mm)
    if knots.size < 2:
        knots = np.array([al.min(), al.min() + tint_knot_mm])
    hat = np.clip(1.0 - np.abs(al[:, None] - knots[None, :]) / tint_knot_mm, 0.0, None)
    hat = hat[:, hat.sum(axis=0) > 0]
    phi = np.concatenate([hat, hat * ac[:, None], hat * (ac * ac)[:, None]], axis=1)
    c_flat = np.concatenate([np.ones(hat.shape[1]), np.zeros(2 * hat.shape[1])])

    row_of = np.unique(pix.rows, return_inverse=True)[1]
    n_rows = int(row_of.max()) + 1
    rsig = None if row_sigma is None else np.maximum(np.asarray(row_sigma, float), 1e-9)

    def row_sum(x):
        return np.stack([np.bincount(row_of, weights=xk, minlength=n_rows) for xk in x])

    def inner(R, F, c0):
        """Alternating weighted least squares of (B, A), the tint's coefficients c and the per-(image, camera
        row) factors f of the device's row jitter (Gaussian prior, sigma ``row_sigma``); 6 rounds.
        Returns the weighted residuals (data, then the prior's f / sigma), B, A, c, f."""
        c = c0.copy()
        f = np.zeros((K, n_rows))
        for _ in range(6):
            tint = phi @ c
            m = 1.0 + f[:, row_of]
            _, B, A = _linear_solve(R * tint * m, F[None, :] * tint * m, data, wts, te)
            G = (B[:, None] * R + A * te[:, None] * F[None, :]) * m
            q = np.sum(wts * G * G, axis=0)
            r = np.sum(wts * G * data, axis=0)
            c = _spd_solve(phi.T @ (q[:, None] * phi), phi.T @ r)
            c /= max(float(np.mean(phi @ c)), 1e-12)
            if rsig is not None:
                P = (B[:, None] * R + A * te[:, None] * F[None, :]) * (phi @ c)[None, :]
                f = row_sum(wts * P * (data - P)) / (row_sum(wts * P * P) + 1.0 / rsig[:, None] ** 2)
        tint = phi @ c
        m = 1.0 + f[:, row_of]
        res, B, A = _linear_solve(R * tint * m, F[None, :] * tint * m, data, wts, te)
        prior = (f / rsig[:, None]).ravel() if rsig is not None else np.zeros(0)
        return np.concatenate([res.ravel(), prior]), B, A, c, f

    o_ratio, o_flood = np.asarray(other[0], float), np.asarray(other[1], float)
    # the vein-free signal of each image per camera row relative to the middle row's: 1 inside, less where the
    # projector's ends cut the band (the first and last ~10 rows); B_k is the middle row's
    s0 = background_signals(model, pix.rows)
    s0_mid = background_signals(model, [model.geometry.camera_rows // 2])
    with np.errstate(invalid="ignore", divide="ignore"):
        edge = np.nan_to_num(s0 / s0_mid, nan=0.0, posinf=0.0)
    o_ratio = o_ratio * edge
    res_null, B0, A0, c_null, f0 = inner(o_ratio, o_flood * amb_on, c_flat)
    if model_relative_sd > 0:
        # the model's own error: a share of each sample's laser light (the vein-free prediction) joins its variance
        laser = B0[:, None] * o_ratio * (phi @ c_null)[None, :] * (1.0 + f0[:, row_of])
        wts = 1.0 / (1.0 / wts + (model_relative_sd * laser) ** 2)
        res_null, B0, A0, c_null, f0 = inner(o_ratio, o_flood * amb_on, c_flat)
    chi2_null = float(np.sum(res_null**2))
    s_sd = float(model_contrast_sd)

    def model_of(theta):
        depth, diam, delta = theta[:3]
        gain = 1.0 + (theta[3] if len(theta) > 3 else 0.0)  # the model's contrast scale 1 + s
        ratio, flood = vein_signals(model, pix.rows, pix.rho_mm + delta, ang, depth, diam, _cache=cache)
        ratio = 1.0 - gain * (1.0 - np.nan_to_num(ratio, nan=1.0))
        return ratio * o_ratio, (1.0 - gain * (1.0 - flood)) * o_flood * amb_on

    def resid(theta):
        R, F = model_of(theta)
        prior = [theta[3] / s_sd] if s_sd > 0 else []
        return np.concatenate([inner(R, F, c_null)[0], prior])

    # coarse grid, then a bounded local fit (with the contrast scale's nuisance s where the model's error is on)
    best = None
    for depth in np.arange(d_lo, d_hi + 1e-9, 0.5):
        for diam in np.arange(D_lo, D_hi + 1e-9, 0.5):
            start = (depth, diam, 0.0, 0.0) if s_sd > 0 else (depth, diam, 0.0)
            r = resid(start)
            c2 = float(r @ r)
            if best is None or c2 < best[0]:
                best = (c2, start)
    if model_relative_sd > 0:
        # the centre line comes from the mask, to a pixel: each pixel's distance from the vein is uncertain by
        # a pixel / sqrt(12) (the mask's quantization), which enters each sample's variance through the
        # contrast's slope at the grid's best fit (a shift of all distances is the fitted offset delta)
        th = np.array(best[1], float)
        step = 0.25 * px
        hi_r, _ = model_of(np.concatenate([[th[0], th[1], th[2] + step], th[3:]]))
        lo_r, _ = model_of(np.concatenate([[th[0], th[1], th[2] - step], th[3:]]))
        _, Bg, _, cg, fg = inner(*model_of(th), c_null)
        slope = Bg[:, None] * (phi @ cg)[None, :] * (1.0 + fg[:, row_of]) * (hi_r - lo_r) / (2.0 * step)
        wts = 1.0 / (1.0 / wts + (px / math.sqrt(12.0) * slope) ** 2)
        res_null = inner(o_ratio, o_flood * amb_on, c_flat)[0]
        chi2_null = float(np.sum(res_null**2))
    lo = [d_lo, D_lo, -px] + ([-0.8] if s_sd > 0 else [])
    hi = [d_hi, D_hi, px] + ([2.0] if s_sd > 0 else [])
    x0 = np.clip(best[1], np.array(lo) + 1e-6, np.array(hi) - 1e-6)
    x_scale = [0.5, 0.5, 0.5 * px] + ([s_sd] if s_sd > 0 else [])
    sol = least_squares(resid, x0, bounds=(lo, hi), x_scale=x_scale, diff_step=1e-3)
    theta = sol.x
    R, F = model_of(theta)
    res, B, A, c, f = inner(R, F, c_null)
    chi2_fit = float(np.sum(res**2)) + (float(theta[3] / s_sd) ** 2 if s_sd > 0 else 0.0)
    n_par = 3 + K + 1 + phi.shape[1] - 1  # s and the row factors each come with their prior's pseudo-sample
    dof = max(data.size - n_par, 1)
    quality = fit_quality(chi2_fit, dof, p_misfit=p_misfit)
    red = quality.reduced_chi2
    scale = quality.inflation**2
    dchi2 = (chi2_null - chi2_fit) / scale

    def _core_contrast(th, R, F):
        """Measured and fitted contrast per image over the vein's core (``|rho + delta| <= D / 2``, at least
        the nearest pixels): the weighted mean of data / vein-free prediction and of the model's ratio."""
        rr = np.abs(pix.rho_mm + th[2])
        core = rr <= max(0.5 * th[1], float(np.min(rr)) + 0.5 * px)
        bg = B[:, None] * tint[None, :] * m * edge
        dc = data - A * te[:, None] * F[None, :] * tint[None, :] * m
        w, g = wts[:, core], bg[:, core]
        den = np.sum(w * g * g, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            meas = np.sum(w * g * dc[:, core], axis=1) / den
            r_vein = np.where(edge > 0, R / np.where(edge > 0, edge, 1.0), 1.0)  # the veins' ratio alone
            fitted = np.sum(w * g * g * r_vein[:, core], axis=1) / den
            se = 1.0 / np.sqrt(den)
        return {
            "delays_us": [float(b.delay_us) for b in model.bands],
            "exposures_us": [float(b.exposure_us) for b in model.bands],
            "contrast_measured": (1.0 - meas).tolist(),
            "contrast_se": (se * np.sqrt(scale)).tolist(),
            "contrast_fit": (1.0 - fitted).tolist(),
            "core_pixels": int(core.sum()),
        }

    # Jacobian of every parameter at the optimum: theta by central differences, B, A and the tint's
    # coefficients analytically; the covariance of (depth, diameter) from its pseudo-inverse (the
    # tint's scale against B's is a gauge direction with no theta component)
    sw = np.sqrt(wts)
    tint = phi @ c
    m = 1.0 + f[:, row_of]

    def pred_of(th):
        Rt, Ft = model_of(th)
        return (B[:, None] * Rt + A * te[:, None] * Ft[None, :]) * tint[None, :] * m

    n_prior = (0 if rsig is None else K * n_rows) + (1 if s_sd > 0 else 0)

    def col_of(x, prior=None):
        out = np.zeros(data.size + n_prior)
        out[: data.size] = (x * sw).ravel()
        if prior is not None:
            out[data.size + prior[0]] = prior[1]
        return out

    cols = []
    for i, h in enumerate((0.02, 0.02, 0.02 * px, 0.01)[: theta.size]):
        t1, t2 = theta.copy(), theta.copy()
        t1[i] = min(t1[i] + h, hi[i])
        t2[i] = max(t2[i] - h, lo[i])
        prior = (n_prior - 1, 1.0 / s_sd) if i == 3 else None  # the contrast scale's prior: the last pseudo-sample
        cols.append(col_of((pred_of(t1) - pred_of(t2)) / (t1[i] - t2[i]), prior))
    for k in range(K):
        col = np.zeros_like(data)
        col[k] = R[k] * tint * m[k]
        cols.append(col_of(col))
    cols.append(col_of(te[:, None] * F[None, :] * tint[None, :] * m))
    G = (B[:, None] * R + A * te[:, None] * F[None, :]) * m
    for j in range(phi.shape[1]):
        cols.append(col_of(G * phi[None, :, j]))
    if rsig is not None:
        P = (B[:, None] * R + A * te[:, None] * F[None, :]) * tint[None, :]
        for k in range(K):
            for t in range(n_rows):
                col = np.zeros_like(data)
                sel = row_of == t
                col[k, sel] = P[k, sel]
                cols.append(col_of(col, (k * n_rows + t, 1.0 / rsig[k])))
    J = np.stack(cols, axis=1)
    try:
        cov = np.linalg.pinv(J.T @ J) * scale
        se_d, se_D = math.sqrt(max(cov[0, 0], 0.0)), math.sqrt(max(cov[1, 1], 0.0))
        corr = cov[0, 1] / (se_d * se_D) if se_d > 0 and se_D > 0 else nan
        n_theta = theta.size
        var_B = np.diag(cov)[n_theta : n_theta + K]
    except np.linalg.LinAlgError:
        se_d = se_D = corr = nan
        var_B = np.full(K, np.inf)
    bg_quality, bg_curve = _background_quality(model, B, var_B, background_relative_sd, p_misfit)
    curves = {
        "theta": theta.tolist(), "B": B.tolist(), "A": float(A), "background": bg_curve, **_core_contrast(theta, R, F),
    }  # fmt: skip
    out = dict(fit_depth_mm=float(theta[0]), fit_diameter_mm=float(theta[1]), curves=curves)
    flags = 0 if quality.fits and (bg_quality is None or bg_quality.fits) else FLAG_MISFIT
    base = dict(
        correlation=float(corr),
        delta_chi2=float(dchi2),
        reduced_chi2=float(red),
        n_pixels=n,
        n_images=K,
        quality=quality,
        background_quality=bg_quality,
        contrast_scale=float(1.0 + theta[3]) if theta.size > 3 else 1.0,
        **out,
    )
    at_edge = []
    if theta[0] <= d_lo + 0.05:
        at_edge.append(f"depth at the shallowest modelled {d_lo:g} mm (it may be shallower)")
    if theta[0] >= d_hi - 0.05:
        at_edge.append(f"depth at the deep edge of the modelled {d_lo:g}-{d_hi:g} mm (it may be deeper)")
    if theta[1] <= D_lo + 0.05 or theta[1] >= D_hi - 0.05:
        at_edge.append(f"diameter at the edge of the modelled {D_lo:g}-{D_hi:g} mm")
    reason = ""
    if dchi2 < detect_dchi2:
        reason = f"not detected by the delay images (chi-square gain {dchi2:.1f} < {detect_dchi2:g})"
    elif at_edge:  # a parameter at the tables' edge is never reported as a fit
        flags |= FLAG_EDGE
        reason = "; ".join(at_edge) + ": not reported"
    elif not np.isfinite(se_d) or se_d > max_depth_se_mm:
        reason = f"depth not identifiable (standard error {se_d:.2f} mm > {max_depth_se_mm:g} mm)"
    elif np.isfinite(corr) and abs(corr) > max_correlation:
        reason = f"depth and diameter trade off (correlation {corr:.3f})"
    if reason:
        return VeinFit(vein_id, False, reason, nan, nan, se_d, se_D, flags=flags, **base)
    note = "" if flags == 0 else "the skin model does not fit the images (see the fit's chi-square): flagged"
    return VeinFit(vein_id, True, note, float(theta[0]), float(theta[1]), se_d, se_D, flags=flags, **base)


def _background_quality(model: VeinModel, B, var_B, relative_sd, p_misfit):
    """The images' vein-free backgrounds ``B_k`` against the skin model's kernel through the sweep.

    ``B_k`` (the middle camera row's background in image ``k``, fitted freely) must be ``c S0_k`` -- one scale
    (the camera, the skin's tint) times the model's vein-free signal :func:`background_signals` -- within their
    standard errors and the kernel's error (``relative_sd`` plus its Monte Carlo error).  A skin model whose
    layers are wrong (a dermis of another thickness, other optics) puts its light at other offsets: the ratio
    ``B_k / S0_k`` then changes with the delay.  Returns ``(FitQuality or None, curve dict)``.
    """
    mid = model.geometry.camera_rows // 2
    s0 = background_signals(model, [mid])[:, 0]
    # the kernel's Monte Carlo error through the band weights (independent bins), relative to each image's signal
    offsets, wide, half, foot = _offsets(model)
    w = _row_weights(model, [mid], offsets)[0]  # (K, U)
    err = np.interp(offsets.astype(float), model.table.offsets_rows, model.table.kernel_stderr, left=0.0, right=0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel_mc = np.sqrt((w**2 * err[None, :] ** 2).sum(axis=1)) / s0
        rel_b = np.sqrt(np.maximum(var_B, 0.0)) / np.abs(B)
        z = np.log(B / s0)
    sd = np.sqrt(rel_b**2 + rel_mc**2 + float(relative_sd) ** 2)
    ok = np.isfinite(z) & np.isfinite(sd) & (sd > 0) & (B > 0)
    curve = {"log_ratio": np.where(ok, z, np.nan).tolist(), "sd": np.where(ok, sd, np.nan).tolist()}
    if ok.sum() < 3:
        return None, curve
    wz = 1.0 / sd[ok] ** 2
    mean = float(np.sum(wz * z[ok]) / np.sum(wz))
    chi2 = float(np.sum(wz * (z[ok] - mean) ** 2))
    curve["log_scale"] = mean
    return fit_quality(chi2, int(ok.sum()) - 1, p_misfit=p_misfit), curve


def fit_veins(
    stack_images,
    bands,
    geometry,
    mask,
    *,
    camera: CameraModel,
    excluded=None,
    tone="fair",
    wavelength_nm: int = 638,
    mm_per_row: float = DEFAULT_MM_PER_ROW,
    guard_mm: float = 5.0,
    joint_rounds: int = 1,
    max_alongside: float = 0.5,
    skin=None,
    progress=None,
    **fit_options,
):
    """Depth and diameter of every vein of a mask (one per connected component) from a sweep.

    Parameters
    ----------
    stack_images : array_like (N, H, W)
        The sweep's images (normalized, as in :class:`planeray.stack.Stack`).
    bands : sequence of Band
        Their illumination (``stack.bands()``).
    geometry : RowGeometry
    mask : ndarray (H, W) bool or int
        Vein pixels; each 8-connected component is one vein (an integer mask's ids are kept).
    camera : CameraModel
        The camera's noise model.
    excluded : array_like of bool, optional
        Images to leave out (the stack's boundary images).
    tone, wavelength_nm, mm_per_row, skin
        The skin (see :func:`vein_model`; ``skin``: the user's layers and blood).
    guard_mm : float
        Pixels closer than this to another vein are left out, mm.
    joint_rounds : int
        Rounds of refitting each vein with the other veins' current estimates multiplied into its
        model (their shadows reach ~10 mm; the skin scene multiplies the ratios of all veins).
    max_alongside : float
        A vein whose mask touches one other vein's along more than this fraction of its pixels is
        reported unresolved (the two form one band: neither's own shadow can be told apart).
    progress : callable, optional
        Called once per vein fitted (``n_veins * (1 + joint_rounds)`` times with several veins).
    **fit_options
        Passed to :func:`fit_vein`.

    Returns
    -------
    fits : list of VeinFit
    model : VeinModel
        The model of the usable images (for figures).
    use : ndarray of bool
        Which images were used.
    """
    mask = np.asarray(mask)
    if mask.dtype == bool or mask.max() <= 1:
        lab, nlab = label(mask.astype(bool), structure=np.ones((3, 3)))
        ids = list(range(1, nlab + 1))
    else:
        lab = mask.astype(np.int64)
        ids = [int(v) for v in np.unique(lab) if v > 0]
    if not ids:
        raise InputError("the vein mask has no vein pixels")
    skin_kw = dict(tone=tone, wavelength_nm=wavelength_nm, mm_per_row=mm_per_row, skin=skin)
    everything = vein_model(bands, geometry, **skin_kw)
    far = far_bands(everything, excluded=excluded)
    use = usable_bands(bands, geometry, excluded=excluded) & ~far
    if not use.any():
        raise InputError(
            "no image of the sweep is usable for the depth fit (every band holds direct light, is excluded "
            "or lies beyond the skin's kernel)"
        )
    idx = np.nonzero(use)[0]
    model = vein_model([bands[i] for i in idx], geometry, **skin_kw)
    imgs = np.stack([np.asarray(stack_images[i], float) for i in idx])
    var = image_variance(imgs, camera)
    # ambient light: measured per pixel from the images whose band lies beyond the skin's kernel
    # (they hold only the ambient light, proportional to the exposure, with its own vein shadow), and
    # subtracted; without such images it is fitted (one rate per microsecond, the flood-lit contrast)
    ambient_note = "fitted (one rate per microsecond of exposure, the flood-lit contrast)"
    if far.any() and fit_options.get("ambient") is not False:
        fi = np.nonzero(far)[0]
        te_far = np.array([bands[i].exposure_us for i in fi])
        far_imgs = np.stack([np.asarray(stack_images[i], float) for i in fi])
        rate = far_imgs.sum(axis=0) / te_far.sum()
        rate_var = image_variance(far_imgs, camera).sum(axis=0) / te_far.sum() ** 2
        te = model.exposures_us[:, None, None]
        imgs = imgs - rate[None] * te
        var = var + rate_var[None] * te**2
        fit_options = {**fit_options, "ambient": False}
        ambient_note = f"measured per pixel from {fi.size} images whose band lies beyond the skin's kernel, subtracted"
    if camera.row_jitter_us > 0 and "row_sigma" not in fit_options:
        fit_options = {**fit_options, "row_sigma": row_jitter_sigma(model, camera)}
    pixs, alongside = {}, {}
    for vid in ids:
        comp = lab == vid
        others = (lab > 0) & ~comp
        pixs[vid] = vein_geometry(comp, others, geometry, mm_per_row=mm_per_row, guard_mm=guard_mm)
        near_comp = binary_dilation(comp, structure=np.ones((3, 3), bool))
        best = max(
            ((int((binary_dilation(lab == j, structure=np.ones((3, 3), bool)) & comp).sum()), j) for j in ids
             if j != vid and (near_comp & (lab == j)).any()),
            default=(0, 0),
        )  # fmt: skip
        alongside[vid] = (best[0] / max(int(comp.sum()), 1), best[1])

    def fit(vid, other):
        f = fit_vein(model, imgs, var, pixs[vid], vein_id=vid, other=other, **fit_options)
        if progress is not None:
            progress(vid)
        return f

    fits = {vid: fit(vid, None) for vid in ids}
    for _ in range(int(joint_rounds) if len(ids) > 1 else 0):
        shadows = {
            vid: (f.fit_depth_mm, f.fit_diameter_mm)
            for vid, f in fits.items()
            if np.isfinite(f.fit_depth_mm) and "not detected" not in f.reason
        }
        new = {}
        for vid in ids:
            p = pixs[vid]
            o_ratio, o_flood = np.ones((len(model.bands), p.rows.size)), np.ones(p.rows.size)
            for j, (d, D) in shadows.items():
                if j != vid:
                    r, fl = other_vein_ratio(model, pixs[j].line, p.rows, p.cols, d, D)
                    o_ratio *= r
                    o_flood *= fl
            new[vid] = fit(vid, (o_ratio, o_flood))
        fits = new
    fits = list(fits.values())
    for f in fits:
        frac, j = alongside[f.id]
        if f.resolved and frac > max_alongside:
            f.resolved = False
            f.reason = (
                f"runs alongside vein {j} ({frac:.0%} of its mask touches vein {j}'s): the two form one band and "
                "cannot be told apart"
            )
            f.depth_mm = f.diameter_mm = math.nan
        f.curves["alongside"] = {"fraction": frac, "vein": j}
    for f in fits:
        f.curves["ambient"] = ambient_note
    return fits, model, use


def bands_of(delay_us, exposure_us, lines_per_second, *, jitter_us=0.0) -> list:
    """Bands of a sweep's (delay, exposure) pairs (convenience for synthetic captures)."""
    return [
        Band(float(d), float(e), float(lines_per_second), jitter_us=float(jitter_us))
        for d, e in zip(np.atleast_1d(delay_us), np.atleast_1d(exposure_us))
    ]
