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


# ------------------------------------------------------- the one binning rule (projector rows -> offset bins)
def _overlap(a0, a1, b0, b1):
    """Length of the intersection of [a0, a1) and [b0, b1) (written out, independent of planeray)."""
    return max(0.0, min(a1, b1) - max(a0, b0))


def _exact_window(per_row, P, H, t, s, lo, hi):
    """Light of projector coordinates p_t + [lo, hi) for pixel (t, s): each projector row v is lit
    uniformly over [v - 1/2, v + 1/2), so it contributes its light times the overlap of its cell."""
    p_t = (t + 0.5) * P / H - 0.5
    return sum(per_row[v, t, s] * _overlap(v - 0.5, v + 0.5, p_t + lo, p_t + hi) for v in range(P))


def _window_from_bins(dense, offsets, P, H, t, s, lo, hi):
    """The same window from the offset bins: bin k holds the light of its part inside the projector,
    [k - 1/2, k + 1/2) clipped to [-1/2, P - 1/2) - p_t, spread evenly over that part (the edge rule)."""
    p_t = (t + 0.5) * P / H - 0.5
    total = 0.0
    for i, k in enumerate(offsets):
        a, b = max(k - 0.5, -0.5 - p_t), min(k + 0.5, P - 0.5 - p_t)
        if b > a:
            total += dense[t, s, i] * _overlap(a, b, lo, hi) / (b - a)
    return total


@settings(max_examples=60, deadline=None)
@given(
    H=st.integers(1, 9),
    ratio=st.floats(1.0, 7.0),
    seed=st.integers(0, 10_000),
    centre=st.integers(-3, 3),
    half_width=st.integers(0, 3),
)
def test_projector_rows_binned_by_overlap_keep_every_bin_aligned_window_exact(H, ratio, seed, centre, half_width):
    from planeray.transport import bin_projector_rows

    P = max(1, int(round(H * ratio)))
    g = RowGeometry(H, P)
    rng = np.random.default_rng(seed)
    per_row = rng.random((P, H, 2)) * (rng.random((P, H, 2)) < 0.6)  # sharp, arbitrary light per row
    B = P + 2
    offsets = np.arange(-B, B + 1)
    dense, (row, col, off, val) = bin_projector_rows(per_row, g, offsets)
    assert row.size == 0  # the band covers every projector row: nothing is long-range
    # energy per pixel unchanged
    np.testing.assert_allclose(dense.sum(axis=2), per_row.sum(axis=0), rtol=1e-6, atol=1e-6)
    # a window whose edges are bin edges ([centre - w/2, centre + w/2), w = 2 half_width + 1) is exact
    lo, hi = centre - half_width - 0.5, centre + half_width + 0.5
    for t in range(H):
        for s in range(2):
            exact = _exact_window(per_row, P, H, t, s, lo, hi)
            assert abs(_window_from_bins(dense, offsets, P, H, t, s, lo, hi) - exact) < 1e-5 * (1 + abs(exact))


@settings(max_examples=40, deadline=None)
@given(H=st.integers(1, 8), ratio=st.floats(1.0, 7.0), lo=st.floats(-4, 4), width=st.floats(0.05, 5))
def test_evenly_lit_rows_give_every_window_exactly(H, ratio, lo, width):
    """Where the light is the same in neighbouring rows, any window (sub-bin edges too) is exact."""
    from planeray.transport import bin_projector_rows

    P = max(1, int(round(H * ratio)))
    g = RowGeometry(H, P)
    per_row = np.ones((P, H, 1))
    offsets = np.arange(-P - 2, P + 3)
    dense, _ = bin_projector_rows(per_row, g, offsets)
    hi = lo + width
    for t in range(H):
        exact = _exact_window(per_row, P, H, t, 0, lo, hi)
        assert abs(_window_from_bins(dense, offsets, P, H, t, 0, lo, hi) - exact) < 1e-6
        # planeray's own band weights (the edge rule included) give the same
        centre_us, width_us = 0.5 * (lo + hi) * 1e6 / 54000, width * 1e6 / 54000
        image = Transport(dense, offsets, g).render(Band(centre_us, width_us, 54000))
        assert abs(image[t, 0] - exact) < 1e-5


def test_row_bins_split_each_row_by_its_overlap_with_two_bins():
    g = RowGeometry(64, 96)  # p_t = 1.5 t + 0.25: bins straddle projector rows
    first, share = g.row_bins(np.arange(64))
    for t in (0, 1, 17):
        p_t = 1.5 * t + 0.25
        for v in (0, 5, 95):
            k = v + first[t]
            assert _overlap(v - 0.5, v + 0.5, p_t + k - 0.5, p_t + k + 0.5) == pytest.approx(1 - share[t])
            assert _overlap(v - 0.5, v + 0.5, p_t + k + 0.5, p_t + k + 1.5) == pytest.approx(share[t])
    assert np.all(RowGeometry(16).row_bins(np.arange(16))[1] == 0)  # P = H: one bin per row


def test_edge_rule_leaves_projector_coordinates_outside_the_projector_unlit():
    """Eq. 4 integrates over [-1/2, P - 1/2): a bin straddling the edge holds the light of its part inside
    and a band lights it in proportion to the fraction of that part it covers."""
    g = RowGeometry(64, 96)
    t = 0  # p_0 = 0.25: the projector's upper edge is at offset -0.75
    assert g.coverage(t, 0) == 1.0
    assert g.coverage(t, -1) == pytest.approx(0.25)  # bin [-1.5, -0.5) of which [-0.75, -0.5) is inside
    assert g.coverage(t, -2) == 0.0
    # evenly lit projector: a bin holds its length inside the projector
    offsets = np.arange(-4, 5)
    dense = np.broadcast_to(g.coverage(np.arange(64)[:, None], offsets[None, :])[:, None, :], (64, 1, 9))
    T = Transport(np.ascontiguousarray(dense, np.float32), offsets, g)
    row_us = 1e6 / 54000
    image = T.render(Band(0.0, 5 * row_us, 54000))  # band [-2.5, 2.5): lights [-0.5, 2.75) of the projector
    assert image[0, 0] == pytest.approx(3.25)
    assert image[30, 0] == pytest.approx(5.0)
    assert T.render(Band(-1.25 * row_us, 0.5 * row_us, 54000))[0, 0] == 0.0  # [-1.5, -1.0): outside
    half = T.render(Band(-0.625 * row_us, 0.25 * row_us, 54000))[0, 0]  # [-0.75, -0.5): the inside part of bin -1
    assert half == pytest.approx(0.25)
    full = T.render(RowPattern(np.ones(96)))
    np.testing.assert_allclose(full, T.full_image(), rtol=1e-6)  # all rows lit = all the light
