"""Vectorized Monte Carlo photon transport in a homogeneous slab.

All photons of a run are advanced together in NumPy arrays (the *MCML* scheme of
Wang, Jacques & Zheng [1]_ with weights, implicit capture and Russian roulette,
vectorized over photons instead of looping over them).  The medium has
absorption ``sigma_a`` and scattering ``sigma_s`` coefficients (mm^-1), a
Henyey-Greenstein phase function with anisotropy ``g``, a relative refractive
index ``n`` against the outside (same on both faces) and a thickness (``inf`` =
semi-infinite).  Light enters at normal incidence at the origin; the exit
points of reflected light are binned by their ``x`` coordinate only, which is
the profile of a *line* source along ``y`` (integrating the point-source
profile along the line) -- the binned form of :func:`planeray.kernels.dipole_line_kernel`
(Jensen et al. [3]_), used by Kubo et al. (TVCG 2019, Sec. 5.2) with a
Henyey-Greenstein medium.

Scheme, per iteration over the photons still alive:

* free path ``s = -ln(xi) / sigma_t``;
* a photon whose step would cross ``z = 0`` (top) or ``z = d`` (bottom) is
  moved to the face; the unpolarized Fresnel fraction ``R(theta_i)`` of its
  weight is internally reflected (``R = 1`` beyond the critical angle) and the
  rest escapes -- tallied as diffuse reflectance at its exit ``x`` (top) or as
  transmittance (bottom).  This is MCML's *partial reflection* option; the
  photon continues with a fresh free path (exact, the exponential being
  memoryless);
* otherwise it interacts: ``(1 - albedo) w`` is deposited as absorbed, ``w``
  is multiplied by the albedo (implicit capture) and the direction is resampled
  from the Henyey-Greenstein phase function (Prahl [2]_) and rotated into the
  photon's frame;
* Russian roulette below ``w < ROULETTE_THRESHOLD``: survive with probability
  ``1 / ROULETTE_CHANCE`` at weight ``ROULETTE_CHANCE * w``.  The net weight
  created or destroyed by roulette (zero in expectation) is booked under
  ``absorbed``, so ``diffuse + specular + transmitted + absorbed == 1`` holds to
  round-off for every run.

At entry the specular fraction ``((n - 1) / (n + 1))^2`` is reflected and counted
as ``specular_reflectance``; the remainder enters with weight ``1 - R_sp``.

References
----------
.. [1] L. Wang, S. L. Jacques, L. Zheng, "MCML -- Monte Carlo modeling of light
   transport in multi-layered tissues", Comput. Methods Programs Biomed. 47,
   131-146, 1995.
.. [2] S. A. Prahl, M. Keijzer, S. L. Jacques, A. J. Welch, "A Monte Carlo model
   of light propagation in tissue", SPIE Institute Series IS 5, 102-111, 1989.
.. [3] H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan, "A practical model
   for subsurface light transport", SIGGRAPH 2001.
"""

from __future__ import annotations

import hashlib
import json
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "MCProfile",
    "mc_line_profile",
    "fresnel_unpolarized",
    "sample_hg_cos",
    "cache_dir",
    "ROULETTE_THRESHOLD",
    "ROULETTE_CHANCE",
]

ROULETTE_THRESHOLD = 1e-4
ROULETTE_CHANCE = 10.0
_ENGINE_VERSION = 1
_N_BATCHES = 32
_N_CHUNKS = 4


