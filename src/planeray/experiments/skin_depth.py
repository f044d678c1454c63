"""Validation of the vein depth fit (:mod:`planeray.skin.depth`) on the simulated skin scene.

Two layouts of veins, each captured with the paper's 85-image sweep, the default camera (noise,
row jitter, ambient light 0.5 e-/us) and fitted from the ground truth's vein masks:

``straight``
    four straight veins 50 mm apart, nearly down the image (tops 1, 2, 3, 1.5 mm deep; 2, 3,
    1.5, 4 mm across: :data:`STRAIGHT_VEINS`);
``forearm``
    the scene's own seeded forearm pattern (2-3 main veins along a random axis, 1-3 branches;
    tops 1-5 mm deep; :func:`planeray.scenes.skin.random_veins`).

:func:`depth_validation` returns one row per vein and condition (tone, wavelength, seed): the
true depth of the top and diameter, the estimate +- standard error, resolved or the reason.
:func:`depth_summary` counts them against the target (every resolved vein 1-3 mm deep
within 0.5 mm).  ``tools/skin_depth_table.py`` prints the table.
"""

from __future__ import annotations

import time

from ..camera import CameraModel
from ..scenes.skin import skin_veins
from ..skin.depth import fit_veins
from .skin_capture import simulate_skin

__all__ = ["STRAIGHT_VEINS", "CONDITIONS", "DEPTH_CONDITION", "depth_validation", "depth_summary"]

#: (depth of the top, diameter) of the straight layout's veins, mm.
STRAIGHT_VEINS = ((1.0, 2.0), (2.0, 3.0), (3.0, 1.5), (1.5, 4.0))
#: The validation's conditions: (tone, wavelength in nm).
CONDITIONS = (("fair", 638), ("fair", 850), ("dark", 638), ("dark", 850))
#: The condition ``skin compare`` (full) and ``planeray paper`` measure the forearm's vein depths in.
DEPTH_CONDITION = ("fair", 850)
#: The target: resolved veins this deep (mm, top) within TARGET_ERROR_MM.
TARGET_DEPTHS_MM = (1.0, 3.0)
TARGET_ERROR_MM = 0.5


def _straight_veins():
    return [
        dict(depth_mm=d, diameter_mm=D, points_mm=[[-10.0, 30.0 + 50.0 * i], [230.0, 38.0 + 50.0 * i]])
        for i, (d, D) in enumerate(STRAIGHT_VEINS)
    ]


def depth_validation(
    layout: str = "forearm",
    *,
    conditions=CONDITIONS,
    seeds=(0, 1),
    size=(128, 128),
    joint_rounds: int = 1,
    progress=None,
) -> list[dict]:
    """Fit every vein of simulated captures and compare with the truth.

    Parameters
    ----------
    layout : {"forearm", "straight"}
        The veins (see the module's docstring).
    conditions : sequence of (tone, wavelength_nm)
    seeds : sequence of int
        Seeds of the capture (skin texture, camera noise; the forearm's veins too).
    size : (int, int)
        Image size, pixels (over the paper's 720 projector rows, 0.3 mm each).
    joint_rounds : int
        Rounds of refitting each vein with its neighbours' shadows (:func:`planeray.skin.depth.fit_veins`).
    progress : callable, optional
        Called with a one-line message after each capture's fit.

    Returns
    -------
    list of dict
        Per vein: ``layout, tone, wavelength_nm, seed, id, parent, true_depth_mm, true_diameter_mm,
        resolved, reason, depth_mm, depth_se_mm, diameter_mm, diameter_se_mm, fit_depth_mm,
        fit_diameter_mm, error_mm`` (estimate - truth; None when unresolved), ``reduced_chi2``,
        ``seconds`` (of the capture's fit).
    """
    if layout not in ("forearm", "straight"):
        raise ValueError(f"layout must be 'forearm' or 'straight', got {layout!r}")
    rows = []
    for tone, wl in conditions:
        for seed in seeds:
            kw = {} if layout == "forearm" else {"veins": _straight_veins()}
            cap = simulate_skin(None, size=tuple(size), seed=seed, tone=tone, wavelength_nm=wl, **kw)
            st = cap.stack
            truth = {v.id: v for v in skin_veins(cap.scene)}
            t0 = time.perf_counter()
            fits, _, _ = fit_veins(
                st.images,
                st.bands(),
                st.geometry,
                cap.scene.maps["vein_id"],
                camera=CameraModel(**st.metadata["camera"]),
                excluded=st.excluded,
                tone=tone,
                wavelength_nm=wl,
                mm_per_row=0.3,
                joint_rounds=joint_rounds,
            )
            seconds = time.perf_counter() - t0
            for f in fits:
                v = truth[f.id]
                j = f.to_json()
                rows.append(
                    dict(
                        layout=layout,
                        tone=tone,
                        wavelength_nm=wl,
                        seed=seed,
                        id=f.id,
                        parent=v.parent,
                        true_depth_mm=v.depth_mm,
                        true_diameter_mm=v.diameter_mm,
                        resolved=f.resolved,
                        reason=f.reason,
                        depth_mm=j["depth_mm"],
                        depth_se_mm=j["depth_se_mm"],
                        diameter_mm=j["diameter_mm"],
                        diameter_se_mm=j["diameter_se_mm"],
                        fit_depth_mm=j["fit_depth_mm"],
                        fit_diameter_mm=j["fit_diameter_mm"],
                        error_mm=None if not f.resolved else round(f.depth_mm - v.depth_mm, 4),
                        reduced_chi2=j["reduced_chi2"],
                        seconds=round(seconds, 1),
                    )
                )
            if progress is not None:
                progress(f"{layout} {tone} {wl} nm seed {seed}: {len(fits)} veins, {seconds:.0f} s")
    return rows


