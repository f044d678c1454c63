"""Issue 42: criteria for the automatic weights against the truth, on transports nobody tuned them on.

For each *condition* -- a scene (a store rendered by ``planeray render`` from the fixed scene
files in ``tools/demux_weights_scenes/``, or a built-in scene of issue 26), at its projector /
camera rows, with or without the camera's ambient light -- the paper's 85-image sweep is
simulated with the default camera's noise (seed 0) and

* **the truth curve**: the stack restricted to ``--cols`` evenly spaced columns (all rows) is
  demultiplexed at every pair of the half-decade grid (alpha 1e-3 ... 1e4, beta 1e-4 ... 10:
  165 pairs) on the problem of ``--problem`` (default ``estimate``, Eq. 6a, what
  ``--alpha auto --beta auto`` solves) and held against ``signal_scale`` times the scene's
  transport on the same offsets: the relative error ``||T - T_true|| / ||T_true||`` over those
  pixels (1-row offset bins, as in issue 26's table), with every solve's certified relative
  duality gap (the worst of the curve is reported) and the error of four images the sweep never
  captured, predicted from ``T`` (a 12-row sharpened epipolar image and three bands 20-24 rows
  wide at offsets -25, +15, +45: what ``T`` is used for);
* **every candidate criterion** on the full grid, on the pixel sample the product scores
  (``planeray.demux.auto._sample``), each a per-pixel array per pair so that
  combinations can be evaluated afterwards: ``cv-random`` (5 random folds of images, the
  criterion of issue 26), ``cv-blocks`` (5 folds of contiguous delays: a left-out image has no
  near neighbour in the training set), both noise-weighted; ``sure`` (Stein's unbiased risk
  estimate of the noise-weighted prediction error, with the degrees of freedom of the
  constrained solution, the trace of the influence matrix on each pixel's free set), ``gcv``
  and the weighted chi-square per degree of freedom (the discrepancy principle's statistic);
  ``null`` (the share of the estimate's energy outside the row space of the illumination matrix:
  what no image sees);
* the choice of each criterion (its grid argmin), its error, the truth's best and 0.01 / 0.01.

Results are cached per condition in ``--cache`` (JSON + NPZ), so a rerun only computes what is
missing; ``--report`` prints the tables from the cache.  Run with ``nice``: a condition takes
2-10 minutes on the shared 2-core machine::

    nice -n 10 .venv/bin/python tools/demux_weights_study.py --cache /work/cache-auto-weights/study \\
        --stores /work/cache-auto-weights/stores/*.zarr --builtin wax corner mirror_ball disco_ball skin materials

The stores come from ``tools/demux_weights_scenes/render.sh`` (not committed: regenerable).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from demux_auto_table import columns, truth_on  # issue 26's tool, beside this one

from planeray.acquire import simulate_stack
from planeray.camera import CameraModel
from planeray.demux import DemuxProblem
from planeray.demux import auto as auto_mod
from planeray.demux.fast import AdmmRowSolver, blas_one_thread, solve_fast
from planeray.demux.problem import difference_matrix, read_observations
from planeray.stack import Stack
from planeray.synthesis import offset_window
from planeray.timing import PAPER_PROJECTOR_ROWS, RowGeometry, paper_sweep

ALPHAS = tuple(float(10.0**e) for e in np.arange(-3.0, 4.01, 0.5))
BETAS = tuple(float(10.0**e) for e in np.arange(-4.0, 1.01, 0.5))
DEFAULT = (0.01, 0.01)
#: Images the sweep never captured, predicted from T: (centre, width) in projector rows.
UNCAPTURED = ((0.0, 12.0), (-25.0, 20.0), (15.0, 20.0), (45.0, 24.0))
CRITERIA = ("cv-random", "sure", "gcv", "chi2dof", "null")
#: Measured on the first two conditions and dropped (see the docs): 5 folds of contiguous delays.
BLOCK_FOLDS = False


# ------------------------------------------------------------------ the condition
def band_images(T, problem: DemuxProblem) -> np.ndarray:
    """The images of :data:`UNCAPTURED` predicted from ``T`` ``(H, C, U)``: ``(len(UNCAPTURED), H, C)``."""
    H = T.shape[0]
    geometry = RowGeometry(H, problem.projector_rows)
    rows = np.arange(H)[:, None]
    out = []
    for c, w in UNCAPTURED:
        weights = offset_window(c, w).weights(geometry, rows, problem.offsets_rows[None, :])  # (H, U)
        out.append(np.einsum("tsu,tu->ts", T, weights))
    return np.stack(out)


def solve_subset(sub: Stack, problem: DemuxProblem, alpha: float, beta: float, ambient: bool):
    """``T`` ``(H, C, U)``, the worst certified relative gap and the share converged, at one pair."""
    H, C = sub.shape
    obs, sat = read_observations(sub, problem, slice(0, H))
    T = np.zeros((H, C, problem.n_offsets))
    worst, n_conv, n = 0.0, 0, 0
    col = problem.exposure_rows if ambient else None
    for g in problem.groups:
        if g.A.shape[1] == 0:
            continue
        B = obs[:, g.rows, :].reshape(obs.shape[0], -1).T
        mask = None if sat is None else ~sat[:, g.rows, :].reshape(obs.shape[0], -1).T
        if mask is not None and mask.all():
            mask = None
        res = solve_fast(g, B, alpha, beta, mask=mask, ambient=col)
        usable = np.ones(B.shape[0], bool) if mask is None else mask.any(axis=1)
        T[g.rows, :, g.valid] = g.transport(res.X).reshape(len(g.rows), C, -1)
        worst = max(worst, float(res.gap[usable].max(initial=0.0)))
        n_conv += int(res.converged[usable].sum())
        n += int(usable.sum())
    return T, worst, n_conv / max(n, 1)


def make_condition(scene, *, ambient_e_per_us: float, cols_n: int, seed: int = 0):
    stack = simulate_stack(scene, paper_sweep(), seed=seed, camera=CameraModel(ambient_e_per_us=ambient_e_per_us))
    scale = float(stack.metadata["signal_scale"])
    W = stack.shape[1]
    cols = np.unique(np.round(np.linspace(0, W - 1, cols_n)).astype(int))
    sub = columns(stack, cols)
    problem = DemuxProblem.from_stack(sub)
    truth = truth_on(scene, problem, scale, cols)
    return stack, sub, problem, truth


# ------------------------------------------------------------------ the criteria
def _block_folds(problem: DemuxProblem, stack: Stack, k: int = 5) -> list[np.ndarray]:
    """Folds of contiguous delays: the used images sorted by band centre, cut into ``k`` blocks."""
    delays = np.asarray(stack.delay_us)[problem.image_index]
    order = np.argsort(delays, kind="stable")
    return [np.sort(b) for b in np.array_split(order, k)]


def _dof(A, alpha: float, n_x: int, x, keep) -> float:
    """Trace of the influence matrix ``A_F (A_F^T A_F + alpha (D^T D)_FF)^{-1} A_F^T`` on the free set."""
    F = np.flatnonzero(x > 0)
    if F.size == 0:
        return 0.0
    Ak = A if keep is None else A[keep]
    D = difference_matrix(n_x)
    R = np.zeros((A.shape[1], A.shape[1]))
    R[:n_x, :n_x] = D.T @ D
    AF = Ak[:, F]
    H = AF.T @ AF + alpha * R[np.ix_(F, F)]
    G = AF.T @ AF
    try:
        return float(np.trace(np.linalg.solve(H, G)))
    except np.linalg.LinAlgError:
        return float(np.trace(np.linalg.lstsq(H, G, rcond=None)[0]))


def criteria_at(sample, folds_random, folds_blocks, alpha, beta, column, tol) -> dict:
    """Every candidate criterion's per-pixel value at one pair (and the worst gap of its solves)."""
    out = {name: [] for name in CRITERIA}
    worst = 0.0
    for g, B, mask, w in zip(sample.groups, sample.B, sample.mask, sample.weight):
        N = B.shape[1]
        full = AdmmRowSolver(g.A, alpha, beta, ambient=column)
        X, _, _, gap, *_ = full.solve(B, tol, mask=mask)
        worst = max(worst, float(gap.max(initial=0.0)))
        A = full.A
        R = B - X @ A.T
        used = np.ones_like(B, bool) if mask is None else mask
        chi2 = (w * R * R * used).sum(axis=1)
        n = used.sum(axis=1)
        dof = np.array([_dof(A, alpha, full.n_x, X[p], None if mask is None else mask[p]) for p in range(B.shape[0])])
        out["sure"].append((chi2 - n + 2.0 * dof) / np.maximum(n, 1))
        out["gcv"].append(n * chi2 / np.maximum(n - dof, 1.0) ** 2)
        out["chi2dof"].append(chi2 / np.maximum(n - dof, 1.0))
        # the share of the estimate outside the row space of A (no image sees it)
        _, s, Vt = np.linalg.svd(A, full_matrices=False)
        V = Vt[s > 1e-8 * s[0]]
        seen = (X @ V.T) @ V
        tot = (X * X).sum(axis=1)
        out["null"].append(1.0 - (seen * seen).sum(axis=1) / np.maximum(tot, 1e-300))
        for name, folds in (("cv-random", folds_random), ("cv-blocks", folds_blocks)):
            if name not in out:
                continue
            ss = np.zeros(B.shape[0])
            cnt = np.zeros(B.shape[0])
            for test in folds:
                train = np.setdiff1d(np.arange(N), test)
                e = None if column is None else np.asarray(column)[train]
                solver = AdmmRowSolver(g.A[train], alpha, beta, ambient=e)
                m = None if mask is None else mask[:, train]
                if m is not None and m.all():
                    m = None
                Xf, _, _, gf, *_ = solver.solve(B[:, train], tol, mask=m)
                worst = max(worst, float(gf.max(initial=0.0)))
                At = (
                    g.A[test] if column is None else auto_mod._test_columns(solver, g.A[test], np.asarray(column)[test])
                )
                Rt = B[:, test] - Xf @ At.T
                wt = w[:, test]
                ss += (wt * Rt * Rt).sum(axis=1)
                cnt += (wt > 0).sum(axis=1)
            out[name].append(ss / np.maximum(cnt, 1))
    return {k: np.concatenate(v) for k, v in out.items()} | {"worst_gap": worst}


