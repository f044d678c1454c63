"""The IDS uEye driver against a fake ``pyueye.ueye`` (``fake_pyueye``): no SDK, no camera, same on every machine.

The fake checks the ctypes of every argument and the order of calls, and
returns error codes on demand; its camera renders what a rolling-shutter camera
triggered by the projector's VSYNC sees, through the simulated Episcan, with a
hidden base trigger delay that the calibration has to find.
"""

import json
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from fake_pyueye import CONSTANTS, FakeCamera, install, uninstall
from planeray.acquire import acquire_sweep, acquire_to_store
from planeray.calibration import (
    calibrate_base_trigger_delay,
    delay_zero_sweep,
    required_base_trigger_delay_us,
    write_calibration,
)
from planeray.cli import app
from planeray.devices import Device, SimulatedEpiscan, UEyeEpiscan, open_device
from planeray.errors import DeviceError, InputError
from planeray.io import read_stack
from planeray.scenes import make_scene
from planeray.timing import paper_sweep, quick_sweep, sync_offset_from_delay

C = CONSTANTS
ROLLING = C["IS_DEVICE_FEATURE_CAP_SHUTTER_MODE_ROLLING"]
T_P = 1e6 / 54_000.0


def names(camera):
    return [c[0] for c in camera.calls]


def calls_of(camera, name):
    return [c[1:] for c in camera.calls if c[0] == name]


@pytest.fixture
def camera(monkeypatch):
    cam = FakeCamera()
    install(monkeypatch, cam)
    return cam


def scene_renderer(scene):
    """``render(delay, exposure)`` of the noise-free simulated Episcan: what the fake camera sees."""
    sim = SimulatedEpiscan(scene, noise=False)

    def render(delay_us, exposure_us):
        sim.set_timing(delay_us, exposure_us)
        return sim.grab()[0]

    return render


# ----------------------------------------------------------------------------- opening
def test_without_pyueye_the_driver_says_what_is_missing(monkeypatch):
    uninstall(monkeypatch)
    with pytest.raises(DeviceError, match="pyueye"):
        UEyeEpiscan(base_trigger_delay_us=3000.0)


@pytest.mark.parametrize(
    ("option", "match"),
    [
        ({"bit_depth": 8}, "bit_depth must be 12 or 10"),
        ({"frames_averaged": 0}, "frames_averaged"),
        ({"black_level": 4095}, "black_level"),
        ({"trigger_edge": "up"}, "trigger_edge"),
        ({"pixel_clock_mhz": 0}, "pixel_clock_mhz"),
        ({"parameter_file": "nowhere/rig.ini"}, "parameter file not found"),
        ({"trigger_timeout_s": 0.0}, "trigger_timeout_s"),
    ],
)
def test_bad_options_are_refused_before_the_camera_is_touched(camera, option, match):
    with pytest.raises(InputError, match=match):
        UEyeEpiscan(**option)
    assert camera.calls == []


def test_setup_selects_rolling_shutter_trigger_and_a_linear_12_bit_response(camera):
    with UEyeEpiscan(base_trigger_delay_us=3000.0) as dev:
        assert isinstance(dev, Device)
        assert names(camera)[0] == "is_InitCamera"
        # rolling shutter: capability checked, selected, read back
        features = calls_of(camera, "is_DeviceFeature")
        assert features == [
            (C["IS_DEVICE_FEATURE_CMD_GET_SUPPORTED_FEATURES"], 0),
            (C["IS_DEVICE_FEATURE_CMD_SET_SHUTTER_MODE"], ROLLING),
            (C["IS_DEVICE_FEATURE_CMD_GET_SHUTTER_MODE"], 0),
        ]
        assert camera.shutter_mode == ROLLING  # the camera started in global shutter
        assert camera.color_mode == C["IS_CM_MONO12"]
        assert camera.trigger_mode == C["IS_SET_TRIGGER_LO_HI"]
        assert camera.timeout_units == 100  # 1 s in 10 ms units
        assert camera.autos_on == set()  # every auto feature off
        assert calls_of(camera, "is_SetHardwareGamma") == [(C["IS_SET_HW_GAMMA_OFF"],)]
        assert calls_of(camera, "is_Gamma") == [(C["IS_GAMMA_CMD_SET"], 100)]
        assert calls_of(camera, "is_LUT") == [(C["IS_LUT_CMD_SET_ENABLED"], C["IS_LUT_DISABLED"])]
        assert calls_of(camera, "is_SetGainBoost") == [(C["IS_SET_GAINBOOST_OFF"],)]
        assert calls_of(camera, "is_EdgeEnhancement") == [(C["IS_EDGE_ENHANCEMENT_CMD_SET"], 0)]
        # the image buffer: 16-bit pixels, the real (padded) pitch read from the SDK
        assert calls_of(camera, "is_AllocImageMem") == [(24, 16, 16)]
        assert dev.pitch == camera.pitch == 2 * 24 + 8
        assert dev.describe()["image_shape"] == [16, 24]
        # nothing is captured or timed while opening
        assert "is_FreezeVideo" not in names(camera)
        assert [a for a in calls_of(camera, "is_SetTriggerDelay") if a[0] < 0x8000] == []
    assert camera.exited == 1 and not camera.open
    assert names(camera)[-2:] == ["is_FreeImageMem", "is_ExitCamera"]


