"""Delay-profile characterization and effect classification (Sec. 8, Fig. 9).

Unit tests on synthetic transport profiles (closed forms), then agreement of the
labels with the built-in scenes' ground truth, on demultiplexed transports (the
realistic case: paper sweep, default camera) and on the exact transports.
"""

import dataclasses
import json

import numpy as np
import pytest

from planeray.acquire import simulate_stack
from planeray.classify import (
    CLASSIFY_THRESHOLDS,
    characterize,
    classify_transport,
    label_agreement,
    visible_effect_mask,
)
from planeray.demux import demultiplex
from planeray.errors import InputError
from planeray.profiles import transport_delay_profiles
from planeray.scenes import list_scenes, make_scene
from planeray.timing import Band, paper_sweep, sweep_support_rows
from planeray.transport import SparseEntries, Transport

U = np.arange(-114, 115)  # the paper sweep's offsets


def delta(at=0, value=1.0):
    p = np.zeros(U.size)
    p[np.flatnonzero(U == at)[0]] = value
    return p


def gaussian(sigma, centre=0.0, energy=1.0):
    g = np.exp(-0.5 * ((U - centre) / sigma) ** 2)
    return energy * g / g.sum()


# ---------------------------------------------------------------- synthetic profiles
def test_delta_is_unimodal_narrow_diffuse():
    ch = characterize(delta(), U, smooth_bins=1)
    assert ch.label == 1 and ch.peak_count == 1
    assert ch.fwhm_rows == pytest.approx(1.0)  # half maximum half a bin either side
    assert ch.indirect_fraction == 0.0 and ch.asymmetry == 0.0 and ch.spread_rows == 0.0
    assert np.isnan(ch.second_peak_offset_rows) and np.isnan(ch.displaced_peak_offset_rows)
    # default smoothing (5 bins) widens it to a 5-bin box, still one narrow peak
    ch = characterize(delta(), U)
    assert ch.label == 1 and ch.peak_count == 1 and ch.fwhm_rows == pytest.approx(5.0)


def test_direct_peak_inside_unresolved_cell_is_diffuse():
    # a camera-row footprint of 5.6 rows inside the 6-row cell of the paper sweep
    p = np.where(np.abs(U) <= 3, 1.0, 0.0)
    ch = characterize(p, U, resolution_rows=6.075, footprint_rows=5.625)
    assert ch.cell_rows == pytest.approx(6.075 + 5.625 / 2 + 0.5)
    assert ch.label == 1 and ch.indirect_fraction == 0.0


def test_broad_gaussian_is_subsurface():
    ch = characterize(delta() + gaussian(12.0), U)
    assert ch.label == 2
    assert abs(ch.asymmetry) < 0.05
    assert ch.indirect_fraction > 0.4
    assert ch.spread_rows > 8.0
    assert ch.peak_count == 1


def test_one_sided_decay_is_diffuse_interreflection():
    tail = np.where(U >= 4, 0.02 * np.exp(-(U - 4) / 25.0), 0.0)
    ch = characterize(delta() + tail, U)
    assert ch.label == 3
    assert ch.asymmetry > 0.6
    mirrored = characterize((delta() + tail)[::-1], U)
    assert mirrored.label == 3 and mirrored.asymmetry < -0.6


def test_a_displaced_spike_must_hold_a_real_share_of_the_light():
    # A weakly regularized estimate of a broad skirt piles light into spikes (on the
    # Monte Carlo wax: at u = 50 and 54, 2-4 % of the light). A spike prominent enough
    # to pass the peak rules but holding 3.8 % of the light is subsurface; the same
    # spike holding 13 % is a specular reflection.
    skirt = gaussian(20.0)
    small = skirt + delta(52, 0.04)
    assert characterize(small, U, displaced_share_min=0.0).label == 4  # the peak rules alone
    ch = characterize(small, U)
    assert ch.label == 2 and np.isnan(ch.displaced_peak_offset_rows)
    big = characterize(skirt + delta(52, 0.15), U)
    assert big.label == 4 and big.displaced_peak_offset_rows == pytest.approx(52, abs=3)  # 5-bin smoothing


def test_displaced_second_peak_is_specular():
    for at in (40, -40, 75):
        ch = characterize(delta() + delta(at, 0.5), U)
        assert ch.label == 4
        assert ch.peak_count == 2
        assert ch.second_peak_offset_rows == at
        assert ch.displaced_peak_offset_rows == at
        assert ch.peak_offset_rows == 0
    # a dominant displaced peak: the main peak itself lies beyond the cell
    ch = characterize(delta(0, 0.2) + delta(60, 1.0), U)
    assert ch.label == 4 and ch.peak_offset_rows == 60 and ch.second_peak_offset_rows == 0


