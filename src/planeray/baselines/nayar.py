"""Direct/global separation with shifted high-frequency stripes (Nayar et al. 2006 [1]_), the baseline of Sec. 2.

References
----------
.. [1] S. K. Nayar, G. Krishnan, M. D. Grossberg, R. Raskar, "Fast separation of
   direct and global components of a scene using high frequency illumination",
   ACM Trans. Graph. 25(3) (SIGGRAPH 2006), 935-944.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..timing import RowGeometry
from ._device import (
    DEFAULT_FRAME_PERIOD_US,
    capture,
    device_geometry,
    to_transport_units,
)


def default_period_rows(geometry: RowGeometry) -> int:
    """Default stripe period (projector rows): ``2 (ceil(P / H) + 2)``.

    Each half period then covers every projector row that can reach one camera
    row's direct light through the transport's offset bins (``ceil(P/H) + 2``
    rows; see the module notes), so one of the shifts lights a row's whole
    footprint and another darkens it.  6 rows for ``P = H``, 16 rows for 128
    camera rows of a 720-row projector.

    Parameters
    ----------
    geometry : RowGeometry
        Camera and projector rows.

    Returns
    -------
    int
        The stripe period, projector rows.

    See Also
    --------
    stripe_patterns : the patterns.

    Examples
    --------
    >>> from planeray.timing import RowGeometry
    >>> default_period_rows(RowGeometry(128, 720))  # 2 (ceil(720 / 128) + 2)
    16
    """
    return int(2 * (np.ceil(geometry.rows_per_camera_row - 1e-9) + 2))


def stripe_patterns(
    projector_rows: int, *, period_rows: int = 16, n_shifts: int | None = None, low: float = 0.0
) -> np.ndarray:
    """Shifted horizontal stripe patterns (50 % duty cycle) over projector rows.

    Pattern ``k`` lights projector row ``v`` when ``(v - s_k) mod period < period / 2``
    with the shift ``s_k = round(k * period / n_shifts)``: ``period/2`` bright rows,
    ``period/2`` dark rows, the high-frequency illumination of Nayar et al. [1]_
    restricted to the rows of a plane-to-ray transport.

    Parameters
    ----------
    projector_rows : int
        Number of projector rows ``P``.
    period_rows : int
        Stripe period in projector rows; even, at least 2.  See
        :func:`default_period_rows` for the smallest period that resolves a
        camera row.
    n_shifts : int, optional
        Number of shifted patterns spread over one period; default ``period_rows``
        (a one-row step, so every row is fully lit and fully dark in some pattern).
    low : float
        Intensity of the "dark" rows (Nayar's ``b``: a deactivated projector pixel
        still emits this fraction of the bright intensity).

    Returns
    -------
    patterns : ndarray (n_shifts, projector_rows) float64
        Values ``1`` (bright) and ``low`` (dark).

    See Also
    --------
    separate_direct_global : separates their captures.

    References
    ----------
    .. [1] Nayar et al., "Fast separation of direct and global components of a
       scene using high frequency illumination", SIGGRAPH 2006.

    Examples
    --------
    >>> stripe_patterns(8, period_rows=4).tolist()
    [[1.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0], [0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0], [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 1.0], [1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0]]
    """
    P, period = int(projector_rows), int(period_rows)
    if period < 2 or period % 2:
        raise ValueError(f"period_rows must be an even number >= 2, got {period_rows}")
    if P < 1:
        raise ValueError("projector_rows must be positive")
    n = period if n_shifts is None else int(n_shifts)
    if not 2 <= n <= period:
        raise ValueError(f"n_shifts must be in [2, period_rows = {period}], got {n_shifts}")
    if not 0.0 <= low < 1.0:
        raise ValueError(f"low must be in [0, 1), got {low}")
    shifts = np.rint(np.arange(n) * period / n).astype(np.int64)
    v = np.arange(P)
    bright = np.mod(v[None, :] - shifts[:, None], period) < period // 2
    return np.where(bright, 1.0, float(low))


def separate_direct_global(images, *, pattern_contrast_b: float = 0.0):
    """Direct and global images from captures under shifted high-frequency patterns.

    With ``L+ = max_k I_k`` and ``L- = min_k I_k`` per pixel, and a projector
    whose dark pixels still emit a fraction ``b`` of the bright intensity, Nayar
    et al. [1]_ model (50 % duty cycle, global light smooth at the pattern
    frequency)::

        L+ = Ld + (1 + b) Lg / 2,     L- = b Ld + (1 + b) Lg / 2

    hence ``Ld = (L+ - L-) / (1 - b)`` and ``Lg = 2 (L- - b L+) / (1 - b^2)``;
    ``b = 0`` gives ``Ld = L+ - L-``, ``Lg = 2 L-``.

    Parameters
    ----------
    images : array_like (N, H, W)
        Captures under the N shifted patterns (any linear units, dark frame removed).
    pattern_contrast_b : float
        ``b`` in ``[0, 1)``.

    Returns
    -------
    direct, global : ndarray (H, W) float64

    See Also
    --------
    capture_direct_global : captures and separates.

    References
    ----------
    .. [1] S. K. Nayar, G. Krishnan, M. D. Grossberg, R. Raskar, "Fast separation
       of direct and global components of a scene using high frequency
       illumination", SIGGRAPH 2006, Sec. 3.

    Examples
    --------
    Nayar's model: a pixel sees all its direct light when lit, none when dark, half its global light always:

    >>> import numpy as np
    >>> images = np.array([[[1.0 + 0.5]], [[0.5]]])  # max 1.5, min 0.5 over the shifted patterns
    >>> direct, global_ = separate_direct_global(images)
    >>> float(direct[0, 0]), float(global_[0, 0])
    (1.0, 1.0)
    """
    stack = np.asarray(images, dtype=np.float64)
    if stack.ndim != 3 or stack.shape[0] < 2:
        raise ValueError(f"images must be a stack (N >= 2, H, W), got shape {stack.shape}")
    b = float(pattern_contrast_b)
    if not 0.0 <= b < 1.0:
        raise ValueError(f"pattern_contrast_b must be in [0, 1), got {pattern_contrast_b}")
    l_max, l_min = stack.max(axis=0), stack.min(axis=0)
    direct = (l_max - l_min) / (1.0 - b)
    global_ = 2.0 * (l_min - b * l_max) / (1.0 - b * b)
    return direct, global_


@dataclass
class DirectGlobalResult:
    """Result of :func:`capture_direct_global` (images in transport units).

    Attributes
    ----------
    direct, global_ : ndarray (H, W)
        Nayar direct and global images.
    images : ndarray (N, H, W)
        The dark-subtracted captures under the shifted patterns, transport units.
    patterns : ndarray (N, P)
        The projected patterns.
    saturated : ndarray (H, W) bool
        Pixels saturated in any capture (their separation is invalid).
    n_captures : int
        Captures taken, the dark frame included.
    period_rows, n_shifts : int
    pattern_contrast_b : float

    See Also
    --------
    capture_direct_global : returns it.

    Examples
    --------
    >>> from planeray.devices import simulated_device
    >>> device = simulated_device("corner", (16, 16), seed=0)
    >>> result = capture_direct_global(device)
    >>> type(result).__name__, result.direct.shape, result.n_captures
    ('DirectGlobalResult', (16, 16), 7)
    """

    direct: np.ndarray
    global_: np.ndarray
    images: np.ndarray = field(repr=False)
    patterns: np.ndarray = field(repr=False)
    saturated: np.ndarray = field(repr=False)
    n_captures: int
    period_rows: int
    n_shifts: int
    pattern_contrast_b: float = 0.0


def capture_direct_global(
    device,
    *,
    period_rows: int | None = None,
    n_shifts: int | None = None,
    exposure_us: float = DEFAULT_FRAME_PERIOD_US,
    frame_period_us: float = DEFAULT_FRAME_PERIOD_US,
    pattern_contrast_b: float = 0.0,
    subtract_dark: bool = True,
    projector_rows: int | None = None,
) -> DirectGlobalResult:
    """Nayar et al. direct/global separation with a conventional projector-camera.

    Projects :func:`stripe_patterns` (one full-frame, unsynchronized capture
    each), subtracts a dark frame (projector off, same exposure: the ambient light
    a full-frame exposure collects would otherwise count as global light),
    converts to transport units and applies :func:`separate_direct_global`.

    Parameters
    ----------
    device : PatternDevice
        E.g. :class:`planeray.devices.simulated.SimulatedEpiscan`.
    period_rows : int, optional
        Stripe period in projector rows; default :func:`default_period_rows`.
    n_shifts : int, optional
        Shifted patterns per period; default ``period_rows`` (one-row steps).
    exposure_us, frame_period_us : float
        Exposure of each capture and the projector's frame period; the capture
        collects ``exposure_us / frame_period_us`` passes of the pattern.
    pattern_contrast_b : float
        Projector black level ``b``: the dark stripes are projected at ``b`` and the
        separation corrects for it (a real projector's ``b`` is not a choice; the
        simulated one emits exactly what it is given).
    subtract_dark : bool
        Capture and subtract a dark frame (counted in ``n_captures``).
    projector_rows : int, optional
        For devices that do not report it.

    Returns
    -------
    DirectGlobalResult

    See Also
    --------
    compare_direct_global : against the synchronized epipolar image.

    References
    ----------
    .. [1] Nayar et al., "Fast separation of direct and global components of a
       scene using high frequency illumination", SIGGRAPH 2006.

    Examples
    --------
    >>> from planeray.devices import simulated_device
    >>> device = simulated_device("corner", (16, 16), seed=0)
    >>> result = capture_direct_global(device)
    >>> result.direct.shape, result.global_.shape
    ((16, 16), (16, 16))
    """
    geometry = device_geometry(device, projector_rows)
    period = default_period_rows(geometry) if period_rows is None else int(period_rows)
    patterns = stripe_patterns(geometry.projector_rows, period_rows=period, n_shifts=n_shifts, low=pattern_contrast_b)
    captures, saturated = [], None
    for pattern in patterns:
        img, sat = capture(device, pattern, exposure_us, frame_period_us)
        captures.append(img)
        saturated = sat if saturated is None else saturated | sat
    dark = 0.0
    if subtract_dark:
        dark, sat = capture(device, np.zeros(geometry.projector_rows), exposure_us, frame_period_us)
        saturated |= sat
    images = to_transport_units(device, np.stack(captures), dark, exposure_us, frame_period_us)
    direct, global_ = separate_direct_global(images, pattern_contrast_b=pattern_contrast_b)
    return DirectGlobalResult(
        direct.astype(np.float32),
        global_.astype(np.float32),
        images.astype(np.float32),
        patterns,
        saturated,
        len(patterns) + int(subtract_dark),
        period,
        len(patterns),
        float(pattern_contrast_b),
    )
