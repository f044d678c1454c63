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

__all__ = ["check_number", "check_positive", "check_nonnegative", "check_integer", "check_finite_array"]


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
