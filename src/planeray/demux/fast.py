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
*shared*: one float64 Cholesky per distinct illumination matrix and penalty, then
every iteration for all pixels of a batch is a single float32 matrix product and
one fused per-pixel pass (:mod:`planeray.demux._kernels`).  With over-relaxation
``r`` and the scaled dual ``w`` the iteration collapses onto one vector per pixel,
``v = x_relaxed + w`` (``z = max(v, 0)``, ``w = min(v, 0)``)::

    v <- (1 - r/2) v + |v| (r rho M - r/2 I) + r c M,       M = (Q + rho I)^{-1}

Convergence is *certified*, not assumed: for any ``lam >= 0`` weak duality gives
``f(z) - f* <= 1/2 (g - lam)^T Q^{-1} (g - lam) + lam^T z`` with ``g`` the gradient
at ``z``; with ``lam`` the ADMM multiplier ``-rho min(v, 0)`` this bound is within
~1.5x of the true gap.  A pixel stops when the bound proves a relative objective
gap ``<= tol`` and leaves the batch, so the cost follows the mean iteration count,
not the maximum.  Each pixel's ``rho`` moves along a ladder by residual balancing
(Boyd et al. 2011, Sec. 3.4.1): the best ``rho`` depends on the data (~1 with
ambient light, ~5 without).

**The few pixels left at the iteration cap** without a proof (a float32 iterate at its
precision floor when the objective is tiny, slow convergence at extreme weights) are finished
exactly in float64: an active-set solve warm-started from ADMM's split, accepted only where the
same certificate, in float64, proves the gap (:mod:`planeray.demux._finish`).  Every other pixel
is untouched (the paper's problem gives the same bytes as before).

**Saturated observations** stay in the batch.  A pixel that drops the rows ``s``
has the Hessian ``Q - 2 A_s^T A_s``; its operator is the shared ``M`` plus a rank-k
Woodbury term ``(A_s M)^T S^{-1} (A_s M)``, ``S = I/2 - A_s M A_s^T`` (a k x k
Cholesky per pixel and rho, ``2 k U`` flops per iteration), and its certificate
uses its own ``Q_p^{-1}`` the same way.

**The ambient term** (Eq. 6a, ``ambient=``) adds one unknown per pixel with its own
column; where the bands lie inside the projector that column equals ``A 1``, so ``Q``
is singular along ``(1, ..., 1, -1)`` (a flat transport traded for ambient).  ADMM
needs only ``Q + rho I``; the certificate uses the pseudo-inverse on that direction's
complement and first moves the multiplier along it (:class:`AdmmRowSolver`), where that costs
least (:func:`planeray.demux._kernels.null_adjust`).

Practicalities measured on a 2-core machine: batches of 512 pixels run on two
Python threads (the products in BLAS held to one thread, the per-pixel passes
compiled without the GIL); float32 entries below 1e-30 are flushed to zero
(denormals make sgemm ~10x slower); only NumPy's matmul is used in the loop (SciPy
ships its own BLAS with its own spinning thread pool).

References
----------
.. [1] S. Boyd, N. Parikh, E. Chu, B. Peleato, J. Eckstein, "Distributed
   optimization and statistical learning via the alternating direction method of
   multipliers", Found. Trends Mach. Learn. 3(1), 2011 (over-relaxation, Sec. 3.4.3).
.. [2] B. Stellato et al., "OSQP: an operator splitting solver for quadratic
   programs", Math. Prog. Comp. 12, 2020.
