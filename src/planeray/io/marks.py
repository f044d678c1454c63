"""Single files planeray writes carry a mark, so ``--overwrite`` replaces only what planeray wrote.

Folders and stores are recognized by their format attributes
(:func:`planeray.io.atomic.planeray_output_kind`); a single file -- an image, a
figure, a video, a calibration file, a JSON record -- carries its mark in its own
metadata, readable by any tool:

==========================  ================================================================
file                        where the mark is
==========================  ================================================================
``.png``                    text chunk ``Software`` (PNG ``tEXt``)
``.tif`` / ``.tiff``        tag ``Software`` (305) of the first page
``.mp4`` ``.avi`` ``.mkv``  container metadata ``title`` (``ffmpeg -i`` shows it)
``.json``                   key ``"planeray_mark"`` of the top-level object
``.npz``                    member ``planeray_mark`` (a 0-d string array)
``.csv``                    first line ``# planeray_mark: ...``
==========================  ================================================================

The mark reads ``planeray:KIND:VERSION`` (``planeray:figure:0.1.0``); :func:`file_mark`
returns ``KIND``.  A file without a mark -- or of another type -- was not written by
planeray and is never replaced (:func:`planeray.io.atomic.check_replaceable`).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

__all__ = ["MARK_KEY", "mark_text", "file_mark", "png_mark_info", "VIDEO_SUFFIXES"]

#: Key of the mark in JSON records and npz archives.
MARK_KEY = "planeray_mark"
#: Video containers written through ffmpeg.
VIDEO_SUFFIXES = (".mp4", ".avi", ".mkv", ".mov")
_MARK = re.compile(r"^planeray:([a-z0-9][a-z0-9 _-]*):")


def mark_text(kind: str) -> str:
    """The mark of a file of ``kind`` (``"image"``, ``"figure"``, ``"video"``...): ``planeray:KIND:VERSION``."""
    from ._common import planeray_version

    if not _MARK.match(f"planeray:{kind}:"):
        raise ValueError(f"a file kind is lower-case words, got {kind!r}")
    return f"planeray:{kind}:{planeray_version()}"


def _kind(text) -> str | None:
    m = _MARK.match(str(text or ""))
    return m.group(1) if m else None


def png_mark_info(kind: str):
    """A Pillow ``PngInfo`` carrying the mark (``Image.save(..., pnginfo=...)``)."""
    from PIL.PngImagePlugin import PngInfo

    info = PngInfo()
    info.add_text("Software", mark_text(kind))
    return info


def _video_title(path: Path) -> str | None:
    import subprocess

    try:
        import imageio_ffmpeg
    except ImportError:  # the `video` extra is not installed: no video can be read, so none is planeray's
        return None
    try:
        run = subprocess.run(
            [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)],
            capture_output=True,
            text=True,
            timeout=30,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    for line in run.stderr.splitlines():
        key, sep, value = line.strip().partition(":")
        if sep and key.strip() == "title":
            return value.strip()
    return None


def file_mark(path) -> str | None:
    """The kind of planeray file at ``path`` (from its mark), or None when planeray did not write it.

    Never raises: an unreadable or foreign file is simply not planeray's.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "notes.json"
    >>> _ = p.write_text('{"planeray_mark": "planeray:record:0.1.0"}')
    >>> file_mark(p)
    'record'
    >>> _ = p.write_text('{"mine": 1}')
    >>> file_mark(p) is None
    True
    """
    p = Path(path)
    if p.is_symlink() or not p.is_file():
        return None
    suffix = p.suffix.lower()
    try:
        if suffix == ".png":
            from PIL import Image

            with Image.open(p) as im:
                return _kind(im.info.get("Software"))
        if suffix in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(p) as tif:
                tag = tif.pages[0].tags.get(305) if len(tif.pages) else None
                return _kind(tag.value if tag is not None else None)
        if suffix == ".json":
            data = json.loads(p.read_text(encoding="utf-8"))
            return _kind(data.get(MARK_KEY)) if isinstance(data, dict) else None
        if suffix == ".npz":
            import numpy as np

            with np.load(p, allow_pickle=False) as z:
                return _kind(str(z[MARK_KEY])) if MARK_KEY in z.files else None
        if suffix == ".csv":
            with p.open(encoding="utf-8") as f:
                first = f.readline()
            return _kind(first[len(f"# {MARK_KEY}: ") :].strip()) if first.startswith(f"# {MARK_KEY}: ") else None
        if suffix in VIDEO_SUFFIXES:
            return _kind(_video_title(p))
    except Exception:  # any unreadable file is not one of ours
        return None
    return None
