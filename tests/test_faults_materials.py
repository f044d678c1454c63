"""Fault injection for the writing commands of ``planeray materials`` (issue 24).

Every writing command -- ``simulate`` (a capture folder), ``train`` (a model file), ``predict``
(a segmentation PNG/TIFF) and ``report`` (a report folder) -- against: an existing file of the
user's, an existing planeray output (replaced only with ``--overwrite``), a read-only folder, a
full disk, a run killed mid-way, and a run started again after a killed one (none of these
commands resumes: the next run cleans the dead run's temporaries and writes the whole result).
The table of what happens, cell by cell, is in the README ("Material recognition").
"""

from __future__ import annotations

import errno
import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import test_faults
from planeray.cli import app

#: what these tests check is what happens to files, not what the figures show (conftest.py)
pytestmark = pytest.mark.usefixtures("figures_not_drawn")

failing_folder = test_faults.failing_folder  # the fixture: writes under a folder fail with an OSError
runner = CliRunner()
SIZE = 32
TINY_GRID = {"C": (10.0,), "gamma_scale": (1.0,)}


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_line_error(res, *needles):
    assert res.exit_code == 1, res.output
    lines = [line for line in res.output.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    assert "unexpected" not in lines[0], lines[0]
    for needle in needles:
        assert str(needle) in lines[0], (needle, lines[0])
    return lines[0]


def digest(path: Path) -> str:
    """SHA-256 of a file, or of every file below a folder."""
    if path.is_file():
        return hashlib.sha256(path.read_bytes()).hexdigest()
    h = hashlib.sha256()
    for p in sorted(path.rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(path)).encode() + p.read_bytes())
    return h.hexdigest()


