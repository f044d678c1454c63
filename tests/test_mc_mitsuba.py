"""Cross-check of planeray's Monte Carlo line profile against Mitsuba 3 (planeray.mc.mitsuba_ref).

Skipped only when Mitsuba 3 is not installed (``pip install "planeray[mitsuba]"``).
"""

import sys

import numpy as np
import pytest

pytest.importorskip("mitsuba")
from planeray.mc import mc_line_profile
from planeray.mc.mitsuba_ref import (
    _mitsuba,
    mitsuba_line_profile,
    single_scattering_radiance,
)
from planeray.medium import Medium

pytestmark = pytest.mark.slow  # renders with Mitsuba 3

# Multiple-scattering comparison medium (mm^-1): albedo 0.95, moderately forward
# scattering.  At g = 0.9 Mitsuba's estimate is heavy-tailed (the HG peak is reached
# only by next-event estimation towards the delta light): 10x the samples still give
# per-bin z-scores up to 5, so that case is left to offline runs.
MS = Medium(sigma_s=1.0, sigma_a=0.05, g=0.5)
MS_MM_PER_ROW = 1.0
MS_OFFSETS = np.arange(-10, 11)


@pytest.fixture(scope="module")
def ms_profiles():
    # ~5e5 camera paths (24k per bin; 1024 rows along the line keep the row-spread
    # standard error honest for the skewed far bins) and 1.5e5 MC photons: ~6 s.  The
    # tolerances are in standard errors: at these counts, seeds 1-4 gave mean z^2
    # 0.93-1.39 and |z| <= 3.5 (half of the samples the test used to take).
    mi = mitsuba_line_profile(MS, MS_OFFSETS, mm_per_row=MS_MM_PER_ROW, spp=24, along_pixels=1024, seed=1)
    mc = mc_line_profile(
        MS, n_photons=150_000, offsets_rows=MS_OFFSETS, mm_per_row=MS_MM_PER_ROW, source_width_mm=MS_MM_PER_ROW, seed=1
    )
    return mi, mc


def test_calibration_is_unit_line_power():
    p = mitsuba_line_profile(Medium(0.02, 0.98, 0.0), [0], mm_per_row=0.5, spp=1, along_pixels=2, max_depth=2)
    # White Lambertian plane: every lit sample is exactly E / pi, so the measured line
    # power equals the nominal one up to float32 round-off.
    assert abs(p.params["calibrated_line_power"] - 1.0) < 1e-5


@pytest.mark.parametrize("g", [0.0, 0.5, -0.5])
def test_single_scattering_matches_closed_form(g):
    # Index-matched half-space, collimated normal light on one bin (x in [-w/2, w/2]):
    # L1 = sigma_s p_HG(-1) E / (2 sigma_t) inside the strip, 0 outside.  An asymmetric
    # window checks the pixel <-> offset mapping.
    sigma_s, sigma_a, mm = 0.02, 0.98, 0.5
    offsets = np.arange(-2, 4)
    medium = Medium(sigma_s, sigma_a, g)
    l1 = single_scattering_radiance(medium, source_width_mm=mm)
    single = mitsuba_line_profile(medium, offsets, mm_per_row=mm, spp=512, along_pixels=32, max_depth=2, seed=2)
    on = offsets == 0
    assert abs(single.radiance[on][0] - l1) < 4 * single.stderr[on][0]
    assert single.stderr[on][0] < 0.01 * l1
    # Off the strip single scattering is exactly dark (1e-3: float32 rounding at the edges).
    assert np.all(single.radiance[~on] < 1e-3 * l1)

    # All orders: multiple scattering adds O(albedo) relative (albedo = 0.02), in the
    # strip and as a faint halo beside it.
    full = mitsuba_line_profile(medium, offsets, mm_per_row=mm, spp=512, along_pixels=32, seed=3)
    albedo = sigma_s / (sigma_s + sigma_a)
    assert abs(full.radiance[on][0] - l1) < 4 * full.stderr[on][0] + 2 * albedo * l1
    assert np.all(full.radiance[~on] < albedo * l1)


def test_profile_symmetric_and_peaked_at_zero(ms_profiles):
    mi, _ = ms_profiles
    assert mi.offsets_rows[np.argmax(mi.radiance)] == 0
    center = len(MS_OFFSETS) // 2
    right = mi.radiance[center + 1 :]
    left = mi.radiance[:center][::-1]
    se = np.hypot(mi.stderr[center + 1 :], mi.stderr[:center][::-1])
    assert np.all(np.abs(right - left) < 4 * se)
    # Monotone decay away from the line on both sides, beyond the noise.
    assert np.all(np.diff(right[:5]) < 0) and np.all(np.diff(left[:5]) < 0)


def test_matches_planeray_mc(ms_profiles):
    mi, mc = ms_profiles
    diff = mi.radiance - mc.radiance
    se = np.hypot(mi.stderr, mc.radiance_stderr)
    # 2 % floor: both estimators are unbiased for the same quantity; what is left is
    # float32 rendering (~1e-4), the finite medium box and MC cutoff (< 1e-3 of the
    # light) and the uncertainty of the standard errors themselves.
    tol = 4 * se + 0.02 * np.abs(mc.radiance)
    assert np.all(np.abs(diff) <= tol), (diff / se).round(2)
    z = diff / se
    assert np.mean(z**2) < 2.5
    ratio = mi.radiance.sum() / mc.radiance.sum()
    ratio_se = np.hypot(
        np.sqrt(np.sum(mi.stderr**2)) / mi.radiance.sum(), np.sqrt(np.sum(mc.radiance_stderr**2)) / mc.radiance.sum()
    )
    assert abs(ratio - 1.0) < min(0.03, 4 * ratio_se + 0.01)


def test_missing_mitsuba_gives_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "mitsuba", None)
    with pytest.raises(ImportError, match=r"planeray\[mitsuba\]"):
        _mitsuba("scalar_rgb")


def test_rejects_bad_parameters():
    with pytest.raises(ValueError):
        mitsuba_line_profile(Medium(1.0, 0.1, 1.0), [0], mm_per_row=1.0)
    with pytest.raises(ValueError):
        mitsuba_line_profile(Medium(1.0, 0.1, 0.0), [0.5], mm_per_row=1.0)
    with pytest.raises(ValueError):
        mitsuba_line_profile(Medium(1.0, 0.1, 0.0), [0], mm_per_row=1.0, source_width_mm=0.0)
