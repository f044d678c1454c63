"""Delay profiles measured from simulated stacks show the paper's shapes (Sec. 8, Fig. 9)."""

import numpy as np
import pytest
from scipy.signal import find_peaks

from planeray.acquire import simulate_stack
from planeray.profiles import area_normalize, measured_delay_profiles
from planeray.scenes import make_scene, representative_pixels
from planeray.timing import paper_sweep, sweep_support_rows


@pytest.fixture(scope="module")
def mirror():
    scene = make_scene("mirror_ball", (64, 64), projector_rows=360, seed=1)
    return scene, simulate_stack(scene, paper_sweep(), seed=1)


def _peaks(profile, delays):
    """Peaks standing out by 10 % of the profile's range (noise-robust)."""
    prominence = 0.1 * (np.nanmax(profile) - np.nanmin(profile))
    idx, _ = find_peaks(np.concatenate([[0], profile, [0]]), prominence=prominence)
    return delays[idx - 1]


def test_specular_interreflection_profile_is_bimodal(mirror):
    scene, stack = mirror
    pixels, names = representative_pixels(scene, sweep_support_rows(paper_sweep(), 54000), per_label=2)
    spec = pixels[[n == "specular interreflection" for n in names]]
    assert len(spec) == 2
    prof = measured_delay_profiles(stack, spec)
    e600 = list(prof.exposure_us).index(600.0)
    for p in range(len(spec)):
        peaks = _peaks(prof.values[p, e600], prof.delay_us)
        assert len(peaks) == 2, peaks
        assert np.min(np.abs(peaks)) <= 200  # one peak on the epipolar plane (the ball's diffuse part)
        assert np.max(np.abs(peaks)) >= 500  # the other displaced beyond the band: light from a far row


def test_diffuse_profile_is_unimodal_and_centred(mirror):
    scene, stack = mirror
    pixels, names = representative_pixels(scene, 114, per_label=2)
    diffuse = pixels[[n == "diffuse" for n in names]]
    prof = measured_delay_profiles(stack, diffuse)
    e600 = list(prof.exposure_us).index(600.0)
    for p in range(len(diffuse)):
        peaks = _peaks(prof.values[p, e600], prof.delay_us)
        assert len(peaks) == 1 and abs(peaks[0]) <= 200


def test_profiles_are_area_normalized(mirror):
    _, stack = mirror
    prof = measured_delay_profiles(stack, [[10, 10], [32, 5]])
    area = np.trapezoid(prof.values, prof.delay_us * 1e-3, axis=-1)
    np.testing.assert_allclose(area, 1.0, rtol=1e-5)
    # albedo cancels: a profile and twice that profile normalize the same
    np.testing.assert_allclose(area_normalize(2 * prof.raw, prof.delay_us), prof.values, rtol=1e-5)
