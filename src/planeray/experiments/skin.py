"""Seeing veins through skin, end to end (Sec. 10, Figs. 13, 14, 16): images, metrics, ambient light, Eq. 7.

:func:`run_skin_compare` (``planeray skin compare``) runs the whole study on the ``skin``
scene and writes its numbers and figures:

1. **Methods over conditions (Fig. 16).**  Skin tone (fair, dark), hair, wavelength
   (638 nm red, 850 nm NIR), each seeded forearm captured with every method of
   :mod:`planeray.skin.imaging` on the simulated device under office light (500 lx); per
   method the pooled CNR, Weber contrast and detected veins (per-vein CNR >= 1), per vein
   its depth, diameter and CNR.  The noise-free Weber contrast of the scene's transport is
   reported next to it.
2. **Ambient light (Fig. 13).**  The fair-skin, 638 nm forearm under
   :data:`planeray.skin.ambient.AMBIENT_LEVELS` (dark room to sunlight and the brightest
   surgical lamp): pooled CNR of every method against the illuminance.
3. **Depth.**  A ladder of straight veins 3 mm wide, tops 1-5 mm deep
   (:func:`ladder_veins`): which veins each method detects; and a delay sweep
   (:data:`SWEEP_EXPOSURE_US` = 300 us, delays 250-1000 us, three noise realizations): per
   vein, the delay of highest mean CNR against its depth, with a straight-line fit.
4. **Contrast enhancement (Eq. 7, Fig. 14).**  The ladder's sweep and a sweep of the forearm
   through :func:`planeray.skin.enhance.enhance_contrast`: CNR and detections against the
   best single delay image (raw, and with the same filtering), and the blurred delay map
   against the ground-truth depth of the pixels of the veins the composite shows (a
   straight-line fit depth ~ t_d*, its RMSE against the spread of the depths).

Metrics use only rows whose delay band lies on the projector for every delay used (near the
bottom of the image the band of a long delay falls off the projector and the image darkens
for that reason alone) and leave out hair and pixels off the skin.
"""

from __future__ import annotations

import csv
import io
import json
import time
from pathlib import Path

import numpy as np

from ..camera import CameraModel
from ..io import atomic_directory, jsonable
from ..io.atomic import MARKER, check_replaceable
from ..skin.ambient import AMBIENT_LEVELS, ambient_e_per_us, ambient_table
from ..skin.enhance import enhance_contrast
from ..skin.imaging import (
    DEFAULT_DELAY_US,
    DEFAULT_EXPOSURE_US,
    METHODS,
    band_record,
    delay_band_mm,
    delay_band_rows,
    device_images,
    direct_exposure_us,
    epipolar_record,
    mm_per_row,
    pixel_mm,
    truth_images,
)
from ..skin.metrics import band_definition, vein_metrics
from ..timing import PAPER_LINES_PER_SECOND, PAPER_PROJECTOR_ROWS
from .skin_depth import DEPTH_CONDITION, depth_summary, depth_validation

__all__ = [
    "REPORT_FORMAT",
    "CONDITIONS",
    "ROOM_LIGHT",
    "SWEEP_DELAYS_US",
    "SWEEP_EXPOSURE_US",
    "LADDER_DEPTHS_MM",
    "ladder_veins",
    "skin_scene",
    "camera_at",
    "scene_truth",
    "valid_rows",
    "scene_pixel_mm",
    "measure",
    "capture_delay_sweep",
    "best_delay_by_depth",
    "depth_from_delay_map",
    "run_skin_compare",
    "compare_steps",
    "compare_delay_range_us",
    "MIN_SIZE",
]

