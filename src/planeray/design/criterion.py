"""What a design minimizes: the expected transport error of the regularized problem (Sec. 4).

Per pixel the demultiplexer solves Eq. 6 (:mod:`planeray.demux.problem`).  Its linear part -- the
regularized least squares without ``T >= 0`` and without the sparsity term -- is the estimator

.. math::

    \\hat x = P A^T b, \\qquad P = (A^T A + R)^{-1}, \\qquad R = \\alpha D^T D + \\epsilon I,

of a transport ``x`` from images ``b = A x + n`` with independent noise of variances
``sigma_i^2`` (the camera's noise model, :meth:`planeray.camera.CameraModel.image_variance`, at
the prior's mean signal).  Its error ``\\hat x - x = -P R x + P A^T n`` has, over a prior of
transports with second moment ``S = E[x x^T]`` (:mod:`planeray.design.prior`), the expected square

.. math::

    E(A) = \\operatorname{tr}(P G P), \\qquad G = R S R + A^T \\Sigma A
    \\qquad (\\text{criterion } ``mse``):

the regularization's bias (what the images cannot see, filled by the smoothness prior) plus the
noise passed through.  ``epsilon`` (:data:`RIDGE`) only keeps ``P`` finite before the images see
every offset.  Adding an image ``a`` (or removing it, ``s = -1``) changes ``P`` by a rank-one term,
so with ``h = P a`` and ``c = 1 + s a^T h``

.. math::

    \\Delta E = -2 s\\, h^T G P h / c + (h^T h)(h^T G h) / c^2 + s\\, \\sigma^2 h^T h / c^2,

four quadratic forms ``a^T Q a`` (``Q = P, P^2, P G P, P G P^2``) for every candidate at once: one
matrix product (:meth:`ExpectedError.deltas`).

The Bayesian alternatives (the posterior of a Gaussian prior of covariance ``S``, the design
literature's criteria) are offered for comparison: ``bayes-a`` minimizes ``tr (A^T
Sigma^{-1} A + S^{-1})^{-1}`` (A-optimal), ``bayes-d`` its log-determinant (D-optimal, Joshi &
Boyd 2009).  They describe an estimator that knows the prior, which the demultiplexer does not;
measured on simulated stacks they choose worse sweeps (see the demultiplexing guide).

References
----------
.. [1] S. Joshi, S. Boyd, "Sensor selection via convex optimization", IEEE Trans. Signal
   Processing 57(2), 2009.
.. [2] K. Chaloner, I. Verdinelli, "Bayesian experimental design: a review", Statistical Science
   10(3), 1995.
"""

from __future__ import annotations

import numpy as np

from ..demux.problem import difference_matrix

__all__ = ["CRITERIA", "RIDGE", "ExpectedError"]

#: The criteria a design may minimize.
CRITERIA = {
    "mse": "expected squared transport error of the regularized problem (Eq. 6, linear part) under the camera's noise",
    "bayes-a": "Bayesian A-optimal: trace of the posterior covariance of a Gaussian prior of the prior's second moment",
    "bayes-d": "Bayesian D-optimal: log-determinant of that posterior covariance (Joshi & Boyd 2009)",
}
#: The ridge ``epsilon`` of ``R`` (relative to nothing: transports are ~1e-3 per row, this is far below).
RIDGE = 1e-6
#: The Bayesian criteria's prior covariance is ``S + RIDGE_BAYES tr(S) / U I`` (S is of low rank).
RIDGE_BAYES = 1e-3


