"""The rig under program control, on a real X server (Xvfb): line-velocity captures and ``rig check``.

The simulated Episcan's projector reads the screen back from the X server, so
its images follow what the real window shows; the uEye driver runs on the
stand-in SDK (``fake_pyueye``) whose camera renders through such a projector.
"""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from fake_pyueye import FakeCamera, install
from planeray.cli import app
from xvfb import display_for_tests

SIM = ["-O", "scene=diffuse_plane"]
LINES = ["--rows-per-line", "4", "--json"]


@pytest.fixture(scope="module")
def xdisplay():
    yield from display_for_tests()


def test_calibrate_lines_on_the_simulated_rig_recovers_its_line_velocity(xdisplay, tmp_path):
    runner = CliRunner()
    res = runner.invoke(
        app,
        ["calibrate", "lines", "--device", "sim", *SIM, "-O", "size=[1440, 8]", "--screen", "1", *LINES]
        + ["--write", str(tmp_path)],
    )
    assert res.exit_code == 0, res.output
    info = json.loads(res.output[res.output.index("{") :])
    # the simulated 54,000 lines/s within the reported uncertainty (2 sigma: one run of a random capture)
    assert abs(info["lines_per_second"] - 54_000.0) <= 2 * info["lines_per_second_uncertainty"], info
    assert json.loads((tmp_path / "acquisition.json").read_text())["lines_per_second"] == info["lines_per_second"]
    # the projector on the other screen: one line that says so, and nothing written
    res = runner.invoke(
        app, ["calibrate", "lines", "--device", "sim", *SIM, "-O", "size=[1440, 8]", "-O", "screen=0", "--screen", "1"]
    )
    assert res.exit_code == 1 and "sees no projector light" in res.output and len(res.output.splitlines()) == 1


def test_calibrate_lines_through_the_ueye_stand_in(xdisplay, monkeypatch):
    from planeray.devices import open_device

    sim = open_device("sim", scene="diffuse_plane", size=(1440, 8), screen=1)
    camera = FakeCamera(
        width=8, height=1440, render_global=lambda delay, exposure: sim.global_exposure(exposure, delay)[0]
    )
    install(monkeypatch, camera)
    # the rig's trigger jitter, as its user would have measured it: per frame, averaged over the sim's and the driver's 8
    jitter = sim.camera.jitter_us / np.sqrt(sim.camera.frames_averaged * 8)
    res = CliRunner().invoke(
        app, ["calibrate", "lines", "--device", "ueye", "--screen", "1", "--timing-jitter-us", str(jitter), *LINES]
    )
    assert res.exit_code == 0, res.output
    info = json.loads(res.output[res.output.index("{") :])
    assert abs(info["lines_per_second"] - 54_000.0) <= 2 * info["lines_per_second_uncertainty"], info
    assert camera.opened == camera.exited == 1
    assert camera.shutter_mode == 1  # rolling again after the capture


def test_bad_input_is_one_line(xdisplay, tmp_path):
    from planeray.acquire import acquire_to_store
    from planeray.devices import open_device
    from planeray.timing import quick_sweep

    acquire_to_store(open_device("sim", size=(16, 16)), quick_sweep(), tmp_path / "s.zarr")
    runner = CliRunner()
    for args, text in (
        (
            ["calibrate", "lines", "--device", "replay", "-O", f"replay={tmp_path / 's.zarr'}", "--screen", "1"],
            "device 'replay' has no global-shutter mode, which calibrate lines --device needs",
        ),
        (["calibrate", "lines", "--device", "sim", "--screen", "3"], "no screen 3"),
        (["rig", "check", "--device", "sim", "--screen", "3"], "no screen 3"),
    ):
        res = runner.invoke(app, args)
        assert res.exit_code == 1 and text in res.output and len(res.output.strip().splitlines()) == 1, res.output