.. [3] W. W. Hager, "Updating the inverse of a matrix", SIAM Review 31(2), 1989.
"""

from __future__ import annotations

import contextlib
import hashlib
import sys
import threading
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba
import numpy as np
import scipy.linalg as sla

from . import _kernels as K
from ._finish import finish_pixels
from .problem import RowGroup, difference_matrix, pixel_terms
from .result import SolveResult

__all__ = ["solve_fast", "AdmmRowSolver", "WarmStart", "DEFAULT_TOL"]

#: Certified relative objective gap at which a pixel stops.
DEFAULT_TOL = 1e-4
_RELAX = 1.8
#: Pixels per batch (one task of a worker thread).
_CHUNK = 512
_FIRST_CHECK = 30
_CHECK_EVERY = 10
_MAX_ITER = 2000

#: Penalty ladder: each pixel's rho is moved along it by residual balancing
#: (a factor 2 per step; the best rho depends on the data, e.g. ~1 with ambient
#: light and 4-8 without, a 3-5x difference in iterations).
_RHO_LADDER = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)
_RHO_START = 2  # index of 1.0 in the ladder


def _ambient_start(beta: float) -> int:
    """Start of the rho ladder with the ambient term: ``rho ~ 8 (beta / 1e-3)^(1/3)``.

    Along the null direction ``(1, ..., 1, -sqrt(U))`` only the sparsity term pulls, and
    the multipliers that stop it sum to ``beta (U - 1)``: the larger ``beta``, the larger
    the best ``rho`` (mean iterations over 8-10 pairs of the search's grid on wax, skin,
    the mirror ball and the corner: 1.4x fewer than a start at 1; see the demultiplexing
    guide).
    """
    rho = 8.0 * (max(beta, 1e-12) / 1e-3) ** (1.0 / 3.0)
    return int(np.clip(np.round(np.log2(rho / _RHO_LADDER[0])), 0, len(_RHO_LADDER) - 1))


#: A warm-started pixel's first certificate comes after this many iterations, and the next ones
#: every :data:`WARM_CHECK_EVERY` (it starts near its optimum: a live transport's pixels after one
#: new image of the window).
WARM_FIRST_CHECK = 6
WARM_CHECK_EVERY = 8
_BALANCE_AFTER = 30
#: A pixel's rho moves at most this often (balancing can otherwise cycle).
_MAX_MOVES = 6
#: An ambient column within this (relative) of ``A 1`` is taken as ``A 1`` (bands inside the projector).
_COLLINEAR = 1e-6


def _flush32(M) -> np.ndarray:
    """float32 copy with would-be denormals set to zero (they make sgemm ~10x slower)."""
    M = np.array(M, np.float64)
    M[np.abs(M) < 1e-30] = 0.0
    return np.ascontiguousarray(M.astype(np.float32))


def _lower_inverse(S) -> np.ndarray:
    """``L^{-1}`` of the Cholesky factor ``S = L L^T`` (LAPACK potrf + trtri)."""
    L = np.linalg.cholesky(S)
    # dtrtri reads and writes the lower triangle only: the upper one stays the zeros cholesky left there
    Li, info = sla.lapack.dtrtri(L, lower=1, overwrite_c=1)
    if info != 0:  # pragma: no cover - L is a valid Cholesky factor
        raise np.linalg.LinAlgError(f"dtrtri failed ({info})")
    return Li


class _Factor:
    """ADMM operator for one rho: ``v <- decay v + |v| Mp + c M r``."""

    def __init__(self, A, Q, beta, rho, relax, n_x=None):
        U = Q.shape[0]
        Li = _lower_inverse(Q + rho * np.eye(U))
        Minv = Li.T @ Li
        self.rho = rho
        self.Mp = _flush32(relax * rho * Minv - 0.5 * relax * np.eye(U))
        self.AM = A @ Minv  # (N, U): rows of the Woodbury terms
        self.G1 = (2.0 * relax) * self.AM  # r c M = b G1 + g0 with c = 2 A^T b - beta (1, 0)
        self.g0 = -beta * relax * Minv[: U if n_x is None else n_x].sum(axis=0)
        self.K = self.AM @ A.T  # A M A^T (N, N): Woodbury blocks of pixels with dropped observations


@dataclass
class WarmStart:
    """The ADMM state of a batch of pixels: a previous solve's end, the next solve's start.

    ``V`` (P, U) float32 is each pixel's ADMM vector ``v`` (its iterate ``z = max(v, 0)`` and scaled
    multiplier ``min(v, 0)``) and ``level`` (P,) its penalty's place on the ladder.  A pixel's state
    depends only on its own data and start, so a solve warm-started from it gives the same answer to
    the certified accuracy as a cold one (``tests/test_live_transport.py``).
    """

    V: np.ndarray
    level: np.ndarray

    @classmethod
    def empty(cls, n_pixels: int, n_unknowns: int) -> WarmStart:
        return cls(np.zeros((n_pixels, n_unknowns), np.float32), np.zeros(n_pixels, np.int64))

    def __getitem__(self, rows) -> WarmStart:
        return WarmStart(self.V[rows], self.level[rows])


class AdmmRowSolver:
    """Everything that depends only on the illumination matrix ``A`` (one per row group).

    With ``ambient`` (the column ``I_w`` (N,) of Eq. 6a) the unknowns are ``(T, a')``:
    ``U + 1`` columns, the last one the ambient, solved scaled as ``a' = sqrt(U) a``
    (column ``I_w / sqrt(U)``; no smoothness, no sparsity).  Where the bands lie inside
    the projector ``A 1 = I_w`` up to the jitter's tails beyond the support (~2e-8
    relative); there the column is taken as ``A 1`` exactly, so that ``n = (1, ..., 1,
    -sqrt(U))`` is an exact null direction of ``Q``: the certificate then uses the
    pseudo-inverse on ``n``'s complement and moves the multiplier along ``n``
    (:func:`planeray.demux._kernels.null_adjust`), which keeps the weak-duality bound
    finite where ``Q^{-1}`` does not exist.
    """

    def __init__(self, A, alpha, beta, relax=_RELAX, *, ambient=None):
        A = np.ascontiguousarray(A, np.float64)
        self.n_x = A.shape[1]  # unknowns of T; with the ambient one more column
        self.null = None  # the exact null direction of Q (ambient, bands inside the projector)
        self.null_basis = None  # an orthonormal basis of its complement (U, U - 1)
        if ambient is not None:
            e = np.asarray(ambient, np.float64).ravel()
            if e.shape != (A.shape[0],):
                raise ValueError(f"ambient column of {e.size} values for {A.shape[0]} images")
            flat = A.sum(axis=1)
            collinear = self.n_x > 0 and np.abs(flat - e).max(initial=0.0) <= _COLLINEAR * max(
                e.max(initial=0.0), 1e-300
            )
            if collinear:
                e = flat
            A = np.ascontiguousarray(np.column_stack([A, e / np.sqrt(max(self.n_x, 1))]))
        self.ambient = ambient is not None
        # the ambient unknown is solved as a' = sqrt(U) a (column I_w / sqrt(U)): the null direction
        # (1, ..., 1, -sqrt(U)) then has half its length on a', and ADMM needs 2-3x fewer iterations at small beta
        self.ambient_scale = float(np.sqrt(max(self.n_x, 1))) if self.ambient else 1.0
        self.A, self.alpha, self.beta, self.relax = A, float(alpha), float(beta), relax
        U = A.shape[1]
        D = difference_matrix(self.n_x)
        if self.ambient:
            D = np.pad(D, ((0, 0), (0, 1)))
        self.Q = 2.0 * (A.T @ A + alpha * D.T @ D)
        # beta per unknown, the linear term's sparsity part (0 for the ambient)
        self.beta_u = np.full(U, self.beta)
        self.beta_u[self.n_x :] = 0.0
        self.decay = np.float32(1.0 - 0.5 * relax)
        self._factors: dict[int, _Factor] = {}
        # A M of every rho on the ladder (filled as they are factored) and r rho: the
        # Woodbury terms of a batch's masked rows in one call, whatever their rho
        self._AMs = np.zeros((len(_RHO_LADDER), A.shape[0], A.shape[1]), np.float32)
        self._scales = relax * np.asarray(_RHO_LADDER, np.float32)
        self._lock = threading.Lock()
        # Q^{-1} norm for the certificate: h^T Q^{-1} h = ||h Lc^{-T}||^2.  An
        # unregularized problem (alpha = 0) with unlit offsets is only semidefinite.
        if self.ambient and collinear:
            # Q n = 0 for n ~ (1, ..., 1, -sqrt(U)) (A 1 = I_w): Q^+ = Bn (Bn^T Q Bn)^{-1} Bn^T with Bn
            # an orthonormal basis of n's complement (a Householder reflection's other columns)
            n = np.ones(U)
            n[-1] = -self.ambient_scale
            n /= np.linalg.norm(n)
            w = n.copy()
            w[-1] -= 1.0  # H = I - 2 w w^T / w^T w maps n to the last unit vector
            H = np.eye(U) - 2.0 * np.outer(w, w) / (w @ w)
            Bn = H[:, :-1]
            Qr = Bn.T @ self.Q @ Bn
            Lr = _lower_inverse(Qr + 1e-12 * np.trace(Qr) / max(U - 1, 1) * np.eye(U - 1))
            Linv = Lr @ Bn.T  # (U - 1, U): h^T Q^+ h = ||Linv h||^2
            self.null = n
            self.null_basis = Bn
        else:
            Linv = _lower_inverse(self.Q + 1e-12 * np.trace(self.Q) / max(U, 1) * np.eye(U))
        self.LinvT32 = _flush32(Linv.T)
        self.A32 = A.astype(np.float32)
        self.AT = np.ascontiguousarray(A.T)
        self._Linv = Linv
        self._AQ = None

    @property
    def start_level(self) -> int:
        """The penalty's place on the ladder where a cold (or primal-started) pixel begins."""
        return _ambient_start(self.beta) if self.ambient else _RHO_START

    @property
    def ambient_column(self) -> np.ndarray | None:
        """The ambient column the solver uses (``A 1`` where collinear; unscaled), or None."""
        return self.A[:, -1] * self.ambient_scale if self.ambient else None

    def factor(self, level: int) -> _Factor:
        fac = self._factors.get(level)
        if fac is None:
            with self._lock:
                fac = self._factors.get(level)
                if fac is None:
                    fac = _Factor(self.A, self.Q, self.beta, _RHO_LADDER[level], self.relax, self.n_x)
                    self._AMs[level] = _flush32(fac.AM)
                    self._factors[level] = fac
        return fac

    def certificate_woodbury(self):
        """``A Q^{-1}`` and ``A Q^{-1} A^T`` (for the certificate of pixels with dropped observations)."""
        with self._lock:
            if self._AQ is None:
                ALt = self.A @ self._Linv.T
                self._AQ = (ALt @ self._Linv, ALt @ ALt.T)
        return self._AQ

    # ------------------------------------------------------------------ solve
    def solve(self, B, tol=DEFAULT_TOL, max_iter=None, *, mask=None, start=None, state=None):
        """ADMM for a batch of pixels ``B`` (P, N).

        Parameters
        ----------
        B : ndarray (P, N)
        tol : float
            Certified relative objective gap at which a pixel stops.
        max_iter : int, optional
            Iteration cap (default ``_MAX_ITER``, 2000); pixels left there are finished exactly.
        mask : ndarray (P, N) bool, optional
            Observations to use (False: dropped, e.g. saturated).  A pixel without any
            is returned as 0, not converged, with 0 iterations.
        start : WarmStart or ndarray (P, U), optional
            Where each pixel starts.  A :class:`WarmStart` is a previous solve's ``state`` (e.g. of
            the same pixels a moment ago): its iterate, multiplier and penalty on the ladder.  An
            array is a start in the solver's variables (e.g. each pixel's solution at nearby
            weights), with the multipliers this problem's gradient gives on its zero entries.  The
            first certificate then comes after :data:`WARM_FIRST_CHECK` iterations, not 30; the
            result is certified all the same.
        state : WarmStart, optional
            Filled with each pixel's final state (a warm start for the next solve).

        Returns
        -------
        X, iterations, converged, relative gap bound, objective, unscaled KKT residual (in the
        solver's variables), residual sum of squares (over the observations used) -- of the
        returned ``X``
        (``(P, U + 1)`` with the ambient: its last column is ``a' = sqrt(U) a``, the solver's
        scaled ambient; :func:`solve_fast` returns ``a``).
        """
        max_iter = _MAX_ITER if max_iter is None else int(max_iter)
        B = np.ascontiguousarray(B, np.float64)
        P, N = B.shape
        U = self.A.shape[1]
        X = np.zeros((P, U))
        iters = np.zeros(P, np.int32)
        gap = np.full(P, np.inf)
        fval = np.zeros(P)
        kkt = np.zeros(P)
        rss = np.zeros(P)
        run = np.ones(P, bool)
        wb = None
        if mask is not None:
            mask = np.asarray(mask, bool)
            usable = mask.any(axis=1)
            run &= usable
            B = np.where(mask, B, 0.0)
            wb = _Dropped(mask, usable)
            if wb.n:
                KQ = self.certificate_woodbury()[1]
                ok = np.ones(wb.n, bool)
                K.woodbury_factors(KQ, wb.sel, wb.k, np.arange(wb.n), wb.L0, ok)
                if not ok.all():  # numerically singular: those pixels on their own rows (cold)
                    self._solve_apart(B, mask, wb.pix[~ok], tol, max_iter, X, iters, gap, fval, kkt, rss)
                    run[wb.pix[~ok]] = False
            else:
                wb = None
        if U == 0 or not run.any():
            done = run if U == 0 else np.zeros(P, bool)
            gap[done] = 0.0
            return X, iters, done, np.where(done, 0.0, np.inf), fval, kkt, rss
        if start is not None and not isinstance(start, WarmStart):
            X0 = np.maximum(np.asarray(start, np.float64), 0.0)
            if X0.shape != (P, U):
                raise ValueError(f"start must be {(P, U)}, got {X0.shape}")
            lv = self.start_level
            keep = np.zeros((0, 0), bool) if mask is None else mask
            start = WarmStart(self._warm(X0, B, keep, _RHO_LADDER[lv]), np.full(P, lv, np.int64))
        self._admm(B, tol, max_iter, np.flatnonzero(run), wb, mask, X, iters, gap, fval, kkt, rss, start, state)
        capped = np.flatnonzero(run & (iters >= max_iter) & ~(gap <= tol * np.maximum(fval - gap, 0.0)))
        if capped.size:  # the few pixels left at the cap: finished exactly in float64 (certified or kept)
            finish_pixels(self, B, mask, capped, tol, X, gap, fval, kkt, rss)
        rel_gap = gap / np.maximum(fval - gap, 1e-300)
        conv = (rel_gap <= tol) & np.isfinite(gap)  # pixels without observations: gap inf
        return X, iters, conv, rel_gap, fval, kkt, rss

    def _solve_apart(self, B, mask, pix, tol, max_iter, X, iters, gap, fval, kkt, rss):
        for p in pix:
            keep = mask[p]
            e = self.ambient_column[keep] if self.ambient else None
            sub = AdmmRowSolver(self.A[keep, : self.n_x], self.alpha, self.beta, self.relax, ambient=e)
            x, it, _, rg, f, kk, rs = sub.solve(B[p : p + 1, keep], tol, max_iter)
            X[p], iters[p], fval[p], kkt[p], rss[p] = x[0], it[0], f[0], kk[0], rs[0]
            gap[p] = rg[0] * max(f[0], 1e-300) / (1.0 + rg[0])

    def _constants(self, Bb, level, masked, wb):
        """``r c M_p`` for the rows of a batch (float32), all at rho ``level``."""
        fac = self.factor(level)
        C = Bb @ fac.G1 + fac.g0
        if wb is not None and (masked >= 0).any():
            m = masked >= 0
            cvec = 2.0 * Bb[m] @ self.A - (self.beta_u if self.ambient else self.beta)
            C[m] += _woodbury(cvec, fac.AM, masked[m], wb, self.relax)
        C[np.abs(C) < 1e-30] = 0.0
        return C.astype(np.float32)

    def _warm(self, X0, Bb, keep, rho) -> np.ndarray:
        """ADMM's ``v = z + w`` at a warm start ``X0``: ``w = -lambda / rho``, ``lambda`` this problem's gradient on zeros."""
        R = X0 @ self.AT - Bb
        if keep.size:
            R = np.where(keep, R, 0.0)
        G = 2.0 * (R @ self.A) + self.beta_u
        if self.n_x > 1:
            d = 2.0 * self.alpha * np.diff(X0[:, : self.n_x], axis=1)
            G[:, : self.n_x - 1] -= d
            G[:, 1 : self.n_x] += d
        lam = np.where(X0 > 0, 0.0, np.maximum(G, 0.0))
        return (X0 - lam / rho).astype(np.float32)

    def _admm(self, Ball, tol, max_iter, idx, wb, mask, X, iters, gap, fval, kkt, rss, warm=None, out_state=None):
        ladder = np.asarray(_RHO_LADDER)
        U = self.A.shape[1]
        P = idx.size
        Bb = Ball[idx]
        keep = np.zeros((0, 0), bool) if mask is None else np.ascontiguousarray(mask[idx])
        masked = np.full(P, -1) if wb is None else wb.index[idx]
        start = self.start_level
        level = np.full(P, start) if warm is None else np.asarray(warm.level, np.int64)[idx].copy()
        if wb is not None or warm is not None:  # rows by level, masked pixels first within each level
            first = np.lexsort((masked < 0, level))
            idx, Bb, masked, level = idx[first], Bb[first], masked[first], level[first]
            if keep.size:
                keep = keep[first]
        moves = np.zeros(P, np.int32)
        if wb is not None:
            for lv in np.unique(level):
                m = masked[level == lv]
                wb.refactor(self.factor(int(lv)).K, m[m >= 0])
        if warm is not None:
            V = np.ascontiguousarray(np.asarray(warm.V, np.float32)[idx])
        else:
            V = np.zeros((P, U), np.float32)
        if self.ambient and warm is None:
            # start: every offset's multiplier at beta (the sparsity term's pull balanced) and the
            # ambient at its upper bound min_i b_i / I_w,i over the observations used (T >= 0), scaled
            V[:, : self.n_x] = -self.beta / _RHO_LADDER[start]
            e = self.ambient_column
            if e.min(initial=0.0) > 0:
                ratio = Bb / e
                if keep.size:
                    ratio = np.where(keep, ratio, np.inf)
                a0 = ratio.min(axis=1, initial=np.inf)
                V[:, -1] = np.where(np.isfinite(a0), np.maximum(a0, 0.0), 0.0) * self.ambient_scale
        absV = np.abs(V)
        T = np.empty_like(V)
        if warm is None:
            C = self._constants(Bb, start, masked, wb)
        else:
            C = np.empty((P, U), np.float32)
            for lv in np.unique(level):
                m = level == lv
                C[m] = self._constants(Bb[m], int(lv), masked[m], wb)
        dz2 = np.zeros(P)
        dw2 = np.zeros(P)
        k, n = 0, (_FIRST_CHECK if warm is None else WARM_FIRST_CHECK)
        AQ = None if wb is None else self.certificate_woodbury()[0]
        while P:
            # rows are sorted by level: one product per level, on views
            levels, starts = np.unique(level, return_index=True)
            bounds = list(zip(levels, starts, list(starts[1:]) + [P]))
            for i in range(n):
                for lv, a, b in bounds:
                    fac = self.factor(int(lv))
                    np.matmul(absV[a:b], fac.Mp, out=T[a:b])
                if wb is not None:
                    K.woodbury_apply(absV, self._AMs, level, masked, wb.sel, wb.k, wb.Sinv, self._scales, T)
                K.relaxed_step(V, T, C, self.decay, absV, i == n - 1, dz2, dw2)
            k += n
            # ---- certificate
            rho = ladder[level]
            Z = np.empty((P, U))
            Lam = np.empty((P, U), np.float32)
            K.split_dual(V, rho.astype(np.float32), Z, Lam)
            R = Z @ self.AT
            R32 = np.empty(R.shape, np.float32)
            rr = np.empty(P)
            K.finish_residual(R, Bb, keep, R32, rr)
            G = R32 @ self.A32
            f = np.empty(P)
            kk = np.empty(P)
            lamz = np.empty(P)
            K.finish_gradient(G, Z, Lam, self.alpha, self.beta, self.n_x, rr, f, kk, lamz)
            if self.null is not None:  # the multiplier moved along Q's null direction (bound finite)
                K.null_adjust(G, Z, Lam, self.null, lamz)
            W = G @ self.LinvT32
            g = np.empty(P)
            K.half_norms(W, lamz, g)
            if wb is not None:
                K.woodbury_quad(G, AQ, masked, wb.sel, wb.k, wb.L0, g)
            done = (g <= tol * np.maximum(f - g, 0.0)) | (k >= max_iter)
            if done.any():
                d = idx[done]
                X[d], iters[d], gap[d], fval[d], kkt[d], rss[d] = Z[done], k, g[done], f[done], kk[done], rr[done]
                if out_state is not None:
                    out_state.V[d], out_state.level[d] = V[done], level[done]
            # ---- residual balancing on the ladder (only pixels still running late)
            dz, dw = np.sqrt(dz2), np.sqrt(dw2)
            free = (k >= _BALANCE_AFTER) & ~done & (moves < _MAX_MOVES)
            up = free & (dw > 3.0 * dz) & (level < len(_RHO_LADDER) - 1)
            down = free & (dz > 3.0 * dw) & (level > 0)
            moved = np.flatnonzero(up | down)
            if moved.size:
                new = level[moved] + up[moved] - down[moved]
                ratio = (rho[moved] / ladder[new]).astype(np.float32)[:, None]
                V[moved] = np.maximum(V[moved], 0) + np.minimum(V[moved], 0) * ratio
                absV[moved] = np.abs(V[moved])
                level[moved] = new
                moves[moved] += 1
                for lv in np.unique(new):
                    m = moved[new == lv]
                    if wb is not None and (masked[m] >= 0).any():
                        wb.refactor(self.factor(int(lv)).K, masked[m][masked[m] >= 0])
                    C[m] = self._constants(Bb[m], int(lv), masked[m], wb)
            if done.any() or moved.size:
                order = np.flatnonzero(~done)
                order = order[np.lexsort((masked[order] < 0, level[order]))]
                idx, Bb, masked, level, moves = idx[order], Bb[order], masked[order], level[order], moves[order]
                V, absV, C = V[order], absV[order], C[order]
                if keep.size:
                    keep = keep[order]
                P = idx.size
                T = np.empty_like(V)
                dz2, dw2 = dz2[:P], dw2[:P]
            n = _CHECK_EVERY if warm is None else WARM_CHECK_EVERY


