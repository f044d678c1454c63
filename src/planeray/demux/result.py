"""What a solver returns for a batch of pixels."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SolveResult"]


@dataclass
class SolveResult:
    """Solution of a batch of pixels.

    Attributes
    ----------
    X : ndarray (P, V) float64
        Transport over the row group's valid offsets.
    iterations : ndarray (P,) int32
        Iterations each pixel took (solver-specific unit).
    converged : ndarray (P,) bool
        Whether the solver's own convergence test passed for the pixel.
    objective, residual_ss, kkt_residual : ndarray (P,), optional
        The objective, the residual sum of squares over the observations used and the
        scaled KKT residual of ``X``, when the solver has them (the driver's maps;
        otherwise it computes them).
    ambient : ndarray (P,), optional
        Each pixel's ambient ``a`` (normalized value per projector row of exposure) when
        the problem has the ambient term (Eq. 6a); None otherwise.
    gap : ndarray (P,), optional
        The certified relative objective gap of each pixel (``(f - f*) / f*`` is at most
        this), when the solver certifies one (``fast``); inf where nothing was usable.

    See Also
    --------
    solve_fast, solve_cvxpy, solve_nnls, solve_pinv : return it.

    Examples
    --------
    >>> import numpy as np
    >>> from planeray.study import scaled_truth, study_setup, dipole_provider
    >>> from planeray.timing import quick_sweep
    >>> setup = study_setup(quick_sweep())  # one camera row's band matrix A: 23 images x 229 offsets
    >>> T = scaled_truth(setup.A, dipole_provider(setup.offsets)(1.0, 0.01, 0.9))
    >>> B = (setup.A @ T)[None] + 0.01 * np.random.default_rng(0).standard_normal((2, 23))  # 2 noisy pixels
    >>> from planeray.demux import solve_fast
    >>> result = solve_fast(setup.group, B)
    >>> type(result).__name__, result.X.shape, bool(result.converged.all())
    ('SolveResult', (2, 229), True)
    """

    X: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    objective: np.ndarray | None = None
    residual_ss: np.ndarray | None = None
    kkt_residual: np.ndarray | None = None
    ambient: np.ndarray | None = None
    gap: np.ndarray | None = None
