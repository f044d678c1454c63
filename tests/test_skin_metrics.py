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
    band = background_bands(ids, mm_per_px=1.0, gap_mm=2, width_mm=3)[1]
    # columns at distance 3, 4, 5 from the stripe on both sides, every row
    cols = np.flatnonzero(band.any(axis=0)).tolist()
    assert cols == [5, 6, 7, 14, 15, 16]
    assert band.sum() == 6 * 40


def test_band_leaves_out_other_veins_their_surroundings_and_hair():
    ids = _stripes(cols=((10, 12), (16, 18)))  # vein 2 five columns to the right of vein 1
    hair = np.zeros(ids.shape, bool)
    hair[:, 6] = True
    band = background_bands(ids, mm_per_px=1.0, gap_mm=2, width_mm=4, exclude=hair)[1]
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
    m = vein_metrics(img, ids, mm_per_px=1.0, gap_mm=2, width_mm=4)
    n = m["veins"][0]["band_pixels"]
    assert n == 2 * 4 * 40
    assert m["veins"][0]["cnr"] == pytest.approx(abs(b - v) / (s * np.sqrt(n / (n - 1))), rel=1e-12)
    assert m["veins"][0]["weber"] == pytest.approx((v - b) / b, rel=1e-12)
    assert m["cnr"] == pytest.approx(m["veins"][0]["cnr"])
    band = background_bands(ids, mm_per_px=1.0, gap_mm=2, width_mm=4)[1]
    assert weber_contrast(img, ids > 0, band) == pytest.approx(-0.2)


def test_cnr_of_noise_matches_its_definition_statistically():
    rng = np.random.default_rng(3)
    ids = _stripes(H=400, W=60, cols=((28, 32),))
    sigma, delta = 0.02, 0.03
    img = 0.5 + sigma * rng.standard_normal(ids.shape)
    img[ids > 0] -= delta
    m = vein_metrics(img, ids, mm_per_px=1.0)
    assert m["veins"][0]["cnr"] == pytest.approx(delta / sigma, rel=0.08)
    assert m["veins"][0]["detected"]


def test_detection_rules():
    rng = np.random.default_rng(0)
    ids = _stripes()
    img = 1.0 + 0.01 * rng.standard_normal(ids.shape)
    img[ids == 1] += 0.1  # brighter than the skin: not a vein seen, however high its CNR
    m = vein_metrics(img, ids, mm_per_px=1.0)
    assert m["veins"][0]["cnr"] > 5 and not m["veins"][0]["detected"]
    assert not m["veins"][1]["detected"]  # invisible
    assert m["n_detected"] == 0


def test_a_vein_without_usable_pixels_is_reported_not_measured():
    ids = _stripes()
    img = np.ones(ids.shape)
    hair = ids == 2  # vein 2 entirely under hair
    m = vein_metrics(img + 0.01 * np.random.default_rng(1).standard_normal(ids.shape), ids, mm_per_px=1.0, exclude=hair)
    v2 = m["veins"][1]
    assert v2["cnr"] is None and v2["detected"] is False and v2["pixels"] == 0


def test_ground_truth_depth_and_diameter_per_vein():
    ids = _stripes()
    depth = np.where(ids == 1, 2.0, np.where(ids == 2, 4.5, np.nan))
    m = vein_metrics(
        np.random.default_rng(2).random(ids.shape), ids, mm_per_px=1.0, depth_mm=depth, diameter_mm=depth / 2
    )
    assert [v["depth_mm"] for v in m["veins"]] == [2.0, 4.5]
    assert [v["diameter_mm"] for v in m["veins"]] == [1.0, 2.25]


def test_boolean_mask_is_split_into_veins():
    ids = _stripes()
    assert np.unique(vein_ids_from_mask(ids > 0)).tolist() == [0, 1, 2]
    m = vein_metrics(np.random.default_rng(0).random(ids.shape), ids > 0, mm_per_px=1.0)
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


# ---------------------------------------------------------------- the band in mm: the same at every image size
FIELD_MM = 108.0  # a 360-row projector at 0.3 mm per row (not the 216 mm field the old pixel band assumed)
#: (a point on the axis (x down, y across), direction, radius, contrast), mm
MM_VEINS = (
    ((0.0, 27.0), (1.0, 0.0), 4.0, 0.25),
    ((0.0, 60.0), (1.0, 0.35), 3.0, 0.15),
    ((70.0, 0.0), (0.1, 1.0), 3.5, 0.2),
)
SHOULDER_MM, NOISE = 1.5, 0.05


