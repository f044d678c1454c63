"""``planeray demux``: a delay-exposure stack demultiplexed into 3D light transport (Sec. 4)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from .._console import console, out, progress_bar
from ..errors import InputError
from . import _limits as lim
from ._common import StackArg, _check_outputs, _friendly_errors, _load_stack

#: The solvers of ``--method``.
METHODS = ("fast", "pinv", "nnls", "cvxpy")
#: The values of ``--ambient`` and the methods that estimate the ambient.
AMBIENT = ("none", "estimate")
AMBIENT_METHODS = ("fast", "cvxpy")
#: Largest smoothness or sparsity weight (the Sec. 5.2 study sweeps up to 1e4).
MAX_WEIGHT = 1e6
#: Most Dask workers of a local cluster.
MAX_WORKERS = 1024


def _weight(text: str, option: str):
    """``"auto"`` or a weight in ``[0, MAX_WEIGHT]`` (one line naming ``option`` otherwise)."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{option} must be a number or 'auto', got {text!r}") from None
    return lim.nonnegative(value, option, maximum=MAX_WEIGHT)


@_friendly_errors
def demux(
    stack_path: StackArg,
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Transport store to write (Zarr).")],
    alpha: Annotated[
        str,
        typer.Option(
            help="Smoothness weight (paper: 0.01), or 'auto': chosen from the images (generalized cross-validation)."
        ),
    ] = "0.01",
    beta: Annotated[
        str,
        typer.Option(
            help="Sparsity weight (paper: 0.01), or 'auto': chosen from the images (generalized cross-validation)."
        ),
    ] = "0.01",
    ambient: Annotated[
        str | None,
        typer.Option(
            help="none: the paper's problem; estimate: an ambient-light unknown per pixel, kept out of T "
            "(the store's 'ambient' map). Default: estimate with 'auto' weights (unless --beta 0), none otherwise.",
            show_default=False,
        ),
    ] = None,
    method: Annotated[str, typer.Option(help="fast | pinv | nnls | cvxpy.")] = "fast",
    workers: Annotated[int | None, typer.Option(help="Run on a Dask LocalCluster with N workers.")] = None,
    scheduler: Annotated[str | None, typer.Option(help="Address of an existing Dask scheduler.")] = None,
    chunk_rows: Annotated[
        int, typer.Option("--chunk-rows", "--chunk", help="Camera rows per chunk (bounds memory).")
    ] = 16,
    tol: Annotated[float | None, typer.Option(help="Solver tolerance (relative objective gap for fast).")] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing finished output.")] = False,
    restart: Annotated[bool, typer.Option(help="Discard an unfinished run instead of resuming it.")] = False,
    report: Annotated[
        Path | None,
        typer.Option(help="With 'auto' weights: write the criterion's curve to DIR/weights_cv.png."),
    ] = None,
    sweep: Annotated[
        str | None,
        typer.Option(
            help="Use only the stack's images at this sweep's settings (paper, quick, or a sweep file .json, e.g. "
            "a design's 24 of a captured 85); its boundary flags apply.",
            show_default="every image of the stack",
        ),
    ] = None,
):
    """Demultiplex a delay-exposure stack into 3D light transport (Sec. 4); resumable."""
    import time

    from ..demux import demultiplex_to_store

    alpha, beta, ambient, figure = _demux_options(
        stack_path, out_path, alpha=alpha, beta=beta, ambient=ambient, method=method, workers=workers,
        scheduler=scheduler, chunk_rows=chunk_rows, tol=tol, report=report, overwrite=overwrite,
    )  # fmt: skip
    chosen_sweep = None if sweep is None else lim.sweep(sweep)
    st = _load_stack(stack_path)
    if chosen_sweep is not None:
        try:
            st = st.restricted_to(chosen_sweep)
        except InputError as exc:
            raise InputError(f"--sweep {sweep}: {exc}", stack_path) from None
    t0 = time.perf_counter()
    chosen = {}

    def on_choice(choice, resumed):
        chosen["choice"] = choice
        note = " (taken from the unfinished run)" if resumed else f" ({time.perf_counter() - t0:.1f} s)"
        out.print(choice.summary() + note, markup=False, highlight=False)
        warning = choice.edge_warning()
        if warning:  # the best lies on an end of what was searched: said, not silent
            console.print(warning, style="yellow", markup=False, highlight=False)

    if "auto" in (alpha, beta):
        console.print("choosing the weights from the images ...", markup=False, highlight=False)
    with progress_bar() as bar:
        task = bar.add_task(f"demultiplexing ({method})", total=st.shape[0])
        path = demultiplex_to_store(
            st, out_path, alpha=alpha, beta=beta, ambient=ambient, method=method, chunk_rows=chunk_rows, tol=tol,
            workers=workers, scheduler=scheduler, overwrite=overwrite, restart=restart,
            progress=lambda rows: bar.advance(task, rows),
            on_resume=lambda done, total: console.print(
                f"resuming an unfinished run of {out_path}: {done} of {total} chunks already done "
                "(same stack content and parameters)",
                markup=False,
                highlight=False,
            ),
            on_choice=on_choice,
            source=str(stack_path),
        )  # fmt: skip
    _print_demux(path, st.shape, time.perf_counter() - t0, figure, chosen.get("choice"))


