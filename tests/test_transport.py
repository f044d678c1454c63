"""Image formation (Eq. 4) and Eqs. 5-6 against independent dense references."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planeray.timing import Band, RowGeometry, RowPattern, band_bin_weights, paper_sweep
from planeray.transport import SparseEntries, Transport


def _random_transport(H=24, W=10, K=40, seed=0, geometry=None):
    rng = np.random.default_rng(seed)
    return Transport(rng.random((H, W, 2 * K + 1), dtype=np.float32), np.arange(-K, K + 1), geometry)


def _reference_render(T: Transport, illum):
    """Independent reference: the dense weighted sum of Eq. 4, pixel by pixel in float64."""
    H, W, U = T.dense.shape
    out = np.zeros((H, W))
    for t in range(H):
        w = illum.weights(T.geometry, t, T.offsets_rows)
        out[t] = T.dense[t].astype(np.float64) @ w
    sp = T.sparse
    for r, c, u, v in zip(sp.row, sp.col, sp.offset, sp.value):
        out[r, c] += v * illum.weights(T.geometry, r, u)
    return out


@pytest.mark.parametrize(
    "band",
    [
        Band(0.0, 600.0, 54000),
        Band(-187.5, 750.0, 54000, jitter_us=8.0),
        Band(562.5, 1050.0, 54000, jitter_us=5.0, line_width_us=20.0),
        Band(1500.0, 1200.0, 54000),  # clipped by the bottom of the projector for late rows
        Band(40.0, 16.0, 54000),  # narrower than a row: no plateau at all
    ],
)
def test_band_render_matches_dense_reference(band):
    T = _random_transport()
    np.testing.assert_allclose(T.render(band), _reference_render(T, band), rtol=1e-5, atol=1e-4)


def test_row_jitter_render_matches_reference():
    T = _random_transport()
    shifts = np.random.default_rng(1).normal(0, 0.7, (8, T.shape[0]))
    band = Band(300.0, 600.0, 54000, jitter_us=5.0, row_shifts_rows=shifts)
    np.testing.assert_allclose(T.render(band), _reference_render(T, band), rtol=1e-5, atol=1e-4)


def test_pattern_render_and_scaled_geometry():
    g = RowGeometry(24, 135)
    T = _random_transport(geometry=g)
    pattern = RowPattern(np.random.default_rng(2).random(135))
    np.testing.assert_allclose(T.render(pattern), _reference_render(T, pattern), rtol=1e-5, atol=1e-4)


def test_sparse_entries_render_like_a_wide_dense_band():
    wide = _random_transport(K=60, seed=3)
    rows, cols, ks = np.nonzero(wide.dense)
    narrow = Transport.from_entries(
        wide.shape, np.arange(-20, 21), rows, cols, wide.offsets_rows[ks], wide.dense[rows, cols, ks]
    )
    assert len(narrow.sparse) > 0
    for band in [Band(900.0, 900.0, 54000), Band(-1100.0, 600.0, 54000), Band(0.0, 1200.0, 54000)]:
        np.testing.assert_allclose(narrow.render(band), wide.render(band), rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(narrow.full_image(), wide.full_image(), rtol=1e-5)


@settings(max_examples=25, deadline=None)
@given(st.floats(-3, 3), st.floats(-3, 3), st.integers(0, 1000))
def test_rendering_is_linear_in_the_illumination(a, b, seed):
    T = _random_transport(H=12, W=6, K=20)
    rng = np.random.default_rng(seed)
    p1, p2 = rng.random(12), rng.random(12)
    lhs = T.render(RowPattern(a * p1 + b * p2))
    rhs = a * T.render(RowPattern(p1)) + b * T.render(RowPattern(p2))
    np.testing.assert_allclose(lhs, rhs, atol=1e-4)


def test_bands_tiling_the_support_conserve_energy():
    """Disjoint bands covering every offset add up to the full image (energy conservation)."""
    T = _random_transport(H=16, W=8, K=30)
    total = 0.0
    edges = np.arange(-30.5, 31.0, 7.0)
    for lo, hi in zip(edges[:-1], edges[1:]):
        total = total + T.render_weights(
            np.broadcast_to(band_bin_weights(T.offsets_rows, (lo + hi) / 2, hi - lo), (16, T.offsets_rows.size))
        )
    rest = band_bin_weights(T.offsets_rows, (edges[-1] + 40) / 2, 40 - edges[-1])
    total = total + T.render_weights(np.broadcast_to(rest, (16, T.offsets_rows.size)))
    np.testing.assert_allclose(total, T.full_image(), rtol=1e-5)


def test_render_into_a_given_buffer():
    """``out=`` (the live viewer reuses one frame buffer): the same image, written over whatever was there."""
    wide = _random_transport(K=60, seed=4)
    rows, cols, ks = np.nonzero(wide.dense > 0.98)
    T = Transport.from_entries(wide.shape, np.arange(-20, 21), rows, cols, wide.offsets_rows[ks], np.ones(rows.size))
    assert len(T.sparse) > 0
    out = np.full(T.shape, np.nan, np.float32)
    pattern = RowPattern(np.random.default_rng(5).random(T.shape[0]))  # the dense weighted-sum path
    for illum in (Band(-187.5, 750.0, 54000), Band(900.0, 900.0, 54000), pattern):
        image = T.render(illum, out=out)
        assert image is out
        np.testing.assert_allclose(out, _reference_render(T, illum), rtol=1e-5, atol=1e-4)
        out[:] = np.nan
    for bad in (np.zeros(T.shape, np.float64), np.zeros((3, 3), np.float32), np.zeros(T.shape[::-1], np.float32).T):
        with pytest.raises(ValueError, match="out must be"):
            T.render(Band(0.0, 600.0, 54000), out=bad)


def test_epipolar_plus_non_epipolar_is_full():
    T = _random_transport()
    np.testing.assert_allclose(T.epipolar_image() + T.non_epipolar_image(), T.full_image(), rtol=1e-5)
    np.testing.assert_allclose(T.epipolar_image(), T.dense[:, :, T.offsets_rows == 0][..., 0])


def test_validation_errors():
    with pytest.raises(ValueError, match="consecutive"):
        Transport(np.zeros((2, 2, 3)), [0, 1, 3])
    with pytest.raises(ValueError, match="NaN"):
        Transport(np.full((2, 2, 1), np.nan), [0])
    with pytest.raises(ValueError, match="equal length"):
        SparseEntries([0], [0, 1], [0], [1.0])


def test_sweep_render_speed_is_independent_of_band_width():
    """Prefix sums: the wide bands of a sweep take the plateau path (few edge bins)."""
    T = _random_transport(H=32, W=32, K=114)
    for band in paper_sweep().bands(54000, jitter_us=5.0):
        w = T.illumination_weights(band)
        assert ((w > 0) & (w < 1 - 1e-9)).sum(axis=1).max() <= 16
