"""Monte Carlo line kernels beside a container wall (Sec. 8: pixels near the edge of a container).

A container of a scattering liquid seen from above is a half-space ``z > 0`` cut by its
vertical walls.  Far from a wall a pixel sees the slab's line kernel
(:func:`planeray.mc.mc_line_profile`); near one, light that reaches the wall is lost
through it (a black wall, or the part a clear wall transmits) or reflected back, and
the kernel changes on the wall's side -- the paper's explanation of its only
recognition errors ("pixels near the edge of the container, where the scattering
profile changes ... due to the asymmetry of a boundary condition").  This module traces
that geometry with the engine's scheme (:mod:`planeray.mc.engine`: MCML weights,
Henyey-Greenstein scattering, Fresnel top face, 32 seeded xoshiro256+ batches).

Geometry
--------
A **pencil beam** enters at normal incidence at the origin of the top face.  The wall
is the vertical plane ``x cos(phi) + y sin(phi) = a``: ``a`` (``wall_distance_mm``) is
the distance from the entry point to the wall, ``phi`` (``wall_angle_deg``) the angle
between the wall's normal and the ``x`` axis, ``x`` being the offset axis across the
projector's lines (camera rows) and ``y`` the direction along them.  ``phi = 0``: the
wall runs parallel to the lit lines (the top or bottom side of a tray, seen by the
camera), on the side of positive offsets; ``phi = 90``: the wall is perpendicular to
them (a left or right side).  Exits are binned by ``x`` and integrated over ``y``.

Why a pencil beam at the pixel: the scene needs ``T(pixel, line)``, the light a pixel
at distance ``a`` from the wall receives when the projector lights the line at offset
``u``.  By the reciprocity of radiative transfer with Fresnel boundaries (normal
incidence in, radiance along the normal out, the same on both ends), the light that
enters at the pixel and leaves along the whole line equals the light that enters along
the line and leaves at the pixel: the binned **normal-view radiance** of this run *is*
the pixel's line kernel, for every offset at once.  Without a wall it is the slab's
line kernel (the line integral of a pencil beam's response, by translation invariance).
``tests/test_mc_wall.py`` checks both: the reciprocity (a wall parallel to the lines,
source and pixel exchanged) and the far-wall limit, bin by bin against
:func:`planeray.mc.mc_line_profile`.

The wall
--------
``wall="fresnel"``: a thin clear wall (glass, plastic) with air behind it; a photon
reaching it is reflected with the unpolarized Fresnel reflectance of the medium against
air (index ``n``) and otherwise leaves (booked as ``wall_loss``), like at the top face.
``wall="absorbing"``: a black wall; every photon reaching it is lost.  The wall is
vertical and infinitely deep, and the top face is flat up to it (no meniscus, no rim).

Hybrid continuation with a wall
-------------------------------
As in the engine, a photon that reaches ``diffusion_depth_mfp`` transport mean free
paths in a half-space is handed to diffusion theory (Wang & Jacques [1]_).  With a
wall the exit law is the diffusion solution of the *quarter* space: the point source
at the crossing depth ``z_c`` and its image above the extrapolated top boundary (the
engine's dipole, Farrell et al. [2]_), plus the mirror images of both across the wall's
extrapolated boundary ``z_bw = 2 A D`` behind the wall (``A`` of the wall's index; 1
for a black wall), with opposite sign -- the method of images of Haskell et al. [3]_
for a second boundary.  Its flux through the top face, binned by ``x`` over the inside
of the wall, is where the photon leaves; its flux through the wall plane is lost; the
rest is absorbed.  Without absorption the two fluxes add up to 1 (nothing is lost in
the model; a test checks it).  Crossing points are histogrammed by ``x`` and by their
distance to the wall (``phi > 0``; for ``phi = 0`` the distance follows from ``x``).

So ``diffuse + specular + transmitted + absorbed + truncated + wall_loss == 1``.

References
----------
.. [1] L. Wang, S. L. Jacques, "Hybrid model of Monte Carlo simulation and diffusion
   theory for light reflectance by turbid media", JOSA A 10(8), 1746-1752, 1993.
.. [2] T. J. Farrell, M. S. Patterson, B. Wilson, "A diffusion theory model of spatially
   resolved, steady-state diffuse reflectance", Med. Phys. 19, 879-888, 1992.
.. [3] R. C. Haskell, L. O. Svaasand, T.-T. Tsay, T.-C. Feng, M. S. McAdams, B. J.
   Tromberg, "Boundary conditions for the diffusion equation in radiative transfer",
   JOSA A 11(10), 2727-2741, 1994.
.. [4] L. Wang, S. L. Jacques, L. Zheng, "MCML -- Monte Carlo modeling of light transport
   in multi-layered tissues", Comput. Methods Programs Biomed. 47, 131-146, 1995.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numba
import numpy as np
from scipy.special import k1e

from ..errors import InputError
from ..medium import Medium, as_medium
from ._batches import trace_batches
from .cache import (
    ENGINE_VERSION,
    TABLES_DIR,
    cache_dir,
    cache_key,
    load_profile,
    save_profile,
    save_table,
    write_or_warn,
)
from .diffusion import boundary_mismatch_A, diffusion_exit, diffusion_normal_radiance_ratio
from .engine import (
    _N_BATCHES,
    DIFFUSION_DEPTH_MFP,
    ROULETTE_CHANCE,
    ROULETTE_THRESHOLD,
    _batch_stats,
    _uniform,
    default_cutoff_mm,
    mc_line_profile,
)
from .physics import fresnel_jit, hg_pdf_jit, hg_scatter_jit
from .result import MCProfile

__all__ = [
    "WALL_MODELS",
    "WALL_VERSION",
    "mc_wall_profile",
    "WallKernelTable",
    "mc_wall_table",
    "wall_exit_fractions",
]

#: Wall models: a clear wall with air behind it (Fresnel), or a black one.
WALL_MODELS = ("fresnel", "absorbing")
#: Bumped whenever the wall runs' results change (part of every wall cache key).
WALL_VERSION = 2
#: Distance bins of the crossing points to the wall (the continuation's exit law).
_N_WALL_BINS = 48


# ---------------------------------------------------------------- the kernel
@numba.njit(cache=True, inline="always")
def _splitmix64(x):
    """One step of SplitMix64 (Steele, Lea & Flood 2014): ``(next state, output)``."""
    x = x + np.uint64(0x9E3779B97F4A7C15)
    z = x
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x, z ^ (z >> np.uint64(31))


@numba.njit(cache=True, inline="always")
def _photon_state(key, index, s):
    """Seed the xoshiro256+ state ``s`` of photon ``index`` from the run's ``key`` (SplitMix64, as its authors advise)."""
    x = key ^ (np.uint64(index) * np.uint64(0xD1B54A32D192ED03))
    for i in range(4):
        x, out = _splitmix64(x)
        s[i] = out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _trace_wall(
    starts,
    counts,
    key,
    sigma_s,
    sigma_a,
    g,
    n,
    d,
    kmin,
    nk,
    mm_per_row,
    w0,
    cutoff_mm,
    z_cont,
    hmin,
    nh,
    dbin,
    nd,
    wall_a,
    wcx,
    wcy,
    n_wall,
):
    """Trace ``counts[b]`` pencil-beam photons per batch ``b`` beside the wall; per-batch tallies.

    Photon ``starts[b] + i`` draws from its own xoshiro256+ stream seeded from ``key``, so
    two runs with the same key trace the same photons until one of them meets the wall:
    runs at several wall distances and one without a wall are correlated photon by photon
    (what makes their differences, the wall's effect, precise; :func:`mc_wall_table`).

    The medium is ``0 < z < d`` and ``x wcx + y wcy < wall_a``.  A photon whose step
    crosses ``z_cont`` stops there and is histogrammed by the ``x`` bin of the crossing
    (``hmin .. hmin + nh - 1``) and its distance to the wall (bins of ``dbin``; the last
    of ``nd`` takes every larger distance).  At the wall a fraction ``R`` (Fresnel of
    ``n_wall``; 0 for ``n_wall = 1``) is reflected specularly, the rest is lost.
    """
    B = counts.size
    cont_hist = np.zeros((B, nh, nd))
    cont_far = np.zeros(B)
    refl_bins = np.zeros((B, nk))
    rad_bins = np.zeros((B, nk))
    refl = np.zeros(B)
    trans = np.zeros(B)
    absorbed = np.zeros(B)
    truncated = np.zeros(B)
    wall = np.zeros(B)
    events = np.zeros(B, dtype=np.int64)
    sigma_t = sigma_s + sigma_a
    albedo = sigma_s / sigma_t
    finite = d < np.inf
    up_gain = (1.0 - fresnel_jit(1.0, n)) / (n * n)
    inv_bin = 1.0 / mm_per_row
    for b in range(B):
        s = np.zeros(4, dtype=np.uint64)
        refl_b = 0.0
        trans_b = 0.0
        abs_b = 0.0
        trunc_b = 0.0
        far_b = 0.0
        wall_b = 0.0
        events_b = 0
        for i in range(counts[b]):
            _photon_state(key, starts[b] + i, s)
            x = 0.0
            y = 0.0
            z = 0.0
            ux = 0.0
            uy = 0.0
            uz = 1.0
            w = w0
            while True:
                step = -math.log(1.0 - _uniform(s)) / sigma_t
                # Distance to the wall along the direction of flight.
                dn = ux * wcx + uy * wcy
                s_wall = np.inf
                if dn > 0.0:
                    s_wall = max((wall_a - (x * wcx + y * wcy)) / dn, 0.0)
                # Distance to the next depth event: the continuation depth, the bottom or the top face.
                s_z = np.inf
                cont = False
                if uz > 0.0:
                    if z_cont < d:
                        s_z = (z_cont - z) / uz
                        cont = True
                    elif finite:
                        s_z = (d - z) / uz
                elif uz < 0.0:
                    s_z = -z / uz
                if s_wall < step and s_wall <= s_z:
                    # The wall: Fresnel reflection, the rest leaves the container.
                    x += s_wall * ux
                    y += s_wall * uy
                    z += s_wall * uz
                    R = fresnel_jit(dn, n_wall)
                    wall_b += w * (1.0 - R)
                    w *= R
                    ux -= 2.0 * dn * wcx
                    uy -= 2.0 * dn * wcy
                    if w <= 0.0:
                        break
                elif s_z < step:
                    xc = x + s_z * ux
                    yc = y + s_z * uy
                    if cont:
                        h = math.floor(xc * inv_bin + 0.5) - hmin
                        delta = wall_a - (xc * wcx + yc * wcy)
                        j = nd - 1
                        if dbin > 0.0:
                            j = min(int(max(delta, 0.0) / dbin), nd - 1)
                        if 0 <= h < nh:
                            cont_hist[b, int(h), j] += w
                        else:
                            far_b += w
                        break
                    x = xc
                    y = yc
                    top = uz < 0.0
                    z = 0.0 if top else d
                    R = fresnel_jit(abs(uz), n)
                    esc = w * (1.0 - R)
                    if top:
                        refl_b += esc
                        k = math.floor(x * inv_bin + 0.5) - kmin
                        if 0 <= k < nk:
                            refl_bins[b, int(k)] += esc
                    else:
                        trans_b += esc
                    w *= R
                    uz = -uz
                    if w <= 0.0:
                        break
                else:
                    x += step * ux
                    y += step * uy
                    z += step * uz
                    events_b += 1
                    tau = sigma_t * z
                    if tau < 40.0:
                        k = math.floor(x * inv_bin + 0.5) - kmin
                        if 0 <= k < nk:
                            rad_bins[b, int(k)] += w * albedo * hg_pdf_jit(-uz, g) * math.exp(-tau) * up_gain
                    abs_b += w * (1.0 - albedo)
                    w *= albedo
                    ux, uy, uz = hg_scatter_jit(ux, uy, uz, g, _uniform(s), _uniform(s))
                if w < ROULETTE_THRESHOLD:
                    if _uniform(s) < 1.0 / ROULETTE_CHANCE:
                        abs_b -= w * (ROULETTE_CHANCE - 1.0)
                        w *= ROULETTE_CHANCE
                    else:
                        abs_b += w
                        break
                if z > cutoff_mm or abs(x) > cutoff_mm or abs(y) > cutoff_mm:
                    trunc_b += w
                    break
        refl[b] = refl_b
        trans[b] = trans_b
        absorbed[b] = abs_b
        truncated[b] = trunc_b
        cont_far[b] = far_b
        wall[b] = wall_b
        events[b] = events_b
    return refl_bins, rad_bins, refl, trans, absorbed, truncated, wall, events, cont_hist, cont_far


