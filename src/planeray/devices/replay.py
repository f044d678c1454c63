"""Replay device: serves a recorded stack through the device protocol.

Lets every acquisition path (sweep runner, calibration, CLI) run on real data
captured elsewhere, or re-run a simulated capture, without the hardware.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..stack import Stack
from .base import DeviceBase, register_device

__all__ = ["ReplayDevice", "open_replay"]


class ReplayDevice(DeviceBase):
    """Answers ``grab()`` with the recorded image of the current (delay, exposure).

    Parameters
    ----------
    stack : Stack
        The recording (native store or import folder, e.g. via :func:`planeray.io.read_stack`).
    source : str, optional
        Name of the recording, for metadata and error messages.

    See Also
    --------
    planeray.SimulatedEpiscan : a simulated device.
    planeray.acquire_sweep : capture a sweep from any device.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("corner", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> again = pr.acquire_sweep(pr.ReplayDevice(stack), pr.quick_sweep())
    >>> bool(np.array_equal(again.images, stack.images))
    True
    """

    kind = "replay"

    def __init__(self, stack: Stack, *, source: str | None = None):
        self.stack = stack
        self.source = source or stack.metadata.get("source", "stack")
        self.lines_per_second = stack.lines_per_second
        self.delay_us = float(stack.delay_us[0])
        self.exposure_us = float(stack.exposure_us[0])

    def set_delay(self, delay_us: float) -> None:
        self.delay_us = float(delay_us)

    def set_exposure(self, exposure_us: float) -> None:
        if exposure_us <= 0:
            raise InputError(f"exposure must be positive, got {exposure_us}")
        self.exposure_us = float(exposure_us)

    def get_timing_us(self) -> tuple[float, float]:
        """The delay and exposure of the image the next grab serves (us)."""
        return self.delay_us, self.exposure_us

    def grab(self):
        i = self.stack.index_of(self.delay_us, self.exposure_us)
        if i is None:
            raise InputError(
                f"the recording has no image at delay {self.delay_us:g} us, exposure {self.exposure_us:g} us",
                self.source,
            )
        sat = self.stack.saturated
        mask = np.zeros(self.stack.shape, bool) if sat is None else np.asarray(sat[i], bool)
        return self.stack.image(i), mask

    def describe(self) -> dict:
        return {
            "device": self.kind,
            "source": str(self.source),
            "image_shape": list(self.stack.shape),
            "projector_rows": int(self.stack.projector_rows),
            "lines_per_second": self.lines_per_second,
            "recording": self.stack.metadata,
        }


@register_device("replay", "replay of a recorded stack (native store or import folder), served image by image")
def open_replay(*, replay) -> ReplayDevice:
    """A :class:`ReplayDevice` serving the stack at path ``replay`` (``planeray acquire --device replay``)."""
    from ..io import read_stack

    return ReplayDevice(read_stack(replay), source=str(replay))
