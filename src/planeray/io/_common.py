"""Shared pieces of the on-disk formats: format names, versions, JSON and Zarr helpers.

Chunk safety
------------
zarr 3 does not store a chunk that equals the array's fill value (its
``write_empty_chunks`` setting is off by default) and reads an absent chunk as the
fill value.  A deleted or never-copied chunk file is then indistinguishable from
"all zeros", so a damaged store would be read silently wrong.  planeray therefore
writes its stores so that *every* chunk is on disk (:func:`create_array` and
:func:`writable` turn ``write_empty_chunks`` on; it is a runtime setting that is
not saved in the store, so every writer that reopens a store must use
:func:`writable`) and marks them with the group attribute
``all_chunks_stored = true`` (:data:`ALL_CHUNKS_ATTR`).  Readers refuse a marked
store with an absent chunk (:func:`check_chunks`).  Stores written before the
marker existed may legitimately lack all-fill-value chunks (an all-False
``saturated`` mask, a zero band of ``T``), so for them absent chunks still read
as the fill value: there is nothing to check them against.

New arrays are compressed with zstd *with its content checksum*
(:data:`COMPRESSORS`, standard Zarr v3 codec metadata that plain ``zarr`` reads),
so a chunk whose bytes were altered fails to decode instead of decoding to
wrong numbers; every decoding failure becomes one :class:`StackError` or
:class:`TransportError` naming the store, the array and the chunk
(:func:`read_array`).
"""

from __future__ import annotations

import math
import os
from importlib import metadata as _importlib_metadata
from pathlib import Path

import numpy as np
import zarr
from zarr.codecs import ZstdCodec

from ..errors import StackError

STACK_FORMAT = "planeray-stack"
TRANSPORT_FORMAT = "planeray-transport"
FORMAT_VERSION = 1

STACK_ARRAYS = ("images", "delay_us", "exposure_us", "excluded")
SPARSE_ARRAYS = ("sparse_row", "sparse_col", "sparse_offset", "sparse_value")
IMAGE_SUFFIXES = {".tif": "tiff", ".tiff": "tiff", ".png": "png"}

#: Group attribute of stores whose every chunk is stored (see the module docstring).
ALL_CHUNKS_ATTR = "all_chunks_stored"
#: zarr runtime configuration of planeray's writers: store chunks equal to the fill value too.
WRITE_CONFIG = {"write_empty_chunks": True}
#: Compression of new arrays: zstd (zarr's default level) with a content checksum.
COMPRESSORS = (ZstdCodec(level=0, checksum=True),)

#: Names of the axes of each planeray array, for error messages (see :func:`describe_region`).
AXES = {
    "images": ("image", "rows", "columns"),
    "saturated": ("image", "rows", "columns"),
    "T": ("rows", "columns", "offsets"),
}


def store_format(path) -> str | None:
    """``"stack"``, ``"transport"`` or None: what planeray store (or import folder) ``path`` is.

    Read from the Zarr group's ``format`` attribute (``zarr.json``) without opening
    the arrays; a folder with a ``manifest.csv`` is a stack import folder.

    Parameters
    ----------
    path : str or path
        A folder.

    Returns
    -------
    {"stack", "transport"} or None

    See Also
    --------
    planeray.read_stack, planeray.read_transport

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pr.write_transport(pr.make_scene("corner", (8, 8), seed=0).transport, pathlib.Path(tmp) / "T.zarr")
    ...     store_format(path), store_format(tmp)
    ('transport', None)
    """
    import json

    path = Path(path)
    if not path.is_dir():
        return None
    if (path / "manifest.csv").is_file():
        return "stack"
    meta = path / "zarr.json"
    if meta.is_file():
        try:
            attrs = json.loads(meta.read_text(encoding="utf-8")).get("attributes") or {}
        except (OSError, ValueError, AttributeError):
            return None
        if isinstance(attrs, dict):
            return {STACK_FORMAT: "stack", TRANSPORT_FORMAT: "transport"}.get(attrs.get("format"))
    return None


