"""``planeray skin pulse | video | pulse-report``: the pulse from a video with Eulerian magnification (Sec. 10, Fig. 15).

Every option is checked before any work (the video is read, but nothing magnified, simulated or
written): bounds are physical (a heart beats 30-240 times a minute; the projector gives at most
75 delay images a second; a pass band must stay below the video's Nyquist frequency) or what
memory holds; every output -- result folder, magnified video, simulated videos and their vein
mask -- is checked before the first frame is made.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._console import console, out, print_json, progress_bar
from . import _bounds
from ._common import _check_outputs

#: The strongest amplification ``--alpha`` may ask for (Wu et al. use 10-150).
MAX_ALPHA = 1000.0
#: Kind of the mark of the vein mask ``skin video`` writes beside its video(s).
VIDEO_MASK_KIND = "video vein mask"


def _parse_band(text: str, name: str) -> tuple[float, float]:
    return _bounds.frequency_band(text, name)


def _check_bands_against(video, bands: dict, rate_option: str = "--rate-band") -> None:
    """Each pass band below the video's Nyquist frequency, and the video long enough for the rate band."""
    nyquist = video.fps / 2.0
    for option, (lo, hi) in bands.items():
        if hi > nyquist:
            raise ValueError(
                f"{option} {lo:g},{hi:g} Hz reaches above the Nyquist frequency of the video, {nyquist:g} Hz "
                f"({video.fps:g} fps)"
            )
    lo = bands[rate_option][0]
    need = 2.0 / max(lo, 1e-9)
    if video.duration_s < need:
        raise ValueError(
            f"{rate_option} starts at {lo:g} Hz: a rate that slow needs two of its periods, {need:.3g} s of video; "
            f"the video is {video.n_frames} frames at {video.fps:g} frames per second, {video.duration_s:.3g} s"
            + (" (is --fps right?)" if video.meta.get("fps_from") == "argument" else "")
        )


def _check_pulse_resources(video, out_dir: Path, opts: dict) -> None:
    """Refuse, before any work, what memory or the disk beside ``out_dir`` cannot hold.

    The analysis holds a bounded amount of memory (its allowance and a few frames: only frames too
    large for the memory are refused) and keeps the rest in temporary files beside ``out_dir``,
    which must have room for them.
    """
    import shutil

    from .._validate import _bytes_text, check_memory
    from ..pulse.analysis import scratch_bytes

    H, W = video.shape
    needs = scratch_bytes(
        video.n_frames,
        (H, W),
        levels=opts["levels"],
        pyramid=opts["pyramid"],
        alpha=opts["alpha"],
        search="region" not in opts,
        fps=video.fps,
        rate_band_hz=opts["rate_band_hz"],
    )
    check_memory(
        _bounds.BASE_BYTES + needs["memory"],
        f"{video.source}: magnifying frames of {H}x{W}",
        advice="the frames are too large for this machine",
    )
    need = needs["disk"]
    if not need:
        return
    folder = Path(out_dir).absolute().parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return
    if need > free:
        kept = ["the laplacian pyramid's bands" if opts["pyramid"] == "laplacian" else "the pyramid level it filters"]
        if "region" not in opts:
            kept.append("the magnified video of the region search")
        kept = " and ".join(kept)
        raise ValueError(
            f"{video.source}: {video.n_frames:,} frames of {H}x{W} need about {_bytes_text(need)} of temporary disk "
            f"space beside {out_dir} for {kept}, more than the {_bytes_text(free)} free there; "
            + ("give --region (no search), " if "region" not in opts else "")
            + "write --out on a disk with more room, or use a shorter video"
        )


