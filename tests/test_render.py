"""planeray.render: a Mitsuba 3 scene -> plane-to-ray transport in one pass, checked against independent references.

* per-row renders with Mitsuba's own ``path`` / ``volpath`` (a one-row projector bitmap,
  nearest filtering, box film filter): agreement within Monte Carlo noise, block by block;
* the sum over rows against one full-projector render;
* the caustic pass against Mitsuba's particle tracer ``ptracer``;
* analytic scenes: a white plane facing the rig (exactly 1, direct light only at u ~ 0),
  a wall above a floor (one-sided interreflection: u > 0 on the wall, u < 0 on the floor);
* the whole pipeline: sweep -> demultiplex -> sharpened epipolar image = the band of the rendered T;
* the driver (resuming, fingerprints, sparse long-range light), the scalar fallback, the CLI.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from planeray.render import example_scenes, labels_from_classes, render_to_store, render_transport, render_work
from planeray.render._mitsuba import choose_variant, find_libllvm
from planeray.render.rig import Rig

LLVM = choose_variant().startswith("llvm")
needs_llvm = pytest.mark.skipif(not LLVM, reason="the one-pass tally needs Mitsuba's llvm variant (libllvm19)")

SENSOR = """
    <sensor type="perspective">
        <float name="fov" value="{fov}"/>
        <transform name="to_world"><lookat origin="{origin}" target="{target}" up="{up}"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
    </sensor>"""
PAGE = """
    <shape type="rectangle" id="page">
        <transform name="to_world"><scale x="{half}" y="{half}"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="{albedo}"/></bsdf>
    </shape>"""
MIRROR_BALL = """
    <shape type="sphere" id="ball"><point name="center" x="0" y="0" z="1"/><float name="radius" value="1"/>
        <bsdf type="conductor"/></shape>"""
MEDIUM_BALL = """
    <shape type="sphere" id="ball"><point name="center" x="0" y="0" z="1.2"/><float name="radius" value="1.2"/>
        <bsdf type="null"/>
        <medium type="homogeneous" name="interior"><float name="sigma_t" value="1.5"/><rgb name="albedo" value="0.9"/>
            <phase type="hg"><float name="g" value="0.3"/></phase></medium></shape>"""
# a mirror beside the page, out of the camera's view, throwing projector light on the page
SIDE_MIRROR = """
    <shape type="rectangle" id="mirror">
        <transform name="to_world"><scale value="1.5"/><rotate y="1" angle="60"/><translate x="-2.5" z="2"/></transform>
        <bsdf type="conductor"/></shape>"""
WALL = """
    <shape type="rectangle" id="wall">
        <transform name="to_world"><scale x="6" y="3"/><rotate x="1" angle="90"/><translate y="2" z="3"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.8"/></bsdf>
    </shape>"""


def scene_xml(
    tmp_path, *parts, name="scene.xml", fov=40, origin="0, -8, 6", target="0, 0, 1", baseline=1.0, up="0, 0, 1"
):
    body = "".join(parts)
    text = (
        f'<scene version="3.0.0">\n    <default name="planeray_baseline" value="{baseline}"/>'
        + SENSOR.format(fov=fov, origin=origin, target=target, up=up)
        + body
        + "\n</scene>\n"
    )
    path = tmp_path / name
    path.write_text(text)
    return path


def _parts(path, rows, shape, rgb=False):
    import mitsuba as mi

    from planeray.render.scene_file import load_scene_file

    choose_variant(rgb=rgb)
    mi.set_log_level(mi.LogLevel.Error)
    loaded = load_scene_file(path)
    rig = Rig.from_sensor(loaded.sensor, baseline=float(loaded.defaults["planeray_baseline"]), projector_rows=rows)
    sensor = mi.load_dict(rig.sensor_dict(shape, rgb=rgb))
    projector = mi.load_dict(rig.projector_dict())
    return loaded, rig, sensor, projector


def block_z(a1, a2, b1, b2, block=4):
    """z-scores of block sums of two estimates, each given as two independent halves (noise from the halves)."""
    return block_z_runs([a1, a2], [b1, b2], block=block)


def block_z_runs(runs_a, runs_b, block=4):
    """z-scores of block sums of two estimates, each the mean of independent runs (noise from their spread per pixel)."""

    def blocks(x):
        h, w = x.shape
        return x[: h // block * block, : w // block * block].reshape(h // block, block, w // block, block).sum((1, 3))

    A, B = np.stack(runs_a), np.stack(runs_b)
    a, b = blocks(A.mean(0)), blocks(B.mean(0))
    # pixels are independent: a block's variance is the sum of its pixels' (pooled over the block's pixels)
    var = blocks(A.var(0, ddof=1) / len(A)) + blocks(B.var(0, ddof=1) / len(B))
    scale = max(np.abs(a).max(), np.abs(b).max())
    lit = (np.abs(a) + np.abs(b) > 1e-6 * scale) & (var > 0)
    return (a - b)[lit] / np.sqrt(var[lit])


def _tally(path, rows, shape, spp, seed, rgb=False):
    from planeray.render.integrator import tally_transport

    loaded, rig, sensor, projector = _parts(path, rows, shape, rgb=rgb)
    r = tally_transport(loaded.scene, sensor, projector, shape=shape, projector_rows=rows, spp=spp, seed=seed)
    return (r.transport / spp if rgb else r.transport[0] / spp), r


# ------------------------------------------------------------------ against Mitsuba, row by row
@needs_llvm
@pytest.mark.parametrize("kind", ["surfaces", "medium", "medium_thin_glass"])
def test_tally_matches_per_row_renders(tmp_path, kind):
    from planeray.render.reference import render_rows

    extra = {
        "surfaces": MIRROR_BALL,
        "medium": MEDIUM_BALL,
        "medium_thin_glass": MEDIUM_BALL.replace('<bsdf type="null"/>', '<bsdf type="thindielectric"/>'),
    }[kind]
    path = scene_xml(tmp_path, PAGE.format(half=6, albedo=0.6), extra)
    shape, P, spp = (16, 16), 16, 512
    T1, _ = _tally(path, P, shape, spp, seed=1)
    T2, _ = _tally(path, P, shape, spp, seed=2)
    loaded, rig, _, _ = _parts(path, P, shape)
    rows = [4, 8, 11]
    R1 = render_rows(loaded, rig, shape, rows, spp=spp, seed=10)[..., 0]
    R2 = render_rows(loaded, rig, shape, rows, spp=spp, seed=50)[..., 0]
    zs = []
    for i, v in enumerate(rows):
        assert R1[i].sum() > 0.002 * T1.sum()  # the row lights something
        zs.append(block_z(T1[v], T2[v], R1[i], R2[i]))
    z = np.concatenate(zs)
    assert z.size >= 20
    assert np.abs(z).max() < 5.0, np.abs(z).max()
    assert np.mean(z**2) < 2.5, np.mean(z**2)
    # the comparison has power: the neighbouring row is far off
    wrong = block_z(T1[rows[1] + 1], T2[rows[1] + 1], R1[1], R2[1])
    assert np.abs(wrong).max() > 8


@pytest.mark.slow
@needs_llvm
def test_rgb_tally_with_spectral_extinction_matches_per_row_volpath(tmp_path):
    """Colour: a medium whose extinction differs per channel (the tally's spectral MIS) against volpath."""
    from planeray.render.reference import render_rows

    medium = MEDIUM_BALL.replace('<float name="sigma_t" value="1.5"/><rgb name="albedo" value="0.9"/>', "")
    medium = medium.replace(
        '<medium type="homogeneous" name="interior">',
        '<medium type="homogeneous" name="interior"><rgb name="sigma_t" value="1.0, 0.5, 0.2"/><float name="scale" value="2"/>'
        '<rgb name="albedo" value="0.95, 0.7, 0.4"/>',
    )
    path = scene_xml(tmp_path, PAGE.format(half=6, albedo="0.6, 0.5, 0.4"), medium)
    shape, P, spp, runs = (16, 16), 16, 512, 8
    rows = [6, 9]
    try:
        T = [_tally(path, P, shape, spp, seed=s, rgb=True)[0] for s in range(runs)]
        loaded, rig, _, _ = _parts(path, P, shape, rgb=True)
        R = [render_rows(loaded, rig, shape, rows, spp=spp, seed=100 + s, rgb=True) for s in range(runs)]
    finally:
        choose_variant()
    # the medium's paths are heavy-tailed: the noise comes from the spread of eight runs each
    z = np.concatenate(
        [block_z_runs([t[c, v] for t in T], [r[i, ..., c] for r in R]) for i, v in enumerate(rows) for c in range(3)]
    )
    assert z.size >= 40
    assert np.abs(z).max() < 5.0 and np.mean(z**2) < 2.5, (np.abs(z).max(), np.mean(z**2))
    T1 = T[0]
    # the channels differ (the test sees colour): red scatters most inside the ball
    assert T1[0].sum() > 1.2 * T1[2].sum()


@needs_llvm
def test_sum_over_rows_equals_a_full_projector_render(tmp_path):
    from planeray.render.reference import render_pattern

    path = scene_xml(tmp_path, PAGE.format(half=6, albedo=0.6), MIRROR_BALL, WALL)
    shape, P, spp = (16, 16), 24, 256
    T1, _ = _tally(path, P, shape, spp, seed=3)
    T2, _ = _tally(path, P, shape, spp, seed=4)
    loaded, rig, _, _ = _parts(path, P, shape)
    F1 = render_pattern(loaded, rig, shape, np.ones(P), spp=spp, seed=5)[..., 0]
    F2 = render_pattern(loaded, rig, shape, np.ones(P), spp=spp, seed=6)[..., 0]
    z = block_z(T1.sum(0), T2.sum(0), F1, F2)
    assert np.abs(z).max() < 5.0 and np.mean(z**2) < 2.5, (np.abs(z).max(), np.mean(z**2))
    np.testing.assert_allclose(T1.sum() + T2.sum(), F1.sum() + F2.sum(), rtol=0.02)


@needs_llvm
def test_caustic_pass_adds_what_the_particle_tracer_sees(tmp_path):
    """On page pixels, ptracer renders every path; camera tally + caustic pass must add up to it."""
    import mitsuba as mi

    from planeray.render.caustics import trace_caustics

    path = scene_xml(
        tmp_path,
        PAGE.format(half=6, albedo=0.6),
        SIDE_MIRROR,
        fov=50,
        origin="0, 0, 10",
        target="0, 0, 0",
        up="0, 1, 0",
    )
    shape, P, spp = (16, 16), 16, 1024
    loaded, rig, sensor, projector = _parts(path, P, shape)
    n = shape[0] * shape[1] * spp
    est = []
    for seed in (1, 2):
        T, r = _tally(path, P, shape, spp, seed)
        page = r.albedo / spp > 0.3  # pixels that see the page, not the mirror (ptracer cannot see through it)
        c = trace_caustics(loaded.scene, sensor, projector, shape=shape, projector_rows=P, n_paths=n, seed=seed)
        est.append((T.sum(0), c.transport[0].sum(0)))
    scene = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "ptracer"},
            "sensor": rig.sensor_dict(shape, spp=spp),
            "projector": rig.projector_dict(),
            **{f"s{i}": s for i, s in enumerate(loaded.shapes)},
        }
    )
    ref = [np.asarray(mi.render(scene, spp=spp, seed=s), dtype=np.float64)[..., 0] * page for s in (7, 8)]
    est = [(a * page, b * page) for a, b in est]
    assert page.mean() > 0.6
    caustic = est[0][1] + est[1][1]
    assert caustic.sum() > 0.01 * (est[0][0] + est[1][0]).sum()  # a real caustic, not noise
    z = block_z(est[0][0] + est[0][1], est[1][0] + est[1][1], ref[0], ref[1])
    assert np.abs(z).max() < 5.0 and np.mean(z**2) < 2.5, (np.abs(z).max(), np.mean(z**2))
    # without the caustic pass the tally misses light the particle tracer sees
    z_missing = block_z(est[0][0], est[1][0], ref[0], ref[1])
    assert np.abs(z_missing).max() > 6


