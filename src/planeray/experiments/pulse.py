"""Pulse from short-range indirect light (Sec. 10, Fig. 15): one video's analysis, and the simulated study.

* :func:`write_pulse_analysis` -- ``planeray skin pulse VIDEO --out DIR``: magnify, find the rate,
  write ``pulse.json``, ``signal.csv``, ``spectrum.csv``, ``fig15a_pulse.png`` and ``region.png``.
* :func:`run_pulse_report` -- ``planeray skin pulse-report --out DIR``: simulated live captures of
  the skin scene in regular, direct, global and indirect light; Fig. 15a/15b, the heart-rate
  accuracy over rates and seeds, the pulse SNR of each method, pulse-free videos (false alarms),
  the frequency resolution of a 480-frame window, and the linearization error.
"""

from __future__ import annotations

import csv
import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..io import atomic_directory, jsonable
from ..io.atomic import MARKER
from ..pulse.analysis import analyze_pulse
from ..pulse.rate import estimate_heart_rate, pulse_spectrum
from ..pulse.simulate import METHODS, LiveSettings, linearize, simulate_live, skin_builder
from ..pulse.waveform import cardiac_signal

__all__ = [
    "ANALYSIS_FORMAT",
    "REPORT_FORMAT",
    "QUICK_REPORT",
    "write_pulse_analysis",
    "resolution_study",
    "false_alarm_study",
    "delay_study",
    "noise_study",
    "run_pulse_report",
    "pulse_report_steps",
    "REPORT_RATES_BPM",
]

#: ``format`` of the ``planeray.json`` of an analysis folder / a report folder.
ANALYSIS_FORMAT = "planeray-pulse-report"
REPORT_FORMAT = "planeray-pulse-report"

#: Conditions of :func:`noise_study`.
NOISE_CONDITIONS = {
    "camera noise only": {"motion_px": 0.0, "breathing_px": 0.0, "breathing_gain": 0.0, "laser_flicker": 0.0},
    "defaults": {},
    "laser flicker 0.2 %": {"laser_flicker": 0.002},
}
NOISE_SEEDS = (0, 1)
#: Delays and exposures of :func:`delay_study`.
DELAY_STUDY_US = (0, 150, 250, 350, 450, 550)
DELAY_STUDY_EXPOSURES_US = (300, 600)
#: Rates, seeds and pulse-free seeds of :func:`run_pulse_report`.
REPORT_RATES_BPM = (50, 60, 70, 80, 90, 100, 110)
REPORT_SEEDS = (0, 1, 2)
REPORT_NULL_SEEDS = range(10)
#: ``skin pulse-report --quick`` (and ``planeray paper --quick``): three rates, one seed, three pulse-free videos,
#: one seed per noise condition, three delays at the longer exposure.
QUICK_REPORT = {
    "rates_bpm": (50, 80, 110),
    "seeds": (0,),
    "null_seeds": range(3),
    "null_runs": 100,
    "noise_seeds": (0,),
    "delays_us": (0, 250, 550),
    "exposures_us": (600,),
}


def _write_csv(path: Path, header, rows) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)


