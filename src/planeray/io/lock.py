"""One writer per output: a lock file beside every output while planeray writes it.

Two runs started by accident into one output (two terminals, a job submitted twice)
would otherwise interleave: both fill the same partial store, one renames the other's
half-written result into place, the slower one dies on a file that vanished under it.
Every planeray writer therefore holds the output's lock while it writes:

* the lock is the file ``.NAME.lock`` beside the output ``NAME`` (a hidden sibling, as
  planeray's temporaries are), created if needed and held with an exclusive
  ``flock`` for the whole run; it records the holder's process id, host, start time and
  command line (JSON), and is deleted when the run ends, however it ends;
* a second run that finds the lock held is refused before any work, in one line:
  ``OUT: another planeray run (pid N) is writing it`` (:class:`OutputBusyError`);
* a lock whose holder is gone (``kill -9``, a power cut: the kernel drops a dead
  process's ``flock``) is *stale*: the next run takes it over and says so
  (:class:`StaleLockWarning`, or the ``on_stale`` callback: the command line prints a note);
* within one process the lock is re-entrant: a command that locks its outputs before
  its work and the library writers it calls (which lock the same output) share it.

Where the file system has no ``flock`` (some network mounts answer ``ENOLCK``), the
holder's process id decides on the same host; a lock of another host is then taken as
held and the message names the lock file to remove.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import socket
import sys
import threading
import time
import warnings
from pathlib import Path

from ..errors import InputError, StorageError

__all__ = ["OutputBusyError", "StaleLockWarning", "lock_holder", "lock_path", "output_lock", "writes_output"]


class OutputBusyError(InputError):
    """Another planeray run holds the output's lock (it is writing the output now)."""


class StaleLockWarning(UserWarning):
    """The lock of an output was left by a run that is no longer running, and is taken over."""


_HELD: dict[Path, list] = {}  # lock path -> [fd, depth]
_HELD_GUARD = threading.Lock()


def lock_path(path) -> Path:
    """The lock file of the output ``path``: ``.NAME.lock`` in the same folder."""
    path = Path(path)
    return path.parent / f".{path.name}.lock"


def _key(path: Path) -> Path:
    try:
        return path.parent.resolve() / path.name
    except OSError:
        return path.absolute()


def lock_holder(path) -> dict | None:
    """What the lock file of the output ``path`` says of its holder (``pid``, ``host``, ``started``, ``command``).

    None when there is no lock file or it cannot be read; an empty dict when it is empty.
    Says nothing of whether the holder is still running (see :func:`output_lock`).
    """
    try:
        text = lock_path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    return _parse(text)


def _parse(text: str) -> dict:
    try:
        info = json.loads(text) if text.strip() else {}
    except ValueError:
        return {}
    return info if isinstance(info, dict) else {}


def _read_fd(fd: int) -> dict:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        data = b""
        while chunk := os.read(fd, 65536):
            data += chunk
        return _parse(data.decode("utf-8", "replace"))
    except OSError:
        return {}


def _pid_alive(pid) -> bool:
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except (OSError, ValueError, TypeError, OverflowError):
        return True  # alive but not ours (EPERM), or not a pid we can judge
    return True


def _who(info: dict) -> str:
    pid = info.get("pid")
    host = info.get("host")
    here = socket.gethostname()
    if pid is None:
        return "another planeray run"
    where = f" on {host}" if host and host != here else ""
    return f"another planeray run (pid {pid}{where})"


def _busy(path: Path, info: dict, error=OutputBusyError) -> InputError:
    return error(
        f"{_who(info)} is writing it; wait for it to finish, or name another output (its lock: {lock_path(path).name})",
        path,
    )


def _describe(info: dict) -> str:
    parts = [f"pid {info.get('pid', '?')}"]
    if info.get("host"):
        parts.append(f"on {info['host']}")
    if info.get("started"):
        parts.append(f"started {info['started']}")
    return " ".join(parts)


def _record() -> bytes:
    info = {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "command": " ".join([Path(sys.argv[0]).name if sys.argv else "python", *sys.argv[1:]])[:2000],
        "planeray_lock": 1,
    }
    return (json.dumps(info) + "\n").encode("utf-8")


def _flock(fd: int) -> bool | None:
    """Take the exclusive ``flock`` of ``fd`` without waiting: True, False (held), None (not supported)."""
    import fcntl

    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except BlockingIOError:
        return False
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            return False
        if exc.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):
            return None
        raise


def _acquire(path: Path, lock: Path, on_stale, error) -> int:
    """Open, lock and stamp ``lock``; return its descriptor (see :func:`output_lock`)."""
    for _ in range(20):  # the file may be removed by its holder between our open and our flock: try again
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except FileNotFoundError:
            raise error("cannot be created: its folder does not exist", path) from None
        except OSError as exc:
            from ._storage import storage_error

            raise storage_error(exc, path) from None
        try:
            got = _flock(fd)
            info = _read_fd(fd)
            if got is False:
                raise _busy(path, info, error)
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(lock))
            except FileNotFoundError:
                same = False
            if not same:  # its holder finished and removed it meanwhile: lock the new one
                os.close(fd)
                continue
            if info.get("pid") is not None:  # a holder that ended cleanly removed the file: this one died
                if got is None:  # no flock on this file system: the pid decides, on this host only
                    here = info.get("host") in (None, socket.gethostname())
                    if not here or (info["pid"] != os.getpid() and _pid_alive(info["pid"])):
                        raise _busy(path, info, error)
                _stale(path, info, on_stale)
            os.ftruncate(fd, 0)
            os.lseek(fd, 0, os.SEEK_SET)
            os.write(fd, _record())
            return fd
        except BaseException as exc:
            with contextlib.suppress(OSError):
                os.close(fd)
            if isinstance(exc, OSError) and not isinstance(exc, StorageError):
                from ._storage import storage_error

                raise storage_error(exc, path) from None
            raise
    raise error("its lock file keeps changing under planeray (another run is starting?); try again", path)


