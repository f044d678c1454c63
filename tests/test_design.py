"""Sweep design (:mod:`planeray.design`): the criterion against a Monte Carlo of the estimator it describes,
its rank-one updates against direct evaluation, the selection against an exhaustive search of a tiny
problem, the camera's noise formula against its simulated frames, candidates the camera can realize,
reproducibility and the record a sweep file keeps."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from planeray.camera import CameraModel
from planeray.design import (
    Candidates,
    DesignCamera,
    ExpectedError,
    TransportPrior,
    band_rows,
    candidate_settings,
    design_sweep,
    expected_error,
    image_variance,
    transport_prior,
)
from planeray.design.candidates import LIT
from planeray.errors import InputError
from planeray.timing import boundary_images

LPS = 54_000.0
ROW_US = 1e6 / LPS
#: A prior on which greedy selection alone misses the optimum of 4 of the 18 tiny candidates.
SEED_GREEDY_MISSES = 0


def _prior(K=14, n=400, seed=0) -> tuple[TransportPrior, np.ndarray]:
    """A prior of random non-negative transports on -K..K: a spike near 0 and a one-sided tail."""
    rng = np.random.default_rng(seed)
    u = np.arange(-K, K + 1, dtype=float)
    X = rng.uniform(0.05, 0.5, (n, 1)) * np.exp(-0.5 * (u / rng.uniform(0.6, 1.5, (n, 1))) ** 2)
    X += rng.uniform(0.0, 0.05, (n, 1)) * np.exp(-np.abs(u) / rng.uniform(1.0, 5.0, (n, 1)))
    return TransportPrior(u.astype(int), X.T @ X / n, X.mean(axis=0), 0.5, n, {"sources": ["test"]}), X


def _tiny_candidates(K=14) -> Candidates:
    """18 settings of a support of +-14 rows: every offset can be seen."""
    return candidate_settings(DesignCamera(), support_rows=K, exposure_range_us=(150.0, 400.0),
                              exposure_step_us=2 * ROW_US, delay_step_us=2 * ROW_US)  # fmt: skip


def test_the_criterion_is_the_mean_squared_error_of_the_linear_estimator_by_monte_carlo():
    prior, X = _prior()
    cands = _tiny_candidates()
    cam = DesignCamera(model=CameraModel(read_noise_e=1500.0, frames_averaged=1))  # noise that matters
    var = image_variance(cands.rows, cands.exposure_us, prior, cam)
    chosen = list(range(0, len(cands), max(1, len(cands) // 9)))[:9]
    alpha = 0.05
    value = ExpectedError(cands.rows, var, prior.second_moment, alpha=alpha).value(chosen)
    # the estimator itself, written out here: x_hat = (A^T A + alpha D^T D + eps I)^-1 A^T b
    A = cands.rows[chosen]
    U = A.shape[1]
    D = np.diff(np.eye(U), axis=0)
    M = np.linalg.solve(A.T @ A + alpha * D.T @ D + 1e-6 * np.eye(U), A.T)
    rng = np.random.default_rng(1)
    errors = []
    for _ in range(40):
        b = X @ A.T + rng.normal(0.0, np.sqrt(var[chosen]), (len(X), len(chosen)))
        errors.append(np.mean(np.sum((b @ M.T - X) ** 2, axis=1)))
    mc = float(np.mean(errors))
    assert value == pytest.approx(mc, rel=0.03)
    # and noise matters here: without it the error is clearly smaller
    quiet = ExpectedError(cands.rows, var * 0, prior.second_moment, alpha=alpha).value(chosen)
    assert quiet < 0.8 * value


@pytest.mark.parametrize("criterion", ["mse", "bayes-a", "bayes-d"])
def test_rank_one_updates_equal_direct_evaluation(criterion):
    prior, _ = _prior()
    cands = _tiny_candidates()
    var = image_variance(cands.rows, cands.exposure_us, prior, DesignCamera())
    crit = ExpectedError(cands.rows, var, prior.second_moment, criterion=criterion)
    chosen = [3, 9, 14]
    d = crit.deltas(chosen)
    base = crit.value(chosen)
    direct = np.array([crit.value(chosen + [c]) - base if c not in chosen else np.inf for c in range(len(cands))])
    finite = np.isfinite(direct)
    np.testing.assert_allclose(d[finite], direct[finite], rtol=1e-6, atol=1e-12 * abs(base))
    assert np.all(np.isinf(d[~finite]))


def _exhaustive(crit, lit, k):
    need = lit.any(axis=0)
    best = None
    for subset in itertools.combinations(range(lit.shape[0]), k):
        if (need & ~lit[list(subset)].any(axis=0)).any():
            continue  # not every offset seen
        v = crit.value(subset)
        if best is None or v < best[0]:
            best = (v, set(subset))
    return best


def test_a_tiny_design_finds_the_exhaustive_optimum():
    prior, _ = _prior(seed=3)
    full = _tiny_candidates()
    assert len(full) == 18 and full.lit.any(axis=0).all()
    k = 4
    var = image_variance(full.rows, full.exposure_us, prior, DesignCamera())
    crit = ExpectedError(full.rows, var, prior.second_moment)
    optimum, chosen = _exhaustive(crit, full.lit, k)  # 3060 subsets
    result = design_sweep(k, prior=prior, candidates=full)
    got = {int(np.flatnonzero((full.delay_us == d) & (full.exposure_us == e))[0])
           for d, e in zip(result.sweep.delay_us, result.sweep.exposure_us)}  # fmt: skip
    assert result.criterion_value == pytest.approx(optimum, rel=1e-9)
    assert got == chosen
    assert full.lit[list(got)].any(axis=0).all()  # every offset of the support is seen


def test_greedy_alone_misses_an_optimum_the_exchanges_find():
    """The exchange passes matter: on this problem greedy selection (and coverage) alone stops above the optimum."""
    prior, _ = _prior(seed=SEED_GREEDY_MISSES)
    full = _tiny_candidates()
    var = image_variance(full.rows, full.exposure_us, prior, DesignCamera())
    optimum, _ = _exhaustive(ExpectedError(full.rows, var, prior.second_moment), full.lit, 4)
    greedy = design_sweep(4, prior=prior, candidates=full, max_passes=0)
    assert greedy.criterion_value > optimum * (1 + 1e-6)
    assert design_sweep(4, prior=prior, candidates=full).criterion_value == pytest.approx(optimum, rel=1e-9)


def test_the_noise_formula_is_the_simulated_cameras():
    cam = CameraModel(frames_averaged=4)
    rng = np.random.default_rng(0)
    signal = np.full((300, 300), 0.2)
    albedo = np.full((300, 300), 0.7)
    image, _ = cam.expose(signal, 900.0, rng, ambient_albedo=albedo)
    assert float(image.var()) == pytest.approx(cam.image_variance(0.2, 900.0, ambient_albedo=0.7), rel=0.02)
    # more frames, less variance; ambient light adds shot noise
    assert CameraModel(frames_averaged=8).image_variance(0.2, 900.0) < cam.image_variance(0.2, 900.0)
    assert cam.image_variance(0.2, 900.0, ambient_albedo=1.0) > cam.image_variance(0.2, 900.0)


def test_candidates_are_on_the_cameras_steps_inside_its_range_and_never_boundary_images():
    cam = DesignCamera(exposure_range_us=(100.0, 700.0), exposure_step_us=25.0, delay_step_us=4.0)
    c = candidate_settings(cam, support_rows=40, exposure_range_us=(50.0, 2000.0))
    assert c.exposure_us.min() >= 100.0 and c.exposure_us.max() <= 700.0
    np.testing.assert_allclose((c.exposure_us - 100.0) / 25.0, np.round((c.exposure_us - 100.0) / 25.0), atol=1e-9)
    np.testing.assert_allclose(c.delay_us / 4.0, np.round(c.delay_us / 4.0), atol=1e-9)
    assert not boundary_images(c.delay_us, c.exposure_us).any()
    reach = np.abs(c.delay_us) * LPS * 1e-6 + 0.5 * c.exposure_us * LPS * 1e-6
    assert reach.max() <= 40 + 1e-9
    # a candidate's row is its band: it sums to its width in rows (inside the support)
    np.testing.assert_allclose(c.rows.sum(axis=1), c.exposure_us * LPS * 1e-6, rtol=1e-3)  # jitter tails cut
    assert (c.lit == (c.rows >= LIT)).all()
    with pytest.raises(InputError, match="no exposure both in"):
        candidate_settings(cam, exposure_range_us=(800.0, 900.0))


def test_a_design_is_reproducible_and_records_its_prior_camera_and_criterion(tmp_path):
    from planeray.io import read_sweep, write_sweep

    kw = dict(shape=(24, 24), projector_rows=135, support_rows=20, pixels=120, seed=5)
    cam = DesignCamera(model=CameraModel(frames_averaged=12))
    cands = candidate_settings(cam, support_rows=20, exposure_range_us=(150.0, 600.0), exposure_step_us=2 * ROW_US)
    a = design_sweep(6, prior=transport_prior(["wax", "corner"], **kw), camera=cam, candidates=cands)
    b = design_sweep(6, prior=transport_prior(["wax", "corner"], **kw), camera=cam, candidates=cands)
    np.testing.assert_array_equal(a.sweep.delay_us, b.sweep.delay_us)
    np.testing.assert_array_equal(a.sweep.exposure_us, b.sweep.exposure_us)
    path = write_sweep(a.sweep, tmp_path / "d.json")
    rec = read_sweep(path).record
    assert rec["prior"]["sources"] == ["wax", "corner"] and rec["prior"]["seed"] == 5
    assert rec["camera"]["model"]["frames_averaged"] == 12 and rec["camera"]["source"] == "default"
    assert rec["criterion"]["name"] == "mse" and rec["criterion"]["alpha"] == 0.01
    assert rec["criterion"]["expected_relative_error"] == pytest.approx(a.expected_error)
    # the expected error of the file's sweep, recomputed, is the recorded one
    again = expected_error(read_sweep(path), prior=transport_prior(["wax", "corner"], **kw), camera=cam)
    assert again == pytest.approx(a.expected_error, rel=1e-9)
    assert not a.sweep.excluded.any() and not boundary_images(a.sweep.delay_us, a.sweep.exposure_us).any()


def test_band_rows_are_the_demultiplexers_matrix():
    """A candidate's row is the row of DemuxProblem's interior matrix for the same image."""
    from planeray.demux import DemuxProblem
    from planeray.stack import Stack
    from planeray.timing import quick_sweep

    q = quick_sweep()
    st = Stack(np.zeros((len(q), 64, 2), np.float32), q.delay_us, q.exposure_us, LPS, excluded=q.excluded,
               projector_rows=720, metadata={"sync": {"jitter_us": 5.0}})  # fmt: skip
    p = DemuxProblem.from_stack(st)
    g = p.groups[int(np.bincount(p.row_group).argmax())]
    used = ~q.excluded
    rows = band_rows(q.delay_us[used], q.exposure_us[used], p.offsets_rows, lines_per_second=LPS, jitter_us=5.0)
    np.testing.assert_allclose(g.A, rows[:, g.valid], atol=1e-12)


def test_impossible_designs_are_refused_in_one_line():
    prior, _ = _prior(n=50)
    few = candidate_settings(
        DesignCamera(), support_rows=14, exposure_range_us=(150.0, 170.0), delay_step_us=8 * ROW_US
    )
    with pytest.raises(InputError, match="at least 4 images"):
        design_sweep(3, prior=prior, candidates=few)
    with pytest.raises(InputError, match="cannot see every offset|candidate settings"):
        design_sweep(4, prior=prior, candidates=few)
    with pytest.raises(InputError, match="not a transport store and not a scene name"):
        transport_prior(["no_such_scene"])
