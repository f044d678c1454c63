"""Vein depth and diameter from a delay-exposure sweep (issue 27, part 3; planeray.skin.depth).

Ground truth: the skin scene's veins (depth of the top, diameter) and synthetic captures whose
answer is known; the contrast model is checked against the simulator's own images of the same
skin with and without the vein (the ratio cancels the skin's tint exactly).
"""

from __future__ import annotations

import numpy as np
import pytest

from planeray.camera import CameraModel
from planeray.experiments.skin_capture import simulate_skin
from planeray.goodness import FLAG_EDGE
from planeray.scenes.skin import skin_veins
from planeray.skin.depth import (
    background_signals,
    fit_vein,
    fit_veins,
    image_variance,
    row_jitter_sigma,
    usable_bands,
    vein_geometry,
    vein_model,
    vein_signals,
)
from planeray.timing import RowGeometry

SPECS = [(1.0, 3.0), (2.0, 2.0)]


def _veins(specs):
    return [
        dict(depth_mm=d, diameter_mm=D, points_mm=[[-10.0, 40.0 + 90.0 * i], [230.0, 48.0 + 90.0 * i]])
        for i, (d, D) in enumerate(specs)
    ]


def _truth_ids(scene):
    vid = np.zeros(scene.shape, int)
    for v in skin_veins(scene):
        vid[v.mask] = v.id
    return vid


@pytest.fixture(scope="module")
def noiseless():
    cam = CameraModel(ambient_e_per_us=0.0, row_jitter_us=0.0)
    with_vein = simulate_skin(None, size=(128, 128), seed=3, veins=_veins(SPECS), camera=cam, noise=False)
    without = simulate_skin(None, size=(128, 128), seed=3, veins=[], camera=cam, noise=False)
    return with_vein, without


def test_contrast_model_is_the_simulators_vein_over_no_vein_ratio(noiseless):
    """1 - C_k from the model equals the simulated image with the vein over the image without it."""
    cap, bare = noiseless
    st = cap.stack
    use = usable_bands(st.bands(), st.geometry, excluded=st.excluded)
    idx = np.nonzero(use)[0]
    assert idx.size >= 5
    model = vein_model([st.bands()[i] for i in idx], st.geometry, mm_per_row=0.3)
    truth = skin_veins(cap.scene)
    for v in truth:
        others = np.zeros(st.shape, bool)
        pix = vein_geometry(v.mask, others, st.geometry, mm_per_row=0.3, reach_mm=10.0)
        # the true signed distance of each pixel from the vein's axis (a straight segment), mm
        p0, p1 = np.asarray(v.points_mm[0]), np.asarray(v.points_mm[-1])
        a = np.degrees(np.arctan2(p1[0] - p0[0], p1[1] - p0[1])) % 180.0
        x = (st.geometry.projector_row_of(pix.rows) + 0.5) * 0.3
        y = (pix.cols + 0.5) * st.geometry.projector_rows * 0.3 / st.shape[0]
        rho = (x - p0[0]) * np.cos(np.radians(a)) - (y - p0[1]) * np.sin(np.radians(a))
        ratio, _ = vein_signals(model, pix.rows, rho, np.full(rho.size, a), v.depth_mm, v.diameter_mm)
        sim = np.stack([np.asarray(st.images[i], float) for i in idx])[:, pix.rows, pix.cols]
        ref = np.stack([np.asarray(bare.stack.images[i], float) for i in idx])[:, pix.rows, pix.cols]
        lit = ref > 1e-6
        measured = np.divide(sim, ref, out=np.full(sim.shape, np.nan), where=lit)
        err = np.abs(measured - ratio)[lit & np.isfinite(ratio)]
        assert lit.mean() > 0.8 and err.size > 0.8 * lit.size
        assert err.max() < 2e-3, (v.id, err.max())
        assert np.nanmin(ratio) < 0.8  # the vein is there: a test that cannot pass trivially


