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
    simulated_device : one.
    capture_direct_global, emulate_delay_image : use it.

    Examples
    --------
    >>> from planeray.baselines import simulated_device
    >>> device = simulated_device("corner", (16, 16), seed=0)
    >>> import numpy as np
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


def simulated_device(
    scene: str,
    size,
    *,
    projector_rows=None,
    seed: int = 0,
    ambient_e_per_us: float = 0.01,
    noise: bool = True,
    lines_per_second: float | None = None,
):
    """The simulated Episcan on built-in ``scene`` as ``planeray emulate`` and ``separate`` use it.

    Parameters
    ----------
    scene : str
        Built-in scene name.
    size : tuple of int
        Image size ``(H, W)`` (camera pixels).
    projector_rows : int, optional
        Projector rows spanned by the image height (default: ``H``, as :func:`planeray.scenes.make_scene`).
    seed : int
        Scene and noise seed.
    ambient_e_per_us : float
        Room light, electrons per microsecond (a dim room by default: conventional
        frames integrate 16.7 ms).
    noise : bool
        Simulate noise.
    lines_per_second : float, optional
        Projector line rate (default: the paper's 54,000 lines/s).

    Returns
    -------
    SimulatedEpiscan

    See Also
    --------
    compare_direct_global, compare_emulation : the comparisons it serves.

    Examples
    --------
    >>> from planeray.baselines import simulated_device
    >>> device = simulated_device("corner", (16, 16), seed=0)
    >>> device.lines_per_second, device.scene.name
    (54000.0, 'corner')
    """
    from ..camera import CameraModel
    from ..devices import SimulatedEpiscan
    from ..scenes import make_scene
    from ..timing import PAPER_LINES_PER_SECOND

    return SimulatedEpiscan(
        make_scene(scene, tuple(size), projector_rows=projector_rows, seed=seed),
        camera=CameraModel(ambient_e_per_us=ambient_e_per_us),
        lines_per_second=lines_per_second or PAPER_LINES_PER_SECOND,
        seed=seed,
        noise=noise,
    )
