"""The automatic weights against the truth: T error at the chosen, best-grid and paper weights.

For every scene (built-in by name, or a transport store, e.g. from ``planeray render``):
the paper's 85-image sweep is simulated with camera noise (the default camera, seed 0);
``alpha``/``beta`` are chosen by :func:`planeray.demux.choose_weights` from the whole
stack; then the stack restricted to ``--cols`` evenly spaced columns (all rows) is
demultiplexed at every pair of the automatic search's grid, and each result is held
against the ground truth (``signal_scale`` times the scene's transport on the same
offsets): the relative error ``||T - T_true|| / ||T_true||`` over those pixels.

Also reported: the best weights per band of camera rows (4 bands) with knowledge of the
truth, i.e. what weights per region could gain at most over one pair per stack.

Run (nice, small sizes): ``nice -n 10 .venv/bin/python tools/demux_auto_table.py --size 32 --cols 8``
``[--store my_T.zarr ...] [--ambient 0] [--json out/demux_auto.json]``; the README's stores come from
``planeray render tools/demux_auto_scenes/NAME.xml --out NAME.zarr --rows 720 --size 32 32 --spp 64``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from planeray.acquire import simulate_stack
from planeray.demux import DemuxProblem, choose_weights, demultiplex
from planeray.demux.auto import DEFAULT_ALPHAS, DEFAULT_BETAS, PAPER_WEIGHT
from planeray.scenes import make_scene
from planeray.stack import Stack
from planeray.timing import PAPER_PROJECTOR_ROWS, paper_sweep

BUILT_IN = ("wax", "corner", "mirror_ball", "disco_ball", "skin", "materials")
BANDS = 4


def columns(stack: Stack, cols) -> Stack:
    """The stack restricted to some columns (the problem depends on rows only)."""
    sat = None if stack.saturated is None else np.asarray(stack.saturated)[:, :, cols]
    return Stack(
        np.asarray(stack.images)[:, :, cols],
        stack.delay_us,
        stack.exposure_us,
        stack.lines_per_second,
        excluded=stack.excluded,
        saturated=sat,
        projector_rows=stack.projector_rows,
        metadata=stack.metadata,
    )


def truth_on(scene, problem: DemuxProblem, scale: float, cols) -> np.ndarray:
    """``scale`` times the scene's dense transport on the problem's offsets (0 where it has none)."""
    tr = scene.transport
    H = tr.dense.shape[0]
    out = np.zeros((H, len(cols), problem.n_offsets))
    u0 = int(problem.offsets_rows[0])
    for k, u in enumerate(tr.offsets_rows):
        j = int(u) - u0
        if 0 <= j < problem.n_offsets:
            out[:, :, j] = tr.dense[:, cols, k]
    sp = tr.sparse
    if len(sp):
        keep = np.isin(sp.col, cols)
        colpos = {c: i for i, c in enumerate(cols)}
        for r, c, o, v in zip(sp.row[keep], sp.col[keep], sp.offset[keep], sp.value[keep]):
            j = int(o) - u0
            if 0 <= j < problem.n_offsets:
                out[r, colpos[int(c)], j] += v
    return scale * out


def measure(name: str, scene, *, cols_n: int, seed: int = 0, camera=None) -> dict:
    stack = simulate_stack(scene, paper_sweep(), seed=seed, camera=camera)
    scale = float(stack.metadata["signal_scale"])
    t0 = time.perf_counter()
    choice = choose_weights(stack)
    t_auto = time.perf_counter() - t0
    t0 = time.perf_counter()
    demultiplex(stack)
    t_plain = time.perf_counter() - t0
    W = stack.shape[1]
    cols = np.unique(np.round(np.linspace(0, W - 1, cols_n)).astype(int))
    sub = columns(stack, cols)
    problem = DemuxProblem.from_stack(sub)
    truth = truth_on(scene, problem, scale, cols)
    H = truth.shape[0]
    band = np.minimum(np.arange(H) * BANDS // H, BANDS - 1)
    norm = np.sqrt((truth**2).sum())
    band_norm2 = np.array([(truth[band == b] ** 2).sum() for b in range(BANDS)])
    errors, band_err2 = {}, {}
    for a in DEFAULT_ALPHAS:
        for b in DEFAULT_BETAS:
            T = demultiplex(sub, alpha=a, beta=b).transport.dense.astype(np.float64)
            d2 = ((T - truth) ** 2).sum(axis=(1, 2))
            errors[(a, b)] = float(np.sqrt(d2.sum()) / norm)
            band_err2[(a, b)] = np.array([d2[band == k].sum() for k in range(BANDS)])
    best = min(errors, key=errors.get)
    # per band the truth-best pair: what weights per region could gain at most
    per_band = sum(min(v[k] for v in band_err2.values()) for k in range(BANDS))
    chosen = (choice.alpha, choice.beta)
    default = (PAPER_WEIGHT, PAPER_WEIGHT)
    row = {
        "scene": name,
        "chosen": chosen,
        "alpha_range": choice.alpha_range,
        "beta_range": choice.beta_range,
        "error_chosen": errors[chosen],
        "best": best,
        "error_best": errors[best],
        "error_default": errors[default],
        "error_best_per_band": float(np.sqrt(per_band) / norm),
        "auto_s": t_auto,
        "plain_s": t_plain,
        "band_norm2": band_norm2.tolist(),
        "grid": {f"{a:g},{b:g}": e for (a, b), e in errors.items()},
        "curve": choice.to_attrs()["curve"],
    }
    print(
        f"{name:>14}: chosen alpha={chosen[0]:.3g} beta={chosen[1]:.3g} err {row['error_chosen']:.4f} | "
        f"best ({best[0]:.3g},{best[1]:.3g}) {row['error_best']:.4f} | default {row['error_default']:.4f} | "
        f"ratio {row['error_chosen'] / row['error_best']:.2f} vs default {row['error_chosen'] / row['error_default']:.3f} | "
        f"per-band best {row['error_best_per_band']:.4f} | auto {t_auto:.1f} s, plain {t_plain:.1f} s",
        flush=True,
    )
    return row


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="*", default=list(BUILT_IN))
    ap.add_argument("--store", nargs="*", default=[], help="transport stores (e.g. from planeray render)")
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--cols", type=int, default=8)
    ap.add_argument("--projector-rows", type=int, default=PAPER_PROJECTOR_ROWS)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--ambient", type=float, default=None, help="ambient e-/us of the camera (default: its 0.5)")
    args = ap.parse_args(argv)
    from planeray.camera import CameraModel

    camera = None if args.ambient is None else CameraModel(ambient_e_per_us=args.ambient)
    rows = []
    for name in args.scenes:
        scene = make_scene(name, (args.size, args.size), projector_rows=args.projector_rows, seed=0)
        rows.append(measure(name, scene, cols_n=args.cols, camera=camera))
    for path in args.store:
        from planeray.scenes.store_scene import scene_from_transport_store

        scene = scene_from_transport_store(path)
        rows.append(measure(Path(path).stem, scene, cols_n=args.cols, camera=camera))
    print(
        "\n| scene | chosen alpha / beta (1-SE range of alpha) | error at chosen | best (alpha / beta) | error at best | error at 0.01 / 0.01 | chosen / best | chosen / default |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        a, b = r["chosen"]
        ba, bb = r["best"]
        lo, hi = r["alpha_range"]
        print(
            f"| {r['scene']} | {a:.3g} / {b:.3g} ({lo:.3g}-{hi:.3g}) | {r['error_chosen']:.3f} | {ba:.3g} / {bb:.3g} | "
            f"{r['error_best']:.3f} | {r['error_default']:.3f} | {r['error_chosen'] / r['error_best']:.2f} | "
            f"{r['error_chosen'] / r['error_default']:.2f} |"
        )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1, default=lambda o: list(o) if isinstance(o, tuple) else o))


if __name__ == "__main__":
    main()
