"""``planeray acquire`` and ``planeray devices``: a delay-exposure sweep from any registered device into a stack."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.text import Text

from .._console import console, out, progress_bar
from ..errors import InputError
from . import _limits as lim
from ._common import _check_outputs, _friendly_errors
from ._devices import CalibrationArg, DeviceOptionArg, close_device, describe_options, open_device_from_cli


@_friendly_errors
def acquire(
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Native stack to write (Zarr); resumable.")],
    device: Annotated[
        str, typer.Option(help="Device by name: sim | replay | ueye | genicam | ... (`planeray devices`).")
    ] = "sim",
    sweep: Annotated[
        str,
        typer.Option(
            help="Delay-exposure sweep: paper (85 images), quick, or a sweep file (.json, `planeray sweep design`)."
        ),
    ] = "paper",
    scene: Annotated[str | None, typer.Option(help="sim: built-in scene.", show_default="wax")] = None,
    size: Annotated[
        tuple[int, int] | None, typer.Option(help="sim: image size H W (camera pixels).", show_default="128 128")
    ] = None,
    projector_rows: Annotated[
        int | None, typer.Option(help="sim: projector rows spanned by the image.", show_default="H")
    ] = None,
    seed: Annotated[int | None, typer.Option(help="sim: seed.", show_default="0")] = None,
    replay: Annotated[Path | None, typer.Option(help="replay: the recorded stack to serve.")] = None,
    camera_id: Annotated[
        int | None,
        typer.Option(help="ueye: camera ID (0: the first free); genicam: -O camera_id=ID.", show_default="0"),
    ] = None,
    lines_per_second: Annotated[
        float | None,
        typer.Option(help="Projector scanline velocity, lines/s (sim, ueye).", show_default="54000"),
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
    from ..devices import device_options

    _check_outputs(
        (out_path, "stack"), overwrite=overwrite, inputs=[("--replay", replay), ("--calibration", calibration)]
    )  # before the device opens
    sw = lim.sweep(sweep)
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

    def check(options):
        if "base_trigger_delay_us" in device_options(device) and options.get("base_trigger_delay_us") is None:
            raise InputError(
                f"device {device!r} needs its base trigger delay: run `planeray calibrate delay-zero --device "
                f"{device} --write acquisition.json` and pass --calibration acquisition.json (or "
                "--base-trigger-delay-us)"
            )
        if "size" in options:  # the images of the whole sweep, in memory while the scene renders them
            h, w = lim.size(tuple(options["size"]))
            given = f"--size {h} {w}" if size is not None else f"-O size=[{h}, {w}]"
            lim.check_memory(_simulation_bytes(h, w, len(sw)), f"{given} (a capture of {len(sw)} images)")

    dev = open_device_from_cli(device, explicit, device_option, calibration, check=check)

    def resuming(done: int, total: int) -> None:
        console.print(
            Text(
                f"resuming an unfinished capture of {out_path}: {done} of {total} images already captured "
                "(same device description and sweep)"
            ),
            highlight=False,
        )

    try:
        with progress_bar() as bar:
            task = bar.add_task(f"capturing {len(sw)} images ({device})", total=len(sw))
            path = acquire_to_store(
                dev,
                sw,
                out_path,
                overwrite=overwrite,
                restart=restart,
                progress=lambda i: bar.advance(task),
                on_resume=resuming,
            )
    finally:
        close_device(dev)  # the camera is released however the capture ends (error, Ctrl-C)
    out.print(f"stack: {path}  ({len(sw)} images)", markup=False, highlight=False)


def _simulation_bytes(h: int, w: int, n_images: int) -> float:
    """Memory of a simulated capture: the scene's dense transport (a band of 257 offsets) and working copies."""
    return h * w * (257 * 4 * 3 + n_images * 8)


@_friendly_errors
def devices():
    """List the registered devices (built in, this package's modules, and plug-ins) with their options."""
    from ..devices import is_hardware, list_devices

    for name, description in list_devices().items():
        kind = "camera" if is_hardware(name) else "no hardware"
        out.print(Text(name, style="bold") + Text(f"  {description} ({kind})"), highlight=False)
        out.print(Text(f"    options: {describe_options(name) or 'none'}"), highlight=False)
