"""The inner loop of the O(pixels) band renderer (:meth:`planeray.transport.Transport.render_weights`), compiled.

For each camera row the image is the difference of two prefix sums over offsets (the band's
plateau of full weights) plus the few fractional or blurred edge bins, each a weighted row of
the offset-major transport.  NumPy would gather the edge rows into an ``(H, n_edge, W)``
temporary and contract it; fused here, the row is read once and nothing is allocated (the image
is written into ``out``; about 5x less time at 512x512).  Compiled by Numba on first use and cached on disk;
imported only when a band is rendered (``import planeray`` stays instant).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["band_rows"]


@numba.njit(cache=True)
def band_rows(prefix, by_offset, k0, k1, residual, out):  # pragma: no cover - compiled
    """``out[t] = prefix[k1[t], t] - prefix[k0[t], t] + sum_u residual[t, u] * by_offset[u, t]`` (float32).

    ``prefix``: (U + 1, H, W) float32 prefix sums over offsets; ``by_offset``: (U, H, W) float32;
    ``k0, k1``: (H,) plateau bounds; ``residual``: (H, U) float64 weights minus the plateau
    (non-zero only at a few edge bins); ``out``: (H, W) float32, overwritten and returned.
    """
    H = prefix.shape[1]
    W = prefix.shape[2]
    U = residual.shape[1]
    for t in range(H):
        a = k0[t]
        b = k1[t]
        for w in range(W):
            out[t, w] = prefix[b, t, w] - prefix[a, t, w]
        for u in range(U):
            v = np.float32(residual[t, u])
            if v != 0.0:
                for w in range(W):
                    out[t, w] += v * by_offset[u, t, w]
    return out
