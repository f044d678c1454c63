"""Monte Carlo photon transport in a homogeneous slab, compiled with Numba.

Photon packets are traced one by one inside a Numba kernel (the *MCML* scheme of
Wang, Jacques & Zheng [1]_: weights, implicit capture, Russian roulette), in 32
fixed batches run in parallel; each batch owns a xoshiro256+ stream seeded from
``numpy.random.SeedSequence(seed).spawn(32)``, so a result depends only on the
seed, never on the number of threads.  The medium (a :class:`planeray.medium.Medium`)
has absorption ``sigma_a`` and scattering ``sigma_s`` coefficients (mm^-1), a
Henyey-Greenstein phase function with anisotropy ``g``, a relative refractive
index ``n`` against the outside (same on both faces) and a thickness
``thickness_mm`` (``inf`` = semi-infinite).  Light enters
collimated at normal incidence, spread uniformly over ``|x| <= w / 2``
(``w = source_width_mm``; 0 is an ideal line) and infinitely long along ``y``:
binning exit points by ``x`` only integrates the point-source response along
the line -- the binned form of :func:`planeray.kernels.dipole_line_kernel`
(Jensen et al. [3]_), used by Kubo et al. (TVCG 2019, Sec. 5.2) with a
Henyey-Greenstein medium.  :func:`mc_point_profile` bins by the distance from
a single entry point instead (a pencil beam: MCML's ``R_d(r)``).

Scheme, per photon:

* free path ``s = -ln(xi) / sigma_t``;
* a step that would cross ``z = 0`` (top) or ``z = d`` (bottom) stops on the
  face; the unpolarized Fresnel fraction ``R(theta_i)`` of the weight is
  internally reflected (``R = 1`` beyond the critical angle) and the rest
  escapes -- tallied as diffuse reflectance at its exit ``x`` (top) or as
  transmittance (bottom).  The photon continues with a fresh free path (exact:
  the exponential is memoryless);
* otherwise it interacts: the *radiance estimator* books the light this
  collision sends straight up (below), ``(1 - albedo) w`` is absorbed, ``w`` is
  multiplied by the albedo and a new direction is drawn from the HG phase
  function (Prahl [2]_);
* Russian roulette below ``w < ROULETTE_THRESHOLD`` (survive with probability
  ``1 / ROULETTE_CHANCE`` at ``ROULETTE_CHANCE * w``); the net weight it creates
  or destroys (zero mean) is booked under ``absorbed``;
* **hybrid continuation** (semi-infinite media): a photon that reaches the depth
  ``z_c = diffusion_depth_mfp`` transport mean free paths (default 10) has
  forgotten its direction; where it leaves the surface is then given by
  diffusion theory (the 2-D dipole of a line source at ``z_c``,
  :func:`diffusion_exit`) instead of thousands more collisions -- the hybrid
  model of Wang & Jacques [6]_.  A non-absorbing half-space reflects everything
  eventually, but its photons make unbounded random walks (the 1-D return time
  has infinite mean): this is what makes ``sigma_a = 0`` affordable;
* a photon farther than ``cutoff_mm`` from the line (``|x|``, or depth ``z``
  when the continuation is off) is stopped and its weight booked as
  ``truncated``; the cutoff sits far outside the binned window by default
  (:func:`default_cutoff_mm`) and ``truncated`` says how much weight that was.

So ``diffuse + specular + transmitted + absorbed + truncated == 1`` to round-off.

Two profiles are tallied:

``values``
    power *exiting* the top face per bin (all directions): the exitance a
    camera with a Lambertian-like view of the surface would integrate;
``radiance``
    radiance leaving along the outward normal, averaged over the bin -- what an
    orthographic camera looking straight down measures.  It is a collision
    (next-event) estimator: a collision at depth ``z`` with weight ``w`` adds
    ``w a p_HG(-u_z) exp(-sigma_t z) (1 - R(0)) / n^2`` at its ``x``, ``a`` the
    albedo, ``R(0)`` the normal Fresnel reflectance and ``1/n^2`` the radiance
    change across the face; divided by the bin width it is in mm^-1 sr^-1 per
    unit line power.  It is the quantity Mitsuba renders (see
    :mod:`planeray.mc.mitsuba_ref`).

References
----------
.. [1] L. Wang, S. L. Jacques, L. Zheng, "MCML -- Monte Carlo modeling of light
   transport in multi-layered tissues", Comput. Methods Programs Biomed. 47,
   131-146, 1995.
.. [2] S. A. Prahl, M. Keijzer, S. L. Jacques, A. J. Welch, "A Monte Carlo model
   of light propagation in tissue", SPIE Institute Series IS 5, 102-111, 1989.
.. [3] H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan, "A practical model
   for subsurface light transport", SIGGRAPH 2001.
.. [4] D. Blackman, S. Vigna, "Scrambled linear pseudorandom number
   generators", ACM TOMS 47(4), 2021 (xoshiro256+).
.. [5] T. J. Farrell, M. S. Patterson, B. Wilson, "A diffusion theory model of
   spatially resolved, steady-state diffuse reflectance", Med. Phys. 19, 1992.
.. [6] L. Wang, S. L. Jacques, "Hybrid model of Monte Carlo simulation and
   diffusion theory for light reflectance by turbid media", J. Opt. Soc. Am. A
   10(8), 1746-1752, 1993.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..errors import InputError
from ..medium import Medium, as_medium
from ._batches import trace_batches
from .cache import cache_key, load_profile, save_profile, stored
from .diffusion import DIFFUSION_DEPTH_MFP, diffusion_exit, diffusion_normal_radiance_ratio
from .events import (
    ROULETTE_CHANCE,
    ROULETTE_THRESHOLD,
    batch_counts,
    batch_states,
    beyond_cutoff,
    check_offsets,
    check_photons,
    collide,
    free_path,
    fresnel_escape,
    launch,
    new_tallies,
    roulette,
    uniform,
)
from .physics import fresnel_jit, hg_pdf_jit
from .result import MCProfile, profile_from_tallies

__all__ = [
    "mc_line_profile",
    "mc_point_profile",
    "default_cutoff_mm",
    "bin_measure",
    "DIFFUSION_DEPTH_MFP",
    "ROULETTE_THRESHOLD",
    "ROULETTE_CHANCE",
]


# ---------------------------------------------------------------- the kernel
@numba.njit(cache=True, inline="always")
def _bin(x, y, inv_bin, radial):
    """Bin index of an exit point: by ``x`` (line source) or by radius (point source)."""
    if radial:
        return math.floor(math.sqrt(x * x + y * y) * inv_bin + 0.5)
    return math.floor(x * inv_bin + 0.5)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _trace(
    states,
    counts,
    sigma_s,
    sigma_a,
    g,
    n,
    d,
    kmin,
    nk,
    mm_per_row,
    w0,
    source_width_mm,
    cutoff_mm,
    z_cont,
    hmin,
    nh,
    radial,
):
    """Trace ``counts[b]`` photons for each batch ``b``; per-batch tallies.

    A photon whose step crosses depth ``z_cont`` stops there; its weight is
    tallied in ``cont_hist`` by the ``x`` of the crossing (bins ``hmin ..
    hmin + nh - 1``; ``cont_far`` beyond them) for the diffusion continuation.
    ``radial``: bin by the distance ``sqrt(x^2 + y^2)`` from the entry point (a
    point source) instead of by ``x`` (a line along ``y``).
    """
    B = counts.size
    cont_hist = np.zeros((B, nh))
    cont_far = np.zeros(B)
    refl_bins, rad_bins, refl, trans, absorbed, truncated, events = new_tallies(B, nk)
    sigma_t = sigma_s + sigma_a
    albedo = sigma_s / sigma_t
    finite = d < np.inf
    # Straight-up radiance: normal transmission and the n^2 radiance law at the face.
    up_gain = (1.0 - fresnel_jit(1.0, n)) / (n * n)
    inv_bin = 1.0 / mm_per_row
    cutoff_y = cutoff_mm if radial else np.inf  # a line source is infinitely long along y
    for b in range(B):
        s = states[b].copy()
        # Scalar accumulators per batch: writing neighbouring array slots from
        # several threads on every collision would thrash a shared cache line.
        refl_b = 0.0
        trans_b = 0.0
        abs_b = 0.0
        trunc_b = 0.0
        far_b = 0.0
        events_b = 0
        for _ in range(counts[b]):
            x, y, z, ux, uy, uz, w = launch((uniform(s) - 0.5) * source_width_mm, 0.0, w0)
            while True:
                step = free_path(s, sigma_t)
                zn = z + step * uz
                if zn > z_cont:
                    xc = x + (z_cont - z) / uz * ux
                    h = math.floor(xc * inv_bin + 0.5) - hmin
                    if 0 <= h < nh:
                        cont_hist[b, int(h)] += w
                    else:  # so far out that it cannot reach the bins: it still leaves
                        far_b += w
                    break
                if zn < 0.0 or (finite and zn > d):
                    top = zn < 0.0
                    zf = 0.0 if top else d
                    x += (zf - z) / uz * ux
                    y += (zf - z) / uz * uy
                    z = zf
                    esc, w = fresnel_escape(w, abs(uz), n)
                    if top:
                        refl_b += esc
                        k = _bin(x, y, inv_bin, radial) - kmin
                        if 0 <= k < nk:
                            refl_bins[b, int(k)] += esc
                    else:
                        trans_b += esc
                    uz = -uz
                    if w <= 0.0:
                        break
                else:
                    x += step * ux
                    y += step * uy
                    z = zn
                    events_b += 1
                    # Collision estimator of the radiance leaving straight up (-z inside).
                    tau = sigma_t * z
                    if tau < 40.0:
                        k = _bin(x, y, inv_bin, radial) - kmin
                        if 0 <= k < nk:
                            rad_bins[b, int(k)] += w * albedo * hg_pdf_jit(-uz, g) * math.exp(-tau) * up_gain
                    # Implicit capture, then a new direction: HG polar angle, uniform azimuth.
                    dabs, w, ux, uy, uz = collide(s, w, albedo, ux, uy, uz, g)
                    abs_b += dabs
                w, dabs, alive = roulette(s, w)
                abs_b += dabs
                if not alive:
                    break
                if beyond_cutoff(x, y, z, cutoff_mm, cutoff_y, cutoff_mm):
                    trunc_b += w
                    break
        refl[b] = refl_b
        trans[b] = trans_b
        absorbed[b] = abs_b
        truncated[b] = trunc_b
        cont_far[b] = far_b
        events[b] = events_b
    return refl_bins, rad_bins, refl, trans, absorbed, truncated, events, cont_hist, cont_far


# ---------------------------------------------------------------- public entry point
def bin_measure(bins, mm_per_bin, radial=False):
    """Size of profile bins: their width in mm (line source) or annulus area in mm^2 (point).

    Bin ``k`` covers ``[k - 1/2, k + 1/2) * mm_per_bin``; radial bin 0 is the disk of
    radius ``mm_per_bin / 2``.  Dividing a bin's power by it gives exitance per mm
    (line) or per mm^2 (point).
    """
    if not radial:
        return float(mm_per_bin)
    k = np.asarray(bins, dtype=np.float64)
    return np.pi * ((k + 0.5) ** 2 - np.maximum(k - 0.5, 0.0) ** 2) * float(mm_per_bin) ** 2


def default_cutoff_mm(medium: Medium, offsets_rows, *, mm_per_row) -> float:
    """Default photon cutoff: far outside both the binned window and the medium's scales.

    ``max(4 * window half-width, 20 / sigma_tr, 20 / sigma_t')`` with the
    transport coefficient ``sigma_t' = sigma_a + sigma_s (1 - g)`` and the
    effective attenuation ``sigma_tr = sqrt(3 sigma_a sigma_t')``.  A photon
    that far away re-emerges spread over a width of the order of its distance,
    so it adds at most ~1/4 of its weight (a non-absorbing medium) to the
    window and much less with absorption -- and :attr:`MCProfile.truncated`
    says how much weight that was.

    Parameters
    ----------
    medium : Medium
        The medium.
    offsets_rows : array_like of int
        The binned window (bins of ``mm_per_row``).
    mm_per_row : float
        Bin width in mm.

    Returns
    -------
    float
        The cutoff distance in mm.

    See Also
    --------
    planeray.mc_line_profile : uses it.

    Examples
    --------
    >>> import numpy as np
    >>> from planeray.medium import Medium
    >>> default_cutoff_mm(Medium(sigma_s=1.0, sigma_a=0.01, g=0.9), np.arange(-50, 51), mm_per_row=1.0) > 50
    True
    """
    medium = as_medium(medium)
    sigma_a = medium.sigma_a
    half = (np.max(np.abs(np.asarray(offsets_rows))) + 0.5) * float(mm_per_row)
    sigma_tp = sigma_a + medium.sigma_s_prime
    scales = [4.0 * half, 20.0 / sigma_tp]
    if sigma_a > 0:
        scales.append(20.0 / math.sqrt(3.0 * sigma_a * sigma_tp))
    return float(min(max(scales), 1e6))


def mc_line_profile(
    medium: Medium,
    *,
    n_photons=10**6,
    offsets_rows=None,
    mm_per_row=1.0,
    source_width_mm=0.0,
    diffusion_depth_mfp=DIFFUSION_DEPTH_MFP,
    cutoff_mm=None,
    seed=0,
    cache=False,
    progress=None,
) -> MCProfile:
    """Monte Carlo line-source reflectance profile of a homogeneous slab.

    Parameters
    ----------
    medium : Medium
        The slab: ``sigma_s``, ``sigma_a`` (mm^-1), HG ``g``, relative index ``n``
        against the outside (1 = index matched) and ``thickness_mm`` (``inf``:
        semi-infinite).
    n_photons : int
        Number of photon packets.
    offsets_rows : array_like of int, optional
        Distinct integer offset bins; default ``arange(-50, 51)``.
    mm_per_row : float
        Bin width in mm.
    source_width_mm : float
        Width of the lit strip (uniform over ``|x| <= w/2``); 0 = ideal line.
    diffusion_depth_mfp : float or None
        Semi-infinite media only: a photon reaching this depth, in transport mean
        free paths ``1 / (sigma_a + sigma_s (1 - g))``, is handed to diffusion
        theory (:func:`diffusion_exit`; the hybrid model of Wang & Jacques [6]_)
        instead of being traced on.  ``None`` or 0 traces every photon to the end.
    cutoff_mm : float, optional
        Stop photons farther than this from the line (``|x|``) or deeper (``z``);
        default :func:`default_cutoff_mm`.  Their weight is reported as ``truncated``.
    seed : int
        Seed; same seed, same bytes, whatever the number of threads.
    cache : bool
        Read/write an ``.npz`` result keyed by the medium and every option under
        :func:`cache_dir` (after the read-only shipped tables, :data:`TABLES_DIR`).
    progress : callable, optional
        Called as ``progress(n)`` with the number of photons just traced, after
        each group of batches (one batch per Numba thread; once with
        ``n_photons`` on a cache hit), so the calls add up to ``n_photons``.
        Tracing in groups gives the same bytes as without a callback.

    Returns
    -------
    MCProfile
        Binned exiting power (``values``) and normal-view radiance (``radiance``)
        of a line source along ``y`` lit at ``x = 0``, with batch standard errors
        and the energy balance.

    See Also
    --------
    planeray.line_kernel : the tabulated kernel for a scene.
    planeray.Medium : the optical constants.

    Notes
    -----
    See the module docstring for the transport scheme (MCML [1]_, HG sampling
    [2]_) and the radiance estimator.  Compare with
    :func:`planeray.kernels.dipole_line_kernel` on the same medium (which uses
    ``sigma_s' = sigma_s (1 - g)`` and ``n``) [3]_.

    Examples
    --------
    >>> from planeray.medium import Medium
    >>> p = mc_line_profile(Medium(sigma_s=1.0, sigma_a=0.1, g=0.9), n_photons=20_000)
    >>> abs(p.energy_balance - 1.0) < 1e-9
    True
    """
    if offsets_rows is None:
        offsets_rows = np.arange(-50, 51)
    return _profile(
        "line",
        as_medium(medium),
        n_photons,
        offsets_rows,
        mm_per_row,
        seed,
        cache,
        source_width_mm,
        cutoff_mm,
        diffusion_depth_mfp,
        progress,
    )


def mc_point_profile(
    medium: Medium,
    *,
    n_photons=10**6,
    radius_bins=None,
    mm_per_bin=1.0,
    cutoff_mm=None,
    seed=0,
    cache=False,
    progress=None,
) -> MCProfile:
    """Monte Carlo radial reflectance of a *point* (pencil-beam) source: MCML's ``R_d(r)``.

    Same engine and checks as :func:`mc_line_profile`, with the exit points binned
    by their distance ``r`` from the entry point: bin ``k`` is the annulus
    ``[(k - 1/2), (k + 1/2)) * mm_per_bin`` (bin 0 the disk of radius
    ``mm_per_bin / 2``).  Every photon is traced (no diffusion hand-off), so a
    non-absorbing medium relies on ``cutoff_mm``.

    Parameters
    ----------
    medium : Medium
        The slab, as in :func:`mc_line_profile`.
    radius_bins : array_like of int, optional
        Distinct non-negative bins; default ``arange(0, 51)``.
    mm_per_bin : float
        Annulus width in mm.
    n_photons, cutoff_mm, seed, cache, progress
        As :func:`mc_line_profile`.

    Returns
    -------
    MCProfile
        ``offsets_rows`` holds the radial bins and ``mm_per_row`` the annulus
        width; ``values`` is the power leaving through each annulus (divide by
        its area for ``R_d(r)`` per mm^2, compare with
        :func:`planeray.kernels.dipole_reflectance`), ``radiance`` the
        normal-view radiance averaged over it (mm^-2 sr^-1 per unit power).

    See Also
    --------
    planeray.mc_line_profile : a lit line.
    planeray.kernels.dipole_reflectance : the diffusion dipole's ``R_d(r)``.

    Examples
    --------
    >>> from planeray.medium import Medium
    >>> p = mc_point_profile(Medium(sigma_s=1.0, sigma_a=0.1, g=0.9), n_photons=5_000)
    >>> abs(p.energy_balance - 1.0) < 1e-9
    True
    """
    medium = as_medium(medium)
    if radius_bins is None:
        radius_bins = np.arange(0, 51)
    if np.any(np.asarray(radius_bins) < 0):
        raise InputError("radius_bins must be non-negative")
    return _profile("point", medium, n_photons, radius_bins, mm_per_bin, seed, cache, 0.0, cutoff_mm, None, progress)


def _profile(
    source,
    medium,
    n_photons,
    offsets_rows,
    mm_per_row,
    seed,
    cache,
    source_width_mm,
    cutoff_mm,
    diffusion_depth_mfp,
    progress=None,
):
    """Validate, look up the caches, trace (:func:`_run`), store."""
    n_photons = check_photons(n_photons)
    mm_per_row = check_mm_per_row(mm_per_row)
    source_width_mm = float(source_width_mm)
    if not source_width_mm >= 0:
        raise InputError(f"source_width_mm must be >= 0, got {source_width_mm}")
    offsets = check_offsets(offsets_rows)
    cutoff_mm = check_cutoff(medium, offsets, mm_per_row, cutoff_mm)
    depth_mfp = check_depth_mfp(diffusion_depth_mfp)
    # The cache key (and MCProfile.params): these keys, values and order are what the
    # shipped tables were hashed with -- keep them as they are.
    params = dict(
        **run_params(medium, n_photons, mm_per_row, seed),
        source_width_mm=source_width_mm,
        cutoff_mm=cutoff_mm,
        diffusion_depth_mfp=depth_mfp,
    )
    if source == "point":
        params["source"] = "point"  # line-source keys stay as they were: shipped tables remain valid

    def build():
        return _run(
            medium,
            n_photons,
            offsets,
            mm_per_row,
            int(seed),
            source_width_mm,
            cutoff_mm,
            params,
            radial=source == "point",
            progress=progress,
        )

    return stored(
        f"{cache_key(params, offsets)}.npz",
        load=load_profile,
        build=build,
        save=save_profile,
        cache=cache,
        on_hit=None if progress is None else (lambda: progress(n_photons)),
    )


def run_params(medium, n_photons, mm_per_row, seed) -> dict:
    """The parameters every slab and wall run's cache key starts with: the medium, photons, bins and seed."""
    return dict(
        sigma_s=medium.sigma_s,
        sigma_a=medium.sigma_a,
        g=medium.g,
        n=medium.n,
        thickness=None if medium.semi_infinite else medium.thickness_mm,
        n_photons=n_photons,
        mm_per_row=mm_per_row,
        seed=int(seed),
    )


def check_mm_per_row(mm_per_row) -> float:
    """``mm_per_row`` as a positive float (InputError otherwise)."""
    mm = float(mm_per_row)
    if not mm > 0:
        raise InputError(f"mm_per_row must be positive, got {mm}")
    return mm


def check_cutoff(medium, offsets, mm_per_row, cutoff_mm) -> float:
    """The photon cutoff: ``cutoff_mm``, or :func:`default_cutoff_mm`; positive (InputError otherwise)."""
    if cutoff_mm is None:
        cutoff_mm = default_cutoff_mm(medium, offsets, mm_per_row=mm_per_row)
    cutoff_mm = float(cutoff_mm)
    if not cutoff_mm > 0:
        raise InputError(f"cutoff_mm must be positive, got {cutoff_mm}")
    return cutoff_mm


def check_depth_mfp(diffusion_depth_mfp) -> float | None:
    """The hand-off depth in transport mean free paths: positive, or None (no hand-off)."""
    depth_mfp = float(diffusion_depth_mfp) if diffusion_depth_mfp else None
    if depth_mfp is not None and not depth_mfp > 0:
        raise InputError(f"diffusion_depth_mfp must be positive or None, got {diffusion_depth_mfp}")
    return depth_mfp


def _run(medium, n_photons, offsets, mm_per_row, seed, source_width_mm, cutoff_mm, params, radial=False, progress=None):
    sigma_s, sigma_a, g, n, d = medium.sigma_s, medium.sigma_a, medium.g, medium.n, medium.thickness_mm
    counts = batch_counts(n_photons)
    states = batch_states(seed)
    kmin = int(offsets.min())
    nk = int(offsets.max()) - kmin + 1
    r_sp = ((n - 1.0) / (n + 1.0)) ** 2
    depth_mfp = params["diffusion_depth_mfp"]
    sigma_tp = sigma_a + medium.sigma_s_prime
    z_cont = depth_mfp / sigma_tp if (depth_mfp and not np.isfinite(d) and not radial) else np.inf
    # Continued photons are histogrammed where they can still reach the bins: within
    # 20 continuation depths of the window (the exit law's tail beyond carries < 1 %
    # of a photon's weight into a window of that size).
    half = max(abs(kmin), abs(kmin + nk - 1)) * mm_per_row
    reach = int(np.ceil(min(cutoff_mm, half + 20.0 * z_cont) / mm_per_row)) if np.isfinite(z_cont) else 0
    hmin, nh = -reach, 2 * reach + 1
    # Batches are independent (own stream, own tallies): traced on threads, concatenated in batch order.
    tallies = trace_batches(
        _trace,
        (states, counts),
        (
            sigma_s,
            sigma_a,
            g,
            n,
            d,
            kmin,
            nk,
            mm_per_row,
            1.0 - r_sp,
            source_width_mm,
            cutoff_mm,
            z_cont,
            hmin,
            nh,
            radial,
        ),
        progress=progress,
    )
    refl_bins, rad_bins, refl, trans, absorbed, truncated, events, cont, far = tallies
    # Radiance is tallied per unit area: divide by the bin's width (line) or annulus area (point).
    rad_bins /= bin_measure(np.arange(kmin, kmin + nk), mm_per_row, radial)
    if np.isfinite(z_cont) and (cont.any() or far.any()):
        exit_bins, exit_total = diffusion_exit(
            cont, hmin, np.arange(kmin, kmin + nk), mm_per_row, z_cont, sigma_a, sigma_tp, n
        )
        w_cont = cont.sum(axis=1) + far
        refl_bins += exit_bins
        rad_bins += exit_bins * (diffusion_normal_radiance_ratio(n) / mm_per_row)
        refl += w_cont * exit_total
        absorbed += w_cont * (1.0 - exit_total)
    return profile_from_tallies(
        offsets_rows=offsets,
        first_bin=kmin,
        mm_per_row=mm_per_row,
        counts=counts,
        refl_bins=refl_bins,
        rad_bins=rad_bins,
        refl=refl,
        trans=trans,
        absorbed=absorbed,
        truncated=truncated,
        events=events,
        specular_reflectance=r_sp,
        params=params,
    )
