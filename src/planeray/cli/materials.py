"""``planeray materials``: recognizing subsurface-scattering materials from delay profiles (Sec. 8, Fig. 10)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._console import console, out, print_json, progress_bar
from ._common import _check_outputs, _claim, _friendly_errors, _load_stack, _not_an_input, _same_place

materials_app = typer.Typer(
    help="Material recognition from delay profiles (Sec. 8, Fig. 10): simulate, train, predict, report.",
    no_args_is_help=True,
)


def _choice(value: str, option: str, choices) -> None:
    if value not in choices:
        raise ValueError(f"{option} must be one of {', '.join(choices)}, got {value!r}")


def _read_labels(path: Path, option: str, shape, *, labelled: bool = True):
    """A label image of the stack's size, errors naming the option; ``labelled``: refuse one with no labelled pixel."""
    import numpy as np

    from ..errors import InputError
    from ..materials import read_label_image

    try:
        lab = read_label_image(path, shape=shape)
    except InputError as exc:
        raise ValueError(f"{option} {exc}") from None
    if labelled and not np.any(lab > 0):
        raise ValueError(
            f"{option} {path}: no labelled pixel (every pixel is 0, 'unlabelled'); mark the regions with class ids "
            "1-255"
        )
    return lab


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
    from ..mc.cache import cache_dir
    from ..mc.wall import TABLE_RUNS
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
@_friendly_errors
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
    from ..experiments._report import jsonable
    from ..experiments.materials import score
    from ..materials import load_model
    from ..materials.labels import LABEL_SUFFIXES, write_label_image
    from ..materials.model import check_unclassified_below

    threshold = check_unclassified_below(unclassified_below)
    if not 0.0 <= majority_px <= 50.0:
        raise ValueError(f"--majority-px must be in 0-50 pixels, got {majority_px:g}")
    if out_png.suffix.lower() not in LABEL_SUFFIXES:
        raise ValueError(f"--out must end in .png, .tif or .tiff (a label image of class ids), got {out_png}")
    if near_wall is not None and labels is None:
        raise ValueError("--near-wall needs --labels: it splits the accuracies into near walls and away from them")
    _check_outputs(
        (out_png, "segmentation"),
        overwrite=overwrite,
        inputs=[("MODEL", model_path), ("STACK", stack_path), ("--labels", labels), ("--near-wall", near_wall)],
    )
    model = load_model(model_path)
    st = _load_stack(stack_path)
    model.check_stack(st, source=str(stack_path))
    truth = _read_labels(labels, "--labels", st.shape) if labels is not None else None
    near = _read_labels(near_wall, "--near-wall", st.shape, labelled=False) > 0 if near_wall is not None else None
    blind = {c: p for c, p in model.smallest_typicality().items() if 0 < threshold <= p}
    if blind:
        console.print(
            "note: --unclassified-below "
            f"{threshold:g} cannot unclassify any pixel of "
            + ", ".join(f"{model.classes[c]} (smallest typicality {p:.3g})" for c, p in blind.items())
            + ": too few held-out training pixels; train with more (--max-per-class, more captures) or raise it",
            highlight=False,
            markup=False,
        )
    if model.definition.kind == "transport":  # demultiplexing first: minutes, counted in camera rows
        with progress_bar() as bar:
            task = bar.add_task("demultiplexing the stack (rows)", total=st.shape[0])
            seg = model.segment(
                st, unclassified_below=threshold, source=str(stack_path), progress=lambda n: bar.advance(task, n)
            )
    else:
        with console.status("classifying pixels"):
            seg = model.segment(st, unclassified_below=threshold, source=str(stack_path))
    if majority_px > 0:
        import numpy as np

        from ..materials.recognize import mode_filter

        voted = mode_filter(seg.labels, radius_px=majority_px, classes=sorted(model.classes))
        keep = (seg.labels > 0) & ~seg.no_profile & ~seg.unclassified
        seg.labels[...] = np.where(keep & (voted > 0), voted, seg.labels)
    write_label_image(out_png, seg.labels, kind="segmentation")
    counts = {}
    for c in sorted(set(seg.labels[~seg.no_profile & ~seg.unclassified].ravel().tolist())):
        counts[model.classes.get(int(c), f"class {int(c)}")] = int(((seg.labels == c) & ~seg.no_profile).sum())
    counts["unclassified"] = int(seg.unclassified.sum())
    counts["no profile"] = int(seg.no_profile.sum())
    numbers = {
        "segmentation": str(out_png),
        "pixels": counts,
        "unclassified_below": threshold,
        "majority_px": majority_px,
        "model": str(model_path),
        "features": model.definition.describe(),
    }
    if truth is not None:
        numbers["score"] = score(
            seg.labels,
            truth,
            near_wall=near,
            classes=sorted(set(model.classes) | {int(c) for c in set(truth.ravel().tolist()) if c}),
            model_classes=sorted(model.classes),
        )
        numbers["score"]["unclassified"] = _unclassified_by_class(seg, truth, numbers["score"]["confusion"])
    if json_out:
        print_json(jsonable(numbers))
        return
    out.print(f"segmentation: {out_png}  (unclassified below typicality {threshold:g})")
    for name, n in counts.items():
        out.print(f"  {name}: {n} px")
    if "score" in numbers:
        sc = numbers["score"]
        for name, acc in sc["accuracy"].items():
            lost = sc["unclassified"].get(name)
            share = f"; {lost:.0%} of its pixels unclassified" if lost is not None else ""
            if name in sc["not_scored"]:
                out.print(f"  accuracy {name}: not scored ({sc['not_scored'][name]}){share}")
                continue
            extra = ""
            if "accuracy_near_wall" in sc:
                extra = (
                    f"  (near walls {_acc(sc['accuracy_near_wall'][name])}, away {_acc(sc['accuracy_interior'][name])})"
                )
            out.print(f"  accuracy {name}: {_acc(acc)}{extra}{share}")


