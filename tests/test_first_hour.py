"""A notebook user's first hour: short reprs, no private parameters in public signatures, progress in a notebook."""

from __future__ import annotations

import builtins
import inspect
import os
import subprocess
import sys

import numpy as np
import pytest

import planeray as pr
from planeray import _progress
from planeray.io import read_stack, write_stack
from planeray.stack import Stack
from planeray.transport import SparseEntries, Transport


def _stack(n=85, h=8, w=8):
    rng = np.random.default_rng(0)
    delays = np.linspace(-3000.0, 3000.0, n)
    return Stack(rng.random((n, h, w), np.float32), delays, np.full(n, 600.0), 54000.0, projector_rows=720)


def test_stack_repr_is_a_summary_not_its_arrays():
    stack = _stack()
    text = repr(stack)
    assert len(text) < 300, text  # was 7.7 kB for 8 x 8 (the arrays printed)
    for part in ("(85, 8, 8)", "float32", "85 images", "[-3000 .. 3000]", "projector_rows=720", "54000"):
        assert part in text, (part, text)
    assert f"excluded={int(stack.excluded.sum())}" in text
    big = _stack(n=9, h=256, w=256)
    assert len(repr(big)) < 300  # independent of the size


def test_lazy_stack_repr_says_lazy(tmp_path):
    write_stack(_stack(n=5), tmp_path / "s.zarr")
    text = repr(read_stack(tmp_path / "s.zarr"))
    assert len(text) < 300 and "(5, 8, 8) float32 lazy" in text, text


def test_transport_repr_is_a_summary_not_its_arrays():
    T = Transport(
        np.ones((8, 8, 21), np.float32),
        np.arange(-10, 11),
        pr.RowGeometry(8, 720) if hasattr(pr, "RowGeometry") else None,
        SparseEntries([1, 2], [3, 4], [100, 200], [0.5, 0.25]),
    )
    text = repr(T)
    assert len(text) < 200, text
    for part in ("(8, 8, 21)", "float32", "[-10 .. 10]", "8 camera rows", "2 entries"):
        assert part in text, (part, text)


def test_no_public_signature_shows_a_private_parameter():
    seen = 0
    for name in dir(pr):
        obj = getattr(pr, name)
        if name.startswith("_") or not callable(obj):
            continue
        try:
            params = inspect.signature(obj).parameters
        except (TypeError, ValueError):
            continue
        seen += 1
        assert not [p for p in params if p.startswith("_")], name
    assert seen > 20


def test_the_kill_hook_still_works_though_hidden(tmp_path):
    from planeray.resumable import partial_path

    stack = _small()
    out = tmp_path / "t.zarr"
    got = pr.demultiplex_to_store(stack, out, chunk_rows=4, _stop_after=1)
    assert got == partial_path(out) and not out.exists()


# ---------------------------------------------------------------- progress in a notebook
class ZMQInteractiveShell:  # the name of Jupyter's kernel shell
    pass


class TerminalInteractiveShell:  # IPython in a terminal
    pass


@pytest.mark.parametrize(("shell", "expected"), [(ZMQInteractiveShell, True), (TerminalInteractiveShell, False)])
def test_notebook_detection(monkeypatch, shell, expected):
    assert not _progress.in_notebook()  # plain Python (pytest)
    monkeypatch.setattr(builtins, "get_ipython", lambda: shell(), raising=False)
    assert _progress.in_notebook() is expected
    monkeypatch.setattr(builtins, "get_ipython", lambda: None, raising=False)
    assert not _progress.in_notebook()


def _small():
    scene = pr.make_scene("diffuse_plane", (8, 8), projector_rows=16, seed=0)
    return pr.simulate_stack(scene, pr.quick_sweep(), seed=0, progress=False)


def test_demultiplex_reports_progress_in_a_notebook(monkeypatch, capsys):
    stack = _small()
    capsys.readouterr()
    monkeypatch.setattr(builtins, "get_ipython", lambda: ZMQInteractiveShell(), raising=False)
    monkeypatch.setattr(_progress, "_has_widgets", lambda: False)  # the text display (no ipywidgets)
    pr.demultiplex(stack, chunk_rows=2)
    err = capsys.readouterr().err
    assert "demultiplexing 8 rows: 8/8" in err, err
    pr.demultiplex(stack, chunk_rows=2, progress=False)
    assert capsys.readouterr().err == ""
    rows = []
    pr.demultiplex(stack, chunk_rows=2, progress=rows.append)  # a callable: the rows of each chunk
    assert sum(rows) == 8 and capsys.readouterr().err == ""


def test_library_stays_quiet_in_pipes(tmp_path):
    code = (
        "import planeray as pr\n"
        "scene = pr.make_scene('diffuse_plane', (8, 8), projector_rows=16, seed=0)\n"
        "stack = pr.simulate_stack(scene, pr.quick_sweep(), seed=0)\n"
        "pr.demultiplex(stack, chunk_rows=2)\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout == "" and run.stderr == "", (run.stdout, run.stderr)
