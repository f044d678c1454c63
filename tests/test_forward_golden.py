"""The forward models, bit for bit: a matrix of small runs whose every array and scalar is hashed (issue 43).

Written before the forward models moved to one home (``planeray.kernels``, photons only in ``planeray.mc``),
with the hashes of the code before the move: the move must not change one byte.  Each case hashes every
output (the bytes of each array, with its dtype and shape; scalars as the ``repr`` of the value rounded to 12
significant digits) and runs at 1 and 2 Numba threads (the results must not depend on them).  The photon
counts are tiny: the hashes are a fingerprint of the code path, not of the physics (the physics is tested
against independent references in ``test_mc*.py``, ``test_materials_fit.py``, ``test_skin_depth.py``).

``test_every_shipped_table_is_a_cache_hit``: every file shipped in ``planeray/mc/tables`` is read by the
builds that use it, and nothing is traced (an empty user cache stays empty).

A change that alters the results on purpose updates :data:`EXPECTED` (``PLANERAY_GOLDEN_PRINT=1`` prints the
new hashes) and says so in its commit.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os

import numba
import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from planeray.medium import Medium

# ---------------------------------------------------------------- the fingerprint


def _feed(h, obj, depth=0):
    """Feed ``obj`` into the hash: arrays by their bytes, scalars rounded, containers and dataclasses by field."""
    if depth > 12:
        raise TypeError("too deep")
    if isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        h.update(f"A{a.dtype.str}{a.shape}".encode())
        if a.dtype.kind == "O":
            for v in a.ravel():
                _feed(h, v, depth + 1)
        else:
            h.update(a.tobytes())
    elif isinstance(obj, (bool, np.bool_)) or obj is None or isinstance(obj, str):
        h.update(repr(obj).encode())
    elif isinstance(obj, (int, np.integer)):
        h.update(f"i{int(obj)}".encode())
    elif isinstance(obj, (float, np.floating)):
        v = float(obj)
        h.update(("f" + (repr(v) if not math.isfinite(v) else f"{v:.12g}")).encode())
    elif isinstance(obj, dict):
        h.update(b"{")
        for k in sorted(obj, key=str):
            h.update(str(k).encode())
            _feed(h, obj[k], depth + 1)
        h.update(b"}")
    elif isinstance(obj, (list, tuple)):
        h.update(b"[")
        for v in obj:
            _feed(h, v, depth + 1)
        h.update(b"]")
    elif dataclasses.is_dataclass(obj):
        h.update(type(obj).__name__.encode())
        for f in dataclasses.fields(obj):
            if f.name.startswith("_"):
                continue
            _feed(h, f.name, depth + 1)
            _feed(h, getattr(obj, f.name), depth + 1)
    else:
        raise TypeError(f"cannot fingerprint {type(obj).__name__}")


def _digest(obj) -> str:
    h = hashlib.sha256()
    _feed(h, obj)
    return h.hexdigest()[:16]


# ---------------------------------------------------------------- the runs
MED = Medium(sigma_s=2.0, sigma_a=0.05, g=0.7, n=1.33)
OFF = np.arange(-12, 13)


def _slab():
    from planeray.mc import mc_line_profile, mc_point_profile

    kw = dict(offsets_rows=OFF, mm_per_row=0.5, seed=1)
    return dict(
        hybrid=mc_line_profile(MED, n_photons=3000, **kw),
        no_hybrid=mc_line_profile(
            Medium(sigma_s=2.0, sigma_a=0.4, g=0.7), n_photons=2000, diffusion_depth_mfp=None, **kw
        ),
        clear=mc_line_profile(Medium(sigma_s=1.0, sigma_a=0.0, g=0.0, n=1.0), n_photons=2000, **kw),
        point=mc_point_profile(MED, n_photons=2000, radius_bins=np.arange(0, 15), mm_per_bin=0.5, seed=2),
        finite=mc_line_profile(
            Medium(sigma_s=2.0, sigma_a=0.05, g=0.7, n=1.4, thickness_mm=2.0), n_photons=2000, source_width_mm=1.0, **kw
        ),
    )


def _diffusion():
    from planeray.kernels import (
        boundary_mismatch_A,
        dipole_line_kernel,
        dipole_reflectance,
        dipole_total_reflectance,
        line_kernel,
    )
    from planeray.mc import diffusion_normal_radiance_ratio
    from planeray.mc.wall import wall_exit_fractions

    med = Medium.from_reduced(1.0, 0.02, g=0.8, n=1.33)
    return dict(
        A=[boundary_mismatch_A(n) for n in (1.0, 1.33, 1.5)],
        R=dipole_reflectance(med, np.linspace(0.0, 5.0, 11)),
        Rt=dipole_total_reflectance(med),
        line=dipole_line_kernel(med, OFF, mm_per_row=0.3),
        named=line_kernel(med, OFF, mm_per_row=0.3, model="dipole"),
        ratio=[diffusion_normal_radiance_ratio(n) for n in (1.0, 1.4)],
        walls=[wall_exit_fractions([0.3, 2.0, 30.0], medium=MED, wall=w) for w in ("fresnel", "absorbing")],
        clear_walls=wall_exit_fractions([0.5, 5.0], medium=Medium(sigma_s=2.0, sigma_a=0.0, g=0.5, n=1.33)),
    )


def _walls():
    from planeray.mc.wall import mc_wall_profile

    out = {}
    for wall in ("fresnel", "absorbing"):
        for angle in (0.0, 45.0, 90.0):
            for dist in (0.0, 1.0, 4.0):
                out[f"{wall}/{angle}/{dist}"] = mc_wall_profile(
                    MED, wall_distance_mm=dist, wall_angle_deg=angle, wall=wall, n_photons=600, offsets_rows=OFF,
                    mm_per_row=0.5, seed=3,
                )  # fmt: skip
    out["none"] = mc_wall_profile(MED, wall_distance_mm=math.inf, n_photons=600, offsets_rows=OFF, mm_per_row=0.5)
    out["traced"] = mc_wall_profile(
        MED, wall_distance_mm=1.0, wall_angle_deg=45.0, diffusion_depth_mfp=None, n_photons=300, offsets_rows=OFF,
        mm_per_row=0.5,
    )  # fmt: skip
    return out


TISSUE = [
    Medium(sigma_s=10.0, sigma_a=0.1, g=0.9, n=1.4, thickness_mm=0.5),
    Medium(sigma_s=5.0, sigma_a=0.05, g=0.85, n=1.4, thickness_mm=6.0),
]
BLOOD = Medium(sigma_s=5.0, sigma_a=0.8, g=0.9, n=1.4)


#: What a layered run reports (its result type changed in issue 43: these fields are hashed, not the type).
LAYERED_FIELDS = (
    "offsets_rows", "mm_per_row", "values", "stderr", "total_reflectance", "total_reflectance_stderr",
    "specular_reflectance", "transmittance", "absorbed", "truncated", "n_photons",
)  # fmt: skip


def _fields(res):
    return {k: getattr(res, k) for k in LAYERED_FIELDS}


def _layered():
    from planeray.mc.layered import mc_layered_profile, mc_layered_vein_brute, mc_vein_kernel_brute

    off = np.arange(-10, 11)
    kw = dict(offsets_rows=off, mm_per_row=0.3)
    return dict(
        pencil=_fields(mc_layered_profile(TISSUE, n_photons=1500, seed=1, **kw)),
        vein_pencil=[
            _fields(
                mc_vein_kernel_brute(
                    TISSUE, BLOOD, depth_mm=0.8, diameter_mm=1.0, angle_deg=a, rho_rows=1.0, n_photons=800, seed=2, **kw
                )
            )
            for a in (0.0, 90.0)
        ],
        vein_line=mc_layered_vein_brute(
            TISSUE,
            BLOOD,
            depth_mm=0.8,
            diameter_mm=1.0,
            angle_deg=90.0,
            rho_rows=np.arange(-2, 3),
            n_photons=800,
            seed=3,
            **kw,
        ),  # fmt: skip
    )


def _tables():
    from planeray.kernels.vein import mc_vein_table
    from planeray.kernels.wall import mc_wall_table
    from planeray.materials.fit import build_forward_table

    wall = mc_wall_table(
        MED, distances_rows=(0.0, 3.0, 50.0), angles_deg=(0.0, 90.0), offsets_rows=OFF, mm_per_row=0.5,
        n_photons=400, slab_photons=1000, cache=False,
    )  # fmt: skip
    vein = mc_vein_table(
        TISSUE, BLOOD, depths_mm=(0.5, 1.0), diameters_mm=(0.5, 1.0), angles_deg=(0.0, 90.0),
        rho_rows=np.arange(-4, 5, 2), offsets_rows=np.arange(-8, 9), n_photons=800, cache=False,
    )  # fmt: skip
    fwd = build_forward_table(
        mu_s_prime_per_mm=(0.3, 1.0, 3.0, 8.0), mu_a_per_mm=(0.001, 0.01, 0.05, 0.2), reach_rows=10, n_photons=200
    )
    return dict(
        wall=wall,
        wall_kernels=wall.kernels(np.array([1.0, 10.0, 100.0]), np.array([30.0, 0.0, 90.0])),
        vein=vein,
        forward=fwd,
        forward_log=fwd.log_kernel_per_row(np.log(0.4), np.log(0.003)),
    )


def _fit_kernels():
    from planeray.materials import fit

    off = np.arange(-30, 31)
    return dict(
        plain=fit.forward_kernel(1.0, 0.01, offsets_rows=off, mm_per_row=0.3, rows_per_camera_row=5.625),
        dipole_side=fit.forward_kernel(20.0, 0.01, offsets_rows=off, mm_per_row=0.3, rows_per_camera_row=1.0),
        walls=fit.forward_kernel(
            1.0,
            0.01,
            offsets_rows=off,
            mm_per_row=0.3,
            rows_per_camera_row=5.625,
            walls=[(4.0, 0.0, 1.0, 1.0), (10.0, 90.0, -1.0, 1.0)],
        ),  # fmt: skip
        black=fit.forward_kernel(
            0.5,
            0.02,
            offsets_rows=off,
            mm_per_row=0.3,
            rows_per_camera_row=2.0,
            walls=[(3.0, 0.0, -1.0, 1.0)],
            wall_kind="black",
        ),  # fmt: skip
        bottom=fit.forward_kernel(
            1.0, 0.01, offsets_rows=off, mm_per_row=0.3, rows_per_camera_row=2.0, walls=[(6.0, 180.0, 1.0, 1.0)]
        ),
    )


def _scene(scene):
    return dict(
        name=scene.name,
        dense=scene.transport.dense,
        offsets=scene.transport.offsets_rows,
        direct=scene.direct,
        ambient=scene.ambient_albedo,
        labels=scene.labels,
        maps=scene.maps,
        params={k: v for k, v in scene.params.items() if isinstance(v, (int, float, str, bool, np.ndarray, list))},
    )


def _scenes():
    from planeray.scenes import make_scene

    mat = make_scene("materials", (32, 32), projector_rows=180, seed=0)
    skin = make_scene("skin", (32, 32), projector_rows=180, seed=0)
    return dict(materials=_scene(mat), skin=_scene(skin))


def _fits():
    from planeray.materials.fit import fit_transport
    from planeray.scenes import make_scene

    scene = make_scene("materials", (32, 32), projector_rows=180, seed=0)
    mm = scene.params["mm_per_row"]
    res = fit_transport(scene.transport, mm_per_row=mm, labels=scene.labels, block_px=8)
    walls = fit_transport(
        scene.transport, mm_per_row=mm, labels=scene.labels, block_px=8, regions_only=True,
        containers=scene.labels, depth_mm=4.0,
    )  # fmt: skip
    return dict(maps=res.maps, regions=res.regions, profiles=res.profiles, walls=walls.regions)


def _stack_fit():
    from planeray.acquire import simulate_stack
    from planeray.materials import fit
    from planeray.materials.stackfit import fit_stack
    from planeray.scenes.base import Scene, footprint_kernel, scene_offsets
    from planeray.timing import RowGeometry, paper_sweep
    from planeray.transport import Transport

    H, W, P, mm = 12, 2, 68, 0.3
    geo = RowGeometry(H, P)
    off = scene_offsets()
    cov = geo.coverage(np.arange(H)[:, None], off[None, :])
    rpc = P / H

    def homogeneous(kernel, albedo):
        dense = np.repeat((kernel[None, :] * cov)[:, None, :], W, axis=1).astype(np.float32)
        return Scene(
            "homogeneous", Transport(dense, off, geo), np.zeros((H, W), np.float32),
            np.full((H, W), albedo, np.float32), np.full((H, W), 2, np.uint8), params={"mm_per_row": mm},
        )  # fmt: skip

    k = fit.forward_kernel(1.0, 0.01, offsets_rows=off, mm_per_row=mm, rows_per_camera_row=rpc)
    sweep = paper_sweep()
    stack = simulate_stack(homogeneous(k, float(k.sum())), sweep, seed=3)
    white = simulate_stack(homogeneous(0.99 * footprint_kernel(off, rpc), 0.99), sweep, seed=4)
    from planeray.materials.stackfit import white_stack_scale

    scale = white_stack_scale(white, albedo=0.99)
    res = fit_stack(stack, mm_per_row=mm, white=scale)
    return dict(scale=scale, regions=res.regions, maps=res.maps)


def _vein_fit():
    from planeray.camera import CameraModel
    from planeray.skin.depth import (
        background_signals,
        fit_vein,
        image_variance,
        usable_bands,
        vein_geometry,
        vein_model,
        vein_signals,
    )
    from planeray.timing import RowGeometry, paper_sweep

    H = W = 40
    geom = RowGeometry(H, 240)
    sweep = paper_sweep()
    bands = sweep.bands(54_000.0, jitter_us=5.0)
    use = usable_bands(bands, geom, excluded=sweep.excluded)
    bands = [b for b, u in zip(bands, use) if u]
    model = vein_model(bands, geom, mm_per_row=0.3)
    col_mm = 240 * 0.3 / H
    rows = np.repeat(np.arange(H), W)
    y = (np.tile(np.arange(W), H) + 0.5) * col_mm
    rho = -(y - 36.0)
    sel = np.abs(rho) < 12.0
    ratio = np.ones((len(bands), H * W))
    ratio[:, sel], _ = vein_signals(model, rows[sel], rho[sel], np.full(sel.sum(), 90.0), 1.5, 2.0)
    ratio = np.nan_to_num(ratio, nan=1.0)
    bg = 0.6 * background_signals(model, np.arange(H))
    images = bg[:, :, None] * ratio.reshape(len(bands), H, W)
    var = image_variance(images, CameraModel())
    images = images + np.random.default_rng(0).normal(0.0, np.sqrt(var))
    yy = np.mgrid[0:H, 0:W][0]
    mask = (np.abs(rho) <= 1.0).reshape(H, W) & (yy >= 6) & (yy < 34)
    pix = vein_geometry(mask, np.zeros((H, W), bool), geom, mm_per_row=0.3)
    fit = fit_vein(model, images, var, pix, ambient=False, max_pixels=120)
    return dict(model_kernel=model.table.kernel, background=bg, fit=fit)


CASES = {
    "slab": _slab,
    "diffusion": _diffusion,
    "walls": _walls,
    "layered": _layered,
    "tables": _tables,
    "fit_kernels": _fit_kernels,
    "scenes": _scenes,
    "fit_transport": _fits,
    "fit_stack": _stack_fit,
    "vein_fit": _vein_fit,
}

#: Hashes of the code on main before the forward models moved (issue 43).
EXPECTED = {
    "slab": "0aeb08644951b6fd",
    "diffusion": "6f5afb9811078959",
    "walls": "7c3cc1143017647a",
    "layered": "62db1492fcd200f8",  # the fields of a layered run (its type changed): computed on main
    "tables": "1e6d586ee09fec80",
    "fit_kernels": "2e0493cc35dc91d3",
    "scenes": "a9f0dabe59be4057",
    "fit_transport": "eae747a2473ed106",  # the walls' model error, a second optimum looked for (issue 41)
    "fit_stack": "7e4c97c0cd9e56e0",  # the media's g a fitted nuisance (issue 41); its second start finds the same
    "vein_fit": "d70b62dc2a932f68",
}


@pytest.fixture(params=[1, 2], ids=["1-thread", "2-threads"])
def threads(request):
    before = numba.get_num_threads()
    numba.set_num_threads(min(request.param, numba.config.NUMBA_NUM_THREADS))
    yield request.param
    numba.set_num_threads(before)


@pytest.mark.parametrize("case", list(CASES))
def test_forward_models_are_bit_for_bit(case, threads, tmp_path, monkeypatch):
    monkeypatch.setenv("PLANERAY_CACHE", str(tmp_path))  # nothing from a user cache: shipped tables or traced
    # one BLAS thread, as each test worker has (conftest.py): OpenBLAS's threads split a product's sums
    # differently (the last bits of the fits' whitening, fit.wall_error_columns, depend on them)
    with threadpool_limits(1, user_api="blas"):
        got = _digest(CASES[case]())
    if os.environ.get("PLANERAY_GOLDEN_PRINT"):
        print(f"\nGOLDEN {case!r}: {got!r},")
    assert got == EXPECTED[case]


_SHIPPED_CHECK = """
import os, sys
import numpy as np
from planeray.materials import fit
from planeray.mc.cache import TABLES_DIR
from planeray.optical_data_skin import SKIN_TONES
from planeray.scenes import list_scenes, make_scene

