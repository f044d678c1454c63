"""A live capture written as a stack the rest of planeray reads (``planeray view --device``'s snapshot)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import write_stack
from ..io.lock import writes_output
from ..stack import Stack
from ..timing import boundary_images

__all__ = ["write_snapshot", "snapshot_path"]


def snapshot_path(folder, view: str, *, now: float | None = None) -> Path:
    """A new name in ``folder`` for a snapshot of ``view``: ``snapshot-YYYYmmdd-HHMMSS-VIEW.zarr`` (``-2``... if taken).

    Parameters
    ----------
    folder : str or path
        Where snapshots go.
    view : str
        The view's name.
    now : float, optional
        The time (seconds since the epoch; default: now).

    Returns
    -------
    pathlib.Path

    See Also
    --------
    write_snapshot : writes it.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = snapshot_path(tmp, "band", now=0.0)
    >>> path.name.startswith("snapshot-"), path.name.endswith("-band.zarr")
    (True, True)
    """
    folder = Path(folder)
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(now))
    path = folder / f"snapshot-{stamp}-{view}.zarr"
    k = 2
    while path.exists():
        path = folder / f"snapshot-{stamp}-{view}-{k}.zarr"
        k += 1
    return path


@writes_output("out")
def write_snapshot(
    frames, out, *, device: dict, lines_per_second: float, projector_rows=None, view: str = "band", excluded=None
) -> Path:
    """Write captured frames as a native stack (one image per frame, in order): locked while written, atomic.

    Parameters
    ----------
    frames : sequence of Frame
        What was captured (one frame, or a cycle of delays).
    out : path
        The stack to create (never replaced).
    device : dict
        The device's description (recorded in the metadata, as ``planeray acquire`` records it).
    lines_per_second : float
        The projector's ``v_p``.
    projector_rows : int, optional
    view : str
        The view it was taken in (recorded).
    excluded : ndarray of bool, optional
        The images left out of demultiplexing (default: the paper's boundary rule).

    Returns
    -------
    pathlib.Path
        The stack written.

    See Also
    --------
    planeray.read_stack : reads it.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> from planeray.live import Frame
    >>> stack = pr.simulate_stack(pr.make_scene("wax", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> frames = [
    ...     Frame(
    ...         i,
    ...         stack.images[i],
    ...         stack.saturated[i],
    ...         float(stack.delay_us[i]),
    ...         float(stack.exposure_us[i]),
    ...         time_s=i / 30,
    ...         captured_at=i / 30,
    ...         generation=0,
    ...     )
    ...     for i in range(len(stack))
    ... ]
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = write_snapshot(
    ...         frames[:3],
    ...         pathlib.Path(tmp) / "snap.zarr",
    ...         device={"device": "sim"},
    ...         lines_per_second=54000.0,
    ...         projector_rows=8,
    ...     )
    ...     pr.read_stack(path).images.shape
    (3, 8, 8)
    """
    frames = list(frames)
    if not frames:
        raise InputError("nothing captured yet to write")
    delay = np.array([f.delay_us for f in frames], np.float64)
    exposure = np.array([f.exposure_us for f in frames], np.float64)
    meta = dict(device)
    meta["live"] = {
        "view": view,
        "frame_indices": [int(f.index) for f in frames],
        "time_s": [float(f.time_s) for f in frames],
        "taken": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    stack = Stack(
        np.stack([f.image for f in frames]).astype(np.float32),
        delay,
        exposure,
        float(lines_per_second),
        excluded=boundary_images(delay, exposure) if excluded is None else np.asarray(excluded, bool),
        saturated=np.stack([f.saturated for f in frames]),
        projector_rows=projector_rows,
        metadata=meta,
    )
    return write_stack(stack, out)
