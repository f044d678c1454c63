"""Five containers of white scattering media seen from above: the recognition scene (Sec. 8, Fig. 10).

Kubo et al. image fat-free milk, 2 % milk, whole milk, toothpaste and liquid soap in
containers on a table, all white and hard to tell apart in an ordinary photograph, and
recognize them per pixel from their delay profiles.  This scene is that experiment on the
simulated device.

Model
-----
* **Layout.**  Five containers (rectangular trays, or round cups with
  ``container="cup"``) on a matte table, three in a top row and two below, at the
  default geometry (0.3 mm per projector row: 720 rows span 216 mm).  ``placement=0``
  puts the materials in class order (:data:`planeray.optical_data.MATERIAL_CLASSES`,
  left to right, top to bottom); ``placement=k`` (``k >= 1``) shuffles the materials over
  the slots and moves and resizes the containers a little, reproducibly from ``k`` -- a
  different arrangement of the same materials for a test capture.
* **Media.**  Each container holds a homogeneous medium
  (:func:`planeray.optical_data.material_medium`: published coefficients of the milks,
  documented choices for toothpaste and soap; ``source`` and ``channel`` select the data
  set and the projector's laser colour, red by default).
* **Kernels.**  A container pixel's transport is the Monte Carlo line kernel of its
  medium (Henyey-Greenstein phase function, Fresnel top face) **with the container's
  walls present**: :func:`planeray.kernels.wall.mc_wall_table` traces, for pixels at 15
  distances from a vertical wall at 0, 45 and 90 degrees to the projector's lines, the
  light each lit line sends to the pixel (by reciprocity, a pencil beam at the pixel),
  so pixels near a wall see light lost through it (a clear wall with air behind:
  Fresnel reflection, the rest lost; ``wall="absorbing"``: a black wall) -- the boundary
  effect the paper names as the cause of its only errors.  The tables of the defaults
  ship with planeray.  A pixel's kernel is the slab kernel plus the wall's effect of
  each nearby wall (interpolated in distance and angle; the effects of two walls, at a
  tray's corners, are added), averaged over the projector rows its camera row spans
  (the distance to a wall moves with them), and is zero for lines that miss the
  container.  A kernel is in the scenes' unit: Lambertian-equivalent reflectance per
  offset (``pi`` x normal-view radiance x row size), so a white Lambertian surface
  would sum to 1.
* **Direct light.**  The liquids have smooth surfaces whose mirror reflection of the
  laser misses the camera: they have no direct (epipolar surface) component, only the
  light that entered them.  Toothpaste's rough surface returns its Fresnel reflection
  diffusely (``((n - 1) / (n + 1))^2 = 3.4 %``).  The table is a matte Lambertian
  surface (direct light only) with a faint texture.
* **Maps** (:attr:`Scene.maps`): ``"material"`` (class ids 1-5, 6 for the table),
  ``"wall_distance_mm"`` (distance of the pixel's centre to the nearest wall of its
  container; ``inf`` on the table) and ``"near_wall"`` (container pixels whose kernel
  the walls change by more than :data:`NEAR_WALL_CHANGE` in L1 norm).

Assumptions and approximations
------------------------------
* Walls are vertical planes, infinitely deep, the surface flat up to them (no meniscus,
  no rim shadow); a cup's wall is replaced near each pixel by its tangent plane (the
  cups' radius, ~30 mm, is several diffusion lengths of the milks; the tables hold wall
  angles 0, 45 and 90 degrees and the angle between is interpolated).
* The walls' effects add: exact far from corners; at a tray's corners and in a narrow
  container light reflected from one wall to the other is counted once.
* The milks and toothpaste are semi-infinite (their diffusion lengths, 1-11 mm, are
  small next to a container's depth); the soap is a 30 mm layer whose bottom loses the
  light that crosses it (:data:`planeray.optical_data.SOAP_DEPTH_MM`).
* The Monte Carlo kernels carry their own noise (10^6 photons for the slab, 10^5 per
  wall distance and angle, the wall's effect estimated against the same photons without
  the wall): a fixed property of the scene, not a per-capture noise.

References
----------
.. [1] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport: Capture and
   Analysis", IEEE TVCG 2019, Sec. 8 and Fig. 10.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..kernels.wall import mc_wall_table
from ..mc.wall import WALL_MODELS
from ..medium import Medium
from ..optical_data import BACKGROUND_CLASS, MATERIAL_CLASSES, OPTICAL_SOURCES, material_medium
from ..timing import RowGeometry
from ..transport import Transport
from ._textures import smooth_noise
from .base import DEFAULT_BAND_ROWS, DEFAULT_MM_PER_ROW, Scene, footprint_kernel, register_scene, scene_offsets

__all__ = ["build", "CONTAINERS", "NEAR_WALL_CHANGE", "container_layout", "material_tables", "tables_to_trace"]

#: Container shapes.
CONTAINERS = ("tray", "cup")
#: A container pixel is "near a wall" when the walls change its kernel by more than this (L1, relative).
NEAR_WALL_CHANGE = 0.05
#: Offsets of the shipped kernel tables (projector rows).
TABLE_REACH_ROWS = 192

# Slot centres (fractions of the field's height and width): three above, two below.
_SLOTS = ((0.27, 0.18), (0.27, 0.50), (0.27, 0.82), (0.73, 0.34), (0.73, 0.66))
_TRAY_HALF = (0.19, 0.14)  # half height, half width (fractions of the field's height, width)
_CUP_RADIUS = 0.15  # fraction of the smaller field side


def container_layout(shape, projector_rows, *, placement=0, container="tray", mm_per_row=DEFAULT_MM_PER_ROW) -> list:
    """The five containers: material, shape and extent in millimetres on the table.

    Coordinates are ``(x, y)`` = (down the image, across it) in mm from the field's top
    left corner; a camera row covers ``projector_rows / H`` projector rows of
    ``mm_per_row`` and camera pixels are square.

    Returns
    -------
    list of dict
        ``{"class_id", "shape", "centre_mm": [x, y], "half_mm": [hx, hy]}`` (a cup's
        radius is ``half_mm[0] == half_mm[1]``).
    """
    if container not in CONTAINERS:
        raise InputError(f"unknown container {container!r}; choose one of {', '.join(CONTAINERS)}")
    try:
        placement = int(placement)
    except (TypeError, ValueError):
        raise InputError(f"placement must be an integer >= 0, got {placement!r}") from None
    if placement < 0:
        raise InputError(f"placement must be an integer >= 0, got {placement}")
    H, W = shape
    geometry = RowGeometry(H, projector_rows)
    height_mm = geometry.projector_rows * mm_per_row
    width_mm = W * geometry.rows_per_camera_row * mm_per_row
    order = list(MATERIAL_CLASSES)
    jitter = np.zeros((5, 2))
    scale = np.ones(5)
    if placement > 0:
        rng = np.random.default_rng([placement, 0x4D415445])  # "MATE"
        while order == list(MATERIAL_CLASSES):
            order = [int(v) for v in rng.permutation(list(MATERIAL_CLASSES))]
        jitter = rng.uniform(-1.0, 1.0, size=(5, 2)) * (0.025, 0.012)
        scale = rng.uniform(0.88, 1.0, size=5)
    out = []
    for slot, cid in enumerate(order):
        cy, cx = _SLOTS[slot][0] + jitter[slot, 0], _SLOTS[slot][1] + jitter[slot, 1]
        centre = [cy * height_mm, cx * width_mm]
        if container == "tray":
            half = [_TRAY_HALF[0] * height_mm * scale[slot], _TRAY_HALF[1] * width_mm * scale[slot]]
        else:
            r = _CUP_RADIUS * min(height_mm, width_mm) * scale[slot]
            half = [r, r]
        out.append({"class_id": cid, "shape": container, "centre_mm": centre, "half_mm": half})
    return out


def material_tables(
    *, source="narasimhan", channel="red", wall="fresnel", mm_per_row=DEFAULT_MM_PER_ROW, progress=None
):
    """The wall-kernel tables of the five media (:func:`planeray.kernels.wall.mc_wall_table`), by class id.

    The defaults ship with planeray; other choices are traced once (minutes) and cached.
    """
    if wall not in WALL_MODELS:
        raise InputError(f"unknown wall model {wall!r}; choose one of {', '.join(WALL_MODELS)}")
    if source not in OPTICAL_SOURCES:
        raise InputError(f"unknown optical data source {source!r}; choose one of {', '.join(OPTICAL_SOURCES)}")
    offsets = np.arange(-TABLE_REACH_ROWS, TABLE_REACH_ROWS + 1)
    key = (source, channel, wall, float(mm_per_row))
    if key not in _TRACED:  # kept for the process: a read-only cache must not cost a second tracing
        _TRACED[key] = {
            cid: mc_wall_table(
                material_medium(cid, source=source, channel=channel),
                wall=wall,
                offsets_rows=offsets,
                mm_per_row=mm_per_row,
                progress=progress,
            )
            for cid in MATERIAL_CLASSES
        }
    return dict(_TRACED[key])


#: Tables of this process, by (source, channel, wall, mm per row).
_TRACED: dict = {}


def tables_to_trace(*, source="narasimhan", channel="red", wall="fresnel", mm_per_row=DEFAULT_MM_PER_ROW) -> list:
    """Class ids whose wall-kernel tables :func:`material_tables` would trace (neither shipped nor cached)."""
    from ..kernels.wall import wall_table_stored

    if (source, channel, wall, float(mm_per_row)) in _TRACED:
        return []
    offsets = np.arange(-TABLE_REACH_ROWS, TABLE_REACH_ROWS + 1)
    return [
        cid
        for cid in MATERIAL_CLASSES
        if not wall_table_stored(
            material_medium(cid, source=source, channel=channel), wall=wall, offsets_rows=offsets, mm_per_row=mm_per_row
        )
    ]


#: Kernel values computed per table lookup in :func:`_pixel_kernels` (bounds its memory: 32 MB of float64).
_KERNELS_PER_CALL = 4_000_000


def _pixel_kernels(table, distances_rows, angles_deg, signs, foot_offsets, foot, cos_phi):
    """Kernels ``(P, U_table)`` of pixels: the footprint average of the pencil beams of its projector rows.

    A pencil beam ``f`` projector rows below the pixel's centre is ``f cos(phi)`` rows
    closer to a wall on the positive side (``sign`` +1) and sees the offsets shifted by
    ``f``.  ``signs`` -1 mirror the table (the wall is on the side of negative offsets).
    """
    P = distances_rows.size
    U = table.offsets_rows.size
    out = np.zeros((P, U))
    pencils = [(f, w) for f, w in zip(foot_offsets, foot) if w > 0]
    # many pencils per table lookup (a camera row of a small image spans 45), in bounded memory
    per_call = max(1, _KERNELS_PER_CALL // max(1, P * U))
    for start in range(0, len(pencils), per_call):
        chunk = pencils[start : start + per_call]
        f = np.array([f for f, _ in chunk])[:, None]
        d = np.maximum(distances_rows - signs * f * cos_phi, 0.0)  # (pencils, P)
        k = table.kernels(d, angles_deg) - table.slab  # the wall's effect, (pencils, P, U) in the wall's frame
        k = np.where((signs < 0)[:, None], k[:, :, ::-1], k)  # back to the image's offsets
        for (f, w), k_f in zip(chunk, k):
            out += w * np.roll(k_f, int(f), axis=1)  # a pencil f rows down: offsets shift by f
    return out


@register_scene("materials", "five containers of white scattering media: milks, toothpaste, soap (Sec. 8, Fig. 10)")
def build(
    shape,
    projector_rows,
    seed,
    mm_per_row: float = DEFAULT_MM_PER_ROW,
    placement: int = 0,
    container: str = "tray",
    wall: str = "fresnel",
    source: str = "narasimhan",
    channel: str = "red",
    background_albedo: float = 0.3,
    band_rows: int = DEFAULT_BAND_ROWS,
    media: dict | None = None,
):
    """Build the scene.

    Parameters
    ----------
    mm_per_row : float
        Size of one projector row on the table, mm (the shipped tables: 0.3).
    placement : int
        0: the materials in class order; ``k >= 1``: shuffled over the slots, the
        containers moved and resized (reproducible from ``k``).
    container : {"tray", "cup"}
        Rectangular trays (walls parallel and perpendicular to the projector's lines) or
        round cups.
    wall : {"fresnel", "absorbing"}
        Clear walls with air behind them, or black walls.
    source : {"narasimhan", "jensen"}
        Optical data set of the milks (:mod:`planeray.optical_data`).
    channel : {"red", "green", "blue"}
        Colour of the projector's line.
    background_albedo : float
        Mean albedo of the matte table.
    band_rows : int
        Half-width of the dense offset band (projector rows), at most 188.
    media : dict, optional
        Replace media: ``{class_id: Medium}`` (traced and cached on first use).
    """
    H, W = shape
    geometry = RowGeometry(H, projector_rows)
    rpc = geometry.rows_per_camera_row
    mm = float(mm_per_row)
    if not mm > 0:
        raise InputError(f"mm_per_row must be positive, got {mm_per_row!r}")
    if channel not in ("red", "green", "blue"):
        raise InputError(f"unknown colour channel {channel!r}; choose one of red, green, blue")
    layout = container_layout(shape, projector_rows, placement=placement, container=container, mm_per_row=mm)
    half_foot = int(np.ceil(0.5 * rpc + 0.5))
    band = max(int(band_rows), int(np.ceil(rpc)) + 1)
    if band + half_foot > TABLE_REACH_ROWS:
        raise InputError(
            f"band_rows {band_rows} too wide for the kernel tables (at most {TABLE_REACH_ROWS - half_foot})"
        )
    offsets = scene_offsets(band)
    U = offsets.size
    tables = material_tables(source=source, channel=channel, wall=wall, mm_per_row=mm)
    for cid, medium in (media or {}).items():
        if int(cid) not in MATERIAL_CLASSES or not isinstance(medium, Medium):
            raise InputError(f"media must map class ids {sorted(MATERIAL_CLASSES)} to planeray.Medium, got {cid!r}")
        tables[int(cid)] = mc_wall_table(medium, wall=wall, offsets_rows=tables[1].offsets_rows, mm_per_row=mm)

    rng = np.random.default_rng(seed)
    foot_offsets = np.arange(-half_foot, half_foot + 1)
    foot = footprint_kernel(foot_offsets, rpc)
    foot_full = footprint_kernel(offsets, rpc).astype(np.float32)
    t_off = tables[1].offsets_rows
    sel = np.searchsorted(t_off, offsets)  # band offsets within the table's

    # Pixel centres: projector coordinate of each camera row, in mm down and across.
    p_t = geometry.projector_row_of(np.arange(H)).astype(np.float64)
    x_mm = (p_t + 0.5) * mm
    y_mm = (np.arange(W) + 0.5) * rpc * mm
    material = np.full((H, W), BACKGROUND_CLASS, np.uint8)
    wall_mm = np.full((H, W), np.inf, np.float32)
    near = np.zeros((H, W), bool)
    table_albedo = np.clip(background_albedo * (1.0 + smooth_noise((H, W), rng, H / 8.0, 0.06)), 0.02, 1.0)
    direct = table_albedo.astype(np.float32)
    dense = np.zeros((H, W, U), np.float32)
    ambient = table_albedo.astype(np.float32)

    for box in layout:
        cid = box["class_id"]
        tab = tables[cid]
        med = tab.medium
        (cx, cy), (hx, hy) = box["centre_mm"], box["half_mm"]
        dx = x_mm[:, None] - cx
        dy = y_mm[None, :] - cy
        if box["shape"] == "tray":
            inside = (np.abs(dx) < hx) & (np.abs(dy) < hy)
        else:
            inside = np.hypot(dx, dy) < hx
        rows, cols = np.nonzero(inside)
        if rows.size == 0:
            continue
        # Slab kernel seen by a camera row (footprint-convolved), on the table's offsets.
        slab_fp = np.convolve(tab.slab, foot, mode="same")
        pert = np.zeros((rows.size, t_off.size))
        if box["shape"] == "tray":
            # Walls parallel to the lines (above and below: angle 0) and across them (angle 90).
            ur, inv_r = np.unique(rows, return_inverse=True)
            d_down = (cx + hx - x_mm[ur]) / mm  # to the wall below (positive offsets)
            d_up = (x_mm[ur] - (cx - hx)) / mm
            for dist, sign in ((d_down, 1.0), (d_up, -1.0)):
                k = _pixel_kernels(tab, dist, np.zeros_like(dist), np.full_like(dist, sign), foot_offsets, foot, 1.0)
                pert += k[inv_r]
            uc, inv_c = np.unique(cols, return_inverse=True)
            for dist in ((cy + hy - y_mm[uc]) / mm, (y_mm[uc] - (cy - hy)) / mm):
                k = _pixel_kernels(tab, dist, np.full_like(dist, 90.0), np.ones_like(dist), foot_offsets, foot, 0.0)
                pert += k[inv_c]
            dist_mm = np.minimum.reduce(
                [cx + hx - x_mm[rows], x_mm[rows] - cx + hx, cy + hy - y_mm[cols], y_mm[cols] - cy + hy]
            )
            lo, hi = cx - hx, cx + hx
        else:
            ddx, ddy = x_mm[rows] - cx, y_mm[cols] - cy
            r = np.hypot(ddx, ddy)
            dist_mm = hx - r
            phi = np.degrees(np.arctan2(np.abs(ddy), np.abs(ddx)))
            sign = np.where(ddx >= 0, 1.0, -1.0)
            pert += _pixel_kernels(tab, dist_mm / mm, phi, sign, foot_offsets, foot, np.cos(np.radians(phi)))
            lo, hi = cx - hx, cx + hx
        kern = np.clip(slab_fp[None, :] + pert, 0.0, None)
        change = np.abs(kern - slab_fp[None, :]).sum(axis=1) / slab_fp.sum()
        # Lines that miss the container light nothing in it.
        lo_p, hi_p = lo / mm - 0.5, hi / mm - 0.5  # container rows in projector coordinates
        v = p_t[rows][:, None] + offsets[None, :]
        hit = ((v + 0.5) > lo_p) & ((v - 0.5) < hi_p)
        band_k = kern[:, sel] * hit
        surface = 0.0
        if cid == 4:  # toothpaste: a rough surface returns its Fresnel reflection diffusely
            surface = ((med.n - 1.0) / (med.n + 1.0)) ** 2
        dense[rows, cols] = (band_k + surface * foot_full[None, :]).astype(np.float32)
        direct[rows, cols] = surface
        ambient[rows, cols] = surface + kern.sum(axis=1)
        material[rows, cols] = cid
        wall_mm[rows, cols] = dist_mm
        near[rows, cols] = change > NEAR_WALL_CHANGE

    background = material == BACKGROUND_CLASS
    dense[background] = direct[background][:, None] * foot_full[None, :]
    transport = Transport(dense, offsets, geometry)
    labels = np.where(background, 1, 2).astype(np.uint8)
    params = {
        "mm_per_row": mm,
        "placement": int(placement),
        "container": container,
        "wall": wall,
        "source": source,
        "channel": channel,
        "background_albedo": float(background_albedo),
        "band_rows": int(band_rows),
        "containers": [
            {
                "class_id": b["class_id"],
                "name": MATERIAL_CLASSES[b["class_id"]],
                "shape": b["shape"],
                "centre_mm": [float(v) for v in b["centre_mm"]],
                "half_mm": [float(v) for v in b["half_mm"]],
            }
            for b in layout
        ],
        "media": {str(cid): tables[cid].medium.to_dict() for cid in MATERIAL_CLASSES},
    }
    maps = {"material": material, "wall_distance_mm": wall_mm, "near_wall": near}
    return Scene("materials", transport, direct.astype(np.float32), ambient.astype(np.float32), labels, params, maps)
