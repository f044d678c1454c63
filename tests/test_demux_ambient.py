"""The ambient unknown of the demultiplexing problem (Eq. 6a; issue 26).

``I_i = sum_u A[i, u] T(u) + a I_w,i``: the fast solver against an optimum computed here
with CVXPY (written out in the test, not planeray's reference), with the distance bounds
that its certified gap implies; a synthetic stack with a known ambient map and a known
sparse transport, recovered within bounds derived from the noise; the paper's problem
untouched when the ambient is off; the store's record; resume; the cross-validation's
predictions with the ambient.
"""

from __future__ import annotations

import numpy as np
import pytest
import zarr

from planeray.demux import DemuxProblem, demultiplex, demultiplex_to_store, solve_fast
from planeray.demux import auto as auto_mod
from planeray.demux import fast as fast_mod
from planeray.demux.fast import DEFAULT_TOL, AdmmRowSolver
from planeray.demux.problem import RowGroup, difference_matrix
from planeray.errors import InputError
from planeray.io import read_transport, read_transport_maps
from planeray.stack import Stack

LPS = 54_000.0  # lines per second: one projector row is 1e6 / LPS us
WIDTHS = (3, 4, 5, 7)  # band widths I_w in projector rows
CENTRES = np.arange(-12, 13)  # band centres I_d in projector rows


def cvxpy_optimum(A, e, b, alpha, beta):
    """Eq. 6a for one pixel, written out with CVXPY + Clarabel (tight tolerances): ``x, a, f*``."""
    cp = pytest.importorskip("cvxpy")  # imported by the worker that runs these tests, not at every collection
    x = cp.Variable(A.shape[1], nonneg=True)
    a = cp.Variable(nonneg=True)
    f = cp.sum_squares(A @ x + a * e - b) + alpha * cp.sum_squares(cp.diff(x)) + beta * cp.sum(x)
    prob = cp.Problem(cp.Minimize(f))
    prob.solve(solver=cp.CLARABEL, tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-12)
    assert prob.status == "optimal"
    return np.maximum(x.value, 0.0), max(float(a.value), 0.0)


def objective(A, e, b, alpha, beta, x, a):
    r = A @ x + a * e - b
    return float(r @ r + alpha * np.sum(np.diff(x) ** 2) + beta * np.sum(x))


def band_matrix(centres, widths, offsets):
    """Band ``[c - w/2, c + w/2]`` integrated over the 1-row bins ``[u - 1/2, u + 1/2)`` (Eq. 2, no jitter)."""
    lo = np.maximum(offsets[None, :] - 0.5, (centres - widths / 2)[:, None])
    hi = np.minimum(offsets[None, :] + 0.5, (centres + widths / 2)[:, None])
    return np.clip(hi - lo, 0.0, None)


