"""Images synthesized from a transport (Secs. 4, 7, 9).

Everything here is a weighted sum of ``T`` over offsets (Eq. 4) with a weight
chosen after capture -- the "software control" of the paper: epipolar and
non-epipolar images (Eqs. 5, 6), sharpened epipolar images with a band
narrower than any captured exposure (Fig. 11), relighting under any linear
combination of projector rows (Fig. 12), banded indirect images for any
(delay, exposure) -- captured or not -- and the split of indirect light into
short and long range.  The transport may be the ground truth of a scene or a
demultiplexed estimate; the functions never care which.

References
----------
.. [1] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport: Capture
   and Analysis", IEEE TVCG 2019, Secs. 4, 7, 9; Figs. 8, 11, 12.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._validate import check_nonnegative, check_number, check_positive
from .errors import InputError
from .timing import PAPER_LINES_PER_SECOND, Band, RowPattern, band_bin_weights
from .transport import Transport

__all__ = [
    "epipolar_image",
    "non_epipolar_image",
    "offset_window",
    "sharpened_epipolar",
    "band_image",
    "relight",
    "single_line_pattern",
    "load_pattern",
    "short_long_range",
    "michelson_contrast",
]

#: One projector row per microsecond: turns a window in rows into a Band.
_ROWS_PER_US = 1e6


def epipolar_image(transport: Transport) -> np.ndarray:
    r"""Epipolar image, Eq. 5: the light from the camera row's own epipolar plane.

    :math:`I_e(s, t) = \int \delta(t - v)\, T(v, s, t)\, dv`: the transport summed
    over the offsets ``u = v - t`` inside one camera row's footprint.  With an
    ideal transport this is the direct light plus the indirect light that
    happens to stay in the plane.

    Parameters
    ----------
    transport : Transport
        Light transport ``T`` (ground truth or demultiplexed), normalized image
        values per projector row.

    Returns
    -------
    ndarray, shape (H, W), float32
        The epipolar image, in normalized image units (full scale = 1).

    See Also
    --------
    non_epipolar_image : everything else (Eq. 6).
    sharpened_epipolar : a narrower epipolar band (Fig. 11).
    band_image : any (delay, exposure) band.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Eq. 5.

    Examples
    --------
    On a direct-only plane the epipolar image is all the light:

    >>> import numpy as np
    >>> import planeray as pr
    >>> T = pr.make_scene("diffuse_plane", (8, 8), seed=0).transport
    >>> epi = pr.epipolar_image(T)
    >>> epi.shape, bool(np.allclose(epi, T.full_image(), atol=1e-6))
    ((8, 8), True)
    """
    return transport.epipolar_image()


def non_epipolar_image(transport: Transport) -> np.ndarray:
    r"""Non-epipolar image, Eq. 6: all the light that comes from other epipolar planes.

    :math:`I_n(s, t) = \int (1 - \delta(t - v))\, T(v, s, t)\, dv`: indirect
    light only (interreflections, subsurface scattering), with the direct light
    and its epipolar neighbours left out.

    Parameters
    ----------
    transport : Transport
        Light transport ``T`` (ground truth or demultiplexed).

    Returns
    -------
    ndarray, shape (H, W), float32
        The non-epipolar image, in normalized image units; ``epipolar_image(T) +
        non_epipolar_image(T)`` is the full image.

    See Also
    --------
    epipolar_image : the complement (Eq. 5).
    short_long_range : the non-epipolar light split by offset.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Eq. 6.

    Examples
    --------
    Wax scatters light under its surface, so it shows up in the non-epipolar image:

    >>> import numpy as np
    >>> import planeray as pr
    >>> T = pr.make_scene("wax", (8, 8), seed=0).transport
    >>> bool(np.allclose(pr.epipolar_image(T) + pr.non_epipolar_image(T), T.full_image(), atol=1e-5))
    True
    >>> bool(pr.non_epipolar_image(T).max() > 0)
    True
    """
    return transport.non_epipolar_image()


def offset_window(centre_rows: float, width_rows: float) -> Band:
    """A band of offsets ``[centre - width/2, centre + width/2]`` in projector rows.

    The same illumination as a (delay, exposure) band, parameterized in rows:
    exact fractional bin weights, no jitter.

    Parameters
    ----------
    centre_rows : float
        Centre of the band, projector rows from the epipolar plane.
    width_rows : float
        Width of the band, projector rows (> 0).

    Returns
    -------
    Band
        An illumination for :meth:`Transport.render`.

    See Also
    --------
    band_image : the same from a delay and an exposure.
    sharpened_epipolar : a band on the epipolar plane.

    Examples
    --------
    >>> band = offset_window(0.0, 1.0)  # one projector row on the epipolar plane
    >>> band.centre_rows, band.width_rows
    (0.0, 1.0)
    """
    check_number(centre_rows, "band centre (rows)")
    check_positive(width_rows, "band width (rows)")
    return Band(float(centre_rows), float(width_rows), _ROWS_PER_US)


def sharpened_epipolar(transport: Transport, *, width_rows: float = 1.0) -> np.ndarray:
    """Sharpened epipolar image (Fig. 11): a band of ``width_rows`` centred on the epipolar plane.

    Narrower than the narrowest captured exposure (600 us = 32.4 rows in the
    paper), down to one projector row, yet with the SNR of the whole stack.  Note
    that a demultiplexed transport cannot split light inside the cell the sweep
    cannot resolve (``epipolar_resolution_rows`` of the transport store, 6.075
    rows for the paper's sweep): windows narrower than ``2 *`` that cell show the
    regularizer's spread of it, not more detail.

    Parameters
    ----------
    transport : Transport
        Light transport ``T`` (ground truth or demultiplexed).
    width_rows : float
        Width of the band in projector rows (> 0; 1: one projector row).

    Returns
    -------
    ndarray, shape (H, W), float32
        The sharpened epipolar image, in normalized image units.

    See Also
    --------
    epipolar_image : the epipolar image of Eq. 5.
    band_image : any band.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Fig. 11.

    Examples
    --------
    On a direct-only scene the one-row epipolar image is the direct image itself:

    >>> import numpy as np
    >>> from planeray.scenes import make_scene
    >>> scene = make_scene("diffuse_plane", (16, 16), seed=0)
    >>> bool(np.allclose(sharpened_epipolar(scene.transport, width_rows=1.0), scene.direct, atol=1e-6))
    True
    """
    return transport.render(offset_window(0.0, width_rows))


def band_image(
    transport: Transport, delay_us: float, exposure_us: float, *, lines_per_second: float = PAPER_LINES_PER_SECOND
) -> np.ndarray:
    """The image a (delay, exposure) setting would give -- captured or not (Secs. 4, 7).

    The band of Eq. 3, centred ``I_d(t_d)`` projector rows from the epipolar plane
    and ``I_w(t_e)`` rows wide (Eq. 2), applied to the transport (Eq. 4).  A delay
    whose band leaves out ``u = 0`` (``|t_d| > t_e / 2``) gives a banded indirect
    image: light that travelled at least ``|t_d| - t_e / 2`` of scan time away.

    Parameters
    ----------
    transport : Transport
        Light transport ``T`` (ground truth or demultiplexed).
    delay_us : float
        Synchronization delay ``t_d`` in microseconds (negative: above the plane).
    exposure_us : float
        Row exposure ``t_e`` in microseconds (> 0).
    lines_per_second : float, optional
        Projector scan rate ``v_p`` in rows per second (the paper's PicoPro:
        54,000).

    Returns
    -------
    ndarray, shape (H, W), float32
        The banded image, in normalized image units.

    See Also
    --------
    planeray.timing.Band : the illumination it renders.
    relight : any pattern of projector rows.
    epipolar_image, non_epipolar_image

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Eqs. 2-4, Sec. 7.

    Examples
    --------
    A band 375 us (20 rows) away from the plane, 600 us (32 rows) wide:

    >>> import planeray as pr
    >>> T = pr.make_scene("wax", (8, 8), seed=0).transport
    >>> pr.band_image(T, delay_us=375.0, exposure_us=600.0).shape
    (8, 8)
    """
    return transport.render(Band(float(delay_us), float(exposure_us), float(lines_per_second)))


def relight(transport: Transport, pattern) -> np.ndarray:
    """Image under any linear combination of projector rows (relighting, Sec. 9, Fig. 12).

    Parameters
    ----------
    transport : Transport
        Light transport ``T`` (ground truth or demultiplexed).
    pattern : array_like (P,)
        Intensity of each projector row ``v = 0 .. P-1`` (``P`` = the transport's
        projector rows; 1 = the projector's full intensity); any real weights --
        relighting is linear.

    Returns
    -------
    ndarray, shape (H, W), float32
        The relit image, in normalized image units.

    See Also
    --------
    single_line_pattern : one lit row.
    load_pattern : a pattern from a file.
    band_image : the illumination of a (delay, exposure) setting.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 9, Fig. 12.

    Examples
    --------
    All rows lit gives the full image:

    >>> import numpy as np
    >>> import planeray as pr
    >>> T = pr.make_scene("wax", (8, 8), seed=0).transport
    >>> bool(np.allclose(pr.relight(T, np.ones(8)), T.full_image(), atol=1e-5))
    True
    """
    pattern = np.asarray(pattern, dtype=np.float64).ravel()
    P = transport.geometry.projector_rows
    if pattern.size != P:
        raise InputError(f"relighting pattern has {pattern.size} rows, the projector has {P}")
    if not np.all(np.isfinite(pattern)):
        raise InputError("relighting pattern contains NaN or infinite values")
    return transport.render(RowPattern(pattern))


def single_line_pattern(projector_rows: int, row: int) -> np.ndarray:
    """A single lit projector row (the paper's virtual single-line illumination).

    Parameters
    ----------
    projector_rows : int
        Rows of the projector ``P``.
    row : int
        The lit row, ``0 .. P-1``.

    Returns
    -------
    ndarray (P,)
        1 at ``row``, 0 elsewhere.

    See Also
    --------
    relight : the image under a pattern.

    Examples
    --------
    >>> single_line_pattern(5, 2).tolist()
    [0.0, 0.0, 1.0, 0.0, 0.0]
    """
    if not 0 <= row < projector_rows:
        raise InputError(f"projector row {row} outside 0..{projector_rows - 1}")
    p = np.zeros(projector_rows)
    p[row] = 1.0
    return p


def load_pattern(path, projector_rows: int) -> np.ndarray:
    """Read a relighting pattern and resample it to ``projector_rows`` rows.

    ``.npy`` or ``.csv``/``.txt`` (one value per row, or one line of values): a 1-D
    profile.  An image (``.png``, ``.tif``, ``.tiff``, ``.jpg``): the mean of each
    image row, top to bottom, scaled to [0, 1] by the image's dtype range.
    Profiles of another length are resampled linearly over the projector height.

    Parameters
    ----------
    path : str or path
        The pattern file.
    projector_rows : int
        Rows of the projector ``P``.

    Returns
    -------
    ndarray (P,)
        Intensity of each projector row (1 = full).

    See Also
    --------
    relight : the image under the pattern.
    single_line_pattern : one lit row.

    Examples
    --------
    A profile of 3 values resampled linearly to 6 projector rows:

    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = pathlib.Path(tmp) / "pattern.txt"
    ...     np.savetxt(path, [0.0, 1.0, 0.0])
    ...     load_pattern(path, 6).round(2).tolist()
    [0.0, 0.25, 0.75, 0.75, 0.25, 0.0]
    """
    path = Path(path)
    if not path.exists():
        raise InputError("pattern file does not exist", path)
    suffix = path.suffix.lower()
    try:
        if suffix == ".npy":
            values = np.load(path, allow_pickle=False)
        elif suffix in (".csv", ".txt"):
            values = np.loadtxt(path, delimiter="," if suffix == ".csv" else None, ndmin=1)
        elif suffix in (".png", ".tif", ".tiff", ".jpg", ".jpeg"):
            from PIL import Image

            with Image.open(path) as im:
                img = np.asarray(im)
            if img.ndim == 3:
                img = img[..., :3].mean(axis=2)
            top = float(np.iinfo(img.dtype).max) if np.issubdtype(img.dtype, np.integer) else 1.0
            values = img.astype(np.float64).mean(axis=1) / top
        else:
            raise InputError(f"unknown pattern format {suffix!r} (use .npy, .csv, .txt or an image)", path)
    except InputError:
        raise
    except Exception as exc:  # a reader's own error, named with the file
        raise InputError(f"cannot read pattern ({type(exc).__name__}: {exc})", path) from exc
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 1:
        values = values.ravel() if 1 in values.shape else None
        if values is None:
            raise InputError("pattern must be one value per row (a 1-D profile)", path)
    if values.size < 1 or not np.all(np.isfinite(values)):
        raise InputError("pattern is empty or contains NaN", path)
    if values.size == projector_rows:
        return values
    # resample over the projector's height (row centres)
    x_old = (np.arange(values.size) + 0.5) / values.size
    x_new = (np.arange(projector_rows) + 0.5) / projector_rows
    return np.interp(x_new, x_old, values)


def short_long_range(transport: Transport, max_rows: float, *, epipolar_rows: float | None = None):
    """Split indirect light into short range (``epipolar < |u| <= max_rows``) and long range.

    Parameters
    ----------
    transport : Transport
    max_rows : float
        Offset threshold (projector rows) between short- and long-range light.
    epipolar_rows : float, optional
        Half-width of the epipolar part left out of both (default: half a camera
        row's footprint, i.e. what :meth:`Transport.epipolar_image` counts).

    Returns
    -------
    short, long : ndarray (H, W) float32
        ``epipolar + short + long`` is the full image (normalized image units).

    See Also
    --------
    non_epipolar_image : ``short + long``.
    band_image : one band of offsets.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 7.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> T = pr.make_scene("corner", (8, 8), seed=0).transport
    >>> short, long = pr.short_long_range(T, max_rows=3.0)
    >>> bool(np.allclose(pr.epipolar_image(T) + short + long, T.full_image(), atol=1e-5))
    True
    """
    check_positive(max_rows, "short-range threshold (rows)")
    if epipolar_rows is not None:
        check_nonnegative(epipolar_rows, "epipolar half-width (rows)")
    u = transport.offsets_rows.astype(np.float64)
    if epipolar_rows is None:
        epi = band_bin_weights(u, 0.0, transport.geometry.rows_per_camera_row) > 0
    else:
        epi = np.abs(u) <= epipolar_rows
    short_w = ((np.abs(u) <= max_rows) & ~epi).astype(np.float32)
    short = np.tensordot(transport.dense, short_w, axes=([2], [0]))
    epipolar = transport.dense[:, :, epi].sum(axis=2)
    long = transport.full_image() - epipolar - short
    return short.astype(np.float32), long.astype(np.float32)


def michelson_contrast(values, *, axis=-1) -> np.ndarray:
    """Michelson contrast ``(max - min) / (max + min)`` along ``axis`` (e.g. a scan line).

    Parameters
    ----------
    values : array_like
        Non-negative values, e.g. a scan line of an image.
    axis : int
        Axis along which the contrast is taken.

    Returns
    -------
    ndarray
        The contrast, 0 to 1.

    See Also
    --------
    sharpened_epipolar : Fig. 11's contrast of sharpened images.

    Examples
    --------
    >>> float(michelson_contrast([1.0, 3.0, 2.0]))
    0.5
    """
    v = np.asarray(values, dtype=np.float64)
    hi, lo = v.max(axis=axis), v.min(axis=axis)
    return (hi - lo) / np.maximum(hi + lo, 1e-12)
