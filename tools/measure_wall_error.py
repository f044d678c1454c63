"""The walls' model error, measured against Mitsuba 3 (a forward model planeray did not write).

The materials fits take a container wall's effect on the kernel from diffusion theory's method of images
(:mod:`planeray.kernels.walls`) and carry its error in the data's covariance
(:func:`planeray.materials.fit.wall_error_columns`): the effect off by :data:`~planeray.materials.fit.WALL_EFFECT_SD` of
itself, the walls' distances off by a transport mean free path, and the effect's **shape** over the offsets off
by :data:`~planeray.materials.fit.WALL_SHAPE_SD` of itself in each smooth bump of the model-error basis.
This tool measures the last one on media that none of issue 41's validation cases holds.

For each calibration medium (fixed below before any was rendered; ``g`` 0.8, the table's, and index-matched
faces, ``n`` 1: Mitsuba's render pipeline refuses a refracting boundary) two scene files are rendered through
planeray's render pipeline (what ``planeray render`` runs): a tray whose side walls let the light go (nothing
behind them: a "black" wall, the kind of an index-matched container) and a wide slab of the same medium.  The
walls' true relative effect on the tray's mean kernel is ``E = K_tray / K_slab - 1`` (Mitsuba against Mitsuba:
the renderer's differences from planeray's table cancel), the model's is the fit's own ``model_kernel`` with the
tray's walls against without.  The shape error's standard deviation is the maximum-likelihood one given the
Mitsuba noise (two interleaved halves of each render's pixels; its scale a nuisance, profiled out) and the other
wall-error terms the fit already carries.

    nice -n 19 python tools/measure_wall_error.py render     # ~1 h on 2 cores (the slabs: 3-18 min each), cached
    python tools/measure_wall_error.py measure [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import honest_cases as hc

ROOT = Path("/work/cache-honest-fits/wall-error")

#: Calibration media (mu_s' and mu_a in 1/mm): two decades of mu_s' where walls matter in a tray, and weak and
#: strong absorption each; none is a validation case's medium.  Fixed before the first render.
MEDIA = [
    dict(id="W1", mu_s_prime=0.4, mu_a=0.001),
    dict(id="W2", mu_s_prime=0.4, mu_a=0.012),
    dict(id="W3", mu_s_prime=1.5, mu_a=0.003),
    dict(id="W4", mu_s_prime=1.5, mu_a=0.04),
    dict(id="W5", mu_s_prime=4.0, mu_a=0.008),
    dict(id="W6", mu_s_prime=4.0, mu_a=0.1),
]
G = 0.8
#: The tray (mm, image down x across) and its depth; the capture's geometry: rows of h mm, camera H x W.
TRAY_MM = (30.0, 24.0)
DEPTH_MM = 100.0
H_MM = 0.3
#: 256 projector rows (76.8 mm) around a 100-row tray: every offset within 77 rows lights every tray pixel.
P, H, W = 256, 64, 64
TRAY_SPP = 2048
SLAB_W, SLAB_SPP = 4, 8192


def _medium(c) -> str:
    return hc._hg_medium("m", c["mu_s_prime"] / (1.0 - G), c["mu_a"], G)


def tray_body(c) -> str:
    """The tray: the medium in a box of null faces, nothing behind them (light that leaves is lost)."""
    down, across = TRAY_MM[0] / 2, TRAY_MM[1] / 2
    return (
        _medium(c) + f"""
    <shape type="cube"><transform name="to_world"><scale x="{across}" y="{down}" z="{DEPTH_MM / 2}"/>"""
        f"""<translate z="{-DEPTH_MM / 2}"/></transform><bsdf type="null"/><ref name="interior" id="m"/></shape>"""
    )


def slab_body(c) -> str:
    """The same medium, 500 mm wide and as deep: no wall within reach."""
    return (
        _medium(c) + f"""
    <shape type="cube"><transform name="to_world"><scale x="250" y="250" z="{DEPTH_MM / 2}"/>"""
        f"""<translate z="{-DEPTH_MM / 2}"/></transform><bsdf type="null"/><ref name="interior" id="m"/></shape>"""
    )


def render(ids=None) -> None:
    for c in MEDIA:
        if ids and c["id"] not in ids:
            continue
        folder = ROOT / c["id"]
        folder.mkdir(parents=True, exist_ok=True)
        t0 = time.time()
        hc._render(tray_body(c), folder, "tray", H=H, W=W, P=P, h=H_MM, spp=TRAY_SPP, seed=101)
        hc._render(slab_body(c), folder, "slab", H=H, W=SLAB_W, P=P, h=H_MM, spp=SLAB_SPP, seed=102)
        print(f"{c['id']}: {time.time() - t0:.0f} s", flush=True)


def _read(path):
    from planeray.io import read_transport

    tr, _ = read_transport(path)
    return np.asarray(tr.dense, np.float64), np.asarray(tr.offsets_rows)


def _smooth(v, width=9):
    """A running mean over the offsets (a noise variance estimated from one difference per offset is noisy)."""
    k = np.ones(width) / width
    return np.convolve(np.pad(v, width // 2, mode="edge"), k, mode="valid")


def _valid_offsets(rows_px, offsets, rpc):
    """Offsets that light every pixel of the rows ``rows_px`` from a projector row on the projector."""
    from planeray.timing import RowGeometry

    first = RowGeometry(H, P).projector_row_of(np.asarray(rows_px))
    t_lo = first.min() - offsets  # the projector row of the topmost pixel
    t_hi = first.max() + rpc - offsets
    return (t_lo >= 0) & (t_hi <= P - 1)


def medium_terms(c):
    """The tray's data error ``d(u)`` against the model, its noise variance and the covariance's columns.

    All over the offsets that light every tray pixel, in the renders' units, means over the tray's pixels:
    ``d = T_tray - T_slab (1 + E_model)`` per pixel, ``E_model`` the fit's relative wall effect
    (:func:`planeray.kernels.forward.model_kernel` with the pixel's four walls against none) at the truth.
    """
    from planeray.kernels.footprint import camera_row_footprint
    from planeray.kernels.forward import forward_table, model_kernel
    from planeray.materials.fit import WALL_EFFECT_SD, group_walls, model_error_basis

    folder = ROOT / c["id"]
    Tt, offsets = _read(folder / "tray.zarr")
    Ts, off_s = _read(folder / "slab.zarr")
    assert np.array_equal(offsets, off_s)
    rpc = P / H
    foot = camera_row_footprint(rpc)
    x, y = hc._pixel_centres_mm(H, W, P, H_MM)
    inside = (np.abs(x)[:, None] < TRAY_MM[0] / 2) & (np.abs(y)[None, :] < TRAY_MM[1] / 2)
    rows, cols = np.nonzero(inside)
    keep = _valid_offsets(rows, offsets, rpc)
    u = offsets[keep]
    slab_rows = Ts[:, :, keep]  # (H, SLAB_W, U)
    table = forward_table(n=1.0)
    ls, la = math.log(c["mu_s_prime"] * H_MM), math.log(c["mu_a"] * H_MM)
    free = model_kernel(table, ls, la, u, foot, None, "black")
    mfp_rows = 1.0 / (c["mu_s_prime"] * H_MM)
    foot_rows = float(np.ptp(foot[0]) + 1)  # as the fit's wall_error_columns
    shift = math.hypot(mfp_rows, 0.5 * foot_rows)
    E, E_hi, E_lo = (np.zeros((rows.size, u.size)) for _ in range(3))
    for i, (r, q) in enumerate(zip(rows, cols)):
        dist = np.array([(TRAY_MM[0] / 2 - x[r]) / H_MM, (x[r] + TRAY_MM[0] / 2) / H_MM,
                         (TRAY_MM[1] / 2 - y[q]) / H_MM, (y[q] + TRAY_MM[1] / 2) / H_MM])  # fmt: skip
        for out, dd in ((E, dist), (E_hi, dist + shift), (E_lo, np.maximum(dist - shift, 0.0))):
            out[i] = model_kernel(table, ls, la, u, foot, group_walls(dd[None]), "black") / free - 1.0
    S = slab_rows.mean(axis=1)[rows]  # (n, U): each tray pixel's row of the slab (its 4 columns' mean)
    tray = Tt[rows, cols][:, keep]
    per_px = tray - S * (1.0 + E)
    d = per_px.mean(axis=0)
    checker = (rows + cols) % 2 == 0
    var_tray = _smooth((per_px[checker].mean(axis=0) - per_px[~checker].mean(axis=0)) ** 2 / 4.0)
    sa = slab_rows[:, :2].mean(axis=1)[rows]
    sb = slab_rows[:, 2:].mean(axis=1)[rows]
    var_slab = _smooth((((sa - sb) * (1.0 + E)).mean(axis=0)) ** 2 / 4.0)
    Wm = (S * E).mean(axis=0)  # the model's wall effect on the tray's mean kernel
    cols_fixed = np.stack([WALL_EFFECT_SD * Wm, 0.5 * (S * (E_hi - E_lo)).mean(axis=0)], axis=1)
    shape_cols = Wm[:, None] * model_error_basis(u)
    return dict(u=u, d=d, var=var_tray + var_slab, fixed=cols_fixed, shape=shape_cols, W=Wm,
                slab=S.mean(axis=0), tray=tray.mean(axis=0))  # fmt: skip


#: The renders' noise variance (from one split per offset, smoothed) is known to a factor: a nuisance scale on it,
#: profiled out of the likelihood (so that noise the split misses is not read as the walls' shape error).
NOISE_SCALES = np.round(np.arange(0.8, 3.01, 0.1), 2)


def _loglik(t, sd, noise_scale=1.0):
    """Gaussian log-likelihood of ``d`` and its reduced chi-square at shape error ``sd`` and noise scale."""
    cov = noise_scale**2 * np.diag(t["var"]) + t["fixed"] @ t["fixed"].T + sd**2 * (t["shape"] @ t["shape"].T)
    sign, logdet = np.linalg.slogdet(cov)
    alpha = np.linalg.solve(cov, t["d"])
    return -0.5 * (logdet + float(t["d"] @ alpha)), float(t["d"] @ alpha) / t["d"].size


def _profile(t, sd):
    """The log-likelihood at ``sd``, the noise scale profiled out: ``(loglik, reduced chi2, noise scale)``."""
    best = max(((*_loglik(t, sd, k), k) for k in NOISE_SCALES), key=lambda v: v[0])
    return best


def measure(json_out=None):
    """The maximum-likelihood share of the wall effect's shape error, per medium and over all of them."""
    grid = np.round(np.arange(0.0, 1.0001, 0.01), 4)
    total = np.zeros(grid.size)
    rows = []
    for c in MEDIA:
        if not (ROOT / c["id"] / "slab.zarr").exists():
            print(f"{c['id']}: not rendered", flush=True)
            continue
        t = medium_terms(c)
        prof = [_profile(t, sd) for sd in grid]
        ll = np.array([p[0] for p in prof])
        total += ll
        chi0 = _loglik(t, 0.0)[1]
        i_best = int(np.argmax(ll))
        best = float(grid[i_best])
        wall_share = float(np.abs(t["W"]).sum() / np.abs(t["slab"]).sum())
        rows.append(dict(id=c["id"], mu_s_prime=c["mu_s_prime"], mu_a=c["mu_a"], wall_share=wall_share,
                         reduced_chi2_without_shape=chi0, ml_shape_sd=best, noise_scale=prof[i_best][2],
                         reduced_chi2_at_ml=prof[i_best][1],
                         total_effect_ratio=float(t["tray"].sum() - t["slab"].sum()) / float(t["W"].sum())))  # fmt: skip
        print(f"{c['id']}: mu_s' {c['mu_s_prime']} mu_a {c['mu_a']}: walls take {wall_share:.1%} of the kernel; "
              f"true/model total wall effect {rows[-1]['total_effect_ratio']:.2f}; reduced chi2 without a shape "
              f"error {chi0:.2f}; ML shape sd {best:.2f} (noise scale {prof[i_best][2]:.1f}, reduced chi2 "
              f"{prof[i_best][1]:.2f})", flush=True)  # fmt: skip
    i = int(np.argmax(total))
    inside = grid[total >= total[i] - 1.92]  # the likelihood-ratio 95 % interval
    summary = dict(ml_shape_sd=float(grid[i]), interval_95=[float(inside.min()), float(inside.max())], media=rows)
    print(f"all media: ML shape sd {grid[i]:.2f} (95 % interval {inside.min():.2f}-{inside.max():.2f})")
    if json_out:
        Path(json_out).write_text(json.dumps(summary, indent=1) + "\n")
    print(markdown(summary))
    return summary


def markdown(summary) -> str:
    """The measurement as the docs' table (indented for a list item)."""
    lines = [
        "| medium | `mu_s'` /mm | `mu_a` /mm | walls' share of the kernel | true / model wall effect (sum) "
        "| reduced chi-square, no shape error | shape share (ML) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in summary["media"]:
        lines.append(
            f"| {r['id']} | {r['mu_s_prime']:g} | {r['mu_a']:g} | {r['wall_share']:.0%} | "
            f"{r['total_effect_ratio']:.2f} | {r['reduced_chi2_without_shape']:.1f} | {r['ml_shape_sd']:.2f} |"
        )
    lo, hi = summary["interval_95"]
    lines.append(f"| all six | | | | | | **{summary['ml_shape_sd']:.2f}** (95 %: {lo:.2f}-{hi:.2f}) |")
    return "\n".join("  " + line for line in lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render")
    r.add_argument("--only", nargs="*")
    m = sub.add_parser("measure")
    m.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    if args.cmd == "render":
        render(args.only)
    else:
        measure(json_out=args.json)


if __name__ == "__main__":
    main()
