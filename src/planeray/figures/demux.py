"""The criterion's curve of an automatic choice of the demultiplexing weights."""

from __future__ import annotations

import numpy as np

from ._common import figure_for, finish, new_figure

__all__ = ["weights_cv_figure"]

#: The score's axis label, per criterion.
_YLABEL = {
    "gcv": "GCV score (noise-weighted)",
    "sure": "risk estimate C_p (1 = noise level)",
    "cv-images": "CV score (left-out images, noise-weighted)",
}


def weights_cv_figure(choice, *, ax=None, out=None):
    """The criterion's score against the weights tried, with the chosen pair marked.

    The score is generalized cross-validation (the default), Stein's risk estimate or K-fold
    cross-validation over the images (``choice.criterion``); the lowest score is marked where the
    choice is a pair nearer the paper's weights within one standard error of it, and a choice on
    an end of what was searched (``choice.edge``) is said in the panel.

    Parameters
    ----------
    choice : planeray.demux.WeightChoice or dict
        The choice (or the ``weights_choice`` attribute of a transport store).
    ax : matplotlib.axes.Axes, optional
        Draw into this Axes (one panel: the scores against ``alpha``, one curve per
        ``beta`` tried); without it a new figure with one panel per automatic weight.
    out : str or os.PathLike, optional
        Also write the figure to this PNG (100 dpi).

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from planeray.demux import WeightChoice
    >>> import numpy as np
    >>> c = WeightChoice(
    ...     1.0,
    ...     0.01,
    ...     {"alpha": "auto", "beta": 0.01},
    ...     alphas=np.array([0.1, 1.0, 10.0]),
    ...     betas=np.full(3, 0.01),
    ...     scores=np.array([3.0, 2.0, 2.5]),
    ...     score_se=np.full(3, 0.1),
    ...     alpha_range=(1.0, 1.0),
    ...     beta_range=(0.01, 0.01),
    ... )
    >>> len(weights_cv_figure(c).axes)
    1
    """
    from ..demux.auto import WeightChoice, is_auto

    if isinstance(choice, dict):
        choice = WeightChoice.from_attrs(choice)
    auto = [n for n in ("alpha", "beta") if is_auto(choice.requested.get(n))] or ["alpha"]
    if ax is not None:
        auto = auto[:1]
        fig, ax, _ = figure_for(ax, (5.5, 4.2))
        axes = [ax]
    else:
        fig = new_figure((5.5 * len(auto), 4.2))
        axes = fig.subplots(1, len(auto), squeeze=False)[0]
    s, se = choice.scores, choice.score_se
    for ax_, name in zip(axes, auto):
        other = "beta" if name == "alpha" else "alpha"
        x_all = choice.alphas if name == "alpha" else choice.betas
        o_all = choice.betas if name == "alpha" else choice.alphas
        chosen_other = getattr(choice, other)
        for value in np.unique(o_all):
            on = o_all == value
            order = np.argsort(x_all[on])
            x, y, e = x_all[on][order], s[on][order], se[on][order]
            main = value == chosen_other
            if x.size < 2 and not main:  # a lone point of another scan
                ax_.plot(x, y, "o", ms=3, color="0.6", alpha=0.6)
                continue
            ax_.errorbar(
                x,
                y,
                yerr=e,
                marker="o",
                ms=4 if main else 3,
                lw=1.6 if main else 0.8,
                alpha=1.0 if main else 0.45,
                capsize=2,
                label=f"{other} = {value:.3g}" + (" (chosen)" if main else ""),
            )
        best = (choice.alphas == choice.alpha) & (choice.betas == choice.beta)
        xb = getattr(choice, name)
        yb = float(s[best][0]) if best.any() else float(s.min())
        lo, hi = getattr(choice, f"{name}_range")
        ax_.axvspan(lo / 1.15, hi * 1.15, color="tab:green", alpha=0.12, label="within 1 SE of the best")
        ax_.plot([xb], [yb], marker="*", ms=16, color="tab:red", zorder=5, label=f"chosen {name} = {xb:.3g}")
        low = (choice.alphas == choice.lowest[0]) & (choice.betas == choice.lowest[1])
        if low.any() and not (low & best).any():  # the lowest score, when the choice is a nearer pair within 1 SE
            xl = choice.lowest[0 if name == "alpha" else 1]
            ax_.plot([xl], [float(s[low][0])], "kx", ms=8, zorder=6, label="lowest score")
        side = choice.edge.get(name)
        if side:
            ax_.annotate(
                f"best on the {'lower' if side == 'low' else 'upper'} end searched:\nit may lie {'below' if side == 'low' else 'above'}",
                (xb, yb),
                xytext=(0.5, 0.85),
                textcoords="axes fraction",
                ha="center",
                fontsize=8,
                color="tab:red",
                arrowprops={"arrowstyle": "->", "color": "tab:red"},
            )
        ax_.set_xscale("log")
        ax_.set_yscale("log")
        ax_.set_xlabel(f"{name} ({'smoothness' if name == 'alpha' else 'sparsity'} weight)")
        ax_.set_ylabel(_YLABEL.get(choice.criterion, "score"))
        ax_.grid(alpha=0.3, which="both")
        ax_.legend(fontsize=7)
        ax_.set_title(f"{choice.criterion_label()}, {choice.n_pixels} pixels ({choice.weighting})", fontsize=9)
    if ax is None:
        fig.tight_layout()
    return finish(fig, out)
