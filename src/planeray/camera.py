"""Rolling-shutter camera model of the simulated Episcan (Sec. 6).

What the sensor does with the light the transport delivers to a pixel:

* **Laser signal.**  Each projector row is lit for one scanline period; a camera
  row collects ``laser_electrons * I`` electrons, where ``I = sum_v L(v) T(v)``
  is Eq. 4.  Direct light comes from one row only, so widening the exposure does
  not make epipolar images brighter -- it only admits more indirect light.
* **Ambient light** is integrated over the whole row exposure:
  ``ambient_e_per_us * t_e * albedo``.  A row is exposed for ``t_e`` (hundreds of
  microseconds) instead of a full frame time, which is why synchronized imaging
  rejects ambient light (Sec. 10, Fig. 13).
* **Photon shot noise** (Poisson), **read noise** (Gaussian, electrons),
  **full-well saturation**, a linear **ADC** with ``bit_depth`` bits and a
  ``black_level`` offset, and **averaging** of ``frames_averaged`` frames
  (the paper: 12 bit, 8 frames).
* **Synchronization**: ``jitter_us`` is the Gaussian timing jitter between laser
  and shutter within an exposure; it blurs the band edges and leaks light into
  neighbouring rows (it is part of the illumination model the demultiplexer
  uses).  ``row_jitter_us`` is a per-frame, per-row trigger offset; it is drawn
  at random for each frame and shows up as horizontal row artifacts exactly where
  a band edge sits on the epipolar plane, ``|t_d| ~ t_e / 2`` (Sec. 4).

Images are returned normalized, ``(adu - black_level) / (2**bit_depth - 1 - black_level)``,
the same normalization as the stack import, so simulated and captured stacks
are interchangeable downstream.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ._validate import check_integer, check_nonnegative, check_number, check_positive

__all__ = ["CameraModel", "binned_camera", "row_shifts_rows"]


@dataclass(frozen=True)
class CameraModel:
    """Sensor and synchronization parameters (defaults: an IDS UI-3250-like camera).

    Parameters
    ----------
    bit_depth : int
        ADC bits (12).
    black_level : int
        ADC offset in codes (64).
    full_well_e : float
        Electrons at which a pixel saturates; mapped to the largest ADC code.
    read_noise_e : float
        Read noise, electrons RMS per frame.
    laser_electrons : float
        Electrons per frame from a white Lambertian surface under its own
        projector row (``T = 1`` integrated over one scanline).
    ambient_e_per_us : float
        Ambient electrons per microsecond of row exposure for albedo 1.
    frames_averaged : int
        Frames averaged per stack image (8).
    jitter_us : float
        Gaussian sigma of laser-to-shutter timing jitter (blurs band edges).
    row_jitter_us : float
        Gaussian sigma of the per-frame, per-row trigger offset (row artifacts).

    See Also
    --------
    planeray.SimulatedEpiscan : the simulated device that uses it.
    planeray.simulate_stack : a simulated sweep.

    Examples
    --------
    >>> cam = CameraModel(read_noise_e=2.0)
    >>> cam.max_code, cam.frames_averaged
    (4095, 8)
    """

    bit_depth: int = 12
    black_level: int = 64
    full_well_e: float = 10_000.0
    read_noise_e: float = 7.0
    laser_electrons: float = 6_000.0
    ambient_e_per_us: float = 0.5
    frames_averaged: int = 8
    jitter_us: float = 5.0
    row_jitter_us: float = 10.0

    def __post_init__(self):
        check_integer(self.bit_depth, "bit_depth", minimum=1, maximum=16)
        check_number(self.black_level, "black_level", minimum=0, maximum=self.max_code, max_inclusive=False)
        for name in ("full_well_e", "laser_electrons"):
            check_positive(getattr(self, name), name)
        for name in ("read_noise_e", "ambient_e_per_us", "jitter_us", "row_jitter_us"):
            check_nonnegative(getattr(self, name), name)
        check_integer(self.frames_averaged, "frames_averaged", minimum=1)

    @property
    def max_code(self) -> int:
        return 2**self.bit_depth - 1

    @property
    def gain_adu_per_e(self) -> float:
        """Conversion gain: full well maps to the largest code above black."""
        return (self.max_code - self.black_level) / self.full_well_e

    @property
    def signal_scale(self) -> float:
        """Normalized image value per unit of Eq. 4 (``laser_electrons / full_well``).

        A transport demultiplexed from this camera's stack is ``signal_scale``
        times the scene's transport.
        """
        return self.laser_electrons / self.full_well_e

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_metadata(cls, metadata) -> CameraModel | None:
        """The camera a stack's metadata records (``camera``: a simulated capture, or an import folder's
        ``acquisition.json`` ``planeray_metadata``), or None when it records none (or an unusable one)."""
        cam = metadata.get("camera") if isinstance(metadata, dict) else None
        if not isinstance(cam, dict):
            return None
        try:
            return cls(**cam)
        except (TypeError, ValueError):
            return None

    def pixel_variance(self, image) -> np.ndarray:
        """Variance of a stack image's pixels (normalized units) under this camera's noise model, from
        the image's own values (:meth:`image_variance` takes the expected signal instead).

        ``frames_averaged`` frames of Poisson electrons (``image * full_well``), Gaussian read noise and
        a uniform rounding to ADC codes per frame, averaged:
        ``var = (e + r^2) / (n FW^2) + 1 / (12 n span^2)``.  (The row jitter, which moves a whole camera
        row's band, is not in it: it depends on the scene, :meth:`row_jitter_rows`.)
        """
        return self._variance_of_electrons(np.maximum(np.asarray(image, float), 0.0) * self.full_well_e)

    def _variance_of_electrons(self, e):
        """The normalized image's variance at ``e`` expected electrons per frame (shot, read, rounding; averaged)."""
        n = self.frames_averaged
        span = self.max_code - self.black_level
        return (e + self.read_noise_e**2) / (n * self.full_well_e**2) + 1.0 / (12.0 * n * span**2)

    def row_jitter_rows(self, lines_per_second: float) -> float:
        """Standard deviation of a stack image's band position per camera row, projector rows.

        The trigger offset of every frame and camera row (``row_jitter_us``) moves the band by
        ``row_jitter_us * lines_per_second`` rows; averaged over ``frames_averaged`` frames.
        """
        return float(self.row_jitter_us) * 1e-6 * float(lines_per_second) / math.sqrt(self.frames_averaged)

    def mean_electrons(self, signal, exposure_us, *, ambient_albedo=None, out=None):
        """Expected electrons per frame: laser signal plus ambient over the row exposure.

        ``out``: a float64 array of the signal's shape written and returned instead of a new one.
        """
        e = np.multiply(signal, self.laser_electrons, out=out, dtype=np.float64)
        if ambient_albedo is not None and self.ambient_e_per_us > 0:
            ambient = self.ambient_e_per_us * float(exposure_us) * np.asarray(ambient_albedo, dtype=np.float64)
            e = np.add(e, ambient, out=out)
        return np.maximum(e, 0.0, out=out)

    def expected_image(self, signal, exposure_us, *, ambient_albedo=None, out=None, work=None):
        """The noise-free image (what :meth:`expose` returns with ``noise=False``) and its number of
        saturated pixels.

        Expected electrons clipped at full well, through the ADC gain, normalized.  ``out`` (float32)
        receives the image and ``work`` (float64, the signal's shape) is scratch; given both, nothing of
        the image's size is allocated but a mask of its saturated pixels (the live viewer reuses them
        for every frame).

        Returns
        -------
        image : ndarray (H, W) float32
            ``out`` when given.
        n_saturated : int
            Pixels at full well.
        """
        e = self.mean_electrons(signal, exposure_us, ambient_albedo=ambient_albedo, out=work)
        n_saturated = int(np.count_nonzero(e >= self.full_well_e))
        return self._normalized_expected(e, out), n_saturated

    def _normalized_expected(self, e_mean, out=None):
        """Normalized image of expected electrons (clipped at full well); overwrites ``e_mean``."""
        np.minimum(e_mean, self.full_well_e, out=e_mean)
        e_mean *= self.gain_adu_per_e
        e_mean /= self.max_code - self.black_level
        if out is None:
            return e_mean.astype(np.float32)
        np.copyto(out, e_mean, casting="same_kind")
        return out

    def image_variance(self, signal, exposure_us, *, ambient_albedo=None):
        """Variance of a stack image (normalized units) of expected signal ``signal``: the noise model of
        :meth:`expose` in one formula.

        Per frame the electrons are Poisson with mean ``e`` (laser plus ambient, :meth:`mean_electrons`),
        the read noise adds ``read_noise_e**2``, and rounding to a code adds ``1/12`` code squared; the
        ``frames_averaged`` frames are averaged.  In normalized units (``e / full_well_e``):

        ``var = (e + read_noise_e**2) / (F full_well_e**2) + 1 / (12 F (2**bit_depth - 1 - black_level)**2)``

        Saturation and the ADC's floor at code 0 are left out (they only lower the variance), and so is
        the row jitter, which moves the band rather than adding noise.  What the sweep designer
        (:mod:`planeray.design`) weighs each image by.

        Parameters
        ----------
        signal : float or ndarray
            Noise-free Eq. 4 value (transport units), as :meth:`expose` takes it.
        exposure_us : float or ndarray
            Row exposure (us), for the ambient term (broadcast against ``signal``).
        ambient_albedo : float or ndarray, optional
            Reflectance under ambient light (None: no ambient light).

        Returns
        -------
        variance : float or ndarray
            Variance of the normalized image value.

        Examples
        --------
        A white surface's epipolar value at the defaults (0.6 of full well, 8 frames): a standard
        deviation of 0.3 % of full scale.

        >>> round(float(np.sqrt(CameraModel().image_variance(1.0, 600.0))), 5)
        0.00275
        """
        e = self.laser_electrons * np.asarray(signal, dtype=np.float64)
        if ambient_albedo is not None and self.ambient_e_per_us > 0:
            e = e + self.ambient_e_per_us * np.asarray(exposure_us, np.float64) * np.asarray(ambient_albedo, np.float64)
        return self._variance_of_electrons(np.maximum(e, 0.0))

    def expose(self, signal, exposure_us, rng: np.random.Generator, *, ambient_albedo=None, noise=True):
        """Capture one stack image: ``frames_averaged`` noisy frames, averaged and normalized.

        Parameters
        ----------
        signal : ndarray (H, W)
            Noise-free Eq. 4 image (transport units), averaged over the frames' sync.
        exposure_us : float
            Row exposure, for the ambient term.
        rng : numpy.random.Generator
        ambient_albedo : ndarray (H, W), optional
        noise : bool
            False gives the expected normalized image (no shot/read noise, no
            quantization) -- for ground-truth comparisons.

        Returns
        -------
        image : ndarray (H, W) float32
            Normalized image; nominally [0, 1], may dip slightly below 0 by read noise.
        saturated : ndarray (H, W) bool
            Pixels that reached full well or the top code in any frame.
        """
        e_mean = self.mean_electrons(signal, exposure_us, ambient_albedo=ambient_albedo)
        span = self.max_code - self.black_level
        if not noise:
            saturated = e_mean >= self.full_well_e
            return self._normalized_expected(e_mean), saturated
        n = self.frames_averaged
        g = self.gain_adu_per_e
        # Frames of pixels that cannot reach full well are summed in one draw: the
        # sum of n Poisson frames is Poisson(n * mean) and the sum of n read noises
        # is Gaussian with n times the variance; each frame's rounding to a code is
        # an independent uniform error (the per-frame noise spans several codes).
        # Pixels that may saturate get the exact frame-by-frame treatment.
        risky = e_mean + 6.0 * np.sqrt(e_mean) + 6.0 * self.read_noise_e >= self.full_well_e
        e_sum = rng.poisson(n * e_mean).astype(np.float64)
        if self.read_noise_e > 0:
            e_sum += rng.normal(0.0, self.read_noise_e * np.sqrt(n), e_mean.shape)
        rounding = rng.random((n, *e_mean.shape)).sum(axis=0) - 0.5 * n
        adu_sum = e_sum * g + rounding
        floor = -self.black_level * n  # the ADC cannot go below code 0
        total = np.maximum(adu_sum, floor) + n * self.black_level
        saturated = np.zeros(e_mean.shape, bool)
        if risky.any():
            sub, sat = self._frames(e_mean[risky], rng)
            total[risky] = sub
            saturated[risky] = sat
        image = (total / n - self.black_level) / span
        return image.astype(np.float32), saturated

    def _frames(self, e_mean, rng):
        """Frame-by-frame capture (full well and ADC clipping per frame); returns the ADU sum."""
        total = np.zeros(e_mean.shape, np.float64)
        saturated = np.zeros(e_mean.shape, bool)
        for _ in range(self.frames_averaged):
            e = rng.poisson(e_mean).astype(np.float64)
            full = e >= self.full_well_e
            if self.read_noise_e > 0:
                e += rng.normal(0.0, self.read_noise_e, e.shape)
            adu = np.clip(np.rint(e * self.gain_adu_per_e) + self.black_level, 0, self.max_code)
            adu[full] = self.max_code  # a full well reads as the top code
            saturated |= adu >= self.max_code
            total += adu
        return total, saturated


def row_shifts_rows(
    rng: np.random.Generator, n_frames: int, camera_rows: int, row_jitter_us: float, lines_per_second: float
):
    """Realized per-frame, per-row trigger offsets ``(n_frames, H)`` in projector rows.

    Returns None when ``row_jitter_us`` is 0 (no artifacts).

    Parameters
    ----------
    rng : numpy.random.Generator
        The source of the jitter.
    n_frames : int
        Frames averaged into one image.
    camera_rows : int
        Camera rows ``H``.
    row_jitter_us : float
        Standard deviation of the per-row trigger offset, microseconds.
    lines_per_second : float
        Projector scan rate in rows per second (turns microseconds into rows).

    Returns
    -------
    ndarray (n_frames, H) or None
        Offsets in projector rows; None when ``row_jitter_us`` is 0.

    See Also
    --------
    planeray.timing.Band : takes them as ``row_shifts_rows``.

    Examples
    --------
    10 us of row jitter at 54,000 rows/s is about half a projector row:

    >>> import numpy as np
    >>> shifts = row_shifts_rows(np.random.default_rng(0), 200, 64, 10.0, 54000.0)
    >>> shifts.shape, round(float(shifts.std()), 1)
    ((200, 64), 0.5)
    """
    if row_jitter_us <= 0:
        return None
    return rng.normal(0.0, row_jitter_us * 1e-6 * lines_per_second, size=(n_frames, camera_rows))


def binned_camera(camera: CameraModel, pixels: float) -> CameraModel:
    """The camera whose one pixel is the sum of ``pixels`` sensor pixels.

    A simulated pixel stands for the pixels of the real sensor that see the same patch: their full
    well, laser and ambient electrons add up (times ``pixels``), their read noise in quadrature
    (times ``sqrt(pixels)``), and the ADC gains the bits the sum gains (up to 16), so that shot noise
    per unit of scene is the real camera's whatever the simulated size.  ``pixels <= 1``: ``camera``.

    Parameters
    ----------
    camera : CameraModel
        The real sensor's model.
    pixels : float
        Sensor pixels summed into one simulated pixel (1 or less: ``camera`` unchanged).

    Returns
    -------
    CameraModel
        The binned camera.

    See Also
    --------
    CameraModel : the noise model.

    Examples
    --------
    >>> binned_camera(CameraModel(), 16).bit_depth
    16
    """
    from dataclasses import replace

    if pixels <= 1:
        return camera
    bits = min(16, camera.bit_depth + int(np.floor(np.log2(pixels) / 2 + 0.5)) * 2)
    return replace(
        camera,
        full_well_e=camera.full_well_e * pixels,
        laser_electrons=camera.laser_electrons * pixels,
        ambient_e_per_us=camera.ambient_e_per_us * pixels,
        read_noise_e=camera.read_noise_e * float(np.sqrt(pixels)),
        bit_depth=bits,
        black_level=camera.black_level * 2 ** (bits - camera.bit_depth),
    )
