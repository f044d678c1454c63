"""The Sec. 5.2 demultiplexing study end to end (Figs. 5, 6): numbers, CSVs and PNGs in one folder.

The computations are in :mod:`planeray.study`, the drawings in :mod:`planeray.figures.study`.
:func:`run_study` reports progress as ``progress(n)`` units of work (one per
swept point, per ``alpha x beta`` cell and per figure drawn; :func:`study_work`
gives their total) and :func:`study_report` formats its numbers as text lines.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from .._validate import check_integer, check_nonnegative
from ..figures import study as figs
from ..io import atomic_file
from ..io.atomic import check_replaceable, storage_error
from ..io.marks import MARK_KEY, mark_text
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

__all__ = ["run_study", "study_work", "study_report", "study_outputs"]

#: The PNGs :func:`run_study` draws (one unit of work each).
_N_FIGURES = 4
#: The parameter sweeps of Fig. 6: (panel, parameter).
_PARAMETERS = (("a", "sigma_s"), ("b", "sigma_a"), ("c", "g"))


def study_outputs() -> list[tuple[str, str]]:
    """``(file name, kind)`` of every file :func:`run_study` writes into its folder.

    Examples
    --------
    >>> [name for name, _ in study_outputs()][:3]
    ['fig5_reconstruction.csv', 'fig5_reconstruction.png', 'fig5c_mse_vs_noise.csv']
    """
    files = [("fig5_reconstruction.csv", "table"), ("fig5_reconstruction.png", "figure")]
    files += [("fig5c_mse_vs_noise.csv", "table"), ("fig5c_mse_vs_noise.png", "figure")]
    files += [(f"fig6{tag}_mse_vs_{name}.csv", "table") for tag, name in _PARAMETERS]
    files += [("fig6_mse_vs_params.png", "figure")]
    files += [("regularization_sweep.csv", "table"), ("regularization_sweep.png", "figure")]
    return files + [("study.json", "record")]


def study_work(*, quick: bool = False) -> int:
    """Units of work :func:`run_study` reports through ``progress``.

    The reconstruction example, each noise level, each value of the three
    parameter sweeps, each ``alpha x beta`` cell and each figure drawn.

    Examples
    --------
    >>> study_work(quick=True)  # 1 + 3 + (2 + 2 + 3) + 3 x 3 + 4
    24
    """
    G = grids(quick)
    return (
        1
        + len(G["noise"])
        + sum(len(G[name]) for _, name in _PARAMETERS)
        + len(G["alpha"]) * len(G["beta"])
        + _N_FIGURES
    )


def _write_csv(path: Path, header, rows) -> Path:
    """A CSV whose first line is planeray's mark (a ``#`` comment), then the header and the rows."""
    with atomic_file(path) as tmp:
        with open(tmp, "w", newline="") as f:
            f.write(f"# {MARK_KEY}: {mark_text('table')}\n")
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
    out_dir,
    provider: Provider | str | None = None,
    seeds: int = 5,
    quick: bool = False,
    noise: float = DEFAULT_NOISE,
    *,
    progress=None,
    overwrite: bool = False,
    auto: bool = False,
) -> dict:
    """Run the whole Sec. 5.2 study, write PNGs, CSVs and its numbers into ``out_dir``, return the numbers.

    Parameters
    ----------
    out_dir : path
        Folder for the files (created).
    provider : callable, {'mc', 'dipole'} or None
        A callable ``profile(sigma_s, sigma_a, g)`` over ``study_setup().offsets``,
        ``'mc'`` / ``None`` (Monte Carlo, :func:`planeray.study.mc_provider`) or
        ``'dipole'`` (:func:`planeray.study.dipole_provider`).
    seeds : int
        Noise realizations per point.
    quick : bool
        Reduced grids (:func:`planeray.study.grids`).
    noise : float
        Noise level ``eta`` of the parameter and regularization sweeps.
    progress : callable, optional
        Called as ``progress(n)`` with the units of work just done; they add up
        to :func:`study_work`.
    overwrite : bool
        Replace files a previous run wrote; a file planeray did not write is never
        replaced.  Every output is checked before any work.
    auto : bool
        Also the full method at weights chosen from each profile's observations by the
        automatic criterion (:func:`planeray.study.auto_weights`, what
        ``planeray demux --alpha auto --beta auto`` does), against the best fixed weights
        of a decade grid per profile (the parameter sweeps' ``auto`` and ``best_fixed``).

    Returns
    -------
    dict
        The numbers (also written as ``study.json``), with ``files``.

    Notes
    -----
    Files (:func:`study_outputs`): ``fig5_reconstruction.png/.csv``,
    ``fig5c_mse_vs_noise.png/.csv``, ``fig6_mse_vs_params.png``,
    ``fig6{a,b,c}_mse_vs_{sigma_s,sigma_a,g}.csv``, ``regularization_sweep.png/.csv``
    and ``study.json``; each carries planeray's mark (the CSVs as a first ``#`` line).
    """

    def done(n=1):
        if progress is not None:
            progress(n)

    check_integer(seeds, "seeds", minimum=1)
    check_nonnegative(noise, "noise")
    out = Path(out_dir)
    for name, kind in study_outputs():
        check_replaceable(out / name, overwrite=overwrite, kind=kind)
    setup = study_setup()
    provider = cached_provider(resolve_provider(provider, setup.offsets))
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise storage_error(exc, out) from None
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
    done()
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
    done()

    ns = noise_sweep(setup, provider, G["noise"], seeds, progress=progress)
    result["noise_sweep"] = {"noise": ns["noise"].tolist(), **_summary(ns["mse"])}
    result["files"].append(
        _write_csv(
            out / "fig5c_mse_vs_noise.csv", ["noise", "seed", *METHODS], _sweep_rows(ns["noise"], ns["mse"], seeds)
        )
    )
    png = out / "fig5c_mse_vs_noise.png"
    figs.plot_noise_sweep(ns, out=png)
    result["files"].append(png)
    done()

    sweeps = {}
    for tag, name in _PARAMETERS:
        ps = parameter_sweep(setup, provider, name, G[name], seeds, noise, progress=progress, auto=auto)
        sweeps[name] = ps
        result[f"{name}_sweep"] = {
            "values": ps["values"].tolist(),
            "mean_abs_offset": ps["mean_abs_offset"].tolist(),
            **_summary(ps["mse"]),
        }
        if auto:
            result[f"{name}_sweep"]["auto"] = {
                "alpha": ps["auto"]["alpha"].tolist(),
                "beta": ps["auto"]["beta"].tolist(),
                "mean": ps["auto"]["mse"].mean(axis=1).tolist(),
            }
            result[f"{name}_sweep"]["best_fixed"] = {k: v.tolist() for k, v in ps["best_fixed"].items()}
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
    done()

    rs = regularization_sweep(setup, provider, G["alpha"], G["beta"], seeds, noise, progress=progress)
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
    done()
    path = out / "study.json"
    result["files"] = [str(f) for f in [*result["files"], path]]
    with atomic_file(path) as tmp:
        tmp.write_text(json.dumps({MARK_KEY: mark_text("record"), **result}, indent=2))
    return result


