"""One exception family for planeray.

Every message names the file (or field) and the problem, so the CLI can print it
as a single line and exit non-zero instead of showing a traceback.
"""

from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar

__all__ = [
    "PlanerayError",
    "InputError",
    "StackError",
    "TransportError",
    "DeviceError",
    "StorageError",
    "parameter_name",
    "parameter_names",
]

#: How messages name a function's parameters (``{"white_reference": "--white-reference"}``); empty:
#: by the keyword itself.  The command line sets it while a command runs, so one message reads
#: right in a notebook (``white_reference``) and on the command line (``--white-reference``).
_PARAMETER_NAMES: ContextVar[dict | None] = ContextVar("planeray_parameter_names", default=None)


def parameter_name(name: str) -> str:
    """How a message names the parameter ``name``: its keyword, or the command-line option that set it.

    Parameters
    ----------
    name : str
        The parameter's keyword.

    Returns
    -------
    str
        The keyword, or the command-line option :func:`parameter_names` set for it.

    See Also
    --------
    parameter_names : sets the names.

    Examples
    --------
    >>> parameter_name("white_reference")
    'white_reference'
    >>> with parameter_names({"white_reference": "--white-reference"}):
    ...     parameter_name("white_reference")
    '--white-reference'
    """
    return (_PARAMETER_NAMES.get() or {}).get(name, name)


@contextmanager
def parameter_names(names: dict):
    """Within the block, messages name parameters as ``names`` says (:func:`parameter_name`).

    Parameters
    ----------
    names : dict of str to str
        Keyword -> how messages name it (``{"white_reference": "--white-reference"}``).

    Returns
    -------
    context manager

    See Also
    --------
    parameter_name : reads them.

    Examples
    --------
    >>> with parameter_names({"mm_per_row": "--mm-per-row"}):
    ...     parameter_name("mm_per_row")
    '--mm-per-row'
    >>> parameter_name("mm_per_row")
    'mm_per_row'
    """
    token = _PARAMETER_NAMES.set({**(_PARAMETER_NAMES.get() or {}), **names})
    try:
        yield
    finally:
        _PARAMETER_NAMES.reset(token)


class PlanerayError(Exception):
    """Base class of every error planeray raises on purpose.

    See Also
    --------
    InputError, StackError, TransportError, DeviceError, StorageError

    Examples
    --------
    Every error planeray raises on purpose is one; the command line prints its message in one line:

    >>> issubclass(InputError, PlanerayError), issubclass(DeviceError, PlanerayError)
    (True, True)
    """


class InputError(PlanerayError, ValueError):
    """Bad user input: a file, a field or a parameter that cannot be used.

    Parameters
    ----------
    problem : str
        What is wrong, in words.
    path : str or os.PathLike, optional
        The file or folder concerned; prefixed to the message.

    See Also
    --------
    StackError, TransportError : malformed stores.

    Examples
    --------
    >>> err = InputError("manifest.csv has no delay_us column", "capture/manifest.csv")
    >>> str(err)
    'capture/manifest.csv: manifest.csv has no delay_us column'
    >>> isinstance(err, ValueError)
    True
    """

    def __init__(self, problem: str, path=None):
        self.path = None if path is None else str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}" if self.path else problem)


class StackError(InputError):
    """A delay-exposure stack (native store or import folder) is malformed.

    Parameters
    ----------
    problem : str
        What is wrong, in words.
    path : str or os.PathLike, optional
        The file or folder concerned; prefixed to the message.

    See Also
    --------
    planeray.read_stack, planeray.import_folder : raise it.

    Examples
    --------
    >>> import numpy as np
    >>> import planeray as pr
    >>> try:
    ...     pr.Stack(np.zeros((2, 4, 4)), [0.0], [600.0, 600.0], 54000.0)
    ... except StackError as err:
    ...     print(err)
    2 images but 1 delays and 2 exposures
    """


class TransportError(InputError):
    """A transport store is malformed.

    Parameters
    ----------
    problem : str
        What is wrong, in words.
    path : str or os.PathLike, optional
        The file or folder concerned; prefixed to the message.

    See Also
    --------
    planeray.read_transport : raises it.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import planeray as pr
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     try:
    ...         pr.read_transport(pathlib.Path(tmp) / "missing.zarr")
    ...     except TransportError:
    ...         print("refused")
    refused
    """


class DeviceError(PlanerayError, RuntimeError):
    """A device cannot be opened or refused a setting (missing SDK, no camera, bad timing).

    See Also
    --------
    planeray.devices.open_device : raises it.

    Examples
    --------
    >>> err = DeviceError("no uEye camera found (camera_id 0)")
    >>> isinstance(err, RuntimeError), str(err)
    (True, 'no uEye camera found (camera_id 0)')
    """


class StorageError(PlanerayError, OSError):
    """The file system refused a write or a read (read-only folder, disk full, unreadable data).

    An ``OSError``, so code that handles file-system failures keeps working; the
    message names the path and the cause on one line.

    Parameters
    ----------
    problem : str
        What failed and why.
    path : str or os.PathLike, optional
        The output (or input) concerned; prefixed to the message.

    See Also
    --------
    planeray.io.atomic_directory, planeray.io.atomic_file : the writes behind it.

    Examples
    --------
    >>> err = StorageError("disk full while writing images", "out/stack.zarr")
    >>> isinstance(err, OSError), err.path
    (True, 'out/stack.zarr')
    """

    def __init__(self, problem: str, path=None):
        self.path = None if path is None else str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}" if self.path else problem)