# ------------------------------------------------------------------ one condition
def run_condition(name: str, scene, *, ambient_e_per_us, cols_n, problem_mode, cache: Path, tol_cv=1e-4) -> dict:
    key = f"{name}__amb{ambient_e_per_us:g}__{problem_mode}"
    jpath, npath = cache / f"{key}.json", cache / f"{key}.npz"
    if jpath.exists() and npath.exists():
        return json.loads(jpath.read_text())
    t0 = time.perf_counter()
    stack, sub, problem, truth = make_condition(scene, ambient_e_per_us=ambient_e_per_us, cols_n=cols_n)
    ambient = problem_mode == "estimate"
    norm = float(np.sqrt((truth**2).sum()))
    truth_img = band_images(truth, problem)
    img_norm = float(np.sqrt((truth_img**2).sum()))
    grid = [(a, b) for a in ALPHAS for b in BETAS]
    err, img_err, gaps, conv = {}, {}, {}, {}
    with blas_one_thread():
        for a, b in grid:
            T, worst, c = solve_subset(sub, problem, a, b, ambient)
            err[(a, b)] = float(np.sqrt(((T - truth) ** 2).sum()) / norm)
            img_err[(a, b)] = float(np.sqrt(((band_images(T, problem) - truth_img) ** 2).sum()) / img_norm)
            gaps[(a, b)] = worst
            conv[(a, b)] = c
    t_truth = time.perf_counter() - t0
    full_problem = DemuxProblem.from_stack(stack)
    sample = auto_mod._sample(stack, full_problem, seed=0, n_pixels=None, weighting="noise")
    folds_r = auto_mod._folds(full_problem.n_images, auto_mod.DEFAULT_FOLDS, 0)
    folds_b = _block_folds(full_problem, stack)
    column = full_problem.exposure_rows if ambient else None
    per_pixel = {c: np.zeros((len(grid), sample.n_pixels)) for c in CRITERIA}
    crit_gap = np.zeros(len(grid))
    with blas_one_thread():
        for i, (a, b) in enumerate(grid):
            vals = criteria_at(sample, folds_r, folds_b, a, b, column, tol_cv)
            crit_gap[i] = vals.pop("worst_gap")
            for c in CRITERIA:
                per_pixel[c][i] = vals[c]
    np.savez_compressed(npath, grid=np.array(grid), **{c.replace("-", "_"): v for c, v in per_pixel.items()})
    rec = {
        "condition": key,
        "scene": name,
        "ambient_e_per_us": ambient_e_per_us,
        "problem": problem_mode,
        "shape": list(stack.shape),
        "projector_rows": int(stack.projector_rows),
        "cols": cols_n,
        "n_sample": int(sample.n_pixels),
        "grid": [[a, b] for a, b in grid],
        "error": [err[p] for p in grid],
        "image_error": [img_err[p] for p in grid],
        "worst_gap": [gaps[p] for p in grid],
        "converged": [conv[p] for p in grid],
        "criterion_worst_gap": crit_gap.tolist(),
        "seconds_truth": t_truth,
        "seconds_total": time.perf_counter() - t0,
    }
    jpath.write_text(json.dumps(rec))
    return rec