REPORT_FORMAT = "planeray-skin-report"
#: Condition name -> keyword arguments of ``make_scene("skin", ...)``.
CONDITIONS = {
    "fair, 638 nm": dict(tone="fair", wavelength_nm=638),
    "dark, 638 nm": dict(tone="dark", wavelength_nm=638),
    "fair, 638 nm, hair": dict(tone="fair", wavelength_nm=638, hair=True),
    "fair, 850 nm": dict(tone="fair", wavelength_nm=850),
    "dark, 850 nm": dict(tone="dark", wavelength_nm=850),
}
QUICK_CONDITIONS = ("fair, 638 nm", "dark, 638 nm")
#: The depth ladder: straight veins across the image (perpendicular to the projector rows),
#: 3 mm wide, their tops at these depths (the range of the scene's vein tables).
LADDER_DEPTHS_MM = (1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0)
LADDER_DIAMETER_MM = 3.0
#: The ambient level of the method comparison (:data:`AMBIENT_LEVELS`).
ROOM_LIGHT = "office"
QUICK_LEVELS = ("dark", "office", "surgical lamp", "sunlight")
#: Delays and exposure of the sweep (Eq. 7 and the best delay against depth): every band off the
#: epipolar plane (``t_d - t_e/2 >= 100 us``) and inside the skin scene's offset band (64 rows).
SWEEP_DELAYS_US = np.arange(250.0, 1000.1, 50.0)
SWEEP_EXPOSURE_US = 300.0


def skin_scene(shape, *, seed: int = 0, **conditions):
    """The ``skin`` scene of a 720-row projector (see :func:`planeray.scenes.make_scene`)."""
    from ..scenes import make_scene

    return make_scene("skin", tuple(shape), projector_rows=PAPER_PROJECTOR_ROWS, seed=seed, **conditions)


def ladder_veins(shape, projector_rows=PAPER_PROJECTOR_ROWS, mm_per_row=0.3, depths_mm=LADDER_DEPTHS_MM):
    """Straight veins down the image (x: down, y: across, surface mm), evenly spaced, one per depth."""
    height = projector_rows * mm_per_row
    width = shape[1] * projector_rows * mm_per_row / shape[0]
    ys = (np.arange(len(depths_mm)) + 1.0) * width / (len(depths_mm) + 1.0)
    return [
        {"depth_mm": float(d), "diameter_mm": LADDER_DIAMETER_MM, "points_mm": [[0.0, float(y)], [height, float(y)]]}
        for d, y in zip(depths_mm, ys)
    ]


def camera_at(level: str, wavelength_nm: float, camera: CameraModel | None = None) -> CameraModel:
    """The camera with the ambient light of ``level`` (:data:`AMBIENT_LEVELS`) at ``wavelength_nm``."""
    import dataclasses

    camera = camera or CameraModel()
    lux, kind = AMBIENT_LEVELS[level]
    amb = ambient_e_per_us(lux, kind, wavelength_nm, laser_electrons=camera.laser_electrons)
    return dataclasses.replace(camera, ambient_e_per_us=amb)


def scene_truth(scene) -> dict:
    """Ground truth of a skin scene for :func:`~planeray.skin.metrics.vein_metrics`."""
    m = scene.maps
    ids = m.get("vein_id")
    if ids is None:
        ids = m["vein_mask"]
    exclude = np.asarray(m["hair"], bool) if "hair" in m else None
    if "skin" in m:  # off the skin (a curved arm on its cloth)
        off = ~np.asarray(m["skin"], bool)
        exclude = off if exclude is None else exclude | off
    return {
        "vein_id": np.asarray(ids),
        "exclude": exclude,
        "depth_mm": m.get("vein_depth_mm"),
        "diameter_mm": m.get("vein_diameter_mm"),
    }


def valid_rows(scene, max_delay_us: float, exposure_us: float, *, lines_per_second=PAPER_LINES_PER_SECOND):
    """Pixels whose delay band (up to ``max_delay_us``) lies entirely on the projector (H, W) bool."""
    g = scene.geometry
    _, far = delay_band_rows(max_delay_us, exposure_us, lines_per_second=lines_per_second)
    rows = g.projector_row_of(np.arange(g.camera_rows)) + float(far) <= g.projector_rows - 0.5
    return np.broadcast_to(rows[:, None], scene.shape).copy()


def scene_pixel_mm(scene) -> float:
    """Size of the scene's camera pixels on the skin, mm (:func:`~planeray.skin.imaging.pixel_mm`)."""
    return pixel_mm(scene.geometry, mm_per_row(scene))