def test_a_camera_without_rolling_shutter_or_that_stays_global_is_refused_and_released(monkeypatch):
    for cam, match in (
        (FakeCamera(supports_rolling=False), "no rolling-shutter mode"),
        (FakeCamera(ignores_shutter_mode=True), "did not switch to rolling shutter"),
    ):
        install(monkeypatch, cam)
        with pytest.raises(DeviceError, match=match):
            UEyeEpiscan(base_trigger_delay_us=3000.0)
        assert cam.exited == 1 and not cam.open


def _setup_calls():
    """Every SDK call the setup makes after is_InitCamera, as (name, command) keys of FakeCamera.fail."""
    cam = FakeCamera()
    with pytest.MonkeyPatch.context() as mp:
        install(mp, cam)
        UEyeEpiscan(pixel_clock_mhz=40).close()
    keys = []
    commanded = {"is_DeviceFeature", "is_PixelClock", "is_Exposure", "is_AOI", "is_SetTriggerDelay", "is_SetColorMode"}
    for name, *args in cam.calls[1:]:
        if name in ("is_FreeImageMem", "is_ExitCamera"):
            break
        key = (name, args[0]) if name in commanded or name == "is_SetAutoParameter" else name
        if key not in keys:
            keys.append(key)
    return keys


@pytest.mark.parametrize("failing", _setup_calls(), ids=str)
def test_every_failed_setup_call_releases_the_camera(monkeypatch, failing):
    cam = FakeCamera()
    install(monkeypatch, cam)
    cam.fail[failing] = -1  # IS_NO_SUCCESS
    with pytest.raises(DeviceError):
        UEyeEpiscan(pixel_clock_mhz=40)
    assert cam.exited == 1 and not cam.open, names(cam)
    assert cam.memory == {}  # no image memory left behind
    # and the camera is not locked: the next open works
    cam.fail.clear()
    UEyeEpiscan(pixel_clock_mhz=40).close()
    assert cam.opened == 2


def test_setup_interrupted_by_the_user_releases_the_camera(camera):
    def interrupt(*args):
        raise KeyboardInterrupt

    sys.modules["pyueye"].ueye.is_AllocImageMem = interrupt
    with pytest.raises(KeyboardInterrupt):
        UEyeEpiscan()
    assert camera.exited == 1 and not camera.open


def test_failed_init_is_reported_and_a_camera_left_open_is_named(camera):
    camera.fail["is_InitCamera"] = 3
    with pytest.raises(DeviceError, match=r"is_InitCamera returned 3 \(IS_CANT_OPEN_DEVICE\)"):
        UEyeEpiscan()
    assert camera.exited == 0  # nothing was opened
    camera.fail.clear()
    first = UEyeEpiscan()
    with pytest.raises(DeviceError, match="not in use by another program"):
        UEyeEpiscan()  # the camera is still held by `first`
    first.close()
    first.close()  # idempotent
    assert camera.exited == 1
    UEyeEpiscan().close()


def test_switches_a_model_lacks_are_recorded_not_fatal(monkeypatch):
    cam = FakeCamera(unsupported={"is_LUT", "is_SetHardwareGamma", "is_EdgeEnhancement"})
    install(monkeypatch, cam)
    with UEyeEpiscan() as dev:
        assert dev.describe()["unsupported_switches"] == ["hardware gamma off", "LUT off", "edge enhancement off"]


