"""Scratch arrays of a pulse analysis: in memory while they fit an allowance, on disk beyond it.

A long or large recording cannot be held whole: the analysis (:func:`planeray.pulse.analysis.analyze_pulse`)
reads it frame by frame and keeps only what it must -- a pyramid level over time, the magnified video
for the automatic region search, the search's per-pixel spectra -- in arrays a :class:`Workspace` hands
out.  Each is an ordinary NumPy array while the workspace's memory allowance lasts, and a
:class:`DiskArray` (a raw file in the workspace's folder, read and written block by block, so none of
it stays in the process's resident memory) beyond it.  Both are read and written by the same slicing, so every step is one implementation
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
    """A C-ordered array in a raw file, read and written by NumPy-style slicing (steps of 1).

    Every access reads or writes the bytes of the selected block with ``os.preadv`` / ``os.pwritev``,
    one contiguous run at a time (a tile of whole rows is one run per frame): what a read returns is an
    ordinary array, and nothing of the file stays in the process.  (:class:`numpy.memmap` was measured
    otherwise: reading a tile of 9 rows of every 1080p frame mapped ~2 MB around each of them -- the
    kernel maps whole page-cache folios -- so a 300-frame tile held ~600 MB of the file resident.)
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
        with _named_plainly():
            self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o600)
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

    def close(self) -> None:
        """Close the file (the workspace removes it)."""
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None

    def _reserve(self, rows: int) -> None:
        if rows > self._capacity:
            with _named_plainly():
                os.ftruncate(self._fd, max(rows * self._row_bytes, 1))  # sparse: nothing written yet
            self._capacity = rows

    def _runs(self, key):
        """The block ``key`` selects: its shape, the axes an integer index drops, and its contiguous runs
        as ``(index into the block's flat data, file offset, number of items)``."""
        shape = self.shape
        key = key if isinstance(key, tuple) else (key,)
        if any(k is Ellipsis for k in key):
            i = key.index(Ellipsis)
            key = key[:i] + (slice(None),) * (len(shape) - len(key) + 1) + key[i + 1 :]
        key = key + (slice(None),) * (len(shape) - len(key))
        if len(key) != len(shape):
            raise IndexError(f"too many indices for a DiskArray of shape {shape}")
        starts, sizes, drop = [], [], []
        for axis, (k, n) in enumerate(zip(key, shape)):
            if isinstance(k, slice):
                start, stop, step = k.indices(n)
                if step != 1:
                    raise IndexError("a DiskArray is sliced with steps of 1")
                starts.append(start)
                sizes.append(max(stop - start, 0))
            else:
                i = int(k) + (n if int(k) < 0 else 0)
                if not 0 <= i < n:
                    raise IndexError(f"index {k} is out of bounds for axis {axis} with size {n}")
                starts.append(i)
                sizes.append(1)
                drop.append(axis)
        strides = [int(np.prod(shape[a + 1 :], dtype=np.int64)) for a in range(len(shape))]
        inner = len(shape) - 1  # the runs: the innermost axes whose whole extent is selected, and the one before
        while inner > 0 and sizes[inner] == shape[inner]:
            inner -= 1
        run = sizes[inner] * strides[inner]
        runs = []
        for k, outer in enumerate(np.ndindex(*sizes[:inner])):
            offset = sum((starts[a] + outer[a]) * strides[a] for a in range(inner)) + starts[inner] * strides[inner]
            runs.append((k * run, offset * self.dtype.itemsize, run))
        return tuple(sizes), drop, runs

    def __getitem__(self, key) -> np.ndarray:
        sizes, drop, runs = self._runs(key)
        out = np.empty(sizes, self.dtype)
        flat = out.reshape(-1)
        if flat.size:
            with _named_plainly():
                for start, offset, n in runs:
                    view = memoryview(flat[start : start + n]).cast("B")
                    got = os.preadv(self._fd, [view], offset)
                    if got != view.nbytes:  # never written (sparse): zeros, as the file reads
                        view[got:] = bytes(view.nbytes - got)
        return out.reshape([n for a, n in enumerate(sizes) if a not in drop])

    def __setitem__(self, key, value) -> None:
        sizes, drop, runs = self._runs(key)
        kept = [n for a, n in enumerate(sizes) if a not in drop]
        flat = np.ascontiguousarray(np.broadcast_to(np.asarray(value, self.dtype), kept)).reshape(-1)
        with _named_plainly():
            for start, offset, n in runs:
                view = memoryview(flat[start : start + n]).cast("B")
                while view.nbytes:
                    done = os.pwritev(self._fd, [view], offset)
                    view, offset = view[done:], offset + done

    def __array__(self, dtype=None, copy=None):
        out = self[...]
        return out if dtype is None else out.astype(dtype, copy=False)

    def append(self, row) -> None:
        """Write ``row`` after the last one (the file grows as needed)."""
        if self.count >= self._capacity:
            self._reserve(max(self.count + 1, int(self._capacity * 1.25) + 1))
        with _named_plainly():
            self._write(self.count, np.ascontiguousarray(row, self.dtype))
        self.count += 1

    def _write(self, index: int, row: np.ndarray) -> None:
        view = memoryview(row.reshape(-1)).cast("B")
        offset = index * self._row_bytes
        while view.nbytes:
            done = os.pwritev(self._fd, [view], offset)
            view, offset = view[done:], offset + done


@contextlib.contextmanager
def _named_plainly():
    """A file-system error in a scratch file, without the scratch file's name: the caller names its output."""
    try:
        yield
    except OSError as exc:
        raise OSError(exc.errno, f"{exc.strerror or exc} (in the analysis's temporary files)") from None


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
            array.close()
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
        for disk in self._disk:
            disk.close()
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
