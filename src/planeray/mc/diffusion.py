"""Diffusion theory of a semi-infinite medium: the dipole (Jensen et al. 2001, Farrell et al. 1992) and the
hybrid Monte Carlo-diffusion hand-off (Wang & Jacques 1993).

* :func:`dipole_reflectance`, :func:`dipole_total_reflectance`, :func:`dipole_line_kernel`:
  the classical point-source dipole, its total reflectance and its integral along a
  lit line binned to projector rows (the ``"dipole"`` scene kernel), of a
  semi-infinite :class:`~planeray.medium.Medium` -- which they see only through
  ``sigma_a``, the reduced scattering ``sigma_s' = sigma_s (1 - g)`` and ``n``;
* :func:`diffusion_exit`, :func:`diffusion_normal_radiance_ratio`: where photons handed
  to diffusion at some depth leave the surface, and with what normal radiance (used
  by :mod:`planeray.mc.engine`).

References
----------
.. [1] H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan, "A practical model
   for subsurface light transport", SIGGRAPH 2001.
.. [5] T. J. Farrell, M. S. Patterson, B. Wilson, "A diffusion theory model of
   spatially resolved, steady-state diffuse reflectance", Med. Phys. 19, 1992.
.. [6] L. Wang, S. L. Jacques, "Hybrid model of Monte Carlo simulation and
   diffusion theory for light reflectance by turbid media", JOSA A 10, 1993.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import k1e

from ..errors import InputError
from ..medium import Medium, as_medium
from .physics import fresnel_unpolarized

__all__ = [
    "boundary_mismatch_A",
    "dipole_reflectance",
    "dipole_total_reflectance",
    "dipole_line_kernel",
    "diffusion_exit",
    "diffusion_normal_radiance_ratio",
]


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
        r = np.hypot(u, zi)
        if sigma_tr > 0.0:
            flux += zi * sigma_tr * k1e(sigma_tr * r) * np.exp(-sigma_tr * r) / r
        else:
            flux += zi / (r * r)
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
