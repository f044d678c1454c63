"""The captured-stack import folder (``manifest.csv`` + images + ``acquisition.json``): import and export."""

from __future__ import annotations

import csv
import json
import math
import os
from pathlib import Path

import numpy as np

from ..errors import StackError
from ..stack import Stack
from ..timing import boundary_images
from ._common import is_integer, is_number, jsonable, planeray_version
from .atomic import atomic_directory
from .images import check_levels, code_bits, quantize, read_raw_image, write_raw

# ----------------------------------------------------------------------------
#: ``bit_depth`` of an ``acquisition.json`` that gives none (refused for 8-bit images).
DEFAULT_BIT_DEPTH = 12
#: Values of the optional ``float_images`` field: what float TIFFs hold.
FLOAT_IMAGES = ("raw", "normalized")


def _read_acquisition(folder: Path) -> dict:
    path = folder / "acquisition.json"
    if not path.is_file():
        raise StackError("file not found (acquisition.json is required)", path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise StackError(f"cannot read file ({exc})", path) from exc
    try:
        acq = json.loads(text)
    except json.JSONDecodeError as exc:
        raise StackError(f"invalid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})", path) from exc
    if not isinstance(acq, dict):
        raise StackError(f"expected a JSON object, got {type(acq).__name__}", path)

    if "lines_per_second" not in acq:
        raise StackError("missing field 'lines_per_second'", path)
    lps = acq["lines_per_second"]
    if not is_number(lps) or not math.isfinite(lps) or lps <= 0:
        raise StackError(f"field 'lines_per_second' must be a positive number, got {lps!r}", path)
    bit_depth = acq.get("bit_depth", DEFAULT_BIT_DEPTH)
    if not is_integer(bit_depth) or not 1 <= bit_depth <= 16:
        raise StackError(f"field 'bit_depth' must be an integer in 1..16, got {bit_depth!r}", path)
    bit_depth = int(bit_depth)
    max_code = 2**bit_depth - 1
    black = acq.get("black_level", 0)
    if not is_number(black) or not math.isfinite(black) or black < 0:
        raise StackError(f"field 'black_level' must be a number >= 0, got {black!r}", path)
    if black >= max_code:
        raise StackError(
            f"field 'black_level' ({black}) must be below the largest code 2**bit_depth - 1 = {max_code}", path
        )
    projector_rows = acq.get("projector_rows")
    if projector_rows is not None and (not is_integer(projector_rows) or projector_rows < 1):
        raise StackError(f"field 'projector_rows' must be a positive integer, got {projector_rows!r}", path)
    float_images = acq.get("float_images")
    if float_images is not None and float_images not in FLOAT_IMAGES:
        raise StackError(f'field \'float_images\' must be "raw" or "normalized", got {float_images!r}', path)
    default_saturation = 1.0 if float_images == "normalized" else max_code
    saturation = acq.get("saturation_level", default_saturation)
    if not is_number(saturation) or not math.isfinite(saturation):
        raise StackError(f"field 'saturation_level' must be a number, got {saturation!r}", path)
    if float_images == "normalized" and not 0 < saturation <= 1:
        raise StackError(
            f'field \'saturation_level\' must be in (0, 1] with "float_images": "normalized" '
            f"(normalized units, not raw codes), got {saturation!r}",
            path,
        )
    planeray_metadata = acq.get("planeray_metadata", {})
    if not isinstance(planeray_metadata, dict):
        raise StackError(f"field 'planeray_metadata' must be a JSON object, got {planeray_metadata!r}", path)
    return {
        "raw": acq,
        "path": path,
        "lines_per_second": float(lps),
        "bit_depth": bit_depth,
        "bit_depth_given": "bit_depth" in acq,
        "black_level": float(black),
        "projector_rows": None if projector_rows is None else int(projector_rows),
        "saturation_level": float(saturation),
        "float_images": float_images,
        "planeray_metadata": planeray_metadata,
    }


def _check_pixel_type(acq: dict, file: Path, pixel_type: str, description: str) -> None:
    """Refuse a pixel type that ``acquisition.json`` does not describe (checked on the first image)."""
    bits = code_bits(pixel_type)
    if bits is None:  # floating point
        if acq["float_images"] is None:
            raise StackError(
                f"{description} image holds floating-point values: say what they are with "
                f'"float_images": "raw" (raw ADC codes) or "normalized" (already '
                f"(raw - black_level) / (2**bit_depth - 1 - black_level)) in acquisition.json",
                file,
            )
        return
    if acq["float_images"] is not None:
        raise StackError(
            f"field 'float_images' is set but the images are {description} (integer images are raw codes); "
            f"remove the field",
            acq["path"],
        )
    if acq["bit_depth"] > bits:
        given = (
            f"bit_depth is {acq['bit_depth']}"
            if acq["bit_depth_given"]
            else f"acquisition.json gives no bit_depth (default {DEFAULT_BIT_DEPTH})"
        )
        raise StackError(
            f"{description} image holds at most {bits}-bit codes but {given}; "
            f'set "bit_depth": {bits} (or the camera\'s smaller ADC depth) in acquisition.json',
            file,
        )


_TRUE = {"1", "true"}
_FALSE = {"0", "false"}


def _read_manifest(folder: Path):
    path = folder / "manifest.csv"
    if not path.is_file():
        raise StackError("file not found (manifest.csv is required)", path)
    files, delays, exposures, excluded, lines = [], [], [], [], []
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh)
            header = None
            for row in reader:
                if not any(cell.strip() for cell in row):
                    continue  # blank line
                if header is None:
                    header = [cell.strip() for cell in row]
                    for column in ("file", "delay_us", "exposure_us"):
                        if column not in header:
                            raise StackError(f"missing column '{column}' (header has: {', '.join(header)})", path)
                    col = {name: header.index(name) for name in header[::-1]}  # first occurrence wins
                    has_excluded = "excluded" in col
                    continue
                line = reader.line_num
                if len(row) < len(header):
                    raise StackError(f"line {line}: expected {len(header)} columns, got {len(row)}", path)
                name = row[col["file"]].strip()
                if not name:
                    raise StackError(f"line {line}: empty 'file'", path)
                values = {}
                for column in ("delay_us", "exposure_us"):
                    text = row[col[column]].strip()
                    try:
                        value = float(text)
                    except ValueError:
                        value = math.nan
                    if not math.isfinite(value):
                        raise StackError(f"line {line}: {column} {text!r} is not a finite number", path)
                    values[column] = value
                if values["exposure_us"] <= 0:
                    raise StackError(f"line {line}: exposure_us must be positive, got {values['exposure_us']}", path)
                if has_excluded:
                    text = row[col["excluded"]].strip().lower()
                    if text in _TRUE:
                        excluded.append(True)
                    elif text in _FALSE:
                        excluded.append(False)
                    else:
                        raise StackError(f"line {line}: excluded {text!r} is not 0, 1, true or false", path)
                files.append(name)
                delays.append(values["delay_us"])
                exposures.append(values["exposure_us"])
                lines.append(line)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise StackError(f"cannot read file ({type(exc).__name__}: {exc})", path) from exc
    if header is None:
        raise StackError("empty manifest (no header line)", path)
    if not files:
        raise StackError("empty manifest (no image lines)", path)
    _refuse_duplicates(files, delays, exposures, lines, path)
    delays = np.asarray(delays, dtype=np.float64)
    exposures = np.asarray(exposures, dtype=np.float64)
    excluded = np.asarray(excluded, dtype=bool) if has_excluded else boundary_images(delays, exposures)
    return files, delays, exposures, excluded, lines


