"""T error against the number of images K: designed, uniformly subsampled and random sweeps.

For every scene (built-in by name, or a transport store such as a ``planeray render`` of the
Mitsuba files in ``tools/sweep_design_scenes/``) and every K of ``--ks``:

* **designed**: ``planeray.design.design_sweep`` with the default prior (every built-in scene,
  textures of seed 0, a little of the smoothness prior) and the camera at the frames per image used;
  ``--loo`` also designs, for each built-in scene, without that scene in the prior (leave one out);
* **uniform**: every subsample of the paper's 17 x 5 grid that takes every n-th delay (any start)
  at a subset of its exposures with exactly K images (those whose bands leave an offset unlit are
  skipped); the best one *for each scene* (an oracle: it knows the truth);
* **random**: K of the paper's 85 images drawn at random (seeded; 3 draws, their mean);
* **paper**: the paper's 85 images.

Each sweep is simulated on the scene (the simulated Episcan's default camera; ``--ambient`` sets its
room light; textures of seed 1, so the built-in scenes are not the prior's pixels) at **equal frames
per image** (8) and at **equal total capture time** (``floor(8 x 85 / K)`` frames per image, never
more frames than the paper's 680), demultiplexed with ``planeray demux``'s defaults (the paper's
problem at alpha = beta = 0.01) on every ``128 / --cols``-th column, and held against ``signal_scale``
times the scene's transport: the relative error ``||T - T_true|| / ||T_true||`` over all offsets
(the estimate is 0 beyond its support), and the same over ``|u| > 8`` rows only (indirect light).

``--methods`` adds, at K = 24, the design choices measured against each other: greedy selection
alone, greedy + exchanges (the default), the Bayesian A- and D-optimal criteria, coarser and finer
candidate grids, and Joshi & Boyd's convex relaxation of the D-optimal design (CVXPY, SCS, in the
prior's leading 20 directions on a coarser grid, rounded to the K largest weights).

Results are cached (``--cache``, one JSON of results and the designs' sweep files), so an interrupted
run continues.  Run (nice, ~1-2 h on the shared 2-core machine)::

    nice -n 10 .venv/bin/python tools/sweep_design_study.py --cache /work/cache-sweep-design/study \\
        --store shelf_candle.zarr milk_tiles_mirror.zarr --loo --methods \\
        --json docs/_static/sweep_design_study.json --figure docs/_static/sweep_design_study.png

with the stores from ``planeray render tools/sweep_design_scenes/NAME.xml --out NAME.zarr --rows 720
--size 128 128 --spp 1024``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from demux_auto_table import columns  # the stack restricted to some columns (tools/ is on the path)

from planeray.acquire import simulate_stack
from planeray.camera import CameraModel
from planeray.demux import demultiplex
from planeray.design import DesignCamera, candidate_settings, design_sweep, expected_error, transport_prior
from planeray.io import read_sweep, write_sweep
from planeray.scenes import list_scenes, make_scene
from planeray.stack import Stack
from planeray.timing import PAPER_PROJECTOR_ROWS, Sweep, paper_sweep

PAPER_FRAMES = 8
PAPER_IMAGES = 85
INDIRECT_ROWS = 8
EVAL_SEED = 1  # the scenes' textures (the prior's are seed 0)


def equal_time_frames(k: int) -> int:
    return max(PAPER_FRAMES, (PAPER_FRAMES * PAPER_IMAGES) // k)


def t_error(scene, sweep: Sweep, camera: CameraModel, cols, seed: int = 0) -> dict:
    """Relative T error (all offsets; |u| > 8 rows) of the paper's problem at 0.01 / 0.01."""
    from planeray.errors import InputError

    stack = columns(simulate_stack(scene, sweep, camera=camera, seed=seed), cols)
    try:
        res = demultiplex(stack)
    except InputError as exc:  # a sweep that leaves an offset unseen (a rounded relaxation may)
        return {"error": float("nan"), "indirect_error": float("nan"), "used_images": 0, "refused": str(exc)}
    tr = scene.transport
    est_u = res.transport.offsets_rows
    lo, hi = min(est_u[0], tr.offsets_rows[0]), max(est_u[-1], tr.offsets_rows[-1])
    H = stack.shape[0]
    truth = np.zeros((H, len(cols), hi - lo + 1))
    est = np.zeros_like(truth)
    truth[:, :, tr.offsets_rows - lo] = np.asarray(tr.dense[:, cols], np.float64) * camera.signal_scale
    sp = tr.sparse
    if sp is not None and len(sp):
        colpos = {int(c): i for i, c in enumerate(cols)}
        keep = np.isin(sp.col, cols) & (sp.offset >= lo) & (sp.offset <= hi)
        for r, c, o, v in zip(sp.row[keep], sp.col[keep], sp.offset[keep], sp.value[keep]):
            truth[r, colpos[int(c)], int(o) - lo] += v * camera.signal_scale
    est[:, :, est_u - lo] = res.transport.dense
    far = np.abs(np.arange(lo, hi + 1)) > INDIRECT_ROWS
    return {
        "error": float(np.linalg.norm(est - truth) / np.linalg.norm(truth)),
        "indirect_error": float(np.linalg.norm((est - truth)[..., far]) / np.linalg.norm(truth[..., far])),
        "used_images": int((~sweep.excluded).sum()),
    }


