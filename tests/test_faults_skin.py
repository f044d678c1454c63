"""Fault injection for every writing command of ``planeray skin ...`` and ``planeray video`` (issue 24).

Each command x {existing user file, existing planeray output, read-only folder, full disk, killed
mid-run, a rerun after a kill}: a user's file or folder at any of its outputs (companion files
included) is never replaced, with or without ``--overwrite``; planeray's own output is refused
without ``--overwrite`` and replaced with it; a failing file system gives one line naming the cause
and leaves nothing; an interruption mid-write leaves no output and no temporaries; none of these
commands resumes (each run starts over), and a rerun removes the temporaries a killed run left.

The commands run small (8-48 pixels, a few frames); the long studies (``skin validate``, ``skin
compare``, ``skin pulse-report``) have their computations replaced by small stand-ins: what is
tested here is how they write.  The table in the README ("What planeray promises about your data")
names the test of each cell.
"""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import test_faults
from test_faults import leftovers, one_line_error

#: what these tests check is what happens to files, not what the figures show (conftest.py)
pytestmark = pytest.mark.usefixtures("figures_not_drawn")

failing_folder = test_faults.failing_folder  # the fixture: writes under a folder fail with an OSError

runner = CliRunner()


def _command():
    import typer.main

    from planeray.cli import app

    global _CMD
    try:
        return _CMD
    except NameError:
        _CMD = typer.main.get_command(app)
        return _CMD


