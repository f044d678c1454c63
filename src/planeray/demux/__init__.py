"""Demultiplexing a delay-exposure stack into 3D light transport (Sec. 4).

Solvers are chosen by name from :data:`SOLVERS` (Mitsuba-style registry):

``fast``   the default: batched over all pixels sharing an illumination matrix,
           exact to a certified tolerance (see :mod:`planeray.demux.fast`);
``pinv``   pseudo-inverse (no constraint, no regularization);
``nnls``   non-negative least squares without regularization;
``cvxpy``  the paper's formulation solved by CVXPY + Clarabel (slow reference).

Every solver has the signature ``solve(group, B, alpha, beta, tol) -> SolveResult``.
"""

from .baselines import solve_cvxpy, solve_nnls, solve_pinv
from .driver import DEFAULT_CHUNK_ROWS, MAP_NAMES, DemuxResult, demultiplex, demultiplex_to_store, solve_chunk
from .fast import solve_fast
from .problem import DemuxProblem, RowGroup, difference_matrix
from .result import SolveResult

#: Demultiplexing methods by name.
SOLVERS = {"fast": solve_fast, "pinv": solve_pinv, "nnls": solve_nnls, "cvxpy": solve_cvxpy}

__all__ = [
    "SOLVERS",
    "DEFAULT_CHUNK_ROWS",
    "MAP_NAMES",
    "DemuxProblem",
    "DemuxResult",
    "RowGroup",
    "SolveResult",
    "demultiplex",
    "demultiplex_to_store",
    "difference_matrix",
    "solve_chunk",
    "solve_cvxpy",
    "solve_fast",
    "solve_nnls",
    "solve_pinv",
]
