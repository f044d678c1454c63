"""What the conventional baselines need of a device: a full-frame capture under a row pattern, in transport units."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from ..timing import RowGeometry

#: Frame period of a conventional 60 Hz projector: one pass over all rows.
DEFAULT_FRAME_PERIOD_US = 1e6 / 60.0


@runtime_checkable
class PatternDevice(Protocol):
    """A projector-camera that can project a row pattern for a full-frame exposure.

    See Also
    --------
    planeray.devices.simulated_device : one.
    capture_direct_global, emulate_delay_image : use it.

    Examples
    --------
    >>> import numpy as np
    >>> from planeray.devices import simulated_device
    >>> device = simulated_device("corner", (16, 16), seed=0)
    >>> isinstance(device, PatternDevice)
    True
    >>> image, saturated = device.capture_pattern(np.ones(16), exposure_us=16_666.7)
    >>> image.shape
    (16, 16)
    """

    def capture_pattern(self, pattern, exposure_us: float, frame_period_us: float = DEFAULT_FRAME_PERIOD_US):
        """Return ``(normalized image (H, W), saturation mask (H, W))``."""


def device_geometry(device, projector_rows=None, camera_rows=None) -> RowGeometry:
    """Camera/projector rows of a device (a simulated device knows them from its scene)."""
    scene = getattr(device, "scene", None)
    if scene is not None:
        g = scene.geometry
        return RowGeometry(int(camera_rows or g.camera_rows), int(projector_rows or g.projector_rows))
    info = device.describe() if hasattr(device, "describe") else {}
    H = camera_rows or (info.get("image_shape") or [None])[0]
    P = projector_rows or info.get("projector_rows")
    if H is None:
        raise ValueError("the device does not report its image size: give camera_rows")
    return RowGeometry(int(H), int(P) if P else None)


def signal_scale(device) -> float:
    """Normalized image value per unit of Eq. 4 for one projector pass."""
    camera = getattr(device, "camera", None)
    if camera is not None and hasattr(camera, "signal_scale"):
        return float(camera.signal_scale)
    info = device.describe() if hasattr(device, "describe") else {}
    return float(info.get("signal_scale", 1.0))


def capture(device, pattern, exposure_us, frame_period_us):
    image, saturated = device.capture_pattern(
        np.asarray(pattern, np.float64), exposure_us, frame_period_us=frame_period_us
    )
    return np.asarray(image, np.float64), np.asarray(saturated, bool)


def to_transport_units(device, images, dark, exposure_us, frame_period_us):
    passes = float(exposure_us) / float(frame_period_us)
    return (images - dark) / (passes * signal_scale(device))