def _woodbury(X, AM, masked, wb, scale) -> np.ndarray:
    """Rows ``scale (A_s M)^T S_p^{-1} (A_s M) x_p`` of masked pixels in float64 (two products)."""
    Y = X @ AM.T
    W = np.empty_like(Y)
    K.woodbury_coeffs(Y, masked, wb.sel, wb.k, wb.Sinv, float(scale), W)
    return W @ AM


class _Dropped:
    """Pixels of a batch with dropped observations: their rows and Woodbury factors."""

    def __init__(self, mask, usable):
        drop = ~mask & usable[:, None]
        self.pix = np.flatnonzero(drop.any(axis=1))
        self.n = self.pix.size
        self.index = np.full(mask.shape[0], -1)
        self.index[self.pix] = np.arange(self.n)
        self.k = drop[self.pix].sum(axis=1).astype(np.int64)
        kmax = int(self.k.max()) if self.n else 0
        # each pixel's dropped rows, in order, first (the rest of the row is unused)
        self.sel = np.ascontiguousarray(np.argsort(~drop[self.pix], axis=1, kind="stable")[:, : max(kmax, 1)])
        self.Sinv = np.zeros((self.n, max(kmax, 1), max(kmax, 1)))  # at each pixel's current rho
        self.L0 = np.zeros_like(self.Sinv)  # Cholesky factors for Q^{-1} (the certificate)

    def refactor(self, Kmat, which):
        ok = np.ones(self.n, bool)
        K.woodbury_inverses(Kmat, self.sel, self.k, np.asarray(which, np.int64), self.Sinv, ok)
        if not ok.all():  # pragma: no cover - S_p is a Schur complement of an SPD matrix
            raise np.linalg.LinAlgError("a Woodbury block lost positive definiteness")


