"""A fake ``pyueye.ueye`` for the uEye driver's tests: no SDK, no camera, every call recorded.

It mirrors the real binding (pyueye 4.96) where the driver meets it -- function
names, constants and their values, and the ctypes each argument must have
(``argtypes``/``byref``/``_pointer_cast`` of the real wrappers: a Python float
where a ``c_double`` is expected, or a ``c_int`` where ``byref`` needs a
``c_mem_p``, raises ``TypeError`` here as it does there).  It checks that calls
come in a legal order (nothing before ``is_InitCamera`` or after
``is_ExitCamera``, memory set before capture, a capture needs the trigger), and
returns error codes on demand (``FakeCamera.fail``).

The camera behind it renders what a rolling-shutter camera triggered by the
projector's VSYNC would see: the trigger delay ``D`` the driver sets and the
hidden ``true_base_us`` give the true sync offset ``t'_o = wrap(true_base - D)``
(the projector repeats every ``frame_period_us``), Eq. 1 gives the true delay,
and ``render(delay_us, exposure_us)`` the image, quantized to 12-bit codes in a
buffer whose lines are padded (``pitch > 2 * width``).

Use::

    camera = FakeCamera(render=...)
    install(monkeypatch, camera)  # now `from pyueye import ueye` finds the fake
"""

from __future__ import annotations

import ctypes
import sys
import types

import numpy as np

# ----------------------------------------------------------------------------- constants (pyueye 4.96 values)
CONSTANTS = dict(
    IS_SUCCESS=0,
    IS_NO_SUCCESS=-1,
    IS_CANT_OPEN_DEVICE=3,
    IS_TIMED_OUT=122,
    IS_INVALID_PARAMETER=125,
    IS_NOT_SUPPORTED=155,
    IS_WAIT=0x0001,
    IS_DONT_WAIT=0x0000,
    IS_GET_COLOR_MODE=0x8000,
    IS_CM_MONO8=6,
    IS_CM_MONO10=34,
    IS_CM_MONO12=26,
    IS_CM_MONO16=28,
    IS_SET_TRIGGER_OFF=0x0000,
    IS_SET_TRIGGER_HI_LO=0x1001,
    IS_SET_TRIGGER_LO_HI=0x1002,
    IS_GET_EXTERNALTRIGGER=0x8000,
    IS_GET_TRIGGER_DELAY=0x8000,
    IS_GET_MIN_TRIGGER_DELAY=0x8001,
    IS_GET_MAX_TRIGGER_DELAY=0x8002,
    IS_GET_TRIGGER_DELAY_GRANULARITY=0x8003,
    IS_TRIGGER_TIMEOUT=0,
    IS_AOI_IMAGE_GET_AOI=0x0002,
    IS_EXPOSURE_CMD_GET_EXPOSURE_RANGE=6,
    IS_EXPOSURE_CMD_GET_EXPOSURE=7,
    IS_EXPOSURE_CMD_SET_EXPOSURE=12,
    IS_DEVICE_FEATURE_CMD_GET_SUPPORTED_FEATURES=1,
    IS_DEVICE_FEATURE_CMD_SET_SHUTTER_MODE=6,
    IS_DEVICE_FEATURE_CMD_GET_SHUTTER_MODE=7,
    IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_ROLLING=1,
    IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_GLOBAL=2,
    IS_PIXELCLOCK_CMD_GET_RANGE=3,
    IS_PIXELCLOCK_CMD_GET=5,
    IS_PIXELCLOCK_CMD_SET=6,
    IS_PARAMETERSET_CMD_LOAD_FILE=2,
    IS_SET_HW_GAMMA_OFF=0x0000,
    IS_GAMMA_CMD_SET=0x0001,
    IS_GAMMA_CMD_GET=0x0003,
    IS_LUT_CMD_SET_ENABLED=0x0001,
    IS_LUT_DISABLED=0,
    IS_SET_GAINBOOST_OFF=0x0000,
    IS_EDGE_ENHANCEMENT_CMD_SET=4,
    IS_SET_ENABLE_AUTO_GAIN=0x8800,
    IS_SET_ENABLE_AUTO_SHUTTER=0x8802,
    IS_SET_ENABLE_AUTO_WHITEBALANCE=0x8804,
    IS_SET_ENABLE_AUTO_FRAMERATE=0x8806,
    IS_SET_ENABLE_AUTO_SENSOR_GAIN=0x8808,
    IS_SET_ENABLE_AUTO_SENSOR_SHUTTER=0x8810,
    IS_SET_ENABLE_AUTO_SENSOR_GAIN_SHUTTER=0x8812,
    IS_SET_ENABLE_AUTO_SENSOR_FRAMERATE=0x8814,
    IS_SET_ENABLE_AUTO_SENSOR_WHITEBALANCE=0x8816,
)
AUTO_PARAMS = {v for k, v in CONSTANTS.items() if k.startswith("IS_SET_ENABLE_AUTO_")}