def test_weak_displaced_bump_is_not_a_peak():
    ch = characterize(delta() + delta(40, 0.05), U)  # below 15 % of the main peak
    assert ch.label == 1 and ch.peak_count == 1


def test_fwhm_and_spread_closed_forms():
    box = np.where(np.abs(U) <= 10, 1.0, 0.0)  # 21 bins
    assert characterize(box, U, smooth_bins=1).fwhm_rows == pytest.approx(21.0)
    for sigma in (4.0, 9.0):
        ch = characterize(gaussian(sigma), U, smooth_bins=1, subtract_floor=False)
        assert ch.fwhm_rows == pytest.approx(2 * np.sqrt(2 * np.log(2)) * sigma, rel=0.01)
        assert ch.spread_rows == pytest.approx(sigma, rel=0.01)


def test_scale_free_and_floor_subtracted():
    p = delta() + gaussian(12.0)
    a, b = characterize(p, U), characterize(37.0 * p, U)
    assert a.indirect_fraction == pytest.approx(b.indirect_fraction, rel=1e-5)
    assert a.fwhm_rows == pytest.approx(b.fwhm_rows, rel=1e-5)
    # ambient light: a constant over all offsets (20 % of the energy) is not indirect light
    ch = characterize(delta() + 0.25 / U.size * U.size / 229 * np.ones(U.size), U)
    assert ch.label == 1 and ch.indirect_fraction < 0.01


def test_noisy_floor_of_a_sparse_estimate_is_rejected():
    # a demultiplexed diffuse pixel: the cell's light spread over |u| <= 6, plus an
    # ambient floor that an L1 estimate concentrates into isolated spikes
    # (half the bins lit, 25 % of the energy: as measured on the built-in scenes)
    rng = np.random.default_rng(3)
    base = np.where(np.abs(U) <= 6, 1.0 / 13, 0.0)
    spikes = np.zeros((200, U.size))
    hit = rng.random((200, U.size)) < 0.5
    spikes[hit] = rng.exponential(0.25 / (0.5 * U.size), hit.sum())
    ch = characterize(base + spikes, U, resolution_rows=6.075)
    raw = characterize(base + spikes, U, resolution_rows=6.075, subtract_floor=False)
    assert np.median(raw.indirect_fraction) > 0.15  # the floor, taken for indirect light
    assert np.median(ch.indirect_fraction) < 0.05  # ... is removed
    assert np.all(ch.peak_count == 1) and not np.any(ch.label == 4)  # spikes are no peaks
    # Independent spikes are harsher than a real estimate, whose band integrals the
    # images pin down (diffuse recall there: > 0.98, see the scene tests below).
    assert np.mean(ch.label == 1) > 0.75


def test_characterize_is_vectorized_over_leading_axes():
    profiles = np.stack([delta(), delta() + gaussian(12.0), delta() + delta(40, 0.5)])
    grid = np.stack([profiles, profiles[::-1]])  # (2, 3, U)
    ch = characterize(grid, U)
    assert ch.label.shape == (2, 3) and ch.label.dtype == np.uint8
    np.testing.assert_array_equal(ch.label, [[1, 2, 4], [4, 2, 1]])
    one = characterize(profiles[2], U)
    assert ch.second_peak_offset_rows[0, 2] == one.second_peak_offset_rows
    valid = np.ones(U.size, bool)
    valid[U < -20] = False  # e.g. off the projector: ignored
    assert characterize(delta() + delta(-40, 0.5), U, valid=valid).label == 1


def test_characterize_rejects_bad_input():
    with pytest.raises(InputError):
        characterize(np.zeros((3, 10)), np.arange(11))
    with pytest.raises(InputError):
        characterize(delta(), U, no_such_threshold=1.0)
    assert characterize(np.zeros(U.size), U).label == 0  # no light at all
    assert set(CLASSIFY_THRESHOLDS) >= {"peak_prominence", "indirect_fraction_min", "asymmetry_min"}


# ---------------------------------------------------------------- delay profiles of a transport
@pytest.fixture(scope="module")
def plane():
    return make_scene("diffuse_plane", (32, 32), projector_rows=180, seed=0)