def _refuse_duplicates(files, delays, exposures, lines, path) -> None:
    """One line per image and per (delay, exposure) setting: no silent choice between two captures."""
    seen_files, seen_settings = {}, {}
    for name, delay, exposure, line in zip(files, delays, exposures, lines):
        key = os.path.normcase(os.path.normpath(name))
        if key in seen_files:
            raise StackError(f"lines {seen_files[key]} and {line} both list the image {name!r}", path)
        seen_files[key] = line
        setting = (delay, exposure)
        if setting in seen_settings:
            raise StackError(
                f"lines {seen_settings[setting]} and {line} have the same delay_us {delay!r} and exposure_us "
                f"{exposure!r} (each setting may appear once; planeray does not average repeated captures: "
                f"average them before importing or remove one)",
                path,
            )
        seen_settings[setting] = line


def import_folder(path) -> Stack:
    """Import a captured delay-exposure stack from a folder of images.

    The folder format (``manifest.csv``, ``acquisition.json`` and grayscale TIFF or
    PNG images) is described in the module docstring of :mod:`planeray.io`.

    Parameters
    ----------
    path : str or os.PathLike
        The folder.

    Returns
    -------
    stack : Stack
        In-memory stack: float32 images normalized as ``(raw - black_level) /
        (2**bit_depth - 1 - black_level)`` (float images with ``"float_images":
        "normalized"`` as they are) and the mask ``raw >= saturation_level``.

    Raises
    ------
    StackError
        Naming the file and the problem, in one line: missing or malformed
        manifest, acquisition record or image; the same image or the same
        (delay_us, exposure_us) setting on two manifest lines (both line numbers
        named); images of different sizes or pixel types (the first image that
        differs, with both types); integer images that cannot hold ``bit_depth``
        (8-bit images need ``"bit_depth": 8``, also when acquisition.json gives
        none); float images without ``float_images``; raw values above the bit
        depth.  Nothing is written to disk.

    See Also
    --------
    export_folder : write one.
    planeray.read_stack : the native stack store.

    Examples
    --------
    An import folder written by :func:`export_folder`, read back:

    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("corner", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     folder = pr.export_folder(stack, pathlib.Path(tmp) / "capture")
    ...     back = pr.import_folder(folder)
    >>> back.images.shape, bool(np.allclose(back.images, stack.images, atol=1e-4))
    ((27, 8, 8), True)
    """
    folder = Path(path)
    if not folder.exists():
        raise StackError("folder does not exist", folder)
    if not folder.is_dir():
        raise StackError("not a folder", folder)
    acq = _read_acquisition(folder)
    files, delays, exposures, excluded, lines = _read_manifest(folder)

    bit_depth, black = acq["bit_depth"], acq["black_level"]
    max_code = 2**bit_depth - 1
    scale = 1.0 / (max_code - black)
    normalized = acq["float_images"] == "normalized"
    images = saturated = None
    first = None
    for i, (name, line) in enumerate(zip(files, lines)):
        file = folder / name
        raw, pixel_type, description = read_raw_image(file, line)
        if raw.dtype.kind == "f" and not np.all(np.isfinite(raw)):
            raise StackError("image contains NaN or infinite values", file)
        if images is None:
            first = (name, raw.shape, pixel_type, description, line)
            images = np.empty((len(files), *raw.shape), dtype=np.float32)
            saturated = np.empty((len(files), *raw.shape), dtype=bool)
        elif pixel_type != first[2]:
            raise StackError(
                f"pixel type {description} differs from {first[3]} of the first image {first[0]!r} "
                f"(manifest.csv line {first[4]}); all images must have the same pixel type",
                file,
            )
        elif raw.shape != first[1]:
            raise StackError(f"image size {raw.shape} differs from the first image {first[0]!r} {first[1]}", file)
        if i == min(1, len(files) - 1):
            # once the first two images agree (or there is one): is the pixel type described by acquisition.json?
            _check_pixel_type(acq, folder / first[0], first[2], first[3])
        if normalized:
            images[i] = raw.astype(np.float32)
            saturated[i] = raw >= acq["saturation_level"]
            continue
        if raw.size:
            top = raw.max()
            if top > max_code:
                raise StackError(f"raw value {top} above the largest code {max_code} of bit_depth {bit_depth}", file)
            if raw.dtype.kind == "i" and raw.min() < 0:
                raise StackError(f"negative raw value {raw.min()}", file)
        images[i] = ((raw.astype(np.float64) - black) * scale).astype(np.float32)
        saturated[i] = raw >= acq["saturation_level"]

    metadata = dict(acq["planeray_metadata"])
    metadata["acquisition"] = {k: v for k, v in acq["raw"].items() if k != "planeray_metadata"}
    metadata["source"] = f"import:{folder}"
    try:
        return Stack(
            images=images,
            delay_us=delays,
            exposure_us=exposures,
            lines_per_second=acq["lines_per_second"],
            excluded=excluded,
            saturated=saturated,
            projector_rows=acq["projector_rows"],
            metadata=metadata,
        )
    except StackError as exc:
        raise StackError(exc.problem, folder) from exc


