"""The sweep file: a delay-exposure sweep as a small JSON file (a public format).

A sweep file names the images of a sweep -- one ``(delay_us, exposure_us)`` each, and which of
them are left out of demultiplexing -- so that a sweep chosen once (``planeray sweep design``,
or written by hand) is used wherever a named sweep is (``--sweep paper`` or ``--sweep
design.json``: ``simulate``, ``acquire``, ``demux``, ``view --device``)::

    {
      "format": "planeray-sweep",
      "format_version": 1,
      "name": "design-24",
      "delay_us":    [-612.0, -371.5, ...],
      "exposure_us": [150.0, 224.0, ...],
      "excluded":    [false, false, ...],
      "record": {"kind": "design", "criterion": {...}, "prior": {...}, "camera": {...}, ...},
      "planeray_mark": "planeray:sweep:0.1.0"
    }

Required: ``delay_us`` and ``exposure_us`` (equal-length lists of finite numbers, exposures > 0,
no setting twice).  Optional: ``format``/``format_version`` (if present they must be these),
``name`` (default: the file's stem), ``excluded`` (booleans; default: the paper's boundary rule
``||t_d| - t_e/2| <= 75 us``), ``record`` (free-form JSON object, kept verbatim: a designed sweep
records its prior, camera, criterion and seed there, see :mod:`planeray.design`), and
``planeray_mark`` (only in files planeray wrote; ``--overwrite`` replaces only those).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..timing import Sweep, boundary_images

__all__ = ["SWEEP_FORMAT", "read_sweep", "write_sweep", "sweep_to_json"]

#: The ``format`` of a sweep file, and its version.
SWEEP_FORMAT = "planeray-sweep"
SWEEP_FORMAT_VERSION = 1
#: Most images a sweep file may list (a sweep of 10,000 images would take hours to capture).
MAX_IMAGES = 10_000


def _numbers(doc, key, path) -> np.ndarray:
    values = doc.get(key)
    if not isinstance(values, list) or not values:
        raise InputError(f"{key!r} must be a non-empty list of numbers", path)
    for i, v in enumerate(values):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f"{key}[{i}] must be a finite number, got {v!r}", path)
    return np.asarray(values, dtype=np.float64)


def read_sweep(path) -> Sweep:
    """Read a sweep file (the module's format) as a :class:`~planeray.timing.Sweep`.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    Sweep
        Its ``name`` is the file's ``name`` (else its stem) and ``record`` the file's ``record``.

    Raises
    ------
    InputError
        One line naming the file and the problem (not JSON, a missing or malformed field, a
        setting listed twice, another format).

    See Also
    --------
    write_sweep : write one.
    planeray.make_sweep : a named sweep.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pr.io.write_sweep(pr.quick_sweep(), pathlib.Path(tmp) / "quick.json")
    ...     len(read_sweep(path))
    27
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("no such sweep file", path) from None
    except IsADirectoryError:
        raise InputError("is a folder, not a sweep file (.json)", path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the sweep file ({type(exc).__name__}: {exc})", path) from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"not JSON ({exc.msg} at line {exc.lineno})", path) from None
    if not isinstance(doc, dict):
        raise InputError("a sweep file is a JSON object with delay_us and exposure_us lists", path)
    fmt = doc.get("format", SWEEP_FORMAT)
    if fmt != SWEEP_FORMAT:
        raise InputError(f"format is {fmt!r}, not a sweep file ({SWEEP_FORMAT!r})", path)
    version = doc.get("format_version", SWEEP_FORMAT_VERSION)
    if version != SWEEP_FORMAT_VERSION:
        raise InputError(f"format_version {version!r} is not one this planeray reads ({SWEEP_FORMAT_VERSION})", path)
    delay = _numbers(doc, "delay_us", path)
    exposure = _numbers(doc, "exposure_us", path)
    if delay.size != exposure.size:
        raise InputError(f"{delay.size} delays but {exposure.size} exposures", path)
    if delay.size > MAX_IMAGES:
        raise InputError(f"{delay.size} images; a sweep file holds at most {MAX_IMAGES}", path)
    bad = np.flatnonzero(exposure <= 0)
    if bad.size:
        raise InputError(f"exposure_us[{bad[0]}] = {exposure[bad[0]]:g}: exposures must be positive", path)
    seen: dict[tuple[float, float], int] = {}
    for i, key in enumerate(zip(delay.tolist(), exposure.tolist())):
        if key in seen:
            raise InputError(
                f"images {seen[key]} and {i} are the same setting (delay {key[0]:g} us, exposure {key[1]:g} us)", path
            )
        seen[key] = i
    if "excluded" in doc:
        excluded = doc["excluded"]
        if (
            not isinstance(excluded, list)
            or len(excluded) != delay.size
            or not all(isinstance(x, bool) for x in excluded)
        ):
            raise InputError(f"'excluded' must be a list of {delay.size} booleans (true/false)", path)
        excluded = np.asarray(excluded, bool)
    else:
        excluded = boundary_images(delay, exposure)
    name = doc.get("name", path.stem)
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"'name' must be a non-empty string, got {name!r}", path)
    record = doc.get("record")
    if record is not None and not isinstance(record, dict):
        raise InputError("'record' must be a JSON object", path)
    return Sweep(delay, exposure, excluded, name=name, record=record)


def sweep_to_json(sweep: Sweep) -> dict:
    """The JSON object of a sweep file (without the mark)."""
    doc = {
        "format": SWEEP_FORMAT,
        "format_version": SWEEP_FORMAT_VERSION,
        "name": sweep.name,
        "delay_us": [float(d) for d in sweep.delay_us],
        "exposure_us": [float(e) for e in sweep.exposure_us],
        "excluded": [bool(x) for x in sweep.excluded],
    }
    if sweep.record is not None:
        doc["record"] = sweep.record
    return doc


def write_sweep(sweep: Sweep, path, *, overwrite: bool = False) -> Path:
    """Write ``sweep`` as a sweep file, atomically, marked as planeray's.

    Parameters
    ----------
    sweep : Sweep
    path : str or os.PathLike
        A ``.json`` file.
    overwrite : bool
        Replace an existing sweep file planeray wrote (never another file).

    Returns
    -------
    pathlib.Path

    See Also
    --------
    read_sweep : read it back.
    planeray.design.design_sweep : a designed sweep to write.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from planeray.timing import quick_sweep
    >>> p = write_sweep(quick_sweep(), pathlib.Path(tempfile.mkdtemp()) / "quick.json")
    >>> back = read_sweep(p)
    >>> len(back), back.name, int(back.excluded.sum())
    (27, 'quick', 4)
    """
    from .atomic import atomic_file, check_replaceable
    from .marks import MARK_KEY, mark_text

    path = Path(path)
    if path.suffix.lower() != ".json":
        raise InputError("a sweep file ends in .json", path)
    check_replaceable(path, overwrite=overwrite, kind="sweep")
    doc = sweep_to_json(sweep)
    doc[MARK_KEY] = mark_text("sweep")
    with atomic_file(path, overwrite=overwrite) as tmp:
        Path(tmp).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    return path
