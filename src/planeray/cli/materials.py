"""``planeray materials``: recognizing subsurface-scattering materials from delay profiles (Sec. 8, Fig. 10)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._console import console, out, print_json, progress_bar
from ._common import _check_outputs, _claim, _friendly_errors, _load_stack, _not_an_input, note, stage_bars

materials_app = typer.Typer(
    help="Material recognition from delay profiles (Sec. 8, Fig. 10): simulate, train, predict, report.",
    no_args_is_help=True,
)


#: The capture settings' options, declared once for the commands that read a capture (fit, recognize, library-add).
MmPerRowOpt = Annotated[
    float | None,
    typer.Option(help="Size of one projector row on the surface, mm (default: the capture's acquisition.json)."),
]
WhiteAlbedoOpt = Annotated[float, typer.Option(help="Albedo of the white reference, in (0, 1].")]


def _choice(value: str, option: str, choices) -> None:
    if value not in choices:
        raise ValueError(f"{option} must be one of {', '.join(choices)}, got {value!r}")


def _read_labels(path: Path, option: str, shape, *, labelled: bool = True):
    """A label image of the stack's size, errors naming the option (:func:`~planeray.experiments.materials_folders.read_labels`)."""
    from ..experiments.materials_folders import read_labels

    return read_labels(path, option, shape, labelled=labelled)


@materials_app.command("classes")
@_friendly_errors
def classes(
    source: Annotated[str, typer.Option(help="Optical data of the milks: narasimhan or jensen.")] = "narasimhan",
    channel: Annotated[str, typer.Option(help="Laser colour: red, green or blue.")] = "red",
):
    """The documented class ids of label images and the simulated media."""
    from ..optical_data import BACKGROUND_CLASS, CHANNELS, CLASS_NAMES, OPTICAL_SOURCES, UNLABELLED, optical_table

    _choice(source, "--source", OPTICAL_SOURCES)
    _choice(channel, "--channel", CHANNELS)
    rows = {r["class_id"]: r for r in optical_table(source=source, channel=channel)}
    out.print(f"class ids of label images (media: {source}, {channel} laser line):")
    out.print(f"  {UNLABELLED}  unlabelled: not trained on, not scored; in a segmentation: no class")
    for cid, name in CLASS_NAMES.items():
        r = rows.get(cid)
        if r is None:
            what = "the table, anything outside the containers" if cid == BACKGROUND_CLASS else ""
            out.print(f"  {cid}  {name}: {what}")
            continue
        depth = "semi-infinite" if r["thickness_mm"] is None else f"{r['thickness_mm']:g} mm deep"
        out.print(
            f"  {cid}  {name}: sigma_s {r['sigma_s']:.4g}/mm, sigma_a {r['sigma_a']:.4g}/mm, g {r['g']:.3g}, "
            f"n {r['n']:.3g}, sigma_s' {r['sigma_s_prime']:.3g}/mm, diffusion length {r['diffusion_length_mm']:.3g} mm, "
            f"{depth}"
        )
    out.print("other ids (7-255) for your own materials: planeray materials train --class-name ID=NAME")


