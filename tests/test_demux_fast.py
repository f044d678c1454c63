"""The fast solver's paths: saturated pixels in the batch (Woodbury), pixels whose penalty
moved along the ladder, batches split over threads, pixels without any usable
observation -- each against an independent reference (CVXPY, or the problem
re-factorized on the pixel's own rows)."""

import numpy as np
import pytest

from planeray.acquire import simulate_stack
from planeray.camera import CameraModel
from planeray.demux import DemuxProblem, RowGroup, demultiplex, fast, solve_chunk, solve_fast
from planeray.demux.driver import read_observations
from planeray.demux.fast import AdmmRowSolver
from planeray.scenes import make_scene
from planeray.stack import Stack
from planeray.timing import paper_sweep


@pytest.fixture(scope="module")
def saturated_stack():
    """Wax under a bright laser: bright pixels saturate where the band covers their peak."""
    scene = make_scene("wax", (32, 24), projector_rows=360, seed=3)
    cam = CameraModel(laser_electrons=40_000.0, ambient_e_per_us=0.0, read_noise_e=2.0)
    stack = simulate_stack(scene, paper_sweep(), camera=cam, seed=3)
    used = stack.saturated[~stack.excluded]
    assert 0.02 < used.mean() < 0.5 and used.any(axis=0).mean() > 0.2  # a real mix of dropped rows
    return stack


def _rows(stack, problem, row):
    obs, sat = read_observations(stack, problem, slice(row, row + 1))
    return problem.groups[problem.row_group[row]], obs[:, 0].T, ~sat[:, 0].T


def test_saturated_pixels_agree_with_cvxpy_on_the_remaining_observations(saturated_stack):
    pytest.importorskip("cvxpy")
    from planeray.demux import solve_cvxpy

    problem = DemuxProblem.from_stack(saturated_stack)
    gaps = []
    for row in (2, 15, 30):  # edge rows (fewer offsets) and interior rows
        group, B, mask = _rows(saturated_stack, problem, row)
        res = solve_fast(group, B, mask=mask)
        dropped = np.flatnonzero(~mask.all(axis=1) & mask.any(axis=1))
        assert dropped.size >= 3
        assert res.converged[dropped].all()
        for p in dropped[:6]:
            sub = RowGroup(group.rows, group.A[mask[p]], group.valid, group.on_projector)
            ref = solve_cvxpy(sub, B[p : p + 1, mask[p]]).X
            f_ref = problem.objective(sub, ref, B[p : p + 1, mask[p]])[0]
            f_fast = problem.objective(group, res.X[p : p + 1], B[p : p + 1], mask[p : p + 1])[0]
            gaps.append((f_fast - f_ref) / f_ref)
    gaps = np.array(gaps)
    # certified per pixel to 1e-4 (negative: planeray lower -- Clarabel stops a little early)
    assert gaps.max() <= 1.2e-4, gaps
    assert np.median(gaps) <= 1e-4


def test_woodbury_update_equals_refactorizing_the_pixels_rows(saturated_stack):
    """Dropping rows by the low-rank correction solves the same problem as a new factorization."""
    problem = DemuxProblem.from_stack(saturated_stack)
    group, B, mask = _rows(saturated_stack, problem, 15)
    pick = np.concatenate([np.flatnonzero(~mask.all(axis=1))[:3], np.flatnonzero(mask.all(axis=1))[:2]])
    B, mask = B[pick], mask[pick]
    batch = AdmmRowSolver(group.A, problem.alpha, problem.beta).solve(B, 1e-5, mask=mask)
    X, conv = batch[0], batch[2]
    for p in np.flatnonzero(~mask.all(axis=1))[:3]:
        own = AdmmRowSolver(group.A[mask[p]], problem.alpha, problem.beta).solve(B[p : p + 1, mask[p]], 1e-5)
        sub = RowGroup(group.rows, group.A[mask[p]], group.valid, group.on_projector)
        f_batch = problem.objective(sub, X[p : p + 1], B[p : p + 1, mask[p]])[0]
        f_own = problem.objective(sub, own[0], B[p : p + 1, mask[p]])[0]
        assert conv[p] and own[2][0]
        assert abs(f_batch - f_own) <= 2e-5 * f_own  # both certified within 1e-5 of the optimum
    # the dropped observations really are ignored: changing them changes nothing
    B2 = np.where(mask, B, 123.0)
    X2 = AdmmRowSolver(group.A, problem.alpha, problem.beta).solve(B2, 1e-5, mask=mask)[0]
    np.testing.assert_allclose(X2, X, atol=1e-9)


