"""Driver: a Mitsuba scene file -> a planeray transport, in batches of samples, resumable, seeded.

:func:`render_transport` renders in memory, :func:`render_to_store` into a
transport store (resumable batch by batch).  Both:

1. choose the Mitsuba variant (:func:`planeray.render._mitsuba.choose_variant`),
   load the scene file and build the rectified rig (:mod:`planeray.render.rig`);
2. accumulate ``T(v, pixel)`` over batches of ``batch_spp`` camera paths per
   pixel with the one-pass tally (:mod:`planeray.render.integrator`) -- or, in
   a scalar variant, with one Mitsuba render per projector row
   (:mod:`planeray.render.reference`) -- plus, with ``caustics``, batches of
   projector paths whose first bounce is specular (:mod:`planeray.render.caustics`);
3. normalize: ``T`` is in units of the radiance of a white Lambertian surface
   facing the projector, on its axis, at the depth the camera's centre pixel
   sees (``reference_distance``) -- so such a surface gives 1 summed over all
   rows, like the built-in scenes' white surfaces;
4. bin it by offset ``u = v - p_t``: projector row ``v`` covers ``[v - 1/2, v + 1/2)``
   and its light goes to the two offset bins ``[k - 1/2, k + 1/2)`` it overlaps, in
   proportion (:func:`planeray.transport.bin_projector_rows`); the dense band ``|u| <= band_rows``, light from farther rows as sparse
   long-range entries (at most ``max_sparse``, the largest; the rest dropped with
   a :class:`RenderWarning` stating the fraction of light dropped);
5. label each pixel with its dominant light-transport effect from the path
   classes (:data:`planeray.scenes.EFFECTS`).

Batches draw disjoint random streams of one seed, so the same seed and
parameters give the same estimate (up to the float32 rounding of concurrent
additions in the LLVM backend: results agree to ~1e-6, not byte for byte), and
a killed :func:`render_to_store` started again resumes with the first batch not
yet done -- only if the scene file (and every file it references), the
parameters, the variant and Mitsuba's version are identical.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import shutil
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._validate import check_integer, check_number, check_positive
from ..errors import InputError
from ..io.lock import writes_output
from ..timing import RowGeometry
from ..transport import SparseEntries, Transport, bin_projector_rows

__all__ = ["RenderWarning", "RenderResult", "render_transport", "render_to_store", "labels_from_classes"]

#: Rec. 709 luminance weights (Mitsuba's ``luminance``) for the monochrome ``T`` of an RGB render.
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])


class RenderWarning(UserWarning):
    """Light the render leaves out: long-range entries dropped (the message says how much), or a caustic pass skipped.

    See Also
    --------
    render_transport : warns with it.

    Examples
    --------
    >>> issubclass(RenderWarning, UserWarning)
    True
    """


@dataclass
class RenderResult:
    """A rendered transport and its ground truth.

    Attributes
    ----------
    transport : Transport
        Monochrome ``T`` (the luminance of an RGB render): dense band + sparse entries.
    rgb : ndarray (H, W, U, 3) float32 or None
        The dense band per colour channel of an RGB render.
    classes : ndarray (4, H, W) float32
        Light per pixel (summed over rows) by path class, keys 1-4 of
        :data:`planeray.scenes.EFFECTS` (direct diffuse, subsurface, diffuse
        interreflection, specular interreflection).
    direct : ndarray (H, W) float32
        Direct light (``classes[0]``).
    albedo : ndarray (H, W) float32
        Diffuse reflectance at each pixel's first scattering vertex (a medium's single-scattering albedo).
    labels : ndarray (H, W) uint8
        Dominant effect per pixel (:func:`labels_from_classes`).
    attrs : dict
        Everything that rebuilds the render (scene file and digest, rig, parameters, variant, timings).
    dropped_fraction : float
        Fraction of the light beyond the band that was neither dense nor sparse.

    See Also
    --------
    render_transport : returns it.

    Examples
    --------
    >>> from planeray.render import example_scene
    >>> result = render_transport(example_scene("room_corner"), shape=(8, 8), projector_rows=16, spp=4, band_rows=8)
    >>> type(result).__name__, result.direct.shape, result.labels.shape
    ('RenderResult', (8, 8), (8, 8))
    """

    transport: Transport
    rgb: np.ndarray | None
    classes: np.ndarray
    direct: np.ndarray
    albedo: np.ndarray
    labels: np.ndarray
    attrs: dict = field(default_factory=dict)
    dropped_fraction: float = 0.0


def labels_from_classes(classes, *, label_fraction=0.1, floor_fraction=1e-3) -> np.ndarray:
    """Effect labels from the path-class tallies.

    A pixel is labelled with the indirect class (subsurface, diffuse or specular
    interreflection) that carries the most light if that is at least
    ``label_fraction`` of its direct light (the rule of the built-in ``corner``
    and ``mirror_ball`` scenes), else direct diffuse (1); pixels whose total is
    below ``floor_fraction`` of the image's 99th percentile are 0 (none).

    Parameters
    ----------
    classes : array_like (4, H, W)
        Light per path class: direct, subsurface, diffuse and specular interreflection.
    label_fraction : float
        Share of the direct light an indirect class needs to label a pixel.
    floor_fraction : float
        Pixels below this share of the image's 99th percentile are labelled 0.

    Returns
    -------
    ndarray (H, W) of int
        Keys of :data:`planeray.scenes.EFFECTS`.

    See Also
    --------
    RenderResult : its ``labels``.

    Examples
    --------
    >>> c = np.zeros((4, 1, 3))
    >>> c[0] = [1, 1, 0]
    >>> c[2] = [0.05, 0.5, 0]
    >>> labels_from_classes(c).tolist()
    [[1, 3, 0]]
    """
    classes = np.asarray(classes, dtype=np.float64)
    total = classes.sum(axis=0)
    direct = classes[0]
    indirect = classes[1:]
    best = np.argmax(indirect, axis=0)
    best_value = np.take_along_axis(indirect, best[None], axis=0)[0]
    labels = np.where(best_value >= label_fraction * direct, best + 2, 1)
    scale = np.percentile(total, 99) if total.size else 0.0
    labels = np.where(total > floor_fraction * scale, labels, 0)
    return labels.astype(np.uint8)


# ----------------------------------------------------------------------------- setup
@dataclass
class _Setup:
    loaded: object
    rig: object
    sensor: object
    projector: object
    shape: tuple
    variant: str
    params: dict
    fingerprint: str
    reference_distance: float
    white_radiance: float


def _reference_distance(mi, loaded, rig) -> float:
    """Depth of the camera's centre pixel (else the distance to the scene's bounding-box centre)."""
    o, f = rig.camera_origin, rig.camera_forward
    ray = mi.Ray3f(mi.Point3f(*map(float, o)), mi.Vector3f(*map(float, f)))
    si = loaded.scene.ray_intersect(ray)
    t = float(np.asarray(si.t).ravel()[0])
    if math.isfinite(t) and t > 0:
        return t
    bbox = loaded.scene.bbox()
    centre = np.asarray([float(np.asarray(c).ravel()[0]) for c in bbox.center()])
    return float(np.linalg.norm(centre - o)) or 1.0


def _white_radiance(mi, projector, rig, distance) -> float:
    """Radiance of a white Lambertian surface facing the projector on its axis at ``distance``: ``E / pi``."""
    m = rig.projector_to_world
    point = m[:3, 3] + distance * m[:3, 2] / np.linalg.norm(m[:3, 2])
    it = mi.Interaction3f()
    it.p = mi.Point3f(*map(float, point))
    _, w = projector.sample_direction(it, mi.Point2f(0.5, 0.5))
    return float(np.asarray(w).ravel()[0]) / math.pi


def _setup(
    scene_file,
    *,
    shape,
    projector_rows,
    spp,
    batch_spp,
    max_depth,
    rr_depth,
    caustics,
    caustic_paths,
    seed,
    band_rows,
    rgb,
    baseline,
    projector_aspect,
    projector_columns,
    projector_vfov_deg,
    variant,
    max_sparse,
    camera,
    vfov_deg,
) -> _Setup:
    from ._mitsuba import choose_variant, mitsuba
    from .rig import Rig
    from .scene_file import load_scene_file, scene_file_digest

    H, W = (check_integer(shape[0], "shape[0]", minimum=1), check_integer(shape[1], "shape[1]", minimum=1))
    check_integer(projector_rows, "projector_rows", minimum=1)
    check_integer(spp, "spp", minimum=1)
    check_integer(batch_spp, "batch_spp", minimum=1)
    check_integer(band_rows, "band_rows", minimum=0)
    check_integer(max_sparse, "max_sparse", minimum=0)
    if max_depth != -1 and max_depth < 1:
        raise InputError(f"max_depth must be -1 (unbounded) or at least 1, got {max_depth}")
    if projector_columns is not None:
        check_integer(projector_columns, "projector_columns", minimum=1)
        if projector_aspect is not None:
            raise InputError("give the projector's columns or its aspect, not both")
        projector_aspect = int(projector_columns) / int(projector_rows)
    if projector_aspect is not None:
        check_positive(projector_aspect, "projector_aspect")
    if projector_vfov_deg is not None:
        check_number(projector_vfov_deg, "projector_vfov_deg")
        if not 0 < projector_vfov_deg < 180:
            raise InputError(f"projector_vfov_deg must be in (0, 180) degrees, got {projector_vfov_deg}")
    chosen = choose_variant(rgb=rgb, prefer=variant)
    mi = mitsuba()
    mi.set_log_level(mi.LogLevel.Error)
    scene_file = Path(scene_file)
    loaded = load_scene_file(scene_file)
    digest = scene_file_digest(scene_file)
    defaults = loaded.defaults
    sources = {
        "baseline": "argument" if baseline is not None else None,
        "projector_aspect": "argument" if projector_aspect is not None else None,
        "vfov_deg": "argument (projector)" if projector_vfov_deg is not None else None,
    }
    try:
        if baseline is None and "planeray_baseline" in defaults:
            baseline = float(defaults["planeray_baseline"])
            sources["baseline"] = "scene file default planeray_baseline"
        if projector_aspect is None and "planeray_projector_aspect" in defaults:
            projector_aspect = float(defaults["planeray_projector_aspect"])
            sources["projector_aspect"] = "scene file default planeray_projector_aspect"
        if projector_vfov_deg is None and "planeray_projector_vfov" in defaults:
            projector_vfov_deg = float(defaults["planeray_projector_vfov"])
            sources["vfov_deg"] = "scene file default planeray_projector_vfov"
        from_file = caustics is None
        if from_file:
            caustics = str(defaults.get("planeray_caustics", "false")).strip().lower() in ("true", "1", "yes")
    except ValueError as exc:
        raise InputError(f"a planeray_* default is not a number ({exc})", scene_file) from None
    if caustics and not chosen.startswith("llvm"):
        if not from_file:
            raise InputError(f"the caustic pass needs an llvm variant (Mitsuba runs {chosen}: install libllvm19)")
        warnings.warn(
            f"{scene_file.name} asks for the caustic pass, which needs an llvm variant (Mitsuba runs {chosen}): "
            "rendered without it",
            RenderWarning,
            stacklevel=3,
        )
        caustics = False
    if camera is None and loaded.sensor is None:
        raise InputError(
            "the scene has no perspective sensor: planeray's camera is the file's first sensor, "
            "or place one with camera= (--look-from/--look-at)",
            scene_file,
        )

    def make_rig(b):
        if camera is None:
            rig = Rig.from_sensor(
                loaded.sensor,
                baseline=b,
                projector_rows=projector_rows,
                projector_aspect=projector_aspect,
                path=scene_file,
            )
        else:
            origin, target, up = (np.asarray(c, dtype=np.float64).reshape(3) for c in camera)
            fov = 40.0 if vfov_deg is None else float(vfov_deg)
            rig = Rig.look_at(
                origin,
                target,
                up,
                vfov_deg=fov,
                baseline=b,
                projector_rows=projector_rows,
                projector_aspect=projector_aspect,
            )
        if projector_vfov_deg is not None:
            # a rectified camera image spans the projector's rows: the camera takes the projector's vertical field
            rig = dataclasses.replace(rig, vfov_deg=float(projector_vfov_deg))
        return rig

    distance = _reference_distance(mi, loaded, make_rig(0.0))
    if baseline is None:
        baseline = 0.1 * distance  # planeray's default: a tenth of the working distance
    rig = make_rig(float(baseline))
    sensor = mi.load_dict(rig.sensor_dict((H, W), rgb=rgb))
    projector = mi.load_dict(rig.projector_dict())
    white = _white_radiance(mi, projector, rig, distance)
    if caustic_paths is None:
        caustic_paths = H * W * int(spp)
    params = {
        "scene_file": str(scene_file),
        "scene_digest": digest,
        "shape": [H, W],
        "projector_rows": int(projector_rows),
        "spp": int(spp),
        "batch_spp": int(batch_spp),
        "max_depth": int(max_depth),
        "rr_depth": int(rr_depth),
        "caustics": bool(caustics),
        "caustic_paths": int(caustic_paths) if caustics else 0,
        "seed": int(seed),
        "band_rows": int(band_rows),
        "rgb": bool(rgb),
        "max_sparse": int(max_sparse),
        "variant": chosen,
        "mitsuba_version": mi.__version__,
        "rig": rig.describe(),
        "rig_sources": {
            "baseline": sources["baseline"] or "planeray default: a tenth of the working distance",
            "projector_aspect": sources["projector_aspect"] or "planeray default: 16:9 (the PicoPro)",
            "vfov_deg": sources["vfov_deg"]
            or ("argument (--vfov)" if camera is not None else "the scene file's sensor"),
        },
    }
    fingerprint = hashlib.sha256(json.dumps(params, sort_keys=True).encode()).hexdigest()
    return _Setup(loaded, rig, sensor, projector, (H, W), chosen, params, fingerprint, distance, white)


def _units(setup: _Setup) -> list[tuple[str, int, int]]:
    """Work units: ("camera", first sample, samples) batches, then ("caustic", first path, paths)."""
    p = setup.params
    units = []
    if setup.variant.startswith("scalar"):
        # one unit per chunk of projector rows (Mitsuba renders each row with all spp)
        step = 16
        for v0 in range(0, p["projector_rows"], step):
            units.append(("rows", v0, min(step, p["projector_rows"] - v0)))
        return units
    for s0 in range(0, p["spp"], p["batch_spp"]):
        units.append(("camera", s0, min(p["batch_spp"], p["spp"] - s0)))
    if p["caustics"]:
        per = p["shape"][0] * p["shape"][1] * p["batch_spp"]
        for q0 in range(0, p["caustic_paths"], per):
            units.append(("caustic", q0, min(per, p["caustic_paths"] - q0)))
    return units


def _run_unit(setup: _Setup, unit):
    """(transport (C, P, H, W), classes (4, H, W), albedo (H, W)) of one unit, as estimates times its weight."""
    from .caustics import trace_caustics
    from .integrator import tally_transport
    from .reference import render_rows

    kind, first, count = unit
    p = setup.params
    H, W = setup.shape
    P = p["projector_rows"]
    rig = (setup.loaded.scene, setup.sensor, setup.projector)
    common = dict(shape=(H, W), projector_rows=P, seed=p["seed"], max_depth=p["max_depth"], rr_depth=p["rr_depth"])
    if kind == "camera":
        r = tally_transport(*rig, spp=count, spp_offset=first, **common)
        # weight: this batch's share of all camera samples
        return r.transport / p["spp"], r.classes / p["spp"], r.albedo / p["spp"]
    if kind == "caustic":
        r = trace_caustics(*rig, n_paths=count, path_offset=first, **common)
        share = count / p["caustic_paths"]
        return r.transport * share, r.classes * share, r.albedo
    # scalar fallback: rows first .. first + count, each with all spp (no class tallies: see labels)
    rows = range(first, first + count)
    T = render_rows(
        setup.loaded,
        setup.rig,
        (H, W),
        rows,
        spp=p["spp"],
        max_depth=p["max_depth"],
        rr_depth=p["rr_depth"],
        seed=p["seed"],
        rgb=p["rgb"],
    )
    full = np.zeros((T.shape[3], P, H, W))
    full[:, first : first + count] = np.moveaxis(T, 3, 0)
    classes = np.zeros((4, H, W))
    classes[0] = T.mean(axis=3).sum(axis=0)  # no path classes in scalar variants: all counted as direct
    return full, classes, np.zeros((H, W))


def _finish(setup: _Setup, full, classes, albedo, *, seconds) -> RenderResult:
    """Normalize, bin by offset, label."""
    p = setup.params
    H, W = setup.shape
    P = p["projector_rows"]
    full = np.asarray(full, dtype=np.float64) / setup.white_radiance
    classes = np.asarray(classes, dtype=np.float64) / setup.white_radiance
    mono = full[0] if full.shape[0] == 1 else np.tensordot(LUMINANCE, full, axes=1)
    geometry = RowGeometry(H, P)
    B = p["band_rows"]
    offsets = np.arange(-B, B + 1)
    # projector row v covers [v - 1/2, v + 1/2): its light is shared between the two offset bins of
    # u = v - p_t it overlaps (planeray.timing.RowGeometry.row_bins), band and long-range entries alike
    dense, (row, col, off, val) = bin_projector_rows(mono, geometry, offsets)
    rgb_band = None
    if p["rgb"]:
        rgb_band = np.stack([bin_projector_rows(c, geometry, offsets, far=False)[0] for c in full], axis=-1)
    dropped = 0.0
    total = float(np.abs(mono).sum())
    if val.size:
        if val.size > p["max_sparse"]:
            keep = np.argpartition(-np.abs(val), p["max_sparse"] - 1)[: p["max_sparse"]] if p["max_sparse"] else []
            lost = np.abs(val).sum() - np.abs(val[keep]).sum()
            dropped = float(lost / total) if total > 0 else 0.0
            row, col, off, val = row[keep], col[keep], off[keep], val[keep]
            warnings.warn(
                f"kept the {p['max_sparse']} largest of the long-range entries beyond +-{B} rows; "
                f"dropped {100 * dropped:.3g} % of the light (raise max_sparse / --max-sparse or --band-rows)",
                RenderWarning,
                stacklevel=3,
            )
        sparse = SparseEntries(row, col, off, val)
    else:
        sparse = SparseEntries.empty()
    transport = Transport(dense, offsets, geometry, sparse)
    classes32 = classes.astype(np.float32)
    attrs = {
        **p,
        "method": "mitsuba_render",
        "reference_distance": setup.reference_distance,
        "radiance_unit": "white Lambertian surface facing the projector at reference_distance = 1",
        "white_radiance": setup.white_radiance,  # that surface's radiance in the scene's own units
        "dropped_fraction": dropped,
        "seconds": float(seconds),
    }
    labels = labels_from_classes(classes32)
    if setup.variant.startswith("scalar"):
        attrs["labels"] = "not available in scalar variants (no path classes): direct light only"
    return RenderResult(
        transport, rgb_band, classes32, classes32[0].copy(), albedo.astype(np.float32), labels, attrs, dropped
    )


def _common_kwargs(kw):
    return {
        "shape": kw.get("shape", (128, 128)),
        "projector_rows": kw.get("projector_rows", 720),
        "spp": kw.get("spp", 64),
        "batch_spp": kw.get("batch_spp", 64),
        "max_depth": kw.get("max_depth", -1),
        "rr_depth": kw.get("rr_depth", 5),
        "caustics": kw.get("caustics"),
        "caustic_paths": kw.get("caustic_paths"),
        "seed": kw.get("seed", 0),
        "band_rows": kw.get("band_rows", 128),
        "rgb": kw.get("rgb", False),
        "baseline": kw.get("baseline"),
        "projector_aspect": kw.get("projector_aspect"),
        "projector_columns": kw.get("projector_columns"),
        "projector_vfov_deg": kw.get("projector_vfov_deg"),
        "variant": kw.get("variant"),
        "max_sparse": kw.get("max_sparse", 4_000_000),
        "camera": kw.get("camera"),
        "vfov_deg": kw.get("vfov_deg"),
    }


def render_transport(
    scene_file,
    *,
    shape=(128, 128),
    projector_rows=720,
    spp=64,
    batch_spp=64,
    max_depth=-1,
    rr_depth=5,
    caustics=None,
    caustic_paths=None,
    seed=0,
    band_rows=128,
    rgb=False,
    baseline=None,
    projector_aspect=None,
    projector_columns=None,
    projector_vfov_deg=None,
    variant=None,
    max_sparse=4_000_000,
    camera=None,
    vfov_deg=None,
    progress=None,
) -> RenderResult:
    """Render a Mitsuba scene file's plane-to-ray transport in memory.

    Parameters
    ----------
    scene_file : str or os.PathLike
        Mitsuba 3 XML scene with a ``perspective`` sensor (the camera; see :mod:`planeray.render.rig`).
    shape : (int, int)
        Camera pixels ``(H, W)``.
    projector_rows : int
        ``P`` (the paper's PicoPro: 720).
    spp : int
        Camera paths per pixel.
    batch_spp : int
        Camera paths per pixel per batch (memory; the unit of progress and resuming).
    max_depth, rr_depth : int
        Longest path (-1: unbounded; 2: direct light only) and the depth where
        Russian roulette starts, as Mitsuba's ``path``.
    caustics : bool, optional
        Add the light-tracing pass for paths whose first bounce is specular
        (default: the file's ``planeray_caustics`` default, else False).
    caustic_paths : int, optional
        Projector paths of that pass (default ``H * W * spp``).
    seed : int
    band_rows : int
        Half-width of the dense band of offsets (``-band_rows .. band_rows``).
    rgb : bool
        Render three channels; ``T`` is then their luminance and ``rgb`` the colour band.
    baseline, projector_aspect : float, optional
        The rig (:mod:`planeray.render.rig`): projector to the camera's right (scene
        units) and its width / height; default: the file's ``planeray_baseline`` /
        ``planeray_projector_aspect`` defaults, else a tenth of the working distance and 16:9.
    projector_columns : int, optional
        The projector's columns, instead of ``projector_aspect`` (aspect = columns / rows).
    projector_vfov_deg : float, optional
        The projector's vertical field of view (degrees; default: the file's
        ``planeray_projector_vfov``, else the camera's).  A rectified camera image
        spans the projector's rows, so the camera takes this vertical field of view
        too (its horizontal one follows from ``shape``).
    variant : {"llvm", "scalar"}, optional
        Force a variant family (default: llvm where its runtime loads).
    max_sparse : int
        Most long-range entries kept (the largest); the rest is dropped with a :class:`RenderWarning`.
    camera : ((3,), (3,), (3,)), optional
        ``(origin, target, up)``: place the camera here instead of the file's sensor
        (Mitsuba's ``look_at``), with vertical field of view ``vfov_deg`` (default 40).
    vfov_deg : float, optional
    progress : callable, optional
        ``progress(n)`` with the work units just done (:func:`render_work` gives the total).

    Returns
    -------
    RenderResult

    See Also
    --------
    planeray.render.RenderResult : what it returns.
    planeray.make_scene : the built-in analytic scenes.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Eq. 4.
    .. [2] W. Jakob et al., "Mitsuba 3 renderer", https://mitsuba-renderer.org, 2022.

    Examples
    --------
    A corner of a room, 8 x 8 pixels, 4 samples per pixel:

    >>> from importlib.resources import files
    >>> import planeray as pr
    >>> scene = files("planeray") / "render" / "scenes" / "room_corner.xml"
    >>> result = pr.render_transport(scene, shape=(8, 8), projector_rows=16, spp=4, band_rows=8)
    >>> result.transport.dense.shape
    (8, 8, 17)
    """
    import time

    kw = _common_kwargs(locals())
    setup = _setup(scene_file, **kw)
    start = time.perf_counter()
    full = classes = albedo = None
    for unit in _units(setup):
        t, c, a = _run_unit(setup, unit)
        full = t if full is None else full + t
        classes = c if classes is None else classes + c
        albedo = a if albedo is None else albedo + a
        if progress is not None:
            progress(1)
    return _finish(setup, full, classes, albedo, seconds=time.perf_counter() - start)


def render_work(scene_file, **kwargs) -> int:
    """Number of ``progress`` units of a render with these parameters (without rendering).

    Silent about what the render itself will warn of (a caustic pass skipped): it renders nothing.

    Parameters
    ----------
    scene_file : str or path
        A Mitsuba 3 scene file.
    **kwargs
        The options of :func:`render_transport`.

    Returns
    -------
    int
        The total the ``progress`` callback will count to.

    See Also
    --------
    render_transport : the render.

    Examples
    --------
    >>> from planeray.render import example_scene
    >>> render_work(example_scene("room_corner"), shape=(8, 8), projector_rows=16, spp=4) > 0
    True
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RenderWarning)
        return len(_units(_setup(scene_file, **_common_kwargs(kwargs))))


def _store_arrays(result: RenderResult) -> dict:
    arrays = {
        "direct": result.direct,
        "ambient_albedo": result.albedo,
        "labels": result.labels,
        **{f"light_{name}": result.classes[i] for i, name in enumerate(_CLASS_NAMES)},
    }
    if result.rgb is not None:
        arrays["T_rgb"] = result.rgb
    return arrays


_CLASS_NAMES = ("direct", "subsurface", "diffuse_interreflection", "specular_interreflection")


@writes_output("out")
def render_to_store(
    scene_file,
    out,
    *,
    overwrite=False,
    restart=False,
    lines_per_second=None,
    progress=None,
    on_resume=None,
    **kwargs,
) -> tuple[Path, RenderResult]:
    """:func:`render_transport` into a transport store, resumable batch by batch.

    ``on_resume(done, total)`` (batches) is called when an unfinished render of the
    same output and inputs is continued, so a front end can say so.

    The running sums live in a hidden partial store next to ``out`` (two
    buffers: a batch is written into the spare one and becomes current when it
    is marked done, so a run killed at any moment resumes exactly); a run with
    other inputs refuses to touch it unless ``restart``.  The finished store
    holds ``T`` (+ sparse entries), the per-pixel maps ``direct``,
    ``ambient_albedo``, ``labels`` and ``light_<class>`` and, for RGB, ``T_rgb``
    (H, W, U, 3); its attributes record every parameter.

    Parameters
    ----------
    scene_file : str or path
        A Mitsuba 3 scene file.
    out : str or path
        The transport store to write.
    overwrite : bool
        Replace a finished store planeray wrote.
    restart : bool
        Discard an unfinished render instead of resuming it.
    lines_per_second : float, optional
        Recorded in the store (default: the paper's).
    progress : callable, optional
        ``progress(n)`` with the work units just done.
    on_resume : callable, optional
        ``on_resume(done, total)`` (batches) when an unfinished render is continued.
    **kwargs
        The options of :func:`render_transport`.

    Returns
    -------
    path : Path
    result : RenderResult

    See Also
    --------
    render_transport : in memory.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> from planeray.render import example_scene
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path, result = render_to_store(
    ...         example_scene("room_corner"),
    ...         pathlib.Path(tmp) / "T.zarr",
    ...         shape=(8, 8),
    ...         projector_rows=16,
    ...         spp=4,
    ...         band_rows=8,
    ...     )
    ...     pr.read_transport(path)[0].dense.shape
    (8, 8, 17)
    """
    import time

    import zarr

    from ..io import write_transport
    from ..io.atomic import check_replaceable
    from ..resumable import discard_if_empty, done_units, mark_done, open_partial, partial_path
    from ..timing import PAPER_LINES_PER_SECOND

    out = Path(out)
    check_replaceable(out, overwrite=overwrite, kind="transport")
    kw = _common_kwargs(kwargs)
    unknown = set(kwargs) - set(kw)
    if unknown:
        raise TypeError(f"unknown parameters {sorted(unknown)}")
    setup = _setup(scene_file, **kw)
    units = _units(setup)
    H, W = setup.shape
    P = setup.params["projector_rows"]
    C = 3 if setup.params["rgb"] else 1

    def create(directory):
        group = zarr.open_group(str(directory), mode="w", zarr_format=3)
        group.create_array("sum_T", shape=(2, C, P, H, W), chunks=(1, 1, P, H, W), dtype="float64", fill_value=0.0)
        group.create_array("sum_classes", shape=(2, 4, H, W), chunks=(1, 4, H, W), dtype="float64", fill_value=0.0)
        group.create_array("sum_albedo", shape=(2, H, W), chunks=(1, H, W), dtype="float64", fill_value=0.0)
        group.attrs["render_params"] = setup.params
        return group

    group = open_partial(out, setup.fingerprint, len(units), create, restart=restart)
    done = done_units(group)
    # the current sums are in buffer (number done) % 2; units are done in order
    n_done = int(done.sum())
    if n_done and not done[:n_done].all():
        raise InputError("internal error: a partial render with units done out of order", partial_path(out))
    cur = n_done % 2
    if n_done:
        if on_resume is not None:
            on_resume(n_done, len(units))
        full, classes, albedo = (np.asarray(group[a][cur]) for a in ("sum_T", "sum_classes", "sum_albedo"))
        if progress is not None:
            progress(n_done)
    else:
        full, classes, albedo = np.zeros((C, P, H, W)), np.zeros((4, H, W)), np.zeros((H, W))
    start = time.perf_counter()
    try:
        for i in range(n_done, len(units)):
            t, c, a = _run_unit(setup, units[i])
            full, classes, albedo = full + t, classes + c, albedo + a
            nxt = (i + 1) % 2
            group["sum_T"][nxt] = full
            group["sum_classes"][nxt] = classes
            group["sum_albedo"][nxt] = albedo
            mark_done(group, i)  # the commit: buffer nxt is now current
            if progress is not None:
                progress(1)
    except BaseException:
        discard_if_empty(out)  # a run that finished no batch leaves nothing behind
        raise
    result = _finish(setup, full, classes, albedo, seconds=time.perf_counter() - start)
    attrs = dict(result.attrs)
    attrs["lines_per_second"] = float(lines_per_second or PAPER_LINES_PER_SECOND)
    write_transport(result.transport, out, attrs=attrs, overwrite=overwrite, arrays=_store_arrays(result))
    shutil.rmtree(partial_path(out), ignore_errors=True)
    return out, result
