"""A translucent wax "rose candle" on a dark table: broad subsurface scattering (Fig. 11).

Model
-----
The candle is a rounded blob (a superellipse region at the image centre, convex
along every column) of homogeneous wax; the table around it is a dark Lambertian
wood texture with direct reflection only.  A wax pixel ``(t, s)`` receives

* **surface reflection** (the direct, epipolar component): a weak glossy/diffuse
  reflection of a few percent (Fresnel reflectance of ``eta = 1.4`` is ~3 %),
  modulated by a sharp engraved petal pattern -- grooves are darker, petal rims
  catch a highlight.  It is spread over the camera row's footprint with
  :func:`~planeray.scenes.base.footprint_kernel`, so its total is the surface
  reflectance, like the albedo of a Lambertian plane.
* **subsurface light** from every projector row ``v = p_t + u`` that enters the
  wax in the same column::

      T_ss[t, s, u] = rho_ss(s, t) * K(u) * inside(t, s, u)

  ``K`` is the line kernel of the wax, a :class:`~planeray.medium.Medium`
  (:func:`planeray.kernels.line_kernel`): by default the Monte Carlo exitance
  profile of a Henyey-Greenstein medium (:data:`WAX_MEDIUM`: ``g = 0.8``,
  ``sigma_s = sigma_s' / (1 - g)``, Fresnel boundary at ``n = 1.4``;
  :mod:`planeray.mc`), or with ``kernel="dipole"`` the classical diffusion
  dipole integrated along the lit line (Jensen et al. 2001) -- binned to
  projector-row offsets at ``mm_per_row`` and, when one camera row spans several
  projector rows, convolved with the camera row's footprint.  ``inside`` is the
  fraction of the offset bin ``[p_t + u - 1/2, p_t + u + 1/2)`` that lies on the
  wax in column ``s`` (light must enter the wax: the kernel is truncated at the
  object's top and bottom boundary).  ``rho_ss`` is a smooth tint variation
  (~5 %) of the wax; the kernel itself carries the diffuse albedo (``K`` sums to
  the medium's total diffuse reflectance, ``params["subsurface_total_reflectance"]``).
  Defaults: a translucent paraffin candle, sigma_s' = 0.3 /mm (transport mean
  free path ~3 mm, ~10 rows), sigma_a = 0.003 /mm, with a frosted, carved surface
  reflecting 8 %: at 600 us the epipolar image is ~4.4x the direct light.

Assumptions and approximations
------------------------------
* Both kernels are semi-infinite flat-medium solutions; curvature, the finite
  thickness of the candle and light escaping through its sides are ignored.
* The illuminated line is treated as infinite along the row (the line kernel):
  truncation happens only along the column, not at the object's left/right
  boundary; the receiving pixel itself must be on the wax.
* The subsurface glow is *global* light: :attr:`Scene.direct` holds the surface
  reflection only, even though the dipole's own offset-0 bin also lands in the
  epipolar image (that is exactly what sharpened epipolar imaging removes, Sec. 9).
* The Monte Carlo kernel carries its own ~1 % noise (10^6 photons) in the far
  skirt: it is a fixed property of the scene (traced once with seed 0), not a
  per-capture noise.
* Defaults (``sigma_a = 0.003 /mm``, ``sigma_s' = 0.3 /mm``, ``n = 1.4``) are
  a translucent paraffin: transport mean free path ~3.3 mm, diffusion length
  ``1/sigma_tr ~ 19 mm`` (~64 projector rows at 0.3 mm/row).  The Monte Carlo
  kernel has a sharp single-scattering cusp (the next bin is already down to
  77 %) and a broad exponential skirt: two thirds of the light inside a 600 us
  band (32.4 rows) comes from more than 3 rows away, and the glow inside that
  band is many times the surface reflection.

References
----------
.. [1] H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan, "A practical model
   for subsurface light transport", SIGGRAPH 2001.
.. [2] Kubo et al., "Programmable Non-Epipolar Indirect Light Transport", TVCG
   2019, Sec. 9 and Fig. 11 (wax rose candle), Fig. 9 (candle delay profile).
"""

from __future__ import annotations

import numpy as np

from ..kernels import line_kernel
from ..medium import Medium, as_medium
from ..timing import RowGeometry
from ..transport import Transport
from ._textures import image_grid, smooth_noise, wood_grain
from .base import (
    DEFAULT_BAND_ROWS,
    DEFAULT_MM_PER_ROW,
    Scene,
    footprint_kernel,
    register_scene,
    scene_offsets,
)

__all__ = ["build", "wax_kernel", "rose_pattern", "WAX_MEDIUM"]

