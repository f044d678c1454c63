"""The default demultiplexer: batched ADMM with a shared factorization and a
certified per-pixel stopping rule.

Why this algorithm
------------------
Per pixel the problem is the QP ``min 1/2 x^T Q x - c^T x, x >= 0`` with
``Q = 2 (A^T A + alpha D^T D)`` shared by every pixel of a row group and
``c = 2 A^T b - beta 1`` per pixel (:mod:`planeray.demux.problem`).  ``Q`` is
badly conditioned (~1e6, ~5e8 on edge rows), so plain first-order methods need
thousands of iterations; and at the optimum about half of the 229 offsets are
non-zero and the solutions are spiky, so active-set, primal-dual active-set and
semismooth-Newton methods need per-pixel dense solves of size ~110 that alone
cost more than the whole budget in batched NumPy (measured: 1.9 s per exact solve
round at 128x128).

ADMM on the splitting ``x = z, z >= 0`` needs only ``(Q + rho I)^{-1}``, which is
*shared*: one float64 Cholesky per distinct illumination matrix, then every
iteration for all pixels of the group is a single float32 matrix product.  With
over-relaxation ``r`` and the scaled dual ``w`` the iteration collapses onto one
vector per pixel, ``v = x_relaxed + w`` (``z = max(v, 0)``, ``w = min(v, 0)``)::

    v <- (1 - r/2) v + |v| (r rho M - r/2 I) + r c M,       M = (Q + rho I)^{-1}

Convergence is *certified*, not assumed: for any ``lam >= 0`` weak duality gives
``f(z) - f* <= 1/2 (g - lam)^T Q^{-1} (g - lam) + lam^T z`` with ``g`` the gradient
at ``z``; with ``lam`` the ADMM multiplier ``-rho min(v, 0)`` this bound is within
~1.5x of the true gap.  A pixel stops when the bound proves a relative objective
gap ``<= tol`` and leaves the batch, so the cost follows the mean iteration count
(~30-75 at ``tol = 1e-4``), not the maximum.  ``rho = 0.7, r = 1.8`` minimized the
mean iteration count over the built-in scenes; rho then moves per pixel along a
ladder by residual balancing (at most ``_MAX_MOVES`` times: it can cycle).

Saturated observations stay on the fast path: a pixel that drops the rows ``s``
has ``Q_p = Q - 2 A_s^T A_s``, so its x-update operator is the shared ``M`` plus a
rank-``k`` Woodbury term, ``M_p = M + (M A_s^T) S^{-1} (A_s M)`` with the k x k
``S = I/2 - A_s M A_s^T`` factored once per pixel and rho; the certificate uses
``Q_p^{-1}`` the same way.  The pixel runs in its group's batch (the correction,
``2 k U`` per iteration, is fused into :func:`planeray.demux._kernels.admm_step`).
Grouping pixels by saturation pattern was not needed: the patterns are nearly all
distinct (one factorization per pixel).

Warm starts (``image_width``): 3/4 of a block's rows start from the final ADMM
state and rho of the pixel 1 or 2 rows above (:func:`_warm_schedule`); only the
start changes, every pixel still stops on its own certificate.  Anderson
acceleration (``anderson=True``) cuts iterations by 30-40 % but its per-pixel
memory traffic costs about one matrix product per iteration: slower, so off.

Practicalities measured on a 2-core machine: pixel chunks of 1024 on 2 Python
threads with BLAS held to one thread (threadpoolctl) are 2-2.5x faster than
multithreaded BLAS; float32 entries below 1e-30 are flushed to zero (denormals
make sgemm ~10x slower); only NumPy's matmul is used in the loop (SciPy ships
its own BLAS with its own spinning thread pool).

References
----------
.. [1] S. Boyd, N. Parikh, E. Chu, B. Peleato, J. Eckstein, "Distributed
   optimization and statistical learning via the alternating direction method of
   multipliers", Found. Trends Mach. Learn. 3(1), 2011 (over-relaxation, Sec. 3.4.3).
.. [2] B. Stellato et al., "OSQP: an operator splitting solver for quadratic
   programs", Math. Prog. Comp. 12, 2020.
"""

from __future__ import annotations

import contextlib
import os
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.linalg as sla

from . import _kernels
from .problem import RowGroup, difference_matrix
from .result import SolveResult

