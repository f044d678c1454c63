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
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._validate import available_memory_bytes, check_integer, check_nonnegative, check_number
from ..acquire import simulate_stack
from ..camera import CameraModel
from ..errors import InputError
from ..figures import materials as figs
from ..io import atomic_directory, atomic_file, jsonable, write_stack
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
from ..stack import Stack
from ..timing import PAPER_PROJECTOR_ROWS, make_sweep

__all__ = [
    "CAPTURE_FORMAT",
    "REPORT_FORMAT",
    "Capture",
    "camera_for",
    "capture_memory_bytes",
    "check_capture_options",
    "check_report_options",
    "max_projector_rows",
    "simulate_capture",
    "simulate_white_reference",
    "WHITE_ALBEDO",
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
    room light).  ``noise`` is at most :data:`MAX_NOISE` (beyond it a white surface
    gets less than one laser electron per image).
    """
    noise = check_number(
        noise,
        "noise",
        minimum=0.0,
        maximum=MAX_NOISE,
        min_inclusive=False,
        requirement=f"a factor > 0 and <= {MAX_NOISE:.4g} (beyond it a white surface gets less than one laser "
        "electron per image: no signal)",
    )
    ambient = check_nonnegative(ambient_e_per_us, "ambient_e_per_us")
    base = CameraModel()
    s2 = noise * noise
    return CameraModel(
        laser_electrons=base.laser_electrons / s2,
        full_well_e=base.full_well_e / s2,
        read_noise_e=base.read_noise_e / noise,
        ambient_e_per_us=ambient / s2,
    )


#: Largest noise factor: the default camera's laser electrons per image of a white surface, square-rooted.
MAX_NOISE = math.sqrt(CameraModel().laser_electrons)
#: Smallest and largest image side of a simulated capture (the scene needs 8 pixels).
MIN_SIZE, MAX_SIZE = 8, 4096
#: Smallest image side of the report: below it a container holds a handful of pixels.
MIN_REPORT_SIZE = 16
#: Memory a capture takes per pixel (bytes per offset of the scene's band, per image):
#: measured 4.6 kB per pixel at 256x256 (257 offsets, 85 images).
_BYTES_PER_PIXEL_OFFSET, _BYTES_PER_PIXEL_IMAGE = 16, 12


def capture_memory_bytes(size, sweep: str = "paper") -> int:
    """Estimated peak memory of simulating one capture of ``size`` (scene kernels and images)."""
    from ..scenes.base import DEFAULT_BAND_ROWS

    H, W = (int(v) for v in size)
    offsets = 2 * DEFAULT_BAND_ROWS + 1
    return H * W * (_BYTES_PER_PIXEL_OFFSET * offsets + _BYTES_PER_PIXEL_IMAGE * len(make_sweep(sweep)))


def _check_memory(needed: int, name: str, what: str) -> None:
    free = available_memory_bytes()
    if free is not None and needed > free:
        raise InputError(
            f"{name} must fit in the memory available: {what} needs about {needed / 2**30:.1f} GiB, "
            f"{free / 2**30:.1f} GiB are available"
        )


def check_capture_options(
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
) -> None:
    """Refuse, before any work, the options of :func:`simulate_capture` that cannot give a capture.

    Every message names the parameter as :func:`simulate_capture` does (the command
    line prints its option instead): sizes from :data:`MIN_SIZE` to :data:`MAX_SIZE`
    that fit in the available memory, a projector row count the kernel tables reach,
    seeds and placements >= 0, the named choices, the noise factor
    (:func:`camera_for`) and an ambient light that does not fill the full well in the
    sweep's shortest exposure by itself.
    """
    from ..mc.wall import WALL_MODELS
    from ..optical_data import CHANNELS, OPTICAL_SOURCES
    from ..scenes.materials import CONTAINERS
    from ..timing import SWEEPS

    def choice(value, name, choices):
        if value not in choices:
            raise InputError(f"{name} must be one of {', '.join(choices)}, got {value!r}")

    if not isinstance(size, (tuple, list)) or len(size) != 2:
        raise InputError(f"size must be two integers H W, got {size!r}")
    H = check_integer(size[0], "size", minimum=MIN_SIZE, maximum=MAX_SIZE)
    W = check_integer(size[1], "size", minimum=MIN_SIZE, maximum=MAX_SIZE)
    rows = check_integer(projector_rows, "projector_rows", minimum=1)
    most = max_projector_rows(H)
    if rows > most:
        raise InputError(
            f"projector_rows must be <= {most} for {H} image rows (the kernel tables reach 192 projector rows; "
            f"{rows / H:.4g} rows per camera row is beyond them), got {projector_rows!r}"
        )
    check_integer(seed, "seed", minimum=0, maximum=2**32 - 1)
    check_integer(placement, "placement", minimum=0, maximum=2**32 - 1)
    choice(container, "container", CONTAINERS)
    choice(wall, "wall", WALL_MODELS)
    choice(source, "source", OPTICAL_SOURCES)
    choice(channel, "channel", CHANNELS)
    choice(sweep, "sweep", tuple(SWEEPS))
    camera = camera_for(noise=noise, ambient_e_per_us=ambient_e_per_us)
    shortest = float(np.min(make_sweep(sweep).exposure_us))
    most_ambient = CameraModel().full_well_e / shortest
    if camera.ambient_e_per_us * shortest >= camera.full_well_e:
        raise InputError(
            f"ambient_e_per_us must be < {most_ambient:g} (at {float(ambient_e_per_us):g} the ambient light alone "
            f"fills the full well in the sweep's shortest exposure, {shortest:g} us: every pixel saturates), "
            f"got {ambient_e_per_us!r}"
        )
    _check_memory(capture_memory_bytes((H, W), sweep), "size", f"a {H}x{W} capture")


def max_projector_rows(camera_rows: int) -> int:
    """Most projector rows a ``camera_rows``-row image of the materials scene may span (its kernel tables' reach)."""
    from ..scenes.base import DEFAULT_BAND_ROWS
    from ..scenes.materials import TABLE_REACH_ROWS

    H = int(camera_rows)
    lo, hi = 1, H * TABLE_REACH_ROWS
    while lo < hi:  # the largest P with max(band, ceil(P/H) + 1) + ceil(P/H/2 + 1/2) <= reach
        mid = (lo + hi + 1) // 2
        rpc = mid / H
        if max(DEFAULT_BAND_ROWS, math.ceil(rpc) + 1) + math.ceil(0.5 * rpc + 0.5) <= TABLE_REACH_ROWS:
            lo = mid
        else:
            hi = mid - 1
    return lo


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


def _capture_scene(settings: dict):
    """The ``materials`` scene of a capture's ``settings`` (:attr:`Capture.settings`): the one
    :func:`simulate_capture` images, and its ground truth when rebuilt later."""
    keys = ("projector_rows", "seed", "placement", "container", "wall", "source", "channel")
    return make_scene("materials", tuple(settings["size"]), **{k: settings[k] for k in keys})


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
    table_progress=None,
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
    table_progress : callable, optional
        Called with 1 after each Monte Carlo run of the wall-kernel tables traced for
        this capture (none for the shipped tables; :func:`tables_to_trace`).
    """
    from ..io.atomic import check_replaceable
    from ..scenes.materials import material_tables

    check_capture_options(
        size=size,
        projector_rows=projector_rows,
        seed=seed,
        placement=placement,
        container=container,
        wall=wall,
        source=source,
        channel=channel,
        noise=noise,
        ambient_e_per_us=ambient_e_per_us,
        sweep=sweep,
    )
    if out is not None:
        check_replaceable(out, overwrite=overwrite, kind="materials capture")
    if table_progress is not None:  # trace (and cache) the tables first, so their runs can be counted
        material_tables(source=source, channel=channel, wall=wall, progress=table_progress)
    H, W = (int(v) for v in size)
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
    scene = _capture_scene(settings)
    camera = camera_for(noise=noise, ambient_e_per_us=ambient_e_per_us)
    stack = simulate_stack(scene, make_sweep(sweep), camera=camera, seed=seed, progress=progress)
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


#: Albedo of the simulated white reference card (:func:`simulate_white_reference`).
WHITE_ALBEDO = 0.99


def simulate_white_reference(
    *,
    size=(128, 128),
    projector_rows: int = PAPER_PROJECTOR_ROWS,
    seed: int = 0,
    noise: float = 1.0,
    ambient_e_per_us: float = 0.5,
    sweep: str = "paper",
    albedo: float = WHITE_ALBEDO,
) -> Stack:
    """A white Lambertian card of uniform ``albedo`` captured as :func:`simulate_capture` captures the scene.

    The calibration target of ``planeray materials fit --white-reference`` (the same sweep, camera
    and image size; its own noise ``seed``): direct light only, the camera row's footprint
    (:func:`planeray.scenes.base.footprint_kernel`), ambient light of the card's albedo.

    Returns
    -------
    Stack
    """
    from ..scenes.base import DEFAULT_MM_PER_ROW, Scene, footprint_kernel, scene_offsets
    from ..timing import RowGeometry
    from ..transport import Transport

    check_capture_options(
        size=size, projector_rows=projector_rows, seed=seed, placement=0, container="tray", wall="fresnel",
        source="narasimhan", channel="red", noise=noise, ambient_e_per_us=ambient_e_per_us, sweep=sweep,
    )  # fmt: skip
    H, W = (int(v) for v in size)
    geometry = RowGeometry(H, int(projector_rows))
    offsets = scene_offsets(int(np.ceil(geometry.rows_per_camera_row)) + 1)
    kernel = float(albedo) * footprint_kernel(offsets, geometry.rows_per_camera_row)
    dense = np.broadcast_to(kernel.astype(np.float32), (H, W, offsets.size))
    card = np.full((H, W), float(albedo), np.float32)
    scene = Scene(
        "white_reference",
        Transport(np.array(dense), offsets, geometry),
        card,
        card.copy(),
        np.ones((H, W), np.uint8),
        params={"name": "white_reference", "albedo": float(albedo), "mm_per_row": DEFAULT_MM_PER_ROW},
    )
    camera = camera_for(noise=noise, ambient_e_per_us=ambient_e_per_us)
    return simulate_stack(scene, make_sweep(sweep), camera=camera, seed=seed)


def _write_png8(path, image):
    """An 8-bit grayscale PNG of an image in [0, 1] (with planeray's mark)."""
    from PIL import Image

    from ..io.marks import png_mark_info

    with atomic_file(path) as tmp:
        Image.fromarray((np.clip(image, 0, 1) * 255 + 0.5).astype(np.uint8)).save(
            tmp, format="PNG", pnginfo=png_mark_info("image")
        )


def write_capture(cap: Capture, out, *, overwrite=False, scene_params=None) -> Path:
    """Write a capture folder (see :func:`simulate_capture`), atomically."""
    out = Path(out)
    with atomic_directory(out, overwrite=overwrite, kind="materials capture") as tmp:
        write_stack(cap.stack, tmp / "stack.zarr")
        write_label_image(tmp / "labels.png", cap.labels, kind="labels")
        write_label_image(tmp / "near_wall.png", np.where(cap.near_wall, 255, 0), kind="mask")
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


def check_report_options(*, size: int = 128, quick: bool = False) -> None:
    """Refuse, before any work, a report size that cannot give one (:data:`MIN_REPORT_SIZE` .. :data:`MAX_SIZE`)."""
    n = check_integer(size, "size", minimum=MIN_REPORT_SIZE, maximum=MAX_SIZE)
    # The report holds four captures and two transports at once (train, test, same conditions, one curve point).
    _check_memory(6 * capture_memory_bytes((n, n)), "size", f"the {n}x{n} report")


#: The SVM grid of a ``--quick`` report: the middle of the default grid, where the full report's best
#: parameters lie (C 100, gamma_scale 1 at 128 x 128), a quarter of its fits.
QUICK_PARAM_GRID = {"C": (10.0, 100.0), "gamma_scale": (0.3, 1.0)}

#: Pixels at least this far from every wall of their container are measured (the region the fit's accuracy target is for).
MEDIA_FIT_NEAR_WALL_MM = 3.0
#: Blocks (pixels a side) whose spread gives each region's noise (as in the fit's validation, tools/validate_fit.py).
MEDIA_FIT_BLOCK_PX = 8


def media_fit_numbers(
    scene, transports: dict, *, near_wall_mm: float = MEDIA_FIT_NEAR_WALL_MM, whites: dict | None = None
) -> dict:
    """``mu_s'`` and ``mu_a`` (1/mm) of each medium of a ``materials`` scene, fitted, beside the published ones.

    Each container's pixels at least ``near_wall_mm`` from its walls are fitted as one region
    (shape only -- the scene has no white target --, the containers' walls modelled from the
    scene's material map), once per entry of ``transports`` (``{source: Transport or Stack}``,
    e.g. the scene's ground truth and the capture): a transport by
    :func:`planeray.materials.fit.fit_transport` (``regions_only``, its noise from the spread of
    :data:`MEDIA_FIT_BLOCK_PX` blocks), a stack by :func:`planeray.materials.stackfit.fit_stack`
    (its images fitted directly: no demultiplexing noise in the tail), calibrated by the white
    reference ``whites[source]`` where given (:func:`simulate_white_reference`, albedo
    :data:`WHITE_ALBEDO`).  Extends Fig. 10 (Sec. 8: "to use delay profiles to better model or
    inverse render subsurface scattering").

    Returns
    -------
    dict
        ``{"near_wall_mm", "mm_per_row", "calibration", "media": {name: {"published": {...},
        source: {"mu_s_prime_per_mm", "mu_s_prime_se_per_mm", "mu_a_per_mm", "mu_a_se_per_mm",
        "mu_s_prime_rel_err", "mu_a_rel_err", "pixels"}}}}`` (None where a parameter is not identified).
    """
    from ..materials.fit import fit_transport
    from ..materials.stackfit import fit_stack
    from ..optical_data import material_medium
    from ..scenes.base import DEFAULT_MM_PER_ROW
    from ..stack import Stack

    mm = float(scene.params.get("mm_per_row", DEFAULT_MM_PER_ROW))
    material = np.asarray(scene.maps["material"], np.int64)
    containers = np.where(np.isin(material, list(MATERIAL_CLASSES)), material, 0)
    regions = np.where(np.asarray(scene.maps["wall_distance_mm"]) >= near_wall_mm, containers, 0)
    media = {
        name: {
            "published": {
                "mu_s_prime_per_mm": material_medium(cid).sigma_s_prime,
                "mu_a_per_mm": material_medium(cid).sigma_a,
            }
        }
        for cid, name in MATERIAL_CLASSES.items()
    }
    for source, transport in transports.items():
        white = (whites or {}).get(source)
        if white is not None and not isinstance(transport, Stack):
            raise ValueError(f"a white reference is for a stack source; {source!r} is a transport")
        if isinstance(transport, Stack):
            kw = {} if white is None else {"white": white, "white_albedo": WHITE_ALBEDO}
            res = fit_stack(transport, mm_per_row=mm, labels=regions, containers=containers, **kw)
        else:
            res = fit_transport(
                transport,
                mm_per_row=mm,
                labels=regions,
                block_px=MEDIA_FIT_BLOCK_PX,
                containers=containers,
                regions_only=True,
            )
        for cid, name in MATERIAL_CLASSES.items():
            reg = res.regions.get(cid) or {}
            row = {"pixels": int((regions == cid).sum())}
            for key in ("mu_s_prime_per_mm", "mu_a_per_mm"):
                value, se = reg.get(key), reg.get(key.replace("_per_mm", "_se_per_mm"))
                ok = value is not None and np.isfinite(value)
                row[key] = float(value) if ok else None
                row[key.replace("_per_mm", "_se_per_mm")] = float(se) if ok and se is not None else None
                truth = media[name]["published"][key]
                row[key.replace("_per_mm", "_rel_err")] = float(value / truth - 1.0) if ok else None
            media[name][source] = row
    calibration = {
        source: f"white reference (albedo {WHITE_ALBEDO:g})" if (whites or {}).get(source) is not None else "shape only"
        for source in transports
    }
    return {"near_wall_mm": float(near_wall_mm), "mm_per_row": mm, "calibration": calibration, "media": media}


def report_tasks(*, quick: bool = False) -> int:
    """Tasks of :func:`run_materials_report` (captures simulated, models trained, transports demultiplexed, figures)."""
    noises, ambients = _report_curves(quick)
    return 12 + len(noises) + len(ambients) + (0 if quick else 7)


def _report_curves(quick: bool):
    noises = (1.0, 2.0, 4.0) if quick else (1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0)
    # Beyond ~5 e-/us the 1200-us images of the milks fill the full well (saturation).
    ambients = (0.5, 4.0) if quick else (0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0)
    return noises, ambients


#: Thresholds of the unclassified-pixel measurement (:func:`unclassified_numbers`).
UNCLASSIFIED_THRESHOLDS = (0.002, 0.005, 0.01, 0.02, 0.05, 0.1)


def unclassified_numbers(seg, truth, model_classes) -> dict:
    """What the typicality threshold does on a capture with ground truth.

    For each threshold of :data:`UNCLASSIFIED_THRESHOLDS` (and the segmentation's own):
    the share of the trained classes' pixels the SVM got right that become unclassified
    (lost), of those it got wrong (flagged), and of the pixels of classes the model was
    trained without (e.g. the table) that are unclassified.
    """
    truth = np.asarray(truth)
    has = ~seg.no_profile
    known = np.isin(truth, list(model_classes)) & has
    right, wrong = known & (seg.svm_labels == truth), known & (seg.svm_labels != truth)
    unknown = (truth > 0) & ~np.isin(truth, list(model_classes)) & has

    def share(mask, below):
        return float((seg.typicality[mask] < below).mean()) if mask.any() else None

    rows = []
    for below in sorted({*UNCLASSIFIED_THRESHOLDS, seg.unclassified_below}):
        rows.append(
            {
                "unclassified_below": below,
                "lost_of_right": share(right, below),
                "flagged_of_wrong": share(wrong, below),
                "unclassified_of_untrained": share(unknown, below),
            }
        )
    return {
        "pixels": {"right": int(right.sum()), "wrong": int(wrong.sum()), "untrained": int(unknown.sum())},
        "thresholds": rows,
    }


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
    experiment with the Jensen et al. milks; round cups instead of trays; and what the
    typicality threshold leaves unclassified (:func:`unclassified_numbers`).  The
    accuracies are the SVM's picks (``unclassified_below=0``, the paper's classifier).

    Parameters
    ----------
    out_dir : path
        Output folder (replaced only with ``overwrite`` and only if it is such a report).
    size : int
        Image size (``size x size`` of a 720-row projector), :data:`MIN_REPORT_SIZE` or more.
    quick : bool
        Fewer points on the curves, no Jensen or cup runs, the SVM grid :data:`QUICK_PARAM_GRID`
        (for tests).
    param_grid : dict, optional
        SVM grid (:data:`planeray.materials.model.DEFAULT_PARAM_GRID`; :data:`QUICK_PARAM_GRID` with ``quick``).
    progress : callable, optional
        Called as ``progress(done, total, description)`` before the first task and
        after each (``total``: :func:`report_tasks`).

    Returns
    -------
    dict
        The numbers written to ``materials.json``.
    """
    from ..io.atomic import check_replaceable
    from ..materials.model import DEFAULT_UNCLASSIFIED_BELOW

    check_report_options(size=size, quick=quick)
    out_dir = Path(out_dir)
    check_replaceable(out_dir, overwrite=overwrite, kind="materials report")
    t0 = time.perf_counter()
    total = report_tasks(quick=quick)
    done = [0]

    def start(msg):
        if progress is not None:
            progress(done[0], total, msg)

    def tick(result=None):
        done[0] += 1
        if progress is not None:
            progress(done[0], total, None)
        return result

    shape = (int(size), int(size))
    numbers: dict = {
        "size": list(shape),
        "projector_rows": PAPER_PROJECTOR_ROWS,
        "train": dict(TRAIN_SETTINGS),
        "test": dict(TEST_SETTINGS),
        "media": optical_table(),
        "media_jensen": optical_table(source="jensen"),
    }

    def capture(**kw):
        return tick(simulate_capture(size=shape, **kw))

    start("simulating the training and test captures")
    train = capture(**TRAIN_SETTINGS)
    test = capture(**TEST_SETTINGS)
    materials = list(MATERIAL_CLASSES)
    ignore = (BACKGROUND_CLASS,)  # the paper recognizes the five materials (its Fig. 10d is 5 x 5)

    def evaluate(model, cap, transport=None):
        pred = model.predict(cap.stack, transport=transport, unclassified_below=0.0)
        scored = BACKGROUND_CLASS in model.classes
        truth = cap.labels if scored else np.where(cap.labels == BACKGROUND_CLASS, 0, cap.labels)
        classes = [*materials, BACKGROUND_CLASS] if scored else materials
        return pred, score(pred, truth, near_wall=cap.near_wall, wall_distance_mm=cap.wall_distance_mm, classes=classes)

    def fit(stacks, labels, **kw):
        kw.setdefault("ignore_classes", ignore)
        grid = param_grid if param_grid is not None else (QUICK_PARAM_GRID if quick else None)
        return tick(train_model(stacks, labels, param_grid=grid, **kw))

    with atomic_directory(out_dir, overwrite=overwrite, kind="materials report") as tmp:
        # --- stack profiles: the paper's features -------------------------------------------
        start("training on stack profiles")
        model = fit([train.stack], [train.labels], floor="edge")
        pred, main = evaluate(model, test)
        model.save(tmp / "materials_model.zip")
        same = capture(**{**TEST_SETTINGS, "noise": 1.0, "ambient_e_per_us": 0.5})
        numbers["stack_profiles"] = {
            "floor_edge": {"training": model.training, "test": main, "test_at_training_noise": evaluate(model, same)[1]}
        }
        # --- pixels unlike every trained class: the table, left out of training ------------
        numbers["unclassified"] = {
            "default": DEFAULT_UNCLASSIFIED_BELOW,
            "test": unclassified_numbers(model.segment(test.stack), test.labels, model.classes),
            "test_at_training_noise": unclassified_numbers(model.segment(same.stack), same.labels, model.classes),
        }
        start("training on stack profiles, minimum as the floor")
        model_min = fit([train.stack], [train.labels], floor="min")
        numbers["stack_profiles"]["floor_min"] = {
            "training": model_min.training,
            "test": evaluate(model_min, test)[1],
            "test_at_training_noise": evaluate(model_min, same)[1],
        }
        start("training on stack profiles, the paper's plain normalization")
        model_none = fit([train.stack], [train.labels], floor="none")
        _, plain = evaluate(model_none, test)
        numbers["stack_profiles"]["floor_none"] = {
            "training": model_none.training,
            "test": plain,
            "test_at_training_noise": evaluate(model_none, same)[1],
        }
        start("training with a background class")
        model_bg = fit([train.stack], [train.labels], ignore_classes=())
        numbers["stack_profiles"]["with_background_class"] = {
            "training": model_bg.training,
            "test": evaluate(model_bg, test)[1],
            "test_at_training_noise": evaluate(model_bg, same)[1],
        }

        # --- transport profiles -------------------------------------------------------------
        start("demultiplexing the captures (transport profiles)")
        T_train = tick(capture_transport(train.stack))
        T_test = tick(capture_transport(test.stack))
        model_t = fit([train.stack], [train.labels], kind="transport", transports=[T_train])
        pred_t, trans = evaluate(model_t, test, transport=T_test)
        T_same = tick(capture_transport(same.stack))
        numbers["transport_profiles"] = {
            "training": model_t.training,
            "test": trans,
            "test_at_training_noise": evaluate(model_t, same, transport=T_same)[1],
        }

        # --- noise and ambient light --------------------------------------------------------
        start("accuracy as noise and ambient light grow")
        noises, ambients = _report_curves(quick)
        curves = {"noise": [], "ambient_e_per_us": []}
        for i, nz in enumerate(noises):
            cap = capture(seed=10 + i, placement=1, noise=nz, ambient_e_per_us=0.5)
            row = {"value": nz, "saturated_pixels": _saturated_share(cap)}
            for tag, m in (("floor_edge", model), ("floor_min", model_min), ("floor_none", model_none)):
                row[tag] = evaluate(m, cap)[1]
            curves["noise"].append(row)
        for i, amb in enumerate(ambients):
            cap = capture(seed=20 + i, placement=1, noise=1.0, ambient_e_per_us=amb)
            row = {"value": amb, "saturated_pixels": _saturated_share(cap)}
            for tag, m in (("floor_edge", model), ("floor_min", model_min), ("floor_none", model_none)):
                row[tag] = evaluate(m, cap)[1]
            curves["ambient_e_per_us"].append(row)
        numbers["curves"] = curves

        # --- robustness: the other data set, round cups -------------------------------------
        if not quick:
            start("the Jensen et al. milks")
            tr_j = capture(source="jensen", **TRAIN_SETTINGS)
            te_j = capture(source="jensen", **TEST_SETTINGS)
            model_j = fit([tr_j.stack], [tr_j.labels])
            numbers["jensen"] = {"training": model_j.training, "test": evaluate(model_j, te_j)[1]}
            # A model trained on one data set applied to the other: how far apart the two are.
            numbers["jensen"]["narasimhan_model_on_jensen"] = evaluate(model, te_j)[1]
            start("round cups")
            tr_c = capture(container="cup", **TRAIN_SETTINGS)
            te_c = capture(container="cup", **TEST_SETTINGS)
            model_c = fit([tr_c.stack], [tr_c.labels])
            numbers["cups"] = {"training": model_c.training, "test": evaluate(model_c, te_c)[1]}
            # --- beyond Fig. 10: the media measured (mu_s', mu_a), not only named ----------------
            start("measuring the media (mu_s', mu_a)")
            truth_scene = _capture_scene(test.settings)
            white = simulate_white_reference(
                size=shape, seed=TEST_SETTINGS["seed"] + 1000, noise=TEST_SETTINGS["noise"],
                ambient_e_per_us=TEST_SETTINGS["ambient_e_per_us"],
            )  # fmt: skip
            numbers["media_fit"] = tick(
                media_fit_numbers(
                    truth_scene,
                    {
                        "ground-truth transport": truth_scene.transport,
                        "capture, shape only": test.stack,
                        "capture, white reference": test.stack,
                    },
                    whites={"capture, white reference": white},
                )
            )

        # --- figures ------------------------------------------------------------------------
        start("figures")
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
        if "media_fit" in numbers:
            figs.measured_media_figure(numbers["media_fit"]["media"], out=tmp / "fig10e_measured_media.png")
        for f in sorted(tmp.glob("*.png")):
            files[f.stem] = f.name
        numbers["files"] = files
        numbers["seconds"] = round(time.perf_counter() - t0, 1)
        numbers = jsonable(numbers)
        (tmp / "materials.json").write_text(json.dumps(numbers, indent=1))
        (tmp / MARKER).write_text(json.dumps({"format": REPORT_FORMAT, "format_version": 1}, indent=1))
        tick()
    return numbers
