"""From image values to display colours: the one mapping shared by the page, snapshots and videos.

A value ``x`` is shown as ``colormap[c]`` with

* ``q = clip(round(4095 * x / white), 0, 4095)`` (``white``: the value shown at full brightness;
  rounding is ``floor(. + 0.5)``),
* ``c = floor(255 * (q / 4095) ** gamma + 0.5)``.

The page does the same in JavaScript with a 4096-entry table (``static/app.js``,
``buildLut`` and ``paint``), so a frame painted in the browser and a frame of
``planeray video`` agree to the code.  The colormaps are matplotlib's, sampled at 256
levels and sent to the page when it connects.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["COLORMAPS", "colormap_table", "colormap_tables", "to_rgb", "auto_white", "check_display"]

#: Colormaps offered by the page (matplotlib names).
COLORMAPS = ("gray", "magma", "inferno", "viridis", "cividis", "turbo")

_LEVELS = 4095


def colormap_table(name: str) -> np.ndarray:
    """``(256, 3)`` uint8 RGB table of a colormap of :data:`COLORMAPS`."""
    if name not in COLORMAPS:
        raise InputError(f"unknown colormap {name!r}; choose one of {', '.join(COLORMAPS)}")
    if name == "gray":
        ramp = np.arange(256, dtype=np.uint8)
        return np.stack([ramp, ramp, ramp], axis=1)
    from matplotlib import colormaps

    rgba = colormaps[name](np.linspace(0.0, 1.0, 256))
    return np.floor(rgba[:, :3] * 255 + 0.5).astype(np.uint8)


def colormap_tables() -> dict[str, list[int]]:
    """Every colormap as 256 integers ``0xRRGGBB`` (what the page receives)."""
    out = {}
    for name in COLORMAPS:
        t = colormap_table(name).astype(np.int64)
        out[name] = ((t[:, 0] << 16) | (t[:, 1] << 8) | t[:, 2]).tolist()
    return out


def check_display(*, white: float, gamma: float, colormap: str) -> None:
    """Refuse display settings that cannot be shown (one line naming the setting)."""
    if not (isinstance(white, int | float) and np.isfinite(white) and white > 0):
        raise InputError(f"white must be a positive number (the value shown white), got {white!r}")
    if not (isinstance(gamma, int | float) and np.isfinite(gamma) and 0.05 <= gamma <= 20):
        raise InputError(f"gamma must be a number in [0.05, 20], got {gamma!r}")
    if colormap not in COLORMAPS:
        raise InputError(f"colormap must be one of {', '.join(COLORMAPS)}, got {colormap!r}")


def display_codes(image, *, white: float, gamma: float = 1.0) -> np.ndarray:
    """Colormap indices 0..255 of an image (the mapping of the module docstring)."""
    x = np.asarray(image, dtype=np.float64) * (_LEVELS / float(white))
    q = np.where(x > 0, np.floor(np.minimum(x, _LEVELS) + 0.5), 0.0)
    q = np.nan_to_num(q, nan=0.0)
    return np.floor(255.0 * (q / _LEVELS) ** float(gamma) + 0.5).astype(np.uint8)


def to_rgb(image, *, white: float, gamma: float = 1.0, colormap: str = "gray") -> np.ndarray:
    """``(H, W, 3)`` uint8 RGB of an image as the page paints it.

    Parameters
    ----------
    image : array_like (H, W)
        The image.
    white : float
        The value shown as white.
    gamma : float
        Display gamma.
    colormap : str
        ``"gray"`` or a matplotlib colormap.

    Returns
    -------
    ndarray (H, W, 3) uint8

    See Also
    --------
    auto_white : a white level.

    Examples
    --------
    >>> to_rgb(np.array([[0.0, 0.5, 1.0, 2.0]]), white=1.0)[0, :, 0].tolist()
    [0, 128, 255, 255]
    """
    check_display(white=white, gamma=gamma, colormap=colormap)
    return colormap_table(colormap)[display_codes(image, white=white, gamma=gamma)]


def auto_white(image, percentile: float = 99.5) -> float:
    """A white level that shows an image brightly: its ``percentile`` (the figures' display scale).

    Subsampled to about 16k pixels (cheap enough for every frame); 1 for a black image.

    Parameters
    ----------
    image : array_like
        The image.
    percentile : float
        Percentile shown as white.

    Returns
    -------
    float

    See Also
    --------
    to_rgb : paints with it.

    Examples
    --------
    >>> import numpy as np
    >>> round(float(auto_white(np.linspace(0.0, 1.0, 1001), percentile=99.5)), 3)
    0.995
    """
    flat = np.asarray(image, dtype=np.float32).ravel()
    step = max(1, flat.size // 16384)
    sample = flat[::step]
    sample = sample[np.isfinite(sample)]
    top = float(np.percentile(sample, percentile)) if sample.size else 0.0
    return top if top > 0 else 1.0