@materials_app.command("simulate")
@_friendly_errors
def simulate(
    out_dir: Annotated[
        Path, typer.Option("--out", "-o", help="Capture folder to write (stack.zarr, labels.png, ...).")
    ],
    size: Annotated[tuple[int, int], typer.Option(help="Image size H W (camera pixels), 8 to 4096.")] = (128, 128),
    projector_rows: Annotated[
        int, typer.Option(help="Projector rows spanned by the image (0.3 mm each), up to 127 per image row.")
    ] = 720,
    seed: Annotated[int, typer.Option(help="Seed of the camera noise and the table's texture (>= 0).")] = 0,
    placement: Annotated[int, typer.Option(help="0: materials in class order; k >= 1: shuffled and moved.")] = 0,
    container: Annotated[str, typer.Option(help="tray (rectangular) or cup (round).")] = "tray",
    wall: Annotated[str, typer.Option(help="Container walls: fresnel (clear) or absorbing (black).")] = "fresnel",
    source: Annotated[str, typer.Option(help="Optical data of the milks: narasimhan or jensen.")] = "narasimhan",
    channel: Annotated[str, typer.Option(help="Laser colour: red, green or blue.")] = "red",
    noise: Annotated[
        float, typer.Option(help="Noise factor: x the default camera's shot and read noise (> 0, at most 77).")
    ] = 1.0,
    ambient_e_per_us: Annotated[
        float,
        typer.Option(
            "--ambient-e-per-us",
            "--ambient",
            help="Ambient light, electrons per us of exposure (albedo 1); below what fills the full well.",
        ),
    ] = 0.5,
    sweep: Annotated[str, typer.Option(help="Named sweep: paper (85 images) or quick.")] = "paper",
    overwrite: Annotated[bool, typer.Option(help="Replace an existing capture folder planeray wrote.")] = False,
):
    """Simulate a capture of the five containers (milks, toothpaste, soap) with its labels."""
    from ..experiments.materials import check_capture_options, simulate_capture
    from ..kernels.wall import TABLE_RUNS
    from ..mc.cache import cache_dir
    from ..optical_data import MATERIAL_CLASSES
    from ..scenes.materials import tables_to_trace
    from ..timing import make_sweep

    options = dict(
        size=size,
        projector_rows=projector_rows,
        seed=seed,
        placement=placement,
        container=container,
        wall=wall,
        source=source,
        channel=channel,
        noise=noise,
        ambient_e_per_us=ambient_e_per_us,
        sweep=sweep,
    )
    check_capture_options(**options)
    _check_outputs((out_dir, "materials capture"), overwrite=overwrite)
    trace = tables_to_trace(source=source, channel=channel, wall=wall)
    n = len(make_sweep(sweep))
    with progress_bar() as bar:
        table_progress = None
        if trace:
            names = ", ".join(MATERIAL_CLASSES[c] for c in trace)
            console.print(
                f"note: the wall-kernel tables of {len(trace)} media ({names}; {source}, {channel} laser line, "
                f"{wall} walls) are neither shipped nor cached: tracing them by Monte Carlo first "
                f"({len(trace) * TABLE_RUNS} runs, about {1.6 * len(trace):.0f} minutes on 2 cores; once: "
                f"cached in {cache_dir()})",
                highlight=False,
                markup=False,
            )
            ttask = bar.add_task("tracing wall-kernel tables (Monte Carlo runs)", total=len(trace) * TABLE_RUNS)
            table_progress = lambda k: bar.advance(ttask, k)  # noqa: E731
        task = bar.add_task(f"building the scene, capturing {n} images", total=n)
        cap = simulate_capture(
            out_dir,
            **options,
            overwrite=overwrite,
            progress=lambda i: bar.advance(task),
            table_progress=table_progress,
        )
    near = int(cap.near_wall.sum())
    out.print(
        f"capture: {out_dir}  ({len(cap.stack)} images, {size[0]}x{size[1]}; labels.png: class ids, "
        f"near_wall.png: {near} pixels near a wall)"
    )


def _parse_class_names(items) -> dict:
    names = {}
    for item in items or []:
        key, sep, name = item.partition("=")
        if not sep or not key.strip().isdigit() or not name.strip():
            raise ValueError(f"--class-name expects ID=NAME (e.g. 7=mayonnaise), got {item!r}")
        if not 1 <= int(key) <= 255:
            raise ValueError(f"--class-name ids must be 1 to 255 (0 is unlabelled), got {item!r}")
        if int(key) in names:
            raise ValueError(
                f"--class-name {int(key)} is named twice ({names[int(key)]!r} and {name.strip()!r}); give each id once"
            )
        if name.strip() in names.values():
            raise ValueError(f"--class-name {name.strip()!r} is given to two ids; give each name once")
        names[int(key)] = name.strip()
    return names


