"""A device live: continuous capture, the live views (band, vein, Eq. 7, pulse) and snapshots as stacks.

* :mod:`~planeray.live.capture`   :class:`LiveCapture`, a device captured in a thread of its own, its frames
* :mod:`~planeray.live.views`     the views of frames: :func:`vein_view`, :func:`composite_view`, :class:`PulseMonitor`
* :mod:`~planeray.live.snapshot`  :func:`write_snapshot`, frames written as a native stack
* :mod:`~planeray.live.transport` :class:`LiveTransport`, a sweep's rolling window demultiplexed as it comes

The explorer (``planeray view --device NAME``, :mod:`planeray.viewer`) is one front end of it.
"""

from .capture import Frame, LiveCapture
from .snapshot import snapshot_path, write_snapshot
from .transport import LiveTransport, LiveUpdate, WindowSolver, window_stack
from .views import DEFAULT_CYCLE_DELAYS_US, PULSE_WINDOW_S, VIEWS, PulseMonitor, composite_view, cycle_delays, vein_view

__all__ = [
    "Frame",
    "LiveCapture",
    "LiveTransport",
    "LiveUpdate",
    "WindowSolver",
    "window_stack",
    "VIEWS",
    "DEFAULT_CYCLE_DELAYS_US",
    "PULSE_WINDOW_S",
    "PulseMonitor",
    "composite_view",
    "cycle_delays",
    "vein_view",
    "snapshot_path",
    "write_snapshot",
]
