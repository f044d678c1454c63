"""Demultiplexing speed and exactness: planeray's fast solver vs CVXPY on the same pixels.

Simulates the paper's 85-image sweep (N = 75 used, 229 offsets) of a built-in
scene at 128x128 camera rows of a 720-row projector, then

1. solves a random subset of pixels with CVXPY + Clarabel -- its fastest honest
   use: the problem compiled once per row group with the observations as a
   ``cp.Parameter`` -- and with planeray's ``fast`` solver, and prints ms/pixel,
   the ratio and the relative objective gap to CVXPY's optimum;
2. times the full 128x128 image with ``fast`` (and the paper's 9 minutes);
3. optionally (``--large 512``) times a 512x512 stack through the chunked,
   store-writing driver and reports peak memory.

Run: ``make bench-demux`` or ``.venv/bin/python benchmarks/bench_demux.py [--scene wax] [--pixels 300]``.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from planeray.acquire import simulate_stack
from planeray.demux import DemuxProblem, demultiplex, demultiplex_to_store, solve_cvxpy, solve_fast
from planeray.demux.driver import read_observations
from planeray.scenes import make_scene
from planeray.timing import PAPER_PROJECTOR_ROWS, paper_sweep

PAPER_SECONDS_128 = 9 * 60  # "it takes 9 minutes to demultiplex these images for 128x128" (Sec. 6)


def compare_with_cvxpy(stack, n_pixels, rng):
    """Solve whole camera rows with both solvers (as a full-image run would).

    Whole rows amortize CVXPY's per-row compilation exactly as in a full image,
    and planeray's time includes its per-row factorization.
    """
    problem = DemuxProblem.from_stack(stack)
    H, W = stack.shape
    interior = np.flatnonzero(problem.row_group == np.bincount(problem.row_group).argmax())
    edge = np.setdiff1d(np.arange(H), interior)
    n_rows = max(1, int(round(n_pixels / W)))
    # the same mix of interior and edge rows as the image
    n_edge = int(round(n_rows * edge.size / H))
    rows = np.concatenate(
        [rng.choice(interior, n_rows - n_edge, replace=False), rng.choice(edge, n_edge, replace=False)]
    )
    t_cvx = t_fast = 0.0
    gaps = []
    for r in rows:
        obs, _ = read_observations(stack, problem, slice(int(r), int(r) + 1))
        group = problem.groups[problem.row_group[r]]
        B = obs[:, 0, :].T
        t0 = time.perf_counter()
        ref = solve_cvxpy(group, B, problem.alpha, problem.beta)
        t_cvx += time.perf_counter() - t0
        group.__dict__.pop("_admm_cache", None)  # include the factorization in planeray's time
        t0 = time.perf_counter()
        fast = solve_fast(group, B, problem.alpha, problem.beta)
        t_fast += time.perf_counter() - t0
        f_ref = problem.objective(group, ref.X, B)
        f_fast = problem.objective(group, fast.X, B)
        gaps.append((f_fast - f_ref) / f_ref)
    return len(rows) * W, t_cvx, t_fast, np.concatenate(gaps)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="wax")
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--pixels", type=int, default=300, help="pixels solved by both CVXPY and planeray")
    parser.add_argument("--large", type=int, default=0, help="also time a LARGE x LARGE stack through the store driver")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)

    scene = make_scene(args.scene, (args.size, args.size), projector_rows=PAPER_PROJECTOR_ROWS, seed=args.seed)
    stack = simulate_stack(scene, paper_sweep(), seed=args.seed)
    problem = DemuxProblem.from_stack(stack)
    print(
        f"scene {args.scene} {args.size}x{args.size} ({PAPER_PROJECTOR_ROWS} projector rows), N = {problem.n_images} images, "
        f"U = {problem.n_offsets} offsets, {len(problem.groups)} distinct row matrices"
    )

    n, t_cvx, t_fast, gaps = compare_with_cvxpy(stack, args.pixels, rng)
    print(f"\n[same {n} pixels: {n // args.size} whole camera rows]")
    print(f"  CVXPY + Clarabel (compiled once per row) : {t_cvx / n * 1e3:8.3f} ms/pixel")
    print(f"  planeray fast                            : {t_fast / n * 1e3:8.3f} ms/pixel")
    print(f"  speed-up                                 : {t_cvx / t_fast:8.1f}x")
    print(
        f"  relative objective gap to CVXPY          : median {np.median(gaps):.2e}, worst {gaps.max():.2e}"
        f"  (negative: planeray lower)"
    )

    demultiplex(stack)  # warm-up (imports, caches)
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        res = demultiplex(stack)
        times.append(time.perf_counter() - t0)
    best = min(times)
    cvx_full = t_cvx / n * args.size * args.size
    print(f"\n[full {args.size}x{args.size} image, fast, best of 3]")
    print(f"  time                 : {best:.2f} s   (runs: {', '.join(f'{t:.2f}' for t in times)})")
    print(f"  CVXPY extrapolated   : {cvx_full:.0f} s  -> ratio {cvx_full / best:.0f}x")
    print(f"  paper (9 min @128^2) : ratio {PAPER_SECONDS_128 * (args.size / 128) ** 2 / best:.0f}x")
    print(
        f"  converged            : {res.maps['converged'].mean() * 100:.2f} %, iterations mean "
        f"{res.maps['iterations'].mean():.0f}, max {res.maps['iterations'].max()}"
    )

    if args.large:
        big = make_scene(args.scene, (args.large, args.large), projector_rows=PAPER_PROJECTOR_ROWS, seed=args.seed)
        big_stack = simulate_stack(big, paper_sweep(), seed=args.seed)
        del big
        with tempfile.TemporaryDirectory() as tmp:
            from planeray.io import write_stack

            path = write_stack(big_stack, Path(tmp) / "big.zarr")
            del big_stack
            # a fresh process, so its peak memory is the demultiplexing's alone
            run = subprocess.run(
                [sys.executable, __file__, "--demux-store", str(path), str(Path(tmp) / "T.zarr")],
                capture_output=True,
                text=True,
                check=True,
            )
            dt, peak = (float(x) for x in run.stdout.split())
        print(
            f"\n[{args.large}x{args.large} stack read lazily from a Zarr store, chunks of 16 rows, written to a transport store]"
        )
        print(
            f"  time: {dt:.1f} s   peak resident memory of that process: {peak:.0f} MiB "
            f"(stack {85 * args.large**2 * 4 / 2**20:.0f} MiB, transport {args.large**2 * 229 * 4 / 2**20:.0f} MiB on disk)"
        )


def _demux_store(stack_path, out_path):
    from planeray.io import read_stack

    t0 = time.perf_counter()
    demultiplex_to_store(read_stack(stack_path), out_path)
    dt = time.perf_counter() - t0
    print(dt, _peak_rss_mib())


def _peak_rss_mib() -> float:
    """Peak resident memory of this process (VmHWM; ru_maxrss survives exec on Linux)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--demux-store":
        _demux_store(sys.argv[2], sys.argv[3])
    else:
        main()
