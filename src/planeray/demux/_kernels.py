"""Compiled per-pixel passes of the fast demultiplexer (:mod:`planeray.demux.fast`).

The shared ``(P, U) x (U, U)`` products of an ADMM iteration and of the certificate stay
in BLAS (NumPy's ``matmul``); everything *per pixel* is fused here into one pass over
each pixel's row with nothing allocated, so that an iteration is one matrix product and
one pass, and two Python threads run two pixel batches at once (``nogil``):

* :func:`relaxed_step`: ``v <- decay v + t + c`` and ``|v|`` for the next product, with
  the residual-balancing norms on the iteration before a check;
* :func:`woodbury_apply`: the low-rank correction of a pixel whose saturated observations
  were dropped: its x-update operator is ``(Q + rho I - 2 A_s^T A_s)^{-1} =
  M + (A_s M)^T S^{-1} (A_s M)`` with ``S = I/2 - A_s M A_s^T`` (``k x k``, ``k`` dropped
  rows), so the shared ``M`` serves every pixel for ``2 k U`` flops per iteration
  (:func:`woodbury_inverses` keeps ``S^{-1}`` per pixel and rho, :func:`woodbury_coeffs`
  does the same in float64 for the once-per-pixel constants);
* :func:`woodbury_factors`, :func:`woodbury_quad`: the same for the certificate's
  ``Q_p^{-1}``;
* :func:`split_dual`, :func:`finish_residual`, :func:`finish_gradient`, :func:`half_norms`:
  the certificate's per-pixel parts (objective, gradient, KKT residual, gap bound);
  :func:`null_adjust` the multiplier's move that keeps the bound finite when ``Q`` is
  singular (the ambient term of Eq. 6a).

Compiled by Numba on first use and cached on disk.

References
----------
.. [1] W. W. Hager, "Updating the inverse of a matrix", SIAM Review 31(2), 1989 (Woodbury).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = [
    "relaxed_step",
    "woodbury_factors",
    "woodbury_inverses",
    "woodbury_apply",
    "woodbury_coeffs",
    "woodbury_quad",
    "split_dual",
    "finish_residual",
    "finish_gradient",
    "null_adjust",
    "half_norms",
    "warm_up",
]

_JIT = dict(cache=True, nogil=True, error_model="numpy")


@numba.njit(**_JIT)
def relaxed_step(V, T, C, decay, absV, track, dz2, dw2):  # pragma: no cover - compiled
    """``V <- decay V + T + C`` and ``absV = |V|`` in one pass (float32, in place).

    With ``track`` also the squared changes of ``z = max(v, 0)`` and ``w = min(v, 0)``
    (the dual and primal residuals of residual balancing) into ``dz2``, ``dw2``.
    """
    P, U = V.shape
    for p in range(P):
        sz = 0.0
        sw = 0.0
        for u in range(U):
            old = V[p, u]
            v = decay * old + T[p, u] + C[p, u]
            V[p, u] = v
            absV[p, u] = abs(v)
            if track:
                d = max(v, np.float32(0.0)) - max(old, np.float32(0.0))
                e = min(v, np.float32(0.0)) - min(old, np.float32(0.0))
                sz += d * d
                sw += e * e
        if track:
            dz2[p] = sz
            dw2[p] = sw


@numba.njit(**_JIT)
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


@numba.njit(**_JIT)
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


@numba.njit(**_JIT)
def _schur_block(K, rows, kq, S):  # pragma: no cover - compiled
    """``S[:kq, :kq] = I/2 - K[rows, rows]`` (the Woodbury capacitance of the dropped rows)."""
    for i in range(kq):
        for j in range(kq):
            S[i, j] = -K[rows[i], rows[j]]
        S[i, i] += 0.5


@numba.njit(**_JIT)
def woodbury_factors(K, sel, k, pix, L, ok):  # pragma: no cover - compiled
    """Cholesky factors of ``S_p = I/2 - K[s_p, s_p]`` for the masked pixels ``pix``.

    ``K``: (N, N) float64 (``A M A^T``, or ``A Q^{-1} A^T`` for the certificate); ``sel``:
    (Pm, kmax) dropped rows of each masked pixel; ``k``: (Pm,) their number; ``L``:
    (Pm, kmax, kmax) float64, rows ``pix`` overwritten; ``ok``: (Pm,) bool (False: ``S_p``
    is not numerically positive definite).
    """
    for q in pix:
        kq = k[q]
        S = L[q]
        _schur_block(K, sel[q], kq, S)
        ok[q] = _chol(S, kq)


@numba.njit(**_JIT)
def woodbury_inverses(K, sel, k, pix, Sinv, ok):  # pragma: no cover - compiled
    """``Sinv[q] = (I/2 - K[s_q, s_q])^{-1}`` (float64, via Cholesky) for the masked pixels ``pix``."""
    kmax = sel.shape[1]
    S = np.empty((kmax, kmax))
    e = np.empty(kmax)
    for q in pix:
        kq = k[q]
        _schur_block(K, sel[q], kq, S)
        ok[q] = _chol(S, kq)
        if not ok[q]:
            continue
        for c in range(kq):
            for i in range(kq):
                e[i] = 0.0
            e[c] = 1.0
            _chol_solve(S, e, kq)
            for i in range(kq):
                Sinv[q, i, c] = e[i]


@numba.njit(**_JIT)
def woodbury_coeffs(Y, masked, sel, k, Sinv, scale, W):  # pragma: no cover - compiled
    """``W[p, s_p] = scale S_p^{-1} Y[p, s_p]``, 0 elsewhere (float64): with ``Y = X (A M)^T``,
    ``W (A M)`` is the Woodbury term of ``x_p M_p`` (the once-per-pixel constants)."""
    for p in range(Y.shape[0]):
        for i in range(W.shape[1]):
            W[p, i] = 0.0
        q = masked[p]
        if q < 0:
            continue
        kq = k[q]
        for i in range(kq):
            acc = 0.0
            for j in range(kq):
                acc += Sinv[q, i, j] * Y[p, sel[q, j]]
            W[p, sel[q, i]] = scale * acc


@numba.njit(cache=True, nogil=True, fastmath=True)
def _selected_dots(Mat, rows, kq, x, y):  # pragma: no cover - compiled
    """``y[j] = Mat[rows[j]] . x`` for ``j < kq``, four rows at a time.

    Four independent sums per pass over ``x`` vectorize (one sum is latency-bound);
    ``fastmath`` reassociates them, a change at the rounding of the operands' type.
    """
    U = x.shape[0]
    j = 0
    while j < kq:
        r0 = Mat[rows[j]]
        r1 = Mat[rows[min(j + 1, kq - 1)]]
        r2 = Mat[rows[min(j + 2, kq - 1)]]
        r3 = Mat[rows[min(j + 3, kq - 1)]]
        a0 = r0[0] * x[0] * 0
        a1 = a0
        a2 = a0
        a3 = a0
        for u in range(U):
            xu = x[u]
            a0 += r0[u] * xu
            a1 += r1[u] * xu
            a2 += r2[u] * xu
            a3 += r3[u] * xu
        y[j] = a0
        if j + 1 < kq:
            y[j + 1] = a1
        if j + 2 < kq:
            y[j + 2] = a2
        if j + 3 < kq:
            y[j + 3] = a3
        j += 4


@numba.njit(cache=True, nogil=True, fastmath=True)
def woodbury_apply(X, AMs, level, masked, sel, k, Sinv, scales, out):  # pragma: no cover - compiled
    """``out[p] += scale (A_s M)^T S_p^{-1} (A_s M) x_p`` for the rows with ``masked[p] >= 0``.

    Float32 (the iteration's precision). ``AMs[level[p]]`` (N, U) is ``A M`` at the row's
    rho and ``scales[level[p]]`` its ``r rho``; ``Sinv[masked[p]]`` the pixel's ``S^{-1}``.
    Four dropped rows at a time (:func:`_selected_dots`; the update likewise).
    """
    kmax = sel.shape[1]
    y = np.empty(kmax, np.float32)
    w = np.empty(kmax, np.float32)
    U = X.shape[1]
    for p in range(X.shape[0]):
        q = masked[p]
        if q < 0:
            continue
        kq = k[q]
        x = X[p]
        o = out[p]
        AM = AMs[level[p]]
        scale = scales[level[p]]
        _selected_dots(AM, sel[q], kq, x, y)
        Si = Sinv[q]
        for i in range(kq):
            acc = 0.0
            for j in range(kq):
                acc += Si[i, j] * y[j]
            w[i] = scale * acc
        j = 0
        while j + 4 <= kq:
            r0 = AM[sel[q, j]]
            r1 = AM[sel[q, j + 1]]
            r2 = AM[sel[q, j + 2]]
            r3 = AM[sel[q, j + 3]]
            w0 = w[j]
            w1 = w[j + 1]
            w2 = w[j + 2]
            w3 = w[j + 3]
            for u in range(U):
                o[u] += w0 * r0[u] + w1 * r1[u] + w2 * r2[u] + w3 * r3[u]
            j += 4
        while j < kq:
            r0 = AM[sel[q, j]]
            w0 = w[j]
            for u in range(U):
                o[u] += w0 * r0[u]
            j += 1


@numba.njit(cache=True, nogil=True, fastmath=True)
def woodbury_quad(H, AQ, masked, sel, k, L, out):  # pragma: no cover - compiled
    """``out[p] += 1/2 y^T S_p^{-1} y`` with ``y = (A Q^{-1})_s h_p``: the extra part of ``1/2 h^T Q_p^{-1} h``.

    Float64 sums, four dropped rows at a time (``fastmath`` reassociates them).
    """
    kmax = max(sel.shape[1], 1)
    y = np.empty(kmax)
    z = np.empty(kmax)
    for p in range(H.shape[0]):
        q = masked[p]
        if q < 0:
            continue
        kq = k[q]
        h = H[p]
        _selected_dots(AQ, sel[q], kq, h, y)
        for j in range(kq):
            z[j] = y[j]
        _chol_solve(L[q], z, kq)
        acc = 0.0
        for j in range(kq):
            acc += y[j] * z[j]
        out[p] += 0.5 * acc


@numba.njit(**_JIT)
def split_dual(V, rho, Z, Lam):  # pragma: no cover - compiled
    """``Z = max(V, 0)`` (float64) and the multiplier ``Lam = -rho min(V, 0)`` (float32)."""
    P, U = V.shape
    for p in range(P):
        r = rho[p]
        for u in range(U):
            v = V[p, u]
            if v > 0:
                Z[p, u] = v
                Lam[p, u] = 0.0
            else:
                Z[p, u] = 0.0
                Lam[p, u] = -r * v


@numba.njit(**_JIT)
def finish_residual(R, B, keep, R32, rr):  # pragma: no cover - compiled
    """``R -= B`` (dropped observations: 0), its float32 copy and ``rr = ||R||^2`` per pixel.

    ``keep`` is (P, N) bool or (0, 0) when every observation counts.
    """
    P, N = R.shape
    masked = keep.shape[0] > 0
    for p in range(P):
        s = 0.0
        for i in range(N):
            r = R[p, i] - B[p, i]
            if masked and not keep[p, i]:
                r = 0.0
            R32[p, i] = r
            s += r * r
        rr[p] = s


@numba.njit(**_JIT)
def finish_gradient(G, Z, Lam, alpha, beta, n_x, rr, f, kkt, lamz):  # pragma: no cover - compiled
    """From ``G = R^T A`` (float32, in place) to ``G - Lam`` with ``G`` the objective's gradient at ``Z``.

    Also the objective ``f`` (float64), the unscaled KKT residual ``max |min(z, g)|`` and
    ``lamz = Lam^T Z`` per pixel.  The first ``n_x`` unknowns are the transport (smoothness
    and sparsity); any further one is the ambient of Eq. 6a (neither).
    """
    P, U = G.shape
    a2 = 2.0 * alpha
    for p in range(P):
        smooth = 0.0
        total = 0.0
        worst = 0.0
        lz = 0.0
        for u in range(U):
            z = Z[p, u]
            if u < n_x:
                g = 2.0 * G[p, u] + beta
                if u > 0:
                    d = z - Z[p, u - 1]
                    smooth += d * d
                    g += a2 * d
                if u < n_x - 1:
                    g -= a2 * (Z[p, u + 1] - z)
                total += z
            else:
                g = 2.0 * G[p, u]
            m = abs(min(z, g))
            if m > worst:
                worst = m
            lz += Lam[p, u] * z
            G[p, u] = g - Lam[p, u]
        f[p] = rr[p] + alpha * smooth + beta * total
        kkt[p] = worst
        lamz[p] = lz


@numba.njit(**_JIT)
def null_adjust(H, Z, Lam, n, lamz):  # pragma: no cover - compiled
    """Move each pixel's multiplier along ``Q``'s null direction ``n`` so that ``n^T (g - lam) = 0``.

    ``H`` (P, U) float32 holds ``g - lam`` (in place), ``Z`` (P, U) the iterate, ``Lam``
    (P, U) the multiplier, ``n`` (U,) the unit null vector, ``lamz`` (P,) ``lam^T z``
    (updated).  Weak duality bounds the gap by ``1/2 h^T Q^+ h + lam^T z`` only when
    ``h = g - lam`` is orthogonal to ``n``; the dual optimum has ``d = n^T h = 0``, so near
    it the move is small, and it is made where it costs least:

    1. raise the multiplier of an unknown at 0 with ``n_j d > 0`` by ``d / n_j`` (it adds
       nothing to ``lam^T z``);
    2. else lower the multipliers with ``n_j d < 0`` in proportion to themselves, if they
       can absorb ``d`` (they stay >= 0 and ``lam^T z`` does not grow; the change of ``h``
       is spread, so the quadratic term moves by ``O(d^2)``);
    3. else raise the multiplier of the unknown with the smallest ``z_j / |n_j|``.

    Without step 2, a ``d < 0`` left by the float32 iterate could only go onto the ambient
    unknown (``n``'s one negative entry), whose ``z`` is large: ``|d| z_a / |n_a|`` then
    floored the bound above ``tol f`` for pixels whose objective is small (low noise), and
    they ran to the iteration cap at a true gap of 1e-8.
    """
    P, U = H.shape
    for p in range(P):
        d = 0.0
        for u in range(U):
            d += H[p, u] * n[u]
        if d == 0.0:
            continue
        best = np.inf
        j = -1
        for u in range(U):
            if n[u] * d > 0.0:
                c = Z[p, u] / abs(n[u])
                if c < best:
                    best = c
                    j = u
        if j >= 0 and best == 0.0:  # 1. free
            H[p, j] = H[p, j] - d / n[j]
            continue
        cap = 0.0
        for u in range(U):
            if n[u] * d < 0.0 and Lam[p, u] > 0.0:
                cap += abs(n[u]) * Lam[p, u]
        if cap >= abs(d):  # 2. spread over the multipliers on the other side
            t = abs(d) / cap
            for u in range(U):
                if n[u] * d < 0.0 and Lam[p, u] > 0.0:
                    step = t * Lam[p, u]
                    H[p, u] = H[p, u] + step
                    lamz[p] -= step * Z[p, u]
            continue
        if j < 0:
            continue
        delta = d / n[j]  # 3. the cheapest raise
        H[p, j] = H[p, j] - delta
        lamz[p] += delta * Z[p, j]


@numba.njit(**_JIT)
def half_norms(W, lamz, out):  # pragma: no cover - compiled
    """``out = 1/2 ||W||^2 + lamz`` per pixel (float64 accumulation): the gap bound."""
    P, U = W.shape
    for p in range(P):
        s = 0.0
        for u in range(U):
            w = W[p, u]
            s += w * w
        out[p] = 0.5 * s + lamz[p]


def warm_up() -> None:
    """Load every kernel from Numba's cache (compile on a first run) on tiny arrays.

    The first call of a kernel in a process costs ~0.3 s (Numba's start); the driver
    runs this on a solver thread while the first rows are read.
    """
    V = np.zeros((1, 4), np.float32)
    z = np.zeros(1)
    relaxed_step(V, V.copy(), V.copy(), np.float32(0.1), V.copy(), True, z.copy(), z.copy())
    split_dual(V, np.ones(1, np.float32), np.zeros((1, 4)), V.copy())
    finish_residual(np.zeros((1, 2)), np.zeros((1, 2)), np.zeros((0, 0), bool), np.zeros((1, 2), np.float32), z.copy())
    finish_gradient(V.copy(), np.zeros((1, 4)), V.copy(), 0.01, 0.01, 4, z.copy(), z.copy(), z.copy(), z.copy())
    null_adjust(V.copy(), np.zeros((1, 4)), V.copy(), np.full(4, 0.5), z.copy())
    half_norms(V, z.copy(), z.copy())
