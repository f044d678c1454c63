"""Calibration files: line-sweep captures (``.npz``) and the calibration fields of ``acquisition.json``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import atomic_file, jsonable
from ..linesweep import PAPER_CALIBRATION_EXPOSURE_US, LineSweep
from .delay_zero import DelayZeroCalibration
from .lines import LineCalibration

#: The mark kind of line-sweep files (:mod:`planeray.io.marks`).
LINE_SWEEP_KIND = "line sweep"


def write_line_sweep(sweep: LineSweep, path, *, overwrite: bool = False) -> Path:
    """Write a :class:`LineSweep` to one ``.npz`` file, atomically.

    The file carries planeray's mark (member ``planeray_mark``,
    :mod:`planeray.io.marks`); an existing file is replaced only with ``overwrite``
    and only if it is a line sweep planeray wrote
    (:func:`planeray.io.atomic.check_replaceable`).

    Parameters
    ----------
    sweep : LineSweep
        The images and their record.
    path : str or path
        The ``.npz`` file.
    overwrite : bool
        Replace a file planeray wrote.

    Returns
    -------
    pathlib.Path

    See Also
    --------
    read_line_sweep : reads it back.

    Examples
    --------
    >>> import planeray as pr
    >>> target = pr.make_scene("diffuse_plane", (288, 32), projector_rows=96, seed=0)
    >>> sweep = pr.SimulatedEpiscan(target, seed=5).capture_line_sweep(500.0)
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = write_line_sweep(sweep, pathlib.Path(tmp) / "lines.npz")
    ...     read_line_sweep(path).images.shape
    (2, 288, 32)
    """
    from ..io.atomic import check_replaceable
    from ..io.marks import MARK_KEY, mark_text

    path = Path(path)
    if path.suffix.lower() != ".npz":
        raise InputError("a line sweep is written as .npz", path)
    check_replaceable(path, overwrite=overwrite, kind=LINE_SWEEP_KIND)
    meta = {
        "format": "planeray-line-sweep",
        "format_version": 1,
        "exposure_us": sweep.exposure_us,
        "line_step_rows": sweep.line_step_rows,
        "phases": None if sweep.phases is None else list(sweep.phases),
        "flat_exposure_us": sweep.flat_exposure_us,
        "timing_jitter_us": sweep.timing_jitter_us,
        "metadata": jsonable(sweep.metadata, finite=False, where="metadata", error=InputError),
    }
    arrays = {
        "images": np.asarray(sweep.images, np.float32),
        "meta": np.array(json.dumps(meta)),
        MARK_KEY: np.array(mark_text(LINE_SWEEP_KIND)),
    }
    for name in ("dark", "flat"):
        if getattr(sweep, name) is not None:
            arrays[name] = np.asarray(getattr(sweep, name), np.float32)
    if sweep.saturated is not None:
        arrays["saturated"] = np.asarray(sweep.saturated, bool)
    with atomic_file(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
    return path


def read_line_sweep(path, *, exposure_us: float | None = None, rows_per_line: int | None = None) -> LineSweep:
    """Read line-sweep images: a ``.npz`` from :func:`write_line_sweep`, or image files.

    Parameters
    ----------
    path : str or os.PathLike
        ``.npz`` (everything included), or one grayscale ``.tif``/``.tiff``/``.png``
        (a multi-page TIFF holds one comb phase per page).
    exposure_us, rows_per_line : optional
        Override (or, for image files, give) the exposure and comb step;
        image files default to the paper's 500 us and ``k = 1``.

    Returns
    -------
    LineSweep

    See Also
    --------
    write_line_sweep : writes one.

    Examples
    --------
    >>> import planeray as pr
    >>> target = pr.make_scene("diffuse_plane", (288, 32), projector_rows=96, seed=0)
    >>> sweep = pr.SimulatedEpiscan(target, seed=5).capture_line_sweep(500.0)
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = read_line_sweep(write_line_sweep(sweep, pathlib.Path(tmp) / "lines.npz"))
    >>> back.exposure_us, back.line_step_rows
    (500.0, 2)
    """
    path = Path(path)
    if not path.exists():
        raise InputError("file not found", path)
    suffix = path.suffix.lower()
    try:
        if suffix == ".npz":
            with np.load(path, allow_pickle=False) as z:
                if "images" not in z or "meta" not in z:
                    raise InputError("not a planeray line sweep (arrays 'images' and 'meta' required)", path)
                meta = json.loads(str(z["meta"]))
                arr = {name: z[name] for name in ("images", "dark", "flat", "saturated") if name in z}
            return LineSweep(
                arr["images"],
                meta["exposure_us"] if exposure_us is None else exposure_us,
                meta["line_step_rows"] if rows_per_line is None else rows_per_line,
                None if meta.get("phases") is None else tuple(meta["phases"]),
                arr.get("dark"),
                arr.get("flat"),
                meta.get("flat_exposure_us"),
                arr.get("saturated"),
                float(meta.get("timing_jitter_us", 0.0)),
                meta.get("metadata", {}),
            )
        if suffix in (".tif", ".tiff"):
            import tifffile

            images = np.asarray(tifffile.imread(path), dtype=np.float64)
        elif suffix == ".png":
            from PIL import Image

            with Image.open(path) as im:
                images = np.asarray(im.convert("I") if im.mode not in ("L", "I", "I;16", "F") else im, dtype=np.float64)
        else:
            raise InputError(f"unsupported line-sweep file {suffix!r} (use .npz, .tif, .tiff or .png)", path)
    except InputError as exc:
        if exc.path is None:
            raise InputError(exc.problem, path) from None
        raise
    except Exception as exc:  # corrupt files raise many types
        raise InputError(f"cannot read line sweep ({type(exc).__name__}: {exc})", path) from exc
    if images.ndim not in (2, 3):
        raise InputError(f"expected a grayscale image or a stack of them, got shape {images.shape}", path)
    return LineSweep(
        images,
        PAPER_CALIBRATION_EXPOSURE_US if exposure_us is None else exposure_us,
        1 if rows_per_line is None else rows_per_line,
    )


#: The fields of ``acquisition.json`` that :func:`write_calibration` sets (every other field is kept).
CALIBRATION_FIELDS = (
    "lines_per_second",
    "lines_per_second_uncertainty",
    "delay_zero_us",
    "delay_zero_uncertainty_us",
    "sync_offset_us",
    "base_trigger_delay_us",
)


def _no_duplicate_keys(pairs):
    keys = [k for k, _ in pairs]
    twice = sorted({k for k in keys if keys.count(k) > 1})
    if twice:
        raise InputError(f"key {twice[0]!r} appears twice; rewriting the file would keep only one of them")
    return dict(pairs)


def calibration_target(path) -> tuple[Path, dict]:
    """The ``acquisition.json`` that :func:`write_calibration` would update, and its current content.

    ``path`` is a ``.json`` file (created if missing) or a folder (``path/acquisition.json``).
    Checked before any calibration work, so a file that could not be updated is refused
    first: another extension, a file that is not a JSON object, a key written twice (a
    rewrite would keep one), a field ``calibration`` that is not an object (planeray
    keeps its results there), a symbolic link or special file.

    Returns
    -------
    path : pathlib.Path
    content : dict
        The file's fields (empty when it does not exist yet).

    Raises
    ------
    InputError
        The file cannot be updated without losing something.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "acquisition.json"
    if path.suffix.lower() != ".json":
        raise InputError("a calibration is written into a .json file (acquisition.json) or its folder", path)
    if path.is_symlink() or (path.exists() and not path.is_file()):
        raise InputError("is a symbolic link or a special file; planeray updates only plain files", path)
    if not path.exists():
        return path, {}
    try:
        acq = json.loads(path.read_text(encoding="utf-8"), object_pairs_hook=_no_duplicate_keys)
    except InputError as exc:
        raise InputError(exc.problem, path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read file ({exc})", path) from exc
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})", path) from exc
    if not isinstance(acq, dict):
        raise InputError(f"expected a JSON object, got {type(acq).__name__}", path)
    if acq.get("calibration") is not None and not isinstance(acq["calibration"], dict):
        raise InputError(
            f"field 'calibration' is a {type(acq['calibration']).__name__}, not an object; planeray keeps its "
            "results there (rename the field to keep it)",
            path,
        )
    return path, acq


