"""Skin scene: time to build it and to render (simulate) the paper's sweep, against the wax scene.

Builds the ``skin`` scene (shipped Monte Carlo tables: no tracing) and the ``wax`` scene
of the same size -- the baseline, measured in the same run -- at 128x128 and 256x256, then
renders the paper's 85-image sweep of each (Eq. 4, noise-free) and simulates a full
capture (render + 8-frame camera noise).  Prints seconds and the ratio skin / wax.

Run: ``.venv/bin/python benchmarks/bench_skin.py [--sizes 128 256]``.
"""

from __future__ import annotations

import argparse
import time

from planeray.acquire import simulate_stack
from planeray.scenes import make_scene
from planeray.timing import PAPER_LINES_PER_SECOND, paper_sweep


def _measure(name, size, params, sweep, bands):
    t0 = time.perf_counter()
    scene = make_scene(name, (size, size), projector_rows=720, seed=0, **params)
    t1 = time.perf_counter()
    for b in bands:
        scene.transport.render(b)
    t2 = time.perf_counter()
    simulate_stack(scene, sweep, seed=0)
    return t1 - t0, t2 - t1, time.perf_counter() - t2


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[128, 256])
    args = parser.parse_args()
    sweep = paper_sweep()
    bands = sweep.bands(PAPER_LINES_PER_SECOND, jitter_us=5.0)
    make_scene("skin", (16, 16), projector_rows=720)  # load the tables and compile once
    make_scene("wax", (16, 16), projector_rows=720)
    for size in args.sizes:
        res = {}
        for name, params in (("wax", {}), ("skin", {}), ("skin", {"hair": True, "curved": True})):
            label = name + ("+hair+curved" if params else "")
            res[label] = _measure(name, size, params, sweep, bands)
        base = res["wax"]
        print(f"{size}x{size}, 720 projector rows, paper sweep ({len(sweep)} images):")
        for label, (b, r, c) in res.items():
            print(
                f"  {label:18s} build {b:6.2f} s ({b / base[0]:5.1f}x wax)   render {r:6.2f} s ({r / base[1]:4.1f}x)"
                f"   capture {c:6.2f} s ({c / base[2]:4.1f}x)"
            )


if __name__ == "__main__":
    main()