def test_transport_profiles_are_T_over_delay_and_area_normalized(plane):
    T = plane.transport
    prof = transport_delay_profiles(T)
    assert prof.values.shape == T.dense.shape and prof.pixels is None and prof.exposure_us is None
    np.testing.assert_allclose(prof.delay_us, T.offsets_rows * 1e6 / 54000.0)
    np.testing.assert_allclose(prof.raw, T.dense)
    area = np.trapezoid(prof.values, prof.delay_us * 1e-3, axis=-1)
    np.testing.assert_allclose(area, 1.0, rtol=1e-5)
    px = np.array([[3, 4], [20, 11]])
    few = transport_delay_profiles(T, px)
    assert few.values.shape == (2, T.offsets_rows.size)
    np.testing.assert_allclose(few.values, prof.values[px[:, 0], px[:, 1]])
    # albedo cancels
    np.testing.assert_allclose(transport_delay_profiles(T, [[3, 4]]).values[0] * 1.0, prof.values[3, 4], rtol=1e-6)


def test_transport_profiles_at_an_exposure_render_bands(plane):
    T = plane.transport
    prof = transport_delay_profiles(T, [[16, 16], [5, 9]], exposure_us=600.0)
    step = 1e6 / 54000.0
    assert prof.delay_us[0] == pytest.approx(-1500.0) and prof.delay_us[-1] == pytest.approx(1500.0)
    np.testing.assert_allclose(np.diff(prof.delay_us), step)
    i = int(np.argmin(np.abs(prof.delay_us - 185.0)))
    np.testing.assert_allclose(prof.raw[0, i], T.render(Band(prof.delay_us[i], 600.0, 54000.0))[16, 16], rtol=1e-6)
    np.testing.assert_allclose(np.trapezoid(prof.values, prof.delay_us * 1e-3, axis=-1), 1.0, rtol=1e-5)
    # direct light: a plateau as wide as the exposure, centred on t_d = 0
    v = prof.values[0]
    width = (v >= 0.5 * v.max()).sum() * step
    assert width == pytest.approx(600.0, abs=2 * step)
    assert abs(np.sum(v * prof.delay_us) / v.sum()) < step
    whole = transport_delay_profiles(T, exposure_us=600.0, delays_us=[0.0, -300.0])
    assert whole.values.shape == (32, 32, 2) and list(whole.delay_us) == [-300.0, 0.0]


def test_transport_profiles_reject_bad_input(plane):
    with pytest.raises(InputError):
        transport_delay_profiles(plane.transport, [[32, 0]])
    with pytest.raises(InputError):
        transport_delay_profiles(plane.transport, exposure_us=-5.0)
    with pytest.raises(InputError):
        transport_delay_profiles(plane.transport, delays_us=[0.0])


# ---------------------------------------------------------------- agreement bookkeeping
def test_label_agreement_counts():
    truth = np.array([[0, 1, 1, 2], [3, 3, 4, 4]])
    pred = np.array([[4, 1, 2, 2], [3, 1, 4, 1]])
    a = label_agreement(pred, truth)
    assert a["n"] == 7  # label 0 ignored
    assert a["recall"] == {1: 0.5, 2: 1.0, 3: 0.5, 4: 0.5}
    assert a["counts"] == {1: 2, 2: 1, 3: 2, 4: 2}
    assert a["confusion"].shape == (5, 5) and a["confusion"][1, 2] == 1 and a["confusion"][3, 1] == 1
    assert a["overall"] == pytest.approx(4 / 7)
    masked = label_agreement(pred, truth, mask=truth != 4)
    assert 4 not in masked["recall"] and masked["n"] == 5
    with pytest.raises(InputError):
        label_agreement(pred[:1], truth)


def test_visible_effect_mask(plane):
    assert visible_effect_mask(plane).all()
    mirror = make_scene("mirror_ball", (64, 64), projector_rows=360, seed=0)
    vis = visible_effect_mask(mirror)
    assert not vis[mirror.labels == 0].any()
    assert vis[mirror.labels == 1].all()
    spec = mirror.labels == 4
    # the page's specular light is a few percent of its direct light: only the ball shows it
    assert 50 < vis[spec].sum() < 0.2 * spec.sum()