def solver_threads() -> int:
    """Solver threads: Numba's thread count (the cores this process may use), at most two; one in a Dask worker.

    Numba's count is the one knob for planeray's parallel kernels (``NUMBA_NUM_THREADS`` or
    :func:`numba.set_num_threads`; the Monte Carlo engines use it too): a process given one core
    (a test worker among several, a job script) runs one solver thread instead of two threads on a
    core (measured with three pytest workers on two cores: the demultiplexing tests took 10 % less
    CPU with one).  At most two, as the pipeline was designed and measured (a 2-core machine).
    The cluster parallelizes a Dask worker's tasks.
    """
    distributed = sys.modules.get("distributed")  # never import it just to ask
    if distributed is not None:
        try:
            distributed.get_worker()
            return 1
        except ValueError:
            pass
    return max(1, min(2, numba.get_num_threads()))


_BLAS_LOCK = threading.Lock()
#: The one BLAS limit held while any solver runs in this process, and how many hold it.
_BLAS = {"held": 0, "limits": None}


@contextlib.contextmanager
def blas_one_thread():
    """Hold BLAS to one thread while the solver runs, on one Python thread or several.

    The batches' products then sum in one order whatever the threads: the same bytes with one
    solver thread or two (a multi-threaded BLAS splits a product, and its sums, by its threads).
    Held once for all holders (a driver's and each of its tasks', or calls from several
    threads): only the first sets the limit (threadpoolctl: ~1.5 ms, too much for every task)
    and only the last to leave restores it, so no caller restores it under another still solving.
    """
    with _BLAS_LOCK:
        if _BLAS["held"] == 0:
            try:
                from threadpoolctl import threadpool_limits
            except ImportError:  # pragma: no cover - threadpoolctl is a dependency
                pass
            else:
                _BLAS["limits"] = threadpool_limits(1, user_api="blas")
        _BLAS["held"] += 1
    try:
        yield
    finally:
        with _BLAS_LOCK:
            _BLAS["held"] -= 1
            if _BLAS["held"] == 0 and _BLAS["limits"] is not None:
                _BLAS["limits"].restore_original_limits()
                _BLAS["limits"] = None


