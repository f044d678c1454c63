"""The synchronized counterparts and the comparisons against ground truth that ``planeray separate`` and ``planeray emulate`` report."""

from __future__ import annotations

import numpy as np

from .._validate import check_number, check_positive
from ._device import DEFAULT_FRAME_PERIOD_US, capture, device_geometry, signal_scale
from .emulation import emulate_delay_image
from .nayar import capture_direct_global


def synchronized_delay_image(device, delay_us: float, exposure_us: float, *, subtract_dark: bool = True):
    """One synchronized capture at (delay, exposure), in transport units.

    Sets the device, grabs, restores the previous settings, and removes the
    ambient light the rows collected during ``t_e`` with a dark frame of the
    same exposure (projector off: ``capture_pattern`` of zeros), so that it is
    comparable with :func:`emulate_delay_image` and with ``Transport.render``.

    Parameters
    ----------
    device : PatternDevice
        A projector-camera (the simulated Episcan is one, :func:`planeray.devices.simulated_device`).
    delay_us, exposure_us : float
        The setting, microseconds.
    subtract_dark : bool
        Subtract a dark frame (ambient light) at the same exposure.

    Returns
    -------
    image : ndarray (H, W) float32
    saturated : ndarray (H, W) bool
    n_captures : int
        1, or 2 with the dark frame.

    See Also
    --------
    emulate_delay_image : the same without synchronization.

    Examples
    --------
    >>> from planeray.devices import simulated_device
    >>> device = simulated_device("corner", (16, 16), seed=0)
    >>> image, saturated, n_captures = synchronized_delay_image(device, 0.0, 200.0)
    >>> image.shape, n_captures
    ((16, 16), 2)
    """
    check_number(delay_us, "delay_us")
    check_positive(exposure_us, "exposure_us")
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
        geometry = device_geometry(device)
        dark, sat = capture(device, np.zeros(geometry.projector_rows), exposure_us, DEFAULT_FRAME_PERIOD_US)
        saturated = saturated | sat
    image = (image - dark) / signal_scale(device)
    return image.astype(np.float32), saturated, 1 + int(subtract_dark)


def deliverable_direct(scene) -> np.ndarray:
    """Ground-truth direct light a projector can actually deliver to each pixel.

    A camera row's footprint ``p_t +- P / (2 H)`` always lies on the projector
    (``[-1/2, P - 1/2)``), and by the edge rule (:meth:`planeray.timing.RowGeometry.bin_parts`)
    a bin straddling the projector's end holds only light from its part on the
    projector, so all of ``Scene.direct`` is deliverable, top and bottom rows included.

    Parameters
    ----------
    scene : Scene
        A scene with ground truth.

    Returns
    -------
    ndarray (H, W)
        In transport units.

    See Also
    --------
    compare_direct_global : scores against it.

    Examples
    --------
    >>> import planeray as pr
    >>> deliverable_direct(pr.make_scene("corner", (16, 16), seed=0)).shape
    (16, 16)
    """
    return np.asarray(scene.direct, np.float32).copy()


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


