"""``planeray mc``: Monte Carlo subsurface scattering profiles (HG slab; line or point source; Sec. 5.2)."""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Annotated

import typer

from .._console import print_verbatim, progress_bar
from ..errors import InputError
from ..io.atomic import written_together
from . import _limits as lim
from ._common import _check_outputs, _friendly_errors

#: Largest scattering or absorption coefficient (1/mm): a mean free path of 0.1 micrometre.
MAX_COEFFICIENT = 1e4
#: Longest length (mm): a kilometre.
MAX_MM = 1e6
#: Most photon packets of one run (1e10 takes hours).
MAX_PHOTONS = 10**10

mc_app = typer.Typer(help="Monte Carlo subsurface scattering (HG slab, line source).", no_args_is_help=True)


@mc_app.command("profile")
@_friendly_errors(options={"n_photons": "--photons", "offsets_rows": "--rows", "mm_per_bin": "--mm-per-row"})
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
    overwrite: Annotated[
        bool, typer.Option(help="Replace the CSV, its JSON and the plot a previous run wrote (only those).")
    ] = False,
):
    """Line-source (or --point) exit profile of a homogeneous HG medium (Sec. 5.2), with Monte Carlo errors.

    Writes the CSV (``--out``; its first line is planeray's mark, a ``#`` comment), its
    JSON sidecar (same name, ``.json``) and, with ``--plot``, a PNG; all three are checked
    before any photon is traced.
    """
    import time

    import numpy as np

    from ..mc import mc_line_profile, mc_point_profile
    from ..mc.report import write_profile
    from ..medium import Medium

    if out_path.suffix.lower() != ".csv":
        raise InputError(f"--out must end in .csv (the JSON sidecar goes beside it), got {out_path.name}")
    if plot is not None and plot.suffix.lower() != ".png":
        raise InputError(f"--plot must end in .png, got {plot.name}")
    _check_outputs(
        (out_path, "table"), (out_path.with_suffix(".json"), "record"), (plot, "figure"), overwrite=overwrite
    )
    _check_mc_options(
        sigma_s=sigma_s, sigma_a=sigma_a, n=n, thickness_mm=thickness_mm, photons=photons, rows=rows,
        mm_per_row=mm_per_row, source_width_mm=source_width_mm, cutoff_mm=cutoff_mm,
        diffusion_depth_mfp=diffusion_depth_mfp, seed=seed,
    )  # fmt: skip
    t0 = time.perf_counter()
    thickness = np.inf if thickness_mm is None else thickness_mm
    medium = Medium(sigma_s=sigma_s, sigma_a=sigma_a, g=g, n=n, thickness_mm=thickness)
    with progress_bar() as bar:
        task = bar.add_task("photons", total=photons)
        advance = partial(bar.advance, task)
        if point:
            prof = mc_point_profile(
                medium, n_photons=photons, radius_bins=np.arange(0, rows + 1), mm_per_bin=mm_per_row, seed=seed,
                cache=cache, cutoff_mm=cutoff_mm, progress=advance,
            )  # fmt: skip
        else:
            prof = mc_line_profile(
                medium, n_photons=photons, offsets_rows=np.arange(-rows, rows + 1), mm_per_row=mm_per_row, seed=seed,
                cache=cache, source_width_mm=source_width_mm, cutoff_mm=cutoff_mm,
                diffusion_depth_mfp=diffusion_depth_mfp or None, progress=advance,
            )  # fmt: skip
    dt = time.perf_counter() - t0
    with written_together(out_path, out_path.with_suffix(".json"), plot):  # the three, or none of them
        csv_path, json_path = write_profile(prof, out_path)
        if plot is not None:
            from ..figures.mc import mc_profile_figure

            mc_profile_figure(prof, out=plot)
    print_verbatim(
        f"diffuse reflectance {prof.total_reflectance:.5f} +- {prof.total_reflectance_stderr:.5f}, "
        f"specular {prof.specular_reflectance:.5f}, transmitted {prof.transmittance:.5f}, "
        f"absorbed {prof.absorbed:.5f}, truncated {prof.truncated:.5f}"
    )
    print_verbatim(f"{prof.n_interactions / max(prof.n_photons, 1):.0f} collisions per photon, {dt:.1f} s")
    print_verbatim(f"  {csv_path}\n  {json_path}")
    if plot is not None:
        print_verbatim(f"  {plot}")


def _check_mc_options(*, sigma_s, sigma_a, n, thickness_mm, photons, rows, mm_per_row, source_width_mm, cutoff_mm,
                      diffusion_depth_mfp, seed) -> None:  # fmt: skip
    """The medium's and the run's options of ``mc profile``, each in its range (one line naming it)."""
    for option, value in (("--sigma-s", sigma_s), ("--sigma-a", sigma_a)):
        lim.nonnegative(value, option, maximum=MAX_COEFFICIENT)
    lim.number(n, "--n", minimum=0.1, maximum=10.0)
    if thickness_mm is not None and thickness_mm != float("inf"):
        lim.positive(thickness_mm, "--thickness-mm", maximum=MAX_MM)
    lim.integer(photons, "--photons", minimum=1, maximum=MAX_PHOTONS)
    lim.integer(rows, "--rows", minimum=0, maximum=100_000)
    lim.positive(mm_per_row, "--mm-per-row", maximum=1_000.0)
    lim.nonnegative(source_width_mm, "--source-width-mm", maximum=1_000.0)
    lim.optional(lim.positive, cutoff_mm, "--cutoff-mm", maximum=MAX_MM)
    lim.nonnegative(diffusion_depth_mfp, "--diffusion-depth-mfp", maximum=1e6)
    lim.seed(seed)
