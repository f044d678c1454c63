"""What every command group shares: one-line errors, stack loading, ``--pixel`` parsing, image saving.

The consoles (``console`` for messages on stderr, ``out`` for results on stdout) and
the progress bar live in :mod:`planeray._console`, shared with the demo.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import os
from pathlib import Path
from typing import Annotated

import typer
from rich.text import Text
from typer.core import TyperGroup

from .._console import console
from ..errors import InputError, PlanerayError, parameter_names
from ..io.atomic import check_not_an_input

#: The positional argument of every command that reads a stack.
StackArg = Annotated[Path, typer.Argument(help="Stack (Zarr) or import folder.")]


#: ``planeray --debug ...``: show the traceback of an error instead of one line.
DEBUG = {"enabled": False}

#: The exit stacks of the running commands: the locks :func:`_check_outputs` takes are held there.
_HELD: list[contextlib.ExitStack] = []


def error_line(exc: BaseException, options: dict | None = None) -> str:
    """One line for any failure: planeray's own errors as they are, file-system and other errors named.

    ``options`` maps the library's parameter names to the command's options as typed
    (``{"projector_rows": "--rows"}``): a message about ``projector_rows`` then names ``--rows``.
    """
    if isinstance(exc, PlanerayError):
        text = str(exc)
    elif isinstance(exc, OSError) and exc.errno is not None:
        name = errno.errorcode.get(exc.errno, str(exc.errno))
        where = f"{exc.filename}: " if exc.filename else ""
        text = f"{where}{exc.strerror or os.strerror(exc.errno)} [{name}]"
    elif isinstance(exc, (ValueError, FileNotFoundError)):
        text = str(exc)
    else:
        text = f"{type(exc).__name__}: {exc} (unexpected; run `planeray --debug ...` for the traceback)"
    text = " ".join(text.split())  # one line, whatever the cause put in it
    return _as_typed(text, options) if options else text


def _as_typed(text: str, options: dict) -> str:
    """Rename the library's parameters to the options the user typed, where a message names them.

    Only a parameter that a message is *about* is renamed: ``NAME must ...``, ``NAME = ...``,
    ``NAME=...`` and ``NAME[0] must ...`` (one element of a tuple option such as ``shape`` ->
    ``--size``) -- never a word of other text ("cannot read the vein mask: ..."), a device option
    (``-O size must ...``) nor a Python keyword argument quoted as such ("or overwrite=True").
    """
    import re

    for name in sorted(options, key=len, reverse=True):
        pattern = rf"(?<![\w\-.])(?<!-O ){re.escape(name)}(\[\d+\])?(?=( must\b| = |=(?!True\b|False\b)))"
        text = re.sub(pattern, options[name], text)
    return text


def option_spellings(fn) -> dict:
    """``{parameter: "--option"}`` for every option of a typer command function (its first long spelling)."""
    import typing

    hints = typing.get_type_hints(fn, include_extras=True)
    names = {}
    for param, hint in hints.items():
        for meta in getattr(hint, "__metadata__", ()):
            decls = getattr(meta, "param_decls", None)
            if decls is None or type(meta).__name__ != "OptionInfo":
                continue
            first = getattr(meta, "default", None)  # typer keeps the first spelling of Option("--a", "--b") here
            decls = ([first] if isinstance(first, str) and first.startswith("-") else []) + list(decls)
            longs = [d.split("/")[0] for d in decls if d.startswith("--")]
            names[param] = longs[0] if longs else "--" + param.replace("_", "-")
    return names


def _friendly_errors(fn=None, *, options: dict | None = None):
    """Turn every failure into one red line and exit status 1 (``--debug``: the traceback).

    Messages name the command's options as typed: every option of ``fn`` by its own
    name, plus ``options`` (library parameter -> option) where the library calls a
    value differently (``@_friendly_errors(options={"projector_rows": "--rows"})``).
    """
    if fn is None:
        return functools.partial(_friendly_errors, options=options)

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            # the locks of the command's outputs, until it returns; the library's messages name its options
            with contextlib.ExitStack() as held, parameter_names({**option_spellings(fn), **(options or {})}):
                _HELD.append(held)
                try:
                    return fn(*args, **kwargs)
                finally:
                    _HELD.remove(held)
        except (typer.Exit, typer.Abort, SystemExit):
            raise
        except KeyboardInterrupt:
            console.print(Text("interrupted", style="bold red"))
            raise typer.Exit(130) from None
        except Exception as exc:
            if DEBUG["enabled"]:
                raise
            spellings = {**option_spellings(fn), **(options or {})}
            console.print(
                Text("error: ", style="bold red") + Text(error_line(exc, spellings)), highlight=False, soft_wrap=True
            )
            raise typer.Exit(1) from None

    return wrapper


def _check_outputs(*outputs, overwrite: bool, inputs=()) -> None:
    """Refuse, before any work, outputs that may not be written; lock the others until the command ends.

    ``outputs``: ``(path, kind)`` pairs, ``kind`` as in :func:`planeray.io.atomic.planeray_output_kind`
    (or ``(path, kind, option)``: the option that names it in messages, default ``--out``);
    a None path is skipped.  Each output is refused when

    * it exists (without ``--overwrite``) or may not be replaced (:func:`~planeray.io.atomic.check_replaceable`);
    * it is named twice, or is one of the command's ``inputs`` (``(option, path)`` pairs), holds
      one or lies inside one, however the paths are spelled (:func:`_not_an_input`);
    * its folder cannot be written (read-only, full disk: :func:`~planeray.io.atomic.check_writable`);
    * another planeray run is writing it (:func:`~planeray.io.lock.output_lock`): the lock is
      then held by this command until it returns, so a second run is refused here.
    """
    from ..io.atomic import check_replaceable

    seen = set()
    pending = []
    for output in outputs:
        path, kind = output[:2]
        option = output[2] if len(output) > 2 else "--out"
        if path is None:
            continue
        _not_a_home(path, option)
        key = Path(path).resolve()
        if key in seen:
            raise ValueError(f"{path}: named twice as an output")
        seen.add(key)
        _not_an_input(path, inputs, option=option)
        check_replaceable(path, overwrite=overwrite, kind=kind)
        pending.append(path)
    _claim(*pending)


def _claim(*paths) -> None:
    """Before any work: each output's folder can be written, and no other run writes it (its lock, held).

    The lock is held until the running command returns (:func:`_friendly_errors`).
    """
    from ..io.atomic import check_writable
    from ..io.lock import output_lock

    for path in paths:
        check_writable(path)
        if _HELD:
            _HELD[-1].enter_context(output_lock(path, on_stale=_note))


def _not_a_home(path, option: str = "--out") -> None:
    """Refuse, with or without ``--overwrite``, the current folder, one of its parents, the home folder or a root."""
    from ..io.atomic import is_protected

    if is_protected(Path(path)):
        raise InputError(
            f"{option} {path}: is the current folder, one of its parents or the home folder; name a new output "
            "inside it (e.g. {option} out/)".replace("{option}", option)
        )


def _note(text: str) -> None:
    console.print(Text("note: ", style="yellow") + Text(text), highlight=False, soft_wrap=True)


def note(text: str) -> None:
    """A library workflow's note on the console: ``note: TEXT``, printed as it is (no markup)."""
    console.print(f"note: {text}", highlight=False, markup=False)


