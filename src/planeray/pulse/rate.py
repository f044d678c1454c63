"""Heart rate and pulse signal-to-noise ratio from a video's signal (Sec. 10, Fig. 15a).

**Spectrum.**  The signal of a pixel or region (its mean per frame) is detrended, windowed
(Hann) and its power spectrum taken with SciPy -- one periodogram of the whole window
(``method="periodogram"``, the default) or Welch's average of overlapping segments
(``method="welch"``, for long or non-stationary records) -- zero-padded to ``pad`` times its length.

**Resolution.**  ``N`` samples at ``fps`` span ``N / fps`` seconds; their DFT has bins ``fps / N``
apart, so 480 frames at 30 fps (16 s) give bins of 1/16 Hz = **3.75 bpm**, and the largest bin of
a plain periodogram is off by up to half that (1.9 bpm).  Zero-padding does not add information
but samples the same (window-smoothed) spectrum more densely, and fitting a parabola to the
logarithm of the three highest samples (exact for a Gaussian-shaped main lobe) finds the peak
between them: for one dominant sinusoid in noise the error then falls far below a bin (see the
README's Pulse section for measured errors).  Only a longer window separates two rates closer
than a bin (the Rayleigh limit ``1 / T``).

**SNR** (de Haan and Jeanne 2013, Eq. 21; the rPPG toolboxes' definition): the power within
``+-half_width_bpm`` of the rate ``f0`` and of its first harmonic ``2 f0``, against the power at
every other frequency of ``snr_band_hz``, in dB (default 0.6-3.3 Hz and 6 bpm, as the rPPG-Toolbox,
Liu et al. 2023, computes it; de Haan and Jeanne summed over 30-240 bpm).  The
template is centred on the detected rate, or on a known one (``reference_bpm``).

**No pulse.**  The SNR above counts breathing (0.25 Hz and its harmonics) and the pulse's own
higher harmonics as noise, so a clear pulse in a moving arm can score below 0 dB; whether a pulse
is there at all is decided on the rate band alone: the **peak SNR** ``band_snr_db`` is the power
within ``+-half_width_bpm`` of the peak (and of ``2 f0`` when it lies in the band) against the
rest of ``band_hz``.  A rate is reported only when it reaches ``min_band_snr_db``; otherwise
:attr:`PulseEstimate.rate_bpm` is None.  The default threshold is set above the highest peak SNR
of simulated pulse-free videos (noise, breathing, motion; README, Pulse: the measured
distributions and the false-alarm rate).

References
----------
.. [1] de Haan and Jeanne, "Robust pulse rate from chrominance-based rPPG", IEEE TBME 60,
   2878 (2013), Eq. 21 (SNR).
.. [4] Liu et al., "rPPG-Toolbox: Deep remote PPG toolbox", NeurIPS Datasets and Benchmarks
   (2023) -- ``calculate_SNR``: +-6 bpm around f0 and 2 f0, 0.6-3.3 Hz.
.. [2] Welch, "The use of fast Fourier transform for the estimation of power spectra", IEEE
   Trans. Audio Electroacoust. 15, 70 (1967).
.. [3] Smith, "Spectral Audio Signal Processing", W3K 2011, "Quadratic interpolation of spectral
   peaks" (parabolic interpolation of the log-magnitude spectrum).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validate import check_integer, check_positive
from ..errors import InputError
from .evm import check_band

__all__ = [
    "RATE_BAND_HZ",
    "SNR_BAND_HZ",
    "MIN_BAND_SNR_DB",
    "PulseEstimate",
    "pulse_spectrum",
    "interpolate_peak",
    "pulse_snr_db",
    "estimate_heart_rate",
    "region_signal",
    "parse_region",
    "find_pulse_region",
]

#: Where a heart rate is searched: 42-120 bpm (the paper's magnification band tops at 2 Hz).
RATE_BAND_HZ = (0.7, 2.0)
#: Band of the SNR: 36-198 bpm, the rPPG-Toolbox's (de Haan and Jeanne 2013 used 30-240 bpm; 0.5 Hz
#: would count the second harmonic of 15 breaths per minute).
SNR_BAND_HZ = (0.6, 3.3)
#: Below this peak SNR (rate band only) no rate is reported (see the module docstring).
MIN_BAND_SNR_DB = 3.0


@dataclass
class PulseEstimate:
    """A heart-rate estimate.

    Attributes
    ----------
    rate_bpm : float or None
        The rate, or None when no pulse stands out (``band_snr_db < min_band_snr_db``).
    peak_bpm : float
        The spectral peak in the rate band, reported or not.
    snr_db : float
        Pulse SNR (de Haan and Jeanne) at ``peak_bpm`` (or at ``reference_bpm`` when one was given).
    band_snr_db : float
        Peak SNR within the rate band: what decides whether a pulse is reported.
    freqs_hz, power : ndarray
        The spectrum the estimate was read from (for plots).
    bin_bpm : float
        DFT bin spacing of the analysis window without zero-padding, ``60 fps / N``.
    """

    rate_bpm: float | None
    peak_bpm: float
    snr_db: float
    band_snr_db: float
    freqs_hz: np.ndarray
    power: np.ndarray
    bin_bpm: float
    settings: dict = field(default_factory=dict)

    @property
    def detected(self) -> bool:
        return self.rate_bpm is not None

    def to_dict(self) -> dict:
        return {
            "rate_bpm": self.rate_bpm,
            "detected": self.detected,
            "peak_bpm": self.peak_bpm,
            "snr_db": self.snr_db,
            "band_snr_db": self.band_snr_db,
            "bin_bpm": self.bin_bpm,
            **self.settings,
        }


def pulse_spectrum(
    signal, fps: float, *, method: str = "periodogram", pad: int = 8, segment_s: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """One-sided power spectrum of a detrended, Hann-windowed signal, zero-padded ``pad`` times.

    ``method="welch"`` averages segments of ``segment_s`` seconds (default: half the record) overlapping by half.

    Parameters
    ----------
    signal : array_like (T,) or (..., T)
        One signal, or many of the same length along the last axis (one call for all: each row's
        spectrum is the one it would have alone).
    fps : float
        Samples per second (Hz).
    method : {"periodogram", "welch"}
    pad : int
        Zero-padding factor (1: none).
    segment_s : float, optional
        Welch segment length, seconds.

    Returns
    -------
    freqs_hz : ndarray (F,)
    power : ndarray (F,) or (..., F)
        Power spectral density (signal units squared per Hz).
    """
    from scipy import signal as sps

    x = np.asarray(signal, np.float64)
    if x.ndim < 1 or x.shape[-1] < 4 or x.size == 0:
        raise InputError(f"a pulse signal needs at least 4 samples, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise InputError("the pulse signal contains NaN or infinite values")
    fps = check_positive(fps, "fps")
    pad = check_integer(pad, "pad", minimum=1)
    n = x.shape[-1]
    if method == "periodogram":
        return sps.periodogram(x, fps, window="hann", nfft=pad * n, detrend="linear", axis=-1)
    if method == "welch":
        nper = n // 2 if segment_s is None else int(round(check_positive(segment_s, "segment_s") * fps))
        nper = int(min(max(nper, 4), n))
        return sps.welch(
            x, fps, window="hann", nperseg=nper, noverlap=nper // 2, nfft=pad * nper, detrend="linear", axis=-1
        )
    raise InputError(f"method must be periodogram or welch, got {method!r}")


def interpolate_peak(freqs, power, index: int) -> float:
    """Frequency of the peak at ``index`` refined by a parabola through the log power of it and its neighbours."""
    if index <= 0 or index >= len(power) - 1:
        return float(freqs[index])
    a, b, c = np.log(np.maximum(power[index - 1 : index + 2], 1e-300))
    denom = a - 2 * b + c
    shift = 0.0 if denom >= 0 else 0.5 * (a - c) / denom
    return float(freqs[index] + np.clip(shift, -0.5, 0.5) * (freqs[1] - freqs[0]))


def pulse_snr_db(freqs, power, f0_hz: float, *, band_hz=SNR_BAND_HZ, half_width_bpm: float = 6.0) -> float:
    """de Haan and Jeanne's SNR: power near ``f0`` and ``2 f0`` against the rest of ``band_hz``, in dB."""
    freqs = np.asarray(freqs)
    power = np.asarray(power)
    inband = (freqs >= band_hz[0]) & (freqs <= band_hz[1])
    hw = half_width_bpm / 60.0
    near = (np.abs(freqs - f0_hz) <= hw) | (np.abs(freqs - 2 * f0_hz) <= hw)
    sig = power[inband & near].sum()
    noise = power[inband & ~near].sum()
    if sig <= 0:
        return -np.inf
    if noise <= 0:
        return np.inf
    return float(10 * np.log10(sig / noise))


