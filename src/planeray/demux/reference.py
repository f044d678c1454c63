"""Reference demultiplexers (the Sec. 5.2 study's baselines and the trusted slow solver).

* ``pinv`` -- the pseudo-inverse: least squares without constraints or
  regularization (goes negative, Fig. 5a);
* ``nnls`` -- non-negative least squares without regularization (Lawson-Hanson,
  :func:`scipy.optimize.nnls`);
* ``cvxpy`` -- the paper's full formulation solved by CVXPY (the paper's own
  tool) with the Clarabel interior-point solver: the trusted, slow reference
  (also with the ambient term of Eq. 6a).
  The problem is compiled once per row group with the observations as a
  ``cp.Parameter`` -- CVXPY's fastest honest use.
"""

from __future__ import annotations

import numpy as np

from .problem import RowGroup
from .result import SolveResult

__all__ = ["solve_pinv", "solve_nnls", "solve_cvxpy"]


def solve_pinv(group: RowGroup, B, alpha=0.0, beta=0.0, tol=None) -> SolveResult:
    """Pseudo-inverse ``x = A^+ b`` for all pixels at once (ignores alpha, beta).

    Parameters
    ----------
    group : RowGroup
        Camera rows sharing one illumination matrix ``A`` (N, V).
    B : ndarray (P, N)
        Observations of ``P`` pixels: normalized image values of the ``N`` used images.
    alpha, beta, tol
        Ignored (the signature every solver shares).

    Returns
    -------
    SolveResult
        ``X = A^+ B`` (P, V), negative values included.

    See Also
    --------
    solve_nnls : non-negative.
    solve_fast : with the paper's regularization.

    Examples
    --------
    >>> import numpy as np
    >>> from planeray.study import scaled_truth, study_setup, dipole_provider
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())  # one camera row's band matrix A: 23 images x 229 offsets
    >>> T = scaled_truth(setup.A, dipole_provider(setup.offsets)(1.0, 0.01, 0.9))
    >>> B = (setup.A @ T)[None] + 0.01 * np.random.default_rng(0).standard_normal((2, 23))  # 2 noisy pixels
    >>> X = solve_pinv(setup.group, B).X
    >>> X.shape, bool((X < 0).any())  # unconstrained: negative light
    ((2, 229), True)
    """
    P = np.linalg.pinv(group.A)
    X = np.asarray(B, np.float64) @ P.T
    n = X.shape[0]
    return SolveResult(X, np.ones(n, np.int32), np.ones(n, bool))


def solve_nnls(group: RowGroup, B, alpha=0.0, beta=0.0, tol=None) -> SolveResult:
    """Unregularized NNLS per pixel (Lawson-Hanson active set; ignores alpha, beta).

    Parameters
    ----------
    group : RowGroup
        Camera rows sharing one illumination matrix ``A`` (N, V).
    B : ndarray (P, N)
        Observations of ``P`` pixels: normalized image values of the ``N`` used images.
    alpha, beta, tol
        Ignored (the signature every solver shares).

    Returns
    -------
    SolveResult
        ``X`` (P, V) >= 0.

    See Also
    --------
    solve_pinv : no constraint at all.
    solve_fast : with the paper's regularization.

    Examples
    --------
    >>> import numpy as np
    >>> from planeray.study import scaled_truth, study_setup, dipole_provider
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())  # one camera row's band matrix A: 23 images x 229 offsets
    >>> T = scaled_truth(setup.A, dipole_provider(setup.offsets)(1.0, 0.01, 0.9))
    >>> B = (setup.A @ T)[None] + 0.01 * np.random.default_rng(0).standard_normal((2, 23))  # 2 noisy pixels
    >>> X = solve_nnls(setup.group, B).X
    >>> X.shape, bool((X >= 0).all())
    ((2, 229), True)
    """
    from scipy.optimize import nnls

    B = np.asarray(B, np.float64)
    X = np.zeros((B.shape[0], group.A.shape[1]))
    ok = np.ones(B.shape[0], bool)
    for p, b in enumerate(B):  # baseline only: one SciPy call per pixel
        try:
            X[p] = nnls(group.A, b, maxiter=50 * group.A.shape[1])[0]
        except RuntimeError:
            ok[p] = False
    return SolveResult(X, np.ones(B.shape[0], np.int32), ok)


