"""Chunked, resumable, optionally distributed demultiplexing of a whole stack.

Work is split into chunks of camera rows.  Each chunk reads only its rows of the
used images (memory is bounded by the chunk, not the image), solves every pixel
with the chosen method and returns the transport plus per-pixel diagnostics.

:func:`demultiplex_to_store` writes chunks into a hidden partial store next to
the output (``.NAME.partial``), marking each chunk done after its data; a run
that is killed and started again with the same output and parameters continues
from the finished chunks and yields the same result.  Only a complete result is
renamed to the output path, so a finished output is never half-written.
``workers=N`` runs the chunks on a Dask ``LocalCluster``; ``scheduler=ADDRESS``
on an existing Dask distributed cluster.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import resumable
from .._validate import check_integer, check_number
from ..errors import InputError, TransportError
from ..io import create_array, transport_attrs, writable
from ..io.atomic import check_replaceable
from ..stack import Stack
from ..timing import RowGeometry
from ..transport import Transport
from .problem import DemuxProblem, RowGroup
from .solvers import get_solver

__all__ = [
    "DEFAULT_CHUNK_ROWS",
    "DemuxResult",
    "ChunkResult",
    "solve_chunk",
    "demultiplex",
    "demultiplex_to_store",
    "MAP_NAMES",
]

DEFAULT_CHUNK_ROWS = 16
#: Seconds to wait for an existing Dask scheduler before giving up with one line.
SCHEDULER_TIMEOUT_S = 5.0
#: Per-pixel diagnostic maps stored beside ``T``.
MAP_NAMES = {
    "residual_rms": "float32",  # RMS of (A x - b) over the observations used
    "kkt_residual": "float32",  # scaled KKT violation (0 at the exact optimum)
    "objective": "float32",  # value of the paper's objective
    "iterations": "int32",
    "converged": "bool",  # certified to the tolerance; False where no observation was usable
    "n_observations": "int16",  # observations used (saturated ones dropped); 0: T is 0, not an estimate
}


@dataclass
class ChunkResult:
    """Transport and diagnostics of a block of camera rows."""

    rows: slice
    T: np.ndarray  # (r, W, U) float32
    maps: dict  # name -> (r, W)


@dataclass
class DemuxResult:
    """An in-memory demultiplexing result."""

    transport: Transport
    maps: dict
    attrs: dict


def read_observations(stack: Stack, problem: DemuxProblem, rows: slice, *, source=None):
    """Observations ``(N, r, W)`` float64 of the used images and their saturation mask."""
    imgs = np.asarray(stack.images[:, rows, :], dtype=np.float64)[problem.image_index]
    bad = ~np.isfinite(imgs)
    if bad.any():
        n, r, c = np.argwhere(bad)[0]
        where = f"{source}: " if source else ""
        raise InputError(
            f"{where}image {int(problem.image_index[n])} has a non-finite value at pixel ({rows.start + r}, {c})"
        )
    sat = None
    if stack.saturated is not None:
        sat = np.asarray(stack.saturated[:, rows, :], dtype=bool)[problem.image_index]
        if not sat.any():
            sat = None
    return imgs, sat


def solve_chunk(
    problem: DemuxProblem, observations, saturated, rows: slice, *, method: str = "fast", tol: float | None = None
) -> ChunkResult:
    """Solve every pixel of camera rows ``rows``.

    Parameters
    ----------
    problem : DemuxProblem
    observations : ndarray (N, r, W)
        Used images restricted to the rows.
    saturated : ndarray (N, r, W) bool or None
        Saturated observations; they are dropped from their pixel's fit.
    rows : slice
        The camera rows (absolute).
    method : str
        A key of :data:`planeray.demux.SOLVERS`.
    """
    solve = get_solver(method)
    N, r, W = observations.shape
    U = problem.n_offsets
    T = np.zeros((r, W, U), np.float32)
    maps = {name: np.zeros((r, W), dtype) for name, dtype in MAP_NAMES.items()}
    row_ids = np.arange(rows.start, rows.stop)
    for g in np.unique(problem.row_group[row_ids]):
        group = problem.groups[g]
        local = np.flatnonzero(problem.row_group[row_ids] == g)
        B = observations[:, local, :].reshape(N, -1).T  # (P, N) pixels of these rows
        mask = None if saturated is None else ~saturated[:, local, :].reshape(N, -1).T
        X = np.zeros((B.shape[0], group.A.shape[1]))
        iters = np.zeros(B.shape[0], np.int32)
        conv = np.zeros(B.shape[0], bool)
        full = np.ones(B.shape[0], bool) if mask is None else mask.all(axis=1)
        if full.any():
            res = solve(group, B[full], problem.alpha, problem.beta, tol)
            X[full], iters[full], conv[full] = res.X, res.iterations, res.converged
        for p in np.flatnonzero(~full):  # rare: pixels with saturated observations
            keep = mask[p]
            if not keep.any():  # nothing usable: T stays 0, flagged (never "converged")
                continue
            sub = RowGroup(group.rows, group.A[keep], group.valid)
            res = solve(sub, B[p : p + 1, keep], problem.alpha, problem.beta, tol)
            X[p], iters[p], conv[p] = res.X[0], res.iterations[0], res.converged[0]
        resid = X @ group.A.T - B
        if mask is not None:
            resid = np.where(mask, resid, 0.0)
        n_obs = np.full(B.shape[0], N) if mask is None else mask.sum(axis=1)
        conv = conv & (n_obs > 0)
        pix_maps = {
            "residual_rms": np.sqrt((resid**2).sum(axis=1) / np.maximum(n_obs, 1)),
            "kkt_residual": problem.kkt_residual(group, X, np.where(mask, B, 0.0) if mask is not None else B),
            "objective": problem.objective(group, X, B, mask),
            "iterations": iters,
            "converged": conv,
            "n_observations": n_obs,
        }
        if mask is not None and (~full).any():
            # The KKT test above used the full matrix; redo masked pixels exactly.
            for p in np.flatnonzero(~full):
                keep = mask[p]
                if not keep.any():
                    pix_maps["kkt_residual"][p] = np.nan
                    continue
                sub = RowGroup(group.rows, group.A[keep], group.valid)
                pix_maps["kkt_residual"][p] = problem.kkt_residual(sub, X[p : p + 1], B[p : p + 1, keep])[0]
        Tg = np.zeros((B.shape[0], U), np.float32)
        Tg[:, group.valid] = X
        T[local] = Tg.reshape(local.size, W, U)
        for name, value in pix_maps.items():
            maps[name][local] = np.asarray(value).reshape(local.size, W)
    return ChunkResult(rows, T, maps)


def _check_run_options(method, chunk_rows, tol, workers=None) -> None:
    """Options of a run, checked before any work (one line naming the option)."""
    get_solver(method)
    check_integer(chunk_rows, "chunk_rows", minimum=1)
    if tol is not None:
        check_number(tol, "tol", minimum=0.0, min_inclusive=False, maximum=1.0, max_inclusive=False)
    if workers is not None:
        check_integer(workers, "workers", minimum=1)


def _chunks(H: int, chunk_rows: int) -> list[slice]:
    if chunk_rows < 1:
        raise InputError(f"chunk must be at least one row, got {chunk_rows}")
    return [slice(r, min(r + chunk_rows, H)) for r in range(0, H, chunk_rows)]


def _attrs(problem: DemuxProblem, method: str, tol) -> dict:
    return {
        "lines_per_second": problem.lines_per_second,
        "alpha": problem.alpha,
        "beta": problem.beta,
        "method": method,
        "tol": tol,
        "n_images": int(problem.n_images),
        "epipolar_resolution_rows": problem.epipolar_resolution_rows,
        "image_index": problem.image_index.tolist(),
    }


def demultiplex(
    stack: Stack,
    *,
    alpha: float = 0.01,
    beta: float = 0.01,
    method: str = "fast",
    chunk_rows: int = DEFAULT_CHUNK_ROWS,
    tol: float | None = None,
    progress: Callable[[int], None] | None = None,
) -> DemuxResult:
    """Demultiplex a stack in memory (Sec. 4).

    Parameters
    ----------
    stack : Stack
    alpha, beta : float
        Smoothness and sparsity weights (paper: 0.01 each).
    method : {'fast', 'pinv', 'nnls', 'cvxpy'}
    chunk_rows : int
        Camera rows per chunk (bounds memory).
    tol : float, optional
        Solver tolerance (method-specific default).
    progress : callable, optional
        Called with the number of rows finished after each chunk.

    Returns
    -------
    DemuxResult
        ``transport`` (``T`` over ``offsets_rows``), per-pixel ``maps`` and ``attrs``.

    Examples
    --------
    >>> from planeray.acquire import simulate_stack
    >>> from planeray.scenes import make_scene
    >>> from planeray.timing import paper_sweep
    >>> stack = simulate_stack(make_scene("wax", (8, 8), projector_rows=45, seed=0), paper_sweep(), seed=0)
    >>> result = demultiplex(stack)
    >>> result.transport.dense.shape, bool(result.maps["converged"].all())
    ((8, 8, 229), True)
    """
    _check_run_options(method, chunk_rows, tol)
    problem = DemuxProblem.from_stack(stack, alpha=alpha, beta=beta)
    H, W = stack.shape
    T = np.zeros((H, W, problem.n_offsets), np.float32)
    maps = {name: np.zeros((H, W), dtype) for name, dtype in MAP_NAMES.items()}
    for rows in _chunks(H, chunk_rows):
        obs, sat = read_observations(stack, problem, rows)
        res = solve_chunk(problem, obs, sat, rows, method=method, tol=tol)
        T[rows] = res.T
        for name in maps:
            maps[name][rows] = res.maps[name]
        if progress is not None:
            progress(rows.stop - rows.start)
    transport = Transport(T, problem.offsets_rows, RowGeometry(H, stack.projector_rows))
    return DemuxResult(transport, maps, _attrs(problem, method, tol))


# ---------------------------------------------------------------- the store
def _fingerprint(stack: Stack, problem: DemuxProblem, method: str, tol, chunk_rows: int) -> str:
    """Identity of a run: a resumed run must match it exactly."""
    h = hashlib.sha256()
    meta = {
        "stack": stack.content_digest(),  # every image and the saturation mask, not a sample of them
        "alpha": problem.alpha,
        "beta": problem.beta,
        "method": method,
        "tol": tol,
        "chunk_rows": chunk_rows,
        "offsets": [int(problem.offsets_rows[0]), int(problem.offsets_rows[-1])],
    }
    h.update(json.dumps(meta, sort_keys=True).encode())
    return h.hexdigest()


def _create_store(directory, shape, problem: DemuxProblem, attrs: dict):
    import zarr

    H, W = shape
    U = problem.n_offsets
    group = zarr.open_group(str(directory), mode="w", zarr_format=3)
    create_array(group, "T", shape=(H, W, U), chunks=(DEFAULT_CHUNK_ROWS, W, U), dtype="float32", fill_value=0.0)
    for name, dtype in MAP_NAMES.items():
        create_array(group, name, shape=(H, W), chunks=(DEFAULT_CHUNK_ROWS, W), dtype=dtype, fill_value=0)
    group.attrs.update(transport_attrs(problem.offsets_rows, problem.projector_rows, attrs=attrs))
    return group


def _write_chunk(group, res: ChunkResult, index: int) -> None:
    writable(group, "T")[res.rows] = res.T  # every chunk stored: the store is marked all_chunks_stored
    for name in MAP_NAMES:
        writable(group, name)[res.rows] = res.maps[name]
    resumable.mark_done(group, index)  # only after the data: a killed run redoes this chunk


def demultiplex_to_store(
    stack: Stack,
    out,
    *,
    alpha: float = 0.01,
    beta: float = 0.01,
    method: str = "fast",
    chunk_rows: int = DEFAULT_CHUNK_ROWS,
    tol: float | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    overwrite: bool = False,
    restart: bool = False,
    progress: Callable[[int], None] | None = None,
    on_resume: Callable[[int, int], None] | None = None,
    source=None,
    _stop_after: int | None = None,
) -> Path:
    """Demultiplex a stack chunk by chunk into a transport store (resumable).

    Parameters
    ----------
    stack : Stack
        May be lazy (Zarr-backed): only a chunk of rows is in memory at a time.
    out : path
        Transport store to write (Zarr group with ``T``, the diagnostic maps of
        :data:`MAP_NAMES` and the attributes of the transport format).
    workers : int, optional
        Run chunks on a Dask ``LocalCluster`` with this many single-threaded workers.
    scheduler : str, optional
        Address of an existing Dask distributed scheduler.
    overwrite : bool
        Replace an existing finished output.
    restart : bool
        Discard an unfinished run of the same output instead of resuming it.
    progress : callable, optional
        Called with the number of rows finished after each chunk.
    on_resume : callable, optional
        Called as ``on_resume(done, total)`` (chunks) when an unfinished run of the
        same output is continued.  A run is continued only when its inputs are
        provably the same: the content digest of every image and of the
        saturation mask (:meth:`planeray.stack.Stack.content_digest`) and every
        parameter; otherwise it is refused (see ``restart``).
    source : str, optional
        Name of the stack for error messages.

    Returns
    -------
    pathlib.Path
        The finished store.
    """
    out = Path(out)
    check_replaceable(out, overwrite=overwrite, kind="transport", error=TransportError)
    _check_run_options(method, chunk_rows, tol, workers)
    problem = DemuxProblem.from_stack(stack, alpha=alpha, beta=beta)
    H, W = stack.shape
    chunks = _chunks(H, chunk_rows)
    fingerprint = _fingerprint(stack, problem, method, tol, chunk_rows)
    attrs = _attrs(problem, method, tol)
    group = resumable.open_partial(
        out, fingerprint, len(chunks), lambda d: _create_store(d, (H, W), problem, attrs), restart=restart
    )
    done = resumable.done_units(group)
    if on_resume is not None and done.any():
        on_resume(int(done.sum()), len(chunks))
    todo = [i for i in range(len(chunks)) if not done[i]]
    if progress is not None and done.any():
        progress(sum(chunks[i].stop - chunks[i].start for i in range(len(chunks)) if done[i]))
    try:
        if _stop_after is not None:  # testing hook: simulate a run killed after k chunks
            todo = todo[:_stop_after]
        if workers or scheduler:
            _run_dask(stack, problem, chunks, todo, method, tol, group, workers, scheduler, progress, source)
        else:
            for i in todo:
                obs, sat = read_observations(stack, problem, chunks[i], source=source)
                _write_chunk(group, solve_chunk(problem, obs, sat, chunks[i], method=method, tol=tol), i)
                if progress is not None:
                    progress(chunks[i].stop - chunks[i].start)
        if _stop_after is not None and len(todo) < sum(1 for i in range(len(chunks)) if not done[i]):
            return resumable.partial_path(out)
    except BaseException:
        resumable.discard_if_empty(out)  # a run that finished nothing leaves nothing behind
        raise
    return resumable.promote(out, overwrite=overwrite, kind="transport", error=TransportError)


def _run_dask(stack, problem, chunks, todo, method, tol, group, workers, scheduler, progress, source):
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise InputError("--workers/--scheduler need dask[distributed]: pip install 'dask[distributed]'") from exc
    cluster = None
    if scheduler:
        try:
            client = Client(scheduler, timeout=SCHEDULER_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(
                f"cannot reach the Dask scheduler at {scheduler!r} within {SCHEDULER_TIMEOUT_S:g} s "
                f"({type(exc).__name__}: {' '.join(str(exc).split())})"
            ) from None
    else:
        cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    try:
        shared = client.scatter(problem, broadcast=True)
        in_flight = max(2, 2 * len(client.scheduler_info()["workers"]))
        pending = list(todo)
        futures = as_completed()
        index_of = {}

        def submit_next():
            i = pending.pop(0)
            obs, sat = read_observations(stack, problem, chunks[i], source=source)
            fut = client.submit(solve_chunk, shared, obs, sat, chunks[i], method=method, tol=tol, pure=False)
            index_of[fut.key] = i
            futures.add(fut)

        for _ in range(min(in_flight, len(pending))):
            submit_next()
        for fut in futures:
            try:
                res = fut.result()
            except (OSError, TimeoutError) as exc:  # a worker or the scheduler went away
                raise InputError(
                    f"the Dask cluster failed ({type(exc).__name__}: {' '.join(str(exc).split())})"
                ) from None
            i = index_of.pop(fut.key)
            _write_chunk(group, res, i)
            if progress is not None:
                progress(chunks[i].stop - chunks[i].start)
            if pending:
                submit_next()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
