"""Looking at stacks and transports: ``contact-sheet``, ``profiles`` (and effect labels), ``synth``, ``figure``."""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from .._console import console, out, print_json, progress_bar
from ..errors import InputError
from ..io.atomic import written_together
from ..timing import PAPER_LINES_PER_SECOND
from . import _limits as lim
from ._common import StackArg, _check_outputs, _friendly_errors, _load_stack, _parse_pixel, _save_image

#: ``--overwrite`` of the commands that write single files (and folders of named files).
OverwriteArg = Annotated[bool, typer.Option(help="Replace outputs a previous planeray run wrote (only those).")]


def _suffix(path: Path | None, option: str, suffixes: tuple[str, ...]) -> None:
    """Refuse an output whose extension the command does not write (before any work)."""
    if path is not None and path.suffix.lower() not in suffixes:
        raise InputError(f"{option} must end in {', '.join(suffixes)}, got {path.name}")


def _file(text: str | None) -> Path | None:
    """An option that may name a file (``--relight ROW`` or ``--relight FILE``): the file, if it is one."""
    return Path(text) if text is not None and Path(text).exists() else None


def _print(text: str) -> None:
    """A result line, verbatim (paths with brackets are not markup)."""
    out.print(text, markup=False, highlight=False)


@_friendly_errors
def contact_sheet(
    stack_path: StackArg,
    out_png: Annotated[Path, typer.Option("--out", "-o", help="PNG to write.")],
    gamma: Annotated[float, typer.Option(help="Display gamma (0.05 to 10).")] = 0.5,
    max_delays: Annotated[int | None, typer.Option(help="Show at most this many delays.")] = None,
    overwrite: OverwriteArg = False,
):
    """Write the delay x exposure grid of a stack (the paper's Fig. 8)."""
    from ..figures import contact_sheet_figure

    _suffix(out_png, "--out", (".png",))
    _check_outputs((out_png, "figure"), overwrite=overwrite, inputs=[("STACK", stack_path)])
    lim.number(gamma, "--gamma", minimum=0.05, maximum=10.0)
    lim.optional(lim.integer, max_delays, "--max-delays", minimum=1, maximum=10_000)
    st = _load_stack(stack_path)
    with console.status("drawing contact sheet"):
        contact_sheet_figure(st, out=out_png, gamma=gamma, max_delays=max_delays)
    _print(f"contact sheet: {out_png}")


