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

import os
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .errors import InputError

__all__ = ["partial_path", "open_partial", "mark_done", "done_units", "promote"]

_DONE = "done_units"
_FINGERPRINT = "run_fingerprint"


def partial_path(out) -> Path:
    """The hidden partial store next to ``out``."""
    out = Path(out)
    return out.parent / f".{out.name}.partial"


def open_partial(out, fingerprint: str, n_units: int, create: Callable[[Path], object], *, restart: bool = False):
    """Open the partial store of ``out`` for ``fingerprint``, creating it with ``create(directory)``.

    ``create`` lays out the store's arrays and attributes in an empty directory
    and returns the Zarr group.  Raises :class:`InputError` when an unfinished
    run with another fingerprint is in the way (unless ``restart``).
    """
    import zarr

    partial = partial_path(out)
    if restart:
        shutil.rmtree(partial, ignore_errors=True)
    if partial.exists():
        group = zarr.open_group(str(partial), mode="r+")
        if group.attrs.get(_FINGERPRINT) != fingerprint or _DONE not in group:
            raise InputError(
                "an unfinished run with different inputs or parameters is in the way; remove it or run with --restart",
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


def mark_done(group, index: int) -> None:
    """Mark unit ``index`` done (call after its data is written)."""
    group[_DONE][index] = True


def done_units(group) -> np.ndarray:
    """Boolean mask of the finished units."""
    return np.asarray(group[_DONE][:], dtype=bool)


def promote(out, *, overwrite: bool, error=InputError) -> Path:
    """Turn a finished partial store into ``out`` (atomic rename; replaces ``out`` if allowed)."""
    import zarr

    out = Path(out)
    partial = partial_path(out)
    group = zarr.open_group(str(partial), mode="r+")
    if not done_units(group).all():
        raise error("internal error: finishing a run with unfinished units", partial)
    del group[_DONE]
    group.attrs.pop(_FINGERPRINT, None)
    if out.exists():
        if not overwrite:
            raise error("already exists (pass overwrite=True to replace it)", out)
        backup = out.parent / f".{out.name}.old"
        shutil.rmtree(backup, ignore_errors=True)
        os.rename(out, backup)
        os.rename(partial, out)
        shutil.rmtree(backup, ignore_errors=True)
    else:
        os.rename(partial, out)
    return out