def test_pixel_clock_and_parameter_file_then_aoi_and_exposure_are_read_again(tmp_path, monkeypatch):
    ini = tmp_path / "rig.ini"
    ini.write_text("[Timing]\nPixelclock=40\n")
    cam = FakeCamera(width=32, height=20)
    install(monkeypatch, cam)
    with UEyeEpiscan(pixel_clock_mhz=40, parameter_file=ini) as dev:
        order = names(cam)
        assert order[1] == "is_ParameterSet" and cam.parameter_file == str(ini)  # first, before anything it overrides
        assert calls_of(cam, "is_ParameterSet") == [(C["IS_PARAMETERSET_CMD_LOAD_FILE"], str(ini))]
        i_set = cam.calls.index(("is_PixelClock", C["IS_PIXELCLOCK_CMD_SET"]))
        assert i_set > order.index("is_DeviceFeature")  # after the shutter mode (which changes its range)
        assert order.index("is_AOI") > i_set and order.index("is_Exposure") > i_set  # AOI and exposure re-read
        assert cam.pixel_clock_mhz == dev.pixel_clock_mhz == 40
        assert dev.describe()["image_shape"] == [20, 32]
    cam2 = FakeCamera(pixel_clock_range_mhz=(5, 35, 1))
    install(monkeypatch, cam2)
    with pytest.raises(DeviceError, match="pixel clock 40 MHz is outside the camera's 5..35 MHz"):
        UEyeEpiscan(pixel_clock_mhz=40)
    assert cam2.exited == 1


# ----------------------------------------------------------------------------- timing (Eq. 1)
def test_trigger_delay_follows_eq1_with_the_exposure_the_camera_really_set(monkeypatch):
    cam = FakeCamera(exposure_range_ms=(0.02, 30.0, 0.0185))  # exposure in steps of one row, 18.5 us
    install(monkeypatch, cam)
    with UEyeEpiscan(base_trigger_delay_us=3000.0) as dev:
        dev.set_timing(-1200.0, 600.0)
        realized = cam.exposure_ms * 1e3
        assert realized != 600.0 and abs(realized - 600.0) <= 9.25
        assert dev.realized_exposure_us == pytest.approx(realized)  # read back with GET_EXPOSURE
        t_o = float(sync_offset_from_delay(-1200.0, realized, lines_per_second=54_000.0))
        assert cam.trigger_delay_us == round(3000.0 - t_o)
        # Eq. 1's sign: a later band (larger t_d) is a longer trigger delay, one for one
        before = cam.trigger_delay_us
        dev.set_timing(-1200.0 + 187.5, 600.0)
        assert cam.trigger_delay_us - before in (187, 188)
        # the exposure is set in ms as a double and read back, never assumed written back
        sets = [a for a in calls_of(cam, "is_Exposure") if a[0] == C["IS_EXPOSURE_CMD_SET_EXPOSURE"]]
        assert sets == [(C["IS_EXPOSURE_CMD_SET_EXPOSURE"], 0.6)]  # once: the exposure did not change


def test_a_feasible_point_is_not_refused_for_the_previous_exposure(camera):
    # base 1500: (t_d=-1200, t_e=600) needs trigger delay 9 us; with the previous exposure 1200 it would be -291
    with UEyeEpiscan(base_trigger_delay_us=1500.0) as dev:
        dev.set_timing(0.0, 1200.0)
        n = len(camera.calls)
        dev.set_delay(-1200.0)  # the runner's old order: delay first...
        dev.set_exposure(600.0)  # ...then exposure
        assert len(camera.calls) == n  # nothing applied yet
        dev.grab()  # applied once, as a pair
        t_o = float(sync_offset_from_delay(-1200.0, 600.0, lines_per_second=54_000.0))
        assert camera.trigger_delay_us == round(1500.0 - t_o) == 9
        m = len(camera.calls)
        dev.set_timing(-1200.0, 600.0)  # the same point again: nothing to write
        assert len(camera.calls) == m
    # and through the runner, the paper's sweep in its own order, on a base that just fits it
    with UEyeEpiscan(base_trigger_delay_us=2092.0, frames_averaged=1) as dev:
        acquire_sweep(dev, paper_sweep())


