"""Sweep runner: capture a delay-exposure stack from any device (Sec. 6, Acquisition)."""

from __future__ import annotations

from typing import Callable

import numpy as np

from .devices.base import Device
from .stack import Stack
from .timing import Sweep

__all__ = ["acquire_sweep", "simulate_stack"]


def acquire_sweep(device: Device, sweep: Sweep, progress: Callable[[int], None] | None = None) -> Stack:
    """Capture one averaged image per (delay, exposure) of ``sweep``.

    Parameters
    ----------
    device : Device
        Anything implementing the device protocol.
    sweep : Sweep
    progress : callable, optional
        Called with the index of each finished image (drives progress bars).

    Returns
    -------
    Stack
        In-memory stack with the device's description as metadata.
    """
    images, saturated = [], []
    for i, (d, e) in enumerate(zip(sweep.delay_us, sweep.exposure_us)):
        device.set_delay(float(d))
        device.set_exposure(float(e))
        img, sat = device.grab()
        images.append(np.asarray(img, np.float32))
        saturated.append(np.asarray(sat, bool))
        if progress is not None:
            progress(i)
    meta = dict(device.describe())
    meta["sweep"] = sweep.name
    projector_rows = meta.get("scene", {}).get("projector_rows")
    return Stack(
        np.stack(images),
        sweep.delay_us,
        sweep.exposure_us,
        device.lines_per_second,
        excluded=sweep.excluded,
        saturated=np.stack(saturated),
        projector_rows=projector_rows,
        metadata=meta,
    )


def simulate_stack(scene, sweep: Sweep, camera=None, lines_per_second=None, seed=0, noise=True, progress=None) -> Stack:
    """Simulate a sweep of a scene on the simulated Episcan (convenience for notebooks)."""
    from .devices.simulated import SimulatedEpiscan
    from .timing import PAPER_LINES_PER_SECOND

    device = SimulatedEpiscan(scene, camera, lines_per_second or PAPER_LINES_PER_SECOND, seed, noise)
    return acquire_sweep(device, sweep, progress)