def test_batches_threads_and_penalty_moves_reach_the_same_certified_gap(saturated_stack):
    """The same pixels alone, in one batch, or in batches over two threads: one optimum."""
    problem = DemuxProblem.from_stack(saturated_stack)
    rows = slice(12, 20)  # interior rows: one row group
    obs, sat = read_observations(saturated_stack, problem, rows)
    group = problem.groups[problem.row_group[15]]
    assert (problem.row_group[rows] == problem.row_group[15]).all()
    N = obs.shape[0]
    B = obs.reshape(N, -1).T
    mask = ~sat.reshape(N, -1).T
    one = solve_fast(group, B, mask=mask, threads=1)
    two = solve_fast(group, np.concatenate([B] * 6), mask=np.concatenate([mask] * 6), threads=2)  # 2 batches
    assert one.converged.all() and two.converged.all()
    f_one = problem.objective(group, one.X, B, mask)
    f_two = problem.objective(group, two.X[: len(B)], B, mask)
    f_last = problem.objective(group, two.X[-len(B) :], B, mask)
    assert np.all(np.abs(f_two - f_one) <= 2e-4 * f_one) and np.all(np.abs(f_last - f_one) <= 2e-4 * f_one)
    # a pixel solved on its own gives its batch result (to the certificate)
    for p in (0, 37, len(B) - 1):
        alone = solve_fast(group, B[p : p + 1], mask=mask[p : p + 1], threads=1)
        f = problem.objective(group, alone.X, B[p : p + 1], mask[p : p + 1])[0]
        assert abs(f - f_one[p]) <= 2e-4 * f_one[p]


def test_pixels_whose_penalty_moved_agree_with_cvxpy():
    """Without ambient light the best rho is ~5: pixels start at 0.7 and move up the ladder."""
    pytest.importorskip("cvxpy")
    from planeray.demux import solve_cvxpy

    scene = make_scene("mirror_ball", (12, 16), projector_rows=240, seed=1)
    cam = CameraModel(ambient_e_per_us=0.0, read_noise_e=2.0)
    stack = simulate_stack(scene, paper_sweep(), camera=cam, seed=1)
    problem = DemuxProblem.from_stack(stack)
    obs, _ = read_observations(stack, problem, slice(6, 7))
    group = problem.groups[problem.row_group[6]]
    B = obs[:, 0].T
    res = solve_fast(group, B)
    assert res.converged.all()
    assert res.iterations.max() > fast._BALANCE_AFTER  # some pixels ran long enough to move
    ref = solve_cvxpy(group, B).X
    f_ref = problem.objective(group, ref, B)
    gaps = (problem.objective(group, res.X, B) - f_ref) / f_ref
    assert gaps.max() <= 1.2e-4 and np.median(gaps) <= 1e-4, gaps


