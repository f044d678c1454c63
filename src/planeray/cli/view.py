"""``planeray view`` (the live explorer in the browser) and ``planeray video`` (a sweep written as a video)."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Annotated

import typer

from .._console import console, print_verbatim, progress_bar
from ..errors import InputError
from ..timing import PAPER_LINES_PER_SECOND
from ._common import _check_outputs, _friendly_errors
from ._devices import CalibrationArg, DeviceOptionArg

PathArg = Annotated[
    str, typer.Argument(help="A scene name (a virtual Episcan: see `planeray scenes`), a transport store or a stack.")
]
ViewPathArg = Annotated[
    str | None,
    typer.Argument(
        help="A scene name (a virtual Episcan: see `planeray scenes`), a transport store or a stack; or --device."
    ),
]
SizeOpt = Annotated[
    tuple[int, int],
    typer.Option(
        help="Scenes: image size H W (camera pixels; at least 8, at most what memory holds; one number: a square)."
    ),
]
ProjectorRowsOpt = Annotated[
    int, typer.Option(help="Scenes: projector rows spanned by the image (1-720: the projector has 720).")
]
SeedOpt = Annotated[int, typer.Option(help="Scenes: seed of the textures and the camera noise (0 to 2^32-1).")]
TruthOpt = Annotated[Path | None, typer.Option(help="Ground-truth transport store, overlaid in the pixel plots.")]
TruthScaleOpt = Annotated[
    float | None,
    typer.Option(
        help="Multiply the ground truth by this (> 0) in the T(u) plot (a transport demultiplexed from a "
        "simulated stack is signal_scale = 0.6 times the scene's); default: compare by area."
    ),
]


def _check_scene_options(path, *, size, projector_rows, seed) -> None:
    """The scene options, before anything is built (a path that exists is not a scene: they do not apply)."""
    from . import _bounds

    _bounds.seed(seed)
    _bounds.projector_rows(projector_rows)
    if not Path(str(path)).exists():
        shape = _bounds.image_size(size)
        _bounds.scene_memory(shape)


PatternOpt = Annotated[
    list[Path] | None,
    typer.Option(help="Relighting pattern (.npy/.csv/.txt/image), offered by its file name (repeatable)."),
]


def _open(path, *, size, projector_rows, seed, truth, truth_scale, pattern):
    from ..viewer.session import open_source

    with console.status(f"opening {path}"):
        return open_source(
            path,
            size=size,
            projector_rows=projector_rows,
            seed=seed,
            lines_per_second=PAPER_LINES_PER_SECOND,
            truth=truth,
            truth_scale=truth_scale,
            patterns=[str(p) for p in pattern or []],
        )


def _can_open_browser() -> bool:
    """A graphical browser can be shown (never a text-mode browser in this terminal)."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


#: What ``view --device sim`` opens unless told otherwise: the pulsing skin (the vein view, Eq. 7 and the pulse),
#: through a camera binned as the paper's 1200-row sensor, one frame per image (a live video).
SIM_LIVE_DEFAULTS = {"scene": "skin", "pulse_bpm": 72.0, "sensor_rows": 1200}


def _sweep_frames(sweep) -> int:
    """Frames per image a sweep was designed for (its record's camera), else the paper's 8."""
    try:
        return int(sweep.record["camera"]["model"]["frames_averaged"])
    except (TypeError, KeyError, ValueError):
        return 8


def _open_live(device: str, device_option, calibration, snapshots, sweep=None):
    """The live source of ``view --device``: the device opened from its options, with the live defaults
    (with a sweep: the live transport, :class:`planeray.viewer.live.LiveTransportSource`)."""
    from ..devices import SimulatedEpiscan, device_options
    from ..viewer.live import DeviceSource, LiveTransportSource
    from ._devices import open_device_from_cli, parse_device_options

    given = parse_device_options(device_option)
    accepted = device_options(device)
    defaults = dict(SIM_LIVE_DEFAULTS) if device == "sim" else {}
    if given.get("scene", "skin") != "skin":
        defaults.pop("pulse_bpm", None)  # only the skin pulses
    if "frames_averaged" in accepted:
        # a live video: one frame per image; a live transport: the frames its sweep was designed for
        defaults["frames_averaged"] = 1 if sweep is None else _sweep_frames(sweep)
    explicit = {k: v for k, v in defaults.items() if k not in given and k in accepted}

    def check(options):
        if "base_trigger_delay_us" in accepted and options.get("base_trigger_delay_us") is None:
            raise InputError(
                f"device {device!r} needs its base trigger delay: run `planeray calibrate delay-zero --device "
                f"{device} --write acquisition.json` and pass --calibration acquisition.json (or -O "
                "base_trigger_delay_us=...)"
            )

    with console.status(f"opening {device}"):
        dev = open_device_from_cli(device, explicit, device_option, calibration, check=check)
    max_fps = None
    if isinstance(dev, SimulatedEpiscan):  # as fast as its projector and averaging allow, never every core
        max_fps = dev.rig["frame_rate_hz"] / dev.camera.frames_averaged
    try:
        if sweep is not None:
            source = LiveTransportSource(dev, sweep, name=device, max_fps=max_fps, snapshot_dir=snapshots)
        else:
            source = DeviceSource(dev, name=device, max_fps=max_fps, snapshot_dir=snapshots)
        return source, explicit
    except BaseException:
        dev.close()
        raise


