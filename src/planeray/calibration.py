"""Calibration of the synchronized projector-camera (Sec. 6), with its own uncertainty.

Two quantities make the imaging model of Eqs. 1-3 true to a device:

* the **projector scanline velocity** ``v_p`` (lines per second), which turns
  delay and exposure into band centre and width, ``I_d = v_p t_d`` and
  ``I_w = v_p t_e`` (Eq. 2).  The paper measures it by projecting a single-pixel
  horizontal line, sweeping it down the projector, imaging the sweep with a
  *global-shutter* exposure of ``t_e = 500 us`` and counting the visible lines:
  ``v_p = n_v / t_e`` ("27 lines in 500 us: 54,000 lines/s", Sec. 6).
  :func:`count_lines` and :func:`calibrate_lines_per_second` do that counting to
  a fraction of a line (noise, blur, uneven brightness, partially exposed end
  lines), and report a 1-sigma uncertainty;
* the **delay zero**: the commanded delay at which the camera row really sees its
  own epipolar plane (``t_d = 0``), i.e. the synchronization offset ``t'_o`` of
  Eq. 1 measured instead of assumed.  :func:`calibrate_delay_zero` sweeps the delay
  finely on a diffuse target and finds the centre of the epipolar response.

:func:`write_calibration` stores the results in a capture folder's
``acquisition.json`` (the field ``lines_per_second`` that the stack import
requires, plus the uncertainties and the delay zero), keeping every other field.

The line-sweep design
---------------------
Adjacent projector rows lit during one exposure form one continuous band: the
paper's 27 lines are countable only because they are imaged one at a time.  A
:class:`LineSweep` therefore lights a *comb* of projector rows ``k`` apart
(``line_step_rows``), so that the lines one image shows are separated by
``k`` projector rows, and sweeps the comb through its ``k`` phases (the paper's
single swept line is the comb with ``k = P``).  All images use the same
VSYNC-triggered exposure window, so together the ``k`` phases light every
projector row once and the fractional line counts of the phases add up to exactly
the ``v_p t_e`` rows scanned during the exposure, whatever the (unknown,
fractional) phase of the window relative to the raster.  A single image of a
comb (or the paper's single image with ``k = 1``) is also accepted; it cannot tell
where inside a dark gap between two lines the window ended, and its uncertainty
says so.

Optional reference frames make the counting independent of the target: a
**dark** frame (laser off, same exposure: the ambient background) and a
**flat** frame (every row lit, an exposure that covers the window with margins:
the per-pixel response to one full line, including the target's texture and the
projector's falloff).  Without them the background and the brightness scale are
estimated robustly from the image itself.

References
----------
.. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa,
   S. G. Narasimhan, "Programmable Non-Epipolar Indirect Light Transport:
   Capture and Analysis", IEEE TVCG 27(4), 2021, Sec. 6 (Calibration).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .errors import InputError
from .timing import PAPER_LINES_PER_SECOND, Sweep, sync_offset_from_delay

__all__ = [
    "PAPER_CALIBRATION_EXPOSURE_US",
    "LineSweep",
    "LineCount",
    "LineCalibration",
    "DelayZeroCalibration",
    "count_lines",
    "calibrate_lines_per_second",
    "calibrate_delay_zero",
    "delay_zero_sweep",
    "device_capture",
    "read_line_sweep",
    "write_line_sweep",
    "write_calibration",
]

#: Global-shutter exposure of the paper's line-velocity calibration (Sec. 6).
PAPER_CALIBRATION_EXPOSURE_US = 500.0

_MAD = 1.482602218505602  # MAD -> standard deviation of a normal distribution


# ============================================================================
# Line sweep: the calibration images
# ============================================================================
@dataclass
class LineSweep:
    """Global-shutter images of a swept line comb, the input of the ``v_p`` calibration.

    Parameters
    ----------
    images : array_like, shape (n, H, W) or (H, W)
        One image per comb phase (any linear units; normalized images of the
        camera model, raw codes...).
    exposure_us : float
        Global-shutter exposure ``t_e`` of every image (the paper: 500 us).
    line_step_rows : int
        ``k``: the lit projector rows of one image are ``k`` rows apart
        (1: every row, the paper's single image).
    phases : sequence of int, optional
        Comb phase (lit rows ``v = phase mod k``) of each image.  ``None``: the
        images are the ``k`` distinct phases if there are ``k`` of them.
    dark : array_like (H, W), optional
        Laser off, same exposure: the ambient background to subtract.
    flat : array_like (H, W), optional
        Every projector row lit, exposure ``flat_exposure_us`` covering the
        lines' window with margins: the per-pixel response to one full line.
    flat_exposure_us : float, optional
        Exposure of ``flat``; its ambient background is ``dark`` scaled by
        ``flat_exposure_us / exposure_us``.
    saturated : array_like of bool (n, H, W), optional
    timing_jitter_us : float
        RMS error of the exposure window's position in one (frame-averaged)
        image, e.g. trigger jitter / sqrt(frames averaged); enters the uncertainty.
    metadata : dict
        Free-form, JSON-serializable (device description, truth of a simulation).
    """

    images: np.ndarray
    exposure_us: float = PAPER_CALIBRATION_EXPOSURE_US
    line_step_rows: int = 1
    phases: tuple | None = None
    dark: np.ndarray | None = None
    flat: np.ndarray | None = None
    flat_exposure_us: float | None = None
    saturated: np.ndarray | None = None
    timing_jitter_us: float = 0.0
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        images = np.asarray(self.images)
        if images.ndim == 2:
            images = images[None]
        if images.ndim != 3 or images.shape[0] < 1:
            raise InputError(f"line-sweep images must be (H, W) or (n, H, W), got shape {images.shape}")
        self.images = images
        if not (np.isfinite(self.exposure_us) and self.exposure_us > 0):
            raise InputError(f"exposure_us must be a positive number, got {self.exposure_us!r}")
        self.exposure_us = float(self.exposure_us)
        if int(self.line_step_rows) != self.line_step_rows or self.line_step_rows < 1:
            raise InputError(f"line_step_rows must be a positive integer, got {self.line_step_rows!r}")
        self.line_step_rows = int(self.line_step_rows)
        if self.phases is not None:
            phases = tuple(int(p) for p in self.phases)
            if len(phases) != images.shape[0]:
                raise InputError(f"{len(phases)} phases for {images.shape[0]} images")
            self.phases = phases
        if self.flat is not None and self.flat_exposure_us is None:
            raise InputError("flat needs flat_exposure_us (to scale the dark frame to it)")
        if not (np.isfinite(self.timing_jitter_us) and self.timing_jitter_us >= 0):
            raise InputError(f"timing_jitter_us must be >= 0, got {self.timing_jitter_us!r}")

    @property
    def complete(self) -> bool:
        """True when the images are all ``k`` phases of the comb, each once."""
        k = self.line_step_rows
        if self.phases is None:
            return self.images.shape[0] == k
        return sorted(p % k for p in self.phases) == list(range(k))

    def flat_field(self) -> np.ndarray | None:
        """The flat frame minus its ambient background (the dark frame scaled to its exposure)."""
        if self.flat is None:
            return None
        flat = np.asarray(self.flat, dtype=np.float64)
        if self.dark is None:
            return flat - np.percentile(flat, 5, axis=0)[None, :]
        return flat - np.asarray(self.dark, dtype=np.float64) * (self.flat_exposure_us / self.exposure_us)


# ============================================================================
# Counting lines
# ============================================================================
@dataclass
class LineCount:
    """Lines found in one global-shutter image (:func:`count_lines`).

    Candidates are the detected lines plus one expected position beyond each end
    (a faint, barely exposed line is counted even if it is not detected).

    Attributes
    ----------
    positions_rows : ndarray
        Camera-row coordinate of each candidate (a regular grid fitted to the peaks).
    index : ndarray of int
        Grid index of each candidate (consecutive).
    areas : ndarray
        Integrated (background-subtracted, flat-fielded) profile over each line's cell.
    fractions : ndarray
        Exposed fraction of each candidate: area over the full-line area at its
        position (a trend fitted to the interior lines).  Measured for the end
        lines, the candidates beyond them and the ends' interior neighbours; 1 for
        the other interior lines, which are fully exposed by construction (the
        exposure window is contiguous).
    detected, interior : ndarray of bool
    spacing_rows : float
        Line spacing in camera rows.
    fraction_sigma : float
        1-sigma error of one end line's fraction (per-line area scatter).
    count : float
        Fractional number of lit lines: interior lines + the end fractions.
    count_uncertainty : float
        1-sigma of ``count``.
    truncated : bool
        The lines may continue beyond the image border.
    noise_rows : float
        Robust noise of the row profile (profile units).
    """

    positions_rows: np.ndarray
    index: np.ndarray
    areas: np.ndarray
    fractions: np.ndarray
    detected: np.ndarray
    interior: np.ndarray
    spacing_rows: float
    fraction_sigma: float
    count: float
    count_uncertainty: float
    truncated: bool
    noise_rows: float

    @property
    def n_detected(self) -> int:
        return int(self.detected.sum())

    def _end(self, first: bool):
        """Fractions of (outermost detected line, candidate beyond it) at one end."""
        det = np.flatnonzero(self.detected)
        i = det[0] if first else det[-1]
        j = i - 1 if first else i + 1
        m = i + 1 if first else i - 1  # the interior neighbour: its deficit is light blurred into the end cells
        beyond = float(self.fractions[j]) if 0 <= j < self.fractions.size and not self.detected[j] else None
        return float(self.fractions[i] + (self.fractions[m] - 1.0)), beyond

    def window_rows(self, rows_per_line: int = 1) -> tuple[float, float]:
        """Length of the exposure window in projector rows, from this image alone.

        With lit rows ``k = rows_per_line`` apart, the window ends ``d`` rows past
        the centre of the outermost lit line at each end: a partially exposed line
        has fraction ``d + 1/2``, and a fully exposed one says only that the window
        ended somewhere in the dark gap that follows (``1/2 <= d < k - 1/2``).  The
        posterior mean and spread of ``d`` under a uniform prior, given the
        measured fractions of the outermost line and of the candidate beyond it,
        give ``n = k (i_last - i_first) + d_first + d_last``.

        Returns
        -------
        rows, sigma : float
            Window length ``v_p t_e`` in projector rows and its 1-sigma.
        """
        k = int(rows_per_line)
        det = np.flatnonzero(self.detected)
        span = k * float(self.index[det[-1]] - self.index[det[0]])
        total, var = span, 0.0
        sf = max(self.fraction_sigma, 1e-3)
        d = np.linspace(-0.5, 2 * k - 0.5, 4001)
        for first in (True, False):
            f0, f1 = self._end(first)
            resid = (np.clip(d + 0.5, 0, 1) - f0) ** 2
            if f1 is not None:
                resid = resid + (np.clip(d + 0.5 - k, 0, 1) - f1) ** 2
            w = np.exp(-0.5 * (resid - resid.min()) / sf**2)
            w /= w.sum()
            mean = float((w * d).sum())
            total += mean
            var += float((w * (d - mean) ** 2).sum())
        return total, math.sqrt(var)


def _check_image(a, name: str, shape=None) -> np.ndarray:
    try:
        a = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} is not a numeric array ({exc})") from None
    if a.ndim != 2:
        raise InputError(f"{name} must be a 2-D image, got shape {a.shape}")
    if shape is not None and a.shape != tuple(shape):
        raise InputError(f"{name} has shape {a.shape}, the image has {tuple(shape)}")
    if a.shape[0] < 8 or a.shape[1] < 1:
        raise InputError(f"{name} is too small ({a.shape[0]}x{a.shape[1]}; need at least 8 rows)")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name} contains NaN or infinite values")
    return a


def _row_profile(sig: np.ndarray, flat: np.ndarray | None):
    """Robust row profile of a background-subtracted image, and its per-row noise.

    With a flat field the profile is the ratio of the row sums of signal and flat
    (the exposed fraction of each camera row, texture and falloff divided out, each
    pixel weighted by its brightness).  Without one each column is normalized by
    its own brightness and the profile is the median over columns (horizontal
    unevenness; smooth vertical unevenness is left to the per-line trend).
    """
    H, W = sig.shape
    if flat is not None:
        fsum = flat.sum(axis=1)
        top = fsum.max()
        if not top > 0:
            raise InputError("the flat frame is blank (no light above its dark level)")
        ref = np.median(fsum[fsum >= 0.5 * top])
        denom = np.maximum(fsum, 0.25 * ref)
        q = sig.sum(axis=1) / denom
        resid = sig - q[:, None] * flat
        s_px = _MAD * np.median(np.abs(resid - np.median(resid, axis=1, keepdims=True)), axis=1)
        return q, s_px * math.sqrt(W) / denom
    scale = np.percentile(sig, 95, axis=0)
    good = scale > 0.1 * max(np.median(scale), 0.0)
    if good.sum() < 1 or not np.any(scale > 0):
        raise InputError("no lit lines found: the image is blank (no light above its background)")
    n = sig[:, good] / scale[good]
    q = np.median(n, axis=1)
    s_px = _MAD * np.median(np.abs(n - q[:, None]), axis=1)
    return q, 1.2533 * s_px / math.sqrt(max(int(good.sum()), 1))


def _detect(q: np.ndarray, sigma: np.ndarray):
    """Peaks of the row profile, each at least 5 local noise sigmas prominent.

    Two passes: the strong lines give the spacing (minimum peak distance), then
    every line is found.  The threshold is relative to the noise of the row the
    peak sits on (rows outside the flat's reach are much noisier), floored at 4 %
    and capped at 30 % of the brightest line.  Peaks are then grouped into runs
    with gaps of at most two spacings (one missing line); the longest run is the
    lit window, anything else (a noise peak far off) is dropped.
    """
    from scipy.ndimage import maximum_filter1d, median_filter
    from scipy.signal import find_peaks

    smooth = median_filter(q, 3, mode="nearest")
    height = float(smooth.max())
    local = maximum_filter1d(sigma, 5, mode="nearest")
    noise = float(np.median(sigma))
    if not height > 0 or not height > 5.0 * float(local[int(np.argmax(smooth))]):
        raise InputError("no lit lines found: the image is blank or pure noise")
    floor, cap = 0.04 * height, 0.3 * height
    strong, _ = find_peaks(q, prominence=cap)
    distance = max(1.0, 0.6 * float(np.median(np.diff(strong)))) if strong.size >= 2 else 2.0
    peaks, props = find_peaks(q, prominence=floor, distance=distance)
    need = np.minimum(np.maximum(5.0 * local[peaks], floor), cap)
    peaks = peaks[props["prominences"] >= need]
    if peaks.size >= 3:
        s = float(np.median(np.diff(peaks)))
        breaks = np.flatnonzero(np.diff(peaks) > 2.5 * s)
        runs = np.split(peaks, breaks + 1)
        peaks = max(runs, key=len)
    return peaks, noise


def _cumulative(q: np.ndarray):
    """``C(x)``: integral of the piecewise-constant row profile from the top edge to ``x``."""
    edges = np.arange(q.size + 1) - 0.5
    cum = np.concatenate([[0.0], np.cumsum(q)])
    return lambda x: np.interp(x, edges, cum)


def _robust_trend(x, y):
    """Least-squares polynomial trend of ``y(x)`` after rejecting outliers beyond 4 robust sigmas.

    Degree 2 with at least 10 points (a vignetting-like falloff), 1 with at least
    3, else a constant.  Least squares (not a median fit) on purpose: line areas
    can be two-valued (texture beating with the line spacing), where a median picks
    one of the values instead of their mean.  Returns ``(coefficients for
    np.polyval, residuals of the kept points)``.
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    keep = np.ones(x.size, bool)
    for _ in range(3):
        n = int(keep.sum())
        deg = 2 if n >= 10 else 1 if n >= 3 else 0
        coef = np.polyfit(x[keep], y[keep], deg)
        r = y - np.polyval(coef, x)
        # interquartile scale: unlike the MAD it does not collapse on two-valued data
        q1, q2, q3 = np.percentile(r[keep], [25, 50, 75])
        s = (q3 - q1) / 1.349
        if s <= 0:
            break
        new = np.abs(r - q2) <= 4.0 * s
        if new.sum() < 2 or np.array_equal(new, keep):
            break
        keep = new
    return coef, r[keep]


def count_lines(image, *, dark=None, flat=None) -> LineCount:
    """Detect and count the lit lines of a global-shutter calibration image (Sec. 6).

    Steps: background subtraction (the dark frame, or per column the median of the
    rows clear of the lines); a robust row profile (flat-fielded ratio of row sums,
    or the median of column-normalized columns); peaks with
    :func:`scipy.signal.find_peaks` above a prominence threshold from a robust (MAD)
    noise estimate; a regular grid fitted to the peaks (sub-row line positions and
    spacing, missed interior lines restored); each line's area integrated over its
    cell of one spacing (sub-row cell edges); a trend of the full lines' areas
    (low-order least squares with outlier rejection: uneven brightness); and the
    exposed fraction of the two end lines, of the candidates beyond them and of
    their interior neighbours (light blurred across a cell edge stays counted)
    relative to that trend.  Interior lines count 1 each: the exposure window is
    contiguous, so only the lines at its ends can be partially exposed.

    Parameters
    ----------
    image : array_like (H, W)
        Lines horizontal, at least 3 of them, separated by at least ~3 camera rows.
    dark : array_like (H, W), optional
        Background to subtract (laser off, same exposure).
    flat : array_like (H, W), optional
        Background-free response to one fully exposed line at every pixel
        (:meth:`LineSweep.flat_field`).

    Returns
    -------
    LineCount

    Raises
    ------
    InputError
        Not a finite 2-D image, blank or pure noise, or fewer than 3 lines.
    """
    img = _check_image(image, "image")
    H, W = img.shape
    dark = None if dark is None else _check_image(dark, "dark frame", img.shape)
    flat = None if flat is None else _check_image(flat, "flat frame", img.shape)
    if dark is not None:
        q, sigma = _row_profile(img - dark, flat)
        peaks, noise = _detect(q, sigma)
    else:
        bg = np.percentile(img, 10, axis=0)[None, :]
        q, sigma = _row_profile(img - bg, flat)
        peaks, noise = _detect(q, sigma)
        if peaks.size >= 2:  # refine: the background of the rows clear of the lines
            s = float(np.median(np.diff(peaks)))
            rows = np.arange(H)
            clear = (rows < peaks[0] - s) | (rows > peaks[-1] + s)
            if clear.sum() >= 4:
                bg = np.median(img[clear], axis=0)[None, :]
                q, sigma = _row_profile(img - bg, flat)
                peaks, noise = _detect(q, sigma)
    if peaks.size < 3:
        raise InputError(f"found {peaks.size} lit line(s); need at least 3 separated lines to count")

    # Regular grid through the peaks: sub-row positions, missed lines restored.
    C = _cumulative(q)
    xs = np.arange(H, dtype=float)
    s = float(np.median(np.diff(peaks)))
    cent = []
    for p in peaks:  # sub-row centroid of each peak, within a third of the spacing
        sel = np.abs(xs - p) <= s / 3
        w = np.maximum(q[sel], 0.0)
        cent.append(float((w * xs[sel]).sum() / w.sum()) if w.sum() > 0 else float(p))
    cent = np.array(cent)
    # Index the lines in order: consecutive peaks are one spacing apart, or a
    # whole number of spacings where lines were missed (line shapes can alternate,
    # so the index comes from each gap, not from an accumulated spacing).
    gaps = np.diff(cent)
    s0 = float(np.median(gaps))
    if not s0 >= 2.0:
        raise InputError(f"lines are {s0:.2f} camera rows apart; need at least 2 to separate them")
    idx = np.concatenate([[0], np.cumsum(np.maximum(1, np.rint(gaps / s0)).astype(int))])
    spacing, icpt = (float(v) for v in np.polyfit(idx, cent, 1))
    off = np.abs(cent - (icpt + spacing * idx)) > 0.3 * spacing
    if off.any():  # a stray peak between lines: drop it, index again
        cent = cent[~off]
        if cent.size < 3:
            raise InputError(f"found {cent.size} lit line(s) on a regular grid; need at least 3 separated lines")
        idx = np.concatenate([[0], np.cumsum(np.maximum(1, np.rint(np.diff(cent) / spacing)).astype(int))])
        spacing, icpt = (float(v) for v in np.polyfit(idx, cent, 1))
    if not spacing >= 2.0:
        raise InputError(f"lines are {spacing:.2f} camera rows apart; need at least 2 to separate them")

    lo_i, hi_i = int(idx.min()), int(idx.max())
    cand = np.arange(lo_i - 1, hi_i + 2)
    pos = icpt + spacing * cand
    lo, hi = pos - 0.5 * spacing, pos + 0.5 * spacing
    in_view = (lo >= -0.5) & (hi <= H - 0.5)
    truncated = not (in_view[0] and in_view[-1])
    cand, pos, lo, hi = cand[in_view], pos[in_view], lo[in_view], hi[in_view]
    areas = C(hi) - C(lo)
    detected = (cand >= lo_i) & (cand <= hi_i)
    interior = (cand > lo_i) & (cand < hi_i)
    n_int = int(interior.sum())
    # Cells whose area is measured: the ends and the candidates beyond them, plus
    # the interior lines next to the ends -- blur moves light between a partial
    # end line and its full neighbour, and counting both conserves it.  The other
    # interior lines are fully exposed (the window is contiguous): they count 1
    # each and give the full-line area.
    measured = ~interior
    if n_int >= 4:
        measured = measured | (cand == lo_i + 1) | (cand == hi_i - 1)
    ref_set = interior & ~measured

    # Full-line area: a robust trend over the reference lines (uneven brightness).
    a_ref, p_ref = areas[ref_set], pos[ref_set]
    n_ref = int(ref_set.sum())
    coef, resid = _robust_trend(p_ref, a_ref)
    trend = np.polyval(coef, pos)
    ref = float(np.median(np.polyval(coef, p_ref)))
    if not ref > 0:
        raise InputError("cannot tell lit lines from background (non-positive line areas)")
    trend = np.maximum(trend, 0.2 * ref)
    # noise of each cell's area: the row-profile noise summed over its rows
    var_rows = np.concatenate([[0.0], np.cumsum(sigma**2)])
    edges = np.arange(H + 1) - 0.5
    cell_noise = np.sqrt(np.maximum(np.interp(hi, edges, var_rows) - np.interp(lo, edges, var_rows), 0.0))
    area_noise = float(np.median(cell_noise[measured]))
    scatter = float(np.sqrt((resid**2).sum() / (resid.size - len(coef)))) if resid.size > len(coef) else 0.0
    sigma_a = max(scatter, area_noise)
    fractions = np.where(measured, areas / trend, 1.0)
    sf = sigma_a / ref
    f_sum = float(fractions[measured].sum())
    count = float(n_int - (interior & measured).sum()) + f_sum
    var = int(measured.sum()) * sf**2 + (f_sum * sf) ** 2 / max(n_ref, 1)
    return LineCount(pos, cand, areas, fractions, detected, interior, spacing, sf, count, math.sqrt(var), truncated, noise)


# ============================================================================
# v_p from line counts
# ============================================================================
@dataclass
class LineCalibration:
    """Result of :func:`calibrate_lines_per_second`.

    Attributes
    ----------
    lines_per_second : float
        ``v_p`` (Eq. 2).
    uncertainty : float
        1-sigma uncertainty of ``v_p``, lines per second.
    n_lines : float
        Fractional number of lines counted over all images.
    window_rows : float
        Projector rows scanned during the exposure, ``v_p t_e``.
    exposure_us : float
    rows_per_line : int
    method : str
        ``"complete sweep"`` (fractional counts of all comb phases added) or
        ``"end positions"`` (each image's window estimated from its end lines).
    details : dict
        Per-image counts, spacings and end fractions (JSON-serializable).
    """

    lines_per_second: float
    uncertainty: float
    n_lines: float
    window_rows: float
    exposure_us: float
    rows_per_line: int
    method: str
    details: dict = field(default_factory=dict)

    @property
    def relative_uncertainty(self) -> float:
        return self.uncertainty / self.lines_per_second

    def to_dict(self) -> dict:
        return {
            "lines_per_second": self.lines_per_second,
            "lines_per_second_uncertainty": self.uncertainty,
            "n_lines": self.n_lines,
            "window_rows": self.window_rows,
            "exposure_us": self.exposure_us,
            "rows_per_line": self.rows_per_line,
            "method": self.method,
            **self.details,
        }


def calibrate_lines_per_second(data, exposure_us=None, rows_per_line=None, *, dark=None, flat=None,
                               timing_jitter_us=None, complete=None) -> LineCalibration:
    """Projector scanline velocity ``v_p = n_v / t_e`` from global-shutter line images (Sec. 6).

    Parameters
    ----------
    data : LineSweep or array_like (H, W) or (n, H, W)
        A :class:`LineSweep` (everything else defaults from it), one image, or the
        images of the comb phases.
    exposure_us : float
        Global-shutter exposure ``t_e`` (paper: 500 us).
    rows_per_line : int
        ``k``: projector rows between the lit lines of one image (1: every row
        lit, the paper's image; the lines must then be resolved by the camera).
    dark : array_like (H, W), optional
        Ambient background (laser off, same exposure).
    flat : array_like (H, W), optional
        Background-free response to one fully exposed line (see
        :meth:`LineSweep.flat_field`).
    timing_jitter_us : float, optional
        RMS error of the exposure window's position per image; adds
        ``2 (v_p sigma_t)^2`` rows^2 (two window ends) to the variance.
    complete : bool, optional
        The images are the ``k`` distinct comb phases (default: ``n == k``).  Their
        fractional counts then add up to exactly ``v_p t_e`` projector rows;
        otherwise each image's window is estimated from its end lines, which
        cannot place an end that fell in a dark gap better than the gap
        (uncertainty up to ``(k - 1) / sqrt(12)`` rows per end).

    Returns
    -------
    LineCalibration
        ``v_p`` with a 1-sigma uncertainty from the end-line fractions (profile
        noise and per-line area scatter), the gap ambiguity of incomplete sweeps
        and the timing jitter.

    Raises
    ------
    InputError
        Bad images (not finite, blank, too few lines), missing exposure, lines
        running off the image.
    """
    if isinstance(data, LineSweep):
        sweep = data
        exposure_us = sweep.exposure_us if exposure_us is None else exposure_us
        rows_per_line = sweep.line_step_rows if rows_per_line is None else rows_per_line
        dark = sweep.dark if dark is None else dark
        flat = sweep.flat_field() if flat is None else flat
        timing_jitter_us = sweep.timing_jitter_us if timing_jitter_us is None else timing_jitter_us
        complete = sweep.complete if complete is None else complete
        images = sweep.images
        n_saturated = int(np.asarray(sweep.saturated).sum()) if sweep.saturated is not None else 0
    else:
        if exposure_us is None:
            raise InputError("exposure_us is required (the global-shutter exposure of the line image)")
        images = np.asarray(data)
        if images.ndim == 2:
            images = images[None]
        if images.ndim != 3:
            raise InputError(f"expected an image (H, W) or images (n, H, W), got shape {images.shape}")
        n_saturated = 0
    rows_per_line = 1 if rows_per_line is None else rows_per_line
    if int(rows_per_line) != rows_per_line or rows_per_line < 1:
        raise InputError(f"rows_per_line must be a positive integer, got {rows_per_line!r}")
    k = int(rows_per_line)
    if not (exposure_us is not None and np.isfinite(exposure_us) and exposure_us > 0):
        raise InputError(f"exposure_us must be a positive number, got {exposure_us!r}")
    t_e = float(exposure_us) * 1e-6
    n = images.shape[0]
    complete = (n == k) if complete is None else bool(complete)
    jitter = float(timing_jitter_us or 0.0)

    counts = []
    for j in range(n):
        try:
            c = count_lines(images[j], dark=dark, flat=flat)
        except InputError as exc:
            raise InputError(f"image {j}: {exc}" if n > 1 else str(exc)) from None
        if c.truncated:
            raise InputError(
                (f"image {j}: " if n > 1 else "")
                + "the lit lines reach the image border: the exposure window is not entirely in view"
            )
        counts.append(c)

    if complete:
        rows = float(sum(c.count for c in counts))
        var = float(sum(c.count_uncertainty**2 for c in counts))
        if n != k:  # several images per phase: the mean over repeats
            rows *= k / n
            var *= (k / n) ** 2
        method = "complete sweep"
    else:
        est = [c.window_rows(k) for c in counts]
        w = np.array([1.0 / max(s, 1e-6) ** 2 for _, s in est])
        rows = float(np.sum(w * [r for r, _ in est]) / w.sum())
        var = float(1.0 / w.sum())
        method = "end positions"
    vp = rows / t_e
    var += 2.0 * (jitter * 1e-6 * vp) ** 2
    sigma = math.sqrt(var) / t_e
    details = {
        "n_images": n,
        "timing_jitter_us": jitter,
        "saturated_pixels": n_saturated,
        "images": [
            {
                "count": round(c.count, 6),
                "count_uncertainty": round(c.count_uncertainty, 6),
                "detected": c.n_detected,
                "spacing_rows": round(c.spacing_rows, 6),
                "end_fractions": [round(float(f), 6) for f in c.fractions[~c.interior]],
                "fraction_sigma": round(c.fraction_sigma, 6),
            }
            for c in counts
        ],
    }
    n_lines = float(sum(c.count for c in counts))
    return LineCalibration(vp, sigma, n_lines, rows, float(exposure_us), k, method, details)


# ============================================================================
# Delay zero
# ============================================================================
@dataclass
class DelayZeroCalibration:
    """Result of :func:`calibrate_delay_zero`.

    Attributes
    ----------
    delay_zero_us : float
        Commanded delay at which the true delay is zero (the centre of the
        epipolar response).  Correct commanded delays as
        ``t_d = commanded - delay_zero_us``.
    uncertainty_us : float
        1-sigma uncertainty of ``delay_zero_us``.
    sync_offset_us : float
        Commanded synchronization offset ``t'_o`` that gives ``t_d = 0`` at
        ``exposure_us`` (Eq. 1 with the measured zero:
        ``t_e/2 - t_p/2 - delay_zero_us``).
    nominal_sync_offset_us : float
        What Eq. 1 assumes without calibration, ``t_e/2 - t_p/2``.
    width_us : float
        Full width at half maximum of the response (about ``t_e``: a check).
    exposure_us : float
    details : dict
        Delays, responses, levels and crossings (JSON-serializable).
    """

    delay_zero_us: float
    uncertainty_us: float
    sync_offset_us: float
    nominal_sync_offset_us: float
    width_us: float
    exposure_us: float
    details: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {
            "delay_zero_us": self.delay_zero_us,
            "delay_zero_uncertainty_us": self.uncertainty_us,
            "sync_offset_us": self.sync_offset_us,
            "nominal_sync_offset_us": self.nominal_sync_offset_us,
            "width_us": self.width_us,
            "exposure_us": self.exposure_us,
            **self.details,
        }


def delay_zero_sweep(exposure_us: float = 600.0, step_us: float = 10.0, half_range_us: float | None = None) -> Sweep:
    """A fine delay sweep around 0 at one exposure, for :func:`calibrate_delay_zero`.

    The default range, ``+-(t_e/2 + max(t_e/2, 250 us))``, brackets the epipolar
    plateau (``|t_d| < t_e/2``) with baseline on both sides even for a sync error
    of a few hundred microseconds.  No image is flagged: every one is used.
    """
    if not (exposure_us > 0 and step_us > 0):
        raise InputError("exposure_us and step_us must be positive")
    half = half_range_us if half_range_us is not None else 0.5 * exposure_us + max(0.5 * exposure_us, 250.0)
    n = int(math.floor(half / step_us + 1e-9))
    d = np.arange(-n, n + 1) * float(step_us)
    return Sweep(d, np.full(d.size, float(exposure_us)), np.zeros(d.size, bool), name="delay-zero")


def device_capture(device, exposure_us: float = 600.0, delay_error_us: float = 0.0) -> Callable[[float], np.ndarray]:
    """A ``capture(delay_us) -> image`` for :func:`calibrate_delay_zero` from any device.

    ``delay_error_us`` simulates an unknown synchronization error: the device
    really runs at ``commanded - delay_error_us`` (so the calibration should
    return ``delay_zero_us = delay_error_us``).  Leave it 0 for a real device.
    """
    device.set_exposure(exposure_us)

    def capture(delay_us: float) -> np.ndarray:
        device.set_delay(float(delay_us) - float(delay_error_us))
        return device.grab()[0]

    return capture


def _ramp(resp, a, b, half, ipk, step):
    """Indices of one ramp of the response (walking from the peak ``ipk`` by ``step``).

    The ramp is the run of points between the last plateau point (above ``b``)
    and the first baseline point (below ``a``); when fewer than 2 points lie
    strictly between, the two points bracketing the ``half`` crossing are used.
    """
    n = resp.size
    i = ipk
    while 0 <= i + step < n and resp[i + step] >= half:
        i += step
    j = i + step  # first point below half
    if not 0 <= j < n:
        raise InputError("the delay sweep does not reach the baseline on both sides of the epipolar peak")
    top = i
    while 0 <= top - step < n and (top - step - ipk) * step >= 0 and resp[top] < b:
        top -= step
    bottom = j
    while 0 <= bottom + step < n and resp[bottom] > a:
        bottom += step
    lo_i, hi_i = sorted((top, bottom))
    inner = [m for m in range(lo_i + 1, hi_i) if a <= resp[m] <= b]
    return inner if len(inner) >= 2 else sorted((i, j))


def _fit_response(d, r, centre, width, ramp, base, amp):
    """Least-squares fit of ``base + amp * (box(width) * box(ramp) * gauss(blur))(d - centre)``.

    The epipolar response of a diffuse target over delay is the band (a box as
    wide as the exposure) slid over one camera row's footprint (a box: the ramp)
    and blurred by the sync jitter (a Gaussian): the exact bin integral of
    :func:`planeray.timing.band_bin_weights` with 1-us bins.  Returns
    ``(centre, sigma, params)`` with the 1-sigma from the Jacobian and the residual
    variance (noise plus any misfit), or None if the fit fails.
    """
    from scipy.optimize import least_squares

    from .timing import band_bin_weights

    def model(p):
        c, w, f, g, b0, a = p
        return b0 + a * band_bin_weights(d, c, abs(w), abs(g), abs(f))

    p0 = np.array([centre, abs(width), max(abs(ramp), 1.0), max(0.1 * abs(ramp), 1.0), base, amp], float)
    try:
        sol = least_squares(lambda p: model(p) - r, p0, x_scale=np.array([10.0, 10.0, 10.0, 5.0, abs(amp), abs(amp)]))
    except (ValueError, FloatingPointError):
        return None
    if not sol.success or d.size <= p0.size:
        return None
    dof = d.size - p0.size
    s2 = float((sol.fun**2).sum()) / dof
    # Heteroscedasticity-consistent (HC3 sandwich) covariance: the ramps, where all
    # the information on the centre is, are much noisier than plateau and
    # baseline (per-row trigger jitter acts exactly there).
    J = sol.jac
    try:
        bread = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return None
    lev = np.clip(np.einsum("ij,jk,ik->i", J, bread, J), 0.0, 0.99)
    meat = (J * (sol.fun / (1.0 - lev))[:, None] ** 2).T @ J  # HC3: leverage-corrected
    cov = bread @ meat @ bread
    sigma = float(np.sqrt(max(cov[0, 0], 0.0)))
    if not np.isfinite(sigma):
        return None
    c, w, f, g, b0, a = (float(v) for v in sol.x)
    params = {"centre_us": c, "width_us": abs(w), "ramp_us": abs(f), "blur_us": abs(g), "baseline": b0, "amplitude": a,
              "residual_rms": math.sqrt(s2)}
    return c, sigma, params


def calibrate_delay_zero(capture, delays_us, exposure_us: float = 600.0, *, lines_per_second=PAPER_LINES_PER_SECOND,
                         roi=None) -> DelayZeroCalibration:
    """Delay zero: the commanded delay at which the epipolar (direct) response peaks.

    On a diffuse calibration target the direct light of a camera row comes from its
    own epipolar plane, so the mean image over a fine delay sweep at one exposure
    is a plateau (the band ``|t_d - zero| < t_e/2`` covers the plane) with ramps as
    wide as one camera row's footprint, blurred by sync jitter.  Its centre is the
    commanded delay where the true ``t_d = 0``; Eq. 1 then gives the sync offset
    ``t'_o`` measured rather than assumed (Sec. 6).

    The centre is first the midpoint of the two half-maximum crossings (each from
    a straight line fitted to the ramp between 20 % and 80 % of the rise), then
    refined by a least-squares fit of the whole curve to a box (exposure) slid
    over a box (footprint) blurred by a Gaussian (jitter), which uses every ramp
    point whatever the grid's phase.  Its 1-sigma comes from a leverage-corrected
    sandwich covariance (the ramps are far noisier than plateau and baseline:
    per-row trigger jitter acts exactly there).  If the fit fails or disagrees
    with the midpoint, the midpoint is returned with its own uncertainty.

    Parameters
    ----------
    capture : callable or array_like
        ``capture(delay_us) -> image`` (or ``(image, saturated)``), e.g.
        :func:`device_capture`; or the images ``(N, H, W)`` already captured at
        ``delays_us`` (a stack's images at one exposure).
    delays_us : array_like (N,)
        Commanded delays, covering the plateau and baseline on both sides
        (:func:`delay_zero_sweep`); steps well below the ramp width (~100 us for a
        128-row image of a 720-row projector) give the best precision.
    exposure_us : float
        Row exposure of the sweep.
    lines_per_second : float
        ``v_p``, for the scanline time ``t_p`` of Eq. 1.
    roi : array_like of bool (H, W) or tuple of slices, optional
        Pixels of the diffuse target (default: all).

    Returns
    -------
    DelayZeroCalibration
        With its 1-sigma uncertainty; ``details["method"]`` says which estimate.

    Raises
    ------
    InputError
        Non-finite or blank images, a sweep that does not bracket the peak, fewer
        than 5 delays.
    """
    d = np.asarray(delays_us, dtype=np.float64).ravel()
    if d.size < 5 or not np.all(np.isfinite(d)):
        raise InputError("need at least 5 finite delays")
    if not (np.isfinite(exposure_us) and exposure_us > 0):
        raise InputError(f"exposure_us must be a positive number, got {exposure_us!r}")
    if callable(capture):
        images = []
        for x in d:
            im = capture(float(x))
            images.append(im[0] if isinstance(im, tuple) else im)
    else:
        images = capture
        if len(images) != d.size:
            raise InputError(f"{len(images)} images for {d.size} delays")
    resp = np.empty(d.size)
    for i, im in enumerate(images):
        im = np.asarray(im, dtype=np.float64)
        if im.ndim != 2:
            raise InputError(f"image at delay {d[i]:g} us must be 2-D, got shape {im.shape}")
        sel = im[roi] if roi is not None else im
        if sel.size == 0:
            raise InputError("the region of interest is empty")
        if not np.all(np.isfinite(sel)):
            raise InputError(f"image at delay {d[i]:g} us contains NaN or infinite values")
        resp[i] = sel.mean()
    order = np.argsort(d, kind="stable")
    d, resp = d[order], resp[order]
    if np.any(np.diff(d) <= 0):
        raise InputError("delays must be distinct")

    # Noise of the response: scatter of second differences (smooth curve removed).
    dd = resp[2:] - 2 * resp[1:-1] + resp[:-2]
    noise = _MAD * float(np.median(np.abs(dd - np.median(dd)))) / math.sqrt(6.0)
    hi = float(np.percentile(resp, 90))
    tails = np.concatenate([resp[:3], resp[-3:]])
    lo = float(np.median(tails))
    if not hi - lo > max(10.0 * noise, 1e-12):
        raise InputError("no epipolar response: the images do not change with delay (blank target?)")
    for name, tail in (("shortest", resp[:2]), ("longest", resp[-2:])):
        if tail.max() > lo + 0.2 * (hi - lo):
            raise InputError(f"the {name} delays are still on the epipolar plateau: widen the delay sweep")
    half = lo + 0.5 * (hi - lo)
    ipk = int(np.argmax(np.convolve(resp, np.ones(3) / 3, mode="same")))

    a, b = lo + 0.2 * (hi - lo), lo + 0.8 * (hi - lo)

    def edge(step):
        idx = _ramp(resp, a, b, half, ipk, step)
        x, y = d[idx], resp[idx]
        slope, icpt = np.polyfit(x, y, 1)
        if slope == 0 or not np.isfinite(slope):
            raise InputError("cannot locate the edge of the epipolar response")
        xc = (half - icpt) / slope
        # error of the crossing: the response noise (or the ramp's departure from
        # a straight line, if larger) through the fitted line
        res = y - (icpt + slope * x)
        lack = float(np.sqrt((res**2).sum() / (len(x) - 2))) if len(x) > 2 else 0.0
        s_r = max(noise, lack)
        xm = x.mean()
        sxx = float(((x - xm) ** 2).sum())
        var_line = s_r**2 * (1.0 / len(x) + (xc - xm) ** 2 / sxx)
        return float(xc), float(slope), math.sqrt(var_line) / abs(slope), len(idx)

    xl, sl, el, nl = edge(-1)
    xr, sr, er, nr = edge(+1)
    mid, mid_sigma = 0.5 * (xl + xr), 0.5 * math.hypot(el, er)
    step = float(np.median(np.diff(d)))
    if min(nl, nr) < 3:  # a ramp seen at two points is placed no better than the grid allows
        mid_sigma = math.hypot(mid_sigma, step / math.sqrt(12.0) / 2)
    # Start the model fit from the crossings: width = FWHM, ramp = rise / slope.
    ramp = 0.5 * (hi - lo) * (1.0 / abs(sl) + 1.0 / abs(sr))
    fit = _fit_response(d, resp, mid, xr - xl, ramp, lo, hi - lo)
    if fit is not None and abs(fit[0] - mid) < max(3.0 * mid_sigma, 0.5 * step, 1.0):
        centre, sigma, params = fit
        method = "model fit"
    else:
        centre, sigma, params = mid, mid_sigma, None
        method = "half-maximum midpoint"
    t_p = 1e6 / float(lines_per_second)
    sync = float(sync_offset_from_delay(centre, exposure_us, line_time_us=t_p))
    nominal = float(sync_offset_from_delay(0.0, exposure_us, line_time_us=t_p))
    details = {
        "delays_us": d.tolist(),
        "response": resp.tolist(),
        "baseline": lo,
        "plateau": hi,
        "response_noise": noise,
        "left_crossing_us": xl,
        "right_crossing_us": xr,
        "ramp_points": [nl, nr],
        "midpoint_us": mid,
        "midpoint_uncertainty_us": mid_sigma,
        "method": method,
        "model": params,
        "lines_per_second": float(lines_per_second),
    }
    return DelayZeroCalibration(float(centre), float(sigma), sync, nominal, float(xr - xl), float(exposure_us), details)


# ============================================================================
# Files
# ============================================================================
def write_line_sweep(sweep: LineSweep, path, overwrite: bool = True) -> Path:
    """Write a :class:`LineSweep` to one ``.npz`` file, atomically."""
    from .io import _jsonable, atomic_file

    path = Path(path)
    if path.suffix.lower() != ".npz":
        raise InputError("a line sweep is written as .npz", path)
    meta = {
        "format": "planeray-line-sweep",
        "format_version": 1,
        "exposure_us": sweep.exposure_us,
        "line_step_rows": sweep.line_step_rows,
        "phases": None if sweep.phases is None else list(sweep.phases),
        "flat_exposure_us": sweep.flat_exposure_us,
        "timing_jitter_us": sweep.timing_jitter_us,
        "metadata": _jsonable(sweep.metadata, "metadata", InputError),
    }
    arrays = {"images": np.asarray(sweep.images, np.float32), "meta": np.array(json.dumps(meta))}
    for name in ("dark", "flat"):
        if getattr(sweep, name) is not None:
            arrays[name] = np.asarray(getattr(sweep, name), np.float32)
    if sweep.saturated is not None:
        arrays["saturated"] = np.asarray(sweep.saturated, bool)
    with atomic_file(path, overwrite) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
    return path


def read_line_sweep(path, exposure_us: float | None = None, rows_per_line: int | None = None) -> LineSweep:
    """Read line-sweep images: a ``.npz`` from :func:`write_line_sweep`, or image files.

    Parameters
    ----------
    path : str or os.PathLike
        ``.npz`` (everything included), or one grayscale ``.tif``/``.tiff``/``.png``
        (a multi-page TIFF holds one comb phase per page).
    exposure_us, rows_per_line : optional
        Override (or, for image files, give) the exposure and comb step;
        image files default to the paper's 500 us and ``k = 1``.
    """
    path = Path(path)
    if not path.exists():
        raise InputError("file not found", path)
    suffix = path.suffix.lower()
    try:
        if suffix == ".npz":
            with np.load(path, allow_pickle=False) as z:
                if "images" not in z or "meta" not in z:
                    raise InputError("not a planeray line sweep (arrays 'images' and 'meta' required)", path)
                meta = json.loads(str(z["meta"]))
                arr = {name: z[name] for name in ("images", "dark", "flat", "saturated") if name in z}
            return LineSweep(
                arr["images"],
                meta["exposure_us"] if exposure_us is None else exposure_us,
                meta["line_step_rows"] if rows_per_line is None else rows_per_line,
                None if meta.get("phases") is None else tuple(meta["phases"]),
                arr.get("dark"), arr.get("flat"), meta.get("flat_exposure_us"), arr.get("saturated"),
                float(meta.get("timing_jitter_us", 0.0)), meta.get("metadata", {}),
            )
        if suffix in (".tif", ".tiff"):
            import tifffile

            images = np.asarray(tifffile.imread(path), dtype=np.float64)
        elif suffix == ".png":
            from PIL import Image

            with Image.open(path) as im:
                images = np.asarray(im.convert("I") if im.mode not in ("L", "I", "I;16", "F") else im, dtype=np.float64)
        else:
            raise InputError(f"unsupported line-sweep file {suffix!r} (use .npz, .tif, .tiff or .png)", path)
    except InputError as exc:
        if exc.path is None:
            raise InputError(exc.problem, path) from None
        raise
    except Exception as exc:  # corrupt files raise many types
        raise InputError(f"cannot read line sweep ({type(exc).__name__}: {exc})", path) from exc
    if images.ndim not in (2, 3):
        raise InputError(f"expected a grayscale image or a stack of them, got shape {images.shape}", path)
    return LineSweep(images, PAPER_CALIBRATION_EXPOSURE_US if exposure_us is None else exposure_us,
                     1 if rows_per_line is None else rows_per_line)


def write_calibration(path, lines: LineCalibration | None = None, delay_zero: DelayZeroCalibration | None = None) -> dict:
    """Store calibration results in an ``acquisition.json``, keeping its other fields.

    Writes ``lines_per_second`` (the field the stack import requires),
    ``lines_per_second_uncertainty``, ``delay_zero_us``,
    ``delay_zero_uncertainty_us`` and ``sync_offset_us`` as given, and the full
    results under ``calibration.lines`` / ``calibration.delay_zero``.  The file
    (or ``path/acquisition.json`` when ``path`` is a folder) is created if missing
    and replaced atomically.

    Returns
    -------
    dict
        The new content.

    Raises
    ------
    InputError
        Nothing to write, or an existing file that is not a JSON object.
    """
    from .io import _jsonable, atomic_file

    if lines is None and delay_zero is None:
        raise InputError("nothing to write: give a line-velocity and/or a delay-zero calibration")
    path = Path(path)
    if path.is_dir():
        path = path / "acquisition.json"
    acq: dict = {}
    if path.exists():
        try:
            acq = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"cannot read file ({exc})", path) from exc
        except json.JSONDecodeError as exc:
            raise InputError(f"invalid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})", path) from exc
        if not isinstance(acq, dict):
            raise InputError(f"expected a JSON object, got {type(acq).__name__}", path)
    cal = dict(acq.get("calibration") or {}) if isinstance(acq.get("calibration"), dict) else {}
    if lines is not None:
        acq["lines_per_second"] = float(lines.lines_per_second)
        acq["lines_per_second_uncertainty"] = float(lines.uncertainty)
        cal["lines"] = lines.to_dict()
    if delay_zero is not None:
        acq["delay_zero_us"] = float(delay_zero.delay_zero_us)
        acq["delay_zero_uncertainty_us"] = float(delay_zero.uncertainty_us)
        acq["sync_offset_us"] = float(delay_zero.sync_offset_us)
        cal["delay_zero"] = delay_zero.to_dict()
    acq["calibration"] = cal
    acq = _jsonable(acq, "acquisition.json", InputError)
    with atomic_file(path) as tmp:
        tmp.write_text(json.dumps(acq, indent=2) + "\n", encoding="utf-8")
    return acq