def _unclassified_by_class(seg, truth, confusion) -> dict:
    """Share of each true class's pixels (with a profile) left unclassified (None: no such pixels)."""
    out = {}
    for cid, name in zip(confusion["classes"], confusion["names"]):
        m = (truth == cid) & ~seg.no_profile
        out[name] = float(seg.unclassified[m].mean()) if m.any() else None
    return out


def _capture_and_row_size(input_path: Path, mm_per_row: float | None):
    """The capture's transport (a stack demultiplexed), its record, and its row size (mm per projector row).

    The row size is ``--mm-per-row`` where given, else the capture's record; neither: one line naming the option.
    """
    transport, meta = _read_fit_input(input_path, "the capture")
    mm = mm_per_row if mm_per_row is not None else _recorded_mm_per_row(meta)
    if mm is None:
        raise ValueError(f"{input_path} does not record its row size: pass --mm-per-row (mm per projector row)")
    return transport, meta, mm


def _capture_shape(input_path: Path) -> tuple[int, int]:
    """The image size of a capture (stack or transport store), read without demultiplexing it."""
    return _capture_geometry(input_path)[:2]


def _capture_geometry(input_path: Path) -> tuple[int, int, float]:
    """``(H, W, rows_per_camera_row)`` of a capture (stack or transport store), read without demultiplexing it."""
    from ..io import read_transport
    from ..io.atomic import planeray_output_kind

    if not Path(input_path).exists():
        raise ValueError(f"the capture {input_path}: no such file or folder")
    if planeray_output_kind(input_path) == "transport":
        import zarr

        try:
            group = zarr.open_group(str(input_path), mode="r")
            H, W = (int(n) for n in group["T"].shape[:2])
            return H, W, float(group.attrs["projector_rows"]) / H
        except Exception:  # a damaged store: read it properly, for the reader's one-line message
            transport = read_transport(input_path)[0]
            return (*transport.shape, float(transport.geometry.rows_per_camera_row))
    st = _load_stack(input_path)
    return (*st.shape, float(st.geometry.rows_per_camera_row))


def _library(library: Path | None):
    """``--library`` (else the shipped one), errors naming the option."""
    from ..errors import InputError
    from ..materials.library import default_library, load_library

    try:
        return load_library(library) if library is not None else default_library()
    except InputError as exc:
        raise ValueError(f"--library {exc}") from None


def _library_and_capture(library: Path | None, input_path: Path, mm_per_row: float | None, lib=None):
    """``--library`` (else the shipped one, or ``lib`` already read), read before the capture, then checked
    against its row size."""
    from ..errors import InputError

    lib = _library(library) if lib is None else lib
    transport, meta, mm = _capture_and_row_size(input_path, mm_per_row)
    try:
        lib.check_conditions(mm_per_row=mm, calibrated=False)
    except InputError as exc:
        raise ValueError(f"--library {exc}") from None
    return lib, transport, meta, mm


def _read_fit_input(path: Path, option: str, *, with_progress: bool = True):
    """``(transport, metadata)`` of a transport store, or of a stack demultiplexed (floor removed) first."""
    from ..io.atomic import planeray_output_kind
    from ..io.transport_store import read_transport
    from ..materials.model import capture_transport

    if not Path(path).exists():
        raise ValueError(f"{option} {path}: no such file or folder")
    if planeray_output_kind(path) == "transport":
        transport, attrs = read_transport(path)
        return transport, dict(attrs)
    st = _load_stack(path)
    if with_progress:
        with progress_bar() as bar:
            task = bar.add_task(f"demultiplexing {Path(path).name} (rows)", total=st.shape[0])
            transport = capture_transport(st, progress=lambda n: bar.advance(task, n))
    else:
        transport = capture_transport(st)
    return transport, dict(st.metadata or {})


#: A capture given as its own white reference would "calibrate" it to an albedo of one.
_WHITE_IS_CAPTURE = (
    "--white-reference {white} is the capture itself: a white reference is a separate capture of a white "
    "Lambertian target, with the same sweep and camera"
)


