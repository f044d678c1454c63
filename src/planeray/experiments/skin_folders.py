"""The documented output folders of ``planeray skin veins`` and ``enhance``, as functions; the skin options' checks.

Each function does one command's whole work -- checks before any work, reading the capture,
computing, writing the folder atomically -- so a notebook produces the same files, bytes and
``planeray.json`` as the command line:

* :func:`vein_images`: the short-range indirect delay image, the t_d = 0 band image and (from a
  transport) the epipolar image, each named for its band, with CNR per vein on a vein mask
  (``planeray skin veins``);
* :func:`enhance_veins`: Eq. 7's contrast enhancement over a stack's delay images and its delay
  map (``planeray skin enhance``).

Each vein's depth (``planeray skin depth``) is :func:`planeray.experiments.skin_depth_folder.vein_depths`.
Options are keyword-only; ``progress`` is as in :mod:`planeray.experiments.workflow`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import InputError, parameter_name
from ..io import atomic_directory, jsonable
from ..io.atomic import MARKER
from ..io.lock import writes_output
from ..timing import PAPER_LINES_PER_SECOND, PAPER_PROJECTOR_ROWS
from .workflow import Stages, check_folder_output

__all__ = [
    "vein_images",
    "enhance_veins",
    "check_tone",
    "check_wavelength",
    "check_mm_per_row",
    "check_delay",
    "check_exposure",
    "source_kind",
    "MAX_MM_PER_ROW",
    "WAVELENGTHS_NM",
]

#: Size of a projector row on the skin an option may ask for, mm (the paper's PicoPro: 0.3 mm at 0.5 m).
MAX_MM_PER_ROW = 10.0
#: The wavelengths the skin optics are tabulated at, nm.
WAVELENGTHS_NM = (638, 850)
#: One sweep of the paper's projector, us: the reach of a delay and the longest exposure.
PROJECTOR_FRAME_US = PAPER_PROJECTOR_ROWS / PAPER_LINES_PER_SECOND * 1e6


def check_tone(text, name: str = "tone"):
    """A skin tone: a tone name or a melanosome fraction in [0, 0.5] (as text or a number)."""
    from ..optical_data_skin import SKIN_TONES

    option = parameter_name(name)
    try:
        value = float(text)
    except ValueError:
        if text not in SKIN_TONES:
            raise InputError(
                f"{option} must be one of {', '.join(SKIN_TONES)} or a melanosome fraction in [0, 0.5], got {text!r}"
            ) from None
        return text
    if not 0.0 <= value <= 0.5:
        raise InputError(f"{option} must be a melanosome fraction in [0, 0.5] (or a tone name), got {text!r}")
    return value


def check_wavelength(value: int, name: str = "wavelength_nm") -> int:
    """A wavelength the skin optics are tabulated at: 638 (red) or 850 nm."""
    if value not in WAVELENGTHS_NM:
        raise InputError(f"{parameter_name(name)} must be 638 (red) or 850 (nm), got {value}")
    return value


def check_mm_per_row(value: float) -> float:
    """The size of a projector row on the skin: > 0 and <= :data:`MAX_MM_PER_ROW` mm."""
    from .._validate import check_number

    return check_number(
        value,
        parameter_name("mm_per_row"),
        minimum=0.0,
        maximum=MAX_MM_PER_ROW,
        min_inclusive=False,
        requirement=f"a size in mm, > 0 and <= {MAX_MM_PER_ROW:g}",
    )


def check_delay(value: float, name: str = "delay_us") -> float:
    """A delay on the projector: finite, within one projector sweep (+-13,333 us) of the epipolar plane."""
    from .._validate import check_number

    f = PROJECTOR_FRAME_US
    return check_number(
        value,
        parameter_name(name),
        minimum=-f,
        maximum=f,
        requirement=f"a delay in us within +-{f:.0f} (one projector sweep)",
    )


def check_exposure(value: float | None, name: str = "exposure_us") -> float | None:
    """A row exposure: > 0 and at most one projector sweep (13,333 us); None passes."""
    from .._validate import check_number

    if value is None:
        return None
    f = PROJECTOR_FRAME_US
    return check_number(
        value,
        parameter_name(name),
        minimum=0.0,
        maximum=f,
        min_inclusive=False,
        requirement=f"an exposure in us, > 0 and <= {f:.0f} (one projector sweep)",
    )


def _truth_for(shape, source_path: Path, mask):
    """Ground truth for the metrics: ``mask``, else the truth ``planeray skin simulate`` wrote beside the source.

    Returns None (no metrics), or a dict with ``vein_id`` and, from a simulated capture,
    ``exclude`` (hair, off the skin), ``depth_mm``, ``diameter_mm`` and ``source``.
    """
    if mask is not None:
        from ..skin.masks import read_vein_mask

        try:
            return {"vein_id": read_vein_mask(mask, shape), "source": str(mask)}
        except InputError as exc:
            raise InputError(f"{parameter_name('mask')} {exc}") from None
    from .skin_capture import read_skin_truth, truth_paths

    if not truth_paths(source_path)["veins"].is_file():
        return None
    _, maps = read_skin_truth(source_path)
    exclude = maps.get("hair")
    if "skin" in maps:
        off = ~np.asarray(maps["skin"], bool)
        exclude = off if exclude is None else np.asarray(exclude, bool) | off
    if tuple(maps["vein_id"].shape) != tuple(shape):
        raise InputError(f"{truth_paths(source_path)['maps']}: ground truth of another image size than the images")
    return {
        "vein_id": maps["vein_id"],
        "exclude": exclude,
        "depth_mm": maps.get("vein_depth_mm"),
        "diameter_mm": maps.get("vein_diameter_mm"),
        "source": str(truth_paths(source_path)["maps"]),
    }


def _metrics(image, truth, mm_per_px):
    from ..skin.metrics import vein_metrics

    return vein_metrics(
        image,
        truth["vein_id"],
        mm_per_px=mm_per_px,
        exclude=truth.get("exclude"),
        depth_mm=truth.get("depth_mm"),
        diameter_mm=truth.get("diameter_mm"),
    )


def _scale(option: float | None, *records) -> tuple[float, str]:
    """``mm_per_row`` and where it came from: the option, a stack's or store's record, or the default."""
    from ..scenes.base import DEFAULT_MM_PER_ROW
    from ..stack import recorded_mm_per_row

    if option is not None:
        return check_mm_per_row(option), parameter_name("mm_per_row")
    for what, meta in records:
        value, source = recorded_mm_per_row(meta)
        if value is not None:
            return value, ("acquisition.json" if source == "acquisition.json" else what)
    return float(DEFAULT_MM_PER_ROW), (
        f"assumed (the simulator's default; set {parameter_name('mm_per_row')} for a real capture)"
    )


def _write_png(path: Path, image, valid=None) -> None:
    from PIL import Image

    from ..io import atomic_file
    from ..io.marks import png_mark_info

    img = np.asarray(image, np.float64)
    vals = img[valid] if valid is not None else img.ravel()
    vals = vals[np.isfinite(vals)]
    lo, hi = np.percentile(vals, [1, 99]) if vals.size else (0.0, 1.0)
    shown = np.clip((img - lo) / (hi - lo if hi > lo else 1.0), 0, 1)
    with atomic_file(path) as tmp:
        Image.fromarray((np.nan_to_num(shown) * 255 + 0.5).astype(np.uint8)).save(
            tmp, format="PNG", pnginfo=png_mark_info("image")
        )


def _write_tiff(path: Path, image, dtype=np.float32) -> None:
    import tifffile

    from ..io import atomic_file
    from ..io.marks import mark_text

    with atomic_file(path) as tmp:
        tifffile.imwrite(tmp, np.asarray(image, dtype), photometric="minisblack", software=mark_text("image"))


def _write_csv(path: Path, rows) -> None:
    import csv

    from ..io import atomic_file

    with atomic_file(path) as tmp, open(tmp, "w", newline="") as f:
        if rows:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)


def _summary(m) -> dict:
    return {k: m[k] for k in ("cnr", "weber", "n_veins", "n_detected")}


def source_kind(path, name: str) -> str:
    """``"stack"`` or ``"transport"``: what planeray store (or import folder) ``path`` is; one line otherwise."""
    from ..io import store_format

    path = Path(path)
    if not (path.exists() or path.is_symlink()):
        raise InputError(f"no such file or folder ({parameter_name(name)})", path)
    kind = store_format(path)
    if kind is None:
        raise InputError(
            f"not a planeray stack, import folder (manifest.csv + images) or transport store ({parameter_name(name)})",
            path,
        )
    return kind


def _ambient_title(metadata) -> str:
    """What the stack's metadata says of the ambient light ("" when it says nothing)."""
    camera = (metadata or {}).get("camera") if isinstance(metadata, dict) else None
    amb = camera.get("ambient_e_per_us") if isinstance(camera, dict) else None
    if not isinstance(amb, (int, float)) or isinstance(amb, bool):
        return ""
    return "; no ambient light" if amb == 0 else f"; ambient light {amb:g} e-/us (the stack's camera)"


