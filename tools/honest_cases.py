"""The independent cases of issue 41: synthetic captures from forward models the fits were not built on.

Written first and kept fixed (never tuned one by one): every inverse method planeray ships
(``materials fit`` per region, the stack fit, ``skin depth``, recognition) is measured on them by
``tools/validate_honest_fits.py``, whose table goes into the docs.

Sources of the captures
-----------------------
``mitsuba``
    Mitsuba 3 scene files written here and rendered through planeray's render pipeline
    (:func:`planeray.render.render_to_store`, what ``planeray render`` runs: Mitsuba's own homogeneous
    media, null interfaces, its projector emitter), then swept on the simulated device (planeray's camera
    noise).  The render pipeline refuses a medium behind a refracting boundary, so every Mitsuba medium is
    **index-matched** (``null`` faces): the user states ``n = 1``.  Russian roulette is off (depth 10^5):
    the media scatter thousands of times with an albedo near 1.
``mc``
    Brute-force Monte Carlo of geometries the fits' tables do not contain: planeray's slab engine traced
    to the end (no diffusion hand-off, unlike the forward table), with a **refracting** Fresnel face of
    another index and another ``g`` than the table's, semi-infinite or a layer on a support that returns
    nothing; and a vein of blood *in* the layered skin (:func:`planeray.mc.layered.mc_layered_vein_brute`:
    photons cross the cylinder with blood's own scattering, unlike the perturbation tables the depth fit
    uses), with layer thicknesses other than the built-in scene's.
``scene``
    The ``materials`` scene: trays of Fig. 10 media on a table, each pixel's kernel brute-force Monte Carlo
    with the tray's clear walls (:mod:`planeray.mc.wall`; the fit models walls by diffusion theory).

Every capture is written as a user's **import folder** (``manifest.csv``, 16-bit images and an
``acquisition.json`` that states ``mm_per_row`` and the camera, nothing of the scene), beside ``truth.json``
and, where the case has them, ``labels.png`` (regions: 1 the medium, 2 the table), ``veins.png`` (the vein's
pixels) and ``white/`` (a white Lambertian target captured with the same sweep and camera).

Optical constants: skin and blood from :mod:`planeray.optical_data_skin` (Jacques 2013, Prahl's haemoglobin,
Bashkatov et al. 2005, Hale & Querry 1973; cited there); the media of the ``materials`` scene from
:mod:`planeray.optical_data` (Narasimhan et al. 2006); every other medium here is a stated synthetic one
(its ``mu_s'``, ``mu_a``, ``g`` are the case's truth, chosen to span the issue's range, not a real material).

    nice -n 19 python tools/honest_cases.py make [--only ID ...] [--root /work/cache-honest-fits/cases]
    python tools/honest_cases.py list
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path("/work/cache-honest-fits/cases")
SWEEP = "paper"
DISTANCE_MM = 1000.0  # camera straight above the surface (little perspective on walls)
BASELINE_MM = 20.0  # projector beside it: 1.1 degrees off the normal
RR_DEPTH = 100_000  # no Russian roulette
# Samples: MS1 was rendered at 4096 paths per pixel; on the shared 2 cores the others at 1024 (slabs, layers) and
# 512 (trays) -- set before any of them was fitted (the fits pool their region's pixels: the render's noise is
# below the forward model's error floor).

# ----------------------------------------------------------------------------- the cases (fixed)
# Media: truth mu_s' / mu_a in 1/mm, g; "model" is what the user states to planeray.  Slabs are 100 mm deep
# and 500 mm wide (semi-infinite for these media); layers lie on nothing (light leaving the bottom is lost).
_MEDIA = [
    # Mitsuba, index-matched slabs (n = 1)
    dict(id="MS1", source="mitsuba", kind="slab", mu_s_prime=0.2, mu_a=0.002, g=0.8, h=0.5, P=64, H=32, W=4, spp=4096),
    dict(id="MS2", source="mitsuba", kind="slab", mu_s_prime=1.0, mu_a=0.01, g=0.8, h=0.3, P=180, H=32, W=4, spp=1024),
    dict(id="MS3", source="mitsuba", kind="slab", mu_s_prime=3.0, mu_a=0.03, g=0.9, h=0.3, P=96, H=32, W=4, spp=1024),
    dict(id="MS4", source="mitsuba", kind="slab", mu_s_prime=8.0, mu_a=0.1, g=0.5, h=0.2, P=64, H=32, W=4, spp=1024),
    dict(id="MS5", source="mitsuba", kind="slab", mu_s_prime=16.0, mu_a=0.02, g=0.0, h=0.25, P=32, H=32, W=4, spp=1024),
    dict(id="MS6", source="mitsuba", kind="slab", mu_s_prime=0.5, mu_a=0.05, g=0.8, h=0.5, P=96, H=32, W=4, spp=1024),
    dict(id="MS7", source="mitsuba", kind="slab", mu_s_prime=2.0, mu_a=0.001, g=0.7, h=0.4, P=64, H=32, W=4, spp=1024),
    dict(id="MS8", source="mitsuba", kind="slab", mu_s_prime=5.0, mu_a=0.005, g=0.8, h=0.3, P=180, H=32, W=4, spp=1024),
    # Mitsuba, index-matched layers whose bottom loses the light (the user states the depth)
    dict(id="ML1", source="mitsuba", kind="layer", mu_s_prime=0.5, mu_a=0.005, g=0.8, depth_mm=10.0, h=0.5, P=64, H=32,
         W=4, spp=1024),
    dict(id="ML2", source="mitsuba", kind="layer", mu_s_prime=0.2, mu_a=0.002, g=0.8, depth_mm=20.0, h=0.5, P=64, H=32,
         W=4, spp=1024),
    dict(id="ML3", source="mitsuba", kind="layer", mu_s_prime=2.0, mu_a=0.01, g=0.8, depth_mm=4.0, h=0.3, P=96, H=32,
         W=4, spp=1024),
    # Mitsuba, index-matched trays on a matte table (albedo 0.3), all four walls in view; the user outlines the tray
    dict(id="MT1", source="mitsuba", kind="tray", mu_s_prime=1.0, mu_a=0.005, g=0.8, tray_mm=(36.0, 36.0),
         depth_mm=30.0, h=0.3, P=160, H=32, W=32, spp=512),
    dict(id="MT2", source="mitsuba", kind="tray", mu_s_prime=3.0, mu_a=0.03, g=0.8, tray_mm=(40.0, 28.0),
         depth_mm=20.0, h=0.4, P=128, H=32, W=32, spp=512),
    dict(id="MT3", source="mitsuba", kind="tray", mu_s_prime=0.5, mu_a=0.002, g=0.8, tray_mm=(40.0, 40.0),
         depth_mm=30.0, h=0.3, P=180, H=32, W=32, spp=512),
    # brute-force Monte Carlo, refracting Fresnel faces, other g and n than the table's
    dict(id="MB1", source="mc", kind="slab", mu_s_prime=1.0, mu_a=0.003, g=0.9, n=1.33, h=0.3, P=180, H=32, W=8),
    dict(id="MB2", source="mc", kind="slab", mu_s_prime=4.0, mu_a=0.04, g=0.6, n=1.40, h=0.3, P=180, H=32, W=8),
    dict(id="MB3", source="mc", kind="slab", mu_s_prime=16.0, mu_a=0.02, g=0.6, n=1.45, h=0.25, P=96, H=32, W=8),
    dict(id="MB4", source="mc", kind="layer", mu_s_prime=0.3, mu_a=0.001, g=0.8, n=1.38, depth_mm=30.0, h=0.5, P=96,
         H=32, W=8),
    dict(id="MB5", source="mc", kind="slab", mu_s_prime=0.8, mu_a=0.08, g=0.95, n=1.33, h=0.3, P=180, H=32, W=8),
    dict(id="MB6", source="mc", kind="layer", mu_s_prime=1.5, mu_a=0.015, g=0.8, n=1.33, depth_mm=10.0, h=0.3, P=96,
         H=32, W=8),
    # the materials scene: five trays with clear walls (brute-force wall kernels), shape only, per tray
    dict(id="MW1", source="scene", kind="materials", size=128, placement=1, seed=1, noise=1.5, ambient=1.5),
    dict(id="MW2", source="scene", kind="materials", size=64, placement=0, seed=0, noise=1.0, ambient=0.5),
]  # fmt: skip

# Skin: one straight vein (top depth, diameter, angle to the rows) in layers of the stated tone, wavelength and
# dermis; the user states the skin model (tone, wavelength, thicknesses, n).  Brute force: Fresnel top face
# (n 1.4, the scene's); Mitsuba: index-matched top (n 1).
_SKIN = [
    dict(id="SB1", source="mc", tone="fair", nm=638, dermis_mm=1.5, depth_mm=1.0, diameter_mm=2.0, angle=0.0),
    dict(id="SB2", source="mc", tone="fair", nm=850, dermis_mm=3.0, depth_mm=2.0, diameter_mm=2.0, angle=90.0),
    dict(id="SB3", source="mc", tone="dark", nm=638, dermis_mm=3.0, depth_mm=1.5, diameter_mm=3.0, angle=0.0),
    dict(id="SB4", source="mc", tone="dark", nm=850, dermis_mm=5.0, depth_mm=2.5, diameter_mm=2.0, angle=90.0,
         wrong={"dermis_mm": 1.5}),
    dict(id="SB5", source="mc", tone="fair", nm=638, dermis_mm=5.0, depth_mm=3.0, diameter_mm=1.5, angle=0.0,
         wrong={"dermis_mm": 1.5}),
    dict(id="SB6", source="mc", tone="fair", nm=850, dermis_mm=1.5, depth_mm=2.5, diameter_mm=3.0, angle=0.0),
    dict(id="SB7", source="mc", tone="dark", nm=850, dermis_mm=3.0, depth_mm=1.0, diameter_mm=1.5, angle=90.0),
    dict(id="SB8", source="mc", tone="fair", nm=638, dermis_mm=3.0, depth_mm=2.0, diameter_mm=2.5, angle=0.0),
    dict(id="SM1", source="mitsuba", tone="fair", nm=638, dermis_mm=3.0, depth_mm=1.2, diameter_mm=1.5, angle=0.0),
    dict(id="SM2", source="mitsuba", tone="fair", nm=850, dermis_mm=5.0, depth_mm=2.0, diameter_mm=2.0, angle=0.0),
    dict(id="SM3", source="mitsuba", tone="dark", nm=850, dermis_mm=3.0, depth_mm=1.5, diameter_mm=1.2, angle=0.0),
]  # fmt: skip
#: Skin captures: camera rows x columns, projector rows (5.625 projector rows per camera row: 1.69 mm pixels at
#: 0.3 mm per row, the skin scene's at 128 x 128), photons of the brute-force runs, Mitsuba's thin render.
SKIN_MM_PER_ROW = 0.3
#: Photons of the brute-force media kernels (traced to the end, no diffusion hand-off).
MEDIA_PHOTONS = 300_000
SKIN_SHAPE = (48, 32)
SKIN_PROJECTOR_ROWS = 270
SKIN_PHOTONS = 300_000  # per distance of a pixel from the vein
SKIN_REACH_MM = 13.5  # pixels farther from the vein see vein-free skin (the depth fit uses those within 12 mm)
SKIN_MITSUBA = dict(H=32, W=4, spp=8192)  # rendered thin (the vein runs along the rows), tiled to SKIN_SHAPE[1]

# "wrong" model variants of media cases: the same capture fitted with a mis-stated model (expected flagged)
_MEDIA_WRONG = {"MS2": {"n": 1.33}, "ML1": {"depth_mm": None}}


def cases() -> list[dict]:
    """Every case (a fresh copy), media then skin."""
    out = []
    for c in _MEDIA:
        d = dict(c, domain="media")
        d.setdefault("n", 1.0 if c["source"] == "mitsuba" else None)
        if c["id"] in _MEDIA_WRONG:
            d["wrong"] = dict(_MEDIA_WRONG[c["id"]])
        out.append(d)
    for c in _SKIN:
        out.append(dict(c, domain="skin", n=1.0 if c["source"] == "mitsuba" else 1.4))
    return out


def case(case_id: str) -> dict:
    for c in cases():
        if c["id"] == case_id:
            return c
    raise KeyError(case_id)


# ----------------------------------------------------------------------------- writing a capture
def _camera(noise=1.0, ambient=0.5):
    from planeray.experiments.materials import camera_for

    return camera_for(noise=noise, ambient_e_per_us=ambient)


def _write_capture(stack, folder: Path, *, mm_per_row: float, camera) -> None:
    """An import folder as a user would have it: images, manifest, acquisition.json with mm_per_row and the camera."""
    from dataclasses import asdict

    from planeray.io import export_folder

    export_folder(stack, folder, overwrite=True)
    acq_path = folder / "acquisition.json"
    acq = json.loads(acq_path.read_text())
    acq["mm_per_row"] = float(mm_per_row)
    acq["planeray_metadata"] = {"camera": asdict(camera)}  # the camera's noise model; nothing of the scene
    acq_path.write_text(json.dumps(acq, indent=2) + "\n")


def _write_labels(path: Path, labels) -> None:
    from planeray.materials.labels import write_label_image

    write_label_image(path, np.asarray(labels, np.uint8), kind="labels")


def _write_mask(path: Path, mask) -> None:
    """A vein mask as a user draws it: grayscale PNG, 255 on the vein, 0 elsewhere."""
    from PIL import Image

    Image.fromarray(np.where(np.asarray(mask, bool), 255, 0).astype(np.uint8), mode="L").save(path)


def _simulate(scene, *, seed, camera):
    from planeray.acquire import simulate_stack
    from planeray.timing import make_sweep

    return simulate_stack(scene, make_sweep(SWEEP), camera=camera, seed=seed)


def _store_scene(path: Path):
    from planeray.scenes.store_scene import scene_from_transport_store

    return scene_from_transport_store(path)


# ----------------------------------------------------------------------------- Mitsuba scene files
_SCENE = """<scene version="3.0.0">
    <default name="planeray_baseline" value="{baseline}"/>
    <default name="planeray_projector_aspect" value="16"/>
    <sensor type="perspective">
        <float name="fov" value="{vfov}"/>
        <string name="fov_axis" value="y"/>
        <transform name="to_world"><lookat origin="0, 0, {d}" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="{w}"/><integer name="height" value="{h}"/></film>
    </sensor>
{body}
</scene>
"""


def _hg_medium(name, mu_s, mu_a, g):
    sigma_t = mu_s + mu_a
    return (
        f'    <medium type="homogeneous" id="{name}"><float name="sigma_t" value="{sigma_t:.9g}"/>'
        f'<float name="albedo" value="{mu_s / sigma_t:.9g}"/>'
        f'<phase type="hg"><float name="g" value="{g:.9g}"/></phase></medium>'
    )


def _medium_body(c) -> str:
    """The scene of a media case: a slab, a layer or a tray of the medium (null faces), mm."""
    g = c["g"]
    mu_s = c["mu_s_prime"] / (1.0 - g)
    med = _hg_medium("m", mu_s, c["mu_a"], g)
    if c["kind"] in ("slab", "layer"):
        depth = 100.0 if c["kind"] == "slab" else c["depth_mm"]
        return (
            med + f"""
    <shape type="cube"><transform name="to_world"><scale x="250" y="250" z="{depth / 2}"/>"""
            f"""<translate z="{-depth / 2}"/></transform><bsdf type="null"/><ref name="interior" id="m"/></shape>"""
        )
    down, across = c["tray_mm"][0] / 2, c["tray_mm"][1] / 2  # image down = world y (the camera's up), across = x
    depth = c["depth_mm"]
    return (
        med + f"""
    <shape type="cube"><transform name="to_world"><scale x="{across}" y="{down}" z="{depth / 2}"/>"""
        f"""<translate z="{-depth / 2}"/></transform><bsdf type="null"/><ref name="interior" id="m"/></shape>
    <shape type="rectangle"><transform name="to_world"><scale x="300" y="300"/><translate z="{-depth}"/></transform>
        <bsdf type="diffuse"><float name="reflectance" value="0.3"/></bsdf></shape>"""
    )


def _white_body() -> str:
    return """    <shape type="rectangle"><transform name="to_world"><scale x="300" y="300"/></transform>
        <bsdf type="diffuse"><float name="reflectance" value="1.0"/></bsdf></shape>"""


def _skin_body(c) -> str:
    """Layered skin (index-matched null interfaces, light below the fat lost) with one blood cylinder along x."""
    from planeray.optical_data_skin import skin_layers

    skin = skin_layers(c["nm"], c["tone"], dermis_mm=c["dermis_mm"])
    names = ("epi", "derm", "fat")
    parts = [_hg_medium(nm, m.sigma_s, m.sigma_a, m.g) for nm, m in zip(names, skin.layers)]
    parts.append(_hg_medium("blood", skin.blood.sigma_s, skin.blood.sigma_a, skin.blood.g))
    z = 0.0
    ext = None
    for nm, m in zip(names, skin.layers):
        refs = (f'<ref name="exterior" id="{ext}"/>' if ext else "") + f'<ref name="interior" id="{nm}"/>'
        parts.append(
            f'    <shape type="rectangle"><transform name="to_world"><scale x="300" y="300"/><translate z="{-z:.6g}"/>'
            f'</transform><bsdf type="null"/>{refs}</shape>'
        )
        z += m.thickness_mm
        ext = nm
    parts.append(
        f'    <shape type="rectangle"><transform name="to_world"><scale x="300" y="300"/><translate z="{-z:.6g}"/>'
        f'</transform><bsdf type="null"/><ref name="exterior" id="fat"/></shape>'
    )
    r = 0.5 * c["diameter_mm"]
    zc = c["depth_mm"] + r
    bounds = np.cumsum([m.thickness_mm for m in skin.layers])
    host = names[int(np.searchsorted(bounds, zc))]
    if not (np.searchsorted(bounds, zc - r) == np.searchsorted(bounds, zc + r)):
        raise ValueError(f"{c['id']}: the vein crosses a layer interface")
    parts.append(
        f'    <shape type="cylinder"><point name="p0" x="-400" y="0" z="{-zc:.6g}"/><point name="p1" x="400" y="0" '
        f'z="{-zc:.6g}"/><float name="radius" value="{r:.6g}"/><bsdf type="null"/><ref name="interior" id="blood"/>'
        f'<ref name="exterior" id="{host}"/></shape>'
    )
    return "\n".join(parts)


def _render(xml: str, folder: Path, name: str, *, H, W, P, h, spp, seed, band_rows=128):
    """Render a scene file through planeray's render pipeline into ``folder/name.zarr`` (resumable, cached)."""
    from planeray.render import render_to_store

    path = folder / f"{name}.xml"
    vfov = 2.0 * math.degrees(math.atan(0.5 * P * h / DISTANCE_MM))
    text = _SCENE.format(baseline=BASELINE_MM, vfov=vfov, d=DISTANCE_MM, w=W, h=H, body=xml)
    if not path.exists() or path.read_text() != text:
        path.write_text(text)
    out = folder / f"{name}.zarr"
    if out.exists():
        return out
    t0 = time.time()
    render_to_store(
        path, out, shape=(H, W), projector_rows=P, spp=spp, batch_spp=min(spp, 256), seed=seed,
        band_rows=band_rows, rr_depth=RR_DEPTH, restart=True,
    )  # fmt: skip
    print(f"  rendered {out} ({time.time() - t0:.0f} s)", flush=True)
    return out