__all__ = ["solve_fast", "AdmmRowSolver", "DEFAULT_TOL"]

#: Certified relative objective gap at which a pixel stops.
DEFAULT_TOL = 1e-4
_RELAX = 1.8
_CHUNK = 1024
_FIRST_CHECK = 20
_CHECK_EVERY = 10
_MAX_ITER = 2000


def _flush32(M) -> np.ndarray:
    """float32 copy with would-be denormals set to zero (they make sgemm ~10x slower)."""
    M = np.array(M, np.float64)
    M[np.abs(M) < 1e-30] = 0.0
    return np.ascontiguousarray(M.astype(np.float32))


#: Penalty ladder: each pixel's rho is moved along it by residual balancing
#: (a factor ~3 per step; the best rho depends on the data, e.g. ~0.7 with ambient
#: light and ~5 without, a 3-5x difference in iterations).
_RHO_LADDER = (0.25, 0.7, 2.0, 5.0, 15.0)
_RHO_START = 1  # index of 0.7 in the ladder
#: Anderson memory (steps); 5 halved the mean iterations on random transports without ambient light.
_AA_MEMORY = 5
_BALANCE_AFTER = 20
#: At most this many rho moves per pixel: residual balancing can cycle between two
#: levels or run to an end of the ladder (measured on saturated pixels warm-started at
#: rho = 5: stuck at a 1e-2 gap for 2000 iterations, or at rho = 0.08 for 2000); a
#: fixed rho is then ADMM's convergence guarantee.  The ladder's ends 0.08 and 45 were
#: dropped for the same reason (no pixel of the built-in scenes needed them).
_MAX_MOVES = 6


def _spd_inverse(S) -> np.ndarray:
    """Inverse of a symmetric positive definite matrix (Cholesky + LAPACK potri)."""
    L = np.linalg.cholesky(S)
    inv, info = sla.lapack.dpotri(L, lower=1)
    if info != 0:  # pragma: no cover - L is a valid Cholesky factor
        raise np.linalg.LinAlgError(f"dpotri failed ({info})")
    inv = np.tril(inv)
    return inv + np.tril(inv, -1).T


class _Factor:
    """ADMM operator for one rho: ``v <- decay v + |v| Mp + c M_r`` (+ the Woodbury term of dropped rows)."""

    def __init__(self, A, Q, beta, rho, relax):
        U = Q.shape[0]
        Minv = _spd_inverse(Q + rho * np.eye(U))
        self.rho = rho
        self.Mp = _flush32(relax * rho * Minv - 0.5 * relax * np.eye(U))
        self.AM = A @ Minv  # (N, U): the rows of M A^T, for the Woodbury term
        self.AM32 = _flush32(self.AM)
        self.K = self.AM @ A.T  # A M A^T
        self.relax = relax  # r c M = 2 r b (A M) + g0 with c = 2 A^T b - beta 1
        self.g0 = -beta * relax * Minv.sum(axis=0)

    def constant(self, B, drop=None, rows=None):
        """``r c M_p`` per pixel (float32), exact in float64 before rounding (pixel ``rows[p]`` of ``drop``)."""
        C = (B @ self.AM) * (2.0 * self.relax) + self.g0
        if drop is not None and drop.any:
            sel, k, L = drop.sel, drop.k, drop.factors[self.rho]
            c = 2.0 * B @ drop.A - drop.beta  # the pixel's own c (B already has dropped rows zeroed)
            _kernels.woodbury_add(c, self.AM, rows, sel, k, L, drop.relax, C)
        return _flush32(C)


