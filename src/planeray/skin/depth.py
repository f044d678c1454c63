"""Vein depth and diameter from how a vein's contrast changes over a delay-exposure sweep.

Model
-----
The forward model is the skin scene's own (:mod:`planeray.scenes.skin`): a pixel at the
signed distance ``rho`` from a vein's axis, whose direction makes the angle ``a`` with the
projector rows, receives in the image of band ``k``::

    S_k(rho) = sum_u w_k(t, u) c(t, u) [(K0 R(rho, . ; a, depth, diameter)) * F](u)

``K0`` the background line kernel of the skin's layers (tone, wavelength), ``R`` the
vein's perturbation table (:class:`planeray.kernels.vein.VeinTable`, bilinear in depth and
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

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.ndimage import binary_dilation, label
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from ..camera import CameraModel
from ..errors import InputError
from ..goodness import DEFAULT_P_MISFIT, FLAG_EDGE, FLAG_MISFIT, FitQuality, describe_flags, fit_quality
from ..scenes.base import DEFAULT_MM_PER_ROW
from ..timing import Band
from .vein_geometry import CentreLine, VeinPixels, centre_line, other_vein_ratio, vein_geometry
from .vein_model import (
    VeinModel,
    background_signals,
    far_bands,
    image_variance,
    model_offsets,
    row_jitter_sigma,
    row_weights,
    usable_bands,
    vein_contrast,
    vein_model,
    vein_signals,
)

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
    "CentreLine",
    "VeinPixels",
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
    offsets, wide, half, foot = model_offsets(model)
    w = row_weights(model, [mid], offsets)[0]  # (K, U)
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