_CACHE_LOCK = threading.Lock()
#: Memory (bytes) of the factorizations a process keeps for later row groups and calls with the same
#: illumination matrix and weights; the least recently used go first.  A solver of a 128-row paper
#: sweep holds about 2.3 MB once factored at the rhos it needed (41 of them for 128 rows of a
#: 720-row projector, 83 for 256).
SOLVER_CACHE_BYTES = 256 * 2**20
_SOLVERS: OrderedDict = OrderedDict()


def _solver_bytes(solver: AdmmRowSolver) -> int:
    """Bytes of the arrays a solver holds now (it grows as it is factored at more rhos)."""
    parts = [vars(solver), *(vars(f) for f in list(solver._factors.values()))]
    arrays = [v for part in parts for v in part.values() if isinstance(v, np.ndarray)]
    arrays += list(solver._AQ or ())
    return sum(a.nbytes for a in arrays)


def _solver_key(A, alpha, beta, ambient) -> tuple:
    """What an :class:`AdmmRowSolver` is a function of: ``A``'s bytes, the weights, the ambient column."""
    digest = hashlib.blake2b(np.ascontiguousarray(A, np.float64), digest_size=16)
    if ambient is not None:
        digest.update(b"ambient")
        digest.update(np.ascontiguousarray(ambient, np.float64))
    return (np.shape(A), float(alpha), float(beta), digest.hexdigest())


