"""The events of a photon's life, shared by the three photon kernels, and the batches they run in.

The kernels (:mod:`planeray.mc.engine`: a slab; :mod:`planeray.mc.wall`: beside a container
wall; :mod:`planeray.mc.layered`: layers and veins) keep their own loops -- their random
streams and boundaries differ on purpose -- but a photon is launched, escapes through the
top face, collides, plays Russian roulette and is cut off by the same steps, written once
here as Numba functions inlined into each kernel (the MCML scheme of Wang, Jacques &
Zheng [1]_, the Henyey-Greenstein sampling of Prahl et al. [2]_).  Each returns the
photon's new state; the kernels add the weights they return to their own tallies.

The batches: every kernel traces its photons in :data:`N_BATCHES` independent batches
(:func:`batch_counts`), each with its own xoshiro256+ stream (:func:`batch_states`,
Blackman & Vigna [3]_); :func:`batch_stats` turns per-batch tallies into means per photon
and their standard errors.

References
----------
.. [1] L. Wang, S. L. Jacques, L. Zheng, "MCML -- Monte Carlo modeling of light
   transport in multi-layered tissues", Comput. Methods Programs Biomed. 47, 1995.
.. [2] S. A. Prahl, M. Keijzer, S. L. Jacques, A. J. Welch, "A Monte Carlo model
   of light propagation in tissue", SPIE IS 5, 1989.
.. [3] D. Blackman, S. Vigna, "Scrambled linear pseudorandom number generators",
   ACM TOMS 47(4), 2021 (xoshiro256+).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..errors import InputError
from .physics import fresnel_jit, hg_scatter_jit

__all__ = [
    "N_BATCHES",
    "ROULETTE_THRESHOLD",
    "ROULETTE_CHANCE",
    "uniform",
    "free_path",
    "launch",
    "fresnel_escape",
    "collide",
    "roulette",
    "beyond_cutoff",
    "new_tallies",
    "batch_counts",
    "batch_states",
    "batch_stats",
    "check_photons",
    "check_offsets",
]

#: Independent photon batches of every run (the standard errors come from their spread).
N_BATCHES = 32
#: Russian roulette: a photon whose weight falls below this ...
ROULETTE_THRESHOLD = 1e-4
#: ... survives with probability ``1 / ROULETTE_CHANCE`` at ``ROULETTE_CHANCE`` times its weight.
ROULETTE_CHANCE = 10.0


# ---------------------------------------------------------------- random numbers
@numba.njit(cache=True, inline="always")
def _rotl(x, k):
    return (x << np.uint64(k)) | (x >> np.uint64(64 - k))


@numba.njit(cache=True, inline="always")
def uniform(s):
    """Next double in ``[0, 1)`` from xoshiro256+ state ``s`` (4 uint64, updated in place) [3]_."""
    s0 = s[0]
    s1 = s[1]
    s2 = s[2]
    s3 = s[3]
    result = s0 + s3
    t = s1 << np.uint64(17)
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = _rotl(s3, 45)
    s[0] = s0
    s[1] = s1
    s[2] = s2
    s[3] = s3
    return float(result >> np.uint64(11)) * (1.0 / 9007199254740992.0)


# ---------------------------------------------------------------- the events
@numba.njit(cache=True, inline="always")
def free_path(s, sigma_t):
    """A free path ``-ln(xi) / sigma_t`` (mm), ``xi`` uniform in ``(0, 1]``."""
    return -math.log(1.0 - uniform(s)) / sigma_t


@numba.njit(cache=True, inline="always")
def launch(x, y, w0):
    """A photon entering at ``(x, y)`` on the top face, straight down: ``(x, y, z, ux, uy, uz, w)``.

    ``w0`` is the weight that enters (1 minus the specular reflection at normal incidence).
    """
    return x, y, 0.0, 0.0, 0.0, 1.0, w0


@numba.njit(cache=True, inline="always")
def fresnel_escape(w, cos_i, n):
    """A photon of weight ``w`` meeting a face at incidence cosine ``cos_i`` from a medium of relative index ``n``.

    Returns ``(escaped, w)``: the Fresnel-transmitted part ``w (1 - R)`` that leaves, and the
    internally reflected weight ``w R`` that goes on (the caller flips its direction).
    """
    R = fresnel_jit(cos_i, n)
    return w * (1.0 - R), w * R


@numba.njit(cache=True, inline="always")
def collide(s, w, albedo, ux, uy, uz, g):
    """A collision: implicit capture and a new Henyey-Greenstein direction.

    Returns ``(absorbed, w, ux, uy, uz)``: the absorbed weight ``(1 - albedo) w``, the
    surviving weight ``albedo w`` and the new direction (polar cosine, then azimuth drawn
    from ``s``, in that order).
    """
    absorbed = w * (1.0 - albedo)
    w *= albedo
    ux, uy, uz = hg_scatter_jit(ux, uy, uz, g, uniform(s), uniform(s))
    return absorbed, w, ux, uy, uz


@numba.njit(cache=True, inline="always")
def roulette(s, w):
    """Russian roulette below :data:`ROULETTE_THRESHOLD`.

    Returns ``(w, absorbed, alive)``: the new weight, the net weight the game booked as
    absorbed (zero mean: negative for a survivor, its whole weight for a loser) and whether
    the photon goes on.  Above the threshold nothing happens (no random number is drawn).
    """
    if w < ROULETTE_THRESHOLD:
        if uniform(s) < 1.0 / ROULETTE_CHANCE:
            return w * ROULETTE_CHANCE, -w * (ROULETTE_CHANCE - 1.0), True
        return w, w, False
    return w, 0.0, True


@numba.njit(cache=True, inline="always")
def beyond_cutoff(dx, dy, z, cutoff_x, cutoff_y, cutoff_z):
    """Whether a photon has gone past the cutoff: ``|dx| > cutoff_x``, ``|dy| > cutoff_y`` or ``z > cutoff_z``
    (mm; ``inf`` for no limit).  Its weight is then booked as truncated."""
    return z > cutoff_z or abs(dx) > cutoff_x or abs(dy) > cutoff_y


@numba.njit(cache=True, inline="always")
def new_tallies(B, nk):
    """Zeroed per-batch tallies of a kernel: ``(refl_bins, rad_bins, refl, trans, absorbed, truncated, events)``.

    ``(B, nk)`` exiting power and normal-view radiance per offset bin, ``(B,)`` totals and collision counts.
    """
    return (
        np.zeros((B, nk)),
        np.zeros((B, nk)),
        np.zeros(B),
        np.zeros(B),
        np.zeros(B),
        np.zeros(B),
        np.zeros(B, dtype=np.int64),
    )


# ---------------------------------------------------------------- batches
def check_photons(n_photons, minimum: int = 1) -> int:
    """``n_photons`` as an int, at least ``minimum`` (InputError otherwise)."""
    n = int(n_photons)
    if n < minimum:
        raise InputError(f"n_photons must be >= {minimum}, got {n}")
    return n


def check_offsets(offsets_rows, *, consecutive: bool = False) -> np.ndarray:
    """Offset bins as int64: distinct integers (``consecutive``: increasing by 1); InputError otherwise."""
    off = np.asarray(offsets_rows)
    o = off.astype(np.int64).ravel()
    if consecutive:
        if o.size == 0 or np.any(o != off.ravel()) or np.any(np.diff(o) != 1):
            raise InputError("offsets_rows must be consecutive integers")
    elif o.size == 0 or np.any(o != off.ravel()) or np.unique(o).size != o.size:
        raise InputError("offsets_rows must be distinct integers")
    return o


def batch_counts(n_photons) -> np.ndarray:
    """Photons of each of the :data:`N_BATCHES` batches (the first ``n_photons % N_BATCHES`` one more)."""
    n_photons = int(n_photons)
    counts = np.full(N_BATCHES, n_photons // N_BATCHES, dtype=np.int64)
    counts[: n_photons % N_BATCHES] += 1
    return counts


def batch_states(seed) -> np.ndarray:
    """xoshiro256+ states of the batches, ``(N_BATCHES, 4)`` uint64, from ``SeedSequence(seed).spawn``."""
    return np.stack([s.generate_state(4, np.uint64) for s in np.random.SeedSequence(int(seed)).spawn(N_BATCHES)])


def batch_stats(per_batch, counts):
    """Mean per photon and its standard error from the spread of batch means."""
    n_total = counts.sum()
    mean = per_batch.sum(axis=0) / n_total
    used = counts > 0
    if used.sum() < 2:
        return mean, np.full(np.shape(mean), np.nan)
    means = per_batch[used] / counts[used].reshape((-1,) + (1,) * (per_batch.ndim - 1))
    return mean, means.std(axis=0, ddof=1) / np.sqrt(used.sum())
