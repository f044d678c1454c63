"""Material recognition from delay profiles, end to end (Sec. 8, Fig. 10): captures, models, numbers, figures.

* :func:`simulate_capture`: a capture of the ``materials`` scene on the simulated device
  (the paper's sweep), with its ground truth, optionally written as a folder
  (``stack.zarr``, ``labels.png``, ``near_wall.png``, ``photo.png``, ``planeray.json``);
* :func:`score`: per-class accuracy overall, near the walls and away from them, the
  confusion matrix, and where the errors fall;
* :func:`run_materials_report`: the whole experiment -- train on one capture, test on
  another (other seed, noise, ambient light, placement), stack profiles against
  transport profiles, accuracy as noise and ambient light grow, the Jensen data set
  against Narasimhan's -- writing the figures of Fig. 10 and ``materials.json``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..acquire import simulate_stack
from ..camera import CameraModel
from ..errors import InputError
from ..figures import materials as figs
from ..io import atomic_directory, atomic_file, write_stack
from ..io.atomic import MARKER
from ..materials import (
    BACKGROUND_CLASS,
    CLASS_NAMES,
    MATERIAL_CLASSES,
    capture_features,
    capture_transport,
    optical_table,
    train_model,
    write_label_image,
)
from ..scenes import make_scene
from ..timing import PAPER_PROJECTOR_ROWS, make_sweep
from ._report import jsonable

__all__ = [
    "CAPTURE_FORMAT",
    "REPORT_FORMAT",
    "Capture",
    "camera_for",
    "simulate_capture",
    "score",
    "run_materials_report",
    "TRAIN_SETTINGS",
    "TEST_SETTINGS",
]

CAPTURE_FORMAT = "planeray-materials-capture"
REPORT_FORMAT = "planeray-materials-report"
#: The training capture of the report: the default camera, ambient light and placement.
TRAIN_SETTINGS = dict(seed=0, placement=0, noise=1.0, ambient_e_per_us=0.5)
#: The held-out test capture: another seed, 1.5x the noise, 3x the ambient light, another placement.
TEST_SETTINGS = dict(seed=1, placement=1, noise=1.5, ambient_e_per_us=1.5)


def camera_for(*, noise: float = 1.0, ambient_e_per_us: float = 0.5) -> CameraModel:
    """The default camera with ``noise`` times its noise at the same image levels.

    Laser electrons, full well and ambient electrons are divided by ``noise^2`` and the
    read noise by ``noise``: every image keeps its expected value (normalized units) and
    its shot and read noise grow ``noise``-fold -- a dimmer laser or a darker scene.
    ``ambient_e_per_us`` is given at the default camera's scale (0.5: the simulator's
    room light).
    """
    noise, ambient = float(noise), float(ambient_e_per_us)
    if not np.isfinite(noise) or noise <= 0:
        raise InputError(f"noise must be a positive factor, got {noise!r}")
    if not np.isfinite(ambient) or ambient < 0:
        raise InputError(f"ambient_e_per_us must be >= 0, got {ambient!r}")
    base = CameraModel()
    s2 = noise * noise
    return CameraModel(
        laser_electrons=base.laser_electrons / s2,
        full_well_e=base.full_well_e / s2,
        read_noise_e=base.read_noise_e / noise,
        ambient_e_per_us=ambient / s2,
    )


@dataclass
class Capture:
    """A simulated capture of the ``materials`` scene with its ground truth.

    Attributes
    ----------
    stack : Stack
    labels : ndarray (H, W) uint8
        Class ids (1-5 materials, 6 background).
    near_wall : ndarray (H, W) bool
        Container pixels whose kernel the walls change by more than 5 %.
    wall_distance_mm : ndarray (H, W) float32
        Distance to the nearest wall of the pixel's container (``inf`` on the table).
    photo : ndarray (H, W) float32
        What an ordinary camera sees under room light (the scene's ambient albedo).
    settings : dict
        The parameters of the capture.
    """

    stack: object
    labels: np.ndarray
    near_wall: np.ndarray
    wall_distance_mm: np.ndarray
    photo: np.ndarray
    settings: dict


def simulate_capture(
    out=None,
    *,
    size=(128, 128),
    projector_rows: int = PAPER_PROJECTOR_ROWS,
    seed: int = 0,
    placement: int = 0,
    container: str = "tray",
    wall: str = "fresnel",
    source: str = "narasimhan",
    channel: str = "red",
    noise: float = 1.0,
    ambient_e_per_us: float = 0.5,
    sweep: str = "paper",
    overwrite: bool = False,
    progress=None,
) -> Capture:
    """Simulate one capture of the ``materials`` scene (and write it as a folder if ``out`` is given).

    Parameters
    ----------
    out : path, optional
        Folder to write: ``stack.zarr`` (native stack), ``labels.png`` (class ids, palette
        PNG), ``near_wall.png`` (255 on pixels near a wall), ``photo.png`` and
        ``planeray.json`` (the settings and the class list).  Replaced only with
        ``overwrite`` and only if it is a capture planeray wrote.
    size : (int, int)
        Image size ``(H, W)``.
    projector_rows : int
        Projector rows the image spans (0.3 mm each).
    seed : int
        Noise and texture seed.
    placement, container, wall, source, channel
        The scene's parameters (:mod:`planeray.scenes.materials`).
    noise : float
        Noise factor (:func:`camera_for`).
    ambient_e_per_us : float
        Ambient light (electrons per microsecond of row exposure, default camera scale).
    sweep : str
        Sweep name (``"paper"``: 17 delays x 5 exposures).
    progress : callable, optional
        Called with the index of each simulated image.
    """
    from ..io.atomic import check_replaceable

    if out is not None:
        check_replaceable(out, overwrite=overwrite, kind="materials capture")
    H, W = (int(v) for v in size)
    scene = make_scene(
        "materials",
        (H, W),
        projector_rows=projector_rows,
        seed=seed,
        placement=placement,
        container=container,
        wall=wall,
        source=source,
        channel=channel,
    )
    camera = camera_for(noise=noise, ambient_e_per_us=ambient_e_per_us)
    stack = simulate_stack(scene, make_sweep(sweep), camera=camera, seed=seed, progress=progress)
    settings = dict(
        size=[H, W],
        projector_rows=int(projector_rows),
        seed=int(seed),
        placement=int(placement),
        container=container,
        wall=wall,
        source=source,
        channel=channel,
        noise=float(noise),
        ambient_e_per_us=float(ambient_e_per_us),
        sweep=sweep,
    )
    cap = Capture(
        stack,
        scene.maps["material"].astype(np.uint8),
        scene.maps["near_wall"].astype(bool),
        scene.maps["wall_distance_mm"].astype(np.float32),
        scene.ambient_albedo.astype(np.float32),
        settings,
    )
    if out is not None:
        write_capture(cap, out, overwrite=overwrite, scene_params=scene.params)
    return cap


def _write_png8(path, image):
    """An 8-bit grayscale PNG of an image in [0, 1]."""
    from PIL import Image

    with atomic_file(path) as tmp:
        Image.fromarray((np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8)).save(tmp, format="PNG")


def write_capture(cap: Capture, out, *, overwrite=False, scene_params=None) -> Path:
    """Write a capture folder (see :func:`simulate_capture`), atomically."""
    out = Path(out)
    with atomic_directory(out, overwrite=overwrite, kind="materials capture") as tmp:
        write_stack(cap.stack, tmp / "stack.zarr")
        write_label_image(tmp / "labels.png", cap.labels)
        write_label_image(tmp / "near_wall.png", np.where(cap.near_wall, 255, 0))
        _write_png8(tmp / "photo.png", cap.photo)
        meta = {
            "format": CAPTURE_FORMAT,
            "format_version": 1,
            "files": {
                "stack": "stack.zarr",
                "labels": "labels.png",
                "near_wall": "near_wall.png",
                "photo": "photo.png",
            },
            "classes": {str(k): v for k, v in CLASS_NAMES.items()},
            "unlabelled": 0,
            "settings": cap.settings,
            "scene": scene_params or {},
        }
        (tmp / MARKER).write_text(json.dumps(meta, indent=1))
    return out


# ---------------------------------------------------------------- scoring
#: Bins of distance to the wall (mm) of the accuracy-by-distance curve.
DISTANCE_BINS_MM = (0.0, 2.0, 4.0, 7.0, 10.0, 15.0, np.inf)


def score(pred, truth, *, near_wall=None, wall_distance_mm=None, classes=None, model_classes=None) -> dict:
    """Per-class accuracy (recall) of a segmentation against ground truth, and where the errors are.

    Parameters
    ----------
    pred, truth : ndarray (H, W) int
        Predicted and true class ids (truth 0: not scored).
    near_wall : ndarray (H, W) bool, optional
        Pixels near a container wall: accuracies are also given near and away from walls.
    wall_distance_mm : ndarray (H, W), optional
        Distance to the wall: accuracy of the materials by distance bin.
    classes : sequence of int, optional
        Classes of the confusion matrix (default: those in ``truth``).
    model_classes : sequence of int, optional
        The classes the model can predict.  A class of ``classes`` outside them
        is *not scored*: its accuracies are ``None`` (not 0: the model never had
        the chance), it is named under ``not_scored`` with the reason, and its
        pixels are left out of ``overall``, ``min_material_accuracy``, ``errors``
        and ``by_distance_mm`` (its row of the confusion matrix still shows what
        they were taken for).

    Returns
    -------
    dict
        ``accuracy`` (per class name), ``accuracy_near_wall``, ``accuracy_interior``,
        ``pixels`` (per class, all / near wall), ``confusion`` (``classes``, ``matrix``
        counts, rows true, columns predicted; a last column for 0 = no prediction),
        ``overall`` (material pixels), ``min_material_accuracy``, ``errors`` (material
        pixels misclassified, and the share of them near a wall), ``by_distance_mm``;
        with ``model_classes``, ``not_scored`` (class name -> reason, empty if none).
    """
    pred = np.asarray(pred)
    truth = np.asarray(truth)
    scored = truth > 0
    classes = sorted(int(c) for c in np.unique(truth[scored])) if classes is None else [int(c) for c in classes]
    names = {c: CLASS_NAMES.get(c, f"class {c}") for c in classes}
    unknown = set() if model_classes is None else set(classes) - {int(c) for c in model_classes}
    out = {"accuracy": {}, "pixels": {}}
    if model_classes is not None:
        out["not_scored"] = {names[c]: "the model was trained without this class" for c in classes if c in unknown}
    if near_wall is not None:
        out["accuracy_near_wall"], out["accuracy_interior"], out["pixels_near_wall"] = {}, {}, {}

    def accuracy(c, m):
        if c in unknown:
            return None
        return float((pred[m] == c).mean()) if m.any() else float("nan")

    for c in classes:
        m = truth == c
        out["pixels"][names[c]] = int(m.sum())
        out["accuracy"][names[c]] = accuracy(c, m)
        if near_wall is not None:
            for key, mm in (("accuracy_near_wall", m & near_wall), ("accuracy_interior", m & ~near_wall)):
                out[key][names[c]] = accuracy(c, mm)
            out["pixels_near_wall"][names[c]] = int((m & near_wall).sum())
    cols = classes + [0]
    matrix = np.array([[int(((truth == c) & (pred == p)).sum()) for p in cols] for c in classes])
    out["confusion"] = {"classes": classes, "names": [names[c] for c in classes], "matrix": matrix.tolist()}
    mat = np.isin(truth, [c for c in MATERIAL_CLASSES if c not in unknown])
    out["overall"] = float((pred[mat] == truth[mat]).mean()) if mat.any() else float("nan")
    accs = [out["accuracy"][names[c]] for c in classes if c in MATERIAL_CLASSES and c not in unknown]
    out["min_material_accuracy"] = float(min(accs)) if accs else float("nan")
    wrong = mat & (pred != truth)
    out["errors"] = {"material_pixels": int(mat.sum()), "misclassified": int(wrong.sum())}
    if near_wall is not None:
        out["errors"]["near_wall"] = int((wrong & near_wall).sum())
        out["errors"]["share_near_wall"] = float((wrong & near_wall).sum() / max(wrong.sum(), 1))
        out["errors"]["near_wall_pixel_share"] = float((mat & near_wall).sum() / max(mat.sum(), 1))
    if wall_distance_mm is not None:
        rows = []
        for lo, hi in zip(DISTANCE_BINS_MM[:-1], DISTANCE_BINS_MM[1:]):
            m = mat & (wall_distance_mm >= lo) & (wall_distance_mm < hi)
            rows.append(
                {
                    "from_mm": lo,
                    "to_mm": None if not np.isfinite(hi) else hi,
                    "pixels": int(m.sum()),
                    "accuracy": float((pred[m] == truth[m]).mean()) if m.any() else None,
                }
            )
        out["by_distance_mm"] = rows
    return out


# ---------------------------------------------------------------- the report
def _mean_profiles(cap: Capture, exposure_us: float, floor: str = "edge"):
    """Average area-normalized profile (Fig. 10b) per material: all pixels, interior and near walls."""
    X, _, d = capture_features(cap.stack, floor=floor)
    delays = np.asarray(d.delay_us)
    exps = np.asarray(d.exposure_us)
    cols = np.flatnonzero(np.isclose(exps, exposure_us))
    out = {}
    lab, near = cap.labels.ravel(), cap.near_wall.ravel()
    for cid in MATERIAL_CLASSES:
        entry = {}
        for key, m in (("all", lab == cid), ("interior", (lab == cid) & ~near), ("near_wall", (lab == cid) & near)):
            if m.sum() >= 5:
                entry[key] = {
                    "mean": X[m][:, cols].mean(axis=0).tolist(),
                    "std": X[m][:, cols].std(axis=0).tolist(),
                    "pixels": int(m.sum()),
                }
        out[MATERIAL_CLASSES[cid]] = entry
    return delays[cols], out


def _saturated_share(cap: Capture) -> float:
    """Share of the material pixels with a saturated observation in any image."""
    sat = (
        np.asarray(cap.stack.saturated).any(axis=0)
        if cap.stack.saturated is not None
        else np.zeros(cap.labels.shape, bool)
    )
    mat = np.isin(cap.labels, list(MATERIAL_CLASSES))
    return float(sat[mat].mean())


def run_materials_report(
    out_dir,
    *,
    size: int = 128,
    quick: bool = False,
    overwrite: bool = False,
    param_grid=None,
    progress=None,
) -> dict:
    """The whole recognition experiment: write the figures and ``materials.json`` into ``out_dir``.

    Train on one capture (:data:`TRAIN_SETTINGS`), test on another
    (:data:`TEST_SETTINGS`): measured stack profiles (floor removed, and the paper's
    plain normalization) and demultiplexed transport profiles; accuracy as the noise
    factor and the ambient light grow (the test placement, new seeds); the same
    experiment with the Jensen et al. milks; round cups instead of trays.

    Parameters
    ----------
    out_dir : path
        Output folder (replaced only with ``overwrite`` and only if it is such a report).
    size : int
        Image size (``size x size`` of a 720-row projector).
    quick : bool
        Fewer points on the curves, no Jensen or cup runs (for tests).
    param_grid : dict, optional
        SVM grid (:data:`planeray.materials.model.DEFAULT_PARAM_GRID`).
    progress : callable, optional
        Called with a short description of each step.

    Returns
    -------
    dict
        The numbers written to ``materials.json``.
    """
    from ..io.atomic import check_replaceable

    out_dir = Path(out_dir)
    check_replaceable(out_dir, overwrite=overwrite, kind="materials report")
    t0 = time.perf_counter()

    def step(msg):
        if progress is not None:
            progress(msg)

    shape = (int(size), int(size))
    numbers: dict = {
        "size": list(shape),
        "projector_rows": PAPER_PROJECTOR_ROWS,
        "train": dict(TRAIN_SETTINGS),
        "test": dict(TEST_SETTINGS),
        "media": optical_table(),
        "media_jensen": optical_table(source="jensen"),
    }
    step("simulating the training and test captures")
    train = simulate_capture(size=shape, **TRAIN_SETTINGS)
    test = simulate_capture(size=shape, **TEST_SETTINGS)
    materials = list(MATERIAL_CLASSES)
    ignore = (BACKGROUND_CLASS,)  # the paper recognizes the five materials (its Fig. 10d is 5 x 5)

    def evaluate(model, cap, transport=None):
        pred = model.predict(cap.stack, transport=transport)
        scored = BACKGROUND_CLASS in model.classes
        truth = cap.labels if scored else np.where(cap.labels == BACKGROUND_CLASS, 0, cap.labels)
        classes = [*materials, BACKGROUND_CLASS] if scored else materials
        return pred, score(pred, truth, near_wall=cap.near_wall, wall_distance_mm=cap.wall_distance_mm, classes=classes)

    def fit(stacks, labels, **kw):
        kw.setdefault("ignore_classes", ignore)
        return train_model(stacks, labels, param_grid=param_grid, **kw)

    with atomic_directory(out_dir, overwrite=overwrite, kind="materials report") as tmp:
        # --- stack profiles: the paper's features -------------------------------------------
        step("training on stack profiles")
        model = fit([train.stack], [train.labels], floor="edge")
        pred, main = evaluate(model, test)
        model.save(tmp / "materials_model.zip")
        same = simulate_capture(size=shape, **{**TEST_SETTINGS, "noise": 1.0, "ambient_e_per_us": 0.5})
        numbers["stack_profiles"] = {
            "floor_edge": {"training": model.training, "test": main, "test_at_training_noise": evaluate(model, same)[1]}
        }
        step("training on stack profiles, minimum as the floor")
        model_min = fit([train.stack], [train.labels], floor="min")
        numbers["stack_profiles"]["floor_min"] = {
            "training": model_min.training,
            "test": evaluate(model_min, test)[1],
            "test_at_training_noise": evaluate(model_min, same)[1],
        }
        step("training on stack profiles, the paper's plain normalization")
        model_none = fit([train.stack], [train.labels], floor="none")
        _, plain = evaluate(model_none, test)
        numbers["stack_profiles"]["floor_none"] = {
            "training": model_none.training,
            "test": plain,
            "test_at_training_noise": evaluate(model_none, same)[1],
        }
        step("training with a background class")
        model_bg = fit([train.stack], [train.labels], ignore_classes=())
        numbers["stack_profiles"]["with_background_class"] = {
            "training": model_bg.training,
            "test": evaluate(model_bg, test)[1],
            "test_at_training_noise": evaluate(model_bg, same)[1],
        }

        # --- transport profiles -------------------------------------------------------------
        step("demultiplexing the captures (transport profiles)")
        T_train = capture_transport(train.stack)
        T_test = capture_transport(test.stack)
        model_t = fit([train.stack], [train.labels], kind="transport", transports=[T_train])
        pred_t, trans = evaluate(model_t, test, transport=T_test)
        numbers["transport_profiles"] = {
            "training": model_t.training,
            "test": trans,
            "test_at_training_noise": evaluate(model_t, same, transport=capture_transport(same.stack))[1],
        }

        # --- noise and ambient light --------------------------------------------------------
        step("accuracy as noise and ambient light grow")
        noises = (1.0, 2.0, 4.0) if quick else (1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0)
        # Beyond ~5 e-/us the 1200-us images of the milks fill the full well (saturation).
        ambients = (0.5, 4.0) if quick else (0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0)
        curves = {"noise": [], "ambient_e_per_us": []}
        for i, nz in enumerate(noises):
            cap = simulate_capture(size=shape, seed=10 + i, placement=1, noise=nz, ambient_e_per_us=0.5)
            row = {"value": nz, "saturated_pixels": _saturated_share(cap)}
            for tag, m in (("floor_edge", model), ("floor_min", model_min), ("floor_none", model_none)):
                row[tag] = evaluate(m, cap)[1]
            curves["noise"].append(row)
        for i, amb in enumerate(ambients):
            cap = simulate_capture(size=shape, seed=20 + i, placement=1, noise=1.0, ambient_e_per_us=amb)
            row = {"value": amb, "saturated_pixels": _saturated_share(cap)}
            for tag, m in (("floor_edge", model), ("floor_min", model_min), ("floor_none", model_none)):
                row[tag] = evaluate(m, cap)[1]
            curves["ambient_e_per_us"].append(row)
        numbers["curves"] = curves

        # --- robustness: the other data set, round cups -------------------------------------
        if not quick:
            step("the Jensen et al. milks")
            tr_j = simulate_capture(size=shape, source="jensen", **TRAIN_SETTINGS)
            te_j = simulate_capture(size=shape, source="jensen", **TEST_SETTINGS)
            model_j = fit([tr_j.stack], [tr_j.labels])
            numbers["jensen"] = {"training": model_j.training, "test": evaluate(model_j, te_j)[1]}
            # A model trained on one data set applied to the other: how far apart the two are.
            numbers["jensen"]["narasimhan_model_on_jensen"] = evaluate(model, te_j)[1]
            step("round cups")
            tr_c = simulate_capture(size=shape, container="cup", **TRAIN_SETTINGS)
            te_c = simulate_capture(size=shape, container="cup", **TEST_SETTINGS)
            model_c = fit([tr_c.stack], [tr_c.labels])
            numbers["cups"] = {"training": model_c.training, "test": evaluate(model_c, te_c)[1]}

        # --- figures ------------------------------------------------------------------------
        step("figures")
        files = {}
        names = {c: CLASS_NAMES[c] for c in [*materials, BACKGROUND_CLASS]}
        shown = np.isin(test.labels, materials)  # the segmentation of the containers, as Fig. 10c
        figs.materials_photo_figure(test.photo, test.labels, names=names, out=tmp / "fig10a_photo.png")
        delays, profiles = _mean_profiles(test, 600.0, floor="edge")
        numbers["mean_profiles_600us"] = {"delay_us": delays.tolist(), "floor": "edge", "materials": profiles}
        figs.material_profiles_figure(
            delays, profiles, exposure_us=600.0, floor="edge", out=tmp / "fig10b_profiles.png"
        )
        figs.segmentation_figure(
            test.labels,
            np.where(shown, pred, 0),
            near_wall=test.near_wall,
            scored=shown,
            names=names,
            out=tmp / "fig10c_segmentation.png",
        )
        figs.confusion_figure(main["confusion"], out=tmp / "fig10d_confusion.png")
        figs.segmentation_figure(
            test.labels,
            pred_t,
            near_wall=test.near_wall,
            scored=shown,
            names=names,
            title="transport profiles",
            out=tmp / "segmentation_transport.png",
        )
        figs.accuracy_curves_figure(curves, out=tmp / "accuracy_vs_noise_ambient.png")
        figs.accuracy_by_distance_figure(
            {"stack profiles": main, "transport profiles": trans}, out=tmp / "accuracy_vs_wall_distance.png"
        )
        from ..scenes.materials import material_tables

        figs.wall_kernels_figure(material_tables(), out=tmp / "wall_kernels.png")
        for f in sorted(tmp.glob("*.png")):
            files[f.stem] = f.name
        numbers["files"] = files
        numbers["seconds"] = round(time.perf_counter() - t0, 1)
        numbers = jsonable(numbers)
        (tmp / "materials.json").write_text(json.dumps(numbers, indent=1))
        (tmp / MARKER).write_text(json.dumps({"format": REPORT_FORMAT, "format_version": 1}, indent=1))
    return numbers
