"""Demultiplexing speed and exactness: the whole ``planeray demux`` command vs CVXPY on the same pixels.

Four stacks of the paper's 85-image sweep (N = 75 used, 229 offsets), 720-row projector:

1. **random transports, no ambient light** (128x128): every pixel a direct spike, an
   asymmetric subsurface kernel and, for 30 % of them, a displaced specular bump; light
   read noise (2 e-); written in the import format (16-bit TIFFs + manifest) and read
   back with ``planeray import``, as a new user would;
2. **the wax scene** (128x128, the simulator's default camera);
3. the random stack **10 % saturated** (a brighter laser; saturated observations are
   dropped from their pixel's fit);
4. **512x512** wax, read lazily from Zarr, chunks of 16 rows (``--large 512``).

Each is demultiplexed by the ``planeray demux`` command in a fresh process (best of
``--repeat``; the command's own solve time and the process's wall time and peak memory).
CVXPY + Clarabel -- compiled once per row matrix with ``b`` as a ``cp.Parameter``, its
fastest honest use -- solves whole camera rows sampled from the same stack (``--pixels``,
the image's mix of interior and edge rows) and is extrapolated to the image; the
relative objective gap of the command's output to CVXPY's optimum is reported on those
pixels (for saturated pixels: the objective over the remaining observations).  The
saturated stack is also solved in this process with its mask used and ignored
(interleaved, best of ``--repeat``): what dropping the saturated observations costs.

**Automatic weights** (``--alpha auto --beta auto``, cross-validation over the images,
the ambient light estimated per pixel by default): the same command with and without them
on the wax and random stacks, alternated, best of ``--repeat`` each; reported as the ratio
of the solve times (the printed time includes the choice), also for the automatic run on
the paper's problem (``--ambient none``) and for the ambient term alone at the paper's
weights (``--ambient estimate``).  ``--auto-only`` runs only this part (no CVXPY).

**Against a baseline** (``--baseline-src DIR``, e.g. main's ``src/`` from ``git archive``): only the
plain command, on the paper's problem and with the ambient estimated, from this tree and from
``DIR``, alternated, best of ``--repeat`` each: the ratio of the solve times, the iterations and
the share of pixels certified.

Run: ``make bench-demux`` or ``.venv/bin/python benchmarks/bench_demux.py [--pixels 384] [--large 512]``.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from planeray.acquire import simulate_stack
from planeray.camera import CameraModel
from planeray.demux import DemuxProblem, solve_cvxpy
from planeray.demux.driver import read_observations
from planeray.demux.problem import RowGroup
from planeray.io import export_folder, read_stack, read_transport, read_transport_maps, write_stack
from planeray.scenes import make_scene
from planeray.scenes.base import Scene, footprint_kernel, scene_offsets
from planeray.timing import PAPER_PROJECTOR_ROWS, RowGeometry, paper_sweep
from planeray.transport import Transport

PAPER_SECONDS_128 = 9 * 60  # "it takes 9 minutes to demultiplex these images for 128x128" (Sec. 6)
#: Laser electrons per frame: the random stack unsaturated, and with ~10 % of observations saturated.
LASER_E = 1000.0
LASER_E_SATURATED = 3800.0


def random_transport_scene(shape, seed=0, projector_rows=PAPER_PROJECTOR_ROWS) -> Scene:
    """Per-pixel random transports: direct spike + asymmetric subsurface kernel (+ a specular bump)."""
    rng = np.random.default_rng(seed)
    H, W = shape
    geometry = RowGeometry(H, projector_rows)
    offsets = scene_offsets()
    u = offsets.astype(np.float64)[None, :]
    P = H * W
    direct = rng.uniform(0.05, 1.0, P)
    dense = direct[:, None] * footprint_kernel(offsets, geometry.rows_per_camera_row)[None, :]
    left, right = rng.uniform(2, 25, (P, 1)), rng.uniform(2, 40, (P, 1))
    dense += rng.uniform(0.0, 0.15, (P, 1)) * np.where(u < 0, np.exp(u / left), np.exp(-u / right))
    bump = (rng.random(P) < 0.3) * rng.uniform(0.05, 0.5, P)
    centre = rng.uniform(15, 100, P) * rng.choice([-1, 1], P)
    width = rng.uniform(1.0, 4.0, P)
    dense += bump[:, None] * np.exp(-0.5 * ((u - centre[:, None]) / width[:, None]) ** 2)
    transport = Transport(dense.reshape(H, W, -1), offsets, geometry)
    zeros = np.zeros(shape, np.float32)
    return Scene(
        "random_transport", transport, direct.reshape(shape).astype(np.float32), zeros, np.ones(shape, np.uint8)
    )


def _cli(*args) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "planeray.cli", *map(str, args)], capture_output=True, text=True, check=True
    )


def import_as_user(stack, tmp: Path, name: str) -> Path:
    """Export to the import format (16-bit TIFFs + manifest) and read it back with ``planeray import``."""
    folder = export_folder(stack, tmp / f"{name}_folder")
    _cli("import", folder, "--out", tmp / f"{name}.zarr")
    return tmp / f"{name}.zarr"


def time_command(stack_path: Path, out: Path, repeat: int, *extra, src: Path | None = None) -> dict:
    """``planeray demux`` in a fresh process, best of ``repeat``: solve time (as printed), wall, peak memory, CPU seconds.

    ``src``: run planeray from this source tree instead (``PYTHONPATH``; a baseline version).
    """
    env = None
    if src is not None:
        import os

        env = dict(os.environ, PYTHONPATH=str(src))
    best = None
    for _ in range(repeat):
        code = (
            "import resource, runpy, sys, time; t0 = time.perf_counter(); sys.argv = ['planeray'] + sys.argv[1:]\n"
            "try:\n    runpy.run_module('planeray.cli', run_name='__main__')\n"
            "except SystemExit:\n    pass\n"
            # VmHWM, not ru_maxrss: that one survives exec and would report this (large) parent
            "hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM:')]\n"
            "peak = int(hwm[0].split()[1]) / 1024 if hwm else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024\n"
            "ru = resource.getrusage(resource.RUSAGE_SELF)\n"
            "print('WALL', time.perf_counter() - t0, peak, ru.ru_utime + ru.ru_stime)"
        )
        run = subprocess.run(
            [sys.executable, "-c", code, "demux", str(stack_path), "--out", str(out), "--overwrite", *map(str, extra)],
            capture_output=True,
            text=True,
            env=env,
        )
        m = re.search(r"pixels in ([0-9.]+) s", run.stdout)
        w = re.search(r"WALL ([0-9.]+) ([0-9.]+) ([0-9.]+)", run.stdout)
        if m is None or w is None:
            raise RuntimeError(f"planeray demux failed: {run.stdout[-500:]} {run.stderr[-2000:]}")
        r = {
            "solve": float(m.group(1)),
            "wall": float(w.group(1)),
            "peak_mib": float(w.group(2)),
            "cpu": float(w.group(3)),
        }
        if best is None or r["solve"] < best["solve"]:
            best = r
    return best


def sample_rows(problem: DemuxProblem, n_rows: int, rng) -> np.ndarray:
    """Whole camera rows with the image's mix of interior and edge rows."""
    H = problem.row_group.size
    interior = np.flatnonzero(problem.row_group == np.bincount(problem.row_group).argmax())
    edge = np.setdiff1d(np.arange(H), interior)
    n_edge = int(round(n_rows * edge.size / H))
    return np.sort(
        np.concatenate([rng.choice(interior, n_rows - n_edge, replace=False), rng.choice(edge, n_edge, replace=False)])
    )