def _mm_per_row_option(value: float | None) -> None:
    """``--mm-per-row``: a finite size in (0, 100] mm, or not given."""
    from .._validate import check_number

    if value is not None:
        check_number(value, "--mm-per-row", minimum=0.0, maximum=100.0, min_inclusive=False)


def _recorded_mm_per_row(meta: dict):
    """The row size a capture records (its ``acquisition.json``, else its scene's ``mm_per_row``), or None."""
    from ..stack import recorded_mm_per_row

    return recorded_mm_per_row(meta)[0]


def _stack_and_row_size(input_path: Path, mm_per_row: float | None):
    """``(stack, metadata, mm per row)``: ``--mm-per-row``, else the capture's (its acquisition.json); neither:
    one line naming both (no default stands in)."""
    stack = _load_stack(input_path)
    meta = dict(stack.metadata or {})
    mm = mm_per_row if mm_per_row is not None else _recorded_mm_per_row(meta)
    if mm is None:
        raise ValueError(
            f"{input_path} does not record its row size: pass --mm-per-row (mm per projector row) or add "
            '"mm_per_row" to its acquisition.json'
        )
    return stack, meta, mm


def _forward_table(n: float):
    """The forward table of index ``n``: loaded silently when shipped or cached, else traced -- announced with
    a time estimate measured on a pilot run, and counted on a progress bar."""
    from ..materials import fit as mfit
    from ..mc.cache import cache_dir

    if mfit.forward_table_stored(n=n):
        return mfit.forward_table(n=n)
    with console.status(f"estimating the time to trace the forward table of n = {n:g}"):
        seconds = mfit.forward_table_seconds(n=n)
    console.print(
        f"note: no forward table for n = {n:g} is shipped or cached: tracing it by Monte Carlo first "
        f"({mfit.TABLE_RUNS} runs, about {seconds / 60:.0f} minutes on this machine, measured on a pilot run; "
        f"once: cached in {cache_dir()})",
        highlight=False,
        markup=False,
    )
    with progress_bar() as bar:
        task = bar.add_task(f"tracing the forward table of n = {n:g} (Monte Carlo runs)", total=mfit.TABLE_RUNS)
        return mfit.forward_table(n=n, progress=lambda k: bar.advance(task, k))