# ------------------------------------------------------------------ analytic scenes
@needs_llvm
def test_white_plane_facing_the_rig_is_one_and_direct_only(tmp_path):
    """A Lambertian plane perpendicular to the projector axis has uniform irradiance: T sums to its albedo."""
    path = scene_xml(
        tmp_path, PAGE.format(half=50, albedo=0.7), fov=30, origin="0, 0, 10", target="0, 0, 0", up="0, 1, 0"
    )
    r = render_transport(path, shape=(16, 16), projector_rows=64, spp=16, band_rows=16)
    full = r.transport.full_image()
    np.testing.assert_allclose(full, 0.7, rtol=1e-4)
    u = r.transport.offsets_rows
    rows_per = 64 / 16
    near = np.abs(u) <= rows_per / 2 + 1
    assert r.transport.dense[:, :, near].sum() / r.transport.dense.sum() > 0.999
    assert len(r.transport.sparse) == 0
    assert set(np.unique(r.labels)) == {1}
    np.testing.assert_allclose(r.direct, full, rtol=1e-5)


@needs_llvm
def test_wall_above_a_floor_interreflects_one_sided(tmp_path):
    """Like the built-in corner: a wall receives interreflection from the floor (lower rows, u > 0), and back.

    One interreflection (``max_depth = 3``) is exactly one-sided; more bounces (wall -> floor -> wall) are not.
    """
    path = scene_xml(
        tmp_path, PAGE.format(half=6, albedo=0.8), WALL, fov=40, origin="0, -9, 4", target="0, 0, 1.5", baseline=0.5
    )
    r = render_transport(path, shape=(24, 24), projector_rows=96, spp=128, band_rows=96, max_depth=3)
    T = r.transport
    u = T.offsets_rows
    far = np.abs(u) > 3  # outside the direct footprint (4 projector rows per camera row)
    pos = T.dense[:, :, far & (u > 0)].sum(axis=2)
    neg = T.dense[:, :, far & (u < 0)].sum(axis=2)
    epi = T.epipolar_image()
    horizon = int(np.argmax(np.abs(np.diff(epi[:, 12]))))  # the edge between wall and floor
    wall = slice(2, horizon - 1)
    floor = slice(horizon + 2, 22)
    assert pos[wall].sum() > 0.05 * T.dense[wall].sum() and neg[floor].sum() > 0.05 * T.dense[floor].sum()
    assert pos[wall].sum() > 1000 * neg[wall].sum()
    assert neg[floor].sum() > 1000 * pos[floor].sum()
    assert (r.labels[wall] == 3).mean() > 0.5


