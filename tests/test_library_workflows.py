"""Every documented output folder of the command line, produced from a notebook: the library functions
(``planeray.experiments.materials_folders``, ``materials_recognize``, ``skin_folders``, ``skin_depth_folder``) write it, and what they write is
checked against the underlying computation run here independently (its arrays, its numbers)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import tifffile
from PIL import Image

from planeray.errors import InputError
from planeray.experiments import materials_folders as mf
from planeray.experiments import materials_recognize as mr
from planeray.experiments import skin_depth_folder as sd
from planeray.experiments import skin_folders as sf
from planeray.io import jsonable, read_stack, read_transport
from planeray.materials import fit, read_label_image
from planeray.materials.library import load_library
from planeray.materials.settings import CaptureSettings
from test_materials_recognition import capture  # noqa: F401 - the fixture: two media, labels, a library

MM = 0.3
MAPS = ("mu_s_prime_per_mm", "mu_a_per_mm", "mu_s_prime_se_per_mm", "mu_a_se_per_mm")


def _tif(path):
    return tifffile.imread(path)


def _json(path):
    return json.loads(path.read_text())


@pytest.fixture(scope="module")
def materials(capture):  # noqa: F811 - the imported fixture
    """An 8 x 8 transport store of two media side by side (known coefficients), its labels and a version-1
    library (``test_materials_recognition``'s), and the forward table."""
    return capture[0], fit.forward_table()


def _same(a, b):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.usefixtures("figures_not_drawn")
def test_fit_materials_writes_the_fit_folder_of_the_underlying_fit(materials, tmp_path):
    root, table = materials
    notes, events = [], []
    summary = mf.fit_materials(
        root / "cap.zarr", tmp_path / "fit", labels=root / "labels.png", block_px=4, walls=False,
        note=notes.append, progress=lambda *e: events.append(e),
    )  # fmt: skip
    transport, attrs = read_transport(root / "cap.zarr")
    lab = read_label_image(root / "labels.png")
    truth = fit.fit_transport(transport, mm_per_row=MM, labels=lab, block_px=4, table=table)  # the fit, directly
    out = tmp_path / "fit"
    for key in MAPS:
        _same(_tif(out / f"{key}.tif"), truth.maps[key].astype(np.float32))
    _same(_tif(out / "identifiability_mask.tif"), truth.maps["mask"].astype(np.uint8))
    _same(_tif(out / "flags.tif"), truth.maps["flags"].astype(np.uint8))
    meta = _json(out / "planeray.json")
    assert meta == jsonable(summary) and meta["regions"] == jsonable({str(k): v for k, v in truth.regions.items()})
    assert (meta["format"], meta["mm_per_row"], meta["block_px"], meta["refractive_index"]) == (
        "planeray-materials-fit", MM, 4, 1.33)  # fmt: skip
    assert meta["walls"] == "none: unbounded media" and meta["method"].startswith("transport")
    # a notebook's words: the parameters by their keywords, the assumption as a note
    assert meta["refractive_index_source"] == "assumed (water-based media; state n)"
    assert len(notes) == 1 and "state it with n (1 for" in notes[0]
    assert ("fitting pixel blocks", 4, 4) in events  # two regions of two 4 x 4 blocks, counted to the end
    assert sorted(p.name for p in out.iterdir()) == sorted([*(f"{k}.tif" for k in MAPS), "identifiability_mask.tif",
                                                             "flags.tif", "fit.png", "planeray.json"])  # fmt: skip
    with pytest.raises(InputError, match="^block_px must be an integer in 1-64, got 0$"):
        mf.fit_materials(root / "cap.zarr", tmp_path / "fit2", block_px=0)
    with pytest.raises(InputError, match="already exists"):  # checked before any work
        mf.fit_materials(root / "cap.zarr", out, settings=CaptureSettings(n=1.33))


@pytest.mark.usefixtures("figures_not_drawn")
def test_recognize_materials_writes_the_segmentation_of_the_underlying_recognition(materials, tmp_path):
    from planeray.materials.recognize import DEFAULT_POOL_MM, fit_image, recognize_image

    root, _ = materials
    out = tmp_path / "rec"
    numbers = mr.recognize_materials(
        root / "cap.zarr", out, library=root / "lib.json", labels=root / "labels.png", progress=lambda *e: None
    )
    transport, _ = read_transport(root / "cap.zarr")
    maps = fit_image(transport, mm_per_row=MM, block_px=2)
    rec = recognize_image(load_library(root / "lib.json"), maps, mm_per_pixel=MM, pool_mm=DEFAULT_POOL_MM,
                          p_unknown=1e-3)  # fmt: skip
    _same(np.asarray(Image.open(out / "segmentation.png")), rec.class_ids.astype(np.uint8))
    _same(_tif(out / "flags.tif"), np.asarray(rec.flags, np.uint8))
    meta = _json(out / "planeray.json")
    assert meta == jsonable(numbers) and meta["format"] == "planeray-materials-recognition"
    assert meta["pixels"] == {"thin": int((rec.class_ids == 1).sum()), "thick": int((rec.class_ids == 2).sum()),
                              "unclassified": int((rec.class_ids == 0).sum())}  # fmt: skip
    assert meta["pooling"] == f"log-likelihoods over a disc of {DEFAULT_POOL_MM:g} mm" and meta["block_px"] == 2
    assert meta["score"]["wall_distance"].startswith("from labels:")
    assert sorted(meta["files"]) == ["figure", "flags", "segmentation"] and (out / "recognition.png").is_file()


def test_add_to_library_adds_the_entry_of_the_underlying_fit(materials, tmp_path):
    from planeray.materials.recognize import entries_from_capture, fit_image

    root, _ = materials
    out = tmp_path / "lib2.json"
    lib, entries = mr.add_to_library(
        root / "cap.zarr", out, labels=root / "labels.png", class_names={2: "paste"}, library=root / "lib.json",
        replace=True,
    )  # fmt: skip
    transport, _ = read_transport(root / "cap.zarr")
    lab = read_label_image(root / "labels.png")
    regions = np.where(lab == 2, lab, 0)
    (expected,) = entries_from_capture(
        fit_image(transport, mm_per_row=MM, block_px=2, regions=regions), regions, {2: "paste"},
        source=f"{root / 'cap.zarr'} ({root / 'labels.png'})",
    )  # fmt: skip
    written = load_library(out)
    assert [e.name for e in written.entries] == ["thin", "paste"] and written.entry("paste") == expected
    assert entries == [expected] and lib.entries == written.entries
    with pytest.raises(InputError, match="^class_names 9=x: labels .* has no pixel of that id$"):
        mr.add_to_library(root / "cap.zarr", tmp_path / "lib3.json", labels=root / "labels.png", class_names={9: "x"})


@pytest.fixture(scope="module")
def skin(tmp_path_factory):
    """A 48 x 48 quick-sweep capture of the toy vein scene and its vein mask (ids 1-3)."""
    import planeray as pr
    from _skin_toy import toy_vein_scene

    d = tmp_path_factory.mktemp("skin_workflows")
    toy = toy_vein_scene((48, 48), projector_rows=270, columns=(8, 24, 40))
    pr.write_stack(pr.simulate_stack(toy, pr.quick_sweep(), seed=0), d / "toy.zarr")
    Image.fromarray(toy.maps["vein_id"].astype(np.uint8)).save(d / "mask.png")
    return d


@pytest.mark.usefixtures("figures_not_drawn")
def test_vein_images_writes_the_band_images_and_their_metrics(skin, tmp_path):
    from planeray.skin.imaging import pixel_mm, stack_images
    from planeray.skin.masks import read_vein_mask
    from planeray.skin.metrics import vein_metrics

    out = tmp_path / "veins"
    result = sf.vein_images(skin / "toy.zarr", out, delay_us=750.0, mask=skin / "mask.png")
    stack = read_stack(skin / "toy.zarr")
    images, info = stack_images(stack, delay_us=750.0, exposure_us=None, include_excluded=False, mm_per_row=MM)
    assert list(result["images"]) == list(images) and result["delay_image"] == info["delay_image"]
    vein_id = read_vein_mask(skin / "mask.png", stack.shape)
    rows = []
    for name, image in images.items():
        _same(_tif(out / f"{name}.tif"), image.astype(np.float32))
        m = vein_metrics(image, vein_id, mm_per_px=pixel_mm(stack.geometry, MM))
        assert result["metrics"][name]["cnr"] == pytest.approx(m["cnr"])
        rows += [{"image": name, **r} for r in m["veins"]]
    with open(out / "veins.csv", newline="") as f:
        got = list(csv.DictReader(f))
    assert [r["image"] for r in got] == [r["image"] for r in rows]
    assert [float(r["cnr"]) for r in got] == pytest.approx([r["cnr"] for r in rows])
    meta = _json(out / "planeray.json")
    assert meta == jsonable(result) and (meta["format"], meta["mm_per_row"]) == ("planeray-skin-veins", MM)
    assert meta["ground_truth"] == str(skin / "mask.png") and meta["mm_per_row_source"] == "stack metadata"
    with pytest.raises(InputError, match=r"\(source\)"):  # the positional argument, by its keyword
        sf.vein_images(tmp_path / "none.zarr", tmp_path / "v2")


@pytest.mark.usefixtures("figures_not_drawn")
def test_enhance_veins_writes_eq7s_image_and_delay_map(skin, tmp_path):
    from planeray.skin.enhance import enhance_contrast
    from planeray.skin.imaging import delay_sweep_images

    out = tmp_path / "enhance"
    stages = []
    result = sf.enhance_veins(skin / "toy.zarr", out, progress=lambda s, done, total: stages.append(s))
    stack = read_stack(skin / "toy.zarr")
    imgs, delays, sel = delay_sweep_images(stack, exposure_us=None, min_delay_us=0.0, include_excluded=False)
    res = enhance_contrast(imgs, delays, patch_px=None, noise_normalize=True)
    _same(_tif(out / "enhanced.tif"), res.image.astype(np.float32))
    _same(_tif(out / "delay_map_us.tif"), res.delay_map_us.astype(np.float32))
    meta = _json(out / "planeray.json")
    assert meta == jsonable(result) and meta["delays_us"] == [float(d) for d in delays]
    assert meta["exposure_us"] == sel["exposure_us"] and "metrics" not in meta  # no mask, no truth beside it
    assert stages[0] == "reading the delay images" and stages[-1].startswith("enhancing (")


@pytest.mark.usefixtures("figures_not_drawn")
def test_vein_depths_writes_each_veins_fit(skin, tmp_path, monkeypatch):
    import planeray.skin.depth as skin_depth

    def fit_vein(model, images, variance, pix, *, vein_id=1, **kw):  # a stand-in answering at once: the folder
        return skin_depth.VeinFit(vein_id, vein_id != 3, "" if vein_id != 3 else "too deep", 1.0 + vein_id, 2.5, 0.1, 0.3,
                          0.2, 100.0, 1.1, pix.rows.size, len(images))  # fmt: skip

    monkeypatch.setattr(skin_depth, "fit_vein", fit_vein)
    out = tmp_path / "depth"
    result = sd.vein_depths(skin / "toy.zarr", out, mask=skin / "mask.png", tone="fair")
    vein_id = np.asarray(Image.open(skin / "mask.png")).astype(np.uint16)
    _same(np.asarray(Image.open(out / "vein_ids.png")), vein_id)
    depth = _tif(out / "depth_mm.tif")
    for vid in (1, 2):
        assert (depth[vein_id == vid] == np.float32(1.0 + vid)).all()
    assert np.isnan(depth[(vein_id == 0) | (vein_id == 3)]).all()
    meta = _json(out / "planeray.json")
    assert meta == jsonable(result) and [v["resolved"] for v in meta["veins"]] == [True, True, False]
    assert (meta["tone"], meta["tone_source"], meta["wavelength_nm"]) == ("fair", "tone", 638)
    with open(out / "veins.csv", newline="") as f:
        assert [int(r["id"]) for r in csv.DictReader(f)] == [1, 2, 3]
    with pytest.raises(InputError, match="^g must be in"):
        sd.vein_depths(skin / "toy.zarr", tmp_path / "d2", g=1.0)


@pytest.mark.usefixtures("figures_not_drawn")
def test_emulation_folder_writes_the_comparisons_images_and_numbers(tmp_path):
    from planeray.baselines import compare_emulation
    from planeray.devices import simulated_device
    from planeray.experiments.baselines import emulation_folder

    def device():
        return simulated_device("diffuse_plane", (16, 16), projector_rows=32, seed=0)

    numbers = emulation_folder(device(), tmp_path / "emu", delay_us=0.0, exposure_us=600.0, spacing_rows=None)
    res = compare_emulation(device(), delay_us=0.0, exposure_us=600.0, spacing_rows=None)  # the same, run here
    for key, image in (("emulated", res["emulated"].image), ("synchronized", res["synchronized"]),
                       ("truth", res["truth"])):  # fmt: skip
        codes = np.round(np.clip(np.nan_to_num(image), 0, 1) * 65535)  # write_image's codes, within its rounding
        assert np.abs(_tif(tmp_path / "emu" / f"{key}.tif").astype(np.float64) - codes).max() <= 1.0, key
        assert (tmp_path / "emu" / f"{key}.png").is_file()
    meta = _json(tmp_path / "emu" / "emulation.json")
    assert meta["n_captures"] == res["numbers"]["n_captures"] == numbers["n_captures"]
    assert meta["errors"] == json.loads(json.dumps(res["numbers"]["errors"]))
