"""The whole paper from one command (``planeray paper``): one step per experiment, resumable.

Every step calls the code of the figure's own command -- :mod:`planeray.experiments.paper`
(``planeray figure``), :func:`planeray.baselines.compare_emulation` (``planeray emulate``),
:func:`~planeray.experiments.study.run_study` (``planeray study demux``),
:func:`~planeray.experiments.materials.run_materials_report` (``planeray materials report``),
:func:`~planeray.experiments.skin.run_skin_compare` (``planeray skin compare``) and
:func:`~planeray.experiments.pulse.run_pulse_report` (``planeray skin pulse-report``) -- with
the settings :func:`step_settings` gives, and writes into its own folder ``DIR/STEP/``.  A step
that yields several figures at once (the Sec. 5.2 study: Figs. 5 and 6; the skin study: Figs.
13, 14 and 16) is one step.

Resuming.  ``DIR/planeray.json`` is the manifest: the options, the settings of every step,
planeray's version and :func:`inputs_digest` (a BLAKE2b digest of planeray's sources and
shipped data: what the numbers are computed from), and the steps done.  A step's folder is
written into a temporary sibling and renamed into place (:func:`planeray.io.atomic_directory`),
then the manifest records it as done; a killed run started again with the same options and
inputs continues with the steps not done; other options or inputs are refused
(``overwrite=True`` starts again).  Last come ``numbers.json`` (per figure, the numbers
measured), ``report.md`` and ``report.html`` (:mod:`planeray.experiments.paper_report`).
"""

from __future__ import annotations

import hashlib
import json
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from .._extras import import_extra
from .._validate import check_integer
from ..errors import InputError
from ..io import atomic_directory, atomic_file, jsonable
from ..io.atomic import MARKER, check_replaceable, planeray_output_kind, storage_error
from ..io.lock import writes_output

__all__ = [
    "FORMAT",
    "STEP_FORMAT",
    "STEPS",
    "Step",
    "step_settings",
    "step_work",
    "inputs_digest",
    "plan_paper_run",
    "run_paper",
    "MIN_SIZE",
    "MAX_SIZE",
]

FORMAT = "planeray-paper"
STEP_FORMAT = "planeray-paper-step"
#: Smallest and largest ``--size`` (the materials and skin studies need 16 pixels; labels are clamped to 64..256).
MIN_SIZE, MAX_SIZE = 16, 1024
#: The scene and band of Fig. 4 (the direct image, as the paper compares: "the direct images with and without synchronization").
FIG4_SCENE, FIG4_DELAY_US, FIG4_EXPOSURE_US = "disco_ball", 0.0, 600.0


@dataclass(frozen=True)
class Step:
    """One step of ``planeray paper``.

    ``figures``: the keys of ``numbers.json`` it yields; ``run(folder, settings, advance)``
    writes into ``folder`` and returns ``{figure key: {"measured": {...}, "figures": [PNG paths
    relative to the folder]}}``; ``work(settings)`` is the number of units ``advance`` receives;
    ``command(settings)`` is the command that regenerates it alone.
    """

    name: str
    figures: tuple
    title: str
    run: Callable
    work: Callable
    command: Callable


# --- settings ------------------------------------------------------------------------------------
_QUICK = {
    "fig4": {"size": 32},
    "study": {"quick": True, "seeds": 2},
    "fig8": {"size": 32},
    "fig9": {"size": 32},
    "fig10": {"size": 32, "quick": True},
    "fig11": {"size": 48},
    "fig12": {"size": 48},
    "skin": {"size": 32, "quick": True},
    "fig15": {"size": 48, "projector_rows": 192, "quick": True},
    "labels": {"size": 64},
}
_FULL = {
    "fig4": {"size": 128},
    "study": {"quick": False, "seeds": 5},
    "fig8": {"size": 128},
    "fig9": {"size": 128},
    "fig10": {"size": 128, "quick": False},
    "fig11": {"size": 128},
    "fig12": {"size": 128},
    "skin": {"size": 128, "quick": False},
    "fig15": {"size": 48, "projector_rows": 192, "quick": False},
    "labels": {"size": 128},
}
#: Steps whose command takes ``--seed`` (the others have their seeds fixed by design: the study's
#: noise seeds 0..n-1, the materials report's train/test captures, the pulse report's videos).
_SEEDED = {"fig4", "fig8", "fig9", "fig11", "fig12", "skin", "labels"}


