"""Label images: integer class ids per pixel, read and written as PNG or TIFF.

A label image has the size of the stack it labels and holds, per pixel, a class id:
``0`` = unlabelled (left out of training and scoring), ``1``-``5`` the paper's materials
and ``6`` the background (:data:`planeray.optical_data.CLASS_NAMES`); a user may label
other materials with other ids (1-255) and name them when training.  Accepted files:
8- or 16-bit grayscale or palette PNG, integer TIFF.  planeray writes palette PNGs whose
pixel values are the class ids and whose palette colours them, so one file is both the
data and a picture (segmentation maps are written the same way).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import atomic_file
from ..optical_data import CLASS_NAMES

__all__ = ["read_label_image", "write_label_image", "CLASS_COLOURS", "LABEL_SUFFIXES", "class_colour"]

#: Display colours of the documented classes (RGB, 0-255); 0 (unlabelled) is black.
CLASS_COLOURS = {
    0: (0, 0, 0),
    1: (166, 206, 227),  # fat-free milk: pale blue
    2: (31, 120, 180),  # 2 % milk: blue
    3: (178, 223, 138),  # whole milk: pale green
    4: (51, 160, 44),  # toothpaste: green
    5: (251, 154, 153),  # liquid soap: pink
    6: (120, 120, 120),  # background: grey
}


def class_colour(class_id: int) -> tuple[int, int, int]:
    """Colour of a class id (documented classes as :data:`CLASS_COLOURS`, others from a fixed cycle)."""
    if class_id in CLASS_COLOURS:
        return CLASS_COLOURS[class_id]
    cycle = [(227, 26, 28), (253, 191, 111), (255, 127, 0), (202, 178, 214), (106, 61, 154), (255, 255, 153)]
    return cycle[class_id % len(cycle)]


#: The largest class id (label images and segmentations are 8-bit; 0 is unlabelled).
MAX_CLASS_ID = 255


def read_label_image(path, *, shape=None) -> np.ndarray:
    """Read a label image as ``(H, W)`` int64 class ids.

    Parameters
    ----------
    path : str or os.PathLike
        PNG (grayscale ``L``/``I;16``/``I`` or palette ``P``) or TIFF of integers.
    shape : (int, int), optional
        The stack's image size: a label image of another size is refused.

    Returns
    -------
    ndarray (H, W) int64
        Class ids.

    See Also
    --------
    write_label_image : writes one.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> labels = np.array([[0, 1], [2, 6]])
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = read_label_image(write_label_image(pathlib.Path(tmp) / "labels.png", labels))
    >>> back.tolist()
    [[0, 1], [2, 6]]
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such label image", path)
    suffix = path.suffix.lower()
    if suffix in (".tif", ".tiff"):
        import tifffile

        try:
            arr = tifffile.imread(path)
        except Exception as exc:  # tifffile raises many types for a bad file
            raise InputError(f"cannot read as TIFF ({type(exc).__name__}: {exc})", path) from None
        if arr.dtype.kind not in "iu":
            raise InputError(f"label TIFF must hold integers, got {arr.dtype}", path)
    elif suffix == ".png":
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(path) as img:
                if img.mode not in ("L", "P", "I;16", "I", "1"):
                    raise InputError(
                        f"label PNG must be grayscale or palette (one integer class id per pixel), got mode {img.mode}",
                        path,
                    )
                arr = np.array(img)
        except (UnidentifiedImageError, OSError, ValueError, Image.DecompressionBombError) as exc:
            if isinstance(exc, InputError):
                raise
            raise InputError(f"cannot read as PNG ({exc})", path) from None
    else:
        raise InputError("label images must be .png, .tif or .tiff", path)
    if arr.ndim != 2:
        raise InputError(f"label image must be one channel (H, W), got shape {arr.shape}", path)
    arr = arr.astype(np.int64)
    if arr.min() < 0:
        raise InputError(f"class ids must be >= 0, got {int(arr.min())}", path)
    if arr.max() > MAX_CLASS_ID:
        bad = int((arr > MAX_CLASS_ID).sum())
        raise InputError(
            f"class ids must be 0-{MAX_CLASS_ID} (0: unlabelled), got {int(arr.max())} ({bad} pixel(s) above "
            f"{MAX_CLASS_ID}): planeray's segmentations are 8-bit",
            path,
        )
    if shape is not None and tuple(arr.shape) != tuple(shape):
        raise InputError(f"label image is {arr.shape[0]}x{arr.shape[1]}, the stack {shape[0]}x{shape[1]}", path)
    return arr


#: Suffixes of label images.
LABEL_SUFFIXES = (".png", ".tif", ".tiff")


def write_label_image(path, labels, *, overwrite: bool = True, kind: str = "segmentation") -> Path:
    """Write class ids as a palette PNG (ids as pixel values, coloured by :func:`class_colour`) or a 16-bit TIFF.

    The file carries planeray's mark of ``kind`` (:mod:`planeray.io.marks`: PNG text /
    TIFF tag ``Software``): ``"segmentation"`` for a predicted map, ``"labels"`` for the
    ground truth of a simulated capture.  Callers check that an existing ``path`` may be
    replaced (:func:`planeray.io.atomic.check_replaceable`) before any work.

    Parameters
    ----------
    path : str or path
        ``.png`` (palette) or ``.tif`` (16-bit).
    labels : array_like (H, W) of int
        Class ids.
    overwrite : bool
        Replace an existing file (only one planeray wrote).
    kind : str
        planeray's mark of the file (``"segmentation"``, ``"labels"``).

    Returns
    -------
    pathlib.Path

    See Also
    --------
    read_label_image : reads it back.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = write_label_image(pathlib.Path(tmp) / "seg.png", np.array([[1, 2], [3, 4]]))
    ...     path.name
    'seg.png'
    """
    from ..io.marks import mark_text, png_mark_info

    path = Path(path)
    labels = np.asarray(labels)
    if labels.ndim != 2 or labels.dtype.kind not in "iub":
        raise InputError(f"labels must be a 2-D integer array, got {labels.dtype} {labels.shape}")
    if labels.size and (labels.min() < 0 or labels.max() > 255):
        raise InputError("class ids must lie in 0..255 to be written as a label image")
    suffix = path.suffix.lower()
    if suffix == ".png":
        from PIL import Image

        img = Image.fromarray(labels.astype(np.uint8), mode="P")
        palette = []
        for cid in range(256):
            palette += list(class_colour(cid))
        img.putpalette(palette)
        with atomic_file(path, overwrite=overwrite) as tmp:
            img.save(tmp, format="PNG", pnginfo=png_mark_info(kind))
    elif suffix in (".tif", ".tiff"):
        import tifffile

        with atomic_file(path, overwrite=overwrite) as tmp:
            tifffile.imwrite(tmp, labels.astype(np.uint16), software=mark_text(kind))
    else:
        raise InputError("label images must be .png, .tif or .tiff", path)
    return path


def documented_classes() -> dict[int, str]:
    """The documented class list (id -> name)."""
    return dict(CLASS_NAMES)