def measure(images: dict, scene, valid=None) -> dict:
    """:func:`~planeray.skin.metrics.vein_metrics` of every image on the scene's veins (band in mm on its skin)."""
    t = scene_truth(scene)
    return {
        k: vein_metrics(
            v,
            t["vein_id"],
            mm_per_px=scene_pixel_mm(scene),
            exclude=t["exclude"],
            depth_mm=t["depth_mm"],
            diameter_mm=t["diameter_mm"],
            valid=valid,
        )
        for k, v in images.items()
    }


def capture_delay_sweep(scene, camera, delays_us, *, exposure_us=DEFAULT_EXPOSURE_US, seed=0):
    """Synchronized delay images (dark frame removed, transport units) of the simulated device, (N, H, W)."""
    imgs = []
    for i, d in enumerate(delays_us):
        im, _ = device_images(
            scene, camera, delay_us=float(d), exposure_us=exposure_us, seed=seed + i, methods=("delay",)
        )
        imgs.append(im["delay"])
    return np.stack(imgs)


def _fit(x, y) -> dict | None:
    from scipy.stats import linregress

    x, y = np.asarray(x, float), np.asarray(y, float)
    if x.size < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return None
    r = linregress(x, y)
    resid = y - (r.intercept + r.slope * x)
    return {
        "slope": float(r.slope),
        "intercept": float(r.intercept),
        "r": float(r.rvalue),
        "p": float(r.pvalue),
        "n": int(x.size),
        "rmse": float(np.sqrt(np.mean(resid**2))),
        "spread": float(np.std(y)),
    }


def best_delay_by_depth(images, delays_us, scene, valid=None) -> dict:
    """Per vein: CNR at every delay, the delay of highest CNR, the vein's depth; fit best delay ~ depth.

    ``images`` is one sweep (N, H, W) or several noise realizations of it (R, N, H, W): the
    per-vein CNR is then averaged over them before the argmax (a steadier best delay).  Only
    veins detected (mean CNR >= 1, darker than their band in most realizations) at their best
    delay enter the fit.
    """
    stacks = np.asarray(images)
    stacks = stacks[None] if stacks.ndim == 3 else stacks

    def metrics(im):
        return measure({0: im}, scene, valid)[0]

    runs = [[metrics(im) for im in sweep] for sweep in stacks]  # [repeat][delay]
    per_delay = runs[0]
    veins = []
    for j, v in enumerate(per_delay[0]["veins"]):
        cnrs, dets = [], []
        for i in range(len(delays_us)):
            vals_r = [run[i]["veins"][j]["cnr"] for run in runs]
            cnrs.append(None if any(c is None for c in vals_r) else float(np.mean(vals_r)))
            dets.append(
                cnrs[-1] is not None
                and cnrs[-1] >= 1.0
                and np.mean([run[i]["veins"][j]["mu_vein"] < run[i]["veins"][j]["mu_bg"] for run in runs]) > 0.5
            )
        vals = np.array([-np.inf if c is None else c for c in cnrs])
        k = int(np.argmax(vals))
        veins.append(
            {
                "id": v["id"],
                "depth_mm": v.get("depth_mm"),
                "diameter_mm": v.get("diameter_mm"),
                "cnr_by_delay": cnrs,
                "best_delay_us": float(delays_us[k]) if np.isfinite(vals[k]) else None,
                "best_cnr": float(vals[k]) if np.isfinite(vals[k]) else None,
                "detected": bool(dets[k]),
            }
        )
    used = [v for v in veins if v["detected"] and v["depth_mm"] is not None]
    fit = _fit([v["depth_mm"] for v in used], [v["best_delay_us"] for v in used])
    return {
        "delays_us": [float(d) for d in delays_us],
        "repeats": int(stacks.shape[0]),
        "veins": veins,
        "fit_delay_vs_depth": fit,
    }