def cvxpy_on_rows(stack, rows, transport_path: Path):
    """CVXPY on whole rows (compiled once per row matrix); gap of the command's output to its optimum."""
    problem = DemuxProblem.from_stack(stack)
    T = read_transport(transport_path)[0].dense
    maps = read_transport_maps(transport_path)
    t_cvx, gaps, n = 0.0, [], 0
    for r in rows:
        obs, sat = read_observations(stack, problem, slice(int(r), int(r) + 1))
        group = problem.groups[problem.row_group[r]]
        B = obs[:, 0, :].T
        mask = None if sat is None else ~sat[:, 0, :].T
        X_fast = T[r][:, group.valid].astype(np.float64)
        t0 = time.perf_counter()
        if mask is None or mask.all():
            ref = solve_cvxpy(group, B, problem.alpha, problem.beta).X
        else:  # each saturated pixel on its remaining observations
            ref = np.zeros_like(X_fast)
            full = mask.all(axis=1)
            ref[full] = solve_cvxpy(group, B[full], problem.alpha, problem.beta).X
            for p in np.flatnonzero(~full & mask.any(axis=1)):
                sub = RowGroup(group.rows, group.A[mask[p]], group.valid)
                ref[p] = solve_cvxpy(sub, B[p : p + 1, mask[p]], problem.alpha, problem.beta).X[0]
        t_cvx += time.perf_counter() - t0
        n += B.shape[0]
        usable = np.ones(B.shape[0], bool) if mask is None else mask.any(axis=1)
        f_ref = problem.objective(group, ref, B, mask)[usable]
        f_fast = problem.objective(group, X_fast, B, mask)[usable]
        gaps.append((f_fast - f_ref) / f_ref)
    gaps = np.concatenate(gaps)
    return n, t_cvx, gaps, bool(maps["converged"][rows].all())


