"""Sweep runner: capture a delay-exposure stack from any device (Sec. 6, Acquisition).

:func:`acquire_sweep` captures into memory; :func:`acquire_to_store` captures
straight into a native stack store, image by image, and resumes an interrupted
capture without losing or duplicating frames (:mod:`planeray.resumable`).  The
device's own description, the sweep and the planeray version are recorded in
the stack's metadata, which is what it takes to reproduce the capture.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .devices.base import Device, apply_timing
from .io.lock import writes_output
from .resumable import killable, stop_after_units
from .stack import Stack
from .timing import Sweep

__all__ = ["acquire_sweep", "acquire_to_store", "simulate_stack"]


def acquire_sweep(device: Device, sweep: Sweep, *, progress: Callable[[int], None] | None = None) -> Stack:
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

    See Also
    --------
    simulate_stack : the same on the simulated Episcan.
    acquire_to_store : into a resumable store on disk.

    Examples
    --------
    >>> import planeray as pr
    >>> device = pr.SimulatedEpiscan(pr.make_scene("corner", (8, 8), seed=0), seed=0)
    >>> pr.acquire_sweep(device, pr.quick_sweep()).images.shape
    (27, 8, 8)
    """
    images, saturated = [], []
    for i, (d, e) in enumerate(zip(sweep.delay_us, sweep.exposure_us)):
        apply_timing(device, d, e)  # one call per point: a camera realizes delay and exposure together
        img, sat = device.grab()
        images.append(np.asarray(img, np.float32))
        saturated.append(np.asarray(sat, bool))
        if progress is not None:
            progress(i)
    meta = _capture_metadata(device, sweep)
    projector_rows = meta.get("projector_rows") or meta.get("scene", {}).get("projector_rows")
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


def simulate_stack(
    scene, sweep: Sweep, *, camera=None, lines_per_second=None, seed=0, noise=True, progress=None
) -> Stack:
    """Simulate a sweep of a scene on the simulated Episcan (the paper's prototype).

    Builds a :class:`~planeray.devices.SimulatedEpiscan` -- a laser raster
    projector synchronized with a rolling-shutter camera, with the camera's
    noise -- and captures one averaged image per (delay, exposure) of the sweep.

    Parameters
    ----------
    scene : Scene
        A scene with a ground-truth transport (:func:`planeray.scenes.make_scene`).
    sweep : Sweep
        The (delay, exposure) settings, in microseconds (:func:`planeray.timing.paper_sweep`).
    camera : CameraModel, optional
        Noise model (default: the paper's camera, :class:`planeray.camera.CameraModel`).
    lines_per_second : float, optional
        Projector scan rate in rows per second (default: 54,000, the PicoPro's).
    seed : int
        Seed of the noise; the same seed gives the same images.
    noise : bool
        False: the noise-free expected images.
    progress : callable, bool or None
        A callable is called with the index of each finished image; None (default) shows a
        progress display in a Jupyter notebook and nothing elsewhere, True anywhere, False never
        (:func:`planeray._progress.progress_reporter`).

    Returns
    -------
    Stack
        Normalized images (N, H, W) in [0, 1] with their delays, exposures and
        the simulation's record as metadata.

    See Also
    --------
    acquire_sweep : the same with any device.
    acquire_to_store : straight into a resumable store on disk.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Secs. 3, 6.

    Examples
    --------
    >>> import planeray as pr
    >>> scene = pr.make_scene("wax", (8, 8), seed=0)
    >>> stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
    >>> stack.images.shape, float(stack.exposure_us[0])
    ((27, 8, 8), 600.0)
    """
    from ._progress import progress_reporter
    from .devices.simulated import SimulatedEpiscan
    from .timing import PAPER_LINES_PER_SECOND

    device = SimulatedEpiscan(
        scene, camera, lines_per_second=lines_per_second or PAPER_LINES_PER_SECOND, seed=seed, noise=noise
    )
    if callable(progress):
        return acquire_sweep(device, sweep, progress=progress)
    with progress_reporter(progress, len(sweep), f"simulating {len(sweep)} images") as advance:
        return acquire_sweep(device, sweep, progress=None if advance is None else (lambda i: advance(1)))