def row_solver(group: RowGroup, alpha: float, beta: float, ambient=None) -> AdmmRowSolver:
    """The factorization of a row group, cached on the group (chunks and threads reuse it).

    Row groups with the same illumination matrix and weights -- the interior rows of every
    stack of one sweep and geometry, in this and later calls of the process (the stacks of
    one experiment, one figure) -- share one solver: it is a function of those alone.
    """
    key = (alpha, beta) if ambient is None else (alpha, beta, np.asarray(ambient, np.float64).tobytes())
    with _CACHE_LOCK:
        cache = group.__dict__.setdefault("_admm_cache", {})
        if key in cache:
            return cache[key]
    # the key and a new factorization outside the lock: the other solver thread goes on with its own group
    # (at the image's top and bottom every row is a group of its own, each factored when first met)
    shared = _solver_key(group.A, alpha, beta, ambient)
    with _CACHE_LOCK:
        solver = _SOLVERS.get(shared)
        if solver is not None:
            _SOLVERS.move_to_end(shared)
    if solver is None:
        built = AdmmRowSolver(group.A, alpha, beta, ambient=ambient)
        with _CACHE_LOCK:
            solver = _SOLVERS.setdefault(shared, built)  # a thread that built the same one first wins
            if solver is built:
                held = sum(map(_solver_bytes, _SOLVERS.values()))
                while len(_SOLVERS) > 1 and held > SOLVER_CACHE_BYTES:
                    held -= _solver_bytes(_SOLVERS.popitem(last=False)[1])
    with _CACHE_LOCK:
        if key not in cache:
            cache.clear()
            cache[key] = solver
        return cache[key]


