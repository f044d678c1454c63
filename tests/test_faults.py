"""Fault injection: nothing a user wrote is lost, nothing goes silently wrong (issue 11).

Each test reproduces one way a demanding user (or a failing disk or cluster) met
planeray and asserts the promise of the README's "What planeray promises about your
data": outputs replaced only when planeray wrote them, resumes only on identical
inputs, one line and exit status 1 for every failure, no temporaries left behind,
numbers checked where they are parsed.  Missing/corrupt chunks and import-folder
pixel formats are in ``test_faults_io.py``.
"""

from __future__ import annotations

import builtins
import errno
import io as _io
import json
import os
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import planeray as pr
from planeray.cli import app
from planeray.errors import InputError, StorageError, TransportError
from planeray.io import read_stack, read_transport, read_transport_maps, write_stack
from planeray.io.atomic import check_replaceable, planeray_output_kind

#: what these tests check is what happens to files, not what the figures show (conftest.py)
pytestmark = pytest.mark.usefixtures("figures_not_drawn")

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_line_error(res, *needles):
    """Exit 1, one ``error:`` line naming every needle, no traceback."""
    assert res.exit_code == 1, res.output
    lines = [line for line in res.output.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, res.output
    assert "Traceback" not in res.output, res.output
    for needle in needles:
        assert str(needle) in lines[0], (needle, lines[0])
    return lines[0]


def leftovers(folder: Path):
    """Temporaries, backups and partial runs planeray may leave beside its outputs."""
    return sorted(
        p.name
        for p in folder.iterdir()
        if p.name.startswith(".") and any(tag in p.name for tag in (".tmp-", ".bak-", ".partial", ".old"))
    )


@pytest.fixture(scope="module")
def small_stack(tmp_path_factory):
    """A 24x20 wax stack on disk (planeray-written)."""
    path = tmp_path_factory.mktemp("faults") / "wax.zarr"
    res = invoke("simulate", "wax", "--out", path, "--size", 24, 20, "--projector-rows", 90, "--seed", 1)
    assert res.exit_code == 0, res.output
    return path


# ---------------------------------------------------------------------------- 1. --overwrite
@pytest.mark.parametrize("command", ["simulate", "demux", "export", "import"])
def test_overwrite_never_deletes_a_folder_planeray_did_not_write(command, small_stack, tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("three weeks of lab notes")
    if command == "simulate":
        res = invoke("simulate", "diffuse_plane", "--size", 16, 16, "--sweep", "quick", "--out", mine, "--overwrite")
    elif command == "demux":
        res = invoke("demux", small_stack, "--out", mine, "--overwrite")
    elif command == "export":
        res = invoke("export", small_stack, "--out", mine, "--overwrite")
    else:
        folder = tmp_path / "exported"
        assert invoke("export", small_stack, "--out", folder).exit_code == 0
        res = invoke("import", folder, "--out", mine, "--overwrite")
    one_line_error(res, mine, "did not write")
    assert (mine / "notes.txt").read_text() == "three weeks of lab notes"
    assert leftovers(tmp_path) == []


def test_overwrite_of_the_current_folder_is_refused_in_one_line(small_stack, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "keep.txt").write_text("x")
    one_line_error(invoke("demux", small_stack, "--out", ".", "--overwrite"), "current folder")
    one_line_error(invoke("simulate", "wax", "--size", 16, 16, "--out", ".", "--overwrite"), "current folder")
    assert (tmp_path / "keep.txt").exists() and leftovers(tmp_path) == [] and leftovers(tmp_path.parent) == []


def test_overwrite_replaces_only_a_result_of_the_same_kind(small_stack, tmp_path):
    transport = tmp_path / "T.zarr"
    assert invoke("demux", small_stack, "--out", transport).exit_code == 0
    assert planeray_output_kind(transport) == "transport" and planeray_output_kind(small_stack) == "stack"
    # a transport may replace a transport, never the captured stack
    assert invoke("demux", small_stack, "--out", transport, "--overwrite").exit_code == 0
    other = tmp_path / "other.zarr"
    assert invoke("simulate", "diffuse_plane", "--size", 24, 20, "--sweep", "quick", "--out", other).exit_code == 0
    one_line_error(invoke("demux", small_stack, "--out", other, "--overwrite"), other, "not a transport")
    one_line_error(invoke("demux", small_stack, "--out", small_stack, "--overwrite"), "is also an input")
    assert read_stack(other).shape == (24, 20)
    with pytest.raises(InputError, match="symbolic link"):
        link = tmp_path / "link.zarr"
        link.symlink_to(transport)
        check_replaceable(link, overwrite=True, kind="transport")


# ---------------------------------------------------------------------------- 2. resumes
def test_a_resume_never_mixes_old_and_new_images(tmp_path):
    scene = pr.make_scene("wax", (24, 16), projector_rows=90, seed=2)
    stack = pr.simulate_stack(scene, pr.paper_sweep(), seed=2)
    src = tmp_path / "s.zarr"
    write_stack(stack, src)
    out = tmp_path / "T.zarr"
    pr.demultiplex_to_store(read_stack(src), out, chunk_rows=4, _stop_after=3)  # killed after 3 of 6 chunks
    # images 1..83 change between the kill and the re-run (first and last stay the same)
    changed = pr.Stack(
        np.concatenate([stack.images[:1], stack.images[1:84] * 0.5, stack.images[84:]]),
        stack.delay_us,
        stack.exposure_us,
        stack.lines_per_second,
        excluded=stack.excluded,
        saturated=stack.saturated,
        projector_rows=stack.projector_rows,
        metadata=stack.metadata,
    )
    write_stack(changed, src, overwrite=True)
    res = invoke("demux", src, "--out", out, "--chunk-rows", 4)
    one_line_error(res, "different inputs", "--restart")
    # --restart computes everything from the new images: the same bytes as a fresh run
    assert invoke("demux", src, "--out", out, "--chunk-rows", 4, "--restart").exit_code == 0
    fresh = tmp_path / "fresh.zarr"
    pr.demultiplex_to_store(read_stack(src), fresh, chunk_rows=4)
    np.testing.assert_array_equal(read_transport(out)[0].dense, read_transport(fresh)[0].dense)


def test_a_resume_says_so_and_finishes_identically(tmp_path):
    scene = pr.make_scene("wax", (24, 16), projector_rows=90, seed=3)
    src = write_stack(pr.simulate_stack(scene, pr.paper_sweep(), seed=3), tmp_path / "s.zarr")
    out, fresh = tmp_path / "T.zarr", tmp_path / "fresh.zarr"
    pr.demultiplex_to_store(read_stack(src), out, chunk_rows=4, _stop_after=2)
    res = invoke("demux", src, "--out", out, "--chunk-rows", 4)
    assert res.exit_code == 0, res.output
    assert "resuming" in res.output and "2 of 6 chunks already done" in res.output
    pr.demultiplex_to_store(read_stack(src), fresh, chunk_rows=4)
    np.testing.assert_array_equal(read_transport(out)[0].dense, read_transport(fresh)[0].dense)


def test_content_digest_sees_every_image_and_the_saturation_mask():
    stack = pr.simulate_stack(pr.make_scene("diffuse_plane", (8, 8), seed=0), pr.quick_sweep(), seed=0)
    base = stack.content_digest()
    images = np.array(stack.images)
    images[13, 4, 4] += 1e-6
    sat = np.zeros(images.shape, bool)
    sat[7, 1, 1] = True
    for im, st in ((images, None), (np.array(stack.images), sat)):
        other = pr.Stack(im, stack.delay_us, stack.exposure_us, stack.lines_per_second, saturated=st)
        assert other.content_digest() != base
    assert pr.Stack(np.array(stack.images), stack.delay_us, stack.exposure_us, 54_000.0).content_digest() == base


# ---------------------------------------------------------------------------- 5. file system, cluster
@pytest.fixture
def failing_folder(monkeypatch):
    """Make writes under a folder fail with an OSError, as a read-only folder or a full disk would.

    Root ignores permission bits, so the failure is injected where every writer goes
    through: ``open`` for writing, ``os.open`` with write flags, ``mkdir``, ``rename``
    and ``replace``.
    """

    def arm(folder: Path, code: int):
        folder = Path(folder).resolve()

        def under(path) -> bool:
            try:
                return Path(os.fsdecode(path)).resolve().is_relative_to(folder)
            except (TypeError, ValueError, OSError):
                return False

        def fail(path):
            raise OSError(code, os.strerror(code), os.fsdecode(path))

        real_open, real_os_open = builtins.open, os.open
        real_mkdir, real_rename, real_replace = os.mkdir, os.rename, os.replace

        def fake_open(file, mode="r", *args, **kwargs):
            if isinstance(file, (str, bytes, os.PathLike)) and any(c in mode for c in "wax+") and under(file):
                fail(file)
            return real_open(file, mode, *args, **kwargs)

        def fake_os_open(path, flags, *args, **kwargs):
            if flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT) and under(path):
                fail(path)
            return real_os_open(path, flags, *args, **kwargs)

        def guard(real):
            def fake(src, *args, **kwargs):
                if under(src) or (args and under(args[0])):
                    fail(src)
                return real(src, *args, **kwargs)

            return fake

        monkeypatch.setattr(builtins, "open", fake_open)
        monkeypatch.setattr(_io, "open", fake_open)
        monkeypatch.setattr(os, "open", fake_os_open)
        monkeypatch.setattr(os, "mkdir", guard(real_mkdir))
        monkeypatch.setattr(os, "rename", guard(real_rename))
        monkeypatch.setattr(os, "replace", guard(real_replace))

    return arm


WRITERS = {
    "simulate": lambda d, s: ("simulate", "diffuse_plane", "--size", 16, 16, "--sweep", "quick", "--out", d / "a.zarr"),
    "demux": lambda d, s: ("demux", s, "--out", d / "T.zarr"),
    "export": lambda d, s: ("export", s, "--out", d / "folder"),
    "import": lambda d, s: ("import", s.parent / "exported", "--out", d / "b.zarr"),
    "acquire": lambda d, s: ("acquire", "--device", "replay", "--replay", s, "--out", d / "c.zarr"),
    "synth": lambda d, s: ("synth", s.parent / "T.zarr", "--epipolar", "--out", d / "epi.png"),
    "contact-sheet": lambda d, s: ("contact-sheet", s, "--out", d / "sheet.png"),
    "profiles": lambda d, s: ("profiles", s, "--pixel", "5,5", "--out", d / "p.png"),
    "simulate-lines": lambda d, s: ("calibrate", "simulate-lines", "--out", d / "lines.npz"),
    "mc profile": lambda d, s: (
        "mc",
        "profile",
        "--sigma-s",
        1,
        "--sigma-a",
        0.1,
        "--g",
        0.5,
        "--photons",
        500,
        "--rows",
        4,
        "--out",
        d / "mc.csv",
    ),
    "emulate": lambda d, s: (
        "emulate",
        "diffuse_plane",
        "--size",
        16,
        16,
        "--delay-us",
        0,
        "--exposure-us",
        600,
        "--out",
        d / "emu",
    ),
}


@pytest.fixture(scope="module")
def inputs(small_stack):
    """A stack, its transport and its export folder side by side."""
    T = small_stack.parent / "T.zarr"
    if not T.exists():
        assert invoke("demux", small_stack, "--out", T).exit_code == 0
    folder = small_stack.parent / "exported"
    if not folder.exists():
        assert invoke("export", small_stack, "--out", folder).exit_code == 0
    return small_stack


@pytest.mark.parametrize("command", sorted(WRITERS))
@pytest.mark.parametrize("code", [errno.EROFS, errno.ENOSPC], ids=["read-only", "disk-full"])
def test_a_failing_disk_gives_one_line_and_leaves_nothing(command, code, inputs, tmp_path, failing_folder):
    if code == errno.ENOSPC and command not in ("simulate", "demux", "export"):
        pytest.skip("disk full is checked on the three big writers")
    target = tmp_path / "out"
    target.mkdir()
    failing_folder(target, code)
    res = invoke(*WRITERS[command](target, inputs))
    line = one_line_error(res, os.strerror(code))
    assert str(target) in line
    assert sorted(p.name for p in target.iterdir()) == []


def test_an_unreachable_scheduler_fails_within_seconds(inputs, tmp_path, monkeypatch):
    # the command waits SCHEDULER_TIMEOUT_S (5 s) for a scheduler; 1 s here, and the message says so
    monkeypatch.setattr("planeray.demux.driver.SCHEDULER_TIMEOUT_S", 1.0)
    t0 = time.perf_counter()
    res = invoke("demux", inputs, "--out", tmp_path / "T.zarr", "--scheduler", "tcp://127.0.0.1:9")
    one_line_error(res, "cannot reach the Dask scheduler", "127.0.0.1:9", "within 1 s")
    assert time.perf_counter() - t0 < 16
    assert leftovers(tmp_path) == []


def test_storage_errors_are_oserrors_with_the_path():
    exc = StorageError("cannot write: No space left on device [ENOSPC]", "/data/x.zarr")
    assert isinstance(exc, OSError) and str(exc).startswith("/data/x.zarr: ")


# ---------------------------------------------------------------------------- 6. printing
def test_file_names_with_markup_are_printed_verbatim(tmp_path):
    res = invoke("info", tmp_path / "img_[bold]0009.zarr")
    one_line_error(res, "img_[bold]0009.zarr")


def test_messages_name_command_line_options(tmp_path):
    stack = tmp_path / "s.zarr"
    assert invoke("simulate", "diffuse_plane", "--size", 16, 16, "--sweep", "quick", "--out", stack).exit_code == 0
    one_line_error(
        invoke("simulate", "diffuse_plane", "--size", 16, 16, "--sweep", "quick", "--out", stack), "--overwrite"
    )


# ---------------------------------------------------------------------------- 7. numbers
@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (("synth", "{T}", "--band", 0, 0, "--out", "{d}/a.png"), "--band (its exposure) must be a finite number > 0"),
        (("synth", "{T}", "--band", "nan", 600, "--out", "{d}/a.png"), "--band (its delay) must be a finite number"),
        (("synth", "{T}", "--sharpen", "nan", "--out", "{d}/a.png"), "--sharpen must be a finite number > 0"),
        (("synth", "{T}", "--short-range", "nan", "--out", "{d}/a.png"), "--short-range must be a finite number > 0"),
        (
            ("profiles", "{S}", "--pixel", "3,3", "--exposure-us", 601, "--out", "{d}/p.png"),
            "600, 750, 900, 1050, 1200",
        ),
        (("demux", "{S}", "--tol", -1, "--out", "{d}/T.zarr"), "tol must be"),
        (("demux", "{S}", "--alpha", "nan", "--out", "{d}/T.zarr"), "alpha"),
        (("demux", "{S}", "--chunk-rows", 0, "--out", "{d}/T.zarr"), "--chunk-rows must be"),
        (
            ("simulate", "wax", "--size", 16, 16, "--ambient", "nan", "--out", "{d}/w.zarr"),
            "--ambient-e-per-us must be",
        ),
        (("simulate", "wax", "--size", 16, 16, "--frames", 0, "--out", "{d}/w.zarr"), "--frames must be"),
        (("emulate", "wax", "--size", 16, 16, "--delay-us", "nan", "--exposure-us", 600, "--out", "{d}/e"), "delay"),
        (
            ("mc", "profile", "--sigma-s", "nan", "--sigma-a", 0.1, "--g", 0.5, "--out", "{d}/m.csv"),
            "--sigma-s must be",
        ),
        (("study", "demux", "--out", "{d}/st", "--seeds", 0, "--quick"), "seeds"),
    ],
)
def test_invalid_numbers_are_refused_where_they_are_parsed(args, needle, inputs, tmp_path):
    fill = {"T": inputs.parent / "T.zarr", "S": inputs, "d": tmp_path}
    res = invoke(*(str(a).format(**fill) for a in args))
    one_line_error(res, needle)
    assert list(tmp_path.iterdir()) == []