def planeray_version() -> str:
    """The installed planeray version (``"unknown"`` in a bare source checkout).

    Returns
    -------
    str
        The distribution's version, as ``planeray --version`` prints it.

    See Also
    --------
    planeray.io.marks.mark_text : the mark planeray writes into its files, with this version.

    Examples
    --------
    >>> isinstance(planeray_version(), str)
    True
    """
    try:
        return _importlib_metadata.version("planeray")
    except _importlib_metadata.PackageNotFoundError:  # pragma: no cover - source checkout
        return "unknown"


# ----------------------------------------------------------------------------
def jsonable(value, *, finite: bool = True, default=None, where: str = "metadata", error=None):
    """``value`` as plain JSON types, for :func:`json.dumps`: the one conversion of every file planeray writes.

    Dicts (keys as ``str``), lists and tuples (as lists) are converted element by element; NumPy
    arrays and scalars become Python lists and numbers; paths become text.

    Parameters
    ----------
    value : object
        What to convert.
    finite : bool
        ``True`` (records and reports): a non-finite float (NaN, +-inf) becomes ``None`` (JSON
        ``null``), so the text is strict JSON. ``False``: kept (written ``NaN`` / ``Infinity``).
    default : callable, optional
        Applied to any other object (e.g. ``str``).
    where, error : str, exception class, optional
        With ``error`` (e.g. :class:`~planeray.errors.StackError`), any other object, or a dict key
        that is not text or a number, raises ``error`` naming ``where`` (``"metadata['a'][2]"``);
        without ``error`` or ``default`` such an object is returned as it is (and
        :func:`json.dumps` refuses it).

    Returns
    -------
    object
        The value in plain JSON types (dicts, lists, floats, ints, strings, booleans, None).

    See Also
    --------
    planeray.write_stack : its metadata passes through it.

    Examples
    --------
    >>> jsonable({"a": np.float32(0.5), 1: [np.int64(2), float("nan")], "m": np.eye(2, dtype=bool)})
    {'a': 0.5, '1': [2, None], 'm': [[True, False], [False, True]]}
    >>> jsonable([np.inf], finite=False)
    [inf]
    """

    def convert(value, where):
        if isinstance(value, dict):
            out = {}
            for key, item in value.items():
                if error is not None and not isinstance(key, (str, int, float, bool, np.integer)):
                    raise error(f"{where} key {key!r} is not a string")
                out[str(key)] = convert(item, f"{where}[{str(key)!r}]")
            return out
        if isinstance(value, (list, tuple)):
            return [convert(item, f"{where}[{i}]") for i, item in enumerate(value)]
        if isinstance(value, np.ndarray):
            return convert(value.tolist(), where)
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, float):
            return None if finite and not math.isfinite(value) else value
        if value is None or isinstance(value, (str, int)):
            return value
        if isinstance(value, os.PathLike):
            return os.fspath(value)
        if default is not None:
            return default(value)
        if error is not None:
            raise error(f"{where} is not JSON-serializable (type {type(value).__name__})")
        return value

    return convert(value, where)


def open_group(path: Path, error):
    """Open a Zarr group read-only, turning every failure into ``error``."""
    if not path.exists():
        raise error("path does not exist", path)
    if not path.is_dir():
        raise error("not a Zarr store (expected a directory)", path)
    if not (path / "zarr.json").is_file():
        raise error("not a planeray store: no zarr.json (stacks and transports are Zarr v3 folders)", path)
    try:
        return zarr.open_group(str(path), mode="r")
    except Exception as exc:  # zarr raises several unrelated types
        cause = " ".join(str(exc).split()) or type(exc).__name__
        raise error(f"not a readable Zarr group: {cause}", path) from exc


def get_array(group, name: str, path: Path, error, required: bool = True):
    try:
        member = group.get(name)
    except Exception as exc:
        raise error(f"cannot open array '{name}' ({type(exc).__name__}: {exc})", path) from exc
    if member is None:
        if required:
            raise error(f"missing array '{name}'", path)
        return None
    if not isinstance(member, zarr.Array):
        raise error(f"'{name}' is a group, expected an array", path)
    return member


def read_vector(array, name: str, n: int, path: Path, error) -> np.ndarray:
    if len(array.shape) != 1 or array.shape[0] != n:
        raise error(f"array '{name}' has shape {tuple(array.shape)}, expected ({n},)", path)
    return read_array(array, ..., path=path, error=error, name=name)