class c_mem_p(ctypes.c_void_p):
    """pyueye's image-memory pointer type (a distinct ``c_void_p`` subclass)."""


class IS_RECT(ctypes.Structure):
    _pack_ = 8
    _fields_ = [("s32X", ctypes.c_int), ("s32Y", ctypes.c_int), ("s32Width", ctypes.c_int), ("s32Height", ctypes.c_int)]


def _int_arg(name, x, ctype=ctypes.c_int):
    """``_value_cast(x, c_int)`` of the real binding: a Python int or a ctypes integer; never a float."""
    if isinstance(x, ctypes._SimpleCData):
        if isinstance(x.value, float):
            raise TypeError(f"{name}: a {type(x).__name__} where an integer is expected")
        return x.value
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)):
        raise TypeError(f"{name}: int expected, got {type(x).__name__}")
    ctype(int(x))  # range check as ctypes would do (silently wraps; keep the value)
    return int(x)


def _expect(name, obj, ctype, size=None, given_size=None):
    """A pointer argument must be an instance of exactly ``ctype`` (and sizeof must match)."""
    if not isinstance(obj, ctype):
        raise TypeError(f"{name}: expected {getattr(ctype, '__name__', ctype)}, got {type(obj).__name__}")
    if size is not None and given_size != size:
        raise TypeError(f"{name}: size of parameter {given_size}, expected {size}")


def _is_array(obj, elem, n):
    return isinstance(obj, ctypes.Array) and obj._type_ is elem and len(obj) == n


