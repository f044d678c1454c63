"""The pulse pipeline: video -> Eulerian magnification -> the signal of a region -> heart rate and SNR."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .evm import DEFAULT_ALPHA, DEFAULT_BAND_HZ, DEFAULT_LEVELS, magnify
from .rate import RATE_BAND_HZ, PulseEstimate, estimate_heart_rate, find_pulse_region, region_signal
from .video_io import Video

__all__ = ["PulseAnalysis", "analyze_pulse"]


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
    settings : dict
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
    video: Video,
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
    **rate_options,
) -> PulseAnalysis:
    """Magnify ``video`` and read the heart rate of a region.

    Parameters
    ----------
    video : Video
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
    **rate_options
        Passed to :func:`planeray.pulse.rate.estimate_heart_rate` (``method``, ``pad``, ``min_band_snr_db`` ...).
    """
    frames = video.frames
    mag = magnify(frames, video.fps, levels=levels, band_hz=band_hz, alpha=alpha, pyramid=pyramid, lambda_c=lambda_c)
    H, W = frames.shape[1:]
    if region is None:
        source = "auto" if mask is None else "mask"
        sel = find_pulse_region(mag, video.fps, mask=mask, band_hz=rate_band_hz, fraction=region_fraction)
    elif isinstance(region, np.ndarray):
        if region.shape != (H, W) or region.dtype != bool or not region.any():
            raise InputError(f"the region mask must be a non-empty {H}x{W} boolean image")
        sel, source = region, "argument"
    else:
        r0, c0, r1, c1 = region
        sel = np.zeros((H, W), bool)
        sel[r0:r1, c0:c1] = True
        source = "argument"
    signal = region_signal(mag, sel)
    raw = region_signal(frames, sel)
    kw = {"band_hz": rate_band_hz, "reference_bpm": reference_bpm, **rate_options}
    settings = {
        "levels": int(levels),
        "band_hz": [float(band_hz[0]), float(band_hz[1])],
        "alpha": float(alpha),
        "pyramid": pyramid,
        "lambda_c": lambda_c,
        "fps": float(video.fps),
        "frames": video.n_frames,
    }
    return PulseAnalysis(
        estimate_heart_rate(signal, video.fps, **kw),
        estimate_heart_rate(raw, video.fps, **kw),
        signal,
        raw,
        sel,
        source,
        np.arange(video.n_frames) / video.fps,
        settings,
        mag if keep_video else None,
    )
