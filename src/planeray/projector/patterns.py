"""The projector's patterns, as arrays whose pixel ``(r, c)`` is the projector's pixel ``(r, c)``.

Every pattern is ``uint8``, ``(rows, columns)`` (grey) or ``(rows, columns, 3)``
(RGB); :func:`as_rgb8` checks any array or image and turns it into what the
window shows.  The comb of the line-velocity calibration (Sec. 6 of Kubo et al.;
the design in :mod:`planeray.calibration`) lights every ``k``-th row from
``phase`` on; a rectification card has a numbered one-pixel line every
``step_rows`` rows to align projector rows with camera rows.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._validate import check_integer
from ..errors import InputError

__all__ = [
    "white",
    "black",
    "comb",
    "rows",
    "rectification_card",
    "load_pattern",
    "as_rgb8",
    "place",
    "parse_pattern",
    "PATTERN_NAMES",
]

#: The named patterns of ``planeray project`` (anything else is an image file).
PATTERN_NAMES = ("white", "black", "comb:K:J", "row:R", "rows:A:B", "card", "card:STEP")


def _shape(shape) -> tuple[int, int]:
    h, w = (int(n) for n in shape[:2])
    if h < 1 or w < 1:
        raise InputError(f"a pattern needs at least one row and column, got {h}x{w}")
    return h, w


def _level(level) -> int:
    return check_integer(level, "level", minimum=0, maximum=255)


def white(shape, *, level: int = 255) -> np.ndarray:
    """Every pixel lit at ``level`` (0-255): the sweep's illumination.

    Parameters
    ----------
    shape : (int, int)
        The screen's ``(rows, columns)``.
    level : int
        Brightness, 0-255.

    Returns
    -------
    ndarray (rows, columns) uint8

    See Also
    --------
    black : the laser off.

    Examples
    --------
    >>> white((2, 3)).shape, int(white((2, 3), level=128).max())
    ((2, 3), 128)
    """
    return np.full(_shape(shape), _level(level), np.uint8)


def black(shape) -> np.ndarray:
    """Every pixel dark: the laser off (a dark frame).

    Parameters
    ----------
    shape : (int, int)
        The screen's ``(rows, columns)``.

    Returns
    -------
    ndarray (rows, columns) uint8

    See Also
    --------
    white : the laser on.

    Examples
    --------
    >>> int(black((2, 3)).max())
    0
    """
    return np.zeros(_shape(shape), np.uint8)


def comb(shape, step_rows: int, phase: int, *, level: int = 255) -> np.ndarray:
    """Rows ``phase, phase + k, phase + 2k, ...`` lit (``k = step_rows``), the others dark (Sec. 6).

    Parameters
    ----------
    shape : (int, int)
        The screen's ``(rows, columns)``.
    step_rows : int
        ``k``: rows between lit rows.
    phase : int
        The first lit row.
    level : int
        Brightness of the lit rows, 0-255.

    Returns
    -------
    ndarray (rows, columns) uint8

    See Also
    --------
    planeray.rig.capture_comb : captures every phase.

    Examples
    --------
    >>> comb((7, 2), 3, 1)[:, 0]
    array([  0, 255,   0,   0, 255,   0,   0], dtype=uint8)
    """
    h, w = _shape(shape)
    k = check_integer(step_rows, "step_rows", minimum=1, maximum=h)
    j = check_integer(phase, "phase", minimum=0, maximum=k - 1)
    out = np.zeros((h, w), np.uint8)
    out[j::k] = _level(level)
    return out


def rows(shape, first: int, last: int | None = None, *, level: int = 255) -> np.ndarray:
    """Row ``first`` lit, or the band of rows ``first`` to ``last`` (both included).

    Parameters
    ----------
    shape : (int, int)
        The screen's ``(rows, columns)``.
    first : int
        The first lit row.
    last : int, optional
        The last lit row (default: ``first``).
    level : int
        Brightness, 0-255.

    Returns
    -------
    ndarray (rows, columns) uint8

    See Also
    --------
    comb : rows ``k`` apart.

    Examples
    --------
    >>> rows((6, 2), 2, 3)[:, 0].tolist()  # rows 2 to 3 lit
    [0, 0, 255, 255, 0, 0]
    """
    h, w = _shape(shape)
    last = first if last is None else last
    a = check_integer(first, "first row", minimum=0, maximum=h - 1)
    b = check_integer(last, "last row", minimum=a, maximum=h - 1)
    out = np.zeros((h, w), np.uint8)
    out[a : b + 1] = _level(level)
    return out


def rectification_card(shape, *, step_rows: int = 40) -> np.ndarray:
    """A numbered one-pixel white line every ``step_rows`` rows (row 0 included), on black.

    Each line's row number is written just below it, at the left, centre and right;
    short ticks at both edges mark every tenth row between.  Point the camera at a
    flat target, show the card, and turn the camera until each line lies on one
    camera row (the numbers tell which projector row it is).

    Parameters
    ----------
    shape : (int, int)
        The screen's ``(rows, columns)``.
    step_rows : int
        Rows between the numbered lines.

    Returns
    -------
    ndarray (rows, columns) uint8

    See Also
    --------
    parse_pattern : ``card`` by name.

    Examples
    --------
    >>> card = rectification_card((100, 200), step_rows=40)
    >>> import numpy as np
    >>> card.shape, np.flatnonzero(card.min(axis=1) == 255).tolist()  # the rows of the full-width lines
    ((100, 200), [0, 40, 80])
    """
    from PIL import Image, ImageDraw, ImageFont

    h, w = _shape(shape)
    step = check_integer(step_rows, "step_rows", minimum=10, maximum=max(10, h))
    card = Image.new("L", (w, h), 0)
    draw = ImageDraw.Draw(card)
    font = ImageFont.load_default()
    tick = max(4, w // 80)
    for r in range(0, h, 10):
        if r % step:
            draw.line([(0, r), (tick - 1, r)], fill=255)
            draw.line([(w - tick, r), (w - 1, r)], fill=255)
    for r in range(0, h, step):
        label = str(r)
        left, top, right, bottom = draw.textbbox((0, 0), label, font=font)
        tw, th = right - left, bottom - top
        if r + 3 + th < min(h, r + step):  # the number fits in the gap below its line
            for x in (tick + 2, (w - tw) // 2, w - tick - 2 - tw):
                draw.text((x - left, r + 3 - top), label, fill=255, font=font)
    out = np.asarray(card, np.uint8).copy()
    out[0:h:step] = 255  # the lines themselves: exactly one row each, drawn last
    return out


def load_pattern(path) -> np.ndarray:
    """An image file (PNG, TIFF, BMP..., 8-bit grey or RGB) or a ``.npy`` array, as a pattern.

    Parameters
    ----------
    path : str or path
        The image or ``.npy`` file.

    Returns
    -------
    ndarray uint8

    Raises
    ------
    InputError
        Missing, unreadable, or not 8-bit (a 16-bit image would need a scaling the
        pattern must not get).

    See Also
    --------
    parse_pattern : a name or a file.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pathlib.Path(tmp) / "p.npy"
    ...     np.save(path, rows((4, 4), 1))
    ...     load_pattern(path).shape
    (4, 4, 3)
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("pattern file not found", path)
    try:
        if path.suffix.lower() == ".npy":
            arr = np.load(path, allow_pickle=False)
        else:
            from PIL import Image

            with Image.open(path) as im:
                if im.mode not in ("1", "L", "RGB", "RGBA", "P"):
                    raise InputError(f"a pattern must be 8-bit grey or RGB, this image is mode {im.mode}", path)
                im = im.convert("RGB") if im.mode in ("P", "RGBA") else im.convert("L") if im.mode == "1" else im
                arr = np.asarray(im)
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"cannot read the pattern ({type(exc).__name__}: {exc})", path) from None
    try:
        return as_rgb8(arr)
    except InputError as exc:
        raise InputError(str(exc), path) from None


