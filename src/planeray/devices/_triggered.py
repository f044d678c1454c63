"""The timing of a camera triggered by the projector's VSYNC (Eq. 1), shared by the camera drivers."""

from __future__ import annotations

import math

from ..errors import DeviceError, InputError
from ..timing import delay_from_sync_offset, sync_offset_from_delay


class TriggeredTiming:
    """Delay and exposure of a VSYNC-triggered camera, realized through its base trigger delay (Eq. 1).

    A driver sets ``self._base`` (the base trigger delay, or None), ``self.lines_per_second``,
    ``self.delay_us``, ``self.exposure_us`` and ``self._applied`` (None: re-apply at the next grab),
    and implements ``_apply()`` (write the exposure and the trigger delay to the camera) and
    ``_read_timing()`` (the exposure and the trigger delay read back, us).
    """

    kind = "camera"

    @property
    def base_trigger_delay_us(self) -> float | None:
        """Trigger delay (us) at which ``t'_o = 0``; changing it re-applies the timing at the next grab."""
        return self._base

    @base_trigger_delay_us.setter
    def base_trigger_delay_us(self, value):
        if value is not None and not math.isfinite(value):
            raise InputError(f"base_trigger_delay_us must be a number, got {value!r}")
        self._base = None if value is None else float(value)
        self._applied = None

    def trigger_delay_for(self, delay_us: float, exposure_us: float) -> float:
        """Trigger delay (us) realizing ``(t_d, t_e)`` by Eq. 1: ``base - (t_e/2 - t_p/2 - t_d)``."""
        if self._base is None:
            raise DeviceError(
                f"the base trigger delay is not calibrated: run `planeray calibrate delay-zero --device {self.kind} "
                "--write acquisition.json` and pass --calibration acquisition.json (or --base-trigger-delay-us)"
            )
        t_o = float(sync_offset_from_delay(delay_us, exposure_us, lines_per_second=self.lines_per_second))
        return self._base - t_o

    def set_delay(self, delay_us: float) -> None:
        if not math.isfinite(delay_us):
            raise InputError(f"delay must be a number, got {delay_us!r}")
        self.delay_us = float(delay_us)

    def set_exposure(self, exposure_us: float) -> None:
        if not (math.isfinite(exposure_us) and exposure_us > 0):
            raise DeviceError(f"exposure must be positive, got {exposure_us}")
        self.exposure_us = float(exposure_us)

    def set_global_timing(self, exposure_us: float, trigger_delay_us: float) -> None:
        """A global exposure of ``exposure_us``, opened ``trigger_delay_us`` after the trigger (applied at grab)."""
        if not (math.isfinite(exposure_us) and exposure_us > 0):
            raise DeviceError(f"exposure must be positive, got {exposure_us}")
        if not math.isfinite(trigger_delay_us):
            raise InputError(f"trigger delay must be a number, got {trigger_delay_us!r}")
        self._global_timing = (float(exposure_us), float(trigger_delay_us))
        self._applied = None

    def set_timing(self, delay_us: float, exposure_us: float) -> None:
        """Set one sweep point and apply it now (refusing a pair the camera cannot realize)."""
        self.set_exposure(exposure_us)
        self.set_delay(delay_us)
        self._apply()

    def get_timing_us(self) -> tuple[float, float]:
        """``(t_d, t_e)`` realized now: the exposure and trigger delay read back from the camera, Eq. 1 inverted."""
        exposure, trigger = self._read_timing()
        if self._base is None or getattr(self, "_shutter", "rolling") == "global":
            return self.delay_us, exposure
        t_o = self._base - trigger
        return float(delay_from_sync_offset(t_o, exposure, lines_per_second=self.lines_per_second)), exposure
