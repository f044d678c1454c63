"""Conventional (unsynchronized) projector-camera baselines the paper compares against (Secs. 2, 5.1).

Two things an ordinary projector-camera can do without the synchronized
rolling shutter, both driving any device with
``capture_pattern(pattern, exposure_us, frame_period_us)`` (a full-frame
exposure under a per-projector-row pattern, e.g.
:meth:`planeray.devices.simulated.SimulatedEpiscan.capture_pattern`):

* **Direct/global separation with high-frequency patterns** (Nayar et al.
  2006, the baseline of Sec. 2).  Our transport is plane-to-ray: a pattern is
  one intensity per projector *row*, so the "high-frequency pattern" is a set of
  horizontal stripes, shifted over one period.  Per pixel, ``L+ = max`` and
  ``L- = min`` over the shifted captures give ``direct = L+ - L-`` and
  ``global = 2 L-`` (with the correction for a projector whose dark rows still
  emit a fraction ``b``).  It assumes the global light of a pixel varies smoothly
  over the stripe period -- true for diffuse interreflections and broad
  subsurface scattering, false for specular interreflections, which bring a
  sharp image of far projector rows that the stripes switch on and off.
  Epipolar imaging [3]_ has no such assumption: it keeps only the light of a
  band around the camera row's own epipolar plane.

* **Digital epipolar (delay) imaging** (Sec. 5.1, Fig. 4): project a horizontal
  band of width ``I_w = v_p t_e`` centred ``I_d = v_p t_d`` rows from camera row
  ``t``, keep camera row ``t`` of that capture, move the band one row and repeat;
  the kept rows form the delay image that the synchronized device captures in one
  exposure.  It needs one capture per camera row (``H`` captures, plus a dark
  frame) instead of one.

Conventions
-----------
Images returned here are in **transport units** (Eq. 4 units, the units of
``Scene.direct`` and ``Transport.render``): the normalized camera image minus a
dark frame (projector off, same exposure), divided by the number of projector
passes in the exposure (``exposure_us / frame_period_us``) and by the camera's
``signal_scale`` (normalized value per unit of Eq. 4).

Geometry of the stripes
-----------------------
A camera row spans ``f = P / H`` projector rows (5.625 for 128 camera rows of a
720-row projector).  Seen through the transport's offset bins its direct light
comes from projector coordinates within ``p_t +- (ceil(f)/2 + 1)``, i.e. up to
``ceil(f) + 2`` projector rows.  ``max - min`` recovers the direct light only if
some shift lights all of them and another darkens all of them, so each half
period must be at least that wide: :func:`default_period_rows` gives
``2 (ceil(f) + 2)`` rows -- 6 rows when ``P = H``, 16 rows (2.8 camera rows)
for ``P = 720, H = 128`` -- shifted one projector row at a time (``n_shifts =
period``).  Shorter periods mix direct light into ``L-``; longer ones weaken the
smoothness assumption on the global light.

References
----------
.. [1] S. K. Nayar, G. Krishnan, M. D. Grossberg, R. Raskar, "Fast separation of
   direct and global components of a scene using high frequency illumination",
   ACM Trans. Graph. 25(3) (SIGGRAPH 2006), 935-944.
.. [2] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa,
   S. G. Narasimhan, "Programmable Non-Epipolar Indirect Light Transport:
   Capture and Analysis", IEEE TVCG 2019, Sec. 2 and Sec. 5.1 (Fig. 4).
.. [3] M. O'Toole, S. Achar, S. G. Narasimhan, K. N. Kutulakos, "Homogeneous
   codes for energy-efficient illumination and imaging", SIGGRAPH 2015 (Episcan3D,
   synchronized epipolar imaging).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from .timing import RowGeometry, band_bin_weights, band_centre_rows, band_width_rows

__all__ = [
    "PatternDevice",
    "DEFAULT_FRAME_PERIOD_US",
    "default_period_rows",
    "stripe_patterns",
    "separate_direct_global",
    "DirectGlobalResult",
    "capture_direct_global",
    "band_pattern",
    "EmulationResult",
    "emulate_delay_image",
    "synchronized_delay_image",
    "deliverable_direct",
    "compare_direct_global",
    "compare_emulation",
]

#: Frame period of a conventional 60 Hz projector: one pass over all rows.
DEFAULT_FRAME_PERIOD_US = 1e6 / 60.0


@runtime_checkable
class PatternDevice(Protocol):
    """A projector-camera that can project a row pattern for a full-frame exposure."""

    def capture_pattern(self, pattern, exposure_us: float, frame_period_us: float = DEFAULT_FRAME_PERIOD_US):
        """Return ``(normalized image (H, W), saturation mask (H, W))``."""


# ----------------------------------------------------------------------------
# Device helpers
# ----------------------------------------------------------------------------
def _geometry(device, projector_rows=None, camera_rows=None) -> RowGeometry:
    """Camera/projector rows of a device (a simulated device knows them from its scene)."""
    scene = getattr(device, "scene", None)
    if scene is not None:
        g = scene.geometry
        return RowGeometry(int(camera_rows or g.camera_rows), int(projector_rows or g.projector_rows))
    info = device.describe() if hasattr(device, "describe") else {}
    H = camera_rows or (info.get("image_shape") or [None])[0]
    P = projector_rows or info.get("projector_rows")
    if H is None:
        raise ValueError("the device does not report its image size: give camera_rows")
    return RowGeometry(int(H), int(P) if P else None)


def _signal_scale(device) -> float:
    """Normalized image value per unit of Eq. 4 for one projector pass."""
    camera = getattr(device, "camera", None)
    if camera is not None and hasattr(camera, "signal_scale"):
        return float(camera.signal_scale)
    info = device.describe() if hasattr(device, "describe") else {}
    return float(info.get("signal_scale", 1.0))


def _capture(device, pattern, exposure_us, frame_period_us):
    image, saturated = device.capture_pattern(np.asarray(pattern, np.float64), exposure_us, frame_period_us)
    return np.asarray(image, np.float64), np.asarray(saturated, bool)


def _to_transport_units(device, images, dark, exposure_us, frame_period_us):
    passes = float(exposure_us) / float(frame_period_us)
    return (images - dark) / (passes * _signal_scale(device))


# ----------------------------------------------------------------------------
# Nayar et al. 2006: direct/global separation with shifted stripes
# ----------------------------------------------------------------------------
def default_period_rows(geometry: RowGeometry) -> int:
    """Default stripe period (projector rows): ``2 (ceil(P / H) + 2)``.

    Each half period then covers every projector row that can reach one camera
    row's direct light through the transport's offset bins (``ceil(P/H) + 2``
    rows; see the module notes), so one of the shifts lights a row's whole
    footprint and another darkens it.  6 rows for ``P = H``, 16 rows for 128
    camera rows of a 720-row projector.
    """
    return int(2 * (np.ceil(geometry.rows_per_camera_row - 1e-9) + 2))


def stripe_patterns(projector_rows: int, period_rows: int = 16, n_shifts: int | None = None, low: float = 0.0) -> np.ndarray:
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

    References
    ----------
    .. [1] Nayar et al., "Fast separation of direct and global components of a
       scene using high frequency illumination", SIGGRAPH 2006.
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


def separate_direct_global(images, pattern_contrast_b: float = 0.0):
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

    References
    ----------
    .. [1] S. K. Nayar, G. Krishnan, M. D. Grossberg, R. Raskar, "Fast separation
       of direct and global components of a scene using high frequency
       illumination", SIGGRAPH 2006, Sec. 3.
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

    References
    ----------
    .. [1] Nayar et al., "Fast separation of direct and global components of a
       scene using high frequency illumination", SIGGRAPH 2006.
    """
    geometry = _geometry(device, projector_rows)
    period = default_period_rows(geometry) if period_rows is None else int(period_rows)
    patterns = stripe_patterns(geometry.projector_rows, period, n_shifts, pattern_contrast_b)
    captures, saturated = [], None
    for pattern in patterns:
        img, sat = _capture(device, pattern, exposure_us, frame_period_us)
        captures.append(img)
        saturated = sat if saturated is None else saturated | sat
    dark = 0.0
    if subtract_dark:
        dark, sat = _capture(device, np.zeros(geometry.projector_rows), exposure_us, frame_period_us)
        saturated |= sat
    images = _to_transport_units(device, np.stack(captures), dark, exposure_us, frame_period_us)
    direct, global_ = separate_direct_global(images, pattern_contrast_b)
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