class _Dropped:
    """Pixels of a batch whose saturated observations are dropped (Woodbury bookkeeping).

    ``sel`` (P, kmax) lists each pixel's dropped rows, ``k`` their number; per rho, the
    Cholesky factors of ``S_p = I/2 - A_s M A_s^T``; for the certificate, those of
    ``I/2 - A_s Q^{-1} A_s^T``.
    """

    def __init__(self, mask, A, beta, relax):
        drop = ~mask
        self.k = drop.sum(axis=1).astype(np.int64)
        kmax = int(self.k.max()) if self.k.size else 0
        self.any = kmax > 0
        order = np.argsort(~drop, axis=1, kind="stable")[:, : max(kmax, 1)]
        self.sel = np.ascontiguousarray(order.astype(np.int64))
        self.kmax = max(kmax, 1)
        self.A, self.beta, self.relax = A, beta, relax
        self.factors: dict[float, np.ndarray] = {}
        self.valid: dict[float, np.ndarray] = {}

    def factor(self, rho, K) -> np.ndarray:
        """Factors for ``rho`` (computed once); returns the pixels whose ``S_p`` is positive definite."""
        if rho not in self.factors:
            L = np.zeros((self.sel.shape[0], self.kmax, self.kmax))
            ok = np.empty(self.sel.shape[0], bool)
            _kernels.woodbury_factors(K, self.sel, self.k, L, ok)
            self.factors[rho] = L
            self.valid[rho] = ok
        return self.valid[rho]

    def take(self, keep, rhos=None):
        """The bookkeeping of a subset of the pixels (with the factors of ``rhos``; default: all)."""
        out = object.__new__(_Dropped)
        out.__dict__.update(self.__dict__)
        out.k, out.sel = self.k[keep], self.sel[keep]
        rhos = self.factors if rhos is None else rhos
        out.factors = {r: self.factors[r][keep] for r in rhos}
        out.valid = {r: self.valid[r][keep] for r in rhos}
        out.any = bool(out.k.size and out.k.max() > 0)
        return out


