"""The newcomer's first run (``make demo``): simulate, store, look -- through the top-level API
(``import planeray as pr``), as a notebook would.

1. The disco-ball scene swept over the paper's 85 delay-exposure pairs on the
   simulated Episcan, stored as a Zarr stack, drawn as the Fig. 8 contact sheet.
2. The mirror ball on a book page, stored likewise, with the delay profiles of
   pixels picked from the scene's ground truth (Fig. 9): direct reflection from
   the page (unimodal) and specular interreflection (a second, displaced peak).
3. That stack demultiplexed into 3D light transport (Sec. 4), written as a
   transport store, and its per-pixel T(u) drawn against the ground truth.
4. Veins through skin (Sec. 10): the forearm (``skin`` scene) as a photo, a direct
   (epipolar) image and a short-range indirect delay image (500 us) side by side, with
   the contrast-to-noise ratio of its veins in each.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import planeray as pr

from ._console import progress_bar
from .figures import contact_sheet_figure, delay_profiles_figure, transport_profiles_figure
from .io import read_transport_maps
from .profiles import write_profiles_csv
from .scenes import representative_pixels
from .timing import sweep_support_rows

__all__ = ["run_demo"]


def _simulate(name, out_dir, size, seed, console, progress):
    sweep = pr.paper_sweep()
    t0 = time.perf_counter()
    scene = pr.make_scene(name, (size, size), projector_rows=pr.PAPER_PROJECTOR_ROWS, seed=seed)
    stack_path = out_dir / f"{name}.zarr"
    with progress() as bar:
        task = bar.add_task(f"{name}: capturing {len(sweep)} images", total=len(sweep))
        stack = pr.simulate_stack(
            scene, sweep, lines_per_second=pr.PAPER_LINES_PER_SECOND, seed=seed, progress=lambda i: bar.advance(task)
        )
        task = bar.add_task(f"{name}: writing stack", total=len(sweep))
        pr.write_stack(stack, stack_path, overwrite=True, progress=lambda i: bar.advance(task))
    truth_path = out_dir / f"{name}_truth.zarr"
    attrs = {"lines_per_second": pr.PAPER_LINES_PER_SECOND, "method": "ground_truth", "scene": scene.params}
    pr.write_transport(scene.transport, truth_path, attrs=attrs, overwrite=True)
    console.print(f"  {name}: {len(stack)} images {size}x{size} in {time.perf_counter() - t0:.1f} s -> {stack_path}")
    return scene, stack


def _skin_headline(out_dir, size, seed, console):
    """Sec. 10's headline: photo, direct and short-range indirect images of the forearm, veins only in the last."""
    from .experiments.skin import ROOM_LIGHT, camera_at, measure, valid_rows
    from .figures.skin import headline_figure
    from .skin.imaging import DEFAULT_DELAY_US, DEFAULT_EXPOSURE_US, band_record, device_images, mm_per_row

    t0 = time.perf_counter()
    scene = pr.make_scene("skin", (size, size), projector_rows=pr.PAPER_PROJECTOR_ROWS, seed=seed)
    camera = camera_at(ROOM_LIGHT, float(scene.params.get("wavelength_nm", 638)))
    images, info = device_images(scene, camera, seed=seed, methods=("photo", "direct", "delay"))
    valid = valid_rows(scene, DEFAULT_DELAY_US, DEFAULT_EXPOSURE_US)
    metrics = measure(images, scene, valid)
    band = dict(mm_per_row=mm_per_row(scene), geometry=scene.geometry)
    direct = band_record(0.0, info["direct_exposure_us"], **band)
    delay = band_record(DEFAULT_DELAY_US, DEFAULT_EXPOSURE_US, **band)
    epi = 0.5 * scene.geometry.rows_per_camera_row
    labels = {  # each image named for the band it shows
        "photo": "photo (every row lit, one 16.7 ms frame)",
        "direct": f"direct: t_d = 0, rows {direct['band_rows'][0]:+.1f} to {direct['band_rows'][1]:+.1f} "
        f"(epipolar: +-{epi:.1f})",
        "delay": f"short-range indirect: t_d = {DEFAULT_DELAY_US:g} us, t_e = {DEFAULT_EXPOSURE_US:g} us "
        f"(entered {delay['band_mm'][0]:.1f}-{delay['band_mm'][1]:.1f} mm away)",
    }
    path = out_dir / "skin_veins.png"
    headline_figure(images, labels=labels, metrics=metrics, valid=valid, out=path)
    summary = ", ".join(
        f"{k} CNR {m['cnr']:.1f} ({m['n_detected']}/{m['n_veins']} veins)"
        for k, m in metrics.items()
        if m["cnr"] is not None
    )
    console.print(f"  skin: {summary} in {time.perf_counter() - t0:.1f} s -> {path}")
    return path