# ----------------------------------------------------------------------------
# Sec. 5.1 / Fig. 4: digital emulation of a delay image
# ----------------------------------------------------------------------------
def band_pattern(geometry: RowGeometry, camera_rows, delay_us: float, exposure_us: float, lines_per_second: float) -> np.ndarray:
    """Projector-row pattern of the bands that emulate (delay, exposure) for some camera rows.

    For each camera row ``t`` the band ``[p_t + I_d - I_w/2, p_t + I_d + I_w/2]``
    (Eq. 2: ``I_d = v_p t_d``, ``I_w = v_p t_e``) is drawn on the projector's
    rows, each row receiving the fraction of it the band covers (the band's
    exact discretization, Eq. 3, on projector rows; off-projector parts are lost,
    as on the synchronized device).  The bands of several rows are added; they
    must not overlap.

    Returns
    -------
    pattern : ndarray (P,) float64, values in [0, 1]
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

    References
    ----------
    .. [1] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport",
       TVCG 2019, Sec. 5.1 and Fig. 4.
    """
    if exposure_us <= 0 or capture_exposure_us <= 0:
        raise ValueError("exposures must be positive")
    geometry = _geometry(device, projector_rows)
    v_p = float(lines_per_second if lines_per_second is not None else device.lines_per_second)
    H = geometry.camera_rows
    S = H if spacing_rows is None else int(spacing_rows)
    if not 1 <= S <= H:
        raise ValueError(f"spacing_rows must be in [1, {H}], got {spacing_rows}")
    rows_of = [np.arange(k, H, S) for k in range(min(S, H))]
    image = saturated = None
    for rows in rows_of:
        pattern = band_pattern(geometry, rows, delay_us, exposure_us, v_p)
        img, sat = _capture(device, pattern, capture_exposure_us, frame_period_us)
        if image is None:
            image, saturated = np.empty_like(img), np.zeros(img.shape, bool)
        image[rows] = img[rows]
        saturated[rows] = sat[rows]
    dark = 0.0
    if subtract_dark:
        dark, sat = _capture(device, np.zeros(geometry.projector_rows), capture_exposure_us, frame_period_us)
        saturated |= sat
    image = _to_transport_units(device, image, dark, capture_exposure_us, frame_period_us)
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


