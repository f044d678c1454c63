"""The terminal: rich consoles and the progress bar shared by the command line and the demo."""

from __future__ import annotations

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

__all__ = ["console", "out", "progress_bar"]

#: Messages, progress and errors (stderr).
console = Console(stderr=True, soft_wrap=True)
#: Results (stdout).
out = Console(soft_wrap=True)


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
