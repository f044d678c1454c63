"""The folder of ``planeray materials fit`` as a function, and how the materials commands read a capture.

:func:`fit_materials` does the command's whole work -- checks before any work, reading the
capture, fitting, writing the folder atomically -- so a notebook produces the same files, bytes
and ``planeray.json`` as the command line: maps of mu_s' and mu_a with standard errors, the
identifiability mask, the flag layer, the figure and ``planeray.json``.  The other materials
commands' outputs (``recognize``, ``library-add``, ``predict``) are in
:mod:`planeray.experiments.materials_recognize`; they read captures with the helpers here.

The capture's settings (row size, refractive index, depth, white reference, camera) are one
:class:`~planeray.materials.settings.CaptureSettings`.  Options are keyword-only; ``progress``
and ``note`` are as in :mod:`planeray.experiments.workflow`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import InputError, parameter_name
from ..io import atomic_directory, jsonable
from ..io.atomic import planeray_output_kind, same_place
from ..io.lock import writes_output
from ..materials.settings import CaptureSettings
from .workflow import Stages, check_folder_output

__all__ = [
    "fit_materials",
    "check_fit_options",
    "forward_table",
    "read_labels",
    "write_map_tiff",
    "MAP_UNITS",
]

#: A capture given as its own white reference would "calibrate" it to an albedo of one.
_WHITE_IS_CAPTURE = (
    "{option} {white} is the capture itself: a white reference is a separate capture of a white "
    "Lambertian target, with the same sweep and camera"
)

#: The quantity and unit each map's TIFF records in its description.
MAP_UNITS = {
    "mu_s_prime_per_mm": ("reduced scattering coefficient mu_s'", "1/mm"),
    "mu_a_per_mm": ("absorption coefficient mu_a", "1/mm"),
    "mu_s_prime_se_per_mm": ("standard error of mu_s'", "1/mm"),
    "mu_a_se_per_mm": ("standard error of mu_a", "1/mm"),
    "mask": ("identifiability mask: bits of the reasons in planeray.json (0: both measured)", "bits"),
    "flags": ("flag layer: bits of flag_bits in planeray.json (0: the model fits, nothing at an edge)", "bits"),
    "recognition_flags": ("recognition flags: bits of flag_bits in planeray.json (8: none of these)", "bits"),
}


def write_map_tiff(path: Path, image, key: str) -> None:
    """A float32 (mask, flags: uint8) TIFF with planeray's mark, and its quantity and unit in the description."""
    import tifffile

    from ..io import atomic_file
    from ..io.marks import mark_text

    what, unit = MAP_UNITS[key]
    arr = np.asarray(image, np.uint8 if key in ("mask", "flags", "recognition_flags") else np.float32)
    with atomic_file(path) as tmp:
        tifffile.imwrite(
            tmp,
            arr,
            photometric="minisblack",
            software=mark_text("image"),
            description=json.dumps({"quantity": what, "unit": unit, "name": key}),
            metadata=None,
        )


def read_labels(path, option: str, shape, *, labelled: bool = True):
    """A label image of the capture's size, errors naming ``option``; ``labelled``: refuse one with no labelled pixel."""
    from ..materials import read_label_image

    try:
        lab = read_label_image(path, shape=shape)
    except InputError as exc:
        raise InputError(f"{option} {exc}") from None
    if labelled and not np.any(lab > 0):
        raise InputError(
            f"{option} {path}: no labelled pixel (every pixel is 0, 'unlabelled'); mark the regions with class ids "
            "1-255"
        )
    return lab


def _labels(path, shape, name: str = "labels", *, labelled: bool = True):
    return read_labels(path, parameter_name(name), shape, labelled=labelled)


def _exists(path) -> None:
    if not Path(path).exists():
        raise InputError(f"the capture {path}: no such file or folder")


def _recorded_mm(meta: dict):
    from ..stack import recorded_mm_per_row

    return recorded_mm_per_row(meta)[0]


def _load_stack(path):
    from ..io import read_stack

    return read_stack(path)


def _stack_and_row_size(path, mm_per_row):
    """``(stack, metadata, mm per row)``: ``mm_per_row``, else the capture's (its acquisition.json); neither:
    one line naming both (no default stands in)."""
    stack = _load_stack(path)
    meta = dict(stack.metadata or {})
    mm = mm_per_row if mm_per_row is not None else _recorded_mm(meta)
    if mm is None:
        raise InputError(
            f"{path} does not record its row size: pass {parameter_name('mm_per_row')} (mm per projector row) or add "
            '"mm_per_row" to its acquisition.json'
        )
    return stack, meta, mm