@materials_app.command("train")
@_friendly_errors(options={"kind": "--features"})
def train(
    stacks: Annotated[list[Path], typer.Argument(help="Training stacks (Zarr or import folder), one or more.")],
    labels: Annotated[list[Path], typer.Option("--labels", help="Label image per stack (PNG/TIFF of class ids).")],
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Model file to write (.zip: JSON + skops).")],
    features: Annotated[str, typer.Option(help="stack (measured profiles) or transport (demultiplexed).")] = "stack",
    floor: Annotated[
        str,
        typer.Option(
            help="Per-curve floor removed before area-normalizing: edge (the mean of the outermost delays: "
            "ambient light, black level; measured best on held-out captures), min (each curve's minimum) "
            "or none (the paper's plain normalization)."
        ),
    ] = "edge",
    class_name: Annotated[
        list[str] | None, typer.Option("--class-name", help="ID=NAME for classes beyond the documented list.")
    ] = None,
    ignore_class: Annotated[
        list[int] | None, typer.Option("--ignore-class", help="Class id to leave out (e.g. 6, the background).")
    ] = None,
    max_per_class: Annotated[int, typer.Option(help="Training pixels per class and capture (10 to 5000).")] = 400,
    cv_folds: Annotated[int, typer.Option(help="Cross-validation folds (grouped by capture), 2 to 20.")] = 4,
    seed: Annotated[int, typer.Option(help="Seed of the pixel sampling (>= 0).")] = 0,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing model file planeray wrote.")] = False,
):
    """Train the per-pixel RBF-SVM on labelled captures (hyper-parameters by grouped cross-validation)."""
    from ..materials import train_model
    from ..materials.model import check_model_output, check_training_options

    options = dict(
        kind=features,
        floor=floor,
        class_names=_parse_class_names(class_name),
        ignore_classes=tuple(ignore_class or ()),
        max_per_class=max_per_class,
        cv_folds=cv_folds,
        seed=seed,
    )
    check_training_options(**options)  # every option refused before any file is read
    if len(labels) != len(stacks):
        raise ValueError(f"--labels: {len(stacks)} stacks but {len(labels)} label images; give one per stack, in order")
    if out_path.suffix.lower() != ".zip":
        raise ValueError(f"--out must end in .zip (a model file: a JSON record and a skops estimator), got {out_path}")
    _not_an_input(out_path, [("STACKS", p) for p in stacks] + [("--labels", p) for p in labels])
    check_model_output(out_path, overwrite=overwrite)
    _claim(out_path)
    loaded = [_load_stack(p) for p in stacks]
    labs = [_read_labels(lp, "--labels", st.shape) for lp, st in zip(labels, loaded)]
    with progress_bar() as bar:
        task = bar.add_task(f"features of {len(stacks)} capture(s)", total=len(stacks))

        def progress(done, total, stage):
            bar.update(task, completed=done, total=total, description=stage)

        model = train_model(loaded, labs, **options, sources=[str(p) for p in stacks], progress=progress)
    model.save(out_path, overwrite=overwrite)
    tr = model.training
    out.print(
        f"model: {out_path}  ({len(model.classes)} classes, C = {tr['best']['C']:g}, gamma = {tr['best']['gamma']:.3g}, "
        f"cross-validated accuracy {tr['cv_accuracy']:.3f} over {tr['cv_folds']} folds of {tr['groups']})"
    )


def _acc(value) -> str:
    """An accuracy for the terminal: three decimals, or "no pixels" (None / NaN: nothing to score)."""
    if value is None or value != value:
        return "no pixels"
    return f"{value:.3f}"


