"""Measuring a medium from the stack images themselves: ``mu_s'`` and ``mu_a`` in 1/mm.

:func:`planeray.materials.fit.fit_transport` fits the *demultiplexed* transport; on a noisy
capture the demultiplexer's sparsity spikes, the removal of the ambient floor and the camera
noise leave a far tail that reads as absorption.  This module fits the stack's images
directly, where the noise is simple (independent per image and pixel).

Forward model
-------------
A pixel of camera row ``t`` seeing a homogeneous medium of line kernel
``K(u; mu_s', mu_a)`` (:func:`planeray.kernels.forward.forward_kernel`: the Monte Carlo forward
table, averaged over the camera row's projector-row footprint, container walls optional)
records in used stack image ``k``

.. math::

    I_k = c \\sum_u A_k(t, u)\\, K(u) + b\\, I_{w,k}

``A_k(t, u)`` is the illumination matrix the demultiplexer uses
(:meth:`planeray.demux.problem.DemuxProblem.from_stack`: the stack's bands, with the
synchronization blur and the projector's ends, sign convention ``u = v - t``), ``I_w,k`` the
image's band width in projector rows (the row exposure: ambient light integrates over it,
:class:`planeray.camera.CameraModel`), ``c`` the camera's scale (normalized image value per
unit of reflectance; ``signal_scale`` of the simulated camera) and ``b`` the ambient per
projector row of exposure.  A region (a container's pixels) is fitted through its **mean
image values**: the model of the mean is the rows' mean illumination matrix times the kernel
(exact without walls; with walls the kernel is the mean of the pixels' kernels with their
walls, as in :func:`~planeray.materials.fit.fit_transport`).

Calibration
-----------
Without a white reference ``c`` is free (shape only).  With one -- a white Lambertian target
of known albedo captured with the same sweep and camera settings -- each pixel's scale is
fitted from the target's images (:func:`white_stack_scale`: ``c`` over the footprint's direct
light plus its own ambient) and divides the medium's images: ``c = 1`` and the magnitude
constrains ``mu_a``.  ``b`` is always free (one ambient unknown per region, linear).

Fit
---
Weighted least squares in ``(log mu_s', log mu_a)`` (:func:`scipy.optimize.least_squares`),
``c`` and ``b`` solved linearly at every trial (variable projection); the start is the
forward table's grid point of least misfit.  Per-image standard errors come from the
pixels' spread within each camera row (rows differ in their illumination near the projector's
ends, not in their noise).  The forward model's own error joins them in the data's covariance:
:data:`STACK_MODEL_RELATIVE_SD` of each image's modelled laser light (independent) and a
**correlated** part -- the kernel off by :data:`STACK_MODEL_CORRELATED_SD` (relative) in each of
eight smooth bumps over ``log(1 + |u|)``, seen through the illumination matrix (the table's
interpolation error is smooth in the offset, so it moves all images together; treated as
independent it made the standard errors optimistic: ``mu_a`` within two of them in 63 % of the
known-media fits).  Residuals are whitened by that covariance, evaluated at the current estimate
(three passes).  Standard errors come from the Jacobian of all four unknowns at the optimum,
scaled by the reduced chi-square where it exceeds 1.  A parameter is NaN with the reason in the mask
(:data:`planeray.materials.fit.REASONS`) where the data do not constrain it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..camera import CameraModel
from ..demux.problem import DemuxProblem
from ..errors import InputError
from ..goodness import (
    DEFAULT_P_MISFIT,
    FLAG_EDGE,
    FLAG_MISFIT,
    FLAG_NOT_FITTED,
    FLAG_RANGE,
    describe_flags,
    fit_quality,
)
from ..kernels.anisotropy import G_PRIOR, anisotropy_table, check_g, kernel_at_g
from ..kernels.footprint import camera_row_footprint
from ..kernels.forward import DEFAULT_G, ForwardTable, forward_table, kernel_per_row, model_kernel, table_kernel
from ..kernels.walls import check_wall_kind
from ..stack import Stack
from .fit import (
    BOTTOM_EFFECT_SD,
    MAP_NAMES,
    MAX_RELATIVE_SE,
    MODEL_RELATIVE_SD,
    MU_A_BAD,
    MU_S_BAD,
    WALL_EFFECT_SD,
    WALL_SHAPE_SD,
    TransportFit,
    bottom_row,
    describe_reasons,
    grid_starts,
    group_walls,
    log_bounds,
    model_error_basis,
    num_or_none,
    out_of_range,
    regions_and_walls,
    sandwich_covariance,
    second_optimum,
    wall_error_columns,
    wall_shape_columns,
    widen_for_second_optimum,
)

__all__ = ["StackDesign", "stack_design", "stack_model_images", "white_stack_scale", "fit_stack"]

#: Fewer used images with data than this: no fit (reason bit 1).
MIN_IMAGES = 6
#: The forward model's relative error per image, independent (of the modelled laser light).
STACK_MODEL_RELATIVE_SD = MODEL_RELATIVE_SD
#: The forward model's correlated relative error: the kernel off by this much in each of a few smooth bumps
#: over the offsets (table interpolation: 2-6 % against direct Monte Carlo, tests and tools/validate_stack_fit.py).
STACK_MODEL_CORRELATED_SD = 0.03


@dataclass(frozen=True)
class StackDesign:
    """The stack's illumination matrices, per group of camera rows that share one.

    Attributes
    ----------
    image_index : ndarray (N,) of int
        Stack images used (the boundary images excluded, as for demultiplexing).
    offsets_rows : ndarray (U,) of int
        Offsets ``u = v - t``, projector rows (the sweep's support).
    A : ndarray (G, N, U)
        Weight of offset bin ``u`` in image ``k`` for the rows of group ``g``: the band's
        weight times the bin's share on the projector (the transport of a bin the projector's
        end cuts holds the light of its part on the projector).
    row_group : ndarray (H,) of int
        Group of each camera row.
    exposure_rows : ndarray (N,)
        Band width of each used image, projector rows (the ambient column).
    rows_per_camera_row : float
    """

    image_index: np.ndarray
    offsets_rows: np.ndarray
    A: np.ndarray
    row_group: np.ndarray
    exposure_rows: np.ndarray
    rows_per_camera_row: float

    def mean_matrix(self, rows) -> np.ndarray:
        """The illumination matrix of the mean of pixels in camera rows ``rows`` (one entry per pixel)."""
        g = np.bincount(self.row_group[np.asarray(rows, np.int64)], minlength=self.A.shape[0]).astype(np.float64)
        return np.tensordot(g / max(g.sum(), 1.0), self.A, axes=1)


def stack_design(stack: Stack) -> StackDesign:
    """The illumination matrices of a stack's used images (:class:`StackDesign`).

    Parameters
    ----------
    stack : Stack

    Returns
    -------
    StackDesign
    """
    prob = DemuxProblem.from_stack(stack)
    U = prob.offsets_rows.size
    A = np.zeros((len(prob.groups), prob.n_images, U))
    for g, grp in enumerate(prob.groups):
        A[g][:, grp.valid] = grp.A  # W_lit * on_projector: the weights of the bins' light (see RowGroup)
    return StackDesign(
        prob.image_index,
        prob.offsets_rows,
        A,
        prob.row_group,
        prob.exposure_rows,
        float(stack.geometry.rows_per_camera_row),
    )


def stack_model_images(
    stack: Stack,
    mu_s_prime_per_mm,
    mu_a_per_mm,
    *,
    mm_per_row,
    scale=1.0,
    ambient=0.0,
    table: ForwardTable | None = None,
    design: StackDesign | None = None,
) -> np.ndarray:
    """The forward model: each used stack image of a camera row seeing an unbounded homogeneous medium.

    Parameters
    ----------
    stack : Stack
        The capture (its sweep, geometry and synchronization metadata; images unused).
    mu_s_prime_per_mm, mu_a_per_mm : float
        Reduced scattering and absorption, mm^-1.
    mm_per_row : float
        Size of one projector row on the surface, mm.
    scale : float
        ``c``: normalized image value per unit of reflectance per bin (the simulated camera's
        ``signal_scale``).
    ambient : float
        ``b``: normalized image value per projector row of exposure.
    table : ForwardTable, optional
    design : StackDesign, optional
        :func:`stack_design` of the stack (computed when not given).

    Returns
    -------
    ndarray (N, H)
        Image ``design.image_index[k]`` at camera row ``t`` (every pixel of the row alike).
    """
    from ..kernels.forward import forward_kernel

    design = design or stack_design(stack)
    k = forward_kernel(
        mu_s_prime_per_mm,
        mu_a_per_mm,
        offsets_rows=design.offsets_rows,
        mm_per_row=mm_per_row,
        rows_per_camera_row=design.rows_per_camera_row,
        table=table,
    )
    per_group = float(scale) * design.A @ k + float(ambient) * design.exposure_rows[None, :]  # (G, N)
    return per_group[design.row_group].T


def _images(stack: Stack, design: StackDesign):
    """Used images ``(N, H, W)`` float64 and where they are usable (finite, not saturated)."""
    imgs = np.asarray(stack.images, np.float64)[design.image_index]
    ok = np.isfinite(imgs)
    if stack.saturated is not None:
        ok &= ~np.asarray(stack.saturated, bool)[design.image_index]
    return imgs, ok


def white_stack_scale(white: Stack, *, albedo=0.99, design: StackDesign | None = None) -> np.ndarray:
    """Per-pixel camera scale from a stack of a white Lambertian target of known ``albedo``.

    Each pixel's images are fitted (linear least squares) by ``c_w (A f)_k + b I_w,k``: ``f``
    the direct light of a Lambertian surface (the camera row's projector-row footprint, summing
    to 1), ``A`` the stack's illumination matrix, ``b`` the pixel's ambient.  A surface of
    albedo ``rho`` gives ``c_w = rho c``; the scale is ``c = c_w / rho``: divide a capture of
    the same sweep and camera settings by it and its unit is reflectance per offset bin, the
    line kernel's.

    Parameters
    ----------
    white : Stack
        The target's capture.
    albedo : float
        Its albedo in (0, 1].
    design : StackDesign, optional
        :func:`stack_design` of ``white``.

    Returns
    -------
    ndarray (H, W)
        The scale (normalized image value per unit reflectance); NaN where the target gives no
        usable direct light.
    """
    if not 0.0 < float(albedo) <= 1.0:
        raise InputError(f"the white reference's albedo must be in (0, 1], got {albedo!r}")
    design = design or stack_design(white)
    f_off, f_w = camera_row_footprint(design.rows_per_camera_row)
    direct = np.zeros(design.offsets_rows.size)
    for o, w in zip(f_off, f_w):
        direct[design.offsets_rows == o] += w
    imgs, ok = _images(white, design)
    H, W = white.shape
    out = np.full((H, W), np.nan)
    for g in range(design.A.shape[0]):
        rows = np.flatnonzero(design.row_group == g)
        D = np.stack([design.A[g] @ direct, design.exposure_rows], axis=1)  # (N, 2)
        Y = imgs[:, rows, :].reshape(imgs.shape[0], -1)
        M = ok[:, rows, :].reshape(imgs.shape[0], -1)
        full = M.all(axis=0)
        c = np.full(Y.shape[1], np.nan)
        c[full] = (np.linalg.pinv(D) @ Y[:, full])[0]  # every image usable: one solve for all such pixels
        for j in np.flatnonzero(~full & (M.sum(axis=0) >= 3)):
            m = M[:, j]
            c[j] = np.linalg.lstsq(D[m], Y[m, j], rcond=None)[0][0]
        out[rows] = c.reshape(rows.size, W)
    out /= float(albedo)
    return np.where(out > 0, out, np.nan)


def _region_data(imgs, ok, rows, cols, variance=None):
    """Mean image values of a pixel set ``(N,)``, their standard errors and the pixels' rows per image.

    With ``variance`` (each pixel's noise variance under the camera's model, ``(N, H, W)``) the standard
    error is that of the mean, ``sqrt(sum var) / n``; otherwise the within-row spread (pixels of one camera
    row share an illumination): ``sqrt(sum_r n_r s_r^2) / n``, rows with a single pixel taking the pooled
    variance.
    """
    v = imgs[:, rows, cols]  # (N, P)
    m = ok[:, rows, cols]
    n = m.sum(axis=1)
    y = np.where(n > 0, np.where(m, v, 0.0).sum(axis=1) / np.maximum(n, 1), np.nan)
    if variance is not None:
        var = np.where(m, variance[:, rows, cols], 0.0).sum(axis=1) / np.maximum(n, 1) ** 2
        return y, np.sqrt(var), m
    urows, inv = np.unique(rows, return_inverse=True)
    R = urows.size
    N = v.shape[0]
    cnt = np.zeros((N, R))
    s1 = np.zeros((N, R))
    s2 = np.zeros((N, R))
    for k in range(N):
        w = m[k].astype(np.float64)
        cnt[k] = np.bincount(inv, w, minlength=R)
        s1[k] = np.bincount(inv, w * v[k], minlength=R)
        s2[k] = np.bincount(inv, w * v[k] ** 2, minlength=R)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_r = s1 / cnt
        var_r = np.maximum(s2 - cnt * mean_r**2, 0.0) / (cnt - 1)
    has = cnt >= 2
    if has.any():
        pooled = np.where(has, var_r * (cnt - 1), 0.0).sum(axis=1) / np.maximum(
            np.where(has, cnt - 1, 0).sum(axis=1), 1
        )
        var_r = np.where(has, var_r, pooled[:, None])
        var = np.where(cnt > 0, cnt * var_r, 0.0).sum(axis=1) / np.maximum(n, 1) ** 2
    else:  # one pixel per row: the spread of all pixels (rows' differences included: conservative)
        var = np.array([np.var(v[k][m[k]], ddof=1) if m[k].sum() > 1 else np.nan for k in range(N)]) / np.maximum(n, 1)
    return y, np.sqrt(var), m


def _fit_region(
    y,
    se,
    Abar,
    Iw,
    offsets,
    foot,
    walls,
    *,
    table,
    calibrated,
    h,
    max_relative_se,
    model_relative_sd,
    model_correlated_sd,
    lo,
    hi,
    starts,
    Kg,
    basis,
    wall_kind="clear",
    jitter=None,
    p_misfit=DEFAULT_P_MISFIT,
    wall_effect_sd=0.0,
    bottom_effect_sd=0.0,
    wall_shape_sd=0.0,
    g=DEFAULT_G,
    g_table=None,
):
    """One region's fit: ``dict`` of per-row estimates (log), standard errors, mask bits, scale, ambient, model.

    The data's covariance is the images' standard errors (diagonal; the camera's noise model of the mean,
    or the pixels' spread), the camera's row jitter (``jitter``: ``(A_g (N, N_img, U), weights (N,),
    variance in rows^2)``: each camera row's band moved as a whole, ``(c A_g K')^2`` per row, the rows'
    weights squared) plus the forward model's error: ``model_relative_sd`` of the modelled laser light per
    image (independent), a correlated part -- the kernel off by ``model_correlated_sd`` (relative) in
    each smooth bump of ``basis`` over the offsets, independently, seen through the illumination matrix --
    and the walls' and the bottom's effects off by ``wall_effect_sd`` and ``bottom_effect_sd`` of themselves; the
    walls' effect off in shape (``wall_shape_sd`` of it in each bump of ``basis``) widens the standard errors
    (:func:`planeray.materials.fit.sandwich_covariance`), not the weights.
    Residuals are whitened by it (held at the current estimate during a least-squares pass; three passes).
    The chi-square of the whitened residuals at ``images - 4`` (shape only; 3 calibrated) degrees of
    freedom is the fit's :class:`planeray.goodness.FitQuality`.  ``g`` is the medium's anisotropy: the
    table's (no change), a stated value (the kernel changed by :func:`planeray.kernels.anisotropy.g_kernel_change`,
    ``g_table``), or None -- fitted within :data:`~planeray.kernels.anisotropy.G_PRIOR`, a third parameter (one
    degree of freedom less; its uncertainty in the others' standard errors).
    """
    out = dict(
        mask=0, x=None, se_log=np.full(2, np.nan), c=np.nan, b=np.nan, chi2=np.nan, dof=0, model=None, kernel=None,
        quality=None,
    )  # fmt: skip
    ok = np.isfinite(y) & np.isfinite(se)
    if ok.sum() < MIN_IMAGES:
        out["mask"] |= 1
        return out
    Y, A, I = y[ok], Abar[ok], Iw[ok]
    se0 = np.maximum(se[ok], 1e-6 * max(float(np.abs(Y).max()), 1e-30))
    if jitter is not None:
        A_g, w_g, var_rows = jitter
        A_g = A_g[:, ok]

    fit_g = g is None

    def kernel(x):
        k_row = table_kernel(table, x[0], x[1])
        k = model_kernel(table, x[0], x[1], offsets, foot, walls, wall_kind, k=k_row)
        return kernel_at_g(k, k_row, x[0], x[1], table.n, x[2] if fit_g else g, offsets, foot, table=g_table)

    def effect_columns(x, c):
        """``(N, K)``: the images' change along each column of the walls' and the bottom's model error
        (:func:`planeray.materials.fit.wall_error_columns`), seen through the illumination matrix."""
        if walls is None or x is None:
            return None
        E = wall_error_columns(
            table, x, offsets, foot, walls, wall_kind, effect_sd=wall_effect_sd, bottom_sd=bottom_effect_sd
        )
        return None if E is None else c * (A @ E)

    def jitter_var(c, k):
        """Variance of each image of the mean from the row jitter: ``sum_g w_g (c A_g K')^2 var_rows``."""
        if jitter is None:
            return 0.0
        dk = np.gradient(np.concatenate([[0.0], k, [0.0]]))[1:-1]
        return var_rows * (w_g[:, None] * (c * (A_g @ dk)) ** 2).sum(axis=0)

    def whitener(m, c, k, x=None):
        """Inverse Cholesky factor of the covariance at modelled laser images ``c m`` and kernel ``c k``."""
        cov = np.diag(se0**2 + (model_relative_sd * c * m) ** 2 + (jitter_var(c, k) if k is not None else 0.0))
        if model_correlated_sd > 0 and k is not None:
            B = A @ (c * k[:, None] * basis)  # (N, J): the images' change per bump of relative kernel error
            cov = cov + model_correlated_sd**2 * (B @ B.T)
        E = effect_columns(x, c)
        if E is not None:
            cov = cov + E @ E.T
        return np.linalg.inv(np.linalg.cholesky(cov))

    def linear(m, L):
        """Best ``(c, b)`` for the modelled laser images ``m`` (``c = 1`` calibrated) and the whitened residual."""
        t = L @ Y
        if calibrated:
            w = L @ I
            t = t - L @ m
            b = float(w @ t) / max(float(w @ w), 1e-300)
            return 1.0, b, t - b * w
        D = L @ np.stack([m, I], axis=1)
        coef, *_ = np.linalg.lstsq(D, t, rcond=None)
        return float(coef[0]), float(coef[1]), t - D @ coef

    # start: the table's grid point of least misfit (walls left out: a start only), independent errors
    L = np.diag(1.0 / np.hypot(se0, model_relative_sd * np.abs(Y)))
    Mg = Kg @ A.T  # (G, N)
    costs = [float(np.sum(linear(Mg[i], L)[2] ** 2)) for i in range(len(Mg))]
    g0 = int(np.argmin(costs))
    if fit_g:  # the anisotropy a third parameter, from the table's
        lo, hi = np.append(lo, G_PRIOR[0]), np.append(hi, G_PRIOR[1])
        x0 = np.clip(np.append(starts[g0], DEFAULT_G), lo + 1e-9, hi - 1e-9)
    else:
        x0 = np.clip(starts[g0], lo + 1e-9, hi - 1e-9)
    c0 = linear(Mg[g0], L)[0]
    L = whitener(Mg[g0], c0, Kg[g0])

    def resid(x):
        return linear(A @ kernel(x), L)[2]

    try:
        for _ in range(3):  # the model's error at the start, then at each estimate
            res = least_squares(resid, x0, bounds=(lo, hi), method="trf", diff_step=1e-4, x_scale=1.0)
            x0 = np.clip(res.x, lo + 1e-9, hi - 1e-9)
            k = kernel(x0)
            m = A @ k
            c, _, _ = linear(m, L)
            L = whitener(m, abs(c), k, x0)
        res = least_squares(resid, x0, bounds=(lo, hi), method="trf", diff_step=1e-4, x_scale=1.0)
    except (ValueError, np.linalg.LinAlgError):
        out["mask"] |= 64
        return out
    # a second optimum, from the best grid start far from the estimate, with the same weights: the better one is
    # the estimate, one nearly as good widens the standard errors (fit.widen_for_second_optimum)
    res, res_alt = second_optimum(
        res, starts, costs,
        lambda i: np.clip(np.append(starts[i], DEFAULT_G) if fit_g else starts[i], lo + 1e-9, hi - 1e-9),
        lambda xa: least_squares(resid, xa, bounds=(lo, hi), method="trf", diff_step=1e-4, x_scale=1.0),
    )  # fmt: skip
    if not res.success:
        out["mask"] |= 64
    x = res.x
    k = kernel(x)
    m = A @ k
    c, b, r = linear(m, L)
    # standard errors: Jacobian of all unknowns (log s, log a, c[, b]) of the whitened residual
    step = 1e-4
    cols = []
    for i in range(x.size):
        xi = np.array(x, float)
        h_i = step if xi[i] + step <= hi[i] else -step  # inside the bounds (g at its upper end)
        xi[i] += h_i
        cols.append(L @ (c * (A @ kernel(xi) - m)) / h_i)
    if not calibrated:
        cols.append(L @ m)
    cols.append(L @ I)
    J = np.stack(cols, axis=1)
    n_dof = max(int(ok.sum()) - J.shape[1], 1)
    quality = fit_quality(float(r @ r), n_dof, p_misfit=p_misfit)
    chi2 = quality.reduced_chi2
    # the walls' shape error widens the standard errors (not the weights, not the chi-square)
    shape = None if walls is None else wall_shape_columns(
        table, x, offsets, foot, walls, wall_kind, shape_sd=wall_shape_sd, basis=basis
    )  # fmt: skip
    cov = sandwich_covariance(J, None if shape is None else L @ (c * (A @ shape))) * quality.inflation**2
    se_log = np.sqrt(np.maximum(np.diag(cov)[:2], 0.0))
    if res_alt is not None and res_alt.success:
        se_log = widen_for_second_optimum(se_log, x, 2.0 * res.cost, res_alt.x, 2.0 * res_alt.cost, quality.inflation)
    corr = float(cov[0, 1] / (se_log[0] * se_log[1])) if se_log[0] > 0 and se_log[1] > 0 else 0.0
    out.update(
        log_correlation=corr,
        x=x[:2], se_log=se_log, c=c, b=b, chi2=chi2, dof=n_dof, quality=quality, model=c * (Abar @ k) + b * Iw,
        kernel=c * k, g=float(x[2]) if fit_g else float(g), g_se=float(np.sqrt(max(cov[2, 2], 0.0))) if fit_g else None,
    )  # fmt: skip
    edge_tol = 0.02
    if min(x[0] - lo[0], hi[0] - x[0]) < edge_tol:
        out["mask"] |= 2
    if min(x[1] - lo[1], hi[1] - x[1]) < edge_tol:
        out["mask"] |= 4
    if not se_log[0] <= max_relative_se:
        out["mask"] |= 8
    if not se_log[1] <= max_relative_se:
        out["mask"] |= 16
    k0 = kernel_per_row(table, x[0], x[1], np.array([0, 1]), camera_row_footprint(1.0))
    if k0[1] < 0.05 * k0[0] and foot[0].size == 1:
        out["mask"] |= 32
    if not calibrated and not c > 0:
        out["mask"] |= 1
    return out


def fit_stack(
    stack: Stack,
    *,
    mm_per_row,
    labels=None,
    containers=None,
    white=None,
    white_albedo=0.99,
    block_px=None,
    table: ForwardTable | None = None,
    max_relative_se=MAX_RELATIVE_SE,
    model_relative_sd=STACK_MODEL_RELATIVE_SD,
    model_correlated_sd=STACK_MODEL_CORRELATED_SD,
    camera: CameraModel | None = None,
    depth_mm=None,
    wall_kind: str = "clear",
    p_misfit=DEFAULT_P_MISFIT,
    wall_effect_sd=WALL_EFFECT_SD,
    bottom_effect_sd=BOTTOM_EFFECT_SD,
    wall_shape_sd=WALL_SHAPE_SD,
    g=None,
    progress=None,
) -> TransportFit:
    """Fit ``mu_s'`` and ``mu_a`` (1/mm) of each region from a stack's images directly (see the module).

    Parameters
    ----------
    stack : Stack
        The capture (normalized images; boundary images are left out as in demultiplexing,
        saturated pixels per image too).
    mm_per_row : float
        Size of one projector row on the surface, mm.
    labels : ndarray (H, W) of int, optional
        Regions (0: left out).  Default: every pixel one region (1).
    containers : ndarray (H, W) of int, optional
        Containers (labels) whose boundaries are clear walls: each region's kernel is the
        mean of its pixels' kernels with their walls (:func:`planeray.materials.fit.fit_transport`).
    white : Stack or ndarray (H, W), optional
        A white Lambertian target's capture with the same sweep and camera settings, or its
        :func:`white_stack_scale`: the fit is calibrated (``c = 1``); otherwise shape only.
    white_albedo : float
        The target's albedo (when ``white`` is a stack).
    block_px : int, optional
        Also fit blocks of ``block_px x block_px`` pixels (within each region) for the maps;
        None: the maps hold each region's estimate on its pixels.
    table : ForwardTable, optional
    max_relative_se : float
        A parameter with a larger relative standard error is NaN (reason in the mask).
    model_relative_sd, model_correlated_sd : float
        The forward model's relative error: independent per image (of its modelled laser light), and
        correlated -- the kernel off by this much in each of a few smooth bumps over the offsets
        (:data:`STACK_MODEL_CORRELATED_SD`; 0: none).
    camera : CameraModel, optional
        The camera's noise model (the stack's record): the images' noise is its shot, read and
        quantization noise of the mean, and its row jitter (each camera row's band moved as a whole).
        None: the pixels' spread within each camera row (no row jitter).
    depth_mm : float or dict, optional
        Depth (mm) of a layer whose bottom loses the light (one value, or ``{region: depth_mm}``; the
        slab's image series, :func:`planeray.kernels.forward.forward_kernel`); default semi-infinite media.
    wall_kind : {"clear", "black"}
        The containers' walls (:data:`planeray.materials.fit.WALL_KINDS`).
    p_misfit : float
        Chi-square probability below which a fit is flagged "model does not fit" (:mod:`planeray.goodness`).
    wall_effect_sd, bottom_effect_sd : float
        The model's error in the walls' and the bottom's effects, shares of them (:data:`WALL_EFFECT_SD`,
        :data:`BOTTOM_EFFECT_SD`; 0: taken as exact): in the data's covariance along their shapes.
    wall_shape_sd : float
        The walls' effect off in its shape over the offsets: this share of it in each smooth bump of the
        model-error basis, independently (:data:`WALL_SHAPE_SD`, measured against Mitsuba 3; 0: none), in the
        standard errors (:func:`planeray.materials.fit.wall_shape_columns`).
    g : float, optional
        The media's Henyey-Greenstein anisotropy (the forward table's is 0.8; :mod:`planeray.kernels.anisotropy`
        changes its kernel to another).  None: unknown -- fitted with ``mu_s'`` and ``mu_a`` within
        :data:`planeray.kernels.anisotropy.G_PRIOR`, its uncertainty carried into theirs (each region's ``g`` and
        ``g_se``).
    progress : callable, optional
        Called with the number of fits just done.

    Returns
    -------
    TransportFit
        ``regions`` per label (estimates, standard errors, reasons, ``scale``, ``ambient``, chi-square,
        ``fit_quality``, ``flags``); ``profiles[region]`` = (mean images, their standard errors, fitted
        images) over ``offsets_rows`` = the used images' indices; ``maps`` (with the flag layer ``flags``:
        bits of :data:`planeray.goodness.FLAGS`, 255 outside every region).
    """
    if not isinstance(stack, Stack):
        raise InputError("fit_stack needs a Stack")
    h = float(mm_per_row)
    if not h > 0:
        raise InputError(f"mm_per_row must be positive, got {mm_per_row!r}")
    table = table or forward_table()
    check_wall_kind(wall_kind)
    g = check_g(g)
    design = stack_design(stack)
    H, W = stack.shape
    imgs, ok = _images(stack, design)
    variance = None if camera is None else camera.pixel_variance(imgs)
    calibrated = white is not None
    if calibrated:
        if isinstance(white, Stack):
            if white.shape != stack.shape or not (
                np.array_equal(white.delay_us, stack.delay_us) and np.array_equal(white.exposure_us, stack.exposure_us)
            ):
                raise InputError("the white reference must be captured with the same sweep and image size")
            scale = white_stack_scale(white, albedo=white_albedo)
        else:
            scale = np.asarray(white, np.float64)
            if scale.shape != (H, W):
                raise InputError(f"white scale has shape {scale.shape}, the stack {(H, W)}")
        good = np.isfinite(scale) & (scale > 0)
        imgs = imgs / np.where(good, scale, 1.0)[None]
        if variance is not None:
            variance = variance / np.where(good, scale, 1.0)[None] ** 2
        ok &= good[None]
    lab, dist = regions_and_walls(labels, containers, (H, W), design.rows_per_camera_row, "stack")
    b = None if block_px is None else int(block_px)
    if b is not None and b < 1:
        raise InputError(f"block_px must be >= 1, got {block_px!r}")
    offsets = design.offsets_rows
    foot = camera_row_footprint(design.rows_per_camera_row)
    lo, hi = log_bounds(table)
    starts, Kg = grid_starts(table, offsets, foot)
    kw = dict(
        table=table, calibrated=calibrated, h=h, max_relative_se=max_relative_se,
        model_relative_sd=model_relative_sd, model_correlated_sd=model_correlated_sd, lo=lo, hi=hi,
        starts=starts, Kg=Kg, basis=model_error_basis(offsets), wall_kind=wall_kind, p_misfit=p_misfit,
        wall_effect_sd=wall_effect_sd, bottom_effect_sd=bottom_effect_sd, wall_shape_sd=wall_shape_sd, g=g,
        g_table=anisotropy_table() if g is None or g != DEFAULT_G else None,
    )  # fmt: skip
    var_rows = None if camera is None else camera.row_jitter_rows(stack.lines_per_second) ** 2

    def bottom_of(region):
        return bottom_row(depth_mm, region, h)

    def fit_pixels(rows, cols, region):
        y, se, m = _region_data(imgs, ok, rows, cols, variance)
        # the mean illumination of the pixels that count in each image (saturated ones drop out)
        Abar = np.empty((y.size, offsets.size))
        for k in range(y.size):
            Abar[k] = design.mean_matrix(rows[m[k]])[k] if m[k].any() else 0.0
        walls = None if dist is None else group_walls(dist[rows, cols])
        bottom = bottom_of(region)
        if bottom is not None:
            walls = bottom if walls is None else np.concatenate([walls, bottom])
        jitter = None
        if var_rows is not None and var_rows > 0:
            # each camera row's pixels share its jitter: the mean's variance weighs a row by (its pixels / n)^2
            n_r = np.bincount(rows, minlength=H).astype(np.float64) / rows.size
            w_g = np.bincount(design.row_group, weights=n_r**2, minlength=design.A.shape[0])
            jitter = (design.A, w_g, var_rows)
        r = _fit_region(y, se, Abar, design.exposure_rows, offsets, foot, walls, jitter=jitter, **kw)
        return r, y, se

    def estimates(r):
        x, se_log, mask = r["x"], r["se_log"], r["mask"]
        bad_s = (mask & MU_S_BAD) > 0 or x is None
        bad_a = (mask & MU_A_BAD) > 0 or x is None
        s = np.nan if bad_s else math.exp(x[0]) / h
        a = np.nan if bad_a else math.exp(x[1]) / h
        return s, a, s * se_log[0], a * se_log[1]

    def flags_of(r):
        if r["quality"] is None:
            return FLAG_NOT_FITTED
        f = 0 if r["quality"].fits else FLAG_MISFIT
        f |= FLAG_RANGE if r.get("out_of_range") else 0
        return f | (FLAG_EDGE if r["mask"] & (2 | 4) else 0)

    def beyond_range(r, rows, cols, region):
        """Walls or a bottom closer than the range of diffusion theory at the fitted mu_s' (fit.out_of_range)."""
        return r["x"] is not None and out_of_range(
            r["x"][0], bottom_of(region), None if dist is None else dist[rows, cols]
        )

    maps = {k: np.full((H, W), np.nan, np.float32) for k in MAP_NAMES}
    maps["mask"] = np.full((H, W), 255, np.uint8)
    maps["flags"] = np.full((H, W), 255, np.uint8)
    regions, profiles = {}, {}
    for region in sorted(int(v) for v in np.unique(lab) if v != 0):
        inside = lab == region
        rows, cols = np.nonzero(inside)
        r, y, se = fit_pixels(rows, cols, region)
        r["out_of_range"] = beyond_range(r, rows, cols, region)
        s, a, se_s, se_a = estimates(r)
        blocks_s, blocks_a, blocks_flagged = [], [], []
        if b is None:
            for name, val in zip(MAP_NAMES, (s, a, se_s, se_a)):
                maps[name][inside] = val
            maps["mask"][inside] = r["mask"]
            maps["flags"][inside] = flags_of(r)
        else:
            for r0 in range(0, H, b):
                for c0 in range(0, W, b):
                    sub = np.zeros((H, W), bool)
                    sub[r0 : r0 + b, c0 : c0 + b] = inside[r0 : r0 + b, c0 : c0 + b]
                    if not sub.any():
                        continue
                    rb = fit_pixels(*np.nonzero(sub), region)[0]
                    rb["out_of_range"] = beyond_range(rb, *np.nonzero(sub), region)
                    vals = estimates(rb)
                    for name, val in zip(MAP_NAMES, vals):
                        maps[name][sub] = val
                    maps["mask"][sub] = rb["mask"]
                    maps["flags"][sub] = flags_of(rb)
                    blocks_s.append(vals[0])
                    blocks_a.append(vals[1])
                    blocks_flagged.append(bool(flags_of(rb) & (FLAG_MISFIT | FLAG_EDGE | FLAG_RANGE)))
                    if progress is not None:
                        progress(1)
        if progress is not None:
            progress(1)
        x = r["x"]
        q = r["quality"]
        regions[region] = {
            "pixels": int(inside.sum()),
            "mu_s_prime_per_mm": num_or_none(s),
            "mu_s_prime_se_per_mm": num_or_none(se_s),
            "mu_a_per_mm": num_or_none(a),
            "mu_a_se_per_mm": num_or_none(se_a),
            "not_identifiable": describe_reasons(int(r["mask"])),
            "mask": int(r["mask"]),
            "chi2_per_dof": num_or_none(r["chi2"]),
            "fit_quality": None if q is None else q.to_json(),
            "model_fits": None if q is None else q.fits,
            "flags": describe_flags(flags_of(r)),
            "flag_bits": int(flags_of(r)),
            "noise_model": "camera" if camera is not None else "spread of the pixels within each camera row",
            "depth_mm": None if bottom_of(region) is None else float(bottom_of(region)[0, 0] * h),
            "scale": num_or_none(r["c"]),
            "ambient_per_row_exposure": num_or_none(r["b"]),
            "log_estimate_per_mm": None if x is None else [float(v - math.log(h)) for v in x],
            "log_se": None if x is None else [float(v) for v in r["se_log"]],
            "log_correlation": r.get("log_correlation"),
            "g": None if r.get("g") is None else num_or_none(r["g"]),
            "g_se": None if r.get("g_se") is None else num_or_none(r["g_se"]),
            "g_source": "stated" if g is not None else "fitted (unknown)",
            "mu_s_prime_edge": _edge_side(x, lo, hi) if x is not None and r["mask"] & 2 else None,
            "blocks": len(blocks_s),
            "blocks_flagged": float(np.mean(blocks_flagged)) if blocks_flagged else None,
            "blocks_median_mu_s_prime_per_mm": _median(blocks_s),
            "blocks_median_mu_a_per_mm": _median(blocks_a),
        }
        model = r["model"] if r["model"] is not None else np.full(y.shape, np.nan)
        profiles[region] = (y, se, model)
    return TransportFit(maps, regions, profiles, design.image_index, calibrated, source="stack")


def _edge_side(x, lo, hi) -> str:
    """Which edge of the forward model a ``mu_s'`` flagged "at the edge" sits on."""
    return "lower" if x[0] - lo[0] < hi[0] - x[0] else "upper"


def _median(v):
    v = np.asarray(v, float)
    return float(np.nanmedian(v)) if v.size and np.isfinite(v).any() else None
