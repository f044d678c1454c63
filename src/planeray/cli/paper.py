"""``planeray paper``: every figure of the paper planeray can reproduce, one resumable step each, and a report."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._console import console, print_verbatim, progress_bar
from . import _limits as lim
from ._common import _claim, _friendly_errors


@_friendly_errors
def paper(
    out_dir: Annotated[
        Path, typer.Option("--out", "-o", help="Folder of the run: figures, numbers.json, report.md, report.html.")
    ],
    quick: Annotated[
        bool, typer.Option(help="Small images, reduced grids, fewer photons (about 2 minutes on 2 cores).")
    ] = False,
    size: Annotated[
        int | None,
        typer.Option(help="Image size of every step (square, camera pixels, 16 to 1024; effect labels: 64 to 256)."),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the scenes and noise of the steps that take one.")] = 0,
    overwrite: Annotated[
        bool, typer.Option(help="Start again over a run of other options (only a folder `planeray paper` wrote).")
    ] = False,
):
    """Reproduce Figs. 4, 5, 6, 8-16 and the effect labels: figures, numbers and a report beside the paper's.

    One step per experiment (Figs. 5-6 and Figs. 13, 14, 16 come from one study each), each calling the code of the figure's own command. A killed run started again with the same options continues with the steps not done; other options are refused (--overwrite starts again). Prints the report's paths on stdout.
    """

    from ..experiments.reproduce import MAX_SIZE, MIN_SIZE, STEPS, plan_paper_run, run_paper, step_work

    lim.folder(out_dir, "--out")
    lim.optional(lim.integer, size, "--size", minimum=MIN_SIZE, maximum=MAX_SIZE)
    lim.seed(seed)
    _claim(out_dir)  # writable, and no other run writing it
    plan = plan_paper_run(out_dir, quick=quick, size=size, seed=seed, overwrite=overwrite)  # before any work
    if plan.done:
        console.print(
            f"resuming {out_dir}: {len(plan.done)} of {len(STEPS)} steps already done ({', '.join(plan.done)})",
            highlight=False,
            markup=False,
        )
    settings = plan.manifest["settings"]
    total = sum(step_work(name, settings[name]) for name in plan.todo)
    with progress_bar() as bar:
        task = bar.add_task("paper", total=total)

        def progress(event, **info):
            if event == "step":
                bar.update(task, description=f"{info['name']}: {info['title']}")
            elif event == "advance":
                bar.advance(task, info["n"])
            elif event == "done":
                console.print(f"  {info['name']} done ({info['seconds']:g} s)", highlight=False, markup=False)

        result = run_paper(
            out_dir, quick=quick, size=size, seed=seed, overwrite=overwrite, progress=progress, plan=plan
        )
        bar.update(task, completed=total)
    for f in result["files"]:
        print_verbatim(f)
