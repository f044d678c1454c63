"""Optional device capabilities: what calibration captures and ``planeray rig check`` use beyond the sweep.

The sweep needs only the protocol of :class:`planeray.devices.Device`.  A
camera may offer more, each part a small protocol of its own that a driver
implements when its hardware has it (and that the simulated device and the
uEye driver implement):

==================  =============================================================================
``global_shutter``  switch rolling / global shutter (read back), and time a global exposure from
                    the trigger: the line-velocity calibration (``planeray calibrate lines --device``)
``trigger_edge``    which edge of the projector's VSYNC starts a frame (read back, settable)
``frame_times``     the camera's own time stamps of the frames of the last grab (frame rate check)
``gamma``           the camera's gamma, read back (1.0: linear)
``row_time``        the rolling shutter's row time, read back (us per camera row)
``ranges``          the exposure and trigger-delay ranges the camera can realize (us)
``steps``           the steps of its exposure and trigger delay (us): the settings it realizes exactly
``timing``          the delay and exposure the device realizes now, read back from the camera (us)
==================  =============================================================================

Use :func:`capabilities` to list what a device has and :func:`require` to refuse,
in one line, a device without what a command needs.  A capability is recognized
by its methods (``isinstance(dev, GlobalShutter)``), so a new camera needs no
registration: implement the methods, with units as named, and raise
:class:`planeray.errors.DeviceError` when the camera does not do what was asked
(a mode that does not read back as set).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import InputError

__all__ = [
    "SHUTTER_MODES",
    "TRIGGER_EDGES",
    "GlobalShutter",
    "TriggerEdge",
    "FrameTimes",
    "Gamma",
    "RowTime",
    "Ranges",
    "Steps",
    "TimingReadback",
    "CAPABILITIES",
    "capabilities",
    "has",
    "require",
]

#: Shutter modes a camera may have.
SHUTTER_MODES = ("rolling", "global")
#: VSYNC edges that may trigger a frame.
TRIGGER_EDGES = ("rising", "falling")


@runtime_checkable
class GlobalShutter(Protocol):
    """A camera that switches between rolling and global shutter.

    In global mode :meth:`~planeray.devices.Device.grab` takes every pixel's
    exposure at once: ``exposure_us`` long, opened ``trigger_delay_us`` after the
    trigger (the projector's VSYNC), averaged over the frames as a sweep image is.
    ``set_timing`` (delay and exposure of Eq. 1) applies to the rolling mode.
    """

    shutter_modes: tuple[str, ...]

    def get_shutter(self) -> str:
        """The mode the camera is in, read back from it (``"rolling"`` or ``"global"``)."""

    def set_shutter(self, mode: str) -> None:
        """Switch to ``mode``; DeviceError if the camera does not read back as switched."""

    def set_global_timing(self, exposure_us: float, trigger_delay_us: float) -> None:
        """The global exposure (us) and when it opens after the trigger (us)."""


@runtime_checkable
class TriggerEdge(Protocol):
    """A camera whose trigger input's active edge is set in software."""

    def get_trigger_edge(self) -> str:
        """``"rising"`` or ``"falling"``, read back."""

    def set_trigger_edge(self, edge: str) -> None:
        """Trigger on ``edge`` from the next frame on."""


@runtime_checkable
class FrameTimes(Protocol):
    """A camera that stamps its frames with its own clock."""

    def frame_times_s(self) -> np.ndarray:
        """Time stamps (s, any origin) of the frames of the last grab, in order."""


@runtime_checkable
class Gamma(Protocol):
    """A camera whose gamma can be read back."""

    def get_gamma(self) -> float:
        """The gamma the camera applies (1.0: linear output)."""


@runtime_checkable
class RowTime(Protocol):
    """A rolling shutter whose row time can be read back."""

    def get_row_time_us(self) -> float:
        """Time between the exposure starts of two adjacent camera rows (us)."""


@runtime_checkable
class Ranges(Protocol):
    """A camera that says which exposures and trigger delays it can realize."""

    def get_exposure_range_us(self) -> tuple[float, float]:
        """Shortest and longest exposure (us)."""

    def get_trigger_delay_range_us(self) -> tuple[float, float]:
        """Shortest and longest trigger delay (us)."""


@runtime_checkable
class Steps(Protocol):
    """A camera whose exposure and trigger delay move in steps (a sweep designer puts its candidates on them)."""

    def get_exposure_step_us(self) -> float:
        """The exposure's step (us; 0: continuous)."""

    def get_trigger_delay_step_us(self) -> float:
        """The trigger delay's step (us; 0: continuous); the delay of Eq. 1 moves with it."""


@runtime_checkable
class TimingReadback(Protocol):
    """A device that says which delay and exposure it realizes now (the conformance suite reads it back)."""

    def get_timing_us(self) -> tuple[float, float]:
        """``(t_d, t_e)`` in us as realized: a camera's from its trigger delay and exposure read back (Eq. 1)."""


#: Capability names and their protocols.
CAPABILITIES = {
    "global_shutter": GlobalShutter,
    "trigger_edge": TriggerEdge,
    "frame_times": FrameTimes,
    "gamma": Gamma,
    "row_time": RowTime,
    "ranges": Ranges,
    "steps": Steps,
    "timing": TimingReadback,
}


def has(device, name: str) -> bool:
    """Whether ``device`` offers capability ``name`` (one of :data:`CAPABILITIES`).

    Examples
    --------
    >>> from planeray.devices import open_device
    >>> has(open_device("sim", size=(16, 16)), "global_shutter")
    True
    """
    if name not in CAPABILITIES:
        raise ValueError(f"unknown capability {name!r}; known: {', '.join(CAPABILITIES)}")
    if not isinstance(device, CAPABILITIES[name]):
        return False
    if name == "global_shutter":
        return "global" in tuple(getattr(device, "shutter_modes", ()))
    return True


def capabilities(device) -> list[str]:
    """The capabilities ``device`` offers, by name."""
    return [name for name in CAPABILITIES if has(device, name)]


def require(device, name: str, needed_for: str) -> None:
    """Refuse in one line a device without capability ``name``, saying what needed it.

    Raises
    ------
    InputError
        ``device 'replay' has no global-shutter mode, which calibrate lines needs``.
    """
    if not has(device, name):
        kind = getattr(device, "kind", type(device).__name__)
        what = {"global_shutter": "global-shutter mode"}.get(name, f"{name.replace('_', ' ')} control")
        raise InputError(f"device {kind!r} has no {what}, which {needed_for} needs")
