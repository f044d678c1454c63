"""``planeray video``: a delay or exposure sweep written as a video (the paper's "sweeping the band").

Frames are rendered by the same :class:`~planeray.viewer.session.ViewSource` as the page
and coloured by the same mapping (:mod:`planeray.viewer.display`), with one white level
for the whole sweep ("all images equally brightened"), upscaled by whole pixels and
captioned with the delay and exposure of each frame.  They are encoded by ffmpeg through
`imageio-ffmpeg <https://github.com/imageio/imageio-ffmpeg>`_, whose wheel carries the
ffmpeg binary (nothing to install besides the Python package).  The file is written
atomically (:func:`planeray.io.atomic_file`); its ``title`` metadata is planeray's mark
(:mod:`planeray.io.marks`: ``--overwrite`` replaces only a video planeray wrote) and its
``comment`` metadata holds the sweep and display settings as JSON, of bounded size: the
sweep's first and last value and its frame count, and the values themselves up to
:data:`MAX_LISTED_VALUES` frames.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from .._validate import check_integer, check_number, check_positive
from ..errors import InputError
from ..io import atomic_file
from .display import auto_white, check_display, to_rgb
from .session import StackSource, ViewSettings, ViewSource

__all__ = [
    "CODECS",
    "MAX_FRAMES",
    "FPS_RANGE",
    "MAX_LISTED_VALUES",
    "check_sweep_value",
    "sweep_values",
    "write_sweep_video",
]

#: Output suffix -> ffmpeg codec.
CODECS = {".mp4": "libx264", ".mkv": "libx264", ".webm": "libvpx-vp9"}

#: Default sweeps of a scene or transport: the paper's delays, and exposures from 1 to 2 paper maxima.
DEFAULT_RANGE_US = {"delay": (-1500.0, 1500.0), "exposure": (100.0, 2400.0)}
#: Most frames a sweep may have (an hour at 30 frames per second is 108,000).
MAX_FRAMES = 100_000
#: Frame rates a video may have, frames per second.
FPS_RANGE = (0.1, 240.0)
#: The sweep's values are listed in the ``comment`` metadata up to this many frames (a summary beyond).
MAX_LISTED_VALUES = 256
#: Kind of planeray's mark in the video's ``title``.
VIDEO_KIND = "video"


def _frame_us() -> float:
    from ..timing import PAPER_LINES_PER_SECOND, PAPER_PROJECTOR_ROWS

    return PAPER_PROJECTOR_ROWS / PAPER_LINES_PER_SECOND * 1e6


def check_sweep_value(value, sweep: str, name: str) -> float:
    """A delay within +-one projector sweep (13,333 us), or an exposure in (0, one sweep]."""
    f = _frame_us()
    if sweep == "delay":
        return check_number(value, name, minimum=-f, maximum=f, requirement=f"a delay in us within +-{f:.0f}")
    return check_number(
        value, name, minimum=0.0, maximum=f, min_inclusive=False, requirement=f"an exposure in us, > 0 and <= {f:.0f}"
    )


def sweep_values(source: ViewSource, sweep: str, *, start_us=None, stop_us=None, frames=None) -> np.ndarray:
    """The delays (or exposures) of a sweep: the captured grid of a stack, else ``frames`` evenly spaced values."""
    if sweep not in ("delay", "exposure"):
        raise InputError(f"--sweep must be delay or exposure, got {sweep!r}")
    for name, value in (("--from", start_us), ("--to", stop_us)):
        if value is not None:
            check_sweep_value(value, sweep, name)
    if isinstance(source, StackSource):
        grid = source.delays if sweep == "delay" else source.exposures
        lo = grid[0] if start_us is None else start_us
        hi = grid[-1] if stop_us is None else stop_us
        values = grid[(grid >= min(lo, hi) - 1e-9) & (grid <= max(lo, hi) + 1e-9)]
        if values.size == 0:
            raise InputError(f"no captured {sweep} between {lo:g} and {hi:g} us (captured: {grid.tolist()})")
        return values if lo <= hi else values[::-1]
    lo, hi = DEFAULT_RANGE_US[sweep]
    lo = lo if start_us is None else float(start_us)
    hi = hi if stop_us is None else float(stop_us)
    n = 121 if frames is None else check_integer(frames, "--frames", minimum=2, maximum=MAX_FRAMES)
    values = np.linspace(lo, hi, n)
    if sweep == "exposure" and np.any(values <= 0):
        raise InputError(f"exposures must be positive, the sweep goes from {lo:g} to {hi:g} us")
    return values


def _caption(rgb: np.ndarray, text: str) -> np.ndarray:
    from PIL import Image, ImageDraw, ImageFont

    h, w, _ = rgb.shape
    strip = max(20, h // 20)
    canvas = Image.new("RGB", (w, h + strip), (0, 0, 0))
    canvas.paste(Image.fromarray(rgb), (0, 0))
    draw = ImageDraw.Draw(canvas)
    try:
        font = ImageFont.load_default(size=max(10, int(strip * 0.6)))
    except TypeError:  # pragma: no cover - Pillow < 10.1
        font = ImageFont.load_default()
    draw.text((6, h + strip // 2), text, fill=(230, 230, 230), font=font, anchor="lm")
    return np.asarray(canvas)


def _even(rgb: np.ndarray) -> np.ndarray:
    """Pad to even width and height (yuv420p needs them)."""
    h, w, _ = rgb.shape
    return np.pad(rgb, ((0, h % 2), (0, w % 2), (0, 0)))


def write_sweep_video(
    source: ViewSource,
    out,
    *,
    sweep: str = "delay",
    settings: ViewSettings | None = None,
    start_us: float | None = None,
    stop_us: float | None = None,
    frames: int | None = None,
    fps: float | None = None,
    white: float | None = None,
    gamma: float = 1.0,
    colormap: str = "gray",
    scale: int | None = None,
    caption: bool = True,
    overwrite: bool = False,
    progress=None,
) -> Path:
    """Render a delay (or exposure) sweep of ``source`` and write it as a video.

    Parameters
    ----------
    source : ViewSource
        What :func:`~planeray.viewer.session.open_source` opened.
    out : path
        ``.mp4`` / ``.mkv`` (H.264) or ``.webm`` (VP9).
    sweep : {"delay", "exposure"}
        What changes from frame to frame; the other stays at ``settings``' value.
    settings : ViewSettings, optional
        The band image's other settings (exposure of a delay sweep, delay of an
        exposure sweep, noise, ambient); mode ``band``.
    start_us, stop_us : float, optional
        Sweep range (default: the paper's delays -1500..1500 us, exposures 100..2400 us;
        a stack's captured grid).
    frames : int, optional
        Frames of a scene or transport sweep (default 121); a stack has one per captured value.
    fps : float, optional
        Frames per second (default 30; 4 for a stack's few captured values).
    white : float, optional
        Value shown at full brightness (default: the 99.5th percentile over nine frames of the sweep).
    gamma, colormap
        Display mapping (:mod:`planeray.viewer.display`).
    scale : int, optional
        Whole-pixel upscaling (default: the least making the image at least 512 pixels tall).
    caption : bool
        A strip under each frame with its delay and exposure.
    overwrite : bool
        Replace an existing file.
    progress : callable, optional
        Called with 1 after each frame.

    Returns
    -------
    pathlib.Path
    """
    from .._extras import import_extra
    from ..io.atomic import check_replaceable
    from ..io.marks import mark_text

    imageio_ffmpeg = import_extra("imageio_ffmpeg", "writing a video")

    out = Path(out)
    codec = CODECS.get(out.suffix.lower())
    if codec is None:
        raise InputError(f"--out must end in {', '.join(CODECS)}, got {out.name!r}")
    check_replaceable(out, overwrite=overwrite, kind=VIDEO_KIND)
    settings = settings or ViewSettings()
    if settings.mode != "band":
        raise InputError(f"a sweep shows band images (mode band), not {settings.mode!r}")
    check_sweep_value(settings.delay_us, "delay", "--delay-us")
    check_sweep_value(settings.exposure_us, "exposure", "--exposure-us")
    source.check(settings)
    if white is not None:
        check_positive(white, "--white")
    check_display(white=1.0 if white is None else white, gamma=gamma, colormap=colormap)
    values = sweep_values(source, sweep, start_us=start_us, stop_us=stop_us, frames=frames)
    if fps is None:
        fps = 4.0 if isinstance(source, StackSource) else 30.0
    fps = check_number(fps, "--fps", minimum=FPS_RANGE[0], maximum=FPS_RANGE[1])
    key = "delay_us" if sweep == "delay" else "exposure_us"
    frame_settings = [replace(settings, **{key: float(v)}) for v in values]

    def render(s):
        image, info = source.render(s)
        return image, info

    if white is None:
        picks = np.unique(np.linspace(0, len(frame_settings) - 1, min(9, len(frame_settings))).round().astype(int))
        white = max(auto_white(render(frame_settings[i])[0]) for i in picks)
    H, W = source.shape
    if scale is None:
        scale = max(1, int(np.ceil(512 / H)))
    scale = check_integer(scale, "--scale", minimum=1, maximum=64)
    meta = {
        "planeray": "video",
        "source": {"kind": source.kind, "name": source.name},
        "sweep": sweep,
        "frames": int(len(values)),
        "from_us": float(values[0]),
        "to_us": float(values[-1]),
        **({"values_us": [float(v) for v in values]} if len(values) <= MAX_LISTED_VALUES else {}),
        "settings": settings.to_dict(),
        "display": {"white": float(white), "gamma": float(gamma), "colormap": colormap},
        "fps": float(fps),
    }
    first = None
    with atomic_file(out, overwrite=overwrite) as tmp:
        writer = None
        try:
            for s in frame_settings:
                image, info = render(s)
                rgb = to_rgb(image, white=white, gamma=gamma, colormap=colormap)
                if scale > 1:
                    rgb = np.repeat(np.repeat(rgb, scale, axis=0), scale, axis=1)
                if caption:
                    if isinstance(source, StackSource):
                        text = info["label"]
                    else:
                        text = f"t_d {s.delay_us:+.1f} us   t_e {s.exposure_us:.1f} us"
                    rgb = _caption(rgb, text)
                rgb = np.ascontiguousarray(_even(rgb))
                if writer is None:
                    first = rgb.shape
                    writer = imageio_ffmpeg.write_frames(
                        str(tmp),
                        (rgb.shape[1], rgb.shape[0]),
                        fps=fps,
                        codec=codec,
                        quality=8,
                        macro_block_size=2,
                        ffmpeg_log_level="error",
                        output_params=[
                            "-metadata",
                            f"title={mark_text(VIDEO_KIND)}",
                            "-metadata",
                            f"comment={json.dumps(meta, separators=(',', ':'))}",
                        ],
                    )
                    writer.send(None)
                writer.send(rgb.tobytes())
                if progress is not None:
                    progress(1)
        finally:
            if writer is not None:
                writer.close()
    if first is None:  # pragma: no cover - sweep_values never returns nothing
        raise InputError("the sweep has no frames")
    return out
