"""Monte Carlo in layered media with an embedded blood cylinder (skin and veins), compiled with Numba.

The engine's scheme (:mod:`planeray.mc.engine`: MCML weights [1]_, Henyey-Greenstein
scattering, Russian roulette, 32 seeded xoshiro256+ batches -- a result depends on the
seed only, never on the number of threads) for a stack of flat layers, top first, each a
:class:`planeray.medium.Medium` with its own ``sigma_s``, ``sigma_a``, ``g``, index ``n``
and thickness.  Steps cross layer interfaces the MCML way (the remaining optical depth is
carried over into the next layer); the top face reflects the unpolarized Fresnel fraction
of the weight against air (the rest escapes and is tallied); an internal interface between
unequal indices reflects or refracts (Fresnel, chosen at random); light leaving the bottom
of the stack is lost (``transmittance``) -- below the fat of the skin scene lies muscle,
treated as a sink.

Coordinates: ``x`` across the projector's lines (the offset axis: projector row minus
camera row, ``u = x / mm_per_row``), ``y`` along them, ``z`` depth.  A **cylinder** (a
vein) is infinitely long, its axis horizontal at depth ``z_c`` (the axis; its top is at
``z_c - r``), along the direction ``(sin theta, cos theta, 0)``: ``theta = 0`` runs
parallel to the projector rows, ``theta = 90`` across them.  The signed distance of a
point from the vein is ``rho = (x, y) . (cos theta, -sin theta)`` (positive below a
parallel vein).  Blood inside has its own ``sigma_s``, ``sigma_a``, ``g`` and the index of
the tissue (no refraction at the vessel wall).

Two runs:

:func:`mc_layered_vein_brute`
    **brute force**: the cylinder is in the medium and photons cross it.  A line source
    (the projector's row, along ``y``, normal incidence) at random positions; exits binned
    by the pixel's distance ``rho`` from the vein and the offset ``u``; a second run with
    the same seed and no vein gives the ratio ``K_vein / K_background`` -- the vein's
    contrast in the plane-to-ray kernel.
:func:`trace_virtual_veins` (:func:`planeray.kernels.vein.mc_vein_table` tabulates it)
    **perturbation** (the fast model's table): a pencil beam enters at the pixel and its
    exits, binned by ``x``, give the pixel's line kernel by reciprocity (the wall kernels of
    :mod:`planeray.mc.wall` do the same).  Along the way each photon records the optical
    depth ``(mu_a,blood - mu_a,layer) L`` it spends inside virtual veins -- one per angle
    and (depth, diameter), each placed at a random distance ``rho`` from the pixel -- and
    every exit is tallied once with weight ``w`` and once per vein with
    ``w exp(-(mu_a,blood - mu_a) L)``: the exact change of the kernel when the vein
    *absorbs* like blood (Monte Carlo perturbation, the pathlength-in-cylinder weighting
    of [2]_ [3]_).  Scattering inside the vein is that of the surrounding tissue: that is
    the approximation, and :func:`mc_layered_vein_brute` measures it.

Both tally the power leaving the top face (exitance), like the wax scene's kernel.

References
----------
.. [1] L. Wang, S. L. Jacques, L. Zheng, "MCML -- Monte Carlo modeling of light transport
   in multi-layered tissues", Comput. Methods Programs Biomed. 47, 131-146, 1995.
.. [2] C. K. Hayakawa, J. Spanier, F. Bevilacqua, A. K. Dunn, J. S. You, B. J. Tromberg,
   V. Venugopalan, "Perturbation Monte Carlo methods to solve inverse photon migration
   problems in heterogeneous tissues", Opt. Lett. 26(17), 1335-1337, 2001.
.. [3] C. Liu, A. K. Maity, A. W. Dubrawski, A. Sabharwal, S. G. Narasimhan, "High
   resolution diffuse optical tomography using short range indirect subsurface
   imaging", ICCP 2020 (the Episcan-style measurement as a convolution with a
   perturbation kernel).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numba
import numpy as np

from ..errors import InputError
from ..medium import Medium, as_medium
from ._batches import trace_batches
from .cache import cache_key, load_profile, save_profile, stored
from .engine import check_mm_per_row
from .events import (
    N_BATCHES,
    batch_counts,
    batch_states,
    beyond_cutoff,
    check_offsets,
    check_photons,
    collide,
    free_path,
    fresnel_escape,
    launch,
    roulette,
    uniform,
)
from .physics import fresnel_jit
from .result import MCProfile, profile_from_tallies

__all__ = [
    "LAYERED_VERSION",
    "LayeredResult",
    "mc_layered_profile",
    "mc_layered_vein_brute",
    "mc_vein_kernel_brute",
    "trace_virtual_veins",
    "layer_arrays",
    "layer_params",
    "check_vein",
]

#: Bumped whenever the layered runs' results change (part of every cache key).
LAYERED_VERSION = 1

_MODE_PENCIL = 0
_MODE_LINE = 1


# ---------------------------------------------------------------- geometry helpers
@numba.njit(cache=True, inline="always")
def _cyl_roots(q, z, dq, dz, qc, zc, r):
    """Parameters ``t1 <= t2`` where the line ``(q, z) + t (dq, dz)`` meets the circle; NaN if never."""
    a = dq * dq + dz * dz
    if a < 1e-14:
        return math.nan, math.nan
    b = 2.0 * ((q - qc) * dq + (z - zc) * dz)
    c = (q - qc) * (q - qc) + (z - zc) * (z - zc) - r * r
    disc = b * b - 4.0 * a * c
    if disc <= 0.0:
        return math.nan, math.nan
    sq = math.sqrt(disc)
    return (-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)


# ---------------------------------------------------------------- the kernel
@numba.njit(cache=True, nogil=True, error_model="numpy")
def _trace(
    states,
    counts,
    zb,
    mus,
    mua,
    gs,
    ns,
    mode,
    src_x,
    src_y,
    acc_y,
    mm,
    kmin,
    nk,
    rmin,
    nr,
    cutoff_mm,
    cyl_on,
    cyl_nx,
    cyl_ny,
    cyl_q,
    cyl_zc,
    cyl_r,
    b_mus,
    b_mua,
    b_g,
    v_nx,
    v_ny,
    rho0,
    drho,
    v_zc,
    v_r,
    v_dmua,
):
    """Trace ``counts[b]`` photons per batch ``b``; per-batch tallies (see the module docstring).

    ``zb``: the L + 1 layer boundaries (``zb[0] = 0``).  ``mode`` pencil (at the origin)
    or line (a line along ``y`` at ``x0`` uniform in ``[-src_x, src_x]``, ``y0`` uniform
    in ``[-src_y, src_y]``; exits tallied only for ``|y| <= acc_y``).  ``cyl_*``: the real
    cylinder (brute force); ``v_*``: virtual veins for the perturbation tallies, angles
    ``j`` (normals ``v_nx, v_ny``), distances ``rho0 + i drho`` of the pixel (the origin) from
    the vein (``i < nr``) and combos ``c`` (``v_zc, v_r``, ``v_dmua[c, layer]``).
    """
    B = counts.size
    L = mus.size
    nj = v_nx.size
    nc = v_zc.size
    refl_bins = np.zeros((B, nk))
    hist = np.zeros((B, nr, nk))
    pert = np.zeros((B, nj, nc, nr, nk))
    refl = np.zeros(B)
    trans = np.zeros(B)
    absorbed = np.zeros(B)
    truncated = np.zeros(B)
    events = np.zeros(B, dtype=np.int64)
    n0 = ns[0]
    w0 = 1.0 - ((n0 - 1.0) / (n0 + 1.0)) ** 2
    inv = 1.0 / mm
    b_mut = b_mus + b_mua
    b_alb = b_mus / b_mut
    zlo_all = math.inf
    for c in range(nc):
        zlo_all = min(zlo_all, v_zc[c] - v_r[c])
    for b in range(B):
        s = states[b].copy()
        tau = np.zeros((nj, nc, nr + 1))
        refl_b = 0.0
        trans_b = 0.0
        abs_b = 0.0
        trunc_b = 0.0
        ev_b = 0
        for _ in range(counts[b]):
            if mode == _MODE_LINE:
                x0 = (2.0 * uniform(s) - 1.0) * src_x
                y0 = (2.0 * uniform(s) - 1.0) * src_y
            else:
                x0 = 0.0
                y0 = 0.0
            x, y, z, ux, uy, uz, w = launch(x0, y0, w0)
            layer = 0
            in_cyl = False
            if nj > 0:
                tau[:] = 0.0
            alive = True
            while alive:
                left = free_path(s, 1.0)  # optical depth of this flight
                collided = False
                while True:
                    if in_cyl:
                        mut = b_mut
                    else:
                        mut = mus[layer] + mua[layer]
                    step = left / mut
                    dist = math.inf
                    which = 0
                    if not in_cyl:
                        if uz < 0.0:
                            dist = (zb[layer] - z) / uz
                            which = -1
                        elif uz > 0.0:
                            dist = (zb[layer + 1] - z) / uz
                            which = 1
                    if cyl_on:
                        q = x * cyl_nx + y * cyl_ny
                        dq = ux * cyl_nx + uy * cyl_ny
                        t1, t2 = _cyl_roots(q, z, dq, uz, cyl_q, cyl_zc, cyl_r)
                        if t2 == t2:
                            if in_cyl:
                                tc = t2
                            else:
                                tc = t1 if t1 > 1e-12 else math.inf
                            if 0.0 <= tc < dist:
                                dist = tc
                                which = 2
                    seg = step if step < dist else dist
                    if nj > 0 and not in_cyl and seg > 0.0:
                        # Path length inside every virtual vein, by the flight's midpoint (flights
                        # are ~0.04 mm, veins >= 1 mm): the veins that contain the midpoint form a
                        # run of rho indices per (angle, combo), booked in a difference array.
                        zm = z + 0.5 * seg * uz
                        if zm > zlo_all:
                            for c in range(nc):
                                dz = zm - v_zc[c]
                                h2 = v_r[c] * v_r[c] - dz * dz
                                if h2 <= 0.0:
                                    continue
                                h = math.sqrt(h2)
                                dt = v_dmua[c, layer] * seg
                                for j in range(nj):
                                    qm = (x + 0.5 * seg * ux) * v_nx[j] + (y + 0.5 * seg * uy) * v_ny[j]
                                    # veins at q_v = -rho with |qm - q_v| < h
                                    i0 = max(0, math.ceil((-qm - h - rho0) / drho))
                                    i1 = min(nr - 1, math.floor((-qm + h - rho0) / drho))
                                    if i0 <= i1:
                                        tau[j, c, i0] += dt
                                        tau[j, c, i1 + 1] -= dt
                    x += seg * ux
                    y += seg * uy
                    z += seg * uz
                    if step < dist:
                        collided = True
                        break
                    left -= dist * mut
                    if which == 2:
                        in_cyl = not in_cyl
                        if not in_cyl:  # back in the tissue: which layer?
                            layer = 0
                            while layer < L - 1 and z >= zb[layer + 1]:
                                layer += 1
                        continue
                    if which == -1:
                        z = zb[layer]
                        if layer == 0:  # the top face: partial escape (Fresnel)
                            esc, w = fresnel_escape(w, -uz, ns[0])
                            refl_b += esc
                            if mode == _MODE_LINE:
                                if abs(y) <= acc_y:
                                    rho = x * cyl_nx + y * cyl_ny
                                    r = math.floor(rho * inv + 0.5) - rmin
                                    k = math.floor((x0 - x) * inv + 0.5) - kmin
                                    if 0 <= r < nr and 0 <= k < nk:
                                        hist[b, r, k] += esc
                            else:
                                k = math.floor(x * inv + 0.5) - kmin
                                if 0 <= k < nk:
                                    refl_bins[b, k] += esc
                                    for j in range(nj):
                                        for c in range(nc):
                                            t = 0.0
                                            for i in range(nr):
                                                t += tau[j, c, i]
                                                pert[b, j, c, i, k] += esc if t == 0.0 else esc * math.exp(-t)
                            uz = -uz
                            if w <= 0.0:
                                alive = False
                                break
                            continue
                        n1 = ns[layer]
                        n2 = ns[layer - 1]
                        nxt = layer - 1
                    else:
                        z = zb[layer + 1]
                        if layer == L - 1:  # the bottom: lost into the sink below
                            trans_b += w
                            alive = False
                            break
                        n1 = ns[layer]
                        n2 = ns[layer + 1]
                        nxt = layer + 1
                    if n1 == n2:
                        layer = nxt
                        continue
                    ci = abs(uz)
                    R = fresnel_jit(ci, n1 / n2)
                    if uniform(s) < R:
                        uz = -uz
                    else:
                        rel = n1 / n2
                        ct = math.sqrt(max(1.0 - rel * rel * (1.0 - ci * ci), 0.0))
                        ux *= rel
                        uy *= rel
                        uz = ct if uz > 0.0 else -ct
                        layer = nxt
                if not alive or not collided:
                    break
                ev_b += 1
                if in_cyl:
                    alb = b_alb
                    g = b_g
                else:
                    alb = mus[layer] / (mus[layer] + mua[layer])
                    g = gs[layer]
                dabs, w, ux, uy, uz = collide(s, w, alb, ux, uy, uz, g)
                abs_b += dabs
                w, dabs, alive = roulette(s, w)
                abs_b += dabs
                if not alive:
                    break
                if beyond_cutoff(x - x0, y, z, cutoff_mm, cutoff_mm + src_y, math.inf):
                    trunc_b += w
                    break
        refl[b] = refl_b
        trans[b] = trans_b
        absorbed[b] = abs_b
        truncated[b] = trunc_b
        events[b] = ev_b
    return refl_bins, hist, pert, refl, trans, absorbed, truncated, events


# ---------------------------------------------------------------- inputs
def layer_arrays(layers):
    """``(layers, boundaries, sigma_s, sigma_a, g, n)`` of a stack (top first), checked: every layer but the last
    finite and positive (InputError otherwise)."""
    layers = [as_medium(m) for m in layers]
    if not layers:
        raise InputError("a layered medium needs at least one layer")
    th = np.array([m.thickness_mm for m in layers], dtype=np.float64)
    if not np.all(np.isfinite(th[:-1])) or np.any(th <= 0):
        raise InputError("every layer but the last needs a finite positive thickness")
    zb = np.concatenate([[0.0], np.cumsum(th)])
    return (
        layers,
        zb,
        np.array([m.sigma_s for m in layers]),
        np.array([m.sigma_a for m in layers]),
        np.array([m.g for m in layers]),
        np.array([m.n for m in layers]),
    )


def layer_params(m: Medium) -> dict:
    """A layer's parameters as they enter the cache keys of layered runs and vein tables."""
    return {"sigma_s": m.sigma_s, "sigma_a": m.sigma_a, "g": m.g, "n": m.n, "thickness_mm": m.thickness_mm}


