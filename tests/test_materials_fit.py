"""Measuring the medium (issue 27): the forward model against direct Monte Carlo, and the fit of mu_s', mu_a.

Ground truth is a medium of known coefficients traced by :func:`planeray.mc.mc_line_profile` with its
own seed and photon count (not the table's), so the fit is checked against a forward model it was not
built from; tolerances come from the Monte Carlo standard errors.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from planeray.errors import InputError
from planeray.kernels import forward
from planeray.kernels.footprint import camera_row_footprint
from planeray.kernels.walls import dipole_per_row, layer_line
from planeray.materials import fit
from planeray.mc import mc_line_profile
from planeray.medium import Medium

MM = 0.3
OFFSETS = np.arange(-100, 101)


@pytest.fixture(scope="module")
def table():
    return fit.forward_table()


def _direct(mu_s_prime, mu_a, *, mm=MM, n_photons=100_000, seed=11, offsets=OFFSETS):
    """Direct Monte Carlo kernel in the scenes' unit and its standard error (independent of the table)."""
    med = Medium.from_reduced(mu_s_prime, mu_a, g=fit.DEFAULT_G, n=fit.DEFAULT_N)
    p = mc_line_profile(med, n_photons=n_photons, offsets_rows=offsets, mm_per_row=mm, seed=seed)
    return np.pi * mm * p.radiance, np.pi * mm * p.radiance_stderr


def test_the_shipped_table_is_found_without_tracing(monkeypatch):
    forward._LOADED.clear()

    def no_tracing(**kwargs):
        raise AssertionError("the shipped forward table was not found")

    monkeypatch.setattr(forward, "build_forward_table", no_tracing)
    t = fit.forward_table()
    assert t.kernel.shape == (fit.TABLE_MU_S_PRIME_PER_MM.size, fit.TABLE_MU_A_PER_MM.size, fit.TABLE_REACH_ROWS + 1)


def _scene_slab(class_id):
    """The materials scene's shipped Monte Carlo slab kernel of a medium (10^6 photons, not the table's run)."""
    from planeray.scenes.materials import material_tables

    wt = material_tables()[class_id]
    sel = np.searchsorted(wt.offsets_rows, OFFSETS)
    return wt.medium, wt.slab[sel], wt.slab_stderr[sel]


@pytest.mark.parametrize("case", ["2% milk", "0.5 mm per row"])
def test_the_forward_model_matches_direct_monte_carlo(table, case):
    if case == "2% milk":  # g 0.82 against the table's 0.8; off the grid
        med, k_dir, e_dir = _scene_slab(2)
        mu_s_prime, mu_a, mm = med.sigma_s_prime, med.sigma_a, 0.3
    else:  # another row size: the per-row scaling (a small run: 10 000 photons)
        mu_s_prime, mu_a, mm = 0.8, 0.004, 0.5
        k_dir, e_dir = _direct(mu_s_prime, mu_a, mm=mm, n_photons=10_000)
    k_fit = fit.forward_kernel(mu_s_prime, mu_a, offsets_rows=OFFSETS, mm_per_row=mm, table=table)
    # Groups of 9 rows (noise averages out), where the kernel carries light.
    groups = OFFSETS.reshape(-1, 1)[:198].reshape(22, 9)
    idx = groups - OFFSETS[0]
    a, b = k_dir[idx].sum(axis=1), k_fit[idx].sum(axis=1)
    ea = np.sqrt((e_dir[idx] ** 2).sum(axis=1))
    keep = a > 1e-3 * a.max()
    # The table has 10^5 photons per point too and is interpolated: allow 3 % of the value beside 4 sigma.
    tol = 4.0 * np.sqrt(2.0) * ea[keep] + 0.03 * a[keep]
    assert np.all(np.abs(a[keep] - b[keep]) <= tol), np.max(np.abs(a[keep] - b[keep]) / tol)
    # and in total within the window (the reflectance a calibrated fit uses)
    assert abs(k_fit.sum() - k_dir.sum()) <= 4 * np.sqrt(2 * (e_dir**2).sum()) + 0.015 * k_dir.sum()


def test_a_kernel_outside_the_table_is_refused(table):
    with pytest.raises(ValueError, match="outside the forward model"):
        fit.forward_kernel(500.0, 0.01, offsets_rows=OFFSETS, mm_per_row=MM, table=table)


@pytest.mark.parametrize("calibrated", [True, False])
def test_the_fit_recovers_the_parameters_of_noiseless_profiles(table, calibrated):
    truth = [(0.5, 0.002), (1.5, 0.02), (4.0, 0.08)]
    Y = np.stack([fit.forward_kernel(s, a, offsets_rows=OFFSETS, mm_per_row=MM, table=table) for s, a in truth])
    if not calibrated:
        Y = Y * 37.0  # camera units: only the shape is used
    r = fit.fit_profiles(Y, offsets_rows=OFFSETS, mm_per_row=MM, calibrated=calibrated, table=table)
    s_true, a_true = np.array(truth).T
    np.testing.assert_allclose(r.mu_s_prime_per_mm, s_true, rtol=2e-3)
    np.testing.assert_allclose(r.mu_a_per_mm, a_true, rtol=5e-3)
    assert np.all(r.mask == 0)
    np.testing.assert_allclose(r.scale, 1.0 if calibrated else 37.0, rtol=5e-3)


def test_the_fit_recovers_media_traced_by_direct_monte_carlo(table):
    """A forward model the fit was not built from (the scene's own Monte Carlo slabs of the three milks, g 0.93,
    0.82, 0.75, 10^6 photons each): the issue's targets."""
    meds, Y, S = zip(*(_scene_slab(c) for c in (1, 2, 3)))
    truth = [(m.sigma_s_prime, m.sigma_a) for m in meds]
    r = fit.fit_profiles(np.stack(Y), offsets_rows=OFFSETS, mm_per_row=MM, sigma=np.stack(S), calibrated=True)
    s_true, a_true = np.array(truth).T
    assert np.all(np.abs(r.mu_s_prime_per_mm / s_true - 1) <= 0.10), r.mu_s_prime_per_mm
    assert np.all(np.abs(r.mu_a_per_mm / a_true - 1) <= 0.25), r.mu_a_per_mm