def in_process(stack, repeat: int, rows: slice | None = None) -> dict:
    """The saturated stack's rows solved in this process, best of ``repeat`` each, interleaved:
    ``mask used`` (the default: saturated observations dropped) and ``mask ignored`` (the
    same observations all counted, clipped values included) -- what dropping them costs."""
    import planeray.demux.driver as driver

    problem = DemuxProblem.from_stack(stack)
    rows = slice(0, stack.shape[0]) if rows is None else rows
    chunks = [(i, slice(r, min(r + 16, rows.stop))) for i, r in enumerate(range(rows.start, rows.stop, 16))]
    data = [read_observations(stack, problem, c) for _, c in chunks]
    out = {}
    for _ in range(1 + repeat):  # the first round is a warm-up: compiled kernels, imports
        for name in ("mask used", "mask ignored"):
            fresh = DemuxProblem.from_stack(stack)  # its factorizations are included
            feed = data if name == "mask used" else [(obs, None) for obs, _ in data]
            maps = {}

            def read(i, feed=feed):
                return feed[i]

            def done(i, res, maps=maps):
                maps[i] = res.maps

            t0 = time.perf_counter()
            driver._solve_in_order(fresh, read, chunks, "fast", None, done)
            dt = time.perf_counter() - t0
            if name not in out or dt < out[name][0]:
                out[name] = (dt, {k: np.concatenate([maps[i][k] for i in sorted(maps)]) for k in maps[0]})
    return out


def _iters(maps) -> str:
    it = maps["iterations"][maps["n_observations"] > 0]
    return f"iterations mean {it.mean():.0f}, max {it.max()}; converged {maps['converged'].mean() * 100:.2f} %"


def report(name, stack, stack_path, tmp, args, rng, *, masked=False):
    size = stack.shape[0] * stack.shape[1]
    out = tmp / f"{name}_T.zarr"
    cmd = time_command(stack_path, out, args.repeat)
    problem = DemuxProblem.from_stack(stack)
    n_rows = max(1, int(round(args.pixels / stack.shape[1])))
    rows = sample_rows(problem, n_rows, rng)
    n, t_cvx, gaps, certified = cvxpy_on_rows(stack, rows, out)
    cvx_full = t_cvx / n * size
    maps = read_transport_maps(out)
    sat = None if stack.saturated is None else np.asarray(stack.saturated[:])
    used = ~stack.excluded
    print(f"\n[{name}: {stack.shape[0]}x{stack.shape[1]}]")
    if sat is not None and sat[used].any():
        print(
            f"  saturated observations      : {sat[used].mean() * 100:.1f} % "
            f"({sat[used].any(axis=0).mean() * 100:.0f} % of pixels affected)"
        )
    print(f"  planeray demux (best of {args.repeat})   : {cmd['solve']:.2f} s solve, {cmd['wall']:.2f} s whole process")
    print(f"  {_iters(maps)}")
    print(f"  CVXPY, {n} pixels ({len(rows)} rows) : {t_cvx / n * 1e3:.2f} ms/pixel -> {cvx_full:.0f} s extrapolated")
    print(
        f"  ratio                       : {cvx_full / cmd['solve']:.0f}x CVXPY (whole process: {cvx_full / cmd['wall']:.0f}x)"
    )
    print(
        f"  gap to CVXPY on those pixels: median {np.median(gaps):.1e}, worst {gaps.max():.1e} "
        f"(negative: planeray lower); all certified: {certified}"
    )
    print(f"  peak memory of the command  : {cmd['peak_mib']:.0f} MiB")
    result = {"solve": cmd["solve"], "cvx_full": cvx_full}
    if masked:
        runs = in_process(stack, args.repeat)
        for variant, (dt, m) in runs.items():
            print(f"  in process, {variant:<13}: {dt:6.2f} s ({_iters(m)})")
        result["runs"] = runs
    return result


#: The automatic runs timed against the plain command (same stack, alternated).
AUTO_VARIANTS = (
    ("--alpha auto --beta auto", ("--alpha", "auto", "--beta", "auto")),  # the ambient estimated (the default)
    ("  ... --ambient none", ("--alpha", "auto", "--beta", "auto", "--ambient", "none")),  # the paper's problem
    ("plain --ambient estimate", ("--ambient", "estimate")),  # the ambient term alone, at 0.01 / 0.01
)