def _pixel_centres_mm(H, W, P, h):
    """Camera pixel centres on the surface, mm from the image centre: (down, across)."""
    from planeray.timing import RowGeometry

    geo = RowGeometry(H, P)
    x = (geo.projector_row_of(np.arange(H)) + 0.5) * h - 0.5 * P * h
    col = P * h / H
    y = (np.arange(W) + 0.5) * col - 0.5 * W * col
    return x, y


def _make_mitsuba_media(c, folder: Path) -> dict:
    H, W, P, h = c["H"], c["W"], c["P"], c["h"]
    T = _render(_medium_body(c), folder, "medium", H=H, W=W, P=P, h=h, spp=c["spp"], seed=1)
    Tw = _render(_white_body(), folder, "white_target", H=H, W=W, P=P, h=h, spp=64, seed=2)
    cam = _camera()
    labels = np.ones((H, W), np.uint8)
    if c["kind"] == "tray":
        x, y = _pixel_centres_mm(H, W, P, h)
        inside = (np.abs(x)[:, None] < c["tray_mm"][0] / 2) & (np.abs(y)[None, :] < c["tray_mm"][1] / 2)
        labels = np.where(inside, 1, 2).astype(np.uint8)
    return dict(stack=_simulate(_store_scene(T), seed=11, camera=cam), white=_simulate(_store_scene(Tw), seed=12,
                camera=cam), labels=labels, camera=cam, h=h)  # fmt: skip


