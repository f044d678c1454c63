"""``planeray skin depth STACK --mask MASK --out DIR``: a simulated capture end to end, bad inputs, data promises.

Ground truth: the skin scene's vein (its top 1.5 mm deep, 3 mm across) and the truth files
``planeray skin simulate`` writes beside the stack.  The data-promise tests replace the per-vein
fit by a stand-in (what they check is how the command writes, not the numbers).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from planeray.cli import app
from planeray.experiments.skin_capture import read_skin_truth, simulate_skin
from test_faults import leftovers, one_line_error

TRUE_DEPTH_MM, TRUE_DIAMETER_MM = 1.5, 3.0


def _run(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """A 96x96 paper-sweep capture of fair skin at 638 nm (camera noise, ambient light) with one straight
    vein, its truth beside it, a binary mask of the vein (0/255) and a small stack of another scene."""
    import planeray as pr
    from _skin_toy import toy_vein_scene

    d = tmp_path_factory.mktemp("skin_depth")
    vein = dict(depth_mm=TRUE_DEPTH_MM, diameter_mm=TRUE_DIAMETER_MM, points_mm=[[-10.0, 90.0], [230.0, 120.0]])
    simulate_skin(d / "arm.zarr", size=(96, 96), seed=1, veins=[vein])
    _, maps = read_skin_truth(d / "arm.zarr")
    Image.fromarray(np.where(maps["vein_id"] > 0, 255, 0).astype(np.uint8)).save(d / "mask.png")
    Image.fromarray(np.zeros((40, 40), np.uint8)).save(d / "small_mask.png")
    toy = toy_vein_scene((48, 48), projector_rows=270, columns=(8, 24, 40))
    pr.write_stack(pr.simulate_stack(toy, pr.timing.quick_sweep(), seed=0), d / "toy.zarr")
    return d


def test_depth_of_a_simulated_vein_end_to_end(capture, tmp_path):
    out = tmp_path / "depth"
    r = _run("skin", "depth", capture / "arm.zarr", "--mask", capture / "mask.png", "--out", out)
    assert r.exit_code == 0, r.output
    assert "1/1 veins resolved" in r.output
    meta = json.loads((out / "planeray.json").read_text())
    assert meta["format"] == "planeray-skin-depth"
    # tone, wavelength and scale from the stack's record; the camera's noise model too
    assert (meta["tone"], meta["wavelength_nm"], meta["mm_per_row"]) == ("fair", 638, 0.3)
    assert meta["tone_source"] == meta["wavelength_source"] == meta["mm_per_row_source"] == "stack metadata"
    assert meta["camera_source"] == "stack metadata"
    (v,) = meta["veins"]
    assert v["resolved"], v["reason"]
    err = v["depth_mm"] - TRUE_DEPTH_MM
    assert abs(err) < 0.5 and abs(err) < 4 * v["depth_se_mm"] + 0.1, (v["depth_mm"], v["depth_se_mm"])
    assert 0 < v["depth_se_mm"] < 0.5
    assert v["axis_depth_mm"] == pytest.approx(v["depth_mm"] + v["diameter_mm"] / 2, abs=2e-4)
    assert abs(v["diameter_mm"] - TRUE_DIAMETER_MM) < 1.0
    # the truth beside the stack, matched to the mask's vein
    assert (v["true_depth_mm"], v["true_diameter_mm"]) == (TRUE_DEPTH_MM, TRUE_DIAMETER_MM)
    # the label image is the mask's veins; the depth map holds the estimate on them, NaN elsewhere
    ids = np.asarray(Image.open(out / "vein_ids.png"))
    mask = np.asarray(Image.open(capture / "mask.png")) > 0
    assert np.array_equal(ids > 0, mask) and set(np.unique(ids[mask])) == {v["id"]}
    import tifffile

    dm = tifffile.imread(out / "depth_mm.tif")
    assert np.all(np.isnan(dm[~mask])) and np.allclose(dm[mask], v["depth_mm"], atol=1e-4)
    rows = (out / "veins.csv").read_text().splitlines()
    assert len(rows) == 2 and rows[0].startswith("id,resolved,reason,depth_mm")
    # the figure: measured and fitted contrast per delay, estimated vs true depth
    with Image.open(out / "depth_fit.png") as im:
        assert im.size[0] > 500 and np.asarray(im.convert("L")).std() > 10


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (("--tone", "purple"), ("--tone",)),
        (("--tone", "0.9"), ("--tone",)),
        (("--wavelength", "700"), ("--wavelength", "700")),
        (("--mm-per-row", "0"), ("--mm-per-row",)),
        (("--mask", "{d}/nowhere.png"), ("--mask", "not found")),
        (("--mask", "{d}/small_mask.png"), ("--mask", "40x40")),
    ],
    ids=["tone-name", "tone-fraction", "wavelength", "mm-per-row", "mask-missing", "mask-size"],
)
def test_bad_options_give_one_line_naming_the_option(capture, tmp_path, args, needles):
    args = [a.format(d=capture) for a in args]
    line = one_line_error(_run("skin", "depth", capture / "arm.zarr", "--out", tmp_path / "o", *args), *needles)
    assert line and not (tmp_path / "o").exists()


def test_a_stack_without_records_or_truth_needs_the_options(capture, tmp_path):
    """The toy stack records no skin tone (its wavelength, 638 nm, it does) and has no truth beside it."""
    o = tmp_path / "o"
    one_line_error(_run("skin", "depth", capture / "toy.zarr", "--out", o), "--tone", "records no tone")
    line = one_line_error(_run("skin", "depth", capture / "toy.zarr", "--out", o, "--tone", "fair"), "--mask")
    assert "no ground truth" in line
    one_line_error(_run("skin", "depth", tmp_path / "none.zarr", "--out", o), "STACK")
    assert not o.exists()


# ---------------------------------------------------------------- data promises (stand-in fit)
@pytest.fixture
def quick_fit(monkeypatch):
    """The per-vein fit replaced by a stand-in that answers at once."""
    import planeray.skin.depth as sd

    def fit_vein(model, images, variance, pix, *, vein_id=1, **kw):
        return sd.VeinFit(vein_id, True, "", 2.0, 2.5, 0.1, 0.3, 0.2, 100.0, 1.1, pix.rows.size, len(images))

    monkeypatch.setattr(sd, "fit_vein", fit_vein)


def _snapshot(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.usefixtures("figures_not_drawn", "quick_fit")
def test_a_users_folder_is_never_replaced_and_planerays_only_with_overwrite(capture, tmp_path):
    from planeray.io.atomic import planeray_output_kind

    user = tmp_path / "mine"
    user.mkdir()
    (user / "notes.txt").write_text("three weeks of lab notes")
    for extra in ((), ("--overwrite",)):
        line = one_line_error(_run("skin", "depth", capture / "arm.zarr", "--out", user, *extra), str(user))
        assert ("planeray did not write" if extra else "already exists") in line
    assert _snapshot(user) == {"notes.txt": b"three weeks of lab notes"}

    out = tmp_path / "depth"
    r = _run("skin", "depth", capture / "arm.zarr", "--out", out)  # the truth's vein ids as the mask
    assert r.exit_code == 0, r.output
    assert planeray_output_kind(out) == "skin depth"
    assert json.loads((out / "planeray.json").read_text())["veins"][0]["depth_mm"] == 2.0
    before = _snapshot(out)
    one_line_error(_run("skin", "depth", capture / "arm.zarr", "--out", out), "already exists")
    assert _snapshot(out) == before
    inode = out.stat().st_ino
    r = _run("skin", "depth", capture / "arm.zarr", "--out", out, "--overwrite")
    assert r.exit_code == 0, r.output
    assert out.stat().st_ino != inode and planeray_output_kind(out) == "skin depth"
    assert leftovers(tmp_path) == []


@pytest.mark.usefixtures("figures_not_drawn")
def test_outputs_are_checked_before_any_work(capture, tmp_path, monkeypatch):
    import planeray.skin.depth as sd

    def work(*a, **k):
        raise AssertionError("the fit started before the output was checked")

    monkeypatch.setattr(sd, "fit_veins", work)
    user = tmp_path / "mine"
    user.mkdir()
    one_line_error(_run("skin", "depth", capture / "arm.zarr", "--out", user), "already exists")


@pytest.mark.usefixtures("figures_not_drawn", "quick_fit")
def test_killed_mid_write_leaves_no_output_and_no_temporaries(capture, tmp_path, monkeypatch):
    import planeray.figures.skin as fs

    calls = []

    def interrupted(*a, **k):
        calls.append(1)
        raise KeyboardInterrupt

    monkeypatch.setattr(fs, "depth_fit_figure", interrupted)
    r = _run("skin", "depth", capture / "arm.zarr", "--out", tmp_path / "depth")
    assert r.exit_code == 130 and "interrupted" in r.output, r.output
    assert calls and sorted(p.name for p in tmp_path.iterdir()) == []


def test_the_row_size_comes_from_acquisition_json_and_the_fit_says_whether_the_model_fits(capture, tmp_path):
    """Issue 41: a user's import folder states mm_per_row in its acquisition.json (and nothing of the scene): the
    depth fit uses it and says so; without it the command refuses in one line (no default stands in).  The fit's
    goodness is in the JSON (chi-square of the contrast and of the backgrounds) and in the flag layer."""
    from dataclasses import asdict

    import tifffile

    from planeray.camera import CameraModel
    from planeray.io import export_folder, read_stack

    def folder(name, **acquisition):
        export_folder(read_stack(capture / "arm.zarr"), tmp_path / name)
        path = tmp_path / name / "acquisition.json"
        acq = json.loads(path.read_text())
        acq["planeray_metadata"] = {"camera": asdict(CameraModel())}
        acq.update(acquisition)
        path.write_text(json.dumps(acq))
        return tmp_path / name

    common = ("--mask", capture / "mask.png", "--tone", "fair", "--wavelength", "638")
    out = tmp_path / "depth"
    r = _run("skin", "depth", folder("stated", mm_per_row=0.3), "--out", out, *common)
    assert r.exit_code == 0, r.output
    meta = json.loads((out / "planeray.json").read_text())
    assert meta["mm_per_row"] == 0.3 and meta["mm_per_row_source"] == "acquisition.json"
    assert meta["skin_model"]["layers"][1]["thickness_mm"] == 1.5 and meta["skin_model_sources"]["dermis_mm"]
    (v,) = meta["veins"]
    assert v["fit_quality"]["dof"] > 100 and v["background_quality"]["dof"] >= 5
    assert v["model_fits"] is True and v["flags"] == [] and "reduced chi-square" in r.output
    flags = tifffile.imread(out / "flags.tif")
    mask = np.asarray(Image.open(capture / "mask.png")) > 0
    assert flags.dtype == np.uint8 and np.all(flags[mask] == 0) and np.all(flags[~mask] == 255)
    r = _run("skin", "depth", folder("silent"), "--out", tmp_path / "depth2", *common)
    assert one_line_error(r) and "mm_per_row" in r.output and "acquisition.json" in r.output
    assert not (tmp_path / "depth2").exists()


def test_new_vein_tables_are_announced_with_an_estimate_before_tracing_and_shipped_ones_silently_used(
    capture, tmp_path, monkeypatch
):
    """A row size the shipped tables were not traced at (0.31 mm; 451 s of silence once): the tables to trace
    are named with a time measured on a pilot run *before* tracing starts, then traced under a progress bar;
    at the capture's own 0.3 mm (shipped tables) nothing is announced."""
    import planeray.skin.depth as depth
    import planeray.skin.model as model
    from planeray.skin.model import stated_skin_model, tables_to_trace

    monkeypatch.setenv("PLANERAY_CACHE", str(tmp_path / "empty-cache"))  # no user cache: only shipped tables
    skin, _ = stated_skin_model({}, tone="fair", wavelength_nm=638)
    assert tables_to_trace(skin, "fair", mm_per_row=0.3) == []  # the capture's row size: shipped
    assert tables_to_trace(skin, "fair", mm_per_row=0.31) != []  # another one: to trace

    events = []

    def pilot(stacks, *, mm_per_row):
        events.append(("pilot", mm_per_row))
        return 451.0

    class Traced(Exception):
        pass  # raised by the stand-in: tracing started

    def trace(*args, progress=None, **kw):
        events.append(("trace", kw["mm_per_row"]))
        raise Traced  # what was printed before tracing is what this test checks

    real_vein_model = depth.vein_model
    monkeypatch.setattr(model, "trace_seconds", pilot)
    monkeypatch.setattr(depth, "vein_model", trace)
    r = _run("skin", "depth", capture / "arm.zarr", "--mask", capture / "mask.png", "--mm-per-row", "0.31",
             "--out", tmp_path / "o")  # fmt: skip
    out = " ".join(r.output.split())
    note = out.index("neither shipped nor cached")
    assert "about 8 minutes" in out and "pilot run" in out, out
    assert r.exit_code == 1 and note < out.index("Traced") and not (tmp_path / "o").exists()  # then tracing began
    assert events == [("pilot", 0.31), ("trace", 0.31)]
    events.clear()
    monkeypatch.setattr(depth, "vein_model", real_vein_model)
    r = _run("skin", "depth", capture / "arm.zarr", "--mask", capture / "mask.png", "--out", tmp_path / "o2")
    assert r.exit_code == 0, r.output
    assert "neither shipped nor cached" not in r.output and events == []  # no pilot run either