def _run(
    layers,
    *,
    n_photons,
    seed,
    mode,
    mm,
    kmin,
    nk,
    rmin=0,
    nr=1,
    src_x=0.0,
    src_y=0.0,
    acc_y=0.0,
    cutoff_mm=40.0,
    normal=(1.0, 0.0),
    cylinder=None,
    blood=None,
    virtual=None,
    progress=None,
):
    _, zb, mus, mua, gs, ns = layer_arrays(layers)
    counts = batch_counts(check_photons(n_photons, N_BATCHES))
    states = batch_states(seed)
    cyl_on = cylinder is not None
    nx, ny = normal
    qc, zc, rc = (0.0, 1.0, 0.0) if cylinder is None else cylinder
    bl = as_medium(blood) if blood is not None else Medium(sigma_s=1.0, sigma_a=0.0, g=0.0)
    if virtual is None:
        v_nx = v_ny = np.zeros(0)
        v_zc = v_r = np.zeros(0)
        v_dmua = np.zeros((0, mus.size))
        rho0, drho = 0.0, 1.0
    else:
        v_nx, v_ny, rho0, drho, v_zc, v_r, v_dmua = virtual
    out = trace_batches(
        _trace,
        (states, counts),
        (
            zb,
            mus,
            mua,
            gs,
            ns,
            mode,
            float(src_x),
            float(src_y),
            float(acc_y),
            float(mm),
            int(kmin),
            int(nk),
            int(rmin),
            int(nr),
            float(cutoff_mm),
            cyl_on,
            float(nx),
            float(ny),
            float(qc),
            float(zc),
            float(rc),
            bl.sigma_s,
            bl.sigma_a,
            bl.g,
            np.ascontiguousarray(v_nx, dtype=np.float64),
            np.ascontiguousarray(v_ny, dtype=np.float64),
            float(rho0),
            float(drho),
            np.ascontiguousarray(v_zc, dtype=np.float64),
            np.ascontiguousarray(v_r, dtype=np.float64),
            np.ascontiguousarray(v_dmua, dtype=np.float64),
        ),
        progress=progress,
    )
    return counts, out


