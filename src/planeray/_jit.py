"""planeray's compiled kernels, compiled into their on-disk cache at once (``python -m planeray._jit``).

Every Numba kernel of planeray (the demultiplexer's per-pixel passes, the band renderer, the
Monte Carlo engines) is compiled on its first call and cached beside its module
(``__pycache__``, or ``NUMBA_CACHE_DIR``).  A fresh install or clone has no cache, and a kernel
takes 4-10 s to compile on a 2-core machine (all of them ~27 s): the first Monte Carlo run
waits for it, and processes that start at once -- test workers, Dask workers, the commands a
test runs -- each compile the same kernel before any of them has cached it (measured: the
test suite 350 s with the kernels cached, 411 s from an empty cache).

:func:`compile_kernels` calls every engine once on a problem a few photons or pixels large,
through its public entry point, so each kernel is compiled for the argument types the real
calls pass (the suite then compiles nothing more: checked by listing the cache after it), in
one process per group, ``min(groups, cores)`` at a time.  ``make demo`` and ``make test`` run
it (``make kernels``), again only when a kernel's module changes.  :func:`uncompiled` lists the
kernels neither compiled in a process nor cached: what ``python -m planeray._jit`` checks after the
groups ran, so that a kernel added without a group here is reported, not left to the workers.
"""

from __future__ import annotations

import importlib
import os
import pkgutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

__all__ = ["GROUPS", "compile_kernels", "compile_group", "uncompiled", "cached_kernels"]


def _demux() -> None:
    """The demultiplexer's passes (with dropped saturated observations and the ambient term) and the band renderer."""
    from .acquire import simulate_stack
    from .camera import CameraModel
    from .demux import demultiplex
    from .scenes import make_scene
    from .timing import paper_sweep

    scene = make_scene("diffuse_plane", (8, 8), projector_rows=60)
    stack = simulate_stack(scene, paper_sweep(), camera=CameraModel(laser_electrons=14_000.0), seed=1)
    if not stack.saturated.any():  # pragma: no cover - the camera is set to saturate
        raise RuntimeError("the warm-up stack has no saturated pixel: the Woodbury passes were not compiled")
    demultiplex(stack)
    demultiplex(stack, ambient="estimate")
    _weights_criterion()


def _weights_criterion() -> None:
    """The automatic weights' degrees of freedom (the batched path solves and ridge traces)."""
    import numpy as np

    from .demux.risk import degrees_of_freedom_batch

    rng = np.random.default_rng(0)
    A = rng.random((3, 6))  # 3 observations, 5 offsets and the ambient's column
    X = np.array([[0.5, 0.2, 0.0, 0.3, 0.1, 0.4]])  # 4 offsets free (of 5) and the ambient: 5 > 3
    degrees_of_freedom_batch(A, 0.1, X, 5)


def _engine() -> None:
    """The slab engine and the phase-function and Fresnel helpers."""
    from .mc import fresnel_unpolarized, hg_phase, mc_line_profile, sample_hg_cos
    from .medium import Medium

    mc_line_profile(Medium(sigma_s=1.0, sigma_a=0.1, g=0.5, n=1.3), n_photons=64, seed=0)
    fresnel_unpolarized([0.5], 1.4)
    sample_hg_cos([0.5], 0.5)
    hg_phase([0.5], 0.5)


def _layered() -> None:
    """The layered engine (its vein is the same kernel)."""
    from .mc.layered import mc_layered_profile
    from .medium import Medium

    top = Medium(sigma_s=10.0, sigma_a=0.5, g=0.8, n=1.4, thickness_mm=0.5)
    mc_layered_profile([top, Medium(sigma_s=3.0, sigma_a=0.2, g=0.9, n=1.4)], n_photons=64)


def _wall() -> None:
    """The engine beside a container wall."""
    import numpy as np

    from .mc.wall import mc_wall_profile
    from .medium import Medium

    medium = Medium(sigma_s=2.0, sigma_a=0.02, g=0.5, n=1.33)
    mc_wall_profile(
        medium, wall_distance_mm=1.5, wall_angle_deg=0.0, n_photons=64, offsets_rows=np.arange(-4, 5), mm_per_row=0.5
    )


