"""Conventional projector-camera baselines against synchronized imaging, on the simulated device.

``planeray separate direct-global`` (Nayar et al. 2006) and ``planeray emulate``
(digital epipolar emulation, Sec. 5.1); both write images and numbers against ground truth.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from .._console import out
from ..errors import InputError
from ..timing import PAPER_LINES_PER_SECOND, PAPER_PROJECTOR_ROWS
from . import _limits as lim
from ._common import _check_outputs, _friendly_errors, stage_bars

#: The images each command writes (a .png preview and a .tif of the values each) and its numbers file
#: (:data:`planeray.experiments.baselines.EMULATION_IMAGES`, ``DIRECT_GLOBAL_IMAGES``).
EMULATE_IMAGES = ("emulated", "synchronized", "truth")
SEPARATE_IMAGES = ("nayar_direct", "nayar_global", "epipolar", "truth_direct", "truth_global")


def _outputs(out_dir: Path, images, name: str) -> list:
    files = [(out_dir / f"{key}{ext}", "image") for key in images for ext in (".png", ".tif")]
    return files + [(out_dir / f"{name}.json", "record")]


def _check_common(out_dir: Path, images, name: str, *, overwrite: bool, size, projector_rows, seed, ambient_e_per_us):
    """Everything these commands take, checked before any work (the outputs first)."""
    lim.folder(out_dir, "--out")
    _check_outputs(*_outputs(out_dir, images, name), overwrite=overwrite)
    size = lim.size(size)
    lim.projector_rows(projector_rows)
    lim.seed(seed)
    lim.nonnegative(ambient_e_per_us, "--ambient-e-per-us", maximum=1e6)
    lim.check_memory(size[0] * size[1] * (257 * 4 * 3 + 200 * 8), f"--size {size[0]} {size[1]}")
    return size


def _scan_time_us(projector_rows, lines_per_second: float = PAPER_LINES_PER_SECOND) -> float:
    """The time the projector takes to scan all its rows (us): no delay or exposure means more."""
    return 1e6 * (projector_rows or PAPER_PROJECTOR_ROWS) / lines_per_second


separate_app = typer.Typer(help="Conventional projector-camera baselines (Nayar et al. 2006).", no_args_is_help=True)


def _sim_device(
    scene: str,
    size,
    projector_rows,
    seed: int,
    ambient_e_per_us: float,
    noise: bool,
    lines_per_second: float = PAPER_LINES_PER_SECOND,
):
    from ..devices import simulated_device

    return simulated_device(
        scene,
        size,
        projector_rows=projector_rows,
        seed=seed,
        ambient_e_per_us=ambient_e_per_us,
        noise=noise,
        lines_per_second=lines_per_second,
    )


def _print_results(out_dir: Path, numbers: dict, name: str) -> None:
    """What a comparison wrote: its captures, and each error's relative RMSE and MAE."""
    out.print(f"{name}: {out_dir}  {json.dumps(numbers.get('n_captures', {}))}", markup=False, highlight=False)
    errors = numbers.get("errors", {})
    for key, value in errors.items():
        overall = value.get("all", value) if isinstance(value, dict) else value
        if isinstance(overall, dict) and "relative_rmse" in overall:
            rmse, mae = overall["relative_rmse"], overall["mae"]
            rmse = "n/a (no light in the truth)" if rmse is None else f"{rmse:.4f}"
            mae = "n/a" if mae is None else f"{mae:.4g}"
            out.print(f"  {key:28s} relative RMSE {rmse}  MAE {mae}", markup=False, highlight=False)