def test_fewer_projector_rows_than_camera_rows_still_give_a_finite_picture(tmp_path):
    # The line-velocity target needs camera rows finer than projector rows; they must work.
    out = tmp_path / "s.zarr"
    assert invoke("simulate", "wax", "--size", 32, 32, "--projector-rows", 8, "--out", out).exit_code == 0
    images = np.asarray(read_stack(out, lazy=False).images)
    assert np.isfinite(images).all() and images.max() > 0.05


# ---------------------------------------------------------------------------- 8. no usable observation
def test_a_fully_saturated_stack_is_flagged_never_converged(tmp_path):
    stack = pr.simulate_stack(pr.make_scene("diffuse_plane", (16, 12), seed=0), pr.paper_sweep(), seed=0)
    sat = np.ones(np.shape(stack.images), bool)
    sat[:, :, 6:] = False  # the right half keeps its observations
    src = write_stack(
        pr.Stack(stack.images, stack.delay_us, stack.exposure_us, stack.lines_per_second, saturated=sat),
        tmp_path / "sat.zarr",
    )
    res = invoke("demux", src, "--out", tmp_path / "T.zarr")
    assert res.exit_code == 0, res.output
    assert "96 pixels (50.0 %) have no usable observation" in res.output
    maps = read_transport_maps(tmp_path / "T.zarr")
    assert not maps["converged"][:, :6].any() and (maps["n_observations"][:, :6] == 0).all()
    assert maps["converged"][:, 6:].all()
    np.testing.assert_array_equal(read_transport(tmp_path / "T.zarr")[0].dense[:, :6], 0.0)


