"""Videos for pulse analysis: read recordings (multi-page TIFF, a folder of frames, mp4/avi/mkv/mov), write them.

A :class:`Video` is ``frames`` ``(T, H, W)`` float32 (grey, or one colour channel) and its frame
rate; a :class:`VideoFile` (:func:`open_video`) is a recording on disk read **frame by frame**, for
videos too long or large to hold (a 30 s 1080p video is 7.5 GB of float32 frames): its frame
count, size and rate come from the file's header (TIFF pages, the folder's listing, the
container's metadata), so everything can be checked before a frame is decoded, and
:meth:`VideoFile.iter_frames` yields the frames one at a time, again on every pass.  Both have
``n_frames``, ``shape``, ``fps`` and ``iter_frames()``, which is all the pulse analysis
(:func:`planeray.pulse.analysis.analyze_pulse`) asks of a video; :func:`read_video` reads a file
whole into a :class:`Video`.

The frame rate is required: it comes from the file (ImageJ ``finterval``/``fps`` of a TIFF, the
container's rate of a video file) or from the caller (``fps=``, the CLI's ``--fps``, which also
overrides the file's).  Integer frames are scaled to 0..1 by their type's range.

Every bad recording is refused with one line naming the file and the problem: no frame rate,
fewer than :data:`MIN_FRAMES` frames, frames of mixed sizes, NaN or infinite values, an
unreadable file.

Formats
-------
* ``.tif`` / ``.tiff``: multi-page TIFF, pages ``(H, W)`` or ``(H, W, C)`` (or one page holding
  the frames contiguously, as ImageJ writes stacks over 4 GB); written as an ImageJ hyperstack
  (float32, ``finterval = 1/fps``) -- lossless, the format to keep a simulated capture in.
* a folder of ``.png`` / ``.tif`` / ``.tiff`` / ``.jpg`` frames, in name order (natural order:
  ``frame2`` before ``frame10``); the folder carries no frame rate, so ``fps`` is required.
* ``.mp4`` / ``.avi`` / ``.mkv`` / ``.mov``: decoded by OpenCV (``cv2.VideoCapture``, its bundled
  FFmpeg), encoded by ffmpeg through ``imageio-ffmpeg`` (the wheel carries ffmpeg), 8-bit:
  H.264 (lossless, ``crf 0``) in mp4/mov, lossless FFV1 in mkv, MJPEG in avi:
  quantization to 8 bits and lossy codecs dilute a 1 % pulse, so keep TIFF for analysis.
  Frames are written one at a time (:func:`encode_frames`), so a video is never held whole to be
  written either.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._extras import import_extra
from .._validate import check_positive
from ..errors import InputError
from ..io import atomic_file

__all__ = [
    "Video",
    "VideoFile",
    "open_video",
    "encode_frames",
    "FramePercentile",
    "MIN_FRAMES",
    "VIDEO_SUFFIXES",
    "WRITE_SUFFIXES",
    "IMAGE_SUFFIXES",
    "read_video",
    "write_video",
    "encode_video",
    "check_video",
    "check_frame_count",
    "check_video_path",
    "video_bytes",
]

#: The fewest frames a pulse analysis accepts (one frame has no time axis).
MIN_FRAMES = 8
#: Video-file suffixes -> the codec that writes them.
VIDEO_SUFFIXES = {".mp4": "libx264", ".avi": "mjpeg", ".mkv": "ffv1", ".mov": "libx264"}
#: Frame files of a folder.
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg")
_CHANNELS = ("gray", "red", "green", "blue")


@dataclass
class Video:
    """Frames and their rate.

    Attributes
    ----------
    frames : ndarray (T, H, W) float32
    fps : float
    source : str
        Where the frames came from (a path, or ``"simulated"``).
    meta : dict
        Anything the reader or simulator knows (JSON-serializable).
    """

    frames: np.ndarray
    fps: float
    source: str = ""
    meta: dict = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.frames.shape[0])

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.frames.shape[1:3])

    @property
    def duration_s(self) -> float:
        return self.n_frames / self.fps

    def iter_frames(self):
        """The frames ``(H, W)`` float32, one at a time (views of :attr:`frames` where they are float32)."""
        for frame in self.frames:
            yield np.asarray(frame, np.float32)


def check_frame_count(n_frames: int, where="video") -> None:
    """A one-line :class:`InputError` naming ``where`` for fewer than :data:`MIN_FRAMES` frames."""
    if n_frames < MIN_FRAMES:
        s = "s" if n_frames != 1 else ""
        raise InputError(f"{n_frames} frame{s}: a pulse needs a video (at least {MIN_FRAMES} frames)", where)


def _check_rate(fps, where) -> float:
    if fps is None:
        raise InputError("no frame rate: the file does not give one; pass fps (--fps)", where)
    try:
        fps = float(fps)
    except (TypeError, ValueError):
        raise InputError(f"frame rate must be a number, got {fps!r}", where) from None
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(f"frame rate must be positive, got {fps:g}", where)
    return fps


def check_video(frames, fps, where="video") -> Video:
    """A :class:`Video` from ``frames`` and ``fps``, or one-line :class:`InputError` naming ``where``."""
    fps = _check_rate(fps, where)
    frames = np.asarray(frames)
    if frames.ndim != 3:
        raise InputError(f"expected frames (T, H, W), got an array of shape {frames.shape}", where)
    check_frame_count(frames.shape[0], where)
    if frames.shape[1] < 1 or frames.shape[2] < 1:
        raise InputError(f"empty frames of shape {frames.shape[1:]}", where)
    frames = frames.astype(np.float32, copy=False)
    bad = ~np.isfinite(frames)
    if bad.any():
        t = int(np.argwhere(bad.reshape(frames.shape[0], -1).any(axis=1))[0, 0])
        raise InputError(f"frame {t} contains NaN or infinite values", where)
    return Video(frames, fps, str(where))


def _to_unit(array: np.ndarray) -> np.ndarray:
    if np.issubdtype(array.dtype, np.integer):
        return array.astype(np.float32) / np.float32(np.iinfo(array.dtype).max)
    if array.dtype == bool:
        return array.astype(np.float32)
    return array.astype(np.float32, copy=False)


#: Weights of red, green and blue in the luma (Rec. 601).
_LUMA = (0.299, 0.587, 0.114)


def _unit_table(dtype) -> np.ndarray:
    """The float32 value :func:`_to_unit` gives every code of an 8- or 16-bit unsigned type."""
    key = np.dtype(dtype).str
    table = _TABLES.get(key)
    if table is None:
        table = _TABLES[key] = _to_unit(np.arange(np.iinfo(dtype).max + 1, dtype=dtype))
    return table


def _luma_tables(dtype) -> list[np.ndarray]:
    key = (np.dtype(dtype).str, "gray")
    tables = _TABLES.get(key)
    if tables is None:
        tables = _TABLES[key] = [_unit_table(dtype) * w for w in _LUMA]
    return tables


_TABLES: dict = {}


def _frame_to_float(raw, channel: str, path, *, bgr: bool = False) -> np.ndarray:
    """One frame ``(H, W[, C])`` of a file (colours in RGB order, or BGR as OpenCV decodes them) ->
    ``(H, W)`` float32: what :func:`_to_unit` and :func:`_pick_channel` make of it in an RGB stack.

    8- and 16-bit frames are looked up in tables of those values (the same operations on the same
    codes, so the same float32 values; a 1080p colour frame ~4x faster).
    """
    raw = np.asarray(raw)
    if raw.dtype.kind == "u" and raw.dtype.itemsize <= 2 and raw.ndim == 2:
        return _lookup(_unit_table(raw.dtype), raw)
    if raw.dtype.kind == "u" and raw.dtype.itemsize <= 2 and raw.ndim == 3 and raw.shape[-1] in (3, 4):
        _check_channel(channel)
        rgb = (2, 1, 0) if bgr else (0, 1, 2)
        if channel != "gray":
            return _lookup(_unit_table(raw.dtype), raw, rgb[_CHANNELS.index(channel) - 1])
        tables = _luma_tables(raw.dtype)
        out = _lookup(tables[0], raw, rgb[0])  # r w_r + g w_g + b w_b, added in that order
        out += _lookup(tables[1], raw, rgb[1])
        out += _lookup(tables[2], raw, rgb[2])
        return out
    if bgr and raw.ndim == 3 and raw.shape[-1] in (3, 4):
        raw = raw[..., [2, 1, 0]]
    frame = _pick_channel(_to_unit(raw)[None], channel, path)[0]
    return np.ascontiguousarray(frame, np.float32)


def _lookup(table: np.ndarray, raw: np.ndarray, channel: int | None = None) -> np.ndarray:
    """``table[raw]`` (of one channel of ``raw``): OpenCV's ``LUT`` for 8 bits, ``numpy.take`` beyond."""
    if raw.dtype == np.uint8:
        cv2 = import_extra("cv2", "reading 8-bit video frames")

        plane = raw if channel is None else cv2.extractChannel(np.ascontiguousarray(raw), channel)
        return cv2.LUT(plane, table)
    return np.take(table, raw if channel is None else raw[..., channel])


