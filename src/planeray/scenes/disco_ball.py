"""A disco ball in front of a wall: specular interreflections that move vertically with delay (Fig. 8).

Model
-----
Orthographic view of a diffuse back wall ``z = 0`` (textured albedo) with the
projector and camera rays along ``-z`` (epipolar planes ``y = const``, see
:mod:`planeray.scenes.mirror_ball`).  A faceted mirror sphere of radius ``R``
hangs at the image centre, its centre at distance ``D`` (default ``1.5 R``) from
the wall, its axis vertical (image ``y``).

* **Facets**: ``n_lat`` latitude bands; band ``i`` holds
  ``max(4, round(n_lon cos(phi_i)))`` facets (as on a real disco ball, facets stay
  roughly square toward the poles), alternate bands staggered by half a facet.
  Each facet is a flat mirror whose normal is the sphere normal at its centre,
  tilted by a small random angle (``facet_tilt_deg``, seeded: hand-glued tiles).
  Hit points are taken on the sphere (the facet's sagitta is neglected).
  Dark grout lines of width ``grout`` (fraction of the facet size) separate the
  facets; grout and facets have a faint diffuse reflectance (the ball's direct term).
* **Projector -> facet -> wall -> camera**: every ray reflects with its facet's
  normal, so a facet throws a displaced copy of its own footprint -- a spot --
  onto the wall.  Rays with ``r_z < 0`` reach the wall; the flux is splatted
  exactly as for the mirror ball (energy-conserving, ``n_splat^2`` jittered
  samples per pixel) at offset ``u = v_facet - p_t(wall pixel)``.  Spots behind
  the ball's image disk are hidden and dropped.
* **Projector -> wall -> facet -> camera**: a ball pixel sees the wall point its
  reflected ray hits (lit by its own row unless it lies in the ball's shadow,
  the image disk), ``T = rho_m albedo(q)`` at ``u = v(q) - p_t``.
* The wall's direct term is its albedo outside the ball's image disk (the
  coaxial projector's shadow of the ball coincides with the disk).

Each spot's light comes from a projector row a fixed distance away (the facet's
rows), so a band centred at ``I_d`` shows only the spots thrown ``I_d`` rows up
(positive delay: the source lies below) and, as the delay grows, the set of
visible spots changes and they appear to move vertically (Fig. 8).

Approximations: orthographic coaxial projector and camera, one specular bounce,
hit points on the sphere rather than on the planar facets, nearest-pixel splats.

References
----------
.. [1] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport", TVCG
   2019, Sec. 7 and Fig. 8.
"""

from __future__ import annotations

import numpy as np

from ..timing import RowGeometry
from ._textures import smooth_noise, wallpaper
from .base import DEFAULT_BAND_ROWS, DEFAULT_MM_PER_ROW, Scene, register_scene
from .mirror_ball import sphere_scene_transport, trace_sphere

__all__ = ["build", "FacetedSphere"]


class FacetedSphere:
    """Lat-long facets of a disco ball; call with sphere normals ``(nx, ny, nz)``.

    ``y`` points down the image, ``z`` toward the camera; latitude is measured
    from the equator upward (``phi = arcsin(-ny)``), longitude around the vertical
    axis (``theta = atan2(nx, nz)``).
    """

    def __init__(self, n_lat=12, n_lon=24, grout=0.08, tilt_deg=0.0, rng=None):
        self.n_lat = int(n_lat)
        self.grout = float(grout)
        phi_c = -0.5 * np.pi + (np.arange(self.n_lat) + 0.5) * np.pi / self.n_lat
        self.phi_c = phi_c
        self.n_lon = np.maximum(4, np.rint(n_lon * np.cos(phi_c))).astype(int)
        self.stagger = 0.5 * (np.arange(self.n_lat) % 2)
        self.facet_size = np.pi / self.n_lat  # angular height of a band (radians)
        n_max = int(self.n_lon.max())
        tilt = np.deg2rad(tilt_deg)
        if rng is not None and tilt > 0:
            self.tilt = tilt * rng.standard_normal((self.n_lat, n_max, 2))
        else:
            self.tilt = np.zeros((self.n_lat, n_max, 2))

    def __call__(self, nx, ny, nz):
        phi = np.arcsin(np.clip(-ny, -1.0, 1.0))
        theta = np.arctan2(nx, nz)
        band = np.clip(np.floor((phi + 0.5 * np.pi) / np.pi * self.n_lat).astype(int), 0, self.n_lat - 1)
        n_lon = self.n_lon[band]
        pos = (theta + np.pi) / (2 * np.pi) * n_lon + self.stagger[band]
        j = np.floor(pos).astype(int)
        frac_lon = pos - j
        j = j % n_lon
        theta_c = (j + 0.5 - self.stagger[band]) / n_lon * 2 * np.pi - np.pi
        phi_c = self.phi_c[band] + self.tilt[band, j, 0]
        theta_c = theta_c + self.tilt[band, j, 1]
        fx = np.cos(phi_c) * np.sin(theta_c)
        fy = -np.sin(phi_c)
        fz = np.cos(phi_c) * np.cos(theta_c)
        # Grout: arc distance to the facet border below half the grout width.
        frac_lat = (phi + 0.5 * np.pi) / np.pi * self.n_lat - band
        half = 0.5 * self.grout
        lat_edge = np.minimum(frac_lat, 1.0 - frac_lat)
        lon_edge = np.minimum(frac_lon, 1.0 - frac_lon) * (2 * np.pi / n_lon) * np.cos(phi) / self.facet_size
        mirror = (lat_edge > half) & (lon_edge > half)
        return fx, fy, fz, mirror


