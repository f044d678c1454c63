"""The caustic pass: light traced from the projector, kept only when its first bounce is specular.

A camera-side tracer (:mod:`planeray.render.integrator`) connects every
camera path to the pinhole projector by next-event estimation, which fails
exactly when the light's first surface is a delta BSDF (mirror, glass): a
point light and a delta lobe never connect.  Those paths -- caustics such as
the disco ball's spots on a wall -- are sampled here from the other end, as
Mitsuba's particle tracer ``ptracer`` does: rays leave the projector
(``projector.sample_ray``; the row is the texture coordinate of the ray, read
back with ``projector.sample_direction``), paths whose first vertex is not
purely specular are dropped (the camera pass has them: no double counting),
the rest are followed (importance transport, Russian roulette) and every smooth
vertex is connected to the camera (``sensor.sample_direction``), adding its
contribution to ``T[row, pixel]``.

Limits: a caustic seen only through another specular surface (a mirror seen in
a mirror) is in neither pass (the camera is a pinhole too); light tracing
stops at a medium boundary (caustics inside media are not rendered); null
interfaces are crossed.  The estimate is checked against Mitsuba's ``ptracer``
in ``tests/test_render.py``.
"""

from __future__ import annotations

import numpy as np

from .integrator import TallyResult, _roulette, _row_of, _shadow_transmittance

__all__ = ["trace_caustics"]


def trace_caustics(
    scene, sensor, projector, *, shape, projector_rows, n_paths, seed=0, max_depth=-1, rr_depth=5, path_offset=0
) -> TallyResult:
    """Trace ``n_paths`` projector paths; tally those whose first bounce is specular.

    Parameters
    ----------
    scene, sensor, projector, shape, projector_rows, max_depth, rr_depth
        As :func:`planeray.render.integrator.tally_transport`.
    n_paths : int
        Light paths in this batch.
    seed, path_offset : int
        Seed of the run and paths already drawn (batches use disjoint streams).

    Returns
    -------
    TallyResult
        Sums scaled to per-pixel estimates times ``spp = 1``: divide by
        ``spp`` (1) as for the camera pass; the class tallies go to specular
        interreflection (4).
    """
    import drjit as dr
    import mitsuba as mi

    H, W = (int(shape[0]), int(shape[1]))
    P = int(projector_rows)
    n_pixels = H * W
    n = int(n_paths)
    C = 1 if mi.variant().endswith("mono") else 3
    max_depth = 2**31 - 1 if max_depth < 0 else int(max_depth)

    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(int((int(seed) * 2_000_003 + 7_919 + int(path_offset)) % (2**32)), n)
    ray, weight = projector.sample_ray(0.0, sampler.next_1d(), sampler.next_2d(), sampler.next_2d())
    # the ray's projector row, by Mitsuba's own mapping
    probe = dr.zeros(mi.Interaction3f, n)
    probe.p = ray(1.0)
    ds0, _ = projector.sample_direction(probe, mi.Point2f(0.5, 0.5))
    row = _row_of(dr, mi, ds0.uv.y, P)

    T = [dr.zeros(mi.Float, P * n_pixels) for _ in range(C)]
    E = dr.zeros(mi.Float, 4 * n_pixels)
    ctx = mi.BSDFContext(mi.TransportMode.Importance)
    # the sensor's importance integrates to 1 over the whole film: a pixel's value is
    # (number of pixels) x (its splats) / (number of light paths)
    scale = float(n_pixels) / n

    beta = mi.Spectrum(weight)
    depth = mi.UInt32(0)
    active = mi.Bool(True)
    state = (sampler, ray, beta, depth, active)

    def cond(sampler, ray, beta, depth, active):
        return active

    def body(sampler, ray, beta, depth, active):
        q = dr.minimum(dr.max(beta), 0.95)
        beta, active = _roulette(dr, sampler, beta, q, depth, active, rr_depth, max_depth)
        si = scene.ray_intersect(ray, active)
        active &= si.is_valid()
        active &= ~si.is_medium_transition() | (si.target_medium(ray.d) == None)  # noqa: E711
        bsdf = si.bsdf(ray)
        flags = bsdf.flags()
        is_null = mi.has_flag(flags, mi.BSDFFlags.Null) & ~mi.has_flag(flags, mi.BSDFFlags.Smooth)
        first = active & (depth == 0) & ~is_null
        # the first real bounce must be purely specular (the camera pass has every other path)
        active &= ~(first & mi.has_flag(flags, mi.BSDFFlags.Smooth))
        connect = active & (depth > 0) & mi.has_flag(flags, mi.BSDFFlags.Smooth) & (depth + 1 < max_depth)
        ds, w_cam = sensor.sample_direction(si, sampler.next_2d(connect), connect)
        connect &= ds.pdf > 0
        vis = _shadow_transmittance(mi, dr, scene, si, ds.p, dr.zeros(mi.MediumPtr, n), connect, from_surface=False)
        f = bsdf.eval(ctx, si, si.to_local(ds.d), connect)
        value = beta * f * w_cam * vis * scale
        px = mi.UInt32(dr.clip(dr.floor(ds.uv.x), 0, W - 1))
        py = mi.UInt32(dr.clip(dr.floor(ds.uv.y), 0, H - 1))
        pixel = py * W + px
        ok = connect & (dr.max(value) > 0)
        for c in range(C):
            dr.scatter_reduce(dr.ReduceOp.Add, T[c], value[c], row * n_pixels + pixel, ok)
        mean = value[0] if C == 1 else (value[0] + value[1] + value[2]) / 3
        dr.scatter_reduce(dr.ReduceOp.Add, E, mean, 3 * n_pixels + pixel, ok)

        bs, bsdf_w = bsdf.sample(ctx, si, sampler.next_1d(active), sampler.next_2d(active), active)
        beta = dr.select(active, beta * bsdf_w, beta)
        ray = dr.select(active, si.spawn_ray(si.to_world(bs.wo)), ray)
        depth = dr.select(active & ~mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null), depth + 1, depth)
        active &= bs.pdf > 0
        return sampler, ray, beta, depth, active

    dr.while_loop(state, cond, body, label="planeray caustics")
    dr.eval(T, E)
    transport = np.stack([np.asarray(t, dtype=np.float64).reshape(P, H, W) for t in T])
    classes = np.asarray(E, dtype=np.float64).reshape(4, H, W)
    return TallyResult(transport, classes, np.zeros((H, W)), 1)