def _read_fit_input(path, option: str, stages: Stages):
    """``(transport, metadata)`` of a transport store, or of a stack demultiplexed (floor removed) first."""
    from ..io.transport_store import read_transport
    from ..materials.model import capture_transport

    if not Path(path).exists():
        raise InputError(f"{option} {path}: no such file or folder")
    if planeray_output_kind(path) == "transport":
        transport, attrs = read_transport(path)
        return transport, dict(attrs)
    st = _load_stack(path)
    advance = stages.stage(f"demultiplexing {Path(path).name} (rows)", st.shape[0])
    return capture_transport(st, progress=advance), dict(st.metadata or {})


def _capture_and_row_size(path, mm_per_row, stages: Stages):
    """The capture's transport (a stack demultiplexed), its record, and its row size (mm per projector row)."""
    transport, meta = _read_fit_input(path, "the capture", stages)
    mm = mm_per_row if mm_per_row is not None else _recorded_mm(meta)
    if mm is None:
        raise InputError(
            f"{path} does not record its row size: pass {parameter_name('mm_per_row')} (mm per projector row)"
        )
    return transport, meta, mm


def _capture_geometry(path) -> tuple[int, int, float]:
    """``(H, W, rows_per_camera_row)`` of a capture (stack or transport store), read without demultiplexing it."""
    from ..io import read_transport

    _exists(path)
    if planeray_output_kind(path) == "transport":
        import zarr

        try:
            group = zarr.open_group(str(path), mode="r")
            H, W = (int(n) for n in group["T"].shape[:2])
            return H, W, float(group.attrs["projector_rows"]) / H
        except Exception:  # a damaged store: read it properly, for the reader's one-line message
            transport = read_transport(path)[0]
            return (*transport.shape, float(transport.geometry.rows_per_camera_row))
    st = _load_stack(path)
    return (*st.shape, float(st.geometry.rows_per_camera_row))


def _library(library):
    """``library`` (else the shipped one), errors naming the parameter."""
    from ..materials.library import default_library, load_library

    try:
        return load_library(library) if library is not None else default_library()
    except InputError as exc:
        raise InputError(f"{parameter_name('library')} {exc}") from None


def _library_and_capture(lib, path, mm_per_row, stages: Stages):
    """The capture's transport, record and row size, the row size checked against the library ``lib``."""
    transport, meta, mm = _capture_and_row_size(path, mm_per_row, stages)
    try:
        lib.check_conditions(mm_per_row=mm, calibrated=False)
    except InputError as exc:
        raise InputError(f"{parameter_name('library')} {exc}") from None
    return transport, meta, mm


def forward_table(n: float, stages: Stages):
    """The forward table of index ``n``: loaded when shipped or cached, else traced -- noted with a time
    estimate measured on a pilot run, and counted as a stage."""
    from ..materials import fit as mfit
    from ..mc.cache import cache_dir

    if mfit.forward_table_stored(n=n):
        return mfit.forward_table(n=n)
    stages.stage(f"estimating the time to trace the forward table of n = {n:g}")
    seconds = mfit.forward_table_seconds(n=n)
    stages.note(
        f"no forward table for n = {n:g} is shipped or cached: tracing it by Monte Carlo first "
        f"({mfit.TABLE_RUNS} runs, about {seconds / 60:.0f} minutes on this machine, measured on a pilot run; "
        f"once: cached in {cache_dir()})"
    )
    advance = stages.stage(f"tracing the forward table of n = {n:g} (Monte Carlo runs)", mfit.TABLE_RUNS)
    return mfit.forward_table(n=n, progress=advance)


def _white_stack(white_reference, stack):
    """The white reference's stack (its kind checked before the capture was read), checked against the capture's
    sweep, size and images."""
    option = parameter_name("white_reference")
    white = _load_stack(white_reference)
    if white.shape != stack.shape or not (
        np.array_equal(white.delay_us, stack.delay_us) and np.array_equal(white.exposure_us, stack.exposure_us)
    ):
        raise InputError(
            f"{option} {white_reference} is {white.shape[0]}x{white.shape[1]} over "
            f"{len(white)} images, the capture {stack.shape[0]}x{stack.shape[1]} over {len(stack)}: "
            "capture it with the same sweep and camera"
        )
    if white.content_digest() == stack.content_digest():
        raise InputError(_WHITE_IS_CAPTURE.format(option=option, white=white_reference) + " (the same images)")
    return white


