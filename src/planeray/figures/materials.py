"""Figures of the material-recognition experiment (Sec. 8, Fig. 10) and of the wall model behind it.

Every function returns a :class:`matplotlib.figure.Figure` (``out=`` also writes the PNG);
the single-panel ones also draw into ``ax=``.
"""

from __future__ import annotations

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch
from matplotlib.ticker import NullFormatter

from ..materials.labels import class_colour
from ..optical_data import CLASS_NAMES, MATERIAL_CLASSES
from ._common import figure_for, finish, new_figure

__all__ = [
    "materials_photo_figure",
    "material_profiles_figure",
    "segmentation_figure",
    "confusion_figure",
    "accuracy_curves_figure",
    "accuracy_by_distance_figure",
    "recognition_by_distance_figure",
    "wall_kernels_figure",
    "fit_figure",
    "measured_media_figure",
]


def _rgb(cid):
    return tuple(v / 255.0 for v in class_colour(int(cid)))


def _label_cmap(max_id=255):
    return ListedColormap([_rgb(c) for c in range(max_id + 1)])


def _label_image(ax, labels, max_id):
    ax.imshow(labels, cmap=_label_cmap(max_id), vmin=-0.5, vmax=max_id + 0.5, interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])


def materials_photo_figure(photo, labels, *, names=None, out=None, ax=None):
    """An ordinary photograph of the containers (room light only), outlined and named (Fig. 10a).

    Parameters
    ----------
    photo : ndarray (H, W)
        Reflectance under ambient light (the scene's ambient albedo).
    labels : ndarray (H, W) int
        Class ids (the containers' outlines and names).
    names : dict, optional
        Class names; default the documented list.

    Examples
    --------
    >>> import numpy as np
    >>> lab = np.full((20, 20), 6)
    >>> lab[5:15, 5:15] = 1
    >>> fig = materials_photo_figure(np.full((20, 20), 0.8), lab)
    >>> len(fig.axes)
    1
    """
    names = names or CLASS_NAMES
    fig, ax, own = figure_for(ax, (5.2, 5.2))
    ax.imshow(photo, cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest")
    for cid in MATERIAL_CLASSES:
        m = labels == cid
        if not m.any():
            continue
        ax.contour(m.astype(float), levels=[0.5], colors=[_rgb(cid)], linewidths=1.2)
        r, c = np.nonzero(m)
        ax.text(c.mean(), r.mean(), names.get(cid, str(cid)), ha="center", va="center", fontsize=8, color="k")
    ax.set_title("room light only: what an ordinary camera sees", fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    if own:
        fig.tight_layout()
    return finish(fig, out)


def material_profiles_figure(delay_us, profiles, *, exposure_us, floor="edge", out=None):
    """Average area-normalized delay profile of each material, away from walls and near them (Fig. 10b).

    Two panels, linear and logarithmic (the tails tell the materials apart).

    Parameters
    ----------
    delay_us : array_like (D,)
    profiles : dict
        ``{name: {"interior": {"mean", "std"}, "near_wall": {...}, "all": {...}}}`` (from the report).
    exposure_us : float
        The exposure of the curves (title).
    floor : {"edge", "min", "none"}
        The features' floor removal (title).
    """
    fig = new_figure((11.5, 4.2))
    axes = fig.subplots(1, 2)
    ids = {v: k for k, v in CLASS_NAMES.items()}
    d = np.asarray(delay_us)
    for ax in axes:
        for name, entry in profiles.items():
            colour = _rgb(ids.get(name, 0))
            main = entry.get("interior") or entry.get("all")
            label = name if "interior" in entry else f"{name} (every pixel near a wall)"
            m, s = np.asarray(main["mean"]), np.asarray(main["std"])
            ax.plot(d, m, "-o", color=colour, ms=3, lw=1.6, label=label)
            ax.fill_between(d, m - s, m + s, color=colour, alpha=0.2, lw=0)
            if "near_wall" in entry and "interior" in entry:
                ax.plot(d, entry["near_wall"]["mean"], "--", color=colour, lw=1.0)
        ax.set_xlabel("delay t_d (us)")
    axes[0].plot([], [], "k--", lw=1.0, label="near a wall")
    axes[0].set_ylabel("area-normalized intensity (1/ms)")
    axes[0].legend(fontsize=7, frameon=False)
    axes[1].set_yscale("log")
    axes[1].set_ylim(1e-3, None)
    fig.suptitle(
        f"average delay profiles at t_e = {exposure_us:g} us, "
        f"{ {'edge': 'edge floor subtracted, ', 'min': 'minimum subtracted, '}.get(floor, '') }"
        "area-normalized (band: +-1 std over the pixels)",
        fontsize=9,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.94))
    return finish(fig, out)


def segmentation_figure(truth, pred, *, near_wall=None, scored=None, names=None, title=None, out=None):
    """Ground truth, per-pixel prediction, and the errors with the near-wall zone (Fig. 10c).

    ``scored``: the pixels that are classified and judged (default: every labelled
    pixel); the prediction is shown there only.
    """
    names = names or CLASS_NAMES
    truth, pred = np.asarray(truth), np.asarray(pred)
    scored = (truth > 0) if scored is None else np.asarray(scored, bool)
    shown = np.where(scored, pred, 0)
    max_id = int(max(truth.max(), pred.max(), max(names)))
    fig = new_figure((11.5, 4.4))
    axes = fig.subplots(1, 3)
    _label_image(axes[0], truth, max_id)
    axes[0].set_title("ground truth", fontsize=9)
    _label_image(axes[1], shown, max_id)
    axes[1].set_title(f"prediction ({title})" if title else "prediction", fontsize=9)
    wrong = scored & (pred != truth)
    err = np.ones((*truth.shape, 3))
    err[scored] = 0.7
    err[wrong] = (0.85, 0.1, 0.1)
    axes[2].imshow(err, interpolation="nearest")
    if near_wall is not None and near_wall.any():
        axes[2].contour(near_wall.astype(float), levels=[0.5], colors=["#1f77b4"], linewidths=0.8)
    axes[2].set_title(f"errors (red): {wrong.sum()} of {scored.sum()} px; blue: near-wall zone", fontsize=9)
    axes[2].set_xticks([])
    axes[2].set_yticks([])
    handles = [Patch(color=_rgb(c), label=names[c]) for c in sorted(names) if c > 0]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.07, 1, 0.97))
    return finish(fig, out)