def compare_direct_global(
    device,
    *,
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
    the same device.  When the device has a ground-truth scene (``device.scene``), errors are
    measured against :func:`deliverable_direct` and the global light under full
    illumination, over all pixels and per effect label (the scene's ``effect_masks()``), leaving out saturated
    pixels; ``relative_rmse`` is relative to the region's mean brightness under
    full illumination.

    A conventional capture integrates ambient light over the whole frame
    (16.7 ms): with the simulated camera's default room light (0.5 e-/us) bright
    pixels saturate and are reported, not separated -- the ambient-light
    advantage of synchronized imaging (Sec. 10).  Use a dim room
    (``CameraModel(ambient_e_per_us=0.01)``) for a fair comparison of the
    separations themselves.

    Parameters
    ----------
    device : PatternDevice
        A projector-camera (the simulated Episcan is one, :func:`planeray.devices.simulated_device`).
    epipolar_exposure_us : float
        Exposure of the synchronized epipolar capture, microseconds.
    period_rows, n_shifts : int, optional
        The stripes (default :func:`default_period_rows`).
    capture_exposure_us, frame_period_us : float
        The conventional captures' exposure and frame period, microseconds.
    pattern_contrast_b : float
        Nayar's ``b``: the dark stripes' fraction of the lit ones.

    Returns
    -------
    dict
        ``nayar`` (:class:`DirectGlobalResult`), ``epipolar`` (image), ``truth_direct``
        and ``truth_global`` (or None), and ``numbers``: a JSON-serializable dict with
        capture counts, settings and ``errors`` -> ``nayar_direct`` / ``nayar_global`` /
        ``epipolar_direct`` -> region -> ``mae, median_abs, rmse, bias, relative_rmse``.

    See Also
    --------
    capture_direct_global : the separation.
    synchronized_delay_image : the epipolar capture.

    References
    ----------
    .. [1] S. K. Nayar, G. Krishnan, M. D. Grossberg, R. Raskar, "Fast separation of direct and global
       components of a scene using high frequency illumination", ACM SIGGRAPH 2006.

    Examples
    --------
    >>> from planeray.devices import simulated_device
    >>> device = simulated_device("corner", (16, 16), seed=0)
    >>> out = compare_direct_global(device, epipolar_exposure_us=200.0)
    >>> out["numbers"]["n_captures"]
    {'nayar': 7, 'epipolar_synchronized': 2}
    """
    nayar = capture_direct_global(
        device,
        period_rows=period_rows,
        n_shifts=n_shifts,
        exposure_us=capture_exposure_us,
        frame_period_us=frame_period_us,
        pattern_contrast_b=pattern_contrast_b,
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
        from ..timing import RowPattern

        direct = deliverable_direct(scene)
        full = scene.transport.render(RowPattern(np.ones(scene.geometry.projector_rows)))
        global_ = full - direct
        masks = scene.effect_masks()
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
    *,
    capture_exposure_us: float = DEFAULT_FRAME_PERIOD_US,
    frame_period_us: float = DEFAULT_FRAME_PERIOD_US,
    spacing_rows: int | None = None,
) -> dict:
    """Digitally emulated delay image against the synchronized one (Sec. 5.1, Fig. 4).

    Parameters
    ----------
    device : PatternDevice
        A projector-camera (the simulated Episcan is one, :func:`planeray.devices.simulated_device`).
    delay_us, exposure_us : float
        The setting, microseconds.
    capture_exposure_us, frame_period_us : float
        The conventional captures' exposure and frame period, microseconds.
    spacing_rows : int, optional
        Camera rows between the bands of one capture.

    Returns
    -------
    dict
        ``emulated`` (:class:`EmulationResult`), ``synchronized`` (image),
        ``truth`` (noise-free ``Transport.render`` of the band, or None) and
        ``numbers``: capture counts (``emulated``: ``H`` + dark frame, or
        ``spacing_rows`` + 1; ``synchronized``: 1 + dark frame) and errors
        (``emulated_vs_truth``, ``synchronized_vs_truth``,
        ``emulated_vs_synchronized``: ``mae, median_abs, rmse, bias, relative_rmse``).

    See Also
    --------
    emulate_delay_image, synchronized_delay_image : the two images.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 5.1, Fig. 4.

    Examples
    --------
    >>> from planeray.devices import simulated_device
    >>> device = simulated_device("corner", (16, 16), seed=0)
    >>> out = compare_emulation(device, 0.0, 200.0)
    >>> out["numbers"]["n_captures"]
    {'emulated': 17, 'synchronized': 2}
    """
    emulated = emulate_delay_image(
        device,
        delay_us,
        exposure_us,
        capture_exposure_us=capture_exposure_us,
        frame_period_us=frame_period_us,
        spacing_rows=spacing_rows,
    )
    sync, sat, n_sync = synchronized_delay_image(device, delay_us, exposure_us)
    masks = {"all": np.ones(sync.shape, bool)}
    numbers = {
        "delay_us": float(delay_us),
        "exposure_us": float(exposure_us),
        "capture_exposure_us": float(capture_exposure_us),
        "n_captures": {"emulated": emulated.n_captures, "synchronized": n_sync},
        "rows_per_capture": emulated.rows_per_capture,
        "saturated_pixels": {"emulated": int(emulated.saturated.sum()), "synchronized": int(sat.sum())},
        "errors": {
            "emulated_vs_synchronized": _errors(emulated.image, sync, masks, valid=~(sat | emulated.saturated)).get(
                "all"
            )
        },
    }
    out = {"emulated": emulated, "synchronized": sync, "truth": None, "numbers": numbers}
    scene = getattr(device, "scene", None)
    if scene is not None:
        from ..timing import Band

        truth = scene.transport.render(Band(float(delay_us), float(exposure_us), float(device.lines_per_second)))
        numbers["errors"]["emulated_vs_truth"] = _errors(emulated.image, truth, masks, valid=~emulated.saturated).get(
            "all"
        )
        numbers["errors"]["synchronized_vs_truth"] = _errors(sync, truth, masks, valid=~sat).get("all")
        out["truth"] = truth
    return out