def uniform_family(k: int) -> list[tuple[str, Sweep]]:
    """Every n-th delay of the paper's grid (any start) at a subset of its exposures, exactly k images."""
    paper = paper_sweep()
    delays = np.unique(paper.delay_us)
    exposures = np.unique(paper.exposure_us)
    out = []
    for n in range(1, len(delays)):
        for o in range(n):
            ds = delays[o::n]
            if k % len(ds) or k // len(ds) > len(exposures):
                continue
            for es in itertools.combinations(exposures, k // len(ds)):
                sweep = Sweep.grid(ds, es, name=f"uniform-{n}th+{o}x{'-'.join(f'{e:g}' for e in es)}")
                out.append((sweep.name, sweep))
    return out


def feasible(sweep: Sweep, projector_rows: int, size: int) -> bool:
    from planeray.demux import DemuxProblem
    from planeray.errors import InputError

    st = Stack(np.zeros((len(sweep), size, 1), np.float32), sweep.delay_us, sweep.exposure_us, 54_000.0,
               excluded=sweep.excluded, projector_rows=projector_rows)  # fmt: skip
    try:
        DemuxProblem.from_stack(st)
        return True
    except InputError:
        return False


def random_sweeps(k: int, draws: int, projector_rows: int, size: int) -> list[tuple[str, Sweep]]:
    paper = paper_sweep()
    out, seed = [], 0
    while len(out) < draws:
        rng = np.random.default_rng([k, seed])
        pick = np.sort(rng.choice(len(paper), size=k, replace=False))
        seed += 1
        sw = Sweep(paper.delay_us[pick], paper.exposure_us[pick], paper.excluded[pick], name=f"random-{k}-{seed}")
        if feasible(sw, projector_rows, size):
            out.append((sw.name, sw))
    return out


class Cache:
    def __init__(self, folder: Path):
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        self.path = folder / "results.json"
        self.data = json.loads(self.path.read_text()) if self.path.exists() else {}

    def get(self, key, compute):
        if key not in self.data:
            self.data[key] = compute()
            tmp = self.path.with_suffix(".tmp")
            tmp.write_text(json.dumps(self.data, indent=0))
            tmp.replace(self.path)
        return self.data[key]

    def design(self, name: str, make) -> Sweep:
        path = self.folder / f"{name}.json"
        if path.exists():
            return read_sweep(path)
        t0, c0 = time.perf_counter(), time.process_time()
        sweep = make()
        rec = dict(sweep.record or {})
        rec["study_cpu_s"] = time.process_time() - c0
        rec["study_wall_s"] = time.perf_counter() - t0
        sweep = replace(sweep, record=rec)
        write_sweep(sweep, path, overwrite=True)
        return sweep


def convex_design(k: int, prior, camera: DesignCamera, rank: int = 20) -> Sweep:
    """Joshi & Boyd's relaxation of the D-optimal design, in the prior's leading directions, rounded."""
    import cvxpy as cp

    from planeray.design import image_variance

    K = int(np.abs(prior.offsets_rows).max())
    row_us = 1e6 / camera.lines_per_second
    cands = candidate_settings(camera, support_rows=K, exposure_step_us=4 * row_us, delay_step_us=2 * row_us)
    var = image_variance(cands.rows, cands.exposure_us, prior, camera)
    lam, V = np.linalg.eigh(prior.second_moment)
    top = np.argsort(lam)[::-1][:rank]
    At = (cands.rows @ (V[:, top] * np.sqrt(lam[top]))) / np.sqrt(var)[:, None]
    outer = np.einsum("ci,cj->cij", At, At).reshape(len(cands), -1)
    w = cp.Variable(len(cands))
    M = cp.reshape(outer.T @ w, (rank, rank), order="C")
    cp.Problem(cp.Maximize(cp.log_det(M + np.eye(rank))), [cp.sum(w) == k, w >= 0, w <= 1]).solve(
        solver=cp.SCS, max_iters=5000
    )
    pick = np.argsort(np.asarray(w.value))[::-1][:k]
    d, e = cands.delay_us[pick], cands.exposure_us[pick]
    o = np.lexsort((d, e))
    return Sweep(d[o], e[o], np.zeros(k, bool), name=f"convex-d-{k}", record={"kind": "convex-d", "rank": rank})


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="*", default=list(list_scenes()))
    ap.add_argument(
        "--store", nargs="*", default=[], help="transport stores (planeray render of tools/sweep_design_scenes)"
    )
    ap.add_argument("--ks", nargs="*", type=int, default=[8, 12, 16, 24, 32, 40, 51, 68, 85])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--projector-rows", type=int, default=PAPER_PROJECTOR_ROWS)
    ap.add_argument("--cols", type=int, default=16, help="columns demultiplexed (evenly spaced)")
    ap.add_argument("--ambient", type=float, default=None, help="the camera's ambient e-/us (default: its 0.5)")
    ap.add_argument("--draws", type=int, default=3, help="random sweeps per K")
    ap.add_argument(
        "--loo", action="store_true", help="also K = 24 designs leaving each built-in scene out of the prior"
    )
    ap.add_argument("--methods", action="store_true", help="also the design choices compared at K = 24")
    ap.add_argument("--cache", type=Path, required=True)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--figure", type=Path, default=None)
    args = ap.parse_args(argv)
    base = CameraModel() if args.ambient is None else CameraModel(ambient_e_per_us=args.ambient)
    tag = f"amb{base.ambient_e_per_us:g}"
    cache = Cache(args.cache)
    shape = (args.size, args.size)
    cols = np.unique(np.round(np.linspace(0, args.size - 1, args.cols)).astype(int))
    scenes = [
        (n, lambda n=n: make_scene(n, shape, projector_rows=args.projector_rows, seed=EVAL_SEED)) for n in args.scenes
    ]
    for p in args.store:
        from planeray.scenes.store_scene import scene_from_transport_store

        scenes.append((Path(p).stem, lambda p=p: scene_from_transport_store(p)))
    priors = {}

    def prior_for(exclude=None):
        key = exclude or "all"
        if key not in priors:
            names = [n for n in list_scenes() if n != exclude]
            priors[key] = transport_prior(names, shape=shape, projector_rows=args.projector_rows, seed=0,
                                          signal_scale=base.signal_scale)  # fmt: skip
        return priors[key]

    def designed(k, frames, *, exclude=None, label="design", **kw):
        cam = DesignCamera(model=replace(base, frames_averaged=frames))
        name = f"{label}-{tag}-k{k}-f{frames}" + (f"-no-{exclude}" if exclude else "")

        def make():
            if label == "convex":
                return convex_design(k, prior_for(exclude), cam)
            return design_sweep(k, prior=prior_for(exclude), camera=cam, **kw).sweep

        return cache.design(name, make)

    sweeps: dict[tuple, Sweep] = {}  # (family, K, frames, name) -> sweep
    for k in args.ks:
        for frames in sorted({PAPER_FRAMES, equal_time_frames(k)}):
            if k == PAPER_IMAGES:
                sweeps[("paper", k, frames, "paper")] = paper_sweep()
                continue
            sweeps[("designed", k, frames, "design")] = designed(k, frames)
            for name, sw in uniform_family(k):
                if feasible(sw, args.projector_rows, args.size):
                    sweeps[("uniform", k, frames, name)] = sw
            for name, sw in random_sweeps(k, args.draws, args.projector_rows, args.size):
                sweeps[("random", k, frames, name)] = sw
    if PAPER_IMAGES not in args.ks:
        sweeps[("paper", PAPER_IMAGES, PAPER_FRAMES, "paper")] = paper_sweep()
    loo = {}
    if args.loo:
        for n in list_scenes():
            for frames in (PAPER_FRAMES, equal_time_frames(24)):
                loo[(n, frames)] = designed(24, frames, exclude=n)
    methods = {}
    if args.methods:
        row_us = 1e6 / 54_000.0
        variants = {
            "greedy only": dict(max_passes=0),
            "greedy + exchanges (default)": {},
            "bayes-a": dict(criterion="bayes-a"),
            "bayes-d": dict(criterion="bayes-d"),
        }
        for label, kw in variants.items():
            methods[label] = designed(
                24, PAPER_FRAMES, label="m-" + label.split()[0] + ("x" if "exch" in label else ""), **kw
            )
        cam = DesignCamera(model=base)
        for label, (es, ds) in {"coarser grid (4 / 2 rows)": (4, 2), "coarser grid (2 / 1 rows)": (2, 1),
                                "finer grid (2 / 0.5 rows)": (2, 0.5)}.items():  # fmt: skip
            cands = candidate_settings(cam, exposure_step_us=es * row_us, delay_step_us=ds * row_us)
            methods[label] = designed(24, PAPER_FRAMES, label=f"m-grid{es}-{ds}", candidates=cands)
        methods["convex relaxation (D-optimal)"] = designed(24, PAPER_FRAMES, label="convex")
    rows = []
    for scene_name, build in scenes:
        scene = build()
        t0 = time.perf_counter()
        for (family, k, frames, name), sw in sweeps.items():
            key = f"{scene_name}|{tag}|{family}|{k}|{frames}|{name}"
            r = cache.get(
                key,
                lambda sw=sw, frames=frames, scene=scene: t_error(
                    scene, sw, replace(base, frames_averaged=frames), cols
                ),
            )
            rows.append({"scene": scene_name, "family": family, "k": k, "frames": frames, "name": name, **r})
        for (excluded, frames), sw in loo.items():
            key = f"{scene_name}|{tag}|loo|24|{frames}|no-{excluded}"
            r = cache.get(
                key,
                lambda sw=sw, frames=frames, scene=scene: t_error(
                    scene, sw, replace(base, frames_averaged=frames), cols
                ),
            )
            rows.append(
                {"scene": scene_name, "family": "loo", "k": 24, "frames": frames, "name": f"no-{excluded}", **r}
            )
        for label, sw in methods.items():
            key = f"{scene_name}|{tag}|method|24|8|{label}"
            r = cache.get(key, lambda sw=sw, scene=scene: t_error(scene, sw, base, cols))
            rows.append({"scene": scene_name, "family": "method", "k": 24, "frames": 8, "name": label, **r})
        print(f"{scene_name}: {time.perf_counter() - t0:.0f} s", flush=True)
    summary = summarize(rows, args.ks, methods, loo, base, prior_for)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"rows": rows, "summary": summary}, indent=1))
    if args.figure:
        figure(rows, args.ks, args.figure)