def invoke(*args):
    return runner.invoke(_command(), [str(a) for a in args])


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A small planeray stack and a planeray pulse video, outside the folders the tests write in."""
    import planeray as pr
    from _skin_toy import toy_vein_scene
    from planeray.pulse.video_io import Video, write_video

    d = tmp_path_factory.mktemp("skin_inputs")
    scene = toy_vein_scene((48, 48), projector_rows=270, columns=(8, 24, 40))
    pr.write_stack(pr.simulate_stack(scene, pr.timing.quick_sweep(), seed=0), d / "s.zarr")
    rng = np.random.default_rng(0)
    frames = (0.5 + 0.01 * rng.standard_normal((120, 16, 16))).astype(np.float32)
    write_video(d / "v.tif", Video(frames, 30.0, "test"))
    from PIL import Image

    mask = np.zeros((48, 48), np.uint8)
    mask[:, [7, 8, 9, 23, 24, 25, 39, 40, 41]] = 255  # the toy scene's three veins
    Image.fromarray(mask).save(d / "mask.png")
    return {"stack": d / "s.zarr", "video": d / "v.tif", "mask": d / "mask.png"}


@pytest.fixture
def small_studies(monkeypatch):
    """The long studies replaced by small stand-ins (their writing is what these tests check)."""
    import planeray.experiments.pulse as ep
    import planeray.experiments.skin as es
    import planeray.experiments.skin_physics as sp
    from _skin_toy import toy_vein_scene

    def vein_validation(*, cases=sp.VALIDATION_CASES, progress=None, **kw):
        rows = []
        for angle, depth, diam, rho in cases:
            rows.append(
                dict(angle_deg=angle, depth_mm=depth, diameter_mm=diam, rho_rows=rho, short_brute=0.3, short_fast=0.3,
                     short_brute_stderr=0.01, epipolar_brute=0.05, epipolar_fast=0.05, offsets_rows=[0, 1, 2],
                     ratio_brute=[0.9, 0.8, 0.7], ratio_fast=[0.9, 0.8, 0.7], seconds=0.0)
            )  # fmt: skip
            if progress is not None:
                progress(1)
        return rows

    monkeypatch.setattr(sp, "vein_validation", vein_validation)
    import planeray.skin.depth as sd

    def fit_vein(model, images, variance, pix, *, vein_id=1, **kw):  # a vein's fit, answered at once
        return sd.VeinFit(vein_id, True, "", 2.0, 2.5, 0.1, 0.3, 0.2, 100.0, 1.1, pix.rows.size, len(images))

    monkeypatch.setattr(sd, "fit_vein", fit_vein)
    monkeypatch.setattr(sp, "layered_adding_doubling", lambda **kw: {"mc": 0.41, "mc_stderr": 0.001, "ad": 0.41})
    monkeypatch.setattr(
        es, "skin_scene", lambda shape, seed=0, **kw: toy_vein_scene(shape, projector_rows=90, columns=(3, 8, 13))
    )
    import planeray.figures.pulse as fp
    import planeray.figures.skin as fs
    from planeray.figures._common import new_figure, save_png

    def figure(*args, out=None, **kwargs):  # a small marked PNG instead of a study's figure
        return save_png(new_figure((1, 1)), out) if out is not None else None

    for name in ("methods_figure", "vein_depth_figure", "ambient_figure", "best_delay_figure", "enhancement_figure"):
        monkeypatch.setattr(fs, name, figure)
    for name in ("pulse_signal_figure", "pulse_methods_figure", "rate_accuracy_figure"):
        monkeypatch.setattr(fp, name, figure)
    monkeypatch.setattr(sp, "vein_validation_figure", figure)
    monkeypatch.setattr(ep, "noise_study", lambda *a, **k: {})
    monkeypatch.setattr(ep, "delay_study", lambda *a, **k: {})
    monkeypatch.setattr(ep, "resolution_study", lambda **k: {})
    monkeypatch.setattr(ep, "false_alarm_study", lambda **k: {})


#: command -> (its words, writing into folder ``{d}``; the outputs they write, relative to ``{d}``)
SPECS = {
    "skin simulate": (
        "skin simulate --out {d}/arm.zarr --size 16 16 --projector-rows 90 --sweep quick",
        ("arm.zarr", "arm_vein_mask.png", "arm_veins.json", "arm_maps.npz"),
    ),
    "skin validate": ("skin validate --out {d}/val --n-photons 32", ("val",)),
    "skin veins": ("skin veins {stack} --out {d}/veins --delay-us 750", ("veins",)),
    "skin depth": ("skin depth {stack} --mask {mask} --out {d}/depth --tone fair --wavelength 638", ("depth",)),
    "skin enhance": ("skin enhance {stack} --out {d}/enh", ("enh",)),
    "skin compare": ("skin compare --out {d}/cmp --size 16 --quick", ("cmp",)),
    "skin pulse": ("skin pulse {video} --out {d}/p --magnified {d}/mag.tif", ("p", "mag.tif")),
    "skin pulse --magnified .mp4": ("skin pulse {video} --out {d}/p --magnified {d}/mag.mp4", ("p", "mag.mp4")),
    "skin video": (
        "skin video --out {d}/arm.tif --size 8 8 --projector-rows 48 --seconds 3 --fps 10",
        ("arm.tif", "arm_video_vein_mask.png"),
    ),
    "skin video --method all .mp4": (
        "skin video --out {d}/arm.mp4 --size 8 8 --projector-rows 48 --seconds 3 --fps 10 --method all",
        ("arm_regular.mp4", "arm_direct.mp4", "arm_global.mp4", "arm_indirect.mp4", "arm_video_vein_mask.png"),
    ),
    "skin pulse-report": (
        "skin pulse-report --out {d}/rep --quick --size 16 16 --projector-rows 48 --seconds 3 --fps 10",
        ("rep",),
    ),
    "video": ("video diffuse_plane --size 8 --projector-rows 48 --frames 3 --out {d}/s.mp4", ("s.mp4",)),
}


def _writer(words: str):
    return lambda d, i: [w.format(d=d, **(i or {})) for w in words.split()]


WRITERS = {name: (_writer(words), outputs) for name, (words, outputs) in SPECS.items()}
COMMANDS = sorted(WRITERS)


def _snapshot(folder: Path) -> dict:
    import hashlib

    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def _user_thing(path: Path) -> None:
    """A file or folder of the user's at ``path`` (a folder for a folder output, a file otherwise)."""
    if path.suffix in ("", ".zarr"):
        path.mkdir()
        (path / "notes.txt").write_text("three weeks of lab notes")
    elif path.suffix == ".png":
        from PIL import Image

        Image.fromarray(np.full((8, 8), 7, np.uint8)).save(path)
    elif path.suffix in (".tif", ".tiff"):
        import tifffile

        tifffile.imwrite(path, np.arange(64, dtype=np.uint16).reshape(8, 8))
    elif path.suffix == ".json":
        path.write_text(json.dumps({"experiment": "forearm 3"}))
    elif path.suffix == ".npz":
        np.savez(path, lines=np.arange(5.0))
    else:
        path.write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(64))  # a video of the user's


