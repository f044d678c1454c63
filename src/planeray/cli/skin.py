"""``planeray skin``: seeing veins through skin (Sec. 10, Figs. 13, 14, 16).

``simulate`` (a capture of the skin scene with its ground truth beside it), ``validate`` (the
fast vein model against brute-force Monte Carlo, the layers against adding-doubling), ``veins``
(the short-range indirect delay image of a stack, and its metrics on a vein mask), ``enhance``
(Eq. 7's contrast enhancement over a stack's delay images), ``compare`` (the whole study on the
simulated skin scene: methods, ambient light, best delay against depth, Eq. 7).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from .._console import console, out, progress_bar
from ._common import StackArg, _check_outputs, _friendly_errors, _load_stack

skin_app = typer.Typer(
    help="Skin and veins (Sec. 10): simulate captures, check the physics, vein images and metrics, Eq. 7.",
    no_args_is_help=True,
)


def _tone(text: str):
    try:
        return float(text)
    except ValueError:
        return text


@skin_app.command("simulate")
@_friendly_errors
def simulate(
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Stack to write (Zarr directory); truth beside it.")],
    tone: Annotated[
        str, typer.Option(help="Skin tone: very_fair, fair, medium, olive, brown, dark or a melanin fraction.")
    ] = "fair",
    wavelength: Annotated[int, typer.Option("--wavelength", "--wavelength-nm", help="638 (red) or 850 (nm).")] = 638,
    ambient_e_per_us: Annotated[
        float,
        typer.Option("--ambient-e-per-us", "--ambient", help="Ambient light, electrons per us of exposure (albedo 1)."),
    ] = 0.5,
    hair: Annotated[bool, typer.Option(help="Hair strands on the skin.")] = False,
    curved: Annotated[
        bool, typer.Option(help="A cylindrical forearm on a dark cloth instead of a flat patch.")
    ] = False,
    size: Annotated[tuple[int, int], typer.Option(help="Image size H W (camera pixels).")] = (128, 128),
    projector_rows: Annotated[int, typer.Option(help="Projector rows spanned by the image.")] = 720,
    mm_per_row: Annotated[float, typer.Option(help="Size of a projector row on the skin (mm).")] = 0.3,
    seed: Annotated[int, typer.Option(help="Seed of the veins, hair, textures and camera noise.")] = 0,
    sweep: Annotated[str, typer.Option(help="Named delay-exposure sweep: paper (85 images) or quick.")] = "paper",
    noise: Annotated[bool, typer.Option(help="Simulate noise (--no-noise: expected images).")] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace existing outputs (only ones planeray wrote).")] = False,
):
    """Simulate a delay-exposure sweep of the skin scene; writes STACK and STEM_vein_mask.png, STEM_veins.json, STEM_maps.npz."""
    from ..camera import CameraModel
    from ..experiments.skin_capture import simulate_skin
    from ..timing import make_sweep

    n = len(make_sweep(sweep))
    with progress_bar() as bar:
        task = bar.add_task(f"skin {size[0]}x{size[1]}: capturing {n} images", total=n)
        cap = simulate_skin(
            out_path,
            size=size,
            projector_rows=projector_rows,
            seed=seed,
            sweep=sweep,
            camera=CameraModel(ambient_e_per_us=ambient_e_per_us),
            noise=noise,
            overwrite=overwrite,
            progress=lambda i: bar.advance(task),
            tone=_tone(tone),
            wavelength_nm=wavelength,
            hair=hair,
            curved=curved,
            mm_per_row=mm_per_row,
        )
    for v in cap.scene.params["veins"]:
        console.print(
            f"vein {v['id']}: top {v['depth_mm']:.2f} mm deep, {v['diameter_mm']:.2f} mm wide"
            + (f", branch of {v['parent']}" if v["parent"] else "")
        )
    for key in ("stack", "mask", "veins", "maps"):
        out.print(f"{key}: {cap.paths[key]}")


@skin_app.command("validate")
@_friendly_errors
def validate(
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder for skin_validation.json and .png.")],
    n_photons: Annotated[int, typer.Option(help="Photons per brute-force run.")] = 200_000,
    wavelength: Annotated[int, typer.Option("--wavelength", "--wavelength-nm", help="638 (red) or 850 (nm).")] = 638,
):
    """Check the fast vein model against brute-force Monte Carlo and the layers against adding-doubling."""
    from ..experiments.skin_physics import DARK_CASES, VALIDATION_CASES, run_skin_validation

    with progress_bar() as bar:
        task = bar.add_task("brute-force Monte Carlo", total=len(VALIDATION_CASES) + len(DARK_CASES))
        rep = run_skin_validation(
            out_dir, n_photons=n_photons, wavelength_nm=wavelength, progress=lambda k: bar.advance(task, k)
        )
    for r in rep["cases"]:
        out.print(
            f"{r['angle_deg']:>4.0f} deg top {r['depth_mm']:g} mm D {r['diameter_mm']:g} mm rho {r['rho_rows']:+.0f}: "
            f"short-range contrast {r['short_brute']:.3f} (brute) {r['short_fast']:.3f} (fast)"
        )
    for r in rep["dark_skin_cases"]:
        out.print(
            f"dark skin, {r['angle_deg']:.0f} deg top {r['depth_mm']:g} mm: short-range contrast "
            f"{r['short_brute']:.3f} (brute) {r['short_fast']:.3f} (fast)"
        )
    ad = rep["adding_doubling"]
    out.print(
        f"diffuse reflectance: Monte Carlo {ad['mc']:.4f} +- {ad['mc_stderr']:.4f}, adding-doubling {ad['ad']:.4f}"
    )
    out.print(f"written: {out_dir / 'skin_validation.json'}, {out_dir / 'skin_validation.png'}")


MaskOpt = Annotated[
    Path | None,
    typer.Option(
        "--mask",
        help="Vein mask (PNG/TIFF, image size; 0 skin, nonzero vein; several values = vein ids) for the metrics "
        "(default: the ground truth `planeray skin simulate` wrote beside the stack, if any).",
    ),
]


def _truth_for(stack, stack_path: Path, mask: Path | None):
    """Ground truth for the metrics: ``--mask``, else the truth ``planeray skin simulate`` wrote beside the stack.

    Returns None (no metrics), or a dict with ``vein_id`` and, from a simulated capture,
    ``exclude`` (hair, off the skin), ``depth_mm``, ``diameter_mm`` and ``source``.
    """
    if mask is not None:
        from ..skin.masks import read_vein_mask

        return {"vein_id": read_vein_mask(mask, stack.shape), "source": str(mask)}
    from ..experiments.skin_capture import read_skin_truth, truth_paths

    if not truth_paths(stack_path)["veins"].is_file():
        return None
    _, maps = read_skin_truth(stack_path)
    exclude = maps.get("hair")
    if "skin" in maps:
        off = ~np.asarray(maps["skin"], bool)
        exclude = off if exclude is None else np.asarray(exclude, bool) | off
    if tuple(maps["vein_id"].shape) != tuple(stack.shape):
        raise ValueError(f"{truth_paths(stack_path)['maps']}: ground truth of another image size than the stack")
    return {
        "vein_id": maps["vein_id"],
        "exclude": exclude,
        "depth_mm": maps.get("vein_depth_mm"),
        "diameter_mm": maps.get("vein_diameter_mm"),
        "source": str(truth_paths(stack_path)["maps"]),
    }


def _metrics(image, truth):
    from ..skin.metrics import vein_metrics

    return vein_metrics(
        image,
        truth["vein_id"],
        exclude=truth.get("exclude"),
        depth_mm=truth.get("depth_mm"),
        diameter_mm=truth.get("diameter_mm"),
    )


def _write_png(path: Path, image, valid=None) -> None:
    from PIL import Image

    from ..io import atomic_file

    img = np.asarray(image, np.float64)
    vals = img[valid] if valid is not None else img.ravel()
    vals = vals[np.isfinite(vals)]
    lo, hi = np.percentile(vals, [1, 99]) if vals.size else (0.0, 1.0)
    shown = np.clip((img - lo) / (hi - lo if hi > lo else 1.0), 0, 1)
    with atomic_file(path) as tmp:
        Image.fromarray((np.nan_to_num(shown) * 255 + 0.5).astype(np.uint8)).save(tmp, format="PNG")


def _write_tiff(path: Path, image) -> None:
    import tifffile

    from ..io import atomic_file

    with atomic_file(path) as tmp:
        tifffile.imwrite(tmp, np.asarray(image, np.float32), photometric="minisblack")


def _metrics_rows(name, m):
    return [{"image": name, **r} for r in m["veins"]]


def _write_csv(path: Path, rows) -> None:
    import csv

    from ..io import atomic_file

    with atomic_file(path) as tmp, open(tmp, "w", newline="") as f:
        if rows:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)


def _num(x) -> str:
    return "n/a" if x is None else f"{x:.2f}"


def _summary(m) -> dict:
    return {k: m[k] for k in ("cnr", "weber", "n_veins", "n_detected")}


@skin_app.command("veins")
@_friendly_errors
def veins(
    stack_path: StackArg,
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder to write (images, metrics, figure).")],
    delay_us: Annotated[float, typer.Option("--delay-us", "--delay", help="Delay of the vein image (us).")] = 500.0,
    exposure_us: Annotated[
        float | None, typer.Option("--exposure-us", "--exposure", help="Exposure (us); default the stack's shortest.")
    ] = None,
    mask: MaskOpt = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an output folder planeray wrote.")] = False,
):
    """The short-range indirect vein image of a stack (+ the epipolar image), and CNR per vein with a mask."""
    from ..figures.skin import headline_figure
    from ..io import atomic_directory
    from ..io.atomic import MARKER
    from ..skin.imaging import delay_band_mm, stack_images

    _check_outputs((out_dir, "skin veins"), overwrite=overwrite)
    stack = _load_stack(stack_path)
    truth = _truth_for(stack, stack_path, mask)
    images, info = stack_images(stack, delay_us=delay_us, exposure_us=exposure_us)
    mpr = float(stack.metadata.get("scene", {}).get("mm_per_row", 0.3)) if isinstance(stack.metadata, dict) else 0.3
    near, far = delay_band_mm(
        info["delay_us"], info["exposure_us"], lines_per_second=stack.lines_per_second, mm_per_row=mpr
    )
    result = {
        "format": "planeray-skin-veins",
        "format_version": 1,
        "stack": str(stack_path),
        **info,
        "band_mm": [float(near), float(far)],
        "mm_per_row": mpr,
    }
    metrics = None
    if truth is not None:
        metrics = {k: _metrics(v, truth) for k, v in images.items()}
        result["metrics"] = {k: _summary(m) for k, m in metrics.items()}
        result["ground_truth"] = truth["source"]
    with atomic_directory(out_dir, overwrite=overwrite, kind="skin veins") as tmp:
        for k, img in images.items():
            _write_png(tmp / f"{k}.png", img)
            _write_tiff(tmp / f"{k}.tif", img)
        if metrics is not None:
            _write_csv(tmp / "veins.csv", [r for k, m in metrics.items() for r in _metrics_rows(k, m)])
        headline_figure(images, metrics=metrics, out=tmp / "veins_figure.png")
        (tmp / MARKER).write_text(json.dumps(result, indent=1))
    out.print(
        f"{out_dir}: delay image at {info['delay_us']:g} us, exposure {info['exposure_us']:g} us "
        f"(light that entered {near:.1f}-{far:.1f} mm away)"
    )
    if metrics is not None:
        for k, m in metrics.items():
            cnr = "n/a" if m["cnr"] is None else f"{m['cnr']:.2f}"
            out.print(f"  {k}: CNR {cnr}, {m['n_detected']}/{m['n_veins']} veins detected (per-vein CNR >= 1)")


@skin_app.command("enhance")
@_friendly_errors
def enhance(
    stack_path: StackArg,
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder to write (enhanced image, delay map).")],
    exposure_us: Annotated[
        float | None, typer.Option("--exposure-us", "--exposure", help="Exposure of the delay images (us).")
    ] = None,
    min_delay_us: Annotated[float, typer.Option("--min-delay-us", help="Use only delays above this (us).")] = 0.0,
    patch_px: Annotated[
        int | None, typer.Option("--patch-px", help="Patch size (default 200 px per 720 rows).")
    ] = None,
    plain: Annotated[
        bool, typer.Option("--plain", help="The paper's plain gradient argmax (no noise weighting).")
    ] = False,
    mask: MaskOpt = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an output folder planeray wrote.")] = False,
):
    """Contrast enhancement from the stack's delay images (Eq. 7, Fig. 14)."""
    from ..io import atomic_directory
    from ..io.atomic import MARKER
    from ..skin.enhance import enhance_contrast
    from ..skin.imaging import delay_sweep_images

    _check_outputs((out_dir, "skin enhance"), overwrite=overwrite)
    stack = _load_stack(stack_path)
    truth = _truth_for(stack, stack_path, mask)
    with console.status("reading the delay images"):
        imgs, delays = delay_sweep_images(stack, exposure_us=exposure_us, min_delay_us=min_delay_us)
    with console.status(f"enhancing ({len(delays)} delay images)"):
        res = enhance_contrast(imgs, delays, patch_px=patch_px, noise_normalize=not plain)
    result = {
        "format": "planeray-skin-enhance",
        "format_version": 1,
        "stack": str(stack_path),
        "delays_us": [float(d) for d in delays],
        "params": res.params,
    }
    if truth is not None:
        single = {f"{d:g}": _metrics(im, truth) for d, im in zip(delays, imgs)}
        best = max(single, key=lambda k: -np.inf if single[k]["cnr"] is None else single[k]["cnr"])
        em = _metrics(res.image, truth)
        result["ground_truth"] = truth["source"]
        result["metrics"] = {
            "enhanced": _summary(em),
            "best_single": {"delay_us": float(best), **_summary(single[best])},
        }
    with atomic_directory(out_dir, overwrite=overwrite, kind="skin enhance") as tmp:
        _write_png(tmp / "enhanced.png", res.image)
        _write_tiff(tmp / "enhanced.tif", res.image)
        _write_tiff(tmp / "delay_map_us.tif", res.delay_map_us)
        _write_png(tmp / "delay_map.png", res.delay_map_us)
        (tmp / MARKER).write_text(json.dumps(result, indent=1))
    out.print(f"{out_dir}: enhanced from {len(delays)} delay images ({delays[0]:g}-{delays[-1]:g} us)")
    if truth is not None:
        e, b = result["metrics"]["enhanced"], result["metrics"]["best_single"]
        out.print(
            f"  enhanced: CNR {_num(e['cnr'])}, {e['n_detected']}/{e['n_veins']} veins; best single delay "
            f"({b['delay_us']:g} us): CNR {_num(b['cnr'])}, {b['n_detected']}/{b['n_veins']} veins"
        )