@materials_app.command("predict")
@_friendly_errors(options={"out_png": "--out"})
def predict(
    model_path: Annotated[Path, typer.Argument(help="Model file (planeray materials train).")],
    stack_path: Annotated[Path, typer.Argument(help="Stack (Zarr or import folder) of the same sweep.")],
    out_png: Annotated[
        Path, typer.Option("--out", "-o", help="Segmentation map: palette PNG of class ids (or TIFF); 0: no class.")
    ],
    labels: Annotated[
        Path | None, typer.Option("--labels", help="Ground-truth label image: score the prediction.")
    ] = None,
    near_wall: Annotated[
        Path | None,
        typer.Option("--near-wall", help="Mask of pixels near walls (non-zero): scored apart (with --labels)."),
    ] = None,
    unclassified_below: Annotated[
        float,
        typer.Option(
            help="A pixel less typical of the SVM's pick than this share of the class's held-out training pixels "
            "is unclassified (0 in the map); 0 keeps every pick. The default is measured on held-out captures "
            "(documentation: Material recognition)."
        ),
    ] = 0.01,
    majority_px: Annotated[
        float,
        typer.Option(
            help="Replace each classified pixel's pick by the majority of the picks within this radius (pixels; "
            "0: off). 1.5 at 128x128 (2.5 mm) kept every class >= 0.95 next to walls (Recognition by parameters)."
        ),
    ] = 0.0,
    json_out: Annotated[bool, typer.Option("--json", help="Print the numbers as JSON on stdout.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing segmentation planeray wrote.")] = False,
):
    """Segment a capture pixel by pixel with a trained model (refused if the sweep differs)."""
    from ..experiments.materials_recognize import check_predict_options, segment_materials
    from ..io import jsonable

    options = dict(labels=labels, near_wall=near_wall, unclassified_below=unclassified_below, majority_px=majority_px)
    check_predict_options(out_png, **options)
    _check_outputs(
        (out_png, "segmentation"),
        overwrite=overwrite,
        inputs=[("MODEL", model_path), ("STACK", stack_path), ("--labels", labels), ("--near-wall", near_wall)],
    )
    with stage_bars() as progress:
        numbers = segment_materials(
            model_path, stack_path, out_png, **options, overwrite=overwrite, progress=progress, note=note
        )
    if json_out:
        print_json(jsonable(numbers))
        return
    out.print(f"segmentation: {out_png}  (unclassified below typicality {numbers['unclassified_below']:g})")
    for name, n in numbers["pixels"].items():
        out.print(f"  {name}: {n} px")
    if "score" in numbers:
        _print_score(numbers["score"])


def _print_score(sc: dict) -> None:
    """A segmentation's accuracy per class on the terminal (near walls and away, the share unclassified)."""
    for name, acc in sc["accuracy"].items():
        lost = sc["unclassified"].get(name)
        share = f"; {lost:.0%} of its pixels unclassified" if lost is not None else ""
        if name in sc["not_scored"]:
            out.print(f"  accuracy {name}: not scored ({sc['not_scored'][name]}){share}")
            continue
        extra = ""
        if "accuracy_near_wall" in sc:
            extra = f"  (near walls {_acc(sc['accuracy_near_wall'][name])}, away {_acc(sc['accuracy_interior'][name])})"
        out.print(f"  accuracy {name}: {_acc(acc)}{extra}{share}")


def _settings(mm_per_row, *, n=None, depth_mm=None, white_reference=None, white_albedo: float = 0.99, g=None):
    """The capture settings of a command, built once (:class:`~planeray.materials.settings.CaptureSettings`)."""
    from ..materials.settings import CaptureSettings

    return CaptureSettings(
        mm_per_row=mm_per_row, n=n, depth_mm=depth_mm, white_reference=white_reference, white_albedo=white_albedo, g=g
    )