class FakeCamera:
    """The state of one fake uEye camera and of its projector.

    Parameters
    ----------
    width, height : int
        Image area (AOI).
    pitch_pad : int
        Bytes of padding at the end of every image line.
    render : callable, optional
        ``render(delay_us, exposure_us) -> (H, W)`` image in full-scale units
        (1.0 = 4095 codes); the true delay comes from the trigger delay set and
        ``true_base_us``.  Default: a ramp that does not depend on timing.
    true_base_us : float
        Trigger delay at which the true ``t'_o`` is 0 (hidden from the driver).
    frame_period_us : float
        Projector frame period (the true ``t'_o`` wraps around it).
    lines_per_second : float
        Projector ``v_p`` of Eq. 1.
    exposure_range_ms : (min, max, increment)
        What ``IS_EXPOSURE_CMD_GET_EXPOSURE_RANGE`` reports; set values are rounded to the increment.
    trigger_range_us : (min, max, granularity)
        What ``is_SetTriggerDelay(IS_GET_MIN/MAX_TRIGGER_DELAY/GRANULARITY)`` returns.
    vsync : bool
        False: no trigger ever arrives (``is_FreezeVideo`` returns IS_TIMED_OUT).
    render_global : callable, optional
        ``render_global(trigger_delay_us, exposure_us) -> (H, W)``: the image of a
        global-shutter exposure opened that long after VSYNC (called at every frame,
        never cached: what the projector shows may change between frames).
    """

    def __init__(
        self,
        *,
        width=24,
        height=16,
        pitch_pad=8,
        render=None,
        true_base_us=5000.0,
        frame_period_us=1e6 / 60.0,
        lines_per_second=54_000.0,
        exposure_range_ms=(0.02, 30.0, 0.001),
        trigger_range_us=(0, 2_000_000, 1),
        pixel_clock_range_mhz=(5, 96, 1),
        pixel_clock_mhz=30,
        supports_rolling=True,
        ignores_shutter_mode=False,
        unsupported=(),
        vsync=True,
        msb_aligned=False,
        render_global=None,
    ):
        self.width, self.height, self.pitch = width, height, 2 * width + pitch_pad
        self.render = render or (lambda d, e: np.tile(np.linspace(0.1, 0.9, width), (height, 1)))
        self.true_base_us = float(true_base_us)
        self.frame_period_us = float(frame_period_us)
        self.lines_per_second = float(lines_per_second)
        self.exposure_range_ms = exposure_range_ms
        self.trigger_range_us = trigger_range_us
        self.pixel_clock_range_mhz = pixel_clock_range_mhz
        self.pixel_clock_mhz = pixel_clock_mhz
        self.supports_rolling = supports_rolling
        self.ignores_shutter_mode = ignores_shutter_mode
        self.unsupported = set(unsupported)  # function names answering IS_NOT_SUPPORTED
        self.vsync = vsync
        self.msb_aligned = msb_aligned
        self.render_global = render_global
        self.gamma = 100
        # state
        self.calls: list[tuple] = []
        self.fail: dict = {}  # "is_Name" or ("is_Name", command) -> return code
        self.handle = None
        self.open = False
        self.opened = 0
        self.exited = 0
        self.shutter_mode = CONSTANTS["IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_GLOBAL"]  # the camera starts global
        self.color_mode = CONSTANTS["IS_CM_MONO8"]
        self.trigger_mode = CONSTANTS["IS_SET_TRIGGER_OFF"]
        self.timeout_units = 0  # 0: the SDK default, 60 s
        self.exposure_ms = 10.0
        self.trigger_delay_us = 0
        self.gamma_hw = 1
        self.autos_on = set(AUTO_PARAMS)
        self.parameter_file = None
        self.memory: dict[int, ctypes.Array] = {}
        self.active_mem = None
        self.frames = 0
        self._cache: dict = {}

    # -- physics
    def true_delay_us(self, trigger_delay_us=None, exposure_us=None) -> float:
        """Eq. 1 with the true sync offset realized by a trigger delay."""
        D = self.trigger_delay_us if trigger_delay_us is None else trigger_delay_us
        e = self.exposure_ms * 1e3 if exposure_us is None else exposure_us
        T = self.frame_period_us
        t_o = (self.true_base_us - D + T / 2) % T - T / 2
        return e / 2 - 0.5e6 / self.lines_per_second - t_o

    def codes(self) -> np.ndarray:
        if self.shutter_mode == CONSTANTS["IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_GLOBAL"]:
            if self.render_global is None:
                raise AssertionError("a global-shutter frame, but the camera has no render_global")
            img = np.asarray(self.render_global(float(self.trigger_delay_us), self.exposure_ms * 1e3), np.float64)
            return np.clip(np.rint(img * 4095), 0, 4095).astype("<u2")
        key = (self.trigger_delay_us, round(self.exposure_ms, 9))
        if key not in self._cache:
            img = np.asarray(self.render(self.true_delay_us(), self.exposure_ms * 1e3), np.float64)
            if img.shape != (self.height, self.width):
                raise AssertionError(f"render returned {img.shape}, camera is {(self.height, self.width)}")
            self._cache[key] = np.clip(np.rint(img * 4095), 0, 4095).astype("<u2")
        return self._cache[key]


