"""Compiled per-pixel parts of the fast demultiplexer (:mod:`planeray.demux.fast`).

The shared ``(P, U) x (U, U)`` matrix product of an ADMM iteration stays in BLAS; what is
*per pixel* is fused here, one pass over each pixel's row, nothing allocated:

* the ADMM step ``g = decay v + |v| Mp + c`` with the **Woodbury correction** of a pixel
  whose saturated observations were dropped: its x-update operator is
  ``(Q + rho I - 2 A_s^T A_s)^{-1} = M + (M A_s^T) S^{-1} (A_s M)`` with
  ``S = I/2 - A_s M A_s^T`` (k x k, ``k`` = dropped rows), so the shared ``M`` serves every
  pixel and the correction costs ``2 k U`` per iteration instead of a factorization;
* **Anderson acceleration** (type II, memory ``m``) of the ADMM fixed-point map with a
  residual safeguard (a step whose fixed-point residual grew restarts the memory).

Compiled by Numba on first use and cached on disk; ``nogil`` so two Python threads run two
pixel batches at once.

References
----------
.. [1] W. W. Hager, "Updating the inverse of a matrix", SIAM Review 31(2), 1989 (Woodbury).
.. [2] H. F. Walker, P. Ni, "Anderson acceleration for fixed-point iterations", SIAM J.
   Numer. Anal. 49(4), 2011.
.. [3] J. Zhang, B. O'Donoghue, S. Boyd, "Globally convergent type-I Anderson acceleration
   for nonsmooth fixed-point iterations", SIAM J. Optim. 30(4), 2020 (safeguarding).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["woodbury_factors", "woodbury_add", "woodbury_quad", "admm_step"]


@numba.njit(cache=True, nogil=True)
def _chol(S, k):  # pragma: no cover - compiled
    """In-place lower Cholesky of ``S[:k, :k]``; False if not positive definite."""
    for j in range(k):
        d = S[j, j]
        for i in range(j):
            d -= S[j, i] * S[j, i]
        if not d > 0.0:
            return False
        d = np.sqrt(d)
        S[j, j] = d
        for r in range(j + 1, k):
            s = S[r, j]
            for i in range(j):
                s -= S[r, i] * S[j, i]
            S[r, j] = s / d
    return True


@numba.njit(cache=True, nogil=True)
def _chol_solve(L, y, k):  # pragma: no cover - compiled
    """Solve ``L L^T w = y`` in place (``y[:k]``)."""
    for i in range(k):
        s = y[i]
        for j in range(i):
            s -= L[i, j] * y[j]
        y[i] = s / L[i, i]
    for i in range(k - 1, -1, -1):
        s = y[i]
        for j in range(i + 1, k):
            s -= L[j, i] * y[j]
        y[i] = s / L[i, i]


@numba.njit(cache=True, nogil=True)
def woodbury_factors(K, sel, k, L, ok):  # pragma: no cover - compiled
    """Cholesky factors of ``S_p = I/2 - K[s_p, s_p]`` for every pixel with dropped rows.

    ``K``: (N, N) float64 (``A M A^T``); ``sel``: (P, kmax) dropped rows; ``k``: (P,) their
    number; ``L``: (P, kmax, kmax) float64 output; ``ok``: (P,) bool output (False: ``S_p``
    not numerically positive definite -- the caller solves that pixel another way).
    """
    for p in range(sel.shape[0]):
        kp = k[p]
        ok[p] = True
        if kp == 0:
            continue
        S = L[p]
        for i in range(kp):
            for j in range(kp):
                S[i, j] = -K[sel[p, i], sel[p, j]]
            S[i, i] += 0.5
        ok[p] = _chol(S, kp)


@numba.njit(cache=True, nogil=True)
def woodbury_add(X, AM, rows, sel, k, L, scale, out):  # pragma: no cover - compiled
    """``out[p] += scale * (AM[s]^T S_p^{-1} AM[s]) x_p``: the Woodbury term of ``x_p M_p`` (pixel ``rows[p]``)."""
    y = np.empty(sel.shape[1])
    U = X.shape[1]
    for p in range(X.shape[0]):
        q = rows[p]
        kp = k[q]
        if kp == 0:
            continue
        for j in range(kp):
            s = sel[q, j]
            acc = 0.0
            for u in range(U):
                acc += AM[s, u] * X[p, u]
            y[j] = acc
        _chol_solve(L[q], y, kp)
        for j in range(kp):
            s = sel[q, j]
            w = scale * y[j]
            for u in range(U):
                out[p, u] += w * AM[s, u]


@numba.njit(cache=True, nogil=True)
def woodbury_quad(R, AQ, rows, sel, k, L, out):  # pragma: no cover - compiled
    """``out[p] = y^T S_p^{-1} y`` with ``y = AQ[s] r_p`` (the extra part of ``r^T Q_p^{-1} r``; pixel ``rows[p]``)."""
    y = np.empty(sel.shape[1])
    U = R.shape[1]
    for p in range(R.shape[0]):
        q = rows[p]
        kp = k[q]
        out[p] = 0.0
        if kp == 0:
            continue
        for j in range(kp):
            s = sel[q, j]
            acc = 0.0
            for u in range(U):
                acc += AQ[s, u] * R[p, u]
            y[j] = acc
        z = y.copy()
        _chol_solve(L[q], z, kp)
        q = 0.0
        for j in range(kp):
            q += y[j] * z[j]
        out[p] = q


@numba.njit(cache=True, nogil=True, fastmath=True)
def admm_step(
    V, T, C, decay, rrho, AM, rows, sel, k, L, Fp, Gp, dF, dG, gram, cnt, head, rn_prev, anderson
):  # pragma: no cover
    """One ADMM step per pixel, in place on ``V`` (float32), after ``T = |V| Mp`` (BLAS).

    Pixel ``p`` of the batch has its dropped rows in ``sel[rows[p]]``, ``k[rows[p]]`` and
    its Woodbury factor in ``L[rows[p]]`` (``rows``: no copy of the factors per batch).

    ``g = decay v + T + c`` (+ ``rrho`` times the Woodbury term for dropped rows), then,
    when ``anderson``, the type-II Anderson extrapolation over the last ``m`` steps
    (``dF``/``dG``: differences of residuals ``g - v`` and of images ``g``; ``gram``: their
    Gram matrix, updated by one row per step).  A step whose residual norm grew since the
    previous one restarts the pixel's memory (the safeguard).
    """
    P, U = V.shape
    m = dF.shape[1]
    g = np.empty(U, np.float32)
    f = np.empty(U, np.float32)
    y = np.empty(max(sel.shape[1], 1))
    G = np.empty((m, m))
    r = np.empty(m)
    for p in range(P):
        for u in range(U):
            g[u] = decay * V[p, u] + T[p, u] + C[p, u]
        q = rows[p]
        kp = k[q]
        if kp > 0:
            for j in range(kp):
                s = sel[q, j]
                acc = np.float32(0.0)
                for u in range(U):
                    acc += AM[s, u] * abs(V[p, u])
                y[j] = acc
            _chol_solve(L[q], y, kp)
            for j in range(kp):
                s = sel[q, j]
                w = np.float32(rrho[p] * y[j])
                for u in range(U):
                    g[u] += w * AM[s, u]
        rn = np.float32(0.0)
        for u in range(U):
            f[u] = g[u] - V[p, u]
            rn += f[u] * f[u]
        if not anderson:
            for u in range(U):
                V[p, u] = g[u]
            continue
        if rn_prev[p] >= 0.0:  # a previous step exists
            if rn > rn_prev[p]:  # safeguard: the residual grew, restart the memory
                cnt[p] = 0
                head[p] = 0
            else:
                j = head[p]
                for u in range(U):
                    dF[p, j, u] = f[u] - Fp[p, u]
                    dG[p, j, u] = g[u] - Gp[p, u]
                c = min(cnt[p] + 1, m)
                cnt[p] = c
                head[p] = (j + 1) % m
                for i in range(c):
                    acc = np.float32(0.0)
                    for u in range(U):
                        acc += dF[p, j, u] * dF[p, i, u]
                    gram[p, j, i] = acc
                    gram[p, i, j] = acc
        rn_prev[p] = rn
        for u in range(U):
            Fp[p, u] = f[u]
            Gp[p, u] = g[u]
        c = cnt[p]
        solved = False
        if c > 0:
            tr = 0.0
            for i in range(c):
                tr += gram[p, i, i]
            for i in range(c):
                for j in range(c):
                    G[i, j] = gram[p, i, j]
                G[i, i] += 1e-10 * tr + 1e-30
                acc = np.float32(0.0)
                for u in range(U):
                    acc += dF[p, i, u] * f[u]
                r[i] = acc
            if _chol(G, c):
                _chol_solve(G, r, c)
                solved = True
        if solved:
            for u in range(U):
                acc = g[u]
                for i in range(c):
                    acc -= np.float32(r[i]) * dG[p, i, u]
                V[p, u] = acc
        else:
            for u in range(U):
                V[p, u] = g[u]
