"""Driver for the paper's camera family: IDS uEye (UI-3250CP), through IDS's ``pyueye``.

Optional (``pip install 'planeray[ueye]'`` plus the IDS Software Suite).  The
module imports without the SDK or a camera; opening a device without them
raises :class:`planeray.errors.DeviceError` saying what is missing.

Wiring assumptions (as in Episcan3D, O'Toole et al. 2015, Sec. 5):

* the laser projector's VSYNC output drives the camera's trigger input
  (rising edge); the camera runs in **rolling-shutter, hardware-triggered** mode,
  so each frame starts a fixed time after the projector starts its raster;
* the lens/pixel clock are set so camera rows advance with projector rows
  (rectified, same vertical velocity -- check with ``planeray calibrate lines``);
* the **trigger delay** of the camera is the sync offset: for a delay ``t_d``
  and exposure ``t_e``, the row exposure must start ``t'_o`` before the
  projector lights that row, ``t'_o = t_e/2 - t_p/2 - t_d`` (Eq. 1, inverted), so
  the trigger delay is ``base_trigger_delay_us - t'_o``, where the base delay is
  the value at which ``t'_o = 0`` -- measured by ``planeray calibrate delay-zero``;
* images are captured at 12 bits without gamma and averaged over
  ``frames_averaged`` frames (the paper: 8).
"""

from __future__ import annotations

import numpy as np

from ..errors import DeviceError
from ..timing import PAPER_LINES_PER_SECOND, sync_offset_from_delay

__all__ = ["UEyeEpiscan", "pyueye_available"]


def pyueye_available() -> bool:
    """Whether IDS's Python binding can be imported."""
    try:
        import pyueye  # noqa: F401
    except Exception:
        return False
    return True


class UEyeEpiscan:
    """An Episcan-style rig with an IDS uEye camera (device protocol of :mod:`planeray.devices`).

    Parameters
    ----------
    camera_id : int
        uEye camera handle (0: first free camera).
    lines_per_second : float
        Projector scanline velocity from calibration.
    base_trigger_delay_us : float
        Trigger delay at which ``t'_o = 0`` (from delay-zero calibration).
    frames_averaged : int
        Frames averaged per image.
    bit_depth : int
        10 or 12 (the paper: 12).
    """

    kind = "ueye"

    def __init__(
        self,
        camera_id: int = 0,
        *,
        lines_per_second: float = PAPER_LINES_PER_SECOND,
        base_trigger_delay_us: float = 0.0,
        frames_averaged: int = 8,
        bit_depth: int = 12,
        black_level: int = 0,
    ):
        try:
            from pyueye import ueye
        except Exception as exc:
            raise DeviceError(
                "the uEye driver needs IDS's pyueye and the IDS Software Suite: pip install 'planeray[ueye]' "
                f"and install the IDS driver ({type(exc).__name__}: {exc})"
            ) from exc
        self._ueye = ueye
        self.lines_per_second = float(lines_per_second)
        self.base_trigger_delay_us = float(base_trigger_delay_us)
        self.frames_averaged = int(frames_averaged)
        self.bit_depth = int(bit_depth)
        self.black_level = int(black_level)
        self.delay_us, self.exposure_us = 0.0, 600.0
        self._h = ueye.HIDS(int(camera_id))
        ret = ueye.is_InitCamera(self._h, None)
        if ret != ueye.IS_SUCCESS:
            raise DeviceError(f"no uEye camera could be opened (is_InitCamera returned {ret}); is one connected?")
        self._setup()

    # ------------------------------------------------------------ setup
    def _check(self, ret, what):
        if ret != self._ueye.IS_SUCCESS:
            raise DeviceError(f"uEye {what} failed with code {ret}")

    def _setup(self):
        ueye = self._ueye
        mode = ueye.IS_CM_MONO12 if self.bit_depth == 12 else ueye.IS_CM_MONO10
        self._check(ueye.is_SetColorMode(self._h, mode), "is_SetColorMode")
        self._check(ueye.is_SetExternalTrigger(self._h, ueye.IS_SET_TRIGGER_LO_HI), "is_SetExternalTrigger (VSYNC)")
        rect = ueye.IS_RECT()
        self._check(ueye.is_AOI(self._h, ueye.IS_AOI_IMAGE_GET_AOI, rect, ueye.sizeof(rect)), "is_AOI")
        self.width, self.height = int(rect.s32Width), int(rect.s32Height)
        self._mem, self._mem_id = ueye.c_mem_p(), ueye.int()
        self._check(
            ueye.is_AllocImageMem(self._h, self.width, self.height, 16, self._mem, self._mem_id), "is_AllocImageMem"
        )
        self._check(ueye.is_SetImageMem(self._h, self._mem, self._mem_id), "is_SetImageMem")

    # --------------------------------------------------------- protocol
    def trigger_delay_us(self) -> float:
        """Camera trigger delay realizing the current (delay, exposure) via Eq. 1."""
        t_o = float(sync_offset_from_delay(self.delay_us, self.exposure_us, lines_per_second=self.lines_per_second))
        return self.base_trigger_delay_us - t_o

    def set_delay(self, delay_us: float) -> None:
        self.delay_us = float(delay_us)
        self._apply_timing()

    def set_exposure(self, exposure_us: float) -> None:
        if exposure_us <= 0:
            raise DeviceError(f"exposure must be positive, got {exposure_us}")
        ueye = self._ueye
        value = ueye.double(float(exposure_us) / 1000.0)  # ms
        self._check(
            ueye.is_Exposure(self._h, ueye.IS_EXPOSURE_CMD_SET_EXPOSURE, value, ueye.sizeof(value)), "is_Exposure"
        )
        self.exposure_us = float(value.value) * 1000.0  # the camera rounds to its line period
        self._apply_timing()

    def _apply_timing(self):
        delay = self.trigger_delay_us()
        if delay < 0:
            raise DeviceError(
                f"delay {self.delay_us:g} us at exposure {self.exposure_us:g} us needs a negative trigger delay; "
                "raise base_trigger_delay_us by one projector frame"
            )
        self._check(self._ueye.is_SetTriggerDelay(self._h, int(round(delay))), "is_SetTriggerDelay")

    def grab(self):
        ueye = self._ueye
        span = 2**self.bit_depth - 1 - self.black_level
        total = np.zeros((self.height, self.width), np.float64)
        saturated = np.zeros((self.height, self.width), bool)
        for _ in range(self.frames_averaged):
            self._check(ueye.is_FreezeVideo(self._h, ueye.IS_WAIT), "is_FreezeVideo")
            raw = ueye.get_data(self._mem, self.width, self.height, 16, self.width * 2, copy=True)
            frame = np.frombuffer(bytes(raw), np.uint16).reshape(self.height, self.width).astype(np.float64)
            saturated |= frame >= 2**self.bit_depth - 1
            total += frame
        image = (total / self.frames_averaged - self.black_level) / span
        return image.astype(np.float32), saturated

    def describe(self) -> dict:
        return {
            "device": self.kind,
            "image_shape": [self.height, self.width],
            "lines_per_second": self.lines_per_second,
            "base_trigger_delay_us": self.base_trigger_delay_us,
            "camera": {
                "bit_depth": self.bit_depth,
                "black_level": self.black_level,
                "frames_averaged": self.frames_averaged,
            },
        }

    def close(self):
        ueye = self._ueye
        ueye.is_FreeImageMem(self._h, self._mem, self._mem_id)
        ueye.is_ExitCamera(self._h)
