"""Checks of command-line values where they are parsed: one line naming the option as typed.

Every command checks its numbers, sizes and outputs before any work; these helpers
raise :class:`~planeray.errors.InputError` with the option's own spelling
(``--lines-per-second must be a positive number, got 0.0``), so no message names a
library parameter or nothing at all (``scale < 0``, ``expected non-negative integer``).

The ranges are those the physics and the machine allow: a camera side of at most
:data:`MAX_SIDE` pixels, at most :data:`MAX_PROJECTOR_ROWS` projector rows, a
scanline velocity between :data:`MIN_LINES_PER_SECOND` and
:data:`MAX_LINES_PER_SECOND`, seeds of NumPy's range, and an estimate of the memory a
command needs against what the machine has (:func:`check_memory`).
"""

from __future__ import annotations

from pathlib import Path

from .._validate import check_integer, check_number
from ..errors import InputError

#: Largest camera side (pixels): the dense transport of a 2048 x 2048 scene alone is 4.3 GB.
MAX_SIDE = 2048
#: Largest projector (rows): a 4K projector has 2160; the simulated scenes slow down beyond 4096.
MAX_PROJECTOR_ROWS = 4096
#: Scanline velocities of raster projectors (lines/s): the paper's PicoPro scans 54,000 (60 Hz x 900 rows).
MIN_LINES_PER_SECOND, MAX_LINES_PER_SECOND = 10_000.0, 10_000_000.0
#: Largest timing value (us): 1 s, sixty projector frames.
MAX_TIME_US = 1_000_000.0
#: Seeds: NumPy takes non-negative integers; one below 2**32 is plenty.
MAX_SEED = 2**32 - 1


def number(value, option: str, *, minimum=None, maximum=None, min_inclusive=True, max_inclusive=True) -> float:
    """A finite number in the range (``--gamma must be a finite number > 0 and <= 10, got nan``)."""
    return check_number(
        value, option, minimum=minimum, maximum=maximum, min_inclusive=min_inclusive, max_inclusive=max_inclusive
    )


def positive(value, option: str, *, maximum=None) -> float:
    """A finite number > 0 (and <= ``maximum``)."""
    return number(value, option, minimum=0.0, min_inclusive=False, maximum=maximum)


def nonnegative(value, option: str, *, maximum=None) -> float:
    """A finite number >= 0 (and <= ``maximum``)."""
    return number(value, option, minimum=0.0, maximum=maximum)


def integer(value, option: str, *, minimum=None, maximum=None) -> int:
    """An integer in ``[minimum, maximum]``."""
    return check_integer(value, option, minimum=minimum, maximum=maximum)


def optional(check, value, option: str, **kwargs):
    """``check(value, option, ...)`` unless ``value`` is None (an option not given)."""
    return None if value is None else check(value, option, **kwargs)


def seed(value, option: str = "--seed") -> int:
    """A seed NumPy takes: an integer in ``[0, 2**32 - 1]``."""
    return integer(value, option, minimum=0, maximum=MAX_SEED)


def size(value, option: str = "--size", *, minimum: int = 8, maximum: int = MAX_SIDE) -> tuple[int, int]:
    """An image size ``H W`` of two integers, each in ``[minimum, maximum]``."""
    try:
        h, w = value
    except (TypeError, ValueError):
        raise InputError(f"{option} must be two integers H W, got {value!r}") from None
    for side in (h, w):
        ok = isinstance(side, int) and not isinstance(side, bool) and minimum <= side <= maximum
        if not ok:
            raise InputError(f"{option} must be two integers H W, each >= {minimum} and <= {maximum}, got {value!r}")
    return int(h), int(w)


def projector_rows(value, option: str = "--projector-rows") -> int | None:
    """Projector rows in ``[1, MAX_PROJECTOR_ROWS]`` (None: not given)."""
    return optional(integer, value, option, minimum=1, maximum=MAX_PROJECTOR_ROWS)


def lines_per_second(value, option: str = "--lines-per-second") -> float | None:
    """A raster projector's scanline velocity, lines/s (None: not given)."""
    return optional(number, value, option, minimum=MIN_LINES_PER_SECOND, maximum=MAX_LINES_PER_SECOND)


def sweep(name: str, option: str = "--sweep"):
    """A named sweep (:func:`planeray.timing.make_sweep`) or a sweep file (``.json``,
    :func:`planeray.io.read_sweep`); anything else is refused in one line naming ``option``."""
    from ..timing import SWEEPS, make_sweep

    if name in SWEEPS:
        return make_sweep(name)
    text = str(name)
    if text.lower().endswith(".json") or Path(text).exists():
        from ..io import read_sweep

        try:
            return read_sweep(text)
        except InputError as exc:
            raise InputError(f"{option} {exc}") from None
    raise InputError(
        f"{option} {name}: unknown sweep; choose one of {', '.join(sorted(SWEEPS))} or give a sweep file (.json, "
        "`planeray sweep design`)"
    )


def scene(name: str, option: str = "--scene") -> str:
    """A built-in scene name (or ``NAME:ARGUMENT`` of a parametric one); an unknown name is refused naming ``option``."""
    from ..scenes import list_scenes

    known = list_scenes(parametric=True)
    if not isinstance(name, str) or (
        name not in known and name.split(":", 1)[0] + ":" not in {k.split(":", 1)[0] + ":" for k in known if ":" in k}
    ):
        raise InputError(f"{option} {name}: unknown scene; choose one of {', '.join(sorted(known))}")
    return name


def folder(path, option: str = "--out") -> None:
    """An output folder: it may exist (and hold other files) but must be a folder, not a file."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{option} {p}: is a file; name a folder (it may exist and hold other files)")
    for parent in p.parents:
        if parent.exists():
            if not parent.is_dir():
                raise InputError(f"{option} {p}: {parent} is a file, not a folder")
            break


def available_memory() -> int | None:
    """Bytes of memory available now (:func:`planeray._validate.available_memory_bytes`; None: unknown)."""
    from .._validate import available_memory_bytes

    return available_memory_bytes()


def check_memory(nbytes: float, what: str) -> None:
    """Refuse, in one line, work whose arrays would not fit in the memory available now.

    ``what`` names the options that set the size (``"--size 2048 2048"``); the check is
    :func:`planeray._validate.check_memory`'s.
    """
    from .._validate import check_memory as check

    check(nbytes, what, advice="choose smaller values", available=available_memory())
