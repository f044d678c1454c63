"""Recognition by fitted parameters against the SVM, by distance to the container wall.

* :func:`reference_library`: the library of the five Fig. 10 media as the fit returns them
  on a labelled reference capture (the shipped ``mc/tables/media-library.json`` is made by
  it from the report's training capture);
* :func:`run_recognition_study`: train / calibrate on one capture of the ``materials`` scene,
  test on a held-out one (another seed, placement, noise and ambient light: the report's
  :data:`~planeray.experiments.materials.TEST_SETTINGS`), for both recognisers -- the
  parameters against the library and the SVM of :mod:`planeray.materials.model` -- per pixel
  and with region-level reasoning (pooling over a disc, over the containers' outlines, a
  region's pooled fit; a majority vote for the SVM); accuracy per class and per bin of
  distance to the nearest wall (:data:`~planeray.materials.recognize.WALL_BINS_MM`), written
  as ``recognition.json`` and ``recognition_vs_wall_distance.png``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

from ..errors import InputError
from ..figures import materials as figs
from ..io import atomic_directory, jsonable
from ..io.atomic import MARKER
from ..materials import CLASS_NAMES, MATERIAL_CLASSES, capture_transport, optical_table, train_model
from ..materials.library import MediaLibrary
from ..materials.recognize import (
    DEFAULT_BLOCK_PX,
    DEFAULT_POOL_MM,
    WALL_BINS_MM,
    accuracy_by_distance,
    entries_from_capture,
    fit_image,
    majority_by_region,
    mode_filter,
    recognize_image,
    recognize_regions,
)
from .materials import TEST_SETTINGS, TRAIN_SETTINGS, simulate_capture

__all__ = [
    "RECOGNITION_FORMAT",
    "reference_library",
    "container_regions",
    "majority_by_region",
    "mode_filter",
    "recognition_tables",
    "write_recognition_study",
    "run_recognition_study",
]

RECOGNITION_FORMAT = "planeray-materials-recognition-study"
#: mm per projector row of the materials scene.
_MM_PER_ROW = 0.3


def _published():
    out = {}
    for row in optical_table():
        out[row["class_id"]] = {
            "mu_s_prime_per_mm": row["sigma_s_prime"],
            "mu_a_per_mm": row["sigma_a"],
            "reference": "planeray.optical_data (Narasimhan et al. 2006 milks; toothpaste, soap argued there)",
        }
    return out


def reference_library(
    transport, labels, *, mm_per_row=_MM_PER_ROW, block_px=DEFAULT_BLOCK_PX, source="", maps=None, progress=None
):
    """The five Fig. 10 media as :func:`~planeray.materials.recognize.fit_image` returns them.

    Parameters
    ----------
    transport : Transport
        Demultiplexed transport of a labelled capture of the five media.
    labels : ndarray (H, W)
        Class ids (1-5 the media; other ids ignored).
    mm_per_row, block_px
        The fit's row size and block size.
    source : str
        Stored with the entries.
    maps : dict, optional
        The fit of ``transport`` within the labelled trays, if already made (``fit_image``
        with ``regions`` the material labels, ``block_px``): not fitted again.

    Returns
    -------
    (MediaLibrary, maps)
    """
    lab = np.asarray(labels)
    regions = np.where(np.isin(lab, list(MATERIAL_CLASSES)), lab, 0)
    if maps is None:
        maps = fit_image(transport, mm_per_row=mm_per_row, block_px=block_px, regions=regions, progress=progress)
    names = {c: CLASS_NAMES[c] for c in MATERIAL_CLASSES}
    entries = entries_from_capture(maps, regions, names, source=source, published=_published())
    cond = {
        "mm_per_row": float(mm_per_row),
        "n": 1.33,
        "calibrated": False,
        "block_px": int(block_px),
        "rows_per_camera_row": float(transport.geometry.rows_per_camera_row),
        "fit": "shape only, demultiplexed stack (capture_transport), 2 x 2 blocks within each labelled tray",
    }
    return MediaLibrary(tuple(entries), cond), maps


def container_regions(labels, *, background=6):
    """Connected regions of the containers (what a user outlines without naming them); 0 elsewhere."""
    lab = np.asarray(labels)
    inside = (lab > 0) & (lab != background)
    out = np.zeros(lab.shape, np.int64)
    n = 0
    for c in np.unique(lab[inside]):
        comp, k = ndimage.label(lab == c)
        out[comp > 0] = comp[comp > 0] + n
        n += k
    return out


def recognition_tables(library, maps, region_maps, svm, truth, wall_distance_mm, regions, *, mm_per_pixel) -> dict:
    """Every recogniser variant's accuracy table on a held-out capture (the core of the study).

    Parameters
    ----------
    library : MediaLibrary
    maps, region_maps : dict
        :func:`~planeray.materials.recognize.fit_image` of the held-out transport: blocks over
        the whole image (one region), and one fit per container (``regions``).
    svm : ndarray (H, W)
        The SVM's per-pixel picks.
    truth, wall_distance_mm : ndarray (H, W)
        Ground truth class ids and distances to the nearest wall, mm.
    regions : ndarray (H, W)
        The containers' outlines (:func:`container_regions`).
    mm_per_pixel : float

    Returns
    -------
    dict
        ``format``, ``mm_per_pixel``, ``pool_mm``, ``wall_bins_mm``, ``library`` (its JSON),
        ``recognisers``: variant -> :func:`~planeray.materials.recognize.accuracy_by_distance`.
    """
    classes = {c: CLASS_NAMES[c] for c in MATERIAL_CLASSES}
    pool_px = DEFAULT_POOL_MM / mm_per_pixel
    preds = {
        "parameters, per pixel": recognize_image(library, maps, pool_mm=0).class_ids,
        f"parameters, pooled over {DEFAULT_POOL_MM:g} mm": recognize_image(
            library, maps, mm_per_pixel=mm_per_pixel
        ).class_ids,
        "parameters, pooled over each container": recognize_image(library, maps, regions=regions).class_ids,
        "parameters, each container's pooled fit": recognize_image(library, region_maps, pool_mm=0).class_ids,
        "SVM, per pixel": np.asarray(svm),
        f"SVM, majority over {DEFAULT_POOL_MM:g} mm": mode_filter(svm, radius_px=pool_px, classes=MATERIAL_CLASSES),
        "SVM, majority over each container": majority_by_region(svm, regions),
    }
    tables = {k: accuracy_by_distance(v, truth, wall_distance_mm, classes=classes) for k, v in preds.items()}
    return {
        "format": RECOGNITION_FORMAT,
        "mm_per_pixel": float(mm_per_pixel),
        "pool_mm": DEFAULT_POOL_MM,
        "wall_bins_mm": [None if not np.isfinite(v) else v for v in WALL_BINS_MM],
        "library": library.to_json(),
        "recognisers": tables,
    }


def write_recognition_study(out_dir, numbers, library, *, overwrite=False):
    """Write ``recognition.json``, ``library.json`` and ``recognition_vs_wall_distance.png`` (atomically)."""
    from ..materials.library import save_library

    with atomic_directory(out_dir, overwrite=overwrite, kind="materials recognition study") as tmp:
        (tmp / "recognition.json").write_text(json.dumps(jsonable(numbers), indent=1) + "\n")
        (tmp / MARKER).write_text(json.dumps({"format": RECOGNITION_FORMAT, "format_version": 1}, indent=1))
        save_library(library, tmp / "library.json")
        figs.recognition_by_distance_figure(numbers["recognisers"], out=tmp / "recognition_vs_wall_distance.png")
    return Path(out_dir)


def run_recognition_study(out_dir=None, *, size=128, block_px=DEFAULT_BLOCK_PX, overwrite=False, progress=None) -> dict:
    """Both recognisers on a held-out arrangement, by distance to the wall; ``recognition.json`` and a figure.

    Parameters
    ----------
    out_dir : path, optional
        Folder to write (``recognition.json``, ``recognition_vs_wall_distance.png``,
        ``library.json``); replaced only with ``overwrite`` and only if planeray wrote it.
    size : int
        Image size (``size x size``, 720 projector rows: 128 -> 1.69 mm per pixel).
    block_px : int
        Block size of the parameter fits.
    progress : callable, optional
        Called with a description before each step.

    Returns
    -------
    dict
        The numbers of ``recognition.json``: per recogniser and variant, the table of
        :func:`~planeray.materials.recognize.accuracy_by_distance`, and the timings.
    """
    from ..io.atomic import check_replaceable

    if int(size) < 32:
        raise InputError(f"--size must be at least 32 for the recognition study, got {size}")
    if out_dir is not None:
        check_replaceable(out_dir, overwrite=overwrite, kind="materials recognition study")

    def say(msg):
        if progress is not None:
            progress(msg)

    t0 = time.perf_counter()
    shape = (int(size), int(size))
    say("simulating the training and held-out captures")
    train = simulate_capture(size=shape, **TRAIN_SETTINGS)
    test = simulate_capture(size=shape, **TEST_SETTINGS)
    say("demultiplexing")
    tr_train, tr_test = capture_transport(train.stack), capture_transport(test.stack)
    mm_per_pixel = _MM_PER_ROW * tr_test.geometry.rows_per_camera_row
    timings = {}
    say("fitting the training capture (the library)")
    t = time.perf_counter()
    library, _ = reference_library(tr_train, train.labels, block_px=block_px, source="report training capture")
    timings["library_fit_s"] = time.perf_counter() - t
    say("fitting the held-out capture")
    t = time.perf_counter()
    maps = fit_image(tr_test, mm_per_row=_MM_PER_ROW, block_px=block_px)
    timings["test_fit_s"] = time.perf_counter() - t
    regions = container_regions(test.labels)
    _, region_maps = recognize_regions(library, tr_test, regions, mm_per_row=_MM_PER_ROW)
    say("training the SVM")
    t = time.perf_counter()
    model = train_model([train.stack], [train.labels], ignore_classes=(6,), floor="edge")
    svm = model.predict(test.stack, unclassified_below=0.0)
    timings["svm_s"] = time.perf_counter() - t
    numbers = recognition_tables(
        library, maps, region_maps, svm, test.labels, test.wall_distance_mm, regions, mm_per_pixel=mm_per_pixel
    )
    numbers.update(
        size=list(shape),
        block_px=int(block_px),
        train=dict(TRAIN_SETTINGS),
        test=dict(TEST_SETTINGS),
        timings_s={**timings, "total": time.perf_counter() - t0},
    )
    if out_dir is not None:
        write_recognition_study(out_dir, numbers, library, overwrite=overwrite)
    return numbers