#: The groups, longest first (seconds to compile on a 2-core machine: demux ~10, layered ~8, engine ~5, wall ~4).
GROUPS = {"demux": _demux, "layered": _layered, "engine": _engine, "wall": _wall}


def cached_kernels() -> dict:
    """Every Numba kernel of planeray compiled with ``cache=True`` (``"module.name"``: dispatcher).

    Kernels inlined into their callers (``inline="always"``) are compiled with them and have no
    cache entry of their own: left out.  Only the modules that use Numba are imported.
    """
    import numba.core.caching as caching
    from numba.core.registry import CPUDispatcher

    root = Path(__file__).resolve().parent
    found = {}
    for info in pkgutil.walk_packages([str(root)], prefix=f"{__package__}."):
        if info.ispkg:
            continue
        path = root.joinpath(*info.name.split(".")[1:]).with_suffix(".py")
        if not path.is_file() or "numba.njit" not in path.read_text(encoding="utf-8"):
            continue
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if (
                isinstance(obj, CPUDispatcher)
                and getattr(obj, "__module__", None) == module.__name__
                and isinstance(obj._cache, caching.FunctionCache)
                and obj.targetoptions.get("inline", "never") != "always"
            ):
                found[f"{module.__name__}.{name}"] = obj
    return found


def _on_disk(dispatcher) -> bool | None:
    """Whether the cache holds a compiled version of the kernel's current source (Numba's index).

    None where this Numba keeps its cache otherwise (its layout is not public): unknown.
    """
    try:
        return bool(dispatcher._cache._cache_file._load_index())
    except Exception:
        return None


def _held(dispatcher) -> bool:
    # a helper called only from other kernels is compiled with them; when they are loaded from the
    # cache it is not compiled in this process, but its own cache entry was written when they were
    return bool(dispatcher.signatures) or _on_disk(dispatcher) is not False


def uncompiled(kernels: dict | None = None) -> list[str]:
    """The kernels (default: :func:`cached_kernels`) neither compiled in this process nor cached for their current source."""
    return sorted(name for name, disp in (cached_kernels() if kernels is None else kernels).items() if not _held(disp))


def compile_group(name: str) -> tuple[float, list[str]]:
    """Run group ``name`` here; its seconds and the kernels this process then holds compiled."""
    start = time.perf_counter()
    GROUPS[name]()
    seconds = time.perf_counter() - start
    return seconds, sorted(k for k, disp in cached_kernels().items() if disp.signatures)


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def compile_kernels(*, processes: int | None = None) -> dict:
    """Compile every kernel into its on-disk cache, one process per group.

    Parameters
    ----------
    processes : int, optional
        Processes at a time (default: the cores this process may use, at most one per group).

    Returns
    -------
    dict
        ``"seconds"`` (per group, wall), ``"compiled"`` (every kernel some group compiled) and
        ``"missing"`` (kernels of :func:`cached_kernels` no group compiled: a group is missing).
    """
    n = max(1, min(len(GROUPS), processes or _cores()))
    with ProcessPoolExecutor(n, mp_context=get_context("spawn")) as pool:
        done = dict(zip(GROUPS, pool.map(compile_group, GROUPS)))
    compiled = sorted({k for _, held in done.values() for k in held})
    missing = [k for k in uncompiled() if k not in compiled]
    return {"seconds": {g: s for g, (s, _) in done.items()}, "compiled": compiled, "missing": missing}


def main() -> int:
    start = time.perf_counter()
    result = compile_kernels()
    if result["missing"]:
        print(f"planeray: no warm-up compiles {', '.join(result['missing'])} (add it to planeray._jit.GROUPS)")
        return 1
    print(f"planeray: {len(cached_kernels())} compiled kernels cached ({time.perf_counter() - start:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
