"""Single image files: normalized images <-> integer codes in 16-bit TIFF or PNG."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import tifffile
from PIL import Image

from ..errors import InputError, StackError
from ._common import IMAGE_SUFFIXES, is_integer, is_number
from .atomic import atomic_file


# ----------------------------------------------------------------------------
def check_levels(bit_depth, black_level, path, error):
    if not is_integer(bit_depth) or not 1 <= bit_depth <= 16:
        raise error(f"bit_depth must be an integer in 1..16, got {bit_depth!r}", path)
    max_code = 2 ** int(bit_depth) - 1
    if not is_number(black_level) or not 0 <= black_level < max_code:
        raise error(f"black_level must be a number in [0, {max_code}), got {black_level!r}", path)
    return int(bit_depth), max_code


def quantize(image, max_code: int, black_level: float) -> np.ndarray:
    """Normalized image -> uint16 raw codes, rounded and clipped to ``[0, max_code]``."""
    raw = np.rint(np.asarray(image, dtype=np.float64) * (max_code - black_level) + black_level)
    return np.clip(raw, 0, max_code).astype(np.uint16)


def write_raw(path: Path, raw: np.ndarray, kind: str, *, mark: str = "image") -> None:
    """Write raw codes as TIFF or PNG, carrying planeray's file mark (:mod:`planeray.io.marks`)."""
    from .marks import mark_text, png_mark_info

    if kind == "tiff":
        tifffile.imwrite(path, raw, photometric="minisblack", software=mark_text(mark))
    else:
        Image.fromarray(raw).save(path, format="PNG", pnginfo=png_mark_info(mark))


def read_raw_image(path: Path, manifest_line: int) -> tuple[np.ndarray, str, str]:
    """Read one grayscale image as stored (integer or float array, 2-D).

    Returns
    -------
    data : numpy.ndarray
        The pixel values in native byte order; 1-bit images as uint8 0/1.
    pixel_type : str
        The dtype as stored (``"uint16"``, ``"uint8"``, ``"bool"``, ``"float32"``...):
        all the images of a folder must share it.
    description : str
        The pixel type in words for messages: ``"uint16 TIFF"``, ``"uint8 PNG (mode 'L')"``.
    """
    where = f"manifest.csv line {manifest_line}"
    if not path.is_file():
        raise StackError(f"image not found ({where})", path)
    kind = IMAGE_SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise StackError(f"unsupported image format {path.suffix!r} (use .tif, .tiff or .png)", path)
    mode = None
    try:
        if kind == "tiff":
            data = np.asarray(tifffile.imread(path))
        else:
            with Image.open(path) as im:
                im.load()
                mode = im.mode
                if im.mode in ("P", "PA", "CMYK", "YCbCr", "LAB", "HSV"):
                    raise StackError(f"expected a grayscale image, got PNG mode {im.mode!r}", path)
                data = np.asarray(im)
    except StackError:
        raise
    except Exception as exc:  # truncated / corrupt files raise many types
        raise StackError(f"cannot read image ({type(exc).__name__}: {exc})", path) from exc
    if data.ndim != 2:
        raise StackError(f"expected a grayscale image, got shape {data.shape}", path)
    if data.dtype.kind not in "buif":
        raise StackError(f"unsupported pixel type {data.dtype}", path)
    if not data.dtype.isnative:
        data = data.astype(data.dtype.newbyteorder("="))
    pixel_type = data.dtype.name
    description = f"{pixel_type} TIFF" if kind == "tiff" else f"{pixel_type} PNG (mode {mode!r})"
    if data.dtype.kind == "b":
        data = data.astype(np.uint8)
    return data, pixel_type, description


def code_bits(pixel_type: str) -> int | None:
    """Largest bit depth an integer pixel type holds (``bool`` 1, ``uint8`` 8, ``int16`` 15); None for floats."""
    dtype = np.dtype(pixel_type)
    if dtype.kind == "b":
        return 1
    if dtype.kind in "ui":
        return int(np.iinfo(dtype).max).bit_length()
    return None


def write_image(path, image, *, bit_depth: int = 16, black_level: float = 0) -> Path:
    """Write one normalized image as a 16-bit grayscale TIFF or PNG, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; ``.tif``/``.tiff`` (tifffile) or ``.png`` (Pillow) picks the
        format.  An existing file is replaced.
    image : array_like, shape (H, W)
        Normalized image (0 = black, 1 = largest code).
    bit_depth : int
        Codes are ``round(image * (2**bit_depth - 1 - black_level) + black_level)``,
        clipped to ``[0, 2**bit_depth - 1]`` and stored as uint16.
    black_level : float
        Raw code of normalized 0.

    Returns
    -------
    path : pathlib.Path

    Raises
    ------
    InputError
        Unknown extension, image not 2-D or not finite, invalid bit depth.

    See Also
    --------
    planeray.export_folder : a stack's images so written.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> import tifffile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = write_image(pathlib.Path(tmp) / "img.tif", np.full((2, 2), 0.5))
    ...     tifffile.imread(path).tolist()
    [[32768, 32768], [32768, 32768]]
    """
    path = Path(path)
    kind = IMAGE_SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise InputError(f"unsupported image extension {path.suffix!r} (use .tif, .tiff or .png)", path)
    _, max_code = check_levels(bit_depth, black_level, path, InputError)
    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 2:
        raise InputError(f"expected a 2-D image, got shape {image.shape}", path)
    if not np.all(np.isfinite(image)):
        raise InputError("image contains NaN or infinite values", path)
    raw = quantize(image, max_code, black_level)
    with atomic_file(path) as tmp:
        write_raw(tmp, raw, kind)
    return path
