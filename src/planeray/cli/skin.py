"""``planeray skin``: seeing veins through skin (Sec. 10, Figs. 13, 14, 16).

``simulate`` (a capture of the skin scene with its ground truth beside it), ``validate`` (the
fast vein model against brute-force Monte Carlo, the layers against adding-doubling), ``veins``
(the short-range indirect delay image of a stack or transport store, its t_d = 0 band image and
the epipolar image where a transport is given, each named for its band, and their metrics on a
vein mask), ``depth`` (each vein's depth and diameter from the delay sweep), ``enhance``
(Eq. 7's contrast enhancement over a stack's delay images), ``compare`` (the whole study on the
simulated skin scene: methods, ambient light, best delay against depth, Eq. 7).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from .._console import console, out, progress_bar
from . import _bounds
from ._common import StackArg, _check_outputs, _friendly_errors, _load_stack, _not_a_home

skin_app = typer.Typer(
    help="Skin and veins (Sec. 10): simulate captures, check the physics, vein images and metrics, Eq. 7.",
    no_args_is_help=True,
)


#: Ambient light an option may ask for, electrons per us (full sunlight is ~11 at 638 nm; README, ambient light).
MAX_AMBIENT_E_PER_US = 1000.0
#: Size of a projector row on the skin an option may ask for, mm (the paper's PicoPro: 0.3 mm at 0.5 m).
MAX_MM_PER_ROW = 10.0
#: The wavelengths the skin optics are tabulated at, nm.
WAVELENGTHS_NM = (638, 850)


def _tone(text: str):
    """``--tone``: a tone name or a melanosome fraction in [0, 0.5]."""
    from ..optical_data_skin import SKIN_TONES

    try:
        value = float(text)
    except ValueError:
        if text not in SKIN_TONES:
            raise ValueError(
                f"--tone must be one of {', '.join(SKIN_TONES)} or a melanosome fraction in [0, 0.5], got {text!r}"
            ) from None
        return text
    if not 0.0 <= value <= 0.5:
        raise ValueError(f"--tone must be a melanosome fraction in [0, 0.5] (or a tone name), got {text!r}")
    return value


def _wavelength(value: int) -> int:
    if value not in WAVELENGTHS_NM:
        raise ValueError(f"--wavelength must be 638 (red) or 850 (nm), got {value}")
    return value


def _mm_per_row_option(value: float) -> float:
    from .._validate import check_number

    return check_number(
        value,
        "--mm-per-row",
        minimum=0.0,
        maximum=MAX_MM_PER_ROW,
        min_inclusive=False,
        requirement=f"a size in mm, > 0 and <= {MAX_MM_PER_ROW:g}",
    )


@skin_app.command("simulate")
@_friendly_errors
def simulate(
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Stack to write (Zarr directory); truth beside it.")],
    tone: Annotated[
        str,
        typer.Option(help="Skin tone: very_fair, fair, medium, olive, brown, dark or a melanosome fraction 0-0.5."),
    ] = "fair",
    wavelength: Annotated[int, typer.Option("--wavelength", "--wavelength-nm", help="638 (red) or 850 (nm).")] = 638,
    ambient_e_per_us: Annotated[
        float,
        typer.Option(
            "--ambient-e-per-us",
            "--ambient",
            help="Ambient light, electrons per us of exposure (albedo 1); 0-1000 (office light ~0.05, "
            "full sunlight ~11).",
        ),
    ] = 0.5,
    hair: Annotated[bool, typer.Option(help="Hair strands on the skin.")] = False,
    curved: Annotated[
        bool, typer.Option(help="A cylindrical forearm on a dark cloth instead of a flat patch.")
    ] = False,
    size: Annotated[
        tuple[int, int], typer.Option(help="Image size H W (camera pixels; at least 8, at most what memory holds).")
    ] = (128, 128),
    projector_rows: Annotated[
        int, typer.Option(help="Projector rows spanned by the image (1-720: the projector has 720).")
    ] = 720,
    mm_per_row: Annotated[
        float,
        typer.Option(help="Size of a projector row on the skin (mm, > 0 and <= 10; other than 0.3 traces tables)."),
    ] = 0.3,
    seed: Annotated[int, typer.Option(help="Seed of the veins, hair, textures and camera noise (0 to 2^32-1).")] = 0,
    sweep: Annotated[str, typer.Option(help="Named delay-exposure sweep: paper (85 images) or quick.")] = "paper",
    noise: Annotated[bool, typer.Option(help="Simulate noise (--no-noise: expected images).")] = True,
    overwrite: Annotated[bool, typer.Option(help="Replace existing outputs (only ones planeray wrote).")] = False,
):
    """Simulate a delay-exposure sweep of the skin scene; writes STACK and STEM_vein_mask.png, STEM_veins.json, STEM_maps.npz."""
    from .._validate import check_number
    from ..camera import CameraModel
    from ..experiments.skin_capture import TRUTH_KIND, simulate_skin, truth_paths
    from ..timing import SWEEPS, make_sweep

    # every option and output, before any work
    tone_value = _tone(tone)
    _wavelength(wavelength)
    check_number(ambient_e_per_us, "--ambient-e-per-us", minimum=0.0, maximum=MAX_AMBIENT_E_PER_US)
    shape = _bounds.image_size(size)
    _bounds.projector_rows(projector_rows)
    _mm_per_row_option(mm_per_row)
    _bounds.seed(seed)
    if sweep not in SWEEPS:
        raise ValueError(f"--sweep must be one of {', '.join(sorted(SWEEPS))}, got {sweep!r}")
    n = len(make_sweep(sweep))
    _bounds.scene_memory(shape, extra_bytes=3 * n * shape[0] * shape[1] * 4)
    _not_a_home(out_path)  # before its name makes the ground truth's file names
    truth = truth_paths(out_path)
    _check_outputs(
        (out_path, "stack"),
        (truth["mask"], TRUTH_KIND),
        (truth["veins"], TRUTH_KIND),
        (truth["maps"], TRUTH_KIND),
        overwrite=overwrite,
    )
    with progress_bar() as bar:
        task = bar.add_task(f"skin {size[0]}x{size[1]}: capturing {n} images", total=n)
        cap = simulate_skin(
            out_path,
            size=shape,
            projector_rows=projector_rows,
            seed=seed,
            sweep=sweep,
            camera=CameraModel(ambient_e_per_us=ambient_e_per_us),
            noise=noise,
            overwrite=overwrite,
            progress=lambda i: bar.advance(task),
            tone=tone_value,
            wavelength_nm=wavelength,
            hair=hair,
            curved=curved,
            mm_per_row=mm_per_row,
        )
    for v in cap.scene.params["veins"]:
        console.print(
            f"vein {v['id']}: top {v['depth_mm']:.2f} mm deep, {v['diameter_mm']:.2f} mm wide"
            + (f", branch of {v['parent']}" if v["parent"] else "")
        )
    for key in ("stack", "mask", "veins", "maps"):
        out.print(f"{key}: {cap.paths[key]}")


#: Photons per brute-force run an option may ask for (the default 200,000 takes ~6.5 min on 2 cores).
MAX_PHOTONS = 10_000_000


@skin_app.command("validate")
@_friendly_errors
def validate(
    out_dir: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            help="Folder to write (skin_validation.json and .png): a new one, or one planeray wrote with --overwrite.",
        ),
    ],
    n_photons: Annotated[
        int,
        typer.Option(
            help="Photons per brute-force run (32 to 10,000,000; the default takes ~6.5 min on 2 cores, time grows "
            "in proportion)."
        ),
    ] = 200_000,
    wavelength: Annotated[int, typer.Option("--wavelength", "--wavelength-nm", help="638 (red) or 850 (nm).")] = 638,
    overwrite: Annotated[bool, typer.Option(help="Replace a validation folder planeray wrote.")] = False,
):
    """Check the fast vein model against brute-force Monte Carlo and the layers against adding-doubling."""
    from .._validate import check_integer
    from ..experiments.skin_physics import DARK_CASES, VALIDATION_CASES, run_skin_validation

    check_integer(n_photons, "--n-photons", minimum=32, maximum=MAX_PHOTONS)
    _wavelength(wavelength)
    _check_outputs((out_dir, "skin validation"), overwrite=overwrite)  # before ~6.5 minutes of Monte Carlo
    with progress_bar() as bar:
        task = bar.add_task("brute-force Monte Carlo", total=len(VALIDATION_CASES) + len(DARK_CASES) + 1)
        rep = run_skin_validation(
            out_dir,
            n_photons=n_photons,
            wavelength_nm=wavelength,
            overwrite=overwrite,
            progress=lambda k: bar.advance(task, k),
        )

    def contrast(x):  # NaN: no traced background light reached the band
        return f"{x:.3f}" if math.isfinite(x) else "none (no traced light in the band: more --n-photons)"

    for r in rep["cases"]:
        out.print(
            f"{r['angle_deg']:>4.0f} deg top {r['depth_mm']:g} mm D {r['diameter_mm']:g} mm rho {r['rho_rows']:+.0f}: "
            f"short-range contrast {contrast(r['short_brute'])} (brute) {contrast(r['short_fast'])} (fast)"
        )
    for r in rep["dark_skin_cases"]:
        out.print(
            f"dark skin, {r['angle_deg']:.0f} deg top {r['depth_mm']:g} mm: short-range contrast "
            f"{contrast(r['short_brute'])} (brute) {contrast(r['short_fast'])} (fast)"
        )
    ad = rep["adding_doubling"]
    out.print(
        f"diffuse reflectance: Monte Carlo {ad['mc']:.4f} +- {ad['mc_stderr']:.4f}, adding-doubling {ad['ad']:.4f}"
    )
    out.print(f"written: {out_dir / 'skin_validation.json'}, {out_dir / 'skin_validation.png'}")


MaskOpt = Annotated[
    Path | None,
    typer.Option(
        "--mask",
        help="Vein mask (PNG/TIFF, image size; 0 skin, nonzero vein; several values = vein ids) for the metrics "
        "(default: the ground truth `planeray skin simulate` wrote beside the stack, if any).",
    ),
]


def _truth_for(shape, source_path: Path, mask: Path | None):
    """Ground truth for the metrics: ``--mask``, else the truth ``planeray skin simulate`` wrote beside the source.

    Returns None (no metrics), or a dict with ``vein_id`` and, from a simulated capture,
    ``exclude`` (hair, off the skin), ``depth_mm``, ``diameter_mm`` and ``source``.
    """
    if mask is not None:
        from ..errors import InputError
        from ..skin.masks import read_vein_mask

        try:
            return {"vein_id": read_vein_mask(mask, shape), "source": str(mask)}
        except InputError as exc:
            raise InputError(f"--mask {exc}") from None
    from ..experiments.skin_capture import read_skin_truth, truth_paths

    if not truth_paths(source_path)["veins"].is_file():
        return None
    _, maps = read_skin_truth(source_path)
    exclude = maps.get("hair")
    if "skin" in maps:
        off = ~np.asarray(maps["skin"], bool)
        exclude = off if exclude is None else np.asarray(exclude, bool) | off
    if tuple(maps["vein_id"].shape) != tuple(shape):
        raise ValueError(f"{truth_paths(source_path)['maps']}: ground truth of another image size than the images")
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
    """``mm_per_row`` and where it came from: ``--mm-per-row``, a stack's or store's record, or the default."""
    from ..scenes.base import DEFAULT_MM_PER_ROW
    from ..stack import recorded_mm_per_row

    if option is not None:
        return _mm_per_row_option(option), "--mm-per-row"
    for what, meta in records:
        value, source = recorded_mm_per_row(meta)
        if value is not None:
            return value, ("acquisition.json" if source == "acquisition.json" else what)
    return float(DEFAULT_MM_PER_ROW), "assumed (the simulator's default; set --mm-per-row for a real capture)"


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


def _metrics_rows(name, m):
    return [{"image": name, **r} for r in m["veins"]]


def _write_csv(path: Path, rows) -> None:
    import csv

    from ..io import atomic_file

    with atomic_file(path) as tmp, open(tmp, "w", newline="") as f:
        if rows:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)


def _num(x) -> str:
    return "n/a" if x is None else f"{x:.2f}"


def _summary(m) -> dict:
    return {k: m[k] for k in ("cnr", "weber", "n_veins", "n_detected")}


MmPerRowOpt = Annotated[
    float | None,
    typer.Option(
        "--mm-per-row",
        help="Size of a projector row on the skin (mm, > 0 and <= 10), for the metrics' band in mm; default: what "
        "the stack or store records, else 0.3 (assumed).",
    ),
]
IncludeExcludedOpt = Annotated[
    bool,
    typer.Option(
        "--include-excluded",
        help="Also use images the stack flags as excluded (boundary images with row artefacts); off by default.",
    ),
]


def _delay_option(value: float, option: str = "--delay-us") -> float:
    """A delay on the projector: finite, within one projector sweep (+-13,333 us) of the epipolar plane."""
    from .._validate import check_number

    f = _bounds.PROJECTOR_FRAME_US
    return check_number(
        value, option, minimum=-f, maximum=f, requirement=f"a delay in us within +-{f:.0f} (one projector sweep)"
    )


def _exposure_option(value: float | None, option: str = "--exposure-us") -> float | None:
    """A row exposure: > 0 and at most one projector sweep (13,333 us)."""
    from .._validate import check_number

    if value is None:
        return None
    f = _bounds.PROJECTOR_FRAME_US
    return check_number(
        value,
        option,
        minimum=0.0,
        maximum=f,
        min_inclusive=False,
        requirement=f"an exposure in us, > 0 and <= {f:.0f} (one projector sweep)",
    )


def _source_kind(path: Path, name: str) -> str:
    """``"stack"`` or ``"transport"``: what planeray store (or import folder) ``path`` is; one line otherwise."""
    from ..errors import InputError
    from ..io import store_format

    if not (path.exists() or path.is_symlink()):
        raise InputError(f"no such file or folder ({name})", path)
    kind = store_format(path)
    if kind is None:
        raise InputError(
            f"not a planeray stack, import folder (manifest.csv + images) or transport store ({name})", path
        )
    return kind


def _ambient_title(metadata) -> str:
    """What the stack's metadata says of the ambient light ("" when it says nothing)."""
    camera = (metadata or {}).get("camera") if isinstance(metadata, dict) else None
    amb = camera.get("ambient_e_per_us") if isinstance(camera, dict) else None
    if not isinstance(amb, (int, float)) or isinstance(amb, bool):
        return ""
    return "; no ambient light" if amb == 0 else f"; ambient light {amb:g} e-/us (the stack's camera)"


