"""Fig. 9: a reference image with marked pixels and their area-normalized delay profiles."""

from __future__ import annotations

import numpy as np

from ..profiles import DelayProfiles
from ..stack import Stack
from ._common import display_scale, finish, new_figure

__all__ = ["delay_profiles_figure"]

_COLORS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive"]


def delay_profiles_figure(
    stack: Stack, profiles: DelayProfiles, *, out=None, exposure_us: float | None = None, names=None, continuous=None
):
    """Draw Fig. 9: the scene with the pixels marked, and each pixel's delay profile.

    Parameters
    ----------
    stack : Stack
        Used for the reference image (the epipolar image at the smallest exposure).
    profiles : DelayProfiles
        From :func:`planeray.profiles.measured_delay_profiles`.
    out : str or os.PathLike, optional
        Also write the figure to this PNG (110 dpi).
    exposure_us : float, optional
        Plot only this exposure (solid); by default all exposures are drawn,
        the smallest solid and the others fainter.
    names : list of str, optional
        A legend label per pixel.
    continuous : TransportDelayProfiles, optional
        Profiles of the same pixels from a transport
        (:func:`planeray.profiles.transport_delay_profiles`), drawn dashed.

    Returns
    -------
    matplotlib.figure.Figure
        Two Axes: the reference image with the pixels circled, and the profiles.

    See Also
    --------
    planeray.measured_delay_profiles : the profiles.

    Examples
    --------
    >>> import planeray as pr
    >>> from planeray.figures import delay_profiles_figure
    >>> scene = pr.make_scene("diffuse_plane", (16, 16), seed=0)
    >>> stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
    >>> profiles = pr.measured_delay_profiles(stack, [(4, 5), (10, 12)])
    >>> fig = delay_profiles_figure(stack, profiles, names=["left", "right"])
    >>> type(fig).__name__, len(fig.axes)
    ('Figure', 2)
    """
    e0 = profiles.exposure_us.min() if exposure_us is None else exposure_us
    ref_idx = stack.index_of(profiles.delay_us[np.argmin(np.abs(profiles.delay_us))], e0)
    ref = stack.image(ref_idx if ref_idx is not None else 0)
    fig = new_figure((11, 4.6))
    ax_img, ax_prof = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.5]})
    ax_img.imshow(np.clip(ref * display_scale([ref]), 0, 1) ** 0.5, cmap="gray", vmin=0, vmax=1)
    ax_img.set_title(f"$t_d$ = 0, $t_e$ = {e0:g} µs", fontsize=10)
    ax_img.set_xticks([])
    ax_img.set_yticks([])
    for p, (row, col) in enumerate(profiles.pixels):
        color = _COLORS[p % len(_COLORS)]
        label = names[p] if names else f"pixel ({row}, {col})"
        ax_img.plot(col, row, "o", mfc="none", mec=color, mew=2, ms=9)
        for e_i, e in enumerate(profiles.exposure_us):
            if exposure_us is not None and not np.isclose(e, exposure_us):
                continue
            solid = np.isclose(e, e0)
            ax_prof.plot(
                profiles.delay_us,
                profiles.values[p, e_i],
                "-o" if solid else "-",
                color=color,
                alpha=1.0 if solid else 0.3,
                lw=2 if solid else 1,
                ms=3,
                label=label if solid else None,
            )
        if continuous is not None:
            ax_prof.plot(
                continuous.delay_us,
                continuous.values[p],
                "--",
                color=color,
                lw=1.2,
                label=f"{label}, from transport" if p == 0 else None,
            )
    ax_prof.axvline(0, color="0.7", lw=0.8)
    ax_prof.set_xlabel("delay $t_d$ (µs)")
    ax_prof.set_ylabel("area-normalized intensity (1/ms)")
    title = "Delay profiles" + (
        "" if exposure_us is not None else f" (solid: $t_e$ = {e0:g} µs, faint: longer exposures)"
    )
    ax_prof.set_title(title, fontsize=10)
    ax_prof.legend(fontsize=8)
    ax_prof.grid(alpha=0.3)
    fig.tight_layout()
    return finish(fig, out, dpi=110)