def best(rows, **match):
    hits = [r for r in rows if all(r[k] == v for k, v in match.items()) and np.isfinite(r["error"])]
    return min(hits, key=lambda r: r["error"]) if hits else None


def mean(rows, **match):
    hits = [r["error"] for r in rows if all(r[k] == v for k, v in match.items())]
    return float(np.mean(hits)) if hits else float("nan")


def summarize(rows, ks, methods, loo, base, prior_for) -> dict:
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    out = {"k24": {}, "curve": {}}
    print("\nK = 24 (relative T error; indirect |u| > 8 rows in brackets):")
    print(
        "| scene | paper 85 x 8 frames | designed 24 x 8 | / paper | best uniform 24 x 8 | designed 24 x 28 (equal time) "
        "| / paper | designed without this scene in the prior, x 8 / x 28 |"
    )
    print("|---|---|---|---|---|---|---|---|")
    et = equal_time_frames(24)
    for s in scenes:
        p = best(rows, scene=s, family="paper")
        d8 = best(rows, scene=s, family="designed", k=24, frames=PAPER_FRAMES)
        dt = best(rows, scene=s, family="designed", k=24, frames=et)
        u8 = best(rows, scene=s, family="uniform", k=24, frames=PAPER_FRAMES)
        l8 = best(rows, scene=s, family="loo", frames=PAPER_FRAMES, name=f"no-{s}")
        lt = best(rows, scene=s, family="loo", frames=et, name=f"no-{s}")
        loo_text = "" if l8 is None else f"{l8['error']:.3f} / {lt['error']:.3f}"
        out["k24"][s] = {"paper": p, "designed_8": d8, "designed_equal_time": dt, "best_uniform_8": u8,
                         "loo_8": l8, "loo_equal_time": lt}  # fmt: skip
        print(
            f"| {s} | {p['error']:.3f} ({p['indirect_error']:.3f}) | {d8['error']:.3f} ({d8['indirect_error']:.3f}) "
            f"| {d8['error'] / p['error']:.2f} | {u8['error']:.3f} ({u8['name']}) | {dt['error']:.3f} "
            f"({dt['indirect_error']:.3f}) | {dt['error'] / p['error']:.2f} | {loo_text} |"
        )
    for s in scenes:
        out["curve"][s] = {
            fam: {str(k): {str(f): (best(rows, scene=s, family=fam, k=k, frames=f) or {}).get("error")
                           for f in (PAPER_FRAMES, equal_time_frames(k))} for k in ks}
            for fam in ("designed", "uniform")
        }  # fmt: skip
        out["curve"][s]["random_mean"] = {str(k): {str(f): mean(rows, scene=s, family="random", k=k, frames=f)
                                                   for f in (PAPER_FRAMES, equal_time_frames(k))} for k in ks}  # fmt: skip
    if methods:
        print("\nDesign choices at K = 24, 8 frames (relative T error per scene; expected error of the criterion):")
        cam = DesignCamera(model=base)
        print("| method | " + " | ".join(scenes) + " | mean | expected (mse) | design CPU s |")
        print("|---|" + "---|" * (len(scenes) + 3))
        out["methods"] = {}
        for label, sw in methods.items():
            errs = [
                (best(rows, scene=s, family="method", name=label) or {"error": float("nan")})["error"] for s in scenes
            ]
            exp = expected_error(sw, prior=prior_for(), camera=cam)
            cpu = (sw.record or {}).get("study_cpu_s")
            out["methods"][label] = {"errors": errs, "expected": exp, "cpu_s": cpu}
            print(
                f"| {label} | "
                + " | ".join(f"{e:.3f}" for e in errs)
                + f" | {np.mean(errs):.3f} | {exp:.3f} | "
                + ("" if cpu is None else f"{cpu:.1f}")
                + " |"
            )
    return out


