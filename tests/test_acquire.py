"""Acquisition: device protocol and registry, resumable sweep runner, replay device (the uEye driver: test_ueye.py)."""

import numpy as np
import pytest
import zarr
from typer.testing import CliRunner

from planeray.acquire import acquire_sweep, acquire_to_store
from planeray.cli import app
from planeray.devices import Device, ReplayDevice, SimulatedEpiscan
from planeray.errors import InputError, StackError
from planeray.io import read_stack
from planeray.scenes import make_scene
from planeray.timing import paper_sweep, quick_sweep


@pytest.fixture
def device():
    return SimulatedEpiscan(make_scene("corner", (24, 20), projector_rows=90, seed=1), seed=3)


def test_devices_implement_the_protocol(device):
    assert isinstance(device, Device)
    stack = acquire_sweep(device, quick_sweep())
    assert isinstance(ReplayDevice(stack), Device)


def test_interrupted_capture_resumes_to_an_identical_stack(tmp_path):
    scene = make_scene("corner", (24, 20), projector_rows=90, seed=1)
    full = acquire_to_store(SimulatedEpiscan(scene, seed=3), paper_sweep(), tmp_path / "full.zarr")
    out = tmp_path / "resumed.zarr"
    partial = acquire_to_store(SimulatedEpiscan(scene, seed=3), paper_sweep(), out, _stop_after=30)  # "killed"
    assert not out.exists()
    assert zarr.open_group(str(partial), mode="r")["done_units"][:].sum() == 30
    seen = []
    acquire_to_store(SimulatedEpiscan(scene, seed=3), paper_sweep(), out, progress=seen.append)  # a fresh process
    assert sorted(seen) == list(range(85))  # every image once: none lost, none duplicated
    a, b = read_stack(full, lazy=False), read_stack(out, lazy=False)
    np.testing.assert_array_equal(a.images, b.images)
    np.testing.assert_array_equal(a.delay_us, b.delay_us)
    assert a.metadata == b.metadata
    assert b.metadata["seed"] == 3 and b.metadata["sweep"] == "paper"  # what it takes to reproduce it


def test_resume_refuses_another_capture(tmp_path, device):
    out = tmp_path / "s.zarr"
    acquire_to_store(device, paper_sweep(), out, _stop_after=3)
    with pytest.raises(InputError, match="unfinished run"):
        acquire_to_store(device, quick_sweep(), out)
    acquire_to_store(device, quick_sweep(), out, restart=True)
    assert len(read_stack(out)) == 27
    with pytest.raises(StackError, match="already exists"):
        acquire_to_store(device, quick_sweep(), out)


def test_replay_device_serves_the_recording(tmp_path, device):
    rec = acquire_sweep(device, quick_sweep())
    replay = ReplayDevice(rec, source="rec")
    again = acquire_sweep(replay, quick_sweep())
    np.testing.assert_array_equal(again.images, rec.images)
    replay.set_delay(12.3)
    with pytest.raises(InputError, match="no image at delay 12.3"):
        replay.grab()


def test_acquire_cli(tmp_path):
    runner = CliRunner()
    res = runner.invoke(
        app,
        [
            "acquire",
            "--device",
            "sim",
            "--scene",
            "diffuse_plane",
            "--size",
            "16",
            "16",
            "--sweep",
            "quick",
            "--out",
            str(tmp_path / "a.zarr"),
        ],
    )
    assert res.exit_code == 0, res.output
    res = runner.invoke(
        app,
        [
            "acquire",
            "--device",
            "replay",
            "--replay",
            str(tmp_path / "a.zarr"),
            "--sweep",
            "quick",
            "--out",
            str(tmp_path / "b.zarr"),
        ],
    )
    assert res.exit_code == 0, res.output
    np.testing.assert_array_equal(read_stack(tmp_path / "b.zarr").images[:], read_stack(tmp_path / "a.zarr").images[:])