def pulse(
    video_path: Annotated[Path, typer.Argument(help="Video: multi-page TIFF, folder of frames, mp4/avi/mkv/mov.")],
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder to write (pulse.json, CSVs, figures).")],
    fps: Annotated[
        float | None,
        typer.Option(
            help="Frame rate (Hz, > 0); required when the file has none, overrides it otherwise. The video must "
            "last two periods of the slowest --rate-band frequency (2.9 s by default)."
        ),
    ] = None,
    region: Annotated[
        str | None,
        typer.Option(help="ROW,COL (a pixel) or R0,C0,R1,C1 (a box, end exclusive); default: found automatically."),
    ] = None,
    mask: Annotated[
        Path | None,
        typer.Option(
            help="PNG/TIFF mask of the frames' size (non-zero = search here, e.g. a vein mask) for the automatic "
            "region."
        ),
    ] = None,
    band: Annotated[
        str, typer.Option(help="Temporal pass band of the magnification, LOW,HIGH Hz (0 <= LOW < HIGH <= fps/2).")
    ] = "0.5,2",
    alpha: Annotated[
        float, typer.Option(help="Amplification (gain applied to the band-passed video; 0-1000, Wu et al. 10-150).")
    ] = 50.0,
    levels: Annotated[
        int, typer.Option(help="Spatial pyramid levels (0 up to the frames' size allows: 6 at 48x48).")
    ] = 4,
    pyramid: Annotated[str, typer.Option(help="gaussian (colour magnification) or laplacian.")] = "gaussian",
    rate_band: Annotated[
        str, typer.Option(help="Where the heart rate is searched, LOW,HIGH Hz (0 < LOW < HIGH <= fps/2).")
    ] = "0.7,2",
    method: Annotated[str, typer.Option(help="Spectrum: periodogram or welch.")] = "periodogram",
    channel: Annotated[str, typer.Option(help="Colour videos: gray, red, green or blue.")] = "gray",
    magnified: Annotated[
        Path | None,
        typer.Option(help="Also write the magnified video here (.mp4/.avi/.mkv/.mov to watch, .tif/.tiff lossless)."),
    ] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the result as JSON on stdout.")] = False,
    overwrite: Annotated[
        bool, typer.Option(help="Replace a result folder (and --magnified video) planeray wrote.")
    ] = False,
):
    """Magnify a video (Eulerian, Wu et al. 2012) and measure the heart rate and its SNR (Fig. 15a).

    The video is read frame by frame, in bounded memory: what must be kept of a long or large video
    (the magnified video for the automatic region search) goes to temporary files beside --out.
    """
    from ..experiments.pulse import write_pulse_analysis

    video, opts = _pulse_inputs(
        video_path, out_dir, fps=fps, band=band, rate_band=rate_band, alpha=alpha, levels=levels, pyramid=pyramid,
        method=method, channel=channel, magnified=magnified, mask=mask, region=region, overwrite=overwrite,
    )  # fmt: skip
    passes = 2 if region is not None else 3
    with progress_bar() as bar:
        task = bar.add_task(
            f"{video.n_frames} frames of {video.shape[0]}x{video.shape[1]}", total=passes * video.n_frames
        )
        done_before = {"stage": None, "frames": 0, "last": 0}

        def progress(stage, done, total):
            if stage != done_before["stage"]:
                done_before["frames"] += done_before["last"]
                done_before["stage"] = stage
            done_before["last"] = done
            bar.update(task, completed=done_before["frames"] + done, description=stage)

        res = write_pulse_analysis(
            video,
            out_dir,
            overwrite=overwrite,
            magnified=magnified,
            progress=progress,
            **opts,
        )
    if json_out:
        print_json(res.to_dict())
        return
    est = res.estimate
    if est.detected:
        out.print(
            f"heart rate {est.rate_bpm:.2f} bpm  (SNR {est.snr_db:.1f} dB, peak SNR {est.band_snr_db:.1f} dB; "
            f"{video.n_frames} frames at {video.fps:g} fps; {out_dir})",
            highlight=False,
        )
    else:
        out.print(
            f"no pulse found  (highest peak {est.peak_bpm:.1f} bpm at peak SNR {est.band_snr_db:.1f} dB < "
            f"{est.settings['min_band_snr_db']:g} dB; {out_dir})",
            highlight=False,
        )