def _white_scale(white_reference, transport, albedo: float, stages: Stages):
    """The white reference's calibration of a transport fit (its transport checked against the capture's)."""
    from ..materials import fit as mfit

    option = parameter_name("white_reference")
    white, _ = _read_fit_input(white_reference, option, stages)
    if white.shape != transport.shape or not np.array_equal(white.offsets_rows, transport.offsets_rows):
        raise InputError(
            f"{option} {white_reference} is {white.shape[0]}x{white.shape[1]} over "
            f"{white.offsets_rows.size} offsets, the capture {transport.shape[0]}x{transport.shape[1]} over "
            f"{transport.offsets_rows.size}: capture it with the same sweep and camera"
        )
    if np.array_equal(white.dense, transport.dense):
        raise InputError(_WHITE_IS_CAPTURE.format(option=option, white=white_reference) + " (the same transport)")
    return mfit.white_reference_scale(white.dense, albedo=albedo)


def check_fit_options(block_px, method, wall_kind) -> None:
    """The options of :func:`fit_materials` that need no file, checked (one line naming the bad one)."""
    from ..materials import fit as mfit

    if block_px is not None and not 1 <= block_px <= 64:
        raise InputError(f"{parameter_name('block_px')} must be an integer in 1-64, got {block_px}")
    if method is not None and method not in ("stack", "transport"):
        raise InputError(f"{parameter_name('method')} must be stack or transport, got {method!r}")
    if wall_kind not in mfit.WALL_KINDS:
        raise InputError(
            f"{parameter_name('wall_kind')} must be one of {', '.join(mfit.WALL_KINDS)}, got {wall_kind!r}"
        )


def _fit_inputs(capture, settings: CaptureSettings, labels, method, block_px, stages: Stages) -> dict:
    """What the fit reads: the capture (a stack, or its transport), its labels, record, row size and white."""
    _exists(capture)
    white_reference = settings.white_reference
    if white_reference is not None and same_place(Path(white_reference), Path(capture)):
        raise InputError(_WHITE_IS_CAPTURE.format(option=parameter_name("white_reference"), white=white_reference))
    is_transport = planeray_output_kind(capture) == "transport"
    if method == "stack" and is_transport:
        raise InputError(f"{parameter_name('method')} stack needs a stack: {capture} is a transport store")
    method = method or ("transport" if is_transport else "stack")
    got = {"method": method, "block_px": block_px, "stack": None, "transport": None, "white": None, "scale": None}
    if method == "stack":
        if white_reference is not None:  # its kind checked before the capture is read
            option = parameter_name("white_reference")
            if not Path(white_reference).exists():
                raise InputError(f"{option} {white_reference}: no such file or folder")
            if planeray_output_kind(white_reference) == "transport":
                raise InputError(
                    f"{option} {white_reference} is a transport store: the stack fit needs the white "
                    f"target's stack (or {parameter_name('method')} transport)"
                )
        stack, meta, mm = _stack_and_row_size(capture, settings.mm_per_row)
        got["labels"] = _labels(labels, stack.shape) if labels is not None else None
        if white_reference is not None:
            got["white"] = _white_stack(white_reference, stack)
        got["stack"], shape = stack, stack.shape
    else:
        transport, meta, mm = _capture_and_row_size(capture, settings.mm_per_row, stages)
        got["labels"] = _labels(labels, transport.shape) if labels is not None else None
        got["block_px"] = 4 if block_px is None else block_px
        if white_reference is not None:
            got["scale"] = _white_scale(white_reference, transport, settings.white_albedo, stages)
        got["transport"], shape = transport, transport.shape
    from ..camera import CameraModel
    from ..stack import recorded_mm_per_row

    got["meta"], got["mm"], got["shape"] = meta, mm, tuple(shape)
    got["mm_source"] = parameter_name("mm_per_row") if settings.mm_per_row is not None else recorded_mm_per_row(meta)[1]
    got["camera"] = None if method != "stack" else settings.camera or CameraModel.from_metadata(meta)
    return got