def test_fit_recovers_depth_and_diameter_from_a_noiseless_capture(noiseless):
    cap, _ = noiseless
    st = cap.stack
    cam = CameraModel(**st.metadata["camera"])
    fits, _, _ = fit_veins(
        st.images,
        st.bands(),
        st.geometry,
        _truth_ids(cap.scene),
        camera=cam,
        excluded=st.excluded,
        mm_per_row=0.3,
        ambient=False,
        joint_rounds=0,  # 90 mm apart: no shadow of one reaches the other
    )
    edge, inside = fits
    # the vein 1 mm deep lies at the tables' shallow edge: found there, flagged and not reported (issue 41)
    assert not edge.resolved and edge.flags & FLAG_EDGE and "shallowest" in edge.reason, edge.reason
    assert np.isnan(edge.depth_mm) and abs(edge.fit_depth_mm - 1.0) < 0.1
    v = skin_veins(cap.scene)[1]
    assert inside.resolved and inside.flags == 0, inside.reason
    assert inside.model_fits
    assert abs(inside.depth_mm - v.depth_mm) < 0.15, (inside.depth_mm, v.depth_mm)
    assert abs(inside.diameter_mm - v.diameter_mm) < 0.5, (inside.diameter_mm, v.diameter_mm)


def _row_spread(row_jitter_us):
    """Excess variance of the camera-row means of flat skin's short-range images (noisy over noiseless
    capture of the same skin, shot noise of the row means subtracted), and row_jitter_sigma squared,
    pooled over the images whose row means' shot noise is below half the predicted sigma."""
    cam = CameraModel(ambient_e_per_us=0.0, row_jitter_us=row_jitter_us)
    noisy = simulate_skin(None, size=(128, 24), seed=5, veins=[], camera=cam).stack
    clean = simulate_skin(None, size=(128, 24), seed=5, veins=[], camera=cam, noise=False).stack
    idx = np.nonzero(usable_bands(noisy.bands(), noisy.geometry, excluded=noisy.excluded))[0]
    model = vein_model([noisy.bands()[i] for i in idx], noisy.geometry, mm_per_row=0.3)
    sigma = row_jitter_sigma(model, CameraModel(row_jitter_us=10.0))  # the default device's
    excess, predicted = [], []
    for k, i in enumerate(idx):
        a, b = (np.asarray(st.images[i], float)[8:-8] for st in (noisy, clean))  # away from the projector's ends
        rel = a.mean(axis=1) / b.mean(axis=1) - 1.0
        shot = np.mean(image_variance(b, cam).sum(axis=1) / b.shape[1] ** 2 / b.mean(axis=1) ** 2)
        if np.sqrt(shot) < 0.5 * sigma[k]:
            excess.append(rel.var() - shot)
            predicted.append(sigma[k] ** 2)
    assert len(excess) >= 4
    return np.sum(excess) / np.sum(predicted)


def test_row_jitter_sigma_is_the_spread_of_the_row_means_of_flat_skin():
    """The device's row jitter (10 us per frame and camera row) moves a whole camera row's band: the row
    means of a short-range image of flat skin scatter by row_jitter_sigma (variance ratio 1 +- 0.25: ~5
    standard errors of a variance pooled over >= 4 images of 112 rows); without the jitter they do not."""
    assert 0.75 < _row_spread(10.0) < 1.33
    assert _row_spread(0.0) < 0.1


# ---------------------------------------------------------------- synthetic captures from the model
GEOM = RowGeometry(128, 720)
Y0_MM = 101.0  # the vein's axis runs down the image (angle 90 deg to the rows) at y = 101 mm