@pytest.mark.parametrize(
    ("base", "delay", "exposure", "match"),
    [
        (None, 0.0, 600.0, "base trigger delay is not calibrated"),
        (1000.0, -1500.0, 1200.0, "outside the camera's 0..2e\\+06 us: use a base one projector frame later"),
        (3000.0, 0.0, 50_000.0, "exposure 50000 us is outside the camera's range 20..30000 us"),
        (3000.0, 0.0, -5.0, "exposure must be positive"),
    ],
)
def test_infeasible_points_are_refused_with_the_reason(camera, base, delay, exposure, match):
    with UEyeEpiscan(base_trigger_delay_us=base) as dev:
        with pytest.raises(DeviceError, match=match):
            dev.set_timing(delay, exposure)


def test_the_paper_sweep_fits_a_base_above_its_largest_sync_offset(camera):
    need = required_base_trigger_delay_us([paper_sweep()], lines_per_second=54_000.0)
    assert need == pytest.approx(1200 / 2 - T_P / 2 + 1500)  # 2090.7 us: t_d = -1500, t_e = 1200
    with UEyeEpiscan(base_trigger_delay_us=need + 1.0) as dev:
        for d, e in zip(paper_sweep().delay_us, paper_sweep().exposure_us):
            dev.set_timing(d, e)
    with UEyeEpiscan(base_trigger_delay_us=need - 2.0) as dev:
        with pytest.raises(DeviceError, match="one projector frame later"):
            dev.set_timing(-1500.0, 1200.0)


def test_a_clamped_exposure_is_refused(monkeypatch):
    cam = FakeCamera(exposure_range_ms=(0.02, 30.0, 0.001))
    install(monkeypatch, cam)
    with UEyeEpiscan(base_trigger_delay_us=3000.0) as dev:
        dev.exposure_range_us = (20.0, 40_000.0)  # the range said more than the camera then allows
        with pytest.raises(DeviceError, match="the camera set exposure 30000.00 us for 35000 us requested"):
            dev.set_timing(0.0, 35_000.0)


def test_trigger_delays_that_are_query_codes_are_refused(camera):
    with UEyeEpiscan(base_trigger_delay_us=0x8001 + 290.74) as dev:  # t_d = 0, t_e = 600: t'_o = 290.74
        with pytest.raises(DeviceError, match="query code"):
            dev.set_timing(0.0, 600.0)


def test_base_change_reapplies_the_timing(camera):
    with UEyeEpiscan(base_trigger_delay_us=3000.0) as dev:
        dev.set_timing(0.0, 600.0)
        first = camera.trigger_delay_us
        dev.base_trigger_delay_us = 3100.0
        dev.grab()
        assert camera.trigger_delay_us == first + 100


# ----------------------------------------------------------------------------- capture
def test_grab_averages_triggered_frames_with_pitch_saturation_and_black_level(monkeypatch):
    ramp = np.tile(np.linspace(0.0, 1.2, 24), (16, 1))  # the right end saturates
    cam = FakeCamera(render=lambda d, e: ramp)
    install(monkeypatch, cam)
    with UEyeEpiscan(base_trigger_delay_us=3000.0, frames_averaged=8, black_level=64) as dev:
        img, sat = dev.grab()
    assert cam.frames == 8 and img.dtype == np.float32 and img.shape == (16, 24)
    codes = np.clip(np.rint(ramp * 4095), 0, 4095)
    np.testing.assert_allclose(img, (codes - 64) / (4095 - 64), rtol=0, atol=1e-6)  # no pitch padding leaks in
    np.testing.assert_array_equal(sat, codes >= 4095)
    assert sat[:, -1].all() and not sat[:, 0].any()
    assert calls_of(cam, "is_FreezeVideo") == [(C["IS_WAIT"],)] * 8
    assert calls_of(cam, "get_data")[0] == (24, 16, 16, 56, True)


def test_missing_vsync_says_so(monkeypatch):
    cam = FakeCamera(vsync=False)
    install(monkeypatch, cam)
    with UEyeEpiscan(base_trigger_delay_us=3000.0, trigger_timeout_s=0.5) as dev:
        assert cam.timeout_units == 50
        with pytest.raises(DeviceError, match=r"no trigger on VSYNC within 0.5 s .*IS_TIMED_OUT"):
            dev.grab()
    assert cam.exited == 1


def test_msb_aligned_data_is_detected(monkeypatch):
    cam = FakeCamera(msb_aligned=True)
    install(monkeypatch, cam)
    with UEyeEpiscan(base_trigger_delay_us=3000.0) as dev:
        with pytest.raises(DeviceError, match="LSB-aligned"):
            dev.grab()


