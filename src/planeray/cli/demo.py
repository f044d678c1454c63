"""``planeray demo``: the newcomer's first run (what ``make demo`` calls)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .._console import out, progress_bar
from ._common import _friendly_errors


@_friendly_errors
def demo(
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("out"),
    size: Annotated[int, typer.Option(help="Image size (square, camera pixels).")] = 128,
    seed: Annotated[int, typer.Option(help="Seed.")] = 0,
):
    """The newcomer's first run: simulate the paper's sweep and look at it."""
    from ..demo import run_demo

    run_demo(out_dir, size=size, seed=seed, console=out, progress=progress_bar)