def _check_channel(channel: str) -> None:
    if channel not in _CHANNELS:
        raise InputError(f"channel must be one of {', '.join(_CHANNELS)}, got {channel!r}")


def _pick_channel(frames: np.ndarray, channel: str, path) -> np.ndarray:
    """(..., H, W, C) -> (..., H, W): luma (Rec. 601) or one of red/green/blue; grey frames as they are.

    ``frames`` is a stack ``(T, H, W[, C])`` or one frame ``(H, W[, C])`` (``frames.ndim`` tells which
    only together with the frame's shape: the caller passes whole stacks, :class:`VideoFile` single frames
    as ``frame[None]``).
    """
    _check_channel(channel)
    if frames.ndim == 3:
        return frames
    if frames.ndim != 4 or frames.shape[-1] not in (3, 4):
        raise InputError(f"expected grey or RGB frames, got an array of shape {frames.shape}", path)
    if channel == "gray":
        return frames[..., 0] * _LUMA[0] + frames[..., 1] * _LUMA[1] + frames[..., 2] * _LUMA[2]
    return frames[..., _CHANNELS.index(channel) - 1]


def _natural_key(path: Path):
    return [int(s) if s.isdigit() else s.lower() for s in re.split(r"(\d+)", path.name)]


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


# ---------------------------------------------------------------------------- sources: a file's raw frames
class _TiffSource:
    """A multi-page TIFF, a page per frame; or one page holding the frames contiguously (ImageJ's > 4 GB
    stacks), read by offset; or one page that is the only frame."""

    def __init__(self, path: Path):
        import tifffile

        self.path = path
        self._array = None  # a single page read whole
        self._contiguous = None  # (offset, dtype, frame shape) of frames stored one after another
        try:
            with tifffile.TiffFile(path) as tif:
                self.fps = None
                ij = tif.imagej_metadata or {}
                if ij.get("finterval"):
                    self.fps = 1.0 / float(ij["finterval"])
                elif ij.get("fps"):
                    self.fps = float(ij["fps"])
                desc = tif.pages[0].description if tif.pages else ""
                if self.fps is None and desc.startswith("{"):
                    try:
                        self.fps = json.loads(desc).get("fps")
                    except ValueError:
                        pass
                pages = tif.pages
                pages.cache = False
                pages.useframes = False
                n = len(pages)
                shapes = {p.shape for p in pages} if n > 1 else {pages[0].shape}
                if len(shapes) > 1:
                    raise InputError(f"pages of mixed sizes {sorted(shapes)}", path)
                if n > 1:
                    self.n_frames, self.frame_shape, self.dtype = n, tuple(pages[0].shape), pages[0].dtype
                    return
                series = tif.series[0]
                page_shape = tuple(pages[0].shape)
                if (
                    len(series.shape) > len(page_shape)
                    and series.dataoffset is not None
                    and int(np.prod(series.shape[: len(series.shape) - len(page_shape)])) > 1
                ):
                    self.n_frames = int(np.prod(series.shape[: len(series.shape) - len(page_shape)]))
                    self.frame_shape, self.dtype = page_shape, series.dtype
                    self._contiguous = (int(series.dataoffset), np.dtype(tif.byteorder + series.dtype.char), page_shape)
                    return
                frames = tif.asarray()
        except InputError:
            raise
        except Exception as exc:
            raise InputError(f"cannot read as TIFF ({_one_line(exc)})", path) from None
        if frames.ndim == 2 or (frames.ndim == 3 and frames.shape[-1] in (3, 4) and len(page_shape) == 3):
            frames = frames[None]  # one grey page, or a single RGB page
        self._array = frames
        self.n_frames, self.frame_shape, self.dtype = frames.shape[0], tuple(frames.shape[1:]), frames.dtype

    def __iter__(self):
        if self._array is not None:
            yield from self._array
            return
        import tifffile

        try:
            if self._contiguous is not None:
                offset, dtype, shape = self._contiguous
                count = int(np.prod(shape))
                with open(self.path, "rb") as f:
                    for t in range(self.n_frames):
                        f.seek(offset + t * count * dtype.itemsize)
                        frame = np.fromfile(f, dtype, count)
                        if frame.size != count:
                            raise InputError(f"the file ends within frame {t}", self.path)
                        yield frame.reshape(shape).astype(dtype.newbyteorder("="), copy=False)
                return
            with tifffile.TiffFile(self.path) as tif:
                pages = tif.pages
                pages.cache = False
                pages.useframes = False
                for t in range(self.n_frames):
                    yield pages[t].asarray()
        except InputError:
            raise
        except Exception as exc:
            raise InputError(f"cannot read as TIFF ({_one_line(exc)})", self.path) from None


