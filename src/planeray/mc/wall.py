"""Monte Carlo line kernels beside a container wall (Sec. 8: pixels near the edge of a container).

A container of a scattering liquid seen from above is a half-space ``z > 0`` cut by its
vertical walls.  Far from a wall a pixel sees the slab's line kernel
(:func:`planeray.mc.mc_line_profile`); near one, light that reaches the wall is lost
through it (a black wall, or the part a clear wall transmits) or reflected back, and
the kernel changes on the wall's side -- the paper's explanation of its only
recognition errors ("pixels near the edge of the container, where the scattering
profile changes ... due to the asymmetry of a boundary condition").  This module traces
that geometry with the engine's scheme (:mod:`planeray.mc.engine`: MCML weights,
Henyey-Greenstein scattering, Fresnel top face, 32 seeded xoshiro256+ batches).

Geometry
--------
A **pencil beam** enters at normal incidence at the origin of the top face.  The wall
is the vertical plane ``x cos(phi) + y sin(phi) = a``: ``a`` (``wall_distance_mm``) is
the distance from the entry point to the wall, ``phi`` (``wall_angle_deg``) the angle
between the wall's normal and the ``x`` axis, ``x`` being the offset axis across the
projector's lines (camera rows) and ``y`` the direction along them.  ``phi = 0``: the
wall runs parallel to the lit lines (the top or bottom side of a tray, seen by the
camera), on the side of positive offsets; ``phi = 90``: the wall is perpendicular to
them (a left or right side).  Exits are binned by ``x`` and integrated over ``y``.

Why a pencil beam at the pixel: the scene needs ``T(pixel, line)``, the light a pixel
at distance ``a`` from the wall receives when the projector lights the line at offset
``u``.  By the reciprocity of radiative transfer with Fresnel boundaries (normal
incidence in, radiance along the normal out, the same on both ends), the light that
enters at the pixel and leaves along the whole line equals the light that enters along
the line and leaves at the pixel: the binned **normal-view radiance** of this run *is*
the pixel's line kernel, for every offset at once.  Without a wall it is the slab's
line kernel (the line integral of a pencil beam's response, by translation invariance).
``tests/test_mc_wall.py`` checks both: the reciprocity (a wall parallel to the lines,
source and pixel exchanged) and the far-wall limit, bin by bin against
:func:`planeray.mc.mc_line_profile`.

The wall
--------
``wall="fresnel"``: a thin clear wall (glass, plastic) with air behind it; a photon
reaching it is reflected with the unpolarized Fresnel reflectance of the medium against
air (index ``n``) and otherwise leaves (booked as ``wall_loss``), like at the top face.
``wall="absorbing"``: a black wall; every photon reaching it is lost.  The wall is
vertical and infinitely deep, and the top face is flat up to it (no meniscus, no rim).

Hybrid continuation with a wall
-------------------------------
As in the engine, a photon that reaches ``diffusion_depth_mfp`` transport mean free
paths in a half-space is handed to diffusion theory (Wang & Jacques [1]_).  With a
wall the exit law is the diffusion solution of the *quarter* space: the point source
at the crossing depth ``z_c`` and its image above the extrapolated top boundary (the
engine's dipole, Farrell et al. [2]_), plus the mirror images of both across the wall's
extrapolated boundary ``z_bw = 2 A D`` behind the wall (``A`` of the wall's index; 1
for a black wall), with opposite sign -- the method of images of Haskell et al. [3]_
for a second boundary.  Its flux through the top face, binned by ``x`` over the inside
of the wall, is where the photon leaves; its flux through the wall plane is lost; the
rest is absorbed.  Without absorption the two fluxes add up to 1 (nothing is lost in
the model; a test checks it).  Crossing points are histogrammed by ``x`` and by their
distance to the wall (``phi > 0``; for ``phi = 0`` the distance follows from ``x``).

So ``diffuse + specular + transmitted + absorbed + truncated + wall_loss == 1``.

References
----------
.. [1] L. Wang, S. L. Jacques, "Hybrid model of Monte Carlo simulation and diffusion
   theory for light reflectance by turbid media", JOSA A 10(8), 1746-1752, 1993.
.. [2] T. J. Farrell, M. S. Patterson, B. Wilson, "A diffusion theory model of spatially
   resolved, steady-state diffuse reflectance", Med. Phys. 19, 879-888, 1992.
.. [3] R. C. Haskell, L. O. Svaasand, T.-T. Tsay, T.-C. Feng, M. S. McAdams, B. J.
   Tromberg, "Boundary conditions for the diffusion equation in radiative transfer",
   JOSA A 11(10), 2727-2741, 1994.
.. [4] L. Wang, S. L. Jacques, L. Zheng, "MCML -- Monte Carlo modeling of light transport
   in multi-layered tissues", Comput. Methods Programs Biomed. 47, 131-146, 1995.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..errors import InputError
from ..medium import Medium, as_medium
from ._batches import trace_batches
from .cache import cache_key, load_profile, save_profile, stored
from .diffusion import (
    DIFFUSION_DEPTH_MFP,
    diffusion_exit,
    diffusion_normal_radiance_ratio,
    exits_oblique,
    exits_parallel,
    quarter_space,
)
from .engine import check_cutoff, check_depth_mfp, check_mm_per_row, default_cutoff_mm, run_params
from .events import (
    N_BATCHES,
    batch_counts,
    beyond_cutoff,
    check_offsets,
    check_photons,
    collide,
    free_path,
    fresnel_escape,
    launch,
    new_tallies,
    roulette,
)
from .physics import fresnel_jit, hg_pdf_jit
from .result import MCProfile, profile_from_tallies

__all__ = [
    "WALL_MODELS",
    "WALL_VERSION",
    "mc_wall_profile",
    "wall_exit_fractions",
    "check_wall_model",
    "wall_run_params",
    "trace_wall_run",
]

#: Wall models: a clear wall with air behind it (Fresnel), or a black one.
WALL_MODELS = ("fresnel", "absorbing")
#: Bumped whenever the wall runs' results change (part of every wall cache key).
WALL_VERSION = 2
#: Distance bins of the crossing points to the wall (the continuation's exit law).
_N_WALL_BINS = 48


# ---------------------------------------------------------------- the kernel
@numba.njit(cache=True, inline="always")
def _splitmix64(x):
    """One step of SplitMix64 (Steele, Lea & Flood 2014): ``(next state, output)``."""
    x = x + np.uint64(0x9E3779B97F4A7C15)
    z = x
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x, z ^ (z >> np.uint64(31))


@numba.njit(cache=True, inline="always")
def _photon_state(key, index, s):
    """Seed the xoshiro256+ state ``s`` of photon ``index`` from the run's ``key`` (SplitMix64, as its authors advise)."""
    x = key ^ (np.uint64(index) * np.uint64(0xD1B54A32D192ED03))
    for i in range(4):
        x, out = _splitmix64(x)
        s[i] = out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _trace_wall(
    starts,
    counts,
    key,
    sigma_s,
    sigma_a,
    g,
    n,
    d,
    kmin,
    nk,
    mm_per_row,
    w0,
    cutoff_mm,
    z_cont,
    hmin,
    nh,
    dbin,
    nd,
    wall_a,
    wcx,
    wcy,
    n_wall,
):
    """Trace ``counts[b]`` pencil-beam photons per batch ``b`` beside the wall; per-batch tallies.

    Photon ``starts[b] + i`` draws from its own xoshiro256+ stream seeded from ``key``, so
    two runs with the same key trace the same photons until one of them meets the wall:
    runs at several wall distances and one without a wall are correlated photon by photon
    (what makes their differences, the wall's effect, precise; :func:`mc_wall_table`).

    The medium is ``0 < z < d`` and ``x wcx + y wcy < wall_a``.  A photon whose step
    crosses ``z_cont`` stops there and is histogrammed by the ``x`` bin of the crossing
    (``hmin .. hmin + nh - 1``) and its distance to the wall (bins of ``dbin``; the last
    of ``nd`` takes every larger distance).  At the wall a fraction ``R`` (Fresnel of
    ``n_wall``; 0 for ``n_wall = 1``) is reflected specularly, the rest is lost.
    """
    B = counts.size
    cont_hist = np.zeros((B, nh, nd))
    cont_far = np.zeros(B)
    refl_bins, rad_bins, refl, trans, absorbed, truncated, events = new_tallies(B, nk)
    wall = np.zeros(B)
    sigma_t = sigma_s + sigma_a
    albedo = sigma_s / sigma_t
    finite = d < np.inf
    up_gain = (1.0 - fresnel_jit(1.0, n)) / (n * n)
    inv_bin = 1.0 / mm_per_row
    for b in range(B):
        s = np.zeros(4, dtype=np.uint64)
        refl_b = 0.0
        trans_b = 0.0
        abs_b = 0.0
        trunc_b = 0.0
        far_b = 0.0
        wall_b = 0.0
        events_b = 0
        for i in range(counts[b]):
            _photon_state(key, starts[b] + i, s)
            x, y, z, ux, uy, uz, w = launch(0.0, 0.0, w0)
            while True:
                step = free_path(s, sigma_t)
                # Distance to the wall along the direction of flight.
                dn = ux * wcx + uy * wcy
                s_wall = np.inf
                if dn > 0.0:
                    s_wall = max((wall_a - (x * wcx + y * wcy)) / dn, 0.0)
                # Distance to the next depth event: the continuation depth, the bottom or the top face.
                s_z = np.inf
                cont = False
                if uz > 0.0:
                    if z_cont < d:
                        s_z = (z_cont - z) / uz
                        cont = True
                    elif finite:
                        s_z = (d - z) / uz
                elif uz < 0.0:
                    s_z = -z / uz
                if s_wall < step and s_wall <= s_z:
                    # The wall: Fresnel reflection, the rest leaves the container.
                    x += s_wall * ux
                    y += s_wall * uy
                    z += s_wall * uz
                    lost, w = fresnel_escape(w, dn, n_wall)
                    wall_b += lost
                    ux -= 2.0 * dn * wcx
                    uy -= 2.0 * dn * wcy
                    if w <= 0.0:
                        break
                elif s_z < step:
                    xc = x + s_z * ux
                    yc = y + s_z * uy
                    if cont:
                        h = math.floor(xc * inv_bin + 0.5) - hmin
                        delta = wall_a - (xc * wcx + yc * wcy)
                        j = nd - 1
                        if dbin > 0.0:
                            j = min(int(max(delta, 0.0) / dbin), nd - 1)
                        if 0 <= h < nh:
                            cont_hist[b, int(h), j] += w
                        else:
                            far_b += w
                        break
                    x = xc
                    y = yc
                    top = uz < 0.0
                    z = 0.0 if top else d
                    esc, w = fresnel_escape(w, abs(uz), n)
                    if top:
                        refl_b += esc
                        k = math.floor(x * inv_bin + 0.5) - kmin
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
                    z += step * uz
                    events_b += 1
                    tau = sigma_t * z
                    if tau < 40.0:
                        k = math.floor(x * inv_bin + 0.5) - kmin
                        if 0 <= k < nk:
                            rad_bins[b, int(k)] += w * albedo * hg_pdf_jit(-uz, g) * math.exp(-tau) * up_gain
                    dabs, w, ux, uy, uz = collide(s, w, albedo, ux, uy, uz, g)
                    abs_b += dabs
                w, dabs, alive = roulette(s, w)
                abs_b += dabs
                if not alive:
                    break
                if beyond_cutoff(x, y, z, cutoff_mm, cutoff_mm, cutoff_mm):
                    trunc_b += w
                    break
        refl[b] = refl_b
        trans[b] = trans_b
        absorbed[b] = abs_b
        truncated[b] = trunc_b
        cont_far[b] = far_b
        wall[b] = wall_b
        events[b] = events_b
    return refl_bins, rad_bins, refl, trans, absorbed, truncated, wall, events, cont_hist, cont_far


