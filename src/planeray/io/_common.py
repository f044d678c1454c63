"""Shared pieces of the on-disk formats: format names, versions, JSON and Zarr helpers."""

from __future__ import annotations

import os
from importlib import metadata as _importlib_metadata
from pathlib import Path

import numpy as np
import zarr

from ..errors import StackError

STACK_FORMAT = "planeray-stack"
TRANSPORT_FORMAT = "planeray-transport"
FORMAT_VERSION = 1

STACK_ARRAYS = ("images", "delay_us", "exposure_us", "excluded")
SPARSE_ARRAYS = ("sparse_row", "sparse_col", "sparse_offset", "sparse_value")
IMAGE_SUFFIXES = {".tif": "tiff", ".tiff": "tiff", ".png": "png"}


def planeray_version() -> str:
    """The installed planeray version (``"unknown"`` in a bare source checkout)."""
    try:
        return _importlib_metadata.version("planeray")
    except _importlib_metadata.PackageNotFoundError:  # pragma: no cover - source checkout
        return "unknown"


# ----------------------------------------------------------------------------
def jsonable(value, where: str = "metadata", error=StackError):
    """Convert numpy scalars/arrays, tuples and paths to plain JSON types (recursively)."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, float)):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist(), where, error)
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            if not isinstance(key, (str, int, float, bool, np.integer)):
                raise error(f"{where} key {key!r} is not a string")
            out[str(key)] = jsonable(item, f"{where}[{str(key)!r}]", error)
        return out
    if isinstance(value, (list, tuple)):
        return [jsonable(item, f"{where}[{i}]", error) for i, item in enumerate(value)]
    raise error(f"{where} is not JSON-serializable (type {type(value).__name__})")


def open_group(path: Path, error):
    """Open a Zarr group read-only, turning every failure into ``error``."""
    if not path.exists():
        raise error("path does not exist", path)
    if not path.is_dir():
        raise error("not a Zarr store (expected a directory)", path)
    try:
        return zarr.open_group(str(path), mode="r")
    except Exception as exc:  # zarr raises several unrelated types
        raise error(f"not a Zarr group ({type(exc).__name__}: {exc})", path) from exc


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
    try:
        return np.asarray(array[...])
    except Exception as exc:
        raise error(f"cannot read array '{name}' ({type(exc).__name__}: {exc})", path) from exc


def is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def is_integer(value) -> bool:
    return is_number(value) and float(value).is_integer()


# ----------------------------------------------------------------------------
class LazyArray:
    """Read-only view of an on-disk Zarr array that behaves like a NumPy array.

    zarr 3 arrays have ``shape`` and slicing but no ``len()``, which
    :class:`~planeray.stack.Stack` needs; this thin wrapper adds it.  Indexing
    reads only the chunks touched and returns NumPy arrays.

    Parameters
    ----------
    array : zarr.Array
        The array to wrap (kept as :attr:`array`).
    """

    def __init__(self, array):
        self.array = array

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
        return np.asarray(self.array[key])

    def __iter__(self):
        for i in range(len(self)):
            yield self[i]

    def __array__(self, dtype=None, copy=None):
        data = np.asarray(self.array[...])
        return data if dtype is None else data.astype(dtype, copy=False)

    def __repr__(self) -> str:
        return f"LazyArray(shape={self.shape}, dtype={self.dtype}, store={self.array.store_path})"
