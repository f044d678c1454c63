"""The sweep file (a public format): it round-trips, bad files fail in one line naming the file, and every
command that takes a sweep takes it -- ``simulate``, ``acquire``, ``demux``, ``view --device`` -- as well
as ``sweep design`` writing it and ``sweep show`` drawing it."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from planeray.cli import app
from planeray.errors import InputError
from planeray.io import read_stack, read_sweep, read_transport, write_sweep
from planeray.timing import Sweep, boundary_images, paper_sweep, quick_sweep

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def _small(tmp_path):
    """Eight of the paper's images (three boundary images among them) as a hand-written sweep file."""
    p = paper_sweep()
    pick = np.array([3, 5, 6, 8, 10, 11, 13, 40])
    doc = {"name": "eight", "delay_us": p.delay_us[pick].tolist(), "exposure_us": p.exposure_us[pick].tolist()}
    path = tmp_path / "eight.json"
    path.write_text(json.dumps(doc))
    return path, p.delay_us[pick], p.exposure_us[pick]


def test_a_sweep_file_round_trips_and_hand_written_ones_get_the_defaults(tmp_path):
    rec = {"kind": "design", "prior": {"sources": ["wax"]}, "camera": {"model": {"frames_averaged": 8}}}
    sweep = Sweep(np.array([-100.0, 0.0, 400.0, 900.0]), np.array([300.0, 600.0, 600.0, 1200.0]),
                  np.array([False, False, True, False]), name="mine", record=rec)  # fmt: skip
    back = read_sweep(write_sweep(sweep, tmp_path / "s.json"))
    np.testing.assert_array_equal(back.delay_us, sweep.delay_us)
    np.testing.assert_array_equal(back.exposure_us, sweep.exposure_us)
    np.testing.assert_array_equal(back.excluded, sweep.excluded)
    assert back.name == "mine" and back.record == rec
    doc = json.loads((tmp_path / "s.json").read_text())
    assert (
        doc["format"] == "planeray-sweep"
        and doc["format_version"] == 1
        and doc["planeray_mark"].startswith("planeray:sweep:")
    )
    # hand-written: the name is the stem, the paper's boundary rule flags the excluded images
    path, d, e = _small(tmp_path)
    mine = read_sweep(path)
    assert mine.name == "eight" and mine.record is None
    np.testing.assert_array_equal(mine.excluded, boundary_images(d, e))
    assert mine.excluded.sum() == 3


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("not json", "not JSON"),
        ("[1, 2]", "a JSON object with delay_us and exposure_us"),
        ('{"delay_us": [0, 100]}', "'exposure_us' must be a non-empty list"),
        ('{"delay_us": [0, 100], "exposure_us": [600]}', "2 delays but 1 exposures"),
        ('{"delay_us": [0, "x"], "exposure_us": [600, 600]}', "delay_us\\[1\\] must be a finite number"),
        ('{"delay_us": [0, 100], "exposure_us": [600, -1]}', "exposures must be positive"),
        ('{"delay_us": [0, 0], "exposure_us": [600, 600]}', "images 0 and 1 are the same setting"),
        ('{"delay_us": [0], "exposure_us": [600], "excluded": [1]}', "'excluded' must be a list of 1 booleans"),
        ('{"format": "planeray-stack", "delay_us": [0], "exposure_us": [600]}', "not a sweep file"),
    ],
)
def test_a_bad_sweep_file_fails_in_one_line_naming_it(tmp_path, text, message):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as err:
        read_sweep(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)
    res = invoke("simulate", "diffuse_plane", "--out", tmp_path / "s.zarr", "--size", 8, 8, "--sweep", path)
    plain = message.replace("\\", "")
    assert res.exit_code == 1 and plain in res.output and "--sweep" in res.output and "Traceback" not in res.output


def test_write_sweep_never_replaces_a_file_planeray_did_not_write(tmp_path):
    mine = tmp_path / "notes.json"
    mine.write_text('{"mine": true}')
    with pytest.raises(InputError, match="planeray did not write"):
        write_sweep(quick_sweep(), mine, overwrite=True)
    assert mine.read_text() == '{"mine": true}'
    path = write_sweep(quick_sweep(), tmp_path / "q.json")
    with pytest.raises(InputError, match="exists"):
        write_sweep(paper_sweep(), path)
    write_sweep(paper_sweep(), path, overwrite=True)
    assert len(read_sweep(path)) == 85