def leftovers(folder: Path) -> list[str]:
    """Hidden temporaries or backups planeray may leave beside its outputs."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


@pytest.fixture(autouse=True)
def tiny_grid(monkeypatch):
    """One SVM fit per fold: train and report run in seconds."""
    monkeypatch.setattr("planeray.materials.training.DEFAULT_PARAM_GRID", TINY_GRID)


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """A capture, a model trained on it and a segmentation, all written by planeray."""
    root = tmp_path_factory.mktemp("materials_faults")
    cap = root / "cap"
    assert invoke("materials", "simulate", "--out", cap, "--size", SIZE, SIZE).exit_code == 0
    import planeray.io as pio
    from planeray.materials import read_label_image, train_model
    from planeray.materials.model import MaterialModel  # noqa: F401  (the type saved)

    stack = pio.read_stack(cap / "stack.zarr")
    model = train_model(
        [stack], [read_label_image(cap / "labels.png")], ignore_classes=(6,), param_grid=TINY_GRID, max_per_class=60
    )
    model.save(root / "model.zip")
    return {"cap": cap, "stack": cap / "stack.zarr", "labels": cap / "labels.png", "model": root / "model.zip"}


def command(name: str, out: Path, env, *extra):
    """The command line of each writing command, writing ``out``."""
    return {
        "simulate": ("materials", "simulate", "--out", out, "--size", 16, 16),
        "train": ("materials", "train", env["stack"], "--labels", env["labels"], "--ignore-class", 6, "--out", out),
        "predict": ("materials", "predict", env["model"], env["stack"], "--out", out),
        "report": ("materials", "report", "--out", out, "--size", 16, "--quick"),
    }[name] + tuple(extra)


OUTPUT = {"simulate": "cap", "train": "model.zip", "predict": "seg.png", "report": "rep"}
COMMANDS = sorted(OUTPUT)


# ----------------------------------------------------------------------------- an existing file of the user's
@pytest.mark.parametrize("name", COMMANDS)
@pytest.mark.parametrize("overwrite", [False, True], ids=["plain", "--overwrite"])
def test_an_existing_user_file_is_never_replaced(name, overwrite, env, tmp_path):
    out = tmp_path / OUTPUT[name]
    if name in ("simulate", "report"):  # a folder of the user's at the output
        out.mkdir()
        (out / "notes.txt").write_text("three weeks of lab notes")
    elif name == "train":
        out.write_bytes(b"PK\x05\x06" + bytes(18))  # the user's own (empty) zip
    else:
        from PIL import Image

        Image.fromarray(np.arange(32 * 32, dtype=np.uint8).reshape(32, 32)).save(out)  # the user's own PNG
    before = digest(out)
    res = invoke(*command(name, out, env, *(["--overwrite"] if overwrite else [])))
    one_line_error(res, "planeray did not write" if overwrite and name != "train" else "")
    if overwrite and name == "train":
        assert "not a planeray materials model" in res.output
    if not overwrite:
        assert "already exists" in res.output
    assert digest(out) == before and leftovers(tmp_path) == []


def test_the_ground_truth_labels_are_never_the_output(env, tmp_path):
    """``--labels lab.png --out lab.png``, however spelled, is refused before anything is read."""
    labels = tmp_path / "lab.png"
    labels.write_bytes(env["labels"].read_bytes())
    before = digest(labels)
    for spelled in (labels, tmp_path / "." / "lab.png", Path(os.path.relpath(labels))):
        for extra in ([], ["--overwrite"]):
            res = invoke(
                "materials", "predict", env["model"], env["stack"], "--labels", labels, "--out", spelled, *extra
            )
            one_line_error(res, "also an input (--labels)")
    assert digest(labels) == before


# ----------------------------------------------------------------------------- an existing planeray output
@pytest.mark.parametrize("name", COMMANDS)
def test_an_existing_planeray_output_is_replaced_only_with_overwrite(name, env, tmp_path):
    out = tmp_path / OUTPUT[name]
    assert invoke(*command(name, out, env)).exit_code == 0
    first = digest(out)
    one_line_error(invoke(*command(name, out, env)), "already exists")
    assert digest(out) == first
    extra = ("--seed", 3) if name == "simulate" else ("--unclassified-below", 0.5) if name == "predict" else ()
    res = invoke(*command(name, out, env, "--overwrite", *extra))
    assert res.exit_code == 0, res.output
    assert leftovers(tmp_path) == []
    if name in ("simulate", "predict"):
        assert digest(out) != first  # replaced by the new result
    # A planeray result of another kind is never replaced by this one.
    other = {"simulate": "report", "report": "simulate", "predict": "labels", "train": None}[name]
    if other == "labels":
        target = tmp_path / "labels.png"
        target.write_bytes(env["labels"].read_bytes())
        one_line_error(invoke(*command(name, target, env, "--overwrite")), "not a segmentation")
    elif other:  # a folder planeray wrote, of the other kind (recognized by its planeray.json)
        target = tmp_path / f"other_{name}"
        target.mkdir()
        fmt = {"report": "planeray-materials-report", "simulate": "planeray-materials-capture"}[other]
        (target / "planeray.json").write_text(f'{{"format": "{fmt}"}}')
        one_line_error(invoke(*command(name, target, env, "--overwrite")), "will not replace")


# ----------------------------------------------------------------------------- a read-only folder, a full disk
@pytest.mark.parametrize("name", COMMANDS)
def test_a_read_only_folder_gives_one_line_and_leaves_nothing(name, env, tmp_path, failing_folder):
    target = tmp_path / "ro"
    target.mkdir()
    failing_folder(target, errno.EROFS)
    res = invoke(*command(name, target / OUTPUT[name], env))
    one_line_error(res, os.strerror(errno.EROFS), target)
    assert list(target.iterdir()) == []


FULL_DISK = {
    # the writer of each command, made to fail as a full disk does
    "simulate": "planeray.experiments.materials.write_stack",
    "train": "zipfile.ZipFile.writestr",  # (of the model file; skops's own zip is in memory)
    "predict": "PIL.Image.Image.save",
    "report": "planeray.materials.model.MaterialModel.save",
}


@pytest.mark.parametrize("name", COMMANDS)
def test_a_full_disk_gives_one_line_and_leaves_nothing(name, env, tmp_path, monkeypatch):
    import zipfile

    real_writestr = zipfile.ZipFile.writestr

    def full(*args, **kwargs):
        if name == "train" and getattr(args[0], "filename", None) is None:  # an in-memory zip: no disk
            return real_writestr(*args, **kwargs)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(FULL_DISK[name], full)
    res = invoke(*command(name, tmp_path / OUTPUT[name], env))
    one_line_error(res, "No space left on device [ENOSPC]", tmp_path / OUTPUT[name])
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- killed mid-run, and run again
KILL = {
    # a step in the middle of each command's work
    "simulate": "planeray.experiments.materials.write_label_image",  # the stack written, the labels not yet
    "train": "zipfile.ZipFile.writestr",  # the model file half written
    "predict": "PIL.Image.Image.save",  # the PNG half written
    "report": "planeray.experiments.materials.capture_transport",  # a model saved, the transport not yet
}


@pytest.mark.parametrize("name", COMMANDS)
def test_a_run_killed_mid_way_leaves_no_half_written_output(name, env, tmp_path, monkeypatch):
    def killed(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(KILL[name], killed)
    res = invoke(*command(name, tmp_path / OUTPUT[name], env))
    assert res.exit_code == 130 and "interrupted" in res.output, res.output
    assert list(tmp_path.iterdir()) == []  # no output, no temporary


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


@pytest.mark.parametrize("name", COMMANDS)
def test_a_run_after_a_killed_one_cleans_its_temporaries_and_writes_everything(name, env, tmp_path):
    """None of these commands resumes: a run killed with ``kill -9`` leaves a temporary (with its process id)
    that the next run to the same output removes, then it writes the whole result."""
    out = tmp_path / OUTPUT[name]
    stale = (
        tmp_path
        / f".{out.name}.tmp-{_dead_pid()}-0123456789abcdef{'' if name in ('simulate', 'report') else out.suffix}"
    )
    if name in ("simulate", "report"):
        stale.mkdir()
        (stale / "half.bin").write_bytes(b"\0" * 100)
    else:
        stale.write_bytes(b"half a file")
    mine = tmp_path / f".{out.name}.tmp-{os.getpid()}-live"  # a live process's temporary: kept
    mine.write_text("in use")
    res = invoke(*command(name, out, env))
    assert res.exit_code == 0, res.output
    assert not stale.exists() and mine.exists() and out.exists()
    assert leftovers(tmp_path) == [mine.name]


# ----------------------------------------------------------------------------- a second run at the same time
@pytest.mark.parametrize("name", COMMANDS)
def test_a_second_run_at_the_same_time_is_refused_in_one_line(name, env, tmp_path):
    """Another planeray process is writing the output (it holds its lock): refused before any work, nothing touched."""
    from planeray.io.lock import lock_holder, lock_path
    from test_faults_concurrency import Holder

    out = tmp_path / OUTPUT[name]
    other = Holder(lock_path(out))
    try:
        one_line_error(invoke(*command(name, out, env)), f"another planeray run (pid {other.pid}) is writing it")
        assert not out.exists() and leftovers(tmp_path) == [lock_path(out).name]
        assert lock_holder(out)["pid"] == other.pid
    finally:
        other.release()