class AdmmRowSolver:
    """Everything that depends only on the illumination matrix ``A`` (one per row group)."""

    def __init__(self, A, alpha, beta, relax=_RELAX):
        A = np.ascontiguousarray(A, np.float64)
        self.A, self.alpha, self.beta, self.relax = A, float(alpha), float(beta), relax
        U = A.shape[1]
        D = difference_matrix(U)
        self.Q = 2.0 * (A.T @ A + alpha * D.T @ D)
        self.decay = np.float32(1.0 - 0.5 * relax)
        self._factors: dict[int, _Factor] = {}
        # Q^{-1} norm for the certificate: r^T Q^{-1} r = ||r Lc^{-T}||^2.  An
        # unregularized problem (alpha = 0) with unlit offsets is only semidefinite.
        Lc = np.linalg.cholesky(self.Q + 1e-12 * np.trace(self.Q) / U * np.eye(U))
        Linv, info = sla.lapack.dtrtri(Lc, lower=1)
        if info != 0:  # pragma: no cover - Lc is a valid Cholesky factor
            raise np.linalg.LinAlgError(f"dtrtri failed ({info})")
        self.LinvT32 = _flush32(Linv.T)
        self.A32 = A.astype(np.float32)
        self._Linv = Linv
        self._AQ = None

    def factor(self, level: int) -> _Factor:
        if level not in self._factors:
            self._factors[level] = _Factor(self.A, self.Q, self.beta, _RHO_LADDER[level], self.relax)
        return self._factors[level]

    def _certificate_operators(self):
        """``A Q^{-1}`` and ``A Q^{-1} A^T`` (float64) for pixels with dropped rows."""
        if self._AQ is None:
            AL = self.A @ self._Linv.T  # A Lc^{-T}
            self._AQ = (AL @ self._Linv, AL @ AL.T)  # A Q^{-1}, A Q^{-1} A^T (one assignment: threads)
        return self._AQ

    def certify(self, Z, B, Lam, mask=None, drop=None, cert_L=None, rows=None):
        """Objective, certified gap bound and KKT residual of feasible ``Z`` (float64).

        With ``mask`` the dropped observations count neither in the objective nor
        in the gradient, and the bound uses ``Q_p^{-1}`` of the pixel's own Hessian
        (Woodbury on the shared ``Q^{-1}``).
        """
        al, be = self.alpha, self.beta
        R = Z @ self.A.T - B  # float64: A z - b cancels
        if mask is not None:
            R *= mask
        dZ = np.diff(Z, axis=1)
        f = np.einsum("ij,ij->i", R, R) + al * np.einsum("ij,ij->i", dZ, dZ) + be * Z.sum(axis=1)
        G = 2.0 * (R.astype(np.float32) @ self.A32)  # gradient of f at Z
        dZ32 = (2.0 * al) * dZ.astype(np.float32)
        G[:, :-1] -= dZ32
        G[:, 1:] += dZ32
        G += np.float32(be)
        kkt = np.abs(np.minimum(Z, G)).max(axis=1)
        GL = G - Lam
        W = GL @ self.LinvT32
        quad = np.einsum("ij,ij->i", W, W).astype(np.float64)
        if drop is not None and drop.any:
            extra = np.empty(Z.shape[0])
            _kernels.woodbury_quad(GL.astype(np.float64), self._AQ[0], rows, drop.sel, drop.k, cert_L, extra)
            quad += extra
        gap = 0.5 * quad + np.einsum("ij,ij->i", Lam, Z)
        return f, gap, kkt

    def _iterate(self, V, C, fac: _Factor, n: int, state, drop, rrho, rows=None):
        """``n`` ADMM iterations in place; returns V before the last one (for residuals).

        ``rows``: the batch's pixels in ``drop`` (default: all, in order).
        """
        absV, T = np.empty_like(V), np.empty_like(V)
        prev = V
        if drop is not None and drop.any:
            sel, k, L = drop.sel, drop.k, drop.factors[fac.rho]
            rows = np.arange(V.shape[0]) if rows is None else rows
        else:
            sel, k, L, rows = _NO_SEL, _NO_K, _NO_L, np.zeros(V.shape[0], np.int64)
        for i in range(n):
            if i == n - 1:
                prev = V.copy()
            np.abs(V, out=absV)
            np.matmul(absV, fac.Mp, out=T)
            _kernels.admm_step(V, T, C, self.decay, rrho, fac.AM32, rows, sel, k, L, *state.arrays(), state.anderson)
        return prev

    def solve(self, B, tol=DEFAULT_TOL, max_iter=_MAX_ITER, mask=None, anderson=False, start=None):
        """ADMM for a batch of pixels ``B`` (P, N); returns X and per-pixel diagnostics.

        Every ``_CHECK_EVERY`` iterations each pixel's gap is certified (converged
        pixels leave the batch) and its rho is re-balanced: when the primal residual
        (change of the scaled dual) dominates the dual one (change of ``z``), rho
        moves up the ladder, else down; the scaled dual is rescaled accordingly and
        the Anderson memory restarts.

        ``mask`` (P, N) bool marks the observations to use (False: saturated,
        dropped): such pixels run in the same batch with their own x-update by a
        Woodbury correction of the shared factorization.  A pixel with no usable
        observation returns 0, not converged.

        ``start = (V, level)`` warm-starts each pixel from another pixel's final ADMM
        state and rho level (e.g. its neighbour in the row above).  Returns
        ``X, iterations, converged, relative gap bound, kkt, V, level``.
        """
        B = np.ascontiguousarray(B, np.float64)
        P, U = B.shape[0], self.A.shape[1]
        X = np.zeros((P, U))
        iters = np.zeros(P, np.int32)
        gap = np.full(P, np.inf)
        fval = np.zeros(P)
        kkt = np.zeros(P)
        idx = np.arange(P)
        drop = None
        Mk = None
        if mask is not None:
            mask = np.asarray(mask, bool)
            usable = mask.any(axis=1)
            if mask.all():
                mask = None
            else:
                B = np.where(mask, B, 0.0)
                idx = np.flatnonzero(usable)
                drop = _Dropped(mask[idx], self.A, self.beta, self.relax)
                Mk = mask[idx].astype(np.float64)
        Bi = B[idx]
        if start is None:
            level = np.full(idx.size, _RHO_START)
            V = np.zeros((idx.size, U), np.float32)
        else:
            V, level = np.array(start[0][idx], np.float32), np.array(start[1][idx], np.int64)
        V_out = np.zeros((P, U), np.float32)
        level_out = np.full(P, _RHO_START)
        state = _AndersonState(idx.size, U, anderson)
        cert_L = None
        fallback = np.zeros(0, np.int64)
        if drop is not None:
            _, K0 = self._certificate_operators()
            cert_ok = drop.factor(-1.0, K0)  # rho = -1: the certificate's I/2 - A_s Q^{-1} A_s^T
            cert_L = drop.factors.pop(-1.0)
            fac = self.factor(_RHO_START)
            bad = ~(cert_ok & drop.factor(fac.rho, fac.K))
            if bad.any():  # numerically hopeless Woodbury: solve those pixels on their own
                fallback = idx[bad]
                keep = ~bad
                idx, Bi, level, V, Mk, cert_L = idx[keep], Bi[keep], level[keep], V[keep], Mk[keep], cert_L[keep]
                drop = drop.take(keep)
                state = _AndersonState(idx.size, U, anderson)
        drow = np.arange(idx.size)  # each running pixel's row in drop (drop itself is never compacted)
        C = np.empty((idx.size, U), np.float32)
        for lv in np.unique(level):
            m = np.flatnonzero(level == lv)
            fac = self.factor(lv)
            if drop is not None:  # pragma: no branch - a failing S_p was sent to the fallback at _RHO_START
                ok = drop.factor(fac.rho, fac.K)[m]
                level[m[~ok]] = _RHO_START
                m = m[ok]
            C[m] = fac.constant(Bi[m], drop, m)
        if start is not None and (level != start[1][idx]).any():  # pragma: no cover - see above
            return self.solve(B, tol, max_iter, mask, anderson)
        k, n = 0, _FIRST_CHECK
        # Each pixel is certified when due: at _FIRST_CHECK, then every _CHECK_EVERY
        # iterations (a warm-started pixel would join a batch in step with it).
        due_at = np.full(idx.size, _FIRST_CHECK)
        moves = np.zeros(idx.size, np.int64)  # rho moves so far: a pixel may cycle between two levels
        while idx.size:
            levels = np.unique(level)
            rho = np.asarray(_RHO_LADDER, np.float32)[level]
            rrho = (self.relax * rho).astype(np.float32)
            if levels.size == 1:  # the common case: no gather/scatter
                prev = self._iterate(V, C, self.factor(levels[0]), n, state, drop, rrho, drow)
            else:
                prev = np.empty_like(V)
                for lv in levels:
                    sel = np.flatnonzero(level == lv)
                    Vs, sub = V[sel], state.take(sel)
                    fac = self.factor(lv)
                    prev[sel] = self._iterate(Vs, C[sel], fac, n, sub, drop, rrho[sel], drow[sel])
                    V[sel] = Vs
                    state.put(sel, sub)
            k += n
            due = np.flatnonzero(due_at <= k)
            done = np.zeros(idx.size, bool)
            if due.size:
                Vd = V[due]
                Z = np.maximum(Vd, 0).astype(np.float64)
                Lam = np.minimum(Vd, 0) * -rho[due, None]  # ADMM multiplier of z >= 0
                if drop is None:
                    f, g, kk = self.certify(Z, Bi[due], Lam)
                else:
                    f, g, kk = self.certify(Z, Bi[due], Lam, Mk[due], drop, cert_L, drow[due])
                done_d = (g <= tol * np.maximum(f - g, 0.0)) | (k >= max_iter)
                done[due] = done_d
                due_at[due] = np.minimum(k + _CHECK_EVERY, max_iter)
                # residual balancing (Boyd et al. 2011, Sec. 3.4.1) on the ladder
                dz = np.linalg.norm(np.maximum(Vd, 0) - np.maximum(prev[due], 0), axis=1)
                dw = np.linalg.norm(np.minimum(Vd, 0) - np.minimum(prev[due], 0), axis=1)
                # Only pixels still running after _BALANCE_AFTER iterations move: most
                # converge before, and each new rho costs a factorization.
                late = k >= _BALANCE_AFTER
                up = np.zeros(idx.size, bool)
                down = np.zeros(idx.size, bool)
                free = late & ~done_d & (moves[due] < _MAX_MOVES)
                up[due] = free & (dw > 3.0 * dz) & (level[due] < len(_RHO_LADDER) - 1)
                down[due] = free & (dz > 3.0 * dw) & (level[due] > 0)
                if up.any() or down.any():
                    new_level = level + up - down
                    moved = np.flatnonzero(new_level != level)
                    ratio = (rho[moved] / np.asarray(_RHO_LADDER, np.float32)[new_level[moved]])[:, None]
                    V[moved] = np.maximum(V[moved], 0) + np.minimum(V[moved], 0) * ratio
                    level = new_level
                    moves[moved] += 1
                    state.restart(moved)
                    for lv in np.unique(level[moved]):
                        m = moved[level[moved] == lv]
                        fac = self.factor(lv)
                        if drop is not None:
                            ok = drop.factor(fac.rho, fac.K)[drow[m]]
                            if not ok.all():  # pragma: no cover - S_p is PD in exact arithmetic: stay put
                                stay = m[~ok]
                                level[stay] = lv - up[stay] + down[stay]
                                V[stay] = np.maximum(V[stay], 0) + np.minimum(V[stay], 0) / ratio[np.isin(moved, stay)]
                                m = m[ok]
                        C[m] = fac.constant(Bi[m], drop, None if drop is None else drow[m])
                if done.any():
                    dd = due[done_d]
                    d = idx[dd]
                    X[d], iters[d], gap[d], fval[d], kkt[d] = Z[done_d], k, g[done_d], f[done_d], kk[done_d]
                    V_out[d], level_out[d] = V[dd], level[dd]
                    keep = ~done
                    idx, V, C, level, Bi = idx[keep], V[keep], C[keep], level[keep], Bi[keep]
                    due_at, moves = due_at[keep], moves[keep]
                    state = state.take(np.flatnonzero(keep))
                    if drop is not None:
                        drow, Mk = drow[keep], Mk[keep]
            n = max(1, int(due_at.min()) - k) if idx.size else 0
        rel_gap = gap / np.maximum(fval - gap, 1e-300)
        for p in fallback:  # one pixel at a time on its own rows (rare)
            keep = mask[p]
            sub = AdmmRowSolver(self.A[keep], self.alpha, self.beta, self.relax)
            res = sub.solve(B[p : p + 1, keep], tol, max_iter, anderson=anderson)
            X[p], iters[p], rel_gap[p], kkt[p] = res[0][0], res[1][0], res[3][0], res[4][0]
        return X, iters, rel_gap <= tol, rel_gap, kkt, V_out, level_out


