"""Calibration (Sec. 6): projector line velocity v_p from counted lines, delay zero, acquisition.json."""

import json

import numpy as np
import pytest

from planeray.calibration import (
    LineSweep,
    calibrate_delay_zero,
    calibrate_lines_per_second,
    count_lines,
    delay_zero_sweep,
    device_capture,
    read_line_sweep,
    write_calibration,
    write_line_sweep,
)
from planeray.camera import CameraModel
from planeray.devices import SimulatedEpiscan
from planeray.errors import InputError
from planeray.scenes import make_scene
from planeray.timing import sync_offset_from_delay


@pytest.fixture(scope="module")
def target():
    """A printed-page diffuse plane imaged at full resolution: 3 camera rows per projector row."""
    return make_scene("diffuse_plane", (288, 32), projector_rows=96, seed=0)


def synthetic_lines(fractions, spacing=6.0, first=20.0, H=200, W=40, sigma=1.2, noise=0.01, seed=0):
    """Horizontal Gaussian lines of integrated height ``fractions`` with uneven brightness and noise."""
    rng = np.random.default_rng(seed)
    rows = np.arange(H, dtype=float)
    profile = sum(f * np.exp(-0.5 * ((rows - first - i * spacing) / sigma) ** 2) for i, f in enumerate(fractions))
    column_gain = rng.uniform(0.4, 1.0, W)  # uneven brightness across the image...
    falloff = 1.0 - 0.4 * (rows / H - 0.5) ** 2  # ...and down it
    image = 0.05 + 0.3 * column_gain + profile[:, None] * falloff[:, None] * column_gain[None, :]
    return image + rng.normal(0.0, noise, image.shape)


# ----------------------------------------------------------------------------- counting
def test_paper_numbers_27_lines_in_500_us_give_54000_lines_per_second():
    image = synthetic_lines(np.ones(27))
    cal = calibrate_lines_per_second(image, exposure_us=500.0, rows_per_line=1)
    assert cal.n_lines == pytest.approx(27.0, abs=0.1)
    assert cal.lines_per_second == pytest.approx(54_000.0, rel=0.005)
    assert abs(cal.lines_per_second - 54_000.0) < 3 * cal.uncertainty + 1.0


def test_partially_exposed_end_lines_count_as_fractions():
    fractions = np.r_[0.3, np.ones(24), 0.65]
    c = count_lines(synthetic_lines(fractions, first=30.3, sigma=1.5, seed=3))
    assert c.n_detected == 26
    assert c.spacing_rows == pytest.approx(6.0, abs=0.02)
    assert c.count == pytest.approx(24.95, abs=0.08)
    assert c.count_uncertainty < 0.1
    cal = calibrate_lines_per_second(synthetic_lines(fractions, first=30.3, sigma=1.5, seed=3), exposure_us=500.0)
    assert cal.window_rows == pytest.approx(24.95, abs=0.08)


def test_a_missing_interior_line_is_restored_by_the_grid():
    fractions = np.ones(15)
    image = synthetic_lines(fractions, noise=0.002)
    image[20 + 7 * 6 - 3 : 20 + 7 * 6 + 4] = image[20 + 7 * 6 + 3 : 20 + 7 * 6 + 10].mean(axis=0)  # line 7 lost
    assert count_lines(image).count == pytest.approx(15.0, abs=0.1)


# ----------------------------------------------------------------------------- v_p from the simulated device
@pytest.mark.parametrize("lines_per_second", [40_000.0, 54_000.0, 60_000.0])
@pytest.mark.parametrize(
    "camera",
    [
        CameraModel(read_noise_e=2.0, laser_electrons=6000.0, ambient_e_per_us=0.5),
        CameraModel(read_noise_e=7.0),
        CameraModel(read_noise_e=20.0, laser_electrons=1500.0, ambient_e_per_us=2.0),
    ],
    ids=["read2", "read7", "read20-dim-bright-ambient"],
)
def test_recovers_the_true_line_velocity_within_2_percent(target, lines_per_second, camera):
    for seed in range(3):
        device = SimulatedEpiscan(target, camera, lines_per_second=lines_per_second, seed=seed)
        sweep = device.capture_line_sweep(500.0, falloff=0.3, blur_rows=1.0)
        cal = calibrate_lines_per_second(sweep)
        assert cal.method == "complete sweep"
        assert cal.lines_per_second == pytest.approx(lines_per_second, rel=0.02)
        assert abs(cal.lines_per_second - lines_per_second) < 3 * cal.uncertainty  # honest uncertainty
        assert cal.relative_uncertainty < 0.02  # and a useful one