BASE = dict(scene="diffuse_plane", size=(72, 8), screen=1, delay_error_us=37.0)
FAULTS = {
    "no_trigger": ({"trigger_wired": False}, "trigger", "no trigger on VSYNC"),
    "trigger_edge": ({"trigger_edge": "falling"}, "trigger edge", "set -O trigger_edge=rising"),
    "gamma": ({"gamma": 2.2}, "linearity", "1.37 times the value, not 2"),
    "global_shutter": ({"shutter": "global"}, "rolling shutter", "the camera is in global shutter"),
    "row_time": ({"row_time_error": 0.1}, "row time", "advance 10."),
    "other_screen": ({"screen": 0}, "projector light", "the projector shows screen 0, not screen 1"),
    "exposure_range": ({"exposure_range_us": [20, 1000]}, "ranges", "cannot reach the sweep's 600..1200 us"),
}


@pytest.fixture(scope="module")
def rig(xdisplay):
    """The window on screen 1 and the delay zero calibrated on the good rig."""
    from planeray.calibration import calibrate_delay_zero, delay_zero_sweep, device_capture
    from planeray.devices import open_device
    from planeray.projector import ProjectorWindow, white

    with ProjectorWindow(1) as window:
        window.show(white(window.shape))
        dev = open_device("sim", **BASE)
        sweep = delay_zero_sweep(exposure_us=600.0)
        zero = calibrate_delay_zero(
            device_capture(dev, exposure_us=600.0), sweep.delay_us, exposure_us=600.0, lines_per_second=54_000.0
        ).delay_zero_us
        yield window, zero


def test_rig_check_passes_the_good_rig(rig):
    from planeray.devices import open_device
    from planeray.rig import check_rig

    window, zero = rig
    assert zero == pytest.approx(-37.0, abs=1.0)
    checks = check_rig(lambda: open_device("sim", **BASE), 1, delay_zero_us=zero, window=window)
    assert [c.status for c in checks] == ["pass"] * 9, "\n".join(c.line() for c in checks)
    names = {c.name for c in checks}
    assert names == {"window", "ranges", "trigger", "projector light", "rolling shutter", "linearity", "row time"} | {
        "delay zero",
        "camera",
    }


@pytest.mark.parametrize("fault", FAULTS)
def test_rig_check_names_each_injected_fault_in_one_line(rig, fault):
    from planeray.devices import open_device
    from planeray.rig import check_rig

    window, zero = rig
    options, name, text = FAULTS[fault]
    checks = check_rig(lambda: open_device("sim", **{**BASE, **options}), 1, delay_zero_us=zero, window=window)
    failed = [c for c in checks if c.status == "fail"]
    report = "\n".join(c.line() for c in checks)
    assert [(c.name, c.fault) for c in failed] == [(name, fault)], report  # that fault, and only it
    assert text in failed[0].message and "\n" not in failed[0].message, report


def test_rig_check_cli(xdisplay, tmp_path):
    acq = tmp_path / "acquisition.json"
    acq.write_text(json.dumps({"lines_per_second": 54000.0, "delay_zero_us": -37.0}))
    opts = ["-O", "scene=diffuse_plane", "-O", "size=[72, 8]", "-O", "delay_error_us=37", "--screen", "1"]
    runner = CliRunner()
    res = runner.invoke(app, ["rig", "check", "--device", "sim", *opts, "--calibration", str(acq)])
    assert res.exit_code == 0, res.output
    assert res.output.count("PASS") == 9 and "9 of 9 checks passed" in res.output
    res = runner.invoke(app, ["rig", "check", "--device", "sim", *opts, "-O", "gamma=2.2", "--json"])
    assert res.exit_code == 1
    checks = json.loads(res.output)
    assert [c["fault"] for c in checks if c["status"] == "fail"] == ["gamma"]
    assert next(c for c in checks if c["name"] == "delay zero")["status"] == "skip"  # no calibration given
    assert np.isfinite(next(c for c in checks if c["name"] == "linearity")["details"]["ratio"])
