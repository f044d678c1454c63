"""Eulerian video magnification (Wu et al. 2012), as the paper used it for the pulse (Sec. 10, Fig. 15).

Each frame is decomposed by a spatial pyramid (OpenCV ``pyrDown`` / ``pyrUp``: the Burt-Adelson
5-tap binomial filter), every pixel of a pyramid level is filtered in **time** by an ideal
band-pass, multiplied by ``alpha`` and added back:

``I_out(x, t) = I(x, t) + alpha * B(x, t)``,

``B`` the band-passed video (Wu et al. Eq. 4: ``I~ = f(x + (1 + alpha) delta(t))``, to first order
``I + (1 + alpha) B`` for the in-band part). The paper's settings are the defaults: an ideal
temporal band-pass of 0.5-2 Hz, ``alpha = 50`` and 4 pyramid levels.

* ``pyramid="gaussian"`` (Wu's colour magnification, the one for a pulse): the video is blurred
  and down-sampled ``levels`` times (a 16x smaller video at 4 levels), filtered, amplified,
  up-sampled back and added.
* ``pyramid="laplacian"`` (Wu's motion magnification): every band of a ``levels``-level Laplacian
  pyramid is filtered and amplified; with Wu's spatial cut-off ``lambda_c`` (pixels) the gain
  falls on the fine levels and the finest level and the low-pass residual are left unamplified,
  as in Wu's reference code (:func:`level_alphas`).

**Amplification convention.**  Our temporal filter is a real, two-sided ideal band-pass: the FFT
along time keeps the bins with ``f_lo <= |f| <= f_hi`` (``numpy.fft.rfft`` / ``irfft``), so
``B`` is exactly the in-band part of the signal and an in-band sinusoid of amplitude ``a``
leaves with amplitude ``(1 + alpha) a``.  Wu et al.'s MATLAB ``ideal_bandpassing`` builds its
mask on the frequencies ``0 .. fs`` of ``fft`` and keeps only the positive ones below ``f_hi``,
then takes the real part of ``ifft``: that is half the band-passed signal, so its ``alpha``
acts as ``alpha / 2`` (``1 + alpha/2`` overall).  ``alpha`` here is the gain that is applied; to
reproduce a video made with Wu's code and factor ``alpha_w``, pass ``alpha = alpha_w / 2``.
``tests/test_pulse.py`` checks both (the one-sided filter is implemented there as a reference).

The temporal filter is vectorized over pixels and frames: one real FFT along the frame axis of the
whole pyramid level.  The spatial pyramid is OpenCV's, called once per frame and level (stacking
the frames as the channels of one image was measured 4-7x slower: the transposes and OpenCV's
many-channel kernels cost more than the calls they save), writing into preallocated arrays;
``benchmarks/bench_pulse.py`` measures it against the per-frame structure of Wu's code.

References
----------
.. [1] Wu, Rubinstein, Shih, Guttag, Durand, Freeman, "Eulerian Video Magnification for
   Revealing Subtle Changes in the World", ACM Trans. Graph. 31(4), 65 (2012).
.. [2] Burt and Adelson, "The Laplacian pyramid as a compact image code", IEEE Trans.
   Commun. 31, 532 (1983).
"""

from __future__ import annotations

import numpy as np

from .._extras import import_extra
from .._validate import check_integer, check_nonnegative, check_positive
from ..errors import InputError

__all__ = [
    "DEFAULT_BAND_HZ",
    "DEFAULT_ALPHA",
    "DEFAULT_LEVELS",
    "ideal_bandpass",
    "pyramid_down",
    "pyramid_up",
    "laplacian_pyramid",
    "level_alphas",
    "magnify",
    "Magnifier",
    "bandpass_tiles",
    "check_band",
]

#: The paper's settings (Sec. 10): ideal band-pass 0.5-2 Hz, alpha = 50, 4 pyramid levels.
DEFAULT_BAND_HZ = (0.5, 2.0)
DEFAULT_ALPHA = 50.0
DEFAULT_LEVELS = 4