def step_settings(name: str, *, quick: bool = False, size: int | None = None, seed: int = 0) -> dict:
    """The settings step ``name`` runs with for ``planeray paper`` options ``quick``, ``size``, ``seed``.

    ``size`` (square images, camera pixels) replaces every step's image size; the effect labels
    are validated at 64 to 256 pixels (:data:`planeray.experiments.paper.EFFECTS_SIZES`) and clamp
    it into that range; the pulse videos span 4 projector rows per camera row (at most 720).

    Examples
    --------
    >>> step_settings("fig8", quick=True)
    {'size': 32, 'seed': 0}
    >>> step_settings("labels", quick=True, size=16)
    {'size': 64, 'seed': 0}
    """
    from .paper import EFFECTS_SIZES

    s = dict((_QUICK if quick else _FULL)[name])
    if size is not None and "size" in s:
        s["size"] = int(size)
        if name == "labels":
            s["size"] = min(max(int(size), EFFECTS_SIZES[0]), EFFECTS_SIZES[1])
        if name == "fig15":
            s["projector_rows"] = min(720, 4 * int(size))
    if name in _SEEDED:
        s["seed"] = int(seed)
    return s


# --- the steps -----------------------------------------------------------------------------------
def _rel(folder: Path, path) -> str:
    """``path`` relative to the step's folder (POSIX separators: it is written into the report)."""
    return Path(path).relative_to(folder).as_posix()


def _fig4(folder: Path, s: dict, advance) -> dict:
    from ..baselines import compare_emulation
    from ..devices import simulated_device
    from ..figures.baselines import emulation_figure

    n = s["size"]
    device = simulated_device(FIG4_SCENE, (n, n), projector_rows=720, seed=s["seed"], ambient_e_per_us=0.01)
    res = compare_emulation(device, delay_us=FIG4_DELAY_US, exposure_us=FIG4_EXPOSURE_US)
    numbers = jsonable(res["numbers"])
    (folder / "emulation.json").write_text(json.dumps(numbers, indent=1))
    png = folder / "fig4_emulation.png"
    emulation_figure(res["emulated"].image, res["synchronized"], res["truth"], numbers=numbers, out=png)
    advance(1)
    err = numbers["errors"]
    measured = {
        "scene": FIG4_SCENE,
        "delay_us": numbers["delay_us"],
        "exposure_us": numbers["exposure_us"],
        "captures_synchronized": numbers["n_captures"]["synchronized"],
        "captures_emulated": numbers["n_captures"]["emulated"],
        "relative_rmse_synchronized_vs_truth": err["synchronized_vs_truth"]["relative_rmse"],
        "relative_rmse_emulated_vs_truth": err["emulated_vs_truth"]["relative_rmse"],
        "relative_rmse_emulated_vs_synchronized": err["emulated_vs_synchronized"]["relative_rmse"],
    }
    return {"fig4": {"measured": measured, "figures": [_rel(folder, png)]}}


def _fig4_command(s: dict) -> str:
    n = s["size"]
    return (
        f"planeray emulate {FIG4_SCENE} --delay-us {FIG4_DELAY_US:g} --exposure-us {FIG4_EXPOSURE_US:g} "
        f"--size {n} {n} --seed {s['seed']} --out fig4"
    )


