"""The outputs of ``planeray materials recognize``, ``library-add`` and ``predict``, as functions.

Each function does one command's whole work -- checks before any work, reading the capture,
fitting or classifying, writing atomically -- so a notebook produces the same files, bytes and
``planeray.json`` as the command line:

* :func:`recognize_materials`: the segmentation, the flag layer, the figure and
  ``planeray.json`` (``planeray materials recognize``);
* :func:`add_to_library`: a media library with the labelled regions of a capture added
  (``planeray materials library-add``);
* :func:`segment_materials`: a trained model's segmentation (``planeray materials predict``).

Options are keyword-only; ``progress`` and ``note`` are as in :mod:`planeray.experiments.workflow`.
"""

from __future__ import annotations

import json
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..errors import InputError, parameter_name
from ..io import atomic_directory, jsonable
from ..io.atomic import planeray_output_kind, same_place
from ..io.lock import writes_output
from ..materials.settings import CaptureSettings
from .materials_folders import (
    _capture_geometry,
    _exists,
    _labels,
    _library,
    _library_and_capture,
    _load_stack,
    _stack_and_row_size,
    forward_table,
    write_map_tiff,
)
from .workflow import Stages, check_folder_output

__all__ = [
    "recognize_materials",
    "add_to_library",
    "segment_materials",
    "check_recognition_options",
    "check_library_add",
    "check_predict_options",
    "wall_distance_from_labels",
]


def wall_distance_from_labels(labels, mm_per_pixel):
    """Distance (mm) of each pixel's centre to the edge of its labelled region (the container's wall)."""
    from scipy import ndimage

    lab = np.asarray(labels)
    out = np.full(lab.shape, np.inf)
    for c in np.unique(lab[lab > 0]):
        m = lab == c
        d = ndimage.distance_transform_edt(np.pad(m, 1, constant_values=False))[1:-1, 1:-1]
        out[m] = (d[m] - 0.5) * mm_per_pixel
    return out


def check_recognition_options(block_px, regions, pool_mm, p_unknown) -> None:
    """The options of :func:`recognize_materials` that need no file, checked."""
    if not 1 <= block_px <= 16:
        raise InputError(f"{parameter_name('block_px')} must be an integer in 1-16, got {block_px}")
    if regions is not None and pool_mm is not None:
        raise InputError(
            f"{parameter_name('regions')} and {parameter_name('pool_mm')}: fit the regions or pool over a disc, "
            "not both"
        )
    if pool_mm is not None and not (np.isfinite(pool_mm) and 0.0 <= pool_mm <= 100.0):
        raise InputError(f"{parameter_name('pool_mm')} must be in 0-100 mm, got {pool_mm:g}")
    if not 0.0 <= p_unknown < 1.0:
        raise InputError(f"{parameter_name('p_unknown')} must be in [0, 1), got {p_unknown:g}")


def _recognize_by_containers(lib, capture, settings, reg, regions, p_unknown, stages) -> dict:
    """Each container (``reg``, else found in the images) fitted from the stack's images."""
    from ..camera import CameraModel
    from ..materials.recognize import recognize_stack

    stack, meta, mm = _stack_and_row_size(capture, settings.mm_per_row)
    for n, _ in lib.hypotheses():
        forward_table(n, stages)  # noted and traced once where not shipped or cached
    advance = stages.stage("fitting the containers (one pass per index and depth)", len(lib.hypotheses()))
    rec, details = recognize_stack(
        lib, stack, mm_per_row=mm, regions=reg, camera=settings.camera or CameraModel.from_metadata(meta),
        p_unknown=p_unknown, progress=advance,
    )  # fmt: skip
    pooling = (
        f"each region of {regions} fitted as a whole" if reg is not None
        else "each container found in the images (light from below the surface) fitted as a whole"
    )  # fmt: skip
    return {"rec": rec, "details": details, "mm": mm, "rpc": float(stack.geometry.rows_per_camera_row),
            "pooling": pooling, "by_containers": True}  # fmt: skip