class _CvxpyRow:
    """The paper's problem (or Eq. 6a, with ``ambient``) compiled once for one illumination matrix."""

    def __init__(self, A, alpha, beta, ambient=None):
        import cvxpy as cp

        self.cp = cp
        N, V = A.shape
        self.x = cp.Variable(V)
        self.b = cp.Parameter(N)
        self.a = None if ambient is None else cp.Variable(nonneg=True)
        prediction = A @ self.x if ambient is None else A @ self.x + self.a * np.asarray(ambient, np.float64)
        objective = cp.sum_squares(prediction - self.b)
        if V > 1:
            objective = objective + alpha * cp.sum_squares(cp.diff(self.x))
        objective = objective + beta * cp.norm1(self.x)
        self.problem = cp.Problem(cp.Minimize(objective), [self.x >= 0])

    def solve(self, b):
        self.b.value = b
        self.problem.solve(solver=self.cp.CLARABEL)
        ok = self.problem.status in ("optimal", "optimal_inaccurate")
        x = np.maximum(np.asarray(self.x.value, np.float64), 0.0) if self.x.value is not None else None
        a = None if self.a is None or self.a.value is None else max(float(self.a.value), 0.0)
        iters = self.problem.solver_stats.num_iters or 0
        return x, a, ok, iters


def solve_cvxpy(group: RowGroup, B, alpha=0.01, beta=0.01, tol=None, *, ambient=None) -> SolveResult:
    """The paper's formulation with CVXPY + Clarabel, compiled once per row group.

    ``ambient``: the ambient column ``I_w`` (N,) of Eq. 6a (each pixel's ambient in
    ``SolveResult.ambient``); None: the paper's problem.

    Parameters
    ----------
    group : RowGroup
        Camera rows sharing one illumination matrix ``A`` (N, V).
    B : ndarray (P, N)
        Observations of ``P`` pixels: normalized image values of the ``N`` used images.
    alpha, beta : float
        Smoothness and sparsity weights (the paper: 0.01 each).
    tol : float, optional
        The solver's tolerance.
    ambient : ndarray (N,), optional
        The ambient column ``I_w`` of Eq. 6a (projector rows of exposure); None: the paper's problem.

    Returns
    -------
    SolveResult
        ``X`` (P, V) and the per-pixel diagnostics.

    See Also
    --------
    solve_fast : the same problem, fast.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 4.

    Examples
    --------
    >>> import numpy as np
    >>> from planeray.study import scaled_truth, study_setup, dipole_provider
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())  # one camera row's band matrix A: 23 images x 229 offsets
    >>> T = scaled_truth(setup.A, dipole_provider(setup.offsets)(1.0, 0.01, 0.9))
    >>> B = (setup.A @ T)[None] + 0.01 * np.random.default_rng(0).standard_normal((2, 23))  # 2 noisy pixels
    >>> X = solve_cvxpy(setup.group, B[:1]).X
    >>> X.shape, bool((X >= -1e-9).all())
    ((1, 229), True)
    """
    try:
        import cvxpy  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("method 'cvxpy' needs cvxpy and clarabel: pip install 'planeray[reference]'") from exc
    B = np.asarray(B, np.float64)
    solver = _CvxpyRow(group.A, alpha, beta, ambient)
    X = np.zeros((B.shape[0], group.A.shape[1]))
    amb = None if ambient is None else np.zeros(B.shape[0])
    ok = np.zeros(B.shape[0], bool)
    iters = np.zeros(B.shape[0], np.int32)
    for p, b in enumerate(B):  # the reference: one interior-point solve per pixel
        x, a, ok[p], iters[p] = solver.solve(b)
        if x is not None:
            X[p] = x
        if amb is not None and a is not None:
            amb[p] = a
    return SolveResult(X, iters, ok, ambient=amb)