# ------------------------------------------------------------------ driver
@needs_llvm
def test_resume_after_a_kill_equals_one_run_and_refuses_other_inputs(tmp_path, monkeypatch):
    from planeray.errors import InputError
    from planeray.io import read_transport
    from planeray.resumable import partial_path

    path = scene_xml(tmp_path, PAGE.format(half=6, albedo=0.6), MIRROR_BALL)
    kw = dict(shape=(16, 16), projector_rows=32, spp=8, batch_spp=2, band_rows=8, seed=3)
    _, whole = render_to_store(path, tmp_path / "whole.zarr", **kw)

    class Killed(Exception):
        pass

    done = []

    def die_after_two(n):
        done.append(n)
        if len(done) == 2:
            raise Killed

    out = tmp_path / "resumed.zarr"

    def die_in_the_first_batch(*args, **kwargs):
        raise Killed

    with monkeypatch.context() as m:
        m.setattr("planeray.render.render._run_unit", die_in_the_first_batch)
        with pytest.raises(Killed):
            render_to_store(path, out, **kw)
    assert not partial_path(out).exists()  # nothing finished: nothing left behind
    with pytest.raises(Killed):
        render_to_store(path, out, progress=die_after_two, **kw)
    assert partial_path(out).exists() and not out.exists()
    with pytest.raises(InputError, match="restart"):
        render_to_store(path, out, **{**kw, "seed": 4})
    seen = []
    _, resumed = render_to_store(path, out, progress=seen.append, **kw)
    assert seen[0] == 2 and sum(seen) == 4  # the two finished batches were not redone
    assert not partial_path(out).exists()
    T, attrs = read_transport(out)
    np.testing.assert_allclose(T.dense, whole.transport.dense, rtol=1e-5, atol=1e-7)
    assert attrs["format"] == "planeray-transport" and attrs["spp"] == 8 and attrs["variant"].startswith("llvm")
    # a changed scene file is another input
    path.write_text(path.read_text().replace('value="0.6"', 'value="0.5"'))
    with pytest.raises(InputError):
        render_to_store(path, tmp_path / "whole.zarr", **kw)


