"""The result of a Monte Carlo run: a binned exit profile with its errors and the energy balance.

One type for every photon kernel (:class:`MCProfile`: the slab, beside a wall, in layers), built
from the kernels' per-batch tallies by one function (:func:`profile_from_tallies`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..medium import Medium
from .events import batch_stats

__all__ = ["MCProfile", "profile_from_tallies"]


@dataclass(frozen=True)
class MCProfile:
    """Result of :func:`mc_line_profile` (and :func:`mc_point_profile`, whose bins are
    radial: see there), of :func:`planeray.mc.wall.mc_wall_profile` and of the layered runs
    (:func:`planeray.mc.layered.mc_layered_profile`, :func:`~planeray.mc.layered.mc_vein_kernel_brute`).
    Power quantities are fractions of the incident power.

    Attributes
    ----------
    offsets_rows : ndarray of int64
        Offset bins ``k``; bin ``k`` covers exit ``x`` in ``[k - 1/2, k + 1/2) * mm_per_row``.
    mm_per_row : float
        Bin width in mm.
    values : ndarray of float64
        Diffusely reflected power exiting the top face in each bin (line-source
        profile); sums to ``total_reflectance`` when the bins cover the profile.
    stderr : ndarray of float64
        Standard error of ``values`` from the spread of 32 independent photon batches.
    radiance : ndarray of float64
        Radiance leaving the top face along the outward normal, averaged over
        each bin, per unit incident line power (mm^-1 sr^-1); NaN where the run does not
        estimate it (the layered runs tally the exitance ``values`` only).
    radiance_stderr : ndarray of float64
        Its batch standard error.
    total_reflectance : float
        Diffuse reflectance (all exit positions, binned or not; excludes specular).
    total_reflectance_stderr : float
        Its batch standard error.
    specular_reflectance : float
        Fresnel reflection at entry, ``((n - 1) / (n + 1))^2``.
    transmittance : float
        Power leaving through the bottom face (0 for a semi-infinite medium),
        unscattered light included.
    transmittance_stderr : float
        Its batch standard error (NaN in a layered cache entry written before it was recorded).
    absorbed : float
        Absorbed power (including the zero-mean net weight of Russian roulette).
    truncated : float
        Power of photons stopped beyond ``cutoff_mm`` (see the module docstring).
    n_photons : int
        Number of photon packets traced.
    n_interactions : int
        Number of collisions traced (a measure of the run's cost; 0 where not recorded).
    params : dict
        The parameters of the run (the cache key's content; the medium's
        thickness is under ``thickness``, ``None`` for a semi-infinite one).
    wall_loss : float
        Power that left through a container wall (:func:`planeray.mc.wall.mc_wall_profile`;
        0 without a wall).
    wall_loss_stderr : float
        Its batch standard error.

    See Also
    --------
    planeray.mc_line_profile, planeray.mc.mc_point_profile : return it.

    Examples
    --------
    >>> from planeray.mc import mc_line_profile
    >>> from planeray.medium import Medium
    >>> p = mc_line_profile(Medium(sigma_s=1.0, sigma_a=0.1, g=0.9), n_photons=5_000)
    >>> type(p).__name__, p.values.shape == p.stderr.shape
    ('MCProfile', True)
    """

    offsets_rows: np.ndarray
    mm_per_row: float
    values: np.ndarray
    stderr: np.ndarray
    radiance: np.ndarray
    radiance_stderr: np.ndarray
    total_reflectance: float
    total_reflectance_stderr: float
    specular_reflectance: float
    transmittance: float
    transmittance_stderr: float
    absorbed: float
    truncated: float
    n_photons: int
    n_interactions: int = 0
    params: dict = field(default_factory=dict)
    wall_loss: float = 0.0
    wall_loss_stderr: float = 0.0

    @property
    def medium(self) -> Medium:
        """The :class:`~planeray.medium.Medium` of the run, rebuilt from :attr:`params` (a slab or wall run)."""
        p = self.params
        if "sigma_s" not in p:
            raise InputError("this run has no single medium (a layered run: its layers are in params['layers'])")
        thickness = p.get("thickness")
        return Medium(
            sigma_s=p["sigma_s"],
            sigma_a=p["sigma_a"],
            g=p["g"],
            n=p["n"],
            thickness_mm=math.inf if thickness is None else thickness,
        )

    @property
    def energy_balance(self) -> float:
        """``diffuse + specular + transmitted + absorbed + truncated + wall loss`` (1 up to round-off)."""
        return (
            self.total_reflectance
            + self.specular_reflectance
            + self.transmittance
            + self.absorbed
            + self.truncated
            + self.wall_loss
        )


def profile_from_tallies(
    *,
    offsets_rows,
    first_bin,
    mm_per_row,
    counts,
    refl_bins,
    refl,
    trans,
    absorbed,
    truncated,
    specular_reflectance,
    params,
    rad_bins=None,
    events=None,
    wall=None,
) -> MCProfile:
    """The :class:`MCProfile` of a run from its kernel's per-batch tallies: means per photon and batch errors.

    Parameters
    ----------
    offsets_rows : ndarray of int64
        The requested bins; ``refl_bins[:, k - first_bin]`` holds bin ``k``.
    first_bin : int or None
        Bin of the tallies' first column (the requested bins are picked from them); None: the
        tallies' columns are the requested bins, in order.
    mm_per_row : float
    counts : ndarray (B,) of int
        Photons per batch.
    refl_bins, rad_bins : ndarray (B, nk)
        Exiting power per bin; normal-view radiance per bin (already per unit area; None: not estimated).
    refl, trans, absorbed, truncated, wall, events : ndarray (B,)
        Per-batch totals (``wall``: lost through a wall, None without one; ``events``: collisions).
    specular_reflectance : float
    params : dict
        The run's parameters (the cache key's content).
    """
    offsets = np.asarray(offsets_rows, dtype=np.int64)
    n = counts.sum()
    if first_bin is None:  # the tallies hold exactly the requested bins
        values, stderr = batch_stats(refl_bins, counts)
    else:
        cols = offsets - int(first_bin)
        values, stderr = batch_stats(refl_bins[:, cols], counts)
    if rad_bins is None:
        radiance = rad_err = np.full(values.shape, np.nan)
    else:
        radiance, rad_err = batch_stats(rad_bins if first_bin is None else rad_bins[:, cols], counts)
    R_tot, r_err = batch_stats(refl, counts)
    T_tot, t_err = batch_stats(trans, counts)
    W_tot, w_err = (0.0, 0.0) if wall is None else batch_stats(wall, counts)
    return MCProfile(
        offsets_rows=offsets.copy(),
        mm_per_row=float(mm_per_row),
        values=values,
        stderr=stderr,
        radiance=radiance,
        radiance_stderr=rad_err,
        total_reflectance=float(R_tot),
        total_reflectance_stderr=float(r_err),
        specular_reflectance=float(specular_reflectance),
        transmittance=float(T_tot),
        transmittance_stderr=float(t_err),
        absorbed=float(absorbed.sum() / n),
        truncated=float(truncated.sum() / n),
        n_photons=int(n),
        n_interactions=0 if events is None else int(events.sum()),
        params=params,
        wall_loss=float(W_tot),
        wall_loss_stderr=float(w_err),
    )