def estimate_heart_rate(
    signal,
    fps: float,
    *,
    band_hz=RATE_BAND_HZ,
    snr_band_hz=SNR_BAND_HZ,
    method: str = "periodogram",
    pad: int = 8,
    segment_s: float | None = None,
    interpolate: bool = True,
    half_width_bpm: float = 6.0,
    min_band_snr_db: float = MIN_BAND_SNR_DB,
    reference_bpm: float | None = None,
    spectrum: tuple[np.ndarray, np.ndarray] | None = None,
) -> PulseEstimate:
    """Heart rate of a pulse signal: the spectral peak in ``band_hz``, and its SNR.

    Parameters
    ----------
    signal : array_like (T,)
        A pixel's or region's value per frame (magnified or not).
    fps : float
    band_hz : (float, float)
        Where the rate is searched (default 0.7-2 Hz, 42-120 bpm).
    snr_band_hz : (float, float)
        Band of the SNR (default 0.6-3.3 Hz).
    method : {"periodogram", "welch"}
    pad : int
        Zero-padding factor (1: none).
    segment_s : float, optional
        Welch segment length.
    interpolate : bool
        Refine the peak between spectrum samples (parabola on log power).
    half_width_bpm : float
        Half-width of the SNR template around ``f0`` and ``2 f0``.
    min_band_snr_db : float
        Report no rate below this peak SNR of the rate band.
    reference_bpm : float, optional
        A known rate: the SNR template is centred on it (the toolboxes' SNR against ground truth).
    spectrum : (ndarray, ndarray), optional
        ``(freqs, power)`` of this signal from :func:`pulse_spectrum` with the same ``method``,
        ``pad`` and ``segment_s``, computed once for several estimates (e.g. with and without
        ``interpolate``); default: computed here.

    Examples
    --------
    >>> t = np.arange(600) / 30.0
    >>> rng = np.random.default_rng(0)
    >>> est = estimate_heart_rate(np.sin(2 * np.pi * 72 / 60 * t) + 0.3 * rng.standard_normal(600), 30.0)
    >>> round(est.rate_bpm, 1), est.snr_db > 0
    (72.0, True)
    """
    fps = check_positive(fps, "fps")
    lo, hi = check_band(band_hz, fps, "rate band")
    snr_band = check_band(snr_band_hz, fps, "SNR band", clip=True)
    if spectrum is None:
        spectrum = pulse_spectrum(signal, fps, method=method, pad=pad, segment_s=segment_s)
    freqs, power = spectrum
    sel = np.flatnonzero((freqs >= lo) & (freqs <= hi))
    if sel.size == 0:
        raise InputError(f"no spectrum sample in the rate band {lo:g}-{hi:g} Hz")
    i = int(sel[np.argmax(power[sel])])
    f_peak = interpolate_peak(freqs, power, i) if interpolate else float(freqs[i])
    f_ref = f_peak if reference_bpm is None else float(reference_bpm) / 60.0
    snr = pulse_snr_db(freqs, power, f_ref, band_hz=snr_band, half_width_bpm=half_width_bpm)
    band_snr = pulse_snr_db(freqs, power, f_peak, band_hz=(lo, hi), half_width_bpm=half_width_bpm)
    n = np.asarray(signal).size
    bin_bpm = 60.0 * fps / (n if method == "periodogram" else _welch_len(n, fps, segment_s))
    detected = band_snr >= min_band_snr_db
    settings = {
        "band_hz": [lo, hi],
        "snr_band_hz": list(snr_band),
        "method": method,
        "pad": pad,
        "interpolate": bool(interpolate),
        "min_band_snr_db": float(min_band_snr_db),
        "window_s": n / fps,
    }
    rate = 60.0 * f_peak if detected else None
    return PulseEstimate(rate, 60.0 * f_peak, snr, band_snr, freqs, power, bin_bpm, settings)