@register_scene("disco_ball", "disco ball: specular interreflections that move vertically with delay (Fig. 8)")
def build(
    shape,
    projector_rows,
    seed,
    mm_per_row: float = DEFAULT_MM_PER_ROW,
    radius: float = 0.2,
    distance: float = 1.5,
    n_lat: int = 12,
    n_lon: int = 24,
    grout: float = 0.1,
    facet_tilt_deg: float = 0.5,
    mirror_reflectance: float = 0.85,
    facet_diffuse: float = 0.02,
    grout_albedo: float = 0.08,
    n_cam: int = 6,
    n_splat: int = 8,
    band_rows: int = DEFAULT_BAND_ROWS,
    label_fraction: float = 0.05,
):
    """Build the scene.

    Parameters
    ----------
    mm_per_row : float
        Size of one projector row on the wall, mm.
    radius : float
        Ball radius as a fraction of the image height.
    distance : float
        Distance from the ball's centre to the wall, in ball radii (> 1).
    n_lat, n_lon : int
        Latitude bands and facets around the equator.
    grout : float
        Width of the grout lines as a fraction of the facet size.
    facet_tilt_deg : float
        Standard deviation of the random tilt of each facet (degrees).
    mirror_reflectance, facet_diffuse, grout_albedo : float
        Facet specular reflectance, facet diffuse reflectance and grout albedo.
    n_cam, n_splat : int
        Samples per pixel side for ball pixels and for the forward splat.
    band_rows : int
        Half-width of the dense offset band; farther entries are sparse.
    label_fraction : float
        Wall pixels whose specular light exceeds this fraction of their direct light
        are spot pixels (``specular_interreflection``).
    """
    if distance <= 1.0:
        raise ValueError(f"the ball must hang in front of the wall: distance > 1 radius, got {distance}")
    H, W = shape
    rng = np.random.default_rng(seed)
    geometry = RowGeometry(H, projector_rows)
    pix = geometry.rows_per_camera_row * mm_per_row
    albedo = wallpaper(shape, rng, mean=0.6, amplitude=0.08, stripes=6.0)
    albedo = np.clip(albedo * (1.0 + smooth_noise(shape, rng, H / 16.0, 0.04)), 0.05, 0.95)
    facets = FacetedSphere(n_lat, n_lon, grout, facet_tilt_deg, rng)
    R = radius * H * pix
    centre = (0.5 * W * pix, 0.5 * H * pix)

    def diffuse(mirror):
        return np.where(mirror, facet_diffuse, grout_albedo)

    trace = trace_sphere(
        shape,
        geometry,
        mm_per_row,
        albedo,
        centre,
        R,
        distance * R,
        facets,
        mirror_reflectance,
        diffuse,
        n_cam,
        n_splat,
        rng,
    )
    transport, direct = sphere_scene_transport(shape, geometry, albedo, trace, band_rows)
    ball = trace.coverage > 0.5
    wall_direct = (1.0 - trace.coverage) * albedo
    labels = np.ones(shape, np.uint8)
    labels[(trace.splat + trace.seen > label_fraction * wall_direct) & ~ball] = 4
    labels[ball] = 4
    ambient = ((1.0 - trace.coverage) * albedo + trace.coverage * (mirror_reflectance * 0.5)).astype(np.float32)
    params = {
        "mm_per_row": float(mm_per_row),
        "radius": float(radius),
        "radius_mm": float(R),
        "distance": float(distance),
        "n_lat": int(n_lat),
        "n_lon": int(n_lon),
        "grout": float(grout),
        "facet_tilt_deg": float(facet_tilt_deg),
        "mirror_reflectance": float(mirror_reflectance),
        "facet_diffuse": float(facet_diffuse),
        "grout_albedo": float(grout_albedo),
        "n_cam": int(n_cam),
        "n_splat": int(n_splat),
        "band_rows": int(band_rows),
        "label_fraction": float(label_fraction),
    }
    return Scene("disco_ball", transport, direct, ambient, labels, params)