# ------------------------------------------------------------------ the product's choice
def run_product(name: str, scene, *, ambient_e_per_us, cols_n, problem_mode, cache: Path, criterion: str) -> dict:
    """``choose_weights`` as ``planeray demux --alpha auto --beta auto`` runs it, and the truth error at its choice."""
    key = f"{name}__amb{ambient_e_per_us:g}__{problem_mode}"
    path = cache / f"{key}__product_{criterion}.json"
    if path.exists():
        return json.loads(path.read_text())
    rec = json.loads((cache / f"{key}.json").read_text())
    stack, sub, problem, truth = make_condition(scene, ambient_e_per_us=ambient_e_per_us, cols_n=cols_n)
    t0 = time.perf_counter()
    choice = auto_mod.choose_weights(stack, criterion=criterion, ambient=problem_mode)
    seconds = time.perf_counter() - t0
    pair = (choice.alpha, choice.beta)
    grid = {tuple(p): e for p, e in zip(rec["grid"], rec["error"])}
    imgs = {tuple(p): e for p, e in zip(rec["grid"], rec["image_error"])}
    if pair in grid:
        err, img = grid[pair], imgs[pair]
    else:  # off the grid (the search went past an end): measured here
        with blas_one_thread():
            T, _, _ = solve_subset(sub, problem, *pair, problem_mode == "estimate")
        norm = np.sqrt((truth**2).sum())
        err = float(np.sqrt(((T - truth) ** 2).sum()) / norm)
        ti = band_images(truth, problem)
        img = float(np.sqrt(((band_images(T, problem) - ti) ** 2).sum()) / np.sqrt((ti**2).sum()))
    out = {
        "condition": key,
        "criterion": choice.criterion,
        "choice": list(pair),
        "error": err,
        "image_error": img,
        "edge": choice.edge,
        "worst_gap": choice.worst_gap,
        "pairs": len(choice.scores),
        "seconds": seconds,
        "curve": choice.to_attrs()["curve"],
    }
    path.write_text(json.dumps(out))
    return out


