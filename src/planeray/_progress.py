"""Progress of the library's long calls (:func:`planeray.demultiplex`, :func:`planeray.simulate_stack`).

Outside a notebook the library is quiet (a script's pipes stay clean; the command line draws its own
bars).  In a Jupyter notebook (or Colab) a call left with ``progress=None`` shows its progress: rich's bar
in a widget when ipywidgets is installed, else a line of text every few seconds.  ``progress=True``
asks for that display anywhere, ``False`` for silence, a callable receives the units done.
"""

from __future__ import annotations

import builtins
import contextlib
import os
import sys
import time
from collections.abc import Callable, Iterator

__all__ = ["in_notebook", "progress_reporter"]

#: Seconds between two lines of the text display.
TEXT_INTERVAL_S = 2.0


def in_notebook() -> bool:
    """True inside a Jupyter kernel (notebook, JupyterLab, qtconsole), Colab or Databricks; False in a
    terminal's IPython and in plain Python (rich's rule, :attr:`rich.console.Console.is_jupyter`).

    Examples
    --------
    >>> in_notebook()
    False
    """
    get_ipython = getattr(builtins, "get_ipython", None)
    if get_ipython is None:
        return False
    shell = get_ipython()
    if shell is None:
        return False
    cls = type(shell)
    return (
        cls.__name__ == "ZMQInteractiveShell"
        or "google.colab" in f"{cls.__module__}.{cls.__qualname__}"
        or bool(os.getenv("DATABRICKS_RUNTIME_VERSION"))
    )


def _has_widgets() -> bool:
    try:
        import ipywidgets  # noqa: F401
    except ImportError:
        return False
    return True


@contextlib.contextmanager
def progress_reporter(progress, total: int, description: str) -> Iterator[Callable[[int], None] | None]:
    """The callback a long call reports its units done to (``advance(n)``), or None to stay quiet.

    Parameters
    ----------
    progress : callable, bool or None
        A callable is returned as it is; False and None outside a notebook: None; True, and None in a
        notebook (:func:`in_notebook`): a display of ``total`` units named ``description``.
    total : int
        Units of the whole call.
    description : str
        What runs, in words.

    Yields
    ------
    callable or None
    """
    if callable(progress):
        yield progress
        return
    if progress is False or (progress is None and not in_notebook()):
        yield None
        return
    if _has_widgets():
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        with Progress(TextColumn(description), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn()) as bar:
            task = bar.add_task(description, total=total)
            yield lambda n: bar.advance(task, n)
        return
    state = {"done": 0, "shown": time.monotonic()}
    start = state["shown"]

    def advance(n: int) -> None:
        state["done"] += n
        now = time.monotonic()
        if now - state["shown"] >= TEXT_INTERVAL_S or state["done"] >= total:
            state["shown"] = now
            _text_line(description, state["done"], total, now - start)

    try:
        yield advance
    finally:
        if state["done"] < total:
            _text_line(description, state["done"], total, time.monotonic() - start)


def _text_line(description: str, done: int, total: int, elapsed_s: float) -> None:
    left = f", ~{elapsed_s * (total - done) / done:.0f} s left" if 0 < done < total else ""
    print(f"{description}: {done}/{total} ({elapsed_s:.0f} s{left})", file=sys.stderr, flush=True)