# ---------------------------------------------------------------- diffusion with a wall
class _QuarterSpace:
    """Diffusion (P1, extrapolated boundaries) of photons handed off at depth ``z_c`` beside a wall.

    Sources: the crossing point at depth ``z_c`` and its negative image at
    ``-(z_c + 2 z_b)`` above the top face (the engine's dipole), and both mirrored across
    the wall's extrapolated boundary (``z_bw`` behind the wall) with opposite signs.
    """

    def __init__(self, z_c, sigma_a, sigma_tp, n, n_wall):
        self.z_c = float(z_c)
        self.sigma_a, self.sigma_tp, self.n = float(sigma_a), float(sigma_tp), float(n)
        self.sigma_tr = math.sqrt(3.0 * sigma_a * sigma_tp)
        D = 1.0 / (3.0 * sigma_tp)
        self.z_b = 2.0 * boundary_mismatch_A(n) * D
        self.z_bw = 2.0 * boundary_mismatch_A(n_wall) * D
        self.depths = np.array([self.z_c, self.z_c + 2.0 * self.z_b])
        self.e0 = 0.5 * float(np.sum(np.exp(-self.sigma_tr * self.depths)))  # exits without a wall
        # Distances to the wall of the tabulated hand-off (beyond: as without a wall).
        self.delta_max = 4.0 * self.z_c + (8.0 / self.sigma_tr if self.sigma_tr > 0 else 400.0 * self.z_c)
        self._grid = None
        self._memo = {}

    def fractions(self, delta):
        """``(E, W)`` at distances ``delta`` (interpolated from a grid computed once; far: ``(e0, 0)``)."""
        if self._grid is None:
            g = self.delta_max * np.linspace(0.0, 1.0, 241) ** 2  # dense near the wall
            self._grid = (g, self.exit_fraction(g), self.wall_fraction(g))
        g, E, W = self._grid
        delta = np.asarray(delta, dtype=np.float64)
        return np.interp(delta, g, E, right=self.e0), np.interp(delta, g, W, right=0.0)

    def memo(self, key, compute):
        """A value computed once per hand-off geometry (the exit laws do not depend on the wall's distance)."""
        if key not in self._memo:
            self._memo[key] = compute()
        return self._memo[key]

    # Exit flux through the top face of one source pair (no wall) ...
    def line_law(self, xi):
        """Flux per mm of ``x`` (integrated along ``y``) at lateral distance ``xi`` from the crossing."""
        xi = np.asarray(xi, dtype=np.float64)
        out = np.zeros_like(xi)
        for zi in self.depths:
            r = np.hypot(xi, zi)
            if self.sigma_tr > 0.0:
                out += zi * self.sigma_tr * k1e(self.sigma_tr * r) * np.exp(-self.sigma_tr * r) / r
            else:
                out += zi / (r * r)
        return out / (2.0 * np.pi)

    def point_law(self, rho):
        """Flux per mm^2 at distance ``rho`` from the point above the crossing (Farrell's dipole)."""
        rho = np.asarray(rho, dtype=np.float64)
        out = np.zeros_like(rho)
        for zi in self.depths:
            r = np.hypot(rho, zi)
            out += zi * (self.sigma_tr + 1.0 / r) * np.exp(-self.sigma_tr * r) / (r * r)
        return out / (4.0 * np.pi)

    # ... its integrals ...
    def _sinh_grid(self, t_max, n=400):
        c = max(self.z_c, 1e-9)
        tau = np.linspace(0.0, math.asinh(t_max / c), n)
        return c * np.sinh(tau), c * np.cosh(tau) * (tau[1] - tau[0])

    def exit_fraction(self, delta):
        """Fraction of the handed-off weight leaving through the top face inside the wall, ``E(delta)``."""
        delta = np.asarray(delta, dtype=np.float64)
        t_max = max(float(np.max(delta)) + 2.0 * self.z_bw, self.z_c) * 4.0 + 50.0 * self.z_c
        y, dy = self._sinh_grid(t_max, 4000)
        f = self.line_law(y) * dy
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]))])  # int_0^t of the line law

        def half(s):  # int_{-inf}^{s} line_law
            s = np.asarray(s, dtype=np.float64)
            return 0.5 * self.e0 + np.sign(s) * np.interp(np.abs(s), y, cum, right=0.5 * self.e0)

        return half(delta) - half(-delta - 2.0 * self.z_bw)

    def wall_fraction(self, delta):
        """Fraction of the handed-off weight leaving through the wall plane at distance ``delta``, ``W(delta)``."""
        delta = np.atleast_1d(np.asarray(delta, dtype=np.float64))
        xw = 2.0 * (delta + self.z_bw)  # lateral position of the wall images
        s_tr = self.sigma_tr
        zs = (self.z_c, -self.depths[1])

        def flux(z, dl, xi_w):
            out = 0.0
            for xi_i, sgn_x in ((0.0, 1.0), (xi_w, -1.0)):
                dx = dl - xi_i
                for z_i, sgn_z in zip(zs, (1.0, -1.0)):
                    r = math.hypot(dx, z - z_i)
                    kern = s_tr * k1e(s_tr * r) * math.exp(-s_tr * r) / r if s_tr > 0 else 1.0 / (r * r)
                    out += sgn_x * sgn_z * kern * dx
            return out / (2.0 * np.pi)

        from scipy.integrate import quad  # here: scipy.integrate costs ~0.3 s to import, every process with a scene

        res = np.empty_like(delta)
        for i, (dl, xi_w) in enumerate(zip(delta, xw)):
            dl = max(dl, 1e-3 * self.z_c)
            # The real source's flux through the plane peaks at z_c with width ~delta: split there.
            w = min(20.0 * dl, 0.5 * self.z_c)
            parts = ((0.0, self.z_c - w), (self.z_c - w, self.z_c + w), (self.z_c + w, np.inf))
            res[i] = sum(quad(flux, lo, hi, args=(dl, xi_w), limit=200)[0] for lo, hi in parts)
        return res


