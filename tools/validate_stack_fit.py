"""Validation of ``planeray.materials.stackfit.fit_stack``: the numbers of docs/user_guide/materials_fit.md,
"From the stack images".

(a) **Known homogeneous media, independent forward model.**  Every pixel of a small image sees one
    medium whose transport is a *direct* Monte Carlo line kernel (:func:`planeray.mc.mc_line_profile`,
    another seed and photon count than the forward table), averaged over the camera row's footprint;
    the stack is simulated with planeray's camera (shot, read, quantization, row jitter, ambient light)
    over the paper's sweep.  ``mu_s'`` in {0.3, 1, 5} x ``mu_a`` in {0.001, 0.01, 0.1} /mm, 3 noise seeds,
    with and without a white reference (a white Lambertian target simulated with the same sweep and
    camera).  Beside it: the same captures demultiplexed (``capture_transport``, floor removed) and
    fitted with ``fit_transport`` (the earlier path).
(b) **The materials scene's noisy capture** (``materials`` report's test settings), pixels >= 3 mm
    from the walls, walls modelled: :func:`planeray.experiments.materials.media_fit_numbers`.

    nice -n 19 python tools/validate_stack_fit.py [--quick] [--no-demux] [--scene-only | --media-only]
        [--scene-seeds 1,2,3] [--near-wall-mm 3] [--out FILE]
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from planeray.acquire import simulate_stack
from planeray.experiments.materials import camera_for
from planeray.materials import fit
from planeray.materials.stackfit import fit_stack, white_stack_scale
from planeray.mc import mc_line_profile
from planeray.medium import Medium
from planeray.scenes.base import Scene, footprint_kernel, scene_offsets
from planeray.timing import RowGeometry, paper_sweep
from planeray.transport import Transport

MM = 0.3
SHAPE = (32, 8)
PROJECTOR_ROWS = 180  # 5.625 projector rows per camera row, as the materials scene at 128 x 128
OUT = Path("/work/notes/i27-stackfit.json")


def direct_kernel(s, a, *, seed, n_photons):
    """Direct Monte Carlo kernel on the scene's offsets (the scenes' unit), averaged over the camera row's footprint."""
    off = scene_offsets()
    med = Medium.from_reduced(s, a, g=fit.DEFAULT_G, n=fit.DEFAULT_N)
    wide = np.arange(off[0] - 8, off[-1] + 9)
    p = mc_line_profile(med, n_photons=n_photons, offsets_rows=wide, mm_per_row=MM, seed=seed)
    k = np.pi * MM * p.radiance
    f = footprint_kernel(np.arange(-8, 9), PROJECTOR_ROWS / SHAPE[0])
    return np.convolve(k, f, mode="same")[8:-8]


def homogeneous_scene(kernel, *, ambient_albedo):
    """A scene whose every pixel sees ``kernel`` (each bin's part on the projector: the edge rule)."""
    H, W = SHAPE
    geo = RowGeometry(H, PROJECTOR_ROWS)
    off = scene_offsets()
    cov = geo.coverage(np.arange(H)[:, None], off[None, :])
    dense = np.repeat((kernel[None, :] * cov)[:, None, :], W, axis=1).astype(np.float32)
    T = Transport(dense, off, geo)
    direct = np.full((H, W), float(kernel[off == 0][0]), np.float32)
    return Scene(
        "homogeneous", T, direct, np.full((H, W), ambient_albedo, np.float32), np.full((H, W), 2, np.uint8),
        params={"mm_per_row": MM},
    )  # fmt: skip


def white_scene(albedo=0.99):
    off = scene_offsets()
    return homogeneous_scene(albedo * footprint_kernel(off, PROJECTOR_ROWS / SHAPE[0]), ambient_albedo=albedo)


def rel(v, truth):
    return None if v is None else float(v / truth - 1.0)


