"""Vein metrics on synthetic images with known answers (planeray.skin.metrics, planeray.skin.masks)."""

from __future__ import annotations

import numpy as np
import pytest

from planeray.errors import InputError
from planeray.skin.masks import read_vein_mask, write_vein_mask
from planeray.skin.metrics import background_bands, cnr, vein_ids_from_mask, vein_metrics, weber_contrast


def _stripes(H=40, W=60, cols=((10, 12), (40, 42))):
    ids = np.zeros((H, W), np.int32)
    for k, (a, b) in enumerate(cols, start=1):
        ids[:, a:b] = k
    return ids


def test_band_is_the_ring_between_gap_and_gap_plus_width():
    ids = _stripes()
    band = background_bands(ids, gap_px=2, width_px=3)[1]
    # columns at distance 3, 4, 5 from the stripe on both sides, every row
    cols = np.flatnonzero(band.any(axis=0)).tolist()
    assert cols == [5, 6, 7, 14, 15, 16]
    assert band.sum() == 6 * 40


def test_band_leaves_out_other_veins_their_surroundings_and_hair():
    ids = _stripes(cols=((10, 12), (16, 18)))  # vein 2 five columns to the right of vein 1
    hair = np.zeros(ids.shape, bool)
    hair[:, 6] = True
    band = background_bands(ids, gap_px=2, width_px=4, exclude=hair)[1]
    cols = np.flatnonzero(band.any(axis=0)).tolist()
    # left side: 4..7 minus hair column 6; right side 14, 15 lie within 2 px of vein 2 -> none
    assert cols == [4, 5, 7]
    assert not (band & (ids > 0)).any()


def test_cnr_and_weber_known_answers():
    """A checkerboard background b +- s around a uniform vein v: CNR = |b - v| / (s sqrt(n / (n - 1)))."""
    b, s, v = 1.0, 0.05, 0.8
    ids = _stripes(cols=((20, 24),))
    img = b + s * np.where((np.indices(ids.shape).sum(axis=0) % 2) == 0, 1.0, -1.0)
    img[ids > 0] = v
    m = vein_metrics(img, ids, gap_px=2, width_px=4)
    n = m["veins"][0]["band_pixels"]
    assert n == 2 * 4 * 40
    assert m["veins"][0]["cnr"] == pytest.approx(abs(b - v) / (s * np.sqrt(n / (n - 1))), rel=1e-12)
    assert m["veins"][0]["weber"] == pytest.approx((v - b) / b, rel=1e-12)
    assert m["cnr"] == pytest.approx(m["veins"][0]["cnr"])
    band = background_bands(ids, gap_px=2, width_px=4)[1]
    assert weber_contrast(img, ids > 0, band) == pytest.approx(-0.2)


def test_cnr_of_noise_matches_its_definition_statistically():
    rng = np.random.default_rng(3)
    ids = _stripes(H=400, W=60, cols=((28, 32),))
    sigma, delta = 0.02, 0.03
    img = 0.5 + sigma * rng.standard_normal(ids.shape)
    img[ids > 0] -= delta
    m = vein_metrics(img, ids)
    assert m["veins"][0]["cnr"] == pytest.approx(delta / sigma, rel=0.08)
    assert m["veins"][0]["detected"]


def test_detection_rules():
    rng = np.random.default_rng(0)
    ids = _stripes()
    img = 1.0 + 0.01 * rng.standard_normal(ids.shape)
    img[ids == 1] += 0.1  # brighter than the skin: not a vein seen, however high its CNR
    m = vein_metrics(img, ids)
    assert m["veins"][0]["cnr"] > 5 and not m["veins"][0]["detected"]
    assert not m["veins"][1]["detected"]  # invisible
    assert m["n_detected"] == 0


def test_a_vein_without_usable_pixels_is_reported_not_measured():
    ids = _stripes()
    img = np.ones(ids.shape)
    hair = ids == 2  # vein 2 entirely under hair
    m = vein_metrics(img + 0.01 * np.random.default_rng(1).standard_normal(ids.shape), ids, exclude=hair)
    v2 = m["veins"][1]
    assert v2["cnr"] is None and v2["detected"] is False and v2["pixels"] == 0


def test_ground_truth_depth_and_diameter_per_vein():
    ids = _stripes()
    depth = np.where(ids == 1, 2.0, np.where(ids == 2, 4.5, np.nan))
    m = vein_metrics(np.random.default_rng(2).random(ids.shape), ids, depth_mm=depth, diameter_mm=depth / 2)
    assert [v["depth_mm"] for v in m["veins"]] == [2.0, 4.5]
    assert [v["diameter_mm"] for v in m["veins"]] == [1.0, 2.25]


def test_boolean_mask_is_split_into_veins():
    ids = _stripes()
    assert np.unique(vein_ids_from_mask(ids > 0)).tolist() == [0, 1, 2]
    m = vein_metrics(np.random.default_rng(0).random(ids.shape), ids > 0)
    assert m["n_veins"] == 2


def test_cnr_needs_pixels():
    with pytest.raises(ValueError):
        cnr(np.ones(4), np.zeros(4, bool), np.ones(4, bool))


def test_vein_mask_files(tmp_path):
    ids = _stripes()
    write_vein_mask(tmp_path / "m.png", ids)
    assert np.array_equal(read_vein_mask(tmp_path / "m.png", ids.shape), ids)
    import tifffile

    tifffile.imwrite(tmp_path / "b.tif", ((ids > 0) * 255).astype(np.uint8))
    assert np.unique(read_vein_mask(tmp_path / "b.tif")).tolist() == [0, 1, 2]
    with pytest.raises(InputError, match=r"m\.png: the vein mask is 40x60, the images 30x30"):
        read_vein_mask(tmp_path / "m.png", (30, 30))
    tifffile.imwrite(tmp_path / "z.tif", np.zeros((4, 4), np.uint8))
    with pytest.raises(InputError, match="marks no vein"):
        read_vein_mask(tmp_path / "z.tif")
    (tmp_path / "junk.png").write_bytes(b"not an image")
    with pytest.raises(InputError, match=r"junk\.png: cannot read the vein mask"):
        read_vein_mask(tmp_path / "junk.png")
    with pytest.raises(InputError, match="not found"):
        read_vein_mask(tmp_path / "none.png")
