"""Driver for any GenICam camera (GigE Vision, USB3 Vision) through Aravis: ``--device genicam``.

Optional: Aravis 0.8 with its GObject introspection data (Debian/Ubuntu ``gir1.2-aravis-0.8``) and
PyGObject (``pip install 'planeray[genicam]'``).  The module imports without them; opening the
device without them raises :class:`planeray.errors.DeviceError` saying what to install.

Why Aravis: it speaks GigE Vision and USB3 Vision itself (no vendor GenTL producer to install),
is packaged by the distributions, maintained (LGPL), and ships a fake camera whose node map and
stream machinery are the real ones, which the tests drive.  A Harvesters + GenTL route needs a
vendor's producer (``.cti``) that no package registry carries.

The camera is set up as the IDS uEye driver sets up its camera (:mod:`planeray.devices.ueye`), with
the Standard Features Naming Convention's names, read back after every write:

* **rolling shutter** (``SensorShutterMode = Rolling``; Basler's older ``ShutterMode``); a camera
  without either is taken as it is (most CMOS sensors are rolling) and says so in ``describe()``;
* **hardware trigger** on ``FrameStart`` from ``trigger_source`` (the line the projector's VSYNC
  drives; ``Software`` for a test camera), on the ``trigger_edge`` (``TriggerActivation``);
* **Eq. 1**: for a delay ``t_d`` and exposure ``t_e`` the trigger delay is ``base - t'_o`` with
  ``t'_o = t_e/2 - t_p/2 - t_d`` (``TriggerDelay``, microseconds; ``TriggerDelayAbs`` on older
  Basler GigE cameras), computed with the exposure the camera really set (``ExposureTime``;
  ``ExposureTimeAbs``); ``base_trigger_delay_us`` comes from ``planeray calibrate delay-zero
  --device genicam``;
* **a linear response**: 16- or 12-bit mono (``Mono16``, ``Mono12``: LSB-aligned in 16 bits),
  ``GammaEnable`` off and ``Gamma`` 1, ``LUTEnable`` off, every ``*Auto`` feature off; the camera's
  ``BlackLevel`` read and recorded; images averaged over ``frames_averaged`` frames.

A feature the rig needs and the camera lacks (trigger, trigger delay, exposure, a 12/16-bit mono
format) is refused in one line naming it.  The camera is released on every exit: a failed set-up
closes it before the error leaves the constructor, and :meth:`GenICamEpiscan.close` (or the
``with`` block) releases it whatever happened.

Aravis's fake camera (``-O camera_id=Fake_1``) is described by planeray's own GenICam file
(``aravis_fake_episcan.xml`` beside this module): a rolling-shutter camera with a trigger delay, a
12-bit format, gamma and auto features to switch off; its trigger clock ticks at
``fake_trigger_hz``.  Its image generator draws Mono8 and Mono16 only.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..errors import DeviceError, InputError
from ..timing import PAPER_LINES_PER_SECOND
from ._triggered import TriggeredTiming
from .base import DeviceBase, register_device
from .capabilities import SHUTTER_MODES, TRIGGER_EDGES

__all__ = ["GenICamEpiscan", "aravis_available", "FAKE_GENICAM_XML", "BIT_DEPTHS"]

#: planeray's GenICam description of Aravis's fake camera (a rolling-shutter trigger camera).
FAKE_GENICAM_XML = Path(__file__).with_name("aravis_fake_episcan.xml")
#: The mono formats the driver takes, and their bits (LSB-aligned in 16-bit words), in order of preference.
BIT_DEPTHS = {"Mono16": 16, "Mono12": 12}
#: Feature names by role: the SFNC's first, then vendors' documented alternatives.
FEATURES = {
    "exposure": ("ExposureTime", "ExposureTimeAbs"),
    "trigger_delay": ("TriggerDelay", "TriggerDelayAbs"),
    "shutter": ("SensorShutterMode", "ShutterMode"),
    "gain": ("Gain", "GainAbs", "GainRaw"),
    "black_level": ("BlackLevel", "BlackLevelAbs", "BlackLevelRaw"),
    "readout_time": ("SensorReadoutTime",),  # Basler: the whole frame's read-out, us
}
#: Automatic features switched off for a fixed, linear response.
AUTO_FEATURES = ("ExposureAuto", "GainAuto", "BlackLevelAuto", "BalanceWhiteAuto")
_EDGES = {"rising": "RisingEdge", "falling": "FallingEdge"}
_SHUTTERS = {"rolling": "Rolling", "global": "Global"}
#: Longest wait of one call into Aravis (us): a wait is cut into slices to notice a lost camera and Ctrl-C.
_SLICE_US = 50_000


def _load_aravis():
    """``(Aravis, GLib)`` from PyGObject, or a DeviceError saying what to install."""
    try:
        import gi

        gi.require_version("Aravis", "0.8")
        from gi.repository import Aravis, GLib
    except (ImportError, ValueError) as exc:
        raise DeviceError(
            "the GenICam driver needs Aravis 0.8 and PyGObject: apt-get install gir1.2-aravis-0.8 (Debian, Ubuntu) "
            f"and pip install 'planeray[genicam]' ({type(exc).__name__}: {exc})"
        ) from None
    return Aravis, GLib


def aravis_available() -> bool:
    """Whether Aravis 0.8 can be loaded through PyGObject.

    Returns
    -------
    bool

    See Also
    --------
    GenICamEpiscan : the device it serves.

    Examples
    --------
    >>> isinstance(aravis_available(), bool)
    True
    """
    try:
        _load_aravis()
    except DeviceError:
        return False
    return True


def _tiny(increment) -> bool:
    """Aravis reports an undefined float increment as the smallest double: no increment."""
    return increment is None or not math.isfinite(increment) or increment <= 1e-9


@register_device(
    "genicam",
    "any GenICam camera (GigE Vision, USB3 Vision) through Aravis, rolling shutter triggered by the projector's VSYNC",
    hardware=True,
)
class GenICamEpiscan(TriggeredTiming, DeviceBase):
    """An Episcan-style rig with any GenICam camera (device protocol of :mod:`planeray.devices`).

    Parameters
    ----------
    camera_id : str, optional
        Aravis's device id (``arv-tool-0.8`` lists them, e.g. ``Basler-21934567``), the serial number,
        or ``Fake_1`` for Aravis's fake camera; default: the only camera found.
    lines_per_second : float
        Projector scanline velocity ``v_p`` (``planeray calibrate lines``).
    base_trigger_delay_us : float, optional
        Trigger delay (us) at which ``t'_o = 0`` (``planeray calibrate delay-zero --device genicam``);
        without it the camera opens but refuses to capture.
    frames_averaged : int
        Frames averaged per image (the paper: 8).
    pixel_format : {"Mono16", "Mono12"}, optional
        Default: the first of these the camera offers.
    black_level : int
        Code subtracted before normalizing to ``[0, 1]`` (the camera's ``BlackLevel`` is read and
        recorded, never changed).
    gain : float, optional
        Set the camera's ``Gain`` (its units, dB on SFNC cameras); default: left as it is (recorded).
    region : [x, y, width, height], optional
        The image area (pixels); default: as the camera is set.
    trigger_source : str
        The trigger input the projector's VSYNC drives (``Line0``, ``Line1``...; ``Software``: the
        driver triggers each frame itself, for a test camera).
    trigger_edge : {"rising", "falling"}
        VSYNC edge that triggers a frame.
    trigger_timeout_s : float
        How long a frame is waited for before "no trigger".
    exposure_tolerance_us : float, optional
        Largest accepted difference between requested and realized exposure (default: half the
        camera's exposure increment, plus 0.5 us).
    fake_genicam_xml : path, optional
        Aravis's fake camera only: its GenICam file (default :data:`FAKE_GENICAM_XML`).
    fake_trigger_hz : float
        Aravis's fake camera only: the rate of its trigger clock (the projector's VSYNC).

    See Also
    --------
    UEyeEpiscan : the paper's camera.
    aravis_available : whether it can run here.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 6.

    Examples
    --------
    A GigE Vision or USB3 Vision camera through Aravis (a real camera, or Aravis's fake one):

    >>> from planeray.devices import open_device
    >>> with open_device("genicam", camera_id="Fake_1", base_trigger_delay_us=0.0) as cam:  # doctest: +SKIP
    ...     cam.set_timing(0.0, 600.0)
    ...     image, saturated = cam.grab()
    """

    kind = "genicam"

    def __init__(
        self,
        *,
        camera_id: str | None = None,
        lines_per_second: float = PAPER_LINES_PER_SECOND,
        base_trigger_delay_us: float | None = None,
        frames_averaged: int = 8,
        pixel_format: str | None = None,
        black_level: int = 0,
        gain: float | None = None,
        region=None,
        trigger_source: str = "Line0",
        trigger_edge: str = "rising",
        trigger_timeout_s: float = 1.0,
        exposure_tolerance_us: float | None = None,
        fake_genicam_xml=None,
        fake_trigger_hz: float = 60.0,
    ):
        self._open = False
        # --- options, checked before the camera is touched
        if camera_id is not None and (isinstance(camera_id, bool) or not isinstance(camera_id, (str, int))):
            raise InputError(f"camera_id must be a device id or a serial number, got {camera_id!r}")
        if int(frames_averaged) != frames_averaged or frames_averaged < 1:
            raise InputError(f"frames_averaged must be a positive integer, got {frames_averaged!r}")
        if pixel_format is not None and pixel_format not in BIT_DEPTHS:
            raise InputError(f"pixel_format must be one of {', '.join(BIT_DEPTHS)}, got {pixel_format!r}")
        if isinstance(black_level, bool) or int(black_level) != black_level or black_level < 0:
            raise InputError(f"black_level must be a code >= 0, got {black_level!r}")
        if not (math.isfinite(lines_per_second) and lines_per_second > 0):
            raise InputError(f"lines_per_second must be positive, got {lines_per_second!r}")
        if not (math.isfinite(trigger_timeout_s) and 0.01 <= trigger_timeout_s <= 3600):
            raise InputError(f"trigger_timeout_s must be between 0.01 and 3600 s, got {trigger_timeout_s!r}")
        if trigger_edge not in TRIGGER_EDGES:
            raise InputError(f"trigger_edge must be 'rising' or 'falling', got {trigger_edge!r}")
        if not isinstance(trigger_source, str) or not trigger_source:
            raise InputError(f"trigger_source must be the name of a trigger input, got {trigger_source!r}")
        if base_trigger_delay_us is not None and not math.isfinite(base_trigger_delay_us):
            raise InputError(f"base_trigger_delay_us must be a number, got {base_trigger_delay_us!r}")
        if gain is not None and not (isinstance(gain, (int, float)) and math.isfinite(gain)):
            raise InputError(f"gain must be a number, got {gain!r}")
        if region is not None:
            ok = isinstance(region, (list, tuple)) and len(region) == 4
            ok = ok and all(isinstance(v, int) and not isinstance(v, bool) for v in region)
            if not ok or region[0] < 0 or region[1] < 0 or region[2] < 1 or region[3] < 1:
                raise InputError(f"region must be [x, y, width, height] in pixels, got {region!r}")
        if not (math.isfinite(fake_trigger_hz) and fake_trigger_hz > 0):
            raise InputError(f"fake_trigger_hz must be positive, got {fake_trigger_hz!r}")
        self.camera_id = None if camera_id is None else str(camera_id)
        fake = self.camera_id is not None and self.camera_id.startswith("Fake")
        if fake_genicam_xml is not None:
            fake_genicam_xml = Path(fake_genicam_xml)
            if not fake_genicam_xml.is_file():
                raise InputError("GenICam file of the fake camera not found", fake_genicam_xml)
        self.lines_per_second = float(lines_per_second)
        self._base = None if base_trigger_delay_us is None else float(base_trigger_delay_us)
        self.frames_averaged = int(frames_averaged)
        self.black_level = int(black_level)
        self.trigger_source = trigger_source
        self.trigger_edge = trigger_edge
        self.trigger_timeout_s = float(trigger_timeout_s)
        self.exposure_tolerance_us = exposure_tolerance_us
        self.delay_us, self.exposure_us = 0.0, 600.0
        self._applied = None
        self._settle = 0  # frames to drop after the timing changed (exposed under the old one)
        self._acquiring = False
        self._lost = None  # why the camera went away (control lost), once it did
        self._frame_ids: list[int] = []
        self._frame_times = np.zeros(0)
        self._pool: list = []
        self._unsupported: list[str] = []
        self.features: dict[str, str | None] = {}
        self.shutter_modes: tuple[str, ...] = ("rolling",)
        self._shutter = "rolling"
        self._global_timing = None
        self.realized_exposure_us = None
        self.applied_trigger_delay_us = None

        self._Aravis, self._GLib = _load_aravis()
        Aravis = self._Aravis
        if fake:
            Aravis.set_fake_camera_genicam_filename(str(fake_genicam_xml or FAKE_GENICAM_XML))
            Aravis.enable_interface("Fake")
        self.fake = fake
        device_id = self._find(camera_id)
        try:
            self._camera = Aravis.Camera.new(device_id)
        except self._GLib.Error as exc:
            raise DeviceError(
                f"GenICam camera {device_id!r} could not be opened ({exc.message}): is it in use by another program?"
            ) from None
        self._device = self._camera.get_device()
        self.device_id = device_id
        self._open = True
        try:
            self._lost_handler = self._device.connect("control-lost", self._on_control_lost)
            if fake and hasattr(self._device, "get_fake_camera"):
                self._device.get_fake_camera().set_trigger_frequency(float(fake_trigger_hz))
            self._setup(pixel_format, gain, region)
        except BaseException:
            self._release()
            raise

    # ------------------------------------------------------------------ finding the camera
    def _find(self, camera_id) -> str:
        Aravis = self._Aravis
        if camera_id is not None and str(camera_id).startswith("Fake"):
            return str(camera_id)  # the fake interface opens its camera by id, no discovery
        Aravis.update_device_list()
        found = []
        for i in range(Aravis.get_n_devices()):
            found.append(
                (Aravis.get_device_id(i), Aravis.get_device_serial_nbr(i) or "", Aravis.get_device_physical_id(i) or "")
            )
        if camera_id is None:
            real = [f for f in found if not f[0].startswith("Fake")]
            if len(real) == 1:
                return real[0][0]
            if not real:
                raise DeviceError(
                    "no GenICam camera found (Aravis sees none on GigE Vision or USB3 Vision): is it connected, "
                    "powered, and (GigE) on this machine's subnet? `arv-tool-0.8` lists what Aravis sees"
                )
            raise DeviceError(
                f"{len(real)} GenICam cameras found ({', '.join(f[0] for f in real)}): choose one with -O camera_id=ID"
            )
        want = str(camera_id)
        for device_id, serial, physical in found:
            if want in (device_id, serial, physical):
                return device_id
        seen = ", ".join(f"{f[0]} (serial {f[1]})" for f in found) or "none"
        raise DeviceError(f"no GenICam camera {want!r} (by id, serial number or address); cameras found: {seen}")

    def _on_control_lost(self, *args) -> None:
        self._lost = "Aravis lost control of it (control-lost: unplugged, powered off, or its link dropped)"

    # ------------------------------------------------------------------ features
    def _err(self, what: str, exc) -> DeviceError:
        message = getattr(exc, "message", str(exc))
        if not self._lost and "timeout" in message.lower():
            self._lost = f"it stopped answering: {message}"
        if self._lost:
            return DeviceError(f"camera {self.device_id} vanished ({self._lost}) while {what}")
        return DeviceError(f"camera {self.device_id}: {what} failed ({message})")

    def _has(self, name: str) -> bool:
        try:
            return self._device.get_feature(name) is not None
        except self._GLib.Error:
            return False

    def _pick(self, role: str, *, needed_for: str | None = None) -> str | None:
        """The first feature of ``role`` the camera has; one line naming them when needed and missing."""
        for name in FEATURES[role]:
            if self._has(name):
                self.features[role] = name
                return name
        self.features[role] = None
        if needed_for is not None:
            names = " or ".join(FEATURES[role])
            raise DeviceError(f"camera {self.device_id} has no {names} feature, which the rig needs {needed_for}")
        return None

    #: Aravis's accessors by the kind of feature.
    _KINDS = {"enum": "string", "float": "float", "int": "integer", "bool": "boolean"}

    def _accessor(self, op: str, kind: str):
        return getattr(self._device, f"{op}_{self._KINDS[kind]}_feature_value")

    def _get(self, kind: str, name: str):
        try:
            return self._accessor("get", kind)(name)
        except self._GLib.Error as exc:
            raise self._err(f"reading {name}", exc) from None

    def _set(self, kind: str, name: str, value) -> None:
        setter = self._accessor("set", kind)
        try:
            setter(name, value)
        except self._GLib.Error as exc:
            if not self._acquiring:
                raise self._err(f"setting {name} to {value!r}", exc) from None
            try:
                self._stop_acquisition()  # some cameras refuse changes while acquiring
                setter(name, value)
            except self._GLib.Error as exc2:
                raise self._err(f"setting {name} to {value!r}", exc2) from None

    def _entries(self, name: str) -> list[str]:
        try:
            return list(self._device.dup_available_enumeration_feature_values_as_strings(name) or [])
        except self._GLib.Error as exc:
            raise self._err(f"listing {name}", exc) from None

    def _set_enum(self, name: str, value: str, *, what: str | None = None) -> None:
        """Set an enumeration and read it back."""
        entries = self._entries(name)
        if value not in entries:
            raise DeviceError(
                f"camera {self.device_id} offers no {value!r} for {name} ({what or name}); it offers "
                f"{', '.join(entries) or 'nothing'}"
            )
        self._set("enum", name, value)
        back = self._get("enum", name)
        if back != value:
            raise DeviceError(f"camera {self.device_id}: {name} reads back {back!r} after setting {value!r}")

    def _switch_off(self, name: str, kind: str) -> None:
        """Switch a feature that would make the response non-linear off, if the camera has it; read back."""
        if not self._has(name):
            return
        try:
            if kind == "bool":
                self._set("bool", name, False)
                ok = self._get("bool", name) is False
            else:
                if "Off" not in self._entries(name):
                    self._unsupported.append(f"{name} (no Off)")
                    return
                self._set("enum", name, "Off")
                ok = self._get("enum", name) == "Off"
        except DeviceError:
            self._unsupported.append(f"{name} (not writable)")
            return
        if not ok:
            raise DeviceError(f"camera {self.device_id}: {name} does not stay off (read back after switching it off)")

    def _float_bounds(self, name: str) -> tuple[float, float]:
        try:
            b = self._device.get_float_feature_bounds(name)
        except self._GLib.Error as exc:
            raise self._err(f"reading the range of {name}", exc) from None
        lo, hi = (b.min, b.max) if hasattr(b, "min") else (b[0], b[1])
        return float(lo), float(hi)

    def _increment(self, name: str) -> float | None:
        try:
            inc = float(self._device.get_float_feature_increment(name))
        except (self._GLib.Error, AttributeError, TypeError):
            return None
        return None if _tiny(inc) else inc

    # ------------------------------------------------------------------ set-up
    def _setup(self, pixel_format, gain, region) -> None:
        cam = self._camera
        try:
            self.vendor = cam.get_vendor_name() or ""
            self.model = cam.get_model_name() or ""
        except self._GLib.Error as exc:
            raise self._err("reading its name", exc) from None
        self.serial = self._serial()
        self._stop_acquisition(force=True)
        # 1. rolling shutter, read back
        shutter = self._pick("shutter")
        if shutter is not None:
            entries = self._entries(shutter)
            if "Rolling" not in entries:
                raise DeviceError(
                    f"camera {self.device_id} has no rolling shutter ({shutter}: {', '.join(entries)}); plane-to-ray "
                    "capture needs one"
                )
            self.shutter_modes = ("rolling", "global") if "Global" in entries else ("rolling",)
            self._set_enum(shutter, "Rolling", what="the rolling shutter")
        else:
            self._unsupported.append("SensorShutterMode (none: the shutter is taken as rolling)")
        # 2. a linear mono format, 12 or 16 bits
        offered = self._entries("PixelFormat") if self._has("PixelFormat") else []
        if pixel_format is None:
            usable = [f for f in BIT_DEPTHS if f in offered]
            if not usable:
                raise DeviceError(
                    f"camera {self.device_id} offers no 16- or 12-bit mono pixel format (Mono16, Mono12), which the "
                    f"rig needs for a linear response; it offers {', '.join(offered) or 'no PixelFormat'}"
                )
            pixel_format = usable[0]
        self._set_enum("PixelFormat", pixel_format, what="a linear mono format")
        self.pixel_format = pixel_format
        self.bit_depth = BIT_DEPTHS[pixel_format]
        if not self.black_level < 2**self.bit_depth - 1:
            raise InputError(
                f"black_level must be below {2**self.bit_depth - 1} for {pixel_format}, got {self.black_level}"
            )
        # 3. image area
        if region is not None:
            try:
                cam.set_region(*[int(v) for v in region])
            except self._GLib.Error as exc:
                raise self._err(f"setting the region {list(region)}", exc) from None
        try:
            x, y, w, h = cam.get_region()
            self.payload = int(cam.get_payload())
        except self._GLib.Error as exc:
            raise self._err("reading the region", exc) from None
        if region is not None and [x, y, w, h] != list(region):
            raise DeviceError(f"camera {self.device_id} set the region {[x, y, w, h]} for {list(region)} requested")
        self.region = [int(x), int(y), int(w), int(h)]
        self.width, self.height = int(w), int(h)
        # 4. hardware trigger on FrameStart, from the chosen line, on the chosen edge
        for name in ("TriggerMode", "TriggerSource"):
            if not self._has(name):
                raise DeviceError(
                    f"camera {self.device_id} has no {name} feature, which the rig needs to start each frame on the "
                    "projector's VSYNC"
                )
        if self._has("TriggerSelector") and "FrameStart" in self._entries("TriggerSelector"):
            self._set_enum("TriggerSelector", "FrameStart")
        self._set_enum("TriggerSource", self.trigger_source, what="the trigger input")
        self._set_enum("TriggerMode", "On", what="the hardware trigger")
        if self._has("TriggerActivation"):
            self._set_enum("TriggerActivation", _EDGES[self.trigger_edge], what="the trigger edge")
            self.get_trigger_edge = self._get_trigger_edge  # the trigger_edge capability
            self.set_trigger_edge = self._set_trigger_edge
        elif self.trigger_edge != "rising":
            raise DeviceError(
                f"camera {self.device_id} has no TriggerActivation feature, which triggering on the falling edge needs"
            )
        else:
            self._unsupported.append("TriggerActivation (none: the camera's own edge)")
        self.features["trigger_activation"] = "TriggerActivation" if self._has("TriggerActivation") else None
        # 5. a linear response: no gamma, no LUT, nothing automatic
        self._switch_off("GammaEnable", "bool")
        if self._has("Gamma") and not (self._has("GammaEnable") and self._get("bool", "GammaEnable") is False):
            try:
                self._set("float", "Gamma", 1.0)
            except DeviceError:
                self._unsupported.append("Gamma (not writable)")
        self._switch_off("LUTEnable", "bool")
        for name in AUTO_FEATURES:
            self._switch_off(name, "enum")
        if self._has("ExposureMode") and "Timed" in self._entries("ExposureMode"):
            self._set_enum("ExposureMode", "Timed")
        # 6. gain (set when asked), black level (read and recorded)
        gain_name = self._pick("gain")
        if gain is not None:
            if gain_name is None:
                raise DeviceError(f"camera {self.device_id} has no Gain feature to set -O gain={gain}")
            kind = "int" if gain_name.endswith("Raw") else "float"
            self._set(kind, gain_name, int(round(gain)) if kind == "int" else float(gain))
        gain_kind = "int" if gain_name is not None and gain_name.endswith("Raw") else "float"
        self.gain = None if gain_name is None else float(self._get(gain_kind, gain_name))
        black = self._pick("black_level")
        self.camera_black_level = (
            None if black is None else float(self._get("int" if black.endswith("Raw") else "float", black))
        )
        # 7. exposure and trigger delay: names, ranges, increments
        self._exposure = self._pick("exposure", needed_for="to set the row exposure t_e")
        self._trigger_delay = self._pick("trigger_delay", needed_for="to realize the delay t_d (Eq. 1)")
        self.exposure_range_us = self._float_bounds(self._exposure)
        self.exposure_step_us = self._increment(self._exposure)
        self.trigger_delay_range_us = self._float_bounds(self._trigger_delay)
        self.trigger_delay_step_us = self._increment(self._trigger_delay)
        if self._pick("readout_time") is not None:
            self.get_row_time_us = self._get_row_time_us  # the row_time capability
        # 8. the stream
        try:
            self._stream = cam.create_stream(None, None)
        except self._GLib.Error as exc:
            raise self._err("opening its stream", exc) from None
        if self._stream is None:
            raise DeviceError(f"camera {self.device_id}: no stream could be opened")

    def _serial(self) -> str:
        for name in ("DeviceSerialNumber", "DeviceID"):
            if self._has(name):
                try:
                    return str(self._device.get_string_feature_value(name))
                except self._GLib.Error:
                    continue
        return ""

    # ------------------------------------------------------------------ capabilities
    def get_shutter(self) -> str:
        """The shutter mode read back from the camera (``SensorShutterMode``); rolling when it has none."""
        self._require_open()
        name = self.features.get("shutter")
        if name is None:
            return "rolling"
        value = self._get("enum", name)
        return {"Rolling": "rolling", "Global": "global"}.get(value, f"unknown ({value})")

    def set_shutter(self, mode: str) -> None:
        """Select the rolling or the global shutter and read it back."""
        if mode not in SHUTTER_MODES:
            raise InputError(f"shutter mode must be 'rolling' or 'global', got {mode!r}")
        if mode not in self.shutter_modes:
            raise DeviceError(f"camera {self.device_id} has no {mode}-shutter mode")
        self._require_open()
        name = self.features.get("shutter")
        if name is not None:
            self._stop_acquisition()
            self._set_enum(name, _SHUTTERS[mode], what=f"the {mode} shutter")
        self._shutter = mode
        self._applied = None

    def _get_trigger_edge(self) -> str:
        """The trigger edge read back (``TriggerActivation``)."""
        self._require_open()
        value = self._get("enum", "TriggerActivation")
        return {"RisingEdge": "rising", "FallingEdge": "falling"}.get(value, f"other ({value})")

    def _set_trigger_edge(self, edge: str) -> None:
        if edge not in TRIGGER_EDGES:
            raise InputError(f"trigger edge must be 'rising' or 'falling', got {edge!r}")
        self._require_open()
        self._set_enum("TriggerActivation", _EDGES[edge], what="the trigger edge")
        self.trigger_edge = edge
        self._settle = 1

    def get_gamma(self) -> float:
        """The gamma the camera applies: 1.0 with ``GammaEnable`` off or no ``Gamma`` feature."""
        self._require_open()
        if self._has("GammaEnable") and self._get("bool", "GammaEnable") is False:
            return 1.0
        return float(self._get("float", "Gamma")) if self._has("Gamma") else 1.0

    def _get_row_time_us(self) -> float:
        """Row time (us): Basler's ``SensorReadoutTime`` (the whole frame's read-out) over the rows read."""
        self._require_open()
        return float(self._get("float", self.features["readout_time"])) / self.height

    def get_exposure_range_us(self) -> tuple[float, float]:
        """Shortest and longest exposure the camera accepts (us)."""
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

    def frame_times_s(self) -> np.ndarray:
        """The camera's time stamps (s) of the frames of the last grab (the host's where it gives none)."""
        return self._frame_times.copy()

    def frame_ids(self) -> list[int]:
        """The camera's frame ids (GenICam block ids) of the frames averaged by the last grab."""
        return list(self._frame_ids)

    def _read_timing(self) -> tuple[float, float]:
        """``ExposureTime`` and ``TriggerDelay`` read back from the camera (us)."""
        self._require_open()
        return float(self._get("float", self._exposure)), float(self._get("float", self._trigger_delay))

    @property
    def aravis_device(self):
        """The camera's node map (an ``Aravis.Device``), to read a feature for a check; None once closed."""
        return self._device if self._open else None

    # ------------------------------------------------------------------ timing (Eq. 1)
    def _write_float(self, name: str, value: float, tolerance: float, what: str) -> float:
        """Write a float feature and read it back; refused in one line when the camera set another value."""
        self._set("float", name, float(value))
        back = float(self._get("float", name))
        if abs(back - value) > tolerance:
            raise DeviceError(
                f"camera {self.device_id} set {name} {back:.3f} us for {value:.3f} us requested ({what}; tolerance "
                f"{tolerance:.2f} us)"
            )
        return back

    def _apply(self) -> None:
        self._require_open()
        glob = self._shutter == "global"
        if glob and self._global_timing is None:
            raise DeviceError("a global-shutter grab needs its exposure and trigger delay: call set_global_timing")
        want = ("global", *self._global_timing) if glob else (self.delay_us, self.exposure_us, self._base)
        if self._applied == want:
            return
        e = self._global_timing[0] if glob else self.exposure_us
        lo, hi = self.exposure_range_us
        if not lo - 1e-6 <= e <= hi + 1e-6:
            raise DeviceError(f"exposure {e:g} us is outside the camera's range {lo:g}..{hi:g} us ({self._exposure})")
        if not glob and self._base is None:
            self.trigger_delay_for(self.delay_us, e)  # the one line asking for the calibration
        step = self.exposure_step_us or 0.0
        tol = 0.5 * step + 0.5 if self.exposure_tolerance_us is None else float(self.exposure_tolerance_us)
        self.realized_exposure_us = self._write_float(self._exposure, e, tol, "the exposure")
        # Eq. 1 with the exposure the camera really uses, so that the band is centred where asked
        ideal = self._global_timing[1] if glob else self.trigger_delay_for(self.delay_us, self.realized_exposure_us)
        dmin, dmax = self.trigger_delay_range_us
        if not dmin - 1e-6 <= ideal <= dmax + 1e-6:
            if glob:
                raise DeviceError(f"trigger delay {ideal:g} us is outside the camera's {dmin:g}..{dmax:g} us")
            raise DeviceError(
                f"delay {self.delay_us:g} us at exposure {e:g} us needs trigger delay {ideal:.1f} us "
                f"(base {self._base:g} us - t'_o {self._base - ideal:.1f} us), outside the camera's {dmin:g}..{dmax:g} "
                "us: "
                + (
                    "use a base one projector frame later (calibrate delay-zero picks one that fits the sweep)"
                    if ideal < dmin
                    else "use a base one projector frame earlier"
                )
            )
        dstep = self.trigger_delay_step_us
        tol_d = 0.5 * dstep + 1e-3 if dstep else 1.0  # an integer-us register truncates by up to 1 us
        self.applied_trigger_delay_us = self._write_float(self._trigger_delay, ideal, tol_d, "the trigger delay")
        self._applied = want
        self._settle = 1

    # ------------------------------------------------------------------ capture
    def _require_open(self) -> None:
        if not self._open:
            raise DeviceError(f"the GenICam camera {getattr(self, 'device_id', '')} is closed".replace("  ", " "))

    def _start_acquisition(self) -> None:
        if not self._acquiring:
            try:
                self._camera.start_acquisition()
            except self._GLib.Error as exc:
                raise self._err("starting the acquisition", exc) from None
            self._acquiring = True

    def _stop_acquisition(self, force: bool = False) -> None:
        if self._acquiring or force:
            self._acquiring = False
            try:
                self._camera.stop_acquisition()
            except self._GLib.Error:
                if not force:
                    raise

    def _buffer(self):
        if self._pool:
            return self._pool.pop()
        return self._Aravis.Buffer.new_allocate(self.payload)

    def _drain(self) -> None:
        """Take back every buffer the stream still holds filled (frames nobody asked for)."""
        while True:
            buf = self._stream.try_pop_buffer()
            if buf is None:
                return
            self._pool.append(buf)

    def _wait(self, what: str):
        """The next filled buffer, or one line saying what never came."""
        deadline = time.monotonic() + self.trigger_timeout_s
        while True:
            if self._lost:
                raise DeviceError(f"camera {self.device_id} vanished ({self._lost}) while {what}")
            left_us = int((deadline - time.monotonic()) * 1e6)
            if left_us <= 0:
                if self.trigger_source == "Software":
                    raise DeviceError(
                        f"no frame from camera {self.device_id} within {self.trigger_timeout_s:g} s of its software "
                        f"trigger, {what}: does it take TriggerSoftware?"
                    )
                raise DeviceError(
                    f"no trigger on {self.trigger_source} ({self.trigger_edge} edge) within {self.trigger_timeout_s:g} s "
                    f"({what}): is the projector on, and its VSYNC wired to the camera's {self.trigger_source} input?"
                )
            buf = self._stream.timeout_pop_buffer(min(left_us, _SLICE_US))
            if buf is not None:
                return buf

    def _frames(self, count: int, *, what: str) -> list[np.ndarray]:
        """``count`` triggered frames as 16-bit codes, checked, with their ids and time stamps recorded."""
        self._start_acquisition()
        self._drain()
        for _ in range(count):
            self._stream.push_buffer(self._buffer())
        frames, ids, stamps = [], [], []
        for k in range(count):
            if self.trigger_source == "Software":
                try:
                    self._device.execute_command("TriggerSoftware")
                except self._GLib.Error as exc:
                    raise self._err("sending a software trigger", exc) from None
            buf = self._wait(f"waiting for frame {k + 1} of {count}")
            try:
                frames.append(self._codes(buf))
                ids.append(int(buf.get_frame_id()))
                stamp = int(buf.get_timestamp()) or int(buf.get_system_timestamp())
                stamps.append(stamp * 1e-9)
            finally:
                self._pool.append(buf)
        self._frame_ids, self._frame_times = ids, np.asarray(stamps, np.float64)
        return frames

    def _codes(self, buf) -> np.ndarray:
        status = buf.get_status()
        if status != self._Aravis.BufferStatus.SUCCESS:
            name = getattr(status, "value_nick", str(status))
            raise DeviceError(f"camera {self.device_id} delivered a broken frame (Aravis buffer status: {name})")
        w, h = int(buf.get_image_width()), int(buf.get_image_height())
        if (h, w) != (self.height, self.width):
            raise DeviceError(f"camera {self.device_id} delivered a {w}x{h} frame, not {self.width}x{self.height}")
        data = buf.get_image_data() if hasattr(buf, "get_image_data") else buf.get_data()
        need = 2 * w * h
        if data is None or len(data) < need:
            got = 0 if data is None else len(data)
            raise DeviceError(
                f"camera {self.device_id} delivered {got} bytes for a {w}x{h} {self.pixel_format} frame ({need} expected)"
            )
        codes = np.frombuffer(data, "<u2", count=w * h).reshape(h, w)
        return codes

    def grab(self):
        """Average ``frames_averaged`` triggered frames at the current delay and exposure.

        Returns the normalized float32 image ``(H, W)`` (``(code - black_level) / (top - black_level)``)
        and its saturation mask.  The first frame after a change of timing is dropped: it may have been
        exposed under the old one.
        """
        self._apply()
        full = 2**self.bit_depth - 1
        settle, self._settle = self._settle, 0
        frames = self._frames(settle + self.frames_averaged, what="capturing an image")[settle:]
        self._frame_ids = self._frame_ids[settle:]
        self._frame_times = self._frame_times[settle:]
        total = np.zeros((self.height, self.width), np.float64)
        saturated = np.zeros((self.height, self.width), bool)
        for frame in frames:
            peak = int(frame.max())
            if peak > full:
                raise DeviceError(
                    f"pixel code {peak} above the {self.bit_depth}-bit maximum {full}: camera {self.device_id} does not "
                    f"deliver LSB-aligned {self.pixel_format}"
                )
            saturated |= frame >= full
            total += frame
        image = (total / len(frames) - self.black_level) / (full - self.black_level)
        return image.astype(np.float32), saturated

    def describe(self) -> dict:
        return {
            "device": self.kind,
            "camera": {
                "id": self.device_id,
                "vendor": self.vendor,
                "model": self.model,
                "serial": self.serial,
                "pixel_format": self.pixel_format,
                "bit_depth": self.bit_depth,
                "black_level": self.black_level,
                "camera_black_level": self.camera_black_level,
                "gain": self.gain,
                "frames_averaged": self.frames_averaged,
                "region": list(self.region),
            },
            "image_shape": [self.height, self.width],
            "lines_per_second": self.lines_per_second,
            "base_trigger_delay_us": self._base,
            "shutter": "rolling",
            "shutter_modes": list(self.shutter_modes),
            "trigger": {
                "source": self.trigger_source,
                "edge": self.trigger_edge,
                "timeout_s": self.trigger_timeout_s,
                "delay_range_us": list(self.trigger_delay_range_us),
                "delay_step_us": self.trigger_delay_step_us,
            },
            "exposure_range_us": list(self.exposure_range_us),
            "exposure_step_us": self.exposure_step_us,
            "features": dict(self.features),
            "unsupported_switches": list(self._unsupported),
        }

    # ------------------------------------------------------------------ close
    def _release(self) -> None:
        """Stop the acquisition, drop the stream and the camera (Aravis closes the device when it is freed)."""
        try:
            if getattr(self, "_camera", None) is not None and not self._lost:
                self._stop_acquisition(force=True)
        except Exception:
            pass
        finally:
            self._open = False
            self._acquiring = False
            handler = getattr(self, "_lost_handler", None)
            if handler is not None and getattr(self, "_device", None) is not None:
                try:
                    self._device.disconnect(handler)
                except Exception:
                    pass
            self._pool = []
            self._stream = None
            self._device = None
            self._camera = None

    def close(self) -> None:
        """Stop the acquisition and release the camera; safe to call twice."""
        if self._open:
            self._release()
