"""A sweep drawn over the (delay, exposure) plane, with the bands it covers (``planeray sweep show``)."""

from __future__ import annotations

import numpy as np

from ..timing import PAPER_BOUNDARY_MARGIN_US, PAPER_LINES_PER_SECOND, Sweep, band_centre_rows, band_width_rows
from ._common import finish, new_figure

__all__ = ["sweep_figure"]


def sweep_figure(
    sweep: Sweep,
    *,
    compare: Sweep | None = None,
    lines_per_second: float = PAPER_LINES_PER_SECOND,
    boundary_margin_us: float = PAPER_BOUNDARY_MARGIN_US,
    out=None,
):
    """Draw a sweep: its settings over the (delay, exposure) plane and the band of every image.

    Left: each image a point at its (delay, exposure); shaded, the epipolar images' region
    ``|t_d| < t_e / 2`` and the boundary strips ``||t_d| - t_e/2| <= margin`` whose images the paper
    leaves out (excluded images drawn as crosses).  Right: each image's band over the offsets ``u``
    (projector rows, ``[I_d - I_w/2, I_d + I_w/2]``, Eq. 2), sorted by centre, and above it how many
    used images see each offset (the sweep's coverage; the epipolar cell no band edge splits is
    marked).  ``compare`` is drawn in grey underneath (e.g. the paper's sweep).

    Parameters
    ----------
    sweep : Sweep
    compare : Sweep, optional
    lines_per_second : float
        Scanline velocity (delays and exposures to rows, Eq. 2).
    boundary_margin_us : float
    out : path, optional
        Also write the PNG.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from planeray.timing import paper_sweep, quick_sweep
    >>> fig = sweep_figure(quick_sweep(), compare=paper_sweep())
    >>> len(fig.axes)
    3
    """
    fig = new_figure((12.0, 5.2))
    grid = fig.add_gridspec(2, 2, width_ratios=(1.0, 1.25), height_ratios=(1.0, 3.0), hspace=0.08, wspace=0.22)
    ax = fig.add_subplot(grid[:, 0])
    cover_ax = fig.add_subplot(grid[0, 1])
    band_ax = fig.add_subplot(grid[1, 1], sharex=cover_ax)
    sweeps = [s for s in (compare, sweep) if s is not None]
    e_all = np.concatenate([s.exposure_us for s in sweeps])
    d_all = np.concatenate([s.delay_us for s in sweeps])
    e_hi = float(e_all.max()) * 1.08
    e = np.linspace(0.0, e_hi, 200)
    d_hi = max(float(np.abs(d_all).max()) * 1.05, e_hi / 2)
    ax.fill_betweenx(e, -e / 2, e / 2, color="0.93", label="epipolar band |t_d| < t_e / 2")
    for sign in (-1, 1):
        ax.fill_betweenx(
            e,
            sign * e / 2 - boundary_margin_us,
            sign * e / 2 + boundary_margin_us,
            color="tab:red",
            alpha=0.15,
            lw=0,
            label=f"boundary images (±{boundary_margin_us:g} us)" if sign > 0 else None,
        )
    if compare is not None:
        ax.scatter(
            compare.delay_us, compare.exposure_us, s=22, c="0.6", marker="s", label=f"{compare.name} ({len(compare)})"
        )
    used = ~sweep.excluded
    ax.scatter(sweep.delay_us[used], sweep.exposure_us[used], s=30, c="tab:blue", zorder=3,
               label=f"{sweep.name} ({int(used.sum())} used)")  # fmt: skip
    if (~used).any():
        ax.scatter(sweep.delay_us[~used], sweep.exposure_us[~used], s=30, c="tab:red", marker="x", zorder=3,
                   label=f"excluded ({int((~used).sum())})")  # fmt: skip
    ax.set_xlim(-d_hi, d_hi)
    ax.set_ylim(0.0, e_hi)
    ax.set_xlabel("delay t_d (us)")
    ax.set_ylabel("exposure t_e (us)")
    ax.set_title("settings over the (delay, exposure) plane", fontsize=10)
    ax.legend(fontsize=7, loc="lower center")

    def bands(s):
        u = ~s.excluded
        c = band_centre_rows(s.delay_us[u], lines_per_second)
        w = band_width_rows(s.exposure_us[u], lines_per_second)
        return c - w / 2, c + w / 2

    reach = max(float(np.abs(np.concatenate(bands(s))).max()) for s in sweeps)
    U = int(np.ceil(reach)) + 2
    u = np.arange(-U, U + 1)
    for s, color, lw in ((compare, "0.7", 1.2), (sweep, "tab:blue", 2.0)):
        if s is None:
            continue
        lo, hi = bands(s)
        order = np.argsort(0.5 * (lo + hi) + 1e-3 * (hi - lo))
        y = np.linspace(0, 1, len(lo)) if len(lo) > 1 else np.array([0.5])
        for yy, a, b in zip(y, lo[order], hi[order]):
            band_ax.plot([a, b], [yy, yy], color=color, lw=lw, solid_capstyle="butt")
        count = ((u[None, :] >= lo[:, None]) & (u[None, :] <= hi[:, None])).sum(axis=0)
        cover_ax.step(u, count, where="mid", color=color, lw=1.2 if s is compare else 1.6, label=s.name)
    lo, hi = bands(sweep)
    edges = np.concatenate([lo, hi])
    cell = float(np.abs(edges).min()) if edges.size else 0.0
    for a in (band_ax, cover_ax):
        a.axvspan(-cell, cell, color="tab:orange", alpha=0.15, lw=0)
    cover_ax.text(0.01, 0.85, f"no edge within ±{cell:.2f} rows of u = 0", transform=cover_ax.transAxes, fontsize=7,
                  color="tab:orange")  # fmt: skip
    band_ax.set_yticks([])
    band_ax.set_xlabel("offset u = v - t (projector rows)")
    band_ax.set_ylabel("images (by band centre)")
    cover_ax.set_ylabel("images seeing u")
    cover_ax.set_title("bands over the offsets (Eq. 2) and their coverage", fontsize=10)
    cover_ax.legend(fontsize=7, loc="upper right")
    cover_ax.tick_params(labelbottom=False)
    band_ax.set_xlim(-U, U)
    return finish(fig, out, dpi=110)
