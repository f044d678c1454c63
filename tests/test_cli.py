"""The command line: every command runs, writes what it says, and fails in one line."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from planeray.cli import _join_pixel_args, app, main
from planeray.io import read_stack

runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def stack_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "plane.zarr"
    res = invoke("simulate", "diffuse_plane", "--out", path, "--size", 32, 40, "--sweep", "quick", "--seed", 3)
    assert res.exit_code == 0, res.output
    return path


def test_scenes_lists_the_builtin_scenes():
    res = invoke("scenes")
    assert res.exit_code == 0
    for name in ("diffuse_plane", "wax", "corner", "mirror_ball", "disco_ball"):
        assert name in res.output


def test_simulate_writes_a_stack_with_its_parameters(stack_path, tmp_path):
    st = read_stack(stack_path)
    assert st.shape == (32, 40) and len(st) == 27
    assert st.metadata["camera"]["frames_averaged"] == 8
    assert st.metadata["scene"]["seed"] == 3
    truth = tmp_path / "truth.zarr"
    res = invoke(
        "simulate",
        "wax",
        "--out",
        tmp_path / "w.zarr",
        "--size",
        32,
        32,
        "--sweep",
        "quick",
        "--frames",
        2,
        "--read-noise",
        3,
        "--projector-rows",
        96,
        "--truth",
        truth,
    )
    assert res.exit_code == 0, res.output
    st = read_stack(tmp_path / "w.zarr")
    assert st.projector_rows == 96 and st.metadata["camera"]["read_noise_e"] == 3
    assert truth.exists()


def test_simulate_refuses_to_overwrite(stack_path):
    res = invoke("simulate", "diffuse_plane", "--out", stack_path, "--size", 16, 16, "--sweep", "quick")
    assert res.exit_code == 1
    assert "already exists" in res.output


def test_info_json(stack_path):
    res = invoke("info", stack_path, "--json")
    assert res.exit_code == 0
    info = json.loads(res.stdout)
    assert info["images"] == 27 and info["shape"] == [32, 40] and info["lines_per_second"] == 54000.0


def test_contact_sheet_and_profiles_write_pngs(stack_path, tmp_path):
    res = invoke("contact-sheet", stack_path, "--out", tmp_path / "cs.png")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "cs.png").read_bytes()[:4] == b"\x89PNG"
    res = invoke(
        "profiles",
        stack_path,
        "--pixel",
        "5,6",
        "--pixel",
        "20,30",
        "--out",
        tmp_path / "p.png",
        "--csv",
        tmp_path / "p.csv",
    )
    assert res.exit_code == 0, res.output
    assert (tmp_path / "p.png").exists()
    mark, *lines = (tmp_path / "p.csv").read_text().splitlines()
    assert mark.startswith("# planeray_mark: planeray:table:")  # so --overwrite may replace it
    assert lines[0].startswith("row,col") and len(lines) == 1 + 2 * 27


@pytest.mark.usefixtures("figures_not_drawn")  # the words parsed; the profile figure: its own tests
def test_pixel_accepts_two_words(stack_path, tmp_path):
    assert _join_pixel_args(["profiles", "s", "--pixel", "5", "6", "--out", "x"]) == [
        "profiles",
        "s",
        "--pixel",
        "5,6",
        "--out",
        "x",
    ]
    with pytest.raises(SystemExit) as exc:
        main(["profiles", str(stack_path), "--pixel", "5", "6", "--out", str(tmp_path / "p2.png")])
    assert exc.value.code == 0
    assert (tmp_path / "p2.png").exists()


def test_export_import_round_trip(stack_path, tmp_path):
    res = invoke("export", stack_path, "--out", tmp_path / "folder", "--format", "png")
    assert res.exit_code == 0, res.output
    res = invoke("import", tmp_path / "folder", "--out", tmp_path / "back.zarr")
    assert res.exit_code == 0, res.output
    a, b = read_stack(stack_path), read_stack(tmp_path / "back.zarr")
    np.testing.assert_allclose(np.asarray(b.images[:]), np.asarray(a.images[:]), atol=1e-4)
    # every command accepts the import folder directly too
    assert invoke("info", tmp_path / "folder").exit_code == 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("info", "/no/such/stack"), "does not exist"),
        (("simulate", "no_such_scene", "--out", "/tmp/x.zarr"), "unknown scene"),
        (("simulate", "diffuse_plane", "--out", "/tmp/x.zarr", "--sweep", "bogus"), "unknown sweep"),
        (("simulate", "diffuse_plane", "--out", "/tmp/x.zarr", "--bit-depth", "20"), "--bit-depth must be"),
        (("simulate", "diffuse_plane", "--out", "/tmp/x.zarr", "--size", "4", "16"), "--size must be"),
        (("simulate", "wax", "--out", "/tmp/x.zarr", "--spp", "16"), "--spp is a rendering option of mitsuba:"),
    ],
)
def test_errors_are_one_line(args, message):
    res = invoke(*args)
    assert res.exit_code == 1
    assert message in res.output
    assert "Traceback" not in res.output


def test_simulate_sweeps_a_transport_store_as_its_scene(tmp_path):
    """A transport written with plain zarr by the contract (no planeray writer): the stack's expected images are
    Eq. 4 over its bins (independent dense sum here), and its size is the store's."""
    import zarr

    from planeray.timing import quick_sweep

    H, W, P = 12, 10, 60
    offsets = np.arange(-40, 41)
    rng = np.random.default_rng(0)
    T = (0.05 * rng.random((H, W, offsets.size)) * np.exp(-np.abs(offsets) / 6.0)).astype(np.float32)
    store = tmp_path / "mine.zarr"
    g = zarr.open_group(str(store), mode="w", zarr_format=3)
    g.create_array("T", data=T)
    g.attrs.update(
        {"format": "planeray-transport", "format_version": 1, "offsets_rows": offsets.tolist(), "projector_rows": P}
    )
    args = ("--sweep", "quick", "--no-noise", "--ambient", 0, "--jitter-us", 0, "--row-jitter-us", 0)
    res = invoke("simulate", store, "--out", tmp_path / "s.zarr", *args)
    assert res.exit_code == 0, res.output
    st = read_stack(tmp_path / "s.zarr")
    assert st.shape == (H, W) and st.projector_rows == P and st.metadata["scene"]["store"] == str(store)
    # expected images: sum over bins of the band's weight times T, the edge rule written out
    scale = st.metadata["signal_scale"]
    for i in (0, 4, 13):
        d, e = quick_sweep().delay_us[i], quick_sweep().exposure_us[i]
        ref = np.zeros((H, W))
        for t in range(H):
            p_t = (t + 0.5) * P / H - 0.5
            for j, k in enumerate(offsets):
                a, b = max(k - 0.5, -0.5 - p_t), min(k + 0.5, P - 0.5 - p_t)
                if b <= a:
                    continue
                c, half = d * 54000e-6, e * 54000e-6 / 2
                lit = max(0.0, min(b, c + half) - max(a, c - half)) / (b - a)
                ref[t] += lit * T[t, :, j]
        np.testing.assert_allclose(np.asarray(st.images[i]) / scale, ref, rtol=1e-5, atol=1e-6)
    # a size or projector that is not the store's is refused, naming the option
    res = invoke("simulate", store, "--out", tmp_path / "x.zarr", "--projector-rows", 720)
    assert res.exit_code == 1 and "--projector-rows asks for 720" in res.output
    res = invoke("simulate", tmp_path / "s.zarr", "--out", tmp_path / "y.zarr")
    assert res.exit_code == 1 and "a stack, not a transport store" in res.output


