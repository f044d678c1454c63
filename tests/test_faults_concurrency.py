"""Nothing lost when an input doubles as an output, when two runs collide, or when an output cannot be written.

Issue 40: every command that reads a file and writes one refuses an output that is (or holds)
one of its inputs, however the paths are spelled; an output being written is locked (a lock
file beside it with the holder's pid and host) and a second run into it is refused in one line
before any work; a lock whose holder died is taken over with a note; every output is checked
writable before any work (a read-only folder or a full disk costs no minutes of work).

The "other run" here is a real process: a small script that takes the lock with ``fcntl``
exactly as the lock module documents it (written here, not planeray's code), or a real
``planeray`` process stopped with SIGSTOP while it holds its lock.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from planeray.cli import app
from planeray.io.lock import OutputBusyError, StaleLockWarning, lock_holder, lock_path, output_lock
from test_faults import failing_folder  # noqa: F401  (the fixture: writes under a folder fail)

pytestmark = pytest.mark.usefixtures("figures_not_drawn")

runner = CliRunner()

#: Longest wait for another process (its start, its lock): generous for a loaded 2-core machine.
WAIT_S = 120.0


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_line_error(res, *needles) -> str:
    assert res.exit_code == 1, res.output
    lines = [line for line in res.output.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    for needle in needles:
        assert str(needle) in lines[0], (needle, lines[0])
    return lines[0]


def snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None) for p in sorted(folder.rglob("*"))}


# ---------------------------------------------------------------------------- another process holding a lock
#: The lock protocol of planeray.io.lock, written independently: flock the file, write pid and host as JSON.
HOLDER = r"""
import fcntl, json, os, socket, sys
fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT, 0o644)
fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
os.write(fd, json.dumps({"pid": os.getpid(), "host": socket.gethostname()}).encode())
print("holding", flush=True)
sys.stdin.readline()
"""


class Holder:
    """A process holding the lock file ``lock`` (started at once; ``kill`` leaves the file, as kill -9 does)."""

    def __init__(self, lock: Path):
        lock.parent.mkdir(parents=True, exist_ok=True)
        self.proc = subprocess.Popen(
            [sys.executable, "-c", HOLDER, str(lock)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        deadline = time.monotonic() + WAIT_S
        line = self.proc.stdout.readline()  # the holder prints once it holds the lock
        assert line.strip() == "holding" and time.monotonic() < deadline, f"the lock holder did not start ({line!r})"
        self.pid = self.proc.pid

    def kill(self):
        self.proc.kill()
        self._close()

    def release(self):
        if self.proc.poll() is None:
            self.proc.stdin.write("\n")
            self.proc.stdin.flush()
        self._close()

    def _close(self):
        self.proc.wait(timeout=WAIT_S)
        self.proc.stdin.close()
        self.proc.stdout.close()


@pytest.fixture
def holder():
    started = []

    def start(output: Path) -> Holder:
        h = Holder(lock_path(output))
        started.append(h)
        return h

    yield start
    for h in started:
        if not h.proc.stdout.closed:
            h.kill()


# ---------------------------------------------------------------------------- the lock itself
def test_the_lock_records_its_holder_is_reentrant_and_leaves_nothing(tmp_path):
    out = tmp_path / "new" / "deeper" / "T.zarr"  # its folders do not exist yet
    with output_lock(out):
        info = lock_holder(out)
        assert info["pid"] == os.getpid() and info["host"] == socket.gethostname() and "started" in info
        with output_lock(tmp_path / "new" / "deeper" / "." / "T.zarr"):  # the same output, another spelling
            assert lock_path(out).exists()
        assert lock_path(out).exists()  # still held by the outer block
    assert not lock_path(out).exists()
    assert not (tmp_path / "new").exists()  # the folders it made for its lock file, removed again


def test_a_live_holder_refuses_a_second_writer_naming_its_pid(tmp_path, holder):
    out = tmp_path / "T.zarr"
    h = holder(out)
    with pytest.raises(OutputBusyError, match=rf"another planeray run \(pid {h.pid}\) is writing it"):
        with output_lock(out):
            pass
    assert lock_holder(out)["pid"] == h.pid  # its lock is left as it was
    h.release()


def test_a_dead_holders_lock_is_taken_over_with_a_note(tmp_path, holder):
    out = tmp_path / "T.zarr"
    h = holder(out)
    h.kill()  # kill -9: the file stays, the kernel drops the flock
    assert lock_holder(out)["pid"] == h.pid
    with pytest.warns(StaleLockWarning, match=rf"no longer running \(pid {h.pid}"):
        with output_lock(out):
            assert lock_holder(out)["pid"] == os.getpid()
    assert not lock_path(out).exists()
    notes = []
    h2 = holder(out)
    h2.kill()
    with output_lock(out, on_stale=notes.append):
        pass
    assert len(notes) == 1 and f"pid {h2.pid}" in notes[0] and str(out) in notes[0]


def test_without_flock_the_pid_decides(tmp_path, monkeypatch):
    """File systems without flock (ENOLCK): a live pid of this host holds, a dead one is stale."""
    import planeray.io.lock as lock

    monkeypatch.setattr(lock, "_flock", lambda fd: None)
    out = tmp_path / "T.zarr"
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    try:
        lock_path(out).write_text(json.dumps({"pid": sleeper.pid, "host": socket.gethostname()}))
        with pytest.raises(OutputBusyError, match=f"pid {sleeper.pid}"):
            with output_lock(out):
                pass
        lock_path(out).write_text(json.dumps({"pid": sleeper.pid, "host": "another-host"}))
        with pytest.raises(OutputBusyError, match=f"pid {sleeper.pid} on another-host"):
            with output_lock(out):
                pass
    finally:
        sleeper.kill()
        sleeper.wait()
    lock_path(out).write_text(json.dumps({"pid": sleeper.pid, "host": socket.gethostname()}))
    with pytest.warns(StaleLockWarning):
        with output_lock(out):
            pass


# ---------------------------------------------------------------------------- inputs as outputs
@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    """A stack, its transport and export folder, a pattern image, a label image, a scene file."""
    from PIL import Image

    from planeray.render import example_scene

    d = tmp_path_factory.mktemp("inputs")
    for args in (
        ("simulate", "wax", "--size", 16, 12, "--projector-rows", 48, "--sweep", "quick", "--out", d / "S.zarr"),
        ("demux", d / "S.zarr", "--out", d / "T.zarr"),
        ("export", d / "S.zarr", "--out", d / "X"),
    ):
        res = invoke(*args)
        assert res.exit_code == 0, res.output
    Image.fromarray(np.full((16, 12), 1, np.uint8)).save(d / "L.png")
    (d / "scene.xml").write_bytes(Path(example_scene("mirror_ball")).read_bytes())
    (d / "link.zarr").symlink_to(d / "T.zarr")
    return d


#: Commands whose output is (or holds) one of their inputs; ``{d}``: the inputs' folder.  Every spelling of
#: the same path: as given, ``./``, a trailing slash, absolute, through ``..``, a symbolic link.
SAME = [
    ("simulate {d}/T.zarr --out {d}/o.zarr --truth {d}/T.zarr --overwrite", "--truth", "SCENE"),
    ("simulate {d}/T.zarr --out {d}/./T.zarr --overwrite", "--out", "SCENE"),
    ("simulate {d}/link.zarr --out {d}/o.zarr --truth {d}/T.zarr/ --overwrite", "--truth", "SCENE"),
    ("demux {d}/S.zarr --out {d}/../{n}/S.zarr --overwrite", "--out", "STACK"),
    ("export {d}/S.zarr --out {d}/S.zarr --overwrite", "--out", "STACK"),
    ("import {d}/X --out {d}/X/ --overwrite", "--out", "FOLDER"),
    ("acquire --device replay --replay {d}/S.zarr --out {d}/S.zarr --overwrite", "--out", "--replay"),
    ("render {d}/scene.xml --out {d}/scene.xml --overwrite", "--out", "SCENE_FILE"),
    ("synth {d}/T.zarr --relight {d}/L.png --out {d}/L.png --overwrite", "--out", "--relight"),
    ("materials fit {d}/T.zarr --out {d}/link.zarr --overwrite", "--out", "the capture"),
    (
        "materials fit {d}/S.zarr --white-reference {d}/T.zarr --out {d}/T.zarr --overwrite",
        "--out",
        "--white-reference",
    ),
    ("materials recognize {d}/T.zarr --regions {d}/L.png --out {d}/L.png --overwrite", "--out", "--regions"),
    ("skin veins {d}/S.zarr --out {d}/S.zarr --overwrite", "--out", "SOURCE"),
    ("skin veins {d}/S.zarr --transport {d}/T.zarr --out {d}/T.zarr --overwrite", "--out", "--transport"),
    ("skin enhance {d}/S.zarr --mask {d}/L.png --out {d}/L.png --overwrite", "--out", "--mask"),
    ("skin depth {d}/S.zarr --out {d}/S.zarr --overwrite", "--out", "STACK"),
]
#: Outputs that would hold an input (replacing them deletes it) or lie inside an input store.
AROUND = [
    ("demux {d}/S.zarr --out {d} --overwrite", "holds an input"),
    ("skin depth {d}/S.zarr --out {d}/S.zarr/depth", "lies inside an input store"),
    ("materials fit {d}/T.zarr --out {d}/T.zarr/fit", "lies inside an input store"),
]


def _args(template: str, d: Path) -> list[str]:
    return template.format(d=d, n=d.name).split()


@pytest.mark.parametrize(("template", "option", "which"), SAME, ids=[t[0].split(" --")[0] for t in SAME])
def test_an_input_named_as_an_output_is_refused_however_it_is_spelled(stores, template, option, which):
    before = snapshot(stores)
    line = one_line_error(invoke(*_args(template, stores)), f"{option} ", f"is also an input ({which})")
    assert "never writes over its inputs" in line
    assert snapshot(stores) == before


@pytest.mark.parametrize(("template", "problem"), AROUND, ids=[t[1] + ":" + t[0].split()[0] for t in AROUND])
def test_an_output_around_or_inside_an_input_is_refused(stores, template, problem):
    before = snapshot(stores)
    one_line_error(invoke(*_args(template, stores)), problem)
    assert snapshot(stores) == before


def test_a_library_is_updated_in_place_only_with_overwrite(stores, tmp_path):
    lib = tmp_path / "lib.json"
    lib.write_text("{}")
    one_line_error(
        invoke(
            "materials", "library-add", stores / "T.zarr", "--labels", stores / "L.png",
            "--class-name", "7=mine", "--library", lib, "--out", lib,
        ),
        "--overwrite",
    )  # fmt: skip
    assert lib.read_text() == "{}"


# ---------------------------------------------------------------------------- outputs checked before any work
@pytest.fixture
def no_work(monkeypatch):
    """Fail the test if a command starts its work (reads its inputs, simulates, traces) before its checks."""

    def started(*args, **kwargs):
        raise AssertionError("the work started before the outputs were checked")

    import planeray.experiments.skin as skin_exp
    import planeray.experiments.skin_physics as skin_physics
    import planeray.io as io

    for module, name in (
        (io, "read_stack"),
        (io, "read_transport"),
        (skin_exp, "run_skin_compare"),
        (skin_physics, "run_skin_validation"),
    ):
        monkeypatch.setattr(module, name, started)


#: Commands that worked for minutes before finding their output unwritable (the report folder of demux).
BEFORE_WORK = {
    "demux --report": "demux {d}/S.zarr --out {o}/T.zarr --alpha auto --report {o}/report",
    "materials fit": "materials fit {d}/T.zarr --out {o}/fit",
    "materials recognize": "materials recognize {d}/T.zarr --out {o}/rec",
    "materials train": "materials train {d}/S.zarr --labels {d}/L.png --out {o}/model.zip",
    "skin compare": "skin compare --quick --out {o}/cmp",
    "skin validate": "skin validate --out {o}/val",
    "skin depth": "skin depth {d}/S.zarr --out {o}/depth",
    "export": "export {d}/S.zarr --out {o}/x",
}


@pytest.mark.parametrize("code", [errno.EROFS, errno.ENOSPC], ids=["read-only", "disk-full"])
@pytest.mark.parametrize("command", list(BEFORE_WORK))
def test_an_unwritable_output_is_refused_before_any_work(
    command,
    code,
    stores,
    tmp_path,
    failing_folder,  # noqa: F811
    no_work,
):
    o = tmp_path / "out"
    o.mkdir()
    failing_folder(o, code)
    line = one_line_error(invoke(*BEFORE_WORK[command].format(d=stores, o=o).split()), os.strerror(code))
    assert str(o) in line
    assert list(o.iterdir()) == []


def test_the_demux_report_folder_is_checked_before_the_transport_is_written(stores, tmp_path, failing_folder):  # noqa: F811
    """The transport's folder is fine, the report's is read-only: nothing is written at all."""
    (tmp_path / "ro").mkdir()
    failing_folder(tmp_path / "ro", errno.EROFS)
    one_line_error(
        invoke(
            "demux", stores / "S.zarr", "--out", tmp_path / "T.zarr", "--alpha", "auto", "--report", tmp_path / "ro"
        ),
        os.strerror(errno.EROFS),
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ro"]


# ---------------------------------------------------------------------------- two real runs into one output
def _planeray(*args) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "planeray.cli", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "COLUMNS": "200"},
    )


def _wait_for_lock(out: Path, proc: subprocess.Popen) -> int:
    """The pid in ``out``'s lock file, once ``proc`` holds it (fails after WAIT_S, saying what it waited for)."""
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        info = lock_holder(out)
        if info and info.get("pid") == proc.pid:
            return proc.pid
        if proc.poll() is not None:
            pytest.fail(f"the first run ended before it held the lock of {out}: {proc.stdout.read()}")
        time.sleep(0.02)
    pytest.fail(f"the first run did not take the lock of {out} within {WAIT_S:g} s")