def _pulse_inputs(video_path, out_dir, *, fps, band, rate_band, alpha, levels, pyramid, method, channel, magnified,
                  mask, region, overwrite):  # fmt: skip
    """Every option and output of ``pulse`` checked before any work, the video opened: ``(video, options)``."""
    import numpy as np

    from .._validate import check_number, check_positive
    from ..pulse.rate import parse_region
    from ..pulse.video_io import VIDEO_KIND, check_video_path, open_video

    # every option and output before any work
    if fps is not None:
        check_positive(fps, "--fps")
    opts = {
        "band_hz": _parse_band(band, "--band"),
        "rate_band_hz": _parse_band(rate_band, "--rate-band"),
        "alpha": check_number(alpha, "--alpha", minimum=0.0, maximum=MAX_ALPHA),
        "levels": levels,
        "pyramid": pyramid,
        "method": method,
    }
    if opts["rate_band_hz"][0] <= 0:
        raise ValueError(f"--rate-band must start above 0 Hz, got {rate_band!r}")
    if levels < 0:
        raise ValueError(f"--levels must be an integer >= 0, got {levels}")
    if pyramid not in ("gaussian", "laplacian"):
        raise ValueError(f"--pyramid must be gaussian or laplacian, got {pyramid!r}")
    if method not in ("periodogram", "welch"):
        raise ValueError(f"--method must be periodogram or welch, got {method!r}")
    if channel not in ("gray", "red", "green", "blue"):
        raise ValueError(f"--channel must be one of gray, red, green, blue, got {channel!r}")
    if magnified is not None:
        check_video_path(magnified, "--magnified")
    _check_outputs(
        (out_dir, "pulse report"),
        (magnified, VIDEO_KIND, "--magnified"),
        overwrite=overwrite,
        inputs=[("VIDEO", video_path), ("--mask", mask)],
    )
    with console.status(f"opening {video_path}"):
        video = open_video(video_path, fps=fps, channel=channel)  # the header only: no frame decoded yet
    _check_bands_against(video, {"--band": opts["band_hz"], "--rate-band": opts["rate_band_hz"]})
    from ..pulse.evm import _pyramid_sizes

    try:
        _pyramid_sizes(video.shape, levels)
    except ValueError:
        raise ValueError(
            f"--levels {levels}: too many pyramid levels for {video.shape[0]}x{video.shape[1]} frames"
        ) from None
    if region is not None:
        opts["region"] = parse_region(region, video.shape)
    if mask is not None:
        from ..errors import InputError
        from ..skin.masks import read_vein_mask

        try:
            opts["mask"] = np.asarray(read_vein_mask(mask, video.shape)) > 0
        except InputError as exc:
            raise InputError(f"--mask {str(exc).replace('vein mask', 'mask')}") from None
    _check_pulse_resources(video, out_dir, opts)
    return video, opts


def video_outputs(out_path: Path, method: str, methods) -> tuple[dict, Path]:
    """The videos ``skin video --out OUT --method M`` writes (method -> path) and its vein mask's path.

    The mask is named after the video output, ``STEM_video_vein_mask.png``: never the
    ``STEM_vein_mask.png`` ground truth ``skin simulate --out STEM.zarr`` writes beside a stack.
    """
    paths = {
        m: out_path if method != "all" else out_path.with_name(f"{out_path.stem}_{m}{out_path.suffix}") for m in methods
    }
    return paths, out_path.with_name(f"{out_path.stem}_video_vein_mask.png")


