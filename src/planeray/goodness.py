"""Goodness of fit: when a measurement cannot be trusted.

Every inverse method of planeray (``materials fit`` per region and per block, the stack fit,
``skin depth``, recognition) fits a forward model to data whose noise it knows (the camera's
noise model, or the spread of the pixels) plus the forward model's own error (a floor measured
against forward models planeray did not write).  This module turns the fit's residuals into a
verdict that travels with the numbers:

* the **reduced chi-square** ``chi2 / dof`` of the whitened residuals and its p-value under the
  chi-square distribution of ``dof`` degrees of freedom (:class:`FitQuality`);
* **"model does not fit"** when that p-value falls below ``p_misfit`` (default
  :data:`DEFAULT_P_MISFIT`): the threshold on the reduced chi-square is
  ``chi2.isf(p_misfit, dof) / dof`` -- 1.6 at 75 degrees of freedom, 1.05 at 10,000 -- so a
  fit of a consistent model is flagged in one of ``1 / p_misfit`` cases, and a model that misses
  the data by more than its stated errors is flagged however many samples there are;
* **standard errors that include the misfit**: scaled by ``sqrt(max(1, chi2 / dof))`` (the
  Birge ratio), so a fit that misses its data by more than their noise reports a wider
  uncertainty -- on top of the model-error floor each method puts in its noise model;
* **flags** (:data:`FLAGS`, bits of the maps' flag layer): the model does not fit, a parameter
  at the edge of the forward model's tables (never reported as a fit), no fit, the data outside
  the forward model's range of validity.

References
----------
.. [1] R. T. Birge, "The calculation of errors by the method of least squares", Phys. Rev. 40,
   207-227, 1932 (the ratio ``sqrt(chi2 / dof)`` as the scale of the standard errors).
.. [2] P. R. Bevington, D. K. Robinson, "Data Reduction and Error Analysis for the Physical
   Sciences", 3rd ed., McGraw-Hill, 2003, Ch. 11 (testing a fit by its chi-square probability).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.stats import chi2 as _chi2

from .errors import InputError

__all__ = [
    "DEFAULT_P_MISFIT",
    "FLAG_MISFIT",
    "FLAG_EDGE",
    "FLAG_NOT_FITTED",
    "FLAG_RANGE",
    "FLAGS",
    "FitQuality",
    "fit_quality",
    "misfit_threshold",
    "describe_flags",
]

#: A fit whose chi-square is less probable than this under its noise model is flagged "model does not fit".
DEFAULT_P_MISFIT = 1e-3
#: Flag bits (the maps' flag layer, ``flags`` in the JSON).
FLAG_MISFIT = 1
FLAG_EDGE = 2
FLAG_NOT_FITTED = 4
FLAG_RANGE = 8
FLAGS = {
    FLAG_MISFIT: "model does not fit: chi-square past the threshold of its noise model (standard errors inflated)",
    FLAG_EDGE: "a parameter at the edge of the forward model (not reported as a fit)",
    FLAG_NOT_FITTED: "not fitted",
    FLAG_RANGE: "outside the forward model's range: walls or a bottom within a few transport mean free paths, "
    "where diffusion theory's method of images is not known to hold",
}


def _check_p(p_misfit) -> float:
    p = float(p_misfit)
    if not 0.0 < p < 1.0:
        raise InputError(f"p_misfit must be in (0, 1), got {p_misfit!r}")
    return p


def misfit_threshold(dof: int, *, p_misfit=DEFAULT_P_MISFIT) -> float:
    """The reduced chi-square above which a fit of ``dof`` degrees of freedom is flagged.

    Parameters
    ----------
    dof : int
        Degrees of freedom.
    p_misfit : float
        The probability that a right model is flagged.

    Returns
    -------
    float
        The reduced chi-square threshold.

    See Also
    --------
    fit_quality : applies it.

    Examples
    --------
    >>> round(misfit_threshold(75), 2), round(misfit_threshold(10_000), 3)
    (1.6, 1.044)
    """
    d = max(int(dof), 1)
    return float(_chi2.isf(_check_p(p_misfit), d) / d)


@dataclass(frozen=True)
class FitQuality:
    """A fit's chi-square against its noise model, and the verdict.

    Attributes
    ----------
    chi2 : float
        Sum of the squared whitened residuals (noise model and model-error floor included).
    dof : int
        Degrees of freedom: samples minus fitted parameters (at least 1).
    p_misfit : float
        The p-value below which the model is said not to fit.

    See Also
    --------
    fit_quality : builds it.
    misfit_threshold : the flag's threshold.

    Examples
    --------
    >>> q = FitQuality(chi2=12.0, dof=10)
    >>> round(q.reduced_chi2, 2), q.fits
    (1.2, True)
    >>> FitQuality(chi2=60.0, dof=10).fits
    False
    """

    chi2: float
    dof: int
    p_misfit: float = DEFAULT_P_MISFIT

    @property
    def reduced_chi2(self) -> float:
        return float(self.chi2) / max(int(self.dof), 1)

    @property
    def p_value(self) -> float:
        """``P(X >= chi2)`` for ``X`` chi-square distributed with ``dof`` degrees of freedom."""
        if not math.isfinite(self.chi2):
            return math.nan
        return float(_chi2.sf(self.chi2, max(int(self.dof), 1)))

    @property
    def threshold(self) -> float:
        """Reduced chi-square above which the fit is flagged (:func:`misfit_threshold`)."""
        return misfit_threshold(self.dof, p_misfit=self.p_misfit)

    @property
    def fits(self) -> bool:
        """False when the model does not fit the data within their noise (or the chi-square is not finite)."""
        return bool(math.isfinite(self.chi2) and self.reduced_chi2 <= self.threshold)

    @property
    def inflation(self) -> float:
        """``sqrt(max(1, chi2 / dof))``: the factor the standard errors are scaled by (Birge ratio)."""
        r = self.reduced_chi2
        return math.sqrt(r) if math.isfinite(r) and r > 1.0 else 1.0

    def describe(self) -> str:
        """One line for the console: the reduced chi-square against its threshold."""
        verdict = "fits" if self.fits else "MODEL DOES NOT FIT"
        return (
            f"{verdict}: reduced chi-square {self.reduced_chi2:.3g} (threshold {self.threshold:.3g} at "
            f"{self.dof} degrees of freedom, p = {self.p_value:.2g})"
        )

    def to_json(self) -> dict:
        def num(v):
            return float(v) if math.isfinite(v) else None

        return {
            "reduced_chi2": num(self.reduced_chi2),
            "dof": int(self.dof),
            "p_value": num(self.p_value),
            "threshold": num(self.threshold),
            "p_misfit": float(self.p_misfit),
            "model_fits": self.fits,
            "se_inflation": num(self.inflation),
        }


def fit_quality(chi2, dof, *, p_misfit=DEFAULT_P_MISFIT) -> FitQuality:
    """:class:`FitQuality` of a fit: ``chi2`` of its whitened residuals at ``dof`` degrees of freedom.

    Parameters
    ----------
    chi2 : float
        Sum of the squared whitened residuals (noise model and model-error floor included).
    dof : int
        Degrees of freedom (observations minus fitted parameters).
    p_misfit : float
        The false-alarm probability of the misfit flag for a right model.

    Returns
    -------
    FitQuality

    See Also
    --------
    misfit_threshold : the threshold it applies.

    Examples
    --------
    >>> q = fit_quality(80.0, 75)
    >>> q.fits, round(q.reduced_chi2, 3), q.inflation > 1
    (True, 1.067, True)
    >>> fit_quality(200.0, 75).fits
    False
    """
    return FitQuality(float(chi2), max(int(dof), 1), _check_p(p_misfit))


def describe_flags(bits: int) -> list[str]:
    """The texts of :data:`FLAGS` set in ``bits``.

    Parameters
    ----------
    bits : int
        An OR of :data:`FLAG_MISFIT`, :data:`FLAG_EDGE`, :data:`FLAG_NOT_FITTED`, :data:`FLAG_RANGE`.

    Returns
    -------
    list of str
        One sentence per flag set.

    See Also
    --------
    FitQuality : a fit's verdict.

    Examples
    --------
    >>> describe_flags(FLAG_EDGE)
    ['a parameter at the edge of the forward model (not reported as a fit)']
    >>> describe_flags(0)
    []
    """
    return [text for bit, text in FLAGS.items() if int(bits) & bit]