@materials_app.command("fit")
@_friendly_errors
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
    white_albedo: Annotated[float, typer.Option(help="Albedo of the white reference, in (0, 1].")] = 0.99,
    n: Annotated[
        float | None,
        typer.Option(
            "--n",
            help="Refractive index of the medium against air (1 for an index-matched surface). Default 1.33 "
            "(water-based media), said so: a wrong index biases mu_s' by tens of percent and does not show in the "
            "fit's chi-square.",
        ),
    ] = None,
    mm_per_row: Annotated[
        float | None,
        typer.Option(help="Size of one projector row on the surface, mm (default: the capture's metadata)."),
    ] = None,
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
    import json

    import numpy as np

    from ..experiments._report import jsonable
    from ..figures.materials import fit_figure
    from ..goodness import DEFAULT_P_MISFIT, FLAGS
    from ..io import atomic_directory
    from ..materials import fit as mfit

    if block is not None and not 1 <= block <= 64:
        raise ValueError(f"--block must be an integer in 1-64, got {block}")
    if method is not None and method not in ("stack", "transport"):
        raise ValueError(f"--method must be stack or transport, got {method!r}")
    if not 0.0 < white_albedo <= 1.0:
        raise ValueError(f"--white-albedo must be in (0, 1], got {white_albedo:g}")
    n_source = "--n" if n is not None else "assumed (water-based media; state --n)"
    n = mfit.DEFAULT_N if n is None else n
    if not 1.0 <= n <= 1.6:
        raise ValueError(f"--n must be in 1.0-1.6 (a liquid or tissue against air), got {n:g}")
    _mm_per_row_option(mm_per_row)
    if wall_kind not in mfit.WALL_KINDS:
        raise ValueError(f"--wall-kind must be one of {', '.join(mfit.WALL_KINDS)}, got {wall_kind!r}")
    if depth_mm is not None and not (np.isfinite(depth_mm) and 0.0 < depth_mm <= 10_000.0):
        raise ValueError(f"--depth-mm must be a depth in (0, 10000] mm, got {depth_mm:g}")
    _check_outputs(
        (out_dir, "materials fit"),
        overwrite=overwrite,
        inputs=[("the capture", input_path), ("--labels", labels), ("--white-reference", white_reference)],
    )
    from ..io.atomic import planeray_output_kind

    if not Path(input_path).exists():
        raise ValueError(f"the capture {input_path}: no such file or folder")
    if white_reference is not None and _same_place(Path(white_reference), Path(input_path)):
        raise ValueError(_WHITE_IS_CAPTURE.format(white=white_reference))
    is_transport = planeray_output_kind(input_path) == "transport"
    if method == "stack" and is_transport:
        raise ValueError(f"--method stack needs a stack: {input_path} is a transport store")
    method = method or ("transport" if is_transport else "stack")
    if method == "stack":
        if white_reference is not None and not Path(white_reference).exists():
            raise ValueError(f"--white-reference {white_reference}: no such file or folder")
        if white_reference is not None and planeray_output_kind(white_reference) == "transport":
            raise ValueError(
                f"--white-reference {white_reference} is a transport store: the stack fit needs the white "
                "target's stack (or --method transport)"
            )
        stack, meta, mm = _stack_and_row_size(input_path, mm_per_row)
        lab = _read_labels(labels, "--labels", stack.shape) if labels is not None else None
        white = None
        if white_reference is not None:
            white = _load_stack(white_reference)
            if white.shape != stack.shape or not (
                np.array_equal(white.delay_us, stack.delay_us) and np.array_equal(white.exposure_us, stack.exposure_us)
            ):
                raise ValueError(
                    f"--white-reference {white_reference} is {white.shape[0]}x{white.shape[1]} over "
                    f"{len(white)} images, the capture {stack.shape[0]}x{stack.shape[1]} over {len(stack)}: "
                    "capture it with the same sweep and camera"
                )
            if white.content_digest() == stack.content_digest():
                raise ValueError(_WHITE_IS_CAPTURE.format(white=white_reference) + " (the same images)")
        transport = None
    else:
        transport, meta, mm = _capture_and_row_size(input_path, mm_per_row)
        lab = _read_labels(labels, "--labels", transport.shape) if labels is not None else None
        block = 4 if block is None else block
    scale = None
    if white_reference is not None and method == "transport":
        white, _ = _read_fit_input(white_reference, "--white-reference")
        if white.shape != transport.shape or not np.array_equal(white.offsets_rows, transport.offsets_rows):
            raise ValueError(
                f"--white-reference {white_reference} is {white.shape[0]}x{white.shape[1]} over "
                f"{white.offsets_rows.size} offsets, the capture {transport.shape[0]}x{transport.shape[1]} over "
                f"{transport.offsets_rows.size}: capture it with the same sweep and camera"
            )
        if np.array_equal(white.dense, transport.dense):
            raise ValueError(_WHITE_IS_CAPTURE.format(white=white_reference) + " (the same transport)")
        scale = mfit.white_reference_scale(white.dense, albedo=white_albedo)
    from ..camera import CameraModel
    from ..stack import recorded_mm_per_row

    mm_source = "--mm-per-row" if mm_per_row is not None else recorded_mm_per_row(meta)[1]
    camera = CameraModel.from_metadata(meta) if method == "stack" else None
    if n_source != "--n":
        console.print(
            f"note: the medium's refractive index is assumed {n:g} (water-based media): a wrong index biases mu_s' "
            "by tens of percent without showing in the fit's chi-square; state it with --n (1 for an index-matched "
            "surface)",
            highlight=False,
            markup=False,
        )
    table = _forward_table(n)
    H, W = transport.shape if transport is not None else stack.shape
    regions = lab if lab is not None else np.ones((H, W), np.int64)
    n_regions = sum(1 for r in np.unique(regions) if r != 0)
    n_blocks = (
        0
        if block is None
        else sum(
            1
            for r in np.unique(regions)
            if r != 0
            for r0 in range(0, H, block)
            for c0 in range(0, W, block)
            if (regions[r0 : r0 + block, c0 : c0 + block] == r).any()
        )
    )
    with progress_bar() as bar:
        if method == "stack":
            from ..materials.stackfit import fit_stack

            task = bar.add_task("fitting the stack's images (regions, blocks)", total=n_regions + n_blocks)
            result = fit_stack(
                stack,
                mm_per_row=mm,
                labels=lab,
                containers=lab if walls else None,
                white=white,
                white_albedo=white_albedo,
                block_px=block,
                table=table,
                camera=camera,
                depth_mm=depth_mm,
                wall_kind=wall_kind,
                progress=lambda k: bar.advance(task, k),
            )
        else:
            task = bar.add_task("fitting pixel blocks", total=n_blocks)
            result = mfit.fit_transport(
                transport,
                mm_per_row=mm,
                labels=lab,
                white_scale=scale,
                block_px=block,
                containers=lab if walls else None,
                table=table,
                depth_mm=depth_mm,
                wall_kind=wall_kind,
                progress=lambda k: bar.advance(task, k),
            )
    calibrated = white_reference is not None
    summary = {
        "format": "planeray-materials-fit",
        "format_version": 1,
        "capture": str(input_path),
        "method": (
            "stack: the stack's images fitted directly (illumination matrix x line kernel + ambient per region)"
            if method == "stack"
            else "transport: the demultiplexed (or given) transport's profiles fitted"
        ),
        "mm_per_row": mm,
        "mm_per_row_source": mm_source,
        "refractive_index": n,
        "refractive_index_source": n_source,
        "anisotropy_g": mfit.DEFAULT_G,
        "depth_mm": depth_mm,
        "bottom": "none: semi-infinite" if depth_mm is None else f"at {depth_mm:g} mm: returns no light",
        "noise_model": (
            "the camera's (its record: shot, read, quantization and row jitter) and the forward model's error"
            if camera is not None
            else "the pixels' spread (the capture records no camera) and the forward model's error"
        ),
        "goodness_of_fit": (
            "reduced chi-square against the noise model; a fit less probable than p = "
            f"{DEFAULT_P_MISFIT:g} is flagged 'model does not fit' and its standard errors are scaled by "
            "sqrt(chi2 / dof); parameters at the forward model's edge are flagged and not reported"
        ),
        "calibration": (
            f"white reference {white_reference} (albedo {white_albedo:g}): absolute reflectance"
            if calibrated
            else f"none: shape only (a free scale per {'region' if method == 'stack' and block is None else 'block'}); mu_a is less identifiable"
        ),
        "block_px": block,
        "walls": (
            f"modelled: each --labels region is a container with a {wall_kind} wall at its boundary"
            if walls and lab is not None
            else "none: unbounded media"
        ),
        "regions": {str(k): v for k, v in result.regions.items()},
        "mask_bits": {str(k): v for k, v in mfit.REASONS.items()} | {"255": "not fitted (outside every region)"},
        "flag_bits": {str(k): v for k, v in FLAGS.items()} | {"255": "outside every region"},
        "files": {
            **{k: f"{k}.tif" for k in ("mu_s_prime_per_mm", "mu_a_per_mm", "mu_s_prime_se_per_mm", "mu_a_se_per_mm")},
            "mask": "identifiability_mask.tif",
            "flags": "flags.tif",
            "figure": "fit.png",
        },
    }
    with atomic_directory(out_dir, overwrite=overwrite, kind="materials fit") as tmp:
        for key, name in summary["files"].items():
            if key == "figure":
                continue
            _write_map_tiff(tmp / name, result.maps[key], key)
        fit_figure(result, mm_per_row=mm, out=tmp / "fit.png")
        (tmp / "planeray.json").write_text(json.dumps(jsonable(summary), indent=1))
    if json_out:
        print_json(jsonable(summary))
        return
    out.print(f"fit: {out_dir}  ({summary['method'].split(':')[0]} fit; {summary['calibration']})")
    for region, r in result.regions.items():
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
        for text in r.get("flags", []):
            out.print(f"    FLAGGED: {text}", highlight=False, markup=False)
        if r.get("blocks_flagged"):
            out.print(
                f"    FLAGGED: {r['blocks_flagged']:.0%} of its blocks (flags.tif)", highlight=False, markup=False
            )


