"""Per-row rendering with Mitsuba's own integrators: the independent check of the tally, and the scalar fallback.

Lighting projector row ``v`` alone -- a ``projector`` emitter whose bitmap is 1
on row ``v`` and 0 elsewhere, ``nearest`` filtering -- and rendering with
Mitsuba's stock ``path`` (or ``volpath`` when the scene has media) and a
``box`` film filter gives ``T(v, ., .)`` directly, one render per row
(Kubo et al., Eq. 4 read backwards).  It shares nothing with
:func:`planeray.render.integrator.tally_transport` but the scene, so the two
agree only if the tally is right; it costs one render per row (see
``benchmarks/bench_render_mitsuba.py``), and it is what planeray renders with
in Mitsuba's scalar variants, which cannot scatter in one pass.
"""

from __future__ import annotations

import numpy as np

__all__ = ["render_rows", "render_pattern"]


def _reference_scene(loaded, rig, shape, *, spp, max_depth, rr_depth, rgb):
    import mitsuba as mi

    integrator = "volpath" if loaded.has_media else "path"
    scene = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": integrator, "max_depth": int(max_depth), "rr_depth": int(rr_depth)},
            "sensor": rig.sensor_dict(shape, rgb=rgb, spp=spp),
            "projector": rig.projector_dict(np.zeros(rig.projector_rows)),
            **{f"shape_{i}": s for i, s in enumerate(loaded.shapes)},
        }
    )
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.startswith("projector") and k.endswith("data"))
    return scene, params, key


def _render(mi, scene, params, key, rig, pattern, *, spp, seed):
    P, C = rig.projector_rows, rig.projector_columns
    image = np.ascontiguousarray(np.broadcast_to(np.asarray(pattern, np.float32).reshape(P, 1, 1), (P, C, 1)))
    params[key] = mi.TensorXf(image)
    params.update()
    img = np.asarray(mi.render(scene, spp=int(spp), seed=int(seed)), dtype=np.float64)
    return img.reshape(img.shape[0], img.shape[1], -1)


def render_pattern(loaded, rig, shape, pattern, *, spp=64, max_depth=-1, rr_depth=5, seed=0, rgb=False):
    """One image under a projector pattern (one value per row), with Mitsuba's ``path``/``volpath``.

    Returns
    -------
    image : ndarray (H, W, C) float64
        ``C = 3`` for ``rgb`` else 1 (the luminance in RGB variants).
    """
    import mitsuba as mi

    scene, params, key = _reference_scene(loaded, rig, shape, spp=spp, max_depth=max_depth, rr_depth=rr_depth, rgb=rgb)
    return _render(mi, scene, params, key, rig, pattern, spp=spp, seed=seed)


def render_rows(
    loaded, rig, shape, rows, *, spp=64, max_depth=-1, rr_depth=5, seed=0, rgb=False, progress=None
) -> np.ndarray:
    """``T(v, ., .)`` for each projector row ``v`` in ``rows``, one render per row.

    Parameters
    ----------
    loaded : LoadedScene
        :func:`planeray.render.scene_file.load_scene_file`.
    rig : Rig
    shape : (int, int)
        Camera pixels ``(H, W)``.
    rows : sequence of int
        Projector rows to light, one at a time.
    spp, max_depth, rr_depth : int
        As Mitsuba's ``path`` integrator.
    seed : int
        Every row is rendered with this seed: the same camera samples for
        every row, so the rows of a pixel add up to the full-projector render
        with the same seed exactly (each sample lights one row).
    progress : callable, optional
        ``progress(1)`` after each row.

    Returns
    -------
    T : ndarray (len(rows), H, W, C) float64
    """
    import mitsuba as mi

    scene, params, key = _reference_scene(loaded, rig, shape, spp=spp, max_depth=max_depth, rr_depth=rr_depth, rgb=rgb)
    out = []
    for v in rows:
        pattern = np.zeros(rig.projector_rows)
        pattern[int(v)] = 1.0
        out.append(_render(mi, scene, params, key, rig, pattern, spp=spp, seed=seed))
        if progress is not None:
            progress(1)
    return np.stack(out) if out else np.zeros((0, int(shape[0]), int(shape[1]), 3 if rgb else 1))
