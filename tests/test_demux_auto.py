"""``alpha``/``beta`` chosen by the data (issues 26 and 42).

The criteria -- generalized cross-validation (the default), Stein's risk estimate and K-fold
cross-validation over the images -- are checked against independent computations (SciPy's NNLS
on the augmented system; folds as documented) by exhaustive search over a grid; pure noise
must choose strong regularization; a best weight beyond the searched range is searched for and
otherwise reported (store and console); explicit weights stay exactly what was asked; the store
records the choice; an interrupted automatic run resumes only on identical inputs.  What each
criterion estimates is tested in ``test_demux_risk.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
import zarr
from scipy.optimize import nnls
from threadpoolctl import threadpool_limits
from typer.testing import CliRunner

from planeray.cli import app
from planeray.demux import DemuxProblem, choose_weights, demultiplex, demultiplex_to_store
from planeray.demux import auto as auto_mod
from planeray.errors import InputError
from planeray.io import read_transport, write_stack
from planeray.stack import Stack
from planeray.timing import PAPER_LINES_PER_SECOND, paper_sweep

H, W = 16, 32
PROJECTOR_ROWS = 720  # rows 3..12 share one illumination matrix at 16 camera rows
SMALL_ALPHAS = (1e-2, 1.0, 100.0, 1e4)
SMALL_BETAS = (1e-3, 1e-1)


@pytest.fixture(autouse=True)
def small_grids(monkeypatch):
    """Coarse grids keep each automatic run to a few pairs (the search itself is the same; it goes
    past the grid's ends only as far as the limits, here the grids' own ranges, except where a test
    widens them)."""
    monkeypatch.setattr(auto_mod, "DEFAULT_ALPHAS", SMALL_ALPHAS)
    monkeypatch.setattr(auto_mod, "DEFAULT_BETAS", SMALL_BETAS)
    monkeypatch.setattr(auto_mod, "ALPHA_LIMITS", (min(SMALL_ALPHAS), max(SMALL_ALPHAS)))
    monkeypatch.setattr(auto_mod, "BETA_LIMITS", (min(SMALL_BETAS), max(SMALL_BETAS)))
    monkeypatch.setattr(auto_mod, "MIN_PIXELS", 48)


def _empty_stack(images) -> Stack:
    sw = paper_sweep()
    return Stack(
        images.astype(np.float32),
        sw.delay_us,
        sw.exposure_us,
        PAPER_LINES_PER_SECOND,
        excluded=sw.excluded,
        projector_rows=PROJECTOR_ROWS,
        metadata={},  # no camera model: equal weights
    )


def synthetic(kind: str, *, noise=0.01, seed=0, shape=(H, W)):
    """A stack ``A x + noise`` with a known transport ``x`` per pixel; returns (stack, x per row)."""
    rng = np.random.default_rng(seed)
    stack = _empty_stack(np.zeros((85, *shape)))
    problem = DemuxProblem.from_stack(stack)
    u = problem.offsets_rows.astype(float)
    images = np.zeros((85, *shape))
    truth = {}
    for g in problem.groups:
        for t in g.rows:
            amp = rng.uniform(0.5, 1.0, (shape[1], 1))
            if kind == "smooth":  # a broad subsurface-like profile
                x = 0.02 * amp * np.exp(-0.5 * (u / 25.0) ** 2)
            elif kind == "noise":
                x = np.zeros((shape[1], u.size))
            x = x[:, g.valid]
            truth[int(t)] = x
            images[problem.image_index, t, :] = (x @ g.A.T).T
    images += rng.normal(0.0, noise, images.shape)
    return _empty_stack(images), truth


def independent_cv(stack, pixels, alpha, *, folds=5, seed=0):
    """The criterion written out with SciPy: beta = 0, so each fit is an NNLS of ``[A; sqrt(alpha) D]``."""
    problem = DemuxProblem.from_stack(stack)
    N = problem.n_images
    perm = np.random.default_rng(seed).permutation(N)  # the documented split: fold k = perm[k::folds]
    split = [np.sort(perm[k::folds]) for k in range(folds)]
    imgs = np.asarray(stack.images, np.float64)[problem.image_index]
    scores = []
    for r, c in pixels:
        A = problem.groups[problem.row_group[r]].A
        V = A.shape[1]
        D = np.diff(np.eye(V), axis=0)
        b = imgs[:, r, c]
        ss = 0.0
        for test in split:
            train = np.setdiff1d(np.arange(N), test)
            M = np.vstack([A[train], np.sqrt(alpha) * D])
            x, _ = nnls(M, np.concatenate([b[train], np.zeros(V - 1)]), maxiter=20 * V)
            ss += float(((b[test] - A[test] @ x) ** 2).sum())
        scores.append(ss / N)
    return float(np.mean(scores))


def independent_gcv(stack, pixels, alpha):
    """GCV written out with SciPy: beta = 0, each fit an NNLS of ``[A; sqrt(alpha) D]``, its influence on the free set."""
    problem = DemuxProblem.from_stack(stack)
    imgs = np.asarray(stack.images, np.float64)[problem.image_index]
    scores = []
    for r, c in pixels:
        A = problem.groups[problem.row_group[r]].A
        N, V = A.shape
        D = np.diff(np.eye(V), axis=0)
        b = imgs[:, r, c]
        x, _ = nnls(np.vstack([A, np.sqrt(alpha) * D]), np.concatenate([b, np.zeros(V - 1)]), maxiter=20 * V)
        F = x > 0
        AF = A[:, F]
        S = AF @ np.linalg.pinv(AF.T @ AF + alpha * (D.T @ D)[np.ix_(F, F)]) @ AF.T  # the influence matrix
        res = b - A @ x
        scores.append(N * float(res @ res) / (N - np.trace(S)) ** 2)
    return float(np.mean(scores))


@pytest.mark.parametrize("criterion", ["gcv", "cv-images"])
def test_criterion_matches_exhaustive_search_with_an_independent_solver(criterion):
    stack, _ = synthetic("smooth", shape=(H, 8))
    grid = (1e-2, 1.0, 30.0, 1e3, 1e5)
    choice = choose_weights(stack, alpha="auto", beta=0.0, alphas=grid, n_pixels=6, tol=1e-6, criterion=criterion)
    assert choice.beta == 0.0 and set(choice.betas) == {0.0} and choice.criterion == criterion
    assert choice.worst_gap <= 1e-6  # every solve behind the curve certified to the tolerance asked
    ours = dict(zip(choice.alphas, choice.scores))
    independent = independent_gcv if criterion == "gcv" else independent_cv
    with threadpool_limits(1, user_api="blas"):  # SciPy's NNLS: many small products (spinning threads cost ~5x)
        theirs = {a: independent(stack, choice.pixels, a) for a in grid if a in ours}
    for a in theirs:
        assert ours[a] == pytest.approx(theirs[a], rel=0.02), a
    best = min(theirs, key=theirs.get)
    assert best not in (grid[0], grid[-1])  # an interior optimum: the test can fail
    assert choice.lowest[0] == best
    # the choice: the alpha nearest the paper's 0.01 among those within one paired standard error of the lowest
    i = list(choice.alphas).index(best)
    j = list(choice.alphas).index(choice.alpha)
    assert choice.scores[j] - choice.scores[i] <= 3 * choice.score_se[i] + 1e-12
    assert abs(np.log10(choice.alpha / 0.01)) <= abs(np.log10(best / 0.01))
    # the scan stops once the score has risen twice: every grid point up to there was scored
    assert set(grid[: grid.index(best) + 2]) <= set(ours)


def test_smooth_transport_gets_strong_smoothing_and_a_lower_error_than_the_paper():
    stack, truth = synthetic("smooth")
    choice = choose_weights(stack)
    assert choice.alpha >= 100.0
    err = {}
    for name, (a, b, amb) in {
        "auto": (choice.alpha, choice.beta, choice.ambient),
        "paper": (0.01, 0.01, "none"),
    }.items():
        T = demultiplex(stack, alpha=a, beta=b, ambient=amb).transport.dense
        problem = DemuxProblem.from_stack(stack)
        g = problem.groups[problem.row_group[6]]
        err[name] = np.linalg.norm(T[6][:, g.valid] - truth[6]) / np.linalg.norm(truth[6])
    assert err["auto"] < 0.5 * err["paper"], err


def test_pure_noise_chooses_strong_regularization():
    stack, _ = synthetic("noise", noise=0.02)
    choice = choose_weights(stack)
    assert choice.alpha >= 100.0 or choice.beta >= 0.1, choice.summary()
    auto = demultiplex(stack, alpha=choice.alpha, beta=choice.beta, ambient=choice.ambient).transport.dense
    paper = demultiplex(stack).transport.dense
    assert np.linalg.norm(auto) < 0.2 * np.linalg.norm(paper)


def test_search_goes_past_the_grids_ends_and_says_when_it_stops_at_a_limit(monkeypatch):
    """A best weight beyond the grid is searched for in half-decade steps; beyond the limits it is reported."""
    monkeypatch.setattr(auto_mod, "ALPHA_LIMITS", (1e-5, 1e6))
    monkeypatch.setattr(auto_mod, "BETA_LIMITS", (1e-6, 100.0))
    alphas, betas = (1e-3, 1e-2, 1e-1, 1.0), (1e-3, 1e-2, 1e-1)
    auto = {"alpha": "auto", "beta": "auto"}

    def bowl(a0, b0):  # per-pixel scores with their minimum at (a0, b0)
        return lambda a, b: np.array([1.0, 1.1]) + (np.log10(a / a0) ** 2 + np.log10(b / b0) ** 2)

    curve = auto_mod.search(bowl(1e-4, 3.16e-1), auto, alphas, betas)  # both beyond the grid, within the limits
    best = auto_mod._best(curve)
    assert best[0] == pytest.approx(1e-4) and best[1] == pytest.approx(10**-0.5)
    assert auto_mod.edges(curve, auto) == {}  # a worse point was scored beyond each
    curve = auto_mod.search(bowl(1e-8, 1e3), auto, alphas, betas)  # beyond the limits
    best = auto_mod._best(curve)
    assert best[0] == pytest.approx(1e-5) and best[1] == pytest.approx(100.0)
    assert auto_mod.edges(curve, auto) == {"alpha": "low", "beta": "high"}
    held = {"alpha": "auto", "beta": 0.01}  # a weight that is not automatic is never moved nor reported
    curve = auto_mod.search(bowl(1e-8, 1e3), held, alphas, betas)
    assert {k[1] for k in curve} == {0.01} and auto_mod.edges(curve, held) == {"alpha": "low"}


def test_the_choice_is_the_pair_nearest_the_papers_weights_that_the_data_cannot_tell_from_the_best():
    """One standard error of the paired difference: within it, the nearer 0.01 / 0.01; beyond it, the lowest."""
    rng = np.random.default_rng(0)
    base = rng.normal(5.0, 1.0, 400)  # per-pixel scores: pixels differ much more than pairs do
    noise = lambda s: rng.normal(0.0, s, 400)  # noqa: E731
    curve = {
        (1.0, 0.01): base - 0.002 + noise(0.05),  # the lowest mean, by less than a paired standard error
        (0.1, 0.01): base + noise(0.05),  # as good to the data, and nearer the paper's weights: chosen
        (10.0, 0.01): base + 0.3 + noise(0.05),
    }
    keys, means, ses, chosen, ranges, lowest = auto_mod.summarize(curve)
    assert lowest == (1.0, 0.01) and chosen == (0.1, 0.01) and ranges[0] == (0.1, 1.0)
    curve[(1.0, 0.01)] = base - 0.2 + noise(0.05)  # now clearly better (40 paired standard errors): the data decide
    keys, means, ses, chosen, ranges, lowest = auto_mod.summarize(curve)
    assert chosen == lowest == (1.0, 0.01) and ranges[0] == (1.0, 1.0)


def test_explicit_weights_are_exactly_what_was_asked(tmp_path):
    stack, _ = synthetic("smooth", shape=(H, 8))
    res = demultiplex(stack, alpha=0.01, beta=0.02)
    assert res.attrs["alpha"] == 0.01 and res.attrs["beta"] == 0.02 and "weights_choice" not in res.attrs
    path = tmp_path / "s.zarr"
    write_stack(stack, path)
    out = tmp_path / "t.zarr"
    r = CliRunner().invoke(app, ["demux", str(path), "--out", str(out), "--alpha", "0.01", "--beta", "0.02"])
    assert r.exit_code == 0, r.output
    assert "weights:" not in r.output
    T, attrs = read_transport(out)
    assert attrs["alpha"] == 0.01 and attrs["beta"] == 0.02 and "weights_choice" not in attrs
    np.testing.assert_array_equal(T.dense, res.transport.dense)
    # one weight fixed, the other automatic: the fixed one is kept exactly
    choice = choose_weights(stack, alpha=0.5, beta="auto")
    assert choice.alpha == 0.5 and set(choice.alphas) == {0.5} and choice.beta in SMALL_BETAS
    r = CliRunner().invoke(app, ["demux", str(path), "--out", str(tmp_path / "x.zarr"), "--alpha", "lots"])
    assert r.exit_code == 1 and "--alpha must be a number or 'auto'" in r.output


def test_store_records_the_choice_and_the_command_prints_and_draws_it(tmp_path, monkeypatch):
    # the smooth transport wants alpha >= 100; the search may go no further than 1 here: a choice on the end
    monkeypatch.setattr(auto_mod, "DEFAULT_ALPHAS", (1e-2, 0.1, 1.0))
    monkeypatch.setattr(auto_mod, "ALPHA_LIMITS", (1e-2, 1.0))
    stack, _ = synthetic("smooth")
    path = tmp_path / "s.zarr"
    write_stack(stack, path)
    out = tmp_path / "t.zarr"
    r = CliRunner().invoke(
        app,
        ["demux", str(path), "--out", str(out), "--alpha", "auto", "--beta", "auto", "--report", str(tmp_path / "rep")],
    )
    assert r.exit_code == 0, r.output
    lines = [line for line in r.output.splitlines() if line.startswith("weights:")]
    assert len(lines) == 1 and "alpha = " in lines[0] and "within 1 SE" in lines[0]
    assert "pairs tried); ambient light estimated per pixel (" in lines[0]  # the default with auto weights, said so
    attrs = zarr.open_group(str(out), mode="r").attrs.asdict()
    rec = attrs["weights_choice"]
    assert attrs["ambient"] == rec["ambient"] == "estimate"
    assert rec["requested"] == {"alpha": "auto", "beta": "auto"} and rec["criterion"] == "gcv"
    assert 0 < rec["worst_gap"] <= 1e-4  # every solve behind the curve certified as the final one
    # a choice on an end of what the search could try is said, not silent: store, console, figure
    assert rec["edge"] == {"alpha": "high"} and rec["alpha"] == 1.0
    warn = [line for line in r.output.splitlines() if line.startswith("warning: alpha = ")]
    assert len(warn) == 1 and "is the largest value the search tried" in warn[0] and "may lie above" in warn[0]
    assert attrs["alpha"] == rec["alpha"] and attrs["beta"] == rec["beta"]
    curve = rec["curve"]
    n = len(curve["score"])
    assert n >= 4 and len(curve["alpha"]) == len(curve["beta"]) == len(curve["score_se"]) == n
    best = int(np.argmin(curve["score"]))
    assert (curve["alpha"][best], curve["beta"][best]) == tuple(rec["lowest"])
    assert rec["alpha_range"][0] <= rec["alpha"] <= rec["alpha_range"][1]
    assert f"alpha = {rec['alpha']:.3g}" in lines[0]
    png = tmp_path / "rep" / "weights_cv.png"
    assert png.is_file() and png.read_bytes()[:4] == b"\x89PNG"


def test_interrupted_auto_run_resumes_only_on_identical_inputs(tmp_path):
    stack, _ = synthetic("smooth")
    out = tmp_path / "t.zarr"
    demultiplex_to_store(stack, out, alpha="auto", beta="auto", chunk_rows=4, _stop_after=1)
    rec = zarr.open_group(str(tmp_path / ".t.zarr.partial"), mode="r").attrs["weights_choice"]
    # a different stack (one pixel changed) is refused, whatever the unfinished run chose
    changed = Stack(
        np.array(stack.images),
        stack.delay_us,
        stack.exposure_us,
        stack.lines_per_second,
        excluded=stack.excluded,
        projector_rows=stack.projector_rows,
        metadata=stack.metadata,
    )
    changed.images[5, 7, 3] += 0.01
    with pytest.raises(InputError, match="unfinished run"):
        demultiplex_to_store(changed, out, alpha="auto", beta="auto", chunk_rows=4)
    # explicit weights equal to the chosen ones are another request: refused too
    with pytest.raises(InputError, match="unfinished run"):
        demultiplex_to_store(stack, out, alpha=rec["alpha"], beta=rec["beta"], chunk_rows=4)
    # the identical run continues, with the recorded choice (no second search)
    seen = []
    demultiplex_to_store(
        stack, out, alpha="auto", beta="auto", chunk_rows=4, on_choice=lambda c, resumed: seen.append(resumed)
    )
    assert seen == [True]
    T, attrs = read_transport(out)
    assert attrs["weights_choice"] == rec and (attrs["alpha"], attrs["beta"]) == (rec["alpha"], rec["beta"])
    # the same bytes as an uninterrupted run at those weights (on the same problem: the ambient estimated)
    assert rec["ambient"] == "estimate" == attrs["ambient"]
    ref = demultiplex(stack, alpha=rec["alpha"], beta=rec["beta"], ambient="estimate", chunk_rows=4).transport.dense
    np.testing.assert_array_equal(T.dense, ref)
