"""What the folder-writing workflows share: progress by stage, notes, and the checks before any work.

A workflow (:func:`~planeray.experiments.materials_folders.fit_materials`,
:func:`~planeray.experiments.skin_depth_folder.vein_depths`, ...)
reports its progress as ``progress(stage, done, total)``: ``stage`` a short description (a new
one starts a new stage), ``done`` the units finished in it, ``total`` its units (None: not
counted).  Its notes -- an assumption made, a table traced first -- go to ``note(text)``, by
default a :class:`UserWarning`.
"""

from __future__ import annotations

import warnings
from pathlib import Path

__all__ = ["Stages", "check_folder_output"]


class Stages:
    """The ``progress`` and ``note`` callbacks of a workflow, with counters for callbacks that count by increments."""

    def __init__(self, progress=None, note=None):
        self._progress = progress
        self._note = note

    def stage(self, name: str, total: int | None = None):
        """Start stage ``name``; returns ``advance(k)``, which adds ``k`` units done to it."""
        done = [0]
        if self._progress is not None:
            self._progress(name, 0, total)

        def advance(k: int = 1) -> None:
            done[0] += int(k)
            if self._progress is not None:
                self._progress(name, done[0], total)

        return advance

    def note(self, text: str) -> None:
        """Pass on a note (without a ``note`` callback: a :class:`UserWarning`)."""
        if self._note is not None:
            self._note(text)
        else:
            warnings.warn(text, UserWarning, stacklevel=3)


def check_folder_output(out_dir, inputs, *, overwrite: bool, kind: str, name: str = "out_dir") -> Path:
    """Before any work: the output ``out_dir`` may be written (planeray's own, or new) and is none of ``inputs``.

    ``inputs``: ``(name, path)`` pairs as messages name them (None paths skipped); ``name``: the
    output's parameter.
    """
    from ..errors import parameter_name
    from ..io.atomic import check_not_an_input, check_replaceable, check_writable

    out_dir = Path(out_dir)
    check_not_an_input(out_dir, inputs, option=parameter_name(name))
    check_replaceable(out_dir, overwrite=overwrite, kind=kind)
    check_writable(out_dir)
    return out_dir
