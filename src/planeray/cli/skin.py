"""``planeray skin``: the skin-and-veins scene (Sec. 10): simulate a capture, check its physics."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._console import console, out, progress_bar
from ._common import _friendly_errors

skin_app = typer.Typer(help="Skin and veins (Sec. 10): simulate captures of the skin scene.", no_args_is_help=True)


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
