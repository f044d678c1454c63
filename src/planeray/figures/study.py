"""Figures of the Sec. 5.2 demultiplexing study (Figs. 5, 6 and the alpha/beta grid).

Each function draws one result of :mod:`planeray.study` and returns the
:class:`~matplotlib.figure.Figure`.  The examples use the paper sweep's band
matrix and the diffusion dipole as the profile provider (fast).
"""

from __future__ import annotations

import numpy as np
from matplotlib.patches import Rectangle
from matplotlib.ticker import NullFormatter

from ._common import figure_for, finish, new_figure

__all__ = ["plot_reconstruction", "plot_noise_sweep", "plot_parameter_sweeps", "plot_regularization"]

METHODS = ("pinv", "nnls", "full")
LABELS = {"pinv": "pseudo-inverse", "nnls": "NNLS", "full": "ours (NNLS + smooth + L1)"}
COLORS = {"pinv": "tab:red", "nnls": "tab:orange", "full": "tab:blue"}
SYMBOLS = {"sigma_s": r"$\sigma_s$ (mm$^{-1}$)", "sigma_a": r"$\sigma_a$ (mm$^{-1}$)", "g": "g"}


def plot_reconstruction(ex: dict, *, noise, out=None):
    """Fig. 5a/b: reconstructions vs truth, full support and close-up of the peak.

    Parameters
    ----------
    ex : dict
        From :func:`planeray.study.reconstruction_example`.
    noise : float
        The noise level of ``ex`` (for the title).
    out : str or os.PathLike, optional
        Also write the figure to this PNG (100 dpi).

    Returns
    -------
    matplotlib.figure.Figure
        Two Axes: the whole support and a close-up of the peak.

    Examples
    --------
    >>> from planeray.figures.study import plot_reconstruction
    >>> from planeray import study
    >>> setup = study.study_setup()
    >>> provider = study.dipole_provider(setup.offsets)
    >>> ex = study.reconstruction_example(setup, provider, noise=0.05)
    >>> fig = plot_reconstruction(ex, noise=0.05)
    >>> type(fig).__name__, len(fig.axes)
    ('Figure', 2)
    """
    u = ex["offsets"]
    fig = new_figure((12, 4.2))
    axes = fig.subplots(1, 2)
    for ax, lim in zip(axes, (None, 25)):
        ax.plot(u, ex["truth"], "k-", lw=2.2, label="truth")
        for m in METHODS:
            ax.plot(u, ex[m], color=COLORS[m], lw=1.1, label=f"{LABELS[m]} (MSE {ex['mse'][m]:.2e})")
        ax.axhline(0, color="0.6", lw=0.6)
        ax.set_xlabel("offset u (projector rows)")
        ax.set_ylabel("T(u)")
        if lim is not None:
            ax.set_xlim(-lim, lim)
            top = max(ex["truth"].max(), max(ex[m][np.abs(u) <= lim].max() for m in METHODS))
            bot = min(0.0, min(ex[m][np.abs(u) <= lim].min() for m in METHODS))
            ax.set_ylim(bot - 0.05 * top, 1.1 * top)
            ax.set_title("(b) close-up of the peak")
        else:
            ax.set_title(f"(a) reconstructions, noise eta = {noise}")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    return finish(fig, out)


def _errorbars(ax, x, mse):
    for m in METHODS:
        v = mse[m]
        mean = v.mean(axis=1)
        err = v.std(axis=1, ddof=1) if v.shape[1] > 1 else np.zeros_like(mean)
        ax.errorbar(x, mean, yerr=err, color=COLORS[m], marker="o", ms=3.5, capsize=2.5, label=LABELS[m])


def plot_noise_sweep(ns: dict, *, out=None, ax=None):
    """Fig. 5c: MSE vs noise level, log-log, mean +- std over seeds.

    Parameters
    ----------
    ns : dict
        From :func:`planeray.study.noise_sweep`.
    out : str or os.PathLike, optional
        Also write the figure to this PNG (100 dpi).
    ax : matplotlib.axes.Axes, optional
        Draw into this Axes instead of a new figure.

    Returns
    -------
    matplotlib.figure.Figure
        The new figure (one Axes), or ``ax.figure``.

    Examples
    --------
    >>> from planeray.figures.study import plot_noise_sweep
    >>> from planeray import study
    >>> setup = study.study_setup()
    >>> provider = study.dipole_provider(setup.offsets)
    >>> ns = study.noise_sweep(setup, provider, [0.01, 0.1], seeds=2)
    >>> fig = plot_noise_sweep(ns)
    >>> type(fig).__name__, len(fig.axes)
    ('Figure', 1)
    >>> from matplotlib.figure import Figure
    >>> ax = Figure().subplots()
    >>> plot_noise_sweep(ns, ax=ax) is ax.figure
    True
    """
    fig, ax, own = figure_for(ax, (6, 4.2))
    _errorbars(ax, ns["noise"], ns["mse"])
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(r"noise level $\eta$ (std, images in [0, 1])")
    ax.set_ylabel("MSE of T")
    ax.set_title("(c) MSE vs noise (mean +- std over seeds)")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    if own:  # a caller's figure keeps its own layout
        fig.tight_layout()
    return finish(fig, out)


