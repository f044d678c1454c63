"""Recognition by fitted parameters over an image: fit, name, pool (issue 27, part 2).

* :func:`fit_image`: ``mu_s'`` and ``mu_a`` per block of pixels (within regions, when
  given) with :func:`planeray.materials.fit.fit_profiles`, and on which side of the forward
  table a ``mu_s'`` flagged "at the edge" lies (:func:`~planeray.materials.library.beyond_table_side`);
* :func:`recognize_image`: those maps named against a :class:`~planeray.materials.library.MediaLibrary`,
  per pixel and, by default, with the log-likelihoods pooled over a disc
  (:data:`DEFAULT_POOL_MM`) -- the default that the recognition study measured best next to
  container walls (docs/user_guide/materials.md, "Recognition by parameters");
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
    maps = {k: np.full((H, W), np.nan, np.float32) for k in _fit._MAP_NAMES}
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
        for name, v in zip(_fit._MAP_NAMES + _RAW_NAMES, values):
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
