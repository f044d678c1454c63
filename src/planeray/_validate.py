"""Shared input checks: one place that says what a valid number, count or array is.

Every check raises :class:`~planeray.errors.InputError` (a ``ValueError``) whose message
names the parameter and the value, ``"{name} must be {requirement}, got {value!r}"``,
so the command line can print it as one line.  NaN and infinities are never valid
unless a check says so.

Examples
--------
>>> check_positive(600.0, "exposure_us")
600.0
>>> check_positive(float("nan"), "exposure_us")
Traceback (most recent call last):
...
planeray.errors.InputError: exposure_us must be a positive number, got nan
>>> check_integer(3.0, "frames", minimum=1)
3
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from .errors import InputError

__all__ = [
    "check_number",
    "check_positive",
    "check_nonnegative",
    "check_integer",
    "check_finite_array",
    "available_memory_bytes",
    "check_memory",
]


def _is_real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def check_number(
    value,
    name: str,
    *,
    minimum=None,
    maximum=None,
    min_inclusive=True,
    max_inclusive=True,
    requirement: str | None = None,
    error=InputError,
) -> float:
    """A finite real number inside ``[minimum, maximum]`` (bounds optional, inclusive by default).

    Parameters
    ----------
    value : object
        The value to check; numpy scalars are accepted, booleans are not.
    name : str
        Parameter name for the message (with its unit, e.g. ``"delay_us"``).
    minimum, maximum : float, optional
        Bounds; ``min_inclusive``/``max_inclusive`` make them strict when False.
    requirement : str, optional
        Words for the message instead of the ones built from the bounds.
    error : type
        Exception class to raise (an :class:`~planeray.errors.InputError`).

    Returns
    -------
    float
    """
    ok = _is_real(value) and math.isfinite(float(value))
    if ok and minimum is not None:
        ok = float(value) >= minimum if min_inclusive else float(value) > minimum
    if ok and maximum is not None:
        ok = float(value) <= maximum if max_inclusive else float(value) < maximum
    if not ok:
        if requirement is None:
            parts = []
            if minimum is not None:
                parts.append(f"{'>=' if min_inclusive else '>'} {minimum:g}")
            if maximum is not None:
                parts.append(f"{'<=' if max_inclusive else '<'} {maximum:g}")
            requirement = "a finite number" + (" " + " and ".join(parts) if parts else "")
        raise error(f"{name} must be {requirement}, got {value!r}")
    return float(value)


def check_positive(value, name: str, *, error=InputError) -> float:
    """A finite number > 0."""
    return check_number(value, name, minimum=0.0, min_inclusive=False, requirement="a positive number", error=error)


def check_nonnegative(value, name: str, *, error=InputError) -> float:
    """A finite number >= 0."""
    return check_number(value, name, minimum=0.0, requirement="a finite number >= 0", error=error)


def check_integer(value, name: str, *, minimum=None, maximum=None, error=InputError) -> int:
    """An integer (or an integral float such as ``3.0``) inside ``[minimum, maximum]``."""
    ok = _is_real(value) and math.isfinite(float(value)) and float(value).is_integer()
    if ok and minimum is not None:
        ok = value >= minimum
    if ok and maximum is not None:
        ok = value <= maximum
    if not ok:
        bounds = [f">= {minimum}" if minimum is not None else "", f"<= {maximum}" if maximum is not None else ""]
        bounds = " and ".join(b for b in bounds if b)
        raise error(f"{name} must be an integer{' ' + bounds if bounds else ''}, got {value!r}")
    return int(value)


def check_finite_array(values, name: str, *, ndim: int | None = None, error=InputError) -> np.ndarray:
    """A real array without NaN or infinities (of ``ndim`` dimensions when given)."""
    a = np.asarray(values)
    if a.dtype.kind not in "biuf":
        raise error(f"{name} must be a real-valued array, got dtype {a.dtype}")
    if ndim is not None and a.ndim != ndim:
        raise error(f"{name} must be {ndim}-D, got shape {a.shape}")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise error(f"{name} contains NaN or infinite values")
    return a


def available_memory_bytes() -> int | None:
    """Memory the system can give a process without swapping, in bytes (None where unknown).

    Linux: ``MemAvailable`` of ``/proc/meminfo``; elsewhere the physical pages ``sysconf`` reports
    as available.
    """
    import os

    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def bytes_text(n: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1024.0
    return f"{n:.3g} EiB"  # pragma: no cover


def check_memory(nbytes: float, what: str, *, advice: str = "", available: int | None = None, error=InputError):
    """Refuse, before allocating, work whose estimated peak memory ``nbytes`` exceeds what is available.

    Parameters
    ----------
    nbytes : float
        Estimated peak memory of the work, bytes.
    what : str
        The work, named by the options that size it (``"--seconds 1e+06 at --fps 75"``): the
        message starts with it.
    advice : str
        What to change (``"shorten --seconds"``), appended after a semicolon.
    available : int, optional
        Bytes available (default :func:`available_memory_bytes`; unknown: nothing is refused).

    Examples
    --------
    >>> check_memory(1e6, "--seconds 30", available=2**30)
    >>> check_memory(2**41, "--seconds 1e+06", advice="shorten --seconds", available=2**34)
    Traceback (most recent call last):
    ...
    planeray.errors.InputError: --seconds 1e+06 needs about 2 TiB of memory, more than the 16 GiB available; shorten --seconds
    """
    avail = available_memory_bytes() if available is None else available
    if avail is None or not nbytes > avail:
        return
    text = f"{what} needs about {bytes_text(float(nbytes))} of memory, more than the {bytes_text(avail)} available"
    raise error(text + (f"; {advice}" if advice else ""))