def test_the_standard_errors_match_the_spread_over_noise_seeds(table):
    clean = fit.forward_kernel(1.2, 0.01, offsets_rows=OFFSETS, mm_per_row=MM, table=table)
    sigma = 0.003 * clean.max() * np.ones_like(clean)  # small noise: the linearized errors hold
    rng = np.random.default_rng(0)
    Y = clean[None, :] + sigma[None, :] * rng.standard_normal((120, clean.size))
    # data made by the table itself: its own error is not part of this noise
    r = fit.fit_profiles(
        Y, offsets_rows=OFFSETS, mm_per_row=MM, sigma=sigma, calibrated=False, table=table, model_relative_sd=0
    )
    ok = r.mask == 0
    assert ok.mean() > 0.9
    for est, se in ((r.mu_s_prime_per_mm, r.mu_s_prime_se_per_mm), (r.mu_a_per_mm, r.mu_a_se_per_mm)):
        logs = np.log(est[ok])
        spread = 1.4826 * np.median(np.abs(logs - np.median(logs)))  # robust: a few fits land in a far minimum
        reported = np.median(se[ok] / est[ok])
        # 120 seeds: the spread's own relative error is ~7 %; allow 25 %.
        assert 0.75 < reported / spread < 1.25, (reported, spread)
    # and without sigma, the errors come from the residuals: about the same
    r2 = fit.fit_profiles(Y[:20], offsets_rows=OFFSETS, mm_per_row=MM, calibrated=False, table=table)
    ratio = np.median(r2.mu_s_prime_se_per_mm / r.mu_s_prime_se_per_mm[:20])
    assert 0.8 < ratio < 1.2


def test_a_parameter_the_data_do_not_constrain_is_nan_with_its_reason(table):
    # Weak absorption seen only near the line (|u| <= 8 rows = 2.4 mm, diffusion length ~ 40 mm), shape only:
    # the profile hardly depends on mu_a -- a flat likelihood.
    near = np.arange(-8, 9)
    clean = fit.forward_kernel(1.0, 0.0008, offsets_rows=near, mm_per_row=MM, table=table)
    sigma = 0.05 * clean.max() * np.ones_like(clean)
    y = clean + sigma * np.random.default_rng(1).standard_normal(clean.size)
    r = fit.fit_profiles(y, offsets_rows=near, mm_per_row=MM, sigma=sigma, table=table, model_relative_sd=0)
    assert np.isnan(r.mu_a_per_mm[0]) and np.isnan(r.mu_a_se_per_mm[0])
    assert r.mask[0] & (4 | 16)
    assert any("mu_a" in why for why in fit.describe_reasons(int(r.mask[0])))
    # mu_s' is still measured there, and close to the truth
    assert abs(r.mu_s_prime_per_mm[0] / 1.0 - 1) < 3 * r.mu_s_prime_se_per_mm[0]


def test_a_profile_without_signal_is_nan_with_its_reason(table):
    r = fit.fit_profiles(np.zeros((2, OFFSETS.size)), offsets_rows=OFFSETS, mm_per_row=MM, table=table)
    assert np.all(np.isnan(r.mu_s_prime_per_mm)) and np.all(np.isnan(r.mu_a_per_mm))
    assert np.all(r.mask & 1)


def test_a_profile_narrower_than_a_bin_gives_no_mu_s_prime(table):
    # Coarse rows (3 mm) of a strongly scattering medium (per-row mu_s' 28.5, far beyond the table's 2.4: the
    # dipole): 98 % of the light returns within the line's own bin, whose shape says nothing of mu_s'.
    coarse = np.arange(-20, 21)
    y = fit.forward_kernel(9.5, 0.019, offsets_rows=coarse, mm_per_row=3.0, table=table)
    assert y[21] < 0.03 * y[20]
    y = y * (1 + 0.01 * np.random.default_rng(4).standard_normal(y.size))
    r = fit.fit_profiles(y, offsets_rows=coarse, mm_per_row=3.0, sigma=0.01 * y + 1e-6, table=table)
    assert np.isnan(r.mu_s_prime_per_mm[0])
    assert r.mask[0] & 32
    assert any("mu_s'" in why for why in fit.describe_reasons(int(r.mask[0])))
    # a third of that (per-row 9, 11 % of the light in the next bin) is measured, by the dipole beyond the table
    y = fit.forward_kernel(3.0, 0.015, offsets_rows=coarse, mm_per_row=3.0, table=table)
    r = fit.fit_profiles(y, offsets_rows=coarse, mm_per_row=3.0, sigma=0.01 * y + 1e-6, table=table)
    assert r.mu_s_prime_per_mm[0] == pytest.approx(3.0, rel=0.02) and r.mask[0] == 0


def test_the_calibrated_fit_constrains_mu_a_better_than_the_shape_alone(table):
    clean = fit.forward_kernel(1.0, 0.003, offsets_rows=OFFSETS, mm_per_row=MM, table=table)
    sigma = 0.03 * clean.max() * np.ones_like(clean)
    y = clean + sigma * np.random.default_rng(2).standard_normal(clean.size)
    opts = dict(offsets_rows=OFFSETS, mm_per_row=MM, sigma=sigma, table=table, model_relative_sd=0)
    cal = fit.fit_profiles(y, calibrated=True, **opts)
    shape = fit.fit_profiles(y, calibrated=False, **opts)
    assert np.isfinite(cal.mu_a_se_per_mm[0])
    assert np.isnan(shape.mu_a_per_mm[0]) or cal.mu_a_se_per_mm[0] < shape.mu_a_se_per_mm[0]


def test_bad_inputs_are_refused_in_one_line(table):
    with pytest.raises(ValueError, match="offsets_rows has 3 values"):
        fit.fit_profiles(np.ones(5), offsets_rows=[0, 1, 2], mm_per_row=MM, table=table)
    with pytest.raises(ValueError, match="mm_per_row must be positive"):
        fit.fit_profiles(np.ones(3), offsets_rows=[0, 1, 2], mm_per_row=0, table=table)
    with pytest.raises(ValueError, match="sigma must be positive"):
        fit.fit_profiles(np.ones(3), offsets_rows=[0, 1, 2], mm_per_row=MM, sigma=0.0, table=table)