def test_iteration_limit_is_never_reported_as_converged(saturated_stack, monkeypatch):
    """At the cap ADMM's iterate is not "converged" unless certified; the exact finish certifies it.

    Without the finish (switched off) no pixel proves 1e-12 in 40 iterations; with it, every
    pixel at the cap is solved exactly in float64 on its own observations (the saturated ones
    dropped), certified to 1e-12, and its objective is CVXPY's optimum on those rows.
    """
    problem = DemuxProblem.from_stack(saturated_stack)
    group, B, mask = _rows(saturated_stack, problem, 15)
    usable = mask.any(axis=1)
    with monkeypatch.context() as m:
        m.setattr(fast, "finish_pixels", lambda *a, **k: None)
        X, iters, conv, rel_gap, f, kkt, rss = AdmmRowSolver(group.A, problem.alpha, problem.beta).solve(
            B, 1e-12, 40, mask=mask
        )
    assert (iters[usable] == 40).all() and not conv.any()
    assert np.all(rel_gap[usable] > 1e-12) and np.all(X >= 0)
    with fast.blas_one_thread():
        X, iters, conv, rel_gap, f, kkt, rss = AdmmRowSolver(group.A, problem.alpha, problem.beta).solve(
            B, 1e-12, 40, mask=mask
        )
    assert (iters[usable] == 40).all() and conv[usable].all() and rel_gap[usable].max() <= 1e-12
    assert np.all(X >= 0)
    np.testing.assert_allclose(f, problem.objective(group, X, B, mask), rtol=1e-12)
    cp = pytest.importorskip("cvxpy")
    dropped = np.flatnonzero(usable & ~mask.all(axis=1))
    for p in dropped[:3]:
        Ap, b = group.A[mask[p]], B[p, mask[p]]
        x = cp.Variable(Ap.shape[1], nonneg=True)
        obj = cp.sum_squares(Ap @ x - b) + problem.alpha * cp.sum_squares(cp.diff(x)) + problem.beta * cp.sum(x)
        prob = cp.Problem(cp.Minimize(obj))
        prob.solve(solver=cp.CLARABEL, tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-12)
        assert abs(f[p] - prob.value) <= 1e-8 * prob.value


def test_pixel_without_usable_observation_is_flagged_never_converged(saturated_stack):
    sat = np.array(saturated_stack.saturated)
    sat[:, 15, 7] = True  # every image saturated at one pixel
    sat[:, 16, :3] = True
    stack = Stack(
        np.asarray(saturated_stack.images),
        saturated_stack.delay_us,
        saturated_stack.exposure_us,
        saturated_stack.lines_per_second,
        saturated_stack.excluded,
        projector_rows=saturated_stack.projector_rows,
        saturated=sat,
        metadata=saturated_stack.metadata,
    )
    res = demultiplex(stack)
    maps = res.maps
    for t, s in [(15, 7), (16, 0), (16, 2)]:
        assert maps["n_observations"][t, s] == 0
        assert not maps["converged"][t, s]
        assert np.isnan(maps["kkt_residual"][t, s])
        assert not res.transport.dense[t, s].any()
    others = maps["n_observations"] > 0
    assert maps["converged"][others].all()


def test_solver_without_mask_support_still_drops_saturated_rows(saturated_stack):
    """A registered solver without ``mask=`` gets the saturated pixels one by one (same problem)."""
    problem = DemuxProblem.from_stack(saturated_stack)
    obs, sat = read_observations(saturated_stack, problem, slice(15, 16))
    fast = solve_chunk(problem, obs, sat, slice(15, 16), method="fast")
    nnls = solve_chunk(problem, obs, sat, slice(15, 16), method="nnls")
    np.testing.assert_array_equal(fast.maps["n_observations"], nnls.maps["n_observations"])
    assert fast.maps["converged"].all()


def test_maps_from_the_certificate_equal_the_float64_diagnostics(saturated_stack):
    """The stored objective / residual RMS / KKT maps come from the solver's last certificate;
    they must be those of the stored transport (recomputed independently in float64)."""
    problem = DemuxProblem.from_stack(saturated_stack)
    rows = slice(10, 14)
    obs, sat = read_observations(saturated_stack, problem, rows)
    res = solve_chunk(problem, obs, sat, rows)
    N, r, W = obs.shape
    group = problem.groups[problem.row_group[12]]
    assert (problem.row_group[rows] == problem.row_group[12]).all()
    X = res.T.reshape(r * W, -1)[:, group.valid].astype(np.float64)
    B = obs.reshape(N, -1).T
    mask = ~sat.reshape(N, -1).T
    ref = problem.diagnostics(group, X, B, mask)
    for name in ("objective", "residual_rms"):
        np.testing.assert_allclose(res.maps[name].ravel(), ref[name], rtol=1e-5)
    np.testing.assert_allclose(res.maps["kkt_residual"].ravel(), ref["kkt_residual"], atol=1e-5)