@functools.lru_cache(maxsize=8)
def _quarter_space(z_c, sigma_a, sigma_tp, n, n_wall) -> _QuarterSpace:
    """The hand-off geometry of a medium and wall, shared by every run (its exit laws are cached)."""
    return _QuarterSpace(z_c, sigma_a, sigma_tp, n, n_wall)


def wall_exit_fractions(delta_mm, *, medium: Medium, wall: str = "fresnel", diffusion_depth_mfp=DIFFUSION_DEPTH_MFP):
    """Diffusion hand-off beside a wall: fractions leaving through the top face and through the wall.

    For a photon handed to diffusion ``diffusion_depth_mfp`` transport mean free paths
    deep at distance ``delta_mm`` from the wall (see the module docstring), returns
    ``(E, W)``: the fraction that leaves through the top face inside the wall and the
    fraction lost through the wall; ``1 - E - W`` is absorbed.  Without absorption
    ``E + W = 1``; far from the wall ``E`` is the half-space value and ``W = 0``.

    Examples
    --------
    >>> from planeray.medium import Medium
    >>> E, W = wall_exit_fractions([0.5, 50.0], medium=Medium(sigma_s=2.0, sigma_a=0.0, g=0.5, n=1.33))
    >>> bool(abs(E[0] + W[0] - 1.0) < 1e-3 and W[1] < 0.2 < 0.8 < W[0])
    True
    """
    medium = as_medium(medium)
    _check_wall(wall)
    sigma_tp = medium.sigma_a + medium.sigma_s_prime
    q = _quarter_space(
        float(diffusion_depth_mfp) / sigma_tp, medium.sigma_a, sigma_tp, medium.n, _wall_index(wall, medium)
    )
    delta = np.atleast_1d(np.asarray(delta_mm, dtype=np.float64))
    return q.exit_fraction(delta), q.wall_fraction(delta)


