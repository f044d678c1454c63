"""``planeray demux`` of one stack by several commits of planeray, interleaved: CPU seconds, and where they go.

For finding (or ruling out) a speed regression on a shared machine: each commit's ``src/`` is taken
with ``git archive`` into a temporary folder, and the same stack -- the 128 x 128 paper-sweep stack of
random transports without ambient light of ``bench_demux.py``, imported from 16-bit TIFFs as a user
would -- is demultiplexed by ``planeray demux`` from each tree in a fresh process, the trees in a new
random order every round (a warm-up round first: Numba's caches, imports).  Per run:

* the process's **CPU seconds** (user + system; wall time on a loaded machine says more about the
  other users than about planeray);
* the **solver threads' CPU** (the tasks of ``planeray.demux.driver._run_task``, timed with
  ``time.thread_time`` inside them) and the **rest** (imports, reading, the content digest, the
  problem, writing);
* an **estimate of the wall time on a quiet 2-core machine**: the rest plus half the solver's CPU
  (its two threads kept busy);
* the iterations (the same on every commit with the same solver: the same work).

Medians over the rounds, with the load average.  Run:
``.venv/bin/python benchmarks/bench_demux_history.py 9f0f3b0 HEAD [--rounds 5] [--worktree .]``
(a label ``.`` is the working tree's ``src/``, uncommitted changes included).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

#: Runs ``planeray demux`` with its solver tasks timed (thread CPU) and writes the record as JSON.
RUNNER = """
import json, resource, sys, threading, time
out_json = sys.argv[1]
sys.argv = ["planeray", "demux", *sys.argv[2:]]
t0 = time.perf_counter()
import planeray.demux.driver as drv
tasks, lock, orig = [], threading.Lock(), drv._run_task
def timed(*a, **k):
    c0 = time.thread_time()
    try:
        return orig(*a, **k)
    finally:
        with lock:
            tasks.append(time.thread_time() - c0)
drv._run_task = timed
import runpy
try:
    runpy.run_module("planeray.cli", run_name="__main__")
except SystemExit:
    pass
ru = resource.getrusage(resource.RUSAGE_SELF)
json.dump({"task_cpu": sum(tasks), "cpu": ru.ru_utime + ru.ru_stime, "wall": time.perf_counter() - t0}, open(out_json, "w"))
"""


def tree_of(commit: str, repo: Path, into: Path) -> Path:
    """``commit``'s ``src/`` in ``into/commit`` (``.``: the working tree's own)."""
    if commit == ".":
        return repo / "src"
    dest = into / commit
    dest.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "-C", str(repo), "archive", commit, "src"], capture_output=True, check=True)
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive.stdout, check=True)
    return dest / "src"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("commits", nargs="+", help="commits (any git revision) or '.' for the working tree")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--worktree", type=Path, default=Path(__file__).resolve().parents[1])
    ap.add_argument("--size", type=int, default=128)
    args = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_demux import LASER_E, import_as_user, random_transport_scene

    from planeray.acquire import simulate_stack
    from planeray.camera import CameraModel
    from planeray.timing import paper_sweep

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        camera = CameraModel(laser_electrons=LASER_E, ambient_e_per_us=0.0, read_noise_e=2.0)
        stack = simulate_stack(random_transport_scene((args.size, args.size), 0), paper_sweep(), camera=camera, seed=0)
        path = import_as_user(stack, tmp, "random")
        (tmp / "runner.py").write_text(RUNNER)
        trees = {c: tree_of(c, args.worktree, tmp / "trees") for c in args.commits}
        results: dict[str, list] = {c: [] for c in trees}
        for k in range(args.rounds + 1):
            order = list(trees)
            random.Random(k).shuffle(order)
            for c in order:
                out = tmp / f"T-{len(results[c])}-{abs(hash(c))}.zarr"
                env = dict(os.environ, PYTHONPATH=str(trees[c]))
                rec = tmp / "rec.json"
                run = subprocess.run([sys.executable, str(tmp / "runner.py"), str(rec), str(path), "--out", str(out),
                                      "--overwrite"], env=env, capture_output=True, text=True)  # fmt: skip
                if run.returncode != 0 or not rec.exists():
                    raise RuntimeError(f"{c}: {run.stdout[-300:]} {run.stderr[-1500:]}")
                r = json.loads(rec.read_text())
                rec.unlink()
                import zarr

                r["iterations"] = float(np.mean(zarr.open_group(str(out), mode="r")["iterations"][:]))
                r["load"] = os.getloadavg()[0]
                if k:  # round 0 warms up
                    results[c].append(r)
        print(f"planeray demux, {args.size}x{args.size} random transports (paper sweep, no ambient), "
              f"{args.rounds} interleaved rounds, medians; {os.cpu_count()} cores")  # fmt: skip
        print(
            "| commit | process CPU s | solver threads CPU s | rest CPU s | quiet 2-core wall estimate s | "
            "iterations | load average |"
        )
        print("|---|---|---|---|---|---|---|")
        base = None
        for c, rs in results.items():
            cpu = float(np.median([r["cpu"] for r in rs]))
            task = float(np.median([r["task_cpu"] for r in rs]))
            rest = float(np.median([r["cpu"] - r["task_cpu"] for r in rs]))
            est = float(np.median([r["cpu"] - r["task_cpu"] / 2 for r in rs]))
            base = base or cpu
            print(
                f"| {c} | {cpu:.2f} ({cpu / base:.2f}x) | {task:.2f} | {rest:.2f} | {est:.2f} | "
                f"{np.mean([r['iterations'] for r in rs]):.1f} | {np.median([r['load'] for r in rs]):.1f} |"
            )


if __name__ == "__main__":
    main()
