"""Figures of the vein study (Sec. 10): methods side by side (Fig. 16), CNR against depth and ambient
light (Fig. 13), the best delay against depth, and the contrast enhancement of Eq. 7 (Fig. 14).

Every function returns a :class:`matplotlib.figure.Figure`; ``out=`` also writes the PNG.
Images are shown each with its own 1-99 % percentile range (what a viewer's auto contrast
does), which shows structure but not absolute brightness; the CNR in each title is the number
that compares them.
"""

from __future__ import annotations

import numpy as np

from ._common import figure_for, finish, new_figure

__all__ = [
    "show_image",
    "methods_figure",
    "vein_depth_figure",
    "ambient_figure",
    "best_delay_figure",
    "enhancement_figure",
    "headline_figure",
    "delay_map_figure",
    "depth_fit_figure",
    "depth_validation_figure",
]

_LABELS = {
    "photo": "photo",
    "flood": "flood + stretch",
    "direct": "direct (t_d = 0, one camera row)",
    "global": "global (Nayar)",
    "non_epipolar": "non-epipolar",
    "delay": "short-range indirect",
    "enhanced": "enhanced (Eq. 7)",
}
_COLORS = {
    "photo": "tab:gray",
    "flood": "tab:olive",
    "direct": "tab:blue",
    "global": "tab:orange",
    "non_epipolar": "tab:purple",
    "delay": "tab:red",
}


def _fmt(x, f="{:.2f}"):
    return "n/a" if x is None else f.format(x)


def show_image(ax, image, *, valid=None, title=None):
    """Grayscale image with its 1-99 % range over ``valid`` pixels, cropped to their rows; axes off."""
    img = np.asarray(image, np.float64)
    if valid is not None and np.any(valid):  # crop to the rows the metrics use
        valid = np.asarray(valid, bool)
        rows = np.flatnonzero(valid.any(axis=1))
        img, valid = img[rows[0] : rows[-1] + 1], valid[rows[0] : rows[-1] + 1]
    vals = img[valid] if valid is not None and np.any(valid) else img.ravel()
    vals = vals[np.isfinite(vals)]
    lo, hi = np.percentile(vals, [1, 99]) if vals.size else (0.0, 1.0)
    ax.imshow(img, cmap="gray", vmin=lo, vmax=hi if hi > lo else lo + 1e-9, interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=8)