@pytest.mark.parametrize(
    "command",
    [
        ("demux", "{d}/S.zarr", "--out", "{o}"),
        ("acquire", "--device", "replay", "--replay", "{d}/S.zarr", "--sweep", "quick", "--out", "{o}"),
    ],
    ids=["demux", "acquire"],
)
def test_a_second_run_while_the_first_writes_is_refused_and_the_first_finishes_whole(stores, tmp_path, command):
    """Run A holds its lock (stopped there with SIGSTOP); run B is refused naming A's pid; A then finishes."""
    from planeray.io import read_stack, read_transport

    out = tmp_path / "out.zarr"
    args = [a.format(d=stores, o=out) for a in command]
    first = _planeray(*args)
    try:
        pid = _wait_for_lock(out, first)
        os.kill(pid, signal.SIGSTOP)
        try:
            line = one_line_error(invoke(*args), f"another planeray run (pid {pid}) is writing it", out)
            assert "--overwrite" not in line
            line = one_line_error(invoke(*args, "--overwrite", "--restart"), f"pid {pid}")
        finally:
            os.kill(pid, signal.SIGCONT)
        output, _ = first.communicate(timeout=WAIT_S)
        assert first.returncode == 0, output
    finally:
        if first.poll() is None:
            first.kill()
            first.communicate()
    assert not lock_path(out).exists()
    if command[0] == "demux":  # what A wrote is whole: the same transport as the fixture's own demux
        np.testing.assert_array_equal(read_transport(out)[0].dense, read_transport(stores / "T.zarr")[0].dense)
    else:
        np.testing.assert_array_equal(
            np.asarray(read_stack(out).images[:]), np.asarray(read_stack(stores / "S.zarr").images[:])
        )


