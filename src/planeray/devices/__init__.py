"""Devices: the protocol, the simulated Episcan and (later) replay and vendor drivers."""

from .base import Device
from .simulated import SimulatedEpiscan

#: Devices chosen by name on the command line.
DEVICES = {"sim": SimulatedEpiscan}

__all__ = ["DEVICES", "Device", "SimulatedEpiscan"]
