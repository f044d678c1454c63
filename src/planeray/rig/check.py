"""``planeray rig check``: is the rig wired and set up right, before a two-minute sweep?

Each check measures what it can on the rig itself -- the projector window read
back from the X server, frames waited for on the trigger, images of white and
black, a short delay scan, a two-exposure linearity test -- and gives one
:class:`Check`: pass, fail (with what to do) or skip (with why).  A check whose
premise failed (no frames, no projector light) is skipped, so that one fault
gives one failing line.

The delay scan (Eqs. 1-3): a camera row sees its own epipolar plane while
``|t_d - z| < t_e / 2``, where ``z`` is the commanded delay of its true delay
zero; the centre of each band of rows' response over the scan is its ``z``.  If
the rolling shutter's row time matches the projector's line time, ``z`` is the
same for every row; if it is off by a fraction ``e``, ``z`` moves by ``e / v_p``
per projector row.  The mean ``z`` must be the calibrated delay zero.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from ..devices.capabilities import has
from ..errors import DeviceError, InputError
from ..projector import ProjectorWindow, black, grab_screen, list_screens, rectification_card, white
from ..timing import Sweep, paper_sweep, sync_offset_from_delay
from .capture import DEFAULT_FRAME_RATE_HZ

__all__ = ["Check", "check_rig", "ROW_TIME_TOLERANCE", "DELAY_ZERO_TOLERANCE_US", "LINEARITY_TOLERANCE"]

#: Largest accepted relative row-time error (the line-velocity calibration is good to ~1 %).
ROW_TIME_TOLERANCE = 0.02
#: Largest accepted distance (us) of the measured epipolar centre from the calibrated delay zero.
DELAY_ZERO_TOLERANCE_US = 30.0
#: Step of the delay scan (us): the check's exposure (600 us) is a whole number of steps, so both edges of
#: the epipolar response fall at the same place between samples and its centre is found to a few us.
SCAN_STEP_US = 150.0
#: Largest accepted relative error of the two-exposure ratio (2 for twice the light).
LINEARITY_TOLERANCE = 0.05


@dataclass
class Check:
    """One line of ``rig check``.

    Attributes
    ----------
    name : str
        What was checked (``"trigger"``, ``"row time"``...).
    status : {"pass", "fail", "skip"}
    message : str
        What was found; for a failure, what to do.
    fault : str or None
        The fault found, by name (``"no_trigger"``, ``"trigger_edge"``, ``"gamma"``,
        ``"global_shutter"``, ``"row_time"``, ``"other_screen"``, ``"exposure_range"``...).
    details : dict
        The measured numbers.

    See Also
    --------
    check_rig : returns them.

    Examples
    --------
    >>> check = Check("trigger", "pass", "one frame per VSYNC")
    >>> check.status, check.fault
    ('pass', None)
    """

    name: str
    status: str
    message: str
    fault: str | None = None
    details: dict = field(default_factory=dict)

    def line(self) -> str:
        return f"{self.status.upper():4}  {self.name:15} {self.message}"

    def to_dict(self) -> dict:
        return asdict(self)


def _band_centre(delays, response) -> float | None:
    """The centre of a box-shaped response over delays: the mid-point of its half-maximum crossings."""
    r = np.asarray(response, float) - np.min(response)
    top = np.max(r)
    if not top > 0:
        return None
    half = 0.5 * top
    above = np.flatnonzero(r >= half)
    i, j = above[0], above[-1]
    if i == 0 or j == len(r) - 1:
        return None  # the plateau runs off the scan
    left = delays[i - 1] + (half - r[i - 1]) / (r[i] - r[i - 1]) * (delays[i] - delays[i - 1])
    right = delays[j] + (r[j] - half) / (r[j] - r[j + 1]) * (delays[j + 1] - delays[j])
    return 0.5 * (left + right)


class _Rig:
    """The device, the window and what the checks learnt on the way."""

    def __init__(self, device, window, exposure_us):
        self.device, self.window, self.exposure_us = device, window, exposure_us

    def show(self, pattern) -> None:
        self.window.show(pattern(self.window.shape))

    def grab_at(self, delay_us, exposure_us=None) -> np.ndarray:
        self.device.set_timing(float(delay_us), float(exposure_us or self.exposure_us))
        return np.asarray(self.device.grab()[0], np.float64)


def _frame_rate(window, frame_rate_hz):
    return frame_rate_hz or (window.screen.refresh_hz if window is not None else None) or DEFAULT_FRAME_RATE_HZ


def check_rig(
    open_device: Callable[[], object],
    screen,
    *,
    display: str | None = None,
    delay_zero_us: float | None = None,
    sweep: Sweep | None = None,
    exposure_us: float = 600.0,
    frame_rate_hz: float | None = None,
    report: Callable[[Check], None] | None = None,
    window: ProjectorWindow | None = None,
) -> list[Check]:
    """Run every check of the rig and return one :class:`Check` per check.

    Parameters
    ----------
    open_device : callable
        Opens the camera (called twice: the second time proves the first released it).
    screen : int
        The projector's screen (``--screen``).
    display : str, optional
        X display (default ``$DISPLAY``).
    delay_zero_us : float, optional
        The calibrated delay zero (commanded delay of the true epipolar centre) for a
        device without a base trigger delay; a device with one has its delay zero at
        0 by construction.  None and no base: the check is skipped.
    sweep : Sweep
        The sweep the rig must serve (default: the paper's).
    exposure_us : float
        Exposure of the check's images (us).
    frame_rate_hz : float, optional
        The projector's frame rate (default: the screen's, else 60 Hz).
    report : callable, optional
        Called with each check as it completes.
    window : ProjectorWindow, optional
        An open window on ``screen`` to use (and leave open); default: one opened and closed here.

    Returns
    -------
    list of Check

    See Also
    --------
    capture_comb : the comb capture it includes.

    Examples
    --------
    On a rig (a projector screen and a camera; tests/test_rig.py runs it on a simulated rig and a
    two-screen Xvfb):

    >>> from planeray.devices import open_device
    >>> from planeray.projector import get_screen
    >>> checks = check_rig(lambda: open_device("ueye"), get_screen(1))  # doctest: +SKIP
    >>> [(c.name, c.status) for c in checks]  # doctest: +SKIP
    [('trigger', 'pass'), ('row time', 'pass'), ...]
    """
    sweep = sweep or paper_sweep()
    checks: list[Check] = []

    def add(check: Check) -> Check:
        checks.append(check)
        if report is not None:
            report(check)
        return check

    try:
        device = open_device()
    except (DeviceError, InputError) as exc:
        add(Check("camera", "fail", f"cannot open the camera: {exc}", "no_camera"))
        return checks
    own = window is None
    try:
        window = _check_window(screen, display, add, window)
        _run(device, window, screen, display, delay_zero_us, sweep, exposure_us, frame_rate_hz, add)
    finally:
        if window is not None and own:
            window.close()
        close = getattr(device, "close", None)
        if close is not None:
            close()
    try:  # released: the camera opens again
        again = open_device()
        getattr(again, "close", lambda: None)()
        add(Check("camera", "pass", f"{getattr(device, 'kind', 'device')} found, and released (it opened again)"))
    except (DeviceError, InputError) as exc:
        add(Check("camera", "fail", f"the camera did not open again after closing ({exc}): restart it", "not_released"))
    return checks


def _check_window(screen, display, add, window=None):
    try:
        window = window or ProjectorWindow(screen, display=display)
    except (DeviceError, InputError) as exc:
        add(Check("window", "fail", f"the projector window did not open on screen {screen}: {exc}", "no_window"))
        return None
    card = rectification_card(window.shape)
    window.show(card)
    shot = grab_screen(window.screen)
    if np.array_equal(shot[:, :, 0], card):
        add(Check("window", "pass", f"up on screen {screen} ({window.shape[1]}x{window.shape[0]}), read back exactly"))
        return window
    others = [s.index for s in list_screens(display) if s.index != window.screen.index and s.shape == window.shape]
    where = [i for i in others if np.array_equal(grab_screen(list_screens(display)[i])[:, :, 0], card)]
    if where:
        add(
            Check(
                "window",
                "fail",
                f"the window opened on screen {where[0]}, not on screen {screen}: check DISPLAY and the window "
                "manager's placement",
                "window_elsewhere",
            )
        )
    else:
        wrong = int(np.count_nonzero(np.any(shot[:, :, 0:1] != card[:, :, None], axis=2)))
        add(
            Check(
                "window",
                "fail",
                f"screen {screen} does not show the pattern pixel for pixel ({wrong} pixels differ): a compositor, "
                "scaling or colour management is in the way; switch them off for this screen",
                "window_altered",
            )
        )
    return window


def _run(device, window, screen, display, delay_zero_us, sweep, exposure_us, frame_rate_hz, add) -> None:
    rig = _Rig(device, window, exposure_us)
    rate = _frame_rate(window, frame_rate_hz)
    base = getattr(device, "base_trigger_delay_us", None)
    expected = 0.0 if base is not None else delay_zero_us
    centre = 0.0 if expected is None else expected

    # ranges first: they need no light
    _check_ranges(device, sweep, base, add)

    # trigger: frames arrive, at the projector's frame rate
    if window is not None:
        rig.show(white)
    try:
        white_img = rig.grab_at(centre)
    except DeviceError as exc:
        add(Check("trigger", "fail", f"{exc}", "no_trigger"))
        for name in ("projector light", "rolling shutter", "linearity", "row time", "delay zero"):
            add(Check(name, "skip", "no frames (fix the trigger first)"))
        return
    _check_trigger(device, rate, add)

    # projector light: white brighter than black
    if window is None:
        for name in ("projector light", "rolling shutter", "linearity", "row time", "delay zero"):
            add(Check(name, "skip", "no projector window (fix the window first)"))
        return
    rig.show(black)
    black_img = rig.grab_at(centre)
    if not _lit(white_img, black_img):
        add(_find_projector(rig, screen, display, centre))
        for name in ("rolling shutter", "linearity", "row time", "delay zero"):
            add(Check(name, "skip", "no projector light (fix that first)"))
        return
    add(Check("projector light", "pass", f"the camera sees the window on screen {screen}"))

    rolling = _check_shutter(device, white_img - black_img, add)
    rig.show(white)
    if not rolling:
        for name in ("linearity", "row time", "delay zero"):
            add(Check(name, "skip", "not in rolling shutter (fix that first)"))
        return
    _check_linearity(rig, rate, add)
    row_ok, scan = _check_row_time(rig, centre, add)
    if expected is None:
        add(
            Check(
                "delay zero", "skip", "no calibrated delay zero: run calibrate delay-zero --write, then --calibration"
            )
        )
    elif not row_ok:
        add(Check("delay zero", "skip", "the row time is off (fix that first)"))
    else:
        _check_delay_zero(rig, expected, scan, add)


def _check_ranges(device, sweep, base, add) -> bool:
    exposures = np.asarray(sweep.exposure_us, float)
    e_lo, e_hi = float(exposures.min()), float(exposures.max())
    if has(device, "ranges"):
        lo, hi = device.get_exposure_range_us()
    elif hasattr(device, "exposure_range_us"):
        lo, hi = device.exposure_range_us
    else:
        add(Check("ranges", "skip", "the device does not say which exposures it can realize"))
        return True
    if not (lo <= e_lo and e_hi <= hi):
        add(
            Check(
                "ranges",
                "fail",
                f"exposures {lo:g}..{hi:g} us cannot reach the sweep's {e_lo:g}..{e_hi:g} us: lower the pixel clock "
                "or the frame rate (longer exposures), or load a parameter file that allows them",
                "exposure_range",
                {"exposure_range_us": [lo, hi], "sweep_exposure_us": [e_lo, e_hi]},
            )
        )
        return False
    text = f"exposures {lo:g}..{hi:g} us cover the sweep's {e_lo:g}..{e_hi:g} us"
    if base is not None:
        d_lo, d_hi = device.get_trigger_delay_range_us() if has(device, "ranges") else device.trigger_delay_range_us
        lps = device.lines_per_second
        t_o = np.array(
            [sync_offset_from_delay(d, e, lines_per_second=lps) for d, e in zip(sweep.delay_us, sweep.exposure_us)]
        )
        need = (base - float(t_o.max()), base - float(t_o.min()))
        if not (d_lo <= need[0] and need[1] <= d_hi):
            add(
                Check(
                    "ranges",
                    "fail",
                    f"the sweep needs trigger delays {need[0]:.0f}..{need[1]:.0f} us, the camera has {d_lo:g}..{d_hi:g}"
                    " us: calibrate delay-zero again (it picks a base that fits)",
                    "trigger_delay_range",
                )
            )
            return False
        text += f"; trigger delays {need[0]:.0f}..{need[1]:.0f} us within {d_lo:g}..{d_hi:g} us"
    add(Check("ranges", "pass", text))
    return True


def _check_trigger(device, rate, add) -> None:
    period = 1.0 / rate
    if not has(device, "frame_times"):
        add(
            Check(
                "trigger", "pass", "frames arrive on the trigger (the camera gives no time stamps: rate not measured)"
            )
        )
        return
    times = np.asarray(device.frame_times_s(), float)
    if times.size < 2:
        add(Check("trigger", "pass", "frames arrive on the trigger (one frame: rate not measured)"))
        return
    step = float(np.median(np.diff(times)))
    if abs(step - period) <= 0.05 * period:
        add(Check("trigger", "pass", f"a frame every {step * 1e3:.2f} ms: the projector's {rate:g} Hz"))
        return
    n = step / period
    hint = (
        f"a frame every {round(n)} VSYNCs: exposure plus read-out is longer than a projector frame"
        if n > 1.5 and abs(n - round(n)) < 0.1
        else "the camera is not triggered by VSYNC (free-running?)"
    )
    add(Check("trigger", "fail", f"a frame every {step * 1e3:.2f} ms, not {period * 1e3:.2f} ms: {hint}", "frame_rate"))


def _lit(white_img, black_img) -> bool:
    """Whether white adds light to black in some rows (a global shutter lights only a band of them)."""
    light = white_img - black_img
    rows = light.mean(axis=1)
    noise = float(np.std(light - rows[:, None])) / math.sqrt(light.shape[1]) + 1e-9
    return float(np.max(rows)) > max(6.0 * noise, 0.003)


def _find_projector(rig, screen, display, centre) -> Check:
    """No light from the window: try the other screens, and say which one the projector shows."""
    reference = rig.grab_at(centre)  # black on every screen
    for other in list_screens(display):
        if other.index == screen:
            continue
        with ProjectorWindow(other, display=display) as probe:
            probe.show(white(probe.shape))
            if _lit(rig.grab_at(centre), reference):
                return Check(
                    "projector light",
                    "fail",
                    f"the projector shows screen {other.index}, not screen {screen}: run with --screen {other.index} "
                    f"(or plug the projector into the output of screen {screen})",
                    "other_screen",
                    {"projector_screen": other.index},
                )
    return Check(
        "projector light",
        "fail",
        f"white on screen {screen} is no brighter than black, nor on any other screen: is the projector on, its "
        "laser enabled, and the camera looking at a white target through an open lens?",
        "no_light",
    )


def _check_shutter(device, light, add) -> bool:
    rows = light.mean(axis=1)
    lit = float(np.mean(rows > 0.5 * np.percentile(rows, 95)))
    if has(device, "global_shutter"):  # read back: a camera may ignore the request for rolling
        mode = device.get_shutter()
        if mode != "rolling":
            add(
                Check(
                    "rolling shutter",
                    "fail",
                    f"the camera is in {mode} shutter ({lit:.0%} of its rows lit at delay zero): select the rolling "
                    "shutter (uEye Cockpit or a parameter file that does not force global)",
                    "global_shutter",
                    {"lit_rows": lit},
                )
            )
            return False
        add(Check("rolling shutter", "pass", f"selected (read back); {lit:.0%} of the rows lit at delay zero"))
        return True
    if lit < 0.5:
        add(
            Check(
                "rolling shutter",
                "fail",
                f"only {lit:.0%} of the rows are lit at delay zero: the camera is in global shutter (select rolling)",
                "global_shutter",
            )
        )
        return False
    add(Check("rolling shutter", "pass", f"{lit:.0%} of the rows lit at delay zero"))
    return True


def _check_linearity(rig, rate, add) -> None:
    device = rig.device
    period_us = 1e6 / rate
    lo, hi = device.get_exposure_range_us() if has(device, "ranges") else getattr(device, "exposure_range_us", (0, 0))
    reported = device.get_gamma() if has(device, "gamma") else None
    if not (lo <= period_us and 2 * period_us <= hi):
        text = f"the camera's exposures {lo:g}..{hi:g} us do not reach two projector frames ({2 * period_us:.0f} us)"
        if reported is not None and abs(reported - 1.0) > 1e-6:
            add(Check("linearity", "fail", f"the camera reports gamma {reported:g}: set it to 1 ({text})", "gamma"))
        else:
            add(Check("linearity", "skip", text))
        return
    one = rig.grab_at(0.0, period_us)  # a whole frame: every row sees the raster once, any delay
    two = rig.grab_at(0.0, 2 * period_us)
    rig.device.set_timing(0.0, rig.exposure_us)
    use = (one > 0.02) & (two < 0.95)
    if np.count_nonzero(use) < 10:
        add(Check("linearity", "skip", "too dark or too bright for the two-exposure test (need 2-95 % of full scale)"))
        return
    ratio = float(np.median(two[use] / one[use]))
    gamma_text = "" if reported is None else f"; the camera reports gamma {reported:g}"
    if abs(ratio / 2.0 - 1.0) > LINEARITY_TOLERANCE:
        add(
            Check(
                "linearity",
                "fail",
                f"twice the light gave {ratio:.2f} times the value, not 2{gamma_text}: switch gamma, the LUT and every "
                "auto feature off, and subtract the right black level",
                "gamma",
                {"ratio": ratio, "gamma": reported},
            )
        )
        return
    add(
        Check(
            "linearity",
            "pass",
            f"twice the light gave {ratio:.3f} times the value{gamma_text}",
            details={"ratio": ratio},
        )
    )


def _scan(rig, centre, half_width_us, step_us):
    delays = centre + np.arange(-half_width_us, half_width_us + 0.5 * step_us, step_us)
    return delays, np.stack([rig.grab_at(d) for d in delays])


def _check_row_time(rig, centre, add):
    device = rig.device
    delays, images = _scan(rig, centre, 1500.0, SCAN_STEP_US)
    H = images.shape[1]
    bands = 4
    edges = np.linspace(0, H, bands + 1).astype(int)
    rows_mid, centres = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        z = _band_centre(delays, images[:, a:b].mean(axis=(1, 2)))
        if z is not None:
            rows_mid.append(0.5 * (a + b - 1))
            centres.append(z)
    scan = (delays, images)
    if len(centres) < 2:
        add(
            Check(
                "row time",
                "fail",
                "no epipolar response found in the delay scan's rows: the camera's rows do not advance with the "
                "projector's (row time far off: set the pixel clock) or the delay zero is far from the calibration",
                "row_time",
            )
        )
        return False, scan
    # camera rows -> projector rows (the rig is rectified: the image spans the projector's rows)
    P = rig.window.shape[0]
    proj = np.asarray(rows_mid) * P / H
    slope_us_per_row = float(np.polyfit(proj, centres, 1)[0])
    error = slope_us_per_row * device.lines_per_second * 1e-6
    reported = ""
    if has(device, "row_time"):
        reported = f"; the camera reports {device.get_row_time_us():.3f} us per row"
    details = {"row_time_error": error, "slope_us_per_projector_row": slope_us_per_row}
    if abs(error) > ROW_TIME_TOLERANCE:
        add(
            Check(
                "row time",
                "fail",
                f"the camera's rows advance {abs(error):.1%} {'slower' if error > 0 else 'faster'} than the projector's "
                f"(the epipolar centre moves {slope_us_per_row:.2f} us per projector row){reported}: adjust the pixel "
                "clock until they match, then calibrate lines again",
                "row_time",
                details,
            )
        )
        return False, scan
    add(
        Check(
            "row time", "pass", f"matches the projector's line velocity to {abs(error):.2%}{reported}", details=details
        )
    )
    return True, scan


def _check_delay_zero(rig, expected, scan, add) -> None:
    delays, images = scan
    measured = _band_centre(delays, images.mean(axis=(1, 2)))
    if measured is not None and abs(measured - expected) <= DELAY_ZERO_TOLERANCE_US:
        add(
            Check(
                "delay zero",
                "pass",
                f"the epipolar response peaks at {measured:+.1f} us, the calibrated {expected:+.1f} us",
                details={"measured_us": measured},
            )
        )
        return
    device = rig.device
    if has(device, "trigger_edge"):  # the other edge: a pulse width away
        edge = device.get_trigger_edge()
        other = "falling" if edge == "rising" else "rising"
        device.set_trigger_edge(other)
        try:
            d2, i2 = _scan(rig, expected, 1500.0, SCAN_STEP_US)
            there = _band_centre(d2, i2.mean(axis=(1, 2)))
        finally:
            device.set_trigger_edge(edge)
        if there is not None and abs(there - expected) <= DELAY_ZERO_TOLERANCE_US:
            add(
                Check(
                    "trigger edge",
                    "fail",
                    f"the camera triggers on the {edge} edge of VSYNC, the rig was calibrated on the {other} one (there "
                    f"the epipolar response peaks at {there:+.1f} us, the calibrated {expected:+.1f} us): set "
                    f"-O trigger_edge={other}",
                    "trigger_edge",
                    {"measured_us": measured, "other_edge_us": there},
                )
            )
            return
    where = "nowhere in the scan" if measured is None else f"at {measured:+.1f} us"
    add(
        Check(
            "delay zero",
            "fail",
            f"the epipolar response peaks {where}, not at the calibrated {expected:+.1f} us: calibrate delay-zero again",
            "delay_zero",
            {"measured_us": measured},
        )
    )
