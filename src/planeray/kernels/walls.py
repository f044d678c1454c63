"""Container walls and a layer's bottom in diffusion theory: the relative effect the fit applies to its kernels.

A pixel near a clear container wall loses the light that reaches the wall (Fresnel reflection
back, the rest lost): the materials scene's Monte Carlo wall kernels (:mod:`planeray.mc.wall`,
:mod:`planeray.kernels.wall`).  The fit cannot trace a wall table for every trial medium, so it
takes the *relative* wall effect from diffusion theory -- the dipole of the half-space (Farrell
et al. 1992; the engine's hand-off) with its mirror images across the wall's extrapolated
boundary, opposite sign (Haskell et al. 1994; the same method of images as
:mod:`planeray.mc.wall`'s continuation) -- and applies it to the Monte Carlo table kernel:
``K_wall(u) = K(u) L_wall(u) / L(u)``, ``L`` the dipole's line kernels
(:func:`planeray.kernels.forward.model_kernel`).  Against the scene's Monte Carlo wall tables
this ratio carries 78-99 % of the wall's effect (L1).  A layer's bottom that loses the light is
the slab's image series (Contini et al. 1997).  Every source's line integral is the one line law
of :func:`planeray.mc.diffusion.k1_line_law`.

All lengths here are in projector rows, the coefficients per row (``mu h``).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ..mc.diffusion import boundary_mismatch_A, k1_line_law

__all__ = [
    "WALL_ANGLES_DEG",
    "WALL_KINDS",
    "BOTTOM_ANGLE_DEG",
    "check_wall_kind",
    "dipole_per_row",
    "dipole_line",
    "layer_line",
    "wall_term",
]


#: Wall angles the fit models: parallel to the projector's lines (0) and across them (90 degrees).
WALL_ANGLES_DEG = (0.0, 90.0)


#: Kinds of container wall: ``"clear"`` (air behind a thin clear wall: the medium's own index mismatch against air,
#: the extrapolated boundary ``2 A(n) D`` behind it, Haskell et al. 1994) or ``"black"`` (nothing returns: ``A = 1``;
#: also a clear wall of an index-matched medium).
WALL_KINDS = ("clear", "black")


#: The ``angle_deg`` of a ``walls`` row that is a layer's **bottom** (``distance_rows``: the layer's depth):
#: light that reaches it is lost (a layer on a dark or clear support, e.g. the 30 mm of liquid soap).
BOTTOM_ANGLE_DEG = 180.0


_Y_GRID = 200  # points of the along-line grid of the half-line integrals (sinh spaced)


_GL_X = (-0.25, 0.25)  # midpoints across an offset bin (the ratio of two binned kernels), parallel walls


_L_STEP = 0.125  # rows: the dipole's line kernel is interpolated from this grid (parallel walls)


def check_wall_kind(wall_kind) -> str:
    if wall_kind not in WALL_KINDS:
        raise InputError(f"wall_kind must be one of {', '.join(WALL_KINDS)}, got {wall_kind!r}")
    return wall_kind


def dipole_per_row(s, a, n, wall_kind="clear"):
    """Dipole constants of a medium of per-row coefficients ``s = mu_s' h``, ``a = mu_a h``.

    ``z`` (the real and image sources under the top face) and ``z_b`` (the extrapolated boundary behind a container
    wall, :data:`WALL_KINDS`: the top's mismatch ``A(n)`` for a clear wall, ``A = 1`` for a black one).
    """
    st = s + a
    A = boundary_mismatch_A(n)
    A_wall = A if wall_kind == "clear" else 1.0
    z_r = 1.0 / st
    return dict(
        albedo=s / st, sigma_tr=math.sqrt(3.0 * a * st), z=(z_r, z_r * (1.0 + 4.0 * A / 3.0)),
        z_b=2.0 * A_wall / (3.0 * st), z_b_top=2.0 * A / (3.0 * st),
    )  # fmt: skip


def _source_line(x, z, st):
    """One diffusion source's term of a line kernel: ``z sigma_tr K1(sigma_tr rho) / rho``, ``rho = sqrt(x^2 + z^2)``.

    Half the line integral of ``z (sigma_tr r + 1) exp(-sigma_tr r) / r^3`` (the source's reflectance at
    depth ``z``, signed), ``x`` the lateral distance to the line (rows).
    """
    return k1_line_law(np.sqrt(x * x + z * z), z, st)


def dipole_line(x, d):
    """Line integral of the dipole's reflectance at lateral distance ``x`` (rows): closed form.

    ``int R(sqrt(x^2 + y^2)) dy`` with ``z (sigma_tr r + 1) exp(-sigma_tr r) / r^3`` per source,
    whose line integral is ``2 z sigma_tr K1(sigma_tr rho) / rho`` (:func:`_source_line`).
    """
    x = np.asarray(x, np.float64)
    out = np.zeros_like(x)
    for z in d["z"]:
        out += _source_line(x, z, d["sigma_tr"])
    return d["albedo"] / (2.0 * np.pi) * out


def layer_line(x, d, depth_rows, images=4):
    """Line integral of the reflectance of a layer ``depth_rows`` deep whose bottom loses the light.

    The dipole's image series for a slab (Contini et al. 1997, Appl. Opt. 36, 4587): the
    top's extrapolated boundary ``z_b`` above the surface (its Fresnel mismatch), the bottom's
    ``2 / (3 sigma_t')`` below the bottom (index-matched: nothing returns); sources ``z_r + m P``
    and images ``-2 z_b - z_r + m P``, period ``P = 2 (t + z_b + z_b')``, ``|m| <= images``.
    Each source's line integral is :func:`_source_line` with its signed depth ``z``; ``images = 0``
    of a deep layer is the semi-infinite dipole.
    """
    x = np.asarray(x, np.float64)
    z_r, z_b = d["z"][0], d["z_b_top"]
    z_b2 = 2.0 * z_r / 3.0  # 2 / (3 sigma_t'), A = 1
    period = 2.0 * (float(depth_rows) + z_b + z_b2)
    out = np.zeros_like(x)
    for m in range(-images, images + 1):
        for z, sign in ((z_r + m * period, 1.0), (-2.0 * z_b - z_r + m * period, -1.0)):
            out += sign * _source_line(x, z, d["sigma_tr"])
    return d["albedo"] / (2.0 * np.pi) * out


def _half_lines(x_abs, d, b_values):
    """``int_b^inf R(sqrt(x^2 + y^2)) dy`` for every ``x`` (rows, >= 0) and every ``b >= 0``: ``(X, B)``."""
    st = d["sigma_tr"]
    y_max = float(np.max(b_values)) + 40.0 / max(st, 1e-3) + 50.0
    c = 0.25
    y = c * np.sinh(np.linspace(0.0, math.asinh(y_max / c), _Y_GRID))
    r = np.sqrt(x_abs[:, None] ** 2 + y[None, :] ** 2)
    R = np.zeros_like(r)
    for z in d["z"]:
        rr = np.sqrt(r * r + z * z)
        R += z * (st * rr + 1.0) * np.exp(-st * rr) / rr**3
    R *= d["albedo"] / (4.0 * np.pi)
    seg = 0.5 * (R[:, 1:] + R[:, :-1]) * np.diff(y)[None, :]
    tail = np.concatenate(
        [np.cumsum(seg[:, ::-1], axis=1)[:, ::-1], np.zeros((x_abs.size, 1))], axis=1
    )  # int_{y_k}^{y_max}
    b = np.asarray(b_values, np.float64)
    k = np.clip(np.searchsorted(y, b) - 1, 0, y.size - 2)
    w = np.clip((b - y[k]) / (y[k + 1] - y[k]), 0.0, 1.0)
    return tail[:, k] * (1.0 - w) + tail[:, k + 1] * w


def _on_grid(t, values):
    """Linear interpolation of ``values`` (on a uniform grid) at fractional indices ``t >= 0``: ``np.interp``
    without its search (the grid is uniform), exact at the grid's points."""
    i = np.minimum(t.astype(np.int64), values.size - 2)
    return values[i] + (values[i + 1] - values[i]) * (t - i)


def wall_term(k_table, log_s, log_a, n, offsets, foot, walls, wall_kind="clear"):
    """The walls' change of the footprint-averaged kernel (``(U,)``), to add to the wall-free kernel.

    ``walls``: array ``(M, 4)`` of ``[distance_rows, angle_deg (0 or 90; 180: a bottom), side (+1/-1), weight]``;
    each pixel's walls weigh ``1 / pixels`` of the profile (a block's mean profile: the mean of
    its pixels' kernels), the effects of several walls add (as in the scene).
    """
    reach = k_table.size - 1
    f, w = foot
    d = dipole_per_row(math.exp(log_s), math.exp(log_a), n, wall_kind)
    x = np.asarray(offsets, np.float64)[:, None] - f[None, :]  # line offset seen by the pencil at f: (U, F)
    kk = np.where(np.abs(x) <= reach, k_table[np.minimum(np.abs(x), reach).astype(np.int64)], 0.0)
    term = np.zeros(x.shape[0])
    sub = np.asarray(_GL_X)
    par = walls[walls[:, 1] == 0.0]
    if par.size:
        dist, side, wt = par[:, 0], par[:, 2], par[:, 3]
        # In the wall's frame (wall on the positive side): offset side * x, the pencil at f is side * f closer.
        xx = side[:, None, None] * x[None] + sub[:, None, None, None]  # (S, M, U, F)
        aa = dist[:, None, None] - side[:, None, None] * f[None, None, :]  # (M, 1, F)
        img = 2.0 * (aa + d["z_b"]) - xx
        grid = np.arange(0.0, max(float(np.abs(xx).max()), float(np.abs(img).max())) + 2 * _L_STEP, _L_STEP)
        Lg = dipole_line(grid, d)  # smooth in x; |xx| lies on the grid, the images between its points
        L = _on_grid(np.abs(xx) / _L_STEP, Lg)
        Lw = np.where(xx < aa, L - _on_grid(np.abs(img) / _L_STEP, Lg), 0.0)
        ratio = Lw.sum(axis=0) / np.maximum(L.sum(axis=0), 1e-300)
        term += (wt[:, None] * ((ratio - 1.0) * kk[None] * w).sum(axis=-1)).sum(axis=0)
    per = walls[walls[:, 1] == 90.0]
    if per.size:
        dist, wt = per[:, 0], per[:, 3]
        u = np.asarray(offsets, np.float64)
        xs, back = np.unique(np.abs(u), return_inverse=True)  # the kernel is symmetric in x
        M = dist.size
        H = _half_lines(xs, d, np.concatenate([dist, dist + 2.0 * d["z_b"]]))
        L = dipole_line(xs, d)
        ratio = ((L[:, None] - H[:, :M] - H[:, M:]) / np.maximum(L, 1e-300)[:, None])[back]  # (U, M)
        term += ((ratio - 1.0) * wt[None, :]).sum(axis=1) * (kk * w).sum(axis=-1)
    bottom = walls[walls[:, 1] == BOTTOM_ANGLE_DEG]
    if bottom.size:
        u = np.abs(np.asarray(offsets, np.float64))
        L = dipole_line(u, d)
        for depth, wt in bottom[:, [0, 3]]:
            ratio = layer_line(u, d, depth) / np.maximum(L, 1e-300)
            term += wt * (ratio - 1.0) * (kk * w).sum(axis=-1)
    return term
