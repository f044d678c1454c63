"""``planeray calibrate``: the projector's line velocity v_p and the delay zero (Sec. 6)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from .._console import out
from ..timing import PAPER_LINES_PER_SECOND
from ._common import _friendly_errors, _load_stack
from ._devices import CalibrationArg, DeviceOptionArg, close_device, device_options_from_cli

calibrate_app = typer.Typer(help="Calibration (Sec. 6): line velocity v_p and delay zero.", no_args_is_help=True)


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
        Path, typer.Argument(help="Line-sweep capture: .npz (from simulate-lines) or grayscale .tif/.png.")
    ],
    exposure_us: Annotated[
        float | None, typer.Option(help="Global-shutter exposure of the capture (default 500 us).")
    ] = None,
    rows_per_line: Annotated[int | None, typer.Option(help="Projector rows between lit lines of the comb.")] = None,
    write: Annotated[
        Path | None, typer.Option(help="Write lines_per_second into this acquisition.json (or folder).")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
):
    """Projector scanline velocity v_p = n_lines / t_e from a line-sweep capture, with its uncertainty."""
    from ..calibration import calibrate_lines_per_second, read_line_sweep

    result = calibrate_lines_per_second(read_line_sweep(path, exposure_us=exposure_us, rows_per_line=rows_per_line))
    _report_calibration(result, write, as_json, "lines")
    if not as_json:
        out.print(
            f"lines_per_second = {result.lines_per_second:,.0f} +- {result.uncertainty:,.0f} (1 sigma, "
            f"{result.relative_uncertainty * 100:.2f} %) from {result.n_lines:.2f} lines in {result.exposure_us:g} us"
            + (f"; written to {write}" if write else "")
        )


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
):
    """Capture a line-velocity calibration on the simulated device (a diffuse target)."""
    from ..calibration import write_line_sweep
    from ..devices import SimulatedEpiscan
    from ..scenes import make_scene

    scene = make_scene("diffuse_plane", size, projector_rows=projector_rows, seed=seed)
    dev = SimulatedEpiscan(scene, lines_per_second=lines_per_second, seed=seed)
    path = write_line_sweep(dev.capture_line_sweep(exposure_us=exposure_us), out_path)
    out.print(f"line sweep: {path}  (true lines_per_second {lines_per_second:,.0f})")


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
        str, typer.Option(help="--device: the sweep the base must serve (the base exceeds its largest t'_o).")
    ] = "paper",
    frame_period_us: Annotated[
        float, typer.Option(help="--device: projector frame period (us), the range of the search.")
    ] = 1e6 / 60.0,  # a 60 Hz projector (planeray.calibration.PROJECTOR_FRAME_PERIOD_US)
    simulate: Annotated[bool, typer.Option(help="Sweep the simulated device instead of reading a stack.")] = False,
    delay_error_us: Annotated[float, typer.Option(help="--simulate: hidden sync error to recover (us).")] = 0.0,
    seed: Annotated[int, typer.Option(help="--simulate: seed.")] = 0,
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
    it was captured with).
    """
    from ..calibration import (
        calibrate_base_trigger_delay,
        calibrate_delay_zero,
        delay_zero_sweep,
        device_capture,
        with_base_trigger_delay,
    )

    if sum((stack_path is not None, simulate, device is not None)) > 1:
        raise ValueError("give one of STACK, --device or --simulate")
    if device is not None:
        from ..devices import open_device
        from ..timing import make_sweep

        options = device_options_from_cli(device, {}, device_option, calibration)
        dev = open_device(device, **options)
        try:
            if hasattr(dev, "base_trigger_delay_us"):  # a camera triggered by VSYNC: find its base
                result = calibrate_base_trigger_delay(
                    dev,
                    exposure_us=exposure_us,
                    sweeps=[make_sweep(sweep)],
                    base_trigger_delay_us=base_trigger_delay_us,
                    frame_period_us=frame_period_us,
                )
            else:
                sw = delay_zero_sweep(exposure_us=exposure_us)
                result = calibrate_delay_zero(
                    device_capture(dev, exposure_us=exposure_us),
                    sw.delay_us,
                    exposure_us=exposure_us,
                    lines_per_second=dev.lines_per_second,
                )
        finally:
            close_device(dev)
    elif simulate:
        from ..devices import SimulatedEpiscan
        from ..scenes import make_scene

        dev = SimulatedEpiscan(make_scene("diffuse_plane", (64, 64), projector_rows=360, seed=seed), seed=seed)
        sweep_ = delay_zero_sweep(exposure_us=exposure_us)
        capture = device_capture(dev, exposure_us=exposure_us, delay_error_us=delay_error_us)
        result = calibrate_delay_zero(
            capture, sweep_.delay_us, exposure_us=exposure_us, lines_per_second=dev.lines_per_second
        )
    else:
        if stack_path is None:
            raise ValueError("give a STACK (a delay sweep around 0), --device DEVICE or --simulate")
        st = _load_stack(stack_path)
        idx = np.flatnonzero(np.isclose(st.exposure_us, exposure_us))
        if idx.size < 5:
            raise ValueError(f"{stack_path}: needs at least 5 images at exposure {exposure_us:g} us, found {idx.size}")
        images = np.stack([st.image(int(i)) for i in idx])
        result = calibrate_delay_zero(
            images, st.delay_us[idx], exposure_us=exposure_us, lines_per_second=st.lines_per_second
        )
        base_used = st.metadata.get("base_trigger_delay_us")
        if isinstance(base_used, (int, float)) and not isinstance(base_used, bool):
            result = with_base_trigger_delay(result, float(base_used))
    _report_calibration(result, write, as_json, "delay_zero")
    if not as_json:
        base = result.base_trigger_delay_us
        out.print(
            f"delay zero = {result.delay_zero_us:+.2f} +- {result.uncertainty_us:.2f} us (commanded delay of the true "
            f"epipolar centre); sync offset t'_o = {result.sync_offset_us:.2f} us"
            + (f"; base trigger delay = {base:.2f} us" if base is not None else "")
            + (f"; written to {write}" if write else "")
        )
        if base is not None and result.details.get("fits_sweeps") is False:
            out.print(
                f"note: the base is below {result.details['required_base_us']:.1f} us, the least the {sweep!r} sweep "
                "needs: its earliest points will be refused. Calibrate again without --base-trigger-delay-us "
                "(the search picks a base that fits)."
            )
