"""Demultiplexing a delay-exposure stack into 3D light transport (Sec. 4).

Modules: :mod:`~planeray.demux.problem` (the per-pixel problem and its row groups),
:mod:`~planeray.demux.fast` (the default solver), :mod:`~planeray.demux.reference`
(pinv, nnls, cvxpy), :mod:`~planeray.demux.solvers` (the registry :data:`SOLVERS`,
chosen by name) and :mod:`~planeray.demux.driver` (chunked, resumable, Dask runs) and
:mod:`~planeray.demux.auto` (``alpha``/``beta`` chosen by cross-validation over the images).
"""

from .auto import WeightChoice, choose_weights
from .driver import (
    AMBIENT_MAP,
    DEFAULT_CHUNK_ROWS,
    MAP_NAMES,
    DemuxResult,
    demultiplex,
    demultiplex_to_store,
    solve_chunk,
)
from .fast import solve_fast
from .problem import DemuxProblem, RowGroup, difference_matrix
from .reference import solve_cvxpy, solve_nnls, solve_pinv
from .result import SolveResult
from .solvers import SOLVERS, get_solver

__all__ = [
    "AMBIENT_MAP",
    "SOLVERS",
    "DEFAULT_CHUNK_ROWS",
    "MAP_NAMES",
    "DemuxProblem",
    "DemuxResult",
    "RowGroup",
    "SolveResult",
    "WeightChoice",
    "choose_weights",
    "demultiplex",
    "demultiplex_to_store",
    "difference_matrix",
    "get_solver",
    "solve_chunk",
    "solve_cvxpy",
    "solve_fast",
    "solve_nnls",
    "solve_pinv",
]
