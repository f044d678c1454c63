"""The pulse analysis in bounded memory (issue 40): videos read frame by frame, what does not fit kept on disk.

Checked against an independent reference -- the in-memory pipeline written out here with NumPy and
OpenCV (the Gaussian magnification of the whole video, the region search of the whole magnified
video by ``numpy.fft``), as ``skin pulse`` computed it before -- on short videos from a TIFF, a folder
of frames and an mp4, with a memory allowance small enough that the tiles and the disk are used;
the memory a moderately sized video takes (tracemalloc, which NumPy reports its allocations to);
the refusal of what the disk beside the output cannot hold; and what an interruption or a failing
disk leaves (nothing).
"""

from __future__ import annotations

import errno
import json
import os
import tracemalloc

import numpy as np
import pytest
from typer.testing import CliRunner

from planeray.cli import app
from planeray.pulse.analysis import analyze_pulse, scratch_bytes
from planeray.pulse.rate import estimate_heart_rate
from planeray.pulse.video_io import Video, open_video, read_video, write_video
from planeray.pulse.waveform import cardiac_signal
from test_faults import one_line_error

runner = CliRunner()
FPS = 30.0
#: A memory allowance that puts the magnified video and the spectra of these small videos on disk.
SMALL = 64 * 1024


def pulse_frames(n=300, shape=(32, 40), bpm=75.0, amplitude=0.01, noise=0.01, seed=0):
    """A flat grey video whose middle block pulses with a PPG waveform, plus white noise (float32, 0..1)."""
    rng = np.random.default_rng(seed)
    c = cardiac_signal(n, FPS, bpm=bpm, seed=seed).volume
    frames = 0.4 + noise * rng.standard_normal((n, *shape))
    H, W = shape
    frames[:, H // 4 : 3 * H // 4, W // 4 : 3 * W // 4] -= amplitude * c[:, None, None]
    return frames.astype(np.float32)


def reference(frames, fps=FPS, *, levels=4, band=(0.5, 2.0), alpha=50.0, rate_band=(0.7, 2.0), fraction=0.05):
    """The whole-video pipeline, written out: magnified frames, the region, its signals (magnified, raw)."""
    import cv2

    T = frames.shape[0]
    sizes = [frames.shape[1:]]
    for _ in range(levels):
        sizes.append(((sizes[-1][0] + 1) // 2, (sizes[-1][1] + 1) // 2))
    small = []
    for f in frames:
        for _ in range(levels):
            f = cv2.pyrDown(f)
        small.append(f)
    spec = np.fft.rfft(np.array(small), axis=0)
    freq = np.fft.rfftfreq(T, 1.0 / fps)
    spec[(freq < band[0]) | (freq > band[1])] = 0
    filtered = np.fft.irfft(spec, T, axis=0).astype(np.float32) * np.float32(alpha)
    mag = frames.copy()
    for t in range(T):
        up = filtered[t]
        for h, w in reversed(sizes[:-1]):
            up = cv2.pyrUp(up, dstsize=(w, h))
        mag[t] += up
    x = mag.reshape(T, -1)
    x = x - x.mean(axis=0)
    power = np.abs(np.fft.rfft(x * np.hanning(T)[:, None].astype(np.float32), axis=0)) ** 2
    inband = (freq >= rate_band[0]) & (freq <= rate_band[1])
    norm = power[inband] / np.maximum(power[inband].sum(axis=0, keepdims=True), 1e-30)
    k0 = int(np.argmax(norm.sum(axis=1)))
    score = norm[np.abs(np.arange(norm.shape[0]) - k0) <= 1].sum(axis=0)
    top = np.argsort(score)[::-1][: max(4, int(np.ceil(fraction * score.size)))]
    region = np.zeros(frames.shape[1:], bool)
    region.ravel()[top] = True
    return mag, region, mag[:, region].mean(axis=1, dtype=np.float64), frames[:, region].mean(axis=1, dtype=np.float64)


def decoded(path):
    """The float32 frames of ``path``, read here without planeray: tifffile, Pillow, OpenCV."""
    import cv2
    import tifffile
    from PIL import Image

    if path.is_dir():
        return np.stack([np.asarray(Image.open(f)) for f in sorted(path.iterdir())]).astype(np.float32) / np.float32(
            255
        )
    if path.suffix == ".tif":
        return tifffile.imread(path).astype(np.float32)
    cap, frames = cv2.VideoCapture(str(path)), []
    while (got := cap.read())[0]:
        rgb = got[1][..., ::-1].astype(np.float32) / np.float32(255)
        frames.append(rgb[..., 0] * 0.299 + rgb[..., 1] * 0.587 + rgb[..., 2] * 0.114)
    return np.stack(frames)


@pytest.fixture(scope="module")
def videos(tmp_path_factory):
    """The same pulsing video as a float32 TIFF, a folder of 8-bit PNG frames and an mp4."""
    from PIL import Image

    d = tmp_path_factory.mktemp("stream_videos")
    frames = pulse_frames()
    write_video(d / "v.tif", Video(frames, FPS, "test"))
    (d / "frames").mkdir()
    for t, f in enumerate(np.clip(frames * 255 + 0.5, 0, 255).astype(np.uint8)):
        Image.fromarray(f).save(d / "frames" / f"f{t:04d}.png")
    write_video(d / "v.mp4", Video(frames, FPS, "test"), white=1.0)
    return {"tif": d / "v.tif", "frames": d / "frames", "mp4": d / "v.mp4"}


@pytest.mark.parametrize("kind", ["tif", "frames", "mp4"])
def test_streamed_analysis_is_the_whole_video_analysis(kind, videos, tmp_path):
    """From a TIFF, a frame folder and an mp4, read frame by frame with the disk used: the region, the
    signals, the rate and the SNR of the whole-video pipeline written out in this test."""
    path = videos[kind]
    frames = decoded(path)
    mag, region, signal, raw = reference(frames)
    video = open_video(path, fps=FPS if kind == "frames" else None)
    res = analyze_pulse(video, memory_bytes=SMALL, scratch_dir=tmp_path, keep_video=True)
    assert res.scratch_disk_bytes >= frames.nbytes  # the magnified video went to disk
    assert list(tmp_path.iterdir()) == []  # and was removed
    np.testing.assert_array_equal(res.region, region)
    np.testing.assert_allclose(res.magnified, mag, rtol=0, atol=1e-6)
    np.testing.assert_allclose(res.signal, signal, rtol=1e-7)
    np.testing.assert_allclose(res.raw_signal, raw, rtol=1e-7)
    np.testing.assert_allclose(res.mean_frame, frames.mean(axis=0), rtol=1e-6)
    expected = estimate_heart_rate(signal, FPS)
    assert res.estimate.rate_bpm == pytest.approx(expected.rate_bpm, abs=1e-6)
    assert res.estimate.rate_bpm == pytest.approx(75.0, abs=1.0)
    assert res.estimate.snr_db == pytest.approx(expected.snr_db, abs=1e-6)
    assert res.estimate_raw.rate_bpm == pytest.approx(estimate_heart_rate(raw, FPS).rate_bpm, abs=1e-6)
    # the frames in memory (the public API's in-memory path): the same numbers, to the bit
    whole = analyze_pulse(Video(frames, FPS, "test"))
    np.testing.assert_array_equal(whole.region, res.region)
    np.testing.assert_array_equal(whole.signal, res.signal)
    assert whole.estimate.to_dict() == res.estimate.to_dict()


@pytest.mark.usefixtures("figures_not_drawn")
@pytest.mark.parametrize("kind", ["tif", "frames", "mp4"])
def test_skin_pulse_writes_the_same_files_whatever_its_memory(kind, videos, tmp_path, monkeypatch):
    """``skin pulse`` with its default allowance (all in memory) and with one that sends the magnified video
    and the spectra to disk: the same pulse.json and CSVs, to the byte, and the signals of the reference."""
    import planeray.pulse.analysis as pa

    path = videos[kind]
    words = ["skin", "pulse", str(path), "--json"] + (["--fps", "30"] if kind == "frames" else [])
    assert runner.invoke(app, [*words, "--out", str(tmp_path / "memory")]).exit_code == 0
    monkeypatch.setattr(pa, "DEFAULT_MEMORY_BYTES", SMALL)
    res = runner.invoke(app, [*words, "--out", str(tmp_path / "disk")])
    assert res.exit_code == 0, res.output
    for name in ("pulse.json", "signal.csv", "spectrum.csv"):
        assert (tmp_path / "disk" / name).read_bytes() == (tmp_path / "memory" / name).read_bytes(), name
    assert sorted(p.name for p in (tmp_path / "disk").iterdir()) == sorted(
        p.name for p in (tmp_path / "memory").iterdir()
    )  # no scratch folder left in the result
    _, region, signal, raw = reference(decoded(path))
    got = np.loadtxt(tmp_path / "disk" / "signal.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(got[:, 1], raw, rtol=1e-7)
    np.testing.assert_allclose(got[:, 2], signal, rtol=1e-7)
    assert json.loads(res.stdout)["region"]["pixels"] == int(region.sum())


def test_the_magnified_video_is_written_frame_by_frame(videos, tmp_path, monkeypatch):
    """``--magnified``: a float32 TIFF of the reference's magnified frames; an 8-bit mp4 whose white is the
    source's 99.9th percentile (found from the largest values only), with the disk used for the search."""
    import planeray.pulse.analysis as pa

    monkeypatch.setattr(pa, "DEFAULT_MEMORY_BYTES", SMALL)
    frames = decoded(videos["tif"])
    mag, *_ = reference(frames)
    res = runner.invoke(
        app, ["skin", "pulse", str(videos["tif"]), "--out", str(tmp_path / "r"), "--magnified", str(tmp_path / "m.tif")]
    )
    assert res.exit_code == 0, res.output
    back = read_video(tmp_path / "m.tif")
    assert back.fps == pytest.approx(FPS)
    np.testing.assert_allclose(back.frames, mag, rtol=0, atol=1e-6)
    res = runner.invoke(
        app,
        ["skin", "pulse", str(videos["tif"]), "--out", str(tmp_path / "r2"), "--magnified", str(tmp_path / "m.mp4")],
    )
    assert res.exit_code == 0, res.output
    scaled = np.clip(mag * (255.0 / np.percentile(frames, 99.9)) + 0.5, 0, 255)
    assert np.abs(decoded(tmp_path / "m.mp4") * 255 - scaled).mean() < 2.0  # H.264, 8 bits


def test_memory_is_bounded(tmp_path):
    """A 64x64 video of 300 frames (4.7 MiB as float32): analysed from its file in a 2 MiB allowance,
    NumPy's allocations peak far below the video's size (the whole-video pipeline took ~35 bytes a
    pixel-frame, 9 times the video)."""
    rng = np.random.default_rng(1)
    c = cardiac_signal(300, FPS, bpm=80.0, seed=1).volume
    frames = (0.4 + 0.01 * rng.standard_normal((300, 64, 64))).astype(np.float32)
    frames[:, 16:48, 16:48] -= (0.01 * c[:, None, None]).astype(np.float32)
    write_video(tmp_path / "v.tif", Video(frames, FPS, "test"))
    video_bytes = frames.nbytes
    del frames
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    video = open_video(tmp_path / "v.tif")
    analyze_pulse(Video(pulse_frames(n=64, shape=(16, 16)), FPS, "warm-up"))  # what it imports, before the count
    tracemalloc.start()
    try:
        res = analyze_pulse(video, memory_bytes=2**21, scratch_dir=scratch)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < video_bytes / 4, f"peak {peak / 2**20:.1f} MiB for a {video_bytes / 2**20:.0f} MiB video"
    assert res.estimate.rate_bpm == pytest.approx(80.0, abs=1.0)
    assert res.scratch_disk_bytes >= video_bytes
    assert list(scratch.iterdir()) == []


def test_a_video_is_opened_from_its_header_alone(tmp_path, monkeypatch):
    """open_video reads no frame: the count, size and rate are known (and the options checked) before any
    decoding; a stack ImageJ writes contiguously in one page is read frame by frame too."""
    import tifffile

    frames = pulse_frames(n=40, shape=(12, 10))
    write_video(tmp_path / "v.tif", Video(frames, FPS, "test"))
    tifffile.imwrite(tmp_path / "one_page.tif", frames, imagej=True, truncate=True, metadata={"finterval": 0.05})
    real = tifffile.TiffPage.asarray

    def refused(*a, **k):
        raise AssertionError("a frame was decoded")

    monkeypatch.setattr(tifffile.TiffPage, "asarray", refused)
    v = open_video(tmp_path / "v.tif")
    assert (v.n_frames, v.shape, v.fps) == (40, (12, 10), pytest.approx(FPS))
    one = open_video(tmp_path / "one_page.tif")
    assert (one.n_frames, one.shape, one.fps) == (40, (12, 10), pytest.approx(20.0))
    np.testing.assert_array_equal(one.read().frames, frames)  # by offset, no page decoded
    monkeypatch.setattr(tifffile.TiffPage, "asarray", real)
    np.testing.assert_array_equal(np.stack(list(v.iter_frames())), frames)
    np.testing.assert_array_equal(np.stack(list(v.iter_frames())), frames)  # every pass anew


def test_the_white_level_is_numpy_s_percentile_from_the_largest_values():
    from planeray.pulse.video_io import FramePercentile

    rng = np.random.default_rng(2)
    for frames in (
        rng.random((300, 20, 30)).astype(np.float32),
        np.round(rng.random((50, 9, 7)) * 6).astype(np.float32),
    ):
        for q in (99.9, 99.0, 50.0, 100.0):
            p = FramePercentile(q, frames.size)
            for f in frames:
                p.add(f)
            assert p.value() == np.percentile(frames, q)
            assert p._held <= 2 * p._keep + 4096 + frames[0].size  # only the largest values are kept


def test_what_the_disk_cannot_hold_is_refused_before_any_work(videos, tmp_path, monkeypatch):
    """The region search's magnified video goes beside --out: where the disk has no room for it, one line
    with the estimate and what to do, before a frame is decoded; with --region nothing goes to disk."""
    import shutil

    import planeray.experiments.pulse as ep
    import planeray.pulse.analysis as pa

    monkeypatch.setattr(pa, "DEFAULT_MEMORY_BYTES", SMALL)
    monkeypatch.setattr(shutil, "disk_usage", lambda p: shutil._ntuple_diskusage(10**9, 10**9 - 1000, 1000))

    def work(*a, **k):
        raise AssertionError("the work started")

    monkeypatch.setattr(ep, "analyze_pulse", work)
    need = scratch_bytes(300, (32, 40), memory_bytes=SMALL)["disk"]
    assert need >= 300 * 32 * 40 * 4
    res = runner.invoke(app, ["skin", "pulse", str(videos["tif"]), "--out", str(tmp_path / "r")])
    line = one_line_error(res)
    from planeray._validate import bytes_text

    assert f"300 frames of 32x40 need about {bytes_text(need)} of temporary disk space" in " ".join(line.split())
    assert "--region" in line and "1000 bytes free" in line
    assert not (tmp_path / "r").exists() and list(tmp_path.iterdir()) == []
    assert scratch_bytes(300, (32, 40), memory_bytes=SMALL, search=False)["disk"] == 0


@pytest.mark.usefixtures("figures_not_drawn")
@pytest.mark.parametrize("fault", ["interrupted", "disk full"])
def test_an_interrupted_or_failing_analysis_leaves_nothing(fault, videos, tmp_path, monkeypatch):
    """Killed (Ctrl-C) or out of disk while the magnified video is being kept on disk: no result folder, no
    magnified video, no temporaries, no scratch files; a full disk is one line naming the output."""
    import planeray.pulse.analysis as pa
    from planeray.pulse._workspace import DiskArray

    monkeypatch.setattr(pa, "DEFAULT_MEMORY_BYTES", SMALL)
    real, calls, folders = DiskArray._write, [], []

    def failing(self, index, row):
        calls.append(self.path)
        if len(calls) == 100:
            folders.append(self.path.parent.parent)
            if fault == "interrupted":
                raise KeyboardInterrupt
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.path))
        return real(self, index, row)

    monkeypatch.setattr(DiskArray, "_write", failing)
    out, mag = tmp_path / "out" / "r", tmp_path / "out" / "m.tif"
    out.parent.mkdir()
    res = runner.invoke(app, ["skin", "pulse", str(videos["tif"]), "--out", str(out), "--magnified", str(mag)])
    assert len(calls) >= 100 and folders[0].name == ".scratch"  # in the result's own temporary
    if fault == "interrupted":
        assert isinstance(res.exception, KeyboardInterrupt) or res.exit_code == 130
    else:
        line = one_line_error(res, out, "No space left on device", "[ENOSPC]")
        assert ".scratch" not in line and ".raw" not in line  # no internal file named
    assert list((tmp_path / "out").iterdir()) == []
    # the Python API: its scratch folder goes too
    scratch = tmp_path / "api"
    scratch.mkdir()
    calls.clear()
    with pytest.raises(KeyboardInterrupt if fault == "interrupted" else OSError):
        analyze_pulse(open_video(videos["tif"]), memory_bytes=SMALL, scratch_dir=scratch)
    assert list(scratch.iterdir()) == []


def test_frames_too_large_for_the_memory_are_refused_before_any_work(videos, tmp_path, monkeypatch):
    """What cannot be bounded -- the few frames the analysis works on at once, and its allowance -- is checked
    against the memory available: refused in one line with the estimate, before a frame is decoded."""
    import planeray._validate as pv
    import planeray.experiments.pulse as ep
    from planeray._validate import bytes_text
    from planeray.cli._bounds import BASE_BYTES

    need = BASE_BYTES + scratch_bytes(300, (32, 40))["memory"]  # the interpreter, the video's arrays, 12 frames
    assert need < BASE_BYTES + 300 * 32 * 40 * (4 + 4 + 16)  # a short video needs no more than it holds
    monkeypatch.setattr(pv, "available_memory_bytes", lambda: need - 1)

    def work(*a, **k):
        raise AssertionError("the work started")

    monkeypatch.setattr(ep, "analyze_pulse", work)
    line = one_line_error(runner.invoke(app, ["skin", "pulse", str(videos["tif"]), "--out", str(tmp_path / "r")]))
    assert f"magnifying frames of 32x40 needs about {bytes_text(need)} of memory" in line
    assert list(tmp_path.iterdir()) == []
