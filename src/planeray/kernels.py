"""Subsurface-scattering kernels: how much light a line of illumination sends to
points at a given distance, binned to projector rows.

Two models of the same quantity -- what a camera row sees when one projector
row lights a semi-infinite homogeneous medium, binned to projector-row offsets:

* ``"dipole"``: the classical diffusion dipole (Jensen et al. 2001) integrated
  along the illuminated line (:func:`dipole_line_kernel`); instant and smooth,
  but it only knows ``sigma_s' = sigma_s (1 - g)`` and misses the
  single-scattering peak near the line;
* ``"mc"``: the Monte Carlo exitance profile of a Henyey-Greenstein medium
  (:func:`mc_line_kernel`, :mod:`planeray.mc`), cached on disk.

:func:`line_kernel` picks one by name; scenes call it.

References
----------
.. [1] H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan, "A practical model
   for subsurface light transport", SIGGRAPH 2001.
.. [2] T. J. Farrell, M. S. Patterson, B. Wilson, "A diffusion theory model of
   spatially resolved, steady-state diffuse reflectance", Med. Phys. 19, 1992.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "boundary_mismatch_A",
    "dipole_reflectance",
    "dipole_total_reflectance",
    "dipole_line_kernel",
    "mc_line_kernel",
    "line_kernel",
    "KERNEL_MODELS",
]

#: Names accepted by :func:`line_kernel`.
KERNEL_MODELS = ("mc", "dipole")
#: Photons per Monte Carlo scene kernel: ~1 % relative error within ~10 transport
#: mean free paths of the line; computed once per parameter set and cached.
MC_KERNEL_PHOTONS = 1_000_000
#: Smallest canonical half-range of a Monte Carlo scene kernel: covers the default
#: scene band (128 rows) plus a camera-row footprint.
MC_KERNEL_REACH_ROWS = 192


def boundary_mismatch_A(eta):
    """Internal-reflection parameter ``A = (1 + F_dr) / (1 - F_dr)`` of the diffusion
    boundary condition, with Groenhuis' fit ``F_dr(eta)`` [1]_ (``A ~ 1`` for ``eta = 1``).
    The extrapolated boundary sits ``2 A D`` above the surface."""
    f_dr = -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta
    return (1.0 + f_dr) / (1.0 - f_dr)


def _dipole_constants(sigma_a, sigma_s_prime, eta):
    sigma_t = sigma_a + sigma_s_prime
    albedo = sigma_s_prime / sigma_t
    sigma_tr = np.sqrt(3.0 * sigma_a * sigma_t)
    A = boundary_mismatch_A(eta)
    z_r = 1.0 / sigma_t
    z_v = z_r * (1.0 + 4.0 * A / 3.0)
    return albedo, sigma_tr, z_r, z_v, A


def dipole_reflectance(r_mm, sigma_a, sigma_s_prime, eta=1.4):
    """Diffuse reflectance ``R_d(r)`` (per mm^2) of a point source, dipole model [1]_."""
    albedo, sigma_tr, z_r, z_v, _ = _dipole_constants(sigma_a, sigma_s_prime, eta)
    r2 = np.asarray(r_mm, dtype=float) ** 2
    d_r = np.sqrt(r2 + z_r**2)
    d_v = np.sqrt(r2 + z_v**2)
    return albedo / (4 * np.pi) * (
        z_r * (sigma_tr * d_r + 1) * np.exp(-sigma_tr * d_r) / d_r**3
        + z_v * (sigma_tr * d_v + 1) * np.exp(-sigma_tr * d_v) / d_v**3
    )


def dipole_total_reflectance(sigma_a, sigma_s_prime, eta=1.4):
    """Total diffuse reflectance ``R_d = int R_d(r) 2 pi r dr`` of the dipole (closed form [1]_)."""
    albedo, _, _, _, A = _dipole_constants(sigma_a, sigma_s_prime, eta)
    s = np.sqrt(3.0 * (1.0 - albedo))
    return 0.5 * albedo * (1.0 + np.exp(-4.0 / 3.0 * A * s)) * np.exp(-s)


def dipole_line_kernel(offsets_rows, mm_per_row, sigma_a, sigma_s_prime, eta=1.4, subsamples=16):
    """Reflectance of a lit line, binned to projector-row offsets.

    ``R_line(x) = int R_d(sqrt(x^2 + y^2)) dy`` integrated over each offset bin
    ``[k - 1/2, k + 1/2) * mm_per_row`` (midpoint rule on ``subsamples`` points per
    bin, Gauss-Legendre along the line).

    Parameters
    ----------
    offsets_rows : array_like of int
        Offset bins ``k`` in projector rows.
    mm_per_row : float
        Size of one projector row on the surface, in mm.
    sigma_a, sigma_s_prime : float
        Absorption and reduced scattering coefficients, mm^-1.
    eta : float
        Relative refractive index of the medium.

    Returns
    -------
    kernel : ndarray of float64
        Light reaching each bin per unit of line illumination; sums to the total
        diffuse reflectance of the medium when the bins cover the whole profile.
    """
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
    R = dipole_reflectance(np.sqrt(x[..., None] ** 2 + y**2), sigma_a, sigma_s_prime, eta)
    line = 2.0 * np.sum(R * dy * jac, axis=-1)  # per mm across the line
    return line.mean(axis=1) * mm_per_row


def mc_line_kernel(offsets_rows, mm_per_row, sigma_a, sigma_s, g, eta=1.4,
                   n_photons=MC_KERNEL_PHOTONS, seed=0):
    """Monte Carlo line kernel: the exitance profile of :func:`planeray.mc.mc_line_profile`.

    The profile is traced once over a canonical symmetric range (at least
    ``MC_KERNEL_REACH_ROWS``, more in steps of 64 for wider offsets) and cached
    on disk, so scenes of any size with the same medium reuse it; the default
    wax medium ships precomputed (:data:`planeray.mc.engine.TABLES_DIR`).

    Parameters
    ----------
    offsets_rows : array_like of int
        Offset bins ``k`` in projector rows.
    mm_per_row : float
        Size of one projector row on the surface, in mm.
    sigma_a, sigma_s : float
        Absorption and scattering coefficients, mm^-1.
    g : float
        Henyey-Greenstein anisotropy.
    eta : float
        Relative refractive index (Fresnel boundary).

    Returns
    -------
    kernel : ndarray of float64
        Diffusely reflected power per bin per unit line power.
    total : float
        Total diffuse reflectance of the medium (all exit positions).
    """
    from .mc import mc_line_profile

    k = np.asarray(offsets_rows, dtype=np.int64)
    reach = max(MC_KERNEL_REACH_ROWS, int(64 * np.ceil((np.abs(k).max() + 1) / 64.0)))
    canon = np.arange(-reach, reach + 1)
    prof = mc_line_profile(sigma_s, sigma_a, g, n=eta, n_photons=n_photons, offsets_rows=canon,
                           mm_per_row=mm_per_row, seed=seed, cache=True)
    return prof.values[k + reach], prof.total_reflectance


def line_kernel(model, offsets_rows, mm_per_row, sigma_a, sigma_s_prime, eta=1.4, g=0.8):
    """Binned line kernel and the medium's total diffuse reflectance, by model name.

    Parameters
    ----------
    model : {"mc", "dipole"}
        See the module docstring.
    sigma_s_prime : float
        Reduced scattering coefficient; the Monte Carlo medium has
        ``sigma_s = sigma_s_prime / (1 - g)`` with HG anisotropy ``g`` (the
        similarity relation, so both models describe the same diffusion regime).

    Returns
    -------
    kernel : ndarray of float64
    total : float
    """
    if model == "dipole":
        return (dipole_line_kernel(offsets_rows, mm_per_row, sigma_a, sigma_s_prime, eta),
                float(dipole_total_reflectance(sigma_a, sigma_s_prime, eta)))
    if model == "mc":
        return mc_line_kernel(offsets_rows, mm_per_row, sigma_a, sigma_s_prime / (1.0 - g), g, eta)
    raise ValueError(f"unknown kernel model {model!r}; expected one of {KERNEL_MODELS}")
