"""Demultiplexing (Sec. 4): problem assembly, exactness against CVXPY, recovery of
simulator ground truth, baselines, resumable chunked runs, Dask."""

import numpy as np
import pytest
import zarr

from planeray.acquire import simulate_stack
from planeray.camera import CameraModel
from planeray.demux import DemuxProblem, demultiplex, demultiplex_to_store, solve_chunk
from planeray.demux.driver import read_observations
from planeray.errors import InputError, TransportError
from planeray.io import read_transport, read_transport_maps, write_stack
from planeray.scenes import make_scene
from planeray.stack import Stack
from planeray.timing import Band, Sweep, paper_sweep


@pytest.fixture(scope="module")
def wax_stack():
    scene = make_scene("wax", (24, 20), projector_rows=135, seed=2)
    return scene, simulate_stack(scene, paper_sweep(), seed=2)


def test_problem_matches_the_paper_sweep():
    stack = simulate_stack(make_scene("diffuse_plane", (128, 8), projector_rows=720), paper_sweep(), noise=False)
    p = DemuxProblem.from_stack(stack)
    assert p.n_images == 75 and p.n_offsets == 229
    assert p.offsets_rows[0] == -114 and p.offsets_rows[-1] == 114
    # rows away from the projector's ends share one illumination matrix
    mid = p.row_group[40:90]
    assert np.all(mid == mid[0])
    # the top row sees fewer valid offsets (no projector rows above it)
    top, middle = p.groups[p.row_group[0]], p.groups[p.row_group[64]]
    assert top.A.shape[1] < middle.A.shape[1] == 229
    # the matrix is the imaging model's: same discretization and sign
    band = stack.bands()[int(p.image_index[0])]
    np.testing.assert_allclose(middle.A[0], band.weights(stack.geometry, 64, p.offsets_rows), atol=1e-12)


def test_too_few_images_and_gaps_are_reported():
    scene = make_scene("diffuse_plane", (16, 16))
    few = simulate_stack(scene, Sweep.grid([0.0, 187.5], [600.0]), noise=False)
    with pytest.raises(InputError, match="at least"):
        DemuxProblem.from_stack(few)
    gappy = simulate_stack(scene, Sweep.grid([-1500.0, -1300.0, 0.0, 150.0, 1400.0], [300.0]), noise=False)
    with pytest.raises(InputError, match="unlit"):
        DemuxProblem.from_stack(gappy)
    good = simulate_stack(scene, paper_sweep(), noise=False)
    with pytest.raises(InputError, match="alpha"):
        DemuxProblem.from_stack(good, alpha=-1)
    good.metadata["sync"]["jitter_us"] = -5.0
    with pytest.raises(InputError, match="inconsistent metadata: sync jitter_us"):
        DemuxProblem.from_stack(good)


def test_nan_in_stack_is_reported(wax_stack):
    _, stack = wax_stack
    images = np.array(stack.images)
    images[5, 3, 4] = np.nan
    bad = Stack(
        images,
        stack.delay_us,
        stack.exposure_us,
        stack.lines_per_second,
        stack.excluded,
        projector_rows=stack.projector_rows,
    )
    with pytest.raises(InputError, match=r"image 5 has a non-finite value at pixel \(3, 4\)"):
        demultiplex(bad, method="pinv")


def _objective_gap(problem, group, X_fast, X_ref, B):
    f_fast = problem.objective(group, X_fast, B)
    f_ref = problem.objective(group, X_ref, B)
    return (f_fast - f_ref) / f_ref


@pytest.mark.parametrize("scene_name", ["wax", "corner", "mirror_ball"])
def test_fast_matches_cvxpy_optimum(scene_name):
    """The fast solver's objective is within 1e-4 (median) and 1e-3 (worst) of CVXPY's."""
    pytest.importorskip("cvxpy")  # the reference solver (the "test" extra); the other demux tests need only planeray
    scene = make_scene(scene_name, (64, 64), projector_rows=360, seed=5)
    stack = simulate_stack(scene, paper_sweep(), seed=5)
    problem = DemuxProblem.from_stack(stack)
    rng = np.random.default_rng(0)
    gaps = []
    for row in rng.choice(64, 4, replace=False):
        rows = slice(int(row), int(row) + 1)
        obs, _ = read_observations(stack, problem, rows)
        group = problem.groups[problem.row_group[row]]
        cols = rng.choice(64, 12, replace=False)
        B = obs[:, 0, cols].T
        fast = solve_chunk(problem, obs, None, rows, method="fast")
        X_fast = fast.T[0, cols][:, group.valid].astype(np.float64)
        if group.on_projector is not None:  # the store holds T = x * on_projector; the problem's unknown is x
            X_fast /= group.on_projector
        from planeray.demux import solve_cvxpy

        X_ref = solve_cvxpy(group, B, problem.alpha, problem.beta).X
        gaps.append(_objective_gap(problem, group, X_fast, X_ref, B))
        assert fast.maps["converged"].all()
    gaps = np.concatenate(gaps)
    assert np.median(gaps) <= 1e-4, np.median(gaps)
    assert gaps.max() <= 1e-3, gaps.max()