def test_simulate_acquire_and_demux_take_a_sweep_file(tmp_path):
    path, d, e = _small(tmp_path)
    res = invoke("simulate", "diffuse_plane", "--out", tmp_path / "sim.zarr", "--size", 16, 16, "--sweep", path)
    assert res.exit_code == 0, res.output
    st = read_stack(tmp_path / "sim.zarr")
    np.testing.assert_array_equal(st.delay_us, d)
    np.testing.assert_array_equal(st.exposure_us, e)
    assert st.metadata["sweep"] == "eight" and st.excluded.sum() == 3
    res = invoke("acquire", "--device", "sim", "--scene", "diffuse_plane", "--size", 16, 16, "--sweep", path,
                 "--out", tmp_path / "acq.zarr")  # fmt: skip
    assert res.exit_code == 0, res.output
    acq = read_stack(tmp_path / "acq.zarr")
    np.testing.assert_array_equal(acq.delay_us, d)
    # demux --sweep: only the sweep's images of a bigger stack (the paper's 85) are used
    res = invoke("simulate", "diffuse_plane", "--out", tmp_path / "paper.zarr", "--size", 16, 16, "--sweep", "paper",
                 "--projector-rows", 90)  # fmt: skip
    assert res.exit_code == 0, res.output
    res = invoke("demux", tmp_path / "paper.zarr", "--out", tmp_path / "T.zarr", "--sweep", path)
    assert res.exit_code == 0, res.output
    _, attrs = read_transport(tmp_path / "T.zarr")
    p = paper_sweep()
    used = [i for i in range(85) if any(p.delay_us[i] == a and p.exposure_us[i] == b for a, b in zip(d, e))]
    assert attrs["image_index"] == [i for i in used if not p.excluded[i]] and attrs["n_images"] == 5
    # a stack without the sweep's settings is refused in one line
    res = invoke("demux", tmp_path / "sim.zarr", "--out", tmp_path / "T2.zarr", "--sweep", "quick")
    assert res.exit_code == 1 and "the stack has no image at" in res.output and "Traceback" not in res.output


def test_view_device_takes_a_sweep_file_and_shows_its_live_transport(tmp_path, monkeypatch):
    """``view --device sim --sweep FILE`` opens the live transport (the server's run replaced by one render)."""
    from planeray.viewer.server import ViewerServer
    from planeray.viewer.session import ViewSettings

    shown = {}

    def run(self):
        self.source.warm()
        image, info = self.source.render(ViewSettings.from_dict({"mode": "sharpened"}))
        shown.update(info=info, shape=image.shape, describe=self.source.describe())

    monkeypatch.setattr(ViewerServer, "run", run)
    path = write_sweep(quick_sweep(), tmp_path / "q.json")
    res = invoke("view", "--device", "sim", "-O", "size=[12, 12]", "-O", "projector_rows=60", "-O", "scene=wax",
                 "-O", "frames_averaged=1", "--sweep", path, "--no-browser", "--port", 0)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert shown["shape"] == (12, 12) and "live transport #" in shown["info"]["label"]
    assert shown["describe"]["transport"]["images"] == int((~quick_sweep().excluded).sum())
    res = invoke("view", "wax", "--sweep", path, "--no-browser")
    assert res.exit_code == 1 and "--sweep applies to --device only" in res.output


def test_sweep_design_writes_a_file_and_sweep_show_draws_it(tmp_path):
    out = tmp_path / "d.json"
    res = invoke("sweep", "design", "--images", 6, "--out", out, "--prior", "diffuse_plane", "--size", 16,
                 "--projector-rows", 90, "--support-rows", 24, "--pixels", 60, "--exposures-us", 150, 600,
                 "--exposure-step-us", 37.037, "--delay-step-us", 37.037, "--frames", 4, "--seed", 2)  # fmt: skip
    assert res.exit_code == 0, res.output
    sweep = read_sweep(out)
    assert len(sweep) == 6 and sweep.name == "design-6"
    rec = sweep.record
    assert rec["prior"]["sources"] == ["diffuse_plane"] and rec["camera"]["model"]["frames_averaged"] == 4
    assert rec["criterion"]["name"] == "mse" and rec["seed"] == 2
    res = invoke("sweep", "show", out, "--compare", "paper", "--out", tmp_path / "d.png")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "d.png").stat().st_size > 10_000
    # refused in one line: an image count below 4, a sweep file that is not one
    res = invoke("sweep", "design", "--images", 3, "--out", tmp_path / "x.json")
    assert res.exit_code == 1 and "--images" in res.output
    res = invoke("sweep", "show", tmp_path / "missing.json", "--out", tmp_path / "x.png")
    assert res.exit_code == 1 and "no such sweep file" in res.output and "Traceback" not in res.output