def test_counts_the_paper_27_lines(target):
    sweep = SimulatedEpiscan(target, seed=5).capture_line_sweep(500.0)
    cal = calibrate_lines_per_second(sweep)
    assert sweep.line_step_rows == 2 and sweep.images.shape[0] == 2
    assert cal.n_lines == pytest.approx(27.0, abs=0.3)  # 13.5 lines per comb phase


def test_noise_free_sweep_is_exact_at_any_sub_row_phase(target):
    device = SimulatedEpiscan(target, lines_per_second=54_000.0, noise=False)
    for start in (20.0, 20.25, 23.5, 31.9):
        cal = calibrate_lines_per_second(device.capture_line_sweep(500.0, start_row=start))
        assert cal.lines_per_second == pytest.approx(54_000.0, rel=1e-6)


def test_uncertainty_is_consistent_over_many_captures(target):
    z = []
    for seed in range(12):
        device = SimulatedEpiscan(target, lines_per_second=54_000.0, seed=100 + seed)
        cal = calibrate_lines_per_second(device.capture_line_sweep(500.0, falloff=0.3, blur_rows=1.0))
        z.append((cal.lines_per_second - 54_000.0) / cal.uncertainty)
    z = np.array(z)
    assert np.abs(z).max() < 3.0
    assert 0.2 < np.sqrt(np.mean(z**2)) < 1.5  # neither over- nor under-stated by much


def test_single_comb_image_and_no_references_still_calibrate(target):
    device = SimulatedEpiscan(target, lines_per_second=54_000.0, seed=7)
    sweep = device.capture_line_sweep(500.0, falloff=0.3)
    full = calibrate_lines_per_second(sweep)
    one = calibrate_lines_per_second(
        sweep.images[0],
        exposure_us=500.0,
        rows_per_line=2,
        dark=sweep.dark,
        flat=sweep.flat_field(),
        timing_jitter_us=sweep.timing_jitter_us,
    )
    assert one.method == "end positions"
    assert one.uncertainty > full.uncertainty  # a window end in a dark gap is only bounded
    assert abs(one.lines_per_second - 54_000.0) < 3 * one.uncertainty
    bare = calibrate_lines_per_second(SimulatedEpiscan(target, seed=8).capture_line_sweep(500.0, references=False))
    assert bare.lines_per_second == pytest.approx(54_000.0, rel=0.03)
    assert abs(bare.lines_per_second - 54_000.0) < 3 * bare.uncertainty


def test_simulated_line_sweep_is_physical(target):
    device = SimulatedEpiscan(target, lines_per_second=54_000.0, noise=False)
    sweep = device.capture_line_sweep(500.0, line_step_rows=3, start_row=30.0, references=False)
    assert sweep.images.shape == (3, 288, 32) and sweep.complete
    assert sweep.metadata["truth"]["window_rows"] == pytest.approx(27.0)
    # the phases together light the window exactly once: their sum is one flat band of rows 30..57
    total = sweep.images.sum(axis=0).mean(axis=1)
    rows = (np.arange(288) + 0.5) / 3 - 0.5  # projector coordinate of each camera row
    inside, outside = (rows > 31) & (rows < 56), (rows < 28) | (rows > 59)
    assert total[outside].max() < 0.5 * total[inside].min()
    with pytest.raises(ValueError, match="do not fit"):
        SimulatedEpiscan(target, lines_per_second=54_000.0).capture_line_sweep(2000.0)


