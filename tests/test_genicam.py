"""The GenICam driver against Aravis's fake camera: its real node map and stream, no mock of planeray's calls.

The in-process fake (``Fake_1``) is described by planeray's GenICam file (a rolling-shutter camera
with a trigger delay, a 12-bit format, gamma and auto features to switch off); its frames are checked
pixel for pixel against the fake's own generator written out in ``_genicam.fake_frame``; the trigger
delays and exposures against Eq. 1, read back from the camera's features.  Aravis's GigE Vision fake
(the same camera behind the real GVCP/GVSP protocol on 127.0.0.1) waits for a hardware trigger that
never comes.  ``make test`` installs Aravis as root; without it these tests skip, saying what to install.
"""

from __future__ import annotations

import gc
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from _genicam import as_cli, expected_image, fake_frame, fake_options, gv_fake_camera, require_aravis
from planeray import resumable
from planeray.acquire import acquire_to_store
from planeray.cli import app
from planeray.devices import open_device
from planeray.devices.capabilities import capabilities
from planeray.devices.genicam import FAKE_GENICAM_XML
from planeray.errors import DeviceError
from planeray.io import read_stack
from planeray.timing import Sweep, paper_sweep, quick_sweep

T_P = 1e6 / 54_000.0


@pytest.fixture(autouse=True)
def _aravis():
    require_aravis()


def finalized(device) -> list:
    """A list that gets an entry when the Aravis camera object behind ``device`` is freed (the device closed)."""
    done: list = []
    device._camera.weak_ref(lambda *a: done.append(1))
    return done


# ----------------------------------------------------------------------------- set-up
def test_setup_reads_back_a_rolling_triggered_linear_camera_and_releases_it():
    dev = open_device("genicam", **fake_options(pixel_format=None))
    node = dev.aravis_device
    read = {n: node.get_string_feature_value(n) for n in ("SensorShutterMode", "TriggerMode", "TriggerSource")}
    read.update({n: node.get_string_feature_value(n) for n in ("TriggerActivation", "PixelFormat", "ExposureMode")})
    read.update({n: node.get_string_feature_value(n) for n in ("ExposureAuto", "GainAuto")})
    assert read == {
        "SensorShutterMode": "Rolling",  # the fake starts in Global
        "TriggerMode": "On",
        "TriggerSource": "Software",
        "TriggerActivation": "RisingEdge",
        "PixelFormat": "Mono16",  # the first linear mono format of the preference the camera offers
        "ExposureMode": "Timed",
        "ExposureAuto": "Off",  # the fake starts Continuous
        "GainAuto": "Off",
    }
    assert (
        node.get_boolean_feature_value("GammaEnable") is False and node.get_boolean_feature_value("LUTEnable") is False
    )
    assert node.get_float_feature_value("Gain") == 1.0
    assert set(capabilities(dev)) == {
        "global_shutter",
        "trigger_edge",
        "frame_times",
        "gamma",
        "row_time",
        "ranges",
        "steps",
        "timing",
    }
    assert dev.get_gamma() == 1.0 and dev.get_row_time_us() == pytest.approx(18.5185)
    d = dev.describe()
    assert d["camera"]["camera_black_level"] == 0.0 and d["camera"]["bit_depth"] == 16 and d["image_shape"] == [16, 24]
    assert d["features"]["trigger_delay"] == "TriggerDelay" and d["features"]["exposure"] == "ExposureTime"
    # the capabilities drive the camera: global shutter and the falling edge, read back from it
    dev.set_shutter("global")
    assert node.get_string_feature_value("SensorShutterMode") == "Global" and dev.get_shutter() == "global"
    dev.set_trigger_edge("falling")
    assert node.get_string_feature_value("TriggerActivation") == "FallingEdge" and dev.get_trigger_edge() == "falling"
    freed = finalized(dev)
    dev.close()
    dev.close()
    gc.collect()
    assert freed == [1] and dev.aravis_device is None
    with pytest.raises(DeviceError, match="closed"):
        dev.grab()