# ---------------------------------------------------------------------------- existing user file
@pytest.mark.parametrize("overwrite", [False, True], ids=["plain", "--overwrite"])
@pytest.mark.parametrize("command", COMMANDS)
def test_a_user_file_at_any_output_is_never_replaced(command, overwrite, inputs, tmp_path, small_studies):
    """Each output in turn (companion files included) is a user's file or folder: refused, before any work."""
    args, outputs = WRITERS[command]
    for name in outputs:
        d = tmp_path / name.replace("/", "_")
        d.mkdir()
        _user_thing(d / name)
        before = _snapshot(d)
        res = invoke(*args(d, inputs), *(["--overwrite"] if overwrite else []))
        line = one_line_error(res, name)
        assert ("planeray did not write" if overwrite else "already exists") in line, line
        assert _snapshot(d) == before and sorted(p.name for p in d.iterdir()) == [name], command


# ---------------------------------------------------------------------------- existing planeray output
@pytest.mark.parametrize("command", COMMANDS)
def test_planeray_output_is_replaced_only_with_overwrite(command, inputs, tmp_path, small_studies):
    from planeray.io.atomic import planeray_output_kind

    args, outputs = WRITERS[command]
    res = invoke(*args(tmp_path, inputs))
    assert res.exit_code == 0, res.output
    kinds = {name: planeray_output_kind(tmp_path / name) for name in outputs}
    assert all(kinds.values()), kinds  # every output, single files included, is recognizably planeray's
    before = _snapshot(tmp_path)
    one_line_error(invoke(*args(tmp_path, inputs)), "already exists")
    assert _snapshot(tmp_path) == before
    inodes = {name: (tmp_path / name).stat().st_ino for name in outputs}
    res = invoke(*args(tmp_path, inputs), "--overwrite")
    assert res.exit_code == 0, res.output
    assert {name: planeray_output_kind(tmp_path / name) for name in outputs} == kinds
    assert all((tmp_path / name).stat().st_ino != inodes[name] for name in outputs)  # written anew, renamed in
    assert leftovers(tmp_path) == []


#: command -> (module, attribute) where its work starts: never reached when an output is refused
WORK = {
    "skin simulate": ("planeray.experiments.skin_capture", "make_scene"),
    "skin validate": ("planeray.experiments.skin_physics", "vein_validation"),
    "skin veins": ("planeray.skin.imaging", "stack_images"),
    "skin depth": ("planeray.skin.depth", "fit_veins"),
    "skin enhance": ("planeray.skin.imaging", "delay_sweep_images"),
    "skin compare": ("planeray.experiments.skin", "skin_scene"),
    "skin pulse": ("planeray.experiments.pulse", "analyze_pulse"),
    "skin pulse --magnified .mp4": ("planeray.experiments.pulse", "analyze_pulse"),
    "skin video": ("planeray.pulse.simulate", "simulate_live"),
    "skin video --method all .mp4": ("planeray.pulse.simulate", "simulate_live"),
    "skin pulse-report": ("planeray.experiments.pulse", "linearize"),
    "video": ("planeray.viewer.session", "open_source"),
}