# ----------------------------------------------------------------------------- bad input
def test_bad_images_give_clear_input_errors():
    with pytest.raises(InputError, match="blank"):
        calibrate_lines_per_second(np.zeros((100, 20)), exposure_us=500.0)
    with pytest.raises(InputError, match="blank|noise"):
        calibrate_lines_per_second(np.random.default_rng(0).normal(0, 0.01, (100, 20)), exposure_us=500.0)
    nan = synthetic_lines(np.ones(10))
    nan[5, 5] = np.nan
    with pytest.raises(InputError, match="NaN"):
        calibrate_lines_per_second(nan, exposure_us=500.0)
    with pytest.raises(InputError, match="2-D"):
        count_lines(np.ones(50))
    with pytest.raises(InputError, match="need at least 3"):
        calibrate_lines_per_second(synthetic_lines(np.ones(2)), exposure_us=500.0)
    with pytest.raises(InputError, match="exposure_us"):
        calibrate_lines_per_second(synthetic_lines(np.ones(10)))
    with pytest.raises(InputError, match="border"):
        calibrate_lines_per_second(synthetic_lines(np.ones(40), first=2.0), exposure_us=500.0)
    with pytest.raises(InputError, match="shape"):
        count_lines(synthetic_lines(np.ones(10)), dark=np.zeros((3, 3)))


# ----------------------------------------------------------------------------- delay zero
@pytest.mark.parametrize("error_us", [37.0, -120.0])
def test_delay_zero_recovers_an_injected_sync_error(error_us):
    scene = make_scene("diffuse_plane", (64, 64), projector_rows=360, seed=0)
    device = SimulatedEpiscan(scene, seed=1)
    sweep = delay_zero_sweep(600.0, step_us=10.0)
    cal = calibrate_delay_zero(
        device_capture(device, exposure_us=600.0, delay_error_us=error_us), sweep.delay_us, exposure_us=600.0
    )
    assert cal.delay_zero_us == pytest.approx(error_us, abs=2.0)
    assert abs(cal.delay_zero_us - error_us) < 3 * cal.uncertainty_us + 0.05
    assert 0 < cal.uncertainty_us < 2.0
    assert cal.width_us == pytest.approx(600.0, abs=10.0)  # FWHM of the plateau = exposure
    assert cal.sync_offset_us == pytest.approx(
        float(sync_offset_from_delay(error_us, 600.0, lines_per_second=54_000.0)), abs=2.0
    )
    # the same from images already captured (e.g. a stack at one exposure)
    images = [device_capture(device, exposure_us=600.0, delay_error_us=error_us)(d) for d in sweep.delay_us]
    again = calibrate_delay_zero(np.array(images), sweep.delay_us, exposure_us=600.0)
    assert again.delay_zero_us == pytest.approx(error_us, abs=2.0)


def test_delay_zero_bad_input():
    d = np.arange(-600.0, 601.0, 50.0)
    with pytest.raises(InputError, match="no epipolar response"):
        calibrate_delay_zero(lambda x: np.full((8, 8), 0.1), d)
    with pytest.raises(InputError, match="NaN"):
        calibrate_delay_zero(lambda x: np.full((8, 8), np.nan), d)
    box = lambda x: np.full((8, 8), 1.0 if abs(x - 200) < 500 else 0.0)  # noqa: E731  (cut by the sweep)
    with pytest.raises(InputError, match="widen"):
        calibrate_delay_zero(box, d)