def _welch_len(n, fps, segment_s):
    nper = n // 2 if segment_s is None else int(round(segment_s * fps))
    return int(min(max(nper, 4), n))


def parse_region(text: str, shape) -> tuple[int, int, int, int]:
    """``"ROW,COL"`` (one pixel) or ``"R0,C0,R1,C1"`` (rows R0..R1-1, columns C0..C1-1) -> ``(r0, c0, r1, c1)``."""
    parts = str(text).replace(",", " ").split()
    try:
        vals = [int(p) for p in parts]
    except ValueError:
        raise InputError(f"--region expects ROW,COL or R0,C0,R1,C1 (integers), got {text!r}") from None
    if len(vals) == 2:
        vals = [vals[0], vals[1], vals[0] + 1, vals[1] + 1]
    if len(vals) != 4:
        raise InputError(f"--region expects ROW,COL or R0,C0,R1,C1, got {text!r}")
    r0, c0, r1, c1 = vals
    H, W = shape
    if not (0 <= r0 < r1 <= H and 0 <= c0 < c1 <= W):
        raise InputError(f"--region {text!r} is not inside the {H}x{W} frames")
    return r0, c0, r1, c1


def region_signal(frames, region=None) -> np.ndarray:
    """Mean of each frame over ``region``: None (whole frame), ``(r0, c0, r1, c1)`` or a boolean mask (H, W)."""
    frames = np.asarray(frames)
    if region is None:
        return frames.reshape(frames.shape[0], -1).mean(axis=1, dtype=np.float64)
    if isinstance(region, np.ndarray) and region.dtype == bool:
        if region.shape != frames.shape[1:] or not region.any():
            raise InputError(f"region mask must be a non-empty {frames.shape[1:]} boolean image")
        return frames[:, region].mean(axis=1, dtype=np.float64)
    r0, c0, r1, c1 = region
    return frames[:, r0:r1, c0:c1].reshape(frames.shape[0], -1).mean(axis=1, dtype=np.float64)