def test_stacks_of_one_geometry_share_the_factorizations_and_give_the_same_bytes(monkeypatch):
    """A second stack of the same sweep and geometry reuses the first one's solvers (each a function of its
    illumination matrix and weights alone): no solver is built again, and the result is the one a process
    that keeps nothing computes, byte for byte.  Other weights, or a budget of 0 bytes, build anew."""
    first, second = (
        simulate_stack(make_scene(name, (24, 8), projector_rows=90, seed=0), paper_sweep(), seed=1)
        for name in ("wax", "corner")
    )
    built = []
    real_init = AdmmRowSolver.__init__

    def counting(self, *args, **kwargs):
        built.append(1)
        real_init(self, *args, **kwargs)

    monkeypatch.setattr(AdmmRowSolver, "__init__", counting)
    monkeypatch.setattr(fast, "_SOLVERS", type(fast._SOLVERS)())
    demultiplex(first)
    n_groups = len(built)
    assert n_groups > 1
    shared = demultiplex(second)
    assert len(built) == n_groups  # every row group of the second stack found its solver
    demultiplex(second, alpha=0.02)
    assert len(built) == 2 * n_groups  # other weights: other solvers
    monkeypatch.setattr(fast, "SOLVER_CACHE_BYTES", 0)  # keep (at most) the last one
    monkeypatch.setattr(fast, "_SOLVERS", type(fast._SOLVERS)())
    alone = demultiplex(second)
    assert len(built) == 3 * n_groups and len(fast._SOLVERS) == 1
    np.testing.assert_array_equal(alone.transport.dense, shared.transport.dense)
    for key in alone.maps:
        np.testing.assert_array_equal(alone.maps[key], shared.maps[key])


def test_solver_threads_follow_numbas_count_and_do_not_change_the_bytes(saturated_stack, tmp_path):
    """One solver thread where Numba may use one (a test worker), two where it may use two: same store.

    BLAS may use two threads outside the solver (as in a user's process): the solver holds it to one,
    or a product split over BLAS threads would sum in another order than on one solver thread.
    """
    import numba
    import zarr
    from threadpoolctl import threadpool_limits

    from planeray.demux import demultiplex_to_store

    before = numba.get_num_threads()
    stores = {}
    try:
        for n in (1, 2):
            if n > numba.config.NUMBA_NUM_THREADS:  # pragma: no cover - a one-core machine
                continue
            numba.set_num_threads(n)
            assert fast.solver_threads() == n
            with threadpool_limits(2, user_api="blas"):
                stores[n] = demultiplex_to_store(saturated_stack, tmp_path / f"T{n}.zarr", chunk_rows=8)
        if numba.config.NUMBA_NUM_THREADS >= 3:  # pragma: no cover - more cores: still two solver threads
            numba.set_num_threads(3)
            assert fast.solver_threads() == 2
    finally:
        numba.set_num_threads(before)
    T = {n: zarr.open_group(str(p), mode="r")["T"][...] for n, p in stores.items()}
    assert T[1].any()
    if 2 in T:
        assert T[1].tobytes() == T[2].tobytes()


def test_blas_is_limited_once_for_all_holders_and_restored_by_the_last(monkeypatch):
    """The driver's hold, its tasks' holds inside it and a solver thread's: one threadpoolctl limit
    (~1.5 ms each, once per task before), kept while any holder solves, restored when the last leaves."""
    import threading

    import threadpoolctl
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas_threads():
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    calls = []
    real = threadpoolctl.threadpool_limits
    monkeypatch.setattr(threadpoolctl, "threadpool_limits", lambda *a, **k: calls.append(a) or real(*a, **k))
    entered, leave = threading.Event(), threading.Event()

    def solver_thread():
        with fast.blas_one_thread():
            entered.set()
            leave.wait(30)

    with threadpool_limits(2, user_api="blas"):  # as in a user's process (a test worker's BLAS may stay at 1)
        before = blas_threads()
        one = [1] * len(before)
        t = threading.Thread(target=solver_thread)
        with fast.blas_one_thread():  # the driver's
            assert blas_threads() == one
            for _ in range(20):  # its tasks'
                with fast.blas_one_thread():
                    assert blas_threads() == one
            t.start()
            assert entered.wait(30)
            leave.set()
            t.join()
            assert blas_threads() == one  # the solver thread left first: still held for the driver
        assert blas_threads() == before  # the last holder restored it
    assert calls == [(1,)]