# ----------------------------------------------------------------------------- files
def test_write_calibration_keeps_other_fields_and_feeds_the_import(tmp_path, target):
    from planeray.acquire import simulate_stack
    from planeray.io import export_folder, import_folder
    from planeray.timing import quick_sweep

    folder = export_folder(
        simulate_stack(make_scene("diffuse_plane", (16, 16), seed=0), quick_sweep()), tmp_path / "cap"
    )
    before = json.loads((folder / "acquisition.json").read_text())
    lines = calibrate_lines_per_second(
        SimulatedEpiscan(target, lines_per_second=52_000.0, seed=2).capture_line_sweep(500.0)
    )
    written = write_calibration(folder, lines=lines)
    after = json.loads((folder / "acquisition.json").read_text())
    assert after == written
    assert after["lines_per_second"] == pytest.approx(lines.lines_per_second)
    assert after["lines_per_second_uncertainty"] == pytest.approx(lines.uncertainty)
    for key, value in before.items():
        if key != "lines_per_second":
            assert after[key] == value
    assert import_folder(folder).lines_per_second == pytest.approx(lines.lines_per_second)
    # a later delay-zero calibration adds its fields and keeps the line velocity
    scene = make_scene("diffuse_plane", (32, 32), projector_rows=180, seed=0)
    dz = calibrate_delay_zero(
        device_capture(SimulatedEpiscan(scene), exposure_us=600.0, delay_error_us=20.0),
        delay_zero_sweep(600.0, step_us=20.0).delay_us,
    )
    both = write_calibration(folder / "acquisition.json", delay_zero=dz)
    assert both["delay_zero_us"] == pytest.approx(dz.delay_zero_us)
    assert both["lines_per_second"] == pytest.approx(lines.lines_per_second)
    assert set(both["calibration"]) == {"lines", "delay_zero", "replaced"}
    # the value the first calibration replaced (the export's own) is kept, not lost
    assert both["calibration"]["replaced"] == {"lines_per_second": before["lines_per_second"]}
    # a new file is created; a broken one is refused
    assert write_calibration(tmp_path / "new" / "acquisition.json", lines=lines)["lines_per_second"] > 0
    (tmp_path / "bad.json").write_text("[1, 2]")
    with pytest.raises(InputError, match="JSON object"):
        write_calibration(tmp_path / "bad.json", lines=lines)
    with pytest.raises(InputError, match="nothing to write"):
        write_calibration(tmp_path / "x.json")


def test_line_sweep_file_round_trip(tmp_path, target):
    import tifffile

    sweep = SimulatedEpiscan(target, seed=4).capture_line_sweep(500.0)
    path = write_line_sweep(sweep, tmp_path / "lines.npz")
    back = read_line_sweep(path)
    np.testing.assert_array_equal(back.images, sweep.images.astype(np.float32))
    assert back.line_step_rows == 2 and back.phases == sweep.phases and back.flat_exposure_us == 1000.0
    assert calibrate_lines_per_second(back).lines_per_second == pytest.approx(
        calibrate_lines_per_second(sweep).lines_per_second, rel=1e-4
    )
    tifffile.imwrite(tmp_path / "paper.tif", (synthetic_lines(np.ones(27)) * 4000).astype(np.uint16))
    single = read_line_sweep(tmp_path / "paper.tif")
    assert single.exposure_us == 500.0 and single.line_step_rows == 1
    assert calibrate_lines_per_second(single).lines_per_second == pytest.approx(54_000.0, rel=0.01)
    with pytest.raises(InputError, match="not found"):
        read_line_sweep(tmp_path / "missing.npz")
    with pytest.raises(InputError):
        LineSweep(np.zeros((2, 3, 4, 5)))


def test_calibrate_cli(tmp_path):
    import json

    from typer.testing import CliRunner

    from planeray.cli import app

    runner = CliRunner()
    res = runner.invoke(
        app, ["calibrate", "simulate-lines", "--out", str(tmp_path / "l.npz"), "--lines-per-second", "60000"]
    )
    assert res.exit_code == 0, res.output
    acq = tmp_path / "acquisition.json"
    acq.write_text(json.dumps({"bit_depth": 12}))
    res = runner.invoke(app, ["calibrate", "lines", str(tmp_path / "l.npz"), "--write", str(acq), "--json"])
    assert res.exit_code == 0, res.output
    info = json.loads(res.stdout)
    assert abs(info["lines_per_second"] - 60000) < 0.02 * 60000
    written = json.loads(acq.read_text())
    assert written["bit_depth"] == 12 and abs(written["lines_per_second"] - 60000) < 1200
    res = runner.invoke(app, ["calibrate", "delay-zero", "--simulate", "--delay-error-us", "-25", "--json"])
    assert res.exit_code == 0, res.output
    assert abs(json.loads(res.stdout)["delay_zero_us"] + 25) < 2
    res = runner.invoke(app, ["calibrate", "lines", str(tmp_path / "missing.npz")])
    assert res.exit_code == 1 and "not found" in res.output
