"""``planeray project`` (the projector window) and ``planeray rig check`` (is the rig set up right?)."""

from __future__ import annotations

import json
import signal
from pathlib import Path
from typing import Annotated

import typer

from .._console import out
from ..errors import InputError
from ._common import _friendly_errors
from ._devices import CalibrationArg, DeviceOptionArg, open_device_from_cli, read_calibration, screen_options

rig_app = typer.Typer(help="The rig: check that it is wired and set up right.", no_args_is_help=True)

ScreenArg = Annotated[int, typer.Option(help="The projector's screen (`planeray project --list-screens`).")]
DisplayArg = Annotated[str | None, typer.Option(help="X display (default $DISPLAY).")]


@_friendly_errors
def project(
    pattern: Annotated[
        str | None,
        typer.Argument(
            help="white, black, comb:K:J (every K-th row from J), row:R, rows:A:B, card[:STEP], or an image file "
            "(PNG/TIFF/.npy, 8-bit)."
        ),
    ] = None,
    screen: Annotated[int, typer.Option(help="The screen to show it on (--list-screens).")] = 0,
    display: DisplayArg = None,
    list_screens_: Annotated[bool, typer.Option("--list-screens", help="List the screens and exit.")] = False,
    place: Annotated[
        tuple[int, int] | None,
        typer.Option(help="Put a pattern of another size on black, its top-left pixel at ROW COLUMN."),
    ] = None,
    seconds: Annotated[
        float | None, typer.Option(help="Close after this many seconds (default: until Esc or Ctrl-C).")
    ] = None,
):
    """Show a pattern full screen on the projector, pixel for pixel, until Esc (in the window) or Ctrl-C.

    The window is borderless, covers the screen, and swaps on vsync; pattern pixel
    (r, c) is projector pixel (r, c): nothing is scaled, filtered or gamma-corrected,
    and a pattern of another size than the screen is refused unless --place puts it.
    Closing it leaves the screen as it was.
    """
    from ..projector import ProjectorWindow, get_screen, list_screens, parse_pattern

    if list_screens_:
        for s in list_screens(display):
            out.print(s.describe(), markup=False, highlight=False)
        return
    if pattern is None:
        raise InputError("give a PATTERN (white, black, comb:K:J, row:R, rows:A:B, card, or an image file)")
    if seconds is not None and not 0 < seconds <= 86_400:
        raise InputError(f"--seconds must be between 0 and 86400, got {seconds:g}")
    target = get_screen(screen, display)
    image = parse_pattern(pattern, target.shape)
    if place is None and image.shape[:2] != target.shape:
        h, w = image.shape[:2]
        raise InputError(
            f"the pattern is {w}x{h} pixels, screen {screen} is {target.width}x{target.height}: a projector pixel "
            "must be a pattern pixel (no scaling); give one of the screen's size, or --place ROW COLUMN"
        )
    previous = signal.getsignal(signal.SIGTERM)
    signal.signal(signal.SIGTERM, lambda *a: (_ for _ in ()).throw(KeyboardInterrupt()))
    try:
        with ProjectorWindow(target) as window:
            window.show(image, at=place)
            out.print(
                f"showing {pattern} on screen {screen} ({target.width}x{target.height}); Esc in the window or Ctrl-C "
                "here closes it",
                markup=False,
                highlight=False,
            )
            try:
                reason = window.wait_closed(seconds)
            except Exception as exc:
                if seconds is not None and "waited" in str(exc):
                    reason = f"{seconds:g} s elapsed"
                else:
                    raise
    finally:
        signal.signal(signal.SIGTERM, previous)
    out.print(f"closed ({reason})", markup=False, highlight=False)


@rig_app.command("check")
@_friendly_errors
def check(
    device: Annotated[str, typer.Option(help="The camera (`planeray devices`).")],
    screen: ScreenArg = 0,
    display: DisplayArg = None,
    device_option: DeviceOptionArg = None,
    calibration: CalibrationArg = None,
    sweep: Annotated[
        str, typer.Option(help="The sweep the rig must serve (paper, quick, or a sweep file .json).")
    ] = "paper",
    frame_rate_hz: Annotated[
        float | None, typer.Option(help="The projector's frame rate.", show_default="the screen's, else 60")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
):
    """Check the rig, one line per check: pass, fail with what to do, or skip with why.

    The camera is found and released; frames arrive on the trigger at the projector's
    frame rate; the rolling shutter is selected; the row time matches the projector's
    line velocity (a short delay scan); the output is linear (a two-exposure test);
    the exposure and trigger-delay ranges cover the sweep; the projector window is up
    on the screen (read back pixel for pixel) and the camera sees it; the epipolar
    response peaks at the calibrated delay zero (--calibration). Exit status 1 if a
    check fails. Put a white diffuse target in front of the rig.
    """
    from ..projector import get_screen
    from ..rig import check_rig
    from . import _limits as lim

    sweep_ = lim.sweep(sweep)
    lim.optional(lim.positive, frame_rate_hz, "--frame-rate-hz", maximum=1000.0)
    get_screen(screen, display)  # an unknown screen: one line, before anything opens
    delay_zero = None
    if calibration is not None:
        try:
            delay_zero = read_calibration(calibration, fields=("delay_zero_us",)).get("delay_zero_us")
        except InputError as exc:
            raise InputError(f"--calibration {exc}") from None
    explicit = screen_options(device, screen, display, device_option)

    def opener():
        return open_device_from_cli(device, explicit, device_option, calibration)

    def report(c):
        if not as_json:
            out.print(c.line(), markup=False, highlight=False, soft_wrap=True)

    results = check_rig(
        opener,
        screen,
        display=display,
        delay_zero_us=delay_zero,
        sweep=sweep_,
        frame_rate_hz=frame_rate_hz,
        report=report,
    )
    failed = [c for c in results if c.status == "fail"]
    if as_json:
        print(json.dumps([c.to_dict() for c in results], indent=2, default=float))
    else:
        out.print(
            f"{len(results) - len(failed)} of {len(results)} checks passed or skipped; {len(failed)} failed",
            markup=False,
            highlight=False,
        )
    if failed:
        raise typer.Exit(1)


__all__ = ["project", "rig_app", "Path"]
