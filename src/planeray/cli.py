"""Command-line interface: a thin shell over the library (typer + rich).

Every command that takes a stack accepts a native Zarr stack or a captured
import folder (``manifest.csv`` + images + ``acquisition.json``).  Bad input
prints one line naming the file and the problem and exits with status 1.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Annotated, Optional

import numpy as np
import typer
from rich.table import Table

from ._console import console, out, progress_bar
from .errors import PlanerayError

app = typer.Typer(
    help="planeray: programmable plane-to-ray light transport (simulate, capture, analyse delay-exposure stacks).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
def _friendly_errors(fn):
    """Turn planeray's own errors into one red line and exit status 1."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except (PlanerayError, ValueError, FileNotFoundError) as exc:
            console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
            raise typer.Exit(1) from None

    return wrapper


def _load_stack(path: Path):
    from .io import read_stack

    return read_stack(path)


# ---------------------------------------------------------------- scenes
@app.command()
@_friendly_errors
def scenes():
    """List the built-in scenes of the simulated device."""
    from .scenes import list_scenes

    table = Table("scene", "what it shows")
    for name, description in list_scenes().items():
        table.add_row(name, description)
    out.print(table)


# -------------------------------------------------------------- simulate
@app.command()
@_friendly_errors
def simulate(
    scene: Annotated[str, typer.Argument(help="Built-in scene (see `planeray scenes`).")],
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Stack to write (Zarr directory).")],
    size: Annotated[tuple[int, int], typer.Option(help="Image size H W.")] = (128, 128),
    projector_rows: Annotated[Optional[int], typer.Option(help="Projector rows spanned by the image (default: H).")] = None,
    seed: Annotated[int, typer.Option(help="Seed of the scene textures and the camera noise.")] = 0,
    sweep: Annotated[str, typer.Option(help="Named delay-exposure sweep: paper (85 images) or quick.")] = "paper",
    lines_per_second: Annotated[float, typer.Option(help="Projector scanline velocity v_p.")] = 54_000.0,
    frames: Annotated[int, typer.Option(help="Frames averaged per image.")] = 8,
    bit_depth: Annotated[int, typer.Option(help="ADC bits.")] = 12,
    black_level: Annotated[int, typer.Option(help="ADC black level (codes).")] = 64,
    full_well: Annotated[float, typer.Option(help="Full-well capacity (electrons).")] = 10_000.0,
    read_noise: Annotated[float, typer.Option(help="Read noise (electrons RMS).")] = 7.0,
    laser_electrons: Annotated[float, typer.Option(help="Electrons from a white surface under its own row.")] = 6_000.0,
    ambient: Annotated[float, typer.Option(help="Ambient electrons per microsecond of exposure (albedo 1).")] = 0.5,
    jitter_us: Annotated[float, typer.Option(help="Laser-shutter timing jitter sigma (blurs band edges).")] = 5.0,
    row_jitter_us: Annotated[float, typer.Option(help="Per-row trigger jitter sigma (row artifacts at the boundary).")] = 10.0,
    noise: Annotated[bool, typer.Option(help="Simulate noise (--no-noise: expected images).")] = True,
    truth: Annotated[Optional[Path], typer.Option(help="Also write the scene's ground-truth transport store here.")] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace existing outputs.")] = False,
):
    """Simulate a delay-exposure sweep of a built-in scene on the simulated Episcan."""
    from .acquire import acquire_sweep
    from .camera import CameraModel
    from .devices import SimulatedEpiscan
    from .io import write_stack, write_transport
    from .scenes import make_scene
    from .timing import make_sweep

    camera = CameraModel(bit_depth, black_level, full_well, read_noise, laser_electrons, ambient, frames, jitter_us, row_jitter_us)
    sw = make_sweep(sweep)
    with console.status(f"building scene {scene} {size[0]}x{size[1]}"):
        sc = make_scene(scene, size, projector_rows, seed)
    device = SimulatedEpiscan(sc, camera, lines_per_second, seed, noise)
    with progress_bar() as bar:
        task = bar.add_task(f"capturing {len(sw)} images", total=len(sw))
        stack = acquire_sweep(device, sw, progress=lambda i: bar.advance(task))
        task = bar.add_task("writing stack", total=len(sw))
        write_stack(stack, out_path, overwrite=overwrite, progress=lambda i: bar.advance(task))
    if truth is not None:
        write_transport(sc.transport, truth, {"lines_per_second": lines_per_second, "method": "ground_truth", "scene": sc.params}, overwrite=overwrite)
        out.print(f"ground-truth transport: {truth}")
    out.print(f"stack: {out_path}  ({len(stack)} images, {size[0]}x{size[1]}, {int((~stack.excluded).sum())} used for demultiplexing)")


