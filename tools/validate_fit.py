"""Validation of ``planeray.materials.fit``: the numbers of docs/user_guide/materials_fit.md.

1. **Known media, independent forward model.**  For a grid of ``mu_s'`` 0.3-5 /mm x ``mu_a``
   0.001-0.1 /mm, a direct Monte Carlo kernel (:func:`planeray.mc.mc_line_profile`, other seed
   and photon count than the table: a forward model the fit was not built from) at 0.3 mm per
   row, |u| <= 100 rows, plus camera-like noise (Gaussian, 2 % of the peak per sample, several
   seeds); fitted calibrated and shape-only.  Median relative errors, where identifiable.
2. **g mismatch.**  The same for media of g = 0.93 and 0.6 (the table has 0.8).
3. **The five Fig. 10 materials** in the ``materials`` scene's ground-truth transport (pixels
   >= 3 mm from every wall; samples beyond the container dropped), fitted shape-only, against
   their published constants (:mod:`planeray.optical_data`).

    nice -n 19 python tools/validate_fit.py [--quick | --fig10 | --stack]
"""

from __future__ import annotations

import json
import sys
import time
from types import SimpleNamespace

import numpy as np

from planeray.materials import fit
from planeray.mc import mc_line_profile
from planeray.medium import Medium

MM = 0.3
OFFSETS = np.arange(-100, 101)
BLOCK = 8  # pixels per block side in the Fig. 10 fits (the regions are fitted whole as well)


def direct(s, a, g, seed, n_photons):
    med = Medium.from_reduced(s, a, g=g, n=fit.DEFAULT_N)
    p = mc_line_profile(med, n_photons=n_photons, offsets_rows=OFFSETS, mm_per_row=MM, seed=seed)
    return np.pi * MM * p.radiance


def known_media(g, seeds, n_photons, quick):
    S = [0.3, 1.0, 5.0] if quick else [0.3, 0.6, 1.2, 2.5, 5.0]
    A = [0.001, 0.01, 0.1] if quick else [0.001, 0.003, 0.01, 0.03, 0.1]
    rows = []
    for s in S:
        for a in A:
            clean = direct(s, a, g, 1000 + int(s * 100) + int(a * 1e4), n_photons)
            sigma = 0.02 * clean.max() * np.ones_like(clean)
            rng = np.random.default_rng(int(s * 1000 + a * 1e5))
            Y = clean[None, :] + sigma * rng.standard_normal((seeds, clean.size))
            for cal in (True, False):
                r = fit.fit_profiles(Y, offsets_rows=OFFSETS, mm_per_row=MM, sigma=sigma, calibrated=cal)
                rows.append(
                    dict(
                        g=g,
                        mu_s_prime=s,
                        mu_a=a,
                        calibrated=cal,
                        err_s=(r.mu_s_prime_per_mm / s - 1).tolist(),
                        err_a=(r.mu_a_per_mm / a - 1).tolist(),
                        se_s=(r.mu_s_prime_se_per_mm / s).tolist(),
                        se_a=(r.mu_a_se_per_mm / a).tolist(),
                        mask=r.mask.tolist(),
                    )
                )
    return rows


def summarize(rows):
    out = {}
    for cal in (True, False):
        sel = [r for r in rows if r["calibrated"] == cal]
        es = np.abs(np.concatenate([r["err_s"] for r in sel]))
        ea = np.abs(np.concatenate([r["err_a"] for r in sel]))
        out["calibrated" if cal else "shape only"] = dict(
            fits=int(es.size),
            mu_s_prime_identified=float(np.isfinite(es).mean()),
            mu_s_prime_median_rel_err=float(np.nanmedian(es)),
            mu_s_prime_p90_rel_err=float(np.nanpercentile(es, 90)),
            mu_a_identified=float(np.isfinite(ea).mean()),
            mu_a_median_rel_err=float(np.nanmedian(ea)) if np.isfinite(ea).any() else None,
            mu_a_p90_rel_err=float(np.nanpercentile(ea, 90)) if np.isfinite(ea).any() else None,
        )
    return out