def _sci(v: float) -> str:
    return f"{v:.1e}"


def _row(cells, width=11) -> str:
    return "  " + "".join(f"{c:<{width}}" for c in cells).rstrip()


def study_report(numbers: dict) -> list[str]:
    """Text lines of the study's findings (what the README quotes) from :func:`run_study`'s numbers.

    MSE are means over the noise seeds.
    """
    lines = [
        f"profiles: {numbers['provider']}; {numbers['seeds']} noise seeds per point; "
        f"{numbers['n_images']} images, {numbers['n_offsets']} offsets",
        "Fig. 5a/b, eta {:g}: minimum of the reconstruction: {}; MSE: {}".format(
            numbers["noise"],
            ", ".join(f"{m} {v:.3g}" for m, v in numbers["example_min"].items()),
            ", ".join(f"{m} {_sci(v)}" for m, v in numbers["example_mse"].items()),
        ),
    ]
    ns = numbers["noise_sweep"]
    lines.append("Fig. 5c: MSE vs noise eta")
    lines.append(_row(["eta", *METHODS, "best"]))
    for i, eta in enumerate(ns["noise"]):
        mse = [ns[m]["mean"][i] for m in METHODS]
        lines.append(_row([f"{eta:.2g}", *(_sci(v) for v in mse), METHODS[int(np.argmin(mse))]]))
    for tag, name in _PARAMETERS:
        ps = numbers[f"{name}_sweep"]
        lines.append(f"Fig. 6{tag}: MSE vs {name}, eta {numbers['noise']:g}")
        auto = ps.get("auto")
        extra = ["auto", "best fixed", "auto/best", "auto a/b"] if auto else []
        lines.append(_row([name, *METHODS, "pinv/full", "mean |u|", *extra]))
        for i, v in enumerate(ps["values"]):
            mse = [ps[m]["mean"][i] for m in METHODS]
            ratio = ps["pinv"]["mean"][i] / ps["full"]["mean"][i]
            cells = [f"{v:.3g}", *(_sci(x) for x in mse), f"{ratio:.2g}", f"{ps['mean_abs_offset'][i]:.3g}"]
            if auto:
                best = ps["best_fixed"]["mse"][i]
                cells += [
                    _sci(auto["mean"][i]),
                    _sci(best),
                    f"{auto['mean'][i] / best:.2f}",
                    f"{auto['alpha'][i]:.2g}/{auto['beta'][i]:.2g}",
                ]
            lines.append(_row(cells))
    reg = numbers["regularization"]
    paper, best = reg["paper"], reg["best"]
    lines.append(
        f"regularization, eta {numbers['noise']:g}: alpha {paper['alpha']:.3g}, beta {paper['beta']:.3g}: "
        f"MSE {_sci(paper['mse'])}; best alpha {best['alpha']:.3g}, beta {best['beta']:.3g}: "
        f"MSE {_sci(best['mse'])} ({paper['mse'] / best['mse']:.3g}x lower)"
    )
    return lines