#: The default wax: a translucent paraffin with sigma_s' = 0.3 /mm, sigma_a = 0.003 /mm,
#: HG g = 0.8 (sigma_s = sigma_s' / (1 - g)) and index 1.4, semi-infinite.  Its Monte
#: Carlo kernel ships precomputed (:data:`planeray.mc.cache.TABLES_DIR`).
WAX_MEDIUM = Medium.from_reduced(0.3, 0.003, g=0.8, n=1.4)


def wax_kernel(medium: Medium, offsets_rows, rows_per_camera_row, *, mm_per_row, model="mc"):
    """Line kernel of ``medium`` on ``offsets_rows`` seen by one camera row (footprint-convolved).

    Returns the kernel and the medium's total diffuse reflectance
    (:func:`planeray.kernels.line_kernel`, ``model`` ``"mc"`` or ``"dipole"``).
    """
    offsets = np.asarray(offsets_rows)
    if rows_per_camera_row <= 1.0:
        return line_kernel(medium, offsets, mm_per_row=mm_per_row, model=model)
    half = int(np.ceil(0.5 * rows_per_camera_row + 0.5))
    foot = footprint_kernel(np.arange(-half, half + 1), rows_per_camera_row)
    # A wider offset range first, so the convolution is exact inside ``offsets``.
    wide = np.arange(offsets[0] - half, offsets[-1] + half + 1)
    kernel, total = line_kernel(medium, wide, mm_per_row=mm_per_row, model=model)
    return np.convolve(kernel, foot, mode="valid"), total


def _scene_medium(medium, sigma_a, sigma_s_prime, eta, g) -> Medium:
    """``medium`` with the legacy keyword overrides applied (in reduced terms: ``sigma_s'`` held)."""
    medium = as_medium(medium)
    if sigma_a is None and sigma_s_prime is None and eta is None and g is None:
        return medium
    return Medium.from_reduced(
        medium.sigma_s_prime if sigma_s_prime is None else sigma_s_prime,
        medium.sigma_a if sigma_a is None else sigma_a,
        g=medium.g if g is None else g,
        n=medium.n if eta is None else eta,
        thickness_mm=medium.thickness_mm,
    )


def rose_pattern(shape, centre, radii, rng: np.random.Generator, petals=5, turns=3.0):
    """Sharp engraved petal pattern in ``[0.25, 3]`` (multiplier of the surface reflectance).

    Petal boundaries are spiral arcs ``frac(petals * theta / 2pi + turns * r) = 0``
    in elliptic polar coordinates about ``centre`` (normalized ``(y, x)``) with
    semi-axes ``radii``; a groove (dark, x0.25) sits on each boundary and a rim
    highlight (up to x3) just inside it.
    """
    y, x = image_grid(shape)
    dy = (y - centre[0]) / radii[0]
    dx = (x - centre[1]) / radii[1]
    r = np.hypot(dx, dy)
    theta = np.arctan2(dy, dx)
    warp = smooth_noise(shape, rng, max(shape) / 12.0, 0.08)
    # The petal count grows outward (inner bud: few petals, outer ring: more).
    n = petals + np.floor(3.0 * r)
    phase = n * (theta / (2 * np.pi) + 0.37 * np.floor(3.0 * r)) + turns * r + warp
    f = phase - np.floor(phase)
    groove_w = 0.06
    pattern = np.ones(shape)
    rim = np.exp(-(((f - 1.0 + 1.5 * groove_w) / (1.2 * groove_w)) ** 2))
    pattern += 2.0 * rim * (r > 0.08)
    pattern = np.where((f < groove_w) | (f > 1.0 - groove_w * 0.5), 0.25, pattern)
    return np.clip(pattern, 0.25, 3.0)


