"""``planeray skin``: skin imaging (Sec. 10).  The pulse commands live in :mod:`planeray.cli.pulse`."""

from __future__ import annotations

import typer

skin_app = typer.Typer(
    help="Skin imaging (Sec. 10): veins, contrast enhancement, the pulse (Fig. 15).",
    no_args_is_help=True,
)
