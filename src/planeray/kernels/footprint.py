"""A camera row's footprint on the projector's rows: what a pixel's kernel is averaged over.

A camera row spans ``rows_per_camera_row`` projector rows (the capture's geometry); a
Lambertian surface returns each in equal share (:func:`planeray.timing.band_bin_weights`).
The scenes spread a pixel's direct light with :func:`footprint_kernel`; the forward model of
the fit averages the line kernel over :func:`camera_row_footprint`.
"""

from __future__ import annotations

import numpy as np

from ..timing import band_bin_weights

__all__ = ["footprint_kernel", "camera_row_footprint", "footprint_average"]


def footprint_kernel(offsets_rows, rows_per_camera_row: float) -> np.ndarray:
    """Direct light of one camera row spread over the projector rows it spans.

    A camera row covers ``rows_per_camera_row`` projector rows; a Lambertian
    surface returns each of them in equal share.  Sums to 1.

    Parameters
    ----------
    offsets_rows : array_like of int
        Offsets ``u``, projector rows.
    rows_per_camera_row : float
        Projector rows one camera row spans (``P / H``).

    Returns
    -------
    ndarray of float64
        The kernel, summing to 1.

    See Also
    --------
    planeray.timing.band_bin_weights : the same bin rule.

    Examples
    --------
    A camera row of 2 projector rows returns light from the rows it spans:

    >>> import numpy as np
    >>> footprint_kernel(np.arange(-2, 3), 2.0).tolist()
    [0.0, 0.25, 0.5, 0.25, 0.0]
    """
    k = band_bin_weights(offsets_rows, 0.0, rows_per_camera_row)
    return (k / k.sum()).astype(np.float64)


def camera_row_footprint(rows_per_camera_row):
    """``(offsets, weights)``: the projector-row offsets a camera row spans around its centre and their shares.

    One row (``rows_per_camera_row <= 1``): ``([0], [1])``.  The weights sum to 1.
    """
    rpc = float(rows_per_camera_row)
    if rpc <= 1.0 + 1e-12:
        return np.zeros(1, np.int64), np.ones(1)
    half = int(np.ceil(0.5 * rpc + 0.5))
    f = np.arange(-half, half + 1)
    w = band_bin_weights(f, 0.0, rpc)
    return f, w / w.sum()


def footprint_average(values_row, offsets_rows, foot) -> np.ndarray:
    """A symmetric kernel given at the offsets 0 to ``R`` (last axis), averaged over a camera row's footprint at
    signed offsets; zero beyond ``R``.

    Parameters
    ----------
    values_row : ndarray (..., R + 1)
        The kernel (or its change) at projector-row offsets ``0 .. R``.
    offsets_rows : array_like of int (U,)
        Signed offsets, projector rows.
    foot : tuple of ndarray
        ``(offsets, weights)`` of :func:`camera_row_footprint`.

    Returns
    -------
    ndarray (..., U)

    Examples
    --------
    >>> import numpy as np
    >>> footprint_average(np.array([1.0, 0.5, 0.25]), np.arange(-3, 4), camera_row_footprint(1.0)).tolist()
    [0.0, 0.25, 0.5, 1.0, 0.5, 0.25, 0.0]
    """
    f, w = foot
    u = np.abs(np.asarray(offsets_rows, np.int64)[:, None] + f[None, :])  # (U, F)
    reach = np.shape(values_row)[-1] - 1
    vals = np.where(u <= reach, values_row[..., np.minimum(u, reach)], 0.0)
    return (vals * w).sum(axis=-1)
