"""``planeray mc``: Monte Carlo subsurface scattering profiles (HG slab; line or point source; Sec. 5.2)."""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Annotated

import typer

from .._console import print_verbatim, progress_bar
from ._common import _friendly_errors

mc_app = typer.Typer(help="Monte Carlo subsurface scattering (HG slab, line source).", no_args_is_help=True)


@mc_app.command("profile")
@_friendly_errors
def mc_profile(
    out_path: Annotated[
        Path,
        typer.Option("--out", "-o", help="CSV of the binned profile (a .json of the totals is written next to it)."),
    ],
    sigma_s: Annotated[float, typer.Option("--sigma-s", help="Scattering coefficient (1/mm).")] = 1.0,
    sigma_a: Annotated[float, typer.Option("--sigma-a", help="Absorption coefficient (1/mm).")] = 0.0,
    g: Annotated[float, typer.Option("--g", help="Henyey-Greenstein anisotropy (-1, 1).")] = 0.9,
    n: Annotated[float, typer.Option("--n", help="Relative refractive index (1 = index matched).")] = 1.0,
    thickness_mm: Annotated[
        float | None, typer.Option("--thickness-mm", help="Slab thickness (mm); default semi-infinite.")
    ] = None,
    photons: Annotated[int, typer.Option(help="Photon packets.")] = 1_000_000,
    rows: Annotated[int, typer.Option(help="Bins -ROWS..ROWS (projector rows).")] = 114,
    mm_per_row: Annotated[float, typer.Option("--mm-per-row", help="Bin width on the surface (mm).")] = 1.0,
    source_width_mm: Annotated[
        float, typer.Option("--source-width-mm", help="Width of the lit strip (mm; 0 = ideal line).")
    ] = 0.0,
    cutoff_mm: Annotated[
        float | None,
        typer.Option("--cutoff-mm", help="Stop photons this far from the line (mm; default: automatic)."),
    ] = None,
    diffusion_depth_mfp: Annotated[
        float,
        typer.Option(
            "--diffusion-depth-mfp",
            help="Hand photons this many transport mean free paths deep to diffusion theory (0: trace every photon).",
        ),
    ] = 10.0,
    point: Annotated[
        bool,
        typer.Option(
            "--point", help="A point (pencil-beam) source: radial bins 0..ROWS of --mm-per-row (MCML's R_d(r))."
        ),
    ] = False,
    seed: Annotated[int, typer.Option(help="Random seed (same seed, same bytes).")] = 0,
    plot: Annotated[Path | None, typer.Option(help="Also write a PNG of the profile against the dipole.")] = None,
    cache: Annotated[bool, typer.Option(help="Reuse/keep the result in the on-disk cache.")] = True,
):
    """Line-source (or --point) exit profile of a homogeneous HG medium (Sec. 5.2), with Monte Carlo errors."""
    import time

    import numpy as np

    from ..mc import mc_line_profile, mc_point_profile
    from ..mc.report import write_profile
    from ..medium import Medium

    t0 = time.perf_counter()
    thickness = np.inf if thickness_mm is None else thickness_mm
    medium = Medium(sigma_s=sigma_s, sigma_a=sigma_a, g=g, n=n, thickness_mm=thickness)
    with progress_bar() as bar:
        task = bar.add_task("photons", total=photons)
        advance = partial(bar.advance, task)
        if point:
            prof = mc_point_profile(
                medium,
                n_photons=photons,
                radius_bins=np.arange(0, rows + 1),
                mm_per_bin=mm_per_row,
                seed=seed,
                cache=cache,
                cutoff_mm=cutoff_mm,
                progress=advance,
            )
        else:
            prof = mc_line_profile(
                medium,
                n_photons=photons,
                offsets_rows=np.arange(-rows, rows + 1),
                mm_per_row=mm_per_row,
                seed=seed,
                cache=cache,
                source_width_mm=source_width_mm,
                cutoff_mm=cutoff_mm,
                diffusion_depth_mfp=diffusion_depth_mfp or None,
                progress=advance,
            )
    dt = time.perf_counter() - t0
    csv_path, json_path = write_profile(prof, out_path)
    print_verbatim(
        f"diffuse reflectance {prof.total_reflectance:.5f} +- {prof.total_reflectance_stderr:.5f}, "
        f"specular {prof.specular_reflectance:.5f}, transmitted {prof.transmittance:.5f}, "
        f"absorbed {prof.absorbed:.5f}, truncated {prof.truncated:.5f}"
    )
    print_verbatim(f"{prof.n_interactions / max(prof.n_photons, 1):.0f} collisions per photon, {dt:.1f} s")
    print_verbatim(f"  {csv_path}\n  {json_path}")
    if plot is not None:
        from ..figures.mc import mc_profile_figure

        mc_profile_figure(prof, out=plot)
        print_verbatim(f"  {plot}")