# ---------------------------------------------------------------- runs
def check_wall_model(wall) -> str:
    """``wall`` if it names a wall model (:data:`WALL_MODELS`); InputError otherwise."""
    if wall not in WALL_MODELS:
        raise InputError(f"unknown wall model {wall!r}; choose one of {', '.join(WALL_MODELS)}")
    return wall


def _wall_index(wall, medium):
    return medium.n if wall == "fresnel" else 1.0


def wall_run_params(
    medium,
    offsets,
    *,
    wall_distance_mm,
    wall_angle_deg,
    wall,
    n_photons,
    mm_per_row,
    seed,
    offsets_rows=None,
    diffusion_depth_mfp=DIFFUSION_DEPTH_MFP,
    cutoff_mm=None,
):
    """Checked parameters of one wall run (the cache key's content; :func:`trace_wall_run` reads them)."""
    a = float(wall_distance_mm)
    n_photons = check_photons(n_photons)
    mm_per_row = check_mm_per_row(mm_per_row)
    if cutoff_mm is None:
        cutoff_mm = default_cutoff_mm(medium, offsets, mm_per_row=mm_per_row)
        if math.isfinite(a):
            cutoff_mm = max(cutoff_mm, 4.0 * a)
    cutoff_mm = check_cutoff(medium, offsets, mm_per_row, cutoff_mm)
    depth_mfp = check_depth_mfp(diffusion_depth_mfp)
    return dict(
        **run_params(medium, n_photons, mm_per_row, seed),
        cutoff_mm=cutoff_mm,
        diffusion_depth_mfp=depth_mfp,
        source="pencil-wall",
        wall=wall,
        wall_distance_mm=a,
        wall_angle_deg=float(wall_angle_deg),
        wall_version=WALL_VERSION,
    )