@_friendly_errors
def profiles(
    stack_path: StackArg,
    out_png: Annotated[Path, typer.Option("--out", "-o", help="PNG to write.")],
    pixel: Annotated[
        list[str] | None, typer.Option(help="Pixel as ROW COL or ROW,COL (repeat for more pixels).")
    ] = None,
    exposure_us: Annotated[
        float | None, typer.Option("--exposure-us", "--exposure", help="Plot only this exposure (us).")
    ] = None,
    csv: Annotated[Path | None, typer.Option(help="Also write the profiles as CSV.")] = None,
    transport: Annotated[
        Path | None, typer.Option(help="Transport store: also draw its continuous delay profiles.")
    ] = None,
    classify: Annotated[
        Path | None, typer.Option(help="With --transport: write the per-pixel effect label map PNG.")
    ] = None,
    direct_reference: Annotated[
        Path | None,
        typer.Option(
            help="With --classify: transport store of a white (diffuse) target demultiplexed from the same "
            "sweep, size and camera; the width of a direct peak is measured on it (default: on the image)."
        ),
    ] = None,
    overwrite: OverwriteArg = False,
):
    """Plot area-normalized delay profiles of pixels (the paper's Fig. 9); classify effects from a transport."""
    from ..classify import classify_transport
    from ..figures import delay_profiles_figure, label_map_figure
    from ..profiles import (
        measured_delay_profiles,
        transport_delay_profiles,
        write_profiles_csv,
    )

    if classify is not None and transport is None:
        raise ValueError("--classify needs --transport (the labels come from the transport's profiles)")
    if direct_reference is not None and classify is None:
        raise ValueError("--direct-reference needs --classify (it calibrates the effect labels)")
    if not pixel and classify is None:
        raise ValueError("give at least one --pixel ROW COL (or --classify with --transport)")
    if csv is not None and not pixel:
        raise ValueError("--csv writes the profiles of the --pixel pixels: give at least one --pixel ROW COL")
    _suffix(out_png, "--out", (".png",))
    _suffix(csv, "--csv", (".csv",))
    _suffix(classify, "--classify", (".png",))
    _check_outputs(
        (out_png if pixel else None, "figure"),
        (csv, "table", "--csv"),
        (classify, "figure", "--classify"),
        overwrite=overwrite,
        inputs=[("STACK", stack_path), ("--transport", transport), ("--direct-reference", direct_reference)],
    )
    st, pixels, T, attrs, white = _profiles_inputs(stack_path, pixel, exposure_us, transport, direct_reference)
    with written_together(out_png if pixel else None, csv, classify):  # all of them, or none
        if pixel:
            prof = measured_delay_profiles(st, pixels)
            continuous = None
            if T is not None:
                e = exposure_us if exposure_us is not None else float(prof.exposure_us.min())
                continuous = transport_delay_profiles(
                    T, pixels=prof.pixels, exposure_us=e, lines_per_second=st.lines_per_second
                )
            delay_profiles_figure(st, prof, out=out_png, exposure_us=exposure_us, continuous=continuous)
            if csv is not None:
                write_profiles_csv(prof, csv)
                _print(f"profiles CSV: {csv}")
            _print(f"delay profiles: {out_png}")
        if classify is not None:
            from ..scenes import EFFECTS

            labels = classify_transport(
                T, resolution_rows=float(attrs.get("epipolar_resolution_rows") or 0.0), direct_reference=white
            )
            ref = st.image(st.index_of(delay_us=0.0, exposure_us=float(st.exposures().min())) or 0)
            label_map_figure(labels, out=classify, reference=ref)
            counts = np.bincount(labels.ravel(), minlength=len(EFFECTS))
            summary = ", ".join(f"{EFFECTS[k]} {counts[k] / labels.size * 100:.1f} %" for k in EFFECTS if counts[k])
            _print(f"label map: {classify}  ({summary})")


def _profiles_inputs(stack_path, pixel, exposure_us, transport, direct_reference):
    """What ``profiles`` reads, checked before anything is written: ``(stack, pixels, T, attrs, white)``."""
    lim.optional(lim.positive, exposure_us, "--exposure-us", maximum=lim.MAX_TIME_US)
    pixels = [_parse_pixel(p) for p in pixel or ()]
    st = _load_stack(stack_path)
    for r, c in pixels:
        if not (0 <= r < st.shape[0] and 0 <= c < st.shape[1]):
            raise InputError(
                f"--pixel {r} {c} is outside the {st.shape[0]}x{st.shape[1]} stack (rows 0..{st.shape[0] - 1}, "
                f"columns 0..{st.shape[1] - 1})"
            )
    if exposure_us is not None and not np.any(np.isclose(st.exposures(), exposure_us, rtol=0, atol=1e-6)):
        have = ", ".join(f"{e:g}" for e in st.exposures())
        raise ValueError(f"--exposure-us {exposure_us:g}: the stack has exposures {have} us")
    T = attrs = None
    if transport is not None:
        from ..io import read_transport

        T, attrs = read_transport(transport)
        if T.shape != st.shape:
            raise ValueError(f"{transport}: transport is {T.shape[0]}x{T.shape[1]}, stack {st.shape[0]}x{st.shape[1]}")
    white = None
    if direct_reference is not None:  # an input: checked before anything is written
        from ..io import read_transport

        white, _ = read_transport(direct_reference)
        if white.geometry.rows_per_camera_row != T.geometry.rows_per_camera_row or not np.array_equal(
            white.offsets_rows, T.offsets_rows
        ):
            raise ValueError(
                f"--direct-reference {direct_reference}: {white.geometry.camera_rows} camera rows of "
                f"{white.geometry.projector_rows} projector rows and {white.offsets_rows.size} offsets; the "
                f"transport has {T.geometry.camera_rows} of {T.geometry.projector_rows} and "
                f"{T.offsets_rows.size}: demultiplex the white target from the same sweep and size"
            )
    return st, pixels, T, attrs, white


