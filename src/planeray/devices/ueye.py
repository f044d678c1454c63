"""Driver for the paper's camera family: IDS uEye (UI-3250CP), through IDS's ``pyueye``.

Optional (``pip install 'planeray[ueye]'`` plus the IDS Software Suite).  The
module imports without the SDK or a camera; opening a device without them
raises :class:`planeray.errors.DeviceError` saying what is missing.

Wiring and set-up (as in Episcan3D, O'Toole et al. 2015, Sec. 5, and the
README's "Capturing with a real camera"):

* the laser projector's VSYNC output drives the camera's trigger input
  (rising edge by default); the driver selects the **rolling shutter**
  (``is_DeviceFeature``, read back) and the **hardware trigger**, so each frame
  starts a fixed time after the projector starts its raster;
* camera rows must advance with projector rows (rectified, same vertical
  velocity): fix the pixel clock (``pixel_clock_mhz``) or load a uEye parameter
  file saved from uEye Cockpit (``parameter_file``; AOI, pixel clock, timing),
  and check with ``planeray calibrate lines``;
* the camera's **trigger delay** realizes the paper's delay: for a delay ``t_d``
  and exposure ``t_e`` the row exposure must start ``t'_o`` before the projector
  lights that row, ``t'_o = t_e/2 - t_p/2 - t_d`` (Eq. 1, inverted), so the
  trigger delay is ``base_trigger_delay_us - t'_o``.  The base is the trigger
  delay at which ``t'_o = 0``; the projector repeats every frame, so it is
  defined up to whole projector frames, and it must exceed the largest ``t'_o``
  of the sweep (2091 us for the paper's sweep) -- ``planeray calibrate
  delay-zero --device ueye`` finds it and writes ``base_trigger_delay_us`` into
  ``acquisition.json``;
* images are captured as 12-bit mono (LSB-aligned in 16 bits) with gamma, LUT,
  gain boost, edge enhancement and every auto feature switched off (linear
  response), and averaged over ``frames_averaged`` frames (the paper: 8).

Delay and exposure are applied together, once per sweep point
(:meth:`UEyeEpiscan.set_timing`, or lazily at :meth:`~UEyeEpiscan.grab`), so a
feasible point is never refused because of the previous point's exposure.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import DeviceError, InputError
from ..timing import PAPER_LINES_PER_SECOND
from ._triggered import TriggeredTiming
from .base import DeviceBase, register_device
from .capabilities import SHUTTER_MODES, TRIGGER_EDGES

__all__ = ["UEyeEpiscan", "pyueye_available"]

#: uEye return codes named in messages (``ueye.h``).
_CODES = {
    -1: "IS_NO_SUCCESS",
    1: "IS_INVALID_CAMERA_HANDLE",
    3: "IS_CANT_OPEN_DEVICE",
    108: "IS_NO_ACTIVE_IMG_MEM",
    122: "IS_TIMED_OUT",
    125: "IS_INVALID_PARAMETER",
    140: "IS_CAPTURE_RUNNING",
    155: "IS_NOT_SUPPORTED",
}
_IS_NOT_SUPPORTED = 155
_IS_TIMED_OUT = 122
#: ``is_SetTriggerDelay`` reads these values as queries (IS_GET_TRIGGER_DELAY ...), never as delays.
_TRIGGER_QUERIES = range(0x8000, 0x8004)
#: Auto features switched off for a linear, fixed-exposure response.
_AUTO_FEATURES = (
    "IS_SET_ENABLE_AUTO_GAIN",
    "IS_SET_ENABLE_AUTO_SHUTTER",
    "IS_SET_ENABLE_AUTO_FRAMERATE",
    "IS_SET_ENABLE_AUTO_WHITEBALANCE",
    "IS_SET_ENABLE_AUTO_SENSOR_GAIN",
    "IS_SET_ENABLE_AUTO_SENSOR_SHUTTER",
    "IS_SET_ENABLE_AUTO_SENSOR_GAIN_SHUTTER",
    "IS_SET_ENABLE_AUTO_SENSOR_FRAMERATE",
    "IS_SET_ENABLE_AUTO_SENSOR_WHITEBALANCE",
)


def pyueye_available() -> bool:
    """Whether IDS's Python binding (and the uEye library under it) can be imported.

    Returns
    -------
    bool

    See Also
    --------
    UEyeEpiscan : the device it serves.

    Examples
    --------
    >>> isinstance(pyueye_available(), bool)
    True
    """
    try:
        from pyueye import ueye  # noqa: F401
    except Exception:
        return False
    return True


def _num(x):
    """The number in a ctypes value (pyueye's own types also convert with int(), plain ctypes do not)."""
    return x.value if hasattr(x, "value") else x


def _code(ret) -> str:
    ret = int(_num(ret))
    return f"{ret} ({_CODES[ret]})" if ret in _CODES else str(ret)


@register_device("ueye", "IDS uEye camera (pyueye), rolling shutter triggered by the projector's VSYNC", hardware=True)
class UEyeEpiscan(TriggeredTiming, DeviceBase):
    """An Episcan-style rig with an IDS uEye camera (device protocol of :mod:`planeray.devices`).

    Opening the device initializes the camera and configures it completely; any
    failure closes it again (``is_ExitCamera``), so a failed start never leaves
    the camera locked.  Use it as a context manager, or call :meth:`close`.

    Parameters
    ----------
    camera_id : int
        uEye camera ID (0: the first free camera).
    lines_per_second : float
        Projector scanline velocity ``v_p`` (``planeray calibrate lines``).
    base_trigger_delay_us : float, optional
        Trigger delay (us) at which ``t'_o = 0`` (``planeray calibrate
        delay-zero --device ueye``).  Without it the camera opens but refuses to
        capture.
    frames_averaged : int
        Frames averaged per image (the paper: 8).
    bit_depth : {12, 10}
        Mono bit depth (the paper: 12).
    black_level : int
        Code subtracted before normalizing to ``[0, 1]``.
    pixel_clock_mhz : int, optional
        Pixel clock to set (sets the row time, hence the rolling-shutter velocity).
    parameter_file : path, optional
        A uEye parameter file (``.ini`` from uEye Cockpit) loaded first (AOI,
        pixel clock, timing); the driver's own settings are applied on top.
    trigger_timeout_s : float
        How long a frame waits for VSYNC before "no trigger on VSYNC".
    trigger_edge : {"rising", "falling"}
        VSYNC edge that triggers a frame.
    exposure_tolerance_us : float, optional
        Largest accepted difference between requested and realized exposure
        (default: half the camera's exposure increment, plus 0.5 us).

    See Also
    --------
    GenICamEpiscan : any GenICam camera.
    pyueye_available : whether it can run here.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 6 (the paper's IDS UI-3250CP).

    Examples
    --------
    The paper's camera (needs IDS's driver and a camera on the trigger of the projector's VSYNC):

    >>> from planeray.devices import open_device
    >>> with open_device("ueye", parameter_file="rig/episcan.ini") as cam:  # doctest: +SKIP
    ...     cam.set_timing(0.0, 600.0)
    ...     image, saturated = cam.grab()
    """

    kind = "ueye"

    def __init__(
        self,
        *,
        camera_id: int = 0,
        lines_per_second: float = PAPER_LINES_PER_SECOND,
        base_trigger_delay_us: float | None = None,
        frames_averaged: int = 8,
        bit_depth: int = 12,
        black_level: int = 0,
        pixel_clock_mhz: int | None = None,
        parameter_file=None,
        trigger_timeout_s: float = 1.0,
        trigger_edge: str = "rising",
        exposure_tolerance_us: float | None = None,
    ):
        self._open = False
        # --- options, checked before the camera is touched
        if bit_depth not in (10, 12):
            raise InputError(f"bit_depth must be 12 or 10, got {bit_depth!r}")
        if int(frames_averaged) != frames_averaged or frames_averaged < 1:
            raise InputError(f"frames_averaged must be a positive integer, got {frames_averaged!r}")
        full = 2**bit_depth - 1
        if not 0 <= black_level < full:
            raise InputError(f"black_level must be in 0..{full - 1} for {bit_depth} bits, got {black_level!r}")
        if not (math.isfinite(lines_per_second) and lines_per_second > 0):
            raise InputError(f"lines_per_second must be positive, got {lines_per_second!r}")
        if not (math.isfinite(trigger_timeout_s) and 0.04 <= trigger_timeout_s <= 4.2e7):
            raise InputError(f"trigger_timeout_s must be between 0.04 and 4.2e7 s, got {trigger_timeout_s!r}")
        if trigger_edge not in ("rising", "falling"):
            raise InputError(f"trigger_edge must be 'rising' or 'falling', got {trigger_edge!r}")
        if pixel_clock_mhz is not None and (int(pixel_clock_mhz) != pixel_clock_mhz or pixel_clock_mhz <= 0):
            raise InputError(f"pixel_clock_mhz must be a positive integer, got {pixel_clock_mhz!r}")
        if base_trigger_delay_us is not None and not math.isfinite(base_trigger_delay_us):
            raise InputError(f"base_trigger_delay_us must be a number, got {base_trigger_delay_us!r}")
        if parameter_file is not None:
            parameter_file = Path(parameter_file)
            if not parameter_file.is_file():
                raise InputError("uEye parameter file not found", parameter_file)
        self.camera_id = int(camera_id)
        self.lines_per_second = float(lines_per_second)
        self._base = None if base_trigger_delay_us is None else float(base_trigger_delay_us)
        self.frames_averaged = int(frames_averaged)
        self.bit_depth = int(bit_depth)
        self.black_level = int(black_level)
        self.parameter_file = parameter_file
        self.trigger_timeout_s = float(trigger_timeout_s)
        self.trigger_edge = trigger_edge
        self.exposure_tolerance_us = exposure_tolerance_us
        self.delay_us, self.exposure_us = 0.0, 600.0
        self._applied = None  # (delay, exposure, base) realized on the camera
        self._exposure_set = None  # requested exposure last written to the camera
        self._trigger_set = None  # trigger delay last written
        self.realized_exposure_us = None
        self.applied_trigger_delay_us = None
        self._allocated = False
        self._unsupported: list[str] = []
        self.shutter_modes = ("rolling",)
        self._shutter = "rolling"
        self._global_timing = None  # (exposure, trigger delay) of a global exposure

        try:
            from pyueye import ueye
        except Exception as exc:
            raise DeviceError(
                "the uEye driver needs IDS's pyueye (pip install pyueye) and the IDS Software Suite with its camera "
                f"driver ({type(exc).__name__}: {exc})"
            ) from exc
        self._ueye = ueye
        self._h = ueye.HIDS(self.camera_id)
        ret = ueye.is_InitCamera(self._h, None)
        if ret != ueye.IS_SUCCESS:
            raise DeviceError(
                f"no uEye camera could be opened (is_InitCamera returned {_code(ret)}): is one connected, "
                f"with ID {self.camera_id} and not in use by another program?"
            )
        self._open = True
        try:
            self._setup(pixel_clock_mhz)
        except BaseException:
            self._release()
            raise

    # ------------------------------------------------------------------ setup
    def _check(self, ret, what):
        if ret != self._ueye.IS_SUCCESS:
            raise DeviceError(f"uEye {what} failed with code {_code(ret)}")

    def _optional(self, ret, what):
        """A switch some models lack: IS_NOT_SUPPORTED is recorded, any other failure raised."""
        if _num(ret) == _IS_NOT_SUPPORTED:
            self._unsupported.append(what)
            return
        self._check(ret, what)

    def _setup(self, pixel_clock_mhz):
        u, h = self._ueye, self._h
        # 1. a saved parameter set first: everything below is applied on top of it
        if self.parameter_file is not None:
            name = u.c_wchar_p(str(self.parameter_file))
            self._check(
                u.is_ParameterSet(h, u.IS_PARAMETERSET_CMD_LOAD_FILE, name, 0),
                f"is_ParameterSet (loading {self.parameter_file})",
            )
        # 2. rolling shutter, read back (a camera left in global shutter would make every image wrong)
        rolling = int(u.IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_ROLLING)
        caps = u.c_uint(0)
        self._check(
            u.is_DeviceFeature(h, u.IS_DEVICE_FEATURE_CMD_GET_SUPPORTED_FEATURES, caps, u.sizeof(caps)),
            "is_DeviceFeature (supported features)",
        )
        if not int(_num(caps)) & rolling:
            raise DeviceError("this uEye camera has no rolling-shutter mode; plane-to-ray capture needs one")
        has_global = bool(int(_num(caps)) & int(u.IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_GLOBAL))
        self.shutter_modes = ("rolling", "global") if has_global else ("rolling",)
        self._shutter = "rolling"
        mode = u.c_uint(rolling)
        self._check(
            u.is_DeviceFeature(h, u.IS_DEVICE_FEATURE_CMD_SET_SHUTTER_MODE, mode, u.sizeof(mode)),
            "is_DeviceFeature (rolling shutter)",
        )
        back = u.c_uint(0)
        self._check(
            u.is_DeviceFeature(h, u.IS_DEVICE_FEATURE_CMD_GET_SHUTTER_MODE, back, u.sizeof(back)),
            "is_DeviceFeature (reading the shutter mode)",
        )
        if int(_num(back)) != rolling:
            raise DeviceError(f"the camera did not switch to rolling shutter (shutter mode read back: {_num(back)})")
        # 3. mono, 12 (or 10) bits LSB-aligned in 16
        colour = u.IS_CM_MONO12 if self.bit_depth == 12 else u.IS_CM_MONO10
        self._check(u.is_SetColorMode(h, colour), f"is_SetColorMode (MONO{self.bit_depth})")
        if _num(u.is_SetColorMode(h, u.IS_GET_COLOR_MODE)) != colour:
            raise DeviceError(f"the camera did not switch to {self.bit_depth}-bit mono")
        # 4. pixel clock: the row time, hence the rolling shutter's velocity
        if pixel_clock_mhz is not None:
            rng = (u.c_uint * 3)()
            self._check(u.is_PixelClock(h, u.IS_PIXELCLOCK_CMD_GET_RANGE, rng, u.sizeof(rng)), "is_PixelClock (range)")
            lo, hi = int(_num(rng[0])), int(_num(rng[1]))
            if not lo <= pixel_clock_mhz <= hi:
                raise DeviceError(f"pixel clock {pixel_clock_mhz} MHz is outside the camera's {lo}..{hi} MHz")
            clock = u.c_uint(int(pixel_clock_mhz))
            self._check(u.is_PixelClock(h, u.IS_PIXELCLOCK_CMD_SET, clock, u.sizeof(clock)), "is_PixelClock (set)")
        clock = u.c_uint(0)
        self._check(u.is_PixelClock(h, u.IS_PIXELCLOCK_CMD_GET, clock, u.sizeof(clock)), "is_PixelClock (get)")
        self.pixel_clock_mhz = int(_num(clock))
        if pixel_clock_mhz is not None and self.pixel_clock_mhz != pixel_clock_mhz:
            raise DeviceError(f"the camera set pixel clock {self.pixel_clock_mhz} MHz for {pixel_clock_mhz} requested")
        # 5. a linear response: no gamma, no LUT, no gain boost, no edge enhancement, no auto feature
        self._optional(u.is_SetHardwareGamma(h, u.IS_SET_HW_GAMMA_OFF), "hardware gamma off")
        gamma = u.c_int(100)  # 1.00
        self._optional(u.is_Gamma(h, u.IS_GAMMA_CMD_SET, gamma, u.sizeof(gamma)), "software gamma 1.0")
        lut = u.c_int(u.IS_LUT_DISABLED)
        self._optional(u.is_LUT(h, u.IS_LUT_CMD_SET_ENABLED, lut, u.sizeof(lut)), "LUT off")
        self._optional(u.is_SetGainBoost(h, u.IS_SET_GAINBOOST_OFF), "gain boost off")
        edge = u.c_uint(0)
        self._optional(
            u.is_EdgeEnhancement(h, u.IS_EDGE_ENHANCEMENT_CMD_SET, edge, u.sizeof(edge)), "edge enhancement off"
        )
        for name in _AUTO_FEATURES:
            off, unused = u.c_double(0.0), u.c_double(0.0)
            self._optional(u.is_SetAutoParameter(h, getattr(u, name), off, unused), f"{name} off")
        # 6. hardware trigger on VSYNC, with a timeout that says so
        trigger = u.IS_SET_TRIGGER_LO_HI if self.trigger_edge == "rising" else u.IS_SET_TRIGGER_HI_LO
        self._check(u.is_SetExternalTrigger(h, trigger), "is_SetExternalTrigger (hardware trigger on VSYNC)")
        units = int(round(self.trigger_timeout_s * 100))  # 10 ms units
        self._check(u.is_SetTimeout(h, u.IS_TRIGGER_TIMEOUT, units), "is_SetTimeout (trigger timeout)")
        lo = int(_num(u.is_SetTriggerDelay(h, u.IS_GET_MIN_TRIGGER_DELAY)))
        hi = int(_num(u.is_SetTriggerDelay(h, u.IS_GET_MAX_TRIGGER_DELAY)))
        step = int(_num(u.is_SetTriggerDelay(h, u.IS_GET_TRIGGER_DELAY_GRANULARITY)))
        if lo < 0 or hi < lo or step < 0:  # negative: an error code, not a delay
            raise DeviceError(f"the camera reports an invalid trigger-delay range {lo}..{hi} us (step {step})")
        self.trigger_delay_range_us = (float(lo), float(hi))
        self.trigger_delay_step_us = max(step, 1)
        # 7. image size (after the parameter file and the pixel clock) and exposure range
        rect = u.IS_RECT()
        self._check(u.is_AOI(h, u.IS_AOI_IMAGE_GET_AOI, rect, u.sizeof(rect)), "is_AOI")
        self.width, self.height = int(_num(rect.s32Width)), int(_num(rect.s32Height))
        if self.width <= 0 or self.height <= 0:
            raise DeviceError(f"the camera reports an empty image area {self.width}x{self.height}")
        rng = (u.c_double * 3)()
        self._check(u.is_Exposure(h, u.IS_EXPOSURE_CMD_GET_EXPOSURE_RANGE, rng, u.sizeof(rng)), "is_Exposure (range)")
        self.exposure_range_us = (float(_num(rng[0])) * 1e3, float(_num(rng[1])) * 1e3)
        self.exposure_step_us = float(_num(rng[2])) * 1e3
        # 8. one image buffer of 16-bit pixels, its real line pitch
        self._mem, self._mem_id = u.c_mem_p(), u.c_int()
        self._check(u.is_AllocImageMem(h, self.width, self.height, 16, self._mem, self._mem_id), "is_AllocImageMem")
        self._allocated = True
        self._check(u.is_SetImageMem(h, self._mem, self._mem_id), "is_SetImageMem")
        pitch = u.c_int()
        self._check(u.is_GetImageMemPitch(h, pitch), "is_GetImageMemPitch")
        self.pitch = int(_num(pitch))
        if self.pitch < 2 * self.width or self.pitch % 2:
            raise DeviceError(f"image line pitch {self.pitch} bytes cannot hold {self.width} 16-bit pixels")

    # ---------------------------------------------------------- capabilities
    def get_shutter(self) -> str:
        """The shutter mode, read back from the camera (``is_DeviceFeature``)."""
        self._require_open()
        u = self._ueye
        back = u.c_uint(0)
        self._check(
            u.is_DeviceFeature(self._h, u.IS_DEVICE_FEATURE_CMD_GET_SHUTTER_MODE, back, u.sizeof(back)),
            "is_DeviceFeature (reading the shutter mode)",
        )
        value = int(_num(back))
        if value == int(u.IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_ROLLING):
            return "rolling"
        if value == int(u.IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_GLOBAL):
            return "global"
        return f"unknown ({value})"

    def set_shutter(self, mode: str) -> None:
        """Select the rolling or the global shutter and read it back."""
        if mode not in SHUTTER_MODES:
            raise InputError(f"shutter mode must be 'rolling' or 'global', got {mode!r}")
        if mode not in self.shutter_modes:
            raise DeviceError(f"this uEye camera has no {mode}-shutter mode")
        self._require_open()
        u = self._ueye
        flag = (
            u.IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_ROLLING
            if mode == "rolling"
            else u.IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_GLOBAL
        )
        value = u.c_uint(int(flag))
        self._check(
            u.is_DeviceFeature(self._h, u.IS_DEVICE_FEATURE_CMD_SET_SHUTTER_MODE, value, u.sizeof(value)),
            f"is_DeviceFeature ({mode} shutter)",
        )
        back = self.get_shutter()
        if back != mode:
            raise DeviceError(f"the camera did not switch to {mode} shutter (shutter mode read back: {back})")
        self._shutter = mode
        self._applied = None  # the exposure range and trigger timing are the mode's own: set them again

    def get_trigger_edge(self) -> str:
        """The VSYNC edge that starts a frame, read back (``is_SetExternalTrigger(IS_GET_EXTERNALTRIGGER)``)."""
        self._require_open()
        u = self._ueye
        mode = int(_num(u.is_SetExternalTrigger(self._h, u.IS_GET_EXTERNALTRIGGER)))
        return {int(u.IS_SET_TRIGGER_LO_HI): "rising", int(u.IS_SET_TRIGGER_HI_LO): "falling"}.get(
            mode, f"off ({mode})"
        )

    def set_trigger_edge(self, edge: str) -> None:
        """Trigger on the ``rising`` or ``falling`` edge of VSYNC."""
        if edge not in TRIGGER_EDGES:
            raise InputError(f"trigger edge must be 'rising' or 'falling', got {edge!r}")
        self._require_open()
        u = self._ueye
        trigger = u.IS_SET_TRIGGER_LO_HI if edge == "rising" else u.IS_SET_TRIGGER_HI_LO
        self._check(u.is_SetExternalTrigger(self._h, trigger), f"is_SetExternalTrigger ({edge} edge)")
        self.trigger_edge = edge

    def get_gamma(self) -> float:
        """The software gamma, read back (``is_Gamma(IS_GAMMA_CMD_GET)``, in hundredths): 1.0 is linear."""
        self._require_open()
        u = self._ueye
        value = u.c_int(0)
        ret = u.is_Gamma(self._h, u.IS_GAMMA_CMD_GET, value, u.sizeof(value))
        if _num(ret) == _IS_NOT_SUPPORTED:
            return 1.0
        self._check(ret, "is_Gamma (get)")
        return int(_num(value)) / 100.0

    def get_exposure_range_us(self) -> tuple[float, float]:
        """Shortest and longest exposure at the current pixel clock (us)."""
        return tuple(self.exposure_range_us)

    def get_trigger_delay_range_us(self) -> tuple[float, float]:
        """Shortest and longest trigger delay (us)."""
        return tuple(self.trigger_delay_range_us)

    def get_exposure_step_us(self) -> float:
        """The exposure's step as the camera reports it (us; 0: none reported)."""
        return float(self.exposure_step_us or 0.0)

    def get_trigger_delay_step_us(self) -> float:
        """The trigger delay's step as the camera reports it (us; 0: none reported)."""
        return float(self.trigger_delay_step_us or 0.0)

    def _read_timing(self) -> tuple[float, float]:
        """The exposure and the trigger delay read back from the camera (us)."""
        self._require_open()
        u = self._ueye
        got = u.c_double(0.0)
        self._check(u.is_Exposure(self._h, u.IS_EXPOSURE_CMD_GET_EXPOSURE, got, u.sizeof(got)), "is_Exposure (get)")
        exposure = float(_num(got)) * 1000.0
        return exposure, float(int(_num(u.is_SetTriggerDelay(self._h, u.IS_GET_TRIGGER_DELAY))))

    # -------------------------------------------------------------- timing
    def _apply(self):
        self._require_open()
        glob = self._shutter == "global"
        if glob and self._global_timing is None:
            raise DeviceError("a global-shutter grab needs its exposure and trigger delay: call set_global_timing")
        want = ("global", *self._global_timing) if glob else (self.delay_us, self.exposure_us, self._base)
        if self._applied == want:
            return
        u, h = self._ueye, self._h
        e = self._global_timing[0] if glob else self.exposure_us
        lo, hi = self.exposure_range_us
        if not lo - 1e-6 <= e <= hi + 1e-6:
            raise DeviceError(
                f"exposure {e:g} us is outside the camera's range {lo:g}..{hi:g} us "
                f"(at pixel clock {self.pixel_clock_mhz} MHz)"
            )
        if self._exposure_set != e:
            self._exposure_set = None
            value = u.c_double(e / 1000.0)  # ms
            self._check(u.is_Exposure(h, u.IS_EXPOSURE_CMD_SET_EXPOSURE, value, u.sizeof(value)), "is_Exposure (set)")
            got = u.c_double(0.0)
            self._check(u.is_Exposure(h, u.IS_EXPOSURE_CMD_GET_EXPOSURE, got, u.sizeof(got)), "is_Exposure (get)")
            realized = float(_num(got)) * 1000.0
            tol = self.exposure_tolerance_us
            tol = 0.5 * self.exposure_step_us + 0.5 if tol is None else float(tol)
            if abs(realized - e) > tol:
                raise DeviceError(
                    f"the camera set exposure {realized:.2f} us for {e:g} us requested (tolerance {tol:.2f} us)"
                )
            self._exposure_set, self.realized_exposure_us = e, realized
        # Eq. 1 with the exposure the camera really uses, so the band is centred where asked
        # (a global exposure opens at the trigger delay asked for)
        ideal = self._global_timing[1] if glob else self.trigger_delay_for(self.delay_us, self.realized_exposure_us)
        step = self.trigger_delay_step_us
        trigger = int(round(ideal / step)) * step
        dmin, dmax = self.trigger_delay_range_us
        if glob and not dmin <= trigger <= dmax:
            raise DeviceError(f"trigger delay {ideal:g} us is outside the camera's {dmin:g}..{dmax:g} us")
        if not dmin <= trigger <= dmax:
            raise DeviceError(
                f"delay {self.delay_us:g} us at exposure {e:g} us needs trigger delay {ideal:.1f} us "
                f"(base {self._base:g} us - t'_o {self._base - ideal:.1f} us), outside the camera's "
                f"{dmin:g}..{dmax:g} us: "
                + (
                    "use a base one projector frame later (calibrate delay-zero picks one that fits the sweep)"
                    if trigger < dmin
                    else "use a base one projector frame earlier"
                )
            )
        if trigger in _TRIGGER_QUERIES:
            raise DeviceError(
                f"trigger delay {trigger} us is a query code of is_SetTriggerDelay and cannot be set; "
                "shift the base by a few microseconds"
            )
        if self._trigger_set != trigger:
            self._trigger_set = None
            self._check(u.is_SetTriggerDelay(h, trigger), "is_SetTriggerDelay")
            back = int(_num(u.is_SetTriggerDelay(h, u.IS_GET_TRIGGER_DELAY)))
            if back != trigger:
                raise DeviceError(f"the camera set trigger delay {back} us for {trigger} us requested")
            self._trigger_set = trigger
        self.applied_trigger_delay_us = float(trigger)
        self._applied = want

    # --------------------------------------------------------------- capture
    def _require_open(self):
        if not self._open:
            raise DeviceError("the uEye camera is closed")

    def grab(self):
        """Average ``frames_averaged`` VSYNC-triggered frames at the current delay and exposure."""
        self._apply()
        u, h = self._ueye, self._h
        full = 2**self.bit_depth - 1
        total = np.zeros((self.height, self.width), np.float64)
        saturated = np.zeros((self.height, self.width), bool)
        for _ in range(self.frames_averaged):
            ret = u.is_FreezeVideo(h, u.IS_WAIT)
            if _num(ret) == _IS_TIMED_OUT:
                raise DeviceError(
                    f"no trigger on VSYNC within {self.trigger_timeout_s:g} s (is_FreezeVideo returned "
                    f"{_code(ret)}): is the projector on, and its VSYNC wired to the camera's trigger input?"
                )
            self._check(ret, "is_FreezeVideo")
            frame = self._frame()
            peak = int(frame.max())
            if peak > full:
                raise DeviceError(
                    f"pixel code {peak} above the {self.bit_depth}-bit maximum {full}: the camera does not deliver "
                    f"LSB-aligned {self.bit_depth}-bit mono"
                )
            saturated |= frame >= full
            total += frame
        image = (total / self.frames_averaged - self.black_level) / (full - self.black_level)
        return image.astype(np.float32), saturated

    def _frame(self) -> np.ndarray:
        """The image buffer as ``(H, W)`` codes, honouring the line pitch (lines may be padded)."""
        raw = self._ueye.get_data(self._mem, self.width, self.height, 16, self.pitch, copy=True)
        rows = np.frombuffer(raw, np.uint8)[: self.height * self.pitch]
        rows = rows.reshape(self.height, self.pitch)[:, : 2 * self.width]
        return np.ascontiguousarray(rows).view("<u2").astype(np.float64)

    def describe(self) -> dict:
        return {
            "device": self.kind,
            "camera_id": self.camera_id,
            "image_shape": [self.height, self.width],
            "lines_per_second": self.lines_per_second,
            "base_trigger_delay_us": self._base,
            "shutter": "rolling",
            "shutter_modes": list(self.shutter_modes),
            "trigger": {
                "source": "projector VSYNC",
                "edge": self.trigger_edge,
                "timeout_s": self.trigger_timeout_s,
                "delay_range_us": list(self.trigger_delay_range_us),
                "delay_step_us": self.trigger_delay_step_us,
            },
            "pixel_clock_mhz": self.pixel_clock_mhz,
            "exposure_range_us": list(self.exposure_range_us),
            "exposure_step_us": self.exposure_step_us,
            "parameter_file": None if self.parameter_file is None else str(self.parameter_file),
            "unsupported_switches": list(self._unsupported),
            "camera": {
                "bit_depth": self.bit_depth,
                "black_level": self.black_level,
                "frames_averaged": self.frames_averaged,
            },
        }

    # ----------------------------------------------------------------- close
    def _release(self):
        u = self._ueye
        try:
            if self._allocated:
                self._allocated = False
                u.is_FreeImageMem(self._h, self._mem, self._mem_id)
        finally:
            self._open = False
            u.is_ExitCamera(self._h)

    def close(self) -> None:
        """Free the image memory and release the camera (``is_ExitCamera``); safe to call twice."""
        if self._open:
            self._release()