class _FolderSource:
    """A folder of frame files in natural name order; their sizes checked from their headers when opened."""

    fps = None

    def __init__(self, path: Path):
        self.path = path
        self.files = sorted((p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES), key=_natural_key)
        if not self.files:
            raise InputError(f"no frames ({', '.join(IMAGE_SUFFIXES)}) in the folder", path)
        self.n_frames = len(self.files)
        shape0 = None
        for f in self.files:
            shape, dtype = self._header(f)
            if shape0 is None:
                shape0, self.dtype = shape, dtype
            elif shape != shape0:
                raise InputError(f"frames of mixed sizes: {f.name} is {shape}, {self.files[0].name} is {shape0}", path)
        self.frame_shape = shape0

    @staticmethod
    def _header(f: Path):
        """``(shape, dtype)`` of a frame file without decoding it."""
        try:
            if f.suffix.lower() in (".tif", ".tiff"):
                import tifffile

                with tifffile.TiffFile(f) as tif:
                    series = tif.series[0]
                    return tuple(series.shape), series.dtype
            from PIL import Image

            with Image.open(f) as im:
                bands = len(im.getbands())
                shape = (im.height, im.width) if bands == 1 else (im.height, im.width, bands)
                return shape, None
        except Exception as exc:
            raise InputError(f"cannot read frame ({_one_line(exc)})", f) from None

    def __iter__(self):
        from PIL import Image

        for f in self.files:
            try:
                if f.suffix.lower() in (".tif", ".tiff"):
                    import tifffile

                    a = tifffile.imread(f)
                else:
                    with Image.open(f) as im:
                        a = np.asarray(im)
            except Exception as exc:
                raise InputError(f"cannot read frame ({_one_line(exc)})", f) from None
            if a.shape != self.frame_shape:
                raise InputError(
                    f"frames of mixed sizes: {f.name} is {a.shape}, {self.files[0].name} is {self.frame_shape}",
                    self.path,
                )
            yield a


