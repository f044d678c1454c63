"""Bounds of the options of ``planeray skin ...``, ``view`` and ``video``, checked before any work.

Every check names the option as the user typed it and says what it may be (one line, exit 1);
the bounds are physical (the projector has 720 rows and sweeps them 75 times a second, a heart
beats 30-240 times a minute) or what the machine can hold (estimated memory against what is
available, :func:`planeray._validate.check_memory`).  The help text of each option states them.
"""

from __future__ import annotations

from .._validate import check_integer, check_memory
from ..timing import PAPER_LINES_PER_SECOND, PAPER_PROJECTOR_ROWS

#: The largest seed numpy's generators take.
MAX_SEED = 2**32 - 1
#: One sweep of the paper's projector (720 rows at 54,000 lines/s), us: the longest row exposure,
#: and the camera's shortest frame (one delay image per sweep).
PROJECTOR_FRAME_US = PAPER_PROJECTOR_ROWS / PAPER_LINES_PER_SECOND * 1e6
#: Frames per second of the paper's projector (75 Hz): the fastest a camera gets one delay image per frame.
PROJECTOR_FPS = PAPER_LINES_PER_SECOND / PAPER_PROJECTOR_ROWS
#: Memory a scene needs per camera pixel (its dense transport of <= 257 offsets, maps and
#: temporaries; measured 3-5 KiB at 128-512 px), with a margin, and the interpreter's own.
SCENE_BYTES_PER_PIXEL = 8 * 1024
BASE_BYTES = 400 * 2**20


def seed(value: int, option: str = "--seed") -> int:
    """A seed: an integer 0 .. 2**32 - 1."""
    return check_integer(value, option, minimum=0, maximum=MAX_SEED)


def image_size(shape, option: str = "--size", *, minimum: int = 8) -> tuple[int, int]:
    """``H W`` of a simulated image: integers >= ``minimum`` (the upper bound is memory: :func:`scene_memory`)."""
    h, w = (int(v) for v in shape)
    if h < minimum or w < minimum:
        raise ValueError(f"{option} must be at least {minimum}x{minimum} pixels, got {h}x{w}")
    return h, w


def projector_rows(value: int, option: str = "--projector-rows") -> int:
    """Projector rows an image spans: 1 .. 720 (the projector has 720 rows)."""
    return check_integer(value, option, minimum=1, maximum=PAPER_PROJECTOR_ROWS)


def scene_memory(
    shape, option: str = "--size", *, copies: float = 1.0, extra_bytes: float = 0.0, square: bool = False
) -> None:
    """Refuse an image size whose scene(s) cannot fit in memory (``copies`` scenes held at once).

    ``square``: the option is one number (``--size 128``), not ``H W``.
    """
    h, w = shape
    need = BASE_BYTES + copies * h * w * SCENE_BYTES_PER_PIXEL + extra_bytes
    typed = f"{option} {h}" if square else f"{option} {h} {w}"
    check_memory(need, f"{typed} ({h}x{w} pixels)", advice=f"choose a smaller {option}")


def frequency_band(text: str, option: str) -> tuple[float, float]:
    """``"LOW,HIGH"`` (or ``"LOW HIGH"``, ``"LOW-HIGH"``; Hz) -> ``(low, high)``, finite, ``0 <= low < high``."""
    import math
    import re

    parts = [p for p in re.split(r"[,\s]+", str(text).strip()) if p]
    if len(parts) == 1 and re.fullmatch(r"[0-9.]+-[0-9.]+", parts[0]):
        parts = parts[0].split("-")
    try:
        lo, hi = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"{option} expects LOW,HIGH in Hz (e.g. 0.5,2), got {text!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
        raise ValueError(f"{option} must be LOW,HIGH with 0 <= LOW < HIGH (Hz), got {text!r}")
    return lo, hi
