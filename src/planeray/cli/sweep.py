"""``planeray sweep design`` and ``planeray sweep show``: choosing the images of a sweep, and drawing one."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._console import console, out
from ..errors import InputError
from ..timing import PAPER_LINES_PER_SECOND
from . import _limits as lim
from ._common import _check_outputs, _friendly_errors
from ._devices import CalibrationArg, DeviceOptionArg

sweep_app = typer.Typer(
    help="Sweeps: design the few images that determine the transport best; draw a sweep.", no_args_is_help=True
)

OverwriteArg = Annotated[bool, typer.Option(help="Replace outputs a previous planeray run wrote (only those).")]
#: Most images a design may have (the candidates are a few thousand; the paper's sweep has 85).
MAX_IMAGES = 500


def _range(values, option: str, *, minimum: float) -> tuple[float, float] | None:
    if values is None:
        return None
    lo, hi = (lim.number(v, option, minimum=minimum) for v in values)
    if not lo < hi:
        raise InputError(f"{option} must be LO HI with LO < HI, got {lo:g} {hi:g}")
    return lo, hi


def _camera(camera, device, device_option, calibration, frames):
    """The design's camera: a device's, a file's, or the default; at ``frames`` frames per image."""
    from ..design import DesignCamera, camera_from_device, camera_from_file

    if device is not None and camera is not None:
        raise InputError("give --camera or --device, not both")
    if device is None and (device_option or calibration is not None):
        raise InputError("--device-option and --calibration apply to --device only")
    if device is not None:
        from ._devices import open_device_from_cli

        explicit = {"frames_averaged": int(frames)} if frames is not None and device == "sim" else {}
        with console.status(f"opening {device}"):
            dev = open_device_from_cli(device, explicit, device_option, calibration)
        try:
            cam = camera_from_device(dev, device)
        finally:
            dev.close()
    elif camera is None or camera == "default":
        cam = DesignCamera()
    else:
        cam = camera_from_file(camera)
    return cam if frames is None else cam.with_frames(frames)


