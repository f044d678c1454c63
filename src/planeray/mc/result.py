"""The result of a Monte Carlo run: a binned exit profile with its errors and the energy balance."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..medium import Medium

__all__ = ["MCProfile"]


@dataclass(frozen=True)
class MCProfile:
    """Result of :func:`mc_line_profile` (and :func:`mc_point_profile`, whose bins are
    radial: see there). Power quantities are fractions of the incident power.

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
        each bin, per unit incident line power (mm^-1 sr^-1).
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
        Its batch standard error.
    absorbed : float
        Absorbed power (including the zero-mean net weight of Russian roulette).
    truncated : float
        Power of photons stopped beyond ``cutoff_mm`` (see the module docstring).
    n_photons : int
        Number of photon packets traced.
    n_interactions : int
        Number of collisions traced (a measure of the run's cost).
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
        """The :class:`~planeray.medium.Medium` of the run, rebuilt from :attr:`params`."""
        p = self.params
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