# ---------------------------------------------------------------------------- 9. before, during, after
def test_outputs_are_checked_before_any_work(tmp_path):
    truth = tmp_path / "truth.zarr"
    truth.mkdir()
    (truth / "zarr.json").write_text(json.dumps({"zarr_format": 3, "node_type": "group", "attributes": {}}))
    res = invoke("simulate", "wax", "--size", 16, 16, "--out", tmp_path / "s.zarr", "--truth", truth)
    one_line_error(res, truth, "already exists")
    assert not (tmp_path / "s.zarr").exists()


def test_temporaries_of_a_killed_run_are_cleaned_and_live_ones_kept(tmp_path):
    out = tmp_path / "s.zarr"
    dead = tmp_path / ".s.zarr.tmp-999999999-0123abcd"  # no such process
    live = tmp_path / f".s.zarr.tmp-{os.getppid()}-4567ef01"  # a running process (our parent)
    for t in (dead, live):
        t.mkdir()
        (t / "images").write_bytes(b"\0" * 1000)
    assert invoke("simulate", "diffuse_plane", "--size", 16, 16, "--sweep", "quick", "--out", out).exit_code == 0
    assert not dead.exists() and live.exists()


def test_an_output_created_by_someone_else_mid_run_keeps_the_finished_result(tmp_path, monkeypatch):
    import planeray.demux.driver as driver

    scene = pr.make_scene("wax", (16, 12), projector_rows=60, seed=4)
    src = write_stack(pr.simulate_stack(scene, pr.paper_sweep(), seed=4), tmp_path / "s.zarr")
    out = tmp_path / "T.zarr"
    real = driver._write_chunk
    calls = {"n": 0}

    def intruder(*args, **kwargs):
        calls["n"] += 1
        if not out.exists():
            out.mkdir()
            (out / "theirs.txt").write_text("someone else's")
        return real(*args, **kwargs)

    monkeypatch.setattr(driver, "_write_chunk", intruder)  # during the run, between chunks
    res = invoke("demux", src, "--out", out, "--chunk-rows", 4)
    line = one_line_error(res, out, "already exists", "kept")
    assert "different inputs" not in line and (out / "theirs.txt").exists()
    # once the user moves their folder away, the same command finishes without recomputing
    (out / "theirs.txt").unlink()
    out.rmdir()
    calls["n"] = 0
    res = invoke("demux", src, "--out", out, "--chunk-rows", 4)
    assert res.exit_code == 0, res.output
    assert calls["n"] == 0 and read_transport(out)[0].shape == (16, 12)


