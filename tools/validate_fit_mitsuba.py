"""Check ``materials.fit`` against a forward model it was not fitted with: Mitsuba 3 renders of a slab.

For a few homogeneous media of known ``mu_s'`` / ``mu_a`` (HG, ``g`` 0.8), a thick slab (100 mm deep,
500 mm wide) is rendered through planeray's render pipeline (``planeray.render.render_transport``:
Mitsuba's own homogeneous-medium sampling, a pinhole projector, a camera looking straight down from
200 mm) into a transport ``T`` at ``--mm-per-row`` per projector row, together with a white Lambertian
plane in the same place (the calibration, ``fit.white_reference_scale``).  The camera rows away from
the top and bottom of the view (``--margin``) are fitted as one region over the offsets
``|u| < margin`` that every one of them sees (``fit.fit_transport``), calibrated and shape
only, and the table prints true vs. fitted values with their relative errors.

The render pipeline refuses a medium behind a refracting (``dielectric``) boundary (light from a
pinhole projector cannot be connected through it), so the slab has an index-matched ``null``
boundary: the fit then uses a forward table traced for ``n = 1`` (``fit.forward_table(n=1.0)``,
traced once and cached).

    nice -n 19 python tools/validate_fit_mitsuba.py --spp 4096 --json out/validate_fit_mitsuba.json   # 4 min
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from planeray.materials import fit
from planeray.render import render_transport
from planeray.transport import Transport

G = 0.8
DIAG_OFFSETS = (0, 1, 2, 5, 10, 15, 20, 25, 30)
DISTANCE_MM = 200.0
MEDIA = {  # name: (mu_s' /mm, mu_a /mm)
    "A": (1.0, 0.05),
    "B": (1.0, 0.01),
    "C": (3.0, 0.03),
}

SCENE = """<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="{vfov}"/>
        <string name="fov_axis" value="y"/>
        <transform name="to_world"><lookat origin="0, 0, {d}" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="{w}"/><integer name="height" value="{h}"/></film>
    </sensor>
    <shape type="cube">
        <transform name="to_world"><scale x="250" y="250" z="50"/><translate z="-50"/></transform>
        {body}
    </shape>