read = set()
real_load = np.load


def spy(file, *a, **k):
    p = os.path.abspath(os.fspath(file))
    if os.path.dirname(p) == os.path.abspath(TABLES_DIR):
        read.add(os.path.basename(p))
    return real_load(file, *a, **k)


np.load = spy
# tools/build_mc_tables.py's builds (the scenes' tables) and tools/build_fit_table.py's forward tables.
builds = [(name, {}) for name in list_scenes()]
builds += [("materials", {"source": "jensen"}), ("materials", {"channel": "green"})]
builds += [("materials", {"channel": "blue"}), ("materials", {"container": "cup", "placement": 2})]
builds += [("skin", {"wavelength_nm": w, "tone": t}) for w in (638, 850) for t in SKIN_TONES]
for name, params in builds:
    make_scene(name, (16, 16), projector_rows=90, seed=0, **params)
for n in (1.33, 1.38, 1.45):
    fit.forward_table(n=n)
from planeray.kernels.anisotropy import anisotropy_table
anisotropy_table()  # the fits' model error over the unknown g
print(sorted({p.name for p in TABLES_DIR.glob("*.npz")} - read))
"""


def test_every_shipped_table_is_a_cache_hit(tmp_path):
    """Every file in the shipped tables is read by the builds that use it (a fresh process: no tables held),
    and nothing is traced (the empty user cache stays empty)."""
    import subprocess
    import sys

    env = {**os.environ, "PLANERAY_CACHE": str(tmp_path), "NUMBA_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", _SHIPPED_CHECK], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[]", "shipped tables no build reads (stale keys?)"
    assert not list(tmp_path.rglob("*.npz")), "a build traced what should have been shipped"
