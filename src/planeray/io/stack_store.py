"""The native stack store (Zarr v3 group ``images``, ``saturated``, ``delay_us``, ``exposure_us``, ``excluded``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import zarr

from ..errors import StackError
from ..stack import Stack
from ._common import (
    ALL_CHUNKS_ATTR,
    FORMAT_VERSION,
    STACK_ARRAYS,
    STACK_FORMAT,
    LazyArray,
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
    writable,
)
from .atomic import atomic_directory
from .folder import import_folder


# ----------------------------------------------------------------------------
def write_stack(stack: Stack, path, *, overwrite: bool = False, progress=None) -> Path:
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

    See Also
    --------
    read_stack : read it back.
    planeray.export_folder : an import folder of image files instead.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("corner", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pr.write_stack(stack, pathlib.Path(tmp) / "stack.zarr")
    ...     path.name, pr.read_stack(path).images.shape
    ('stack.zarr', (27, 8, 8))
    """
    path = Path(path)
    if not isinstance(stack, Stack):
        raise StackError(f"expected a Stack, got {type(stack).__name__}", path)
    n, h, w = (int(x) for x in stack.images.shape)
    with atomic_directory(path, overwrite=overwrite, kind="stack", error=StackError) as tmp:
        group = create_stack_group(
            tmp,
            (n, h, w),
            stack.delay_us,
            stack.exposure_us,
            stack.excluded,
            stack.lines_per_second,
            stack.projector_rows,
            stack.metadata,
            path=path,
        )
        images, saturated = writable(group, "images"), writable(group, "saturated")
        for i in range(n):
            image = np.asarray(stack.images[i], dtype=np.float32)
            if image.shape != (h, w):
                raise StackError(f"image {i} has shape {image.shape}, expected {(h, w)}", path)
            if not np.all(np.isfinite(image)):
                raise StackError(f"image {i} contains NaN or infinite values", path)
            images[i] = image
            # every chunk is stored, all-False masks too (the store is marked all_chunks_stored)
            saturated[i] = False if stack.saturated is None else np.asarray(stack.saturated[i], dtype=bool)
            if progress is not None:
                progress(i)
    return path


def create_stack_group(
    directory, shape, delay_us, exposure_us, excluded, lines_per_second, projector_rows, metadata, *, path=None
):
    """Create the layout of a native stack store in ``directory`` (images left at 0).

    Shared by :func:`write_stack` and writers that fill a store image by image
    (the resumable sweep runner, :func:`planeray.acquire.acquire_to_store`).

    The group is marked ``all_chunks_stored``: the caller must write *every*
    image and mask, through arrays that store chunks equal to the fill value
    (the returned group's ``images``/``saturated`` after reopening:
    :func:`planeray.io.writable`), or :func:`read_stack` refuses the store.

    Parameters
    ----------
    directory : str or path
        An empty folder.
    shape : (int, int, int)
        ``(N, H, W)``: images and their size.
    delay_us, exposure_us : array_like (N,)
        Delay and exposure of each image, microseconds.
    excluded : array_like of bool (N,)
        Images left out of demultiplexing.
    lines_per_second : float
        Projector scan rate, rows per second.
    projector_rows : int
        Projector rows spanned by the image height.
    metadata : dict
        The acquisition record (JSON-serializable).
    path : str or path, optional
        The store's final name, for error messages.

    Returns
    -------
    zarr.Group
        The store's group with ``images``, ``saturated`` and the vectors, images at 0.

    See Also
    --------
    planeray.write_stack : a whole stack at once.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     group = create_stack_group(
    ...         pathlib.Path(tmp) / "s",
    ...         (2, 8, 8),
    ...         [0.0, 375.0],
    ...         [600.0, 600.0],
    ...         [False, False],
    ...         54000.0,
    ...         8,
    ...         {"source": "example"},
    ...     )
    ...     group["images"].shape
    (2, 8, 8)
    """
    n, h, w = (int(x) for x in shape)
    group = zarr.open_group(str(directory), mode="w", zarr_format=3)
    # Row blocks: demultiplexing reads a few camera rows of every image at a time.
    chunks = (1, max(min(h, 32), 1), max(w, 1))
    create_array(group, "images", shape=(n, h, w), chunks=chunks, dtype="float32", fill_value=0.0)
    create_array(group, "saturated", shape=(n, h, w), chunks=chunks, dtype="bool", fill_value=False)
    create_array(group, "delay_us", data=np.asarray(delay_us, dtype=np.float64))
    create_array(group, "exposure_us", data=np.asarray(exposure_us, dtype=np.float64))
    create_array(group, "excluded", data=np.asarray(excluded, dtype=bool))
    group.attrs.update(
        {
            "format": STACK_FORMAT,
            "format_version": FORMAT_VERSION,
            "lines_per_second": float(lines_per_second),
            "projector_rows": int(projector_rows),
            "metadata": jsonable(metadata, finite=False, where="metadata", error=StackError),
            "planeray_version": planeray_version(),
            ALL_CHUNKS_ATTR: True,
        }
    )
    return group


