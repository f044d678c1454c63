"""``planeray render``: a Mitsuba 3 scene file -> plane-to-ray transport store (planeray.render)."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Annotated

import typer
from rich.text import Text

from .._console import console, out, progress_bar
from ._common import _check_outputs, _friendly_errors

#: The library's names for what `render` and `simulate mitsuba:` call by their options.
RENDER_OPTIONS = {
    "projector_rows": "--rows",
    "shape": "--size",
    "prefer": "--variant",
    "projector_vfov_deg": "--projector-vfov",
    "vfov_deg": "--vfov",
}


@_friendly_errors(options=RENDER_OPTIONS)
def render(
    scene_file: Annotated[
        str, typer.Argument(help="Mitsuba 3 XML scene with a perspective sensor, or a shipped example's name.")
    ],
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Transport store to write (Zarr directory).")],
    rows: Annotated[int, typer.Option("--rows", help="Projector rows P.")] = 720,
    size: Annotated[tuple[int, int], typer.Option(help="Camera pixels H W.")] = (128, 128),
    spp: Annotated[int, typer.Option(help="Camera paths per pixel.")] = 64,
    batch_spp: Annotated[
        int, typer.Option(help="Camera paths per pixel per batch (the unit of resuming; memory grows with it).")
    ] = 64,
    max_depth: Annotated[int, typer.Option(help="Longest path, as Mitsuba's path (-1 unbounded; 2 direct only).")] = -1,
    caustics: Annotated[
        bool | None,
        typer.Option("--caustics/--no-caustics", help="Add the projector-side pass for specular-first paths."),
    ] = None,
    caustic_paths: Annotated[
        int | None, typer.Option(help="Light paths of the caustic pass (default H*W*spp).")
    ] = None,
    seed: Annotated[int, typer.Option(help="Random seed (same seed, same estimate).")] = 0,
    band_rows: Annotated[int, typer.Option(help="Dense band of offsets -B..B (projector rows).")] = 128,
    max_sparse: Annotated[int, typer.Option(help="Most long-range entries kept beyond the band.")] = 4_000_000,
    rgb: Annotated[bool, typer.Option("--rgb/--mono", help="Three colour channels (T is their luminance).")] = False,
    baseline: Annotated[
        float | None, typer.Option(help="Projector to the camera's right, in scene units (default: the file's).")
    ] = None,
    projector_aspect: Annotated[
        float | None,
        typer.Option(help="Projector width / height (default: the file's planeray_projector_aspect, else 16:9)."),
    ] = None,
    projector_columns: Annotated[
        int | None, typer.Option(help="Projector columns, instead of --projector-aspect (e.g. 1280 for 1280x720).")
    ] = None,
    projector_vfov: Annotated[
        float | None,
        typer.Option(
            help="Projector's vertical field of view, degrees, if it differs from the camera's "
            "(the rectified camera then spans the projector's rows)."
        ),
    ] = None,
    variant: Annotated[
        str | None, typer.Option(help="Force the Mitsuba variant family: llvm or scalar (default: llvm if it loads).")
    ] = None,
    look_from: Annotated[
        tuple[float, float, float] | None,
        typer.Option(help="Place the camera here (scene units) instead of the file's sensor; needs --look-at."),
    ] = None,
    look_at: Annotated[tuple[float, float, float] | None, typer.Option(help="Point the camera looks at.")] = None,
    up: Annotated[tuple[float, float, float], typer.Option(help="Camera up direction (with --look-from).")] = (0, 0, 1),
    vfov: Annotated[float, typer.Option(help="Vertical field of view, degrees (with --look-from).")] = 40.0,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing transport store.")] = False,
    restart: Annotated[bool, typer.Option(help="Discard an unfinished render of other inputs in the way.")] = False,
):
    """Render a Mitsuba 3 scene's plane-to-ray transport T(v, s, t) in one pass (resumable, seeded)."""
    from ..render import render_to_store, render_work
    from ..scenes.mitsuba_scene import resolve_scene_file

    _check_outputs((out_path, "transport"), overwrite=overwrite)
    if (look_from is None) != (look_at is None):
        raise ValueError("--look-from and --look-at go together")
    path = resolve_scene_file(scene_file)
    kwargs = dict(
        shape=size,
        projector_rows=rows,
        spp=spp,
        batch_spp=batch_spp,
        max_depth=max_depth,
        caustics=caustics,
        caustic_paths=caustic_paths,
        seed=seed,
        band_rows=band_rows,
        max_sparse=max_sparse,
        rgb=rgb,
        baseline=baseline,
        projector_aspect=projector_aspect,
        projector_columns=projector_columns,
        projector_vfov_deg=projector_vfov,
        variant=variant,
        camera=None if look_from is None else (look_from, look_at, up),
        vfov_deg=None if look_from is None else vfov,
    )
    with console.status(f"loading {path.name}"):
        total = render_work(path, **kwargs)
    with warnings.catch_warnings(record=True) as caught, progress_bar() as bar:
        warnings.simplefilter("always")
        task = bar.add_task(f"rendering {path.name} {size[0]}x{size[1]}, {rows} rows", total=total)
        _, result = render_to_store(
            path, out_path, overwrite=overwrite, restart=restart, progress=lambda n: bar.advance(task, n), **kwargs
        )
    for w in caught:
        console.print(Text("warning: ", style="bold yellow") + Text(str(w.message)), highlight=False, soft_wrap=True)
    a = result.attrs
    r = a["rig"]
    out.print(
        f"transport: {out_path}  ({size[0]}x{size[1]}, projector {r['projector_rows']}x{r['projector_columns']} "
        f"rows x columns, vfov {r['vfov_deg']:.4g} deg, baseline {r['baseline']:.4g}, offsets -{band_rows}..{band_rows}, "
        f"{len(result.transport.sparse)} sparse entries, {a['variant']}, {a['seconds']:.1f} s)"
    )


@_friendly_errors
def render_examples(
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder for the stores, figures and numbers.")],
    size: Annotated[int, typer.Option(help="Camera pixels per side.")] = 128,
    rows: Annotated[int, typer.Option("--rows", help="Projector rows P.")] = 720,
    spp: Annotated[int, typer.Option(help="Camera paths per pixel.")] = 64,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    scene: Annotated[list[str] | None, typer.Option(help="Only these examples (repeatable).")] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace what a previous run wrote.")] = False,
):
    """Render the shipped example scenes (mirror ball, disco ball, wax candle, room corner): stores + figures."""
    from ..experiments.render import render_examples_work, run_render_examples

    kw = dict(size=size, projector_rows=rows, spp=spp, seed=seed, names=scene or None)
    with console.status("loading the example scenes"):
        total = render_examples_work(**kw)
    with progress_bar() as bar:
        task = bar.add_task(f"rendering examples {size}x{size}, {rows} rows, {spp} spp", total=total)
        summary = run_render_examples(out_dir, overwrite=overwrite, progress=lambda n: bar.advance(task, n), **kw)
    for name, s in summary.items():
        out.print(f"{name}: {out_dir / (name + '.zarr')}, {out_dir / (name + '.png')}  ({s['seconds']} s)")
