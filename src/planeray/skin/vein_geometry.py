"""Where a vein lies in the image: its mask's pixels, their distances and angles to the vein's centre line.

:func:`vein_geometry` turns a vein's mask into :class:`VeinPixels` (each pixel's signed
distance ``rho`` from the centre line and the vein's angle to the projector rows there, in
the fit's millimetres); :func:`centre_line` finds the centre line of one mask component;
:func:`other_vein_ratio` is the shadow a neighbouring vein casts on a pixel (the fit of
:mod:`planeray.skin.depth` models neighbours together).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt
from scipy.spatial import cKDTree

from ..timing import RowGeometry
from .vein_model import VeinModel, vein_signals

__all__ = ["VeinPixels", "CentreLine", "vein_geometry", "centre_line", "other_vein_ratio"]


# ---------------------------------------------------------------- the vein's geometry from a mask
@dataclass
class VeinPixels:
    """Pixels around one vein: index, row, signed distance from the centre line and local angle."""

    rows: np.ndarray
    cols: np.ndarray
    rho_mm: np.ndarray
    angle_deg: np.ndarray
    x_mm: np.ndarray  # position (for the tint gradient), mm, relative to the vein's centre
    y_mm: np.ndarray
    width_mm: float  # the mask's width across the vein (area / centre-line length)
    line: CentreLine | None = None  # the centre line the distances are measured from


def _pixel_mm(geometry: RowGeometry, mm_per_row: float, shape):
    H, W = shape
    x = (geometry.projector_row_of(np.arange(H)) + 0.5) * mm_per_row
    col = geometry.projector_rows * mm_per_row / H
    y = (np.arange(W) + 0.5) * col
    return x, y, col


@dataclass(frozen=True)
class CentreLine:
    """A vein's centre line from its mask: points (mm, surface ``(x down, y right)``) and local angles."""

    points_mm: np.ndarray  # (m, 2), one per mask pixel: the local centroid
    angle_deg: np.ndarray  # (m,), direction to the rows, in [0, 180)
    px_mm: float  # the larger side of a camera pixel on the skin, mm
    mask_points_mm: np.ndarray  # (m, 2), the mask's pixel centres


def centre_line(component, geometry: RowGeometry, *, mm_per_row: float) -> CentreLine:
    """The centre line of one vein's mask: the local centroid of the mask within a disc (on the axis of a
    locally straight band; radius ``max(5 mm, 2.5 pixels)``) and the local direction, the principal axis of
    the mask in the same disc.

    Parameters
    ----------
    component : ndarray (H, W) bool
        The vein's pixels.
    geometry : RowGeometry
    mm_per_row : float
        Size of a projector row on the skin, mm.
    """
    xs, ys, col_mm = _pixel_mm(geometry, mm_per_row, component.shape)
    row_mm = geometry.rows_per_camera_row * mm_per_row
    ci_, cj_ = np.nonzero(component)
    comp_pts = np.stack([xs[ci_], ys[cj_]], axis=1)
    radius = max(5.0, 2.5 * max(row_mm, col_mm))
    ctree = cKDTree(comp_pts)
    S = np.empty_like(comp_pts)
    dirs = np.empty_like(comp_pts)
    for k, nb in enumerate(ctree.query_ball_point(comp_pts, r=radius)):
        P = comp_pts[nb] if len(nb) >= 3 else comp_pts
        S[k] = P.mean(axis=0)
        _, _, vt = np.linalg.svd(P - P.mean(axis=0), full_matrices=False)
        dirs[k] = vt[0]
    ang = np.degrees(np.arctan2(dirs[:, 0], dirs[:, 1])) % 180.0
    return CentreLine(S, ang, float(max(row_mm, col_mm)), comp_pts)


def _line_coords(line: CentreLine, P):
    """Distance (mm) of points ``P`` (n, 2) from the nearest centre-line point, their signed ``rho`` (mm)
    along its normal, its angle, and whether they lie beside the line (not beyond its ends)."""
    S = line.points_mm
    d, idx = cKDTree(S).query(P)
    a = np.radians(line.angle_deg[idx])
    dx, dy = P[:, 0] - S[idx, 0], P[:, 1] - S[idx, 1]
    rho = dx * np.cos(a) - dy * np.sin(a)
    along = dx * np.sin(a) + dy * np.cos(a)
    return d, rho, line.angle_deg[idx], np.abs(along) <= 0.75 * line.px_mm


def other_vein_ratio(model: VeinModel, line: CentreLine, rows, cols, depth_mm, diameter_mm):
    """Ratio (K, n) and flood ratio (n,) of another vein (its centre line, depth, diameter) at pixels
    ``(rows, cols)``: 1 beyond its ends and beyond the vein table's reach (the skin scene multiplies the
    ratios of all veins)."""
    rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
    K = len(model.bands)
    ratio, flood = np.ones((K, rows.size)), np.ones(rows.size)
    xs, ys, _ = _pixel_mm(model.geometry, model.mm_per_row, (model.geometry.camera_rows, cols.max(initial=0) + 1))
    P = np.stack([xs[rows], ys[cols]], axis=1)
    _, rho, angle, ok = _line_coords(line, P)
    ok &= np.abs(rho) <= (model.table.rho_rows[-1] + 1) * model.mm_per_row
    if ok.any():
        r, f = vein_signals(model, rows[ok], rho[ok], angle[ok], depth_mm, diameter_mm)
        ratio[:, ok] = np.nan_to_num(r, nan=1.0)
        flood[ok] = f
    return ratio, flood


def vein_geometry(
    component, others, geometry: RowGeometry, *, mm_per_row: float, reach_mm: float = 12.0, guard_mm: float = 5.0
) -> VeinPixels:
    """Centre line of one vein's mask and the signed distance of every pixel near it.

    Parameters
    ----------
    component : ndarray (H, W) bool
        The vein's pixels (one connected component of a mask).
    others : ndarray (H, W) bool
        Every other vein's pixels: pixels within ``guard_mm`` of them are left out.
    geometry : RowGeometry
    mm_per_row : float
        Size of a projector row on the skin, mm.
    reach_mm : float
        Pixels up to this distance from the centre line are used, mm.
    guard_mm : float
        Distance kept from other veins, mm.
    """
    shape = component.shape
    xs, ys, col_mm = _pixel_mm(geometry, mm_per_row, shape)
    row_mm = geometry.rows_per_camera_row * mm_per_row
    line = centre_line(component, geometry, mm_per_row=mm_per_row)
    S = line.points_mm
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    dist_other = distance_transform_edt(~others, sampling=(row_mm, col_mm)) if others.any() else np.full(shape, np.inf)
    near = dist_other > guard_mm
    P = np.stack([X[near], Y[near]], axis=1)
    d, rho, angle, ok = _line_coords(line, P)
    keep = d <= reach_mm
    P, rho, angle, ok = P[keep], rho[keep], angle[keep], ok[keep]
    ri, ci = np.nonzero(near)
    ri, ci = ri[keep][ok], ci[keep][ok]
    centre = S.mean(axis=0)
    comp_pts = line.mask_points_mm
    _, _, vt = np.linalg.svd(comp_pts - comp_pts.mean(axis=0), full_matrices=False)
    along_all = comp_pts @ vt[0]
    length = float(along_all.max() - along_all.min()) + min(row_mm, col_mm)
    return VeinPixels(
        rows=ri,
        cols=ci,
        rho_mm=rho[ok],
        angle_deg=angle[ok],
        x_mm=P[ok, 0] - centre[0],
        y_mm=P[ok, 1] - centre[1],
        width_mm=float(component.sum() * row_mm * col_mm / length),
        line=line,
    )
