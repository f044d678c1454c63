"""The transport store (Zarr v3 group: ``T`` + ``offsets_rows`` and optional sparse entries)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import zarr

from ..errors import TransportError
from ..timing import RowGeometry
from ..transport import SparseEntries, Transport
from ._common import (
    ALL_CHUNKS_ATTR,
    FORMAT_VERSION,
    SPARSE_ARRAYS,
    TRANSPORT_FORMAT,
    check_chunks,
    create_array,
    get_array,
    is_integer,
    is_number,
    jsonable,
    open_group,
    planeray_version,
    read_array,
    read_vector,
)
from .atomic import atomic_directory


# ----------------------------------------------------------------------------
def transport_attrs(offsets_rows, projector_rows: int, *, attrs: dict | None = None, path=None) -> dict:
    """Group attributes of a transport store: ``attrs`` plus the reserved format fields.

    Used by :func:`write_transport` and by writers that fill a store chunk by chunk
    (:func:`planeray.demux.demultiplex_to_store`), so both produce the same format.
    The attributes mark the store ``all_chunks_stored``: such a writer must store
    every chunk of every array, also those equal to the fill value (create them
    with :func:`planeray.io.create_array`, write through
    :func:`planeray.io.writable`), or :func:`read_transport` refuses the store.

    Parameters
    ----------
    offsets_rows : array_like of int
        The offsets ``u`` of the dense band, projector rows.
    projector_rows : int
        Projector rows spanned by the image height.
    attrs : dict, optional
        The caller's attributes (JSON-serializable).
    path : str or path, optional
        The store, for error messages.

    Returns
    -------
    dict
        ``attrs`` with the reserved format fields.

    See Also
    --------
    planeray.write_transport : writes them.

    Examples
    --------
    >>> import numpy as np
    >>> attrs = transport_attrs(np.arange(-3, 4), 720, attrs={"note": "example"})
    >>> attrs["projector_rows"], attrs["note"]
    (720, 'example')
    """
    out = jsonable(dict(attrs or {}), finite=False, where="attrs", error=TransportError)
    out.update(
        {
            "format": TRANSPORT_FORMAT,
            "format_version": FORMAT_VERSION,
            "offsets_rows": [int(u) for u in offsets_rows],
            "projector_rows": int(projector_rows),
            "lines_per_second": out.get("lines_per_second"),
            ALL_CHUNKS_ATTR: True,
        }
    )
    out.setdefault("planeray_version", planeray_version())
    return out


def read_transport_maps(path) -> dict:
    """Per-pixel 2-D arrays stored beside ``T`` (e.g. demultiplexing diagnostics), by name.

    Parameters
    ----------
    path : str or path
        A transport store.

    Returns
    -------
    dict of str to ndarray (H, W)
        The maps by name (``converged``, ``iterations``, ``objective``, ...).

    Raises
    ------
    TransportError
        The store cannot be opened, a chunk of a map is absent from a store marked
        ``all_chunks_stored`` or cannot be decoded (naming the map and the rows).

    See Also
    --------
    planeray.read_transport : the transport itself.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("corner", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     maps = read_transport_maps(pr.demultiplex_to_store(stack, pathlib.Path(tmp) / "T.zarr"))
    >>> maps["converged"].shape
    (8, 8)
    """
    path = Path(path)
    group = open_group(path, TransportError)
    try:
        members = sorted(group.members())
    except Exception as exc:
        raise TransportError(f"cannot list the arrays ({type(exc).__name__}: {exc})", path) from exc
    maps = {}
    for name, member in members:
        if name != "T" and name not in SPARSE_ARRAYS and isinstance(member, zarr.Array) and len(member.shape) == 2:
            check_chunks(group, member, name, path, TransportError)
            maps[name] = read_array(member, ..., path=path, error=TransportError, name=name)
    return maps


def write_transport(
    transport: Transport, path, *, attrs: dict | None = None, overwrite: bool = False, arrays: dict | None = None
) -> Path:
    """Write a transport to a Zarr v3 store, atomically.

    Parameters
    ----------
    transport : Transport
    path : str or os.PathLike
        Store directory to create.
    attrs : dict, optional
        Extra JSON attributes (``lines_per_second``, ``alpha``, ``beta``,
        ``method``...).  The reserved attributes ``format``, ``format_version``,
        ``offsets_rows`` and ``projector_rows`` always describe ``transport``, so
        the dict returned by :func:`read_transport` can be passed back unchanged.
    overwrite : bool
        Replace an existing store at ``path`` (atomically).
    arrays : dict of str to ndarray, optional
        Further arrays stored beside ``T`` in the same atomic write (per-pixel
        ``(H, W)`` maps, read back by :func:`read_transport_maps`, or others such
        as a rendered scene's colour band ``T_rgb``).  Names may not be ``T`` or
        a sparse array's.

    Returns
    -------
    path : pathlib.Path

    Raises
    ------
    TransportError
        ``path`` exists and ``overwrite`` is False, or ``attrs`` is not
        JSON-serializable.

    See Also
    --------
    read_transport : read it back.
    planeray.demultiplex_to_store : demultiplex straight into a store.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> T = pr.make_scene("corner", (8, 8), seed=0).transport
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     pr.write_transport(T, pathlib.Path(tmp) / "T.zarr").name
    'T.zarr'
    """
    path = Path(path)
    if not isinstance(transport, Transport):
        raise TransportError(f"expected a Transport, got {type(transport).__name__}", path)
    out = transport_attrs(transport.offsets_rows, transport.geometry.projector_rows, attrs=attrs, path=path)
    dense = np.asarray(transport.dense, dtype=np.float32)
    h, w, u = dense.shape
    arrays = dict(arrays or {})
    for name in arrays:
        if name == "T" or name in SPARSE_ARRAYS:
            raise TransportError(f"array name {name!r} is reserved", path)
    with atomic_directory(path, overwrite=overwrite, kind="transport", error=TransportError) as tmp:
        group = zarr.open_group(str(tmp), mode="w", zarr_format=3)
        chunks = (max(min(h, 64), 1), max(min(w, 64), 1), max(u, 1))
        # every chunk is stored, zero blocks too (the store is marked all_chunks_stored)
        array = create_array(group, "T", shape=dense.shape, chunks=chunks, dtype="float32", fill_value=0.0)
        array[...] = dense
        sparse = transport.sparse
        if sparse is not None and len(sparse):
            create_array(group, "sparse_row", data=np.asarray(sparse.row, dtype=np.int32))
            create_array(group, "sparse_col", data=np.asarray(sparse.col, dtype=np.int32))
            create_array(group, "sparse_offset", data=np.asarray(sparse.offset, dtype=np.int32))
            create_array(group, "sparse_value", data=np.asarray(sparse.value, dtype=np.float32))
        for name, data in arrays.items():
            create_array(group, name, data=np.asarray(data))
        group.attrs.update(out)
    return path


def read_transport(path) -> tuple[Transport, dict]:
    """Read a transport store written by :func:`write_transport`.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    transport : Transport
    attrs : dict
        All group attributes (``offsets_rows``, ``lines_per_second``, ...).

    Raises
    ------
    TransportError
        Naming the path and the problem (missing ``T``, wrong shape, offsets that
        do not match ``T``, non-finite values, malformed sparse entries, a chunk
        absent from a store marked ``all_chunks_stored`` -- e.g. ``T: chunk (1, 0,
        0) is missing (rows 64-127) -- the store is incomplete`` -- or a chunk that
        cannot be decoded).

    See Also
    --------
    write_transport : write one.
    planeray.demultiplex_to_store : demultiplex into one.

    Notes
    -----
    Stores written by this version of planeray store every chunk and carry the
    attribute ``all_chunks_stored = true``; older stores, which skipped chunks
    equal to the fill value, are read with absent chunks as 0.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> T = pr.make_scene("corner", (8, 8), seed=0).transport
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pr.write_transport(T, pathlib.Path(tmp) / "T.zarr", attrs={"note": "ground truth"})
    ...     back, attrs = pr.read_transport(path)
    >>> back.dense.shape == T.dense.shape, attrs["note"]
    (True, 'ground truth')
    """
    path = Path(path)
    group = open_group(path, TransportError)
    attrs = dict(group.attrs)
    fmt = attrs.get("format")
    if fmt is not None and fmt != TRANSPORT_FORMAT:
        raise TransportError(f"not a planeray transport (format is {fmt!r})", path)
    version = attrs.get("format_version", FORMAT_VERSION)
    if not is_integer(version) or int(version) > FORMAT_VERSION:
        raise TransportError(
            f"unsupported format_version {version!r} (this planeray reads up to {FORMAT_VERSION})", path
        )
    array = get_array(group, "T", path, TransportError)
    if len(array.shape) != 3:
        raise TransportError(f"array 'T' must be (H, W, U), got shape {tuple(array.shape)}", path)
    h, w, u = (int(x) for x in array.shape)
    offsets = attrs.get("offsets_rows")
    if offsets is None:
        raise TransportError("missing attribute 'offsets_rows'", path)
    if not isinstance(offsets, list) or not all(is_integer(o) for o in offsets):
        raise TransportError("attribute 'offsets_rows' must be a list of integers", path)
    if len(offsets) != u:
        raise TransportError(f"{len(offsets)} offsets_rows for array 'T' with U = {u}", path)
    projector_rows = attrs.get("projector_rows")
    if projector_rows is not None and (not is_integer(projector_rows) or projector_rows < 1):
        raise TransportError(f"attribute 'projector_rows' must be a positive integer, got {projector_rows!r}", path)
    lps = attrs.get("lines_per_second")
    if lps is not None and (not is_number(lps) or not math.isfinite(lps) or lps <= 0):
        raise TransportError(f"attribute 'lines_per_second' must be a positive number or null, got {lps!r}", path)
    check_chunks(group, array, "T", path, TransportError)
    dense = read_array(array, ..., path=path, error=TransportError, name="T").astype(np.float32, copy=False)
    if not np.all(np.isfinite(dense)):
        raise TransportError("array 'T' contains NaN or infinite values", path)

    present = [name for name in SPARSE_ARRAYS if group.get(name) is not None]
    sparse = SparseEntries.empty()
    if present:
        missing = [name for name in SPARSE_ARRAYS if name not in present]
        if missing:
            raise TransportError(f"missing array '{missing[0]}' (sparse entries need all of {SPARSE_ARRAYS})", path)
        members = [get_array(group, name, path, TransportError) for name in SPARSE_ARRAYS]
        if len(members[0].shape) != 1:
            raise TransportError(f"array 'sparse_row' must be 1-D, got shape {tuple(members[0].shape)}", path)
        m = int(members[0].shape[0])
        for member, name in zip(members, SPARSE_ARRAYS):
            check_chunks(group, member, name, path, TransportError)
        data = [read_vector(a, name, m, path, TransportError) for a, name in zip(members, SPARSE_ARRAYS)]
        row, col, offset, value = data
        if not np.all(np.isfinite(value)):
            raise TransportError("array 'sparse_value' contains NaN or infinite values", path)
        if np.any((row < 0) | (row >= h)) or np.any((col < 0) | (col >= w)):
            raise TransportError(f"sparse entries outside the {h}x{w} image", path)
        sparse = SparseEntries(row, col, offset, value)
    try:
        geometry = RowGeometry(h, None if projector_rows is None else int(projector_rows))
        transport = Transport(dense, np.asarray(offsets, dtype=np.int64), geometry, sparse)
    except ValueError as exc:
        raise TransportError(str(exc), path) from exc
    return transport, attrs