def _read_transport_arg(path, name: str):
    from ..io import read_transport
    from ..io.atomic import planeray_output_kind

    if planeray_output_kind(path) != "transport":
        raise InputError(f"{parameter_name(name)} {path}: not a planeray transport store")
    return read_transport(path)


def _load_stack(path):
    from ..io import read_stack

    return read_stack(path)


def _vein_inputs(source, transport, mask, delay_us, exposure_us, mm_per_row, include_excluded) -> dict:
    """The vein images of ``source`` (a stack, with ``transport``'s epipolar image; or a transport store), their
    record, scale, ambient light and ground truth."""
    from ..skin.imaging import stack_images, transport_images
    from ..timing import PAPER_LINES_PER_SECOND

    source, opt = Path(source), parameter_name("transport")
    from_transport = source_kind(source, "source") == "transport"
    if from_transport and transport is not None:
        raise InputError(f"{opt}: {source} is already a transport store; give a stack with {opt}")
    if from_transport:
        T, attrs = _read_transport_arg(source, "source")
        lps = float(attrs.get("lines_per_second") or PAPER_LINES_PER_SECOND)
        mpr, mpr_source = _scale(mm_per_row, ("transport store", attrs))
        truth = _truth_for(tuple(T.dense.shape[:2]), source, mask)
        images, info = transport_images(
            T, delay_us=delay_us, exposure_us=exposure_us, lines_per_second=lps, mm_per_row=mpr
        )
        return {"images": images, "info": info, "geometry": T.geometry, "ambient": "", "truth": truth,
                "mpr": mpr, "mpr_source": mpr_source, "from_transport": True}  # fmt: skip
    stack = _load_stack(source)
    shape, attrs = tuple(stack.shape), None
    if transport is not None:
        T, attrs = _read_transport_arg(transport, "transport")
        if tuple(T.dense.shape[:2]) != shape:
            raise InputError(
                f"{opt} {transport}: images of {T.dense.shape[0]}x{T.dense.shape[1]}, "
                f"the stack's are {shape[0]}x{shape[1]}"
            )
    mpr, mpr_source = _scale(mm_per_row, ("stack metadata", stack.metadata), ("transport store", attrs))
    truth = _truth_for(shape, source, mask)
    images, info = stack_images(
        stack, delay_us=delay_us, exposure_us=exposure_us, include_excluded=include_excluded, mm_per_row=mpr
    )
    if transport is not None:
        epi, epi_info = transport_images(T, delay=False, mm_per_row=mpr)
        images.update(epi)
        info["images"].update(epi_info["images"])
        info["images"]["epipolar"]["source"] = f"transport {transport}"
    return {"images": images, "info": info, "geometry": stack.geometry, "ambient": _ambient_title(stack.metadata),
            "truth": truth, "mpr": mpr, "mpr_source": mpr_source, "from_transport": False}  # fmt: skip