@sweep_app.command("design")
@_friendly_errors
def design(
    images: Annotated[int, typer.Option("--images", "-k", help="Images K of the sweep (at least 4).")],
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Sweep file to write (.json).")],
    prior: Annotated[
        list[str] | None,
        typer.Option(
            help="What the scenes are like (repeatable): 'scenes' (every built-in scene), a scene name, a transport "
            "store (a render, a ground truth, a demux result), or 'smooth' (a generic smoothness prior).",
            show_default="scenes",
        ),
    ] = None,
    camera: Annotated[
        str | None,
        typer.Option(
            help="The camera's noise model: 'default' (the simulated Episcan), a stack, an acquisition.json or a "
            "sweep file's record.",
            show_default="default",
        ),
    ] = None,
    device: Annotated[
        str | None,
        typer.Option(help="Take the camera from this device: its noise model, exposure range and steps."),
    ] = None,
    device_option: DeviceOptionArg = None,
    calibration: CalibrationArg = None,
    frames: Annotated[
        int | None,
        typer.Option(help="Frames averaged per image (default: the camera's; the paper: 8).", show_default=False),
    ] = None,
    criterion: Annotated[
        str, typer.Option(help="mse (the regularized problem's expected error), bayes-a or bayes-d.")
    ] = "mse",
    alpha: Annotated[float, typer.Option(help="Smoothness weight of the demultiplexing the sweep is for.")] = 0.01,
    beta: Annotated[float, typer.Option(help="Sparsity weight of that demultiplexing (recorded).")] = 0.01,
    size: Annotated[int, typer.Option(help="Camera size of the built-in scenes of the prior (square).")] = 128,
    projector_rows: Annotated[int, typer.Option(help="Projector rows the built-in scenes span.")] = 720,
    support_rows: Annotated[int, typer.Option(help="Half-width K of the offsets -K..K (the paper's: 114).")] = 114,
    exposures_us: Annotated[
        tuple[float, float] | None,
        typer.Option(help="Exposures considered, LO HI (us).", show_default="150 1500"),
    ] = None,
    delays_us: Annotated[
        tuple[float, float] | None,
        typer.Option(help="Delays considered, LO HI (us).", show_default="all whose band fits the support"),
    ] = None,
    exposure_step_us: Annotated[
        float | None,
        typer.Option(help="Candidates' exposure step (us), a multiple of the camera's.", show_default="1 row"),
    ] = None,
    delay_step_us: Annotated[
        float | None,
        typer.Option(help="Candidates' delay step (us), a multiple of the camera's.", show_default="1 row"),
    ] = None,
    boundary_margin_us: Annotated[
        float,
        typer.Option(help="Leave out settings with a band edge this close to the epipolar plane (the paper's 75 us)."),
    ] = 75.0,
    pixels: Annotated[int, typer.Option(help="Pixels drawn from each scene or store of the prior.")] = 1500,
    smooth_weight: Annotated[
        float, typer.Option(help="Energy of the smoothness prior mixed into the scenes', as a fraction of theirs.")
    ] = 0.03,
    seed: Annotated[int, typer.Option(help="Seed of the prior's scenes and pixels (0 to 2^32-1).")] = 0,
    name: Annotated[str | None, typer.Option(help="The sweep's name.", show_default="design-K")] = None,
    overwrite: OverwriteArg = False,
):
    """Design a sweep: K (delay, exposure) settings the camera can realize that minimize the expected transport
    error of the regularized problem (Eq. 6) under the camera's noise, for a prior of scenes; the paper's boundary
    images are avoided.  The sweep file records the prior, the camera and the criterion; the same options give the
    same sweep."""
    import time

    from ..design import candidate_settings, design_sweep, transport_prior
    from ..io import write_sweep

    k, e_range, d_range = _design_options(
        out_path, images=images, criterion=criterion, alpha=alpha, beta=beta, frames=frames, size=size,
        projector_rows=projector_rows, support_rows=support_rows, pixels=pixels,
        boundary_margin_us=boundary_margin_us, smooth_weight=smooth_weight, seed=seed, exposures_us=exposures_us,
        delays_us=delays_us, exposure_step_us=exposure_step_us, delay_step_us=delay_step_us,
    )  # fmt: skip
    sources = list(prior or ["scenes"])
    _check_outputs(
        (out_path, "sweep"), overwrite=overwrite, inputs=[("--prior", p) for p in sources if Path(p).exists()]
    )
    cam = _camera(camera, device, device_option, calibration, frames)
    t0 = time.perf_counter()
    with console.status(f"building the prior ({', '.join(sources)})"):
        prior_ = transport_prior(
            sources,
            shape=(size, size),
            projector_rows=projector_rows,
            support_rows=support_rows,
            pixels=pixels,
            seed=seed,
            signal_scale=cam.model.signal_scale,
            smooth_weight=smooth_weight,
        )
    cands = candidate_settings(
        cam,
        support_rows=support_rows,
        exposure_range_us=e_range,
        delay_range_us=d_range,
        exposure_step_us=exposure_step_us,
        delay_step_us=delay_step_us,
        boundary_margin_us=boundary_margin_us,
    )
    with console.status(f"choosing {k} of {len(cands)} candidate settings"):
        result = design_sweep(k, prior=prior_, camera=cam, candidates=cands, criterion=criterion, alpha=alpha,
                              beta=beta, name=name)  # fmt: skip
    write_sweep(result.sweep, out_path, overwrite=overwrite)
    rec = result.record["criterion"]
    paper = rec.get("paper_sweep_expected_relative_error")
    vs = "" if paper is None else f"; the paper's 85 images: {paper:.3f}"
    what = (
        f"expected relative T error {result.expected_error:.3f}{vs}"
        if criterion == "mse"
        else f"{criterion} {result.criterion_value:.4g}"
    )
    out.print(
        f"sweep: {out_path}  ({k} images of {len(cands)} candidates, {cam.model.frames_averaged} frames each; {what}; "
        f"prior {prior_.n_pixels} pixels of {', '.join(sources)}; {time.perf_counter() - t0:.1f} s)",
        markup=False,
        highlight=False,
    )