def test_promote_failure_keeps_the_run_resumable(tmp_path, monkeypatch):
    scene = pr.make_scene("wax", (16, 12), projector_rows=60, seed=5)
    stack = pr.simulate_stack(scene, pr.paper_sweep(), seed=5)
    out = tmp_path / "T.zarr"
    real_rename = os.rename

    def refuse(src, dst, *a, **k):
        if Path(dst) == out:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(dst))
        return real_rename(src, dst, *a, **k)

    monkeypatch.setattr(os, "rename", refuse)
    with pytest.raises(StorageError, match="Read-only file system"):
        pr.demultiplex_to_store(stack, out, chunk_rows=4)
    monkeypatch.setattr(os, "rename", real_rename)
    assert pr.demultiplex_to_store(stack, out, chunk_rows=4) == out  # resumes: every chunk done


def test_library_errors_name_the_output_and_say_how_to_replace_it(tmp_path):
    T = pr.make_scene("diffuse_plane", (8, 8), seed=0).transport
    pr.write_transport(T, tmp_path / "T.zarr")
    with pytest.raises(TransportError, match=r"T\.zarr: already exists \(pass --overwrite, or overwrite=True"):
        pr.write_transport(T, tmp_path / "T.zarr")


def test_a_stored_stack_is_digested_from_its_stored_bytes(tmp_path):
    stack = pr.simulate_stack(pr.make_scene("diffuse_plane", (16, 8), seed=0), pr.quick_sweep(), seed=0)
    path = write_stack(stack, tmp_path / "s.zarr")
    first = read_stack(path).content_digest()
    assert read_stack(path).content_digest() == first  # the same store, read again
    chunk = sorted((path / "images" / "c").rglob("*"))[-1]
    data = bytearray(chunk.read_bytes())
    data[-1] ^= 0xFF  # one stored byte changes
    chunk.write_bytes(bytes(data))
    assert read_stack(path).content_digest() != first