# ---------------------------------------------------------------- the background kernel
#: The result of a layered run: the one result type of the photon kernels, :class:`~planeray.mc.result.MCProfile`
#: (a pencil beam at the pixel, exits binned by ``x``: the pixel's line kernel by reciprocity).  ``values[k]``
#: is the power leaving the top face through offset bin ``k`` per unit incident power; ``radiance`` is not
#: estimated (NaN); ``params`` holds the layers.
LayeredResult = MCProfile


def _check_offsets(offsets_rows):
    return check_offsets(offsets_rows, consecutive=True)


def _load_layered(path, params) -> MCProfile:
    """A layered cache entry (written by :func:`~planeray.mc.cache.save_profile`, or an older entry without the
    radiance, the transmittance's error, the collisions and the parameters: NaN, NaN, 0 and ``params``)."""
    prof = load_profile(path)
    return prof if prof.params else replace(prof, params=params)


def mc_layered_profile(
    layers, *, n_photons=200_000, offsets_rows=None, mm_per_row=0.3, seed=0, cache=False, progress=None
) -> LayeredResult:
    """Monte Carlo line kernel and total reflectance of a stack of layers (top first).

    Parameters
    ----------
    layers : sequence of Medium
        The layers, top first; every layer but the last needs a finite thickness (the last
        may be semi-infinite).  Each has its own index (Fresnel at unequal interfaces); the
        top layer's index meets air.
    n_photons : int
        Photon packets (at least 32).
    offsets_rows : array_like of int, optional
        Consecutive offset bins; default ``arange(-64, 65)``.
    mm_per_row : float
        Bin width, mm.
    seed : int
        Seed; same seed, same bytes whatever the number of threads.
    cache : bool
        Read/write the result in the Monte Carlo cache (shipped tables first).
    progress : callable, optional
        ``progress(n)`` with the photons just traced.

    Examples
    --------
    >>> from planeray.medium import Medium
    >>> r = mc_layered_profile(
    ...     [
    ...         Medium(sigma_s=10.0, sigma_a=0.1, g=0.9, n=1.4, thickness_mm=1.0),
    ...         Medium(sigma_s=5.0, sigma_a=0.05, g=0.9, n=1.4),
    ...     ],
    ...     n_photons=2000,
    ... )
    >>> abs(r.energy_balance - 1.0) < 1e-9
    True
    """
    off = _check_offsets(np.arange(-64, 65) if offsets_rows is None else offsets_rows)
    mm = check_mm_per_row(mm_per_row)
    params = {
        "kind": "layered-profile",
        "version": LAYERED_VERSION,
        "layers": [layer_params(as_medium(m)) for m in layers],
        "mm_per_row": mm,
        "n_photons": int(n_photons),
        "seed": int(seed),
    }

    def build():
        counts, out = _run(
            layers,
            n_photons=n_photons,
            seed=seed,
            mode=_MODE_PENCIL,
            mm=mm,
            kmin=off[0],
            nk=off.size,
            progress=progress,
        )
        return _pencil_result(layers, off, mm, counts, out, params)

    return stored(
        f"layered-{cache_key(params, off)}.npz",
        load=lambda path: _load_layered(path, params),
        build=build,
        save=save_profile,
        cache=cache,
        on_hit=None if progress is None else (lambda: progress(int(n_photons))),
    )


