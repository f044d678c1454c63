"""The automatic weights against the truth: T error at the chosen, best-grid and paper weights.

For every scene (built-in by name, or a transport store, e.g. from ``planeray render``):
the paper's 85-image sweep is simulated with camera noise (the default camera, seed 0);
``alpha``/``beta`` are chosen by :func:`planeray.demux.choose_weights` from the whole
stack, for each problem of ``--problems``: ``estimate`` (Eq. 6a, an ambient unknown per
pixel: the default of ``--alpha auto --beta auto``) and ``none`` (the paper's problem).
Then the stack restricted to ``--cols`` evenly spaced columns (all rows) is
demultiplexed on the same problem at every pair of the automatic search's grid, and each
result is held against the ground truth (``signal_scale`` times the scene's transport on
the same offsets, which holds no ambient light): the relative error
``||T - T_true|| / ||T_true||`` over those pixels.  The paper's problem at 0.01 / 0.01 is
always measured (the honest reference), and with the ambient estimated the ambient map's
relative error against the camera's ambient (``ambient_e_per_us * albedo * 1e6 /
(lines_per_second * full_well_e)``).

Also reported: the best weights per band of camera rows (4 bands) with knowledge of the
truth, i.e. what weights per region could gain at most over one pair per stack.

Run (nice, small sizes): ``nice -n 10 .venv/bin/python tools/demux_auto_table.py --size 32 --cols 8``
``[--store my_T.zarr ...] [--ambient 0] [--problems estimate none] [--json out/demux_auto.json]``; the stores come from
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


def true_ambient(scene, stack: Stack, cols) -> np.ndarray:
    """The camera's ambient in Eq. 6a's units (normalized value per projector row of exposure), (H, len(cols))."""
    cam = stack.metadata["camera"]
    per_row = cam["ambient_e_per_us"] * 1e6 / (stack.lines_per_second * cam["full_well_e"])
    return per_row * np.asarray(scene.ambient_albedo, np.float64)[:, cols]


def measure(name: str, scene, *, cols_n: int, seed: int = 0, camera=None, problems=("estimate", "none")) -> dict:
    stack = simulate_stack(scene, paper_sweep(), seed=seed, camera=camera)
    scale = float(stack.metadata["signal_scale"])
    W = stack.shape[1]
    cols = np.unique(np.round(np.linspace(0, W - 1, cols_n)).astype(int))
    sub = columns(stack, cols)
    truth = truth_on(scene, DemuxProblem.from_stack(sub), scale, cols)
    a_true = true_ambient(scene, stack, cols)
    H = truth.shape[0]
    band = np.minimum(np.arange(H) * BANDS // H, BANDS - 1)
    norm = np.sqrt((truth**2).sum())
    band_norm2 = np.array([(truth[band == b] ** 2).sum() for b in range(BANDS)])
    default = (PAPER_WEIGHT, PAPER_WEIGHT)
    row = {"scene": name, "band_norm2": band_norm2.tolist()}

    def error_of(result):
        T = result.transport.dense.astype(np.float64)
        d2 = ((T - truth) ** 2).sum(axis=(1, 2))
        return float(np.sqrt(d2.sum()) / norm), np.array([d2[band == k].sum() for k in range(BANDS)])

    def ambient_error(result):
        if result.ambient is None or not np.any(a_true):
            return None
        return float(np.linalg.norm(result.ambient - a_true) / np.linalg.norm(a_true))

    t0 = time.perf_counter()
    demultiplex(stack)
    row["plain_s"] = time.perf_counter() - t0
    # the honest reference: the paper's problem at the paper's weights
    row["paper_default"] = error_of(demultiplex(sub, alpha=PAPER_WEIGHT, beta=PAPER_WEIGHT, ambient="none"))[0]
    for problem in problems:
        t0 = time.perf_counter()
        choice = choose_weights(stack, ambient=problem)
        t_auto = time.perf_counter() - t0
        errors, band_err2, amb_err = {}, {}, {}
        for a in DEFAULT_ALPHAS:
            for b in DEFAULT_BETAS:
                res = demultiplex(sub, alpha=a, beta=b, ambient=problem)
                errors[(a, b)], band_err2[(a, b)] = error_of(res)
                amb_err[(a, b)] = ambient_error(res)
        best = min(errors, key=errors.get)
        # per band the truth-best pair: what weights per region could gain at most
        per_band = sum(min(v[k] for v in band_err2.values()) for k in range(BANDS))
        chosen = (choice.alpha, choice.beta)
        r = {
            "chosen": chosen,
            "alpha_range": choice.alpha_range,
            "beta_range": choice.beta_range,
            "error_chosen": errors[chosen],
            "ambient_error_chosen": amb_err[chosen],
            "best": best,
            "error_best": errors[best],
            "error_default": errors[default],
            "error_best_per_band": float(np.sqrt(per_band) / norm),
            "auto_s": t_auto,
            "grid": {f"{a:g},{b:g}": e for (a, b), e in errors.items()},
            "curve": choice.to_attrs()["curve"],
        }
        row[problem] = r
        amb = "" if r["ambient_error_chosen"] is None else f" | ambient map err {r['ambient_error_chosen']:.3f}"
        print(
            f"{name:>14} [{problem:>8}]: chosen alpha={chosen[0]:.3g} beta={chosen[1]:.3g} err {r['error_chosen']:.4f} | "
            f"best ({best[0]:.3g},{best[1]:.3g}) {r['error_best']:.4f} | 0.01/0.01 {r['error_default']:.4f} | "
            f"ratio {r['error_chosen'] / r['error_best']:.2f} vs 0.01/0.01 {r['error_chosen'] / r['error_default']:.3f} "
            f"vs paper's 0.01/0.01 {r['error_chosen'] / row['paper_default']:.3f} | "
            f"per-band best {r['error_best_per_band']:.4f}{amb} | auto {t_auto:.1f} s, plain {row['plain_s']:.1f} s",
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
    ap.add_argument(
        "--problems",
        nargs="+",
        default=["estimate", "none"],
        choices=["estimate", "none"],
        help="ambient modes measured",
    )
    args = ap.parse_args(argv)
    from planeray.camera import CameraModel

    camera = None if args.ambient is None else CameraModel(ambient_e_per_us=args.ambient)
    rows = []

    def save():
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps(rows, indent=1, default=lambda o: list(o) if isinstance(o, tuple) else o))

    for name in args.scenes:
        scene = make_scene(name, (args.size, args.size), projector_rows=args.projector_rows, seed=0)
        rows.append(measure(name, scene, cols_n=args.cols, camera=camera, problems=args.problems))
        save()
    for path in args.store:
        from planeray.scenes.store_scene import scene_from_transport_store

        scene = scene_from_transport_store(path)
        rows.append(measure(Path(path).stem, scene, cols_n=args.cols, camera=camera, problems=args.problems))
        save()
    for problem in args.problems:
        print(
            f"\nproblem: {problem} (best and 0.01 / 0.01 on the same problem; last column: the paper's problem at 0.01 / 0.01)"
        )
        print(
            "| scene | chosen alpha / beta | error at chosen | best alpha / beta (truth) | error at best | "
            "error at 0.01 / 0.01 | chosen / best | chosen / 0.01-0.01 | paper's problem at 0.01 / 0.01 | chosen / paper's |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|")
        for row in rows:
            r = row[problem]
            a, b = r["chosen"]
            ba, bb = r["best"]
            print(
                f"| {row['scene']} | {a:.3g} / {b:.3g} | {r['error_chosen']:.3f} | {ba:.3g} / {bb:.3g} | "
                f"{r['error_best']:.3f} | {r['error_default']:.3f} | {r['error_chosen'] / r['error_best']:.2f} | "
                f"{r['error_chosen'] / r['error_default']:.2f} | {row['paper_default']:.3f} | "
                f"{r['error_chosen'] / row['paper_default']:.2f} |"
            )


if __name__ == "__main__":
    main()
