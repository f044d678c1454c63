"""The base trigger delay of a camera triggered by the projector's VSYNC (Sec. 6, Eq. 1).

A camera triggered by VSYNC starts row ``r``'s exposure at ``D + c + r t_p``
(``D`` its trigger delay, ``c`` a fixed latency, rows advancing with the
projector's), while the projector lights the matching row at ``a + r t_p``; so
the sync offset of Eq. 1 is ``t'_o = B - D`` with a constant ``B``, the **base
trigger delay**.  A point ``(t_d, t_e)`` of a sweep is realized by the trigger
delay ``D = B - t'_o = B - (t_e/2 - t_p/2 - t_d)``.

``B`` is defined up to whole projector frames (the raster repeats every frame:
a trigger delay one frame longer exposes the next frame at the same phase), and
since trigger delays cannot be negative it must exceed the largest ``t'_o`` of
every sweep to be captured -- 2091 us for the paper's sweep (``t_d = -1500``,
``t_e = 1200``).  :func:`calibrate_base_trigger_delay` finds it on the device:

1. a **coarse search** over one projector frame, from a provisional base
   ``B_0`` (the least the sweeps need): commanded delays every ``t_e / 3``
   from ``-t_e`` to one frame and a bit, on a diffuse target, and the first
   epipolar response (a plateau about ``t_e`` wide) centred at ``c >= 0`` gives
   ``B_1 = B_0 + c >= B_0`` to a fraction of the step;
2. the **fine** delay-zero calibration (:func:`calibrate_delay_zero`) around
   ``B_1`` gives the commanded delay of the true ``t_d = 0``, ``delay_zero_us``,
   to a fraction of a microsecond, and ``B = B_1 + delay_zero_us``.

A delay-zero calibration captured with a known base (a stack recorded by the
uEye driver, whose metadata holds ``base_trigger_delay_us``) converts the same
way: :func:`with_base_trigger_delay`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import replace

import numpy as np

from ..errors import InputError
from ..timing import Sweep, sync_offset_from_delay
from ._stats import MAD_TO_SIGMA
from .delay_zero import DelayZeroCalibration, calibrate_delay_zero, delay_zero_sweep, device_capture

__all__ = [
    "calibrate_delay_zero_from_stack",
    "PROJECTOR_FRAME_PERIOD_US",
    "required_base_trigger_delay_us",
    "search_delay_zero",
    "calibrate_base_trigger_delay",
    "with_base_trigger_delay",
]

#: Frame period of a 60 Hz projector (the paper's Celluon PicoPro), us.
PROJECTOR_FRAME_PERIOD_US = 1e6 / 60.0


def required_base_trigger_delay_us(
    sweeps: Iterable[Sweep], *, lines_per_second: float, min_trigger_delay_us: float = 0.0
) -> float:
    """The least base trigger delay that realizes every point of ``sweeps``: ``max t'_o + min delay``.

    Parameters
    ----------
    sweeps : iterable of Sweep
        The sweeps the base must serve.
    lines_per_second : float
        Projector scan rate, rows per second.
    min_trigger_delay_us : float
        The camera's least trigger delay, microseconds.

    Returns
    -------
    float
        Microseconds.

    See Also
    --------
    calibrate_base_trigger_delay : finds the base.

    Examples
    --------
    >>> from planeray.timing import paper_sweep
    >>> round(required_base_trigger_delay_us([paper_sweep()], lines_per_second=54_000), 1)
    2090.7
    """
    largest = -math.inf
    for sweep in sweeps:
        t_o = sync_offset_from_delay(sweep.delay_us, sweep.exposure_us, lines_per_second=lines_per_second)
        largest = max(largest, float(np.max(t_o)))
    if not math.isfinite(largest):
        raise InputError("no sweep given")
    return largest + float(min_trigger_delay_us)


def _crossing(x0, y0, x1, y1, level):
    return x0 + (level - y0) * (x1 - x0) / (y1 - y0)


def search_delay_zero(
    capture: Callable[[float], np.ndarray],
    *,
    exposure_us: float,
    frame_period_us: float = PROJECTOR_FRAME_PERIOD_US,
    step_us: float | None = None,
    roi=None,
) -> dict:
    """Coarse delay zero over one projector frame: the centre of the first epipolar response at or after 0.

    Parameters
    ----------
    capture : callable
        ``capture(delay_us) -> image`` (or ``(image, saturated)``) at ``exposure_us``,
        e.g. :func:`planeray.calibration.device_capture`.
    exposure_us : float
    frame_period_us : float
        Projector frame period; the scan covers 5 % more than that, so one
        response is always wholly inside it.
    step_us : float, optional
        Delay step (default ``t_e / 3``: three points on the plateau).
    roi : optional
        Pixels of the diffuse target (default: all).

    Returns
    -------
    dict
        ``centre_us`` (commanded delay of the response's centre, ``>= step/2``),
        ``delays_us``, ``response``, ``baseline``, ``plateau`` and ``responses``
        (centres of every complete response seen).

    Raises
    ------
    InputError
        No response over the frame (nothing changes with delay).

    See Also
    --------
    calibrate_base_trigger_delay : then refines it.

    Examples
    --------
    A camera whose epipolar response comes 5000 us after its trigger, once per 60 Hz frame:

    >>> import numpy as np
    >>> def capture(delay_us):
    ...     phase = (delay_us - 5000.0 + 8333.3) % 16666.7 - 8333.3
    ...     return np.full((4, 4), 1.0 if abs(phase) < 300.0 else 0.1)
    >>> search_delay_zero(capture, exposure_us=600.0)["centre_us"]
    5000.0
    """
    if not (exposure_us > 0 and frame_period_us > 0):
        raise InputError("exposure_us and frame_period_us must be positive")
    step = float(step_us) if step_us is not None else exposure_us / 3.0
    if not step > 0:
        raise InputError(f"step_us must be positive, got {step_us!r}")
    d = np.arange(-float(exposure_us), 1.05 * frame_period_us + exposure_us + step, step)
    resp = np.empty(d.size)
    for i, x in enumerate(d):
        im = capture(float(x))
        im = np.asarray(im[0] if isinstance(im, tuple) else im, dtype=np.float64)
        sel = im[roi] if roi is not None else im
        if sel.size == 0 or not np.all(np.isfinite(sel)):
            raise InputError(f"image at delay {x:g} us is empty or not finite")
        resp[i] = sel.mean()
    base = float(np.median(resp))
    noise = MAD_TO_SIGMA * float(np.median(np.abs(resp - base)))
    top = float(resp.max())
    if not top - base > max(10.0 * noise, 1e-9):
        raise InputError(
            "no epipolar response over one projector frame: check that the projector lights the target, "
            "that its VSYNC triggers the camera, and the exposure"
        )
    half = base + 0.5 * (top - base)
    above = resp > half
    centres = []
    i = 0
    while i < d.size:
        if not above[i]:
            i += 1
            continue
        j = i
        while j + 1 < d.size and above[j + 1]:
            j += 1
        if i > 0 and j < d.size - 1:  # a response cut by the scan's ends is not located
            left = _crossing(d[i - 1], resp[i - 1], d[i], resp[i], half)
            right = _crossing(d[j], resp[j], d[j + 1], resp[j + 1], half)
            centres.append(0.5 * (left + right))
        i = j + 1
    chosen = [c for c in centres if c >= 0.5 * step]
    if not chosen:
        raise InputError(
            f"no complete epipolar response between delays {0.5 * step:g} and {d[-1]:g} us: "
            "is the projector's frame period longer than frame_period_us?"
        )
    return {
        "centre_us": float(chosen[0]),
        "step_us": step,
        "delays_us": d.tolist(),
        "response": resp.tolist(),
        "baseline": base,
        "plateau": top,
        "responses": [float(c) for c in centres],
    }


def with_base_trigger_delay(result: DelayZeroCalibration, base_used_us: float) -> DelayZeroCalibration:
    """The calibration with ``base_trigger_delay_us = base_used_us + delay_zero_us``.

    ``base_used_us`` is the base trigger delay with which the fine delay sweep
    was captured: the commanded delay ``delay_zero_us`` then realizes the true
    ``t_d = 0``, so that base plus ``delay_zero_us`` is the trigger delay at
    ``t'_o = 0``.

    Parameters
    ----------
    result : DelayZeroCalibration
        The fine delay zero, measured with ``base_used_us``.
    base_used_us : float
        The base trigger delay of that sweep, microseconds.

    Returns
    -------
    DelayZeroCalibration

    See Also
    --------
    calibrate_base_trigger_delay : uses it.

    Examples
    --------
    >>> from planeray.calibration import DelayZeroCalibration
    >>> cal = DelayZeroCalibration(37.5, 0.2, 253.2, 290.7, 600.0, 600.0)
    >>> with_base_trigger_delay(cal, 5000.0).base_trigger_delay_us
    5037.5
    """
    details = dict(result.details, base_used_us=float(base_used_us))
    return replace(result, base_trigger_delay_us=float(base_used_us) + result.delay_zero_us, details=details)


def calibrate_base_trigger_delay(
    device,
    *,
    exposure_us: float = 600.0,
    sweeps: Iterable[Sweep] = (),
    base_trigger_delay_us: float | None = None,
    frame_period_us: float = PROJECTOR_FRAME_PERIOD_US,
    step_us: float = 10.0,
    roi=None,
) -> DelayZeroCalibration:
    """Find a camera's base trigger delay on a diffuse target: coarse search, then the fine delay zero.

    Parameters
    ----------
    device : Device
        A device with a settable ``base_trigger_delay_us`` (e.g. the uEye
        driver) and, optionally, ``trigger_delay_range_us = (min, max)``.
    exposure_us : float
        Row exposure of the calibration sweeps.
    sweeps : iterable of Sweep
        The sweeps the base must serve (e.g. the paper's): the result is at
        least their largest ``t'_o`` plus the camera's least trigger delay.
    base_trigger_delay_us : float, optional
        A known base to refine: skips the coarse search.
    frame_period_us : float
        Projector frame period, for the coarse search's range.
    step_us : float
        Step of the fine sweep.
    roi : optional
        Pixels of the diffuse target.

    Returns
    -------
    DelayZeroCalibration
        The fine calibration with ``base_trigger_delay_us`` set; ``details``
        hold ``base_used_us``, ``required_base_us``, ``fits_sweeps`` and the
        coarse ``search``.  The device is left at the calibrated base.

    See Also
    --------
    search_delay_zero : the coarse search.
    planeray.calibrate_delay_zero : the fine delay zero.

    Examples
    --------
    On a camera whose trigger delay is settable (here the uEye driver; tests/test_ueye.py runs it on a
    stand-in SDK):

    >>> import planeray as pr
    >>> from planeray.timing import paper_sweep
    >>> with pr.devices.open_device("ueye", parameter_file="rig/episcan.ini") as cam:  # doctest: +SKIP
    ...     cal = calibrate_base_trigger_delay(cam, sweeps=[paper_sweep()])
    ...     cal.base_trigger_delay_us
    """
    v_p = float(device.lines_per_second)
    t_p = 1e6 / v_p
    dmin = float(getattr(device, "trigger_delay_range_us", (0.0, math.inf))[0])
    fine = delay_zero_sweep(exposure_us, step_us=step_us)
    sweeps = list(sweeps)
    need_sweeps = required_base_trigger_delay_us(sweeps + [fine], lines_per_second=v_p, min_trigger_delay_us=dmin)
    search = None
    if base_trigger_delay_us is None:
        # the coarse scan starts at t_d = -t_e, where t'_o = 1.5 t_e - t_p/2
        start = 1.5 * exposure_us - 0.5 * t_p + dmin
        base0 = math.ceil(max(need_sweeps, start))
        device.base_trigger_delay_us = base0
        search = search_delay_zero(
            device_capture(device, exposure_us=exposure_us),
            exposure_us=exposure_us,
            frame_period_us=frame_period_us,
            roi=roi,
        )
        base1 = base0 + search["centre_us"]
        search["base_used_us"] = float(base0)
    else:
        base1 = float(base_trigger_delay_us)
        if base1 < need_sweeps:
            raise InputError(
                f"base trigger delay {base1:g} us is below {need_sweeps:.1f} us, the least that the sweeps and the "
                "delay-zero sweep need: add one projector frame to it, or leave it out to search"
            )
    device.base_trigger_delay_us = base1
    result = calibrate_delay_zero(
        device_capture(device, exposure_us=exposure_us),
        fine.delay_us,
        exposure_us=exposure_us,
        lines_per_second=v_p,
        roi=roi,
    )
    result = with_base_trigger_delay(result, base1)
    need = required_base_trigger_delay_us(sweeps, lines_per_second=v_p, min_trigger_delay_us=dmin) if sweeps else dmin
    result.details.update(required_base_us=float(need), fits_sweeps=bool(result.base_trigger_delay_us >= need))
    if search is not None:
        result.details["search"] = search
    device.base_trigger_delay_us = result.base_trigger_delay_us
    return result


def calibrate_delay_zero_from_stack(stack, *, exposure_us: float = 600.0, source=None):
    """:func:`calibrate_delay_zero` on a captured fine delay sweep around 0 (``planeray calibrate delay-zero STACK``).

    Uses the stack's images at ``exposure_us``; a stack captured by the uEye driver records the
    base trigger delay it was captured with, and the result then holds the camera's base too
    (:func:`~planeray.calibration.with_base_trigger_delay`).

    Parameters
    ----------
    stack : Stack
        The capture (at least 5 images at ``exposure_us``).
    exposure_us : float
        Exposure of the sweep's images to use, us.
    source : str or os.PathLike, optional
        The stack's file, named in messages.

    Returns
    -------
    DelayZeroCalibration

    See Also
    --------
    planeray.calibrate_delay_zero : the calibration itself.

    Examples
    --------
    A fine delay sweep around 0 captured on the simulated device:

    >>> import planeray as pr
    >>> from planeray.calibration import delay_zero_sweep
    >>> scene = pr.make_scene("diffuse_plane", (16, 16), projector_rows=90, seed=0)
    >>> stack = pr.simulate_stack(scene, delay_zero_sweep(600.0, step_us=20.0), seed=1)
    >>> abs(calibrate_delay_zero_from_stack(stack).delay_zero_us) < 10.0
    True
    """
    from ..errors import parameter_name

    where = "the stack" if source is None else str(source)
    idx = np.flatnonzero(np.isclose(stack.exposure_us, exposure_us))
    if idx.size < 5:
        have = ", ".join(f"{e:g}" for e in stack.exposures())
        raise InputError(
            f"{where}: needs at least 5 images at {parameter_name('exposure_us')} {exposure_us:g}, found {idx.size} "
            f"(its exposures: {have} us)"
        )
    images = np.stack([stack.image(int(i)) for i in idx])
    try:
        result = calibrate_delay_zero(
            images, stack.delay_us[idx], exposure_us=exposure_us, lines_per_second=stack.lines_per_second
        )
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    base_used = (stack.metadata or {}).get("base_trigger_delay_us")
    if isinstance(base_used, (int, float)) and not isinstance(base_used, bool):
        result = with_base_trigger_delay(result, float(base_used))
    return result