def depth_from_delay_map(delay_map_us, scene, valid=None, *, veins=None) -> dict:
    """Does Eq. 7's delay map estimate depth?  Fit depth ~ t_d* on vein pixels and per vein (median).

    Returns the pixel fit and the per-vein fit (``rmse`` in mm, ``spread`` the standard
    deviation of the true depths: the error of always guessing the mean depth).  ``veins``
    (ids) restricts the fit to those veins -- the ones the enhanced image shows: a vein it does
    not show has no edge of its own, and its delay is the fallback's, not a measurement.
    """
    t = scene_truth(scene)
    depth = t["depth_mm"]
    if depth is None:
        return {}
    depth = np.asarray(depth, float)
    on = np.isfinite(depth) & (np.asarray(t["vein_id"]) > 0)
    if t["exclude"] is not None:
        on &= ~t["exclude"]
    if valid is not None:
        on &= valid
    ids = np.asarray(t["vein_id"])
    if veins is not None:
        on &= np.isin(ids, np.asarray(list(veins), int))
    per_vein = []
    for k in np.unique(ids[on]):
        sel = on & (ids == k)
        per_vein.append(
            {"id": int(k), "depth_mm": float(np.median(depth[sel])), "delay_us": float(np.median(delay_map_us[sel]))}
        )
    pix = _fit(delay_map_us[on], depth[on])
    vein = _fit([v["delay_us"] for v in per_vein], [v["depth_mm"] for v in per_vein])
    return {"pixels": pix, "veins": per_vein, "per_vein_fit": vein}


#: The smallest image the study runs on (its metrics need a few pixels of background beside each vein).
MIN_SIZE = 16


def compare_delay_range_us(exposure_us: float = DEFAULT_EXPOSURE_US, *, lines_per_second=PAPER_LINES_PER_SECOND):
    """Delays whose band of ``exposure_us`` leaves the epipolar plane and stays inside the skin scene's kernel.

    ``(t_e / 2, K / v_p - t_e / 2]`` with ``K`` = :data:`planeray.scenes.skin.SKIN_BAND_ROWS` (64 rows,
    where the kernel has fallen below 1e-6): ``(300, 885.2]`` us at 600 us and 54,000 lines/s.
    """
    from ..scenes.skin import SKIN_BAND_ROWS

    half = 0.5 * float(exposure_us)
    return half, SKIN_BAND_ROWS / float(lines_per_second) * 1e6 - half


def compare_steps(quick: bool = False) -> int:
    """Progress steps of :func:`run_skin_compare` (conditions, ambient levels, sweep, enhancement, figures)."""
    n_cond = len(QUICK_CONDITIONS) if quick else len(CONDITIONS)
    n_lev = sum(1 for k in AMBIENT_LEVELS if (k in QUICK_LEVELS or not quick))
    return n_cond + n_lev + 3 + (0 if quick else 1)  # the full run also measures the veins' depth


def _csv(rows: list[dict]) -> str:
    buf = io.StringIO()
    if rows:
        w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    return buf.getvalue()


