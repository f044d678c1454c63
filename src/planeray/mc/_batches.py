"""Independent photon batches traced on threads: the one parallel loop of the Monte Carlo engines.

Every engine (:mod:`planeray.mc.engine`, :mod:`planeray.mc.wall`, :mod:`planeray.mc.layered`)
traces its photons in batches, each with its own random stream and its own tallies, in a
compiled kernel that releases the GIL (``nogil``).  The batches are run here, one kernel call
per batch on a pool of ``numba.get_num_threads()`` threads, and their tallies concatenated in
batch order: the bytes of a result do not depend on the number of threads, nor on the order
in which batches finish.  (The kernels were ``parallel=True`` with ``prange``: the same bytes,
but a 3x longer compile on first use, 30-50 s per kernel on a 2-core machine.)
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np


def trace_batches(kernel, per_batch, shared, *, progress=None):
    """Tallies of ``kernel`` over every batch, concatenated in batch order.

    Parameters
    ----------
    kernel : numba dispatcher
        Compiled with ``nogil=True``; called as ``kernel(*per_batch_slices, *shared)`` and
        returning a tuple of arrays whose first axis is the batch.
    per_batch : tuple of ndarray
        Arrays with one row per batch (random states, first photon index, photon counts).
    shared : tuple
        The kernel's other arguments (the same for every batch).
    progress : callable, optional
        ``progress(n)`` after each batch (in batch order), ``n`` its photons (the batch's
        entry of ``per_batch[-1]``, the photon counts).

    Returns
    -------
    tuple of ndarray
    """
    B = len(per_batch[0])
    threads = max(1, min(B, numba.get_num_threads()))
    if threads == 1 and progress is None:
        return kernel(*per_batch, *shared)
    photons = per_batch[-1]

    def one(b):
        return kernel(*(a[b : b + 1] for a in per_batch), *shared)

    parts = []
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for b, part in enumerate(pool.map(one, range(B))):
            parts.append(part)
            if progress is not None:
                progress(int(photons[b]))
    return tuple(np.concatenate(t) for t in zip(*parts))
