"""Delay zero (Sec. 6, Eq. 1): the commanded delay at which a camera row sees its own epipolar plane."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..timing import PAPER_LINES_PER_SECOND, Sweep, sync_offset_from_delay
from ._stats import MAD_TO_SIGMA


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
    base_trigger_delay_us : float or None
        For a camera triggered by the projector's VSYNC: the trigger delay at
        which ``t'_o = 0``, i.e. the base used for the sweep plus
        ``delay_zero_us`` -- what the camera driver needs
        (:func:`planeray.calibration.calibrate_base_trigger_delay`).  None when
        the sweep's base is unknown (a simulated device, a stack without it).

    See Also
    --------
    planeray.calibrate_delay_zero : returns it.
    write_calibration : stores it.

    Examples
    --------
    >>> import planeray as pr
    >>> from planeray.calibration import delay_zero_sweep, device_capture
    >>> device = pr.SimulatedEpiscan(pr.make_scene("diffuse_plane", (16, 16), projector_rows=90, seed=0), seed=1)
    >>> cal = pr.calibrate_delay_zero(device_capture(device), delay_zero_sweep(600.0, step_us=20.0).delay_us)
    >>> type(cal).__name__, abs(cal.delay_zero_us) < 10.0, round(cal.width_us, -2)
    ('DelayZeroCalibration', True, 600.0)
    """

    delay_zero_us: float
    uncertainty_us: float
    sync_offset_us: float
    nominal_sync_offset_us: float
    width_us: float
    exposure_us: float
    details: dict = field(default_factory=dict)
    base_trigger_delay_us: float | None = None

    def to_dict(self) -> dict:
        base = {} if self.base_trigger_delay_us is None else {"base_trigger_delay_us": self.base_trigger_delay_us}
        return {
            "delay_zero_us": self.delay_zero_us,
            "delay_zero_uncertainty_us": self.uncertainty_us,
            **base,
            "sync_offset_us": self.sync_offset_us,
            "nominal_sync_offset_us": self.nominal_sync_offset_us,
            "width_us": self.width_us,
            "exposure_us": self.exposure_us,
            **self.details,
        }


def delay_zero_sweep(exposure_us: float = 600.0, *, step_us: float = 10.0, half_range_us: float | None = None) -> Sweep:
    """A fine delay sweep around 0 at one exposure, for :func:`calibrate_delay_zero`.

    The default range, ``+-(t_e/2 + max(t_e/2, 250 us))``, brackets the epipolar
    plateau (``|t_d| < t_e/2``) with baseline on both sides even for a sync error
    of a few hundred microseconds.  No image is flagged: every one is used.

    Parameters
    ----------
    exposure_us : float
        The exposure of every image, microseconds.
    step_us : float
        Delay step, microseconds.
    half_range_us : float, optional
        The sweep covers ``-half_range_us .. half_range_us`` (default: see above).

    Returns
    -------
    Sweep
        No image flagged.

    See Also
    --------
    planeray.calibrate_delay_zero : reads its images.

    Examples
    --------
    >>> sweep = delay_zero_sweep(600.0, step_us=10.0)
    >>> len(sweep), float(sweep.delay_us[0]), float(sweep.delay_us[-1])
    (121, -600.0, 600.0)
    """
    if not (exposure_us > 0 and step_us > 0):
        raise InputError("exposure_us and step_us must be positive")
    half = half_range_us if half_range_us is not None else 0.5 * exposure_us + max(0.5 * exposure_us, 250.0)
    n = int(math.floor(half / step_us + 1e-9))
    d = np.arange(-n, n + 1) * float(step_us)
    return Sweep(d, np.full(d.size, float(exposure_us)), np.zeros(d.size, bool), name="delay-zero")


def device_capture(device, *, exposure_us: float = 600.0, delay_error_us: float = 0.0) -> Callable[[float], np.ndarray]:
    """A ``capture(delay_us) -> image`` for :func:`calibrate_delay_zero` from any device.

    ``delay_error_us`` simulates an unknown synchronization error: the device
    really runs at ``commanded - delay_error_us`` (so the calibration should
    return ``delay_zero_us = delay_error_us``).  Leave it 0 for a real device.

    Parameters
    ----------
    device : Device
        An open device.
    exposure_us : float
        The exposure of every image, microseconds.
    delay_error_us : float
        A synchronization error to simulate, microseconds (0 for a real device).

    Returns
    -------
    callable
        ``capture(delay_us) -> image`` (H, W).

    See Also
    --------
    planeray.calibrate_delay_zero : takes it.

    Examples
    --------
    >>> import planeray as pr
    >>> device = pr.SimulatedEpiscan(pr.make_scene("diffuse_plane", (16, 16), projector_rows=90, seed=0), seed=1)
    >>> capture = device_capture(device, exposure_us=600.0)
    >>> capture(0.0).shape  # the image at delay 0
    (16, 16)
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

    from ..timing import band_bin_weights

    def model(p):
        c, w, f, g, b0, a = p
        return b0 + a * band_bin_weights(d, c, abs(w), blur_sigma_rows=abs(g), line_width_rows=abs(f))

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
    params = {
        "centre_us": c,
        "width_us": abs(w),
        "ramp_us": abs(f),
        "blur_us": abs(g),
        "baseline": b0,
        "amplitude": a,
        "residual_rms": math.sqrt(s2),
    }
    return c, sigma, params


def calibrate_delay_zero(
    capture, delays_us, *, exposure_us: float = 600.0, lines_per_second=PAPER_LINES_PER_SECOND, roi=None
) -> DelayZeroCalibration:
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

    See Also
    --------
    delay_zero_sweep : the fine sweep it reads.
    device_capture : a ``capture(delay_us)`` from any device.
    calibrate_lines_per_second : the scan rate.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 6 (calibration).

    Examples
    --------
    A device whose synchronization is 40 us late:

    >>> import planeray as pr
    >>> from planeray.calibration import delay_zero_sweep, device_capture
    >>> device = pr.SimulatedEpiscan(pr.make_scene("diffuse_plane", (16, 16), projector_rows=90, seed=0), seed=1)
    >>> sweep = delay_zero_sweep(600.0, step_us=20.0)
    >>> cal = pr.calibrate_delay_zero(device_capture(device, delay_error_us=40.0), sweep.delay_us)
    >>> abs(cal.delay_zero_us - 40.0) < 10.0
    True
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
    noise = MAD_TO_SIGMA * float(np.median(np.abs(dd - np.median(dd)))) / math.sqrt(6.0)
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