@_friendly_errors
def view(
    path: ViewPathArg = None,
    device: Annotated[
        str | None,
        typer.Option(help="Show this device live instead (`planeray devices`): sim, genicam, ueye, ..."),
    ] = None,
    device_option: DeviceOptionArg = None,
    calibration: CalibrationArg = None,
    snapshots: Annotated[
        Path | None,
        typer.Option(help="--device: the folder the page's 'save stack' writes to.", show_default="the current folder"),
    ] = None,
    sweep: Annotated[
        str | None,
        typer.Option(
            help="--device: cycle this sweep (a sweep file from `planeray sweep design`, or paper, quick) and show "
            "the live transport of its rolling window (sharpened, relit, short/long range), updated as images arrive.",
            show_default=False,
        ),
    ] = None,
    host: Annotated[
        str, typer.Option(help="Address to serve on. 127.0.0.1 (default): this machine only.")
    ] = "127.0.0.1",
    port: Annotated[
        int, typer.Option(help="Port, 0-65535 (0: any free port; a port in use falls back to a free one).")
    ] = 8765,
    browser: Annotated[
        bool, typer.Option(help="Open the page in the default browser (--no-browser: only print its URL).")
    ] = True,
    size: SizeOpt = (128, 128),
    projector_rows: ProjectorRowsOpt = 720,
    seed: SeedOpt = 0,
    truth: TruthOpt = None,
    truth_scale: TruthScaleOpt = None,
    pattern: PatternOpt = None,
):
    """Explore a scene, a transport or a stack live in the browser: delay and exposure sliders, epipolar,
    non-epipolar, sharpened, short/long range, relighting, pixel plots, snapshots (Ctrl-C stops).

    With ``--device NAME`` the page drives a device live: its sliders set the camera's trigger delay and
    exposure; the band image, the vein view, Eq. 7's composite over a cycle of delays and the pulse of a
    rolling window; 'save stack' writes what was captured into --snapshots.  ``--device sim`` is the
    simulated pulsing skin (-O scene=... for another scene).  With ``--sweep sweep.json`` the device cycles the
    sweep and the page shows the live transport of its rolling window (sharpened epipolar, relit, short/long
    range), updated as images arrive, with its update rate and age."""
    from .._validate import check_integer, check_positive
    from ..viewer.server import ViewerServer

    check_integer(port, "--port", minimum=0, maximum=65535)
    if (path is None) == (device is None):
        raise InputError("give a PATH (a scene, a transport store or a stack) or --device NAME, one of them")
    if device is None:
        for option, value in (("--device-option", device_option or None), ("--calibration", calibration),
                              ("--snapshots", snapshots), ("--sweep", sweep)):  # fmt: skip
            if value is not None:
                raise InputError(f"{option} applies to --device only")
    if truth_scale is not None:
        check_positive(truth_scale, "--truth-scale")
    if device is not None:
        if truth is not None or pattern:
            raise InputError("--truth and --pattern apply to a PATH, not to --device")
        folder = Path.cwd() if snapshots is None else snapshots
        if not folder.is_dir():
            raise InputError("--snapshots must be an existing folder", folder)
        from . import _limits as lim

        chosen = None if sweep is None else lim.sweep(sweep)
        source, used = _open_live(device, device_option, calibration, folder, chosen)
    else:
        _check_scene_options(path, size=size, projector_rows=projector_rows, seed=seed)
        source = _open(path, size=size, projector_rows=projector_rows, seed=seed, truth=truth,
                       truth_scale=truth_scale, pattern=pattern)  # fmt: skip
    try:
        server = ViewerServer(source, host=host, port=port)
    except BaseException:
        getattr(source, "close", lambda: None)()
        raise
    if server.port_fallback:
        console.print(f"port {port} is in use; serving on {server.port}")
    if not server.loopback:
        console.print(
            f"note: serving on {host}, reachable from other machines; the access token in the URL is the only lock"
        )
    what = f"{source.kind} {source.name}"
    if device is not None and used:
        what += " (" + ", ".join(f"-O {k}={v}" for k, v in used.items()) + ")"
    console.print(f"planeray view: {what} ({source.shape[0]}x{source.shape[1]}); Ctrl-C stops")
    print_verbatim(server.url)
    if browser and _can_open_browser():
        import webbrowser

        webbrowser.open(server.url)
    try:
        server.run()
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()