def as_rgb8(pattern) -> np.ndarray:
    """The pattern as the window shows it: ``(rows, columns, 3)`` uint8, values unchanged.

    ``uint8`` and ``bool`` arrays are taken as they are (True = 255); floats must lie
    in ``[0, 1]`` and become ``round(255 x)``; grey is repeated on the three channels.
    Nothing else is changed: no scaling, filtering or gamma.

    Parameters
    ----------
    pattern : array_like
        Grey ``(rows, columns)`` or RGB ``(rows, columns, 3)``, 0-255.

    Returns
    -------
    ndarray (rows, columns, 3) uint8

    See Also
    --------
    parse_pattern : patterns by name.

    Examples
    --------
    >>> as_rgb8(white((2, 3))).shape
    (2, 3, 3)
    """
    a = np.asarray(pattern)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] != 3) or a.shape[0] < 1 or a.shape[1] < 1:
        raise InputError(f"a pattern must be (rows, columns) or (rows, columns, 3), got shape {a.shape}")
    if a.dtype == np.bool_:
        a = a.astype(np.uint8) * 255
    elif np.issubdtype(a.dtype, np.floating):
        if not np.all(np.isfinite(a)) or a.min(initial=0) < 0 or a.max(initial=0) > 1:
            raise InputError("a float pattern must lie in [0, 1] (it becomes 0-255)")
        a = np.rint(a * 255.0).astype(np.uint8)
    elif a.dtype != np.uint8:
        if np.issubdtype(a.dtype, np.integer) and a.size and 0 <= a.min() and a.max() <= 255:
            a = a.astype(np.uint8)
        else:
            raise InputError(f"a pattern must be 8-bit (0-255), got {a.dtype} values beyond that")
    if a.ndim == 2:
        a = np.repeat(a[:, :, None], 3, axis=2)
    return np.ascontiguousarray(a)