def _synthetic(depth_mm, diameter_mm, seed, *, vein=True, noise=True):
    """Images of a straight vein down the image: B_k (1 - C_k(rho)) x a smooth tint, with camera noise."""
    from planeray.timing import paper_sweep

    sweep = paper_sweep()
    bands = sweep.bands(54_000.0, jitter_us=5.0)
    use = usable_bands(bands, GEOM, excluded=sweep.excluded)
    bands = [b for b, u in zip(bands, use) if u]
    model = vein_model(bands, GEOM, mm_per_row=0.3)
    H, W = 128, 128
    col_mm = 720 * 0.3 / H
    rows = np.repeat(np.arange(H), W)
    y = (np.tile(np.arange(W), H) + 0.5) * col_mm
    rho = -(y - Y0_MM)
    sel = np.abs(rho) < 20.0
    ratio = np.ones((len(bands), H * W))
    if vein:
        ratio[:, sel], _ = vein_signals(model, rows[sel], rho[sel], np.full(sel.sum(), 90.0), depth_mm, diameter_mm)
    ratio = np.nan_to_num(ratio, nan=1.0)
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W]
    tint = 1.0 + 0.03 * np.sin(2 * np.pi * (xx / 97.0 + yy / 131.0) + seed)
    bg = 0.6 * background_signals(model, np.arange(H))  # (K, H): laser electrons / full well = 0.6
    images = bg[:, :, None] * ratio.reshape(len(bands), H, W) * tint[None]
    cam = CameraModel()
    var = image_variance(images, cam)
    if noise:
        images = images + rng.normal(0.0, np.sqrt(var))
    mask = (np.abs(rho) <= 0.5 * diameter_mm).reshape(H, W) & (yy >= 20) & (yy < 108)
    pix = vein_geometry(mask, np.zeros((H, W), bool), GEOM, mm_per_row=0.3)
    return model, images, var, pix


@pytest.mark.parametrize(("depth_mm", "diameter_mm"), [(1.5, 3.0), (2.5, 2.0)])
def test_fit_recovers_a_known_vein_from_a_noiseless_synthetic_capture(depth_mm, diameter_mm):
    model, images, var, pix = _synthetic(depth_mm, diameter_mm, 0, noise=False)
    f = fit_vein(model, images, var, pix, ambient=False, max_pixels=250)
    assert f.resolved, f.reason
    assert abs(f.depth_mm - depth_mm) < 0.2
    assert abs(f.diameter_mm - diameter_mm) < 0.6


def test_noisy_fit_recovers_depth_within_its_standard_error():
    errs, ses = [], []
    for seed in range(3):
        model, images, var, pix = _synthetic(2.0, 3.0, seed)
        f = fit_vein(model, images, var, pix, ambient=False, max_pixels=250)
        assert f.resolved, f.reason
        errs.append(f.depth_mm - 2.0)
        ses.append(f.depth_se_mm)
    errs, ses = np.array(errs), np.array(ses)
    assert np.all(np.abs(errs) < 4.0 * ses + 0.1), (errs, ses)
    assert np.all(np.abs(errs) < 0.5)


def test_a_mask_over_skin_without_a_vein_is_reported_not_detected():
    model, images, var, pix = _synthetic(2.0, 3.0, 0, vein=False)
    f = fit_vein(model, images, var, pix, ambient=False, max_pixels=250)
    assert not f.resolved
    assert "not detected" in f.reason
    assert np.isnan(f.depth_mm) and np.isnan(f.diameter_mm)
    assert f.to_json()["depth_mm"] is None


@pytest.mark.slow
def test_contrast_model_against_brute_force_monte_carlo_of_a_vein():
    """The fit's contrast model (perturbation tables) against brute force: blood in the medium with its own
    scattering (mc_vein_kernel_brute), a pixel over a vein 1 mm deep, 2 mm wide, across the rows, the
    500 us / 200 us band through the camera row's footprint; tolerance 10 % (the documented model error in
    this regime) + 3 standard errors of the brute-force contrast (20,000 photons: contrast 0.79 +- 0.025
    against the model's 0.81, a tolerance of 0.15; 0.83 +- 0.015 at 40,000)."""
    from planeray.mc.layered import mc_layered_profile, mc_vein_kernel_brute
    from planeray.optical_data_skin import skin_layers
    from planeray.scenes.base import footprint_kernel
    from planeray.timing import Band

    band = Band(500.0, 200.0, 54_000.0)
    geom = RowGeometry(128, 720)
    model = vein_model([band], geom, mm_per_row=0.3)
    fast = 1.0 - vein_signals(model, [64], [0.0], [90.0], 1.0, 2.0)[0][0, 0]

    skin = skin_layers(638, "fair")
    n = 20_000
    brute = mc_vein_kernel_brute(skin.layers, skin.blood, depth_mm=1.0, diameter_mm=2.0, angle_deg=90.0, n_photons=n)
    plain = mc_layered_profile(skin.layers, n_photons=n, offsets_rows=brute.offsets_rows, mm_per_row=0.3)
    u = brute.offsets_rows
    rpc = geom.rows_per_camera_row
    half = int(np.ceil(0.5 * rpc + 0.5))
    foot = footprint_kernel(np.arange(-half, half + 1), rpc)
    w = band.profile(u)
    vein = np.convolve(brute.values, foot, mode="same") @ w
    bare = np.convolve(plain.values, foot, mode="same") @ w
    contrast = 1.0 - vein / bare
    # standard error of the ratio from the two kernels' batch errors (independent runs)
    se = (vein / bare) * np.hypot(
        np.sqrt(np.convolve(brute.stderr**2, foot**2, mode="same") @ w**2) / vein,
        np.sqrt(np.convolve(plain.stderr**2, foot**2, mode="same") @ w**2) / bare,
    )
    assert fast > 0.5  # a strong vein: the comparison means something
    assert abs(fast - contrast) <= 0.1 * contrast + 3.0 * se, (fast, contrast, se)