def solve_fast(
    group: RowGroup,
    B,
    alpha=0.01,
    beta=0.01,
    tol=None,
    *,
    mask=None,
    threads=None,
    ambient=None,
    start: WarmStart | None = None,
    state: WarmStart | None = None,
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
        Observations to use (False: dropped, e.g. saturated); solved in the same
        batches through a low-rank update.  A pixel without any is 0 and not converged.
    threads : int, optional
        Python threads for batches of 512 pixels (default: Numba's thread count, at most 2;
        1 inside a Dask worker).  The result does not depend on them.
    ambient : ndarray (N,), optional
        The ambient column ``I_w`` (exposure in projector rows) of Eq. 6a: each pixel
        then also has an ambient unknown, returned in ``SolveResult.ambient``.
    start : WarmStart, optional
        Each pixel's ADMM state to start from (``state`` of an earlier solve of the same pixels and
        group, e.g. a live transport's previous window): far fewer iterations when little changed.
    state : WarmStart, optional
        Filled with each pixel's final state (``WarmStart.empty(P, U)``; ``U`` the group's unknowns,
        one more with the ambient).

    Returns
    -------
    SolveResult
        ``converged`` is True where the certificate proved the gap ``<= tol``; ``gap`` is
        each pixel's certified relative gap.

    See Also
    --------
    solve_cvxpy : the reference solver of the same problem.
    get_solver : solvers by name.

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
    >>> from planeray.demux import solve_cvxpy
    >>> fast = solve_fast(setup.group, B[:1]).X
    >>> ref = solve_cvxpy(setup.group, B[:1]).X
    >>> bool(np.abs(setup.A @ (fast - ref)[0]).max() < 1e-3)  # the same images predicted
    True
    """
    tol = DEFAULT_TOL if tol is None else float(tol)
    B = np.asarray(B, np.float64)
    P = B.shape[0]
    threads = solver_threads() if threads is None else max(1, int(threads))
    slices = [slice(s, min(P, s + _CHUNK)) for s in range(0, P, _CHUNK)]
    with blas_one_thread():
        solver = row_solver(group, alpha, beta, ambient)

        def run(s):
            return solver.solve(
                B[s],
                tol,
                mask=None if mask is None else mask[s],
                start=None if start is None else start[s],
                state=None if state is None else state[s],
            )

        if threads > 1 and len(slices) > 1:
            with ThreadPoolExecutor(threads) as pool:
                parts = list(pool.map(run, slices))
        else:
            parts = [run(s) for s in slices]
    if not parts:
        return SolveResult(
            np.zeros((0, group.A.shape[1])),
            np.zeros(0, np.int32),
            np.zeros(0, bool),
            ambient=None if ambient is None else np.zeros(0),
            gap=np.zeros(0),
        )
    X, iters, conv, gap, f, kkt, rss = (np.concatenate([p[i] for p in parts]) for i in range(7))
    # the driver's maps, from the last certificate (float64 residual; gradient in float32)
    Bm = B if mask is None else np.where(mask, B, 0.0)
    if ambient is None:
        c = 2.0 * (Bm.astype(np.float32) @ solver.A32) - np.float32(beta)
        scaled = kkt / (1.0 + np.abs(c).max(axis=1, initial=0.0))
        return SolveResult(X, iters, conv, objective=f, residual_ss=rss, kkt_residual=scaled, gap=gap)
    # with the ambient the maps are those of Eq. 6a itself (the solver's a' is scaled), in float64
    n = solver.n_x
    a = X[:, n] / solver.ambient_scale
    e = np.asarray(ambient, np.float64)
    d = pixel_terms(group.A, X[:, :n], B, alpha, beta, mask=mask, exposure_rows=e, ambient=a)
    return SolveResult(X[:, :n], iters, conv, ambient=a, gap=gap, **d)
