"""Figures of the Sec. 5.2 demultiplexing study (Figs. 5, 6 and the alpha/beta grid)."""

from __future__ import annotations

import numpy as np

from ._common import plt, save_png

__all__ = ["plot_reconstruction", "plot_noise_sweep", "plot_parameter_sweeps", "plot_regularization"]

METHODS = ("pinv", "nnls", "full")
LABELS = {"pinv": "pseudo-inverse", "nnls": "NNLS", "full": "ours (NNLS + smooth + L1)"}
COLORS = {"pinv": "tab:red", "nnls": "tab:orange", "full": "tab:blue"}
SYMBOLS = {"sigma_s": r"$\sigma_s$ (mm$^{-1}$)", "sigma_a": r"$\sigma_a$ (mm$^{-1}$)", "g": "g"}


def plot_reconstruction(ex: dict, path, noise):
    """Fig. 5a/b: reconstructions vs truth, full support and close-up of the peak."""
    u = ex["offsets"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
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
    return save_png(fig, path)


def _errorbars(ax, x, mse):
    for m in METHODS:
        v = mse[m]
        mean = v.mean(axis=1)
        err = v.std(axis=1, ddof=1) if v.shape[1] > 1 else np.zeros_like(mean)
        ax.errorbar(x, mean, yerr=err, color=COLORS[m], marker="o", ms=3.5, capsize=2.5, label=LABELS[m])


def plot_noise_sweep(ns: dict, path):
    """Fig. 5c: MSE vs noise level, log-log, mean +- std over seeds."""
    fig, ax = plt.subplots(figsize=(6, 4.2))
    _errorbars(ax, ns["noise"], ns["mse"])
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(r"noise level $\eta$ (std, images in [0, 1])")
    ax.set_ylabel("MSE of T")
    ax.set_title("(c) MSE vs noise (mean +- std over seeds)")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return save_png(fig, path)


def plot_parameter_sweeps(sweeps: dict, path, noise):
    """Fig. 6a/b/c: MSE vs sigma_s, sigma_a and g."""
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.2))
    for ax, tag, name in zip(axes, "abc", ("sigma_s", "sigma_a", "g")):
        ps = sweeps[name]
        _errorbars(ax, ps["values"], ps["mse"])
        ax.set_yscale("log")
        if name == "sigma_s":
            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(plt.NullFormatter())
        elif name == "sigma_a":
            ax.set_xscale("symlog", linthresh=0.002)
            ax.set_xlim(left=0.0)
        ax.set_xlabel(SYMBOLS[name])
        ax.set_ylabel("MSE of T")
        ax.set_title(f"({tag}) MSE vs {name}, eta = {noise}")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    return save_png(fig, path)


def plot_regularization(rs: dict, path, noise):
    """Heatmaps of MSE and squared bias of the full method over (alpha, beta)."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    a, b = rs["alphas"], rs["betas"]
    i, j = np.unravel_index(np.argmin(rs["mse"]), rs["mse"].shape)
    for ax, key, title in zip(axes, ("mse", "bias2"), ("MSE", "squared bias")):
        im = ax.imshow(np.log10(rs[key]), origin="lower", cmap="viridis", aspect="auto")
        ax.set_xticks(range(len(b)), [f"{x:.0e}" for x in b], rotation=45, fontsize=7)
        ax.set_yticks(range(len(a)), [f"{x:.0e}" for x in a], fontsize=7)
        ax.set_xlabel(r"$\beta$ (L1)")
        ax.set_ylabel(r"$\alpha$ (smoothness)")
        for p in (range(len(a)) if len(a) * len(b) <= 81 else ()):
            for q in range(len(b)):
                ax.text(q, p, f"{rs[key][p, q]:.1e}", ha="center", va="center", fontsize=5.5, color="w")
        ia, ib = int(np.argmin(np.abs(np.log(a / 0.01)))), int(np.argmin(np.abs(np.log(b / 0.01))))
        ax.plot(ib, ia, "s", mfc="none", mec="r", ms=16, mew=1.5, label="paper 0.01 / 0.01")
        ax.plot(j, i, "x", color="w", ms=12, mew=2, label="min MSE")
        ax.set_title(f"log10 {title} of the full method, eta = {noise}\n"
                     "red square: the paper's 0.01 / 0.01, white x: lowest MSE", fontsize=10)
        fig.colorbar(im, ax=ax)
    fig.tight_layout()
    return save_png(fig, path)
