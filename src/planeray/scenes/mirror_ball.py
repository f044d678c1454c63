"""A mirror ball resting on a book page: specular interreflection with a bimodal delay profile (Fig. 9).

Model
-----
Top-down orthographic geometry: the page is the plane ``z = 0`` (printed-text
albedo), a mirror sphere of radius ``R`` rests on it at the image centre (centre
at height ``z = R``).  Projector and camera rays are both vertical (direction
``d = (0, 0, -1)``), so epipolar planes are ``y = const`` (image rows) and the
projector coordinate of a point is ``y / mm_per_row - 1/2``; one camera pixel is
``rows_per_camera_row * mm_per_row`` mm on a side.

* **Page -> camera (direct)**: a page pixel has ``T = albedo`` spread over its
  row footprint, times the fraction of the pixel not covered by the ball's image
  disk (the page under the ball is both shadowed and hidden).
* **Projector -> ball -> page -> camera** (forward splat): each projector ray
  hitting the sphere at normal ``n`` reflects to ``r = d - 2 (d.n) n``; rays with
  ``r_z < 0`` (the outer ring ``rho > R / sqrt 2``) hit the page at ``q``.  The ray
  carries the beam cross-section ``dA`` of its sample, so the page pixel of ``q``
  gets ``T += rho_m albedo(q) dA / A_px`` (flux conservation: a pixel lit directly
  by the full beam gets ``albedo``) at offset ``u = v_sample - p_t(q)``.  Splats
  landing inside the ball's image disk are hidden and dropped, as are points
  outside the field of view (the projector lights only the camera's field).
  The sphere's disk is sampled with ``n_splat x n_splat`` jittered samples per
  pixel.  For the smooth sphere the default replaces this Monte Carlo splat by
  its exact inverse (gather): the page point at radius ``rho_q`` receives from
  the sphere point of the same azimuth with ``rho_q(beta) = rho_q`` (``rho = R
  sin beta``), with irradiance ``rho_m rho |d rho| / (rho_q |d rho_q|)`` of the
  projector's (flux conservation), evaluated on ``n x n`` points per page pixel.
* **Projector -> page -> ball -> camera**: a ball pixel sees the page point ``q``
  hit by its reflected camera ray; ``q`` is lit by its own projector row, so the
  pixel gets ``T = rho_m albedo(q)`` at offset ``u = v(q) - p_t``; rays with
  ``r_z >= 0`` see the (dark) room.  Averaged over ``n_cam x n_cam`` samples per pixel.
* The ball has a faint diffuse reflectance (dust) as its direct term.

A page pixel just beyond the ball therefore has two peaks in its delay profile:
its own diffuse reflection at ``u = 0`` and the mirror's reflection from the
sphere point in the same radial direction, displaced by ``rho_q - rho`` (Fig. 9).
The second peak is weak -- a few percent of the first (at most ~4 % of the
direct light, reached ~1.5 R from the centre): a convex mirror spreads a
collimated beam evenly over all directions (intensity ``rho_m E0 R^2 / 4`` per
steradian), and in this coaxial geometry the rays reaching the page near the
ball arrive at grazing incidence.  Ball pixels, in contrast, carry the full
``rho_m albedo(q)`` at a displaced offset next to their faint diffuse peak at 0.
Labels: ball pixels that see the page and page pixels whose specular light
exceeds ``label_fraction`` (2 %) of their direct light are
``specular_interreflection`` (4); ball pixels that see only the room are ``none`` (0).

Approximations: orthographic, coaxial projector and camera; one specular bounce
(no page -> ball -> page -> ball paths); the page is purely Lambertian (no
paper subsurface); splats are deposited into the pixel containing ``q``.
Entries outside the dense band become sparse long-range entries.

The ray-sphere machinery here (:func:`trace_sphere`) is shared with the
``disco_ball`` scene, which supplies faceted normals.

References
----------
.. [1] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport", TVCG
   2019, Sec. 8 and Fig. 9 ("the specular interreflection has a bimodal peak").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..timing import RowGeometry
from ..transport import Transport
from ._textures import printed_page, smooth_noise
from .base import DEFAULT_BAND_ROWS, DEFAULT_MM_PER_ROW, Scene, footprint_kernel, register_scene, scene_offsets

__all__ = ["build", "SphereTrace", "trace_sphere", "smooth_normals", "gather_resting_sphere", "sphere_scene_transport"]


@dataclass
class SphereTrace:
    """Result of :func:`trace_sphere`.

    ``coverage``: fraction of each pixel covered by the ball's image disk;
    ``ball_direct``: the ball's own diffuse (direct) reflection, per pixel;
    ``row, col, offset, value``: aggregated specular entries (integer offsets);
    ``splat``: specular transport received by each pixel from page/wall splats
    (summed over offsets); ``seen``: same for ball pixels seeing the wall/page.
    """

    coverage: np.ndarray
    ball_direct: np.ndarray
    row: np.ndarray
    col: np.ndarray
    offset: np.ndarray
    value: np.ndarray
    splat: np.ndarray
    seen: np.ndarray

    def add(self, row, col, offset, value):
        """Add specular entries received by the plane (``splat``) and re-aggregate."""
        H, W = self.coverage.shape
        np.add.at(self.splat, (row, col), value)
        rows = np.concatenate([self.row, row])
        cols = np.concatenate([self.col, col])
        k = np.concatenate([self.offset, offset]).astype(np.int64)
        vals = np.concatenate([self.value, value])
        lo = int(k.min()) if k.size else 0
        self.row, self.col, self.offset, self.value = _aggregate(H, W, lo, rows, cols, k, vals)


def smooth_normals(nx, ny, nz):
    """A perfect mirror sphere: reflect with the true normal everywhere."""
    return nx, ny, nz, np.ones(nx.shape, bool)


def _aggregate(H, W, span_lo, rows, cols, k, vals):
    """Sum duplicate (row, col, integer offset) entries."""
    if rows.size == 0:
        return rows, cols, k, vals
    span = int(k.max() - span_lo + 1)
    key = (rows.astype(np.int64) * W + cols) * span + (k - span_lo)
    uniq, inv = np.unique(key, return_inverse=True)
    summed = np.bincount(inv.ravel(), vals)
    pix, kk = np.divmod(uniq, span)
    r, c = np.divmod(pix, W)
    return r, c, kk + span_lo, summed


def trace_sphere(
    shape,
    geometry: RowGeometry,
    mm_per_row: float,
    albedo: np.ndarray,
    centre_xy_mm,
    radius_mm: float,
    centre_z_mm: float,
    normals=smooth_normals,
    mirror_reflectance: float = 0.9,
    diffuse_reflectance=0.01,
    n_cam: int = 6,
    n_splat: int = 12,
    rng: np.random.Generator | None = None,
) -> SphereTrace:
    """Specular transport of a (possibly faceted) mirror sphere above a Lambertian plane ``z = 0``.

    Parameters
    ----------
    shape : (H, W)
        Camera image.
    geometry : RowGeometry
        Camera/projector rows; a pixel is ``rows_per_camera_row * mm_per_row`` mm wide and high.
    albedo : ndarray (H, W)
        Albedo of the plane ``z = 0`` as seen in each pixel.
    centre_xy_mm, radius_mm, centre_z_mm : float
        Sphere centre in the image plane (mm from the top-left corner), radius and
        height above the plane.
    normals : callable ``(nx, ny, nz) -> (fx, fy, fz, mirror)``
        Reflecting normal (and a mirror mask; ``False`` = grout) for sphere normals.
    mirror_reflectance : float
        Reflectance of the mirror.
    diffuse_reflectance : float or callable ``(mirror_mask) -> array``
        Diffuse reflectance of the ball surface (direct term).
    n_cam, n_splat : int
        Samples per pixel side for ball pixels (regular) and for the forward splat (jittered).
    rng : numpy.random.Generator, optional
        Jitter of the splat samples; ``None``: regular grid.
    """
    H, W = shape
    pix = geometry.rows_per_camera_row * mm_per_row
    cx, cy = float(centre_xy_mm[0]), float(centre_xy_mm[1])
    R, zc = float(radius_mm), float(centre_z_mm)
    p_t = geometry.projector_row_of(np.arange(H))
    alb = np.asarray(albedo, dtype=np.float64)

    r0, r1 = max(0, int(np.floor((cy - R) / pix))), min(H, int(np.ceil((cy + R) / pix)) + 1)
    c0, c1 = max(0, int(np.floor((cx - R) / pix))), min(W, int(np.ceil((cx + R) / pix)) + 1)
    br, bc = np.meshgrid(np.arange(r0, r1), np.arange(c0, c1), indexing="ij")
    br, bc = br.ravel(), bc.ravel()

    def shade(x, y):
        """Sphere normal, facet normal and reflected ray for image points (x, y) mm."""
        nx, ny = (x - cx) / R, (y - cy) / R
        rho2 = nx * nx + ny * ny
        inside = rho2 < 1.0
        nz = np.sqrt(np.clip(1.0 - rho2, 0.0, None))
        fx, fy, fz, mirror = normals(nx, ny, nz)
        rx, ry, rz = 2 * fz * fx, 2 * fz * fy, 2 * fz * fz - 1.0  # r = d - 2 (d.f) f, d = -z
        outward = rx * nx + ry * ny + rz * nz > 0.0
        valid = inside & mirror & (rz < 0.0) & outward
        lam = np.where(valid, (zc + R * nz) / np.where(valid, -rz, 1.0), 0.0)
        qx, qy = x + lam * rx, y + lam * ry
        # Visible, lit plane: inside the field of view and outside the ball's disk.
        qc, qr = np.floor(qx / pix).astype(np.int64), np.floor(qy / pix).astype(np.int64)
        ok = valid & (qc >= 0) & (qc < W) & (qr >= 0) & (qr < H) & ((qx - cx) ** 2 + (qy - cy) ** 2 >= R * R)
        return inside, nz, mirror, ok, qx, qy, np.clip(qr, 0, H - 1), np.clip(qc, 0, W - 1)

    ent_r, ent_c, ent_k, ent_v = [], [], [], []
    coverage = np.zeros(shape)
    ball_direct = np.zeros(shape)
    seen = np.zeros(shape)
    splat = np.zeros(shape)
    to_proj = lambda y_mm: y_mm / mm_per_row - 0.5  # noqa: E731

    # Ball pixels: regular n_cam x n_cam samples, averaged.
    for i in range(n_cam):
        for j in range(n_cam):
            y = (br + (i + 0.5) / n_cam) * pix
            x = (bc + (j + 0.5) / n_cam) * pix
            inside, nz, mirror, ok, qx, qy, qr, qc = shade(x, y)
            w = 1.0 / (n_cam * n_cam)
            np.add.at(coverage, (br, bc), w * inside)
            diff = diffuse_reflectance(mirror) if callable(diffuse_reflectance) else diffuse_reflectance
            np.add.at(ball_direct, (br, bc), w * inside * diff * nz)
            v = w * mirror_reflectance * alb[qr[ok], qc[ok]]
            ent_r.append(br[ok])
            ent_c.append(bc[ok])
            ent_k.append(np.floor(to_proj(qy[ok]) - p_t[br[ok]] + 0.5).astype(np.int64))
            ent_v.append(v)
            np.add.at(seen, (br[ok], bc[ok]), v)

    # Forward splat of the projector's rays off the sphere onto the plane.
    for i in range(n_splat):
        for j in range(n_splat):
            jy = rng.uniform(size=br.size) if rng is not None else 0.5
            jx = rng.uniform(size=br.size) if rng is not None else 0.5
            y = (br + (i + jy) / n_splat) * pix
            x = (bc + (j + jx) / n_splat) * pix
            inside, nz, mirror, ok, qx, qy, qr, qc = shade(x, y)
            qr, qc = qr[ok], qc[ok]
            v = mirror_reflectance * alb[qr, qc] / (n_splat * n_splat)
            ent_r.append(qr)
            ent_c.append(qc)
            ent_k.append(np.floor(to_proj(y[ok]) - p_t[qr] + 0.5).astype(np.int64))
            ent_v.append(v)
            np.add.at(splat, (qr, qc), v)

    rows, cols = np.concatenate(ent_r), np.concatenate(ent_c)
    k, vals = np.concatenate(ent_k), np.concatenate(ent_v)
    lo = int(k.min()) if k.size else 0
    rows, cols, k, vals = _aggregate(H, W, lo, rows, cols, k, vals)
    return SphereTrace(coverage, ball_direct, rows, cols, k, vals, splat, seen)


def _reflection_radius(beta, R):
    """Page radius ``rho_q`` hit by the ray reflected at polar angle ``beta`` of a sphere resting
    on the page, and ``d rho_q / d beta`` (vertical rays; ``beta`` in ``(pi/4, pi/2]``)."""
    sb, cb, t2 = np.sin(beta), np.cos(beta), np.tan(2 * beta)
    rq = R * sb - R * (1.0 + cb) * t2
    drq = R * cb + R * sb * t2 - 2.0 * R * (1.0 + cb) / np.cos(2 * beta) ** 2
    return rq, drq


def gather_resting_sphere(
    shape, geometry, mm_per_row, albedo, centre_xy_mm, radius_mm, mirror_reflectance, n_gather, coverage
):
    """Specular light a smooth mirror sphere resting on the page throws onto each page pixel.

    The noise-free counterpart of the forward splat: the page point at radius
    ``rho_q > R`` from the contact point receives the ray reflected at the sphere
    point of polar angle ``beta`` with ``rho_q(beta) = rho_q`` (same azimuth), with
    irradiance ``E0 rho_m rho |d rho| / (rho_q |d rho_q|)`` (flux conservation between
    the annulus ``rho = R sin(beta)`` of the beam and the page).  Each page pixel is
    sampled with ``n_gather x n_gather`` points; every point contributes at the
    offset of its sphere point's projector row.

    Returns
    -------
    row, col, offset, value : ndarray
        Entries (integer offsets), summed over identical keys by the caller.
    """
    H, W = shape
    pix = geometry.rows_per_camera_row * mm_per_row
    cx, cy = float(centre_xy_mm[0]), float(centre_xy_mm[1])
    R = float(radius_mm)
    p_t = geometry.projector_row_of(np.arange(H))
    # Inverse table of rho_q(beta), refined by Newton steps.
    s = np.linspace(0.0, 1.0, 4097)[1:-1] ** 2
    beta_tab = 0.5 * np.pi - 0.25 * np.pi * s  # from the limb (rho_q = R) inward
    rq_tab, _ = _reflection_radius(beta_tab, R)
    visible = coverage < 1.0
    rr, cc = np.nonzero(visible)
    rows_l, cols_l, k_l, v_l = [], [], [], []
    for i in range(n_gather):
        for j in range(n_gather):
            y = (rr + (i + 0.5) / n_gather) * pix
            x = (cc + (j + 0.5) / n_gather) * pix
            dx, dy = x - cx, y - cy
            rho_q = np.hypot(dx, dy)
            hit = (rho_q > R) & (rho_q < rq_tab[-1])
            rq = rho_q[hit]
            beta = np.interp(rq, rq_tab, beta_tab)
            for _ in range(3):
                f, df = _reflection_radius(beta, R)
                beta = np.clip(beta - (f - rq) / df, 0.25 * np.pi + 1e-9, 0.5 * np.pi)
            f, df = _reflection_radius(beta, R)
            rho = R * np.sin(beta)
            density = rho * R * np.cos(beta) / (rq * np.abs(df))
            y_src = cy + dy[hit] * (rho / rq)
            r_hit, c_hit = rr[hit], cc[hit]
            rows_l.append(r_hit)
            cols_l.append(c_hit)
            k_l.append(np.floor(y_src / mm_per_row - p_t[r_hit]).astype(np.int64))
            v_l.append(mirror_reflectance * albedo[r_hit, c_hit] * density / (n_gather * n_gather))
    return np.concatenate(rows_l), np.concatenate(cols_l), np.concatenate(k_l), np.concatenate(v_l)


def sphere_scene_transport(shape, geometry, albedo, trace: SphereTrace, band_rows):
    """Dense direct term (plane outside the ball + ball's diffuse) plus the specular entries."""
    rpc = geometry.rows_per_camera_row
    offsets = scene_offsets(max(int(band_rows), int(np.ceil(rpc)) + 1))
    direct = ((1.0 - trace.coverage) * albedo + trace.ball_direct).astype(np.float32)
    foot = footprint_kernel(offsets, rpc).astype(np.float32)
    dense = direct[:, :, None] * foot[None, None, :]
    transport = Transport.from_entries(
        shape, offsets, trace.row, trace.col, trace.offset, trace.value, geometry=geometry, dense=dense
    )
    return transport, direct


@register_scene("mirror_ball", "mirror ball on a book page: specular interreflection (bimodal delay profile, Fig. 9)")
def build(
    shape,
    projector_rows,
    seed,
    mm_per_row: float = DEFAULT_MM_PER_ROW,
    radius: float = 0.18,
    mirror_reflectance: float = 0.9,
    ball_diffuse: float = 0.08,
    n_cam: int = 6,
    n_splat: int = 0,
    band_rows: int = DEFAULT_BAND_ROWS,
    label_fraction: float = 0.02,
):
    """Build the scene.

    Parameters
    ----------
    mm_per_row : float
        Size of one projector row on the page, mm.
    radius : float
        Sphere radius as a fraction of the image height.
    mirror_reflectance, ball_diffuse : float
        Specular and diffuse reflectance of the ball (a chrome ball with a dull,
        dusty finish: its diffuse part gives ball pixels a peak at u = 0 beside the
        displaced specular one, a clearly bimodal delay profile).
    n_cam, n_splat : int
        Samples per pixel side for ball pixels and for the forward splat; ``n_splat = 0``
        (default) replaces the splat by the exact, noise-free gather
        (:func:`gather_resting_sphere`), which gives the same transport without noise.
    band_rows : int
        Half-width of the dense offset band; farther entries are sparse.
    label_fraction : float
        Page pixels whose specular light exceeds this fraction of their direct
        light are labelled ``specular_interreflection``.
    """
    H, W = shape
    rng = np.random.default_rng(seed)
    geometry = RowGeometry(H, projector_rows)
    pix = geometry.rows_per_camera_row * mm_per_row
    albedo = printed_page(shape, rng) * (1.0 + smooth_noise(shape, rng, H / 8.0, 0.04))
    albedo = np.clip(albedo, 0.02, 0.95)
    R = radius * H * pix
    centre = (0.5 * W * pix, 0.5 * H * pix)
    trace = trace_sphere(
        shape,
        geometry,
        mm_per_row,
        albedo,
        centre,
        R,
        R,
        smooth_normals,
        mirror_reflectance,
        ball_diffuse,
        n_cam,
        n_splat,
        rng,
    )
    if n_splat == 0:  # exact gather instead of the forward splat
        n_gather = max(4, int(np.ceil(geometry.rows_per_camera_row)))
        trace.add(
            *gather_resting_sphere(
                shape, geometry, mm_per_row, albedo, centre, R, mirror_reflectance, n_gather, trace.coverage
            )
        )
    transport, direct = sphere_scene_transport(shape, geometry, albedo, trace, band_rows)
    ball = trace.coverage > 0.5
    page_direct = (1.0 - trace.coverage) * albedo
    labels = np.ones(shape, np.uint8)
    labels[(trace.splat + trace.seen > label_fraction * page_direct) & ~ball] = 4
    labels[ball] = np.where(trace.seen[ball] > 0, 4, 0)
    ambient = ((1.0 - trace.coverage) * albedo + trace.coverage * (mirror_reflectance * 0.5 + ball_diffuse)).astype(
        np.float32
    )
    params = {
        "mm_per_row": float(mm_per_row),
        "radius": float(radius),
        "radius_mm": float(R),
        "mirror_reflectance": float(mirror_reflectance),
        "ball_diffuse": float(ball_diffuse),
        "n_cam": int(n_cam),
        "n_splat": int(n_splat),
        "band_rows": int(band_rows),
        "label_fraction": float(label_fraction),
    }
    return Scene("mirror_ball", transport, direct, ambient, labels, params)
