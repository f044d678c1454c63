"""``planeray scenes`` and ``planeray simulate``: the built-in scenes swept on the simulated Episcan."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from .._console import out
from ..timing import PAPER_LINES_PER_SECOND
from . import _limits as lim
from ._common import _check_outputs, _friendly_errors, stage_bars

#: Most electrons a camera model takes (full well, laser, per microsecond of ambient light x 1e3).
MAX_ELECTRONS = 1e9
#: Longest timing jitter (us): beyond 10 ms the bands of a 60 Hz projector are gone.
MAX_JITTER_US = 10_000.0
#: Most frames averaged per image.
MAX_FRAMES = 65_536


def check_camera_options(
    *, frames, full_well_e, read_noise_e, laser_electrons, ambient_e_per_us, jitter_us, row_jitter_us
) -> None:
    """The camera model's options, where they are parsed (the ranges a camera has)."""
    lim.integer(frames, "--frames", minimum=1, maximum=MAX_FRAMES)
    lim.positive(full_well_e, "--full-well-e", maximum=MAX_ELECTRONS)
    lim.nonnegative(read_noise_e, "--read-noise-e", maximum=full_well_e)
    lim.positive(laser_electrons, "--laser-electrons", maximum=MAX_ELECTRONS)
    lim.nonnegative(ambient_e_per_us, "--ambient-e-per-us", maximum=MAX_ELECTRONS / 1e3)
    lim.nonnegative(jitter_us, "--jitter-us", maximum=MAX_JITTER_US)
    lim.nonnegative(row_jitter_us, "--row-jitter-us", maximum=MAX_JITTER_US)


@_friendly_errors
def scenes():
    """List the built-in scenes of the simulated device."""
    from ..scenes import list_scenes

    table = Table("scene", "what it shows")
    for name, description in list_scenes(parametric=True).items():
        table.add_row(name, description)
    out.print(table)


#: What ``simulate`` calls by the library's names.
SIMULATE_OPTIONS = {
    "shape": "--size",
    "projector_vfov_deg": "--projector-vfov",
    "prefer": "--variant",
    "frames_averaged": "--frames",
}