def _pool_radius(pool_mm, px_mm: float, mm: float, stages: Stages) -> float:
    """The pooling radius (mm): ``pool_mm``, else the default; one smaller than a pixel is refused (or, the
    default, dropped with a note)."""
    from ..materials.recognize import DEFAULT_POOL_MM

    pool = DEFAULT_POOL_MM if pool_mm is None else pool_mm
    if 0.0 < pool < px_mm:
        if pool_mm is not None:
            raise InputError(
                f"{parameter_name('pool_mm')} {pool_mm:g} is smaller than a pixel ({px_mm:.3g} mm at {mm:g} mm per "
                f"row): it would pool nothing; give at least {px_mm:.3g} mm, or 0 (per block)"
            )
        stages.note(f"the default pooling radius {pool:g} mm is smaller than a pixel ({px_mm:.3g} mm): no pooling")
        pool = 0.0
    return pool


def _recognize_by_fits(lib, capture, settings, reg, regions, pool_mm, block_px, p_unknown, stages) -> dict:
    """The capture's transport fitted (each region's pooled profile, or pixel blocks pooled over a disc)."""
    from ..materials.recognize import fit_image, recognize_image, recognize_regions

    transport, meta, mm = _library_and_capture(lib, capture, settings.mm_per_row, stages)
    H, W = transport.shape
    rpc = float(transport.geometry.rows_per_camera_row)
    pool = _pool_radius(pool_mm, mm * rpc, mm, stages)
    lib_rpc = lib.conditions.get("rows_per_camera_row")
    if not lib.physical and isinstance(lib_rpc, (int, float)) and abs(rpc / lib_rpc - 1.0) > 0.1:
        stages.note(
            f"the library's media were fitted at {lib_rpc:g} projector rows per camera row, this capture "
            f"has {rpc:g}: a version-1 library's fits are bound to their resolution; a library of physical "
            "parameters (planeray materials library-add from a stack) travels"
        )
    if reg is not None:  # each region's pooled profile fitted once
        stages.stage("fitting each region's pooled profile")
        rec, _ = recognize_regions(lib, transport, reg, mm_per_row=mm, p_unknown=p_unknown)
    else:
        advance = stages.stage("fitting pixel blocks", -(-H // block_px) * -(-W // block_px))
        maps = fit_image(transport, mm_per_row=mm, block_px=block_px, progress=advance)
        rec = recognize_image(lib, maps, mm_per_pixel=mm * rpc, pool_mm=pool, p_unknown=p_unknown)
    pooling = (
        f"regions of {regions}: each region's pooled profile fitted"
        if reg is not None
        else (f"log-likelihoods over a disc of {pool:g} mm" if pool else "none: per pixel block")
    )
    return {"rec": rec, "details": None, "mm": mm, "rpc": rpc, "pooling": pooling, "by_containers": False}


def _recognition_score(rec, truth, names: dict, mm_per_pixel: float) -> dict:
    """Accuracy per class by distance to the walls of ``truth``'s regions, and the share of other pixels named none."""
    from ..materials.recognize import accuracy_by_distance

    wall = wall_distance_from_labels(truth, mm_per_pixel)
    scored = {c: n for c, n in names.items() if (truth == c).any()}
    table = accuracy_by_distance(rec.class_ids, truth, wall, classes=scored)
    others = np.isin(truth, list(scored), invert=True) & (truth > 0)
    table["none_of_these"] = {
        "pixels": int(others.sum()),
        "labelled_none": float((rec.class_ids[others] == 0).mean()) if others.any() else None,
    }
    return table


@writes_output("out_dir")
def recognize_materials(
    capture,
    out_dir,
    *,
    library=None,
    regions=None,
    pool_mm: float | None = None,
    block_px: int = 2,
    p_unknown: float = 1e-3,
    labels=None,
    settings: CaptureSettings | None = None,
    overwrite: bool = False,
    progress=None,
    note=None,
) -> dict:
    """Name each container's medium by its measured mu_s' and mu_a against a library of known media.

    Writes the folder of ``planeray materials recognize``: ``segmentation.png`` (class ids of the
    library; 0: none of these, or not fitted), ``flags.tif`` (uint8 bits of ``flag_bits``),
    ``planeray.json`` and, with ``labels``, ``recognition.png`` (accuracy by distance to the walls).
    With a stack and a library of physical parameters (the shipped one), the containers are found in
    the images and each is fitted as a whole with its walls; otherwise the demultiplexed capture's
    pixel blocks (or ``regions``) are fitted and pooled.

    Parameters
    ----------
    capture : str or os.PathLike
        Stack or transport store.
    out_dir : str or os.PathLike
        Folder to write.
    library : str or os.PathLike, optional
        Media library (JSON); default: the five Fig. 10 media shipped.
    regions : str or os.PathLike, optional
        Label image of the containers (0: none); default: found in the images.
    pool_mm : float, optional
        Fit pixel blocks and pool their evidence over a disc of this radius (mm; 0: per block); the
        default for a transport store or a version-1 library (2.5 mm).
    block_px : int
        With ``pool_mm``: blocks of ``block_px`` x ``block_px`` pixels, 1-16.
    p_unknown : float
        A fit less typical of every medium than this p-value is none of these, in [0, 1).
    labels : str or os.PathLike, optional
        Ground-truth class ids: score per class and by distance to the walls.
    settings : CaptureSettings, optional
        The capture's row size (``mm_per_row``) and camera (default: its record).
    overwrite : bool
        Replace a recognition folder planeray wrote.
    progress, note : callable, optional
        As in :mod:`planeray.experiments.workflow`.

    Returns
    -------
    dict
        The numbers written to ``planeray.json`` (before non-finite numbers become ``null``).
    """
    from ..figures.materials import recognition_by_distance_figure
    from ..materials.labels import write_label_image
    from ..materials.library import FLAGS

    settings = CaptureSettings() if settings is None else settings
    stages = Stages(progress, note)
    check_recognition_options(block_px, regions, pool_mm, p_unknown)
    out_dir = check_folder_output(
        out_dir,
        [("the capture", capture), (parameter_name("library"), library), (parameter_name("regions"), regions),
         (parameter_name("labels"), labels)],
        overwrite=overwrite, kind="materials recognition",
    )  # fmt: skip
    lib = _library(library)
    _exists(capture)
    shape = _capture_geometry(capture)[:2] if regions is not None or labels is not None else None
    reg = _labels(regions, shape, "regions") if regions is not None else None  # before any demultiplexing
    truth = _labels(labels, shape) if labels is not None else None
    if lib.physical and pool_mm is None and planeray_output_kind(capture) != "transport":
        got = _recognize_by_containers(lib, capture, settings, reg, regions, p_unknown, stages)
    else:
        got = _recognize_by_fits(lib, capture, settings, reg, regions, pool_mm, block_px, p_unknown, stages)
    rec, mm = got["rec"], got["mm"]
    names = {e.class_id: e.name for e in lib.entries}
    counts = {names[c]: int((rec.class_ids == c).sum()) for c in lib.class_ids}
    counts["unclassified"] = int((rec.class_ids == 0).sum())  # none of these, or not fitted
    numbers = {
        "format": "planeray-materials-recognition",
        "format_version": 1,
        "capture": str(capture),
        "library": str(library) if library is not None else "shipped (the five Fig. 10 media)",
        "library_version": lib.version,
        "mm_per_row": mm,
        "mm_per_pixel": mm * got["rpc"],
        "block_px": None if got["by_containers"] else block_px,
        "pooling": got["pooling"],
        "p_unknown": p_unknown,
        "pixels": counts,
        "flags": {text: int(((rec.flags & bit) > 0).sum()) for bit, text in FLAGS.items()},
        "flag_bits": {str(bit): text for bit, text in FLAGS.items()},
        "files": {"segmentation": "segmentation.png", "flags": "flags.tif"},
    }
    if got["by_containers"]:
        numbers["containers"] = got["details"]
    table = None if truth is None else _recognition_score(rec, truth, names, mm * got["rpc"])
    if table is not None:
        wall_note = f"from {parameter_name('labels')}: distance to the edge of each labelled region"
        numbers["score"] = {**table, "wall_distance": wall_note}
        numbers["files"]["figure"] = "recognition.png"
    with atomic_directory(out_dir, overwrite=overwrite, kind="materials recognition") as tmp:
        write_label_image(tmp / "segmentation.png", rec.class_ids.astype(np.uint8), kind="segmentation")
        write_map_tiff(tmp / "flags.tif", np.asarray(rec.flags, np.uint8), "recognition_flags")
        if table is not None:
            recognition_by_distance_figure({"parameters": table}, out=tmp / "recognition.png")
        (tmp / "planeray.json").write_text(json.dumps(jsonable(numbers), indent=1))
    return numbers


def check_library_add(out_json, library, class_names: dict, *, overwrite: bool) -> bool:
    """The options of :func:`add_to_library`, checked; returns whether the library is updated in place."""
    if Path(out_json).suffix.lower() != ".json":
        raise InputError(f"{parameter_name('out_json')} must end in .json (a media library), got {out_json}")
    if not class_names:
        raise InputError(f"{parameter_name('class_names')} is needed: ID=NAME of the labelled region to add")
    in_place = library is not None and same_place(Path(out_json), Path(library))
    if in_place and not overwrite:  # updating the library itself: a planeray library, replaced atomically
        raise InputError(
            f"{parameter_name('out_json')} {out_json} is the {parameter_name('library')} to add to: pass "
            f"{parameter_name('overwrite')} to update it in place (planeray replaces only a library it wrote), or "
            f"name a new {parameter_name('out_json')}"
        )
    return in_place


@contextmanager
def _as_class_name_error():
    """A measured entry that cannot be added (a region too small, a name taken): named by ``class_names``."""
    try:
        yield
    except InputError as exc:
        raise InputError(f"{parameter_name('class_names')} {exc}") from None


def _new_entries(lib, capture, lab, class_names, labels, settings, rpc, library, stages) -> list:
    """The library's new entries measured on the capture: physical parameters from the stack's images
    (a version-2 library), else the transport's block fits (version 1)."""
    from ..camera import CameraModel
    from ..materials.recognize import entries_from_capture, entries_from_stack, fit_image

    source = f"{capture} ({labels})"
    if lib.physical:
        if planeray_output_kind(capture) == "transport":
            raise InputError(
                f"{capture} is a transport store: a library of physical parameters is measured from a stack's "
                "images (give the stack)"
            )
        stack, meta, mm = _stack_and_row_size(capture, settings.mm_per_row)
        white = _load_stack(settings.white_reference) if settings.white_reference is not None else None
        n = settings.refractive_index
        with _as_class_name_error():
            table = forward_table(n, stages)
            stages.stage("measuring the labelled regions (each fitted as a whole, walls modelled)")
            return entries_from_stack(
                stack, lab, class_names, mm_per_row=mm, n=n, depth_mm=settings.depth_mm,
                camera=settings.camera or CameraModel.from_metadata(meta), white=white,
                white_albedo=settings.white_albedo, table=table, source=source,
            )  # fmt: skip
    lib_rpc = lib.conditions.get("rows_per_camera_row")
    if lib.entries and isinstance(lib_rpc, (int, float)) and abs(rpc / lib_rpc - 1.0) > 0.1:
        raise InputError(
            f"{parameter_name('library')} {library or '(the shipped one)'}: a version-1 library's media were fitted "
            f"at {lib_rpc:g} projector rows per camera row, {capture} has {rpc:g}: its fits are bound to their "
            "resolution, so an entry from this capture would not be comparable with the others; start a library "
            "of physical parameters (version 2) instead"
        )
    transport, meta, mm = _library_and_capture(lib, capture, settings.mm_per_row, stages)
    block = int(lib.conditions.get("block_px", 2))
    regions = np.where(np.isin(lab, list(class_names)), lab, 0)
    with _as_class_name_error():
        stages.stage("fitting the labelled regions")
        maps = fit_image(transport, mm_per_row=mm, block_px=block, regions=regions)
        return entries_from_capture(maps, regions, class_names, source=source)


@writes_output("out_json")
def add_to_library(
    capture,
    out_json,
    *,
    labels,
    class_names: dict,
    library=None,
    replace: bool = False,
    settings: CaptureSettings | None = None,
    overwrite: bool = False,
    progress=None,
    note=None,
):
    """Add media to a library from labelled regions of a capture (``planeray materials library-add``).

    A library of physical parameters (version 2, the shipped one) gets each region's mu_s' and mu_a,
    measured from the stack's images with its walls modelled, with their uncertainties, the index and
    the layer's depth: values of the medium, which recognize it in captures of any resolution and row
    size.  A version-1 library gets the transport's block fits.

    Parameters
    ----------
    capture : str or os.PathLike
        Stack of the capture (a transport store: version-1 libraries).
    out_json : str or os.PathLike
        The new library (``.json``); the ``library`` itself only with ``overwrite``.
    labels : str or os.PathLike
        Label image: the region(s) of the new media.
    class_names : dict of int to str
        ``{class id: name}`` of the labelled regions to add (ids 1-255).
    library : str or os.PathLike, optional
        Library to add to; default: the shipped one.
    replace : bool
        Replace an entry of the same name or id.
    settings : CaptureSettings, optional
        Row size, the medium's index (stored with it; default 1.33) and layer depth, white reference
        and camera.
    overwrite : bool
        Replace a library file planeray wrote.
    progress, note : callable, optional
        As in :mod:`planeray.experiments.workflow`.

    Returns
    -------
    (MediaLibrary, list of MediaEntry)
        The library written and the entries added.
    """
    from ..materials.library import save_library

    settings = CaptureSettings() if settings is None else settings
    stages = Stages(progress, note)
    in_place = check_library_add(out_json, library, class_names, overwrite=overwrite)
    check_folder_output(
        out_json,
        [("the capture", capture), (parameter_name("labels"), labels),
         (parameter_name("white_reference"), settings.white_reference)]
        + ([] if in_place else [(parameter_name("library"), library)]),
        overwrite=overwrite, kind="media library", name="out_json",
    )  # fmt: skip
    lib = _library(library)
    H, W, rpc = _capture_geometry(capture)  # the labels and the resolution before any demultiplexing
    lab = _labels(labels, (H, W))
    missing = [f"{c}={nm}" for c, nm in class_names.items() if not (lab == c).any()]
    if missing:
        raise InputError(
            f"{parameter_name('class_names')} {', '.join(missing)}: {parameter_name('labels')} {labels} has no "
            "pixel of that id"
        )
    entries = _new_entries(lib, capture, lab, class_names, labels, settings, rpc, library, stages)
    with _as_class_name_error():
        for e in entries:
            lib = lib.add(e, replace=replace)
    save_library(lib, out_json)
    return lib, entries


def check_predict_options(out_png, *, labels, near_wall, unclassified_below: float, majority_px: float) -> float:
    """The options of :func:`segment_materials` that need no file, checked; returns the typicality threshold."""
    from ..materials.labels import LABEL_SUFFIXES
    from ..materials.model import check_unclassified_below

    threshold = check_unclassified_below(unclassified_below)
    if not 0.0 <= majority_px <= 50.0:
        raise InputError(f"{parameter_name('majority_px')} must be in 0-50 pixels, got {majority_px:g}")
    if Path(out_png).suffix.lower() not in LABEL_SUFFIXES:
        raise InputError(
            f"{parameter_name('out_png')} must end in .png, .tif or .tiff (a label image of class ids), got {out_png}"
        )
    if near_wall is not None and labels is None:
        raise InputError(
            f"{parameter_name('near_wall')} needs {parameter_name('labels')}: it splits the accuracies into near "
            "walls and away from them"
        )
    return threshold


def _unclassified_by_class(seg, truth, confusion) -> dict:
    """Share of each true class's pixels (with a profile) left unclassified (None: no such pixels)."""
    out = {}
    for cid, name in zip(confusion["classes"], confusion["names"]):
        m = (truth == cid) & ~seg.no_profile
        out[name] = float(seg.unclassified[m].mean()) if m.any() else None
    return out


def _segment(model, st, source: str, threshold: float, majority_px: float, stages: Stages):
    """The model's segmentation of the stack (demultiplexed first for a transport model), majority-voted."""
    if model.definition.kind == "transport":  # demultiplexing first: minutes, counted in camera rows
        advance = stages.stage("demultiplexing the stack (rows)", st.shape[0])
        seg = model.segment(st, unclassified_below=threshold, source=source, progress=advance)
    else:
        stages.stage("classifying pixels")
        seg = model.segment(st, unclassified_below=threshold, source=source)
    if majority_px > 0:
        from ..materials.recognize import mode_filter

        voted = mode_filter(seg.labels, radius_px=majority_px, classes=sorted(model.classes))
        keep = (seg.labels > 0) & ~seg.no_profile & ~seg.unclassified
        seg.labels[...] = np.where(keep & (voted > 0), voted, seg.labels)
    return seg


@writes_output("out_png")
def segment_materials(
    model,
    stack,
    out_png,
    *,
    labels=None,
    near_wall=None,
    unclassified_below: float = 0.01,
    majority_px: float = 0.0,
    overwrite: bool = False,
    progress=None,
    note=None,
) -> dict:
    """Segment a capture pixel by pixel with a trained model (``planeray materials predict``).

    Writes the segmentation ``out_png``: a palette PNG (or TIFF) of class ids, 0 where no class
    (unclassified, or no profile).  Refused if the stack's sweep differs from the model's.

    Parameters
    ----------
    model : str or os.PathLike
        Model file (``planeray materials train``).
    stack : str or os.PathLike
        Stack (Zarr or import folder) of the same sweep.
    out_png : str or os.PathLike
        Segmentation to write (``.png``, ``.tif`` or ``.tiff``).
    labels : str or os.PathLike, optional
        Ground-truth label image: score the prediction.
    near_wall : str or os.PathLike, optional
        Mask of pixels near walls (non-zero), scored apart (with ``labels``).
    unclassified_below : float
        A pixel less typical of the SVM's pick than this share of the class's held-out training pixels
        is unclassified; 0 keeps every pick.
    majority_px : float
        Radius (pixels, 0-50; 0: off) of the majority vote over the picks.
    overwrite : bool
        Replace a segmentation planeray wrote.
    progress, note : callable, optional
        As in :mod:`planeray.experiments.workflow`.

    Returns
    -------
    dict
        The numbers: pixels per class, the settings and, with ``labels``, the score.
    """
    from ..materials import load_model
    from ..materials.labels import write_label_image
    from .materials import score

    stages = Stages(progress, note)
    threshold = check_predict_options(
        out_png, labels=labels, near_wall=near_wall, unclassified_below=unclassified_below, majority_px=majority_px
    )
    inputs = [("MODEL", model), ("STACK", stack), (parameter_name("labels"), labels),
              (parameter_name("near_wall"), near_wall)]  # fmt: skip
    check_folder_output(out_png, inputs, overwrite=overwrite, kind="segmentation", name="out_png")
    svm = load_model(model)
    st = _load_stack(stack)
    svm.check_stack(st, source=str(stack))
    truth = _labels(labels, st.shape) if labels is not None else None
    near = _labels(near_wall, st.shape, "near_wall", labelled=False) > 0 if near_wall is not None else None
    blind = {c: p for c, p in svm.smallest_typicality().items() if 0 < threshold <= p}
    if blind:
        stages.note(
            f"{parameter_name('unclassified_below')} {threshold:g} cannot unclassify any pixel of "
            + ", ".join(f"{svm.classes[c]} (smallest typicality {p:.3g})" for c, p in blind.items())
            + ": too few held-out training pixels; train with more (--max-per-class, more captures) or raise it"
        )
    seg = _segment(svm, st, str(stack), threshold, majority_px, stages)
    write_label_image(out_png, seg.labels, kind="segmentation")
    counts = {}
    for c in sorted(set(seg.labels[~seg.no_profile & ~seg.unclassified].ravel().tolist())):
        counts[svm.classes.get(int(c), f"class {int(c)}")] = int(((seg.labels == c) & ~seg.no_profile).sum())
    counts["unclassified"] = int(seg.unclassified.sum())
    counts["no profile"] = int(seg.no_profile.sum())
    numbers = {"segmentation": str(out_png), "pixels": counts, "unclassified_below": threshold,
               "majority_px": majority_px, "model": str(model), "features": svm.definition.describe()}  # fmt: skip
    if truth is not None:
        classes = sorted(set(svm.classes) | {int(c) for c in set(truth.ravel().tolist()) if c})
        numbers["score"] = score(seg.labels, truth, near_wall=near, classes=classes, model_classes=sorted(svm.classes))
        numbers["score"]["unclassified"] = _unclassified_by_class(seg, truth, numbers["score"]["confusion"])
    return numbers