_NO_SEL = np.zeros((1, 1), np.int64)
_NO_L = np.zeros((1, 1, 1))
_NO_K = np.zeros(1, np.int64)


class _AndersonState:
    """Per-pixel Anderson memory (see :func:`planeray.demux._kernels.admm_step`)."""

    def __init__(self, P, U, anderson=True):
        self.anderson = bool(anderson)
        m = _AA_MEMORY if anderson else 1
        Ua = U if anderson else 1
        self.Fp = np.zeros((P, Ua), np.float32)
        self.Gp = np.zeros((P, Ua), np.float32)
        self.dF = np.zeros((P, m, Ua), np.float32)
        self.dG = np.zeros((P, m, Ua), np.float32)
        self.gram = np.zeros((P, m, m))
        self.cnt = np.zeros(P, np.int64)
        self.head = np.zeros(P, np.int64)
        self.rn_prev = np.full(P, -1.0)

    _NAMES = ("Fp", "Gp", "dF", "dG", "gram", "cnt", "head", "rn_prev")

    def arrays(self):
        return tuple(getattr(self, n) for n in self._NAMES)

    def take(self, sel):
        out = object.__new__(_AndersonState)
        out.anderson = self.anderson
        for n in self._NAMES:
            setattr(out, n, np.ascontiguousarray(getattr(self, n)[sel]))
        return out

    def put(self, sel, sub):
        for n in self._NAMES:
            getattr(self, n)[sel] = getattr(sub, n)

    def restart(self, sel):
        """Forget the memory of pixels whose fixed-point map changed (new rho)."""
        self.cnt[sel] = 0
        self.head[sel] = 0
        self.rn_prev[sel] = -1.0


