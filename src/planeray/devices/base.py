"""The device protocol and the device registry.

Every device -- the simulated Episcan, a replay of a recorded stack, a real
camera driver -- implements the few calls of :class:`Device`, and the sweep
runner (:mod:`planeray.acquire`), the calibration and the command line need
nothing else.

Devices are chosen by name (``planeray acquire --device NAME``).  Each lives in
its own module of this package and registers a factory with
:func:`register_device`; modules are discovered automatically, so adding a
camera is adding one module (or, from another package, one entry point in the
group ``planeray.devices``).  The factory's keyword options are the device's
options on the command line (``--device-option KEY=VALUE``).
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import InputError

__all__ = [
    "Device",
    "DeviceBase",
    "apply_timing",
    "register_device",
    "list_devices",
    "device_options",
    "open_device",
    "is_hardware",
    "ENTRY_POINT_GROUP",
]

#: Entry-point group through which other packages register devices.
ENTRY_POINT_GROUP = "planeray.devices"


@runtime_checkable
class Device(Protocol):
    """A synchronized rolling-shutter projector-camera.

    The timing knobs are the paper's: the delay ``t_d`` between the centre of a
    row's exposure and the centre of its illumination, and the row exposure
    ``t_e`` (Eq. 1).  A device may apply them when they are set or only at the
    next :meth:`grab` (a camera realizes the pair together: its trigger delay
    depends on both), so :meth:`set_timing` is the call that checks a pair.

    See Also
    --------
    DeviceBase : its defaults.
    open_device : a registered device.

    Examples
    --------
    Any object with these methods is a device; the simulated Episcan is one:

    >>> import planeray as pr
    >>> with pr.devices.open_device("sim", scene="corner", size=[8, 8]) as device:
    ...     device.set_timing(0.0, 600.0)
    ...     image, saturated = device.grab()
    >>> isinstance(device, Device), image.shape
    (True, (8, 8))
    """

    #: Projector scanline velocity ``v_p`` (Eq. 2), from calibration.
    lines_per_second: float

    def set_delay(self, delay_us: float) -> None:
        """Set the delay ``t_d`` between illuminated projector row and exposed camera row."""

    def set_exposure(self, exposure_us: float) -> None:
        """Set the row exposure ``t_e``."""

    def set_timing(self, delay_us: float, exposure_us: float) -> None:
        """Set delay and exposure together (one sweep point), refusing a pair the device cannot realize."""

    def grab(self) -> tuple[np.ndarray, np.ndarray]:
        """Capture one averaged image at the current settings.

        Returns the normalized float32 image ``(H, W)`` and its saturation mask.
        """

    def describe(self) -> dict:
        """JSON-serializable description (device kind, camera, sync, scene, seed...).

        It must not change while the device is open: it is the fingerprint
        against which an interrupted capture is resumed.
        """

    def close(self) -> None:
        """Release the hardware; safe to call twice."""


class DeviceBase:
    """Defaults for a device: ``set_timing`` from the two setters, a no-op ``close``, a context manager.

    Subclass it (or write the calls yourself) so that ``with open_device(...) as dev:``
    always releases the hardware.

    See Also
    --------
    Device : the protocol.

    Examples
    --------
    A minimal device of your own (here a constant image), usable by every command through the protocol:

    >>> import numpy as np
    >>> class Flat(DeviceBase):
    ...     kind, lines_per_second = "flat", 54000.0
    ...
    ...     def set_delay(self, delay_us):
    ...         self.delay_us = delay_us
    ...
    ...     def set_exposure(self, exposure_us):
    ...         self.exposure_us = exposure_us
    ...
    ...     def grab(self):
    ...         return np.full((4, 4), 0.5, np.float32), np.zeros((4, 4), bool)
    ...
    ...     def describe(self):
    ...         return {"device": "flat", "image_shape": [4, 4]}
    >>> with Flat() as device:
    ...     device.set_timing(375.0, 600.0)
    ...     float(device.grab()[0].mean()), device.delay_us
    (0.5, 375.0)
    """

    def set_timing(self, delay_us: float, exposure_us: float) -> None:
        self.set_exposure(exposure_us)
        self.set_delay(delay_us)

    def close(self) -> None:
        """Nothing to release."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def apply_timing(device, delay_us: float, exposure_us: float) -> None:
    """Set one sweep point on any device (``set_timing``, or the two setters of an older device).

    Parameters
    ----------
    device : Device
        An open device.
    delay_us, exposure_us : float
        The sweep point, microseconds.

    Returns
    -------
    None

    See Also
    --------
    planeray.acquire_sweep : sets every point of a sweep.

    Examples
    --------
    >>> import planeray as pr
    >>> device = pr.SimulatedEpiscan(pr.make_scene("corner", (8, 8), seed=0), seed=0)
    >>> apply_timing(device, 375.0, 600.0)
    >>> device.grab()[0].shape
    (8, 8)
    """
    set_timing = getattr(device, "set_timing", None)
    if set_timing is not None:
        set_timing(float(delay_us), float(exposure_us))
    else:
        device.set_exposure(float(exposure_us))
        device.set_delay(float(delay_us))


# ---------------------------------------------------------------------------- registry
@dataclass(frozen=True)
class _Entry:
    open: Callable[..., Device]
    description: str
    hardware: bool


_REGISTRY: dict[str, _Entry] = {}
_BROKEN: dict[str, str] = {}  # plug-ins (entry points) that failed to import, and why
_DISCOVERED = False