def test_bad_pixel_is_reported(stack_path, tmp_path):
    res = invoke("profiles", stack_path, "--pixel", "500,1", "--out", tmp_path / "p.png")
    assert res.exit_code == 1 and "outside" in res.output
    res = invoke("profiles", stack_path, "--pixel", "a,b", "--out", tmp_path / "p.png")
    assert res.exit_code == 1 and "ROW COL" in res.output


def test_demux_command_writes_a_transport_store(tmp_path):
    stack = tmp_path / "wax.zarr"
    assert invoke("simulate", "wax", "--out", stack, "--size", 16, 16, "--projector-rows", 90).exit_code == 0
    res = invoke("demux", stack, "--out", tmp_path / "T.zarr", "--chunk", 8)
    assert res.exit_code == 0, res.output
    assert "converged 100.00 %" in res.output
    from planeray.io import read_transport

    T, attrs = read_transport(tmp_path / "T.zarr")
    assert T.dense.shape == (16, 16, 229) and attrs["method"] == "fast"
    res = invoke("demux", stack, "--out", tmp_path / "T.zarr")
    assert res.exit_code == 1 and "already exists" in res.output
    res = invoke("demux", stack, "--out", tmp_path / "P.zarr", "--method", "magic")
    assert res.exit_code == 1 and "unknown demultiplexing method" in res.output