@_friendly_errors
def synth(
    transport_path: Annotated[Path, typer.Argument(help="Transport store (Zarr).")],
    out_path: Annotated[Path, typer.Option("--out", "-o", help="Image to write (.png preview, .tif 16-bit values).")],
    epipolar: Annotated[bool, typer.Option("--epipolar", help="Epipolar image (Eq. 5).")] = False,
    non_epipolar: Annotated[bool, typer.Option("--non-epipolar", help="Non-epipolar image (Eq. 6).")] = False,
    sharpen: Annotated[
        float | None, typer.Option(help="Sharpened epipolar image with a band of ROWS projector rows.")
    ] = None,
    relight: Annotated[
        str | None, typer.Option(help="Relight: a projector row number, or a pattern file (.npy/.csv/image).")
    ] = None,
    band: Annotated[
        tuple[float, float] | None, typer.Option(help="Banded image for DELAY_US EXPOSURE_US (any pair, us).")
    ] = None,
    short_range: Annotated[
        float | None, typer.Option(help="Short-range indirect light up to MAX_ROWS offsets (projector rows).")
    ] = None,
    long_range: Annotated[
        float | None, typer.Option(help="Long-range indirect light beyond MAX_ROWS offsets (projector rows).")
    ] = None,
    overwrite: OverwriteArg = False,
):
    """Synthesize an image from a transport: epipolar, non-epipolar, sharpened, relit, banded, short/long range."""
    from ..io import read_transport

    chosen = [
        x
        for x in (
            epipolar,
            non_epipolar,
            sharpen is not None,
            relight is not None,
            band is not None,
            short_range is not None,
            long_range is not None,
        )
        if x
    ]
    if len(chosen) != 1:
        raise ValueError(
            "choose exactly one of --epipolar, --non-epipolar, --sharpen, --relight, --band, --short-range, --long-range"
        )
    _suffix(out_path, "--out", (".png", ".tif", ".tiff"))
    _check_outputs(
        (out_path, "image"), overwrite=overwrite, inputs=[("TRANSPORT", transport_path), ("--relight", _file(relight))]
    )
    if band is not None:
        lim.number(band[0], "--band (its delay)", minimum=-lim.MAX_TIME_US, maximum=lim.MAX_TIME_US)
        lim.positive(band[1], "--band (its exposure)", maximum=lim.MAX_TIME_US)
    T, attrs = read_transport(transport_path)
    P = T.geometry.projector_rows
    for option, rows in (("--sharpen", sharpen), ("--short-range", short_range), ("--long-range", long_range)):
        lim.optional(lim.positive, rows, option, maximum=P)  # in projector rows: at most the projector
    if relight is not None and relight.lstrip("-").isdigit() and not 0 <= int(relight) < P:
        raise InputError(f"--relight {relight}: projector row outside 0..{P - 1}")
    image, what = _synthesized(
        T, attrs, epipolar=epipolar, non_epipolar=non_epipolar, sharpen=sharpen, relight=relight, band=band,
        short_range=short_range, long_range=long_range,
    )  # fmt: skip
    path = _save_image(image, out_path)
    _print(f"{what}: {path}  (min {image.min():.3g}, max {image.max():.3g})")


