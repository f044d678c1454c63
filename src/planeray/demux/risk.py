"""A demultiplexed pixel's prediction risk: GCV and Stein's estimate (the automatic weights' criterion).

For one pixel with ``n`` used observations ``b``, noise variances ``sigma_i^2`` (the stack's
camera model, :func:`planeray.demux.auto.observation_variance`) and the Sec. 4 estimator
``x(b)`` at weights ``(alpha, beta)`` (Eq. 6a with the ambient column), Stein's lemma gives an
unbiased estimate of the noise-weighted error of predicting the noise-free images,

.. math::

    \\widehat R = \\sum_i w_i (b_i - A_i x)^2 - n + 2\\,\\mathrm{df},
    \\qquad w_i = 1 / \\sigma_i^2,
    \\qquad \\mathrm{df} = \\operatorname{tr} \\frac{\\partial (A x)}{\\partial b}
        = \\operatorname{tr}\\bigl(A_F H_{FF}^{-1} A_F^T\\bigr),
    \\quad H = A^T A + \\alpha D^T D,

``F`` the pixel's free unknowns (``x_F > 0``).  The estimator is a QP whose active set is locally
constant, so ``x_F = H_FF^{-1} (A_F^T b - beta/2)`` there: the sparsity term only shifts it and
``df`` is the trace of the ridge-like smoother on the free set (for the lasso, the number of
non-zeros; Tibshirani & Taylor 2012).  SURE's score is ``(sum w r^2 + 2 df) / n = 1 + R / n``:
Mallows' ``C_p``, the expected noise-weighted squared error of a *new* image at the same
settings, 1 at the noise level.  Generalized cross-validation, ``n sum w r^2 / (n - df)^2``
(Craven & Wahba 1979), estimates the same with the noise *level* taken from the residual
instead of the camera model (the weights ``w`` keep the model's relative noise; ``w = 1``
without a camera model).

Which of them (measured on 46 stacks nobody tuned them on, ``docs/user_guide/demux_weights.md``).
GCV is the default: the camera model gives the observations' *relative* noise, but the camera's
row jitter and other unmodelled noise scale it by 1.5-4x, and SURE at the model's level then
charges too little for ``df`` and smooths too little (wax: 1.22x the best error); GCV takes the
level from the residuals.  Both need only the fit to the pixel's own observations, which a
certified objective gap pins down, and one solve per pair.  K-fold cross-validation over the
images (the earlier criterion) needs neither ``df`` nor a noise level, but a fold left out shrinks
the sweep from 75 to 60 images of an underdetermined problem (229 offsets, rank of ``A`` ~ 40-70):
it scores the weights a *smaller* sweep needs -- more smoothing (the mirror ball: 1.21x the best,
13 % worse than 0.01 / 0.01) -- and its predictions of left-out images go through directions the
training images barely see, where a solve certified to an objective gap of 1e-3 is still far from
its optimum: its curve at small ``alpha`` measured where ADMM stopped.

References
----------
.. [1] C. M. Stein, "Estimation of the mean of a multivariate normal distribution", Ann. Statist.
   9(6), 1981.
.. [2] C. L. Mallows, "Some comments on C_p", Technometrics 15(4), 1973.
.. [3] R. J. Tibshirani, J. Taylor, "Degrees of freedom in lasso problems", Ann. Statist. 40(2), 2012.
.. [4] P. Craven, G. Wahba, "Smoothing noisy data with spline functions", Numer. Math. 31, 1979.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from . import _kernels as K

__all__ = ["degrees_of_freedom", "degrees_of_freedom_batch", "pixel_scores"]


def _path_band(F, n_x: int):
    """Diagonal and first off-diagonal of ``(D^T D)_FF`` for sorted unknowns ``F < n_x``.

    ``D^T D`` is the path Laplacian (2 inside, 1 at the two ends, -1 between neighbours), so
    its principal submatrix is tridiagonal: -1 where consecutive free unknowns are neighbours.
    """
    d = np.where((F == 0) | (F == n_x - 1), 1.0, 2.0) if n_x > 1 else np.zeros(F.size)
    off = np.where(np.diff(F) == 1, -1.0, 0.0)
    return d, off


def degrees_of_freedom(A, alpha: float, x, n_x: int) -> float:
    """``df = tr(A_F (A_F^T A_F + alpha R_FF)^{-1} A_F^T)`` of one pixel, ``R = D^T D`` on the transport.

    Two exact routes, whichever is smaller: with ``m = |F|`` free unknowns and ``n`` observations,

    * ``m <= n`` (or ``alpha = 0``, or every transport unknown free): ``df = m - alpha tr(H^{-1}
      R_FF)`` from the Cholesky factor of ``H_FF`` (LAPACK potrf, trtri; ``R`` is tridiagonal, so
      only the band of ``H^{-1}`` next to the diagonal is needed);
    * ``m > n`` (underdetermined, the usual case at small weights): in the observations' space.
      With ``C = S R_TT^{-1} S^T / alpha`` (``S`` the free transport columns; ``R_TT`` their
      tridiagonal block, positive definite unless every transport unknown is free) the ridge
      part is ``J_T = C (I + C)^{-1}`` (Woodbury), ``tr J_T = n - tr W``, ``W = (I + C)^{-1}``; the
      unpenalized columns ``S_U`` (the ambient) add ``tr((S_U^T W S_U)^{-1} S_U^T W^2 S_U)``
      (the fit after partialling them out).  ``n^2 m`` flops instead of ``m^3``.

    Parameters
    ----------
    A : ndarray (n, U)
        The rows of the illumination matrix the pixel uses, in the solver's variables.
    alpha : float
    x : ndarray (U,)
        The pixel's solution; its positive entries are the free set ``F``.
    n_x : int
        Unknowns of the transport (smoothed); the rest are not.

    Returns
    -------
    float
        Between 0 and ``min(|F|, rank A_F)``.
    """
    F = np.flatnonzero(np.asarray(x) > 0)
    m = F.size
    if m == 0:
        return 0.0
    A = np.asarray(A, np.float64)
    n = A.shape[0]
    FT, FU = F[F < n_x], F[F >= n_x]
    every = FT.size == n_x
    if m > n and alpha > 0 and FT.size and not every:
        S = A[:, FT]
        d, off = _path_band(FT, n_x)
        ab = np.zeros((2, FT.size))
        ab[0, 1:] = off
        ab[1] = d
        Y = sla.solveh_banded(ab, S.T, check_finite=False)  # R_TT^{-1} S^T
        M = (S @ Y) / alpha
        M[np.diag_indices(n)] += 1.0
        L, info = sla.lapack.dpotrf(M, lower=1, clean=1, overwrite_a=1)
        if info == 0:
            Li, info = sla.lapack.dtrtri(L, lower=1, overwrite_c=1)
        if info == 0:
            df = n - float(np.einsum("ij,ij->", Li, Li))
            if FU.size:
                V = Li @ A[:, FU]  # W = Li^T Li
                WU = Li.T @ V
                df += float(np.trace(np.linalg.solve(V.T @ V, WU.T @ WU)))
            return df
    d = np.zeros(m)
    off = np.zeros(max(m - 1, 0))
    if FT.size:
        d[: FT.size], off[: FT.size - 1] = _path_band(FT, n_x)
    S = A[:, F]
    H = S.T @ S
    k = np.arange(m)
    H[k, k] += alpha * d
    H[k[:-1], k[1:]] += alpha * off
    H[k[1:], k[:-1]] += alpha * off
    L, info = sla.lapack.dpotrf(H, lower=1, clean=1)
    if info != 0:  # singular on the free set (alpha = 0 and more free unknowns than observations)
        return float(np.trace(np.linalg.pinv(H, hermitian=True) @ (S.T @ S)))
    if alpha == 0.0:
        return float(m)
    Li, info = sla.lapack.dtrtri(L, lower=1, overwrite_c=1)
    if info != 0:  # pragma: no cover - L is a valid Cholesky factor
        raise np.linalg.LinAlgError(f"dtrtri failed ({info})")
    diag = np.einsum("ij,ij->j", Li, Li)  # (H^{-1})_kk = ||Li[:, k]||^2 (Li is lower: no clean-up needed)
    band = np.einsum("ij,ij->j", Li[:, :-1], Li[:, 1:])  # (H^{-1})_{k,k+1}
    return float(m - alpha * (d @ diag + 2.0 * off @ band))


#: Pixels whose observation-space degrees of freedom are computed together (memory: 2 x CHUNK x N x U floats).
_CHUNK = 64


def _rebuild(S, Y, alpha):
    M = S @ Y / alpha
    M[np.diag_indices(M.shape[0])] += 1.0
    return M


def _ridge_traces_lapack(M, SU, use) -> tuple[float, float]:
    """``tr W`` and ``tr((S_U^T W S_U)^{-1} S_U^T W^2 S_U)`` of ``W = M^{-1}`` by LAPACK (any number of columns)."""
    L, info = sla.lapack.dpotrf(M, lower=1, clean=1)
    if info != 0:  # pragma: no cover - I + C is positive definite
        raise np.linalg.LinAlgError("I + C is not positive definite")
    Li, _ = sla.lapack.dtrtri(L, lower=1)
    extra = 0.0
    if use.any():
        V = Li @ SU[:, use]
        WU = Li.T @ V
        extra = float(np.trace(np.linalg.solve(V.T @ V, WU.T @ WU)))
    return float(np.einsum("ij,ij->", Li, Li)), extra


def degrees_of_freedom_batch(A, alpha: float, X, n_x: int, *, mask=None) -> np.ndarray:
    """:func:`degrees_of_freedom` of every pixel ``X`` (P, U), the observation-space ones together.

    Pixels with more free unknowns than observations, all of them used (the usual case at small
    weights), go through the observation-space route in stacks of :data:`_CHUNK` of similar
    sizes: the tridiagonal solves compiled (:func:`planeray.demux._kernels.path_solves`), one
    stacked product, then each pixel's ``n x n`` Cholesky factor and its inverse's trace compiled
    without the GIL (:func:`planeray.demux._kernels.ridge_traces`) -- the same numbers as one by
    one (to 1e-13), 2-3x faster, and the solver threads run them side by side.  The others one
    by one.
    """
    A = np.asarray(A, np.float64)
    X = np.asarray(X, np.float64)
    P, U = X.shape
    n = A.shape[0]
    free = X > 0
    m = free.sum(axis=1)
    mT = free[:, :n_x].sum(axis=1)
    full = np.ones(P, bool) if mask is None else np.asarray(mask, bool).all(axis=1)
    batch = (alpha > 0) & (m > n) & (mT > 0) & (mT < n_x) & full
    df = np.empty(P)
    for p in np.flatnonzero(~batch):
        Ap = A if full[p] else A[np.asarray(mask[p], bool)]
        df[p] = degrees_of_freedom(Ap, alpha, X[p], n_x)
    idx = np.flatnonzero(batch)
    idx = idx[np.argsort(mT[idx], kind="stable")]  # chunks of similar sizes: little padding
    SU = A[:, n_x:]  # the unpenalized columns (the ambient)
    for s in range(0, idx.size, _CHUNK):
        ps = idx[s : s + _CHUNK]
        k = int(mT[ps].max())
        order = np.argsort(~free[ps, :n_x], axis=1, kind="stable")[:, :k]  # each pixel's free unknowns first
        S = np.zeros((ps.size, n, k))
        Y = np.zeros((ps.size, k, n))
        K.path_solves(A, np.ascontiguousarray(order), mT[ps].astype(np.int64), n_x, S, Y)
        M = np.matmul(S, Y)
        M /= alpha
        M[:, np.arange(n), np.arange(n)] += 1.0
        use = free[ps, n_x:]  # which unpenalized columns are free, per pixel
        tr = np.empty((ps.size, 2))
        if SU.shape[1] == 1:  # the ambient: compiled, no GIL (the solver threads run it side by side)
            K.ridge_traces(M, np.ascontiguousarray(SU[:, 0]), use[:, 0].copy(), tr)
        else:
            tr[:] = np.nan
        for q in np.flatnonzero(~np.isfinite(tr[:, 0])):  # other unpenalized columns (or a failed factor)
            tr[q] = _ridge_traces_lapack(M[q] if SU.shape[1] != 1 else _rebuild(S[q], Y[q], alpha), SU, use[q])
        df[ps] = n - tr[:, 0] + tr[:, 1]
    return df


def pixel_scores(A, X, B, weights, alpha: float, n_x: int, *, mask=None, gcv: bool = False) -> np.ndarray:
    """The criterion of each pixel: ``(sum w r^2 + 2 df) / n`` (SURE / ``C_p``), or GCV's ``n sum r^2 / (n - df)^2``.

    Parameters
    ----------
    A : ndarray (N, U)
        Illumination matrix in the solver's variables (with the ambient: its scaled column last).
    X : ndarray (P, U)
        The pixels' solutions (exact to a certified gap).
    B, weights : ndarray (P, N)
        Observations and inverse noise variances (0 where an observation is not used).
    alpha : float
    n_x : int
        Unknowns of the transport (the smoothness term's); the rest (the ambient) is not smoothed.
    mask : ndarray (P, N) bool, optional
        Observations used (None: all).
    gcv : bool
        Generalized cross-validation on the unweighted residual instead (no noise model).
    """
    A = np.asarray(A, np.float64)
    Rr = B - X @ A.T
    used = np.ones(B.shape, bool) if mask is None else np.asarray(mask, bool)
    n = used.sum(axis=1)
    dfs = degrees_of_freedom_batch(A, alpha, X, n_x, mask=mask)
    out = np.empty(B.shape[0])
    for p in range(B.shape[0]):
        df = dfs[p]
        r = Rr[p][used[p]]
        chi2 = float(weights[p][used[p]] @ (r * r))
        if gcv:
            out[p] = n[p] * chi2 / max(n[p] - df, 1.0) ** 2
        else:
            out[p] = (chi2 + 2.0 * df) / max(n[p], 1)
    return out