@needs_llvm
def test_long_range_light_is_sparse_or_dropped_with_a_warning(tmp_path):
    from planeray.render import RenderWarning

    path = scene_xml(tmp_path, PAGE.format(half=6, albedo=0.8), WALL, origin="0, -9, 4", target="0, 0, 1.5")
    kw = dict(shape=(16, 16), projector_rows=64, spp=16, band_rows=4, seed=0)
    full = render_transport(path, **kw)
    assert len(full.transport.sparse) > 100 and full.dropped_fraction == 0
    # dense + sparse hold all of it: the full images agree
    with pytest.warns(RenderWarning, match=r"dropped [0-9.e-]+ % of the light"):
        cut = render_transport(path, max_sparse=10, **kw)
    assert 0 < cut.dropped_fraction < 1
    lost = 1 - cut.transport.full_image().sum() / full.transport.full_image().sum()
    np.testing.assert_allclose(lost, cut.dropped_fraction, rtol=1e-3)


@needs_llvm
def test_rgb_render_stores_colour_band_and_luminance(tmp_path):
    from planeray.io import read_transport, read_transport_maps
    from planeray.render.render import LUMINANCE

    path = scene_xml(
        tmp_path, PAGE.format(half=50, albedo="0.8, 0.4, 0.2"), fov=30, origin="0, 0, 10", target="0,0,0", up="0, 1, 0"
    )
    out, r = render_to_store(path, tmp_path / "rgb.zarr", shape=(8, 8), projector_rows=16, spp=4, band_rows=4, rgb=True)
    assert r.attrs["variant"] == "llvm_ad_rgb"
    full_rgb = r.rgb.sum(axis=2)
    np.testing.assert_allclose(full_rgb, np.broadcast_to([0.8, 0.4, 0.2], full_rgb.shape), rtol=1e-4)
    T, _ = read_transport(out)
    np.testing.assert_allclose(T.dense, r.rgb @ LUMINANCE, rtol=1e-5)
    maps = read_transport_maps(out)
    assert {"direct", "ambient_albedo", "labels", "light_direct"} <= set(maps)