# ----------------------------------------------------------------------------
# writing every chunk, finding absent and undecodable chunks
# ----------------------------------------------------------------------------
def create_array(group, name: str, **kwargs):
    """``group.create_array(name, **kwargs)`` storing every chunk, zstd with checksum.

    The returned array has ``write_empty_chunks`` on; an array reopened later
    does not (see :func:`writable`).

    Parameters
    ----------
    group : zarr.Group
        The store's group.
    name : str
        The array's name.
    **kwargs
        ``shape``, ``chunks``, ``dtype``, ``fill_value``... as for ``zarr.Group.create_array``.

    Returns
    -------
    zarr.Array

    See Also
    --------
    writable : the same setting for an array opened again.

    Examples
    --------
    >>> import zarr
    >>> group = zarr.open_group(zarr.storage.MemoryStore(), mode="w")
    >>> create_array(group, "T", shape=(4, 4), chunks=(2, 4), dtype="float32").shape
    (4, 4)
    """
    kwargs.setdefault("compressors", COMPRESSORS)
    return group.create_array(name, config=WRITE_CONFIG, **kwargs)


def writable(group, name: str):
    """``group[name]`` set to store every chunk, also those equal to the fill value.

    ``write_empty_chunks`` is a runtime setting that zarr does not save in the
    store: a writer that reopens a store (a resumed run) must get its arrays
    through this function, or the chunks it writes that equal the fill value are
    skipped and the store, marked :data:`ALL_CHUNKS_ATTR`, is refused on reading.

    Parameters
    ----------
    group : zarr.Group
        The store's group, opened for writing.
    name : str
        The array's name.

    Returns
    -------
    zarr.Array

    See Also
    --------
    create_array : a new array so set.

    Examples
    --------
    >>> import zarr
    >>> group = zarr.open_group(zarr.storage.MemoryStore(), mode="w")
    >>> _ = create_array(group, "done", shape=(3,), chunks=(3,), dtype="bool", fill_value=False)
    >>> writable(group, "done").shape
    (3,)
    """
    return group[name].with_config(WRITE_CONFIG)


def _one_line(text) -> str:
    return " ".join(str(text).split())