# ---------------------------------------------------------------- the command
@pytest.fixture(scope="module")
def capture(tmp_path_factory, table):
    """A small transport store of two media side by side (known coefficients), with its row size recorded."""
    from planeray.io import write_transport
    from planeray.transport import Transport

    root = tmp_path_factory.mktemp("fitcli")
    off = np.arange(-60, 61)
    k1 = fit.forward_kernel(0.8, 0.005, offsets_rows=off, mm_per_row=MM, table=table)
    k2 = fit.forward_kernel(2.5, 0.04, offsets_rows=off, mm_per_row=MM, table=table)
    rng = np.random.default_rng(3)
    dense = np.empty((8, 8, off.size), np.float32)
    dense[:, :4] = k1 * 50.0
    dense[:, 4:] = k2 * 50.0
    dense *= 1.0 + 0.01 * rng.standard_normal(dense.shape)
    path = write_transport(Transport(dense, off), root / "cap.zarr", attrs={"mm_per_row": MM})
    white = np.zeros_like(dense)
    white[:, :, off == 0] = 50.0 * 0.99  # a Lambertian card of albedo 0.99, same camera units
    write_transport(Transport(white, off), root / "white.zarr", attrs={"mm_per_row": MM})
    labels = np.zeros((8, 8), np.uint8)
    labels[:, :4], labels[:, 4:] = 1, 2
    from planeray.materials import write_label_image

    write_label_image(root / "labels.png", labels, kind="labels")
    return root, path


def test_the_command_writes_maps_with_units_a_figure_and_a_summary(capture):
    import json

    import tifffile
    from typer.testing import CliRunner

    from planeray.cli import app

    cli_runner = CliRunner()
    root, cap = capture
    out = root / "fit1"
    res = cli_runner.invoke(
        app,
        [
            "materials",
            "fit",
            str(cap),
            "--out",
            str(out),
            "--labels",
            str(root / "labels.png"),
            "--block",
            "4",
            "--no-walls",
        ],
    )  # two unbounded media side by side: no container walls
    assert res.exit_code == 0, res.output
    meta = json.loads((out / "planeray.json").read_text())
    assert meta["format"] == "planeray-materials-fit" and "shape only" in meta["calibration"]
    assert meta["walls"].startswith("none")
    r1, r2 = meta["regions"]["1"], meta["regions"]["2"]
    assert abs(r1["mu_s_prime_per_mm"] / 0.8 - 1) < 0.05 and abs(r2["mu_s_prime_per_mm"] / 2.5 - 1) < 0.05
    assert abs(r2["mu_a_per_mm"] / 0.04 - 1) < 0.25
    with tifffile.TiffFile(out / "mu_a_per_mm.tif") as tif:
        page = tif.pages[0]
        assert page.dtype == np.float32
        assert json.loads(page.description)["unit"] == "1/mm"
        m = page.asarray()
    assert np.nanmedian(m[:, 4:]) == pytest.approx(0.04, rel=0.25)
    assert (out / "fit.png").stat().st_size > 10_000
    # the data promises: an existing output is refused without --overwrite, replaced with it
    again = cli_runner.invoke(app, ["materials", "fit", str(cap), "--out", str(out)])
    assert again.exit_code == 1 and "already exists" in again.output
    again = cli_runner.invoke(app, ["materials", "fit", str(cap), "--out", str(out), "--overwrite", "--block", "8"])
    assert again.exit_code == 0, again.output


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--block", "0"], "--block"),
        (["--n", "2.5"], "--n"),
        (["--mm-per-row", "-1"], "--mm-per-row"),
        (["--white-albedo", "1.5"], "--white-albedo"),
        (["--g", "0.99"], "--g"),
        (["--labels", "{d}/nothing.png"], "--labels"),
        (["--white-reference", "{d}/nothing.zarr"], "--white-reference"),
    ],
)
def test_bad_command_inputs_are_refused_in_one_line_and_touch_nothing(capture, tmp_path, extra, needle):
    from _new_user import run_bad, user_files

    root, cap = capture
    user_files(tmp_path)
    run_bad(["materials", "fit", cap, "--out", "{d}/fit", *extra], folder=tmp_path, option=needle)


def test_a_user_folder_is_never_the_output(capture, tmp_path):
    from _new_user import run_bad, user_files

    root, cap = capture
    user_files(tmp_path)
    run_bad(["materials", "fit", cap, "--out", "{d}", "--overwrite"], folder=tmp_path)


@pytest.mark.usefixtures("figures_not_drawn")  # the numbers; the fit's figure: the tests that draw it above
def test_the_white_reference_calibrates_the_magnitude(capture):
    import json

    from typer.testing import CliRunner

    from planeray.cli import app

    root, cap = capture
    out = root / "fit_white"
    args = ["materials", "fit", str(cap), "--out", str(out), "--labels", str(root / "labels.png"), "--no-walls"]
    res = CliRunner().invoke(app, [*args, "--white-reference", str(root / "white.zarr"), "--white-albedo", "0.99"])
    assert res.exit_code == 0, res.output
    meta = json.loads((out / "planeray.json").read_text())
    assert "white reference" in meta["calibration"]
    for region, (s_true, a_true) in {"1": (0.8, 0.005), "2": (2.5, 0.04)}.items():
        r = meta["regions"][region]
        assert abs(r["mu_s_prime_per_mm"] / s_true - 1) < 0.05, r
        assert abs(r["mu_a_per_mm"] / a_true - 1) < 0.10, r


@pytest.mark.usefixtures("figures_not_drawn")
def test_a_stated_g_is_used_and_an_unstated_one_is_fitted(capture):
    """`--g` states the medium's anisotropy (used, said so, one parameter fewer); without it g is fitted with
    mu_s' and mu_a and reported with its standard error (planeray.kernels.anisotropy)."""
    import json

    from typer.testing import CliRunner

    from planeray.cli import app

    root, cap = capture
    base = ["materials", "fit", str(cap), "--labels", str(root / "labels.png"), "--no-walls", "--white-reference",
            str(root / "white.zarr")]  # fmt: skip
    metas = {}
    for name, extra in (("stated", ["--g", "0.8"]), ("unknown", [])):
        res = CliRunner().invoke(app, [*base, "--out", str(root / f"fit_g_{name}"), *extra])
        assert res.exit_code == 0, res.output
        metas[name] = json.loads((root / f"fit_g_{name}" / "planeray.json").read_text())
    stated, unknown = metas["stated"], metas["unknown"]
    assert stated["anisotropy_g"] == 0.8 and stated["anisotropy_g_source"] == "--g"
    assert unknown["anisotropy_g"] is None and unknown["anisotropy_g_source"].startswith("unknown")
    for region in ("1", "2"):
        s, u = stated["regions"][region], unknown["regions"][region]
        assert s["g"] == 0.8 and s["g_se"] is None
        assert 0.0 <= u["g"] <= 0.95 and u["g_se"] > 0
        assert s["fit_quality"]["dof"] == u["fit_quality"]["dof"] + 1


