"""Recognition by fitted parameters over an image: fit, name, pool.

* :func:`fit_image`: ``mu_s'`` and ``mu_a`` per block of pixels (within regions, when
  given) with :func:`planeray.materials.fit.fit_profiles`, and on which side of the forward
  table a ``mu_s'`` flagged "at the edge" lies (:func:`~planeray.materials.library.beyond_table_side`);
* :func:`recognize_image`: those maps named against a :class:`~planeray.materials.library.MediaLibrary`,
  per pixel and, by default, with the log-likelihoods pooled over a disc
  (:data:`DEFAULT_POOL_MM`) -- the default that the recognition study measured best next to
  container walls (docs/user_guide/materials_library.md);
* :func:`accuracy_by_distance`: per-class accuracy in bins of distance to the nearest wall
  (:data:`WALL_BINS_MM`);
* :func:`entries_from_capture`: library entries from labelled regions of a capture ("add
  from a capture").
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from ..errors import InputError
from . import fit as _fit
from .library import (
    DEFAULT_P_UNKNOWN,
    MediaLibrary,
    Recognition,
    beyond_table_side,
    decide,
    entry_from_fit,
    log_likelihoods,
    pool_log_likelihoods,
)

__all__ = [
    "WALL_BINS_MM",
    "DEFAULT_BLOCK_PX",
    "DEFAULT_POOL_MM",
    "fit_image",
    "usable_parameters",
    "recognize_image",
    "recognize_regions",
    "entries_from_capture",
    "accuracy_by_distance",
    "mode_filter",
    "majority_by_region",
]

#: Bins of distance to the nearest wall (mm) of the accuracy tables.
WALL_BINS_MM = (0.0, 1.0, 2.0, 3.0, 5.0, math.inf)
#: Block size of the fits (pixels): 2 x 2 (the fit's cost, 27 ms per block on one core).
DEFAULT_BLOCK_PX = 2
#: Radius (mm on the surface) over which the log-likelihoods are pooled by default.
DEFAULT_POOL_MM = 2.5


_RAW_NAMES = (
    "mu_s_prime_raw_per_mm",
    "mu_a_raw_per_mm",
    "mu_s_prime_raw_se_per_mm",
    "mu_a_raw_se_per_mm",
)


def usable_parameters(maps: dict):
    """The parameters recognition uses: each estimate with its error, however poorly constrained.

    A relative standard error above the fit's threshold makes the fit report NaN (reason bits
    8 / 16); for *recognition* such an estimate still carries evidence, weighed by its error
    in the likelihood.  Used: ``mu_s'`` unless no fit ran or it is beyond the table or
    narrower than a bin (bits 1, 2, 32, 64); ``mu_a`` with a usable ``mu_s'`` unless at the
    table's edge (bit 4).  Without the raw maps, the fit's identified values.

    Returns
    -------
    (mu_s', mu_a, se mu_s', se mu_a, side), arrays like the maps (mm^-1; NaN: not used)
    """
    mask = np.asarray(maps["mask"]).astype(np.int64)
    side = maps.get("side")
    if "mu_s_prime_raw_per_mm" not in maps:
        return (
            maps["mu_s_prime_per_mm"],
            maps["mu_a_per_mm"],
            maps.get("mu_s_prime_se_per_mm"),
            maps.get("mu_a_se_per_mm"),
            side,
        )
    fitted = mask != 255
    s_ok = fitted & ((mask & (1 | 2 | 32 | 64)) == 0)
    a_ok = s_ok & ((mask & 4) == 0)
    nan = np.float32(np.nan)
    return (
        np.where(s_ok, maps["mu_s_prime_raw_per_mm"], nan),
        np.where(a_ok, maps["mu_a_raw_per_mm"], nan),
        np.where(s_ok, maps["mu_s_prime_raw_se_per_mm"], nan),
        np.where(a_ok, maps["mu_a_raw_se_per_mm"], nan),
        side,
    )


def fit_image(transport, *, mm_per_row, block_px=DEFAULT_BLOCK_PX, regions=None, table=None, progress=None) -> dict:
    """Fit ``mu_s'``, ``mu_a`` per ``block_px x block_px`` block, within regions.

    Parameters
    ----------
    transport : Transport
        Demultiplexed transport (``dense`` (H, W, U), ``offsets_rows``, ``geometry``).
    mm_per_row : float
        Projector row size on the surface, mm.
    block_px : int
        Block size, pixels (1: every pixel).
    regions : ndarray (H, W) of int, optional
        Blocks never mix regions (0: not fitted).  Default: one region.
    table : ForwardTable, optional
    progress : callable, optional
        Called with the number of blocks fitted.

    Returns
    -------
    dict of ndarray (H, W)
        ``mu_s_prime_per_mm``, ``mu_a_per_mm``, their ``*_se_per_mm`` (NaN where not
        identifiable), ``mask`` (the fit's reason bits; 255 not fitted) and ``side``
        (+1 / -1: ``mu_s'`` above / below the forward table).
    """
    dense = np.asarray(transport.dense, np.float64)
    H, W, U = dense.shape
    offsets = np.asarray(transport.offsets_rows)
    rpc = float(transport.geometry.rows_per_camera_row)
    reg = np.ones((H, W), np.int64) if regions is None else np.asarray(regions, np.int64)
    if reg.shape != (H, W):
        raise InputError(f"regions have shape {reg.shape}, the image {(H, W)}")
    b = int(block_px)
    if b < 1:
        raise InputError(f"block_px must be >= 1, got {block_px!r}")
    table = table or _fit.forward_table()
    means, sds, where = [], [], []
    for r0 in range(0, H, b):
        for c0 in range(0, W, b):
            rb = reg[r0 : r0 + b, c0 : c0 + b]
            for label in np.unique(rb[rb > 0]):
                m = rb == label
                px = dense[r0 : r0 + b, c0 : c0 + b][m]
                mean = px.mean(axis=0)
                sd = px.std(axis=0, ddof=1) / math.sqrt(px.shape[0]) if px.shape[0] > 1 else np.zeros(U)
                means.append(mean)
                sds.append(np.maximum(sd, 0.01 * max(float(np.abs(mean).max()), 1e-30)))
                where.append((r0, c0, m))
    maps = {k: np.full((H, W), np.nan, np.float32) for k in _fit.MAP_NAMES}
    for name in _RAW_NAMES:
        maps[name] = np.full((H, W), np.nan, np.float32)
    maps["mask"] = np.full((H, W), 255, np.uint8)
    maps["side"] = np.zeros((H, W), np.int8)
    if not where:
        return maps
    Y = np.stack(means)
    Y[Y == 0] = np.nan
    res = _fit.fit_profiles(
        Y, offsets_rows=offsets, mm_per_row=mm_per_row, sigma=np.stack(sds), rows_per_camera_row=rpc, table=table
    )
    if progress is not None:
        progress(len(where))
    side = beyond_table_side(
        res.mask, res.model, offsets_rows=offsets, mm_per_row=mm_per_row, rows_per_camera_row=rpc, table=table
    )
    values = (
        res.mu_s_prime_per_mm,
        res.mu_a_per_mm,
        res.mu_s_prime_se_per_mm,
        res.mu_a_se_per_mm,
    )
    est, se = np.exp(res.log_estimate_per_mm), np.exp(res.log_estimate_per_mm) * res.log_se
    values = values + (est[:, 0], est[:, 1], se[:, 0], se[:, 1])
    for i, (r0, c0, m) in enumerate(where):
        sl = (slice(r0, r0 + b), slice(c0, c0 + b))
        for name, v in zip(_fit.MAP_NAMES + _RAW_NAMES, values):
            maps[name][sl][m] = v[i]
        maps["mask"][sl][m] = res.mask[i]
        maps["side"][sl][m] = side[i]
    return maps


def recognize_image(
    library: MediaLibrary,
    maps: dict,
    *,
    mm_per_pixel=None,
    pool_mm=DEFAULT_POOL_MM,
    regions=None,
    p_unknown=DEFAULT_P_UNKNOWN,
    use_standard_errors=False,
) -> Recognition:
    """Name every pixel's medium from the maps of :func:`fit_image`.

    Parameters
    ----------
    library : MediaLibrary
    maps : dict
        :func:`fit_image`'s output.
    mm_per_pixel : float, optional
        Pixel size on the surface, mm (needed with ``pool_mm > 0``).
    pool_mm : float
        Pool the log-likelihoods over a disc of this radius (mm) around each pixel, among the
        pixels whose own fit is known to the library (:func:`~planeray.materials.library.pool_log_likelihoods`);
        0: per pixel.
    regions : ndarray (H, W) of int, optional
        Pool over these regions instead (a user's labels; label 0 pixels per pixel).
    p_unknown : float
        Typicality threshold of a pixel's own fit (:func:`~planeray.materials.library.decide`).
    use_standard_errors : bool
        Add each pixel's standard errors to the entries' spreads.  Off by default: an entry
        made by :func:`entries_from_capture` holds the spread of the fit's estimates over its
        reference blocks, which already includes their estimation noise -- and the linearized
        errors of a poorly constrained fit are far larger than that spread (measured: a median
        relative error of 2.0 reported for toothpaste's ``mu_s'`` where the estimates spread
        by 0.10 in ``ln``), so adding them would drown the evidence.

    Returns
    -------
    Recognition
        ``class_ids`` (H, W): 0 unclassified (not fitted or unknown by its own fit).
    """
    s, a, se_s, se_a, side = usable_parameters(maps)
    if not use_standard_errors:
        se_s = se_a = None
    ll, d2, dof, flags = log_likelihoods(library, s, a, mu_s_prime_se_per_mm=se_s, mu_a_se_per_mm=se_a, side=side)
    own = decide(library, ll, d2, dof, flags, p_unknown=p_unknown)
    known = own.class_ids > 0
    if regions is not None:
        pooled = pool_log_likelihoods(ll, regions=regions, valid=known)
    elif float(pool_mm) > 0:
        if mm_per_pixel is None or not float(mm_per_pixel) > 0:
            raise InputError("pooling over a disc needs the pixel size (mm_per_pixel)")
        pooled = pool_log_likelihoods(ll, radius_px=float(pool_mm) / float(mm_per_pixel), valid=known)
    else:
        return own
    res = decide(library, pooled, d2, dof, flags, p_unknown=0.0)
    return Recognition(np.where(known, res.class_ids, 0), pooled, own.d2, own.flags, own.classes)


def recognize_regions(
    library: MediaLibrary, transport, regions, *, mm_per_row, p_unknown=DEFAULT_P_UNKNOWN, table=None
):
    """Name each region by the fit of its pooled profile (a region's pixels averaged, then fitted once).

    The region-level reasoning measured best next to container walls: the mean profile of a
    whole region (a container the user outlined) has little noise, and its wall pixels are a
    minority of it.  The library's entries are distributions of *block* fits, so a region's
    estimate is compared with the entries' centres using their spreads -- a conservative
    test for a pooled estimate.

    Parameters
    ----------
    library : MediaLibrary
    transport : Transport
    regions : ndarray (H, W) of int
        Region labels (0: not named).
    mm_per_row : float
    p_unknown : float
        A region whose fit is less typical of every entry is unknown (0).
    table : ForwardTable, optional

    Returns
    -------
    (Recognition, maps)
        Per pixel (every pixel of a region gets its class; 0 outside the regions) and the
        region fits (:func:`fit_image` with one block per region).
    """
    reg = np.asarray(regions)
    H, W = reg.shape
    maps = fit_image(transport, mm_per_row=mm_per_row, block_px=max(H, W), regions=reg, table=table)
    return recognize_image(library, maps, pool_mm=0, p_unknown=p_unknown), maps


def entries_from_capture(maps: dict, labels, names: dict, *, source="", published=None) -> list:
    """Library entries from labelled regions of a fitted capture ("add from a capture").

    Parameters
    ----------
    maps : dict
        :func:`fit_image` of the capture (fit with ``regions=labels`` so blocks do not mix media).
    labels : ndarray (H, W) of int
        The regions (class ids; 0 and ids missing from ``names`` ignored).
    names : dict of int -> str
        Class id -> the medium's name, for each region to make an entry of.
    source : str
        Stored with every entry (e.g. the capture's path).
    published : dict of int -> dict, optional
        Published constants per class id, stored with the entries.

    Returns
    -------
    list of MediumEntry
    """
    labels = np.asarray(labels)
    s, a, _, _, side = usable_parameters(maps)
    out = []
    for cid, name in names.items():
        m = labels == cid
        if not m.any():
            raise InputError(f"the labels have no pixel of class {cid} ({name})")
        out.append(
            entry_from_fit(
                s[m],
                a[m],
                side[m],
                name=name,
                class_id=cid,
                source=source,
                published=(published or {}).get(cid),
            )
        )
    return out


def majority_by_region(pred, regions):
    """Each region's most frequent non-zero class (pixels outside regions keep theirs)."""
    pred = np.asarray(pred)
    out = np.array(pred, copy=True)
    for r in np.unique(regions[regions > 0]):
        m = regions == r
        v = pred[m]
        v = v[v > 0]
        if v.size:
            out[m] = np.bincount(v).argmax()
    return out


def mode_filter(pred, *, radius_px, classes):
    """Most frequent class of ``classes`` in a disc around each pixel (0 and other ids do not vote)."""
    pred = np.asarray(pred)
    k = int(np.floor(radius_px))
    yy, xx = np.mgrid[-k : k + 1, -k : k + 1]
    disc = (yy * yy + xx * xx <= radius_px * radius_px + 1e-9).astype(np.float64)
    classes = list(classes)
    votes = np.stack([ndimage.correlate((pred == c).astype(np.float64), disc, mode="constant") for c in classes], -1)
    best = np.asarray(classes)[votes.argmax(-1)]
    return np.where(votes.max(-1) > 0, best, 0)


def accuracy_by_distance(pred, truth, wall_distance_mm, *, classes, bins_mm=WALL_BINS_MM) -> dict:
    """Per-class accuracy (recall) overall and in bins of distance to the nearest wall.

    Parameters
    ----------
    pred, truth : ndarray (H, W) of int
        Predicted and true class ids.
    wall_distance_mm : ndarray (H, W)
        Distance of each pixel to the nearest wall of its container, mm.
    classes : dict of int -> str
        The classes to score, by id, with their names.
    bins_mm : sequence of float
        Bin edges, mm (a pixel at ``d`` is in ``[lo, hi)``).

    Returns
    -------
    dict
        ``bins_mm`` (the edges; ``None`` for infinity), ``classes``: name -> ``{"all":
        accuracy, "pixels": n, "bins": [{"accuracy", "pixels"} per bin]}`` (accuracy ``None``
        where a bin has no pixel), ``within_3_mm``: name -> accuracy of pixels closer than 3 mm,
        ``min_class_accuracy``.
    """
    pred, truth = np.asarray(pred), np.asarray(truth)
    wall = np.asarray(wall_distance_mm, np.float64)
    if not pred.shape == truth.shape == wall.shape:
        raise InputError(f"pred {pred.shape}, truth {truth.shape} and wall distances {wall.shape} differ in shape")
    edges = [float(v) for v in bins_mm]

    def acc(m):
        return float((pred[m] == truth[m]).mean()) if m.any() else None

    out = {"bins_mm": [None if math.isinf(v) else v for v in edges], "classes": {}, "within_3_mm": {}}
    for cid, name in classes.items():
        m = truth == cid
        rows = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            mm = m & (wall >= lo) & (wall < hi)
            rows.append({"accuracy": acc(mm), "pixels": int(mm.sum())})
        out["classes"][name] = {"all": acc(m), "pixels": int(m.sum()), "bins": rows}
        out["within_3_mm"][name] = acc(m & (wall < 3.0))
    vals = [v["all"] for v in out["classes"].values() if v["all"] is not None]
    out["min_class_accuracy"] = min(vals) if vals else None
    return out


# ---------------------------------------------------------------- recognition that travels
#: Chi-square gain that makes a pixel "a scattering medium": the best medium kernel (one more coefficient than
#: a surface's direct light) must improve the chi-square by this much -- chi2.isf(1e-6, 1) = 24 for one kernel,
#: rounded up for the choice among :data:`_GENERIC_MEDIA` and the library's (a look-elsewhere margin).
SUBSURFACE_DCHI2 = 30.0
#: Smallest container the automatic segmentation keeps, mm^2 (smaller components are noise, or a wall).
MIN_CONTAINER_MM2 = 25.0
#: Generic media whose kernels make a pixel "a scattering medium" besides the library's: (mu_s', mu_a) in 1/mm.
_GENERIC_MEDIA = tuple((s, a) for s in (0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 30.0) for a in (0.003, 0.03))
#: Relative model error of the per-pixel test (of each image's light), as the stack fit's.
_PIXEL_MODEL_SD = 0.02
#: Evidence is also pooled over a disc of this radius (pixels) among neighbours that look alike: of the same
#: brightness within this relative difference, their own evidence within a factor of 10 (in 1 + evidence: a
#: table pixel beside a tray of soap, as dim as the soap, does not borrow the soap's evidence) ...
POOL_RADIUS_PX = 3
POOL_BRIGHTNESS_TOLERANCE = 0.2
POOL_EVIDENCE_FACTOR_LOG = math.log(10.0)
#: ... and the pool must pass this gain: a surface's pixels gain ~0.5 each (the best of the kernels, positive
#: coefficient), 29 pixels ~15 +- 6; 60 lies 7 standard deviations above.
POOLED_DCHI2 = 60.0
#: A container takes up to this many pixels of its border whose brightness lies within this share of its median
#: (and nearer to it than to the brightness outside the containers) and whose own evidence reaches this (a
#: surface's pixel gains less than 0.5 in 70 % of cases) ...
GROW_PX = 2
GROW_BRIGHTNESS_TOLERANCE = 0.5
GROW_EVIDENCE = 0.5
#: ... and a pooled pixel must show at least this much of its own (a surface's: in 80 % of cases less).
POOL_OWN_EVIDENCE = 1.0


def _kernel_or_none(s, a, *, mm_per_row, offsets, rpc, table):
    try:
        return _fit.forward_kernel(
            s, a, offsets_rows=offsets, mm_per_row=mm_per_row, rows_per_camera_row=rpc, table=table
        )
    except InputError:  # outside the forward model at this row size
        return None


def subsurface_evidence(stack, *, mm_per_row, library=None, camera=None, table=None) -> np.ndarray:
    """Per pixel, how strongly its images show light from below the surface (chi-square gain).

    Each pixel's used images (:func:`planeray.materials.stackfit.stack_design`) are fitted twice, linearly:
    as a **surface** (its direct light: the camera row's footprint through the illumination matrix, plus
    ambient light) and as a surface **and a scattering medium** (plus one medium's kernel: generic media
    over ``mu_s'`` 0.2-30 /mm and the library's entries), weighted by the camera's noise model and a 2 %
    model error.  The gain in chi-square of the best medium (its coefficient positive) is the evidence: a
    matte table or a container's rim shows none, a milk or a paste thousands.

    Parameters
    ----------
    stack : Stack
    mm_per_row : float
    library : MediaLibrary, optional
        Its (version 2) entries' kernels join the generic ones.
    camera : CameraModel, optional
        The camera's noise model (default: planeray's default camera).
    table : ForwardTable, optional

    Returns
    -------
    ndarray (H, W)
        The chi-square gain (0 where a pixel has too few usable images).
    """
    from ..camera import CameraModel
    from ..kernels.footprint import camera_row_footprint
    from .stackfit import _images, stack_design

    design = stack_design(stack)
    imgs, ok = _images(stack, design)
    camera = camera or CameraModel()
    var = camera.pixel_variance(imgs) + (_PIXEL_MODEL_SD * np.maximum(imgs, 0.0)) ** 2
    wts = np.where(ok, 1.0 / var, 0.0)  # (N, H, W)
    offsets, rpc = design.offsets_rows, design.rows_per_camera_row
    f_off, f_w = camera_row_footprint(rpc)
    direct = np.zeros(offsets.size)
    for o, w in zip(f_off, f_w):
        direct[offsets == o] += w
    media = list(_GENERIC_MEDIA)
    if library is not None and library.physical:
        media += [(e.mu_s_prime_per_mm, e.mu_a_per_mm or 0.003) for e in library.entries if e.mu_s_prime_per_mm]
    kernels = []
    for s, a in media:
        k = _kernel_or_none(s, a, mm_per_row=mm_per_row, offsets=offsets, rpc=rpc, table=table or _fit.forward_table())
        if k is not None:
            kernels.append(k)
    H, W = stack.shape
    out = np.zeros((H, W))
    I = design.exposure_rows
    for g in range(design.A.shape[0]):
        rows = np.flatnonzero(design.row_group == g)
        if rows.size == 0:
            continue
        A = design.A[g]  # (N, U)
        y = imgs[:, rows, :].reshape(imgs.shape[0], -1)  # (N, P)
        w = wts[:, rows, :].reshape(imgs.shape[0], -1)

        def chi2_of(X, y=y, w=w):
            """Weighted least squares of every pixel on the columns X (N, q): chi-square and coefficients."""
            XtWX = np.einsum("ni,np,nj->pij", X, w, X)
            XtWy = np.einsum("ni,np,np->pi", X, w, y)
            coef = np.linalg.solve(XtWX + 1e-30 * np.eye(X.shape[1]), XtWy[..., None])[..., 0]
            r = y - X @ coef.T
            return (w * r * r).sum(axis=0), coef

        chi_s, _ = chi2_of(np.stack([A @ direct, I], axis=1))
        best = np.zeros(y.shape[1])
        for k in kernels:
            chi_m, coef = chi2_of(np.stack([A @ direct, A @ k, I], axis=1))
            gain = np.where(coef[:, 1] > 0, chi_s - chi_m, 0.0)
            best = np.maximum(best, gain)
        enough = ok[:, rows, :].reshape(imgs.shape[0], -1).sum(axis=0) >= 6
        out[rows] = np.where(enough, best, 0.0).reshape(rows.size, W)
    return out


def stack_brightness(stack) -> np.ndarray:
    """Each pixel's brightness: the sum of its used images (saturated ones counted as they read)."""
    from .stackfit import _images, stack_design

    imgs, _ = _images(stack, stack_design(stack))
    return np.where(np.isfinite(imgs), imgs, 0.0).sum(axis=0)


def pooled_evidence(evidence, brightness, *, radius_px=POOL_RADIUS_PX, tolerance=POOL_BRIGHTNESS_TOLERANCE):
    """The evidence of light from below the surface summed over a pixel's neighbours of its own brightness.

    A medium whose kernel is barely wider than a camera row's footprint (a paste of ``mu_s'`` ~ 16 /mm at
    1.7 mm pixels) shows a few units of chi-square per pixel, a surface a fraction of one: summed over the
    disc of ``radius_px`` -- independent pixels' evidence adds -- among the neighbours whose brightness
    (the sum of the pixel's images) lies within ``tolerance`` of the pixel's (relative), so that a table
    pixel beside a tray of milk does not borrow the milk's evidence.

    Returns
    -------
    ndarray (H, W)
    """
    E = np.maximum(np.asarray(evidence, np.float64), 0.0)
    lb = np.log(np.maximum(np.asarray(brightness, np.float64), 1e-12))
    le = np.log1p(E)
    r = int(radius_px)
    H, W = E.shape
    pad_e = np.pad(E, r)
    pad_le = np.pad(le, r, constant_values=np.inf)
    pad_b = np.pad(lb, r, constant_values=np.inf)
    out = np.zeros_like(E)
    tol = math.log1p(float(tolerance))
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            if dy * dy + dx * dx > r * r:
                continue
            sl = (slice(r + dy, r + dy + H), slice(r + dx, r + dx + W))
            alike = (np.abs(pad_b[sl] - lb) <= tol) & (np.abs(pad_le[sl] - le) <= POOL_EVIDENCE_FACTOR_LOG)
            out += np.where(alike, pad_e[sl], 0.0)
    return out


def find_containers(
    evidence, *, mm_per_pixel, brightness=None, threshold=SUBSURFACE_DCHI2, pooled_threshold=POOLED_DCHI2,
    min_area_mm2=MIN_CONTAINER_MM2,
):  # fmt: skip
    """Containers of scattering media: the connected regions of pixels that show light from below the surface.

    A pixel is a medium's when its own evidence (:func:`subsurface_evidence`) passes ``threshold`` or, given
    its ``brightness``, the evidence pooled over its neighbours of its brightness (:func:`pooled_evidence`)
    passes ``pooled_threshold``; isolated pixels are removed (a 3 x 3 majority), and each 4-connected region
    of at least ``min_area_mm2`` is a container (labels 1, 2, ...; 0 elsewhere: a table, a wall, a surface).
    Containers that touch one another form one region: outline them (``regions`` of :func:`recognize_stack`).

    Returns
    -------
    ndarray (H, W) of int
    """
    mask = np.asarray(evidence) > float(threshold)
    if brightness is not None:  # a pixel that shows a little of its own and whose alike neighbours show much
        mask |= (pooled_evidence(evidence, brightness) > float(pooled_threshold)) & (
            np.asarray(evidence) >= POOL_OWN_EVIDENCE
        )
    votes = ndimage.uniform_filter(mask.astype(np.float64), size=3, mode="nearest")
    mask = np.where(votes >= 5.0 / 9.0 - 1e-9, True, np.where(votes <= 4.0 / 9.0 + 1e-9, False, mask))
    lab, n = ndimage.label(mask)
    if n == 0:
        return lab
    sizes = np.bincount(lab.ravel())[1:] * float(mm_per_pixel) ** 2
    keep = np.flatnonzero(sizes >= float(min_area_mm2)) + 1
    out = np.zeros_like(lab)
    for i, k in enumerate(keep, start=1):
        out[lab == k] = i
    if brightness is not None and out.max() > 0:
        # the pixels next to a container's wall, where its kernel is cut and the pool straddles the wall: a
        # container takes (up to GROW_PX deep) its neighbours of its own brightness that show some evidence
        lb = np.log(np.maximum(np.asarray(brightness, np.float64), 1e-12))
        E = np.asarray(evidence, np.float64)
        median = np.array([np.median(lb[out == k]) for k in range(1, out.max() + 1)])
        outside = float(np.median(lb[out == 0])) if (out == 0).any() else -np.inf
        cross = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool)
        for _ in range(GROW_PX):
            grown = ndimage.grey_dilation(out, footprint=cross)
            new = (out == 0) & (grown > 0) & (E >= GROW_EVIDENCE)
            near = np.abs(lb - median[np.maximum(grown, 1) - 1])
            # of the container's brightness, and nearer to it than to what lies outside the containers (a table)
            new &= (near <= math.log1p(GROW_BRIGHTNESS_TOLERANCE)) & (near < np.abs(lb - outside))
            if not new.any():
                break
            out = np.where(new, grown, out)
    for k in range(1, out.max() + 1):  # a container has no holes (a pixel it surrounds is its medium)
        out[ndimage.binary_fill_holes(out == k) & (out == 0)] = k
    return out


def entries_from_stack(
    stack, labels, names: dict, *, mm_per_row, n=_fit.DEFAULT_N, depth_mm=None, camera=None, white=None,
    white_albedo=0.99, wall_kind="clear", source="", published=None, table=None,
) -> list:  # fmt: skip
    """Version-2 library entries -- physical parameters -- from labelled regions of a stack.

    Each region named in ``names`` is one container: fitted as a whole from the stack's images
    (:func:`planeray.materials.stackfit.fit_stack`, its walls modelled from ``labels``, the medium's index
    ``n`` and layer depth), and its entry holds the fitted ``mu_s'``, ``mu_a``, their uncertainties (the fit's
    standard errors of their logs, with the model's error and the misfit in them) and correlation, ``n`` and
    ``depth_mm`` -- values of the medium, so the entry recognizes it at any resolution and row size.

    Returns
    -------
    list of MediumEntry
    """
    from .library import MIN_LOG_SD, MediumEntry
    from .stackfit import fit_stack

    lab = np.asarray(labels)
    regions = np.where(np.isin(lab, list(names)), lab, 0)
    res = fit_stack(
        stack, mm_per_row=mm_per_row, labels=regions, containers=regions, white=white, white_albedo=white_albedo,
        table=table or _fit.forward_table(n=n), camera=camera, depth_mm=depth_mm, wall_kind=wall_kind,
    )  # fmt: skip
    out = []
    for cid, name in names.items():
        r = res.regions.get(int(cid))
        if r is None or r["log_estimate_per_mm"] is None or r["mu_s_prime_per_mm"] is None:
            why = "; ".join(r["not_identifiable"] + r["flags"]) if r else "no pixels"
            raise InputError(f"{name!r} (class {cid}): its mu_s' is not measured in this capture ({why})")
        ls, la = r["log_estimate_per_mm"]
        ses, sea = r["log_se"]
        has_a = r["mu_a_per_mm"] is not None
        out.append(
            MediumEntry(
                name=str(name).strip(), class_id=int(cid), mu_s_prime_per_mm=float(math.exp(ls)),
                mu_s_prime_log_sd=max(float(ses), MIN_LOG_SD),
                mu_a_per_mm=float(math.exp(la)) if has_a else None,
                mu_a_log_sd=max(float(sea), MIN_LOG_SD) if has_a else None,
                correlation=float(np.clip(r.get("log_correlation") or 0.0, -0.95, 0.95)) if has_a else 0.0,
                blocks=int(r["pixels"]), source=source, published=(published or {}).get(int(cid)),
                n=float(n), depth_mm=None if depth_mm is None else float(depth_mm),
            )
        )  # fmt: skip
    return out


def recognize_stack(
    library: MediaLibrary, stack, *, mm_per_row, regions=None, camera=None, white=None, white_albedo=0.99,
    wall_kind="clear", p_unknown=DEFAULT_P_UNKNOWN, evidence=None, progress=None,
):  # fmt: skip
    """Name each container's medium from the stack's images, against a version-2 (physical) library.

    1. **Containers**: ``regions`` (a user's outline), else found (:func:`subsurface_evidence`,
       :func:`find_containers`): pixels without light from below the surface -- a table, a wall -- are no
       medium and stay 0 ("none").
    2. **Fits**: each container as a whole from its images (:func:`planeray.materials.stackfit.fit_stack`, its
       walls modelled), once per ``(n, depth)`` the library's entries were fitted with.
    3. **Decision**: an entry is compared with the fit under its own ``(n, depth)``: the squared Mahalanobis
       distance ``d^2`` of the fitted log parameters from the entry's, under the sum of both covariances (a
       ``mu_s'`` at the forward model's edge is censored: "at most" the edge's value).  An entry whose model
       does not fit the container (its chi-square past the threshold) is not it.  The container is the entry
       of least ``d^2`` plus the fit's chi-square, unless no entry is within the chi-square quantile of
       ``1 - p_unknown`` (at the parameters compared): then "none of these" (0).

    Returns
    -------
    (Recognition, list of dict)
        Per pixel (each container's pixels get its class, 0 elsewhere) and per container: its pixels, each
        hypothesis' fit, each entry's ``d^2``, the decision and why.
    """
    from .library import NOT_FITTED, UNKNOWN, Recognition
    from .stackfit import fit_stack

    if not library.physical:
        raise InputError("recognizing a stack's containers needs a version-2 library (physical parameters)")
    H, W = stack.shape
    rpc = float(stack.geometry.rows_per_camera_row)
    if regions is None:
        if evidence is None:
            evidence = subsurface_evidence(stack, mm_per_row=mm_per_row, library=library, camera=camera)
        regions = find_containers(evidence, mm_per_pixel=mm_per_row * rpc, brightness=stack_brightness(stack))
    reg = np.asarray(regions, np.int64)
    if reg.shape != (H, W):
        raise InputError(f"regions have shape {reg.shape}, the stack {(H, W)}")
    fits = {}
    for n, depth in library.hypotheses():
        fits[(n, depth)] = fit_stack(
            stack, mm_per_row=mm_per_row, labels=reg, containers=reg, white=white, white_albedo=white_albedo,
            table=_fit.forward_table(n=n), camera=camera, depth_mm=depth, wall_kind=wall_kind,
        ).regions  # fmt: skip
        if progress is not None:
            progress(1)
    class_ids = np.zeros((H, W), np.int64)
    flags = np.zeros((H, W), np.uint8)
    ids = library.class_ids
    K = len(ids)
    ll = np.full((H, W, K), np.nan)
    d2_map = np.full((H, W, K), np.nan)
    details = []
    for region in sorted(int(v) for v in np.unique(reg) if v > 0):
        inside = reg == region
        rows = []
        for e in library.entries:
            h = (_fit.DEFAULT_N if e.n is None else float(e.n), e.depth_mm)
            r = fits[h].get(region)
            rows.append(_compare(e, r, p_unknown))
        scores = [x["score"] for x in rows]
        best = int(np.nanargmin(scores)) if np.isfinite(scores).any() else None
        decision = 0
        why = "no entry's fit measures mu_s'" if best is None else ""
        if best is not None:
            b = rows[best]
            if b["d2"] > b["limit"]:
                why = (
                    f"none of these: the nearest, {library.entries[best].name}, is at d^2 = {b['d2']:.1f} > "
                    f"{b['limit']:.1f} (p = {p_unknown:g})"
                )
            else:
                decision = ids[best]
                why = f"{library.entries[best].name}: d^2 = {b['d2']:.2f} (limit {b['limit']:.1f})"
        class_ids[inside] = decision
        if decision == 0:
            flags[inside] |= UNKNOWN if best is not None else NOT_FITTED
        ll[inside] = [-0.5 * x["score"] for x in rows]
        d2_map[inside] = [x["d2"] for x in rows]
        details.append(
            {"region": region, "pixels": int(inside.sum()), "class_id": int(decision), "decision": why,
             "entries": {e.name: {k: v for k, v in x.items() if k != "score"} for e, x in zip(library.entries, rows)}}
        )  # fmt: skip
    rec = Recognition(class_ids, ll, d2_map, flags, list(ids))
    return rec, details


def _compare(entry, r, p_unknown=DEFAULT_P_UNKNOWN) -> dict:
    """An entry against a region's fit (under the entry's hypothesis): ``d^2``, its limit, the score."""
    from scipy.stats import chi2

    out = {"d2": math.inf, "limit": math.nan, "score": math.inf, "fit": None, "model_fits": None}
    if r is None or r.get("log_estimate_per_mm") is None:
        return out
    q = r.get("fit_quality") or {}
    out["fit"] = {k: r.get(k) for k in ("mu_s_prime_per_mm", "mu_a_per_mm", "mu_s_prime_se_per_mm", "mu_a_se_per_mm")}
    out["model_fits"] = q.get("model_fits")
    out["flags"] = r.get("flags", [])
    if q.get("model_fits") is False:  # the entry's model (its index, its depth) does not fit this container
        return out
    if r.get("mask", 0) & 2 and r.get("mu_s_prime_edge") in ("lower", "upper"):
        # mu_s' at the forward model's edge is a censored measurement: "at most" (or "at least") the edge's value;
        # an entry beyond the edge agrees with it, one inside it by its distance from the edge in its own sd
        edge = float(r["log_estimate_per_mm"][0])
        m = math.log(entry.mu_s_prime_per_mm)
        beyond = m <= edge if r["mu_s_prime_edge"] == "lower" else m >= edge
        d2 = 0.0 if beyond else ((m - edge) / entry.mu_s_prime_log_sd) ** 2
        chi_data = (q.get("reduced_chi2") or 0.0) * (q.get("dof") or 0)
        out.update(d2=d2, limit=float(chi2.isf(p_unknown, 1)), score=d2 + chi_data, parameters=1, censored=True)
        return out
    if r.get("mask", 0) & 2 or r.get("mu_s_prime_per_mm") is None:  # mu_s' not measured: not this entry
        return out
    x = np.array(r["log_estimate_per_mm"], float)
    se = np.array(r["log_se"], float)
    rho = float(r.get("log_correlation") or 0.0)
    m = [math.log(entry.mu_s_prime_per_mm)]
    S_e = [[entry.mu_s_prime_log_sd**2]]
    use_a = entry.mu_a_per_mm is not None and r.get("mu_a_per_mm") is not None
    if use_a:
        m.append(math.log(entry.mu_a_per_mm))
        c = entry.correlation * entry.mu_s_prime_log_sd * entry.mu_a_log_sd
        S_e = [[entry.mu_s_prime_log_sd**2, c], [c, entry.mu_a_log_sd**2]]
    k = len(m)
    S_x = np.array([[se[0] ** 2, rho * se[0] * se[1]], [rho * se[0] * se[1], se[1] ** 2]])[:k, :k]
    S = np.array(S_e) + S_x
    dx = x[:k] - np.array(m)
    d2 = float(dx @ np.linalg.solve(S, dx))
    chi_data = (q.get("reduced_chi2") or 0.0) * (q.get("dof") or 0)
    out.update(d2=d2, limit=float(chi2.isf(p_unknown, k)), score=d2 + chi_data, parameters=k)
    return out