def test_pseudo_inverse_goes_negative_and_constrained_methods_do_not(wax_stack):
    _, stack = wax_stack
    pinv = demultiplex(stack, method="pinv").transport.dense
    fast = demultiplex(stack, method="fast").transport.dense
    nnls = demultiplex(stack, method="nnls").transport.dense
    assert pinv.min() < -0.05 * pinv.max()  # the paper's Fig. 5a observation
    assert fast.min() >= 0 and nnls.min() >= 0


def _predictable_hold_out(stack, n):
    """Images whose band edges all remain among the fitted images' edges.

    An image measures ``C(hi) - C(lo)`` of the cumulative transport; holding out
    an image with an edge no other image has would ask the fit for information
    no fitted image carries (regularization would fill it in, not the data).
    """
    c = stack.delay_us * 1e-6 * stack.lines_per_second
    h = stack.exposure_us * 1e-6 * stack.lines_per_second / 2
    lo, hi = np.round(c - h, 6), np.round(c + h, 6)
    fit = set(np.flatnonzero(~stack.excluded))
    held = np.zeros(len(stack), bool)
    for i in sorted(fit, reverse=True):
        others = list(fit - {i})
        edges = set(lo[others]) | set(hi[others])
        if held.sum() < n and lo[i] in edges and hi[i] in edges:
            held[i] = True
            fit.discard(i)
    return held


@pytest.mark.parametrize(
    ("scene_name", "beta", "bound"),
    [
        ("mirror_ball", 0.01, 1.5),
        ("corner", 0.01, 1.5),
        # The paper's sparsity term biases a broad, faint subsurface kernel down
        # (its stated limitation): 1.64x the noise at beta = 0.01, 1.25x without it.
        ("wax", 0.01, 1.8),
        ("wax", 0.0, 1.4),
    ],
)
def test_held_out_images_are_predicted_within_noise(scene_name, beta, bound):
    """Fit without 12 of the 75 images, predict them from T: error at the noise level.

    Ambient light is off here: it is not light transport (it does not follow the
    projector's edges), so with it the fit's residual floor is the ambient level.
    """
    scene = make_scene(scene_name, (32, 32), projector_rows=180, seed=3)
    cam = CameraModel(row_jitter_us=0.0, ambient_e_per_us=0.0)
    stack = simulate_stack(scene, paper_sweep(), camera=cam, seed=3)
    held = _predictable_hold_out(stack, 12)
    fit = Stack(
        stack.images,
        stack.delay_us,
        stack.exposure_us,
        stack.lines_per_second,
        stack.excluded | held,
        projector_rows=stack.projector_rows,
        metadata=stack.metadata,
    )
    est = demultiplex(fit, beta=beta).transport
    # the same images captured again with fresh noise give the noise floor
    again = simulate_stack(scene, paper_sweep(), camera=cam, seed=99)
    errs, floor = [], []
    for i in np.flatnonzero(held):
        pred = est.render(Band(stack.delay_us[i], stack.exposure_us[i], stack.lines_per_second, cam.jitter_us))
        errs.append(np.sqrt(np.mean((pred - stack.images[i]) ** 2)))
        floor.append(np.sqrt(np.mean((again.images[i] - stack.images[i]) ** 2)) / np.sqrt(2))
    assert np.mean(errs) <= bound * np.mean(floor), (np.mean(errs), np.mean(floor))