def test_regions_only_gives_the_same_regions_without_the_maps(capture, table):
    from planeray.io import read_transport

    transport, _ = read_transport(capture[1])
    labels = np.zeros((8, 8), int)
    labels[:, :4], labels[:, 4:] = 1, 2
    kw = {"mm_per_row": MM, "labels": labels, "block_px": 2, "table": table}
    full = fit.fit_transport(transport, **kw)
    quick = fit.fit_transport(transport, regions_only=True, **kw)
    for region in (1, 2):
        for key in ("mu_s_prime_per_mm", "mu_a_per_mm", "mu_s_prime_se_per_mm", "mu_a_se_per_mm", "pixels"):
            assert quick.regions[region][key] == full.regions[region][key], (region, key)
        assert quick.regions[region]["blocks_identified"] is None
    assert np.isfinite(full.maps["mu_s_prime_per_mm"]).all()
    assert np.isnan(quick.maps["mu_s_prime_per_mm"]).all() and (quick.maps["mask"] == 255).all()


# ---------------------------------------------------------------- walls and beyond the table
def test_container_wall_distances_are_halfway_to_the_next_label():
    lab = np.zeros((6, 7), int)
    lab[1:4, 2:6] = 1  # rows 1-3, columns 2-5
    lab[4:, :] = 2  # touches the image's border below: no wall there
    d = fit.container_wall_distances(lab, rows_per_camera_row=2.0)
    # pixel (1, 2): 3 pixels of its run downward -> wall 2.5 px = 5 rows; up 0.5 px; right 3.5 px; left 0.5 px
    np.testing.assert_allclose(d[1, 2], [5.0, 1.0, 7.0, 1.0])
    np.testing.assert_allclose(d[2, 4], [3.0, 3.0, 3.0, 5.0])
    assert np.all(np.isinf(d[5, 3, [0, 2, 3]])) and d[5, 3, 1] == pytest.approx(3.0)  # only the wall above
    assert np.all(np.isnan(d[0, 0]))  # not a container


@pytest.mark.parametrize("angle", [0.0, 90.0])
def test_the_wall_model_carries_the_monte_carlo_walls_effect(table, angle):
    """The fit's wall model (diffusion images on the table's kernel) against the scene's brute-force Monte Carlo
    wall kernels (:mod:`planeray.mc.wall`, shipped): 2 % milk, a wall 12 rows (3.6 mm) from the pixel."""
    from planeray.scenes.materials import material_tables

    wt = material_tables()[2]
    med = wt.medium
    u = np.arange(-120, 121)
    sel = np.searchsorted(wt.offsets_rows, u)
    mc_effect = wt.kernels(12.0, angle)[sel] - wt.slab[sel]
    walls = np.array([[12.0, angle, 1.0, 1.0]])
    kw = dict(offsets_rows=u, mm_per_row=wt.mm_per_row, table=table)
    free = fit.forward_kernel(med.sigma_s_prime, med.sigma_a, **kw)
    effect = fit.forward_kernel(med.sigma_s_prime, med.sigma_a, walls=walls, **kw) - free
    size = np.abs(mc_effect).sum()
    assert size > 0.05 * wt.slab[sel].sum()  # the wall matters: 8 % of the kernel
    assert np.abs(effect - mc_effect).sum() < 0.2 * size  # the model carries >= 80 % of it (measured 91-96 %)


@pytest.mark.parametrize("class_id", [1, 2])  # fat-free and 2 % milk: the weakest absorbers, the largest wall effects
def test_the_fit_with_walls_reads_mu_a_of_monte_carlo_pixels_beside_walls(table, class_id):
    """A region of pixels 2.4-10 mm from a tray's walls, each pixel's kernel the scene's brute-force Monte Carlo
    with its wall (shipped wall tables, g of the milk, not the table's 0.8): without the walls the light they
    lose reads as absorption (mu_a ~2x too high); with them, the issue's targets hold."""
    from planeray.scenes.materials import material_tables

    wt = material_tables()[class_id]
    med = wt.medium
    sel = np.searchsorted(wt.offsets_rows, OFFSETS)
    pixels = [(d, ang) for d in (8.0, 12.0, 17.0, 24.0, 33.0) for ang in (0.0, 90.0)]
    y = np.mean([wt.kernels(d, ang)[sel] for d, ang in pixels], axis=0)
    y[y <= 0] = np.nan  # lines beyond the wall
    sd = np.mean([wt.kernel_stderr[list(wt.angles_deg).index(ang), list(wt.distances_rows).index(d)][sel]
                  for d, ang in pixels], axis=0)  # fmt: skip
    walls = np.array([[d, ang, 1.0, 1.0 / len(pixels)] for d, ang in pixels])
    kw = dict(offsets_rows=OFFSETS, mm_per_row=wt.mm_per_row, sigma=np.maximum(sd, 1e-3 * np.nanmax(y)), table=table)
    with_walls = fit.fit_profiles(y, walls=[walls], **kw)
    without = fit.fit_profiles(y, **kw)
    assert abs(with_walls.mu_s_prime_per_mm[0] / med.sigma_s_prime - 1) < 0.10, with_walls
    assert abs(with_walls.mu_a_per_mm[0] / med.sigma_a - 1) < 0.25, with_walls
    assert without.mu_a_per_mm[0] / med.sigma_a - 1 > 0.5, without  # the bias the walls' model removes


def test_beyond_the_table_toothpaste_is_measured_by_the_dipole(table):
    """Toothpaste (mu_s' 16 /mm: 4.8 per row, twice the table's largest; g 0.6, n 1.45): the scene's Monte Carlo
    slab, shape only."""
    med, y, e = _scene_slab(4)
    r = fit.fit_profiles(y, offsets_rows=OFFSETS, mm_per_row=MM, sigma=np.maximum(e, 1e-4 * y.max()), table=table)
    assert abs(r.mu_s_prime_per_mm[0] / med.sigma_s_prime - 1) < 0.10, r.mu_s_prime_per_mm


def test_beyond_the_table_the_dipole_takes_over_continuously(table):
    s1 = table.mu_s_prime_per_row[-1] / MM  # the table's largest mu_s', 1/mm
    kw = dict(offsets_rows=np.arange(-30, 31), mm_per_row=MM, table=table)
    at, beyond = fit.forward_kernel(s1, 0.02, **kw), fit.forward_kernel(s1 * 1.001, 0.02, **kw)
    np.testing.assert_allclose(beyond, at, rtol=5e-3)
    # and it narrows as mu_s' grows (more light near the line)
    far = fit.forward_kernel(4 * s1, 0.02, **kw)
    assert far[30] / far.sum() > at[30] / at.sum()