def test_ten_bit_mode_normalizes_to_1023_and_checks_the_codes(monkeypatch):
    level = [0.1]
    cam = FakeCamera(render=lambda d, e: np.full((16, 24), level[0]))  # the fake writes 12-bit-scaled codes
    install(monkeypatch, cam)
    with UEyeEpiscan(base_trigger_delay_us=3000.0, bit_depth=10) as dev:
        assert cam.color_mode == C["IS_CM_MONO10"]
        img, _ = dev.grab()
        np.testing.assert_allclose(img, np.rint(0.1 * 4095) / 1023)
        level[0], cam._cache = 0.5, {}
        with pytest.raises(DeviceError, match="above the 10-bit maximum 1023"):
            dev.grab()


def test_closed_camera_refuses_to_capture(camera):
    dev = UEyeEpiscan(base_trigger_delay_us=3000.0)
    dev.close()
    with pytest.raises(DeviceError, match="closed"):
        dev.grab()


# ----------------------------------------------------------------------------- calibration and a whole sweep
@pytest.fixture
def rig(monkeypatch):
    """A fake camera on a diffuse target, whose base trigger delay (hidden) is 800 us: below the paper's 2091."""
    scene = make_scene("diffuse_plane", (16, 24), projector_rows=90, seed=0)
    cam = FakeCamera(render=scene_renderer(scene), true_base_us=800.0)
    install(monkeypatch, cam)
    return cam, scene


def test_calibration_finds_a_base_that_fits_the_sweep(rig):
    cam, _ = rig
    with UEyeEpiscan(frames_averaged=1) as dev:
        result = calibrate_base_trigger_delay(dev, sweeps=[paper_sweep()])
        assert dev.base_trigger_delay_us == result.base_trigger_delay_us
    truth = cam.true_base_us + cam.frame_period_us  # one frame later: 800 us cannot serve t'_o = 2091 us
    assert result.base_trigger_delay_us == pytest.approx(truth, abs=1.0)
    assert result.details["fits_sweeps"] and result.details["search"]["base_used_us"] >= 2091
    assert abs(result.delay_zero_us) < result.details["search"]["step_us"]  # the search was already close
    assert result.to_dict()["base_trigger_delay_us"] == result.base_trigger_delay_us
    assert cam.exited == 1


def test_a_whole_sweep_through_the_fake_camera_matches_the_simulated_device_and_resumes(rig, tmp_path):
    cam, scene = rig
    with UEyeEpiscan(frames_averaged=2) as dev:
        base = calibrate_base_trigger_delay(dev, sweeps=[paper_sweep()]).base_trigger_delay_us
    full = tmp_path / "full.zarr"
    with UEyeEpiscan(base_trigger_delay_us=base, frames_averaged=2) as dev:
        acquire_to_store(dev, paper_sweep(), full)
    out = tmp_path / "resumed.zarr"
    with UEyeEpiscan(base_trigger_delay_us=base, frames_averaged=2) as dev:
        acquire_to_store(dev, paper_sweep(), out, _stop_after=30)  # "killed"
    seen = []
    with UEyeEpiscan(base_trigger_delay_us=base, frames_averaged=2) as dev:  # a fresh process, the camera reopened
        acquire_to_store(dev, paper_sweep(), out, progress=seen.append)
    assert sorted(seen) == list(range(85)) and cam.opened == cam.exited == 4
    a, b = read_stack(full, lazy=False), read_stack(out, lazy=False)
    np.testing.assert_array_equal(a.images, b.images)
    assert a.metadata["base_trigger_delay_us"] == base and a.metadata["shutter"] == "rolling"
    expected = acquire_sweep(SimulatedEpiscan(scene, noise=False), paper_sweep())
    np.testing.assert_allclose(a.images, expected.images, atol=0.004)  # 12-bit codes, sub-us timing
    np.testing.assert_array_equal(a.delay_us, expected.delay_us)