@register_scene("wax", "translucent wax object: broad subsurface kernel (Fig. 11)")
def build(
    shape,
    projector_rows,
    seed,
    mm_per_row: float = DEFAULT_MM_PER_ROW,
    medium: Medium = WAX_MEDIUM,
    surface_reflectance: float = 0.08,
    background_albedo: float = 0.2,
    size: float = 0.36,
    band_rows: int = DEFAULT_BAND_ROWS,
    kernel: str = "mc",
    sigma_a: float | None = None,
    sigma_s_prime: float | None = None,
    eta: float | None = None,
    g: float | None = None,
):
    """Build the scene.

    Parameters
    ----------
    mm_per_row : float
        Size of one projector row on the wax, mm.
    medium : Medium
        The wax (default :data:`WAX_MEDIUM`).  The dipole kernel sees it through
        ``sigma_a``, ``sigma_s_prime`` and ``n``; the Monte Carlo kernel traces
        its HG phase function.
    kernel : {"mc", "dipole"}
        Subsurface kernel model (:func:`planeray.kernels.line_kernel`): Monte
        Carlo of an HG medium (default; traced once, then cached on disk) or
        the diffusion dipole.
    sigma_a, sigma_s_prime, eta, g : float, optional
        Overrides of the medium's absorption, reduced scattering (mm^-1),
        refractive index and HG anisotropy, as ``make_scene("wax", ...,
        sigma_a=...)`` keywords; the medium is rebuilt with
        :meth:`Medium.from_reduced`, so ``sigma_s'`` is held when only ``g``
        changes (``sigma_s = sigma_s' / (1 - g)``).
    surface_reflectance : float
        Mean surface (direct) reflectance of the wax before the petal pattern.
    background_albedo : float
        Mean albedo of the dark table.
    size : float
        Semi-axes of the candle as a fraction of the image height/width.
    band_rows : int
        Half-width of the dense offset band (projector rows).
    """
    medium = _scene_medium(medium, sigma_a, sigma_s_prime, eta, g)
    H, W = shape
    rng = np.random.default_rng(seed)
    geometry = RowGeometry(H, projector_rows)
    P, rpc = geometry.projector_rows, geometry.rows_per_camera_row
    offsets = scene_offsets(max(int(band_rows), int(np.ceil(rpc)) + 1))

    # Candle outline: a superellipse, convex along every column.
    cy, cx, ry, rx, expo = 0.52, 0.5, size, 0.85 * size, 2.6
    y, x = image_grid(shape)
    level = np.abs((y - cy) / ry) ** expo + np.abs((x - cx) / rx) ** expo
    mask = level < 1.0
    xs = (np.arange(W) + 0.5) / W
    half = ry * np.clip(1.0 - np.abs((xs - cx) / rx) ** expo, 0.0, None) ** (1.0 / expo)
    top = (cy - half) * P - 0.5  # object extent in continuous projector coordinates
    bottom = (cy + half) * P - 0.5

    # Albedos.
    table = np.clip(wood_grain(shape, rng, mean=background_albedo, amplitude=0.25 * background_albedo), 0.02, 1.0)
    petals = rose_pattern(shape, (cy, cx), (ry, rx), rng)
    surface = surface_reflectance * petals * (1.0 + smooth_noise(shape, rng, H / 10.0, 0.1))
    rho_ss = 1.0 + smooth_noise(shape, rng, H / 6.0, 0.05)
    surface = np.clip(surface, 0.0, 1.0)

    direct = np.where(mask, surface, table).astype(np.float32)
    foot = footprint_kernel(offsets, rpc).astype(np.float32)
    dense = direct[:, :, None] * foot[None, None, :]

    # Subsurface: kernel x (fraction of the offset bin on the wax in this column).
    ss_kernel, r_total = wax_kernel(medium, offsets, rpc, mm_per_row=mm_per_row, model=kernel)
    ss_kernel = ss_kernel.astype(np.float32)
    p_t = geometry.projector_row_of(np.arange(H)).astype(np.float32)
    lo = p_t[:, None] + offsets[None, :].astype(np.float32) - 0.5  # (H, U)
    inside = np.minimum(lo[:, None, :] + 1.0, bottom.astype(np.float32)[None, :, None])
    inside -= np.maximum(lo[:, None, :], top.astype(np.float32)[None, :, None])
    np.clip(inside, 0.0, 1.0, out=inside)
    weight = (mask * rho_ss).astype(np.float32)
    inside *= weight[:, :, None]
    inside *= ss_kernel[None, None, :]
    dense += inside
    del inside

    transport = Transport(dense, offsets, geometry)
    r_total = float(r_total)
    ambient = np.where(mask, surface + r_total * rho_ss, table).astype(np.float32)
    labels = np.where(mask, 2, 1).astype(np.uint8)
    params = {
        "mm_per_row": float(mm_per_row),
        "sigma_a": medium.sigma_a,
        "sigma_s_prime": medium.sigma_s_prime,
        "eta": medium.n,
        "surface_reflectance": float(surface_reflectance),
        "background_albedo": float(background_albedo),
        "size": float(size),
        "band_rows": int(band_rows),
        "kernel": str(kernel),
        "g": medium.g,
        "subsurface_total_reflectance": r_total,
    }
    if not medium.semi_infinite:
        params["thickness_mm"] = medium.thickness_mm
    return Scene("wax", transport, direct, ambient, labels, params)