def _pencil_result(layers, off, mm, counts, out, params) -> MCProfile:
    """The result of a pencil-beam run from its per-batch tallies."""
    refl_bins, _, _, refl, trans, absorbed, truncated, events = out
    n0 = as_medium(layers[0]).n
    return profile_from_tallies(
        offsets_rows=off,
        first_bin=None,
        mm_per_row=mm,
        counts=counts,
        refl_bins=refl_bins,
        refl=refl,
        trans=trans,
        absorbed=absorbed,
        truncated=truncated,
        events=events,
        specular_reflectance=((n0 - 1.0) / (n0 + 1.0)) ** 2,
        params=params,
    )


# ---------------------------------------------------------------- brute force: the vein in the medium
def vein_normal(angle_deg):
    """The horizontal normal ``(cos a, -sin a)`` of a vein at ``angle_deg`` to the projector rows."""
    t = math.radians(float(angle_deg))
    return math.cos(t), -math.sin(t)


def check_vein(layers, depth_mm, diameter_mm):
    """``(axis depth, radius)`` of a vein ``depth_mm`` to its top, ``diameter_mm`` wide, inside the stack (InputError
    otherwise)."""
    _, zb, *_ = layer_arrays(layers)
    r = 0.5 * float(diameter_mm)
    top = float(depth_mm)
    if not (r > 0 and top > 0):
        raise InputError(f"vein depth and diameter must be positive, got {depth_mm} and {diameter_mm}")
    if top + 2 * r >= zb[-1]:
        raise InputError(f"a vein {depth_mm} mm deep and {diameter_mm} mm wide reaches below the stack ({zb[-1]} mm)")
    return top + r, r