@materials_app.command("fit")
@_friendly_errors(options={"block_px": "--block"})
def fit_cmd(
    input_path: Annotated[Path, typer.Argument(help="Stack (demultiplexed first) or transport store of the capture.")],
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder to write: maps (TIFF), figure, fit.json.")],
    labels: Annotated[
        Path | None, typer.Option("--labels", help="Label image of regions (0: left out); default: one region.")
    ] = None,
    white_reference: Annotated[
        Path | None,
        typer.Option(
            "--white-reference",
            help="Capture (stack or transport) of a white Lambertian target, same sweep and camera settings: "
            "calibrates the magnitude. Without it only the shape is used (mu_a less identifiable).",
        ),
    ] = None,
    white_albedo: WhiteAlbedoOpt = 0.99,
    n: Annotated[
        float | None,
        typer.Option(
            "--n",
            help="Refractive index of the medium against air (1 for an index-matched surface). Default 1.33 "
            "(water-based media), said so: a wrong index biases mu_s' by tens of percent and does not show in the "
            "fit's chi-square.",
        ),
    ] = None,
    g: Annotated[
        float | None,
        typer.Option(
            "--g",
            help="The medium's scattering anisotropy (Henyey-Greenstein g), 0-0.95. Default: unknown -- fitted "
            "with mu_s' and mu_a, its uncertainty carried into theirs.",
        ),
    ] = None,
    mm_per_row: MmPerRowOpt = None,
    block: Annotated[
        int | None,
        typer.Option(
            help="Fit blocks of BLOCK x BLOCK pixels (1: every pixel), 1-64, for the maps. Default: 4 for a "
            "transport; for a stack's images none (the maps hold each region's estimate).",
        ),
    ] = None,
    method: Annotated[
        str | None,
        typer.Option(
            help="stack: fit the stack's images directly (band weights x kernel + ambient; default for a stack); "
            "transport: demultiplex first and fit the transport (the only one for a transport store).",
        ),
    ] = None,
    walls: Annotated[
        bool,
        typer.Option(
            help="With --labels: each labelled region is a container whose boundary is a clear wall (air behind it); "
            "the model includes the light lost through it. --no-walls: the media are unbounded.",
        ),
    ] = True,
    wall_kind: Annotated[
        str,
        typer.Option(
            help="The containers' walls: clear (a thin clear wall with air behind) or black (nothing returns).",
        ),
    ] = "clear",
    depth_mm: Annotated[
        float | None,
        typer.Option(
            help="The layer's depth, mm: the medium lies on a support that returns no light (a black or clear "
            "bottom). Default: semi-infinite (deep enough that no light reaches the bottom).",
        ),
    ] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the summary as JSON on stdout.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace a fit folder planeray wrote.")] = False,
):
    """Measure the medium: maps of mu_s' and mu_a (1/mm) with standard errors, per region and per pixel block.

    Every fit says whether its forward model fits the data (reduced chi-square against the camera's noise
    model and the model's own error): a fit that does not, or a parameter at the forward model's edge, is
    flagged on the console, in planeray.json and in the flag layer flags.tif.
    """
    from ..experiments.materials_folders import check_fit_options, fit_materials
    from ..io import jsonable

    settings = _settings(
        mm_per_row, n=n, depth_mm=depth_mm, white_reference=white_reference, white_albedo=white_albedo, g=g
    )
    check_fit_options(block, method, wall_kind)
    _check_outputs(
        (out_dir, "materials fit"),
        overwrite=overwrite,
        inputs=[("the capture", input_path), ("--labels", labels), ("--white-reference", white_reference)],
    )
    with stage_bars() as progress:
        summary = fit_materials(
            input_path, out_dir, settings=settings, labels=labels, block_px=block, method=method, walls=walls,
            wall_kind=wall_kind, overwrite=overwrite, progress=progress, note=note,
        )  # fmt: skip
    if json_out:
        print_json(jsonable(summary))
        return
    out.print(f"fit: {out_dir}  ({summary['method'].split(':')[0]} fit; {summary['calibration']})")
    for region, r in summary["regions"].items():
        _print_region(region, r)


