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