@separate_app.command("direct-global")
@_friendly_errors(
    options={
        "n_shifts": "--shifts",
        "low": "--contrast-b",
        "period_rows": "--period-rows",
        "exposure_us": "--epipolar-exposure-us",
        "shape": "--size",
    }
)
def separate_direct_global(
    scene: Annotated[str, typer.Argument(help="Built-in scene (simulated conventional projector-camera).")],
    out_dir: Annotated[
        Path, typer.Option("--out", "-o", help="Folder for images (.png previews, .tif values) and numbers.")
    ],
    size: Annotated[tuple[int, int], typer.Option(help="Image size H W (camera pixels).")] = (128, 128),
    projector_rows: Annotated[
        int | None, typer.Option(help="Projector rows spanned by the image.")
    ] = PAPER_PROJECTOR_ROWS,
    seed: Annotated[int, typer.Option(help="Seed.")] = 0,
    period_rows: Annotated[
        int | None,
        typer.Option(
            "--period-rows", "--period", help="Stripe period in projector rows (default: resolvable by the camera)."
        ),
    ] = None,
    shifts: Annotated[int | None, typer.Option(help="Shifted patterns (default: one per row of the period).")] = None,
    contrast_b: Annotated[
        float, typer.Option(help="Projector black level b of the patterns, a fraction of white (Nayar's correction).")
    ] = 0.0,
    epipolar_exposure_us: Annotated[
        float, typer.Option(help="Exposure of the synchronized epipolar image (us).")
    ] = 600.0,
    ambient_e_per_us: Annotated[
        float,
        typer.Option(
            "--ambient-e-per-us",
            "--ambient",
            help="Room light, electrons per microsecond (conventional frames integrate 16.7 ms).",
        ),
    ] = 0.01,
    noise: Annotated[bool, typer.Option(help="Simulate noise.")] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace the files a previous run wrote (only those).")] = False,
):
    """Direct/global separation with shifted stripes vs synchronized epipolar imaging, against ground truth.

    Writes ``nayar_direct``, ``nayar_global``, ``epipolar``, ``truth_direct`` and
    ``truth_global`` (.png preview, .tif values) and ``direct_global.json`` into
    ``--out``, a folder that may hold other files; each is checked before any work.
    """
    from ..experiments.baselines import direct_global_folder

    size = _check_common(
        out_dir,
        SEPARATE_IMAGES,
        "direct_global",
        overwrite=overwrite,
        size=size,
        projector_rows=projector_rows,
        seed=seed,
        ambient_e_per_us=ambient_e_per_us,
    )
    P = projector_rows or PAPER_PROJECTOR_ROWS
    if period_rows is not None:
        if period_rows < 2 or period_rows % 2 or period_rows > P:
            raise InputError(f"--period-rows must be an even number in 2..{P} (--projector-rows), got {period_rows}")
    if shifts is not None:
        top = period_rows if period_rows is not None else P
        lim.integer(shifts, "--shifts", minimum=2, maximum=top)
    lim.number(contrast_b, "--contrast-b", minimum=0.0, maximum=1.0, max_inclusive=False)
    lim.positive(epipolar_exposure_us, "--epipolar-exposure-us", maximum=_scan_time_us(P))
    dev = _sim_device(scene, size, projector_rows, seed, ambient_e_per_us, noise)
    with stage_bars() as progress:
        numbers = direct_global_folder(
            dev, out_dir, epipolar_exposure_us=epipolar_exposure_us, period_rows=period_rows, n_shifts=shifts,
            pattern_contrast_b=contrast_b, progress=progress,
        )  # fmt: skip
    _print_results(out_dir, numbers, "direct_global")


@_friendly_errors(options={"shape": "--size"})
def emulate(
    scene: Annotated[str, typer.Argument(help="Built-in scene (simulated conventional projector-camera).")],
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder for images and numbers.")],
    delay_us: Annotated[float, typer.Option(help="Delay of the emulated image (us).")] = 0.0,
    exposure_us: Annotated[float, typer.Option(help="Exposure (band width) of the emulated image (us).")] = 600.0,
    size: Annotated[tuple[int, int], typer.Option(help="Image size H W (camera pixels).")] = (128, 128),
    projector_rows: Annotated[
        int | None, typer.Option(help="Projector rows spanned by the image.")
    ] = PAPER_PROJECTOR_ROWS,
    seed: Annotated[int, typer.Option(help="Seed.")] = 0,
    spacing_rows: Annotated[
        int | None, typer.Option(help="Camera rows between bands sharing one capture (fewer captures).")
    ] = None,
    ambient_e_per_us: Annotated[
        float, typer.Option("--ambient-e-per-us", "--ambient", help="Room light, electrons per microsecond.")
    ] = 0.01,
    noise: Annotated[bool, typer.Option(help="Simulate noise.")] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace the files a previous run wrote (only those).")] = False,
):
    """Digital epipolar emulation (Sec. 5.1, Fig. 4): one band per capture vs one synchronized capture.

    Writes ``emulated``, ``synchronized`` and ``truth`` (.png preview, .tif values) and
    ``emulation.json`` into ``--out``, a folder that may hold other files; each is
    checked before any work.
    """
    from ..experiments.baselines import emulation_folder

    size = _check_common(
        out_dir,
        EMULATE_IMAGES,
        "emulation",
        overwrite=overwrite,
        size=size,
        projector_rows=projector_rows,
        seed=seed,
        ambient_e_per_us=ambient_e_per_us,
    )
    scan = _scan_time_us(projector_rows)
    lim.number(delay_us, "--delay-us", minimum=-scan, maximum=scan)
    lim.positive(exposure_us, "--exposure-us", maximum=scan)
    lim.optional(lim.integer, spacing_rows, "--spacing-rows", minimum=1, maximum=size[0])
    dev = _sim_device(scene, size, projector_rows, seed, ambient_e_per_us, noise)
    with stage_bars() as progress:
        numbers = emulation_folder(
            dev, out_dir, delay_us=delay_us, exposure_us=exposure_us, spacing_rows=spacing_rows, progress=progress
        )
    _print_results(out_dir, numbers, "emulation")
