"""``planeray info``, ``export`` and ``import``: describe a stack, and move it to and from the import folder format."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from .._console import console, out, progress_bar
from ..errors import InputError
from . import _limits as lim
from ._common import StackArg, _check_outputs, _friendly_errors, _load_stack


@_friendly_errors
def info(
    stack_path: StackArg,
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable output.")] = False,
):
    """Describe a stack: size, sweep, timing, camera and scene parameters."""
    st = _load_stack(stack_path)
    summary = {
        "path": str(stack_path),
        "images": len(st),
        "shape": list(st.shape),
        "projector_rows": st.projector_rows,
        "lines_per_second": st.lines_per_second,
        "delays_us": st.delays().tolist(),
        "exposures_us": st.exposures().tolist(),
        "excluded": int(st.excluded.sum()),
        "used_for_demux": int((~st.excluded).sum()),
        "metadata": st.metadata,
    }
    if as_json:
        print(json.dumps(summary, indent=2, default=str))
        return
    table = Table(show_header=False)
    table.add_column(no_wrap=True)
    table.add_column(overflow="fold")  # a narrow terminal folds long values (paths), never cuts them
    for key in ("path", "images", "shape", "projector_rows", "lines_per_second", "excluded", "used_for_demux"):
        table.add_row(key, str(summary[key]))
    table.add_row("delays_us", f"{len(summary['delays_us'])}: {st.delays().min():g} .. {st.delays().max():g}")
    table.add_row("exposures_us", ", ".join(f"{e:g}" for e in summary["exposures_us"]))
    for key, value in st.metadata.items():
        table.add_row(key, json.dumps(value, default=str))
    out.print(table)


@_friendly_errors
def export(
    stack_path: StackArg,
    out_dir: Annotated[
        Path, typer.Option("--out", "-o", help="Folder to write (manifest.csv + images + acquisition.json).")
    ],
    fmt: Annotated[str, typer.Option("--format", help="tiff or png (16-bit grayscale).")] = "tiff",
    bit_depth: Annotated[int, typer.Option(help="Bits of the written codes.")] = 16,
    black_level: Annotated[int, typer.Option(help="Code of black (keeps small negative values).")] = 256,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing folder.")] = False,
):
    """Export a stack as 16-bit images + manifest.csv + acquisition.json (the import format)."""
    from ..io import export_folder

    _check_outputs((out_dir, "export folder"), overwrite=overwrite, inputs=[("STACK", stack_path)])
    if fmt.lower() not in ("tiff", "tif", "png"):
        raise InputError(f"--format must be tiff or png, got {fmt!r}")
    lim.integer(bit_depth, "--bit-depth", minimum=1, maximum=16)
    lim.number(black_level, "--black-level", minimum=0, maximum=2**bit_depth - 1, max_inclusive=False)
    st = _load_stack(stack_path)
    with console.status(f"exporting {len(st)} images"):
        export_folder(st, out_dir, fmt=fmt, bit_depth=bit_depth, black_level=black_level, overwrite=overwrite)
    out.print(f"exported folder: {out_dir}", markup=False, highlight=False)


@_friendly_errors
def import_(
    folder: Annotated[Path, typer.Argument(help="Folder with manifest.csv, images and acquisition.json.")],
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Native stack to write (Zarr).")],
    overwrite: Annotated[bool, typer.Option(help="Replace an existing store.")] = False,
):
    """Import a captured stack folder into a native Zarr stack."""
    from ..io import import_folder, write_stack

    _check_outputs((out_path, "stack"), overwrite=overwrite, inputs=[("FOLDER", folder)])
    st = import_folder(folder)
    with progress_bar() as bar:
        task = bar.add_task("writing stack", total=len(st))
        write_stack(st, out_path, overwrite=overwrite, progress=lambda i: bar.advance(task))
    out.print(f"stack: {out_path}  ({len(st)} images, {st.shape[0]}x{st.shape[1]})", markup=False, highlight=False)
