"""Monte Carlo beside a container wall (planeray.mc.wall): energy, limits, the hand-off, reciprocity, tables."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from planeray.errors import InputError
from planeray.kernels.wall import WallKernelTable, mc_wall_table
from planeray.mc import mc_line_profile
from planeray.mc.diffusion import diffusion_exit
from planeray.mc.wall import mc_wall_profile, wall_exit_fractions
from planeray.medium import Medium

# A cheap medium: transport mfp ~1 mm, diffusion length ~4 mm, Fresnel boundary of water.
MED = Medium(sigma_s=2.0, sigma_a=0.02, g=0.5, n=1.33)
OFF = np.arange(-40, 41)
KW = dict(offsets_rows=OFF, mm_per_row=0.5)


def _z(a, b, ea, eb):
    with np.errstate(invalid="ignore", divide="ignore"):
        z = (a - b) / np.hypot(ea, eb)
    return z[np.isfinite(z)]


@pytest.mark.parametrize("angle", [0.0, 45.0, 90.0])
@pytest.mark.parametrize("wall", ["fresnel", "absorbing"])
def test_energy_balance_with_a_wall(angle, wall):
    for medium in (MED, MED.replace(thickness_mm=6.0)):  # hand-off (half-space) and full tracing (slab)
        p = mc_wall_profile(medium, wall_distance_mm=1.5, wall_angle_deg=angle, wall=wall, n_photons=4000, **KW)
        assert abs(p.energy_balance - 1.0) < 1e-9
        assert p.wall_loss > 0.05 and p.truncated < 1e-3
        assert np.all(p.values >= 0) and np.all(p.radiance >= 0)


def test_black_wall_takes_more_than_a_clear_one():
    kw = dict(wall_distance_mm=1.0, wall_angle_deg=0.0, n_photons=20_000, seed=3, **KW)
    clear = mc_wall_profile(MED, wall="fresnel", **kw)
    black = mc_wall_profile(MED, wall="absorbing", **kw)
    assert black.wall_loss > clear.wall_loss + 5 * np.hypot(black.wall_loss_stderr, clear.wall_loss_stderr)
    assert black.total_reflectance < clear.total_reflectance


def test_nothing_leaves_beyond_a_parallel_wall():
    p = mc_wall_profile(MED, wall_distance_mm=2.0, wall_angle_deg=0.0, n_photons=20_000, **KW)
    beyond = OFF * 0.5 - 0.25 >= 2.0  # bins wholly behind the wall
    assert np.all(p.values[beyond] == 0) and np.all(p.radiance[beyond] == 0)
    assert p.values[OFF == 4].item() > 0  # the bin the wall cuts still gets its inside part


def test_diffusion_hand_off_fractions_conserve_energy_without_absorption():
    # No absorption: what does not leave through the top face leaves through the wall (E + W = 1).
    E, W = wall_exit_fractions([0.0, 0.3, 2.0, 10.0, 60.0], medium=Medium(sigma_s=2.0, sigma_a=0.0, g=0.5, n=1.33))
    assert np.allclose(E + W, 1.0, atol=1e-3)
    assert np.all(np.diff(W) < 0) and W[-1] < 0.2 < 0.8 < W[0]  # heavy-tailed without absorption
    # With absorption: far from the wall it is the half-space dipole, and nothing goes through the wall.
    E, W = wall_exit_fractions([1e3], medium=MED)
    sigma_tp = MED.sigma_a + MED.sigma_s_prime
    _, half = diffusion_exit(np.ones((1, 1)), 0, np.arange(1), 1.0, 10.0 / sigma_tp, MED.sigma_a, sigma_tp, MED.n)
    assert W[0] < 1e-6 and abs(E[0] - half) < 1e-3 * half


def test_non_absorbing_medium_absorbs_nothing_with_a_wall():
    m = Medium(sigma_s=2.0, sigma_a=0.0, g=0.5, n=1.33)
    for angle in (0.0, 90.0):
        p = mc_wall_profile(m, wall_distance_mm=2.0, wall_angle_deg=angle, n_photons=20_000, **KW)
        assert abs(p.absorbed) < 5e-3  # Russian roulette's zero-mean noise and the quadrature, nothing more
        assert abs(p.total_reflectance + p.wall_loss + p.specular_reflectance + p.truncated - 1.0) < 5e-3


def test_far_wall_is_the_slab():
    # A wall 200 mm away (50 diffusion lengths) changes nothing: bin by bin the engine's line profile.
    far = mc_wall_profile(MED, wall_distance_mm=200.0, wall_angle_deg=0.0, n_photons=100_000, seed=3, **KW)
    slab = mc_line_profile(MED, n_photons=100_000, seed=4, **KW)
    for a, b, ea, eb in (
        (far.radiance, slab.radiance, far.radiance_stderr, slab.radiance_stderr),
        (far.values, slab.values, far.stderr, slab.stderr),
    ):
        z = _z(a, b, ea, eb)
        assert np.mean(z**2) < 2.0 and np.abs(z).max() < 5.0
    assert far.wall_loss < 1e-4
    assert abs(far.total_reflectance - slab.total_reflectance) < 4 * np.hypot(
        far.total_reflectance_stderr, slab.total_reflectance_stderr
    )


@pytest.mark.parametrize("angle", [0.0, 90.0])
def test_hand_off_with_a_wall_matches_full_tracing(angle):
    # The quarter-space exit law (dipole + images across the wall) against photons traced to the end.
    kw = dict(wall_distance_mm=2.0, wall_angle_deg=angle, n_photons=60_000, **KW)
    hyb = mc_wall_profile(MED, seed=1, **kw)
    full = mc_wall_profile(MED, seed=2, diffusion_depth_mfp=None, cutoff_mm=300.0, **kw)
    assert hyb.n_interactions < 0.8 * full.n_interactions
    z = _z(hyb.radiance, full.radiance, hyb.radiance_stderr, full.radiance_stderr)
    assert np.mean(z**2) < 2.0 and np.abs(z).max() < 5.0
    for a, b, ea, eb in (
        (hyb.total_reflectance, full.total_reflectance, hyb.total_reflectance_stderr, full.total_reflectance_stderr),
        (hyb.wall_loss, full.wall_loss, hyb.wall_loss_stderr, full.wall_loss_stderr),
    ):
        assert abs(a - b) < 4 * np.hypot(ea, eb) + 2e-3


def test_reciprocity_justifies_the_pencil_beam_at_the_pixel():
    # Light from the line at offset u into a pixel a from the wall = light from a pixel at
    # (a - u) into the line at -u: normal-view radiance is reciprocal with Fresnel boundaries.
    mm = 0.5
    kw = dict(wall_angle_deg=0.0, n_photons=200_000, offsets_rows=OFF, mm_per_row=mm)
    runs = {a: mc_wall_profile(MED, wall_distance_mm=a, seed=int(10 * a), **kw) for a in (1.5, 3.0, 5.0)}
    for u, a in ((-4, 3.0), (3, 3.0), (-3, 1.5)):
        p, q = runs[a], runs[a - u * mm]
        i, j = np.flatnonzero(OFF == u)[0], np.flatnonzero(OFF == -u)[0]
        z = (p.radiance[i] - q.radiance[j]) / np.hypot(p.radiance_stderr[i], q.radiance_stderr[j])
        assert abs(z) < 4.0, (u, a, z)
        assert abs(p.radiance[i] / q.radiance[j] - 1) < 0.05


def test_perpendicular_wall_keeps_the_profile_symmetric():
    p = mc_wall_profile(MED, wall_distance_mm=1.0, wall_angle_deg=90.0, n_photons=60_000, **KW)
    z = _z(p.radiance, p.radiance[::-1], p.radiance_stderr, p.radiance_stderr[::-1])
    assert np.mean(z**2) < 2.5


def test_same_bytes_whatever_the_thread_count():
    kw = dict(wall_distance_mm=1.0, wall_angle_deg=45.0, n_photons=3000, seed=5, **KW)
    before = numba.get_num_threads()
    many = numba.config.NUMBA_NUM_THREADS  # the pool's size (a test worker may hold a share of it)
    try:
        numba.set_num_threads(1)
        a = mc_wall_profile(MED, **kw)
        numba.set_num_threads(many)
        b = mc_wall_profile(MED, **kw)
    finally:
        numba.set_num_threads(before)
    assert a.radiance.tobytes() == b.radiance.tobytes() and a.wall_loss == b.wall_loss


def test_bad_parameters():
    with pytest.raises(InputError, match="wall_distance_mm"):
        mc_wall_profile(MED, wall_distance_mm=-1.0)
    with pytest.raises(InputError, match="wall_angle_deg"):
        mc_wall_profile(MED, wall_distance_mm=1.0, wall_angle_deg=120.0)
    with pytest.raises(InputError, match="wall model"):
        mc_wall_profile(MED, wall_distance_mm=1.0, wall="mirror")
    with pytest.raises(InputError, match="distances_rows"):
        mc_wall_table(MED, distances_rows=(3.0, 1.0), cache=False)


def test_wall_table_correlated_control_variate(tmp_path, monkeypatch):
    monkeypatch.setenv("PLANERAY_CACHE", str(tmp_path))
    kw = dict(
        offsets_rows=OFF,
        mm_per_row=0.5,
        distances_rows=(0.0, 2.0, 6.0, 40.0, 400.0),
        angles_deg=(0.0, 90.0),
        n_photons=4000,
        slab_photons=20_000,
    )
    tab = mc_wall_table(MED, **kw)
    # 200 mm from the wall every photon is the same with and without it: exactly the slab.
    assert np.allclose(tab.kernel[:, -1], tab.slab, rtol=0, atol=1e-12)
    # The wall takes light monotonically as the pixel approaches it.
    totals = tab.kernel.sum(axis=2)
    assert np.all(np.diff(totals, axis=1) > 0) and np.all(totals[:, 0] < 0.8 * tab.slab.sum())
    assert np.all(np.diff(tab.wall_loss, axis=1) < 0)
    # Interpolation: the tabulated points, the slab beyond, in between in between.
    assert np.allclose(tab.kernels(2.0, 90.0), tab.kernel[1, 1])
    assert np.allclose(tab.kernels(1e4, 0.0), tab.slab)
    mid = tab.kernels(4.0, 45.0).sum()
    assert min(totals[:, 1].min(), totals[:, 2].min()) <= mid <= max(totals[:, 1].max(), totals[:, 2].max())
    # Cached on disk (no pickle) and read back.
    files = list((tmp_path / "mc").glob("wall-*.npz"))
    assert len(files) == 1
    back = WallKernelTable.load(files[0])
    assert np.allclose(back.kernel, tab.kernel, rtol=1e-6) and back.medium == MED and back.wall == "fresnel"
    again = mc_wall_table(MED, **kw)
    assert np.array_equal(again.kernel, back.kernel)


def test_materials_scene_uses_the_shipped_tables(tmp_path, monkeypatch):
    # The default media at the three laser lines (and the Jensen et al. milks of the report) ship precomputed
    # (src/planeray/mc/tables, tools/build_mc_tables.py); a stale table would make every
    # fresh machine trace ~10^7 photons per medium when it builds the scene.
    import planeray.kernels.wall as wall
    import planeray.mc.engine as engine
    import planeray.scenes.materials as sm
    from planeray.scenes import make_scene

    monkeypatch.setenv("PLANERAY_CACHE", str(tmp_path))
    monkeypatch.setattr(sm, "_TRACED", {})  # not the tables this process already holds

    def no_tracing(*a, **k):
        raise AssertionError("a wall-kernel table of the materials scene was not found in the shipped tables")

    monkeypatch.setattr(engine, "_run", no_tracing)
    monkeypatch.setattr(wall, "trace_wall_run", no_tracing)
    for kw in (
        {},
        {"source": "jensen"},
        {"container": "cup", "placement": 2},
        {"channel": "green"},
        {"channel": "blue"},
    ):
        s = make_scene("materials", (64, 64), projector_rows=720, seed=0, **kw)
        assert s.maps["near_wall"].any()
    assert not any(tmp_path.rglob("*.npz"))
