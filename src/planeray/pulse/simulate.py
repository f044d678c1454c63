"""A simulated live capture of the pulse in skin: regular, direct, global and short-range indirect video.

The skin scene (``make_scene("skin", ...)``) is imaged frame by frame at a fixed delay and
exposure, while the blood volume pulses, the arm breathes and drifts, ambient light shines, and
the camera (:class:`planeray.camera.CameraModel`, one frame per video frame) adds its noise.

**Pulsation.**  The heart changes the blood volume in the veins by a small fraction
``pulse_amplitude`` (2 % from diastole to systole by default): the scene is built with its
blood-volume knob ``blood_scale = 1 + pulse_amplitude * w(t)`` (each vein's kernel ratio ``R``
becomes ``R ** blood_scale``; the dermis's own blood has no knob in the scene and does not pulse), ``w`` the cardiac waveform
(:func:`planeray.pulse.waveform.cardiac_signal`, 0 at diastole, 1 at the systolic peak).

**Linearization.**  Every image here is linear in the transport, and the transport is smooth in
the blood volume, so instead of rebuilding the scene per frame, each method's noise-free image is
``I(s) = I(1) + (s - 1) dI/ds`` with ``dI/ds`` a central difference of two scene builds at
``1 +- step``.  :func:`linearize` also builds the scene at the extremes of the pulse and reports
the largest error of the linear model there relative to the pulsatile change itself
(:attr:`LinearModel.linearity_error`; README, Pulse: the measured value).

**Methods** (the paper's Fig. 15b), the camera row exposure ``t_e`` and ambient light each sees:

* ``indirect``: the short-range indirect delay image, band at ``delay_us``, exposure ``exposure_us``.
* ``direct``: the epipolar image, delay 0, exposure ``exposure_us``.
* ``regular``: all projector rows (flood illumination, ``T`` summed over every offset), exposed for
  a whole frame of the 720-row projector (13.3 ms at 54,000 lines/s), so ambient light adds up.
* ``global``: ``regular - direct``, two captures subtracted (their noise adds).

Each method's exposure is scaled (as aperture or gain would) so that its brightest pixel sits at
``fill`` of full well: the regular camera is not left saturated by ambient light.

**Pixels.**  A simulated pixel stands for the pixels of the real sensor that see the same patch
of skin, binned together: the sensor's ``sensor_rows`` (the paper's camera, an IDS UI-3250, has
1200) span the whole 720-row projector field, so a scene of ``H`` rows showing ``P`` projector rows
has ``(sensor_rows P / 720 / H)^2`` sensor pixels per simulated pixel: the camera's full well, laser and
ambient electrons scale by that count and its read noise by the square root, and the ADC gains the
bits the sum gains (up to 16), so shot noise per unit of skin is that of the real camera whatever
the simulated size (``sensor_rows=None``: one sensor pixel per simulated pixel).

**Motion and flicker.**  Breathing shifts the image by ``breathing_px`` (peak) and changes the
laser light by ``breathing_gain`` (the distance to the projector); the arm moves by ``motion_px``
(standard deviation, ``1/f`` below 5 Hz); the laser's power fluctuates by ``laser_flicker``
(``1/f``).  These act on all four methods alike in relative terms, while shot noise favours the
brightest (README, Pulse).  Frames are shifted with linear interpolation (``scipy.ndimage.shift``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from .._validate import check_nonnegative, check_number, check_positive
from ..camera import CameraModel, binned_camera
from ..errors import InputError
from ..timing import PAPER_LINES_PER_SECOND, PAPER_PROJECTOR_ROWS, Band
from .video_io import Video
from .waveform import arm_motion, breathing_signal, cardiac_signal, power_fluctuation

__all__ = [
    "METHODS",
    "DEFAULT_DELAY_US",
    "DEFAULT_EXPOSURE_US",
    "LiveSettings",
    "LIMITS",
    "BREATHS_PER_MIN",
    "live_capture_bytes",
    "LinearModel",
    "LiveCapture",
    "method_images",
    "linearize",
    "skin_builder",
    "binned_camera",
    "simulate_live",
]

#: The four videos of Fig. 15b.
METHODS = ("regular", "direct", "global", "indirect")
#: The paper's skin delay: 400-600 us at ~0.5 m (Sec. 10).
DEFAULT_DELAY_US = 450.0
#: Row exposure of the delay images.
DEFAULT_EXPOSURE_US = 600.0


#: Upper bounds of the physiological settings (fractions): heart-rate variability (std of the rate;
#: resting SDNN is ~5 %), respiratory sinus arrhythmia, blood-volume change of the veins per beat (the
#: linear model is checked at 3 %, README Pulse).
LIMITS = {"hrv": 0.2, "rsa": 0.3, "pulse_amplitude": 0.1}
#: Breaths per minute (slow paced breathing to panting).
BREATHS_PER_MIN = (4.0, 60.0)
#: Bytes per frame pixel of :func:`simulate_live` at its peak (the capture's float64 temporaries:
#: measured 86 at 48x48 and 96x96), plus 8 per method kept.
BYTES_PER_FRAME_PIXEL = 96


def live_capture_bytes(settings: LiveSettings, shape, methods=METHODS) -> int:
    """Estimated peak memory of :func:`simulate_live` for ``shape`` (H, W) images, bytes."""
    n = int(round(settings.seconds * settings.frame_rate()))
    return int(n * int(shape[0]) * int(shape[1]) * (BYTES_PER_FRAME_PIXEL + 8 * len(methods)))


@dataclass(frozen=True)
class LiveSettings:
    """What is captured and how the subject moves.

    Parameters
    ----------
    seconds : float
        Length of the video.
    fps : float, optional
        Camera frame rate; default the projector's frame rate ``lines_per_second / projector_rows``.
    bpm, hrv, rsa, breaths_per_min : float
        Heart rate, its variability and respiratory sinus arrhythmia (fractions of the rate), breathing rate
        (:func:`planeray.pulse.waveform.cardiac_signal`).
    pulse_amplitude : float
        Relative blood-volume change of the veins from diastole to the systolic peak (0.02).
    breathing_px, breathing_gain, motion_px : float
        Breathing shift (pixels, peak), breathing brightness change (fraction, peak), arm motion (pixels, std).
    laser_flicker : float
        Relative standard deviation of the laser's power fluctuation (``1/f``).
    delay_us, exposure_us : float
        The indirect image's delay and the row exposure of the delay and direct images.
    lines_per_second : float
    ambient : bool
        Ambient light (the camera's ``ambient_e_per_us``) on.
    noise : bool
        Camera noise on (False: the expected images).
    fill : float
        Brightest expected pixel of each method as a fraction of full well (auto-exposure).
    sensor_rows : int, optional
        Rows of the real sensor the image stands for (binning, see the module docstring).
    """

    seconds: float = 30.0
    fps: float | None = None
    bpm: float = 72.0
    hrv: float = 0.0
    rsa: float = 0.0
    breaths_per_min: float = 15.0
    pulse_amplitude: float = 0.02
    breathing_px: float = 0.3
    breathing_gain: float = 0.003
    motion_px: float = 0.1
    laser_flicker: float = 0.0005
    delay_us: float = DEFAULT_DELAY_US
    exposure_us: float = DEFAULT_EXPOSURE_US
    lines_per_second: float = PAPER_LINES_PER_SECOND
    ambient: bool = True
    noise: bool = True
    fill: float = 0.7
    sensor_rows: int | None = 1200

    def __post_init__(self):
        check_positive(self.seconds, "seconds")
        check_positive(self.lines_per_second, "lines_per_second")
        frame_us = PAPER_PROJECTOR_ROWS / self.lines_per_second * 1e6  # one sweep of the projector
        if self.fps is not None:
            top = self.lines_per_second / PAPER_PROJECTOR_ROWS
            check_number(
                self.fps,
                "fps",
                minimum=0.0,
                maximum=top,
                min_inclusive=False,
                requirement=f"a frame rate > 0 and <= {top:g} Hz (one delay image per sweep of the projector)",
            )
        check_number(self.bpm, "bpm", minimum=30.0, maximum=240.0)
        if self.frame_rate() <= 2 * self.bpm / 60.0:
            raise InputError(
                f"fps must be above twice the heart rate (the Nyquist rate: {2 * self.bpm / 60:g} Hz at bpm "
                f"{self.bpm:g}), got {self.frame_rate():g}"
            )
        for name, top in LIMITS.items():
            check_number(getattr(self, name), name, minimum=0.0, maximum=top)
        for name in ("breathing_px", "breathing_gain", "motion_px", "laser_flicker"):
            check_nonnegative(getattr(self, name), name)
        check_number(self.breaths_per_min, "breaths_per_min", minimum=BREATHS_PER_MIN[0], maximum=BREATHS_PER_MIN[1])
        check_number(
            self.delay_us,
            "delay_us",
            minimum=-frame_us,
            maximum=frame_us,
            requirement=f"a delay in us within +-{frame_us:.0f} (one projector sweep)",
        )
        check_number(
            self.exposure_us,
            "exposure_us",
            minimum=0.0,
            maximum=frame_us,
            min_inclusive=False,
            requirement=f"an exposure in us, > 0 and <= {frame_us:.0f} (one projector sweep)",
        )
        check_number(self.fill, "fill", minimum=0.01, maximum=1.0)
        if self.sensor_rows is not None:
            check_positive(self.sensor_rows, "sensor_rows")

    def frame_rate(self) -> float:
        """The camera's frame rate: ``fps``, or one frame per sweep of the whole (720-row) projector."""
        return float(self.fps) if self.fps is not None else self.lines_per_second / PAPER_PROJECTOR_ROWS


def method_images(scene, *, delay_us: float, exposure_us: float, lines_per_second: float = PAPER_LINES_PER_SECOND):
    """Noise-free laser images (transport units) of ``regular``, ``direct`` and ``indirect`` light of a scene.

    ``global`` is not an image of its own: it is the difference of two captures (:func:`simulate_live`).
    """
    T = scene.transport
    return {
        "regular": T.full_image().astype(np.float64),
        "direct": T.render(Band(0.0, float(exposure_us), float(lines_per_second))).astype(np.float64),
        "indirect": T.render(Band(float(delay_us), float(exposure_us), float(lines_per_second))).astype(np.float64),
    }


@dataclass
class LinearModel:
    """Images at blood scale 1, their derivatives in the scale, and the scene they came from."""

    images: dict
    derivatives: dict
    scene: object
    linearity_error: dict = field(default_factory=dict)
    delay_us: float = DEFAULT_DELAY_US
    exposure_us: float = DEFAULT_EXPOSURE_US

    def at(self, method: str, scale) -> np.ndarray:
        """Images at blood scale(s) ``scale`` (scalar or (T,) -> (H, W) or (T, H, W))."""
        s = np.asarray(scale, np.float64) - 1.0
        return self.images[method] + s[..., None, None] * self.derivatives[method]


def linearize(
    build: Callable[[float], object],
    *,
    delay_us: float = DEFAULT_DELAY_US,
    exposure_us: float = DEFAULT_EXPOSURE_US,
    lines_per_second: float = PAPER_LINES_PER_SECOND,
    step: float = 0.02,
    check_amplitude: float | None = 0.03,
) -> LinearModel:
    """Images and their derivatives in the blood scale, by central differences of scene builds.

    Parameters
    ----------
    build : callable
        ``build(blood_scale) -> Scene``.
    step : float
        Half-width of the central difference.
    check_amplitude : float, optional
        Also build the scene at ``1 + check_amplitude`` and record, per method, the largest
        error of the linear model there relative to the largest pulsatile change (None: skip).
    """
    kw = {"delay_us": delay_us, "exposure_us": exposure_us, "lines_per_second": lines_per_second}
    scene = build(1.0)
    base = method_images(scene, **kw)
    up = method_images(build(1.0 + step), **kw)
    down = method_images(build(1.0 - step), **kw)
    deriv = {m: (up[m] - down[m]) / (2 * step) for m in base}
    model = LinearModel(base, deriv, scene, delay_us=float(delay_us), exposure_us=float(exposure_us))
    if check_amplitude:
        far = method_images(build(1.0 + check_amplitude), **kw)
        for m in base:
            change = np.abs(far[m] - base[m]).max()
            err = np.abs(model.at(m, 1.0 + check_amplitude) - far[m]).max()
            model.linearity_error[m] = float(err / change) if change > 0 else 0.0
    return model


def skin_builder(shape=(64, 64), *, projector_rows: int = 720, seed: int = 0, **scene_params):
    """``build(blood_scale) -> Scene`` of the skin scene (its ``blood_scale`` knob).

    The last eight scenes built are kept: a blood scale asked again returns the same scene
    (read, never changed, by :func:`linearize` and :func:`simulate_live`), so that a report
    linearizing at several delays builds each scene once (the pulse report: 4 builds instead of 18).
    """
    from functools import lru_cache

    from ..scenes import make_scene

    @lru_cache(maxsize=8)
    def scene(blood_scale: float):
        return make_scene(
            "skin", shape, projector_rows=projector_rows, seed=seed, blood_scale=blood_scale, **scene_params
        )

    def build(blood_scale: float):
        return scene(float(blood_scale))

    return build


@dataclass
class LiveCapture:
    """The simulated videos and their ground truth.

    Attributes
    ----------
    videos : dict of str to Video
        One per method of :data:`METHODS` (normalized camera values).
    truth : dict
        ``time_s``, ``volume`` (cardiac waveform), ``rate_bpm`` (instantaneous), ``mean_rate_bpm``,
        ``shift_px`` (T, 2), ``breathing``.
    settings : LiveSettings
    model : LinearModel
    """

    videos: dict
    truth: dict
    settings: LiveSettings
    model: LinearModel

    @property
    def fps(self) -> float:
        return next(iter(self.videos.values())).fps


def _shift_frames(images: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """Frame ``t`` of ``images`` (T, H, W) moved by ``shifts[t]`` = (rows, columns) pixels.

    Bilinear, with the edge pixels repeated outside: what ``scipy.ndimage.shift(frame, shifts[t],
    order=1, mode="nearest")`` gives frame by frame (to rounding), in a few array passes over the
    whole video, one axis at a time (the bilinear weights are separable and the same over a frame).
    """
    shifts = np.asarray(shifts, np.float64)
    if not np.any(shifts):
        return images
    moved = _shift_axis(np.asarray(images, np.float64), shifts[:, 0], axis=1)
    moved = _shift_axis(moved, shifts[:, 1], axis=2)
    return moved.astype(images.dtype, copy=False)


def _shift_axis(frames: np.ndarray, shift: np.ndarray, axis: int) -> np.ndarray:
    """``frames`` (T, H, W) with frame ``t`` moved by ``shift[t]`` pixels along ``axis`` (1 or 2):
    ``out[i] = frame(i - shift)``, linear between pixels, coordinates clamped to the frame."""
    n = frames.shape[axis]
    whole = np.floor(-shift)
    frac = (-shift - whole).reshape(-1, 1, 1)  # in [0, 1): the weight of the next pixel
    first = np.arange(n)[None, :] + whole.astype(np.int64)[:, None]
    shape = [frames.shape[0], 1, 1]
    shape[axis] = n
    lo = np.clip(first, 0, n - 1).reshape(shape)
    hi = np.clip(first + 1, 0, n - 1).reshape(shape)
    return (1.0 - frac) * np.take_along_axis(frames, lo, axis=axis) + frac * np.take_along_axis(frames, hi, axis=axis)


def simulate_live(
    settings: LiveSettings | None = None,
    *,
    build=None,
    model: LinearModel | None = None,
    camera: CameraModel | None = None,
    methods=METHODS,
    seed: int = 0,
    progress=None,
) -> LiveCapture:
    """Simulate the live capture of a pulse in every method of ``methods``.

    Parameters
    ----------
    settings : LiveSettings
    build : callable, optional
        ``build(blood_scale) -> Scene`` (default: the 64x64 skin scene, :func:`skin_builder`).
    model : LinearModel, optional
        A precomputed :func:`linearize` result of ``build`` at these settings' delay and exposure.
    camera : CameraModel, optional
        The sensor (default: the simulated Episcan's); one frame per video frame.
    seed : int
        Seed of the heart-rate variability, motion and camera noise.
    progress : callable, optional
        Called with 1 after each method.
    """
    s = settings or LiveSettings()
    unknown = set(methods) - set(METHODS)
    if unknown:
        raise InputError(f"unknown method(s) {sorted(unknown)}; choose from {', '.join(METHODS)}")
    if model is None:
        model = linearize(
            build or skin_builder(), delay_us=s.delay_us, exposure_us=s.exposure_us, lines_per_second=s.lines_per_second
        )
    elif (model.delay_us, model.exposure_us) != (s.delay_us, s.exposure_us):
        raise InputError(
            f"the model was linearized at delay {model.delay_us:g} us, exposure {model.exposure_us:g} us, "
            f"the settings ask for {s.delay_us:g} and {s.exposure_us:g} us"
        )
    scene = model.scene
    camera = replace(camera or CameraModel(), frames_averaged=1)
    if not s.ambient:
        camera = replace(camera, ambient_e_per_us=0.0)
    if s.sensor_rows is not None:
        # the sensor spans the whole projector field; the scene may show a part of it
        rows = s.sensor_rows * scene.geometry.projector_rows / PAPER_PROJECTOR_ROWS
        camera = binned_camera(camera, (rows / scene.shape[0]) ** 2)
    fps = s.frame_rate()
    n = int(round(s.seconds * fps))
    if n < 8:
        raise InputError(f"{s.seconds:g} s at {fps:g} fps is {n} frames; a pulse video needs at least 8")
    heart = cardiac_signal(n, fps, bpm=s.bpm, hrv=s.hrv, rsa=s.rsa, breaths_per_min=s.breaths_per_min, seed=seed)
    breath = breathing_signal(n, fps, breaths_per_min=s.breaths_per_min, seed=seed)
    shifts = arm_motion(n, fps, std_px=s.motion_px, seed=seed)
    shifts[:, 0] += s.breathing_px * breath
    gain = (1.0 + s.breathing_gain * breath) * (1.0 + power_fluctuation(n, fps, std=s.laser_flicker, seed=seed))
    scale = 1.0 + s.pulse_amplitude * heart.volume
    frame_us = PAPER_PROJECTOR_ROWS / s.lines_per_second * 1e6  # one frame of the whole projector
    albedo = np.asarray(scene.ambient_albedo, np.float64)
    rng = np.random.default_rng([seed, 1])
    # the room light's albedo moved with the arm: the same in every method's video
    amb = _shift_frames(np.broadcast_to(albedo, (n, *albedo.shape)), shifts)

    def capture(method, exposure_us):
        laser = _shift_frames(model.at(method, scale), shifts) * gain[:, None, None]
        expected = camera.mean_electrons(laser.max(axis=0), exposure_us, ambient_albedo=amb.max(axis=0))
        k = min(1.0, s.fill * camera.full_well_e / max(float(expected.max()), 1e-12))
        image, _ = camera.expose(k * laser, exposure_us, rng, ambient_albedo=k * amb, noise=s.noise)
        return image / np.float32(k)  # back to a common scale (what the exposure would have given unscaled)

    videos = {}
    frames = {}
    for m in ("regular", "direct", "indirect"):
        if m in methods or (m in ("regular", "direct") and "global" in methods):
            frames[m] = capture(m, frame_us if m == "regular" else s.exposure_us)
    if "global" in methods:
        frames["global"] = frames["regular"] - frames["direct"]
    meta = {"settings": asdict(s), "seed": int(seed), "scene": scene.params}
    for m in methods:
        videos[m] = Video(frames[m].astype(np.float32), fps, "simulated", {**meta, "method": m})
        if progress:
            progress(1)
    truth = {
        "time_s": heart.time_s,
        "volume": heart.volume,
        "rate_bpm": heart.rate_bpm,
        "mean_rate_bpm": heart.mean_rate_bpm,
        "beat_times_s": heart.beat_times_s,
        "shift_px": shifts,
        "breathing": breath,
        "blood_scale": scale,
    }
    return LiveCapture(videos, truth, s, model)
