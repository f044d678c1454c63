"""The live transport (:mod:`planeray.live.transport`): the rolling window of a sweep, demultiplexed warm-started,
equals an offline ``demultiplex`` of the same images to the solver's certified accuracy; warm starts cut the
iterations, not the accuracy; the capture cycles a sweep's settings."""

from __future__ import annotations

import numpy as np
import pytest

from planeray.acquire import simulate_stack
from planeray.demux import DemuxProblem, demultiplex
from planeray.demux.fast import WarmStart, solve_fast
from planeray.demux.problem import read_observations
from planeray.devices import open_device
from planeray.live import LiveCapture, LiveTransport, WindowSolver, window_stack
from planeray.scenes import make_scene
from planeray.timing import quick_sweep

TOL = 1e-4


def _q_norms(problem, T_a, T_b):
    """``||x_a - x_b||_Q`` of every pixel (the unknowns: T per projector row of each bin)."""
    H, W = problem.shape
    out = np.zeros((H, W))
    for g in problem.groups:
        Q = 2.0 * g.hessian(problem.alpha)
        on = 1.0 if g.on_projector is None else g.on_projector
        d = (T_a[g.rows][:, :, g.valid].astype(np.float64) - T_b[g.rows][:, :, g.valid]) / on
        out[g.rows] = np.sqrt(np.maximum(np.einsum("rwi,ij,rwj->rw", d, Q, d), 0.0))
    return out


def test_the_rolling_window_transport_is_the_offline_demux_of_the_same_images():
    dev = open_device("sim", scene="wax", size=(12, 16), projector_rows=68, frames_averaged=1, seed=3)
    capture = LiveCapture(dev, max_fps=200.0)
    live = LiveTransport(capture, quick_sweep(), lines_per_second=dev.lines_per_second, projector_rows=68,
                         jitter_us=dev.camera.jitter_us)  # fmt: skip
    with live:
        first = live.wait_update(timeout_s=60)
        update = live.wait_update(first.number + 2, timeout_s=60)  # a warm-started window
    assert update.warm and update.maps["converged"].all()
    # the window: the newest frame of every used setting, in the sweep's order
    used = ~quick_sweep().excluded
    assert [(f.delay_us, f.exposure_us) for f in update.frames] == list(
        zip(quick_sweep().delay_us[used], quick_sweep().exposure_us[used])
    )
    offline = demultiplex(window_stack(update.frames, lines_per_second=dev.lines_per_second, projector_rows=68,
                                       jitter_us=dev.camera.jitter_us))  # fmt: skip
    assert offline.maps["converged"].all()
    np.testing.assert_array_equal(offline.transport.offsets_rows, update.transport.offsets_rows)
    f_live, f_off = update.maps["objective"], offline.maps["objective"].astype(np.float64)
    # both certified to a relative gap <= tol of the same problem: their objectives agree to ~tol ...
    assert np.all(np.abs(f_live - f_off) <= 2.5 * TOL * f_off)
    # ... and, the QP being Q-strongly convex at its optimum, f(x) - f* >= ||x - x*||_Q^2 / 2 for both
    problem = live.solver.problem
    gap_off = TOL * f_off / (1 + TOL)
    bound = np.sqrt(2 * update.maps["gap"]) + np.sqrt(2 * gap_off)
    q = _q_norms(problem, update.transport.dense, offline.transport.dense)
    assert np.all(q <= bound * 1.001 + 1e-12)
    # the transports themselves: close in the relative sense too
    rel = np.linalg.norm(update.transport.dense - offline.transport.dense) / np.linalg.norm(offline.transport.dense)
    assert rel < 0.1
    assert live.rate_hz >= 0 and update.age_s() >= 0 and update.window_span_s >= 0


def test_a_window_of_other_images_is_not_the_transport():
    """The comparison above can fail: the offline demux of a window with one image from elsewhere differs."""
    scene = make_scene("wax", (12, 16), projector_rows=68, seed=3)
    sweep = quick_sweep()
    a = simulate_stack(scene, sweep, seed=1)
    b = simulate_stack(scene, sweep, seed=2)
    used = ~sweep.excluded
    solver = WindowSolver(sweep, (12, 16), lines_per_second=a.lines_per_second, projector_rows=68,
                          jitter_us=a.jitter_us)  # fmt: skip
    T_a, m_a = solver.solve(np.asarray(a.images)[used])
    mixed = np.asarray(a.images)[used].copy()
    mixed[3] = np.asarray(b.images)[used][5]  # an image of another setting in slot 3
    T_m, m_m = solver.solve(mixed)
    bound = np.sqrt(2 * m_a["gap"]) + np.sqrt(2 * m_m["gap"])
    assert np.any(_q_norms(solver.problem, T_a.dense, T_m.dense) > 10 * bound)


def test_warm_starts_cut_the_iterations_not_the_accuracy():
    scene = make_scene("wax", (16, 24), projector_rows=90, seed=0)
    sweep = quick_sweep()
    st1 = simulate_stack(scene, sweep, seed=1)
    st2 = simulate_stack(scene, sweep, seed=2)
    problem = DemuxProblem.from_stack(st1)
    g = problem.groups[int(np.bincount(problem.row_group).argmax())]

    def B(st):
        obs, _ = read_observations(st, problem, slice(0, st.shape[0]))
        return obs[:, g.rows, :].reshape(obs.shape[0], -1).T

    B1, B2 = B(st1), B(st2)
    B2[:, 4:] = B1[:, 4:]  # the next window: four images new, the rest as before
    state = WarmStart.empty(B1.shape[0], g.A.shape[1])
    solve_fast(g, B1, state=state)
    cold = solve_fast(g, B2)
    warm = solve_fast(g, B2, start=state)
    assert cold.converged.all() and warm.converged.all()
    assert warm.iterations.mean() < 0.6 * cold.iterations.mean()
    assert np.all(np.abs(warm.objective - cold.objective) <= 2.5 * TOL * cold.objective)
    # a warm start from the pixel's own optimum on the same data: certified at the first check
    again = WarmStart.empty(B1.shape[0], g.A.shape[1])
    solve_fast(g, B2, state=again)
    from planeray.demux.fast import WARM_FIRST_CHECK

    assert solve_fast(g, B2, start=again).iterations.max() == WARM_FIRST_CHECK


def test_the_capture_cycles_a_sweeps_settings():
    dev = open_device("sim", scene="diffuse_plane", size=(8, 8), frames_averaged=1)
    d, e = [0.0, 375.0, -750.0], [600.0, 300.0, 900.0]
    with LiveCapture(dev, max_fps=500.0) as capture:
        capture.set_sweep(d, e)
        window = capture.wait_sweep(d, e, timeout_s=30)
        assert [(f.delay_us, f.exposure_us) for f in window] == list(zip(d, e))
        newer = capture.wait_sweep(d, e, after=max(f.index for f in window), timeout_s=30)
        assert max(f.index for f in newer) > max(f.index for f in window)
        assert capture.target == (tuple(d), tuple(e))
    with pytest.raises(Exception, match="one exposure per delay"):
        LiveCapture(open_device("sim", scene="diffuse_plane", size=(8, 8))).set_sweep([0.0, 1.0], [600.0])
