"""Sweep-rendering throughput (Eq. 4) at 512x512: prefix sums vs. the dense baseline.

Renders the paper's 85-image sweep of a 512x512 scene with a 257-offset dense
band, once with planeray's O(pixels) band renderer (prefix sums over offsets)
and once with the obvious dense weighted sum over offsets (``np.matmul``, BLAS)
on the same transport, checks they agree, and prints images per second and the
ratio.  Also times a full simulated capture (render + 8-frame camera noise).

Run: ``make bench`` or ``.venv/bin/python benchmarks/bench_render.py [--size 512]``.
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

from planeray.acquire import acquire_sweep
from planeray.camera import CameraModel
from planeray.devices import SimulatedEpiscan
from planeray.scenes import make_scene
from planeray.timing import PAPER_LINES_PER_SECOND, paper_sweep


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--scene", default="wax")
    args = parser.parse_args()

    t0 = time.perf_counter()
    scene = make_scene(args.scene, (args.size, args.size), seed=0)
    T = scene.transport
    build_s = time.perf_counter() - t0
    bands = paper_sweep().bands(PAPER_LINES_PER_SECOND, jitter_us=5.0)
    print(
        f"scene {args.scene} {args.size}x{args.size}, {T.offsets_rows.size} offsets, "
        f"{len(T.sparse)} sparse entries, T = {T.dense.nbytes / 2**20:.0f} MiB (built in {build_s:.1f} s)"
    )

    T.render(bands[0])  # build the prefix-sum cache once (reported separately)
    t0 = time.perf_counter()
    T.invalidate_cache()
    T.render(bands[0])
    cache_s = time.perf_counter() - t0

    t0 = time.perf_counter()
    _ = [T.render(b) for b in bands]
    fast_s = time.perf_counter() - t0

    t0 = time.perf_counter()
    dense = []
    for b in bands:
        w = T.illumination_weights(b).astype(np.float32)
        dense.append(np.matmul(T.dense, w[:, :, None])[..., 0])
    dense_s = time.perf_counter() - t0
    # the baseline has no sparse part: compare on the dense band only
    fast_dense = [T.render_weights(T.illumination_weights(b)) for b in bands[:5]]
    err = max(float(np.abs(a - b).max()) for a, b in zip(fast_dense, dense[:5]))

    n = len(bands)
    print(f"prefix-sum cache build: {cache_s:.2f} s (once per transport)")
    print(f"planeray band renderer : {n} images in {fast_s:.3f} s = {n / fast_s:7.1f} images/s")
    print(f"dense matmul baseline  : {n} images in {dense_s:.3f} s = {n / dense_s:7.1f} images/s")
    print(f"speed-up vs baseline   : {dense_s / fast_s:.1f}x   (max |difference| {err:.2e})")

    device = SimulatedEpiscan(scene, CameraModel(), seed=0)
    t0 = time.perf_counter()
    acquire_sweep(device, paper_sweep())
    cap_s = time.perf_counter() - t0
    print(
        f"full simulated capture (render + 8-frame Poisson/read noise + ADC): {n} images in {cap_s:.2f} s = {n / cap_s:.1f} images/s"
    )
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak resident memory: {peak:.0f} MiB")


if __name__ == "__main__":
    main()
