"""``planeray skin veins | enhance`` on a small stack, and the compare study's outputs (synthetic vein scene)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import planeray as pr
from _skin_toy import toy_vein_scene
from planeray.cli import app
from planeray.experiments.skin import run_skin_compare
from planeray.skin.masks import write_vein_mask


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    d = tmp_path_factory.mktemp("skin")
    scene = toy_vein_scene((48, 48), projector_rows=270, columns=(8, 24, 40))
    stack = pr.simulate_stack(scene, pr.timing.quick_sweep(), seed=0)
    pr.write_stack(stack, d / "s.zarr")
    write_vein_mask(d / "mask.png", scene.maps["vein_id"])
    return d


def _run(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def test_veins_writes_the_images_and_the_metrics(capture):
    out = capture / "veins"
    r = _run("skin", "veins", capture / "s.zarr", "--delay-us", 700, "--out", out, "--mask", capture / "mask.png")
    assert r.exit_code == 0, r.output
    assert "td750us_te600us (asked 700 us; served t_d 750 us, t_e 600 us)" in r.output
    assert "veins detected" in r.output
    meta = json.loads((out / "planeray.json").read_text())
    assert meta["format"] == "planeray-skin-veins" and meta["format_version"] == 2
    # the requested delay and the one that served it; each image named for its band
    assert meta["requested_delay_us"] == 700.0 and meta["requested_exposure_us"] is None
    assert meta["delay_us"] == 750.0 and meta["exposure_us"] == 600.0
    assert set(meta["metrics"]) == set(meta["images"]) == {"td750us_te600us", "td0us_te600us"}
    td0 = meta["images"]["td0us_te600us"]
    assert td0["band_rows"] == pytest.approx([-16.2, 16.2])  # +-t_e/2 = 300 us at 54,000 lines/s
    assert "rows -16.2 to +16.2" in td0["label"] and "5.8x the epipolar image" in td0["label"]
    assert meta["band_mm"] == pytest.approx([0.3 * 54_000 * 450e-6, 0.3 * 54_000 * 1050e-6])
    # the metric's definition and values, in mm on the skin (270 rows x 0.3 mm over 48 pixels)
    assert meta["mm_per_px"] == pytest.approx(270 * 0.3 / 48)
    assert meta["metric"]["gap_mm"] == 5.0 and meta["metric"]["width_mm"] == 10.0
    for name in ("td750us_te600us.png", "td750us_te600us.tif", "td0us_te600us.png", "veins.csv", "veins_figure.png"):
        assert (out / name).is_file()
    # a second run refuses to write over it, then replaces it with --overwrite
    r = _run("skin", "veins", capture / "s.zarr", "--out", out)
    assert r.exit_code == 1 and "already exists" in r.output
    r = _run("skin", "veins", capture / "s.zarr", "--delay-us", 750, "--out", out, "--overwrite")
    assert r.exit_code == 0, r.output
    assert "metrics" not in json.loads((out / "planeray.json").read_text())


def test_veins_never_serves_an_excluded_image_unless_asked(capture, tmp_path):
    """375 us at 600 us is a boundary image of the quick sweep (flagged excluded): refused, or used on request."""
    r = _run("skin", "veins", capture / "s.zarr", "--delay-us", 375, "--out", tmp_path / "v")
    assert r.exit_code == 1 and "375 us) is excluded" in r.output and "--include-excluded" in r.output
    assert len(r.output.strip().splitlines()) == 1 and not (tmp_path / "v").exists()
    r = _run("skin", "veins", capture / "s.zarr", "--delay-us", 375, "--include-excluded", "--out", tmp_path / "v")
    assert r.exit_code == 0, r.output
    meta = json.loads((tmp_path / "v" / "planeray.json").read_text())
    assert meta["delay_image"] == "td375us_te600us" and meta["include_excluded"] is True


def test_veins_gives_the_true_epipolar_image_from_a_transport(capture, tmp_path):
    """With ``--transport`` (or a transport store as the source) the epipolar image is Eq. 5's, not the
    t_d = 0 band, and a band image from a transport serves exactly the delay asked."""
    scene = toy_vein_scene((48, 48), projector_rows=270, columns=(8, 24, 40))
    pr.write_transport(scene.transport, tmp_path / "t.zarr", attrs={"lines_per_second": 54_000.0})
    mask = capture / "mask.png"
    args = ("--delay-us", 750, "--transport", tmp_path / "t.zarr", "--mask", mask)
    r = _run("skin", "veins", capture / "s.zarr", *args, "--out", tmp_path / "a")
    assert r.exit_code == 0, r.output
    meta = json.loads((tmp_path / "a" / "planeray.json").read_text())
    assert set(meta["images"]) == set(meta["metrics"]) == {"td750us_te600us", "td0us_te600us", "epipolar"}
    half = 270 / 48 / 2  # the camera row's own footprint, against +-16.2 rows for the t_d = 0 band
    assert meta["images"]["epipolar"]["band_rows"] == pytest.approx([-half, half])
    assert meta["images"]["td0us_te600us"]["band_rows"] == pytest.approx([-16.2, 16.2])
    import tifffile

    epi = tifffile.imread(tmp_path / "a" / "epipolar.tif")
    assert np.allclose(epi, scene.transport.epipolar_image(), rtol=1e-6)
    r = _run("skin", "veins", tmp_path / "t.zarr", "--delay-us", 500, "--out", tmp_path / "b", "--mask", mask)
    assert r.exit_code == 0, r.output
    meta = json.loads((tmp_path / "b" / "planeray.json").read_text())
    assert meta["source_kind"] == "transport" and meta["delay_us"] == 500.0 == meta["requested_delay_us"]
    assert set(meta["images"]) == {"td500us_te600us", "epipolar"}
    assert "assumed" in meta["mm_per_row_source"]
    img = tifffile.imread(tmp_path / "b" / "td500us_te600us.tif")
    assert np.allclose(img, pr.band_image(scene.transport, 500.0, 600.0), rtol=1e-5)
    # one line naming the option
    r = _run("skin", "veins", capture / "s.zarr", "--transport", capture / "s.zarr", "--out", tmp_path / "c")
    assert r.exit_code == 1 and "--transport" in r.output and "not a planeray transport store" in r.output
    r = _run("skin", "veins", tmp_path / "t.zarr", "--transport", tmp_path / "t.zarr", "--out", tmp_path / "c")
    assert r.exit_code == 1 and "--transport" in r.output
    r = _run("skin", "veins", capture / "s.zarr", "--mm-per-row", -1, "--out", tmp_path / "c")
    assert r.exit_code == 1 and "--mm-per-row" in r.output


def test_enhance_writes_the_composite_and_the_delay_map(capture):
    out = capture / "enh"
    r = _run("skin", "enhance", capture / "s.zarr", "--out", out, "--mask", capture / "mask.png")
    assert r.exit_code == 0, r.output
    assert "left out the stack's excluded 375 us" in r.output
    meta = json.loads((out / "planeray.json").read_text())
    assert meta["delays_us"] == [750.0, 1125.0, 1500.0] and meta["excluded_delays_us"] == [375.0]
    assert meta["images"] == ["td750us_te600us", "td1125us_te600us", "td1500us_te600us"]
    assert meta["metrics"]["enhanced"]["n_veins"] == 3 and meta["metric"]["gap_mm"] == 5.0
    assert meta["metrics"]["best_single"]["image"] in meta["images"]
    import tifffile

    dmap = tifffile.imread(out / "delay_map_us.tif")
    assert dmap.shape == (48, 48) and 750.0 <= dmap.min() and dmap.max() <= 1500.0
    r = _run("skin", "enhance", capture / "s.zarr", "--out", capture / "enh2", "--include-excluded")
    assert r.exit_code == 0, r.output
    meta = json.loads((capture / "enh2" / "planeray.json").read_text())
    assert meta["delays_us"] == [375.0, 750.0, 1125.0, 1500.0] and meta["include_excluded"] is True


def test_bad_inputs_give_one_line(capture, tmp_path):
    (tmp_path / "bad.png").write_bytes(b"junk")
    r = _run("skin", "veins", capture / "s.zarr", "--out", tmp_path / "o", "--mask", tmp_path / "bad.png")
    assert r.exit_code == 1 and "bad.png: cannot read the vein mask" in r.output
    assert len(r.output.strip().splitlines()) == 1
    r = _run("skin", "veins", capture / "s.zarr", "--out", tmp_path / "o2", "--delay-us", 9000)
    assert r.exit_code == 1 and "--delay-us = 9000: the stack has no image near that delay" in r.output
    r = _run("skin", "enhance", capture / "s.zarr", "--out", tmp_path / "o3", "--min-delay-us", 1400)
    assert r.exit_code == 1 and "needs at least 2" in r.output
    assert not any(p.name.startswith("o") for p in tmp_path.iterdir() if p.name != "bad.png")


def test_compare_study_writes_numbers_and_figures(tmp_path):
    def factory(shape, seed=0, **conditions):
        return toy_vein_scene(shape, projector_rows=270, columns=(8, 24, 40))

    n = run_skin_compare(tmp_path / "rep", size=48, quick=True, scene_factory=factory)
    files = {p.name for p in (tmp_path / "rep").iterdir()}
    assert {"skin.json", "skin_cnr.csv", "skin_veins.csv", "skin_ambient.csv", "planeray.json"} <= files
    assert {"fig13_skin_ambient.png", "fig14_skin_enhance.png", "fig16_skin_methods.png"} <= files
    assert json.loads((tmp_path / "rep" / "skin.json").read_text())["table"] == n["table"]
    amb = {(r["level"], r["method"]): r["cnr"] for r in n["ambient"]}
    assert amb[("sunlight", "delay")] > amb[("sunlight", "photo")]
    assert amb[("sunlight", "delay")] > amb[("sunlight", "global")]
    assert np.isfinite(n["enhancement"]["enhanced_cnr"])


def test_veins_on_a_simulated_skin_capture_uses_its_ground_truth(tmp_path):
    """``skin simulate`` writes the truth beside the stack; ``skin veins`` finds it (hair and depths included)."""
    r = _run(
        "skin", "simulate", "--out", tmp_path / "arm.zarr", "--size", 64, 64, "--sweep", "quick", "--hair", "--seed", 1
    )
    assert r.exit_code == 0, r.output
    r = _run("skin", "veins", tmp_path / "arm.zarr", "--delay-us", 750, "--out", tmp_path / "v")
    assert r.exit_code == 0, r.output
    meta = json.loads((tmp_path / "v" / "planeray.json").read_text())
    assert meta["ground_truth"].endswith("arm_maps.npz")
    rows = (tmp_path / "v" / "veins.csv").read_text().splitlines()
    assert rows[0].startswith("image,id,pixels,band_pixels,depth_mm,diameter_mm")
    r = _run("skin", "enhance", tmp_path / "arm.zarr", "--out", tmp_path / "e")
    assert r.exit_code == 0, r.output
    assert "best single delay" in r.output


def test_veins_on_a_captured_import_folder(capture, tmp_path):
    """The import format (16-bit TIFFs + manifest) gives what the native stack gives, to quantization."""
    r = _run("export", capture / "s.zarr", "--out", tmp_path / "folder")
    assert r.exit_code == 0, r.output
    for src, out in ((tmp_path / "folder", "v"), (capture / "s.zarr", "n")):
        r = _run("skin", "veins", src, "--delay-us", 750, "--out", tmp_path / out, "--mask", capture / "mask.png")
        assert r.exit_code == 0, r.output
    imported = json.loads((tmp_path / "v" / "planeray.json").read_text())
    native = json.loads((tmp_path / "n" / "planeray.json").read_text())
    assert imported["delay_us"] == 750.0 and imported["metrics"]["td750us_te600us"]["n_veins"] == 3
    assert imported["include_excluded"] is False
    assert imported["metrics"]["td750us_te600us"]["cnr"] == pytest.approx(
        native["metrics"]["td750us_te600us"]["cnr"], rel=0.02
    )