def auto_ratio(name: str, stack_path: Path, tmp: Path, repeat: int) -> float:
    """The automatic runs of :data:`AUTO_VARIANTS` against the plain command, alternated, best of ``repeat`` each.

    Returns the ratio of the default automatic run (``--alpha auto --beta auto``, the ambient estimated).
    """
    best: dict = {}
    for _ in range(repeat):
        for label, extra in (("plain", ()), *AUTO_VARIANTS):
            t = time_command(stack_path, tmp / f"{name}_{len(extra)}.zarr", 1, *extra)
            if label not in best or t["solve"] < best[label]["solve"]:
                best[label] = t
    plain = best["plain"]
    ratios = {}
    for label, extra in AUTO_VARIANTS:
        run = best[label]
        ratios[label] = run["solve"] / plain["solve"]
        attrs = zarr_attrs(tmp / f"{name}_{len(extra)}.zarr")
        chosen = attrs.get("weights_choice")
        what = (
            f"chose alpha {chosen['alpha']:.3g}, beta {chosen['beta']:.3g} from {len(chosen['curve']['score'])} "
            f"pairs, {chosen['n_pixels']} pixels"
            if chosen
            else "the weights 0.01 / 0.01"
        )
        print(
            f"  {label:<26}: {run['solve']:.2f} s vs {plain['solve']:.2f} s plain -> **{ratios[label]:.2f}x** "
            f"(whole process {run['wall'] / plain['wall']:.2f}x; ambient {attrs.get('ambient')}; {what})"
        )
    return ratios[AUTO_VARIANTS[0][0]]


#: The runs compared against a baseline source tree (``--baseline-src``): the paper's problem and the ambient term.
BASELINE_VARIANTS = (("plain", ()), ("--ambient estimate", ("--ambient", "estimate")))


def against_baseline(name: str, stack_path: Path, tmp: Path, repeat: int, src: Path) -> None:
    """The plain command (and with the ambient) here and from the baseline tree ``src``, alternated, best of ``repeat``.

    Prints the solve times, their ratio, the iterations and the share of pixels certified.
    """
    best: dict = {}
    for _ in range(repeat):
        for label, extra in BASELINE_VARIANTS:
            for which, tree in (("baseline", src), ("this", None)):
                out = tmp / f"{name}_{which}_{len(extra)}.zarr"
                t = time_command(stack_path, out, 1, *extra, src=tree)
                key = (label, which)
                cpu = best.setdefault(("cpu",) + key, [])
                cpu.append(t["cpu"])
                if key not in best or t["solve"] < best[key]["solve"]:
                    best[key] = t
    for label, extra in BASELINE_VARIANTS:
        a, b = best[(label, "baseline")], best[(label, "this")]
        paths = {w: tmp / f"{name}_{w}_{len(extra)}.zarr" for w in ("baseline", "this")}
        its = {w: _iters(read_transport_maps(p)) for w, p in paths.items()}
        same = np.array_equal(read_transport(paths["baseline"])[0].dense, read_transport(paths["this"])[0].dense)
        print(
            f"  {label:<22}: {b['solve']:.2f} s vs {a['solve']:.2f} s baseline -> **{b['solve'] / a['solve']:.2f}x** "
            f"(whole process {b['wall'] / a['wall']:.2f}x; CPU seconds of the process, median "
            f"{np.median(best[('cpu', label, 'this')]):.2f} vs {np.median(best[('cpu', label, 'baseline')]):.2f} -> "
            f"{np.median(best[('cpu', label, 'this')]) / np.median(best[('cpu', label, 'baseline')]):.2f}x; "
            f"T the same bytes: {same})\n"
            f"      baseline: {its['baseline']}\n      this    : {its['this']}"
        )