# ------------------------------------------------------------------ info
@app.command()
@_friendly_errors
def info(
    stack_path: Annotated[Path, typer.Argument(help="Stack (Zarr) or import folder.")],
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
):
    """Describe a stack: size, sweep, timing, camera and scene parameters."""
    st = _load_stack(stack_path)
    summary = {
        "path": str(stack_path),
        "images": len(st),
        "shape": list(st.shape),
        "projector_rows": st.projector_rows,
        "lines_per_second": st.lines_per_second,
        "delays_us": st.delays().tolist(),
        "exposures_us": st.exposures().tolist(),
        "excluded": int(st.excluded.sum()),
        "used_for_demux": int((~st.excluded).sum()),
        "metadata": st.metadata,
    }
    if as_json:
        print(json.dumps(summary, indent=2, default=str))
        return
    table = Table(show_header=False)
    for key in ("path", "images", "shape", "projector_rows", "lines_per_second", "excluded", "used_for_demux"):
        table.add_row(key, str(summary[key]))
    table.add_row("delays_us", f"{len(summary['delays_us'])}: {st.delays().min():g} .. {st.delays().max():g}")
    table.add_row("exposures_us", ", ".join(f"{e:g}" for e in summary["exposures_us"]))
    for key, value in st.metadata.items():
        table.add_row(key, json.dumps(value, default=str))
    out.print(table)


# --------------------------------------------------------- contact sheet
@app.command("contact-sheet")
@_friendly_errors
def contact_sheet(
    stack_path: Annotated[Path, typer.Argument(help="Stack (Zarr) or import folder.")],
    out_png: Annotated[Path, typer.Option("--out", "-o", help="PNG to write.")],
    gamma: Annotated[float, typer.Option(help="Display gamma.")] = 0.5,
    max_delays: Annotated[Optional[int], typer.Option(help="Show at most this many delays.")] = None,
):
    """Write the delay x exposure grid of a stack (the paper's Fig. 8)."""
    from .figures import contact_sheet_figure

    st = _load_stack(stack_path)
    with console.status("drawing contact sheet"):
        contact_sheet_figure(st, out=out_png, gamma=gamma, max_delays=max_delays)
    out.print(f"contact sheet: {out_png}")


# -------------------------------------------------------------- profiles
@app.command()
@_friendly_errors
def profiles(
    stack_path: Annotated[Path, typer.Argument(help="Stack (Zarr) or import folder.")],
    out_png: Annotated[Path, typer.Option("--out", "-o", help="PNG to write.")],
    pixel: Annotated[Optional[list[str]], typer.Option(help="Pixel as ROW COL or ROW,COL (repeat for more pixels).")] = None,
    exposure: Annotated[Optional[float], typer.Option(help="Plot only this exposure (us).")] = None,
    csv: Annotated[Optional[Path], typer.Option(help="Also write the profiles as CSV.")] = None,
    transport: Annotated[Optional[Path], typer.Option(help="Transport store: also draw its continuous delay profiles.")] = None,
    classify: Annotated[Optional[Path], typer.Option(help="With --transport: write the per-pixel effect label map PNG.")] = None,
):
    """Plot area-normalized delay profiles of pixels (the paper's Fig. 9); classify effects from a transport."""
    from .classify import classify_transport
    from .figures import delay_profiles_figure, label_map_figure
    from .profiles import (
        measured_delay_profiles,
        transport_delay_profiles,
        write_profiles_csv,
    )

    if classify is not None and transport is None:
        raise ValueError("--classify needs --transport (the labels come from the transport's profiles)")
    if not pixel and classify is None:
        raise ValueError("give at least one --pixel ROW COL (or --classify with --transport)")
    st = _load_stack(stack_path)
    T = attrs = None
    if transport is not None:
        from .io import read_transport

        T, attrs = read_transport(transport)
        if T.shape != st.shape:
            raise ValueError(f"{transport}: transport is {T.shape[0]}x{T.shape[1]}, stack {st.shape[0]}x{st.shape[1]}")
    if pixel:
        prof = measured_delay_profiles(st, [_parse_pixel(p) for p in pixel])
        continuous = None
        if T is not None:
            e = exposure if exposure is not None else float(prof.exposure_us.min())
            continuous = transport_delay_profiles(T, prof.pixels, exposure_us=e, lines_per_second=st.lines_per_second)
        delay_profiles_figure(st, prof, out=out_png, exposure_us=exposure, continuous=continuous)
        if csv is not None:
            write_profiles_csv(prof, csv)
            out.print(f"profiles CSV: {csv}")
        out.print(f"delay profiles: {out_png}")
    if classify is not None:
        from .scenes import EFFECTS

        labels = classify_transport(T, resolution_rows=float(attrs.get("epipolar_resolution_rows") or 0.0))
        ref = st.image(st.index_of(0.0, float(st.exposures().min())) or 0)
        label_map_figure(labels, out=classify, reference=ref)
        counts = np.bincount(labels.ravel(), minlength=len(EFFECTS))
        summary = ", ".join(f"{EFFECTS[k]} {counts[k] / labels.size * 100:.1f} %" for k in EFFECTS if counts[k])
        out.print(f"label map: {classify}  ({summary})")


