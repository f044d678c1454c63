"""The device registry: adding a camera is one module (or one plug-in entry point), and the CLI needs no change."""

import inspect

import numpy as np
import pytest
from typer.testing import CliRunner

import planeray.devices.base as base
from planeray.acquire import acquire_sweep
from planeray.cli import app
from planeray.devices import (
    DeviceBase,
    apply_timing,
    device_options,
    list_devices,
    open_device,
    register_device,
)
from planeray.errors import InputError
from planeray.io import read_stack
from planeray.scenes import make_scene
from planeray.timing import quick_sweep


@pytest.fixture
def registry(monkeypatch):
    """A scratch copy of the registry, so test devices do not outlive the test."""
    list_devices()  # discover the built-in devices first
    monkeypatch.setattr(base, "_REGISTRY", dict(base._REGISTRY))
    monkeypatch.setattr(base, "_BROKEN", {})
    return base._REGISTRY


class ToyCamera(DeviceBase):
    """A camera written by a lab: the four calls, a flat image that depends on the delay."""

    kind = "toy"

    def __init__(self, *, gain: float = 1.0, lines_per_second: float = 54_000.0):
        self.gain, self.lines_per_second = gain, lines_per_second
        self.delay_us, self.exposure_us, self.closed = 0.0, 600.0, 0

    def set_delay(self, delay_us):
        self.delay_us = delay_us

    def set_exposure(self, exposure_us):
        self.exposure_us = exposure_us

    def grab(self):
        img = np.full((4, 5), self.gain * (1.0 + self.delay_us / 1e4), np.float32)
        return img, np.zeros(img.shape, bool)

    def describe(self):
        return {"device": self.kind, "image_shape": [4, 5], "gain": self.gain}

    def close(self):
        self.closed += 1


def test_built_in_devices_are_registered():
    assert {"sim", "replay", "ueye"} <= set(list_devices())
    assert device_options("replay") == {"replay": inspect.Parameter.empty}


def test_a_registered_camera_is_usable_from_the_cli_without_touching_it(registry, tmp_path):
    opened = []

    @register_device("toy", "a lab's own camera", hardware=True)
    def open_toy(*, gain: float = 1.0, lines_per_second: float = 54_000.0):
        opened.append(ToyCamera(gain=gain, lines_per_second=lines_per_second))
        return opened[-1]

    runner = CliRunner()
    res = runner.invoke(app, ["devices"])
    assert res.exit_code == 0 and "toy" in res.output and "gain=1.0" in res.output
    acq = tmp_path / "acquisition.json"
    acq.write_text('{"lines_per_second": 50000.0, "base_trigger_delay_us": 1234.0}')
    res = runner.invoke(
        app,
        ["acquire", "--device", "toy", "-O", "gain=2.5", "--calibration", str(acq), "--sweep", "quick"]
        + ["--out", str(tmp_path / "toy.zarr")],
    )
    assert res.exit_code == 0, res.output
    st = read_stack(tmp_path / "toy.zarr")
    assert st.metadata["gain"] == 2.5 and st.lines_per_second == 50000.0  # the calibration filled v_p
    assert opened[0].closed == 1  # the CLI released it
    res = runner.invoke(app, ["acquire", "--device", "toy", "-O", "exposure=3", "--out", str(tmp_path / "x.zarr")])
    assert res.exit_code == 1 and "-O exposure: device 'toy' has no option 'exposure'" in res.output
    res = runner.invoke(app, ["acquire", "--device", "toy", "-O", "gain", "--out", str(tmp_path / "x.zarr")])
    assert res.exit_code == 1 and "KEY=VALUE" in res.output


def test_plug_ins_register_through_entry_points(registry, monkeypatch):
    class EntryPoint:
        def __init__(self, name, load):
            self.name, self.load = name, load

    def load_good():
        register_device("plugged", "from another package")(ToyCamera)

    def load_broken():
        raise ImportError("vendor SDK missing")

    import importlib.metadata

    monkeypatch.setattr(
        importlib.metadata,
        "entry_points",
        lambda group: (
            [EntryPoint("plugged", load_good), EntryPoint("vendor", load_broken)]
            if group == base.ENTRY_POINT_GROUP
            else []
        ),
    )
    monkeypatch.setattr(base, "_DISCOVERED", False)
    assert "plugged" in list_devices()
    assert isinstance(open_device("plugged", gain=3.0), ToyCamera)
    with pytest.raises(InputError, match="its plug-in failed to load: ImportError: vendor SDK missing"):
        open_device("vendor")


def test_open_device_errors_name_the_problem():
    with pytest.raises(InputError, match="unknown device 'nope'; choose one of .*sim"):
        open_device("nope")
    with pytest.raises(InputError, match="device 'replay' needs the option replay"):
        open_device("replay")
    with pytest.raises(InputError, match="has no options 'a', 'b'"):
        open_device("sim", a=1, b=2)


def test_runner_drives_older_devices_without_set_timing():
    class Old:
        lines_per_second = 54_000.0

        def __init__(self):
            self.calls = []

        def set_delay(self, d):
            self.calls.append(("delay", d))

        def set_exposure(self, e):
            self.calls.append(("exposure", e))

        def grab(self):
            return np.zeros((2, 2), np.float32), np.zeros((2, 2), bool)

        def describe(self):
            return {"device": "old"}

    dev = Old()
    apply_timing(dev, -1.0, 600.0)
    assert dev.calls == [("exposure", 600.0), ("delay", -1.0)]
    assert len(acquire_sweep(Old(), quick_sweep())) == 27


def test_simulated_device_is_unchanged_by_set_timing():
    scene = make_scene("corner", (16, 12), projector_rows=60, seed=1)
    old = open_device("sim", scene="corner", size=(16, 12), projector_rows=60, seed=1)
    new = open_device("sim", scene="corner", size=(16, 12), projector_rows=60, seed=1)
    assert old.scene.params == scene.params
    for d, e in zip(quick_sweep().delay_us, quick_sweep().exposure_us):
        old.set_delay(d)
        old.set_exposure(e)
        new.set_timing(d, e)
        np.testing.assert_array_equal(old.grab()[0], new.grab()[0])  # same seeds, same bytes
