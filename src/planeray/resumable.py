"""Resumable stores: long runs that fill a Zarr store unit by unit and survive being killed.

A run writes into a hidden sibling ``.NAME.partial`` whose layout is complete
from the start, marks each unit (an image, a chunk of rows) done in a ``done``
array *after* its data, and is identified by a fingerprint of its inputs.  A
run started again with the same output and fingerprint continues from the done
units; a different run refuses to touch it.  Only a finished store is renamed to
``NAME`` -- the output path never holds a half-written result.  Used by the
sweep runner (:func:`planeray.acquire.acquire_to_store`) and the demultiplexer
(:func:`planeray.demux.demultiplex_to_store`).
"""

from __future__ import annotations

import contextvars
import functools
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .errors import InputError

__all__ = ["partial_path", "open_partial", "mark_done", "done_units", "discard_if_empty", "promote"]

_STOP_AFTER: contextvars.ContextVar[int | None] = contextvars.ContextVar("planeray_stop_after", default=None)


def killable(fn):
    """Give a resumable run the tests' hook ``_stop_after=k`` (end as if killed after ``k`` units) without
    showing it in ``fn``'s public signature (:func:`inspect.signature` follows ``__wrapped__``); ``fn`` reads
    it with :func:`stop_after_units`."""

    @functools.wraps(fn)
    def wrapper(*args, _stop_after: int | None = None, **kwargs):
        token = _STOP_AFTER.set(_stop_after)
        try:
            return fn(*args, **kwargs)
        finally:
            _STOP_AFTER.reset(token)

    return wrapper


def stop_after_units() -> int | None:
    """The ``_stop_after`` of the running :func:`killable` call (None: run to the end)."""
    return _STOP_AFTER.get()


_DONE = "done_units"
_FINGERPRINT = "run_fingerprint"


def partial_path(out) -> Path:
    """The hidden partial store next to ``out``.

    Parameters
    ----------
    out : str or path
        The output store.

    Returns
    -------
    pathlib.Path
        ``.NAME.partial`` beside ``out``.

    See Also
    --------
    open_partial : opens it.

    Examples
    --------
    >>> partial_path("out/T.zarr").as_posix()
    'out/.T.zarr.partial'
    """
    out = Path(out)
    return out.parent / f".{out.name}.partial"


def open_partial(out, fingerprint: str, n_units: int, create: Callable[[Path], object], *, restart: bool = False):
    """Open the partial store of ``out`` for ``fingerprint``, creating it with ``create(directory)``.

    ``create`` lays out the store's arrays and attributes in an empty directory
    and returns the Zarr group.  Raises :class:`InputError` when an unfinished
    run with another fingerprint is in the way (unless ``restart``).

    Parameters
    ----------
    out : str or path
        The output store.
    fingerprint : str
        What identifies the run's inputs and parameters.
    n_units : int
        Units of work (images, chunks of rows).
    create : callable
        ``create(directory) -> zarr.Group``: lays out the store in an empty folder.
    restart : bool
        Discard an unfinished run of another fingerprint instead of refusing.

    Returns
    -------
    zarr.Group
        The partial store, opened for writing.

    See Also
    --------
    mark_done, done_units, promote

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import zarr
    >>> tmp = tempfile.TemporaryDirectory()
    >>> out = pathlib.Path(tmp.name) / "result.zarr"
    >>> group = open_partial(out, "inputs-v1", 3, lambda d: zarr.open_group(str(d), mode="w"))
    >>> mark_done(group, 0)
    >>> open_partial(out, "inputs-v1", 3, None) is not None  # the same run resumes
    True
    >>> tmp.cleanup()
    """
    import zarr

    partial = partial_path(out)
    if restart:
        shutil.rmtree(partial, ignore_errors=True)
    if partial.exists():
        group = zarr.open_group(str(partial), mode="r+")
        if group.attrs.get(_FINGERPRINT) != fingerprint or _DONE not in group:
            raise InputError(
                "an unfinished run with different inputs or parameters is in the way; run with --restart "
                "(restart=True) to discard it, or name another output",
                partial,
            )
        return group
    tmp = partial.parent / f"{partial.name}.init"
    shutil.rmtree(tmp, ignore_errors=True)
    partial.parent.mkdir(parents=True, exist_ok=True)
    tmp.mkdir()
    try:
        group = create(tmp)
        group.create_array(_DONE, shape=(n_units,), chunks=(max(n_units, 1),), dtype="bool", fill_value=False)
        group.attrs[_FINGERPRINT] = fingerprint
        os.rename(tmp, partial)  # the partial store appears with its whole layout
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return zarr.open_group(str(partial), mode="r+")


