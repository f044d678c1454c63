"""Fault injection for the capture, calibration, rendering and analysis commands (issue 24).

Every writing command of the area x {existing user file, existing planeray output, read-only
folder, full disk, killed mid-run, resumed}: the user's files are never replaced, planeray's
only with ``--overwrite``, a failing disk gives one line and leaves nothing, a run killed at the
moment its result would appear leaves no half-written output and no temporary, and the
resumable commands (``acquire``, ``render``, ``render-examples``) resume saying so.  The
``calibrate ... --write`` commands update a user's ``acquisition.json`` in place: every field
of the user's is kept, the values a calibration replaces are kept under
``calibration.replaced``.  Cells already exercised elsewhere are named in the README's table
(``tests/test_faults.py``: simulate, demux, export, import on a full disk; demux resuming).
"""

from __future__ import annotations

import errno
import importlib.util
import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from planeray.cli import app
from planeray.io.lock import lock_holder, lock_path
from planeray.io.marks import file_mark
from test_faults import failing_folder  # noqa: F401  (the fixture: writes under a folder fail)

#: what these tests check is what happens to files, not what the figures show (conftest.py)
pytestmark = pytest.mark.usefixtures("figures_not_drawn")

runner = CliRunner()
HAS_MITSUBA = importlib.util.find_spec("mitsuba") is not None


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_line_error(res, *needles) -> str:
    assert res.exit_code == 1, res.output
    lines = [line for line in res.output.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    for needle in needles:
        assert str(needle) in lines[0], (needle, lines[0])
    return lines[0]


def temporaries(folder: Path) -> list[str]:
    """planeray's temporaries and backups anywhere below ``folder`` (never left behind)."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob(".*") if ".tmp-" in p.name or ".bak-" in p.name)


def snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """planeray's own inputs: a stack (the 27-image quick sweep), its transport, its export folder, a line sweep."""
    d = tmp_path_factory.mktemp("faults_ops")
    for args in (
        ("simulate", "wax", "--size", 24, 20, "--projector-rows", 90, "--sweep", "quick", "--out", d / "s.zarr"),
        ("demux", d / "s.zarr", "--out", d / "T.zarr"),
        ("export", d / "s.zarr", "--out", d / "exp"),
        ("calibrate", "simulate-lines", "--out", d / "lines.npz"),
    ):
        res = invoke(*args)
        assert res.exit_code == 0, res.output
    return {"S": d / "s.zarr", "T": d / "T.zarr", "X": d / "exp", "L": d / "lines.npz"}


@pytest.fixture(autouse=True)
def _tiny_study(monkeypatch):
    """``study demux --quick`` on two values per axis: what it writes is checked here, not what it finds."""
    import planeray.experiments.study as study

    quick = study.grids(True)
    monkeypatch.setattr(study, "grids", lambda q=False: {k: v[-2:] for k, v in quick.items()})


@pytest.fixture(autouse=True)
def _own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("PLANERAY_CACHE", str(tmp_path / "cache"))  # mc profile: never the user's cache


@dataclass
class Writer:
    """A writing command: its arguments (``d``: the output folder) and the outputs it writes."""

    args: object
    outputs: object
    overwrite: bool = True  # takes --overwrite
    all_or_nothing: bool = True  # a failed run leaves none of the outputs it creates
    mitsuba: bool = False
    slow: bool = False
    marks: dict = field(default_factory=dict)


def _files(*names):
    return lambda d: [d / n for n in names]


WRITERS = {
    "calibrate simulate-lines": Writer(
        lambda d, i: ("calibrate", "simulate-lines", "--out", d / "l.npz"), _files("l.npz")
    ),
    "calibrate lines --write": Writer(
        lambda d, i: ("calibrate", "lines", i["L"], "--write", d / "acquisition.json"),
        _files("acquisition.json"),
        overwrite=False,
    ),
    "calibrate delay-zero --write": Writer(
        lambda d, i: ("calibrate", "delay-zero", "--simulate", "--write", d / "acquisition.json"),
        _files("acquisition.json"),
        overwrite=False,
    ),
    "acquire": Writer(
        lambda d, i: ("acquire", "--size", 16, 16, "--sweep", "quick", "--out", d / "a.zarr"), _files("a.zarr")
    ),
    "render": Writer(
        lambda d, i: (
            ("render", "mirror_ball", "--size", 8, 8, "--rows", 16, "--spp", 2, "--batch-spp", 1)
            + ("--out", d / "R.zarr")
        ),
        _files("R.zarr"),
        mitsuba=True,
    ),
    "render-examples": Writer(
        lambda d, i: (
            ("render-examples", "--scene", "mirror_ball", "--size", 8, "--rows", 16, "--spp", 1) + ("--out", d / "ex")
        ),
        _files("ex/mirror_ball.zarr", "ex/mirror_ball.png", "ex/render_examples.json"),
        mitsuba=True,
        all_or_nothing=False,
    ),
    "simulate": Writer(
        lambda d, i: (
            ("simulate", "diffuse_plane", "--size", 16, 16, "--sweep", "quick", "--out", d / "s.zarr")
            + ("--truth", d / "t.zarr")
        ),
        _files("s.zarr", "t.zarr"),
        all_or_nothing=False,
    ),
    "contact-sheet": Writer(lambda d, i: ("contact-sheet", i["S"], "--out", d / "c.png"), _files("c.png")),
    "profiles": Writer(
        lambda d, i: ("profiles", i["S"], "--pixel", "3,3", "--out", d / "p.png", "--csv", d / "p.csv"),
        _files("p.png", "p.csv"),
    ),
    "synth": Writer(lambda d, i: ("synth", i["T"], "--epipolar", "--out", d / "e.tif"), _files("e.tif")),
    "figure": Writer(
        lambda d, i: ("figure", "fig8", "--size", 16, "--out", d / "f"),
        _files("f/fig8_contact_sheet.png", "f/fig8.json"),
        all_or_nothing=False,
        slow=True,
    ),
    "export": Writer(lambda d, i: ("export", i["S"], "--out", d / "x"), _files("x")),
    "import": Writer(lambda d, i: ("import", i["X"], "--out", d / "i.zarr"), _files("i.zarr")),
    "demux": Writer(lambda d, i: ("demux", i["S"], "--out", d / "D.zarr"), _files("D.zarr")),
    "emulate": Writer(
        lambda d, i: ("emulate", "diffuse_plane", "--size", 16, 16, "--out", d / "e"),
        _files(
            *(f"e/{k}{x}" for k in ("emulated", "synchronized", "truth") for x in (".png", ".tif")), "e/emulation.json"
        ),
    ),
    "separate direct-global": Writer(
        lambda d, i: ("separate", "direct-global", "diffuse_plane", "--size", 16, 16, "--out", d / "g"),
        _files("g/direct_global.json", "g/nayar_direct.png", "g/epipolar.tif"),
    ),
    "mc profile": Writer(
        lambda d, i: ("mc", "profile", "--photons", 300, "--rows", 3, "--out", d / "m.csv", "--plot", d / "m.png"),
        _files("m.csv", "m.json", "m.png"),
    ),
    "study demux": Writer(
        lambda d, i: ("study", "demux", "--quick", "--seeds", 1, "--provider", "dipole", "--out", d / "st"),
        _files("st/study.json", "st/fig5_reconstruction.csv", "st/regularization_sweep.png"),
        all_or_nothing=False,
        slow=True,
    ),
}


def _params(*, slow_too=True, resumable=False):
    out = []
    for name, w in WRITERS.items():
        marks = []
        if w.mitsuba:
            marks.append(pytest.mark.skipif(not HAS_MITSUBA, reason="needs mitsuba"))
        if w.slow and slow_too:
            marks.append(pytest.mark.slow)
        out.append(pytest.param(name, marks=marks, id=name))
    return out


def _user_file(path: Path) -> None:
    """Write a file of the user's (no planeray mark) at ``path``, of the type its extension says."""
    import tifffile
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    suffix = path.suffix.lower()
    if suffix == ".png":
        Image.fromarray(np.full((8, 8), 77, np.uint8)).save(path)
    elif suffix in (".tif", ".tiff"):
        tifffile.imwrite(path, np.arange(64, dtype=np.uint16).reshape(8, 8))
    elif suffix == ".npz":
        np.savez(path, mine=np.arange(3.0))
    elif suffix == ".json":
        path.write_text(json.dumps({"experiment": "forearm 3", "notes": "do not lose"}))
    elif suffix == ".csv":
        path.write_text("a,b\n1,2\n")
    else:  # a store or folder: a folder of the user's
        path.mkdir()
        (path / "notes.txt").write_text("three weeks of lab notes")


# ---------------------------------------------------------------------------- 1. existing user file
@pytest.mark.parametrize("command", _params(slow_too=False))
def test_an_existing_user_file_is_never_replaced(command, inputs, tmp_path):
    w = WRITERS[command]
    d = tmp_path / "out"
    d.mkdir()
    target = w.outputs(d)[-1]  # the last output: for folders of results, one of the files inside
    _user_file(target)
    (d / "mine.txt").write_text("keep")
    before = snapshot(d)
    args = w.args(d, inputs)
    if command.endswith("--write"):  # the calibration goes INTO the user's acquisition.json, keeping it
        res = invoke(*args)
        assert res.exit_code == 0, res.output
        after = json.loads(target.read_text())
        assert after["experiment"] == "forearm 3" and after["notes"] == "do not lose"
        assert list(after)[:2] == ["experiment", "notes"]  # the user's fields, in their order
        assert (d / "mine.txt").read_text() == "keep" and temporaries(d) == []
        return
    one_line_error(invoke(*args), target.name, "already exists")
    assert snapshot(d) == before and temporaries(d) == []
    if w.overwrite:
        one_line_error(invoke(*args, "--overwrite"), target.name, "planeray did not write")
        assert snapshot(d) == before and temporaries(d) == []


# ---------------------------------------------------------------------------- 2. existing planeray output
@pytest.mark.parametrize("command", _params())
def test_an_existing_planeray_output_is_replaced_only_with_overwrite(command, inputs, tmp_path):
    w = WRITERS[command]
    d = tmp_path / "out"
    args = w.args(d, inputs)
    res = invoke(*args)
    assert res.exit_code == 0, res.output
    outputs = w.outputs(d)
    for path in outputs:  # every single file planeray wrote carries its mark (the user's acquisition.json: none)
        assert path.exists(), path
        if path.is_file() and not command.endswith("--write"):
            assert file_mark(path) is not None, path
    if command.endswith("--write"):  # updated in place: a second calibration records what it replaced
        first = json.loads(outputs[0].read_text())
        res = invoke(*args)
        assert res.exit_code == 0, res.output
        second = json.loads(outputs[0].read_text())
        changed = {k: v for k, v in first.items() if k != "calibration" and second.get(k) != v}
        assert second["calibration"].get("replaced", {}) == changed
        return
    before = snapshot(d)
    line = one_line_error(invoke(*args), "already exists", "--overwrite")
    assert any(p.name in line for p in outputs)
    assert snapshot(d) == before and temporaries(d) == []
    res = invoke(*args, "--overwrite")
    assert res.exit_code == 0, res.output
    assert all(p.exists() for p in outputs) and temporaries(d) == []


# ---------------------------------------------------------------------------- 3, 4. read-only folder, full disk
@pytest.mark.parametrize("code", [errno.EROFS, errno.ENOSPC], ids=["read-only", "disk-full"])
@pytest.mark.parametrize("command", _params())
def test_a_failing_disk_gives_one_line_and_leaves_nothing(command, code, inputs, tmp_path, failing_folder):  # noqa: F811
    w = WRITERS[command]
    d = tmp_path / "out"
    d.mkdir()
    acq = d / "acquisition.json"
    if command.endswith("--write"):  # the user's calibration file, to be updated
        acq.write_text(json.dumps({"bit_depth": 12, "lines_per_second": 50000.0}))
    before = snapshot(d)
    failing_folder(d, code)
    line = one_line_error(invoke(*w.args(d, inputs)), os.strerror(code))
    assert str(d) in line
    assert snapshot(d) == before and temporaries(d) == []
    assert sorted(p.name for p in d.iterdir()) == (["acquisition.json"] if acq.exists() else [])


# ---------------------------------------------------------------------------- 5. killed mid-run
@pytest.fixture
def kill_when_a_result_appears(monkeypatch):
    """Ctrl-C at the moment the ``n``-th of ``outputs`` is renamed into place (after its temporary is written).

    Only the renames of the command's own outputs are intercepted (Zarr's chunk writes, in its
    own threads, are left alone).
    """

    def arm(outputs, n: int = 1):
        targets = {Path(p).resolve() for p in outputs}
        seen = []
        real_rename, real_replace = os.rename, os.replace

        def guard(real):
            def fake(src, dst, *args, **kwargs):
                if Path(os.fsdecode(dst)).resolve() in targets:
                    seen.append(dst)
                    if len(seen) == n:
                        raise KeyboardInterrupt
                return real(src, dst, *args, **kwargs)

            return fake

        monkeypatch.setattr(os, "rename", guard(real_rename))
        monkeypatch.setattr(os, "replace", guard(real_replace))
        return seen

    return arm


@pytest.mark.parametrize("command", _params())
def test_a_run_killed_as_its_result_appears_leaves_nothing_half_written(
    command, inputs, tmp_path, kill_when_a_result_appears
):
    w = WRITERS[command]
    d = tmp_path / "out"
    d.mkdir()
    acq = d / "acquisition.json"
    if command.endswith("--write"):
        acq.write_text(json.dumps({"bit_depth": 12, "lines_per_second": 50000.0}))
    before = snapshot(d)
    outputs = w.outputs(d)
    seen = kill_when_a_result_appears(outputs, n=2 if len(outputs) > 1 else 1)
    res = invoke(*w.args(d, inputs))
    assert res.exit_code == 130 and "interrupted" in res.output and "Traceback" not in res.output, res.output
    assert seen, "the kill never happened"
    assert temporaries(d) == []
    if command.endswith("--write"):
        assert snapshot(d) == before  # the user's file: the old one, byte for byte
        return
    existing = [p for p in outputs if p.exists()]
    if w.all_or_nothing:
        assert existing == [], existing
    for path in existing:  # what a long run finished before the kill is whole and planeray's
        assert path.is_dir() or file_mark(path) is not None, path


# ---------------------------------------------------------------------------- 7. a second run at the same time
@pytest.mark.parametrize("command", _params(slow_too=False))
def test_a_second_run_at_the_same_time_is_refused_in_one_line(command, inputs, tmp_path):
    """Another planeray process writes the output (it holds its lock): refused before any work, nothing touched."""
    from test_faults_concurrency import Holder

    w = WRITERS[command]
    d = tmp_path / "out"
    d.mkdir()
    if command.endswith("--write"):
        (d / "acquisition.json").write_text(json.dumps({"bit_depth": 12, "lines_per_second": 50000.0}))
    target = w.outputs(d)[0]
    other = Holder(lock_path(target))
    try:
        before = snapshot(d)
        line = one_line_error(invoke(*w.args(d, inputs)), f"another planeray run (pid {other.pid}) is writing it")
        assert target.name in line
        assert snapshot(d) == before and temporaries(d) == []
        assert lock_holder(target)["pid"] == other.pid  # the other run's lock, untouched
    finally:
        other.release()


# ---------------------------------------------------------------------------- 6. resumed
def test_a_killed_capture_resumes_says_so_and_gives_the_same_stack(tmp_path, monkeypatch):
    from planeray.devices.simulated import SimulatedEpiscan
    from planeray.io import read_stack

    args = ("acquire", "--size", 16, 16, "--sweep", "quick", "--seed", 2)
    assert invoke(*args, "--out", tmp_path / "whole.zarr").exit_code == 0
    real, grabs = SimulatedEpiscan.grab, []

    def killed_at_the_tenth(self):
        grabs.append(1)
        if len(grabs) == 10:
            raise KeyboardInterrupt
        return real(self)

    out = tmp_path / "a.zarr"
    with monkeypatch.context() as m:
        m.setattr(SimulatedEpiscan, "grab", killed_at_the_tenth)
        res = invoke(*args, "--out", out)
    assert res.exit_code == 130 and not out.exists() and temporaries(tmp_path) == []
    res = invoke(*args, "--out", out)
    assert res.exit_code == 0, res.output
    assert f"resuming an unfinished capture of {out}: 9 of 27 images already captured" in res.output
    np.testing.assert_array_equal(
        np.asarray(read_stack(out).images[:]), np.asarray(read_stack(tmp_path / "whole.zarr").images[:])
    )
    res = invoke(*args, "--out", tmp_path / "again.zarr")
    assert res.exit_code == 0 and "resuming" not in res.output  # a fresh capture says nothing of the kind


@pytest.mark.skipif(not HAS_MITSUBA, reason="needs mitsuba")
@pytest.mark.parametrize("command", ["render", "render-examples"])
def test_a_killed_render_resumes_and_says_so(command, inputs, tmp_path, monkeypatch):
    import planeray.render.render as driver
    from planeray.io import read_transport
    from planeray.render._mitsuba import choose_variant

    if not choose_variant().startswith("llvm"):  # the scalar fallback renders in one unit: nothing to resume
        pytest.skip("resuming a render needs batches: the one-pass tally needs Mitsuba's llvm variant (libllvm19)")
    w = WRITERS[command]
    args = w.args(tmp_path, inputs)
    real, units = driver._run_unit, []

    def killed_in_the_second_batch(*a, **k):
        units.append(1)
        if len(units) == 2:
            raise KeyboardInterrupt
        return real(*a, **k)

    with monkeypatch.context() as m:
        m.setattr(driver, "_run_unit", killed_in_the_second_batch)
        res = invoke(*args)
    assert res.exit_code == 130, res.output
    assert not any(p.exists() for p in w.outputs(tmp_path)) and temporaries(tmp_path) == []
    res = invoke(*args)
    assert res.exit_code == 0, res.output
    store = w.outputs(tmp_path)[0]  # camera batches (render: --spp 2 --batch-spp 1) and the caustic pass
    assert re.search(
        rf"resuming an unfinished render of {re.escape(str(store))}: 1 of \d+ batches already done", res.output
    )
    if command == "render":
        fresh = tmp_path / "fresh.zarr"
        assert invoke(*args[:-1], fresh).exit_code == 0
        np.testing.assert_allclose(read_transport(store)[0].dense, read_transport(fresh)[0].dense, rtol=1e-5, atol=1e-7)
    else:
        assert read_transport(store)[0].shape == (8, 8)


# ---------------------------------------------------------------------------- acquisition.json, field by field
def test_calibration_write_keeps_every_field_of_the_users_file_and_what_it_replaced(inputs, tmp_path):
    acq = tmp_path / "acquisition.json"
    mine = {
        "bit_depth": 12,
        "notes": "rig B, lens 2 — ünïcode kept",
        "lines_per_second": 52000.0,
        "base_trigger_delay_us": 2500.0,
        "nested": {"a": [1, 2, {"b": None}]},
        "calibration": {"by_hand": True},
    }
    acq.write_text(json.dumps(mine, ensure_ascii=False))
    res = invoke("calibrate", "lines", inputs["L"], "--write", acq)
    assert res.exit_code == 0, res.output
    res = invoke("calibrate", "delay-zero", "--simulate", "--write", acq)  # a delay zero without a base
    assert res.exit_code == 0, res.output
    after = json.loads(acq.read_text(encoding="utf-8"))
    for key in ("bit_depth", "notes", "nested"):
        assert after[key] == mine[key]
    assert after["calibration"]["by_hand"] is True
    assert abs(after["lines_per_second"] - 54000) < 0.02 * 54000
    assert "base_trigger_delay_us" not in after  # never an old base with a new delay zero ...
    assert after["calibration"]["replaced"] == {
        "lines_per_second": 52000.0,
        "base_trigger_delay_us": 2500.0,
    }  # ... kept
    assert file_mark(acq) is None  # still the user's file: planeray does not claim it


def test_calibration_write_refuses_before_any_work_what_it_could_not_update_without_loss(inputs, tmp_path, monkeypatch):
    import planeray.calibration as calibration

    def no_sweep(*args, **kwargs):
        raise AssertionError("the sweep ran before the --write file was checked")

    monkeypatch.setattr(calibration, "calibrate_delay_zero", no_sweep)  # before the sweep, not after it
    for text, needle in (
        ('{"a": 1, "a": 2}', "appears twice"),
        ("[1, 2]", "JSON object"),
        ('{"calibration": [1]}', "'calibration'"),
        ("{not json", "invalid JSON"),
    ):
        acq = tmp_path / "acquisition.json"
        acq.write_text(text)
        one_line_error(invoke("calibrate", "delay-zero", "--simulate", "--write", acq), "--write", needle)
        assert acq.read_text() == text
