"""``planeray acquire``: a delay-exposure sweep from a device (simulated, replayed, IDS uEye) into a native stack."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._console import out, progress_bar
from ..timing import PAPER_LINES_PER_SECOND
from ._common import _friendly_errors, _load_stack


@_friendly_errors
def acquire(
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Native stack to write (Zarr); resumable.")],
    device: Annotated[str, typer.Option(help="sim | replay | ueye.")] = "sim",
    sweep: Annotated[str, typer.Option(help="Named delay-exposure sweep.")] = "paper",
    scene: Annotated[str, typer.Option(help="sim: built-in scene.")] = "wax",
    size: Annotated[tuple[int, int], typer.Option(help="sim: image size H W (camera pixels).")] = (128, 128),
    projector_rows: Annotated[int | None, typer.Option(help="sim: projector rows spanned by the image.")] = None,
    seed: Annotated[int, typer.Option(help="sim: seed.")] = 0,
    replay: Annotated[Path | None, typer.Option(help="replay: the recorded stack to serve.")] = None,
    camera_id: Annotated[int, typer.Option(help="ueye: camera handle.")] = 0,
    lines_per_second: Annotated[
        float, typer.Option(help="Projector scanline velocity, lines/s (sim, ueye).")
    ] = PAPER_LINES_PER_SECOND,
    base_trigger_delay_us: Annotated[
        float, typer.Option(help="ueye: trigger delay (us) at t'_o = 0 (delay-zero calibration).")
    ] = 0.0,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing finished stack.")] = False,
    restart: Annotated[bool, typer.Option(help="Discard an unfinished capture instead of resuming it.")] = False,
):
    """Capture a delay-exposure sweep from a device into a native stack (resumes an interrupted capture)."""
    from ..acquire import acquire_to_store
    from ..timing import make_sweep

    sw = make_sweep(sweep)
    if device == "sim":
        from ..devices import SimulatedEpiscan
        from ..scenes import make_scene

        scene_ = make_scene(scene, size, projector_rows=projector_rows, seed=seed)
        dev = SimulatedEpiscan(scene_, lines_per_second=lines_per_second, seed=seed)
    elif device == "replay":
        from ..devices import ReplayDevice

        if replay is None:
            raise ValueError("--device replay needs --replay STACK")
        dev = ReplayDevice(_load_stack(replay), source=str(replay))
    elif device == "ueye":
        from ..devices import UEyeEpiscan

        dev = UEyeEpiscan(
            camera_id=camera_id, lines_per_second=lines_per_second, base_trigger_delay_us=base_trigger_delay_us
        )
    else:
        raise ValueError(f"unknown device {device!r}; choose sim, replay or ueye")
    with progress_bar() as bar:
        task = bar.add_task(f"capturing {len(sw)} images ({device})", total=len(sw))
        path = acquire_to_store(
            dev, sw, out_path, overwrite=overwrite, restart=restart, progress=lambda i: bar.advance(task)
        )
    out.print(f"stack: {path}  ({len(sw)} images)")