def test_cli_calibrates_writes_and_acquires_through_the_fake_camera(rig, tmp_path):
    cam, _ = rig
    runner = CliRunner()
    acq = tmp_path / "acquisition.json"
    acq.write_text(json.dumps({"lines_per_second": 54_000.0, "projector": "PicoPro"}))
    res = runner.invoke(
        app,
        ["calibrate", "delay-zero", "--device", "ueye", "-O", "frames_averaged=1", "--calibration", str(acq)]
        + ["--write", str(acq)],
    )
    assert res.exit_code == 0, res.output
    assert "base trigger delay" in res.output
    written = json.loads(acq.read_text())
    assert written["base_trigger_delay_us"] == pytest.approx(800.0 + cam.frame_period_us, abs=1.0)
    assert written["projector"] == "PicoPro" and "delay_zero_us" in written
    res = runner.invoke(
        app,
        ["acquire", "--device", "ueye", "--calibration", str(acq), "-O", "frames_averaged=1", "--sweep", "quick"]
        + ["--out", str(tmp_path / "s.zarr")],
    )
    assert res.exit_code == 0, res.output
    st = read_stack(tmp_path / "s.zarr")
    assert len(st) == len(quick_sweep()) and st.metadata["base_trigger_delay_us"] == written["base_trigger_delay_us"]
    assert cam.opened == cam.exited == 2  # the CLI released the camera both times
    res = runner.invoke(app, ["demux", str(tmp_path / "s.zarr"), "--out", str(tmp_path / "T.zarr")])
    assert res.exit_code == 0, res.output  # and the capture demultiplexes
    # a failure mid-capture releases the camera too, and is one line
    cam.vsync = False
    res = runner.invoke(
        app, ["acquire", "--device", "ueye", "--calibration", str(acq), "--out", str(tmp_path / "t.zarr")]
    )
    assert res.exit_code == 1 and "no trigger on VSYNC" in res.output and "Traceback" not in res.output
    assert cam.opened == cam.exited == 3


def test_delay_zero_from_a_stack_captured_with_a_known_base(rig, tmp_path):
    cam, _ = rig
    base_used = 800.0 + cam.frame_period_us + 40.0  # 40 us off
    with UEyeEpiscan(base_trigger_delay_us=base_used, frames_averaged=1) as dev:
        acquire_to_store(dev, delay_zero_sweep(600.0), tmp_path / "dz.zarr")
    res = CliRunner().invoke(
        app, ["calibrate", "delay-zero", str(tmp_path / "dz.zarr"), "--json", "--write", str(tmp_path)]
    )
    assert res.exit_code == 0, res.output
    info = json.loads(res.output)
    assert info["delay_zero_us"] == pytest.approx(-40.0, abs=1.0)
    assert info["base_trigger_delay_us"] == pytest.approx(800.0 + cam.frame_period_us, abs=1.0)
    assert (
        json.loads((tmp_path / "acquisition.json").read_text())["base_trigger_delay_us"]
        == info["base_trigger_delay_us"]
    )


def test_acquire_cli_asks_for_the_base_and_for_pyueye(monkeypatch, tmp_path):
    runner = CliRunner()
    res = runner.invoke(app, ["acquire", "--device", "ueye", "--out", str(tmp_path / "c.zarr")])
    assert res.exit_code == 1 and "needs its base trigger delay" in res.output and "calibrate delay-zero" in res.output
    uninstall(monkeypatch)
    res = runner.invoke(
        app, ["acquire", "--device", "ueye", "--base-trigger-delay-us", "3000", "--out", str(tmp_path / "c.zarr")]
    )
    assert res.exit_code == 1 and "pyueye" in res.output and "Traceback" not in res.output


def test_write_calibration_keeps_the_base_with_its_delay_zero(tmp_path, rig):
    with UEyeEpiscan(frames_averaged=1) as dev:
        with_base = calibrate_base_trigger_delay(dev, base_trigger_delay_us=800.0 + 1e6 / 60.0 + 20.0)
    acq = write_calibration(tmp_path, delay_zero=with_base)
    assert acq["base_trigger_delay_us"] == with_base.base_trigger_delay_us
    from dataclasses import replace

    acq = write_calibration(tmp_path, delay_zero=replace(with_base, base_trigger_delay_us=None))
    assert "base_trigger_delay_us" not in acq  # never a new delay zero with an old base


def test_a_given_base_below_the_sweep_is_refused(rig):
    with UEyeEpiscan(frames_averaged=1) as dev:
        with pytest.raises(InputError, match="below 2090.7 us"):
            calibrate_base_trigger_delay(dev, sweeps=[paper_sweep()], base_trigger_delay_us=1000.0)


def test_open_device_by_name(camera):
    with open_device("ueye", base_trigger_delay_us=3000.0, frames_averaged=2) as dev:
        assert isinstance(dev, UEyeEpiscan) and dev.frames_averaged == 2
    with pytest.raises(InputError, match="has no option 'scene'"):
        open_device("ueye", scene="wax")
