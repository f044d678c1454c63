"""Conventional (unsynchronized) projector-camera baselines the paper compares against (Secs. 2, 5.1).

Two things an ordinary projector-camera can do without the synchronized
rolling shutter, both driving any device with
``capture_pattern(pattern, exposure_us, frame_period_us)`` (a full-frame
exposure under a per-projector-row pattern, e.g.
:meth:`planeray.devices.simulated.SimulatedEpiscan.capture_pattern`):

* **Direct/global separation with high-frequency patterns** (Nayar et al.
  2006, the baseline of Sec. 2).  Our transport is plane-to-ray: a pattern is
  one intensity per projector *row*, so the "high-frequency pattern" is a set of
  horizontal stripes, shifted over one period.  Per pixel, ``L+ = max`` and
  ``L- = min`` over the shifted captures give ``direct = L+ - L-`` and
  ``global = 2 L-`` (with the correction for a projector whose dark rows still
  emit a fraction ``b``).  It assumes the global light of a pixel varies smoothly
  over the stripe period -- true for diffuse interreflections and broad
  subsurface scattering, false for specular interreflections, which bring a
  sharp image of far projector rows that the stripes switch on and off.
  Epipolar imaging [3]_ has no such assumption: it keeps only the light of a
  band around the camera row's own epipolar plane.

* **Digital epipolar (delay) imaging** (Sec. 5.1, Fig. 4): project a horizontal
  band of width ``I_w = v_p t_e`` centred ``I_d = v_p t_d`` rows from camera row
  ``t``, keep camera row ``t`` of that capture, move the band one row and repeat;
  the kept rows form the delay image that the synchronized device captures in one
  exposure.  It needs one capture per camera row (``H`` captures, plus a dark
  frame) instead of one.

Conventions
-----------
Images returned here are in **transport units** (Eq. 4 units, the units of
``Scene.direct`` and ``Transport.render``): the normalized camera image minus a
dark frame (projector off, same exposure), divided by the number of projector
passes in the exposure (``exposure_us / frame_period_us``) and by the camera's
``signal_scale`` (normalized value per unit of Eq. 4).

Geometry of the stripes
-----------------------
A camera row spans ``f = P / H`` projector rows (5.625 for 128 camera rows of a
720-row projector).  Seen through the transport's offset bins its direct light
comes from projector coordinates within ``p_t +- (ceil(f)/2 + 1)``, i.e. up to
``ceil(f) + 2`` projector rows.  ``max - min`` recovers the direct light only if
some shift lights all of them and another darkens all of them, so each half
period must be at least that wide: :func:`default_period_rows` gives
``2 (ceil(f) + 2)`` rows -- 6 rows when ``P = H``, 16 rows (2.8 camera rows)
for ``P = 720, H = 128`` -- shifted one projector row at a time (``n_shifts =
period``).  Shorter periods mix direct light into ``L-``; longer ones weaken the
smoothness assumption on the global light.

References
----------
.. [1] S. K. Nayar, G. Krishnan, M. D. Grossberg, R. Raskar, "Fast separation of
   direct and global components of a scene using high frequency illumination",
   ACM Trans. Graph. 25(3) (SIGGRAPH 2006), 935-944.
.. [2] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa,
   S. G. Narasimhan, "Programmable Non-Epipolar Indirect Light Transport:
   Capture and Analysis", IEEE TVCG 2019, Sec. 2 and Sec. 5.1 (Fig. 4).
.. [3] M. O'Toole, S. Achar, S. G. Narasimhan, K. N. Kutulakos, "Homogeneous
   codes for energy-efficient illumination and imaging", SIGGRAPH 2015 (Episcan3D,
   synchronized epipolar imaging).
"""

from ._device import DEFAULT_FRAME_PERIOD_US, PatternDevice
from .compare import (
    compare_direct_global,
    compare_emulation,
    deliverable_direct,
    synchronized_delay_image,
)
from .emulation import EmulationResult, band_pattern, emulate_delay_image
from .nayar import (
    DirectGlobalResult,
    capture_direct_global,
    default_period_rows,
    separate_direct_global,
    stripe_patterns,
)

__all__ = [
    "PatternDevice",
    "DEFAULT_FRAME_PERIOD_US",
    "default_period_rows",
    "stripe_patterns",
    "separate_direct_global",
    "DirectGlobalResult",
    "capture_direct_global",
    "band_pattern",
    "EmulationResult",
    "emulate_delay_image",
    "synchronized_delay_image",
    "deliverable_direct",
    "compare_direct_global",
    "compare_emulation",
]
