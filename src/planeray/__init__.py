"""planeray: programmable plane-to-ray light transport (Kubo, Jayasuriya et al., IEEE TVCG 2019).

The front door for notebooks and scripts: everything a user needs is one attribute
away, loaded only when first used (PEP 562), so ``import planeray`` is instant and
does not pull in Numba, Dask or matplotlib.

>>> import planeray as pr
>>> scene = pr.make_scene("wax", (32, 32), projector_rows=180, seed=0)
>>> stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)
>>> stack.images.shape
(27, 32, 32)
>>> image = scene.transport.render(pr.Band(delay_us=0.0, exposure_us=600.0))
>>> image.shape, image.dtype
((32, 32), dtype('float32'))

The pipeline, one module (or subpackage) per stage, dependencies pointing down it:
:mod:`~planeray.timing` (Eqs. 1-3), :mod:`~planeray.transport` (Eqs. 4-6),
:mod:`~planeray.scenes`, :mod:`~planeray.camera`, :mod:`~planeray.devices`,
:mod:`~planeray.acquire`, :mod:`~planeray.calibration`, :mod:`~planeray.io`,
:mod:`~planeray.demux`, :mod:`~planeray.synthesis`, :mod:`~planeray.profiles`,
:mod:`~planeray.classify`, :mod:`~planeray.baselines`, :mod:`~planeray.mc`,
:mod:`~planeray.study`, :mod:`~planeray.render`, :mod:`~planeray.figures`, :mod:`~planeray.experiments`.
"""

from __future__ import annotations

import importlib
from importlib import metadata as _metadata
from typing import TYPE_CHECKING

try:
    __version__ = _metadata.version("planeray")
except _metadata.PackageNotFoundError:  # pragma: no cover - a bare source checkout
    __version__ = "0+unknown"

#: Public names of the top level and the module that defines each.
_EXPORTS = {
    # imaging model (Eqs. 1-6)
    "PAPER_LINES_PER_SECOND": "timing",
    "PAPER_PROJECTOR_ROWS": "timing",
    "Band": "timing",
    "RowPattern": "timing",
    "RowGeometry": "timing",
    "Sweep": "timing",
    "paper_sweep": "timing",
    "quick_sweep": "timing",
    "make_sweep": "timing",
    "Transport": "transport",
    "SparseEntries": "transport",
    # captures
    "Stack": "stack",
    "CameraModel": "camera",
    "make_scene": "scenes",
    "list_scenes": "scenes",
    "skin_veins": "scenes.skin",
    "SimulatedEpiscan": "devices",
    "ReplayDevice": "devices",
    "simulate_stack": "acquire",
    "acquire_sweep": "acquire",
    "acquire_to_store": "acquire",
    "calibrate_lines_per_second": "calibration",
    "calibrate_delay_zero": "calibration",
    # files
    "read_stack": "io",
    "write_stack": "io",
    "import_folder": "io",
    "export_folder": "io",
    "read_transport": "io",
    "write_transport": "io",
    # demultiplexing (Sec. 4)
    "DemuxProblem": "demux",
    "demultiplex": "demux",
    "demultiplex_to_store": "demux",
    # analysis (Secs. 4, 7, 8, 9)
    "epipolar_image": "synthesis",
    "non_epipolar_image": "synthesis",
    "sharpened_epipolar": "synthesis",
    "band_image": "synthesis",
    "relight": "synthesis",
    "short_long_range": "synthesis",
    "measured_delay_profiles": "profiles",
    "transport_delay_profiles": "profiles",
    "classify_transport": "classify",
    # subsurface scattering (Sec. 5.2)
    "Medium": "medium",
    "mc_line_profile": "mc",
    "line_kernel": "kernels",
    # any Mitsuba 3 scene -> transport
    "render_transport": "render",
}

_SUBMODULES = {
    "timing",
    "transport",
    "stack",
    "camera",
    "scenes",
    "devices",
    "acquire",
    "calibration",
    "io",
    "demux",
    "synthesis",
    "profiles",
    "classify",
    "baselines",
    "mc",
    "kernels",
    "render",
    "study",
    "figures",
    "experiments",
    "errors",
    "medium",
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
        globals()[name] = value  # later look-ups skip this hook
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'planeray' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS) | _SUBMODULES)


if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs only
    from .acquire import acquire_sweep, acquire_to_store, simulate_stack
    from .calibration import calibrate_delay_zero, calibrate_lines_per_second
    from .camera import CameraModel
    from .classify import classify_transport
    from .demux import DemuxProblem, demultiplex, demultiplex_to_store
    from .devices import ReplayDevice, SimulatedEpiscan
    from .io import export_folder, import_folder, read_stack, read_transport, write_stack, write_transport
    from .kernels import line_kernel
    from .mc import mc_line_profile
    from .medium import Medium
    from .profiles import measured_delay_profiles, transport_delay_profiles
    from .scenes import list_scenes, make_scene
    from .stack import Stack
    from .synthesis import band_image, epipolar_image, non_epipolar_image, relight, sharpened_epipolar, short_long_range
    from .timing import (
        PAPER_LINES_PER_SECOND,
        PAPER_PROJECTOR_ROWS,
        Band,
        RowGeometry,
        RowPattern,
        Sweep,
        make_sweep,
        paper_sweep,
        quick_sweep,
    )
    from .transport import SparseEntries, Transport