class ExpectedError:
    """The criterion of a design over candidate rows, with cheap updates.

    Parameters
    ----------
    rows : ndarray (C, U)
        Candidates' rows of the illumination matrix.
    variance : ndarray (C,)
        Noise variance of each candidate image.
    second_moment : ndarray (U, U)
        The prior's ``E[x x^T]``.
    alpha : float
        The smoothness weight of the demultiplexing the sweep is for.
    criterion : {"mse", "bayes-a", "bayes-d"}
    threads : int
        Python threads over which the candidates' forms are split (hold BLAS to one thread meanwhile:
        on a shared 2-core machine a two-thread OpenBLAS inverts a 229 x 229 matrix 40x slower).

    See Also
    --------
    design_sweep : minimizes it.

    Examples
    --------
    >>> from planeray.design import transport_prior
    >>> prior = transport_prior(["diffuse_plane"], shape=(32, 32), projector_rows=180, support_rows=20, pixels=50)
    >>> from planeray.design import candidate_settings
    >>> cands = candidate_settings(support_rows=20, exposure_range_us=(300, 600))
    >>> from planeray.design import image_variance, DesignCamera
    >>> variance = image_variance(cands.rows, cands.exposure_us, prior, DesignCamera())
    >>> crit = ExpectedError(cands.rows, variance, prior.second_moment)
    >>> few, more = crit.value([0, 50, 100]), crit.value([0, 50, 100, 150, 190])
    >>> bool(more < few)  # more images, a smaller expected error
    True
    """

    def __init__(self, rows, variance, second_moment, *, alpha: float = 0.01, criterion: str = "mse", threads: int = 1):
        if criterion not in CRITERIA:
            raise ValueError(f"unknown criterion {criterion!r}; choose one of {', '.join(CRITERIA)}")
        self.rows = np.ascontiguousarray(rows, np.float64)
        self.variance = np.asarray(variance, np.float64)
        self.criterion = criterion
        self.threads = max(1, int(threads))
        self._executor = None
        S = np.asarray(second_moment, np.float64)
        U = S.shape[0]
        self.energy = float(np.trace(S))
        if criterion == "mse":
            D = difference_matrix(U)
            self.R = float(alpha) * (D.T @ D) + RIDGE * np.eye(U)
            self.G0 = self.R @ S @ self.R
        else:
            C = S + RIDGE_BAYES * self.energy / U * np.eye(U)
            self.R = np.linalg.inv(C)
            self.G0 = None

    def _pool(self):
        if self._executor is None:
            from concurrent.futures import ThreadPoolExecutor

            self._executor = ThreadPoolExecutor(self.threads, thread_name_prefix="planeray-design")
        return self._executor

    def close(self) -> None:
        """Stop the worker threads (if any)."""
        if self._executor is not None:
            self._executor.shutdown()
            self._executor = None

    def _state(self, chosen):
        A = self.rows[list(chosen)]
        v = self.variance[list(chosen)]
        if self.criterion == "mse":
            P = np.linalg.inv(self.R + A.T @ A)
            return 0.5 * (P + P.T), self.G0 + (A.T * v) @ A
        P = np.linalg.inv(self.R + (A.T / v) @ A)
        return 0.5 * (P + P.T), None

    def value(self, chosen) -> float:
        """The criterion of the images ``chosen`` (candidate indices): ``E`` for mse (squared, normalized
        units), the trace or log-determinant of the posterior covariance for the Bayesian ones."""
        P, G = self._state(chosen)
        if self.criterion == "mse":
            return float(np.einsum("ij,ji->", P @ G, P))
        if self.criterion == "bayes-a":
            return float(np.trace(P))
        return float(np.linalg.slogdet(P)[1])

    def relative(self, value: float) -> float:
        """``sqrt(E / E||x||^2)``: the expected relative transport error (mse only; NaN otherwise)."""
        return float(np.sqrt(max(value, 0.0) / self.energy)) if self.criterion == "mse" else float("nan")

    def deltas(self, chosen) -> np.ndarray:
        """The change of the criterion when each candidate is added to ``chosen``, (C,) (the chosen ones: inf)."""
        P, G = self._state(chosen)
        Y = self.rows
        if self.criterion == "mse":
            PGP = P @ G @ P
            Q4 = PGP @ P
            Q = np.hstack([P, P @ P, PGP, 0.5 * (Q4 + Q4.T)])
        else:
            Q = np.hstack([P, P @ P])
        U = P.shape[0]
        n_forms = Q.shape[1] // U

        def part(rows):
            Z = Y[rows] @ Q
            return [np.einsum("cu,cu->c", Z[:, k * U : (k + 1) * U], Y[rows]) for k in range(n_forms)]

        halves = np.array_split(np.arange(Y.shape[0]), self.threads)
        if self.threads > 1:  # the candidates split over threads (NumPy releases the GIL in the product)
            parts = list(self._pool().map(part, halves))
        else:
            parts = [part(halves[0])]
        forms = [np.concatenate([p[k] for p in parts]) for k in range(n_forms)]
        q, hh = forms[0], forms[1]
        v = self.variance
        if self.criterion == "mse":
            q2, q1 = forms[2], forms[3]
            c = 1.0 + q
            d = -2.0 * q1 / c + hh * q2 / c**2 + v * hh / c**2
        elif self.criterion == "bayes-a":
            d = -hh / (v + q)
        else:
            d = -np.log1p(q / v)
        d[list(chosen)] = np.inf
        return d
