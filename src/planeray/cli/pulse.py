"""``planeray skin pulse | video | pulse-report``: the pulse from a video with Eulerian magnification (Sec. 10, Fig. 15)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._console import console, out, print_json, progress_bar


def _parse_band(text: str, name: str) -> tuple[float, float]:
    parts = str(text).replace(",", " ").replace("-", " ").split()
    try:
        lo, hi = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"{name} expects LOW,HIGH in Hz (e.g. 0.5,2), got {text!r}") from None
    return lo, hi


def pulse(
    video_path: Annotated[Path, typer.Argument(help="Video: multi-page TIFF, folder of frames, mp4/avi/mkv/mov.")],
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder to write (pulse.json, CSVs, figures).")],
    fps: Annotated[
        float | None, typer.Option(help="Frame rate (Hz); required when the file has none, overrides it otherwise.")
    ] = None,
    region: Annotated[
        str | None,
        typer.Option(help="ROW,COL (a pixel) or R0,C0,R1,C1 (a box, end exclusive); default: found automatically."),
    ] = None,
    mask: Annotated[
        Path | None,
        typer.Option(help="PNG/TIFF mask (non-zero = search here, e.g. a vein mask) for the automatic region."),
    ] = None,
    band: Annotated[str, typer.Option(help="Temporal pass band of the magnification, Hz.")] = "0.5,2",
    alpha: Annotated[float, typer.Option(help="Amplification (gain applied to the band-passed video).")] = 50.0,
    levels: Annotated[int, typer.Option(help="Spatial pyramid levels.")] = 4,
    pyramid: Annotated[str, typer.Option(help="gaussian (colour magnification) or laplacian.")] = "gaussian",
    rate_band: Annotated[str, typer.Option(help="Where the heart rate is searched, Hz.")] = "0.7,2",
    method: Annotated[str, typer.Option(help="Spectrum: periodogram or welch.")] = "periodogram",
    channel: Annotated[str, typer.Option(help="Colour videos: gray, red, green or blue.")] = "gray",
    magnified: Annotated[
        Path | None, typer.Option(help="Also write the magnified video here (.mp4 to watch, .tif lossless).")
    ] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the result as JSON on stdout.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace a result folder planeray wrote.")] = False,
):
    """Magnify a video (Eulerian, Wu et al. 2012) and measure the heart rate and its SNR (Fig. 15a)."""
    import numpy as np

    from ..experiments.pulse import write_pulse_analysis
    from ..io.atomic import check_replaceable
    from ..pulse.rate import parse_region
    from ..pulse.video_io import read_video

    check_replaceable(out_dir, overwrite=overwrite, kind="pulse report")
    if magnified is not None and magnified.exists() and not overwrite:
        from ..errors import InputError
        from ..io.atomic import ALREADY_EXISTS

        raise InputError(ALREADY_EXISTS, magnified)
    with console.status(f"reading {video_path}"):
        video = read_video(video_path, fps=fps, channel=channel)
    opts = {
        "band_hz": _parse_band(band, "--band"),
        "rate_band_hz": _parse_band(rate_band, "--rate-band"),
        "alpha": alpha,
        "levels": levels,
        "pyramid": pyramid,
        "method": method,
    }
    if region is not None:
        opts["region"] = parse_region(region, video.shape)
    if mask is not None:
        from ..materials.labels import read_label_image

        opts["mask"] = np.asarray(read_label_image(mask, shape=video.shape)) > 0
    with console.status(f"magnifying {video.n_frames} frames of {video.shape[0]}x{video.shape[1]}"):
        res = write_pulse_analysis(video, out_dir, overwrite=overwrite, keep_video=magnified is not None, **opts)
    if magnified is not None:
        from ..pulse.video_io import Video, write_video

        mag = Video(res.magnified, video.fps, str(video_path), {"magnified": res.settings})
        write_video(magnified, mag, overwrite=overwrite, white=float(np.percentile(video.frames, 99.9)))
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


def video(
    out_path: Annotated[
        Path, typer.Option("--out", "-o", help="Video to write: .tif (lossless float) or .mp4/.avi/.mkv.")
    ],
    bpm: Annotated[float, typer.Option(help="Mean heart rate, beats per minute.")] = 72.0,
    seconds: Annotated[float, typer.Option(help="Length of the video.")] = 30.0,
    method: Annotated[
        str, typer.Option(help="indirect, regular, direct, global, or all (one file per method).")
    ] = "indirect",
    fps: Annotated[float | None, typer.Option(help="Camera frame rate (default: the projector's, 75 Hz).")] = None,
    size: Annotated[tuple[int, int], typer.Option(help="Image size H W.")] = (48, 48),
    projector_rows: Annotated[
        int, typer.Option(help="Projector rows the image spans (0.3 mm each: 192 = a 58 mm patch of forearm).")
    ] = 192,
    seed: Annotated[int, typer.Option(help="Seed of the scene, the variability, motion and noise.")] = 0,
    hrv: Annotated[float, typer.Option(help="Slow heart-rate variability, fraction of the rate (std).")] = 0.02,
    rsa: Annotated[float, typer.Option(help="Respiratory sinus arrhythmia, fraction of the rate.")] = 0.03,
    breaths_per_min: Annotated[float, typer.Option(help="Breathing rate.")] = 15.0,
    pulse_amplitude: Annotated[
        float, typer.Option(help="Vein blood-volume change diastole -> systole (fraction).")
    ] = 0.02,
    delay_us: Annotated[float, typer.Option(help="Delay of the short-range indirect image.")] = 450.0,
    exposure_us: Annotated[float, typer.Option(help="Row exposure of the delay and direct images.")] = 600.0,
    motion: Annotated[bool, typer.Option(help="Breathing and arm motion.")] = True,
    ambient: Annotated[bool, typer.Option(help="Ambient light.")] = True,
    noise: Annotated[bool, typer.Option(help="Camera noise.")] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing file.")] = False,
):
    """Simulate a live capture of the pulse in the skin scene and write it as a video (Fig. 15).

    Also writes STEM_vein_mask.png, the scene's vein mask (for ``planeray skin pulse --mask``).
    """
    import numpy as np

    from ..errors import InputError
    from ..io.atomic import ALREADY_EXISTS
    from ..pulse.simulate import METHODS, LiveSettings, simulate_live, skin_builder
    from ..pulse.video_io import write_video

    methods = METHODS if method == "all" else (method,)
    if method != "all" and method not in METHODS:
        raise InputError(f"--method must be one of {', '.join(METHODS)} or all, got {method!r}")
    paths = {
        m: out_path if method != "all" else out_path.with_name(f"{out_path.stem}_{m}{out_path.suffix}") for m in methods
    }
    mask_path = out_path.with_name(f"{out_path.stem}_vein_mask.png")
    for p in [*paths.values(), mask_path]:
        if p.exists() and not overwrite:
            raise InputError(ALREADY_EXISTS, p)
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
    with progress_bar() as bar:
        task = bar.add_task("building the skin scene, simulating", total=len(methods))
        cap = simulate_live(
            settings,
            build=skin_builder(tuple(size), seed=seed, projector_rows=projector_rows),
            methods=methods,
            seed=seed,
            progress=lambda i: bar.advance(task),
        )
    vein = cap.model.scene.maps.get("vein_mask")
    if vein is not None:
        from PIL import Image

        from ..io import atomic_file

        with atomic_file(mask_path, overwrite=overwrite) as tmp:
            Image.fromarray((np.asarray(vein, bool) * 255).astype(np.uint8)).save(tmp, format="PNG")
    for m, p in paths.items():
        v = cap.videos[m]
        v.meta = {**v.meta, "true_mean_rate_bpm": cap.truth["mean_rate_bpm"]}
        write_video(p, v, overwrite=overwrite)
        out.print(
            f"{p}  ({m}, {v.n_frames} frames at {v.fps:g} fps, {v.shape[0]}x{v.shape[1]}, "
            f"true mean rate {cap.truth['mean_rate_bpm']:.2f} bpm)",
            highlight=False,
        )
    if vein is not None:
        out.print(f"{mask_path}  (vein mask)", highlight=False)


def pulse_report(
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder to write (report.json + figures).")],
    size: Annotated[tuple[int, int], typer.Option(help="Image size H W.")] = (48, 48),
    projector_rows: Annotated[int, typer.Option(help="Projector rows the image spans (0.3 mm each).")] = 192,
    seconds: Annotated[float, typer.Option(help="Length of each video.")] = 30.0,
    fps: Annotated[float, typer.Option(help="Camera frame rate.")] = 30.0,
    quick: Annotated[bool, typer.Option(help="Fewer rates, seeds and pulse-free videos.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace a report folder planeray wrote.")] = False,
):
    """The simulated pulse study: Fig. 15a/b, rate accuracy over rates and seeds, SNR per method, false alarms."""
    from ..experiments.pulse import run_pulse_report
    from ..io.atomic import check_replaceable

    check_replaceable(out_dir, overwrite=overwrite, kind="pulse report")
    kw = {"rates_bpm": (50, 80, 110), "seeds": (0,), "null_seeds": range(3), "null_runs": 100} if quick else {}
    with console.status("pulse report") as status:
        rep = run_pulse_report(
            out_dir,
            size=size,
            projector_rows=projector_rows,
            seconds=seconds,
            fps=fps,
            overwrite=overwrite,
            progress=status.update,
            **kw,
        )
    acc = rep["accuracy"]
    out.print(
        f"rate: {acc['detected']}/{acc['total']} detected, mean |error| {acc['mean_abs_error_bpm']:.2f} bpm, "
        f"max {acc['max_abs_error_bpm']:.2f} bpm; SNR (dB) "
        + ", ".join(f"{m} {v['snr_db']:.1f}" for m, v in rep["methods"].items())
        + f"; pulse-free false alarms {rep['pulse_free']['false_alarms']}/{len(rep['pulse_free']['runs'])}; {out_dir}",
        highlight=False,
    )