# ---------------------------------------------------------------- built-in scenes
SCENES = ["diffuse_plane", "wax", "corner", "mirror_ball", "disco_ball"]
# Recall on the visible pixels, 64x64 camera rows of 360 projector rows, seed 0,
# measured: demux diffuse 0.984-0.992, wax subsurface 0.934, corner diffuse
# interreflection 0.974, mirror-ball specular 0.891, disco-ball specular 0.963
# (seeds 0-3: minimum 0.982 / 0.927 / 0.972 / 0.840 / 0.903).  Asserted with margins.
DEMUX_MIN = {
    "diffuse_plane": {1: 0.95},
    "wax": {1: 0.95, 2: 0.88},
    "corner": {1: 0.95, 3: 0.92},
    "mirror_ball": {1: 0.95, 4: 0.82},
    "disco_ball": {1: 0.95, 4: 0.88},
}
# Ground truth seen as the sweep sees it (support 114 rows, cell 6.075 rows): measured
# 1.0 except corner diffuse 0.954 (pixels with 5-7 % real one-sided light, labelled
# diffuse by the scene's 10 %-of-direct rule), wax 0.990, mirror ball 0.891, disco
# ball 0.822 (spots 12-17 rows from the epipolar plane merge with the direct peak).
TRUTH_MIN = {
    "diffuse_plane": {1: 0.99},
    "wax": {1: 0.99, 2: 0.94},
    "corner": {1: 0.9, 3: 0.95},
    "mirror_ball": {1: 0.99, 4: 0.84},
    "disco_ball": {1: 0.99, 4: 0.7},
}


@pytest.fixture(scope="module")
def scenes():
    out = {}
    for name in SCENES:
        scene = make_scene(name, (64, 64), projector_rows=360, seed=0)
        result = demultiplex(simulate_stack(scene, paper_sweep(), seed=0))
        out[name] = (scene, result)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENES)
def test_labels_agree_on_demultiplexed_scenes(scenes, name):
    scene, result = scenes[name]
    resolution = result.attrs["epipolar_resolution_rows"]
    assert resolution == pytest.approx(6.075)
    labels, ch = classify_transport(result.transport, resolution_rows=resolution, return_character=True)
    assert labels.shape == scene.shape and labels.dtype == np.uint8
    assert ch.fwhm_rows.shape == scene.shape
    vis = visible_effect_mask(
        scene, support_rows=sweep_support_rows(paper_sweep(), 54000.0), resolution_rows=resolution
    )
    a = label_agreement(labels, scene.labels, mask=vis)
    for k, minimum in DEMUX_MIN[name].items():
        assert a["recall"][k] >= minimum, (name, k, a["recall"], a["confusion"].tolist())


@pytest.mark.parametrize("name", SCENES)
def test_labels_agree_on_ground_truth(scenes, name):
    scene, _ = scenes[name]
    labels = classify_transport(scene.transport, resolution_rows=6.075, support_rows=114)
    a = label_agreement(labels, scene.labels, mask=visible_effect_mask(scene))
    for k, minimum in TRUTH_MIN[name].items():
        assert a["recall"][k] >= minimum, (name, k, a["recall"], a["confusion"].tolist())


def test_mirror_ball_page_specular_light_is_below_the_demux_noise(scenes):
    """Documented limitation: page pixels labelled specular hold 2-4 % specular light."""
    scene, result = scenes["mirror_ball"]
    labels = classify_transport(result.transport, resolution_rows=result.attrs["epipolar_resolution_rows"])
    page = (scene.labels == 4) & ~visible_effect_mask(scene)
    assert page.sum() > 1000
    assert np.mean(labels[page] == 1) > 0.8


# ---------------------------------------------------------------- every scene, every size of `figure effects`
# `planeray figure effects --size N` demultiplexes every built-in scene at N x N camera
# pixels of the paper's 720-row projector (a camera row spans 720 / N projector rows).
# Labels against each scene's ground truth at the sizes the command accepts, on a
# subset of the columns (demultiplexing is per pixel: a column sees exactly what it
# would in the whole image; the simulated noise differs only in its draws).
SIZES = [64, 128, pytest.param(256, marks=pytest.mark.slow)]
COLUMNS = {64: 64, 128: 32, 256: 16}
#: Visible ground-truth effects of each scene (keys of EFFECTS); a new scene must say its own.
SCENE_EFFECTS = {
    "corner": {1, 3},
    "diffuse_plane": {1},
    "disco_ball": {1, 4},
    "materials": {1, 2},
    "mirror_ball": {1, 4},
    "skin": {2},
    "wax": {1, 2},
}
# Measured (seeds 0 and 1, these columns): diffuse >= 0.989, subsurface >= 0.944
# (materials at 256: near-wall milk), skin 0.991-1.0, corner diffuse interreflection
# >= 0.938, disco-ball specular >= 0.911, mirror-ball specular >= 0.814 (85-110 pixels).
# Before issue 23: diffuse plane 0.961 at 64 (two camera rows "subsurface"), skin
# subsurface 0.00-0.14, soap tray half "specular interreflection" at 64.
MIN_RECALL = {1: 0.97, 2: 0.9, 3: 0.9, 4: 0.75}