</scene>
"""
MEDIUM = """<bsdf type="null"/>
        <medium type="homogeneous" name="interior">
            <float name="sigma_t" value="{sigma_t}"/><rgb name="albedo" value="{albedo}"/>
            <phase type="hg"><float name="g" value="{g}"/></phase>
        </medium>"""
WHITE = """<bsdf type="diffuse"><rgb name="reflectance" value="1.0"/></bsdf>"""


def render(body, *, rows, cols, mm_per_row, spp, seed, folder, name, rr_depth=500):
    vfov = 2.0 * math.degrees(math.atan(0.5 * rows * mm_per_row / DISTANCE_MM))
    path = Path(folder) / f"{name}.xml"
    path.write_text(SCENE.format(vfov=vfov, d=DISTANCE_MM, w=cols, h=rows, body=body))
    r = render_transport(
        path,
        shape=(rows, cols),
        projector_rows=rows,
        spp=spp,
        batch_spp=min(spp, 64),
        seed=seed,
        band_rows=rows,
        rr_depth=rr_depth,
        projector_aspect=16.0,  # long lit lines: +-190 mm either side of the view
    )
    return r.transport


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=96, help="camera = projector rows")
    ap.add_argument("--cols", type=int, default=4, help="camera columns")
    ap.add_argument("--mm-per-row", type=float, default=0.5)
    ap.add_argument("--spp", type=int, default=4096)
    ap.add_argument("--margin", type=int, default=32, help="camera rows left out at top and bottom")
    ap.add_argument("--media", default=",".join(MEDIA), help="names from " + ", ".join(MEDIA))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)

    table = fit.forward_table(n=1.0, n_photons=30_000)
    rows, cols, h = args.rows, args.cols, args.mm_per_row
    labels = np.zeros((rows, cols), np.int64)
    labels[args.margin : rows - args.margin] = 1
    out = {"params": {**vars(args), "json": str(args.json), "g": G, "n": 1.0, "boundary": "null"}, "media": {}}
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.time()
        white = render(WHITE, rows=rows, cols=cols, mm_per_row=h, spp=16, seed=1, folder=tmp, name="white")
        scale = fit.white_reference_scale(np.asarray(white.dense), albedo=1.0)
        print(f"white reference: {time.time() - t0:.0f} s, sum over rows {np.nanmedian(scale):.4f}")
        for name in args.media.split(","):
            s, a = MEDIA[name]
            mu_s = s / (1.0 - G)
            body = MEDIUM.format(sigma_t=mu_s + a, albedo=mu_s / (mu_s + a), g=G)
            t0 = time.time()
            T = render(body, rows=rows, cols=cols, mm_per_row=h, spp=args.spp, seed=2, folder=tmp, name=name)
            # the same window of offsets for every fitted pixel: a block mixing pixels whose lit rows end
            # at different offsets would average real light with the zeros beyond the projector
            keep = np.abs(T.offsets_rows) < args.margin
            T = Transport(np.asarray(T.dense)[..., keep], T.offsets_rows[keep], geometry=T.geometry)
            dt = time.time() - t0
            row = {"mu_s_prime_per_mm": s, "mu_a_per_mm": a, "render_s": dt}
            # the render against the forward model at the true parameters (calibrated, rows inside the margin)
            u = np.asarray(T.offsets_rows)
            prof = (np.asarray(T.dense, np.float64) / scale[..., None])[labels == 1].mean(axis=0)
            model = fit.forward_kernel(s, a, offsets_rows=u, mm_per_row=h, table=table)
            row["render_over_model"] = {
                int(k): float(prof[u == k][0] / model[u == k][0]) for k in DIAG_OFFSETS if np.any(u == k)
            }
            for kind, ws in (("calibrated", scale), ("shape_only", None)):
                res = fit.fit_transport(T, mm_per_row=h, labels=labels, white_scale=ws, block_px=4, table=table)
                reg = res.regions[1]
                fs, fa = reg["mu_s_prime_per_mm"], reg["mu_a_per_mm"]
                row[kind] = {
                    "mu_s_prime_per_mm": fs,
                    "mu_s_prime_se_per_mm": reg["mu_s_prime_se_per_mm"],
                    "mu_a_per_mm": fa,
                    "mu_a_se_per_mm": reg["mu_a_se_per_mm"],
                    "rel_err_mu_s_prime": (fs - s) / s,
                    "rel_err_mu_a": (fa - a) / a,
                }
            out["media"][name] = row
            print(f"{name}: rendered in {dt:.0f} s")
    print("\n| medium | true mu_s' / mu_a (1/mm) | fit | mu_s' (1/mm) | mu_a (1/mm) | err mu_s' | err mu_a |")
    print("|---|---|---|---|---|---|---|")
    for name, row in out["media"].items():
        for kind in ("calibrated", "shape_only"):
            f = row[kind]
            print(
                f"| {name} | {row['mu_s_prime_per_mm']:g} / {row['mu_a_per_mm']:g} | {kind} "
                f"| {f['mu_s_prime_per_mm']:.3f} +- {f['mu_s_prime_se_per_mm']:.3f} "
                f"| {f['mu_a_per_mm']:.4f} +- {f['mu_a_se_per_mm']:.4f} "
                f"| {100 * f['rel_err_mu_s_prime']:+.1f} % | {100 * f['rel_err_mu_a']:+.1f} % |"
            )
    print("\nrender / forward model at the true parameters (region mean, calibrated), by offset (rows):")
    print("| medium | " + " | ".join(f"u = {k}" for k in DIAG_OFFSETS) + " |")
    for name, row in out["media"].items():
        print(
            f"| {name} | "
            + " | ".join(f"{row['render_over_model'].get(k, float('nan')):.3f}" for k in DIAG_OFFSETS)
            + " |"
        )
    for kind in ("calibrated", "shape_only"):
        es = [abs(r[kind]["rel_err_mu_s_prime"]) for r in out["media"].values()]
        ea = [abs(r[kind]["rel_err_mu_a"]) for r in out["media"].values()]
        out[f"median_abs_rel_err_{kind}"] = {"mu_s_prime": float(np.median(es)), "mu_a": float(np.median(ea))}
        print(f"median |rel. error| {kind}: mu_s' {100 * np.median(es):.1f} %, mu_a {100 * np.median(ea):.1f} %")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