def _print_region(region, r: dict) -> None:
    """One fitted region on the terminal: its estimates, fit quality and flags."""
    f = lambda v: "n/a" if v is None else f"{v:.4g}"  # noqa: E731
    why = f"  [{'; '.join(r['not_identifiable'])}]" if r["not_identifiable"] else ""
    out.print(
        f"  region {region} ({r['pixels']} px): mu_s' {f(r['mu_s_prime_per_mm'])} +- "
        f"{f(r['mu_s_prime_se_per_mm'])} /mm, mu_a {f(r['mu_a_per_mm'])} +- {f(r['mu_a_se_per_mm'])} /mm{why}",
        highlight=False,
    )
    q = r.get("fit_quality")
    if q is not None:
        out.print(
            f"    reduced chi-square {q['reduced_chi2']:.3g} (threshold {q['threshold']:.3g} at {q['dof']} degrees "
            "of freedom)",
            highlight=False,
        )
    if r.get("g_se") is not None:
        out.print(f"    g (unknown, fitted with them) {r['g']:.2f} +- {r['g_se']:.2f}", highlight=False)
    for text in r.get("flags", []):
        out.print(f"    FLAGGED: {text}", highlight=False, markup=False)
    if r.get("blocks_flagged"):
        out.print(f"    FLAGGED: {r['blocks_flagged']:.0%} of its blocks (flags.tif)", highlight=False, markup=False)


@materials_app.command("report")
@_friendly_errors
def report(
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder for the figures (Fig. 10) and materials.json.")],
    size: Annotated[int, typer.Option(help="Image size (size x size of a 720-row projector), 16 to 4096.")] = 128,
    quick: Annotated[bool, typer.Option(help="Fewer curve points, no Jensen or cup runs, a 2 x 2 SVM grid.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing report folder planeray wrote.")] = False,
):
    """The whole experiment end to end: simulate, train, test, curves, figures (Fig. 10b, c, d)."""
    from ..experiments.materials import check_report_options, report_tasks, run_materials_report

    check_report_options(size=size, quick=quick)
    _check_outputs((out_dir, "materials report"), overwrite=overwrite)
    with progress_bar() as bar:
        task = bar.add_task("materials report", total=report_tasks(quick=quick))

        def progress(done, total, msg):
            bar.update(task, completed=done, total=total, **({"description": msg} if msg else {}))

        numbers = run_materials_report(out_dir, size=size, quick=quick, overwrite=overwrite, progress=progress)
    main = numbers["stack_profiles"]["floor_edge"]["test"]
    out.print(f"report: {out_dir}  ({numbers['seconds']:g} s)")
    for name, acc in main["accuracy"].items():
        out.print(
            f"  {name}: {_acc(acc)} (near walls {_acc(main['accuracy_near_wall'][name])}, "
            f"away {_acc(main['accuracy_interior'][name])})"
        )
    out.print(f"  share of the errors near walls: {main['errors']['share_near_wall']:.2f}")
    unc = (numbers.get("unclassified") or {}).get("test")
    if unc:
        row = next(r for r in unc["thresholds"] if r["unclassified_below"] == numbers["unclassified"]["default"])
        out.print(
            f"  unclassified at the default threshold {row['unclassified_below']:g}: the table (not trained) "
            f"{_pct(row['unclassified_of_untrained'])}, right picks lost {_pct(row['lost_of_right'])}, wrong picks "
            f"flagged {_pct(row['flagged_of_wrong'])}"
        )


def _pct(value) -> str:
    return "no pixels" if value is None else f"{value:.1%}"


