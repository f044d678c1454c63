"""``planeray study demux``: the Sec. 5.2 study of the demultiplexing method (Figs. 5, 6)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._console import print_verbatim, progress_bar
from ..errors import InputError
from . import _limits as lim
from ._common import _check_outputs, _friendly_errors

study_app = typer.Typer(help="Studies of the method (Sec. 5.2).", no_args_is_help=True)


@study_app.command("demux")
@_friendly_errors
def study_demux(
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder for the figures (PNG) and numbers (CSV, JSON).")],
    provider: Annotated[str, typer.Option(help="Scattering profiles: mc (Monte Carlo, cached) or dipole.")] = "mc",
    seeds: Annotated[int, typer.Option(help="Noise seeds per point.")] = 5,
    quick: Annotated[bool, typer.Option(help="Reduced grids.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace the files a previous run wrote (only those).")] = False,
    auto: Annotated[
        bool,
        typer.Option(help="Add the weights chosen by cross-validation (demux --alpha auto --beta auto) per profile."),
    ] = False,
):
    """Reconstruction quality of pinv, NNLS and the full method (Figs. 5, 6) and an alpha/beta sweep.

    Prints the findings (mean MSE per swept point) and the files written; all the
    numbers are in ``study.json``.  The folder may hold other files; the study's own files
    are checked before any work.
    """
    from ..experiments.study import run_study, study_outputs, study_report, study_work

    if provider not in ("mc", "dipole"):
        raise InputError(f"--provider must be mc or dipole, got {provider!r}")
    lim.integer(seeds, "--seeds", minimum=1, maximum=1_000)
    lim.folder(out_dir, "--out")
    _check_outputs(*((out_dir / name, kind) for name, kind in study_outputs()), overwrite=overwrite)

    with progress_bar() as bar:
        task = bar.add_task("study", total=study_work(quick=quick))
        numbers = run_study(
            out_dir,
            provider=provider,
            seeds=seeds,
            quick=quick,
            progress=lambda n: bar.advance(task, n),
            overwrite=overwrite,
            auto=auto,
        )
    for line in study_report(numbers):
        print_verbatim(line)
    print_verbatim("files:")
    for f in numbers["files"]:
        print_verbatim(f"  {f}")