class FakeUEye(types.ModuleType):
    """The ``pyueye.ueye`` module of a :class:`FakeCamera`."""

    HIDS = ctypes.c_uint
    c_int = int = INT = ctypes.c_int
    c_uint = uint = UINT = ctypes.c_uint
    c_double = double = ctypes.c_double
    c_wchar_p = wchar_p = ctypes.c_wchar_p
    c_mem_p = mem_p = c_mem_p
    IS_RECT = IS_RECT

    def __init__(self, camera: FakeCamera):
        super().__init__("pyueye.ueye")
        self.camera = camera
        for k, v in CONSTANTS.items():
            setattr(self, k, v)

    @staticmethod
    def sizeof(obj):
        return ctypes.sizeof(obj)

    def get_data(self, image_mem, x, y, bits, pitch, copy):
        # the real one: memmove y * pitch bytes from the address into a new buffer -> numpy uint8
        self.camera.calls.append(("get_data", x, y, bits, pitch, copy))
        _expect("get_data image_mem", image_mem, c_mem_p)
        mem = ctypes.create_string_buffer(y * pitch)
        ctypes.memmove(mem, image_mem, y * pitch)
        return np.frombuffer(mem, dtype=np.uint8)

    # -- plumbing
    def _call(self, name, hCam, *args, command=None):
        cam = self.camera
        cam.calls.append((name, *args))
        if name != "is_InitCamera":
            if not cam.open:
                raise AssertionError(f"{name} called on a camera that is not open")
            if _int_arg(f"{name} hCam", hCam, ctypes.c_uint) != cam.handle:
                raise AssertionError(f"{name}: wrong camera handle")
        for key in ((name, command), name):
            if key in cam.fail:
                return cam.fail[key]
        if name in cam.unsupported:
            return CONSTANTS["IS_NOT_SUPPORTED"]
        return None

    # -- functions the driver calls
    def is_InitCamera(self, phCam, hWnd):
        _expect("is_InitCamera phCam", phCam, ctypes.c_uint)  # byref(POINTER(c_uint))
        assert hWnd is None
        cam = self.camera
        if cam.open:
            cam.calls.append(("is_InitCamera", phCam.value))
            return CONSTANTS["IS_CANT_OPEN_DEVICE"]  # locked by a previous user that never exited
        ret = self._call("is_InitCamera", None, phCam.value)
        if ret is not None:
            return ret
        cam.handle = 1 if phCam.value == 0 else phCam.value
        phCam.value = cam.handle
        cam.open = True
        cam.opened += 1
        return 0

    def is_ExitCamera(self, hCam):
        ret = self._call("is_ExitCamera", hCam)
        self.camera.open = False
        self.camera.exited += 1
        self.camera.memory.clear()
        self.camera.active_mem = None
        return 0 if ret is None else ret

    def is_ParameterSet(self, hCam, nCommand, pParam, cbSizeOfParam):
        cmd = _int_arg("is_ParameterSet nCommand", nCommand, ctypes.c_uint)
        ret = self._call("is_ParameterSet", hCam, cmd, getattr(pParam, "value", pParam), command=cmd)
        assert cmd == CONSTANTS["IS_PARAMETERSET_CMD_LOAD_FILE"]
        _expect("is_ParameterSet pParam", pParam, ctypes.c_wchar_p, 0, cbSizeOfParam)
        if ret is not None:
            return ret
        self.camera.parameter_file = pParam.value
        return 0

    def is_DeviceFeature(self, hCam, nCommand, pParam, cbSizeOfParam):
        cmd = _int_arg("is_DeviceFeature nCommand", nCommand, ctypes.c_uint)
        _expect("is_DeviceFeature pParam", pParam, ctypes.c_uint, 4, cbSizeOfParam)
        ret = self._call("is_DeviceFeature", hCam, cmd, pParam.value, command=cmd)
        if ret is not None:
            return ret
        cam, C = self.camera, CONSTANTS
        if cmd == C["IS_DEVICE_FEATURE_CMD_GET_SUPPORTED_FEATURES"]:
            pParam.value = C["IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_GLOBAL"] | (
                C["IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_ROLLING"] if cam.supports_rolling else 0
            )
        elif cmd == C["IS_DEVICE_FEATURE_CMD_SET_SHUTTER_MODE"]:
            if not cam.ignores_shutter_mode:
                cam.shutter_mode = pParam.value
        elif cmd == C["IS_DEVICE_FEATURE_CMD_GET_SHUTTER_MODE"]:
            pParam.value = cam.shutter_mode
        else:
            raise AssertionError(f"unexpected is_DeviceFeature command {cmd}")
        return 0

    def is_SetColorMode(self, hCam, Mode):
        mode = _int_arg("is_SetColorMode Mode", Mode)
        ret = self._call("is_SetColorMode", hCam, mode, command=mode)
        if ret is not None:
            return ret
        if mode == CONSTANTS["IS_GET_COLOR_MODE"]:
            return self.camera.color_mode
        self.camera.color_mode = mode
        return 0

    def is_PixelClock(self, hCam, nCommand, pParam, cbSizeOfParam):
        cmd = _int_arg("is_PixelClock nCommand", nCommand, ctypes.c_uint)
        cam, C = self.camera, CONSTANTS
        if cmd == C["IS_PIXELCLOCK_CMD_GET_RANGE"]:
            if not _is_array(pParam, ctypes.c_uint, 3) or cbSizeOfParam != 12:
                raise TypeError("is_PixelClock GET_RANGE: expected (c_uint * 3) and size 12")
        else:
            _expect("is_PixelClock pParam", pParam, ctypes.c_uint, 4, cbSizeOfParam)
        ret = self._call("is_PixelClock", hCam, cmd, command=cmd)
        if ret is not None:
            return ret
        if cmd == C["IS_PIXELCLOCK_CMD_GET_RANGE"]:
            pParam[0], pParam[1], pParam[2] = cam.pixel_clock_range_mhz
        elif cmd == C["IS_PIXELCLOCK_CMD_SET"]:
            lo, hi, _ = cam.pixel_clock_range_mhz
            if not lo <= pParam.value <= hi:
                return C["IS_INVALID_PARAMETER"]
            cam.pixel_clock_mhz = pParam.value
        elif cmd == C["IS_PIXELCLOCK_CMD_GET"]:
            pParam.value = cam.pixel_clock_mhz
        return 0

    def is_SetHardwareGamma(self, hCam, nMode):
        ret = self._call("is_SetHardwareGamma", hCam, _int_arg("is_SetHardwareGamma nMode", nMode))
        if ret is None:
            self.camera.gamma_hw = nMode
        return 0 if ret is None else ret

    def is_Gamma(self, hCam, nCommand, pParam, cbSizeOfParams):
        _expect("is_Gamma pParam", pParam, ctypes.c_int, 4, cbSizeOfParams)
        cmd = _int_arg("is_Gamma nCommand", nCommand, ctypes.c_uint)
        ret = self._call("is_Gamma", hCam, cmd, pParam.value)
        if ret is not None:
            return ret
        if cmd == CONSTANTS["IS_GAMMA_CMD_SET"]:
            self.camera.gamma = pParam.value
        elif cmd == CONSTANTS["IS_GAMMA_CMD_GET"]:
            pParam.value = self.camera.gamma
        return 0

    def is_LUT(self, hCam, nCommand, pParam, cbSizeOfParams):
        _expect("is_LUT pParam", pParam, ctypes.c_int, 4, cbSizeOfParams)
        ret = self._call("is_LUT", hCam, _int_arg("is_LUT nCommand", nCommand, ctypes.c_uint), pParam.value)
        return 0 if ret is None else ret

    def is_SetGainBoost(self, hCam, mode):
        ret = self._call("is_SetGainBoost", hCam, _int_arg("is_SetGainBoost mode", mode))
        return 0 if ret is None else ret

    def is_EdgeEnhancement(self, hCam, nCommand, pParam, cbSizeOfParam):
        _expect("is_EdgeEnhancement pParam", pParam, ctypes.c_uint, 4, cbSizeOfParam)
        ret = self._call(
            "is_EdgeEnhancement", hCam, _int_arg("is_EdgeEnhancement nCommand", nCommand, ctypes.c_uint), pParam.value
        )
        return 0 if ret is None else ret

    def is_SetAutoParameter(self, hCam, param, pval1, pval2):
        p = _int_arg("is_SetAutoParameter param", param)
        _expect("is_SetAutoParameter pval1", pval1, ctypes.c_double)  # byref(POINTER(c_double))
        if pval2 is not None:
            _expect("is_SetAutoParameter pval2", pval2, ctypes.c_double)
        ret = self._call("is_SetAutoParameter", hCam, p, pval1.value, command=p)
        if ret is not None:
            return ret
        assert p in AUTO_PARAMS, p
        if pval1.value == 0:
            self.camera.autos_on.discard(p)
        return 0

    def is_SetExternalTrigger(self, hCam, nTriggerMode):
        mode = _int_arg("is_SetExternalTrigger nTriggerMode", nTriggerMode)
        ret = self._call("is_SetExternalTrigger", hCam, mode)
        if ret is not None:
            return ret
        if mode == CONSTANTS["IS_GET_EXTERNALTRIGGER"]:
            return self.camera.trigger_mode
        self.camera.trigger_mode = mode
        return 0

    def is_SetTimeout(self, hCam, nMode, Timeout):
        mode = _int_arg("is_SetTimeout nMode", nMode, ctypes.c_uint)
        units = _int_arg("is_SetTimeout Timeout", Timeout, ctypes.c_uint)
        ret = self._call("is_SetTimeout", hCam, mode, units)
        if ret is not None:
            return ret
        assert mode == CONSTANTS["IS_TRIGGER_TIMEOUT"]
        self.camera.timeout_units = units
        return 0

    def is_SetTriggerDelay(self, hCam, nTriggerDelay):
        value = _int_arg("is_SetTriggerDelay nTriggerDelay", nTriggerDelay)
        ret = self._call("is_SetTriggerDelay", hCam, value, command=value)
        if ret is not None:
            return ret
        cam, C = self.camera, CONSTANTS
        lo, hi, step = cam.trigger_range_us
        queries = {
            C["IS_GET_TRIGGER_DELAY"]: cam.trigger_delay_us,
            C["IS_GET_MIN_TRIGGER_DELAY"]: lo,
            C["IS_GET_MAX_TRIGGER_DELAY"]: hi,
            C["IS_GET_TRIGGER_DELAY_GRANULARITY"]: step,
        }
        if value in queries:
            return queries[value]
        if not lo <= value <= hi:
            return C["IS_INVALID_PARAMETER"]
        cam.trigger_delay_us = value // step * step
        return 0

    def is_AOI(self, hCam, nCommand, pParam, SizeOfParam):
        cmd = _int_arg("is_AOI nCommand", nCommand, ctypes.c_uint)
        _expect("is_AOI pParam", pParam, IS_RECT, 16, SizeOfParam)
        ret = self._call("is_AOI", hCam, cmd, command=cmd)
        if ret is not None:
            return ret
        assert cmd == CONSTANTS["IS_AOI_IMAGE_GET_AOI"]
        pParam.s32X, pParam.s32Y, pParam.s32Width, pParam.s32Height = 0, 0, self.camera.width, self.camera.height
        return 0

    def is_Exposure(self, hCam, nCommand, pParam, cbSizeOfParam):
        cmd = _int_arg("is_Exposure nCommand", nCommand, ctypes.c_uint)
        cam, C = self.camera, CONSTANTS
        if cmd == C["IS_EXPOSURE_CMD_GET_EXPOSURE_RANGE"]:
            if not _is_array(pParam, ctypes.c_double, 3) or cbSizeOfParam != 24:
                raise TypeError("is_Exposure GET_EXPOSURE_RANGE: expected (c_double * 3) and size 24")
        else:
            _expect("is_Exposure pParam", pParam, ctypes.c_double, 8, cbSizeOfParam)
        ret = self._call("is_Exposure", hCam, cmd, getattr(pParam, "value", None), command=cmd)
        if ret is not None:
            return ret
        lo, hi, inc = cam.exposure_range_ms
        if cmd == C["IS_EXPOSURE_CMD_GET_EXPOSURE_RANGE"]:
            pParam[0], pParam[1], pParam[2] = lo, hi, inc
        elif cmd == C["IS_EXPOSURE_CMD_SET_EXPOSURE"]:
            # the camera clamps to its range and rounds to its increment; it does NOT write the value back
            cam.exposure_ms = min(max(round(pParam.value / inc) * inc, lo), hi)
        elif cmd == C["IS_EXPOSURE_CMD_GET_EXPOSURE"]:
            pParam.value = cam.exposure_ms
        else:
            raise AssertionError(f"unexpected is_Exposure command {cmd}")
        return 0

    def is_AllocImageMem(self, hCam, width, height, bitspixel, ppcMem, pnMemId):
        w, h, b = (_int_arg("is_AllocImageMem", v) for v in (width, height, bitspixel))
        _expect("is_AllocImageMem ppcMem", ppcMem, c_mem_p)  # byref(POINTER(c_mem_p))
        _expect("is_AllocImageMem pnMemId", pnMemId, ctypes.c_int)
        ret = self._call("is_AllocImageMem", hCam, w, h, b)
        if ret is not None:
            return ret
        cam = self.camera
        assert (w, h, b) == (cam.width, cam.height, 16), (w, h, b)
        buf = ctypes.create_string_buffer(cam.height * cam.pitch)
        mem_id = len(cam.memory) + 1
        cam.memory[mem_id] = buf
        ppcMem.value = ctypes.addressof(buf)
        pnMemId.value = mem_id
        return 0

    def _mem(self, name, pcMem, nMemId):
        _expect(f"{name} pcMem", pcMem, c_mem_p)
        mem_id = _int_arg(f"{name} nMemId", nMemId)
        buf = self.camera.memory.get(mem_id)
        if buf is None or pcMem.value != ctypes.addressof(buf):
            raise AssertionError(f"{name}: unknown image memory")
        return mem_id

    def is_SetImageMem(self, hCam, pcMem, nMemId):
        ret = self._call("is_SetImageMem", hCam)
        mem_id = self._mem("is_SetImageMem", pcMem, nMemId)
        if ret is not None:
            return ret
        self.camera.active_mem = mem_id
        return 0

    def is_GetImageMemPitch(self, hCam, pPitch):
        _expect("is_GetImageMemPitch pPitch", pPitch, ctypes.c_int)  # byref(POINTER(c_int))
        ret = self._call("is_GetImageMemPitch", hCam)
        if ret is not None:
            return ret
        if self.camera.active_mem is None:
            return 108  # IS_NO_ACTIVE_IMG_MEM
        pPitch.value = self.camera.pitch
        return 0

    def is_FreeImageMem(self, hCam, pcMem, nMemId):
        ret = self._call("is_FreeImageMem", hCam)
        mem_id = self._mem("is_FreeImageMem", pcMem, nMemId)
        self.camera.memory.pop(mem_id)
        if self.camera.active_mem == mem_id:
            self.camera.active_mem = None
        return 0 if ret is None else ret

    def is_FreezeVideo(self, hCam, Wait):
        wait = _int_arg("is_FreezeVideo Wait", Wait)
        ret = self._call("is_FreezeVideo", hCam, wait)
        if ret is not None:
            return ret
        cam, C = self.camera, CONSTANTS
        if cam.active_mem is None:
            return 108  # IS_NO_ACTIVE_IMG_MEM
        assert wait == C["IS_WAIT"]
        if cam.trigger_mode == C["IS_SET_TRIGGER_OFF"]:
            raise AssertionError("capture in free-run mode: the frame is not synchronized to the projector")
        if not cam.vsync:
            return C["IS_TIMED_OUT"]
        codes = cam.codes()
        if cam.msb_aligned:
            codes = (codes << 4).astype("<u2")
        lines = np.zeros((cam.height, cam.pitch), np.uint8)
        lines[:, : 2 * cam.width] = codes.view(np.uint8).reshape(cam.height, 2 * cam.width)
        lines[:, 2 * cam.width :] = 0xAB  # padding garbage: must never reach the image
        ctypes.memmove(cam.memory[cam.active_mem], lines.tobytes(), lines.size)
        cam.frames += 1
        return 0


def install(monkeypatch, camera: FakeCamera) -> FakeUEye:
    """Make ``from pyueye import ueye`` return a fake of ``camera`` for one test."""
    module = FakeUEye(camera)
    package = types.ModuleType("pyueye")
    package.ueye = module
    package.__path__ = []
    monkeypatch.setitem(sys.modules, "pyueye", package)
    monkeypatch.setitem(sys.modules, "pyueye.ueye", module)
    return module


def uninstall(monkeypatch) -> None:
    """Make ``import pyueye`` fail, as on a machine without the IDS SDK."""
    monkeypatch.setitem(sys.modules, "pyueye", None)
    monkeypatch.setitem(sys.modules, "pyueye.ueye", None)