@pytest.mark.parametrize(
    "command",
    [
        ("render", "{d}/scene.xml", "--out", "{o}"),
        ("paper", "--quick", "--out", "{o}"),
        ("demux", "{d}/S.zarr", "--out", "{o}"),
        ("acquire", "--device", "replay", "--replay", "{d}/S.zarr", "--sweep", "quick", "--out", "{o}"),
    ],
    ids=["render", "paper", "demux", "acquire"],
)
def test_every_resumable_command_is_refused_while_another_process_holds_its_output(stores, tmp_path, holder, command):
    """The lock held by an independent process (the protocol written in this test): each resumable command is
    refused in one line naming the holder's pid before any work -- nothing written, the lock left as it was."""
    out = tmp_path / "out.zarr"
    h = holder(out)
    one_line_error(invoke(*[a.format(d=stores, o=out) for a in command]), f"another planeray run (pid {h.pid})", out)
    assert not out.exists() and not any(p.name.startswith("out.zarr.partial") for p in tmp_path.iterdir())
    assert lock_holder(out)["pid"] == h.pid
    h.release()


def test_a_killed_runs_lock_is_taken_over_with_a_note_and_the_run_resumes(stores, tmp_path):
    """A run killed (-9) while it writes leaves its lock; the next run says it takes it over and finishes."""
    from planeray.io import read_transport

    out = tmp_path / "T.zarr"
    first = _planeray("demux", stores / "S.zarr", "--out", out, "--chunk-rows", 2)
    try:
        pid = _wait_for_lock(out, first)
    finally:
        first.kill()
        first.communicate(timeout=WAIT_S)
    assert lock_holder(out)["pid"] == pid
    res = invoke("demux", stores / "S.zarr", "--out", out, "--chunk-rows", 2)
    assert res.exit_code == 0, res.output
    assert f"took over the lock of a planeray run that is no longer running (pid {pid}" in " ".join(res.output.split())
    assert not lock_path(out).exists()
    assert read_transport(out)[0].shape == (16, 12)


# ---------------------------------------------------------------------------- a disk that fills while a run writes
def test_a_disk_that_fills_during_demux_is_named_in_one_line(stores, tmp_path, monkeypatch):
    """The checks pass, then the disk fills under Zarr's chunk writes: the message names the output, not a chunk."""
    import zarr.storage

    real = zarr.storage.LocalStore.set

    async def full(self, key, value):
        if "/c/" in key or key.startswith("c/"):  # a chunk: the disk is full now
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), f"{self}/{key}")
        return await real(self, key, value)

    monkeypatch.setattr(zarr.storage.LocalStore, "set", full)
    out = tmp_path / "T.zarr"
    line = one_line_error(
        invoke("demux", stores / "S.zarr", "--out", out), f"{out}: cannot write: No space left on device [ENOSPC]"
    )
    assert "unexpected" not in line
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing finished: nothing left