def _fit_units(regions, block_px) -> tuple[int, int]:
    """``(regions, blocks)`` the fit works through (for its progress)."""
    H, W = regions.shape
    n_regions = sum(1 for r in np.unique(regions) if r != 0)
    if block_px is None:
        return n_regions, 0
    n_blocks = sum(
        1
        for r in np.unique(regions)
        if r != 0
        for r0 in range(0, H, block_px)
        for c0 in range(0, W, block_px)
        if (regions[r0 : r0 + block_px, c0 : c0 + block_px] == r).any()
    )
    return n_regions, n_blocks


def _run_fit(got: dict, settings: CaptureSettings, table, walls: bool, wall_kind: str, stages: Stages):
    """The fit itself: the stack's images (:func:`~planeray.materials.stackfit.fit_stack`) or the transport's."""
    from ..materials import fit as mfit

    lab, block = got["labels"], got["block_px"]
    regions = lab if lab is not None else np.ones(got["shape"], np.int64)
    n_regions, n_blocks = _fit_units(regions, block)
    if got["method"] == "stack":
        from ..materials.stackfit import fit_stack

        advance = stages.stage("fitting the stack's images (regions, blocks)", n_regions + n_blocks)
        return fit_stack(
            got["stack"], mm_per_row=got["mm"], labels=lab, containers=lab if walls else None, white=got["white"],
            white_albedo=settings.white_albedo, block_px=block, table=table, camera=got["camera"],
            depth_mm=settings.depth_mm, wall_kind=wall_kind, g=settings.g, progress=advance,
        )  # fmt: skip
    advance = stages.stage("fitting pixel blocks", n_blocks)
    return mfit.fit_transport(
        got["transport"], mm_per_row=got["mm"], labels=lab, white_scale=got["scale"], block_px=block,
        containers=lab if walls else None, table=table, depth_mm=settings.depth_mm, wall_kind=wall_kind,
        g=settings.g, progress=advance,
    )  # fmt: skip


def _fit_summary(capture, got: dict, settings: CaptureSettings, result, walls: bool, wall_kind: str) -> dict:
    """The fit's ``planeray.json`` (before :func:`~planeray.io.jsonable`)."""
    from ..goodness import DEFAULT_P_MISFIT, FLAGS
    from ..materials import fit as mfit

    method, block, n = got["method"], got["block_px"], settings.refractive_index
    depth_mm, white_reference = settings.depth_mm, settings.white_reference
    return {
        "format": "planeray-materials-fit",
        "format_version": 1,
        "capture": str(capture),
        "method": (
            "stack: the stack's images fitted directly (illumination matrix x line kernel + ambient per region)"
            if method == "stack"
            else "transport: the demultiplexed (or given) transport's profiles fitted"
        ),
        "mm_per_row": got["mm"],
        "mm_per_row_source": got["mm_source"],
        "refractive_index": n,
        "refractive_index_source": (
            parameter_name("n") if settings.n_stated else f"assumed (water-based media; state {parameter_name('n')})"
        ),
        "anisotropy_g": settings.g,
        "anisotropy_g_source": (
            parameter_name("g")
            if settings.g is not None
            else "unknown: fitted within 0-0.95 with mu_s' and mu_a (each region's g, g_se); its uncertainty is in "
            "theirs"
        ),
        "depth_mm": depth_mm,
        "bottom": "none: semi-infinite" if depth_mm is None else f"at {depth_mm:g} mm: returns no light",
        "noise_model": (
            "the camera's (its record: shot, read, quantization and row jitter) and the forward model's error"
            if got["camera"] is not None
            else "the pixels' spread (the capture records no camera) and the forward model's error"
        ),
        "goodness_of_fit": (
            "reduced chi-square against the noise model; a fit less probable than p = "
            f"{DEFAULT_P_MISFIT:g} is flagged 'model does not fit' and its standard errors are scaled by "
            "sqrt(chi2 / dof); parameters at the forward model's edge are flagged and not reported"
        ),
        "calibration": (
            f"white reference {white_reference} (albedo {settings.white_albedo:g}): absolute reflectance"
            if white_reference is not None
            else f"none: shape only (a free scale per {'region' if method == 'stack' and block is None else 'block'}); mu_a is less identifiable"
        ),
        "block_px": block,
        "walls": (
            f"modelled: each {parameter_name('labels')} region is a container with a {wall_kind} wall at its boundary"
            if walls and got["labels"] is not None
            else "none: unbounded media"
        ),
        "regions": {str(k): v for k, v in result.regions.items()},
        "mask_bits": {str(k): v for k, v in mfit.REASONS.items()} | {"255": "not fitted (outside every region)"},
        "flag_bits": {str(k): v for k, v in FLAGS.items()} | {"255": "outside every region"},
        "files": {
            **{k: f"{k}.tif" for k in ("mu_s_prime_per_mm", "mu_a_per_mm", "mu_s_prime_se_per_mm", "mu_a_se_per_mm")},
            "mask": "identifiability_mask.tif",
            "flags": "flags.tif",
            "figure": "fit.png",
        },
    }