@pytest.mark.parametrize("command", COMMANDS)
def test_every_output_is_checked_before_any_work(command, inputs, tmp_path, monkeypatch, small_studies):
    """An existing output -- any of them, the last companion file too -- is refused before the work starts."""
    import importlib

    module, name = WORK[command]

    def work(*args, **kwargs):
        raise AssertionError(f"{command}: the work started before its outputs were checked")

    monkeypatch.setattr(importlib.import_module(module), name, work)
    args, outputs = WRITERS[command]
    for output in outputs:
        d = tmp_path / output
        d.mkdir()
        _user_thing(d / output)
        one_line_error(invoke(*args(d, inputs)), output, "already exists")


def test_one_kind_of_planeray_file_never_replaces_another(inputs, tmp_path):
    """The README's skin and pulse examples in one folder: the stack's truth and the video's mask are apart,
    and a planeray file of another kind at an output is refused even with --overwrite."""
    from planeray.io.marks import file_mark

    assert invoke("skin", "simulate", "--out", tmp_path / "arm.zarr", "--size", 16, 16, "--projector-rows", 90,
                  "--sweep", "quick").exit_code == 0  # fmt: skip
    video = ("skin", "video", "--out", tmp_path / "arm.tif", "--size", 8, 8, "--projector-rows", 48, "--seconds", 3,
             "--fps", 10)  # fmt: skip
    assert invoke(*video).exit_code == 0
    assert file_mark(tmp_path / "arm_vein_mask.png") == "skin truth"
    assert file_mark(tmp_path / "arm_video_vein_mask.png") == "video vein mask"
    before = _snapshot(tmp_path)
    # the truth's mask where the video's mask goes: another kind, never replaced
    os.replace(tmp_path / "arm_vein_mask.png", tmp_path / "arm_video_vein_mask.png")
    before = _snapshot(tmp_path)
    line = one_line_error(invoke(*video, "--overwrite"), "arm_video_vein_mask.png", "not a video vein mask")
    assert "skin truth" in line and _snapshot(tmp_path) == before


# ---------------------------------------------------------------------------- read-only folder, full disk
@pytest.mark.parametrize("code", [errno.EROFS, errno.ENOSPC], ids=["read-only", "disk-full"])
@pytest.mark.parametrize("command", COMMANDS)
def test_a_failing_disk_gives_one_line_and_leaves_nothing(command, code, inputs, tmp_path, failing_folder,
                                                         small_studies):  # fmt: skip
    args, _ = WRITERS[command]
    target = tmp_path / "out"
    target.mkdir()
    failing_folder(target, code)
    line = one_line_error(invoke(*args(target, inputs)), os.strerror(code))
    assert str(target) in line
    assert sorted(p.name for p in target.iterdir()) == []


def test_a_full_disk_inside_ffmpeg_gives_one_line_and_leaves_nothing(tmp_path, monkeypatch):
    """ffmpeg writes the videos itself (a subprocess): its own failure mid-video is reported the same way."""
    import imageio_ffmpeg

    def full_disk(path, *args, **kwargs):
        def frames():
            yield  # started
            yield  # the first frame
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), path)

        return frames()

    monkeypatch.setattr(imageio_ffmpeg, "write_frames", full_disk)
    for n, args in enumerate((WRITERS["video"][0], WRITERS["skin video --method all .mp4"][0])):
        d = tmp_path / f"out{n}"
        d.mkdir()
        line = one_line_error(invoke(*args(d, None)), os.strerror(errno.ENOSPC))
        assert str(d) in line and sorted(p.name for p in d.iterdir()) == []