def plot_parameter_sweeps(sweeps: dict, *, noise, out=None):
    """Fig. 6a/b/c: MSE vs sigma_s, sigma_a and g.

    Parameters
    ----------
    sweeps : dict
        ``{"sigma_s": ..., "sigma_a": ..., "g": ...}``, each from
        :func:`planeray.study.parameter_sweep`.
    noise : float
        The noise level of the sweeps (for the titles).
    out : str or os.PathLike, optional
        Also write the figure to this PNG (100 dpi).

    Returns
    -------
    matplotlib.figure.Figure
        Three Axes, one per parameter.

    Examples
    --------
    >>> from planeray.figures.study import plot_parameter_sweeps
    >>> from planeray import study
    >>> setup = study.study_setup()
    >>> provider = study.dipole_provider(setup.offsets)
    >>> grid = {"sigma_s": [0.5, 2.0], "sigma_a": [0.0, 0.1], "g": [0.0, 0.9]}
    >>> sweeps = {
    ...     name: study.parameter_sweep(setup, provider, name, values, seeds=1, noise=0.05)
    ...     for name, values in grid.items()
    ... }
    >>> fig = plot_parameter_sweeps(sweeps, noise=0.05)
    >>> type(fig).__name__, len(fig.axes)
    ('Figure', 3)
    """
    fig = new_figure((16, 4.2))
    axes = fig.subplots(1, 3)
    for ax, tag, name in zip(axes, "abc", ("sigma_s", "sigma_a", "g")):
        ps = sweeps[name]
        _errorbars(ax, ps["values"], ps["mse"])
        ax.set_yscale("log")
        if name == "sigma_s":
            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(NullFormatter())
        elif name == "sigma_a":
            ax.set_xscale("symlog", linthresh=0.002)
            ax.set_xlim(left=0.0)
        ax.set_xlabel(SYMBOLS[name])
        ax.set_ylabel("MSE of T")
        ax.set_title(f"({tag}) MSE vs {name}, eta = {noise}")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    return finish(fig, out)


def _ink(im, value) -> str:
    """Black or white, whichever contrasts more with the cell of ``im`` showing ``value``.

    The cell's relative luminance ``L`` (WCAG, linearized sRGB): black text has contrast
    ``(L + 0.05) / 0.05``, white ``1.05 / (L + 0.05)``; they are equal at ``L = 0.179``, and
    the better of the two is at least 4.58 on any colour.
    """
    c = np.asarray(im.cmap(im.norm(value))[:3], float)
    c = np.where(c <= 0.03928, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return "k" if 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2] > 0.179 else "w"


def _outline():  # a dark edge keeps a white marker visible on light cells
    import matplotlib.patheffects as pe

    return [pe.Stroke(linewidth=3.5, foreground="k"), pe.Normal()]


def plot_regularization(rs: dict, *, noise, out=None):
    """Heatmaps of MSE and squared bias of the full method over (alpha, beta).

    Parameters
    ----------
    rs : dict
        From :func:`planeray.study.regularization_sweep`.
    noise : float
        The noise level of the sweep (for the titles).
    out : str or os.PathLike, optional
        Also write the figure to this PNG (100 dpi).

    Returns
    -------
    matplotlib.figure.Figure
        Four Axes: the MSE and squared-bias heatmaps and their colorbars.

    Examples
    --------
    >>> from planeray.figures.study import plot_regularization
    >>> from planeray import study
    >>> setup = study.study_setup()
    >>> provider = study.dipole_provider(setup.offsets)
    >>> rs = study.regularization_sweep(setup, provider, [1e-2, 1e-1], [1e-2, 1e-1], seeds=2, noise=0.05)
    >>> fig = plot_regularization(rs, noise=0.05)
    >>> type(fig).__name__, len(fig.axes)
    ('Figure', 4)
    """
    fig = new_figure((12, 4.8))
    axes = fig.subplots(1, 2)
    a, b = rs["alphas"], rs["betas"]
    i, j = np.unravel_index(np.argmin(rs["mse"]), rs["mse"].shape)
    for ax, key, title in zip(axes, ("mse", "bias2"), ("MSE", "squared bias")):
        im = ax.imshow(np.log10(rs[key]), origin="lower", cmap="viridis", aspect="auto")
        ax.set_xticks(range(len(b)), [f"{x:.0e}" for x in b], rotation=45, fontsize=7)
        ax.set_yticks(range(len(a)), [f"{x:.0e}" for x in a], fontsize=7)
        ax.set_xlabel(r"$\beta$ (L1)")
        ax.set_ylabel(r"$\alpha$ (smoothness)")
        for p in range(len(a)) if len(a) * len(b) <= 81 else ():
            for q in range(len(b)):
                ax.text(
                    q,
                    p,
                    f"{rs[key][p, q]:.1e}",
                    ha="center",
                    va="center",
                    fontsize=6.5,
                    color=_ink(im, np.log10(rs[key][p, q])),
                )
        ia, ib = int(np.argmin(np.abs(np.log(a / 0.01)))), int(np.argmin(np.abs(np.log(b / 0.01))))
        # the markers frame their cells and sit in a corner, so they never cover a cell's number
        ax.add_patch(Rectangle((ib - 0.5, ia - 0.5), 1, 1, fill=False, ec="r", lw=2, label="paper 0.01 / 0.01"))
        ax.plot(j - 0.3, i + 0.28, "x", color="w", ms=7, mew=2, label="min MSE", path_effects=_outline())
        ax.set_title(
            f"log10 {title} of the full method, eta = {noise}\nred frame: the paper's 0.01 / 0.01, white x: lowest MSE",
            fontsize=10,
        )
        fig.colorbar(im, ax=ax)
    fig.tight_layout()
    return finish(fig, out)
