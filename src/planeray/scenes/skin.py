"""Forearm skin with veins: layered tissue lit row by row (Sec. 10, Figs. 13, 14, 16).

Model
-----
The skin is a stack of layers -- epidermis (melanin: the ``tone``), dermis, subcutaneous
fat -- with the published optical constants of :mod:`planeray.optical_data_skin` at the
projector's red line (638 nm) or at 850 nm, and veins: infinitely long cylinders of
venous blood, locally straight, at any orientation in the image plane.  A skin pixel
``(t, s)`` receives

* **surface reflection** (the direct, epipolar component): ``surface_reflectance``
  (default 3 %, the rough Fresnel reflection of skin at ``n = 1.4``) with a fine skin
  texture, spread over the camera row's footprint;
* **light from below the surface** from every lit projector row ``v = p_t + u``::

      T_ss[t, s, u] = rho(s, t) (K0 * F)(u) prod_veins R_vein(rho_pix, u)

  ``K0`` is the plane-to-ray kernel of the vein-free layers: Monte Carlo
  (:func:`planeray.kernels.vein.mc_vein_table`; a pencil beam at the pixel, exits binned
  by the offset ``u`` of the row they leave through: the pixel's line kernel by
  reciprocity).  ``F`` is the camera row's footprint.  ``R_vein`` is the vein's
  multiplicative change of the kernel, a Monte Carlo **perturbation table** over the
  pixel's signed distance ``rho`` from the vein axis, the offset ``u``, the angle
  between vein and projector rows (0, 45, 90 deg; linear in between), the depth of the
  vein's top (1-5 mm) and its diameter (1-4 mm): every photon path of the background
  run is re-weighted by ``exp(-(mu_a,blood - mu_a,tissue) L)``, ``L`` its path length
  inside the vein (the pathlength-in-cylinder weighting of perturbation Monte Carlo;
  the convolution model of short-range indirect imaging of Liu et al., ICCP 2020).
  Several veins multiply.  ``rho`` is a smooth ~5 % tint of the skin.

The veins are absorbers only (blood scatters like the tissue around it); a
brute-force Monte Carlo with the blood cylinder in the medium
(:func:`planeray.mc.layered.mc_layered_vein_brute`) checks the approximation
(``tests/test_skin.py``, README "Skin and veins").

Ground truth (``Scene.maps``)
-----------------------------
``vein_mask`` (bool): pixels whose centre lies over a vein (within its radius of the
projected centreline); ``vein_id`` (int32; 0 none, ``1..N``; every branch has its own
id and records its ``parent``; where veins overlap, the one whose axis is nearest
relative to its radius); ``vein_depth_mm`` (float32, NaN off veins): depth of the
**top** of the vein (the vessel wall nearest the surface) below the skin surface;
``vein_axis_depth_mm`` (its axis: top + radius); ``vein_diameter_mm``; ``skin``
(bool: pixels on the skin); with ``hair`` on, ``hair`` (bool) and ``hair_coverage``
(float32, the fraction of the pixel covered by hair); with ``curved``,
``surface_tilt_deg`` (angle between the surface normal and the viewing axis).
:func:`skin_veins` lists each vein with its own mask (a pixel can be over two veins).

Geometry and timing
-------------------
``mm_per_row`` (default 0.3 mm) is the size of a projector row on the skin: 720 rows
over 216 mm, the paper's PicoPro at about 0.5 m.  The paper's short-range indirect
delays, 400-600 us at 54,000 lines/s, centre the band on offsets of 21.6-32.4 rows, i.e.
6.5-9.7 mm from the pixel: the source-detector distances of diffuse reflectance that
probe 2-5 mm deep, where the perturbation tables put the vein contrast of veins 1-3 mm
deep (README).  Camera pixels are square: a camera column is ``projector_rows *
mm_per_row / H`` wide.

``curved=True``: a cylindrical forearm (``arm_radius_mm``, default 35 mm) with its axis
along the image rows, centred, on a dark cloth.  A pixel at height ``x`` from the axis
sees the surface tilted by ``phi = asin(x / R)``; distances on the surface grow as
``1 / cos(phi)`` (the kernel is evaluated at stretched offsets), light enters with the
Fresnel transmission of oblique incidence, and the surface reflection falls as
``cos(phi)``.  Only rows lit on the arm send light into it (the kernel is cut at the arm's
silhouette, like the wax candle's).  The layers follow the surface; veins live in surface
coordinates.

``hair=True``: dark strands (80 um thick, 3-15 mm long, seeded) lying on the skin: a
pixel partly covered by hair shows the hair's reflectance over that fraction instead of
the skin (the light hair casts on the lit line is ignored).

Assumptions
-----------
* Vein tables are traced per wavelength and layer thicknesses for fair (3 % melanosomes)
  and dark (30 %) skin: the melanin changes the vein's contrast (dark skin: +6 to +19 % in
  the short-range band, -26 to -35 % in the epipolar band for veins 1-3 mm deep), so other
  tones interpolate the log ratio linearly in the melanosome fraction (clamped below fair)
  and get their own background kernel ``K0``.
* Veins are locally straight (the nearest segment of the centreline gives ``rho`` and the
  angle); beyond a vein's ends its shadow fades as from a round cap (``|rho|`` is the
  distance to the end, the angle the cap's tangent: :func:`_nearest_segment`); where a
  branch meets its parent both perturb the kernel (multiplied).
* The camera pixel's own extent across a vein is not integrated (the ratio is taken at
  the pixel centre).

References
----------
.. [1] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport", TVCG 2019,
   Sec. 10 (vein imaging, delays 400-600 us at ~0.5 m).
.. [2] C. Liu, A. K. Maity, A. W. Dubrawski, A. Sabharwal, S. G. Narasimhan, "High
   resolution diffuse optical tomography using short range indirect subsurface
   imaging", ICCP 2020.
.. [3] S. Y. Park et al., forearm vein depth 4.8 +- 2.2 mm and diameters 3-4.5 mm by
   ultrasound, 2023.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import convolve1d
from scipy.spatial import cKDTree

from ..errors import InputError
from ..kernels.vein import TABLE_DEPTHS_MM, TABLE_DIAMETERS_MM, mc_vein_table, vein_ratio, vein_table_slice
from ..mc.layered import mc_layered_profile
from ..mc.physics import fresnel_unpolarized
from ..optical_data_skin import SKIN_N, skin_layers, tone_fraction
from ..timing import RowGeometry
from ..transport import Transport
from ._textures import smooth_noise
from .base import DEFAULT_MM_PER_ROW, Scene, footprint_kernel, register_scene

__all__ = [
    "build",
    "skin_veins",
    "skin_tables",
    "skin_tables_to_trace",
    "random_veins",
    "SkinVein",
    "SKIN_BAND_ROWS",
    "TABLE_TONES",
    "VEIN_DEPTH_RANGE_MM",
    "VEIN_DIAMETER_RANGE_MM",
]

#: Half-width of the skin scene's dense offset band (rows): the kernel is < 1e-6 beyond.
SKIN_BAND_ROWS = 64
#: Tones with their own vein tables (others interpolate between them).
TABLE_TONES = ("fair", "dark")
#: Photons of the shipped vein tables and of the background kernels of other tones.
TABLE_PHOTONS = 400_000
KERNEL_PHOTONS = 100_000
#: Depth of the vein's top and its diameter, as tabulated (mm).
VEIN_DEPTH_RANGE_MM = (float(TABLE_DEPTHS_MM[0]), float(TABLE_DEPTHS_MM[-1]))
VEIN_DIAMETER_RANGE_MM = (float(TABLE_DIAMETERS_MM[0]), float(TABLE_DIAMETERS_MM[-1]))
_HAIR_WIDTH_MM = 0.08


# ---------------------------------------------------------------- tables
def skin_tables(
    wavelength_nm=638,
    tone="fair",
    *,
    epidermis_mm=0.1,
    dermis_mm=1.5,
    fat_mm=8.0,
    mm_per_row=DEFAULT_MM_PER_ROW,
    progress=None,
    skin=None,
):
    """The vein perturbation table and the background kernel of a skin.

    Returns ``(table, kernel, total_reflectance)``.  Vein tables are traced for the two
    tones of :data:`TABLE_TONES` (``"fair"`` and ``"dark"``; shipped for the default
    thicknesses); for a tone in between, the log of the kernel ratio is interpolated
    linearly in the melanosome fraction (clamped outside), and the background line kernel
    ``K0`` and total diffuse reflectance are traced for the tone itself (shipped for the
    named tones).  ``skin`` (:class:`planeray.optical_data_skin.SkinLayers`, e.g. a user's
    :func:`~planeray.optical_data_skin.skin_model`): the table of exactly those layers and
    blood (traced once and cached; ``wavelength_nm``, ``tone`` and the thicknesses are then
    not used).
    """
    if skin is not None:
        table = mc_vein_table(
            skin.layers, skin.blood, mm_per_row=mm_per_row, n_photons=TABLE_PHOTONS, progress=progress
        )
        return table, table.kernel, table.total_reflectance
    kw = dict(epidermis_mm=epidermis_mm, dermis_mm=dermis_mm, fat_mm=fat_mm)

    def table_of(name):
        ref = skin_layers(wavelength_nm, name, **kw)
        return mc_vein_table(ref.layers, ref.blood, mm_per_row=mm_per_row, n_photons=TABLE_PHOTONS, progress=progress)

    m = tone_fraction(tone)
    m_lo, m_hi = (tone_fraction(t) for t in TABLE_TONES)
    for name, mt in zip(TABLE_TONES, (m_lo, m_hi)):
        if math.isclose(m, mt):
            table = table_of(name)
            return table, table.kernel, table.total_reflectance
    lo, hi = table_of(TABLE_TONES[0]), table_of(TABLE_TONES[1])
    w = float(np.clip((m - m_lo) / (m_hi - m_lo), 0.0, 1.0))
    log_r = (1 - w) * np.log(np.maximum(lo.ratio, 1e-12)) + w * np.log(np.maximum(hi.ratio, 1e-12))
    skin = skin_layers(wavelength_nm, tone, **kw)
    prof = mc_layered_profile(
        skin.layers, n_photons=KERNEL_PHOTONS, offsets_rows=lo.offsets_rows, mm_per_row=mm_per_row, cache=True
    )
    table = replace(
        lo,
        ratio=np.exp(log_r),
        kernel=prof.values,
        kernel_stderr=prof.stderr,
        total_reflectance=prof.total_reflectance,
        params={**lo.params, "interpolated_melanin_fraction": m, "between": list(TABLE_TONES)},
    )
    return table, prof.values, prof.total_reflectance


def skin_tables_to_trace(wavelength_nm=638, tone="fair", *, mm_per_row=DEFAULT_MM_PER_ROW, skin=None, **thicknesses):
    """The layer stacks (:class:`~planeray.optical_data_skin.SkinLayers`) whose vein tables :func:`skin_tables`
    would trace with these arguments: neither shipped nor cached (empty: it reads them)."""
    from ..kernels.vein import vein_table_stored

    if skin is not None:
        stacks = [skin]
    else:
        m = tone_fraction(tone)
        named = [t for t in TABLE_TONES if math.isclose(m, tone_fraction(t))]
        stacks = [skin_layers(wavelength_nm, t, **thicknesses) for t in (named or TABLE_TONES)]
    return [
        s for s in stacks
        if not vein_table_stored(s.layers, s.blood, mm_per_row=mm_per_row, n_photons=TABLE_PHOTONS)
    ]  # fmt: skip


# ---------------------------------------------------------------- veins
def _ar1(x, memory):
    """``y[..., i] = x[..., i] + memory * y[..., i - 1]`` along the last axis, ``y[..., -1] = 0`` before the first:
    ``scipy.signal.lfilter([1], [1, -memory], x)`` (the same arithmetic, so the same numbers), without
    importing ``scipy.signal`` (~0.6 s, in every process that builds a skin scene)."""
    x = np.asarray(x, dtype=float)
    y = np.empty_like(x)
    prev = np.zeros(x.shape[:-1])
    for i in range(x.shape[-1]):
        prev = x[..., i] + memory * prev
        y[..., i] = prev
    return y


def _polyline(rng, start, heading_deg, length_mm, wiggle_deg=2.0, max_turn_deg=25.0, step_mm=1.0):
    """A smooth random curve: ``length_mm`` in steps of ``step_mm``, heading near ``heading_deg``.

    The heading deviates from ``heading_deg`` by an AR(1) random walk (``0.9`` memory,
    ``wiggle_deg`` per step), clipped to ``+-max_turn_deg``.
    """
    n = max(2, int(length_mm / step_mm) + 1)
    dev = np.clip(_ar1(rng.normal(0.0, wiggle_deg, n - 1), 0.9), -max_turn_deg, max_turn_deg)
    h = np.radians(heading_deg + dev)
    steps = step_mm * np.stack([np.sin(h), np.cos(h)], axis=1)
    return np.asarray(start, dtype=float) + np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])


def random_veins(
    rng: np.random.Generator, height_mm, width_mm, *, axis_deg=None, n_main=None, top_mm=0.0
) -> list[dict]:
    """A seeded forearm-like vein pattern in surface coordinates ``(x down, y right)``, mm.

    ``n_main`` (default 2-3) main veins run along the arm's axis (``axis_deg`` from the
    rows; default random, any orientation) across the whole field, and 1-3 branches
    leave them at 25-50 deg; the field spans ``top_mm .. top_mm + height_mm`` down and
    ``0 .. width_mm`` across.  Depths of the vein's top uniform in 1-5 mm; diameters
    2-4 mm (main) and 1-2.5 mm (branches), as adult forearm veins (Park et al. 2023:
    depth 4.8 +- 2.2 mm, diameters 3-4.5 mm).  Each vein is a dict with ``id``,
    ``parent`` (0 for a main vein), ``depth_mm`` (top), ``diameter_mm`` and ``points_mm``.
    """
    axis = float(rng.uniform(0.0, 180.0)) if axis_deg is None else float(axis_deg)
    n_main = int(rng.integers(2, 4)) if n_main is None else int(n_main)
    centre = np.array([top_mm + 0.5 * height_mm, 0.5 * width_mm])
    diag = math.hypot(height_mm, width_mm)
    a = math.radians(axis)
    along = np.array([math.sin(a), math.cos(a)])
    across = np.array([math.cos(a), -math.sin(a)])
    veins = []
    spread = 0.7 * min(height_mm, width_mm) / 2.0
    offsets = np.sort(rng.uniform(-spread, spread, n_main))
    for i, off in enumerate(offsets):
        start = centre + off * across - 0.75 * diag * along
        pts = _polyline(rng, start, axis, 1.5 * diag)
        veins.append(
            dict(
                id=i + 1,
                parent=0,
                depth_mm=round(float(rng.uniform(1.0, 5.0)), 2),
                diameter_mm=round(float(rng.uniform(2.0, 4.0)), 2),
                points_mm=pts,
            )
        )
    inside = [
        (v, k)
        for v in veins
        for k in range(len(v["points_mm"]))
        if top_mm + 0.15 * height_mm < v["points_mm"][k][0] < top_mm + 0.85 * height_mm
        and 0.15 * width_mm < v["points_mm"][k][1] < 0.85 * width_mm
    ]
    for _ in range(int(rng.integers(1, 4)) if inside else 0):
        parent, k = inside[int(rng.integers(len(inside)))]
        turn = float(rng.uniform(25.0, 50.0)) * (1 if rng.uniform() < 0.5 else -1)
        pts = _polyline(rng, parent["points_mm"][k], axis + turn, float(rng.uniform(0.3, 0.6)) * diag)
        veins.append(
            dict(
                id=len(veins) + 1,
                parent=parent["id"],
                depth_mm=round(float(np.clip(parent["depth_mm"] + rng.uniform(-1.0, 0.5), 1.0, 5.0)), 2),
                diameter_mm=round(float(rng.uniform(1.0, 2.5)), 2),
                points_mm=pts,
            )
        )
    return veins


def _check_veins(veins) -> list[dict]:
    out = []
    for i, v in enumerate(veins):
        try:
            pts = np.asarray(v.get("points_mm", v.get("points")), dtype=float)
            depth = float(v["depth_mm"])
            diam = float(v["diameter_mm"])
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise InputError(f"vein {i}: needs depth_mm, diameter_mm and points_mm ({exc})") from None
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2 or not np.all(np.isfinite(pts)):
            raise InputError(f"vein {i}: points_mm must be at least two finite (x, y) points in mm")
        lo, hi = VEIN_DEPTH_RANGE_MM
        if not lo <= depth <= hi:
            raise InputError(f"vein {i}: depth_mm {depth} outside the tabulated {lo}-{hi} mm (depth of its top)")
        lo, hi = VEIN_DIAMETER_RANGE_MM
        if not lo <= diam <= hi:
            raise InputError(f"vein {i}: diameter_mm {diam} outside the tabulated {lo}-{hi} mm")
        out.append(
            dict(
                id=int(v.get("id", i + 1)),
                parent=int(v.get("parent", 0)),
                depth_mm=depth,
                diameter_mm=diam,
                points_mm=pts,
            )
        )
    ids = [v["id"] for v in out]
    if len(set(ids)) != len(ids) or any(k < 1 for k in ids):
        raise InputError("vein ids must be distinct positive integers")
    return out


def _nearest_segment(points, X, Y):
    """Distance, signed distance ``rho`` (mm) and local angle to the rows (deg, in [0, 180)) of
    each point ``(X, Y)`` from a vein's centreline.

    The centreline is sampled every <= 0.25 mm (a k-d tree finds the nearest sample);
    the point is then projected exactly onto that sample's segment and its two neighbours.
    Where the projection falls inside the nearest segment, ``rho`` is the signed distance
    from that segment's line and the angle the segment's.  Where it falls on a segment's end
    (beyond the vein's ends, or outside a bend), the nearest centreline point is that end:
    ``|rho|`` is the distance to it and the angle is the tangent of the round cap there
    (perpendicular to the point's offset from it), so a vein's shadow ends in a round cap
    (as its ground-truth mask, ``distance <= radius``) instead of continuing along the last
    segment's line, and it is continuous everywhere (at the cap's edge the tangent is the
    segment's direction).
    """
    points = np.asarray(points, dtype=float)
    d = np.diff(points, axis=0)
    seg_len = np.hypot(d[:, 0], d[:, 1])
    keep = seg_len > 0
    p0, d, seg_len = points[:-1][keep], d[keep], seg_len[keep]
    n_sub = np.maximum(1, np.ceil(seg_len / 0.25).astype(int))
    seg_of = np.repeat(np.arange(len(p0)), n_sub)
    frac = np.concatenate([np.arange(k) / k for k in n_sub])
    samples = p0[seg_of] + frac[:, None] * d[seg_of]
    P = np.stack([X.ravel(), Y.ravel()], axis=1)
    _, idx = cKDTree(samples).query(P)
    k0 = seg_of[idx]
    best = np.full(len(P), np.inf)
    kbest = k0.copy()
    tbest = np.zeros(len(P))
    for dk in (-1, 0, 1):
        k = np.clip(k0 + dk, 0, len(p0) - 1)
        t = np.clip(np.einsum("ij,ij->i", P - p0[k], d[k]) / seg_len[k] ** 2, 0.0, 1.0)
        dist = np.hypot(*(P - p0[k] - t[:, None] * d[k]).T)
        better = dist < best
        best = np.where(better, dist, best)
        kbest = np.where(better, k, kbest)
        tbest = np.where(better, t, tbest)
    ang = np.degrees(np.arctan2(d[kbest, 0], d[kbest, 1])) % 180.0  # direction (sin a, cos a) in (x, y)
    # On an end of the segment: the tangent of the round cap, perpendicular to the offset.
    off = P - p0[kbest] - tbest[:, None] * d[kbest]
    cap = ((tbest <= 0.0) | (tbest >= 1.0)) & (best > 0.0)
    ang = np.where(cap, np.degrees(np.arctan2(-off[:, 1], off[:, 0])) % 180.0, ang)
    a = np.radians(ang)
    rho = np.where(
        cap,
        off[:, 0] * np.cos(a) - off[:, 1] * np.sin(a),  # +-distance: the cap's tangent is normal to the offset
        (P[:, 0] - p0[kbest, 0]) * np.cos(a) - (P[:, 1] - p0[kbest, 1]) * np.sin(a),
    )
    return best.reshape(X.shape), rho.reshape(X.shape), ang.reshape(X.shape)


# ---------------------------------------------------------------- pixel geometry
def _surface_coords(shape, projector_rows, mm_per_row, curved, arm_radius_mm):
    """Surface coordinates (mm) of the pixel centres, the skin mask, tilt and distance stretch."""
    H, W = shape
    geometry = RowGeometry(H, projector_rows)
    P = geometry.projector_rows
    x_img = (geometry.projector_row_of(np.arange(H)) + 0.5) * mm_per_row  # from the top edge
    col_mm = P * mm_per_row / H
    y = (np.arange(W) + 0.5) * col_mm
    if curved:
        xc = 0.5 * P * mm_per_row
        s = np.clip((x_img - xc) / arm_radius_mm, -1.0, 1.0)
        on = np.abs(s) < 0.97
        phi = np.arcsin(np.clip(s, -0.97, 0.97))
        x = xc + arm_radius_mm * phi
        stretch = 1.0 / np.cos(phi)
    else:
        on = np.ones(H, bool)
        phi = np.zeros(H)
        x = x_img
        stretch = np.ones(H)
    X, Y = np.meshgrid(x, y, indexing="ij")
    return geometry, X, Y, np.broadcast_to(on[:, None], shape), phi, stretch


def _geometry_params(params):
    return (
        tuple(params["shape"]),
        params["projector_rows"],
        params["mm_per_row"],
        bool(params["curved"]),
        params["arm_radius_mm"],
    )


@dataclass(frozen=True)
class SkinVein:
    """Ground truth of one vein of a skin scene (:func:`skin_veins`)."""

    id: int
    parent: int
    depth_mm: float  # of the top of the vein
    diameter_mm: float
    points_mm: np.ndarray  # centreline in surface coordinates (x down, y right)
    mask: np.ndarray  # (H, W) bool: pixels within the radius of the centreline

    @property
    def axis_depth_mm(self) -> float:
        return self.depth_mm + 0.5 * self.diameter_mm


def skin_veins(scene: Scene) -> list[SkinVein]:
    """Each vein of a ``skin`` scene with its exact ground truth: depth, diameter, its own pixel mask.

    Parameters
    ----------
    scene : Scene
        A scene built by ``make_scene("skin", ...)``.

    Returns
    -------
    list of SkinVein
        Per vein: ``id``, ``parent`` (the vein it branches from, 0 for none), ``depth_mm``
        (of its top below the surface), ``diameter_mm``, ``points_mm`` (its centre line) and
        ``mask`` (H, W) of the pixels over it; ``axis_depth_mm`` is ``depth_mm + diameter_mm / 2``.

    See Also
    --------
    planeray.skin.depth : vein depths measured from a stack.

    References
    ----------
    .. [1] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa, S. G. Narasimhan,
       "Programmable Non-Epipolar Indirect Light Transport: Capture and Analysis",
       IEEE TVCG 27(4), 2019, doi:10.1109/TVCG.2019.2946812, Sec. 10.

    Examples
    --------
    >>> from planeray.scenes import make_scene
    >>> scene = make_scene("skin", (32, 32), projector_rows=180, seed=1)
    >>> veins = skin_veins(scene)
    >>> all(v.mask.shape == (32, 32) for v in veins), all(1 <= v.depth_mm <= 5 for v in veins)
    (True, True)
    """
    if scene.name != "skin":
        raise InputError(f"skin_veins needs a skin scene, got {scene.name!r}")
    shape, P, mm, curved, radius = _geometry_params(scene.params)
    _, X, Y, on, _, _ = _surface_coords(shape, P, mm, curved, radius)
    out = []
    for v in scene.params["veins"]:
        pts = np.asarray(v["points_mm"], dtype=float)
        dist, _, _ = _nearest_segment(pts, X, Y)
        out.append(
            SkinVein(
                id=int(v["id"]),
                parent=int(v["parent"]),
                depth_mm=float(v["depth_mm"]),
                diameter_mm=float(v["diameter_mm"]),
                points_mm=pts,
                mask=(dist <= 0.5 * float(v["diameter_mm"])) & on,
            )
        )
    return out


# ---------------------------------------------------------------- hair
def _hair(rng, X, Y, col_mm, row_mm_img, *, density_per_cm2):
    """Coverage of each pixel by hair strands (fraction), seeded.

    Strands 3-15 mm long, 80 um thick, wavy (AR(1) heading), mostly along one direction
    (+-20 deg); each 0.1 mm piece adds its area to the pixel it falls in.
    """
    H, W = X.shape
    x0, x1, y0, y1 = X.min(), X.max(), Y.min(), Y.max()
    area_cm2 = (x1 - x0 + row_mm_img) * (y1 - y0 + col_mm) / 100.0
    n = int(rng.poisson(density_per_cm2 * area_cm2))
    step = 0.1
    m = int(15.0 / step)
    if n == 0:
        return np.zeros((H, W))
    length = rng.uniform(3.0, 15.0, n)
    heading = rng.uniform(0, 180) + rng.normal(0, 20, n)
    dev = np.clip(_ar1(rng.normal(0.0, 1.5, (n, m)), 0.97), -40.0, 40.0)
    h = np.radians(heading[:, None] + dev)
    start = np.stack([rng.uniform(x0, x1, n), rng.uniform(y0, y1, n)], axis=1)
    px = start[:, :1] + step * np.cumsum(np.sin(h), axis=1)
    py = start[:, 1:] + step * np.cumsum(np.cos(h), axis=1)
    on = np.arange(m)[None, :] * step < length[:, None]
    i = np.floor((px - x0) / row_mm_img + 0.5).astype(np.int64)
    j = np.floor((py - y0) / col_mm + 0.5).astype(np.int64)
    ok = on & (i >= 0) & (i < H) & (j >= 0) & (j < W)
    cov = np.bincount(i[ok] * W + j[ok], minlength=H * W) * (_HAIR_WIDTH_MM * step / (row_mm_img * col_mm))
    return np.clip(cov.reshape(H, W), 0.0, 1.0)


# ---------------------------------------------------------------- the scene
@register_scene("skin", "forearm skin with veins: layered tissue, blood cylinders (Sec. 10)")
def build(
    shape,
    projector_rows,
    seed,
    tone="fair",
    wavelength_nm: int = 638,
    hair: bool = False,
    curved: bool = False,
    veins=None,
    mm_per_row: float = DEFAULT_MM_PER_ROW,
    epidermis_mm: float = 0.1,
    dermis_mm: float = 1.5,
    fat_mm: float = 8.0,
    surface_reflectance: float = 0.03,
    arm_radius_mm: float = 35.0,
    arm_axis_deg: float | None = None,
    hair_density_per_cm2: float = 20.0,
    hair_reflectance: float = 0.04,
    cloth_albedo: float = 0.05,
    band_rows: int = SKIN_BAND_ROWS,
    blood_scale: float = 1.0,
):
    """Build the scene.

    Parameters
    ----------
    tone : str or float
        Skin tone: a name of :data:`planeray.optical_data_skin.SKIN_TONES` (``"very_fair"``
        ... ``"dark"``) or the epidermal melanosome volume fraction.
    wavelength_nm : {638, 850}
        The projector's red line or the near infrared.
    hair : bool
        Dark hair strands on the skin (seeded).
    curved : bool
        A cylindrical forearm of radius ``arm_radius_mm`` (axis along the rows) on a dark
        cloth instead of a flat patch of skin filling the image.
    veins : list of dict, optional
        Explicit veins, each ``{"depth_mm": top depth, "diameter_mm": ..., "points_mm":
        [[x, y], ...]}`` (surface coordinates in mm, ``x`` down from the image's top edge,
        ``y`` right; optional ``id`` and ``parent``); default a seeded forearm pattern
        (:func:`random_veins`, axis ``arm_axis_deg``; along the arm when ``curved``).
        ``[]``: no veins.
    mm_per_row : float
        Size of one projector row on the skin, mm.
    epidermis_mm, dermis_mm, fat_mm : float
        Layer thicknesses (the defaults have shipped tables; others are traced once,
        a few minutes, and cached).
    surface_reflectance : float
        Mean reflectance of the skin's surface (the direct light).
    band_rows : int
        Half-width of the dense offset band (projector rows).
    blood_scale : float
        Blood volume of the veins relative to the tabulated vessels (the pulse: 1 + ~1.5 %).
        Each vein's ratio becomes ``R ** blood_scale``: to first order in the absorption,
        ``ln R = -(mu_a,blood - mu_a,tissue) <L>``, ``<L>`` the mean path length in the vein,
        and more blood in the same vessel scales that absorption (``planeray.pulse.simulate``).
    """
    H, W = shape
    rng = np.random.default_rng(seed)
    mm = float(mm_per_row)
    if not mm > 0:
        raise InputError(f"mm_per_row must be positive, got {mm_per_row}")
    tone_name = tone if isinstance(tone, str) else None
    melanin = tone_fraction(tone)
    skin = skin_layers(wavelength_nm, tone, epidermis_mm=epidermis_mm, dermis_mm=dermis_mm, fat_mm=fat_mm)
    table, k0, r_total = skin_tables(
        wavelength_nm, tone, epidermis_mm=epidermis_mm, dermis_mm=dermis_mm, fat_mm=fat_mm, mm_per_row=mm
    )
    geometry, X, Y, on, phi, stretch = _surface_coords(shape, projector_rows, mm, curved, arm_radius_mm)
    P, rpc = geometry.projector_rows, geometry.rows_per_camera_row
    col_mm = P * mm / H
    height_mm = P * mm
    width_mm = W * col_mm

    if veins is None:
        axis = (rng.normal(0.0, 10.0) if curved else None) if arm_axis_deg is None else arm_axis_deg
        xs = X[np.asarray(on)[:, 0], 0]  # the skin's extent down the image, surface mm
        veins = random_veins(rng, xs.max() - xs.min(), width_mm, axis_deg=axis, top_mm=xs.min())
    veins = _check_veins(veins)

    # Offsets of the band (+ the footprint's reach for the convolution).
    band = max(int(band_rows), int(np.ceil(rpc)) + 1)
    offsets = np.arange(-band, band + 1)
    half = int(np.ceil(0.5 * rpc + 0.5))
    wide = np.arange(offsets[0] - half, offsets[-1] + half + 1)
    foot = footprint_kernel(np.arange(-half, half + 1), rpc)

    # Background kernel per camera row: density over surface mm, stretched on a curved arm.
    k_off = table.offsets_rows
    u_t = wide[None, :] * stretch[:, None]  # (H, U') offsets in table rows
    k_row = np.interp(u_t, k_off, k0, left=0.0, right=0.0)
    cos_in = np.cos(phi)
    t_in = (1.0 - fresnel_unpolarized(cos_in, 1.0 / SKIN_N)) / (1.0 - fresnel_unpolarized(1.0, 1.0 / SKIN_N))
    k_row *= t_in[:, None]
    if curved:  # light must enter the arm: the part of each offset bin that lies on it
        xc, half_arc = 0.5 * P * mm, 0.97 * arm_radius_mm
        top, bottom = (xc - half_arc) / mm - 0.5, (xc + half_arc) / mm - 0.5  # projector coordinates
        lo = geometry.projector_row_of(np.arange(H))[:, None] + wide[None, :] - 0.5
        k_row *= np.clip(np.minimum(lo + 1.0, bottom) - np.maximum(lo, top), 0.0, 1.0)

    # Vein ratios, per pixel (product over veins).
    ratio = np.ones((H, W, wide.size))
    vid = np.zeros(shape, np.int32)
    vdepth = np.full(shape, np.nan, np.float32)
    vdiam = np.full(shape, np.nan, np.float32)
    best = np.full(shape, np.inf)
    reach_mm = (table.rho_rows[-1] + 1) * mm
    for v in veins:
        # Only pixels within reach of the centreline's bounding box can be near it (|rho| is the
        # distance to the centreline, never below the distance to its box): the same numbers.
        pts = np.asarray(v["points_mm"], dtype=float)
        margin = max(reach_mm, 0.5 * v["diameter_mm"])
        (x0, y0), (x1, y1) = pts.min(axis=0) - margin, pts.max(axis=0) + margin
        bi, bj = np.nonzero((X >= x0) & (X <= x1) & (Y >= y0) & (Y <= y1))
        if bi.size == 0:
            continue
        dist, rho_mm, ang = _nearest_segment(pts, X[bi, bj], Y[bi, bj])
        sl = vein_table_slice(table, v["depth_mm"], v["diameter_mm"])
        near = (np.abs(rho_mm) <= reach_mm) & on[bi, bj]
        if near.any():
            ti, si = bi[near], bj[near]
            r = vein_ratio(sl, table, rho_mm[near] / mm, ang[near], u_t[ti])
            ratio[ti, si] *= r if blood_scale == 1.0 else np.power(np.maximum(r, 1e-12), float(blood_scale))
        rel = dist / (0.5 * v["diameter_mm"])
        over = (rel <= 1.0) & on[bi, bj] & (rel < best[bi, bj])
        oi, oj = bi[over], bj[over]
        best[oi, oj] = rel[over]
        vid[oi, oj] = v["id"]
        vdepth[oi, oj] = v["depth_mm"]
        vdiam[oi, oj] = v["diameter_mm"]

    tint = 1.0 + smooth_noise(shape, rng, max(H, W) / 8.0, 0.05)
    texture = 1.0 + smooth_noise(shape, rng, 0.7, 0.15)
    surface = np.clip(surface_reflectance * texture * np.cos(phi)[:, None], 0.0, 1.0)
    sub = (k_row[:, None, :] * ratio) * (tint * on)[:, :, None]
    sub = convolve1d(sub, foot[::-1], axis=2, mode="constant")[:, :, half:-half]
    maps = {}
    direct = np.where(on, surface, cloth_albedo)
    if hair:
        cov = _hair(rng, X, Y, col_mm, height_mm / H, density_per_cm2=hair_density_per_cm2) * on
        sub *= (1.0 - cov)[:, :, None]
        direct = (1.0 - cov) * direct + cov * hair_reflectance
        maps["hair"] = cov > 0.02
        maps["hair_coverage"] = cov.astype(np.float32)
    direct = direct.astype(np.float32)
    fo = footprint_kernel(offsets, rpc).astype(np.float32)
    dense = sub.astype(np.float32) + direct[:, :, None] * fo[None, None, :]
    ambient = dense.sum(axis=2, dtype=np.float64).astype(np.float32)  # room light reaches the whole arm
    # the edge rule: light enters only where the projector is, [-1/2, P - 1/2) (RowGeometry.bin_parts)
    dense *= geometry.coverage(np.arange(H)[:, None], offsets[None, :]).astype(np.float32)[:, None, :]
    transport = Transport(dense, offsets, geometry)
    labels = np.where(on, 2, 1).astype(np.uint8)
    maps.update(
        vein_mask=vid > 0,
        vein_id=vid,
        vein_depth_mm=vdepth,
        vein_axis_depth_mm=(vdepth + 0.5 * vdiam).astype(np.float32),
        vein_diameter_mm=vdiam,
        skin=np.ascontiguousarray(on),
    )
    if curved:
        maps["surface_tilt_deg"] = np.broadcast_to(np.degrees(phi)[:, None], shape).astype(np.float32)
    params = {
        "tone": tone_name if tone_name is not None else float(melanin),
        "melanin_fraction": float(melanin),
        "wavelength_nm": int(skin.wavelength_nm),
        "hair": bool(hair),
        "curved": bool(curved),
        "mm_per_row": mm,
        "epidermis_mm": float(epidermis_mm),
        "dermis_mm": float(dermis_mm),
        "fat_mm": float(fat_mm),
        "surface_reflectance": float(surface_reflectance),
        "arm_radius_mm": float(arm_radius_mm),
        "hair_density_per_cm2": float(hair_density_per_cm2),
        "hair_reflectance": float(hair_reflectance),
        "cloth_albedo": float(cloth_albedo),
        "band_rows": int(band_rows),
        "blood_scale": float(blood_scale),
        "veins": [
            {
                "id": v["id"],
                "parent": v["parent"],
                "depth_mm": v["depth_mm"],
                "axis_depth_mm": v["depth_mm"] + 0.5 * v["diameter_mm"],
                "diameter_mm": v["diameter_mm"],
                "points_mm": np.round(v["points_mm"], 4).tolist(),
            }
            for v in veins
        ],
        "optics": skin.to_json(),
        "subsurface_total_reflectance": float(r_total),
    }
    return Scene("skin", transport, direct, ambient, labels, params, maps)
