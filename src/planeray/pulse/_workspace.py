"""Scratch arrays of a pulse analysis: in memory while they fit an allowance, on disk beyond it.

A long or large recording cannot be held whole: the analysis (:func:`planeray.pulse.analysis.analyze_pulse`)
reads it frame by frame and keeps only what it must -- a pyramid level over time, the magnified video
for the automatic region search, the search's per-pixel spectra -- in arrays a :class:`Workspace` hands
out.  Each is an ordinary NumPy array while the workspace's memory allowance lasts, and a
:class:`DiskArray` (a raw file in the workspace's folder, mapped with :class:`numpy.memmap` only for the
duration of one read or write, so its pages never accumulate in the process's resident memory)
beyond it.  Both are read and written by the same slicing, so every step is one implementation
whatever holds its data.  Work over whole time series is done in tiles of pixels
(:func:`pixel_tiles`) of at most the workspace's ``tile_bytes``.

The workspace's folder is created on first use and removed, with everything in it, when the
workspace closes -- on success, error or interruption; a folder inside the output's own temporary
(``planeray skin pulse``) is also removed with it by :func:`planeray.io.atomic_directory`.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["DEFAULT_MEMORY_BYTES", "DiskArray", "Workspace", "pixel_tiles"]

#: Working memory a streamed analysis may hold by default (half for arrays kept between passes,
#: half for one tile of per-pixel work), bytes.
DEFAULT_MEMORY_BYTES = 512 * 2**20


class DiskArray:
    """A C-ordered array in a raw file, read and written by NumPy slicing.

    Every access maps the file (:class:`numpy.memmap`), copies the slice in or out and unmaps it:
    what a read returns is an ordinary array, and the mapped pages leave the process with the map.
    Along its first axis it grows by :meth:`append` (a frame at a time, as a video is read).
    """

    def __init__(self, path, shape, dtype=np.float32):
        self.path = Path(path)
        self.dtype = np.dtype(dtype)
        self._item = tuple(int(s) for s in shape[1:])
        self._row_bytes = int(np.prod(self._item, dtype=np.int64)) * self.dtype.itemsize
        self._capacity = 0
        #: rows in use: ``shape[0]``; :meth:`append` writes after them
        self.count = int(shape[0])
        with open(self.path, "wb"):
            pass
        self._reserve(self.count)

    @property
    def file_bytes(self) -> int:
        return self._capacity * self._row_bytes

    @property
    def shape(self) -> tuple[int, ...]:
        return (self.count, *self._item)

    @property
    def ndim(self) -> int:
        return 1 + len(self._item)

    @property
    def nbytes(self) -> int:
        return self.count * self._row_bytes

    def _reserve(self, rows: int) -> None:
        if rows > self._capacity:
            os.truncate(self.path, max(rows * self._row_bytes, 1))  # sparse: nothing written yet
            self._capacity = rows

    def _map(self, mode: str) -> np.memmap:
        return np.memmap(self.path, self.dtype, mode, shape=(self._capacity, *self._item))[: self.count]

    def __getitem__(self, key) -> np.ndarray:
        m = self._map("r")
        try:
            return np.array(m[key])
        finally:
            del m

    def __setitem__(self, key, value) -> None:
        m = self._map("r+")
        try:
            m[key] = value
        finally:
            del m

    def __array__(self, dtype=None, copy=None):
        out = self[...]
        return out if dtype is None else out.astype(dtype, copy=False)

    def append(self, row) -> None:
        """Write ``row`` after the last one (the file grows as needed)."""
        if self.count >= self._capacity:
            self._reserve(max(self.count + 1, int(self._capacity * 1.25) + 1))
        with open(self.path, "r+b") as f:
            f.seek(self.count * self._row_bytes)
            f.write(np.ascontiguousarray(row, self.dtype).tobytes())
        self.count += 1


class Workspace:
    """Where a streamed analysis keeps its arrays: memory up to ``memory_bytes``, files in ``folder`` beyond.

    Parameters
    ----------
    folder : str or os.PathLike, optional
        An existing folder in which a scratch folder (``.planeray-pulse-*``) is made when an array
        first does not fit in memory, and removed with its files at :meth:`close`.  Default: the
        system's temporary folder.
    memory_bytes : int, optional
        Working memory, bytes: half may be held by arrays, half by one tile of per-pixel work
        (:attr:`tile_bytes`).  None: no limit (everything in memory, untiled).
    """

    def __init__(self, folder=None, *, memory_bytes: int | None = DEFAULT_MEMORY_BYTES):
        self._folder = None if folder is None else Path(folder)
        self._made: Path | None = None
        self.memory_bytes = None if memory_bytes is None else int(memory_bytes)
        self._left = None if memory_bytes is None else self.memory_bytes // 2
        self.tile_bytes = None if memory_bytes is None else max(self.memory_bytes // 2, 1)
        self._disk: list[DiskArray] = []
        self._held: dict[int, int] = {}
        self._names = 0
        #: the most bytes of files held at once
        self.disk_bytes = 0

    # ------------------------------------------------------------------ arrays
    def array(self, shape, dtype=np.float32, *, name: str = "array"):
        """An uninitialized array of ``shape``: in memory if it fits what is left of the allowance, else on disk."""
        shape = tuple(int(s) for s in shape)
        nbytes = int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
        if self._left is None or nbytes <= self._left:
            out = np.empty(shape, dtype)
            if self._left is not None:
                self._left -= nbytes
                self._held[id(out)] = nbytes
            return out
        disk = DiskArray(self._new_path(name), shape, dtype)
        self._disk.append(disk)
        self.note_disk()
        return disk

    def note_disk(self) -> None:
        """Record the bytes its files hold now (:attr:`disk_bytes` keeps the most)."""
        self.disk_bytes = max(self.disk_bytes, sum(d.file_bytes for d in self._disk))

    def frames(self, n_frames: int, shape, dtype=np.float32, *, name: str = "frames") -> FrameBuffer:
        """A :class:`FrameBuffer` for about ``n_frames`` frames of ``shape``, filled frame by frame."""
        return FrameBuffer(self, n_frames, shape, dtype, name)

    def release(self, array) -> None:
        """Give back an array this workspace handed out (its memory to the allowance, or its file)."""
        if isinstance(array, FrameBuffer):
            array = array.data
        if isinstance(array, DiskArray):
            with contextlib.suppress(OSError):
                array.path.unlink(missing_ok=True)
            self._disk = [d for d in self._disk if d is not array]
        elif self._left is not None and id(array) in self._held:
            self._left += self._held.pop(id(array))

    def _new_path(self, name: str) -> Path:
        if self._made is None:
            self._made = Path(tempfile.mkdtemp(prefix=".planeray-pulse-", dir=self._folder))
        self._names += 1
        return self._made / f"{self._names}-{name}.raw"

    # ------------------------------------------------------------------ life
    def close(self) -> None:
        """Remove the folder and every file in it (never raises)."""
        self._disk = []
        if self._made is not None:
            shutil.rmtree(self._made, ignore_errors=True)
            self._made = None

    def __enter__(self) -> Workspace:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class FrameBuffer:
    """Frames appended one at a time into a workspace array; :attr:`data` is ``(count, *shape)`` once filled.

    Sized for the frame count a video's header gives; a video that turns out longer grows it.
    """

    def __init__(self, workspace: Workspace, n_frames: int, shape, dtype, name: str):
        self._ws = workspace
        self._shape = tuple(int(s) for s in shape)
        self._dtype = np.dtype(dtype)
        self._array = workspace.array((max(int(n_frames), 1), *self._shape), dtype, name=name)
        if isinstance(self._array, DiskArray):
            self._array.count = 0
        self.count = 0

    def append(self, frame) -> None:
        if isinstance(self._array, DiskArray):
            self._array.append(frame)
            self._ws.note_disk()
        else:
            if self.count >= self._array.shape[0]:  # more frames than the header said
                bigger = np.empty((int(self.count * 1.25) + 1, *self._shape), self._dtype)
                bigger[: self.count] = self._array[: self.count]
                self._ws.release(self._array)
                self._array = bigger
            self._array[self.count] = frame
        self.count += 1

    @property
    def data(self):
        """The frames appended so far, ``(count, *shape)``: an array, or a :class:`DiskArray`."""
        if isinstance(self._array, DiskArray):
            return self._array
        return self._array[: self.count]


def pixel_tiles(shape, bytes_per_pixel: float, tile_bytes: int | None):
    """Boxes ``(r0, r1, c0, c1)`` covering an ``(H, W)`` image in row-major order, each of at most
    ``tile_bytes / bytes_per_pixel`` pixels: whole rows where a row fits, parts of one row where it
    does not; one box (the image) without ``tile_bytes``.

    Examples
    --------
    >>> list(pixel_tiles((3, 4), 8.0, 64))
    [(0, 2, 0, 4), (2, 3, 0, 4)]
    >>> list(pixel_tiles((1, 4), 8.0, 24))
    [(0, 1, 0, 3), (0, 1, 3, 4)]
    """
    H, W = (int(s) for s in shape)
    if tile_bytes is None:
        yield (0, H, 0, W)
        return
    pixels = max(int(tile_bytes // max(bytes_per_pixel, 1e-300)), 1)
    if pixels >= W:
        rows = pixels // W
        for r0 in range(0, H, rows):
            yield (r0, min(r0 + rows, H), 0, W)
        return
    for r in range(H):
        for c0 in range(0, W, pixels):
            yield (r, r + 1, c0, min(c0 + pixels, W))