def test_epipolar_image_matches_ground_truth():
    """The synthesized epipolar image equals the ground truth's at the sweep's resolution.

    No used image of the paper's sweep has a band edge within 6.075 rows of the
    epipolar plane, so light inside that cell cannot be split further: compare
    epipolar images integrated over exactly that cell.
    """
    scene = make_scene("mirror_ball", (64, 32), projector_rows=360, seed=4)
    cam = CameraModel(ambient_e_per_us=0.0)
    stack = simulate_stack(scene, paper_sweep(), camera=cam, seed=4)
    problem = DemuxProblem.from_stack(stack)
    res = problem.epipolar_resolution_rows
    assert res == pytest.approx(6.075)
    est = demultiplex(stack).transport
    cell = Band(0.0, 2 * res / 54000 * 1e6, 54000)
    truth = scene.transport.render(cell) * cam.signal_scale
    got = est.render(cell)
    inner = slice(12, 52)  # rows whose cell lies inside the projector
    bright = truth[inner] > 0.2 * truth.max()
    rel = np.abs(got[inner] - truth[inner])[bright] / truth[inner][bright]
    assert np.median(rel) < 0.02, np.median(rel)
    assert np.percentile(rel, 95) < 0.08, np.percentile(rel, 95)
    # the direct light of the page sits inside the cell: it matches the scene's direct image
    page = (scene.labels[inner] == 1) & bright
    direct = scene.direct[inner][page] * cam.signal_scale
    assert np.median(np.abs(got[inner][page] - direct) / direct) < 0.02


def test_resume_after_interrupted_run_gives_the_same_result(wax_stack, tmp_path):
    _, stack = wax_stack
    full = demultiplex_to_store(stack, tmp_path / "full.zarr", chunk_rows=4)
    out = tmp_path / "resumed.zarr"
    partial = demultiplex_to_store(stack, out, chunk_rows=4, _stop_after=3)  # "killed" after 3 chunks
    assert not out.exists() and partial.exists()
    assert zarr.open_group(str(partial), mode="r")["done_units"][:].sum() == 3
    seen = []
    demultiplex_to_store(stack, out, chunk_rows=4, progress=seen.append)
    assert seen[0] == 12  # the finished chunks are reported, not redone
    a, b = read_transport(full)[0], read_transport(out)[0]
    np.testing.assert_array_equal(a.dense, b.dense)
    assert not partial.exists()
    with pytest.raises(TransportError, match="already exists"):
        demultiplex_to_store(stack, out, chunk_rows=4)


def test_resume_refuses_a_different_run(wax_stack, tmp_path):
    _, stack = wax_stack
    out = tmp_path / "t.zarr"
    demultiplex_to_store(stack, out, chunk_rows=4, _stop_after=1)
    with pytest.raises(InputError, match="unfinished run"):
        demultiplex_to_store(stack, out, chunk_rows=4, alpha=0.1)
    demultiplex_to_store(stack, out, chunk_rows=4, alpha=0.1, restart=True)
    assert read_transport(out)[1]["alpha"] == 0.1


def test_store_is_readable_with_plain_zarr(wax_stack, tmp_path):
    _, stack = wax_stack
    out = demultiplex_to_store(stack, tmp_path / "t.zarr", chunk_rows=8)
    g = zarr.open_group(str(out), mode="r")
    assert g["T"].shape == (24, 20, 229) and g["T"].dtype == np.float32
    assert g.attrs["offsets_rows"] == list(range(-114, 115))
    assert g.attrs["method"] == "fast" and g.attrs["alpha"] == 0.01 and g.attrs["beta"] == 0.01
    assert g.attrs["lines_per_second"] == 54000.0
    maps = read_transport_maps(out)
    assert maps["converged"].all() and maps["residual_rms"].shape == (24, 20)


def test_saturated_observations_are_dropped():
    scene = make_scene("diffuse_plane", (16, 16), projector_rows=90)
    cam = CameraModel(laser_electrons=14_000.0)  # bright pixels saturate at delay ~0
    stack = simulate_stack(scene, paper_sweep(), camera=cam, seed=1)
    assert stack.saturated.any()
    res = demultiplex(stack)
    n_obs = res.maps["n_observations"]
    assert n_obs.min() < 75 and n_obs.max() == 75
    assert res.maps["converged"].all()


@pytest.mark.slow
def test_lazy_stack_and_dask_equal_the_local_path(wax_stack, tmp_path):
    pytest.importorskip("dask.distributed")
    _, stack = wax_stack
    path = write_stack(stack, tmp_path / "s.zarr")
    from planeray.io import read_stack

    lazy = read_stack(path)
    local = demultiplex_to_store(lazy, tmp_path / "local.zarr", chunk_rows=6)
    dask = demultiplex_to_store(lazy, tmp_path / "dask.zarr", chunk_rows=6, workers=2)
    np.testing.assert_allclose(read_transport(dask)[0].dense, read_transport(local)[0].dense, rtol=1e-5, atol=1e-7)