def _study(folder: Path, s: dict, advance) -> dict:
    from .study import run_study

    r = run_study(folder, provider="mc", seeds=s["seeds"], quick=s["quick"], progress=advance)
    ns = r["noise_sweep"]
    methods = [m for m in ("pinv", "nnls", "full") if m in ns]
    at_high = {m: ns[m]["mean"][-1] for m in methods}
    fig5 = {
        "provider": r["provider"],
        "noise_eta": r["noise"],
        "n_images": r["n_images"],
        "n_offsets": r["n_offsets"],
        "pinv_minimum": r["example_min"]["pinv"],
        "example_mse": r["example_mse"],
        "highest_noise_eta": ns["noise"][-1],
        "mse_at_highest_noise": at_high,
        "best_at_highest_noise": min(at_high, key=at_high.get),
        "best_per_noise": [min(methods, key=lambda m: ns[m]["mean"][i]) for i in range(len(ns["noise"]))],
        "noise": ns["noise"],
    }
    fig6 = {}
    for name in ("sigma_s", "sigma_a", "g"):
        ps = r[f"{name}_sweep"]
        fig6[name] = {
            "values": ps["values"],
            "mse_full": ps["full"]["mean"],
            "mse_pinv": ps["pinv"]["mean"],
            "mse_nnls": ps["nnls"]["mean"],
            "full_best_at": sum(
                ps["full"]["mean"][i] <= min(ps["pinv"]["mean"][i], ps["nnls"]["mean"][i])
                for i in range(len(ps["values"]))
            ),
            "points": len(ps["values"]),
        }
    fig6["regularization"] = r["regularization"]["paper"] | {"best": r["regularization"]["best"]}
    base = folder
    return {
        "fig5": {
            "measured": fig5,
            "figures": [_rel(folder, base / "fig5_reconstruction.png"), _rel(folder, base / "fig5c_mse_vs_noise.png")],
        },
        "fig6": {"measured": fig6, "figures": [_rel(folder, base / "fig6_mse_vs_params.png")]},
    }


def _study_work(s: dict) -> int:
    from .study import study_work

    return study_work(quick=s["quick"])


def _study_command(s: dict) -> str:
    return "planeray study demux --out study" + (" --quick" if s["quick"] else "") + f" --seeds {s['seeds']}"


def _figure(name: str):
    """A step over :data:`planeray.experiments.paper.FIGURES` ``[name]`` (``planeray figure NAME``)."""

    def run(folder: Path, s: dict, advance) -> dict:
        from .paper import FIGURES, figure_outputs

        numbers = FIGURES[name](folder, size=s["size"], seed=s["seed"], progress=advance)
        pngs = [_rel(folder, folder / f) for f, kind in figure_outputs(name) if kind == "figure"]
        return {name if name != "effects" else "labels": {"measured": _figure_measured(name, numbers), "figures": pngs}}

    return run