_MAP_UNITS = {
    "mu_s_prime_per_mm": ("reduced scattering coefficient mu_s'", "1/mm"),
    "mu_a_per_mm": ("absorption coefficient mu_a", "1/mm"),
    "mu_s_prime_se_per_mm": ("standard error of mu_s'", "1/mm"),
    "mu_a_se_per_mm": ("standard error of mu_a", "1/mm"),
    "mask": ("identifiability mask: bits of the reasons in planeray.json (0: both measured)", "bits"),
    "flags": ("flag layer: bits of flag_bits in planeray.json (0: the model fits, nothing at an edge)", "bits"),
    "recognition_flags": ("recognition flags: bits of flag_bits in planeray.json (8: none of these)", "bits"),
}


def _write_map_tiff(path: Path, image, key: str) -> None:
    """A float32 (mask: uint8) TIFF with planeray's mark, and its quantity and unit in the description."""
    import json

    import numpy as np
    import tifffile

    from ..io import atomic_file
    from ..io.marks import mark_text

    what, unit = _MAP_UNITS[key]
    arr = np.asarray(image, np.uint8 if key in ("mask", "flags", "recognition_flags") else np.float32)
    with atomic_file(path) as tmp:
        tifffile.imwrite(
            tmp,
            arr,
            photometric="minisblack",
            software=mark_text("image"),
            description=json.dumps({"quantity": what, "unit": unit, "name": key}),
            metadata=None,
        )


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


def _wall_distance_from_labels(labels, mm_per_pixel):
    """Distance (mm) of each pixel's centre to the edge of its labelled region (the container's wall)."""
    import numpy as np
    from scipy import ndimage

    lab = np.asarray(labels)
    out = np.full(lab.shape, np.inf)
    for c in np.unique(lab[lab > 0]):
        m = lab == c
        d = ndimage.distance_transform_edt(np.pad(m, 1, constant_values=False))[1:-1, 1:-1]
        out[m] = (d[m] - 0.5) * mm_per_pixel
    return out


