"""Fig. 4: a delay image emulated without synchronization beside the synchronized one and the truth."""

from __future__ import annotations

import numpy as np

from ._common import display_scale, finish, new_figure

__all__ = ["emulation_figure"]


def emulation_figure(emulated, synchronized, truth=None, *, numbers: dict | None = None, out=None):
    """The emulated delay image, the synchronized one and the noise-free truth, equally brightened.

    Parameters
    ----------
    emulated, synchronized : ndarray (H, W)
        Images in transport units (:func:`planeray.baselines.compare_emulation`).
    truth : ndarray (H, W), optional
        The noise-free render of the same band.
    numbers : dict, optional
        ``compare_emulation(...)["numbers"]``: capture counts and errors in the titles.
    out : path, optional
        Also write the PNG.

    Returns
    -------
    matplotlib.figure.Figure
    """
    numbers = numbers or {}
    captures = numbers.get("n_captures", {})
    errors = numbers.get("errors", {})

    def rel(key):
        e = errors.get(key) or {}
        return "" if e.get("relative_rmse") is None else f", rel. RMSE vs truth {e['relative_rmse']:.3f}"

    panels = [
        (f"(a) synchronized: {captures.get('synchronized', '?')} captures{rel('synchronized_vs_truth')}", synchronized),
        (f"(b) one band per capture: {captures.get('emulated', '?')} captures{rel('emulated_vs_truth')}", emulated),
    ]
    if truth is not None:
        panels.append(("(c) noise-free truth (Eq. 4 band)", truth))
    images = [np.nan_to_num(np.asarray(im, np.float64)) for _, im in panels]
    scale = display_scale(images, 99.5)
    fig = new_figure((4.2 * len(panels), 4.6))
    axes = np.atleast_1d(fig.subplots(1, len(panels)))
    for ax, (title, _), im in zip(axes, panels, images):
        ax.imshow(np.clip(im * scale, 0, 1), cmap="gray", vmin=0, vmax=1)
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    d, e = numbers.get("delay_us"), numbers.get("exposure_us")
    band = "" if d is None else f" (t_d = {d:g} µs, t_e = {e:g} µs)"
    fig.suptitle(
        f"Delay image with and without synchronization{band}; equally brightened (cf. paper Fig. 4)", fontsize=10
    )
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    return finish(fig, out)