@skin_app.command("compare")
@_friendly_errors
def compare(
    out_dir: Annotated[
        Path, typer.Option("--out", "-o", help="Folder for the figures (Figs. 13, 14, 16) and skin.json.")
    ],
    size: Annotated[int, typer.Option(help="Image size (size x size of a 720-row projector).")] = 128,
    quick: Annotated[bool, typer.Option(help="Two conditions, four ambient levels, fewer delays.")] = False,
    seed: Annotated[int, typer.Option(help="Seed of the scenes and the camera noise.")] = 0,
    delay_us: Annotated[
        float, typer.Option("--delay-us", help="Delay of the short-range indirect image (us).")
    ] = 500.0,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing report folder planeray wrote.")] = False,
):
    """The Fig. 13/14/16 study end to end on the simulated skin scene: writes figures, CSV tables and skin.json."""
    from ..experiments.skin import compare_steps, run_skin_compare
    from ..io.atomic import check_replaceable

    check_replaceable(out_dir, overwrite=overwrite, kind="skin report")
    with progress_bar() as bar:
        task = bar.add_task("skin study", total=compare_steps(quick))

        def progress(msg):
            bar.update(task, advance=1, description=msg)

        numbers = run_skin_compare(
            out_dir, size=size, quick=quick, seed=seed, delay_us=delay_us, overwrite=overwrite, progress=progress
        )
    out.print(f"report: {out_dir}  ({numbers['seconds']:.0f} s)")
    for row in numbers["table"]:
        cnr = "n/a" if row["cnr"] is None else f"{row['cnr']:.2f}"
        out.print(
            f"  {row['condition']:<22} {row['method']:<13} CNR {cnr:>6}  {row['n_detected']}/{row['n_veins']} veins"
        )
    e = numbers["enhancement"]
    if e.get("gain") is not None:
        out.print(
            f"  Eq. 7 enhancement: CNR {_num(e['enhanced_cnr'])} vs best single delay {_num(e['best_single_cnr'])}"
        )
