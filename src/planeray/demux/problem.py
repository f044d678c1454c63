"""The demultiplexing problem of Sec. 4 as one object (CVXPY style).

For every camera pixel ``(s, t)`` the transport over offset bins is

.. math::

    T^* = \\arg\\min_{T \\ge 0} \\sum_i \\| I_i - \\sum_u L_i(u) T(u) \\|^2
          + \\alpha \\| \\partial T / \\partial v \\|^2 + \\beta \\| T \\|_1

(the paper's optimization problem after Eq. 6; ``alpha = beta = 0.01`` on images
normalized to [0, 1]).  The illumination matrix ``A[i, u] = L_i(u)`` comes from
the stack's own metadata through :mod:`planeray.timing` -- the same
discretization, sign convention and edge rule as the simulator; in the top and
bottom rows the unknown of a bin the projector's end cuts is its light per
projector row (:attr:`RowGroup.on_projector`).  It is shared by every
pixel of a camera row, and by most rows: it differs only where the projector
ends (rows near the top and bottom have fewer valid offsets).  Rows with equal
matrices form a :class:`RowGroup`; solvers work group by group.

Because ``T >= 0``, ``||T||_1 = 1^T T`` and the problem is the strictly convex
QP ``min 1/2 x^T Q x - c^T x, x >= 0`` with ``Q = 2 (A^T A + alpha D^T D)`` and
``c = 2 A^T b - beta 1``.

References
----------
.. [1] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport: Capture
   and Analysis", IEEE TVCG 2019, Sec. 4.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..stack import Stack
from ..timing import band_weights_at_row, sweep_support_rows

__all__ = ["RowGroup", "DemuxProblem", "difference_matrix", "read_observations"]

#: Fewer used images than this cannot say anything about a 1-D profile.
MIN_IMAGES = 4


def difference_matrix(n: int) -> np.ndarray:
    """Forward difference ``D`` (``(n-1, n)``): the discrete ``d/dv`` of the smoothness term."""
    D = np.zeros((max(n - 1, 0), n))
    idx = np.arange(n - 1)
    D[idx, idx] = -1.0
    D[idx, idx + 1] = 1.0
    return D


@dataclass
class RowGroup:
    """Camera rows that share one illumination matrix.

    Attributes
    ----------
    rows : ndarray of int
        Camera rows of the group.
    A : ndarray (N, V) float64
        Illumination weights of the used images over the group's valid offsets.
    valid : slice
        The contiguous valid offsets (indices into ``DemuxProblem.offsets_rows``);
        offsets outside it fall off the projector and stay 0.
    on_projector : ndarray (V,) float64, optional
        Fraction of each valid bin that lies on the projector
        (:meth:`planeray.timing.RowGeometry.coverage`; None: all 1).  The unknowns
        ``x`` are the light *per projector row* of each bin, so that smoothness and
        sparsity weigh every bin alike; the transport is ``T = x * on_projector``
        (a bin the projector's end cuts to a sliver holds the light of the sliver).
    """

    rows: np.ndarray
    A: np.ndarray
    valid: slice
    on_projector: np.ndarray | None = None

    def transport(self, X) -> np.ndarray:
        """The light of each bin, ``T = x * on_projector``, from the unknowns ``X`` (``(P, V)``)."""
        return X if self.on_projector is None else X * self.on_projector

    def hessian(self, alpha: float) -> np.ndarray:
        """``A^T A + alpha D^T D`` (half the QP's ``Q``), shared by the group's pixels."""
        D = difference_matrix(self.A.shape[1])
        return self.A.T @ self.A + alpha * D.T @ D


class DemuxProblem:
    """Per-pixel regularized non-negative least squares for a stack (Sec. 4).

    Build it with :meth:`from_stack`; evaluate :meth:`objective`; solve it with
    :func:`planeray.demux.demultiplex` or any solver of
    :data:`planeray.demux.SOLVERS`.

    Attributes
    ----------
    offsets_rows : ndarray (U,) int
        Offsets ``u = v - t`` of the unknowns (the sweep's full support).
    image_index : ndarray (N,) int
        Stack images used (boundary images excluded).
    groups : list of RowGroup
    row_group : ndarray (H,) int
        Group of each camera row.
    """

    def __init__(
        self, offsets_rows, image_index, groups, row_group, alpha, beta, shape, lines_per_second, projector_rows
    ):
        self.offsets_rows = np.asarray(offsets_rows, dtype=np.int64)
        self.image_index = np.asarray(image_index, dtype=np.int64)
        self.groups = list(groups)
        self.row_group = np.asarray(row_group, dtype=np.int64)
        self.alpha = float(alpha)
        self.beta = float(beta)
        self.shape = tuple(shape)
        self.lines_per_second = float(lines_per_second)
        self.projector_rows = int(projector_rows)

    @property
    def epipolar_resolution_rows(self) -> float:
        """Half-width of the cell around the epipolar plane that the data cannot split.

        The distance from ``u = 0`` to the nearest band edge of the used images:
        light within ``+-`` this many rows of the epipolar plane is seen by every
        image alike, so its distribution inside the cell comes from the
        regularization alone.  For the paper's sweep (boundary images excluded)
        it is 6.075 rows -- why the paper cannot separate short-range indirect
        light very near the epipolar plane (Sec. 11).
        """
        return self._epipolar_resolution

    @property
    def n_offsets(self) -> int:
        return self.offsets_rows.size

    @property
    def n_images(self) -> int:
        return self.image_index.size

    @classmethod
    def from_stack(
        cls, stack: Stack, *, alpha: float = 0.01, beta: float = 0.01, support_rows: int | None = None
    ) -> DemuxProblem:
        """Assemble the problem from a stack's metadata.

        Parameters
        ----------
        stack : Stack
        alpha, beta : float
            Smoothness and sparsity weights (paper: 0.01, 0.01).
        support_rows : int, optional
            Half-width ``K`` of the unknown offsets ``-K..K``; default: the sweep's
            full support ``max |I_d| + I_w / 2``.

        Raises
        ------
        InputError
            Negative weights, too few images, or a sweep whose bands leave offsets
            inside its support unlit.
        """
        if not (np.isfinite(alpha) and np.isfinite(beta)) or alpha < 0 or beta < 0:
            raise InputError(f"alpha and beta must be non-negative numbers, got alpha={alpha}, beta={beta}")
        for name in ("jitter_us", "line_width_us"):
            value = getattr(stack, name)
            if not np.isfinite(value) or value < 0:
                raise InputError(f"inconsistent metadata: sync {name} = {value!r} must be a non-negative number")
        if stack.projector_rows < 1:
            raise InputError(f"inconsistent metadata: projector_rows = {stack.projector_rows}")
        used = np.flatnonzero(~stack.excluded)
        if used.size < MIN_IMAGES:
            raise InputError(
                f"stack has {used.size} images usable for demultiplexing ({int(stack.excluded.sum())} boundary images excluded); "
                f"at least {MIN_IMAGES} are needed"
            )
        K = sweep_support_rows(stack.sweep, stack.lines_per_second) if support_rows is None else int(support_rows)
        offsets = np.arange(-K, K + 1)
        bands = [b for i, b in enumerate(stack.bands()) if not stack.excluded[i]]
        geometry = stack.geometry
        rows = np.arange(stack.shape[0])
        # A row's matrix is the bands' common profile, clipped to the projector by the
        # edge rule (RowGeometry.bin_parts), so rows with the same projector coverage share one matrix.
        profile = np.stack([b.profile(offsets) for b in bands])  # (N, U)
        coverage = geometry.coverage(rows[:, None], offsets[None, :])  # (H, U)
        lit_profile = profile.max(axis=0) > 0
        lit = (coverage > 0) & lit_profile[None, :]
        # Offsets inside the projector that no used band lights cannot be recovered.
        holes = (coverage > 0) & ~lit_profile[None, :]
        inner = np.abs(offsets) < K
        if np.any(holes[:, inner]):
            u_hole = offsets[inner][np.flatnonzero(holes[:, inner].any(axis=0))[0]]
            raise InputError(
                f"the sweep's bands leave offset u = {u_hole} unlit inside its support -/+{K}: "
                "add delays/exposures so the bands overlap (too few images for the support)"
            )
        index: dict[bytes, int] = {}
        row_group = np.array([index.setdefault(coverage[t].tobytes(), len(index)) for t in rows])
        groups = []
        for g in index.values():
            members = np.flatnonzero(row_group == g)
            t0 = members[0]
            nz = np.flatnonzero(lit[t0])
            valid = slice(int(nz[0]), int(nz[-1]) + 1) if nz.size else slice(0, 0)
            # the edge rule: a band lights the fraction of a bin's part on the projector that it covers
            # (Band.weights); the unknown is the light per row, so A carries the part's length too
            W_lit = band_weights_at_row(bands, geometry, t0, offsets)
            on = coverage[t0][valid].astype(np.float64)
            partial = None if np.all(on == 1.0) else on
            groups.append(RowGroup(members, (W_lit[:, valid] * on).astype(np.float64), valid, partial))
        problem = cls(
            offsets, used, groups, row_group, alpha, beta, stack.shape, stack.lines_per_second, stack.projector_rows
        )
        edges = np.concatenate([[b.centre_rows - b.width_rows / 2, b.centre_rows + b.width_rows / 2] for b in bands])
        problem._epipolar_resolution = float(np.abs(edges).min())
        return problem

    # ------------------------------------------------------------ evaluation
    def objective(self, group: RowGroup, X, B, mask=None) -> np.ndarray:
        """The objective of each pixel, in float64.

        Parameters
        ----------
        group : RowGroup
        X : ndarray (P, V)
            Transport over the group's valid offsets.
        B : ndarray (P, N)
            Observations (normalized images).
        mask : ndarray (P, N) bool, optional
            Observations to count (False: dropped, e.g. saturated).
        """
        X = np.asarray(X, dtype=np.float64)
        r = X @ group.A.T - np.asarray(B, dtype=np.float64)
        if mask is not None:
            r = np.where(mask, r, 0.0)
        dx = np.diff(X, axis=1)
        return (r * r).sum(axis=1) + self.alpha * (dx * dx).sum(axis=1) + self.beta * np.abs(X).sum(axis=1)

    def diagnostics(self, group: RowGroup, X, B, mask=None) -> dict:
        """Residual RMS, objective and scaled KKT residual of each pixel, from one residual.

        The driver's per-pixel maps (:data:`planeray.demux.MAP_NAMES`); ``mask`` as in
        :meth:`objective`.  A pixel without any observation gets RMS 0 and KKT NaN.
        """
        X, R, B = _masked_residual(group, X, B, mask)
        n_obs = np.full(X.shape[0], B.shape[1]) if mask is None else mask.sum(axis=1)
        rr = np.einsum("ij,ij->i", R, R)
        dx = np.diff(X, axis=1)
        objective = rr + self.alpha * np.einsum("ij,ij->i", dx, dx) + self.beta * np.abs(X).sum(axis=1)
        kkt = self._kkt(group, X, R, B, dx)
        kkt[n_obs == 0] = np.nan
        return {"residual_rms": np.sqrt(rr / np.maximum(n_obs, 1)), "objective": objective, "kkt_residual": kkt}

    def _kkt(self, group, X, R, Bm, dx):
        g = 2.0 * R @ group.A + self.beta
        if X.shape[1] > 1:
            dX = (2.0 * self.alpha) * dx
            g[:, :-1] -= dX
            g[:, 1:] += dX
        c = 2.0 * Bm @ group.A - self.beta
        return np.abs(np.minimum(X, g)).max(axis=1) / (1.0 + np.abs(c).max(axis=1))

    def kkt_residual(self, group: RowGroup, X, B, mask=None) -> np.ndarray:
        """Scaled KKT violation of each pixel (0 at the exact optimum).

        ``max |min(x, g)|`` over offsets, with ``g = Q x - c`` the QP gradient,
        divided by ``1 + max |c|``; it vanishes iff ``x >= 0``, ``g >= 0`` and
        ``x g = 0``.  With ``mask`` (P, N) the dropped observations count in neither
        ``Q`` nor ``c`` (the pixel's own problem).  Costs two ``(P, N) x (N, V)``
        products: the Hessian is never formed.
        """
        X, R, B = _masked_residual(group, X, B, mask)
        return self._kkt(group, X, R, B, np.diff(X, axis=1))


def _masked_residual(group: RowGroup, X, B, mask):
    """``X``, the residual ``A x - b`` and ``B`` in float64, dropped observations set to 0 in both."""
    X = np.asarray(X, dtype=np.float64)
    B = np.asarray(B, dtype=np.float64)
    R = X @ group.A.T - B
    if mask is not None:
        R = np.where(mask, R, 0.0)
        B = np.where(mask, B, 0.0)
    return X, R, B


def read_observations(stack: Stack, problem: DemuxProblem, rows: slice, *, source=None):
    """Observations ``(N, r, W)`` float64 of the used images and their saturation mask."""
    imgs = np.asarray(stack.images[:, rows, :], dtype=np.float64)[problem.image_index]
    bad = ~np.isfinite(imgs)
    if bad.any():
        n, r, c = np.argwhere(bad)[0]
        where = f"{source}: " if source else ""
        raise InputError(
            f"{where}image {int(problem.image_index[n])} has a non-finite value at pixel ({rows.start + r}, {c})"
        )
    sat = None
    if stack.saturated is not None:
        sat = np.asarray(stack.saturated[:, rows, :], dtype=bool)[problem.image_index]
        if not sat.any():
            sat = None
    return imgs, sat
