"""The live plumbing (:mod:`planeray.live`): continuous capture, the pulse of a rolling window, snapshots.

The pulse is read from the simulated pulsing skin, whose veins' blood volume follows a rate the test
chooses, within 10 s of video on the device's clock; frames are compared with what another instance
of the device renders at the same timing; a device that fails ends the capture in one line and is
closed; a snapshot reads back as a stack that ``planeray skin``'s readers take.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from typer.testing import CliRunner

from planeray.cli import app
from planeray.devices import open_device
from planeray.errors import DeviceError, InputError
from planeray.io import read_stack
from planeray.live import LiveCapture, PulseMonitor, composite_view, cycle_delays, snapshot_path, write_snapshot
from planeray.skin.enhance import enhance_contrast
from planeray.skin.imaging import delay_sweep_images


def _until(predicate, timeout_s=60.0):
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


def test_the_live_pulse_reads_the_simulated_rate_within_2_bpm_from_10_s_of_video():
    bpm = 83.0  # not a round number of bins of a 10 s window (6 bpm)
    dev = open_device("sim", scene="skin", size=(48, 48), pulse_bpm=bpm, frames_averaged=1, sensor_rows=1200, seed=3)
    timing = (450.0, 1200.0)
    with LiveCapture(dev, delay_us=timing[0], exposure_us=timing[1], history=700) as live:
        _until(lambda: live.frames_captured >= 601)
        frames = live.window(10.0, timing=timing)
    span = frames[-1].time_s - frames[0].time_s
    assert span == pytest.approx(10.0) and len(frames) == 601  # 10 s of the rig's 60 Hz clock
    result = PulseMonitor().analyze(frames)
    assert result["detected"] and abs(result["rate_bpm"] - bpm) <= 2.0, result["rate_bpm"]
    assert result["timing"] == list(timing) and len(result["spectrum"]["bpm"]) > 10


def test_without_a_pulse_no_rate_is_reported():
    # the same skin, not pulsing: the detector must not invent a rate (a test that could pass on any output fails here)
    dev = open_device("sim", scene="skin", size=(48, 48), frames_averaged=1, sensor_rows=1200, seed=3)
    with LiveCapture(dev, delay_us=450.0, exposure_us=1200.0, history=700) as live:
        _until(lambda: live.frames_captured >= 601)
        frames = live.window(10.0)
    assert PulseMonitor().analyze(frames)["rate_bpm"] is None


def test_frames_follow_the_timing_and_the_cycle_asked_for():
    options = dict(scene="diffuse_plane", size=(8, 12), projector_rows=90, noise=False, frames_averaged=1)
    reference = open_device("sim", **options)
    with LiveCapture(open_device("sim", **options)) as live:
        live.set_timing(375.0, 900.0)
        frame = live.wait_frame(timing=(375.0, 900.0), timeout_s=30)
        reference.set_timing(375.0, 900.0)
        np.testing.assert_array_equal(frame.image, reference.grab()[0])
        delays = cycle_delays(600.0)
        live.set_cycle(delays, 600.0)
        cycle = live.wait_cycle(delays, 600.0, after=frame.index, timeout_s=30)
        assert [f.delay_us for f in cycle] == list(delays) and min(f.index for f in cycle) > frame.index
        image, used = composite_view(cycle)
        expected = enhance_contrast(np.stack([f.image for f in cycle]), delays).image
        np.testing.assert_array_equal(image, expected.astype(np.float32))
        assert used["delays_us"] == list(delays)


def test_a_device_that_fails_ends_the_capture_in_one_line_and_is_closed():
    dev = open_device("sim", scene="diffuse_plane", size=(8, 8), trigger_wired=False, frames_averaged=1)
    closed = []
    dev.close = lambda: closed.append(1)
    live = LiveCapture(dev).start()
    with pytest.raises(DeviceError) as err:
        live.wait_frame(timeout_s=30)
    assert str(err.value).startswith("the capture stopped: no trigger on VSYNC within 1 s")
    assert "\n" not in str(err.value)
    _until(lambda: closed == [1], 10)
    live.stop()
    assert closed == [1]


def test_a_frame_that_never_comes_says_what_was_waited_for():
    with LiveCapture(open_device("sim", scene="diffuse_plane", size=(8, 8), frames_averaged=1)) as live:
        with pytest.raises(
            DeviceError, match=r"no frame at delay 123 us, exposure 456 us from the device within 0.05 s"
        ):
            live.wait_frame(timing=(123.0, 456.0), timeout_s=0.05)


def test_a_snapshot_of_a_cycle_is_a_stack_the_skin_commands_read(tmp_path):
    options = dict(scene="skin", size=(16, 16), frames_averaged=1, noise=False)
    with LiveCapture(open_device("sim", **options)) as live:
        delays = cycle_delays(600.0)
        live.set_cycle(delays, 600.0)
        cycle = live.wait_cycle(delays, 600.0, timeout_s=30)
        description = live.device.describe()
    out = snapshot_path(tmp_path, "composite", now=0.0)
    write_snapshot(cycle, out, device=description, lines_per_second=54_000.0, projector_rows=16, view="composite")
    st = read_stack(out, lazy=False)
    np.testing.assert_array_equal(st.images, np.stack([f.image for f in cycle]))
    assert st.metadata["live"]["frame_indices"] == [f.index for f in cycle] and st.metadata["scene"]["name"] == "skin"
    images, got, _ = delay_sweep_images(st)  # what `planeray skin enhance` reads
    assert got.tolist() == list(delays) and images.shape == (len(delays), 16, 16)
    assert snapshot_path(tmp_path, "composite", now=0.0) != out  # never the same name twice
    with pytest.raises(InputError):
        write_snapshot(cycle, out, device=description, lines_per_second=54_000.0)  # nor written over


def test_view_refuses_bad_combinations_in_one_line(tmp_path):
    runner = CliRunner()
    for args, message in (
        (["view"], "give a PATH (a scene, a transport store or a stack) or --device NAME"),
        (["view", "wax", "--device", "sim"], "give a PATH (a scene, a transport store or a stack) or --device NAME"),
        (["view", "wax", "-O", "size=[8, 8]"], "--device-option applies to --device only"),
        (["view", "--device", "sim", "--snapshots", str(tmp_path / "none")], "--snapshots must be an existing folder"),
        (["view", "--device", "sim", "-O", "scene=wax", "-O", "pulse_bpm=70"], "pulse_bpm needs -O scene='skin'"),
        (["view", "--device", "nothing"], "unknown device 'nothing'"),
        (["view", "--device", "ueye"], "device 'ueye' needs its base trigger delay"),
    ):
        res = runner.invoke(app, [*args, "--no-browser"])
        assert res.exit_code == 1 and message in res.output and "Traceback" not in res.output, (args, res.output)