def _figure_measured(name: str, numbers: dict) -> dict:
    from ..timing import paper_sweep

    numbers = {k: v for k, v in numbers.items() if k != "png"}
    if name == "fig8":
        sweep = paper_sweep()
        delays = sorted({float(d) for d in sweep.delay_us})
        exposures = sorted({float(e) for e in sweep.exposure_us})
        epipolar = sum(abs(float(d)) < float(e) / 2 for d, e in zip(sweep.delay_us, sweep.exposure_us))
        return {
            **numbers,
            "delays_us": [delays[0], delays[-1]],
            "delay_step_us": delays[1] - delays[0],
            "n_delays": len(delays),
            "exposures_us": exposures,
            "epipolar_images": int(epipolar),
            "boundary_images_left_out": int(sweep.excluded.sum()),
            "images_demultiplexed": int((~sweep.excluded).sum()),
        }
    if name == "fig11":
        imgs = numbers["images"]
        captured = next(v for k, v in imgs.items() if k.startswith("captured"))
        one_row = imgs["sharpened, 1 row"]
        narrow = next(v for k, v in imgs.items() if k.startswith("sharpened") and k != "sharpened, 1 row")
        return {
            **numbers,
            "michelson_captured_600us": captured["michelson_scan_line"],
            "michelson_sharpened_resolution": narrow["michelson_scan_line"],
            "michelson_sharpened_1_row": one_row["michelson_scan_line"],
            "michelson_truth_direct": imgs["ground-truth direct"]["michelson_scan_line"],
            "michelson_seeds": {
                short: next(v for k, v in numbers.get("michelson_noise_seeds", {}).items() if match(k))
                for short, match in (
                    ("captured_600us", lambda k: k.startswith("captured")),
                    ("sharpened_resolution", lambda k: k.startswith("sharpened") and k != "sharpened, 1 row"),
                    ("sharpened_1_row", lambda k: k == "sharpened, 1 row"),
                )
                if numbers.get("michelson_noise_seeds")
            },
        }
    if name == "fig12":
        imgs = numbers["images"]
        return {
            **numbers,
            "relative_rmse_synthesized": imgs["synthesized from the stack"]["relative_rmse"],
            "relative_rmse_16ms": imgs["single line, 16 ms"]["relative_rmse"],
            "relative_rmse_800ms": imgs["single line, 800 ms"]["relative_rmse"],
            "relative_rmse_seeds": {
                short: numbers["relative_rmse_noise_seeds"][name]
                for short, name in (
                    ("synthesized", "synthesized from the stack"),
                    ("16ms", "single line, 16 ms"),
                    ("800ms", "single line, 800 ms"),
                )
                if name in numbers.get("relative_rmse_noise_seeds", {})
            },
        }
    if name == "effects":
        return {
            "overall_visible": {scene: v["overall_visible"] for scene, v in numbers.items()},
            "recall_visible": {scene: v["recall_visible"] for scene, v in numbers.items()},
        }
    return numbers


def _figure_work(name: str):
    def work(s: dict) -> int:
        from .paper import figure_work

        return figure_work(name, size=s["size"])

    return work


def _figure_command(name: str):
    return lambda s: f"planeray figure {name} --size {s['size']} --seed {s['seed']} --out figures"


def _fig10(folder: Path, s: dict, advance) -> dict:
    from .materials import run_materials_report

    last = [0]

    def progress(done, total, msg):
        if done > last[0]:
            advance(done - last[0])
            last[0] = done

    r = run_materials_report(folder / "materials", size=s["size"], quick=s["quick"], progress=progress)
    test = r["stack_profiles"]["floor_edge"]["test"]
    measured = {
        "accuracy": test["accuracy"],
        "pixels": test["pixels"],  # per material: its test pixels, behind the accuracy's interval
        "overall": test["overall"],
        "min_material_accuracy": test["min_material_accuracy"],
        "misclassified": test["errors"]["misclassified"],
        "share_of_errors_near_wall": test["errors"]["share_near_wall"],
        "near_wall_pixel_share": test["errors"]["near_wall_pixel_share"],
        "accuracy_near_wall": test["accuracy_near_wall"],
        "accuracy_interior": test["accuracy_interior"],
    }
    pngs = [f"fig10{p}" for p in ("a_photo", "b_profiles", "c_segmentation", "d_confusion")]
    if "media_fit" in r:  # beyond Fig. 10: the media measured (the full run; --quick skips it)
        measured["media_fit"] = r["media_fit"]
        pngs.append("fig10e_measured_media")
    return {"fig10": {"measured": measured, "figures": [_rel(folder, folder / "materials" / f"{p}.png") for p in pngs]}}


def _fig10_work(s: dict) -> int:
    from .materials import report_tasks

    return report_tasks(quick=s["quick"])


def _fig10_command(s: dict) -> str:
    return f"planeray materials report --out materials --size {s['size']}" + (" --quick" if s["quick"] else "")