@materials_app.command("recognize")
@_friendly_errors(options={"block_px": "--block"})
def recognize_cmd(
    input_path: Annotated[Path, typer.Argument(help="Stack or transport store of the capture.")],
    out_dir: Annotated[
        Path, typer.Option("--out", "-o", help="Folder to write: segmentation.png, planeray.json, recognition.png.")
    ],
    library: Annotated[
        Path | None,
        typer.Option("--library", help="Media library (JSON); default: the five Fig. 10 media shipped."),
    ] = None,
    regions: Annotated[
        Path | None,
        typer.Option(
            "--regions", help="Label image of the containers (0: none); default: found in the capture's images."
        ),
    ] = None,
    pool_mm: Annotated[
        float | None,
        typer.Option(
            help="Fit pixel blocks of the demultiplexed capture and pool their evidence over a disc of this radius "
            "(mm, at least a pixel; 0: per block) instead of fitting each container; the default for a transport "
            "store or a version-1 library (2.5 mm).",
        ),
    ] = None,
    block: Annotated[int, typer.Option(help="With --pool-mm: fit blocks of BLOCK x BLOCK pixels, 1-16.")] = 2,
    p_unknown: Annotated[
        float, typer.Option(help="A fit less typical of every medium than this p-value is none of these (0).")
    ] = 1e-3,
    labels: Annotated[
        Path | None,
        typer.Option("--labels", help="Ground-truth class ids: score per class and by distance to the walls."),
    ] = None,
    mm_per_row: MmPerRowOpt = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the numbers as JSON on stdout.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace a recognition folder planeray wrote.")] = False,
):
    """Name each container's medium by its measured mu_s' and mu_a against a library of known media.

    With a stack and a library of physical parameters (the shipped one; library-add), the containers are
    found in the images (pixels with light from below the surface; a table or a wall is none of them),
    each is fitted as a whole with its walls, and named by the library's entry its parameters match -- or
    "none of these".  A library of parameters travels: one built at one resolution recognizes another.
    """
    from ..experiments.materials_recognize import check_recognition_options, recognize_materials
    from ..io import jsonable

    check_recognition_options(block, regions, pool_mm, p_unknown)
    settings = _settings(mm_per_row)
    _check_outputs(
        (out_dir, "materials recognition"),
        overwrite=overwrite,
        inputs=[("the capture", input_path), ("--library", library), ("--regions", regions), ("--labels", labels)],
    )
    with stage_bars() as progress:
        numbers = recognize_materials(
            input_path, out_dir, library=library, regions=regions, pool_mm=pool_mm, block_px=block,
            p_unknown=p_unknown, labels=labels, settings=settings, overwrite=overwrite, progress=progress, note=note,
        )  # fmt: skip
    if json_out:
        print_json(jsonable(numbers))
        return
    out.print(f"recognition: {out_dir}  ({numbers['pooling']}; library: {numbers['library']})")
    for name, n in numbers["pixels"].items():
        out.print(f"  {name}: {n} px")
    for d in numbers.get("containers") or ():
        out.print(f"  container {d['region']} ({d['pixels']} px): {d['decision']}", highlight=False, markup=False)
    for text, n in numbers["flags"].items():
        if n:
            out.print(f"  {n} px: {text}")
    if "score" in numbers:
        _print_recognition_score(numbers["score"])


def _print_recognition_score(table: dict) -> None:
    """Accuracy per class, by distance to the wall, on the terminal."""
    edges = table["bins_mm"]
    spans = [f"{lo:g}-{hi:g} mm" if hi is not None else f">{lo:g} mm" for lo, hi in zip(edges[:-1], edges[1:])]
    for name, row in table["classes"].items():
        bins = ", ".join(f"{span} {_acc(b['accuracy'])}" for span, b in zip(spans, row["bins"]))
        out.print(f"  accuracy {name}: {_acc(row['all'])}  (by distance to the wall: {bins})", highlight=False)
    if table["none_of_these"]["labelled_none"] is not None:
        out.print(f"  other pixels labelled none: {table['none_of_these']['labelled_none']:.3f}")


