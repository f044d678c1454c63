"""One line for a file-system failure while writing an output (shared by the atomic writers and the locks)."""

from __future__ import annotations

import errno
import os

from ..errors import StorageError


def storage_error(exc: BaseException, path) -> StorageError:
    """A one-line :class:`~planeray.errors.StorageError` for a file-system failure while writing ``path``."""
    if isinstance(exc, OSError) and exc.errno is not None:
        name = errno.errorcode.get(exc.errno, str(exc.errno))
        cause = f"{exc.strerror or os.strerror(exc.errno)} [{name}]"
        where = f" ({exc.filename})" if exc.filename and str(exc.filename) != str(path) else ""
        return StorageError(f"cannot write: {cause}{where}", path)
    # an encoder's own message (ffmpeg's: the error, then its whole command line): its first line only
    first = next((line.strip() for line in str(exc).splitlines() if line.strip()), "")
    return StorageError(f"cannot write: {type(exc).__name__}: {first}", path)