def test_scalar_fallback_renders_row_by_row(tmp_path):
    """The scalar variants cannot scatter in one pass: planeray renders each row with Mitsuba's path tracer."""
    path = scene_xml(
        tmp_path, PAGE.format(half=50, albedo=0.7), fov=30, origin="0, 0, 10", target="0, 0, 0", up="0, 1, 0"
    )
    try:
        r = render_transport(path, shape=(8, 8), projector_rows=16, spp=4, band_rows=4, variant="scalar")
    finally:
        choose_variant()  # back to the default variant for the other tests
    assert r.attrs["variant"] == "scalar_rgb"
    np.testing.assert_allclose(r.transport.full_image(), 0.7, rtol=1e-3)
    from planeray.errors import InputError
    from planeray.render import RenderWarning

    try:
        with pytest.raises(InputError, match="caustic pass needs an llvm variant"):
            render_transport(path, shape=(8, 8), projector_rows=16, spp=1, caustics=True, variant="scalar")
        # a file that asks for caustics renders without them, saying so
        path.write_text(path.read_text().replace("<sensor", '<default name="planeray_caustics" value="true"/><sensor'))
        with pytest.warns(RenderWarning, match="rendered without it"):
            r = render_transport(path, shape=(8, 8), projector_rows=16, spp=1, variant="scalar")
        assert r.attrs["caustics"] is False
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # counting the work renders nothing: nothing to warn of
            assert render_work(path, shape=(8, 8), projector_rows=16, spp=1, variant="scalar") >= 1
        # the command says so once, as a warning line after the bar (counting the work loads the file too)
        from typer.testing import CliRunner

        from planeray.cli import app

        args = ["render", str(path), "--size", "8", "8", "--rows", "16", "--spp", "1", "--variant", "scalar"]
        res = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "s.zarr")])
        assert res.exit_code == 0, res.output
        assert res.output.count("rendered without it") == 1 and "warning: " in res.output, res.output
        assert "RenderWarning" not in res.output
    finally:
        choose_variant()
    u = r.transport.offsets_rows
    assert r.transport.dense[:, :, np.abs(u) <= 2].sum() / r.transport.dense.sum() > 0.999


def test_variant_and_llvm_discovery():
    lib = find_libllvm()
    assert lib is None or "libLLVM" in lib
    assert choose_variant(prefer="scalar") == "scalar_rgb"
    with pytest.raises(ValueError, match="prefer"):
        choose_variant(prefer="cuda")
    choose_variant()


def test_rig_is_rectified_by_construction():
    rig = Rig.look_at([0, -5, 2], [0, 0, 0], [0, 0, 1], vfov_deg=40, baseline=0.3, projector_rows=720)
    cam, proj = rig.camera_to_world, rig.projector_to_world
    np.testing.assert_allclose(proj[:3, :3], cam[:3, :3])  # same orientation
    shift = proj[:3, 3] - cam[:3, 3]
    np.testing.assert_allclose(np.linalg.norm(shift), 0.3)
    np.testing.assert_allclose(shift @ cam[:3, 1], 0, atol=1e-12)  # baseline along the rows
    np.testing.assert_allclose(shift @ cam[:3, 2], 0, atol=1e-12)
    assert rig.projector_columns == 1280


def test_labels_follow_the_dominant_path_class():
    c = np.zeros((4, 2, 2))
    c[0] = [[1, 1], [1, 0]]
    c[1, 0, 1] = 0.5
    c[3, 1, 0] = 0.2
    assert labels_from_classes(c).tolist() == [[1, 2], [4, 0]]