@writes_output("out_dir")
def fit_materials(
    capture,
    out_dir,
    *,
    settings: CaptureSettings | None = None,
    labels=None,
    block_px: int | None = None,
    method: str | None = None,
    walls: bool = True,
    wall_kind: str = "clear",
    overwrite: bool = False,
    progress=None,
    note=None,
) -> dict:
    """Measure a medium: maps of mu_s' and mu_a (1/mm) with standard errors, per region and pixel block.

    Writes the folder of ``planeray materials fit``: ``mu_s_prime_per_mm.tif``, ``mu_a_per_mm.tif``
    and their standard errors ``*_se_per_mm.tif`` (float32, 1/mm), ``identifiability_mask.tif``
    (uint8 bits of the reasons a parameter is not measured), ``flags.tif`` (uint8 bits: the model
    does not fit, a parameter at the forward model's edge), ``fit.png`` and ``planeray.json``.
    Every fit says whether its forward model fits the data (reduced chi-square against the
    camera's noise model and the model's own error).

    Parameters
    ----------
    capture : str or os.PathLike
        Stack (fitted directly, or demultiplexed first with ``method="transport"``) or transport store.
    out_dir : str or os.PathLike
        Folder to write (refused if it exists, unless ``overwrite`` and planeray wrote it).
    settings : CaptureSettings, optional
        Row size, refractive index, depth, white reference and camera (default: all from the capture,
        the index assumed 1.33 and noted).
    labels : str or os.PathLike, optional
        Label image of regions (0: left out); default: one region.
    block_px : int, optional
        Fit blocks of ``block_px`` x ``block_px`` pixels (1-64) for the maps; default: 4 for a
        transport, none for a stack (the maps hold each region's estimate).
    method : {"stack", "transport"}, optional
        Default: ``"stack"`` for a stack, ``"transport"`` for a transport store.
    walls : bool
        With ``labels``: each region is a container with a wall at its boundary.
    wall_kind : {"clear", "black"}
        The containers' walls.
    overwrite : bool
        Replace a fit folder planeray wrote.
    progress, note : callable, optional
        ``progress(stage, done, total)`` and ``note(text)`` (:mod:`planeray.experiments.workflow`).

    Returns
    -------
    dict
        The summary written to ``planeray.json`` (its ``regions``: each region's estimates, standard
        errors, fit quality and flags), before non-finite numbers become ``null``.
    """
    settings = CaptureSettings() if settings is None else settings
    stages = Stages(progress, note)
    check_fit_options(block_px, method, wall_kind)
    out_dir = check_folder_output(
        out_dir,
        [("the capture", capture), (parameter_name("labels"), labels),
         (parameter_name("white_reference"), settings.white_reference)],
        overwrite=overwrite, kind="materials fit",
    )  # fmt: skip
    got = _fit_inputs(capture, settings, labels, method, block_px, stages)
    n = settings.refractive_index
    if not settings.n_stated:
        stages.note(
            f"the medium's refractive index is assumed {n:g} (water-based media): a wrong index biases mu_s' "
            f"by tens of percent without showing in the fit's chi-square; state it with {parameter_name('n')} (1 for "
            "an index-matched surface)"
        )
    result = _run_fit(got, settings, forward_table(n, stages), walls, wall_kind, stages)
    summary = _fit_summary(capture, got, settings, result, walls, wall_kind)
    from ..figures.materials import fit_figure

    with atomic_directory(out_dir, overwrite=overwrite, kind="materials fit") as tmp:
        for key, name in summary["files"].items():
            if key != "figure":
                write_map_tiff(tmp / name, result.maps[key], key)
        fit_figure(result, mm_per_row=got["mm"], out=tmp / "fit.png")
        (tmp / "planeray.json").write_text(json.dumps(jsonable(summary), indent=1))
    return summary