def run_demo(out_dir, size: int = 128, seed: int = 0, console=None, progress=None):
    """Run the demo and return the paths it wrote.

    Parameters
    ----------
    out_dir : str or path
        The folder to write (created).
    size : int
        Image size in pixels (square).
    seed : int
        Seed of the simulated noise.
    console : rich.console.Console, optional
        Where messages and progress bars go (default: the terminal).
    progress : optional
        A rich Progress to show the steps in.

    Returns
    -------
    dict of str to pathlib.Path
        What it wrote, by name (``stack_disco_ball``, ``fig8_contact_sheet``, ...).

    See Also
    --------
    planeray.simulate_stack, planeray.demultiplex : the steps it runs.

    Examples
    --------
    The demo at 8 x 8 pixels, its messages kept out of the way:

    >>> import io, pathlib, tempfile
    >>> from rich.console import Console
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     paths = run_demo(pathlib.Path(tmp) / "out", size=8, console=Console(file=io.StringIO()))
    >>> sorted(paths)[:3]
    ['fig8_contact_sheet', 'fig9_delay_profiles', 'fig9_profiles_csv']
    """
    from rich.console import Console
    from rich.text import Text

    console = console or Console()
    progress = progress or progress_bar
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    # Styles as Text, not markup: the console may print verbatim (paths can hold "[...]").
    console.print(
        Text.assemble(
            ("planeray demo", "bold"), ": the paper's sweep (17 delays x 5 exposures) on the simulated Episcan"
        )
    )
    written = {}

    disco, disco_stack = _simulate("disco_ball", out_dir, size=size, seed=seed, console=console, progress=progress)
    written["stack_disco_ball"] = out_dir / "disco_ball.zarr"
    written["fig8_contact_sheet"] = out_dir / "fig8_contact_sheet.png"
    contact_sheet_figure(disco_stack, out=written["fig8_contact_sheet"])

    mirror, mirror_stack = _simulate("mirror_ball", out_dir, size=size, seed=seed, console=console, progress=progress)
    written["stack_mirror_ball"] = out_dir / "mirror_ball.zarr"
    support = sweep_support_rows(pr.paper_sweep(), lines_per_second=pr.PAPER_LINES_PER_SECOND)
    pixels, names = representative_pixels(mirror, support_rows=support, per_label=1)
    prof = pr.measured_delay_profiles(mirror_stack, pixels)
    written["fig9_delay_profiles"] = out_dir / "fig9_delay_profiles.png"
    delay_profiles_figure(mirror_stack, prof, out=written["fig9_delay_profiles"], names=names)
    write_profiles_csv(prof, out_dir / "fig9_delay_profiles.csv")
    written["fig9_profiles_csv"] = out_dir / "fig9_delay_profiles.csv"

    # Demultiplex the mirror-ball stack (Sec. 4) and hold it against the ground truth.
    t0 = time.perf_counter()
    transport_path = out_dir / "mirror_ball_transport.zarr"
    with progress() as bar:
        task = bar.add_task("mirror_ball: demultiplexing", total=mirror_stack.shape[0])
        pr.demultiplex_to_store(mirror_stack, transport_path, overwrite=True, progress=lambda n: bar.advance(task, n))
    estimate, attrs = pr.read_transport(transport_path)
    maps = read_transport_maps(transport_path)
    console.print(
        f"  mirror_ball: demultiplexed {size}x{size} pixels in {time.perf_counter() - t0:.1f} s "
        f"(converged {maps['converged'].mean() * 100:.1f} %) -> {transport_path}"
    )
    written["transport_mirror_ball"] = transport_path
    written["transport_vs_truth"] = out_dir / "transport_vs_truth.png"
    transport_profiles_figure(
        estimate,
        pixels,
        out=written["transport_vs_truth"],
        truth=mirror.transport,
        truth_scale=float(mirror_stack.metadata["signal_scale"]),
        names=names,
        resolution_rows=attrs["epipolar_resolution_rows"],
        title="Demultiplexed T(u) (solid) vs ground truth x signal scale (dashed); grey: cell the sweep cannot split",
    )

    written["skin_veins"] = _skin_headline(out_dir, size=size, seed=seed, console=console)

    console.print(Text.assemble(("done.", "bold green"), " Results:"))
    for key, path in written.items():
        console.print(f"  {key:22s} {path}")
    return written


def main(argv=None):
    parser = argparse.ArgumentParser(description="planeray demo on the simulated device")
    parser.add_argument("--out", default="out")
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    run_demo(args.out, size=args.size, seed=args.seed)


if __name__ == "__main__":
    main()