def fig10_materials(size=(96, 96), variants=("none", "walls", "exclude"), near_mm=(3.0, 0.0)):
    """The five materials of the ``materials`` scene (ground-truth transport), against their published constants.

    ``variants``: ``none`` -- semi-infinite media; ``walls`` -- the containers' walls modelled
    (``containers=`` the material map: each tray's boundary a clear wall); ``exclude`` -- no wall
    model, but every pixel's samples beyond its nearest wall's distance dropped (NaN).  For pixels
    at least ``near_mm`` from every wall (0: all pixels of each tray).
    """
    from planeray.materials.fit import container_wall_distances
    from planeray.optical_data import MATERIAL_CLASSES, material_medium
    from planeray.scenes import make_scene

    sc = make_scene("materials", size, projector_rows=720, seed=0)
    material = np.where(sc.maps["material"] == 6, 0, sc.maps["material"]).astype(np.int64)
    tr = sc.transport
    out = {}
    for near in near_mm:
        labels = np.where(sc.maps["wall_distance_mm"] >= near, material, 0)
        for variant in variants:
            t0 = time.time()
            transport, containers = tr, None
            if variant == "walls":
                containers = material
            elif variant == "exclude":
                d = container_wall_distances(material, rows_per_camera_row=tr.geometry.rows_per_camera_row)
                dmin = np.nanmin(d, axis=-1)
                dense = np.array(tr.dense, np.float64)
                dense[np.abs(tr.offsets_rows)[None, None, :] >= dmin[..., None]] = np.nan
                transport = SimpleNamespace(dense=dense, offsets_rows=tr.offsets_rows, geometry=tr.geometry)
            if variant == "exclude":  # region fits only: each region's mean over the pixels that keep a sample
                regions = {}
                for cid in MATERIAL_CLASSES:
                    m = labels == cid
                    px = transport.dense[m]
                    cnt = np.isfinite(px).sum(axis=0)
                    y = np.where(cnt > 0, np.nansum(px, axis=0) / np.maximum(cnt, 1), np.nan)
                    y[(y == 0) | (cnt < 0.1 * m.sum())] = np.nan
                    rr = fit.fit_profiles(
                        y,
                        offsets_rows=tr.offsets_rows,
                        mm_per_row=MM,
                        sigma=0.01 * np.nanmax(y),
                        rows_per_camera_row=tr.geometry.rows_per_camera_row,
                    )
                    regions[cid] = dict(
                        mu_s_prime_per_mm=fit.num_or_none(rr.mu_s_prime_per_mm[0]),
                        mu_a_per_mm=fit.num_or_none(rr.mu_a_per_mm[0]),
                        mu_s_prime_se_per_mm=fit.num_or_none(rr.mu_s_prime_se_per_mm[0]),
                        mu_a_se_per_mm=fit.num_or_none(rr.mu_a_se_per_mm[0]),
                        pixels=int(m.sum()),
                    )
                r = SimpleNamespace(regions=regions)
            else:
                r = fit.fit_transport(transport, mm_per_row=MM, labels=labels, block_px=BLOCK, containers=containers)
            res = {}
            for cid, name in MATERIAL_CLASSES.items():
                med = material_medium(cid)
                reg = r.regions.get(cid) or {}
                row = dict(true_mu_s_prime=med.sigma_s_prime, true_mu_a=med.sigma_a, g=med.g, n=med.n)
                for key, true in (("mu_s_prime_per_mm", med.sigma_s_prime), ("mu_a_per_mm", med.sigma_a)):
                    v = reg.get(key)
                    row[key] = v
                    row[key.replace("_per_mm", "_se_per_mm")] = reg.get(key.replace("_per_mm", "_se_per_mm"))
                    row[key.replace("_per_mm", "_rel_err")] = None if v is None else v / true - 1
                    bm = reg.get("blocks_median_" + key)
                    row["blocks_median_" + key.replace("_per_mm", "_rel_err")] = None if bm is None else bm / true - 1
                row["pixels"] = reg.get("pixels")
                row["blocks_identified"] = reg.get("blocks_identified")
                res[name] = row
            res["seconds"] = time.time() - t0
            out[f">= {near:g} mm, {variant}"] = res
            print(f">= {near:g} mm, {variant}:", json.dumps(res, indent=None), flush=True)
    return out


def stack_fit(size=48, seed=0):
    """A noisy simulated capture (``materials simulate``) through ``planeray materials fit --method transport``
    (demultiplexed by the command, then the transport fitted; the stack's images themselves: validate_stack_fit.py),
    with and without the walls' model: every pixel of each tray."""
    import tempfile
    from pathlib import Path

    from typer.testing import CliRunner

    from planeray.cli import app
    from planeray.experiments.materials import simulate_capture
    from planeray.optical_data import MATERIAL_CLASSES, material_medium

    out = {}
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        simulate_capture(d / "cap", size=(size, size), seed=seed)
        for walls in ("--walls", "--no-walls"):
            t0 = time.time()
            args = [
                "materials",
                "fit",
                str(d / "cap" / "stack.zarr"),
                "--out",
                str(d / walls),
                walls,
                "--method",
                "transport",
            ]
            res = CliRunner().invoke(app, [*args, "--labels", str(d / "cap" / "labels.png")])
            assert res.exit_code == 0, res.output
            regions = json.loads((d / walls / "planeray.json").read_text())["regions"]
            row = {}
            for cid, name in MATERIAL_CLASSES.items():
                med, r = material_medium(cid), regions.get(str(cid), {})
                s, a = r.get("mu_s_prime_per_mm"), r.get("mu_a_per_mm")
                row[name] = dict(
                    mu_s_prime_rel_err=None if s is None else s / med.sigma_s_prime - 1,
                    mu_a_rel_err=None if a is None else a / med.sigma_a - 1,
                    not_identifiable=r.get("not_identifiable"),
                )
            row["seconds"] = time.time() - t0
            out[walls] = row
            print(walls, json.dumps(row), flush=True)
    return out


def main():
    quick = "--quick" in sys.argv
    t0 = time.time()
    out = {}
    if "--stack" in sys.argv:  # a noisy stack through the command (was a test: beyond the test budget)
        out["stack"] = stack_fit()
        print(json.dumps(out, indent=1))
        return
    if "--fig10" in sys.argv:  # the Fig. 10 materials only (walls, near and far)
        out["fig10"] = fig10_materials()
        out["seconds"] = time.time() - t0
        print(json.dumps(out, indent=1))
        return
    rows = known_media(fit.DEFAULT_G, 3 if quick else 5, 50_000, quick)
    out["known_media_g0.8"] = summarize(rows)
    print(json.dumps(out, indent=1), flush=True)
    for g in (0.93, 0.6):
        out[f"known_media_g{g}"] = summarize(known_media(g, 3, 50_000, True))
        print(json.dumps(out[f"known_media_g{g}"], indent=1), flush=True)
    out["fig10"] = fig10_materials()
    out["seconds"] = time.time() - t0
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
