"""``planeray calibrate``: the projector's line velocity v_p and the delay zero (Sec. 6)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from .._console import out
from ..errors import InputError
from ..timing import PAPER_LINES_PER_SECOND
from . import _limits as lim
from ._common import _check_outputs, _claim, _friendly_errors, _load_stack
from ._devices import CalibrationArg, DeviceOptionArg, close_device, open_device_from_cli, screen_options

calibrate_app = typer.Typer(help="Calibration (Sec. 6): line velocity v_p and delay zero.", no_args_is_help=True)


#: Longest exposure of a calibration capture (us): a little over one 60 Hz projector frame.
MAX_CALIBRATION_EXPOSURE_US = 20_000.0
#: Projector frame periods of the base-trigger search (us): 1 kHz to 1 Hz.
FRAME_PERIOD_RANGE_US = (1_000.0, 1_000_000.0)


def _check_write_target(write: Path | None) -> None:
    """Refuse, before any work, an acquisition.json that could not be updated without loss."""
    if write is not None:
        from ..calibration.files import calibration_target

        try:
            target, _ = calibration_target(write)
        except InputError as exc:
            raise InputError(f"--write: {exc}") from None
        _claim(target)  # writable, and no other calibration writing it


def _report_calibration(result, write: Path | None, as_json: bool, key: str):
    from ..calibration import write_calibration

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
    path: Annotated[
        Path | None,
        typer.Argument(help="Line-sweep capture: .npz (from simulate-lines) or grayscale .tif/.png (or --device)."),
    ] = None,
    exposure_us: Annotated[
        float | None, typer.Option(help="Global-shutter exposure of the capture (default 500 us).")
    ] = None,
    rows_per_line: Annotated[
        int | None, typer.Option(help="Projector rows between lit lines of the comb (--device: default 8).")
    ] = None,
    device: Annotated[
        str | None,
        typer.Option(help="Capture live: the camera (global shutter) images each comb phase shown on --screen."),
    ] = None,
    device_option: DeviceOptionArg = None,
    calibration: CalibrationArg = None,
    screen: Annotated[
        int | None, typer.Option(help="--device: the projector's screen (`planeray project --list-screens`).")
    ] = None,
    display: Annotated[str | None, typer.Option(help="--device: X display (default $DISPLAY).")] = None,
    trigger_delay_us: Annotated[
        float | None,
        typer.Option(help="--device: when the global exposure opens after VSYNC (us).", show_default="mid-frame"),
    ] = None,
    timing_jitter_us: Annotated[
        float | None,
        typer.Option(
            help="--device: RMS jitter (us) of the exposure window per averaged image, for the uncertainty.",
            show_default="the device's, else 0",
        ),
    ] = None,
    save: Annotated[
        Path | None, typer.Option(help="--device: also save the captured line sweep (.npz) to count again later.")
    ] = None,
    write: Annotated[
        Path | None, typer.Option(help="Write lines_per_second into this acquisition.json (or folder).")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
):
    """Projector scanline velocity v_p = n_lines / t_e from a line-sweep capture, with its uncertainty.

    With ``--device NAME --screen N`` planeray captures it: a full-screen window on
    screen N shows each phase of a comb of rows ``--rows-per-line`` apart, the
    camera (switched to its global shutter, then back) takes one exposure of
    ``--exposure-us`` per phase at a fixed delay after VSYNC, then a dark and a flat
    frame.  ``--write`` updates (or creates) an acquisition.json: it sets the
    calibration fields and keeps every other field; a value it changes is kept under
    ``calibration.replaced``.  The file is checked before any work and replaced
    atomically.
    """
    from ..calibration import calibrate_lines_per_second, read_line_sweep

    lim.optional(lim.positive, exposure_us, "--exposure-us", maximum=MAX_CALIBRATION_EXPOSURE_US)
    lim.optional(lim.integer, rows_per_line, "--rows-per-line", minimum=1, maximum=lim.MAX_PROJECTOR_ROWS)
    if (path is None) == (device is None):
        raise InputError("give a line-sweep capture PATH, or --device NAME --screen N to capture one")
    live_only = {"--screen": screen, "--display": display, "--trigger-delay-us": trigger_delay_us, "--save": save}
    live_only["--timing-jitter-us"] = timing_jitter_us
    live_only.update({"--device-option": device_option or None, "--calibration": calibration})
    for option, value in live_only.items():
        if value is not None and device is None:
            raise InputError(f"{option} applies to --device only")
    _check_write_target(write)
    if device is not None:
        lim.optional(lim.nonnegative, timing_jitter_us, "--timing-jitter-us", maximum=10_000.0)
        sweep = _capture_lines_live(
            device,
            device_option,
            calibration,
            screen,
            display,
            exposure_us,
            rows_per_line,
            trigger_delay_us,
            save,
            timing_jitter_us,
        )
    else:
        sweep = read_line_sweep(path, exposure_us=exposure_us, rows_per_line=rows_per_line)
    result = calibrate_lines_per_second(sweep)
    if not lim.MIN_LINES_PER_SECOND <= result.lines_per_second <= lim.MAX_LINES_PER_SECOND:
        raise InputError(
            f"{result.n_lines:.2f} lines in {result.exposure_us:g} us make {result.lines_per_second:,.0f} lines/s, "
            f"outside what a raster projector scans ({lim.MIN_LINES_PER_SECOND:,.0f}-{lim.MAX_LINES_PER_SECOND:,.0f}); "
            "check --exposure-us (the capture's global-shutter exposure)"
        )
    _report_calibration(result, write, as_json, "lines")
    if not as_json:
        out.print(
            f"lines_per_second = {result.lines_per_second:,.0f} +- {result.uncertainty:,.0f} (1 sigma, "
            f"{result.relative_uncertainty * 100:.2f} %) from {result.n_lines:.2f} lines in {result.exposure_us:g} us"
            + (f"; written to {write}" if write else ""),
            markup=False,
            highlight=False,
        )


def _capture_lines_live(
    device,
    device_option,
    calibration,
    screen,
    display,
    exposure_us,
    rows_per_line,
    trigger_delay_us,
    save,
    timing_jitter_us=None,
):
    """The comb shown on the screen and captured by the device (``calibrate lines --device``)."""
    from ..calibration import write_line_sweep
    from ..calibration.files import LINE_SWEEP_KIND
    from ..devices.capabilities import require
    from ..linesweep import PAPER_CALIBRATION_EXPOSURE_US
    from ..projector import ProjectorWindow, get_screen
    from ..rig import DEFAULT_COMB_STEP_ROWS, capture_comb

    if screen is None:
        raise InputError("--device needs --screen N, the projector's screen (`planeray project --list-screens`)")
    if save is not None:
        if save.suffix.lower() != ".npz":
            raise InputError(f"--save must end in .npz (a line sweep), got {save.name}")
        _check_outputs((save, LINE_SWEEP_KIND, "--save"), overwrite=False)
    lim.optional(lim.nonnegative, trigger_delay_us, "--trigger-delay-us", maximum=lim.MAX_TIME_US)
    target = get_screen(screen, display)  # an unknown screen: one line, before the camera opens
    explicit = screen_options(device, screen, display, device_option)
    dev = open_device_from_cli(device, explicit, device_option, calibration)
    try:
        require(dev, "global_shutter", "calibrate lines --device")
        with ProjectorWindow(target) as window:
            sweep = capture_comb(
                dev,
                window,
                exposure_us=PAPER_CALIBRATION_EXPOSURE_US if exposure_us is None else exposure_us,
                line_step_rows=DEFAULT_COMB_STEP_ROWS if rows_per_line is None else rows_per_line,
                trigger_delay_us=trigger_delay_us,
                timing_jitter_us=timing_jitter_us,
            )
    finally:
        close_device(dev)
    if save is not None:
        write_line_sweep(sweep, save)
    return sweep


@calibrate_app.command("simulate-lines")
@_friendly_errors
def calibrate_simulate_lines(
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Line-sweep capture to write (.npz).")],
    lines_per_second: Annotated[
        float, typer.Option(help="True v_p of the simulated projector (lines/s).")
    ] = PAPER_LINES_PER_SECOND,
    size: Annotated[
        tuple[int, int], typer.Option(help="Calibration camera H W (pixels; must resolve projector rows).")
    ] = (288, 64),
    projector_rows: Annotated[int, typer.Option(help="Projector rows spanned by the image.")] = 96,
    exposure_us: Annotated[float, typer.Option(help="Global-shutter exposure (us).")] = 500.0,
    seed: Annotated[int, typer.Option(help="Seed.")] = 0,
    overwrite: Annotated[bool, typer.Option(help="Replace a line sweep planeray wrote.")] = False,
):
    """Capture a line-velocity calibration on the simulated device (a diffuse target)."""
    from ..calibration import write_line_sweep
    from ..calibration.files import LINE_SWEEP_KIND
    from ..devices import SimulatedEpiscan
    from ..scenes import make_scene

    if out_path.suffix.lower() != ".npz":
        raise InputError(f"--out must end in .npz (a line sweep), got {out_path.name}")
    _check_outputs((out_path, LINE_SWEEP_KIND), overwrite=overwrite)
    lim.lines_per_second(lines_per_second)
    size = lim.size(size)
    lim.projector_rows(projector_rows)
    lim.positive(exposure_us, "--exposure-us", maximum=MAX_CALIBRATION_EXPOSURE_US)
    lim.seed(seed)
    scene = make_scene("diffuse_plane", size, projector_rows=projector_rows, seed=seed)
    dev = SimulatedEpiscan(scene, lines_per_second=lines_per_second, seed=seed)
    try:
        sweep = dev.capture_line_sweep(exposure_us=exposure_us)
    except ValueError as exc:  # the geometry: the lines must be resolved and fit on the projector
        raise InputError(
            f"--exposure-us {exposure_us:g} at --lines-per-second {lines_per_second:g} with --size {size[0]} "
            f"{size[1]} and --projector-rows {projector_rows}: {exc}"
        ) from None
    path = write_line_sweep(sweep, out_path, overwrite=overwrite)
    out.print(f"line sweep: {path}  (true lines_per_second {lines_per_second:,.0f})", markup=False, highlight=False)


@calibrate_app.command("delay-zero")
@_friendly_errors
def calibrate_delay_zero_cmd(
    stack_path: Annotated[
        Path | None, typer.Argument(help="A fine delay sweep around 0 at one exposure (stack or folder).")
    ] = None,
    exposure_us: Annotated[float, typer.Option(help="Exposure of the sweep's images to use (us).")] = 600.0,
    device: Annotated[
        str | None,
        typer.Option(help="Calibrate live on this device (e.g. ueye): finds the camera's base trigger delay."),
    ] = None,
    device_option: DeviceOptionArg = None,
    calibration: CalibrationArg = None,
    base_trigger_delay_us: Annotated[
        float | None,
        typer.Option(help="--device: a known base trigger delay (us) to refine; skips the search over one frame."),
    ] = None,
    sweep: Annotated[
        str | None,
        typer.Option(
            help="--device: the sweep the base must serve (the base exceeds its largest t'_o).", show_default="paper"
        ),
    ] = None,
    frame_period_us: Annotated[
        float | None,
        typer.Option(
            help="--device: projector frame period (us), the range of the search.", show_default="16666.7 (60 Hz)"
        ),
    ] = None,
    simulate: Annotated[bool, typer.Option(help="Sweep the simulated device instead of reading a stack.")] = False,
    delay_error_us: Annotated[
        float | None, typer.Option(help="--simulate: hidden sync error to recover (us).", show_default="0")
    ] = None,
    seed: Annotated[int | None, typer.Option(help="--simulate: seed.", show_default="0")] = None,
    screen: Annotated[
        int | None,
        typer.Option(help="--device: show white on this screen (the projector's) for the whole calibration."),
    ] = None,
    display: Annotated[str | None, typer.Option(help="--screen: X display (default $DISPLAY).")] = None,
    write: Annotated[
        Path | None,
        typer.Option(help="Write delay_zero_us (and base_trigger_delay_us) into this acquisition.json (or folder)."),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
):
    """The commanded delay at which the epipolar (direct) response is centred, so t'_o is measured (Eq. 1).

    With ``--device ueye`` (a diffuse target in front of the rig) it is captured
    live and turned into the camera's base trigger delay, the trigger delay at
    t'_o = 0, which ``--write`` stores for ``planeray acquire --calibration``.  A
    stack captured by the uEye driver gives it too (its metadata holds the base
    it was captured with).  ``--write`` keeps every other field of the file (a
    value it changes or removes is kept under ``calibration.replaced``).
    """
    from ..calibration import calibrate_delay_zero, calibrate_delay_zero_from_stack, delay_zero_sweep, device_capture

    _delay_zero_options(
        stack_path, device, simulate, exposure_us=exposure_us, base_trigger_delay_us=base_trigger_delay_us,
        sweep=sweep, frame_period_us=frame_period_us, device_option=device_option, calibration=calibration,
        screen=screen, display=display, delay_error_us=delay_error_us, seed=seed,
    )  # fmt: skip
    seed = lim.seed(0 if seed is None else seed)
    delay_error_us = lim.number(0.0 if delay_error_us is None else delay_error_us, "--delay-error-us")
    reach = max(0.5 * exposure_us, 250.0)  # the fine sweep brackets the plateau by this much on each side
    if abs(delay_error_us) > reach:
        raise InputError(
            f"--delay-error-us must be within +-{reach:g} us at --exposure-us {exposure_us:g} (the fine delay sweep "
            f"brackets the epipolar plateau by that much), got {delay_error_us:g}"
        )
    _check_write_target(write)
    if device is not None:
        result = _delay_zero_on_device(
            device, exposure_us=exposure_us, device_option=device_option, calibration=calibration, screen=screen,
            display=display, sweep=sweep, base_trigger_delay_us=base_trigger_delay_us, frame_period_us=frame_period_us,
        )  # fmt: skip
    elif simulate:
        from ..devices import SimulatedEpiscan
        from ..scenes import make_scene

        dev = SimulatedEpiscan(make_scene("diffuse_plane", (64, 64), projector_rows=360, seed=seed), seed=seed)
        capture = device_capture(dev, exposure_us=exposure_us, delay_error_us=delay_error_us)
        result = calibrate_delay_zero(
            capture, delay_zero_sweep(exposure_us=exposure_us).delay_us, exposure_us=exposure_us,
            lines_per_second=dev.lines_per_second,
        )  # fmt: skip
    else:
        if stack_path is None:
            raise ValueError("give a STACK (a delay sweep around 0), --device DEVICE or --simulate")
        result = calibrate_delay_zero_from_stack(_load_stack(stack_path), exposure_us=exposure_us, source=stack_path)
    _report_calibration(result, write, as_json, "delay_zero")
    if not as_json:
        _print_delay_zero(result, write, sweep)


def _delay_zero_options(stack_path, device, simulate, *, exposure_us, base_trigger_delay_us, sweep, frame_period_us,
                        device_option, calibration, screen, display, delay_error_us, seed) -> None:  # fmt: skip
    """The options of ``calibrate delay-zero``: one source, each option where it applies, in its range."""
    if sum((stack_path is not None, simulate, device is not None)) > 1:
        raise ValueError("give one of STACK, --device or --simulate")
    given = {
        "--base-trigger-delay-us": (base_trigger_delay_us, device is not None),
        "--sweep": (sweep, device is not None),
        "--frame-period-us": (frame_period_us, device is not None),
        "--device-option": (device_option or None, device is not None),
        "--calibration": (calibration, device is not None),
        "--screen": (screen, device is not None),
        "--display": (display, screen is not None),
        "--delay-error-us": (delay_error_us, simulate),
        "--seed": (seed, simulate),
    }
    for option, (value, applies) in given.items():
        if value is not None and not applies:
            mode = "--simulate" if option in ("--delay-error-us", "--seed") else "--device"
            raise InputError(f"{option} applies to {mode} only")
    lim.positive(exposure_us, "--exposure-us", maximum=MAX_CALIBRATION_EXPOSURE_US)
    lim.optional(lim.nonnegative, base_trigger_delay_us, "--base-trigger-delay-us", maximum=lim.MAX_TIME_US)
    lim.optional(
        lim.number,
        frame_period_us,
        "--frame-period-us",
        minimum=FRAME_PERIOD_RANGE_US[0],
        maximum=FRAME_PERIOD_RANGE_US[1],
    )


def _delay_zero_on_device(device, *, exposure_us, device_option, calibration, screen, display, sweep,
                          base_trigger_delay_us, frame_period_us):  # fmt: skip
    """Delay zero measured live (with white on ``screen``): the base trigger delay of a VSYNC-triggered camera."""
    from ..calibration import (
        PROJECTOR_FRAME_PERIOD_US,
        calibrate_base_trigger_delay,
        calibrate_delay_zero,
        delay_zero_sweep,
        device_capture,
    )

    if sweep is not None:
        lim.sweep(sweep)
    window = None
    if screen is not None:
        from ..projector import ProjectorWindow, get_screen, white

        target = get_screen(screen, display)  # an unknown screen: one line, before the camera opens
    explicit = screen_options(device, screen, display, device_option)
    dev = open_device_from_cli(device, explicit, device_option, calibration)
    try:
        if screen is not None:
            window = ProjectorWindow(target)
            window.show(white(window.shape))
        if hasattr(dev, "base_trigger_delay_us"):  # a camera triggered by VSYNC: find its base
            return calibrate_base_trigger_delay(
                dev,
                exposure_us=exposure_us,
                sweeps=[lim.sweep(sweep or "paper")],
                base_trigger_delay_us=base_trigger_delay_us,
                frame_period_us=PROJECTOR_FRAME_PERIOD_US if frame_period_us is None else frame_period_us,
            )
        sw = delay_zero_sweep(exposure_us=exposure_us)
        return calibrate_delay_zero(
            device_capture(dev, exposure_us=exposure_us), sw.delay_us, exposure_us=exposure_us,
            lines_per_second=dev.lines_per_second,
        )  # fmt: skip
    finally:
        if window is not None:
            window.close()
        close_device(dev)


def _print_delay_zero(result, write, sweep) -> None:
    base = result.base_trigger_delay_us
    out.print(
        f"delay zero = {result.delay_zero_us:+.2f} +- {result.uncertainty_us:.2f} us (commanded delay of the true "
        f"epipolar centre); sync offset t'_o = {result.sync_offset_us:.2f} us"
        + (f"; base trigger delay = {base:.2f} us" if base is not None else "")
        + (f"; written to {write}" if write else ""),
        markup=False,
        highlight=False,
    )
    if base is not None and result.details.get("fits_sweeps") is False:
        out.print(
            f"note: the base is below {result.details['required_base_us']:.1f} us, the least the "
            f"{sweep or 'paper'!r} sweep needs: its earliest points will be refused. Calibrate again without "
            "--base-trigger-delay-us (the search picks a base that fits).",
            markup=False,
            highlight=False,
        )