# ----------------------------------------------------------------------------
# Synchronized counterpart and comparisons (what `planeray separate` / `emulate` report)
# ----------------------------------------------------------------------------
def synchronized_delay_image(device, delay_us: float, exposure_us: float, subtract_dark: bool = True):
    """One synchronized capture at (delay, exposure), in transport units.

    Sets the device, grabs, restores the previous settings, and removes the
    ambient light the rows collected during ``t_e`` with a dark frame of the
    same exposure (projector off: ``capture_pattern`` of zeros), so that it is
    comparable with :func:`emulate_delay_image` and with ``Transport.render``.

    Returns
    -------
    image : ndarray (H, W) float32
    saturated : ndarray (H, W) bool
    n_captures : int
        1, or 2 with the dark frame.
    """
    previous = (getattr(device, "delay_us", None), getattr(device, "exposure_us", None))
    device.set_delay(float(delay_us))
    device.set_exposure(float(exposure_us))
    try:
        image, saturated = device.grab()
    finally:
        if previous[0] is not None:
            device.set_delay(previous[0])
        if previous[1] is not None:
            device.set_exposure(previous[1])
    image = np.asarray(image, np.float64)
    saturated = np.asarray(saturated, bool)
    dark = 0.0
    if subtract_dark:
        geometry = _geometry(device)
        dark, sat = _capture(device, np.zeros(geometry.projector_rows), exposure_us, DEFAULT_FRAME_PERIOD_US)
        saturated = saturated | sat
    image = (image - dark) / _signal_scale(device)
    return image.astype(np.float32), saturated, 1 + int(subtract_dark)