def _columns(scene, cols):
    """The scene seen through camera columns ``cols`` only (same rows, same projector)."""
    T = scene.transport
    keep = np.isin(T.sparse.col, cols)
    sparse = SparseEntries(
        T.sparse.row[keep], np.searchsorted(cols, T.sparse.col[keep]), T.sparse.offset[keep], T.sparse.value[keep]
    )
    return dataclasses.replace(
        scene,
        transport=Transport(np.ascontiguousarray(T.dense[:, cols]), T.offsets_rows, T.geometry, sparse),
        direct=scene.direct[:, cols],
        ambient_albedo=scene.ambient_albedo[:, cols],
        labels=scene.labels[:, cols],
        maps={key: value[:, cols] for key, value in scene.maps.items()},
    )


_DEMUXED = {}


def _demuxed(name, size, *, with_stack=False):
    """(scene, demultiplexing result[, stack]) of a built-in scene at ``size`` x ``size`` (a column subset), cached."""
    if (name, size) not in _DEMUXED:
        cols = np.unique(np.linspace(0, size - 1, COLUMNS[size]).round().astype(int))
        scene = _columns(make_scene(name, (size, size), projector_rows=720, seed=0), cols)
        stack = simulate_stack(scene, paper_sweep(), seed=0)
        _DEMUXED[name, size] = (scene, demultiplex(stack), stack)
    return _DEMUXED[name, size] if with_stack else _DEMUXED[name, size][:2]


def test_every_scene_says_its_effects():
    assert set(SCENE_EFFECTS) == set(list_scenes())


# every scene at one size, then the next size: the scenes of a size share their demultiplexing factorizations
@pytest.mark.parametrize("name", sorted(SCENE_EFFECTS))
@pytest.mark.parametrize("size", SIZES)
def test_labels_agree_with_ground_truth_in_every_scene_at_every_size(name, size):
    scene, result = _demuxed(name, size)
    _, plane = _demuxed("diffuse_plane", size)  # the white target: width of a direct peak
    res = result.attrs["epipolar_resolution_rows"]
    labels = classify_transport(result.transport, resolution_rows=res, direct_reference=plane.transport)
    visible = visible_effect_mask(scene, support_rows=sweep_support_rows(paper_sweep(), 54000.0), resolution_rows=res)
    a = label_agreement(labels, scene.labels, mask=visible)
    assert set(a["counts"]) == SCENE_EFFECTS[name], a["counts"]
    for k, recall in a["recall"].items():
        assert recall >= MIN_RECALL[k], (name, size, k, a["recall"], a["confusion"].tolist())
    # No camera row of diffuse pixels is labelled wrong as a whole: a short tail at the
    # projector's ends once made two rows "subsurface" in every scene at 64.  (A row of
    # an effect can be wrong as a whole where the scene is the same along the row,
    # e.g. the corner's fold, whose interreflected light lies within the cell.)
    diffuse = scene.labels == 1
    rows = diffuse.sum(axis=1) >= 8  # rows mostly of diffuse pixels (not a few at a band's edge)
    wrong = (diffuse & (labels != 1)).sum(axis=1)[rows] / diffuse.sum(axis=1)[rows]
    assert wrong.max(initial=0.0) <= 0.25, (name, size, np.flatnonzero(rows)[wrong > 0.25])


def test_a_reused_reference_gives_what_a_fresh_one_gives_for_every_setting():
    """The widths measured on a white target are kept on it: per settings, never across them."""
    wax = make_scene("wax", (32, 32), projector_rows=360, seed=0).transport
    kept = dataclasses.replace(wax)  # as its own white target: the widths of its diffuse pixels
    settings = [{}, {"broadening": 1.05, "core_broadening": 1.02}, {"smooth_bins": 3}, {}]
    labels = []
    for kw in settings:
        fresh = dataclasses.replace(kept)  # the same arrays, nothing remembered
        expected = classify_transport(wax, support_rows=114, direct_reference=fresh, **kw)
        labels.append(classify_transport(wax, support_rows=114, direct_reference=kept, **kw))
        np.testing.assert_array_equal(labels[-1], expected)
    assert len(kept.__dict__["_direct_widths"]) == 3
    assert not np.array_equal(labels[0], labels[1])  # the settings matter here


