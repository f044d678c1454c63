"""The live transport: a designed sweep's rolling window demultiplexed as the images arrive, against a cold demux.

The simulated Episcan (``--scene``, 128 x 128 of the paper's 720-row projector, ``--frames`` frames per
image) cycles a sweep (``--sweep FILE``, default: a 24-image design made here with the default prior
and camera) and :class:`planeray.live.LiveTransport` demultiplexes the newest image of every
setting, warm-started from the previous window.  Two measurements, in the same run:

1. **live** (``--seconds``): updates per second (host clock), the solve's wall time and iterations,
   the window's age, the process's CPU seconds per update (capture included);
2. **replay**: the windows the live run saw, in order, solved again in this process with nothing
   else running -- warm-started (``WindowSolver``, as live), each cold (the same solver without warm
   starts), and the last one by ``planeray.demux.demultiplex`` (the offline demux of the same 24
   images, the whole in-memory pipeline) -- CPU seconds per solve, their ratios, and the rate two
   free cores would give (``2 / CPU seconds``, the solver's two threads kept busy).  The simulated
   device's own rendering is timed apart (CPU seconds per image): a camera costs the host nothing.

The live transport is checked against the offline demux of the same window: every pixel of both is
certified to a relative objective gap <= tol, so their objectives agree to ~tol and their difference
in the Hessian's norm is at most ``sqrt(2 gap_live) + sqrt(2 gap_offline)``.  The machine's load
average is printed: the 2 cores are shared.

Run: ``.venv/bin/python benchmarks/bench_live_transport.py [--seconds 20 --scene wax --frames 8]``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from planeray.demux import demultiplex
from planeray.design import design_sweep
from planeray.devices import open_device
from planeray.io import read_sweep, write_sweep
from planeray.live import LiveCapture, LiveTransport, WindowSolver, window_stack


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} cores"


def q_norm_bound(problem, live_update, offline) -> tuple[float, float]:
    """The largest ``||x_live - x_off||_Q`` over pixels and its certified bound ``sqrt(2 g_live) + sqrt(2 g_off)``."""
    H, W = problem.shape
    worst_ratio, worst = 0.0, 0.0
    T_live = live_update.transport.dense.astype(np.float64)
    T_off = offline.transport.dense.astype(np.float64)
    f_off = offline.maps["objective"].astype(np.float64)
    for group in problem.groups:
        Q = 2.0 * group.hessian(problem.alpha)
        on = 1.0 if group.on_projector is None else group.on_projector
        d = (T_live[group.rows][:, :, group.valid] - T_off[group.rows][:, :, group.valid]) / on
        d = d.reshape(-1, d.shape[-1])
        qn = np.sqrt(np.maximum(np.einsum("pi,ij,pj->p", d, Q, d), 0.0))
        g_live = live_update.maps["gap"][group.rows].reshape(-1)
        g_off = 1e-4 * f_off[group.rows].reshape(-1)  # the offline solve certified a relative gap <= tol
        bound = np.sqrt(2 * g_live) + np.sqrt(2 * g_off)
        worst = max(worst, float(qn.max()))
        worst_ratio = max(worst_ratio, float(np.max(qn / np.maximum(bound, 1e-300))))
    return worst, worst_ratio


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sweep", type=Path, default=None, help="a sweep file (default: a 24-image design made here)")
    ap.add_argument("--scene", default="wax")
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--frames", type=int, default=8, help="frames per image (the design's camera: 8)")
    ap.add_argument("--seconds", type=float, default=20.0)
    args = ap.parse_args()
    print(_load())
    if args.sweep is None:
        t0 = time.process_time()
        design = design_sweep(24)
        sweep = design.sweep
        print(
            f"design of 24 images: {time.process_time() - t0:.1f} CPU s (expected relative error {design.expected_error:.3f})"
        )
        args.sweep = Path(tempfile.mkdtemp()) / "design24.json"
        write_sweep(sweep, args.sweep)
    sweep = read_sweep(args.sweep)
    dev = open_device("sim", scene=args.scene, size=(args.size, args.size), projector_rows=720,
                      frames_averaged=args.frames)  # fmt: skip
    lps, jitter = dev.lines_per_second, dev.camera.jitter_us
    # the simulated device's own cost per image (a camera's is the camera's)
    dev.set_timing(float(sweep.delay_us[0]), float(sweep.exposure_us[0]))
    c0 = time.process_time()
    for _ in range(8):
        dev.grab()
    capture_cpu = (time.process_time() - c0) / 8
    capture = LiveCapture(dev, history=4096, max_fps=dev.rig["frame_rate_hz"] / args.frames)
    live = LiveTransport(capture, sweep, lines_per_second=lps, projector_rows=720, jitter_us=jitter)
    windows = []
    with live:
        first = live.wait_update(timeout_s=300)
        windows.append(first.frames)
        c0, t0, n0 = time.process_time(), time.monotonic(), first.number
        seen, solve_s, iters, ages = first.number, [], [], []
        while time.monotonic() - t0 < args.seconds:
            u = live.wait_update(seen, timeout_s=60)
            seen = u.number
            windows.append(u.frames)
            solve_s.append(u.seconds)
            iters.append(float(u.maps["iterations"].mean()))
            ages.append(u.age_s(u.solved_at))
        dt, dc, n = time.monotonic() - t0, time.process_time() - c0, seen - n0
        last = live.latest
    print(f"\n[live: {args.scene} {args.size}x{args.size}, {len(sweep)} images, {args.frames} frames each, "
          f"{_load()}]")  # fmt: skip
    print(f"  updates                     : {n} in {dt:.1f} s -> **{n / dt:.2f} per second** (host clock)")
    print(f"  solve (wall)                : median {np.median(solve_s):.2f} s; iterations mean {np.mean(iters):.1f}")
    print(
        f"  age at update               : median {np.median(ages):.2f} s (newest image to transport); "
        f"window spans {last.window_span_s:.1f} s"
    )
    print(
        f"  process CPU per update      : {dc / max(n, 1):.2f} s (capture included: the device "
        f"{capture_cpu:.3f} CPU s per image)"
    )
    # ---- replay in the same process
    solver_w = WindowSolver(sweep, (args.size, args.size), lines_per_second=lps, projector_rows=720, jitter_us=jitter)
    solver_c = WindowSolver(sweep, (args.size, args.size), lines_per_second=lps, projector_rows=720, jitter_us=jitter)
    solver_w.solve(np.stack([f.image for f in windows[0]]))  # the first window: cold (and factorizations made)
    cpu_w, cpu_c, it_w, it_c = [], [], [], []
    for frames in windows[1:]:
        images = np.stack([f.image for f in frames])
        c0 = time.process_time()
        _, m = solver_w.solve(images)
        cpu_w.append(time.process_time() - c0)
        it_w.append(float(m["iterations"].mean()))
        c0 = time.process_time()
        _, m = solver_c.solve(images, warm=False)
        cpu_c.append(time.process_time() - c0)
        it_c.append(float(m["iterations"].mean()))
    stack = window_stack(last.frames, lines_per_second=lps, projector_rows=720, jitter_us=jitter)
    c0 = time.process_time()
    offline = demultiplex(stack)
    cpu_off = time.process_time() - c0
    w, c = float(np.median(cpu_w)), float(np.median(cpu_c))
    print(f"\n[replay of the {len(windows) - 1} windows, in process; {_load()}]")
    print(
        f"  warm-started (live)         : {w:.2f} CPU s per update, iterations {np.mean(it_w):.1f} -> "
        f"{1 / w:.1f} updates per second on one free core, **{2 / w:.1f} on 2 free cores**"
    )
    print(
        f"  cold, same solver           : {c:.2f} CPU s, iterations {np.mean(it_c):.1f} -> warm is **{c / w:.1f}x** less"
    )
    print(
        f"  offline demultiplex()       : {cpu_off:.2f} CPU s on the last window (iterations "
        f"{offline.maps['iterations'].mean():.1f})"
    )
    f_live = last.maps["objective"]
    f_off = offline.maps["objective"].astype(np.float64)
    rel = np.abs(f_live - f_off) / np.maximum(f_off, 1e-300)
    qn, ratio = q_norm_bound(solver_w.problem, last, offline)
    print(
        f"  live vs offline (last window): objectives differ by median {np.median(rel):.1e}, at most {rel.max():.1e} "
        f"(tol 1e-4 each); ||x_live - x_off||_Q at most {ratio:.2f} of its certified bound; certified "
        f"{last.maps['converged'].mean() * 100:.1f} % / {offline.maps['converged'].mean() * 100:.1f} %"
    )


if __name__ == "__main__":
    main()