def _parse_pixel(text: str) -> tuple[int, int]:
    parts = text.replace(",", " ").split()
    if len(parts) != 2 or not all(p.lstrip("-").isdigit() for p in parts):
        raise ValueError(f"--pixel expects ROW COL (two integers), got {text!r}")
    return int(parts[0]), int(parts[1])


def _join_pixel_args(argv: list[str]) -> list[str]:
    """Let ``--pixel ROW COL`` (two words) through typer, which takes one value per option."""
    joined, i = [], 0
    while i < len(argv):
        if argv[i] == "--pixel" and i + 2 < len(argv) and argv[i + 1].lstrip("-").isdigit() and argv[i + 2].lstrip("-").isdigit():
            joined += ["--pixel", f"{argv[i + 1]},{argv[i + 2]}"]
            i += 3
        else:
            joined.append(argv[i])
            i += 1
    return joined


# --------------------------------------------------------------- acquire
@app.command()
@_friendly_errors
def acquire(
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Native stack to write (Zarr); resumable.")],
    device: Annotated[str, typer.Option(help="sim | replay | ueye.")] = "sim",
    sweep: Annotated[str, typer.Option(help="Named delay-exposure sweep.")] = "paper",
    scene: Annotated[str, typer.Option(help="sim: built-in scene.")] = "wax",
    size: Annotated[tuple[int, int], typer.Option(help="sim: image size H W.")] = (128, 128),
    projector_rows: Annotated[Optional[int], typer.Option(help="sim: projector rows spanned by the image.")] = None,
    seed: Annotated[int, typer.Option(help="sim: seed.")] = 0,
    replay: Annotated[Optional[Path], typer.Option(help="replay: the recorded stack to serve.")] = None,
    camera_id: Annotated[int, typer.Option(help="ueye: camera handle.")] = 0,
    lines_per_second: Annotated[float, typer.Option(help="Projector scanline velocity (sim, ueye).")] = 54_000.0,
    base_trigger_delay_us: Annotated[float, typer.Option(help="ueye: trigger delay at t'_o = 0 (delay-zero calibration).")] = 0.0,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing finished stack.")] = False,
    restart: Annotated[bool, typer.Option(help="Discard an unfinished capture instead of resuming it.")] = False,
):
    """Capture a delay-exposure sweep from a device into a native stack (resumes an interrupted capture)."""
    from .acquire import acquire_to_store
    from .timing import make_sweep

    sw = make_sweep(sweep)
    if device == "sim":
        from .devices import SimulatedEpiscan
        from .scenes import make_scene

        dev = SimulatedEpiscan(make_scene(scene, size, projector_rows, seed), lines_per_second=lines_per_second, seed=seed)
    elif device == "replay":
        from .devices import ReplayDevice

        if replay is None:
            raise ValueError("--device replay needs --replay STACK")
        dev = ReplayDevice(_load_stack(replay), source=str(replay))
    elif device == "ueye":
        from .devices import UEyeEpiscan

        dev = UEyeEpiscan(camera_id, lines_per_second, base_trigger_delay_us)
    else:
        raise ValueError(f"unknown device {device!r}; choose sim, replay or ueye")
    with progress_bar() as bar:
        task = bar.add_task(f"capturing {len(sw)} images ({device})", total=len(sw))
        path = acquire_to_store(dev, sw, out_path, overwrite, restart, progress=lambda i: bar.advance(task))
    out.print(f"stack: {path}  ({len(sw)} images)")


# ------------------------------------------------- conventional baselines
separate_app = typer.Typer(help="Conventional projector-camera baselines (Nayar et al. 2006).", no_args_is_help=True)
app.add_typer(separate_app, name="separate")


def _sim_device(scene: str, size, projector_rows, seed: int, ambient: float, noise: bool, lines_per_second: float = 54_000.0):
    from .camera import CameraModel
    from .devices import SimulatedEpiscan
    from .scenes import make_scene

    return SimulatedEpiscan(make_scene(scene, size, projector_rows, seed), CameraModel(ambient_e_per_us=ambient),
                            lines_per_second, seed, noise)


def _write_results(out_dir: Path, images: dict, numbers: dict, name: str):
    from .io import atomic_file

    out_dir.mkdir(parents=True, exist_ok=True)
    valid = [im for im in images.values() if im is not None]
    from .figures._common import display_scale

    scale = display_scale(valid, 99.5)  # one brightening for all, so they compare
    for key, image in images.items():
        if image is not None:
            _save_image(np.nan_to_num(image), out_dir / f"{key}.png", scale_to=scale)
            _save_image(np.clip(np.nan_to_num(image), 0, 1), out_dir / f"{key}.tif")
    with atomic_file(out_dir / f"{name}.json") as tmp:
        tmp.write_text(json.dumps(numbers, indent=2, default=float))
    out.print(f"{name}: {out_dir}  {json.dumps(numbers.get('n_captures', {}))}")
    errors = numbers.get("errors", {})
    for key, value in errors.items():
        overall = value.get("all", value) if isinstance(value, dict) else value
        if isinstance(overall, dict) and "relative_rmse" in overall:
            out.print(f"  {key:28s} relative RMSE {overall['relative_rmse']:.4f}  MAE {overall['mae']:.4g}")