@dataclass(frozen=True)
class MCProfile:
    """Result of :func:`mc_line_profile`. All quantities are fractions of the incident power.

    Attributes
    ----------
    offsets_rows : ndarray of int64
        Offset bins ``k``; bin ``k`` covers exit ``x`` in ``[k - 1/2, k + 1/2) * mm_per_row``.
    mm_per_row : float
        Bin width in mm.
    values : ndarray of float64
        Diffusely reflected power exiting the top face in each bin (line-source
        profile); sums to ``total_reflectance`` when the bins cover the profile.
    stderr : ndarray of float64
        Standard error of ``values`` from the spread of 32 independent photon batches.
    total_reflectance : float
        Diffuse reflectance (all exit positions, binned or not; excludes specular).
    total_reflectance_stderr : float
        Its batch standard error.
    specular_reflectance : float
        Fresnel reflection at entry, ``((n - 1) / (n + 1))^2``.
    transmittance : float
        Power leaving through the bottom face (0 for a semi-infinite medium).
    absorbed : float
        Absorbed power (including the zero-mean net weight of Russian roulette).
    n_photons : int
        Number of photon packets traced.
    params : dict
        The parameters of the run.
    """

    offsets_rows: np.ndarray
    mm_per_row: float
    values: np.ndarray
    stderr: np.ndarray
    total_reflectance: float
    total_reflectance_stderr: float
    specular_reflectance: float
    transmittance: float
    absorbed: float
    n_photons: int
    params: dict = field(default_factory=dict)

    @property
    def energy_balance(self) -> float:
        """``diffuse + specular + transmitted + absorbed`` (1 up to round-off)."""
        return (self.total_reflectance + self.specular_reflectance
                + self.transmittance + self.absorbed)


def fresnel_unpolarized(cos_i, n):
    """Unpolarized Fresnel reflectance for light inside a medium of index ``n`` hitting
    a face to index 1 at incidence cosine ``cos_i``; 1 beyond the critical angle.

    Parameters
    ----------
    cos_i : array_like
        Cosine of the incidence angle, in ``[0, 1]``.
    n : float
        Relative refractive index (inside / outside).

    Returns
    -------
    ndarray of float64
        Reflectance ``(r_s^2 + r_p^2) / 2``.
    """
    cos_i = np.clip(np.asarray(cos_i, dtype=np.float64), 0.0, 1.0)
    if n == 1.0:
        return np.zeros_like(cos_i)
    sin_t2 = n * n * (1.0 - cos_i * cos_i)
    tir = sin_t2 >= 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin_t2, 0.0))
    rs = (n * cos_i - cos_t) / (n * cos_i + cos_t)
    rp = (cos_i - n * cos_t) / (cos_i + n * cos_t)
    R = 0.5 * (rs * rs + rp * rp)
    return np.where(tir, 1.0, R)


def sample_hg_cos(xi, g):
    """Sample the cosine of the Henyey-Greenstein scattering angle (Prahl 1989 [2]_).

    ``cos = (1 + g^2 - ((1 - g^2) / (1 - g + 2 g xi))^2) / (2 g)``, and
    ``cos = 2 xi - 1`` for ``g = 0`` (isotropic).

    Parameters
    ----------
    xi : ndarray
        Uniform variates in ``[0, 1)``.
    g : float
        Anisotropy, ``-1 < g < 1``.
    """
    if abs(g) < 1e-6:
        return 2.0 * xi - 1.0
    t = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi)
    return np.clip((1.0 + g * g - t * t) / (2.0 * g), -1.0, 1.0)


def _scatter(ux, uy, uz, cos_t, phi):
    """Rotate directions by polar ``cos_t`` and azimuth ``phi`` about themselves (MCML [1]_)."""
    sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
    cp = np.cos(phi)
    sp = np.sin(phi)
    den2 = 1.0 - uz * uz
    near_pole = den2 < 1e-10
    den = np.sqrt(np.where(near_pole, 1.0, den2))
    a = sin_t / den
    nux = a * (ux * uz * cp - uy * sp) + ux * cos_t
    nuy = a * (uy * uz * cp + ux * sp) + uy * cos_t
    nuz = -sin_t * cp * den + uz * cos_t
    if near_pole.any():
        sgn = np.where(uz >= 0.0, 1.0, -1.0)
        nux = np.where(near_pole, sin_t * cp, nux)
        nuy = np.where(near_pole, sin_t * sp, nuy)
        nuz = np.where(near_pole, sgn * cos_t, nuz)
    # Renormalize against drift over thousands of rotations.
    norm = 1.0 / np.sqrt(nux * nux + nuy * nuy + nuz * nuz)
    return nux * norm, nuy * norm, nuz * norm