def mc_wall_profile(
    medium: Medium,
    *,
    wall_distance_mm,
    wall_angle_deg=0.0,
    wall="fresnel",
    n_photons=10**5,
    offsets_rows=None,
    mm_per_row=1.0,
    diffusion_depth_mfp=DIFFUSION_DEPTH_MFP,
    cutoff_mm=None,
    seed=0,
    cache=False,
) -> MCProfile:
    """Monte Carlo line kernel of a pixel ``wall_distance_mm`` from a container wall.

    Parameters
    ----------
    medium : Medium
        The liquid (``thickness_mm``: its depth; semi-infinite by default).
    wall_distance_mm : float
        Distance ``a >= 0`` from the pixel (the pencil beam's entry point) to the wall.
    wall_angle_deg : float
        Angle ``phi`` in ``[0, 90]`` between the wall's normal and the offset axis: 0 for
        a wall parallel to the projector's lines (at positive offsets), 90 for one
        perpendicular to them.
    wall : {"fresnel", "absorbing"}
        A clear wall with air behind it (Fresnel reflection at the medium's index, the
        rest lost) or a black wall (everything lost).
    n_photons : int
        Photon packets.
    offsets_rows : array_like of int, optional
        Offset bins; default ``arange(-50, 51)``.
    mm_per_row : float
        Bin width in mm.
    diffusion_depth_mfp : float or None
        Hand-off depth (semi-infinite media) in transport mean free paths, with the
        quarter-space exit law (module docstring); None traces every photon.
    cutoff_mm : float, optional
        Stop photons farther than this from the entry point (``|x|``, ``|y|``, ``z``);
        default :func:`planeray.mc.default_cutoff_mm`.
    seed : int
        Seed: same seed, same bytes, whatever the number of threads.
    cache : bool
        Read/write the result in the disk cache (after the shipped tables).

    Returns
    -------
    MCProfile
        ``radiance`` is the pixel's line kernel (normal-view radiance per bin, per unit
        power; by reciprocity the light the pixel receives from each lit line),
        ``values`` the exitance of the pencil beam per ``x`` bin, and ``wall_loss`` the
        power lost through the wall.

    Examples
    --------
    >>> from planeray.medium import Medium
    >>> m = Medium(sigma_s=2.0, sigma_a=0.05, g=0.5, n=1.33)
    >>> p = mc_wall_profile(m, wall_distance_mm=1.0, n_photons=4000, offsets_rows=range(-5, 6))
    >>> abs(p.energy_balance - 1.0) < 1e-9 and p.wall_loss > 0
    True
    >>> float(p.values[-1])  # beyond the wall (x > 1 mm): nothing leaves there
    0.0
    """
    medium = as_medium(medium)
    check_wall_model(wall)
    a = float(wall_distance_mm)
    phi_deg = float(wall_angle_deg)
    if not a >= 0:  # also rejects NaN; inf: no wall (the reference of :func:`mc_wall_table`)
        raise InputError(f"wall_distance_mm must be >= 0 (inf: no wall), got {wall_distance_mm!r}")
    if not (0.0 <= phi_deg <= 90.0):
        raise InputError(f"wall_angle_deg must lie in [0, 90], got {wall_angle_deg!r}")
    if offsets_rows is None:
        offsets_rows = np.arange(-50, 51)
    offsets = check_offsets(offsets_rows)
    params = wall_run_params(
        medium,
        offsets,
        wall_distance_mm=a,
        wall_angle_deg=phi_deg,
        wall=wall,
        n_photons=n_photons,
        mm_per_row=mm_per_row,
        diffusion_depth_mfp=diffusion_depth_mfp,
        cutoff_mm=cutoff_mm,
        seed=seed,
    )
    return stored(
        f"{cache_key(params, offsets)}.npz",
        load=load_profile,
        build=lambda: trace_wall_run(medium, offsets, params)[0],
        save=save_profile,
        cache=cache,
    )


