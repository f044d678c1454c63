"""The media's anisotropy g (planeray.kernels.anisotropy): the table of its effect against direct Monte Carlo runs
of another seed, and the fits -- g unknown (a nuisance parameter) or stated -- on media of another g than the
forward table's 0.8."""

from __future__ import annotations

import numpy as np
import pytest

from planeray.kernels import anisotropy as an
from planeray.materials import fit
from planeray.mc import mc_line_profile
from planeray.medium import Medium

MM = 0.3
OFFSETS = np.arange(-60, 61)


def test_the_shipped_table_is_found_without_tracing(monkeypatch):
    an._LOADED.clear()

    def no_tracing(*args, **kwargs):
        raise AssertionError("the shipped anisotropy table was not found")

    monkeypatch.setattr(an, "_build", no_tracing)
    assert an.anisotropy_table_stored()
    t = an.anisotropy_table()
    assert t.deviation.shape == (3, 2, 6, len(an.G_NODES), an.G_TABLE_REACH_ROWS + 1)
    np.testing.assert_array_equal(t.deviation[:, :, :, list(an.G_NODES).index(0.8)], 0.0)


def _direct(mu_s_prime, mu_a, g, *, n_photons, seed):
    """Direct Monte Carlo kernel of a medium of anisotropy ``g`` (the scenes' unit) and its standard error."""
    med = Medium.from_reduced(mu_s_prime, mu_a, g=g, n=fit.DEFAULT_N)
    p = mc_line_profile(med, n_photons=n_photons, offsets_rows=OFFSETS, mm_per_row=MM, seed=seed)
    return np.pi * MM * p.radiance, np.pi * MM * p.radiance_stderr


def test_the_table_holds_an_independent_run_at_a_node():
    """The table's deviation at g = 0 against a direct run of another seed, off the table's grid (mu_s' h = 0.45)."""
    y0, e0 = _direct(1.5, 0.015, 0.0, n_photons=400_000, seed=21)
    y8, e8 = _direct(1.5, 0.015, 0.8, n_photons=400_000, seed=22)
    t = an.anisotropy_table()
    dev = t.at(1.5 * MM, 0.015 * MM, fit.DEFAULT_N)[list(an.G_NODES).index(0.0)]
    u = np.abs(OFFSETS)
    near = u <= 8  # the deviation lives within a few transport mean free paths (2.2 rows here)
    ratio = y0 / y8 - 1.0
    err = np.hypot(e0 / y8, y0 * e8 / y8**2)
    assert abs(ratio[OFFSETS == 0][0]) > 0.1  # a g of 0 changes the line's own bin by more than 10 %
    # the interpolated table (in log mu_s' h between 0.3 and 1) against the run: within its Monte Carlo error, 2 %
    # and a tenth of the deviation (the line's own bin changes fast with mu_s' h: 0.83 at 0.3, 0.29 at 1)
    assert np.all(np.abs(dev[u[near]] - ratio[near]) < 3 * err[near] + 0.02 + 0.1 * np.abs(ratio[near]))


@pytest.mark.parametrize("g", [0.0, 0.5])
def test_a_medium_of_another_g_is_covered_when_g_is_unknown_and_missed_when_taken_as_the_tables(g):
    """A profile of a medium with g far from the table's 0.8 (direct Monte Carlo, 10^6 photons, the data's errors
    its Monte Carlo errors plus 1 %): with g unknown (fitted) the truth lies within 2 standard errors and the fit is
    not flagged; taken as the table's g, the same data put mu_s' beyond 2 standard errors or flag the fit; stated,
    g is used (no third parameter: one more degree of freedom) and the truth is covered."""
    mu_s, mu_a = 1.0, 0.01
    y, e = _direct(mu_s, mu_a, g, n_photons=1_000_000, seed=31)
    sd = np.hypot(e, 0.01 * y)
    kw = dict(offsets_rows=OFFSETS, mm_per_row=MM, sigma=sd)
    unknown = fit.fit_profiles(y, **kw)
    table_g = fit.fit_profiles(y, **kw, g=fit.DEFAULT_G)
    stated = fit.fit_profiles(y, **kw, g=g)
    for r in (unknown, stated):
        z = abs(r.mu_s_prime_per_mm[0] - mu_s) / r.mu_s_prime_se_per_mm[0]
        za = abs(r.mu_a_per_mm[0] - mu_a) / r.mu_a_se_per_mm[0]
        assert z < 2 and za < 2 and r.flags[0] == 0, (r.mu_s_prime_per_mm, r.mu_s_prime_se_per_mm, r.flags)
    assert stated.dof[0] == unknown.dof[0] + 1 and stated.g[0] == g and np.isnan(stated.g_se[0])
    assert abs(unknown.g[0] - g) < 2 * unknown.g_se[0] + 0.05  # and g itself, roughly
    z_fixed = abs(table_g.mu_s_prime_per_mm[0] - mu_s) / table_g.mu_s_prime_se_per_mm[0]
    assert z_fixed > 2 or table_g.flags[0] != 0, (table_g.mu_s_prime_per_mm, table_g.mu_s_prime_se_per_mm)


def test_a_g_outside_the_covered_range_is_refused():
    from planeray.errors import InputError

    with pytest.raises(InputError, match="g must lie within"):
        fit.fit_profiles(np.ones(OFFSETS.size), offsets_rows=OFFSETS, mm_per_row=MM, g=0.99)


def test_the_interpolation_in_g_is_scipys_pchip():
    """The fits' own monotone cubic in g (written out for speed) against scipy's PchipInterpolator, on random rows
    (monotone, oscillating, flat stretches) and at every point of the range, nodes included."""
    from scipy.interpolate import PchipInterpolator

    rng = np.random.default_rng(7)
    x = np.array(an.G_NODES)
    for trial in range(40):
        y = rng.normal(size=(x.size, 30)) * rng.choice([0.0, 1.0], size=(x.size, 30), p=[0.2, 0.8])
        y = np.cumsum(y, axis=0) if trial % 2 else y
        for q in np.linspace(*an.G_PRIOR, 39):
            np.testing.assert_allclose(an._pchip(x, y, q), PchipInterpolator(x, y, axis=0)(q), rtol=1e-12, atol=1e-12)
