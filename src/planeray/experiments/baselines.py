"""The outputs of ``planeray separate direct-global`` and ``planeray emulate``, as functions.

Each runs a conventional projector-camera baseline on the simulated device against synchronized
imaging and its ground truth (:mod:`planeray.baselines`), and writes the images (a ``.png``
preview and a ``.tif`` of the values each, one brightening for all so they compare) and the
numbers (``NAME.json``) into a folder that may hold other files: all of them, or none (each file
written atomically, under its own lock).
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import numpy as np

from .workflow import Stages

__all__ = ["direct_global_folder", "emulation_folder", "write_comparison", "DIRECT_GLOBAL_IMAGES", "EMULATION_IMAGES"]

#: The images each comparison writes (a .png preview and a .tif of the values each).
DIRECT_GLOBAL_IMAGES = ("nayar_direct", "nayar_global", "epipolar", "truth_direct", "truth_global")
EMULATION_IMAGES = ("emulated", "synchronized", "truth")


def write_comparison(out_dir, images: dict, numbers: dict, name: str) -> list[Path]:
    """The images (None: left out) and ``NAME.json`` into ``out_dir``: all of them, or none of those this run creates.

    Returns the files written.
    """
    from ..figures._common import display_scale, save_image
    from ..io import atomic_file
    from ..io.atomic import written_together
    from ..io.marks import MARK_KEY, mark_text

    out_dir = Path(out_dir)
    created = not out_dir.exists()
    out_dir.mkdir(parents=True, exist_ok=True)
    valid = [im for im in images.values() if im is not None]
    scale = display_scale(valid, percentile=99.5)  # one brightening for all, so they compare
    files = [out_dir / f"{key}{ext}" for key in images for ext in (".png", ".tif")] + [out_dir / f"{name}.json"]
    try:
        with written_together(*files):  # all of them, or none of those this run creates
            for key, image in images.items():
                if image is not None:
                    save_image(np.nan_to_num(image), out_dir / f"{key}.png", scale_to=scale)
                    save_image(np.clip(np.nan_to_num(image), 0, 1), out_dir / f"{key}.tif")
            with atomic_file(out_dir / f"{name}.json") as tmp:
                tmp.write_text(json.dumps({MARK_KEY: mark_text("record"), **numbers}, indent=2, default=float))
    except BaseException:
        if created:
            with contextlib.suppress(OSError):
                out_dir.rmdir()  # the folder this run made, if nothing else is in it
        raise
    return files


def direct_global_folder(
    device,
    out_dir,
    *,
    epipolar_exposure_us: float = 600.0,
    period_rows: int | None = None,
    n_shifts: int | None = None,
    pattern_contrast_b: float = 0.0,
    progress=None,
) -> dict:
    """Nayar's direct/global separation against synchronized epipolar imaging, written as a folder.

    Runs :func:`planeray.baselines.compare_direct_global` on ``device`` (e.g.
    :func:`planeray.devices.simulated_device`) and writes ``nayar_direct``, ``nayar_global``,
    ``epipolar``, ``truth_direct`` and ``truth_global`` (``.png``, ``.tif``) and
    ``direct_global.json`` (:func:`write_comparison`).  Returns the numbers.
    """
    from ..baselines import compare_direct_global

    Stages(progress).stage("capturing stripe patterns and the epipolar image")
    res = compare_direct_global(
        device, epipolar_exposure_us=epipolar_exposure_us, period_rows=period_rows, n_shifts=n_shifts,
        pattern_contrast_b=pattern_contrast_b,
    )  # fmt: skip
    images = {
        "nayar_direct": res["nayar"].direct,
        "nayar_global": res["nayar"].global_,
        "epipolar": res["epipolar"],
        "truth_direct": res["truth_direct"],
        "truth_global": res["truth_global"],
    }
    write_comparison(out_dir, images, res["numbers"], "direct_global")
    return res["numbers"]


def emulation_folder(
    device, out_dir, *, delay_us: float, exposure_us: float, spacing_rows: int | None = None, progress=None
) -> dict:
    """Digital epipolar emulation (Sec. 5.1, Fig. 4) against the synchronized image, written as a folder.

    Runs :func:`planeray.baselines.compare_emulation` on ``device`` and writes ``emulated``,
    ``synchronized`` and ``truth`` (``.png``, ``.tif``) and ``emulation.json``.  Returns the numbers.
    """
    from ..baselines import compare_emulation

    Stages(progress).stage("sweeping the band one row at a time")
    res = compare_emulation(device, delay_us=delay_us, exposure_us=exposure_us, spacing_rows=spacing_rows)
    images = {"emulated": res["emulated"].image, "synchronized": res["synchronized"], "truth": res["truth"]}
    write_comparison(out_dir, images, res["numbers"], "emulation")
    return res["numbers"]