def test_a_problem_that_has_solved_chunks_still_pickles(wax_stack):
    """A Dask worker sends the problem it holds to another worker after solving chunks with it.

    The solver cache a solve leaves on each row group holds locks, which do not pickle: the
    worker could not send it and the cluster waited forever (seen as a hung test).  The
    problem pickles without the cache, and the copy solves the same chunk to the same bytes.
    """
    import pickle

    _, stack = wax_stack
    problem = DemuxProblem.from_stack(stack)
    rows = slice(6, 12)
    obs, sat = read_observations(stack, problem, rows)
    first = solve_chunk(problem, obs, sat, rows)
    assert any("_admm_cache" in vars(g) for g in problem.groups)  # what a solve leaves behind
    copy = pickle.loads(pickle.dumps(problem))
    assert not any("_admm_cache" in vars(g) for g in copy.groups)
    again = solve_chunk(copy, obs, sat, rows)
    np.testing.assert_array_equal(again.T, first.T)


class _GuardedImages:
    """An image array that refuses reads of more camera rows than a chunk (larger-than-memory stand-in)."""

    def __init__(self, images, max_rows):
        self.images, self.max_rows, self.shape = images, max_rows, images.shape

    def __len__(self):
        return self.shape[0]

    def __getitem__(self, key):
        if isinstance(key, tuple) and len(key) > 1 and isinstance(key[1], slice):
            rows = range(*key[1].indices(self.shape[1]))
            assert len(rows) <= self.max_rows, f"read {len(rows)} rows at once"
        elif not isinstance(key, (int, np.integer)):
            raise AssertionError(f"whole-stack read {key!r}")
        return self.images[key]


def test_memory_is_bounded_by_the_chunk(wax_stack, tmp_path):
    _, stack = wax_stack
    guarded = Stack(
        _GuardedImages(np.asarray(stack.images), 4),
        stack.delay_us,
        stack.exposure_us,
        stack.lines_per_second,
        stack.excluded,
        saturated=None,
        projector_rows=stack.projector_rows,
        metadata=stack.metadata,
    )
    out = demultiplex_to_store(guarded, tmp_path / "t.zarr", chunk_rows=4)
    ref = demultiplex(stack, chunk_rows=24).transport.dense
    np.testing.assert_allclose(read_transport(out)[0].dense, ref, rtol=1e-5, atol=1e-7)


@pytest.mark.slow
def test_existing_dask_cluster_by_address(wax_stack, tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    _, stack = wax_stack
    local = demultiplex_to_store(stack, tmp_path / "local.zarr", chunk_rows=8)
    # one worker, a thread of this process: the address is what this checks (the scheduler is reached over
    # TCP all the same); chunks shared among worker processes: the test above
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0"
    ) as cluster:
        remote = demultiplex_to_store(
            stack, tmp_path / "remote.zarr", chunk_rows=8, scheduler=cluster.scheduler_address
        )
    np.testing.assert_allclose(read_transport(remote)[0].dense, read_transport(local)[0].dense, rtol=1e-5, atol=1e-7)
    assert read_transport_maps(remote)["converged"].all()


def test_top_and_bottom_rows_keep_their_light_by_the_edge_rule():
    """A noise-free diffuse plane at P/H = 11.25: the demultiplexed full image of every row, the first and last
    included (whose footprint ends on the projector's edge, inside a bin), is the truth's to 0.1 %.
    Before the edge rule (a bin straddling the edge weighted by its coverage twice) they lost 1 %."""
    from planeray.camera import CameraModel

    scene = make_scene("diffuse_plane", (32, 16), projector_rows=360, seed=0)
    stack = simulate_stack(scene, paper_sweep(), seed=0, noise=False, camera=CameraModel(ambient_e_per_us=0.0))
    result = demultiplex(stack)
    full = result.transport.full_image() / stack.metadata["signal_scale"]
    ratio = full.mean(axis=1) / scene.transport.full_image().mean(axis=1)
    assert np.abs(ratio - 1).max() < 1e-3, ratio[[0, 1, 16, 30, 31]]