def discard_if_empty(out) -> bool:
    """Remove the partial store of ``out`` if none of its units is done; True if removed.

    Called when a run fails: a partial store with finished units is kept (the next run
    resumes it), one without any holds nothing worth keeping and is not left behind.

    Parameters
    ----------
    out : str or path
        The output store.

    Returns
    -------
    bool
        True if the partial store was removed.

    See Also
    --------
    open_partial : creates it.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import zarr
    >>> tmp = tempfile.TemporaryDirectory()
    >>> out = pathlib.Path(tmp.name) / "result.zarr"
    >>> group = open_partial(out, "inputs-v1", 3, lambda d: zarr.open_group(str(d), mode="w"))
    >>> discard_if_empty(out), partial_path(out).exists()
    (True, False)
    >>> tmp.cleanup()
    """
    import zarr

    partial = partial_path(out)
    try:
        group = zarr.open_group(str(partial), mode="r")
        if _DONE in group and done_units(group).any():
            return False
    except Exception:  # unreadable: not ours to judge, leave it
        return False
    shutil.rmtree(partial, ignore_errors=True)
    return not partial.exists()


def mark_done(group, index: int) -> None:
    """Mark unit ``index`` done (call after its data is written).

    Parameters
    ----------
    group : zarr.Group
        The partial store.
    index : int
        The unit finished.

    Returns
    -------
    None

    See Also
    --------
    done_units : the units marked.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import zarr
    >>> tmp = tempfile.TemporaryDirectory()
    >>> out = pathlib.Path(tmp.name) / "result.zarr"
    >>> group = open_partial(out, "inputs-v1", 3, lambda d: zarr.open_group(str(d), mode="w"))
    >>> mark_done(group, 1)
    >>> done_units(group).tolist()
    [False, True, False]
    >>> tmp.cleanup()
    """
    group[_DONE][index] = True


def done_units(group) -> np.ndarray:
    """Boolean mask of the finished units.

    Parameters
    ----------
    group : zarr.Group
        The partial store.

    Returns
    -------
    ndarray of bool (n_units,)

    See Also
    --------
    mark_done : marks one.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import zarr
    >>> tmp = tempfile.TemporaryDirectory()
    >>> out = pathlib.Path(tmp.name) / "result.zarr"
    >>> group = open_partial(out, "inputs-v1", 3, lambda d: zarr.open_group(str(d), mode="w"))
    >>> done_units(group).tolist()
    [False, False, False]
    >>> tmp.cleanup()
    """
    return np.asarray(group[_DONE][:], dtype=bool)


def promote(out, *, overwrite: bool, kind: str | None = None, error=InputError) -> Path:
    """Turn a finished partial store into ``out`` (atomic rename).

    An existing ``out`` is replaced only with ``overwrite`` and only if it is a planeray
    result of the same ``kind`` (:func:`planeray.io.atomic.check_replaceable`).  When
    ``out`` may not be replaced (for instance it appeared while the run was going),
    the finished partial store is kept as it is: a re-run with the same inputs
    finds every unit done and finishes without recomputing.

    Parameters
    ----------
    out : str or path
        The output store.
    overwrite : bool
        Replace an existing ``out`` (only a planeray result of the same ``kind``).
    kind : str, optional
        What the store is (``"stack"``, ``"transport"``).
    error : type
        The exception raised when ``out`` may not be replaced.

    Returns
    -------
    pathlib.Path
        ``out``.

    See Also
    --------
    open_partial : the run's start.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import zarr
    >>> tmp = tempfile.TemporaryDirectory()
    >>> out = pathlib.Path(tmp.name) / "result.zarr"
    >>> group = open_partial(out, "inputs-v1", 3, lambda d: zarr.open_group(str(d), mode="w"))
    >>> for unit in range(3):
    ...     mark_done(group, unit)
    >>> promote(out, overwrite=False).name, partial_path(out).exists()
    ('result.zarr', False)
    >>> tmp.cleanup()
    """
    import zarr

    from .io.atomic import check_replaceable, storage_error

    out = Path(out)
    partial = partial_path(out)
    group = zarr.open_group(str(partial), mode="r+")
    if not done_units(group).all():
        raise error("internal error: finishing a run with unfinished units", partial)
    try:
        check_replaceable(out, overwrite=overwrite, kind=kind, error=error)
    except InputError as exc:
        raise error(
            f"{exc.problem} -- the finished result is kept in {partial.name}; run again with the same inputs "
            "(and --overwrite if the output is a planeray result) to move it into place without recomputing",
            out,
        ) from None
    n_units = int(group[_DONE].shape[0])
    fingerprint = group.attrs.get(_FINGERPRINT)
    del group[_DONE]
    group.attrs.pop(_FINGERPRINT, None)
    try:
        if out.exists() or out.is_symlink():
            backup = out.parent / f".{out.name}.old"
            shutil.rmtree(backup, ignore_errors=True)
            os.rename(out, backup)
            try:
                os.rename(partial, out)
            except BaseException:
                os.rename(backup, out)
                raise
            shutil.rmtree(backup, ignore_errors=True)
        else:
            os.rename(partial, out)
    except OSError as exc:
        # keep the partial store resumable: put its done marker back
        group.create_array(_DONE, shape=(n_units,), chunks=(max(n_units, 1),), dtype="bool", fill_value=True)
        group[_DONE][:] = True
        group.attrs[_FINGERPRINT] = fingerprint
        raise storage_error(exc, out) from None
    return out
