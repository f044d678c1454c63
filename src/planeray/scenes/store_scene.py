"""A transport store as a scene: sweep any ``T`` on the simulated Episcan.

``planeray simulate T.zarr --out S.zarr`` captures a delay-exposure sweep of a
transport that planeray did not build itself: a render (``planeray render``,
perhaps at thousands of samples per pixel), a demultiplexed capture
(``planeray demux``) or a store a user wrote with plain ``zarr`` following the
transport-store contract (README, "File formats").  The store's size and
projector rows are the scene's; its optional per-pixel maps supply the rest:

* ``direct``: the direct light (else the epipolar image of ``T``, Eq. 5);
* ``ambient_albedo``: the reflectance under room light (else the image under
  full projector illumination, clipped to ``[0, 1]``: ``T`` is in units of a
  white surface facing the projector, so that image is the reflectance a
  diffuse scene would show);
* ``labels``: the effect labels (else 0, "none", everywhere).

Which of them came from the store is recorded in the scene's parameters
(``maps_from_store``), and so in the stack's metadata.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .base import Scene

__all__ = ["is_transport_store", "scene_from_transport_store"]


def is_transport_store(path) -> bool:
    """True when ``path`` is a planeray transport store (its Zarr ``format`` attribute)."""
    from ..io import store_format

    return store_format(path) == "transport"


def _refuse_negative(transport, path) -> None:
    """Light transport is non-negative: a store with negative entries is no scene (a pinv demux, a bug, a sign)."""
    dense = np.asarray(transport.dense)
    sparse = np.asarray(transport.sparse.value) if transport.sparse is not None else np.zeros(0)
    n = int((dense < 0).sum() + (sparse < 0).sum())
    if n:
        low = float(min(dense.min(initial=0.0), sparse.min(initial=0.0)))
        raise InputError(
            f"T has {n} negative entries (down to {low:.3g}): light transport is non-negative, so it is no scene to "
            "simulate; clip it (numpy.clip(T, 0, None)) or demultiplex with a non-negative method (fast, nnls)",
            path,
        )


def scene_from_transport_store(path, *, shape=None, projector_rows=None) -> Scene:
    """A :class:`Scene` whose ground truth is the transport stored at ``path``.

    Parameters
    ----------
    path : str or os.PathLike
        A transport store (``T`` + ``offsets_rows``; :func:`planeray.io.read_transport`).
    shape : (int, int), optional
        Expected camera size ``(H, W)``; a store of another size is refused.
    projector_rows : int, optional
        Expected projector rows; a store with others is refused.

    Returns
    -------
    Scene
        Named ``store:PATH``; ``params`` record the store's path, its method
        (``attrs["method"]``) and which maps it supplied.

    Raises
    ------
    planeray.errors.TransportError
        The store cannot be read (one line naming it and the problem).
    planeray.errors.InputError
        Its size or projector rows differ from ``shape`` / ``projector_rows``.
    """
    from ..io import read_transport, read_transport_maps

    path = Path(path)
    transport, attrs = read_transport(path)
    H, W = transport.shape
    P = transport.geometry.projector_rows
    if shape is not None and tuple(int(s) for s in shape) != (H, W):
        raise InputError(f"the store is {H}x{W} pixels, --size asks for {shape[0]}x{shape[1]}", path)
    if projector_rows is not None and int(projector_rows) != P:
        raise InputError(f"the store has {P} projector rows, --projector-rows asks for {projector_rows}", path)
    _refuse_negative(transport, path)
    maps = read_transport_maps(path)
    used = []

    def take(name, fallback):
        value = maps.get(name)
        if value is not None and value.shape == (H, W) and np.all(np.isfinite(value)):
            used.append(name)
            return value
        return fallback()

    direct = take("direct", transport.epipolar_image).astype(np.float32)
    ambient = take("ambient_albedo", lambda: np.clip(transport.full_image(), 0.0, 1.0)).astype(np.float32)
    labels = take("labels", lambda: np.zeros((H, W), np.uint8))
    labels = np.clip(np.asarray(labels), 0, 4).astype(np.uint8)
    params = {
        "store": str(path),
        "store_method": attrs.get("method"),
        "maps_from_store": used,
    }
    extra = {k: v for k, v in maps.items() if k not in ("direct", "ambient_albedo", "labels") and v.shape == (H, W)}
    return Scene(f"store:{path}", transport, direct, ambient, labels, params, extra)
