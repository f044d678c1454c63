"""The pulse pipeline: video -> Eulerian magnification -> the signal of a region -> heart rate and SNR.

**Bounded memory.**  :func:`analyze_pulse` reads the video frame by frame -- a :class:`~planeray.pulse.video_io.Video`
in memory or a :class:`~planeray.pulse.video_io.VideoFile` decoded from disk, the same code -- in up to
three passes:

1. every frame is decomposed (:class:`~planeray.pulse.evm.Magnifier`: the Gaussian pyramid's coarsest level,
   or the Laplacian's amplified bands, kept over time), and the mean frame is summed; the kept levels are then
   band-passed in time;
2. only for the automatic region search: every magnified frame is kept (the search needs each pixel's whole
   time series), and the region is searched in tiles of pixels (:func:`~planeray.pulse.rate.find_pulse_region`);
3. every frame is magnified again, the region's mean taken with and without magnification, and the magnified
   frame handed to whoever writes the magnified video.

What is kept between passes lives in a :class:`~planeray.pulse._workspace.Workspace`: in memory up to its
allowance (``memory_bytes``), in files of its folder (``scratch_dir``) beyond it.  At the paper's 4 levels the
kept Gaussian level is 1/256 of the video; the magnified video of the region search (pass 2) and the Laplacian's
full-resolution band are the video's size (4 bytes a pixel-frame) and go to disk on long or large videos
(:func:`scratch_bytes` estimates them).  The results are those of the whole video in memory: each pixel's
time series is filtered and searched whole, the frames are magnified by the same operations in the same order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ._workspace import DEFAULT_MEMORY_BYTES, Workspace
from .evm import DEFAULT_ALPHA, DEFAULT_BAND_HZ, DEFAULT_LEVELS, Magnifier, level_alphas, pyramid_sizes
from .rate import RATE_BAND_HZ, PulseEstimate, estimate_heart_rate, find_pulse_region
from .video_io import check_frame_count

__all__ = ["PulseAnalysis", "analyze_pulse", "scratch_bytes"]


@dataclass
class PulseAnalysis:
    """What :func:`analyze_pulse` found.

    Attributes
    ----------
    estimate : PulseEstimate
        From the magnified signal.
    estimate_raw : PulseEstimate
        From the same region without magnification.
    signal, raw_signal : ndarray (T,)
        Region mean per frame, magnified and not.
    region : ndarray (H, W) bool
        The pixels averaged.
    region_source : str
        ``"argument"`` (a pixel or box the user gave), ``"mask"`` (searched inside a mask) or ``"auto"``.
    time_s : ndarray (T,)
        Time of each frame, seconds.
    settings : dict
    magnified : ndarray (T, H, W) or None
        The magnified frames, with ``keep_video`` only.
    mean_frame : ndarray (H, W) float32
        The mean of the frames (not magnified), as ``frames.mean(axis=0)``.
    scratch_disk_bytes : int
        The most bytes of temporary files the analysis held at once (0: it all fitted in memory).
    """

    estimate: PulseEstimate
    estimate_raw: PulseEstimate
    signal: np.ndarray
    raw_signal: np.ndarray
    region: np.ndarray
    region_source: str
    time_s: np.ndarray
    settings: dict = field(default_factory=dict)
    magnified: np.ndarray | None = None
    mean_frame: np.ndarray | None = None
    scratch_disk_bytes: int = 0

    def to_dict(self) -> dict:
        rows, cols = np.nonzero(self.region)
        return {
            "rate_bpm": self.estimate.rate_bpm,
            "detected": self.estimate.detected,
            "estimate": self.estimate.to_dict(),
            "without_magnification": self.estimate_raw.to_dict(),
            "region": {
                "source": self.region_source,
                "pixels": int(self.region.sum()),
                "bounding_box": [int(rows.min()), int(cols.min()), int(rows.max()) + 1, int(cols.max()) + 1],
            },
            "magnification": self.settings,
        }


def analyze_pulse(
    video,
    *,
    region=None,
    mask=None,
    levels: int = DEFAULT_LEVELS,
    band_hz=DEFAULT_BAND_HZ,
    alpha: float = DEFAULT_ALPHA,
    pyramid: str = "gaussian",
    lambda_c: float | None = None,
    rate_band_hz=RATE_BAND_HZ,
    region_fraction: float = 0.05,
    keep_video: bool = False,
    reference_bpm: float | None = None,
    memory_bytes: int | None = None,
    scratch_dir=None,
    observe=None,
    write_magnified=None,
    progress=None,
    **rate_options,
) -> PulseAnalysis:
    """Magnify ``video`` and read the heart rate of a region.

    Parameters
    ----------
    video : Video or VideoFile
        Frames in memory (:class:`~planeray.pulse.video_io.Video`) or read frame by frame from a file
        (:class:`~planeray.pulse.video_io.VideoFile`, :func:`~planeray.pulse.video_io.open_video`).
    region : (r0, c0, r1, c1) or ndarray (H, W) bool, optional
        Where to read the pulse (see :func:`planeray.pulse.rate.parse_region`); default: found
        automatically (:func:`planeray.pulse.rate.find_pulse_region`), inside ``mask`` if given.
    mask : ndarray (H, W) bool, optional
        Where the automatic search may look (e.g. a vein mask).
    levels, band_hz, alpha, pyramid, lambda_c
        Eulerian magnification (:func:`planeray.pulse.evm.magnify`; the paper's settings by default).
    rate_band_hz : (float, float)
        Where the rate is searched.
    region_fraction : float
        Share of the (masked) pixels the automatic search keeps.
    keep_video : bool
        Keep the magnified frames in the result (memory: the size of the video).
    reference_bpm : float, optional
        A known rate for the SNR template.
    memory_bytes : int, optional
        Working memory of the analysis beyond a few frames, bytes (default
        :data:`planeray.pulse._workspace.DEFAULT_MEMORY_BYTES`, 512 MiB): what is kept between passes and
        does not fit goes to temporary files in ``scratch_dir``.
    scratch_dir : str or os.PathLike, optional
        An existing folder for the temporary files (a subfolder, removed on every exit); default: the
        system's temporary folder.
    observe : callable, optional
        Called with every frame ``(H, W)`` float32 of the first pass (statistics a caller needs, e.g. the
        white level of an 8-bit video).
    write_magnified : callable, optional
        ``write_magnified(frames, n_frames, settings)``: given the magnified frames as an iterator in the last
        pass, to write them (it must consume them all).
    progress : callable, optional
        ``progress(stage, done, total)`` after each frame of each pass.
    **rate_options
        Passed to :func:`planeray.pulse.rate.estimate_heart_rate` (``method``, ``pad``, ``min_band_snr_db`` ...).
    """
    fps = float(video.fps)
    H, W = video.shape
    if region is None:
        source = "auto" if mask is None else "mask"
        if mask is not None:
            mask = np.asarray(mask, bool)
            if mask.shape != (H, W) or not mask.any():
                raise InputError(f"the search mask must be a non-empty {H}x{W} boolean image")
        sel = None
    elif isinstance(region, np.ndarray):
        if region.shape != (H, W) or region.dtype != bool or not region.any():
            raise InputError(f"the region mask must be a non-empty {H}x{W} boolean image")
        sel, source = region, "argument"
    else:
        r0, c0, r1, c1 = region
        sel = np.zeros((H, W), bool)
        sel[r0:r1, c0:c1] = True
        source = "argument"
    memory_bytes = DEFAULT_MEMORY_BYTES if memory_bytes is None else memory_bytes

    def tick(stage):
        if progress is None:
            return lambda done: None
        return lambda done: progress(stage, done, video.n_frames)

    with Workspace(scratch_dir, memory_bytes=memory_bytes) as ws:
        mag = Magnifier(
            (H, W),
            fps,
            n_frames=video.n_frames,
            levels=levels,
            band_hz=band_hz,
            alpha=alpha,
            pyramid=pyramid,
            lambda_c=lambda_c,
            workspace=ws,
        )
        # pass 1: the pyramid's kept levels, the mean frame
        total = np.zeros((H, W), np.float32)
        step = tick("decomposing")
        n = 0
        for frame in video.iter_frames():
            mag.add(frame)
            total += frame
            if observe is not None:
                observe(frame)
            n += 1
            step(n)
        check_frame_count(n, video.source)
        mean_frame = total / n
        del total
        mag.filter()
        if sel is None:  # pass 2: the magnified video, kept for the search
            kept = ws.frames(n, (H, W), name="magnified")
            step = tick("magnifying for the region search")
            for t, frame in enumerate(video.iter_frames()):
                kept.append(mag.magnified(t, frame))
                step(t + 1)
            sel = find_pulse_region(
                kept.data, fps, mask=mask, band_hz=rate_band_hz, fraction=region_fraction, workspace=ws
            )
            ws.release(kept)
            del kept
        settings = {
            "levels": int(levels),
            "band_hz": [float(band_hz[0]), float(band_hz[1])],
            "alpha": float(alpha),
            "pyramid": pyramid,
            "lambda_c": lambda_c,
            "fps": fps,
            "frames": n,
        }
        # pass 3: the region's signals, the magnified frames to whoever writes them
        signal = np.empty(n, np.float64)
        raw = np.empty(n, np.float64)
        inside = int(sel.sum())
        mean = np.add.reduce  # frame[sel].mean(dtype=np.float64), without its Python wrapper: the same sum
        frames_kept = np.empty((n, H, W), np.float32) if keep_video else None
        step = tick("magnifying")

        def magnified():
            for t, frame in enumerate(video.iter_frames()):
                out = mag.magnified(t, frame)
                signal[t] = mean(out[sel], dtype=np.float64) / inside
                raw[t] = mean(frame[sel], dtype=np.float64) / inside
                if frames_kept is not None:
                    frames_kept[t] = out
                yield out
                step(t + 1)

        frames = magnified()
        if write_magnified is not None:
            write_magnified(frames, n, settings)
        for _ in frames:  # whatever the writer left
            pass
        disk = ws.disk_bytes
    kw = {"band_hz": rate_band_hz, "reference_bpm": reference_bpm, **rate_options}
    return PulseAnalysis(
        estimate_heart_rate(signal, fps, **kw),
        estimate_heart_rate(raw, fps, **kw),
        signal,
        raw,
        sel,
        source,
        np.arange(n) / fps,
        settings,
        frames_kept,
        mean_frame,
        disk,
    )


def scratch_bytes(
    n_frames: int,
    shape,
    *,
    levels: int = DEFAULT_LEVELS,
    pyramid: str = "gaussian",
    lambda_c: float | None = None,
    alpha: float = DEFAULT_ALPHA,
    search: bool = True,
    fps: float = 30.0,
    rate_band_hz=RATE_BAND_HZ,
    memory_bytes: int | None = None,
) -> dict:
    """What :func:`analyze_pulse` keeps between its passes, how much of it goes to temporary files, and
    the memory it needs, bytes.

    Returns ``{"kept": ..., "disk": ..., "memory": ...}``: every array it keeps -- the amplified pyramid
    levels over time and, for the automatic region ``search``, the magnified video and each pixel's
    normalized band spectrum -- and the part of them that does not fit the half of ``memory_bytes``
    (default :data:`~planeray.pulse._workspace.DEFAULT_MEMORY_BYTES`) arrays may hold, placed in the order
    the analysis makes them (all are held at once at the search's end, so ``disk`` is the most disk it
    needs); and its memory beyond the interpreter: the arrays in memory, one tile of per-pixel work (at most
    the other half of ``memory_bytes``) and the dozen frames it works on at once (a decoded colour frame,
    its float copies, the pyramid, the magnified frame).
    """
    from .evm import _BANDPASS_BYTES
    from .rate import _REGION_BYTES

    memory_bytes = DEFAULT_MEMORY_BYTES if memory_bytes is None else int(memory_bytes)
    T = int(n_frames)
    shape = tuple(int(s) for s in shape)
    sizes = pyramid_sizes(shape, levels)
    if pyramid == "gaussian":
        kept_levels = [levels]
    else:
        kept_levels = [lv for lv, g in enumerate(level_alphas(shape, levels, alpha, lambda_c)) if g]
    arrays = [T * sizes[lv][0] * sizes[lv][1] * 4 for lv in kept_levels]
    tiles = [T * sizes[lv][0] * sizes[lv][1] * _BANDPASS_BYTES for lv in kept_levels]
    if search:
        f = np.fft.rfftfreq(T, 1.0 / fps)
        k = int(((f >= rate_band_hz[0]) & (f <= rate_band_hz[1])).sum())
        arrays += [T * shape[0] * shape[1] * 4, shape[0] * shape[1] * k * 4]
        tiles.append(T * shape[0] * shape[1] * _REGION_BYTES)
    left, disk = memory_bytes // 2, 0
    for nbytes in arrays:
        if nbytes <= left:
            left -= nbytes
        else:
            disk += nbytes
    tile = min(max(tiles, default=0), memory_bytes // 2)
    frames = 12 * 4 * shape[0] * shape[1]
    return {"kept": sum(arrays), "disk": disk, "memory": sum(arrays) - disk + tile + frames}