def _tri_points():
    """Quadrature of a triangle density on ``[-1, 1]`` (source uniform in one bin, exit in another)."""
    t, wt = np.polynomial.legendre.leggauss(16)
    t = 0.5 * (t + 1.0)
    wt = 0.5 * wt
    return np.concatenate([t - 1.0, t]), np.concatenate([t * wt, (1.0 - t) * wt])


def _exits_parallel(cont, hmin, out_bins, mm, q: _QuarterSpace, wall_a):
    """Exits of photons handed off beside a wall parallel to the lines (``phi = 0``, wall at ``x = a``).

    ``cont`` is ``(B, nh)``: weight by the ``x`` bin of the crossing.  Returns the exit
    weight per output bin ``(B, K)``, and per batch the exiting and wall-lost weight.
    """
    nh = cont.shape[1]
    h = hmin + np.arange(nh)
    k = np.asarray(out_bins)
    tq, tw = _tri_points()
    # Source uniform in its bin, exit integrated over another: triangle weights in x - x_c and x + x_c.
    m1 = np.arange(int(k.min()) - int(h.max()), int(k.max()) - int(h.min()) + 1)
    T1 = q.memo(
        ("tri", int(m1[0]), int(m1[-1]), mm),
        lambda: (q.line_law((m1[:, None] + tq[None, :]) * mm) * tw).sum(axis=1) * mm,
    )
    m2 = np.arange(int(k.min()) + int(h.min()), int(k.max()) + int(h.max()) + 1)
    T2 = (q.line_law((m2[:, None] + tq[None, :]) * mm - 2.0 * (wall_a + q.z_bw)) * tw).sum(axis=1) * mm
    P = T1[k[None, :] - h[:, None] - m1[0]] - T2[k[None, :] + h[:, None] - m2[0]]
    # Exit bins beyond the wall get nothing; the bins the wall cuts, and crossing bins the
    # wall cuts, by direct quadrature over the parts inside.
    g8, w8 = np.polynomial.legendre.leggauss(8)
    lo_k, hi_k = (k - 0.5) * mm, (k + 0.5) * mm
    lo_h, hi_h = (h - 0.5) * mm, np.minimum((h + 0.5) * mm, wall_a)
    P[:, lo_k >= wall_a] = 0.0
    cut_k = np.flatnonzero((lo_k < wall_a) & (hi_k > wall_a))
    cut_h = np.flatnonzero(hi_h < (h + 0.5) * mm)
    for i in range(nh):
        cols = cut_k if i not in cut_h else np.flatnonzero(lo_k < wall_a)
        if cols.size == 0 or hi_h[i] <= lo_h[i]:
            continue
        xc = 0.5 * (lo_h[i] + hi_h[i]) + 0.5 * (hi_h[i] - lo_h[i]) * g8  # (8,)
        wc = 0.5 * w8  # crossings spread uniformly over the part of the bin inside the wall
        a_lo, a_hi = lo_k[cols], np.minimum(hi_k[cols], wall_a)
        x = 0.5 * (a_lo + a_hi)[:, None] + 0.5 * (a_hi - a_lo)[:, None] * g8[None, :]  # (C, 8)
        wx = 0.5 * (a_hi - a_lo)[:, None] * w8[None, :]
        dx = x[:, :, None] - xc[None, None, :]
        img = x[:, :, None] + xc[None, None, :] - 2.0 * (wall_a + q.z_bw)
        f = q.line_law(dx) - q.line_law(img)
        P[i, cols] = np.einsum("cs,cst,t->c", wx, f, wc)
    # Exiting and wall-lost fractions per crossing bin (delta averaged over the bin's inside).
    xs = 0.5 * (lo_h + hi_h)[:, None] + 0.5 * np.maximum(hi_h - lo_h, 0.0)[:, None] * g8[None, :]
    E_d, W_d = q.fractions(np.maximum(wall_a - xs, 0.0))
    E = (E_d * 0.5 * w8).sum(axis=1)
    W = (W_d * 0.5 * w8).sum(axis=1)
    return cont @ P, cont @ E, cont @ W


class _HalfLineTable:
    """``H(dx, t) = int_0^t F(sqrt(dx^2 + y^2)) dy`` of the point law ``F``, tabulated and bilinearly interpolated."""

    def __init__(self, q: _QuarterSpace, dx_max, t_max):
        self.q = q
        c = max(q.z_c, 1e-9)
        self.c = c
        step = max(q.z_c / 6.0, dx_max / 6000.0)
        self.dx = np.arange(0.0, dx_max + 2 * step, step)
        self.tau = np.linspace(0.0, math.asinh(t_max / c), 256)
        y = c * np.sinh(self.tau)
        jac = c * np.cosh(self.tau)
        f = q.point_law(np.hypot(self.dx[:, None], y[None, :])) * jac[None, :]
        dtau = self.tau[1] - self.tau[0]
        self.H = np.concatenate(
            [np.zeros((self.dx.size, 1)), np.cumsum(0.5 * (f[:, 1:] + f[:, :-1]), axis=1) * dtau], axis=1
        )

    def __call__(self, dx, t):
        dx = np.abs(dx)
        tau = np.arcsinh(np.abs(t) / self.c)
        fi = np.clip(dx / (self.dx[1] - self.dx[0]), 0, self.dx.size - 1.000001)
        i = fi.astype(np.int64)
        fx = fi - i
        ft = np.clip(tau / (self.tau[1] - self.tau[0]), 0, self.tau.size - 1.000001)
        j = ft.astype(np.int64)
        fy = ft - j
        H = self.H
        val = (
            H[i, j] * (1 - fx) * (1 - fy)
            + H[i + 1, j] * fx * (1 - fy)
            + H[i, j + 1] * (1 - fx) * fy
            + H[i + 1, j + 1] * fx * fy
        )
        half = 0.5 * self.q.line_law(dx)
        # Beyond the table's reach the half line holds all of it.
        return np.where(tau >= self.tau[-1], half, np.minimum(val, half))


def _exits_oblique(cont, hmin, out_bins, mm, q: _QuarterSpace, phi, dbin):
    """Exits of photons handed off beside a wall at angle ``phi`` (radians, ``0 < phi <= pi/2``).

    ``cont`` is ``(B, nh, nd)``: weight by the ``x`` bin of the crossing and by the bin of
    its distance to the wall (the last column: far from it, no wall).  For a crossing at
    distance ``delta`` the exit law depends only on ``x - x_c`` (the geometry is
    invariant along the wall): the point law's flux integrated over the ``y`` inside the
    wall, minus that of the image source across the wall.
    """
    B, nh, nd = cont.shape
    k = np.asarray(out_bins)
    m = np.arange(int(k.min()) - (hmin + nh - 1), int(k.max()) - hmin + 1)
    idx = k[None, :] - (hmin + np.arange(nh))[:, None] - m[0]
    deltas = (np.arange(nd - 1) + 0.5) * dbin
    laws = q.memo(
        ("oblique", float(phi), float(dbin), nd, int(m[0]), int(m[-1]), mm),
        lambda: _oblique_laws(q, m, mm, phi, deltas),
    )
    exits = np.zeros((B, k.size))
    for j in range(nd - 1):
        exits += cont[:, :, j] @ laws[j][idx]
    far = cont[:, :, nd - 1]
    far_bins, _ = diffusion_exit(far, hmin, k, mm, q.z_c, q.sigma_a, q.sigma_tp, q.n)
    exits += far_bins
    E, W = q.fractions(deltas)
    E, W = np.append(E, q.e0), np.append(W, 0.0)
    return exits, cont.sum(axis=1) @ E, cont.sum(axis=1) @ W