def test_a_twelve_bit_format_is_selected_and_an_empty_frame_refused():
    # Mono12 is set and read back; the fake's generator draws no Mono12, so its frames come back empty: one line
    with open_device("genicam", **fake_options(pixel_format="Mono12")) as dev:
        assert dev.aravis_device.get_string_feature_value("PixelFormat") == "Mono12" and dev.bit_depth == 12
        dev.set_timing(0.0, 600.0)
        with pytest.raises(DeviceError, match=r"delivered 0 bytes for a 24x16 Mono12 frame \(768 expected\)"):
            dev.grab()


# ----------------------------------------------------------------------------- a sweep, pixel for pixel
def test_a_sweep_is_the_cameras_frames_with_eq1_trigger_delays_and_resumes_after_an_interruption(tmp_path):
    sweep, out, seen = quick_sweep(), tmp_path / "s.zarr", {}
    base = fake_options()["base_trigger_delay_us"]

    def recorder(dev):
        node = dev.aravis_device

        def progress(i):
            if i not in seen:  # a resumed capture reports the images found captured too
                exposure, trigger = (
                    node.get_float_feature_value("ExposureTime"),
                    node.get_float_feature_value("TriggerDelay"),
                )
                seen[i] = (dev.frame_ids(), exposure, trigger)

        return progress

    with open_device("genicam", **fake_options()) as dev:
        acquire_to_store(dev, sweep, out, _stop_after=10, progress=recorder(dev))  # "killed" after 10 images
    assert sorted(seen) == list(range(10)) and not out.exists()
    with open_device("genicam", **fake_options()) as dev:  # a fresh process: the camera opened again
        acquire_to_store(dev, sweep, out, progress=recorder(dev))
    st = read_stack(out, lazy=False)
    assert sorted(seen) == list(range(len(sweep))) and st.metadata["device"] == "genicam"
    for part in (range(10), range(10, len(sweep))):  # each opening of the fake counts its frames from 65401
        ids = [f for i in part for f in seen[i][0]]
        assert len(set(ids)) == len(ids)  # no frame taken twice
    for i, (d, e) in enumerate(zip(sweep.delay_us, sweep.exposure_us)):
        frame_ids, exposure, trigger = seen[i]
        assert exposure == e
        t_o = e / 2 - T_P / 2 - d  # Eq. 1, inverted
        assert trigger == np.floor(base - t_o)  # the camera's whole-us register
        np.testing.assert_array_equal(st.images[i], expected_image(frame_ids, (16, 24), exposure, gain=1))
    np.testing.assert_array_equal(st.delay_us, sweep.delay_us)


# ----------------------------------------------------------------------------- the command line
def _done(out: Path) -> int:
    partial = resumable.partial_path(out)
    if not partial.exists():
        return 0
    try:
        import zarr

        return int(resumable.done_units(zarr.open_group(str(partial), mode="r")).sum())
    except Exception:
        return 0


def _frame_id_of(image, exposure_us, gain=1):
    """Which of the fake's frames ``image`` is (its ids run from 65401, wrapping to 1 after 65535)."""
    for fid in [*range(65401, 65536), *range(1, 4000)]:
        if np.array_equal(image, expected_image([fid], image.shape, exposure_us, gain)):
            return fid
    return None