def _skin(folder: Path, s: dict, advance) -> dict:
    from .skin import run_skin_compare

    r = run_skin_compare(
        folder / "compare", size=s["size"], quick=s["quick"], seed=s["seed"], progress=lambda msg: advance(1)
    )
    cnr = {}
    for row in r["table"]:
        cnr.setdefault(row["condition"], {})[row["method"]] = {
            "cnr": row["cnr"],
            "detected": row["n_detected"],
            "veins": row["n_veins"],
        }
    ambient = {}
    for row in r["ambient"]:
        ambient.setdefault(row["level"], {"lux": row["lux"]})[row["method"]] = row["cnr"]
    e = r["enhancement"]
    ef = r["enhancement_forearm"]
    base = folder / "compare"
    return {
        "fig13": {
            "measured": {"cnr_by_ambient_level": ambient, "delay_us": r["delay_us"], "exposure_us": r["exposure_us"]},
            "figures": [_rel(folder, base / "fig13_skin_ambient.png")],
        },
        "fig14": {
            "measured": {
                "ladder": {k: e[k] for k in ("best_single_delay_us", "best_single_cnr", "enhanced_cnr", "gain")},
                "forearm": {k: ef[k] for k in ("best_single_delay_us", "best_single_cnr", "enhanced_cnr", "gain")},
                "ladder_detected": {"enhanced": e["enhanced_detected"], "best_single": e["best_single_detected"]},
                "veins": e["n_veins"],
                # beyond the paper (the full run): each vein's depth fitted from a sweep
                **({"vein_depth": r["vein_depth"]} if "vein_depth" in r else {}),
            },
            "figures": [
                _rel(folder, base / "fig14_skin_enhance.png"),
                _rel(folder, base / "fig14_skin_enhance_forearm.png"),
                *([_rel(folder, base / "fig14_vein_depth.png")] if "vein_depth" in r else []),
            ],
        },
        "fig16": {
            "measured": {"by_condition": cnr, "delay_us": r["delay_us"], "exposure_us": r["exposure_us"]},
            "figures": [_rel(folder, base / "fig16_skin_methods.png"), _rel(folder, base / "fig16_skin_depth.png")],
        },
    }


def _skin_work(s: dict) -> int:
    from .skin import compare_steps

    return compare_steps(s["quick"])


def _skin_command(s: dict) -> str:
    return f"planeray skin compare --out skin --size {s['size']} --seed {s['seed']}" + (
        " --quick" if s["quick"] else ""
    )


def _pulse_options(s: dict) -> dict:
    from .pulse import QUICK_REPORT

    return dict(QUICK_REPORT) if s["quick"] else {}


def _fig15(folder: Path, s: dict, advance) -> dict:
    from .pulse import run_pulse_report

    n = s["size"]
    r = run_pulse_report(
        folder / "pulse",
        size=(n, n),
        projector_rows=s["projector_rows"],
        progress=lambda text: advance(1),
        **_pulse_options(s),
    )
    a = r["fig15a"]
    measured = {
        "true_mean_rate_bpm": r["true_mean_rate_bpm"],
        "fig15a_rate_bpm": a["rate_bpm"],
        "fig15a_peak_bpm": a["peak_bpm"],
        "fig15a_detected": a["detected"],
        "snr_db": {m: v["snr_db"] for m, v in r["methods"].items()},
        "snr_db_without_magnification": {m: v["snr_db_without_magnification"] for m, v in r["methods"].items()},
        "rate_bpm": {m: v["rate_bpm"] for m, v in r["methods"].items()},
        "accuracy": {k: r["accuracy"][k] for k in ("detected", "total", "mean_abs_error_bpm", "max_abs_error_bpm")},
        # one video's error each, over rates and seeds: the spread the paper's one error is set against
        "abs_errors_bpm": [
            abs(x["rate_bpm"] - x["true_bpm"]) for x in r["accuracy"]["runs"] if x["rate_bpm"] is not None
        ],
        "false_alarms": r["pulse_free"]["false_alarms"],
        "pulse_free_videos": len(r["pulse_free"]["runs"]),
    }
    base = folder / "pulse"
    return {
        "fig15": {
            "measured": measured,
            "figures": [_rel(folder, base / "fig15a_pulse.png"), _rel(folder, base / "fig15b_methods.png")],
        }
    }