@writes_output("out_dir")
def vein_images(
    source,
    out_dir,
    *,
    delay_us: float = 500.0,
    exposure_us: float | None = None,
    transport=None,
    mask=None,
    mm_per_row: float | None = None,
    include_excluded: bool = False,
    overwrite: bool = False,
) -> dict:
    """The short-range indirect vein image, the t_d = 0 band image and (from a transport) the epipolar image.

    Writes the folder of ``planeray skin veins``: each image as ``NAME.png`` (display-scaled) and
    ``NAME.tif`` (float32 values), named for its band (``td562.5us_te600us``, ``td0us_te600us``,
    ``epipolar``), ``veins_figure.png``, ``planeray.json`` and, with a vein mask (or the ground
    truth beside a simulated stack), ``veins.csv``: CNR per vein and image.

    Parameters
    ----------
    source : str or os.PathLike
        Stack (Zarr or import folder), or a transport store.
    out_dir : str or os.PathLike
        Folder to write.
    delay_us : float
        Delay of the vein image, us, within +-13,333 (one projector sweep); the stack's nearest is served.
    exposure_us : float, optional
        Exposure, us, in (0, 13,333]; default: the stack's shortest (600 from a transport).
    transport : str or os.PathLike, optional
        Transport store of the same scene (with a stack): adds the epipolar image.
    mask : str or os.PathLike, optional
        Vein mask (0 skin, nonzero vein; several values: vein ids) for the metrics; default: the ground
        truth ``planeray skin simulate`` wrote beside the stack, if any.
    mm_per_row : float, optional
        Size of a projector row on the skin, mm, in (0, 10]; default: the capture's record, else 0.3
        (assumed).
    include_excluded : bool
        Also use images the stack flags as excluded.
    overwrite : bool
        Replace an output folder planeray wrote.

    Returns
    -------
    dict
        The record written to ``planeray.json`` (before non-finite numbers become ``null``).
    """
    from ..figures.skin import headline_figure
    from ..skin.imaging import pixel_mm

    check_delay(delay_us)
    check_exposure(exposure_us)
    if mm_per_row is not None:
        check_mm_per_row(mm_per_row)
    out_dir = check_folder_output(
        out_dir,
        [(parameter_name("source"), source), (parameter_name("transport"), transport), (parameter_name("mask"), mask)],
        overwrite=overwrite,
        kind="skin veins",
    )
    got = _vein_inputs(source, transport, mask, delay_us, exposure_us, mm_per_row, include_excluded)
    images, info, truth = got["images"], got["info"], got["truth"]
    mm_px = pixel_mm(got["geometry"], got["mpr"])
    result = {
        "format": "planeray-skin-veins",
        "format_version": 2,
        "source": str(source),
        "source_kind": "transport" if got["from_transport"] else "stack",
        "transport": None if transport is None else str(transport),
        **info,
        "band_mm": info["images"][info["delay_image"]]["band_mm"],
        "mm_per_row": got["mpr"],
        "mm_per_row_source": got["mpr_source"],
        "mm_per_px": mm_px,
    }
    metrics = None
    if truth is not None:
        metrics = {k: _metrics(v, truth, mm_px) for k, v in images.items()}
        result["metric"] = next(iter(metrics.values()))["band"]
        result["metrics"] = {k: _summary(m) for k, m in metrics.items()}
        result["ground_truth"] = truth["source"]
    labels = {k: r["label"] for k, r in info["images"].items()}
    with atomic_directory(out_dir, overwrite=overwrite, kind="skin veins") as tmp:
        for k, img in images.items():
            _write_png(tmp / f"{k}.png", img)
            _write_tiff(tmp / f"{k}.tif", img)
        if metrics is not None:
            _write_csv(tmp / "veins.csv", [{"image": k, **r} for k, m in metrics.items() for r in m["veins"]])
        headline_figure(
            images, labels=labels, metrics=metrics, title=f"Veins: {Path(source).name}{got['ambient']}",
            out=tmp / "veins_figure.png",
        )  # fmt: skip
        (tmp / MARKER).write_text(json.dumps(jsonable(result), indent=1))
    return result


