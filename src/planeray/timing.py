"""Timing and illumination model of a synchronized rolling-shutter projector-camera (Sec. 3.1).

This module is the single place that turns the two knobs of the device -- the
**delay** ``t_d`` and the **exposure** ``t_e`` -- into illumination weights over
projector rows.  The simulator, the demultiplexer and synthesis all call it, so
they can never disagree about the sign convention or the discretization.

Conventions
-----------
* Rows are counted downward, in projector rows.  A camera row ``t`` sits at the
  projector coordinate ``p_t = (t + 1/2) * rows_per_camera_row - 1/2``
  (:class:`RowGeometry`), so a 128-row image of a 720-row projector is expressible.
* The **offset** ``u = v - t`` is projector row minus camera row (both in projector
  rows).  A positive delay centres the band at ``u = +I_d``: the camera row then
  receives light from a *lower* epipolar plane (Sec. 3.1: "positive t_d > t_e/2
  means the camera row receives light from a vertically lower epipolar plane").
* Offsets are discretized on 1-row bins ``[k - 1/2, k + 1/2)``.  The weight of a
  bin is the exact integral of the (optionally blurred) band over it, so the
  weights of one image sum to ``I_w`` (Eq. 2) wherever the band lies inside the
  projector.

References
----------
.. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa,
   S. G. Narasimhan, "Programmable Non-Epipolar Indirect Light Transport:
   Capture and Analysis", IEEE TVCG 27(4), 2021 (doi:10.1109/TVCG.2019.2946812).
.. [2] M. O'Toole, S. Achar, S. G. Narasimhan, K. N. Kutulakos, "Homogeneous
   codes for energy-efficient illumination and imaging", SIGGRAPH 2015.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtr

from ._validate import check_integer, check_nonnegative, check_number, check_positive

__all__ = [
    "PAPER_LINES_PER_SECOND",
    "PAPER_PROJECTOR_ROWS",
    "PAPER_BOUNDARY_MARGIN_US",
    "delay_from_sync_offset",
    "sync_offset_from_delay",
    "band_centre_rows",
    "band_width_rows",
    "illumination",
    "band_bin_weights",
    "band_interval_weights",
    "RowGeometry",
    "Band",
    "band_weights_at_row",
    "RowPattern",
    "Sweep",
    "paper_sweep",
    "sweep_support_rows",
    "SWEEPS",
    "make_sweep",
    "boundary_images",
    "quick_sweep",
]

#: Projector scanline velocity measured in the paper (27 lines in 500 us, Sec. 6).
PAPER_LINES_PER_SECOND = 54_000.0
#: Rows of the paper's projector (the PicoPro, 720 lines).
PAPER_PROJECTOR_ROWS = 720
#: Images with ``||t_d| - t_e/2| <= 75 us`` sit on the epipolar/non-epipolar
#: boundary and show synchronization artifacts; the paper leaves them out (N = 75).
PAPER_BOUNDARY_MARGIN_US = 75.0


# ----------------------------------------------------------------------------
# Eq. 1 and Eq. 2
# ----------------------------------------------------------------------------
def _line_time_us(line_time_us, lines_per_second):
    if line_time_us is None:
        if lines_per_second is None:
            raise ValueError("give line_time_us or lines_per_second")
        return 1e6 / float(lines_per_second)
    return line_time_us


def delay_from_sync_offset(sync_offset_us, exposure_us, *, line_time_us=None, lines_per_second=None):
    """Delay from the synchronization offset, Eq. 1: ``t_d = t_e/2 - t_p/2 - t'_o``.

    Parameters
    ----------
    sync_offset_us : float or array_like
        ``t'_o``, time between the start of a row's exposure and the moment the
        projector illuminates that row, in microseconds.
    exposure_us : float or array_like
        Row exposure ``t_e`` in microseconds.
    line_time_us : float, optional
        ``t_p``, time the projector illuminates one scanline.  Defaults to one
        scanline period ``1e6 / lines_per_second``.
    lines_per_second : float, optional
        Projector scanline velocity ``v_p``; used only when ``line_time_us`` is None.

    Returns
    -------
    delay_us : float or ndarray
        Delay ``t_d`` between the centre of exposure and the centre of illumination.

    See Also
    --------
    sync_offset_from_delay : the inverse.
    band_centre_rows : the delay in projector rows (Eq. 2).

    Examples
    --------
    The paper's line time at 54,000 lines/s is 18.5 us; a sync offset of 0 with a
    600 us exposure puts the band 290.7 us ahead:

    >>> round(float(delay_from_sync_offset(0.0, 600.0, lines_per_second=54_000)), 2)
    290.74
    >>> round(float(sync_offset_from_delay(290.74, 600.0, lines_per_second=54_000)), 2)
    0.0
    """
    t_p = _line_time_us(line_time_us, lines_per_second)
    return 0.5 * np.asarray(exposure_us, dtype=float) - 0.5 * t_p - np.asarray(sync_offset_us, dtype=float)


def sync_offset_from_delay(delay_us, exposure_us, *, line_time_us=None, lines_per_second=None):
    """Inverse of Eq. 1: ``t'_o = t_e/2 - t_p/2 - t_d`` (see :func:`delay_from_sync_offset`).

    Parameters
    ----------
    delay_us : float or array_like
        Delay ``t_d`` in microseconds.
    exposure_us : float or array_like
        Row exposure ``t_e`` in microseconds.
    line_time_us : float, optional
        ``t_p``, the time the projector lights one scanline, in microseconds (default
        ``1e6 / lines_per_second``).
    lines_per_second : float, optional
        Projector scan rate ``v_p`` in rows per second; used only when ``line_time_us`` is None.

    Returns
    -------
    sync_offset_us : float or ndarray
        ``t'_o`` in microseconds: the time from the start of a row's exposure to the moment the projector
        lights that row.

    See Also
    --------
    delay_from_sync_offset : Eq. 1.

    Examples
    --------
    The inverse of :func:`delay_from_sync_offset`:

    >>> t_o = sync_offset_from_delay(375.0, 600.0, lines_per_second=PAPER_LINES_PER_SECOND)
    >>> float(delay_from_sync_offset(t_o, 600.0, lines_per_second=PAPER_LINES_PER_SECOND))
    375.0
    """
    t_p = _line_time_us(line_time_us, lines_per_second)
    return 0.5 * np.asarray(exposure_us, dtype=float) - 0.5 * t_p - np.asarray(delay_us, dtype=float)


def band_centre_rows(delay_us, lines_per_second):
    """Band centre ``I_d = v_p t_d`` in projector rows, Eq. 2 (``v_p`` in lines per second).

    Parameters
    ----------
    delay_us : float or array_like
        Delay ``t_d`` in microseconds.
    lines_per_second : float
        Projector scan rate ``v_p`` in rows per second.

    Returns
    -------
    float or ndarray
        ``I_d`` in projector rows (positive: below the camera row's epipolar plane).

    See Also
    --------
    band_width_rows : the band's width.
    Band : a band as an illumination.

    Examples
    --------
    >>> float(band_centre_rows(375.0, PAPER_LINES_PER_SECOND))  # 375 us at 54,000 rows/s
    20.25
    """
    return np.asarray(delay_us, dtype=float) * 1e-6 * float(lines_per_second)


def band_width_rows(exposure_us, lines_per_second):
    """Band width ``I_w = v_p t_e`` in projector rows, Eq. 2 (``v_p`` in lines per second).

    Parameters
    ----------
    exposure_us : float or array_like
        Row exposure ``t_e`` in microseconds.
    lines_per_second : float
        Projector scan rate ``v_p`` in rows per second.

    Returns
    -------
    float or ndarray
        ``I_w`` in projector rows.

    See Also
    --------
    band_centre_rows : the band's centre.

    Examples
    --------
    >>> float(band_width_rows(600.0, PAPER_LINES_PER_SECOND))  # the paper's shortest exposure
    32.4
    """
    return np.asarray(exposure_us, dtype=float) * 1e-6 * float(lines_per_second)


def illumination(offset_rows, delay_us, exposure_us, lines_per_second):
    """Continuous illumination function ``L``, Eq. 3.

    ``L(u) = 1`` where ``|u - I_d| < I_w / 2`` and 0 elsewhere, with ``u = v - t``
    the projector-row offset.  Use :func:`band_bin_weights` for its exact
    discretization on 1-row bins.

    Parameters
    ----------
    offset_rows : float or array_like
        Offsets ``u = v - t`` in projector rows.
    delay_us, exposure_us : float
        Delay ``t_d`` and exposure ``t_e`` in microseconds.
    lines_per_second : float
        Projector scan rate ``v_p`` in rows per second.

    Returns
    -------
    ndarray of float
        1 inside the band, 0 outside (the projector's full intensity is 1).

    See Also
    --------
    band_bin_weights : its exact discretization on 1-row bins.
    Band : the band with jitter and the projector's ends.

    Examples
    --------
    A 600 us band centred 375 us away lights offsets 4 to 36 (Eq. 3):

    >>> import numpy as np
    >>> illumination(np.array([0.0, 10.0, 40.0]), 375.0, 600.0, PAPER_LINES_PER_SECOND).tolist()
    [0.0, 1.0, 0.0]
    """
    centre = band_centre_rows(delay_us, lines_per_second)
    half = 0.5 * band_width_rows(exposure_us, lines_per_second)
    return (np.abs(np.asarray(offset_rows, dtype=float) - centre) < half).astype(np.float32)


# ----------------------------------------------------------------------------
# Exact bin integrals of a blurred box
# ----------------------------------------------------------------------------
def _second_antiderivative(x, sigma, width):
    """``G(x) = int_{-inf}^x CDF_K(z) dz`` of the blur kernel ``K``.

    ``K`` is a Gaussian of std ``sigma`` convolved with a centred box of width
    ``width`` (either may be zero).  The bin weight of a box ``[a, b]`` blurred by
    ``K`` over the bin ``[l, r]`` is ``G(r-a) - G(l-a) - G(r-b) + G(l-b)``.
    Far from the kernel's support ``G`` is exactly ``max(x, 0)``; using that there
    avoids cancellation between large numbers.
    """
    x = np.asarray(x, dtype=float)
    ramp = np.maximum(x, 0.0)
    if width <= 0.0 and sigma <= 0.0:
        return ramp
    if sigma <= 0.0:
        inner = (x + 0.5 * width) ** 2 / (2.0 * width)
        return np.where(x >= 0.5 * width, x, np.where(x <= -0.5 * width, 0.0, inner))

    def gauss2(y):
        z = y / sigma
        return y * ndtr(z) + sigma * np.exp(-0.5 * z * z) / np.sqrt(2.0 * np.pi)

    def third(y):
        z = y / sigma
        return 0.5 * (y * y + sigma * sigma) * ndtr(z) + 0.5 * y * sigma * np.exp(-0.5 * z * z) / np.sqrt(2.0 * np.pi)

    # Special functions only where the kernel reaches (a few bins per band edge).
    near = np.abs(x) < 0.5 * width + 10.0 * sigma
    out = ramp.copy()
    xn = x[near]
    if width <= 0.0:
        out[near] = gauss2(xn)
    else:
        out[near] = (third(xn + 0.5 * width) - third(xn - 0.5 * width)) / width
    return out


def band_bin_weights(offset_rows, centre_rows, width_rows, *, blur_sigma_rows=0.0, line_width_rows=0.0):
    """Exact weights of a (blurred) box band on 1-row offset bins, discretizing Eq. 3.

    Parameters
    ----------
    offset_rows : array_like
        Bin centres ``k`` (projector rows); the bin is ``[k - 1/2, k + 1/2)``.
    centre_rows, width_rows : array_like
        Band centre ``I_d`` and width ``I_w`` (Eq. 2), broadcast against ``offset_rows``.
    blur_sigma_rows : float
        Standard deviation of a Gaussian blur of the band edges (synchronization
        jitter ``sigma_us * v_p``).
    line_width_rows : float
        Width of a box blur of the band edges (the laser line's own width ``t_p v_p``).

    Returns
    -------
    weights : ndarray of float64
        Fraction of each bin lit by the band; they sum to ``width_rows`` over all bins.

    See Also
    --------
    illumination : the continuous band (Eq. 3).
    band_interval_weights : the same over any intervals.

    Examples
    --------
    A 600 us band at 54,000 lines/s is 32.4 rows wide; its bin weights add up to that
    width whatever its centre (here 3.7 rows below the camera row):

    >>> import numpy as np
    >>> w = band_bin_weights(np.arange(-30, 31), 3.7, band_width_rows(600.0, 54_000))
    >>> round(float(w.sum()), 6), round(float(w[30]), 6)
    (32.4, 1.0)
    """
    k = np.asarray(offset_rows, dtype=float)
    w = band_interval_weights(
        k - 0.5, k + 0.5, centre_rows, width_rows, blur_sigma_rows=blur_sigma_rows, line_width_rows=line_width_rows
    )
    return np.minimum(w, 1.0)


def band_interval_weights(lo_rows, hi_rows, centre_rows, width_rows, *, blur_sigma_rows=0.0, line_width_rows=0.0):
    """Exact integral of a (blurred) box band over intervals ``[lo, hi)`` of offsets.

    :func:`band_bin_weights` is the case ``[k - 1/2, k + 1/2)``; the part of a bin
    inside the projector (:meth:`RowGeometry.bin_parts`) is another.

    Parameters
    ----------
    lo_rows, hi_rows : array_like
        Interval ends (offsets, projector rows), ``hi >= lo``.
    centre_rows, width_rows : array_like
        Band centre ``I_d`` and width ``I_w`` (Eq. 2).
    blur_sigma_rows, line_width_rows : float
        Gaussian and box blur of the band edges (see :func:`band_bin_weights`).

    Returns
    -------
    weights : ndarray of float64
        Length of each interval lit by the band (rows); 0 below ``1e-10``.

    See Also
    --------
    band_bin_weights : over 1-row bins.

    Examples
    --------
    A one-row band centred on the camera row lights 0.75 of the interval ``[-0.25, 0.75)``:

    >>> float(band_interval_weights(-0.25, 0.75, 0.0, 1.0))
    0.75
    """
    lo_e = np.asarray(lo_rows, dtype=float)
    hi_e = np.asarray(hi_rows, dtype=float)
    c = np.asarray(centre_rows, dtype=float)
    half = 0.5 * np.asarray(width_rows, dtype=float)
    lo, hi = c - half, c + half
    # Blurs far below a row change nothing but would overflow x / sigma (or, for
    # a box narrower than 1/1000 row, lose precision dividing by its width).
    sigma = float(blur_sigma_rows) if blur_sigma_rows > 1e-6 else 0.0
    line = float(line_width_rows) if line_width_rows > 1e-3 else 0.0
    G = lambda x: _second_antiderivative(x, sigma, line)  # noqa: E731
    w = G(hi_e - lo) - G(lo_e - lo) - G(hi_e - hi) + G(lo_e - hi)
    # Differences of large numbers leave ~1e-12 noise far from the band; a weight
    # of 1e-10 of a row is far below any photon count, so it is zeroed.
    return np.where(w < 1e-10, 0.0, np.minimum(w, np.maximum(hi_e - lo_e, 0.0)))


# ----------------------------------------------------------------------------
# Geometry: camera rows in projector rows
# ----------------------------------------------------------------------------
@dataclass(frozen=True)
class RowGeometry:
    """Vertical geometry of a rectified projector-camera pair.

    Parameters
    ----------
    camera_rows : int
        Number of camera rows ``H``.
    projector_rows : int, optional
        Number of projector rows ``P`` seen by the camera; defaults to ``H``
        (one camera row per projector row).  ``P = 720, H = 128`` models the
        paper's 128x128 images of a 720-row PicoPro.

    See Also
    --------
    planeray.Transport : a transport over this geometry.

    Examples
    --------
    >>> RowGeometry(128, 720).rows_per_camera_row
    5.625
    """

    camera_rows: int
    projector_rows: int | None = None

    def __post_init__(self):
        if self.projector_rows is None:
            object.__setattr__(self, "projector_rows", int(self.camera_rows))
        check_integer(self.camera_rows, "camera_rows", minimum=1)
        check_integer(self.projector_rows, "projector_rows", minimum=1)

    @property
    def rows_per_camera_row(self) -> float:
        """Projector rows spanned by one camera row."""
        return self.projector_rows / self.camera_rows

    def projector_row_of(self, camera_row):
        """Projector coordinate ``p_t`` of the centre of camera row ``t``."""
        return (np.asarray(camera_row, dtype=float) + 0.5) * self.rows_per_camera_row - 0.5

    def row_bins(self, camera_row):
        """Where each projector row falls among the offset bins of camera row ``t`` (the one binning rule).

        Projector row ``v`` covers projector coordinates ``[v - 1/2, v + 1/2)``, i.e.
        offsets ``[x - 1/2, x + 1/2)`` with ``x = v - p_t``; offset bin ``k`` covers
        ``[k - 1/2, k + 1/2)``.  The row therefore overlaps exactly two bins: bin
        ``v + first`` by ``1 - share`` and bin ``v + first + 1`` by ``share``, with
        ``first = floor(-p_t)`` and ``share = -p_t - first``, the same for every row
        ``v`` of one camera row.  Light of row ``v`` is filed under those bins in
        those proportions (it is spread evenly over the row), so a transport's bins
        are exact integrals over their cells of the light of whole projector rows.
        ``share`` is 0 (one bin per row) when ``p_t`` is an integer, as for ``P = H``.

        Parameters
        ----------
        camera_row : int or array_like of int
            Camera row(s) ``t``.

        Returns
        -------
        first : ndarray of int64
            Offset bin of projector row 0's larger-or-equal part: ``floor(-p_t)``.
        share : ndarray of float64
            Fraction of every projector row filed under the next bin, in ``[0, 1)``.

        Examples
        --------
        The paper's 128 rows of a 720-row projector: camera row 0 sits at
        ``p_0 = 2.3125``, so projector row 3 (``x = 0.6875``) gives 0.3125 of its
        light to bin 0 and 0.6875 to bin 1:

        >>> first, share = RowGeometry(128, 720).row_bins(0)
        >>> int(first) + 3, float(1 - share), float(share)
        (0, 0.3125, 0.6875)
        """
        minus_p = -self.projector_row_of(camera_row)
        first = np.floor(minus_p)
        return first.astype(np.int64), minus_p - first

    def bin_parts(self, camera_row, offset_rows):
        """The part of each offset bin inside the projector, ``[lo, hi)`` in offsets (the edge rule).

        Eq. 4 integrates over the projector's rows only: projector coordinates
        outside ``[-1/2, P - 1/2)`` (above row 0's upper edge, below row ``P - 1``'s
        lower edge) do not exist, so no light comes from them.  Offset bin ``u`` of
        camera row ``t`` lies at projector coordinates ``p_t + [u - 1/2, u + 1/2)``;
        its part inside the projector is ``[lo, hi)`` (``hi = lo`` for a bin wholly
        outside).  A transport's bin holds the light of that part, spread evenly
        over it, and an illumination lights a bin in proportion to the fraction of
        that part it covers (:meth:`Band.weights`, :meth:`RowPattern.weights`): a
        bin straddling the edge is as bright under full illumination as its light,
        and a bin wholly outside holds no light and gets weight 0.

        Returns
        -------
        lo, hi : ndarray of float64
            Broadcast over ``camera_row`` and ``offset_rows``.
        """
        p_t = self.projector_row_of(camera_row)
        u = np.asarray(offset_rows, dtype=float)
        lo = np.maximum(u - 0.5, -0.5 - p_t)
        hi = np.maximum(np.minimum(u + 0.5, self.projector_rows - 0.5 - p_t), lo)
        return lo, hi

    def coverage(self, camera_row, offset_rows):
        """Fraction of offset bin ``[u - 1/2, u + 1/2)`` of row ``t`` inside the projector (see :meth:`bin_parts`).

        Rows near the top and bottom of the image have fewer valid offsets.
        """
        lo, hi = self.bin_parts(camera_row, offset_rows)
        return hi - lo


def _fraction_of_part(lit, lo, hi):
    """``lit / (hi - lo)``: the fraction of each bin's part inside the projector that is lit (0 where none is)."""
    inside = hi - lo
    return np.where(inside > 1e-9, np.minimum(lit / np.where(inside > 1e-9, inside, 1.0), 1.0), 0.0)


# ----------------------------------------------------------------------------
# Illuminations: anything with ``weights(geometry, rows, offsets)``
# ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Band:
    """The band of projector rows seen by a camera row for one (delay, exposure).

    ``weights`` discretizes Eq. 3 on offset bins, blurred by synchronization jitter
    (Gaussian, ``jitter_us``) and the laser line's width (box, ``line_width_us``),
    and clipped to the projector.  ``row_shifts_rows`` (``(F, H)``) optionally holds
    a realized per-frame, per-row trigger offset in projector rows; the weights are
    then the average over the ``F`` frames -- this is what produces horizontal row
    artifacts when a band edge sits on the epipolar plane (``|t_d| ~ t_e/2``).

    Parameters
    ----------
    delay_us : float
        Synchronization delay ``t_d`` in microseconds.
    exposure_us : float
        Row exposure ``t_e`` in microseconds (> 0).
    lines_per_second : float
        Projector scan rate ``v_p`` in rows per second (Eq. 2).
    jitter_us : float
        Standard deviation of the synchronization jitter, microseconds.
    line_width_us : float
        Width of the laser line in scan time, microseconds.
    row_shifts_rows : ndarray (F, H), optional
        Realized per-frame, per-row trigger offsets in projector rows.

    See Also
    --------
    planeray.band_image : the image of a band.
    Sweep : one band per image.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Eqs. 2-3.

    Examples
    --------
    The paper's scan rate turns microseconds into projector rows (Eq. 2):

    >>> band = Band(delay_us=375.0, exposure_us=600.0)
    >>> band.centre_rows, band.width_rows
    (20.25, 32.4)
    """

    delay_us: float
    exposure_us: float
    lines_per_second: float = PAPER_LINES_PER_SECOND
    jitter_us: float = 0.0
    line_width_us: float = 0.0
    row_shifts_rows: np.ndarray | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        check_number(self.delay_us, "delay_us")
        check_positive(self.exposure_us, "exposure_us")
        check_positive(self.lines_per_second, "lines_per_second")
        check_nonnegative(self.jitter_us, "jitter_us")
        check_nonnegative(self.line_width_us, "line_width_us")

    @property
    def centre_rows(self) -> float:
        return float(band_centre_rows(self.delay_us, self.lines_per_second))

    @property
    def width_rows(self) -> float:
        return float(band_width_rows(self.exposure_us, self.lines_per_second))

    @property
    def blur_sigma_rows(self) -> float:
        """The Gaussian blur of the band edges (synchronization jitter), in projector rows."""
        return self.jitter_us * 1e-6 * self.lines_per_second

    @property
    def line_width_rows(self) -> float:
        """The box blur of the band edges (the laser line's own width), in projector rows."""
        return self.line_width_us * 1e-6 * self.lines_per_second

    def profile(self, offsets_rows, centre_shift_rows=0.0) -> np.ndarray:
        """Weights over offset bins before clipping to the projector (same for every row)."""
        return band_bin_weights(
            offsets_rows,
            self.centre_rows + centre_shift_rows,
            self.width_rows,
            blur_sigma_rows=self.blur_sigma_rows,
            line_width_rows=self.line_width_rows,
        )

    def weights(self, geometry: RowGeometry, rows, offsets_rows) -> np.ndarray:
        """Illumination weight of offset bin ``offsets_rows`` for camera row ``rows`` (broadcast).

        The fraction of the bin's part inside the projector that the band lights
        (:meth:`RowGeometry.bin_parts`: the edge rule); for a bin wholly inside, the
        exact integral of the band over it (:func:`band_bin_weights`).  With realized
        ``row_shifts_rows`` the weights are integrated once per process for each band,
        geometry, rows and offsets and kept (:data:`WEIGHTS_CACHE_BYTES`); every call
        returns a new array of the caller's own.
        """
        rows = np.asarray(rows)
        if self.row_shifts_rows is not None:
            # Exact repeats are common (the same sweep and seed on another scene of the same
            # geometry: the shifts are drawn per delay and exposure, not per scene): computed once.
            key = self._jittered_key(geometry, rows, offsets_rows)
            kept = _kept_jittered(key)
            if kept is None:
                kept = _keep_jittered(key, self._jittered_weights(geometry, rows, offsets_rows))
            return kept.copy()
        # the same profile for every row, recomputed only on the bins that straddle the projector's edge
        lo, hi = geometry.bin_parts(rows, offsets_rows)
        w = np.array(np.broadcast_to(self.profile(offsets_rows), lo.shape), dtype=np.float64)
        edge = hi - lo < 1.0 - 1e-12
        if edge.any():
            a, b = lo[edge], hi[edge]
            w[edge] = _fraction_of_part(self._lit(0.0, a, b), a, b)
        return w

    def _lit(self, shift, a, b):
        """The band, its centre moved by ``shift`` (rows), integrated over the intervals ``[a, b)``."""
        c = self.centre_rows + shift
        return band_interval_weights(
            a, b, c, self.width_rows, blur_sigma_rows=self.blur_sigma_rows, line_width_rows=self.line_width_rows
        )

    def _jittered_key(self, geometry: RowGeometry, rows, offsets_rows) -> tuple:
        """What the weights with realized row shifts are a function of (the shifts, rows and offsets by their bytes)."""
        digest = hashlib.blake2b(digest_size=16)
        for a in (self.row_shifts_rows, rows, offsets_rows):
            a = np.ascontiguousarray(a)
            digest.update(f"{a.dtype.str}{a.shape};".encode())
            digest.update(a)
        fields = (self.delay_us, self.exposure_us, self.lines_per_second, self.jitter_us, self.line_width_us)
        return (*map(float, fields), geometry.camera_rows, geometry.projector_rows, digest.hexdigest())

    def _jittered_weights(self, geometry: RowGeometry, rows, offsets_rows) -> np.ndarray:
        """:meth:`weights` averaged over the frames of ``row_shifts_rows`` (computed, never kept)."""
        lo, hi = geometry.bin_parts(rows, offsets_rows)
        shifts = np.asarray(self.row_shifts_rows, dtype=float)
        # Only bins within reach of the band (half its width, the blurs' reach in
        # _second_antiderivative, the largest shift, one bin) can be lit: the integral
        # is exactly 0 beyond it (below the 1e-10 floor), so it is evaluated there only.
        reach = 0.5 * self.width_rows + 10.0 * self.blur_sigma_rows + self.line_width_rows + 1.0
        rows_b = np.broadcast_to(rows, lo.shape)
        near = (hi > self.centre_rows + shifts.min(initial=0.0) - reach) & (
            lo < self.centre_rows + shifts.max(initial=0.0) + reach
        )
        a, b, r = lo[near], hi[near], rows_b[near]
        acc = 0.0
        for frame in self._lit(shifts[:, r], a, b):  # every frame at once, summed in frame order
            acc = acc + frame
        w = np.zeros(lo.shape)
        w[near] = _fraction_of_part(acc / len(shifts), a, b)
        return w


#: Memory (bytes) of the jittered band weights a process keeps for later renders of the same band (the
#: same realized row shifts) on the same geometry; the least recently used go first.  A 256-row paper
#: sweep image's weights are 0.5 MB (256 rows x 229 offsets, float64): a sweep of 85 images 40 MB.
WEIGHTS_CACHE_BYTES = 128 * 2**20
_JITTERED: OrderedDict = OrderedDict()
_JITTERED_LOCK = threading.Lock()
_jittered_bytes = 0


def _kept_jittered(key: tuple) -> np.ndarray | None:
    """The weights kept under ``key`` (now the most recently used), or None."""
    with _JITTERED_LOCK:
        w = _JITTERED.get(key)
        if w is not None:
            _JITTERED.move_to_end(key)
        return w


def _keep_jittered(key: tuple, w: np.ndarray) -> np.ndarray:
    """Keep ``w`` (read-only) under ``key``, dropping the least recently used beyond :data:`WEIGHTS_CACHE_BYTES`."""
    global _jittered_bytes
    w.setflags(write=False)
    with _JITTERED_LOCK:
        if key not in _JITTERED:
            _JITTERED[key] = w
            _jittered_bytes += w.nbytes
            while len(_JITTERED) > 1 and _jittered_bytes > WEIGHTS_CACHE_BYTES:
                _jittered_bytes -= _JITTERED.popitem(last=False)[1].nbytes
        return _JITTERED[key]


def band_weights_at_row(bands, geometry: RowGeometry, camera_row: int, offsets_rows, *, profile=None) -> np.ndarray:
    """:meth:`Band.weights` of many bands at one camera row, ``(N, U)``, in one vectorized pass.

    The same numbers as ``np.stack([b.weights(geometry, camera_row, offsets_rows) for b in bands])``
    (each band's profile once, the bins the projector's end cuts recomputed by the edge rule), at a
    fraction of the cost: a demultiplexing problem needs them for every row group of a stack.
    Bands with realized row shifts, or with different blurs, are computed band by band.

    Parameters
    ----------
    bands : sequence of Band
    geometry : RowGeometry
    camera_row : int
        Camera row ``t``.
    offsets_rows : array_like of int, shape (U,)
        Offset bins ``u = v - t`` (projector rows).
    profile : ndarray (N, U), optional
        The bands' common profile on these offsets (``[b.profile(offsets_rows) for b in bands]``), when
        the caller has it already (a demultiplexing problem: one for all its row groups); only the bins
        the projector's end cuts are then computed here.

    Returns
    -------
    weights : ndarray (N, U) float64

    See Also
    --------
    Band.weights : one band at many rows.

    Examples
    --------
    >>> import numpy as np
    >>> bands = quick_sweep().bands(PAPER_LINES_PER_SECOND)
    >>> band_weights_at_row(bands, RowGeometry(64, 720), 32, np.arange(-114, 115)).shape
    (27, 229)
    """
    bands = list(bands)
    offsets = np.asarray(offsets_rows)
    if not bands:
        return np.zeros((0, offsets.size))
    blur = {(b.blur_sigma_rows, b.line_width_rows) for b in bands}
    if len(blur) > 1 or any(b.row_shifts_rows is not None for b in bands):
        return np.stack([b.weights(geometry, camera_row, offsets) for b in bands])
    ((sigma, line),) = blur
    centre = np.array([b.centre_rows for b in bands])[:, None]
    width = np.array([b.width_rows for b in bands])[:, None]
    if profile is not None:
        w = np.array(profile, dtype=np.float64)
    else:
        k = offsets.astype(float)[None, :]
        w = np.minimum(
            band_interval_weights(k - 0.5, k + 0.5, centre, width, blur_sigma_rows=sigma, line_width_rows=line), 1.0
        )
    lo, hi = geometry.bin_parts(camera_row, offsets)
    edge = hi - lo < 1.0 - 1e-12
    if edge.any():
        a, b = lo[edge][None, :], hi[edge][None, :]
        lit = band_interval_weights(a, b, centre, width, blur_sigma_rows=sigma, line_width_rows=line)
        w[:, edge] = _fraction_of_part(lit, a, b)
    return w


@dataclass(frozen=True)
class RowPattern:
    """Any illumination given as an intensity per projector row (relighting, Sec. 9).

    ``pattern`` has one value per projector row ``v = 0 .. P-1``; the weight of an
    offset bin is the exact average of the piecewise-constant pattern over the
    bin's part inside the projector (:meth:`RowGeometry.bin_parts`).

    Parameters
    ----------
    pattern : ndarray (P,)
        Intensity of each projector row (1 = full intensity).

    See Also
    --------
    planeray.relight : the image under a pattern.
    Band : a (delay, exposure) illumination.

    Examples
    --------
    >>> import numpy as np
    >>> w = RowPattern(np.ones(4)).weights(RowGeometry(4), np.arange(4)[:, None], np.array([-1, 0, 1]))
    >>> w.tolist()[0]  # the row above row 0 is off the projector
    [0.0, 1.0, 1.0]
    """

    pattern: np.ndarray

    def weights(self, geometry: RowGeometry, rows, offsets_rows) -> np.ndarray:
        p = np.asarray(self.pattern, dtype=float).ravel()
        if p.size != geometry.projector_rows:
            raise ValueError(f"pattern has {p.size} rows, projector has {geometry.projector_rows}")
        edges = np.concatenate([[0.0], np.cumsum(p)])  # integral up to projector coordinate x - 1/2
        lo, hi = geometry.bin_parts(rows, offsets_rows)
        p_t = geometry.projector_row_of(rows)
        cum = lambda x: np.interp(x + 0.5, np.arange(p.size + 1), edges)  # noqa: E731
        inside = hi - lo
        mean = (cum(p_t + hi) - cum(p_t + lo)) / np.where(inside > 1e-9, inside, 1.0)
        return np.where(inside > 1e-9, mean, 0.0)


# ----------------------------------------------------------------------------
# Sweeps
# ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Sweep:
    """A delay-exposure sweep: one (delay, exposure) per image, plus exclusion flags.

    ``excluded`` marks the images that sit on the epipolar/non-epipolar boundary
    (``||t_d| - t_e/2| <= boundary_margin_us``); they are captured and stored but
    left out of demultiplexing (Sec. 4).  ``record`` holds what a sweep file says about
    where the sweep came from (a designed sweep: its prior, camera and criterion;
    :func:`planeray.io.read_sweep`), or None.

    Parameters
    ----------
    delay_us, exposure_us : ndarray (N,)
        Delay ``t_d`` and exposure ``t_e`` of each image, microseconds.
    excluded : ndarray of bool (N,)
        Images left out of demultiplexing.
    name : str
        A name for the record (``"paper"``, ``"quick"``, ``"custom"``).
    record : dict, optional
        Where the sweep came from (a sweep file's record).

    See Also
    --------
    paper_sweep, quick_sweep, make_sweep
    Sweep.grid : every delay at every exposure.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 4.

    Examples
    --------
    >>> sweep = Sweep.grid([-750.0, 0.0, 750.0], [600.0])
    >>> len(sweep), sweep.excluded.tolist()
    (3, [False, False, False])
    """

    delay_us: np.ndarray
    exposure_us: np.ndarray
    excluded: np.ndarray
    name: str = "custom"
    record: dict | None = field(default=None, compare=False)

    def __post_init__(self):
        d = np.asarray(self.delay_us, dtype=float).ravel()
        e = np.asarray(self.exposure_us, dtype=float).ravel()
        x = np.asarray(self.excluded, dtype=bool).ravel()
        if not (d.shape == e.shape == x.shape):
            raise ValueError("delay_us, exposure_us and excluded must have one entry per image")
        if np.any(e <= 0):
            raise ValueError("exposures must be positive")
        object.__setattr__(self, "delay_us", d)
        object.__setattr__(self, "exposure_us", e)
        object.__setattr__(self, "excluded", x)

    def __len__(self) -> int:
        return self.delay_us.size

    @classmethod
    def grid(cls, delays_us, exposures_us, *, boundary_margin_us=PAPER_BOUNDARY_MARGIN_US, name="custom"):
        """Every delay at every exposure, exposure-major (rows of the Fig. 8 contact sheet)."""
        e, d = np.meshgrid(np.asarray(exposures_us, float), np.asarray(delays_us, float), indexing="ij")
        d, e = d.ravel(), e.ravel()
        return cls(d, e, boundary_images(d, e, margin_us=boundary_margin_us), name=name)

    def bands(self, lines_per_second, *, jitter_us=0.0, line_width_us=0.0):
        """One :class:`Band` per image."""
        return [
            Band(float(d), float(e), lines_per_second, jitter_us, line_width_us)
            for d, e in zip(self.delay_us, self.exposure_us)
        ]


def boundary_images(delay_us, exposure_us, *, margin_us=PAPER_BOUNDARY_MARGIN_US):
    """Flag images whose band edge sits on the epipolar plane: ``||t_d| - t_e/2| <= margin``.

    Parameters
    ----------
    delay_us, exposure_us : array_like
        Delay ``t_d`` and exposure ``t_e`` of each image, microseconds.
    margin_us : float
        How close (microseconds) a band edge may come to the epipolar plane (the paper: 75).

    Returns
    -------
    ndarray of bool
        True for the images left out of demultiplexing.

    See Also
    --------
    Sweep : its ``excluded`` flags.

    Examples
    --------
    A band whose edge is on the epipolar plane (``|t_d| = t_e / 2``) is a boundary image:

    >>> boundary_images([0.0, 300.0, 750.0], [600.0, 600.0, 600.0]).tolist()
    [False, True, False]
    """
    d = np.asarray(delay_us, dtype=float)
    e = np.asarray(exposure_us, dtype=float)
    return np.abs(np.abs(d) - 0.5 * e) <= margin_us + 1e-9


def paper_sweep() -> Sweep:
    """The paper's sweep (Sec. 6): delays -1500..1500 us step 187.5 (17) x exposures
    600..1200 us step 150 (5) = 85 images, 10 boundary images flagged -> N = 75.

    Returns
    -------
    Sweep
        85 (delay, exposure) settings in microseconds, exposure-major (the rows of Fig. 8).

    See Also
    --------
    quick_sweep : 27 images for quick looks.
    Sweep.grid : any grid of delays and exposures.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 6.

    Examples
    --------
    >>> sweep = paper_sweep()
    >>> len(sweep), int(sweep.excluded.sum())
    (85, 10)
    >>> sweep_support_rows(sweep, PAPER_LINES_PER_SECOND)
    114
    """
    return Sweep.grid(np.arange(-8, 9) * 187.5, np.arange(600.0, 1201.0, 150.0), name="paper")


def quick_sweep() -> Sweep:
    """A small sweep for quick looks and tests: 9 delays x 3 exposures.

    Delays -1500..1500 us in steps of 375 us, exposures 600, 900 and 1200 us; the
    boundary images (band edge on the epipolar plane) are flagged as in
    :func:`paper_sweep`.

    Returns
    -------
    Sweep
        27 (delay, exposure) settings in microseconds.

    See Also
    --------
    paper_sweep : the paper's 85-image sweep.
    make_sweep : a named sweep.

    Examples
    --------
    >>> sweep = quick_sweep()
    >>> len(sweep), int(sweep.excluded.sum()), sweep.name
    (27, 4, 'quick')
    """
    return Sweep.grid(np.arange(-4, 5) * 375.0, np.array([600.0, 900.0, 1200.0]), name="quick")


#: Named sweeps, chosen by name on the command line (``--sweep paper``).
SWEEPS = {"paper": paper_sweep, "quick": quick_sweep}


def make_sweep(name: str) -> Sweep:
    """A named sweep of :data:`SWEEPS` (what ``--sweep NAME`` of the command line takes).

    Parameters
    ----------
    name : {'paper', 'quick'}
        ``"paper"``: the paper's 85 images (Sec. 6); ``"quick"``: 27 images.

    Returns
    -------
    Sweep
        The (delay, exposure) settings in microseconds.

    Raises
    ------
    ValueError
        An unknown name (the message lists the known ones).

    See Also
    --------
    paper_sweep, quick_sweep
    planeray.io.read_sweep : a sweep from a file.

    Examples
    --------
    >>> len(make_sweep("paper")), len(make_sweep("quick"))
    (85, 27)
    """
    try:
        return SWEEPS[name]()
    except KeyError:
        raise ValueError(f"unknown sweep {name!r}; choose one of {sorted(SWEEPS)}") from None


def sweep_support_rows(sweep: Sweep, lines_per_second, *, include_excluded=False) -> int:
    """Half-width ``K`` of the offset support ``-K..K`` reached by a sweep's bands:
    ``max |I_d| + I_w / 2`` rounded up (114 rows -> 229 offsets for the paper's sweep).

    Parameters
    ----------
    sweep : Sweep
        The (delay, exposure) settings, microseconds.
    lines_per_second : float
        Projector scan rate ``v_p`` in rows per second.
    include_excluded : bool
        Count the boundary images too (default: only the images demultiplexing uses).

    Returns
    -------
    int
        ``K``: the demultiplexer's unknowns are the offsets ``-K..K`` (projector rows).

    See Also
    --------
    paper_sweep : 114 rows for the paper's sweep.

    Examples
    --------
    >>> sweep_support_rows(quick_sweep(), PAPER_LINES_PER_SECOND)
    114
    """
    keep = np.ones(len(sweep), bool) if include_excluded else ~sweep.excluded
    reach = np.abs(band_centre_rows(sweep.delay_us[keep], lines_per_second)) + 0.5 * band_width_rows(
        sweep.exposure_us[keep], lines_per_second
    )
    return int(np.ceil(reach.max() - 1e-9))
