"""Contrast enhancement, Eq. 7 (planeray.skin.enhance), on synthetic delay stacks with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from planeray.skin.enhance import (
    best_delay_map,
    compose,
    enhance_contrast,
    noise_sigma,
    paper_patch_px,
)
from planeray.skin.metrics import vein_metrics


def _two_depth_stack(seed=0, noise=0.01):
    """Vein 1 visible only at the first delay, vein 2 only at the third; the rest is noise."""
    rng = np.random.default_rng(seed)
    H = W = 96
    ids = np.zeros((H, W), np.int32)
    ids[:, 20:24] = 1
    ids[:, 70:74] = 2
    delays = np.array([400.0, 700.0, 1000.0])
    level = np.array([1.0, 0.5, 0.25])  # longer delays: darker and noisier
    imgs = level[:, None, None] * (1.0 + noise / np.sqrt(level)[:, None, None] * rng.standard_normal((3, H, W)))
    imgs[0][ids == 1] *= 0.85
    imgs[2][ids == 2] *= 0.85
    return imgs, delays, ids


def test_enhancement_beats_the_best_single_delay_image():
    imgs, delays, ids = _two_depth_stack()
    single = [vein_metrics(im, ids, mm_per_px=1.0) for im in imgs]
    res = enhance_contrast(imgs, delays)
    enh = vein_metrics(res.image, ids, mm_per_px=1.0)
    assert max(s["n_detected"] for s in single) == 1
    assert enh["n_detected"] == 2
    assert enh["cnr"] > 1.5 * max(s["cnr"] for s in single)
    # the delay map finds each vein's delay
    assert np.median(res.delay_map_us[ids == 1]) < 550
    assert np.median(res.delay_map_us[ids == 2]) > 850


def test_plain_gradient_argmax_prefers_the_noisiest_image():
    """Why the gradient is weighed by the noise: without it the noisy long delay wins off the veins."""
    imgs, delays, ids = _two_depth_stack(noise=0.05)
    plain = enhance_contrast(imgs, delays, noise_normalize=False)
    weighted = enhance_contrast(imgs, delays)
    off = ids == 0
    assert np.mean(plain.raw_delay_map_us[off] == 1000.0) > 0.8
    assert (
        vein_metrics(weighted.image, ids, mm_per_px=1.0)["cnr"] > vein_metrics(plain.image, ids, mm_per_px=1.0)["cnr"]
    )


def test_compose_is_eq7_on_the_delays_and_linear_between():
    rng = np.random.default_rng(0)
    imgs = rng.random((3, 5, 6))
    d = np.array([100.0, 200.0, 400.0])
    idx = rng.integers(0, 3, (5, 6))
    out = compose(imgs, d, d[idx])
    assert np.array_equal(out, np.take_along_axis(imgs, idx[None], 0)[0])
    mid = compose(imgs, d, np.full((5, 6), 300.0))
    assert np.allclose(mid, 0.5 * (imgs[1] + imgs[2]))
    assert np.allclose(compose(imgs, d, np.full((5, 6), 9e9)), imgs[2])  # clipped to the sweep
    with pytest.raises(ValueError):
        compose(imgs, d[::-1], d[idx])


def test_best_delay_map_is_the_argmax():
    g = np.random.default_rng(1).random((4, 3, 3))
    d = np.array([10.0, 20.0, 30.0, 40.0])
    assert np.array_equal(best_delay_map(g, d), d[np.argmax(g, axis=0)])


def test_noise_estimate_and_patch_size():
    rng = np.random.default_rng(5)
    yy, xx = np.mgrid[0:128, 0:128]
    smooth = np.sin(xx / 20.0) + yy / 50.0
    assert noise_sigma(smooth + 0.03 * rng.standard_normal(smooth.shape)) == pytest.approx(0.03, rel=0.1)
    assert paper_patch_px((720, 1280)) == 200
    assert paper_patch_px((128, 128)) == 36


def test_bad_inputs():
    with pytest.raises(ValueError):
        enhance_contrast(np.ones((2, 8, 8)), [1.0, 1.0])
    with pytest.raises(ValueError):
        enhance_contrast(np.ones((2, 8, 8)), [1.0])