def _stored_grid(array) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Block shape of the stored objects (shards if sharded, else chunks) and the grid shape."""
    shards = getattr(array, "shards", None)
    block = tuple(int(c) for c in (shards or array.chunks))
    grid = tuple(-(-int(n) // c) if c else 0 for n, c in zip(array.shape, block))
    return block, grid


def _axes(name: str, ndim: int) -> tuple[str, ...]:
    axes = AXES.get(name) or {1: ("entries",), 2: ("rows", "columns")}.get(ndim, ())
    return axes if len(axes) == ndim else tuple(f"axis {k}" for k in range(ndim))


def _describe_bounds(bounds, shape, name: str) -> str:
    """Words for the index ranges ``bounds`` (``[start, stop)`` per axis): ``"image 12, rows 64-95"``.

    Axes are named after :data:`AXES` (``"rows"``, ``"columns"`` for 2-D maps,
    ``"entries"`` for vectors); an axis other than the first that is covered
    entirely is not mentioned.
    """
    words = []
    for k, ((lo, hi), n, axis) in enumerate(zip(bounds, shape, _axes(name, len(shape)))):
        if k > 0 and lo == 0 and hi == n:
            continue
        if axis == "image":
            axis = "image" if hi - lo == 1 else "images"
        words.append(f"{axis} {lo}" if hi - lo == 1 else f"{axis} {lo}-{hi - 1}")
    return ", ".join(words) or "the whole array"


def describe_region(array, name: str, coords) -> str:
    """Words for the part of ``array`` held by chunk ``coords`` (see :func:`_describe_bounds`)."""
    block, _ = _stored_grid(array)
    shape = tuple(int(n) for n in array.shape)
    return _describe_bounds([(s.start, s.stop) for s in _chunk_selection(coords, block, shape)], shape, name)


def absent_chunks(array) -> tuple[list[tuple[int, ...]], int]:
    """Grid coordinates of the chunks of ``array`` that are not in its store, and the chunk count.

    On a local directory store this is one ``stat`` per chunk (about 10 ms for
    the 1360 chunks of a 512x512x85 ``images`` array); other stores are listed
    through zarr.
    """
    block, grid = _stored_grid(array)
    total = int(np.prod(grid, dtype=np.int64))
    if total == 0:
        return [], 0
    encode = array.metadata.chunk_key_encoding.encode_chunk_key
    store = array.store_path.store
    root = getattr(store, "root", None)
    if isinstance(store, zarr.storage.LocalStore) and root is not None:
        prefix = os.path.join(os.fspath(root), *array.store_path.path.split("/"), "")
        exists = os.path.exists
        missing = [c for c in np.ndindex(*grid) if not exists(prefix + encode(c))]
    else:  # pragma: no cover - planeray opens local directories only
        from zarr.core.sync import sync

        async def listing():
            return {key async for key in store.list_prefix(array.store_path.path)}

        keys = sync(listing())
        base = array.store_path.path.rstrip("/") + "/" if array.store_path.path else ""
        missing = [c for c in np.ndindex(*grid) if base + encode(c) not in keys]
    return [tuple(int(i) for i in c) for c in missing], total


def check_chunks(group, array, name: str, path, error) -> None:
    """Raise ``error`` if ``group`` is marked :data:`ALL_CHUNKS_ATTR` and a chunk of ``array`` is absent.

    Without the marker (stores written by planeray before it existed, or by other
    tools) nothing is checked: zarr reads an absent chunk as the fill value.
    """
    if group.attrs.get(ALL_CHUNKS_ATTR) is not True:
        return
    missing, total = absent_chunks(array)
    if missing:
        first = missing[0]
        more = f" ({len(missing)} of {total} chunks missing)" if len(missing) > 1 else ""
        raise error(
            f"{name}: chunk {first} is missing ({describe_region(array, name, first)}) -- the store is incomplete{more}",
            path,
        )


def _bounds(key, shape) -> list[tuple[int, int]]:
    """Per-axis index range ``[start, stop)`` that a basic selection touches (whole axes otherwise)."""
    full = [(0, int(n)) for n in shape]
    if not isinstance(key, tuple):
        key = (key,)
    if sum(k is Ellipsis for k in key) > 1:
        return full
    if Ellipsis in key:
        at = key.index(Ellipsis)
        key = key[:at] + (slice(None),) * (len(shape) - len(key) + 1) + key[at + 1 :]
    if len(key) > len(shape):
        return full
    out = list(full)
    for axis, k in enumerate(key):
        n = int(shape[axis])
        if isinstance(k, (int, np.integer)) and not isinstance(k, bool):
            i = int(k) + n if k < 0 else int(k)
            if 0 <= i < n:
                out[axis] = (i, i + 1)
        elif isinstance(k, slice):
            start, stop, step = k.indices(n)
            picked = range(start, stop, step)
            if len(picked):
                out[axis] = (min(picked[0], picked[-1]), max(picked[0], picked[-1]) + 1)
    return out


def _chunk_selection(coords, block, shape) -> tuple[slice, ...]:
    return tuple(slice(c * b, min((c + 1) * b, int(n))) for c, b, n in zip(coords, block, shape))


def read_array(array, key, *, path, error, name: str) -> np.ndarray:
    """``array[key]`` as a NumPy array; a chunk that cannot be read or decoded raises ``error``.

    The message names the store (``path``), the array, the first chunk in the
    selection that fails and the part of the array it holds, and the cause, in
    one line, e.g. ``s.zarr: images: cannot read chunk (12, 2, 0) (image 12,
    rows 64-95): RuntimeError: Zstd decompression error: ... -- the store is
    damaged``.
    """
    try:
        return np.asarray(array[key])
    except (MemoryError, IndexError, TypeError):
        raise  # out of memory, or a bad selection (zarr raises IndexError): not a bad store
    except Exception as exc:
        raise _read_error(array, key, exc, path, error, name) from exc


def _read_error(array, key, exc: Exception, path, error, name: str):
    """Find the chunk behind a failed read (one chunk at a time) and build the error."""
    cause = exc
    block, _ = _stored_grid(array)
    shape = tuple(int(n) for n in array.shape)
    bounds = _bounds(key, shape)
    ranges = [range(lo // b, -(-hi // b)) if b else range(0) for (lo, hi), b in zip(bounds, block)]
    for coords in np.ndindex(*(len(r) for r in ranges)):
        chunk = tuple(r[i] for r, i in zip(ranges, coords))
        try:
            array[_chunk_selection(chunk, block, shape)]
        except Exception as chunk_exc:  # the culprit
            cause = chunk_exc
            where = f"cannot read chunk {chunk} ({describe_region(array, name, chunk)})"
            break
    else:
        where = f"cannot read {_describe_bounds(bounds, shape, name)}"
    return error(f"{name}: {where}: {type(cause).__name__}: {_one_line(cause)} -- the store is damaged", path)


def is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def is_integer(value) -> bool:
    return is_number(value) and float(value).is_integer()


# ----------------------------------------------------------------------------
class LazyArray:
    """Read-only view of an on-disk Zarr array that behaves like a NumPy array.

    zarr 3 arrays have ``shape`` and slicing but no ``len()``, which
    :class:`~planeray.stack.Stack` needs; this thin wrapper adds it.  Indexing
    reads only the chunks touched and returns NumPy arrays.  A chunk that cannot
    be read or decoded (corrupt or truncated file, I/O error) raises ``error``
    naming the store, the array, the chunk and the cause in one line (see
    :func:`read_array`), never zarr's or the codec's own exception.

    Parameters
    ----------
    array : zarr.Array
        The array to wrap (kept as :attr:`array`).
    path : str or os.PathLike, optional
        The store, named in error messages (default: the array's store).
    error : type
        Exception class raised on a read failure (:class:`StackError` or
        :class:`~planeray.errors.TransportError`).
    name : str, optional
        The array's name in messages (default: its name in the store).

    See Also
    --------
    planeray.read_stack : gives its images as one.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("corner", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     lazy = pr.read_stack(pr.write_stack(stack, pathlib.Path(tmp) / "s.zarr")).images
    ...     type(lazy).__name__, lazy.shape, lazy[0].shape
    ('LazyArray', (27, 8, 8), (8, 8))
    """

    def __init__(self, array, *, path=None, error=StackError, name: str | None = None):
        self.array = array
        self.path = path if path is not None else str(array.store_path)
        self.error = error
        self.name = name if name is not None else str(array.store_path.path).rsplit("/", 1)[-1]

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(self.array.shape)

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(self.array.dtype)

    @property
    def ndim(self) -> int:
        return len(self.array.shape)

    @property
    def size(self) -> int:
        return int(np.prod(self.array.shape, dtype=np.int64))

    @property
    def chunks(self) -> tuple[int, ...]:
        return tuple(self.array.chunks)

    def __len__(self) -> int:
        return int(self.array.shape[0])

    def __getitem__(self, key) -> np.ndarray:
        return read_array(self.array, key, path=self.path, error=self.error, name=self.name)

    def __iter__(self):
        for i in range(len(self)):
            yield self[i]

    def update_digest(self, h) -> bool:
        """Feed the array's stored bytes (metadata + every chunk file, in order) to hash ``h``.

        Much cheaper than decoding every chunk (a 512x512x85 stack: ~0.2 s instead of
        ~2.6 s); identical stored bytes mean identical values.  Returns False (and feeds
        nothing) when the array is not in a local directory store; the caller then
        hashes decoded values instead.
        """
        root = getattr(self.array.store, "root", None)
        if root is None:
            return False
        base = Path(root) / str(self.array.store_path.path)
        try:
            h.update((base / "zarr.json").read_bytes())
            for chunk in sorted(p for p in base.rglob("*") if p.is_file() and p.name != "zarr.json"):
                h.update(str(chunk.relative_to(base)).encode())
                h.update(chunk.read_bytes())
        except OSError as exc:
            raise self.error(
                f"{self.name}: cannot read stored chunks ({type(exc).__name__}: {exc})", self.path
            ) from None
        return True

    def __array__(self, dtype=None, copy=None):
        data = self[...]
        return data if dtype is None else data.astype(dtype, copy=False)

    def __repr__(self) -> str:
        return f"LazyArray(shape={self.shape}, dtype={self.dtype}, store={self.array.store_path})"