def test_neighbouring_veins_are_fitted_with_each_others_shadows():
    """Two veins 11 mm apart (noiseless capture): the deeper one's fit, alone, takes in its neighbour's shadow
    (2.21 mm for 2.5, diameter at the tables' 1 mm, when measured); refitted with the neighbour's estimate
    multiplied in, both come out right (2.53 and 1.51 mm)."""
    cam = CameraModel(ambient_e_per_us=0.0, row_jitter_us=0.0)
    veins = [
        dict(depth_mm=1.5, diameter_mm=3.0, points_mm=[[-10.0, 90.0], [230.0, 100.0]]),
        dict(depth_mm=2.5, diameter_mm=2.0, points_mm=[[-10.0, 101.0], [230.0, 111.0]]),
    ]
    cap = simulate_skin(None, size=(128, 128), seed=3, veins=veins, camera=cam, noise=False)
    st = cap.stack
    fits, _, _ = fit_veins(
        st.images,
        st.bands(),
        st.geometry,
        cap.scene.maps["vein_id"],
        camera=cam,
        excluded=st.excluded,
        mm_per_row=0.3,
        ambient=False,
        guard_mm=3.0,
        joint_rounds=1,
        max_pixels=300,
    )
    for f, v in zip(fits, veins):
        assert f.resolved, f.reason
        assert abs(f.depth_mm - v["depth_mm"]) < 0.1, (f.id, f.depth_mm)


# ---------------------------------------------------------------- the fit's two small linear solves
def _arrow(d, e, s):
    K = d.size
    M = np.zeros((K + 1, K + 1))
    M[np.arange(K), np.arange(K)] = d
    M[:K, K] = M[K, :K] = e
    M[K, K] = s
    return M


def _normal_equations(rng, K, n, *, ambient, zero_image=None, ambient_like_image=None):
    """The weighted normal equations of backgrounds B_k (one column per image) and one ambient column."""
    cols = rng.uniform(0.5, 1.5, (K, n))
    amb = rng.uniform(0.0, 2.0, (K, n)) * ambient
    if zero_image is not None:
        cols[zero_image] = 0.0
    if ambient_like_image is not None:  # an ambient column the backgrounds can imitate exactly
        amb[:] = 0.0
        amb[ambient_like_image] = 3.0 * cols[ambient_like_image]
    w = rng.uniform(0.2, 1.0, (K, n))
    data = rng.normal(size=(K, n))
    d, e = np.sum(w * cols * cols, axis=1), np.sum(w * cols * amb, axis=1)
    s, b, c = float(np.sum(w * amb * amb)), np.sum(w * cols * data, axis=1), float(np.sum(w * amb * data))
    return d, e, s, b, c