def _region_png(path: Path, mean_frame, region) -> None:
    from ..figures._common import new_figure, save_png

    mean = np.asarray(mean_frame)
    fig = new_figure((4.2, 4.2 * mean.shape[0] / mean.shape[1] + 0.4))
    ax = fig.subplots()
    lo, hi = np.percentile(mean, [0.5, 99.5])
    ax.imshow(mean, cmap="gray", vmin=lo, vmax=hi if hi > lo else lo + 1)
    ax.contour(region.astype(float), levels=[0.5], colors="tab:red", linewidths=1)
    ax.set_title("mean frame, pulse region (red)", fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.tight_layout()
    save_png(fig, path, dpi=110)


#: The folder, inside the result's temporary, where ``skin pulse`` keeps what does not fit in memory.
SCRATCH_FOLDER = ".scratch"


def write_pulse_analysis(
    video, out_dir, *, overwrite: bool = False, truth_bpm=None, magnified=None, progress=None, **options
):
    """Analyse ``video`` (:func:`planeray.pulse.analysis.analyze_pulse` with ``options``) and write ``out_dir``.

    ``video`` is a :class:`~planeray.pulse.video_io.Video` or a :class:`~planeray.pulse.video_io.VideoFile`
    (read frame by frame: the analysis holds a bounded amount of memory and keeps the rest in temporary
    files inside the result folder's own temporary, removed with it whatever happens).
    ``magnified``: also write the magnified video to this file, frame by frame as the analysis makes
    them (:func:`planeray.pulse.video_io.encode_frames`; 8-bit formats show the video's 99.9th percentile
    as white).  Both outputs are checked before any work and go into place together at the end (a
    failure leaves neither).  ``progress``: see :func:`~planeray.pulse.analysis.analyze_pulse`.
    Returns the :class:`~planeray.pulse.analysis.PulseAnalysis`.
    """
    import contextlib
    import shutil

    from ..figures.pulse import pulse_signal_figure
    from ..io import atomic_file
    from ..io.atomic import check_replaceable
    from ..pulse.video_io import VIDEO_KIND, FramePercentile, check_video_path, encode_frames

    check_replaceable(out_dir, overwrite=overwrite, kind="pulse report")
    if magnified is not None:
        check_video_path(magnified, "magnified")
        check_replaceable(magnified, overwrite=overwrite, kind=VIDEO_KIND)
    with contextlib.ExitStack() as outputs:
        mag_tmp = white = None
        if magnified is not None:  # renamed into place after the folder
            mag_tmp = outputs.enter_context(atomic_file(magnified, overwrite=overwrite))
            if Path(magnified).suffix.lower() not in (".tif", ".tiff"):
                white = FramePercentile(99.9, video.n_frames * video.shape[0] * video.shape[1])
        tmp = outputs.enter_context(atomic_directory(out_dir, overwrite=overwrite, kind="pulse report"))
        scratch = tmp / SCRATCH_FOLDER
        scratch.mkdir()

        def write_magnified(frames, n_frames, settings):
            encode_frames(
                mag_tmp,
                frames,
                n_frames=n_frames,
                shape=video.shape,
                fps=video.fps,
                meta={"magnified": settings},
                white=white.value() if white is not None else 1.0,
                suffix=Path(magnified).suffix,
            )

        result = analyze_pulse(
            video,
            scratch_dir=scratch,
            observe=white.add if white is not None else None,
            write_magnified=write_magnified if magnified is not None else None,
            progress=progress,
            **options,
        )
        shutil.rmtree(scratch)
        meta = {
            "format": ANALYSIS_FORMAT,
            "format_version": 1,
            "kind": "analysis",
            "video": video.source,
            "fps": video.fps,
            "frames": video.n_frames,
            "size": list(video.shape),
        }
        _write_analysis_folder(tmp, result, meta, truth_bpm, pulse_signal_figure)
    return result


def _write_analysis_folder(tmp, result, meta, truth_bpm, pulse_signal_figure) -> None:
    """The files of a ``skin pulse`` result folder, written into ``tmp``."""
    (tmp / "pulse.json").write_text(json.dumps({**meta, **result.to_dict()}, indent=1, default=float))
    _write_csv(
        tmp / "signal.csv",
        ["time_s", "raw", "magnified"],
        [[f"{t:.6f}", f"{r:.8g}", f"{s:.8g}"] for t, r, s in zip(result.time_s, result.raw_signal, result.signal)],
    )
    est = result.estimate
    _write_csv(
        tmp / "spectrum.csv",
        ["frequency_hz", "bpm", "power"],
        [[f"{f:.6f}", f"{60 * f:.4f}", f"{p:.6g}"] for f, p in zip(est.freqs_hz, est.power)],
    )
    pulse_signal_figure(
        result.time_s, result.signal, est, raw=result.raw_signal, truth_bpm=truth_bpm, out=tmp / "fig15a_pulse.png"
    )
    _region_png(tmp / "region.png", result.mean_frame, result.region)
    (tmp / MARKER).write_text(json.dumps(meta, indent=1))


def false_alarm_study(*, fps: float = 30.0, seconds=(16.0, 20.0, 30.0), runs: int = 1000, breathing: float = 3.0):
    """How often pulse-free signals (white noise plus breathing ``breathing`` times its std) report a rate.

    Returns, per record length, the percentiles of the peak SNR (rate band) and the share of runs
    at or above :data:`planeray.pulse.rate.MIN_BAND_SNR_DB` (the false-alarm rate).
    """
    from ..pulse.rate import MIN_BAND_SNR_DB
    from ..pulse.waveform import breathing_signal

    out = {"threshold_db": MIN_BAND_SNR_DB, "runs": int(runs), "by_seconds": {}}
    for secs in seconds:
        n = int(round(secs * fps))
        signals = np.empty((int(runs), n))
        for seed in range(int(runs)):
            rng = np.random.default_rng(seed)
            signals[seed] = rng.standard_normal(n) + breathing * breathing_signal(
                n, fps, breaths_per_min=12 + 8 * rng.random(), seed=seed
            )
        freqs, power = pulse_spectrum(signals, fps)  # every run's spectrum in one call
        vals = np.array([estimate_heart_rate(x, fps, spectrum=(freqs, p)).band_snr_db for x, p in zip(signals, power)])
        out["by_seconds"][f"{secs:g}"] = {
            "p50_db": float(np.percentile(vals, 50)),
            "p99_db": float(np.percentile(vals, 99)),
            "max_db": float(vals.max()),
            "false_alarm_rate": float(np.mean(vals >= MIN_BAND_SNR_DB)),
        }
    return out


def resolution_study(*, fps: float = 30.0, frames: int = 480, rates_bpm=None, seeds=range(5), noise: float = 0.1):
    """Heart-rate error of a plain periodogram (largest bin) against zero-padding + peak interpolation.

    Synthetic PPG signals (:func:`planeray.pulse.waveform.cardiac_signal`, no variability) plus white
    noise of ``noise`` times the pulse's peak-to-peak amplitude, ``frames`` samples at ``fps``.
    Returns the mean and largest absolute error (bpm) of each estimator and the bin spacing.
    """
    rates = np.linspace(50.0, 110.0, 61) if rates_bpm is None else np.asarray(rates_bpm, float)
    errs = {"bin": [], "zero-padded x8": [], "zero-padded x8 + interpolation": [], "interpolation only": []}
    for seed in seeds:
        rng = np.random.default_rng(seed)
        signals = np.array(
            [
                cardiac_signal(frames, fps, bpm=bpm, seed=seed).volume + noise * rng.standard_normal(frames)
                for bpm in rates
            ]
        )
        # each spectrum shared by two estimators; every rate's in one call
        spectra = {pad: pulse_spectrum(signals, fps, pad=pad) for pad in (1, 8)}
        for i, (x, truth) in enumerate(zip(signals, rates)):
            for key, kw in (
                ("bin", {"pad": 1, "interpolate": False}),
                ("zero-padded x8", {"pad": 8, "interpolate": False}),
                ("zero-padded x8 + interpolation", {"pad": 8, "interpolate": True}),
                ("interpolation only", {"pad": 1, "interpolate": True}),
            ):
                freqs, power = spectra[kw["pad"]]
                est = estimate_heart_rate(x, fps, min_band_snr_db=-np.inf, spectrum=(freqs, power[i]), **kw)
                errs[key].append(abs(est.peak_bpm - truth))
    return {
        "fps": fps,
        "frames": frames,
        "window_s": frames / fps,
        "bin_bpm": 60.0 * fps / frames,
        "noise": noise,
        "error_bpm": {k: {"mean": float(np.mean(v)), "max": float(np.max(v))} for k, v in errs.items()},
    }


def _vein_region(scene, shape):
    """The veins' cores (the vein mask eroded by one pixel; the mask itself where that leaves nothing)."""
    from scipy.ndimage import binary_erosion

    mask = scene.maps.get("vein_mask") if scene.maps else None
    if mask is None or not np.any(mask):
        return None
    core = binary_erosion(np.asarray(mask, bool))
    return core if core.any() else np.asarray(mask, bool)


def delay_study(
    build, *, delays_us=DELAY_STUDY_US, exposures_us=DELAY_STUDY_EXPOSURES_US, amplitude=0.02, progress=None
):
    """Per delay and exposure, on the veins' cores: the indirect image's level, its pulsatile fraction, ambient/laser.

    ``fom`` is the shot-noise-limited pulse figure of merit per sensor pixel of the default camera,
    ``pulse electrons / sqrt(all electrons)`` (laser + ambient over the row exposure).  ``progress``:
    called with a description after each scene linearized (``len(delays_us) * len(exposures_us) + 1``).
    """
    from ..camera import CameraModel

    cam = CameraModel()
    rows = []
    region = None
    for te in exposures_us:
        for d in delays_us:
            m = linearize(build, delay_us=d, exposure_us=te, check_amplitude=None)
            region = _vein_region(m.scene, None) if region is None else region
            level = float(m.images["indirect"][region].mean())
            pulse = amplitude * float(m.derivatives["indirect"][region].mean())
            laser = cam.laser_electrons * level
            amb = cam.ambient_e_per_us * te * float(m.scene.ambient_albedo[region].mean())
            rows.append(
                {
                    "delay_us": d,
                    "exposure_us": te,
                    "level": level,
                    "pulsatile_pct": 100 * pulse / level if level else 0.0,
                    "ambient_over_laser": amb / laser if laser else float("inf"),
                    "fom": abs(pulse) * cam.laser_electrons / np.sqrt(laser + amb),
                }
            )
            if progress is not None:
                progress(f"delay study: {d:g} us, {te:g} us")
    m = linearize(build, check_amplitude=None)
    if progress is not None:
        progress("delay study: regular light")
    lvl = float(m.images["regular"][region].mean())
    laser = cam.laser_electrons * lvl
    amb = cam.ambient_e_per_us * 720 / 54000 * 1e6 * float(m.scene.ambient_albedo[region].mean())
    pulse = amplitude * float(m.derivatives["regular"][region].mean())
    regular = {
        "level": lvl,
        "pulsatile_pct": 100 * pulse / lvl,
        "ambient_over_laser": amb / laser,
        "fom": abs(pulse) * cam.laser_electrons / np.sqrt(laser + amb),
    }
    return {"indirect": rows, "regular": regular}


def noise_study(model, base, *, seeds=NOISE_SEEDS, progress=None) -> dict:
    """Pulse SNR of each method (veins' cores, mean over seeds) under shot noise only, the defaults, strong flicker.

    ``progress``: called with a description after each capture (``len(NOISE_CONDITIONS) * len(seeds)``).
    """
    region = _vein_region(model.scene, None)
    out = {}
    for name, kw in NOISE_CONDITIONS.items():
        snr = {m: [] for m in METHODS}
        for sd in seeds:
            c = simulate_live(LiveSettings(**{**asdict(base), **kw}), model=model, seed=int(sd))
            t = c.truth["mean_rate_bpm"]
            for m in METHODS:
                snr[m].append(analyze_pulse(c.videos[m], region=region, reference_bpm=t).estimate.snr_db)
            if progress is not None:
                progress(f"noise study: {name}, seed {sd}")
        out[name] = {m: float(np.mean(v)) for m, v in snr.items()}
    return out


def pulse_report_steps(
    *,
    rates_bpm=REPORT_RATES_BPM,
    seeds=REPORT_SEEDS,
    null_seeds=REPORT_NULL_SEEDS,
    null_runs=None,
    noise_seeds=NOISE_SEEDS,
    delays_us=DELAY_STUDY_US,
    exposures_us=DELAY_STUDY_EXPOSURES_US,
) -> int:
    """Progress steps :func:`run_pulse_report` reports: the scene, Fig. 15, every rate x seed, every
    pulse-free video, the noise and delay studies' captures, the synthetic studies, the figures."""
    del null_runs  # the synthetic false-alarm study is one step whatever its runs
    return (
        2
        + len(rates_bpm) * len(seeds)
        + len(null_seeds)
        + len(NOISE_CONDITIONS) * len(noise_seeds)
        + len(delays_us) * len(exposures_us)
        + 1  # the delay study's regular light
        + 2  # the resolution study at two noise levels
        + 1  # the synthetic false-alarm study
        + 1  # the figures written
    )


def run_pulse_report(
    out_dir,
    *,
    size=(48, 48),
    projector_rows: int = 192,
    seconds: float = 30.0,
    fps: float = 30.0,
    bpm: float = 72.0,
    rates_bpm=REPORT_RATES_BPM,
    seeds=REPORT_SEEDS,
    null_seeds=REPORT_NULL_SEEDS,
    null_runs: int = 1000,
    noise_seeds=NOISE_SEEDS,
    delays_us=DELAY_STUDY_US,
    exposures_us=DELAY_STUDY_EXPOSURES_US,
    seed: int = 0,
    scene_params: dict | None = None,
    build=None,
    overwrite: bool = False,
    progress=None,
) -> dict:
    """Simulate, magnify and measure; write the numbers (``report.json``) and figures to ``out_dir``.

    ``build``: ``build(blood_scale) -> Scene`` (default: the skin scene at ``size``, :func:`skin_builder`).
    ``progress``: called with a short description after each step (:func:`pulse_report_steps` in all).
    Checks ``out_dir`` before any work.
    """
    from ..io.atomic import check_replaceable

    check_replaceable(out_dir, overwrite=overwrite, kind="pulse report")
    from ..figures.pulse import pulse_methods_figure, pulse_signal_figure, rate_accuracy_figure

    def step(text):
        if progress:
            progress(text)

    build = build or skin_builder(tuple(size), seed=seed, projector_rows=projector_rows, **(scene_params or {}))
    base = LiveSettings(seconds=seconds, fps=fps, bpm=bpm, hrv=0.02, rsa=0.03)
    model = linearize(build, delay_us=base.delay_us, exposure_us=base.exposure_us)
    step("scene linearized")
    vein = _vein_region(model.scene, size)
    report = {
        "settings": asdict(base),
        "linearity_error": model.linearity_error,
        "scene": model.scene.params,
    }
    # Fig. 15a/b: one capture, the four methods on the same vein pixels
    cap = simulate_live(base, model=model, seed=seed)
    truth = cap.truth["mean_rate_bpm"]
    signals, snrs, per_method = {}, {}, {}
    region = vein if vein is not None else analyze_pulse(cap.videos["indirect"]).region
    for m in METHODS:
        res = analyze_pulse(cap.videos[m], region=region, reference_bpm=truth)
        per_method[m] = {
            "rate_bpm": res.estimate.rate_bpm,
            "snr_db": res.estimate.snr_db,
            "snr_db_without_magnification": res.estimate_raw.snr_db,
            "pulsatile_fraction_pct": _pulsatile_pct(model, m, region, base.pulse_amplitude),
        }
        signals[m] = res.signal
        snrs[m] = res.estimate.snr_db
        if m == "indirect":
            core = res
    signals["indirect (no magnification)"] = core.raw_signal
    snrs["indirect (no magnification)"] = core.estimate_raw.snr_db
    # Fig. 15a: the pulse region found automatically on the vein mask, as `planeray skin pulse --mask` does
    fig_a = analyze_pulse(cap.videos["indirect"], mask=model.scene.maps.get("vein_mask"), reference_bpm=None)
    report["fig15a"] = {"region_pixels": int(fig_a.region.sum()), **fig_a.estimate.to_dict()}
    report["methods"] = per_method
    report["true_mean_rate_bpm"] = truth
    step("four methods analysed")
    # accuracy over rates and seeds, from the indirect video
    rows = []
    for r in rates_bpm:
        for sd in seeds:
            s = LiveSettings(**{**base.__dict__, "bpm": float(r)})
            c = simulate_live(s, model=model, seed=int(sd), methods=("indirect",))
            res = analyze_pulse(c.videos["indirect"], mask=c.model.scene.maps.get("vein_mask"))
            t = c.truth["mean_rate_bpm"]
            rows.append(
                {"true_bpm": t, "seed": int(sd), "rate_bpm": res.estimate.rate_bpm, "snr_db": res.estimate.snr_db}
            )
            step(f"rate {r} bpm, seed {sd}")
    errs = [abs(r["rate_bpm"] - r["true_bpm"]) for r in rows if r["rate_bpm"] is not None]
    report["accuracy"] = {
        "runs": rows,
        "detected": sum(r["rate_bpm"] is not None for r in rows),
        "total": len(rows),
        "mean_abs_error_bpm": float(np.mean(errs)) if errs else None,
        "max_abs_error_bpm": float(np.max(errs)) if errs else None,
    }
    # pulse-free videos: no rate may be reported
    null = []
    for sd in null_seeds:
        s = LiveSettings(**{**base.__dict__, "pulse_amplitude": 0.0})
        c = simulate_live(s, model=model, seed=1000 + int(sd), methods=("indirect",))
        res = analyze_pulse(c.videos["indirect"], mask=c.model.scene.maps.get("vein_mask"))
        null.append({"seed": int(sd), "rate_bpm": res.estimate.rate_bpm, "band_snr_db": res.estimate.band_snr_db})
        step(f"pulse-free video {sd}")
    report["pulse_free"] = {
        "runs": null,
        "false_alarms": sum(r["rate_bpm"] is not None for r in null),
        "max_band_snr_db": float(max(r["band_snr_db"] for r in null)) if null else None,
    }
    report["noise_study"] = noise_study(model, base, seeds=noise_seeds, progress=step)
    report["delay_study"] = delay_study(build, delays_us=delays_us, exposures_us=exposures_us, progress=step)
    report["resolution"] = {}
    for nz in (0.1, 0.5):
        report["resolution"][f"noise {nz:g}"] = resolution_study(fps=fps, noise=nz)
        step(f"resolution study, noise {nz:g}")
    report["false_alarms_synthetic"] = false_alarm_study(fps=fps, runs=null_runs)
    step("false-alarm study")
    with atomic_directory(out_dir, overwrite=overwrite, kind="pulse report") as tmp:
        pulse_signal_figure(
            fig_a.time_s,
            fig_a.signal,
            fig_a.estimate,
            raw=fig_a.raw_signal,
            truth_bpm=truth,
            title="Pulse from short-range indirect light (simulated, Fig. 15a)",
            out=tmp / "fig15a_pulse.png",
        )
        pulse_methods_figure(fig_a.time_s, signals, snr_db=snrs, out=tmp / "fig15b_methods.png")
        rate_accuracy_figure(
            [r["true_bpm"] for r in rows],
            {"indirect, magnified": [np.nan if r["rate_bpm"] is None else r["rate_bpm"] for r in rows]},
            out=tmp / "rate_accuracy.png",
        )
        (tmp / "report.json").write_text(json.dumps(jsonable(report, finite=False, default=str), indent=1))
        (tmp / MARKER).write_text(json.dumps({"format": REPORT_FORMAT, "format_version": 1, "kind": "report"}))
    step("figures written")
    return report


def _pulsatile_pct(model, method, region, amplitude) -> float:
    """Systolic change of a method's laser light on ``region``, percent of its diastolic level (no ambient, no noise)."""
    if method == "global":
        image = model.images["regular"] - model.images["direct"]
        deriv = model.derivatives["regular"] - model.derivatives["direct"]
    else:
        image, deriv = model.images[method], model.derivatives[method]
    level = float(image[region].mean())
    return 100.0 * amplitude * float(deriv[region].mean()) / level if level else 0.0
