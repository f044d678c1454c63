"""Videos for pulse analysis: read recordings (multi-page TIFF, a folder of frames, mp4/avi/mkv/mov), write them.

A :class:`Video` is ``frames`` ``(T, H, W)`` float32 (grey, or one colour channel) and its frame
rate.  The frame rate is required: it comes from the file (ImageJ ``finterval``/``fps`` of a
TIFF, the container's rate of a video file) or from the caller (``fps=``, the CLI's ``--fps``,
which also overrides the file's).  Integer frames are scaled to 0..1 by their type's range.

Every bad recording is refused with one line naming the file and the problem: no frame rate,
fewer than :data:`MIN_FRAMES` frames, frames of mixed sizes, NaN or infinite values, an
unreadable file.

Formats
-------
* ``.tif`` / ``.tiff``: multi-page TIFF, pages ``(H, W)`` or ``(H, W, C)``; written as an ImageJ
  hyperstack (float32, ``finterval = 1/fps``) -- lossless, the format to keep a simulated capture in.
* a folder of ``.png`` / ``.tif`` / ``.tiff`` / ``.jpg`` frames, in name order (natural order:
  ``frame2`` before ``frame10``); the folder carries no frame rate, so ``fps`` is required.
* ``.mp4`` / ``.avi`` / ``.mkv`` / ``.mov``: decoded by OpenCV (``cv2.VideoCapture``, its bundled
  FFmpeg), encoded by ffmpeg through ``imageio-ffmpeg`` (the wheel carries ffmpeg), 8-bit:
  H.264 (lossless, ``crf 0``) in mp4/mov, lossless FFV1 in mkv, MJPEG in avi:
  quantization to 8 bits and lossy codecs dilute a 1 % pulse, so keep TIFF for analysis.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._validate import check_positive
from ..errors import InputError
from ..io import atomic_file

__all__ = [
    "Video",
    "MIN_FRAMES",
    "VIDEO_SUFFIXES",
    "WRITE_SUFFIXES",
    "IMAGE_SUFFIXES",
    "read_video",
    "write_video",
    "encode_video",
    "check_video",
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


def check_video(frames, fps, where="video") -> Video:
    """A :class:`Video` from ``frames`` and ``fps``, or one-line :class:`InputError` naming ``where``."""
    if fps is None:
        raise InputError("no frame rate: the file does not give one; pass fps (--fps)", where)
    try:
        fps = float(fps)
    except (TypeError, ValueError):
        raise InputError(f"frame rate must be a number, got {fps!r}", where) from None
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(f"frame rate must be positive, got {fps:g}", where)
    frames = np.asarray(frames)
    if frames.ndim != 3:
        raise InputError(f"expected frames (T, H, W), got an array of shape {frames.shape}", where)
    if frames.shape[0] < MIN_FRAMES:
        raise InputError(
            f"{frames.shape[0]} frame{'s' if frames.shape[0] != 1 else ''}: a pulse needs a video "
            f"(at least {MIN_FRAMES} frames)",
            where,
        )
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


def _pick_channel(frames: np.ndarray, channel: str, path) -> np.ndarray:
    """(T, H, W, C) -> (T, H, W): luma (Rec. 601) or one of red/green/blue."""
    if channel not in _CHANNELS:
        raise InputError(f"channel must be one of {', '.join(_CHANNELS)}, got {channel!r}")
    if frames.ndim == 3:
        return frames
    if frames.ndim != 4 or frames.shape[-1] not in (3, 4):
        raise InputError(f"expected grey or RGB frames, got an array of shape {frames.shape}", path)
    if channel == "gray":
        return frames[..., 0] * 0.299 + frames[..., 1] * 0.587 + frames[..., 2] * 0.114
    return frames[..., _CHANNELS.index(channel) - 1]


def _natural_key(path: Path):
    return [int(s) if s.isdigit() else s.lower() for s in re.split(r"(\d+)", path.name)]


def _read_tiff(path: Path):
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            fps = None
            ij = tif.imagej_metadata or {}
            if ij.get("finterval"):
                fps = 1.0 / float(ij["finterval"])
            elif ij.get("fps"):
                fps = float(ij["fps"])
            desc = tif.pages[0].description if tif.pages else ""
            if fps is None and desc.startswith("{"):
                try:
                    fps = json.loads(desc).get("fps")
                except ValueError:
                    pass
            shapes = {p.shape for p in tif.pages}
            if len(shapes) > 1:
                raise InputError(f"pages of mixed sizes {sorted(shapes)}", path)
            frames = tif.asarray(key=range(len(tif.pages))) if len(tif.pages) > 1 else tif.asarray()
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"cannot read as TIFF ({' '.join(str(exc).split())})", path) from None
    if frames.ndim == 2:
        frames = frames[None]
    elif frames.ndim == 3 and frames.shape[-1] in (3, 4) and len(shapes) == 1 and len(next(iter(shapes))) == 3:
        frames = frames[None]  # a single RGB page
    return frames, fps


def _read_folder(path: Path):
    files = sorted((p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES), key=_natural_key)
    if not files:
        raise InputError(f"no frames ({', '.join(IMAGE_SUFFIXES)}) in the folder", path)
    from PIL import Image

    frames, shape0 = [], None
    for f in files:
        try:
            if f.suffix.lower() in (".tif", ".tiff"):
                import tifffile

                a = tifffile.imread(f)
            else:
                with Image.open(f) as im:
                    a = np.asarray(im)
        except Exception as exc:
            raise InputError(f"cannot read frame ({' '.join(str(exc).split())})", f) from None
        if shape0 is None:
            shape0 = a.shape
        elif a.shape != shape0:
            raise InputError(f"frames of mixed sizes: {f.name} is {a.shape}, {files[0].name} is {shape0}", path)
        frames.append(a)
    return np.stack(frames), None


def _read_opencv(path: Path):
    import os

    # FFmpeg inside OpenCV would print its own complaints about a bad file; the error below says it in one line
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
    import cv2

    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise InputError("cannot decode the video (OpenCV/FFmpeg could not open it)", path)
        fps = cap.get(cv2.CAP_PROP_FPS)
        frames = []
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            frames.append(frame[..., ::-1] if frame.ndim == 3 else frame)  # BGR -> RGB
    finally:
        cap.release()
    if not frames:
        raise InputError("cannot decode the video (no frames)", path)
    fps = float(fps) if fps and np.isfinite(fps) and fps > 0 else None
    return np.stack(frames), fps


def read_video(path, *, fps: float | None = None, channel: str = "gray") -> Video:
    """Read a recording as a :class:`Video`.

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
        One line naming the file: missing, unreadable, no frame rate, too few frames,
        mixed sizes, NaN.
    """
    path = Path(path)
    if not path.exists():
        raise InputError("no such file or folder", path)
    if path.is_dir():
        raw, file_fps = _read_folder(path)
    elif path.suffix.lower() in (".tif", ".tiff"):
        raw, file_fps = _read_tiff(path)
    elif path.suffix.lower() in VIDEO_SUFFIXES:
        raw, file_fps = _read_opencv(path)
    else:
        raise InputError(
            f"unknown video format {path.suffix!r}: expected .tif/.tiff, {'/'.join(VIDEO_SUFFIXES)} or a folder of frames",
            path,
        )
    if fps is not None:
        fps = check_positive(fps, "--fps")
    frames = _pick_channel(_to_unit(np.asarray(raw)), channel, path)
    video = check_video(frames, fps if fps is not None else file_fps, path)
    video.meta = {"fps_from": "argument" if fps is not None else "file", "channel": channel}
    return video


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

    ``suffix`` picks the format (default: ``path``'s own).
    """
    from ..io.marks import mark_text

    path = Path(path)
    suffix = (suffix or path.suffix).lower()
    if suffix not in WRITE_SUFFIXES:
        raise InputError(f"video files end in {', '.join(WRITE_SUFFIXES)}, got {path.name!r}")
    frames = np.asarray(video.frames, np.float32)
    if suffix in (".tif", ".tiff"):
        import tifffile

        info = json.dumps({"planeray_video": {"fps": video.fps, **video.meta}})
        tifffile.imwrite(
            path,
            frames,
            imagej=True,
            software=mark_text(VIDEO_KIND),
            metadata={"axes": "TYX", "finterval": 1.0 / video.fps, "Info": info},
        )
    else:
        import imageio_ffmpeg

        top = float(np.percentile(frames, 99.9)) if white is None else float(white)
        scale = 255.0 / top if top > 0 else 1.0
        H, W = frames.shape[1:]
        gray = np.clip(frames * scale + 0.5, 0, 255).astype(np.uint8)
        gray = np.pad(gray, ((0, 0), (0, H % 2), (0, W % 2)), mode="edge")
        codec = VIDEO_SUFFIXES[suffix]
        extra = {"pix_fmt_out": "yuvj420p"} if codec == "mjpeg" else {}
        if codec == "ffv1":
            extra = {"pix_fmt_out": "gray"}
        writer = imageio_ffmpeg.write_frames(
            str(path),
            (gray.shape[2], gray.shape[1]),
            pix_fmt_in="gray",
            fps=video.fps,
            codec=codec,
            macro_block_size=1,
            quality=None if codec == "ffv1" else 10,
            ffmpeg_log_level="error",
            output_params=["-metadata", f"title={mark_text(VIDEO_KIND)}"],
            **extra,
        )
        try:
            writer.send(None)
            for f in gray:
                writer.send(np.ascontiguousarray(f))
        finally:
            writer.close()
    return path