# ----------------------------------------------------------------------------- brute-force media
def _homogeneous_scene(kernel_fp, offsets, H, W, P, *, ambient_albedo):
    from planeray.scenes.base import Scene
    from planeray.timing import RowGeometry
    from planeray.transport import Transport

    geo = RowGeometry(H, P)
    cov = geo.coverage(np.arange(H)[:, None], offsets[None, :])
    dense = np.repeat((kernel_fp[None, :] * cov)[:, None, :], W, axis=1).astype(np.float32)
    direct = np.full((H, W), float(kernel_fp[offsets == 0][0]), np.float32)
    return Scene("case", Transport(dense, offsets, geo), direct, np.full((H, W), ambient_albedo, np.float32),
                 np.full((H, W), 2, np.uint8), params={})  # fmt: skip


def _make_mc_media(c, folder: Path) -> dict:
    from planeray.mc import mc_line_profile
    from planeray.medium import Medium
    from planeray.scenes.base import footprint_kernel, scene_offsets

    H, W, P, h = c["H"], c["W"], c["P"], c["h"]
    rpc = P / H
    off = scene_offsets()
    half = int(math.ceil(0.5 * rpc + 0.5)) + 1
    wide = np.arange(off[0] - half, off[-1] + half + 1)
    thick = math.inf if c["kind"] == "slab" else c["depth_mm"]
    med = Medium.from_reduced(c["mu_s_prime"], c["mu_a"], g=c["g"], n=c["n"], thickness_mm=thick)
    cache = folder / "kernel.npz"
    if cache.exists():
        k = np.load(cache)["k"]
    else:
        t0 = time.time()
        p = mc_line_profile(med, n_photons=MEDIA_PHOTONS, offsets_rows=wide, mm_per_row=h, seed=41,
                            diffusion_depth_mfp=None)  # fmt: skip
        k = np.pi * h * p.radiance  # the scenes' unit: Lambertian-equivalent reflectance per row
        np.savez(cache, k=k)
        print(f"  traced {c['id']} ({time.time() - t0:.0f} s)", flush=True)
    f = footprint_kernel(np.arange(-half, half + 1), rpc)
    k_fp = np.convolve(k, f, mode="same")[half:-half]
    cam = _camera()
    scene = _homogeneous_scene(k_fp, off, H, W, P, ambient_albedo=float(k.sum()))
    white = _homogeneous_scene(0.99 * footprint_kernel(off, rpc), off, H, W, P, ambient_albedo=0.99)
    return dict(stack=_simulate(scene, seed=21, camera=cam), white=_simulate(white, seed=22, camera=cam),
                labels=np.ones((H, W), np.uint8), camera=cam, h=h, white_albedo=0.99)  # fmt: skip


