"""Atomic writes: a temporary sibling renamed into place, so no half-written result is ever seen."""

from __future__ import annotations

import contextlib
import os
import shutil
import uuid
from pathlib import Path

from ..errors import InputError


# ----------------------------------------------------------------------------
def _temp_sibling(path: Path, kind: str, suffix: str = "") -> Path:
    return path.parent / f".{path.name}.{kind}-{uuid.uuid4().hex}{suffix}"


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


@contextlib.contextmanager
def atomic_directory(path, *, overwrite: bool = False, error=InputError):
    """Write a directory atomically: yield a temporary sibling, rename it into place.

    Parameters
    ----------
    path : str or os.PathLike
        Final location of the directory.  Its parent is created if needed.
    overwrite : bool
        Replace an existing ``path``.  The old content is first renamed to a
        temporary backup, the new directory renamed into place, then the backup
        deleted, so ``path`` never holds a half-written result.
    error : type
        Exception class (an :class:`~planeray.errors.InputError`) raised when
        ``path`` exists and ``overwrite`` is False.

    Yields
    ------
    tmp : pathlib.Path
        Empty temporary directory ``.{name}.tmp-{uuid}`` next to ``path``; write
        everything there.  It is removed if the block raises.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise error("already exists (pass overwrite=True to replace it)", path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temp_sibling(path, "tmp")
    tmp.mkdir()
    try:
        yield tmp
        if path.exists() or path.is_symlink():
            if not overwrite:
                raise error("already exists (pass overwrite=True to replace it)", path)
            backup = _temp_sibling(path, "bak")
            os.rename(path, backup)
            try:
                os.rename(tmp, path)
            except BaseException:
                os.rename(backup, path)
                raise
            _remove(backup)
        else:
            os.rename(tmp, path)
    except BaseException:
        _remove(tmp)
        raise


@contextlib.contextmanager
def atomic_file(path, *, overwrite: bool = True, error=InputError):
    """Write a single file atomically: yield a temporary sibling, ``os.replace`` it.

    Parameters
    ----------
    path : str or os.PathLike
        Final file path.  Its parent is created if needed.
    overwrite : bool
        Replace an existing file (default True).
    error : type
        Exception class raised when ``path`` exists and ``overwrite`` is False.

    Yields
    ------
    tmp : pathlib.Path
        Temporary path ``.{name}.tmp-{uuid}{suffix}`` in the same folder (same
        suffix, so writers that pick a format by extension work); removed if the
        block raises.
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise error("already exists (pass overwrite=True to replace it)", path)
    if path.is_dir():
        raise error("is a directory, expected a file path", path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temp_sibling(path, "tmp", path.suffix)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        _remove(tmp)
        raise