@materials_app.command("recognize")
@_friendly_errors
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
    mm_per_row: Annotated[
        float | None,
        typer.Option(help="Size of one projector row on the surface, mm (default: the capture's acquisition.json)."),
    ] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the numbers as JSON on stdout.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace a recognition folder planeray wrote.")] = False,
):
    """Name each container's medium by its measured mu_s' and mu_a against a library of known media.

    With a stack and a library of physical parameters (the shipped one; library-add), the containers are
    found in the images (pixels with light from below the surface; a table or a wall is none of them),
    each is fitted as a whole with its walls, and named by the library's entry its parameters match -- or
    "none of these".  A library of parameters travels: one built at one resolution recognizes another.
    """
    import json

    import numpy as np

    from ..experiments._report import jsonable
    from ..figures.materials import recognition_by_distance_figure
    from ..io import atomic_directory
    from ..io.atomic import planeray_output_kind
    from ..materials.labels import write_label_image
    from ..materials.library import FLAGS
    from ..materials.recognize import (
        DEFAULT_POOL_MM,
        accuracy_by_distance,
        fit_image,
        recognize_image,
        recognize_regions,
        recognize_stack,
    )

    if not 1 <= block <= 16:
        raise ValueError(f"--block must be an integer in 1-16, got {block}")
    if regions is not None and pool_mm is not None:
        raise ValueError("--regions and --pool-mm: fit the regions or pool over a disc, not both")
    if pool_mm is not None and not (np.isfinite(pool_mm) and 0.0 <= pool_mm <= 100.0):
        raise ValueError(f"--pool-mm must be in 0-100 mm, got {pool_mm:g}")
    if not 0.0 <= p_unknown < 1.0:
        raise ValueError(f"--p-unknown must be in [0, 1), got {p_unknown:g}")
    _mm_per_row_option(mm_per_row)
    _check_outputs(
        (out_dir, "materials recognition"),
        overwrite=overwrite,
        inputs=[("the capture", input_path), ("--library", library), ("--regions", regions), ("--labels", labels)],
    )
    lib = _library(library)
    if not Path(input_path).exists():
        raise ValueError(f"the capture {input_path}: no such file or folder")
    shape = _capture_shape(input_path) if regions is not None or labels is not None else None
    reg = _read_labels(regions, "--regions", shape) if regions is not None else None  # before any demultiplexing
    truth = _read_labels(labels, "--labels", shape) if labels is not None else None
    by_containers = lib.physical and pool_mm is None and planeray_output_kind(input_path) != "transport"
    details = None
    if by_containers:  # each container fitted from the stack's images
        from ..camera import CameraModel

        stack, meta, mm = _stack_and_row_size(input_path, mm_per_row)
        H, W = stack.shape
        rpc = float(stack.geometry.rows_per_camera_row)
        for n, _ in lib.hypotheses():
            _forward_table(n)  # announced and traced once where not shipped or cached
        with progress_bar() as bar:
            task = bar.add_task("fitting the containers (one pass per index and depth)", total=len(lib.hypotheses()))
            rec, details = recognize_stack(
                lib, stack, mm_per_row=mm, regions=reg, camera=CameraModel.from_metadata(meta), p_unknown=p_unknown,
                progress=lambda k: bar.advance(task, k),
            )  # fmt: skip
        pooling = (
            f"each region of {regions} fitted as a whole" if reg is not None
            else "each container found in the images (light from below the surface) fitted as a whole"
        )  # fmt: skip
    else:
        lib, transport, meta, mm = _library_and_capture(library, input_path, mm_per_row, lib=lib)
        H, W = transport.shape
        rpc = float(transport.geometry.rows_per_camera_row)
        px_mm = mm * rpc
        pool = DEFAULT_POOL_MM if pool_mm is None else pool_mm
        if 0.0 < pool < px_mm:
            if pool_mm is not None:
                raise ValueError(
                    f"--pool-mm {pool_mm:g} is smaller than a pixel ({px_mm:.3g} mm at {mm:g} mm per row): it would "
                    f"pool nothing; give at least {px_mm:.3g} mm, or 0 (per block)"
                )
            console.print(
                f"note: the default pooling radius {pool:g} mm is smaller than a pixel ({px_mm:.3g} mm): no pooling",
                highlight=False,
                markup=False,
            )
            pool = 0.0
        lib_rpc = lib.conditions.get("rows_per_camera_row")
        if not lib.physical and isinstance(lib_rpc, (int, float)) and abs(rpc / lib_rpc - 1.0) > 0.1:
            console.print(
                f"note: the library's media were fitted at {lib_rpc:g} projector rows per camera row, this capture "
                f"has {rpc:g}: a version-1 library's fits are bound to their resolution; a library of physical "
                "parameters (planeray materials library-add from a stack) travels",
                highlight=False,
                markup=False,
            )
        if reg is not None:  # each region's pooled profile fitted once
            with console.status("fitting each region's pooled profile"):
                rec, _ = recognize_regions(lib, transport, reg, mm_per_row=mm, p_unknown=p_unknown)
        else:
            with progress_bar() as bar:
                task = bar.add_task("fitting pixel blocks", total=-(-H // block) * -(-W // block))
                maps = fit_image(transport, mm_per_row=mm, block_px=block, progress=lambda k: bar.advance(task, k))
            rec = recognize_image(lib, maps, mm_per_pixel=mm * rpc, pool_mm=pool, p_unknown=p_unknown)
        pooling = (
            f"regions of {regions}: each region's pooled profile fitted"
            if reg is not None
            else (f"log-likelihoods over a disc of {pool:g} mm" if pool else "none: per pixel block")
        )
    mm_per_pixel = mm * rpc
    names = {e.class_id: e.name for e in lib.entries}
    counts = {names[c]: int((rec.class_ids == c).sum()) for c in lib.class_ids}
    counts["unclassified"] = int((rec.class_ids == 0).sum())  # none of these, or not fitted
    numbers = {
        "format": "planeray-materials-recognition",
        "format_version": 1,
        "capture": str(input_path),
        "library": str(library) if library is not None else "shipped (the five Fig. 10 media)",
        "library_version": lib.version,
        "mm_per_row": mm,
        "mm_per_pixel": mm_per_pixel,
        "block_px": None if by_containers else block,
        "pooling": pooling,
        "p_unknown": p_unknown,
        "pixels": counts,
        "flags": {text: int(((rec.flags & bit) > 0).sum()) for bit, text in FLAGS.items()},
        "flag_bits": {str(bit): text for bit, text in FLAGS.items()},
        "files": {"segmentation": "segmentation.png", "flags": "flags.tif"},
    }
    if details is not None:
        numbers["containers"] = details
    table = None
    if truth is not None:
        wall = _wall_distance_from_labels(truth, mm_per_pixel)
        scored = {c: n for c, n in names.items() if (truth == c).any()}
        table = accuracy_by_distance(rec.class_ids, truth, wall, classes=scored)
        others = np.isin(truth, list(scored), invert=True) & (truth > 0)
        table["none_of_these"] = {
            "pixels": int(others.sum()),
            "labelled_none": float((rec.class_ids[others] == 0).mean()) if others.any() else None,
        }
        numbers["score"] = {**table, "wall_distance": "from --labels: distance to the edge of each labelled region"}
        numbers["files"]["figure"] = "recognition.png"
    with atomic_directory(out_dir, overwrite=overwrite, kind="materials recognition") as tmp:
        write_label_image(tmp / "segmentation.png", rec.class_ids.astype(np.uint8), kind="segmentation")
        _write_map_tiff(tmp / "flags.tif", np.asarray(rec.flags, np.uint8), "recognition_flags")
        if table is not None:
            recognition_by_distance_figure({"parameters": table}, out=tmp / "recognition.png")
        (tmp / "planeray.json").write_text(json.dumps(jsonable(numbers), indent=1))
    if json_out:
        print_json(jsonable(numbers))
        return
    out.print(f"recognition: {out_dir}  ({numbers['pooling']}; library: {numbers['library']})")
    for name, n in counts.items():
        out.print(f"  {name}: {n} px")
    for d in details or ():
        out.print(f"  container {d['region']} ({d['pixels']} px): {d['decision']}", highlight=False, markup=False)
    for text, n in numbers["flags"].items():
        if n:
            out.print(f"  {n} px: {text}")
    if table is not None:
        edges = table["bins_mm"]
        spans = [f"{lo:g}-{hi:g} mm" if hi is not None else f">{lo:g} mm" for lo, hi in zip(edges[:-1], edges[1:])]
        for name, row in table["classes"].items():
            bins = ", ".join(f"{span} {_acc(b['accuracy'])}" for span, b in zip(spans, row["bins"]))
            out.print(f"  accuracy {name}: {_acc(row['all'])}  (by distance to the wall: {bins})", highlight=False)
        if table["none_of_these"]["labelled_none"] is not None:
            out.print(f"  other pixels labelled none: {table['none_of_these']['labelled_none']:.3f}")


@materials_app.command("library-add")
@_friendly_errors
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
    mm_per_row: Annotated[
        float | None,
        typer.Option(help="Size of one projector row on the surface, mm (default: the capture's acquisition.json)."),
    ] = None,
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
    white_albedo: Annotated[float, typer.Option(help="Albedo of the white reference, in (0, 1].")] = 0.99,
    overwrite: Annotated[bool, typer.Option(help="Replace a library file planeray wrote.")] = False,
):
    """Add media to a library from labelled regions of a capture.

    A library of physical parameters (version 2, the shipped one) gets each region's mu_s' and mu_a, measured
    from the stack's images with its walls modelled, with their uncertainties, the index and the layer's depth:
    values of the medium, which recognize it in captures of any resolution and row size.
    """
    import numpy as np

    from ..errors import InputError
    from ..io.atomic import planeray_output_kind
    from ..materials.library import save_library
    from ..materials.recognize import entries_from_capture, entries_from_stack, fit_image

    if out_json.suffix.lower() != ".json":
        raise ValueError(f"--out must end in .json (a media library), got {out_json}")
    _mm_per_row_option(mm_per_row)
    names = _parse_class_names(class_name)
    if not names:
        raise ValueError("--class-name is needed: ID=NAME of the labelled region to add")
    if not 1.0 <= n <= 1.6:
        raise ValueError(f"--n must be in 1.0-1.6 (a liquid or tissue against air), got {n:g}")
    if depth_mm is not None and not (np.isfinite(depth_mm) and 0.0 < depth_mm <= 10_000.0):
        raise ValueError(f"--depth-mm must be a depth in (0, 10000] mm, got {depth_mm:g}")
    if not 0.0 < white_albedo <= 1.0:
        raise ValueError(f"--white-albedo must be in (0, 1], got {white_albedo:g}")
    in_place = library is not None and _same_place(Path(out_json), Path(library))
    if in_place and not overwrite:  # updating the library itself: a planeray library, replaced atomically
        raise ValueError(
            f"--out {out_json} is the --library to add to: pass --overwrite to update it in place (planeray replaces "
            "only a library it wrote), or name a new --out"
        )
    _check_outputs(
        (out_json, "media library"),
        overwrite=overwrite,
        inputs=[("the capture", input_path), ("--labels", labels), ("--white-reference", white_reference)]
        + ([] if in_place else [("--library", library)]),
    )
    lib = _library(library)
    H, W, rpc = _capture_geometry(input_path)  # the labels and the resolution before any demultiplexing
    lab = _read_labels(labels, "--labels", (H, W))
    missing = [f"{c}={nm}" for c, nm in names.items() if not (lab == c).any()]
    if missing:
        raise ValueError(f"--class-name {', '.join(missing)}: --labels {labels} has no pixel of that id")
    if lib.physical:
        from ..camera import CameraModel

        if planeray_output_kind(input_path) == "transport":
            raise ValueError(
                f"{input_path} is a transport store: a library of physical parameters is measured from a stack's "
                "images (give the stack)"
            )
        stack, meta, mm = _stack_and_row_size(input_path, mm_per_row)
        white = _load_stack(white_reference) if white_reference is not None else None
    else:
        lib_rpc = lib.conditions.get("rows_per_camera_row")
        if lib.entries and isinstance(lib_rpc, (int, float)) and abs(rpc / lib_rpc - 1.0) > 0.1:
            raise ValueError(
                f"--library {library or '(the shipped one)'}: a version-1 library's media were fitted at {lib_rpc:g} "
                f"projector rows per camera row, {input_path} has {rpc:g}: its fits are bound to their resolution, "
                "so an entry from this capture would not be comparable with the others; start a library of "
                "physical parameters (version 2) instead"
            )
        lib, transport, meta, mm = _library_and_capture(library, input_path, mm_per_row, lib=lib)
    try:
        if lib.physical:
            table = _forward_table(n)
            with console.status("measuring the labelled regions (each fitted as a whole, walls modelled)"):
                entries = entries_from_stack(
                    stack, lab, names, mm_per_row=mm, n=n, depth_mm=depth_mm, camera=CameraModel.from_metadata(meta),
                    white=white, white_albedo=white_albedo, table=table, source=f"{input_path} ({labels})",
                )  # fmt: skip
        else:
            block = int(lib.conditions.get("block_px", 2))
            regions = np.where(np.isin(lab, list(names)), lab, 0)
            with console.status("fitting the labelled regions"):
                maps = fit_image(transport, mm_per_row=mm, block_px=block, regions=regions)
            entries = entries_from_capture(maps, regions, names, source=f"{input_path} ({labels})")
        for e in entries:
            lib = lib.add(e, replace=replace)
    except InputError as exc:
        raise ValueError(f"--class-name {exc}") from None
    save_library(lib, out_json)
    out.print(f"library: {out_json}  ({len(lib.entries)} media)")
    for e in entries:
        f = lambda v: "n/a" if v is None else f"{v:.4g}"  # noqa: E731
        if lib.physical:
            sa = "" if e.mu_a_log_sd is None else f" (+- {100 * e.mu_a_log_sd:.0f} %)"
            out.print(
                f"  added {e.name} (class {e.class_id}): mu_s' {f(e.mu_s_prime_per_mm)} /mm (+- "
                f"{100 * e.mu_s_prime_log_sd:.1f} %), mu_a {f(e.mu_a_per_mm)} /mm{sa}, n {e.n:g}"
                + ("" if e.depth_mm is None else f", a {e.depth_mm:g} mm layer"),
                highlight=False,
            )
            continue
        out.print(
            f"  added {e.name} (class {e.class_id}): mu_s' {f(e.mu_s_prime_per_mm)} /mm (log sd "
            f"{e.mu_s_prime_log_sd:.2f}), mu_a {f(e.mu_a_per_mm)} /mm, beyond the table: "
            f"{e.beyond_table['above']:.0%} above, {e.beyond_table['below']:.0%} below ({e.blocks} blocks)",
            highlight=False,
        )
