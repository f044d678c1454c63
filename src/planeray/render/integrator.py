"""The one-pass tally: a camera-side path tracer that bins every projector connection by projector row.

Image formation with a row-scanning projector (Kubo et al. [1]_, Eq. 4) is
``I(s, t) = sum_v L(v) T(v, s, t)``: ``T(v, s, t)`` is the radiance camera pixel
``(s, t)`` receives when projector row ``v`` alone is lit.  A path tracer with
next-event estimation towards a *pinhole* projector receives all of its light
through that one connection, and the connection's direction fixes the
projector row the light left from.  So one camera-side pass yields every row:
each next-event contribution is added to ``T[v, pixel]`` (:func:`drjit.scatter_reduce`)
instead of to the pixel, where ``v`` is the row of the projector's bitmap that the
connection falls into -- the texture coordinate Mitsuba's ``projector`` emitter
returns itself, so the row mapping is the renderer's own (row 0 at the top).

The tracer follows Mitsuba 3's ``path`` / ``volpath`` integrators [2]_ for the
parts it supports -- any surface BSDF (smooth lobes get next-event estimation,
delta lobes are followed), ``null`` interfaces, and homogeneous media (free-flight
sampling with a channel drawn per flight and the channels' mean density -- spectral MIS --, phase-function next-event estimation and sampling, the transmittance
of shadow rays through null interfaces and media) -- with Russian roulette from
depth ``rr_depth`` and ``max_depth`` counted as Mitsuba does (``2`` = direct light
only).  It is checked against per-row renders with Mitsuba's own integrators
(:mod:`planeray.render.reference`) in ``tests/test_render.py``.  Light from
other emitters in the scene is ignored (the projector is the only light).

Each contribution is also tallied, per pixel, by the kind of path it ends
(:data:`PATH_CLASSES`, keys of :data:`planeray.scenes.EFFECTS`): the ground truth
behind the rendered scene's effect labels.

What camera-side tracing cannot produce: light that leaves the projector
through a *specular* first bounce (a mirror throwing a caustic on a wall), since
a delta-position light and a delta BSDF never connect.  :mod:`planeray.render.caustics`
adds exactly those paths.

References
----------
.. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa,
   S. G. Narasimhan, "Programmable Non-Epipolar Indirect Light Transport:
   Capture and Analysis", IEEE TVCG 27(4), 2021, Eq. 4.
.. [2] W. Jakob et al., "Mitsuba 3 renderer", 2022, https://mitsuba-renderer.org
   (``path``, ``volpath``, ``projector``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PATH_CLASSES", "TallyResult", "tally_transport"]

#: Path classes of the per-pixel tallies (keys of planeray.scenes.EFFECTS): a path with a
#: medium vertex is subsurface (2); else one that met a delta (specular) surface before its
#: last vertex is specular interreflection (4); else one with several surface vertices is
#: diffuse interreflection (3); a single surface vertex is direct diffuse light (1).
PATH_CLASSES = (1, 2, 3, 4)


@dataclass
class TallyResult:
    """Sums of one batch of samples (divide by ``spp`` for estimates).

    Attributes
    ----------
    transport : ndarray (C, P, H, W) float64
        Summed contributions per colour channel, projector row and pixel.
    classes : ndarray (4, H, W) float64
        Summed (channel-mean) contributions per path class :data:`PATH_CLASSES`.
    albedo : ndarray (H, W) float64
        Summed diffuse reflectance at each camera path's first scattering vertex.
    spp : int
        Samples per pixel in the sums.
    """

    transport: np.ndarray
    classes: np.ndarray
    albedo: np.ndarray
    spp: int


def _shadow_transmittance(mi, dr, scene, it, target, medium, active, *, from_surface, max_crossings=32):
    """Transmittance from ``it`` to the point ``target`` through null interfaces and homogeneous media.

    Opaque surfaces block (``eval_null_transmission`` is 0 for them); a homogeneous
    medium attenuates a segment of length ``d`` by ``exp(-sigma_t d)`` exactly.
    """
    ray = it.spawn_ray_to(target)
    if from_surface:
        medium = dr.select(it.is_medium_transition(), it.target_medium(ray.d), medium)
    tr = dr.full(mi.Spectrum, 1.0)
    crossing = mi.Bool(active)
    i = mi.UInt32(0)

    def cond(ray, medium, tr, crossing, i):
        return crossing

    def body(ray, medium, tr, crossing, i):
        si = scene.ray_intersect(ray, crossing)
        hit = crossing & si.is_valid()
        seg = dr.select(hit, si.t, ray.maxt)
        in_med = crossing & (medium != None)  # noqa: E711  (Dr.Jit pointer comparison)
        mei = dr.zeros(mi.MediumInteraction3f)
        mei.p = ray.o
        sigma_t = medium.get_majorant(mei, in_med)
        tr = dr.select(in_med, tr * dr.exp(-sigma_t * seg), tr)
        bsdf = si.bsdf(ray)
        tr = dr.select(hit, tr * bsdf.eval_null_transmission(si, hit), tr)
        medium = dr.select(hit & si.is_medium_transition(), si.target_medium(ray.d), medium)
        ray = dr.select(hit, si.spawn_ray_to(target), ray)
        i = i + 1
        # a path still crossing after max_crossings interfaces counts as blocked
        tr = dr.select(hit & (i >= max_crossings), 0.0, tr)
        crossing = hit & (dr.max(tr) > 0)
        return ray, medium, tr, crossing, i

    ray, medium, tr, crossing, i = dr.while_loop((ray, medium, tr, crossing, i), cond, body)
    return tr


def _roulette(dr, sampler, beta, q, depth, active, rr_depth, max_depth):
    """Russian roulette with survival ``q`` past ``rr_depth`` and the depth limit (as Mitsuba's path/volpath).

    Returns the reweighted throughput and the paths still active.
    """
    rr = depth > rr_depth
    active &= dr.any(beta != 0.0)
    active &= (sampler.next_1d(active) < q) | ~rr
    beta = dr.select(rr, beta / q, beta)
    active &= depth < max_depth
    return beta, active


def _row_of(dr, mi, uv_y, P):
    """Projector row of a texture coordinate (row 0 at the top), as the ``nearest`` bitmap filter picks it."""
    return mi.UInt32(dr.clip(dr.floor(uv_y * P), 0, P - 1))


def tally_transport(
    scene, sensor, projector, *, shape, projector_rows, spp, seed=0, max_depth=-1, rr_depth=5, spp_offset=0
) -> TallyResult:
    """Trace ``spp`` camera paths per pixel and bin every projector connection by projector row.

    Parameters
    ----------
    scene : mitsuba.Scene
        Geometry, BSDFs and homogeneous media (its emitters are ignored).
    sensor : mitsuba.Sensor
        The rig's camera (:meth:`planeray.render.rig.Rig.sensor_dict`).
    projector : mitsuba.Emitter
        The rig's ``projector`` with an all-ones pattern (:meth:`Rig.projector_dict`).
    shape : (int, int)
        Camera pixels ``(H, W)``.
    projector_rows : int
        ``P``, the rows of the projector's pattern.
    spp : int
        Camera paths per pixel in this batch.
    seed : int
        Seed of the sampler (a batch is a function of ``seed`` and ``spp_offset``).
    max_depth, rr_depth : int
        As Mitsuba's ``path``: longest path (-1: unbounded) and the depth where
        Russian roulette starts.
    spp_offset : int
        Samples already drawn for this seed (batches of one run use disjoint streams).

    Returns
    -------
    TallyResult
    """
    import drjit as dr
    import mitsuba as mi

    H, W = (int(shape[0]), int(shape[1]))
    P = int(projector_rows)
    n_pixels = H * W
    n = n_pixels * int(spp)
    C = 1 if mi.variant().endswith("mono") else 3
    max_depth = 2**31 - 1 if max_depth < 0 else int(max_depth)

    sampler = mi.load_dict({"type": "independent"})
    # disjoint streams per batch: the seed mixes the run seed and the batch's first sample
    sampler.seed(int((int(seed) * 1_000_003 + int(spp_offset)) % (2**32)), n)

    idx = dr.arange(mi.UInt32, n)
    pixel = idx // int(spp)
    px = mi.Float(pixel % W)
    py = mi.Float(pixel // W)
    film_pos = mi.Point2f((px + sampler.next_1d()) / W, (py + sampler.next_1d()) / H)
    ray, ray_weight = sensor.sample_ray(0.0, sampler.next_1d(), film_pos, sampler.next_2d())

    T = [dr.zeros(mi.Float, P * n_pixels) for _ in range(C)]
    E = dr.zeros(mi.Float, 4 * n_pixels)
    A = dr.zeros(mi.Float, n_pixels)
    ctx = mi.BSDFContext()
    phase_ctx = mi.PhaseFunctionContext(sampler)

    def tally(value, uv_y, kind, active):
        row = _row_of(dr, mi, uv_y, P)
        index = row * n_pixels + pixel
        for c in range(C):
            dr.scatter_reduce(dr.ReduceOp.Add, T[c], value[c], index, active)
        mean = value[0] if C == 1 else (value[0] + value[1] + value[2]) / 3
        dr.scatter_reduce(dr.ReduceOp.Add, E, mean, (kind - 1) * n_pixels + pixel, active)

    def path_class(medium_seen, specular_seen, surfaces_before):
        return dr.select(
            medium_seen,
            mi.UInt32(2),
            dr.select(specular_seen, mi.UInt32(4), dr.select(surfaces_before > 0, mi.UInt32(3), mi.UInt32(1))),
        )

    beta = mi.Spectrum(ray_weight)
    eta = mi.Float(1.0)
    depth = mi.UInt32(0)
    active = mi.Bool(True)
    medium = dr.zeros(mi.MediumPtr, n)
    medium_seen = mi.Bool(False)
    specular_seen = mi.Bool(False)
    surfaces = mi.UInt32(0)
    albedo_done = mi.Bool(False)

    state = (sampler, ray, beta, eta, depth, active, medium, medium_seen, specular_seen, surfaces, albedo_done)

    def cond(sampler, ray, beta, eta, depth, active, medium, medium_seen, specular_seen, surfaces, albedo_done):
        return active

    def body(sampler, ray, beta, eta, depth, active, medium, medium_seen, specular_seen, surfaces, albedo_done):
        # Russian roulette (as Mitsuba's path/volpath) and the depth limit
        q = dr.minimum(dr.max(beta) * dr.square(eta), 0.95)
        beta, active = _roulette(dr, sampler, beta, q, depth, active, rr_depth, max_depth)

        si = scene.ray_intersect(ray, active)

        # ---------------- homogeneous media: free flight (spectral MIS over channels)
        in_medium = active & (medium != None)  # noqa: E711
        # a fresh channel per free flight, so the mean of the channels' pdfs is this event's density
        # (one-sample MIS over channels; a channel fixed per path would need its own pdf, as volpath does)
        channel = mi.UInt32(0)
        if C == 3:
            channel = mi.UInt32(dr.minimum(sampler.next_1d(in_medium) * 3, 2))
        mei = medium.sample_interaction(ray, sampler.next_1d(in_medium), channel, in_medium)
        mei.t = dr.select(si.t < mei.t, dr.inf, mei.t)
        scatter = in_medium & mei.is_valid()
        tr, pdf = medium.transmittance_eval_pdf(mei, si, in_medium)
        pdf_mean = dr.mean(pdf) if C == 3 else pdf[0]
        beta = dr.select(in_medium, beta * dr.select(pdf_mean > 0, tr / pdf_mean, 0.0), beta)
        beta = dr.select(scatter, beta * mei.sigma_s, beta)
        depth = dr.select(scatter, depth + 1, depth)
        scatter &= depth < max_depth
        active &= ~(in_medium & mei.is_valid() & ~scatter)
        medium_seen |= scatter

        rec = scatter & ~albedo_done
        dr.scatter_reduce(dr.ReduceOp.Add, A, dr.mean(mei.sigma_s / mei.sigma_t), pixel, rec)
        albedo_done |= rec

        phase = mei.medium.phase_function()
        # next event through the phase function
        ds, w_em = projector.sample_direction(mei, sampler.next_2d(scatter), scatter)
        nee = scatter & (ds.pdf > 0) & (depth + 1 < max_depth)
        tr_shadow = _shadow_transmittance(mi, dr, scene, mei, ds.p, medium, nee, from_surface=False)
        phase_val, _ = phase.eval_pdf(phase_ctx, mei, ds.d, nee)
        tally(beta * phase_val * w_em * tr_shadow, ds.uv.y, mi.UInt32(2), nee & (dr.max(w_em) > 0))
        # phase sampling
        wo, phase_w, phase_pdf = phase.sample(
            phase_ctx, mei, sampler.next_1d(scatter), sampler.next_2d(scatter), scatter
        )
        scatter &= phase_pdf > 0
        ray = dr.select(scatter, mei.spawn_ray(wo), ray)
        beta = dr.select(scatter, beta * phase_w, beta)

        # ---------------- surfaces
        surface = active & ~(in_medium & mei.is_valid()) & si.is_valid()
        active &= ~(active & ~(in_medium & mei.is_valid()) & ~si.is_valid())  # escaped
        bsdf = si.bsdf(ray)
        flags = bsdf.flags()
        smooth = mi.has_flag(flags, mi.BSDFFlags.Smooth)
        nee = surface & smooth & (depth + 1 < max_depth)
        ds, w_em = projector.sample_direction(si, sampler.next_2d(nee), nee)
        nee &= ds.pdf > 0
        tr_shadow = _shadow_transmittance(mi, dr, scene, si, ds.p, medium, nee, from_surface=True)
        wo_local = si.to_local(ds.d)
        f = bsdf.eval(ctx, si, wo_local, nee)
        kind = path_class(medium_seen, specular_seen, surfaces)
        tally(beta * f * w_em * tr_shadow, ds.uv.y, kind, nee & (dr.max(w_em) > 0))

        bs, bsdf_w = bsdf.sample(ctx, si, sampler.next_1d(surface), sampler.next_2d(surface), surface)
        non_null = surface & ~mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
        rec = non_null & ~albedo_done
        refl = bsdf.eval_diffuse_reflectance(si, rec)
        dr.scatter_reduce(dr.ReduceOp.Add, A, dr.mean(refl) if C == 3 else refl[0], pixel, rec)
        albedo_done |= rec
        beta = dr.select(surface, beta * bsdf_w, beta)
        eta = dr.select(surface, eta * bs.eta, eta)
        new_ray = si.spawn_ray(si.to_world(bs.wo))
        ray = dr.select(surface, new_ray, ray)
        depth = dr.select(non_null, depth + 1, depth)
        specular_seen |= non_null & mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        surfaces = dr.select(non_null, surfaces + 1, surfaces)
        medium = dr.select(surface & si.is_medium_transition(), si.target_medium(new_ray.d), medium)
        active &= ~surface | (bs.pdf > 0) | mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
        return sampler, ray, beta, eta, depth, active, medium, medium_seen, specular_seen, surfaces, albedo_done

    dr.while_loop(state, cond, body, label="planeray tally")
    dr.eval(T, E, A)
    transport = np.stack([np.asarray(t, dtype=np.float64).reshape(P, H, W) for t in T])
    classes = np.asarray(E, dtype=np.float64).reshape(4, H, W)
    albedo = np.asarray(A, dtype=np.float64).reshape(H, W)
    return TallyResult(transport, classes, albedo, int(spp))