def depth_summary(rows) -> dict:
    """Counts against the target: veins 1-3 mm deep (resolved, within 0.5 mm, worst error), deeper ones
    (resolved within 0.5 mm, resolved but wrong by more: the confidently wrong answers)."""
    lo, hi = TARGET_DEPTHS_MM
    tgt = [r for r in rows if lo <= r["true_depth_mm"] <= hi]
    deep = [r for r in rows if r["true_depth_mm"] > hi]
    res = [r for r in tgt if r["resolved"]]

    def wrong(rs):
        return [r for r in rs if r["resolved"] and abs(r["error_mm"]) > TARGET_ERROR_MM]

    return {
        "target_veins": len(tgt),
        "target_resolved": len(res),
        "target_within": sum(abs(r["error_mm"]) <= TARGET_ERROR_MM for r in res),
        "target_max_error_mm": max((abs(r["error_mm"]) for r in res), default=None),
        "deep_veins": len(deep),
        "deep_resolved": sum(r["resolved"] for r in deep),
        "deep_within": sum(r["resolved"] and abs(r["error_mm"]) <= TARGET_ERROR_MM for r in deep),
        "wrong": [(r["tone"], r["wavelength_nm"], r["seed"], r["id"]) for r in wrong(rows)],
        "max_abs_z": max(
            (abs(r["error_mm"]) / r["depth_se_mm"] for r in rows if r["resolved"] and r["depth_se_mm"]), default=None
        ),
    }


def format_table(rows) -> str:
    """The rows as a Markdown table (tone, wavelength, seed, vein, truth, estimate +- se, resolved or reason)."""
    out = [
        "| tone | nm | seed | vein | true top / D (mm) | top +- se (mm) | D +- se (mm) | error (mm) | resolved or why |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        par = f" (branch of {r['parent']})" if r["parent"] else ""
        if r["resolved"]:
            est = f"{r['depth_mm']:.2f} +- {r['depth_se_mm']:.2f}"
            dia = f"{r['diameter_mm']:.2f} +- {r['diameter_se_mm']:.2f}"
            err = f"{r['error_mm']:+.2f}"
            why = "resolved" + (f"; {r['reason']}" if r["reason"] else "")
        else:
            fd = r["fit_depth_mm"]
            est, dia, err = "-", "-", "-"
            why = f"unresolved: {r['reason']}" + ("" if fd is None else f" (fit {fd:.2f})")
        out.append(
            f"| {r['tone']} | {r['wavelength_nm']} | {r['seed']} | {r['id']}{par} | "
            f"{r['true_depth_mm']:.2f} / {r['true_diameter_mm']:.2f} | {est} | {dia} | {err} | {why} |"
        )
    return "\n".join(out)