def _mm_scene(n, seed):
    """The same skin in mm sampled by an n x n camera: dark veins with a shadow fading over 1.5 mm past
    their edge, and per-pixel noise of one sigma at every size (a camera's pixels, not the skin's)."""
    pitch = FIELD_MM / n
    c = (np.arange(n) + 0.5) * pitch
    X, Y = np.meshgrid(c, c, indexing="ij")
    img, ids, best = np.ones((n, n)), np.zeros((n, n), np.int32), np.full((n, n), np.inf)
    for k, (p0, d, r, contrast) in enumerate(MM_VEINS, start=1):
        d = np.asarray(d) / np.hypot(*d)
        dist = np.abs((X - p0[0]) * d[1] - (Y - p0[1]) * d[0])
        img *= 1.0 - contrast * np.where(dist <= r, 1.0, np.exp(-(dist - r) / SHOULDER_MM))
        over = (dist <= r) & (dist / r < best)  # a pixel whose centre lies over the vein
        ids[over], best = k, np.where(over, dist / r, best)
    return img + NOISE * np.random.default_rng(seed).standard_normal(img.shape), ids, pitch, img


def _independent_cnr(img, ids, pitch_mm, gap_mm=5.0, width_mm=10.0, sigma=None):
    """The README's definition, brute force: distances between pixel centres in mm (k-d tree, not a distance
    transform); band of vein k = (gap, gap + width] from vein k, farther than gap from every vein."""
    from scipy.spatial import cKDTree

    centres = (np.indices(ids.shape).reshape(2, -1).T + 0.5) * pitch_mm
    flat = ids.ravel()
    d_any = cKDTree(centres[flat > 0]).query(centres)[0].reshape(ids.shape)
    out = {}
    for k in np.unique(flat[flat > 0]):
        d_k = cKDTree(centres[flat == k]).query(centres)[0].reshape(ids.shape)
        band = (d_k > gap_mm) & (d_k <= gap_mm + width_mm) & (d_any > gap_mm)
        v, b = img[ids == k], img[band]
        out[int(k)] = abs(b.mean() - v.mean()) / (b.std(ddof=1) if sigma is None else sigma)
    return out


def test_vein_cnr_is_the_same_at_64_128_and_256_pixels_and_matches_an_independent_computation():
    """Issue 23, item 4: one skin, three image sizes: per-vein and pooled CNR agree within noise (6 %; the
    CNR of one 64x64 image scatters by 3 %), and every number equals a brute-force computation of the
    documented definition from the image and the mask.  A band scaled with the image height (2-8 px at
    128 rows) differs by 10 % between 64 and 128 rows on this skin and sits in the veins' shadow."""
    means = {}
    for n in (64, 128, 256):
        runs = []
        for seed in range(6):
            img, ids, pitch, clean = _mm_scene(n, seed)
            m = vein_metrics(img, ids, mm_per_px=pitch)
            assert m["band"]["gap_mm"] == 5.0 and m["band"]["width_mm"] == 10.0
            assert m["band"]["gap_px"] == pytest.approx(5.0 / pitch)
            if seed == 0:
                ind = _independent_cnr(img, ids, pitch)
                assert [v["cnr"] for v in m["veins"]] == pytest.approx([ind[k] for k in (1, 2, 3)], rel=1e-9)
                # the CNR to expect: the noise-free contrast between vein and band over the noise's sigma
                expected = _independent_cnr(clean, ids, pitch, sigma=NOISE)
            runs.append([v["cnr"] for v in m["veins"]] + [m["cnr"]])
        means[n] = np.mean(runs, axis=0)
        assert means[n][:3] == pytest.approx([expected[k] for k in (1, 2, 3)], rel=0.04), n
    for n, mean in means.items():
        assert mean == pytest.approx(means[256], rel=0.06), n


def test_band_lies_between_gap_and_gap_plus_width_in_mm_at_every_size():
    for n in (64, 128, 256):
        pitch = 216.0 / n
        ids = np.zeros((n, n), np.int32)
        ids[:, n // 2] = 1
        band = background_bands(ids, mm_per_px=pitch)[1]
        dist_mm = np.abs(np.flatnonzero(band[0]) - n // 2) * pitch
        assert dist_mm.min() > 5.0 and dist_mm.max() <= 15.0
        # every column whose centre lies in (5, 15] mm of the vein's is in the band
        cols = np.abs(np.arange(n) - n // 2) * pitch
        assert band[0].sum() == np.count_nonzero((cols > 5.0) & (cols <= 15.0))
    with pytest.raises(ValueError, match="mm_per_px must be positive"):
        background_bands(ids, mm_per_px=0.0)