def test_a_layers_bottom_is_the_slab_image_series_integrated_along_the_line(table):
    """`walls` row of angle BOTTOM_ANGLE_DEG: the kernel's change is the slab dipole's (Contini et al. 1997) over
    the semi-infinite one, the line integral checked here by quadrature of the point-source reflectance."""
    from scipy.integrate import quad

    s, a, n = 0.06, 0.0012, 1.33  # per row: soap-like (0.2 /mm, 0.004 /mm at 0.3 mm per row)
    d = dipole_per_row(s, a, n)
    st, z_r, z_b = d["sigma_tr"], d["z"][0], d["z_b"]
    depth = 100.0
    period = 2.0 * (depth + z_b + 2.0 / (3.0 * (s + a)))

    def reflectance(rho):  # the slab's image series, point source: sum of sign * z (st r + 1) exp(-st r) / r^3
        out = 0.0
        for m in range(-4, 5):
            for z, sign in ((z_r + m * period, 1.0), (-2.0 * z_b - z_r + m * period, -1.0)):
                r = np.hypot(rho, z)
                out += sign * z * (st * r + 1.0) * np.exp(-st * r) / r**3
        return d["albedo"] / (4.0 * np.pi) * out

    for x in (0.5, 10.0, 60.0):
        line = 2.0 * quad(lambda y, x=x: reflectance(np.hypot(x, y)), 0.0, np.inf, limit=200)[0]
        assert layer_line(np.array([x]), d, depth)[0] == pytest.approx(line, rel=1e-6)
    off = np.arange(0, 101)
    free = fit.forward_kernel(0.2, 0.004, offsets_rows=off, mm_per_row=0.3, table=table)
    deep = fit.forward_kernel(0.2, 0.004, offsets_rows=off, mm_per_row=0.3, table=table, walls=[[1e5, 180.0, 0, 1]])
    layer = fit.forward_kernel(0.2, 0.004, offsets_rows=off, mm_per_row=0.3, table=table, walls=[[depth, 180.0, 0, 1]])
    np.testing.assert_allclose(deep, free, rtol=1e-9)  # a bottom far below changes nothing
    ratio = layer / free
    assert 0.98 < ratio[0] < 1.0 and ratio[100] < 0.9 and np.all(np.diff(ratio[::10]) < 0)  # the far light is lost


def test_a_layer_fitted_with_its_depth_is_recovered_and_biased_without(table):
    from planeray.transport import Transport

    off = np.arange(-60, 61)
    bottom = [[10.0 / MM, fit.BOTTOM_ANGLE_DEG, 0.0, 1.0]]  # a 10 mm layer of a medium 2 transport paths deep
    k = fit.forward_kernel(0.2, 0.004, offsets_rows=off, mm_per_row=MM, table=table, walls=bottom)
    rng = np.random.default_rng(5)
    dense = (k * 50.0 * (1.0 + 0.002 * rng.standard_normal((4, 4, off.size)))).astype(np.float32)
    transport = Transport(dense, off)
    got = {}
    for depth in (10.0, None):
        r = fit.fit_transport(transport, mm_per_row=MM, block_px=2, table=table, depth_mm=depth, regions_only=True)
        got[depth] = (r.regions[1]["mu_s_prime_per_mm"] / 0.2 - 1, r.regions[1]["mu_a_per_mm"] / 0.004 - 1)
    assert abs(got[10.0][0]) < 0.03 and abs(got[10.0][1]) < 0.05, got
    assert abs(got[None][1]) > 0.3, got  # the light lost at the bottom read as absorption
    with pytest.raises(InputError, match="depth_mm"):
        fit.fit_transport(transport, mm_per_row=MM, table=table, depth_mm=-1.0)


def test_a_mismatched_model_is_flagged_and_a_consistent_one_is_not(table):
    """Goodness of fit (issue 41): a 2 mm layer of a weakly scattering medium (its kernel cut by the bottom)
    fitted as semi-infinite does not fit within the noise and is flagged (in the region's summary and the flag
    layer); fitted with its depth it fits and nothing is flagged.  A 3 mm layer is flagged only when the medium's
    g is stated: with g unknown, part of the bottom's cut reads as a forward-scattering g (reduced chi-square 1.64
    against 1.67).  (A deep layer's loss reads as absorption within the noise -- the 10 mm layer above: not every
    wrong model shows in the chi-square.)"""
    from planeray.goodness import FLAG_MISFIT, FLAG_RANGE
    from planeray.transport import Transport

    off = np.arange(-60, 61)

    def layer(depth_mm):
        k = fit.forward_kernel(0.2, 0.004, offsets_rows=off, mm_per_row=MM, table=table,
                            walls=[[depth_mm / MM, fit.BOTTOM_ANGLE_DEG, 0.0, 1.0]])  # fmt: skip
        rng = np.random.default_rng(5)
        return Transport((k * 50.0 * (1.0 + 0.002 * rng.standard_normal((4, 4, off.size)))).astype(np.float32), off)

    kw = dict(mm_per_row=MM, block_px=4, table=table, regions_only=True)
    right = fit.fit_transport(layer(2.0), depth_mm=2.0, **kw)
    wrong = fit.fit_transport(layer(2.0), **kw)
    r, w = right.regions[1], wrong.regions[1]
    assert r["model_fits"] and r["fit_quality"]["reduced_chi2"] < r["fit_quality"]["threshold"]
    # the right model fits; its 2 mm bottom lies within 5 transport mean free paths (1 / 0.2 mm): flagged out of
    # diffusion theory's range, never as a misfit
    assert r["flag_bits"] == FLAG_RANGE and np.all(right.maps["flags"] == FLAG_RANGE)
    assert not w["model_fits"] and w["flag_bits"] & FLAG_MISFIT and "model does not fit" in w["flags"][0]
    assert np.all(wrong.maps["flags"] & FLAG_MISFIT)
    # the misfit widens the standard errors by sqrt(chi2 / dof)
    assert w["fit_quality"]["se_inflation"] == pytest.approx(np.sqrt(w["fit_quality"]["reduced_chi2"]))
    # 3 mm: flagged with the medium's g stated (with g unknown it is not: the docstring)
    stated = fit.fit_transport(layer(3.0), g=fit.DEFAULT_G, **kw).regions[1]
    assert stated["flag_bits"] & FLAG_MISFIT


