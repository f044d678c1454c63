"""The device protocol: what a synchronized projector-camera must offer.

Every device -- the simulated Episcan, a replay of a recorded stack, a real
camera driver -- implements these few calls, and the sweep runner
(:mod:`planeray.acquire`) needs nothing else.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["Device"]


@runtime_checkable
class Device(Protocol):
    """A synchronized rolling-shutter projector-camera."""

    #: Projector scanline velocity ``v_p`` (Eq. 2), from calibration.
    lines_per_second: float

    def set_delay(self, delay_us: float) -> None:
        """Set the delay ``t_d`` between illuminated projector row and exposed camera row."""

    def set_exposure(self, exposure_us: float) -> None:
        """Set the row exposure ``t_e``."""

    def grab(self) -> tuple[np.ndarray, np.ndarray]:
        """Capture one averaged image at the current settings.

        Returns the normalized float32 image ``(H, W)`` and its saturation mask.
        """

    def describe(self) -> dict:
        """JSON-serializable description (device kind, camera, sync, scene, seed...)."""
