"""Vein masks drawn by a user (PNG or TIFF), for metrics on captured stacks.

Format: a grayscale PNG or TIFF of the image's size; 0 is skin, anything else a vein.  A mask
with one nonzero value (0/1, 0/255) is split into veins by 8-connected components; a mask
with several nonzero values is read as vein ids (all pixels of a vein share its value; up to
65535 veins in a 16-bit image).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .metrics import vein_ids_from_mask

__all__ = ["read_vein_mask", "write_vein_mask"]


def read_vein_mask(path, shape=None) -> np.ndarray:
    """Vein ids (int32, 0 off veins) from a mask image; one clear line naming the file on any problem."""
    path = Path(path)
    if not path.is_file():
        raise InputError("vein mask not found", path)
    suffix = path.suffix.lower()
    try:
        if suffix in (".tif", ".tiff"):
            import tifffile

            data = np.asarray(tifffile.imread(path))
        elif suffix == ".png":
            from PIL import Image

            with Image.open(path) as im:
                im.load()
                if im.mode not in ("1", "L", "I", "I;16", "I;16B", "LA", "RGB", "RGBA"):
                    raise InputError(f"unsupported PNG mode {im.mode!r} for a vein mask (use grayscale)", path)
                if im.mode in ("LA", "RGB", "RGBA"):
                    im = im.convert("L")
                data = np.asarray(im)
        else:
            raise InputError(f"unsupported vein mask format {path.suffix!r} (use .png, .tif or .tiff)", path)
    except InputError:
        raise
    except Exception as exc:  # a damaged or non-image file
        raise InputError(f"cannot read the vein mask: {exc}", path) from exc
    if data.ndim != 2:
        raise InputError(f"a vein mask must be one grayscale image, got shape {data.shape}", path)
    if data.dtype.kind == "f" and not np.all(np.isfinite(data)):
        raise InputError("the vein mask contains NaN or infinite values", path)
    if shape is not None and tuple(data.shape) != tuple(shape):
        raise InputError(f"the vein mask is {data.shape[0]}x{data.shape[1]}, the images {shape[0]}x{shape[1]}", path)
    values = np.unique(data[data != 0])
    if values.size == 0:
        raise InputError("the vein mask marks no vein (every pixel is 0)", path)
    if values.size == 1:
        return vein_ids_from_mask(data != 0)
    ids = np.zeros(data.shape, np.int32)
    for k, v in enumerate(values, start=1):
        ids[data == v] = k
    return ids


def write_vein_mask(path, vein_id) -> Path:
    """Write vein ids as a 16-bit PNG (readable by :func:`read_vein_mask`), atomically."""
    from PIL import Image

    from ..io import atomic_file

    ids = np.asarray(vein_id)
    if ids.max() > 65535 or ids.min() < 0:
        raise ValueError("vein ids must be in 0..65535")
    path = Path(path)
    with atomic_file(path) as tmp:
        Image.fromarray(ids.astype(np.uint16)).save(tmp, format="PNG")
    return path
