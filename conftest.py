"""Settings of a test session, for the suite (``tests/``) and the docstrings' examples (``src/planeray``).

Under pytest-xdist every core already runs a test: a worker whose BLAS, OpenMP or Numba
starts a thread per core as well puts two threads on each core, and OpenBLAS's threads,
which spin while they wait for each other, then run many times slower (measured: a 75 x 229
pseudo-inverse 3 ms alone, ~470 ms beside another busy process; ``test_faults_ops`` study
case 27 s -> 16 s).  So each worker gets its share of the cores.  A user's own
``OPENBLAS_NUM_THREADS`` (etc.) is kept.

The tests write some 45,000 files (stores, figures, reports) into their temporary folders: on a
machine with a large RAM disk (``/dev/shm``, 8 GiB free or more) they go there (3x faster to
create than on this machine's disk, and nothing to delete from a disk later); pytest keeps only
the latest session's folders (``tmp_path_retention_count = 1`` in pyproject.toml).  A user's own
``PYTEST_DEBUG_TEMPROOT`` or ``--basetemp`` is kept.

``-n auto`` starts one worker per core.  One more worker once ran tests while the others waited
(on chromium, a Dask cluster, a subprocess: 359-369 s with two workers, 318-334 s with three,
when each worker also compiled kernels and ran two demultiplexing threads); with the kernels
compiled before the suite and one solver thread a worker, the third worker only shared the cores:
four back-to-back pairs on the 2-core machine, two workers against three, 311/326, 270/338,
277/287 and 284/310 s (user CPU 521/556, 448/578, 462/489, 472/529 s).  A user's ``-n N`` or
``PYTEST_XDIST_AUTO_NUM_WORKERS`` is kept.

Typer builds the whole click command tree of ``planeray`` (some forty commands, evaluating every
option's annotations) at each ``CliRunner.invoke``: 0.13-0.18 s a call, a third of the data-promise
suites' time (``test_faults_ops``: 159 calls, 28 of 74 s).  The tests build it once per app and
reuse it, as the ``planeray`` program does in its one process; a test that registers or replaces a
command gets a new tree (the key holds every registered callback).

glibc's allocator keeps freed memory for reuse (``GLIBC_TUNABLES``, read by each process as it
starts: the test workers, which start after this file is read, and every subprocess): by default
it maps each block above 128 KiB afresh and hands the top of its heap back once 256 KiB are free,
so the numpy temporaries of the physics checks were faulted in again page by page, test after
test.  With blocks up to 32 MiB served from the heap and up to 256 MiB of free heap kept (the
settings of :func:`planeray.viewer.server.keep_freed_memory`), two of the heaviest modules
(``test_classify``, ``test_skin_depth``) faulted in 0.29 M instead of 1.1 M pages and took 82
instead of 91 CPU-s.  A user's own ``GLIBC_TUNABLES`` is kept.

The garbage collector runs less often: a test session allocates tens of millions of short-lived
objects (matplotlib's artists, Typer's and Rich's), and at Python's default thresholds (700, 10, 10)
each worker spent ~5 % of its time in collections that found little; at (100,000, 50, 50) the
suite took 297 s instead of 308 s (520 instead of 541 CPU-s), its largest process 1.79 instead
of 1.75 GB.
"""

from __future__ import annotations

import gc
import os

import pytest

gc.set_threshold(100_000, 50, 50)

_RAM_DISK = "/dev/shm"
#: Free space a RAM disk needs to hold the suite's temporary folders (about 250 MB a session).
_RAM_DISK_FREE_BYTES = 8 * 2**30


def _free_bytes(path: str) -> int:
    try:
        st = os.statvfs(path)
    except OSError:
        return 0
    return st.f_bavail * st.f_frsize


#: glibc's allocator settings for the test workers and their subprocesses (see above).
_MALLOC_TUNABLES = "glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=268435456"
os.environ.setdefault("GLIBC_TUNABLES", _MALLOC_TUNABLES)

if "PYTEST_DEBUG_TEMPROOT" not in os.environ and _free_bytes(_RAM_DISK) >= _RAM_DISK_FREE_BYTES:
    os.environ["PYTEST_DEBUG_TEMPROOT"] = _RAM_DISK  # read by pytest when it makes the first tmp_path


def _cores() -> int:
    """The cores this process may run on (its CPU affinity where the platform tells it)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - macOS, Windows
        return os.cpu_count() or 1


@pytest.hookimpl(optionalhook=True)  # a pytest-xdist hook: pytest without it runs the suite in one process
def pytest_xdist_auto_num_workers(config):
    """``-n auto``: a worker per core (see above)."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None  # the user's own count: pytest-xdist reads it
    return _cores()


_WORKERS = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
#: Threads each worker may use (1 on the 2-core CI machine running two workers).
THREADS_PER_WORKER = max(1, _cores() // max(1, _WORKERS))

if _WORKERS > 1:
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, str(THREADS_PER_WORKER))  # libraries loaded later, and subprocesses
    from threadpoolctl import threadpool_limits

    # libraries this worker has loaded already (numpy's OpenBLAS); held for the whole session
    _LIMITS = threadpool_limits(int(os.environ["OPENBLAS_NUM_THREADS"]), user_api="blas")

    import numba

    # Numba's thread count, which sizes the Monte Carlo batch pool (planeray.mc._batches): the
    # launched pool keeps its size (tests that compare thread counts still can), this worker uses its share
    numba.set_num_threads(min(THREADS_PER_WORKER, numba.config.NUMBA_NUM_THREADS))


def _command_key(app) -> tuple:
    """The app and every callback registered in it, recursively (a changed app: a new key)."""
    key = [app, getattr(app.registered_callback, "callback", None), getattr(app.info, "callback", None)]
    key += [c.callback for c in app.registered_commands]
    for group in app.registered_groups:
        key.append(group.callback)
        if group.typer_instance is not None:
            key.append(_command_key(group.typer_instance))
    return tuple(key)


def _cache_command_trees() -> None:
    import typer.testing

    build = typer.testing._get_command  # what CliRunner.invoke calls with the app
    trees: dict = {}

    def cached(app):
        key = _command_key(app)
        if key not in trees:
            trees[key] = build(app)
        return trees[key]

    typer.testing._get_command = cached


_cache_command_trees()


def _blank_figures(monkeypatch) -> None:
    """Every figure saved blank and small, without drawing it (no layout, no ticks, no text)."""
    from matplotlib.figure import Figure

    savefig = Figure.savefig

    def blank(self, *args, **kwargs):
        # a new empty figure of the same size is saved in its place (clearing this one's axes costs more)
        kwargs["dpi"] = 10
        kwargs.pop("bbox_inches", None)
        return savefig(Figure(figsize=self.get_size_inches()), *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", blank)
    monkeypatch.setattr(Figure, "tight_layout", lambda self, *args, **kwargs: None)


@pytest.fixture
def figures_not_drawn(monkeypatch):
    """Every figure saved blank and small, without drawing it (no layout, no ticks, no text).

    For the suites that test what a command does with files (the data promises: what it
    writes, replaces, refuses, leaves after a kill), not what its figures show: the PNGs are
    still written by planeray's own atomic writer, with planeray's mark, at the same paths.
    Drawing the figures is most of a quick report's time; the figures themselves are tested
    by the tests of each command.
    """
    _blank_figures(monkeypatch)


@pytest.fixture(scope="session")
def blank_figures():
    """:func:`figures_not_drawn` as a function of a ``MonkeyPatch``, for module-scoped fixtures."""
    return _blank_figures
