"""The demultiplexing problem of Sec. 4 as one object (CVXPY style).

For every camera pixel ``(s, t)`` the transport over offset bins is

.. math::

    T^*, a^* = \\arg\\min_{T \\ge 0,\\; a \\ge 0} \\sum_i \\| I_i - \\sum_u L_i(u) T(u) - a\\, I_{w,i} \\|^2
          + \\alpha \\| \\partial T / \\partial v \\|^2 + \\beta \\| T \\|_1
    \\qquad \\text{(Eq. 6a)}

This is the paper's optimization problem after Eq. 6 (``alpha = beta = 0.01`` on
images normalized to [0, 1]) when the ambient term is off (``a = 0``, the default);
with ``ambient=True`` (planeray's extension, "Eq. 6a") every pixel also has an
**ambient** unknown ``a >= 0``: room light integrated over the row exposure adds
``a * I_w,i`` to image ``i`` (``I_w,i = t_e,i * lines_per_second``, the band width of
Eq. 2 in projector rows: :attr:`DemuxProblem.exposure_rows`).  ``a`` is in the units of
``T`` -- normalized image value per projector row of exposure -- so the ambient image
is a flat transport of height ``a`` over a whole exposure; the simulated camera's
ambient is ``a = ambient_e_per_us * albedo * 1e6 / (lines_per_second * full_well_e)``
(:class:`planeray.camera.CameraModel`).  ``a`` is not penalized by ``alpha`` or ``beta``.

*Identifiability.*  Where every band lies inside the projector, the band weights of
an image sum to its width (Eq. 2), so ``a I_w = A (a 1)``: the ambient column is
collinear with a flat transport, and no image can tell them apart.  The split is
decided by the sparsity term alone: moving a floor ``c`` from ``T`` into ``a`` leaves
every residual and the smoothness term unchanged and lowers ``beta ||T||_1`` by
``beta U c``, so at the optimum ``min_u T(u) = 0`` there -- the flat floor of ``T``
goes into ``a``.  With ``beta = 0`` the split is not identifiable (a whole
segment of optima) and the ambient term is refused.  In the rows near the
projector's ends, where bands are cut and ``a`` is not, the data see ``a`` directly.  The illumination matrix ``A[i, u] = L_i(u)`` comes from
the stack's own metadata through :mod:`planeray.timing` -- the same
discretization, sign convention and edge rule as the simulator; in the top and
bottom rows the unknown of a bin the projector's end cuts is its light per
projector row (:attr:`RowGroup.on_projector`).  It is shared by every
pixel of a camera row, and by most rows: it differs only where the projector
ends (rows near the top and bottom have fewer valid offsets).  Rows with equal
matrices form a :class:`RowGroup`; solvers work group by group.

Because ``T >= 0``, ``||T||_1 = 1^T T`` and the problem is the strictly convex
QP ``min 1/2 x^T Q x - c^T x, x >= 0`` with ``Q = 2 (A^T A + alpha D^T D)`` and
``c = 2 A^T b - beta 1``.  With the ambient term ``x = (T, a)``, ``A = [A_T, I_w]``,
``D`` acts on ``T`` only and ``c = 2 A^T b - beta (1, 0)``; ``Q`` is then (nearly)
singular along ``(1, -1)`` and the QP convex, not strictly (the solvers treat that
direction explicitly).

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

__all__ = ["RowGroup", "DemuxProblem", "difference_matrix", "read_observations", "pixel_terms", "AMBIENT_MODES"]

#: Values of the ``ambient`` option: the paper's problem, or Eq. 6a with an ambient unknown per pixel.
AMBIENT_MODES = ("none", "estimate")

#: Fewer used images than this cannot say anything about a 1-D profile.
MIN_IMAGES = 4


def difference_matrix(n: int) -> np.ndarray:
    """Forward difference ``D`` (``(n-1, n)``): the discrete ``d/dv`` of the smoothness term.

    Parameters
    ----------
    n : int
        Number of offsets.

    Returns
    -------
    ndarray (n - 1, n) float64
        ``D`` with ``(D x)_i = x_{i+1} - x_i``.

    See Also
    --------
    DemuxProblem : its smoothness term ``alpha ||D T||^2``.

    Examples
    --------
    >>> difference_matrix(3).tolist()
    [[-1.0, 1.0, 0.0], [0.0, -1.0, 1.0]]
    """
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

    See Also
    --------
    DemuxProblem : its groups.

    Examples
    --------
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("wax", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> group = pr.DemuxProblem.from_stack(stack).groups[0]
    >>> type(group).__name__, group.A.shape
    ('RowGroup', (23, 8))
    """

    rows: np.ndarray
    A: np.ndarray
    valid: slice
    on_projector: np.ndarray | None = None

    def __getstate__(self) -> dict:
        """The group without the solver cache a solve leaves on it (:func:`planeray.demux.fast.row_solver`).

        A problem is sent to Dask workers by pickling, also from one worker to another after
        it has solved chunks there; the cache holds locks, which do not pickle (the worker
        could not send it, and the chunk waited forever).  A receiver factors again.
        """
        state = dict(self.__dict__)
        state.pop("_admm_cache", None)
        return state

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
    ambient : bool
        Whether each pixel has an ambient unknown (Eq. 6a).
    exposure_rows : ndarray (N,) float64
        Row exposure of each used image in projector rows (``I_w``, Eq. 2): the
        ambient column.

    See Also
    --------
    planeray.demultiplex : solve it for a whole stack.
    planeray.demux.SOLVERS : the solvers by name.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 4, the optimization below Eq. 6.

    Examples
    --------
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("corner", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> problem = pr.DemuxProblem.from_stack(stack, alpha=0.01, beta=0.01)
    >>> problem.n_offsets, len(problem.image_index)  # offsets u = -114..114; 4 boundary images left out
    (229, 23)
    """

    def __init__(
        self,
        offsets_rows,
        image_index,
        groups,
        row_group,
        alpha,
        beta,
        shape,
        lines_per_second,
        projector_rows,
        *,
        exposure_rows=None,
        ambient: bool = False,
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
        self.exposure_rows = None if exposure_rows is None else np.asarray(exposure_rows, dtype=np.float64)
        self.ambient = bool(ambient)
        if self.ambient and self.exposure_rows is None:
            raise ValueError("the ambient term needs the images' exposures (exposure_rows)")

    @property
    def ambient_column(self) -> np.ndarray | None:
        """The ambient column ``I_w`` (N,) of Eq. 6a, or None for the paper's problem."""
        return self.exposure_rows if self.ambient else None

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
        cls,
        stack: Stack,
        *,
        alpha: float = 0.01,
        beta: float = 0.01,
        support_rows: int | None = None,
        ambient: bool = False,
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
        ambient : bool
            Add the ambient unknown of each pixel (Eq. 6a; default: the paper's problem).

        Raises
        ------
        InputError
            Negative weights, too few images, a sweep whose bands leave offsets
            inside its support unlit, or the ambient term with ``beta = 0`` (the split
            between a flat transport and the ambient is then not identifiable).
        """
        if not (np.isfinite(alpha) and np.isfinite(beta)) or alpha < 0 or beta < 0:
            raise InputError(f"alpha and beta must be non-negative numbers, got alpha={alpha}, beta={beta}")
        if ambient and beta == 0:
            raise InputError(
                "the ambient term needs beta > 0: with beta = 0 a flat transport and the ambient light are "
                "not identifiable (every split fits the images alike)"
            )
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
            W_lit = band_weights_at_row(bands, geometry, t0, offsets, profile=profile)
            on = coverage[t0][valid].astype(np.float64)
            partial = None if np.all(on == 1.0) else on
            groups.append(RowGroup(members, (W_lit[:, valid] * on).astype(np.float64), valid, partial))
        problem = cls(
            offsets,
            used,
            groups,
            row_group,
            alpha,
            beta,
            stack.shape,
            stack.lines_per_second,
            stack.projector_rows,
            exposure_rows=np.array([b.width_rows for b in bands]),
            ambient=ambient,
        )
        edges = np.concatenate([[b.centre_rows - b.width_rows / 2, b.centre_rows + b.width_rows / 2] for b in bands])
        problem._epipolar_resolution = float(np.abs(edges).min())
        return problem

    # ------------------------------------------------------------ evaluation
    def objective(self, group: RowGroup, X, B, mask=None, ambient=None) -> np.ndarray:
        """The objective of each pixel (Eq. 6a; the paper's problem without ``ambient``), in float64.

        Parameters
        ----------
        group : RowGroup
        X : ndarray (P, V)
            Transport over the group's valid offsets.
        B : ndarray (P, N)
            Observations (normalized images).
        mask : ndarray (P, N) bool, optional
            Observations to count (False: dropped, e.g. saturated).
        ambient : ndarray (P,), optional
            Each pixel's ambient ``a`` (normalized value per projector row of exposure);
            only for a problem with the ambient term.
        """
        return self._pixels(group, X, B, mask, ambient, kkt=False)["objective"]

    def diagnostics(self, group: RowGroup, X, B, mask=None, ambient=None) -> dict:
        """Residual RMS, objective and scaled KKT residual of each pixel, from one residual.

        The driver's per-pixel maps (:data:`planeray.demux.MAP_NAMES`); ``mask`` and
        ``ambient`` as in :meth:`objective`.  A pixel without any observation gets RMS 0
        and KKT NaN.
        """
        d = self._pixels(group, X, B, mask, ambient)
        n_obs = np.full(d["objective"].shape[0], np.shape(B)[1]) if mask is None else mask.sum(axis=1)
        d["kkt_residual"][n_obs == 0] = np.nan
        rss = d.pop("residual_ss")
        return {"residual_rms": np.sqrt(rss / np.maximum(n_obs, 1))} | d

    def kkt_residual(self, group: RowGroup, X, B, mask=None, ambient=None) -> np.ndarray:
        """Scaled KKT violation of each pixel (0 at the exact optimum).

        ``max |min(x, g)|`` over the unknowns (offsets, and the ambient with
        ``ambient``), with ``g = Q x - c`` the QP gradient, divided by ``1 + max |c|``;
        it vanishes iff ``x >= 0``, ``g >= 0`` and ``x g = 0``.  With ``mask`` (P, N)
        the dropped observations count in neither ``Q`` nor ``c`` (the pixel's own
        problem).  Costs two ``(P, N) x (N, V)`` products: the Hessian is never formed.
        """
        return self._pixels(group, X, B, mask, ambient)["kkt_residual"]

    def _pixels(self, group, X, B, mask, ambient, kkt=True):
        if ambient is not None and not self.ambient:
            raise ValueError("ambient values given for a problem without the ambient term")
        e = self.exposure_rows if ambient is not None else None
        return pixel_terms(group.A, X, B, self.alpha, self.beta, mask=mask, exposure_rows=e, ambient=ambient, kkt=kkt)


def pixel_terms(A, X, B, alpha, beta, *, mask=None, exposure_rows=None, ambient=None, kkt=True) -> dict:
    """Residual sum of squares, objective and scaled KKT residual of each pixel, in float64.

    The evaluation of Eq. 6a (the paper's problem without ``ambient``) behind
    :meth:`DemuxProblem.diagnostics`, also used by solvers that change variables
    internally (:func:`planeray.demux.fast.solve_fast` with the ambient term).

    Parameters
    ----------
    A : ndarray (N, V)
        Illumination matrix of the pixels' row group.
    X : ndarray (P, V)
        Transport over the group's valid offsets.
    B : ndarray (P, N)
        Observations.
    alpha, beta : float
    mask : ndarray (P, N) bool, optional
        Observations to count (False: dropped).
    exposure_rows, ambient : ndarray (N,) and (P,), optional
        The ambient column ``I_w`` (projector rows) and each pixel's ambient ``a``.
    kkt : bool
        Also the scaled KKT residual (two more products).

    Returns
    -------
    dict
        ``residual_ss``, ``objective`` and (with ``kkt``) ``kkt_residual``, each (P,).
    """
    X = np.asarray(X, dtype=np.float64)
    B = np.asarray(B, dtype=np.float64)
    R = X @ A.T - B
    if ambient is not None:
        R += np.asarray(ambient, np.float64)[:, None] * exposure_rows[None, :]
    if mask is not None:
        R = np.where(mask, R, 0.0)
        B = np.where(mask, B, 0.0)
    rr = np.einsum("ij,ij->i", R, R)
    dx = np.diff(X, axis=1)
    out = {"residual_ss": rr, "objective": rr + alpha * np.einsum("ij,ij->i", dx, dx) + beta * np.abs(X).sum(axis=1)}
    if kkt:
        g = 2.0 * R @ A + beta
        if X.shape[1] > 1:
            dX = (2.0 * alpha) * dx
            g[:, :-1] -= dX
            g[:, 1:] += dX
        c = 2.0 * B @ A - beta
        worst = np.abs(np.minimum(X, g)).max(axis=1, initial=0.0)
        if ambient is not None:  # the ambient unknown: gradient 2 R . I_w, no penalty
            worst = np.maximum(worst, np.abs(np.minimum(np.asarray(ambient, np.float64), 2.0 * R @ exposure_rows)))
            c = np.concatenate([c, (2.0 * B @ exposure_rows)[:, None]], axis=1)
        out["kkt_residual"] = worst / (1.0 + np.abs(c).max(axis=1))
    return out


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
