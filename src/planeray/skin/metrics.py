"""Vein visibility metrics on a ground-truth (or user) vein mask: CNR, Weber contrast, per-vein detection.

The contrast-to-noise ratio of a vein against its surroundings is::

    CNR = |mu_bg - mu_vein| / sigma_bg,

with ``mu`` the mean of the image over the vein's pixels and over its **background band**,
and ``sigma_bg`` the standard deviation over the band (ddof = 1).  Weber contrast is
``(mu_vein - mu_bg) / mu_bg`` (negative for a vein darker than the skin around it).

Background band of a vein ``k``, in **millimetres on the skin** (the same skin at every image
size): the pixels whose centre lies more than ``gap_mm`` and at most ``gap_mm + width_mm``
from the centre of the nearest pixel of vein ``k`` (Euclidean distance between pixel centres,
``mm_per_px`` apart), minus every pixel within ``gap_mm`` of *any* vein (so another vein and
its shadow never count as background) and minus every excluded pixel (hair, pixels off the
skin, unusable rows).  Defaults :data:`BAND_GAP_MM` = 5 mm and :data:`BAND_WIDTH_MM` = 10 mm:

* the gap is where most of the short-range indirect shadow of a vein has faded (a 3 mm vein
  whose top is 1.5 mm deep, in the 500 us / 600 us band image of the skin scene: 3-6 % below
  the far skin 5 mm from its pixels, 50 % on the vein), and more than the diagonal of a pixel
  of a 64-row image of the paper's 216 mm field (4.8 mm), so a one-pixel hole in a coarse vein
  mask never puts the vein itself in its band;
* the width holds two to three rings of pixels at 64 rows (3.4 mm pixels) and stays the skin
  right next to the vein, where an observer judges it.

A camera pixel of the simulated skin is ``rows_per_camera_row * mm_per_row`` mm on a side
(:func:`planeray.skin.imaging.pixel_mm`): 1.69 mm at 128 rows of the paper's 720-row
projector at 0.3 mm per row, so the band is 2.96-8.89 pixels there, 1.48-4.44 at 64 rows and
5.93-17.8 at 256.  Every result states the definition and the values used
(:func:`band_definition`, the ``band`` entry of :func:`vein_metrics`).  Vein pixels under
hair are left out of the vein region as well.  The pooled (all-veins) CNR uses the union of
the vein regions against the union of the bands.

A vein counts as **detected** when its CNR is at least ``min_cnr`` (1 by default, the
rule of the study) *and* it is darker than its band (veins absorb: a brighter "vein" is not a vein seen).
A vein with fewer than ``min_pixels`` usable pixels (or band pixels) is reported with
``cnr = None`` and ``detected = False`` -- never a made-up number.

References
----------
.. [1] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport: Capture and
   Analysis", IEEE TVCG 2019, Sec. 10, Figs. 13, 16.
.. [2] A. Rose, "Vision: Human and Electronic", Plenum 1973 (contrast-to-noise and the
   detectability of a uniform object against a noisy background).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = [
    "BAND_GAP_MM",
    "BAND_WIDTH_MM",
    "band_definition",
    "background_bands",
    "cnr",
    "weber_contrast",
    "vein_metrics",
    "vein_ids_from_mask",
]

#: Background band of a vein: from this distance (mm on the skin, pixel centre to the vein's
#: nearest pixel centre) ...
BAND_GAP_MM = 5.0
#: ... over this width (mm).
BAND_WIDTH_MM = 10.0


def _pitch(mm_per_px) -> tuple[float, float]:
    """``(row, column)`` pixel pitch in mm from a number or a pair; positive and finite."""
    p = np.broadcast_to(np.asarray(mm_per_px, dtype=np.float64), (2,))
    if not np.all(np.isfinite(p)) or np.any(p <= 0):
        raise ValueError(f"mm_per_px must be positive (mm on the skin per pixel), got {mm_per_px!r}")
    return float(p[0]), float(p[1])


def band_definition(mm_per_px, *, gap_mm: float = BAND_GAP_MM, width_mm: float = BAND_WIDTH_MM) -> dict:
    """The background band's definition and values, for a result file (JSON-ready).

    Parameters
    ----------
    mm_per_px : float or (float, float)
        Size of a pixel on the skin, mm (rows, columns).
    gap_mm, width_mm : float
        Start of the band and its width, mm.

    Returns
    -------
    dict
        ``definition`` (text), ``gap_mm``, ``width_mm``, ``mm_per_px`` and the band in pixels
        (``gap_px``, ``width_px``; along the rows).

    See Also
    --------
    background_bands : the bands.

    Examples
    --------
    >>> b = band_definition(1.6875)
    >>> b["gap_mm"], b["width_mm"], round(b["gap_px"], 2), round(b["width_px"], 2)
    (5.0, 10.0, 2.96, 5.93)
    """
    rows, cols = _pitch(mm_per_px)
    return {
        "definition": (
            "CNR = |mu_bg - mu_vein| / sigma_bg (ddof 1); background band of a vein: pixels whose centre lies "
            "more than gap_mm and at most gap_mm + width_mm from the centre of the vein's nearest pixel, minus "
            "pixels within gap_mm of any vein, hair, pixels off the skin and unusable pixels"
        ),
        "gap_mm": float(gap_mm),
        "width_mm": float(width_mm),
        "mm_per_px": rows if rows == cols else [rows, cols],
        "gap_px": float(gap_mm) / rows,
        "width_px": float(width_mm) / rows,
    }


def vein_ids_from_mask(mask) -> np.ndarray:
    """Integer vein ids (1, 2, ...; 0 off veins) from a boolean mask: 8-connected components.

    For a user mask without ids (a PNG/TIFF drawn over a captured image).

    Parameters
    ----------
    mask : array_like of bool (H, W)
        Vein pixels.

    Returns
    -------
    ndarray (H, W) of int

    See Also
    --------
    vein_metrics : metrics per id.

    Examples
    --------
    >>> import numpy as np
    >>> mask = np.zeros((4, 6), bool)
    >>> mask[:, 1] = mask[:, 4] = True
    >>> vein_ids_from_mask(mask)[0].tolist()
    [0, 1, 0, 0, 2, 0]
    """
    labels, _ = ndimage.label(np.asarray(mask, bool), structure=np.ones((3, 3), bool))
    return labels.astype(np.int32)


def background_bands(
    vein_id, *, mm_per_px, gap_mm: float = BAND_GAP_MM, width_mm: float = BAND_WIDTH_MM, exclude=None
) -> dict[int, np.ndarray]:
    """Background band of each vein (see the module notes for the definition).

    Parameters
    ----------
    vein_id : array_like (H, W) int
        0 off veins, ``k >= 1`` on vein ``k``.
    mm_per_px : float or (float, float)
        Size of a pixel on the skin, mm (rows, columns): pixel centres are this far apart.
    gap_mm, width_mm : float
        Distance from the vein's pixels at which the band starts, and its width, mm
        (:data:`BAND_GAP_MM`, :data:`BAND_WIDTH_MM`).
    exclude : array_like (H, W) bool, optional
        Pixels never used (hair, off the skin).

    Returns
    -------
    dict of int to ndarray (H, W) bool

    See Also
    --------
    vein_metrics : uses them.

    Examples
    --------
    >>> ids = np.zeros((9, 9), int)
    >>> ids[:, 4] = 1
    >>> band = background_bands(ids, mm_per_px=0.5, gap_mm=0.5, width_mm=1.0)[1]
    >>> band[0].astype(int).tolist()
    [0, 1, 1, 0, 0, 0, 1, 1, 0]
    """
    ids = np.asarray(vein_id)
    if ids.ndim != 2:
        raise ValueError(f"vein ids must be an image (H, W), got shape {ids.shape}")
    pitch = _pitch(mm_per_px)
    gap, width = float(gap_mm), float(width_mm)
    if not (np.isfinite(gap) and np.isfinite(width)) or gap < 0 or width <= 0:
        raise ValueError(f"background band needs gap_mm >= 0 and width_mm > 0, got {gap_mm}, {width_mm}")
    any_vein = ids > 0
    if any_vein.any():
        near_any = ndimage.distance_transform_edt(~any_vein, sampling=pitch) <= gap
    else:
        near_any = np.zeros(ids.shape, bool)
    blocked = near_any | (np.zeros(ids.shape, bool) if exclude is None else np.asarray(exclude, bool))
    bands = {}
    for k in np.unique(ids[any_vein]):
        d = ndimage.distance_transform_edt(ids != k, sampling=pitch)
        bands[int(k)] = (d > gap) & (d <= gap + width) & ~blocked
    return bands


def cnr(image, vein, background) -> float:
    """Contrast-to-noise ratio ``|mu_bg - mu_vein| / sigma_bg`` (``sigma_bg`` with ddof = 1).

    Parameters
    ----------
    image : array_like (H, W)
        The image.
    vein, background : array_like of bool (H, W)
        The vein's pixels and its background band.

    Returns
    -------
    float

    See Also
    --------
    weber_contrast : the contrast without the noise.
    vein_metrics : per vein of an id map.

    Examples
    --------
    >>> img = np.array([1.0, 1.2, 0.8, 1.0, 0.5])
    >>> round(cnr(img, img == 0.5, img != 0.5), 3)
    3.062
    """
    img = np.asarray(image, np.float64)
    v, b = img[np.asarray(vein, bool)], img[np.asarray(background, bool)]
    if v.size < 1 or b.size < 2:
        raise ValueError("CNR needs at least one vein pixel and two background pixels")
    s = b.std(ddof=1)
    diff = abs(b.mean() - v.mean())
    if s == 0:
        return float("inf") if diff > 0 else 0.0
    return float(diff / s)


def weber_contrast(image, vein, background) -> float:
    """Weber contrast ``(mu_vein - mu_bg) / mu_bg``.

    Parameters
    ----------
    image : array_like (H, W)
        The image.
    vein, background : array_like of bool (H, W)
        The vein's pixels and its background band.

    Returns
    -------
    float
        Negative for a vein darker than its background.

    See Also
    --------
    cnr : over the background's noise.

    Examples
    --------
    >>> img = np.array([2.0, 2.0, 1.0])
    >>> weber_contrast(img, img == 1.0, img == 2.0)
    -0.5
    """
    img = np.asarray(image, np.float64)
    mb = img[np.asarray(background, bool)].mean()
    return float((img[np.asarray(vein, bool)].mean() - mb) / mb) if mb != 0 else float("nan")


def _stats(img, vein, band):
    v, b = img[vein], img[band]
    mu_v, mu_b, s_b = float(v.mean()), float(b.mean()), float(b.std(ddof=1))
    c = abs(mu_b - mu_v) / s_b if s_b > 0 else (float("inf") if mu_b != mu_v else 0.0)
    return mu_v, mu_b, s_b, float(c), (float((mu_v - mu_b) / mu_b) if mu_b != 0 else None)


def vein_metrics(
    image,
    vein_id,
    *,
    mm_per_px,
    exclude=None,
    gap_mm: float = BAND_GAP_MM,
    width_mm: float = BAND_WIDTH_MM,
    min_cnr: float = 1.0,
    min_pixels: int = 5,
    depth_mm=None,
    diameter_mm=None,
    valid=None,
) -> dict:
    """Pooled and per-vein CNR and Weber contrast of ``image`` on a vein id map.

    Parameters
    ----------
    image : array_like (H, W)
    vein_id : array_like (H, W) int
        Ground-truth vein ids (0 off veins); a boolean mask is split into connected components.
    mm_per_px : float or (float, float)
        Size of a pixel on the skin, mm (:func:`planeray.skin.imaging.pixel_mm`).
    exclude : array_like (H, W) bool, optional
        Pixels left out of veins and bands (hair).
    gap_mm, width_mm : float
        Background band, mm on the skin (see :func:`background_bands`).
    min_cnr : float
        Detection threshold on the per-vein CNR (1).
    min_pixels : int
        Fewest usable vein and band pixels for a vein to be measured.
    depth_mm, diameter_mm : array_like (H, W), optional
        Ground-truth maps (NaN off veins); each vein's median is reported.
    valid : array_like (H, W) bool, optional
        Pixels that may be used (e.g. not saturated).

    Returns
    -------
    dict
        ``cnr``, ``weber`` (pooled), ``n_veins``, ``n_detected``, ``veins``: one dict per vein
        with ``id``, ``pixels``, ``band_pixels``, ``mu_vein``, ``mu_bg``, ``sigma_bg``, ``cnr``,
        ``weber``, ``detected`` and, where given, ``depth_mm`` and ``diameter_mm``; ``band``:
        the band's definition and values (:func:`band_definition`).

    See Also
    --------
    cnr, weber_contrast : the two measures.

    Examples
    --------
    A dark stripe on a noisy background is detected; an invisible one is not:

    >>> rng = np.random.default_rng(0)
    >>> img = 1.0 + 0.01 * rng.standard_normal((40, 40))
    >>> ids = np.zeros((40, 40), int)
    >>> ids[:, 10:12] = 1
    >>> ids[:, 28:30] = 2
    >>> img[:, 10:12] -= 0.05
    >>> m = vein_metrics(img, ids, mm_per_px=1.0)
    >>> [v["detected"] for v in m["veins"]], m["n_detected"]
    ([True, False], 1)
    """
    img = np.asarray(image, np.float64)
    ids = np.asarray(vein_id)
    if ids.dtype == bool:
        ids = vein_ids_from_mask(ids)
    if img.shape != ids.shape:
        raise ValueError(f"image {img.shape} and vein mask {ids.shape} differ in shape")
    usable = np.isfinite(img)
    if exclude is not None:
        usable &= ~np.asarray(exclude, bool)
    if valid is not None:
        usable &= np.asarray(valid, bool)
    bands = background_bands(ids, mm_per_px=mm_per_px, gap_mm=gap_mm, width_mm=width_mm, exclude=~usable)
    veins, all_v, all_b = [], np.zeros(ids.shape, bool), np.zeros(ids.shape, bool)
    for k, band in bands.items():
        vein = (ids == k) & usable
        row = {"id": k, "pixels": int(vein.sum()), "band_pixels": int(band.sum())}
        for name, m in (("depth_mm", depth_mm), ("diameter_mm", diameter_mm)):
            if m is not None:
                vals = np.asarray(m, np.float64)[ids == k]
                vals = vals[np.isfinite(vals)]
                row[name] = float(np.median(vals)) if vals.size else None
        if row["pixels"] < min_pixels or row["band_pixels"] < max(min_pixels, 2):
            row.update(mu_vein=None, mu_bg=None, sigma_bg=None, cnr=None, weber=None, detected=False)
        else:
            mu_v, mu_b, s_b, c, w = _stats(img, vein, band)
            row.update(mu_vein=mu_v, mu_bg=mu_b, sigma_bg=s_b, cnr=c, weber=w)
            row["detected"] = bool(c >= min_cnr and mu_v < mu_b)
            all_v |= vein
            all_b |= band
        veins.append(row)
    pooled_cnr = pooled_weber = None
    if all_v.sum() >= 1 and all_b.sum() >= 2:
        _, _, _, pooled_cnr, pooled_weber = _stats(img, all_v, all_b)
    return {
        "cnr": pooled_cnr,
        "weber": pooled_weber,
        "n_veins": len(veins),
        "n_detected": int(sum(v["detected"] for v in veins)),
        "veins": veins,
        "band": band_definition(mm_per_px, gap_mm=gap_mm, width_mm=width_mm),
    }
