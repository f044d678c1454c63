"""The exact float64 finish of pixels the fast solver's ADMM leaves at its iteration cap.

ADMM (:mod:`planeray.demux.fast`) iterates in float32 and stops a pixel when its
weak-duality certificate proves a relative objective gap ``<= tol``.  A pixel can reach the
iteration cap without that proof: its iterate stalls at float32's precision (a floor that
matters only when the pixel's objective is tiny, i.e. almost noise-free data), or
convergence is slow at extreme weights.  Such a pixel is finished here, alone, in float64:
a primal active-set method for the per-pixel QP

.. math::

    \\min_{x \\ge 0} \\tfrac12 x^T Q_p x - c_p^T x,
    \\qquad Q_p = 2 (A_p^T A_p + \\alpha D^T D), \\quad c_p = 2 A_p^T b - \\beta 1
    \\qquad \\text{(Sec. 4; Eq. 6a with the ambient column)}

warm-started from ADMM's iterate (its free set is nearly the optimum's, so a few dense
solves of the free block suffice), then the same weak-duality certificate in float64 with the
multiplier ``lam = max(g, 0)`` (exact at an exact optimum; moved along ``Q``'s null
direction where the ambient makes ``Q`` singular, :func:`planeray.demux._kernels.null_adjust`).
The finish is accepted only where that certificate proves the gap; otherwise the pixel keeps
ADMM's iterate, flagged not converged.

The active-set method is the textbook one (Nocedal & Wright, Alg. 16.3, for bound
constraints): solve the equality-constrained QP on the free set; if the solution leaves the
feasible set, step to the first bound it meets and fix that unknown; if not, free the fixed
unknown whose gradient is most negative; stop when no gradient on a fixed unknown is negative.
Each step is one Cholesky of the free block (``<= 230`` unknowns: about a millisecond).

References
----------
.. [1] J. Nocedal, S. J. Wright, "Numerical Optimization", 2nd ed., Springer 2006, Sec. 16.5.
"""

from __future__ import annotations

import numpy as np

from . import _kernels as K

__all__ = ["active_set_qp", "primal_dual_active_set", "finish_pixels"]


def _solve_block(Qff, cf) -> np.ndarray:
    """``Qff^{-1} cf`` (Cholesky; least squares where the block is singular)."""
    try:
        L = np.linalg.cholesky(Qff)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(Qff, cf, rcond=None)[0]
    y = np.linalg.solve(L, cf)
    return np.linalg.solve(L.T, y)


def active_set_qp(Q, c, x0, *, null=None, max_steps: int | None = None):
    """``argmin_{x >= 0} 1/2 x^T Q x - c^T x`` by a primal active-set method from ``x0 >= 0``.

    Parameters
    ----------
    Q : ndarray (U, U)
        Symmetric positive semidefinite; its block on every free set visited must be positive
        definite, except along ``null``.
    c : ndarray (U,)
    x0 : ndarray (U,)
        Start (clipped at 0); its positive entries are the first free set.
    null : ndarray (U,), optional
        A unit vector with ``Q null = 0`` (the ambient of Eq. 6a where its column is ``A 1``).
        While every unknown it touches is free, the objective is linear along it: the step
        then follows it downhill to the first bound (the flat floor of ``T`` moves into the
        ambient until ``min T = 0``).
    max_steps : int, optional
        Most steps (default ``4 U + 20``).

    Returns
    -------
    x : ndarray (U,)
    optimal : bool
        Whether the last free set's solution was feasible with no negative gradient on a fixed
        unknown (to rounding).
    """
    Q = np.asarray(Q, np.float64)
    c = np.asarray(c, np.float64)
    U = c.size
    x = np.maximum(np.asarray(x0, np.float64), 0.0)
    free = x > 0
    scale = 1.0 + np.abs(c).max(initial=0.0)
    along = None if null is None else np.abs(null) > 0
    for _ in range(4 * U + 20 if max_steps is None else max_steps):
        idx = np.flatnonzero(free)
        if along is not None and free[along].all():  # linear along null: downhill to the first bound
            d = null if c @ null > 0 else -null
            down = np.flatnonzero(d < 0)
            if down.size == 0:  # pragma: no cover - the sparsity term's slope points to a bound
                return x, False
            steps = x[down] / -d[down]
            j = int(np.argmin(steps))
            x = x + steps[j] * d
            x[down[j]] = 0.0
            x[free & (x <= 0.0)] = 0.0
            free &= x > 0.0
            continue
        y = np.zeros(U)
        if idx.size:
            y[idx] = _solve_block(Q[np.ix_(idx, idx)], c[idx])
        blocking = idx[y[idx] <= 0.0]
        if blocking.size == 0:
            x = y
            g = Q @ x - c
            fixed = np.flatnonzero(~free)
            if fixed.size == 0 or g[fixed].min() >= -1e-13 * scale:
                return x, True
            free[fixed[np.argmin(g[fixed])]] = True
            continue
        # step from x towards y until the first free unknown meets its bound, and fix it
        ratio = x[blocking] / (x[blocking] - y[blocking])
        k = int(np.argmin(ratio))
        x = x + ratio[k] * (y - x)
        x[blocking[k]] = 0.0
        x[free & (x <= 0.0)] = 0.0
        free &= x > 0.0
    return x, False