def deliverable_direct(scene) -> np.ndarray:
    """Ground-truth direct light a projector can actually deliver to each pixel.

    ``Scene.direct`` spread over the camera row's footprint, keeping only the
    part of the footprint that lies on the projector (rows at the very top and
    bottom of a ``P != H`` image lose a few percent).  Equal to ``Scene.direct``
    everywhere else.
    """
    g = scene.geometry
    half = int(np.ceil(0.5 * g.rows_per_camera_row + 1.0))
    offsets = np.arange(-half, half + 1)
    foot = band_bin_weights(offsets, 0.0, g.rows_per_camera_row)
    foot = foot / foot.sum()
    inside = (foot[None, :] * g.coverage(np.arange(g.camera_rows)[:, None], offsets[None, :])).sum(axis=1)
    return (np.asarray(scene.direct, np.float64) * inside[:, None]).astype(np.float32)


def _errors(estimate, truth, masks: dict, reference=None, valid=None) -> dict:
    """Error statistics of ``estimate - truth`` per region.

    ``relative_rmse`` is the RMSE over the region's mean of ``reference`` (default
    ``|truth|``): with the full-illumination image as reference it stays meaningful
    where the truth itself is ~0 (e.g. the global light of a diffuse plane).
    Pixels outside ``valid`` (saturated ones) are left out.
    """
    err = np.asarray(estimate, np.float64) - np.asarray(truth, np.float64)
    ref = np.abs(np.asarray(truth if reference is None else reference, np.float64))
    out = {}
    for name, m in masks.items():
        if valid is not None:
            m = m & valid
        if not np.any(m):
            continue
        e = err[m]
        rmse = float(np.sqrt(np.mean(e * e)))
        scale = float(ref[m].mean())
        out[name] = {
            "pixels": int(m.sum()),
            "mae": float(np.abs(e).mean()),
            "median_abs": float(np.median(np.abs(e))),
            "rmse": rmse,
            "bias": float(e.mean()),
            "relative_rmse": rmse / scale if scale > 0 else None,
        }
    return out


def _label_masks(scene) -> dict:
    from .scenes import EFFECTS

    masks = {"all": np.ones(scene.shape, bool)}
    for label in np.unique(scene.labels):
        if label != 0:
            masks[EFFECTS[int(label)]] = scene.labels == label
    return masks