def _enhance_metrics(res, imgs, delays, t_e, truth, mm_px) -> dict:
    """CNR of the enhanced image, of each single delay image and of the best of them."""
    from ..skin.imaging import band_name

    single = {band_name(d, t_e): _metrics(im, truth, mm_px) for d, im in zip(delays, imgs)}
    best = max(single, key=lambda k: -np.inf if single[k]["cnr"] is None else single[k]["cnr"])
    em = _metrics(res.image, truth, mm_px)
    return {
        "ground_truth": truth["source"],
        "metric": em["band"],
        "metrics": {
            "enhanced": _summary(em),
            "best_single": {
                "image": best,
                "delay_us": float(delays[list(single).index(best)]),
                "exposure_us": t_e,
                **_summary(single[best]),
            },
            "single": {k: _summary(m) for k, m in single.items()},
        },
    }


@writes_output("out_dir")
def enhance_veins(
    stack,
    out_dir,
    *,
    exposure_us: float | None = None,
    min_delay_us: float = 0.0,
    patch_px: int | None = None,
    plain: bool = False,
    mask=None,
    mm_per_row: float | None = None,
    include_excluded: bool = False,
    overwrite: bool = False,
    progress=None,
) -> dict:
    """Contrast enhancement from a stack's delay images (Eq. 7, Fig. 14), never from images the stack excludes.

    Writes the folder of ``planeray skin enhance``: ``enhanced.png`` / ``enhanced.tif``, the delay
    map ``delay_map_us.tif`` (us) and its figure ``delay_map.png``, and ``planeray.json`` (with a
    vein mask or the ground truth: CNR of the enhanced image against the best single delay image).

    Parameters
    ----------
    stack : str or os.PathLike
        Stack (Zarr or import folder).
    out_dir : str or os.PathLike
        Folder to write.
    exposure_us : float, optional
        Exposure of the delay images, us (default: the stack's shortest).
    min_delay_us : float
        Use only delays above this, us.
    patch_px : int, optional
        Patch size, 2 up to the image's smaller side (default 200 px per 720 rows).
    plain : bool
        The paper's plain gradient argmax (no noise weighting).
    mask, mm_per_row, include_excluded, overwrite
        As in :func:`vein_images`.
    progress : callable, optional
        ``progress(stage, done, total)``.

    Returns
    -------
    dict
        The record written to ``planeray.json``.
    """
    from .._validate import check_integer
    from ..figures.skin import delay_map_figure
    from ..skin.enhance import enhance_contrast, enhance_steps
    from ..skin.imaging import band_name, delay_sweep_images, delay_sweep_selection, pixel_mm

    stages = Stages(progress)
    check_exposure(exposure_us)
    check_delay(min_delay_us, "min_delay_us")
    if mm_per_row is not None:
        check_mm_per_row(mm_per_row)
    opt = parameter_name("stack")
    out_dir = check_folder_output(
        out_dir, [(opt, stack), (parameter_name("mask"), mask)], overwrite=overwrite, kind="skin enhance"
    )
    source_kind(stack, "stack")
    st = _load_stack(stack)
    if patch_px is not None:  # bounded by the image: a patch larger than the image is the image
        check_integer(patch_px, parameter_name("patch_px"), minimum=2, maximum=min(st.shape))
    truth = _truth_for(st.shape, Path(stack), mask)
    mpr, mpr_source = _scale(mm_per_row, ("stack metadata", st.metadata))
    selection = dict(exposure_us=exposure_us, min_delay_us=min_delay_us, include_excluded=include_excluded)
    chosen, _, _ = delay_sweep_selection(st, **selection)  # refuses fewer than 2 images before reading any
    advance = stages.stage("reading the delay images", len(chosen))
    imgs, delays, sel = delay_sweep_images(st, **selection, progress=advance)
    t_e = sel["exposure_us"]
    advance = stages.stage(f"enhancing ({len(delays)} delay images)", enhance_steps(len(delays)))
    res = enhance_contrast(imgs, delays, patch_px=patch_px, noise_normalize=not plain, progress=advance)
    result = {
        "format": "planeray-skin-enhance",
        "format_version": 2,
        "stack": str(stack),
        "exposure_us": t_e,
        "delays_us": [float(d) for d in delays],
        "images": [band_name(d, t_e) for d in delays],
        "excluded_delays_us": sel["excluded_delays_us"],
        "include_excluded": sel["include_excluded"],
        "mm_per_row": mpr,
        "mm_per_row_source": mpr_source,
        "params": res.params,
    }
    if truth is not None:
        result.update(_enhance_metrics(res, imgs, delays, t_e, truth, pixel_mm(st.geometry, mpr)))
    with atomic_directory(out_dir, overwrite=overwrite, kind="skin enhance") as tmp:
        _write_png(tmp / "enhanced.png", res.image)
        _write_tiff(tmp / "enhanced.tif", res.image)
        _write_tiff(tmp / "delay_map_us.tif", res.delay_map_us)
        delay_map_figure(
            res.delay_map_us,
            vein_id=None if truth is None else truth["vein_id"],
            used_us=res.delays_us,
            title=f"Eq. 7 delay map: {Path(stack).name}, t_e {t_e:g} us" + ("" if truth is None else " (white: true veins)"),
            out=tmp / "delay_map.png",
        )  # fmt: skip
        (tmp / MARKER).write_text(json.dumps(jsonable(result), indent=1))
    return result
