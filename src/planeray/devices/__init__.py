"""Devices: the protocol, the registry, the simulated Episcan, a replay device, the IDS uEye and GenICam drivers.

Adding a camera is adding one module to this package (or an entry point in the
group ``planeray.devices`` of another package) that registers a factory with
:func:`register_device`; see the README, "Capturing with a real camera".
"""

from .base import (
    Device,
    DeviceBase,
    apply_timing,
    device_options,
    is_hardware,
    list_devices,
    open_device,
    register_device,
)
from .genicam import GenICamEpiscan, aravis_available
from .replay import ReplayDevice
from .simulated import SimulatedEpiscan, simulated_device
from .ueye import UEyeEpiscan, pyueye_available

#: The built-in devices by name (every registered one: :func:`list_devices`).
DEVICES = {"sim": SimulatedEpiscan, "replay": ReplayDevice, "ueye": UEyeEpiscan, "genicam": GenICamEpiscan}

__all__ = [
    "DEVICES",
    "Device",
    "DeviceBase",
    "GenICamEpiscan",
    "ReplayDevice",
    "SimulatedEpiscan",
    "UEyeEpiscan",
    "apply_timing",
    "aravis_available",
    "device_options",
    "is_hardware",
    "list_devices",
    "open_device",
    "pyueye_available",
    "simulated_device",
    "register_device",
]