def write_calibration(
    path, *, lines: LineCalibration | None = None, delay_zero: DelayZeroCalibration | None = None
) -> dict:
    """Store calibration results in an ``acquisition.json``, keeping every other field.

    Writes ``lines_per_second`` (the field the stack import requires),
    ``lines_per_second_uncertainty``, ``delay_zero_us``,
    ``delay_zero_uncertainty_us`` and ``sync_offset_us`` as given,
    ``base_trigger_delay_us`` (the camera's trigger delay at ``t'_o = 0``, read by
    ``planeray acquire --calibration``) when the delay-zero result has one --
    and removes a previous one when it has not, so the file never pairs a new
    delay zero with an old base -- and the full results under
    ``calibration.lines`` / ``calibration.delay_zero``.

    Nothing of the file is lost: every other field (and its order) is kept, and a
    value that a new calibration changes or removes is kept under
    ``calibration.replaced`` (``{"lines_per_second": 52000.0, ...}``, the values as
    they were before the latest update), so an old calibration can be restored by
    hand.  The file (or ``path/acquisition.json`` when ``path`` is a folder) is created
    if missing and replaced atomically (a temporary sibling renamed into place: a
    crash leaves the old file or the new one, never half of either); see
    :func:`calibration_target` for what is refused.

    Parameters
    ----------
    path : str or path
        An ``acquisition.json`` (or the folder holding it).
    lines : LineCalibration, optional
        The line velocity.
    delay_zero : DelayZeroCalibration, optional
        The delay zero (and base trigger delay).

    Returns
    -------
    dict
        The new content.

    Raises
    ------
    InputError
        Nothing to write, or a file that cannot be updated (:func:`calibration_target`).

    See Also
    --------
    planeray.import_folder : reads the file.

    Examples
    --------
    >>> import planeray as pr
    >>> target = pr.make_scene("diffuse_plane", (288, 32), projector_rows=96, seed=0)
    >>> sweep = pr.SimulatedEpiscan(target, seed=5).capture_line_sweep(500.0)
    >>> import json, pathlib, tempfile
    >>> cal = pr.calibrate_lines_per_second(sweep)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     _ = write_calibration(pathlib.Path(tmp) / "acquisition.json", lines=cal)
    ...     record = json.loads((pathlib.Path(tmp) / "acquisition.json").read_text())
    >>> abs(record["lines_per_second"] - 54000) < 1000
    True
    """

    if lines is None and delay_zero is None:
        raise InputError("nothing to write: give a line-velocity and/or a delay-zero calibration")
    path, acq = calibration_target(path)
    old = dict(acq)
    cal = dict(acq.get("calibration") or {})
    if lines is not None:
        acq["lines_per_second"] = float(lines.lines_per_second)
        acq["lines_per_second_uncertainty"] = float(lines.uncertainty)
        cal["lines"] = lines.to_dict()
    if delay_zero is not None:
        acq["delay_zero_us"] = float(delay_zero.delay_zero_us)
        acq["delay_zero_uncertainty_us"] = float(delay_zero.uncertainty_us)
        acq["sync_offset_us"] = float(delay_zero.sync_offset_us)
        if delay_zero.base_trigger_delay_us is not None:
            acq["base_trigger_delay_us"] = float(delay_zero.base_trigger_delay_us)
        else:
            acq.pop("base_trigger_delay_us", None)
        cal["delay_zero"] = delay_zero.to_dict()
    replaced = {k: old[k] for k in CALIBRATION_FIELDS if k in old and acq.get(k, _MISSING) != old[k]}
    if replaced:
        cal["replaced"] = {**(cal.get("replaced") if isinstance(cal.get("replaced"), dict) else {}), **replaced}
    acq["calibration"] = cal
    acq = jsonable(acq, finite=False, where="acquisition.json", error=InputError)
    with atomic_file(path) as tmp:
        tmp.write_text(json.dumps(acq, indent=2) + "\n", encoding="utf-8")
    return acq


_MISSING = object()