def _oblique_laws(q: _QuarterSpace, m, mm, phi, deltas):
    """Exit laws ``(len(deltas), len(m))``: weight leaving through the bin ``m`` bins from the crossing's."""
    tq, tw = _tri_points()
    u = (m[:, None] + tq[None, :]) * mm  # x - x_c
    cphi, sphi = math.cos(phi), math.sin(phi)
    table = _HalfLineTable(
        q,
        np.abs(u).max() + 2.0 * (deltas.max() + q.z_bw) + 1.0,
        (np.abs(u).max() + 3 * deltas.max()) / sphi + 50 * q.z_c,
    )
    L_u = q.line_law(u)
    laws = np.empty((deltas.size, m.size))
    for j, dl in enumerate(deltas):
        off = 2.0 * (dl + q.z_bw)
        s1 = (dl - u * cphi) / sphi  # y-limit of the inside, from the crossing
        u2 = u - off * cphi  # from the image
        s2 = s1 - off * sphi
        L2 = L_u if cphi == 0.0 else q.line_law(u2)
        J = (0.5 * L_u + np.sign(s1) * table(u, s1)) - (0.5 * L2 + np.sign(s2) * table(u2, s2))
        laws[j] = (J * tw).sum(axis=1) * mm
    return laws


# ---------------------------------------------------------------- runs
def _check_wall(wall):
    if wall not in WALL_MODELS:
        raise InputError(f"unknown wall model {wall!r}; choose one of {', '.join(WALL_MODELS)}")


def _wall_index(wall, medium):
    return medium.n if wall == "fresnel" else 1.0


def _check_offsets(offsets_rows):
    offsets_f = np.asarray(offsets_rows)
    offsets = offsets_f.astype(np.int64).ravel()
    if offsets.size == 0 or np.any(offsets != offsets_f.ravel()) or np.unique(offsets).size != offsets.size:
        raise InputError("offsets_rows must be distinct integers")
    return offsets


def _wall_params(
    medium,
    offsets,
    *,
    wall_distance_mm,
    wall_angle_deg,
    wall,
    n_photons,
    mm_per_row,
    seed,
    offsets_rows=None,
    diffusion_depth_mfp=DIFFUSION_DEPTH_MFP,
    cutoff_mm=None,
):
    """Checked parameters of one wall run (the cache key's content)."""
    a = float(wall_distance_mm)
    n_photons = int(n_photons)
    mm_per_row = float(mm_per_row)
    if n_photons < 1:
        raise InputError(f"n_photons must be >= 1, got {n_photons}")
    if not mm_per_row > 0:
        raise InputError(f"mm_per_row must be positive, got {mm_per_row}")
    if cutoff_mm is None:
        cutoff_mm = default_cutoff_mm(medium, offsets, mm_per_row=mm_per_row)
        if math.isfinite(a):
            cutoff_mm = max(cutoff_mm, 4.0 * a)
    cutoff_mm = float(cutoff_mm)
    if not cutoff_mm > 0:
        raise InputError(f"cutoff_mm must be positive, got {cutoff_mm}")
    depth_mfp = float(diffusion_depth_mfp) if diffusion_depth_mfp else None
    if depth_mfp is not None and not depth_mfp > 0:
        raise InputError(f"diffusion_depth_mfp must be positive or None, got {diffusion_depth_mfp}")
    return dict(
        sigma_s=medium.sigma_s,
        sigma_a=medium.sigma_a,
        g=medium.g,
        n=medium.n,
        thickness=None if medium.semi_infinite else medium.thickness_mm,
        n_photons=n_photons,
        mm_per_row=mm_per_row,
        seed=int(seed),
        cutoff_mm=cutoff_mm,
        diffusion_depth_mfp=depth_mfp,
        source="pencil-wall",
        wall=wall,
        wall_distance_mm=a,
        wall_angle_deg=float(wall_angle_deg),
        wall_version=WALL_VERSION,
    )


def mc_wall_profile(
    medium: Medium,
    *,
    wall_distance_mm,
    wall_angle_deg=0.0,
    wall="fresnel",
    n_photons=10**5,
    offsets_rows=None,
    mm_per_row=1.0,
    diffusion_depth_mfp=DIFFUSION_DEPTH_MFP,
    cutoff_mm=None,
    seed=0,
    cache=False,
) -> MCProfile:
    """Monte Carlo line kernel of a pixel ``wall_distance_mm`` from a container wall.

    Parameters
    ----------
    medium : Medium
        The liquid (``thickness_mm``: its depth; semi-infinite by default).
    wall_distance_mm : float
        Distance ``a >= 0`` from the pixel (the pencil beam's entry point) to the wall.
    wall_angle_deg : float
        Angle ``phi`` in ``[0, 90]`` between the wall's normal and the offset axis: 0 for
        a wall parallel to the projector's lines (at positive offsets), 90 for one
        perpendicular to them.
    wall : {"fresnel", "absorbing"}
        A clear wall with air behind it (Fresnel reflection at the medium's index, the
        rest lost) or a black wall (everything lost).
    n_photons : int
        Photon packets.
    offsets_rows : array_like of int, optional
        Offset bins; default ``arange(-50, 51)``.
    mm_per_row : float
        Bin width in mm.
    diffusion_depth_mfp : float or None
        Hand-off depth (semi-infinite media) in transport mean free paths, with the
        quarter-space exit law (module docstring); None traces every photon.
    cutoff_mm : float, optional
        Stop photons farther than this from the entry point (``|x|``, ``|y|``, ``z``);
        default :func:`planeray.mc.default_cutoff_mm`.
    seed : int
        Seed: same seed, same bytes, whatever the number of threads.
    cache : bool
        Read/write the result in the disk cache (after the shipped tables).

    Returns
    -------
    MCProfile
        ``radiance`` is the pixel's line kernel (normal-view radiance per bin, per unit
        power; by reciprocity the light the pixel receives from each lit line),
        ``values`` the exitance of the pencil beam per ``x`` bin, and ``wall_loss`` the
        power lost through the wall.

    Examples
    --------
    >>> from planeray.medium import Medium
    >>> m = Medium(sigma_s=2.0, sigma_a=0.05, g=0.5, n=1.33)
    >>> p = mc_wall_profile(m, wall_distance_mm=1.0, n_photons=4000, offsets_rows=range(-5, 6))
    >>> abs(p.energy_balance - 1.0) < 1e-9 and p.wall_loss > 0
    True
    >>> float(p.values[-1])  # beyond the wall (x > 1 mm): nothing leaves there
    0.0
    """
    medium = as_medium(medium)
    _check_wall(wall)
    a = float(wall_distance_mm)
    phi_deg = float(wall_angle_deg)
    if not a >= 0:  # also rejects NaN; inf: no wall (the reference of :func:`mc_wall_table`)
        raise InputError(f"wall_distance_mm must be >= 0 (inf: no wall), got {wall_distance_mm!r}")
    if not (0.0 <= phi_deg <= 90.0):
        raise InputError(f"wall_angle_deg must lie in [0, 90], got {wall_angle_deg!r}")
    if offsets_rows is None:
        offsets_rows = np.arange(-50, 51)
    offsets = _check_offsets(offsets_rows)
    params = _wall_params(
        medium,
        offsets,
        wall_distance_mm=a,
        wall_angle_deg=phi_deg,
        wall=wall,
        n_photons=n_photons,
        mm_per_row=mm_per_row,
        diffusion_depth_mfp=diffusion_depth_mfp,
        cutoff_mm=cutoff_mm,
        seed=seed,
    )
    path = None
    if cache:
        name = f"{cache_key(params, offsets)}.npz"
        path = cache_dir() / name
        for hit in (TABLES_DIR / name, path):
            if hit.exists():
                try:
                    return load_profile(hit)
                except (OSError, ValueError, KeyError):
                    pass
    prof, _ = _run_wall(medium, offsets, params)
    if path is not None:
        write_or_warn(lambda p: save_profile(p, prof), path)
    return prof


