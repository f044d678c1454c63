"""The prior a sweep is designed for: what transports the scenes it will image have.

A design needs the second moment ``S = E[x x^T]`` of a pixel's transport ``x`` over the offsets
of the support (the bias of the regularized problem depends on it) and its mean (the images'
expected values set their shot noise).  :func:`transport_prior` estimates both from pixels of
built-in scenes (:func:`planeray.scenes.make_scene`), of transport stores (a render of your own
scene, a ground truth, an earlier demultiplexing) or from a generic smoothness prior, in the
normalized image units the demultiplexer recovers (``signal_scale`` times a scene's transport).

The generic smoothness prior (``"smooth"``) is a Gaussian process over offsets: a mean of a
direct spike of albedo 0.5 (the camera row's footprint) and fluctuations of squared-exponential
covariance with a correlation length of ``smooth_rows`` projector rows, holding as much energy as
the mean.  Mixed into a prior of scenes (``smooth_weight``, a fraction of the scenes' energy) it
keeps every offset of the support worth measuring -- light where the scenes had none -- so that a
design does not bet everything on the scenes it was made from.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..timing import PAPER_PROJECTOR_ROWS, RowGeometry

__all__ = ["TransportPrior", "transport_prior", "PRIOR_ALL_SCENES", "PRIOR_SMOOTH", "DEFAULT_SMOOTH_WEIGHT"]

#: The source naming every built-in scene.
PRIOR_ALL_SCENES = "scenes"
#: The source naming the generic smoothness prior.
PRIOR_SMOOTH = "smooth"
#: Energy of the smoothness prior mixed into a prior of scenes, as a fraction of theirs.
DEFAULT_SMOOTH_WEIGHT = 0.03
#: Correlation length of the smoothness prior (projector rows).
DEFAULT_SMOOTH_ROWS = 8.0
#: Demultiplexing methods: a store they wrote is already in normalized image units.
_DEMUX_METHODS = ("fast", "pinv", "nnls", "cvxpy")


@dataclass(frozen=True)
class TransportPrior:
    """Second moment and mean of a pixel's transport over the support's offsets.

    Attributes
    ----------
    offsets_rows : ndarray (U,) int
        Offsets ``-K .. K`` (projector rows).
    second_moment : ndarray (U, U) float64
        ``E[x x^T]`` (normalized image units squared).
    mean : ndarray (U,) float64
        ``E[x]``.
    ambient_albedo : float
        Mean reflectance under ambient light (for the ambient part of the images' noise).
    n_pixels : int
        Pixels the moments were estimated from (0: the smoothness prior alone).
    description : dict
        JSON record: the sources, geometry, pixels, seed and smoothness mixed in.

    See Also
    --------
    transport_prior : builds one.

    Examples
    --------
    >>> from planeray.design import transport_prior
    >>> prior = transport_prior(["diffuse_plane"], shape=(32, 32), projector_rows=180, support_rows=20, pixels=50)
    >>> type(prior).__name__, prior.offsets_rows.size, prior.second_moment.shape
    ('TransportPrior', 41, (41, 41))
    """

    offsets_rows: np.ndarray
    second_moment: np.ndarray
    mean: np.ndarray
    ambient_albedo: float
    n_pixels: int
    description: dict

    @property
    def energy(self) -> float:
        """``E ||x||^2`` (the trace of the second moment): the error of estimating nothing."""
        return float(np.trace(self.second_moment))


def _smooth_kernel(offsets, rows: float) -> np.ndarray:
    u = np.asarray(offsets, np.float64)
    return np.exp(-0.5 * ((u[:, None] - u[None, :]) / float(rows)) ** 2)


def _interior_rows(geometry: RowGeometry, support_rows: int) -> np.ndarray:
    """Camera rows whose whole support lies on the projector (the rows a design's matrix is for)."""
    t = np.arange(geometry.camera_rows)
    p = geometry.projector_row_of(t)
    inside = (p - support_rows >= -0.5) & (p + support_rows <= geometry.projector_rows - 0.5)
    return t[inside] if inside.any() else t


def _on_support(transport, rows, cols, offsets) -> np.ndarray:
    """The transport of pixels ``(rows, cols)`` on ``offsets`` (dense band and sparse entries), (n, U)."""
    out = np.zeros((rows.size, offsets.size))
    u0 = int(offsets[0])
    own = np.asarray(transport.offsets_rows)
    keep = (own >= offsets[0]) & (own <= offsets[-1])
    out[:, own[keep] - u0] = np.asarray(transport.dense[rows, cols][:, keep], np.float64)
    sp = transport.sparse
    if sp is not None and len(sp):
        inside = (sp.offset >= offsets[0]) & (sp.offset <= offsets[-1])
        index = {(int(r), int(c)): i for i, (r, c) in enumerate(zip(rows, cols))}
        for r, c, o, v in zip(sp.row[inside], sp.col[inside], sp.offset[inside], sp.value[inside]):
            i = index.get((int(r), int(c)))
            if i is not None:
                out[i, int(o) - u0] += float(v)
    return out


def _sample(scene_like, n: int, rng, support_rows: int, offsets):
    """``n`` random pixels of a scene's interior rows: their transports and ambient albedos."""
    T = scene_like.transport
    H, W = T.shape
    rows = rng.choice(_interior_rows(T.geometry, support_rows), size=n)
    cols = rng.integers(0, W, size=n)
    albedo = np.asarray(scene_like.ambient_albedo, np.float64)[rows, cols]
    return _on_support(T, rows, cols, offsets), albedo


def transport_prior(
    sources=(PRIOR_ALL_SCENES,),
    *,
    shape=(128, 128),
    projector_rows: int = PAPER_PROJECTOR_ROWS,
    support_rows: int = 114,
    pixels: int = 1500,
    seed: int = 0,
    signal_scale: float = 0.6,
    smooth_weight: float = DEFAULT_SMOOTH_WEIGHT,
    smooth_rows: float = DEFAULT_SMOOTH_ROWS,
) -> TransportPrior:
    """The transport prior of a design, from scenes, transport stores or the smoothness prior.

    Parameters
    ----------
    sources : sequence of str
        Each a built-in scene name, ``"scenes"`` (every built-in scene), a transport store's path, or
        ``"smooth"`` (the generic smoothness prior; alone, it is the whole prior).
    shape : (int, int)
        Camera size of the built-in scenes (a store has its own).
    projector_rows : int
        Projector rows the built-in scenes span (the paper's 720).
    support_rows : int
        Half-width ``K`` of the offsets ``-K .. K`` (the paper's sweep reaches 114).
    pixels : int
        Pixels drawn from each scene or store (interior rows, uniformly).
    seed : int
        Seed of the scenes' textures and of the pixels drawn: the same seed, the same prior.
    signal_scale : float
        Normalized image value per unit of a scene's transport (the camera's ``laser_electrons /
        full_well_e``); a store written by ``planeray demux`` is taken as it is.
    smooth_weight : float
        Energy of the smoothness prior mixed into a prior of scenes or stores, as a fraction of theirs.
    smooth_rows : float
        Correlation length of the smoothness prior (projector rows).

    Returns
    -------
    TransportPrior

    See Also
    --------
    design_sweep : uses it.

    Examples
    --------
    >>> p = transport_prior(["diffuse_plane"], shape=(32, 32), projector_rows=180, support_rows=20, pixels=50)
    >>> p.second_moment.shape, p.n_pixels
    ((41, 41), 50)
    """
    from ..scenes import is_scene_name, list_scenes, make_scene

    sources = [str(s) for s in sources] or [PRIOR_ALL_SCENES]
    K = int(support_rows)
    if K < 1:
        raise InputError(f"support_rows must be at least 1, got {support_rows!r}")
    if int(pixels) < 1:
        raise InputError(f"pixels must be at least 1, got {pixels!r}")
    if not (np.isfinite(smooth_weight) and smooth_weight >= 0):
        raise InputError(f"smooth_weight must be a non-negative number, got {smooth_weight!r}")
    offsets = np.arange(-K, K + 1)
    rng = np.random.default_rng(int(seed))
    names: list[str] = []
    for s in sources:
        if s == PRIOR_ALL_SCENES:
            names.extend(list_scenes())
        else:
            names.append(s)
    X, albedo, used = [], [], []
    smooth_only = True
    for name in dict.fromkeys(names):  # each once, in order
        if name == PRIOR_SMOOTH:
            continue
        smooth_only = False
        if Path(name).exists():
            from ..scenes.store_scene import scene_from_transport_store

            scene = scene_from_transport_store(name)
            from ..io import read_transport

            method = read_transport(name)[1].get("method")
            scale = 1.0 if method in _DEMUX_METHODS else float(signal_scale)
            used.append({"store": str(name), "method": method, "scale": scale})
        elif is_scene_name(name):
            scene = make_scene(name, tuple(int(n) for n in shape), projector_rows=projector_rows, seed=int(seed))
            scale = float(signal_scale)
            used.append({"scene": name, "scale": scale})
        else:
            raise InputError(
                f"prior {name!r}: not a transport store and not a scene name (scenes: {', '.join(list_scenes())}; "
                f"{PRIOR_ALL_SCENES!r} for all of them, {PRIOR_SMOOTH!r} for the smoothness prior)"
            )
        x, a = _sample(scene, int(pixels), rng, K, offsets)
        X.append(scale * x)
        albedo.append(a)
    kernel = _smooth_kernel(offsets, smooth_rows)
    description = {
        "sources": sources,
        "used": used,
        "shape": [int(n) for n in shape],
        "projector_rows": int(projector_rows),
        "support_rows": K,
        "pixels_per_source": int(pixels),
        "seed": int(seed),
        "signal_scale": float(signal_scale),
        "smooth_rows": float(smooth_rows),
    }
    if smooth_only:
        from ..scenes import footprint_kernel

        geometry = RowGeometry(int(shape[0]), int(projector_rows))
        mean = 0.5 * float(signal_scale) * footprint_kernel(offsets, geometry.rows_per_camera_row)
        S = np.outer(mean, mean) + float(mean @ mean) / float(np.trace(kernel)) * kernel
        description["smooth_weight"] = 1.0
        return TransportPrior(offsets, S, mean, 0.5, 0, description)
    X = np.concatenate(X)
    S = X.T @ X / len(X)
    if PRIOR_SMOOTH in names or smooth_weight > 0:
        w = 1.0 if PRIOR_SMOOTH in names and smooth_weight == 0 else float(smooth_weight)
        S = S + w * float(np.trace(S)) / float(np.trace(kernel)) * kernel
        description["smooth_weight"] = w
    else:
        description["smooth_weight"] = 0.0
    return TransportPrior(offsets, S, X.mean(axis=0), float(np.mean(np.concatenate(albedo))), len(X), description)