# ---------------------------------------------------------------- Fig. 10 extended (`materials report`, `paper`)
def test_the_report_measures_each_container_away_from_its_walls_with_its_walls_modelled(monkeypatch, tmp_path):
    """`materials report` (full) fits each tray's pixels >= 3 mm from its walls as one region, the walls from
    every tray pixel; the numbers are the fit's, beside the published constants (the fit itself: above)."""
    from types import SimpleNamespace

    from planeray.experiments.materials import media_fit_numbers
    from planeray.figures.materials import measured_media_figure
    from planeray.optical_data import MATERIAL_CLASSES, material_medium
    from planeray.scenes import make_scene

    scene = make_scene("materials", (24, 24), projector_rows=720, seed=0)
    seen = []

    def fake_fit(transport, *, mm_per_row, labels, block_px, containers, regions_only):
        assert regions_only  # the maps are not needed
        seen.append((transport, mm_per_row, labels, block_px, containers))
        regions = {}
        for cid in MATERIAL_CLASSES:  # mu_s' 10 x cid % high; mu_a not identified for cid 3
            med = material_medium(cid)
            regions[cid] = {
                "mu_s_prime_per_mm": med.sigma_s_prime * (1 + 0.1 * cid),
                "mu_s_prime_se_per_mm": 0.01,
                "mu_a_per_mm": np.nan if cid == 3 else med.sigma_a * (1 - 0.05 * cid),
                "mu_a_se_per_mm": 0.001,
            }
        return SimpleNamespace(regions=regions)

    def fake_stack_fit(stack, *, mm_per_row, labels, containers):  # a capture's stack: its images fitted
        seen.append((stack, mm_per_row, labels, "stack", containers))
        return SimpleNamespace(regions={})

    from planeray.materials import stackfit
    from planeray.stack import Stack

    monkeypatch.setattr(fit, "fit_transport", fake_fit)
    monkeypatch.setattr(stackfit, "fit_stack", fake_stack_fit)
    stack = Stack(np.zeros((2, 24, 24), np.float32), [0.0, 900.0], [600.0, 600.0], 54_000.0)
    out = media_fit_numbers(scene, {"truth": scene.transport, "other": "T", "cap": stack}, near_wall_mm=3.0)
    material = scene.maps["material"]
    trays = np.where((material >= 1) & (material <= 5), material, 0)
    away = np.where(scene.maps["wall_distance_mm"] >= 3.0, trays, 0)
    assert [s[0] for s in seen] == [scene.transport, "T", stack]
    assert [s[3] for s in seen] == [8, 8, "stack"]  # transports: 8-px blocks give each region's noise
    assert all(out["media"][name]["cap"]["mu_a_per_mm"] is None for name in MATERIAL_CLASSES.values())
    for _, mm, labels, _, containers in seen:
        assert mm == 0.3
        np.testing.assert_array_equal(labels, away)
        np.testing.assert_array_equal(containers, trays)
    assert 0 < (away > 0).sum() < (trays > 0).sum()
    for cid, name in MATERIAL_CLASSES.items():
        row = out["media"][name]["truth"]
        assert row["mu_s_prime_rel_err"] == pytest.approx(0.1 * cid)
        assert row["pixels"] == (away == cid).sum()
        if cid == 3:
            assert row["mu_a_per_mm"] is None and row["mu_a_rel_err"] is None
        else:
            assert row["mu_a_rel_err"] == pytest.approx(-0.05 * cid)
        assert out["media"][name]["published"]["mu_a_per_mm"] == material_medium(cid).sigma_a
    fig = measured_media_figure(out["media"], out=tmp_path / "m.png")
    assert len(fig.axes) == 2 and (tmp_path / "m.png").stat().st_size > 10_000


# ---------------------------------------------------------------- the stack's images fitted directly
STACK_SHAPE, STACK_PROJECTOR_ROWS = (16, 3), 90  # 5.625 projector rows per camera row (the materials scene's)
STACK_MEDIUM = (1.0, 0.01)  # mu_s', mu_a (1/mm)


def _homogeneous_scene(kernel, ambient_albedo):
    """Every pixel sees ``kernel`` (each bin's part on the projector holds its light: the edge rule)."""
    from planeray.scenes.base import Scene, scene_offsets
    from planeray.timing import RowGeometry
    from planeray.transport import Transport

    H, W = STACK_SHAPE
    geo = RowGeometry(H, STACK_PROJECTOR_ROWS)
    off = scene_offsets()
    cov = geo.coverage(np.arange(H)[:, None], off[None, :])
    dense = np.repeat((kernel[None, :] * cov)[:, None, :], W, axis=1).astype(np.float32)
    return Scene(
        "homogeneous", Transport(dense, off, geo), np.zeros((H, W), np.float32),
        np.full((H, W), ambient_albedo, np.float32), np.full((H, W), 2, np.uint8), params={"mm_per_row": MM},
    )  # fmt: skip


@pytest.fixture(scope="module")
def stacks(table):
    """Captures of one medium (its kernel from the table: exact for the model) and of a white card, by the
    simulated camera: noiseless and noisy (the paper's sweep, default camera and ambient light)."""
    from planeray.acquire import simulate_stack
    from planeray.scenes.base import footprint_kernel, scene_offsets
    from planeray.timing import paper_sweep

    off = scene_offsets()
    rpc = STACK_PROJECTOR_ROWS / STACK_SHAPE[0]
    k = fit.forward_kernel(*STACK_MEDIUM, offsets_rows=off, mm_per_row=MM, rows_per_camera_row=rpc, table=table)
    medium = _homogeneous_scene(k, float(k.sum()))
    white = _homogeneous_scene(0.99 * footprint_kernel(off, rpc), 0.99)
    sweep = paper_sweep()
    return dict(
        kernel_sum=float(k.sum()),
        clean=simulate_stack(medium, sweep, noise=False),
        noisy=simulate_stack(medium, sweep, seed=3),
        white_clean=simulate_stack(white, sweep, noise=False),
        white_noisy=simulate_stack(white, sweep, seed=4),
    )


def test_the_stack_model_is_what_the_simulated_camera_records(stacks, table):
    """The model's images against the simulator's (Transport.render through the bands, the camera's ambient)."""
    from planeray.camera import CameraModel
    from planeray.materials.stackfit import stack_design, stack_model_images

    st = stacks["clean"]
    cam = CameraModel()
    ambient = cam.ambient_e_per_us * stacks["kernel_sum"] * 1e6 / (st.lines_per_second * cam.full_well_e)
    design = stack_design(st)
    model = stack_model_images(
        st, *STACK_MEDIUM, mm_per_row=MM, scale=cam.signal_scale, ambient=ambient, table=table, design=design
    )
    images = np.asarray(st.images)[design.image_index]
    assert images.max() > 0.1
    for col in range(STACK_SHAPE[1]):
        np.testing.assert_allclose(model, images[:, :, col], rtol=1e-5, atol=1e-7)
    # the rows near the projector's ends differ (their bands are cut): the model follows them
    assert np.ptp(model, axis=1).max() > 0.05 * model.max()


