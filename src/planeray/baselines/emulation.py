"""Digital emulation of a delay image with an ordinary projector (Sec. 5.1, Fig. 4): one band per camera row."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validate import check_number, check_positive
from ..timing import RowGeometry, band_bin_weights, band_centre_rows, band_width_rows
from ._device import (
    DEFAULT_FRAME_PERIOD_US,
    capture,
    device_geometry,
    to_transport_units,
)


def band_pattern(
    geometry: RowGeometry, camera_rows, delay_us: float, exposure_us: float, lines_per_second: float
) -> np.ndarray:
    """Projector-row pattern of the bands that emulate (delay, exposure) for some camera rows.

    For each camera row ``t`` the band ``[p_t + I_d - I_w/2, p_t + I_d + I_w/2]``
    (Eq. 2: ``I_d = v_p t_d``, ``I_w = v_p t_e``) is drawn on the projector's
    rows, each row receiving the fraction of it the band covers (the band's
    exact discretization, Eq. 3, on projector rows; off-projector parts are lost,
    as on the synchronized device).  The bands of several rows are added; they
    must not overlap.

    Parameters
    ----------
    geometry : RowGeometry
        Camera and projector rows.
    camera_rows : int or array_like of int
        The camera rows the pattern serves.
    delay_us, exposure_us : float
        The (delay, exposure) emulated, microseconds.
    lines_per_second : float
        Projector scan rate, rows per second.

    Returns
    -------
    pattern : ndarray (P,) float64, values in [0, 1]

    See Also
    --------
    emulate_delay_image : captures under such patterns.

    Examples
    --------
    The projector rows that emulate ``t_d = 0``, ``t_e = 200 us`` (10.8 rows) for camera row 8 of 16:

    >>> import numpy as np
    >>> from planeray.timing import RowGeometry
    >>> p = band_pattern(RowGeometry(16), [8], 0.0, 200.0, 54000.0)
    >>> round(float(p.sum()), 1), float(p[8])
    (10.8, 1.0)
    """
    rows = np.atleast_1d(np.asarray(camera_rows))
    centre = geometry.projector_row_of(rows) + float(band_centre_rows(delay_us, lines_per_second))
    width = float(band_width_rows(exposure_us, lines_per_second))
    v = np.arange(geometry.projector_rows, dtype=float)
    pattern = band_bin_weights(v[None, :], centre[:, None], width).sum(axis=0)
    if pattern.max(initial=0.0) > 1.0 + 1e-9:
        raise ValueError("the bands of the camera rows of one capture overlap: increase the spacing")
    return np.minimum(pattern, 1.0)


@dataclass
class EmulationResult:
    """Result of :func:`emulate_delay_image`.

    Attributes
    ----------
    image : ndarray (H, W) float32
        The assembled delay image, transport units (compare with
        ``Transport.render(Band(delay_us, exposure_us))``).
    saturated : ndarray (H, W) bool
        Saturation of the capture each row was taken from (or of the dark frame).
    n_captures : int
        Conventional captures taken (the dark frame included).
    n_captures_synchronized : int
        Captures the synchronized device needs for the same image: 1.
    rows_per_capture : int
        Camera rows kept from each capture (> 1 when bands are multiplexed).
    delay_us, exposure_us, capture_exposure_us : float
        The emulated delay and exposure (band centre and width), and the
        conventional exposure of each capture.

    See Also
    --------
    emulate_delay_image : returns it.

    Examples
    --------
    >>> from planeray.devices import simulated_device
    >>> device = simulated_device("corner", (16, 16), seed=0)
    >>> result = emulate_delay_image(device, 0.0, 200.0)
    >>> type(result).__name__, result.image.shape
    ('EmulationResult', (16, 16))
    """

    image: np.ndarray
    saturated: np.ndarray = field(repr=False)
    n_captures: int
    n_captures_synchronized: int
    rows_per_capture: int
    delay_us: float
    exposure_us: float
    capture_exposure_us: float


def emulate_delay_image(
    device,
    delay_us: float,
    exposure_us: float,
    *,
    capture_exposure_us: float = DEFAULT_FRAME_PERIOD_US,
    frame_period_us: float = DEFAULT_FRAME_PERIOD_US,
    spacing_rows: int | None = None,
    subtract_dark: bool = True,
    lines_per_second: float | None = None,
    projector_rows: int | None = None,
) -> EmulationResult:
    """Digital epipolar imaging without synchronization (Sec. 5.1, Fig. 4).

    For each camera row ``t``, project (:func:`band_pattern`) the band a
    synchronized device would light for the delay ``t_d`` and exposure ``t_e`` --
    width ``I_w = v_p t_e``, centred ``I_d = v_p t_d`` projector rows below
    the row's own epipolar plane -- take one conventional full-frame capture and
    keep camera row ``t``.  The kept rows, dark-frame subtracted and divided by
    the passes and the signal scale, form the delay image in transport units.

    The straightforward form needs one capture per camera row (``H``, plus the
    dark frame) where the synchronized device needs one.  ``spacing_rows`` ``= S``
    multiplexes: capture ``k`` lights the bands of rows ``k, k + S, k + 2S, ...``
    at once and keeps all of them (``S`` captures).  That is exact only if no
    light travels farther than ``S`` camera rows minus the band width -- the
    assumption the paper's Sec. 5.1 leaves for future work; specular
    interreflections and long diffuse tails break it.

    Parameters
    ----------
    device : PatternDevice
        Must be optically rectified (projector rows = epipolar planes).
    delay_us, exposure_us : float
        The synchronized setting to emulate (Eqs. 1-2).
    capture_exposure_us, frame_period_us : float
        Exposure of each conventional capture and the projector's frame period
        (decoupled from ``exposure_us``: that is the emulation's one advantage).
    spacing_rows : int, optional
        Camera-row spacing of bands multiplexed into one capture; None: one band
        per capture.
    subtract_dark : bool
        Capture and subtract a dark frame (counted in ``n_captures``).
    lines_per_second : float, optional
        ``v_p``; default the device's.
    projector_rows : int, optional
        For devices that do not report it.

    Returns
    -------
    EmulationResult

    See Also
    --------
    compare_emulation : against the synchronized capture.

    References
    ----------
    .. [1] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport",
       TVCG 2019, Sec. 5.1 and Fig. 4.

    Examples
    --------
    >>> from planeray.devices import simulated_device
    >>> device = simulated_device("corner", (16, 16), seed=0)
    >>> result = emulate_delay_image(device, 0.0, 200.0)
    >>> result.n_captures > result.n_captures_synchronized
    True
    """
    check_number(delay_us, "delay_us")
    check_positive(exposure_us, "exposure_us")
    if exposure_us <= 0 or capture_exposure_us <= 0:
        raise ValueError("exposures must be positive")
    geometry = device_geometry(device, projector_rows)
    v_p = float(lines_per_second if lines_per_second is not None else device.lines_per_second)
    H = geometry.camera_rows
    S = H if spacing_rows is None else int(spacing_rows)
    if not 1 <= S <= H:
        raise ValueError(f"spacing_rows must be in [1, {H}], got {spacing_rows}")
    rows_of = [np.arange(k, H, S) for k in range(min(S, H))]
    image = saturated = None
    for rows in rows_of:
        pattern = band_pattern(geometry, rows, delay_us, exposure_us, v_p)
        img, sat = capture(device, pattern, capture_exposure_us, frame_period_us)
        if image is None:
            image, saturated = np.empty_like(img), np.zeros(img.shape, bool)
        image[rows] = img[rows]
        saturated[rows] = sat[rows]
    dark = 0.0
    if subtract_dark:
        dark, sat = capture(device, np.zeros(geometry.projector_rows), capture_exposure_us, frame_period_us)
        saturated |= sat
    image = to_transport_units(device, image, dark, capture_exposure_us, frame_period_us)
    return EmulationResult(
        image.astype(np.float32),
        saturated,
        len(rows_of) + int(subtract_dark),
        1,
        int(np.ceil(H / S)),
        float(delay_us),
        float(exposure_us),
        float(capture_exposure_us),
    )
