"""The pulse (Sec. 10, Fig. 15): waveform, video files, Eulerian magnification, heart rate, the simulated capture, CLI.

What does not need the skin scene is checked here against closed forms and independent
references (OpenCV frame by frame, Wu et al.'s one-sided filter, a linear toy scene); the
skin-scene acceptance tests are in ``tests/test_pulse_skin.py``.
"""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from planeray.cli import app
from planeray.errors import InputError
from planeray.pulse.evm import ideal_bandpass, laplacian_pyramid, magnify, pyramid_down, pyramid_up
from planeray.pulse.rate import estimate_heart_rate, find_pulse_region, parse_region, region_signal
from planeray.pulse.simulate import LiveSettings, linearize, simulate_live
from planeray.pulse.video_io import Video, read_video, write_video
from planeray.pulse.waveform import beat_shape, cardiac_signal
from planeray.scenes.base import Scene, scene_offsets
from planeray.timing import RowGeometry
from planeray.transport import Transport

runner = CliRunner()
FPS = 30.0


def pulse_video(bpm=66.0, n=600, shape=(32, 32), amplitude=0.004, noise=0.01, seed=0):
    """A flat grey video whose middle block pulses with a PPG waveform, plus white noise."""
    rng = np.random.default_rng(seed)
    c = cardiac_signal(n, FPS, bpm=bpm, seed=seed).volume
    frames = 0.4 + noise * rng.standard_normal((n, *shape))
    H, W = shape
    frames[:, H // 4 : 3 * H // 4, W // 4 : 3 * W // 4] -= amplitude * c[:, None, None]
    return Video(frames.astype(np.float32), FPS, "test")


# --------------------------------------------------------------------------- waveform
def test_beat_has_a_systolic_peak_a_dicrotic_notch_and_a_diastolic_wave():
    phase = np.linspace(0, 1, 2001)
    v = beat_shape(phase)
    d = np.diff(v)
    maxima = phase[1:-1][(d[:-1] > 0) & (d[1:] <= 0)]
    minima = phase[1:-1][(d[:-1] < 0) & (d[1:] >= 0)]
    assert len(maxima) == 2 and maxima[0] == pytest.approx(0.2, abs=0.01)  # systolic, then diastolic peak
    notch = minima[(minima > maxima[0]) & (minima < maxima[1])]
    assert len(notch) == 1 and 0.25 < notch[0] < 0.4  # the dicrotic notch between them
    assert v[np.searchsorted(phase, notch[0])] > 0.2  # a notch, not diastole


@pytest.mark.parametrize("bpm", [45.0, 72.0, 120.0])
def test_cardiac_signal_beats_at_its_rate_with_and_without_variability(bpm):
    s = cardiac_signal(1800, FPS, bpm=bpm, seed=1)
    assert len(s.beat_times_s) == pytest.approx(bpm, abs=1)  # 60 s
    assert np.allclose(60 / np.diff(s.beat_times_s), bpm, rtol=1e-6)
    v = cardiac_signal(1800, FPS, bpm=bpm, hrv=0.03, rsa=0.04, seed=1)
    ibi = 60 / np.diff(v.beat_times_s)
    assert ibi.std() > 0.01 * bpm  # the rate varies
    assert v.mean_rate_bpm == pytest.approx(len(v.beat_times_s), rel=0.05)


# --------------------------------------------------------------------------- magnification
def test_ideal_bandpass_keeps_in_band_sinusoids_exactly_and_removes_the_rest():
    t = np.arange(600) / FPS
    inside = 0.3 * np.sin(2 * np.pi * 1.2 * t + 0.4)
    x = 2.0 + inside + np.sin(2 * np.pi * 0.2 * t) + np.sin(2 * np.pi * 5 * t)
    assert np.allclose(ideal_bandpass(x, FPS, (0.5, 2.0)), inside, atol=1e-9)


def _wu_one_sided_bandpass(x, fps, lo, hi):
    """Wu et al.'s MATLAB ideal_bandpassing: a mask on the frequencies 0..fs of fft, real(ifft)."""
    n = x.shape[0]
    freq = np.arange(n) / n * fps
    mask = (freq > lo) & (freq < hi)
    spec = np.fft.fft(x, axis=0)
    spec[~mask] = 0
    return np.real(np.fft.ifft(spec, axis=0))


def test_amplification_convention_is_one_plus_alpha_and_wu_s_filter_halves_it():
    t = np.arange(300) / FPS
    a = 0.01 * np.sin(2 * np.pi * 1.2 * t)  # exactly 12 periods
    video = (0.5 + a[:, None, None] * np.ones((1, 16, 16))).astype(np.float32)
    for alpha in (10.0, 50.0):
        out = magnify(video, FPS, levels=2, alpha=alpha)
        gain = np.ptp(out[:, 8, 8]) / np.ptp(a)
        assert gain == pytest.approx(1 + alpha, rel=1e-3)
    wu = a + 50.0 * _wu_one_sided_bandpass(a, FPS, 0.5, 2.0)
    assert np.ptp(wu) / np.ptp(a) == pytest.approx(1 + 50.0 / 2, rel=1e-3)
    # out of band: untouched
    slow = (0.5 + 0.01 * np.sin(2 * np.pi * 0.1 * t))[:, None, None] * np.ones((1, 16, 16))
    assert np.allclose(magnify(slow, FPS, levels=2), slow, atol=1e-5)


def test_pyramids_are_opencv_frame_by_frame_and_the_laplacian_pyramid_is_lossless():
    import cv2

    rng = np.random.default_rng(0)
    frames = rng.random((600, 20, 27)).astype(np.float32)  # > 512 frames: two channel blocks
    small, sizes = pyramid_down(frames, 3)
    ref = frames[599]
    for _ in range(3):
        ref = cv2.pyrDown(ref)
    assert np.allclose(small[599], ref, atol=1e-6)
    assert sizes == [(20, 27), (10, 14), (5, 7), (3, 4)]
    up = pyramid_up(small, sizes)
    assert up.shape == frames.shape
    bands = laplacian_pyramid(frames[:40], 3)
    rec = bands[-1]
    for b in reversed(bands[:-1]):
        rec = np.stack([cv2.pyrUp(f, dstsize=(b.shape[2], b.shape[1])) for f in rec]) + b
    assert np.allclose(rec, frames[:40], atol=1e-5)


def test_laplacian_magnification_amplifies_every_band_but_the_residual():
    from planeray.pulse.evm import level_alphas

    t = np.arange(240) / FPS
    a = 0.01 * np.sin(2 * np.pi * 1.0 * t)
    rng = np.random.default_rng(0)
    tex = ((0.5 + 0.1 * rng.random((32, 32)))[None] * (1 + a[:, None, None])).astype(np.float32)
    out = magnify(tex, FPS, levels=3, pyramid="laplacian", alpha=20)
    # linear: the added video is alpha times the band-passed detail above the low-pass residual
    low, sizes = pyramid_down(tex, 3)
    detail = tex - pyramid_up(low, sizes)
    assert np.allclose(out - tex, 20 * ideal_bandpass(detail, FPS, (0.5, 2.0)), atol=2e-6)
    # a spatially uniform change lives in the residual, which is not amplified (Wu's code)
    flat = (0.5 + a[:, None, None] * np.ones((1, 32, 32))).astype(np.float32)
    assert np.allclose(magnify(flat, FPS, levels=3, pyramid="laplacian", alpha=20), flat, atol=1e-5)
    # Wu's spatial cut-off: finest level and residual 0, alpha capped where lambda is short
    gains = level_alphas((480, 640), 4, 50.0, 1000.0)
    assert gains[0] == 0 and gains[-1] == 0 and max(gains) <= 50
    assert 0 < gains[1] < gains[2] < gains[3]  # coarser levels (longer wavelengths) get more
    assert level_alphas((480, 640), 4, 50.0, 16.0)[1:4] == [50.0] * 3
    with pytest.raises(InputError, match="too many"):
        magnify(flat[:, :4, :4], FPS, levels=5)


# --------------------------------------------------------------------------- heart rate
def test_zero_padding_and_interpolation_beat_the_3_75_bpm_bin_of_480_frames():
    rates = np.linspace(50, 110, 25)
    err_bin, err_fine = [], []
    for bpm in rates:
        x = cardiac_signal(480, FPS, bpm=bpm, seed=0).volume
        err_bin.append(abs(estimate_heart_rate(x, FPS, pad=1, interpolate=False).peak_bpm - bpm))
        err_fine.append(abs(estimate_heart_rate(x, FPS).peak_bpm - bpm))
    assert 60 * FPS / 480 == 3.75
    assert max(err_bin) > 1.0  # up to half a bin
    assert max(err_fine) < 0.25 and np.mean(err_fine) < 0.1


def test_a_spectrum_computed_once_gives_what_each_estimate_computes():
    """``spectrum=``: one periodogram per padding serves the estimates with and without interpolation."""
    from scipy.signal import periodogram

    rng = np.random.default_rng(3)
    x = cardiac_signal(480, FPS, bpm=77.0, seed=3).volume + 0.3 * rng.standard_normal(480)
    for pad in (1, 8):
        spectrum = periodogram(x, FPS, window="hann", nfft=pad * x.size, detrend="linear")  # SciPy's, directly
        for interpolate in (False, True):
            shared = estimate_heart_rate(x, FPS, pad=pad, interpolate=interpolate, spectrum=spectrum)
            own = estimate_heart_rate(x, FPS, pad=pad, interpolate=interpolate)
            assert (shared.rate_bpm, shared.peak_bpm, shared.snr_db, shared.band_snr_db) == (
                own.rate_bpm,
                own.peak_bpm,
                own.snr_db,
                own.band_snr_db,
            )
    wrong = periodogram(x, FPS, window="hann", nfft=x.size, detrend="linear")  # pad 1, estimate asked at pad 8
    assert estimate_heart_rate(x, FPS, pad=8, spectrum=wrong).peak_bpm != estimate_heart_rate(x, FPS, pad=8).peak_bpm


def test_many_signals_spectra_in_one_call_are_each_signal_s_own():
    """``pulse_spectrum`` of (..., T) signals: each row's spectrum is SciPy's of that row alone."""
    from scipy.signal import periodogram, welch

    from planeray.pulse.rate import pulse_spectrum

    rng = np.random.default_rng(5)
    signals = rng.standard_normal((2, 3, 150)) + np.linspace(0.0, 4.0, 150)  # a trend for the detrending
    freqs, power = pulse_spectrum(signals, FPS, pad=4)
    assert power.shape == (2, 3, freqs.size)
    f_w, p_w = pulse_spectrum(signals, FPS, method="welch", segment_s=2.0, pad=2)
    for i, j in np.ndindex(2, 3):
        x = signals[i, j]
        f, p = periodogram(x, FPS, window="hann", nfft=4 * x.size, detrend="linear")
        np.testing.assert_array_equal(freqs, f)
        np.testing.assert_allclose(power[i, j], p, rtol=1e-12, atol=1e-15 * p.max())
        f, p = welch(x, FPS, window="hann", nperseg=60, noverlap=30, nfft=120, detrend="linear")
        np.testing.assert_array_equal(f_w, f)
        np.testing.assert_allclose(p_w[i, j], p, rtol=1e-12, atol=1e-15 * p.max())
    with pytest.raises(InputError, match="at least 4 samples"):
        pulse_spectrum(np.zeros((5, 3)), FPS)


def test_heart_rate_from_a_noisy_video_and_its_region():
    video = pulse_video(bpm=83.0)
    region = find_pulse_region(magnify(video.frames, FPS, levels=2), FPS)
    assert region[8:24, 8:24].sum() >= 0.9 * region.sum()  # the pulsing block
    est = estimate_heart_rate(region_signal(video.frames, region), FPS)
    assert est.rate_bpm == pytest.approx(83.0, abs=1.0)
    assert est.snr_db > 0 and est.band_snr_db > 3
    welch = estimate_heart_rate(region_signal(video.frames, region), FPS, method="welch", segment_s=10)
    assert welch.rate_bpm == pytest.approx(83.0, abs=1.5) and welch.bin_bpm == pytest.approx(6.0)
    assert region_signal(video.frames, parse_region("8,8,24,24", (32, 32))).shape == (600,)
    assert parse_region("3,4", (32, 32)) == (3, 4, 4, 5)
    with pytest.raises(InputError, match="not inside"):
        parse_region("30,30,40,40", (32, 32))


@pytest.mark.parametrize("seed", range(6))
def test_noise_and_breathing_alone_report_no_pulse(seed):
    from planeray.pulse.waveform import breathing_signal

    rng = np.random.default_rng(seed)
    x = rng.standard_normal(600) + 3 * breathing_signal(600, FPS, seed=seed)
    est = estimate_heart_rate(x, FPS)
    assert est.rate_bpm is None and not est.detected


# --------------------------------------------------------------------------- video files
def test_tiff_round_trip_keeps_frames_and_frame_rate(tmp_path):
    v = pulse_video(n=40)
    write_video(tmp_path / "v.tif", v)
    back = read_video(tmp_path / "v.tif")
    assert back.fps == pytest.approx(FPS) and np.array_equal(back.frames, v.frames)
    with pytest.raises(InputError, match="already exists"):
        write_video(tmp_path / "v.tif", v)
    assert read_video(tmp_path / "v.tif", fps=25).fps == 25


@pytest.mark.parametrize("suffix", [".mp4", ".avi", ".mkv"])
def test_video_files_are_decoded_with_their_frame_rate(tmp_path, suffix):
    v = pulse_video(n=24, shape=(17, 22))
    write_video(tmp_path / f"v{suffix}", v)
    back = read_video(tmp_path / f"v{suffix}")
    assert back.fps == pytest.approx(FPS) and back.n_frames == 24
    assert back.shape[0] >= 17 and back.shape[1] >= 22
    scale = np.percentile(v.frames, 99.9)
    err = np.abs(back.frames[:, :17, :22] * scale - v.frames).mean()
    assert err < 0.02 * scale


def test_bad_videos_give_one_line_errors(tmp_path):
    import tifffile
    from PIL import Image

    tifffile.imwrite(tmp_path / "nofps.tif", np.zeros((10, 8, 8), np.uint16))
    with pytest.raises(InputError, match="no frame rate"):
        read_video(tmp_path / "nofps.tif")
    assert read_video(tmp_path / "nofps.tif", fps=30).n_frames == 10
    tifffile.imwrite(tmp_path / "one.tif", np.zeros((8, 8), np.uint16))
    with pytest.raises(InputError, match="1 frame: a pulse needs a video"):
        read_video(tmp_path / "one.tif", fps=30)
    nan = np.zeros((10, 8, 8), np.float32)
    nan[3, 2, 2] = np.nan
    tifffile.imwrite(tmp_path / "nan.tif", nan)
    with pytest.raises(InputError, match="frame 3 contains NaN"):
        read_video(tmp_path / "nan.tif", fps=30)
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(10):
        Image.fromarray(np.zeros((8, 8), np.uint8)).save(folder / f"f{i}.png")
    with pytest.raises(InputError, match="no frame rate"):
        read_video(folder)
    Image.fromarray(np.zeros((8, 9), np.uint8)).save(folder / "f7.png")
    with pytest.raises(InputError, match=r"mixed sizes: f7.png"):
        read_video(folder, fps=30)
    (tmp_path / "x.gif").write_bytes(b"GIF89a")
    with pytest.raises(InputError, match="unknown video format"):
        read_video(tmp_path / "x.gif")
    (tmp_path / "bad.mp4").write_bytes(b"not a video")
    with pytest.raises(InputError, match="cannot decode"):
        read_video(tmp_path / "bad.mp4")
    with pytest.raises(InputError, match="no such file"):
        read_video(tmp_path / "missing.tif")


def test_folder_of_frames_in_natural_order(tmp_path):
    from PIL import Image

    for i in range(12):
        Image.fromarray(np.full((6, 6), i * 10, np.uint8)).save(tmp_path / f"frame{i}.png")
    v = read_video(tmp_path, fps=15)
    assert np.allclose(v.frames[:, 0, 0] * 255, np.arange(12) * 10, atol=1e-3)


# --------------------------------------------------------------------------- simulation (a linear toy scene)
def toy_builder(shape=(24, 24)):
    """Subsurface kernel with a blood-absorbing vein stripe, exactly linear in the blood scale."""
    H, W = shape
    u = scene_offsets(40)
    vein = np.zeros((H, W), bool)
    vein[:, W // 2 - 3 : W // 2 + 3] = True
    albedo = np.full((H, W), 0.6)

    def build(s):
        k = np.exp(-np.abs(u) / 30.0)
        dense = 0.5 * albedo[:, :, None] * k / k.sum()
        dense = dense * (1 - np.where(vein, 0.4 * s, 0.05 * s)[:, :, None] * (np.abs(u) >= 2))
        dense[:, :, u == 0] += 0.3
        T = Transport(dense.astype(np.float32), u, RowGeometry(H, 120))
        return Scene(
            "toy",
            T,
            np.full((H, W), 0.3, np.float32),
            albedo.astype(np.float32),
            np.zeros((H, W), np.uint8),
            {},
            {"vein_mask": vein},
        )

    return build


def test_linearization_is_exact_for_a_linear_scene_and_the_capture_is_reproducible():
    model = linearize(toy_builder(), check_amplitude=0.05)
    assert max(model.linearity_error.values()) < 1e-4
    s = LiveSettings(seconds=4, fps=FPS, bpm=90)
    a = simulate_live(s, model=model, seed=3)
    b = simulate_live(s, model=model, seed=3)
    for m in ("regular", "direct", "global", "indirect"):
        assert a.videos[m].frames.shape == (120, 24, 24)
        assert np.array_equal(a.videos[m].frames, b.videos[m].frames)
    assert a.truth["mean_rate_bpm"] == pytest.approx(90)
    # without noise and motion, the indirect vein signal is the blood volume, inverted (absorption)
    quiet = LiveSettings(
        seconds=4, fps=FPS, bpm=90, noise=False, breathing_px=0, breathing_gain=0, motion_px=0, laser_flicker=0
    )
    c = simulate_live(quiet, model=model, seed=3, methods=("indirect",))
    sig = region_signal(c.videos["indirect"].frames, model.scene.maps["vein_mask"])
    assert np.corrcoef(sig, c.truth["volume"])[0, 1] < -0.999


def test_the_arm_motion_moves_each_frame_as_scipy_s_bilinear_shift_does():
    """The video's motion, in one pass, against ``scipy.ndimage.shift`` frame by frame (the reference)."""
    from scipy.ndimage import shift

    from planeray.pulse.simulate import _shift_frames

    rng = np.random.default_rng(7)
    shifts = rng.normal(0.0, 3.0, (40, 2))
    shifts[:4] = [[0.0, 0.0], [2.0, -3.0], [-0.5, 0.25], [31.0, -45.5]]  # still, whole pixels, beyond the frame
    for dtype in (np.float64, np.float32):
        frames = rng.random((40, 17, 29)).astype(dtype)
        moved = _shift_frames(frames, shifts)
        assert moved.dtype == dtype and moved.shape == frames.shape
        for t in range(40):
            expected = shift(frames[t].astype(np.float64), shifts[t], order=1, mode="nearest")
            np.testing.assert_allclose(moved[t], expected, rtol=0, atol=1e-6 if dtype == np.float32 else 1e-13)
    still = rng.random((3, 5, 5))
    assert _shift_frames(still, np.zeros((3, 2))) is still


# --------------------------------------------------------------------------- CLI
def test_cli_pulse_writes_its_folder_and_reports_the_rate(tmp_path):
    write_video(tmp_path / "v.tif", pulse_video(bpm=75.0))
    res = runner.invoke(app, ["skin", "pulse", str(tmp_path / "v.tif"), "--out", str(tmp_path / "r"), "--json"])
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    assert got["rate_bpm"] == pytest.approx(75.0, abs=1.0)
    for name in ("pulse.json", "signal.csv", "spectrum.csv", "fig15a_pulse.png", "region.png", "planeray.json"):
        assert (tmp_path / "r" / name).is_file()
    res = runner.invoke(
        app,
        [
            "skin",
            "pulse",
            str(tmp_path / "v.tif"),
            "--out",
            str(tmp_path / "r"),
            "--region",
            "8,8,24,24",
            "--alpha",
            "20",
            "--levels",
            "2",
            "--band",
            "0.6,1.8",
            "--overwrite",
        ],
    )
    assert res.exit_code == 0 and "heart rate 75." in res.stdout
    # refuses a folder it did not write, and bad input in one line
    (tmp_path / "mine").mkdir()
    res = runner.invoke(app, ["skin", "pulse", str(tmp_path / "v.tif"), "--out", str(tmp_path / "mine"), "--overwrite"])
    assert res.exit_code == 1 and "did not write" in res.output
    import tifffile

    tifffile.imwrite(tmp_path / "nofps.tif", np.zeros((10, 8, 8), np.uint16))
    res = runner.invoke(app, ["skin", "pulse", str(tmp_path / "nofps.tif"), "--out", str(tmp_path / "n")])
    assert res.exit_code == 1 and "no frame rate" in res.output and "Traceback" not in res.output
    assert len(res.output.strip().splitlines()) == 1


@pytest.mark.usefixtures("figures_not_drawn")  # what it says; the pulse figure: the test above
def test_cli_pulse_says_when_there_is_no_pulse(tmp_path):
    write_video(tmp_path / "v.tif", pulse_video(amplitude=0.0, seed=4))
    res = runner.invoke(app, ["skin", "pulse", str(tmp_path / "v.tif"), "--out", str(tmp_path / "r")])
    assert res.exit_code == 0 and "no pulse found" in res.stdout


def test_the_skin_builder_builds_each_blood_scale_once():
    """A report linearizes at several delays: the same blood scale is the same scene, built once."""
    from planeray.pulse.simulate import skin_builder
    from planeray.scenes import make_scene

    build = skin_builder((8, 8), projector_rows=32, seed=2)
    assert build(1.0) is build(1) and build(1.02) is not build(1.0)
    fresh = make_scene("skin", (8, 8), projector_rows=32, seed=2, blood_scale=1.02)
    np.testing.assert_array_equal(build(1.02).transport.dense, fresh.transport.dense)
    assert not np.array_equal(build(1.0).transport.dense, fresh.transport.dense)