# ---------------------------------------------------------------- the fast solver
@pytest.mark.parametrize("collinear", [True, False])
def test_fast_solver_with_ambient_matches_an_independent_optimum(collinear):
    """Random problems: the certified gap holds against CVXPY, and so do the distances it implies.

    ``f(y) - f* <= g`` with ``f`` convex quadratic and ``y*`` optimal gives, for ``d = y - y*``,
    ``g >= grad f(y*)^T d + 1/2 d^T Q d >= 1/2 d^T Q d`` (the first term is >= 0 at a
    constrained optimum).  Where ``A 1 = I_w`` (bands inside the projector) ``Q`` is singular
    along ``n = (1, ..., 1, -1)``: then ``|d_perp| <= sqrt(2 g / mu_perp)`` on ``n``'s
    complement and along ``n`` ``t kappa <= g + |lambda*| |d_perp|`` with ``kappa = n^T
    lambda* = beta (U - 1) / |n|`` the pull of the sparsity term (``lambda*`` the optimal
    multipliers); otherwise ``|d| <= sqrt(2 g / mu)``.
    """
    rng = np.random.default_rng(1 if collinear else 2)
    N, U, P = 30, 12, 6
    A = band_matrix(rng.uniform(-4, 4, N), rng.uniform(1.5, 5.0, N), np.arange(U) - U // 2)
    e = A.sum(axis=1) if collinear else A.sum(axis=1) + rng.uniform(0.5, 2.0, N)  # cut bands: not collinear
    X = np.where(rng.random((P, U)) < 0.5, rng.exponential(0.05, (P, U)), 0.0)
    amb = rng.uniform(0.005, 0.02, P)
    B = X @ A.T + amb[:, None] * e + rng.normal(0.0, 1e-3, (P, N))
    alpha, beta, tol = 0.3, 0.01, 1e-6
    group = RowGroup(np.arange(1), A, slice(0, U))
    res = solve_fast(group, B, alpha, beta, tol, ambient=e, threads=1)
    assert res.converged.all() and res.ambient.shape == (P,)
    Ae = np.column_stack([A, e])
    D = np.pad(difference_matrix(U), ((0, 0), (0, 1)))
    Q = 2.0 * (Ae.T @ Ae + alpha * D.T @ D)
    n = np.append(np.ones(U), -1.0)
    n /= np.linalg.norm(n)
    for p in range(P):
        x_ref, a_ref = cvxpy_optimum(A, e, B[p], alpha, beta)
        f_ref = objective(A, e, B[p], alpha, beta, x_ref, a_ref)
        f_fast = objective(A, e, B[p], alpha, beta, res.X[p], res.ambient[p])
        assert f_fast <= f_ref * (1.0 + tol) + 1e-12  # the certified gap, against the independent optimum
        assert f_fast >= f_ref * (1.0 - 1e-8)  # (nothing beats the optimum)
        assert res.objective[p] == pytest.approx(f_fast, rel=1e-9)
        g = f_fast - f_ref + 1e-8 * f_ref  # bounds both solutions' gaps (Clarabel's to its 1e-12 tolerances)
        d = np.append(res.X[p] - x_ref, res.ambient[p] - a_ref)
        if collinear:
            Pn = np.eye(U + 1) - np.outer(n, n)
            mu = np.linalg.eigvalsh(Pn @ Q @ Pn)[1]  # [0] is n's zero
            d_perp = Pn @ d
            bound_perp = 2.0 * np.sqrt(2.0 * g / mu)  # the triangle inequality over both gaps
            assert np.linalg.norm(d_perp) <= bound_perp
            y_ref = np.append(x_ref, a_ref)
            l1 = np.append(np.ones(U), 0.0)  # the sparsity term's weights: not on the ambient
            lam = np.clip(2.0 * Ae.T @ (Ae @ y_ref - B[p]) + 2.0 * alpha * D.T @ (D @ y_ref) + beta * l1, 0, None)
            kappa = beta * U / np.sqrt(U + 1)
            assert abs(n @ d) <= 2.0 * (g + np.linalg.norm(lam) * bound_perp) / kappa
        else:
            mu = np.linalg.eigvalsh(Q)[0]
            assert np.linalg.norm(d) <= 2.0 * np.sqrt(2.0 * g / mu)


@pytest.mark.parametrize("collinear", [True, False])
def test_fast_solver_with_ambient_drops_saturated_observations_like_their_own_problem(collinear):
    """Pixels with dropped observations (the low-rank update, in the batch): each is the optimum of its own rows."""
    rng = np.random.default_rng(4)
    N, U, P = 30, 12, 8
    A = band_matrix(rng.uniform(-4, 4, N), rng.uniform(1.5, 5.0, N), np.arange(U) - U // 2)
    e = A.sum(axis=1) if collinear else A.sum(axis=1) + rng.uniform(0.5, 2.0, N)
    X = np.where(rng.random((P, U)) < 0.5, rng.exponential(0.05, (P, U)), 0.0)
    B = X @ A.T + rng.uniform(0.005, 0.02, (P, 1)) * e + rng.normal(0.0, 1e-3, (P, N))
    mask = rng.random((P, N)) > 0.2
    mask[0] = True  # one pixel keeps everything
    alpha, beta, tol = 0.3, 0.01, 1e-6
    res = solve_fast(RowGroup(np.arange(1), A, slice(0, U)), B, alpha, beta, tol, ambient=e, mask=mask, threads=1)
    assert res.converged.all()
    for p in range(P):
        k = mask[p]
        x_ref, a_ref = cvxpy_optimum(A[k], e[k], B[p, k], alpha, beta)
        f_ref = objective(A[k], e[k], B[p, k], alpha, beta, x_ref, a_ref)
        f_fast = objective(A[k], e[k], B[p, k], alpha, beta, res.X[p], res.ambient[p])
        assert f_ref * (1.0 - 1e-8) <= f_fast <= f_ref * (1.0 + tol) + 1e-12


def test_collinear_ambient_makes_the_null_direction_exact_and_the_rest_of_the_problem_unchanged():
    rng = np.random.default_rng(3)
    A = band_matrix(rng.uniform(-4, 4, 20), rng.uniform(2, 5, 20), np.arange(11) - 5)
    e = A.sum(axis=1) * (1.0 + 1e-9 * rng.standard_normal(20))  # the jitter's tails: ~1e-9 off
    s = AdmmRowSolver(A, 0.1, 0.01, ambient=e)
    assert s.null is not None and np.abs(s.Q @ s.null).max() < 1e-12 * np.abs(s.Q).max()
    np.testing.assert_allclose(s.ambient_column, A.sum(axis=1), rtol=1e-15)
    plain = AdmmRowSolver(A, 0.1, 0.01)
    assert plain.null is None and plain.A.shape == A.shape  # the paper's problem: no extra column
    cut = AdmmRowSolver(A, 0.1, 0.01, ambient=e + 1.0)  # bands cut by the projector: a is seen directly
    assert cut.null is None and np.linalg.eigvalsh(cut.Q)[0] > 0


# ---------------------------------------------------------------- a synthetic stack
def _stack(images, *, projector_rows, metadata=None):
    w, c = np.meshgrid(np.asarray(WIDTHS, float), CENTRES.astype(float), indexing="ij")
    return Stack(
        np.asarray(images, np.float32),
        c.ravel() / LPS * 1e6,
        w.ravel() / LPS * 1e6,
        LPS,
        excluded=np.zeros(w.size, bool),
        projector_rows=projector_rows,
        metadata=metadata or {},
    )


def synthetic_ambient(*, sigma=1e-4, shape=(4, 16), seed=0):
    """``A T + a I_w + noise`` with a sparse ``T`` (zeros at most offsets) and a known ambient map."""
    rng = np.random.default_rng(seed)
    H, W = shape
    w, c = np.meshgrid(np.asarray(WIDTHS, float), CENTRES.astype(float), indexing="ij")
    K = int(np.ceil(np.abs(c).max() + w.max() / 2))
    offsets = np.arange(-K, K + 1)  # planeray's support: max |I_d| + I_w / 2, rounded up
    A = band_matrix(c.ravel(), w.ravel(), offsets)  # every camera row: bands inside the 400-row projector
    lit = np.flatnonzero(A.sum(axis=0) > 0)  # the outermost bins no band reaches hold no unknown
    T = np.zeros((H, W, offsets.size))
    for t in range(H):
        for s in range(W):
            peak = rng.integers(lit[0] + 3, lit[-1] - 3)
            T[t, s, peak] = rng.uniform(0.05, 0.1)  # the direct-like spike
            T[t, s, peak + 1 : peak + 3] = rng.uniform(0.005, 0.02, 2)  # a short tail; zeros elsewhere
    amb = rng.uniform(0.02, 0.05, (H, W))
    images = np.einsum("tsu,iu->its", T, A) + amb[None] * w.ravel()[:, None, None]
    images += rng.normal(0.0, sigma, images.shape)
    return _stack(images, projector_rows=400), T, amb, A[:, lit]


def test_synthetic_stack_recovers_the_ambient_map_and_the_transport():
    """Known ambient and sparse ``T``, recovered within bounds derived from the noise.

    ``A`` has full column rank, so the data fix the total ``w = T + a 1`` (``A w = A T + a
    I_w``): ``w_hat`` is the least-squares estimate (``w_true >= a > 0`` lies inside the
    constraint, so it is not active) plus the regularization's bias, and the sparsity term
    then moves the floor of ``w_hat`` into the ambient: ``a_hat = min_u w_hat(u)`` and
    ``T_hat = w_hat - a_hat``.  With ``|w_hat - w_true| <= E`` everywhere and ``T_true``
    zero somewhere, ``|a_hat - a| <= E`` and ``|T_hat - T| <= 2 E``, where ``E`` is 6
    standard deviations of the least-squares noise ``sigma sqrt(diag (A^T A)^-1)`` plus the
    bias ``|(2 A^T A)^-1| (alpha |D^T D T| + beta (U + sqrt U))`` (the subgradient of the
    regularization is at most that) plus the solver's ``sqrt(2 tol f / mu)``.
    """
    sigma, alpha, beta, tol = 1e-4, 1e-6, 1e-5, DEFAULT_TOL  # the solver's own certified gap
    stack, T, amb, A_ref = synthetic_ambient(sigma=sigma)
    problem = DemuxProblem.from_stack(stack, ambient=True, alpha=alpha, beta=beta)
    assert len(problem.groups) == 1
    np.testing.assert_allclose(problem.groups[0].A, A_ref, atol=1e-12)  # the same imaging model as written here
    np.testing.assert_allclose(problem.exposure_rows, A_ref.sum(axis=1), rtol=1e-12)  # collinear
    res = demultiplex(stack, alpha=alpha, beta=beta, ambient="estimate")
    assert res.maps["converged"].all()
    U, N = A_ref.shape[1], A_ref.shape[0]
    G = np.linalg.inv(A_ref.T @ A_ref)
    sd = sigma * np.sqrt(np.diag(G))
    D = difference_matrix(U)
    valid = problem.groups[0].valid
    reg = 2.0 * alpha * np.abs(D.T @ D @ T[..., valid].reshape(-1, U).T).max() * np.sqrt(U) + beta * (U + np.sqrt(U))
    bias = np.linalg.norm(G / 2, 2) * reg
    f_max = float(res.maps["objective"].max())
    solver = np.sqrt(2.0 * tol * f_max / (2.0 * np.linalg.eigvalsh(A_ref.T @ A_ref)[0]))
    split = tol * f_max / (beta * U)  # how far the certified gap lets a fall short of min(w)
    E = 6.0 * sd.max() + bias + solver + split
    assert E < 0.1 * amb.min()  # the bound is informative: a tenth of the smallest ambient
    err_a = np.abs(res.ambient - amb).max()
    err_T = np.abs(res.transport.dense - T).max()
    assert err_a <= E, (err_a, E)
    assert err_T <= 2.0 * E, (err_T, E)
    # the paper's problem keeps the ambient in T as a flat floor: far outside the same bound
    paper = demultiplex(stack, alpha=alpha, beta=beta, ambient="none").transport.dense
    assert np.abs(paper - T).max() > 10.0 * E
    assert N > U  # (the design: more images than offsets)


def test_low_noise_pixels_certify_their_gap_before_the_cap(monkeypatch):
    """The certificate's move along the null direction costs nothing at a near-optimal iterate.

    At low noise the objective ``f`` is tiny, and the float32 iterate leaves the multiplier a
    little off balance along ``n = (1, ..., 1, -sqrt(U))``.  When that imbalance could only go
    onto the ambient's multiplier (``z`` large), the bound stayed at ``|d| z_a / |n_a| > tol f``
    and such pixels ran to the cap at a true gap of 1e-8 (4 of 256 here, 1 of 64 in the test
    above on NumPy 2.4).  Lowering the offsets' positive multipliers instead certifies them;
    the exact finish at the cap is switched off, so that ADMM's own certificate is what is tested.
    """
    monkeypatch.setattr(fast_mod, "finish_pixels", lambda *a, **k: None)
    stack, *_ = synthetic_ambient(sigma=1e-5, shape=(8, 32))
    alpha, beta = 1e-6, 1e-5
    problem = DemuxProblem.from_stack(stack, ambient=True, alpha=alpha, beta=beta)
    B = np.asarray(stack.images, np.float64)[problem.image_index].reshape(problem.n_images, -1).T
    with fast_mod.blas_one_thread():
        solver = AdmmRowSolver(problem.groups[0].A, alpha, beta, ambient=problem.exposure_rows)
        X, iters, conv, rel_gap, f, *_ = solver.solve(B)
    assert conv.all() and iters.max() < fast_mod._MAX_ITER and rel_gap.max() <= DEFAULT_TOL


@pytest.mark.parametrize("collinear", [True, False])
def test_pixels_left_at_the_iteration_cap_are_finished_exactly(collinear):
    """40 ADMM iterations, then the float64 active-set finish: every pixel certified to 1e-10, as CVXPY's optimum."""
    rng = np.random.default_rng(5)
    N, U, P = 30, 12, 5
    A = band_matrix(rng.uniform(-4, 4, N), rng.uniform(1.5, 5.0, N), np.arange(U) - U // 2)
    e = A.sum(axis=1) if collinear else A.sum(axis=1) + rng.uniform(0.5, 2.0, N)
    X = np.where(rng.random((P, U)) < 0.5, rng.exponential(0.05, (P, U)), 0.0)
    B = X @ A.T + rng.uniform(0.005, 0.02, (P, 1)) * e + rng.normal(0.0, 1e-3, (P, N))
    alpha, beta, tol = 0.3, 0.01, 1e-10
    solver = AdmmRowSolver(A, alpha, beta, ambient=e)
    Y, iters, conv, rel_gap, f, *_ = solver.solve(B, tol, 40)
    assert (iters == 40).all() and conv.all() and rel_gap.max() <= tol
    for p in range(P):
        x_ref, a_ref = cvxpy_optimum(A, e, B[p], alpha, beta)
        f_ref = objective(A, e, B[p], alpha, beta, x_ref, a_ref)
        a = Y[p, -1] / solver.ambient_scale
        f_fin = objective(A, e, B[p], alpha, beta, Y[p, :-1], a)
        assert f[p] == pytest.approx(f_fin, rel=1e-12)
        assert abs(f_fin - f_ref) <= 1e-9 * f_ref


def test_beta_zero_with_the_ambient_is_refused_and_auto_defaults_follow_it():
    stack, *_ = synthetic_ambient(shape=(2, 4))
    with pytest.raises(InputError, match="beta > 0"):
        demultiplex(stack, alpha=0.1, beta=0.0, ambient="estimate")
    with pytest.raises(InputError, match="beta > 0"):
        DemuxProblem.from_stack(stack, beta=0.0, ambient=True)
    with pytest.raises(InputError, match="cannot estimate the ambient"):
        demultiplex(stack, alpha=0.1, beta=0.1, ambient="estimate", method="pinv")
    with pytest.raises(InputError, match="ambient must be one of"):
        demultiplex(stack, ambient="yes")
    assert auto_mod.resolve_ambient(None, 0.01, 0.01) == "none"  # explicit weights: the paper's problem
    assert auto_mod.resolve_ambient(None, "auto", "auto") == "estimate"
    assert auto_mod.resolve_ambient(None, "auto", 0.0) == "none"  # beta = 0 cannot split it
    assert auto_mod.resolve_ambient("none", "auto", "auto") == "none"


# ---------------------------------------------------------------- off: the paper's problem
def test_ambient_off_is_the_papers_problem_bit_for_bit():
    stack, *_ = synthetic_ambient(shape=(4, 8))
    default = demultiplex(stack, alpha=0.01, beta=0.01)
    none = demultiplex(stack, alpha=0.01, beta=0.01, ambient="none")
    assert default.ambient is None and "ambient" not in default.maps and default.attrs["ambient"] == "none"
    np.testing.assert_array_equal(default.transport.dense, none.transport.dense)
    for name in default.maps:
        np.testing.assert_array_equal(default.maps[name], none.maps[name])
    # and the solver without the column solves the paper's problem, to its certified gap
    problem = DemuxProblem.from_stack(stack)
    g = problem.groups[0]
    B = np.asarray(stack.images, np.float64)[problem.image_index, 1, :].T
    res = solve_fast(g, B, 0.01, 0.01, 1e-6, threads=1)
    assert res.ambient is None and res.X.shape[1] == g.A.shape[1]
    for p in range(B.shape[0]):
        x_ref, _ = cvxpy_optimum(g.A, np.zeros(B.shape[1]), B[p], 0.01, 0.01)  # a's column 0: the paper's
        f_ref = objective(g.A, 0, B[p], 0.01, 0.01, x_ref, 0.0)
        assert objective(g.A, 0, B[p], 0.01, 0.01, res.X[p], 0.0) <= f_ref * (1 + 1e-6) + 1e-12


# ---------------------------------------------------------------- the store and resume
def test_store_records_the_option_and_the_map(tmp_path):
    stack, _, amb, _ = synthetic_ambient(shape=(4, 8))
    mem = demultiplex(stack, alpha=1e-3, beta=1e-3, ambient="estimate", chunk_rows=2)
    out = demultiplex_to_store(stack, tmp_path / "T.zarr", alpha=1e-3, beta=1e-3, ambient="estimate", chunk_rows=2)
    T, attrs = read_transport(out)
    assert attrs["ambient"] == "estimate"
    maps = read_transport_maps(out)
    assert maps["ambient"].dtype == np.float32 and maps["ambient"].shape == (4, 8)
    np.testing.assert_array_equal(maps["ambient"], mem.ambient)
    np.testing.assert_array_equal(T.dense, mem.transport.dense)
    assert np.abs(maps["ambient"] - amb).max() < 0.1 * amb.min()
    plain = demultiplex_to_store(stack, tmp_path / "P.zarr", alpha=1e-3, beta=1e-3, chunk_rows=2)
    group = zarr.open_group(str(plain), mode="r")
    assert group.attrs["ambient"] == "none" and "ambient" not in group


def test_command_estimates_the_ambient_on_request_and_keeps_the_papers_problem_otherwise(tmp_path):
    from typer.testing import CliRunner

    from planeray.cli import app
    from planeray.io import write_stack

    stack, _, amb, _ = synthetic_ambient(shape=(4, 8))
    path = write_stack(stack, tmp_path / "s.zarr")
    r = CliRunner().invoke(app, ["demux", str(path), "--out", str(tmp_path / "a.zarr"), "--ambient", "estimate"])
    assert r.exit_code == 0, r.output
    assert "median ambient" in r.output
    maps = read_transport_maps(tmp_path / "a.zarr")
    np.testing.assert_array_equal(maps["ambient"], demultiplex(stack, ambient="estimate").ambient)
    r = CliRunner().invoke(app, ["demux", str(path), "--out", str(tmp_path / "p.zarr")])
    assert r.exit_code == 0 and "median ambient" not in r.output
    assert "ambient" not in read_transport_maps(tmp_path / "p.zarr")


def test_resume_refuses_a_changed_ambient_and_continues_an_identical_run(tmp_path):
    stack, *_ = synthetic_ambient(shape=(4, 8))
    out = tmp_path / "T.zarr"
    demultiplex_to_store(stack, out, alpha=1e-3, beta=1e-3, ambient="none", chunk_rows=1, _stop_after=1)
    with pytest.raises(InputError, match="unfinished run"):
        demultiplex_to_store(stack, out, alpha=1e-3, beta=1e-3, ambient="estimate", chunk_rows=1)
    out2 = tmp_path / "U.zarr"
    demultiplex_to_store(stack, out2, alpha=1e-3, beta=1e-3, ambient="estimate", chunk_rows=1, _stop_after=2)
    with pytest.raises(InputError, match="unfinished run"):
        demultiplex_to_store(stack, out2, alpha=1e-3, beta=1e-3, ambient="none", chunk_rows=1)
    resumed = []
    demultiplex_to_store(
        stack, out2, alpha=1e-3, beta=1e-3, ambient="estimate", chunk_rows=1, on_resume=lambda d, t: resumed.append(d)
    )
    assert resumed == [2]
    ref = demultiplex(stack, alpha=1e-3, beta=1e-3, ambient="estimate", chunk_rows=1)
    np.testing.assert_array_equal(read_transport_maps(out2)["ambient"], ref.ambient)
    np.testing.assert_array_equal(read_transport(out2)[0].dense, ref.transport.dense)


# ---------------------------------------------------------------- cross-validation
def test_cross_validation_predicts_left_out_images_with_the_ambient():
    """``cv_score`` with the ambient against the criterion written out with CVXPY (Eq. 6a per fold)."""
    stack, *_ = synthetic_ambient(sigma=1e-3, shape=(1, 4))
    problem = DemuxProblem.from_stack(stack)
    g = problem.groups[0]
    B = np.asarray(stack.images, np.float64)[problem.image_index, 0, :].T
    e = problem.exposure_rows
    N = B.shape[1]
    split = auto_mod.fold_indices(N, 5, 0)
    alpha, beta = 0.1, 1e-3
    ours = auto_mod.cv_score([g], [B], [None], [np.ones_like(B)], split, alpha, beta, tol=1e-7, threads=1, ambient=e)
    with_a, without_a = np.zeros(B.shape[0]), np.zeros(B.shape[0])
    for p in range(B.shape[0]):
        for test in split:
            train = np.setdiff1d(np.arange(N), test)
            x, a = cvxpy_optimum(g.A[train], e[train], B[p, train], alpha, beta)
            with_a[p] += (((B[p, test] - g.A[test] @ x - a * e[test]) ** 2).sum()) / N
            without_a[p] += (((B[p, test] - g.A[test] @ x) ** 2).sum()) / N
    # the scores are squared prediction errors; a certified 1e-7 gap moves them by far less than 1 %
    np.testing.assert_allclose(ours, with_a, rtol=0.01)
    assert (without_a > 10 * with_a).all()  # leaving the ambient out of the prediction would show
