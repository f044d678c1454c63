"""Import Mitsuba 3 lazily and choose its variant: ``llvm_ad_*`` where its LLVM runtime loads, else ``scalar_*``.

The one-pass tally (:mod:`planeray.render.integrator`) scatters into a
projector-row x pixel array with :func:`drjit.scatter_reduce`, which needs a
vectorized (JIT) variant.  The ``llvm_ad_*`` variants need an LLVM shared
library at run time, version 16 or later (Debian 12: ``apt-get install
libllvm19``; ``make llvm`` does it as root).  planeray points Dr.Jit at the newest
``libLLVM*.so*`` in the system library folders through ``DRJIT_LIBLLVM_PATH``
(unless that is set already): older ones (Debian 12's default LLVM 14/15) abort
the process on some kernels (``Cannot select: fminimum``), so they are never
used.  Without a usable one
planeray falls back to ``scalar_rgb`` (the pip wheels ship no ``scalar_mono``)
and renders row by row with Mitsuba's own integrators
(:mod:`planeray.render.reference`): correct, slower.
"""

from __future__ import annotations

import functools
import glob
import os
import re

__all__ = ["mitsuba", "choose_variant", "is_vectorized", "channels_of", "find_libllvm"]

#: Oldest LLVM whose code generation handles every kernel the tally needs.
MIN_LLVM = 16
_LIB_DIRS = ("/usr/lib/x86_64-linux-gnu", "/lib/x86_64-linux-gnu", "/usr/lib64", "/usr/lib", "/usr/local/lib")


def find_libllvm() -> str | None:
    """Path of the newest ``libLLVM`` (version >= 16) in the system library folders, or None."""
    best, best_version = None, -1
    patterns = [os.path.join(d, "libLLVM*.so*") for d in _LIB_DIRS] + ["/usr/lib/llvm-*/lib/libLLVM*.so*"]
    for pattern in patterns:
        for path in glob.glob(pattern):
            m = re.search(r"libLLVM(?:-|\.so\.)(\d+)", os.path.basename(path))
            if m and int(m.group(1)) > best_version:
                best, best_version = path, int(m.group(1))
    return best if best_version >= MIN_LLVM else None


@functools.cache
def _llvm_runtime() -> bool:
    """Point Dr.Jit at a usable LLVM (once, before any llvm variant starts); True if there is one."""
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return True  # the user's choice
    path = find_libllvm()
    if path is None:
        return False
    os.environ["DRJIT_LIBLLVM_PATH"] = path
    return True


def mitsuba():
    """The ``mitsuba`` module, or an ImportError that says how to install it."""
    try:
        import mitsuba as mi
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError('planeray.render needs Mitsuba 3: pip install "planeray[mitsuba]"') from exc
    return mi


@functools.cache
def _variant_works(variant: str) -> bool:
    mi = mitsuba()
    if variant not in mi.variants():
        return False
    if variant.startswith("llvm") and not _llvm_runtime():
        return False
    previous = mi.variant()
    try:
        mi.set_variant(variant)
        mi.load_dict({"type": "scene"})
        return True
    except Exception:  # the LLVM runtime is missing or broken: fall back
        return False
    finally:
        if previous is not None and previous != variant:
            mi.set_variant(previous)


def choose_variant(*, rgb: bool = False, prefer: str | None = None) -> str:
    """The Mitsuba variant to render with, selected (and made active).

    Parameters
    ----------
    rgb : bool
        Three colour channels instead of one.
    prefer : {"llvm", "scalar"}, optional
        Force the vectorized or the scalar family (default: llvm where it works).

    Returns
    -------
    variant : str
        ``llvm_ad_mono`` / ``llvm_ad_rgb`` where the LLVM runtime loads, else
        ``scalar_rgb`` (monochrome results are then the luminance of RGB).
    """
    mi = mitsuba()
    order = []
    if prefer in (None, "llvm"):
        order.append("llvm_ad_rgb" if rgb else "llvm_ad_mono")
    if prefer in (None, "scalar"):
        order.append("scalar_rgb")
    if prefer not in (None, "llvm", "scalar"):
        raise ValueError(f"prefer must be 'llvm' or 'scalar', got {prefer!r}")
    for variant in order:
        if _variant_works(variant):
            if mi.variant() != variant:
                mi.set_variant(variant)
            return variant
    raise ImportError(
        f"no usable Mitsuba variant among {order}: install Mitsuba 3 with its LLVM runtime "
        "(Debian: apt-get install libllvm19)"
    )


def is_vectorized(variant: str) -> bool:
    """True for the JIT variants (``llvm_*``, ``cuda_*``) that can scatter in one pass."""
    return not variant.startswith("scalar")


def channels_of(variant: str) -> int:
    """Colour channels of a variant's spectra (1 for ``*_mono``, else 3)."""
    return 1 if variant.endswith("mono") else 3