def register_device(name: str, description: str, *, hardware: bool = False):
    """Decorator registering a device factory (a class or a function) under ``name``.

    The factory takes keyword options only; those without a default are
    required.  ``hardware`` marks devices that talk to a camera (the command line
    then asks for their calibration).  See ``devices/simulated.py`` for a
    factory function and ``devices/ueye.py`` for a registered class.

    Parameters
    ----------
    name : str
        The device's name (``--device NAME``).
    description : str
        One line for ``planeray devices``.
    hardware : bool
        Whether it talks to a camera.

    Returns
    -------
    callable
        The decorator; it returns the factory unchanged.

    See Also
    --------
    open_device : opens a registered device.

    Examples
    --------
    A device factory registered by name, then opened like the built-in ones:

    >>> import planeray as pr
    >>> @register_device("doc-sim", "the simulated Episcan on the corner scene (an example)")
    ... def _open(*, seed: int = 0):
    ...     return pr.SimulatedEpiscan(pr.make_scene("corner", (8, 8), seed=0), seed=seed)
    >>> "doc-sim" in list_devices(), open_device("doc-sim").lines_per_second
    (True, 54000.0)
    >>> del _REGISTRY["doc-sim"]  # this example leaves the registry as it found it
    """

    def deco(factory):
        if name in _REGISTRY and _REGISTRY[name].open is not factory:
            raise ValueError(f"device {name!r} registered twice")
        _REGISTRY[name] = _Entry(factory, description, bool(hardware))
        return factory

    return deco


def _discover() -> None:
    global _DISCOVERED
    if _DISCOVERED:
        return
    _DISCOVERED = True
    package = __name__.rsplit(".", 1)[0]
    for mod in pkgutil.iter_modules(importlib.import_module(package).__path__):
        if mod.name != "base" and not mod.name.startswith("_"):
            importlib.import_module(f"{package}.{mod.name}")
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            ep.load()  # the module registers its devices on import
        except Exception as exc:  # a broken plug-in must not take the built-in devices down
            _BROKEN[ep.name] = f"{type(exc).__name__}: {exc}"


def list_devices() -> dict[str, str]:
    """Names and one-line descriptions of all registered devices.

    Returns
    -------
    dict of str to str
        Name -> description.

    See Also
    --------
    open_device : opens one.

    Examples
    --------
    >>> sorted(list_devices())[:3]
    ['genicam', 'replay', 'sim']
    """
    _discover()
    return {k: v.description for k, v in sorted(_REGISTRY.items())}


def _entry(name: str) -> _Entry:
    _discover()
    if name not in _REGISTRY:
        hint = f" (its plug-in failed to load: {_BROKEN[name]})" if name in _BROKEN else ""
        raise InputError(f"unknown device {name!r}{hint}; choose one of {', '.join(sorted(_REGISTRY))}")
    return _REGISTRY[name]


def device_options(name: str) -> dict[str, object]:
    """The options of device ``name`` and their defaults (``inspect.Parameter.empty`` when required).

    Parameters
    ----------
    name : str
        A registered device.

    Returns
    -------
    dict of str to object
        Option -> default.

    See Also
    --------
    open_device : opens it with options.

    Examples
    --------
    >>> options = device_options("sim")
    >>> options["scene"], options["noise"]
    ('wax', True)
    """
    sig = inspect.signature(_entry(name).open)
    return {
        p.name: p.default
        for p in sig.parameters.values()
        if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD) and p.name != "self"
    }


def is_hardware(name: str) -> bool:
    """Whether device ``name`` talks to a camera.

    Parameters
    ----------
    name : str
        A registered device.

    Returns
    -------
    bool

    See Also
    --------
    list_devices : every device.

    Examples
    --------
    >>> is_hardware("sim"), is_hardware("ueye")
    (False, True)
    """
    return _entry(name).hardware


def open_device(name: str, **options) -> Device:
    """Open a registered device by name with its keyword options.

    Parameters
    ----------
    name : str
        A registered device (:func:`list_devices`).
    **options
        Its keyword options (:func:`device_options`).

    Returns
    -------
    Device
        Open; close it (or use ``with``).

    Raises
    ------
    InputError
        Unknown device, an option the device does not take, or a required option missing.

    See Also
    --------
    register_device : adds a device.

    Examples
    --------
    >>> dev = open_device("sim", scene="diffuse_plane", size=(16, 16), seed=1)
    >>> dev.set_timing(0.0, 600.0)
    >>> dev.grab()[0].shape
    (16, 16)
    >>> open_device("sim", camera_id=0)
    Traceback (most recent call last):
    ...
    planeray.errors.InputError: device 'sim' has no option 'camera_id'; its options: delay_error_us, display, exposure_range_us, frame_rate_hz, frames_averaged, gamma, lines_per_second, noise, projector_rows, pulse_amplitude, pulse_bpm, row_time_error, scene, screen, seed, sensor_rows, shutter, size, trigger_delay_range_us, trigger_edge, trigger_wired
    """
    entry = _entry(name)
    accepted = device_options(name)
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        plural = "s" if len(unknown) > 1 else ""
        raise InputError(
            f"device {name!r} has no option{plural} {', '.join(repr(u) for u in unknown)}; "
            f"its options: {', '.join(sorted(accepted)) or 'none'}"
        )
    missing = sorted(k for k, v in accepted.items() if v is inspect.Parameter.empty and k not in options)
    if missing:
        raise InputError(f"device {name!r} needs the option{'s' if len(missing) > 1 else ''} {', '.join(missing)}")
    return entry.open(**options)
