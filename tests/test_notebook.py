"""A notebook session through the top-level API only (``import planeray as pr``), no CLI.

Simulate the paper's sweep of a scene, store and reload it, demultiplex it, and use
the transport: synthesis, profiles, labels -- each against the scene's ground truth.
"""

import numpy as np

import planeray as pr


def test_top_level_api_end_to_end(tmp_path):
    assert pr.__version__ and "demultiplex" in dir(pr)
    scene = pr.make_scene("wax", (24, 24), projector_rows=135, seed=1)
    stack = pr.simulate_stack(scene, pr.paper_sweep(), seed=1)
    assert stack.images.shape == (85, 24, 24)

    path = pr.write_stack(stack, tmp_path / "wax.zarr")
    again = pr.read_stack(path)
    np.testing.assert_array_equal(np.asarray(again.images), stack.images)

    result = pr.demultiplex(again)
    T = result.transport
    assert result.maps["converged"].mean() > 0.99

    # The estimate re-renders the expected (noise-free, ambient included) epipolar capture.
    expected = pr.simulate_stack(scene, pr.paper_sweep(), seed=1, noise=False)
    truth_epi = expected.image(expected.index_of(0.0, 600.0))
    est_epi = pr.band_image(T, 0.0, 600.0)
    rel = np.abs(est_epi - truth_epi).mean() / truth_epi.mean()
    assert rel < 0.03, rel

    sharp = pr.sharpened_epipolar(T, width_rows=1.0)
    assert sharp.shape == (24, 24) and np.all(np.isfinite(sharp))

    prof = pr.measured_delay_profiles(again, [(12, 12)])
    # area-normalized over delay in milliseconds (Sec. 8: cancels albedo)
    assert np.isclose(np.trapezoid(prof.values[0, 0], prof.delay_us * 1e-3), 1.0, rtol=1e-4)

    labels = pr.classify_transport(T, resolution_rows=result.attrs["epipolar_resolution_rows"])
    assert labels.shape == (24, 24)

    store = pr.write_transport(T, tmp_path / "T.zarr", attrs=result.attrs)
    back, attrs = pr.read_transport(store)
    np.testing.assert_array_equal(back.dense, T.dense)
    assert attrs["offsets_rows"][0] == -114