def _stale(path: Path, info: dict, on_stale) -> None:
    note = (
        f"took over the lock of a planeray run that is no longer running ({_describe(info)}); "
        "what it left unfinished is resumed or replaced as usual"
    )
    if on_stale is not None:
        on_stale(f"{path}: {note}")
    else:
        warnings.warn(f"{path}: {note}", StaleLockWarning, stacklevel=4)


def _release(lock: Path, fd: int) -> None:
    with contextlib.suppress(OSError):
        os.unlink(lock)  # removed while still held: a run waiting on this file sees it gone and retries
    with contextlib.suppress(OSError):
        os.close(fd)


@contextlib.contextmanager
def output_lock(path, *, on_stale=None, error=OutputBusyError, make_folders: bool = True):
    """Hold the lock of the output ``path`` while the block runs (see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        The output (a store, folder or file) about to be written.
    on_stale : callable, optional
        Called with a one-line note when a stale lock (its holder gone) is taken over;
        default: a :class:`StaleLockWarning`.
    error : type
        The :class:`~planeray.errors.InputError` subclass raised when the output is busy.
    make_folders : bool
        Create the missing folders above ``path`` (the lock file lives there); those
        still empty when the lock is released are removed again.

    Raises
    ------
    OutputBusyError
        Another planeray run, alive, holds the lock: ``OUT: another planeray run (pid N)
        is writing it ...`` -- before any work.
    StorageError
        The lock file cannot be created (read-only folder, full disk): one line naming
        the output.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "T.zarr"
    >>> with output_lock(out):
    ...     lock_holder(out)["pid"] == os.getpid()
    True
    >>> lock_path(out).exists()
    False
    """
    path = Path(path)
    key = _key(path)
    with _HELD_GUARD:
        held = _HELD.get(key)
        if held is not None:
            held[1] += 1
    if held is None:
        made = _make_folders(path) if make_folders else []
        lock = key.parent / f".{key.name}.lock"
        try:
            fd = _acquire(path, lock, on_stale, error)
        except BaseException:
            _remove_folders(made)
            raise
        with _HELD_GUARD:
            _HELD[key] = held = [fd, 1, made]
    try:
        yield path
    finally:
        with _HELD_GUARD:
            held[1] -= 1
            last = held[1] == 0
            if last:
                _HELD.pop(key, None)
        if last:
            _release(key.parent / f".{key.name}.lock", held[0])
            _remove_folders(held[2])


def _make_folders(path: Path) -> list[Path]:
    """Create the missing folders above ``path``; the ones created, innermost first."""
    from ._storage import storage_error

    missing = []
    folder = path.absolute().parent
    while not folder.exists() and folder.parent != folder:
        missing.append(folder)
        folder = folder.parent
    if not folder.is_dir():
        raise InputError(f"cannot be created: {folder} is a file, not a folder", path)
    created: list[Path] = []
    for folder in reversed(missing):
        try:
            folder.mkdir()
        except FileExistsError:
            if folder.is_dir():
                continue  # made meanwhile by someone else: not ours to remove
            _remove_folders(created[::-1])
            raise InputError(f"cannot be created: {folder} is a file, not a folder", path) from None
        except OSError as exc:
            _remove_folders(created[::-1])
            raise storage_error(exc, path) from None
        created.append(folder)
    return created[::-1]


def _remove_folders(folders: list[Path]) -> None:
    """Remove the folders a lock created, innermost first, where they are still empty."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            return


#: File-system failures that can only come from writing: a full disk or quota, a read-only file system, a file too big.
_WRITE_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EFBIG}


def writes_output(parameter: str = "out"):
    """Decorate a writer of the output named by its argument ``parameter``: locked, and its disk failures named.

    The writer holds the output's lock while it runs (:func:`output_lock`), taken before
    its first check, so a second run into the same output is refused before any work.
    A full disk, a read-only file system or a file too big met while it writes (deep in
    Zarr's threads, where the file named is an internal chunk) becomes one
    :class:`~planeray.errors.StorageError` naming the output.
    """
    import functools
    import inspect

    def decorate(fn):
        signature = inspect.signature(fn)

        @functools.wraps(fn)
        def locked(*args, **kwargs):
            out = signature.bind_partial(*args, **kwargs).arguments.get(parameter)
            if out is None:
                return fn(*args, **kwargs)
            with output_lock(out):
                try:
                    return fn(*args, **kwargs)
                except OSError as exc:
                    if isinstance(exc, StorageError) or exc.errno not in _WRITE_ERRNOS:
                        raise
                    from ._storage import storage_error

                    raise storage_error(exc, out) from None

        return locked

    return decorate