# ------------------------------------------------------------------ analysis
def load(cache: Path, key: str):
    rec = json.loads((cache / f"{key}.json").read_text())
    z = np.load(cache / f"{key}.npz")
    per_pixel = {c: z[c.replace("-", "_")] for c in CRITERIA}
    return rec, per_pixel


def summary_row(rec: dict, choice: tuple) -> dict:
    grid = [tuple(p) for p in rec["grid"]]
    err = dict(zip(grid, rec["error"]))
    img = dict(zip(grid, rec["image_error"]))
    best = min(err, key=err.get)
    return {
        "choice": choice,
        "error": err[choice],
        "best": best,
        "error_best": err[best],
        "error_default": err[DEFAULT],
        "ratio_best": err[choice] / err[best],
        "ratio_default": err[choice] / err[DEFAULT],
        "image_ratio_default": img[choice] / img[DEFAULT],
        "worst_gap": max(rec["worst_gap"]),
    }


def _label(rec: dict) -> tuple[str, str]:
    """Scene name and ``projector / camera rows`` of a condition."""
    name = rec["scene"]
    parts = name.split("_")
    geo = f"{rec['projector_rows']}/{rec['shape'][0]}"
    base = "_".join(parts[:-2]) if len(parts) > 2 and parts[-1].isdigit() and parts[-2].isdigit() else name
    return base, geo


def _fmt(pair) -> str:
    return f"{pair[0]:.3g} / {pair[1]:.3g}"