# ----------------------------------------------------------------------------- skin
def _vein_mask(H, W, P, h, c):
    """The pixels the vein crosses (as a user outlines it: a pixel whose area meets the vein's projection); also
    each pixel's signed distance from the vein's axis, mm."""
    x, y = _pixel_centres_mm(H, W, P, h)
    if c["source"] == "mc":  # the vein on a pixel centre (the brute-force runs are at pixel centres)
        x, y = x - x[H // 2], y - y[W // 2]
    X, Y = np.meshgrid(x, y, indexing="ij")
    rho = X if c["angle"] == 0.0 else -Y
    return np.abs(rho) < 0.5 * c["diameter_mm"] + 0.5 * P * h / H, rho


def _skin_scene(c, kernel_of):
    """A skin capture's scene from the kernel ``kernel_of(rho_mm, u)`` of a pixel ``rho_mm`` from the vein."""
    from planeray.scenes._textures import smooth_noise
    from planeray.scenes.base import Scene, footprint_kernel
    from planeray.timing import RowGeometry
    from planeray.transport import Transport

    H, W = SKIN_SHAPE
    P, h = SKIN_PROJECTOR_ROWS, SKIN_MM_PER_ROW
    geo = RowGeometry(H, P)
    rpc = geo.rows_per_camera_row
    band = 64
    offsets = np.arange(-band, band + 1)
    half = int(math.ceil(0.5 * rpc + 0.5))
    wide = np.arange(offsets[0] - half, offsets[-1] + half + 1)
    foot = footprint_kernel(np.arange(-half, half + 1), rpc)
    mask, rho = _vein_mask(H, W, P, h, c)
    rng = np.random.default_rng(7)
    tint = 1.0 + smooth_noise((H, W), rng, max(H, W) / 8.0, 0.05)
    sub = kernel_of(rho, wide) * tint[:, :, None]  # (H, W, U')
    from scipy.ndimage import convolve1d

    sub = convolve1d(sub, foot[::-1], axis=2, mode="constant")[:, :, half:-half]
    surface = (0.03 * (1.0 + smooth_noise((H, W), rng, 0.7, 0.15))).astype(np.float32)
    fo = footprint_kernel(offsets, rpc).astype(np.float32)
    dense = sub.astype(np.float32) + surface[:, :, None] * fo[None, None, :]
    ambient = dense.sum(axis=2)
    dense *= geo.coverage(np.arange(H)[:, None], offsets[None, :]).astype(np.float32)[:, None, :]
    return Scene("case", Transport(dense, offsets, geo), surface, ambient.astype(np.float32),
                 np.full((H, W), 2, np.uint8), params={}), mask  # fmt: skip


def _make_mc_skin(c, folder: Path) -> dict:
    """The vein's kernel at every pixel from brute force: a pencil beam at the pixel, the blood cylinder in the medium
    (:func:`planeray.mc.layered.mc_vein_kernel_brute`), one run per distance of a pixel centre from the vein."""
    from planeray.mc.layered import mc_layered_profile, mc_vein_kernel_brute
    from planeray.optical_data_skin import skin_layers

    skin = skin_layers(c["nm"], c["tone"], dermis_mm=c["dermis_mm"])
    h = SKIN_MM_PER_ROW
    px = SKIN_PROJECTOR_ROWS * h / SKIN_SHAPE[0]
    n_rho = int(SKIN_REACH_MM // px) + 1  # |rho| = k px, k = 0 .. n_rho - 1 (the vein on a pixel centre)
    off = np.arange(-72, 73)
    cache = folder / "brute.npz"
    if cache.exists():
        z = np.load(cache)
        kern, k0 = z["kernels"], z["k0"]
    else:
        t0 = time.time()
        kern = np.stack([
            mc_vein_kernel_brute(skin.layers, skin.blood, depth_mm=c["depth_mm"], diameter_mm=c["diameter_mm"],
                                 angle_deg=c["angle"], rho_rows=k * px / h, offsets_rows=off, mm_per_row=h,
                                 n_photons=SKIN_PHOTONS, seed=31 + k).values
            for k in range(n_rho)
        ])  # fmt: skip
        k0 = mc_layered_profile(skin.layers, n_photons=SKIN_PHOTONS, offsets_rows=off, mm_per_row=h, seed=30).values
        np.savez(cache, kernels=kern, k0=k0)
        print(f"  traced {c['id']} ({time.time() - t0:.0f} s)", flush=True)

    def kernel_of(rho_mm, u):
        """Each pixel's kernel: its run's (|rho| on the grid; the mirror image for rho < 0), vein-free beyond."""
        k = np.rint(np.abs(rho_mm) / px).astype(np.int64)
        uu = np.asarray(u)
        inside = (uu >= off[0]) & (uu <= off[-1])
        j = np.clip(uu - off[0], 0, off.size - 1)
        jm = np.clip(-uu - off[0], 0, off.size - 1)  # u -> -u
        # mirroring rho -> -rho: (x, y) -> (-x, y) for a vein along the rows (angle 0), offsets u -> -u;
        # (x, -y) for a vein across them (angle 90), offsets unchanged
        neg = (rho_mm < 0)[..., None] & (c["angle"] == 0.0)
        kk = np.where(neg, kern[np.minimum(k, n_rho - 1)][..., jm], kern[np.minimum(k, n_rho - 1)][..., j])
        kk = np.where((k < n_rho)[..., None], kk, k0[j])
        return np.where(inside, kk, 0.0)

    scene, mask = _skin_scene(c, kernel_of)
    cam = _camera()
    return dict(stack=_simulate(scene, seed=51, camera=cam), veins=mask, camera=cam, h=h)


def _make_mitsuba_skin(c, folder: Path) -> dict:
    """A thin render (the vein along the rows: every column alike), its columns averaged and tiled."""
    from planeray.io import read_transport
    from planeray.scenes.base import Scene
    from planeray.timing import RowGeometry
    from planeray.transport import Transport

    H, W = SKIN_SHAPE
    P, h = SKIN_PROJECTOR_ROWS, SKIN_MM_PER_ROW
    m = SKIN_MITSUBA
    # the thin render covers the vein's neighbourhood, m["H"] camera rows about the middle at the same pixel size:
    # its projector reaches >= 15 mm beyond every row within 12 mm of the vein (the kernel there is < 1e-5)
    Pm = int(round(P * m["H"] / H))
    T = _render(_skin_body(c), folder, "skin", H=m["H"], W=m["W"], P=Pm, h=h, spp=m["spp"], seed=3, band_rows=64)
    tr, _ = read_transport(T)
    prof = np.asarray(tr.dense, np.float64).mean(axis=1)  # (Hm, U): columns averaged
    # camera rows of the capture whose centre lies within the render's rows get its profiles (by distance from
    # the vein); the rest are vein-free skin: the render's outermost rows (>= 12 mm from the vein)
    x_cap, _ = _pixel_centres_mm(H, W, P, h)
    x_ren, _ = _pixel_centres_mm(m["H"], m["W"], Pm, h)
    idx = np.abs(x_cap[:, None] - x_ren[None, :]).argmin(axis=1)
    far = np.abs(x_cap) > np.abs(x_ren).max()
    bg = 0.5 * (prof[0] + prof[-1])
    rows = np.where(far[:, None], bg[None, :], prof[idx])
    geo = RowGeometry(H, P)
    off = np.asarray(tr.offsets_rows)
    cov = geo.coverage(np.arange(H)[:, None], off[None, :])
    dense = np.repeat((rows * cov)[:, None, :], W, axis=1).astype(np.float32)
    direct = dense[:, :, off == 0][..., 0]
    scene = Scene("case", Transport(dense, off, geo), direct, dense.sum(axis=2), np.full((H, W), 2, np.uint8), {})
    mask, _ = _vein_mask(H, W, P, h, c)
    cam = _camera()
    return dict(stack=_simulate(scene, seed=61, camera=cam), veins=mask, camera=cam, h=h)


# ----------------------------------------------------------------------------- the materials scene
def _make_scene_case(c, folder: Path) -> dict:
    from planeray.experiments.materials import simulate_capture

    cap = simulate_capture(size=(c["size"], c["size"]), seed=c["seed"], placement=c["placement"], noise=c["noise"],
                           ambient_e_per_us=c["ambient"])  # fmt: skip
    return dict(stack=cap.stack, labels=cap.labels, camera=_camera(c["noise"], c["ambient"]), h=0.3,
                wall_distance_mm=cap.wall_distance_mm)  # fmt: skip


# ----------------------------------------------------------------------------- making and listing
def make(c: dict, root: Path = ROOT) -> Path:
    """Make one case's capture folder (idempotent: an existing ``done`` marker skips it)."""
    folder = root / c["id"]
    if (folder / "done").exists():
        return folder
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    if c["domain"] == "media":
        made = {"mitsuba": _make_mitsuba_media, "mc": _make_mc_media, "scene": _make_scene_case}[c["source"]](c, folder)
    else:
        made = {"mitsuba": _make_mitsuba_skin, "mc": _make_mc_skin}[c["source"]](c, folder)
    for name in ("capture", "white"):
        if (folder / name).exists():
            shutil.rmtree(folder / name)
    _write_capture(made["stack"], folder / "capture", mm_per_row=made["h"], camera=made["camera"])
    if made.get("white") is not None:
        _write_capture(made["white"], folder / "white", mm_per_row=made["h"], camera=made["camera"])
    if made.get("labels") is not None:
        _write_labels(folder / "labels.png", made["labels"])
    if made.get("wall_distance_mm") is not None:
        np.save(folder / "wall_distance_mm.npy", np.asarray(made["wall_distance_mm"], np.float32))
    if made.get("veins") is not None:
        _write_mask(folder / "veins.png", made["veins"])
    truth = dict(c)
    truth["white_albedo"] = made.get("white_albedo", 1.0)
    (folder / "truth.json").write_text(json.dumps(truth, indent=1))
    (folder / "done").write_text(f"{time.time() - t0:.0f} s\n")
    print(f"{c['id']}: {folder} ({time.time() - t0:.0f} s)", flush=True)
    return folder


def write_mask(c: dict, root: Path = ROOT) -> None:
    """(Re)write a skin case's vein mask from its definition (the capture is left as it is)."""
    H, W = SKIN_SHAPE
    mask, _ = _vein_mask(H, W, SKIN_PROJECTOR_ROWS, SKIN_MM_PER_ROW, c)
    _write_mask(root / c["id"] / "veins.png", mask)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("make", "list"))
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--root", type=Path, default=ROOT)
    a = ap.parse_args(argv)
    todo = cases() if a.only is None else [case(i) for i in a.only]  # in the order asked
    if a.what == "list":
        for c in todo:
            print(json.dumps(c))
        return
    for c in todo:
        try:
            make(c, a.root)
        except Exception as exc:  # one failed case must not stop the others
            print(f"{c['id']}: FAILED {exc!r}", file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
