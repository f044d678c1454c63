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
    transport_images,
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


def test_stack_images_name_each_band_and_skip_excluded_images(scene):
    stack = pr.simulate_stack(scene, pr.timing.quick_sweep(), seed=0)
    # 500 us: nearest is 375 us at 600 us, a boundary image the stack excludes -> refused, or used on request
    with pytest.raises(InputError, match=r"\(375 us\) is excluded"):
        stack_images(stack, delay_us=500.0)
    imgs, info = stack_images(stack, delay_us=500.0, include_excluded=True)
    assert info["delay_us"] == 375.0 and info["requested_delay_us"] == 500.0
    imgs, info = stack_images(stack, delay_us=700.0)
    assert (info["requested_delay_us"], info["delay_us"], info["exposure_us"]) == (700.0, 750.0, 600.0)
    assert list(imgs) == ["td750us_te600us", "td0us_te600us"] and info["delay_image"] == "td750us_te600us"
    assert np.array_equal(imgs["td750us_te600us"], np.asarray(stack.images[info["delay_index"]]))
    rec = info["images"]["td0us_te600us"]
    # the t_d = 0 band is +-t_e/2 = +-16.2 rows wide at 54,000 lines/s: 5.8x the camera row's +-2.8 rows
    assert rec["band_rows"] == pytest.approx([-16.2, 16.2]) and not stack.excluded[rec["stack_index"]]
    assert "5.8x the epipolar image" in rec["label"]
    assert info["images"]["td750us_te600us"]["band_rows"] == pytest.approx([24.3, 56.7])
    with pytest.raises(InputError, match="delay_us = 5000: the stack has no image near that delay"):
        stack_images(stack, delay_us=5000.0)
    with pytest.raises(InputError, match="exposure_us = 700: the stack has no image at that exposure"):
        stack_images(stack, exposure_us=700.0)
    sweep, delays, sel = delay_sweep_images(stack)
    assert delays.tolist() == [750.0, 1125.0, 1500.0] and sweep.shape == (3, 48, 48)
    assert sel["excluded_delays_us"] == [375.0] and not stack.excluded[sel["indices"]].any()
    _, delays, _ = delay_sweep_images(stack, include_excluded=True)
    assert delays.tolist() == [375.0, 750.0, 1125.0, 1500.0]


def test_transport_images_give_the_epipolar_image_and_the_exact_delay(scene):
    imgs, info = transport_images(scene.transport, delay_us=480.0, exposure_us=300.0)
    assert list(imgs) == ["td480us_te300us", "epipolar"] and info["delay_us"] == 480.0
    assert np.allclose(imgs["epipolar"], scene.transport.epipolar_image())
    assert np.allclose(imgs["td480us_te300us"], pr.band_image(scene.transport, 480.0, 300.0))
    half = 0.5 * scene.geometry.rows_per_camera_row
    assert info["images"]["epipolar"]["band_rows"] == pytest.approx([-half, half])