def find_pulse_region(
    frames,
    fps: float,
    *,
    mask=None,
    band_hz=RATE_BAND_HZ,
    fraction: float = 0.05,
    min_pixels: int = 4,
    workspace=None,
) -> np.ndarray:
    """Pixels where the pulse is strongest: a boolean mask (H, W).

    Every pixel's spectrum (one FFT along time of its mean-free, Hann-windowed series) is normalized
    to unit power in ``band_hz`` and summed into a common spectrum, whose peak is the candidate rate
    bin ``k0``; the pixels with the most of their band power within one bin of ``k0`` -- the top
    ``fraction`` of ``mask`` (all pixels by default; e.g. a vein mask), at least ``min_pixels`` --
    form the region.

    Parameters
    ----------
    frames : array_like (T, H, W)
        The video (magnified or not); an array, or a :class:`planeray.pulse._workspace.DiskArray`.
    fps : float
        Frame rate (Hz).
    mask : ndarray (H, W) bool, optional
        Where to search.
    band_hz : (float, float)
        Band of the rate (Hz).
    fraction : float
        Share of the searched pixels kept.
    min_pixels : int
        Fewest pixels kept.
    workspace : planeray.pulse._workspace.Workspace, optional
        Bounds the memory: the spectra are taken in tiles of pixels of at most its ``tile_bytes``, and
        each pixel's normalized band spectrum (``4 K`` bytes, ``K`` the band's FFT bins) is kept in
        one of its arrays.  Default: the whole video at once, in memory.
    """
    T, H, W = frames.shape
    lo, hi = check_band(band_hz, fps, "rate band")
    sel = np.ones((H, W), bool) if mask is None else np.asarray(mask, bool)
    if sel.shape != (H, W) or not sel.any():
        raise InputError(f"the search mask must be a non-empty {H}x{W} boolean image")
    import scipy.fft

    from ._workspace import pixel_tiles

    f = np.fft.rfftfreq(T, 1.0 / fps)
    inband = (f >= lo) & (f <= hi)
    K = int(inband.sum())
    window = np.hanning(T)[:, None].astype(np.float32)
    n_sel = int(sel.sum())
    tile_bytes = None if workspace is None else workspace.tile_bytes
    norm = np.empty((n_sel, K), np.float32) if workspace is None else workspace.array((n_sel, K), name="spectra")
    common = np.zeros(K, np.float64)
    p = 0
    for r0, r1, c0, c1 in pixel_tiles((H, W), _REGION_BYTES * T, tile_bytes):
        inside = sel[r0:r1, c0:c1]
        if not inside.any():
            continue
        x = np.asarray(frames[:, r0:r1, c0:c1], np.float32)
        x = x.reshape(T, -1) if inside.all() else x[:, inside]
        x -= x.mean(axis=0)
        x *= window
        power = np.abs(scipy.fft.rfft(x, axis=0)[inband])
        del x
        power **= 2
        power /= np.maximum(power.sum(axis=0, keepdims=True), 1e-30)
        common += power.sum(axis=1, dtype=np.float64)
        norm[p : p + power.shape[1]] = power.T
        p += power.shape[1]
    k0 = int(np.argmax(common))
    near = np.flatnonzero(np.abs(np.arange(K) - k0) <= 1)
    score = np.empty(n_sel, np.float32)
    step = max(int(tile_bytes // (4 * K)), 1) if tile_bytes else n_sel
    for a in range(0, n_sel, step):
        block = norm[a : a + step][:, near[0] : near[-1] + 1]  # whole rows read, then the bins near k0
        score[a : a + step] = block[:, 0]
        for j in range(1, block.shape[1]):
            score[a : a + step] += block[:, j]
    if workspace is not None:
        workspace.release(norm)
    n = max(int(min_pixels), int(np.ceil(fraction * score.size)))
    n = min(n, score.size)
    top = np.argsort(score)[::-1][:n]
    out = np.zeros((H, W), bool)
    idx = np.flatnonzero(sel.ravel())[top]
    out.ravel()[idx] = True
    return out


#: Working memory of :func:`find_pulse_region` per sample of a tile (the tile read, the searched
#: pixels' series, their spectrum), bytes.
_REGION_BYTES = 16
