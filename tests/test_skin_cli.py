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
    r = _run("skin", "veins", capture / "s.zarr", "--delay-us", 375, "--out", out, "--mask", capture / "mask.png")
    assert r.exit_code == 0, r.output
    assert "delay image at 375 us" in r.output and "veins detected" in r.output
    meta = json.loads((out / "planeray.json").read_text())
    assert meta["format"] == "planeray-skin-veins" and meta["delay_us"] == 375.0
    assert set(meta["metrics"]) == {"delay", "direct"}
    assert meta["band_mm"] == pytest.approx([0.3 * 54_000 * 75e-6, 0.3 * 54_000 * 675e-6])
    for name in ("delay.png", "delay.tif", "direct.png", "veins.csv", "veins_figure.png"):
        assert (out / name).is_file()
    # a second run refuses to write over it, then replaces it with --overwrite
    r = _run("skin", "veins", capture / "s.zarr", "--out", out)
    assert r.exit_code == 1 and "already exists" in r.output
    r = _run("skin", "veins", capture / "s.zarr", "--out", out, "--overwrite")
    assert r.exit_code == 0, r.output
    assert "metrics" not in json.loads((out / "planeray.json").read_text())


def test_enhance_writes_the_composite_and_the_delay_map(capture):
    out = capture / "enh"
    r = _run("skin", "enhance", capture / "s.zarr", "--out", out, "--mask", capture / "mask.png")
    assert r.exit_code == 0, r.output
    meta = json.loads((out / "planeray.json").read_text())
    assert meta["delays_us"] == [375.0, 750.0, 1125.0, 1500.0]
    assert meta["metrics"]["enhanced"]["n_veins"] == 3
    import tifffile

    dmap = tifffile.imread(out / "delay_map_us.tif")
    assert dmap.shape == (48, 48) and 375.0 <= dmap.min() and dmap.max() <= 1500.0


def test_bad_inputs_give_one_line(capture, tmp_path):
    (tmp_path / "bad.png").write_bytes(b"junk")
    r = _run("skin", "veins", capture / "s.zarr", "--out", tmp_path / "o", "--mask", tmp_path / "bad.png")
    assert r.exit_code == 1 and "bad.png: cannot read the vein mask" in r.output
    assert len(r.output.strip().splitlines()) == 1
    r = _run("skin", "veins", capture / "s.zarr", "--out", tmp_path / "o2", "--delay-us", 9000)
    assert r.exit_code == 1 and "no image near delay 9000" in r.output
    r = _run("skin", "enhance", capture / "s.zarr", "--out", tmp_path / "o3", "--min-delay-us", 1400)
    assert r.exit_code == 1 and "needs at least 2" in r.output
    assert not any(p.name.startswith("o") for p in tmp_path.iterdir())


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
    r = _run("skin", "veins", tmp_path / "arm.zarr", "--delay-us", 375, "--out", tmp_path / "v")
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
        r = _run("skin", "veins", src, "--delay-us", 375, "--out", tmp_path / out, "--mask", capture / "mask.png")
        assert r.exit_code == 0, r.output
    imported = json.loads((tmp_path / "v" / "planeray.json").read_text())
    native = json.loads((tmp_path / "n" / "planeray.json").read_text())
    assert imported["delay_us"] == 375.0 and imported["metrics"]["delay"]["n_veins"] == 3
    assert imported["metrics"]["delay"]["cnr"] == pytest.approx(native["metrics"]["delay"]["cnr"], rel=0.02)