def _threads() -> int:
    """Two threads on a workstation; one inside a Dask worker (the cluster parallelizes)."""
    distributed = sys.modules.get("distributed")  # never import it just to ask
    if distributed is not None:
        try:
            distributed.get_worker()
            return 1
        except ValueError:
            pass
    return max(1, min(2, os.cpu_count() or 1))


_CONTROLLER = None
_POOLS: dict[int, ThreadPoolExecutor] = {}


def _pool(threads: int) -> ThreadPoolExecutor:
    """A process-wide pool of solver threads (starting threads per batch costs ms under load)."""
    if threads not in _POOLS:
        _POOLS[threads] = ThreadPoolExecutor(threads, thread_name_prefix="planeray-demux")
    return _POOLS[threads]


def _blas_one_thread(threads: int):
    """Hold BLAS to one thread (our own threads parallelize); the library scan is done once."""
    global _CONTROLLER
    del threads  # one BLAS thread even alone: a threaded sgemm of this size only spins (~10x slower under load)
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        return contextlib.nullcontext()
    if _CONTROLLER is None:
        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER.limit(limits=1, user_api="blas")


def _row_solver(group: RowGroup, alpha: float, beta: float) -> AdmmRowSolver:
    """The factorization of a row group, cached on the group (chunks reuse it)."""
    key = (alpha, beta)
    cache = group.__dict__.setdefault("_admm_cache", {})
    if key not in cache:
        cache.clear()
        cache[key] = AdmmRowSolver(group.A, alpha, beta)
    return cache[key]