@contextlib.contextmanager
def stage_bars():
    """``progress(stage, done, total)`` for a library workflow: one progress bar per stage (total None: a status
    line, shown while the stage runs).

    The bars stop when the block ends: print results after it (while a bar is live, stdout goes to its console).
    """
    from .._console import progress_bar

    with progress_bar() as bar:
        tasks, spinners = {}, []

        def stop_spinners() -> None:  # an uncounted stage shows while it runs, like a status line, then goes
            for task in spinners:
                bar.remove_task(task)
            spinners.clear()

        def progress(stage: str, done: int, total: int | None = None) -> None:
            if stage not in tasks:
                stop_spinners()
                tasks[stage] = bar.add_task(stage, total=total)
                if total is None:
                    spinners.append(tasks[stage])
            if tasks[stage] in bar.task_ids:
                bar.update(tasks[stage], completed=done, total=total)

        try:
            yield progress
        finally:
            stop_spinners()


#: Refuse an output that is or holds an input (:func:`planeray.io.atomic.check_not_an_input`), named ``--out``.
_not_an_input = functools.partial(check_not_an_input, option="--out")


def _load_stack(path: Path):
    """A native Zarr stack or a captured import folder, read lazily."""
    from ..io import read_stack

    return read_stack(path)


def _parse_pixel(text: str) -> tuple[int, int]:
    """``"ROW,COL"`` or ``"ROW COL"`` -> ``(row, col)``."""
    parts = text.replace(",", " ").split()
    if len(parts) != 2 or not all(p.lstrip("-").isdigit() for p in parts):
        raise ValueError(f"--pixel expects ROW COL (two integers), got {text!r}")
    return int(parts[0]), int(parts[1])


#: Commands whose ``--size H W`` also takes one number for a square image (``view``, ``video``: a scene).
SQUARE_SIZE_COMMANDS = ("view", "video")


def _is_int(word: str) -> bool:
    return word.lstrip("-").isdigit()


def _join_pixel_args(argv: list[str]) -> list[str]:
    """Let ``--pixel ROW COL`` (two words) through typer, which takes one value per option."""
    joined, i = [], 0
    while i < len(argv):
        if argv[i] == "--pixel" and i + 2 < len(argv) and _is_int(argv[i + 1]) and _is_int(argv[i + 2]):
            joined += ["--pixel", f"{argv[i + 1]},{argv[i + 2]}"]
            i += 3
        else:
            joined.append(argv[i])
            i += 1
    return joined


def _square_size_args(argv: list[str]) -> list[str]:
    """``view``/``video --size N`` (one number) is the square ``--size N N``."""
    words = [a for a in argv if not a.startswith("-")]
    if not words or words[0] not in SQUARE_SIZE_COMMANDS:
        return list(argv)
    out, i = [], 0
    while i < len(argv):
        if argv[i] == "--size" and i + 1 < len(argv) and _is_int(argv[i + 1]):
            two = i + 2 < len(argv) and _is_int(argv[i + 2])
            out += argv[i : i + 3] if two else ["--size", argv[i + 1], argv[i + 1]]
            i += 3 if two else 2
        else:
            out.append(argv[i])
            i += 1
    return out


class PlanerayGroup(TyperGroup):
    """The root command: reads ``view``/``video --size N`` as ``--size N N`` (:func:`_square_size_args`)."""

    def parse_args(self, ctx, args):
        return super().parse_args(ctx, _square_size_args([str(a) for a in args]))


def _save_image(image, path: Path, scale_to: float | None = None) -> Path:
    """PNG: display-scaled 8-bit preview; TIFF: the values as 16-bit codes (:func:`planeray.figures.save_image`)."""
    from ..figures import save_image

    return save_image(image, path, scale_to=scale_to)
