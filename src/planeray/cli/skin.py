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

import math
from pathlib import Path
from typing import Annotated

import typer

from .._console import console, out, progress_bar
from . import _bounds
from ._common import StackArg, _check_outputs, _friendly_errors, _not_a_home, note, stage_bars

skin_app = typer.Typer(
    help="Skin and veins (Sec. 10): simulate captures, check the physics, vein images and metrics, Eq. 7.",
    no_args_is_help=True,
)


#: Ambient light an option may ask for, electrons per us (full sunlight is ~11 at 638 nm; README, ambient light).
MAX_AMBIENT_E_PER_US = 1000.0


def _tone(text: str):
    """``--tone``: a tone name or a melanosome fraction in [0, 0.5] (:func:`~planeray.experiments.skin_folders.check_tone`)."""
    from ..experiments.skin_folders import check_tone

    return check_tone(text)


def _wavelength(value: int) -> int:
    from ..experiments.skin_folders import check_wavelength

    return check_wavelength(value, "wavelength")


def _mm_per_row_option(value: float) -> float:
    from ..experiments.skin_folders import check_mm_per_row

    return check_mm_per_row(value)


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


def _num(x) -> str:
    return "n/a" if x is None else f"{x:.2f}"


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


@skin_app.command("veins")
@_friendly_errors(options={"source": "SOURCE", "transport": "--transport"})
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
    from ..experiments.skin_folders import check_delay, check_exposure, check_mm_per_row, vein_images

    check_delay(delay_us)
    check_exposure(exposure_us)
    if mm_per_row is not None:
        check_mm_per_row(mm_per_row)
    _check_outputs(
        (out_dir, "skin veins"),
        overwrite=overwrite,
        inputs=[("SOURCE", source), ("--transport", transport_path), ("--mask", mask)],
    )
    result = vein_images(
        source, out_dir, delay_us=delay_us, exposure_us=exposure_us, transport=transport_path, mask=mask,
        mm_per_row=mm_per_row, include_excluded=include_excluded, overwrite=overwrite,
    )  # fmt: skip
    asked = f"{delay_us:g} us" + ("" if exposure_us is None else f", {exposure_us:g} us")
    out.print(
        f"{out_dir}: {result['delay_image']} (asked {asked}; served t_d {result['delay_us']:g} us, "
        f"t_e {result['exposure_us']:g} us)"
    )
    for k, record in result["images"].items():
        line = f"  {k}: {record['label']}"
        if "metrics" in result:
            m = result["metrics"][k]
            line += f"; CNR {_num(m['cnr'])}, {m['n_detected']}/{m['n_veins']} veins detected (per-vein CNR >= 1)"
        out.print(line)


@skin_app.command("enhance")
@_friendly_errors(options={"stack": "STACK"})
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
    from ..experiments.skin_folders import check_delay, check_exposure, check_mm_per_row, enhance_veins

    check_exposure(exposure_us)
    check_delay(min_delay_us, "min_delay_us")
    if mm_per_row is not None:
        check_mm_per_row(mm_per_row)
    _check_outputs((out_dir, "skin enhance"), overwrite=overwrite, inputs=[("STACK", stack_path), ("--mask", mask)])
    with stage_bars() as progress:
        result = enhance_veins(
            stack_path, out_dir, exposure_us=exposure_us, min_delay_us=min_delay_us, patch_px=patch_px, plain=plain,
            mask=mask, mm_per_row=mm_per_row, include_excluded=include_excluded, overwrite=overwrite,
            progress=progress,
        )  # fmt: skip
    delays, t_e, left = result["delays_us"], result["exposure_us"], result["excluded_delays_us"]
    out.print(
        f"{out_dir}: enhanced from {len(delays)} delay images ({delays[0]:g}-{delays[-1]:g} us, t_e {t_e:g} us)"
        + (f"; left out the stack's excluded {', '.join(f'{d:g}' for d in left)} us" if left else "")
    )
    if "metrics" in result:
        e, b = result["metrics"]["enhanced"], result["metrics"]["best_single"]
        out.print(
            f"  enhanced: CNR {_num(e['cnr'])}, {e['n_detected']}/{e['n_veins']} veins; best single delay "
            f"({b['delay_us']:g} us): CNR {_num(b['cnr'])}, {b['n_detected']}/{b['n_veins']} veins"
        )


@skin_app.command("depth")
@_friendly_errors(options={"stack": "STACK", "wavelength_nm": "--wavelength"})
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
    from ..experiments.skin_depth_folder import check_skin_options, vein_depths

    options = dict(
        tone=tone, wavelength_nm=wavelength, mm_per_row=mm_per_row, epidermis_mm=epidermis_mm, dermis_mm=dermis_mm,
        fat_mm=fat_mm, n=n, g=g, layer_optics=layer_optics, blood_saturation=blood_saturation,
        blood_mu_a=blood_mu_a, blood_mu_s=blood_mu_s,
    )  # fmt: skip
    check_skin_options(**options)
    _check_outputs((out_dir, "skin depth"), overwrite=overwrite, inputs=[("STACK", stack_path), ("--mask", mask)])
    with stage_bars() as progress:
        result = vein_depths(
            stack_path, out_dir, mask=mask, **options, overwrite=overwrite, progress=progress, note=note
        )
    veins_json = result["veins"]
    n_res = sum(j["resolved"] for j in veins_json)
    out.print(f"{out_dir}: {n_res}/{len(veins_json)} veins resolved (depth of the vessel's top, mm below the surface)")
    for j in veins_json:
        _print_vein(j)


def _print_vein(j: dict) -> None:
    """One fitted vein on the terminal: its depth and diameter (or why not), its fit quality and flags."""
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
