"""planeray: programmable plane-to-ray light transport (Kubo, Jayasuriya et al., IEEE TVCG 2019).

The front door for notebooks and scripts: everything a user needs is one attribute
away -- the core functions and every module and subpackage (``pr.materials``,
``pr.skin``, ``pr.pulse``, ``pr.viewer``, ...) -- loaded only when first used (PEP 562),
so ``import planeray`` is instant and does not pull in NumPy, Numba, Dask or matplotlib.
The one list of these names is the stub ``planeray/__init__.pyi``: it drives the lazy
loading, ``__all__`` and ``dir()`` here, and type checkers and IDEs read it as it is.

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
from pathlib import Path as _Path

try:
    __version__ = _metadata.version("planeray")
except _metadata.PackageNotFoundError:  # pragma: no cover - a bare source checkout
    __version__ = "0+unknown"


def _read_stub() -> tuple[dict[str, str], list[str]]:
    """The front door's one list, ``__init__.pyi``: ``({name: defining module}, [subpackage, ...])``.

    The stub serves type checkers as it is; here its ``from .MODULE import NAME as NAME`` lines drive
    lazy loading (PEP 562), ``__all__`` and ``dir()`` -- scikit-image's pattern
    (``lazy_loader.attach_stub``), read with one regular expression instead of :mod:`ast`, which
    would double the time ``import planeray`` takes.
    """
    import re

    exports, submodules = {}, []
    text = (_Path(__file__).parent / "__init__.pyi").read_text(encoding="utf-8")
    for module, name in re.findall(r"^from \.([\w.]*) import (\w+) as \2$", text, flags=re.MULTILINE):
        if module:
            exports[name] = module
        else:
            submodules.append(name)
    return exports, submodules


#: Public names of the top level and the module that defines each; the public modules and subpackages.
_EXPORTS, _SUBMODULES = _read_stub()

__all__ = ["__version__", *_EXPORTS, *_SUBMODULES]


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
        globals()[name] = value  # later look-ups skip this hook
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'planeray' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
