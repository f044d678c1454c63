"""Calibration captures under program control: the projector window shows, the camera captures (Sec. 6).

:func:`capture_comb` is the line-velocity capture of Sec. 6 (design in
:mod:`planeray.calibration`): the window shows each phase of a comb of rows
``k`` apart, and the camera, switched to its global shutter, takes one
exposure of ``t_e`` (the paper: 500 us) opened at a fixed delay after VSYNC, so
that every phase sees the same exposure window; then a dark frame (black) and a
flat frame (white, ``2 t_e`` opened ``t_e / 2`` earlier).  The result is the
:class:`~planeray.linesweep.LineSweep` that
:func:`planeray.calibration.calibrate_lines_per_second` counts.
"""

from __future__ import annotations

import numpy as np

from ..devices.capabilities import require
from ..errors import InputError
from ..linesweep import PAPER_CALIBRATION_EXPOSURE_US, LineSweep
from ..projector import black, comb, white

__all__ = ["capture_comb", "DEFAULT_COMB_STEP_ROWS", "DEFAULT_FRAME_RATE_HZ"]

#: Comb step ``k`` (projector rows between lit rows) when none is given.
DEFAULT_COMB_STEP_ROWS = 8
#: The projector's frame rate when the X server does not say (the paper's PicoPro: 60 Hz).
DEFAULT_FRAME_RATE_HZ = 60.0


def _check_light(dark, flat, screen_index, trigger_delay_us) -> None:
    """Refuse a capture in which the projector's white adds no light to its black (the flat's exposure is 2 t_e)."""
    from ..errors import DeviceError

    light = flat - 2.0 * dark  # the dark frame's ambient, scaled to the flat's exposure
    gain = float(np.mean(light))
    noise = float(np.std(light)) / np.sqrt(light.size)
    if gain < max(5.0 * noise, 0.01 * float(np.mean(flat))):
        raise DeviceError(
            f"the camera sees no projector light: white on screen {screen_index} is no brighter than black "
            f"(mean difference {gain:.2g}): is the projector on, showing screen {screen_index}, and the exposure "
            f"opened inside its raster (trigger delay {trigger_delay_us:g} us; --trigger-delay-us)?"
        )


def capture_comb(
    device,
    window,
    *,
    exposure_us: float = PAPER_CALIBRATION_EXPOSURE_US,
    line_step_rows: int = DEFAULT_COMB_STEP_ROWS,
    trigger_delay_us: float | None = None,
    frame_rate_hz: float | None = None,
    references: bool = True,
    timing_jitter_us: float | None = None,
    progress=None,
) -> LineSweep:
    """Show every phase of a comb and capture each with one global-shutter exposure.

    Parameters
    ----------
    device : Device with the ``global_shutter`` capability
        The camera (:mod:`planeray.devices.capabilities`); its shutter mode is
        restored afterwards.
    window : ProjectorWindow
        The projector's window (:class:`planeray.projector.ProjectorWindow`).
    exposure_us : float
        Global exposure ``t_e`` (us; the paper: 500).
    line_step_rows : int
        Comb step ``k``: lines ``k`` projector rows apart (the camera must see at
        least 6 of its rows between two lines).
    trigger_delay_us : float, optional
        When the exposure opens after VSYNC (us).  Default: mid-frame, so that the
        window and the flat frame's longer one fall inside the raster.
    frame_rate_hz : float, optional
        The projector's frame rate (default: the screen's, else 60 Hz).
    references : bool
        Capture the dark and flat frames too.
    timing_jitter_us : float, optional
        RMS error of the window's position per (averaged) image, for the
        uncertainty; default: the device's ``sync.jitter_us`` over the square root of
        its frames averaged, else 0.
    progress : callable, optional
        Called with a short text before each capture.

    Returns
    -------
    LineSweep

    Raises
    ------
    InputError
        The device has no global shutter, or the comb does not fit the screen.

    See Also
    --------
    planeray.calibrate_lines_per_second : reads what it captures.

    Examples
    --------
    On a rig, the line-velocity calibration's comb captured through the projector window (the
    simulated rig with ``-O screen=N`` and Xvfb in tests/test_rig.py):

    >>> from planeray.calibration import calibrate_lines_per_second
    >>> sweep = capture_comb(camera, window, exposure_us=500.0, line_step_rows=8)  # doctest: +SKIP
    >>> calibrate_lines_per_second(sweep).lines_per_second  # doctest: +SKIP
    54012.3
    """
    require(device, "global_shutter", "the line-velocity capture (calibrate lines --device)")
    rows, cols = window.shape
    k = int(line_step_rows)
    if not 1 <= k <= rows // 2:
        raise InputError(f"--rows-per-line must be between 1 and {rows // 2} for a {rows}-row screen, got {k}")
    if not exposure_us > 0:
        raise InputError(f"exposure must be positive, got {exposure_us}")
    rate = frame_rate_hz or window.screen.refresh_hz or DEFAULT_FRAME_RATE_HZ
    if trigger_delay_us is None:
        trigger_delay_us = max(0.5e6 / rate - 0.5 * exposure_us, exposure_us)
    if trigger_delay_us < 0.5 * exposure_us and references:
        raise InputError(
            f"trigger delay {trigger_delay_us:g} us: the flat frame opens t_e/2 = {0.5 * exposure_us:g} us earlier, "
            "so it must be at least that"
        )
    say = progress or (lambda text: None)
    before = device.get_shutter()
    device.set_shutter("global")
    try:
        dark = flat = flat_exposure = None
        if references:
            say("dark frame")
            device.set_global_timing(exposure_us, trigger_delay_us)
            window.show(black((rows, cols)))
            dark = np.asarray(device.grab()[0], np.float64)
            say("flat frame")
            window.show(white((rows, cols)))
            flat_exposure = 2.0 * exposure_us
            device.set_global_timing(flat_exposure, trigger_delay_us - 0.5 * exposure_us)
            flat = np.asarray(device.grab()[0], np.float64)
            _check_light(dark, flat, window.screen.index, trigger_delay_us)
        device.set_global_timing(exposure_us, trigger_delay_us)
        images, saturated = [], []
        for j in range(k):
            say(f"comb phase {j + 1} of {k}")
            window.show(comb((rows, cols), k, j))
            img, sat = device.grab()
            images.append(np.asarray(img, np.float64))
            saturated.append(np.asarray(sat, bool))
        window.show(black((rows, cols)))
    finally:
        device.set_shutter(before)
    description = device.describe()
    if timing_jitter_us is None:
        sync = description.get("sync", {}) if isinstance(description, dict) else {}
        frames = description.get("camera", {}).get("frames_averaged", 1) or 1
        timing_jitter_us = float(sync.get("jitter_us", 0.0)) / np.sqrt(frames)
    return LineSweep(
        np.stack(images),
        float(exposure_us),
        k,
        tuple(range(k)),
        dark,
        flat,
        flat_exposure,
        np.stack(saturated),
        timing_jitter_us=float(timing_jitter_us),
        metadata={
            "device": description,
            "screen": window.screen.to_dict(),
            "trigger_delay_us": float(trigger_delay_us),
            "captured_by": "planeray calibrate lines --device",
        },
    )