def trace_wall_run(medium, offsets, params):
    """Trace one wall run of :func:`wall_run_params`' parameters: ``(profile, per-batch radiance per photon)``.

    The second, ``(N_BATCHES, U)``, is what :func:`planeray.kernels.wall.mc_wall_table` differences
    photon by photon against a run without the wall (a control variate).
    """
    sigma_s, sigma_a, g, n, d = medium.sigma_s, medium.sigma_a, medium.g, medium.n, medium.thickness_mm
    n_photons, mm, seed = params["n_photons"], params["mm_per_row"], params["seed"]
    cutoff_mm, a = params["cutoff_mm"], params["wall_distance_mm"]
    phi = math.radians(params["wall_angle_deg"])
    wcx, wcy = math.cos(phi), math.sin(phi)
    if params["wall_angle_deg"] == 90.0:
        wcx = 0.0
    n_wall = _wall_index(params["wall"], medium)
    B = N_BATCHES
    counts = batch_counts(n_photons)
    key = np.random.SeedSequence(seed).generate_state(1, np.uint64)[0]
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    kmin = int(offsets.min())
    nk = int(offsets.max()) - kmin + 1
    r_sp = ((n - 1.0) / (n + 1.0)) ** 2
    depth_mfp = params["diffusion_depth_mfp"]
    sigma_tp = sigma_a + medium.sigma_s_prime
    z_cont = depth_mfp / sigma_tp if (depth_mfp and not np.isfinite(d)) else np.inf
    q = None
    dbin, nd = 0.0, 1
    hmin, nh = 0, 1
    if np.isfinite(z_cont):
        q = quarter_space(z_cont, sigma_a, sigma_tp, n, n_wall)
        half = max(abs(kmin), abs(kmin + nk - 1)) * mm
        reach = int(np.ceil(min(cutoff_mm, half + 20.0 * z_cont) / mm))
        hmin, nh = -reach, 2 * reach + 1
        if wcy > 0.0 and math.isfinite(a):  # distance to the wall is not a function of x: histogram it
            delta_max = 4.0 * z_cont + (6.0 / q.sigma_tr if q.sigma_tr > 0 else 20.0 * z_cont)
            nd = _N_WALL_BINS + 1
            dbin = delta_max / _N_WALL_BINS
    refl_bins, rad_bins, refl, trans, absorbed, truncated, wall, events, cont, far = trace_batches(
        _trace_wall,
        (starts, counts),
        (
            key,
            sigma_s,
            sigma_a,
            g,
            n,
            d,
            kmin,
            nk,
            mm,
            1.0 - r_sp,
            cutoff_mm,
            z_cont,
            hmin,
            nh,
            dbin,
            nd,
            a,
            wcx,
            wcy,
            n_wall,
        ),
    )
    rad_bins /= mm
    out = np.arange(kmin, kmin + nk)
    if q is not None and (cont.any() or far.any()):
        if not math.isfinite(a):  # no wall: the engine's exit law
            c1 = cont.sum(axis=2)
            exit_bins, e_tot = diffusion_exit(c1, hmin, out, mm, z_cont, sigma_a, sigma_tp, n)
            e_w, w_w = c1.sum(axis=1) * e_tot, np.zeros(B)
        elif wcy > 0.0:
            exit_bins, e_w, w_w = exits_oblique(cont, hmin, out, mm, q, phi, dbin)
        else:
            exit_bins, e_w, w_w = exits_parallel(cont[:, :, 0], hmin, out, mm, q, a)
        refl_bins += exit_bins
        rad_bins += exit_bins * (diffusion_normal_radiance_ratio(n) / mm)
        # Photons beyond the crossing histogram cannot reach the bins: they leave as without a wall.
        refl += e_w + far * q.e0
        wall += w_w
        absorbed += cont.sum(axis=(1, 2)) - e_w - w_w + far * (1.0 - q.e0)
    prof = profile_from_tallies(
        offsets_rows=offsets,
        first_bin=kmin,
        mm_per_row=mm,
        counts=counts,
        refl_bins=refl_bins,
        rad_bins=rad_bins,
        refl=refl,
        trans=trans,
        absorbed=absorbed,
        truncated=truncated,
        events=events,
        wall=wall,
        specular_reflectance=r_sp,
        params=params,
    )
    cols = offsets - kmin
    per_photon = rad_bins[:, cols] / counts[:, None]
    return prof, per_photon


