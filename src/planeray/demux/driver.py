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
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import resumable
from .._progress import progress_reporter
from .._validate import check_integer, check_number
from ..errors import InputError, TransportError
from ..io import create_array, transport_attrs, writable
from ..io.atomic import check_replaceable
from ..io.lock import writes_output
from ..stack import Stack
from ..timing import RowGeometry
from ..transport import Transport
from ._kernels import warm_up
from .auto import WeightChoice, choose_weights, is_auto, resolve_ambient
from .fast import blas_one_thread, solver_threads
from .problem import DemuxProblem, RowGroup, read_observations
from .solvers import SOLVERS, get_solver, options

__all__ = [
    "DEFAULT_CHUNK_ROWS",
    "DemuxResult",
    "ChunkResult",
    "solve_chunk",
    "demultiplex",
    "demultiplex_to_store",
    "MAP_NAMES",
    "AMBIENT_MAP",
    "resolve_ambient",
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
#: The per-pixel ambient map (Eq. 6a's ``a``, float32) stored beside ``T`` when the ambient is estimated.
AMBIENT_MAP = "ambient"


@dataclass
class ChunkResult:
    """Transport and diagnostics of a block of camera rows."""

    rows: slice
    T: np.ndarray  # (r, W, U) float32
    maps: dict  # name -> (r, W)


@dataclass
class DemuxResult:
    """An in-memory demultiplexing result.

    ``maps`` holds the per-pixel maps of :data:`MAP_NAMES` and, when the ambient was
    estimated, :data:`AMBIENT_MAP` (also :attr:`ambient`).

    Parameters
    ----------
    transport : Transport
        ``T`` over ``offsets_rows`` (normalized image value per projector row).
    maps : dict of str to ndarray (H, W)
        Per-pixel diagnostics: ``converged``, ``iterations``, ``objective``, ``residual_rms``, ...
    attrs : dict
        The run's record (weights, method, the sweep's epipolar resolution, ...).

    See Also
    --------
    demultiplex : returns it.

    Examples
    --------
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("wax", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> result = pr.demultiplex(stack)
    >>> type(result).__name__, result.transport.dense.shape, "converged" in result.maps
    ('DemuxResult', (8, 8, 229), True)
    """

    transport: Transport
    maps: dict
    attrs: dict

    @property
    def ambient(self) -> np.ndarray | None:
        """The ambient image ``a`` (H, W) of Eq. 6a (normalized value per projector row of exposure), or None."""
        return self.maps.get(AMBIENT_MAP)


def _storage_rows(stack: Stack) -> int:
    """Rows per stored chunk of a lazily read stack (1: in memory, nothing to align to)."""
    chunks = getattr(stack.images, "chunks", None)
    return int(chunks[1]) if chunks is not None and len(chunks) == 3 else 1


def _many_chunks_at_once():
    """Zarr settings for reading one row block of every image (hundreds of small chunks).

    Zarr's default of 10 concurrent chunk requests leaves its per-chunk overhead
    serial; 128 with batches of 64 reads such a block ~1.5x faster (measured).
    """
    import zarr

    return zarr.config.set({"async.concurrency": 128, "codec_pipeline.batch_size": 64})


class _RowReader:
    """Reads the observations of successive row chunks, in blocks aligned to the stored chunks.

    A store with chunks of 32 rows read in chunks of 16 would decode every stored chunk
    twice (and Zarr's per-chunk cost dominates small reads); here each stored block of
    rows is read once, kept until the chunks inside it are served (memory: one stored
    block of rows of every image).
    """

    def __init__(self, stack: Stack, problem: DemuxProblem, *, source=None):
        self.stack, self.problem, self.source = stack, problem, source
        self.block = _storage_rows(stack)
        self._rows = slice(0, 0)
        self._data = None

    def __call__(self, rows: slice):
        if self.block <= 1 or rows.stop - rows.start >= self.block:
            with _many_chunks_at_once():
                return read_observations(self.stack, self.problem, rows, source=self.source)
        if not (self._rows.start <= rows.start and rows.stop <= self._rows.stop):
            H = self.stack.shape[0]
            lo = rows.start // self.block * self.block
            hi = min(H, -(-rows.stop // self.block) * self.block)
            self._rows = slice(lo, hi)
            self._data = None
            with _many_chunks_at_once():
                self._data = read_observations(self.stack, self.problem, self._rows, source=self.source)
        imgs, sat = self._data
        part = slice(rows.start - self._rows.start, rows.stop - self._rows.start)
        sat = None if sat is None or not sat[:, part].any() else sat[:, part]
        return imgs[:, part], sat


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

    Returns
    -------
    ChunkResult
        ``T`` (rows, W, U) and the chunk's per-pixel maps.

    See Also
    --------
    demultiplex : every chunk of a stack.

    Examples
    --------
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("wax", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> import numpy as np
    >>> problem = pr.DemuxProblem.from_stack(stack)
    >>> chunk = solve_chunk(problem, np.asarray(stack.images)[problem.image_index], None, slice(0, 2))
    >>> chunk.T.shape  # 2 camera rows x 8 columns x 229 offsets
    (2, 8, 229)
    """
    tasks = _plan(problem, observations, saturated, rows)
    threads = solver_threads() if "threads" in options(get_solver(method)) and len(tasks) > 1 else 1
    run = lambda t: _run_task(problem, t, method, tol)  # noqa: E731
    with blas_one_thread():
        if threads > 1:
            with ThreadPoolExecutor(threads) as pool:
                results = list(pool.map(run, tasks))
        else:
            results = [run(t) for t in tasks]
    return _assemble(problem, rows, observations.shape[2], tasks, results)


@dataclass
class _Task:
    """Pixels of one row group inside a chunk: a unit of work for one solver thread."""

    group: RowGroup
    local: np.ndarray  # the group's rows inside the chunk
    pixels: slice  # of the group's pixels in the chunk (row-major)
    B: np.ndarray  # (P, N)
    mask: np.ndarray | None  # (P, N) observations used; None: all


#: Pixels per task: small enough to keep two threads busy to the end of a chunk,
#: large enough for an efficient matrix product.
_TASK_PIXELS = 512


def _plan(problem: DemuxProblem, observations, saturated, rows: slice) -> list[_Task]:
    N = observations.shape[0]
    row_ids = np.arange(rows.start, rows.stop)
    tasks = []
    for g in np.unique(problem.row_group[row_ids]):
        local = np.flatnonzero(problem.row_group[row_ids] == g)
        B = observations[:, local, :].reshape(N, -1).T  # (P, N) pixels of these rows, row-major
        mask = None if saturated is None else ~saturated[:, local, :].reshape(N, -1).T
        if mask is not None and mask.all():
            mask = None
        for s in range(0, B.shape[0], _TASK_PIXELS):
            sl = slice(s, min(s + _TASK_PIXELS, B.shape[0]))
            tasks.append(_Task(problem.groups[g], local, sl, B[sl], None if mask is None else mask[sl]))
    return tasks


def _run_task(problem: DemuxProblem, task: _Task, method: str, tol):
    """Solution and per-pixel maps of one task (run in a solver thread)."""
    solve = get_solver(method)
    group, B, mask = task.group, task.B, task.mask
    opts = options(solve)
    res = None
    amb = None
    if mask is None or "mask" in opts:  # dropped observations (if any) in the same batch
        extra = {"threads": 1} if "threads" in opts else {}
        if mask is not None:
            extra["mask"] = mask
        if problem.ambient:
            extra["ambient"] = problem.exposure_rows
        res = solve(group, B, problem.alpha, problem.beta, tol, **extra)
        X, iters, conv, amb = res.X, res.iterations, res.converged, res.ambient
    else:  # a solver without masks: pixels with dropped observations one by one
        X, iters, conv, amb = _solve_masked_one_by_one(solve, problem, group, B, mask, tol)
    n_obs = np.full(B.shape[0], B.shape[1]) if mask is None else mask.sum(axis=1)
    X = np.where(n_obs[:, None] > 0, X, 0.0)  # nothing usable: T is 0, flagged (never "converged")
    if amb is not None:
        amb = np.where(n_obs > 0, amb, 0.0)
    if res is not None and res.objective is not None:  # the solver's own (its last certificate)
        kkt = np.where(n_obs > 0, res.kkt_residual, np.nan)
        rms = np.sqrt(res.residual_ss / np.maximum(n_obs, 1))
        maps = {"residual_rms": rms, "objective": res.objective, "kkt_residual": kkt}
    else:
        maps = problem.diagnostics(group, X, B, mask, ambient=amb)
    maps |= {"iterations": iters, "converged": conv & (n_obs > 0), "n_observations": n_obs}
    if problem.ambient:
        maps[AMBIENT_MAP] = amb
    return X, maps


def _assemble(problem: DemuxProblem, rows: slice, W: int, tasks, results) -> ChunkResult:
    r = rows.stop - rows.start
    U = problem.n_offsets
    T = np.zeros((r, W, U), np.float32)
    maps = {name: np.zeros((r, W), dtype) for name, dtype in _map_names(problem).items()}
    flatT = T.reshape(r * W, U)
    flat = {name: m.reshape(r * W) for name, m in maps.items()}
    for task, (X, pix_maps) in zip(tasks, results):
        # the task's pixels: row-major over its group's rows inside the chunk
        where = (task.local[:, None] * W + np.arange(W)[None, :]).reshape(-1)[task.pixels]
        flatT[where, task.group.valid] = task.group.transport(X)
        for name, value in pix_maps.items():
            flat[name][where] = value
    return ChunkResult(rows, T, maps)


def _solve_masked_one_by_one(solve, problem, group, B, mask, tol):
    """For solvers that take no mask: every pixel with dropped observations on its own rows."""
    X = np.zeros((B.shape[0], group.A.shape[1]))
    iters = np.zeros(B.shape[0], np.int32)
    conv = np.zeros(B.shape[0], bool)
    amb = np.zeros(B.shape[0]) if problem.ambient else None
    full = mask.all(axis=1)
    e = problem.exposure_rows
    if full.any():
        res = solve(group, B[full], problem.alpha, problem.beta, tol, **({"ambient": e} if problem.ambient else {}))
        X[full], iters[full], conv[full] = res.X, res.iterations, res.converged
        if amb is not None:
            amb[full] = res.ambient
    for p in np.flatnonzero(~full):
        keep = mask[p]
        if not keep.any():
            continue
        sub = RowGroup(group.rows, group.A[keep], group.valid, group.on_projector)
        extra = {"ambient": e[keep]} if problem.ambient else {}
        res = solve(sub, B[p : p + 1, keep], problem.alpha, problem.beta, tol, **extra)
        X[p], iters[p], conv[p] = res.X[0], res.iterations[0], res.converged[0]
        if amb is not None:
            amb[p] = res.ambient[0]
    return X, iters, conv, amb


def _map_names(problem: DemuxProblem) -> dict:
    """The per-pixel maps of a run: :data:`MAP_NAMES`, and the ambient when estimated."""
    return MAP_NAMES | ({AMBIENT_MAP: "float32"} if problem.ambient else {})


def _solve_in_order(problem: DemuxProblem, read, chunks, method, tol, done):
    """Solve ``chunks`` in order on the solver threads; ``done(i, ChunkResult)`` for each, in order.

    The tasks of the next chunk are queued (and its rows read) while the current one
    runs, so both threads stay busy across chunk boundaries; at most two chunks and
    their results are in memory.  Row groups whose last chunk is done release their
    factorizations (memory bounded by the chunk).
    """
    if not chunks:
        return
    release = _cache_release(problem, [c for _, c in chunks])
    threads = solver_threads() if "threads" in options(get_solver(method)) else 1
    with blas_one_thread(), ThreadPoolExecutor(threads, thread_name_prefix="planeray-demux") as pool:
        if method == "fast":
            pool.submit(warm_up)  # Numba's start, while the first rows are read
        pending = None
        for n, (i, rows) in enumerate(chunks + [(None, None)]):
            queued = None
            if rows is not None:
                obs, sat = read(i)
                tasks = _plan(problem, obs, sat, rows)
                queued = (
                    i,
                    rows,
                    obs.shape[2],
                    tasks,
                    [pool.submit(_run_task, problem, t, method, tol) for t in tasks],
                )
                del obs, sat
            if pending is not None:
                j, prow, W, ptasks, futures = pending
                res = _assemble(problem, prow, W, ptasks, [f.result() for f in futures])
                release(n - 1)
                done(j, res)
            pending = queued


def _cache_release(problem: DemuxProblem, order: list[slice]):
    """``release(n)`` drops the cached factorizations of row groups whose last chunk is ``order[n]``."""
    last = {}
    for n, rows in enumerate(order):
        for g in np.unique(problem.row_group[rows]):
            last[int(g)] = n

    def release(n: int) -> None:
        for g, m in last.items():
            if m == n:
                problem.groups[g].__dict__.pop("_admm_cache", None)

    return release


def _check_run_options(method, chunk_rows, tol, workers=None, ambient="none") -> None:
    """Options of a run, checked before any work (one line naming the option)."""
    solve = get_solver(method)
    if ambient == "estimate" and "ambient" not in options(solve):
        able = sorted(m for m, f in SOLVERS.items() if "ambient" in options(f))
        raise InputError(f"method {method!r} cannot estimate the ambient light; use one of {', '.join(able)}")
    check_integer(chunk_rows, "chunk_rows", minimum=1)
    if tol is not None:
        check_number(tol, "tol", minimum=0.0, min_inclusive=False, maximum=1.0, max_inclusive=False)
    if workers is not None:
        check_integer(workers, "workers", minimum=1)


def _chunks(H: int, chunk_rows: int) -> list[slice]:
    if chunk_rows < 1:
        raise InputError(f"chunk must be at least one row, got {chunk_rows}")
    return [slice(r, min(r + chunk_rows, H)) for r in range(0, H, chunk_rows)]


def _attrs(problem: DemuxProblem, method: str, tol, choice: WeightChoice | None = None) -> dict:
    extra = {} if choice is None else {"weights_choice": choice.to_attrs()}
    return extra | {
        "lines_per_second": problem.lines_per_second,
        "alpha": problem.alpha,
        "beta": problem.beta,
        "ambient": "estimate" if problem.ambient else "none",
        "method": method,
        "tol": tol,
        "n_images": int(problem.n_images),
        "epipolar_resolution_rows": problem.epipolar_resolution_rows,
        "image_index": problem.image_index.tolist(),
    }


def demultiplex(
    stack: Stack,
    *,
    alpha: float | str = 0.01,
    beta: float | str = 0.01,
    ambient: str | None = None,
    method: str = "fast",
    chunk_rows: int = DEFAULT_CHUNK_ROWS,
    tol: float | None = None,
    progress: Callable[[int], None] | bool | None = None,
) -> DemuxResult:
    """Demultiplex a stack in memory (Sec. 4).

    Parameters
    ----------
    stack : Stack
    alpha, beta : float or "auto"
        Smoothness and sparsity weights (paper: 0.01 each); ``"auto"`` chooses a
        weight from the stack by cross-validation over its images
        (:func:`planeray.demux.auto.choose_weights`), recorded in
        ``attrs["weights_choice"]``.
    ambient : {'none', 'estimate'}, optional
        ``"estimate"``: each pixel also has an ambient unknown (Eq. 6a,
        :mod:`planeray.demux.problem`), returned as ``maps["ambient"]``
        (:attr:`DemuxResult.ambient`; normalized image value per projector row of
        exposure) and kept out of ``T``; ``"none"``: the paper's problem.  Default: the
        paper's problem with explicit weights, ``"estimate"`` when a weight is
        ``"auto"`` (:func:`resolve_ambient`).  Needs ``beta > 0`` and a method that
        models it (``fast``, ``cvxpy``).
    method : {'fast', 'pinv', 'nnls', 'cvxpy'}
    chunk_rows : int
        Camera rows per chunk (bounds memory).
    tol : float, optional
        Solver tolerance (method-specific default).
    progress : callable or bool, optional
        Called with the number of rows finished after each chunk.  None (default): a progress display
        in a Jupyter notebook, nothing elsewhere; True: the display anywhere; False: nothing
        (:func:`planeray._progress.progress_reporter`).

    Returns
    -------
    DemuxResult
        ``transport`` (``T`` over ``offsets_rows``), per-pixel ``maps`` and ``attrs``.

    See Also
    --------
    demultiplex_to_store : the same into a resumable store on disk.
    DemuxProblem : the problem it solves.
    planeray.demux.choose_weights : the ``"auto"`` weights.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 4, the optimization below Eq. 6.

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
    ambient = resolve_ambient(ambient, alpha, beta)
    _check_run_options(method, chunk_rows, tol, ambient=ambient)
    _check_ambient_weights(ambient, beta)
    choice = None
    if is_auto(alpha) or is_auto(beta):
        choice = choose_weights(stack, alpha=alpha, beta=beta, ambient=ambient)
        alpha, beta = choice.alpha, choice.beta
    problem = DemuxProblem.from_stack(stack, alpha=alpha, beta=beta, ambient=ambient == "estimate")
    H, W = stack.shape
    T = np.zeros((H, W, problem.n_offsets), np.float32)
    maps = {name: np.zeros((H, W), dtype) for name, dtype in _map_names(problem).items()}

    def done(i, res):
        T[res.rows] = res.T
        for name in maps:
            maps[name][res.rows] = res.maps[name]
        if advance is not None:
            advance(res.rows.stop - res.rows.start)

    chunks = list(enumerate(_chunks(H, chunk_rows)))
    reader = _RowReader(stack, problem)
    with progress_reporter(progress, H, f"demultiplexing {H} rows") as advance:
        _solve_in_order(problem, lambda i: reader(chunks[i][1]), chunks, method, tol, done)
    transport = Transport(T, problem.offsets_rows, RowGeometry(H, stack.projector_rows))
    return DemuxResult(transport, maps, _attrs(problem, method, tol, choice))


# ---------------------------------------------------------------- the store
def _fingerprint(
    stack: Stack, problem: DemuxProblem, method: str, tol, chunk_rows: int, choice: WeightChoice | None = None
) -> str:
    """Identity of a run: a resumed run must match it exactly.

    A run with automatic weights is identified by what was asked (``"auto"``), how
    the weights are chosen and the weights chosen, besides the stack's content.
    """
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
    if problem.ambient:  # only then: the fingerprints of the paper's problem are those of before
        meta["ambient"] = "estimate"
    if choice is not None:
        meta["weights_choice"] = {
            "requested": choice.requested,
            "criterion": choice.criterion,
            "folds": choice.folds,
            "n_pixels": choice.n_pixels,
            "rows": choice.rows,
            "alpha": choice.alpha,
            "beta": choice.beta,
        }
        if choice.ambient != "none":
            meta["weights_choice"]["ambient"] = choice.ambient
    h.update(json.dumps(meta, sort_keys=True).encode())
    return h.hexdigest()


def _create_store(directory, shape, problem: DemuxProblem, attrs: dict):
    import zarr
    from zarr.codecs import ZstdCodec

    H, W = shape
    U = problem.n_offsets
    group = zarr.open_group(str(directory), mode="w", zarr_format=3)
    # zstd level 1 (with its checksum, like every planeray array): on transports the same
    # ratio as the default level 3 (1.85 on wax), ~1.6x faster to write
    create_array(
        group,
        "T",
        shape=(H, W, U),
        chunks=(DEFAULT_CHUNK_ROWS, W, U),
        dtype="float32",
        fill_value=0.0,
        compressors=(ZstdCodec(level=1, checksum=True),),
    )
    for name, dtype in _map_names(problem).items():
        create_array(group, name, shape=(H, W), chunks=(DEFAULT_CHUNK_ROWS, W), dtype=dtype, fill_value=0)
    group.attrs.update(transport_attrs(problem.offsets_rows, problem.projector_rows, attrs=attrs))
    return group


def _write_chunk(group, res: ChunkResult, index: int) -> None:
    writable(group, "T")[res.rows] = res.T  # every chunk stored: the store is marked all_chunks_stored
    for name in res.maps:
        writable(group, name)[res.rows] = res.maps[name]
    resumable.mark_done(group, index)  # only after the data: a killed run redoes this chunk


@resumable.killable
@writes_output("out")
def demultiplex_to_store(
    stack: Stack,
    out,
    *,
    alpha: float | str = 0.01,
    beta: float | str = 0.01,
    ambient: str | None = None,
    method: str = "fast",
    chunk_rows: int = DEFAULT_CHUNK_ROWS,
    tol: float | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    overwrite: bool = False,
    restart: bool = False,
    progress: Callable[[int], None] | None = None,
    on_resume: Callable[[int, int], None] | None = None,
    on_choice: Callable[[WeightChoice, bool], None] | None = None,
    source=None,
) -> Path:
    """Demultiplex a stack chunk by chunk into a transport store (resumable).

    Parameters
    ----------
    stack : Stack
        May be lazy (Zarr-backed): only a chunk of rows is in memory at a time.
    out : path
        Transport store to write (Zarr group with ``T``, the diagnostic maps of
        :data:`MAP_NAMES` and the attributes of the transport format).
    alpha, beta : float or "auto"
        As in :func:`demultiplex`.  With ``"auto"`` the choice
        (:class:`~planeray.demux.auto.WeightChoice`) is made before the first chunk and
        stored in the attribute ``weights_choice``; a resumed run takes it from the
        unfinished store (the run's fingerprint includes it and the stack's content,
        so only an identical run continues).
    ambient : {'none', 'estimate'}, optional
        As in :func:`demultiplex`; with ``"estimate"`` the store also has the (H, W)
        float32 array ``ambient`` and the attribute ``ambient = "estimate"``.  Part of
        the run's fingerprint: a resumed run with another ``ambient`` is refused.
    on_choice : callable, optional
        Called with the :class:`~planeray.demux.auto.WeightChoice` of an automatic run
        (and whether it was taken from an unfinished run) before any chunk is solved.
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

    See Also
    --------
    planeray.demultiplex : the same in memory.
    planeray.read_transport : read the store back.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 4.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("corner", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pr.demultiplex_to_store(stack, pathlib.Path(tmp) / "T.zarr")
    ...     T, attrs = pr.read_transport(path)
    >>> T.dense.shape, attrs["alpha"]
    ((8, 8, 229), 0.01)
    """
    out = Path(out)
    check_replaceable(out, overwrite=overwrite, kind="transport", error=TransportError)
    ambient = resolve_ambient(ambient, alpha, beta)
    _check_run_options(method, chunk_rows, tol, workers, ambient=ambient)
    _check_ambient_weights(ambient, beta)
    choice = None
    if is_auto(alpha) or is_auto(beta):
        requested = {
            "alpha": "auto" if is_auto(alpha) else float(alpha),
            "beta": "auto" if is_auto(beta) else float(beta),
        }
        choice = None if restart else _recorded_choice(out, requested)
        resumed = choice is not None
        if choice is None:
            choice = choose_weights(stack, alpha=alpha, beta=beta, ambient=ambient)
        if on_choice is not None:
            on_choice(choice, resumed)
        alpha, beta = choice.alpha, choice.beta
    problem = DemuxProblem.from_stack(stack, alpha=alpha, beta=beta, ambient=ambient == "estimate")
    H, W = stack.shape
    chunks = _chunks(H, chunk_rows)
    fingerprint = _fingerprint(stack, problem, method, tol, chunk_rows, choice)
    attrs = _attrs(problem, method, tol, choice)
    group = resumable.open_partial(
        out, fingerprint, len(chunks), lambda d: _create_store(d, (H, W), problem, attrs), restart=restart
    )
    done = resumable.done_units(group)
    if on_resume is not None and done.any():
        on_resume(int(done.sum()), len(chunks))
    todo = [i for i in range(len(chunks)) if not done[i]]
    if progress is not None and done.any():
        progress(sum(chunks[i].stop - chunks[i].start for i in range(len(chunks)) if done[i]))
    _stop_after = resumable.stop_after_units()  # the tests' hook: a run killed after k chunks
    try:
        if _stop_after is not None:
            todo = todo[:_stop_after]
        if workers or scheduler:
            _run_dask(stack, problem, chunks, todo, method, tol, group, workers, scheduler, progress, source)
        else:
            _run_local(stack, problem, chunks, todo, method, tol, group, progress, source)
        if _stop_after is not None and len(todo) < sum(1 for i in range(len(chunks)) if not done[i]):
            return resumable.partial_path(out)
    except BaseException:
        resumable.discard_if_empty(out)  # a run that finished nothing leaves nothing behind
        raise
    return resumable.promote(out, overwrite=overwrite, kind="transport", error=TransportError)


def _check_ambient_weights(ambient: str, beta) -> None:
    """The ambient term with an explicit ``beta = 0`` is refused before any work (not identifiable)."""
    if ambient == "estimate" and not is_auto(beta):
        try:
            value = float(beta)
        except (TypeError, ValueError):
            return  # checked with the weights
        if value == 0:
            raise InputError(
                "ambient estimation needs beta > 0: with beta = 0 a flat transport and the ambient light "
                "fit the images alike (the split is not identifiable)"
            )


def _recorded_choice(out, requested: dict) -> WeightChoice | None:
    """The weights an unfinished automatic run of ``out`` chose (None: no such run).

    Taken as they are only because the run's fingerprint (checked next) covers the
    stack's content, the request, the ambient mode and the choice: a different stack,
    request or ambient mode is refused.
    """
    partial = resumable.partial_path(out)
    if not partial.exists():
        return None
    import zarr

    try:
        recorded = zarr.open_group(str(partial), mode="r").attrs.get("weights_choice")
        if recorded is None or recorded.get("requested") != requested:
            return None
        return WeightChoice.from_attrs(recorded)
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _run_local(stack, problem, chunks, todo, method, tol, group, progress, source):
    """Chunks in order on the solver threads; each written (and marked done) as it finishes.

    Writing (compression) runs on its own thread, in order, so that reading the next
    chunk and queueing its work never wait for it; at most two writes are pending.
    """
    writes = []

    def done(i, res):
        while len(writes) >= 2:
            writes.pop(0).result()
        writes.append(io.submit(_write_chunk, group, res, i))
        if progress is not None:
            progress(res.rows.stop - res.rows.start)

    reader = _RowReader(stack, problem, source=source)
    read = lambda i: reader(chunks[i])  # noqa: E731
    with ThreadPoolExecutor(1, thread_name_prefix="planeray-demux-write") as io:
        try:
            _solve_in_order(problem, read, [(i, chunks[i]) for i in todo], method, tol, done)
        finally:
            for w in writes:  # in order; the first failure is raised (after the others finished)
                w.exception()
        for w in writes:
            w.result()


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
        cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True, dashboard_address=":0")
        client = Client(cluster)
        client.wait_for_workers(int(workers))  # the problem is broadcast to every worker, not fetched later
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