@_friendly_errors(options=SIMULATE_OPTIONS)
def simulate(
    scene: Annotated[
        str,
        typer.Argument(
            help="Built-in scene (see `planeray scenes`), mitsuba:FILE.xml (a Mitsuba 3 scene, rendered as "
            "`planeray render` does), or a transport store (rendered, demultiplexed or your own)."
        ),
    ],
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Stack to write (Zarr directory).")],
    size: Annotated[
        tuple[int, int] | None, typer.Option(help="Image size H W (camera pixels; default 128 128, a store's own).")
    ] = None,
    projector_rows: Annotated[
        int | None, typer.Option(help="Projector rows spanned by the image (default: H; a store's own).")
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the scene textures and the camera noise.")] = 0,
    sweep: Annotated[
        str,
        typer.Option(
            help="Delay-exposure sweep: paper (85 images), quick, or a sweep file (.json, `planeray sweep design`)."
        ),
    ] = "paper",
    lines_per_second: Annotated[
        float, typer.Option(help="Projector scanline velocity v_p (lines/s).")
    ] = PAPER_LINES_PER_SECOND,
    frames: Annotated[int, typer.Option(help="Frames averaged per image.")] = 8,
    bit_depth: Annotated[int, typer.Option(help="ADC bits.")] = 12,
    black_level: Annotated[int, typer.Option(help="ADC black level (codes).")] = 64,
    full_well_e: Annotated[
        float, typer.Option("--full-well-e", "--full-well", help="Full-well capacity (electrons).")
    ] = 10_000.0,
    read_noise_e: Annotated[
        float, typer.Option("--read-noise-e", "--read-noise", help="Read noise (electrons RMS).")
    ] = 7.0,
    laser_electrons: Annotated[float, typer.Option(help="Electrons from a white surface under its own row.")] = 6_000.0,
    ambient_e_per_us: Annotated[
        float,
        typer.Option(
            "--ambient-e-per-us", "--ambient", help="Ambient light, electrons per microsecond of exposure (albedo 1)."
        ),
    ] = 0.5,
    jitter_us: Annotated[float, typer.Option(help="Laser-shutter timing jitter sigma (us; blurs band edges).")] = 5.0,
    row_jitter_us: Annotated[
        float, typer.Option(help="Per-row trigger jitter sigma (us; row artifacts at the boundary).")
    ] = 10.0,
    noise: Annotated[bool, typer.Option(help="Simulate noise (--no-noise: expected images).")] = True,
    truth: Annotated[
        Path | None, typer.Option(help="Also write the scene's ground-truth transport store here.")
    ] = None,
    spp: Annotated[int | None, typer.Option(help="mitsuba: scenes: camera paths per pixel (default 64).")] = None,
    batch_spp: Annotated[int | None, typer.Option(help="mitsuba: scenes: paths per pixel per batch.")] = None,
    max_depth: Annotated[
        int | None, typer.Option(help="mitsuba: scenes: longest path (-1 unbounded; 2 direct only).")
    ] = None,
    caustics: Annotated[
        bool | None,
        typer.Option("--caustics/--no-caustics", help="mitsuba: scenes: the projector-side pass for caustics."),
    ] = None,
    band_rows: Annotated[
        int | None, typer.Option(help="mitsuba: scenes: dense band of offsets -B..B (default 128).")
    ] = None,
    baseline: Annotated[float | None, typer.Option(help="mitsuba: scenes: projector baseline (scene units).")] = None,
    projector_aspect: Annotated[float | None, typer.Option(help="mitsuba: scenes: projector width / height.")] = None,
    projector_columns: Annotated[int | None, typer.Option(help="mitsuba: scenes: projector columns.")] = None,
    projector_vfov: Annotated[
        float | None, typer.Option(help="mitsuba: scenes: projector vertical field of view (degrees).")
    ] = None,
    variant: Annotated[
        str | None, typer.Option(help="mitsuba: scenes: Mitsuba variant family, llvm or scalar.")
    ] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace existing outputs.")] = False,
):
    """Simulate a delay-exposure sweep of a scene (built-in, Mitsuba 3 file or transport store) on the simulated Episcan."""
    from ..camera import CameraModel
    from ..experiments.simulate import simulate_to_store

    scene_file = Path(scene.removeprefix("mitsuba:")) if scene.startswith("mitsuba:") else Path(scene)
    _check_outputs(
        (out_path, "stack"),
        (truth, "transport", "--truth"),
        overwrite=overwrite,
        inputs=[("SCENE", scene_file if scene_file.exists() else None)],
    )
    camera_options = dict(
        frames_averaged=frames, full_well_e=full_well_e, read_noise_e=read_noise_e, laser_electrons=laser_electrons,
        ambient_e_per_us=ambient_e_per_us, jitter_us=jitter_us, row_jitter_us=row_jitter_us,
    )  # fmt: skip
    render_options = {
        "--spp": ("spp", spp), "--batch-spp": ("batch_spp", batch_spp), "--max-depth": ("max_depth", max_depth),
        "--caustics": ("caustics", caustics), "--band-rows": ("band_rows", band_rows),
        "--baseline": ("baseline", baseline), "--projector-aspect": ("projector_aspect", projector_aspect),
        "--projector-columns": ("projector_columns", projector_columns),
        "--projector-vfov": ("projector_vfov_deg", projector_vfov), "--variant": ("variant", variant),
    }  # fmt: skip
    given = {option: pair for option, pair in render_options.items() if pair[1] is not None}
    size, sw = _simulate_options(scene, size, projector_rows, seed, lines_per_second, sweep, camera_options, given)
    camera = CameraModel(bit_depth=bit_depth, black_level=black_level, **camera_options)
    with stage_bars() as progress:
        stack, sc = simulate_to_store(
            scene, out_path, sweep=sw, size=size, projector_rows=projector_rows, seed=seed,
            lines_per_second=lines_per_second, camera=camera, noise=noise, render_options=dict(given.values()),
            truth=truth, overwrite=overwrite, progress=progress,
        )  # fmt: skip
    if truth is not None:
        out.print(f"ground-truth transport: {truth}", markup=False, highlight=False)
    H, W = sc.shape
    out.print(
        f"stack: {out_path}  ({len(stack)} images, {H}x{W}, {int((~stack.excluded).sum())} used for demultiplexing)",
        markup=False,
        highlight=False,
    )


def _simulate_options(scene: str, size, projector_rows, seed, lines_per_second, sweep, camera_options, given):
    """Every option of ``simulate`` checked before any work: ``(size, sweep)``."""
    from ..io import store_format

    if size is not None:
        size = lim.size(size, minimum=1)
    lim.projector_rows(projector_rows)
    lim.seed(seed)
    lim.lines_per_second(lines_per_second)
    sw = lim.sweep(sweep)
    check_camera_options(**{"frames" if k == "frames_averaged" else k: v for k, v in camera_options.items()})
    is_store = store_format(Path(scene)) is not None
    if given and not scene.startswith("mitsuba:"):
        first = next(iter(given))
        raise ValueError(f"{first} is a rendering option of mitsuba:FILE.xml scenes; {scene} is not one")
    if is_store and store_format(Path(scene)) != "transport":
        raise ValueError(f"{scene}: a stack, not a transport store (simulate sweeps a scene or a transport)")
    if not is_store and Path(scene).exists():
        raise ValueError(
            f"{scene}: not a transport store (no planeray-transport format attribute); simulate sweeps a built-in "
            "scene (`planeray scenes`), mitsuba:FILE.xml or a transport store"
        )
    if scene.startswith("mitsuba:"):
        from .render import check_render_options

        options = dict(given.values())
        check_render_options(
            size=size or (128, 128), rows=projector_rows or (size or (128, 128))[0], spp=options.get("spp"),
            batch_spp=options.get("batch_spp"), caustics=options.get("caustics"),
            band_rows=options.get("band_rows"), max_depth=options.get("max_depth"),
            baseline=options.get("baseline"), projector_aspect=options.get("projector_aspect"),
            projector_columns=options.get("projector_columns"), projector_vfov=options.get("projector_vfov_deg"),
            names={"rows": "--projector-rows"},
        )  # fmt: skip
    elif not is_store:
        h, w = size or (128, 128)
        lim.check_memory(h * w * (257 * 4 * 3 + 85 * 8), f"--size {h} {w}")
    return size, sw