def _fig15_work(s: dict) -> int:
    from .pulse import pulse_report_steps

    return pulse_report_steps(**_pulse_options(s))


def _fig15_command(s: dict) -> str:
    n = s["size"]
    return f"planeray skin pulse-report --out pulse --size {n} {n} --projector-rows {s['projector_rows']}" + (
        " --quick" if s["quick"] else ""
    )


#: The steps, in the order they run (the paper's order of figures).
STEPS = {
    step.name: step
    for step in (
        Step("fig4", ("fig4",), "Fig. 4: emulated vs synchronized delay imaging", _fig4, lambda s: 1, _fig4_command),
        Step("study", ("fig5", "fig6"), "Figs. 5, 6: the demultiplexing study", _study, _study_work, _study_command),
        Step(
            "fig8",
            ("fig8",),
            "Fig. 8: delay x exposure stack",
            _figure("fig8"),
            _figure_work("fig8"),
            _figure_command("fig8"),
        ),
        Step(
            "fig9", ("fig9",), "Fig. 9: delay profiles", _figure("fig9"), _figure_work("fig9"), _figure_command("fig9")
        ),
        Step("fig10", ("fig10",), "Fig. 10: material recognition", _fig10, _fig10_work, _fig10_command),
        Step(
            "fig11",
            ("fig11",),
            "Fig. 11: sharpened epipolar imaging",
            _figure("fig11"),
            _figure_work("fig11"),
            _figure_command("fig11"),
        ),
        Step(
            "fig12",
            ("fig12",),
            "Fig. 12: relighting",
            _figure("fig12"),
            _figure_work("fig12"),
            _figure_command("fig12"),
        ),
        Step(
            "skin",
            ("fig13", "fig14", "fig16"),
            "Figs. 13, 14, 16: veins through skin",
            _skin,
            _skin_work,
            _skin_command,
        ),
        Step("fig15", ("fig15",), "Fig. 15: pulse", _fig15, _fig15_work, _fig15_command),
        Step(
            "labels",
            ("labels",),
            "Effect labels (Sec. 8)",
            _figure("effects"),
            _figure_work("effects"),
            _figure_command("effects"),
        ),
    )
}


def step_work(name: str, settings: dict) -> int:
    """Units of progress step ``name`` reports at ``settings``."""
    return int(STEPS[name].work(settings))