def known_media(quick, demux, camera):
    from planeray.materials.model import capture_transport

    S = [0.3, 1.0, 5.0]
    A = [0.001, 0.01, 0.1]
    seeds = [1, 2] if quick else [1, 2, 3]
    table = fit.forward_table()
    rows = []
    white_scales = {}
    for seed in seeds:
        w = simulate_stack(white_scene(), paper_sweep(), camera=camera, seed=500 + seed)
        white_scales[seed] = white_stack_scale(w, albedo=0.99)
    for s in S:
        for a in A:
            t0 = time.time()
            k = direct_kernel(s, a, seed=1000 + int(s * 100) + int(a * 1e4), n_photons=20_000 if quick else 50_000)
            sc = homogeneous_scene(k, ambient_albedo=float(k.sum()))
            for seed in seeds:
                st = simulate_stack(sc, paper_sweep(), camera=camera, seed=seed)
                row = dict(mu_s_prime=s, mu_a=a, seed=seed)
                for tag, white in (("stack_white", white_scales[seed]), ("stack_shape", None)):
                    r = fit_stack(st, mm_per_row=MM, white=white, table=table).regions[1]
                    row[tag] = dict(
                        err_s=rel(r["mu_s_prime_per_mm"], s),
                        err_a=rel(r["mu_a_per_mm"], a),
                        se_s=None if r["mu_s_prime_se_per_mm"] is None else r["mu_s_prime_se_per_mm"] / s,
                        se_a=None if r["mu_a_se_per_mm"] is None else r["mu_a_se_per_mm"] / a,
                        mask=r["mask"],
                        chi2=r["chi2_per_dof"],
                    )
                if demux:
                    T = capture_transport(st)
                    r = fit.fit_transport(T, mm_per_row=MM, block_px=4, regions_only=True, table=table).regions[1]
                    row["demux_shape"] = dict(err_s=rel(r["mu_s_prime_per_mm"], s), err_a=rel(r["mu_a_per_mm"], a))
                rows.append(row)
                print(json.dumps(row), flush=True)
            print(f"  mu_s' {s} mu_a {a}: {time.time() - t0:.0f} s", flush=True)
    return rows


def summarize(rows):
    out = {}
    for tag in ("stack_white", "stack_shape", "demux_shape"):
        sel = [r[tag] for r in rows if tag in r]
        if not sel:
            continue
        es = np.array([np.nan if r["err_s"] is None else abs(r["err_s"]) for r in sel])
        ea = np.array([np.nan if r["err_a"] is None else abs(r["err_a"]) for r in sel])

        def stat(v, q):
            return float(np.nanpercentile(v, q)) if np.isfinite(v).any() else None

        out[tag] = dict(
            fits=len(sel),
            mu_s_prime_identified=float(np.isfinite(es).mean()),
            mu_s_prime_median_rel_err=stat(es, 50),
            mu_s_prime_p90_rel_err=stat(es, 90),
            mu_a_identified=float(np.isfinite(ea).mean()),
            mu_a_median_rel_err=stat(ea, 50),
            mu_a_p90_rel_err=stat(ea, 90),
        )
        for p in ("s", "a"):  # are the standard errors honest? |error| / standard error
            z = np.array(
                [abs(r[f"err_{p}"]) / r[f"se_{p}"] for r in sel if r.get(f"se_{p}") and r[f"err_{p}"] is not None]
            )
            key = "mu_s_prime" if p == "s" else "mu_a"
            out[tag][f"{key}_within_2se"] = float((z < 2).mean()) if z.size else None
            out[tag][f"{key}_median_err_over_se"] = float(np.median(z)) if z.size else None
        per = {}
        for r, e_s, e_a in zip([r for r in rows if tag in r], es, ea):
            key = f"{r['mu_s_prime']}/{r['mu_a']}"
            per.setdefault(key, {"err_s": [], "err_a": []})
            per[key]["err_s"].append(None if not np.isfinite(e_s) else round(float(e_s), 4))
            per[key]["err_a"].append(None if not np.isfinite(e_a) else round(float(e_a), 4))
        out[tag]["per_medium_abs_rel_err"] = per
    return out


def scene_capture(size, demux, seed=None, near_wall_mm=3.0):
    """(b): the materials scene's test capture: the stack fit (shape only; a white card's capture), the
    demultiplex-then-fit path and the ground-truth transport, each container >= 3 mm from its walls, walls modelled."""
    from planeray.experiments.materials import (
        TEST_SETTINGS,
        _capture_scene,
        media_fit_numbers,
        simulate_capture,
        simulate_white_reference,
    )
    from planeray.materials.model import capture_transport

    settings = {**TEST_SETTINGS, **({} if seed is None else {"seed": seed})}
    cap = simulate_capture(size=(size, size), **settings)
    white = simulate_white_reference(
        size=(size, size), seed=settings["seed"] + 1000, noise=TEST_SETTINGS["noise"],
        ambient_e_per_us=TEST_SETTINGS["ambient_e_per_us"],
    )  # fmt: skip
    scene = _capture_scene(cap)
    sources = {
        "ground-truth transport": scene.transport,
        "capture, stack fit, shape only": cap.stack,
        "capture, stack fit, white reference": cap.stack,
    }
    if demux:
        sources["capture, demultiplexed, transport fit"] = capture_transport(cap.stack)
    out = {}
    for name, src in sources.items():
        t0 = time.time()
        whites = {name: white} if "white" in name else None
        r = media_fit_numbers(scene, {name: src}, whites=whites, near_wall_mm=near_wall_mm)
        for medium, row in r["media"].items():
            out.setdefault(medium, {"published": row["published"]})[name] = row[name]
        out.setdefault("seconds", {})[name] = round(time.time() - t0, 1)
        print(name, json.dumps({m: (v[name] if m != "seconds" else None) for m, v in out.items() if m != "seconds"}),
              flush=True)  # fmt: skip
    return out