def _read_transport_arg(path: Path, option: str):
    from ..io import read_transport
    from ..io.atomic import planeray_output_kind

    if planeray_output_kind(path) != "transport":
        raise ValueError(f"{option} {path}: not a planeray transport store")
    return read_transport(path)


@skin_app.command("veins")
@_friendly_errors
def veins(
    source: Annotated[
        Path, typer.Argument(help="Stack (Zarr or import folder), or a transport store (Zarr, e.g. from demux).")
    ],
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder to write (images, metrics, figure).")],
    delay_us: Annotated[
        float,
        typer.Option(
            "--delay-us", "--delay", help="Delay of the vein image (us, within +-13,333: one projector sweep)."
        ),
    ] = 500.0,
    exposure_us: Annotated[
        float | None,
        typer.Option(
            "--exposure-us",
            "--exposure",
            help="Exposure (us, > 0 and <= 13,333); default the stack's shortest (600 from a transport).",
        ),
    ] = None,
    transport_path: Annotated[
        Path | None,
        typer.Option(
            "--transport",
            help="Transport store of the same scene (e.g. `planeray demux` of the stack): adds the epipolar image.",
        ),
    ] = None,
    mask: MaskOpt = None,
    mm_per_row: MmPerRowOpt = None,
    include_excluded: IncludeExcludedOpt = False,
    overwrite: Annotated[bool, typer.Option(help="Replace an output folder planeray wrote.")] = False,
):
    """The short-range indirect vein image, the t_d = 0 band image and (from a transport) the epipolar image.

    Every image is named for its band (``td562.5us_te600us``, ``td0us_te600us``, ``epipolar``);
    with a vein mask (or the ground truth beside a simulated stack), CNR per vein.
    """
    from ..figures.skin import headline_figure
    from ..io import atomic_directory, jsonable
    from ..io.atomic import MARKER
    from ..skin.imaging import pixel_mm, stack_images, transport_images
    from ..timing import PAPER_LINES_PER_SECOND

    _delay_option(delay_us)
    _exposure_option(exposure_us)
    if mm_per_row is not None:
        _mm_per_row_option(mm_per_row)
    _check_outputs(
        (out_dir, "skin veins"),
        overwrite=overwrite,
        inputs=[("SOURCE", source), ("--transport", transport_path), ("--mask", mask)],
    )
    from_transport = _source_kind(source, "SOURCE") == "transport"
    if from_transport and transport_path is not None:
        raise ValueError(f"--transport: {source} is already a transport store; give a stack with --transport")
    if from_transport:
        T, attrs = _read_transport_arg(source, "SOURCE")
        ambient = ""  # a transport has no ambient light
        lps = float(attrs.get("lines_per_second") or PAPER_LINES_PER_SECOND)
        mpr, mpr_source = _scale(mm_per_row, ("transport store", attrs))
        geometry, shape = T.geometry, tuple(T.dense.shape[:2])
        truth = _truth_for(shape, source, mask)
        images, info = transport_images(
            T, delay_us=delay_us, exposure_us=exposure_us, lines_per_second=lps, mm_per_row=mpr
        )
    else:
        stack = _load_stack(source)
        geometry, shape = stack.geometry, tuple(stack.shape)
        ambient = _ambient_title(stack.metadata)
        attrs = None
        if transport_path is not None:
            T, attrs = _read_transport_arg(transport_path, "--transport")
            if tuple(T.dense.shape[:2]) != shape:
                raise ValueError(
                    f"--transport {transport_path}: images of {T.dense.shape[0]}x{T.dense.shape[1]}, "
                    f"the stack's are {shape[0]}x{shape[1]}"
                )
        mpr, mpr_source = _scale(mm_per_row, ("stack metadata", stack.metadata), ("transport store", attrs))
        truth = _truth_for(shape, source, mask)
        images, info = stack_images(
            stack, delay_us=delay_us, exposure_us=exposure_us, include_excluded=include_excluded, mm_per_row=mpr
        )
        if transport_path is not None:
            epi, epi_info = transport_images(T, delay=False, mm_per_row=mpr)
            images.update(epi)
            info["images"].update(epi_info["images"])
            info["images"]["epipolar"]["source"] = f"transport {transport_path}"
    mm_px = pixel_mm(geometry, mpr)
    served = info["images"][info["delay_image"]]
    result = {
        "format": "planeray-skin-veins",
        "format_version": 2,
        "source": str(source),
        "source_kind": "transport" if from_transport else "stack",
        "transport": None if transport_path is None else str(transport_path),
        **info,
        "band_mm": served["band_mm"],
        "mm_per_row": mpr,
        "mm_per_row_source": mpr_source,
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
            _write_csv(tmp / "veins.csv", [r for k, m in metrics.items() for r in _metrics_rows(k, m)])
        headline_figure(
            images,
            labels=labels,
            metrics=metrics,
            title=f"Veins: {source.name}{ambient}",
            out=tmp / "veins_figure.png",
        )
        (tmp / MARKER).write_text(json.dumps(jsonable(result), indent=1))
    asked = f"{delay_us:g} us" + ("" if exposure_us is None else f", {exposure_us:g} us")
    out.print(
        f"{out_dir}: {info['delay_image']} (asked {asked}; served t_d {info['delay_us']:g} us, "
        f"t_e {info['exposure_us']:g} us)"
    )
    for k in images:
        line = f"  {k}: {labels[k]}"
        if metrics is not None:
            m = metrics[k]
            line += f"; CNR {_num(m['cnr'])}, {m['n_detected']}/{m['n_veins']} veins detected (per-vein CNR >= 1)"
        out.print(line)


@skin_app.command("enhance")
@_friendly_errors
def enhance(
    stack_path: StackArg,
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder to write (enhanced image, delay map).")],
    exposure_us: Annotated[
        float | None,
        typer.Option("--exposure-us", "--exposure", help="Exposure of the delay images (us, > 0 and <= 13,333)."),
    ] = None,
    min_delay_us: Annotated[
        float, typer.Option("--min-delay-us", help="Use only delays above this (us, within +-13,333).")
    ] = 0.0,
    patch_px: Annotated[
        int | None,
        typer.Option("--patch-px", help="Patch size (2 up to the image's smaller side; default 200 px per 720 rows)."),
    ] = None,
    plain: Annotated[
        bool, typer.Option("--plain", help="The paper's plain gradient argmax (no noise weighting).")
    ] = False,
    mask: MaskOpt = None,
    mm_per_row: MmPerRowOpt = None,
    include_excluded: IncludeExcludedOpt = False,
    overwrite: Annotated[bool, typer.Option(help="Replace an output folder planeray wrote.")] = False,
):
    """Contrast enhancement from the stack's delay images (Eq. 7, Fig. 14), never from images the stack excludes."""
    from .._validate import check_integer
    from ..figures.skin import delay_map_figure
    from ..io import atomic_directory, jsonable
    from ..io.atomic import MARKER
    from ..skin.enhance import enhance_contrast, enhance_steps
    from ..skin.imaging import band_name, delay_sweep_images, delay_sweep_selection, pixel_mm

    _exposure_option(exposure_us)
    _delay_option(min_delay_us, "--min-delay-us")
    if mm_per_row is not None:
        _mm_per_row_option(mm_per_row)
    _check_outputs((out_dir, "skin enhance"), overwrite=overwrite, inputs=[("STACK", stack_path), ("--mask", mask)])
    _source_kind(stack_path, "STACK")
    stack = _load_stack(stack_path)
    if patch_px is not None:  # bounded by the image: a patch larger than the image is the image
        check_integer(patch_px, "--patch-px", minimum=2, maximum=min(stack.shape))
    truth = _truth_for(stack.shape, stack_path, mask)
    mpr, mpr_source = _scale(mm_per_row, ("stack metadata", stack.metadata))
    chosen, _, _ = delay_sweep_selection(  # refuses a selection of fewer than 2 images before reading any
        stack, exposure_us=exposure_us, min_delay_us=min_delay_us, include_excluded=include_excluded
    )
    with progress_bar() as bar:
        task = bar.add_task("reading the delay images", total=len(chosen))
        imgs, delays, sel = delay_sweep_images(
            stack,
            exposure_us=exposure_us,
            min_delay_us=min_delay_us,
            include_excluded=include_excluded,
            progress=lambda k: bar.advance(task, k),
        )
        t_e = sel["exposure_us"]
        task = bar.add_task(f"enhancing ({len(delays)} delay images)", total=enhance_steps(len(delays)))
        res = enhance_contrast(
            imgs, delays, patch_px=patch_px, noise_normalize=not plain, progress=lambda k: bar.advance(task, k)
        )
    result = {
        "format": "planeray-skin-enhance",
        "format_version": 2,
        "stack": str(stack_path),
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
        mm_px = pixel_mm(stack.geometry, mpr)
        single = {band_name(d, t_e): _metrics(im, truth, mm_px) for d, im in zip(delays, imgs)}
        best = max(single, key=lambda k: -np.inf if single[k]["cnr"] is None else single[k]["cnr"])
        em = _metrics(res.image, truth, mm_px)
        result["ground_truth"] = truth["source"]
        result["metric"] = em["band"]
        result["metrics"] = {
            "enhanced": _summary(em),
            "best_single": {
                "image": best,
                "delay_us": float(delays[list(single).index(best)]),
                "exposure_us": t_e,
                **_summary(single[best]),
            },
            "single": {k: _summary(m) for k, m in single.items()},
        }
    with atomic_directory(out_dir, overwrite=overwrite, kind="skin enhance") as tmp:
        _write_png(tmp / "enhanced.png", res.image)
        _write_tiff(tmp / "enhanced.tif", res.image)
        _write_tiff(tmp / "delay_map_us.tif", res.delay_map_us)
        delay_map_figure(
            res.delay_map_us,
            vein_id=None if truth is None else truth["vein_id"],
            used_us=res.delays_us,
            title=f"Eq. 7 delay map: {stack_path.name}, t_e {t_e:g} us"
            + ("" if truth is None else " (white: true veins)"),
            out=tmp / "delay_map.png",
        )
        (tmp / MARKER).write_text(json.dumps(jsonable(result), indent=1))
    left = sel["excluded_delays_us"]
    out.print(
        f"{out_dir}: enhanced from {len(delays)} delay images ({delays[0]:g}-{delays[-1]:g} us, t_e {t_e:g} us)"
        + (f"; left out the stack's excluded {', '.join(f'{d:g}' for d in left)} us" if left else "")
    )
    if truth is not None:
        e, b = result["metrics"]["enhanced"], result["metrics"]["best_single"]
        out.print(
            f"  enhanced: CNR {_num(e['cnr'])}, {e['n_detected']}/{e['n_veins']} veins; best single delay "
            f"({b['delay_us']:g} us): CNR {_num(b['cnr'])}, {b['n_detected']}/{b['n_veins']} veins"
        )


def _recorded(option, option_name: str, metadata, key: str, parse):
    """An option's value and where it came from: as given, else the stack's scene record; one line if neither."""
    if option is not None:
        return parse(option), option_name
    scene = metadata.get("scene") if isinstance(metadata, dict) else None
    value = scene.get(key) if isinstance(scene, dict) else None
    if value is None or isinstance(value, bool):
        raise ValueError(f"{option_name}: the stack records no {key}; give {option_name}")
    try:
        return parse(value), "stack metadata"
    except (TypeError, ValueError) as exc:
        raise ValueError(f"the stack's recorded {key} {value!r} is not usable ({exc}); give {option_name}") from None


def _stack_camera(metadata):
    """The camera noise model the stack records, else the default one (and which)."""
    from ..camera import CameraModel

    cam = metadata.get("camera") if isinstance(metadata, dict) else None
    if isinstance(cam, dict):
        try:
            return CameraModel(**cam), "stack metadata"
        except (TypeError, ValueError):
            pass
    return CameraModel(), "assumed (planeray's default camera; the stack records none)"


def _truth_depths(stack_path: Path, vein_id) -> dict:
    """``{fitted vein id: (true top depth, true diameter) mm}`` from the ground truth beside a simulated
    stack (each fitted vein matched to the true vein it overlaps most); ``{}`` without truth."""
    from ..experiments.skin_capture import read_skin_truth, truth_paths

    if not truth_paths(stack_path)["veins"].is_file():
        return {}
    meta, maps = read_skin_truth(stack_path)
    true_id = np.asarray(maps.get("vein_id", np.zeros(0)))
    if true_id.shape != np.shape(vein_id):
        return {}
    spec = {int(v["id"]): (float(v["depth_mm"]), float(v["diameter_mm"])) for v in meta.get("veins", [])}
    out = {}
    for vid in np.unique(vein_id[vein_id > 0]):
        hits = true_id[(vein_id == vid) & (true_id > 0)]
        if hits.size:
            best = int(np.bincount(hits).argmax())
            if best in spec:
                out[int(vid)] = spec[best]
    return out


#: Rounds of refitting each vein with its neighbours' shadows (skin.depth.fit_veins).
JOINT_ROUNDS = 1


@skin_app.command("depth")
@_friendly_errors
def depth(
    stack_path: StackArg,
    out_dir: Annotated[
        Path, typer.Option("--out", "-o", help="Folder to write (per-vein JSON and CSV, images, figure).")
    ],
    mask: Annotated[
        Path | None,
        typer.Option(
            "--mask",
            help="Vein mask (PNG/TIFF, image size; 0 skin, nonzero vein; several values = vein ids, else one vein per "
            "connected region); default: the ground truth `planeray skin simulate` wrote beside the stack.",
        ),
    ] = None,
    tone: Annotated[
        str | None,
        typer.Option(
            help="Skin tone (very_fair ... dark or a melanosome fraction 0-0.5); default: the stack's record."
        ),
    ] = None,
    wavelength: Annotated[
        int | None,
        typer.Option("--wavelength", "--wavelength-nm", help="638 or 850 (nm); default: the stack's record."),
    ] = None,
    mm_per_row: Annotated[
        float | None,
        typer.Option(
            "--mm-per-row",
            help="Size of a projector row on the skin (mm, > 0 and <= 10; other than 0.3 traces the vein tables); "
            "default: the stack's record (an import folder's acquisition.json: mm_per_row); neither: refused.",
        ),
    ] = None,
    epidermis_mm: Annotated[
        float | None, typer.Option(help="Epidermis thickness, mm (default: the stack's record, else 0.1).")
    ] = None,
    dermis_mm: Annotated[
        float | None, typer.Option(help="Dermis thickness, mm (default: the stack's record, else 1.5).")
    ] = None,
    fat_mm: Annotated[
        float | None, typer.Option(help="Subcutaneous fat thickness, mm (default: the stack's record, else 8).")
    ] = None,
    n: Annotated[
        float | None,
        typer.Option(
            "--n", help="Refractive index of the skin's layers (1 for an index-matched surface; default 1.4)."
        ),
    ] = None,
    g: Annotated[
        float | None, typer.Option("--g", help="Henyey-Greenstein anisotropy of the layers and blood (default 0.9).")
    ] = None,
    layer_optics: Annotated[
        list[str] | None,
        typer.Option(
            "--layer-optics",
            help="A layer's own optics instead of the published ones: LAYER=MU_S_PRIME,MU_A in 1/mm "
            "(epidermis, dermis or fat; repeatable).",
        ),
    ] = None,
    blood_saturation: Annotated[
        float | None, typer.Option(help="Oxygen saturation of the veins' blood, 0-1 (default 0.7).")
    ] = None,
    blood_mu_a: Annotated[float | None, typer.Option(help="The blood's absorption, 1/mm (default: published).")] = None,
    blood_mu_s: Annotated[float | None, typer.Option(help="The blood's scattering, 1/mm (default: published).")] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an output folder planeray wrote.")] = False,
):
    """Depth (of the vessel's top and axis) and diameter of each vein, with standard errors, from the delay sweep.

    Veins the delay images cannot resolve are reported with the reason, never with a number.  Every fit says
    whether the skin model fits the images (chi-square of the vein's contrast and of the images' backgrounds
    against the camera's noise model and the model's own error): a fit that does not, or a parameter at the
    tables' edge, is flagged on the console, in planeray.json and in the flag layer flags.tif.
    """
    from ..errors import InputError
    from ..figures.skin import depth_fit_figure
    from ..io import atomic_directory, jsonable
    from ..io.atomic import MARKER
    from ..skin.depth import fit_veins
    from ..skin.model import parse_layer_optics, stated_skin_model, tables_to_trace, trace_seconds

    if tone is not None:
        _tone(tone)
    if wavelength is not None:
        _wavelength(wavelength)
    if mm_per_row is not None:
        _mm_per_row_option(mm_per_row)
    for option, value, (lo, hi), closed in (
        ("--epidermis-mm", epidermis_mm, (0.0, 10.0), False), ("--dermis-mm", dermis_mm, (0.0, 20.0), False),
        ("--fat-mm", fat_mm, (0.0, 100.0), False), ("--n", n, (1.0, 2.0), True), ("--g", g, (-1.0, 1.0), False),
        ("--blood-saturation", blood_saturation, (0.0, 1.0), True), ("--blood-mu-a", blood_mu_a, (0.0, 100.0), False),
        ("--blood-mu-s", blood_mu_s, (0.0, 1000.0), False),
    ):  # fmt: skip
        if value is None:
            continue
        inside = math.isfinite(value) and (lo <= value if closed else lo < value) and value <= hi
        if not inside or (option == "--g" and value >= hi):
            raise ValueError(f"{option} must be in {'[' if closed else '('}{lo:g}, {hi:g}], got {value:g}")
    try:
        optics = parse_layer_optics(layer_optics)
    except InputError as exc:
        raise ValueError(f"--layer-optics: {exc}") from None
    _check_outputs((out_dir, "skin depth"), overwrite=overwrite, inputs=[("STACK", stack_path), ("--mask", mask)])
    if _source_kind(stack_path, "STACK") != "stack":
        raise InputError("a transport store has no delay sweep: give the stack (STACK)", stack_path)
    stack = _load_stack(stack_path)
    tone_value, tone_source = _recorded(tone, "--tone", stack.metadata, "tone", lambda v: _tone(str(v)))
    wl, wl_source = _recorded(
        wavelength, "--wavelength", stack.metadata, "wavelength_nm", lambda v: _wavelength(int(v))
    )
    mpr, mpr_source = _scale(mm_per_row, ("stack metadata", stack.metadata))
    if mpr_source.startswith("assumed"):
        raise ValueError(
            f"{stack_path} does not record the size of a projector row on the skin: give --mm-per-row, or add "
            '"mm_per_row" to the capture\'s acquisition.json'
        )
    camera, camera_source = _stack_camera(stack.metadata)
    skin, skin_sources = stated_skin_model(
        stack.metadata, tone=tone_value, wavelength_nm=wl, epidermis_mm=epidermis_mm, dermis_mm=dermis_mm,
        fat_mm=fat_mm, n=n, g=g, optics=optics, blood_saturation=blood_saturation, blood_mu_a=blood_mu_a,
        blood_mu_s=blood_mu_s,
    )  # fmt: skip
    to_trace = tables_to_trace(skin, tone_value, mm_per_row=mpr)
    if to_trace:
        from ..mc.cache import cache_dir
        from ..scenes.skin import TABLE_PHOTONS

        with console.status("estimating the time to trace the skin model's vein tables"):
            seconds = trace_seconds(to_trace, mm_per_row=mpr)
        console.print(
            f"note: the vein tables of this skin model ({len(to_trace)}) are neither shipped nor cached: tracing them "
            f"by Monte Carlo first ({len(to_trace) * TABLE_PHOTONS:,} photons, about {seconds / 60:.0f} minutes on "
            f"this machine, measured on a pilot run; once: cached in {cache_dir()})",
            highlight=False,
            markup=False,
        )
        from ..skin.depth import vein_model

        with progress_bar() as bar:
            task = bar.add_task("tracing the vein tables (photons)", total=len(to_trace) * TABLE_PHOTONS)
            vein_model(
                stack.bands(), stack.geometry, tone=tone_value, wavelength_nm=wl, mm_per_row=mpr, skin=skin,
                progress=lambda k: bar.advance(task, k),
            )  # fmt: skip
    truth = _truth_for(stack.shape, stack_path, mask)
    if truth is None:
        raise ValueError("--mask: give a vein mask (there is no ground truth beside the stack)")
    vein_id = np.asarray(truth["vein_id"])
    if truth.get("exclude") is not None:  # the truth's veins under hair or off the skin: not fitted
        vein_id = np.where(np.asarray(truth["exclude"], bool), 0, vein_id)
    n_veins = int(np.unique(vein_id[vein_id > 0]).size)
    if n_veins == 0:
        raise ValueError("--mask: the vein mask marks no vein")
    true_depths = _truth_depths(stack_path, vein_id)
    with progress_bar() as bar:
        rounds = 1 + (JOINT_ROUNDS if n_veins > 1 else 0)  # each vein alone, then with the others' shadows
        task = bar.add_task(f"fitting {n_veins} vein(s)", total=n_veins * rounds)
        try:
            fits, model, use = fit_veins(
                stack.images,
                stack.bands(),
                stack.geometry,
                vein_id,
                camera=camera,
                excluded=stack.excluded,
                tone=tone_value,
                wavelength_nm=wl,
                mm_per_row=mpr,
                skin=skin,
                joint_rounds=JOINT_ROUNDS,
                progress=lambda vid: bar.advance(task),
            )
        except InputError as exc:
            raise InputError(f"{stack_path}: {exc}") from None
    veins_json = []
    for f in fits:
        j = f.to_json()
        if true_depths:
            j["true_depth_mm"], j["true_diameter_mm"] = true_depths.get(f.id, (None, None))
        veins_json.append(j)
    result = {
        "format": "planeray-skin-depth",
        "format_version": 1,
        "stack": str(stack_path),
        "depth_is": "depth_mm: of the vessel's top (its wall nearest the surface); axis_depth_mm = depth_mm + "
        "diameter_mm / 2; mm below the skin's surface",
        "tone": tone_value,
        "tone_source": tone_source,
        "wavelength_nm": wl,
        "wavelength_source": wl_source,
        "mm_per_row": mpr,
        "mm_per_row_source": mpr_source,
        "skin_model": skin.to_json(),
        "skin_model_sources": skin_sources,
        "camera_source": camera_source,
        "goodness_of_fit": (
            "each vein's chi-square against the camera's noise model with the model's error (its contrast scaled "
            "by 1 + s, s fitted with a prior of 0.15; 2 % of each sample's laser light), and the images' "
            "backgrounds against the skin model's kernel (3 %): a fit less probable than p = 0.001 is flagged "
            "'model does not fit' and its standard errors are scaled by sqrt(chi2 / dof); a depth or diameter at "
            "the tables' edge is flagged and not reported"
        ),
        "mask": truth["source"],
        "images_used": [int(i) for i in np.nonzero(use)[0]],
        "ambient": fits[0].curves.get("ambient") if fits else None,
        "veins": veins_json,
    }
    depth_map = np.full(vein_id.shape, np.nan, np.float32)
    flag_map = np.full(vein_id.shape, 255, np.uint8)
    for f in fits:
        if f.resolved:
            depth_map[vein_id == f.id] = f.depth_mm
        flag_map[vein_id == f.id] = f.flags
    with atomic_directory(out_dir, overwrite=overwrite, kind="skin depth") as tmp:
        from PIL import Image

        Image.fromarray(vein_id.astype(np.uint16)).save(tmp / "vein_ids.png", format="PNG")
        _write_tiff(tmp / "depth_mm.tif", depth_map)
        _write_tiff(tmp / "flags.tif", flag_map, np.uint8)
        _write_csv(tmp / "veins.csv", veins_json)
        depth_fit_figure(
            [{**f.to_json(), "curves": f.curves} for f in fits],
            truth=true_depths or None,
            title=f"Vein depth: {stack_path.name} ({tone_value}, {wl} nm)",
            out=tmp / "depth_fit.png",
        )
        (tmp / MARKER).write_text(json.dumps(jsonable(result), indent=1))
    n_res = sum(f.resolved for f in fits)
    out.print(f"{out_dir}: {n_res}/{len(fits)} veins resolved (depth of the vessel's top, mm below the surface)")
    for j in veins_json:
        line = f"  vein {j['id']}: "
        if j["resolved"]:
            line += (
                f"top {j['depth_mm']:.2f} +- {j['depth_se_mm']:.2f} mm (axis {j['axis_depth_mm']:.2f}), "
                f"diameter {j['diameter_mm']:.2f} +- {j['diameter_se_mm']:.2f} mm"
            )
        else:
            line += f"unresolved: {j['reason']}"
        if j.get("true_depth_mm") is not None:
            line += f" [true: top {j['true_depth_mm']:.2f}, diameter {j['true_diameter_mm']:.2f} mm]"
        out.print(line)
        q, bq = j.get("fit_quality"), j.get("background_quality")
        if q is not None:
            extra = "" if bq is None else f"; backgrounds {bq['reduced_chi2']:.3g} (threshold {bq['threshold']:.3g})"
            out.print(f"    reduced chi-square {q['reduced_chi2']:.3g} (threshold {q['threshold']:.3g}){extra}")
        for text in j.get("flags", []):
            out.print(f"    FLAGGED: {text}", highlight=False, markup=False)


@skin_app.command("compare")
@_friendly_errors
def compare(
    out_dir: Annotated[
        Path, typer.Option("--out", "-o", help="Folder for the figures (Figs. 13, 14, 16) and skin.json.")
    ],
    size: Annotated[
        int,
        typer.Option(help="Image size (size x size of a 720-row projector; at least 16, at most what memory holds)."),
    ] = 128,
    quick: Annotated[bool, typer.Option(help="Two conditions, four ambient levels, fewer delays.")] = False,
    seed: Annotated[int, typer.Option(help="Seed of the scenes and the camera noise (0 to 2^32-1).")] = 0,
    delay_us: Annotated[
        float,
        typer.Option(
            "--delay-us",
            help="Delay of the short-range indirect image (us; > 300 and <= 885: its 600 us band off the "
            "epipolar plane, inside the skin's 64-row kernel).",
        ),
    ] = 500.0,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing report folder planeray wrote.")] = False,
):
    """The Fig. 13/14/16 study end to end on the simulated skin scene: writes figures, CSV tables and skin.json."""
    from .._validate import check_integer, check_number
    from ..experiments.skin import MIN_SIZE, compare_delay_range_us, compare_steps, run_skin_compare

    check_integer(size, "--size", minimum=MIN_SIZE)
    lo, hi = compare_delay_range_us()
    check_number(
        delay_us,
        "--delay-us",
        minimum=lo,
        maximum=hi,
        min_inclusive=False,
        requirement=f"a delay in us, > {lo:g} and <= {hi:.1f} (the 600 us band must leave the epipolar plane and "
        "stay inside the skin scene's 64-row kernel)",
    )
    _bounds.seed(seed)
    _bounds.scene_memory((size, size), copies=4, square=True)
    _check_outputs((out_dir, "skin report"), overwrite=overwrite)
    with progress_bar() as bar:
        task = bar.add_task("skin study", total=compare_steps(quick))

        def progress(msg):
            bar.update(task, advance=1, description=msg)

        numbers = run_skin_compare(
            out_dir, size=size, quick=quick, seed=seed, delay_us=delay_us, overwrite=overwrite, progress=progress
        )
    out.print(f"report: {out_dir}  ({numbers['seconds']:.0f} s)")
    for row in numbers["table"]:
        cnr = "n/a" if row["cnr"] is None else f"{row['cnr']:.2f}"
        out.print(
            f"  {row['condition']:<22} {row['method']:<13} CNR {cnr:>6}  {row['n_detected']}/{row['n_veins']} veins"
        )
    e = numbers["enhancement"]
    if e.get("gain") is not None:
        out.print(
            f"  Eq. 7 enhancement: CNR {_num(e['enhanced_cnr'])} vs best single delay {_num(e['best_single_cnr'])}"
        )
