"""Checks of the vectorized Monte Carlo slab engine (planeray.mc)."""

import numpy as np
import pytest

from planeray.kernels import dipole_line_kernel, dipole_total_reflectance
from planeray.mc import fresnel_unpolarized, mc_line_profile, sample_hg_cos


def test_energy_conservation_finite_slab_with_fresnel():
    p = mc_line_profile(1.0, 0.1, 0.5, n=1.3, thickness=2.0, n_photons=20_000, seed=3)
    total = p.total_reflectance + p.specular_reflectance + p.transmittance + p.absorbed
    assert abs(total - 1.0) < 1e-9
    assert p.transmittance > 0 and p.total_reflectance > 0 and p.absorbed > 0
    assert p.values.sum() <= p.total_reflectance + 1e-12


def test_energy_conservation_semi_infinite():
    p = mc_line_profile(1.0, 0.05, 0.0, n_photons=10_000, seed=5)
    assert p.transmittance == 0.0
    assert abs(p.energy_balance - 1.0) < 1e-9


def test_single_scattering_limit():
    # Normal incidence, isotropic, index matched, semi-infinite:
    # R_1 = (a/2) int_0^1 mu/(1+mu) dmu = (a/2)(1 - ln 2); higher orders are O(a^2).
    a = 0.01
    p = mc_line_profile(a, 1.0 - a, 0.0, n_photons=100_000, seed=0)
    expected = 0.5 * a * (1.0 - np.log(2.0))
    tol = 4 * p.total_reflectance_stderr + expected * a
    assert abs(p.total_reflectance - expected) < tol


def test_high_albedo_matches_dipole_total_reflectance():
    p = mc_line_profile(0.999, 0.001, 0.0, n_photons=20_000, seed=0)
    ref = dipole_total_reflectance(0.001, 0.999, eta=1.0)
    assert abs(p.total_reflectance / ref - 1.0) < 0.05


def test_far_profile_shape_matches_dipole_line_kernel():
    sigma_s, sigma_a, g = 1.0, 0.01, 0.0
    sp = sigma_s * (1 - g)
    mfp = 1.0 / (sp + sigma_a)
    off = np.arange(-8, 9)
    p = mc_line_profile(sigma_s, sigma_a, g, n_photons=30_000, offsets_rows=off,
                        mm_per_row=mfp, seed=2)
    k = dipole_line_kernel(off, mfp, sigma_a, sp, eta=1.0)
    # fold +/- offsets for statistics
    i3, i6 = [np.flatnonzero(np.abs(off) == j) for j in (3, 6)]
    r_mc = p.values[i3].sum() / p.values[i6].sum()
    r_dp = k[i3].sum() / k[i6].sum()
    rel = np.hypot(np.linalg.norm(p.stderr[i3]) / p.values[i3].sum(),
                   np.linalg.norm(p.stderr[i6]) / p.values[i6].sum())
    assert abs(r_mc / r_dp - 1.0) < max(0.1, 3 * rel)
    # symmetric about the line
    assert np.allclose(p.values, p.values[::-1], atol=5 * p.stderr.max())


def test_specular_reflectance_is_normal_fresnel():
    p = mc_line_profile(1.0, 0.1, 0.0, n=1.4, n_photons=2_000, seed=0)
    assert p.specular_reflectance == pytest.approx(((1.4 - 1) / (1.4 + 1)) ** 2, rel=1e-12)
    assert p.specular_reflectance == pytest.approx(0.0278, abs=1e-4)
    assert abs(p.energy_balance - 1.0) < 1e-9


def test_fresnel_and_hg_helpers():
    assert fresnel_unpolarized(1.0, 1.4) == pytest.approx(((0.4) / 2.4) ** 2)
    crit = np.sqrt(1 - 1 / 1.4**2)  # cos of the critical angle
    assert fresnel_unpolarized(crit * 0.99, 1.4) == 1.0
    assert np.all(fresnel_unpolarized(np.linspace(0, 1, 11), 1.0) == 0.0)
    xi = np.random.default_rng(0).random(200_000)
    for g in (0.0, 0.5, 0.9, -0.3):
        assert sample_hg_cos(xi, g).mean() == pytest.approx(g, abs=0.01)


def test_determinism():
    kw = dict(sigma_s=1.0, sigma_a=0.1, g=0.8, n=1.33, thickness=3.0, n_photons=5_000)
    a = mc_line_profile(**kw, seed=7)
    b = mc_line_profile(**kw, seed=7)
    c = mc_line_profile(**kw, seed=8)
    assert a.values.tobytes() == b.values.tobytes()
    assert a.stderr.tobytes() == b.stderr.tobytes()
    assert (a.total_reflectance, a.transmittance, a.absorbed) == (
        b.total_reflectance, b.transmittance, b.absorbed)
    assert a.values.tobytes() != c.values.tobytes()


def test_cache_roundtrip(tmp_path, monkeypatch):
    monkeypatch.setenv("PLANERAY_CACHE", str(tmp_path))
    kw = dict(sigma_s=1.0, sigma_a=0.2, g=0.3, n_photons=3_000, seed=1, cache=True)
    a = mc_line_profile(**kw)
    files = list((tmp_path / "mc").glob("*.npz"))
    assert len(files) == 1
    b = mc_line_profile(**kw)
    assert b.values.tobytes() == a.values.tobytes()
    assert b.total_reflectance == a.total_reflectance and b.params == a.params


def test_rejects_bad_parameters():
    with pytest.raises(ValueError):
        mc_line_profile(1.0, 0.1, 1.0, n_photons=10)
    with pytest.raises(ValueError):
        mc_line_profile(1.0, 0.1, 0.0, n_photons=10, offsets_rows=[0.5, 1.5])