def _synthesized(T, attrs, *, epipolar, non_epipolar, sharpen, relight, band, short_range, long_range):
    """The image ``synth`` makes of the transport, and what it is called: ``(image, what)``."""
    from .. import synthesis as syn

    P = T.geometry.projector_rows
    lps = attrs.get("lines_per_second") or PAPER_LINES_PER_SECOND
    if epipolar:
        image, what = syn.epipolar_image(T), "epipolar image"
    elif non_epipolar:
        image, what = syn.non_epipolar_image(T), "non-epipolar image"
    elif sharpen is not None:
        image, what = syn.sharpened_epipolar(T, width_rows=sharpen), f"sharpened epipolar image ({sharpen:g} rows)"
        res = attrs.get("epipolar_resolution_rows")
        if res and sharpen < 2 * res:
            console.print(
                f"[yellow]note:[/] the sweep cannot split light within +-{res:.2f} rows of the epipolar plane; "
                f"a {sharpen:g}-row band shows the regularizer's spread there"
            )
    elif relight is not None:
        if relight.lstrip("-").isdigit():
            pattern = syn.single_line_pattern(P, row=int(relight))
        else:
            try:
                pattern = syn.load_pattern(relight, projector_rows=P)
            except ValueError as exc:
                raise InputError(
                    f"--relight {relight}: not a projector row (0..{P - 1}) nor a pattern file: {exc}"
                ) from None
        image, what = syn.relight(T, pattern), "relit image"
    elif band is not None:
        image = syn.band_image(T, delay_us=band[0], exposure_us=band[1], lines_per_second=lps)
        what = f"band image (t_d {band[0]:g} us, t_e {band[1]:g} us)"
    else:
        short, long = syn.short_long_range(T, max_rows=short_range if short_range is not None else long_range)
        image, what = (
            (short, "short-range indirect image") if short_range is not None else (long, "long-range indirect image")
        )
    return image, what


@_friendly_errors
def figure(
    name: Annotated[str, typer.Argument(help="fig8 | fig9 | fig11 | fig12 | effects | all")],
    out_dir: Annotated[Path, typer.Option("--out", "-o", help="Folder for the PNGs and their numbers (JSON).")] = Path(
        "out/figures"
    ),
    size: Annotated[int, typer.Option(help="Image size (square, camera pixels).")] = 128,
    seed: Annotated[int, typer.Option(help="Seed.")] = 0,
    overwrite: OverwriteArg = False,
):
    """Reproduce a paper figure on the built-in scenes (writes PNG + JSON of the measured numbers).

    Prints one JSON line per figure on stdout: its name ("figure"), the JSON file written ("json")
    and the numbers measured ("numbers").  The folder may hold other files; the figure's own
    files are checked before any work (an existing one needs ``--overwrite`` and is replaced
    only if planeray wrote it).
    """
    from ..experiments.paper import FIGURES, check_figure_size, figure_outputs, figure_work

    names = list(FIGURES) if name == "all" else [name]
    unknown = [n for n in names if n not in FIGURES]
    if unknown:
        raise ValueError(f"unknown figure {unknown[0]!r}; choose one of {sorted(FIGURES)} or all")
    lim.folder(out_dir, "--out")
    lim.integer(size, "--size", minimum=8, maximum=1024)
    lim.seed(seed)
    for n in names:  # before running anything
        check_figure_size(n, size, option="--size")
    _check_outputs(*((out_dir / f, kind) for n in names for f, kind in figure_outputs(n)), overwrite=overwrite)
    for n in names:
        with progress_bar() as bar:
            task = bar.add_task(n, total=figure_work(n, size=size))
            numbers = FIGURES[n](out_dir, size=size, seed=seed, progress=partial(bar.advance, task))
        # After the bar has stopped (a live bar re-routes stdout to its console), verbatim: never wrapped.
        print_json({"figure": n, "json": str(out_dir / f"{n}.json"), "numbers": numbers})
