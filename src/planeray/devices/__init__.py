"""Devices: the protocol, the simulated Episcan, a replay device and the IDS uEye driver."""

from .base import Device
from .replay import ReplayDevice
from .simulated import SimulatedEpiscan
from .ueye import UEyeEpiscan, pyueye_available

#: Devices chosen by name on the command line.
DEVICES = {"sim": SimulatedEpiscan, "replay": ReplayDevice, "ueye": UEyeEpiscan}

__all__ = ["DEVICES", "Device", "ReplayDevice", "SimulatedEpiscan", "UEyeEpiscan", "pyueye_available"]
