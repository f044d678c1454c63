"""Atomic writes, and the rule for replacing outputs: planeray replaces only what planeray wrote.

Every result is written into a temporary sibling (``.{name}.tmp-{pid}-{uuid}``) and
renamed into place, so no half-written result is ever seen at the output path.  An
existing output is replaced only when asked (``overwrite``) *and* when it is a result
planeray itself wrote, of the same kind (recognized by its format attributes, see
:func:`planeray_output_kind`): a folder holding anything else -- a user's notes, the
current folder, a symbolic link -- is refused by name, never deleted.  Temporaries
left by a process that died (``kill -9``, power loss) carry its process id and are
cleaned by the next write to the same output; file-system failures (read-only folder,
disk full) become one :class:`~planeray.errors.StorageError` naming the output.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import uuid
from pathlib import Path

from ..errors import InputError
from ._storage import storage_error

__all__ = [
    "written_together",
    "check_not_an_input",
    "same_place",
    "ALREADY_EXISTS",
    "atomic_directory",
    "atomic_file",
    "check_replaceable",
    "check_writable",
    "planeray_output_kind",
    "storage_error",
]

#: Message of an output that exists and may not be replaced without asking.
ALREADY_EXISTS = "already exists (pass --overwrite, or overwrite=True, to replace it)"

_KINDS = {"planeray-stack": "stack", "planeray-transport": "transport"}
#: Result folders recognized by the ``format`` of their ``planeray.json``.
_FOLDER_KINDS = {
    "planeray-materials-capture": "materials capture",
    "planeray-materials-report": "materials report",
    "planeray-materials-fit": "materials fit",
    "planeray-materials-recognition": "materials recognition",
    "planeray-materials-recognition-study": "materials recognition study",
    "planeray-skin-report": "skin report",
    "planeray-skin-veins": "skin veins",
    "planeray-skin-enhance": "skin enhance",
    "planeray-skin-depth": "skin depth",
    "planeray-skin-validation": "skin validation",
    "planeray-pulse-report": "pulse report",  # `planeray skin pulse` / `skin pulse-report`
    "planeray-paper": "paper report",  # `planeray paper`: the folder, its manifest
    "planeray-paper-step": "paper step",  # one finished step of `planeray paper` inside it
}
#: The marker file of such folders.
MARKER = "planeray.json"


def planeray_output_kind(path) -> str | None:
    """The kind of planeray result at ``path``, or None when planeray did not write it.

    ``"stack"`` / ``"transport"``: a Zarr group whose ``format`` attribute is
    ``planeray-stack`` / ``planeray-transport``; ``"export folder"``: an import folder
    written by :func:`planeray.io.export_folder` (its ``acquisition.json`` carries
    ``planeray_version``); ``"materials capture"`` / ``"materials report"``: a folder
    whose ``planeray.json`` has that ``format`` (``planeray-materials-capture`` /
    ``planeray-materials-report``); a single file: the kind in its mark
    (:func:`planeray.io.marks.file_mark`: ``"image"``, ``"figure"``, ``"video"``...).
    Symbolic links and unmarked files are never recognized.
    """
    p = Path(path)
    if p.is_symlink():
        return None
    if p.is_file():
        from .marks import file_mark

        return file_mark(p)
    if not p.is_dir():
        return None
    try:
        zarr_json = p / "zarr.json"
        if zarr_json.is_file():
            attrs = json.loads(zarr_json.read_text(encoding="utf-8")).get("attributes") or {}
            return _KINDS.get(attrs.get("format"))
        marker = p / MARKER
        if marker.is_file():
            meta = json.loads(marker.read_text(encoding="utf-8"))
            return _FOLDER_KINDS.get(meta.get("format")) if isinstance(meta, dict) else None
        acquisition = p / "acquisition.json"
        if acquisition.is_file() and (p / "manifest.csv").is_file():
            meta = json.loads(acquisition.read_text(encoding="utf-8"))
            return "export folder" if isinstance(meta, dict) and "planeray_version" in meta else None
    except (OSError, ValueError, AttributeError):
        return None
    return None


def is_protected(path: Path) -> bool:
    """The current folder, one of its parents, the home folder or a file-system root."""
    try:
        resolved = path.resolve()
        cwd = Path.cwd().resolve()
    except OSError:
        return False
    return (
        resolved == cwd or resolved in cwd.parents or resolved == Path.home().resolve() or resolved.parent == resolved
    )


def check_replaceable(path, *, overwrite: bool, kind: str | None = None, error=InputError) -> None:
    """Raise unless ``path`` may be written: it does not exist, or it may be replaced.

    Parameters
    ----------
    path : str or os.PathLike
        The output.
    overwrite : bool
        Whether the caller asked to replace an existing output.
    kind : str, optional
        The kind of result about to be written (see :func:`planeray_output_kind`); an
        existing output is replaced only if it is a planeray result of the same kind
        (so a demultiplexed transport never replaces a captured stack).  None: any
        planeray result.
    error : type
        The :class:`~planeray.errors.InputError` subclass to raise.
    """
    path = Path(path)
    if not (path.exists() or path.is_symlink()):
        return
    if not overwrite:
        raise error(ALREADY_EXISTS, path)
    if is_protected(path):
        raise error("is the current folder, one of its parents or the home folder; name a new output inside it", path)
    if path.is_symlink():
        raise error("is a symbolic link; planeray replaces only results it wrote itself", path)
    found = planeray_output_kind(path)
    if found is None:
        what = "a file" if path.is_file() else "a folder"
        raise error(
            f"is {what} planeray did not write (no planeray format attributes or file mark); planeray never "
            "deletes what it did not write: choose another output or remove it yourself",
            path,
        )
    if kind is not None and found != kind:
        raise error(
            f"is a planeray {found}, not a {kind}; planeray will not replace one kind of result with another", path
        )


#: Bytes the write probe of :func:`check_writable` writes (a full disk refuses its first block).
_PROBE_BYTES = 4096


def same_place(a: Path, b: Path) -> bool:
    """``a`` and ``b`` name the same file or folder (resolved; the same inode where both exist)."""
    try:
        if a.resolve() == b.resolve():
            return True
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _inside(inner: Path, outer: Path) -> bool:
    """``inner`` lies inside the folder ``outer`` (resolved paths)."""
    try:
        return inner.resolve().is_relative_to(outer.resolve()) and inner.resolve() != outer.resolve()
    except OSError:
        return False


def _is_store(path: Path) -> bool:
    """A Zarr store or a planeray result folder: a folder whose content a format defines (nothing may be added)."""
    return (path / "zarr.json").is_file() or (path / "planeray.json").is_file()


def check_not_an_input(out, inputs, *, option: str = "out") -> None:
    """Refuse an output that is or holds one of the command's inputs, or lies inside an input store.

    ``inputs``: ``(option, path)`` pairs (``("STACK", path)`` for a positional argument); None
    paths are skipped; ``option`` names the output in the message.  Compared resolved (``./T.zarr``, ``T.zarr/``, an absolute path or a
    symbolic link to it are the same) and by inode where both exist (hard links, bind mounts).
    """
    out = Path(out)
    for name, path in inputs:
        if path is None:
            continue
        path = Path(path)
        if same_place(out, path):
            problem = "is also an input"
        elif _inside(path, out):
            problem = "holds an input"
        elif _inside(out, path) and _is_store(path):
            problem = "lies inside an input store"
        else:
            continue
        which = name if problem == "is also an input" else f"{name} {path}"
        raise InputError(
            f"{option} {out} {problem} ({which}): planeray never writes over its inputs; choose another output"
        )


@contextlib.contextmanager
def written_together(*paths):
    """Files a command writes as one result: if the block fails (an error, Ctrl-C), the ones it created go.

    Each file is written atomically by itself; this removes those of the set that did not
    exist before the block, so a failed run leaves no partial set behind (a file it
    replaced with ``--overwrite`` stays replaced, whole).
    """
    paths = [Path(p) for p in paths if p is not None]
    existed = {p: p.exists() for p in paths}
    try:
        yield
    except BaseException:
        for p in paths:
            if not existed[p]:
                with contextlib.suppress(OSError):
                    if p.is_file() and not p.is_symlink():
                        p.unlink()
        raise


def check_writable(path) -> None:
    """Raise unless a file can be written where ``path`` will be: before any work.

    A file of :data:`_PROBE_BYTES` bytes is written (and removed) in the nearest
    existing folder above ``path``: a read-only folder, a full disk or a folder the
    user may not write into fails here, in one line, instead of after minutes of work.

    Parameters
    ----------
    path : str or os.PathLike
        The output about to be written (it need not exist, nor its folder).

    Raises
    ------
    StorageError
        ``PATH: cannot write: Read-only file system [EROFS] (probe ...)`` and the like.
    InputError
        A file stands where a folder above ``path`` must be.
    """
    path = Path(path)
    folder = path.absolute().parent
    while not folder.exists() and folder.parent != folder:
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(f"cannot be created: {folder} is a file, not a folder", path)
    probe = folder / f".{path.name}.probe-{os.getpid()}-{uuid.uuid4().hex}"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        try:
            os.write(fd, b"\0" * _PROBE_BYTES)
        finally:
            os.close(fd)
    except OSError as exc:
        raise storage_error(exc, path) from None
    finally:
        with contextlib.suppress(OSError):
            os.unlink(probe)


# ----------------------------------------------------------------------------
def _temp_sibling(path: Path, kind: str, suffix: str = "") -> Path:
    return path.parent / f".{path.name}.{kind}-{os.getpid()}-{uuid.uuid4().hex}{suffix}"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, owned by someone else
        return True
    except OSError:
        return True
    return True


def remove_stale_temporaries(path) -> list[Path]:
    """Remove temporaries of ``path`` left by planeray processes that are no longer running.

    Only names planeray gives its temporaries (``.{name}.tmp-{pid}-{uuid}...`` and
    ``.{name}.bak-{pid}-{uuid}``) with the id of a dead process are touched.
    """
    path = Path(path)
    removed = []
    with contextlib.suppress(OSError):
        for kind in ("tmp", "bak"):
            for sib in path.parent.glob(f".{path.name}.{kind}-*"):
                pid = sib.name[len(f".{path.name}.{kind}-") :].split("-", 1)[0]
                if pid.isdigit() and int(pid) != os.getpid() and not _pid_alive(int(pid)):
                    _remove(sib)
                    removed.append(sib)
    return removed


def _remove(path: Path) -> None:
    """Best-effort removal of one of our temporaries (never raises: it must not mask the real error)."""
    with contextlib.suppress(OSError):
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)


def _make_parent(path: Path, error) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise error("cannot be created: its parent is a file", path) from None
    except OSError as exc:
        raise storage_error(exc, path) from None


@contextlib.contextmanager
def atomic_directory(path, *, overwrite: bool = False, kind: str | None = None, error=InputError):
    """Write a directory atomically: yield a temporary sibling, rename it into place.

    Parameters
    ----------
    path : str or os.PathLike
        Final location of the directory.  Its parent is created if needed.
    overwrite : bool
        Replace an existing ``path`` -- only if planeray wrote it (see
        :func:`check_replaceable`).  The old content is first renamed to a temporary
        backup, the new directory renamed into place, then the backup deleted, so
        ``path`` never holds a half-written result.
    kind : str, optional
        What is written (``"stack"``, ``"transport"``, ``"export folder"``): an
        existing output must be a planeray result of this kind to be replaced.
    error : type
        Exception class (an :class:`~planeray.errors.InputError`) raised when
        ``path`` may not be written.

    Yields
    ------
    tmp : pathlib.Path
        Empty temporary directory ``.{name}.tmp-{pid}-{uuid}`` next to ``path``; write
        everything there.  It is removed if the block raises.

    Raises
    ------
    StorageError
        The file system refused (read-only folder, disk full...): one line naming
        ``path`` and the cause; nothing is left behind.

    See Also
    --------
    atomic_file : one file.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     with atomic_directory(pathlib.Path(tmp) / "result") as work:
    ...         _ = (work / "a.txt").write_text("done")
    ...     sorted(p.name for p in pathlib.Path(tmp).iterdir())
    ['result']
    """
    from .lock import output_lock

    path = Path(path)
    check_replaceable(path, overwrite=overwrite, kind=kind, error=error)
    _make_parent(path, error)
    with output_lock(path):
        remove_stale_temporaries(path)
        tmp = _temp_sibling(path, "tmp")
        try:
            tmp.mkdir()
        except OSError as exc:
            raise storage_error(exc, path) from None
        try:
            try:
                yield tmp
            except OSError as exc:
                raise storage_error(exc, path) from None
            check_replaceable(path, overwrite=overwrite, kind=kind, error=error)  # it may have appeared meanwhile
            try:
                if path.exists() or path.is_symlink():
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
            except OSError as exc:
                raise storage_error(exc, path) from None
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
        Replace an existing *file* (default True: figures, CSVs and reports are
        rewritten by each run).  A directory, symbolic link or special file at
        ``path`` is never replaced.
    error : type
        Exception class raised when ``path`` may not be written.

    Yields
    ------
    tmp : pathlib.Path
        Temporary path ``.{name}.tmp-{pid}-{uuid}{suffix}`` in the same folder (same
        suffix, so writers that pick a format by extension work); removed if the
        block raises.

    Raises
    ------
    StorageError
        The file system refused (read-only folder, disk full...).

    See Also
    --------
    atomic_directory : a whole folder.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     with atomic_file(pathlib.Path(tmp) / "table.csv") as work:
    ...         _ = work.write_text("a,b")
    ...     (pathlib.Path(tmp) / "table.csv").read_text()
    'a,b'
    """
    path = Path(path)
    if path.is_dir():
        raise error("is a directory, expected a file path", path)
    if path.exists() and not overwrite:
        raise error(ALREADY_EXISTS, path)
    if path.is_symlink() or (path.exists() and not path.is_file()):
        raise error("is a symbolic link or a special file; planeray replaces only plain files", path)
    from .lock import output_lock

    _make_parent(path, error)
    with output_lock(path):
        remove_stale_temporaries(path)
        tmp = _temp_sibling(path, "tmp", path.suffix)
        try:
            try:
                yield tmp
                os.replace(tmp, path)
            except OSError as exc:
                raise storage_error(exc, path) from None
        except BaseException:
            _remove(tmp)
            raise