def export_folder(
    stack: Stack, folder, *, fmt: str = "tiff", bit_depth: int = 16, black_level: float = 256, overwrite: bool = False
) -> Path:
    """Export a stack as an import folder of 16-bit grayscale images, atomically.

    Writes ``img_0000.tif`` (or ``.png``) per image, ``manifest.csv``
    (``file,delay_us,exposure_us,excluded``) and ``acquisition.json``
    (``lines_per_second``, ``bit_depth``, ``black_level``, ``projector_rows`` and
    ``planeray_metadata`` = the stack's metadata), so that :func:`import_folder`
    reads it back: images within half a quantization step
    ``0.5 / (2**bit_depth - 1 - black_level)``, everything else exactly.

    Parameters
    ----------
    stack : Stack
    folder : str or os.PathLike
        Folder to create.
    fmt : {"tiff", "png"}
        Image format (16-bit TIFF via tifffile or 16-bit PNG via Pillow).
    bit_depth : int
        Bit depth of the raw codes (1..16); images are always stored as 16-bit.
    black_level : float
        Raw code of normalized 0.
    overwrite : bool
        Replace an existing folder (atomically).

    Returns
    -------
    folder : pathlib.Path

    See Also
    --------
    import_folder : read one.
    planeray.write_stack : the native stack store.

    Notes
    -----
    Values are clipped to the representable range: below ``-black_level /
    (2**bit_depth - 1 - black_level)`` they become code 0, above 1 the largest code
    (and are flagged saturated on import).  The stack's own saturation mask is not
    exported; import re-derives it from the codes (``raw >= 2**bit_depth - 1``).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> stack = pr.simulate_stack(pr.make_scene("corner", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     folder = pr.export_folder(stack, pathlib.Path(tmp) / "capture")
    ...     sorted(p.name for p in folder.iterdir())[:3]
    ['acquisition.json', 'img_0000.tif', 'img_0001.tif']
    """
    folder = Path(folder)
    kind = {"tiff": "tiff", "tif": "tiff", "png": "png"}.get(str(fmt).lower())
    if kind is None:
        raise StackError(f"unknown image format {fmt!r} (use 'tiff' or 'png')", folder)
    bit_depth, max_code = check_levels(bit_depth, black_level, folder, StackError)
    n = len(stack)
    digits = max(4, len(str(max(n - 1, 0))))
    suffix = ".tif" if kind == "tiff" else ".png"
    acquisition = {
        "lines_per_second": float(stack.lines_per_second),
        "bit_depth": bit_depth,
        "black_level": black_level.item() if isinstance(black_level, np.generic) else black_level,
        "projector_rows": int(stack.projector_rows),
        "planeray_version": planeray_version(),
        "planeray_metadata": jsonable(stack.metadata, finite=False, where="metadata", error=StackError),
    }
    with atomic_directory(folder, overwrite=overwrite, kind="export folder", error=StackError) as tmp:
        rows = []
        for i in range(n):
            image = np.asarray(stack.images[i], dtype=np.float32)
            if not np.all(np.isfinite(image)):
                raise StackError(f"image {i} contains NaN or infinite values", folder)
            name = f"img_{i:0{digits}d}{suffix}"
            write_raw(tmp / name, quantize(image, max_code, black_level), kind)
            rows.append(
                [name, repr(float(stack.delay_us[i])), repr(float(stack.exposure_us[i])), int(bool(stack.excluded[i]))]
            )
        with open(tmp / "manifest.csv", "w", newline="", encoding="utf-8") as fh:
            writer = csv.writer(fh)
            writer.writerow(["file", "delay_us", "exposure_us", "excluded"])
            writer.writerows(rows)
        (tmp / "acquisition.json").write_text(json.dumps(acquisition, indent=2) + "\n", encoding="utf-8")
    return folder