@materials_app.command("library-add")
@_friendly_errors(options={"class_names": "--class-name", "out_json": "--out"})
def library_add(
    input_path: Annotated[Path, typer.Argument(help="Stack of the capture (a transport store: version-1 libraries).")],
    labels: Annotated[Path, typer.Option("--labels", help="Label image: the region(s) of the new medium.")],
    class_name: Annotated[
        list[str], typer.Option("--class-name", help="ID=NAME of a labelled region to add (repeatable), ID 1-255.")
    ],
    out_json: Annotated[Path, typer.Option("--out", "-o", help="The new library (JSON).")],
    library: Annotated[
        Path | None, typer.Option("--library", help="Library to add to; default: the shipped one.")
    ] = None,
    replace: Annotated[bool, typer.Option(help="Replace an entry of the same name or id.")] = False,
    mm_per_row: MmPerRowOpt = None,
    n: Annotated[
        float, typer.Option("--n", help="Refractive index of the new medium (the fit's; stored with it).")
    ] = 1.33,
    depth_mm: Annotated[
        float | None,
        typer.Option(help="Depth of its layer, mm, on a support that returns no light (default: semi-infinite)."),
    ] = None,
    white_reference: Annotated[
        Path | None,
        typer.Option("--white-reference", help="A white target's stack, same sweep and camera: calibrates the fit."),
    ] = None,
    white_albedo: WhiteAlbedoOpt = 0.99,
    overwrite: Annotated[bool, typer.Option(help="Replace a library file planeray wrote.")] = False,
):
    """Add media to a library from labelled regions of a capture.

    A library of physical parameters (version 2, the shipped one) gets each region's mu_s' and mu_a, measured
    from the stack's images with its walls modelled, with their uncertainties, the index and the layer's depth:
    values of the medium, which recognize it in captures of any resolution and row size.
    """
    from ..experiments.materials_recognize import add_to_library, check_library_add

    settings = _settings(mm_per_row, n=n, depth_mm=depth_mm, white_reference=white_reference, white_albedo=white_albedo)
    names = _parse_class_names(class_name)
    in_place = check_library_add(out_json, library, names, overwrite=overwrite)
    _check_outputs(
        (out_json, "media library"),
        overwrite=overwrite,
        inputs=[("the capture", input_path), ("--labels", labels), ("--white-reference", white_reference)]
        + ([] if in_place else [("--library", library)]),
    )
    with stage_bars() as progress:
        lib, entries = add_to_library(
            input_path, out_json, labels=labels, class_names=names, library=library, replace=replace,
            settings=settings, overwrite=overwrite, progress=progress, note=note,
        )  # fmt: skip
    out.print(f"library: {out_json}  ({len(lib.entries)} media)")
    for e in entries:
        _print_entry(e, physical=lib.physical)


def _print_entry(e, *, physical: bool) -> None:
    """A library's new entry on the terminal."""
    f = lambda v: "n/a" if v is None else f"{v:.4g}"  # noqa: E731
    if physical:
        sa = "" if e.mu_a_log_sd is None else f" (+- {100 * e.mu_a_log_sd:.0f} %)"
        out.print(
            f"  added {e.name} (class {e.class_id}): mu_s' {f(e.mu_s_prime_per_mm)} /mm (+- "
            f"{100 * e.mu_s_prime_log_sd:.1f} %), mu_a {f(e.mu_a_per_mm)} /mm{sa}, n {e.n:g}"
            + ("" if e.depth_mm is None else f", a {e.depth_mm:g} mm layer"),
            highlight=False,
        )
        return
    out.print(
        f"  added {e.name} (class {e.class_id}): mu_s' {f(e.mu_s_prime_per_mm)} /mm (log sd "
        f"{e.mu_s_prime_log_sd:.2f}), mu_a {f(e.mu_a_per_mm)} /mm, beyond the table: "
        f"{e.beyond_table['above']:.0%} above, {e.beyond_table['below']:.0%} below ({e.blocks} blocks)",
        highlight=False,
    )