@pytest.mark.parametrize(
    "case",
    [
        dict(ambient=1.0),
        dict(ambient=0.0),  # no ambient light fitted: lstsq's minimum-norm A = 0
        dict(ambient=1e-9),  # an ambient column far below the backgrounds'
        dict(ambient=1.0, zero_image=2),  # an image without light: its B_k = 0
        dict(ambient=1.0, ambient_like_image=1),  # the ambient column is one image's own: singular
    ],
    ids=["ambient", "none", "faint", "dark-image", "imitated"],
)
def test_the_arrow_solve_is_lstsqs_minimum_norm_solution(case):
    """The background-and-ambient solve (O(K) by the Schur complement) against LAPACK's least squares."""
    from planeray.skin.depth import _arrow_solve

    rng = np.random.default_rng(7)
    for K in (1, 5, 40):
        if K <= 2 and ("zero_image" in case or "ambient_like_image" in case):
            continue
        d, e, s, b, c = _normal_equations(rng, K, 300, **case)
        B, A = _arrow_solve(d, e, s, b, c)
        ref = np.linalg.lstsq(_arrow(d, e, s), np.concatenate([b, [c]]), rcond=None)[0]
        # (an ambient column below lstsq's cutoff: lstsq keeps an A of ~e / d times the backgrounds, ~1e-9)
        np.testing.assert_allclose(np.append(B, A), ref, rtol=0, atol=1e-8 * np.abs(ref).max())


def test_the_tint_solve_is_lstsqs_solution_and_its_minimum_norm_one_when_singular():
    from planeray.skin.depth import _spd_solve

    rng = np.random.default_rng(3)
    phi = rng.normal(size=(300, 24))
    q = rng.uniform(0.1, 1.0, 300)
    N, rhs = phi.T @ (q[:, None] * phi), phi.T @ rng.normal(size=300)
    np.testing.assert_allclose(_spd_solve(N, rhs), np.linalg.solve(N, rhs), rtol=1e-10)
    # a column repeated (a knot whose pixels lie on one line across the vein): singular, the minimum-norm answer
    phi[:, 5] = phi[:, 4]
    N, rhs = phi.T @ (q[:, None] * phi), phi.T @ rng.normal(size=300)
    x = _spd_solve(N, rhs)
    ref = np.linalg.lstsq(N, rhs, rcond=None)[0]
    np.testing.assert_allclose(x, ref, rtol=0, atol=1e-8 * np.abs(ref).max())
    assert abs(x[4] - x[5]) < 1e-8 * np.abs(ref).max()


def test_the_backgrounds_of_another_skin_model_are_flagged():
    """Issue 41: the images' vein-free backgrounds B_k must follow the skin model's kernel through the sweep.
    Backgrounds of the model itself (1 % noise) pass; those of a skin whose dermis is 5 mm thick -- an
    independent Monte Carlo of those layers -- do not (the light of the clear dermis reaches farther)."""
    import dataclasses

    from planeray.mc.layered import mc_layered_profile
    from planeray.optical_data_skin import skin_layers
    from planeray.skin.depth import _background_quality, bands_of
    from planeray.timing import paper_sweep

    geom = RowGeometry(64, 360)
    sweep = paper_sweep()
    bands = bands_of(sweep.delay_us, sweep.exposure_us, 54_000)
    bands = [b for b, u in zip(bands, usable_bands(bands, geom)) if u]
    model = vein_model(bands, geom, mm_per_row=0.3)  # fair skin, 638 nm, dermis 1.5 mm (shipped tables)
    s0 = background_signals(model, [32])[:, 0]
    rng = np.random.default_rng(1)
    same = 3.0 * s0 * (1.0 + 0.01 * rng.standard_normal(s0.size))
    q, curve = _background_quality(model, same, (0.01 * same) ** 2, 0.03, 1e-3)
    assert q.fits and len(bands) >= 8 and np.isfinite(curve["log_scale"])
    thick = skin_layers(638, "fair", dermis_mm=5.0).layers
    k5 = mc_layered_profile(thick, n_photons=5_000, offsets_rows=model.table.offsets_rows, mm_per_row=0.3, seed=7)
    other = 3.0 * background_signals(dataclasses.replace(model, kernel=k5.values), [32])[:, 0]
    q5, _ = _background_quality(model, other, (0.01 * other) ** 2, 0.03, 1e-3)
    assert not q5.fits and q5.reduced_chi2 > 10 * q5.threshold