def read_stack(path, *, lazy: bool = True) -> Stack:
    """Read a stack from a native store, or import it from a captured-image folder.

    Parameters
    ----------
    path : str or os.PathLike
        A native Zarr store written by :func:`write_stack`, or a folder holding a
        ``manifest.csv`` (read with :func:`import_folder`, always in memory).
    lazy : bool
        Keep ``images`` and ``saturated`` on disk (:class:`LazyArray` views read on
        demand) instead of loading them.  Lazy images are not scanned for NaN; call
        :func:`validate_images` to do so.  Reading a chunk that cannot be decoded
        later raises :class:`StackError` too (see :class:`LazyArray`).

    Returns
    -------
    stack : Stack

    Raises
    ------
    StackError
        The path does not exist or is not a valid planeray stack; the message names
        the path and the problem (missing array or attribute, inconsistent shapes,
        non-finite image, a chunk file that is absent from a store marked
        ``all_chunks_stored`` -- e.g. ``s.zarr: images: chunk (12, 2, 0) is missing
        (image 12, rows 64-95) -- the store is incomplete`` -- or that cannot be
        decoded...).

    See Also
    --------
    write_stack : write one.
    planeray.import_folder : a folder of image files.

    Notes
    -----
    Stores written by this version of planeray store every chunk and carry the
    attribute ``all_chunks_stored = true``; an absent chunk file then means lost
    data and is refused (one ``stat`` per chunk, about 20 ms for the images and
    mask of a 512x512x85 stack).  Older stores, which skipped chunks equal to the
    fill value, are read as before: an absent chunk reads as 0 (``False`` in the
    mask).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from planeray.acquire import simulate_stack
    >>> from planeray.scenes import make_scene
    >>> from planeray.timing import quick_sweep
    >>> stack = simulate_stack(make_scene("diffuse_plane", (16, 16), seed=0), quick_sweep(), seed=0)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = write_stack(stack, pathlib.Path(tmp) / "s.zarr")
    ...     back = read_stack(path, lazy=False)
    >>> bool((back.images == stack.images).all()), back.lines_per_second
    (True, 54000.0)
    """
    path = Path(path)
    if path.is_dir() and (path / "manifest.csv").is_file():
        return import_folder(path)
    group = open_group(path, StackError)
    attrs = dict(group.attrs)
    if "format" not in attrs:
        raise StackError("not a planeray stack (no 'format' attribute)", path)
    if attrs["format"] != STACK_FORMAT:
        raise StackError(f"not a planeray stack (format is {attrs['format']!r})", path)
    version = attrs.get("format_version")
    if not is_integer(version):
        raise StackError(f"missing or invalid attribute 'format_version' ({version!r})", path)
    if int(version) > FORMAT_VERSION:
        raise StackError(f"unsupported format_version {version} (this planeray reads up to {FORMAT_VERSION})", path)
    lps = attrs.get("lines_per_second")
    if lps is None:
        raise StackError("missing attribute 'lines_per_second'", path)
    if not is_number(lps) or not math.isfinite(lps) or lps <= 0:
        raise StackError(f"attribute 'lines_per_second' must be a positive number, got {lps!r}", path)
    projector_rows = attrs.get("projector_rows")
    if projector_rows is not None and (not is_integer(projector_rows) or projector_rows < 1):
        raise StackError(f"attribute 'projector_rows' must be a positive integer, got {projector_rows!r}", path)
    metadata = attrs.get("metadata", {})
    if not isinstance(metadata, dict):
        raise StackError(f"attribute 'metadata' must be a JSON object, got {type(metadata).__name__}", path)

    arrays = {name: get_array(group, name, path, StackError) for name in STACK_ARRAYS}
    saturated = get_array(group, "saturated", path, StackError, required=False)
    images = arrays["images"]
    if len(images.shape) != 3:
        raise StackError(f"array 'images' must be (N, H, W), got shape {tuple(images.shape)}", path)
    if np.dtype(images.dtype).kind != "f":
        raise StackError(f"array 'images' must be floating point, got {images.dtype}", path)
    n = int(images.shape[0])
    delay = read_vector(arrays["delay_us"], "delay_us", n, path, StackError)
    exposure = read_vector(arrays["exposure_us"], "exposure_us", n, path, StackError)
    excluded = read_vector(arrays["excluded"], "excluded", n, path, StackError)
    if saturated is not None and tuple(saturated.shape) != tuple(images.shape):
        raise StackError(f"array 'saturated' has shape {tuple(saturated.shape)}, images {tuple(images.shape)}", path)
    for name, array in (*arrays.items(), ("saturated", saturated)):
        if array is not None:
            check_chunks(group, array, name, path, StackError)

    if lazy:
        image_data = LazyArray(images, path=path, error=StackError, name="images")
        saturated_data = (
            None if saturated is None else LazyArray(saturated, path=path, error=StackError, name="saturated")
        )
    else:
        image_data = read_array(images, ..., path=path, error=StackError, name="images").astype(np.float32, copy=False)
        saturated_data = None
        if saturated is not None:
            saturated_data = read_array(saturated, ..., path=path, error=StackError, name="saturated").astype(bool)
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

    Returns
    -------
    None
        Returns when every value is finite; raises otherwise.

    Raises
    ------
    StackError
        Naming the index of the first non-finite image.

    See Also
    --------
    planeray.write_stack : validates before writing.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> images = np.zeros((1, 2, 2), np.float32)
    >>> images[0, 0, 0] = np.nan
    >>> try:
    ...     validate_images(pr.Stack(images, [0.0], [600.0], 54000.0))
    ... except pr.errors.StackError as err:
    ...     print("refused:", "NaN" in str(err))
    refused: True
    """
    try:
        _check_finite_images(stack.images, path)
    except StackError:
        raise
    except Exception as exc:
        raise StackError(f"cannot read images ({type(exc).__name__}: {exc})", path) from exc
