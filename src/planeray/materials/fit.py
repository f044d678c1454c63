"""Measuring a medium: reduced scattering ``mu_s'`` and absorption ``mu_a`` from its line kernel.

The paper recognizes materials by the shape of their delay profiles (Sec. 8); this module
*measures* them.  A pixel of a homogeneous, semi-infinite scattering medium seen from
above receives from the projector's line at offset ``u`` (projector rows) the light of
the medium's **line kernel** ``K(u; mu_s', mu_a)`` -- the demultiplexed transport
profile ``T(u)`` of that pixel (Sec. 4).  Fitting ``K`` to a measured profile gives the
two coefficients, in 1/mm.

Forward model
-------------
``K`` is :func:`planeray.kernels.forward.forward_kernel`: the project's own Monte Carlo,
tabulated (:class:`~planeray.kernels.forward.ForwardTable`, :func:`~planeray.kernels.forward.forward_table`)
and interpolated, averaged over a camera row's footprint, beyond the table's ``mu_s'`` the
diffusion dipole, and near container walls or above a layer's bottom changed by their relative
effect in diffusion theory (:mod:`planeray.kernels.walls`).  Its units, the fixed ``g`` and ``n``
and their consequences are described there.

Calibration
-----------
``K`` is an **absolute** reflectance.  A measured profile is in the camera's units; to
compare magnitudes, divide it by the capture of a white reference (a Lambertian target
of known albedo -- Spectralon, or a region of known albedo in the field -- imaged with
the same sweep: its direct light per unit albedo) before fitting, and pass
``calibrated=True``.  Without it (``calibrated=False``, the default) the fit also
estimates a free scale ``c`` and uses **only the shape**: ``mu_s'`` is still set by the
profile's width near the line, but ``mu_a`` only by how the far tail falls, so it is
less identifiable (larger standard errors; NaN where they exceed the threshold).  The
output says which was used.

Fit and uncertainties
---------------------
Weighted least squares (:func:`scipy.optimize.least_squares`, trust region) in the
log-parameters ``(log mu_s', log mu_a[, log c])``, with per-sample standard deviations
``sigma`` (the camera noise model, or the demultiplexing residual); without them the
samples are weighted equally and the covariance is scaled by the residual variance.
Standard errors come from the Jacobian at the optimum, ``(J^T J)^-1``; that they match
the spread over noise seeds is tested.

Identifiability
---------------
A parameter is **NaN, with the reason in a bit mask, not a guess**, where the data do not
constrain it (:data:`REASONS`): no usable signal, the optimum at the edge of the table,
a relative standard error above :data:`MAX_RELATIVE_SE` (a flat likelihood: e.g.
``mu_a << mu_s'`` leaves the profile's shape nearly independent of ``mu_a`` within the
sampled offsets), or a profile narrower than a bin (``mu_s'`` leaves no trace in the
shape when nearly all of the light returns within the line's own bin).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

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
from ..kernels.forward import (
    DEFAULT_G,
    DEFAULT_N,
    DIPOLE_MU_S_PRIME_MAX_PER_ROW,
    TABLE_MM_PER_ROW,
    TABLE_MU_A_PER_MM,
    TABLE_MU_S_PRIME_PER_MM,
    TABLE_PHOTONS,
    TABLE_REACH_ROWS,
    TABLE_RUNS,
    ForwardTable,
    build_forward_table,
    forward_kernel,
    forward_table,
    forward_table_seconds,
    forward_table_stored,
    kernel_per_row,
    model_kernel,
    table_kernel,
)
from ..kernels.walls import BOTTOM_ANGLE_DEG, WALL_ANGLES_DEG, WALL_KINDS, check_wall_kind

__all__ = [
    "DEFAULT_G",
    "DEFAULT_N",
    "TABLE_MM_PER_ROW",
    "TABLE_MU_S_PRIME_PER_MM",
    "TABLE_MU_A_PER_MM",
    "TABLE_REACH_ROWS",
    "TABLE_PHOTONS",
    "MAX_RELATIVE_SE",
    "DIPOLE_MU_S_PRIME_MAX_PER_ROW",
    "REASONS",
    "ForwardTable",
    "FitResult",
    "TABLE_RUNS",
    "build_forward_table",
    "forward_table",
    "forward_table_stored",
    "forward_table_seconds",
    "forward_kernel",
    "line_kernel",
    "WALL_ANGLES_DEG",
    "WALL_KINDS",
    "BOTTOM_ANGLE_DEG",
    "container_wall_distances",
    "fit_profiles",
    "describe_reasons",
    "TransportFit",
    "white_reference_scale",
    "fit_transport",
]


def line_kernel(*args, **kwargs):
    """Deprecated name of :func:`planeray.kernels.forward.forward_kernel` (the fit's forward model).

    Renamed so that it is not mistaken for :func:`planeray.kernels.line_kernel` (a scene's kernel of
    a :class:`~planeray.medium.Medium` by model name); this alias warns and will go.
    """
    import warnings

    warnings.warn(
        "planeray.materials.fit.line_kernel is now planeray.kernels.forward.forward_kernel",
        DeprecationWarning,
        stacklevel=2,
    )
    return forward_kernel(*args, **kwargs)


#: A parameter whose relative standard error exceeds this is not identifiable (NaN).
MAX_RELATIVE_SE = 0.5


#: Walls or a bottom closer than this many transport mean free paths (1 / mu_s') lie outside the range where
#: diffusion theory's method of images -- the walls' and the bottom's models -- is trusted: the fit is flagged.
DIFFUSION_RANGE_MFP = 5.0


#: Relative uncertainty of the forward model (table noise and interpolation; the forward-model
#: test allows 3 % against direct Monte Carlo), added in quadrature to the data's noise.
MODEL_RELATIVE_SD = 0.02


#: The walls' effect on the kernel (diffusion theory's method of images) is off by this share of itself: against
#: the materials scene's brute-force Monte Carlo wall tables it carries 78-99 % of their effect
#: (docs/user_guide/materials_fit.md, "Container walls").  Their distances are also uncertain by a transport mean
#: free path and the pixel's half (:func:`wall_error_columns`).
WALL_EFFECT_SD = 0.2


#: The walls' effect is also off in its **shape** over the offsets: by this share of itself in each smooth bump of
#: :func:`model_error_basis`, independently.  Measured against Mitsuba 3 renders of trays (a forward model planeray
#: did not write; six media none of the validation cases holds, mu_s' 0.4-4 /mm), the maximum-likelihood share
#: beside the other wall terms: 0.18 (95 %: 0.13-0.24; per medium 0.11-0.35, the largest where the walls take half
#: the kernel): ``tools/measure_wall_error.py`` (docs/user_guide/materials_fit.md, "Container walls").
WALL_SHAPE_SD = 0.18


#: A layer's bottom's effect (the slab's image series) is off by this share of itself: against planeray's Monte
#: Carlo of the soap's 30 mm layer (6 transport mean free paths) it removes 3.8 % of the kernel where the Monte
#: Carlo removes 2.1 %: 80 % too much, and diffusion theory errs more in thinner layers.  (Walls and a bottom
#: closer than :data:`DIFFUSION_RANGE_MFP` flag the fit.)
BOTTOM_EFFECT_SD = 1.0


#: Reasons for a NaN, as bits of the identifiability mask.
REASONS = {
    1: "no signal: too few positive samples",
    2: "mu_s' at the edge of the forward table",
    4: "mu_a at the edge of the forward table",
    8: f"mu_s' not constrained (relative standard error > {MAX_RELATIVE_SE:g})",
    16: f"mu_a not constrained (relative standard error > {MAX_RELATIVE_SE:g})",
    32: "profile narrower than a bin: shape carries no mu_s'",
    64: "fit did not converge",
}


_WALL_BINS_PER_E_FOLD = 20  # wall distances of a group pooled within 5 % (1 + d)


_WALL_PASSES = 12  # at most, of the fixed point of the walls' effect (fit_profiles)


def container_wall_distances(containers, *, rows_per_camera_row) -> np.ndarray:
    """Distance from each pixel's centre to its container's walls, down, up, right and left.

    A container is a connected run of one label; the wall lies halfway between its last
    pixel and the first pixel of another label (a pixel's resolution); where the run
    reaches the image's border there is no wall (``inf``: the medium goes on beyond the
    field of view).  Camera pixels are square, ``rows_per_camera_row`` projector rows wide.

    Parameters
    ----------
    containers : ndarray (H, W) of int
        Container labels (0: not a container).
    rows_per_camera_row : float
        Projector rows one camera row spans.

    Returns
    -------
    ndarray (H, W, 4) of float
        Projector rows to the wall below (toward positive offsets), above, right and left of
        the pixel; NaN outside the containers.
    """
    lab = np.asarray(containers)
    if lab.ndim != 2:
        raise InputError(f"containers must be a 2-D label image, got shape {lab.shape}")
    rpc = float(rows_per_camera_row)

    def forward(a):  # (N, L): pixels to the first other label after each pixel, along axis 1
        n, m = a.shape
        out = np.full(a.shape, np.inf)
        idx = np.arange(m)
        for i in range(n):
            change = np.flatnonzero(a[i, 1:] != a[i, :-1]) + 1  # first pixel of each new run
            if not change.size:
                continue
            j = np.searchsorted(change, idx, side="right")
            has = j < change.size
            out[i, has] = change[np.minimum(j, change.size - 1)][has] - idx[has]
        return (out - 0.5) * rpc

    down = forward(lab.T).T
    up = forward(lab[::-1].T).T[::-1]
    right = forward(lab)
    left = forward(lab[:, ::-1])[:, ::-1]
    d = np.stack([down, up, right, left], axis=-1)
    d[lab == 0] = np.nan
    return d


# (angle_deg, side) of the four directions of :func:`container_wall_distances`.
_WALL_DIRECTIONS = ((0.0, 1.0), (0.0, -1.0), (90.0, 1.0), (90.0, -1.0))


def group_walls(distances, per_e_fold=_WALL_BINS_PER_E_FOLD):
    """The walls of a group of pixels (their mean kernel): ``(M, 4)`` rows of :func:`fit_profiles`' ``walls``.

    Distances are pooled in bins of ``1 / per_e_fold`` in ``log(1 + d)`` (their weighted mean kept), so
    a large region costs a few dozen walls per direction, not one per pixel row or column.
    """
    d = np.asarray(distances, np.float64).reshape(-1, 4)
    n = d.shape[0]
    rows = []
    for k, (ang, side) in enumerate(_WALL_DIRECTIONS):
        v = d[:, k][np.isfinite(d[:, k])]
        if v.size:
            key, inv = np.unique(np.round(np.log1p(v) * per_e_fold), return_inverse=True)
            cnt = np.bincount(inv, minlength=key.size)
            mean = np.bincount(inv, weights=v, minlength=key.size) / cnt
            rows.append(np.stack([mean, np.full(key.size, ang), np.full(key.size, side), cnt / n], axis=1))
    return np.concatenate(rows) if rows else np.zeros((0, 4))


def model_error_basis(offsets):
    """Smooth bumps over ``log(1 + |u|)`` (``(U, J)``): the shapes of the forward model's correlated error."""
    x = np.log1p(np.abs(np.asarray(offsets, np.float64)))
    centres = np.log1p(np.array([0.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0]))
    width = 0.5 * float(np.mean(np.diff(centres)))
    return np.exp(-0.5 * ((x[:, None] - centres[None, :]) / width) ** 2)


def _wall_effects(table, x, offsets, foot, walls, wall_kind):
    """The walls' and the bottom's parts of ``walls`` (``(rows, is_bottom)``) and the wall-free kernel at ``x``."""
    w = np.asarray(walls, np.float64)
    is_bottom = w[:, 1] == BOTTOM_ANGLE_DEG
    parts = [(w[m], b) for m, b in ((~is_bottom, False), (is_bottom, True)) if m.any()]
    return parts, model_kernel(table, x[0], x[1], offsets, foot, None, wall_kind)


def wall_error_columns(table, x, offsets, foot, walls, wall_kind, *, effect_sd, bottom_sd):
    """The walls' and the bottom's model error in the fit's weights: columns ``(U, K)``, their outer product its covariance.

    Diffusion theory's walls and bottom (:mod:`planeray.kernels.walls`) are uncertain: each part's effect
    (``K_walls - K``) off by ``effect_sd`` (walls) or ``bottom_sd`` (bottom) of itself, and its distances off by a
    transport mean free path (diffusion theory's boundaries are uncertain by about one, Haskell et al. 1994) --
    for walls also by the pixel's half (their positions come from the labels).  ``x`` holds the per-row
    log-coefficients ``(log mu_s' h, log mu_a h, ...)``.  None when there is nothing uncertain.  The walls'
    *shape* error is apart (:func:`wall_shape_columns`): it widens the standard errors, not the weights.
    """
    if walls is None or not len(walls) or (effect_sd <= 0 and bottom_sd <= 0):
        return None
    parts, free = _wall_effects(table, x, offsets, foot, walls, wall_kind)
    foot_rows = float(np.ptp(foot[0]) + 1) if foot[0].size > 1 else 1.0  # a camera row's extent, projector rows
    mfp_rows = 1.0 / math.exp(x[0])  # 1 / mu_s' in rows
    cols = []
    for ww, bottom in parts:
        sd = bottom_sd if bottom else effect_sd
        if sd <= 0:
            continue
        cols.append(sd * (model_kernel(table, x[0], x[1], offsets, foot, ww, wall_kind) - free))
        shift = mfp_rows if bottom else math.hypot(mfp_rows, 0.5 * foot_rows)
        hi, lo = ww.copy(), ww.copy()
        hi[:, 0] += shift
        lo[:, 0] = np.maximum(lo[:, 0] - shift, 0.0)
        k_hi = model_kernel(table, x[0], x[1], offsets, foot, hi, wall_kind)
        k_lo = model_kernel(table, x[0], x[1], offsets, foot, lo, wall_kind)
        cols.append(0.5 * (k_hi - k_lo))
    return np.stack(cols, axis=1)


def wall_shape_columns(table, x, offsets, foot, walls, wall_kind, *, shape_sd, basis):
    """The walls' effect off in its shape over the offsets: ``shape_sd`` of it in each bump of ``basis``
    (:func:`model_error_basis`), columns ``(U, J)``; None without walls.

    Measured against Mitsuba 3 as a spread over media (:data:`WALL_SHAPE_SD`), not as one fit's error
    covariance: the fits put it in their standard errors (:func:`sandwich_covariance`), not in their weights --
    weighted by it, a medium whose wall effect dominates its kernel moved to another optimum (fat-free milk's
    ``mu_s'`` -26 % at 3.4 standard errors in the 64-pixel tray capture), and a misfit it describes is no
    excuse: the chi-square keeps to the weights' covariance.
    """
    if walls is None or not len(walls) or shape_sd <= 0:
        return None
    parts, free = _wall_effects(table, x, offsets, foot, walls, wall_kind)
    walls_only = [ww for ww, bottom in parts if not bottom]
    if not walls_only:
        return None
    effect = model_kernel(table, x[0], x[1], offsets, foot, walls_only[0], wall_kind) - free
    return shape_sd * effect[:, None] * basis


def sandwich_covariance(J, S_white):
    """The estimates' covariance ``(J^T J)^-1 + B B^T``, ``B = (J^T J)^-1 J^T S``: a least-squares fit whose weights
    leave out errors with the (whitened) columns ``S_white`` (None: ``(J^T J)^-1``; ``J`` the whitened Jacobian)."""
    inv = np.linalg.pinv(J.T @ J)
    if S_white is None:
        return inv
    B = inv @ (J.T @ S_white)
    return inv + B @ B.T


#: A second optimum is looked for from the best grid start at least this far (in ``(log mu_s', log mu_a)``) from
#: the fit's estimate: a factor e in one coefficient.
SECOND_START_LOG_DISTANCE = 1.0


def second_start(starts, costs, x, min_distance=SECOND_START_LOG_DISTANCE):
    """Index of the least-cost grid start (``starts`` ``(G, 2)`` log-coefficients, ``costs`` ``(G,)``) farther than
    ``min_distance`` from the estimate ``x`` in ``(log mu_s', log mu_a)``; None when there is none."""
    d = np.hypot(starts[:, 0] - x[0], starts[:, 1] - x[1])
    far = np.flatnonzero(d > min_distance)
    return None if far.size == 0 else int(far[np.argmin(np.asarray(costs)[far])])


def second_optimum(res, starts, costs, start_of, solve):
    """The fit ``res`` against a second one from the best grid start far from it (:func:`second_start`):
    ``(estimate, other)``, the better (lower cost) first; ``other`` None when no start lies far enough or its
    fit fails.  ``start_of(i)`` is the full parameter vector of grid start ``i``, ``solve(x0)`` the fit's
    least-squares run with the same weights."""
    i = second_start(starts, costs, res.x)
    if i is None:
        return res, None
    try:
        alt = solve(start_of(i))
    except (ValueError, np.linalg.LinAlgError):
        return res, None
    if alt.success and alt.cost < res.cost:
        return alt, res
    return res, alt


def widen_for_second_optimum(se_log, x, chi2, x_alt, chi2_alt, inflation):
    """Standard errors that also cover a second optimum nearly as good: where the chi-squares differ by less than
    ``4 inflation^2`` (two standard errors), each of ``(log mu_s', log mu_a)``'s is at least half its distance to
    the other optimum (a bimodal likelihood reported as one wide interval; beyond
    :data:`MAX_RELATIVE_SE` the parameter is not identifiable).  The local curvature alone says nothing of it: a
    medium whose walls take most of its light had its ``mu_a`` 5x off at 0.1 standard errors in log."""
    se = np.array(se_log, np.float64)
    if x_alt is None or not abs(chi2_alt - chi2) < 4.0 * inflation**2:
        return se
    return np.maximum(se, 0.5 * np.abs(np.asarray(x_alt[:2]) - np.asarray(x[:2])))


def _whitener(sd, ok, E=None, c=1.0):
    """Whitened residuals of the samples ``ok``: ``v / sd``, or ``L v`` with ``L L^T`` the inverse of
    ``diag(sd^2) + (c E)(c E)^T`` (the walls' model error, :func:`wall_error_columns`; None: none)."""
    if E is None:
        return lambda v: np.where(ok, v / sd, 0.0)
    Eok = c * E[ok]
    L = np.linalg.inv(np.linalg.cholesky(np.diag(sd[ok] ** 2) + Eok @ Eok.T))
    return lambda v: L @ v[ok]


@dataclass(frozen=True)
class FitResult:
    """Fitted coefficients of a set of profiles (one per pixel or region).

    Attributes
    ----------
    mu_s_prime_per_mm, mu_a_per_mm : ndarray (P,)
        Estimates, mm^-1; NaN where not identifiable (see ``mask``).
    mu_s_prime_se_per_mm, mu_a_se_per_mm : ndarray (P,)
        Standard errors, mm^-1 (NaN with the estimate).
    scale : ndarray (P,)
        Fitted calibration scale ``c`` (1 when ``calibrated``).
    mask : ndarray (P,) uint8
        Bits of :data:`REASONS`; 0 = both parameters identified.
    chi2_per_dof : ndarray (P,)
        Reduced chi-square at the optimum (``sigma`` given) or the residual variance (not given).
    model : ndarray (P, U)
        The fitted kernels ``c K`` (for plots).
    calibrated : bool
        Whether the magnitude was used (absolute reflectance) or only the shape.
    log_estimate_per_mm, log_se : ndarray (P, 2) or None
        ``ln mu_s'``, ``ln mu_a`` (mm^-1) at the optimum and their standard errors, *before*
        the identifiability NaNs (NaN only where no fit ran): for recognition, which weighs
        a poorly constrained estimate by its error (:mod:`planeray.materials.library`).
    dof : ndarray (P,) of int or None
        Degrees of freedom of each fit (samples minus parameters; 0 where no fit ran).
    flags : ndarray (P,) uint8 or None
        Bits of :data:`planeray.goodness.FLAGS`: the model does not fit (chi-square past the
        threshold at ``dof``; the standard errors are then inflated by ``sqrt(chi2 / dof)``), a
        parameter at the forward model's edge, not fitted.
    g, g_se : ndarray (P,) or None
        The media's anisotropy: fitted (unknown ``g``) with its standard error, or the stated one (``g_se`` NaN).
    """

    mu_s_prime_per_mm: np.ndarray
    mu_a_per_mm: np.ndarray
    mu_s_prime_se_per_mm: np.ndarray
    mu_a_se_per_mm: np.ndarray
    scale: np.ndarray
    mask: np.ndarray
    chi2_per_dof: np.ndarray
    model: np.ndarray
    calibrated: bool
    log_estimate_per_mm: np.ndarray | None = None
    log_se: np.ndarray | None = None
    dof: np.ndarray | None = None
    flags: np.ndarray | None = None
    g: np.ndarray | None = None
    g_se: np.ndarray | None = None

    def quality(self, i: int = 0):
        """:class:`planeray.goodness.FitQuality` of profile ``i`` (None where no fit ran)."""
        if self.dof is None or not np.isfinite(self.chi2_per_dof[i]) or self.dof[i] <= 0:
            return None
        return fit_quality(self.chi2_per_dof[i] * self.dof[i], int(self.dof[i]))


def _cell_rel(table_rel, gs, ga, log_s, log_a):
    """Largest table relative error per offset over the grid cell that holds ``(log_s, log_a)``."""
    i = int(np.clip(np.searchsorted(gs, log_s) - 1, 0, gs.size - 2))
    j = int(np.clip(np.searchsorted(ga, log_a) - 1, 0, ga.size - 2))
    return table_rel[i : i + 2, j : j + 2].max(axis=(0, 1))


def _forward_jac(resid, step=1e-4, upper=None):
    """Forward-difference Jacobian with an absolute step in the log-parameters (scipy's relative step
    is 0 at a parameter that is exactly 0, e.g. ``log c`` of a perfectly calibrated profile); a backward step
    where the forward one would pass ``upper`` (a bounded parameter at its end)."""

    def jac(x, *args):
        r0 = resid(x)
        cols = []
        for i in range(len(x)):
            xi = np.array(x, float)
            h = -step if upper is not None and xi[i] + step > upper[i] else step
            xi[i] += h
            cols.append((resid(xi) - r0) / h)
        return np.stack(cols, axis=1)

    return jac


def describe_reasons(bits: int) -> list[str]:
    """The reasons (:data:`REASONS`) set in a mask value."""
    return [text for bit, text in REASONS.items() if int(bits) & bit]


#: Mask bits that leave ``mu_s'`` / ``mu_a`` without an estimate (a ``mu_a`` beside a ``mu_s'`` stuck at the edge is none).
MU_S_BAD = 1 | 2 | 8 | 32 | 64


MU_A_BAD = 1 | 2 | 4 | 16 | 64


def log_bounds(table: ForwardTable):
    """``(lo, hi)``: the fit's bounds in per-row ``(log mu_s', log mu_a)``, the dipole beyond the table's ``mu_s'``."""
    (s0, s1), (a0, a1) = table.bounds_per_row
    s1 = max(s1, DIPOLE_MU_S_PRIME_MAX_PER_ROW)
    return np.array([math.log(s0), math.log(a0)]), np.array([math.log(s1), math.log(a1)])


def grid_starts(table: ForwardTable, offsets, foot):
    """The table's grid points ``(G, 2)`` in per-row log-coefficients and their kernels ``(G, U)``: the coarse start."""
    GS, GA = np.meshgrid(np.log(table.mu_s_prime_per_row), np.log(table.mu_a_per_row), indexing="ij")
    starts = np.stack([GS.ravel(), GA.ravel()], axis=1)
    return starts, kernel_per_row(table, starts[:, 0], starts[:, 1], offsets, foot)


def bottom_row(depth_mm, region, mm_per_row):
    """A region's bottom as a ``walls`` row (``depth_mm``: one value or ``{region: depth}``), None: semi-infinite."""
    v = depth_mm.get(region) if isinstance(depth_mm, dict) else depth_mm
    if v is None or not np.isfinite(float(v)):
        return None
    if not float(v) > 0:
        raise InputError(f"depth_mm must be positive, got {v!r}")
    return np.array([[float(v) / float(mm_per_row), BOTTOM_ANGLE_DEG, 0.0, 1.0]])


def out_of_range(log_s_per_row, bottom, distances) -> bool:
    """Whether a fit's walls or bottom lie within :data:`DIFFUSION_RANGE_MFP` transport mean free paths.

    ``log_s_per_row``: the fitted ``log(mu_s' h)``; ``bottom``: :func:`bottom_row` (rows) or None; ``distances``:
    the region's pixels' wall distances (:func:`container_wall_distances`, rows) or None -- the median pixel's
    nearest wall counts.
    """
    if not np.isfinite(log_s_per_row):
        return False
    reach = DIFFUSION_RANGE_MFP / math.exp(float(log_s_per_row))  # rows
    if bottom is not None and bottom[0, 0] < reach:
        return True
    if distances is not None and len(distances):
        d = np.asarray(distances, np.float64).reshape(-1, 4)
        nearest = np.min(np.where(np.isfinite(d), d, np.inf), axis=1)
        return bool(np.median(nearest) < reach)
    return False


def regions_and_walls(labels, containers, shape, rows_per_camera_row, what):
    """The region labels (default one region) and each pixel's wall distances (None without ``containers``)."""
    lab = np.ones(shape, np.int64) if labels is None else np.asarray(labels, np.int64)
    if lab.shape != tuple(shape):
        raise InputError(f"labels have shape {lab.shape}, the {what} {tuple(shape)}")
    if containers is None:
        return lab, None
    if np.shape(containers) != tuple(shape):
        raise InputError(f"containers have shape {np.shape(containers)}, the {what} {tuple(shape)}")
    return lab, container_wall_distances(containers, rows_per_camera_row=rows_per_camera_row)


def fit_profiles(
    profiles,
    *,
    offsets_rows,
    mm_per_row,
    sigma=None,
    calibrated=False,
    rows_per_camera_row=1.0,
    table: ForwardTable | None = None,
    max_relative_se=MAX_RELATIVE_SE,
    model_relative_sd=MODEL_RELATIVE_SD,
    walls=None,
    wall_kind: str = "clear",
    p_misfit=DEFAULT_P_MISFIT,
    g=None,
    wall_effect_sd=WALL_EFFECT_SD,
    bottom_effect_sd=BOTTOM_EFFECT_SD,
    wall_shape_sd=WALL_SHAPE_SD,
) -> FitResult:
    """Fit ``mu_s'`` and ``mu_a`` to line-kernel profiles (weighted least squares in log-parameters).

    Parameters
    ----------
    profiles : array_like (P, U) or (U,)
        Transport profiles ``T(u)`` (demultiplexed, or a region's mean), in reflectance per
        offset bin when ``calibrated`` (divided by a white reference), else any unit.
    offsets_rows : array_like of int (U,)
        Their offsets, projector rows.
    mm_per_row : float
        Size of one projector row on the surface, mm.
    sigma : array_like, optional
        Standard deviation of every sample (broadcast to ``profiles``), same unit.  Without
        it the samples weigh equally and the errors come from the residual spread.
    calibrated : bool
        Use the magnitude (``c = 1``); otherwise fit a free scale and use the shape only.
    rows_per_camera_row : float
        Projector rows a camera row spans.
    table : ForwardTable, optional
        Default :func:`forward_table`.
    max_relative_se : float
        A parameter with a larger relative standard error is NaN (reason in ``mask``).
    model_relative_sd : float
        Relative uncertainty of the forward model's interpolation; with the table's own Monte
        Carlo relative error per offset (at the start grid point) it is added in quadrature to
        ``sigma`` (as a share of the data): without it, precise samples would fit the table's
        own errors.  Only with ``sigma``; 0 leaves the model's error out (data made by the
        table itself).
    walls : sequence of (ndarray (M, 4) or None), optional
        Per profile, the container walls its pixels see (:func:`container_wall_distances`): rows of
        ``[distance_rows, angle_deg, side, weight]`` -- a clear wall (air behind it) at
        ``distance_rows`` projector rows from a pixel, parallel (``angle_deg`` 0; ``side`` +1
        toward positive offsets, -1 negative) or perpendicular (90) to the lit lines, weighing
        ``weight`` (the share of the profile's pixels that see it).  The model is then the
        table's kernel times the walls' relative effect from diffusion theory (method of
        images; :func:`forward_kernel` with ``walls``); a row of angle :data:`BOTTOM_ANGLE_DEG` is
        the bottom of a layer ``distance_rows`` deep (weight 1).  None: a semi-infinite medium
        without walls.
    wall_kind : {"clear", "black"}
        The walls' kind (:data:`WALL_KINDS`).
    p_misfit : float
        A fit whose chi-square is less probable than this is flagged "model does not fit"
        (:func:`planeray.goodness.fit_quality`).
    g : float, optional
        The media's Henyey-Greenstein anisotropy (the table's is :data:`DEFAULT_G`; another changes the kernel by
        :func:`planeray.kernels.anisotropy.g_kernel_change`).  None: unknown -- a third parameter, fitted within
        :data:`planeray.kernels.anisotropy.G_PRIOR`, its uncertainty carried into the others' standard errors.
    wall_effect_sd, bottom_effect_sd, wall_shape_sd : float
        The walls' and the bottom's model error (:data:`WALL_EFFECT_SD`, :data:`BOTTOM_EFFECT_SD`,
        :data:`WALL_SHAPE_SD`; 0: taken as exact).  With ``sigma`` and walls, the first two join the data's
        covariance (:func:`wall_error_columns`: correlated over the offsets; residuals whitened by it, held at each
        pass's estimate); the walls' shape error widens the standard errors (:func:`wall_shape_columns`,
        :func:`sandwich_covariance`).

    Returns
    -------
    FitResult
        Standard errors from the Jacobian, scaled by ``sqrt(chi2 / dof)`` where that exceeds 1 (the
        misfit inflates them; the model's own error is in ``sigma`` through ``model_relative_sd``, the walls'
        through ``wall_effect_sd``, ``bottom_effect_sd`` and ``wall_shape_sd``).
    """
    table = table or forward_table()
    check_wall_kind(wall_kind)
    g = check_g(g)
    fit_g = g is None
    g_table = anisotropy_table() if fit_g or g != DEFAULT_G else None
    Y = np.atleast_2d(np.asarray(profiles, np.float64))
    if walls is not None and len(walls) != Y.shape[0]:
        raise InputError(f"walls has {len(walls)} entries, one per profile expected ({Y.shape[0]})")
    offsets = np.asarray(offsets_rows)
    if offsets.ndim != 1 or offsets.size != Y.shape[1]:
        raise InputError(f"offsets_rows has {offsets.size} values, the profiles {Y.shape[1]} samples")
    if not float(mm_per_row) > 0:
        raise InputError(f"mm_per_row must be positive, got {mm_per_row!r}")
    S = np.ones_like(Y) if sigma is None else np.broadcast_to(np.asarray(sigma, np.float64), Y.shape)
    if np.any(~(S > 0)):
        raise InputError("sigma must be positive everywhere")
    # The table's own relative Monte Carlo error per offset (added to sigma at the start grid point).
    with np.errstate(divide="ignore", invalid="ignore"):
        table_rel = np.clip(np.nan_to_num(table.kernel_stderr / table.kernel, nan=1.0, posinf=1.0), 0.0, 1.0)
    u_tab = np.minimum(np.abs(offsets).astype(np.int64), table.offsets_rows[-1])
    h = float(mm_per_row)
    foot = camera_row_footprint(rows_per_camera_row)
    lo, hi = log_bounds(table)
    P = Y.shape[0]
    out = {k: np.full(P, np.nan) for k in ("s", "a", "se_s", "se_a", "chi2")}
    scale = np.ones(P)
    mask = np.zeros(P, np.uint8)
    model = np.full(Y.shape, np.nan)
    raw, raw_se = np.full((P, 2), np.nan), np.full((P, 2), np.nan)
    dofs = np.zeros(P, np.int64)
    g_est = np.full(P, np.nan if fit_g else float(g))
    g_se = np.full(P, np.nan)

    def with_anisotropy(k, x, k_row):
        """The kernel ``k`` at the log-parameters ``x`` (:func:`table_kernel` ``k_row``) changed to the media's
        anisotropy (``x[-1]`` when fitted)."""
        return kernel_at_g(k, k_row, x[0], x[1], table.n, x[-1] if fit_g else g, offsets, foot, table=g_table)

    def walls_kernel(x, wp):
        """The kernel with the walls ``wp`` (None: none) and the media's anisotropy, at the log-parameters ``x``."""
        k_row = table_kernel(table, x[0], x[1])
        return with_anisotropy(model_kernel(table, x[0], x[1], offsets, foot, wp, wall_kind, k=k_row), x, k_row)

    # A coarse start: the grid point of least misfit (shape only, scale solved in closed form).
    gs, ga = np.log(table.mu_s_prime_per_row), np.log(table.mu_a_per_row)
    starts, Kg = grid_starts(table, offsets, foot)
    basis = model_error_basis(offsets)
    edge_tol = 0.02
    for p in range(P):
        y, sd = Y[p], S[p]
        wp = None if walls is None or walls[p] is None or not len(walls[p]) else np.asarray(walls[p], np.float64)
        ok = np.isfinite(y)
        if np.count_nonzero(ok & (y > 0)) < 4:
            mask[p] |= 1
            continue
        wy = np.where(ok, y / sd, 0.0)
        rho_g, tried = 1.0, set()
        for _ in range(4 if wp is not None else 1):
            # With walls: the grid kernels times the walls' effect at the best point so far, until it stays.
            wK = np.where(ok, Kg * rho_g / sd, 0.0)
            if calibrated:
                c_g = np.ones(len(Kg))
            else:
                c_g = np.maximum((wK @ wy) / np.maximum((wK * wK).sum(axis=1), 1e-300), 1e-300)
            cost_g = ((wy[None, :] - c_g[:, None] * wK) ** 2).sum(axis=1)
            g0 = int(np.argmin(cost_g))
            if wp is None or g0 in tried:
                break
            tried.add(g0)
            k_free = Kg[g0]
            k_wall = model_kernel(table, starts[g0, 0], starts[g0, 1], offsets, foot, wp, wall_kind)
            rho_g = np.where(k_free > 0, k_wall / np.where(k_free > 0, k_free, 1.0), 0.0)
        sd0 = sd
        x0 = list(starts[g0])
        lo_p, hi_p = list(lo), list(hi)
        if not calibrated:
            x0.append(math.log(c_g[g0]))
            lo_p.append(-np.inf)
            hi_p.append(np.inf)
        if fit_g:  # the anisotropy, last, from the table's
            x0.append(DEFAULT_G)
            lo_p.append(G_PRIOR[0])
            hi_p.append(G_PRIOR[1])
        x0 = np.clip(x0, np.array(lo_p) + 1e-9, np.array(hi_p) - 1e-9)
        # Two passes when sigma is given: the model's own error (the table's Monte Carlo error per
        # offset, largest of the grid cell around the estimate, plus the interpolation share) joins
        # the data's; first that of the start's cell, then of the first estimate's.
        # With walls, their relative effect (diffusion theory, costly) is evaluated at the current
        # estimate and held during a pass, until the estimate stops moving (a fixed point, exact for
        # data the model describes).
        model_error = sigma is not None and model_relative_sd > 0
        passes = _WALL_PASSES if wp is not None else 2 if model_error else 1
        try:
            for i_pass in range(passes):
                x_prev = np.array(x0, float)
                if model_error:
                    rel = float(model_relative_sd) + _cell_rel(table_rel, gs, ga, x0[0], x0[1])[u_tab]
                    sd = np.hypot(sd0, rel * np.nan_to_num(np.abs(y)))
                rho = 1.0
                if wp is not None:
                    k_free = kernel_per_row(table, x0[0], x0[1], offsets, foot)
                    k_wall = model_kernel(table, x0[0], x0[1], offsets, foot, wp, wall_kind)
                    rho = np.where(k_free > 0, k_wall / np.where(k_free > 0, k_free, 1.0), 0.0)
                c0 = 1.0 if calibrated else math.exp(x0[2])
                E = None
                if model_error and wp is not None:
                    E = wall_error_columns(table, x0, offsets, foot, wp, wall_kind, effect_sd=wall_effect_sd,
                                           bottom_sd=bottom_effect_sd)  # fmt: skip
                white = _whitener(sd, ok, E, c0)

                def resid(x, y=y, white=white, rho=rho):
                    k_row = table_kernel(table, x[0], x[1])
                    k = with_anisotropy(kernel_per_row(table, x[0], x[1], offsets, foot, k=k_row) * rho, x, k_row)
                    c = 1.0 if calibrated else math.exp(x[2])
                    return white(c * k - y)

                res = least_squares(
                    resid, x0, jac=_forward_jac(resid, upper=hi_p), bounds=(lo_p, hi_p), method="trf", x_scale=1.0
                )
                x0 = np.clip(res.x, np.array(lo_p) + 1e-9, np.array(hi_p) - 1e-9)
                if wp is not None and i_pass >= 1 and np.max(np.abs(x0[:2] - x_prev[:2])) < 1e-3:
                    break
            if wp is not None:  # polish with the walls' effect evaluated at every trial (the exact Jacobian)

                def resid(x, y=y, white=white, wp=wp):
                    k = walls_kernel(x, wp)
                    c = 1.0 if calibrated else math.exp(x[2])
                    return white(c * k - y)

                res = least_squares(
                    resid, x0, jac=_forward_jac(resid, upper=hi_p), bounds=(lo_p, hi_p), method="trf", x_scale=1.0
                )
        except (ValueError, np.linalg.LinAlgError):
            mask[p] |= 64
            continue

        # a second optimum, from the best grid start far from the estimate, with the same weights: the better
        # one is the estimate, and one nearly as good widens the standard errors (widen_for_second_optimum)
        def start_of(i, c_g=c_g, lo_p=lo_p, hi_p=hi_p):
            x = [*starts[i], *([] if calibrated else [math.log(c_g[i])]), *([DEFAULT_G] if fit_g else [])]
            return np.clip(x, np.array(lo_p) + 1e-9, np.array(hi_p) - 1e-9)

        def solve(xa, resid=resid, lo_p=lo_p, hi_p=hi_p):
            return least_squares(
                resid, xa, jac=_forward_jac(resid, upper=hi_p), bounds=(lo_p, hi_p), method="trf", x_scale=1.0
            )

        res, res_alt = second_optimum(res, starts, cost_g, start_of, solve)
        if not res.success:
            mask[p] |= 64
        n_dof = max(int(ok.sum()) - len(x0), 1)
        dofs[p] = n_dof
        chi2 = float(2.0 * res.cost / n_dof)
        J = res.jac
        shape = None
        if model_error and wp is not None:  # the walls' shape error: in the standard errors, not the weights
            shape = wall_shape_columns(table, res.x, offsets, foot, wp, wall_kind, shape_sd=wall_shape_sd, basis=basis)
        c_fit = 1.0 if calibrated else math.exp(res.x[2])
        try:
            cov = sandwich_covariance(J, None if shape is None else np.stack([white(c_fit * v) for v in shape.T], 1))
        except np.linalg.LinAlgError:
            cov = np.full((len(x0), len(x0)), np.inf)
        # without sigma the residual variance is the noise; with it, a misfit beyond the noise (and the model's
        # error in it) widens the errors by sqrt(chi2 / dof) (planeray.goodness, the Birge ratio)
        infl2 = chi2 if sigma is None else max(chi2, 1.0)
        cov = cov * infl2
        se_log = np.sqrt(np.maximum(np.diag(cov), 0.0))
        if res_alt is not None and res_alt.success:
            se_log[:2] = widen_for_second_optimum(
                se_log[:2], res.x, 2.0 * res.cost, res_alt.x, 2.0 * res_alt.cost, math.sqrt(infl2)
            )
        x = res.x
        s_est, a_est = math.exp(x[0]) / h, math.exp(x[1]) / h
        out["s"][p], out["a"][p] = s_est, a_est
        out["se_s"][p], out["se_a"][p] = s_est * se_log[0], a_est * se_log[1]
        out["chi2"][p] = chi2
        raw[p], raw_se[p] = x[:2] - math.log(h), se_log[:2]
        scale[p] = 1.0 if calibrated else math.exp(x[2])
        model[p] = scale[p] * walls_kernel(x, wp)
        if fit_g:
            g_est[p], g_se[p] = x[-1], se_log[-1]
        if min(x[0] - lo[0], hi[0] - x[0]) < edge_tol:
            mask[p] |= 2
        if min(x[1] - lo[1], hi[1] - x[1]) < edge_tol:
            mask[p] |= 4
        if not se_log[0] <= max_relative_se:
            mask[p] |= 8
        if not se_log[1] <= max_relative_se:
            mask[p] |= 16
        k0 = kernel_per_row(table, x[0], x[1], np.array([0, 1]), camera_row_footprint(1.0))
        if k0[1] < 0.05 * k0[0] and float(rows_per_camera_row) <= 1.0 + 1e-12:
            mask[p] |= 32
    bad_s = (mask & MU_S_BAD) > 0
    bad_a = (mask & MU_A_BAD) > 0
    for k in ("s", "se_s"):
        out[k][bad_s] = np.nan
    for k in ("a", "se_a"):
        out[k][bad_a] = np.nan
    flags = np.zeros(P, np.uint8)
    for p in range(P):
        if dofs[p] == 0:
            flags[p] = FLAG_NOT_FITTED
            continue
        if sigma is not None and not fit_quality(out["chi2"][p] * dofs[p], dofs[p], p_misfit=p_misfit).fits:
            flags[p] |= FLAG_MISFIT
        if mask[p] & (2 | 4):
            flags[p] |= FLAG_EDGE
    return FitResult(
        mu_s_prime_per_mm=out["s"],
        mu_a_per_mm=out["a"],
        mu_s_prime_se_per_mm=out["se_s"],
        mu_a_se_per_mm=out["se_a"],
        scale=scale,
        mask=mask,
        chi2_per_dof=out["chi2"],
        model=model,
        calibrated=bool(calibrated),
        log_estimate_per_mm=raw,
        log_se=raw_se,
        dof=dofs,
        flags=flags,
        g=g_est,
        g_se=g_se,
    )


@dataclass(frozen=True)
class TransportFit:
    """Maps and per-region results of :func:`fit_transport`.

    Attributes
    ----------
    maps : dict of str -> ndarray (H, W)
        ``mu_s_prime_per_mm``, ``mu_a_per_mm``, ``mu_s_prime_se_per_mm``, ``mu_a_se_per_mm``
        (float32, NaN where not fitted or not identifiable) and ``mask`` (uint8, the bits of
        :data:`REASONS`; 255: not fitted -- outside every region or no pixel block).
    regions : dict of int -> dict
        Per label: pixels, the fit of the region's mean profile (estimates, standard errors,
        reasons) and the median of the block estimates.
    profiles : dict of int -> (data, sigma, model)
        The regions' mean profiles, their standard errors and the fitted kernels (for figures).
    offsets_rows : ndarray
        The profiles' offsets (projector rows); for a stack fit the used images' indices.
    calibrated : bool
    source : str
        ``"transport"`` (:func:`fit_transport`: ``profiles`` are transport profiles over offsets) or
        ``"stack"`` (:func:`planeray.materials.stackfit.fit_stack`: the regions' mean stack images).
    """

    maps: dict
    regions: dict
    profiles: dict
    offsets_rows: np.ndarray
    calibrated: bool
    source: str = "transport"


def white_reference_scale(white_dense, *, albedo=1.0):
    """Per-pixel calibration from the transport of a white Lambertian reference of known ``albedo``.

    A Lambertian surface of albedo ``rho`` returns ``rho`` summed over the offsets (the
    scenes' unit); dividing a profile by ``sum_u T_white(u) / rho`` of the same pixel puts it
    in Lambertian-equivalent reflectance per offset, the unit of :func:`forward_kernel`.

    Parameters
    ----------
    white_dense : ndarray (H, W, U)
        Transport of the reference, same sweep and camera settings.
    albedo : float
        Its albedo in (0, 1].

    Returns
    -------
    ndarray (H, W)
        The divisor (NaN where the reference is dark).
    """
    if not 0.0 < float(albedo) <= 1.0:
        raise InputError(f"the white reference's albedo must be in (0, 1], got {albedo!r}")
    total = np.asarray(white_dense, np.float64).sum(axis=-1) / float(albedo)
    return np.where(total > 0, total, np.nan)


def fit_transport(
    transport,
    *,
    mm_per_row,
    labels=None,
    white_scale=None,
    block_px=4,
    containers=None,
    table: ForwardTable | None = None,
    depth_mm=None,
    regions_only: bool = False,
    wall_kind: str = "clear",
    p_misfit=DEFAULT_P_MISFIT,
    g=None,
    progress=None,
) -> TransportFit:
    """Fit ``mu_s'`` and ``mu_a`` over a transport: maps (per pixel block) and per-region results.

    Parameters
    ----------
    transport : Transport
        Demultiplexed (or ground-truth) transport.
    mm_per_row : float
        Size of one projector row on the surface, mm.
    labels : ndarray (H, W) of int, optional
        Regions (0: left out).  Default: every pixel one region (1).
    white_scale : ndarray (H, W), optional
        :func:`white_reference_scale`: given, the fit is calibrated (absolute reflectance);
        otherwise shape only.
    block_px : int
        Pixels are averaged in ``block_px x block_px`` blocks (within a region) before
        fitting; the block's estimate fills its pixels.  1: every pixel.
    containers : ndarray (H, W) of int, optional
        The containers (labels; often ``labels`` itself): given, each container's boundary is
        a clear wall (air behind it; the image's border is none) and every block's and
        region's model is the mean kernel of its pixels with their walls
        (:func:`container_wall_distances`, :func:`fit_profiles`' ``walls``).  Without it the
        media are unbounded, and pixels near walls read the light lost through them as
        absorption.
    table : ForwardTable, optional
    depth_mm : float or dict, optional
        Depth (mm) of a layer whose bottom loses the light (``walls`` row of angle
        :data:`BOTTOM_ANGLE_DEG`): one value for every region, or ``{region: depth_mm}``;
        default every medium semi-infinite.
    regions_only : bool
        Fit the regions only (the maps stay NaN, mask 255): the blocks still give each
        region's noise, but are not fitted themselves (with walls, most of the time).
    wall_kind : {"clear", "black"}
        The containers' walls (:data:`WALL_KINDS`).
    p_misfit : float
        Chi-square probability below which a fit is flagged "model does not fit" (:mod:`planeray.goodness`).
    g : float, optional
        The media's anisotropy; None: unknown, fitted as a nuisance parameter (:func:`fit_profiles`).
    progress : callable, optional
        Called with the number of fits just done.

    Returns
    -------
    TransportFit
        ``maps["flags"]`` is the flag layer (bits of :data:`planeray.goodness.FLAGS`, 255 outside every
        region); each region's summary carries its ``fit_quality``, ``flags`` and ``model_fits``.

    Notes
    -----
    Samples whose transport is 0 (a line that misses the container, beyond the band) carry no
    information and are left out.  A block's noise is taken from the spread of its pixels
    (standard error of the mean, floored at 1 % of the block's peak); a region's from the
    spread of its blocks.
    """
    table = table or forward_table()
    dense = np.asarray(transport.dense, np.float64)
    H, W, U = dense.shape
    offsets = np.asarray(transport.offsets_rows)
    rpc = transport.geometry.rows_per_camera_row
    calibrated = white_scale is not None
    if calibrated:
        dense = dense / np.asarray(white_scale, np.float64)[..., None]
    lab, dist = regions_and_walls(labels, containers, (H, W), rpc, "transport")
    b = int(block_px)
    if b < 1:
        raise InputError(f"block_px must be >= 1, got {block_px!r}")

    def depth_of(region):
        return bottom_row(depth_mm, region, mm_per_row)

    def with_bottom(walls, bottom):
        if bottom is None:
            return walls
        return bottom if walls is None else np.concatenate([np.asarray(walls, np.float64).reshape(-1, 4), bottom])

    maps = {k: np.full((H, W), np.nan, np.float32) for k in MAP_NAMES}
    maps["mask"] = np.full((H, W), 255, np.uint8)
    maps["flags"] = np.full((H, W), 255, np.uint8)
    check_wall_kind(wall_kind)
    fit_kw = dict(wall_kind=wall_kind, p_misfit=p_misfit, g=check_g(g))
    regions, profiles = {}, {}
    for region in sorted(int(v) for v in np.unique(lab) if v != 0):
        inside = lab == region
        bottom = depth_of(region)
        blocks, means, sds, walls = [], [], [], []
        for r0 in range(0, H, b):
            for c0 in range(0, W, b):
                m = inside[r0 : r0 + b, c0 : c0 + b]
                if not m.any():
                    continue
                px = dense[r0 : r0 + b, c0 : c0 + b][m]  # (n, U)
                mean = px.mean(axis=0)
                sd = px.std(axis=0, ddof=1) / math.sqrt(px.shape[0]) if px.shape[0] > 1 else np.zeros(U)
                means.append(mean)
                sds.append(np.maximum(sd, 0.01 * max(float(np.abs(mean).max()), 1e-30)))
                blocks.append((r0, c0, m))
                if dist is not None or bottom is not None:
                    wb = None if dist is None else group_walls(dist[r0 : r0 + b, c0 : c0 + b][m])
                    walls.append(with_bottom(wb, bottom))
        if not blocks:
            continue
        Y = np.stack(means)
        Y[Y == 0] = np.nan
        S = np.stack(sds)
        res = None
        if not regions_only:
            res = fit_profiles(
                Y, offsets_rows=offsets, mm_per_row=mm_per_row, sigma=S, calibrated=calibrated,
                rows_per_camera_row=rpc, table=table, walls=walls or None, **fit_kw,
            )  # fmt: skip
            if progress is not None:
                progress(len(blocks))
        for i, (r0, c0, m) in enumerate(blocks if res is not None else ()):
            sl = (slice(r0, r0 + b), slice(c0, c0 + b))
            for name, val in zip(
                MAP_NAMES,
                (res.mu_s_prime_per_mm, res.mu_a_per_mm, res.mu_s_prime_se_per_mm, res.mu_a_se_per_mm),
            ):
                maps[name][sl][m] = val[i]
            maps["mask"][sl][m] = res.mask[i]
            maps["flags"][sl][m] = res.flags[i]
        # The region: its mean profile, noise from the spread of its blocks.
        fin = np.isfinite(Y)
        cnt = fin.sum(axis=0)
        Y0 = np.where(fin, Y, 0.0)
        y = np.where(cnt > 0, Y0.sum(axis=0) / np.maximum(cnt, 1), np.nan)  # nanmean without the warning
        var = np.where(fin, (Y0 - y) ** 2, 0.0).sum(axis=0) / np.maximum(cnt - 1, 1)
        s = np.sqrt(var) / np.sqrt(np.maximum(cnt, 1)) if len(blocks) > 2 else S[0]
        s = np.where(np.isfinite(s) & (s > 0) & (cnt > 2), s, np.nanmax(S))
        s = np.maximum(s, 1e-3 * np.nanmax(np.abs(y)))
        rw = None
        if dist is not None:
            # With the walls modelled, the region's profile is the mean of its pixels, zeros (lines
            # beyond a wall) included: its model is the mean of the pixels' kernels with their walls.
            y = dense[inside].mean(axis=0)
            y[y == 0] = np.nan
            rw = [group_walls(dist[inside])]
        if bottom is not None:
            rw = [with_bottom(None if rw is None else rw[0], bottom)]
        rr = fit_profiles(
            y, offsets_rows=offsets, mm_per_row=mm_per_row, sigma=s, calibrated=calibrated,
            rows_per_camera_row=rpc, table=table, walls=rw, **fit_kw,
        )  # fmt: skip
        flag0 = int(rr.flags[0])
        log_s_row = rr.log_estimate_per_mm[0, 0] + math.log(float(mm_per_row))
        if out_of_range(log_s_row, bottom, None if dist is None else dist[inside]):
            flag0 |= FLAG_RANGE
        if res is None:
            maps["flags"][inside] = flag0
        q = rr.quality(0)
        regions[region] = {
            "pixels": int(inside.sum()),
            "blocks": len(blocks),
            "mu_s_prime_per_mm": num_or_none(rr.mu_s_prime_per_mm[0]),
            "mu_s_prime_se_per_mm": num_or_none(rr.mu_s_prime_se_per_mm[0]),
            "mu_a_per_mm": num_or_none(rr.mu_a_per_mm[0]),
            "mu_a_se_per_mm": num_or_none(rr.mu_a_se_per_mm[0]),
            "not_identifiable": describe_reasons(int(rr.mask[0])),
            "chi2_per_dof": num_or_none(rr.chi2_per_dof[0]),
            "fit_quality": None if q is None else q.to_json(),
            "model_fits": None if q is None else q.fits,
            "flags": describe_flags(flag0),
            "flag_bits": flag0,
            "g": num_or_none(rr.g[0]),
            "g_se": num_or_none(rr.g_se[0]),
            "g_source": "fitted (unknown)" if fit_kw["g"] is None else "stated",
            "blocks_flagged": None if res is None else float(((res.flags & (FLAG_MISFIT | FLAG_EDGE)) > 0).mean()),
            "blocks_median_mu_s_prime_per_mm": None if res is None else _nanmedian(res.mu_s_prime_per_mm),
            "blocks_median_mu_a_per_mm": None if res is None else _nanmedian(res.mu_a_per_mm),
            "blocks_identified": None
            if res is None
            else {
                "mu_s_prime": float(np.isfinite(res.mu_s_prime_per_mm).mean()),
                "mu_a": float(np.isfinite(res.mu_a_per_mm).mean()),
            },
        }
        profiles[region] = (y, s, rr.model[0])
    return TransportFit(maps, regions, profiles, offsets, calibrated)


MAP_NAMES = ("mu_s_prime_per_mm", "mu_a_per_mm", "mu_s_prime_se_per_mm", "mu_a_se_per_mm")


def num_or_none(v):
    return float(v) if np.isfinite(v) else None


def _nanmedian(v):
    v = np.asarray(v, float)
    return float(np.nanmedian(v)) if np.isfinite(v).any() else None