# --- inputs and manifest -------------------------------------------------------------------------
def inputs_digest() -> str:
    """BLAKE2b digest of what the numbers are computed from: planeray's sources and shipped data.

    Every file of the installed ``planeray`` package (path and bytes), compiled caches left out.
    """
    root = Path(__file__).resolve().parents[1]
    h = hashlib.blake2b(digest_size=16)
    for path in sorted(root.rglob("*")):
        if not path.is_file() or "__pycache__" in path.parts or path.suffix in (".pyc", ".nbi", ".nbc"):
            continue
        h.update(str(path.relative_to(root)).encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def _header(*, quick: bool, size, seed: int) -> dict:
    from ..io._common import planeray_version

    options = {"quick": bool(quick), "size": None if size is None else int(size), "seed": int(seed)}
    return {
        "format": FORMAT,
        "format_version": 1,
        "planeray_version": planeray_version(),
        "options": options,
        "settings": {name: step_settings(name, quick=quick, size=size, seed=seed) for name in STEPS},
        "inputs_digest": inputs_digest(),
    }


def _options_text(options: dict) -> str:
    words = ["--quick"] if options.get("quick") else []
    if options.get("size") is not None:
        words.append(f"--size {options['size']}")
    words.append(f"--seed {options.get('seed', 0)}")
    return " ".join(words)


def _read_manifest(out: Path) -> dict | None:
    try:
        data = json.loads((out / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and data.get("format") == FORMAT else None


def _step_done(out: Path, manifest: dict, name: str) -> bool:
    """Step ``name`` finished: the manifest says so and its folder holds the record it wrote last."""
    if not (manifest.get("steps") or {}).get(name, {}).get("done"):
        return False
    try:
        record = json.loads((out / name / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(record, dict) and record.get("format") == STEP_FORMAT and "results" in record


@dataclass
class Plan:
    """What :func:`run_paper` will do: the manifest to write, the steps done and to do, and why."""

    out: Path
    manifest: dict
    done: list
    todo: list
    resuming: bool
    restart: bool


def plan_paper_run(out_dir, *, quick: bool = False, size: int | None = None, seed: int = 0, overwrite: bool = False):
    """Check ``out_dir`` and the options before any work and say which steps remain.

    A new folder starts a run; a folder of a ``planeray paper`` run with the same options,
    version and inputs resumes it (its finished steps are kept); with other options it is refused
    (one line naming both) unless ``overwrite``, which starts again; anything else at ``out_dir``
    is refused (:func:`planeray.io.atomic.check_replaceable`: planeray never replaces what it did
    not write).

    Returns
    -------
    Plan
    """
    check_integer(seed, "seed", minimum=0, maximum=2**32 - 1)
    if size is not None:
        check_integer(size, "size", minimum=MIN_SIZE, maximum=MAX_SIZE)
    import_extra("cv2", "planeray paper (Figs. 13-16: Eq. 7's bilateral filter, Eulerian magnification)")
    out = Path(out_dir)
    header = _header(quick=quick, size=size, seed=seed)
    fresh = {**header, "steps": {}}
    if not (out.exists() or out.is_symlink()):
        return Plan(out, fresh, [], list(STEPS), resuming=False, restart=False)
    old = _read_manifest(out) if out.is_dir() and not out.is_symlink() else None
    if old is None or planeray_output_kind(out) != "paper report":
        check_replaceable(out, overwrite=overwrite, kind="paper report")  # raises: not ours, or ours of another kind
        return Plan(out, fresh, [], list(STEPS), resuming=False, restart=True)
    same = all(old.get(k) == header[k] for k in ("options", "planeray_version", "inputs_digest", "settings"))
    if not same:
        if overwrite:
            check_replaceable(out, overwrite=True, kind="paper report")
            return Plan(out, fresh, [], list(STEPS), resuming=False, restart=True)
        if old.get("options") != header["options"]:
            why = (
                f"options {_options_text(old.get('options') or {})}, not {_options_text(header['options'])}: "
                "rerun with its options to resume it, or pass --overwrite to start again"
            )
        elif old.get("planeray_version") != header["planeray_version"]:
            why = (
                f"planeray {old.get('planeray_version')}, not {header['planeray_version']}: a run resumes only on "
                "the same inputs; pass --overwrite to start again"
            )
        else:
            why = (
                "other inputs (planeray's sources or data changed since): a run resumes only on the same inputs; "
                "pass --overwrite to start again"
            )
        raise InputError(f"holds a planeray paper run with {why}", out)
    done = [n for n in STEPS if _step_done(out, old, n)]
    manifest = {**header, "steps": {n: old["steps"][n] for n in done}}
    todo = [n for n in STEPS if n not in done]
    for name in todo:  # a step's folder left by a killed run is replaced; anything else there is refused now
        check_replaceable(out / name, overwrite=True, kind="paper step")
    if overwrite and not todo:  # a finished run, asked to be replaced: start again
        return Plan(out, fresh, [], list(STEPS), resuming=False, restart=True)
    return Plan(out, manifest, done, todo, resuming=True, restart=False)


def _write_manifest(out: Path, manifest: dict) -> None:
    with atomic_file(out / MARKER) as tmp:
        tmp.write_text(json.dumps(jsonable(manifest), indent=1))


def _start(plan: Plan) -> None:
    out = plan.out
    if plan.restart and (out.exists() or out.is_symlink()):
        try:
            if out.is_dir() and not out.is_symlink():
                shutil.rmtree(out)
            else:
                out.unlink()
        except OSError as exc:
            raise storage_error(exc, out) from None
    try:
        out.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise InputError("cannot be created: a file is in its way", out) from None
    except OSError as exc:
        raise storage_error(exc, out) from None
    _write_manifest(out, plan.manifest)


def run_step(out: Path, name: str, settings: dict, *, advance=None) -> dict:
    """Run step ``name`` into ``out/NAME`` (written atomically) and return its per-figure record.

    A folder left there by a run killed before it was recorded as done is replaced (it is a
    step folder planeray wrote); anything else there is refused.
    """
    step = STEPS[name]
    advance = advance or (lambda n=1: None)
    t0 = time.perf_counter()
    with atomic_directory(out / name, overwrite=True, kind="paper step") as tmp:
        figures = step.run(tmp, settings, advance)
        seconds = round(time.perf_counter() - t0, 1)
        figures = {
            key: {**value, "figures": [f"{name}/{p}" for p in value["figures"]]} for key, value in figures.items()
        }
        record = {
            "format": STEP_FORMAT,
            "format_version": 1,
            "step": name,
            "settings": settings,
            "command": step.command(settings),
            "seconds": seconds,
            "results": figures,
        }
        (tmp / MARKER).write_text(json.dumps(jsonable(record), indent=1, allow_nan=False))
    return jsonable(record)


@writes_output("out_dir")
def run_paper(
    out_dir,
    *,
    quick: bool = False,
    size: int | None = None,
    seed: int = 0,
    overwrite: bool = False,
    progress=None,
    plan: Plan | None = None,
) -> dict:
    """Reproduce every figure planeray can into ``out_dir``; resume a killed run of the same options.

    Parameters
    ----------
    out_dir : path
        Folder of the run (created).
    quick : bool
        Small sizes, reduced grids and fewer photons (a few minutes on 2 cores).
    size : int, optional
        Image size of every step (square, camera pixels; :data:`MIN_SIZE` to :data:`MAX_SIZE`).
    seed : int
        Seed of the steps that take one (:func:`step_settings`).
    overwrite : bool
        Start again over a run of other options (only a folder ``planeray paper`` wrote).
    progress : callable, optional
        ``progress(event, **info)``: ``("step", name=, title=, work=)`` before a step,
        ``("advance", n=)`` for its units of work, ``("done", name=, seconds=)`` after it.
    plan : Plan, optional
        :func:`plan_paper_run`'s answer for the same arguments (checked before any work).

    Returns
    -------
    dict
        ``numbers`` (what ``numbers.json`` holds), ``steps`` (per step: seconds, whether it ran
        now) and ``files`` (the report files).
    """
    from .paper_report import write_report

    plan = plan or plan_paper_run(out_dir, quick=quick, size=size, seed=seed, overwrite=overwrite)
    out = plan.out

    def emit(event, **info):
        if progress is not None:
            progress(event, **info)

    _start(plan)
    manifest = plan.manifest
    ran = []
    for name in plan.todo:
        settings = manifest["settings"][name]
        emit("step", name=name, title=STEPS[name].title, work=step_work(name, settings))
        record = run_step(out, name, settings, advance=lambda n=1: emit("advance", n=n))
        manifest["steps"][name] = {"done": True, "seconds": record["seconds"]}
        _write_manifest(out, manifest)
        ran.append(name)
        emit("done", name=name, seconds=record["seconds"])
    records = {name: json.loads((out / name / MARKER).read_text(encoding="utf-8")) for name in STEPS}
    files = write_report(out, manifest, records)
    numbers = json.loads((out / "numbers.json").read_text(encoding="utf-8"))
    steps = {name: {"seconds": manifest["steps"][name]["seconds"], "ran": name in ran} for name in STEPS}
    return {"numbers": numbers, "steps": steps, "files": files}
