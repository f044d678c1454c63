"""Scalar optics of the Monte Carlo engine: Fresnel reflectance and the Henyey-Greenstein phase function.

Compiled (Numba) for the photon kernel, with NumPy wrappers for tests and users.

References
----------
.. [2] S. A. Prahl, M. Keijzer, S. L. Jacques, A. J. Welch, "A Monte Carlo model
   of light propagation in tissue", SPIE IS 5, 1989.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["fresnel_unpolarized", "sample_hg_cos", "hg_phase"]


@numba.njit(cache=True, inline="always")
def fresnel_jit(cos_i, n):
    """Unpolarized Fresnel reflectance from inside (index ``n``) to outside (index 1)."""
    if n == 1.0:
        return 0.0
    cos_i = min(max(cos_i, 0.0), 1.0)
    sin_t2 = n * n * (1.0 - cos_i * cos_i)
    if sin_t2 >= 1.0:
        return 1.0
    cos_t = math.sqrt(1.0 - sin_t2)
    rs = (n * cos_i - cos_t) / (n * cos_i + cos_t)
    rp = (cos_i - n * cos_t) / (cos_i + n * cos_t)
    return 0.5 * (rs * rs + rp * rp)


@numba.njit(cache=True, inline="always")
def hg_cos_jit(xi, g):
    """Inverse-CDF sample of the HG scattering cosine (Prahl 1989 [2]_)."""
    if abs(g) < 1e-6:
        return 2.0 * xi - 1.0
    t = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi)
    return min(max((1.0 + g * g - t * t) / (2.0 * g), -1.0), 1.0)


@numba.njit(cache=True, inline="always")
def hg_scatter_jit(ux, uy, uz, g, xi_cos, xi_phi):
    """New unit direction after an HG scattering event (MCML's rotation, Wang et al. 1995).

    ``xi_cos`` draws the polar cosine (:func:`hg_cos_jit`), ``xi_phi`` the uniform
    azimuth; the new direction is rotated into the frame of ``(ux, uy, uz)`` and
    renormalized.
    """
    ct = hg_cos_jit(xi_cos, g)
    st = math.sqrt(max(1.0 - ct * ct, 0.0))
    phi = 2.0 * math.pi * xi_phi
    cp = math.cos(phi)
    sp = math.sin(phi)
    den2 = 1.0 - uz * uz
    if den2 < 1e-10:
        sgn = 1.0 if uz >= 0.0 else -1.0
        nux = st * cp
        nuy = st * sp
        nuz = sgn * ct
    else:
        den = math.sqrt(den2)
        a = st / den
        nux = a * (ux * uz * cp - uy * sp) + ux * ct
        nuy = a * (uy * uz * cp + ux * sp) + uy * ct
        nuz = -st * cp * den + uz * ct
    norm = 1.0 / math.sqrt(nux * nux + nuy * nuy + nuz * nuz)
    return nux * norm, nuy * norm, nuz * norm


@numba.njit(cache=True, inline="always")
def hg_pdf_jit(mu, g):
    """HG phase function per steradian, ``(1 - g^2) / (4 pi (1 + g^2 - 2 g mu)^1.5)``."""
    q = 1.0 + g * g - 2.0 * g * mu
    return (1.0 - g * g) / (4.0 * math.pi * q * math.sqrt(q))


@numba.njit(cache=True)
def _fresnel_array(cos_i, n, out):
    for i in range(cos_i.size):
        out[i] = fresnel_jit(cos_i[i], n)


@numba.njit(cache=True)
def _hg_cos_array(xi, g, out):
    for i in range(xi.size):
        out[i] = hg_cos_jit(xi[i], g)


@numba.njit(cache=True)
def _hg_pdf_array(mu, g, out):
    for i in range(mu.size):
        out[i] = hg_pdf_jit(mu[i], g)


def _apply(kernel, x, *args):
    x = np.asarray(x, dtype=np.float64)
    flat = np.ascontiguousarray(x).ravel()
    out = np.empty_like(flat)
    kernel(flat, *[float(a) for a in args], out)
    return out.reshape(x.shape)


def fresnel_unpolarized(cos_i, n):
    """Unpolarized Fresnel reflectance for light inside a medium of index ``n``
    hitting a face to index 1 at incidence cosine ``cos_i``; 1 beyond the critical angle.

    Parameters
    ----------
    cos_i : array_like
        Cosine of the incidence angle, clipped to ``[0, 1]``.
    n : float
        Relative refractive index (inside / outside).

    Returns
    -------
    ndarray of float64
        Reflectance ``(r_s^2 + r_p^2) / 2``.

    See Also
    --------
    planeray.mc_line_profile : the engine that uses it.

    Examples
    --------
    Inside water (n = 1.33) at normal incidence 2 % is reflected; past the critical angle all of it:

    >>> round(float(fresnel_unpolarized(1.0, 1.33)), 3), float(fresnel_unpolarized(0.3, 1.33))
    (0.02, 1.0)
    """
    return _apply(_fresnel_array, cos_i, n)


def sample_hg_cos(xi, g):
    """Sample the cosine of the Henyey-Greenstein scattering angle (Prahl 1989 [2]_).

    ``cos = (1 + g^2 - ((1 - g^2) / (1 - g + 2 g xi))^2) / (2 g)``, and
    ``cos = 2 xi - 1`` for ``g = 0`` (isotropic).

    Parameters
    ----------
    xi : array_like
        Uniform variates in ``[0, 1)``.
    g : float
        Anisotropy, ``-1 < g < 1``.

    Returns
    -------
    ndarray
        Cosines of the scattering angle, in [-1, 1].

    See Also
    --------
    hg_phase : the density it samples.

    Examples
    --------
    The mean cosine of Henyey-Greenstein scattering is ``g``:

    >>> import numpy as np
    >>> xi = (np.arange(100_000) + 0.5) / 100_000
    >>> round(float(sample_hg_cos(xi, 0.9).mean()), 3)
    0.9
    """
    return _apply(_hg_cos_array, xi, g)


def hg_phase(mu, g):
    """Henyey-Greenstein phase function ``p(mu)`` per steradian (integrates to 1 over the sphere).

    Parameters
    ----------
    mu : array_like
        Cosine of the scattering angle.
    g : float
        Anisotropy, -1 < g < 1.

    Returns
    -------
    ndarray
        ``p(mu)`` per steradian.

    See Also
    --------
    sample_hg_cos : draws from it.

    Examples
    --------
    >>> import numpy as np
    >>> mu = np.linspace(-1, 1, 20001)
    >>> round(float(np.trapezoid(hg_phase(mu, 0.8), mu) * 2 * np.pi), 4)  # integrates to 1
    1.0
    """
    return _apply(_hg_pdf_array, mu, g)