def _demux_options(stack_path, out_path, *, alpha, beta, ambient, method, workers, scheduler, chunk_rows, tol,
                   report, overwrite):  # fmt: skip
    """Every option of ``demux`` checked before any work (the outputs locked): ``(alpha, beta, ambient, figure)``."""
    from ..demux.auto import resolve_ambient

    if workers is not None and scheduler is not None:
        raise ValueError("give --workers or --scheduler, not both")
    alpha, beta = _weight(alpha, "--alpha"), _weight(beta, "--beta")
    if report is not None and "auto" not in (alpha, beta):
        raise InputError("--report draws the choice of --alpha auto / --beta auto; give one of them")
    figure = None if report is None else Path(report) / "weights_cv.png"
    if figure is not None and Path(report).exists() and not Path(report).is_dir():
        raise InputError(f"--report {report}: exists and is not a directory")
    _check_outputs(
        (out_path, "transport"), (figure, "figure", "--report"), overwrite=overwrite, inputs=[("STACK", stack_path)]
    )
    if method not in METHODS:
        raise InputError(f"--method {method}: unknown demultiplexing method; choose one of {', '.join(METHODS)}")
    if ambient is not None and ambient.strip().lower() not in AMBIENT:
        raise InputError(f"--ambient {ambient}: choose one of {', '.join(AMBIENT)}")
    ambient = resolve_ambient(ambient, alpha, beta)
    if ambient == "estimate" and method not in AMBIENT_METHODS:
        raise InputError(
            f"--ambient estimate: --method {method} cannot estimate the ambient light; use "
            f"{' or '.join(AMBIENT_METHODS)}, or --ambient none"
        )
    if ambient == "estimate" and beta == 0:
        raise InputError(
            "--ambient estimate needs --beta > 0: with --beta 0 a flat transport and the ambient light "
            "fit the images alike (not identifiable)"
        )
    lim.optional(lim.integer, workers, "--workers", minimum=1, maximum=MAX_WORKERS)
    lim.integer(chunk_rows, "--chunk-rows", minimum=1, maximum=lim.MAX_SIDE)
    lim.optional(lim.number, tol, "--tol", minimum=0.0, maximum=1.0, min_inclusive=False, max_inclusive=False)
    return alpha, beta, ambient, figure


def _print_demux(path, shape, elapsed: float, figure, choice) -> None:
    """What ``demux`` wrote: the transport's convergence and residuals, the criterion's curve, pixels with no data."""
    from ..io import read_transport_maps

    maps = read_transport_maps(path)
    conv = maps["converged"]
    amb = "" if "ambient" not in maps else f", median ambient {np.median(maps['ambient']):.2e} per row of exposure"
    out.print(
        f"transport: {path}  ({shape[0]}x{shape[1]} pixels in {elapsed:.1f} s; "
        f"converged {conv.mean() * 100:.2f} %, median residual RMS {np.median(maps['residual_rms']):.2e}{amb})",
        markup=False,
        highlight=False,
    )
    if figure is not None:
        from ..figures.demux import weights_cv_figure

        figure.parent.mkdir(parents=True, exist_ok=True)
        weights_cv_figure(choice, out=figure)
        out.print(f"criterion curve: {figure}", markup=False, highlight=False)
    empty = int((maps["n_observations"] == 0).sum())
    if empty:
        console.print(
            f"warning: {empty} pixels ({empty / conv.size * 100:.1f} %) have no usable observation (every image "
            "saturated): their T is 0 and they are flagged not converged (map n_observations)",
            style="yellow",
            markup=False,
            highlight=False,
        )