# ---------------------------------------------------------------------------- killed mid-run
#: command -> (module, attribute) raising KeyboardInterrupt once the command is writing its outputs
INTERRUPT = {
    "skin simulate": ("planeray.experiments.skin_capture", "write_stack"),  # the truth files are in temporaries
    "skin validate": ("planeray.experiments.skin_physics", "vein_validation_figure"),
    "skin veins": ("planeray.figures.skin", "headline_figure"),
    "skin depth": ("planeray.figures.skin", "depth_fit_figure"),
    "skin enhance": ("planeray.figures.skin", "delay_map_figure"),
    "skin compare": ("planeray.figures.skin", "best_delay_figure"),
    "skin pulse": ("planeray.experiments.pulse", "_region_png"),  # the magnified video is in its temporary
    "skin pulse --magnified .mp4": ("planeray.experiments.pulse", "_region_png"),
    "skin video": ("PIL.Image.Image", "save"),  # the video is written, its mask is being written
    "skin video --method all .mp4": ("planeray.pulse.video_io", "encode_video", 2),  # the second video
    "skin pulse-report": ("planeray.figures.pulse", "rate_accuracy_figure"),
    "video": ("planeray.viewer.video", "_caption", 2),  # ffmpeg has the first frame
}


@pytest.mark.parametrize("command", COMMANDS)
def test_killed_mid_write_leaves_no_output_and_no_temporaries(command, inputs, tmp_path, monkeypatch,
                                                              small_studies):  # fmt: skip
    import importlib

    module, name, *after = INTERRUPT[command]
    try:
        owner = importlib.import_module(module)
    except ModuleNotFoundError:
        mod, _, cls = module.rpartition(".")
        owner = getattr(importlib.import_module(mod), cls)
    real, calls = getattr(owner, name), []

    def interrupted(*a, **k):
        calls.append(1)
        if len(calls) >= (after[0] if after else 1):
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(owner, name, interrupted)
    args, _ = WRITERS[command]
    res = invoke(*args(tmp_path, inputs))
    assert res.exit_code == 130 and "interrupted" in res.output, res.output
    assert calls, "the interruption was never reached"
    assert sorted(p.name for p in tmp_path.iterdir()) == [], command


# ---------------------------------------------------------------------------- resumed
def _dead_pid() -> int:
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    return int(proc.stdout)


@pytest.mark.parametrize("command", COMMANDS)
def test_none_resumes_and_a_rerun_removes_what_a_killed_run_left(command, inputs, tmp_path, small_studies):
    """No command of the area resumes (each run starts over); the temporaries a run killed by the kernel
    (``kill -9``: no cleanup) left beside its outputs are removed by the next run, nothing else."""
    args, outputs = WRITERS[command]
    pid = _dead_pid()
    stale = []
    for name in outputs:
        p = tmp_path / f".{name}.tmp-{pid}-0123456789abcdef{Path(name).suffix}"
        (p.mkdir() if Path(name).suffix in ("", ".zarr") else p.write_bytes(b"half a file"))
        stale.append(p)
    live = tmp_path / f".{outputs[0]}.tmp-{os.getpid()}-fedcba9876543210"  # a running process's: kept
    live.write_bytes(b"in use")
    res = invoke(*args(tmp_path, inputs))
    assert res.exit_code == 0, res.output
    assert not any(p.exists() for p in stale), command
    assert live.exists() and all((tmp_path / name).exists() for name in outputs)


# ---------------------------------------------------------------------------- a second run at the same time
@pytest.mark.parametrize("command", COMMANDS)
def test_a_second_run_at_the_same_time_is_refused_before_any_work(command, inputs, tmp_path, monkeypatch):
    """Another planeray process is writing an output (it holds its lock): refused before any work, nothing touched."""
    import importlib

    from planeray.io.lock import lock_holder, lock_path
    from test_faults_concurrency import Holder

    module, name = WORK[command]

    def work(*args, **kwargs):
        raise AssertionError(f"{command}: the work started while another run held its output")

    monkeypatch.setattr(importlib.import_module(module), name, work)
    args, outputs = WRITERS[command]
    d = tmp_path / "out"
    d.mkdir()
    target = d / outputs[-1]  # the last output: a companion file too is locked
    other = Holder(lock_path(target))
    try:
        before = _snapshot(d)
        line = one_line_error(invoke(*args(d, inputs)), f"another planeray run (pid {other.pid}) is writing it")
        assert outputs[-1] in line
        assert _snapshot(d) == before and lock_holder(target)["pid"] == other.pid
    finally:
        other.release()
