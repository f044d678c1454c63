"""``planeray render``: a Mitsuba 3 scene file -> plane-to-ray transport store (planeray.render)."""

from __future__ import annotations

import contextlib
import warnings
from pathlib import Path
from typing import Annotated

import typer
from rich.text import Text

from .._console import console, out, progress_bar
from ..errors import InputError
from . import _limits as lim
from ._common import _check_outputs, _friendly_errors

#: The library's names for what `render` and `simulate mitsuba:` call by their options.
RENDER_OPTIONS = {
    "projector_rows": "--rows",
    "shape": "--size",
    "prefer": "--variant",
    "projector_vfov_deg": "--projector-vfov",
    "vfov_deg": "--vfov",
    "n_photons": "--caustic-paths",
    "caustic_paths": "--caustic-paths",
}

#: Most camera paths per pixel (a 128 x 128 render at this many takes days).
MAX_SPP = 1_000_000
#: Largest coordinate or baseline (scene units): Mitsuba computes in float32, which keeps no fraction beyond.
MAX_COORDINATE = 1e6
#: Most projector columns, and the widest projector (width / height).
MAX_PROJECTOR_COLUMNS = 16_384


def check_render_options(
    *,
    size=None,
    rows=None,
    spp=None,
    batch_spp=None,
    caustics=None,
    caustic_paths=None,
    seed=None,
    band_rows=None,
    max_sparse=None,
    max_depth=None,
    baseline=None,
    projector_aspect=None,
    projector_columns=None,
    projector_vfov=None,
    rgb=False,
    names: dict | None = None,
) -> None:
    """Check the rendering options where they are parsed (None: not given); ``names``: other spellings."""
    n = {"size": "--size", "rows": "--rows", **(names or {})}
    if size is not None:
        size = lim.size(size, n["size"], minimum=1)
    lim.optional(lim.integer, rows, n["rows"], minimum=1, maximum=2 * lim.MAX_PROJECTOR_ROWS)
    lim.optional(lim.integer, spp, "--spp", minimum=1, maximum=MAX_SPP)
    lim.optional(lim.integer, batch_spp, "--batch-spp", minimum=1, maximum=MAX_SPP)
    if caustic_paths is not None:
        if caustics is False:
            raise InputError("--caustic-paths is the size of the caustic pass: it needs --caustics, not --no-caustics")
        lim.integer(caustic_paths, "--caustic-paths", minimum=1, maximum=10**10)
    lim.optional(lim.seed, seed, "--seed")
    lim.optional(lim.integer, band_rows, "--band-rows", minimum=0, maximum=2 * lim.MAX_PROJECTOR_ROWS)
    lim.optional(lim.integer, max_sparse, "--max-sparse", minimum=0, maximum=10**9)
    if max_depth is not None and max_depth != -1:
        lim.integer(max_depth, "--max-depth", minimum=1, maximum=1024)
    lim.optional(lim.number, baseline, "--baseline", minimum=-MAX_COORDINATE, maximum=MAX_COORDINATE)
    from ..render.rig import MAX_PROJECTOR_ASPECT, MIN_PROJECTOR_ASPECT

    lim.optional(  # a projector is at most 10 times wider than tall, or taller than wide
        lim.number,
        projector_aspect,
        "--projector-aspect",
        minimum=MIN_PROJECTOR_ASPECT,
        maximum=MAX_PROJECTOR_ASPECT,
    )
    lim.optional(lim.integer, projector_columns, "--projector-columns", minimum=1, maximum=MAX_PROJECTOR_COLUMNS)
    # --projector-vfov: checked by the renderer's setup, before any work (in (0, 180) degrees)
    if size is not None and rows is not None:
        # the running sums (two buffers) and the finished transport, float64, per colour channel
        channels = 3 if rgb else 1
        need = 3 * channels * rows * size[0] * size[1] * 8
        lim.check_memory(need, f"{n['size']} {size[0]} {size[1]} with {n['rows']} {rows}")


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
    up: Annotated[
        tuple[float, float, float] | None,
        typer.Option(help="Camera up direction (with --look-from).", show_default="0 0 1"),
    ] = None,
    vfov: Annotated[
        float | None, typer.Option(help="Vertical field of view, degrees (with --look-from).", show_default="40")
    ] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing transport store.")] = False,
    restart: Annotated[bool, typer.Option(help="Discard an unfinished render of other inputs in the way.")] = False,
):
    """Render a Mitsuba 3 scene's plane-to-ray transport T(v, s, t) in one pass (resumable, seeded)."""
    from ..render import render_to_store, render_work
    from ..scenes.mitsuba_scene import resolve_scene_file

    _check_outputs(
        (out_path, "transport"),
        overwrite=overwrite,
        inputs=[("SCENE_FILE", Path(scene_file) if Path(scene_file).exists() else None)],
    )
    up, vfov = _camera_placement(look_from, look_at, up, vfov)
    check_render_options(
        size=size,
        rows=rows,
        spp=spp,
        batch_spp=batch_spp,
        caustics=caustics,
        caustic_paths=caustic_paths,
        seed=seed,
        band_rows=band_rows,
        max_sparse=max_sparse,
        max_depth=max_depth,
        baseline=baseline,
        projector_aspect=projector_aspect,
        projector_columns=projector_columns,
        projector_vfov=projector_vfov,
        rgb=rgb,
    )
    path = resolve_scene_file(scene_file)
    kwargs = dict(
        shape=size, projector_rows=rows, spp=spp, batch_spp=batch_spp, max_depth=max_depth, caustics=caustics,
        caustic_paths=caustic_paths, seed=seed, band_rows=band_rows, max_sparse=max_sparse, rgb=rgb, baseline=baseline,
        projector_aspect=projector_aspect, projector_columns=projector_columns, projector_vfov_deg=projector_vfov,
        variant=variant, camera=None if look_from is None else (look_from, look_at, up),
        vfov_deg=None if look_from is None else vfov,
    )  # fmt: skip
    with _render_warnings():
        with console.status(f"loading {path.name}"):
            total = render_work(path, **kwargs)
        with progress_bar() as bar:
            task = bar.add_task(f"rendering {path.name} {size[0]}x{size[1]}, {rows} rows", total=total)
            _, result = render_to_store(
                path,
                out_path,
                overwrite=overwrite,
                restart=restart,
                progress=lambda n: bar.advance(task, n),
                on_resume=_say_resuming(out_path),
                **kwargs,
            )
    a = result.attrs
    r = a["rig"]
    out.print(
        f"transport: {out_path}  ({size[0]}x{size[1]}, projector {r['projector_rows']}x{r['projector_columns']} "
        f"rows x columns, vfov {r['vfov_deg']:.4g} deg, baseline {r['baseline']:.4g}, offsets -{band_rows}..{band_rows}, "
        f"{len(result.transport.sparse)} sparse entries, {a['variant']}, {a['seconds']:.1f} s)",
        markup=False,
        highlight=False,
    )


