"""Reading and writing stacks, captured image folders and transports.

Three on-disk formats are handled here.  All writers are atomic: they write into a
temporary sibling (``.{name}.tmp-{uuid}`` in the same parent folder) and rename it
into place, so a crash or an error never leaves a half-written result at the
target path (see :func:`atomic_directory` and :func:`atomic_file`).

Native stack store
------------------
A Zarr v3 directory store (group) written by :func:`write_stack`, read by
:func:`read_stack`:

=================  ==========  =======  ==========================================
array              shape       dtype    content
=================  ==========  =======  ==========================================
``images``         (N, H, W)   float32  normalized images, chunked ``(1, 32, W)``
``saturated``      (N, H, W)   bool     saturation mask (all False if unknown)
``delay_us``       (N,)        float64  delay ``t_d`` of each image
``exposure_us``    (N,)        float64  exposure ``t_e`` of each image
``excluded``       (N,)        bool     images left out of demultiplexing
=================  ==========  =======  ==========================================

Group attributes: ``format = "planeray-stack"``, ``format_version = 1``,
``lines_per_second`` (float), ``projector_rows`` (int), ``metadata`` (the
:attr:`planeray.stack.Stack.metadata` dict, JSON) and ``planeray_version``.

Captured-stack import folder (public format)
--------------------------------------------
A folder read by :func:`import_folder` (and by :func:`read_stack` when the folder
holds a ``manifest.csv``), written by :func:`export_folder`::

    my_capture/
        manifest.csv
        acquisition.json
        img_0000.tif            (or .tiff / .png; any names, listed in the manifest)
        ...

``manifest.csv``
    Comma-separated, UTF-8, one header line, one line per image.  Required columns
    ``file,delay_us,exposure_us``; ``file`` is the image path relative to the
    folder, ``delay_us`` the delay ``t_d`` and ``exposure_us`` the exposure ``t_e``
    in microseconds (finite numbers, exposure > 0).  Optional column ``excluded``
    (``0``/``1``/``true``/``false``, case-insensitive) marks images left out of
    demultiplexing; without it the paper's boundary rule
    ``||t_d| - t_e/2| <= 75 us`` is applied
    (:func:`planeray.timing.boundary_images`).  Other columns are ignored.

images
    Single-channel (grayscale) 2-D images, all of the same size: 8- or 16-bit
    integer TIFF (``.tif``/``.tiff``) or PNG (``.png``), or float32/float64 TIFF
    holding raw codes.  Values are raw ADC codes and must not exceed
    ``2**bit_depth - 1``; float images must not contain NaN.

``acquisition.json``
    A JSON object with

    * ``lines_per_second`` (required, positive number): projector scanline
      velocity ``v_p`` (Eq. 2);
    * ``bit_depth`` (integer 1..16, default 12): ADC bit depth;
    * ``black_level`` (number >= 0 and < ``2**bit_depth - 1``, default 0): raw code
      of black;
    * ``projector_rows`` (integer, optional): projector rows spanned by the image
      height (default: the image height);
    * ``saturation_level`` (number, optional): raw code at or above which a pixel
      counts as saturated (default ``2**bit_depth - 1``);
    * ``planeray_metadata`` (object, optional): written by :func:`export_folder`;
      restored as the stack's metadata on import;
    * any other field, kept verbatim.

    Images are normalized as ``(raw - black_level) / (2**bit_depth - 1 -
    black_level)`` (float32) and a pixel is flagged saturated where ``raw >=
    saturation_level``.  The imported stack's metadata is ``planeray_metadata`` (if
    any) plus ``metadata["acquisition"]`` (the JSON object without
    ``planeray_metadata``) and ``metadata["source"] = "import:<folder>"``.

Transport store (public format)
-------------------------------
A Zarr v3 group written by :func:`write_transport`, read by :func:`read_transport`:
array ``T`` of shape ``(H, W, U)`` float32 (the dense band of
:class:`planeray.transport.Transport`) and attributes ``offsets_rows`` (the ``U``
consecutive integer offsets ``u = v - t``, in projector rows), ``lines_per_second``
(or null), ``projector_rows``, ``format = "planeray-transport"``,
``format_version = 1``, plus free-form attributes (``alpha``, ``beta``,
``method``...).  Sparse long-range entries, when there are any, are stored as the
1-D arrays ``sparse_row``, ``sparse_col``, ``sparse_offset`` (int32) and
``sparse_value`` (float32) of equal length.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import shutil
import uuid
from importlib import metadata as _importlib_metadata
from pathlib import Path

import numpy as np
import tifffile
import zarr
from PIL import Image

from .errors import InputError, StackError, TransportError
from .stack import Stack
from .timing import RowGeometry, boundary_images
from .transport import SparseEntries, Transport

__all__ = [
    "STACK_FORMAT",
    "TRANSPORT_FORMAT",
    "FORMAT_VERSION",
    "LazyArray",
    "atomic_directory",
    "atomic_file",
    "write_stack",
    "create_stack_group",
    "read_stack",
    "validate_images",
    "import_folder",
    "export_folder",
    "write_image",
    "write_transport",
    "read_transport",
    "read_transport_maps",
    "transport_attrs",
]

STACK_FORMAT = "planeray-stack"
TRANSPORT_FORMAT = "planeray-transport"
FORMAT_VERSION = 1

_STACK_ARRAYS = ("images", "delay_us", "exposure_us", "excluded")
_SPARSE_ARRAYS = ("sparse_row", "sparse_col", "sparse_offset", "sparse_value")
_IMAGE_SUFFIXES = {".tif": "tiff", ".tiff": "tiff", ".png": "png"}


def _planeray_version() -> str:
    try:
        return _importlib_metadata.version("planeray")
    except _importlib_metadata.PackageNotFoundError:  # pragma: no cover - source checkout
        return "unknown"


# ----------------------------------------------------------------------------
# Atomic writes
# ----------------------------------------------------------------------------
def _temp_sibling(path: Path, kind: str, suffix: str = "") -> Path:
    return path.parent / f".{path.name}.{kind}-{uuid.uuid4().hex}{suffix}"


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


@contextlib.contextmanager
def atomic_directory(path, overwrite: bool = False, *, error=InputError):
    """Write a directory atomically: yield a temporary sibling, rename it into place.

    Parameters
    ----------
    path : str or os.PathLike
        Final location of the directory.  Its parent is created if needed.
    overwrite : bool
        Replace an existing ``path``.  The old content is first renamed to a
        temporary backup, the new directory renamed into place, then the backup
        deleted, so ``path`` never holds a half-written result.
    error : type
        Exception class (an :class:`~planeray.errors.InputError`) raised when
        ``path`` exists and ``overwrite`` is False.

    Yields
    ------
    tmp : pathlib.Path
        Empty temporary directory ``.{name}.tmp-{uuid}`` next to ``path``; write
        everything there.  It is removed if the block raises.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise error("already exists (pass overwrite=True to replace it)", path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temp_sibling(path, "tmp")
    tmp.mkdir()
    try:
        yield tmp
        if path.exists() or path.is_symlink():
            if not overwrite:
                raise error("already exists (pass overwrite=True to replace it)", path)
            backup = _temp_sibling(path, "bak")
            os.rename(path, backup)
            try:
                os.rename(tmp, path)
            except BaseException:
                os.rename(backup, path)
                raise
            _remove(backup)
        else:
            os.rename(tmp, path)
    except BaseException:
        _remove(tmp)
        raise


@contextlib.contextmanager
def atomic_file(path, overwrite: bool = True, *, error=InputError):
    """Write a single file atomically: yield a temporary sibling, ``os.replace`` it.

    Parameters
    ----------
    path : str or os.PathLike
        Final file path.  Its parent is created if needed.
    overwrite : bool
        Replace an existing file (default True).
    error : type
        Exception class raised when ``path`` exists and ``overwrite`` is False.

    Yields
    ------
    tmp : pathlib.Path
        Temporary path ``.{name}.tmp-{uuid}{suffix}`` in the same folder (same
        suffix, so writers that pick a format by extension work); removed if the
        block raises.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise error("already exists (pass overwrite=True to replace it)", path)
    if path.is_dir():
        raise error("is a directory, expected a file path", path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temp_sibling(path, "tmp", path.suffix)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        _remove(tmp)
        raise


# ----------------------------------------------------------------------------
# JSON helpers
# ----------------------------------------------------------------------------
def _jsonable(value, where: str = "metadata", error=StackError):
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
        return _jsonable(value.tolist(), where, error)
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            if not isinstance(key, (str, int, float, bool, np.integer)):
                raise error(f"{where} key {key!r} is not a string")
            out[str(key)] = _jsonable(item, f"{where}[{str(key)!r}]", error)
        return out
    if isinstance(value, (list, tuple)):
        return [_jsonable(item, f"{where}[{i}]", error) for i, item in enumerate(value)]
    raise error(f"{where} is not JSON-serializable (type {type(value).__name__})")


# ----------------------------------------------------------------------------
# Lazy arrays
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


# ----------------------------------------------------------------------------
# Native stack store
# ----------------------------------------------------------------------------
def write_stack(stack: Stack, path, overwrite: bool = False, progress=None) -> Path:
    """Write a stack to a native Zarr v3 store, atomically.

    Parameters
    ----------
    stack : Stack
        The stack to write.  ``images`` (and ``saturated``) may be NumPy arrays or
        lazy arrays; they are copied one image at a time.
    path : str or os.PathLike
        Store directory to create.
    overwrite : bool
        Replace an existing store at ``path`` (atomically).
    progress : callable, optional
        Called as ``progress(i)`` after image ``i`` has been written.

    Returns
    -------
    path : pathlib.Path

    Raises
    ------
    StackError
        ``path`` exists and ``overwrite`` is False, an image is not finite or does
        not match the stack's shape, or the metadata is not JSON-serializable.
    """
    path = Path(path)
    if not isinstance(stack, Stack):
        raise StackError(f"expected a Stack, got {type(stack).__name__}", path)
    n, h, w = (int(x) for x in stack.images.shape)
    with atomic_directory(path, overwrite, error=StackError) as tmp:
        group = create_stack_group(tmp, (n, h, w), stack.delay_us, stack.exposure_us, stack.excluded,
                                   stack.lines_per_second, stack.projector_rows, stack.metadata, path)
        images, saturated = group["images"], group["saturated"]
        for i in range(n):
            image = np.asarray(stack.images[i], dtype=np.float32)
            if image.shape != (h, w):
                raise StackError(f"image {i} has shape {image.shape}, expected {(h, w)}", path)
            if not np.all(np.isfinite(image)):
                raise StackError(f"image {i} contains NaN or infinite values", path)
            images[i] = image
            if stack.saturated is not None:
                mask = np.asarray(stack.saturated[i], dtype=bool)
                if mask.any():  # all-False chunks equal the fill value and are not stored
                    saturated[i] = mask
            if progress is not None:
                progress(i)
    return path


def create_stack_group(directory, shape, delay_us, exposure_us, excluded, lines_per_second, projector_rows, metadata, path=None):
    """Create the layout of a native stack store in ``directory`` (images left at 0).

    Shared by :func:`write_stack` and writers that fill a store image by image
    (the resumable sweep runner, :func:`planeray.acquire.acquire_to_store`).
    """
    n, h, w = (int(x) for x in shape)
    group = zarr.open_group(str(directory), mode="w", zarr_format=3)
    # Row blocks: demultiplexing reads a few camera rows of every image at a time.
    chunks = (1, max(min(h, 32), 1), max(w, 1))
    group.create_array("images", shape=(n, h, w), chunks=chunks, dtype="float32", fill_value=0.0)
    group.create_array("saturated", shape=(n, h, w), chunks=chunks, dtype="bool", fill_value=False)
    group.create_array("delay_us", data=np.asarray(delay_us, dtype=np.float64))
    group.create_array("exposure_us", data=np.asarray(exposure_us, dtype=np.float64))
    group.create_array("excluded", data=np.asarray(excluded, dtype=bool))
    group.attrs.update(
        {
            "format": STACK_FORMAT,
            "format_version": FORMAT_VERSION,
            "lines_per_second": float(lines_per_second),
            "projector_rows": int(projector_rows),
            "metadata": _jsonable(metadata, "metadata", StackError),
            "planeray_version": _planeray_version(),
        }
    )
    return group


def _open_group(path: Path, error):
    """Open a Zarr group read-only, turning every failure into ``error``."""
    if not path.exists():
        raise error("path does not exist", path)
    if not path.is_dir():
        raise error("not a Zarr store (expected a directory)", path)
    try:
        return zarr.open_group(str(path), mode="r")
    except Exception as exc:  # zarr raises several unrelated types
        raise error(f"not a Zarr group ({type(exc).__name__}: {exc})", path) from exc


def _get_array(group, name: str, path: Path, error, required: bool = True):
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


def _read_vector(array, name: str, n: int, path: Path, error) -> np.ndarray:
    if len(array.shape) != 1 or array.shape[0] != n:
        raise error(f"array '{name}' has shape {tuple(array.shape)}, expected ({n},)", path)
    try:
        return np.asarray(array[...])
    except Exception as exc:
        raise error(f"cannot read array '{name}' ({type(exc).__name__}: {exc})", path) from exc


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_integer(value) -> bool:
    return _is_number(value) and float(value).is_integer()


def read_stack(path, lazy: bool = True) -> Stack:
    """Read a stack from a native store, or import it from a captured-image folder.

    Parameters
    ----------
    path : str or os.PathLike
        A native Zarr store written by :func:`write_stack`, or a folder holding a
        ``manifest.csv`` (read with :func:`import_folder`, always in memory).
    lazy : bool
        Keep ``images`` and ``saturated`` on disk (:class:`LazyArray` views read on
        demand) instead of loading them.  Lazy images are not scanned for NaN; call
        :func:`validate_images` to do so.

    Returns
    -------
    stack : Stack

    Raises
    ------
    StackError
        The path does not exist or is not a valid planeray stack; the message names
        the path and the problem (missing array or attribute, inconsistent shapes,
        non-finite image...).
    """
    path = Path(path)
    if path.is_dir() and (path / "manifest.csv").is_file():
        return import_folder(path)
    group = _open_group(path, StackError)
    attrs = dict(group.attrs)
    if "format" not in attrs:
        raise StackError("not a planeray stack (no 'format' attribute)", path)
    if attrs["format"] != STACK_FORMAT:
        raise StackError(f"not a planeray stack (format is {attrs['format']!r})", path)
    version = attrs.get("format_version")
    if not _is_integer(version):
        raise StackError(f"missing or invalid attribute 'format_version' ({version!r})", path)
    if int(version) > FORMAT_VERSION:
        raise StackError(f"unsupported format_version {version} (this planeray reads up to {FORMAT_VERSION})", path)
    lps = attrs.get("lines_per_second")
    if lps is None:
        raise StackError("missing attribute 'lines_per_second'", path)
    if not _is_number(lps) or not math.isfinite(lps) or lps <= 0:
        raise StackError(f"attribute 'lines_per_second' must be a positive number, got {lps!r}", path)
    projector_rows = attrs.get("projector_rows")
    if projector_rows is not None and (not _is_integer(projector_rows) or projector_rows < 1):
        raise StackError(f"attribute 'projector_rows' must be a positive integer, got {projector_rows!r}", path)
    metadata = attrs.get("metadata", {})
    if not isinstance(metadata, dict):
        raise StackError(f"attribute 'metadata' must be a JSON object, got {type(metadata).__name__}", path)

    arrays = {name: _get_array(group, name, path, StackError) for name in _STACK_ARRAYS}
    saturated = _get_array(group, "saturated", path, StackError, required=False)
    images = arrays["images"]
    if len(images.shape) != 3:
        raise StackError(f"array 'images' must be (N, H, W), got shape {tuple(images.shape)}", path)
    if np.dtype(images.dtype).kind != "f":
        raise StackError(f"array 'images' must be floating point, got {images.dtype}", path)
    n = int(images.shape[0])
    delay = _read_vector(arrays["delay_us"], "delay_us", n, path, StackError)
    exposure = _read_vector(arrays["exposure_us"], "exposure_us", n, path, StackError)
    excluded = _read_vector(arrays["excluded"], "excluded", n, path, StackError)
    if saturated is not None and tuple(saturated.shape) != tuple(images.shape):
        raise StackError(
            f"array 'saturated' has shape {tuple(saturated.shape)}, images {tuple(images.shape)}", path
        )

    if lazy:
        image_data = LazyArray(images)
        saturated_data = None if saturated is None else LazyArray(saturated)
    else:
        try:
            image_data = np.asarray(images[...], dtype=np.float32)
            saturated_data = None if saturated is None else np.asarray(saturated[...], dtype=bool)
        except Exception as exc:
            raise StackError(f"cannot read images ({type(exc).__name__}: {exc})", path) from exc
        _check_finite_images(image_data, path)
    try:
        return Stack(
            images=image_data,
            delay_us=delay,
            exposure_us=exposure,
            lines_per_second=float(lps),
            excluded=excluded.astype(bool),
            saturated=saturated_data,
            projector_rows=None if projector_rows is None else int(projector_rows),
            metadata=metadata,
        )
    except StackError as exc:
        raise StackError(exc.problem, path) from exc


def _check_finite_images(images, path) -> None:
    for i in range(len(images)):
        if not np.all(np.isfinite(images[i])):
            raise StackError(f"image {i} contains NaN or infinite values", path)


def validate_images(stack: Stack, path=None) -> None:
    """Scan a (possibly lazy) stack image by image for NaN or infinite values.

    Parameters
    ----------
    stack : Stack
    path : str or os.PathLike, optional
        Named in the error message.

    Raises
    ------
    StackError
        Naming the index of the first non-finite image.
    """
    try:
        _check_finite_images(stack.images, path)
    except StackError:
        raise
    except Exception as exc:
        raise StackError(f"cannot read images ({type(exc).__name__}: {exc})", path) from exc


# ----------------------------------------------------------------------------
# Import folder
# ----------------------------------------------------------------------------
def _read_acquisition(folder: Path) -> dict:
    path = folder / "acquisition.json"
    if not path.is_file():
        raise StackError("file not found (acquisition.json is required)", path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise StackError(f"cannot read file ({exc})", path) from exc
    try:
        acq = json.loads(text)
    except json.JSONDecodeError as exc:
        raise StackError(f"invalid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})", path) from exc
    if not isinstance(acq, dict):
        raise StackError(f"expected a JSON object, got {type(acq).__name__}", path)

    if "lines_per_second" not in acq:
        raise StackError("missing field 'lines_per_second'", path)
    lps = acq["lines_per_second"]
    if not _is_number(lps) or not math.isfinite(lps) or lps <= 0:
        raise StackError(f"field 'lines_per_second' must be a positive number, got {lps!r}", path)
    bit_depth = acq.get("bit_depth", 12)
    if not _is_integer(bit_depth) or not 1 <= bit_depth <= 16:
        raise StackError(f"field 'bit_depth' must be an integer in 1..16, got {bit_depth!r}", path)
    bit_depth = int(bit_depth)
    max_code = 2**bit_depth - 1
    black = acq.get("black_level", 0)
    if not _is_number(black) or not math.isfinite(black) or black < 0:
        raise StackError(f"field 'black_level' must be a number >= 0, got {black!r}", path)
    if black >= max_code:
        raise StackError(
            f"field 'black_level' ({black}) must be below the largest code 2**bit_depth - 1 = {max_code}", path
        )
    projector_rows = acq.get("projector_rows")
    if projector_rows is not None and (not _is_integer(projector_rows) or projector_rows < 1):
        raise StackError(f"field 'projector_rows' must be a positive integer, got {projector_rows!r}", path)
    saturation = acq.get("saturation_level", max_code)
    if not _is_number(saturation) or not math.isfinite(saturation):
        raise StackError(f"field 'saturation_level' must be a number, got {saturation!r}", path)
    planeray_metadata = acq.get("planeray_metadata", {})
    if not isinstance(planeray_metadata, dict):
        raise StackError(f"field 'planeray_metadata' must be a JSON object, got {planeray_metadata!r}", path)
    return {
        "raw": acq,
        "lines_per_second": float(lps),
        "bit_depth": bit_depth,
        "black_level": float(black),
        "projector_rows": None if projector_rows is None else int(projector_rows),
        "saturation_level": float(saturation),
        "planeray_metadata": planeray_metadata,
    }


_TRUE = {"1", "true"}
_FALSE = {"0", "false"}


def _read_manifest(folder: Path):
    path = folder / "manifest.csv"
    if not path.is_file():
        raise StackError("file not found (manifest.csv is required)", path)
    files, delays, exposures, excluded, lines = [], [], [], [], []
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh)
            header = None
            for row in reader:
                if not any(cell.strip() for cell in row):
                    continue  # blank line
                if header is None:
                    header = [cell.strip() for cell in row]
                    for column in ("file", "delay_us", "exposure_us"):
                        if column not in header:
                            raise StackError(
                                f"missing column '{column}' (header has: {', '.join(header)})", path
                            )
                    col = {name: header.index(name) for name in header[::-1]}  # first occurrence wins
                    has_excluded = "excluded" in col
                    continue
                line = reader.line_num
                if len(row) < len(header):
                    raise StackError(f"line {line}: expected {len(header)} columns, got {len(row)}", path)
                name = row[col["file"]].strip()
                if not name:
                    raise StackError(f"line {line}: empty 'file'", path)
                values = {}
                for column in ("delay_us", "exposure_us"):
                    text = row[col[column]].strip()
                    try:
                        value = float(text)
                    except ValueError:
                        value = math.nan
                    if not math.isfinite(value):
                        raise StackError(f"line {line}: {column} {text!r} is not a finite number", path)
                    values[column] = value
                if values["exposure_us"] <= 0:
                    raise StackError(f"line {line}: exposure_us must be positive, got {values['exposure_us']}", path)
                if has_excluded:
                    text = row[col["excluded"]].strip().lower()
                    if text in _TRUE:
                        excluded.append(True)
                    elif text in _FALSE:
                        excluded.append(False)
                    else:
                        raise StackError(f"line {line}: excluded {text!r} is not 0, 1, true or false", path)
                files.append(name)
                delays.append(values["delay_us"])
                exposures.append(values["exposure_us"])
                lines.append(line)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise StackError(f"cannot read file ({type(exc).__name__}: {exc})", path) from exc
    if header is None:
        raise StackError("empty manifest (no header line)", path)
    if not files:
        raise StackError("empty manifest (no image lines)", path)
    delays = np.asarray(delays, dtype=np.float64)
    exposures = np.asarray(exposures, dtype=np.float64)
    excluded = np.asarray(excluded, dtype=bool) if has_excluded else boundary_images(delays, exposures)
    return files, delays, exposures, excluded, lines


def _read_raw_image(path: Path, manifest_line: int) -> np.ndarray:
    """Read one grayscale image as raw codes (integer or float array, 2-D)."""
    where = f"manifest.csv line {manifest_line}"
    if not path.is_file():
        raise StackError(f"image not found ({where})", path)
    kind = _IMAGE_SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise StackError(f"unsupported image format {path.suffix!r} (use .tif, .tiff or .png)", path)
    try:
        if kind == "tiff":
            data = np.asarray(tifffile.imread(path))
        else:
            with Image.open(path) as im:
                im.load()
                if im.mode in ("P", "PA", "CMYK", "YCbCr", "LAB", "HSV"):
                    raise StackError(f"expected a grayscale image, got PNG mode {im.mode!r}", path)
                data = np.asarray(im)
    except StackError:
        raise
    except Exception as exc:  # truncated / corrupt files raise many types
        raise StackError(f"cannot read image ({type(exc).__name__}: {exc})", path) from exc
    if data.ndim != 2:
        raise StackError(f"expected a grayscale image, got shape {data.shape}", path)
    if data.dtype.kind == "b":
        data = data.astype(np.uint8)
    if data.dtype.kind not in "uif":
        raise StackError(f"unsupported pixel type {data.dtype}", path)
    return data


def import_folder(path) -> Stack:
    """Import a captured delay-exposure stack from a folder of images.

    The folder format (``manifest.csv``, ``acquisition.json`` and grayscale TIFF or
    PNG images) is described in the module docstring of :mod:`planeray.io`.

    Parameters
    ----------
    path : str or os.PathLike
        The folder.

    Returns
    -------
    stack : Stack
        In-memory stack: float32 images normalized as ``(raw - black_level) /
        (2**bit_depth - 1 - black_level)`` and the mask ``raw >= saturation_level``.

    Raises
    ------
    StackError
        Naming the file and the problem (missing or malformed manifest, acquisition
        record or image; inconsistent image sizes; raw values above the bit depth).
        Nothing is written to disk.
    """
    folder = Path(path)
    if not folder.exists():
        raise StackError("folder does not exist", folder)
    if not folder.is_dir():
        raise StackError("not a folder", folder)
    acq = _read_acquisition(folder)
    files, delays, exposures, excluded, lines = _read_manifest(folder)

    bit_depth, black = acq["bit_depth"], acq["black_level"]
    max_code = 2**bit_depth - 1
    scale = 1.0 / (max_code - black)
    images = saturated = None
    first = None
    for i, (name, line) in enumerate(zip(files, lines)):
        file = folder / name
        raw = _read_raw_image(file, line)
        if raw.dtype.kind == "f" and not np.all(np.isfinite(raw)):
            raise StackError("image contains NaN or infinite values", file)
        if images is None:
            first = (name, raw.shape)
            images = np.empty((len(files), *raw.shape), dtype=np.float32)
            saturated = np.empty((len(files), *raw.shape), dtype=bool)
        elif raw.shape != first[1]:
            raise StackError(f"image size {raw.shape} differs from the first image {first[0]!r} {first[1]}", file)
        if raw.size:
            top = raw.max()
            if top > max_code:
                raise StackError(
                    f"raw value {top} above the largest code {max_code} of bit_depth {bit_depth}", file
                )
            if raw.dtype.kind == "i" and raw.min() < 0:
                raise StackError(f"negative raw value {raw.min()}", file)
        images[i] = ((raw.astype(np.float64) - black) * scale).astype(np.float32)
        saturated[i] = raw >= acq["saturation_level"]

    metadata = dict(acq["planeray_metadata"])
    metadata["acquisition"] = {k: v for k, v in acq["raw"].items() if k != "planeray_metadata"}
    metadata["source"] = f"import:{folder}"
    try:
        return Stack(
            images=images,
            delay_us=delays,
            exposure_us=exposures,
            lines_per_second=acq["lines_per_second"],
            excluded=excluded,
            saturated=saturated,
            projector_rows=acq["projector_rows"],
            metadata=metadata,
        )
    except StackError as exc:
        raise StackError(exc.problem, folder) from exc


# ----------------------------------------------------------------------------
# Export
# ----------------------------------------------------------------------------
def _check_levels(bit_depth, black_level, path, error):
    if not _is_integer(bit_depth) or not 1 <= bit_depth <= 16:
        raise error(f"bit_depth must be an integer in 1..16, got {bit_depth!r}", path)
    max_code = 2 ** int(bit_depth) - 1
    if not _is_number(black_level) or not 0 <= black_level < max_code:
        raise error(f"black_level must be a number in [0, {max_code}), got {black_level!r}", path)
    return int(bit_depth), max_code


def _quantize(image, max_code: int, black_level: float) -> np.ndarray:
    """Normalized image -> uint16 raw codes, rounded and clipped to ``[0, max_code]``."""
    raw = np.rint(np.asarray(image, dtype=np.float64) * (max_code - black_level) + black_level)
    return np.clip(raw, 0, max_code).astype(np.uint16)


def _write_raw(path: Path, raw: np.ndarray, kind: str) -> None:
    if kind == "tiff":
        tifffile.imwrite(path, raw, photometric="minisblack")
    else:
        Image.fromarray(raw.astype(np.uint16)).save(path, format="PNG")


def export_folder(stack: Stack, folder, fmt: str = "tiff", bit_depth: int = 16, black_level: float = 256,
                  overwrite: bool = False) -> Path:
    """Export a stack as an import folder of 16-bit grayscale images, atomically.

    Writes ``img_0000.tif`` (or ``.png``) per image, ``manifest.csv``
    (``file,delay_us,exposure_us,excluded``) and ``acquisition.json``
    (``lines_per_second``, ``bit_depth``, ``black_level``, ``projector_rows`` and
    ``planeray_metadata`` = the stack's metadata), so that :func:`import_folder`
    reads it back: images within half a quantization step
    ``0.5 / (2**bit_depth - 1 - black_level)``, everything else exactly.

    Parameters
    ----------
    stack : Stack
    folder : str or os.PathLike
        Folder to create.
    fmt : {"tiff", "png"}
        Image format (16-bit TIFF via tifffile or 16-bit PNG via Pillow).
    bit_depth : int
        Bit depth of the raw codes (1..16); images are always stored as 16-bit.
    black_level : float
        Raw code of normalized 0.
    overwrite : bool
        Replace an existing folder (atomically).

    Returns
    -------
    folder : pathlib.Path

    Notes
    -----
    Values are clipped to the representable range: below ``-black_level /
    (2**bit_depth - 1 - black_level)`` they become code 0, above 1 the largest code
    (and are flagged saturated on import).  The stack's own saturation mask is not
    exported; import re-derives it from the codes (``raw >= 2**bit_depth - 1``).
    """
    folder = Path(folder)
    kind = {"tiff": "tiff", "tif": "tiff", "png": "png"}.get(str(fmt).lower())
    if kind is None:
        raise StackError(f"unknown image format {fmt!r} (use 'tiff' or 'png')", folder)
    bit_depth, max_code = _check_levels(bit_depth, black_level, folder, StackError)
    n = len(stack)
    digits = max(4, len(str(max(n - 1, 0))))
    suffix = ".tif" if kind == "tiff" else ".png"
    acquisition = {
        "lines_per_second": float(stack.lines_per_second),
        "bit_depth": bit_depth,
        "black_level": black_level.item() if isinstance(black_level, np.generic) else black_level,
        "projector_rows": int(stack.projector_rows),
        "planeray_version": _planeray_version(),
        "planeray_metadata": _jsonable(stack.metadata, "metadata", StackError),
    }
    with atomic_directory(folder, overwrite, error=StackError) as tmp:
        rows = []
        for i in range(n):
            image = np.asarray(stack.images[i], dtype=np.float32)
            if not np.all(np.isfinite(image)):
                raise StackError(f"image {i} contains NaN or infinite values", folder)
            name = f"img_{i:0{digits}d}{suffix}"
            _write_raw(tmp / name, _quantize(image, max_code, black_level), kind)
            rows.append([name, repr(float(stack.delay_us[i])), repr(float(stack.exposure_us[i])),
                         int(bool(stack.excluded[i]))])
        with open(tmp / "manifest.csv", "w", newline="", encoding="utf-8") as fh:
            writer = csv.writer(fh)
            writer.writerow(["file", "delay_us", "exposure_us", "excluded"])
            writer.writerows(rows)
        (tmp / "acquisition.json").write_text(json.dumps(acquisition, indent=2) + "\n", encoding="utf-8")
    return folder


def write_image(path, image, bit_depth: int = 16, black_level: float = 0) -> Path:
    """Write one normalized image as a 16-bit grayscale TIFF or PNG, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; ``.tif``/``.tiff`` (tifffile) or ``.png`` (Pillow) picks the
        format.  An existing file is replaced.
    image : array_like, shape (H, W)
        Normalized image (0 = black, 1 = largest code).
    bit_depth : int
        Codes are ``round(image * (2**bit_depth - 1 - black_level) + black_level)``,
        clipped to ``[0, 2**bit_depth - 1]`` and stored as uint16.
    black_level : float
        Raw code of normalized 0.

    Returns
    -------
    path : pathlib.Path

    Raises
    ------
    InputError
        Unknown extension, image not 2-D or not finite, invalid bit depth.
    """
    path = Path(path)
    kind = _IMAGE_SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise InputError(f"unsupported image extension {path.suffix!r} (use .tif, .tiff or .png)", path)
    _, max_code = _check_levels(bit_depth, black_level, path, InputError)
    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 2:
        raise InputError(f"expected a 2-D image, got shape {image.shape}", path)
    if not np.all(np.isfinite(image)):
        raise InputError("image contains NaN or infinite values", path)
    raw = _quantize(image, max_code, black_level)
    with atomic_file(path) as tmp:
        _write_raw(tmp, raw, kind)
    return path


# ----------------------------------------------------------------------------
# Transport store
# ----------------------------------------------------------------------------
def transport_attrs(offsets_rows, projector_rows: int, attrs: dict | None = None, path=None) -> dict:
    """Group attributes of a transport store: ``attrs`` plus the reserved format fields.

    Used by :func:`write_transport` and by writers that fill a store chunk by chunk
    (:func:`planeray.demux.demultiplex_to_store`), so both produce the same format.
    """
    out = _jsonable(dict(attrs or {}), "attrs", TransportError)
    out.update(
        {
            "format": TRANSPORT_FORMAT,
            "format_version": FORMAT_VERSION,
            "offsets_rows": [int(u) for u in offsets_rows],
            "projector_rows": int(projector_rows),
            "lines_per_second": out.get("lines_per_second"),
        }
    )
    out.setdefault("planeray_version", _planeray_version())
    return out


def read_transport_maps(path) -> dict:
    """Per-pixel 2-D arrays stored beside ``T`` (e.g. demultiplexing diagnostics), by name."""
    path = Path(path)
    group = _open_group(path, TransportError)
    maps = {}
    for name, member in group.members():
        if name != "T" and name not in _SPARSE_ARRAYS and hasattr(member, "shape") and len(member.shape) == 2:
            maps[name] = np.asarray(member[...])
    return maps


def write_transport(transport: Transport, path, attrs: dict | None = None, overwrite: bool = False) -> Path:
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

    Returns
    -------
    path : pathlib.Path

    Raises
    ------
    TransportError
        ``path`` exists and ``overwrite`` is False, or ``attrs`` is not
        JSON-serializable.
    """
    path = Path(path)
    if not isinstance(transport, Transport):
        raise TransportError(f"expected a Transport, got {type(transport).__name__}", path)
    out = transport_attrs(transport.offsets_rows, transport.geometry.projector_rows, attrs, path)
    dense = np.asarray(transport.dense, dtype=np.float32)
    h, w, u = dense.shape
    with atomic_directory(path, overwrite, error=TransportError) as tmp:
        group = zarr.open_group(str(tmp), mode="w", zarr_format=3)
        chunks = (max(min(h, 64), 1), max(min(w, 64), 1), max(u, 1))
        array = group.create_array("T", shape=dense.shape, chunks=chunks, dtype="float32", fill_value=0.0)
        array[...] = dense
        sparse = transport.sparse
        if sparse is not None and len(sparse):
            group.create_array("sparse_row", data=np.asarray(sparse.row, dtype=np.int32))
            group.create_array("sparse_col", data=np.asarray(sparse.col, dtype=np.int32))
            group.create_array("sparse_offset", data=np.asarray(sparse.offset, dtype=np.int32))
            group.create_array("sparse_value", data=np.asarray(sparse.value, dtype=np.float32))
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
        do not match ``T``, non-finite values, malformed sparse entries...).
    """
    path = Path(path)
    group = _open_group(path, TransportError)
    attrs = dict(group.attrs)
    fmt = attrs.get("format")
    if fmt is not None and fmt != TRANSPORT_FORMAT:
        raise TransportError(f"not a planeray transport (format is {fmt!r})", path)
    version = attrs.get("format_version", FORMAT_VERSION)
    if not _is_integer(version) or int(version) > FORMAT_VERSION:
        raise TransportError(f"unsupported format_version {version!r} (this planeray reads up to {FORMAT_VERSION})", path)
    array = _get_array(group, "T", path, TransportError)
    if len(array.shape) != 3:
        raise TransportError(f"array 'T' must be (H, W, U), got shape {tuple(array.shape)}", path)
    h, w, u = (int(x) for x in array.shape)
    offsets = attrs.get("offsets_rows")
    if offsets is None:
        raise TransportError("missing attribute 'offsets_rows'", path)
    if not isinstance(offsets, list) or not all(_is_integer(o) for o in offsets):
        raise TransportError("attribute 'offsets_rows' must be a list of integers", path)
    if len(offsets) != u:
        raise TransportError(f"{len(offsets)} offsets_rows for array 'T' with U = {u}", path)
    projector_rows = attrs.get("projector_rows")
    if projector_rows is not None and (not _is_integer(projector_rows) or projector_rows < 1):
        raise TransportError(f"attribute 'projector_rows' must be a positive integer, got {projector_rows!r}", path)
    lps = attrs.get("lines_per_second")
    if lps is not None and (not _is_number(lps) or not math.isfinite(lps) or lps <= 0):
        raise TransportError(f"attribute 'lines_per_second' must be a positive number or null, got {lps!r}", path)
    try:
        dense = np.asarray(array[...], dtype=np.float32)
    except Exception as exc:
        raise TransportError(f"cannot read array 'T' ({type(exc).__name__}: {exc})", path) from exc
    if not np.all(np.isfinite(dense)):
        raise TransportError("array 'T' contains NaN or infinite values", path)

    present = [name for name in _SPARSE_ARRAYS if group.get(name) is not None]
    sparse = SparseEntries.empty()
    if present:
        missing = [name for name in _SPARSE_ARRAYS if name not in present]
        if missing:
            raise TransportError(f"missing array '{missing[0]}' (sparse entries need all of {_SPARSE_ARRAYS})", path)
        members = [_get_array(group, name, path, TransportError) for name in _SPARSE_ARRAYS]
        if len(members[0].shape) != 1:
            raise TransportError(f"array 'sparse_row' must be 1-D, got shape {tuple(members[0].shape)}", path)
        m = int(members[0].shape[0])
        data = [_read_vector(a, name, m, path, TransportError) for a, name in zip(members, _SPARSE_ARRAYS)]
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
