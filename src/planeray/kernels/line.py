"""Subsurface-scattering kernels: how much light a line of illumination sends to
points at a given distance, binned to projector rows.

Two models of the same quantity -- what a camera row sees when one projector
row lights a semi-infinite homogeneous medium, binned to projector-row offsets:

* ``"dipole"``: the classical diffusion dipole (Jensen et al. 2001) integrated
  along the illuminated line (:func:`planeray.mc.diffusion.dipole_line_kernel`); instant and smooth,
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

from ..errors import InputError
from ..mc import mc_line_profile
from ..mc.diffusion import (
    boundary_mismatch_A,
    dipole_line_kernel,
    dipole_reflectance,
    dipole_total_reflectance,
)
from ..medium import Medium, as_medium

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


def mc_line_kernel(medium: Medium, offsets_rows, *, mm_per_row, n_photons=MC_KERNEL_PHOTONS, seed=0):
    """Monte Carlo line kernel: the exitance profile of :func:`planeray.mc.mc_line_profile`.

    The profile is traced once over a canonical symmetric range (at least
    ``MC_KERNEL_REACH_ROWS``, more in steps of 64 for wider offsets) and cached
    on disk, so scenes of any size with the same medium reuse it; the default
    wax medium ships precomputed (:data:`planeray.mc.cache.TABLES_DIR`).

    Parameters
    ----------
    medium : Medium
        The HG medium (``sigma_s``, ``sigma_a``, ``g``, ``n``: Fresnel boundary).
    offsets_rows : array_like of int
        Offset bins ``k`` in projector rows.
    mm_per_row : float
        Size of one projector row on the surface, in mm.
    n_photons : int
        Photon packets of the canonical profile.
    seed : int
        Its seed.

    Returns
    -------
    kernel : ndarray of float64
        Diffusely reflected power per bin per unit line power.
    total : float
        Total diffuse reflectance of the medium (all exit positions).

    See Also
    --------
    planeray.mc.mc_line_profile : the Monte Carlo profile.
    planeray.line_kernel : by model name.

    Examples
    --------
    >>> import numpy as np
    >>> from planeray.medium import Medium
    >>> kernel, total = mc_line_kernel(
    ...     Medium(sigma_s=1.0, sigma_a=0.1, g=0.9), np.arange(-5, 6), mm_per_row=1.0, n_photons=5_000
    ... )
    >>> kernel.shape, bool(0 < total < 1)
    ((11,), True)
    """
    k = np.asarray(offsets_rows, dtype=np.int64)
    reach = max(MC_KERNEL_REACH_ROWS, int(64 * np.ceil((np.abs(k).max() + 1) / 64.0)))
    canon = np.arange(-reach, reach + 1)
    prof = mc_line_profile(
        as_medium(medium), n_photons=n_photons, offsets_rows=canon, mm_per_row=mm_per_row, seed=seed, cache=True
    )
    return prof.values[k + reach], prof.total_reflectance


def line_kernel(medium: Medium, offsets_rows, *, mm_per_row, model):
    """Binned line kernel and the medium's total diffuse reflectance, by model name.

    Parameters
    ----------
    medium : Medium
        The medium.  The dipole sees it only through ``sigma_a``,
        ``sigma_s_prime = sigma_s (1 - g)`` and ``n`` (build one from
        ``sigma_s'`` with :meth:`Medium.from_reduced`: by the similarity
        relation both models then describe the same diffusion regime); the
        Monte Carlo kernel traces its HG phase function.
    offsets_rows : array_like of int
        Offset bins ``k`` in projector rows.
    mm_per_row : float
        Size of one projector row on the surface, in mm.
    model : {"mc", "dipole"}
        See the module docstring.

    Returns
    -------
    kernel : ndarray of float64
    total : float

    See Also
    --------
    planeray.Medium : the medium's optical constants.
    planeray.mc_line_profile : the Monte Carlo profile behind ``model="mc"``.

    Examples
    --------
    The dipole's kernel of a scattering medium, one value per offset (projector rows):

    >>> import numpy as np
    >>> import planeray as pr
    >>> kernel, total = pr.line_kernel(
    ...     pr.Medium(sigma_s=1.0, sigma_a=0.01, g=0.0), np.arange(-3, 4), mm_per_row=0.5, model="dipole"
    ... )
    >>> kernel.shape, bool(kernel[3] == kernel.max()), bool(0 < total < 1)
    ((7,), True, True)
    """
    if model == "dipole":
        return (
            dipole_line_kernel(medium, offsets_rows, mm_per_row=mm_per_row),
            float(dipole_total_reflectance(medium)),
        )
    if model == "mc":
        return mc_line_kernel(medium, offsets_rows, mm_per_row=mm_per_row)
    raise InputError(f"unknown kernel model {model!r}; expected one of {KERNEL_MODELS}")
