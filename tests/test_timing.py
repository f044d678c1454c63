"""Imaging model (Eqs. 1-3) against closed forms and independent discretizations."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planeray.timing import (
    Band,
    RowGeometry,
    RowPattern,
    Sweep,
    band_bin_weights,
    band_centre_rows,
    band_interval_weights,
    band_weights_at_row,
    band_width_rows,
    boundary_images,
    delay_from_sync_offset,
    illumination,
    make_sweep,
    paper_sweep,
    sweep_support_rows,
    sync_offset_from_delay,
)

finite = dict(allow_nan=False, allow_infinity=False)


def test_eq1_closed_form():
    # t_d = t_e/2 - t_p/2 - t'_o
    assert delay_from_sync_offset(100.0, 600.0, line_time_us=20.0) == pytest.approx(300 - 10 - 100)
    # default t_p is one scanline period: 1e6 / 54000 us
    assert delay_from_sync_offset(0.0, 600.0, lines_per_second=54000) == pytest.approx(300 - 0.5e6 / 54000)


@given(st.floats(-5000, 5000, **finite), st.floats(1, 5000, **finite), st.floats(0, 100, **finite))
def test_eq1_inverse_round_trip(delay, exposure, t_p):
    offset = sync_offset_from_delay(delay, exposure, line_time_us=t_p)
    assert delay_from_sync_offset(offset, exposure, line_time_us=t_p) == pytest.approx(delay, abs=1e-9)


def test_eq2_paper_numbers():
    assert band_centre_rows(1500, 54000) == pytest.approx(81.0)
    assert band_width_rows(600, 54000) == pytest.approx(32.4)
    assert band_width_rows(500, 54000) == pytest.approx(27.0)  # the calibration: 27 lines in 500 us


def test_eq3_indicator_and_sign_convention():
    u = np.arange(-100, 101)
    L = illumination(u, 1000.0, 600.0, 54000)  # centre +54, half width 16.2
    lit = u[L > 0]
    assert lit.min() == 38 and lit.max() == 70
    # positive delay lights lower projector rows (u = v - t > 0)
    assert np.all(lit > 0)


def _brute_force_bins(k, centre, width, sigma=0.0, line=0.0, n=801):
    """Independent reference: integrate the blurred box on a fine grid."""
    x = np.linspace(-0.5, 0.5, n)
    out = []
    for kk in k:
        xs = kk + x
        if sigma == 0 and line == 0:
            f = (np.abs(xs - centre) <= width / 2).astype(float)
        else:
            # box convolved with kernel: average of shifted boxes over kernel samples
            z = np.linspace(-6, 6, 121)
            g = np.exp(-0.5 * z**2) if sigma > 0 else np.zeros_like(z)
            shifts = z * sigma if sigma > 0 else np.array([0.0])
            wts = g / g.sum() if sigma > 0 else np.array([1.0])
            if line > 0:
                ls = ((np.arange(100) + 0.5) / 100 - 0.5) * line
                shifts = (shifts[:, None] + ls[None, :]).ravel()
                wts = (wts[:, None] * np.full(100, 1 / 100)[None, :]).ravel()
            f = (np.abs(xs[None, :] - shifts[:, None] - centre) <= width / 2).astype(float)
            f = (wts[:, None] * f).sum(axis=0)
        out.append(np.trapezoid(f, xs))
    return np.array(out)


@pytest.mark.parametrize(("sigma", "line"), [(0.0, 0.0), (0.8, 0.0), (0.0, 1.5), (0.6, 1.0)])
def test_bin_weights_match_brute_force_integration(sigma, line):
    k = np.arange(-12, 13)
    w = band_bin_weights(k, 2.3, 9.7, blur_sigma_rows=sigma, line_width_rows=line)
    ref = _brute_force_bins(k, 2.3, 9.7, sigma, line)
    np.testing.assert_allclose(w, ref, atol=2e-3)


@settings(max_examples=200)
@given(
    st.floats(-60, 60, **finite),
    st.floats(0.01, 70, **finite),
    st.floats(0, 3, **finite),
    st.floats(0, 3, **finite),
)
def test_bin_weights_sum_to_band_width(centre, width, sigma, line):
    k = np.arange(-150, 151)
    w = band_bin_weights(k, centre, width, blur_sigma_rows=sigma, line_width_rows=line)
    assert w.sum() == pytest.approx(width, rel=1e-9, abs=1e-9)
    assert np.all(w >= -1e-12) and np.all(w <= 1 + 1e-12)


def test_paper_sweep():
    s = paper_sweep()
    assert len(s) == 85
    assert (~s.excluded).sum() == 75
    assert sorted(set(s.delay_us)) == list(np.arange(-8, 9) * 187.5)
    assert sorted(set(s.exposure_us)) == [600.0, 750.0, 900.0, 1050.0, 1200.0]
    # flagged images are exactly the boundary rule
    assert np.array_equal(s.excluded, np.abs(np.abs(s.delay_us) - s.exposure_us / 2) <= 75)
    K = sweep_support_rows(s, 54000)
    assert 2 * K + 1 == 229
    assert make_sweep("paper").name == "paper"
    with pytest.raises(ValueError, match="unknown sweep"):
        make_sweep("nope")


def test_boundary_rule_examples():
    assert boundary_images(375.0, 750.0)  # |375| - 375 = 0
    assert boundary_images(-562.5, 1050.0)  # 37.5
    assert not boundary_images(0.0, 600.0)
    assert not boundary_images(187.5, 600.0)  # 112.5


def test_sweep_validation():
    with pytest.raises(ValueError):
        Sweep([0.0, 1.0], [600.0], [False, False])
    with pytest.raises(ValueError):
        Sweep([0.0], [-600.0], [False])


def test_scaled_camera_geometry():
    g = RowGeometry(128, 720)
    assert g.rows_per_camera_row == pytest.approx(5.625)
    # centres of the first and last camera row in projector coordinates
    assert g.projector_row_of(0) == pytest.approx(2.3125)
    assert g.projector_row_of(127) == pytest.approx(716.6875)
    # rows near the top have fewer valid offsets
    cov = g.coverage(0, np.arange(-5, 6))
    assert cov[0] == 0 and cov[-1] == 1 and 0 < cov[2] < 1


def test_band_is_clipped_to_projector():
    g = RowGeometry(128)
    b = Band(-1000.0, 600.0, 54000)  # centre -54 rows: above the top for early rows
    w = b.weights(g, np.arange(128)[:, None], np.arange(-80, 81)[None, :])
    assert w[0].sum() == 0  # camera row 0 sees projector rows -70..-38: none exist
    assert w[63].sum() == pytest.approx(25.7)  # rows -7.2..25.2 clipped at the top edge -0.5
    assert w[100].sum() == pytest.approx(32.4)


def test_row_pattern_matches_band():
    g = RowGeometry(50)
    b = Band(200.0, 300.0, 54000)
    t = 25
    u = np.arange(-40, 41)
    v = np.arange(50)
    pattern = band_bin_weights(v - t, b.centre_rows, b.width_rows)  # band around row t
    np.testing.assert_allclose(RowPattern(pattern).weights(g, t, u), b.weights(g, t, u), atol=1e-12)


def test_row_jitter_averages_frames():
    g = RowGeometry(4)
    shifts = np.array([[0.5, 0, 0, 0], [-0.5, 0, 0, 0]])
    b = Band(0.0, 300.0, 54000, row_shifts_rows=shifts)
    u = np.arange(-20, 21)
    w = b.weights(g, np.arange(4)[:, None], u[None, :])
    b0 = Band(0.0, 300.0, 54000)
    ref0 = 0.5 * (band_bin_weights(u, 0.5, b0.width_rows) + band_bin_weights(u, -0.5, b0.width_rows))
    np.testing.assert_allclose(w[0], ref0 * g.coverage(0, u), atol=1e-12)
    np.testing.assert_allclose(w[1], b0.weights(g, 1, u), atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    camera_rows=st.integers(2, 60),
    projector_rows=st.integers(2, 700),
    delay_us=st.floats(-15_000.0, 15_000.0, **finite),
    exposure_us=st.floats(5.0, 3_000.0, **finite),
    jitter_us=st.sampled_from([0.0, 0.5, 10.0, 120.0]),
    line_width_us=st.sampled_from([0.0, 1.5, 40.0]),
    shift_rows=st.sampled_from([0.01, 0.5, 4.0]),
    frames=st.integers(1, 8),
    entries=st.booleans(),
    seed=st.integers(0, 2**16),
)
def test_row_jitter_weights_equal_every_frames_integral_over_every_bin(
    camera_rows, projector_rows, delay_us, exposure_us, jitter_us, line_width_us, shift_rows, frames, entries, seed
):
    """With realized row shifts only the bins near the band are integrated: the same bytes as all of them.

    Reference: the exact integral (band_interval_weights) of each frame's shifted band over
    every bin's part inside the projector, averaged over the frames, as a fraction of the part.
    """
    rng = np.random.default_rng(seed)
    geometry = RowGeometry(camera_rows, projector_rows)
    shifts = rng.normal(0.0, shift_rows, size=(frames, camera_rows))
    band = Band(delay_us, exposure_us, 54_000.0, jitter_us, line_width_us, row_shifts_rows=shifts)
    if entries:  # a transport's sparse entries: (row, offset) pairs
        n = int(rng.integers(1, 300))
        rows, offsets = rng.integers(0, camera_rows, n), rng.integers(-projector_rows, projector_rows + 1, n)
    else:
        rows, offsets = np.arange(camera_rows)[:, None], np.arange(-projector_rows, projector_rows + 1)[None, :]
    lo, hi = geometry.bin_parts(rows, offsets)
    sigma, line = jitter_us * 1e-6 * 54_000.0, line_width_us * 1e-6 * 54_000.0  # as Band computes them
    lit = sum(
        band_interval_weights(
            lo, hi, band.centre_rows + s[rows], band.width_rows, blur_sigma_rows=sigma, line_width_rows=line
        )
        for s in shifts
    )
    part = hi - lo
    expected = np.where(part > 1e-9, np.minimum(lit / frames / np.where(part > 1e-9, part, 1.0), 1.0), 0.0)
    np.testing.assert_array_equal(band.weights(geometry, rows, offsets), expected)


def test_jittered_weights_are_computed_once_per_band_and_geometry(monkeypatch):
    """The same band with the same realized shifts on the same geometry (another scene of one sweep and
    seed) is integrated once: later calls give the same bytes, as a new array of the caller's own; any
    other shift, rows, offsets, geometry or band setting is integrated anew."""
    import planeray.timing as timing

    monkeypatch.setattr(timing, "_JITTERED", timing.OrderedDict())
    monkeypatch.setattr(timing, "_jittered_bytes", 0)
    computed = []
    integrate = Band._jittered_weights
    monkeypatch.setattr(Band, "_jittered_weights", lambda self, *a: computed.append(1) or integrate(self, *a))
    rng = np.random.default_rng(0)
    shifts = rng.normal(0.0, 0.5, size=(4, 16))
    g = RowGeometry(16, 90)
    rows, u = np.arange(16)[:, None], np.arange(-30, 31)[None, :]
    band = Band(150.0, 600.0, 54_000.0, 5.0, row_shifts_rows=shifts)
    first = band.weights(g, rows, u)
    again = Band(150.0, 600.0, 54_000.0, 5.0, row_shifts_rows=shifts.copy()).weights(g, rows, u)
    assert len(computed) == 1
    np.testing.assert_array_equal(again, first)
    assert again.flags.writeable and not np.shares_memory(again, first)
    again[:] = -1.0  # the caller's own array: what is kept is not touched
    np.testing.assert_array_equal(band.weights(g, rows, u), first)
    assert len(computed) == 1
    other_shifts = shifts.copy()
    other_shifts[3, 7] += 1e-9
    others = [
        (Band(150.0, 600.0, 54_000.0, 5.0, row_shifts_rows=other_shifts), g, rows, u),
        (Band(150.0, 600.0, 54_000.0, 5.5, row_shifts_rows=shifts), g, rows, u),
        (Band(151.0, 600.0, 54_000.0, 5.0, row_shifts_rows=shifts), g, rows, u),
        (band, RowGeometry(16, 91), rows, u),
        (band, g, rows, u[:, :-1]),
        (band, g, rows[::-1], u),
    ]
    for i, (b, geometry, r, o) in enumerate(others, start=2):
        w = b.weights(geometry, r, o)
        assert len(computed) == i
        np.testing.assert_array_equal(w, integrate(b, geometry, r, o))  # its own weights, not the kept ones
    # bounded: the least recently used are dropped beyond the budget
    monkeypatch.setattr(timing, "WEIGHTS_CACHE_BYTES", 2 * first.nbytes)
    for k in range(4):
        Band(100.0 + k, 600.0, 54_000.0, 5.0, row_shifts_rows=shifts).weights(g, rows, u)
    assert len(timing._JITTERED) == 2 and timing._jittered_bytes == 2 * first.nbytes


@settings(max_examples=40, deadline=None)
@given(
    camera_rows=st.integers(8, 300),
    projector_rows=st.integers(8, 900),
    row_frac=st.floats(0.0, 1.0),
    jitter_us=st.sampled_from([0.0, 3.0, 25.0]),
    line_width_us=st.sampled_from([0.0, 1.5, 40.0]),
)
def test_band_weights_at_row_are_each_bands_own_weights(
    camera_rows, projector_rows, row_frac, jitter_us, line_width_us
):
    """The vectorized weights of a demultiplexing problem are exactly each band's :meth:`Band.weights`."""
    geometry = RowGeometry(camera_rows, projector_rows)
    row = min(int(row_frac * camera_rows), camera_rows - 1)
    bands = paper_sweep().bands(54_000.0, jitter_us=jitter_us, line_width_us=line_width_us)
    offsets = np.arange(-70, 71)
    expected = np.stack([b.weights(geometry, row, offsets) for b in bands])
    np.testing.assert_array_equal(band_weights_at_row(bands, geometry, row, offsets), expected)
    # bands of different blurs (and with realized row shifts) fall back to the bands' own weights
    mixed = bands[:3] + [Band(100.0, 600.0, 54_000.0, jitter_us + 7.0, 0.0)]
    np.testing.assert_array_equal(
        band_weights_at_row(mixed, geometry, row, offsets), np.stack([b.weights(geometry, row, offsets) for b in mixed])
    )