def test_bad_scene_files_give_one_line(tmp_path):
    from planeray.errors import InputError

    with pytest.raises(InputError, match="no such scene file"):
        render_transport(tmp_path / "missing.xml")
    bad = tmp_path / "bad.xml"
    bad.write_text("<scene version='3.0.0'><shape type='nonsense'/></scene>")
    with pytest.raises(InputError, match="bad.xml: Mitsuba cannot load it"):
        render_transport(bad)
    no_sensor = tmp_path / "no_sensor.xml"
    no_sensor.write_text("<scene version='3.0.0'><shape type='sphere'/></scene>")
    with pytest.raises(InputError, match="no perspective sensor"):
        render_transport(no_sensor)
    hetero = tmp_path / "hetero.xml"
    hetero.write_text(
        "<scene version='3.0.0'><shape type='sphere'><bsdf type='null'/><medium type='heterogeneous' name='interior'>"
        "<volume type='constvolume' name='sigma_t'><float name='value' value='1'/></volume></medium></shape></scene>"
    )
    with pytest.raises(InputError, match="heterogeneous"):
        render_transport(hetero)
    # a medium behind a refracting boundary: the point projector's light cannot enter it -- refused by name
    glass = scene_xml(
        tmp_path, PAGE.format(half=6, albedo=0.6), MEDIUM_BALL.replace("null", "dielectric"), name="g.xml"
    )
    with pytest.raises(InputError, match=r"g\.xml: shape 'ball' bounds a medium through a .*Dielectric boundary") as e:
        render_transport(glass, shape=(8, 8), projector_rows=8, spp=1)
    assert "\n" not in str(e.value)
    rough = MEDIUM_BALL.replace('<bsdf type="null"/>', '<bsdf type="roughdielectric"/>')
    with pytest.raises(InputError, match="refracts"):
        render_transport(scene_xml(tmp_path, rough, name="r.xml"), shape=(8, 8), projector_rows=8, spp=1)


# ------------------------------------------------------------------ scene plugin, pipeline, CLI
@needs_llvm
def test_example_scenes_render_with_their_effects():
    assert set(example_scenes()) == {"mirror_ball", "disco_ball", "wax_candle", "room_corner"}
    expected = {"mirror_ball": 4, "wax_candle": 2, "room_corner": 3}
    for name, label in expected.items():
        r = render_transport(example_scenes()[name], shape=(24, 24), projector_rows=96, spp=8, band_rows=32)
        assert (r.labels == label).sum() >= 10, (name, np.bincount(r.labels.ravel()))
        assert (r.labels == 1).sum() >= 10


@pytest.mark.slow
@needs_llvm
def test_pipeline_sharpened_epipolar_equals_the_rendered_band(tmp_path):
    """mitsuba:FILE.xml -> paper sweep on the simulated Episcan -> demultiplex -> sharpened epipolar image.

    Without ambient light (which the demultiplexer spreads over all offsets, for any scene) the
    median error is at the camera-noise level (the spread of two noise seeds): 1.4x it here.
    """
    from planeray.acquire import simulate_stack
    from planeray.camera import CameraModel
    from planeray.demux import demultiplex
    from planeray.scenes import make_scene
    from planeray.synthesis import sharpened_epipolar
    from planeray.timing import paper_sweep

    path = scene_xml(tmp_path, PAGE.format(half=6, albedo=0.7), MEDIUM_BALL)
    scene = make_scene(f"mitsuba:{path}", (24, 24), projector_rows=135, seed=0, spp=32)
    assert scene.params["name"] == f"mitsuba:{path}" and scene.params["variant"].startswith("llvm")
    est = []
    for seed in (0, 1):
        stack = simulate_stack(scene, paper_sweep(), seed=seed, camera=CameraModel(ambient_e_per_us=0.0))
        result = demultiplex(stack)
        width = 4 * result.attrs["epipolar_resolution_rows"]
        est.append(sharpened_epipolar(result.transport, width_rows=width) / stack.metadata["signal_scale"])
    truth = sharpened_epipolar(scene.transport, width_rows=width)
    lit = truth > 0.1 * truth.max()
    error = np.median(np.abs(est[0] - truth)[lit])
    noise = np.median(np.abs(est[0] - est[1])[lit]) / np.sqrt(2)
    assert error < 2.0 * noise, (error, noise)
    assert error < 0.01 * np.median(truth[lit])


@needs_llvm
def test_cli_render(tmp_path):
    from typer.testing import CliRunner

    from planeray.cli import app
    from planeray.io import read_transport

    runner = CliRunner()
    out = tmp_path / "T.zarr"
    res = runner.invoke(
        app, ["render", "room_corner", "--out", str(out), "--rows", "48", "--size", "12", "12", "--spp", "4"]
    )
    assert res.exit_code == 0, res.output
    T, attrs = read_transport(out)
    assert T.shape == (12, 12) and attrs["projector_rows"] == 48 and attrs["method"] == "mitsuba_render"
    # a file without a sensor: planeray places the camera (rectified rig from a baseline and a field of view)
    bare = tmp_path / "bare.xml"
    bare.write_text(
        scene_xml(tmp_path, PAGE.format(half=50, albedo=0.7)).read_text().split("<sensor")[0]
        + PAGE.format(half=50, albedo=0.7)
        + "</scene>"
    )
    placed = ["--look-from", "0", "0", "10", "--look-at", "0", "0", "0", "--up", "0", "1", "0", "--vfov", "30"]
    res = runner.invoke(
        app, ["render", str(bare), "--out", str(tmp_path / "P.zarr"), "--rows", "16", "--size", "8", "8", *placed]
    )
    assert res.exit_code == 0, res.output
    T, attrs = read_transport(tmp_path / "P.zarr")
    np.testing.assert_allclose(T.full_image(), 0.7, rtol=1e-4)  # the white-plane check, camera placed by planeray
    assert attrs["rig"]["vfov_deg"] == 30
    res = runner.invoke(app, ["render", str(bare), "--out", str(tmp_path / "Q.zarr")])
    assert res.exit_code == 1 and "no perspective sensor" in res.output
    res = runner.invoke(app, ["render", str(tmp_path / "none.xml"), "--out", str(tmp_path / "x.zarr")])
    assert res.exit_code == 1 and "no such scene file" in res.output and "Traceback" not in res.output


