"""Independent reference for :func:`planeray.mc.mc_line_profile`, rendered with Mitsuba 3.

Kubo et al. [3]_ (TVCG 2019, Sec. 5.2) simulated their subsurface-scattering
profiles with Mitsuba and a homogeneous Henyey-Greenstein medium.  This module
renders the same observable -- the radiance leaving a semi-infinite,
index-matched HG half-space along its outward normal, next to a thin line of
collimated light at normal incidence -- with Mitsuba 3's stock volumetric path
tracer (``volpath`` [1]_, [2]_), so that planeray's own Monte Carlo engine can be
checked against code it shares nothing with.

Scene (lengths in mm, ``z`` up, the medium below ``z = 0``):

* **Medium**: a ``cube`` of half-size ``L`` (``x, y`` in ``[-L, L]``, ``z`` in
  ``[-2L, 0]``) with a ``null`` BSDF -- relative index 1, no surface
  reflection -- and a ``homogeneous`` interior (``sigma_t = sigma_s + sigma_a``,
  albedo ``sigma_s / sigma_t``, ``hg`` phase with anisotropy ``g``).  ``L`` is
  many diffusion lengths, so the box is a half-space for the binned window.
* **Light**: a ``directional`` emitter shining straight down (exactly
  collimated, delta in direction) behind an opaque black mask at ``z = 1``
  made of two half-planes that leave the slit ``|x| <= w / 2`` open.
  ``volpath``'s next-event estimation traces shadow rays straight up, so the
  medium is lit exactly on the strip, infinitely long along ``y``.  Light that
  leaves the medium and hits the mask is absorbed, as if it had escaped: the
  mask changes nothing else.  (This replaces a ``projector`` emitter: its
  perspective frustum makes the light neither collimated nor easy to place on
  a row, and its texture orientation and irradiance scale have to be reverse
  engineered.)
* **Camera**: an ``orthographic`` sensor between the surface and the mask,
  looking along ``-z``, so every pixel measures radiance leaving along ``+z``.
  Its pixels are ``mm_per_row`` wide in ``x``; pixel column ``i`` covers
  ``x`` in ``[(k_min + i - 1/2), (k_min + i + 1/2)) * mm_per_row`` (a ``box``
  reconstruction filter keeps samples in their pixel, so a pixel is the exact
  bin average).  Rows run along the line; since the scene is invariant along
  ``y`` every row is an independent estimate of the same profile, and their
  spread gives the standard error.

Calibration.  The emitter's ``irradiance`` is set to ``1 / w`` (unit line
power), but the normalisation is *measured*, not assumed: the same emitter,
mask and camera render a white Lambertian plane (``diffuse``, reflectance 1)
whose radiance is exactly ``E / pi``, so ``pi * sum(L_white) * pixel_width`` is
the line power Mitsuba actually delivers; the medium image is divided by it.
With Mitsuba 3.9 it comes out as 1 to float32 round-off.

Variance.  A camera path collects light only at vertices inside the lit slab
``|x| <= w / 2``, and ``volpath`` estimates the shadow ray's transmittance by
tracking (0 or 1), so bins far from the line are noisy and heavy-tailed.  For
``sigma_s = 1``, ``sigma_a = 0.05`` mm^-1, ``g = 0.5`` and 1 mm bins the
relative standard deviation of one camera path is about 2 on the line, 7 at
3 mm and 20 at 10 mm; at ``g = 0.9`` the HG peak, met only through next-event
estimation towards the delta light, makes it 2-3.5 times larger, and even
2.6e5 paths per bin leave occasional bins off by 5 standard errors.  Many pixel rows with few samples each (default 1024 rows) keep the
row-spread standard error honest for such heavy tails; 32 rows underestimate
it.  ``volpathmis`` gives the same estimates, more slowly (it only adds
spectral MIS).  Cost is linear in ``spp * along_pixels * passes`` per column
(about 1e5 camera paths per second on two cores for an albedo of 0.95);
Mitsuba's ``scalar`` variants render image blocks on all cores.

``max_depth = -1`` (unbounded, Russian roulette only) is unbiased; a finite
``max_depth`` truncates the scattering order (``2`` gives exactly single
scattering, which the tests compare with the closed form).  For an albedo of
0.95 (``g = 0.5``) depth 20 loses 11 % of the profile, 50 loses 0.3 % and 400
is byte-identical to -1.

References
----------
.. [1] W. Jakob, S. Speierer, N. Roussel, M. Nimier-David, D. Vicini, T. Zeltner,
   B. Nicolet, M. Crespo, V. Leroy, Z. Zhang, "Mitsuba 3 renderer", 2022,
   https://mitsuba-renderer.org.
.. [2] Mitsuba 3 documentation, plugin reference: ``volpath``, ``homogeneous``,
   ``hg``, ``directional``, ``orthographic``, ``null``,
   https://mitsuba.readthedocs.io.
.. [3] H. Kubo, S. Jayasuriya, T. Iwaguchi, T. Funatomi, Y. Mukaigawa,
   S. G. Narasimhan, "Programmable Non-Epipolar Indirect Light Transport:
   Capture and Analysis", IEEE TVCG 27(4), 2021 (online 2019), Sec. 5.2.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..medium import Medium, as_medium

__all__ = ["MitsubaProfile", "mitsuba_line_profile", "single_scattering_radiance"]

# Heights above the surface (mm): the camera sits below the mask so it sees the surface
# unobstructed while shadow rays, which go straight up, must pass the slit.
_CAMERA_Z_MM = 0.5
_MASK_Z_MM = 1.0
# Fixed image-block size: scalar variants seed the sampler per image block, so a fixed
# block layout keeps the bytes of a result independent of the core count (1 and 2
# threads checked identical).
_BLOCK_SIZE = 16


@dataclass(frozen=True)
class MitsubaProfile:
    """Result of :func:`mitsuba_line_profile`.

    Attributes
    ----------
    offsets_rows : ndarray of int64
        Offset bins ``k``; bin ``k`` covers ``x`` in ``[k - 1/2, k + 1/2) * mm_per_row``.
    radiance : ndarray of float64
        Radiance leaving the top face along the outward normal, averaged over
        each bin, per unit incident line power (mm^-1 sr^-1).
    stderr : ndarray of float64
        Standard error of ``radiance`` from the spread of the independent pixel
        rows (along the line) of all passes.
    params : dict
        Parameters of the run, the Mitsuba version and the measured line power
        (``calibrated_line_power``, in units of the nominal one).
    seconds : float
        Wall time of the renders.
    """

    offsets_rows: np.ndarray
    radiance: np.ndarray
    stderr: np.ndarray
    params: dict = field(default_factory=dict)
    seconds: float = 0.0


def _index_matched_half_space(medium, what) -> Medium:
    """``medium`` if it is what the Mitsuba scene models: ``n = 1``, semi-infinite."""
    medium = as_medium(medium)
    if medium.n != 1.0 or not medium.semi_infinite:
        raise InputError(
            f"{what} models an index-matched (n = 1) semi-infinite medium, got n {medium.n}, "
            f"thickness_mm {medium.thickness_mm}"
        )
    return medium


def single_scattering_radiance(medium: Medium, *, source_width_mm):
    """Closed-form single-scattering radiance along ``+z`` inside the lit strip.

    For collimated irradiance ``E = 1 / w`` at normal incidence on an
    index-matched half-space, light scattered once straight back up has
    ``L1 = sigma_s p_HG(-1) E / (2 sigma_t)`` (the ``1 / (2 sigma_t)`` is the
    depth integral of the in- and out-going attenuation ``exp(-2 sigma_t z)``),
    with ``p_HG(-1) = (1 - g) / (4 pi (1 + g)^2)``; outside the strip it is 0.

    Parameters
    ----------
    medium : Medium
        An index-matched (``n = 1``) semi-infinite medium.
    source_width_mm : float
        Width ``w`` of the strip carrying unit line power.

    Returns
    -------
    float
        ``L1`` in mm^-1 sr^-1 per unit line power.
    """
    medium = _index_matched_half_space(medium, "single_scattering_radiance")
    sigma_s, g = medium.sigma_s, medium.g
    sigma_t = sigma_s + medium.sigma_a
    p_back = (1.0 - g) / (4.0 * math.pi * (1.0 + g) ** 2)
    return sigma_s * p_back / (2.0 * sigma_t * source_width_mm)


def _mitsuba(variant):
    """Import Mitsuba lazily and select ``variant`` (only if another one is active)."""
    try:
        import mitsuba as mi
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError('planeray.mc.mitsuba_ref needs Mitsuba 3: pip install "planeray[mitsuba]"') from exc
    if mi.variant() != variant:
        mi.set_variant(variant)
    return mi


def _default_medium_size_mm(medium, extent_mm):
    """Half-size of the medium cube: many transport lengths beyond the binned window."""
    sigma_a = medium.sigma_a
    sigma_t = medium.sigma_s + sigma_a
    mu_tr = sigma_a + medium.sigma_s_prime
    sigma_eff = math.sqrt(3.0 * sigma_a * mu_tr) if sigma_a > 0 else 0.0
    # 1 / sigma_eff is the diffusion length; a non-absorbing medium has none, so cap.
    diffusion_mm = 1.0 / sigma_eff if sigma_eff > 0 else math.inf
    length = 40.0 * max(1.0 / sigma_t, 1.0 / mu_tr, min(diffusion_mm, 250.0))
    return float(min(max(length, 100.0, 10.0 * extent_mm), 1.0e4))


def _scene(
    mi, *, medium, x_left_mm, ncols, pixel_mm, source_width_mm, along_pixels, spp, seed, max_depth, rr_depth, size_mm
):
    """Scene dict: masked directional light over either the medium or a white plane.

    Film column ``i`` covers ``x`` in ``[x_left_mm + i * pixel_mm, x_left_mm + (i + 1) * pixel_mm)``.
    """
    T = mi.ScalarTransform4f
    w = source_width_mm
    big = 4.0 * size_mm
    half_w = 0.5 * ncols * pixel_mm
    x_center = x_left_mm + half_w
    # The orthographic sensor maps local x in [-1, 1] onto the film width and local y in
    # [-1/aspect, 1/aspect] (aspect = width / height in pixels) onto its height.  All
    # rows are packed into one bin height along the line (the scene is invariant
    # along y), so the medium needs no extra room for them.  look_at with up = +y puts
    # film columns along +x (checked by the single-scattering test's asymmetric window).
    scale_y = 0.5 * pixel_mm * ncols / along_pixels
    sensor_to_world = T.look_at(
        origin=[x_center, 0.0, _CAMERA_Z_MM], target=[x_center, 0.0, 0.0], up=[0.0, 1.0, 0.0]
    ) @ T.scale([half_w, scale_y, 1.0])
    scene = {
        "type": "scene",
        "integrator": {
            "type": "volpath",
            "max_depth": int(max_depth),
            "rr_depth": int(rr_depth),
            "block_size": _BLOCK_SIZE,
        },
        "sensor": {
            "type": "orthographic",
            "to_world": sensor_to_world,
            "film": {
                "type": "hdrfilm",
                "width": int(ncols),
                "height": int(along_pixels),
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
                "sample_border": False,
            },
            "sampler": {"type": "independent", "sample_count": int(spp), "seed": int(seed)},
        },
        # Irradiance 1/w on a surface normal to the beam: unit power per unit line length.
        "light": {"type": "directional", "direction": [0.0, 0.0, -1.0], "irradiance": 1.0 / w},
        "black": {"type": "diffuse", "id": "black", "reflectance": 0.0},
        "mask_left": {
            "type": "rectangle",
            "to_world": T.translate([-0.5 * w - big, 0.0, _MASK_Z_MM]) @ T.scale([big, big, 1.0]),
            "bsdf": {"type": "ref", "id": "black"},
        },
        "mask_right": {
            "type": "rectangle",
            "to_world": T.translate([0.5 * w + big, 0.0, _MASK_Z_MM]) @ T.scale([big, big, 1.0]),
            "bsdf": {"type": "ref", "id": "black"},
        },
    }
    if medium is None:
        scene["white"] = {
            "type": "rectangle",
            "to_world": T.scale([big, big, 1.0]),
            "bsdf": {"type": "diffuse", "reflectance": 1.0},
        }
    else:
        sigma_s, g = medium.sigma_s, medium.g
        sigma_t = sigma_s + medium.sigma_a
        scene["medium"] = {
            "type": "cube",
            "to_world": T.translate([0.0, 0.0, -size_mm]) @ T.scale([size_mm] * 3),
            "bsdf": {"type": "null"},
            "interior": {
                "type": "homogeneous",
                "sigma_t": sigma_t,
                "albedo": sigma_s / sigma_t,
                "phase": {"type": "hg", "g": g},
            },
        }
    return scene


def _render(mi, scene_dict):
    """Render; return the image as float64 ``(rows, columns)`` (the RGB channels are equal)."""
    img = np.asarray(mi.render(mi.load_dict(scene_dict)), dtype=np.float64)
    return img.mean(axis=2)


def _line_power(mi, source_width_mm, size_mm):
    """Line power the masked emitter delivers, measured on a white Lambertian plane.

    The camera here has pixels ``w / 4`` wide, one dark pixel on either side
    of the slit and pixel edges on the slit's edges, so every sample sees
    either ``E / pi`` or 0 and the sum is exact.
    """
    sub = 4
    pixel_mm = source_width_mm / sub
    d = _scene(
        mi,
        medium=None,
        x_left_mm=-0.5 * source_width_mm - pixel_mm,
        ncols=sub + 2,
        pixel_mm=pixel_mm,
        source_width_mm=source_width_mm,
        along_pixels=2,
        spp=4,
        seed=0,
        max_depth=2,
        rr_depth=5,
        size_mm=size_mm,
    )
    img = _render(mi, d)
    return float(math.pi * img.mean(axis=0).sum() * pixel_mm)


def mitsuba_line_profile(
    medium: Medium,
    offsets_rows,
    *,
    mm_per_row,
    source_width_mm=None,
    spp=64,
    passes=1,
    seed=0,
    along_pixels=1024,
    variant="scalar_rgb",
    max_depth=-1,
    rr_depth=5,
    medium_size_mm=None,
):
    """Normal-view radiance profile next to a line light, rendered with Mitsuba 3.

    Parameters
    ----------
    medium : Medium
        ``sigma_s``, ``sigma_a`` (mm^-1) and HG ``g`` of an index-matched
        (``n = 1``) semi-infinite medium: the scene models no other.
    offsets_rows : array_like of int
        Offset bins to return; the image spans ``min .. max`` contiguously.
    mm_per_row : float
        Bin width in mm (one image column per bin).
    source_width_mm : float, optional
        Width of the lit strip ``|x| <= w / 2``; default ``mm_per_row`` (one lit row).
    spp : int
        Samples per pixel.
    passes : int
        Independent renders (sampler seeds from ``numpy.random.SeedSequence(seed)``)
        pooled into the estimate and its standard error.
    seed : int
        Seed of the passes' sampler seeds.
    along_pixels : int
        Pixel rows along the line per pass (each an independent estimate; at
        least 2 in all for a standard error).
    variant : str
        Mitsuba variant; ``"scalar_rgb"`` runs on the CPU.  It is activated
        with ``mitsuba.set_variant`` only if another one is active.
    max_depth : int
        ``volpath`` path depth; -1 (default) is unbounded (unbiased), 2 keeps
        single scattering only.
    rr_depth : int
        Depth from which ``volpath`` applies Russian roulette.
    medium_size_mm : float, optional
        Half-size ``L`` of the medium cube; default many transport lengths
        (at least 100 mm and 10x the binned window).

    Returns
    -------
    MitsubaProfile
        Bin-averaged radiance along the outward normal per unit line power
        (mm^-1 sr^-1), its standard error and the run's parameters.

    Raises
    ------
    ImportError
        If Mitsuba 3 is not installed.

    Notes
    -----
    See the module docstring for the scene, the calibration on a white
    Lambertian plane and the variance.  The quantity is the ``radiance`` of
    :func:`planeray.mc.mc_line_profile` with ``n = 1`` and the same
    ``source_width_mm``.

    Examples
    --------
    >>> from planeray.medium import Medium
    >>> m = Medium(sigma_s=0.02, sigma_a=0.98, g=0.0)
    >>> p = mitsuba_line_profile(m, [-1, 0, 1], mm_per_row=0.5, spp=64, max_depth=2)  # doctest: +SKIP
    >>> p.radiance[1] / single_scattering_radiance(m, source_width_mm=0.5)  # doctest: +SKIP
    1.0...
    """
    medium = _index_matched_half_space(medium, "mitsuba_line_profile")
    sigma_s, sigma_a, g = medium.sigma_s, medium.sigma_a, medium.g
    mm_per_row = float(mm_per_row)
    if not (math.isfinite(mm_per_row) and mm_per_row > 0):
        raise InputError(f"mm_per_row must be positive, got {mm_per_row}")
    width = mm_per_row if source_width_mm is None else float(source_width_mm)
    if not (math.isfinite(width) and width > 0):
        raise InputError(f"source_width_mm must be positive, got {source_width_mm}")
    offsets = np.asarray(offsets_rows)
    if offsets.ndim != 1 or offsets.size == 0 or not np.all(offsets == np.round(offsets)):
        raise InputError("offsets_rows must be a non-empty 1-D sequence of integers")
    offsets = offsets.astype(np.int64)
    spp, passes, along_pixels = int(spp), int(passes), int(along_pixels)
    if spp < 1 or passes < 1 or along_pixels < 1 or passes * along_pixels < 2:
        raise InputError("need spp >= 1, passes >= 1, along_pixels >= 1 and passes * along_pixels >= 2")

    mi = _mitsuba(variant)
    kmin, kmax = int(offsets.min()), int(offsets.max())
    ncols = kmax - kmin + 1
    extent_mm = (max(abs(kmin), abs(kmax)) + 0.5) * mm_per_row
    size_mm = _default_medium_size_mm(medium, extent_mm) if medium_size_mm is None else float(medium_size_mm)

    t0 = time.perf_counter()
    line_power = _line_power(mi, width, size_mm)
    seeds = np.random.SeedSequence(int(seed)).generate_state(passes, dtype=np.uint32)
    # Keep seeds in int32 range: the plugin property is a signed integer.
    seeds = (seeds >> np.uint32(1)).astype(np.int64)
    images = [
        _render(
            mi,
            _scene(
                mi,
                medium=medium,
                x_left_mm=(kmin - 0.5) * mm_per_row,
                ncols=ncols,
                pixel_mm=mm_per_row,
                source_width_mm=width,
                along_pixels=along_pixels,
                spp=spp,
                seed=int(s),
                max_depth=max_depth,
                rr_depth=rr_depth,
                size_mm=size_mm,
            ),
        )
        for s in seeds
    ]
    seconds = time.perf_counter() - t0
    # Every pixel row (of every pass) is an independent, identically distributed estimate.
    rows = np.concatenate(images, axis=0) / line_power
    cols = offsets - kmin
    radiance = rows.mean(axis=0)[cols]
    stderr = rows.std(axis=0, ddof=1)[cols] / math.sqrt(rows.shape[0])

    params = {
        "sigma_s": sigma_s,
        "sigma_a": sigma_a,
        "g": g,
        "n": 1.0,
        "mm_per_row": mm_per_row,
        "source_width_mm": width,
        "spp": spp,
        "passes": passes,
        "seed": int(seed),
        "along_pixels": along_pixels,
        "variant": variant,
        "integrator": "volpath",
        "max_depth": int(max_depth),
        "rr_depth": int(rr_depth),
        "medium_size_mm": size_mm,
        "calibrated_line_power": line_power,
        "mitsuba_version": mi.__version__,
        "samples_per_bin": spp * along_pixels * passes,
    }
    return MitsubaProfile(
        offsets_rows=offsets,
        radiance=radiance.astype(np.float64),
        stderr=stderr.astype(np.float64),
        params=params,
        seconds=seconds,
    )