@separate_app.command("direct-global")
@_friendly_errors
def separate_direct_global(
    scene: Annotated[str, typer.Argument(help="Built-in scene (simulated conventional projector-camera).")],
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder for images (.png previews, .tif values) and numbers.")],
    size: Annotated[tuple[int, int], typer.Option(help="Image size H W.")] = (128, 128),
    projector_rows: Annotated[Optional[int], typer.Option(help="Projector rows spanned by the image.")] = 720,
    seed: Annotated[int, typer.Option(help="Seed.")] = 0,
    period: Annotated[Optional[int], typer.Option(help="Stripe period in projector rows (default: resolvable by the camera).")] = None,
    shifts: Annotated[Optional[int], typer.Option(help="Shifted patterns (default: one per row of the period).")] = None,
    contrast_b: Annotated[float, typer.Option(help="Projector black level b of the patterns (Nayar's correction).")] = 0.0,
    epipolar_exposure_us: Annotated[float, typer.Option(help="Exposure of the synchronized epipolar image.")] = 600.0,
    ambient: Annotated[float, typer.Option(help="Room light, electrons per microsecond (conventional frames integrate 16.7 ms).")] = 0.01,
    noise: Annotated[bool, typer.Option(help="Simulate noise.")] = True,
):
    """Direct/global separation with shifted stripes vs synchronized epipolar imaging, against ground truth."""
    from .baselines import compare_direct_global

    dev = _sim_device(scene, size, projector_rows, seed, ambient, noise)
    with console.status("capturing stripe patterns and the epipolar image"):
        res = compare_direct_global(dev, epipolar_exposure_us, period, shifts, pattern_contrast_b=contrast_b)
    images = {"nayar_direct": res["nayar"].direct, "nayar_global": res["nayar"].global_, "epipolar": res["epipolar"],
              "truth_direct": res["truth_direct"], "truth_global": res["truth_global"]}
    _write_results(out_dir, images, res["numbers"], "direct_global")


@app.command()
@_friendly_errors
def emulate(
    scene: Annotated[str, typer.Argument(help="Built-in scene (simulated conventional projector-camera).")],
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder for images and numbers.")],
    delay_us: Annotated[float, typer.Option(help="Delay of the emulated image.")] = 0.0,
    exposure_us: Annotated[float, typer.Option(help="Exposure (band width) of the emulated image.")] = 600.0,
    size: Annotated[tuple[int, int], typer.Option(help="Image size H W.")] = (128, 128),
    projector_rows: Annotated[Optional[int], typer.Option(help="Projector rows spanned by the image.")] = 720,
    seed: Annotated[int, typer.Option(help="Seed.")] = 0,
    spacing_rows: Annotated[Optional[int], typer.Option(help="Camera rows between bands sharing one capture (fewer captures).")] = None,
    ambient: Annotated[float, typer.Option(help="Room light, electrons per microsecond.")] = 0.01,
    noise: Annotated[bool, typer.Option(help="Simulate noise.")] = True,
):
    """Digital epipolar emulation (Sec. 5.1, Fig. 4): one band per capture vs one synchronized capture."""
    from .baselines import compare_emulation

    dev = _sim_device(scene, size, projector_rows, seed, ambient, noise)
    with console.status("sweeping the band one row at a time"):
        res = compare_emulation(dev, delay_us, exposure_us, spacing_rows=spacing_rows)
    images = {"emulated": res["emulated"].image, "synchronized": res["synchronized"], "truth": res["truth"]}
    _write_results(out_dir, images, res["numbers"], "emulation")


# ------------------------------------------------------------- calibrate
calibrate_app = typer.Typer(help="Calibration (Sec. 6): line velocity v_p and delay zero.", no_args_is_help=True)
app.add_typer(calibrate_app, name="calibrate")


def _report_calibration(result, write: Optional[Path], as_json: bool, key: str):
    from .calibration import write_calibration

    info = result.to_dict()
    if write is not None:
        write_calibration(write, **{key: result})
        info["written_to"] = str(write)
    if as_json:
        print(json.dumps(info, indent=2, default=float))
    return info


