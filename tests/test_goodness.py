"""Goodness of fit (issue 41): the misfit flag's rate under a consistent model, and its power on a wrong one.

Independent references: chi-square draws from NumPy's generator (not SciPy's distribution the module uses),
and for the fits, data made by forward models other than the fitted one (a layer with a bottom fitted as
semi-infinite; a skin background of another dermis).
"""

from __future__ import annotations

import numpy as np
import pytest

from planeray.goodness import DEFAULT_P_MISFIT, FLAG_EDGE, FLAG_MISFIT, describe_flags, fit_quality, misfit_threshold


@pytest.mark.parametrize("dof", [3, 40, 2000])
def test_a_consistent_model_is_flagged_at_the_stated_rate(dof):
    """Chi-squares of a model that fits (sums of dof squared standard normals): flagged in p_misfit of the cases."""
    rng = np.random.default_rng(dof)
    chi2 = (rng.standard_normal((100_000, dof)) ** 2).sum(axis=1) if dof < 100 else rng.chisquare(dof, 100_000)
    flagged = chi2 / dof > misfit_threshold(dof)
    # 100,000 draws at p = 0.001: 100 expected, 3 sigma 30
    assert 70 <= flagged.sum() <= 130
    # the verdict of a fit is the threshold's: on the draws either side of it
    for c in chi2[np.argsort(np.abs(chi2 / dof - misfit_threshold(dof)))[:20]]:
        assert fit_quality(c, dof).fits == (c / dof <= misfit_threshold(dof))
    # the threshold is the distribution's quantile: a 1 % one flags about 10x as many
    assert np.mean(chi2 / dof > misfit_threshold(dof, p_misfit=0.01)) == pytest.approx(0.01, abs=0.0015)


def test_a_misfit_by_more_than_the_noise_is_flagged_and_inflates_the_errors():
    q = fit_quality(2.0 * 75, 75)  # twice the noise's variance
    assert not q.fits and q.inflation == pytest.approx(np.sqrt(2.0))
    assert "MODEL DOES NOT FIT" in q.describe()
    ok = fit_quality(70.0, 75)
    assert ok.fits and ok.inflation == 1.0 and ok.to_json()["model_fits"] is True
    assert describe_flags(FLAG_MISFIT | FLAG_EDGE) and describe_flags(0) == []
    assert DEFAULT_P_MISFIT == 1e-3