def mc_layered_vein_brute(
    layers,
    blood: Medium,
    *,
    depth_mm,
    diameter_mm,
    angle_deg=0.0,
    rho_rows=None,
    offsets_rows=None,
    mm_per_row=0.3,
    n_photons=1_000_000,
    seed=0,
    progress=None,
):
    """Brute-force Monte Carlo of a vein in the layered medium: the kernel ratio ``K_vein / K_background``.

    A line source along ``y`` (the projector's row) lights the skin at random positions;
    the vein (``depth_mm`` to its top, ``diameter_mm`` wide, at ``angle_deg`` to the rows,
    its axis through the origin) is a cylinder of ``blood`` that photons actually cross.
    Exits are binned by the pixel's signed distance ``rho`` from the vein (rows) and by the
    offset ``u`` from the pixel to the lit line; a second run with the same seed and no vein
    is the background.  Only ``angle_deg`` 0 (parallel to the rows) and 90 (across them)
    are exact 1-D problems; they are what the validation uses.

    Returns
    -------
    dict
        ``rho_rows``, ``offsets_rows``, ``vein`` and ``background`` (power per bin,
        arbitrary common units), ``ratio`` (``vein / background``, NaN where the
        background is 0), ``n_photons``.
    """
    zc, r = check_vein(layers, depth_mm, diameter_mm)
    mm = check_mm_per_row(mm_per_row)
    rho = _check_offsets(np.arange(-24, 25) if rho_rows is None else rho_rows)
    off = _check_offsets(np.arange(-48, 49) if offsets_rows is None else offsets_rows)
    nx, ny = vein_normal(angle_deg)
    reach = (max(abs(rho[0]), abs(rho[-1])) + 0.5) * mm
    span = (max(abs(off[0]), abs(off[-1])) + 0.5) * mm
    margin = 15.0
    parallel = abs(ny) < 1e-12
    across = abs(nx) < 1e-12
    src_x = 0.0 if across else reach + span
    src_y = 0.0 if parallel else (reach if across else 2 * (reach + span)) + margin
    acc_y = math.inf if parallel else src_y - margin
    res = {}
    for name, cyl in (("vein", (0.0, zc, r)), ("background", None)):
        counts, out = _run(
            layers,
            n_photons=n_photons,
            seed=seed,
            mode=_MODE_LINE,
            mm=mm,
            kmin=off[0],
            nk=off.size,
            rmin=rho[0],
            nr=rho.size,
            src_x=src_x,
            src_y=src_y,
            acc_y=acc_y,
            normal=(nx, ny),
            cylinder=cyl,
            blood=blood,
            progress=progress,
        )
        res[name] = out[1].sum(axis=0) / counts.sum()
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(res["background"] > 0, res["vein"] / res["background"], np.nan)
    return {
        "rho_rows": rho,
        "offsets_rows": off,
        "vein": res["vein"],
        "background": res["background"],
        "ratio": ratio,
        "n_photons": int(n_photons),
        "mm_per_row": mm,
        "angle_deg": float(angle_deg),
        "depth_mm": float(depth_mm),
        "diameter_mm": float(diameter_mm),
    }


