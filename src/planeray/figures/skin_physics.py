"""Figures of the skin scene's physics: the fast vein model against brute-force Monte Carlo."""

from __future__ import annotations

import numpy as np

from ._common import finish, new_figure

__all__ = ["vein_validation_figure"]


def _label(r):
    return f"{r['angle_deg']:.0f} deg, top {r['depth_mm']:g} mm, D {r['diameter_mm']:g} mm, rho {r['rho_rows']:+.0f}"


def vein_validation_figure(rows, *, out=None):
    """Vein contrast, fast model against brute force (left) and the kernel ratios over offsets (right).

    Parameters
    ----------
    rows : list of dict
        :func:`planeray.experiments.skin_physics.vein_validation` output.
    out : path, optional
        Also write the PNG.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> row = dict(
    ...     angle_deg=0.0,
    ...     depth_mm=2.0,
    ...     diameter_mm=2.0,
    ...     rho_rows=0.0,
    ...     short_brute=0.3,
    ...     short_fast=0.31,
    ...     short_brute_stderr=0.01,
    ...     epipolar_brute=0.05,
    ...     epipolar_fast=0.05,
    ...     offsets_rows=[0, 1, 2],
    ...     ratio_brute=[0.9, 0.8, 0.7],
    ...     ratio_fast=[0.9, 0.8, 0.72],
    ... )
    >>> len(vein_validation_figure([row]).axes)
    2
    """
    fig = new_figure((13, 5.2))
    ax, ax2 = fig.subplots(1, 2)
    sb = np.array([r["short_brute"] for r in rows])
    sf = np.array([r["short_fast"] for r in rows])
    se = np.array([r["short_brute_stderr"] for r in rows])
    eb = np.array([r["epipolar_brute"] for r in rows])
    ef = np.array([r["epipolar_fast"] for r in rows])
    colors = [f"C{i % 10}" for i in range(len(rows))]
    ax.errorbar(sb, sf, xerr=2 * se, fmt="none", ecolor="0.5", lw=0.8)
    ax.scatter(sb, sf, c=colors, s=40, label="short-range band (500 us / 200 us)", zorder=3)
    ax.scatter(eb, ef, edgecolors=colors, marker="s", s=25, facecolors="none", label="epipolar band (|u| <= 2)")
    top = max(sb.max(), sf.max(), ef.max(), eb.max(), 0.05) * 1.1
    ax.plot([0, top], [0, top], "k-", lw=0.8)
    ax.fill_between([0, top], [0, 0.9 * top], [0, 1.1 * top], color="0.9", label="+-10 %")
    ax.set(xlim=(0, top), ylim=(0, top), xlabel="vein contrast, brute-force Monte Carlo", ylabel="fast model")
    ax.set_title("vein contrast 1 - K_vein / K_skin")
    ax.legend(loc="upper left", fontsize=8)
    for r, c in zip(rows, colors):
        u = np.asarray(r["offsets_rows"])
        ax2.plot(u, r["ratio_brute"], color=c, lw=0.7, alpha=0.6)
        ax2.plot(u, r["ratio_fast"], color=c, lw=1.6, label=_label(r))
    ax2.axvspan(21.6, 32.4, color="0.9", zorder=0)
    ax2.set(xlim=(-45, 45), ylim=(0, 1.1), xlabel="offset u (projector rows)", ylabel="K_vein / K_skin")
    ax2.set_title("kernel ratio: fast (thick) vs brute force (thin); grey: 400-600 us band")
    ax2.legend(fontsize=6, loc="lower left")
    fig.tight_layout()
    return finish(fig, out)