def _capture_metadata(device: Device, sweep: Sweep) -> dict:
    meta = dict(device.describe())
    meta["sweep"] = sweep.name
    meta["sweep_settings"] = {"delay_us": sweep.delay_us.tolist(), "exposure_us": sweep.exposure_us.tolist()}
    if sweep.record:  # a sweep file's record (a design's prior, camera and criterion) travels with the stack
        meta["sweep_record"] = sweep.record
    return meta


@killable
@writes_output("out")
def acquire_to_store(
    device: Device,
    sweep: Sweep,
    out,
    *,
    overwrite: bool = False,
    restart: bool = False,
    progress: Callable[[int], None] | None = None,
    on_resume: Callable[[int, int], None] | None = None,
) -> Path:
    """Capture a sweep straight into a native stack store; resumable.

    Each image is written, then marked captured.  A capture that is killed and
    started again with the same device description, sweep and output continues
    with the first image not yet captured: no frame is lost or taken twice, and
    with the simulated device (noise seeded per setting) the result is
    byte-identical to an uninterrupted capture.

    Parameters
    ----------
    device : Device
    sweep : Sweep
    out : path
        Native stack store to write.
    overwrite : bool
        Replace an existing finished store.
    restart : bool
        Discard an unfinished capture of the same output instead of resuming it.
    progress : callable, optional
        Called with the index of each image captured (or found captured).
    on_resume : callable, optional
        Called as ``on_resume(done, total)`` (images) when an unfinished capture of
        the same output, device description and sweep is continued.

    Returns
    -------
    pathlib.Path

    See Also
    --------
    planeray.acquire_sweep : the same in memory.
    planeray.read_stack : read the store back.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> device = pr.SimulatedEpiscan(pr.make_scene("corner", (8, 8), seed=0), seed=0)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pr.acquire_to_store(device, pr.quick_sweep(), pathlib.Path(tmp) / "stack.zarr")
    ...     pr.read_stack(path).images.shape
    (27, 8, 8)
    """
    from . import resumable
    from .errors import StackError
    from .io import create_stack_group, writable
    from .io.atomic import check_replaceable

    out = Path(out)
    check_replaceable(out, overwrite=overwrite, kind="stack", error=StackError)
    meta = _capture_metadata(device, sweep)
    fingerprint = hashlib.sha256(json.dumps(meta, sort_keys=True, default=str).encode()).hexdigest()
    first = None
    shape = meta.get("image_shape")
    partial = resumable.partial_path(out)
    if shape is None and not partial.exists():
        # the device does not say its image size: take the first image now
        apply_timing(device, sweep.delay_us[0], sweep.exposure_us[0])
        first = device.grab()
        shape = first[0].shape
    projector_rows = (
        meta.get("projector_rows") or meta.get("scene", {}).get("projector_rows") or (shape[0] if shape else None)
    )

    def create(directory):
        return create_stack_group(
            directory,
            (len(sweep), *shape),
            sweep.delay_us,
            sweep.exposure_us,
            sweep.excluded,
            device.lines_per_second,
            projector_rows,
            meta,
            path=out,
        )

    group = resumable.open_partial(out, fingerprint, len(sweep), create, restart=restart)
    done = resumable.done_units(group)
    if on_resume is not None and done.any():
        on_resume(int(done.sum()), len(sweep))
    _stop_after = stop_after_units()  # the tests' hook: a capture killed midway
    try:
        taken = 0
        for i, (d, e) in enumerate(zip(sweep.delay_us, sweep.exposure_us)):
            if done[i]:
                if progress is not None:
                    progress(i)
                continue
            if _stop_after is not None and taken >= _stop_after:
                return partial
            if i == 0 and first is not None:
                img, sat = first
            else:
                apply_timing(device, d, e)
                img, sat = device.grab()
            img = np.asarray(img, np.float32)
            if img.shape != tuple(group["images"].shape[1:]) or not np.all(np.isfinite(img)):
                raise StackError(f"image {i} from the device has shape {img.shape} or non-finite values", out)
            writable(group, "images")[i] = img  # every chunk stored, all-False masks too (all_chunks_stored)
            writable(group, "saturated")[i] = np.asarray(sat, bool)
            resumable.mark_done(group, i)
            taken += 1
            if progress is not None:
                progress(i)
    except BaseException:
        resumable.discard_if_empty(out)  # a capture that took nothing leaves nothing behind
        raise
    return resumable.promote(out, overwrite=overwrite, kind="stack", error=StackError)
