"""``planeray materials``: recognizing subsurface-scattering materials from delay profiles (Sec. 8, Fig. 10)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from .._console import console, out, progress_bar
from ._common import _friendly_errors, _load_stack

materials_app = typer.Typer(
    help="Material recognition from delay profiles (Sec. 8, Fig. 10): simulate, train, predict, report.",
    no_args_is_help=True,
)


@materials_app.command("classes")
@_friendly_errors
def classes(
    source: Annotated[str, typer.Option(help="Optical data of the milks: narasimhan or jensen.")] = "narasimhan",
    channel: Annotated[str, typer.Option(help="Laser colour: red, green or blue.")] = "red",
):
    """The documented class ids of label images and the simulated media."""
    from ..optical_data import BACKGROUND_CLASS, CLASS_NAMES, UNLABELLED, optical_table

    rows = {r["class_id"]: r for r in optical_table(source=source, channel=channel)}
    out.print(f"class ids of label images (media: {source}, {channel} laser line):")
    out.print(f"  {UNLABELLED}  unlabelled: not trained on, not scored")
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
    size: Annotated[tuple[int, int], typer.Option(help="Image size H W (camera pixels).")] = (128, 128),
    projector_rows: Annotated[int, typer.Option(help="Projector rows spanned by the image (0.3 mm each).")] = 720,
    seed: Annotated[int, typer.Option(help="Seed of the camera noise and the table's texture.")] = 0,
    placement: Annotated[int, typer.Option(help="0: materials in class order; k >= 1: shuffled and moved.")] = 0,
    container: Annotated[str, typer.Option(help="tray (rectangular) or cup (round).")] = "tray",
    wall: Annotated[str, typer.Option(help="Container walls: fresnel (clear) or absorbing (black).")] = "fresnel",
    source: Annotated[str, typer.Option(help="Optical data of the milks: narasimhan or jensen.")] = "narasimhan",
    channel: Annotated[str, typer.Option(help="Laser colour: red, green or blue.")] = "red",
    noise: Annotated[float, typer.Option(help="Noise factor: x the default camera's shot and read noise.")] = 1.0,
    ambient_e_per_us: Annotated[
        float,
        typer.Option("--ambient-e-per-us", "--ambient", help="Ambient light, electrons per us of exposure (albedo 1)."),
    ] = 0.5,
    sweep: Annotated[str, typer.Option(help="Named sweep: paper (85 images) or quick.")] = "paper",
    overwrite: Annotated[bool, typer.Option(help="Replace an existing capture folder planeray wrote.")] = False,
):
    """Simulate a capture of the five containers (milks, toothpaste, soap) with its labels."""
    from ..experiments.materials import simulate_capture
    from ..io.atomic import check_replaceable
    from ..timing import make_sweep

    check_replaceable(out_dir, overwrite=overwrite, kind="materials capture")
    n = len(make_sweep(sweep))
    with progress_bar() as bar:
        task = bar.add_task(f"building the scene, capturing {n} images", total=n)
        cap = simulate_capture(
            out_dir,
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
            overwrite=overwrite,
            progress=lambda i: bar.advance(task),
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
            raise ValueError(f"--class-name expects ID=NAME (e.g. 1='fat-free milk'), got {item!r}")
        names[int(key)] = name.strip()
    return names


@materials_app.command("train")
@_friendly_errors
def train(
    stacks: Annotated[list[Path], typer.Argument(help="Training stacks (Zarr or import folder), one or more.")],
    labels: Annotated[list[Path], typer.Option("--labels", help="Label image per stack (PNG/TIFF of class ids).")],
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Model file to write (a zip: JSON + skops).")],
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
    max_per_class: Annotated[int, typer.Option(help="Training pixels per class and capture.")] = 400,
    cv_folds: Annotated[int, typer.Option(help="Cross-validation folds (grouped by capture).")] = 4,
    seed: Annotated[int, typer.Option(help="Seed of the pixel sampling.")] = 0,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing model file planeray wrote.")] = False,
):
    """Train the per-pixel RBF-SVM on labelled captures (hyper-parameters by grouped cross-validation)."""
    from ..io.atomic import ALREADY_EXISTS
    from ..materials import read_label_image, train_model
    from ..materials.features import FLOORS
    from ..materials.model import _is_model_file

    if out_path.exists() and (not overwrite or not _is_model_file(out_path)):
        raise ValueError(f"{out_path}: {ALREADY_EXISTS}" if not overwrite else f"{out_path}: is not a planeray model")
    if floor not in FLOORS:
        raise ValueError(f"--floor {floor!r}: choose one of {', '.join(FLOORS)}")
    if len(labels) != len(stacks):
        raise ValueError(f"{len(stacks)} stacks but {len(labels)} --labels: give one label image per stack, in order")
    names = _parse_class_names(class_name)
    loaded = [_load_stack(p) for p in stacks]
    labs = [read_label_image(lp, shape=st.shape) for lp, st in zip(labels, loaded)]
    with progress_bar() as bar:
        task = bar.add_task(f"features of {len(stacks)} capture(s)", total=len(stacks))
        with console.status("cross-validating the SVM"):
            model = train_model(
                loaded,
                labs,
                kind=features,
                floor=floor,
                class_names=names,
                ignore_classes=tuple(ignore_class or ()),
                max_per_class=max_per_class,
                cv_folds=cv_folds,
                seed=seed,
                sources=[str(p) for p in stacks],
                progress=lambda n: bar.advance(task),
            )
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
    out_png: Annotated[Path, typer.Option("--out", "-o", help="Segmentation map: palette PNG of class ids (or TIFF).")],
    labels: Annotated[
        Path | None, typer.Option("--labels", help="Ground-truth label image: score the prediction.")
    ] = None,
    near_wall: Annotated[
        Path | None, typer.Option("--near-wall", help="Mask of pixels near walls (non-zero): scored apart.")
    ] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the numbers as JSON on stdout.")] = False,
):
    """Segment a capture pixel by pixel with a trained model (refused if the sweep differs)."""
    from ..experiments._report import jsonable
    from ..experiments.materials import score
    from ..materials import load_model, read_label_image, write_label_image

    model = load_model(model_path)
    st = _load_stack(stack_path)
    with console.status("classifying pixels"):
        seg = model.predict(st, source=str(stack_path))
    write_label_image(out_png, seg)
    counts = {
        model.classes.get(int(c), f"class {int(c)}") if c else "no profile": int((seg == c).sum())
        for c in sorted(set(seg.ravel().tolist()))
    }
    numbers = {
        "segmentation": str(out_png),
        "pixels": counts,
        "model": str(model_path),
        "features": model.definition.describe(),
    }
    if labels is not None:
        truth = read_label_image(labels, shape=st.shape)
        near = read_label_image(near_wall, shape=st.shape) > 0 if near_wall is not None else None
        numbers["score"] = score(
            seg,
            truth,
            near_wall=near,
            classes=sorted(set(model.classes) | {int(c) for c in set(truth.ravel().tolist()) if c}),
            model_classes=sorted(model.classes),
        )
    if json_out:
        out.print_json(json.dumps(jsonable(numbers), allow_nan=False))
        return
    out.print(f"segmentation: {out_png}")
    for name, n in counts.items():
        out.print(f"  {name}: {n} px")
    if "score" in numbers:
        sc = numbers["score"]
        for name, acc in sc["accuracy"].items():
            if name in sc["not_scored"]:
                out.print(f"  accuracy {name}: not scored ({sc['not_scored'][name]})")
                continue
            extra = ""
            if "accuracy_near_wall" in sc:
                extra = (
                    f"  (near walls {_acc(sc['accuracy_near_wall'][name])}, away {_acc(sc['accuracy_interior'][name])})"
                )
            out.print(f"  accuracy {name}: {_acc(acc)}{extra}")


@materials_app.command("report")
@_friendly_errors
def report(
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder for the figures (Fig. 10) and materials.json.")],
    size: Annotated[int, typer.Option(help="Image size (size x size of a 720-row projector).")] = 128,
    quick: Annotated[bool, typer.Option(help="Fewer curve points, no Jensen or cup runs.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing report folder planeray wrote.")] = False,
):
    """The whole experiment end to end: simulate, train, test, curves, figures (Fig. 10b, c, d)."""
    from ..experiments.materials import run_materials_report
    from ..io.atomic import check_replaceable

    check_replaceable(out_dir, overwrite=overwrite, kind="materials report")
    with console.status("materials report") as status:
        numbers = run_materials_report(
            out_dir, size=size, quick=quick, overwrite=overwrite, progress=lambda msg: status.update(msg)
        )
    main = numbers["stack_profiles"]["floor_edge"]["test"]
    out.print(f"report: {out_dir}  ({numbers['seconds']:g} s)")
    for name, acc in main["accuracy"].items():
        out.print(
            f"  {name}: {_acc(acc)} (near walls {_acc(main['accuracy_near_wall'][name])}, "
            f"away {_acc(main['accuracy_interior'][name])})"
        )
    out.print(f"  share of the errors near walls: {main['errors']['share_near_wall']:.2f}")