def video(
    out_path: Annotated[
        Path, typer.Option("--out", "-o", help="Video to write: .tif/.tiff (lossless float) or .mp4/.avi/.mkv/.mov.")
    ],
    bpm: Annotated[float, typer.Option(help="Mean heart rate, beats per minute (30-240).")] = 72.0,
    seconds: Annotated[
        float, typer.Option(help="Length of the video (s; at least 8 frames, at most what memory holds).")
    ] = 30.0,
    method: Annotated[
        str, typer.Option(help="indirect, regular, direct, global, or all (one file per method).")
    ] = "indirect",
    fps: Annotated[
        float | None,
        typer.Option(
            help="Camera frame rate (Hz; above twice the heart rate, at most the projector's 75 Hz: one delay "
            "image per sweep; default 75)."
        ),
    ] = None,
    size: Annotated[tuple[int, int], typer.Option(help="Image size H W (at least 8x8, at most what memory holds).")] = (
        48,
        48,
    ),
    projector_rows: Annotated[
        int,
        typer.Option(help="Projector rows the image spans (1-720; 0.3 mm each: 192 = a 58 mm patch of forearm)."),
    ] = 192,
    seed: Annotated[int, typer.Option(help="Seed of the scene, the variability, motion and noise (0 to 2^32-1).")] = 0,
    hrv: Annotated[float, typer.Option(help="Slow heart-rate variability, fraction of the rate (std; 0-0.2).")] = 0.02,
    rsa: Annotated[float, typer.Option(help="Respiratory sinus arrhythmia, fraction of the rate (0-0.3).")] = 0.03,
    breaths_per_min: Annotated[float, typer.Option(help="Breathing rate (4-60 per minute).")] = 15.0,
    pulse_amplitude: Annotated[
        float, typer.Option(help="Vein blood-volume change diastole -> systole (fraction, 0-0.1).")
    ] = 0.02,
    delay_us: Annotated[
        float,
        typer.Option(
            help="Delay of the short-range indirect image (us; its band must reach the skin's 64-row kernel: "
            "|delay| < 1185 + exposure/2)."
        ),
    ] = 450.0,
    exposure_us: Annotated[
        float, typer.Option(help="Row exposure of the delay and direct images (us, > 0 and <= 13,333: one sweep).")
    ] = 600.0,
    motion: Annotated[bool, typer.Option(help="Breathing and arm motion.")] = True,
    ambient: Annotated[bool, typer.Option(help="Ambient light.")] = True,
    noise: Annotated[bool, typer.Option(help="Camera noise.")] = True,
    overwrite: Annotated[
        bool, typer.Option(help="Replace existing videos and their mask (only files planeray wrote).")
    ] = False,
):
    """Simulate a live capture of the pulse in the skin scene and write it as a video (Fig. 15).

    Also writes STEM_video_vein_mask.png, the scene's vein mask (for ``planeray skin pulse --mask``).
    """
    from ..pulse.simulate import METHODS, LiveSettings, simulate_live, skin_builder
    from ..pulse.video_io import VIDEO_KIND, check_video_path

    # every option and output before any work
    methods = METHODS if method == "all" else (method,)
    if method != "all" and method not in METHODS:
        raise ValueError(f"--method must be one of {', '.join(METHODS)} or all, got {method!r}")
    check_video_path(out_path, "--out")
    shape = _bounds.image_size(size)
    _bounds.projector_rows(projector_rows)
    _bounds.seed(seed)
    settings = LiveSettings(
        seconds=seconds,
        fps=fps,
        bpm=bpm,
        hrv=hrv,
        rsa=rsa,
        breaths_per_min=breaths_per_min,
        pulse_amplitude=pulse_amplitude,
        delay_us=delay_us,
        exposure_us=exposure_us,
        ambient=ambient,
        noise=noise,
        **({} if motion else {"breathing_px": 0.0, "breathing_gain": 0.0, "motion_px": 0.0}),
    )
    _check_live_settings(settings, shape, methods, seconds=seconds, delay_us=delay_us, exposure_us=exposure_us)
    paths, mask_path = video_outputs(out_path, method, methods)
    _check_outputs(*((p, VIDEO_KIND) for p in paths.values()), (mask_path, VIDEO_MASK_KIND), overwrite=overwrite)
    with progress_bar() as bar:
        task = bar.add_task("building the skin scene, simulating", total=len(methods))
        cap = simulate_live(
            settings,
            build=skin_builder(shape, seed=seed, projector_rows=projector_rows),
            methods=methods,
            seed=seed,
            progress=lambda i: bar.advance(task),
        )
        task = bar.add_task("writing", total=len(paths) + 1)
        _write_videos(cap, paths, mask_path, overwrite=overwrite, progress=lambda: bar.advance(task))
    for m, p in paths.items():
        v = cap.videos[m]
        out.print(
            f"{p}  ({m}, {v.n_frames} frames at {v.fps:g} fps, {v.shape[0]}x{v.shape[1]}, "
            f"true mean rate {cap.truth['mean_rate_bpm']:.2f} bpm)",
            highlight=False,
        )
    if mask_path.exists():
        out.print(f"{mask_path}  (vein mask)", highlight=False)


