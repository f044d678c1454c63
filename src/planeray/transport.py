"""Plane-to-ray light transport ``T(v, s, t)`` and image formation (Eqs. 4-6).

A :class:`Transport` holds, for every camera pixel ``(t, s)`` (row, column), the
light it receives from each projector row, indexed by the offset ``u = v - t``
(projector row minus camera row, see :mod:`planeray.timing`):

* a **dense band** ``dense[t, s, k]`` over the integer offsets ``offsets_rows[k]``
  around the epipolar plane -- direct light, subsurface scattering, diffuse
  interreflections; this is the array stored as ``T`` in the transport store.
  Bin ``k`` is ``[k - 1/2, k + 1/2)`` of ``u = v - p_t`` and holds the light of its
  part on the projector (the binning and edge rules:
  :meth:`planeray.timing.RowGeometry.row_bins`, :meth:`~planeray.timing.RowGeometry.bin_parts`);
* optional **sparse long-range entries** ``(row, col, offset, value)`` for light
  from far rows (specular interreflections) that would waste a dense band.

Rendering an image under any illumination (Eq. 4, discretized) is a weighted sum
over offsets.  For a band the weights are 1 on a plateau with a few fractional or
blurred bins at its edges; with prefix sums over offsets the plateau costs two
look-ups per pixel, so a band costs O(pixels) independent of its width.

References
----------
.. [1] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport: Capture
   and Analysis", IEEE TVCG 2019, Eqs. 4-6.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .timing import RowGeometry, band_bin_weights

__all__ = ["SparseEntries", "Transport", "bin_projector_rows"]

_PLATEAU_TOL = 1e-9


@dataclass
class SparseEntries:
    """Long-range transport entries in coordinate form (all arrays of equal length).

    ``row``/``col`` are camera pixel indices, ``offset`` the integer offset bin
    ``u = v - t`` in projector rows, ``value`` the transport (float32).

    Parameters
    ----------
    row, col : ndarray of int (K,)
        Camera pixel of each entry.
    offset : ndarray of int (K,)
        Offset ``u = v - t`` of each entry, projector rows.
    value : ndarray of float32 (K,)
        Transport of each entry (normalized image value per projector row).

    See Also
    --------
    Transport : the dense band these entries extend.

    Examples
    --------
    >>> len(SparseEntries.empty().value)
    0
    """

    row: np.ndarray
    col: np.ndarray
    offset: np.ndarray
    value: np.ndarray

    def __post_init__(self):
        self.row = np.asarray(self.row, dtype=np.int32).ravel()
        self.col = np.asarray(self.col, dtype=np.int32).ravel()
        self.offset = np.asarray(self.offset, dtype=np.int32).ravel()
        self.value = np.asarray(self.value, dtype=np.float32).ravel()
        if not (self.row.size == self.col.size == self.offset.size == self.value.size):
            raise ValueError("sparse entries need row, col, offset and value of equal length")

    def __len__(self) -> int:
        return self.value.size

    @classmethod
    def empty(cls) -> SparseEntries:
        z = np.zeros(0)
        return cls(z, z, z, z)


def bin_projector_rows(per_row, geometry: RowGeometry, offsets_rows, *, far: bool = True):
    """File light given per projector row under offset bins, by the one exact rule.

    Projector row ``v`` covers ``[v - 1/2, v + 1/2)``; for camera row ``t`` its
    light goes to the bins ``[k - 1/2, k + 1/2)`` of ``u = v - p_t`` that the row
    overlaps, in proportion to the overlap (:meth:`planeray.timing.RowGeometry.row_bins`).
    Every producer that knows its light per whole projector row (``planeray render``
    in all its paths) bins it here, so the bins are the exact integrals of that
    light over their cells and each pixel keeps its energy.

    Parameters
    ----------
    per_row : ndarray, shape (P, H, W)
        Light from projector row ``v`` to camera pixel ``(t, s)`` (any units).
    geometry : RowGeometry
        Camera and projector rows (``P`` must be ``geometry.projector_rows``).
    offsets_rows : array_like of int, shape (U,)
        Consecutive integer offsets of the dense band.
    far : bool
        Also return the light that falls outside the band, as coordinate entries.

    Returns
    -------
    dense : ndarray of float32, shape (H, W, U)
    entries : tuple of ndarray ``(row, col, offset, value)``
        Nonzero light outside the band (empty arrays when ``far`` is False).

    See Also
    --------
    Transport : the offset bins.
    planeray.timing.RowGeometry.row_bins : the overlap rule.

    Examples
    --------
    Two camera rows of a three-row projector: camera row 0 sits at ``p_0 = 0.25``,
    so projector row 0 (offsets -0.75 to 0.25) gives 3/4 of its light to bin 0 and
    1/4 to bin -1 (the same energy, in the cells it covers):

    >>> per_row = np.zeros((3, 2, 1))
    >>> per_row[0, 0, 0] = 1.0
    >>> dense, _ = bin_projector_rows(per_row, RowGeometry(2, 3), [-1, 0, 1])
    >>> dense[0, 0].tolist()
    [0.25, 0.75, 0.0]
    """
    per_row = np.asarray(per_row)
    offsets = np.asarray(offsets_rows).astype(np.int64)
    P, H, W = per_row.shape
    if P != geometry.projector_rows or H != geometry.camera_rows:
        raise ValueError(f"light of shape {per_row.shape} for {geometry.projector_rows} projector and {H} camera rows")
    k_lo, k_hi = int(offsets[0]), int(offsets[-1])
    first, share = geometry.row_bins(np.arange(H))
    dense = np.zeros((H, W, offsets.size), np.float32)
    rows, cols, ks, vals = [], [], [], []
    for t in range(H):
        light = per_row[:, t, :].astype(np.float64)  # (P, W)
        binned = np.zeros((P + 1, W))  # bins first[t] .. first[t] + P
        binned[:P] += (1.0 - share[t]) * light
        binned[1:] += share[t] * light
        k = np.arange(P + 1) + first[t]
        inside = (k >= k_lo) & (k <= k_hi)
        dense[t][:, k[inside] - k_lo] = binned[inside].T
        if far:
            outside = binned[~inside]
            nz = np.nonzero(outside)
            if nz[0].size:
                rows.append(np.full(nz[0].size, t))
                cols.append(nz[1])
                ks.append(k[~inside][nz[0]])
                vals.append(outside[nz])
    if rows:
        entries = tuple(np.concatenate(a) for a in (rows, cols, ks, vals))
    else:
        entries = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
    return dense, entries


@dataclass
class Transport:
    """3D light transport over row offsets, plus sparse long-range entries.

    Parameters
    ----------
    dense : ndarray, shape (H, W, U)
        Transport per pixel over the offsets ``offsets_rows`` (float32).
    offsets_rows : ndarray of int, shape (U,)
        Consecutive integer offsets ``u = v - t`` in projector rows.
    geometry : RowGeometry, optional
        Camera/projector rows; defaults to one projector row per camera row.
    sparse : SparseEntries, optional
        Long-range entries outside the dense band.

    See Also
    --------
    planeray.demultiplex : a transport from a stack.
    planeray.read_transport, planeray.write_transport : the transport store.
    planeray.epipolar_image, planeray.band_image, planeray.relight : images from it.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Eq. 4, Fig. 2.

    Examples
    --------
    A transport that keeps all light in the epipolar plane (a mirror-free, direct-only scene):

    >>> import numpy as np
    >>> dense = np.zeros((4, 4, 3), np.float32)
    >>> dense[:, :, 1] = 0.5  # offset u = 0
    >>> T = Transport(dense, offsets_rows=np.array([-1, 0, 1]))
    >>> float(T.epipolar_image()[0, 0]), float(T.non_epipolar_image()[0, 0])
    (0.5, 0.0)
    """

    dense: np.ndarray
    offsets_rows: np.ndarray
    geometry: RowGeometry | None = None
    sparse: SparseEntries = field(default_factory=SparseEntries.empty)
    _prefix: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)
    _by_offset: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        self.dense = np.asarray(self.dense, dtype=np.float32)
        if self.dense.ndim != 3:
            raise ValueError(f"dense transport must be (H, W, U), got shape {self.dense.shape}")
        self.offsets_rows = np.asarray(self.offsets_rows).astype(np.int64)
        if self.offsets_rows.shape != (self.dense.shape[2],):
            raise ValueError(f"{self.offsets_rows.size} offsets for a band of {self.dense.shape[2]}")
        if self.offsets_rows.size > 1 and np.any(np.diff(self.offsets_rows) != 1):
            raise ValueError("offsets_rows must be consecutive integers")
        if self.geometry is None:
            self.geometry = RowGeometry(self.dense.shape[0])
        if self.geometry.camera_rows != self.dense.shape[0]:
            raise ValueError(f"geometry has {self.geometry.camera_rows} camera rows, transport {self.dense.shape[0]}")
        if self.sparse is None:
            self.sparse = SparseEntries.empty()
        if not np.all(np.isfinite(self.dense)):
            raise ValueError("transport contains NaN or infinite values")

    def __repr__(self) -> str:
        """A summary, never the arrays: shape, dtype, offsets, geometry, sparse entries.

        Examples
        --------
        >>> Transport.zeros((8, 6), range(-4, 5))
        Transport(dense=(8, 6, 9) float32, offsets_rows=[-4 .. 4], geometry=8 camera rows, 8 projector rows, sparse=0 entries)
        """
        offsets = self.offsets_rows
        span = f"[{offsets[0]} .. {offsets[-1]}]" if offsets.size else "[]"
        g = self.geometry
        return (
            f"Transport(dense={self.dense.shape} {self.dense.dtype}, offsets_rows={span}, "
            f"geometry={g.camera_rows} camera rows, {g.projector_rows} projector rows, "
            f"sparse={self.sparse.row.size} entries)"
        )

    # ------------------------------------------------------------------ shape
    @property
    def shape(self) -> tuple[int, int]:
        """Camera image shape ``(H, W)``."""
        return self.dense.shape[:2]

    @classmethod
    def zeros(cls, shape, offsets_rows, *, geometry=None) -> Transport:
        offsets = np.asarray(offsets_rows)
        return cls(np.zeros((*shape, offsets.size), np.float32), offsets, geometry)

    @classmethod
    def from_entries(cls, shape, offsets_rows, row, col, offset, value, *, geometry=None, dense=None) -> Transport:
        """Build a transport from coordinate entries, binning each offset into its bin.

        ``offset`` holds point positions ``u`` (continuous, in projector rows): each
        is filed under the bin ``[k - 1/2, k + 1/2)`` that contains it,
        ``k = floor(u + 1/2)``.  Light known per whole projector row goes through
        :func:`bin_projector_rows` instead.  Entries with offsets inside ``offsets_rows`` are added to the dense band (to
        ``dense`` if given), the others become sparse long-range entries.
        """
        offsets_rows = np.asarray(offsets_rows)
        H, W = shape
        if dense is None:
            dense = np.zeros((H, W, offsets_rows.size), np.float32)
        k = np.floor(np.asarray(offset, float) + 0.5).astype(np.int64)
        row = np.asarray(row, np.int64)
        col = np.asarray(col, np.int64)
        value = np.asarray(value, np.float64)
        inside = (k >= offsets_rows[0]) & (k <= offsets_rows[-1])
        flat = (row[inside] * W + col[inside]) * offsets_rows.size + (k[inside] - offsets_rows[0])
        dense = dense + np.bincount(flat, value[inside], minlength=dense.size).reshape(dense.shape).astype(np.float32)
        far = ~inside
        if far.any():
            # Merge duplicate far entries so the sparse list stays compact; one int64
            # key per entry keeps np.unique fast for millions of entries.
            k_far = k[far]
            k_min, span = k_far.min(), int(k_far.max() - k_far.min()) + 1
            key = (row[far] * W + col[far]) * span + (k_far - k_min)
            uniq, inv = np.unique(key, return_inverse=True)
            vals = np.bincount(inv.ravel(), value[far], minlength=uniq.size)
            pix, kk = np.divmod(uniq, span)
            sparse = SparseEntries(pix // W, pix % W, kk + k_min, vals)
        else:
            sparse = SparseEntries.empty()
        return cls(dense, offsets_rows, geometry, sparse)

    # ------------------------------------------------------------ rendering
    def illumination_weights(self, illumination) -> np.ndarray:
        """Weights ``(H, U)`` of an illumination over this transport's offset bins."""
        rows = np.arange(self.shape[0])[:, None]
        return illumination.weights(self.geometry, rows, self.offsets_rows[None, :])

    def render(self, illumination, *, out=None) -> np.ndarray:
        """Image ``I(s, t) = sum_v L(v) T(v, s, t)`` under an illumination, Eq. 4.

        Parameters
        ----------
        illumination : object with ``weights(geometry, rows, offsets)``
            A :class:`planeray.timing.Band`, :class:`planeray.timing.RowPattern` or
            any object returning illumination weights per (camera row, offset bin).
        out : ndarray of float32, shape (H, W), optional
            Written and returned instead of a new image (a caller rendering many
            frames reuses one buffer).

        Returns
        -------
        image : ndarray of float32, shape (H, W)
        """
        image = self.render_weights(self.illumination_weights(illumination), out=out)
        if len(self.sparse):
            sp = self.sparse
            w = illumination.weights(self.geometry, sp.row, sp.offset)
            flat = sp.row.astype(np.int64) * self.shape[1] + sp.col
            image += np.bincount(flat, w * sp.value, minlength=image.size).reshape(image.shape).astype(np.float32)
        return image

    def render_weights(self, weights, *, out=None) -> np.ndarray:
        """Dense part of Eq. 4 for per-row weights ``(H, U)`` over ``offsets_rows``.

        Band-like weights (a plateau of ones plus a few edge bins) take the O(pixels)
        prefix-sum path; any other pattern a dense weighted sum over offsets.
        ``out``: a float32 ``(H, W)`` array written and returned instead of a new image.
        """
        weights = np.asarray(weights, dtype=np.float64)
        H, W, U = self.dense.shape
        if weights.shape != (H, U):
            raise ValueError(f"weights must be (H, U) = {(H, U)}, got {weights.shape}")
        if out is None:
            out = np.empty((H, W), np.float32)
        elif out.shape != (H, W) or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise ValueError(f"out must be a C-contiguous float32 array of shape {(H, W)}")
        full = weights >= 1.0 - _PLATEAU_TOL
        has = full.any(axis=1)
        k0 = np.where(has, np.argmax(full, axis=1), 0)
        k1 = np.where(has, U - np.argmax(full[:, ::-1], axis=1), 0)
        contiguous = full.sum(axis=1) == (k1 - k0)
        k0 = np.where(contiguous, k0, 0)
        k1 = np.where(contiguous, k1, 0)
        cols = np.arange(U)
        plateau = (cols >= k0[:, None]) & (cols < k1[:, None])
        residual = weights - plateau
        nonzero = residual != 0.0
        n_edge = int(nonzero.sum(axis=1).max(initial=0))
        if n_edge > max(8, U // 3):
            np.matmul(self.dense, weights.astype(np.float32)[:, :, None], out=out[..., None])
            return out
        from ._bandsum import band_rows  # compiled (Numba): plateau + edge bins in one pass per row

        return band_rows(self._prefix_sums(), self._offset_major(), k0, k1, residual, out)

    def _offset_major(self) -> np.ndarray:
        if self._by_offset is None:
            self._by_offset = np.ascontiguousarray(np.moveaxis(self.dense, 2, 0))
        return self._by_offset

    def _prefix_sums(self) -> np.ndarray:
        if self._prefix is None:
            by_u = self._offset_major()
            prefix = np.empty((by_u.shape[0] + 1, *by_u.shape[1:]), np.float32)
            prefix[0] = 0.0
            acc = np.zeros(by_u.shape[1:], np.float64)  # float64 accumulator, float32 storage
            for k in range(by_u.shape[0]):  # loop over offsets, vectorized over pixels
                acc += by_u[k]
                prefix[k + 1] = acc
            self._prefix = prefix
        return self._prefix

    def invalidate_cache(self) -> None:
        """Drop render caches after modifying ``dense`` in place."""
        self._prefix = None
        self._by_offset = None

    # ------------------------------------------------------- Eqs. 5 and 6
    def full_image(self) -> np.ndarray:
        """Image under full illumination of every projector row (direct + global)."""
        image = self.dense.sum(axis=2, dtype=np.float64)
        if len(self.sparse):
            flat = self.sparse.row.astype(np.int64) * self.shape[1] + self.sparse.col
            image += np.bincount(flat, self.sparse.value, minlength=image.size).reshape(image.shape)
        return image.astype(np.float32)

    def epipolar_image(self) -> np.ndarray:
        """Epipolar image ``I_e = int delta(t - v) T dv``, Eq. 5.

        The delta picks the offset bins that intersect the camera row's own
        footprint: bin 0 when one camera row is one projector row, the ~``P/H``
        bins a camera row spans otherwise.
        """
        footprint = band_bin_weights(self.offsets_rows, 0.0, self.geometry.rows_per_camera_row) > 0
        return self.dense[:, :, footprint].sum(axis=2, dtype=np.float64).astype(np.float32)

    def non_epipolar_image(self) -> np.ndarray:
        """Non-epipolar image ``I_n = int (1 - delta(t - v)) T dv``, Eq. 6."""
        return self.full_image() - self.epipolar_image()