def place(pattern, shape, at) -> np.ndarray:
    """The pattern put on a black screen of ``shape`` with its top-left pixel at ``at = (row, column)``.

    Parameters
    ----------
    pattern : array_like
        The pattern.
    shape : (int, int)
        The screen's ``(rows, columns)``.
    at : (int, int)
        Where its top-left pixel goes, ``(row, column)``.

    Returns
    -------
    ndarray uint8

    Raises
    ------
    InputError
        It does not fit there (nothing is cropped).

    See Also
    --------
    black : the screen around it.

    Examples
    --------
    >>> placed = place(white((1, 2)), (3, 4), (1, 2))
    >>> placed[..., 0].tolist()
    [[0, 0, 0, 0], [0, 0, 255, 255], [0, 0, 0, 0]]
    """
    p = as_rgb8(pattern)
    h, w = _shape(shape)
    r, c = (int(x) for x in at)
    if r < 0 or c < 0 or r + p.shape[0] > h or c + p.shape[1] > w:
        raise InputError(
            f"a {p.shape[1]}x{p.shape[0]} pattern placed at row {r}, column {c} does not fit on a {w}x{h} screen"
        )
    out = np.zeros((h, w, 3), np.uint8)
    out[r : r + p.shape[0], c : c + p.shape[1]] = p
    return out


def parse_pattern(spec: str, shape) -> np.ndarray:
    """The pattern named by ``spec`` for a screen of ``shape``, or the image file ``spec``.

    ``white``, ``black``, ``comb:K:J`` (every ``K``-th row from ``J``), ``row:R``,
    ``rows:A:B`` (rows ``A`` to ``B``, both included), ``card`` or ``card:STEP``;
    anything else is read as an image file.

    Parameters
    ----------
    spec : str
        A pattern's name (``white``, ``black``, ``card``, ``rows:A-B``, ``comb:K:P``...) or an image file.
    shape : (int, int)
        The screen's ``(rows, columns)``.

    Returns
    -------
    ndarray (rows, columns) uint8

    See Also
    --------
    load_pattern : an image file.

    Examples
    --------
    >>> parse_pattern("white", (2, 2)).tolist()
    [[255, 255], [255, 255]]
    """
    name, _, rest = spec.partition(":")
    args = rest.split(":") if rest else []
    builders = {
        "white": (0, lambda: white(shape)),
        "black": (0, lambda: black(shape)),
        "comb": (2, lambda k, j: comb(shape, k, j)),
        "row": (1, lambda r: rows(shape, r)),
        "rows": (2, lambda a, b: rows(shape, a, b)),
        "card": ((0, 1), lambda *s: rectification_card(shape, step_rows=s[0]) if s else rectification_card(shape)),
    }
    if name in builders and not Path(spec).exists():
        n, build = builders[name]
        counts = n if isinstance(n, tuple) else (n,)
        if len(args) not in counts or not all(a.strip().lstrip("-").isdigit() for a in args):
            raise InputError(f"pattern {spec!r}: expected one of {', '.join(PATTERN_NAMES)} or an image file")
        return build(*(int(a) for a in args))
    return load_pattern(spec)