def check_band(band_hz, fps: float, name: str = "band", *, clip: bool = False) -> tuple[float, float]:
    """``(f_lo, f_hi)`` with ``0 <= f_lo < f_hi <= fps / 2``, or a one-line :class:`InputError`.

    A band reaching above the Nyquist frequency ``fps / 2`` is refused (``clip``: cut at it instead,
    for a band that is a default rather than a request).
    """
    try:
        lo, hi = (float(band_hz[0]), float(band_hz[1]))
    except (TypeError, ValueError, IndexError):
        raise InputError(f"{name} must be two frequencies (Hz), got {band_hz!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo < 0 or hi <= lo:
        raise InputError(f"{name} must be 0 <= low < high (Hz), got {lo:g}-{hi:g}")
    if lo >= fps / 2:
        raise InputError(f"{name} {lo:g}-{hi:g} Hz lies above the Nyquist frequency {fps / 2:g} Hz of {fps:g} fps")
    if hi > fps / 2 and not clip:
        raise InputError(f"{name} {lo:g}-{hi:g} Hz reaches above the Nyquist frequency {fps / 2:g} Hz of {fps:g} fps")
    return lo, min(hi, fps / 2)


def ideal_bandpass(x, fps: float, band_hz=DEFAULT_BAND_HZ, *, axis: int = 0) -> np.ndarray:
    """Ideal (brick-wall) temporal band-pass along ``axis``: keeps ``f_lo <= |f| <= f_hi`` exactly.

    Two-sided and real: a sinusoid inside the band passes unchanged (gain 1), outside it is removed.

    Examples
    --------
    >>> t = np.arange(300) / 30.0
    >>> x = np.sin(2 * np.pi * 1.0 * t) + np.sin(2 * np.pi * 5.0 * t) + 3.0
    >>> y = ideal_bandpass(x, 30.0, (0.5, 2.0))
    >>> bool(np.allclose(y, np.sin(2 * np.pi * 1.0 * t), atol=1e-9))
    True
    """
    x = np.asarray(x)
    fps = check_positive(fps, "fps")
    lo, hi = check_band(band_hz, fps)
    n = x.shape[axis]
    spec = np.fft.rfft(x, axis=axis)
    f = np.fft.rfftfreq(n, 1.0 / fps)
    keep = (f >= lo) & (f <= hi)
    shape = [1] * x.ndim
    shape[axis] = f.size
    spec *= keep.reshape(shape)
    out = np.fft.irfft(spec, n, axis=axis)
    return out.astype(np.float32) if x.dtype == np.float32 else out


def _down_chain(image, levels: int):
    cv2 = import_extra("cv2", "Eulerian video magnification (its pyramids)")

    for _ in range(levels):
        image = cv2.pyrDown(image)
    return image


def _up_chain(image, sizes):
    cv2 = import_extra("cv2", "Eulerian video magnification (its pyramids)")

    for h, w in reversed(sizes[:-1]):
        image = cv2.pyrUp(image, dstsize=(w, h))
    return image


def _pyramid_sizes(shape, levels: int) -> list[tuple[int, int]]:
    sizes = [tuple(int(v) for v in shape)]
    for _ in range(levels):
        h, w = sizes[-1]
        if min(h, w) < 2:
            raise InputError(
                f"levels = {levels}: too many pyramid levels for {shape[0]}x{shape[1]} frames (at most "
                f"{len(sizes) - 1})"
            )
        sizes.append(((h + 1) // 2, (w + 1) // 2))  # cv2.pyrDown's default size
    return sizes


def pyramid_down(frames, levels: int) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Blur and down-sample every frame ``levels`` times (``cv2.pyrDown``).

    Returns the smallest level ``(T, h, w)`` and the ``(H, W)`` of every level from the
    original down (``levels + 1`` sizes), which :func:`pyramid_up` needs to return exactly.
    """
    frames = np.asarray(frames, np.float32)
    sizes = _pyramid_sizes(frames.shape[1:3], levels)
    out = np.empty((frames.shape[0], *sizes[-1]), np.float32)
    for t in range(frames.shape[0]):
        out[t] = _down_chain(frames[t], levels)
    return out, sizes


def pyramid_up(frames, sizes: list[tuple[int, int]]) -> np.ndarray:
    """Up-sample ``frames`` (the level of ``sizes[-1]``) back through ``sizes`` to ``sizes[0]`` (``cv2.pyrUp``)."""
    frames = np.asarray(frames, np.float32)
    out = np.empty((frames.shape[0], *sizes[0]), np.float32)
    for t in range(frames.shape[0]):
        out[t] = _up_chain(frames[t], sizes)
    return out


def laplacian_pyramid(frames, levels: int) -> list[np.ndarray]:
    """``levels`` band-pass levels (finest first) and the low-pass residual, each ``(T, h_l, w_l)``.

    The frames are exactly the sum of every level up-sampled (the pyramid is lossless).
    """
    g = np.asarray(frames, np.float32)
    sizes = _pyramid_sizes(g.shape[1:3], levels)
    bands = [np.empty((g.shape[0], *sz), np.float32) for sz in sizes]
    for t in range(g.shape[0]):
        for level, band in enumerate(_laplacian_frame(g[t], sizes)):
            bands[level][t] = band
    return bands


def _laplacian_frame(frame, sizes) -> list[np.ndarray]:
    """One frame's Laplacian pyramid: ``len(sizes) - 1`` band-pass levels (finest first) and the residual."""
    cv2 = import_extra("cv2", "Eulerian video magnification (its pyramids)")

    out, cur = [], frame
    for level in range(len(sizes) - 1):
        down = cv2.pyrDown(cur)
        h, w = sizes[level]
        out.append(cur - cv2.pyrUp(down, dstsize=(w, h)))
        cur = down
    out.append(cur)
    return out


def _collapse(levels: dict, sizes) -> np.ndarray | None:
    """Sum pyramid levels ``{level: (h_l, w_l) image}`` into the finest size, coarse to fine (``cv2.pyrUp``
    the running sum, add the level); None when no level is given.  With only the coarsest level this is
    the up-sampling of a Gaussian level (:func:`pyramid_up`), with the band levels the Laplacian collapse."""
    cv2 = import_extra("cv2", "Eulerian video magnification (its pyramids)")

    acc = None
    for level in range(len(sizes) - 1, -1, -1):
        if acc is not None:
            h, w = sizes[level]
            acc = cv2.pyrUp(acc, dstsize=(w, h))
        band = levels.get(level)
        if band is not None:
            acc = np.array(band, np.float32) if acc is None else acc + band
    return acc


def level_alphas(shape, levels: int, alpha: float, lambda_c: float | None, *, exaggeration: float = 2.0) -> list[float]:
    """Gain of every Laplacian level (finest first, then the residual), Wu et al.'s rule.

    Without ``lambda_c`` every band level gets ``alpha`` and the residual 0.  With it (Wu et al.
    2012, Sec. 3, as their ``amplify_spatial_lpyr_temporal_ideal`` does it): the residual has the
    representative wavelength ``lambda = sqrt(H^2 + W^2) / 3``, which halves at each finer level;
    a level gets ``min(alpha, exaggeration * (lambda / (8 delta) - 1))``,
    ``delta = lambda_c / (8 (1 + alpha))``, and the finest level and the residual get 0.

    Examples
    --------
    >>> [round(a, 1) for a in level_alphas((480, 640), 4, 50.0, 1000.0)]
    [0.0, 1.4, 4.8, 11.6, 0.0]
    """
    if lambda_c is None:
        return [float(alpha)] * levels + [0.0]
    delta = lambda_c / 8.0 / (1.0 + alpha)
    lam = float(np.hypot(*shape)) / 3.0
    out = [0.0] * (levels + 1)
    for level in range(levels, -1, -1):  # from the residual to the finest level
        a = exaggeration * (lam / delta / 8.0 - 1.0)
        out[level] = 0.0 if level in (0, levels) else float(np.clip(a, 0.0, alpha))
        lam /= 2.0
    return out


def magnify(
    frames,
    fps: float,
    *,
    levels: int = DEFAULT_LEVELS,
    band_hz=DEFAULT_BAND_HZ,
    alpha: float = DEFAULT_ALPHA,
    pyramid: str = "gaussian",
    lambda_c: float | None = None,
    return_band: bool = False,
):
    """Eulerian video magnification of ``frames`` ``(T, H, W)``.

    Parameters
    ----------
    frames : array_like (T, H, W)
    fps : float
        Frame rate (Hz).
    levels : int
        Pyramid levels (the paper: 4).
    band_hz : (float, float)
        Ideal temporal pass band (the paper: 0.5-2 Hz).
    alpha : float
        Gain applied to the band-passed video (the paper: 50); see the module's convention.
    pyramid : {"gaussian", "laplacian"}
        Colour magnification of the coarsest Gaussian level (default), or every Laplacian band.
    lambda_c : float, optional
        Laplacian only: Wu's spatial cut-off wavelength in pixels (None: no attenuation).
    return_band : bool
        Also return the amplified, up-sampled band ``alpha * B`` that was added.

    Returns
    -------
    magnified : ndarray (T, H, W) float32
    added : ndarray (T, H, W) float32, only with ``return_band``

    Examples
    --------
    >>> t = np.arange(240) / 30.0
    >>> pulse = 0.01 * np.sin(2 * np.pi * 1.25 * t)  # 75 bpm, 1 % of the light
    >>> video = 0.5 + pulse[:, None, None] * np.ones((1, 32, 32))
    >>> out = magnify(video, 30.0, levels=2)
    >>> float(np.round((out[:, 16, 16] - 0.5).max() / pulse.max(), 3))  # 1 + alpha
    51.0
    """
    frames = np.asarray(frames, np.float32)
    if frames.ndim != 3:
        raise InputError(f"expected frames (T, H, W), got shape {frames.shape}")
    mag = Magnifier(
        frames.shape[1:3],
        fps,
        n_frames=frames.shape[0],
        levels=levels,
        band_hz=band_hz,
        alpha=alpha,
        pyramid=pyramid,
        lambda_c=lambda_c,
    )
    for frame in frames:
        mag.add(frame)
    mag.filter()
    out = np.empty_like(frames)
    added = np.zeros_like(frames) if return_band else None
    for t in range(frames.shape[0]):
        out[t] = mag.magnified(t, frames[t])
        if return_band:
            band = mag.added(t)
            if band is not None:
                added[t] = band
    return (out, added) if return_band else out


def bandpass_tiles(levels, fps: float, band_hz, *, gain: float = 1.0, tile_bytes: int | None = None) -> None:
    """Band-pass ``levels`` ``(T, h, w)`` in time, in place, and multiply by ``gain``: :func:`ideal_bandpass`
    of tiles of pixels of at most ``tile_bytes`` of working memory (each pixel's time series whole).

    ``levels`` is an array or a :class:`planeray.pulse._workspace.DiskArray`; every pixel's result is the
    one :func:`ideal_bandpass` gives the whole array (the FFT of each time series is its own).
    """
    T, h, w = levels.shape
    from ._workspace import pixel_tiles

    for r0, r1, c0, c1 in pixel_tiles((h, w), _BANDPASS_BYTES * T, tile_bytes):
        out = ideal_bandpass(levels[:, r0:r1, c0:c1], fps, band_hz, axis=0)
        out *= np.float32(gain)
        levels[:, r0:r1, c0:c1] = out


#: Working memory of :func:`ideal_bandpass` per float32 sample (the input, its spectrum, the output), bytes.
_BANDPASS_BYTES = 20


class Magnifier:
    """Eulerian magnification of a video given frame by frame: :meth:`add` every frame, :meth:`filter`
    once, then :meth:`magnified` (or :meth:`added`) of any frame.

    What :func:`magnify` does to an array, for videos too long or large to hold: only the pyramid levels
    that are amplified are kept over time (the Gaussian pyramid's coarsest level -- 1/256 of the pixels
    at 4 levels -- or the Laplacian's band levels), in arrays of ``workspace``
    (:class:`planeray.pulse._workspace.Workspace`: memory, or files beyond its allowance), and they are
    band-passed in tiles of pixels.  Parameters as :func:`magnify`; ``n_frames`` sizes the kept levels
    (a video that turns out longer grows them).
    """

    def __init__(
        self,
        shape,
        fps: float,
        *,
        n_frames: int,
        levels: int = DEFAULT_LEVELS,
        band_hz=DEFAULT_BAND_HZ,
        alpha: float = DEFAULT_ALPHA,
        pyramid: str = "gaussian",
        lambda_c: float | None = None,
        workspace=None,
    ):
        from ._workspace import Workspace

        self.fps = check_positive(fps, "fps")
        self.levels = check_integer(levels, "levels", minimum=0)
        check_nonnegative(alpha, "alpha")
        self.band_hz = check_band(band_hz, self.fps)
        self.alpha = float(alpha)
        self.pyramid = pyramid
        self.workspace = Workspace(memory_bytes=None) if workspace is None else workspace
        shape = tuple(int(s) for s in shape)
        if pyramid == "gaussian":
            if lambda_c is not None:
                raise InputError("lambda_c applies to the laplacian pyramid only")
            self.sizes = _pyramid_sizes(shape, self.levels)
            self.gains = {self.levels: self.alpha}
        elif pyramid == "laplacian":
            if lambda_c is not None:
                check_positive(lambda_c, "lambda_c")
            self.sizes = _pyramid_sizes(shape, self.levels)
            gains = level_alphas(shape, self.levels, alpha, lambda_c)
            self.gains = {level: g for level, g in enumerate(gains) if g}
        else:
            raise InputError(f"pyramid must be gaussian or laplacian, got {pyramid!r}")
        self._kept = {
            level: self.workspace.frames(n_frames, self.sizes[level], name=f"level{level}") for level in self.gains
        }
        self._filtered = None  # the kept levels' arrays, once filtered

    def add(self, frame) -> None:
        """Decompose the next frame ``(H, W)`` float32 and keep its amplified levels."""
        if not self._kept:
            return
        if self.pyramid == "gaussian":
            self._kept[self.levels].append(_down_chain(frame, self.levels))
        else:
            bands = _laplacian_frame(frame, self.sizes)
            for level, kept in self._kept.items():
                kept.append(bands[level])

    def filter(self) -> None:
        """Band-pass every kept level in time and apply its gain (once, after the last :meth:`add`)."""
        for level, kept in self._kept.items():
            bandpass_tiles(
                kept.data, self.fps, self.band_hz, gain=self.gains[level], tile_bytes=self.workspace.tile_bytes
            )
        self._filtered = {level: kept.data for level, kept in self._kept.items()}

    def added(self, t: int) -> np.ndarray | None:
        """What is added to frame ``t``: ``alpha * B`` at full size (None where no level is amplified)."""
        if self._filtered is None:
            raise RuntimeError("Magnifier.filter() must run before the magnified frames are read")
        return _collapse({level: data[t] for level, data in self._filtered.items()}, self.sizes)

    def magnified(self, t: int, frame) -> np.ndarray:
        """Frame ``t`` magnified: ``frame + alpha * B`` (a new array)."""
        band = self.added(t)
        return np.array(frame, np.float32) if band is None else frame + band

    def close(self) -> None:
        """Give the kept levels back to the workspace."""
        for kept in self._kept.values():
            self.workspace.release(kept)
        self._kept, self._filtered = {}, None
