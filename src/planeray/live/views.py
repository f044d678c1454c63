"""What a live device is shown as: the band image, the vein view, Eq. 7's composite, the pulse.

Each view turns captured frames (:class:`~planeray.live.capture.Frame`) into one image, with the
same functions the offline commands use, so that what the explorer shows live is what
``planeray skin`` computes from a stack or a video:

* ``band``: the frame itself (the delay image of its timing);
* ``vein``: the short-range vein view, the delay image with its contrast stretched
  (:func:`planeray.skin.imaging.contrast_stretch`, the vein viewer's percentile scaling and CLAHE);
* ``composite``: Eq. 7 over a cycle of delays (:func:`planeray.skin.enhance.enhance_contrast`);
* ``pulse``: the frame, and the heart rate and spectrum of a rolling window of frames, computed as
  ``planeray skin pulse`` computes them (:func:`planeray.pulse.analysis.analyze_pulse`: Eulerian
  magnification, the region found automatically, the periodogram) by :class:`PulseMonitor`.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from ..errors import InputError

__all__ = [
    "VIEWS",
    "DEFAULT_CYCLE_DELAYS_US",
    "PULSE_WINDOW_S",
    "cycle_delays",
    "vein_view",
    "composite_view",
    "PulseMonitor",
]

#: The live views: name -> label.
VIEWS = {
    "band": "band image (delay, exposure)",
    "vein": "vein view (contrast-stretched delay image)",
    "composite": "Eq. 7 composite (cycling delays)",
    "pulse": "pulse (rolling window)",
}
#: Eq. 7's delays when none are given: the paper's delay grid (187.5 us) off the epipolar band, 375-1125 us.
DEFAULT_CYCLE_DELAYS_US = (375.0, 562.5, 750.0, 937.5, 1125.0)
#: The pulse's rolling window: 10 s (the rate band's slowest 0.7 Hz needs 2.9 s; a rate to 2 bpm ~10 s).
PULSE_WINDOW_S = 10.0


def cycle_delays(exposure_us: float, delays_us=DEFAULT_CYCLE_DELAYS_US) -> tuple[float, ...]:
    """The delays of Eq. 7's cycle at ``exposure_us``: those whose band is off the epipolar plane
    (``|t_d| > t_e/2``) and whose edge is not on it (the boundary images a stack leaves out, Sec. 4).

    Parameters
    ----------
    exposure_us : float
        The cycle's exposure, microseconds.
    delays_us : tuple of float
        The candidate delays, microseconds.

    Returns
    -------
    tuple of float

    See Also
    --------
    composite_view : the composite of a cycle.

    Examples
    --------
    >>> cycle_delays(600.0)
    (562.5, 750.0, 937.5, 1125.0)
    >>> cycle_delays(1200.0)
    (750.0, 937.5, 1125.0)
    """
    from ..timing import boundary_images

    d = np.asarray(delays_us, np.float64)
    edge = boundary_images(d, np.full_like(d, float(exposure_us)))
    keep = tuple(float(x) for x, b in zip(d, edge) if abs(x) > 0.5 * float(exposure_us) and not b)
    if len(keep) < 2:
        raise InputError(
            f"exposure_us = {exposure_us:g}: Eq. 7's composite needs at least 2 delays off the epipolar band "
            f"(|t_d| > t_e / 2, its edge not on it) among {', '.join(f'{d:g}' for d in delays_us)} us"
        )
    return keep


def vein_view(image) -> np.ndarray:
    """The vein view of a delay image: its contrast stretched (percentiles, then CLAHE), in [0, 1], float32.

    Parameters
    ----------
    image : array_like (H, W)
        A delay image.

    Returns
    -------
    ndarray (H, W) float32

    See Also
    --------
    composite_view : Eq. 7's composite.

    Examples
    --------
    >>> import numpy as np
    >>> view = vein_view(np.linspace(0.1, 0.3, 256).reshape(16, 16))
    >>> view.dtype.name, float(view.min()) >= 0.0, float(view.max()) <= 1.0
    ('float32', True, True)
    """
    from ..skin.imaging import contrast_stretch

    return contrast_stretch(np.asarray(image, np.float64)).astype(np.float32)


def composite_view(frames) -> tuple[np.ndarray, dict]:
    """Eq. 7's composite of a cycle of frames (one per delay, one exposure) and what it used.

    Returns the composite (float32, ~1 on skin: the locally normalized delay images) and
    ``{"delays_us": [...], "delay_map_us": [min, max]}``.

    Parameters
    ----------
    frames : sequence of Frame
        One frame per delay of :func:`cycle_delays`, one exposure.

    Returns
    -------
    image : ndarray (H, W) float32
    info : dict
        ``delays_us`` used and the ``delay_map_us`` range.

    See Also
    --------
    planeray.skin.enhance_contrast : Eq. 7.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Eq. 7, Sec. 10.

    Examples
    --------
    >>> import numpy as np
    >>> from planeray.live import Frame
    >>> frames = [
    ...     Frame(i, np.full((16, 16), 0.2 + 0.1 * i, np.float32), np.zeros((16, 16), bool), d, 600.0, i, i, 0)
    ...     for i, d in enumerate(cycle_delays(600.0))
    ... ]
    >>> image, used = composite_view(frames)
    >>> image.shape, used["delays_us"] == list(cycle_delays(600.0))
    ((16, 16), True)
    """
    from ..skin.enhance import enhance_contrast

    delays = [f.delay_us for f in frames]
    result = enhance_contrast(np.stack([f.image for f in frames]), delays)
    used = result.delays_us.tolist()
    return np.asarray(result.image, np.float32), {
        "delays_us": used,
        "delay_map_us": [float(result.delay_map_us.min()), float(result.delay_map_us.max())],
    }


class PulseMonitor:
    """The heart rate of a rolling window of frames, recomputed in the background as frames come.

    Parameters
    ----------
    window_s : float
        The window (device seconds).
    update_s : float
        Recompute at most this often (host seconds).
    min_window_s : float
        The shortest window analysed (two periods of the rate band's slowest 0.7 Hz).
    spectrum_points : int
        Samples of the spectrum kept for display (the rate band and up to 3.3 Hz).

    See Also
    --------
    planeray.pulse.analysis.analyze_pulse : the analysis.

    References
    ----------
    .. [1] H.-Y. Wu, M. Rubinstein, E. Shih, J. Guttag, F. Durand, W. T. Freeman, "Eulerian Video
       Magnification for Revealing Subtle Changes in the World", ACM SIGGRAPH 2012.

    Examples
    --------
    Ten seconds of a skin patch whose brightness pulses at 72 beats a minute:

    >>> import numpy as np
    >>> from planeray.live import Frame
    >>> rng = np.random.default_rng(0)
    >>> frames = []
    >>> for i in range(300):
    ...     t = i / 30
    ...     image = (0.5 + 0.005 * np.sin(2 * np.pi * 1.2 * t) + 0.001 * rng.standard_normal((16, 16))).astype(
    ...         np.float32
    ...     )
    ...     frames.append(Frame(i, image, np.zeros((16, 16), bool), 500.0, 600.0, t, t, 0))
    >>> result = PulseMonitor().analyze(frames)
    >>> round(result["rate_bpm"]), result["detected"]
    (72, True)
    """

    def __init__(
        self, *, window_s: float = PULSE_WINDOW_S, update_s: float = 1.0, min_window_s: float = 3.0, spectrum_points=200
    ):
        self.window_s = float(window_s)
        self.update_s = float(update_s)
        self.min_window_s = float(min_window_s)
        self.spectrum_points = int(spectrum_points)
        self._lock = threading.Lock()
        self._busy = False
        self._last_run = -np.inf
        self._key = None
        self.result: dict | None = None

    def analyze(self, frames) -> dict | None:
        """Analyse ``frames`` now (consecutive frames at one timing); None when they span too little time."""
        from ..pulse.analysis import analyze_pulse
        from ..pulse.video_io import Video

        if len(frames) < 8:
            return None
        times = np.array([f.time_s for f in frames])
        span = float(times[-1] - times[0])
        if span < self.min_window_s:
            return None
        fps = (len(frames) - 1) / span
        video = Video(np.stack([f.image for f in frames]), fps, "live", {})
        res = analyze_pulse(video)
        est = res.estimate
        freqs, power = est.freqs_hz, est.power
        band = (freqs >= 0.5) & (freqs <= 3.3)
        step = max(1, int(np.ceil(band.sum() / self.spectrum_points)))
        f_show, p_show = freqs[band][::step], power[band][::step]
        rows, cols = np.nonzero(res.region)
        return {
            "rate_bpm": est.rate_bpm,
            "peak_bpm": est.peak_bpm,
            "snr_db": float(est.snr_db),
            "band_snr_db": float(est.band_snr_db),
            "detected": est.detected,
            "window_s": span,
            "frames": len(frames),
            "fps": fps,
            "spectrum": {
                "bpm": (60.0 * f_show).tolist(),
                "power": (p_show / max(float(p_show.max()), 1e-300)).tolist(),
            },
            "signal": {"t_s": (times - times[-1]).tolist(), "value": res.signal.tolist()},
            "region": [int(rows.min()), int(cols.min()), int(rows.max()) + 1, int(cols.max()) + 1],
            "timing": [frames[-1].delay_us, frames[-1].exposure_us],
            "last_frame": frames[-1].index,
        }

    def update(self, frames, executor=None) -> dict | None:
        """The latest result; starts a new analysis of ``frames`` (in ``executor``, else here) when one is due.

        A new timing (the frames' delay and exposure) drops the old result.
        """
        if frames:
            key = (frames[-1].delay_us, frames[-1].exposure_us)
            if key != self._key:
                with self._lock:
                    self._key, self.result, self._last_run = key, None, -np.inf
        now = time.monotonic()
        with self._lock:
            due = not self._busy and now - self._last_run >= self.update_s and len(frames) >= 8
            if due:
                self._busy, self._last_run = True, now
        if due:
            frames = list(frames)

            def run():
                try:
                    result = self.analyze(frames)
                    with self._lock:
                        if result is not None and self._key == tuple(result["timing"]):
                            self.result = result
                finally:
                    with self._lock:
                        self._busy = False

            if executor is None:
                run()
            else:
                executor.submit(run)
        return self.result