def _run_wall(medium, offsets, params):
    sigma_s, sigma_a, g, n, d = medium.sigma_s, medium.sigma_a, medium.g, medium.n, medium.thickness_mm
    n_photons, mm, seed = params["n_photons"], params["mm_per_row"], params["seed"]
    cutoff_mm, a = params["cutoff_mm"], params["wall_distance_mm"]
    phi = math.radians(params["wall_angle_deg"])
    wcx, wcy = math.cos(phi), math.sin(phi)
    if params["wall_angle_deg"] == 90.0:
        wcx = 0.0
    n_wall = _wall_index(params["wall"], medium)
    B = _N_BATCHES
    counts = np.full(B, n_photons // B, dtype=np.int64)
    counts[: n_photons % B] += 1
    key = np.random.SeedSequence(seed).generate_state(1, np.uint64)[0]
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    kmin = int(offsets.min())
    nk = int(offsets.max()) - kmin + 1
    r_sp = ((n - 1.0) / (n + 1.0)) ** 2
    depth_mfp = params["diffusion_depth_mfp"]
    sigma_tp = sigma_a + medium.sigma_s_prime
    z_cont = depth_mfp / sigma_tp if (depth_mfp and not np.isfinite(d)) else np.inf
    q = None
    dbin, nd = 0.0, 1
    hmin, nh = 0, 1
    if np.isfinite(z_cont):
        q = _quarter_space(z_cont, sigma_a, sigma_tp, n, n_wall)
        half = max(abs(kmin), abs(kmin + nk - 1)) * mm
        reach = int(np.ceil(min(cutoff_mm, half + 20.0 * z_cont) / mm))
        hmin, nh = -reach, 2 * reach + 1
        if wcy > 0.0 and math.isfinite(a):  # distance to the wall is not a function of x: histogram it
            delta_max = 4.0 * z_cont + (6.0 / q.sigma_tr if q.sigma_tr > 0 else 20.0 * z_cont)
            nd = _N_WALL_BINS + 1
            dbin = delta_max / _N_WALL_BINS
    refl_bins, rad_bins, refl, trans, absorbed, truncated, wall, events, cont, far = trace_batches(
        _trace_wall,
        (starts, counts),
        (
            key,
            sigma_s,
            sigma_a,
            g,
            n,
            d,
            kmin,
            nk,
            mm,
            1.0 - r_sp,
            cutoff_mm,
            z_cont,
            hmin,
            nh,
            dbin,
            nd,
            a,
            wcx,
            wcy,
            n_wall,
        ),
    )
    rad_bins /= mm
    out = np.arange(kmin, kmin + nk)
    if q is not None and (cont.any() or far.any()):
        if not math.isfinite(a):  # no wall: the engine's exit law
            c1 = cont.sum(axis=2)
            exit_bins, e_tot = diffusion_exit(c1, hmin, out, mm, z_cont, sigma_a, sigma_tp, n)
            e_w, w_w = c1.sum(axis=1) * e_tot, np.zeros(B)
        elif wcy > 0.0:
            exit_bins, e_w, w_w = _exits_oblique(cont, hmin, out, mm, q, phi, dbin)
        else:
            exit_bins, e_w, w_w = _exits_parallel(cont[:, :, 0], hmin, out, mm, q, a)
        refl_bins += exit_bins
        rad_bins += exit_bins * (diffusion_normal_radiance_ratio(n) / mm)
        # Photons beyond the crossing histogram cannot reach the bins: they leave as without a wall.
        refl += e_w + far * q.e0
        wall += w_w
        absorbed += cont.sum(axis=(1, 2)) - e_w - w_w + far * (1.0 - q.e0)
    cols = offsets - kmin
    values, stderr = _batch_stats(refl_bins[:, cols], counts)
    radiance, rad_err = _batch_stats(rad_bins[:, cols], counts)
    R_tot, r_err = _batch_stats(refl, counts)
    T_tot, t_err = _batch_stats(trans, counts)
    W_tot, w_err = _batch_stats(wall, counts)
    prof = MCProfile(
        offsets_rows=offsets.copy(),
        mm_per_row=mm,
        values=values,
        stderr=stderr,
        radiance=radiance,
        radiance_stderr=rad_err,
        total_reflectance=float(R_tot),
        total_reflectance_stderr=float(r_err),
        specular_reflectance=float(r_sp),
        transmittance=float(T_tot),
        transmittance_stderr=float(t_err),
        absorbed=float(absorbed.sum() / n_photons),
        truncated=float(truncated.sum() / n_photons),
        n_photons=n_photons,
        n_interactions=int(events.sum()),
        params=params,
        wall_loss=float(W_tot),
        wall_loss_stderr=float(w_err),
    )
    per_photon = rad_bins[:, cols] / counts[:, None]
    return prof, per_photon


# ---------------------------------------------------------------- kernel tables
#: Default wall distances of a table, in projector rows: dense near the wall, out to the
#: canonical kernel reach (:data:`planeray.kernels.MC_KERNEL_REACH_ROWS`).
TABLE_DISTANCES_ROWS = (0.0, 1.5, 3.0, 5.0, 8.0, 12.0, 17.0, 24.0, 33.0, 45.0, 60.0, 80.0, 105.0, 140.0, 192.0)
#: Default wall angles of a table: parallel, oblique and perpendicular to the lit lines (trays use 0 and 90).
TABLE_ANGLES_DEG = (0.0, 45.0, 90.0)
#: Photons per wall distance and angle of a table; the slab kernel gets :data:`TABLE_SLAB_PHOTONS`.
TABLE_PHOTONS = 100_000
TABLE_SLAB_PHOTONS = 1_000_000

#: Monte Carlo runs of a default table (the slab, the reference without a wall, one per angle and distance):
#: what :func:`mc_wall_table` counts with ``progress``.
TABLE_RUNS = 2 + len(TABLE_ANGLES_DEG) * len(TABLE_DISTANCES_ROWS)
__all__ += [
    "TABLE_DISTANCES_ROWS",
    "TABLE_ANGLES_DEG",
    "TABLE_PHOTONS",
    "TABLE_SLAB_PHOTONS",
    "TABLE_RUNS",
    "wall_table_stored",
]

_TABLE_ARRAYS = (
    "offsets_rows",
    "angles_deg",
    "distances_rows",
    "kernel",
    "kernel_stderr",
    "wall_loss",
    "slab",
    "slab_stderr",
)


def _physical(kernel, angles_deg, distances_rows, offsets_rows):
    """Kernels with what cannot be: no negative light (the control variate's noise), and nothing from
    behind a wall parallel to the lines (angle 0: bins wholly beyond the wall, where the run with the
    wall has no exits and the difference is the reference's noise alone)."""
    k = np.clip(kernel, 0.0, None)
    for i, ang in enumerate(angles_deg):
        if ang == 0.0:
            beyond = np.asarray(offsets_rows)[None, :] - 0.5 >= np.asarray(distances_rows)[:, None]
            k[i][beyond] = 0.0
    return k


@dataclass(frozen=True)
class WallKernelTable:
    """Line kernels of a medium for pixels at several distances and angles from a wall.

    ``kernel[i, j]`` is what a pixel ``distances_rows[j]`` projector rows from a wall at
    ``angles_deg[i]`` (:func:`mc_wall_profile`) receives from the lit line at each offset,
    in **Lambertian-equivalent reflectance per offset bin**: ``pi`` times the normal-view
    radiance times the bin width, so that a white Lambertian surface would sum to 1 (the
    unit of the scenes' transport).  ``slab`` is the same without a wall.

    Attributes
    ----------
    medium : Medium
    wall : str
        ``"fresnel"`` or ``"absorbing"``.
    mm_per_row : float
    offsets_rows : ndarray (U,) of int
    angles_deg : ndarray (A,)
    distances_rows : ndarray (D,)
    kernel, kernel_stderr : ndarray (A, D, U)
        Kernels and their Monte Carlo standard errors.
    wall_loss : ndarray (A, D)
        Power lost through the wall per unit power entering at the pixel.
    slab, slab_stderr : ndarray (U,)
        The kernel far from any wall and its error.
    params : dict
        How the table was computed (photons, seed, versions).
    """

    medium: Medium
    wall: str
    mm_per_row: float
    offsets_rows: np.ndarray
    angles_deg: np.ndarray
    distances_rows: np.ndarray
    kernel: np.ndarray
    kernel_stderr: np.ndarray
    wall_loss: np.ndarray
    slab: np.ndarray
    slab_stderr: np.ndarray
    params: dict = field(default_factory=dict)

    @functools.cached_property
    def _wall_effect(self) -> np.ndarray:
        """``kernel - slab``, what :meth:`kernels` interpolates (computed once: a scene asks per pixel row)."""
        return self.kernel - self.slab[None, None, :]

    def kernels(self, distance_rows, angle_deg) -> np.ndarray:
        """Kernels of pixels at ``distance_rows`` from a wall at ``angle_deg`` (broadcast), ``(..., U)``.

        Bilinear interpolation of the wall's effect (``kernel - slab``) in angle and
        distance; beyond the largest tabulated distance the slab kernel.  Angles outside
        the tabulated range take the nearest tabulated angle.
        """
        d, a = np.broadcast_arrays(np.asarray(distance_rows, np.float64), np.asarray(angle_deg, np.float64))
        pert = self._wall_effect
        A, D = self.angles_deg, self.distances_rows
        fa = np.interp(a, A, np.arange(A.size)) if A.size > 1 else np.zeros_like(a)
        ia = np.minimum(np.floor(fa).astype(np.int64), A.size - 1)
        ia1 = np.minimum(ia + 1, A.size - 1)
        wa = (fa - ia)[..., None]
        dd = np.clip(d, D[0], None)
        fd = np.interp(dd, D, np.arange(D.size))
        idd = np.minimum(np.floor(fd).astype(np.int64), D.size - 1)
        id1 = np.minimum(idd + 1, D.size - 1)
        wd = (fd - idd)[..., None]
        p = (1 - wa) * ((1 - wd) * pert[ia, idd] + wd * pert[ia, id1]) + wa * (
            (1 - wd) * pert[ia1, idd] + wd * pert[ia1, id1]
        )
        p = np.where((d > D[-1])[..., None], 0.0, p)
        return self.slab + p

    # ------------------------------------------------------------ storage
    def save(self, path) -> Path:
        """Write the table as one compressed ``.npz`` (no pickle), atomically."""
        meta = {
            "medium": self.medium.to_dict(),
            "wall": self.wall,
            "mm_per_row": self.mm_per_row,
            "params": self.params,
        }
        arrays = {k: getattr(self, k) for k in _TABLE_ARRAYS}
        arrays = {k: (v.astype(np.float32) if v.dtype.kind == "f" else v) for k, v in arrays.items()}
        return save_table(path, meta=np.array(json.dumps(meta, sort_keys=True)), **arrays)

    @classmethod
    def load(cls, path) -> WallKernelTable:
        """Read a table written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            arrays = {k: z[k] for k in _TABLE_ARRAYS}
        arrays = {k: (v.astype(np.float64) if v.dtype.kind == "f" else v) for k, v in arrays.items()}
        arrays["kernel"] = _physical(
            arrays["kernel"], arrays["angles_deg"], arrays["distances_rows"], arrays["offsets_rows"]
        )
        return cls(
            medium=Medium.from_dict(meta["medium"]),
            wall=meta["wall"],
            mm_per_row=float(meta["mm_per_row"]),
            params=meta["params"],
            **arrays,
        )


def wall_table_key(
    medium: Medium,
    *,
    wall,
    angles_deg,
    distances_rows,
    offsets_rows,
    mm_per_row,
    n_photons,
    slab_photons,
    seed,
    diffusion_depth_mfp=DIFFUSION_DEPTH_MFP,
) -> str:
    """File name of a wall table in the caches: ``wall-`` and a hash of everything it depends on."""
    params = dict(
        kind="wall-table",
        wall_version=WALL_VERSION,
        medium=as_medium(medium).to_dict(),
        wall=wall,
        angles_deg=[float(v) for v in angles_deg],
        distances_rows=[float(v) for v in distances_rows],
        mm_per_row=float(mm_per_row),
        n_photons=int(n_photons),
        slab_photons=int(slab_photons),
        seed=int(seed),
        diffusion_depth_mfp=None if diffusion_depth_mfp is None else float(diffusion_depth_mfp),
    )
    return f"wall-{cache_key(params, np.asarray(offsets_rows, dtype=np.int64))}.npz"


def wall_table_stored(medium: Medium, *, wall="fresnel", offsets_rows=None, mm_per_row=0.3) -> bool:
    """Whether the default :func:`mc_wall_table` of ``medium`` is shipped or cached (no Monte Carlo to run).

    Lets a front end say, before it starts, that tables will be traced (minutes each).
    """
    offsets = np.arange(-192, 193) if offsets_rows is None else np.asarray(offsets_rows, dtype=np.int64)
    name = wall_table_key(
        medium,
        wall=wall,
        angles_deg=np.asarray(TABLE_ANGLES_DEG, dtype=np.float64),
        distances_rows=np.asarray(TABLE_DISTANCES_ROWS, dtype=np.float64),
        offsets_rows=offsets,
        mm_per_row=mm_per_row,
        n_photons=TABLE_PHOTONS,
        slab_photons=TABLE_SLAB_PHOTONS,
        seed=0,
    )
    return (TABLES_DIR / name).exists() or (cache_dir() / name).exists()


def mc_wall_table(
    medium: Medium,
    *,
    wall="fresnel",
    angles_deg=TABLE_ANGLES_DEG,
    distances_rows=TABLE_DISTANCES_ROWS,
    offsets_rows=None,
    mm_per_row=0.3,
    n_photons=TABLE_PHOTONS,
    slab_photons=TABLE_SLAB_PHOTONS,
    seed=0,
    cache=True,
    progress=None,
) -> WallKernelTable:
    """Line kernels of ``medium`` beside a wall, at every tabulated distance and angle.

    The slab kernel is :func:`planeray.mc.mc_line_profile` (``slab_photons``); each wall
    kernel is that plus the wall's effect, estimated as the difference between a run
    with the wall (:func:`mc_wall_profile`, ``n_photons``) and one without it that traces
    the very same photons (the same per-photon random streams): photons that never meet
    the wall cancel exactly, so the difference carries only the noise of those that do
    (a control variate).  Far from the wall the kernel is the slab's, without added noise.

    Parameters
    ----------
    medium : Medium
    wall : {"fresnel", "absorbing"}
    angles_deg : sequence of float
        Wall angles in ``[0, 90]`` (see :func:`mc_wall_profile`).
    distances_rows : sequence of float
        Distances from the pixel to the wall, projector rows, increasing.
    offsets_rows : array_like of int, optional
        Offset bins; default ``-192 .. 192`` (:data:`planeray.kernels.MC_KERNEL_REACH_ROWS`).
    mm_per_row : float
        Size of a projector row on the surface (mm).
    n_photons, slab_photons : int
        Photons per wall run and of the slab kernel.
    seed : int
    cache : bool
        Look the table up in the shipped tables (:data:`planeray.mc.cache.TABLES_DIR`) and
        the disk cache, and store it there when computed.
    progress : callable, optional
        Called with 1 after each Monte Carlo run (``1 + 1 + A * D`` runs).

    Returns
    -------
    WallKernelTable
    """
    medium = as_medium(medium)
    _check_wall(wall)
    if offsets_rows is None:
        offsets_rows = np.arange(-192, 193)
    offsets = np.asarray(offsets_rows, dtype=np.int64)
    angles = np.asarray(angles_deg, dtype=np.float64)
    dists = np.asarray(distances_rows, dtype=np.float64)
    if angles.size == 0 or np.any(np.diff(angles) <= 0) or angles.min() < 0 or angles.max() > 90:
        raise InputError(f"angles_deg must increase within [0, 90], got {list(angles)}")
    if dists.size == 0 or np.any(np.diff(dists) <= 0) or dists.min() < 0:
        raise InputError(f"distances_rows must increase from >= 0, got {list(dists)}")
    name = wall_table_key(
        medium,
        wall=wall,
        angles_deg=angles,
        distances_rows=dists,
        offsets_rows=offsets,
        mm_per_row=mm_per_row,
        n_photons=n_photons,
        slab_photons=slab_photons,
        seed=seed,
    )
    path = cache_dir() / name
    if cache:
        for hit in (TABLES_DIR / name, path):
            if hit.exists():
                try:
                    return WallKernelTable.load(hit)
                except (OSError, ValueError, KeyError):
                    pass

    def tick():
        if progress is not None:
            progress(1)

    mm = float(mm_per_row)
    slab = mc_line_profile(medium, n_photons=slab_photons, offsets_rows=offsets, mm_per_row=mm, seed=seed, cache=cache)
    tick()
    base = dict(n_photons=int(n_photons), offsets_rows=offsets, mm_per_row=mm, seed=seed, wall=wall)
    ref_params = _wall_params(medium, offsets, wall_distance_mm=math.inf, wall_angle_deg=0.0, **base)
    _, ref = _run_wall(medium, offsets, ref_params)
    tick()
    to_lambert = np.pi * mm
    kernel = np.empty((angles.size, dists.size, offsets.size))
    kernel_err = np.empty_like(kernel)
    wall_loss = np.empty((angles.size, dists.size))
    n_b = ref.shape[0]
    for i, ang in enumerate(angles):
        for j, dist in enumerate(dists):
            params = _wall_params(medium, offsets, wall_distance_mm=dist * mm, wall_angle_deg=ang, **base)
            prof, batches = _run_wall(medium, offsets, params)
            diff = batches - ref
            kernel[i, j] = to_lambert * (slab.radiance + diff.mean(axis=0))
            kernel_err[i, j] = to_lambert * np.hypot(slab.radiance_stderr, diff.std(axis=0, ddof=1) / math.sqrt(n_b))
            wall_loss[i, j] = prof.wall_loss
            tick()
    table = WallKernelTable(
        medium=medium,
        wall=wall,
        mm_per_row=mm,
        offsets_rows=offsets.copy(),
        angles_deg=angles,
        distances_rows=dists,
        kernel=_physical(kernel, angles, dists, offsets),
        kernel_stderr=kernel_err,
        wall_loss=wall_loss,
        slab=to_lambert * slab.radiance,
        slab_stderr=to_lambert * slab.radiance_stderr,
        params=dict(
            n_photons=int(n_photons),
            slab_photons=int(slab_photons),
            seed=int(seed),
            wall_version=WALL_VERSION,
            engine_version=ENGINE_VERSION,
            slab_total_reflectance=slab.total_reflectance,
            diffusion_depth_mfp=DIFFUSION_DEPTH_MFP,
        ),
    )
    if cache:
        write_or_warn(table.save, path)
    return table
