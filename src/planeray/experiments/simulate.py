"""A scene swept on the simulated Episcan, written as a stack (``planeray simulate``).

:func:`simulate_to_store` takes a built-in scene (``planeray scenes``), a Mitsuba 3 scene file
(``mitsuba:FILE.xml``, rendered as ``planeray render`` does) or a transport store, captures the
sweep with a camera model, and writes the stack (and, on request, the ground-truth transport).
"""

from __future__ import annotations

from pathlib import Path

from ..camera import CameraModel
from ..io.lock import writes_output
from ..timing import PAPER_LINES_PER_SECOND, Sweep
from .workflow import Stages

__all__ = ["simulate_to_store"]


@writes_output("out")
def simulate_to_store(
    scene: str,
    out,
    *,
    sweep: Sweep,
    size: tuple[int, int] | None = None,
    projector_rows: int | None = None,
    seed: int = 0,
    lines_per_second: float = PAPER_LINES_PER_SECOND,
    camera: CameraModel | None = None,
    noise: bool = True,
    render_options: dict | None = None,
    truth=None,
    overwrite: bool = False,
    progress=None,
):
    """Capture ``sweep`` of ``scene`` on the simulated Episcan and write the stack to ``out`` (Zarr).

    Parameters
    ----------
    scene : str
        A built-in scene name, ``mitsuba:FILE.xml``, or the path of a transport store.
    out : str or os.PathLike
        Stack to write.
    sweep : Sweep
        The delay-exposure settings (:func:`planeray.timing.make_sweep`, a sweep file).
    size : (int, int), optional
        Image size ``(H, W)``, camera pixels (default 128 x 128; a store's own).
    projector_rows : int, optional
        Projector rows spanned by the image (default ``H``; a store's own).
    seed : int
        Seed of the scene's textures and the camera noise.
    lines_per_second : float
        Projector scanline velocity ``v_p`` (Eq. 2).
    camera : CameraModel, optional
        The camera's noise model (default :class:`~planeray.camera.CameraModel`).
    noise : bool
        Simulate noise (``False``: expected images).
    render_options : dict, optional
        Rendering options of a ``mitsuba:`` scene (:func:`planeray.render.render_transport`).
    truth : str or os.PathLike, optional
        Also write the scene's ground-truth transport store here.
    overwrite : bool
        Replace existing outputs planeray wrote.
    progress : callable, optional
        ``progress(stage, done, total)`` (:mod:`planeray.experiments.workflow`).

    Returns
    -------
    (Stack, Scene)
        The stack written and the scene it captured.
    """
    from ..acquire import acquire_sweep
    from ..devices import SimulatedEpiscan
    from ..io import store_format, write_stack, write_transport
    from ..scenes import make_scene
    from ..scenes.store_scene import scene_from_transport_store

    stages = Stages(progress)
    if store_format(Path(scene)) is not None:
        stages.stage(f"reading transport store {scene}")
        sc = scene_from_transport_store(scene, shape=size, projector_rows=projector_rows)
    else:
        shape = size or (128, 128)
        stages.stage(f"building scene {scene} {shape[0]}x{shape[1]}")
        sc = make_scene(scene, shape, projector_rows=projector_rows, seed=seed, **(render_options or {}))
    device = SimulatedEpiscan(
        sc, camera=camera or CameraModel(), lines_per_second=lines_per_second, seed=seed, noise=noise
    )
    advance = stages.stage(f"capturing {len(sweep)} images", len(sweep))
    stack = acquire_sweep(device, sweep, progress=lambda i: advance())
    advance = stages.stage("writing stack", len(sweep))
    write_stack(stack, out, overwrite=overwrite, progress=lambda i: advance())
    if truth is not None:
        attrs = {"lines_per_second": lines_per_second, "method": "ground_truth", "scene": sc.params}
        write_transport(sc.transport, truth, attrs=attrs, overwrite=overwrite)
    return stack, sc
