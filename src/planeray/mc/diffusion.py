"""Diffusion theory of a semi-infinite medium: the dipole (Jensen et al. 2001, Farrell et al. 1992) and the
hybrid Monte Carlo-diffusion hand-off (Wang & Jacques 1993).

* :func:`dipole_reflectance`, :func:`dipole_total_reflectance`, :func:`dipole_line_kernel`:
  the classical point-source dipole, its total reflectance and its integral along a
  lit line binned to projector rows (the ``"dipole"`` scene kernel), of a
  semi-infinite :class:`~planeray.medium.Medium` -- which they see only through
  ``sigma_a``, the reduced scattering ``sigma_s' = sigma_s (1 - g)`` and ``n``;
* :func:`k1_line_law`: the one line law of diffusion theory -- the exit flux of a point
  source at depth ``z``, integrated along a line: ``z sigma_tr K1(sigma_tr rho) / rho``
  (Farrell et al. [5]_ integrated along ``y``) -- that every line kernel below, the fit's
  wall images (:mod:`planeray.kernels.walls`) and the quarter space are sums of;
* :func:`diffusion_exit`, :func:`diffusion_normal_radiance_ratio`: where photons handed
  to diffusion at some depth leave the surface, and with what normal radiance (used
  by :mod:`planeray.mc.engine`);
* :class:`QuarterSpace`: the same hand-off beside a vertical container wall (the method
  of images of Haskell et al. [7]_ for the wall's extrapolated boundary; used by
  :mod:`planeray.mc.wall`), with :func:`exits_parallel` and :func:`exits_oblique`.

References
----------
.. [1] H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan, "A practical model
   for subsurface light transport", SIGGRAPH 2001.
.. [5] T. J. Farrell, M. S. Patterson, B. Wilson, "A diffusion theory model of
   spatially resolved, steady-state diffuse reflectance", Med. Phys. 19, 1992.
.. [6] L. Wang, S. L. Jacques, "Hybrid model of Monte Carlo simulation and
   diffusion theory for light reflectance by turbid media", JOSA A 10, 1993.
.. [7] R. C. Haskell, L. O. Svaasand, T.-T. Tsay, T.-C. Feng, M. S. McAdams, B. J.
   Tromberg, "Boundary conditions for the diffusion equation in radiative transfer",
   JOSA A 11(10), 2727-2741, 1994.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy.special import k1e

from ..errors import InputError
from ..medium import Medium, as_medium
from .physics import fresnel_unpolarized

__all__ = [
    "DIFFUSION_DEPTH_MFP",
    "k1_line_law",
    "QuarterSpace",
    "quarter_space",
    "exits_parallel",
    "exits_oblique",
    "boundary_mismatch_A",
    "dipole_reflectance",
    "dipole_total_reflectance",
    "dipole_line_kernel",
    "diffusion_exit",
    "diffusion_normal_radiance_ratio",
]


#: Default depth (transport mean free paths) at which photons in a half-space are
#: handed to diffusion theory; see :func:`planeray.mc.mc_line_profile`.
DIFFUSION_DEPTH_MFP = 10.0


def k1_line_law(rho_mm, z_mm, sigma_tr):
    """The line law of diffusion theory: one source's exit flux integrated along a line, times ``2 pi``.

    A point source at depth ``z`` (a dipole's real or image source, signed) sends
    ``z (sigma_tr r + 1) exp(-sigma_tr r) / (4 pi r^3)`` per mm^2 through the surface at
    distance ``r`` (Farrell et al. [5]_, Eq. 5 of the dipole); integrated along a line at
    lateral distance ``x`` it is ``z sigma_tr K1(sigma_tr rho) / (2 pi rho)``,
    ``rho = sqrt(x^2 + z^2)``, and ``z / (2 pi rho^2)`` without absorption (``sigma_tr = 0``).
    Returns the law without its ``1 / (2 pi)`` (callers divide once, after summing).

    Parameters
    ----------
    rho_mm : float or ndarray
        Distance ``rho`` from the source to the line (any length unit, the same as ``z``).
    z_mm : float or ndarray
        The source's depth (signed; 1 gives the flux per unit depth).
    sigma_tr : float
        Effective attenuation ``sqrt(3 sigma_a (sigma_a + sigma_s'))`` in the inverse unit.
    """
    if sigma_tr > 0.0:
        return z_mm * sigma_tr * k1e(sigma_tr * rho_mm) * np.exp(-sigma_tr * rho_mm) / rho_mm
    return z_mm / (rho_mm * rho_mm)


def boundary_mismatch_A(eta):
    """Internal-reflection parameter ``A = (1 + F_dr) / (1 - F_dr)`` of the diffusion
    boundary condition, with Groenhuis' fit ``F_dr(eta)`` [1]_ (``A ~ 1`` for ``eta = 1``).
    The extrapolated boundary sits ``2 A D`` above the surface.

    Parameters
    ----------
    eta : float
        Relative refractive index of the medium.

    Returns
    -------
    float
        ``A``.

    See Also
    --------
    dipole_reflectance : uses it.

    Examples
    --------
    >>> round(float(boundary_mismatch_A(1.0)), 2), round(float(boundary_mismatch_A(1.4)), 2)
    (1.0, 3.25)
    """
    f_dr = -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta
    return (1.0 + f_dr) / (1.0 - f_dr)


def _dipole_medium(medium) -> tuple[float, float, float]:
    """``(sigma_a, sigma_s', n)`` of a semi-infinite medium (the dipole knows nothing else)."""
    medium = as_medium(medium)
    if not medium.semi_infinite:
        raise InputError(f"the diffusion dipole models a semi-infinite medium, got thickness_mm {medium.thickness_mm}")
    return medium.sigma_a, medium.sigma_s_prime, medium.n


def _dipole_constants(sigma_a, sigma_s_prime, eta):
    sigma_t = sigma_a + sigma_s_prime
    albedo = sigma_s_prime / sigma_t
    sigma_tr = np.sqrt(3.0 * sigma_a * sigma_t)
    A = boundary_mismatch_A(eta)
    z_r = 1.0 / sigma_t
    z_v = z_r * (1.0 + 4.0 * A / 3.0)
    return albedo, sigma_tr, z_r, z_v, A


def _reflectance(r_mm, sigma_a, sigma_s_prime, eta):
    albedo, sigma_tr, z_r, z_v, _ = _dipole_constants(sigma_a, sigma_s_prime, eta)
    r2 = np.asarray(r_mm, dtype=float) ** 2
    d_r = np.sqrt(r2 + z_r**2)
    d_v = np.sqrt(r2 + z_v**2)
    return (
        albedo
        / (4 * np.pi)
        * (
            z_r * (sigma_tr * d_r + 1) * np.exp(-sigma_tr * d_r) / d_r**3
            + z_v * (sigma_tr * d_v + 1) * np.exp(-sigma_tr * d_v) / d_v**3
        )
    )


def dipole_reflectance(medium: Medium, r_mm):
    """Diffuse reflectance ``R_d(r)`` (per mm^2) of a point source, dipole model [1]_.

    Parameters
    ----------
    medium : Medium
        A semi-infinite medium; the dipole uses ``sigma_a``, ``sigma_s_prime`` and ``n``.
    r_mm : array_like of float
        Distances from the entry point, mm.

    Returns
    -------
    ndarray
        ``R_d(r)`` per mm^2 (fraction of the incident power).

    See Also
    --------
    dipole_total_reflectance : its integral.
    dipole_line_kernel : a lit line.

    Examples
    --------
    >>> from planeray.medium import Medium
    >>> m = Medium(sigma_s=1.0, sigma_a=0.01, g=0.0)
    >>> r = dipole_reflectance(m, [0.5, 5.0])  # per mm^2, at 0.5 and 5 mm
    >>> bool(r[0] > r[1] > 0)
    True
    """
    sigma_a, sigma_s_prime, eta = _dipole_medium(medium)
    return _reflectance(r_mm, sigma_a, sigma_s_prime, eta)


def dipole_total_reflectance(medium: Medium):
    """Total diffuse reflectance ``R_d = int R_d(r) 2 pi r dr`` of the dipole (closed form [1]_).

    ``medium`` is semi-infinite; only ``sigma_a``, ``sigma_s_prime`` and ``n`` matter.

    Parameters
    ----------
    medium : Medium
        The medium (1/mm coefficients, index ``n``).

    Returns
    -------
    float
        The fraction of the incident power that leaves the surface.

    See Also
    --------
    dipole_reflectance : per distance.

    Examples
    --------
    >>> from planeray.medium import Medium
    >>> round(float(dipole_total_reflectance(Medium(sigma_s=1.0, sigma_a=0.01, g=0.0))), 3)
    0.748
    """
    albedo, _, _, _, A = _dipole_constants(*_dipole_medium(medium))
    s = np.sqrt(3.0 * (1.0 - albedo))
    return 0.5 * albedo * (1.0 + np.exp(-4.0 / 3.0 * A * s)) * np.exp(-s)


def dipole_line_kernel(medium: Medium, offsets_rows, *, mm_per_row, subsamples=16):
    """Reflectance of a lit line, binned to projector-row offsets.

    ``R_line(x) = int R_d(sqrt(x^2 + y^2)) dy`` integrated over each offset bin
    ``[k - 1/2, k + 1/2) * mm_per_row`` (midpoint rule on ``subsamples`` points per
    bin, Gauss-Legendre along the line).

    Parameters
    ----------
    medium : Medium
        A semi-infinite medium; the dipole uses ``sigma_a``, the reduced
        scattering coefficient ``sigma_s_prime`` and the relative index ``n``.
    offsets_rows : array_like of int
        Offset bins ``k`` in projector rows.
    mm_per_row : float
        Size of one projector row on the surface, in mm.
    subsamples : int
        Midpoint-rule points per bin across the line.

    Returns
    -------
    kernel : ndarray of float64
        Light reaching each bin per unit of line illumination; sums to the total
        diffuse reflectance of the medium when the bins cover the whole profile.

    See Also
    --------
    dipole_reflectance : the point source.
    planeray.line_kernel : the kernel a scene uses.

    Examples
    --------
    >>> import numpy as np
    >>> from planeray.medium import Medium
    >>> k = dipole_line_kernel(Medium(sigma_s=1.0, sigma_a=0.01, g=0.0), np.arange(-3, 4), mm_per_row=0.5)
    >>> k.shape, bool(np.allclose(k, k[::-1]))
    ((7,), True)
    """
    sigma_a, sigma_s_prime, eta = _dipole_medium(medium)
    k = np.asarray(offsets_rows, dtype=float)
    frac = (np.arange(subsamples) + 0.5) / subsamples - 0.5
    x = (k[:, None] + frac[None, :]) * mm_per_row  # (K, S) mm across the line
    # Integrate along the line with a change of variable y = z tan(theta) that
    # handles the heavy tail: int_0^inf f(y) dy over theta in (0, pi/2).
    nodes, wts = np.polynomial.legendre.leggauss(64)
    theta = 0.25 * np.pi * (nodes + 1.0)
    jac = 0.25 * np.pi * wts
    scale = np.maximum(np.abs(x), 1.0 / (sigma_a + sigma_s_prime))[..., None]
    y = scale * np.tan(theta)
    dy = scale / np.cos(theta) ** 2
    R = _reflectance(np.sqrt(x[..., None] ** 2 + y**2), sigma_a, sigma_s_prime, eta)
    line = 2.0 * np.sum(R * dy * jac, axis=-1)  # per mm across the line
    return line.mean(axis=1) * mm_per_row


def diffusion_exit(hist, hmin, out_bins, mm_per_row, z_mm, sigma_a, sigma_tp, n):
    """Where photons diffusing from depth ``z_mm`` leave the top face (hybrid MC-diffusion).

    The 2-D diffusion dipole of a line source at depth ``z`` (the line along
    ``y``, so the problem is 2-D in ``x, z``) with an extrapolated boundary
    ``z_b = 2 A D`` above the surface (Farrell et al. [5]_, integrated along the
    line) gives the exiting flux at lateral offset ``x``::

        J(x) = (1 / 2 pi) sum_{z_i in (z, z + 2 z_b)} z_i sigma_tr K1(sigma_tr r_i) / r_i,
        r_i = sqrt(x^2 + z_i^2),

    (``z_i / r_i^2`` for ``sigma_a = 0``) whose integral, the fraction that
    leaves at all, is ``(exp(-sigma_tr z) + exp(-sigma_tr (z + 2 z_b))) / 2``
    (1 without absorption).  Bins are integrated exactly up to Gauss-Legendre
    quadrature, a source spread uniformly over its histogram bin.

    Parameters
    ----------
    hist : ndarray (B, nh)
        Continued weight per batch by the bin ``hmin + j`` of its crossing point.
    hmin : int
        Bin of ``hist[:, 0]``.
    out_bins : ndarray of int
        Output bins.
    mm_per_row, z_mm, sigma_a, sigma_tp, n : float
        Bin width, continuation depth, absorption, transport coefficient
        ``sigma_a + sigma_s (1 - g)`` and relative index.

    Returns
    -------
    exit_bins : ndarray (B, len(out_bins))
        Weight leaving through each output bin.
    exit_total : float
        Fraction of the continued weight that leaves the medium (anywhere).

    See Also
    --------
    planeray.mc_line_profile : the engine that hands photons to it.

    Examples
    --------
    A unit of weight handed to diffusion 2 mm deep under bin 0, leaving through bins -2..2 (1 mm each):

    >>> import numpy as np
    >>> exit_bins, total = diffusion_exit(np.array([[1.0]]), 0, np.arange(-2, 3), 1.0, 2.0, 0.01, 1.0, 1.0)
    >>> exit_bins.shape, bool(np.allclose(exit_bins, exit_bins[:, ::-1])), bool(0 < total < 1)
    ((1, 5), True, True)
    """
    sigma_tr = math.sqrt(3.0 * sigma_a * sigma_tp)
    z_b = 2.0 * boundary_mismatch_A(n) / (3.0 * sigma_tp)
    depths = np.array([z_mm, z_mm + 2.0 * z_b])
    nh = hist.shape[1]
    m = np.arange(int(out_bins.min()) - (hmin + nh - 1), int(out_bins.max()) - hmin + 1)
    # Triangle weight: source uniform over its bin, flux integrated over the output bin.
    t, wt = np.polynomial.legendre.leggauss(16)
    t = 0.5 * (t + 1.0)  # (0, 1)
    wt = 0.5 * wt
    u = np.concatenate([m[:, None] - 1.0 + t[None, :], m[:, None] + t[None, :]], axis=1) * mm_per_row
    tri = np.concatenate([t, 1.0 - t])[None, :] * np.concatenate([wt, wt])[None, :]
    flux = np.zeros_like(u)
    for zi in depths:
        flux += k1_line_law(np.hypot(u, zi), zi, sigma_tr)
    P = (flux * tri).sum(axis=1) * mm_per_row / (2.0 * np.pi)
    idx = out_bins[None, :] - (hmin + np.arange(nh))[:, None] - m[0]
    exit_bins = hist @ P[idx]
    exit_total = 0.5 * float(np.exp(-sigma_tr * depths[0]) + np.exp(-sigma_tr * depths[1]))
    return exit_bins, exit_total


def diffusion_normal_radiance_ratio(n):
    """Normal-view radiance per unit exitance of diffuse light leaving a medium of index ``n``.

    In the diffusion (P1) approximation with the extrapolated boundary the
    radiance inside the surface is ``L(mu) ~ 2A + 3 mu`` (``mu`` toward the
    outside); outside, the normal radiance is ``L(1) (1 - R(1)) / n^2`` and the
    exitance ``2 pi int L(mu) (1 - R(mu)) mu dmu``.  0.398 sr^-1 for ``n = 1``
    (Lambertian: 1/pi = 0.318; Chandrasekhar's exact H-function value: 0.401).

    Parameters
    ----------
    n : float
        Relative refractive index of the medium.

    Returns
    -------
    float
        Radiance per unit exitance, 1/sr.

    See Also
    --------
    planeray.mc_line_profile : its ``radiance``.

    Examples
    --------
    >>> round(float(diffusion_normal_radiance_ratio(1.0)), 3)  # per steradian
    0.398
    """
    A = boundary_mismatch_A(n)
    mu, wt = np.polynomial.legendre.leggauss(64)
    mu = 0.5 * (mu + 1.0)
    wt = 0.5 * wt
    T = 1.0 - fresnel_unpolarized(mu, n)
    exitance = 2.0 * np.pi * np.sum(wt * (2.0 * A + 3.0 * mu) * T * mu)
    return float((2.0 * A + 3.0) * (1.0 - fresnel_unpolarized(1.0, n)) / (n * n) / exitance)


# ---------------------------------------------------------------- diffusion with a wall
class QuarterSpace:
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
            out += k1_line_law(np.hypot(xi, zi), zi, self.sigma_tr)
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
                    kern = k1_line_law(math.hypot(dx, z - z_i), 1.0, s_tr)
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
def quarter_space(z_c, sigma_a, sigma_tp, n, n_wall) -> QuarterSpace:
    """The hand-off geometry of a medium and wall, shared by every run (its exit laws are cached)."""
    return QuarterSpace(z_c, sigma_a, sigma_tp, n, n_wall)


def _tri_points():
    """Quadrature of a triangle density on ``[-1, 1]`` (source uniform in one bin, exit in another)."""
    t, wt = np.polynomial.legendre.leggauss(16)
    t = 0.5 * (t + 1.0)
    wt = 0.5 * wt
    return np.concatenate([t - 1.0, t]), np.concatenate([t * wt, (1.0 - t) * wt])


def exits_parallel(cont, hmin, out_bins, mm, q: QuarterSpace, wall_a):
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

    def __init__(self, q: QuarterSpace, dx_max, t_max):
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


def exits_oblique(cont, hmin, out_bins, mm, q: QuarterSpace, phi, dbin):
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


def _oblique_laws(q: QuarterSpace, m, mm, phi, deltas):
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
