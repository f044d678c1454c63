"""Vein imaging on the skin scene itself (layered skin, Monte Carlo vein tables): Sec. 10's claims, measured.

* under strong ambient light the short-range indirect delay image keeps veins that Nayar's
  global image and the non-epipolar image lose (Fig. 13);
* a vein deeper than the delay image can see is reported as not detected;
* Eq. 7's enhancement beats the best single delay image (Fig. 14).
"""

from __future__ import annotations

import numpy as np
import pytest

import planeray as pr
from planeray.experiments.skin import (
    SWEEP_DELAYS_US,
    SWEEP_EXPOSURE_US,
    camera_at,
    capture_delay_sweep,
    ladder_veins,
    measure,
    valid_rows,
)
from planeray.skin.enhance import enhance_contrast
from planeray.skin.imaging import device_images

SHAPE = (128, 128)


@pytest.fixture(scope="module")
def ladder():
    """Three straight veins 3 mm wide, tops 1, 2 and 5 mm deep."""
    return pr.make_scene(
        "skin", SHAPE, projector_rows=720, seed=0, veins=ladder_veins(SHAPE, depths_mm=(1.0, 2.0, 5.0))
    )


def test_strong_ambient_light_keeps_the_delay_image_only(ladder):
    valid = valid_rows(ladder, 500.0, 600.0)
    office = measure(device_images(ladder, camera_at("office", 638), seed=3)[0], ladder, valid)
    sun = measure(device_images(ladder, camera_at("sunlight", 638), seed=3)[0], ladder, valid)
    for meth in ("global", "non_epipolar"):
        assert sun[meth]["cnr"] < 0.3 * office[meth]["cnr"], meth  # the projector's light drowns
        assert sun["delay"]["cnr"] > 2.0 * sun[meth]["cnr"], meth
    assert sun["delay"]["veins"][0]["detected"]
    # In the camera's band, ambient light is flood light: the photo becomes an ambient-lit photo and
    # keeps its veins (README "Seeing veins through skin"), within 30 %.
    assert sun["photo"]["cnr"] == pytest.approx(office["photo"]["cnr"], rel=0.3)


def test_a_vein_too_deep_is_not_detected(ladder):
    valid = valid_rows(ladder, 500.0, 600.0)
    m = measure(device_images(ladder, camera_at("office", 638), seed=4)[0], ladder, valid)
    veins = m["delay"]["veins"]
    assert [v["depth_mm"] for v in veins] == pytest.approx([1.0, 2.0, 5.0])
    assert veins[0]["detected"] and veins[1]["detected"]
    assert not veins[2]["detected"] and veins[2]["cnr"] < 0.5
    assert all(not m[k]["veins"][2]["detected"] for k in m)


def test_enhancement_beats_the_best_single_delay_image():
    scene = pr.make_scene("skin", SHAPE, projector_rows=720, seed=0)
    valid = valid_rows(scene, float(SWEEP_DELAYS_US[-1]), SWEEP_EXPOSURE_US)
    sweep = capture_delay_sweep(
        scene, camera_at("office", 638), SWEEP_DELAYS_US, exposure_us=SWEEP_EXPOSURE_US, seed=11
    )
    single = measure({f"{d:g}": im for d, im in zip(SWEEP_DELAYS_US, sweep)}, scene, valid)
    best = max(m["cnr"] for m in single.values())
    res = enhance_contrast(sweep, SWEEP_DELAYS_US)
    enh = measure({"e": res.image}, scene, valid)["e"]
    assert enh["cnr"] > 1.2 * best
    assert enh["n_detected"] >= max(m["n_detected"] for m in single.values())
    assert np.all(np.isfinite(res.image))


def test_eq7_composite_of_a_paper_sweep_stack_is_never_below_its_best_usable_delay_image():
    """Issue 23, item 9: the paper's sweep flags 375 us / 600 us as excluded (a boundary image with row
    artefacts); Eq. 7 never takes it, and the composite is at least as good as the best single usable delay
    image.  (With that image in, the composite fell below it in 3 of these 4 forearms: row stripes.)"""
    from planeray.experiments.skin_capture import simulate_skin
    from planeray.skin.imaging import delay_sweep_images

    for seed in range(4):
        cap = simulate_skin(None, size=(64, 64), seed=seed, sweep="paper", camera=pr.CameraModel(ambient_e_per_us=0.5))
        imgs, delays, sel = delay_sweep_images(cap.stack)
        assert 375.0 not in delays and sel["excluded_delays_us"] == [375.0]
        assert not cap.stack.excluded[sel["indices"]].any()
        res = enhance_contrast(imgs, delays)
        single = measure({f"{d:g}": im for d, im in zip(delays, imgs)}, cap.scene)
        enh = measure({"e": res.image}, cap.scene)["e"]
        best = max(m["cnr"] for m in single.values())
        assert enh["cnr"] >= best, (seed, enh["cnr"], best)


def test_vein_cnr_of_one_forearm_at_64_128_and_256_pixels():
    """Issue 23, item 4, on the skin scene: the same three veins (mm on the skin) imaged at three sizes.

    The band is in mm, so 128 and 256 pixels agree vein by vein within 10 % (a band of the same pixels at
    both sizes, 3-9 px, gives 20-50 % less at 256 pixels: it lies in the veins' shadow).  At 64 pixels the
    image itself differs: a camera row spans 11 projector rows (3.4 mm) and a 2.5-3.5 mm vein is one pixel
    sampled off its axis; the pooled CNR stays within 15 %.
    """
    from planeray.experiments.skin import scene_truth, skin_scene
    from planeray.skin.metrics import vein_metrics

    veins = [
        {"depth_mm": 1.5, "diameter_mm": 3.0, "points_mm": [[0, 60], [216, 60]]},
        {"depth_mm": 2.0, "diameter_mm": 2.5, "points_mm": [[0, 110], [216, 150]]},
        {"depth_mm": 1.5, "diameter_mm": 3.5, "points_mm": [[60, 0], [80, 216]]},
    ]
    cnr = {}
    for n in (64, 128, 256):
        scene = skin_scene((n, n), seed=0, veins=veins)
        valid, truth = valid_rows(scene, 500.0, 600.0), scene_truth(scene)
        runs = []
        for seed in range(2):
            img = device_images(scene, camera_at("office", 638), methods=("delay",), seed=seed)[0]["delay"]
            m = measure({"delay": img}, scene, valid)["delay"]
            assert m["band"]["mm_per_px"] == pytest.approx(216.0 / n) and m["band"]["gap_mm"] == 5.0
            runs.append([v["cnr"] for v in m["veins"]] + [m["cnr"]])
            if n == 256:  # the same band in pixels as at 128 rows would not do
                fixed = vein_metrics(img, truth["vein_id"], mm_per_px=216.0 / 128, valid=valid)
                assert fixed["cnr"] < 0.8 * m["cnr"]
        cnr[n] = np.mean(runs, axis=0)
    assert cnr[128] == pytest.approx(cnr[256], rel=0.1)
    assert cnr[64][-1] == pytest.approx(cnr[256][-1], rel=0.15)