def _check_live_settings(settings, shape, methods, *, seconds, delay_us, exposure_us) -> None:
    """The simulated capture's band, memory and length checked before any work (one line naming the option)."""
    from ..scenes.skin import SKIN_BAND_ROWS
    from ..timing import PAPER_LINES_PER_SECOND

    reach_us = SKIN_BAND_ROWS / PAPER_LINES_PER_SECOND * 1e6 + exposure_us / 2.0
    if abs(delay_us) >= reach_us:
        raise ValueError(
            f"--delay-us must put the band on the skin's kernel (|delay| < {reach_us:.0f} us at --exposure-us "
            f"{exposure_us:g}: 64 rows + half the band), got {delay_us:g}"
        )
    _bounds.scene_memory(shape, copies=4)
    fr = settings.frame_rate()
    n = int(round(seconds * fr))
    if n < 8:
        raise ValueError(f"--seconds {seconds:g} at {fr:g} fps is {n} frames; a pulse video needs at least 8")
    _check_live_memory(
        settings, shape, methods, f"--seconds {seconds:g} at {fr:g} fps ({n:,} frames of {shape[0]}x{shape[1]}, "
        f"{len(methods)} method(s))",
    )  # fmt: skip


def _check_live_memory(settings, shape, methods, what: str) -> None:
    """A simulated live capture of ``methods`` at ``shape`` fits in memory (else one line: ``what`` needs more)."""
    from .._validate import check_memory
    from ..pulse.simulate import live_capture_bytes

    check_memory(
        _bounds.BASE_BYTES
        + _bounds.SCENE_BYTES_PER_PIXEL * shape[0] * shape[1] * 4
        + live_capture_bytes(settings, shape, methods),
        what,
        advice="shorten --seconds, lower --fps or --size",
    )


def _write_videos(cap, paths: dict, mask_path: Path, *, overwrite: bool, progress) -> None:
    """The videos and the vein mask, each into a temporary, renamed into place together at the end:
    a failure (disk full, an interruption) leaves none of them behind."""
    import contextlib

    import numpy as np
    from PIL import Image

    from ..io import atomic_file
    from ..io.marks import png_mark_info
    from ..pulse.video_io import encode_video

    vein = cap.model.scene.maps.get("vein_mask")
    with contextlib.ExitStack() as files:
        tmps = {}
        for m, p in paths.items():
            # each video into a hidden sibling first (same suffix: the writer picks its format by it)
            tmps[m] = files.enter_context(atomic_file(p, overwrite=overwrite))
            v = cap.videos[m]
            v.meta = {**v.meta, "true_mean_rate_bpm": cap.truth["mean_rate_bpm"]}
            encode_video(tmps[m], v)
            progress()
        if vein is not None:
            tmp = files.enter_context(atomic_file(mask_path, overwrite=overwrite))
            Image.fromarray((np.asarray(vein, bool) * 255).astype(np.uint8)).save(
                tmp, format="PNG", pnginfo=png_mark_info(VIDEO_MASK_KIND)
            )
        progress()