def confusion_figure(confusion, *, out=None, ax=None):
    """Row-normalized confusion matrix in percent (Fig. 10d); ``confusion`` as from :func:`score`."""
    names = list(confusion["names"])
    M = np.asarray(confusion["matrix"], dtype=np.float64)
    if M.shape[1] == len(names) + 1:  # the "no prediction" column, shown only if used
        if M[:, -1].sum() == 0:
            M = M[:, :-1]
            cols = names
        else:
            cols = [*names, "none"]
    else:
        cols = names
    P = 100.0 * M / np.maximum(M.sum(axis=1, keepdims=True), 1)
    fig, ax, own = figure_for(ax, (6.2, 5.2))
    ax.imshow(P, cmap="Blues", vmin=0, vmax=100)
    for i in range(P.shape[0]):
        for j in range(P.shape[1]):
            if M[i, j] > 0:
                ax.text(
                    j, i, f"{P[i, j]:.1f}", ha="center", va="center", fontsize=8, color="w" if P[i, j] > 60 else "k"
                )
    ax.set_xticks(range(len(cols)), cols, rotation=35, ha="right", fontsize=8)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    ax.set_title("confusion matrix (% of each true class)", fontsize=9)
    if own:
        fig.tight_layout()
    return finish(fig, out)


def accuracy_curves_figure(curves, *, floor="edge", out=None):
    """Per-class accuracy as the noise factor and the ambient light grow.

    Colours: each material with the given ``floor`` (the report's model); black: the
    worst class with that floor (solid), the minimum as the floor (dotted) and the
    paper's plain normalization (dashed).  Grey bars: share of the material pixels
    with a saturated observation.
    """
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    fkey = f"floor_{floor}"
    fig = new_figure((11, 4.2))
    axes = fig.subplots(1, 2)
    for ax, key, label in (
        (axes[0], "noise", "noise factor (x the default camera's shot and read noise)"),
        (axes[1], "ambient_e_per_us", "ambient light (e- per us of row exposure, albedo 1)"),
    ):
        rows = curves[key]
        x = [r["value"] for r in rows]
        sat = [r.get("saturated_pixels", 0.0) for r in rows]
        if any(s > 0 for s in sat):
            ax.bar(x, sat, width=[0.12 * v for v in x], color="0.85", zorder=0, label="saturated pixels (share)")
        for cid, name in MATERIAL_CLASSES.items():
            ax.plot(x, [r[fkey]["accuracy"][name] for r in rows], "-o", color=_rgb(cid), ms=3, label=name)
        ax.plot(x, [r[fkey]["min_material_accuracy"] for r in rows], "k-", lw=1.5, label=f"worst class, floor {floor}")
        for other, style in (("min", ":"), ("none", "--")):
            key_other = f"floor_{other}"
            if key_other != fkey and key_other in rows[0]:
                what = "no floor removal (paper)" if other == "none" else "floor min"
                ax.plot(
                    x,
                    [r[key_other]["min_material_accuracy"] for r in rows],
                    "k" + style,
                    lw=1,
                    label=f"worst class, {what}",
                )
        ax.axhline(0.9, color="0.6", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xticks(x)
        ax.set_ylim(0, 1.02)
        ax.set_xlabel(label, fontsize=8)
        ax.set_ylabel("per-class accuracy" + (" | bars: share" if any(s > 0 for s in sat) else ""))
        if any(s > 0 for s in sat):  # the bars' legend beside them (the curves' is on the left panel)
            bars = [h for h, t in zip(*ax.get_legend_handles_labels()) if t.startswith("saturated")]
            ax.legend(
                bars, ["saturated pixels (share of the material pixels)"], fontsize=7, frameon=False, loc="lower left"
            )
    axes[0].legend(fontsize=7, frameon=False, loc="lower left")
    fig.suptitle(
        "recognition of the held-out placement as the capture gets worse (model trained at x1, 0.5 e-/us)", fontsize=9
    )
    fig.tight_layout(rect=(0, 0, 1, 0.94))
    return finish(fig, out)


def accuracy_by_distance_figure(results, *, out=None, ax=None):
    """Accuracy of the material pixels against their distance to the container wall."""
    fig, ax, own = figure_for(ax, (5.6, 3.8))
    for (name, res), style in zip(results.items(), ("-o", "--s", ":^")):
        rows = [r for r in res["by_distance_mm"] if r["accuracy"] is not None]
        mid = [0.5 * (r["from_mm"] + (r["to_mm"] if r["to_mm"] is not None else r["from_mm"] + 10.0)) for r in rows]
        ax.plot(mid, [r["accuracy"] for r in rows], style, ms=4, label=name)
    ax.set_xlabel("distance to the container wall (mm)")
    ax.set_ylabel("accuracy (material pixels)")
    ax.set_ylim(0, 1.02)
    ax.axhline(0.9, color="0.6", lw=0.8, ls=":")
    ax.legend(fontsize=8, frameon=False)
    ax.set_title("where the errors fall", fontsize=9)
    if own:
        fig.tight_layout()
    return finish(fig, out)


def recognition_by_distance_figure(tables, *, out=None):
    """Per-class accuracy against the distance to the nearest wall, one panel per recogniser variant.

    Parameters
    ----------
    tables : dict of str -> dict
        Variant name -> :func:`planeray.materials.recognize.accuracy_by_distance` table.
    """
    n = len(tables)
    cols = min(n, 4)
    rows = (n + cols - 1) // cols
    fig = new_figure((3.1 * cols, 2.8 * rows + 0.4))
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for ax, (name, tab) in zip(axes, tables.items()):
        edges = [np.inf if v is None else v for v in tab["bins_mm"]]
        labels = [f"{lo:g}-{hi:g}" if np.isfinite(hi) else f">{lo:g}" for lo, hi in zip(edges[:-1], edges[1:])]
        x = np.arange(len(labels))
        for cname, row in tab["classes"].items():
            cid = next((c for c, v in CLASS_NAMES.items() if v == cname), 0)
            acc = [np.nan if b["accuracy"] is None else b["accuracy"] for b in row["bins"]]
            ax.plot(x, acc, "-o", ms=3, lw=1.2, color=_rgb(cid) if cid else None, label=cname)
        ax.axhline(0.9, color="0.5", lw=0.8, ls=":")
        ax.set_ylim(-0.02, 1.04)
        ax.set_xticks(x)
        ax.set_xticklabels(labels, fontsize=7)
        ax.set_xlabel("distance to the wall (mm)", fontsize=8)
        worst = tab.get("min_class_accuracy")
        ax.set_title(f"{name}\nworst class {worst:.2f}" if worst is not None else name, fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in axes[n:]:
        ax.set_visible(False)
    axes[0].set_ylabel("accuracy (per class)", fontsize=8)
    axes[0].legend(fontsize=6, frameon=False, loc="lower right")
    fig.tight_layout()
    return finish(fig, out)


def wall_kernels_figure(tables, *, distances_rows=(0.0, 5.0, 17.0, 45.0), angle_deg=0.0, out=None):
    """The Monte Carlo wall model: each material's kernel beside a wall, and the light the wall takes.

    Parameters
    ----------
    tables : dict of int to WallKernelTable
        By class id (:func:`planeray.scenes.materials.material_tables`).
    distances_rows : sequence of float
        Pixel-to-wall distances to draw (projector rows), with the slab (no wall).
    angle_deg : float
        Wall angle of the kernels (0: parallel to the lines, the wall at positive offsets).
    """
    n = len(tables)
    fig = new_figure((3.2 * n, 7.0))
    axes = fig.subplots(2, n, squeeze=False)
    from matplotlib import colormaps

    colours = colormaps["plasma"](np.linspace(0.0, 0.8, len(distances_rows)))
    for k, (cid, tab) in enumerate(tables.items()):
        ax = axes[0, k]
        u = tab.offsets_rows * tab.mm_per_row
        ax.semilogy(u, np.maximum(tab.slab, 1e-9), "k-", lw=1.4, label="no wall")
        for d, colour in zip(distances_rows, colours):
            kern = tab.kernels(d, angle_deg)
            ax.semilogy(u, np.maximum(kern, 1e-9), color=colour, lw=1.0, label=f"wall {d * tab.mm_per_row:g} mm away")
        peak = tab.slab.max()
        ax.set_ylim(peak * 1e-4, peak * 2)
        ax.set_xlim(-30, 30)
        ax.set_title(CLASS_NAMES.get(cid, str(cid)), fontsize=9)
        ax.set_xlabel("offset (mm)", fontsize=8)
        if k == 0:
            ax.set_ylabel("kernel (per projector row)", fontsize=8)
            ax.legend(fontsize=7, frameon=True, loc="upper left")
        ax2 = axes[1, k]
        dist_mm = tab.distances_rows * tab.mm_per_row
        for i, a in enumerate(tab.angles_deg):
            total = tab.kernel[i].sum(axis=1) / tab.slab.sum()
            ax2.plot(dist_mm, total, "-o", ms=2.5, lw=1, label=f"reflectance, wall at {a:g} deg")
            ax2.plot(dist_mm, tab.wall_loss[i], "--", lw=1, label=f"lost through the wall, {a:g} deg")
        ax2.set_xscale("symlog", linthresh=1.0)
        ax2.set_ylim(0, 1.05)
        ax2.grid(alpha=0.3)
        ax2.set_xlabel("pixel-to-wall distance (mm)", fontsize=8)
        if k == 0:
            ax2.set_ylabel("relative reflectance / wall loss", fontsize=8)
            ax2.legend(fontsize=6.5, frameon=True, loc="center right")
    fig.suptitle(
        f"Monte Carlo kernels beside a {next(iter(tables.values())).wall} wall (top: wall parallel to the lines, "
        "on the right); bottom: the pixel's total relative to the slab and the power lost through the wall",
        fontsize=9,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    return finish(fig, out)


def fit_figure(result, *, mm_per_row, names=None, max_profiles=4, out=None):
    """Maps of the fitted ``mu_s'`` and ``mu_a`` (1/mm), where they are not identifiable, and
    the regions' mean profiles over the fitted kernels.

    Parameters
    ----------
    result : planeray.materials.fit.TransportFit
    mm_per_row : float
        Row size, mm (the profiles' x axis in mm).
    names : dict, optional
        Region names by label.
    max_profiles : int
        Regions whose profiles are drawn (the largest).
    """
    names = names or {}
    maps = result.maps
    fig = new_figure((12.0, 7.2))
    gs = fig.add_gridspec(2, 3, height_ratios=(1.0, 0.9))
    panels = (
        ("mu_s_prime_per_mm", "reduced scattering $\\mu_s'$ (1/mm)"),
        ("mu_a_per_mm", "absorption $\\mu_a$ (1/mm)"),
    )
    from matplotlib.colors import LogNorm

    for i, (key, title) in enumerate(panels):
        ax = fig.add_subplot(gs[0, i])
        v = maps[key]
        fin = v[np.isfinite(v) & (v > 0)]
        norm = LogNorm(vmin=float(fin.min()), vmax=float(max(fin.max(), fin.min() * 1.01))) if fin.size else None
        im = ax.imshow(np.ma.masked_invalid(v), cmap="viridis", norm=norm, interpolation="nearest")
        ax.set_facecolor("0.85")
        ax.set_title(title + "  (grey: none)", fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03)
    ax = fig.add_subplot(gs[0, 2])
    mask = maps["mask"]
    state = np.where(mask == 255, 0, np.where(mask == 0, 1, np.where(np.isfinite(maps["mu_s_prime_per_mm"]), 2, 3)))
    flags = maps.get("flags")
    if flags is not None:  # the flag layer: the model does not fit, or a parameter at the model's edge
        state = np.where((flags != 255) & (flags & 11 > 0), 4, state)
    cmap = ListedColormap(["0.85", "#3b8f3b", "#e0a030", "#c03030", "#7b3fa0"])
    ax.imshow(state, cmap=cmap, vmin=-0.5, vmax=4.5, interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title("identifiability and flags", fontsize=9)
    ax.legend(
        handles=[
            Patch(color="#3b8f3b", label="both measured"),
            Patch(color="#e0a030", label="mu_a not identifiable"),
            Patch(color="#c03030", label="neither"),
            Patch(color="#7b3fa0", label="FLAGGED: no fit / at an edge / out of range"),
            Patch(color="0.85", label="not fitted"),
        ],
        fontsize=7,
        loc="lower left",
        framealpha=0.8,
    )
    axp = fig.add_subplot(gs[1, :])
    order = sorted(result.profiles, key=lambda r: -result.regions[r]["pixels"])[:max_profiles]
    stack = getattr(result, "source", "transport") == "stack"
    x = np.asarray(result.offsets_rows) * (1.0 if stack else float(mm_per_row))
    top = 0.0
    for k, region in enumerate(order):
        y, s, model = result.profiles[region]
        info = result.regions[region]
        colour = f"C{k}"
        fmt = lambda v: "n/a" if v is None else f"{v:.3g}"  # noqa: E731
        label = (
            f"{names.get(region, f'region {region}')}: mu_s' {fmt(info['mu_s_prime_per_mm'])} "
            f"+- {fmt(info['mu_s_prime_se_per_mm'])}, mu_a {fmt(info['mu_a_per_mm'])} +- {fmt(info['mu_a_se_per_mm'])} /mm"
        )
        q = info.get("fit_quality")
        if q is not None:
            label += f"; chi2/dof {q['reduced_chi2']:.2g}" + ("" if info.get("model_fits") else " FLAGGED")
        ok = np.isfinite(y) & (y > 0)
        axp.plot(x[ok], y[ok], ".", ms=3, color=colour, alpha=0.6)
        top = max(top, float(np.nanmax(y[ok]))) if ok.any() else top
        if np.all(np.isfinite(model)):
            axp.plot(x, model, "-", color=colour, lw=1.2, label=label)
        else:
            axp.plot([], [], ".", color=colour, label=label)
    if stack:  # the regions' mean images over the fitted model: image index on x
        axp.set_yscale("log")
        axp.set_xlabel("stack image (index; the sweep's order, boundary images left out)")
        axp.set_ylabel("mean image value (normalized)")
        axp.set_title("regions' mean stack images (dots) and the fitted model (lines)", fontsize=9)
        axp.legend(fontsize=7, frameon=True, framealpha=0.85, loc="upper right")
        fig.tight_layout()
        return finish(fig, out)
    axp.set_yscale("log")
    if top > 0:
        axp.set_ylim(top * 1e-6, top * 2.0)  # six decades: what a camera's dynamic range sees
    axp.set_xlabel("offset from the lit line (mm)")
    axp.set_ylabel("transport (reflectance per row)" if result.calibrated else "transport (camera units)")
    axp.set_title(
        "regions' mean profiles (dots) and fitted kernels (lines); "
        + ("calibrated by the white reference" if result.calibrated else "shape only (no white reference)"),
        fontsize=9,
    )
    axp.legend(fontsize=7, frameon=True, framealpha=0.85, loc="upper right")
    fig.tight_layout()
    return finish(fig, out)


def measured_media_figure(media, *, out=None):
    """Fitted against published ``mu_s'`` and ``mu_a`` (1/mm) of each medium, log-log, with standard errors.

    ``media``: ``{name: {"published": {"mu_s_prime_per_mm", "mu_a_per_mm"}, SOURCE: {"mu_s_prime_per_mm",
    "mu_s_prime_se_per_mm", "mu_a_per_mm", "mu_a_se_per_mm"}, ...}}`` -- one marker per source (e.g. the
    ground-truth transport and the demultiplexed capture); a parameter not identified (None) is left out.
    """
    fig = new_figure((8.4, 3.8))
    axes = fig.subplots(1, 2)
    names = list(media)
    sources = [k for k in media[names[0]] if k != "published"] if names else []
    markers = ("o", "s", "^", "D")
    for ax, key, label in zip(axes, ("mu_s_prime_per_mm", "mu_a_per_mm"), ("$\\mu_s'$ (1/mm)", "$\\mu_a$ (1/mm)")):
        lo, hi = np.inf, 0.0
        for name in names:
            cid = next((c for c, n in CLASS_NAMES.items() if n == name), None)
            colour = _rgb(cid) if cid is not None else "0.3"
            truth = media[name]["published"][key]
            for src, marker in zip(sources, markers):
                got = (media[name].get(src) or {}).get(key)
                if got is None or truth is None:
                    continue
                se = (media[name][src] or {}).get(key.replace("_per_mm", "_se_per_mm")) or 0.0
                ax.errorbar(truth, got, yerr=se, fmt=marker, color=colour, ms=6, mec="k", mew=0.5, capsize=2)
                lo, hi = min(lo, truth, got), max(hi, truth, got)
        if hi > 0:
            span = np.array([lo / 1.6, hi * 1.6])
            ax.plot(span, span, color="0.5", lw=0.8)
            ax.fill_between(span, span / 1.25, span * 1.25, color="0.9", zorder=0, label="within 25 %")
            ax.set_xlim(*span)
            ax.set_ylim(*span)
        ax.set_xscale("log")
        ax.set_yscale("log")
        for axis in (ax.xaxis, ax.yaxis):  # decades only: minor labels of a narrow span collide
            axis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("published " + label)
        ax.set_ylabel("fitted " + label)
    handles = [Patch(color=_rgb(c), label=n) for c, n in CLASS_NAMES.items() if n in names]
    handles += [
        axes[0].plot([], [], m, color="0.4", mec="k", mew=0.5, label=src)[0] for src, m in zip(sources, markers)
    ]
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 4), fontsize=7, frameon=False)
    fig.suptitle("the Fig. 10 media measured: fitted vs published (walls modelled; grey: within 25 %)", fontsize=9)
    fig.tight_layout(rect=(0, 0.12, 1, 0.95))
    return finish(fig, out)
