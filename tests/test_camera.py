"""Camera model (Sec. 6): noise statistics, ADC, saturation, ambient, sync artifacts."""

import numpy as np
import pytest

from planeray.acquire import simulate_stack
from planeray.camera import CameraModel
from planeray.devices import SimulatedEpiscan
from planeray.scenes import make_scene
from planeray.timing import Sweep


def test_noise_mean_and_variance_match_poisson_plus_read_model():
    cam = CameraModel(ambient_e_per_us=0.0, frames_averaged=4, read_noise_e=12.0)
    signal = np.full((400, 500), 0.35)  # 2100 electrons per frame
    img, sat = cam.expose(signal, 600.0, np.random.default_rng(0))
    e = cam.laser_electrons * 0.35
    g = cam.gain_adu_per_e
    span = cam.max_code - cam.black_level
    expected_mean = e * g / span
    # per-frame variance in ADU: shot + read (through the gain) + quantization
    var_adu = (e + cam.read_noise_e**2) * g**2 + 1 / 12
    expected_var = var_adu / cam.frames_averaged / span**2
    assert img.mean() == pytest.approx(expected_mean, rel=2e-3)
    assert img.var() == pytest.approx(expected_var, rel=0.03)
    assert not sat.any()


def test_shot_noise_grows_with_signal():
    cam = CameraModel(ambient_e_per_us=0.0, read_noise_e=0.0, frames_averaged=1)
    rng = np.random.default_rng(1)
    lo = cam.expose(np.full((300, 300), 0.05), 600.0, rng)[0].var()
    hi = cam.expose(np.full((300, 300), 0.8), 600.0, rng)[0].var()
    assert hi / lo == pytest.approx(16.0, rel=0.1)  # variance proportional to the mean


def test_black_level_is_removed_without_bias():
    cam = CameraModel(ambient_e_per_us=0.0)
    img, _ = cam.expose(np.zeros((300, 300)), 600.0, np.random.default_rng(2))
    assert abs(img.mean()) < 2e-4
    assert img.min() < 0  # read noise below black is kept, not clipped


def test_saturation_is_flagged_and_clipped():
    cam = CameraModel(ambient_e_per_us=0.0)
    signal = np.zeros((10, 10))
    signal[3:5] = 5.0  # 30000 electrons >> full well
    img, sat = cam.expose(signal, 600.0, np.random.default_rng(3))
    assert sat[3:5].all() and not sat[:3].any()
    np.testing.assert_allclose(img[3:5], 1.0)


def test_expected_image_in_given_buffers():
    """The noise-free image written into reused buffers (the live viewer): the camera's expected response,
    computed here from its definition, and the bytes of ``expose(noise=False)``."""
    cam = CameraModel(ambient_e_per_us=2.0)
    rng = np.random.default_rng(4)
    signal = (rng.random((12, 9)) * 2.2 - 0.1).astype(np.float32)  # some saturate, some below zero
    albedo = rng.random((12, 9)).astype(np.float32)
    out, work = np.full((12, 9), np.nan, np.float32), np.full((12, 9), np.nan)
    for amb in (None, albedo):
        e = cam.laser_electrons * signal.astype(float) + (0.0 if amb is None else 2.0 * 750.0 * amb.astype(float))
        want = np.clip(e, 0.0, cam.full_well_e) * cam.gain_adu_per_e / (cam.max_code - cam.black_level)
        image, n_sat = cam.expected_image(signal, 750.0, ambient_albedo=amb, out=out, work=work)
        assert image is out and n_sat == int((e >= cam.full_well_e).sum()) > 0
        np.testing.assert_allclose(image, want, rtol=1e-6, atol=1e-9)
        plain, sat = cam.expose(signal, 750.0, None, ambient_albedo=amb, noise=False)
        assert np.array_equal(plain, image) and int(sat.sum()) == n_sat


def test_ambient_integrates_over_row_exposure_only():
    """Ambient grows with the row exposure; the laser's direct light does not."""
    cam = CameraModel(ambient_e_per_us=2.0)
    albedo = np.full((4, 4), 0.5)
    a600, _ = cam.expose(np.zeros((4, 4)), 600.0, None, ambient_albedo=albedo, noise=False)
    a1200, _ = cam.expose(np.zeros((4, 4)), 1200.0, None, ambient_albedo=albedo, noise=False)
    np.testing.assert_allclose(a1200, 2 * a600, rtol=1e-6)
    assert a600[0, 0] == pytest.approx(2.0 * 600 * 0.5 / cam.full_well_e, rel=1e-5)


def test_epipolar_image_of_diffuse_plane_does_not_grow_with_exposure():
    scene = make_scene("diffuse_plane", (32, 32))
    cam = CameraModel(ambient_e_per_us=0.0, jitter_us=0.0, row_jitter_us=0.0)
    stack = simulate_stack(scene, Sweep.grid([0.0], [600.0, 1200.0]), camera=cam, noise=False)
    np.testing.assert_allclose(stack.images[0], stack.images[1], rtol=1e-6)
    np.testing.assert_allclose(stack.images[0], cam.signal_scale * scene.direct, rtol=1e-5, atol=1e-6)


def test_row_artifacts_appear_at_the_epipolar_boundary():
    """Per-row trigger jitter stripes images whose band edge sits on the epipolar plane."""
    scene = make_scene("diffuse_plane", (64, 64))
    cam = CameraModel(read_noise_e=0.0, ambient_e_per_us=0.0, row_jitter_us=15.0)
    stack = simulate_stack(scene, Sweep.grid([0.0, 300.0], [600.0]), camera=cam, seed=4)
    ratio = stack.images / scene.direct  # remove the texture
    row_spread = ratio.mean(axis=2).std(axis=1)
    assert row_spread[1] > 10 * row_spread[0]


def test_same_seed_same_bytes_any_capture_order():
    scene = make_scene("diffuse_plane", (16, 16))
    a = SimulatedEpiscan(scene, seed=7)
    b = SimulatedEpiscan(scene, seed=7)
    a.set_delay(375.0), a.set_exposure(900.0)
    first = a.grab()[0]
    b.set_delay(-375.0), b.set_exposure(600.0)
    b.grab()
    b.set_delay(375.0), b.set_exposure(900.0)
    assert np.array_equal(first, b.grab()[0])
    assert not np.array_equal(first, a.grab()[0])  # a second grab has fresh noise


def test_invalid_camera_parameters():
    with pytest.raises(ValueError, match="bit_depth"):
        CameraModel(bit_depth=17)
    with pytest.raises(ValueError, match="black_level"):
        CameraModel(black_level=5000)