def pulse_report(
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder to write (report.json + figures).")],
    size: Annotated[tuple[int, int], typer.Option(help="Image size H W (at least 8x8, at most what memory holds).")] = (
        48,
        48,
    ),
    projector_rows: Annotated[int, typer.Option(help="Projector rows the image spans (1-720; 0.3 mm each).")] = 192,
    seconds: Annotated[
        float, typer.Option(help="Length of each video (s; at least 2.9: two periods of 42 bpm).")
    ] = 30.0,
    fps: Annotated[
        float, typer.Option(help="Camera frame rate (Hz; above 7.4 = twice 110 bpm, at most the projector's 75).")
    ] = 30.0,
    quick: Annotated[
        bool,
        typer.Option(help="Fewer rates, seeds and pulse-free videos; one seed per noise condition, three delays."),
    ] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace a report folder planeray wrote.")] = False,
):
    """The simulated pulse study: Fig. 15a/b, rate accuracy over rates and seeds, SNR per method, false alarms."""
    from ..experiments.pulse import QUICK_REPORT, REPORT_RATES_BPM, pulse_report_steps, run_pulse_report
    from ..pulse.evm import DEFAULT_LEVELS, _pyramid_sizes
    from ..pulse.rate import RATE_BAND_HZ
    from ..pulse.simulate import METHODS, LiveSettings

    shape = _bounds.image_size(size)
    try:  # the report magnifies with the paper's pyramid levels
        _pyramid_sizes(shape, DEFAULT_LEVELS)
    except ValueError:
        raise ValueError(
            f"--size must be large enough for {DEFAULT_LEVELS} pyramid levels (at least 12x12), "
            f"got {shape[0]}x{shape[1]}"
        ) from None
    _bounds.projector_rows(projector_rows)
    kw = dict(QUICK_REPORT) if quick else {}
    rates = kw.get("rates_bpm", REPORT_RATES_BPM)
    settings = LiveSettings(seconds=seconds, fps=fps, bpm=max(rates), hrv=0.02, rsa=0.03)
    need = 2.0 / RATE_BAND_HZ[0]
    if seconds < need:
        raise ValueError(
            f"--seconds must be at least {need:.3g} (two periods of the slowest rate searched, "
            f"{RATE_BAND_HZ[0]:g} Hz), got {seconds:g}"
        )
    _bounds.scene_memory(shape, copies=4)
    n = int(round(seconds * fps))
    _check_live_memory(
        settings,
        shape,
        METHODS,
        f"--seconds {seconds:g} at --fps {fps:g} ({n:,} frames of {shape[0]}x{shape[1]}, 4 methods)",
    )
    _check_outputs((out_dir, "pulse report"), overwrite=overwrite)
    with progress_bar() as bar:
        task = bar.add_task("pulse report", total=pulse_report_steps(**kw))
        rep = run_pulse_report(
            out_dir,
            size=shape,
            projector_rows=projector_rows,
            seconds=seconds,
            fps=fps,
            overwrite=overwrite,
            progress=lambda text: bar.update(task, advance=1, description=text),
            **kw,
        )
    acc = rep["accuracy"]

    def bpm(x):
        return "n/a" if x is None else f"{x:.2f}"

    out.print(
        f"rate: {acc['detected']}/{acc['total']} detected, mean |error| {bpm(acc['mean_abs_error_bpm'])} bpm, "
        f"max {bpm(acc['max_abs_error_bpm'])} bpm; SNR (dB) "
        + ", ".join(f"{m} {v['snr_db']:.1f}" for m, v in rep["methods"].items())
        + f"; pulse-free false alarms {rep['pulse_free']['false_alarms']}/{len(rep['pulse_free']['runs'])}; {out_dir}",
        highlight=False,
    )
