"""The terminal: rich consoles and the progress bar shared by the command line and the demo.

Results that a script may read (JSON, paths) go to stdout verbatim through
:func:`print_json` and :func:`print_verbatim`: never wrapped at the terminal's
width, never read as rich markup.  Print them after a progress bar has stopped:
while a bar is live on a terminal, rich routes ``sys.stdout`` through the bar's
console (stderr).
"""

from __future__ import annotations

import json
import sys

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

__all__ = ["console", "out", "progress_bar", "print_json", "print_verbatim"]

#: Messages, progress and errors (stderr).
console = Console(stderr=True, soft_wrap=True)
#: Results (stdout): long lines are left to the terminal (soft wrap), never cut, and text is
#: printed as it is (no markup: a path such as ``runs/[a]/x.zarr`` keeps its brackets; no emoji codes).
out = Console(soft_wrap=True, markup=False, emoji=False)


def progress_bar() -> Progress:
    """A rich progress bar (description, bar, n/total, elapsed, remaining) on :data:`console`."""
    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=False,
    )


def print_json(obj, *, indent: int | None = None) -> None:
    """Write ``obj`` as JSON to stdout verbatim (one line unless ``indent``; NumPy values and paths as plain JSON)."""
    from .io import jsonable

    sys.stdout.write(json.dumps(jsonable(obj, finite=False), indent=indent) + "\n")
    sys.stdout.flush()


def print_verbatim(text: str) -> None:
    """Write ``text`` and a newline to stdout as it is: no wrapping, no markup, no highlighting."""
    sys.stdout.write(f"{text}\n")
    sys.stdout.flush()