def wall_exit_fractions(delta_mm, *, medium: Medium, wall: str = "fresnel", diffusion_depth_mfp=DIFFUSION_DEPTH_MFP):
    """Diffusion hand-off beside a wall: fractions leaving through the top face and through the wall.

    For a photon handed to diffusion ``diffusion_depth_mfp`` transport mean free paths
    deep at distance ``delta_mm`` from the wall (see the module docstring), returns
    ``(E, W)``: the fraction that leaves through the top face inside the wall and the
    fraction lost through the wall; ``1 - E - W`` is absorbed.  Without absorption
    ``E + W = 1``; far from the wall ``E`` is the half-space value and ``W = 0``.

    Examples
    --------
    >>> from planeray.medium import Medium
    >>> E, W = wall_exit_fractions([0.5, 50.0], medium=Medium(sigma_s=2.0, sigma_a=0.0, g=0.5, n=1.33))
    >>> bool(abs(E[0] + W[0] - 1.0) < 1e-3 and W[1] < 0.2 < 0.8 < W[0])
    True
    """
    medium = as_medium(medium)
    check_wall_model(wall)
    sigma_tp = medium.sigma_a + medium.sigma_s_prime
    q = quarter_space(
        float(diffusion_depth_mfp) / sigma_tp, medium.sigma_a, sigma_tp, medium.n, _wall_index(wall, medium)
    )
    delta = np.atleast_1d(np.asarray(delta_mm, dtype=np.float64))
    return q.exit_fraction(delta), q.wall_fraction(delta)
