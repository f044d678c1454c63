"""Monte Carlo speed: planeray's engine vs Mitsuba 3 on the same profile, at equal error.

Both estimate the normal-view radiance next to a lit strip one bin wide on an
index-matched HG half-space (what :mod:`planeray.mc.mitsuba_ref` renders).  Run
time alone is not comparable (different estimators), so the figure of merit is
the *efficiency* ``1 / (seconds * relative variance)`` of the profile, with the
relative variance taken as the mean of ``(stderr / value)^2`` over the bins
within 5 transport mean free paths of the line; the ratio of efficiencies is the
speed-up at equal error.  Also prints photon and collision rates for media from
the paper's study (Sec. 5.2: sigma_s = 1, sigma_a = 0, g = 0.9) -- with and without the
hybrid diffusion hand-off, the baseline of that ratio -- and the wax scene.

Run: ``make bench-mc`` or ``.venv/bin/python benchmarks/bench_mc.py [--photons 1000000]
[--plot mc_vs_mitsuba.png]``.
"""

from __future__ import annotations

import argparse
import time

import numba
import numpy as np

from planeray.mc import mc_line_profile
from planeray.medium import Medium


def rates(n_photons):
    print(f"planeray MC, {n_photons:.0e} photons, {numba.get_num_threads()} threads")
    print(f"{'medium':44s} {'s':>7s} {'photons/s':>10s} {'coll/photon':>11s} {'ns/coll/thread':>14s}")
    study = Medium(sigma_s=1.0, sigma_a=0.0, g=0.9)
    media = [
        ("study default: 1 / 0 / g 0.9, n 1, +-114 mm", study, dict(offsets_rows=np.arange(-114, 115))),
        (
            "  same, full tracing (no diffusion hand-off)",
            study,
            dict(offsets_rows=np.arange(-114, 115), diffusion_depth_mfp=None),
        ),
        ("absorbing: 1 / 0.1 / g 0.9, n 1", Medium(sigma_s=1.0, sigma_a=0.1, g=0.9), {}),
        (
            "wax: 1.5 / 0.003 / g 0.8, n 1.4, 0.3 mm",
            Medium(sigma_s=1.5, sigma_a=0.003, g=0.8, n=1.4),
            dict(offsets_rows=np.arange(-192, 193), mm_per_row=0.3),
        ),
    ]
    mc_line_profile(Medium(sigma_s=1.0, sigma_a=0.1, g=0.5), n_photons=1000)  # compile (or load the compiled cache)
    times = []
    for name, medium, kw in media:
        t0 = time.perf_counter()
        p = mc_line_profile(medium, n_photons=n_photons, **kw)
        dt = time.perf_counter() - t0
        times.append(dt)
        per = p.n_interactions / p.n_photons
        print(
            f"{name:44s} {dt:7.2f} {p.n_photons / dt:10.3g} {per:11.0f} "
            f"{dt * numba.get_num_threads() / p.n_interactions * 1e9:14.1f}"
        )
    print(f"hybrid hand-off vs full tracing on the study default: {times[1] / times[0]:.1f}x faster")


def efficiency(seconds, value, stderr, mask):
    rel_var = np.mean((stderr[mask] / value[mask]) ** 2)
    return 1.0 / (seconds * rel_var), np.sqrt(rel_var)


def plot_versus(off, dx, mi, mc, path):
    """Both radiance profiles with error bars, and their z-scores."""
    from planeray.figures._common import new_figure, save_png

    x = off * dx
    fig = new_figure((11, 4))
    ax, ax2 = fig.subplots(1, 2)
    ax.errorbar(x, mi.radiance, yerr=mi.stderr, fmt="o", ms=3, lw=0.8, label="Mitsuba 3 volpath")
    ax.errorbar(x, mc.radiance, yerr=mc.radiance_stderr, fmt=".", ms=3, lw=0.8, label="planeray MC")
    ax.set_yscale("log")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("normal-view radiance (mm^-1 sr^-1)")
    ax.set_title("HG half-space: sigma_s 1, sigma_a 0.05 /mm, g 0.5; 1 mm strip", fontsize=10)
    ax.legend(fontsize=8)
    z = (mc.radiance - mi.radiance) / np.hypot(mc.radiance_stderr, mi.stderr)
    ax2.bar(x, z, width=0.8 * dx)
    for v in (-3, 3):
        ax2.axhline(v, color="k", lw=0.5, ls="--")
    ax2.set_xlabel("x (mm)")
    ax2.set_ylabel("z = (planeray - Mitsuba) / error")
    ax2.set_title(f"max |z| {np.abs(z).max():.2f}, mean z^2 {np.mean(z**2):.2f}", fontsize=10)
    fig.tight_layout()
    return save_png(fig, path)


def versus_mitsuba(n_photons, spp, plot=None):
    try:
        from planeray.mc.mitsuba_ref import mitsuba_line_profile
    except ImportError:
        print("\nMitsuba 3 not installed (pip install 'planeray[mitsuba]'): skipping the comparison")
        return
    medium, dx = Medium(sigma_s=1.0, sigma_a=0.05, g=0.5, n=1.0), 1.0
    sigma_s, sigma_a, g = medium.sigma_s, medium.sigma_a, medium.g
    off = np.arange(-10, 11)
    mfp = medium.transport_mfp_mm
    mask = np.abs(off) * dx <= 5 * mfp
    mitsuba_line_profile(medium, off, mm_per_row=dx, spp=1, along_pixels=16)  # load variant, warm up
    t0 = time.perf_counter()
    mi = mitsuba_line_profile(medium, off, mm_per_row=dx, spp=spp, along_pixels=1024)
    t_mi = time.perf_counter() - t0
    t0 = time.perf_counter()
    mc = mc_line_profile(medium, n_photons=n_photons, offsets_rows=off, mm_per_row=dx, source_width_mm=dx)
    t_mc = time.perf_counter() - t0
    e_mi, r_mi = efficiency(t_mi, mi.radiance, mi.stderr, mask)
    e_mc, r_mc = efficiency(t_mc, mc.radiance, mc.radiance_stderr, mask)
    z = (mc.radiance - mi.radiance) / np.hypot(mc.radiance_stderr, mi.stderr)
    print(
        f"\nsame profile (sigma_s {sigma_s}, sigma_a {sigma_a}, g {g}, {off.size} bins of {dx} mm, "
        f"bins within 5 mfp: {mask.sum()})"
    )
    print(f"  Mitsuba volpath : {t_mi:6.2f} s, {spp} spp x 1024 rows, rms rel. error {r_mi:.4f}")
    print(f"  planeray MC     : {t_mc:6.2f} s, {n_photons:.0e} photons, rms rel. error {r_mc:.4f}")
    print(f"  agreement: max |z| {np.abs(z).max():.2f}, integrated ratio {mc.radiance.sum() / mi.radiance.sum():.4f}")
    print(f"  efficiency ratio (planeray / Mitsuba, time at equal error): {e_mc / e_mi:.1f}x")
    if plot:
        print(f"  {plot_versus(off, dx, mi, mc, plot)}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photons", type=int, default=1_000_000)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--plot", help="write a PNG of the Mitsuba comparison here")
    ap.add_argument("--skip-rates", action="store_true", help="only the Mitsuba comparison")
    args = ap.parse_args()
    if not args.skip_rates:
        rates(args.photons)
    versus_mitsuba(args.photons, args.spp, args.plot)


if __name__ == "__main__":
    main()