def _warm_schedule(n_rows: int) -> list[tuple[np.ndarray, int]]:
    """Rows of a block solved in phases: ``(rows, distance)`` -- each row starts from the row ``distance`` above.

    Phase 0 solves every 4th row cold (distance 0), phase 1 the rows half-way between
    them from the row 2 above, phase 2 the odd rows from the row just above: 3/4 of
    the rows start from a neighbour while every phase stays a large batch.
    """
    rows = np.arange(n_rows)
    return [(rows[rows % 4 == 0], 0), (rows[rows % 4 == 2], 2), (rows[rows % 2 == 1], 1)]


def solve_fast(
    group: RowGroup, B, alpha=0.01, beta=0.01, tol=None, *, mask=None, anderson=False, image_width=None
) -> SolveResult:
    """Solve every pixel of ``B`` (P, N) sharing ``group``'s illumination matrix.

    Parameters
    ----------
    group : RowGroup
    B : ndarray (P, N)
        Observations.
    alpha, beta : float
    tol : float, optional
        Certified relative objective gap at which a pixel stops (default 1e-4).
    mask : ndarray (P, N) bool, optional
        Observations to use (False: dropped, e.g. saturated).  Such pixels stay in the
        batch (Woodbury-corrected x-update); a pixel with none is 0 and not converged.
    anderson : bool
        Anderson-accelerate the ADMM iteration (fewer iterations, each dearer; off by
        default: see the README's measurements).
    image_width : int, optional
        The pixels are whole image rows of this width (row-major): warm-start 3/4 of
        the rows from the final ADMM state and rho of the pixel above
        (:func:`_warm_schedule`).  Only the start changes: every pixel still stops on
        its own certificate.

    Returns
    -------
    SolveResult
        ``converged`` is True where the certificate proved the gap ``<= tol``.
    """
    tol = DEFAULT_TOL if tol is None else float(tol)
    B = np.asarray(B, np.float64)
    P = B.shape[0]
    U = group.A.shape[1]
    if mask is not None:
        mask = np.asarray(mask, bool)
        if mask.shape != B.shape:
            raise ValueError(f"mask shape {mask.shape} != observations {B.shape}")
    if image_width is not None and (image_width < 1 or P % image_width):
        raise ValueError(f"{P} pixels are not whole rows of {image_width}")
    X = np.zeros((P, U))
    iters = np.zeros(P, np.int32)
    conv = np.zeros(P, bool)
    if P == 0:
        return SolveResult(X, iters, conv)
    threads = _threads()
    with _blas_one_thread(threads):
        solver = _row_solver(group, alpha, beta)
        if image_width is None or P == image_width:
            phases = [(np.arange(P), None)]
        else:
            grid = np.arange(P).reshape(-1, image_width)
            phases = [(grid[r].ravel(), grid[r - d].ravel() if d else None) for r, d in _warm_schedule(grid.shape[0])]
        V = np.zeros((P, U), np.float32)
        level = np.full(P, _RHO_START)
        for pix, src in phases:
            start = None if src is None else (V[src], level[src])
            n = max(1, min(threads, pix.size // 64), -(-pix.size // _CHUNK))
            bounds = np.linspace(0, pix.size, n + 1).astype(int)
            slices = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]

            def run(s, pix=pix, start=start):
                st = None if start is None else (start[0][s], start[1][s])
                m = None if mask is None else mask[pix[s]]
                return solver.solve(B[pix[s]], tol, mask=m, anderson=anderson, start=st)

            if threads > 1 and len(slices) > 1:
                parts = list(_pool(threads).map(run, slices))
            else:
                parts = [run(s) for s in slices]
            for s, part in zip(slices, parts):
                q = pix[s]
                X[q], iters[q], conv[q], V[q], level[q] = part[0], part[1], part[2], part[5], part[6]
    return SolveResult(X, iters, conv)
