"""Mitsuba scene -> transport: the one-pass tally against one Mitsuba render per projector row.

Both run in the same process on the same scene and variant (``llvm_ad_mono`` where
its LLVM runtime loads), after a warm-up that compiles their kernels:

1. **per-row** (:func:`planeray.render.reference.render_rows`): Mitsuba's
   ``path``/``volpath`` with a one-row projector bitmap, timed on a subset of
   rows and extrapolated to all ``--rows`` (its cost is linear in the rows);
2. **one pass** (:func:`planeray.render.render_transport`): every row at once, with
   the same ``--spp`` (so the same noise per row);
3. the full-size render: ``--rows`` rows x ``--large`` pixels at ``--large-spp``.

Run: ``.venv/bin/python benchmarks/bench_render_mitsuba.py [--scene mirror_ball --size 64 --rows 720 --spp 64]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from planeray.render import example_scene, render_transport
from planeray.render._mitsuba import choose_variant


def _parts(path, rows):
    import mitsuba as mi

    from planeray.render.rig import Rig
    from planeray.render.scene_file import load_scene_file

    mi.set_log_level(mi.LogLevel.Error)
    loaded = load_scene_file(path)
    rig = Rig.from_sensor(
        loaded.sensor, baseline=float(loaded.defaults.get("planeray_baseline", 40)), projector_rows=rows
    )
    return loaded, rig


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="mirror_ball")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--rows", type=int, default=720)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--subset", type=int, default=12, help="Rows rendered one by one (extrapolated to --rows).")
    parser.add_argument("--large", type=int, default=128)
    parser.add_argument("--large-spp", type=int, nargs="+", default=[64, 512])
    args = parser.parse_args()
    from planeray.render.reference import render_rows

    variant = choose_variant()
    path = example_scene(args.scene)
    shape = (args.size, args.size)
    loaded, rig = _parts(path, args.rows)
    rows = np.linspace(args.rows // 4, 3 * args.rows // 4, args.subset).astype(int)
    print(f"scene {args.scene}, {args.size}x{args.size} pixels, {args.rows} projector rows, {args.spp} spp, {variant}")

    # warm-up: compile both kernels
    render_rows(loaded, rig, shape, rows[:1], spp=args.spp)
    render_transport(path, shape=shape, projector_rows=args.rows, spp=args.spp, caustics=False)

    t = time.perf_counter()
    render_rows(loaded, rig, shape, rows, spp=args.spp)
    per_row = (time.perf_counter() - t) / len(rows)
    all_rows = per_row * args.rows
    print(f"per-row rendering: {per_row:.3f} s/row on {len(rows)} rows -> {all_rows:.1f} s for {args.rows} rows")

    t = time.perf_counter()
    render_transport(path, shape=shape, projector_rows=args.rows, spp=args.spp, caustics=False)
    one = time.perf_counter() - t
    print(f"one pass:          {one:.2f} s for all {args.rows} rows -> {all_rows / one:.0f}x faster")

    for spp in args.large_spp:
        t = time.perf_counter()
        r = render_transport(path, shape=(args.large, args.large), projector_rows=args.rows, spp=spp, caustics=False)
        dt = time.perf_counter() - t
        print(
            f"{args.rows} rows x {args.large}x{args.large} at {spp} spp: {dt:.1f} s "
            f"({len(r.transport.sparse)} sparse entries; per-row extrapolated: "
            f"{per_row * args.rows * (args.large / args.size) ** 2 * spp / args.spp:.0f} s)"
        )
    t = time.perf_counter()
    render_transport(
        example_scene("disco_ball"), shape=(args.large, args.large), projector_rows=args.rows, spp=64, caustics=True
    )
    print(f"disco_ball with the caustic pass, {args.large}x{args.large}, 64 spp: {time.perf_counter() - t:.1f} s")


if __name__ == "__main__":
    main()