@calibrate_app.command("lines")
@_friendly_errors
def calibrate_lines(
    path: Annotated[Path, typer.Argument(help="Line-sweep capture: .npz (from simulate-lines) or grayscale .tif/.png.")],
    exposure_us: Annotated[Optional[float], typer.Option(help="Global-shutter exposure of the capture (default 500 us).")] = None,
    rows_per_line: Annotated[Optional[int], typer.Option(help="Projector rows between lit lines of the comb.")] = None,
    write: Annotated[Optional[Path], typer.Option(help="Write lines_per_second into this acquisition.json (or folder).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
):
    """Projector scanline velocity v_p = n_lines / t_e from a line-sweep capture, with its uncertainty."""
    from .calibration import calibrate_lines_per_second, read_line_sweep

    result = calibrate_lines_per_second(read_line_sweep(path, exposure_us, rows_per_line))
    _report_calibration(result, write, as_json, "lines")
    if not as_json:
        out.print(f"lines_per_second = {result.lines_per_second:,.0f} +- {result.uncertainty:,.0f} (1 sigma, "
                  f"{result.relative_uncertainty * 100:.2f} %) from {result.n_lines:.2f} lines in {result.exposure_us:g} us"
                  + (f"; written to {write}" if write else ""))


@calibrate_app.command("simulate-lines")
@_friendly_errors
def calibrate_simulate_lines(
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Line-sweep capture to write (.npz).")],
    lines_per_second: Annotated[float, typer.Option(help="True v_p of the simulated projector.")] = 54_000.0,
    size: Annotated[tuple[int, int], typer.Option(help="Calibration camera H W (must resolve projector rows).")] = (288, 64),
    projector_rows: Annotated[int, typer.Option(help="Projector rows spanned by the image.")] = 96,
    exposure_us: Annotated[float, typer.Option(help="Global-shutter exposure.")] = 500.0,
    seed: Annotated[int, typer.Option(help="Seed.")] = 0,
):
    """Capture a line-velocity calibration on the simulated device (a diffuse target)."""
    from .calibration import write_line_sweep
    from .devices import SimulatedEpiscan
    from .scenes import make_scene

    dev = SimulatedEpiscan(make_scene("diffuse_plane", size, projector_rows, seed), lines_per_second=lines_per_second, seed=seed)
    path = write_line_sweep(dev.capture_line_sweep(exposure_us), out_path)
    out.print(f"line sweep: {path}  (true lines_per_second {lines_per_second:,.0f})")


@calibrate_app.command("delay-zero")
@_friendly_errors
def calibrate_delay_zero_cmd(
    stack_path: Annotated[Optional[Path], typer.Argument(help="A fine delay sweep around 0 at one exposure (stack or folder).")] = None,
    exposure_us: Annotated[float, typer.Option(help="Exposure of the sweep's images to use.")] = 600.0,
    simulate: Annotated[bool, typer.Option(help="Sweep the simulated device instead of reading a stack.")] = False,
    delay_error_us: Annotated[float, typer.Option(help="--simulate: hidden sync error to recover.")] = 0.0,
    seed: Annotated[int, typer.Option(help="--simulate: seed.")] = 0,
    write: Annotated[Optional[Path], typer.Option(help="Write delay_zero_us into this acquisition.json (or folder).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
):
    """The commanded delay at which the epipolar (direct) response is centred, so t'_o is measured (Eq. 1)."""
    from .calibration import calibrate_delay_zero, delay_zero_sweep, device_capture

    if simulate:
        from .devices import SimulatedEpiscan
        from .scenes import make_scene

        dev = SimulatedEpiscan(make_scene("diffuse_plane", (64, 64), 360, seed), seed=seed)
        sweep = delay_zero_sweep(exposure_us)
        result = calibrate_delay_zero(device_capture(dev, exposure_us, delay_error_us), sweep.delay_us, exposure_us,
                                      lines_per_second=dev.lines_per_second)
    else:
        if stack_path is None:
            raise ValueError("give a STACK (a delay sweep around 0) or --simulate")
        st = _load_stack(stack_path)
        idx = np.flatnonzero(np.isclose(st.exposure_us, exposure_us))
        if idx.size < 5:
            raise ValueError(f"{stack_path}: needs at least 5 images at exposure {exposure_us:g} us, found {idx.size}")
        images = np.stack([st.image(int(i)) for i in idx])
        result = calibrate_delay_zero(images, st.delay_us[idx], exposure_us, lines_per_second=st.lines_per_second)
    _report_calibration(result, write, as_json, "delay_zero")
    if not as_json:
        out.print(f"delay zero = {result.delay_zero_us:+.2f} +- {result.uncertainty_us:.2f} us (commanded delay of the true "
                  f"epipolar centre); sync offset t'_o = {result.sync_offset_us:.2f} us" + (f"; written to {write}" if write else ""))


# ----------------------------------------------------------------- mc
mc_app = typer.Typer(help="Monte Carlo subsurface scattering (HG slab, line source).", no_args_is_help=True)
app.add_typer(mc_app, name="mc")


@mc_app.command("profile")
@_friendly_errors
def mc_profile(
    out_path: Annotated[Path, typer.Option("--out", "-o", help="CSV of the binned profile (a .json of the totals is written next to it).")],
    sigma_s: Annotated[float, typer.Option("--sigma-s", help="Scattering coefficient (1/mm).")] = 1.0,
    sigma_a: Annotated[float, typer.Option("--sigma-a", help="Absorption coefficient (1/mm).")] = 0.0,
    g: Annotated[float, typer.Option("--g", help="Henyey-Greenstein anisotropy (-1, 1).")] = 0.9,
    n: Annotated[float, typer.Option("--n", help="Relative refractive index (1 = index matched).")] = 1.0,
    thickness_mm: Annotated[Optional[float], typer.Option("--thickness-mm", help="Slab thickness; default semi-infinite.")] = None,
    photons: Annotated[int, typer.Option(help="Photon packets.")] = 1_000_000,
    rows: Annotated[int, typer.Option(help="Bins -ROWS..ROWS (projector rows).")] = 114,
    mm_per_row: Annotated[float, typer.Option("--mm-per-row", help="Bin width on the surface (mm).")] = 1.0,
    source_width_mm: Annotated[float, typer.Option("--source-width-mm", help="Width of the lit strip (0 = ideal line).")] = 0.0,
    cutoff_mm: Annotated[Optional[float], typer.Option("--cutoff-mm", help="Stop photons this far from the line (default: automatic).")] = None,
    diffusion_depth_mfp: Annotated[float, typer.Option("--diffusion-depth-mfp", help="Hand photons this many transport mean free paths deep to diffusion theory (0: trace every photon).")] = 10.0,
    point: Annotated[bool, typer.Option("--point", help="A point (pencil-beam) source: radial bins 0..ROWS of --mm-per-row (MCML's R_d(r)).")] = False,
    seed: Annotated[int, typer.Option(help="Random seed (same seed, same bytes).")] = 0,
    plot: Annotated[Optional[Path], typer.Option(help="Also write a PNG of the profile against the dipole.")] = None,
    cache: Annotated[bool, typer.Option(help="Reuse/keep the result in the on-disk cache.")] = True,
):
    """Line-source (or --point) exit profile of a homogeneous HG medium (Sec. 5.2), with Monte Carlo errors."""
    import time

    import numpy as np

    from .mc import mc_line_profile, mc_point_profile
    from .mc.report import write_profile
    from .medium import Medium

    t0 = time.perf_counter()
    thickness = np.inf if thickness_mm is None else thickness_mm
    medium = Medium(sigma_s=sigma_s, sigma_a=sigma_a, g=g, n=n, thickness_mm=thickness)
    with console.status(f"tracing {photons:,} photons"):
        if point:
            prof = mc_point_profile(medium, n_photons=photons,
                                    radius_bins=np.arange(0, rows + 1), mm_per_bin=mm_per_row, seed=seed,
                                    cache=cache, cutoff_mm=cutoff_mm)
        else:
            prof = mc_line_profile(medium, n_photons=photons,
                                   offsets_rows=np.arange(-rows, rows + 1), mm_per_row=mm_per_row, seed=seed,
                                   cache=cache, source_width_mm=source_width_mm, cutoff_mm=cutoff_mm,
                                   diffusion_depth_mfp=diffusion_depth_mfp or None)
    dt = time.perf_counter() - t0
    csv_path, json_path = write_profile(prof, out_path)
    out.print(f"diffuse reflectance {prof.total_reflectance:.5f} +- {prof.total_reflectance_stderr:.5f}, "
              f"specular {prof.specular_reflectance:.5f}, transmitted {prof.transmittance:.5f}, "
              f"absorbed {prof.absorbed:.5f}, truncated {prof.truncated:.5f}")
    out.print(f"{prof.n_interactions / max(prof.n_photons, 1):.0f} collisions per photon, {dt:.1f} s")
    out.print(f"  {csv_path}\n  {json_path}")
    if plot is not None:
        from .figures.mc import mc_profile_figure

        mc_profile_figure(prof, out=plot)
        out.print(f"  {plot}")


# ----------------------------------------------------------------- study
study_app = typer.Typer(help="Studies of the method (Sec. 5.2).", no_args_is_help=True)
app.add_typer(study_app, name="study")


@study_app.command("demux")
@_friendly_errors
def study_demux(
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder for the figures (PNG) and numbers (CSV).")],
    provider: Annotated[str, typer.Option(help="Scattering profiles: mc (Monte Carlo, cached) or dipole.")] = "mc",
    seeds: Annotated[int, typer.Option(help="Noise seeds per point.")] = 5,
    quick: Annotated[bool, typer.Option(help="Reduced grids.")] = False,
):
    """Reconstruction quality of pinv, NNLS and the full method (Figs. 5, 6) and an alpha/beta sweep."""
    from .experiments.study import run_study

    with console.status("running the demultiplexing study"):
        numbers = run_study(out_dir, provider, seeds, quick)
    for f in numbers.get("files", []):
        out.print(f"  {f}")


# ----------------------------------------------------------------- demux
@app.command()
@_friendly_errors
def demux(
    stack_path: Annotated[Path, typer.Argument(help="Stack (Zarr) or import folder.")],
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Transport store to write (Zarr).")],
    alpha: Annotated[float, typer.Option(help="Smoothness weight (paper: 0.01).")] = 0.01,
    beta: Annotated[float, typer.Option(help="Sparsity weight (paper: 0.01).")] = 0.01,
    method: Annotated[str, typer.Option(help="fast | pinv | nnls | cvxpy.")] = "fast",
    workers: Annotated[Optional[int], typer.Option(help="Run on a Dask LocalCluster with N workers.")] = None,
    scheduler: Annotated[Optional[str], typer.Option(help="Address of an existing Dask scheduler.")] = None,
    chunk: Annotated[int, typer.Option(help="Camera rows per chunk (bounds memory).")] = 16,
    tol: Annotated[Optional[float], typer.Option(help="Solver tolerance (relative objective gap for fast).")] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing finished output.")] = False,
    restart: Annotated[bool, typer.Option(help="Discard an unfinished run instead of resuming it.")] = False,
):
    """Demultiplex a delay-exposure stack into 3D light transport (Sec. 4); resumable."""
    import time

    from .demux import demultiplex_to_store
    from .io import read_transport_maps

    if workers is not None and scheduler is not None:
        raise ValueError("give --workers or --scheduler, not both")
    st = _load_stack(stack_path)
    t0 = time.perf_counter()
    with progress_bar() as bar:
        task = bar.add_task(f"demultiplexing ({method})", total=st.shape[0])
        path = demultiplex_to_store(
            st, out_path, alpha, beta, method, chunk, tol, workers, scheduler, overwrite, restart,
            progress=lambda rows: bar.advance(task, rows), source=str(stack_path),
        )
    elapsed = time.perf_counter() - t0
    maps = read_transport_maps(path)
    conv = maps["converged"]
    out.print(
        f"transport: {path}  ({st.shape[0]}x{st.shape[1]} pixels in {elapsed:.1f} s; "
        f"converged {conv.mean() * 100:.2f} %, median residual RMS {np.median(maps['residual_rms']):.2e})"
    )


# ----------------------------------------------------------------- synth
def _save_image(image, path: Path, scale_to: float | None = None) -> Path:
    """PNG: display-scaled 8-bit preview; TIFF: the values as 16-bit codes (0..1 -> 0..65535)."""
    from .io import write_image

    if path.suffix.lower() == ".png":
        from PIL import Image

        from .figures._common import display_scale
        from .io import atomic_file

        shown = np.clip(image * (scale_to or display_scale([image], 99.5)), 0, 1)
        with atomic_file(path) as tmp:
            Image.fromarray((shown * 255 + 0.5).astype(np.uint8)).save(tmp, format="PNG")
        return path
    if path.suffix.lower() in (".tif", ".tiff"):
        return write_image(path, image, bit_depth=16)
    raise ValueError(f"--out must end in .png, .tif or .tiff, got {path.name}")


@app.command()
@_friendly_errors
def synth(
    transport_path: Annotated[Path, typer.Argument(help="Transport store (Zarr).")],
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Image to write (.png preview, .tif 16-bit values).")],
    epipolar: Annotated[bool, typer.Option("--epipolar", help="Epipolar image (Eq. 5).")] = False,
    non_epipolar: Annotated[bool, typer.Option("--non-epipolar", help="Non-epipolar image (Eq. 6).")] = False,
    sharpen: Annotated[Optional[float], typer.Option(help="Sharpened epipolar image with a band of ROWS projector rows.")] = None,
    relight: Annotated[Optional[str], typer.Option(help="Relight: a projector row number, or a pattern file (.npy/.csv/image).")] = None,
    band: Annotated[Optional[tuple[float, float]], typer.Option(help="Banded image for DELAY_US EXPOSURE_US (any pair).")] = None,
    short_range: Annotated[Optional[float], typer.Option(help="Short-range indirect light up to MAX_ROWS offsets.")] = None,
    long_range: Annotated[Optional[float], typer.Option(help="Long-range indirect light beyond MAX_ROWS offsets.")] = None,
):
    """Synthesize an image from a transport: epipolar, non-epipolar, sharpened, relit, banded, short/long range."""
    from . import synthesis as syn
    from .io import read_transport

    chosen = [x for x in (epipolar, non_epipolar, sharpen is not None, relight is not None, band is not None,
                          short_range is not None, long_range is not None) if x]
    if len(chosen) != 1:
        raise ValueError("choose exactly one of --epipolar, --non-epipolar, --sharpen, --relight, --band, --short-range, --long-range")
    T, attrs = read_transport(transport_path)
    lps = attrs.get("lines_per_second") or 54_000.0
    if epipolar:
        image, what = syn.epipolar_image(T), "epipolar image"
    elif non_epipolar:
        image, what = syn.non_epipolar_image(T), "non-epipolar image"
    elif sharpen is not None:
        image, what = syn.sharpened_epipolar(T, sharpen), f"sharpened epipolar image ({sharpen:g} rows)"
        res = attrs.get("epipolar_resolution_rows")
        if res and sharpen < 2 * res:
            console.print(f"[yellow]note:[/] the sweep cannot split light within +-{res:.2f} rows of the epipolar plane; "
                          f"a {sharpen:g}-row band shows the regularizer's spread there")
    elif relight is not None:
        P = T.geometry.projector_rows
        pattern = syn.single_line_pattern(P, int(relight)) if relight.lstrip("-").isdigit() else syn.load_pattern(relight, P)
        image, what = syn.relight(T, pattern), "relit image"
    elif band is not None:
        image, what = syn.band_image(T, band[0], band[1], lps), f"band image (t_d {band[0]:g} us, t_e {band[1]:g} us)"
    else:
        short, long = syn.short_long_range(T, short_range if short_range is not None else long_range)
        image, what = (short, "short-range indirect image") if short_range is not None else (long, "long-range indirect image")
    path = _save_image(image, out_path)
    out.print(f"{what}: {path}  (min {image.min():.3g}, max {image.max():.3g})")


# ---------------------------------------------------------------- figure
@app.command()
@_friendly_errors
def figure(
    name: Annotated[str, typer.Argument(help="fig8 | fig9 | fig11 | fig12 | effects | all")],
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder for the PNGs and their numbers (JSON).")] = Path("out/figures"),
    size: Annotated[int, typer.Option(help="Image size (square).")] = 128,
    seed: Annotated[int, typer.Option(help="Seed.")] = 0,
):
    """Reproduce a paper figure on the built-in scenes (writes PNG + JSON of the measured numbers)."""
    from .experiments.paper import FIGURES

    names = list(FIGURES) if name == "all" else [name]
    for n in names:
        if n not in FIGURES:
            raise ValueError(f"unknown figure {n!r}; choose one of {sorted(FIGURES)} or all")
        with console.status(f"reproducing {n}"):
            numbers = FIGURES[n](out_dir, size=size, seed=seed)
        shown = numbers.get("images", numbers)
        out.print(f"{n}: {out_dir / (n + '.json')}  {json.dumps(shown, default=float)[:400]}")


# ------------------------------------------------------ export / import
@app.command()
@_friendly_errors
def export(
    stack_path: Annotated[Path, typer.Argument(help="Stack (Zarr) or import folder.")],
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder to write (manifest.csv + images + acquisition.json).")],
    fmt: Annotated[str, typer.Option("--format", help="tiff or png (16-bit grayscale).")] = "tiff",
    bit_depth: Annotated[int, typer.Option(help="Bits of the written codes.")] = 16,
    black_level: Annotated[int, typer.Option(help="Code of black (keeps small negative values).")] = 256,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing folder.")] = False,
):
    """Export a stack as 16-bit images + manifest.csv + acquisition.json (the import format)."""
    from .io import export_folder

    st = _load_stack(stack_path)
    with console.status(f"exporting {len(st)} images"):
        export_folder(st, out_dir, fmt=fmt, bit_depth=bit_depth, black_level=black_level, overwrite=overwrite)
    out.print(f"exported folder: {out_dir}")


@app.command("import")
@_friendly_errors
def import_(
    folder: Annotated[Path, typer.Argument(help="Folder with manifest.csv, images and acquisition.json.")],
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Native stack to write (Zarr).")],
    overwrite: Annotated[bool, typer.Option(help="Replace an existing store.")] = False,
):
    """Import a captured stack folder into a native Zarr stack."""
    from .io import import_folder, write_stack

    st = import_folder(folder)
    with progress_bar() as bar:
        task = bar.add_task("writing stack", total=len(st))
        write_stack(st, out_path, overwrite=overwrite, progress=lambda i: bar.advance(task))
    out.print(f"stack: {out_path}  ({len(st)} images, {st.shape[0]}x{st.shape[1]})")


# ------------------------------------------------------------------ demo
@app.command()
@_friendly_errors
def demo(
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("out"),
    size: Annotated[int, typer.Option(help="Image size (square).")] = 128,
    seed: Annotated[int, typer.Option(help="Seed.")] = 0,
):
    """The newcomer's first run: simulate the paper's sweep and look at it."""
    from .demo import run_demo

    run_demo(out_dir, size=size, seed=seed, console=out, progress=progress_bar)


def main(argv: list[str] | None = None):
    """Console entry point (``planeray``)."""
    import sys

    args = _join_pixel_args(list(sys.argv[1:] if argv is None else argv))
    app(args=args, prog_name="planeray")


if __name__ == "__main__":  # pragma: no cover
    main()