class _OpenCVSource:
    """A video file decoded by OpenCV; its frame count and rate from the container, its size from the first frame."""

    bgr = True  # colour frames come in OpenCV's order

    def __init__(self, path: Path):
        self.path = path
        cap = self._open()
        try:
            fps = cap.get(self._cv2.CAP_PROP_FPS)
            count = cap.get(self._cv2.CAP_PROP_FRAME_COUNT)
            ok, frame = cap.read()
        finally:
            cap.release()
        if not ok:
            raise InputError("cannot decode the video (no frames)", path)
        self.fps = float(fps) if fps and np.isfinite(fps) and fps > 0 else None
        self.frame_shape, self.dtype = tuple(frame.shape), frame.dtype
        if count and np.isfinite(count) and count >= 1:
            self.n_frames = int(count)
        else:  # no count in the container: count by demuxing (no decoding)
            cap = self._open()
            try:
                n = 0
                while cap.grab():
                    n += 1
            finally:
                cap.release()
            self.n_frames = n

    def _open(self):
        import os

        # FFmpeg inside OpenCV would print its own complaints about a bad file; the error says it in one line
        os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
        cv2 = import_extra("cv2", "decoding a video")

        self._cv2 = cv2
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            cap.release()
            raise InputError("cannot decode the video (OpenCV/FFmpeg could not open it)", self.path)
        return cap

    def __iter__(self):
        cap = self._open()
        try:
            while True:
                ok, frame = cap.read()
                if not ok:
                    break
                yield frame  # BGR (see bgr)
        finally:
            cap.release()