def run_skin_compare(
    out_dir=None,
    *,
    size: int = 128,
    quick: bool = False,
    seed: int = 0,
    delay_us: float = DEFAULT_DELAY_US,
    exposure_us: float = DEFAULT_EXPOSURE_US,
    overwrite: bool = False,
    scene_factory=None,
    progress=None,
) -> dict:
    """The Fig. 13/14/16 study: write ``skin.json``, CSV tables and the figures into ``out_dir``.

    Parameters
    ----------
    out_dir : path, optional
        Output folder (replaced only with ``overwrite`` and only if it is such a report);
        None computes the numbers only.
    size : int
        Image size (``size x size`` camera pixels of a 720-row projector).
    quick : bool
        Two conditions, four ambient levels, every other sweep delay (for tests and a first look).
    seed : int
        Seed of the scenes and the camera noise.
    delay_us, exposure_us : float
        The short-range indirect delay image compared with the other methods.
    scene_factory : callable, optional
        ``scene_factory(shape, seed=..., **conditions)`` -> Scene; default :func:`skin_scene`.
    progress : callable, optional
        Called with a short description of each step.

    Returns
    -------
    dict
        The numbers written to ``skin.json``.
    """
    from .._validate import check_integer, check_number
    from ..figures import skin as figs

    check_integer(size, "size", minimum=MIN_SIZE)
    lo, hi = compare_delay_range_us(exposure_us)
    check_number(
        delay_us,
        "delay_us",
        minimum=lo,
        maximum=hi,
        min_inclusive=False,
        requirement=f"a delay in us, > {lo:g} and <= {hi:.1f} (the band of t_e = {exposure_us:g} us must leave "
        "the epipolar plane and stay inside the skin scene's 64-row kernel)",
    )
    if out_dir is not None:
        check_replaceable(Path(out_dir), overwrite=overwrite, kind="skin report")
    factory = scene_factory or skin_scene
    t0 = time.perf_counter()

    def step(msg):
        if progress is not None:
            progress(msg)

    shape = (int(size), int(size))
    conditions = {k: CONDITIONS[k] for k in (QUICK_CONDITIONS if quick else CONDITIONS)}
    levels = [k for k in AMBIENT_LEVELS if (k in QUICK_LEVELS or not quick)]
    sweep = SWEEP_DELAYS_US[::2] if quick else SWEEP_DELAYS_US
    lps = PAPER_LINES_PER_SECOND
    numbers: dict = {
        "size": list(shape),
        "projector_rows": PAPER_PROJECTOR_ROWS,
        "seed": seed,
        "delay_us": delay_us,
        "exposure_us": exposure_us,
        "room_light": ROOM_LIGHT,
        "methods": METHODS,
    }
    figures_out: dict = {}

    # 1. methods over conditions (Fig. 16)
    table, vein_rows, panels, scenes = [], [], [], {}
    for name, kw in conditions.items():
        step(f"methods: {name}")
        scene = factory(shape, seed=seed, **kw)
        scenes[name] = scene
        valid = valid_rows(scene, delay_us, exposure_us, lines_per_second=lps)
        wl = float(kw.get("wavelength_nm", 638))
        imgs, info = device_images(
            scene,
            camera_at(ROOM_LIGHT, wl),
            delay_us=delay_us,
            exposure_us=exposure_us,
            lines_per_second=lps,
            seed=seed,
        )
        truth = truth_images(scene, delay_us=delay_us, exposure_us=exposure_us, lines_per_second=lps)
        m, mt = measure(imgs, scene, valid), measure(truth, scene, valid)
        for meth in METHODS:
            table.append(
                {
                    "condition": name,
                    "method": meth,
                    "cnr": m[meth]["cnr"],
                    "weber": m[meth]["weber"],
                    "n_detected": m[meth]["n_detected"],
                    "n_veins": m[meth]["n_veins"],
                    "truth_weber": mt[meth]["weber"],
                    "truth_n_dark": int(sum(1 for v in mt[meth]["veins"] if (v["weber"] or 0) < 0)),
                    "captures": info["captures"][meth],
                }
            )
            for v in m[meth]["veins"]:
                vein_rows.append(
                    {
                        "condition": name,
                        "method": meth,
                        "vein": v["id"],
                        "depth_mm": v.get("depth_mm"),
                        "diameter_mm": v.get("diameter_mm"),
                        "cnr": v["cnr"],
                        "weber": v["weber"],
                        "detected": v["detected"],
                    }
                )
        panels.append({"condition": name, "images": imgs, "metrics": m, "valid": valid, "truth": scene_truth(scene)})
        numbers.setdefault("photo_attenuation", {})[name] = info["photo_attenuation"]
    numbers["table"] = table
    numbers["veins"] = vein_rows
    first = next(iter(conditions))
    base_scene = scenes[first]
    mpr = mm_per_row(base_scene)
    near, far = delay_band_mm(delay_us, exposure_us, lines_per_second=lps, mm_per_row=mpr)
    numbers["delay_band_mm"] = [float(near), float(far)]
    numbers["mm_per_row"] = mpr
    numbers["metric"] = band_definition(scene_pixel_mm(base_scene))
    g = base_scene.geometry
    numbers["method_bands"] = {
        "direct": band_record(
            0.0, direct_exposure_us(g, lines_per_second=lps), lines_per_second=lps, mm_per_row=mpr, geometry=g
        ),
        "delay": band_record(delay_us, exposure_us, lines_per_second=lps, mm_per_row=mpr, geometry=g),
        "direct_truth": epipolar_record(g, mm_per_row=mpr, source="truth_weber of the direct method (noise-free)"),
    }

    # 2. ambient light (Fig. 13)
    wl0 = float(conditions[first].get("wavelength_nm", 638))
    valid0 = valid_rows(base_scene, delay_us, exposure_us, lines_per_second=lps)
    amb_rows, strongest = [], None
    for level in levels:
        step(f"ambient light: {level}")
        cam = camera_at(level, wl0)
        imgs, info = device_images(
            base_scene, cam, delay_us=delay_us, exposure_us=exposure_us, lines_per_second=lps, seed=seed + 1
        )
        m = measure(imgs, base_scene, valid0)
        lux, kind = AMBIENT_LEVELS[level]
        for meth in METHODS:
            amb_rows.append(
                {
                    "level": level,
                    "lux": lux,
                    "ambient_e_per_us": cam.ambient_e_per_us,
                    "method": meth,
                    "cnr": m[meth]["cnr"],
                    "n_detected": m[meth]["n_detected"],
                    "n_veins": m[meth]["n_veins"],
                    "saturated_pixels": info["saturated_pixels"].get(meth),
                }
            )
        strongest = (level, imgs, m)
    numbers["ambient"] = amb_rows
    numbers["ambient_levels"] = ambient_table(wl0)

    # 3. the depth ladder: detection and best delay against depth; 4. contrast enhancement (Eq. 7)
    step("depth ladder")
    ladder = factory(shape, seed=seed, **conditions[first], veins=ladder_veins(shape, mm_per_row=mpr))
    valid_l = valid_rows(ladder, max(delay_us, float(sweep[-1])), SWEEP_EXPOSURE_US, lines_per_second=lps)
    valid_l &= valid_rows(ladder, delay_us, exposure_us, lines_per_second=lps)
    cam_room = camera_at(ROOM_LIGHT, wl0)
    imgs, _ = device_images(
        ladder, cam_room, delay_us=delay_us, exposure_us=exposure_us, lines_per_second=lps, seed=seed
    )
    m = measure(imgs, ladder, valid_l)
    ladder_rows = [
        {"method": meth, "vein": v["id"], "depth_mm": v.get("depth_mm"), "cnr": v["cnr"], "detected": v["detected"]}
        for meth in METHODS
        for v in m[meth]["veins"]
    ]
    numbers["ladder"] = {"veins": ladder_rows, "n_detected": {k: m[k]["n_detected"] for k in METHODS}}
    repeats = 1 if quick else 3
    sweeps = np.stack(
        [
            capture_delay_sweep(ladder, cam_room, sweep, exposure_us=SWEEP_EXPOSURE_US, seed=seed + 100 + 1000 * r)
            for r in range(repeats)
        ]
    )
    best = best_delay_by_depth(sweeps, sweep, ladder, valid_l)
    best["exposure_us"] = SWEEP_EXPOSURE_US
    numbers["best_delay"] = best

    def enhancement(scene, sweep_imgs, valid):
        enh = enhance_contrast(sweep_imgs, sweep)
        single = measure({f"{d:g}": im for d, im in zip(sweep, sweep_imgs)}, scene, valid)
        best_key = max(single, key=lambda k: -np.inf if single[k]["cnr"] is None else single[k]["cnr"])
        filtered = measure({f"{d:g}": im for d, im in zip(enh.delays_us, enh.normalized)}, scene, valid)
        best_f = max(filtered, key=lambda k: -np.inf if filtered[k]["cnr"] is None else filtered[k]["cnr"])
        em = measure({"enhanced": enh.image}, scene, valid)["enhanced"]
        b = single[best_key]["cnr"]
        return enh, {
            "params": enh.params,
            "exposure_us": SWEEP_EXPOSURE_US,
            "single": {k: {"cnr": v["cnr"], "n_detected": v["n_detected"]} for k, v in single.items()},
            "best_single_delay_us": float(best_key),
            "best_single_cnr": b,
            "best_single_detected": single[best_key]["n_detected"],
            "best_filtered_delay_us": float(best_f),
            "best_filtered_cnr": filtered[best_f]["cnr"],
            "enhanced_cnr": em["cnr"],
            "enhanced_detected": em["n_detected"],
            "n_veins": em["n_veins"],
            "gain": (em["cnr"] / b) if em["cnr"] and b else None,
            "gain_over_filtered": (em["cnr"] / filtered[best_f]["cnr"])
            if em["cnr"] and filtered[best_f]["cnr"]
            else None,
            "depth_from_delay_map": depth_from_delay_map(
                enh.delay_map_us, scene, valid, veins=[v["id"] for v in em["veins"] if v["detected"]]
            ),
            "depth_from_delay_map_all_veins": depth_from_delay_map(enh.delay_map_us, scene, valid),
        }

    step("contrast enhancement (Eq. 7)")
    enh_l, numbers["enhancement"] = enhancement(ladder, sweeps[0], valid_l)
    valid_f = valid_rows(base_scene, float(sweep[-1]), SWEEP_EXPOSURE_US, lines_per_second=lps)
    forearm_sweep = capture_delay_sweep(base_scene, cam_room, sweep, exposure_us=SWEEP_EXPOSURE_US, seed=seed + 50)
    enh_f, numbers["enhancement_forearm"] = enhancement(base_scene, forearm_sweep, valid_f)
    depth_rows = None
    if not quick:  # 5. beyond the paper: each vein's depth, fitted from a whole sweep (planeray skin depth)
        step("vein depth (skin depth)")
        depth_rows = depth_validation("forearm", conditions=(DEPTH_CONDITION,), seeds=(seed,), size=shape)
        numbers["vein_depth"] = {
            "condition": {"tone": DEPTH_CONDITION[0], "wavelength_nm": DEPTH_CONDITION[1]},
            "summary": depth_summary(depth_rows),
            "veins": depth_rows,
        }
    numbers["seconds"] = time.perf_counter() - t0

    if out_dir is not None:
        step("figures")
        labels = {"delay": f"short-range (t_d/t_e {delay_us:g}/{exposure_us:g} us)"}
        figures_out = {
            "fig16_skin_methods.png": lambda p: figs.methods_figure(panels, labels=labels, out=p),
            "fig16_skin_depth.png": lambda p: figs.vein_depth_figure(
                [{**r, "condition": "depth ladder"} for r in ladder_rows],
                light=f"{ROOM_LIGHT} light, {AMBIENT_LEVELS[ROOM_LIGHT][0]:g} lx",
                out=p,
            ),
            "fig13_skin_ambient.png": lambda p: figs.ambient_figure(
                amb_rows, strongest, valid=valid0, labels=labels, out=p
            ),
            "skin_best_delay.png": lambda p: figs.best_delay_figure(best, out=p),
            "fig14_skin_enhance.png": lambda p: figs.enhancement_figure(
                sweeps[0][list(sweep).index(numbers["enhancement"]["best_single_delay_us"])],
                numbers["enhancement"]["best_single_delay_us"],
                enh_l,
                scene_truth(ladder),
                numbers["enhancement"],
                valid=valid_l,
                out=p,
            ),
            "fig14_skin_enhance_forearm.png": lambda p: figs.enhancement_figure(
                forearm_sweep[list(sweep).index(numbers["enhancement_forearm"]["best_single_delay_us"])],
                numbers["enhancement_forearm"]["best_single_delay_us"],
                enh_f,
                scene_truth(base_scene),
                numbers["enhancement_forearm"],
                valid=valid_f,
                out=p,
            ),
        }
        if depth_rows is not None:
            figures_out["fig14_vein_depth.png"] = lambda p: figs.depth_validation_figure(
                depth_rows, title=f"Vein depth, forearm, {DEPTH_CONDITION[0]} skin, {DEPTH_CONDITION[1]} nm", out=p
            )
        with atomic_directory(Path(out_dir), overwrite=overwrite, kind="skin report") as tmp:
            (tmp / MARKER).write_text(json.dumps({"format": REPORT_FORMAT, "format_version": 1}, indent=1))
            (tmp / "skin.json").write_text(json.dumps(jsonable(numbers), indent=1))
            (tmp / "skin_cnr.csv").write_text(_csv(jsonable(table)))
            (tmp / "skin_veins.csv").write_text(_csv(jsonable(vein_rows)))
            (tmp / "skin_ambient.csv").write_text(_csv(jsonable(amb_rows)))
            for name, draw in figures_out.items():
                draw(tmp / name)
        numbers["figures"] = list(figures_out)
    return jsonable(numbers)