def test_profiles_from_transport_and_classification(tmp_path):
    stack = tmp_path / "mb.zarr"
    assert invoke("simulate", "mirror_ball", "--out", stack, "--size", 32, 32, "--projector-rows", 180).exit_code == 0
    assert invoke("demux", stack, "--out", tmp_path / "T.zarr").exit_code == 0
    res = invoke(
        "profiles",
        stack,
        "--pixel",
        "10,10",
        "--transport",
        tmp_path / "T.zarr",
        "--classify",
        tmp_path / "labels.png",
        "--out",
        tmp_path / "p.png",
    )
    assert res.exit_code == 0, res.output
    assert (tmp_path / "labels.png").read_bytes()[:4] == b"\x89PNG" and (tmp_path / "p.png").exists()
    assert "specular_interreflection" in res.output
    res = invoke("profiles", stack, "--classify", tmp_path / "l2.png", "--out", tmp_path / "p2.png")
    assert res.exit_code == 1 and "--transport" in res.output


def test_mc_profile_writes_csv_json_and_png(tmp_path, monkeypatch):
    monkeypatch.setenv("PLANERAY_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "p.csv"
    r = invoke(
        "mc",
        "profile",
        "--out",
        out,
        "--sigma-s",
        1.0,
        "--sigma-a",
        0.1,
        "--g",
        0.5,
        "--photons",
        4000,
        "--rows",
        10,
        "--plot",
        tmp_path / "p.png",
    )
    assert r.exit_code == 0, r.output
    import csv
    import json

    with open(out) as fh:
        assert fh.readline().startswith("# planeray_mark: ")  # the mark, a comment line
        rows = list(csv.DictReader(fh))
    assert len(rows) == 21 and rows[10]["offset_rows"] == "0"
    assert float(rows[10]["exitance"]) > float(rows[0]["exitance"]) > 0
    summary = json.loads(out.with_suffix(".json").read_text())
    assert summary["planeray_mark"].startswith("planeray:record:")
    assert abs(summary["energy_balance"] - 1.0) < 1e-9
    assert summary["params"]["sigma_a"] == 0.1 and summary["n_photons"] == 4000
    assert (tmp_path / "p.png").stat().st_size > 10_000
    bad = invoke("mc", "profile", "--out", tmp_path / "bad.csv", "--g", 1.5, "--photons", 10)
    assert bad.exit_code != 0 and "g must lie in (-1, 1)" in bad.output


def test_mc_profile_point_source(tmp_path, monkeypatch):
    monkeypatch.setenv("PLANERAY_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "r.csv"
    r = invoke(
        "mc",
        "profile",
        "--point",
        "--out",
        out,
        "--sigma-a",
        0.2,
        "--g",
        0.0,
        "--photons",
        3000,
        "--rows",
        8,
        "--plot",
        tmp_path / "r.png",
    )
    assert r.exit_code == 0, r.output
    lines = out.read_text().splitlines()[1:]  # after the mark
    assert lines[0].startswith("radius_bin,r_mm,exitance") and len(lines) == 1 + 9
    assert (tmp_path / "r.png").exists()


@pytest.mark.parametrize(
    ("new", "old", "value", "field"),
    [
        ("--full-well-e", "--full-well", 9000, "full_well_e"),
        ("--read-noise-e", "--read-noise", 3, "read_noise_e"),
        ("--ambient-e-per-us", "--ambient", 0.25, "ambient_e_per_us"),
    ],
)
def test_unit_option_names_and_their_old_spellings_agree(tmp_path, new, old, value, field):
    stacks = []
    for i, name in enumerate((new, old)):
        path = tmp_path / f"{i}.zarr"
        res = invoke("simulate", "diffuse_plane", "--out", path, "--size", 16, 16, "--sweep", "quick", name, value)
        assert res.exit_code == 0, res.output
        stacks.append(read_stack(path))
    a, b = stacks
    assert a.metadata["camera"][field] == b.metadata["camera"][field] == value
    np.testing.assert_array_equal(np.asarray(a.images[:]), np.asarray(b.images[:]))


def test_every_renamed_option_keeps_its_old_spelling():
    import typer.main

    group = typer.main.get_command(app)
    renamed = {
        ("simulate",): {
            "--full-well-e": "--full-well",
            "--read-noise-e": "--read-noise",
            "--ambient-e-per-us": "--ambient",
        },
        ("profiles",): {"--exposure-us": "--exposure"},
        ("demux",): {"--chunk-rows": "--chunk"},
        ("emulate",): {"--ambient-e-per-us": "--ambient"},
        ("separate", "direct-global"): {"--ambient-e-per-us": "--ambient", "--period-rows": "--period"},
    }
    for path, names in renamed.items():
        cmd = group
        for part in path:
            cmd = cmd.commands[part]
        opts = [p.opts for p in cmd.params]
        for new, old in names.items():
            assert [new, old] in opts, f"{' '.join(path)}: {new} / {old}"