def cache_dir() -> Path:
    """Cache folder: ``$PLANERAY_CACHE/mc`` if set, else ``~/.cache/planeray/mc``."""
    root = os.environ.get("PLANERAY_CACHE")
    base = Path(root) if root else Path.home() / ".cache" / "planeray"
    return base / "mc"


def _cache_key(params: dict, offsets: np.ndarray) -> str:
    blob = json.dumps({"v": _ENGINE_VERSION, **params}, sort_keys=True)
    h = hashlib.sha256(blob.encode())
    h.update(np.ascontiguousarray(offsets, dtype=np.int64).tobytes())
    return h.hexdigest()[:32]


_SCALARS = ("mm_per_row", "total_reflectance", "total_reflectance_stderr",
            "specular_reflectance", "transmittance", "absorbed")


def _save(path: Path, prof: MCProfile) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + f".{os.getpid()}.tmp.npz")
    np.savez(tmp, offsets_rows=prof.offsets_rows, values=prof.values, stderr=prof.stderr,
             n_photons=np.int64(prof.n_photons),
             params=np.array(json.dumps(prof.params, sort_keys=True)),
             **{k: np.float64(getattr(prof, k)) for k in _SCALARS})
    os.replace(tmp, path)


def _load(path: Path) -> MCProfile:
    with np.load(path, allow_pickle=False) as z:
        return MCProfile(
            offsets_rows=z["offsets_rows"], values=z["values"], stderr=z["stderr"],
            n_photons=int(z["n_photons"]), params=json.loads(str(z["params"])),
            **{k: float(z[k]) for k in _SCALARS})


def mc_line_profile(sigma_s, sigma_a, g, n=1.0, thickness=np.inf, n_photons=10**6,
                    offsets_rows=None, mm_per_row=1.0, seed=0, cache=False):
    """Monte Carlo line-source reflectance profile of a homogeneous slab.

    Parameters
    ----------
    sigma_s, sigma_a : float
        Scattering and absorption coefficients, mm^-1 (``sigma_s + sigma_a > 0``).
    g : float
        Henyey-Greenstein anisotropy, ``-1 < g < 1``.
    n : float
        Relative refractive index of the medium against the outside (1 = index matched).
    thickness : float
        Slab thickness in mm; ``inf`` for a semi-infinite medium.
    n_photons : int
        Number of photon packets.
    offsets_rows : array_like of int, optional
        Distinct integer offset bins; default ``arange(-50, 51)``.
    mm_per_row : float
        Bin width in mm.
    seed : int
        Seed of the ``numpy.random.Generator`` (PCG64); same seed, same bytes.
    cache : bool
        Read/write an ``.npz`` result keyed by all parameters under :func:`cache_dir`.

    Returns
    -------
    MCProfile
        Binned diffuse reflectance of a line source along ``y`` lit at ``x = 0``
        (fractions of incident power per bin), with batch standard errors and the
        energy balance.

    Notes
    -----
    See the module docstring for the transport scheme (MCML [1]_, HG sampling [2]_).
    Compare with :func:`planeray.kernels.dipole_line_kernel` using
    ``sigma_s_prime = sigma_s * (1 - g)`` and ``eta = n`` [3]_.
    """
    sigma_s = float(sigma_s)
    sigma_a = float(sigma_a)
    g = float(g)
    n = float(n)
    thickness = float(thickness)
    n_photons = int(n_photons)
    mm_per_row = float(mm_per_row)
    if sigma_s < 0 or sigma_a < 0 or sigma_s + sigma_a <= 0:
        raise ValueError("need sigma_s, sigma_a >= 0 and sigma_s + sigma_a > 0")
    if not -1.0 < g < 1.0:
        raise ValueError("g must lie in (-1, 1)")
    if not n > 0:
        raise ValueError("n must be positive")
    if not thickness > 0:
        raise ValueError("thickness must be positive")
    if n_photons < 1:
        raise ValueError("n_photons must be >= 1")
    if not mm_per_row > 0:
        raise ValueError("mm_per_row must be positive")
    if offsets_rows is None:
        offsets_rows = np.arange(-50, 51)
    offsets_f = np.asarray(offsets_rows)
    offsets = offsets_f.astype(np.int64).ravel()
    if offsets.size == 0 or np.any(offsets != offsets_f.ravel()) or np.unique(offsets).size != offsets.size:
        raise ValueError("offsets_rows must be distinct integers")

    params = dict(sigma_s=sigma_s, sigma_a=sigma_a, g=g, n=n,
                  thickness=None if np.isinf(thickness) else thickness,
                  n_photons=n_photons, mm_per_row=mm_per_row, seed=int(seed))
    path = None
    if cache:
        path = cache_dir() / f"{_cache_key(params, offsets)}.npz"
        if path.exists():
            try:
                return _load(path)
            except (OSError, ValueError, KeyError):
                pass

    prof = _run(sigma_s, sigma_a, g, n, thickness, n_photons, offsets, mm_per_row, int(seed))
    prof = MCProfile(**{**prof.__dict__, "params": params})
    if path is not None:
        _save(path, prof)
    return prof


