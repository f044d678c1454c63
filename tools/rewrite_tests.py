"""Write pytest's assertion-rewritten bytecode of the test modules once (``make bytecode``).

pytest rewrites the ``assert`` statements of every test module and ``conftest.py`` as it imports
them, and caches the result beside the module (``__pycache__/*-pytest-*.pyc``), except where
``PYTHONDONTWRITEBYTECODE`` is set: then every test worker of every run rewrites every module
again (~2.5 s of a worker's start on a 2-core machine, three workers at once).  pytest *reads*
a cached rewrite whatever that variable says, so the rewrites are written here, once (then only
for the modules changed since).

This uses pytest's own rewriting functions, which are not public: with a pytest whose functions
differ it writes nothing and pytest rewrites as before (the same code either way: a cache is
checked against its module's source before it is used).

Usage: ``python tools/rewrite_tests.py conftest.py tests/test_*.py``
"""

from __future__ import annotations

import os
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path


class _State:
    """What ``_write_pyc`` needs of pytest's assertion state: a trace that says nothing."""

    @staticmethod
    def trace(*args) -> None:
        return None


def rewrite_modules(paths: list[str]) -> None:
    """Write the rewrite of each module not cached for its current source (silently nothing on failure)."""
    try:
        from _pytest.assertion import rewrite
    except ImportError:  # no pytest: nothing to do
        return
    for name in paths:
        source = Path(name).absolute()
        try:
            pyc = rewrite.get_cache_dir(source) / (source.name[:-3] + rewrite.PYC_TAIL)
            if rewrite._read_pyc(source, pyc) is not None:
                continue  # cached for the current source
            key, code = rewrite._rewrite_test(source, None)  # the suite's ini leaves the assertion pass hook off
            pyc.parent.mkdir(exist_ok=True)
            rewrite._write_pyc(_State(), code, key, pyc)
        except (AttributeError, TypeError, ValueError, OSError, SyntaxError):
            return  # another pytest, a read-only checkout or a module that does not compile: pytest's own way


def main(paths: list[str]) -> int:
    # the modules shared out over the cores (rewriting is pure Python: ~4 s for the suite on one core)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    parts = [paths[i :: max(1, cores)] for i in range(max(1, cores))]
    with ProcessPoolExecutor(len(parts)) as pool:
        list(pool.map(rewrite_modules, parts))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