def test_a_white_card_gives_the_cameras_scale(stacks):
    from planeray.camera import CameraModel
    from planeray.materials.stackfit import white_stack_scale

    scale = white_stack_scale(stacks["white_clean"], albedo=0.99)
    np.testing.assert_allclose(scale, CameraModel().signal_scale, rtol=1e-4)
    noisy = white_stack_scale(stacks["white_noisy"], albedo=0.99)
    assert np.median(noisy) == pytest.approx(CameraModel().signal_scale, rel=0.02)


@pytest.mark.parametrize("white", [False, True])
def test_the_stack_fit_recovers_a_noiseless_capture(stacks, table, white):
    from planeray.materials.stackfit import fit_stack

    w = stacks["white_clean"] if white else None
    res = fit_stack(stacks["clean"], mm_per_row=MM, white=w, table=table)
    r = res.regions[1]
    assert res.source == "stack" and res.calibrated == white
    assert r["mu_s_prime_per_mm"] == pytest.approx(STACK_MEDIUM[0], rel=0.005)
    assert r["mu_a_per_mm"] == pytest.approx(STACK_MEDIUM[1], rel=0.01)
    assert r["mask"] == 0 and r["ambient_per_row_exposure"] > 0
    assert np.all(res.maps["mu_s_prime_per_mm"] == np.float32(r["mu_s_prime_per_mm"]))


def test_the_stack_fit_of_a_noisy_capture_lies_within_its_standard_errors(stacks, table):
    from planeray.materials.stackfit import fit_stack

    for white in (stacks["white_noisy"], None):
        r = fit_stack(stacks["noisy"], mm_per_row=MM, white=white, table=table).regions[1]
        for key, truth in zip(("mu_s_prime", "mu_a"), STACK_MEDIUM):
            v, se = r[f"{key}_per_mm"], r[f"{key}_se_per_mm"]
            assert 0 < se < 0.3 * truth and abs(v - truth) < 3 * se, (white is None, key, v, se)


def test_the_stack_fit_says_why_a_parameter_is_not_identified(stacks, table):
    from planeray.materials.stackfit import fit_stack

    st = stacks["noisy"]
    labels = np.ones(STACK_SHAPE, int)
    labels[:, 2] = 2
    sat = np.zeros(np.shape(st.images), bool)
    sat[:, :, 2] = True  # region 2: every image saturated, no data
    from dataclasses import replace

    res = fit_stack(replace(st, saturated=sat), mm_per_row=MM, labels=labels, table=table, max_relative_se=0.08)
    r1, r2 = res.regions[1], res.regions[2]
    se_s, se_a = r1["log_se"]
    assert se_s < 0.08 < se_a  # region 1: mu_s' constrained to 8 %, mu_a not
    assert r1["mu_s_prime_per_mm"] is not None and r1["mu_a_per_mm"] is None and r1["mask"] == 16
    assert any("mu_a not constrained" in t for t in r1["not_identifiable"])
    assert r2["mu_s_prime_per_mm"] is None and r2["mask"] & 1 and np.isnan(res.maps["mu_a_per_mm"][:, 2]).all()