def _design_options(out_path, *, images, criterion, alpha, beta, frames, size, projector_rows, support_rows, pixels,
                    boundary_margin_us, smooth_weight, seed, exposures_us, delays_us, exposure_step_us,
                    delay_step_us):  # fmt: skip
    """The options of ``sweep design`` in their ranges: ``(images, exposure range, delay range)``."""
    from ..design import CRITERIA
    from ..design.candidates import DEFAULT_EXPOSURE_RANGE_US
    from . import _bounds

    if out_path.suffix.lower() != ".json":
        raise InputError(f"--out must end in .json, got {out_path.name}")
    k = lim.integer(images, "--images", minimum=4, maximum=MAX_IMAGES)
    if criterion not in CRITERIA:
        raise InputError(f"--criterion {criterion}: choose one of {', '.join(CRITERIA)}")
    lim.positive(alpha, "--alpha", maximum=1e6)
    lim.nonnegative(beta, "--beta", maximum=1e6)
    lim.optional(lim.integer, frames, "--frames", minimum=1, maximum=10_000)
    _bounds.image_size((size, size))
    _bounds.projector_rows(projector_rows)
    lim.integer(support_rows, "--support-rows", minimum=4, maximum=lim.MAX_PROJECTOR_ROWS)
    lim.integer(pixels, "--pixels", minimum=10, maximum=1_000_000)
    lim.nonnegative(boundary_margin_us, "--boundary-margin-us", maximum=lim.MAX_TIME_US)
    lim.nonnegative(smooth_weight, "--smooth-weight", maximum=100.0)
    lim.seed(seed)
    e_range = _range(exposures_us, "--exposures-us", minimum=0.0) or DEFAULT_EXPOSURE_RANGE_US
    d_range = _range(delays_us, "--delays-us", minimum=-lim.MAX_TIME_US)
    lim.optional(lim.positive, exposure_step_us, "--exposure-step-us", maximum=lim.MAX_TIME_US)
    lim.optional(lim.positive, delay_step_us, "--delay-step-us", maximum=lim.MAX_TIME_US)
    return k, e_range, d_range


@sweep_app.command("show")
@_friendly_errors
def show(
    sweep: Annotated[str, typer.Argument(help="A sweep: paper, quick, or a sweep file (.json).")],
    out_png: Annotated[Path, typer.Option("--out", "-o", help="PNG to write.")],
    compare: Annotated[
        str | None, typer.Option(help="Another sweep drawn underneath (e.g. paper).", show_default=False)
    ] = None,
    lines_per_second: Annotated[
        float, typer.Option(help="Projector scanline velocity (delays and exposures to rows, Eq. 2).")
    ] = PAPER_LINES_PER_SECOND,
    overwrite: OverwriteArg = False,
):
    """Draw a sweep over the (delay, exposure) plane, with the boundary images' strips, and the bands it covers."""
    from ..figures.sweep import sweep_figure

    if out_png.suffix.lower() != ".png":
        raise InputError(f"--out must end in .png, got {out_png.name}")
    lim.lines_per_second(lines_per_second)
    sw = lim.sweep(sweep, "SWEEP")
    other = None if compare is None else lim.sweep(compare, "--compare")
    inputs = [(opt, p) for opt, p in (("SWEEP", sweep), ("--compare", compare)) if p is not None and Path(p).exists()]
    _check_outputs((out_png, "figure"), overwrite=overwrite, inputs=inputs)
    sweep_figure(sw, compare=other, lines_per_second=lines_per_second, out=out_png)
    out.print(
        f"figure: {out_png}  ({sw.name}: {len(sw)} images, {int(sw.excluded.sum())} excluded)",
        markup=False,
        highlight=False,
    )