@needs_llvm
def test_cli_render_projector_options_are_recorded_and_bad_values_named_as_typed(tmp_path):
    """--projector-columns / --projector-aspect / --projector-vfov set the rig; the store records it and where
    each value came from; messages name the options as typed (--rows, --size), the file for a wrong sensor."""
    from typer.testing import CliRunner

    from planeray.cli import app
    from planeray.io import read_transport

    runner = CliRunner()
    path = scene_xml(tmp_path, PAGE.format(half=6, albedo=0.6), WALL)
    base = ["render", str(path), "--rows", "30", "--size", "10", "10", "--spp", "2"]
    res = runner.invoke(app, [*base, "--out", str(tmp_path / "a.zarr"), "--projector-columns", "50"])
    assert res.exit_code == 0, res.output
    _, attrs = read_transport(tmp_path / "a.zarr")
    rig = attrs["rig"]
    assert rig["projector_columns"] == 50 and rig["projector_aspect"] == pytest.approx(5 / 3)
    assert attrs["rig_sources"]["projector_aspect"] == "argument"
    assert attrs["rig_sources"]["baseline"] == "scene file default planeray_baseline"
    assert rig["vfov_deg"] == pytest.approx(40 * 16 / 16)  # the file's square sensor: vertical fov = its fov
    res = runner.invoke(app, [*base, "--out", str(tmp_path / "b.zarr"), "--projector-vfov", "25"])
    assert res.exit_code == 0, res.output
    _, attrs = read_transport(tmp_path / "b.zarr")
    assert attrs["rig"]["vfov_deg"] == 25 and attrs["rig_sources"]["vfov_deg"] == "argument (projector)"
    assert attrs["rig_sources"]["projector_aspect"].startswith("planeray default: 16:9")
    bad = [
        ([*base, "--projector-columns", "50", "--projector-aspect", "1.5"], "columns or its aspect, not both"),
        (["render", str(path), "--rows", "0"], "--rows must be an integer >= 1 and <= 8192, got 0"),
        (
            ["render", str(path), "--size", "0", "4"],
            "--size must be two integers H W, each >= 1 and <= 2048, got (0, 4)",
        ),
        ([*base, "--projector-vfov", "200"], "--projector-vfov must be in (0, 180) degrees"),
        ([*base, "--variant", "cuda"], "--variant must be 'llvm' or 'scalar'"),
    ]
    for args, message in bad:
        res = runner.invoke(app, [*args, "--out", str(tmp_path / "x.zarr")])
        assert res.exit_code == 1 and message in res.output, (args, res.output)
        assert "projector_rows" not in res.output and "shape[" not in res.output
    ortho = tmp_path / "ortho.xml"
    ortho.write_text(
        path.read_text()
        .replace('type="perspective"', 'type="orthographic"')
        .replace('<float name="fov" value="40"/>', "")
    )
    res = runner.invoke(app, ["render", str(ortho), "--out", str(tmp_path / "o.zarr")])
    assert res.exit_code == 1 and f"{ortho}: the scene's first sensor is a" in res.output
    assert "--look-from" in res.output and "perspective" in res.output


@needs_llvm
def test_viewer_and_scene_registry_take_mitsuba_scenes():
    from planeray.scenes import is_scene_name, list_scenes
    from planeray.viewer.session import ViewSettings, open_source

    assert "mitsuba:FILE.xml" in list_scenes(parametric=True) and "mitsuba" not in list_scenes()
    assert is_scene_name("mitsuba:room_corner") and not is_scene_name("mitsuba") and not is_scene_name("mitsuba:")
    src = open_source("mitsuba:room_corner", size=16, projector_rows=64)
    assert src.kind == "scene" and src.shape == (16, 16)
    image, _ = src.render(ViewSettings(delay_us=0.0, exposure_us=600.0))
    assert image.shape == (16, 16) and image.max() > 0