def test_a_direct_reference_must_match_the_geometry():
    _, result = _demuxed("diffuse_plane", 64)
    other = make_scene("diffuse_plane", (32, 32), projector_rows=720, seed=0).transport
    with pytest.raises(InputError, match="direct_reference"):
        classify_transport(result.transport, resolution_rows=6.075, direct_reference=other)


def test_without_a_reference_an_all_skin_image_has_no_direct_width():
    """Documented: the image's own "diffuse" pixels are the reference by default; skin has none."""
    scene, result = _demuxed("skin", 64)
    res = result.attrs["epipolar_resolution_rows"]
    alone = classify_transport(result.transport, resolution_rows=res)
    _, plane = _demuxed("diffuse_plane", 64)
    with_plane = classify_transport(result.transport, resolution_rows=res, direct_reference=plane.transport)
    assert np.mean(alone == 2) < 0.1 < 0.95 < np.mean(with_plane == 2)


def test_cli_labels_skin_with_a_white_reference(tmp_path):
    from typer.testing import CliRunner

    from planeray.cli import app
    from planeray.io import write_stack, write_transport

    _, skin, stack = _demuxed("skin", 64, with_stack=True)
    _, plane = _demuxed("diffuse_plane", 64)
    write_stack(stack, tmp_path / "skin.zarr")
    write_transport(skin.transport, tmp_path / "T.zarr", attrs=skin.attrs)
    write_transport(plane.transport, tmp_path / "white.zarr", attrs=plane.attrs)
    small = demultiplex(simulate_stack(make_scene("diffuse_plane", (32, 32), projector_rows=720), paper_sweep()))
    write_transport(small.transport, tmp_path / "small.zarr", attrs=small.attrs)

    def run(*extra):
        args = ["profiles", tmp_path / "skin.zarr", "--out", tmp_path / "p.png", "--transport", tmp_path / "T.zarr"]
        extra = (*extra, "--overwrite")  # each run replaces the label map the previous one wrote
        return CliRunner().invoke(app, [str(a) for a in [*args, "--classify", tmp_path / "labels.png", *extra]])

    res = run("--direct-reference", tmp_path / "white.zarr")
    assert res.exit_code == 0, res.output
    share = float(res.output.split("subsurface ")[1].split(" %")[0])
    assert share > 95.0, res.output
    res = run()  # no reference: skin's own pixels are the "direct" width
    assert res.exit_code == 0 and "diffuse " in res.output
    res = run("--direct-reference", tmp_path / "small.zarr")
    assert res.exit_code == 1 and len(res.output.strip().splitlines()) == 1, res.output
    assert "--direct-reference" in res.output and "32 camera rows" in res.output


def _no_constant(name):
    raise AssertionError(f"not strict JSON: {name}")


def test_effects_figure_writes_strict_json(tmp_path, monkeypatch):
    import planeray.experiments.paper as paper

    # Two scenes keep it short: the reference (diffuse plane) and skin.
    monkeypatch.setattr(paper, "list_scenes", lambda: {"diffuse_plane": "", "skin": ""})
    numbers = paper.effects(tmp_path, size=64, seed=0)
    saved = json.loads((tmp_path / "effects.json").read_text(), parse_constant=_no_constant)
    assert saved.pop("planeray_mark").startswith("planeray:record:")  # so --overwrite may replace it
    assert saved == numbers and set(saved) == {"diffuse_plane", "skin"}
    assert saved["skin"]["recall_visible"]["subsurface"] > 0.95
    assert saved["skin"]["direct_reference"] == "diffuse_plane"
    # A number with nothing to score is null, never NaN.
    paper._write_numbers(tmp_path, "x", {"overall_visible": float("nan"), "n": np.float32(2.5)})
    assert json.loads((tmp_path / "x.json").read_text(), parse_constant=_no_constant) == {
        "planeray_mark": paper.mark_text("record"),
        "overall_visible": None,
        "n": 2.5,
    }
    with pytest.raises(InputError, match="size"):
        paper.effects(tmp_path, size=32)