def methods_figure(panels, *, methods=None, labels=None, out=None):
    """Fig. 16 analogue: one row per condition, one column per method (+ the true vein mask).

    ``panels``: list of dicts with ``condition``, ``images`` (method -> image), ``metrics``
    (method -> :func:`~planeray.skin.metrics.vein_metrics`), ``valid`` and ``truth``;
    ``labels``: method -> column title (default: the method's name).
    """
    names = {**_LABELS, **(labels or {})}
    methods = list(methods or panels[0]["images"])
    n, m = len(panels), len(methods) + 1
    fig = new_figure((1.75 * m, 2.1 * n + 0.4))
    axes = np.atleast_2d(fig.subplots(n, m, squeeze=False))
    for i, p in enumerate(panels):
        ids = np.asarray(p["truth"]["vein_id"])
        mask_img = np.where(ids > 0, 1.0, 0.0)
        if p["truth"].get("exclude") is not None:
            mask_img = np.where(p["truth"]["exclude"], 0.5, mask_img)
        show_image(axes[i, 0], mask_img, valid=p["valid"], title=f"{p['condition']}\nveins (truth; grey: hair)")
        for j, meth in enumerate(methods, start=1):
            mt = p["metrics"][meth]
            show_image(
                axes[i, j],
                p["images"][meth],
                valid=p["valid"],
                title=f"{names.get(meth, meth)}\nCNR {_fmt(mt['cnr'])}, {mt['n_detected']}/{mt['n_veins']} veins",
            )
    fig.suptitle("Veins through skin: methods (Fig. 16 analogue; per-vein CNR >= 1 counts as detected)", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    return finish(fig, out)


def vein_depth_figure(vein_rows, *, condition=None, light=None, ax=None, out=None):
    """Per-vein CNR against vein depth, one colour per method, threshold CNR = 1 dashed.

    The legend lists only what is drawn: the methods with at least one vein, and the conditions
    (marker shapes) only when there are several.  Methods are set side by side at each depth
    (a small horizontal offset) so that none hides another; a CNR below 0.01 is drawn at 0.01
    (marked ``v``), and veins with no number (too few usable pixels) are counted in the title.
    ``light``: the ambient light the CNRs were measured under (the y label), if known.
    """
    fig, ax, own = figure_for(ax, (7.6, 4.0))
    rows = [r for r in vein_rows if condition is None or r["condition"] == condition]
    conds = sorted({r["condition"] for r in rows})
    markers = dict(zip(conds, "osDx<>^*"))
    floor = 1e-2
    drawn = [m for m in _COLORS if any(r["method"] == m and r["depth_mm"] is not None for r in rows)]
    depths = sorted({r["depth_mm"] for r in rows if r["depth_mm"] is not None})
    step = min(np.diff(depths)) if len(depths) > 1 else 1.0
    dodge = {m: (i - (len(drawn) - 1) / 2) * 0.12 * step for i, m in enumerate(drawn)}
    no_number, below = 0, False
    for meth in drawn:
        for c in conds:
            sel = [r for r in rows if r["method"] == meth and r["condition"] == c and r["depth_mm"] is not None]
            no_number += sum(r["cnr"] is None for r in sel)
            pts = [(r["depth_mm"] + dodge[meth], r["cnr"]) for r in sel if r["cnr"] is not None]
            if not pts:
                continue
            x, y = (np.asarray(v, float) for v in zip(*pts))
            low = y < floor
            below |= bool(low.any())
            ax.scatter(x[~low], y[~low], s=18, color=_COLORS[meth], marker=markers[c], alpha=0.85)
            ax.scatter(x[low], np.full(low.sum(), floor), s=22, color=_COLORS[meth], marker="v", alpha=0.85)
    for meth in drawn:
        ax.plot([], [], "o", color=_COLORS[meth], label=_LABELS[meth])
    if len(conds) > 1:
        for c, mk in markers.items():
            ax.plot([], [], mk, color="k", label=c, markerfacecolor="none")
    if below:
        ax.plot([], [], "v", color="k", label="CNR below 0.01 (drawn at 0.01)")
    ax.axhline(1.0, color="k", ls="--", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("vein depth (mm, ground truth; methods side by side)")
    ax.set_ylabel("per-vein CNR" + (f" ({light})" if light else ""))
    title = "Which veins each method shows, by depth\n(below the dashed line: not detected)"
    if len(conds) == 1:
        title = f"{conds[0]}: " + title[0].lower() + title[1:]
    if no_number:
        title += f"\n{no_number} vein-method pair(s) without a number (too few usable pixels), not drawn"
    ax.set_title(title, fontsize=9)
    if drawn:
        ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    if own:
        fig.tight_layout()
    return finish(fig, out)


def ambient_figure(amb_rows, strongest=None, *, valid=None, labels=None, out=None):
    """Fig. 13 analogue: pooled CNR against ambient illuminance per method, and the images at the brightest level.

    ``strongest``: ``(level name, images, metrics)`` of the brightest level, or None;
    ``labels``: method -> name (default: the method's name).
    """
    names = {**_LABELS, **(labels or {})}
    shown = ["photo", "global", "delay"]
    ncol = 1 + (len(shown) if strongest is not None else 0)
    fig = new_figure((3.6 + 2.3 * (ncol - 1), 3.4))
    gs = fig.add_gridspec(1, ncol, width_ratios=[1.8] + [1.0] * (ncol - 1))
    ax = fig.add_subplot(gs[0, 0])
    for meth, col in _COLORS.items():
        pts = sorted((max(r["lux"], 10.0), r["cnr"] or 0.0) for r in amb_rows if r["method"] == meth)
        if pts:
            x, y = zip(*pts)
            ax.plot(x, np.maximum(y, 1e-2), "o-", color=col, label=names[meth].replace("\n", " "), ms=3)
    ax.axhline(1.0, color="k", ls="--", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("ambient illuminance (lux; 'dark' drawn at 10)")
    ax.set_ylabel("pooled vein CNR")
    ax.set_title("CNR against ambient light (Fig. 13 analogue)", fontsize=9)
    ax.legend(fontsize=6)
    if strongest is not None:
        level, imgs, m = strongest
        for j, meth in enumerate(shown, start=1):
            a = fig.add_subplot(gs[0, j])
            show_image(a, imgs[meth], valid=valid, title=f"{names[meth]}\n{level}: CNR {_fmt(m[meth]['cnr'])}")
    fig.tight_layout()
    return finish(fig, out)


def best_delay_figure(best, *, ax=None, out=None):
    """The delay of highest CNR per vein against its depth, with the straight-line fit."""
    fig, ax, own = figure_for(ax, (4.5, 3.5))
    veins = [v for v in best["veins"] if v["depth_mm"] is not None]
    det = [v for v in veins if v["detected"]]
    nod = [v for v in veins if not v["detected"]]
    if det:
        ax.scatter([v["depth_mm"] for v in det], [v["best_delay_us"] for v in det], color="tab:red", label="detected")
    if nod:
        ax.scatter(
            [v["depth_mm"] for v in nod],
            [v["best_delay_us"] for v in nod],
            marker="x",
            color="k",
            label="not detected at any delay (argmax of noise)",
        )
    fit = best.get("fit_delay_vs_depth")
    if fit:
        x = np.linspace(min(v["depth_mm"] for v in det), max(v["depth_mm"] for v in det), 20)
        ax.plot(
            x, fit["intercept"] + fit["slope"] * x, "k-", lw=1, label=f"{fit['slope']:.0f} us/mm, r = {fit['r']:.2f}"
        )
    ax.set_xlabel("vein depth (mm)")
    ax.set_ylabel("delay of highest CNR (us)")
    ax.set_title(f"Delay of highest CNR against depth (t_e = {best.get('exposure_us', 0):g} us)", fontsize=9)
    ax.legend(fontsize=7)
    if own:
        fig.tight_layout()
    return finish(fig, out)


def enhancement_figure(single, single_delay_us, result, truth, numbers, *, valid=None, out=None):
    """Fig. 14 analogue: best single delay image, enhanced composite, delay map, delay map against depth."""
    fig = new_figure((12.0, 3.3))
    axes = fig.subplots(1, 4)
    e = numbers
    show_image(
        axes[0],
        single,
        valid=valid,
        title=f"best single delay ({single_delay_us:g} us)\nCNR {_fmt(e['best_single_cnr'])}, "
        f"{e['best_single_detected']}/{e['n_veins']} veins",
    )
    show_image(
        axes[1],
        result.image,
        valid=valid,
        title=f"enhanced (Eq. 7)\nCNR {_fmt(e['enhanced_cnr'])}, {e['enhanced_detected']}/{e['n_veins']} veins",
    )
    im = axes[2].imshow(result.delay_map_us, cmap="viridis", interpolation="nearest")
    axes[2].set_xticks([])
    axes[2].set_yticks([])
    ids = np.asarray(truth["vein_id"])
    axes[2].contour(ids > 0, levels=[0.5], colors="w", linewidths=0.5)
    axes[2].set_title("blurred delay map t_d* (us)\nwhite: true veins", fontsize=8)
    fig.colorbar(im, ax=axes[2], fraction=0.046)
    ax = axes[3]
    d = e.get("depth_from_delay_map") or {}
    if d.get("veins"):
        depth = np.asarray(truth["depth_mm"], float)
        on = (ids > 0) & np.isfinite(depth)
        if valid is not None:
            on &= valid
        ax.scatter(result.delay_map_us[on], depth[on], s=2, alpha=0.2, color="tab:blue", label="vein pixels")
        ax.scatter(
            [v["delay_us"] for v in d["veins"]],
            [v["depth_mm"] for v in d["veins"]],
            color="tab:red",
            s=25,
            label="per vein (median)",
        )
        f = d.get("pixels")
        if f:
            x = np.linspace(result.delay_map_us[on].min(), result.delay_map_us[on].max(), 10)
            ax.plot(
                x,
                f["intercept"] + f["slope"] * x,
                "k-",
                lw=1,
                label=f"fit: RMSE {f['rmse']:.2f} mm (spread {f['spread']:.2f}), r = {f['r']:.2f}",
            )
        ax.legend(fontsize=6)
    ax.set_xlabel("t_d* (us)")
    ax.set_ylabel("true vein depth (mm)")
    ax.set_title("does the delay map estimate depth?", fontsize=8)
    fig.tight_layout()
    return finish(fig, out)


def headline_figure(images: dict, *, labels=None, metrics=None, valid=None, title=None, out=None):
    """Images side by side, each titled with what it is (``labels``: key -> text) and its CNR.

    The demo's headline (photo, direct and short-range indirect images of the forearm) and
    ``planeray skin veins``'s figure (its band images, each named for its band).
    """
    import textwrap

    keys = list(images)
    fig = new_figure((3.0 * len(keys), 3.6))
    axes = np.atleast_1d(fig.subplots(1, len(keys)))
    for ax, k in zip(axes, keys):
        t = (labels or {}).get(k) or _LABELS.get(k, k)
        t = "\n".join(textwrap.wrap(t, 44))
        if metrics is not None:
            t += f"\nCNR {_fmt(metrics[k]['cnr'])}, {metrics[k]['n_detected']}/{metrics[k]['n_veins']} veins"
        show_image(ax, images[k], valid=valid, title=t)
    fig.suptitle(title or "Forearm: veins through skin (Sec. 10), office light", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.94))
    return finish(fig, out)


def delay_map_figure(delay_map_us, *, vein_id=None, used_us=None, title=None, out=None):
    """Eq. 7's map of the best delay ``t_d*`` per pixel, with a colour bar in microseconds.

    ``vein_id``: true veins outlined in white, if known; ``used_us``: the delays the composite
    chose from (ticks of the colour bar).
    """
    img = np.asarray(delay_map_us, np.float64)
    h, w = img.shape
    fig = new_figure((4.6, 4.0 * h / max(w, 1) + 0.6))
    ax = fig.subplots()
    lo, hi = (float(np.nanmin(img)), float(np.nanmax(img))) if np.isfinite(img).any() else (0.0, 1.0)
    im = ax.imshow(img, cmap="viridis", vmin=lo, vmax=hi if hi > lo else lo + 1.0, interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])
    if vein_id is not None and np.any(np.asarray(vein_id) > 0):
        ax.contour(np.asarray(vein_id) > 0, levels=[0.5], colors="w", linewidths=0.6)
    bar = fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03)
    bar.set_label("delay t_d* (us)")
    if used_us is not None and len(used_us):
        ticks = [t for t in used_us if lo - 1e-9 <= t <= hi + 1e-9]
        if 2 <= len(ticks) <= 12:
            bar.set_ticks(ticks)
    ax.set_title(title or "Eq. 7: delay of the strongest edge per pixel (blurred)", fontsize=8)
    fig.tight_layout()
    return finish(fig, out)


