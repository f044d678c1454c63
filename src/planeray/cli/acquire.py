"""``planeray acquire`` and ``planeray devices``: a delay-exposure sweep from any registered device into a stack."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._console import out, progress_bar
from ..errors import InputError
from ._common import _friendly_errors
from ._devices import CalibrationArg, DeviceOptionArg, close_device, describe_options, device_options_from_cli


@_friendly_errors
def acquire(
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Native stack to write (Zarr); resumable.")],
    device: Annotated[
        str, typer.Option(help="Device by name: sim | replay | ueye | ... (`planeray devices`).")
    ] = "sim",
    sweep: Annotated[str, typer.Option(help="Named delay-exposure sweep.")] = "paper",
    scene: Annotated[str | None, typer.Option(help="sim: built-in scene [default: wax].")] = None,
    size: Annotated[
        tuple[int, int] | None, typer.Option(help="sim: image size H W (camera pixels) [default: 128 128].")
    ] = None,
    projector_rows: Annotated[int | None, typer.Option(help="sim: projector rows spanned by the image.")] = None,
    seed: Annotated[int | None, typer.Option(help="sim: seed [default: 0].")] = None,
    replay: Annotated[Path | None, typer.Option(help="replay: the recorded stack to serve.")] = None,
    camera_id: Annotated[int | None, typer.Option(help="ueye: camera ID [default: 0, the first free].")] = None,
    lines_per_second: Annotated[
        float | None, typer.Option(help="Projector scanline velocity, lines/s (sim, ueye) [default: 54000].")
    ] = None,
    base_trigger_delay_us: Annotated[
        float | None,
        typer.Option(help="ueye: trigger delay (us) at t'_o = 0, from `planeray calibrate delay-zero --device ueye`."),
    ] = None,
    calibration: CalibrationArg = None,
    device_option: DeviceOptionArg = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing finished stack.")] = False,
    restart: Annotated[bool, typer.Option(help="Discard an unfinished capture instead of resuming it.")] = False,
):
    """Capture a delay-exposure sweep from a device into a native stack (resumes an interrupted capture).

    A camera (``--device ueye``) needs its calibration: ``--calibration
    acquisition.json`` from ``planeray calibrate lines`` and ``planeray calibrate
    delay-zero --device ueye`` (or ``--lines-per-second`` and
    ``--base-trigger-delay-us``).  The camera is released on every exit.
    """
    from ..acquire import acquire_to_store
    from ..devices import device_options, open_device
    from ..timing import make_sweep

    sw = make_sweep(sweep)
    explicit = dict(
        scene=scene,
        size=size,
        projector_rows=projector_rows,
        seed=seed,
        replay=replay,
        camera_id=camera_id,
        lines_per_second=lines_per_second,
        base_trigger_delay_us=base_trigger_delay_us,
    )
    options = device_options_from_cli(device, explicit, device_option, calibration)
    if "base_trigger_delay_us" in device_options(device) and options.get("base_trigger_delay_us") is None:
        raise InputError(
            f"device {device!r} needs its base trigger delay: run `planeray calibrate delay-zero --device {device} "
            "--write acquisition.json` and pass --calibration acquisition.json (or --base-trigger-delay-us)"
        )
    dev = open_device(device, **options)
    try:
        with progress_bar() as bar:
            task = bar.add_task(f"capturing {len(sw)} images ({device})", total=len(sw))
            path = acquire_to_store(
                dev, sw, out_path, overwrite=overwrite, restart=restart, progress=lambda i: bar.advance(task)
            )
    finally:
        close_device(dev)  # the camera is released however the capture ends (error, Ctrl-C)
    out.print(f"stack: {path}  ({len(sw)} images)")


@_friendly_errors
def devices():
    """List the registered devices (built in, this package's modules, and plug-ins) with their options."""
    from ..devices import is_hardware, list_devices

    for name, description in list_devices().items():
        kind = "camera" if is_hardware(name) else "no hardware"
        out.print(f"[bold]{name}[/]  {description} ({kind})", highlight=False)
        out.print(f"    options: {describe_options(name) or 'none'}", highlight=False)
