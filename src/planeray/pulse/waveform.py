"""Physiological signals of a live skin capture: the cardiac blood-volume waveform, breathing, arm motion.

The **cardiac waveform** is the photoplethysmographic (PPG) blood-volume pulse: each beat a
fast systolic upstroke, a systolic peak, the **dicrotic notch** (aortic valve closure) and a
smaller diastolic (dicrotic) wave, modelled as the sum of Gaussians in beat phase of
Banerjee et al. / McSharry-style PPG models (systolic peak at 20 % of the beat, dicrotic
wave at 45 %; the notch is the trough between them, at ~33 %).  The beats follow an
instantaneous heart rate

``f(t) = f0 * (1 + a_rsa sin(2 pi f_b t) + h(t))``,

with **respiratory sinus arrhythmia** (``a_rsa``: the rate rises on inspiration, Berntson et
al. 1993) and a slow random **heart-rate variability** ``h`` (band-limited Gaussian noise below
0.15 Hz, the LF band, of standard deviation ``hrv``); the phase is ``2 pi int f dt``, so the
beats stay continuous while the rate drifts.

**Breathing** moves the chest and arm at 12-20 breaths per minute; **arm motion** is a random
2-D ``1/f`` drift below 5 Hz.  Both are returned in pixels for the video simulator
(:mod:`planeray.pulse.simulate`) to shift the image by.  The projector laser's **power
fluctuation** is ``1/f`` noise of a few tenths of a percent.

References
----------
.. [1] Allen, "Photoplethysmography and its application in clinical physiological
   measurement", Physiol. Meas. 28, R1 (2007) -- the PPG waveform, dicrotic notch.
.. [2] McSharry et al., "A dynamical model for generating synthetic electrocardiogram
   signals", IEEE TBME 50, 289 (2003) -- Gaussians in beat phase, RSA and LF/HF variability.
.. [3] Berntson et al., "Respiratory sinus arrhythmia", Psychophysiology 30, 183 (1993).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import check_nonnegative, check_number, check_positive

__all__ = [
    "BEAT_SHAPE",
    "CardiacSignal",
    "beat_shape",
    "cardiac_signal",
    "breathing_signal",
    "arm_motion",
    "power_fluctuation",
]

#: Gaussians ``(phase centre, phase width, amplitude)`` of one beat: the systolic peak, the
#: dicrotic (diastolic) wave and a slow diastolic run-off.  Their sum, minus its minimum,
#: divided by its range, is :func:`beat_shape`.
BEAT_SHAPE = ((0.20, 0.060, 1.00), (0.45, 0.075, 0.55), (0.62, 0.14, 0.12))


def beat_shape(phase) -> np.ndarray:
    """Blood volume over one beat, ``phase`` in cycles (periodic), normalized to [0, 1].

    Examples
    --------
    >>> phase = np.linspace(0, 1, 1001)
    >>> v = beat_shape(phase)
    >>> float(v.min()), float(v.max())
    (0.0, 1.0)
    >>> float(round(phase[np.argmax(v)], 2))  # the systolic peak
    0.2
    """
    phase = np.asarray(phase, dtype=np.float64) % 1.0
    v = _raw_shape(phase)
    lo, hi = _shape_range()
    return (v - lo) / (hi - lo)


def _raw_shape(phase):
    v = np.zeros_like(phase)
    for centre, width, amp in BEAT_SHAPE:
        d = (phase - centre + 0.5) % 1.0 - 0.5  # wrapped distance: the beat is periodic
        v += amp * np.exp(-0.5 * (d / width) ** 2)
    return v


_RANGE: tuple[float, float] | None = None


def _shape_range() -> tuple[float, float]:
    global _RANGE
    if _RANGE is None:
        v = _raw_shape(np.linspace(0.0, 1.0, 20001))
        _RANGE = (float(v.min()), float(v.max()))
    return _RANGE


@dataclass(frozen=True)
class CardiacSignal:
    """A sampled cardiac signal.

    Attributes
    ----------
    time_s : ndarray (N,)
    volume : ndarray (N,)
        Blood-volume pulse, 0 (diastole) .. 1 (systolic peak) per beat.
    rate_bpm : ndarray (N,)
        Instantaneous heart rate.
    beat_times_s : ndarray
        Times of the systolic peaks.
    mean_rate_bpm : float
        Beats per minute over the record: ``60 * beats / duration`` from the phase.
    """

    time_s: np.ndarray
    volume: np.ndarray
    rate_bpm: np.ndarray
    beat_times_s: np.ndarray
    mean_rate_bpm: float


def _lowpass_noise(rng, n, fps, cutoff_hz, std, *, pink=False):
    """Gaussian noise band-limited below ``cutoff_hz`` (ideal filter in frequency), standard deviation ``std``.

    ``pink``: a ``1/f`` power spectrum (amplitude ``1/sqrt(f)``) instead of a flat one.
    """
    if std == 0 or n < 2:
        return np.zeros(n)
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1.0 / fps)
    if pink:
        spec[1:] /= np.sqrt(f[1:])
    spec[(f > cutoff_hz) | (f == 0)] = 0.0
    x = np.fft.irfft(spec, n)
    s = x.std()
    return x * (std / s) if s > 0 else x


def cardiac_signal(
    n_samples: int,
    fps: float,
    *,
    bpm: float = 72.0,
    hrv: float = 0.0,
    rsa: float = 0.0,
    breaths_per_min: float = 15.0,
    seed: int = 0,
) -> CardiacSignal:
    """The blood-volume pulse sampled at ``fps``.

    Parameters
    ----------
    n_samples : int
    fps : float
        Sampling (frame) rate, Hz.
    bpm : float
        Mean heart rate ``f0``, beats per minute.
    hrv : float
        Standard deviation of the slow (< 0.15 Hz) random rate variation, as a fraction of
        ``f0`` (0.03 is a typical resting value).
    rsa : float
        Amplitude of the respiratory sinus arrhythmia, a fraction of ``f0`` (~0.03-0.05 at rest).
    breaths_per_min : float
        Breathing rate driving the RSA.
    seed : int
        Seed of the random variability and of the first beat's phase.

    Examples
    --------
    >>> s = cardiac_signal(900, 30.0, bpm=60.0)
    >>> len(s.beat_times_s), round(s.mean_rate_bpm, 6)
    (30, 60.0)
    """
    n = int(n_samples)
    fps = check_positive(fps, "fps")
    check_number(bpm, "bpm", minimum=20.0, maximum=250.0)
    check_nonnegative(hrv, "hrv")
    check_nonnegative(rsa, "rsa")
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fps
    f0 = bpm / 60.0
    rel = rsa * np.sin(2 * np.pi * breaths_per_min / 60.0 * t) + _lowpass_noise(rng, n, fps, 0.15, hrv)
    f = f0 * np.maximum(1.0 + rel, 0.2)
    phase0 = rng.random()
    # cumulative phase (trapezoids), cycles
    phase = phase0 + np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) / fps)])
    volume = beat_shape(phase)
    # systolic peaks: where phase crosses k + 0.20
    k = np.arange(np.ceil(phase[0] - 0.2), np.floor(phase[-1] - 0.2) + 1)
    beats = np.interp(k + 0.2, phase, t) if k.size else np.zeros(0)
    duration = n / fps
    mean_rate = 60.0 * float(np.mean(f)) if n else float(bpm)
    return CardiacSignal(t, volume, 60.0 * f, beats, mean_rate if duration > 0 else float(bpm))


def breathing_signal(n_samples: int, fps: float, *, breaths_per_min: float = 15.0, seed: int = 0) -> np.ndarray:
    """Chest excursion over time, -1 .. 1: inspiration shorter than expiration (a skewed sinusoid)."""
    rng = np.random.default_rng(seed + 7919)
    t = np.arange(int(n_samples)) / check_positive(fps, "fps")
    phase = 2 * np.pi * (breaths_per_min / 60.0 * t + rng.random())
    x = np.sin(phase) + 0.25 * np.sin(2 * phase + 0.8)
    return x / np.max(np.abs(x)) if x.size else x


def arm_motion(n_samples: int, fps: float, *, std_px: float = 0.2, cutoff_hz: float = 5.0, seed: int = 0) -> np.ndarray:
    """Random arm motion ``(N, 2)`` in pixels (rows, columns): ``1/f`` (pink) noise below ``cutoff_hz``.

    Postural sway and small movements of a resting limb have a ``1/f``-like spectrum (most of the
    motion slow, some in the pulse band), standard deviation ``std_px``.
    """
    rng = np.random.default_rng(seed + 104729)
    n = int(n_samples)
    return np.stack([_lowpass_noise(rng, n, fps, cutoff_hz, std_px, pink=True) for _ in range(2)], axis=1)


def power_fluctuation(n_samples: int, fps: float, *, std: float = 0.003, seed: int = 0) -> np.ndarray:
    """Relative fluctuation of a light source's power over time: ``1/f`` noise of standard deviation ``std``.

    Diode lasers drift with temperature and hop between modes: slow, ``1/f``-like power
    changes of a few tenths of a percent (the projector's laser; multiplies all its light).
    """
    rng = np.random.default_rng(seed + 1299709)
    return _lowpass_noise(rng, int(n_samples), fps, fps / 2, std, pink=True)