def test_cli_acquire_is_killed_resumed_and_each_image_is_a_frame_of_the_camera(tmp_path):
    opts = as_cli(fake_options(fake_trigger_hz=40.0))
    out = tmp_path / "s.zarr"
    args = ["acquire", "--device", "genicam", *opts, "--sweep", "paper", "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parents[1] / "src"), *sys.path])}
    proc = subprocess.Popen([sys.executable, "-m", "planeray.cli", *args], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while _done(out) < 5 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)  # killed mid-capture: nothing runs after this
    finally:
        proc.wait()
    killed_at = _done(out)
    assert 5 <= killed_at < len(paper_sweep()) and not out.exists()
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    assert f"resuming an unfinished capture of {out}: {killed_at} of 85 images already captured" in res.output
    st = read_stack(out, lazy=False)
    ids = [_frame_id_of(st.images[i], e) for i, e in enumerate(st.exposure_us)]
    assert None not in ids  # every image is one of the camera's frames
    for part in (ids[:killed_at], ids[killed_at:]):  # each run's camera counts its frames from 65401
        assert len(set(part)) == len(part)  # each taken once


def test_a_missing_feature_is_one_line_naming_it_and_the_camera_is_released(monkeypatch, tmp_path):
    from gi.repository import Aravis

    opened = []
    new = Aravis.Camera.new

    def spy(device_id):
        camera = new(device_id)
        camera.weak_ref(lambda *a: opened.append("freed"))
        opened.append("opened")
        return camera

    monkeypatch.setattr(Aravis.Camera, "new", spy)
    # an older camera: ExposureTimeAbs (Basler's name, which the driver takes), and no trigger delay at all
    xml = FAKE_GENICAM_XML.read_text(encoding="utf-8").replace('"ExposureTime"', '"ExposureTimeAbs"')
    start = xml.index('<Float Name="TriggerDelay"')
    xml = xml[:start] + xml[xml.index("</Float>", start) + len("</Float>") :]
    assert "ExposureTimeAbs" in xml and 'Name="TriggerDelay"' not in xml
    older = tmp_path / "older.xml"
    older.write_text(xml.replace("<pFeature>TriggerDelay</pFeature>", ""), encoding="utf-8")
    message = None
    try:
        open_device("genicam", **fake_options(fake_genicam_xml=str(older)))
    except DeviceError as exc:  # handled: its traceback (and every frame it kept) goes with it
        message = str(exc)
    gc.collect()
    assert message == (
        "camera Fake_1 has no TriggerDelay or TriggerDelayAbs feature, which the rig needs to realize the delay t_d "
        "(Eq. 1)"
    )
    assert opened == ["opened", "freed"]
    res = CliRunner().invoke(app, ["acquire", "--device", "genicam", *as_cli(fake_options(fake_genicam_xml=str(older))),
                                   "--out", str(tmp_path / "x.zarr")])  # fmt: skip
    assert res.exit_code == 1 and "has no TriggerDelay" in res.output and len(res.output.strip().splitlines()) == 1


def test_a_camera_that_vanishes_mid_sweep_is_one_line_released_and_nothing_half_written(tmp_path):
    out = tmp_path / "s.zarr"
    dev = open_device("genicam", **fake_options())
    freed = finalized(dev)

    def vanish(i):
        if i == 3:  # what Aravis signals when a camera's link drops (a GigE heartbeat lost, a USB cable pulled)
            dev.aravis_device.emit("control-lost")

    with pytest.raises(DeviceError, match=r"camera Fake_1 vanished \(Aravis lost control of it") as err:
        acquire_to_store(dev, quick_sweep(), out, progress=vanish)
    assert "\n" not in str(err.value)
    dev.close()
    gc.collect()
    assert freed == [1] and not out.exists() and _done(out) == 4  # the four images taken, marked; nothing else
    with open_device("genicam", **fake_options()) as again:  # and the capture resumes
        acquire_to_store(again, quick_sweep(), out)
    assert len(read_stack(out)) == len(quick_sweep())


def test_a_trigger_that_never_comes_says_what_it_waited_for_and_the_camera_is_released():
    with gv_fake_camera(f"PRT{os.getpid()}") as device_id:
        dev = open_device("genicam", **fake_options(camera_id=device_id, trigger_source="Line0", trigger_timeout_s=0.3))
        dev.set_timing(0.0, 600.0)
        t0 = time.monotonic()
        with pytest.raises(DeviceError) as err:
            dev.grab()  # the GigE fake waits for its Line0, which nothing drives
        assert time.monotonic() - t0 < 3.0
        assert str(err.value) == (
            "no trigger on Line0 (rising edge) within 0.3 s (waiting for frame 1 of 2): is the projector on, and its "
            "VSYNC wired to the camera's Line0 input?"
        )
        dev.close()
        # released: a GigE Vision camera takes a new controller only once the last one let go
        with open_device("genicam", **fake_options(camera_id=device_id)) as again:
            again.set_timing(0.0, 600.0)
            image, _ = again.grab()
            np.testing.assert_array_equal(image, expected_image(again.frame_ids(), (16, 24), 600.0, gain=1))


# ----------------------------------------------------------------------------- calibration and rig check
def test_calibrate_delay_zero_runs_against_the_camera_and_says_it_sees_no_response():
    # gain 0 at 1000 us: the fake's ramp is scaled by 1 + 0 + log10(0.1) = 0 -- a camera that sees nothing
    opts = as_cli(fake_options(gain=0))
    res = CliRunner().invoke(
        app,
        ["calibrate", "delay-zero", "--device", "genicam", *opts, "--exposure-us", "1000", "--frame-period-us", "2000"],
    )
    assert res.exit_code == 1 and "Traceback" not in res.output
    assert "no epipolar response over one projector frame" in res.output and len(res.output.strip().splitlines()) == 1


def test_rig_check_runs_against_the_camera(tmp_path):
    from xvfb import display_for_tests

    gen = display_for_tests()
    display = next(gen)
    try:
        # gain 0 at 600 us: the fake's ramp is scaled by 1 + 0 + log10(0.06) < 0, black -- it sees no projector
        opts = as_cli(fake_options(frames_averaged=4, fake_trigger_hz=60.0, gain=0))
        res = CliRunner().invoke(
            app,
            ["rig", "check", "--device", "genicam", *opts, "--screen", "1", "--display", display, "--sweep", "quick"]
            + ["--frame-rate-hz", "60", "--json"],
        )
    finally:
        gen.close()
    checks = {c["name"]: c for c in json.loads(res.output[res.output.index("[") :])}
    assert res.exit_code == 1  # the fake camera cannot see the projector
    assert checks["ranges"]["status"] == "pass" and checks["window"]["status"] == "pass"
    period = re.search(r"a frame every ([\d.]+) ms", checks["trigger"]["message"])
    assert checks["trigger"]["status"] == "pass" and period, checks["trigger"]
    assert float(period.group(1)) == pytest.approx(1000 / 60, rel=0.05)  # the fake's 60 Hz, on a loaded machine
    assert checks["projector light"]["fault"] == "no_light"
    assert checks["camera"]["status"] == "pass"  # found, and released: it opened again
    assert {checks[n]["status"] for n in ("rolling shutter", "linearity", "row time", "delay zero")} == {"skip"}


def test_fake_frame_is_the_generator_not_planerays_reading_of_it():
    # a test that cannot fail is a defect: the written-out generator differs between frames and exposures
    a, b = fake_frame(65401, (4, 4), 600.0, 2), fake_frame(65402, (4, 4), 600.0, 2)
    assert not np.array_equal(a, b) and not np.array_equal(a, fake_frame(65401, (4, 4), 900.0, 2))
    assert a[0, 0] == 55533  # 256 * 65401 mod 65535 = 31231, times 3 + log10(0.06): read off a frame of Aravis 0.8.26


def test_sweep_points_the_camera_cannot_realize_are_refused_with_the_reason():
    with open_device("genicam", **fake_options(base_trigger_delay_us=500.0)) as dev:
        with pytest.raises(DeviceError, match=r"needs trigger delay -1590.7 us .* outside the camera's 0..1e\+06 us"):
            dev.set_timing(-1500.0, 1200.0)
        with pytest.raises(DeviceError, match="outside the camera's range 10..1e"):
            dev.set_timing(0.0, 5.0)
    with open_device("genicam", **fake_options(base_trigger_delay_us=None)) as dev:
        with pytest.raises(DeviceError, match="base trigger delay is not calibrated"):
            dev.set_timing(0.0, 600.0)
    assert len(Sweep.grid([0.0], [600.0])) == 1