def primal_dual_active_set(Q, c, free, *, null=None, max_steps: int = 30):
    """Primal-dual active-set steps (Hintermueller, Ito & Kunisch 2003) from the free set ``free``.

    Each step solves the equality-constrained QP on the free set, then frees the fixed unknowns
    whose gradient is negative and fixes the free ones that went negative -- many at a time,
    so a start near the optimum (ADMM's split) needs a few steps, where the primal method
    (:func:`active_set_qp`) moves one unknown per step.  It can cycle on problems far from
    M-matrices; it stops when the set repeats.  Where the free set holds every unknown of
    ``null`` (the objective is linear along it), the step goes downhill along ``null`` from the
    block's least-squares solution to the first bound.

    Returns
    -------
    x : ndarray (U,)
        The last step's solution clipped at 0 (feasible).
    optimal : bool
        Whether the set stopped changing (``x`` is then the exact optimum to rounding).
    """
    Q = np.asarray(Q, np.float64)
    c = np.asarray(c, np.float64)
    U = c.size
    free = np.asarray(free, bool).copy()
    along = None if null is None else np.abs(null) > 0
    x = np.zeros(U)
    for _ in range(max_steps):
        idx = np.flatnonzero(free)
        x = np.zeros(U)
        if idx.size:
            Qff = Q[np.ix_(idx, idx)]
            if along is not None and free[along].all():
                x[idx] = np.linalg.lstsq(Qff, c[idx], rcond=1e-12)[0]
                d = null if c @ null > 0 else -null
                down = np.flatnonzero((d < 0) & (x > 0))
                if down.size:
                    x = x + np.min(x[down] / -d[down]) * d
            else:
                x[idx] = _solve_block(Qff, c[idx])
        g = Q @ x - c
        new = np.where(free, x > 0.0, g < 0.0)
        if np.array_equal(new, free):
            return np.maximum(x, 0.0), True
        free = new
    return np.maximum(x, 0.0), False


def finish_pixels(solver, B, mask, pix, tol, X, gap, fval, kkt, rss) -> np.ndarray:
    """Finish the pixels ``pix`` of a batch exactly in float64; returns which of them it certified.

    ``solver`` is the batch's :class:`planeray.demux.fast.AdmmRowSolver` (its ``A`` in the
    solver's variables, the ambient scaled), ``B`` (P, N) the observations (dropped ones
    zeroed), ``mask`` (P, N) the observations used or None; ``X, gap, fval, kkt, rss`` are
    the batch's outputs, overwritten for the pixels whose finish certifies a smaller relative
    gap than ADMM's.
    """
    A = solver.A
    U = A.shape[1]
    n_x = solver.n_x
    D = np.zeros((max(n_x - 1, 0), U))
    i = np.arange(n_x - 1)
    D[i, i], D[i, i + 1] = -1.0, 1.0
    R = solver.alpha * (D.T @ D)
    ok = np.zeros(len(pix), bool)
    for k, p in enumerate(pix):
        Ap = A if mask is None else A[mask[p]]
        b = B[p] if mask is None else B[p][mask[p]]
        Q = 2.0 * (Ap.T @ Ap + R)
        c = 2.0 * (Ap.T @ b) - solver.beta_u
        x, exact = primal_dual_active_set(Q, c, X[p] > 0, null=solver.null)
        if not exact:  # it cycled: the primal method from its (feasible) point, one unknown per step
            x, _ = active_set_qp(Q, c, x, null=solver.null)
        r = Ap @ x - b
        dx = D @ x
        rr = float(r @ r)
        f = rr + float(dx @ dx) * solver.alpha + solver.beta * float(x[:n_x].sum())
        g = Q @ x - c
        lam = np.maximum(g, 0.0)
        h = (g - lam)[None, :]
        lamz = np.array([lam @ x])
        if solver.null is not None:
            K.null_adjust(h, x[None, :], lam[None, :], solver.null, lamz)
        bound = 0.5 * _quad_inverse(solver, Q, h[0]) + float(lamz[0])
        rel = bound / max(f - bound, 1e-300)
        old = gap[p] / max(fval[p] - gap[p], 1e-300)
        if np.isfinite(rel) and rel < old:
            X[p], gap[p], fval[p], rss[p] = x, bound, f, rr
            kkt[p] = float(np.abs(np.minimum(x, g)).max(initial=0.0))
        ok[k] = bool(rel <= tol)
    return ok


def _quad_inverse(solver, Q, h) -> float:
    """``h^T Q^+ h`` in float64: on the null direction's complement where the solver has one."""
    U = Q.shape[0]
    if solver.null is not None:
        Bn = solver.null_basis
        Qr = Bn.T @ Q @ Bn
        hr = Bn.T @ h
    else:
        Qr, hr = Q, h
    m = Qr.shape[0]
    if m == 0:
        return 0.0
    Qr = Qr + 1e-12 * np.trace(Qr) / max(m, 1) * np.eye(m)  # as the solver's own certificate
    try:
        return float(hr @ np.linalg.solve(Qr, hr))
    except np.linalg.LinAlgError:  # pragma: no cover - Qr is positive definite
        return float(hr @ np.linalg.lstsq(Qr, hr, rcond=None)[0]) if U else 0.0
