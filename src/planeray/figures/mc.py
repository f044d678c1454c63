"""A Monte Carlo line profile against the diffusion dipole (log scale, error bars)."""

from __future__ import annotations

import numpy as np

from ..mc.diffusion import dipole_line_kernel, dipole_reflectance
from ..mc.engine import bin_measure
from ._common import finish, new_figure

__all__ = ["mc_profile_figure"]


def mc_profile_figure(prof, *, out=None, compare_dipole: bool = True):
    """Plot exitance (and normal-view radiance) of ``prof`` vs distance from the line or point.

    Parameters
    ----------
    prof : planeray.mc.MCProfile
        The profile to plot.
    out : str or os.PathLike, optional
        Also write the figure to this PNG (100 dpi).
    compare_dipole : bool
        Overlay :func:`planeray.kernels.dipole_line_kernel` of the same medium
        (``sigma_s' = sigma_s (1 - g)`` and ``n``; Jensen et al. 2001), the
        classical approximation the engine should approach far from the line.

    Returns
    -------
    matplotlib.figure.Figure
        Two Axes: exitance (left) and normal-view radiance (right), log scale.

    Examples
    --------
    >>> import planeray as pr
    >>> from planeray.figures.mc import mc_profile_figure
    >>> prof = pr.mc_line_profile(pr.Medium(sigma_s=1.0, sigma_a=0.1, g=0.5), n_photons=2000)
    >>> fig = mc_profile_figure(prof)
    >>> type(fig).__name__, len(fig.axes)
    ('Figure', 2)
    """
    p = prof.params
    point = p.get("source") == "point"
    k = np.asarray(prof.offsets_rows)
    x = k * prof.mm_per_row
    dx = prof.mm_per_row
    measure = bin_measure(k, dx, radial=point)  # exitance per mm (line) or per mm^2 (point)
    fig = new_figure((11, 4.2))
    ax, ax2 = fig.subplots(1, 2)
    ok = prof.values > 0
    ax.errorbar(
        x[ok],
        (prof.values / measure)[ok],
        yerr=(prof.stderr / measure)[ok],
        fmt=".",
        ms=3,
        lw=0.8,
        label="Monte Carlo exitance",
    )
    medium = prof.medium
    if compare_dipole and medium.semi_infinite:
        if point:
            ref = dipole_reflectance(medium, x)
        else:
            ref = dipole_line_kernel(medium, k, mm_per_row=dx) / dx
        ax.plot(x, ref, "-", lw=1, label="diffusion dipole (Jensen 2001)")
    ax.set_yscale("log")
    ax.set_xlabel("distance from the entry point r (mm)" if point else "distance from the lit line x (mm)")
    ax.set_ylabel("exiting power per mm^2 (per unit power)" if point else "exiting power per mm (per unit line power)")
    ax.set_title(f"sigma_s={medium.sigma_s:g}, sigma_a={medium.sigma_a:g} /mm, g={medium.g:g}, n={medium.n:g}")
    ax.legend(fontsize=8)
    okr = prof.radiance > 0
    ax2.errorbar(
        x[okr],
        prof.radiance[okr],
        yerr=prof.radiance_stderr[okr],
        fmt=".",
        ms=3,
        lw=0.8,
        color="C2",
        label="normal-view radiance",
    )
    ax2.set_yscale("log")
    ax2.set_xlabel("r (mm)" if point else "x (mm)")
    ax2.set_ylabel("radiance (mm^-2 sr^-1 per unit power)" if point else "radiance (mm^-1 sr^-1 per unit line power)")
    ax2.set_title(f"{prof.n_photons:.0e} photons; R={prof.total_reflectance:.4f}, truncated {prof.truncated:.3f}")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    return finish(fig, out)