def _check_video_options(out_path, sweep, delay_us, exposure_us, start_us, stop_us, frames, fps, white, gamma,
                         colormap, scale) -> None:  # fmt: skip
    """``planeray video``'s options, each refused in one line naming it."""
    from .._validate import check_integer, check_number, check_positive
    from ..viewer.display import check_display
    from ..viewer.video import CODECS, FPS_RANGE, MAX_FRAMES, check_sweep_value

    if out_path.suffix.lower() not in CODECS:
        raise ValueError(f"--out must end in {', '.join(CODECS)}, got {out_path.name!r}")
    if sweep not in ("delay", "exposure"):
        raise ValueError(f"--sweep must be delay or exposure, got {sweep!r}")
    check_sweep_value(delay_us, "delay", "--delay-us")
    check_sweep_value(exposure_us, "exposure", "--exposure-us")
    for name, value in (("--from", start_us), ("--to", stop_us)):
        if value is not None:
            check_sweep_value(value, sweep, name)
    if frames is not None:
        check_integer(frames, "--frames", minimum=2, maximum=MAX_FRAMES)
    if fps is not None:
        check_number(fps, "--fps", minimum=FPS_RANGE[0], maximum=FPS_RANGE[1])
    if white is not None:
        check_positive(white, "--white")
    check_display(white=1.0 if white is None else white, gamma=gamma, colormap=colormap)
    if scale is not None:
        check_integer(scale, "--scale", minimum=1, maximum=64)


@_friendly_errors
def video(
    path: PathArg,
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Video to write (.mp4, .mkv or .webm).")],
    sweep: Annotated[str, typer.Option(help="What changes over the video: delay or exposure.")] = "delay",
    delay_us: Annotated[
        float, typer.Option("--delay-us", help="Delay of an exposure sweep (us, within +-13,333: one sweep).")
    ] = 0.0,
    exposure_us: Annotated[
        float, typer.Option("--exposure-us", help="Exposure of a delay sweep (us, > 0 and <= 13,333).")
    ] = 600.0,
    start_us: Annotated[
        float | None,
        typer.Option(
            "--from",
            help="First delay/exposure (us, within one projector sweep; default -1500 / 100, a stack's first).",
        ),
    ] = None,
    stop_us: Annotated[
        float | None,
        typer.Option("--to", help="Last delay/exposure (us, as --from; default 1500 / 2400, a stack's last)."),
    ] = None,
    frames: Annotated[int | None, typer.Option(help="Frames (scenes, transports; 2-100,000; default 121).")] = None,
    fps: Annotated[float | None, typer.Option(help="Frames per second (0.1-240; default 30, 4 for a stack).")] = None,
    noise: Annotated[bool, typer.Option(help="Scenes: camera noise.")] = False,
    ambient: Annotated[bool, typer.Option(help="Scenes: ambient light.")] = False,
    white: Annotated[
        float | None, typer.Option(help="Value shown white (> 0; default: 99.5th percentile over the sweep).")
    ] = None,
    gamma: Annotated[float, typer.Option(help="Display gamma (0.05-20).")] = 1.0,
    colormap: Annotated[str, typer.Option(help="gray, magma, inferno, viridis, cividis or turbo.")] = "gray",
    scale: Annotated[int | None, typer.Option(help="Whole-pixel upscaling (1-64; default: at least 512 rows).")] = None,
    size: SizeOpt = (128, 128),
    projector_rows: ProjectorRowsOpt = 720,
    seed: SeedOpt = 0,
    overwrite: Annotated[bool, typer.Option(help="Replace a video planeray wrote.")] = False,
):
    """Write a delay (or exposure) sweep as a video: the paper's "sweeping the band"."""
    from .._extras import import_extra
    from ..viewer.session import ViewSettings
    from ..viewer.video import (
        VIDEO_KIND,
        sweep_values,
        write_sweep_video,
    )

    # every option and the output before anything is built or rendered
    import_extra("imageio_ffmpeg", "planeray video")
    _check_video_options(out_path, sweep, delay_us, exposure_us, start_us, stop_us, frames, fps, white, gamma,
                         colormap, scale)  # fmt: skip
    _check_scene_options(path, size=size, projector_rows=projector_rows, seed=seed)
    _check_outputs(
        (out_path, VIDEO_KIND), overwrite=overwrite, inputs=[("PATH", path if Path(path).exists() else None)]
    )
    source = _open(path, size=size, projector_rows=projector_rows, seed=seed, truth=None, truth_scale=None,
                   pattern=None)  # fmt: skip
    settings = ViewSettings(delay_us=delay_us, exposure_us=exposure_us, noise=noise, ambient=ambient)
    n = len(sweep_values(source, sweep, start_us=start_us, stop_us=stop_us, frames=frames))
    with progress_bar() as bar:
        task = bar.add_task(f"{sweep} sweep", total=n)
        written = write_sweep_video(
            source,
            out_path,
            sweep=sweep,
            settings=settings,
            start_us=start_us,
            stop_us=stop_us,
            frames=frames,
            fps=fps,
            white=white,
            gamma=gamma,
            colormap=colormap,
            scale=scale,
            overwrite=overwrite,
            progress=lambda k: bar.advance(task, k),
        )
    print_verbatim(str(written))
