"""The new user's harness: run a command with bad input in a folder of the user's own files, check the promises.

Used by ``tests/test_new_user*.py`` (issue 24): every bad input must give

* exit status 1 and exactly one ``error:`` line, without a traceback;
* no "unexpected" error (planeray recognized the problem and says what it is);
* the option as the user typed it (``--rows``), never the library's name (``projector_rows``);
* no data loss: every file of the user's folder has the same bytes afterwards, and
  nothing new appears beside them but what the case allows (nothing, by default).

``user_files(tmp_path)`` makes the user's folder: an image, a label mask, a video, a
JSON record, a calibration file, notes -- each written by "someone else" (no planeray mark).
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from planeray.cli import app

runner = CliRunner()


@functools.cache
def _command():
    """The click command of ``planeray``, built once (typer rebuilds it for every ``invoke``: 0.2 s each)."""
    import typer.main

    return typer.main.get_command(app)


#: The library's names that a message must never show instead of the option (a message may quote
#: neither; these are checked only when a case says which option it is about).
LIBRARY_NAMES = (
    "projector_rows",
    "shape[0]",
    "shape[1]",
    "mm_per_row",
    "ambient_e_per_us",
    "n_photons",
    "patch_px",
    "band_rows",
    "prefer",
    "frames_averaged",
)


def user_files(folder: Path) -> dict[str, Path]:
    """A user's own files, none of them written by planeray."""
    import tifffile
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    files = {
        "image": folder / "photo.png",
        "labels": folder / "labels.png",
        "tiff": folder / "scan.tif",
        "video": folder / "clip.tif",
        "json": folder / "notes.json",
        "npz": folder / "lines.npz",
        "csv": folder / "table.csv",
        "text": folder / "notes.txt",
    }
    Image.fromarray((np.arange(64 * 64).reshape(64, 64) % 251).astype(np.uint8)).save(files["image"])
    Image.fromarray(np.zeros((32, 32), np.uint8)).save(files["labels"])
    tifffile.imwrite(files["tiff"], np.arange(256, dtype=np.uint16).reshape(16, 16))
    tifffile.imwrite(files["video"], np.zeros((4, 8, 8), np.uint8), photometric="minisblack")
    files["json"].write_text(json.dumps({"experiment": "forearm 3", "notes": "do not lose"}))
    np.savez(files["npz"], lines=np.arange(5.0))
    files["csv"].write_text("a,b\n1,2\n")
    files["text"].write_text("three weeks of lab notes")
    return files


def snapshot(folder: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file below ``folder`` (hidden files included)."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def run_bad(args, *, folder: Path, needles=(), option: str | None = None, may_create=()) -> str:
    """Run ``planeray ARGS`` expected to fail; check every promise; return the error line.

    Parameters
    ----------
    args : sequence
        Command-line words (``str()`` is applied; ``{d}`` in a word is replaced by ``folder``).
    folder : Path
        The user's folder (its files must be untouched).
    needles : sequence of str
        Text the error line must contain.
    option : str, optional
        The option the input was wrong in, as typed: it must be named, and no library name with it.
    may_create : sequence of str
        Names (relative to ``folder``) the failed command may leave (default: none).
    """
    words = [str(a).replace("{d}", str(folder)) for a in args]
    before = snapshot(folder)
    res = runner.invoke(_command(), words)
    after = snapshot(folder)
    where = " ".join(words)
    assert res.exit_code == 1, f"{where}\nexit {res.exit_code}: {res.output}"
    lines = [line for line in res.output.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, f"{where}\n{res.output}"
    line = lines[0]
    assert "Traceback" not in res.output, f"{where}\n{res.output}"
    assert "unexpected" not in line, f"{where}\n{line}"
    for needle in needles:
        assert needle in line, f"{where}\nmissing {needle!r} in: {line}"
    if option is not None:
        assert option in line, f"{where}\nthe option {option} is not named in: {line}"
        for name in LIBRARY_NAMES:
            assert name not in line, f"{where}\nthe library's {name} instead of {option}: {line}"
    changed = [k for k in before if after.get(k) != before[k]]
    assert not changed, f"{where}\nchanged or removed the user's {changed}"
    created = sorted(set(after) - set(before) - set(may_create))
    assert not created, f"{where}\nleft {created} behind after failing"
    return line