def zarr_attrs(path: Path) -> dict:
    import zarr

    return zarr.open_group(str(path), mode="r").attrs.asdict()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--pixels", type=int, default=384, help="pixels (whole rows) solved by CVXPY per stack")
    parser.add_argument("--repeat", type=int, default=3, help="best of this many timed runs")
    parser.add_argument("--large", type=int, default=0, help="also time a LARGE x LARGE wax stack")
    parser.add_argument("--dask", action="store_true", help="also time the large stack with --workers 2")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--auto-only", action="store_true", help="only the automatic weights' cost (no CVXPY)")
    parser.add_argument(
        "--baseline-src",
        type=Path,
        default=None,
        help="only the plain command against planeray from this source tree (e.g. main's src/), alternated",
    )
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    shape = (args.size, args.size)
    sweep = paper_sweep()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        light = dict(ambient_e_per_us=0.0, read_noise_e=2.0)
        scene = random_transport_scene(shape, args.seed)
        random_path = import_as_user(
            simulate_stack(scene, sweep, camera=CameraModel(laser_electrons=LASER_E, **light), seed=args.seed),
            tmp,
            "random",
        )
        print(f"paper sweep, {PAPER_PROJECTOR_ROWS}-row projector; stacks written in the import format and imported")
        if args.baseline_src is not None:
            wax = simulate_stack(make_scene("wax", shape, projector_rows=PAPER_PROJECTOR_ROWS, seed=args.seed), sweep)
            wax_path = write_stack(wax, tmp / "wax.zarr")
            for name, path in (("random transports, no ambient", random_path), ("wax scene", wax_path)):
                print(f"\n[{name}: {args.size}x{args.size}; against {args.baseline_src}]")
                against_baseline(name.split()[0], path, tmp, args.repeat, args.baseline_src.resolve())
            return
        if args.auto_only:
            wax = simulate_stack(make_scene("wax", shape, projector_rows=PAPER_PROJECTOR_ROWS, seed=args.seed), sweep)
            wax_path = write_stack(wax, tmp / "wax.zarr")
            for name, path in (("random transports, no ambient", random_path), ("wax scene", wax_path)):
                print(f"\n[{name}: {args.size}x{args.size}]")
                auto_ratio(name.split()[0], path, tmp, args.repeat)
            return
        rand = report("random transports, no ambient", read_stack(random_path), random_path, tmp, args, rng)
        auto_ratio("random", random_path, tmp, args.repeat)

        wax = simulate_stack(make_scene("wax", shape, projector_rows=PAPER_PROJECTOR_ROWS, seed=args.seed), sweep)
        wax_path = write_stack(wax, tmp / "wax.zarr")
        w = report("wax scene", read_stack(wax_path), wax_path, tmp, args, rng)
        paper = PAPER_SECONDS_128 * (args.size / 128) ** 2
        print(f"  the paper (9 min @128^2)    : {paper / w['solve']:.0f}x")
        auto_ratio("wax", wax_path, tmp, args.repeat)

        sat_stack = simulate_stack(
            scene, sweep, camera=CameraModel(laser_electrons=LASER_E_SATURATED, **light), seed=args.seed
        )
        sat_path = import_as_user(sat_stack, tmp, "saturated")
        s = report(
            "random transports, 10 % saturated",
            read_stack(sat_path),
            sat_path,
            tmp,
            args,
            rng,
            masked=True,
        )
        print(f"  saturated / unsaturated stack (command): {s['solve'] / rand['solve']:.2f}x")
        runs = s["runs"]
        print(f"  saturated / mask ignored (in process): {runs['mask used'][0] / runs['mask ignored'][0]:.2f}x")

        if args.large:
            big = simulate_stack(make_scene("wax", (args.large,) * 2, projector_rows=PAPER_PROJECTOR_ROWS), sweep)
            big_path = write_stack(big, tmp / "big.zarr")
            del big
            cmd = time_command(big_path, tmp / "big_T.zarr", max(1, args.repeat - 1))
            big_stack = read_stack(big_path)
            problem = DemuxProblem.from_stack(big_stack)
            rows = sample_rows(problem, 1, rng)
            n, t_cvx, gaps, certified = cvxpy_on_rows(big_stack, rows, tmp / "big_T.zarr")
            maps = read_transport_maps(tmp / "big_T.zarr")
            cvx_full = t_cvx / n * args.large**2
            print(
                f"\n[wax {args.large}x{args.large}: read lazily from Zarr, chunks of 16 rows, written to a transport store]"
            )
            print(f"  planeray demux              : {cmd['solve']:.1f} s solve, {cmd['wall']:.1f} s whole process")
            print(f"  {_iters(maps)}")
            print(
                f"  peak memory of the command  : {cmd['peak_mib']:.0f} MiB (stack {85 * args.large**2 * 4 / 2**20:.0f} MiB, "
                f"transport {args.large**2 * 229 * 4 / 2**20:.0f} MiB on disk)"
            )
            print(f"  CVXPY, {n} pixels (1 row)   : {cvx_full:.0f} s extrapolated -> {cvx_full / cmd['solve']:.0f}x")
            print(f"  gap to CVXPY                : median {np.median(gaps):.1e}, worst {gaps.max():.1e}")
            if args.dask:
                d = time_command(big_path, tmp / "big_T2.zarr", 1, "--workers", "2")
                print(
                    f"  --workers 2 (Dask)          : {d['solve']:.1f} s ({d['solve'] / cmd['solve']:.2f}x the local run)"
                )


if __name__ == "__main__":
    main()
