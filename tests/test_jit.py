"""``planeray._jit``: every cached Numba kernel is compiled by a warm-up group (``make kernels``)."""

from __future__ import annotations

import numba

from planeray import _jit


@numba.njit(cache=True)
def _never_called(x):  # pragma: no cover - compiled, never called
    return x + 1


def test_every_cached_kernel_is_compiled_by_a_warm_up_group():
    kernels = _jit.cached_kernels()
    # the engines' kernels are found (and helpers inlined into them are not: no cache entry of their own)
    assert {"planeray.mc.engine._trace", "planeray.mc.layered._trace", "planeray.mc.wall._trace_wall"} <= set(kernels)
    assert {"planeray.demux._kernels.relaxed_step", "planeray._bandsum.band_rows"} <= set(kernels)
    assert "planeray.mc.events.uniform" not in kernels  # inline="always"
    assert "planeray.mc.events.roulette" not in kernels
    for group in _jit.GROUPS:
        _jit.compile_group(group)
    assert _jit.uncompiled() == []


def test_a_kernel_no_group_compiles_is_reported():
    assert _jit.uncompiled({"tests.never": _never_called}) == ["tests.never"]