def depth_fit_figure(veins, *, truth=None, title=None, out=None):
    """The depth fit of each vein: measured and fitted contrast per delay; estimated against true depth.

    ``veins``: one dict per vein (:meth:`planeray.skin.depth.VeinFit.to_json` with ``curves``: the
    ``delays_us``, ``exposures_us``, ``contrast_measured`` +- ``contrast_se`` over the vein's core
    and ``contrast_fit``).  ``truth``: ``{vein id: (true depth of the top, true diameter) in mm}``
    (a simulated capture), which adds a panel of the estimated against the true depth with
    1-standard-error bars, the identity and the +-0.5 mm band (unresolved veins drawn at the fit's
    value, hollow, in grey).
    """
    n = len(veins) + (1 if truth else 0)
    cols = min(n, 3)
    rows = -(-n // cols)
    fig = new_figure((3.4 * cols, 2.9 * rows))
    axes = [fig.add_subplot(rows, cols, i + 1) for i in range(n)]
    for ax, v in zip(axes, veins):
        c = v.get("curves", {})
        d = np.asarray(c.get("delays_us", []), float)
        e = np.asarray(c.get("exposures_us", []), float)
        for j, te in enumerate(sorted(set(e.tolist()))):
            sel = e == te
            o = np.argsort(d[sel])
            color = f"C{j}"
            ax.errorbar(d[sel][o], np.asarray(c["contrast_measured"], float)[sel][o],
                        yerr=np.asarray(c["contrast_se"], float)[sel][o], fmt="o", ms=3, color=color,
                        label=f"measured, t_e {te:g} us")  # fmt: skip
            fit = np.asarray(c["contrast_fit"], float)[sel][o]
            for side in (d[sel][o] < 0, d[sel][o] > 0):  # no line across the epipolar plane (no image there)
                ax.plot(d[sel][o][side], fit[side], "-", color=color, lw=1)
            ax.plot([], [], "-", color=color, lw=1, label=f"fit, t_e {te:g} us")
        if v["resolved"]:
            head = (
                f"vein {v['id']}: top {v['depth_mm']:.2f} +- {v['depth_se_mm']:.2f} mm, "
                f"D {v['diameter_mm']:.1f} +- {v['diameter_se_mm']:.1f} mm"
            )
        else:
            head = f"vein {v['id']}: unresolved\n({_wrap(v['reason'])})"
        if v.get("flags") and v["resolved"]:
            head += "\nFLAGGED: the skin model does not fit"
        if truth and v["id"] in truth:
            head += f"\ntrue: top {truth[v['id']][0]:.2f} mm, D {truth[v['id']][1]:.1f} mm"
        ax.set_title(head, fontsize=7)
        ax.set_xlabel("delay t_d (us)", fontsize=8)
        ax.set_ylabel("contrast over the vein's core", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.axhline(0.0, color="k", lw=0.5)
    if veins and axes[0].get_legend_handles_labels()[0]:
        axes[0].legend(fontsize=6, frameon=False)
    if truth:
        ax = axes[-1]
        lo_hi = [t[0] for t in truth.values()]
        for v in veins:
            if v["id"] not in truth:
                continue
            t = truth[v["id"]][0]
            if v["resolved"]:
                ax.errorbar([t], [v["depth_mm"]], yerr=[v["depth_se_mm"]], fmt="o", ms=4, color="tab:red")
                y = v["depth_mm"]
            else:
                y = v.get("fit_depth_mm")
                if y is None:
                    continue
                ax.plot([t], [y], "o", ms=4, mfc="none", color="0.5")
            ax.annotate(str(v["id"]), (t, y), xytext=(3, 3), textcoords="offset points", fontsize=7)
            lo_hi += [y]
        lo, hi = min(lo_hi) - 0.5, max(lo_hi) + 0.5
        x = np.array([lo, hi])
        ax.plot(x, x, "k-", lw=0.8)
        ax.fill_between(x, x - 0.5, x + 0.5, color="0.85", zorder=0)
        ax.plot([], [], "o", color="tab:red", label="resolved (+- 1 se)")
        ax.plot([], [], "o", mfc="none", color="0.5", label="unresolved (the fit's value)")
        ax.fill_between([], [], [], color="0.85", label="+- 0.5 mm")
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_xlabel("true depth of the top (mm)", fontsize=8)
        ax.set_ylabel("estimated depth of the top (mm)", fontsize=8)
        ax.set_title("estimated against true depth", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6, frameon=False, loc="upper left")
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return finish(fig, out)


def depth_validation_figure(rows, *, title=None, out=None):
    """Estimated against true depth of the vein's top over a validation (:mod:`planeray.experiments.skin_depth`).

    One colour per (tone, wavelength); resolved veins with 1-standard-error bars, unresolved ones hollow at
    the fit's value (grey edge); the identity and the +-0.5 mm band; the target's 1-3 mm shaded.
    """
    fig = new_figure((5.6, 4.6))
    ax = fig.add_subplot(1, 1, 1)
    conds = sorted({(r["tone"], r["wavelength_nm"]) for r in rows})
    xs = [r["true_depth_mm"] for r in rows] + [r["fit_depth_mm"] for r in rows if r["fit_depth_mm"] is not None]
    lo, hi = (min(xs) - 0.3, max(xs) + 0.3) if xs else (0.5, 5.5)
    x = np.array([lo, hi])
    ax.fill_between(x, x - 0.5, x + 0.5, color="0.88", zorder=0, label="+- 0.5 mm")
    ax.axvspan(1.0, 3.0, color="tab:green", alpha=0.06, zorder=0, label="target depths (1-3 mm)")
    ax.plot(x, x, "k-", lw=0.8)
    for i, c in enumerate(conds):
        sel = [r for r in rows if (r["tone"], r["wavelength_nm"]) == c]
        res = [r for r in sel if r["resolved"]]
        unr = [r for r in sel if not r["resolved"] and r["fit_depth_mm"] is not None]
        if res:
            ax.errorbar([r["true_depth_mm"] for r in res], [r["depth_mm"] for r in res],
                        yerr=[r["depth_se_mm"] for r in res], fmt="o", ms=4, color=f"C{i}",
                        label=f"{c[0]}, {c[1]} nm")  # fmt: skip
        if unr:
            ax.plot([r["true_depth_mm"] for r in unr], [r["fit_depth_mm"] for r in unr], "o", ms=5, mfc="none",
                    color=f"C{i}", mec="0.4")  # fmt: skip
    ax.plot([], [], "o", mfc="none", mec="0.4", color="0.4", label="unresolved (the fit's value)")
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_xlabel("true depth of the vein's top (mm)")
    ax.set_ylabel("estimated depth of the top (mm)")
    n_res = sum(r["resolved"] for r in rows)
    ax.set_title(title or f"Vein depth: {n_res}/{len(rows)} fits resolved", fontsize=9)
    ax.legend(fontsize=7, frameon=False, loc="upper left")
    fig.tight_layout()
    return finish(fig, out)


def _wrap(text: str, width: int = 48) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(text, width))