def _camera_placement(look_from, look_at, up, vfov):
    """``--look-from``/``--look-at`` (with ``--up``, ``--vfov``) checked: ``(up, vfov)``, their defaults filled in."""
    if (look_from is None) != (look_at is None):
        raise ValueError("--look-from and --look-at go together")
    if look_from is None:
        for option, value in (("--up", up), ("--vfov", vfov)):
            if value is not None:
                raise InputError(f"{option} places the camera with --look-from and --look-at; give them too")
        return up, vfov
    up = (0.0, 0.0, 1.0) if up is None else up
    vfov = 40.0 if vfov is None else vfov
    _check_camera(look_from, look_at, up, vfov)
    return up, vfov


@contextlib.contextmanager
def _render_warnings():
    """Collect the renderer's warnings and print each as a ``warning:`` line after the bar (left to
    Python they would print as ``file:line: RenderWarning: ...`` in the middle of the bar)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    for w in caught:
        console.print(Text("warning: ", style="bold yellow") + Text(str(w.message)), highlight=False, soft_wrap=True)


def _check_camera(look_from, look_at, up, vfov) -> None:
    import numpy as np

    for option, value in (("--look-from", look_from), ("--look-at", look_at), ("--up", up)):
        if not (np.all(np.isfinite(value)) and np.all(np.abs(value) <= MAX_COORDINATE)):
            raise InputError(
                f"{option} must be three finite numbers X Y Z within +-{MAX_COORDINATE:g} scene units (float32), "
                f"got {' '.join(f'{v:g}' for v in value)}"
            )
    view = np.subtract(look_at, look_from)
    if not np.any(view):
        raise InputError("--look-from and --look-at are the same point; the camera needs a direction")
    if np.linalg.norm(np.cross(view, up)) <= 1e-9 * np.linalg.norm(view) * max(np.linalg.norm(up), 1e-300):
        raise InputError("--up must not be zero nor parallel to the view direction (--look-at minus --look-from)")
    lim.number(vfov, "--vfov", minimum=0.0, maximum=180.0, min_inclusive=False, max_inclusive=False)


def _say_resuming(out_path):
    """``on_resume`` of a render: one line saying it resumes and how much was already done."""

    def say(done: int, total: int) -> None:
        text = Text(
            f"resuming an unfinished render of {out_path}: {done} of {total} batches already done "
            "(same scene file content and parameters)"
        )
        console.print(text, highlight=False)

    return say


@_friendly_errors(options={"shape": "--size", "projector_rows": "--rows"})
def render_examples(
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder for the stores, figures and numbers.")],
    size: Annotated[int, typer.Option(help="Camera pixels per side.")] = 128,
    rows: Annotated[int, typer.Option("--rows", help="Projector rows P.")] = 720,
    spp: Annotated[int, typer.Option(help="Camera paths per pixel.")] = 64,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    scene: Annotated[list[str] | None, typer.Option(help="Only these examples (repeatable).")] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace what a previous run wrote.")] = False,
):
    """Render the shipped example scenes (mirror ball, disco ball, wax candle, room corner): stores + figures.

    Writes ``NAME.zarr``, ``NAME.png`` per scene and ``render_examples.json`` into
    ``--out`` (which may hold other files); each is checked before any work: an
    existing one needs ``--overwrite`` and is replaced only if planeray wrote it.
    An unfinished render of a scene resumes (it says so).
    """
    from ..experiments.render import render_examples_outputs, render_examples_work, run_render_examples
    from ..render import example_scenes

    lim.folder(out_dir, "--out")
    for name in scene or ():
        if name not in example_scenes():
            raise InputError(f"--scene {name}: no such example; choose from {', '.join(sorted(example_scenes()))}")
    lim.integer(size, "--size", minimum=8, maximum=lim.MAX_SIDE)
    check_render_options(size=(size, size), rows=rows, spp=spp, seed=seed)
    _check_outputs(*render_examples_outputs(out_dir, names=scene or None), overwrite=overwrite)
    kw = dict(size=size, projector_rows=rows, spp=spp, seed=seed, names=scene or None)
    with _render_warnings():
        with console.status("loading the example scenes"):
            total = render_examples_work(**kw)
        with progress_bar() as bar:
            task = bar.add_task(f"rendering examples {size}x{size}, {rows} rows, {spp} spp", total=total)
            summary = run_render_examples(
                out_dir,
                overwrite=overwrite,
                progress=lambda n: bar.advance(task, n),
                on_resume=lambda name, done, total: _say_resuming(out_dir / f"{name}.zarr")(done, total),
                **kw,
            )
    for name, s in summary.items():
        out.print(
            f"{name}: {out_dir / (name + '.zarr')}, {out_dir / (name + '.png')}  ({s['seconds']} s)",
            markup=False,
            highlight=False,
        )
