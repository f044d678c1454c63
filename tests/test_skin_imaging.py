"""The Sec. 10 imaging methods (planeray.skin.imaging) on a synthetic vein scene with known answers.

The scene (tests/_skin_toy.py) is a fixture, not skin physics: veins remove light that travelled
farther than twice their depth under the surface; vein 3 lies far deeper than any delay reaches.
"""

from __future__ import annotations

import numpy as np
import pytest

import planeray as pr
from _skin_toy import toy_vein_scene
from planeray.errors import InputError
from planeray.experiments.skin import camera_at, measure, valid_rows
from planeray.skin.imaging import (
    METHODS,
    delay_band_mm,
    delay_for_offset_mm,
    delay_sweep_images,
    device_images,
    stack_images,
    truth_images,
)


@pytest.fixture(scope="module")
def scene():
    return toy_vein_scene((48, 48), projector_rows=270, columns=(8, 24, 40))


def test_delay_band_in_mm_is_eq2():
    near, far = delay_band_mm(500.0, 600.0, lines_per_second=54_000, mm_per_row=0.3)
    assert (near, far) == pytest.approx((0.3 * 54_000 * 200e-6, 0.3 * 54_000 * 800e-6))
    assert delay_for_offset_mm(0.5 * (near + far), lines_per_second=54_000, mm_per_row=0.3) == pytest.approx(500.0)


def test_truth_images(scene):
    img = truth_images(scene, delay_us=500.0, exposure_us=600.0)
    T = scene.transport
    assert set(img) == set(METHODS)
    assert np.allclose(img["non_epipolar"], T.full_image() - T.epipolar_image(), atol=1e-6)
    assert np.allclose(img["delay"], pr.band_image(T, 500.0, 600.0))
    valid = valid_rows(scene, 500.0, 600.0)
    m = measure(img, scene, valid)
    # the direct image carries (almost) no vein; the delay image shows the two shallow veins
    assert abs(m["direct"]["veins"][0]["weber"]) < 0.01
    assert m["delay"]["veins"][0]["weber"] < -0.2 and m["delay"]["veins"][1]["weber"] < -0.05
    # Nayar's global image of a noise-free scene is the indirect light (full minus direct)
    g = img["global"][valid]
    ref = (T.full_image() - scene.direct)[valid]
    assert np.median(np.abs(g - ref) / ref) < 0.1


def test_strong_ambient_light_keeps_the_delay_image_and_loses_photo_and_global(scene):
    valid = valid_rows(scene, 500.0, 600.0)
    dim, _ = device_images(scene, camera_at("dark", 638.0), seed=1)
    sun, info = device_images(scene, camera_at("sunlight", 638.0), seed=1)
    md, ms = measure(dim, scene, valid), measure(sun, scene, valid)
    assert info["photo_attenuation"] < 0.2  # the photo had to be stopped down against saturation
    for meth in ("photo", "global"):
        assert ms[meth]["cnr"] < 0.5 * md[meth]["cnr"]
        assert ms["delay"]["cnr"] > 2.0 * ms[meth]["cnr"]
    assert ms["delay"]["n_detected"] == 2


def test_too_deep_a_vein_is_reported_not_detected(scene):
    imgs, _ = device_images(scene, camera_at("office", 638.0), seed=2)
    m = measure(imgs, scene, valid_rows(scene, 500.0, 600.0))
    for meth in METHODS:
        deep = m[meth]["veins"][2]
        assert deep["depth_mm"] == 30.0
        assert deep["detected"] is False, meth


def test_stack_images_pick_the_delay_and_the_epipolar_image(scene):
    stack = pr.simulate_stack(scene, pr.timing.quick_sweep(), seed=0)
    imgs, info = stack_images(stack, delay_us=500.0)
    assert info["delay_us"] == 375.0 and info["exposure_us"] == 600.0 and info["direct_delay_us"] == 0.0
    assert np.array_equal(imgs["delay"], np.asarray(stack.images[info["delay_index"]]))
    with pytest.raises(InputError, match="no image near delay 5000"):
        stack_images(stack, delay_us=5000.0)
    with pytest.raises(InputError, match="no image at exposure 700"):
        stack_images(stack, exposure_us=700.0)
    sweep, delays = delay_sweep_images(stack)
    assert delays.tolist() == [375.0, 750.0, 1125.0, 1500.0] and sweep.shape == (4, 48, 48)