def compare_direct_global(
    device,
    epipolar_exposure_us: float = 600.0,
    period_rows: int | None = None,
    n_shifts: int | None = None,
    capture_exposure_us: float = DEFAULT_FRAME_PERIOD_US,
    frame_period_us: float = DEFAULT_FRAME_PERIOD_US,
    pattern_contrast_b: float = 0.0,
) -> dict:
    """Nayar direct/global separation against synchronized epipolar imaging (Secs. 2, 5.1).

    Runs :func:`capture_direct_global` and one synchronized epipolar capture
    (:func:`synchronized_delay_image` at delay 0, ``epipolar_exposure_us``) on
    the same device.  When the device has a ground-truth scene, errors are
    measured against :func:`deliverable_direct` and the global light under full
    illumination, over all pixels and per effect label, leaving out saturated
    pixels; ``relative_rmse`` is relative to the region's mean brightness under
    full illumination.

    A conventional capture integrates ambient light over the whole frame
    (16.7 ms): with the simulated camera's default room light (0.5 e-/us) bright
    pixels saturate and are reported, not separated -- the ambient-light
    advantage of synchronized imaging (Sec. 10).  Use a dim room
    (``CameraModel(ambient_e_per_us=0.01)``) for a fair comparison of the
    separations themselves.

    Returns
    -------
    dict
        ``nayar`` (:class:`DirectGlobalResult`), ``epipolar`` (image), ``truth_direct``
        and ``truth_global`` (or None), and ``numbers``: a JSON-serializable dict with
        capture counts, settings and ``errors`` -> ``nayar_direct`` / ``nayar_global`` /
        ``epipolar_direct`` -> region -> ``mae, median_abs, rmse, bias, relative_rmse``.
    """
    nayar = capture_direct_global(
        device, period_rows, n_shifts, capture_exposure_us, frame_period_us, pattern_contrast_b
    )
    epipolar, sat, n_sync = synchronized_delay_image(device, 0.0, epipolar_exposure_us)
    numbers = {
        "n_captures": {"nayar": nayar.n_captures, "epipolar_synchronized": n_sync},
        "period_rows": nayar.period_rows,
        "n_shifts": nayar.n_shifts,
        "pattern_contrast_b": nayar.pattern_contrast_b,
        "epipolar_exposure_us": float(epipolar_exposure_us),
        "capture_exposure_us": float(capture_exposure_us),
        "saturated_pixels": {"nayar": int(nayar.saturated.sum()), "epipolar": int(sat.sum())},
    }
    out = {"nayar": nayar, "epipolar": epipolar, "truth_direct": None, "truth_global": None, "numbers": numbers}
    scene = getattr(device, "scene", None)
    if scene is not None:
        from .timing import RowPattern

        direct = deliverable_direct(scene)
        full = scene.transport.render(RowPattern(np.ones(scene.geometry.projector_rows)))
        global_ = full - direct
        masks = _label_masks(scene)
        numbers["errors"] = {
            "nayar_direct": _errors(nayar.direct, direct, masks, full, ~nayar.saturated),
            "nayar_global": _errors(nayar.global_, global_, masks, full, ~nayar.saturated),
            "epipolar_direct": _errors(epipolar, direct, masks, full, ~sat),
        }
        out["truth_direct"], out["truth_global"] = direct, global_
    return out


def compare_emulation(
    device,
    delay_us: float,
    exposure_us: float,
    capture_exposure_us: float = DEFAULT_FRAME_PERIOD_US,
    frame_period_us: float = DEFAULT_FRAME_PERIOD_US,
    spacing_rows: int | None = None,
) -> dict:
    """Digitally emulated delay image against the synchronized one (Sec. 5.1, Fig. 4).

    Returns
    -------
    dict
        ``emulated`` (:class:`EmulationResult`), ``synchronized`` (image),
        ``truth`` (noise-free ``Transport.render`` of the band, or None) and
        ``numbers``: capture counts (``emulated``: ``H`` + dark frame, or
        ``spacing_rows`` + 1; ``synchronized``: 1 + dark frame) and errors
        (``emulated_vs_truth``, ``synchronized_vs_truth``,
        ``emulated_vs_synchronized``: ``mae, median_abs, rmse, bias, relative_rmse``).
    """
    emulated = emulate_delay_image(device, delay_us, exposure_us, capture_exposure_us, frame_period_us, spacing_rows)
    sync, sat, n_sync = synchronized_delay_image(device, delay_us, exposure_us)
    masks = {"all": np.ones(sync.shape, bool)}
    numbers = {
        "delay_us": float(delay_us),
        "exposure_us": float(exposure_us),
        "capture_exposure_us": float(capture_exposure_us),
        "n_captures": {"emulated": emulated.n_captures, "synchronized": n_sync},
        "rows_per_capture": emulated.rows_per_capture,
        "saturated_pixels": {"emulated": int(emulated.saturated.sum()), "synchronized": int(sat.sum())},
        "errors": {"emulated_vs_synchronized": _errors(emulated.image, sync, masks, valid=~(sat | emulated.saturated)).get("all")},
    }
    out = {"emulated": emulated, "synchronized": sync, "truth": None, "numbers": numbers}
    scene = getattr(device, "scene", None)
    if scene is not None:
        from .timing import Band

        truth = scene.transport.render(Band(float(delay_us), float(exposure_us), float(device.lines_per_second)))
        numbers["errors"]["emulated_vs_truth"] = _errors(emulated.image, truth, masks, valid=~emulated.saturated).get("all")
        numbers["errors"]["synchronized_vs_truth"] = _errors(sync, truth, masks, valid=~sat).get("all")
        out["truth"] = truth
    return out