def _run(sigma_s, sigma_a, g, n, d, n_photons, offsets, mm_per_row, seed):
    B = min(_N_BATCHES, n_photons)
    kmin, kmax = int(offsets.min()), int(offsets.max())
    lut = np.full(kmax - kmin + 1, -1, dtype=np.int64)
    lut[offsets - kmin] = np.arange(offsets.size)
    nb = offsets.size
    r_sp = ((n - 1.0) / (n + 1.0)) ** 2

    # Fixed split into chunks, each with its own spawned stream: results do not
    # depend on how many threads run them (summed in chunk order).
    n_chunks = max(1, min(_N_CHUNKS, n_photons // 25000))
    bounds = np.linspace(0, n_photons, n_chunks + 1).astype(np.int64)
    seeds = np.random.SeedSequence(seed).spawn(n_chunks)
    jobs = [(np.arange(bounds[i], bounds[i + 1]) % B, seeds[i]) for i in range(n_chunks)]

    def work(job):
        return _trace(job[0], np.random.Generator(np.random.PCG64(job[1])), sigma_s, sigma_a,
                      g, n, d, B, nb, kmin, kmax, lut, mm_per_row, 1.0 - r_sp)

    workers = min(n_chunks, os.cpu_count() or 1)
    if workers > 1:
        with ThreadPoolExecutor(max_workers=workers) as ex:
            parts = list(ex.map(work, jobs))
    else:
        parts = [work(j) for j in jobs]
    refl_bins = np.zeros(B * nb)
    refl_batch = np.zeros(B)
    trans_batch = np.zeros(B)
    absorbed = 0.0
    for rb, rt, tb, ab in parts:
        refl_bins += rb
        refl_batch += rt
        trans_batch += tb
        absorbed += ab

    counts = np.bincount(np.arange(n_photons) % B, minlength=B).astype(np.float64)
    bins_b = refl_bins.reshape(B, nb)
    values = bins_b.sum(axis=0) / n_photons
    R_tot = float(refl_batch.sum() / n_photons)
    if B > 1:
        per_b = bins_b / counts[:, None]
        stderr = per_b.std(axis=0, ddof=1) / np.sqrt(B)
        r_err = float((refl_batch / counts).std(ddof=1) / np.sqrt(B))
    else:
        stderr = np.full(nb, np.nan)
        r_err = float("nan")
    return MCProfile(
        offsets_rows=offsets.copy(), mm_per_row=mm_per_row, values=values, stderr=stderr,
        total_reflectance=R_tot, total_reflectance_stderr=r_err,
        specular_reflectance=float(r_sp), transmittance=float(trans_batch.sum() / n_photons),
        absorbed=absorbed / n_photons, n_photons=n_photons)


def _trace(batch, rng, sigma_s, sigma_a, g, n, d, B, nb, kmin, kmax, lut, mm_per_row, w0):
    """Trace one chunk of photons to extinction; returns the tallies."""
    sigma_t = sigma_s + sigma_a
    albedo = sigma_s / sigma_t
    finite = np.isfinite(d)
    m0 = batch.size
    refl_bins = np.zeros(B * nb)
    refl_batch = np.zeros(B)
    trans_batch = np.zeros(B)
    absorbed = 0.0
    x = np.zeros(m0)
    y = np.zeros(m0)
    z = np.zeros(m0)
    ux = np.zeros(m0)
    uy = np.zeros(m0)
    uz = np.ones(m0)
    w = np.full(m0, w0)
    while x.size:
        m = x.size
        s = -np.log1p(-rng.random(m)) / sigma_t  # 1 - xi in (0, 1]
        zn = z + s * uz
        hit = zn < 0.0
        if finite:
            hit |= zn > d
        hh = np.flatnonzero(hit)
        # Boundary hits: position on the face, from the pre-step state.
        if hh.size:
            uzh = uz[hh]
            zface = np.where(zn[hh] < 0.0, 0.0, d)
            t = (zface - z[hh]) / uzh
            xh = x[hh] + t * ux[hh]
            yh = y[hh] + t * uy[hh]
            uxh = ux[hh]
            uyh = uy[hh]
            wh = w[hh]
        # Interactions, computed for everyone (cheaper than gathering), hits restored after.
        x += s * ux
        y += s * uy
        z = zn
        absorbed += float(np.sum(w)) * (1.0 - albedo)
        w *= albedo
        cos_t = sample_hg_cos(rng.random(m), g)
        phi = (2.0 * np.pi) * rng.random(m)
        ux, uy, uz = _scatter(ux, uy, uz, cos_t, phi)
        if hh.size:
            absorbed -= float(np.sum(wh)) * (1.0 - albedo)
            R = fresnel_unpolarized(np.abs(uzh), n)
            esc = wh * (1.0 - R)
            x[hh] = xh
            y[hh] = yh
            z[hh] = zface
            ux[hh] = uxh
            uy[hh] = uyh
            uz[hh] = -uzh
            w[hh] = wh * R
            bh = batch[hh]
            th = zface == 0.0
            if th.any():
                et = esc[th]
                bt = bh[th]
                refl_batch += np.bincount(bt, weights=et, minlength=B)
                k = np.floor(xh[th] / mm_per_row + 0.5)
                inr = (k >= kmin) & (k <= kmax)
                col = np.full(k.shape, -1, dtype=np.int64)
                col[inr] = lut[k[inr].astype(np.int64) - kmin]
                ok = col >= 0
                if ok.any():
                    refl_bins += np.bincount(bt[ok] * nb + col[ok], weights=et[ok],
                                             minlength=B * nb)
            if finite and not th.all():
                trans_batch += np.bincount(bh[~th], weights=esc[~th], minlength=B)

        # Russian roulette
        li = np.flatnonzero(w < ROULETTE_THRESHOLD)
        if li.size:
            wl = w[li]
            survive = rng.random(li.size) < 1.0 / ROULETTE_CHANCE
            new = np.where(survive, wl * ROULETTE_CHANCE, 0.0)
            absorbed += float(np.sum(wl) - np.sum(new))  # net roulette weight (zero mean)
            w[li] = new
            alive = w > 0.0
            x, y, z, ux, uy, uz, w, batch = (a[alive] for a in (x, y, z, ux, uy, uz, w, batch))
    return refl_bins, refl_batch, trans_batch, absorbed
