"""The demultiplexing solvers, by name (a Mitsuba-style registry).

* ``fast``: the default, batched over all pixels sharing an illumination matrix,
  exact to a certified tolerance (:mod:`planeray.demux.fast`);
* ``pinv``: pseudo-inverse (no constraint, no regularization);
* ``nnls``: non-negative least squares without regularization;
* ``cvxpy``: the paper's formulation solved by CVXPY + Clarabel (slow reference).

The last three are in :mod:`planeray.demux.reference`.  Every solver has the
signature ``solve(group, B, alpha, beta, tol) -> SolveResult``; it may also take the
keyword-only options ``mask=`` (the observations to use: the driver then leaves
pixels with saturated observations to it, in the same batch), ``threads=`` (the
driver then runs its batches on solver threads, calling it with ``threads=1``) and
``ambient=`` (the ambient column of Eq. 6a: only such solvers serve ``ambient="estimate"``;
they return each pixel's ambient in ``SolveResult.ambient``).  The driver passes only
the options a solver declares (:func:`options`); without ``mask=`` it solves each pixel
with dropped observations on its own rows.
"""

from __future__ import annotations

from collections.abc import Callable

from ..errors import InputError
from .fast import solve_fast
from .reference import solve_cvxpy, solve_nnls, solve_pinv

__all__ = ["SOLVERS", "get_solver", "options"]

#: Demultiplexing methods by name.
SOLVERS: dict[str, Callable] = {"fast": solve_fast, "pinv": solve_pinv, "nnls": solve_nnls, "cvxpy": solve_cvxpy}


def get_solver(method: str) -> Callable:
    """The solver registered as ``method``; an :class:`~planeray.errors.InputError` names the choices otherwise.

    Parameters
    ----------
    method : {"fast", "pinv", "nnls", "cvxpy"}
        A name of :data:`SOLVERS`.

    Returns
    -------
    callable
        ``solve(group, B, alpha, beta, tol, ...) -> SolveResult``.

    See Also
    --------
    solve_fast, solve_cvxpy, solve_nnls, solve_pinv

    Examples
    --------
    >>> get_solver("fast").__name__
    'solve_fast'
    """
    try:
        return SOLVERS[method]
    except KeyError:
        raise InputError(f"unknown demultiplexing method {method!r}; choose one of {sorted(SOLVERS)}") from None


def options(solve: Callable) -> frozenset:
    """The keyword-only options (``mask``, ``threads``, ``ambient``) a registered solver accepts."""
    import inspect

    try:
        params = inspect.signature(solve).parameters
    except (TypeError, ValueError):  # pragma: no cover - builtins
        return frozenset()
    return frozenset(n for n, p in params.items() if p.kind is inspect.Parameter.KEYWORD_ONLY)