def _source(path: Path):
    if not path.exists():
        raise InputError("no such file or folder", path)
    if path.is_dir():
        return _FolderSource(path)
    if path.suffix.lower() in (".tif", ".tiff"):
        return _TiffSource(path)
    if path.suffix.lower() in VIDEO_SUFFIXES:
        return _OpenCVSource(path)
    raise InputError(
        f"unknown video format {path.suffix!r}: expected .tif/.tiff, {'/'.join(VIDEO_SUFFIXES)} or a folder of frames",
        path,
    )


class VideoFile:
    """A recording on disk, read frame by frame: a :class:`Video` whose frames are not held.

    Made by :func:`open_video`, which reads only the file's header: :attr:`n_frames`, :attr:`shape`,
    :attr:`fps`, :attr:`duration_s` are known before any frame is decoded.  :meth:`iter_frames`
    decodes the frames one at a time, as :func:`read_video` would give them (the same float32
    values), on every call anew; :meth:`read` reads them all into a :class:`Video`.

    A container whose header miscounts its frames is believed until a pass has decoded them all:
    that pass's count becomes :attr:`n_frames`, and a later pass that finds another count is refused
    (the file changed while it was read).
    """

    def __init__(self, source, fps: float, channel: str, meta: dict):
        self._source = source
        self.path = source.path
        self.fps = fps
        self.channel = channel
        self.source = str(source.path)
        self.meta = meta
        self.n_frames = int(source.n_frames)
        self._counted = False
        self._integer = source.dtype is not None and (np.issubdtype(source.dtype, np.integer) or source.dtype == bool)
        frame_shape = tuple(source.frame_shape)
        self.shape = frame_shape[:2]
        if len(frame_shape) == 3 and frame_shape[-1] not in (3, 4) or len(frame_shape) not in (2, 3):
            raise InputError(
                f"expected grey or RGB frames, got an array of shape {(self.n_frames, *frame_shape)}", self.path
            )

    @property
    def duration_s(self) -> float:
        return self.n_frames / self.fps

    @property
    def frame_bytes(self) -> int:
        """Bytes of one float32 frame."""
        return video_bytes(1, self.shape)

    def iter_frames(self):
        """The frames ``(H, W)`` float32 in order, decoded one at a time.

        Raises
        ------
        InputError
            A frame with NaN or infinite values, a frame that cannot be decoded, or a pass that finds
            another number of frames than an earlier one.
        """
        n = 0
        for raw in self._source:
            frame = _frame_to_float(raw, self.channel, self.path, bgr=getattr(self._source, "bgr", False))
            if not self._integer and not np.isfinite(frame).all():
                raise InputError(f"frame {n} contains NaN or infinite values", self.path)
            yield frame
            n += 1
        if n != self.n_frames:
            if self._counted:
                raise InputError(f"the video changed while it was read: {self.n_frames} frames, then {n}", self.path)
            self.n_frames = n
            self.meta = {**self.meta, "frames_from": "decoded (the header said otherwise)"}
        self._counted = True
        check_frame_count(n, self.path)

    def read(self) -> Video:
        """All frames, in memory (``n_frames * H * W * 4`` bytes)."""
        frames = np.empty((self.n_frames, *self.shape), np.float32)
        n = 0
        for frame in self.iter_frames():
            if n == frames.shape[0]:  # more frames than the header said
                frames = np.concatenate([frames, np.empty_like(frames[: n // 4 + 1])])
            frames[n] = frame
            n += 1
        return Video(frames[: self.n_frames], self.fps, self.source, dict(self.meta))


def open_video(path, *, fps: float | None = None, channel: str = "gray") -> VideoFile:
    """Open a recording to be read frame by frame (:class:`VideoFile`), reading only its header.

    Parameters
    ----------
    path : str or os.PathLike
        A multi-page TIFF, a folder of frames, or a video file (see the module's formats).
    fps : float, optional
        Frame rate; required when the file does not give one, and overrides it when it does.
    channel : {"gray", "red", "green", "blue"}
        What to keep of colour frames (luma by default; rPPG often prefers green).

    Raises
    ------
    InputError
        One line naming the file: missing, unreadable, no frame rate, too few frames, mixed sizes
        (NaN values are found while the frames are read).
    """
    path = Path(path)
    source = _source(path)
    if fps is not None:
        fps = check_positive(fps, "--fps")
    _check_channel(channel)
    rate = _check_rate(fps if fps is not None else source.fps, path)
    check_frame_count(int(source.n_frames), path)
    shape = tuple(source.frame_shape)
    if len(shape) < 2 or shape[0] < 1 or shape[1] < 1:
        raise InputError(f"empty frames of shape {shape}", path)
    meta = {"fps_from": "argument" if fps is not None else "file", "channel": channel}
    return VideoFile(source, rate, channel, meta)


def read_video(path, *, fps: float | None = None, channel: str = "gray") -> Video:
    """Read a recording whole as a :class:`Video`: :func:`open_video` (its parameters), then every frame.

    Raises
    ------
    InputError
        One line naming the file: missing, unreadable, no frame rate, too few frames,
        mixed sizes, NaN.
    """
    return open_video(path, fps=fps, channel=channel).read()


#: Suffixes :func:`write_video` writes.
WRITE_SUFFIXES = (".tif", ".tiff", *VIDEO_SUFFIXES)
#: Kind of planeray's mark in the videos it writes (TIFF tag ``Software``, the container's ``title``).
VIDEO_KIND = "video"


def check_video_path(path, option: str = "path") -> Path:
    """A path :func:`write_video` can write (by its suffix), or one line naming ``option``."""
    path = Path(path)
    if path.suffix.lower() not in WRITE_SUFFIXES:
        raise InputError(f"{option} must end in {', '.join(WRITE_SUFFIXES)}, got {path.name!r}")
    return path


def video_bytes(n_frames: int, shape) -> int:
    """Bytes of ``n_frames`` float32 frames of ``shape`` (H, W)."""
    return int(n_frames) * int(shape[0]) * int(shape[1]) * 4


def write_video(path, video: Video, *, overwrite: bool = False, white: float | None = None) -> Path:
    """Write a video atomically: TIFF (float32, lossless, with its rate) or 8-bit mp4/avi/mkv/mov.

    ``white`` (8-bit formats): the value shown as 255 (default: the 99.9th percentile).
    ``video.meta`` goes into the TIFF as JSON (``planeray_video`` in the ImageJ ``Info``).  Every
    file carries planeray's mark (:mod:`planeray.io.marks`: the TIFF's ``Software`` tag, the
    container's ``title``), and an existing file is replaced only with ``overwrite`` and only if
    its mark says planeray wrote it as a video.
    """
    from ..io.atomic import check_replaceable

    path = check_video_path(path)
    check_replaceable(path, overwrite=overwrite, kind=VIDEO_KIND)
    with atomic_file(path, overwrite=overwrite) as tmp:
        encode_video(tmp, video, white=white, suffix=path.suffix)
    return path


def encode_video(path, video: Video, *, white: float | None = None, suffix: str | None = None) -> Path:
    """Write ``video`` to ``path`` as it is, not atomically: for a caller that holds a temporary
    (:func:`write_video` and the commands that write several files together).

    ``suffix`` picks the format (default: ``path``'s own); ``white`` (8-bit formats) the value shown
    as 255 (default: the frames' 99.9th percentile).
    """
    suffix = (suffix or Path(path).suffix).lower()
    if white is None and suffix not in (".tif", ".tiff"):
        white = float(np.percentile(np.asarray(video.frames, np.float32), 99.9))
    return encode_frames(
        path,
        video.iter_frames(),
        n_frames=video.n_frames,
        shape=video.shape,
        fps=video.fps,
        meta=video.meta,
        white=white,
        suffix=suffix,
    )


def encode_frames(
    path, frames, *, n_frames: int, shape, fps: float, meta: dict | None = None, white: float = 1.0, suffix=None
) -> Path:
    """Write frames given one at a time to ``path``, not atomically (:func:`encode_video` of a whole video).

    Parameters
    ----------
    path : str or os.PathLike
        The file (its caller's temporary).
    frames : iterable of ndarray (H, W) float32
        Exactly ``n_frames`` frames, consumed one at a time.
    n_frames : int
    shape : (int, int)
        ``(H, W)``.
    fps : float
        Frame rate (Hz), recorded in the file.
    meta : dict, optional
        JSON-serializable; written into the TIFF (``planeray_video`` in the ImageJ ``Info``).
    white : float
        8-bit formats: the value shown as 255.
    suffix : str, optional
        Picks the format (default: ``path``'s own).
    """
    from ..io.marks import mark_text

    path = Path(path)
    suffix = (suffix or path.suffix).lower()
    if suffix not in WRITE_SUFFIXES:
        raise InputError(f"video files end in {', '.join(WRITE_SUFFIXES)}, got {path.name!r}")
    H, W = (int(v) for v in shape)
    frames = (np.asarray(f, np.float32) for f in frames)
    if suffix in (".tif", ".tiff"):
        import tifffile

        info = json.dumps({"planeray_video": {"fps": fps, **(meta or {})}})
        tifffile.imwrite(
            path,
            frames,
            shape=(int(n_frames), H, W),
            dtype=np.float32,
            imagej=True,
            software=mark_text(VIDEO_KIND),
            metadata={"axes": "TYX", "finterval": 1.0 / fps, "Info": info},
        )
        return path
    imageio_ffmpeg = import_extra("imageio_ffmpeg", f"writing a {suffix} video")

    top = float(white)
    scale = 255.0 / top if top > 0 else 1.0
    codec = VIDEO_SUFFIXES[suffix]
    extra = {"pix_fmt_out": "yuvj420p"} if codec == "mjpeg" else {}
    if codec == "ffv1":
        extra = {"pix_fmt_out": "gray"}
    writer = imageio_ffmpeg.write_frames(
        str(path),
        (W + W % 2, H + H % 2),
        pix_fmt_in="gray",
        fps=fps,
        codec=codec,
        macro_block_size=1,
        quality=None if codec == "ffv1" else 10,
        ffmpeg_log_level="error",
        output_params=["-metadata", f"title={mark_text(VIDEO_KIND)}"],
        **extra,
    )
    try:
        writer.send(None)
        for f in frames:
            gray = np.clip(f * scale + 0.5, 0, 255).astype(np.uint8)
            writer.send(np.ascontiguousarray(np.pad(gray, ((0, H % 2), (0, W % 2)), mode="edge")))
    finally:
        writer.close()
    return path


class FramePercentile:
    """The ``q``-th percentile of every value of frames given one at a time, as :func:`numpy.percentile`
    of them all gives it (linear interpolation), holding only the largest values: ``(1 - q/100)`` of the
    ``n_values`` expected (0.1 % of a video for the 99.9th percentile, the white level of an 8-bit video).

    Parameters
    ----------
    q : float
        Percentile, at least 50.
    n_values : int
        Values expected in all (frames times pixels); with more, the answer is the one of the largest
        values kept (exact as long as no more than ``n_values`` arrive).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> frames = rng.random((20, 8, 8)).astype(np.float32)
    >>> p = FramePercentile(99.0, frames.size)
    >>> for f in frames:
    ...     p.add(f)
    >>> bool(p.value() == np.percentile(frames, 99.0))
    True
    """

    def __init__(self, q: float, n_values: int):
        if not 50.0 <= float(q) <= 100.0:
            raise InputError(f"FramePercentile keeps the largest values: q must be 50-100, got {q!r}")
        self.q = float(q)
        self.n_expected = int(n_values)
        self._keep = self.n_expected - int(np.floor(self.q / 100.0 * (self.n_expected - 1))) + 1
        self._parts: list[np.ndarray] = []
        self._held = 0
        self._floor = -np.inf
        self.count = 0

    def add(self, values) -> None:
        v = np.asarray(values).ravel()
        self.count += v.size
        v = v[v > self._floor] if np.isfinite(self._floor) else v.copy()
        if v.size:
            self._parts.append(v)
            self._held += v.size
        if self._held > 2 * self._keep + 4096:
            self._shrink()

    def _shrink(self) -> None:
        top = np.concatenate(self._parts)
        if top.size > self._keep:
            top = np.partition(top, top.size - self._keep)[top.size - self._keep :]
            self._floor = top.min()
        self._parts, self._held = [top], top.size

    def value(self) -> float:
        """The percentile of the values given so far (NaN before any)."""
        if not self.count:
            return float("nan")
        top = np.sort(np.concatenate(self._parts)) if self._parts else np.empty(0, np.float32)
        n = self.count
        q = self.q / 100.0
        virtual = n * q + (1 + q * -1) - 1  # numpy's linear method (alpha = beta = 1)
        below = int(np.floor(virtual))
        first = n - top.size  # the rank of top[0] among all values
        i = min(max(below - first, 0), top.size - 1)
        j = min(max(below + 1 - first, 0), top.size - 1) if below + 1 < n else i
        a, b = top[i], top[j]
        gamma = float(virtual - below)
        diff = b - a
        out = a + diff * gamma
        if gamma >= 0.5:
            out = b - diff * (1 - gamma)
        return float(out)