@pytest.mark.slow
@needs_llvm
def test_render_examples_writes_stores_figures_and_numbers(tmp_path):
    import json

    from planeray.experiments.render import render_examples_work, run_render_examples
    from planeray.io import read_transport_maps

    ticks = []
    kw = dict(size=16, projector_rows=64, spp=4, names=["room_corner", "disco_ball"])
    summary = run_render_examples(tmp_path, progress=ticks.append, **kw)
    assert sum(ticks) == render_examples_work(**kw)
    assert summary["disco_ball"]["caustics"] is True  # the file's planeray_caustics default
    assert summary["room_corner"]["light_fraction"]["diffuse_interreflection"] > 0.1
    saved = json.loads((tmp_path / "render_examples.json").read_text())
    assert saved["room_corner"]["labels"] == summary["room_corner"]["labels"]
    assert (tmp_path / "disco_ball.png").stat().st_size > 1000
    assert read_transport_maps(tmp_path / "room_corner.zarr")["labels"].shape == (16, 16)
    with pytest.raises(Exception, match="already exists"):
        run_render_examples(tmp_path, **kw)


# ------------------------------------------------------------------ the one binning rule, against per-row renders
def _window_from_rows(per_row, P, H, lo, hi):
    """Exact integral of projector coordinates p_t + [lo, hi) over a per-row rendering: projector row v is lit
    evenly over [v - 1/2, v + 1/2), so it counts with the length of its overlap with the window."""
    out = np.zeros(per_row.shape[1:])
    for t in range(H):
        p_t = (t + 0.5) * P / H - 0.5
        for v in range(P):
            w = max(0.0, min(v + 0.5, p_t + hi) - max(v - 0.5, p_t + lo))
            out[t] += w * per_row[v, t]
    return out


@needs_llvm
@pytest.mark.parametrize(("P", "windows"), [(24, (1.0, 3.0)), (90, (0.5, 1.0, 1.5, 3.0))])
def test_rendered_windows_equal_the_exact_integral_over_per_row_renders(tmp_path, P, windows):
    """A wall above a floor with P / H = 1.5 (96/64) and 5.625 (720/128): sharpened epipolar windows of the
    rendered transport against the same windows integrated exactly over Mitsuba's own per-row renders.

    Windows whose edges are bin edges (1 and 3 rows) are exact at every P / H.  Windows with edges inside
    a bin (0.5 and 1.5 rows) are exact where neighbouring projector rows carry the same light -- at 720/128
    the rows they touch lie inside every camera row's 5.6-row direct footprint; at 96/64 the footprint is
    1.5 rows and a bin cannot say where inside it its light came from (README, "Conventions").
    """
    from planeray.render.reference import render_rows
    from planeray.synthesis import sharpened_epipolar

    path = scene_xml(tmp_path, PAGE.format(half=6, albedo=0.6), WALL)
    # 128 samples per pixel (measured, seeds as here: max |z| 2.4 / 3.4, mean z^2 0.83 / 1.25 at P = 24 / 90;
    # the quarter-row-wider window told apart at z 30 / 14; at 256 samples 2.8 / 2.5, 1.9 / 1.1, z 44 / 22)
    H, shape, spp = 16, (16, 16), 128
    rendered = [render_transport(path, shape=shape, projector_rows=P, spp=spp, seed=s, band_rows=8) for s in (1, 2)]
    loaded, rig, _, _ = _parts(path, P, shape)
    per_row = [render_rows(loaded, rig, shape, range(P), spp=spp, seed=s)[..., 0] for s in (10, 50)]
    # the renderer's unit: the radiance of a white surface facing the projector (Mitsuba's own units here)
    scale = 1.0 / rendered[0].attrs["white_radiance"]
    zs, z_shifted = [], []
    for w in windows:
        est = [sharpened_epipolar(r.transport, width_rows=w) for r in rendered]
        ref = [scale * _window_from_rows(r, P, H, -w / 2, w / 2) for r in per_row]
        zs.append(block_z(*est, *ref))
        # power: a window a quarter row wider is told apart
        shifted = [scale * _window_from_rows(r, P, H, -w / 2 - 0.125, w / 2 + 0.125) for r in per_row]
        z_shifted.append(np.abs(block_z(*est, *shifted)).max())
    z = np.concatenate(zs)
    assert z.size >= 12 * len(windows)
    assert np.abs(z).max() < 5.0, np.abs(z).max()
    assert np.mean(z**2) < 2.5, np.mean(z**2)
    assert z_shifted[windows.index(1.0)] > 8, z_shifted  # the 1-row window: a quarter row wider adds 25 %
