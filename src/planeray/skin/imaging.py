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
captured stack (:func:`stack_images`) only what a delay-exposure sweep holds: the delay band
image and the ``t_d = 0`` band image (``+-t_e / 2`` around the epipolar plane: +-16 projector
rows at 600 us, far wider than the epipolar image), both named for their band
(:func:`band_name`, :func:`band_record`) and never an image the stack excludes; from a
transport store (:func:`transport_images`) the true epipolar image and any band image.

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

from .._extras import import_extra
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
    "recorded_mm_per_row",
    "pixel_mm",
    "band_name",
    "band_record",
    "epipolar_record",
    "direct_exposure_us",
    "contrast_stretch",
    "truth_images",
    "device_images",
    "stack_images",
    "transport_images",
    "delay_sweep_images",
    "delay_sweep_selection",
]

#: Method key -> label for tables and figures (the order of the panels).
METHODS = {
    "photo": "photo (full illumination)",
    "flood": "flood + stretch (vein viewer)",
    "direct": "direct (t_d = 0, t_e = one camera row + 1 row: epipolar)",
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
    cv2 = import_extra("cv2", "the vein viewer's contrast stretch (CLAHE)")

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


def band_name(delay_us: float, exposure_us: float) -> str:
    """Name of a band image that says its band: ``td{t_d}us_te{t_e}us``.

    >>> band_name(562.5, 600.0), band_name(0.0, 600.0)
    ('td562.5us_te600us', 'td0us_te600us')
    """
    return f"td{float(delay_us):g}us_te{float(exposure_us):g}us"


def _us(x: float) -> str:
    """A time in us for a label: at most one decimal (122.685 -> 122.7, 562.5, 600)."""
    return f"{float(x):.1f}".rstrip("0").rstrip(".")


def band_record(
    delay_us: float,
    exposure_us: float,
    *,
    lines_per_second: float = PAPER_LINES_PER_SECOND,
    mm_per_row: float = DEFAULT_MM_PER_ROW,
    geometry=None,
    source: str = "",
) -> dict:
    """What a band image is, for a result file: delay, exposure, its rows and mm, and a label.

    The band of ``(t_d, t_e)`` lights projector rows ``u`` in ``v_p (t_d -+ t_e / 2)`` from the
    pixel's own epipolar plane (Eq. 2).  A band that holds ``u = 0`` is labelled with its rows
    around the epipolar plane and, given the ``geometry``, how much wider it is than the
    epipolar image (the camera row's own footprint, :meth:`planeray.transport.Transport.epipolar_image`,
    Eq. 5): the ``t_d = 0``, ``t_e = 600 us`` band of a stack is +-16.2 rows, the epipolar image
    of a 128-row image of a 720-row projector +-2.8.

    >>> from planeray.timing import RowGeometry
    >>> band_record(0.0, 600.0, geometry=RowGeometry(128, 720))["label"]
    't_d = 0 band image (t_e = 600 us): rows -16.2 to +16.2 around the epipolar plane, 5.8x the epipolar image (+-2.8 rows)'
    >>> band_record(562.5, 600.0)["label"]
    't_d = 562.5 us band image (t_e = 600 us): light that entered +14.2 to +46.6 rows (4.3-14.0 mm) away'
    """
    near, far = delay_band_rows(delay_us, exposure_us, lines_per_second=lines_per_second)
    near, far = float(near), float(far)
    if near <= 0.0 <= far:
        label = (
            f"t_d = {_us(delay_us)}{' us' if delay_us else ''} band image (t_e = {_us(exposure_us)} us): rows {near:+.1f} "
            f"to {far:+.1f} around the epipolar plane"
        )
        if geometry is not None:
            half = 0.5 * float(geometry.rows_per_camera_row)
            label += f", {0.5 * (far - near) / half:.1f}x the epipolar image (+-{half:.1f} rows)"
    else:
        lo, hi = sorted((abs(near), abs(far)))
        label = (
            f"t_d = {_us(delay_us)} us band image (t_e = {_us(exposure_us)} us): light that entered {near:+.1f} to "
            f"{far:+.1f} rows ({lo * mm_per_row:.1f}-{hi * mm_per_row:.1f} mm) away"
        )
    return {
        "kind": "band",
        "label": label,
        "delay_us": float(delay_us),
        "exposure_us": float(exposure_us),
        "band_rows": [near, far],
        "band_mm": [near * float(mm_per_row), far * float(mm_per_row)],
        "source": source,
    }


def epipolar_record(geometry, *, mm_per_row: float = DEFAULT_MM_PER_ROW, source: str = "") -> dict:
    """What the epipolar image (Eq. 5) is: the camera row's own footprint, +-``P / 2H`` rows."""
    half = 0.5 * float(geometry.rows_per_camera_row)
    return {
        "kind": "epipolar",
        "label": f"epipolar image (Eq. 5): the camera row's own footprint, rows {-half:+.1f} to {half:+.1f}",
        "band_rows": [-half, half],
        "band_mm": [-half * float(mm_per_row), half * float(mm_per_row)],
        "source": source,
    }


def recorded_mm_per_row(metadata) -> float | None:
    """``mm_per_row`` a stack's metadata or a transport store's attributes record, or None
    (:func:`planeray.stack.recorded_mm_per_row`: the import folder's ``acquisition.json`` first)."""
    from ..stack import recorded_mm_per_row as _recorded

    return _recorded(metadata)[0]


def pixel_mm(geometry, mm_per_row: float = DEFAULT_MM_PER_ROW) -> float:
    """Size of a camera pixel on the skin, mm: ``rows_per_camera_row * mm_per_row`` (square pixels).

    >>> from planeray.timing import RowGeometry
    >>> pixel_mm(RowGeometry(128, 720), 0.3), pixel_mm(RowGeometry(64, 720), 0.3)
    (1.6875, 3.375)
    """
    return float(geometry.rows_per_camera_row) * float(mm_per_row)


def _usable(stack, include_excluded: bool) -> np.ndarray:
    return np.ones(len(stack), bool) if include_excluded else ~np.asarray(stack.excluded, bool)


def stack_images(
    stack,
    *,
    delay_us: float = DEFAULT_DELAY_US,
    exposure_us: float | None = None,
    include_excluded: bool = False,
    mm_per_row: float = DEFAULT_MM_PER_ROW,
) -> tuple[dict, dict]:
    """The delay band image of a captured (or simulated) stack and its ``t_d = 0`` band image.

    Picks, at ``exposure_us`` (default: the stack's shortest exposure), the image whose delay is
    nearest ``delay_us`` and the one nearest 0, among the images the stack does not exclude
    (its ``excluded`` flags: boundary images with row artefacts; ``include_excluded`` uses them
    too).  A delay farther than half the stack's delay step from any usable image is refused
    (one line naming the delays the stack has).  The ``t_d = 0`` image is a band of
    ``+-t_e / 2``, not the epipolar image (:func:`transport_images` gives that one).

    Returns
    -------
    images : dict of str to ndarray (H, W)
        Keyed by :func:`band_name` (``td562.5us_te600us``, ``td0us_te600us``): the delay image
        first, then the ``t_d = 0`` band image when the stack has one within its step of 0.
    info : dict
        ``requested_delay_us``, ``requested_exposure_us`` (None: the shortest), the
        ``delay_us`` and ``exposure_us`` that served them, ``delay_index``, ``delay_image``
        (its name) and ``images``: name -> :func:`band_record` (with the stack index).
    """
    exp = np.asarray(stack.exposure_us, np.float64)
    dl = np.asarray(stack.delay_us, np.float64)
    usable = _usable(stack, include_excluded)
    t_e = float(exp[usable].min() if usable.any() else exp.min()) if exposure_us is None else float(exposure_us)
    at_all = np.flatnonzero(np.isclose(exp, t_e, atol=0.5))
    if at_all.size == 0:
        raise InputError(
            f"exposure_us = {t_e:g}: the stack has no image at that exposure (it has "
            f"{', '.join(f'{x:g}' for x in sorted(set(exp.tolist())))} us)"
        )
    at = at_all[usable[at_all]]
    uniq = np.unique(dl[at_all])
    step = float(np.min(np.diff(uniq))) if uniq.size > 1 else np.inf
    tol = 0.5 * step if np.isfinite(step) else 1.0

    def pick(target, among):
        if among.size == 0:
            return None, None
        j = int(np.argmin(np.abs(dl[among] - target)))
        return (int(among[j]), float(dl[among[j]])) if abs(dl[among[j]] - target) <= tol + 1e-6 else (None, None)

    i, d = pick(float(delay_us), at)
    if i is None:
        flagged, fd = pick(float(delay_us), at_all)
        if flagged is not None:
            raise InputError(
                f"delay_us = {delay_us:g}: the stack's image nearest it at exposure {t_e:g} us ({fd:g} us) is "
                f"excluded (a boundary image, flagged in the stack; usable delays "
                f"{', '.join(f'{x:g}' for x in np.unique(dl[at]))} us); pass --include-excluded to use it"
            )
        raise InputError(
            f"delay_us = {delay_us:g}: the stack has no image near that delay at exposure {t_e:g} us "
            f"(delays {', '.join(f'{x:g}' for x in np.unique(dl[at]))} us)"
        )
    lps = float(stack.lines_per_second)
    name = band_name(d, t_e)
    images = {name: np.asarray(stack.images[i], np.float64)}
    rec = dict(lines_per_second=lps, mm_per_row=mm_per_row, geometry=stack.geometry, source="stack")
    records = {name: {**band_record(d, t_e, **rec), "stack_index": i}}
    j, d0 = pick(0.0, at)
    if j is not None and j != i:
        name0 = band_name(d0, t_e)
        images[name0] = np.asarray(stack.images[j], np.float64)
        records[name0] = {**band_record(d0, t_e, **rec), "stack_index": j}
    info = {
        "requested_delay_us": float(delay_us),
        "requested_exposure_us": None if exposure_us is None else float(exposure_us),
        "delay_us": d,
        "exposure_us": t_e,
        "delay_index": i,
        "delay_image": name,
        "include_excluded": bool(include_excluded),
        "images": records,
    }
    return images, info


def transport_images(
    transport,
    *,
    delay_us: float = DEFAULT_DELAY_US,
    exposure_us: float | None = None,
    lines_per_second: float = PAPER_LINES_PER_SECOND,
    mm_per_row: float = DEFAULT_MM_PER_ROW,
    delay: bool = True,
) -> tuple[dict, dict]:
    """The delay band image synthesized from a transport (exactly the delay asked) and the epipolar image.

    Returns ``(images, info)`` as :func:`stack_images`: ``td{t_d}us_te{t_e}us`` (with
    ``delay``; :func:`planeray.synthesis.band_image`, ``t_e`` default 600 us) and
    ``epipolar`` (:meth:`~planeray.transport.Transport.epipolar_image`, Eq. 5).
    """
    from ..synthesis import band_image

    t_e = DEFAULT_EXPOSURE_US if exposure_us is None else float(exposure_us)
    images, records = {}, {}
    if delay:
        name = band_name(delay_us, t_e)
        images[name] = band_image(transport, delay_us, t_e, lines_per_second=lines_per_second).astype(np.float64)
        records[name] = band_record(
            delay_us,
            t_e,
            lines_per_second=lines_per_second,
            mm_per_row=mm_per_row,
            geometry=transport.geometry,
            source="transport (synthesized)",
        )
    images["epipolar"] = transport.epipolar_image().astype(np.float64)
    records["epipolar"] = epipolar_record(transport.geometry, mm_per_row=mm_per_row, source="transport")
    info = {
        "requested_delay_us": float(delay_us),
        "requested_exposure_us": None if exposure_us is None else float(exposure_us),
        "images": records,
    }
    if delay:
        info.update(delay_us=float(delay_us), exposure_us=t_e, delay_image=band_name(delay_us, t_e))
    return images, info


def delay_sweep_selection(
    stack, *, exposure_us: float | None = None, min_delay_us: float = 0.0, include_excluded: bool = False
) -> tuple[np.ndarray, np.ndarray, dict]:
    """Which images :func:`delay_sweep_images` reads, without reading them: ``(indices, delays_us, info)``.

    Refuses (one line naming ``exposure_us`` or ``min_delay_us``) a selection of fewer than 2 images.
    """
    exp = np.asarray(stack.exposure_us, np.float64)
    dl = np.asarray(stack.delay_us, np.float64)
    usable = _usable(stack, include_excluded)
    t_e = float(exp[usable].min() if usable.any() else exp.min()) if exposure_us is None else float(exposure_us)
    cand = np.isclose(exp, t_e, atol=0.5) & (dl > min_delay_us) & (np.abs(dl) > 0.5 * t_e)
    sel = np.flatnonzero(cand & usable)
    left_out = np.flatnonzero(cand & ~usable)
    if sel.size < 2:
        flagged = (
            f" ({left_out.size} more excluded by the stack; --include-excluded uses them)" if left_out.size else ""
        )
        if not np.isclose(exp, t_e, atol=0.5).any():
            raise InputError(
                f"exposure_us = {t_e:g}: the stack has no image at that exposure (it has "
                f"{', '.join(f'{x:g}' for x in sorted(set(exp.tolist())))} us)"
            )
        raise InputError(
            f"min_delay_us = {min_delay_us:g}: the stack has {sel.size} usable non-epipolar delay images at "
            f"exposure {t_e:g} us with a longer delay{flagged}; contrast enhancement needs at least 2"
        )
    sel = sel[np.argsort(dl[sel])]
    info = {
        "exposure_us": t_e,
        "indices": [int(i) for i in sel],
        "excluded_delays_us": sorted(float(dl[i]) for i in left_out),
        "include_excluded": bool(include_excluded),
    }
    return sel, dl[sel], info


def delay_sweep_images(
    stack,
    *,
    exposure_us: float | None = None,
    min_delay_us: float = 0.0,
    include_excluded: bool = False,
    progress=None,
):
    """Delay images of one exposure with ``t_d > min_delay_us``, the band off the epipolar plane, not excluded.

    Returns ``(images (N, H, W), delays_us (N,), info)`` sorted by delay: the input of
    :func:`planeray.skin.enhance.enhance_contrast`.  Images whose band touches the epipolar
    plane (``|t_d| <= t_e / 2``) are left out, and so are the images the stack excludes (its
    ``excluded`` flags: boundary images, whose row artefacts would stripe Eq. 7's composite)
    unless ``include_excluded``.  ``info``: ``exposure_us``, ``indices`` (stack images used),
    ``excluded_delays_us`` (flagged images left out), ``include_excluded``.  ``progress``, if
    given, is called with 1 after each image read.
    """
    sel, delays, info = delay_sweep_selection(
        stack, exposure_us=exposure_us, min_delay_us=min_delay_us, include_excluded=include_excluded
    )
    images = np.empty((sel.size, *stack.shape), np.float64)
    for k, i in enumerate(sel):
        images[k] = np.asarray(stack.images[int(i)], np.float64)
        if progress is not None:
            progress(1)
    return images, delays, info