def mc_vein_kernel_brute(
    layers,
    blood: Medium,
    *,
    depth_mm,
    diameter_mm,
    angle_deg=0.0,
    rho_rows=0.0,
    offsets_rows=None,
    mm_per_row=0.3,
    n_photons=200_000,
    seed=0,
    progress=None,
) -> LayeredResult:
    """Brute-force line kernel of one pixel beside a vein in the medium (pencil beam at the pixel).

    The pixel sits at signed distance ``rho_rows`` from the axis of a blood cylinder
    (``depth_mm`` to its top, ``diameter_mm`` wide, at ``angle_deg`` to the rows) that
    photons cross with blood's own ``sigma_s``, ``sigma_a`` and ``g``; exits binned by
    ``x`` give the pixel's kernel over all offsets at once (reciprocity, as for
    :func:`mc_vein_table`, whose approximation this checks bin by bin).  Compare with
    :func:`mc_layered_profile` (same seed) for the ratio.
    """
    zc, r = check_vein(layers, depth_mm, diameter_mm)
    off = _check_offsets(np.arange(-64, 65) if offsets_rows is None else offsets_rows)
    mm = check_mm_per_row(mm_per_row)
    nx, ny = vein_normal(angle_deg)
    counts, out = _run(
        layers,
        n_photons=n_photons,
        seed=seed,
        mode=_MODE_PENCIL,
        mm=mm,
        kmin=off[0],
        nk=off.size,
        normal=(nx, ny),
        cylinder=(-float(rho_rows) * mm, zc, r),
        blood=blood,
        progress=progress,
    )
    params = {
        "kind": "layered-vein-brute",
        "version": LAYERED_VERSION,
        "layers": [layer_params(as_medium(m)) for m in layers],
        "blood": layer_params(as_medium(blood)),
        "depth_mm": float(depth_mm),
        "diameter_mm": float(diameter_mm),
        "angle_deg": float(angle_deg),
        "rho_rows": float(rho_rows),
        "mm_per_row": mm,
        "n_photons": int(n_photons),
        "seed": int(seed),
    }
    return _pencil_result(layers, off, mm, counts, out, params)


