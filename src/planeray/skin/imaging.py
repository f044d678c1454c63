"""The vein-imaging methods compared in Sec. 10 (Figs. 13, 16), from a transport, the simulated device or a stack.

Methods (keys of :data:`METHODS`):

``delay``
    The **short-range indirect delay image** (the paper: ``t_d`` = 400-600 us at about
    0.5 m): one synchronized capture whose band lights projector rows ``u`` in
    ``v_p (t_d -+ t_e / 2)`` (Eq. 2) -- light that entered the skin that far from the pixel's
    own epipolar plane and came back out under it, after travelling under the surface.
    :func:`delay_band_mm` gives the band in millimetres on the skin.
``photo``
    A regular photo: every projector row lit, one unsynchronized 16.7 ms frame, ambient light
    included (no dark frame), exposure reduced (as an aperture or ND filter would, equally
    for laser and ambient light) when the brightest pixel would exceed 70 % of the full well.
``direct``
    The epipolar image (Eq. 5): a synchronized capture at ``t_d = 0`` with an exposure that
    covers one camera row's footprint (``direct_exposure_us``).
``global``
    Nayar et al.'s global image (:func:`planeray.baselines.nayar.capture_direct_global`), with
    the photo's exposure reduction against saturation and a dark frame.
``non_epipolar``
    Eq. 6: the dark-subtracted photo minus the epipolar image (all light from other planes).
``flood``
    Flood-illumination reflectance at the scene's wavelength (638 nm red or 850 nm NIR) with
    the contrast stretch of a commercial vein viewer (AccuVein-like): the photo through
    CLAHE (:func:`contrast_stretch`).

From a scene's transport (:func:`truth_images`) every method is noise-free and free of
ambient light; from the simulated device (:func:`device_images`) every capture goes through
the camera model (shot and read noise, ambient light, saturation, 12 bits, 8 frames).  From a
captured stack (:func:`stack_images`) only what a delay-exposure sweep holds: the delay image
and the epipolar image.

References
----------
.. [1] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport: Capture and
   Analysis", IEEE TVCG 2019, Sec. 10, Figs. 13, 16.
.. [2] S. K. Nayar et al., "Fast separation of direct and global components of a scene using
   high frequency illumination", SIGGRAPH 2006.
.. [3] K. Zuiderveld, "Contrast limited adaptive histogram equalization", Graphics Gems IV, 1994.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InputError
from ..scenes.base import DEFAULT_MM_PER_ROW
from ..timing import PAPER_LINES_PER_SECOND, band_centre_rows, band_width_rows

__all__ = [
    "METHODS",
    "DEFAULT_DELAY_US",
    "DEFAULT_EXPOSURE_US",
    "delay_band_rows",
    "delay_band_mm",
    "delay_for_offset_mm",
    "mm_per_row",
    "direct_exposure_us",
    "contrast_stretch",
    "truth_images",
    "device_images",
    "stack_images",
    "delay_sweep_images",
]

#: Method key -> label for tables and figures (the order of the panels).
METHODS = {
    "photo": "photo (full illumination)",
    "flood": "flood + stretch (vein viewer)",
    "direct": "direct (epipolar)",
    "global": "global (Nayar)",
    "non_epipolar": "non-epipolar",
    "delay": "short-range indirect (delay)",
}
#: The paper's delay for veins (400-600 us) and the exposure of its sweeps' shortest images.
DEFAULT_DELAY_US = 500.0
DEFAULT_EXPOSURE_US = 600.0
#: Largest expected signal of an auto-exposed photo, as a fraction of the full well.
PHOTO_FILL = 0.7
FRAME_PERIOD_US = 1e6 / 60.0


def delay_band_rows(delay_us, exposure_us, *, lines_per_second=PAPER_LINES_PER_SECOND):
    """Offsets ``(near, far)`` of a delay image's band in projector rows: ``v_p (t_d -+ t_e/2)`` (Eq. 2).

    >>> [round(float(x), 1) for x in delay_band_rows(500.0, 600.0)]
    [10.8, 43.2]
    """
    c = band_centre_rows(delay_us, lines_per_second)
    w = band_width_rows(exposure_us, lines_per_second)
    return c - 0.5 * w, c + 0.5 * w


def mm_per_row(scene_or_params) -> float:
    """Millimetres on the surface per projector row (``params["mm_per_row"]``, default 0.3 mm)."""
    params = getattr(scene_or_params, "params", scene_or_params) or {}
    return float(params.get("mm_per_row", DEFAULT_MM_PER_ROW))


def delay_band_mm(delay_us, exposure_us, *, lines_per_second=PAPER_LINES_PER_SECOND, mm_per_row=DEFAULT_MM_PER_ROW):
    """Distances ``(near, far)`` on the skin between where light enters and the pixel, in mm.

    At the paper's 54,000 lines/s and the simulator's 0.3 mm per row, ``t_d = 500 us`` with
    ``t_e = 600 us`` collects light that entered 3.2-13.0 mm away:

    >>> [round(float(x), 1) for x in delay_band_mm(500.0, 600.0)]
    [3.2, 13.0]
    """
    near, far = delay_band_rows(delay_us, exposure_us, lines_per_second=lines_per_second)
    return near * mm_per_row, far * mm_per_row


def delay_for_offset_mm(offset_mm, *, lines_per_second=PAPER_LINES_PER_SECOND, mm_per_row=DEFAULT_MM_PER_ROW):
    """Delay (us) whose band is centred ``offset_mm`` from the pixel (inverse of Eq. 2).

    >>> round(delay_for_offset_mm(8.1), 1)
    500.0
    """
    return float(offset_mm) / float(mm_per_row) / float(lines_per_second) * 1e6


def direct_exposure_us(geometry, *, lines_per_second=PAPER_LINES_PER_SECOND) -> float:
    """Exposure of the epipolar image: one camera row's footprint plus one projector row.

    >>> from planeray.timing import RowGeometry
    >>> round(direct_exposure_us(RowGeometry(128, 720)), 1)
    122.7
    """
    return (geometry.rows_per_camera_row + 1.0) / float(lines_per_second) * 1e6


def contrast_stretch(image, *, clip_limit: float = 2.0, tiles: int = 8) -> np.ndarray:
    """A vein viewer's contrast stretch: 0.5-99.5 % percentile scaling, then CLAHE (Zuiderveld 1994).

    OpenCV's ``createCLAHE`` on 16-bit codes, ``tiles x tiles`` tiles, clip limit ``clip_limit``
    (OpenCV's units: multiples of the mean histogram bin).  Returns values in [0, 1].
    """
    import cv2

    img = np.asarray(image, np.float64)
    lo, hi = np.percentile(img[np.isfinite(img)], [0.5, 99.5])
    scaled = np.clip((img - lo) / (hi - lo), 0.0, 1.0) if hi > lo else np.zeros_like(img)
    codes = np.nan_to_num(scaled * 65535.0 + 0.5).astype(np.uint16)
    clahe = cv2.createCLAHE(clipLimit=float(clip_limit), tileGridSize=(int(tiles), int(tiles)))
    return clahe.apply(codes).astype(np.float64) / 65535.0


def truth_images(
    scene,
    *,
    delay_us: float = DEFAULT_DELAY_US,
    exposure_us: float = DEFAULT_EXPOSURE_US,
    lines_per_second: float = PAPER_LINES_PER_SECOND,
    methods=None,
) -> dict:
    """Noise-free images of every method from a scene's ground-truth transport (no ambient light).

    ``photo`` is the full image, ``direct`` Eq. 5, ``non_epipolar`` Eq. 6, ``delay`` the band
    image (:func:`planeray.synthesis.band_image`), ``global`` Nayar's separation on the
    noise-free simulated device, ``flood`` the stretched photo.
    """
    from ..synthesis import band_image

    methods = tuple(METHODS) if methods is None else tuple(methods)
    T = scene.transport
    out = {}
    full = T.full_image().astype(np.float64)
    for m in methods:
        if m == "photo":
            out[m] = full
        elif m == "flood":
            out[m] = contrast_stretch(full)
        elif m == "direct":
            out[m] = T.epipolar_image().astype(np.float64)
        elif m == "non_epipolar":
            out[m] = T.non_epipolar_image().astype(np.float64)
        elif m == "delay":
            out[m] = band_image(T, delay_us, exposure_us, lines_per_second=lines_per_second).astype(np.float64)
        elif m == "global":
            from ..baselines.nayar import capture_direct_global
            from ..camera import CameraModel
            from ..devices.simulated import SimulatedEpiscan

            dev = SimulatedEpiscan(
                scene, CameraModel(ambient_e_per_us=0.0), lines_per_second=lines_per_second, noise=False
            )
            out[m] = capture_direct_global(dev).global_.astype(np.float64)
        else:
            raise ValueError(f"unknown method {m!r}; one of {', '.join(METHODS)}")
    return out


def _photo_camera(scene, camera, exposure_us):
    """The camera with laser and ambient light attenuated so the photo fills at most PHOTO_FILL of the well."""
    full = scene.transport.full_image().astype(np.float64)
    passes = exposure_us / FRAME_PERIOD_US
    peak = float(
        np.max(passes * camera.laser_electrons * full + camera.ambient_e_per_us * exposure_us * scene.ambient_albedo)
    )
    a = min(1.0, PHOTO_FILL * camera.full_well_e / peak) if peak > 0 else 1.0
    cam = dataclasses.replace(
        camera, laser_electrons=camera.laser_electrons * a, ambient_e_per_us=camera.ambient_e_per_us * a
    )
    return cam, a


def device_images(
    scene,
    camera=None,
    *,
    delay_us: float = DEFAULT_DELAY_US,
    exposure_us: float = DEFAULT_EXPOSURE_US,
    lines_per_second: float = PAPER_LINES_PER_SECOND,
    seed: int = 0,
    methods=None,
) -> tuple[dict, dict]:
    """Every method captured with the simulated Episcan (camera noise, ambient light, saturation).

    Parameters
    ----------
    scene : Scene
    camera : CameraModel, optional
        Its ``ambient_e_per_us`` sets the ambient light (see :mod:`planeray.skin.ambient`).
    delay_us, exposure_us : float
        The delay image's setting.
    seed : int
        Noise seed.
    methods : sequence of str, optional
        Subset of :data:`METHODS`.

    Returns
    -------
    images : dict of str to ndarray (H, W)
        Synchronized images and the global/non-epipolar images in transport units; the photo and
        flood images as the camera recorded them (normalized, ambient light included).
    info : dict
        Captures taken per method, the photo's attenuation, the direct exposure, saturated
        pixel counts.
    """
    from ..baselines.compare import synchronized_delay_image
    from ..baselines.nayar import capture_direct_global
    from ..camera import CameraModel
    from ..devices.simulated import SimulatedEpiscan

    camera = camera or CameraModel()
    methods = tuple(METHODS) if methods is None else tuple(methods)
    unknown = set(methods) - set(METHODS)
    if unknown:
        raise ValueError(f"unknown method {sorted(unknown)[0]!r}; one of {', '.join(METHODS)}")
    sync = SimulatedEpiscan(scene, camera, lines_per_second=lines_per_second, seed=seed)
    photo_cam, attenuation = _photo_camera(scene, camera, FRAME_PERIOD_US)
    conv = SimulatedEpiscan(scene, photo_cam, lines_per_second=lines_per_second, seed=seed)
    t_direct = direct_exposure_us(scene.geometry, lines_per_second=lines_per_second)
    images, info = {}, {"photo_attenuation": attenuation, "direct_exposure_us": t_direct, "captures": {}}
    info["saturated_pixels"] = {}
    P = scene.geometry.projector_rows
    need_photo = {"photo", "flood", "non_epipolar"} & set(methods)
    need_direct = {"direct", "non_epipolar"} & set(methods)
    if need_photo:
        photo, sat = conv.capture_pattern(np.ones(P), FRAME_PERIOD_US, frame_period_us=FRAME_PERIOD_US)
        photo = np.asarray(photo, np.float64)
        info["saturated_pixels"]["photo"] = int(np.sum(sat))
    if need_direct:
        direct, sat, n = synchronized_delay_image(sync, 0.0, t_direct)
        info["saturated_pixels"]["direct"] = int(np.sum(sat))
    for m in methods:
        if m == "photo":
            images[m], info["captures"][m] = photo, 1
        elif m == "flood":
            images[m], info["captures"][m] = contrast_stretch(photo), 1
        elif m == "direct":
            images[m], info["captures"][m] = np.asarray(direct, np.float64), n
        elif m == "delay":
            img, sat, k = synchronized_delay_image(sync, delay_us, exposure_us)
            images[m], info["captures"][m] = np.asarray(img, np.float64), k
            info["saturated_pixels"]["delay"] = int(np.sum(sat))
        elif m == "global":
            res = capture_direct_global(conv, frame_period_us=FRAME_PERIOD_US)
            images[m], info["captures"][m] = res.global_.astype(np.float64), res.n_captures
            info["saturated_pixels"]["global"] = int(np.sum(res.saturated))
        elif m == "non_epipolar":
            dark, _ = conv.capture_pattern(np.zeros(P), FRAME_PERIOD_US, frame_period_us=FRAME_PERIOD_US)
            full = (photo - np.asarray(dark, np.float64)) / photo_cam.signal_scale
            images[m], info["captures"][m] = full - direct, 2 + n
    return images, info


def stack_images(stack, *, delay_us: float = DEFAULT_DELAY_US, exposure_us: float | None = None) -> tuple[dict, dict]:
    """The delay image and the epipolar image of a captured (or simulated) stack.

    Picks, at ``exposure_us`` (default: the stack's shortest exposure), the image whose delay is
    nearest ``delay_us`` and the one nearest 0.  A delay farther than half the stack's delay
    step from any image is refused (one line naming the delays the stack has).

    Returns
    -------
    images : dict
        ``delay`` and, when the stack has a delay within its step of 0, ``direct`` (normalized).
    info : dict
        The delays, exposure and image indices used.
    """
    exp = np.asarray(stack.exposure_us, np.float64)
    dl = np.asarray(stack.delay_us, np.float64)
    t_e = float(exp.min()) if exposure_us is None else float(exposure_us)
    at = np.flatnonzero(np.isclose(exp, t_e, atol=0.5))
    if at.size == 0:
        raise InputError(f"the stack has no image at exposure {t_e:g} us (it has {sorted(set(exp.tolist()))})")
    delays = dl[at]
    uniq = np.unique(delays)
    step = float(np.min(np.diff(uniq))) if uniq.size > 1 else np.inf
    tol = 0.5 * step if np.isfinite(step) else 1.0

    def pick(target):
        j = int(np.argmin(np.abs(delays - target)))
        return (int(at[j]), float(delays[j])) if abs(delays[j] - target) <= tol + 1e-6 else (None, None)

    i, d = pick(float(delay_us))
    if i is None:
        raise InputError(
            f"the stack has no image near delay {delay_us:g} us at exposure {t_e:g} us "
            f"(delays {', '.join(f'{x:g}' for x in uniq)})"
        )
    images = {"delay": np.asarray(stack.images[i], np.float64)}
    info = {"exposure_us": t_e, "delay_us": d, "delay_index": i}
    j, d0 = pick(0.0)
    if j is not None:
        images["direct"] = np.asarray(stack.images[j], np.float64)
        info.update(direct_delay_us=d0, direct_index=j)
    return images, info


def delay_sweep_images(stack, *, exposure_us: float | None = None, min_delay_us: float = 0.0):
    """Delay images of one exposure with ``t_d > min_delay_us`` and the band off the epipolar plane.

    Returns ``(images (N, H, W), delays_us (N,))`` sorted by delay: the input of
    :func:`planeray.skin.enhance.enhance_contrast`.  Images whose band touches the epipolar
    plane (``|t_d| <= t_e / 2``) are left out.
    """
    exp = np.asarray(stack.exposure_us, np.float64)
    dl = np.asarray(stack.delay_us, np.float64)
    t_e = float(exp.min()) if exposure_us is None else float(exposure_us)
    sel = np.flatnonzero(np.isclose(exp, t_e, atol=0.5) & (dl > min_delay_us) & (np.abs(dl) > 0.5 * t_e))
    if sel.size < 2:
        raise InputError(
            f"the stack has {sel.size} non-epipolar delay images at exposure {t_e:g} us with delay > "
            f"{min_delay_us:g} us; contrast enhancement needs at least 2"
        )
    sel = sel[np.argsort(dl[sel])]
    return np.stack([np.asarray(stack.images[int(i)], np.float64) for i in sel]), dl[sel]
