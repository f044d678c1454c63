"""The medium's fit with its anisotropy unknown (fitted) against the same fit with ``g`` stated (the baseline).

A capture of the ``materials`` scene on the simulated device (``--size`` x ``--size`` pixels, the paper's
sweep, its five trays labelled): the stack fit of each tray with its walls (:func:`fit_stack`, what
``planeray materials fit`` runs on a stack), and the transport fit of the ground-truth transport in 4 x 4
pixel blocks (:func:`fit_transport`), each with ``g`` stated at the table's 0.8 (one parameter fewer: what
the fit did before ``g`` was fitted) and with ``g`` unknown, alternated, best of ``--repeat``.  Prints
seconds and the ratio unknown / stated.

Run: ``.venv/bin/python benchmarks/bench_materials_fit.py [--size 64] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from planeray.camera import CameraModel
from planeray.experiments.materials import _capture_scene, simulate_capture
from planeray.materials.fit import fit_transport, forward_table
from planeray.materials.stackfit import fit_stack
from planeray.scenes.materials import DEFAULT_MM_PER_ROW


def _alternated(run, repeat):
    """Best seconds of ``run(0.8)`` (g stated) and ``run(None)`` (g unknown), alternated ``repeat`` times."""
    best = {0.8: np.inf, None: np.inf}
    for _ in range(repeat):
        for g in best:
            t0 = time.perf_counter()
            run(g)
            best[g] = min(best[g], time.perf_counter() - t0)
    return best[0.8], best[None]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    cap = simulate_capture(size=(args.size, args.size), seed=0, placement=0)
    labels = np.where(cap.labels <= 5, cap.labels, 0).astype(np.int64)  # the five trays; the table left out
    mm = DEFAULT_MM_PER_ROW
    camera = CameraModel.from_metadata(cap.stack.metadata)
    transport = _capture_scene(cap.settings).transport
    table = forward_table()
    runs = {
        "stack fit, 5 trays with walls": lambda g: fit_stack(
            cap.stack, mm_per_row=mm, labels=labels, containers=labels, table=table, camera=camera, g=g
        ),
        "transport fit, 4x4 blocks": lambda g: fit_transport(
            transport, mm_per_row=mm, labels=labels, block_px=4, table=table, g=g
        ),
    }
    print(f"materials scene {args.size}x{args.size}, best of {args.repeat}:")
    for name, run in runs.items():
        run(0.8)  # warm: tables read, code compiled
        stated, unknown = _alternated(run, args.repeat)
        print(f"  {name:32s} g stated {stated:6.2f} s   g unknown {unknown:6.2f} s   ({unknown / stated:.2f}x)")


if __name__ == "__main__":
    main()