# ---------------------------------------------------------------- virtual veins (the perturbation run)
def trace_virtual_veins(
    layers, blood: Medium, *, depths_mm, diameters_mm, angles_deg, rho_rows, offsets_rows, mm_per_row, n_photons, seed,
    progress=None,
):  # fmt: skip
    """One pencil-beam run through the vein-free layers tallying every virtual vein of a grid (the perturbation).

    Each photon carries the optical depth ``(mu_a,blood - mu_a,layer) L`` of its path inside
    every virtual vein -- per angle, per distance ``rho`` of the pixel from the vein
    (``rho_rows``, evenly spaced) and per (depth, diameter) -- and every exit adds ``w`` to the
    background and ``w exp(-tau)`` to each vein's bin ``(rho, u)`` (the module docstring);
    :func:`planeray.kernels.vein.mc_vein_table` turns the tallies into kernel ratios.

    Returns
    -------
    dict
        ``counts`` (photons per batch), ``refl_bins`` ``(B, U)`` (the background's exits per
        offset bin), ``pert`` ``(B, angles, depth x diameter combos, rho, U)`` (the veins')
        and ``refl`` ``(B,)`` (all exits), per batch.
    """
    _, _, _, mua, _, _ = layer_arrays(layers)
    blood = as_medium(blood)
    rho = np.asarray(rho_rows, dtype=np.float64)
    off = np.asarray(offsets_rows, dtype=np.int64)
    mm = check_mm_per_row(mm_per_row)
    combos = [(d, D) for d in depths_mm for D in diameters_mm]
    v_zc = np.array([d + 0.5 * D for d, D in combos])
    v_r = np.array([0.5 * D for _, D in combos])
    v_dmua = np.array([[blood.sigma_a - a for a in mua] for _ in combos])
    nxy = np.array([vein_normal(a) for a in angles_deg])
    counts, out = _run(
        layers,
        n_photons=n_photons,
        seed=seed,
        mode=_MODE_PENCIL,
        mm=mm,
        kmin=off[0],
        nk=off.size,
        nr=rho.size,
        virtual=(nxy[:, 0], nxy[:, 1], rho[0] * mm, (rho[1] - rho[0]) * mm, v_zc, v_r, v_dmua),
        progress=progress,
    )
    refl_bins, _, pert, refl, *_ = out
    return dict(counts=counts, refl_bins=refl_bins, pert=pert, refl=refl)
