"""The Sec. 5.2 demultiplexing study end to end (Figs. 5, 6): numbers, CSVs and PNGs in one folder.

The computations are in :mod:`planeray.study`, the drawings in :mod:`planeray.figures.study`.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..figures import study as figs
from ..io import atomic_file
from ..study import (
    DEFAULT_NOISE,
    METHODS,
    Provider,
    cached_provider,
    grids,
    noise_sweep,
    parameter_sweep,
    reconstruction_example,
    regularization_sweep,
    resolve_provider,
    study_setup,
)

__all__ = ["run_study"]


def _write_csv(path: Path, header, rows) -> Path:
    with atomic_file(path) as tmp:
        with open(tmp, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(header)
            for r in rows:
                w.writerow([f"{v:.9g}" if isinstance(v, (float, np.floating)) else v for v in r])
    return path


def _sweep_rows(x, mse, seeds):
    for i, v in enumerate(x):
        for s in range(seeds):
            yield [float(v), s] + [float(mse[m][i, s]) for m in METHODS]


def _summary(mse):
    return {
        m: {
            "mean": v.mean(axis=1).tolist(),
            "std": v.std(axis=1, ddof=1).tolist() if v.shape[1] > 1 else [0.0] * len(v),
        }
        for m, v in mse.items()
    }


def run_study(
    out_dir, provider: Provider | str | None = None, seeds: int = 5, quick: bool = False, noise: float = DEFAULT_NOISE
) -> dict:
    """Run the whole Sec. 5.2 study, write PNGs and CSVs into ``out_dir``, return the numbers.

    ``provider``: a callable ``profile(sigma_s, sigma_a, g)`` over ``study_setup().offsets``,
    ``'mc'`` / ``None`` (Monte Carlo, :func:`mc_provider`) or ``'dipole'``
    (:func:`dipole_provider`).

    Files: ``fig5_reconstruction.png/.csv``, ``fig5c_mse_vs_noise.png/.csv``,
    ``fig6_mse_vs_params.png``, ``fig6{a,b,c}_mse_vs_{sigma_s,sigma_a,g}.csv``,
    ``regularization_sweep.png/.csv``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    setup = study_setup()
    provider = cached_provider(resolve_provider(provider, setup.offsets))
    G = grids(quick)
    result = {
        "provider": provider.name,
        "seeds": seeds,
        "noise": noise,
        "n_images": int(setup.A.shape[0]),
        "n_offsets": int(setup.offsets.size),
        "files": [],
    }

    ex = reconstruction_example(setup, provider, noise)
    result["example_mse"] = ex["mse"]
    result["example_min"] = {m: float(ex[m].min()) for m in METHODS}
    result["files"].append(
        _write_csv(
            out / "fig5_reconstruction.csv",
            ["offset_rows", "truth", *METHODS],
            ([int(u), ex["truth"][k]] + [ex[m][k] for m in METHODS] for k, u in enumerate(ex["offsets"])),
        )
    )
    png = out / "fig5_reconstruction.png"
    figs.plot_reconstruction(ex, noise=noise, out=png)
    result["files"].append(png)

    ns = noise_sweep(setup, provider, G["noise"], seeds)
    result["noise_sweep"] = {"noise": ns["noise"].tolist(), **_summary(ns["mse"])}
    result["files"].append(
        _write_csv(
            out / "fig5c_mse_vs_noise.csv", ["noise", "seed", *METHODS], _sweep_rows(ns["noise"], ns["mse"], seeds)
        )
    )
    png = out / "fig5c_mse_vs_noise.png"
    figs.plot_noise_sweep(ns, out=png)
    result["files"].append(png)

    sweeps = {}
    for tag, name in (("a", "sigma_s"), ("b", "sigma_a"), ("c", "g")):
        ps = parameter_sweep(setup, provider, name, G[name], seeds, noise)
        sweeps[name] = ps
        result[f"{name}_sweep"] = {
            "values": ps["values"].tolist(),
            "mean_abs_offset": ps["mean_abs_offset"].tolist(),
            **_summary(ps["mse"]),
        }
        result["files"].append(
            _write_csv(
                out / f"fig6{tag}_mse_vs_{name}.csv",
                [name, "seed", *METHODS],
                _sweep_rows(ps["values"], ps["mse"], seeds),
            )
        )
    png = out / "fig6_mse_vs_params.png"
    figs.plot_parameter_sweeps(sweeps, noise=noise, out=png)
    result["files"].append(png)

    rs = regularization_sweep(setup, provider, G["alpha"], G["beta"], seeds, noise)
    i, j = np.unravel_index(np.argmin(rs["mse"]), rs["mse"].shape)
    ia, ib = int(np.argmin(np.abs(np.log(rs["alphas"] / 0.01)))), int(np.argmin(np.abs(np.log(rs["betas"] / 0.01))))
    result["regularization"] = {
        "alphas": rs["alphas"].tolist(),
        "betas": rs["betas"].tolist(),
        "mse": rs["mse"].tolist(),
        "bias2": rs["bias2"].tolist(),
        "best": {"alpha": float(rs["alphas"][i]), "beta": float(rs["betas"][j]), "mse": float(rs["mse"][i, j])},
        "paper": {"alpha": float(rs["alphas"][ia]), "beta": float(rs["betas"][ib]), "mse": float(rs["mse"][ia, ib])},
    }
    result["files"].append(
        _write_csv(
            out / "regularization_sweep.csv",
            ["alpha", "beta", "mse", "bias2", "variance"],
            (
                [float(a), float(b), float(rs["mse"][p, q]), float(rs["bias2"][p, q]), float(rs["variance"][p, q])]
                for p, a in enumerate(rs["alphas"])
                for q, b in enumerate(rs["betas"])
            ),
        )
    )
    png = out / "regularization_sweep.png"
    figs.plot_regularization(rs, noise=noise, out=png)
    result["files"].append(png)
    result["files"] = [str(f) for f in result["files"]]
    return result