def scene_summary(blocks):
    """Median and p90 of |relative error| per source over the captures, milks and toothpaste (the soap is a
    30 mm layer: not the semi-infinite medium of the model) and all five, and the identified shares."""
    out = {}
    for subset, names in (
        ("milks_and_toothpaste", ("fat-free milk", "2% milk", "whole milk", "toothpaste")),
        ("all", None),
    ):
        for block in blocks:
            for medium, row in block.items():
                if medium == "seconds" or (names is not None and medium not in names):
                    continue
                for src, v in row.items():
                    if src == "published":
                        continue
                    d = out.setdefault(subset, {}).setdefault(src, {"s": [], "a": []})
                    d["s"].append(np.nan if v["mu_s_prime_rel_err"] is None else abs(v["mu_s_prime_rel_err"]))
                    d["a"].append(np.nan if v["mu_a_rel_err"] is None else abs(v["mu_a_rel_err"]))
        for src, d in out[subset].items():
            s_, a_ = np.array(d["s"]), np.array(d["a"])

            def q(v, p):
                return float(np.nanpercentile(v, p)) if np.isfinite(v).any() else None

            out[subset][src] = dict(
                fits=int(s_.size), mu_s_prime_identified=float(np.isfinite(s_).mean()),
                mu_s_prime_median=q(s_, 50), mu_s_prime_p90=q(s_, 90), mu_a_identified=float(np.isfinite(a_).mean()),
                mu_a_median=q(a_, 50), mu_a_p90=q(a_, 90),
            )  # fmt: skip
    return out


def main():
    quick = "--quick" in sys.argv
    demux = "--no-demux" not in sys.argv
    out_path = Path(sys.argv[sys.argv.index("--out") + 1]) if "--out" in sys.argv else OUT
    t0 = time.time()
    out = {"settings": dict(shape=list(SHAPE), projector_rows=PROJECTOR_ROWS, mm_per_row=MM, camera="materials test")}
    camera = camera_for(noise=1.5, ambient_e_per_us=1.5)  # the materials report's test capture's camera
    if "--scene-only" not in sys.argv:
        rows = known_media(quick, demux, camera)
        out["known_media"] = {"summary": summarize(rows), "rows": rows}
        print(json.dumps(out["known_media"]["summary"], indent=1), flush=True)
        out_path.parent.mkdir(parents=True, exist_ok=True)
        out_path.write_text(json.dumps(out, indent=1))
    if "--media-only" not in sys.argv:
        size = 64 if quick else 128
        seeds = [None]
        if "--scene-seeds" in sys.argv:
            seeds = [int(v) for v in sys.argv[sys.argv.index("--scene-seeds") + 1].split(",")]
        near = float(sys.argv[sys.argv.index("--near-wall-mm") + 1]) if "--near-wall-mm" in sys.argv else 3.0
        for seed in seeds:
            tag = f"materials_scene_{size}" + ("" if seed is None else f"_seed{seed}")
            tag += "" if near == 3.0 else f"_near{near:g}mm"
            out[tag] = scene_capture(size, demux, seed, near)
        if len(seeds) > 1:
            out[f"materials_scene_{size}_summary"] = scene_summary(
                [out[k] for k in out if k.startswith(f"materials_scene_{size}_seed")]
            )
            print(json.dumps(out[f"materials_scene_{size}_summary"], indent=1), flush=True)
    out["seconds"] = time.time() - t0
    if out_path.exists() and "--scene-only" in sys.argv:
        prev = json.loads(out_path.read_text())
        out = {**prev, **out}
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(json.dumps(out, indent=1))
    for key, block in out.items():  # a compact table of the scene's relative errors
        if key.startswith("materials_scene") and not key.endswith("_summary"):
            print(key)
            for medium, row in block.items():
                if medium == "seconds":
                    continue
                cells = [
                    f"{src}: {_pct(v['mu_s_prime_rel_err'])} / {_pct(v['mu_a_rel_err'])}"
                    for src, v in row.items()
                    if src != "published"
                ]
                print(f"  {medium}: " + "; ".join(cells))
    print(f"written: {out_path} ({out['seconds']:.0f} s)")


def _pct(v):
    return "NaN" if v is None else f"{v:+.1%}"


if __name__ == "__main__":
    main()