def figure(rows, ks, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    n = len(scenes)
    cols = min(n, 3)
    fig, axes = plt.subplots(-(-n // cols), cols, figsize=(4.2 * cols, 3.3 * -(-n // cols)), squeeze=False)
    for ax, s in zip(axes.ravel(), scenes):
        paper = best(rows, scene=s, family="paper")
        for fam, color in (("designed", "C0"), ("uniform", "C1"), ("random", "C2")):
            for equal_time, style in ((False, "-"), (True, "--")):
                xs, ys = [], []
                for k in ks:
                    if k == PAPER_IMAGES:
                        continue
                    f = equal_time_frames(k) if equal_time else PAPER_FRAMES
                    if fam == "random":
                        y = mean(rows, scene=s, family=fam, k=k, frames=f)
                    else:
                        b = best(rows, scene=s, family=fam, k=k, frames=f)
                        y = None if b is None else b["error"]
                    if y is not None and np.isfinite(y):
                        xs.append(k)
                        ys.append(y)
                label = {"designed": "designed", "uniform": "best uniform", "random": "random (mean)"}[fam]
                ax.plot(xs, ys, style, color=color, marker="o", ms=3,
                        label=f"{label}, {'equal time' if equal_time else '8 frames'}")  # fmt: skip
        ax.axhline(paper["error"], color="k", lw=1, label="paper's 85 images")
        ax.set_title(s, fontsize=9)
        ax.set_xlabel("images K")
        ax.set_ylabel("relative T error")
        ax.set_xscale("log")
        ax.set_xticks(list(ks))
        ax.set_xticklabels([str(k) for k in ks], fontsize=7)
        ax.minorticks_off()
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    axes.ravel()[0].legend(fontsize=6)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)


if __name__ == "__main__":
    main()