def report(cache: Path, *, product: str = "gcv", figure: Path | None = None) -> None:
    """The docs' tables (markdown, stdout) and the curves' figure, from the cache."""
    keys = sorted(p.stem for p in cache.glob("*.json") if "__product_" not in p.stem)
    recs = [json.loads((cache / f"{k}.json").read_text()) for k in keys]
    order = sorted(
        range(len(recs)), key=lambda i: (_label(recs[i])[1] != "720/32", _label(recs[i]), recs[i]["ambient_e_per_us"])
    )
    print(f"\n### The automatic weights ({product}) against the truth\n")
    print(
        "| scene | P / H rows | ambient | chosen alpha / beta | error at chosen | best alpha / beta (truth) | error at best | "
        "error at 0.01 / 0.01 | chosen / best | chosen / 0.01-0.01 | uncaptured images, chosen / 0.01-0.01 | worst gap |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    worst = {"best": 0.0, "default": 0.0}
    for i in order:
        rec = recs[i]
        path = cache / f"{rec['condition']}__product_{product}.json"
        if not path.exists():
            continue
        pr_ = json.loads(path.read_text())
        s = summary_row(rec, DEFAULT)
        base, geo = _label(rec)
        img = dict(zip(map(tuple, rec["grid"]), rec["image_error"]))
        rb, rd = pr_["error"] / s["error_best"], pr_["error"] / s["error_default"]
        worst["best"], worst["default"] = max(worst["best"], rb), max(worst["default"], rd)
        edge = "" if not pr_["edge"] else " (edge: " + ", ".join(f"{k} {v}" for k, v in pr_["edge"].items()) + ")"
        gap = max(max(rec["worst_gap"]), pr_["worst_gap"])
        print(
            f"| {base} | {geo} | {'on' if rec['ambient_e_per_us'] else 'off'} | {_fmt(pr_['choice'])}{edge} | "
            f"{pr_['error']:.3f} | {_fmt(s['best'])} | {s['error_best']:.3f} | {s['error_default']:.3f} | "
            f"**{rb:.2f}** | **{rd:.3f}** | {pr_['image_error'] / img[DEFAULT]:.2f} | {gap:.1e} |"
        )
    print(f"\nworst chosen / best {worst['best']:.3f}, worst chosen / 0.01-0.01 {worst['default']:.3f}")
    print("\n### Every criterion's grid choice (chosen / best, chosen / 0.01-0.01)\n")
    crits = [c for c in CRITERIA if c != "null"]
    print("| scene | P / H | ambient | " + " | ".join(crits) + " |")
    print("|---|---|---|" + "---|" * len(crits))
    summary = {c: [] for c in crits}
    for i in order:
        rec = recs[i]
        _, pp = load(cache, rec["condition"])
        grid = [tuple(p) for p in rec["grid"]]
        cells = []
        for c in crits:
            s = summary_row(rec, grid[int(np.argmin(pp[c].mean(axis=1)))])
            summary[c].append((s["ratio_best"], s["ratio_default"]))
            miss = "" if s["ratio_best"] <= 1.3 and s["ratio_default"] <= 1.05 else " ✗"
            cells.append(f"{s['ratio_best']:.2f} / {s['ratio_default']:.2f}{miss}")
        base, geo = _label(rec)
        print(f"| {base} | {geo} | {'on' if rec['ambient_e_per_us'] else 'off'} | " + " | ".join(cells) + " |")
    for c in crits:
        w = np.array(summary[c])
        fails = int(((w[:, 0] > 1.3) | (w[:, 1] > 1.05)).sum())
        print(f"{c}: worst {w[:, 0].max():.3f} / {w[:, 1].max():.3f}, misses {fails} of {len(w)}")
    if figure is not None:
        _figure(cache, recs, order, product, figure)


def _figure(cache, recs, order, product, path) -> None:
    """Per condition with ambient light: the criterion and the truth error along alpha at the chosen beta."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sel = [
        i
        for i in order
        if recs[i]["ambient_e_per_us"] > 0 and (cache / f"{recs[i]['condition']}__product_{product}.json").exists()
    ]
    cols = 5
    rows = -(-len(sel) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.5 * rows), squeeze=False)
    for ax, i in zip(axes.ravel(), sel):
        rec = recs[i]
        pr_ = json.loads((cache / f"{rec['condition']}__product_{product}.json").read_text())
        _, pp = load(cache, rec["condition"])
        grid = np.array(rec["grid"])
        b = min(BETAS, key=lambda v: abs(np.log(v / pr_["choice"][1])))
        on = np.isclose(grid[:, 1], b)
        a = grid[on, 0]
        crit = pp[product if product in pp else "gcv"][on].mean(axis=1)
        err = np.array(rec["error"])[on]
        ax.plot(a, crit / crit.min(), "o-", ms=3, color="tab:blue", label=f"{product} / min")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax2 = ax.twinx()
        ax2.plot(a, err / np.min(rec["error"]), "s--", ms=3, color="tab:red", label="T error / grid best")
        ax2.axhline(1.3, color="tab:red", lw=0.6, alpha=0.5)
        ax.axvline(pr_["choice"][0], color="tab:blue", lw=1.2, alpha=0.6)
        ax.axvline(0.01, color="0.5", lw=0.8, ls=":")
        base, geo = _label(rec)
        ax.set_title(f"{base} {geo}, beta {b:.2g}", fontsize=8)
        ax.tick_params(labelsize=7)
        ax2.tick_params(labelsize=7, colors="tab:red")
    for ax in axes.ravel()[len(sel) :]:
        ax.axis("off")
    handles = [
        plt.Line2D([], [], color="tab:blue", marker="o", label=f"criterion ({product}) / its minimum"),
        plt.Line2D([], [], color="tab:red", marker="s", ls="--", label="T error / the grid's best (right axis)"),
        plt.Line2D([], [], color="tab:blue", lw=1.2, alpha=0.6, label="chosen alpha"),
        plt.Line2D([], [], color="0.5", ls=":", label="alpha = 0.01"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=8)
    fig.suptitle("The criterion along alpha (at the chosen beta) and the truth's error; ambient light on", fontsize=10)
    fig.tight_layout(rect=(0, 0.04, 1, 0.97))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    print(f"figure: {path}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--stores", nargs="*", default=[], type=Path)
    ap.add_argument("--builtin", nargs="*", default=[])
    ap.add_argument("--builtin-size", type=int, default=32)
    ap.add_argument("--ambient", nargs="+", type=float, default=[0.0, 0.5], help="camera ambient e-/us per condition")
    ap.add_argument("--cols", type=int, default=8)
    ap.add_argument("--problem", default="estimate", choices=["estimate", "none"])
    ap.add_argument("--product", nargs="*", default=[], help="also run choose_weights with these criteria")
    ap.add_argument("--no-grid", action="store_true", help="only the conditions whose grid is cached (with --product)")
    ap.add_argument("--report", action="store_true", help="print the tables of everything in the cache")
    ap.add_argument("--report-criterion", default="gcv", help="the product's criterion in the main table")
    ap.add_argument("--figure", type=Path, default=None, help="with --report: write the curves' figure here")
    args = ap.parse_args(argv)
    args.cache.mkdir(parents=True, exist_ok=True)
    from planeray.scenes import make_scene
    from planeray.scenes.store_scene import scene_from_transport_store

    jobs = [(p.stem, lambda p=p: scene_from_transport_store(p)) for p in args.stores]
    size = (args.builtin_size, args.builtin_size)
    jobs += [
        (f"{n}_{PAPER_PROJECTOR_ROWS}_{args.builtin_size}", lambda n=n: make_scene(n, size, projector_rows=720, seed=0))
        for n in args.builtin
    ]
    for name, build in jobs:
        scene = None
        for amb in args.ambient:
            key = f"{name}__amb{amb:g}__{args.problem}"
            if not (args.cache / f"{key}.json").exists():
                if args.no_grid:
                    continue
                scene = build() if scene is None else scene
                rec = run_condition(
                    name, scene, ambient_e_per_us=amb, cols_n=args.cols, problem_mode=args.problem, cache=args.cache
                )
                s = summary_row(rec, DEFAULT)
                print(
                    f"{key}: best {s['best']} err {s['error_best']:.4f}, 0.01/0.01 {s['error_default']:.4f}, worst gap "
                    f"{s['worst_gap']:.1e}, {rec['seconds_total']:.0f} s",
                    flush=True,
                )
            for crit in args.product:
                if not (args.cache / f"{key}__product_{crit}.json").exists():
                    scene = build() if scene is None else scene
                    r = run_product(
                        name,
                        scene,
                        ambient_e_per_us=amb,
                        cols_n=args.cols,
                        problem_mode=args.problem,
                        cache=args.cache,
                        criterion=crit,
                    )
                    print(
                        f"{key} [{crit}]: chose {r['choice']} err {r['error']:.4f} edge {r['edge']} {r['seconds']:.0f} s",
                        flush=True,
                    )
    if args.report:
        report(args.cache, product=args.report_criterion, figure=args.figure)


if __name__ == "__main__":
    main()
