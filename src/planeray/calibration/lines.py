"""Line velocity ``v_p`` (Sec. 6): count the lines of a global-shutter comb capture, to a fraction of a line, with an uncertainty."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..linesweep import LineSweep
from ._stats import MAD_TO_SIGMA


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
    grid_rms : float
        RMS distance of the detected lines from their regular grid, in spacings (a comb's:
        a few hundredths; peaks found in noise: ~0.2).

    See Also
    --------
    count_lines : returns it.

    Examples
    --------
    >>> import planeray as pr
    >>> target = pr.make_scene("diffuse_plane", (288, 32), projector_rows=96, seed=0)
    >>> sweep = pr.SimulatedEpiscan(target, seed=5).capture_line_sweep(500.0)
    >>> from planeray.calibration import count_lines
    >>> count = count_lines(sweep.images[0])
    >>> type(count).__name__, bool(count.detected.sum() > 10)
    ('LineCount', True)
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
    grid_rms: float = 0.0

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
        s_px = MAD_TO_SIGMA * np.median(np.abs(resid - np.median(resid, axis=1, keepdims=True)), axis=1)
        return q, s_px * math.sqrt(W) / denom
    scale = np.percentile(sig, 95, axis=0)
    good = scale > 0.1 * max(np.median(scale), 0.0)
    if good.sum() < 1 or not np.any(scale > 0):
        raise InputError("no lit lines found: the image is blank (no light above its background)")
    n = sig[:, good] / scale[good]
    q = np.median(n, axis=1)
    s_px = MAD_TO_SIGMA * np.median(np.abs(n - q[:, None]), axis=1)
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


#: Largest RMS distance of detected lines from their regular grid, in spacings.  A comb's lines are
#: regular (measured: at most 0.011 over the 105 counts of tests/test_calibration.py, blur, noise and
#: ambient light included); peaks found in noise lay 0.05-0.2 off their grid in 296 of 300 noise images.
MAX_GRID_RMS = 0.04


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

    See Also
    --------
    planeray.calibrate_lines_per_second : the whole calibration.

    Examples
    --------
    >>> import planeray as pr
    >>> target = pr.make_scene("diffuse_plane", (288, 32), projector_rows=96, seed=0)
    >>> sweep = pr.SimulatedEpiscan(target, seed=5).capture_line_sweep(500.0)
    >>> count = count_lines(sweep.images[0])
    >>> 13 <= float(count.fractions.sum()) <= 14  # 13.5 lines of each comb phase in 500 us
    True
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
    grid_rms = float(np.sqrt(np.mean((cent - (icpt + spacing * idx)) ** 2)) / spacing)
    if grid_rms > MAX_GRID_RMS:
        raise InputError(
            f"no comb of lit lines found: the {cent.size} brightest rows lie {grid_rms:.2f} spacings (RMS) off a "
            f"regular grid, a comb's within {MAX_GRID_RMS:g}; the image is noise or not a comb of lines"
        )

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
    return LineCount(
        pos, cand, areas, fractions, detected, interior, spacing, sf, count, math.sqrt(var), truncated, noise, grid_rms
    )


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

    See Also
    --------
    planeray.calibrate_lines_per_second : returns it.
    write_calibration : stores it.

    Examples
    --------
    >>> import planeray as pr
    >>> target = pr.make_scene("diffuse_plane", (288, 32), projector_rows=96, seed=0)
    >>> sweep = pr.SimulatedEpiscan(target, seed=5).capture_line_sweep(500.0)
    >>> cal = pr.calibrate_lines_per_second(sweep)
    >>> type(cal).__name__, round(cal.n_lines), cal.method
    ('LineCalibration', 27, 'complete sweep')
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


def calibrate_lines_per_second(
    data, *, exposure_us=None, rows_per_line=None, dark=None, flat=None, timing_jitter_us=None, complete=None
) -> LineCalibration:
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

    See Also
    --------
    calibrate_delay_zero : the other calibration (delay 0).
    planeray.calibration.count_lines : the line count of one image.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 6 (calibration).

    Examples
    --------
    A comb of lit projector rows seen by the simulated device (96 projector rows on 288 camera rows):

    >>> import planeray as pr
    >>> target = pr.make_scene("diffuse_plane", (288, 32), projector_rows=96, seed=0)
    >>> sweep = pr.SimulatedEpiscan(target, lines_per_second=54_000.0, seed=5).capture_line_sweep(500.0)
    >>> cal = pr.calibrate_lines_per_second(sweep)
    >>> abs(cal.lines_per_second - 54_000.0) < 3 * cal.uncertainty
    True
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