def test_the_command_fits_a_stack_through_its_images(stacks, tmp_path):
    import json

    from typer.testing import CliRunner

    from _new_user import run_bad, user_files
    from planeray.cli import app
    from planeray.io import write_stack, write_transport
    from planeray.transport import Transport

    write_stack(stacks["noisy"], tmp_path / "cap.zarr")
    write_stack(stacks["white_noisy"], tmp_path / "white.zarr")
    out = tmp_path / "fit"
    res = CliRunner().invoke(
        app, ["materials", "fit", str(tmp_path / "cap.zarr"), "--out", str(out), "--white-reference",
              str(tmp_path / "white.zarr")],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "stack fit" in res.output
    meta = json.loads((out / "planeray.json").read_text())
    assert meta["method"].startswith("stack") and "white reference" in meta["calibration"]
    r = meta["regions"]["1"]
    assert r["mu_s_prime_per_mm"] == pytest.approx(STACK_MEDIUM[0], rel=0.1)
    assert r["mu_a_per_mm"] == pytest.approx(STACK_MEDIUM[1], rel=0.25)
    assert (out / "fit.png").stat().st_size > 10_000
    write_transport(Transport(np.zeros((4, 4, 3), np.float32), np.arange(-1, 2)), tmp_path / "t.zarr")
    user_files(tmp_path / "u")
    for extra, option in (
        (["--method", "stacks"], "--method"),
        (["--white-reference", str(tmp_path / "t.zarr")], "--white-reference"),
    ):
        run_bad(["materials", "fit", tmp_path / "cap.zarr", "--out", "{d}/fit", *extra], folder=tmp_path / "u",
                option=option)  # fmt: skip
    run_bad(["materials", "fit", tmp_path / "t.zarr", "--out", "{d}/fit", "--method", "stack"],
            folder=tmp_path / "u", option="--method")  # fmt: skip


def _import_folder(stack, folder, **acquisition):
    """The stack as a user's import folder: its acquisition.json states the camera and ``acquisition``, no scene."""
    from dataclasses import asdict

    from planeray.camera import CameraModel
    from planeray.io import export_folder

    export_folder(stack, folder)
    path = folder / "acquisition.json"
    acq = json.loads(path.read_text())
    acq["planeray_metadata"] = {"camera": asdict(CameraModel())}
    acq.update(acquisition)
    path.write_text(json.dumps(acq))
    return folder


def test_the_row_size_comes_from_acquisition_json_and_is_never_assumed(stacks, tmp_path):
    """Issue 41: an import folder's acquisition.json states mm_per_row; the fit uses it (and says so), and a
    capture that states none is refused in one line -- no default stands in for it."""
    from typer.testing import CliRunner

    from planeray.cli import app

    stated = _import_folder(stacks["noisy"], tmp_path / "stated", mm_per_row=0.35)
    res = CliRunner().invoke(app, ["materials", "fit", str(stated), "--out", str(tmp_path / "fit")])
    assert res.exit_code == 0, res.output
    meta = json.loads((tmp_path / "fit" / "planeray.json").read_text())
    assert meta["mm_per_row"] == 0.35 and meta["mm_per_row_source"] == "acquisition.json"
    assert "reduced chi-square" in res.output and meta["regions"]["1"]["fit_quality"]["dof"] > 50
    assert "camera" in meta["noise_model"]
    silent = _import_folder(stacks["noisy"], tmp_path / "silent")
    res = CliRunner().invoke(app, ["materials", "fit", str(silent), "--out", str(tmp_path / "fit2")])
    assert res.exit_code == 1 and "mm_per_row" in res.output and "acquisition.json" in res.output
    assert len(res.output.strip().splitlines()) == 1 and not (tmp_path / "fit2").exists()


def test_a_cached_forward_table_is_reused_silently_and_a_missing_one_announced(monkeypatch, table, tmp_path):
    """--n of a table that is shipped or cached: no note; of one that is not: the note with the estimate from a
    pilot run, then a stage counted over its runs (here the tracing is a stand-in returning the shipped table)."""
    from planeray.experiments.materials_folders import forward_table
    from planeray.experiments.workflow import Stages

    calls = []
    monkeypatch.setattr(fit, "forward_table_stored", lambda **kw: kw["n"] == fit.DEFAULT_N)
    monkeypatch.setattr(fit, "forward_table_seconds", lambda **kw: 120.0)

    def trace(**kw):
        calls.append(kw)
        if kw.get("progress"):
            kw["progress"](fit.TABLE_RUNS)
        return table

    monkeypatch.setattr(fit, "forward_table", trace)
    events = []
    stages = Stages(lambda name, done, total: events.append(("progress", name, done, total)),
                    lambda text: events.append(("note", text)))  # fmt: skip

    forward_table(fit.DEFAULT_N, stages)
    assert events == [] and calls[-1] == {"n": fit.DEFAULT_N}
    forward_table(1.45, stages)
    notes = [i for i, e in enumerate(events) if e[0] == "note"]
    assert len(notes) == 1
    text = events[notes[0]][1]
    assert "no forward table for n = 1.45" in text and "about 2 minutes" in text and "pilot" in text
    tracing = [e for e in events[notes[0] :] if e[0] == "progress" and "tracing" in e[1]]
    assert tracing[-1][2:] == (fit.TABLE_RUNS, fit.TABLE_RUNS)  # announced first, then counted to the end
    assert calls[-1]["n"] == 1.45 and callable(calls[-1]["progress"])


def test_the_old_name_of_the_forward_kernel_warns_and_is_the_forward_kernel(table):
    """``materials.fit.line_kernel`` was renamed ``kernels.forward.forward_kernel`` (``pr.line_kernel`` is the
    scene kernel of a Medium, another function): the old name still answers, with a DeprecationWarning."""
    with pytest.warns(DeprecationWarning, match="forward_kernel"):
        old = fit.line_kernel(1.0, 0.01, offsets_rows=OFFSETS, mm_per_row=MM, table=table)
    np.testing.assert_array_equal(
        old, forward.forward_kernel(1.0, 0.01, offsets_rows=OFFSETS, mm_per_row=MM, table=table)
    )


def test_the_walls_model_error_is_in_the_transport_fits_covariance(table):
    """Profiles of a weakly absorbing medium beside walls, drawn as the fit's own model plus the walls' model error
    at its stated size -- their effect's size and distances (:func:`fit.wall_error_columns`, in the weights) and
    shape (:func:`fit.wall_shape_columns`, in the standard errors) -- and a little noise.  Without the shape error
    the chi-squares are of their degrees of freedom (the weights' covariance is the draws'); with it the standard
    errors cover the truth but once in eight; the same fit with the walls taken as exact flags the draws or misses."""
    rng = np.random.default_rng(3)
    u = np.arange(-80, 81)
    s, a = 0.9, 0.003  # 1/mm: a diffusion length (11 mm) longer than the walls' distances
    walls = np.array([[d, ang, side, 1.0 / 8] for d in (10.0, 30.0) for ang in (0.0, 90.0) for side in (1.0, -1.0)])
    x = np.log([s * MM, a * MM])
    foot = camera_row_footprint(1.0)
    k = fit.model_kernel(table, x[0], x[1], u, foot, walls, "clear")
    E = fit.wall_error_columns(table, x, u, foot, walls, "clear", effect_sd=fit.WALL_EFFECT_SD, bottom_sd=0.0)
    S = fit.wall_shape_columns(table, x, u, foot, walls, "clear", shape_sd=0.2, basis=fit.model_error_basis(u))
    sd = 0.002 * k.max()
    kw = dict(offsets_rows=u, mm_per_row=MM, sigma=sd, table=table, g=fit.DEFAULT_G, model_relative_sd=1e-6)
    chi2, z, z_exact, flagged_exact = [], [], [], 0
    for _ in range(8):
        y = k + E @ rng.normal(size=E.shape[1]) + sd * rng.normal(size=u.size)
        chi2.append(fit.fit_profiles(y, walls=[walls], wall_shape_sd=0.2, **kw).chi2_per_dof[0])
        y = y + S @ rng.normal(size=S.shape[1])
        r = fit.fit_profiles(y, walls=[walls], wall_shape_sd=0.2, **kw)
        z.append((np.log(r.mu_a_per_mm[0]) - np.log(a)) / r.log_se[0, 1])
        exact = fit.fit_profiles(y, walls=[walls], wall_effect_sd=0.0, bottom_effect_sd=0.0, wall_shape_sd=0.0, **kw)
        flagged_exact += int(exact.flags[0] & fit.FLAG_MISFIT > 0)
        if not exact.flags[0] & fit.FLAG_MISFIT:
            z_exact.append((np.log(exact.mu_a_per_mm[0]) - np.log(a)) / exact.log_se[0, 1])
    assert 0.5 < np.median(chi2) < 1.6, chi2
    # covered but for one draw of eight (NaN, not identifiable, counts as a miss): the shape error moves this
    # medium's mu_a by more than its linearization says (measured: 7 draws within 1.4, one at 7.2 -- the known
    # limit of a local standard error, in docs/user_guide/trust.md)
    assert np.sum(np.abs(z) < 3.0) >= 7, z
    # taken as exact, the walls' error is either flagged or read as a confident mu_a (measured: 2 flagged, 2 of the
    # other 6 beyond 2 standard errors, one at 22)
    assert flagged_exact + int(np.sum(np.abs(z_exact) > 2.0)) >= 3, (flagged_exact, z_exact)
