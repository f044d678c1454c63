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

For a camera triggered by the projector's VSYNC the delay zero fixes the
camera's **base trigger delay** (the trigger delay at ``t'_o = 0``, defined up
to whole projector frames): :func:`calibrate_base_trigger_delay` finds it on the
device (a coarse search over one frame, then the fine delay zero) and
:func:`with_base_trigger_delay` converts a delay zero measured with a known base
(:mod:`planeray.calibration.trigger`).

:func:`write_calibration` stores the results in a capture folder's
``acquisition.json`` (the field ``lines_per_second`` that the stack import
requires, plus the uncertainties, the delay zero and the base trigger delay
that ``planeray acquire --calibration`` reads), keeping every other field.

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

from ..linesweep import PAPER_CALIBRATION_EXPOSURE_US, LineSweep
from .delay_zero import (
    DelayZeroCalibration,
    calibrate_delay_zero,
    delay_zero_sweep,
    device_capture,
)
from .files import read_line_sweep, write_calibration, write_line_sweep
from .lines import LineCalibration, LineCount, calibrate_lines_per_second, count_lines
from .trigger import (
    PROJECTOR_FRAME_PERIOD_US,
    calibrate_base_trigger_delay,
    calibrate_delay_zero_from_stack,
    required_base_trigger_delay_us,
    search_delay_zero,
    with_base_trigger_delay,
)

__all__ = [
    "PAPER_CALIBRATION_EXPOSURE_US",
    "LineSweep",
    "LineCount",
    "LineCalibration",
    "DelayZeroCalibration",
    "count_lines",
    "calibrate_lines_per_second",
    "calibrate_delay_zero",
    "calibrate_delay_zero_from_stack",
    "delay_zero_sweep",
    "device_capture",
    "PROJECTOR_FRAME_PERIOD_US",
    "calibrate_base_trigger_delay",
    "required_base_trigger_delay_us",
    "search_delay_zero",
    "with_base_trigger_delay",
    "read_line_sweep",
    "write_line_sweep",
    "write_calibration",
]
